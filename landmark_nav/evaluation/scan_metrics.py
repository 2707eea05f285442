"""Feature metrics that need no ground-truth features: scores of real scans.

Everything here takes one scan (ranges, beam angles, masks; laser frame) and the features
extracted from it, and needs nothing else, except repeatability, which also needs the
reference pose of each scan (e.g. the corrected pose of a Carmen log).

* **PLE ray metric** (Schaefer, Buescher, Luft, Burgard: "A maximum likelihood approach to
  extract polylines from 2-D laser range scans", IROS 2018, section V; their evaluation
  script ``evalexp.m`` and ray caster ``xpm.m`` in github.com/acschaefer/ple): the ray of
  every beam with a return is traced against the extracted segments; ``f`` = fraction of
  those beams whose ray hits a segment; ray RMSE = RMS over the hitting beams of
  (measured range - range to the first segment hit along the ray). Beams without a return
  (REP 117 +inf) are scored apart as in the paper: ``f_no_return`` = fraction of them whose
  ray hits no segment. :func:`ray_metrics`. The ray RMSE is also given without the
  **occluders**, hitting beams that end more than the false-surface margin in front of their
  segment (an object before the line, e.g. a lone stray return that the extractor kept
  inside a wall line): a few such beams metres short dominate a scan's RMSE.
* **False-surface beams**: beams with a return measured more than ``max(3 sigma_r, 5 cm)``
  beyond a segment that their ray crosses inside the segment's extent: the laser saw
  through a surface that is not there. :func:`ray_metrics`.
* **Fit residual**: perpendicular distance of each beam's point to the line of the first
  segment its ray hits, over the beams within 20 cm of it. :func:`ray_metrics`.
* **Repeatability** between consecutive scans through the reference poses:
  :func:`line_repeatability`, :func:`corner_repeatability`. An opportunity is a feature
  the next scan could re-detect: a line's midpoint in view (:func:`in_view`), a corner's
  place and a point 15 cm along each arm seen (:func:`corner_observable`). Corner
  repeatability is also given per class of the corner in scan k: structural (both arms at
  least ``STRUCTURAL_ARM`` = 0.2 m and ``STRUCTURAL_BEAM_STEPS`` + 1 = 6 beams,
  ``Corner.structural``) and the others.
* **Baseline** line extractor: iterative end-point fit (Douglas-Peucker) per breakpoint
  cluster, OpenCV ``approxPolyDP``: :func:`approx_poly_segments`.

Choices stated (the paper leaves them open or its script differs from its text):

* A ray hits a segment when its bearing lies within the bearings of the segment's end
  points widened by ``angle_tol`` = 1e-3 rad, the tolerance of ``xpm.m`` (end points are
  projections of the first and last supporting points on the fitted line, so the rays of
  those beams land on the line a hair outside the extent). The range is that of the ray's
  intersection with the segment's line, and must be > 0.
* The first hit is the nearest along the ray, as the paper's text says (``xpm.m`` keeps
  the last segment in map order, which is the same whenever segments do not overlap in
  bearing).
* The fit residual belongs to the first-hit segment (the same association as the ray
  metric); 20 cm keeps beams of a neighbouring object out.
"""

from dataclasses import asdict, dataclass, replace
import math
import time
from typing import Dict, List, Mapping, Optional, Sequence, Tuple, Union

from landmark_nav.evaluation.features import normal_form, segment_per_extractor
from landmark_nav.geometry import inverse_transform_points, transform_points, wrap_angle
import numpy as np

ANGLE_TOL = 1e-3        # rad: bearing tolerance of a ray hitting a segment (xpm.m)
FALSE_SURFACE_MIN = 0.05  # m: smallest see-through margin (max(3 sigma_r, 5 cm))
FIT_WINDOW = 0.2        # m: beams within this of their segment count for the fit residual
SEE_THROUGH = 0.3       # m: false-surface beams also counted apart beyond this (openings)


def segments_of(lines: Sequence) -> np.ndarray:
    """Return (S, 2, 2) [start, end] of objects with ``start`` and ``end`` (laser frame)."""
    if not len(lines):
        return np.zeros((0, 2, 2))
    return np.array([[ln.start, ln.end] for ln in lines], dtype=float).reshape(-1, 2, 2)


