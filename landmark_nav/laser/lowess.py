"""Robust lowess smoothing (line chapter, "Smoothing data", eqs. 8-10).

Each value ``y_i`` is replaced by a local linear weighted least-squares fit evaluated at
``x_i``. The fit uses the ``span`` nearest neighbours of ``x_i`` (by ``|x - x_i|``) with
tricube regression weights (eq. 8); ``d(x)`` is the distance to the most distant of them,
which therefore gets weight 0, as in Cleveland (1979) and MATLAB's ``smooth``. Robust
iterations then recompute the fits with the regression weights multiplied by bisquare
robustness weights of the previous residuals (eq. 9, cut off at six median absolute
deviations), so a few outliers lose their influence on their neighbours.

Eq. 10 prints the combined weight as a *sum* ``w_i1 + w_i2``. The procedure it cites
(MATLAB's ``rlowess``, Cleveland 1979) *multiplies* them; with a sum an outlier would keep
its full tricube weight and the smoother would not be robust, so the product is used.

All groups (e.g. the clusters of one scan) are smoothed in one vectorised pass.
"""

from typing import Optional

import numpy as np


def _knn_windows(x: np.ndarray, offsets: np.ndarray, span: np.ndarray) -> np.ndarray:
    """Return (N,) the first index of the ``span`` nearest neighbours of every x (sorted x).

    For sorted x the k nearest neighbours of ``x_i`` are a contiguous window; of the
    ``k`` windows containing ``i`` the one with the smallest largest distance wins.
    """
    n = x.shape[0]
    sizes = offsets[1:] - offsets[:-1]
    group = np.arange(sizes.size).repeat(sizes)
    lo_g = offsets[group]
    k = span[group]
    kmax = max(span.tolist())
    i = np.arange(n)
    steps = np.arange(kmax)
    # Candidate window starts i-k+1 .. i, clipped to the group.
    cand = i[:, None] - steps
    hi_start = offsets[group + 1] - k
    k_col = k[:, None]
    ok = steps < k_col
    np.maximum(cand, lo_g[:, None], out=cand)  # np.clip
    np.minimum(cand, hi_start[:, None], out=cand)
    x_col = x[:, None]
    left = x_col - x[cand]
    right = x[np.minimum(cand + k_col - 1, n - 1)] - x_col
    reach = np.where(ok, np.maximum(left, right), np.inf)
    return cand.ravel()[reach.argmin(axis=1) + i * kmax]


