"""Refinement of window detections by two TLS lines, and the checks of a corner's arms.

The vertex is re-located at the best two-line split of the window, the arms are extended
and refitted (eqs. 8-10) and intersected (:func:`_refine`); both arms must be real
surfaces and no beam may be seen through them (:func:`_arm_support`, :func:`_behind`,
also used by split and merge).
"""

from typing import List, Tuple

from landmark_nav.laser.corner_detection.corner import _free_side, _make, Corner
from landmark_nav.laser.corner_detection.params import CornerParams
from landmark_nav.laser.corner_detection.scan_stack import _gather_arms, _Stack
from landmark_nav.laser.corner_detection.tls_lines import (_arm_directions,
                                                           _corner_covariance, _intersect,
                                                           _line_angle_variance, _Lines,
                                                           _lines, _smallest_scatter,
                                                           _weighted_moments)
import numpy as np


def _two_line_split(st: _Stack, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, gap: int,
                    min_pts: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the vertex sample of each window ``[lo, hi]``, its arm moment sums, success.

    For every split sample ``s`` of the window (each side keeping ``min_pts`` samples after
    ``gap`` samples next to ``s`` are left out) the TLS residuals of ``[lo, s - gap - 1]``
    and ``[s + gap + 1, hi]`` (smallest scatter eigenvalues, from moment prefix sums over
    the window) are added; the smallest sum wins. The sharpest window ``g`` is only a sample
    or two off on clean data but can be far off with noise when the arms differ in length;
    the best two-line split puts the vertex where the data bend.
    """
    width = int((hi - lo).max()) + 1
    j = np.arange(width)
    win = np.minimum(lo[:, None] + j, hi[:, None])  # (K, W) window samples, padded
    x, y = st.x[win], st.y[win]
    cm = np.zeros((6, g.size, width + 1))  # prefix sums of the moments over each window
    cm[0, :, 1:] = 1.0
    cm[1, :, 1:], cm[2, :, 1:] = x, y
    cm[3, :, 1:], cm[4, :, 1:], cm[5, :, 1:] = x * x, y * y, x * y
    np.cumsum(cm, axis=2, out=cm)
    nwin = (hi - lo + 1)[:, None]
    a_end = np.maximum(j - gap, 0)  # arm 0 = window samples [0, j - gap)
    b_beg = np.minimum(j + gap + 1, nwin)  # arm 1 = [j + gap + 1, nwin)
    ok = (a_end >= min_pts) & (nwin - b_beg >= min_pts)
    rows = np.arange(g.size)[:, None]
    both = np.empty((6, 2, g.size, width))
    both[:, 0] = cm[:, :, a_end]
    both[:, 1] = cm[:, rows, nwin] - cm[:, rows, b_beg]
    cost = _smallest_scatter(both)
    cost = np.where(ok, cost[0] + cost[1], np.inf)
    best = np.argmin(cost, axis=1)
    r1 = rows[:, 0]
    found = ok[r1, best]
    sums = both[:, :, r1, best].transpose(0, 2, 1)  # (6, K, 2)
    gain = _smallest_scatter(cm[:, r1, nwin[:, 0]]) - cost[r1, best]  # one line vs two
    return np.where(found, lo + best, g), sums, gain


def _fit_arms(st: _Stack, g: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              p: CornerParams) -> tuple:
    """Split each window ``[lo, hi]`` around ``g`` in two TLS lines and refit the arms.

    Returns ``(g, found, lines, cx, cy, x, y, r, valid, w)``: the split sample, whether the
    split is a significant bend, the refitted lines, their intersection, the arm samples
    (K, 2, M) with ranges, validity and the weights of the final fit. The checks on them
    are :func:`_refine`'s.
    """
    gap = p.corner_gap
    g, sums, gain = _two_line_split(st, g, lo, hi, gap, 2)
    sig = np.sqrt(p.sigma_r ** 2 + (p.sigma_phi * st.r[g]) ** 2)
    found = gain >= p.min_significance * sig * sig  # a bend, not a noisy straight line
    lines = _lines(sums)  # first fit: both arms inside the detection window
    cx, cy = _intersect(lines)
    # Extend the arms to fit_length and keep the samples that stay on the first line.
    spacing = np.maximum(st.r[g] * st.dphi[g], 1e-9)
    n_fit = np.minimum(np.ceil(p.fit_length / spacing), 4 * p.max_half_window)
    count = np.empty((g.size, 2), dtype=np.int64)
    count[:, 0] = np.maximum(n_fit, g - gap - lo)  # at least the window part of each arm
    count[:, 1] = np.maximum(n_fit, hi - g - gap)
    first = np.empty((g.size, 2), dtype=np.int64)
    first[:, 0], first[:, 1] = g - gap - 1, g + gap + 1
    idx, valid = _gather_arms(st, first, count, g)
    x, y = st.x[idx], st.y[idx]
    sig = sig[:, None, None]
    near = np.maximum(sig, 0.5 * spacing[:, None, None])
    far_tol = 4.0 * sig + 0.01
    stop = np.zeros(x.shape, dtype=bool)
    size = x.shape[-1]
    r = np.hypot(x, y)
    for _ in range(2):
        c, s, rho = lines.c[..., None], lines.s[..., None], lines.rho[..., None]
        d = x * c + y * s - rho
        d_own = np.abs(d)
        d_other = np.abs(x * c[:, ::-1] + y * s[:, ::-1] - rho[:, ::-1])
        far = d_own > far_tol
        # The arm ends at two consecutive misses and before an opening seen through it
        # (no false surface): a sample off the line (far) and beyond it along its ray by
        # more than its noise allows (tested on the few far samples only).
        np.logical_and(far[..., :-1], far[..., 1:], out=stop[..., :-1])
        stop[..., -1] = False
        off = np.flatnonzero(far & valid)
        if off.size:
            stop.ravel()[off] |= _opening(d.ravel()[off], r.ravel()[off],
                                          lines.rho.ravel()[off // size], p)
        cut = np.logical_or.accumulate(stop, axis=-1)
        ux, uy = _arm_directions(lines, cx, cy)
        along = (x - cx[:, None, None]) * ux[..., None] + (y - cy[:, None, None]) * uy[..., None]
        keep = valid & (d_own <= d_other) & (along > near)
        keep &= ~(cut | far)
        w = keep.astype(float)
        lines = _lines(_weighted_moments(w, x, y))  # eqs. 8-10 on the kept arm samples
        cx, cy = _intersect(lines)
    return g, found, lines, cx, cy, x, y, r, valid, w


def _refine(st: _Stack, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, fg: np.ndarray,
            p: CornerParams) -> List[Corner]:
    """Refine detections (window ``[lo, hi]`` around ``g``) by intersecting two TLS lines."""
    g, found, lines, cx, cy, x, y, r, valid, w = _fit_arms(st, g, lo, hi, p)
    ux, uy = _arm_directions(lines, cx, cy)
    bis, opening, cos_t = _free_side(cx, cy, ux[:, 0], uy[:, 0], ux[:, 1], uy[:, 1])
    f_fit = -cos_t  # eq. 11 for the fitted arms
    fit_widen = 0.0
    if p.fit_sigmas > 0.0:  # theta = alpha_0 - alpha_1 (+ const), df = sin(theta) d theta
        var_a = _line_angle_variance(x, y, w, lines, p.sigma_r, p.sigma_phi)
        fit_widen = p.fit_sigmas * np.sqrt((1.0 - cos_t * cos_t) * var_a.sum(axis=1))
    px, py = st.x[g], st.y[g]
    reach2 = np.minimum((st.x[lo] - px) ** 2 + (st.y[lo] - py) ** 2,
                        (st.x[hi] - px) ** 2 + (st.y[hi] - py) ** 2)
    shift2 = (cx - px) ** 2 + (cy - py) ** 2
    arms, real = _arm_support(x, y, r, valid, w, lines, p)
    good = (found & real & (f_fit >= p.f_min - fit_widen)
            & (f_fit <= p.f_max + fit_widen) & (shift2 <= reach2))  # nan fails every comparison
    sel = np.flatnonzero(good)
    if sel.size == 0:
        return []
    if sel.size > 1:
        sel = sel[_dedup(cx[sel], cy[sel], fg[sel], max(3.0 * p.sigma_r, 0.05))]
    if sel.size < g.size:
        x, y, w, lines, arms = x[sel], y[sel], w[sel], lines.take(sel), arms[sel]
        cx, cy, g, bis, opening, fg = cx[sel], cy[sel], g[sel], bis[sel], opening[sel], fg[sel]
    cov = _corner_covariance(x, y, w, lines, cx, cy, p.sigma_r, p.sigma_phi)
    return _make(cx, cy, bis, opening, cov, st.beam[g], fg, arms, st.dphi[g])


def _past_line(d: np.ndarray, r: np.ndarray, rho: np.ndarray, p: CornerParams
               ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``d + rho``, how far beyond its line each sample lies, and whether too far.

    ``d`` are the samples' signed distances to their line ``x cos a + y sin a = rho``, ``r``
    their ranges. The ray meets the line at range ``t = rho r / (d + rho)`` (``d + rho`` is
    ``r cos(incidence)``); a sample lies ``r - t = r d / (d + rho)`` beyond it, too far
    when ``t > 0`` and that exceeds ``see_through_tolerance``.
    """
    proj = d + rho
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        t = rho * r / proj
        beyond = r * d / proj
        return proj, beyond, (t > 0.0) & (beyond > p.see_through_tolerance)


def _behind(d: np.ndarray, r: np.ndarray, valid: np.ndarray, rho: np.ndarray,
            p: CornerParams) -> np.ndarray:
    """Return the valid samples (K, 2, M) seen through their arm's line (:func:`_past_line`).

    ``rho`` (K, 2, 1) are the arms' lines.
    """
    return valid & _past_line(d, r, rho, p)[2]


def _opening(d: np.ndarray, r: np.ndarray, rho: np.ndarray, p: CornerParams) -> np.ndarray:
    """Return which valid samples (any shape, with their line's ``rho``) are openings.

    An opening is seen through the line (:func:`_past_line`) by more than
    ``see_through_tolerance`` plus 3 standard deviations of its distance along the ray
    (eq. 7: ``sigma_r^2 + (r sigma_phi tan(incidence))^2``), else it is the surface's own
    noise (at grazing incidence, or a rare large error).
    """
    proj, beyond, seen = _past_line(d, r, rho, p)
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        c2 = (proj / r) ** 2
        var = p.sigma_r ** 2 + (r * p.sigma_phi) ** 2 * (1.0 - c2) / c2
        return seen & (beyond > p.see_through_tolerance + 3.0 * np.sqrt(var))


def _arm_support(x: np.ndarray, y: np.ndarray, r: np.ndarray, valid: np.ndarray,
                 w: np.ndarray, ln: _Lines, p: CornerParams) -> Tuple[np.ndarray, np.ndarray]:
    """Return the arms' extents (K, 2, 2, 2) and whether both arms are real surfaces (K,).

    Samples run from the vertex outward; the arm fits use the samples ``w`` (cut before
    any opening off the line, see :func:`_behind`). Both arms are real surfaces when each
    fit uses at least ``min_arm_points`` samples, reaches ``arm_length`` from the corner
    (half of it when the arm ends at its cluster's end: an occlusion or a jump, as the
    window's own arms), fits them with an RMS distance of at most ``arm_tolerance``, and
    uses at least ``min_arm_inliers`` of the samples between its innermost and outermost
    used one (an arm of scattered points, e.g. furniture clutter, loses its outliers and
    fails). An arm's extent is its run of used samples with the most samples and no sample
    seen through the line (its own noise at grazing incidence) between them, from the
    innermost to the outermost, each end where that sample's ray meets the line.
    """
    size = x.shape[-1]
    used = w > 0.0
    n = used.sum(axis=-1)
    pick = np.empty(x.shape[:-1] + (3,), dtype=np.int64)  # inner, outer, last used sample
    first = used.argmax(axis=-1)
    last = size - 1 - used[..., ::-1].argmax(axis=-1)
    c, s, rho = ln.c[..., None], ln.s[..., None], ln.rho[..., None]
    d = x * c + y * s - rho
    seen = _behind(d, r, valid, rho, p)
    if seen.any():
        run = np.cumsum(seen, axis=-1)  # samples seen through the line separate the runs
        good = used & ~seen
        # run sizes by (corner, arm, run number); the run of most samples wins
        arm = np.arange(good.size // size).reshape(good.shape[:-1])[..., None]  # (K, 2, 1)
        key = arm * (size + 1) + run
        counts = np.bincount(key[good], minlength=arm.size * (size + 1))
        best = counts.reshape(good.shape[:-1] + (size + 1,)).argmax(axis=-1)
        in_run = good & (run == best[..., None])
        pick[..., 0] = in_run.argmax(axis=-1)
        pick[..., 1] = size - 1 - in_run[..., ::-1].argmax(axis=-1)
    else:
        pick[..., 0], pick[..., 1] = first, last
    pick[..., 2] = last
    flat = pick + size * np.arange(pick.size // 3).reshape(pick.shape[:-1] + (1,))
    xi, yi = x.ravel()[flat], y.ravel()[flat]
    ends = np.empty(pick.shape + (2,))  # (K, arm, inner / outer / last used, xy)
    with np.errstate(divide='ignore', invalid='ignore'):
        t = rho / (xi * c + yi * s)  # the ray through the sample meets the line
    np.multiply(t, xi, out=ends[..., 0])
    np.multiply(t, yi, out=ends[..., 1])
    cx, cy = _intersect(ln)
    reach = np.hypot(ends[..., 2, 0] - cx[:, None], ends[..., 2, 1] - cy[:, None])
    real = n >= p.min_arm_points
    if p.real_arms:
        with np.errstate(divide='ignore', invalid='ignore'):
            rmse = np.sqrt(np.where(used, d * d, 0.0).sum(axis=-1) / n)
            inliers = n / (last - first + 1)
        # An arm that ends inside its cluster (its samples leave the line: clutter, another
        # surface) must reach arm_length; one cut by the cluster's end (an occlusion, a
        # jump) half of it, as the window's own arms.
        ends_inside = (valid & (np.arange(size) > last[..., None])).any(axis=-1)
        need = np.where(ends_inside, p.arm_length, 0.5 * p.arm_length)
        real &= (reach >= need) & (rmse <= p.arm_tolerance) & (inliers >= p.min_arm_inliers)
    return ends[..., :2, :], real.all(axis=-1)


def _dedup(x: np.ndarray, y: np.ndarray, score: np.ndarray, radius: float) -> np.ndarray:
    """Return the indices kept by greedy suppression of points near a better-scoring one."""
    dx = x[:, None] - x
    dy = y[:, None] - y
    d2 = dx * dx + dy * dy
    np.fill_diagonal(d2, np.inf)
    r2 = radius * radius
    if not d2.min() < r2:
        return np.arange(x.size)
    kept: List[int] = []
    rows = d2.tolist()  # Python floats: the same comparisons without numpy scalars
    for i in np.argsort(score, kind='stable').tolist():
        row = rows[i]
        if all(row[j] >= r2 for j in kept):
            kept.append(i)
    return np.sort(np.array(kept, dtype=np.int64))
