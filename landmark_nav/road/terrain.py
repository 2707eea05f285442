"""Terrain classification from single scans of a tilted 2-D laser (visual navigation ch. §4.2).

A laser scanner pitched slightly down sweeps a line across the ground in front of the
robot. Each reading is classified into ``C = {C_t traversable, C_n not traversable,
C_0 invalid}`` from features of the single scan,
``F = {H_h raw height, F_sigma roughness, F_z step size, F_c curvature, F_t slope,
F_w width}``:

1. the readings are placed in ``base_link`` (x forward, y left, z up, z = 0 on the ground
   plane under the robot) through the laser mount (x, y, z, roll, pitch, yaw);
2. *roughness* ``F_sigma``: the root of the local variance about a line fitted (total least
   squares, in the scan plane) over the readings within ``window`` (about one wheel base,
   0.45 m) of path length along the scan;
3. *roughness groups*: runs of consecutive valid readings with a roughness below
   ``roughness_max``, a raw height ``|H_h|`` below ``height_max`` and no *step* ``F_z``
   (height jump between neighbours) above ``step_max``;
4. groups separated by at most ``gap_max`` metres of rough readings at a compatible height
   are combined (a stone or a tuft of grass does not cut a road in two);
5. *edges at the reading*: the windowed roughness of a reading within half a window of a
   rougher one is raised by it, so the groups end up to ``window / 2`` short of (or, beside
   a smooth verge, past) the true edge. Each group is widened by half a window (stretches
   that then touch are joined) and segmented along the lateral position into pieces, each
   a quadratic (crowned road) or straight (flat shoulder) height profile with its own
   residual variance (roughness), floored by the laser's height noise
   (``range_sigma`` times the beam's vertical component): binary segmentation by the
   likelihood gain with the Bayesian information criterion's penalty, then neighbours
   are rejoined, least significant boundary first (per reading), unless they differ
   physically -- roughness by ``rough_ratio`` (F-test at ``rough_alpha``) or profile by a
   kink of more than ``split_rms`` -- each remaining boundary is re-placed by a continuous
   fit of the two neighbours (the wider quadratic, the narrower straight, meeting without
   a step), and the rougher of two pieces beside a road-wide smooth piece is a verge. So
   the edge is the reading where the profile bends or the roughness changes: the kink
   between a crowned road and its flat shoulder, which roughness alone does not separate
   on gravel (the chapter's +0.7 m), or smooth asphalt next to a rough verge;
   each piece is then filtered by its quadratic height profile ``z = a + b s + c s^2``
   across the scan: slope ``F_t = |b|`` below ``slope_max``, curvature ``F_c = |2 c|``
   below ``curvature_max``, median roughness ``F_sigma`` below ``roughness_max``, width
   ``F_w`` (end-to-end distance) at least ``min_width`` (the robot's width): the pieces that
   pass are the *traversable segments*, their readings ``C_t``; the other valid readings
   are ``C_n``; neighbouring traversable pieces (no step or gap between them) whose
   profiles do not kink by more than ``split_rms`` are one segment (a smoother patch of a
   gravel road kept apart by the roughness test does not split the road);
6. *obstacles*: runs of valid readings outside the traversable segments higher than
   ``obstacle_height`` above the ground plane (a kerb face, a post), or not traversable,
   between traversable readings and more than ``obstacle_depth`` short of the ground line
   they trace (the tilted laser meets a pedestrian's legs just before the ground).

Modules, each named after what it computes (this one is the entry point and re-exports
:class:`LaserMount`, :func:`scan_points` and :class:`TerrainParams`):

* :mod:`.laser_mount` -- step 1, the laser's pose and the readings in ``base_link``;
* :mod:`.terrain_params` -- the thresholds;
* :mod:`.roughness` -- step 2, the roughness ``F_sigma``;
* :mod:`.profile_fits` -- the closed-form line and quadratic height profiles of pieces;
* :mod:`.profile_segmentation` -- step 5, the binary segmentation of a stretch;
* :mod:`.road_edges` -- step 5, merging the pieces, placing the edges, the verges;
* here: steps 3-6 put together in :func:`classify_scan` (groups, segments, obstacles).

Pure numpy (and scipy.special for the F-test); the node is
:mod:`landmark_nav.nodes.road_classifier`.
"""

