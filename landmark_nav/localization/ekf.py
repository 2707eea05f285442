"""EKF pose tracking with sonars on an occupancy grid (section 4.2, eqs. 24-36).

State ``x = [x, y, Theta]``, covariance P (3, 3); see :mod:`landmark_nav.localization`.

Measurement function (eqs. 27-28, 33): the predicted reading of sonar i is the ray-cast
range of its beam (eqs. 21-23) to the first occupied cell ``p_i``. Eq. 27 writes this
range as the distance ``sqrt((x_i - x)^2 + (y_i - y)^2)`` to the hit point. Two Jacobians
``grad h_x`` are offered:

* ``'raycast'`` (default): central differences of the ray-cast range itself with respect
  to x, y, Theta (steps ``jac_step_xy``, ``jac_step_theta``), all sonars x all 2 x 3
  perturbed poses in one :func:`~.sonar_model.predict_ranges` call. The hit point moves
  along the wall when the robot moves, as it does for the real beam: a wall parallel to
  the motion gives no information on the motion direction. With a multi-ray lobe
  (``cone_rays > 1``) the prediction is the minimum over the lobe's rays, whose
  derivative is that of the ray attaining it: one call predicts the lobe at the state and
  reports that ray, a second one casts only it at the 6 perturbed poses
  (``jac_active_ray``; otherwise the whole lobe at all 7 poses in one call).
* ``'point'``: eq. 27 literally, ``p_i`` held fixed: the gradient of the distance from the
  sonar position (eqs. 21-22) to ``p_i``. This treats every wall hit as a point landmark
  and invents information along walls.

A reading whose perturbed predictions jump (its beam is near an edge or a corner of the
map: the second difference ``|h(x + d) + h(x - d) - 2 h(x)|`` exceeds ``jac_max_jump``)
has no usable derivative and is not used.
"""

from typing import Any, Dict, Tuple

import numpy as np

from .grid import GridMap
from .odometry import motion_jacobians, motion_model, process_noise
from .params import (accept_readings, LocalizationParams, prediction_kwargs,
                     usable_readings)
from .sonar_model import predict_ranges, sonar_global_poses
from ..geometry import wrap_angle


