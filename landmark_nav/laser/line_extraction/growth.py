"""Step 4 of the line extractors: lines grow over the free points beside their ends.

A free point joins a line when its distance to it is within ``trim_sigma`` standard
deviations (eq. 7 on the normal) and the split tolerance (:func:`_grow`).
"""

import math
from typing import List, Tuple

from landmark_nav.laser.line_extraction.params import LineParams
from landmark_nav.laser.line_extraction.scan_batch import _PHI, _Scan
from landmark_nav.laser.line_extraction.tls_fit import _Fit, NUM_SUMS
import numpy as np


def _grow(scan: _Scan, feats: np.ndarray, sums: np.ndarray, first: np.ndarray,
          last: np.ndarray, f: _Fit, params: LineParams
          ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Grow the lines f over the free points beside them that fit (step 4).

    Free points are those of no line, also in other (small) clusters. A line takes the
    run of consecutive free points next to its ends whose distance to it is within
    ``trim_sigma`` standard deviations (eq. 7) and within the split tolerance, and whose
    bearing steps stay within ``merge_gap_angle``; a gap claimed from both sides goes
    first to the line before it. Returns the new sums, first, last and whether any grew.
    """
    gate = params.trim_sigma
    if not math.isfinite(gate):
        return sums, first, last, False
    n_pts = scan.x.size
    n_lines = first.size
    if n_lines <= _GROW_PY:  # (an empty gap gives no run)
        first_l, last_l = first.tolist(), last.tolist()
        run_f, run_b = _grow_runs_py(scan, f, first_l, last_l, params)
        if not (any(run_f) or any(run_b)):
            return sums, first, last, False
        return _grown_py(feats, sums, first_l, last_l, run_f, run_b)
    lo = np.empty(n_lines + 1, dtype=np.int64)  # gap k: points lo[k] .. hi[k] - 1, between
    hi = np.empty(n_lines + 1, dtype=np.int64)  # line k - 1 and line k
    lo[0] = 0
    np.add(last, 1, out=lo[1:])
    hi[:-1] = first
    hi[-1] = n_pts
    size = hi - lo
    gaps = (size > 0).nonzero()[0]
    if not gaps.size:
        return sums, first, last, False
    size_g = size[gaps]
    starts = size_g.cumsum() - size_g
    pos = np.arange(starts[-1] + size_g[-1])
    within = pos - starts.repeat(size_g)  # position in the gap
    idx = within + lo[gaps].repeat(size_g)
    # row 0: the line before the gap growing forward, row 1: the line after it, backward
    owner = np.empty((2, gaps.size), dtype=np.int64)
    np.subtract(gaps, 1, out=owner[0])
    owner[1] = gaps
    has = (owner >= 0) & (owner < n_lines)
    clipped = np.minimum(np.maximum(owner, 0), n_lines - 1)
    rho, _, nx, ny = f.params.take(clipped.repeat(size_g, axis=1), axis=1)
    x, y, rng, cp, sp, tol = scan.cols[:_PHI].take(idx, axis=1)
    ox, oy = scan.origin
    d = (x + ox) * nx + (y + oy) * ny - rho
    n_u = nx * cp + ny * sp
    n_v = ny * cp - nx * sp
    var = (params.gate_sigma_r * n_u) ** 2 + (rng * params.sigma_phi * n_v) ** 2
    ok = has.repeat(size_g, axis=1) & (d * d <= gate * gate * var) & (np.abs(d) <= tol)
    # Bearing steps: step[i] is the step from point i - 1 to i (True at both scan ends);
    # row 0 steps onto each point, row 1 off it.
    phi = scan.cols[_PHI]
    step = np.ones(n_pts + 1, dtype=bool)
    np.less_equal(np.abs(phi[1:] - phi[:-1]), params.merge_gap_angle, out=step[1:-1])
    ok &= step[idx + _NEXT]
    # run_f: leading run of row 0 (to the first miss), run_b: trailing run of row 1
    run_f = np.minimum(np.minimum.reduceat(np.where(ok[0], pos.size, within), starts), size_g)
    run_b = np.minimum(size_g - 1 - np.maximum.reduceat(np.where(ok[1], -1, within), starts),
                       size_g - run_f)
    if not (np.count_nonzero(run_f) or np.count_nonzero(run_b)):
        return sums, first, last, False
    grow = np.zeros((2, n_lines + 1), dtype=np.int64)  # by gap: forward, backward
    grow[0, gaps] = run_f
    grow[1, gaps] = run_b
    return _grown(feats, sums, first, last, grow)


# Lines up to which _grow_runs_py is faster than the array operations (measured).
_GROW_PY = 40


def _grow_runs_py(scan: _Scan, f: _Fit, first: List[int], last: List[int],
                  params: LineParams) -> Tuple[List[int], List[int]]:
    """Return the runs of free points each gap gives to its lines (see :func:`_grow`).

    Per gap (before line 0, between consecutive lines, after the last line) the number of
    points the line before it takes forward and the line after it takes backward, found by
    walking from the gap's ends to the first point that fails (the same tests, the same
    operations as the array version of :func:`_grow`, on Python floats).
    """
    xs, ys, rng, cps, sps, tols, phi = scan.rows()
    rhos, _, nxs, nys = f.params.tolist()
    ox, oy = scan.origin
    gg = params.trim_sigma * params.trim_sigma
    sr, sp_ = params.gate_sigma_r, params.sigma_phi
    angle = params.merge_gap_angle
    n_pts, n_lines = len(xs), len(first)

    def fits(i: int, j: int) -> bool:
        """Return whether point i is within the gates of line j (eq. 7 on the normal)."""
        nx, ny = nxs[j], nys[j]
        d = (xs[i] + ox) * nx + (ys[i] + oy) * ny - rhos[j]
        cp, sp = cps[i], sps[i]
        a = sr * (nx * cp + ny * sp)
        b = rng[i] * sp_ * (ny * cp - nx * sp)
        return d * d <= gg * (a * a + b * b) and abs(d) <= tols[i]

    run_f, run_b = [0] * (n_lines + 1), [0] * (n_lines + 1)
    for k in range(n_lines + 1):
        lo = last[k - 1] + 1 if k else 0
        hi = first[k] if k < n_lines else n_pts
        i = lo
        if k:  # the line before the gap, forward
            while i < hi and (i == 0 or abs(phi[i] - phi[i - 1]) <= angle) and fits(i, k - 1):
                i += 1
        run_f[k] = i - lo
        if k < n_lines:  # the line after it, backward (after the forward run)
            m = hi - 1
            while m >= i and (m + 1 == n_pts or abs(phi[m + 1] - phi[m]) <= angle) and fits(m, k):
                m -= 1
            run_b[k] = hi - 1 - m
    return run_f, run_b


def _grown(feats: np.ndarray, sums: np.ndarray, first: np.ndarray, last: np.ndarray,
           grow: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Return :func:`_grow`'s sums, first, last, True for the runs ``grow`` (2, gaps)."""
    n_lines = first.size
    new_first, new_last = first - grow[1, :-1], last + grow[0, 1:]
    # Sums of the added ranges (disjoint, in order): [new_first, first) and (last, new_last].
    add_lo = np.empty(2 * n_lines, dtype=np.int64)
    add_hi = np.empty(2 * n_lines, dtype=np.int64)  # exclusive
    add_lo[0::2] = new_first
    np.add(last, 1, out=add_lo[1::2])
    add_hi[0::2] = first
    np.add(new_last, 1, out=add_hi[1::2])
    nonempty = add_hi > add_lo
    bounds = np.empty(2 * int(nonempty.sum()), dtype=np.int64)
    bounds[0::2] = add_lo[nonempty]
    bounds[1::2] = add_hi[nonempty]
    added = np.zeros((NUM_SUMS, 2 * n_lines))
    added[:, nonempty] = np.add.reduceat(feats, bounds, axis=1)[:, 0::2]
    return sums + added[:, 0::2] + added[:, 1::2], new_first, new_last, True