import bisect
from dataclasses import dataclass, field
import math
from typing import Optional

from landmark_nav.road.laser_mount import LaserMount, scan_points
from landmark_nav.road.profile_fits import _moment_table
from landmark_nav.road.profile_segmentation import _segment_profiles
from landmark_nav.road.road_edges import _merge_pieces, _refine_edges, _verges
from landmark_nav.road.roughness import _roughness
from landmark_nav.road.terrain_params import TerrainParams
import numpy as np

__all__ = ['INVALID', 'LaserMount', 'NOT_TRAVERSABLE', 'Obstacle', 'Segment', 'TerrainParams',
           'TerrainScan', 'TRAVERSABLE', 'classify_scan', 'scan_points']

#: Reading classes (the chapter's C_0, C_t, C_n).
INVALID = 0
TRAVERSABLE = 1
NOT_TRAVERSABLE = 2


@dataclass(frozen=True)
class Segment:
    """One traversable segment of a scan (readings ``first`` .. ``last`` inclusive).

    Attributes:
        first: Index of the first reading (in the scan's order).
        last: Index of the last reading.
        start: (x, y) of the first reading in base_link [m].
        end: (x, y) of the last reading in base_link [m].
        width: End-to-end distance ``F_w`` [m].
        height: Mean raw height ``H_h`` [m].
        roughness: Mean roughness ``F_sigma`` [m].
        slope: Height slope ``F_t`` across the segment at its centre [m/m].
        curvature: Height curvature ``F_c`` [1/m] (negative: convex, e.g. a crowned road).
    """

    first: int
    last: int
    start: tuple
    end: tuple
    width: float
    height: float
    roughness: float
    slope: float
    curvature: float

    @property
    def centre(self) -> np.ndarray:
        """Midpoint of the end points (x, y) [m]."""
        return 0.5 * (np.asarray(self.start) + np.asarray(self.end))

    def lateral_extent(self) -> tuple[float, float]:
        """Return (y_min, y_max) of the end points [m] (across the robot heading)."""
        ys = (self.start[1], self.end[1])
        return float(min(ys)), float(max(ys))


@dataclass(frozen=True)
class Obstacle:
    """A run of readings standing above the ground (``first`` .. ``last`` inclusive)."""

    first: int
    last: int
    points: np.ndarray = field(repr=False)   # (M, 3) base_link [m]
    height: float = 0.0                      # highest reading above the ground [m]


@dataclass(frozen=True, eq=False)
class TerrainScan:
    """Classification of one scan; arrays have one row per reading (NaN where invalid)."""

    points: np.ndarray        # (N, 3) base_link
    classes: np.ndarray       # (N,) INVALID / TRAVERSABLE / NOT_TRAVERSABLE
    roughness: np.ndarray     # (N,) F_sigma [m]
    step: np.ndarray          # (N,) F_z [m]: largest height jump to a valid neighbour
    groups: np.ndarray        # (N,) roughness group id, -1 outside every group
    segments: tuple           # Segment, ordered by first reading
    obstacles: tuple          # Obstacle
    ground_hits: int          # valid readings on the ground (|z| <= height_max)

    def best_segment(self, y: float = 0.0) -> Optional[Segment]:
        """Return the segment spanning the lateral offset ``y`` (else the nearest, or None)."""
        if not self.segments:
            return None

        def distance(s: Segment) -> float:
            lo, hi = s.lateral_extent()
            return 0.0 if lo <= y <= hi else min(abs(lo - y), abs(hi - y))
        return min(self.segments, key=lambda s: (distance(s), -s.width))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive (first, last) index pairs of the runs of True in a 1-D mask."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1) - 1
    return list(zip(starts.tolist(), ends.tolist()))


