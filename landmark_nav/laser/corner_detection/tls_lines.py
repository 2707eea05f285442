"""Total-least-squares lines from moment sums (corner chapter eqs. 5-10) and their noise.

The point noise ``Q_i`` (line chapter eq. 7, :func:`point_covariance`), TLS lines from
moment sums (:func:`_lines`), the intersection of two lines and its first-order
covariance (:func:`_corner_covariance`), and the variance of a line's angle
(:func:`_line_angle_variance`).
"""

from dataclasses import dataclass
from typing import Tuple

import numpy as np


def point_covariance(ranges: np.ndarray, angles: np.ndarray, sigma_r: float,
                     sigma_phi: float) -> np.ndarray:
    """Return the (..., 2, 2) covariance ``Q_i`` of scan points (line chapter, eq. 7)."""
    d = np.asarray(ranges, dtype=float)
    c, s = np.cos(angles), np.sin(angles)
    a = (sigma_phi * d) ** 2
    b = sigma_r ** 2
    q = np.empty(d.shape + (2, 2))
    q[..., 0, 0] = a * s * s + b * c * c  # eq. 7
    q[..., 1, 1] = a * c * c + b * s * s
    q[..., 0, 1] = q[..., 1, 0] = (b - a) * s * c
    return q


@dataclass(frozen=True, eq=False)
class _Lines:
    """TLS lines (any leading shape) from moment sums."""

    alpha: np.ndarray   # normal angle (eq. 8)
    rho: np.ndarray     # signed distance to the origin (eq. 9)
    xm: np.ndarray      # centroid (eq. 10)
    ym: np.ndarray
    n: np.ndarray       # number of points
    num: np.ndarray     # -2 Sxy (numerator of eq. 8)
    den: np.ndarray     # Syy - Sxx (denominator of eq. 8)
    c: np.ndarray       # cos(alpha)
    s: np.ndarray       # sin(alpha)

    def take(self, sel: np.ndarray) -> '_Lines':
        """Return the rows ``sel``."""
        return _Lines(*(getattr(self, f)[sel] for f in self.__dataclass_fields__))


def _lines(m: np.ndarray) -> _Lines:
    """Fit total-least-squares lines (eqs. 5-10) from moment sums ``m`` (6, ...).

    ``m`` holds ``[n, sum x, sum y, sum x^2, sum y^2, sum xy]``.
    """
    n = m[0]
    ns = np.maximum(n, 1.0)
    xm = m[1] / ns  # eq. 10
    ym = m[2] / ns
    sxx = m[3] - m[1] * xm
    syy = m[4] - m[2] * ym
    sxy = m[5] - m[1] * ym
    num = -2.0 * sxy
    den = syy - sxx
    alpha = 0.5 * np.arctan2(num, den)  # eq. 8
    c, s = np.cos(alpha), np.sin(alpha)
    return _Lines(alpha, xm * c + ym * s, xm, ym, n, num, den, c, s)  # eq. 9


