"""Closed-form least-squares height profiles of pieces of a scan (§4.2, step 5).

A piece's height profile across the scan is a line or a quadratic ``z = a + b s + c s^2``
of the lateral position. Its fit and residual sum of squares come from prefix sums of the
stretch (:func:`_moment_table`) in closed form, the basis 1, t, t^2 orthogonalised by
Gram-Schmidt (:func:`_orthogonal_sums`, :func:`_explained`, :func:`_poly_sse`,
:func:`_fit_piece`); :func:`_piece_nll` is a piece's Gaussian negative log-likelihood with
its own variance, floored by the laser's height noise. Used by
:mod:`.profile_segmentation`, :mod:`.road_edges` and
:func:`landmark_nav.road.terrain.classify_scan`.
"""

from typing import Optional

import numpy as np


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


def _moment_table(s: np.ndarray, z: np.ndarray, var0: np.ndarray) -> np.ndarray:
    """Prefix sums (with a leading zero column) of t^0..t^4, z t^0..t^2, z^2 and ``var0``.

    ``t`` is ``s`` about the stretch's middle; the sums over readings [a, b) of the stretch
    are ``table[:, b] - table[:, a]``.
    """
    t = s - 0.5 * (s[0] + s[-1])
    t2 = t * t
    rows = np.vstack([np.ones_like(t), t, t2, t2 * t, t2 * t2, z, z * t, z * t2, z * z, var0])
    return np.concatenate([np.zeros((10, 1)), np.cumsum(rows, axis=1)], axis=1)


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
