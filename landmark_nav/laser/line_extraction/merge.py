"""Step 3 of the line extractors: merge of collinear neighbouring pieces.

The collinearity test ``d^2 = dp^T (C1 + C2)^-1 dp`` on (rho, alpha) (:func:`_chi2`),
with covariances scaled by the a-posteriori variance factor where the residuals reject
the stated noise (:func:`_variance_factor`), and the merge of chains of passing pairs
(:func:`_merge`).
"""

import math
from typing import List, Optional, Tuple

from landmark_nav.laser.line_extraction.params import LineParams
from landmark_nav.laser.line_extraction.scan_batch import _PHI, _Scan, _TOL, _X, _Y
from landmark_nav.laser.line_extraction.tls_fit import (_Fit, _MATH_TRIG, _solve, _wrap,
                                                        TWO_PI)
import numpy as np


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