def _group_median(values: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Return the median of each group ``values[offsets[g]:offsets[g + 1]]`` (vectorised)."""
    sizes = offsets[1:] - offsets[:-1]
    group = np.arange(sizes.size).repeat(sizes)
    order = np.lexsort((values, group))
    s = values[order]
    lo = offsets[:-1] + (sizes - 1) // 2
    hi = offsets[:-1] + sizes // 2
    return 0.5 * (s[lo] + s[hi])


def lowess_groups(x: np.ndarray, y: np.ndarray, offsets: np.ndarray, span: int = 9,
                  iterations: int = 2) -> np.ndarray:
    """Smooth several series at once; series g is ``x[offsets[g]:offsets[g + 1]]``.

    Args:
        x: (N,) predictor, increasing within each series (e.g. beam angles) [any unit].
        y: (N,) response (e.g. ranges).
        offsets: (G + 1,) increasing series boundaries, ``offsets[0] == 0``,
            ``offsets[-1] == N``; every series needs at least one point.
        span: number of nearest neighbours in each local fit (>= 2); a series shorter
            than ``span`` uses all its points.
        iterations: robust (bisquare) iterations after the first fit (0 = plain lowess).

    Returns:
        (N,) smoothed response.

    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    offsets = np.asarray(offsets, dtype=np.int64)
    n = x.shape[0]
    if n == 0:
        return np.zeros(0)
    sizes = offsets[1:] - offsets[:-1]
    k_g = np.minimum(sizes, int(span))
    starts = _knn_windows(x, offsets, k_g)
    group = np.arange(sizes.size).repeat(sizes)
    k = k_g[group]
    kmax = max(k_g.tolist())
    cols = np.arange(kmax)[None, :]
    in_win = cols < k[:, None]
    idx = np.minimum(starts[:, None] + cols, n - 1)
    u = x[idx] - x[:, None]  # predictor relative to x_i, so the fit at x_i is the intercept
    u = np.where(in_win, u, 0.0)
    yw = y[idx]
    dist = np.abs(u)  # 0 outside the window
    d = dist.max(axis=1, keepdims=True)  # d(x): distance to the most distant neighbour
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = np.where(d > 0.0, dist / d, 0.0)
    w1 = np.where(in_win, (1.0 - ratio ** 3) ** 3, 0.0)  # eq. 8, tricube
    fit = _weighted_linear(u, yw, w1, y)
    scale = float(np.abs(y).max()) + 1.0
    for _ in range(int(iterations)):
        res = y - fit
        mad = _group_median(np.abs(res), offsets)  # M of eq. 9
        six_m = 6.0 * np.maximum(mad, 1e-12 * scale)[group]
        q = res / six_m
        w2 = np.where(np.abs(q) < 1.0, (1.0 - q * q) ** 2, 0.0)  # eq. 9, bisquare
        fit = _weighted_linear(u, yw, w1 * w2[idx], fit)  # eq. 10 (product, see module doc)
    return fit


def _weighted_linear(u: np.ndarray, yw: np.ndarray, w: np.ndarray,
                     fallback: np.ndarray) -> np.ndarray:
    """Return the intercepts of row-wise weighted linear fits ``y = a + b u``."""
    sw = w.sum(axis=1)
    su = (w * u).sum(axis=1)
    sy = (w * yw).sum(axis=1)
    suu = (w * u * u).sum(axis=1)
    suy = (w * u * yw).sum(axis=1)
    det = sw * suu - su * su
    with np.errstate(divide='ignore', invalid='ignore'):
        lin = (sy * suu - su * suy) / det
        mean = sy / sw
    good_lin = det > 1e-12 * np.maximum(sw * suu, 1e-300)
    out = np.where(good_lin, lin, mean)
    return np.where(np.isfinite(out) & (sw > 0.0), out, fallback)


def lowess(x: np.ndarray, y: np.ndarray, span: int = 9, iterations: int = 2,
           sort: Optional[bool] = None) -> np.ndarray:
    """Return the robust lowess smoothing of ``y(x)`` (eqs. 8-10).

    Args:
        x: (K,) predictor values (e.g. beam angles).
        y: (K,) responses (e.g. ranges).
        span: number of nearest neighbours per local linear fit (>= 2).
        iterations: number of robust bisquare iterations (>= 0, 0 = plain lowess).
        sort: sort by x first (default: only if x is not already non-decreasing).

    Returns:
        (K,) smoothed y, in the order of the input.

    Raises:
        ValueError: shapes differ, non-finite input, span < 2 or iterations < 0.

    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.ndim != 1 or x.shape != y.shape:
        raise ValueError('x and y must be 1-D arrays of equal length')
    if int(span) != span or span < 2:
        raise ValueError(f'span must be an integer >= 2, got {span}')
    if int(iterations) != iterations or iterations < 0:
        raise ValueError(f'iterations must be an integer >= 0, got {iterations}')
    if x.size == 0:
        return np.zeros(0)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError('x and y must be finite')
    if sort is None:
        sort = bool(np.any(np.diff(x) < 0.0))
    order = np.argsort(x, kind='stable') if sort else None
    xs = x[order] if sort else x
    ys = y[order] if sort else y
    fit = lowess_groups(xs, ys, np.array([0, x.size]), int(span), int(iterations))
    if not sort:
        return fit
    out = np.empty_like(fit)
    out[order] = fit
    return out
