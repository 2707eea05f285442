"""Line extraction from laser scan clusters: split-and-merge and ALFA.

Both methods work on the clusters of :func:`landmark_nav.laser.segmentation.segment_scan`
and return :class:`LineSegment` objects in the laser frame.

* ``split_merge`` (corner chapter, section 2.1.2): recursive split of a cluster at the point
  of largest perpendicular distance to the chord (eq. 4) while it exceeds
  ``split_threshold``; each piece is fitted by total least squares in Hessian normal form
  (eqs. 5-10); adjacent collinear pieces are merged.
* ``alfa`` (line chapter, ALFA pseudo code): each cluster's ranges are smoothed by robust
  lowess (tricube weights eq. 8, bisquare robustness weights eq. 9); the end of each line
  is then found by binary search: the longest run from the current start whose fit keeps
  its RMSE (eq. 21) below a floating threshold and whose RMSE gradient stays low. The
  threshold floats between ``rmse_min`` and ``rmse_max``: a good fit pulls it to the mean
  of itself and the current RMSE, a steep RMSE gradient lowers it to the current RMSE.
  Breakpoints are decided on the smoothed points; the final lines are fitted on the
  original points, and adjacent collinear lines are merged as for split-and-merge.

Choices where the chapters are silent, or misprinted:

* Fits and RMSE use perpendicular (total least squares) residuals, not the vertical
  residuals of the line chapter's eq. 12, which fail on lines parallel to the y axis.
* Lowess combines the two weights by product, as robust lowess does (the line chapter
  prints a sum, eq. 10, which could not give an outlier the zero weight its Fig. 1 shows).
* Merging: two adjacent lines are merged when their (rho, alpha) difference passes a
  chi-square test (95 %, 2 dof) with the sum of their covariances, and the merged fit
  still passes the split criterion.
* The (rho, alpha) covariance propagates the per-point noise of the line chapter's
  eq. 7 through first-order derivatives of the total-least-squares solution.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

from landmark_nav.geometry import wrap_angle
from landmark_nav.laser.segmentation import Cluster
import numpy as np

METHODS = ('split_merge', 'alfa')
CHI2_2DOF_95 = 5.991


@dataclass(frozen=True)
class LineSegment:
    """A line fitted to consecutive scan points (laser frame).

    Attributes:
        rho: Distance of the line to the laser origin, >= 0 [m] (eq. 5).
        alpha: Angle of the line normal, wrapped to [-pi, pi) [rad].
        start: (2,) projection of the first supporting point onto the line.
        end: (2,) projection of the last supporting point.
        num_points: Number of supporting points.
        rmse: Perpendicular RMSE of the supporting points [m].
        covariance: (2, 2) covariance of (rho, alpha).
        first_index: Beam index of the first supporting point.
        last_index: Beam index of the last supporting point.

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
        return float(np.hypot(*(self.end - self.start)))


