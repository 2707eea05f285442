"""EKF-SLAM batch update (corner chapter eqs. 32-37) and covariance numerics.

Iterated update
---------------
After a long stretch without observations (a laser blackout, a loop closure) the first
update can move the robot by tens of centimetres, and ``h`` linearised at the prediction is
then wrong by centimetres: the plain EKF lands off the truth with a collapsed covariance and
rejects the next scans. :func:`ekf_update` therefore re-linearises (iterated EKF,
Gauss-Newton on the prior and the observations) while an observed landmark moves, relative
to the robot, by more than ``relinearize_ratio`` (2 %) of its range, at most
``max_update_iterations`` times. The association is decided once, at the prediction. In
ordinary tracking the moves stay below the ratio (office seeds 0-9: at most 1.8 %), so the
update is the plain EKF there. With any ``jacobians`` but ``'standard'`` the covariance
takes the first linearisation instead (at the prior, see "Consistency"): Jacobians taken at
the iterate, which moved in the unobservable directions too, would add information there;
``'first_estimates'`` and ``'observability_gain'`` do not iterate at all (their gain is not
the Jacobian at the iterate, and Gauss-Newton steps with it diverged).

Numerics
--------
The update uses the symmetric Cholesky form of eq. 35, ``P <- P - W1 W1^T`` with ``W1 = P
H^T L^-T`` and ``S = L L^T``, then ``P <- (P + P^T) / 2``. After every update (every
``psd_check_interval``-th) a Cholesky factorisation of ``P + eps I`` (``eps`` =
``psd_tolerance`` times the largest diagonal entry) tests positive semi-definiteness; if it
fails, ``P`` is replaced by its nearest PSD matrix (eigenvalues clipped at 0), the repair is
counted in :attr:`.ekf_slam.EkfSlam.stats` and in the :class:`.ekf_slam.UpdateResult`, and
the filter goes on with the repaired matrix. Non-finite inputs are rejected before they
reach the state.
"""

from typing import Optional, Tuple

import numpy as np

from ._linalg import _wrap, lapack, solve_lower
from .consistent_linearisation import (constrain_jacobians, invariant_retraction,
                                       invariant_transport)
from .observation_models import _landmark_cols, _relative_points, observation_model


def ekf_update(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray,
               index: np.ndarray, max_iterations: int = 1,
               relinearize_ratio: float = 0.02, kind: Optional[np.ndarray] = None,
               nullspace: Optional[np.ndarray] = None, constrained_gain: bool = False,
               jacobian_state: Optional[np.ndarray] = None,
               invariant_kinds: Optional[np.ndarray] = None) -> Tuple[np.ndarray, float]:
    """Batch EKF update with observations of map landmarks (eqs. 32-37), in place.

    ``nu = z - h(x)`` (eqs. 36-37, bearings wrapped), ``S = H P H^T + R`` (eq. 33),
    ``W = P H^T S^-1`` (eq. 32), ``x += W nu`` (eq. 34), ``P -= W S W^T`` (eq. 35) evaluated
    as ``P -= W1 W1^T`` with ``W1 = P H^T L^-T``, ``S = L L^T``. ``H`` is never formed: each
    observation touches the robot and one landmark, so ``P H^T`` is gathered block-wise.

    Iterated form (module docstring, "Iterated update"): with ``max_iterations > 1``, if an
    observed landmark moved relative to the robot by more than ``relinearize_ratio`` times
    its range, ``h`` and ``H`` are evaluated again at the new estimate ``x_i`` and the update
    is recomputed from the prior ``x_0, P`` with ``nu_i = z - h(x_i) - H_i (x_0 - x_i)``
    (Gauss-Newton); ``P`` takes the last ``H_i``. Otherwise the result is the plain update.

    Args:
        x: State (modified in place).
        p: Covariance (overwritten with the unsymmetrised result).
        z: (K, 2) observations.
        r: (K, 2, 2) their covariances.
        index: (K,) landmark index of each observation (distinct).
        max_iterations: Largest number of linearisations (1 = plain EKF).
        relinearize_ratio: Relative move that triggers another linearisation (a line's
            "position" relative to the robot is its foot point ``rho_b (cos, sin)(alpha)``).
        kind: Optional (K,) kind of each observed landmark (None: corners).
        nullspace: Optional (K, 5, 3) unobservable directions of ``[robot, landmark]`` per
            observation (:func:`unobservable_directions`); each ``[H_r, H_F]`` is replaced
            by the closest matrix that maps them to zero (observability-constrained EKF) in
            the covariance update (taken at the first linearisation), and with
            ``constrained_gain`` in the mean update too (at every linearisation).
        constrained_gain: With ``nullspace``: the mean update's gain from the constrained
            Jacobians as well (Huang et al.'s OC-EKF); one linearisation (no iteration).
        jacobian_state: Optional state the Jacobians (not ``h``) are taken at, for the gain
            and the covariance (first-estimates Jacobians: the robot's prior and each
            landmark's first estimate; :mod:`.consistent_linearisation`); the innovation
            stays ``z - h(x)``; one linearisation (no iteration).
        invariant_kinds: Optional kinds of every landmark in the state: right-invariant
            update (:func:`invariant_retraction`, :func:`invariant_transport`; the
            covariance from the first linearisation).

    Returns:
        ``(P, NIS)``: the symmetrised covariance (a new array) and ``nu^T S^-1 nu`` (eq. 60)
        of the first linearisation (the prior innovation).

    Raises:
        numpy.linalg.LinAlgError: If ``S`` is not positive definite.
    """
    if index.size == 0:
        return p, 0.0
    cols = _landmark_cols(index)
    x0 = x
    x_prior = x.copy() if invariant_kinds is not None else x
    x_lin = x
    nis_value = 0.0
    if jacobian_state is not None or constrained_gain:
        # Gauss-Newton steps need the Jacobian at the iterate; with first-estimate or
        # constrained ones they are not (iterated, each ran the state off, to 1e12 m on
        # aces, on 11 of 24 Carmen runs), so these take one linearisation.
        max_iterations = 1
    for it in range(max(1, int(max_iterations))):
        zhat, hr, hf = observation_model(x_lin, index, kind)  # eq. 37
        nu = z - zhat  # eq. 36
        nu[:, 1] = _wrap(nu[:, 1])
        # FEJ-EKF (Huang, Mourikis, Roumeliotis, IJRR 2010, the FEJ-EKF section): H_k at
        # p_R(k|k-1) and each landmark's first estimate p_Li; OC-EKF (same paper): H* the
        # closest to H with H* N = 0 (:func:`constrain_jacobians`).
        if jacobian_state is not None:
            hr, hf = observation_model(jacobian_state, index, kind)[1:]
        elif nullspace is not None and constrained_gain:
            hr, hf = constrain_jacobians(hr, hf, nullspace)
        if it > 0:  # iterated EKF: nu_i = z - h(x_i) - H_i (x_0 - x_i)
            dx = x0 - x_lin
            dx[2] = _wrap(dx[2])
            nu -= hr @ dx[:3] + np.einsum('kij,kj->ki', hf, dx[cols])
        w1, low = _gain_factor(p, hr, hf, r, cols)
        y = solve_lower(low, nu.reshape(-1))
        if it == 0:
            nis_value = float(y @ y)
            if jacobian_state is not None or constrained_gain or invariant_kinds is not None:
                w1_cov = w1
            elif nullspace is not None:  # covariance: constrained Jacobians at the prior
                w1_cov = _gain_factor(p, *constrain_jacobians(hr, hf, nullspace), r, cols)[0]
        x_new = x0 + w1 @ y  # eqs. 32, 34
        x_new[2] = _wrap(x_new[2])
        if it + 1 >= max_iterations:
            break
        rel_old = _relative_points(x_lin, index, kind)
        move = _relative_points(x_new, index, kind) - rel_old
        if np.all(np.hypot(move[:, 0], move[:, 1])
                  <= relinearize_ratio * np.hypot(rel_old[:, 0], rel_old[:, 1])):
            break
        x_lin = x_new
    if invariant_kinds is not None:
        dx = x_new - x_prior
        dx[2] = _wrap(dx[2])
        x_new = invariant_retraction(x_prior, dx, invariant_kinds)
    x[:] = x_new
    if nullspace is None and jacobian_state is None and invariant_kinds is None:
        w1_cov = w1  # the last linearisation (the iterated EKF's covariance)
    p -= w1_cov @ w1_cov.T  # eq. 35 (in place: no fresh n x n allocation)
    if invariant_kinds is not None:
        p = invariant_transport(p, x_prior, x, invariant_kinds)
    return 0.5 * (p + p.T), nis_value


