"""Data association on innovations (corner chapter section 3.5, eqs. 49-55; JCBB).

Pure functions on arrays; nothing here knows the filter. Notation (eqs. 49-54): ``M``
observations ``z_i``, ``N`` map features with predicted observations ``zhat_j`` (eq. 50);
``nu[i, j] = z_i - zhat_j`` (eq. 51, bearing wrapped) and ``S[i, j]`` its covariance
(eq. 52). A hypothesis ``H = [j_1 .. j_M]`` (eq. 49) is returned as an int array with
``-1`` for "no feature" (the chapter's ``j_i = 0``).

* :func:`mahalanobis_table` -- ``D2[i, j] = nu^T S^-1 nu`` for all pairs (eq. 54), closed-form
  2 x 2 inverses, no loop.
* :func:`icnn` -- Individual Compatibility Nearest Neighbour: a pair is compatible when
  ``D2 < chi2_{2, 1 - alpha}`` (eq. 55); each observation takes its compatible feature with
  the smallest ``D2``. One-to-one by default: pairs are taken greedily in increasing ``D2``
  so that a feature explains at most one observation of a scan (the chapter's ICNN lets two
  observations share a feature; ``one_to_one=False`` gives that).
* :func:`jcbb` -- Joint Compatibility Branch and Bound (Neira & Tardos 2001): depth-first
  over observations, branching on the individually compatible features (nearest first) and
  on "no feature"; a branch is kept only if the whole hypothesis is jointly compatible,
  ``D2_H = nu_H^T S_H^-1 nu_H < chi2_{2p, 1 - alpha}`` with ``p`` pairings, where ``S_H``
  holds the cross-covariances of the predicted observations (they share the robot pose).
  The best hypothesis has the most pairings, ties broken by the smaller ``D2_H``. The
  branch "no feature" is explored only while it can still reach the best pairing count.
  ``D2_H`` is extended incrementally with a bordered Cholesky factor (O(p^2) per node).
"""

from typing import List, Optional, Tuple

import numpy as np

from ._linalg import solve_lower
from .consistency import chi2_gate