def classify_scan(ranges: np.ndarray, angles: np.ndarray, mount: LaserMount,
                  params: TerrainParams = TerrainParams(), range_min: float = 0.0,
                  range_max: float = math.inf) -> TerrainScan:
    """Classify the readings of one tilted-laser scan (§4.2).

    Args:
        ranges: (N,) ranges [m] in scan order; non-finite or outside
            [range_min, range_max] are invalid (REP 117).
        angles: (N,) beam angles in the laser frame [rad], increasing.
        mount: The laser's pose in base_link.
        params: Feature-function thresholds.
        range_min: Smallest valid range [m].
        range_max: Largest valid range [m].

    Returns:
        The per-reading classes, features, traversable segments and obstacles.

    Raises:
        ValueError: ``ranges`` and ``angles`` differ in shape or are not 1-D.
    """
    r = np.asarray(ranges, dtype=float)
    a = np.asarray(angles, dtype=float)
    if r.ndim != 1 or r.shape != a.shape:
        raise ValueError(f'ranges and angles must be 1-D of one length; got {r.shape} and '
                         f'{a.shape}')
    n_all = r.size
    with np.errstate(invalid='ignore'):
        valid = np.isfinite(r) & (r >= range_min) & (r <= range_max) & np.isfinite(a)
    pts = np.full((n_all, 3), np.nan)
    classes = np.full(n_all, INVALID, dtype=np.int8)
    rough_all = np.full(n_all, np.nan)
    step_all = np.full(n_all, np.nan)
    groups_all = np.full(n_all, -1, dtype=int)
    idx = np.flatnonzero(valid)
    if idx.size == 0:
        return TerrainScan(pts, classes, rough_all, step_all, groups_all, (), (), 0)
    # scan_points, with the beams' cosines and sines computed once for the other uses.
    ri, ca, sa = r[idx], np.cos(a[idx]), np.sin(a[idx])
    local = np.vstack([ri * ca, ri * sa])
    rot = mount.rotation()[:, :2]                 # the laser frame's z column meets z = 0
    p = (rot @ local).T + mount.translation()
    pts[idx] = p
    classes[idx] = NOT_TRAVERSABLE
    plane = local.T
    d_plane = np.diff(local, axis=1)
    gaps = np.sqrt(d_plane[0] * d_plane[0] + d_plane[1] * d_plane[1])
    # Path length along the scan; a jump longer than the window is capped at it so that
    # no window spans both sides of a range discontinuity.
    s = np.concatenate([[0.0], np.cumsum(np.minimum(gaps, params.window))])
    z = p[:, 2]
    rough = _roughness(plane, s, params.window, params.min_points)   # F_sigma
    dz = np.abs(np.diff(z))
    step = np.maximum(np.concatenate([[0.0], dz]), np.concatenate([dz, [0.0]]))   # F_z
    rough_all[idx] = rough
    step_all[idx] = step
    ground = np.abs(z) <= params.height_max                          # H_h
    smooth = (rough <= params.roughness_max) & ground
    # Runs of smooth readings, cut at steps and at gaps.
    cut = np.zeros(idx.size, dtype=bool)
    cut[1:] = (dz > params.step_max) | (gaps > params.gap_max)
    groups = []
    cuts = np.flatnonzero(cut).tolist()
    for first, last in _runs(smooth):
        start = first
        for k in cuts[bisect.bisect_right(cuts, first):bisect.bisect_right(cuts, last)]:
            groups.append((start, k - 1))
            start = k
        groups.append((start, last))
    groups = _combine(groups, s, z, cut, params)
    # Height profiles across the scan are functions of the lateral position (base_link y,
    # increasing along the scan), which a crowned road's profile is a quadratic of.
    lateral = p[:, 1]
    # The sensor's height noise per reading: the range noise along the beam's z component.
    beam_z = rot[2, 0] * ca + rot[2, 1] * sa
    var0 = (params.range_sigma * beam_z) ** 2
    # The windowed roughness of the readings within half a window of a rougher neighbour is
    # raised by it, which trims every group by up to window / 2 at each end: each group is
    # widened by half a window (not across a step or a gap, nor into the next group) and
    # the profile segmentation puts the edge on the reading where the profile or its
    # roughness changes.
    stretches = []
    s_l, cut_l, ground_l = s.tolist(), cut.tolist(), ground.tolist()
    for g, (first, last) in enumerate(groups):
        taken = stretches[-1][1] if stretches else -1
        nxt = groups[g + 1][0] if g + 1 < len(groups) else idx.size
        while first - 1 > taken and not cut_l[first] and \
                s_l[first - 1] >= s_l[first] - 0.5 * params.window and ground_l[first - 1]:
            first -= 1
        while last + 1 < nxt and not cut_l[last + 1] and \
                s_l[last + 1] <= s_l[last] + 0.5 * params.window and ground_l[last + 1]:
            last += 1
        if stretches and stretches[-1][1] + 1 == first and not cut_l[first]:
            first = stretches.pop()[0]         # a rough gap shorter than the window
        stretches.append((first, last))
    pieces = []
    # Empty and degenerate pieces divide by zero in the closed-form fits: silenced once.
    with np.errstate(divide='ignore', invalid='ignore'):
        tables = [_moment_table(lateral[first:last + 1], z[first:last + 1],
                                var0[first:last + 1]) for first, last in stretches]
        for (first, last), table, found in zip(stretches, tables,
                                               _segment_profiles(tables, params)):
            fits = {}
            merged = _refine_edges(_merge_pieces(found, table, params, fits), table, params,
                                   fits)
            verge = _verges(merged, lateral[first:last + 1], table, params, fits)
            pieces += [(a + first, b + first) for (a, b), v in zip(merged, verge) if not v]
    segments = []
    for g, (first, last) in enumerate(pieces):
        groups_all[idx[first:last + 1]] = g
        seg = _segment(first, last, p, lateral, rough, idx, params)
        if seg is not None:
            # A traversable neighbour without a kink between (a smoother patch of the same
            # road, kept apart by the roughness test) continues the segment.
            classes[idx[first:last + 1]] = TRAVERSABLE
            if segments and segments[-1][0] + 1 == first and \
                    not _kink(segments[-1][1][0], first, last, lateral, z, params):
                joined = _segment(segments[-1][1][0], last, p, lateral, rough, idx, params)
                if joined is not None:
                    first, seg = segments.pop()[1][0], joined
            segments.append((last, (first, last), seg))
    segments = [seg for _, _, seg in segments]
    # Obstacles: readings high above the ground plane, or (a tilted laser meets an object
    # before the ground) well short of the ground line the traversable readings trace.
    # A traversable segment is ground whatever its height (the crown of a gravel road
    # stands 0.15 m above its edges).
    high = (z > params.obstacle_height) & (classes[idx] != TRAVERSABLE)
    trav = np.flatnonzero(classes[idx] == TRAVERSABLE)
    if trav.size >= 2:
        k = np.arange(idx.size)
        ground_x = np.interp(k, trav, p[trav, 0])
        between = (k > trav[0]) & (k < trav[-1])
        high |= (between & (classes[idx] != TRAVERSABLE)
                 & (ground_x - p[:, 0] > params.obstacle_depth))
    obstacles = []
    for first, last in _runs(high):
        obstacles.append(Obstacle(int(idx[first]), int(idx[last]), p[first:last + 1].copy(),
                                  float(z[first:last + 1].max())))
    return TerrainScan(pts, classes, rough_all, step_all, groups_all, tuple(segments),
                       tuple(obstacles), int(ground.sum()))