def symmetrize_psd(p: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """Return ``(P + P^T) / 2`` with eigenvalues below ``floor`` raised to it (PSD guard)."""
    p = 0.5 * (p + p.T)
    w, v = np.linalg.eigh(p)
    if w.min() < floor:
        p = (v * np.maximum(w, floor)) @ v.T
        p = 0.5 * (p + p.T)
    return p


def time_update(x: Any, p: Any, u: Any,
                params: LocalizationParams = LocalizationParams()) -> Tuple[np.ndarray,
                                                                            np.ndarray]:
    """EKF time update (prediction) with control ``u = [D, dTheta]`` (eqs. 29-30).

    Args:
        x: (3,) state estimate at k-1.
        p: (3, 3) its covariance.
        u: (2,) control input u_{k-1}.
        params: filter parameters (process noise Q, eq. 26).

    Returns:
        ``(x_prior (3,), P_prior (3, 3))``.
    """
    x = np.asarray(x, dtype=float)
    p = np.asarray(p, dtype=float)
    u = np.asarray(u, dtype=float)
    x_pri = motion_model(x, u, midpoint=params.midpoint)  # eq. 29
    f_x, f_u = motion_jacobians(x, u, midpoint=params.midpoint)
    q = process_noise(u, params.noise)  # eq. 26
    p_pri = f_x @ p @ f_x.T + f_u @ q @ f_u.T  # eq. 30
    return x_pri, symmetrize_psd(p_pri)


def measurement_prediction(grid: GridMap, x: Any, mounts: Any,
                           params: LocalizationParams = LocalizationParams()
                           ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted readings ``zhat`` (eq. 33) and the Jacobian ``grad h_x`` (eq. 27).

    Args:
        grid: the occupancy grid.
        x: (3,) predicted state.
        mounts: (S, 3) sonar poses in base_link.
        params: filter parameters (``jacobian`` mode and steps).

    Returns:
        ``(zhat (S,), H (S, 3), usable (S,) bool)``; ``zhat`` is nan where no prediction
        exists, ``usable`` is False where the Jacobian is undefined.
    """
    x = np.asarray(x, dtype=float)
    mounts = np.asarray(mounts, dtype=float).reshape(-1, 3)
    kw = prediction_kwargs(params)
    if params.jacobian == 'point':
        z_hat = predict_ranges(grid, x, mounts, **kw)[0]  # eq. 33
        s = sonar_global_poses(x, mounts)  # (S, 3)
        c, sn = np.cos(s[:, 2]), np.sin(s[:, 2])
        # eq. 27 with p_i = S + zhat (cos, sin) fixed: d/d(x, y) = -u, d/dTheta = -u . dS/dTheta
        h = np.stack([-c, -sn, c * (s[:, 1] - x[1]) - sn * (s[:, 0] - x[0])], axis=1)
        return z_hat, h, np.isfinite(z_hat)
    steps = np.array([params.jac_step_xy, params.jac_step_xy, params.jac_step_theta])
    n_pert = 6 if params.jac_central else 3
    poses = np.repeat(x[None, :], n_pert, axis=0)
    poses[0:3] += np.diag(steps)
    if params.jac_central:
        poses[3:6] -= np.diag(steps)
    if params.cone_rays > 1 and params.jac_active_ray:
        # The predicted reading is the minimum over the lobe's rays; its derivative is the
        # derivative of the ray attaining it (envelope), so only that ray is perturbed.
        z_hat, offs = predict_ranges(grid, x, mounts, return_ray=True, **kw)  # eq. 33
        z_hat, offs = z_hat[0], offs[0]
        r = np.full((n_pert, z_hat.size), np.nan)
        ok = np.isfinite(offs)
        if ok.any():
            r[:, ok] = predict_ranges(grid, poses, mounts[ok], ray_offsets=offs[ok],
                                      **kw)  # all sonars x perturbations, one call
    else:
        r_all = predict_ranges(grid, np.vstack([x, poses]), mounts, **kw)  # ONE call
        z_hat, r = r_all[0], r_all[1:]
    plus = r[0:3]
    minus = r[3:6] if params.jac_central else z_hat[None, :]
    base = 2.0 * steps if params.jac_central else steps
    with np.errstate(invalid='ignore'):
        h = ((plus - minus) / base[:, None]).T  # (S, 3), eq. 27 linearised
        # Discontinuity test: second difference (central) or first difference (forward).
        jump = np.abs(plus + minus - 2.0 * z_hat if params.jac_central
                      else plus - z_hat).max(axis=0)
        usable = (np.isfinite(z_hat) & np.isfinite(r).all(axis=0)
                  & (jump <= params.jac_max_jump))
    return z_hat, np.where(np.isfinite(h), h, 0.0), usable


def measurement_update(x_prior: Any, p_prior: Any, z: Any, grid: GridMap, mounts: Any,
                       params: LocalizationParams = LocalizationParams()
                       ) -> Tuple[np.ndarray, np.ndarray, Dict[str, Any]]:
    """EKF measurement update with one sonar cycle (eqs. 31-36), Joseph form.

    All accepted readings are stacked into one measurement vector (batch update). With no
    accepted reading the prior is returned (eqs. 31-32).

    Args:
        x_prior: (3,) predicted state.
        p_prior: (3, 3) predicted covariance.
        z: (S,) sonar readings [m] (``+inf`` no echo, ``-inf`` too close, ``nan`` missing).
        grid: the occupancy grid.
        mounts: (S, 3) sonar poses in base_link.
        params: filter parameters.

    Returns:
        ``(x (3,), P (3, 3), info)`` with ``info['accepted']`` (S,) bool,
        ``info['z_hat']`` (S,) predictions and ``info['innovation']`` (S,).
    """
    x_pri = np.asarray(x_prior, dtype=float)
    p_pri = np.asarray(p_prior, dtype=float)
    z = np.asarray(z, dtype=float).reshape(-1)
    mounts = np.asarray(mounts, dtype=float).reshape(-1, 3)
    # Only readings that can pass the acceptance test are predicted (saves ray casts).
    cand = np.flatnonzero(usable_readings(z, params))
    z_hat = np.full(z.shape, np.nan)
    h_all = np.zeros((z.size, 3))
    usable = np.zeros(z.shape, dtype=bool)
    if cand.size:
        z_hat[cand], h_all[cand], usable[cand] = measurement_prediction(
            grid, x_pri, mounts[cand], params)
    r_all = params.measurement_variance(np.where(np.isfinite(z), z, 0.0))
    s_diag = np.einsum('ij,jk,ik->i', h_all, p_pri, h_all) + r_all
    ok = accept_readings(z, z_hat, params, s_diag) & usable
    nu_all = z - z_hat
    info: Dict[str, Any] = {'accepted': ok, 'z_hat': z_hat, 'innovation': nu_all}
    if not ok.any():
        return x_pri.copy(), p_pri.copy(), info  # eqs. 31-32
    h = h_all[ok]
    r = np.diag(r_all[ok])
    nu = nu_all[ok]  # z_k - zhat_k^-
    s = h @ p_pri @ h.T + r
    k = np.linalg.solve(s, h @ p_pri).T  # eq. 36: P H^T S^-1 (S symmetric)
    x = x_pri + k @ nu  # eq. 34
    x[2] = wrap_angle(x[2])
    i_kh = np.eye(3) - k @ h
    p = i_kh @ p_pri @ i_kh.T + k @ r @ k.T  # eq. 35 in Joseph form
    return x, symmetrize_psd(p), info