def _grown_py(feats: np.ndarray, sums: np.ndarray, first: List[int], last: List[int],
              run_f: List[int], run_b: List[int]
              ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Return :func:`_grown` for the runs of :func:`_grow_runs_py`, laid out in Python.

    The same sums (one ``reduceat`` over the same non-empty ranges, in the same order,
    added to the lines' sums as there); only the index bookkeeping runs on lists.
    """
    n_lines = len(first)
    new_first = [a - run_b[j] for j, a in enumerate(first)]
    new_last = [b + run_f[j + 1] for j, b in enumerate(last)]
    bounds: List[int] = []  # the added ranges [lo, hi), in order: before line j, after it
    cols: List[int] = []
    for j in range(n_lines):
        if new_first[j] < first[j]:
            bounds += (new_first[j], first[j])
            cols.append(2 * j)
        if new_last[j] > last[j]:
            bounds += (last[j] + 1, new_last[j] + 1)
            cols.append(2 * j + 1)
    added = np.zeros((NUM_SUMS, 2 * n_lines))
    added[:, cols] = np.add.reduceat(feats, bounds, axis=1)[:, 0::2]
    return (sums + added[:, 0::2] + added[:, 1::2], np.array(new_first, dtype=np.int64),
            np.array(new_last, dtype=np.int64), True)


_NEXT = np.array([[0], [1]])
