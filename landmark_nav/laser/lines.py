"""Line extraction from laser scan clusters: split-and-merge and ALFA.

Both methods work on the clusters of :func:`landmark_nav.laser.segmentation.segment_scan`
and return :class:`LineSegment` objects in the laser frame: ``x cos(alpha) + y sin(alpha)
= rho`` (corner chapter eq. 5) with ``rho >= 0`` and ``alpha`` wrapped to [-pi, pi).

* ``split_merge`` (corner chapter, section 2.1.2): recursive split of a cluster at the point
  of largest perpendicular distance to the chord joining its first and last points (eq. 4)
  while that distance exceeds the tolerance; total-least-squares fit of every piece in
  Hessian normal form (eqs. 5-10); adjacent collinear pieces merged.
* ``alfa`` (line chapter, Mavaei 2011, ALFA pseudo code): each cluster's ranges are smoothed
  over the bearing by robust lowess (tricube weights eq. 8, bisquare robustness weights
  eq. 9, see :mod:`landmark_nav.laser.lowess`); the end of each line is then found by
  binary search on the RMSE criterion (eq. 21) with a floating threshold and the
  RMSE-gradient test (:func:`alfa_pieces`). The smoothed points only place the
  breakpoints: the lines are fitted on the ORIGINAL points (the chapter smooths "to
  increase the algorithm efficiency" and says nothing about fitting the smoothed data;
  smoothing would round corners and correlate the noise the covariance assumes).

Shared steps after the breakpoints (both methods), all clusters of a scan in one
vectorised batch (fits from prefix sums of point moments):

1. Break refinement: a break between two adjacent pieces moves, within ``min_points``
   beams, to where the summed squared residuals of both fits are smallest (the farthest
   point from a chord, or the end of a binary search on smoothed data, is often a beam or
   two off the true corner).
2. Endpoint clean-up: leading and trailing points farther than ``trim_sigma`` standard
   deviations from their piece's line (eq. 7 projected on the line normal) are dropped,
   and a split point shared by two pieces stays with the one it fits better. Pieces with
   fewer than ``min_points`` points are dropped here: their (rho, alpha) are too uncertain
   for a linearised merge test, and their points become free for step 4.
3. Merge: two consecutive pieces are merged when they are neighbours (same cluster, or
   clusters whose facing ends are at most ``merge_gap`` or ``merge_gap_angle`` apart, e.g.
   a wall cut by a dropout or a spurious return) and their (rho, alpha) agree in a
   chi-square test, ``d^2 = dp^T (C1 + C2)^-1 dp <= merge_chi2`` with the covariances of
   the two independent fits, each scaled by its a-posteriori variance factor where its
   residuals reject the stated noise (:func:`_variance_factor`: a SICK in cm mode or a
   rough wall scatters more than ``sigma_r``, and pieces of one wall would otherwise stay
   apart). Chains of passing pairs are refitted on
   the union of their points (points between them are not used) and kept only if every
   member also passes the test against the merged line and its end points are within
   the split tolerance of it.
4. Growth: each line takes the free points beside its ends (also of small clusters) that
   lie within ``trim_sigma`` standard deviations and the split tolerance of it, e.g. a
   corridor wall seen at grazing angles, whose points the segmentation isolates.
5. No false surfaces: a line never covers a valid beam whose return lies more than
   ``see_through`` (default ``max(3 sigma_r, 5 cm)``) beyond it along the ray, i.e. a beam
   the laser saw through it. The beams checked are all beams between a line's first and
   last supporting beam, also those of no cluster (dropped small clusters, read from the
   whole scan of :func:`~landmark_nav.laser.segmentation.segment_scan`). A line hiding an
   *opening* (a beam beyond it by more than ``see_through`` plus 3 standard deviations
   of its distance along the ray, eq. 7) is cut there and both sides are refitted, until
   no line hides one; thus merging across a cluster break and growth over neighbouring
   beams stand only over beams that are occluded from the front or missing. A line
   hiding only its own noise (a wall seen at grazing incidence, where bearing noise puts
   returns 5 cm or more beyond it) is cut likewise when that leaves two or more lines of
   ``min_points`` and ``min_length``; otherwise it keeps its fit on all its points, and
   its extent shrinks to its run of support between those beams with the most points.
   See :func:`_cut_seen_through`. A line keeps its fit across an *occluder* (two or more
   neighbouring beams in front of it by more than the opening margin: a table leg, a
   person), but not its extent: it is reported as one segment per side of at least
   ``min_points`` points, each with the line's (rho, alpha), covariance and point count,
   since a segment along the occluder's rays would claim a surface where the laser saw
   something else (the PLE ray metric scores such beams with their full distance to the
   line). A lone beam in front (one return cannot tell an object from a spurious return)
   stays inside. See :func:`_occluded_extents`. Lines of one surface on both sides of
   an occluder (or of a gap the merge did not test) then get one fit when they pass the
   merge's chi-square test and no beam between them saw further than the joint line
   (:func:`_join_occluded`); their extents stay as they were (none dropped), and the
   segments of each side carry the same fit: one measurement, not two.
6. Lines with fewer than ``min_points`` points, shorter than ``min_length`` or with an
   RMSE above the split tolerance are dropped. End points are the projections of the
   first and last supporting points, moved onto the ray of that beam when the projection
   falls outside the supporting beams' bearings: a segment covers no beam outside them.

Choices where the chapters are silent, or misprinted:

* Fits and RMSE use perpendicular (total least squares) residuals, not the vertical
  residuals of the line chapter's eqs. 12-19, which fail on lines parallel to the y axis.
* Lowess combines the two weights by product (the line chapter prints a sum in eq. 10,
  which could not give an outlier the zero weight its Fig. 1 shows).
* The (rho, alpha) covariance propagates the per-point noise of the line chapter's eq. 7
  through first-order derivatives of the total-least-squares solution (:func:`fit_line`).
"""

from bisect import bisect_left
from dataclasses import dataclass, field
import math
from operator import lt
from typing import List, Optional, Sequence, Tuple

from landmark_nav.laser.lowess import lowess, lowess_groups
from landmark_nav.laser.segmentation import Cluster, ScanArrays
import numpy as np

__all__ = ['alfa_pieces', 'CHI2_2DOF_95', 'explained_points', 'extract_lines', 'fit_line',
           'LineParams', 'LineSegment', 'lowess', 'METHODS', 'point_covariances',
           'split_pieces']

METHODS = ('split_merge', 'alfa')
CHI2_2DOF_95 = 5.991
TWO_PI = 2.0 * math.pi


def _wrap(a):
    """Wrap angle(s) to [-pi, pi)."""
    return (a + math.pi) % TWO_PI - math.pi