def ray_ranges(angles: np.ndarray, segments: np.ndarray,
               angle_tol: float = ANGLE_TOL) -> np.ndarray:
    """Return (N, S) range along each beam's ray to each segment; +inf where it misses.

    Rays start at the laser origin with bearing ``angles`` (N,); ``segments`` (S, 2, 2) are
    [start, end] in the laser frame. A ray hits a segment when its bearing is within the
    bearings of the end points (widened by ``angle_tol``); the range is that of the
    intersection with the segment's line (module docstring).
    """
    angles = np.asarray(angles, dtype=float).reshape(-1)
    seg = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    if not angles.size or not len(seg):
        return np.full((angles.size, len(seg)), np.inf)
    p, q = seg[:, 0], seg[:, 1]
    th_s = np.arctan2(p[:, 1], p[:, 0])
    dth = wrap_angle(np.arctan2(q[:, 1], q[:, 0]) - th_s)              # (S,)
    daz = np.where(dth < 0.0, -1.0, 1.0) * wrap_angle(angles[:, None] - th_s[None])
    inside = (daz >= -angle_tol) & (daz <= np.abs(dth) + angle_tol)     # (N, S)
    d = q - p
    cross_pd = p[:, 0] * d[:, 1] - p[:, 1] * d[:, 0]                    # p x d
    cross_ud = (np.cos(angles)[:, None] * d[None, :, 1]
                - np.sin(angles)[:, None] * d[None, :, 0])              # u x d
    with np.errstate(divide='ignore', invalid='ignore'):
        s = cross_pd[None] / cross_ud                                   # r u = p + t d
    hit = inside & np.isfinite(s) & (s > 0.0)
    return np.where(hit, s, np.inf)


@dataclass(frozen=True)
class RayMetrics:
    """Ray metrics of one scan against its extracted segments (module docstring).

    Attributes:
        valid: Beams with a return.
        hits: Of those, beams whose ray hits a segment.
        residuals: (hits,) measured range - range to the first hit [m].
        no_return: Beams without a return (+inf).
        no_return_clear: Of those, beams whose ray hits no segment.
        false_surface: Indices of the beams seen through a segment (increasing).
        false_surface_excess: (len(false_surface),) how far each of them was measured
            beyond the nearest segment it crossed [m] (a few cm at grazing incidence; an
            opening bridged by a line gives metres).
        fit_residuals: Perpendicular residuals of the hitting beams within ``FIT_WINDOW``
            of their first-hit segment's line [m].
        margin: A hitting beam that ends more than this in front of its first-hit segment
            is an occluder (a return from an object before the line, e.g. a lone stray
            return kept inside a wall line) [m]; the false-surface margin.

    """

    valid: int
    hits: int
    residuals: np.ndarray
    no_return: int
    no_return_clear: int
    false_surface: np.ndarray
    false_surface_excess: np.ndarray
    fit_residuals: np.ndarray
    margin: float = FALSE_SURFACE_MIN

    @property
    def f(self) -> float:
        """Fraction of the beams with a return whose ray hits a segment (PLE f)."""
        return self.hits / self.valid if self.valid else float('nan')

    @property
    def rmse(self) -> float:
        """RMS range residual of the hitting beams [m] (PLE ray RMSE); NaN without hits."""
        return (float(np.sqrt(np.mean(np.square(self.residuals)))) if self.hits
                else float('nan'))

    @property
    def occluders(self) -> int:
        """Return the hitting beams that end more than ``margin`` in front of the segment."""
        return int(np.count_nonzero(self.residuals < -self.margin))

    @property
    def rmse_without_occluders(self) -> float:
        """Ray RMSE over the hitting beams that are not occluders [m]; NaN without any."""
        kept = self.residuals[self.residuals >= -self.margin]
        return float(np.sqrt(np.mean(np.square(kept)))) if kept.size else float('nan')

    @property
    def f_no_return(self) -> float:
        """Fraction of the no-return beams whose ray hits no segment (PLE f_nr)."""
        return self.no_return_clear / self.no_return if self.no_return else float('nan')