@dataclass(frozen=True)
class LineParams:
    """Line extraction parameters (SI units).

    Attributes:
        method: ``'split_merge'`` (default) or ``'alfa'``.
        split_threshold: Split-and-merge distance tolerance [m] (eq. 4); None means
            ``max(0.03, 4 * sigma_r)``.
        min_points: Fewest points of a line (shorter fits are too uncertain to be useful).
        min_length: Shortest line [m].
        merge_chi2: Chi-square gate of the collinearity test for merging (2 dof).
        merge_gap: Largest gap between collinear lines of neighbouring clusters that are
            merged into one line [m].
        sigma_r: Range noise std [m] (eq. 7).
        sigma_phi: Bearing noise std [rad] (eq. 7).
        lowess_span: ALFA: lowess window in points (odd).
        lowess_iterations: ALFA: robustness iterations (bisquare weights, eq. 9).
        rmse_min: ALFA: lowest floating RMSE threshold [m]; None means ``0.3 * sigma_r``.
        rmse_max: ALFA: highest floating RMSE threshold [m]; None means ``sigma_r``.
        max_gradient: ALFA: largest RMSE growth per added point, relative to the threshold.

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

    def __post_init__(self) -> None:
        """Validate; raise ValueError naming the bad parameter."""
        def bad(name: str, rule: str) -> ValueError:
            return ValueError(f'LineParams.{name} must be {rule}, got {getattr(self, name)!r}')

        def positive(v, allow_none=False) -> bool:
            if v is None:
                return allow_none
            return isinstance(v, (int, float)) and not isinstance(v, bool) and \
                math.isfinite(v) and v > 0

        if self.method not in METHODS:
            raise bad('method', 'one of ' + ', '.join(METHODS))
        if not positive(self.split_threshold, allow_none=True):
            raise bad('split_threshold', 'None or a number > 0')
        if not isinstance(self.min_points, int) or self.min_points < 2:
            raise bad('min_points', 'an integer >= 2')
        if not (isinstance(self.min_length, (int, float)) and self.min_length >= 0):
            raise bad('min_length', 'a number >= 0')
        if not positive(self.merge_chi2):
            raise bad('merge_chi2', 'a number > 0')
        if not (isinstance(self.merge_gap, (int, float)) and self.merge_gap >= 0):
            raise bad('merge_gap', 'a number >= 0')
        if not positive(self.sigma_r):
            raise bad('sigma_r', 'a number > 0')
        if not (isinstance(self.sigma_phi, (int, float)) and self.sigma_phi >= 0):
            raise bad('sigma_phi', 'a number >= 0')
        if (not isinstance(self.lowess_span, int) or self.lowess_span < 3
                or self.lowess_span % 2 == 0):
            raise bad('lowess_span', 'an odd integer >= 3')
        if not isinstance(self.lowess_iterations, int) or self.lowess_iterations < 0:
            raise bad('lowess_iterations', 'an integer >= 0')
        if not positive(self.rmse_min, allow_none=True):
            raise bad('rmse_min', 'None or a number > 0')
        if not positive(self.rmse_max, allow_none=True):
            raise bad('rmse_max', 'None or a number > 0')
        if self.rmse_bounds[0] > self.rmse_bounds[1]:
            raise bad('rmse_min', f'<= rmse_max ({self.rmse_bounds[1]})')
        if not positive(self.max_gradient):
            raise bad('max_gradient', 'a number > 0')

    @property
    def threshold(self) -> float:
        """Return the split tolerance [m]."""
        if self.split_threshold is not None:
            return float(self.split_threshold)
        return max(0.03, 4.0 * self.sigma_r)

    @property
    def rmse_bounds(self) -> Tuple[float, float]:
        """Return (rmse_min, rmse_max) of the ALFA floating threshold [m]."""
        lo = 0.3 * self.sigma_r if self.rmse_min is None else float(self.rmse_min)
        hi = self.sigma_r if self.rmse_max is None else float(self.rmse_max)
        return lo, hi


def point_covariances(ranges: np.ndarray, angles: np.ndarray, sigma_r: float,
                      sigma_phi: float) -> np.ndarray:
    """Return (N, 2, 2) Cartesian covariances of scan points (line chapter eq. 7)."""
    c, s = np.cos(angles), np.sin(angles)
    rad = np.stack([np.stack([c * c, c * s], -1), np.stack([c * s, s * s], -1)], -2)
    tan = np.stack([np.stack([s * s, -c * s], -1), np.stack([-c * s, c * c], -1)], -2)
    return (sigma_r ** 2) * rad + ((ranges * sigma_phi) ** 2)[:, None, None] * tan  # eq. 7


def _tls(points: np.ndarray) -> Tuple[float, float, np.ndarray, float, float]:
    """Fit by total least squares; return rho, alpha, centroid, lambda_min, lambda_max."""
    m = points.mean(axis=0)  # eq. 10
    q = points - m
    sxx, syy, sxy = float(q[:, 0] @ q[:, 0]), float(q[:, 1] @ q[:, 1]), float(q[:, 0] @ q[:, 1])
    alpha = 0.5 * math.atan2(-2.0 * sxy, syy - sxx)  # eq. 8
    rho = m[0] * math.cos(alpha) + m[1] * math.sin(alpha)  # eq. 9
    if rho < 0.0:
        rho, alpha = -rho, alpha + math.pi
    half_trace, det = 0.5 * (sxx + syy), sxx * syy - sxy * sxy
    disc = math.sqrt(max(half_trace * half_trace - det, 0.0))
    return rho, float(wrap_angle(alpha)), m, half_trace - disc, half_trace + disc


def fit_line(points: np.ndarray, ranges: np.ndarray, angles: np.ndarray, sigma_r: float,
             sigma_phi: float) -> Tuple[float, float, np.ndarray, float]:
    """Fit a line (eqs. 5-10) and propagate the point noise (eq. 7) to (rho, alpha).

    Returns:
        rho, alpha, covariance (2, 2) of (rho, alpha), perpendicular RMSE.

    """
    points = np.asarray(points, dtype=float)
    rho, alpha, m, lam1, lam2 = _tls(points)
    n = np.array([math.cos(alpha), math.sin(alpha)])
    d = np.array([-math.sin(alpha), math.cos(alpha)])
    q = points - m
    resid = points @ n - rho
    rmse = float(math.sqrt(np.mean(resid * resid)))
    gap = lam1 - lam2
    if gap >= -1e-15:
        return rho, alpha, np.full((2, 2), np.inf), rmse
    # First-order derivatives of the TLS solution w.r.t. each point (eigenvector
    # perturbation): d alpha / d p_i = ((q_i.n) d + (q_i.d) n) / (lambda_min - lambda_max),
    # d rho / d p_i = (d.m) d alpha / d p_i + n / N. With the eq. 7 noise
    # Q_i = sigma_r^2 u u^T + (r sigma_phi)^2 v v^T (u along the beam, v across it),
    # J Q J^T is a sum of two rank-one terms per point: only dot products are needed.
    qn, qd = q @ n, q @ d
    c, s = np.cos(angles), np.sin(angles)
    cov = np.zeros((2, 2))
    for ux, uy, weight in ((c, s, sigma_r ** 2), (-s, c, (ranges * sigma_phi) ** 2)):
        a_u = (qn * (d[0] * ux + d[1] * uy) + qd * (n[0] * ux + n[1] * uy)) / gap
        r_u = float(d @ m) * a_u + (n[0] * ux + n[1] * uy) / len(points)
        cov += np.array([[np.sum(weight * r_u * r_u), np.sum(weight * r_u * a_u)],
                         [0.0, np.sum(weight * a_u * a_u)]])
    cov[1, 0] = cov[0, 1]
    return rho, alpha, cov, rmse


def _fit_segment(pts: np.ndarray, ranges: np.ndarray, angles: np.ndarray,
                 indices: np.ndarray, params: LineParams) -> LineSegment:
    """Fit points (with their ranges, angles and beam indices) into a LineSegment."""
    rho, alpha, cov, rmse = fit_line(pts, ranges, angles, params.sigma_r, params.sigma_phi)
    n = np.array([math.cos(alpha), math.sin(alpha)])
    start = pts[0] - (pts[0] @ n - rho) * n
    end = pts[-1] - (pts[-1] @ n - rho) * n
    return LineSegment(rho, alpha, start, end, len(pts), rmse, cov, int(indices[0]),
                       int(indices[-1]))


def _make_segment(cluster: Cluster, lo: int, hi: int, params: LineParams) -> LineSegment:
    """Fit the points lo..hi (inclusive) of a cluster into a LineSegment."""
    sl = slice(lo, hi + 1)
    return _fit_segment(cluster.points[sl], cluster.ranges[sl], cluster.angles[sl],
                        cluster.indices[sl], params)


def _collinear(a: LineSegment, b: LineSegment, gate: float) -> bool:
    """Chi-square test that two lines have the same (rho, alpha)."""
    diff = np.array([a.rho - b.rho, float(wrap_angle(a.alpha - b.alpha))])
    cov = a.covariance + b.covariance
    if not np.all(np.isfinite(cov)) or np.linalg.det(cov) <= 0:
        return False
    return float(diff @ np.linalg.solve(cov, diff)) <= gate


def _split(points: np.ndarray, threshold: np.ndarray) -> List[Tuple[int, int]]:
    """Split points recursively at the largest chord distance (eq. 4); return index ranges.

    ``threshold`` (N,) is the distance tolerance of each point.
    """
    out, stack = [], [(0, len(points) - 1)]
    while stack:
        lo, hi = stack.pop()
        if hi - lo < 2:
            out.append((lo, hi))
            continue
        p, f = points[lo], points[hi]
        a, b = f[1] - p[1], f[0] - p[0]
        norm = math.hypot(a, b)
        seg = points[lo + 1:hi]
        dist = np.abs(a * (seg[:, 0] - p[0]) - b * (seg[:, 1] - p[1])) / max(norm, 1e-12)
        k = int(np.argmax(dist))
        if dist[k] > threshold[lo + 1 + k]:
            stack.append((lo + 1 + k, hi))
            stack.append((lo, lo + 1 + k))
        else:
            out.append((lo, hi))
    return sorted(out)


def _merge(cluster: Cluster, pieces: List[Tuple[int, int]], params: LineParams
           ) -> List[Tuple[int, int, Optional[LineSegment]]]:
    """Merge adjacent collinear pieces (chi-square test on rho, alpha); keep their fits."""
    merged = [(lo, hi, _make_segment(cluster, lo, hi, params) if hi - lo >= 1 else None)
              for lo, hi in pieces]
    i = 0
    while i + 1 < len(merged):
        (a0, _, la), (_, b1, lb) = merged[i], merged[i + 1]
        if la is not None and lb is not None and _collinear(la, lb, params.merge_chi2):
            merged[i:i + 2] = [(a0, b1, _make_segment(cluster, a0, b1, params))]
            continue
        i += 1
    return merged


def lowess(x: np.ndarray, y: np.ndarray, span: int = 7, iterations: int = 2) -> np.ndarray:
    """Smooth y(x) by robust locally weighted linear regression (eqs. 8-10).

    Each point is fitted by a weighted line over its ``span`` nearest neighbours in index
    order, with tricube distance weights (eq. 8) times bisquare robustness weights from
    the previous pass's residuals (eq. 9, zero beyond 6 median absolute deviations).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(x)
    if n < 3:
        return y.copy()
    k = min(span, n)
    start = np.clip(np.arange(n) - k // 2, 0, n - k)
    idx = start[:, None] + np.arange(k)[None, :]  # (n, k) window of each point
    xs, ys = x[idx], y[idx]
    dist = np.abs(xs - x[:, None])
    dmax = dist.max(axis=1, keepdims=True) * 1.0001 + 1e-15
    w_dist = (1.0 - (dist / dmax) ** 3) ** 3  # eq. 8
    robust = np.ones(n)
    smooth = y
    for it in range(iterations + 1):
        w = w_dist * robust[idx]  # product of the two weights (eq. 10, see module note)
        sw = w.sum(axis=1)
        sw = np.where(sw > 0, sw, 1.0)
        mx = (w * xs).sum(axis=1) / sw
        my = (w * ys).sum(axis=1) / sw
        dx = xs - mx[:, None]
        sxx = (w * dx * dx).sum(axis=1)
        sxy = (w * dx * (ys - my[:, None])).sum(axis=1)
        slope = np.where(sxx > 1e-30, sxy / np.where(sxx > 1e-30, sxx, 1.0), 0.0)
        smooth = my + slope * (x - mx)
        if it == iterations:
            break
        resid = y - smooth
        # MAD -> 0 (noise-free data) is the limit where every residual point is an outlier.
        mad = max(float(np.median(np.abs(resid))), 1e-12 * (1.0 + float(np.abs(y).max())))
        u = resid / (6.0 * mad)
        robust = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)  # eq. 9
    return smooth


