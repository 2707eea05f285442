"""Total-least-squares line fits in Hessian normal form and their covariance.

Corner chapter eqs. 5-10 (TLS fit: alpha eq. 8, rho eq. 9, centroid eq. 10), the line
chapter's point noise (eq. 7) propagated to the covariance of (rho, alpha), and the RMSE
(eq. 21). Every fit is computed from sums of point moments, so that any run of points is
fitted in O(1) from prefix sums (see the comment above ``NUM_SUMS``). Public:
:func:`fit_line`, :func:`point_covariances`.
"""

import math
from typing import List, Optional, Tuple

import numpy as np


TWO_PI = 2.0 * math.pi


def _wrap(a):
    """Wrap angle(s) to [-pi, pi)."""
    return (a + math.pi) % TWO_PI - math.pi


def point_covariances(ranges: np.ndarray, angles: np.ndarray, sigma_r: float,
                      sigma_phi: float) -> np.ndarray:
    """Return (N, 2, 2) Cartesian covariances of scan points (line chapter eq. 7)."""
    ranges = np.asarray(ranges, dtype=float)
    angles = np.asarray(angles, dtype=float)
    c, s = np.cos(angles), np.sin(angles)
    rad = np.stack([np.stack([c * c, c * s], -1), np.stack([c * s, s * s], -1)], -2)
    tan = np.stack([np.stack([s * s, -c * s], -1), np.stack([-c * s, c * c], -1)], -2)
    return (sigma_r ** 2) * rad + ((ranges * sigma_phi) ** 2)[:, None, None] * tan  # eq. 7


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
