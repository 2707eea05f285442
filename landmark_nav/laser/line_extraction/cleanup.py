"""Steps 1-2 of the line extractors: break refinement and endpoint clean-up.

Breaks between adjacent pieces move to where both TLS fits are best
(:func:`_refine_breaks`); outlying end points (distance to the line over its standard
deviation from eq. 7, :func:`_z`) leave their piece and short pieces are dropped
(:func:`_clean_pieces`).
"""

import math
from typing import Tuple

from landmark_nav.laser.line_extraction.params import LineParams
from landmark_nav.laser.line_extraction.scan_batch import _Scan, _TOL
from landmark_nav.laser.line_extraction.tls_fit import _MATH_TRIG, _normal, _scatter, _sse
import numpy as np


def _refine_breaks(scan: _Scan, pre: np.ndarray, s: np.ndarray, e: np.ndarray, reach: int
                   ) -> Tuple[np.ndarray, np.ndarray]:
    """Move every break between adjacent pieces to where both fits are best (step 1).

    Pieces ``[lo, b]`` and ``[b + o, hi]`` (o = 0 for a shared split point, 1 for
    abutting pieces) of one cluster get the break ``b'`` within ``reach`` of ``b`` that
    minimises ``SSE(lo..b') + SSE(b' + o..hi)``, both pieces keeping at least 3 points.
    Returns the new first and last points of the pieces.
    """
    if s.size < 2:
        return s, e
    o = s[1:] - e[:-1]
    adj = ((o >= 0) & (o <= 1) & (scan.cluster[s[1:]] == scan.cluster[e[:-1]])).nonzero()[0]
    if not adj.size:
        return s, e
    s, e = s.copy(), e.copy()
    width = 2 * reach + 1
    # (lo, b, hi, o) of every pair, once per candidate break (no broadcasting below)
    lo, b, hi, oo = np.array((s[adj], e[adj], e[adj + 1], o[adj])).repeat(
        width, axis=1).reshape(4, adj.size, width)
    cand = b + np.arange(-reach, reach + 1)
    ok = (cand - lo >= 2) & (hi - cand - oo >= 2)
    cand = np.where(ok, cand, b)
    # Both pieces of every candidate break in one batch: [lo, b'] and [b' + o, hi].
    first = np.empty((2,) + cand.shape, dtype=np.int64)
    last = np.empty_like(first)
    first[0] = lo
    np.add(cand, oo, out=first[1])
    last[0] = cand
    last[1] = hi
    sse = _sse(pre, first, last)
    cost = np.where(ok, sse[0] + sse[1], np.inf)
    best = cand.ravel()[cost.argmin(axis=1) + np.arange(0, cost.size, width)]
    e[adj] = best
    s[adj + 1] = best + o[adj]
    good = e - s >= 2  # breaks of a chain moved past each other: drop the squeezed piece
    if np.count_nonzero(good) == good.size:
        return s, e
    return s[good], e[good]


def _clean_pieces(scan: _Scan, pre: np.ndarray, s: np.ndarray, e: np.ndarray,
                  params: LineParams) -> Tuple[np.ndarray, np.ndarray]:
    """Trim outlying ends, give shared split points to one piece, drop short ones (step 2).

    Returns the first and last points of the pieces of at least ``min_points`` points.
    """
    if not s.size:
        return s, e
    if s.size <= _CLEAN_PY:
        return _clean_pieces_py(scan, pre, s, e, params)
    sums = np.empty((6, s.size))
    sums[0] = e - s + 1
    np.subtract(pre.take(e + 1, axis=1), pre.take(s, axis=1), out=sums[1:])
    cx, cy, sxx, syy, sxy = _scatter(sums)
    nrm = np.empty((2, s.size))
    _normal(sxx, syy, sxy, nrm)
    nx, ny = nrm
    # rho of the line relative to the scan origin (|distances| do not depend on the sign
    # of the normal, so the fit is not flipped to rho >= 0 here)
    ox, oy = scan.origin
    rho = (cx + ox) * nx + (cy + oy) * ny - nx * ox - ny * oy
    gate = params.trim_sigma
    reach = params.min_points
    steps = np.arange(reach)
    win = np.empty((s.size, 2 * reach), dtype=np.int64)
    np.minimum(s[:, None] + steps, e[:, None], out=win[:, :reach])
    np.maximum(e[:, None] - steps, s[:, None], out=win[:, reach:])
    z = _z(scan, nx, ny, rho, win, params)
    # leading (head) and trailing (tail) runs of outlying points
    lead, trail = (z > gate).reshape(s.size, 2, reach).cumprod(axis=2).sum(axis=2).T
    ns, ne = s + lead, e - trail
    # A split point shared by consecutive pieces goes to the piece it fits better.
    shared = ((e[:-1] >= s[1:]) & (ne[:-1] >= ns[1:])).nonzero()[0]
    if shared.size:
        to_prev = z[shared, reach] <= z[shared + 1, 0]
        ns[shared + 1] = np.where(to_prev, ne[shared] + 1, ns[shared + 1])
        ne[shared] = np.where(to_prev, ne[shared], ns[shared + 1] - 1)
    # Too short to be a line (min_points >= 3): their fits are too uncertain for the merge
    # test (the (rho, alpha) linearisation fails for them); their points stay free for
    # the lines to grow.
    keep = ne - ns + 1 >= params.min_points
    return ns[keep], ne[keep]


# Pieces up to which _clean_pieces_py is faster than the array operations (measured).
_CLEAN_PY = 40