def _gain_factor(p: np.ndarray, hr: np.ndarray, hf: np.ndarray, r: np.ndarray,
                 cols: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``W1 = P H^T L^-T`` and ``L`` (``S = H P H^T + R = L L^T``, eq. 33)."""
    k, n = hr.shape[0], p.shape[0]
    rows = np.arange(k)
    hr2 = hr.reshape(2 * k, 3)
    # P H^T, (n, 2K): robot part plus each observation's landmark block.
    pht = p[:, :3] @ hr2.T
    p_cols = np.transpose(p[:, cols], (1, 0, 2))  # (K, n, 2)
    pht += np.transpose(p_cols @ np.transpose(hf, (0, 2, 1)), (1, 0, 2)).reshape(n, 2 * k)
    s = hr2 @ pht[:3] + (hf @ pht[cols]).reshape(2 * k, 2 * k)
    s4 = s.reshape(k, 2, k, 2)
    s4[rows, :, rows, :] += r
    s = 0.5 * (s + s.T)
    low = np.linalg.cholesky(s)
    return solve_lower(low, pht.T).T, low


def nearest_psd(p: np.ndarray) -> np.ndarray:
    """Nearest symmetric positive semi-definite matrix in the Frobenius norm (Higham 1988).

    Args:
        p: Square matrix.

    Returns:
        ``V max(L, 0) V^T`` of the eigen-decomposition of ``(P + P^T) / 2``.
    """
    w, v = np.linalg.eigh(0.5 * (p + p.T))
    out = (v * np.maximum(w, 0.0)) @ v.T
    return 0.5 * (out + out.T)


def is_psd(p: np.ndarray, tolerance: float = 1e-9) -> bool:
    """Test positive semi-definiteness by a Cholesky factorisation of ``P + eps I``.

    Args:
        p: Symmetric matrix.
        tolerance: ``eps`` relative to the largest diagonal entry.

    Returns:
        True if the factorisation succeeds (no eigenvalue below about ``-eps``).
    """
    if p.size == 0:
        return True
    if not np.all(np.isfinite(p)):
        return False
    eps = tolerance * max(float(np.max(np.abs(np.diag(p)))), 1e-300) + 1e-300
    q = p.T.copy(order='F')  # P symmetric: a plain memory copy in LAPACK order
    q.flat[::q.shape[0] + 1] += eps
    _, info = lapack().dpotrf(q, lower=1, clean=0, overwrite_a=1)  # far faster than numpy's
    return info == 0