def ray_metrics(ranges: np.ndarray, angles: np.ndarray, valid: np.ndarray,
                segments: np.ndarray, sigma_r: float = 0.01,
                no_return: Optional[np.ndarray] = None, angle_tol: float = ANGLE_TOL,
                min_margin: float = FALSE_SURFACE_MIN,
                fit_window: float = FIT_WINDOW) -> RayMetrics:
    """Score one scan's segments with the ray metrics (one numpy pass over beams x segments).

    Args:
        ranges: (N,) measured ranges [m].
        angles: (N,) beam angles [rad].
        valid: (N,) beams with a return inside [range_min, range_max].
        segments: (S, 2, 2) extracted segments [start, end], laser frame.
        sigma_r: The sensor's range noise [m] (false-surface margin ``max(3 sigma_r,
            min_margin)``).
        no_return: (N,) beams without a return; default ``ranges == +inf`` (REP 117).
        angle_tol: Bearing tolerance of a hit [rad].
        min_margin: Smallest false-surface margin [m].
        fit_window: Largest perpendicular distance counted in the fit residual [m].

    Returns:
        The scan's :class:`RayMetrics`.

    """
    r = np.asarray(ranges, dtype=float).reshape(-1)
    phi = np.asarray(angles, dtype=float).reshape(-1)
    valid = np.asarray(valid, dtype=bool).reshape(-1)
    if not r.shape == phi.shape == valid.shape:
        raise ValueError(f'ranges {r.shape}, angles {phi.shape} and valid {valid.shape} '
                         'differ in length')
    nr = np.isposinf(r) if no_return is None else np.asarray(no_return, dtype=bool)
    nr = nr & ~valid
    seg = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    cast = ray_ranges(phi, seg, angle_tol)                              # (N, S)
    first = cast.argmin(axis=1) if seg.size else np.zeros(r.size, dtype=np.int64)
    s_first = cast[np.arange(r.size), first] if seg.size else np.full(r.size, np.inf)
    hit = valid & np.isfinite(s_first)
    margin = max(3.0 * sigma_r, min_margin)
    with np.errstate(invalid='ignore'):
        excess = np.where(np.isfinite(cast), r[:, None] - cast, -np.inf).max(axis=1,
                                                                             initial=-np.inf)
    seen_through = valid & (excess > margin)
    # Fit residual: distance of the point to the first-hit segment's line.
    fit = np.zeros(0)
    if hit.any():
        p, q = seg[first[hit], 0], seg[first[hit], 1]
        d = q - p
        n = np.column_stack([-d[:, 1], d[:, 0]]) / np.hypot(d[:, 0], d[:, 1])[:, None]
        pts = r[hit, None] * np.column_stack([np.cos(phi[hit]), np.sin(phi[hit])])
        dist = np.abs(np.einsum('ij,ij->i', pts - p, n))
        fit = dist[dist <= fit_window]
    return RayMetrics(valid=int(valid.sum()), hits=int(hit.sum()),
                      residuals=r[hit] - s_first[hit], no_return=int(nr.sum()),
                      no_return_clear=int((nr & ~np.isfinite(s_first)).sum()),
                      false_surface=np.flatnonzero(seen_through),
                      false_surface_excess=excess[seen_through], fit_residuals=fit,
                      margin=margin)


# ---------------------------------------------------------------------------- baseline
def approx_poly_segments(clusters: Sequence, epsilon: float = 0.05,
                         min_points: int = 0, min_length: float = 0.0
                         ) -> Tuple[np.ndarray, np.ndarray]:
    """Return the baseline's segments: OpenCV ``approxPolyDP`` per breakpoint cluster.

    Each cluster's points (beam order) are simplified by the iterative end-point fit
    (Douglas-Peucker, ``cv2.approxPolyDP`` with ``epsilon`` and ``closed=False``); every
    pair of consecutive kept vertices is a segment, its end points being measured points.
    Segments are kept when they span at least ``min_points`` beams (end points included)
    and ``min_length`` metres (the extractors' minimum size restricts the baseline).

    Args:
        clusters: Clusters of one scan (:func:`landmark_nav.laser.segmentation.segment_scan`).
        epsilon: Largest distance of a point to its segment [m].
        min_points: Fewest beams of a kept segment.
        min_length: Shortest kept segment [m].

    Returns:
        ((S, 2, 2) segments [start, end], (S, 2) first and last beam index).

    """
    import cv2

    segs, idx = [], []
    for cl in clusters:
        if len(cl) < 2:
            continue
        pts = np.ascontiguousarray(cl.points, dtype=np.float32)
        verts = cv2.approxPolyDP(pts.reshape(-1, 1, 2), epsilon, False).reshape(-1, 2)
        # approxPolyDP returns a subset of the input points, in order: find their indices.
        same = (pts[None, :, :] == verts[:, None, :]).all(axis=2)       # (M, K)
        k = np.maximum.accumulate(same.argmax(axis=1))
        a, b = k[:-1], k[1:]
        keep = (b > a) & (b - a + 1 >= min_points)
        p0, p1 = cl.points[a[keep]], cl.points[b[keep]]
        long_enough = np.hypot(*(p1 - p0).T) >= min_length
        segs.append(np.stack([p0, p1], axis=1)[long_enough])
        idx.append(np.column_stack([cl.indices[a[keep]], cl.indices[b[keep]]])[long_enough])
    if not segs:
        return np.zeros((0, 2, 2)), np.zeros((0, 2), dtype=np.int64)
    return np.concatenate(segs).reshape(-1, 2, 2), np.concatenate(idx).astype(np.int64)


# ---------------------------------------------------------------------------- repeatability
@dataclass(frozen=True)
class MetricScan:
    """One scan for the truth-free metrics, and what it saw for :func:`in_view`.

    Attributes:
        ranges: (N,) ranges [m].
        angles: (N,) beam angles [rad], evenly spaced.
        valid: (N,) beams with a return in [range_min, range_max].
        no_return: (N,) beams without a return (REP 117 +inf).
        range_min: Closest valid range [m].
        range_max: Farthest valid range [m].
        pose: (3,) laser pose in the map frame (reference pose composed with the mount),
            or None without a reference (no repeatability).

    """

    ranges: np.ndarray
    angles: np.ndarray
    valid: np.ndarray
    no_return: np.ndarray
    range_min: float
    range_max: float
    pose: Optional[np.ndarray] = None

    @property
    def angle_increment(self) -> float:
        """Beam spacing [rad]."""
        return float(self.angles[1] - self.angles[0]) if len(self.angles) > 1 else 0.0