class _Moments:
    """Prefix sums of point moments: O(1) total-least-squares residuals of any run."""

    def __init__(self, points: np.ndarray) -> None:
        """Accumulate x, y, x^2, y^2 and xy."""
        x, y = points[:, 0], points[:, 1]
        self.c = np.vstack([np.zeros((1, 5)), np.cumsum(
            np.column_stack([x, y, x * x, y * y, x * y]), axis=0)])

    def sse(self, lo, hi):
        """Return the summed squared perpendicular residuals of points lo..hi (arrays ok)."""
        lo, hi = np.asarray(lo), np.asarray(hi)
        s = self.c[hi + 1] - self.c[lo]
        m = (hi - lo + 1)[..., None] if s.ndim > 1 else hi - lo + 1
        mean = s / m
        sxx = mean[..., 2] - mean[..., 0] ** 2
        syy = mean[..., 3] - mean[..., 1] ** 2
        sxy = mean[..., 4] - mean[..., 0] * mean[..., 1]
        half = 0.5 * (sxx + syy)
        lam = half - np.sqrt(np.maximum(half * half - (sxx * syy - sxy * sxy), 0.0))
        return np.maximum(lam, 0.0) * (hi - lo + 1)

    def rmse(self, lo: int, hi: int) -> float:
        """Return the perpendicular RMSE of the TLS fit of points lo..hi (eq. 21)."""
        sx, sy, sxx, syy, sxy = (self.c[hi + 1] - self.c[lo]).tolist()
        m = hi - lo + 1
        mx, my = sx / m, sy / m
        vxx, vyy, vxy = sxx / m - mx * mx, syy / m - my * my, sxy / m - mx * my
        half = 0.5 * (vxx + vyy)
        lam = half - math.sqrt(max(half * half - (vxx * vyy - vxy * vxy), 0.0))
        return math.sqrt(max(lam, 0.0))


