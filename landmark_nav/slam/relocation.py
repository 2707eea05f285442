"""Relocation: one scan's pairs chosen jointly, and only when no other pairing competes.

When the robot's pose is uncertain (a heading std of 10-20 deg after a long corridor), the
individual gate of each observation holds several landmarks, and the spurious check
(``SlamParams.spurious_limit``) rightly refuses every such pair on its own. Yet the scan as
a whole may still fix the pose: two pairs determine it, and the other observations then
fall on their landmarks only if those two were right. This module searches the pairings a
scan allows and returns the best-supported one together with the best pairing that
contradicts it, so that the filter can use a pairing only when it stands alone (module
docstring of :mod:`.ekf_slam`, "Relocation"). It is the hypothesise-and-test relocation of
Neira, Tardos and Castellanos (linear-time vehicle relocation in SLAM, ICRA 2003), with the
hypotheses drawn from the individually compatible pairs and each tested by the
conditional individual compatibility of the others:

1. *Seeds*: every two candidate pairs (different observations, different landmarks) give,
   by an iterated Kalman update of the robot pose alone from its prior ``(x, P_rr)``, a
   pose ``x_h`` and covariance ``P_h`` (the landmarks' marginal covariances added to the
   observations' ``R``; eqs. 32-37 restricted to the robot); a seed whose two pairs fail
   their joint test (NIS over the 4 measurements) is dropped.
2. *Support*: at ``x_h``, every other candidate pair is gated with
   ``S = H_r P_h H_r^T + H_F P_FF H_F^T + R`` (the gate of eq. 55 conditioned on the seed)
   and, for lines, with the extents overlapping with the segment put in the map at
   ``x_h``. Each observation takes its nearest compatible landmark, each landmark its
   nearest observation: the seed's pairing.
3. *Competition*: the pairings with the most pairs win (ties: the smaller summed ``d2``);
   the runner-up is the largest pairing that *contradicts* it (an observation or a landmark
   paired differently). Pairings that agree where both pair (e.g. one a subset of the
   other, or the same walls of a corridor at two positions along it) do not compete.

The filter then updates with the winner's pairs through its own EKF update (eqs. 32-37),
so the map's correlations are used as for any other pairs.
"""

from typing import Tuple

import numpy as np
from scipy.stats import poisson

_PI = np.pi
_TWO_PI = 2.0 * np.pi


def _wrap(a):
    return np.mod(a + _PI, _TWO_PI) - _PI