@dataclass(frozen=True, eq=False)
class LineSegment:
    """A line fitted to consecutive scan points (laser frame).

    Attributes:
        rho: Distance of the line to the laser origin, >= 0 [m] (eq. 5).
        alpha: Angle of the line normal, wrapped to [-pi, pi) [rad].
        start: (2,) projection of the first supporting point onto the line, or the
            crossing of its beam's ray with the line when that is nearer the middle [m].
        end: (2,) the same at the last supporting point [m].
        num_points: Number of supporting points (the points of the fit; a line that hides
            its own noisy returns at grazing incidence keeps them in the fit but not in
            its extent, see step 5 above).
        rmse: Perpendicular RMSE of the supporting points [m] (eq. 21).
        covariance: (2, 2) covariance of (rho, alpha) [m^2, m rad; m rad, rad^2].
        first_index: Beam index of the first supporting point of the extent.
        last_index: Beam index of the last supporting point of the extent.

    Segments of one surface on both sides of an occluder share one fit (step 5): equal
    ``rho``, ``alpha``, ``covariance``, ``num_points`` and ``rmse``, one extent each: one
    measurement, not two (``LineParams.join_occluded``).
    """

    rho: float
    alpha: float
    start: np.ndarray
    end: np.ndarray
    num_points: int
    rmse: float
    covariance: np.ndarray
    first_index: int
    last_index: int

    @property
    def length(self) -> float:
        """Return the distance between the endpoints [m]."""
        return float(math.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1]))

    @property
    def normal(self) -> np.ndarray:
        """Return the unit normal ``(cos alpha, sin alpha)``."""
        return np.array([math.cos(self.alpha), math.sin(self.alpha)])

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Return the signed distances (K,) of points (K, 2) to the line [m]."""
        return np.asarray(points, dtype=float).reshape(-1, 2) @ self.normal - self.rho


@dataclass(frozen=True)
class LineParams:
    """Line extraction parameters (SI units, radians).

    Attributes:
        method: ``'split_merge'`` (default) or ``'alfa'``.
        split_threshold: Split-and-merge distance tolerance [m] (eq. 4); None means
            ``max(0.03, 4 * sigma_r)``. The tolerance of a point at range r is this plus
            ``3 * sigma_phi * r`` (the bearing noise's lateral effect). Also bounds the
            merge, the growth and every line's RMSE (both methods).
        min_points: Fewest points of a line (ALFA's ``least_point_in_line``).
        min_length: Shortest line [m].
        merge_chi2: Chi-square gate (2 dof) of the collinearity test for merging.
        merge_gap: Largest gap between the facing ends of collinear lines of neighbouring
            clusters that are merged into one line [m].
        sigma_r: Range noise std sigma_d [m] (line chapter eqs. 2, 7).
        sigma_phi: Bearing noise std [rad] (eqs. 3, 7).
        lowess_span: ALFA: lowess window in points (odd).
        lowess_iterations: ALFA: robustness iterations (bisquare weights, eq. 9).
        rmse_min: ALFA: lowest floating RMSE threshold [m]; None means ``0.3 * sigma_r``.
        rmse_max: ALFA: highest (and initial) floating RMSE threshold [m]; None means
            ``sigma_r``. Both apply to the smoothed points.
        max_gradient: ALFA: largest RMSE growth per added point, relative to the current
            threshold (see :func:`alfa_pieces`).
        trim_sigma: Endpoint clean-up and growth gate in standard deviations of a point's
            distance to its line (eq. 7); ``inf`` disables both.
        merge_gap_angle: Lines of neighbouring clusters are also neighbours (for merging
            and growing) when their facing ends are at most this bearing apart [rad].
        see_through: Largest distance a valid beam inside a line's extent may lie beyond
            the line along its ray [m] (step 5); None means ``max(3 sigma_r, 0.05)``.
        join_occluded: Give the lines of one surface on both sides of an occluder one fit
            (step 5, :func:`_join_occluded`); their segments then share it. False: each
            side is fitted on its own beams (independent measurements, as a filter that
            maps each segment as a landmark with its extent needs).

    """

    method: str = 'split_merge'
    split_threshold: Optional[float] = None
    min_points: int = 8
    min_length: float = 0.3
    merge_chi2: float = CHI2_2DOF_95
    merge_gap: float = 0.3
    sigma_r: float = 0.01
    sigma_phi: float = math.radians(0.1)
    lowess_span: int = 7
    lowess_iterations: int = 2
    rmse_min: Optional[float] = None
    rmse_max: Optional[float] = None
    max_gradient: float = 0.1
    trim_sigma: float = 3.0
    merge_gap_angle: float = math.radians(5.0)
    see_through: Optional[float] = None
    join_occluded: bool = True

    def __post_init__(self) -> None:
        """Validate; raise ValueError naming the bad parameter."""
        def bad(name: str, rule: str) -> ValueError:
            return ValueError(f'LineParams.{name} must be {rule}, got {getattr(self, name)!r}')

        def number(v) -> bool:
            return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(
                v, bool) and not math.isnan(v)

        def positive(v, allow_none: bool = False) -> bool:
            if v is None:
                return allow_none
            return number(v) and math.isfinite(v) and v > 0

        def integer(v) -> bool:
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        if self.method not in METHODS:
            raise bad('method', 'one of ' + ', '.join(METHODS))
        if not positive(self.split_threshold, allow_none=True):
            raise bad('split_threshold', 'None or a number > 0')
        if not integer(self.min_points) or self.min_points < 3:
            raise bad('min_points', 'an integer >= 3')
        if not (number(self.min_length) and math.isfinite(self.min_length)
                and self.min_length >= 0):
            raise bad('min_length', 'a number >= 0')
        if not positive(self.merge_chi2):
            raise bad('merge_chi2', 'a number > 0')
        if not (number(self.merge_gap) and math.isfinite(self.merge_gap)
                and self.merge_gap >= 0):
            raise bad('merge_gap', 'a number >= 0')
        if not positive(self.sigma_r):
            raise bad('sigma_r', 'a number > 0')
        if not (number(self.sigma_phi) and math.isfinite(self.sigma_phi)
                and self.sigma_phi >= 0):
            raise bad('sigma_phi', 'a number >= 0')
        if not integer(self.lowess_span) or self.lowess_span < 3 or self.lowess_span % 2 == 0:
            raise bad('lowess_span', 'an odd integer >= 3')
        if not integer(self.lowess_iterations) or self.lowess_iterations < 0:
            raise bad('lowess_iterations', 'an integer >= 0')
        if not positive(self.rmse_min, allow_none=True):
            raise bad('rmse_min', 'None or a number > 0')
        if not positive(self.rmse_max, allow_none=True):
            raise bad('rmse_max', 'None or a number > 0')
        if self.rmse_bounds[0] > self.rmse_bounds[1]:
            raise bad('rmse_min', f'<= rmse_max ({self.rmse_bounds[1]})')
        if not positive(self.max_gradient):
            raise bad('max_gradient', 'a number > 0')
        if not (number(self.merge_gap_angle) and 0 <= self.merge_gap_angle <= math.pi):
            raise bad('merge_gap_angle', 'an angle in [0, pi]')
        if not positive(self.see_through, allow_none=True):
            raise bad('see_through', 'None or a number > 0')
        if not isinstance(self.join_occluded, (bool, np.bool_)):
            raise bad('join_occluded', 'a bool')
        if not (number(self.trim_sigma) and self.trim_sigma > 0):
            raise bad('trim_sigma', 'a number > 0 (inf disables the clean-up)')

    @property
    def threshold(self) -> float:
        """Return the split tolerance at zero range [m]."""
        if self.split_threshold is not None:
            return float(self.split_threshold)
        return max(0.03, 4.0 * self.sigma_r)

    @property
    def see_through_tolerance(self) -> float:
        """Return the see-through tolerance [m] (``see_through`` or its default)."""
        if self.see_through is not None:
            return float(self.see_through)
        return max(3.0 * self.sigma_r, 0.05)

    @property
    def rmse_bounds(self) -> Tuple[float, float]:
        """Return (rmse_min, rmse_max) of the ALFA floating threshold [m]."""
        lo = 0.3 * self.sigma_r if self.rmse_min is None else float(self.rmse_min)
        hi = self.sigma_r if self.rmse_max is None else float(self.rmse_max)
        return lo, hi


def point_covariances(ranges: np.ndarray, angles: np.ndarray, sigma_r: float,
                      sigma_phi: float) -> np.ndarray:
    """Return (N, 2, 2) Cartesian covariances of scan points (line chapter eq. 7)."""
    ranges = np.asarray(ranges, dtype=float)
    angles = np.asarray(angles, dtype=float)
    c, s = np.cos(angles), np.sin(angles)
    rad = np.stack([np.stack([c * c, c * s], -1), np.stack([c * s, s * s], -1)], -2)
    tan = np.stack([np.stack([s * s, -c * s], -1), np.stack([-c * s, c * c], -1)], -2)
    return (sigma_r ** 2) * rad + ((ranges * sigma_phi) ** 2)[:, None, None] * tan  # eq. 7


# ---------------------------------------------------------------------- moment-based TLS fits
# A fit needs only sums over its points of the monomials (1, x, y, x^2, y^2, xy), plain and
# weighted by the three entries of each point's eq.-7 covariance (A = Q_xx, B = Q_yy,
# C = Q_xy): 24 sums, stored as rows. Prefix sums of the plain monomials give the fit of any
# run in O(1); all pieces of a scan are fitted with a handful of array operations.
NUM_SUMS = 24


def _features(x: np.ndarray, y: np.ndarray, rng: np.ndarray, cphi: np.ndarray,
              sphi: np.ndarray, sigma_r: float, sigma_phi: float, pad: int = 0) -> np.ndarray:
    """Return (24, N + pad) per-point terms whose sums define a TLS fit and its covariance."""
    n = x.size
    out = np.zeros((NUM_SUMS, n + pad))
    mono = out[:6, :n]
    mono[0] = 1.0
    mono[1] = x
    mono[2] = y
    np.multiply(x, x, out=mono[3])
    np.multiply(y, y, out=mono[4])
    np.multiply(x, y, out=mono[5])
    vr = sigma_r * sigma_r
    vp = rng * rng * (sigma_phi * sigma_phi)
    cc, ss = cphi * cphi, sphi * sphi
    # eq. 7: Q = sigma_d^2 u u^T + D^2 sigma_phi^2 v v^T, u = (cos, sin), v = (-sin, cos)
    w = np.empty((3, n))
    np.add(vr * cc, vp * ss, out=w[0])
    np.add(vr * ss, vp * cc, out=w[1])
    np.multiply(vr - vp, cphi * sphi, out=w[2])
    np.multiply(w[:, None, :], mono[None, :, :], out=out[6:, :n].reshape(3, 6, n))
    return out


def _prefix5(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Return (5, N + 1) prefix sums of x, y, x^2, y^2, xy (column i = first i points)."""
    out = np.zeros((5, x.size + 1))
    np.cumsum(np.stack([x, y, x * x, y * y, x * y]), axis=1, out=out[:, 1:])
    return out


class _Fit:
    """TLS fits of G point sets from their sums (internal; a plain class: built per step).

    ``params`` (4, G) holds the rows rho, alpha, nx, ny (one gather takes all of them);
    ``rmse`` (G,) or None when not asked for; ``count`` (G,) number of points (float);
    ``cov`` (G, 2, 2) covariance of (rho, alpha), or None. ``extent`` caches the last
    :func:`_extent_beams` of these fits (the first / last arrays it was for, the result).
    """

    __slots__ = ('params', 'rmse', 'count', 'cov', 'extent')

    def __init__(self, params: np.ndarray, rmse: Optional[np.ndarray], count: np.ndarray,
                 cov: Optional[np.ndarray]) -> None:
        """Hold the arrays (not copied)."""
        self.params = params
        self.rmse = rmse
        self.count = count
        self.cov = cov
        self.extent: Optional[tuple] = None

    @property
    def rho(self) -> np.ndarray:
        """Return the (G,) distances to the laser origin (>= 0)."""
        return self.params[0]

    @property
    def alpha(self) -> np.ndarray:
        """Return the (G,) normal angles."""
        return self.params[1]

    @property
    def nx(self) -> np.ndarray:
        """Return the (G,) x components of the normals."""
        return self.params[2]

    @property
    def ny(self) -> np.ndarray:
        """Return the (G,) y components of the normals."""
        return self.params[3]


def _scatter(sums: np.ndarray) -> Tuple[np.ndarray, ...]:
    """Return the centroid (cx, cy) and the scatter sxx, syy, sxy of sums (>= 6, G)."""
    n = sums[0]
    cx = sums[1] / n
    cy = sums[2] / n
    ncx = n * cx
    return cx, cy, sums[3] - ncx * cx, sums[4] - n * cy * cy, sums[5] - ncx * cy


def _normal(sxx: np.ndarray, syy: np.ndarray, sxy: np.ndarray, out: np.ndarray
            ) -> np.ndarray:
    """Write the unit normal of the TLS lines (eq. 8) to ``out`` (2, G); return alpha."""
    alpha = 0.5 * np.arctan2(-2.0 * sxy, syy - sxx)  # eq. 8
    np.cos(alpha, out=out[0])
    np.sin(alpha, out=out[1])
    return alpha


def _math_is_numpy() -> bool:
    """Return whether math's atan2, cos, sin and x ** 3 give numpy's float64 results here.

    They do where numpy calls the C library for them (no SIMD version for this CPU, e.g.
    x86-64 without AVX-512); the Python-float paths then call math's, without the array
    round trip of a numpy call. Checked at import on 4096 arguments of each over the
    ranges the fits use (eq. 8: alpha in [-pi/2, pi/2]), all signs of atan2's.
    """
    rng = np.random.default_rng(0)
    y, x = rng.standard_normal((2, 4096)) * np.exp(rng.uniform(-20.0, 5.0, (2, 4096)))
    half = 0.5 * np.arctan2(y, x)
    base = np.abs(x)
    return (np.arctan2(y, x).tolist() == list(map(math.atan2, y.tolist(), x.tolist()))
            and np.cos(half).tolist() == list(map(math.cos, half.tolist()))
            and np.sin(half).tolist() == list(map(math.sin, half.tolist()))
            and (base ** 3).tolist() == [b ** 3 for b in base.tolist()])


_MATH_TRIG = _math_is_numpy()


def _solve(sums: np.ndarray, origin: np.ndarray, rmse: bool = True) -> _Fit:
    """Fit a line to each column of sums (6 or 24, G); coordinates relative to ``origin``.

    TLS in Hessian normal form (eqs. 5-10). With 24 rows the covariance is added: the
    first-order propagation of eq. 7 through the solution, linearised at the fitted line.
    With ``q_i`` the centred points, ``n`` the normal, ``t = dn/dalpha`` and ``L =
    lambda_max - lambda_min`` of the scatter matrix, a normal displacement ``e_i`` of point
    i moves alpha by ``-(t.q_i) e_i / L`` (stationarity of eq. 6 in alpha) and ``rho =
    n.c`` by ``(t.c) d alpha + e_i / N``; ``C = sum_i J_i J_i^T s_i^2``, ``s_i^2 = n^T Q_i n``.
    The RMSE (eq. 21) is left out unless ``rmse``.
    """
    if sums.shape[1] <= (_SMALL if sums.shape[0] == NUM_SUMS else _SMALL_NO_COV):
        try:
            return _solve_small(sums, origin, rmse)
        except (ZeroDivisionError, ValueError):  # degenerate fits: numpy's inf / nan below
            pass
    n = sums[0]
    cx, cy, sxx, syy, sxy = _scatter(sums)
    out = np.empty((4, n.size))
    alpha = _normal(sxx, syy, sxy, out[2:])
    nx, ny = out[2], out[3]
    ax, ay = cx + float(origin[0]), cy + float(origin[1])  # centroid in the laser frame (eq. 10)
    rho = np.add(ax * nx, ay * ny, out=out[0])  # eq. 9
    flip = rho < 0.0
    if np.count_nonzero(flip):
        np.abs(rho, out=rho)
        alpha[flip] += math.pi
        alpha = _wrap(alpha)
        np.negative(out[2:], out=out[2:], where=flip)
    out[1] = alpha
    half = 0.5 * (sxx - syy)
    root = np.sqrt(half * half + sxy * sxy)
    err = np.sqrt(np.maximum(0.5 * (sxx + syy) - root, 0.0) / n) if rmse else None  # eq. 21
    cov = None
    if sums.shape[0] == NUM_SUMS:
        cov = _covariance(sums, n, cx, cy, ax, ay, nx, ny, root)
    return _Fit(out, err, n, cov)


# Fits per call up to which _solve_small is faster than the array operations (measured).
_SMALL = 14
_SMALL_NO_COV = 20


def _solve_small(sums: np.ndarray, origin: np.ndarray, rmse: bool) -> _Fit:
    """Return :func:`_solve` for a few fits, computed on Python floats.

    The same operations in the same order, hence the same results (numpy's arctan2, cos
    and sin, one call each, as the array version, or math's where they are the same:
    :func:`_math_is_numpy`). Raises ZeroDivisionError or ValueError
    on degenerate sums (e.g. a zero count or scatter), which :func:`_solve` then fits
    with numpy's inf / nan semantics.
    """
    full = sums.shape[0] == NUM_SUMS
    cols = sums.T.tolist()  # one list of sums per fit
    scat, a_in, b_in = [], [], []
    for c in cols:
        n, cx, cy, sxx, syy, sxy = _scatter_py(c)
        scat.append((n, cx, cy, sxx, syy, sxy))
        a_in.append(-2.0 * sxy)
        b_in.append(syy - sxx)
    if _MATH_TRIG:  # numpy's results (see _math_is_numpy)
        alpha_l = [0.5 * a for a in map(math.atan2, a_in, b_in)]  # eq. 8
        nx_l, ny_l = list(map(math.cos, alpha_l)), list(map(math.sin, alpha_l))
    else:
        alpha_a = np.arctan2(a_in, b_in)
        alpha_a *= 0.5  # eq. 8
        nx_l, ny_l = np.cos(alpha_a).tolist(), np.sin(alpha_a).tolist()
        alpha_l = alpha_a.tolist()
    ox, oy = float(origin[0]), float(origin[1])
    rho_l, err_l, cov_l = [], [], []
    flip = False
    pi = math.pi
    isfinite = math.isfinite
    for j, (n, cx, cy, sxx, syy, sxy) in enumerate(scat):
        nx, ny = nx_l[j], ny_l[j]
        ax = cx + ox  # centroid in the laser frame (eq. 10)
        ay = cy + oy
        rho = ax * nx + ay * ny  # eq. 9
        if rho < 0.0:
            flip = True
            rho = -rho
            alpha_l[j] += pi
            nx = nx_l[j] = -nx
            ny = ny_l[j] = -ny
        rho_l.append(rho)
        half = 0.5 * (sxx - syy)
        root = math.sqrt(half * half + sxy * sxy)
        if rmse:
            v = 0.5 * (sxx + syy) - root
            err_l.append(math.sqrt(max(v, 0.0) / n))  # eq. 21
        if full:  # _covariance, term by term
            c = cols[j]
            a2, b2, ab = nx * nx, ny * ny, 2.0 * nx * ny
            w0 = a2 * c[6] + b2 * c[12] + ab * c[18]
            w1 = a2 * c[7] + b2 * c[13] + ab * c[19]
            w2 = a2 * c[8] + b2 * c[14] + ab * c[20]
            w3 = a2 * c[9] + b2 * c[15] + ab * c[21]
            w4 = a2 * c[10] + b2 * c[16] + ab * c[22]
            w5 = a2 * c[11] + b2 * c[17] + ab * c[23]
            tx, ty = -ny, nx
            tcl = tx * cx + ty * cy
            tw = tx * w1 + ty * w2
            t1 = tw - tcl * w0
            t2 = (b2 * w3 - ab * w5 + a2 * w4 - 2.0 * tcl * tw + tcl * tcl * w0)
            lever = tx * ax + ty * ay
            big_l = 2.0 * root
            caa = t2 / (big_l * big_l)
            nl = n * big_l
            cra = lever * caa - t1 / nl
            crr = lever * lever * caa - 2.0 * lever * t1 / nl + w0 / (n * n)
            if not (isfinite(crr) and isfinite(cra) and isfinite(caa) and root > 0.0):
                crr = cra = caa = math.inf
            cov_l += (crr, cra, cra, caa)
    if flip:
        alpha_l = [(a + pi) % TWO_PI - pi for a in alpha_l]  # _wrap
    cov = np.array(cov_l).reshape(-1, 2, 2) if full else None
    out = np.array((rho_l, alpha_l, nx_l, ny_l))
    return _Fit(out, np.array(err_l) if rmse else None, sums[0], cov)


def _scatter_py(c: List[float]) -> Tuple[float, float, float, float, float, float]:
    """Return (n, cx, cy, sxx, syy, sxy) of one column of sums ``c``: :func:`_scatter` on floats.

    Raises ZeroDivisionError on a zero count.
    """
    n = c[0]
    cx = c[1] / n
    cy = c[2] / n
    ncx = n * cx
    return n, cx, cy, c[3] - ncx * cx, c[4] - n * cy * cy, c[5] - ncx * cy


def _line_py(c: List[float], origin: Tuple[float, float]) -> Tuple[float, float, float, float]:
    """Return (rho, alpha, nx, ny) of :func:`_solve` of one column of sums ``c`` (a list).

    The operations of :func:`_solve_small` for a single fit, without arrays (eqs. 8-10).
    Raises ZeroDivisionError on a zero count.
    """
    n, cx, cy, sxx, syy, sxy = _scatter_py(c)
    if _MATH_TRIG:  # numpy's results (see _math_is_numpy)
        alpha = 0.5 * math.atan2(-2.0 * sxy, syy - sxx)  # eq. 8
        nx, ny = math.cos(alpha), math.sin(alpha)
    else:
        alpha_a = np.arctan2([-2.0 * sxy], [syy - sxx])
        alpha_a *= 0.5  # eq. 8
        nx, ny, alpha = np.cos(alpha_a).item(), np.sin(alpha_a).item(), alpha_a.item()
    ax = cx + float(origin[0])  # centroid in the laser frame (eq. 10)
    ay = cy + float(origin[1])
    rho = ax * nx + ay * ny  # eq. 9
    if rho < 0.0:
        rho = -rho
        alpha += math.pi
        alpha = (alpha + math.pi) % TWO_PI - math.pi  # _wrap
        nx = -nx
        ny = -ny
    return rho, alpha, nx, ny


def _covariance(sums: np.ndarray, n: np.ndarray, cx: np.ndarray, cy: np.ndarray,
                ax: np.ndarray, ay: np.ndarray, nx: np.ndarray, ny: np.ndarray,
                root: np.ndarray) -> np.ndarray:
    """Return the (G, 2, 2) covariance of (rho, alpha) of the fits of :func:`_solve`."""
    a2, b2, ab = nx * nx, ny * ny, 2.0 * nx * ny
    w = a2 * sums[6:12] + b2 * sums[12:18] + ab * sums[18:24]  # sums of s_i^2 * monomial
    tx, ty = -ny, nx  # t = (tx, ty): tx^2 = b2, ty^2 = a2, 2 tx ty = -ab (exactly)
    tcl = tx * cx + ty * cy  # t.c in the fit's coordinates
    tw = tx * w[1] + ty * w[2]
    t1 = tw - tcl * w[0]  # sum s^2 (t.q)
    t2 = (b2 * w[3] - ab * w[5] + a2 * w[4] - 2.0 * tcl * tw
          + tcl * tcl * w[0])  # sum s^2 (t.q)^2
    lever = tx * ax + ty * ay  # t.c in the laser frame
    big_l = 2.0 * root
    caa = t2 / (big_l * big_l)
    nl = n * big_l
    cra = lever * caa - t1 / nl
    crr = lever * lever * caa - 2.0 * lever * t1 / nl + w[0] / (n * n)
    cov = np.empty(n.shape + (2, 2))
    cov[..., 0, 0] = crr
    cov[..., 0, 1] = cra
    cov[..., 1, 0] = cra
    cov[..., 1, 1] = caa
    if np.count_nonzero(np.isfinite(cov)) < cov.size or np.count_nonzero(root > 0.0) < root.size:
        bad = ~(np.isfinite(crr) & np.isfinite(cra) & np.isfinite(caa) & (root > 0.0))
        cov[bad] = np.inf
    return cov


def fit_line(points: np.ndarray, ranges: Optional[np.ndarray] = None,
             angles: Optional[np.ndarray] = None, sigma_r: float = 0.01,
             sigma_phi: float = math.radians(0.1)) -> Tuple[float, float, np.ndarray, float]:
    """Fit a line by total least squares (eqs. 5-10) with the covariance of (rho, alpha).

    ``alpha = 0.5 atan2(-2 sum(dy dx), sum(dy^2 - dx^2))`` about the centroid (eq. 8) and
    ``rho = x_m cos(alpha) + y_m sin(alpha)`` (eq. 9); if rho < 0 the normal is flipped so
    that rho >= 0, and alpha is wrapped to [-pi, pi). For a line through the origin the
    sign of the normal is arbitrary.

    Covariance: point i at range d_i and bearing phi_i has the covariance Q_i of the line
    chapter's eq. 7, evaluated at the measured values (as the chapter allows). Linearising
    the TLS solution at the fitted line (stationarity of eq. 6 in alpha, ``rho = n.c``)
    gives ``J_i = d(rho, alpha)/d e_i`` for the normal displacement ``e_i`` of point i and
    ``C = sum_i J_i J_i^T n^T Q_i n`` (along the line a point does not move the line to
    first order); this is the unweighted case of Pfister et al. (2003).

    Args:
        points: (K, 2) points in the laser frame [m], K >= 2.
        ranges: (K,) measured ranges [m]; None = ``|points|``.
        angles: (K,) beam angles [rad]; None = the points' bearings.
        sigma_r: Range noise std [m] (eq. 2).
        sigma_phi: Bearing noise std [rad] (eq. 3).

    Returns:
        ``(rho, alpha, covariance (2, 2), rmse)``: rmse is the point-to-line RMS [m]
        (eq. 21); the covariance is infinite when the points do not define a line.

    Raises:
        ValueError: Fewer than 2 points or mismatched shapes.

    """
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f'points must have shape (K, 2), got {p.shape}')
    k = p.shape[0]
    if k < 2:
        raise ValueError('fit_line needs at least 2 points')
    rng = np.hypot(p[:, 0], p[:, 1]) if ranges is None else np.asarray(ranges, dtype=float)
    phi = np.arctan2(p[:, 1], p[:, 0]) if angles is None else np.asarray(angles, dtype=float)
    if rng.shape != (k,) or phi.shape != (k,):
        raise ValueError('ranges and angles must have one entry per point')
    origin = p.mean(axis=0)
    q = p - origin
    feats = _features(q[:, 0], q[:, 1], rng, np.cos(phi), np.sin(phi), float(sigma_r),
                      float(sigma_phi))
    with np.errstate(divide='ignore', invalid='ignore'):
        f = _solve(feats.sum(axis=1)[:, None], origin)
    res = p @ np.array([f.nx[0], f.ny[0]]) - f.rho[0]  # direct residuals: exact RMSE
    return float(f.rho[0]), float(f.alpha[0]), f.cov[0], float(np.sqrt(np.mean(res * res)))


def _gather(starts: np.ndarray, ends: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return the concatenated inclusive index ranges ``[starts[i], ends[i]]`` and offsets."""
    cnt = ends - starts + 1
    offs = np.zeros(cnt.size + 1, dtype=np.int64)
    cnt.cumsum(out=offs[1:])
    idx = np.arange(offs[-1], dtype=np.int64) - (offs[:-1] - starts).repeat(cnt)
    return idx, offs


# ---------------------------------------------------------------------- split (eq. 4)
def split_pieces(xy: np.ndarray, offsets: np.ndarray, tolerance) -> np.ndarray:
    """Split point runs recursively at the point farthest from the chord (eq. 4).

    All runs and all pieces of one recursion level are processed together.

    Args:
        xy: (N, 2) points, runs back to back.
        offsets: (C + 1,) run boundaries: run c is ``xy[offsets[c]:offsets[c + 1]]``.
        tolerance: split while the farthest point is farther than this from the chord
            [m]: a number, or (N,) one tolerance per point.

    Returns:
        (P, 2) int array of inclusive ``[first, last]`` indices of the final pieces, in
        order; neighbouring pieces of a run share the split point.

    """
    xy = np.asarray(xy, dtype=float)
    offsets = np.asarray(offsets, dtype=np.int64)
    keep = offsets[1:] > offsets[:-1]
    return _split(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                  offsets[:-1][keep], offsets[1:][keep] - 1,
                  np.broadcast_to(np.asarray(tolerance, dtype=float), xy.shape[:1])).T


def _split(px: np.ndarray, py: np.ndarray, s: np.ndarray, e: np.ndarray,
           tol: np.ndarray, min_span: int = 0) -> np.ndarray:
    """Split the runs ``s[i]..e[i]`` (inclusive); return the (2, P) first and last points.

    Pieces with ``last - first < min_span`` are left out of the result.

    All pieces of one recursion level in one batch. The farthest point from a chord is
    found on the unnormalised cross product ``|(q - p0) x (p1 - p0)|`` (the distance of
    eq. 4 times the chord length, constant within a piece), compared with the tolerance
    times the chord length: no chord equation is formed. A level's interior points are
    laid out as a (pieces, longest interior) array whose rows are padded with copies of
    their last interior point, so that a row's first maximum is its first farthest point
    (padding repeats a value, never precedes it); when the padding would outweigh the
    points (one long piece among many short ones) the rows are concatenated instead. A
    piece without interior points is padded with its first point, whose cross product is
    0: it is not split. The small per-level reductions run on Python lists (a numpy
    reduction costs more than the list on a few pieces).
    """
    done_s: List[np.ndarray] = []  # final pieces
    done_e: List[np.ndarray] = []
    mixed = False  # pieces out of order
    short = False  # pieces of less than min_span may be among them
    lone = e <= s  # runs of one point: no chord
    if np.count_nonzero(lone):
        short = True
        done_s.append(s[lone])
        done_e.append(e[lone])
        s, e = s[~lone], e[~lone]
    steps = None  # 1, 2, ... (made at the first array level, for the pieces' layout)
    while s.size:
        s_l, e_l = s.tolist(), e.tolist()
        cl = [b - a - 1 for a, b in zip(s_l, e_l)]  # interior points of every piece, >= 0
        width = max(cl)
        if width == 0:
            done_s.append(s)
            done_e.append(e)
            short = True
            break
        if sum(cl) <= _SPLIT_PY:  # few points left: finish piece by piece
            if not mixed:  # the runs themselves: index the points in place
                ps, pe = _split_py(px, py, tol, s_l, e_l, min_span)
                done_s.append(np.array(ps, dtype=np.int64))
                done_e.append(np.array(pe, dtype=np.int64))
                break
            idx, offs = _gather(s, e)  # the pieces' points (a shared split point twice)
            ps, pe = _split_py(px[idx], py[idx], tol[idx], offs[:-1].tolist(),
                               (offs[1:] - 1).tolist(), min_span)
            done_s.append(idx[ps])
            done_e.append(idx[pe])
            break
        if steps is None:  # the later pieces lie within these
            steps = np.arange(1, max(e_l) - min(s_l) + 1)
        x0, y0 = px[s], py[s]
        cx = px[e] - x0
        cy = py[e] - y0
        if s.size * width <= 2 * sum(cl) + 64:
            idx = s[:, None] + steps[:width]
            np.minimum(idx, (e - 1)[:, None], out=idx)  # pad with the last interior point
            cross = (px[idx] - x0[:, None]) * cy[:, None]
            cross -= (py[idx] - y0[:, None]) * cx[:, None]
            np.abs(cross, out=cross)  # eq. 4 distance times the chord length
            at = cross.argmax(axis=1)  # the first farthest point
            cmax = cross.ravel()[at + steps[:s.size] * width - width]
            at += s
            k = at + 1
        else:
            cnt = np.array(cl, dtype=np.int64)
            inner = cnt.nonzero()[0]
            cmax = np.zeros(s.size)
            k = s.copy()
            cnt = cnt[inner]
            offs = cnt.cumsum()
            total = int(offs[-1])
            offs -= cnt
            idx = (s[inner] + 1 - offs).repeat(cnt)
            idx += np.arange(total)
            cross = (px[idx] - x0[inner].repeat(cnt)) * cy[inner].repeat(cnt)
            cross -= (py[idx] - y0[inner].repeat(cnt)) * cx[inner].repeat(cnt)
            np.abs(cross, out=cross)
            cm = np.maximum.reduceat(cross, offs)
            at = (cross == cm.repeat(cnt)).nonzero()[0]
            cmax[inner] = cm
            k[inner] = idx[at[at.searchsorted(offs)]]  # the first farthest point
        split = cmax > tol[k] * np.hypot(cx, cy)
        go = split.nonzero()[0]
        if go.size < split.size:
            stop = ~split
            done_s.append(s[stop])
            done_e.append(e[stop])
            short = True
            if not go.size:
                break
            s, e, k = s[go], e[go], k[go]
        s = np.concatenate((s, k))  # pieces out of order from here on
        e = np.concatenate((k, e))
        mixed = True
    if not done_s:
        return np.zeros((2, 0), dtype=np.int64)
    if len(done_s) == 1 and not mixed:  # the runs' pieces, in order
        out = np.array((done_s[0], done_e[0]))
    else:
        s, e = np.concatenate(done_s), np.concatenate(done_e)
        order = np.lexsort((e, s))
        out = np.empty((2, s.size), dtype=np.int64)
        out[0] = s[order]
        out[1] = e[order]
    if short and min_span > 0:
        out = out[:, out[1] - out[0] >= min_span]
    return out


# Interior points of a recursion level up to which _split_py is faster than a numpy level
# (measured on 180- and 361-beam Carmen scans: the whole scan of one).
_SPLIT_PY = 400
# Interior points of a piece up to which _split_py finds its farthest point on Python
# floats rather than with array operations (measured).
_SPLIT_PIECE_PY = 48


def _split_py(px: np.ndarray, py: np.ndarray, tol: np.ndarray, s: List[int],
              e: List[int], min_span: int = 0) -> Tuple[List[int], List[int]]:
    """Split the pieces ``s[i]..e[i]`` as :func:`_split` does, one piece at a time.

    The same cross products in the same order (eq. 4 distance times the chord length, the
    first farthest point), on Python floats for small pieces and as arrays for large ones;
    depth first, left piece first. Returns the final pieces' first and last points, in
    order, without those of ``last - first < min_span``. The pieces index ``px``, ``py``
    and ``tol``, whose points are all listed (:func:`_split` passes the runs themselves,
    or the points of the pieces left after array levels).
    """
    pts = list(zip(px.tolist(), py.tolist()))  # (x, y) of every point: one slice a piece
    tol = memoryview(tol)
    small = _SPLIT_PIECE_PY
    out_s: List[int] = []
    out_e: List[int] = []
    stack = list(zip(s, e))
    stack.reverse()
    while stack:
        a, b = stack.pop()
        if b - a < 2:  # no interior point: no split
            if b - a >= min_span:
                out_s.append(a)
                out_e.append(b)
            continue
        x0, y0 = pts[a]
        x1, y1 = pts[b]
        cx, cy = x1 - x0, y1 - y0
        if b - a - 1 <= small:
            cross = [abs((x - x0) * cy - (y - y0) * cx) for x, y in pts[a + 1:b]]
            cmax = max(cross)
            k = a + 1 + cross.index(cmax)
        else:
            cross = px[a + 1:b] - x0
            cross *= cy
            dy = py[a + 1:b] - y0
            dy *= cx
            cross -= dy
            np.abs(cross, out=cross)
            k = int(cross.argmax())  # the first farthest point
            cmax = cross[k].item()
            k += a + 1
        if cmax > tol[k] * abs(complex(cx, cy)):  # C hypot, as np.hypot
            stack.append((k, b))
            stack.append((a, k))
        elif b - a >= min_span:
            out_s.append(a)
            out_e.append(b)
    return out_s, out_e


# ---------------------------------------------------------------------- ALFA
def alfa_pieces(xy: np.ndarray, offsets: np.ndarray, params: LineParams) -> np.ndarray:
    """Find line pieces by ALFA's split and merge with binary search (line chapter).

    ``xy`` are the smoothed points. Per run, from ``K_Min`` (its first point) the end
    ``a`` of the line is searched over ``[K_Min + min_points - 1, K_Max]``, starting in
    the middle of the remaining data. The fit of ``K_Min..a`` is judged by its RMSE
    (eq. 21, perpendicular residuals) and by the RMSE gradient, estimated as the RMSE
    growth per added point relative to the current threshold::

        g(a) = (RMSE(a) - RMSE(a - h)) / (h * Max_ERR),  h = max(2, min_points // 2)

    As in the pseudo code: a bad fit (``RMSE > Max_ERR`` or ``g > max_gradient``) moves
    the upper bound below ``a``; when the gradient was the reason, the threshold drops to
    the current RMSE (``Max_ERR = min(RMSE, Max_ERR)``). A good fit moves the lower bound
    to ``a`` and sets ``Max_ERR = mean(RMSE, Max_ERR)``. ``Max_ERR`` starts at ``rmse_max``
    for every line and stays within ``[rmse_min, rmse_max]`` (the floating threshold).
    The next candidate is ``ceil((b1 + b2) / 2)``, so the search always makes progress
    (the pseudo code's ``floor`` after a bad fit can test ``b1`` again). The largest
    accepted ``a`` ends the line; the next search starts at ``a + 1`` (the pseudo code's
    ``K_Min = a + 1``). If even the shortest line ``K_Min..K_Min + min_points - 1`` has
    an RMSE above ``rmse_max``, ``K_Min`` alone is dropped and the search restarts one
    point later (the pseudo code leaves this case open).

    Args:
        xy: (N, 2) smoothed points, runs back to back.
        offsets: (C + 1,) run boundaries.
        params: Line parameters (min_points, rmse bounds, max_gradient).

    Returns:
        (P, 2) int array of inclusive ``[first, last]`` indices, non-overlapping, in order.

    """
    least = params.min_points
    step = max(2, least // 2)
    lo_thr, hi_thr = params.rmse_bounds
    gmax = params.max_gradient
    out: List[Tuple[int, int]] = []
    xy = np.asarray(xy, dtype=float)
    bounds = np.asarray(offsets).tolist()
    sizes = [b - a for a, b in zip(bounds[:-1], bounds[1:])]
    # Each run's points relative to its mean (np.mean's sum and division), and their
    # monomials x, y, x^2, y^2, xy, all runs in one pass; the prefix sums of a run as in
    # _prefix5, as Python floats for the search.
    means = np.zeros((len(sizes), 2))
    for c, (c0, n_pts) in enumerate(zip(bounds, sizes)):
        if n_pts >= least:
            means[c] = np.add.reduce(xy[c0:c0 + n_pts], axis=0) / n_pts
    mono = np.empty((5, xy.shape[0]))
    np.subtract(xy, means.repeat(sizes, axis=0), out=mono[:2].T)
    np.multiply(mono[0], mono[0], out=mono[2])
    np.multiply(mono[1], mono[1], out=mono[3])
    np.multiply(mono[0], mono[1], out=mono[4])
    for c0, n_pts in zip(bounds, sizes):
        if n_pts < least:
            continue
        pre = np.zeros((5, n_pts + 1))
        np.cumsum(mono[:, c0:c0 + n_pts], axis=1, out=pre[:, 1:])
        sx, sy, sxx, syy, sxy = pre.tolist()

        def rmse(i: int, j: int) -> float:
            """Return the RMSE (eq. 21) of the TLS line through points i..j."""
            k = j + 1
            m = k - i
            mx = (sx[k] - sx[i]) / m
            my = (sy[k] - sy[i]) / m
            vxx = (sxx[k] - sxx[i]) / m - mx * mx
            vyy = (syy[k] - syy[i]) / m - my * my
            vxy = (sxy[k] - sxy[i]) / m - mx * my
            half = 0.5 * (vxx - vyy)
            lam = 0.5 * (vxx + vyy) - math.sqrt(half * half + vxy * vxy)
            return math.sqrt(lam) if lam > 0.0 else 0.0

        k_min, k_max = 0, n_pts - 1
        while k_max - k_min + 1 >= least:
            lo = k_min + least - 1
            if rmse(k_min, lo) > hi_thr:
                k_min += 1  # no line starts here
                continue
            max_err = hi_thr
            b1, b2 = lo, k_max
            a = max((k_min + k_max + 1) // 2, b1 + 1)  # the middle of the data
            while b2 > b1:
                err = rmse(k_min, a)
                if err > max_err:  # bad fit: split the recent data
                    b2 = a - 1  # (the gradient would not change Max_ERR: not computed)
                else:
                    grad = (err - rmse(k_min, max(a - step, k_min + 1))) / (step * max_err)
                    if grad > gmax:  # bad fit by the gradient: split, lower the threshold
                        b2 = a - 1
                        max_err = max(min(err, max_err), lo_thr)
                    else:  # satisfied: add a split of the remainder
                        b1 = a
                        max_err = min(max(0.5 * (err + max_err), lo_thr), hi_thr)
                a = (b1 + b2 + 1) // 2
            out.append((c0 + k_min, c0 + b1))
            k_min = b1 + 1
    if not out:
        return np.zeros((0, 2), dtype=np.int64)
    return np.array(out, dtype=np.int64)


# ---------------------------------------------------------------------- shared steps
@dataclass(frozen=True, eq=False)
class _Scan:
    """All clusters of a scan back to back, coordinates relative to ``origin`` (internal).

    ``cols`` holds one row per point attribute (see the ``_X`` .. ``_PHI`` row numbers), so
    that one gather takes all of them; ``x`` and ``y`` are views of its rows.
    """

    cols: np.ndarray  # (7, N)
    x: np.ndarray
    y: np.ndarray
    origin: Tuple[float, float]
    beam: np.ndarray
    cluster: np.ndarray  # (N,) cluster number of each point
    offsets: np.ndarray
    nbeam: int  # largest beam index + 1
    whole: Optional[ScanArrays] = None  # the whole scan, when the clusters share it
    _rows: list = field(default_factory=list, repr=False)  # cache of rows()

    def rows(self) -> List[memoryview]:
        """Return the rows of ``cols`` for the Python-float paths (indexing gives floats).

        Memory views, not lists: those paths read a few points of a row, and a list would
        make a Python float of every point.
        """
        if not self._rows:
            self._rows.extend(memoryview(row) for row in self.cols)
        return self._rows

    def beams(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return range, cos, sin and validity of every beam, by beam index.

        From the whole scan when known (also the beams of no cluster: dropped small
        clusters, returns the segmentation left out), else from the clusters' points alone
        (beams of no cluster count as missing).
        """
        w = self.whole
        if w is not None:
            return w.ranges, w.cos, w.sin, w.valid
        size = self.nbeam
        out = np.zeros((3, size))
        out[:, self.beam] = self.cols[_RNG:_TOL]
        valid = np.zeros(size, dtype=bool)
        valid[self.beam] = np.isfinite(self.cols[_RNG]) & (self.cols[_RNG] > 0.0)
        return out[0], out[1], out[2], valid


# Rows of _Scan.cols: point coordinates relative to the origin, range, cos and sin of the
# bearing, split tolerance (threshold + 3 sigma_phi r), bearing.
_X, _Y, _RNG, _COS, _SIN, _TOL, _PHI = range(7)


def _concat(clusters: Sequence[Cluster], params: LineParams) -> Optional[_Scan]:
    """Stack the non-empty clusters; None if there are none."""
    cl, bounds, sizes = [], [0], []
    for c in clusters:
        size = c.indices.size
        if size:
            cl.append(c)
            sizes.append(size)
            bounds.append(bounds[-1] + size)
    if not cl:
        return None
    offsets = np.array(bounds, dtype=np.int64)
    n = bounds[-1]
    cols = np.empty((7, n))
    whole = cl[0].scan
    one = whole is not None and all(c.scan is whole for c in cl)  # of one segment_scan call
    if one and all(c.points.base is whole.points for c in cl):
        # Clusters of one segment_scan call: gather from its whole-scan arrays.
        beam = np.concatenate([c.indices for c in cl], dtype=np.int64)
        xy = whole.points.take(beam, axis=0)
        whole.ranges.take(beam, out=cols[_RNG])
        whole.cos.take(beam, out=cols[_COS])
        whole.sin.take(beam, out=cols[_SIN])
        whole.angles.take(beam, out=cols[_PHI])
    else:
        beam = np.concatenate([c.indices for c in cl], dtype=np.int64)
        xy = np.concatenate([c.points for c in cl], dtype=float).reshape(-1, 2)
        cols[_RNG] = np.concatenate([c.ranges for c in cl], dtype=float)
        cols[_PHI] = np.concatenate([c.angles for c in cl], dtype=float)
        np.cos(cols[_PHI], out=cols[_COS])
        np.sin(cols[_PHI], out=cols[_SIN])
    ox, oy = (xy.cumsum(axis=0)[-1] / n).tolist()  # the mean (summed in point order)
    np.subtract(xy[:, 0], ox, out=cols[_X])
    np.subtract(xy[:, 1], oy, out=cols[_Y])
    np.multiply(cols[_RNG], 3.0 * params.sigma_phi, out=cols[_TOL])  # split tolerance
    cols[_TOL] += params.threshold
    shared = whole if one and whole.valid is not None else None
    return _Scan(cols, cols[_X], cols[_Y], (ox, oy), beam,
                 np.arange(len(cl)).repeat(sizes), offsets,
                 int(beam.max()) + 1, shared)


def _sse(pre: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Return the TLS sum of squared perpendicular residuals of points lo..hi (inclusive)."""
    n = (hi - lo + 1).astype(float)
    s = pre.take(hi + 1, axis=1)
    s -= pre.take(lo, axis=1)
    m = s[:2] / n  # mx, my
    nm = n * m
    c = s[2:4] - nm * m  # cxx = sxx - n mx mx, cyy likewise
    cxy = s[4] - nm[0] * m[1]
    half = 0.5 * (c[0] - c[1])
    out = 0.5 * (c[0] + c[1]) - np.sqrt(half * half + cxy * cxy)
    return np.maximum(out, 0.0, out=out)


def _refine_breaks(scan: _Scan, pre: np.ndarray, s: np.ndarray, e: np.ndarray, reach: int
                   ) -> Tuple[np.ndarray, np.ndarray]:
    """Move every break between adjacent pieces to where both fits are best (step 1).

    Pieces ``[lo, b]`` and ``[b + o, hi]`` (o = 0 for a shared split point, 1 for
    abutting pieces) of one cluster get the break ``b'`` within ``reach`` of ``b`` that
    minimises ``SSE(lo..b') + SSE(b' + o..hi)``, both pieces keeping at least 3 points.
    Returns the new first and last points of the pieces.
    """
    if s.size < 2:
        return s, e
    o = s[1:] - e[:-1]
    adj = ((o >= 0) & (o <= 1) & (scan.cluster[s[1:]] == scan.cluster[e[:-1]])).nonzero()[0]
    if not adj.size:
        return s, e
    s, e = s.copy(), e.copy()
    width = 2 * reach + 1
    # (lo, b, hi, o) of every pair, once per candidate break (no broadcasting below)
    lo, b, hi, oo = np.array((s[adj], e[adj], e[adj + 1], o[adj])).repeat(
        width, axis=1).reshape(4, adj.size, width)
    cand = b + np.arange(-reach, reach + 1)
    ok = (cand - lo >= 2) & (hi - cand - oo >= 2)
    cand = np.where(ok, cand, b)
    # Both pieces of every candidate break in one batch: [lo, b'] and [b' + o, hi].
    first = np.empty((2,) + cand.shape, dtype=np.int64)
    last = np.empty_like(first)
    first[0] = lo
    np.add(cand, oo, out=first[1])
    last[0] = cand
    last[1] = hi
    sse = _sse(pre, first, last)
    cost = np.where(ok, sse[0] + sse[1], np.inf)
    best = cand.ravel()[cost.argmin(axis=1) + np.arange(0, cost.size, width)]
    e[adj] = best
    s[adj + 1] = best + o[adj]
    good = e - s >= 2  # breaks of a chain moved past each other: drop the squeezed piece
    if np.count_nonzero(good) == good.size:
        return s, e
    return s[good], e[good]


def _clean_pieces(scan: _Scan, pre: np.ndarray, s: np.ndarray, e: np.ndarray,
                  params: LineParams) -> Tuple[np.ndarray, np.ndarray]:
    """Trim outlying ends, give shared split points to one piece, drop short ones (step 2).

    Returns the first and last points of the pieces of at least ``min_points`` points.
    """
    if not s.size:
        return s, e
    if s.size <= _CLEAN_PY:
        return _clean_pieces_py(scan, pre, s, e, params)
    sums = np.empty((6, s.size))
    sums[0] = e - s + 1
    np.subtract(pre.take(e + 1, axis=1), pre.take(s, axis=1), out=sums[1:])
    cx, cy, sxx, syy, sxy = _scatter(sums)
    nrm = np.empty((2, s.size))
    _normal(sxx, syy, sxy, nrm)
    nx, ny = nrm
    # rho of the line relative to the scan origin (|distances| do not depend on the sign
    # of the normal, so the fit is not flipped to rho >= 0 here)
    ox, oy = scan.origin
    rho = (cx + ox) * nx + (cy + oy) * ny - nx * ox - ny * oy
    gate = params.trim_sigma
    reach = params.min_points
    steps = np.arange(reach)
    win = np.empty((s.size, 2 * reach), dtype=np.int64)
    np.minimum(s[:, None] + steps, e[:, None], out=win[:, :reach])
    np.maximum(e[:, None] - steps, s[:, None], out=win[:, reach:])
    z = _z(scan, nx, ny, rho, win, params)
    # leading (head) and trailing (tail) runs of outlying points
    lead, trail = (z > gate).reshape(s.size, 2, reach).cumprod(axis=2).sum(axis=2).T
    ns, ne = s + lead, e - trail
    # A split point shared by consecutive pieces goes to the piece it fits better.
    shared = ((e[:-1] >= s[1:]) & (ne[:-1] >= ns[1:])).nonzero()[0]
    if shared.size:
        to_prev = z[shared, reach] <= z[shared + 1, 0]
        ns[shared + 1] = np.where(to_prev, ne[shared] + 1, ns[shared + 1])
        ne[shared] = np.where(to_prev, ne[shared], ns[shared + 1] - 1)
    # Too short to be a line (min_points >= 3): their fits are too uncertain for the merge
    # test (the (rho, alpha) linearisation fails for them); their points stay free for
    # the lines to grow.
    keep = ne - ns + 1 >= params.min_points
    return ns[keep], ne[keep]


# Pieces up to which _clean_pieces_py is faster than the array operations (measured).
_CLEAN_PY = 40


def _clean_pieces_py(scan: _Scan, pre: np.ndarray, s: np.ndarray, e: np.ndarray,
                     params: LineParams) -> Tuple[np.ndarray, np.ndarray]:
    """Return :func:`_clean_pieces` computed on Python floats.

    The same operations in the same order (the fits of eqs. 8-9 from the prefix sums,
    the point tests of :func:`_z`), but only the points up to the first one within the
    gate are tested at each end (the array version tests ``min_points`` at each end), and
    a piece of fewer than ``min_points`` points (dropped in any case: the clean-up only
    shortens pieces) is fitted only when it shares its split point with a longer piece,
    whose end it may take or give; the others keep their ends, which touch no kept piece.
    """
    s_l, e_l = s.tolist(), e.tolist()
    least = params.min_points
    size = len(s_l)
    big = [b - a >= least - 1 for a, b in zip(s_l, e_l)]
    touch = [b >= a for b, a in zip(e_l, s_l[1:])]  # piece j shares its last point
    fitted = [j for j in range(size) if big[j] or (j and touch[j - 1] and big[j - 1])
              or (j < size - 1 and touch[j] and big[j + 1])]
    p1, p2, p3, p4, p5 = [memoryview(row) for row in pre]
    scat, a_in, b_in = [], [], []
    for j in fitted:  # _scatter of the sums from the prefix sums
        a, b = s_l[j], e_l[j] + 1
        n = float(b - a)
        cx = (p1[b] - p1[a]) / n
        cy = (p2[b] - p2[a]) / n
        ncx = n * cx
        sxx = (p3[b] - p3[a]) - ncx * cx
        syy = (p4[b] - p4[a]) - n * cy * cy
        sxy = (p5[b] - p5[a]) - ncx * cy
        scat.append((cx, cy))
        a_in.append(-2.0 * sxy)
        b_in.append(syy - sxx)
    if _MATH_TRIG:  # numpy's results (see _math_is_numpy)
        alpha = [0.5 * a for a in map(math.atan2, a_in, b_in)]  # eq. 8 (_normal)
        nxs, nys = list(map(math.cos, alpha)), list(map(math.sin, alpha))
    else:
        alpha = 0.5 * np.arctan2(a_in, b_in)  # eq. 8 (_normal)
        nxs, nys = np.cos(alpha).tolist(), np.sin(alpha).tolist()
    xs, ys, rng, cps, sps = scan.rows()[:_TOL]
    ox, oy = scan.origin
    sr, sp_ = params.sigma_r, params.sigma_phi
    gate = params.trim_sigma
    reach = params.min_points

    def z(i: int, nx: float, ny: float, rho: float) -> float:
        """Return :func:`_z` of point i to one line."""
        d = xs[i] * nx + ys[i] * ny - rho
        cp, sp = cps[i], sps[i]
        a = sr * (nx * cp + ny * sp)
        b = rng[i] * sp_ * (ny * cp - nx * sp)
        return abs(d) / math.sqrt(max(a * a + b * b, 1e-24))

    ns, ne = s_l[:], e_l[:]
    z_first, z_last = [math.inf] * size, [math.inf] * size
    for i, j in enumerate(fitted):
        a, b = s_l[j], e_l[j]
        nx, ny = nxs[i], nys[i]
        cx, cy = scat[i]
        # rho of the line relative to the scan origin (see _clean_pieces)
        rho = (cx + ox) * nx + (cy + oy) * ny - nx * ox - ny * oy
        za, zb = z(a, nx, ny, rho), z(b, nx, ny, rho)
        z_first[j] = za
        z_last[j] = zb
        lead = 0  # leading outliers among the first `reach` points (clipped at b)
        while lead < reach and (za if lead == 0 else zb if a + lead >= b
                                else z(a + lead, nx, ny, rho)) > gate:
            lead += 1
        trail = 0
        while trail < reach and (zb if trail == 0 else za if b - trail <= a
                                 else z(b - trail, nx, ny, rho)) > gate:
            trail += 1
        ns[j] = a + lead
        ne[j] = b - trail
    # A split point shared by consecutive pieces goes to the piece it fits better.
    shared = [j for j in range(size - 1) if touch[j] and ne[j] >= ns[j + 1]]
    if shared:
        ne0 = ne[:]
        to_prev = [z_last[j] <= z_first[j + 1] for j in shared]
        for j, prev in zip(shared, to_prev):
            if prev:
                ns[j + 1] = ne0[j] + 1
        for j, prev in zip(shared, to_prev):
            if not prev:
                ne[j] = ns[j + 1] - 1
    keep = [j for j in range(size) if ne[j] - ns[j] + 1 >= least]
    return (np.array([ns[j] for j in keep], dtype=np.int64),
            np.array([ne[j] for j in keep], dtype=np.int64))


def _z(scan: _Scan, nx: np.ndarray, ny: np.ndarray, rho: np.ndarray, pts: np.ndarray,
       params: LineParams) -> np.ndarray:
    """Return |distance| / std (eq. 7 on the normal) of points pts (L, K) to the L lines.

    ``rho`` is relative to the scan origin.
    """
    x, y, rng, cp, sp = scan.cols[:_TOL].take(pts, axis=1)
    # the lines' parameters once per point (no broadcasting below)
    nx, ny, rho = np.array((nx, ny, rho)).repeat(pts.shape[1], axis=1).reshape((3,) + pts.shape)
    d = x * nx + y * ny - rho
    n_u = nx * cp + ny * sp
    n_v = ny * cp - nx * sp
    var = (params.sigma_r * n_u) ** 2 + (rng * params.sigma_phi * n_v) ** 2
    return np.abs(d) / np.sqrt(np.maximum(var, 1e-24))


def _chi2(rho1: np.ndarray, alpha1: np.ndarray, cov1: np.ndarray, rho2: np.ndarray,
          alpha2: np.ndarray, cov2: Optional[np.ndarray]) -> np.ndarray:
    """Return ``d^2 = dp^T (C1 + C2)^-1 dp`` for line pairs (the merge test statistic).

    ``cov2`` None means exact lines 2 (``C2 = 0``). Pairs whose summed covariance is not
    positive definite get ``inf``.
    """
    da = _wrap(alpha1 - alpha2)
    # Lines near the origin may come with opposite normals: compare (-rho, alpha + pi).
    opposite = np.abs(da) > 0.5 * math.pi
    dr = rho1 - rho2
    c00, c11, c01 = cov1[:, 0, 0], cov1[:, 1, 1], cov1[:, 0, 1]
    if cov2 is not None:
        c00 = c00 + cov2[:, 0, 0]
        c11 = c11 + cov2[:, 1, 1]
    if np.count_nonzero(opposite):
        dr = np.where(opposite, rho1 + rho2, dr)
        da = np.where(opposite, _wrap(da + math.pi), da)
        if cov2 is not None:
            c01 = c01 + np.where(opposite, -1.0, 1.0) * cov2[:, 0, 1]
    elif cov2 is not None:
        c01 = c01 + cov2[:, 0, 1]
    det = c00 * c11 - c01 * c01
    d2 = (c11 * dr * dr - 2.0 * c01 * dr * da + c00 * da * da) / det
    return np.where((det > 0.0) & (d2 > -np.inf) & ~np.isnan(d2), d2, np.inf)


_Z95 = 1.6448536269514722  # standard normal 95 % quantile


def _variance_factor(sums: np.ndarray, f: _Fit) -> np.ndarray:
    """Return (G,) a-posteriori variance factors of fits whose residuals reject eq. 7.

    The residual sum of squares of a fit of n points, divided by the mean variance of
    the points' distances to the line (eq. 7 on the normal), is chi-square with n - 2
    degrees of freedom when the stated noise holds. Where it exceeds the 95 % quantile
    (Wilson-Hilferty approximation) the points are noisier than stated (e.g. a SICK in cm
    mode, a rough or dark wall) and the factor is the ratio of the residual variance to
    the stated one; elsewhere 1.
    """
    n = f.count
    nx, ny = f.nx, f.ny
    var = (nx * nx * sums[6] + ny * ny * sums[12] + 2.0 * nx * ny * sums[18]) / n
    dof = np.maximum(n - 2.0, 1.0)
    stat = n * f.rmse * f.rmse / var  # RSS / sigma^2
    h = 2.0 / (9.0 * dof)
    q95 = dof * (1.0 - h + _Z95 * np.sqrt(h)) ** 3
    return np.where(stat > q95, stat / dof, 1.0)


def _variance_factor_py(sums: np.ndarray, f: _Fit, nx_l: List[float], ny_l: List[float]
                        ) -> List[float]:
    """Return :func:`_variance_factor` on Python floats (the same operations).

    ``nx_l``, ``ny_l`` are the fits' normals as lists. Raises ZeroDivisionError on
    degenerate fits (the array version then gives numpy's inf / nan).
    """
    s6, s12, s18 = sums[6:19:6].tolist()
    stats, dofs, bases = [], [], []
    for n, r, nx, ny, a, b, c in zip(f.count.tolist(), f.rmse.tolist(), nx_l, ny_l, s6, s12,
                                     s18):
        var = (nx * nx * a + ny * ny * b + 2.0 * nx * ny * c) / n
        dof = max(n - 2.0, 1.0)
        stats.append(n * r * r / var)  # RSS / sigma^2
        h = 2.0 / (9.0 * dof)
        dofs.append(dof)
        bases.append(1.0 - h + _Z95 * math.sqrt(h))
    if _MATH_TRIG:  # numpy's power (see _math_is_numpy), as _variance_factor
        cubes = [b ** 3 for b in bases]
    else:
        cubes = (np.array(bases) ** 3).tolist()  # numpy's power, as _variance_factor
    return [stat / dof if stat > dof * cube else 1.0
            for stat, dof, cube in zip(stats, dofs, cubes)]


# Pieces up to which _pairs_py is faster than the array operations (measured).
_PAIRS_PY = 40


def _pairs_py(scan: _Scan, sums: np.ndarray, f: _Fit, s: np.ndarray, e: np.ndarray,
              params: LineParams) -> Tuple[_Fit, List[bool]]:
    """Return the fits with scaled covariances and the merge test of consecutive pieces.

    :func:`_variance_factor` and the first merge test of :func:`_merge` (neighbours whose
    :func:`_chi2` passes the gate) on Python floats, the same operations in the same
    order. Raises ZeroDivisionError on degenerate fits (the array versions then give
    numpy's inf / nan).
    """
    rho_l, alpha_l, nx_l, ny_l = f.params.tolist()
    cov = f.cov * np.array(_variance_factor_py(sums, f, nx_l, ny_l))[:, None, None]
    f = _Fit(f.params, f.rmse, f.count, cov)
    c00, c01, _, c11 = cov.reshape(-1, 4).T.tolist()
    xs, ys, phi = scan.rows()[_X], scan.rows()[_Y], scan.rows()[_PHI]
    cluster = memoryview(scan.cluster)
    gap2, gap_angle, gate = params.merge_gap ** 2, params.merge_gap_angle, params.merge_chi2
    pi = math.pi
    join = []
    for j, (p0, p1) in enumerate(zip(e[:-1].tolist(), s[1:].tolist())):  # facing ends
        gx, gy = xs[p1] - xs[p0], ys[p1] - ys[p0]
        if not (cluster[p0] == cluster[p1] or gx * gx + gy * gy <= gap2
                or abs(phi[p1] - phi[p0]) <= gap_angle):
            join.append(False)
            continue
        # _chi2 of the pair
        da = (alpha_l[j] - alpha_l[j + 1] + pi) % TWO_PI - pi
        a00, a11 = c00[j] + c00[j + 1], c11[j] + c11[j + 1]
        if abs(da) > 0.5 * pi:  # opposite normals: compare (-rho, alpha + pi)
            dr = rho_l[j] + rho_l[j + 1]
            da = (da + pi + pi) % TWO_PI - pi
            a01 = c01[j] + -1.0 * c01[j + 1]
        else:
            dr = rho_l[j] - rho_l[j + 1]
            a01 = c01[j] + c01[j + 1]
        det = a00 * a11 - a01 * a01
        if not det > 0.0:
            join.append(False)
            continue
        d2 = (a11 * dr * dr - 2.0 * a01 * dr * da + a00 * da * da) / det
        join.append(-math.inf < d2 <= gate)
    return f, join


def _merge(scan: _Scan, feats: np.ndarray, s: np.ndarray, e: np.ndarray, params: LineParams
           ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, _Fit, np.ndarray]:
    """Merge collinear neighbours (step 3); return sums (24, L), first, last, fits, labels.

    The pieces ``[s, e]`` must be sorted and disjoint. ``first``/``last`` are the outermost
    point indices of each line (a merged line does not use the points between its pieces);
    ``labels`` gives the line of each piece. The fits have no covariance when lines were
    merged (they are refitted after growing).
    """
    bounds = np.empty(2 * s.size, dtype=np.int64)
    bounds[0::2] = s
    bounds[1::2] = e + 1
    sums = np.add.reduceat(feats, bounds, axis=1)[:, 0::2]
    f = _solve(sums, scan.origin)
    if s.size == 1:
        return sums, s, e, f, np.zeros(1, dtype=np.int64)
    gate = params.merge_chi2
    pairs = None
    if s.size <= _PAIRS_PY:
        try:
            pairs = _pairs_py(scan, sums, f, s, e, params)
        except ZeroDivisionError:  # degenerate fits: numpy's inf / nan below
            pass
    if pairs is None:
        f = _Fit(f.params, f.rmse, f.count, f.cov * _variance_factor(sums, f)[:, None, None])
        gap = scan.cols.take(s[1:], axis=1) - scan.cols.take(e[:-1], axis=1)
        near = ((scan.cluster[s[1:]] == scan.cluster[e[:-1]])
                | (gap[_X] * gap[_X] + gap[_Y] * gap[_Y] <= params.merge_gap ** 2)
                | (np.abs(gap[_PHI]) <= params.merge_gap_angle))
        join = near & (_chi2(f.rho[:-1], f.alpha[:-1], f.cov[:-1], f.rho[1:], f.alpha[1:],
                             f.cov[1:]) <= gate)
    else:
        f, join_l = pairs
        if not any(join_l):
            return sums, s, e, f, np.arange(s.size)
        return _merge_chains_py(scan, sums, s, e, f, join_l, gate)
    if not np.count_nonzero(join):
        return sums, s, e, f, np.arange(s.size)
    ends = np.empty((2, s.size), dtype=np.int64)
    ends[0] = s
    ends[1] = e
    x, y, _, _, _, tol = scan.cols[:_PHI].take(ends, axis=1)
    ox, oy = scan.origin
    while np.count_nonzero(join):
        new = np.empty(s.size, dtype=bool)
        new[0] = True
        np.logical_not(join, out=new[1:])
        g_start = new.nonzero()[0]
        g_end = np.empty_like(g_start)
        np.subtract(g_start[1:], 1, out=g_end[:-1])
        g_end[-1] = s.size - 1
        label = new.cumsum() - 1
        g_sums = np.add.reduceat(sums, g_start, axis=1)
        g = _solve(g_sums[:6], scan.origin, rmse=False)
        # Every member must agree with its merged line: chi-square (the merged line taken
        # as exact) and both of its end points within the split tolerance. badness > 1
        # fails either test.
        rho_g, alpha_g, nx, ny = g.params.take(label, axis=1)
        badness = _chi2(f.rho, f.alpha, f.cov, rho_g, alpha_g, None) / gate
        dist = np.abs(x * nx + y * ny - (rho_g - nx * ox - ny * oy)) / tol
        np.fmax(badness, dist.max(axis=0), out=badness)
        badness[~(g_end > g_start)[label]] = 0.0  # single pieces are not merged
        worst = np.maximum.reduceat(badness, g_start)
        if not np.count_nonzero(worst > 1.0):
            return g_sums, s[g_start], e[g_end], g, label
        # The worst member of a failing chain leaves it; the rest are merged again (a
        # piece off its wall, e.g. a short noisy fit between two pieces of the wall, no
        # longer keeps the wall in pieces).
        out = ((badness == worst[label]) & (worst > 1.0)[label]).nonzero()[0]
        join[out[out < s.size - 1]] = False
        join[out[out > 0] - 1] = False
    return sums, s, e, f, np.arange(s.size)


def _merge_chains_py(scan: _Scan, sums: np.ndarray, s: np.ndarray, e: np.ndarray, f: _Fit,
                     join: List[bool], gate: float
                     ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, _Fit, np.ndarray]:
    """Return :func:`_merge`'s result from the passing pairs ``join``, on Python floats.

    The chain loop of :func:`_merge` (members tested against their merged line with
    :func:`_chi2` and the split tolerance at their end points, the worst member of a
    failing chain leaving it), the same operations in the same order; the merged lines
    are fitted by :func:`_solve`.
    """
    size = s.size
    xs, ys, tols = scan.rows()[_X], scan.rows()[_Y], scan.rows()[_TOL]
    s_l, e_l = s.tolist(), e.tolist()
    rho_l, alpha_l = f.params[:2].tolist()
    c00, c01, _, c11 = f.cov.reshape(-1, 4).T.tolist()
    ox, oy = scan.origin
    pi, inf = math.pi, math.inf
    while any(join):
        starts = [0] + [i + 1 for i in range(size - 1) if not join[i]]
        ends = [i - 1 for i in starts[1:]] + [size - 1]
        label = []
        for k, (a, b) in enumerate(zip(starts, ends)):
            label += [k] * (b - a + 1)
        g_sums = np.add.reduceat(sums, starts, axis=1)
        g = _solve(g_sums[:6], scan.origin, rmse=False)
        rho_g, alpha_g, nx_g, ny_g = g.params.tolist()
        badness = []
        for i, k in enumerate(label):
            if starts[k] == ends[k]:  # single pieces are not merged
                badness.append(0.0)
                continue
            # _chi2 against the merged line taken as exact
            rg = rho_g[k]
            da = (alpha_l[i] - alpha_g[k] + pi) % TWO_PI - pi
            if abs(da) > 0.5 * pi:
                dr = rho_l[i] + rg
                da = (da + pi + pi) % TWO_PI - pi
            else:
                dr = rho_l[i] - rg
            a00, a01, a11 = c00[i], c01[i], c11[i]
            det = a00 * a11 - a01 * a01
            d2 = inf
            if det > 0.0:
                d2 = (a11 * dr * dr - 2.0 * a01 * dr * da + a00 * da * da) / det
                if d2 != d2 or d2 == -inf:
                    d2 = inf
            bad = d2 / gate
            nx, ny = nx_g[k], ny_g[k]
            rel = rg - nx * ox - ny * oy
            pa, pb = s_l[i], e_l[i]
            d0 = abs(xs[pa] * nx + ys[pa] * ny - rel) / tols[pa]
            d1 = abs(xs[pb] * nx + ys[pb] * ny - rel) / tols[pb]
            dist = d0 if d0 >= d1 else d1
            if d0 != d0 or d1 != d1:
                dist = math.nan
            if dist > bad:  # np.fmax
                bad = dist
            badness.append(bad)
        worst = [max(badness[a:b + 1]) for a, b in zip(starts, ends)]
        if not any(w > 1.0 for w in worst):
            return (g_sums, np.array([s_l[a] for a in starts], dtype=np.int64),
                    np.array([e_l[b] for b in ends], dtype=np.int64), g,
                    np.array(label, dtype=np.int64))
        # The worst member of a failing chain leaves it (see _merge).
        for i, k in enumerate(label):
            if worst[k] > 1.0 and badness[i] == worst[k]:
                if i < size - 1:
                    join[i] = False
                if i > 0:
                    join[i - 1] = False
    return sums, s, e, f, np.arange(size)


def _grow(scan: _Scan, feats: np.ndarray, sums: np.ndarray, first: np.ndarray,
          last: np.ndarray, f: _Fit, params: LineParams
          ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Grow the lines f over the free points beside them that fit (step 4).

    Free points are those of no line, also in other (small) clusters. A line takes the
    run of consecutive free points next to its ends whose distance to it is within
    ``trim_sigma`` standard deviations (eq. 7) and within the split tolerance, and whose
    bearing steps stay within ``merge_gap_angle``; a gap claimed from both sides goes
    first to the line before it. Returns the new sums, first, last and whether any grew.
    """
    gate = params.trim_sigma
    if not math.isfinite(gate):
        return sums, first, last, False
    n_pts = scan.x.size
    n_lines = first.size
    if n_lines <= _GROW_PY:  # (an empty gap gives no run)
        first_l, last_l = first.tolist(), last.tolist()
        run_f, run_b = _grow_runs_py(scan, f, first_l, last_l, params)
        if not (any(run_f) or any(run_b)):
            return sums, first, last, False
        return _grown_py(feats, sums, first_l, last_l, run_f, run_b)
    lo = np.empty(n_lines + 1, dtype=np.int64)  # gap k: points lo[k] .. hi[k] - 1, between
    hi = np.empty(n_lines + 1, dtype=np.int64)  # line k - 1 and line k
    lo[0] = 0
    np.add(last, 1, out=lo[1:])
    hi[:-1] = first
    hi[-1] = n_pts
    size = hi - lo
    gaps = (size > 0).nonzero()[0]
    if not gaps.size:
        return sums, first, last, False
    size_g = size[gaps]
    starts = size_g.cumsum() - size_g
    pos = np.arange(starts[-1] + size_g[-1])
    within = pos - starts.repeat(size_g)  # position in the gap
    idx = within + lo[gaps].repeat(size_g)
    # row 0: the line before the gap growing forward, row 1: the line after it, backward
    owner = np.empty((2, gaps.size), dtype=np.int64)
    np.subtract(gaps, 1, out=owner[0])
    owner[1] = gaps
    has = (owner >= 0) & (owner < n_lines)
    clipped = np.minimum(np.maximum(owner, 0), n_lines - 1)
    rho, _, nx, ny = f.params.take(clipped.repeat(size_g, axis=1), axis=1)
    x, y, rng, cp, sp, tol = scan.cols[:_PHI].take(idx, axis=1)
    ox, oy = scan.origin
    d = (x + ox) * nx + (y + oy) * ny - rho
    n_u = nx * cp + ny * sp
    n_v = ny * cp - nx * sp
    var = (params.sigma_r * n_u) ** 2 + (rng * params.sigma_phi * n_v) ** 2
    ok = has.repeat(size_g, axis=1) & (d * d <= gate * gate * var) & (np.abs(d) <= tol)
    # Bearing steps: step[i] is the step from point i - 1 to i (True at both scan ends);
    # row 0 steps onto each point, row 1 off it.
    phi = scan.cols[_PHI]
    step = np.ones(n_pts + 1, dtype=bool)
    np.less_equal(np.abs(phi[1:] - phi[:-1]), params.merge_gap_angle, out=step[1:-1])
    ok &= step[idx + _NEXT]
    # run_f: leading run of row 0 (to the first miss), run_b: trailing run of row 1
    run_f = np.minimum(np.minimum.reduceat(np.where(ok[0], pos.size, within), starts), size_g)
    run_b = np.minimum(size_g - 1 - np.maximum.reduceat(np.where(ok[1], -1, within), starts),
                       size_g - run_f)
    if not (np.count_nonzero(run_f) or np.count_nonzero(run_b)):
        return sums, first, last, False
    grow = np.zeros((2, n_lines + 1), dtype=np.int64)  # by gap: forward, backward
    grow[0, gaps] = run_f
    grow[1, gaps] = run_b
    return _grown(feats, sums, first, last, grow)


# Lines up to which _grow_runs_py is faster than the array operations (measured).
_GROW_PY = 40


def _grow_runs_py(scan: _Scan, f: _Fit, first: List[int], last: List[int],
                  params: LineParams) -> Tuple[List[int], List[int]]:
    """Return the runs of free points each gap gives to its lines (see :func:`_grow`).

    Per gap (before line 0, between consecutive lines, after the last line) the number of
    points the line before it takes forward and the line after it takes backward, found by
    walking from the gap's ends to the first point that fails (the same tests, the same
    operations as the array version of :func:`_grow`, on Python floats).
    """
    xs, ys, rng, cps, sps, tols, phi = scan.rows()
    rhos, _, nxs, nys = f.params.tolist()
    ox, oy = scan.origin
    gg = params.trim_sigma * params.trim_sigma
    sr, sp_ = params.sigma_r, params.sigma_phi
    angle = params.merge_gap_angle
    n_pts, n_lines = len(xs), len(first)

    def fits(i: int, j: int) -> bool:
        """Return whether point i is within the gates of line j (eq. 7 on the normal)."""
        nx, ny = nxs[j], nys[j]
        d = (xs[i] + ox) * nx + (ys[i] + oy) * ny - rhos[j]
        cp, sp = cps[i], sps[i]
        a = sr * (nx * cp + ny * sp)
        b = rng[i] * sp_ * (ny * cp - nx * sp)
        return d * d <= gg * (a * a + b * b) and abs(d) <= tols[i]

    run_f, run_b = [0] * (n_lines + 1), [0] * (n_lines + 1)
    for k in range(n_lines + 1):
        lo = last[k - 1] + 1 if k else 0
        hi = first[k] if k < n_lines else n_pts
        i = lo
        if k:  # the line before the gap, forward
            while i < hi and (i == 0 or abs(phi[i] - phi[i - 1]) <= angle) and fits(i, k - 1):
                i += 1
        run_f[k] = i - lo
        if k < n_lines:  # the line after it, backward (after the forward run)
            m = hi - 1
            while m >= i and (m + 1 == n_pts or abs(phi[m + 1] - phi[m]) <= angle) and fits(m, k):
                m -= 1
            run_b[k] = hi - 1 - m
    return run_f, run_b


def _grown(feats: np.ndarray, sums: np.ndarray, first: np.ndarray, last: np.ndarray,
           grow: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Return :func:`_grow`'s sums, first, last, True for the runs ``grow`` (2, gaps)."""
    n_lines = first.size
    new_first, new_last = first - grow[1, :-1], last + grow[0, 1:]
    # Sums of the added ranges (disjoint, in order): [new_first, first) and (last, new_last].
    add_lo = np.empty(2 * n_lines, dtype=np.int64)
    add_hi = np.empty(2 * n_lines, dtype=np.int64)  # exclusive
    add_lo[0::2] = new_first
    np.add(last, 1, out=add_lo[1::2])
    add_hi[0::2] = first
    np.add(new_last, 1, out=add_hi[1::2])
    nonempty = add_hi > add_lo
    bounds = np.empty(2 * int(nonempty.sum()), dtype=np.int64)
    bounds[0::2] = add_lo[nonempty]
    bounds[1::2] = add_hi[nonempty]
    added = np.zeros((NUM_SUMS, 2 * n_lines))
    added[:, nonempty] = np.add.reduceat(feats, bounds, axis=1)[:, 0::2]
    return sums + added[:, 0::2] + added[:, 1::2], new_first, new_last, True


def _grown_py(feats: np.ndarray, sums: np.ndarray, first: List[int], last: List[int],
              run_f: List[int], run_b: List[int]
              ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Return :func:`_grown` for the runs of :func:`_grow_runs_py`, laid out in Python.

    The same sums (one ``reduceat`` over the same non-empty ranges, in the same order,
    added to the lines' sums as there); only the index bookkeeping runs on lists.
    """
    n_lines = len(first)
    new_first = [a - run_b[j] for j, a in enumerate(first)]
    new_last = [b + run_f[j + 1] for j, b in enumerate(last)]
    bounds: List[int] = []  # the added ranges [lo, hi), in order: before line j, after it
    cols: List[int] = []
    for j in range(n_lines):
        if new_first[j] < first[j]:
            bounds += (new_first[j], first[j])
            cols.append(2 * j)
        if new_last[j] > last[j]:
            bounds += (last[j] + 1, new_last[j] + 1)
            cols.append(2 * j + 1)
    added = np.zeros((NUM_SUMS, 2 * n_lines))
    added[:, cols] = np.add.reduceat(feats, bounds, axis=1)[:, 0::2]
    return (sums + added[:, 0::2] + added[:, 1::2], np.array(new_first, dtype=np.int64),
            np.array(new_last, dtype=np.int64), True)


_NEXT = np.array([[0], [1]])


def _extent_beams(scan: _Scan, f: _Fit, first: np.ndarray, last: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return (beam, line, rho, range, cos incidence) of the valid beams in the lines' extents.

    The extent of a line runs from its first to its last supporting beam in beam order;
    ``cos incidence`` is the ray direction dotted with the line's normal. The result is
    kept on ``f`` for the same ``first`` and ``last`` arrays (the see-through and occluder
    steps look at the same extents when no line was cut).
    """
    if f.extent is not None and f.extent[0] is first and f.extent[1] is last:
        return f.extent[2]
    wr, wc, ws, wv = scan.beams()
    # the beams lo..hi of every line, back to back (as _gather), laid out on lists
    beam = memoryview(scan.beam)
    cnt, shift = [], []
    total = 0
    for a, b in zip(first.tolist(), last.tolist()):
        lo, hi = beam[a], beam[b]
        if hi < lo:
            lo, hi = hi, lo
        cnt.append(hi - lo + 1)
        shift.append(total - lo)
        total += hi - lo + 1
    idx = np.arange(total, dtype=np.int64)
    idx -= np.array(shift, dtype=np.int64).repeat(cnt)
    line = np.arange(len(cnt)).repeat(cnt)
    ok = wv[idx]
    idx, line = idx[ok], line[ok]
    rho, _, nx, ny = f.params.take(line, axis=1)
    out = idx, line, rho, wr[idx], wc[idx] * nx + ws[idx] * ny
    f.extent = (first, last, out)
    return out


def _seen_through(scan: _Scan, f: _Fit, first: np.ndarray, last: np.ndarray,
                  params: LineParams) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (line, beam, opening) of the valid beams the lines hide (step 5).

    A beam between the first and the last supporting beam of a line (in beam order) is
    hidden when its return lies more than ``see_through_tolerance`` beyond the line along
    its ray: the laser saw through where the line claims a surface. ``opening`` marks the
    hidden beams beyond the line by more than that tolerance plus 3 standard deviations of
    their distance along the ray (eq. 7 on the ray: ``sigma_r^2 + (r sigma_phi
    tan(incidence))^2``); the others are the wall's own noise (at grazing incidence, or a
    rare large error). Beams in front of the line (occluders) and missing beams are
    allowed here (occluders are left out of the extents by :func:`_occluded_extents`).
    """
    idx, line, rho, r, cos_in = _extent_beams(scan, f, first, last)
    beyond = r - rho / cos_in
    tol = params.see_through_tolerance
    bad = ((cos_in > 1e-9) & (beyond > tol)).nonzero()[0]
    if not bad.size:
        return line[:0], idx[:0], np.zeros(0, dtype=bool)
    line, idx = line[bad], idx[bad]
    if bad.size <= _SEEN_PY:  # the opening test on Python floats (the same operations)
        sr2, sp = params.sigma_r ** 2, params.sigma_phi
        opening = []
        for b, rr, c in zip(*np.array((beyond, r, cos_in)).take(bad, axis=1).tolist()):
            t, c2 = rr * sp, c * c
            opening.append(b > tol + 3.0 * math.sqrt(sr2 + t * t * (1.0 - c2) / c2))
        return line, idx, np.array(opening, dtype=bool)
    beyond, r, cos_in = beyond[bad], r[bad], cos_in[bad]
    c2 = cos_in * cos_in
    var = params.sigma_r ** 2 + (r * params.sigma_phi) ** 2 * (1.0 - c2) / c2
    return line, idx, beyond > tol + 3.0 * np.sqrt(var)


# Hidden beams up to which _seen_through tests them on Python floats (measured).
_SEEN_PY = 16


def _cut_seen_through(scan: _Scan, feats: np.ndarray, sums: np.ndarray, first: np.ndarray,
                      last: np.ndarray, f: _Fit, pieces: Tuple[np.ndarray, ...],
                      params: LineParams) -> Tuple[np.ndarray, np.ndarray, np.ndarray, _Fit]:
    """Keep the lines off the beams they hide (step 5).

    ``pieces`` = (s, e, label, first0, last0): the merged pieces, their lines and the
    lines' first / last points before growing (the support of line j is its pieces and
    the grown runs ``[first[j], first0[j])`` and ``(last0[j], last[j]]``).

    1. A line that hides an opening (see :func:`_seen_through`) is cut there: the support
       on either side becomes a line of its own and is refitted, a supporting point at the
       opening leaves. Repeated on the new fits; support runs shorter than ``min_points``
       are dropped, and so is a line still hiding an opening after ``_MAX_CUTS`` rounds.
    2. A line that hides only beams within their noise (its own points at grazing
       incidence) is cut there too when at least two of the pieces are lines of their own
       (``min_points``, ``min_length``); otherwise it keeps its fit, all points included,
       and its extent shrinks to the run of its support between those beams with the
       most points.
    """
    line, beam, opening = _seen_through(scan, f, first, last, params)
    if not line.size:
        return sums, first, last, f
    s, e, label, first0, last0 = pieces
    if line.size <= _NOISE_PY and not np.count_nonzero(opening):
        ends = _noise_only_py(scan, pieces, first, last, line, beam, params)
        if ends is not None:
            return sums, ends[0], ends[1], f
    if first.size <= _CUT_PY:
        out = _cut_py(scan, feats, sums, first, last, f, pieces, line, beam, opening, params)
        if out is not None:
            return out
    owner = np.full(scan.x.size, -1, dtype=np.int64)
    # a line's support: its pieces and the runs grown before and after (disjoint, so one
    # gather of all of them)
    lines = np.arange(first.size)
    idx, offs = _gather(np.concatenate((s, first, last0 + 1)),
                        np.concatenate((e, first0 - 1, last)))
    owner[idx] = np.concatenate((label, lines, lines)).repeat(offs[1:] - offs[:-1])
    rounds = 0
    two, runs = _splits_in_two(scan, owner, line, beam, first, params)
    opening |= two
    while np.count_nonzero(opening):
        if rounds == _MAX_CUTS:  # give up on the lines that still hide an opening
            ok = np.ones(first.size, dtype=bool)
            ok[line[opening]] = False
            relabel = ok.cumsum() - 1
            owner = np.where((owner >= 0) & ok[np.maximum(owner, 0)],
                             relabel[np.maximum(owner, 0)], -1)
            sums, first, last = sums[:, ok], first[ok], last[ok]
            if not first.size:
                return sums, first, last, f
            f = _solve(sums, scan.origin)
            sel = ok[line]
            line, beam, opening = relabel[line[sel]], beam[sel], opening[sel]
            runs = None
            break
        rounds += 1
        pos, run, starts, size = _support_runs(scan, owner, beam[opening])
        big = size >= params.min_points
        owner[:] = -1
        kept = big[run]
        owner[pos[kept]] = (big.cumsum() - 1)[run[kept]]
        starts, size = starts[big], size[big]
        if not starts.size:
            return sums[:, :0], first[:0], last[:0], f
        first, last = pos[starts], pos[starts + size - 1]
        sums = np.add.reduceat(feats.take(pos[kept], axis=1), size.cumsum() - size, axis=1)
        f = _solve(sums, scan.origin)
        line, beam, opening = _seen_through(scan, f, first, last, params)
        two, runs = _splits_in_two(scan, owner, line, beam, first, params)
        opening |= two
    if line.size:  # only noise: each line's extent becomes its largest run between them
        pos, run, starts, size = (runs if runs is not None
                                  else _support_runs(scan, owner, beam))
        own = owner[pos[starts]]
        best = np.lexsort((-size, own))  # per line, the run of most points first
        head = np.ones(best.size, dtype=bool)
        head[1:] = own[best[1:]] != own[best[:-1]]
        best = best[head]
        first, last = first.copy(), last.copy()
        first[own[best]] = pos[starts[best]]
        last[own[best]] = pos[starts[best] + size[best] - 1]
    return sums, first, last, f


# Hidden beams up to which _noise_only_py is tried first (a few per scan are typical).
_NOISE_PY = 24


def _noise_only_py(scan: _Scan, pieces: Tuple[np.ndarray, ...], first: np.ndarray,
                   last: np.ndarray, line: np.ndarray, beam: np.ndarray, params: LineParams
                   ) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """Return the lines' first and last points when they hide only their noise, else None.

    Step 2 of :func:`_cut_seen_through` for hidden beams that are no opening, on Python
    objects and looking only at the lines that hide beams: a line's support (its pieces
    and grown runs) is cut into runs at its hidden beams (which leave), as by
    :func:`_support_runs`. Returns None when a line has two runs of ``min_points`` points
    and ``min_length`` (:func:`_splits_in_two`: the line is cut, in the array version);
    otherwise each hiding line's extent becomes its run of most points (the first of
    equal ones).
    """
    s, e, label, first0, last0 = pieces
    hidden: dict = {}
    for j, b in zip(line.tolist(), beam.tolist()):  # beams increasing per line
        hidden.setdefault(j, []).append(b)
    s_l, e_l, lab = s.tolist(), e.tolist(), label.tolist()
    f_l, l_l, f0, l0 = first.tolist(), last.tolist(), first0.tolist(), last0.tolist()
    xs, ys = scan.rows()[_X], scan.rows()[_Y]
    new_first, new_last = f_l[:], l_l[:]
    for j, hb in hidden.items():
        ranges = [(f_l[j], f0[j] - 1)]
        ranges += [(a, b) for a, b, k in zip(s_l, e_l, lab) if k == j]
        ranges.append((l0[j] + 1, l_l[j]))
        pts: List[int] = []
        for a, b in ranges:
            pts.extend(range(a, b + 1))
        bps = scan.beam.take(pts).tolist()  # increasing
        runs: List[Tuple[int, int, int]] = []  # (points, first point, last point)
        start = 0
        for h in hb:  # the support between hidden beams; a hidden supporting point leaves
            pos = bisect_left(bps, h, start)
            if pos > start:
                runs.append((pos - start, pts[start], pts[pos - 1]))
            start = pos + 1 if pos < len(bps) and bps[pos] == h else pos
        if start < len(bps):
            runs.append((len(bps) - start, pts[start], pts[-1]))
        good = 0
        for n, a, b in runs:
            if n >= params.min_points and abs(
                    complex(xs[b] - xs[a], ys[b] - ys[a])) >= params.min_length:
                good += 1
        if good >= 2:
            return None
        if runs:
            best = max(runs, key=lambda r: r[0])  # the first run of most points
            new_first[j], new_last[j] = best[1], best[2]
    if new_first == f_l and new_last == l_l:  # the same extents (their beams are cached)
        return first, last
    return np.array(new_first, dtype=np.int64), np.array(new_last, dtype=np.int64)


# Lines up to which _cut_seen_through cuts on Python lists (:func:`_cut_py`).
_CUT_PY = 40


def _runs_at(bps: List[int], hidden: List[int]) -> List[Tuple[int, int]]:
    """Return the runs ``[a, b)`` of a line's support between its hidden beams.

    ``bps`` are the beams of the line's supporting points (increasing), ``hidden`` the
    hidden beams inside its extent (increasing); a supporting point at a hidden beam
    leaves (as in :func:`_support_runs`).
    """
    runs = []
    start = 0
    size = len(bps)
    for h in hidden:
        pos = bisect_left(bps, h, start)
        if pos > start:
            runs.append((start, pos))
        start = pos + 1 if pos < size and bps[pos] == h else pos
    if start < size:
        runs.append((start, size))
    return runs


def _cut_py(scan: _Scan, feats: np.ndarray, sums: np.ndarray, first: np.ndarray,
            last: np.ndarray, f: _Fit, pieces: Tuple[np.ndarray, ...], line: np.ndarray,
            beam: np.ndarray, opening: np.ndarray, params: LineParams
            ) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray, _Fit]]:
    """Return :func:`_cut_seen_through` for the hidden beams of :func:`_seen_through`.

    The same cuts, the same runs and the same fits as its array steps
    (:func:`_support_runs`, :func:`_splits_in_two`): each line's support is a list of its
    points, and only the lines that hide beams are cut into runs (at their hidden beams,
    found by bisection), not the whole scan; the fits of every round are the same
    ``reduceat`` sums and :func:`_solve` of all lines, tested by :func:`_seen_through`.
    This needs the lines' supports in point order, one after the other, with beam indices
    increasing along them (clusters of one ``segment_scan`` call, in beam order): then a
    line's extent holds no other line's point and its hidden beams cut no other line.
    Returns None otherwise (the array steps then run).
    """
    s, e, label, first0, last0 = pieces
    n = first.size
    f_l, l_l = first.tolist(), last.tolist()
    sup: List[List[int]] = [list(range(a, b)) for a, b in zip(f_l, first0.tolist())]
    for a, b, k in zip(s.tolist(), e.tolist(), label.tolist()):
        sup[k].extend(range(a, b + 1))
    for j, (a, b) in enumerate(zip(last0.tolist(), l_l)):
        sup[j].extend(range(a + 1, b + 1))
    pts = [p for ps in sup for p in ps]
    bps = scan.beam.take(pts).tolist()
    if not (all(map(lt, pts, pts[1:])) and all(map(lt, bps, bps[1:]))):
        return None
    bsup = []
    k = 0
    for ps in sup:
        bsup.append(bps[k:k + len(ps)])
        k += len(ps)
    xs, ys = scan.rows()[_X], scan.rows()[_Y]
    least, min_length = params.min_points, params.min_length

    def hidden_by_line(line_l: List[int], beam_l: List[int], sel: Optional[List[bool]]
                       ) -> dict:
        """Return {line: its hidden beams (increasing)}, of the entries ``sel`` (all: None)."""
        out: dict = {}
        for i, (j, b) in enumerate(zip(line_l, beam_l)):
            if sel is None or sel[i]:
                out.setdefault(j, []).append(b)
        return out

    def splits_in_two(hidden: dict) -> Tuple[set, dict]:
        """Return the lines cut into two or more lines at their hidden beams, and the runs."""
        runs, two = {}, set()
        for j, hb in hidden.items():
            ps = sup[j]
            runs[j] = rj = _runs_at(bsup[j], hb)
            good = 0
            for a, b in rj:
                pa, pb = ps[a], ps[b - 1]
                if b - a >= least and abs(
                        complex(xs[pb] - xs[pa], ys[pb] - ys[pa])) >= min_length:
                    good += 1  # C hypot, as np.hypot
            if good >= 2:
                two.add(j)
        return two, runs

    line_l, beam_l, open_l = line.tolist(), beam.tolist(), opening.tolist()
    hidden = hidden_by_line(line_l, beam_l, None)
    two, runs = splits_in_two(hidden)
    open_l = [o or j in two for o, j in zip(open_l, line_l)]
    rounds = 0
    changed = False
    while any(open_l):
        if rounds == _MAX_CUTS:  # give up on the lines that still hide an opening
            drop = {j for j, o in zip(line_l, open_l) if o}
            keep = [j for j in range(n) if j not in drop]
            relabel = {j: i for i, j in enumerate(keep)}
            sums, first, last = sums[:, keep], first[keep], last[keep]
            if not keep:
                return sums, first, last, f
            f = _solve(sums, scan.origin)
            sup, bsup = [sup[j] for j in keep], [bsup[j] for j in keep]
            sel = [j in relabel for j in line_l]
            line_l = [relabel[j] for j, ok in zip(line_l, sel) if ok]
            beam_l = [b for b, ok in zip(beam_l, sel) if ok]
            hidden = hidden_by_line(line_l, beam_l, None)
            runs = splits_in_two(hidden)[1]
            changed = True
            break
        rounds += 1
        cuts = hidden_by_line(line_l, beam_l, open_l)
        new_sup, new_bsup = [], []
        for j, (ps, bs) in enumerate(zip(sup, bsup)):
            for a, b in (_runs_at(bs, cuts[j]) if j in cuts else ((0, len(ps)),)):
                if b - a >= least:
                    new_sup.append(ps[a:b])
                    new_bsup.append(bs[a:b])
        sup, bsup = new_sup, new_bsup
        if not sup:
            return sums[:, :0], first[:0], last[:0], f
        first = np.array([ps[0] for ps in sup], dtype=np.int64)
        last = np.array([ps[-1] for ps in sup], dtype=np.int64)
        n = len(sup)
        starts = [0]
        for ps in sup[:-1]:
            starts.append(starts[-1] + len(ps))
        sums = np.add.reduceat(feats.take([p for ps in sup for p in ps], axis=1), starts,
                               axis=1)
        f = _solve(sums, scan.origin)
        line, beam, opening = _seen_through(scan, f, first, last, params)
        line_l, beam_l, open_l = line.tolist(), beam.tolist(), opening.tolist()
        hidden = hidden_by_line(line_l, beam_l, None)
        two, runs = splits_in_two(hidden)
        open_l = [o or j in two for o, j in zip(open_l, line_l)]
        changed = True
    if line_l:  # only noise: each line's extent becomes its largest run between them
        new_first, new_last = first.tolist(), last.tolist()
        for j, rj in runs.items():
            if rj:
                a, b = max(rj, key=lambda r: r[1] - r[0])  # the first run of most points
                new_first[j], new_last[j] = sup[j][a], sup[j][b - 1]
        if changed or new_first != first.tolist() or new_last != last.tolist():
            first = np.array(new_first, dtype=np.int64)
            last = np.array(new_last, dtype=np.int64)
    return sums, first, last, f


def _splits_in_two(scan: _Scan, owner: np.ndarray, line: np.ndarray, beam: np.ndarray,
                   first: np.ndarray, params: LineParams) -> Tuple[np.ndarray, Optional[tuple]]:
    """Mark the hidden beams (all of a line's) that cut it into two or more lines.

    ``owner`` gives the line of each point (-1: none), ``first`` the lines' first points.

    A piece between hidden beams counts as a line when it has ``min_points`` supporting
    points and spans ``min_length``. Also returns the :func:`_support_runs` at all the
    hidden beams (None without hidden beams), which the noise-only case reuses.
    """
    if not line.size:
        return np.zeros(0, dtype=bool), None
    runs = _support_runs(scan, owner, beam)
    pos, _, starts, size = runs
    a, b = pos[starts], pos[starts + size - 1]
    span = np.hypot(scan.x[b] - scan.x[a], scan.y[b] - scan.y[a])
    good = (size >= params.min_points) & (span >= params.min_length)
    n_good = np.bincount(owner[a][good], minlength=first.size)
    return n_good[line] >= 2, runs


def _support_runs(scan: _Scan, owner: np.ndarray, hidden: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Split the lines' support at the hidden beams (beam indices, repeats allowed).

    Returns the supporting points left (the hidden ones leave), the run of each, and the
    runs' starts (into the points) and sizes. Runs are consecutive support of one line
    with no hidden beam between; a hidden beam lies inside the extent of one line only.
    """
    pos = (owner >= 0).nonzero()[0]
    bpos = scan.beam[pos]
    mark = np.zeros(scan.nbeam, dtype=np.int8)  # hidden beams lie within the lines' extents
    mark[hidden] = 1
    keep = mark[bpos] == 0
    pos, bpos = pos[keep], bpos[keep]
    cut = mark.cumsum()[bpos]  # hidden beams before each point
    own = owner[pos]
    new = np.empty(pos.size, dtype=bool)
    new[:1] = True
    np.not_equal(own[1:], own[:-1], out=new[1:])
    new[1:] |= cut[1:] != cut[:-1]
    starts = new.nonzero()[0]
    bounds = np.empty(starts.size + 1, dtype=np.int64)
    bounds[:-1] = starts
    bounds[-1] = pos.size
    return pos, new.cumsum() - 1, starts, bounds[1:] - bounds[:-1]


def _shrunk_extents(scan: _Scan, f: _Fit, first: np.ndarray, last: np.ndarray
                    ) -> Optional[List[Tuple[int, int]]]:
    """Return the lines' beam ranges if they lie within those cached on ``f``, else None.

    :func:`_cut_seen_through` shrinks the extents of lines that hide only their noise and
    keeps their fits: the beams of the new extents are then among the cached ones of
    :func:`_extent_beams` (the same values), and a test of those beams needs only to
    keep the ones inside the new ranges. None when nothing is cached for these fits, the
    cache is for these very extents, or a range is not within its line's cached one.
    """
    ext = f.extent
    if ext is None or (ext[0] is first and ext[1] is last) or ext[0].size != first.size:
        return None
    beam = memoryview(scan.beam)
    out = []
    for a, b, a0, b0 in zip(first.tolist(), last.tolist(), ext[0].tolist(), ext[1].tolist()):
        lo, hi = min(beam[a], beam[b]), max(beam[a], beam[b])
        if not min(beam[a0], beam[b0]) <= lo <= hi <= max(beam[a0], beam[b0]):
            return None
        out.append((lo, hi))
    return out


def _occluded_extents(scan: _Scan, f: _Fit, first: np.ndarray, last: np.ndarray,
                      params: LineParams) -> Tuple[Optional[np.ndarray], np.ndarray, np.ndarray]:
    """Cut the lines' extents at occluders (step 5); return (line, first, last) per piece.

    An occluder of a line is a run of two or more neighbouring valid beams inside its
    extent whose returns lie in front of it by more than the opening margin of
    :func:`_seen_through` (``see_through_tolerance`` plus 3 standard deviations of the
    distance along the ray, eq. 7). The extent's points are split at the occluders'
    beams (which leave); pieces of at least ``min_points`` points are kept, each
    pointing to its line's fit. Without occluders every line is one piece and the
    result is ``(None, first, last)``.
    """
    same = None, first, last
    within = _shrunk_extents(scan, f, first, last)
    idx, line, rho, r, cos_in = (_extent_beams(scan, f, first, last) if within is None
                                 else f.extent[2])
    front = rho / cos_in - r  # how far the return lies in front of the line
    # Only a beam in front by more than the tolerance can be in front by the margin.
    hit = ((cos_in > 1e-9) & (front > params.see_through_tolerance)).nonzero()[0]
    if within is not None and hit.size:  # the beams of the earlier extents: keep those
        hit = hit[[within[j][0] <= b <= within[j][1]  # inside the lines' extents now
                   for j, b in zip(line[hit].tolist(), idx[hit].tolist())]]
    if hit.size < 2:
        return same
    r, cos_in = r[hit], cos_in[hit]
    c2 = cos_in * cos_in
    var = params.sigma_r ** 2 + (r * params.sigma_phi) ** 2 * (1.0 - c2) / c2
    hit = hit[front[hit] > params.see_through_tolerance + 3.0 * np.sqrt(var)]
    if hit.size < 2:
        return same
    fl, fb = line[hit], idx[hit]
    pair = (fl[1:] == fl[:-1]) & (fb[1:] - fb[:-1] == 1)
    if not np.count_nonzero(pair):
        return same
    occ = np.zeros(hit.size, dtype=bool)
    occ[1:] |= pair
    occ[:-1] |= pair
    size = scan.nbeam
    key_occ = fl[occ] * size + fb[occ]  # sorted (line-major, beams increasing)
    pts, offs = _gather(first, last)
    own = np.arange(first.size).repeat(offs[1:] - offs[:-1])
    key = own * size + scan.beam[pts]
    cut = np.searchsorted(key_occ, key)  # occluder beams of the line before each point
    keep = (cut >= key_occ.size) | (key_occ[np.minimum(cut, key_occ.size - 1)] != key)
    pts, own, cut = pts[keep], own[keep], cut[keep]
    new = np.empty(pts.size, dtype=bool)
    new[:1] = True
    new[1:] = (own[1:] != own[:-1]) | (cut[1:] != cut[:-1])
    starts = new.nonzero()[0]
    bounds = np.empty(starts.size + 1, dtype=np.int64)
    bounds[:-1] = starts
    bounds[-1] = pts.size
    count = bounds[1:] - bounds[:-1]
    big = count >= params.min_points
    starts, count = starts[big], count[big]
    return own[starts], pts[starts], pts[starts + count - 1]


# Lines per scan up to which _join_occluded's first test runs on Python floats (measured).
_JOIN_PAIRS_PY = 12


def _join_occluded(scan: _Scan, sums: np.ndarray, first: np.ndarray, last: np.ndarray,
                   f: _Fit, pieces: Tuple[np.ndarray, np.ndarray], params: LineParams
                   ) -> _Fit:
    """Fit lines of one surface split by an occluder or a gap as one line (step 5).

    The merge (step 3) tests consecutive pieces only, and neighbouring clusters only
    when their facing ends are within ``merge_gap`` / ``merge_gap_angle``: a wall seen
    on both sides of a table leg or a pillar in front of it (whose pieces lie between
    the wall's) stays two lines, each with the covariance of half the wall's beams. Here
    a line j and a later line k (in beam order) get one fit, on the points of both, when

    * their (rho, alpha) pass the merge test (chi-square with the a-posteriori variance
      factors of :func:`_variance_factor`) and each passes it against the joint fit
      (taken as exact), with its end points within the split tolerance of it;
    * no valid beam from j's first to k's last beam lies beyond the joint line by more
      than ``see_through_tolerance``: the beams between them are occluded from the front
      (or the wall's own returns that no line took), never beams that saw further;
    * no beam between them within that tolerance of the joint line belongs to the
      extent of another line (a line between on the same surface that failed the test);
    * every run of missing beams between them is within ``merge_gap`` or
      ``merge_gap_angle`` of the joint line (the merge's rule for dropouts);
    * every extent that would carry the joint fit still passes step 6 with it (a join
      never drops a segment).

    Consecutive lines whose facing pieces (``pieces``: the first and last points of the
    pieces the merge saw) were consecutive neighbours there are not joined: the merge
    tested them, also against the merged line of the whole chain, which a pair cannot (a
    panel 5 mm proud of a wall must not take one wall piece and keep it from the other).

    A line takes the later lines that pass, in order. The extents stay as they were (the
    joined lines are reported as one segment per extent, each with the joint fit: no
    segment spans the beams between). Returns the fits of the extents ``first``, ``last``
    (the input fits where nothing was joined).
    """
    n = first.size
    if n < 2:
        return f
    gate = params.merge_chi2
    tol = params.see_through_tolerance

    def chi2(r1, a1, c1, r2, a2, c2) -> float:
        """Return :func:`_chi2` of one pair (``c2`` None: line 2 exact)."""
        da = _wrap(a1 - a2)
        sign = 1.0
        if abs(da) > 0.5 * math.pi:
            dr, da, sign = r1 + r2, _wrap(da + math.pi), -1.0
        else:
            dr = r1 - r2
        a00, a01, a11 = c1[0], c1[1], c1[3]
        if c2 is not None:
            a00, a01, a11 = a00 + c2[0], a01 + sign * c2[1], a11 + c2[3]
        det = a00 * a11 - a01 * a01
        if not det > 0.0:
            return math.inf
        d2 = (a11 * dr * dr - 2.0 * a01 * dr * da + a00 * da * da) / det
        return d2 if d2 == d2 else math.inf

    # cheap first test on every pair j < k: the two fits agree (a grown line retests all);
    # on Python floats for a few lines (the same operations as _chi2, the same results)
    rho_l, alpha_l, nx_l, ny_l = f.params.tolist()
    factor = None
    if n <= _JOIN_PAIRS_PY:
        try:
            factor = _variance_factor_py(sums, f, nx_l, ny_l)
        except ZeroDivisionError:  # degenerate fits: numpy's inf / nan below
            pass
    if factor is None:
        factor = _variance_factor(sums, f)
        cov = (f.cov * factor[:, None, None]).reshape(-1, 4).tolist()
    else:
        cov = [[c * k for c in row] for row, k in zip(f.cov.reshape(-1, 4).tolist(), factor)]
    if n <= _JOIN_PAIRS_PY:
        pi, two_pi = math.pi, TWO_PI
        tried = set()
        for j in range(n - 1):
            r1, a1, c1 = rho_l[j], alpha_l[j], cov[j]
            for k in range(j + 1, n):
                r2, c2 = rho_l[k], cov[k]
                da = abs((a1 - alpha_l[k] + pi) % two_pi - pi)
                dr = r1 - r2
                if da > 0.5 * pi:
                    da, dr = pi - da, r1 + r2
                # d2 is at least each part alone, da^2 / (C1 + C2)_aa and dr^2 /
                # (C1 + C2)_rr: most pairs (lines of other walls) fail on these
                if (da * da <= gate * (c1[3] + c2[3]) and dr * dr <= gate * (c1[0] + c2[0])
                        and chi2(r1, a1, c1, r2, alpha_l[k], c2) <= gate):
                    tried.add((j, k))
    else:
        jj, kk = np.triu_indices(n, 1)
        scaled = f.cov * np.asarray(factor)[:, None, None]
        agree = (_chi2(f.rho[jj], f.alpha[jj], scaled[jj], f.rho[kk], f.alpha[kk],
                       scaled[kk]) <= gate).nonzero()[0]
        tried = set(zip(jj[agree].tolist(), kk[agree].tolist()))
    if not tried:
        return f
    wr, wc, ws, wv = scan.beams()
    phi = scan.whole.angles if scan.whole is not None else None
    beam = scan.beam
    xs, ys, tols = scan.rows()[_X], scan.rows()[_Y], scan.rows()[_TOL]
    ox, oy = scan.origin
    first_l, last_l = first.tolist(), last.tolist()
    fits = {j: (rho_l[j], alpha_l[j], cov[j]) for j in range(n)}
    line_sums = {j: sums[:, j] for j in range(n)}
    owner = list(range(n))  # the line whose fit each extent takes
    ends = {j: (first_l[j], last_l[j]) for j in range(n)}  # outermost points of a fit
    gap2 = params.merge_gap ** 2

    def joinable(j: int, k: int) -> Optional[Tuple[np.ndarray, _Fit]]:
        """Return the joint sums and fit of lines j < k if they may be joined, else None."""
        r1, a1, c1 = fits[j]
        r2, a2, c2 = fits[k]
        if chi2(r1, a1, c1, r2, a2, c2) > gate:
            return None
        joint = line_sums[j] + line_sums[k]
        line = None  # the tests need the line only: _solve's, on Python floats if it would be
        if _SMALL_NO_COV >= 1:
            try:
                line = _line_py(joint[:6].tolist(), scan.origin)
            except ZeroDivisionError:  # degenerate sums: numpy's inf / nan below
                pass
        if line is None:
            line = _solve(joint[:6, None], scan.origin, rmse=False).params[:, 0].tolist()
        rg, ag, nx, ny = line
        if not (chi2(r1, a1, c1, rg, ag, None) <= gate and chi2(r2, a2, c2, rg, ag, None)
                <= gate):
            return None
        rel = rg - nx * ox - ny * oy
        for p in ends[j] + (first_l[k], last_l[k]):
            if not abs(xs[p] * nx + ys[p] * ny - rel) <= tols[p]:
                return None
        b0, b1 = int(beam[ends[j][0]]), int(beam[last_l[k]])
        e0, s1 = int(beam[ends[j][1]]), int(beam[first_l[k]])
        if not b0 <= e0 < s1 <= b1:
            return None
        span = slice(b0, b1 + 1)  # the beams from j's first to k's last (views)
        cos_in = wc[span] * nx + ws[span] * ny
        if np.count_nonzero(cos_in <= 1e-9):
            return None
        beyond = wr[span] - rg / cos_in
        ok = wv[span]
        if np.count_nonzero(ok & (beyond > tol)):  # a beam seen through the joint line
            return None
        gap = slice(e0 + 1 - b0, s1 - b0)  # the beams between the two lines
        gv = ok[gap]
        on = gv & (np.abs(beyond[gap]) <= tol)
        if np.count_nonzero(on):  # the wall's free returns, but no other line's beams
            taken = np.zeros(s1 - e0 - 1, dtype=bool)
            for m in range(n):
                if owner[m] != j:
                    lo = max(int(beam[first_l[m]]), e0 + 1)
                    hi = min(int(beam[last_l[m]]), s1 - 1)
                    if lo <= hi:
                        taken[lo - e0 - 1:hi - e0] = True
            if np.count_nonzero(on & taken):
                return None
        if not gv.all():  # runs of missing beams: the merge's rule for dropouts
            miss = np.flatnonzero(~gv) + e0 + 1
            starts = np.flatnonzero(np.diff(miss, prepend=-2) > 1)
            stops = np.append(starts[1:], miss.size) - 1
            for a, b in zip(miss[starts].tolist(), miss[stops].tolist()):
                # the joint line's points on the rays of the beams around the run
                pa, pb = a - 1, b + 1
                ta = rg / (wc[pa] * nx + ws[pa] * ny)
                tb = rg / (wc[pb] * nx + ws[pb] * ny)
                dx, dy = tb * wc[pb] - ta * wc[pa], tb * ws[pb] - ta * ws[pa]
                if not (dx * dx + dy * dy <= gap2 or (
                        phi is not None and abs(phi[pb] - phi[pa]) <= params.merge_gap_angle)):
                    return None
        g = _solve(joint[:, None], scan.origin)
        # every extent that would carry the joint fit must still be a line with it (step
        # 6: its end points on the joint line at least min_length apart, the joint RMSE
        # within the split tolerance), else the join would drop a segment
        owned = [m for m in range(n) if owner[m] == j] + [k]
        col = np.zeros(len(owned), dtype=np.intp)
        shared = _Fit(g.params.take(col, axis=1), g.rmse[col], g.count[col],
                      g.cov.take(col, axis=0))
        if len(_build(scan, params, shared, np.array([first_l[m] for m in owned]),
                      np.array([last_l[m] for m in owned]))) != len(owned):
            return None
        return joint, g

    # Consecutive lines whose facing pieces were consecutive neighbours in the merge were
    # the merge's to join (it also tests each piece against the merged line of the whole
    # chain, which a pair cannot): they are left as they are.
    ps, pe = pieces
    cluster, phis = memoryview(scan.cluster), scan.rows()[_PHI]
    ps_l, pe_l = ps.tolist(), pe.tolist()

    def merge_tested(j: int) -> bool:
        """Return whether lines j and j + 1 met as consecutive neighbouring pieces."""
        a = bisect_left(pe_l, last_l[j] + 1) - 1  # j's last piece, j + 1's first
        b = bisect_left(ps_l, first_l[j + 1])
        ok = a >= 0 and b == a + 1 and b < len(ps_l) and ps_l[a] >= first_l[j] and (
            pe_l[b] <= last_l[j + 1])
        if ok:
            p0, p1 = pe_l[a], ps_l[b]
            ok = (cluster[p0] == cluster[p1]
                  or (xs[p1] - xs[p0]) ** 2 + (ys[p1] - ys[p0]) ** 2 <= gap2
                  or abs(phis[p1] - phis[p0]) <= params.merge_gap_angle)
        return ok

    changed = False
    for j in range(n - 1):  # each line takes the later lines that join it, in order
        if owner[j] != j:
            continue
        grown = False
        for k in range(j + 1, n):
            if owner[k] != k or not (grown or (j, k) in tried) or (
                    k == j + 1 and merge_tested(j)):
                continue
            out = joinable(j, k)
            if out is None:
                continue
            joint, g = out
            line_sums[j] = joint
            fits[j] = (float(g.rho[0]), float(g.alpha[0]),
                       (g.cov[0] * _variance_factor(joint[:, None], g)[0]).reshape(4).tolist())
            ends[j] = (ends[j][0], last_l[k])
            for m in range(k, n):
                if owner[m] == k:
                    owner[m] = j
            changed = grown = True
    if not changed:
        return f
    heads = sorted(set(owner))
    g = _solve(np.stack([line_sums[j] for j in heads], axis=1), scan.origin)
    col = np.searchsorted(np.array(heads), np.array(owner))
    return _Fit(g.params.take(col, axis=1), g.rmse[col], g.count[col], g.cov.take(col, axis=0))


_MAX_CUTS = 8
_INWARD = np.array([[1.0], [-1.0]])  # start moves forward along the line, end backward


def _build(scan: _Scan, params: LineParams, f: _Fit, first: np.ndarray,
           last: np.ndarray) -> List[LineSegment]:
    """Drop small or short fits and build the LineSegments (first/last: point indices)."""
    if first.size <= _BUILD_PY:
        try:
            return _build_py(scan, params, f, first, last)
        except (ZeroDivisionError, OverflowError):  # a ray along a line: numpy inf / nan
            pass
    return _build_arrays(scan, params, f, first, last)


# Lines up to which _build_py is faster than _build_arrays (measured).
_BUILD_PY = 40


def _build_py(scan: _Scan, params: LineParams, f: _Fit, first: np.ndarray,
              last: np.ndarray) -> List[LineSegment]:
    """Return :func:`_build_arrays` computed on Python floats (the same operations).

    Raises ZeroDivisionError where a ray runs along its line (the arrays version then
    gives numpy's inf / nan).
    """
    ox, oy = scan.origin
    xs, ys, _, cps, sps = scan.rows()[:_TOL]
    beam = memoryview(scan.beam)
    firsts, lasts = first.tolist(), last.tolist()
    rhos, alphas, nxs, nys = f.params.tolist()
    rmses, counts = f.rmse.tolist(), f.count.tolist()
    covs = f.cov.reshape(-1, 4).tolist()
    min_points, min_length, thr = params.min_points, params.min_length, params.threshold
    isfinite = math.isfinite
    keep, flat = [], []
    for j, (rho, nx, ny) in enumerate(zip(rhos, nxs, nys)):
        cov = covs[j]
        if not (counts[j] >= min_points and rmses[j] <= thr and isfinite(cov[0])
                and isfinite(cov[3])):
            continue
        ends_j = []
        i0, i1 = firsts[j], lasts[j]
        for x, y, cp, sp in ((xs[i0] + ox, ys[i0] + oy, cps[i0], sps[i0]),
                             (xs[i1] + ox, ys[i1] + oy, cps[i1], sps[i1])):
            d = x * nx + y * ny - rho
            px, py = x - d * nx, y - d * ny
            t = rho / (cp * nx + sp * ny)
            ends_j.append((px, py, t, cp, sp, py * nx - px * ny, t * (sp * nx - cp * ny)))
        (px0, py0, t0, cp0, sp0, al0, ar0), (px1, py1, t1, cp1, sp1, al1, ar1) = ends_j
        # End points at the end beams (see _build_arrays)
        sign = 1.0 if al1 >= al0 else -1.0
        span = abs(al1 - al0)
        inward = sign * (ar0 - al0)
        if t0 > 0.0 and inward > 0.0 and inward < span:
            px0, py0 = t0 * cp0, t0 * sp0
        inward = sign * (ar1 - al1) * -1.0
        if t1 > 0.0 and inward > 0.0 and inward < span:
            px1, py1 = t1 * cp1, t1 * sp1
        if not abs(complex(px1 - px0, py1 - py0)) >= min_length:  # C hypot, as np.hypot
            continue
        keep.append(j)
        flat += (px0, py0, px1, py1)
    if not keep:
        return []
    pts = np.array(flat).reshape(-1, 2, 2)
    # the (2,) start and end points and (2, 2) covariances as views, made in one pass each
    return [_segment(rhos[j], alphas[j], p0, p1, int(counts[j]), rmses[j], c,
                     beam[firsts[j]], beam[lasts[j]])
            for j, p0, p1, c in zip(keep, pts[:, 0], pts[:, 1], f.cov.take(keep, axis=0))]


_new = object.__new__


def _segment(rho: float, alpha: float, start: np.ndarray, end: np.ndarray, num_points: int,
             rmse: float, covariance: np.ndarray, first_index: int, last_index: int
             ) -> LineSegment:
    """Return ``LineSegment(...)`` of these values, its fields set without ``__init__``.

    The frozen dataclass's ``__init__`` sets each field through ``object.__setattr__``;
    this writes them to the instance's ``__dict__`` at once (the same object, a third of
    the time).
    """
    seg = _new(LineSegment)
    d = seg.__dict__
    d['rho'], d['alpha'], d['start'], d['end'], d['num_points'] = (rho, alpha, start, end,
                                                                   num_points)
    d['rmse'], d['covariance'], d['first_index'], d['last_index'] = (rmse, covariance,
                                                                     first_index, last_index)
    return seg


def _build_arrays(scan: _Scan, params: LineParams, f: _Fit, first: np.ndarray,
                  last: np.ndarray) -> List[LineSegment]:
    """Return :func:`_build` on arrays (all lines of the scan at once)."""
    ox, oy = scan.origin
    ends = np.empty((2, first.size), dtype=np.int64)
    ends[0] = first
    ends[1] = last
    x, y, _, cp, sp = scan.cols[:_TOL].take(ends, axis=1)
    x += ox
    y += oy
    rho, alpha = f.params[:2]
    # the line parameters once per end point (2, G): no broadcasting in the steps below
    rho2, _, nx, ny = np.concatenate((f.params, f.params), axis=1).reshape(4, 2, first.size)
    d = x * nx + y * ny - rho2
    proj = np.empty((2, first.size, 2))  # end point (first, last), line, (x, y)
    np.subtract(x, d * nx, out=proj[..., 0])
    np.subtract(y, d * ny, out=proj[..., 1])
    # End points at the end beams: where a projection lies outside the bearings of the
    # supporting beams, the end beam's ray meets the line (the segment then covers no beam
    # outside its support). Inside, the projection stays (it does not depend on the range
    # noise along a grazing ray).
    t = rho2 / (cp * nx + sp * ny)
    along = proj[..., 1] * nx - proj[..., 0] * ny  # position along the line (tangent)
    along_ray = t * (sp * nx - cp * ny)
    inward = np.where(along[1] >= along[0], 1.0, -1.0) * (along_ray - along) * _INWARD
    # nan fails; a ray along the line (through the origin) meets it nowhere useful
    inner = (t > 0.0) & (inward > 0.0) & (inward < np.abs(along[1] - along[0]))
    if np.count_nonzero(inner):
        proj[..., 0] = np.where(inner, t * cp, proj[..., 0])
        proj[..., 1] = np.where(inner, t * sp, proj[..., 1])
    length = np.hypot(proj[1, :, 0] - proj[0, :, 0], proj[1, :, 1] - proj[0, :, 1])
    cov = f.cov
    ok = ((f.count >= params.min_points) & (length >= params.min_length)
          & (f.rmse <= params.threshold)
          & np.isfinite(cov[:, 0, 0]) & np.isfinite(cov[:, 1, 1])).nonzero()[0]
    rho, alpha, rmse = rho[ok].tolist(), alpha[ok].tolist(), f.rmse[ok].tolist()
    count = f.count[ok].astype(np.int64).tolist()
    b0, b1 = scan.beam[ends.take(ok, axis=1)].tolist()
    proj, cov = proj.take(ok, axis=1), cov.take(ok, axis=0)
    return [_segment(rho[j], alpha[j], proj[0, j], proj[1, j], count[j], rmse[j], cov[j],
                     b0[j], b1[j]) for j in range(len(rho))]


def extract_lines(clusters: Sequence[Cluster], params: Optional[LineParams] = None
                  ) -> List[LineSegment]:
    """Extract line segments from the clusters of one scan.

    Args:
        clusters: Clusters of consecutive points of one scan, in beam order (see
            ``segment_scan``), laser frame. Lines start in clusters of at least
            ``min_points`` points and can grow over the points of smaller ones, so pass
            small clusters too (``segment_scan(..., min_points=1)``) to let lines reach
            isolated points on their wall (e.g. a corridor wall seen at grazing angles).
            Clusters of one ``segment_scan`` call carry the whole scan, so no line covers
            a beam seen through it even where that beam's cluster was dropped; for
            clusters built by hand only their own beams are known (step 5).
        params: Method and parameters (default ``LineParams()``).

    Returns:
        Line segments in beam order; empty if no cluster holds a line.

    """
    params = params or LineParams()
    # The fits divide by zero for degenerate point sets (their covariance becomes inf and
    # they are dropped): one error state for the whole scan.
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        return _extract(clusters, params)


def _extract(clusters: Sequence[Cluster], params: LineParams) -> List[LineSegment]:
    """Return the lines of :func:`extract_lines` (floating-point errors ignored)."""
    scan = _concat(clusters, params)
    if scan is None:
        return []
    offsets = scan.offsets
    big = (offsets[1:] - offsets[:-1] >= params.min_points).nonzero()[0]
    if not big.size:
        return []
    cols = scan.cols
    n = scan.x.size
    feats = _features(scan.x, scan.y, cols[_RNG], cols[_COS], cols[_SIN], params.sigma_r,
                      params.sigma_phi, pad=1)
    pre = np.zeros((5, n + 1))  # prefix sums of x, y, x^2, y^2, xy (= _prefix5(x, y))
    feats[1:6, :n].cumsum(axis=1, out=pre[:, 1:])
    if params.method == 'split_merge':
        s, e = _split(scan.x, scan.y, offsets[big], offsets[big + 1] - 1, cols[_TOL], 2)
    else:
        # Smooth each cluster's ranges over the bearing (eqs. 8-10), polar -> Cartesian.
        sub, sub_offs = _gather(offsets[big], offsets[big + 1] - 1)
        rng, cos, sin, _, phi = cols[_RNG:].take(sub, axis=1)
        r_s = lowess_groups(phi, rng, sub_offs, params.lowess_span, params.lowess_iterations)
        pieces = alfa_pieces(np.stack([r_s * cos, r_s * sin], axis=1), sub_offs, params)
        pieces = sub[pieces] if pieces.size else pieces
        s, e = pieces[:, 0], pieces[:, 1]
    s, e = _refine_breaks(scan, pre, s, e, params.min_points)
    s, e = _clean_pieces(scan, pre, s, e, params)
    if not s.size:
        return []
    sums, first0, last0, fit, label = _merge(scan, feats, s, e, params)
    sums, first, last, grown = _grow(scan, feats, sums, first0, last0, fit, params)
    if grown or fit.cov is None:
        fit = _solve(sums, scan.origin)
    sums, first, last, fit = _cut_seen_through(scan, feats, sums, first, last, fit,
                                               (s, e, label, first0, last0), params)
    if not first.size:
        return []
    if params.join_occluded:
        fit = _join_occluded(scan, sums, first, last, fit, (s, e), params)
    col, first, last = _occluded_extents(scan, fit, first, last, params)
    if col is not None:
        fit = _Fit(fit.params.take(col, axis=1), fit.rmse[col], fit.count[col],
                   fit.cov.take(col, axis=0))
    return _build(scan, params, fit, first, last)


def explained_points(lines: Sequence[LineSegment], ranges: np.ndarray, angles: np.ndarray,
                     valid: np.ndarray, sigma_r: float = 0.01,
                     sigma_phi: float = math.radians(0.1), n_sigma: float = 3.0,
                     min_distance: float = 0.05) -> np.ndarray:
    """Return (N,) True for the valid beams that a line explains.

    A valid beam i is explained when some line has ``first_index <= i <= last_index`` and
    the point is within ``max(min_distance, n_sigma * sigma_i)`` of that line, sigma_i
    being the std of the point's distance to the line from eq. 7 (range noise along the
    beam, bearing noise across it, projected on the line normal).

    Args:
        lines: Lines of one scan.
        ranges: (N,) ranges of the scan [m].
        angles: (N,) beam angles [rad].
        valid: (N,) bool, the beams that are real returns.
        sigma_r: Range noise std [m].
        sigma_phi: Bearing noise std [rad].
        n_sigma: Gate in standard deviations.
        min_distance: Smallest gate [m].

    Returns:
        (N,) bool mask (always False where not valid).

    """
    ranges = np.asarray(ranges, dtype=float)
    angles = np.asarray(angles, dtype=float)
    out = np.zeros(ranges.shape, dtype=bool)
    valid = np.asarray(valid, dtype=bool)
    r = np.where(valid, ranges, 0.0)
    c, s = np.cos(angles), np.sin(angles)
    for ln in lines:
        sl = slice(ln.first_index, ln.last_index + 1)
        ca, sa = math.cos(ln.alpha), math.sin(ln.alpha)
        d = r[sl] * (c[sl] * ca + s[sl] * sa) - ln.rho
        n_u = c[sl] * ca + s[sl] * sa
        n_v = c[sl] * sa - s[sl] * ca
        sig = np.sqrt((sigma_r * n_u) ** 2 + (r[sl] * sigma_phi * n_v) ** 2)
        out[sl] |= valid[sl] & (np.abs(d) <= np.maximum(min_distance, n_sigma * sig))
    return out