def in_view(view: MetricScan, points_map: np.ndarray, margin: float = 0.1,
            surface: bool = False) -> np.ndarray:
    """Return (M,) True for map points that the scan ``view`` could see.

    A point is in view when its bearing lies inside the scan's field of view (half a beam
    beyond the first and last beam), its distance inside [range_min, range_max], and the
    beam nearest to its bearing is not occluded in front of it: that beam returned at least
    ``distance - margin`` away, or returned nothing (no return: nothing in the way). Beams
    with an error reading decide nothing (not in view).

    With ``surface`` the point must also be on a surface the scan saw: the beam nearest to
    its bearing returned within ``margin`` of its distance (not beyond it, not nothing).
    This is the rule for corners, which are points on surfaces: a beam that passes the
    corner's place and returns metres further, or returns nothing, shows that the scan
    did not see a surface there, so the corner could not be re-detected in it. Lines keep
    the rule without ``surface`` (their midpoint's beam may pass a line's end).

    Raises:
        ValueError: ``view`` has no pose.
    """
    if view.pose is None:
        raise ValueError("in_view needs the scan's pose (MetricScan.pose is None)")
    pts = inverse_transform_points(view.pose, np.asarray(points_map, dtype=float)
                                   ).reshape(-1, 2)
    n = len(view.angles)
    if not len(pts) or not n:
        return np.zeros(len(pts), dtype=bool)
    dist = np.hypot(pts[:, 0], pts[:, 1])
    bearing = np.arctan2(pts[:, 1], pts[:, 0])
    inc = float(view.angles[1] - view.angles[0]) if n > 1 else 1.0
    k = np.rint((bearing - view.angles[0]) / inc).astype(np.int64)
    inside = (k >= 0) & (k < n) & (dist >= view.range_min) & (dist <= view.range_max)
    k = np.clip(k, 0, n - 1)
    seen = np.where(view.valid, view.ranges, np.where(view.no_return, np.inf, np.nan))
    with np.errstate(invalid='ignore'):
        clear = seen[k] >= dist - margin
        if surface:
            clear &= seen[k] <= dist + margin
    return inside & clear


@dataclass
class Repeatability:
    """Re-detections over opportunities, accumulated over consecutive scan pairs."""

    opportunities: int = 0
    redetected: int = 0
    unobserved: int = 0
    unobserved_redetected: int = 0

    @property
    def fraction(self) -> float:
        """Re-detected / opportunities (NaN without opportunities)."""
        return self.redetected / self.opportunities if self.opportunities else float('nan')

    @property
    def fraction_with_unobserved(self) -> float:
        """Re-detected / opportunities, the unobserved ones counted too (the former rule)."""
        n = self.opportunities + self.unobserved
        return (self.redetected + self.unobserved_redetected) / n if n else float('nan')


def line_opportunities(segments_k: np.ndarray, pose_k: np.ndarray, view_next: MetricScan,
                       min_length: float = 1.0, margin: float = 0.1
                       ) -> Tuple[np.ndarray, np.ndarray]:
    """Return the scan-k segments that are re-detection opportunities in scan k+1.

    A segment (laser frame, laser pose ``pose_k`` in the map) at least ``min_length`` long
    whose midpoint is in view of scan k+1 (:func:`in_view`).

    Returns:
        ``(index (A,) into segments_k, their endpoints in the map (A, 2, 2))``.
    """
    seg_k = np.asarray(segments_k, dtype=float).reshape(-1, 2, 2)
    index = np.flatnonzero(np.hypot(*(seg_k[:, 1] - seg_k[:, 0]).T) >= min_length)
    if not index.size:
        return index, np.zeros((0, 2, 2))
    world = transform_points(pose_k, seg_k[index].reshape(-1, 2)).reshape(-1, 2, 2)
    look = in_view(view_next, world.mean(axis=1), margin)
    return index[look], world[look]


