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


def _knn_windows(x: np.ndarray, offsets: np.ndarray, span: np.ndarray, group: np.ndarray
                 ) -> np.ndarray:
    """Return (N,) the first index of the ``span`` nearest neighbours of every x (sorted x).

    ``group`` (N,) is the group of every x. For sorted x the k nearest neighbours of
    ``x_i`` are a contiguous window; of the ``k`` windows containing ``i`` the one with the
    smallest largest distance wins (the first one on ties). Candidates are laid out (k, N),
    one row per candidate start.
    """
    n = x.shape[0]
    lo_g = offsets[group]
    k = span[group]
    i = np.arange(n)
    spans = span.tolist()
    if n > 1 and spans and all(v % 2 == 1 for v in spans):
        # Equally spaced x (beams of a scan): the window centred on x_i, clipped to its
        # group, is the only one whose reach is below (h + 1) steps, h = (k - 1) // 2,
        # when the steps differ by less than 1 / (2 h) of the smallest (a window shifted
        # by one reaches h + 1 steps on one side). Then no candidates are needed.
        step = x[1:] - x[:-1]
        inner = step[(group[1:] == group[:-1]).nonzero()[0]]
        h = (max(spans) - 1) // 2
        smallest = inner.min() if inner.size else 0.0
        if not inner.size or (smallest > 0.0
                              and (inner.max() - smallest) * (2 * h) < smallest):
            return np.minimum(np.maximum(i - (k - 1) // 2, lo_g), offsets[group + 1] - k)
    kmax = max(spans)
    steps = np.arange(kmax)[:, None]
    # Candidate window starts i-k+1 .. i, clipped to the group.
    cand = i - steps
    hi_start = offsets[group + 1] - k
    ok = steps < k
    np.maximum(cand, lo_g, out=cand)  # np.clip
    np.minimum(cand, hi_start, out=cand)
    left = x - x[cand]
    right = x[np.minimum(cand + k - 1, n - 1)] - x
    reach = np.where(ok, np.maximum(left, right), np.inf)
    return cand[reach.argmin(axis=0), i]


class _Groups:
    """Where the values of the groups go in a (groups, largest group) array (internal).

    ``cell`` (N,) is the flat position of every value, ``lo`` and ``hi`` (G,) are the flat
    positions of each group's middle values once its row is sorted (equal for odd sizes).
    """

    __slots__ = ('shape', 'cell', 'lo', 'hi')

    def __init__(self, offsets: np.ndarray, group: np.ndarray, sizes: np.ndarray) -> None:
        """Lay out the groups ``offsets`` (G + 1,), ``sizes`` (G,); ``group`` of each value."""
        width = max(sizes.tolist())
        self.shape = (sizes.size, width)
        row = np.arange(0, sizes.size * width, width)
        self.cell = np.arange(group.size) + (row - offsets[:-1])[group]
        self.lo = row + (sizes - 1) // 2
        self.hi = row + sizes // 2


def _group_median(values: np.ndarray, groups: _Groups) -> np.ndarray:
    """Return the median of each group of ``values`` (all groups sorted in one call)."""
    rows = np.full(groups.shape, np.nan)  # padding sorts last (after any nan value)
    rows.ravel()[groups.cell] = values
    rows.sort(axis=1)
    flat = rows.ravel()
    return 0.5 * (flat[groups.lo] + flat[groups.hi])


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
    with np.errstate(divide='ignore', invalid='ignore'):
        return _lowess_groups(x, y, offsets, span, iterations)


def _lowess_groups(x: np.ndarray, y: np.ndarray, offsets: np.ndarray, span: int,
                   iterations: int) -> np.ndarray:
    """Return :func:`lowess_groups` (arrays checked, floating-point errors ignored)."""
    n = x.shape[0]
    sizes = offsets[1:] - offsets[:-1]
    k_g = np.minimum(sizes, int(span))
    group = np.arange(sizes.size).repeat(sizes)
    starts = _knn_windows(x, offsets, k_g, group)
    kmin, kmax = min(k_g.tolist()), max(k_g.tolist())
    # The windows are laid out (kmax, N): column i holds the neighbours of x_i, and the
    # reductions over a window run over rows (fast on a few rows; see _window_sums).
    cols = np.arange(kmax)[:, None]
    in_win = cols < k_g[group] if kmin < kmax else None  # None: every window has kmax points
    idx = np.minimum(starts + cols, n - 1)
    u = x[idx] - x  # predictor relative to x_i, so the fit at x_i is the intercept
    if in_win is not None:
        u = np.where(in_win, u, 0.0)
    yw = y[idx]
    dist = np.abs(u)  # 0 outside the window
    d = dist.max(axis=0)  # d(x): distance to the most distant neighbour
    ratio = np.where(d > 0.0, dist / d, 0.0)
    w1 = (1.0 - ratio ** 3) ** 3  # eq. 8, tricube
    if in_win is not None:
        w1 = np.where(in_win, w1, 0.0)
    fit = _weighted_linear(u, yw, w1, y)
    scale = float(np.abs(y).max()) + 1.0
    groups = _Groups(offsets, group, sizes) if iterations else None
    for _ in range(int(iterations)):
        res = y - fit
        mad = _group_median(np.abs(res), groups)  # M of eq. 9
        six_m = 6.0 * np.maximum(mad, 1e-12 * scale)[group]
        q = res / six_m
        w2 = np.where(np.abs(q) < 1.0, (1.0 - q * q) ** 2, 0.0)  # eq. 9, bisquare
        fit = _weighted_linear(u, yw, w1 * w2[idx], fit)  # eq. 10 (product, see module doc)
    return fit


def _weighted_linear(u: np.ndarray, yw: np.ndarray, w: np.ndarray,
                     fallback: np.ndarray) -> np.ndarray:
    """Return the intercepts of column-wise weighted linear fits ``y = a + b u`` (K, N).

    Call under ``np.errstate(divide='ignore', invalid='ignore')``.
    """
    terms = np.empty((w.shape[0], 5, w.shape[1]))  # w, w u, w y, w u u, w u y per row
    terms[:, 0] = w
    wu = np.multiply(w, u, out=terms[:, 1])
    np.multiply(w, yw, out=terms[:, 2])
    np.multiply(wu, u, out=terms[:, 3])
    np.multiply(wu, yw, out=terms[:, 4])
    sw, su, sy, suu, suy = _window_sums(terms)
    sw_suu = sw * suu
    det = sw_suu - su * su
    lin = (sy * suu - su * suy) / det
    mean = sy / sw
    good_lin = det > 1e-12 * np.maximum(sw_suu, 1e-300)
    out = np.where(good_lin, lin, mean)
    return np.where(np.isfinite(out) & (sw > 0.0), out, fallback)


def _window_sums(t: np.ndarray) -> np.ndarray:
    """Return ``t.sum(axis=0)`` of (K, ...) ``t``, added as numpy adds a row of K values.

    numpy sums a contiguous row by pairwise summation (sequentially below 8 values, else
    in 8 partial sums, for rows up to 128 values); repeating its order over the K rows
    gives the sums of the (N, K) layout bit for bit, without a reduction call per row.
    Below 8 rows that order is a reduction over the first axis (row by row, in order).
    """
    k = t.shape[0]
    if k > 128:
        return np.moveaxis(t, 0, -1).copy().sum(axis=-1)
    if k < 8:
        return np.add.reduce(t, axis=0)
    r = t[:8].copy()
    i = 8
    while i < k - k % 8:
        r += t[i:i + 8]
        i += 8
    s = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    for j in range(i, k):
        s += t[j]
    return s


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