def predict_pairs(pose: np.ndarray, lm: np.ndarray, is_line: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted observations of landmarks from poses, broadcast over leading axes.

    Corners: range-bearing (corner chapter eqs. 19-20, Jacobians eq. 53); lines:
    ``(rho_b, alpha_b)`` (:mod:`.line_landmarks`).

    Args:
        pose: (..., 3) robot poses.
        lm: (..., 2) landmarks: ``(x, y)`` of a corner, ``(rho, alpha)`` of a line.
        is_line: (...) bool, which landmarks are lines.

    Returns:
        ``(zhat (..., 2), H_r (..., 2, 3), H_F (..., 2, 2))`` over the broadcast shape.
    """
    shape = np.broadcast_shapes(pose.shape[:-1], lm.shape[:-1], np.shape(is_line))
    pose = np.broadcast_to(pose, shape + (3,))
    lm = np.broadcast_to(lm, shape + (2,))
    line = np.broadcast_to(is_line, shape)
    px, py, ps = pose[..., 0], pose[..., 1], pose[..., 2]
    zhat = np.empty(shape + (2,))
    hr = np.zeros(shape + (2, 3))
    hf = np.zeros(shape + (2, 2))
    # Corners (eqs. 19-20, 53).
    dx, dy = lm[..., 0] - px, lm[..., 1] - py
    q = np.maximum(dx * dx + dy * dy, 1e-18)
    rng = np.sqrt(q)
    c_rng, c_brg = rng, _wrap(np.arctan2(dy, dx) - ps)
    # Lines (line_landmarks module docstring).
    ca, sa = np.cos(lm[..., 1]), np.sin(lm[..., 1])
    l_rho, l_alpha = lm[..., 0] - px * ca - py * sa, _wrap(lm[..., 1] - ps)
    zhat[..., 0] = np.where(line, l_rho, c_rng)
    zhat[..., 1] = np.where(line, l_alpha, c_brg)
    hf[..., 0, 0] = np.where(line, 1.0, dx / rng)
    hf[..., 0, 1] = np.where(line, px * sa - py * ca, dy / rng)
    hf[..., 1, 0] = np.where(line, 0.0, -dy / q)
    hf[..., 1, 1] = np.where(line, 1.0, dx / q)
    hr[..., 0, 0] = np.where(line, -ca, -dx / rng)
    hr[..., 0, 1] = np.where(line, -sa, -dy / rng)
    hr[..., 1, 0] = np.where(line, 0.0, dy / q)
    hr[..., 1, 1] = np.where(line, 0.0, -dx / q)
    hr[..., 1, 2] = -1.0
    return zhat, hr, hf


def _innovation(z: np.ndarray, zhat: np.ndarray) -> np.ndarray:
    nu = z - zhat
    nu[..., 1] = _wrap(nu[..., 1])
    return nu


def seed_poses(pose: np.ndarray, p_rr: np.ndarray, z: np.ndarray, r: np.ndarray,
               lm: np.ndarray, lm_cov: np.ndarray, is_line: np.ndarray,
               iterations: int = 5) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robot pose from its prior and two pairs, per seed (iterated Kalman update).

    Args:
        pose: (3,) prior robot pose; p_rr: (3, 3) its covariance.
        z: (S, 2, 2) the two observations of each seed; r: (S, 2, 2, 2) their covariances.
        lm: (S, 2, 2) the two landmarks; lm_cov: (S, 2, 2, 2) their marginal covariances.
        is_line: (S, 2) bool.
        iterations: Linearisations (the prior may be 20 deg off).

    Returns:
        ``(x_h (S, 3), P_h (S, 3, 3), nis (S,))``: the posterior pose, its covariance
        and the two pairs' joint NIS (4 dof) at the last linearisation.
    """
    n = z.shape[0]
    x0 = np.broadcast_to(np.asarray(pose, dtype=float), (n, 3))
    xi = x0.copy()
    eye = np.eye(3)
    for _ in range(max(1, iterations)):
        zhat, hr, hf = predict_pairs(xi[:, None, :], lm, is_line)
        rt = r + hf @ lm_cov @ np.swapaxes(hf, -1, -2)  # (S, 2, 2, 2)
        h = hr.reshape(n, 4, 3)
        s = h @ p_rr @ np.swapaxes(h, 1, 2)
        s[:, :2, :2] += rt[:, 0]
        s[:, 2:, 2:] += rt[:, 1]
        nu = _innovation(z, zhat).reshape(n, 4) - np.einsum('sij,sj->si', h, x0 - xi)
        w = np.linalg.solve(s, nu[:, :, None])[:, :, 0]  # S^-1 nu
        x_new = x0 + np.einsum('ij,skj,sk->si', p_rr, h, w)
        x_new[:, 2] = x0[:, 2] + _wrap(x_new[:, 2] - x0[:, 2])
        xi = x_new
    k = np.linalg.solve(s, h @ p_rr).transpose(0, 2, 1)  # P H^T S^-1 (S symmetric)
    p_h = (eye - k @ h) @ p_rr
    p_h = 0.5 * (p_h + np.swapaxes(p_h, 1, 2))
    nis = np.einsum('si,si->s', nu, w)
    return xi, p_h, nis


def _overlap_at(poses: np.ndarray, obs_ends: np.ndarray, lm: np.ndarray,
                lm_ends: np.ndarray) -> np.ndarray:
    """(S, C) whether each observed segment, put in the map at each pose, overlaps its line.

    Args:
        poses: (S, 3); obs_ends: (C, 2, 2) base_link endpoints; lm: (C, 2) the lines;
        lm_ends: (C, 2, 2) their map endpoints.
    """
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    ex, ey = obs_ends[None, :, :, 0], obs_ends[None, :, :, 1]  # (1, C, 2)
    mx = poses[:, 0, None, None] + c[:, None, None] * ex - s[:, None, None] * ey
    my = poses[:, 1, None, None] + s[:, None, None] * ex + c[:, None, None] * ey
    dx, dy = -np.sin(lm[:, 1]), np.cos(lm[:, 1])  # (C,)
    t = mx * dx[None, :, None] + my * dy[None, :, None]  # (S, C, 2)
    lt = np.sort(lm_ends[:, :, 0] * dx[:, None] + lm_ends[:, :, 1] * dy[:, None], axis=1)
    return (t.max(axis=2) >= lt[None, :, 0]) & (t.min(axis=2) <= lt[None, :, 1])


def relocate(pose: np.ndarray, p_rr: np.ndarray, z: np.ndarray, r: np.ndarray,
             obs_ends: np.ndarray, cand_obs: np.ndarray, cand_lm: np.ndarray,
             lm: np.ndarray, lm_cov: np.ndarray, lm_is_line: np.ndarray,
             lm_ends: np.ndarray, gate: float, joint_gate: float, density: np.ndarray,
             obs_bisector: np.ndarray, lm_bisector: np.ndarray, bisector_gate: float
             ) -> Tuple[np.ndarray, int, int, float, float]:
    """The best-supported pairing of one scan and the support of its best contradiction.

    Args:
        pose: (3,) prior robot pose; p_rr: (3, 3) its covariance.
        z: (M, 2) observations in base_link; r: (M, 2, 2) their covariances.
        obs_ends: (M, 2, 2) observed segment endpoints in base_link (lines; NaN else).
        cand_obs, cand_lm: (C,) the candidate pairs (observation, landmark), each
            individually compatible at the prior and of one kind.
        lm: (N, 2) landmarks; lm_cov: (N, 2, 2) their marginal covariances;
        lm_is_line: (N,) bool; lm_ends: (N, 2, 2) map endpoints of the lines.
        gate: chi-square bound (2 dof) of the conditional individual test.
        joint_gate: chi-square bound (4 dof) of a seed's joint test.
        density: (M,) the scene's density of each observation's kind (features per m^2
            for corners, per m rad for lines: ``lambda`` of the spurious check).
        obs_bisector: (M,) each corner's bisector in base_link [rad] (NaN: unknown).
        lm_bisector: (N, 2) the landmarks' bisector vectors (zero: unknown).
        bisector_gate: Largest bisector difference of a corner pair at a seed's pose.

    Returns:
        ``(pairing (M,), support, rival, chance_support, chance_rival)``: the landmark
        index per observation (-1: none) of the winning pairing, its number of pairs, the
        number of pairs of the largest pairing that contradicts it (0 if none), and the
        expected numbers of seeds that would reach each of those supports by chance
        (:func:`chance_seeds`). ``support`` is 0 when no seed passes its joint test.
    """
    m = z.shape[0]
    none = np.full(m, -1, dtype=np.int64)
    c_n = cand_obs.size
    if c_n < 2:
        return none, 0, 0, np.inf, np.inf
    a, b = np.triu_indices(c_n, k=1)
    ok = (cand_obs[a] != cand_obs[b]) & (cand_lm[a] != cand_lm[b])
    a, b = a[ok], b[ok]
    if a.size == 0:
        return none, 0, 0, np.inf, np.inf
    oa, ob, la, lb = cand_obs[a], cand_obs[b], cand_lm[a], cand_lm[b]
    x_h, p_h, nis = seed_poses(
        pose, p_rr, np.stack([z[oa], z[ob]], axis=1), np.stack([r[oa], r[ob]], axis=1),
        np.stack([lm[la], lm[lb]], axis=1), np.stack([lm_cov[la], lm_cov[lb]], axis=1),
        np.stack([lm_is_line[la], lm_is_line[lb]], axis=1))
    keep = np.isfinite(nis) & (nis <= joint_gate)
    if not np.any(keep):
        return none, 0, 0, np.inf, np.inf
    x_h, p_h = x_h[keep], p_h[keep]
    # Conditional individual compatibility of every candidate pair at every seed.
    cl = lm[cand_lm]
    line = lm_is_line[cand_lm]
    zhat, hr, hf = predict_pairs(x_h[:, None, :], cl[None, :, :], line[None, :])
    s = (hr @ p_h[:, None] @ np.swapaxes(hr, -1, -2)
         + hf @ lm_cov[cand_lm][None] @ np.swapaxes(hf, -1, -2) + r[cand_obs][None])
    nu = _innovation(z[cand_obs][None], zhat)
    det = s[..., 0, 0] * s[..., 1, 1] - s[..., 0, 1] * s[..., 1, 0]
    d2 = (s[..., 1, 1] * nu[..., 0] ** 2 - 2.0 * s[..., 0, 1] * nu[..., 0] * nu[..., 1]
          + s[..., 0, 0] * nu[..., 1] ** 2) / det
    fit = (det > 0.0) & (d2 <= gate)
    fit &= ~line[None, :] | (zhat[..., 0] > 0.0)  # a wall is seen from its front
    corner = ~line & np.isfinite(obs_bisector[cand_obs])
    if np.any(corner):  # the bisector in the map at the seed's heading (descriptor gate)
        lb = lm_bisector[cand_lm[corner]]
        norm = np.hypot(lb[:, 0], lb[:, 1])
        wb = obs_bisector[cand_obs[corner]][None, :] + x_h[:, 2, None]
        cos_d = (np.cos(wb) * lb[None, :, 0] + np.sin(wb) * lb[None, :, 1]) / np.where(
            norm > 0.0, norm, 1.0)[None, :]
        fit[:, corner] &= (norm[None, :] == 0.0) | (cos_d >= np.cos(bisector_gate) - 1e-12)
    if np.any(line):
        fit[:, line] &= _overlap_at(x_h, obs_ends[cand_obs[line]], cl[line],
                                    lm_ends[cand_lm[line]])
    cost = np.where(fit, d2, np.inf)
    # The chance that each observation finds a landmark in its gate at a wrong pose:
    # 1 - exp(-lambda A), A the gate's area (pi g sqrt(det S), in the plane for corners).
    area = np.pi * gate * np.sqrt(np.maximum(det, 0.0))
    area = np.where(line[None, :], area, area * np.abs(zhat[..., 0]))
    p_pair = 1.0 - np.exp(-density[cand_obs][None, :] * area)
    # Each observation its nearest compatible landmark ...
    ns = x_h.shape[0]
    pairing = np.full((ns, m), -1, dtype=np.int64)
    best = np.full((ns, m), np.inf)
    rows = np.arange(ns)
    mu = np.zeros(ns)  # expected chance pairs per seed, its own two observations apart
    seed_obs = np.column_stack([oa, ob])[keep]
    for i in np.unique(cand_obs):
        cols = np.flatnonzero(cand_obs == i)
        mu += np.where(np.any(seed_obs == i, axis=1), 0.0, p_pair[:, cols].mean(axis=1))
        k = np.argmin(cost[:, cols], axis=1)
        v = cost[rows, cols[k]]
        has = np.isfinite(v)
        pairing[has, i] = cand_lm[cols[k[has]]]
        best[has, i] = v[has]
    # ... and each landmark its nearest observation.
    obs_ids = np.unique(cand_obs)
    for u, i in enumerate(obs_ids):
        for j in obs_ids[u + 1:]:
            same = (pairing[:, i] >= 0) & (pairing[:, i] == pairing[:, j])
            lose_i = same & (best[:, i] > best[:, j])
            lose_j = same & ~lose_i
            pairing[lose_i, i], best[lose_i, i] = -1, np.inf
            pairing[lose_j, j], best[lose_j, j] = -1, np.inf
    sets, first = np.unique(pairing, axis=0, return_index=True)
    support = np.count_nonzero(sets >= 0, axis=1)
    total = np.where(np.isfinite(best[first]), best[first], 0.0).sum(axis=1)
    win = np.lexsort((total, -support))[0]
    w = sets[win]
    both = (sets >= 0) & (w[None, :] >= 0)
    contra = np.any(both & (sets != w[None, :]), axis=1)
    for i in np.flatnonzero(w >= 0):
        elsewhere = np.ones(m, dtype=bool)
        elsewhere[i] = False
        contra |= np.any((sets == w[i]) & elsewhere[None, :], axis=1)
    rival = int(support[contra].max()) if np.any(contra) else 0
    return (w.copy(), int(support[win]), rival, chance_seeds(mu, int(support[win])),
            chance_seeds(mu, rival))


def chance_seeds(mu: np.ndarray, support: int) -> float:
    """Expected number of seeds reaching ``support`` pairs by chance.

    A seed's two pairs are its own; each other observation pairs by chance with
    probability ``1 - exp(-lambda A)``, so the seed's chance pairs are about Poisson with
    the sum ``mu`` of those; the expectation over the seeds is the sum of
    ``P(Poisson(mu) >= support - 2)`` (the false-alarm count of a hypothesise-and-test
    search: the more seeds tried, the more support a pairing needs to stand out).

    Args:
        mu: (S,) expected chance pairs of each seed.
        support: Pairs of the pairing (its seed's two included).
    """
    k = max(int(support) - 2, 0)
    if k == 0:
        return float(mu.size)
    return float(np.sum(poisson.sf(k - 1, mu)))


__all__ = ['chance_seeds', 'predict_pairs', 'relocate', 'seed_poses']
