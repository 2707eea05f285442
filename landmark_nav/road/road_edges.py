"""Road edges from the profile pieces: merging, edge placement and verges (§4.2, step 5).

The pieces of :mod:`.profile_segmentation` are rejoined unless they differ physically
(:func:`_merge_pieces`: roughness by ``rough_ratio``, an F-test in :func:`_rougher`, or a
profile kink of more than ``split_rms``); each remaining boundary is re-placed by a
continuous fit of the two neighbours, the wider quadratic and the narrower straight
(:func:`_refine_edges`, :func:`_hinge_edge`, :func:`_hinge_nll`); and the rougher of two
pieces beside a road-wide smooth piece is a verge (:func:`_verges`). Used by
:func:`landmark_nav.road.terrain.classify_scan`.
"""

import functools
import math
from typing import Optional

from landmark_nav.road.profile_fits import _fit_piece, _orthogonal_sums
from landmark_nav.road.terrain_params import TerrainParams
import numpy as np


def _rougher(v_a: float, n_a: int, v_b: float, n_b: int, params: TerrainParams) -> bool:
    """Whether one piece is rougher than the other by ``rough_ratio``, significantly.

    F-test of the variance ratio against ``rough_ratio^2`` at ``rough_alpha`` (quadratic
    pieces: n - 3 degrees of freedom): a short piece's variance is too uncertain for the
    plain ratio (a smooth stretch of a few readings in a gravel road).
    """
    (v_hi, n_hi), (v_lo, n_lo) = sorted(((v_a, n_a), (v_b, n_b)), reverse=True)
    crit = _f_quantile(max(n_hi - 3, 1), max(n_lo - 3, 1), 1.0 - params.rough_alpha)
    return v_hi >= params.rough_ratio ** 2 * crit * v_lo


@functools.lru_cache(maxsize=4096)
def _f_quantile(dfn: int, dfd: int, q: float) -> float:
    """Return the F distribution's ``q`` quantile (cached: the piece sizes repeat)."""
    from scipy.special import fdtri  # on first use: the node starts without scipy.special
    return float(fdtri(dfn, dfd, q))


def _merge_pieces(pieces: list, table: np.ndarray, params: TerrainParams,
                  fits: Optional[dict] = None) -> list:
    """Rejoin neighbouring pieces whose boundary is not a physical change.

    A boundary stays when the two pieces' roughness differs by ``rough_ratio`` (e.g. smooth
    asphalt next to a rough verge at the same height) or two profiles fit better than one
    by more than ``split_rms`` metres rms over the shorter piece (a kink, e.g. a crowned
    road and its flat shoulder), and the split is still significant (the BIC of
    :func:`_segment_profile`); otherwise the pieces merge (a crowned road split by its
    random texture).
    """
    def nll(sse: float, n: int, floor: float) -> float:
        v = max(sse / n, floor)
        return 0.5 * (n * math.log(v) + sse / v)

    def weakness(j: int) -> float:
        """Return the boundary's gain per reading over the penalty if it may go, else inf."""
        (pf, pl), (first, last) = out[j], out[j + 1]
        if pl + 1 != first:
            return math.inf
        sse_a, v_a, f_a, n_a = _fit_piece(pf, pl, table, fits)
        sse_b, v_b, f_b, n_b = _fit_piece(first, last, table, fits)
        sse_ab, _, f_ab, n = _fit_piece(pf, last, table, fits)
        gain = nll(sse_ab, n, f_ab) - nll(sse_a, n_a, f_a) - nll(sse_b, n_b, f_b) \
            - 2.5 * math.log(n)
        kink = math.sqrt(max(sse_ab - sse_a - sse_b, 0.0) / min(n_a, n_b)) > params.split_rms
        if gain > 0.0 and (kink or _rougher(v_a, n_a, v_b, n_b, params)):
            return math.inf
        return gain / n

    out = list(pieces)
    weak = [weakness(j) for j in range(len(out) - 1)]
    while weak and min(weak) < math.inf:
        # The least significant boundary goes first: two pieces of the road merge before
        # either is merged with a verge.
        j = int(np.argmin(weak))
        out[j:j + 2] = [(out[j][0], out[j + 1][1])]
        del weak[j]
        for i in (j - 1, j):
            if 0 <= i < len(weak):
                weak[i] = weakness(i)
    return out


def _hinge_edge(first: int, last: int, quad_left: bool, v_left: float, v_right: float,
                table: np.ndarray, min_points: int) -> int:
    """Return the reading that starts the right piece of the best continuous two-piece fit.

    The stretch ``first`` .. ``last`` of :func:`_moment_table` is split at every reading
    ``k`` (``min_points`` each side) into a quadratic and a straight profile (the quadratic
    on the left if ``quad_left``) that meet at the lateral position ``tau`` between
    readings ``k - 1`` and ``k`` (no step: a road and its verge are one surface, only the
    slope changes), each side weighted by its own height variance (``v_left``,
    ``v_right``). The split of least negative log-likelihood is the edge.
    """
    n = last - first + 1
    if n < 2 * min_points:
        return first + n // 2
    k, nll = _hinge_nll(first, last, quad_left, v_left, v_right, table, min_points)
    return first + int(k[int(np.argmin(nll))])


