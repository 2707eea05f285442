"""The ``split_merge`` corner detector (corner chapter section 2.1.2).

Recursive split at the largest distance to the chord (eq. 4), merge of pieces that still
fit one line (eqs. 5-10), corners where the lines of adjacent pieces meet.
"""

import math
from typing import List, Sequence, Tuple

from landmark_nav.laser.corner_detection.corner import _free_side, _make, Corner
from landmark_nav.laser.corner_detection.params import CornerParams
from landmark_nav.laser.corner_detection.refine import _arm_support
from landmark_nav.laser.corner_detection.scan_stack import _gather_arms, _Stack
from landmark_nav.laser.corner_detection.tls_lines import (_arm_directions,
                                                           _corner_covariance, _intersect,
                                                           _lines, _weighted_moments)
from landmark_nav.laser.segmentation import Cluster
import numpy as np


def _split_indices(x: np.ndarray, y: np.ndarray, tol: float) -> List[int]:
    """Break indices (incl. both ends) of recursive splitting at the largest eq. 4 distance."""
    breaks = [0, x.size - 1]
    todo = [(0, x.size - 1)]
    xs, ys = x.tolist(), y.tolist()  # Python floats for the ends: no numpy scalars
    while todo:
        i, j = todo.pop()
        if j - i < 2:
            continue
        xi, yi, xf, yf = xs[i], ys[i], xs[j], ys[j]
        a, b = yf - yi, xf - xi  # A x + B y + C = 0 through both ends
        norm = math.hypot(a, b)
        if norm == 0.0:
            continue
        d = np.abs(a * (x[i + 1:j] - xi) - b * (y[i + 1:j] - yi))  # eq. 4 (times norm)
        k = int(d.argmax())
        if d[k] > tol * norm:
            s = i + 1 + k
            breaks.append(s)
            todo.extend(((i, s), (s, j)))
    return sorted(breaks)


def _fits_one_line(x: np.ndarray, y: np.ndarray, tol: float) -> bool:
    """Return True if the TLS line (eqs. 8-10) of the points is within ``tol`` of all."""
    ln = _lines(_weighted_moments(np.ones(x.size), x, y))
    return bool(np.abs(x * ln.c + y * ln.s - ln.rho).max() <= tol)  # the terms of eq. 6


def _split_merge(clusters: Sequence[Cluster], st: _Stack, p: CornerParams) -> List[Corner]:
    """Split-and-merge detector (section 2.1.2): corners where adjacent TLS lines meet."""
    tol = p.split_tolerance
    gap = p.corner_gap
    pieces: List[Tuple[int, int, int, int, int]] = []  # arm 0, arm 1 (first, last), joint
    base = 0
    for c in clusters:
        npts = len(c.indices)
        if npts == 0:
            continue
        b0 = base
        base += npts
        if npts < 2 * p.min_arm_points + 1:
            continue
        x, y = st.x[b0:base], st.y[b0:base]
        br = _split_indices(x, y, tol)
        merged = [br[0]]  # merge: drop a break if its two pieces still fit one line
        for j in range(1, len(br) - 1):
            i, k = merged[-1], br[j + 1] + 1
            if not _fits_one_line(x[i:k], y[i:k], tol):
                merged.append(br[j])
        merged.append(br[-1])
        for j in range(1, len(merged) - 1):
            lo = b0 + merged[j - 1] + (gap + 1 if j > 1 else 0)
            hi = b0 + merged[j + 1] - (gap + 1 if j + 1 < len(merged) - 1 else 0)
            jt = b0 + merged[j]
            pieces.append((lo, jt - gap - 1, jt + gap + 1, hi, jt))
    if not pieces:
        return []
    pc = np.array(pieces)
    jt = pc[:, 4]
    first = pc[:, 1:3]  # arm samples nearest the joint
    count = np.maximum(np.stack([pc[:, 1] - pc[:, 0], pc[:, 3] - pc[:, 2]], axis=1) + 1, 0)
    idx, valid = _gather_arms(st, first, count, jt)
    x, y = st.x[idx], st.y[idx]
    w = valid.astype(float)
    lines = _lines(_weighted_moments(w, x, y))  # eqs. 8-10
    cx, cy = _intersect(lines)
    ux, uy = _arm_directions(lines, cx, cy)
    bis, opening, cos_t = _free_side(cx, cy, ux[:, 0], uy[:, 0], ux[:, 1], uy[:, 1])
    last = st.x.size - 1
    far = np.minimum(np.maximum(pc[:, [0, 3]], 0), last)  # np.clip, cheaper
    near = np.minimum(np.maximum(first, 0), last)
    length = np.hypot(st.x[far] - st.x[near], st.y[far] - st.y[near])
    spacing = st.r[jt] * st.dphi[jt]
    off = np.hypot(cx - st.x[jt], cy - st.y[jt])
    arms, real = _arm_support(x, y, np.hypot(x, y), valid, w, lines, p)
    good = ((count.min(axis=1) >= p.min_arm_points) & (length.min(axis=1) >= p.arm_length)
            & real & (-cos_t >= p.f_min) & (-cos_t <= p.f_max)
            & (off <= np.maximum(2.0 * tol, 3.0 * spacing)))  # nan fails every comparison
    sel = np.flatnonzero(good)
    if sel.size == 0:
        return []
    cov = _corner_covariance(x[sel], y[sel], w[sel], lines.take(sel), cx[sel], cy[sel],
                             p.sigma_r, p.sigma_phi)
    return _make(cx[sel], cy[sel], bis[sel], opening[sel], cov, st.beam[jt[sel]],
                 np.full(sel.size, math.nan), arms[sel], st.dphi[jt[sel]])
