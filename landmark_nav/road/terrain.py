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

Pure numpy (and scipy.special for the F-test); the node is
:mod:`landmark_nav.nodes.road_classifier`.
"""

import bisect
from dataclasses import dataclass, field
import functools
import math
from typing import Optional, Sequence

import numpy as np
from scipy.special import fdtri

#: Reading classes (the chapter's C_0, C_t, C_n).
INVALID = 0
TRAVERSABLE = 1
NOT_TRAVERSABLE = 2


@dataclass(frozen=True)
class LaserMount:
    """Pose of the laser frame in ``base_link`` (REP 103; pitch > 0 tilts the scan down).

    ``z`` is the height of the laser above the ground plane under the robot.
    """

    x: float = 0.3
    y: float = 0.0
    z: float = 0.6
    roll: float = 0.0
    pitch: float = math.radians(14.0)
    yaw: float = 0.0

    def __post_init__(self) -> None:
        """Check that every field is finite and the laser is above the ground."""
        for name in ('x', 'y', 'z', 'roll', 'pitch', 'yaw'):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f'laser mount {name} must be finite; got {value!r}')
        if not self.z > 0.0:
            raise ValueError(f'laser mount z (height above the ground) must be > 0; '
                             f'got {self.z!r}')

    @classmethod
    def from_sequence(cls, values: Sequence[float]) -> 'LaserMount':
        """Build from ``[x, y, z, roll, pitch, yaw]``."""
        if len(values) != 6:
            raise ValueError(f'laser mount needs 6 values (x, y, z, roll, pitch, yaw); '
                             f'got {len(values)}')
        return cls(*(float(v) for v in values))

    def rotation(self) -> np.ndarray:
        """Return R = Rz(yaw) Ry(pitch) Rx(roll), laser frame -> base_link."""
        cr, sr = math.cos(self.roll), math.sin(self.roll)
        cp, sp = math.cos(self.pitch), math.sin(self.pitch)
        cy, sy = math.cos(self.yaw), math.sin(self.yaw)
        rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
        ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
        rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
        return rz @ ry @ rx

    def translation(self) -> np.ndarray:
        """Return the laser origin in ``base_link``."""
        return np.array([self.x, self.y, self.z])

    def ground_range(self, angles: np.ndarray) -> np.ndarray:
        """Range at which each beam meets a flat ground plane z = 0 (inf if it never does)."""
        d = self.rotation() @ np.vstack([np.cos(angles), np.sin(angles), np.zeros_like(angles)])
        with np.errstate(divide='ignore'):
            r = np.where(d[2] < -1e-9, -self.z / np.minimum(d[2], -1e-12), np.inf)
        return r


@dataclass(frozen=True)
class TerrainParams:
    """Thresholds of the feature functions (lengths in metres)."""

    window: float = 0.45
    roughness_max: float = 0.013
    step_max: float = 0.04
    height_max: float = 0.3
    split_rms: float = 0.008
    rough_ratio: float = 1.5
    rough_alpha: float = 0.05
    range_sigma: float = 0.005
    slope_max: float = 0.25
    curvature_max: float = 0.6
    min_width: float = 0.5
    gap_max: float = 0.15
    obstacle_height: float = 0.12
    obstacle_depth: float = 0.06
    min_points: int = 5

    def __post_init__(self) -> None:
        """Check the ranges."""
        for name in ('window', 'roughness_max', 'step_max', 'height_max', 'split_rms',
                     'range_sigma',
                     'slope_max', 'curvature_max', 'min_width', 'obstacle_height',
                     'obstacle_depth'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'terrain {name} must be > 0; got {value!r}')
        if not (math.isfinite(self.gap_max) and self.gap_max >= 0.0):
            raise ValueError(f'terrain gap_max must be >= 0; got {self.gap_max!r}')
        if not self.rough_ratio >= 1.0:
            raise ValueError(f'terrain rough_ratio must be >= 1; got {self.rough_ratio!r}')
        if self.min_points < 3:
            raise ValueError(f'terrain min_points must be >= 3; got {self.min_points!r}')


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


def scan_points(ranges: np.ndarray, angles: np.ndarray, mount: LaserMount) -> np.ndarray:
    """Place the readings in base_link: (N, 3) [m]; non-finite ranges give NaN rows."""
    r = np.asarray(ranges, dtype=float)
    a = np.asarray(angles, dtype=float)
    local = np.vstack([r * np.cos(a), r * np.sin(a), np.zeros_like(r)])
    return (mount.rotation() @ local).T + mount.translation()


def _window_bounds(s: np.ndarray, lo_off: float, hi_off: float) -> tuple[np.ndarray, ...]:
    """Index ranges [lo, hi) of the readings with s in [s_i + lo_off, s_i + hi_off]."""
    lo = np.searchsorted(s, s + lo_off, side='left')
    hi = np.searchsorted(s, s + hi_off, side='right')
    return lo, hi


def _moments(u: np.ndarray, v: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Windowed count, means and central second moments of (u, v)."""
    cs = np.zeros((5, u.size + 1))
    np.cumsum(np.vstack([u, v, u * u, v * v, u * v]), axis=1, out=cs[:, 1:])
    su, sv, suu, svv, suv = cs[:, hi] - cs[:, lo]
    n = (hi - lo).astype(float)
    with np.errstate(invalid='ignore', divide='ignore'):
        mu, mv = su / n, sv / n
        cuu = suu / n - mu * mu
        cvv = svv / n - mv * mv
        cuv = suv / n - mu * mv
    return n, cuu, cvv, cuv