def _clean_pieces_py(scan: _Scan, pre: np.ndarray, s: np.ndarray, e: np.ndarray,
                     params: LineParams) -> Tuple[np.ndarray, np.ndarray]:
    """Return :func:`_clean_pieces` computed on Python floats.

    The same operations in the same order (the fits of eqs. 8-9 from the prefix sums,
    the point tests of :func:`_z`), but only the points up to the first one within the
    gate are tested at each end (the array version tests ``min_points`` at each end), and
    a piece of fewer than ``min_points`` points (dropped in any case: the clean-up only
    shortens pieces) is fitted only when it shares its split point with a longer piece,
    whose end it may take or give; the others keep their ends, which touch no kept piece.
    """
    s_l, e_l = s.tolist(), e.tolist()
    least = params.min_points
    size = len(s_l)
    big = [b - a >= least - 1 for a, b in zip(s_l, e_l)]
    touch = [b >= a for b, a in zip(e_l, s_l[1:])]  # piece j shares its last point
    fitted = [j for j in range(size) if big[j] or (j and touch[j - 1] and big[j - 1])
              or (j < size - 1 and touch[j] and big[j + 1])]
    p1, p2, p3, p4, p5 = [memoryview(row) for row in pre]
    scat, a_in, b_in = [], [], []
    for j in fitted:  # _scatter of the sums from the prefix sums
        a, b = s_l[j], e_l[j] + 1
        n = float(b - a)
        cx = (p1[b] - p1[a]) / n
        cy = (p2[b] - p2[a]) / n
        ncx = n * cx
        sxx = (p3[b] - p3[a]) - ncx * cx
        syy = (p4[b] - p4[a]) - n * cy * cy
        sxy = (p5[b] - p5[a]) - ncx * cy
        scat.append((cx, cy))
        a_in.append(-2.0 * sxy)
        b_in.append(syy - sxx)
    if _MATH_TRIG:  # numpy's results (see _math_is_numpy)
        alpha = [0.5 * a for a in map(math.atan2, a_in, b_in)]  # eq. 8 (_normal)
        nxs, nys = list(map(math.cos, alpha)), list(map(math.sin, alpha))
    else:
        alpha = 0.5 * np.arctan2(a_in, b_in)  # eq. 8 (_normal)
        nxs, nys = np.cos(alpha).tolist(), np.sin(alpha).tolist()
    xs, ys, rng, cps, sps = scan.rows()[:_TOL]
    ox, oy = scan.origin
    sr, sp_ = params.gate_sigma_r, params.sigma_phi
    gate = params.trim_sigma
    reach = params.min_points

    def z(i: int, nx: float, ny: float, rho: float) -> float:
        """Return :func:`_z` of point i to one line."""
        d = xs[i] * nx + ys[i] * ny - rho
        cp, sp = cps[i], sps[i]
        a = sr * (nx * cp + ny * sp)
        b = rng[i] * sp_ * (ny * cp - nx * sp)
        return abs(d) / math.sqrt(max(a * a + b * b, 1e-24))

    ns, ne = s_l[:], e_l[:]
    z_first, z_last = [math.inf] * size, [math.inf] * size
    for i, j in enumerate(fitted):
        a, b = s_l[j], e_l[j]
        nx, ny = nxs[i], nys[i]
        cx, cy = scat[i]
        # rho of the line relative to the scan origin (see _clean_pieces)
        rho = (cx + ox) * nx + (cy + oy) * ny - nx * ox - ny * oy
        za, zb = z(a, nx, ny, rho), z(b, nx, ny, rho)
        z_first[j] = za
        z_last[j] = zb
        lead = 0  # leading outliers among the first `reach` points (clipped at b)
        while lead < reach and (za if lead == 0 else zb if a + lead >= b
                                else z(a + lead, nx, ny, rho)) > gate:
            lead += 1
        trail = 0
        while trail < reach and (zb if trail == 0 else za if b - trail <= a
                                 else z(b - trail, nx, ny, rho)) > gate:
            trail += 1
        ns[j] = a + lead
        ne[j] = b - trail
    # A split point shared by consecutive pieces goes to the piece it fits better.
    shared = [j for j in range(size - 1) if touch[j] and ne[j] >= ns[j + 1]]
    if shared:
        ne0 = ne[:]
        to_prev = [z_last[j] <= z_first[j + 1] for j in shared]
        for j, prev in zip(shared, to_prev):
            if prev:
                ns[j + 1] = ne0[j] + 1
        for j, prev in zip(shared, to_prev):
            if not prev:
                ne[j] = ns[j + 1] - 1
    keep = [j for j in range(size) if ne[j] - ns[j] + 1 >= least]
    return (np.array([ns[j] for j in keep], dtype=np.int64),
            np.array([ne[j] for j in keep], dtype=np.int64))


def _z(scan: _Scan, nx: np.ndarray, ny: np.ndarray, rho: np.ndarray, pts: np.ndarray,
       params: LineParams) -> np.ndarray:
    """Return |distance| / std (eq. 7 on the normal) of points pts (L, K) to the L lines.

    ``rho`` is relative to the scan origin.
    """
    x, y, rng, cp, sp = scan.cols[:_TOL].take(pts, axis=1)
    # the lines' parameters once per point (no broadcasting below)
    nx, ny, rho = np.array((nx, ny, rho)).repeat(pts.shape[1], axis=1).reshape((3,) + pts.shape)
    d = x * nx + y * ny - rho
    n_u = nx * cp + ny * sp
    n_v = ny * cp - nx * sp
    var = (params.gate_sigma_r * n_u) ** 2 + (rng * params.sigma_phi * n_v) ** 2
    return np.abs(d) / np.sqrt(np.maximum(var, 1e-24))