def _hinge_nll(first: int, last: int, quad_left: bool, v_left: float, v_right: float,
               table: np.ndarray, min_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the splits ``k`` of :func:`_hinge_edge` and their negative log-likelihoods.

    The continuous fit is the two sides' own least-squares fits (:func:`_explained`: the
    quadratic on one side, the line on the other) corrected for the one constraint that
    they meet at ``tau``. For an equality-constrained least-squares problem the weighted
    residual sum grows by ``d^2 / (l_q / w_q + l_o / w_o)``: ``d`` is the step between the
    two free fits at ``tau``, ``l`` each fit's leverage at ``tau`` (its value's variance
    over the noise variance: ``1 / n + (tau - mean t)^2 / Sxx`` for the line, plus
    ``phi2(tau)^2 / Rt`` for the quadratic's orthogonalised ``t^2`` term), ``w`` the side's
    weight (Lagrange multiplier of the constraint; e.g. Seber and Lee, Linear Regression
    Analysis, 2nd ed., §3.8.1). All as array arithmetic over the splits.
    """
    n = last - first + 1
    mp = min_points
    base = table[:9, first:first + 1]
    left = table[:9, first + mp:last + 2 - mp] - base                  # sums over [0, k)
    right = (table[:9, last + 1:last + 2] - base) - left
    t = table[1, first + 1:last + 2] - table[1, first:last + 1]        # t of each reading
    k = np.arange(mp, n - mp + 1)
    tau = 0.5 * (t[mp - 1:n - mp] + t[mp:n - mp + 1])
    quad, line = (left, right) if quad_left else (right, left)
    w_q, w_o = (1.0 / v_left, 1.0 / v_right) if quad_left else (1.0 / v_right, 1.0 / v_left)
    # The quadratic side (Gram-Schmidt on its sums, as in _explained).
    mt, mz, m2, sxx, sxz, beta, rt, rz = _orthogonal_sums(quad)
    s0, b0, zz = quad[0], quad[5], quad[8]
    du = tau - mt
    phi = tau * tau - m2 - beta * du                  # the orthogonalised t^2 at tau
    a1, a2 = sxz / sxx, rz / rt
    value_q = mz + a1 * du + a2 * phi
    lever_q = 1.0 / s0 + du * du / sxx + phi * phi / rt
    wss_q = zz - b0 * mz - a1 * sxz - a2 * rz
    # The straight side.
    o0, o1, o2, c0, c1, oz = line[[0, 1, 2, 5, 6, 8]]
    mt, mz = o1 / o0, c0 / o0
    sxx = o2 - o1 * mt
    a1 = (c1 - o1 * mz) / sxx
    du = tau - mt
    value_o = mz + a1 * du
    lever_o = 1.0 / o0 + du * du / sxx
    wss_o = oz - c0 * mz - a1 * a1 * sxx
    d = value_q - value_o
    wss = w_q * wss_q + w_o * wss_o + d * d / (lever_q / w_q + lever_o / w_o)
    return k, 0.5 * (wss + k * math.log(v_left) + (n - k) * math.log(v_right))


def _refine_edges(pieces: list, table: np.ndarray, params: TerrainParams,
                  fits: Optional[dict] = None) -> list:
    """Re-place each boundary between neighbouring pieces by a continuous two-piece fit.

    The binary segmentation fits each piece on its own: the short piece beside the road (a
    shoulder 0.6 m wide), free to curve and to start at any height, takes the last few
    tenths of a metre of the crowned road's falling edge with it. Here the wider piece
    keeps its quadratic profile, the narrower one is straight, and the two meet without a
    step (:func:`_hinge_edge`); each side's height variance is its piece's (floored by the
    laser's height noise).
    """
    out = list(pieces)
    for j in range(len(out) - 1):
        (fa, la), (fb, lb) = out[j], out[j + 1]
        if la + 1 != fb:
            continue
        v_a = _fit_piece(fa, la, table, fits)[1]
        v_b = _fit_piece(fb, lb, table, fits)[1]
        k = _hinge_edge(fa, lb, la - fa >= lb - fb, v_a, v_b, table, params.min_points)
        out[j], out[j + 1] = (fa, k - 1), (k, lb)
    return out


def _verges(pieces: list, s: np.ndarray, table: np.ndarray, params: TerrainParams,
            fits: Optional[dict] = None) -> list:
    """Flag the rougher of two neighbours whose roughness differs by ``rough_ratio``.

    The rougher piece is a verge (shoulder, grass) beside a smoother and wider piece, at
    least ``min_width`` wide (the road, whose roughness is well estimated): not
    traversable. A smooth patch of a gravel road does not make the road a verge.
    """
    rough = [_fit_piece(first, last, table, fits)[1::2] for first, last in pieces]
    width = [abs(s[last] - s[first]) for first, last in pieces]
    verge = [False] * len(pieces)
    for j in range(len(pieces) - 1):
        if pieces[j][1] + 1 != pieces[j + 1][0]:
            continue
        smooth, other = (j, j + 1) if rough[j][0] < rough[j + 1][0] else (j + 1, j)
        if width[smooth] >= max(params.min_width, width[other]) and \
                _rougher(*rough[j], *rough[j + 1], params):
            verge[other] = True
    return verge