def _roughness(plane: np.ndarray, s: np.ndarray, window: float, min_points: int) -> np.ndarray:
    """F_sigma: rms distance to the total-least-squares line over ``window`` of path length."""
    lo, hi = _window_bounds(s, -0.5 * window, 0.5 * window)
    # Centre the coordinates for numerical accuracy of the running sums.
    u = plane[:, 0] - plane[:, 0].mean()
    v = plane[:, 1] - plane[:, 1].mean()
    n, cuu, cvv, cuv = _moments(u, v, lo, hi)
    tr = cuu + cvv
    det = cuu * cvv - cuv * cuv
    smallest = 0.5 * tr - np.sqrt(np.maximum(0.25 * tr * tr - det, 0.0))
    out = np.sqrt(np.maximum(smallest, 0.0))
    out[n < min_points] = np.inf
    return out


def _orthogonal_sums(m) -> tuple:
    """Centred sums of the basis 1, t, t^2 orthogonalised by Gram-Schmidt, from raw sums.

    ``m`` rows: sums of t^0..t^4, z, z t, z t^2 (one column per piece; arrays or floats).
    Returns ``(mean t, mean z, mean t^2, Sxx, Sxz, beta, Rt, Rz)``: ``Sxx``, ``Sxz`` the
    centred sums of t t and t z; ``beta = Sxt2 / Sxx`` the share of t^2 along t;
    ``phi2 = t^2 - mean t^2 - beta (t - mean t)`` the part of t^2 orthogonal to 1 and t,
    ``Rt`` its sum of squares and ``Rz`` its sum against z.
    """
    s0, s1, s2, s3, s4, b0, b1, b2 = m[:8]
    mt, mz, m2 = s1 / s0, b0 / s0, s2 / s0
    sxx = s2 - s1 * mt
    sxz = b1 - s1 * mz
    sxq = s3 - s2 * mt                                # t^2 against t, centred
    beta = sxq / sxx
    rt = s4 - s2 * m2 - beta * sxq
    rz = b2 - s2 * mz - beta * sxz
    return mt, mz, m2, sxx, sxz, beta, rt, rz


