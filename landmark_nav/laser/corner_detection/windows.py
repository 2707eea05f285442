"""The window detectors: ``sliding_window`` (section 2.1.1) and ``minus_cosine`` (2.1.3).

The angle test of eq. 1 with inward checks (:func:`_sliding_window`); ``f = -cos`` of
eq. 11 with the midpoint-shift check of Figs. 11-12 and optionally its uncertainty from
eq. 7 (:func:`_minus_cosine`, :func:`_minus_cos`, :func:`_window_f_sd`); non-maximum
suppression over runs of firing windows.
"""

import math
from typing import List, Tuple

from landmark_nav.laser.corner_detection.corner import _free_side, _make, _unit, Corner
from landmark_nav.laser.corner_detection.params import CornerParams
from landmark_nav.laser.corner_detection.refine import _refine
from landmark_nav.laser.corner_detection.scan_stack import _Stack
from landmark_nav.laser.corner_detection.tls_lines import point_covariance
import numpy as np


def _minus_cos(xl: np.ndarray, yl: np.ndarray, xm: np.ndarray, ym: np.ndarray,
               xh: np.ndarray, yh: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``f`` of eq. 11 for triangles (lo, mid, hi), ``a^2`` and ``b^2``.

    ``f`` is nan when an arm has zero length.
    """
    ax, ay = xl - xm, yl - ym
    bx, by = xh - xm, yh - ym
    cx, cy = xh - xl, yh - yl
    a2 = ax * ax + ay * ay
    b2 = bx * bx + by * by
    c2 = cx * cx + cy * cy
    return (c2 - (a2 + b2)) / (2.0 * np.sqrt(a2 * b2)), a2, b2  # eq. 11


def _runs_best(pos: np.ndarray, score: np.ndarray, gap: np.ndarray,
               start: np.ndarray) -> np.ndarray:
    """Return the positions (into ``pos``) of the smallest score of each run.

    ``pos`` are sorted sample indices of firing windows. A run breaks where the next firing
    window is more than ``gap`` samples further on or in another cluster (``start`` differs).
    """
    if pos.size < 2:
        return np.arange(pos.size)
    new = np.empty(pos.size, dtype=bool)
    new[0] = True
    new[1:] = (pos[1:] - pos[:-1] > gap[:-1]) | (start[1:] != start[:-1])
    run = new.cumsum()
    order = np.lexsort((score, run))
    first = np.empty(order.size, dtype=bool)
    first[0] = True
    ro = run[order]
    first[1:] = ro[1:] != ro[:-1]
    return np.sort(order[first])


def _local_minima(pos: np.ndarray, score: np.ndarray, size: int) -> np.ndarray:
    """Return the positions (into ``pos``) of the local minima of ``score``.

    ``pos`` are sorted sample indices (of ``size`` samples) of firing windows; a window is
    a local minimum when neither firing window next to it has a smaller score (equal ones
    are all kept; the refinement merges what coincides). Windows of different clusters
    are at least ``2 * (window // 2)`` samples apart, so they never compare.
    """
    dense = np.full(size, np.inf)
    dense[pos] = score
    return np.flatnonzero((dense[np.maximum(pos - 1, 0)] >= score)
                          & (dense[np.minimum(pos + 1, size - 1)] >= score))


def _window_f_sd(st: _Stack, lo: np.ndarray, mid: np.ndarray, hi: np.ndarray,
                 p: CornerParams) -> np.ndarray:
    """Return the first-order standard deviation of ``f`` (eq. 11) of windows (lo, mid, hi).

    ``theta = atan2(u x v, u . v)`` with ``u``, ``v`` from the midpoint to the terminal
    points; its gradient is ``-perp(u) / |u|^2`` for the first terminal point,
    ``perp(v) / |v|^2`` for the second and minus their sum for the midpoint, each point
    with its noise ``Q_i`` of eq. 7; ``df = sin(theta) d theta``.
    """
    ux, uy = st.x[lo] - st.x[mid], st.y[lo] - st.y[mid]
    vx, vy = st.x[hi] - st.x[mid], st.y[hi] - st.y[mid]
    u2, v2 = ux * ux + uy * uy, vx * vx + vy * vy
    ga = np.stack([uy / u2, -ux / u2], axis=-1)  # -perp(u) / |u|^2, perp(u) = (-uy, ux)
    gb = np.stack([-vy / v2, vx / v2], axis=-1)
    var = np.zeros(mid.size)
    for i, gr in ((lo, ga), (hi, gb), (mid, -(ga + gb))):
        q = point_covariance(st.r[i], st.phi[i], p.sigma_r, p.sigma_phi)
        var += np.einsum('ki,kij,kj->k', gr, q, gr)
    cos_t = (ux * vx + uy * vy) / np.sqrt(u2 * v2)
    return np.sqrt(np.fmax(1.0 - cos_t * cos_t, 0.0) * var)


def _sliding_window(st: _Stack, p: CornerParams) -> List[Corner]:
    """Sliding-window detector (section 2.1.1) with run-based non-maximum suppression."""
    h = p.window // 2
    m = np.arange(st.x.size)
    mid = np.flatnonzero((m - h >= st.start) & (m + h < st.end))
    if mid.size == 0:
        return []
    cos_max = math.cos(math.radians(p.max_angle_deg))
    cmin2 = p.min_opposite_distance ** 2
    xm, ym = st.x[mid], st.y[mid]
    fire = np.ones(mid.size, dtype=bool)
    cos0 = None
    # Outermost pair (1st / W-th) then the inward checks (2nd / (W-1)-th, ...).
    for d in [h] + list(range(h - 1, max(2, h - 3) - 1, -1)):
        ax, ay = st.x[mid - d] - xm, st.y[mid - d] - ym
        bx, by = st.x[mid + d] - xm, st.y[mid + d] - ym
        nn = np.sqrt((ax * ax + ay * ay) * (bx * bx + by * by))
        cos_t = (ax * bx + ay * by) / nn  # eq. 1, compared as cos
        cx, cy = bx - ax, by - ay
        fire &= (cos_t >= cos_max) & (cx * cx + cy * cy >= cmin2)
        if cos0 is None:
            cos0 = cos_t
    idx = np.flatnonzero(fire)
    if idx.size == 0:
        return []
    g = mid[idx]
    # NMS: one detection per run of firing windows, the sharpest (largest cos theta).
    g = g[_runs_best(g, -cos0[idx], np.full(g.size, h), st.start[g])]
    return _raw_corners(st, g, g - h, g + h, np.full(g.size, math.nan), p)


def _raw_corners(st: _Stack, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, f: np.ndarray,
                 p: CornerParams) -> List[Corner]:
    """Return corners at samples ``g`` with arms toward ``lo`` / ``hi``, covariance ``Q_i``."""
    cx, cy = st.x[g], st.y[g]
    u1x, u1y = _unit(st.x[lo] - cx, st.y[lo] - cy)
    u2x, u2y = _unit(st.x[hi] - cx, st.y[hi] - cy)
    bis, opening, _ = _free_side(cx, cy, u1x, u1y, u2x, u2y)
    cov = point_covariance(st.r[g], st.phi[g], p.sigma_r, p.sigma_phi)
    arms = np.empty((g.size, 2, 2, 2))  # from the corner sample to the terminal samples
    arms[:, :, 0, 0], arms[:, :, 0, 1] = cx[:, None], cy[:, None]
    arms[:, 0, 1, 0], arms[:, 0, 1, 1], arms[:, 1, 1, 0], arms[:, 1, 1, 1] = (
        st.x[lo], st.y[lo], st.x[hi], st.y[hi])
    return _make(cx, cy, bis, opening, cov, st.beam[g], f, arms, st.dphi[g])


def _minus_cosine(st: _Stack, p: CornerParams) -> List[Corner]:
    """Minus-cosine detector (section 2.1.3, Fig. 14) with midpoint-shift ghost check."""
    h0 = p.window // 2
    m = np.arange(st.x.size)
    spacing = np.fmax(st.r * st.dphi, 1e-9)  # fmax: a nan range gives the widest window
    h = np.minimum(np.maximum(np.ceil(p.arm_length / spacing), h0), p.max_half_window)
    h = h.astype(np.int64)
    lo = np.maximum(m - h, st.start)  # widened arms are clipped at the cluster ends,
    hi = np.minimum(m + h, st.end - 1)  # the chapter's W // 2 samples are required
    mid = np.flatnonzero((m - lo >= h0) & (hi - m >= h0))
    if mid.size == 0:
        return []
    lo, hi = lo[mid], hi[mid]
    x, y = st.x, st.y
    xl, yl, xm, ym, xh, yh = x[lo], y[lo], x[mid], y[mid], x[hi], y[hi]
    f, a2, b2 = _minus_cos(xl, yl, xm, ym, xh, yh)  # eq. 11
    widen = 0.0
    if p.gate_sigmas > 0.0:  # confidence test of eq. 11 with the points' noise (eq. 7)
        widen = p.gate_sigmas * _window_f_sd(st, lo, mid, hi, p)
    # Arms clipped by a cluster end or by max_half_window must still span half the length.
    cand = np.flatnonzero((f >= p.f_min - widen) & (f <= p.f_max + widen)
                          & (np.minimum(a2, b2) >= 0.25 * p.arm_length * p.arm_length))
    if cand.size == 0:
        return []
    mid, lo, hi, f = mid[cand], lo[cand], hi[cand], f[cand]
    if p.gate_sigmas > 0.0:
        widen = widen[cand]
    if p.midpoint_shift:
        xl, yl, xm, ym, xh, yh = xl[cand], yl[cand], xm[cand], ym[cand], xh[cand], yh[cand]
        a, b = np.sqrt(a2[cand]), np.sqrt(b2[cand])
        # A true vertex moved by ds along one arm changes f by at most ds / min(a, b); ds is
        # the shift times the mean sample step of the arms (not the shifted point's actual
        # displacement, which for an outlier midpoint is the outlier's offset).
        step = np.maximum(a / (mid - lo), b / (hi - mid))
        tol = p.midpoint_shift * step / np.minimum(a, b) + widen
        good = np.ones(mid.size, dtype=bool)
        for s in (p.midpoint_shift, -p.midpoint_shift):  # Figs. 11-12: shifted midpoint
            fs = _minus_cos(xl, yl, x[mid + s], y[mid + s], xh, yh)[0]
            good &= (fs >= p.f_min - tol) & (fs <= p.f_max + tol)
        sel = np.flatnonzero(good)
        if sel.size == 0:
            return []
        mid, lo, hi, f = mid[sel], lo[sel], hi[sel], f[sel]
        if p.gate_sigmas > 0.0:
            widen = widen[sel]
    if p.refine:
        # Every local minimum of f is refined (two corners in one run: a door frame, a
        # pilaster); the refinement decides, and merges refined corners that coincide.
        sel = _local_minima(mid, f, st.x.size)
        return _refine(st, mid[sel], lo[sel], hi[sel], f[sel], p)
    # NMS: one detection per run of candidate windows, the sharpest (smallest f).
    sel = _runs_best(mid, f, h[mid], st.start[mid])
    return _raw_corners(st, mid[sel], lo[sel], hi[sel], f[sel], p)