def _kink(first: int, mid: int, last: int, lateral: np.ndarray, z: np.ndarray,
          params: TerrainParams) -> bool:
    """Whether readings first..mid-1 and mid..last have profiles kinked by > split_rms."""
    def sse(a: int, b: int) -> float:
        t = lateral[a:b + 1] - lateral[a:b + 1].mean()
        return float(np.sum((np.polyval(np.polyfit(t, z[a:b + 1], 2), t) - z[a:b + 1]) ** 2))
    extra = sse(first, last) - sse(first, mid - 1) - sse(mid, last)
    return math.sqrt(max(extra, 0.0) / min(mid - first, last - mid + 1)) > params.split_rms


def _combine(groups: list, s: np.ndarray, z: np.ndarray, cut: np.ndarray,
             params: TerrainParams) -> list:
    """Join neighbouring groups separated by a short rough gap at a compatible height."""
    out = []
    for first, last in groups:
        if out:
            pf, pl = out[-1]
            short = s[first] - s[pl] <= params.gap_max
            level = abs(z[first] - z[pl]) <= params.step_max
            if short and level and not cut[pl + 1:first + 1].any():
                out[-1] = (pf, last)
                continue
        out.append((first, last))
    return out


def _quadratic_slope_curvature(t: np.ndarray, z: np.ndarray) -> tuple[float, float]:
    """Return ``(b, 2 c)`` of the least-squares ``z = a + b t + c t^2`` (``t`` about 0).

    The normal equations of ``t`` scaled to [-1, 1] (well conditioned), solved in closed
    form: ``np.polyfit(t, z, 2)`` to rounding, without its per-call overhead.
    """
    h = float(np.max(np.abs(t)))
    if not h > 0.0:
        return 0.0, 0.0
    u = t / h
    u2 = u * u
    s0, s1, s2, s3, s4 = float(u.size), float(u.sum()), float(u2.sum()), \
        float(np.dot(u2, u)), float(np.dot(u2, u2))
    b0, b1, b2 = float(z.sum()), float(np.dot(z, u)), float(np.dot(z, u2))
    c00, c01, c02 = s2 * s4 - s3 * s3, s2 * s3 - s1 * s4, s1 * s3 - s2 * s2
    c11, c12, c22 = s0 * s4 - s2 * s2, s1 * s2 - s0 * s3, s0 * s2 - s1 * s1
    det = s0 * c00 + s1 * c01 + s2 * c02
    b = (b0 * c01 + b1 * c11 + b2 * c12) / det
    c = (b0 * c02 + b1 * c12 + b2 * c22) / det
    return b / h, 2.0 * c / (h * h)