def line_repeatability(score: Repeatability, segments_k: np.ndarray, pose_k: np.ndarray,
                       segments_next: np.ndarray, view_next: MetricScan,
                       min_length: float = 1.0, max_drho: float = 0.05,
                       max_dalpha: float = math.radians(2.0), margin: float = 0.1) -> None:
    """Add the line re-detections from scan k to scan k+1 to ``score``.

    Every segment of scan k (laser frame, laser pose ``pose_k`` in the map) at least
    ``min_length`` long whose midpoint is in view of scan k+1 (:func:`in_view`) is an
    opportunity; it is re-detected when some segment of scan k+1 (any length) has
    ``|d rho| <= max_drho`` and ``|d alpha| <= max_dalpha`` and their extents overlap
    (projected on the scan-k segment). Both are compared in the laser frame of scan k+1:
    the map frame moved to the sensor, so that rho carries no lever arm of a far-away map
    origin.
    """
    index, world = line_opportunities(segments_k, pose_k, view_next, min_length, margin)
    score.opportunities += int(index.size)
    if not index.size:
        return
    mine = inverse_transform_points(view_next.pose, world.reshape(-1, 2)).reshape(-1, 2, 2)
    other = np.asarray(segments_next, dtype=float).reshape(-1, 2, 2)
    if not len(other):
        return
    f_k = normal_form(mine[:, 0], mine[:, 1])                          # (A, 2)
    f_n = normal_form(other[:, 0], other[:, 1])                        # (B, 2)
    close = ((np.abs(f_k[:, None, 0] - f_n[None, :, 0]) <= max_drho)
             & (np.abs(wrap_angle(f_k[:, None, 1] - f_n[None, :, 1])) <= max_dalpha))
    d = mine[:, 1] - mine[:, 0]                                          # (A, 2)
    length2 = np.einsum('ij,ij->i', d, d)[:, None]
    t0 = np.einsum('bj,aj->ab', other[:, 0], d) - np.einsum('aj,aj->a', mine[:, 0], d)[:, None]
    t1 = np.einsum('bj,aj->ab', other[:, 1], d) - np.einsum('aj,aj->a', mine[:, 0], d)[:, None]
    lo, hi = np.minimum(t0, t1) / length2, np.maximum(t0, t1) / length2
    overlap = (hi > 0.0) & (lo < 1.0)
    score.redetected += int((close & overlap).any(axis=1).sum())


ARM_PROBE = 0.15  # m: arm points probed for corner observability (detector's arm_length)


def corner_observable(view: MetricScan, corners_map: np.ndarray,
                      arm_angles_map: Optional[np.ndarray] = None, margin: float = 0.1,
                      arm_probe: float = ARM_PROBE) -> np.ndarray:
    """Return (C,) True for corners (map frame) that the scan ``view`` could re-detect.

    The corner's place must be seen (:func:`in_view` with ``surface``: inside the field of
    view and range, not occluded, its beam returning within ``margin`` of its distance),
    and with ``arm_angles_map`` ((C, 2) directions of the two arms from the corner, map
    frame [rad]) also the point ``arm_probe`` (the detector's smallest arm) along each arm.
    A corner is two surfaces meeting; when one of them left the field of view, is hidden
    or returned nothing in the next scan, no detector can find the corner there.
    """
    c = np.asarray(corners_map, dtype=float).reshape(-1, 2)
    ok = in_view(view, c, margin, surface=True)
    if arm_angles_map is None or not len(c):
        return ok
    ang = np.asarray(arm_angles_map, dtype=float).reshape(-1, 2)
    probe = c[:, None] + arm_probe * np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    seen = in_view(view, probe.reshape(-1, 2), margin, surface=True).reshape(-1, 2)
    return ok & seen.all(axis=1)


def corner_repeatability(score: Repeatability, corners_k: np.ndarray, pose_k: np.ndarray,
                         corners_next: np.ndarray, view_next: MetricScan,
                         max_distance: float = 0.1, margin: float = 0.1,
                         wedges_k: Optional[np.ndarray] = None) -> None:
    """Add the corner re-detections from scan k to scan k+1 to ``score``.

    Every corner of scan k ((C, 2) laser frame; laser pose ``pose_k``) that scan k+1 could
    observe (:func:`corner_observable`: its place seen, its beam returning within
    ``margin`` of its distance; with ``wedges_k`` also both arms near it) is an
    opportunity. ``wedges_k`` (C, 2) holds each corner's ``[bisector, opening]`` (laser
    frame of scan k, as :class:`~landmark_nav.laser.corners.Corner` and the
    ``corners/features`` cloud carry them): the arms run along ``bisector +- opening / 2``.
    An opportunity is re-detected when a corner of scan k+1 lies within ``max_distance``
    of it in the map frame. Corners in view by the line rule (:func:`in_view`: the beam
    toward them not occluded) that are not observable are counted apart in
    ``score.unobserved`` (their re-detections in ``score.unobserved_redetected``);
    :attr:`Repeatability.fraction_with_unobserved` is the figure of the former rule,
    which counted them.
    """
    c_k = np.asarray(corners_k, dtype=float).reshape(-1, 2)
    if not len(c_k):
        return
    world = transform_points(pose_k, c_k).reshape(-1, 2)
    arm_angles = None
    if wedges_k is not None:
        wedge = np.asarray(wedges_k, dtype=float).reshape(-1, 2)
        half = 0.5 * wedge[:, 1:2] * np.array([1.0, -1.0])
        arm_angles = float(pose_k[2]) + wedge[:, :1] + half
    look_any = in_view(view_next, world, margin)
    look = look_any & corner_observable(view_next, world, arm_angles, margin)
    unseen = look_any & ~look
    score.opportunities += int(look.sum())
    score.unobserved += int(unseen.sum())
    c_n = np.asarray(corners_next, dtype=float).reshape(-1, 2)
    if not look_any.any() or not len(c_n):
        return
    other = transform_points(view_next.pose, c_n).reshape(-1, 2)
    dist = np.hypot(*(world[:, None, :] - other[None]).transpose(2, 0, 1)).min(axis=1)
    near = dist <= max_distance
    score.redetected += int((near & look).sum())
    score.unobserved_redetected += int((near & unseen).sum())