def _refine_breaks(points: np.ndarray, pieces: List[Tuple[int, int]], reach: int
                   ) -> List[Tuple[int, int]]:
    """Move each break between adjacent pieces to where the two fits fit best.

    The split step breaks at the point farthest from a chord, which near a corner is often
    a few points off the true junction; this searches ``reach`` points either side for the
    break that minimises the summed squared perpendicular residuals of both pieces.
    """
    if len(pieces) < 2:
        return pieces
    moments = _Moments(points)
    out = [list(p) for p in pieces]
    for i in range(len(out) - 1):
        lo, k, hi = out[i][0], out[i][1], out[i + 1][1]
        cand = np.arange(max(lo + 2, k - reach), min(hi - 2, k + reach) + 1)
        if cand.size == 0:
            continue
        cost = moments.sse(np.full(cand.size, lo), cand) + moments.sse(
            cand, np.full(cand.size, hi))
        best_k = int(cand[np.argmin(cost)])
        out[i][1] = best_k
        out[i + 1][0] = best_k
    return [tuple(p) for p in out]


def _alfa_pieces(cluster: Cluster, params: LineParams) -> List[Tuple[int, int]]:
    """Break one cluster into lines with ALFA's binary search (line chapter pseudo code)."""
    n = len(cluster)
    smooth_r = lowess(cluster.angles, cluster.ranges, params.lowess_span,
                      params.lowess_iterations)
    pts = np.column_stack([smooth_r * np.cos(cluster.angles),
                           smooth_r * np.sin(cluster.angles)])
    rmse = _Moments(pts).rmse
    lo_thr, hi_thr = params.rmse_bounds
    least = params.min_points
    step = max(2, least // 2)
    pieces = []
    k_min = 0
    while n - k_min >= least:
        max_err = hi_thr
        b1, b2 = k_min + least - 1, n - 1
        a = b2
        while b2 - b1 > 0:
            err = rmse(k_min, a)
            prev = rmse(k_min, max(a - step, k_min + 1))
            grad = (err - prev) / step / max_err
            if err > max_err or grad > params.max_gradient:
                b2 = a - 1  # bad fit: split the recent data
                if grad > params.max_gradient:
                    max_err = min(max(err, lo_thr), max_err)
                a = (b1 + b2) // 2
            else:
                b1 = a  # good fit: add half of the remaining data
                max_err = min(max(0.5 * (err + max_err), lo_thr), hi_thr)
                a = int(math.floor(0.5 * (b1 + b2) + 0.5))
        end = max(b1, k_min + least - 1) if rmse(k_min, b1) <= hi_thr else b1
        pieces.append((k_min, end))
        k_min = end + 1
    if k_min < n:
        pieces.append((k_min, n - 1))
    return pieces


def extract_lines(clusters: Sequence[Cluster], params: Optional[LineParams] = None
                  ) -> List[LineSegment]:
    """Extract lines from the clusters of one scan with the method of ``params``."""
    params = params or LineParams()
    parts = []  # (points, ranges, angles, indices) of each line, in scan order
    for cluster in clusters:
        if len(cluster) < params.min_points:
            continue
        if params.method == 'split_merge':
            # The tolerance grows with the bearing noise's lateral effect at range.
            tol = params.threshold + 3.0 * params.sigma_phi * cluster.ranges
            pieces = _refine_breaks(cluster.points, _split(cluster.points, tol),
                                    params.min_points)
        else:
            pieces = _refine_breaks(cluster.points, _alfa_pieces(cluster, params),
                                    params.min_points)
        for lo, hi, seg in _merge(cluster, pieces, params):
            if hi - lo + 1 >= params.min_points:
                sl = slice(lo, hi + 1)
                parts.append(((cluster.points[sl], cluster.ranges[sl], cluster.angles[sl],
                               cluster.indices[sl]), seg))
    # Lines of neighbouring clusters (a wall cut by a dropout or a spurious return) are
    # merged when collinear and their ends are less than merge_gap apart.
    lines, members = [], []
    for part, seg in parts:
        if lines and members[-1][-1][3][-1] < part[3][0]:
            prev = lines[-1]
            if (np.hypot(*(seg.start - prev.end)) <= params.merge_gap
                    and _collinear(prev, seg, params.merge_chi2)):
                group = members[-1] + [part]
                joined = _fit_segment(*(np.concatenate(x) for x in zip(*group)), params)
                lines[-1], members[-1] = joined, group
                continue
        lines.append(seg)
        members.append([part])
    return [ln for ln in lines
            if ln.length >= params.min_length and np.all(np.isfinite(ln.covariance))]