def _segment(first: int, last: int, p: np.ndarray, s: np.ndarray, rough: np.ndarray,
             idx: np.ndarray, params: TerrainParams) -> Optional[Segment]:
    """Filter one roughness group by width, slope and curvature; return its segment."""
    if last - first + 1 < params.min_points:
        return None
    (x0, y0), (x1, y1) = p[first, :2].tolist(), p[last, :2].tolist()
    width = math.hypot(x1 - x0, y1 - y0)                               # F_w
    if width < params.min_width:
        return None
    t = s[first:last + 1] - 0.5 * (s[first] + s[last])
    zz = p[first:last + 1, 2]
    slope, curvature = _quadratic_slope_curvature(t, zz)              # F_t, F_c
    if abs(slope) > params.slope_max or abs(curvature) > params.curvature_max:
        return None
    piece = rough[first:last + 1]
    if _median(piece) > params.roughness_max:                         # F_sigma of the piece
        return None
    n = last - first + 1
    return Segment(int(idx[first]), int(idx[last]), (x0, y0), (x1, y1), width,
                   float(zz.sum()) / n, float(piece.sum()) / n, slope, curvature)


def _median(x: np.ndarray) -> float:
    """Return ``np.median(x)`` of a non-empty array without NaN, by one partition."""
    k = x.size // 2
    if x.size % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, (k - 1, k))
    return float((part[k - 1] + part[k]) / 2)