# ---------------------------------------------------------------------------- runner
BASELINE = 'approxPolyDP'
BASELINE_MIN = 'approxPolyDP_min_size'


def sample_scans(n: int, count: int, seed: int) -> np.ndarray:
    """Return the sorted indices of ``count`` of ``n`` scans drawn without replacement.

    ``numpy.random.default_rng(seed).choice(n, min(count, n), replace=False)``: the scans
    of the PLE figures (issue protocol: 20 scans, seed 0).
    """
    rng = np.random.default_rng(seed)
    return np.sort(rng.choice(n, size=min(count, n), replace=False))


class _LineTally:
    """Truth-free line figures of one method over a run."""

    def __init__(self) -> None:
        self.f: List[float] = []
        self.rmse: List[float] = []
        self.rmse_open: List[float] = []  # without occluders
        self.occluders = 0
        self.hits = 0
        self.f_nr: List[float] = []
        self.fit: List[np.ndarray] = []
        self.fs_sample = 0
        self.fs_beams = 0
        self.fs_far = 0
        self.fs_far_scans = 0
        self.fs_scans: List[Tuple[int, List[int]]] = []
        self.repeat = Repeatability()
        self.times: List[float] = []
        self.count = 0

    def add(self, k: int, m: RayMetrics, sampled: bool) -> None:
        n_fs = int(m.false_surface.size)
        self.fs_beams += n_fs
        far = int((m.false_surface_excess > SEE_THROUGH).sum())
        self.fs_far += far
        self.fs_far_scans += bool(far)
        if n_fs:
            self.fs_scans.append((k, [int(i) for i in m.false_surface]))
        if sampled:
            self.fs_sample += n_fs
            self.f.append(m.f)
            self.rmse.append(m.rmse)
            self.rmse_open.append(m.rmse_without_occluders)
            self.occluders += m.occluders
            self.hits += m.hits
            self.f_nr.append(m.f_no_return)
            self.fit.append(m.fit_residuals)

    def figures(self, scans: int) -> dict:
        fit = np.concatenate(self.fit) if self.fit else np.zeros(0)
        rmse = np.asarray(self.rmse, dtype=float)
        rmse = rmse[np.isfinite(rmse)]
        rmse_open = np.asarray(self.rmse_open, dtype=float)
        rmse_open = rmse_open[np.isfinite(rmse_open)]
        f_nr = np.asarray(self.f_nr, dtype=float)
        f_nr = f_nr[np.isfinite(f_nr)]
        return {
            'f': float(np.mean(self.f)) if self.f else float('nan'),
            'ray_rmse_mean_m': float(rmse.mean()) if rmse.size else float('nan'),
            'ray_rmse_median_m': float(np.median(rmse)) if rmse.size else float('nan'),
            'ray_rmse_no_occluders_mean_m': (float(rmse_open.mean()) if rmse_open.size
                                             else float('nan')),
            'ray_rmse_no_occluders_median_m': (float(np.median(rmse_open)) if rmse_open.size
                                               else float('nan')),
            'occluder_beams_sample': self.occluders,
            'hit_beams_sample': self.hits,
            'f_no_return': float(f_nr.mean()) if f_nr.size else float('nan'),
            'fit_rms_m': float(np.sqrt(np.mean(fit ** 2))) if fit.size else float('nan'),
            'fit_beams': int(fit.size),
            'false_surface_beams_sample': self.fs_sample,
            'false_surface_beams': self.fs_beams,
            'false_surface_scans': len(self.fs_scans),
            'false_surface_beams_over_30cm': self.fs_far,
            'false_surface_scans_over_30cm': self.fs_far_scans,
            'false_surface_list': [[k, b] for k, b in self.fs_scans],
            'line_opportunities': self.repeat.opportunities,
            'line_redetected': self.repeat.redetected,
            'line_repeatability': self.repeat.fraction,
            'segments_per_scan': self.count / scans if scans else float('nan'),
            'median_ms_per_scan': 1e3 * float(np.median(self.times)) if self.times else None,
            'mean_ms_per_scan': 1e3 * float(np.mean(self.times)) if self.times else None}