def mahalanobis_table(nu: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distances of 2-D innovations (eq. 54), vectorised.

    Args:
        nu: (..., 2) innovations.
        s: (..., 2, 2) their covariances (symmetric positive definite).

    Returns:
        (...) array ``nu^T S^-1 nu``; ``inf`` where ``S`` is not positive definite.
    """
    a, b, c = s[..., 0, 0], 0.5 * (s[..., 0, 1] + s[..., 1, 0]), s[..., 1, 1]
    det = a * c - b * b
    n0, n1 = nu[..., 0], nu[..., 1]
    with np.errstate(divide='ignore', invalid='ignore'):
        d2 = (c * n0 * n0 - 2.0 * b * n0 * n1 + a * n1 * n1) / det
    return np.where((det > 0.0) & (a > 0.0) & np.isfinite(d2), d2, np.inf)


def icnn(d2: np.ndarray, gate: float, one_to_one: bool = True) -> np.ndarray:
    """Individual Compatibility Nearest Neighbour (eqs. 54-55).

    Args:
        d2: (M, N) squared Mahalanobis distances (:func:`mahalanobis_table`).
        gate: Compatibility threshold ``chi2_{d, 1 - alpha}`` (eq. 55).
        one_to_one: Let each feature explain at most one observation (greedy in ``D2``).

    Returns:
        (M,) feature index per observation, -1 where none is compatible.
    """
    d2 = np.asarray(d2, dtype=float)
    m = d2.shape[0]
    out = np.full(m, -1, dtype=np.int64)
    if d2.size == 0:
        return out
    if not one_to_one:
        best = np.argmin(d2, axis=1)
        ok = d2[np.arange(m), best] < gate  # eq. 55
        out[ok] = best[ok]
        return out
    obs, feat = np.nonzero(d2 < gate)  # eq. 55
    if obs.size == 0:
        return out
    order = np.argsort(d2[obs, feat], kind='stable')
    used = set()
    for k in order:
        i, j = int(obs[k]), int(feat[k])
        if out[i] < 0 and j not in used:
            out[i] = j
            used.add(j)
    return out


def joint_mahalanobis(nu: np.ndarray, s_pred: np.ndarray, r: np.ndarray,
                      hypothesis: np.ndarray) -> float:
    """Return ``D2_H`` of a whole hypothesis (joint compatibility, JCBB's test).

    Args:
        nu: (M, N, 2) innovations ``z_i - zhat_j``.
        s_pred: (N, 2, N, 2) joint covariance of the predicted observations ``H P H^T``.
        r: (M, 2, 2) observation covariances.
        hypothesis: (M,) feature index per observation, -1 for none.

    Returns:
        ``nu_H^T S_H^-1 nu_H`` (0 for an empty hypothesis).
    """
    obs = np.flatnonzero(np.asarray(hypothesis) >= 0)
    if obs.size == 0:
        return 0.0
    feat = np.asarray(hypothesis)[obs]
    v = nu[obs, feat].reshape(-1)
    s = s_pred[feat][:, :, feat].reshape(2 * obs.size, 2 * obs.size)
    s = s + _block_diag(r[obs])
    low = np.linalg.cholesky(s)
    y = solve_lower(low, v)
    return float(y @ y)


def _block_diag(blocks: np.ndarray) -> np.ndarray:
    """Return the block-diagonal matrix of (K, 2, 2) blocks, shape (2K, 2K)."""
    k = blocks.shape[0]
    out = np.zeros((k, 2, k, 2))
    idx = np.arange(k)
    out[idx, :, idx, :] = blocks
    return out.reshape(2 * k, 2 * k)


def jcbb(nu: np.ndarray, s_pred: np.ndarray, r: np.ndarray, d2: np.ndarray,
         probability: float = 0.95, max_nodes: int = 5000
         ) -> Tuple[np.ndarray, float, int]:
    """Joint Compatibility Branch and Bound (Neira & Tardos 2001).

    Args:
        nu: (M, N, 2) innovations ``z_i - zhat_j`` (eq. 51; bearings wrapped).
        s_pred: (N, 2, N, 2) joint covariance ``H P H^T`` of the predicted observations of
            the N features (the diagonal blocks are eq. 52 without ``R``).
        r: (M, 2, 2) observation covariances ``R_i``.
        d2: (M, N) individual ``D2`` (eq. 54); only pairs with
            ``d2 < chi2_{2, probability}`` are branched on.
        probability: Confidence ``1 - alpha`` of the individual and joint gates.
        max_nodes: Cap on the visited nodes; the best hypothesis found so far is returned
            when it is reached.

    Returns:
        ``(hypothesis (M,), D2_H, nodes)``: feature per observation (-1 none), the joint
        Mahalanobis distance of the returned hypothesis and the number of nodes visited.
    """
    m = d2.shape[0]
    gate1 = chi2_gate(2, probability)
    cands: List[np.ndarray] = []
    for i in range(m):
        js = np.flatnonzero(d2[i] < gate1)
        cands.append(js[np.argsort(d2[i, js], kind='stable')])
    # Observations with candidates, fewest first (tighter bound early).
    order = sorted((i for i in range(m) if cands[i].size), key=lambda i: cands[i].size)
    best = {'h': np.full(m, -1, dtype=np.int64), 'pairs': 0, 'd2': 0.0}
    nodes = [0]
    gates = {p: chi2_gate(2 * p, probability) for p in range(1, len(order) + 1)}
    h = np.full(m, -1, dtype=np.int64)

    def extend(low: Optional[np.ndarray], y: np.ndarray, feats: List[int], i: int,
               j: int) -> Optional[Tuple[np.ndarray, np.ndarray, float]]:
        """Border the Cholesky factor of S_H with pair (i, j); None if not PD."""
        s22 = s_pred[j, :, j, :] + r[i]
        v2 = nu[i, j]
        if low is None:
            try:
                l22 = np.linalg.cholesky(s22)
            except np.linalg.LinAlgError:
                return None
            y2 = solve_lower(l22, v2)
            return l22, y2, float(y2 @ y2)
        s12 = s_pred[feats][:, :, j, :].reshape(-1, 2)
        b = solve_lower(low, s12)
        try:
            l22 = np.linalg.cholesky(s22 - b.T @ b)
        except np.linalg.LinAlgError:
            return None
        y2 = solve_lower(l22, v2 - b.T @ y)
        p = low.shape[0]
        new = np.zeros((p + 2, p + 2))
        new[:p, :p] = low
        new[p:, :p] = b.T
        new[p:, p:] = l22
        return new, np.concatenate([y, y2]), float(y2 @ y2)

    def search(k: int, low: Optional[np.ndarray], y: np.ndarray, feats: List[int],
               pairs: int, dist: float) -> None:
        if nodes[0] >= max_nodes:
            return
        nodes[0] += 1
        if k == len(order):
            if pairs > best['pairs'] or (pairs == best['pairs'] and dist < best['d2']):
                best.update(h=h.copy(), pairs=pairs, d2=dist)
            return
        i = order[k]
        for j in cands[i]:
            j = int(j)
            if j in feats:
                continue
            ext = extend(low, y, feats, i, j)
            if ext is None:
                continue
            new_low, new_y, inc = ext
            if dist + inc < gates[pairs + 1]:  # joint compatibility
                h[i] = j
                search(k + 1, new_low, new_y, feats + [j], pairs + 1, dist + inc)
                h[i] = -1
        if pairs + len(order) - k - 1 >= best['pairs']:  # "no feature" can still tie/win
            search(k + 1, low, y, feats, pairs, dist)

    search(0, None, np.zeros(0), [], 0, 0.0)
    return best['h'], float(best['d2']), nodes[0]


__all__ = ['icnn', 'jcbb', 'joint_mahalanobis', 'mahalanobis_table']