def _explained(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Explained sums of squares of least-squares lines and quadratics z(t) from sums.

    ``m`` rows: sums of t^0..t^4, z, z t, z t^2 (one column per piece). The basis 1, t, t^2
    is orthogonalised (:func:`_orthogonal_sums`): the line explains
    ``(sum z)^2 / n + Sxz^2 / Sxx`` (centred sums), the quadratic that plus the share of
    the part of t^2 that the line does not explain, ``Rz^2 / Rt``. The SSE of a piece is
    ``sum z^2`` minus this. Degenerate pieces (fewer readings than coefficients) give
    inf or NaN: the caller masks them.
    """
    _, mz, _, sxx, sxz, _, rt, rz = _orthogonal_sums(m)
    line = m[5] * mz + sxz * sxz / sxx
    return line, line + rz * rz / rt


def _poly_sse(m: np.ndarray, degree: int) -> np.ndarray:
    """SSE of least-squares lines (1) or quadratics (2) z(t) from their sums (closed form).

    ``m`` rows: sums of t^0..t^4, z, z t, z t^2, z^2 (one column per piece); pieces with
    no more readings than coefficients get 0.
    """
    with np.errstate(divide='ignore', invalid='ignore'):
        fit = _explained(m)[degree - 1]
    sse = np.maximum(m[8] - fit, 0.0)
    return np.where(m[0] > degree + 1.5, sse, 0.0)


def _piece_nll(sse: np.ndarray, n: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Gaussian negative log-likelihood of pieces with their own variance (ML, floored).

    ``v = max(SSE / n, floor)``; ``NLL = (n log v + SSE / v) / 2`` (constants dropped): the
    floor is the sensor's height noise, so a piece is never smoother than the laser.
    """
    with np.errstate(divide='ignore', invalid='ignore'):
        v = np.maximum(sse / np.maximum(n, 1), floor)
        return 0.5 * (n * np.log(v) + sse / v)


def _segment_profile(first: int, last: int, table: np.ndarray, params: TerrainParams,
                     out: list) -> None:
    """Split a stretch of readings where the height profile or its roughness changes.

    Each piece is a quadratic height profile ``z = a + b s + c s^2`` (slope ``F_t``,
    curvature ``F_c``) with its own residual variance (roughness ``F_sigma``), floored by
    the sensor's height noise ``var0``. Binary segmentation: the best split point
    maximises the log-likelihood gain of two such pieces over one (computed for every
    reading from prefix sums, so the edge falls on the reading where the profile bends or
    the roughness changes, not on a window's end); it is kept when the gain exceeds the
    Bayesian information criterion's penalty for the extra piece (3 coefficients, a
    variance and the split point: ``5/2 ln n``). :func:`_merge_pieces` then rejoins the
    neighbours that do not differ physically.

    :func:`classify_scan` uses :func:`_segment_profiles`, the same pieces from fewer numpy
    calls; this one-split-at-a-time form is its reference (and the tests' oracle).
    """
    best, gain = _best_split(first, last, table, params)
    if best is None or gain <= 2.5 * math.log(last - first + 1):
        out.append((first, last))
        return
    _segment_profile(first, best - 1, table, params, out)
    _segment_profile(best, last, table, params, out)


def _moment_table(s: np.ndarray, z: np.ndarray, var0: np.ndarray) -> np.ndarray:
    """Prefix sums (with a leading zero column) of t^0..t^4, z t^0..t^2, z^2 and ``var0``.

    ``t`` is ``s`` about the stretch's middle; the sums over readings [a, b) of the stretch
    are ``table[:, b] - table[:, a]``.
    """
    t = s - 0.5 * (s[0] + s[-1])
    t2 = t * t
    rows = np.vstack([np.ones_like(t), t, t2, t2 * t, t2 * t2, z, z * t, z * t2, z * z, var0])
    return np.concatenate([np.zeros((10, 1)), np.cumsum(rows, axis=1)], axis=1)


def _best_split(first: int, last: int, table: np.ndarray,
                params: TerrainParams) -> tuple[Optional[int], float]:
    """Return the reading that starts the second of the best two pieces, and the gain.

    ``first`` and ``last`` index the stretch of :func:`_moment_table`.
    """
    n = last - first + 1
    if n < 2 * params.min_points:
        return None, -math.inf
    cum = table[:, first:last + 2] - table[:, first:first + 1]       # sums over [0, k)
    k = np.arange(n + 1)
    # Each piece is a quadratic (a crowned road) or a line (a flat shoulder, a verge: one
    # parameter fewer, 1/2 ln n less penalty), which locates a kink sharply.
    half = 0.5 * math.log(n)
    m = np.concatenate([cum, cum[:, -1:] - cum], axis=1)        # [0, k) then [k, n)
    cnt = m[0]
    with np.errstate(divide='ignore', invalid='ignore'):
        floor = m[9] / cnt
    nll = np.minimum(_piece_nll(_poly_sse(m, 2), cnt, floor) + half,
                     _piece_nll(_poly_sse(m, 1), cnt, floor))
    gain = nll[n] - nll[:n + 1] - nll[n + 1:]
    allowed = (k >= params.min_points) & (k <= n - params.min_points)
    gain[~allowed] = -np.inf
    best = int(np.argmax(gain))
    if not np.isfinite(gain[best]):
        return None, -math.inf
    return first + best, float(gain[best])


def _segment_profiles(tables: list, params: TerrainParams) -> list:
    """Return :func:`_segment_profile`'s pieces of every table, split level by level.

    The same binary segmentation, with the same fits (:func:`_explained`) and likelihoods
    as :func:`_best_split` (:func:`_poly_sse`, :func:`_piece_nll`), but every stretch still
    to split, of every table, is tried in one pass of array operations per level of the
    recursion (the numpy calls, not the readings, are the cost of a scan). Returns one
    list of ``(first, last)`` per table, in reading order. The caller silences numpy's
    floating-point warnings (empty and degenerate pieces divide by zero).
    """
    if not tables:
        return []
    mp = params.min_points
    found = [[] for _ in tables]
    # All tables side by side: a stretch is a range of columns of one of them.
    big = np.concatenate(tables, axis=1)
    offsets = np.cumsum([0] + [t.shape[1] for t in tables]).tolist()
    todo = []                                   # (table, first, last) still to split
    for i, table in enumerate(tables):
        n = table.shape[1] - 1
        if n >= 2 * mp:
            todo.append((i, 0, n - 1))
        else:
            found[i].append((0, n - 1))
    while todo:
        firsts = np.array([offsets[i] + first for i, first, _ in todo])
        lasts = np.array([offsets[i] + last for i, _, last in todo])
        sizes = lasts - firsts + 2 - 2 * mp                 # allowed splits k per stretch
        reps = np.repeat(np.arange(len(todo)), sizes)
        seg = np.cumsum(sizes) - sizes                      # each stretch's first split
        total = int(seg[-1] + sizes[-1])
        cols = np.arange(total) + (firsts + mp - seg)[reps]
        left = big[:, cols] - big[:, firsts[reps]]          # [0, k), the allowed k
        whole = big[:, lasts + 1] - big[:, firsts]
        # Columns: the left pieces, the whole stretches, the right pieces [k, n).
        m = np.concatenate([left, whole, whole[:, reps] - left], axis=1)
        s0 = m[0]
        # Each piece is a quadratic (a crowned road) or a line (a flat shoulder, a verge:
        # one parameter fewer, 1/2 ln n less penalty), which locates a kink sharply; rows
        # of ``sse``: the quadratic, the line. Every piece has >= min_points >= 3 readings:
        # the line is never degenerate, the quadratic only with 3 (its SSE is 0).
        sse = np.maximum(m[8] - np.stack(_explained(m)[::-1]), 0.0)
        if mp < 4:
            sse[0, s0 < 3.5] = 0.0
        v = np.maximum(sse / s0, m[9] / s0)
        nll = 0.5 * (s0 * np.log(v) + sse / v)
        half = np.log(lasts - firsts + 1.0) * 0.5
        nll[0] += half[np.concatenate([reps, np.arange(len(todo)), reps])]
        nll = nll.min(axis=0)
        gain = nll[total + reps] - nll[:total] - nll[total + len(todo):]
        # np.argmax per stretch: the first maximum, or the first NaN if there is one.
        ends = (seg + sizes).tolist()
        at = [int(np.argmax(gain[a:b])) for a, b in zip(seg.tolist(), ends)]
        nxt = []
        for (i, first, last), best, start in zip(todo, at, seg.tolist()):
            value = float(gain[start + best])
            if not math.isfinite(value) or value <= 2.5 * math.log(last - first + 1):
                found[i].append((first, last))
                continue
            for a, b in ((first, first + mp + best - 1), (first + mp + best, last)):
                if b - a + 1 >= 2 * mp:
                    nxt.append((i, a, b))
                else:
                    found[i].append((a, b))
        todo = nxt
    return [sorted(pieces) for pieces in found]


def _fit_piece(first: int, last: int, table: np.ndarray,
               fits: Optional[dict] = None) -> tuple[float, float, float, int]:
    """Return a piece's quadratic-profile SSE, unbiased variance (floored), floor and size.

    ``first`` and ``last`` index the stretch of :func:`_moment_table` (as :func:`_poly_sse`,
    on floats). ``fits`` (one dict per table) keeps the results by ``(first, last)``: the
    merging, the edge refinement and the verge test ask for the same pieces again.
    """
    if fits is not None:
        got = fits.get((first, last))
        if got is None:
            got = fits[first, last] = _fit_piece(first, last, table)
        return got
    sums = (table[:, last + 1] - table[:, first]).tolist()
    zz, f = sums[8], sums[9]
    n = last - first + 1
    sse = 0.0
    if n > 3:
        try:
            line, quad = _explained(sums)
            # quad < line only when rounding leaves no room for a curvature (t^2 on t).
            sse = max(zz - max(line, quad), 0.0)
        except ZeroDivisionError:           # readings at one lateral position: no profile
            pass
    return sse, max(sse / max(n - 3, 1), f / n), f / n, n


def _rougher(v_a: float, n_a: int, v_b: float, n_b: int, params: TerrainParams) -> bool:
    """Whether one piece is rougher than the other by ``rough_ratio``, significantly.

    F-test of the variance ratio against ``rough_ratio^2`` at ``rough_alpha`` (quadratic
    pieces: n - 3 degrees of freedom): a short piece's variance is too uncertain for the
    plain ratio (a smooth stretch of a few readings in a gravel road).
    """
    (v_hi, n_hi), (v_lo, n_lo) = sorted(((v_a, n_a), (v_b, n_b)), reverse=True)
    crit = _f_quantile(max(n_hi - 3, 1), max(n_lo - 3, 1), 1.0 - params.rough_alpha)
    return v_hi >= params.rough_ratio ** 2 * crit * v_lo


@functools.lru_cache(maxsize=4096)
def _f_quantile(dfn: int, dfd: int, q: float) -> float:
    """Return the F distribution's ``q`` quantile (cached: the piece sizes repeat)."""
    return float(fdtri(dfn, dfd, q))


def _merge_pieces(pieces: list, table: np.ndarray, params: TerrainParams,
                  fits: Optional[dict] = None) -> list:
    """Rejoin neighbouring pieces whose boundary is not a physical change.

    A boundary stays when the two pieces' roughness differs by ``rough_ratio`` (e.g. smooth
    asphalt next to a rough verge at the same height) or two profiles fit better than one
    by more than ``split_rms`` metres rms over the shorter piece (a kink, e.g. a crowned
    road and its flat shoulder), and the split is still significant (the BIC of
    :func:`_segment_profile`); otherwise the pieces merge (a crowned road split by its
    random texture).
    """
    def nll(sse: float, n: int, floor: float) -> float:
        v = max(sse / n, floor)
        return 0.5 * (n * math.log(v) + sse / v)

    def weakness(j: int) -> float:
        """Return the boundary's gain per reading over the penalty if it may go, else inf."""
        (pf, pl), (first, last) = out[j], out[j + 1]
        if pl + 1 != first:
            return math.inf
        sse_a, v_a, f_a, n_a = _fit_piece(pf, pl, table, fits)
        sse_b, v_b, f_b, n_b = _fit_piece(first, last, table, fits)
        sse_ab, _, f_ab, n = _fit_piece(pf, last, table, fits)
        gain = nll(sse_ab, n, f_ab) - nll(sse_a, n_a, f_a) - nll(sse_b, n_b, f_b) \
            - 2.5 * math.log(n)
        kink = math.sqrt(max(sse_ab - sse_a - sse_b, 0.0) / min(n_a, n_b)) > params.split_rms
        if gain > 0.0 and (kink or _rougher(v_a, n_a, v_b, n_b, params)):
            return math.inf
        return gain / n

    out = list(pieces)
    weak = [weakness(j) for j in range(len(out) - 1)]
    while weak and min(weak) < math.inf:
        # The least significant boundary goes first: two pieces of the road merge before
        # either is merged with a verge.
        j = int(np.argmin(weak))
        out[j:j + 2] = [(out[j][0], out[j + 1][1])]
        del weak[j]
        for i in (j - 1, j):
            if 0 <= i < len(weak):
                weak[i] = weakness(i)
    return out


def _hinge_edge(first: int, last: int, quad_left: bool, v_left: float, v_right: float,
                table: np.ndarray, min_points: int) -> int:
    """Return the reading that starts the right piece of the best continuous two-piece fit.

    The stretch ``first`` .. ``last`` of :func:`_moment_table` is split at every reading
    ``k`` (``min_points`` each side) into a quadratic and a straight profile (the quadratic
    on the left if ``quad_left``) that meet at the lateral position ``tau`` between
    readings ``k - 1`` and ``k`` (no step: a road and its verge are one surface, only the
    slope changes), each side weighted by its own height variance (``v_left``,
    ``v_right``). The split of least negative log-likelihood is the edge.
    """
    n = last - first + 1
    if n < 2 * min_points:
        return first + n // 2
    k, nll = _hinge_nll(first, last, quad_left, v_left, v_right, table, min_points)
    return first + int(k[int(np.argmin(nll))])


def _hinge_nll(first: int, last: int, quad_left: bool, v_left: float, v_right: float,
               table: np.ndarray, min_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the splits ``k`` of :func:`_hinge_edge` and their negative log-likelihoods.

    The continuous fit is the two sides' own least-squares fits (:func:`_explained`: the
    quadratic on one side, the line on the other) corrected for the one constraint that
    they meet at ``tau``. For an equality-constrained least-squares problem the weighted
    residual sum grows by ``d^2 / (l_q / w_q + l_o / w_o)``: ``d`` is the step between the
    two free fits at ``tau``, ``l`` each fit's leverage at ``tau`` (its value's variance
    over the noise variance: ``1 / n + (tau - mean t)^2 / Sxx`` for the line, plus
    ``phi2(tau)^2 / Rt`` for the quadratic's orthogonalised ``t^2`` term), ``w`` the side's
    weight (Lagrange multiplier of the constraint; e.g. Seber and Lee, Linear Regression
    Analysis, 2nd ed., §3.8.1). All as array arithmetic over the splits.
    """
    n = last - first + 1
    mp = min_points
    base = table[:9, first:first + 1]
    left = table[:9, first + mp:last + 2 - mp] - base                  # sums over [0, k)
    right = (table[:9, last + 1:last + 2] - base) - left
    t = table[1, first + 1:last + 2] - table[1, first:last + 1]        # t of each reading
    k = np.arange(mp, n - mp + 1)
    tau = 0.5 * (t[mp - 1:n - mp] + t[mp:n - mp + 1])
    quad, line = (left, right) if quad_left else (right, left)
    w_q, w_o = (1.0 / v_left, 1.0 / v_right) if quad_left else (1.0 / v_right, 1.0 / v_left)
    # The quadratic side (Gram-Schmidt on its sums, as in _explained).
    mt, mz, m2, sxx, sxz, beta, rt, rz = _orthogonal_sums(quad)
    s0, b0, zz = quad[0], quad[5], quad[8]
    du = tau - mt
    phi = tau * tau - m2 - beta * du                  # the orthogonalised t^2 at tau
    a1, a2 = sxz / sxx, rz / rt
    value_q = mz + a1 * du + a2 * phi
    lever_q = 1.0 / s0 + du * du / sxx + phi * phi / rt
    wss_q = zz - b0 * mz - a1 * sxz - a2 * rz
    # The straight side.
    o0, o1, o2, c0, c1, oz = line[[0, 1, 2, 5, 6, 8]]
    mt, mz = o1 / o0, c0 / o0
    sxx = o2 - o1 * mt
    a1 = (c1 - o1 * mz) / sxx
    du = tau - mt
    value_o = mz + a1 * du
    lever_o = 1.0 / o0 + du * du / sxx
    wss_o = oz - c0 * mz - a1 * a1 * sxx
    d = value_q - value_o
    wss = w_q * wss_q + w_o * wss_o + d * d / (lever_q / w_q + lever_o / w_o)
    return k, 0.5 * (wss + k * math.log(v_left) + (n - k) * math.log(v_right))


def _refine_edges(pieces: list, table: np.ndarray, params: TerrainParams,
                  fits: Optional[dict] = None) -> list:
    """Re-place each boundary between neighbouring pieces by a continuous two-piece fit.

    The binary segmentation fits each piece on its own: the short piece beside the road (a
    shoulder 0.6 m wide), free to curve and to start at any height, takes the last few
    tenths of a metre of the crowned road's falling edge with it. Here the wider piece
    keeps its quadratic profile, the narrower one is straight, and the two meet without a
    step (:func:`_hinge_edge`); each side's height variance is its piece's (floored by the
    laser's height noise).
    """
    out = list(pieces)
    for j in range(len(out) - 1):
        (fa, la), (fb, lb) = out[j], out[j + 1]
        if la + 1 != fb:
            continue
        v_a = _fit_piece(fa, la, table, fits)[1]
        v_b = _fit_piece(fb, lb, table, fits)[1]
        k = _hinge_edge(fa, lb, la - fa >= lb - fb, v_a, v_b, table, params.min_points)
        out[j], out[j + 1] = (fa, k - 1), (k, lb)
    return out


def _verges(pieces: list, s: np.ndarray, table: np.ndarray, params: TerrainParams,
            fits: Optional[dict] = None) -> list:
    """Flag the rougher of two neighbours whose roughness differs by ``rough_ratio``.

    The rougher piece is a verge (shoulder, grass) beside a smoother and wider piece, at
    least ``min_width`` wide (the road, whose roughness is well estimated): not
    traversable. A smooth patch of a gravel road does not make the road a verge.
    """
    rough = [_fit_piece(first, last, table, fits)[1::2] for first, last in pieces]
    width = [abs(s[last] - s[first]) for first, last in pieces]
    verge = [False] * len(pieces)
    for j in range(len(pieces) - 1):
        if pieces[j][1] + 1 != pieces[j + 1][0]:
            continue
        smooth, other = (j, j + 1) if rough[j][0] < rough[j + 1][0] else (j + 1, j)
        if width[smooth] >= max(params.min_width, width[other]) and \
                _rougher(*rough[j], *rough[j + 1], params):
            verge[other] = True
    return verge


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