def evaluate_scans(scans: Sequence[MetricScan], sigma_r: float = 0.01,
                   ple_scans: int = 20, seed: int = 0,
                   corner_methods: Sequence[str] = ('minus_cosine', 'sliding_window',
                                                    'split_merge'),
                   line_methods: Sequence[str] = ('split_merge', 'alfa'),
                   extractor_sigma_r: Union[None, float, str, Mapping] = None,
                   progress: Optional[str] = None,
                   configs: Optional[Mapping[str, object]] = None,
                   line_gate: Tuple[float, float] = (0.05, math.radians(2.0))) -> dict:
    """Score the extractors and the baseline on real scans with the truth-free metrics.

    Every method runs on every scan with its node's configuration (``configs``: the
    ``corner_extractor`` and ``line_extractor``
    :class:`~landmark_nav.laser.extractor_configuration.ExtractorConfiguration`, default
    the node defaults; ``method`` and ``sigma_r`` set per row and by
    ``extractor_sigma_r``) on its node's segmentation, shared by the nodes whose settings
    agree and counted in each method's time. The
    PLE figures (f, ray RMSE mean and median over scans, f_no_return, fit residual) come
    from ``ple_scans`` scans drawn by :func:`sample_scans` with ``seed``; false-surface
    beams are counted on every scan (and on the sample); repeatability is over every
    pair of consecutive scans that both have a reference pose. The baseline
    (:func:`approx_poly_segments`, epsilon 5 cm) is reported in full and restricted to the
    line extractor's minimum size (``min_points``, ``min_length``).

    Args:
        scans: The scans, in time order.
        sigma_r: The sensor's range noise [m] (false-surface margin).
        ple_scans: Scans drawn for the PLE figures.
        seed: Seed of the draw.
        corner_methods: Corner detectors.
        line_methods: Line extractors.
        extractor_sigma_r: Range noise the extractors and the segmentation assume [m]
            (one value, or one per node name); None: the configuration's ``sigma_r``
            (the node default 0.01 m); ``'auto'``: estimated from the scans with
            ``sigma_r`` as its lower bound
            (:func:`landmark_nav.laser.range_noise.estimate_range_noise`, stated in the
            result's ``extractor_sigma_r_estimate``); the false-surface margin then uses
            the estimate too (the sensor's noise as its data shows it), and the line
            extractors' gates the rounding it finds (``LineParams.range_step``).
        progress: Label of a tqdm progress bar, or None for none.
        configs: The nodes' configurations by node name (see above).
        line_gate: ``(max_drho [m], max_dalpha [rad])`` of :func:`line_repeatability`.

    Returns:
        {'scans', 'ple_scans', 'sample', 'sigma_r', 'extractor_sigma_r' (the line
        extractor's), 'corner_sigma_r',
        (corner figures per class: ``corner_repeatability_structural`` / ``_other``, with
        their opportunities and re-detections, and ``structural_share``),
        'extractor_sigma_r_estimate' (the estimate's figures, or None), 'repeat_pairs',
        'lines': {method: figures}, 'corners': {method: figures}}; without a pair of
        consecutive scans with poses (no reference) the repeatability figures are None.

    """
    from landmark_nav.laser.corners import detect_corners
    from landmark_nav.laser.extractor_configuration import (extractor_configuration,
                                                            ScanSegmenter)
    from landmark_nav.laser.lines import extract_lines

    nodes = ('corner_extractor', 'line_extractor')
    configs = {n: (configs or {}).get(n) or extractor_configuration(n) for n in nodes}
    spec = (dict(extractor_sigma_r) if isinstance(extractor_sigma_r, Mapping)
            else dict.fromkeys(nodes, extractor_sigma_r))
    estimate = None
    if 'auto' in spec.values():
        from landmark_nav.laser.range_noise import estimate_range_noise
        estimate = estimate_range_noise(((s.ranges, s.angles, s.valid) for s in scans),
                                        stated=sigma_r)
        sigma_r = estimate.sigma_r  # the noise the data shows, for the margin too
    ext = {n: (configs[n].params.sigma_r if spec.get(n) is None else estimate.sigma_r
               if spec[n] == 'auto' else float(spec[n])) for n in nodes}
    segmenters = {kind: ScanSegmenter(c.incidence_deg, c.min_points, ext[c.node],
                                      c.sigma_r_from_data, c.sigma_r_scans)
                  for kind, c in (('corners', configs['corner_extractor']),
                                  ('lines', configs['line_extractor']))}
    line_base = configs['line_extractor'].params
    rounding = {}  # the readings' rounding, for the gates of an estimated noise
    if spec.get('line_extractor') == 'auto':
        rounding = {'range_step': estimate.step, 'range_step_share': estimate.step_share}
    line_params = {m: replace(line_base, method=m, sigma_r=ext['line_extractor'], **rounding)
                   for m in line_methods}
    corner_params = {m: replace(configs['corner_extractor'].params, method=m,
                                sigma_r=ext['corner_extractor']) for m in corner_methods}
    min_points, min_length = line_base.min_points, line_base.min_length
    sample = {int(i) for i in sample_scans(len(scans), ple_scans, seed)}
    tallies = {m: _LineTally() for m in (*line_methods, BASELINE, BASELINE_MIN)}
    c_repeat = {m: Repeatability() for m in corner_methods}
    c_class = {m: (Repeatability(), Repeatability()) for m in corner_methods}  # structural, other
    c_structural = dict.fromkeys(corner_methods, 0)
    c_times = {m: [] for m in corner_methods}
    c_count = dict.fromkeys(corner_methods, 0)
    prev = None  # (scan, {method: segments}, {method: corners})
    pairs = 0
    items = enumerate(scans)
    if progress:
        from tqdm import tqdm
        items = tqdm(items, total=len(scans), unit='scan', desc=progress)
    for k, scan in items:
        segmented = segment_per_extractor(segmenters, scan.ranges, scan.angles, scan.valid,
                                          scan.angle_increment)
        clusters, t_seg = segmented['lines']
        segs: Dict[str, np.ndarray] = {}
        for m, params in line_params.items():
            t0 = time.perf_counter()
            lines = extract_lines(clusters, segmenters['lines'].at_scan_noise(params))
            tallies[m].times.append(t_seg + time.perf_counter() - t0)
            segs[m] = segments_of(lines)
        t0 = time.perf_counter()
        base, idx = approx_poly_segments(clusters, 0.05)
        tallies[BASELINE].times.append(t_seg + time.perf_counter() - t0)
        tallies[BASELINE_MIN].times.append(tallies[BASELINE].times[-1])
        segs[BASELINE] = base
        size_ok = ((idx[:, 1] - idx[:, 0] + 1 >= min_points)
                   & (np.hypot(*(base[:, 1] - base[:, 0]).T) >= min_length))
        segs[BASELINE_MIN] = base[size_ok]
        corners: Dict[str, Tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        c_clusters, c_seg = segmented['corners']
        for m, params in corner_params.items():
            t0 = time.perf_counter()
            found = detect_corners(c_clusters, segmenters['corners'].at_scan_noise(params))
            c_times[m].append(c_seg + time.perf_counter() - t0)
            corners[m] = (np.array([c.position for c in found]).reshape(-1, 2),
                          np.array([[c.bisector, c.opening] for c in found]).reshape(-1, 2),
                          np.array([c.structural for c in found], dtype=bool))
            c_count[m] += len(found)
            c_structural[m] += int(corners[m][2].sum())
        for m, tally in tallies.items():
            tally.count += len(segs[m])
            tally.add(k, ray_metrics(scan.ranges, scan.angles, scan.valid, segs[m], sigma_r,
                                     scan.no_return), k in sample)
        if prev is not None and prev[0].pose is not None and scan.pose is not None:
            pairs += 1
            for m, tally in tallies.items():
                line_repeatability(tally.repeat, prev[1][m], prev[0].pose, segs[m], scan,
                                   max_drho=line_gate[0], max_dalpha=line_gate[1])
            for m in corner_methods:
                pos, wedge, label = prev[2][m]
                corner_repeatability(c_repeat[m], pos, prev[0].pose, corners[m][0], scan,
                                     wedges_k=wedge)
                for score, keep in zip(c_class[m], (label, ~label)):
                    corner_repeatability(score, pos[keep], prev[0].pose, corners[m][0], scan,
                                         wedges_k=wedge[keep])
        prev = (scan, segs, corners)
    n = len(scans)
    lines = {m: t.figures(n) for m, t in tallies.items()}
    if not pairs:  # no reference poses: no repeatability (None, not NaN: JSON null)
        for f in lines.values():
            f['line_repeatability'] = None
    return {
        'scans': n, 'ple_scans': len(sample), 'sample': sorted(sample), 'seed': seed,
        'sigma_r': sigma_r, 'extractor_sigma_r': ext['line_extractor'],
        'corner_sigma_r': ext['corner_extractor'], 'repeat_pairs': pairs,
        'extractor_sigma_r_estimate': None if estimate is None else asdict(estimate),
        'false_surface_margin_m': max(3.0 * sigma_r, FALSE_SURFACE_MIN),
        'lines': lines,
        'corners': {m: {
            'corner_opportunities': c_repeat[m].opportunities,
            'corner_redetected': c_repeat[m].redetected,
            'corner_repeatability': c_repeat[m].fraction if pairs else None,
            'corner_unobserved': c_repeat[m].unobserved,
            'corner_unobserved_redetected': c_repeat[m].unobserved_redetected,
            'corner_repeatability_with_unobserved': (
                c_repeat[m].fraction_with_unobserved if pairs else None),
            'corner_repeatability_structural': c_class[m][0].fraction if pairs else None,
            'corner_opportunities_structural': c_class[m][0].opportunities,
            'corner_redetected_structural': c_class[m][0].redetected,
            'corner_repeatability_other': c_class[m][1].fraction if pairs else None,
            'corner_opportunities_other': c_class[m][1].opportunities,
            'corner_redetected_other': c_class[m][1].redetected,
            'structural_share': c_structural[m] / c_count[m] if c_count[m] else float('nan'),
            'corners_per_scan': c_count[m] / n if n else float('nan'),
            'median_ms_per_scan': 1e3 * float(np.median(c_times[m])) if c_times[m] else None,
            'mean_ms_per_scan': 1e3 * float(np.mean(c_times[m])) if c_times[m] else None}
            for m in corner_methods}}