def _weighted_moments(w: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Return moment sums (6, ...) of points ``x, y`` (..., M) with weights ``w``."""
    f = np.empty((6,) + x.shape)
    f[0] = w
    np.multiply(w, x, out=f[1])
    np.multiply(w, y, out=f[2])
    np.multiply(f[1], x, out=f[3])
    np.multiply(f[2], y, out=f[4])
    np.multiply(f[1], y, out=f[5])
    return f.sum(axis=-1)


def _smallest_scatter(m: np.ndarray) -> np.ndarray:
    """Return the TLS residual (smallest scatter eigenvalue) of moment sums ``m`` (6, ...)."""
    n = np.maximum(m[0], 1.0)
    sxx = m[3] - m[1] * m[1] / n
    syy = m[4] - m[2] * m[2] / n
    sxy = m[5] - m[1] * m[2] / n
    half = 0.5 * (sxx - syy)
    return 0.5 * (sxx + syy) - np.sqrt(half * half + sxy * sxy)


def _intersect(ln: _Lines) -> Tuple[np.ndarray, np.ndarray]:
    """Intersect line 0 and line 1 of each row (lines of shape (K, 2))."""
    c0, c1, s0, s1 = ln.c[:, 0], ln.c[:, 1], ln.s[:, 0], ln.s[:, 1]
    det = c0 * s1 - s0 * c1  # 0 for parallel lines: inf / nan fail every later check
    r0, r1 = ln.rho[:, 0], ln.rho[:, 1]
    return (s1 * r0 - s0 * r1) / det, (c0 * r1 - c1 * r0) / det


def _arm_directions(ln: _Lines, cx: np.ndarray, cy: np.ndarray
                    ) -> Tuple[np.ndarray, np.ndarray]:
    """Return unit directions (K, 2) of both lines, from the corner toward the centroid."""
    ux, uy = -ln.s, ln.c
    sign = np.where((ln.xm - cx[:, None]) * ux + (ln.ym - cy[:, None]) * uy < 0.0, -1.0, 1.0)
    return sign * ux, sign * uy


def _corner_covariance(x: np.ndarray, y: np.ndarray, w: np.ndarray, ln: _Lines,
                       cx: np.ndarray, cy: np.ndarray, sigma_r: float,
                       sigma_phi: float) -> np.ndarray:
    """First-order covariance (K, 2, 2) of the intersection ``(cx, cy)`` of two TLS lines.

    ``x``, ``y`` (K, 2, M) arm points with 0/1 weights ``w`` and the fitted lines ``ln``
    (K, 2). Each point moves the corner through its own line only: with ``A p = rho`` (rows
    ``[cos a_k, sin a_k]``), ``dp = A^-1[:, k] (d rho_k - t_k d a_k)``, ``t_k = n_k^perp . p``.
    A scan point is ``D_i (cos phi_i, sin phi_i)``, so its range and bearing directions come
    from ``x, y``.
    """
    q = ln.num * ln.num + ln.den * ln.den
    q = np.where(q > 0.0, q, np.inf)[..., None]
    dx = x - ln.xm[..., None]
    dy = y - ln.ym[..., None]
    num, den = ln.num[..., None], ln.den[..., None]
    # Analytic Jacobian of eq. 8 (centroid terms vanish because sum(dx) = sum(dy) = 0).
    da_dx = (num * dx - den * dy) / q
    da_dy = -(den * dx + num * dy) / q
    ca, sa = ln.c, ln.s
    lever = (ln.ym * ca - ln.xm * sa + sa * cx[:, None] - ca * cy[:, None])[..., None]
    ns = np.maximum(ln.n, 1.0)[..., None]
    gx = w * ((ca[..., None] / ns) + lever * da_dx)  # d(rho - t alpha) / dx_i, eq. 9
    gy = w * ((sa[..., None] / ns) + lever * da_dy)
    # g Q_i g^T with Q_i of eq. 7 = sigma_phi^2 D^2 (tangential)^2 + sigma_r^2 (radial)^2,
    # with D (cos phi, sin phi) = (x, y): D * tangential = gy x - gx y, radial = (gx x + gy y) / D
    tang = gy * x - gx * y
    rad = (gx * x + gy * y) / np.maximum(np.sqrt(x * x + y * y), 1e-12)
    var = ((sigma_phi * sigma_phi) * (tang * tang)
           + (sigma_r * sigma_r) * (rad * rad)).sum(axis=-1)  # (K, 2)
    det = ca[:, 0] * sa[:, 1] - sa[:, 0] * ca[:, 1]
    a0x, a0y = sa[:, 1] / det, -ca[:, 1] / det  # A^-1[:, 0]
    a1x, a1y = -sa[:, 0] / det, ca[:, 0] / det  # A^-1[:, 1]
    v0, v1 = var[:, 0], var[:, 1]
    cov = np.empty((ca.shape[0], 2, 2))
    cov[:, 0, 0] = v0 * a0x * a0x + v1 * a1x * a1x
    cov[:, 1, 1] = v0 * a0y * a0y + v1 * a1y * a1y
    cov[:, 0, 1] = cov[:, 1, 0] = v0 * a0x * a0y + v1 * a1x * a1y
    return cov


def _line_angle_variance(x: np.ndarray, y: np.ndarray, w: np.ndarray, ln: _Lines,
                         sigma_r: float, sigma_phi: float) -> np.ndarray:
    """Return (K, 2) first-order variances of the TLS lines' angles ``alpha`` (eq. 8).

    The analytic Jacobian of eq. 8 (as :func:`_corner_covariance`) with the point noise
    ``Q_i`` of eq. 7.
    """
    q = ln.num * ln.num + ln.den * ln.den
    q = np.where(q > 0.0, q, np.inf)[..., None]
    dx = x - ln.xm[..., None]
    dy = y - ln.ym[..., None]
    num, den = ln.num[..., None], ln.den[..., None]
    gx = w * (num * dx - den * dy) / q
    gy = -w * (den * dx + num * dy) / q
    tang = gy * x - gx * y
    rad = (gx * x + gy * y) / np.maximum(np.sqrt(x * x + y * y), 1e-12)
    return ((sigma_phi * sigma_phi) * (tang * tang)
            + (sigma_r * sigma_r) * (rad * rad)).sum(axis=-1)
