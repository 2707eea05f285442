"""UKF pose tracking with sonars on an occupancy grid (section 4.3, eqs. 37-54).

The process noise is not additive (it enters f through D and dTheta, eq. 25), so the state
is augmented with it: ``x^a = [x, y, Theta, v1, v2]``, ``L = 5`` (eqs. 37-38); the
measurement noise is additive and enters ``P_z`` directly (eq. 51). Sigma points come from
the lower Cholesky factor of ``P^a`` (eq. 41), scaled by ``gamma = sqrt(L + lambda)``,
``lambda = alpha^2 (L + kappa) - L`` (eqs. 39-40); defaults ``alpha = 1`` (see
:class:`~.params.LocalizationParams`), ``beta = 2``, ``kappa = 1``.

Angles: the mean of Theta over sigma points is the weighted circular mean
``atan2(sum W sin, sum W cos)``; Theta residuals are wrapped to [-pi, pi).

The measurement sigma points (eq. 49) are the ray-cast ranges of all 16 sonars at all
``2L + 1`` sigma points, in one :func:`~.sonar_model.predict_ranges` call. A sonar is used
only if every sigma point has a prediction, the acceptance test of
:func:`~.params.accept_readings` passes on the mean prediction (the chapter's corner /
outlier threshold, section 4.3), and its prediction is continuous around the prior mean:
the same discontinuity test as the EKF's (:func:`~.ekf.measurement_prediction`, second
difference over +-``jac_step_xy`` / +-``jac_step_theta`` at most ``jac_max_jump``). Without
that test a reading whose lobe straddles an edge, a corner or a niche opening is used, and
the sigma point that crosses the edge (its range jumps by up to a metre) is read as a steep
slope by eqs. 51-52: strong, wrong information along the hallway.

Map noise (departure from the chapter): the occupancy grid places every surface only to
within its cell, a position error uniform over the cell, std ``sigma_m = res / sqrt(12)``
in x and in y (``LocalizationParams.map_sigma`` overrides it). It is not additive in the
range (a range changes with it as fast as with the robot's position: little on a wall seen
head-on, a lot near an edge), so, like the process noise, it enters through augmentation:
the measurement sigma points are drawn from ``[x, y, Theta, m_x, m_y]`` with covariance
``diag(P^-, sigma_m^2, sigma_m^2)`` (again L = 5, the same weights), and each is predicted at
the pose shifted by ``(m_x, m_y)`` (a shift of the map against the robot, common to the
readings of one cycle). Without it the state sigma points, +-sqrt(6) sigma = +-2.4 cm apart
along the hallway, resolve the grid's structure below its cell, which the map does not
define; with it they sample the map over +-7 cm, about one cell. ``map_sigma = 0`` gives
the chapter's UKF: the propagated sigma points X_{k|k-1} are used (eq. 49) and R alone
enters P_z (eq. 51).
"""

import math
from typing import Any, Dict, Optional, Tuple

import numpy as np

from . import ekf
from .grid import GridMap
from .odometry import motion_model, process_noise
from .params import (accept_readings, LocalizationParams, prediction_kwargs,
                     usable_readings)
from .sonar_model import predict_ranges
from ..geometry import wrap_angle

#: Dimension of the augmented state (x, y, Theta, v1, v2).
L_AUG = 5
#: Index of the heading in the state.
THETA = 2


def weights(n: int = L_AUG, alpha: float = 1.0, beta: float = 2.0,
            kappa: float = 1.0) -> Tuple[np.ndarray, np.ndarray, float]:
    """Sigma-point weights and scale (eqs. 39-40, 44-45, 47-48).

    Args:
        n: dimension L of the (augmented) state.
        alpha: spread, in [1e-4, 1].
        beta: prior-knowledge parameter (2 for Gaussians).
        kappa: secondary scaling (usually 1).

    Returns:
        ``(W_m (2L+1,), W_c (2L+1,), gamma)``.
    """
    lam = alpha ** 2 * (n + kappa) - n  # eq. 40
    gamma = float(np.sqrt(n + lam))  # eq. 39
    w_m = np.full(2 * n + 1, 1.0 / (2.0 * (n + lam)))  # eq. 45
    w_c = w_m.copy()  # eq. 48
    w_m[0] = lam / (n + lam)  # eq. 44
    w_c[0] = lam / (n + lam) + (1.0 - alpha ** 2 + beta)  # eq. 47
    return w_m, w_c, gamma


def _sqrt_psd(p: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor; eigen-decomposition square root for singular P (e.g. Q = 0)."""
    try:
        return np.linalg.cholesky(p)
    except np.linalg.LinAlgError:
        w, v = np.linalg.eigh(0.5 * (p + p.T))
        return v * np.sqrt(np.maximum(w, 0.0))


def sigma_points(mean: Any, cov: Any, gamma: float) -> np.ndarray:
    """Sigma points ``[m, m + gamma sqrt(P), m - gamma sqrt(P)]`` (eq. 41).

    Args:
        mean: (n,) mean.
        cov: (n, n) covariance.
        gamma: scale (eq. 39).

    Returns:
        (2n+1, n) points, one per row.
    """
    m = np.asarray(mean, dtype=float)
    a = gamma * _sqrt_psd(np.asarray(cov, dtype=float))
    return np.vstack([m, m + a.T, m - a.T])


def unscented_mean(points: np.ndarray, w_m: np.ndarray,
                   angular: Optional[int] = THETA) -> np.ndarray:
    """Weighted mean of sigma points (eqs. 43, 50), circular for column ``angular``."""
    mean = w_m @ points
    if angular is not None:
        a = points[:, angular]
        mean[angular] = np.arctan2(w_m @ np.sin(a), w_m @ np.cos(a))
    return mean


def residuals(points: np.ndarray, mean: np.ndarray,
              angular: Optional[int] = THETA) -> np.ndarray:
    """Sigma point minus mean, the ``angular`` column wrapped to [-pi, pi)."""
    d = points - mean
    if angular is not None:
        d[:, angular] = wrap_angle(d[:, angular])
    return d


def unscented_transform(points: np.ndarray, w_m: np.ndarray, w_c: np.ndarray,
                        angular: Optional[int] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of transformed sigma points (eqs. 43, 46).

    Args:
        points: (2n+1, m) transformed sigma points.
        w_m: mean weights.
        w_c: covariance weights.
        angular: index of an angle column (circular mean, wrapped residuals), or None.

    Returns:
        ``(mean (m,), cov (m, m))``.
    """
    mean = unscented_mean(points, w_m, angular)
    d = residuals(points, mean, angular)
    return mean, (w_c[:, None] * d).T @ d


def _weights(params: LocalizationParams) -> Tuple[np.ndarray, np.ndarray, float]:
    return weights(L_AUG, params.ukf_alpha, params.ukf_beta, params.ukf_kappa)


def _psd(p: np.ndarray) -> np.ndarray:
    p = 0.5 * (p + p.T)
    w, v = np.linalg.eigh(p)
    if w.min() < 0.0:
        p = (v * np.maximum(w, 0.0)) @ v.T
        p = 0.5 * (p + p.T)
    return p


def time_update(x: Any, p: Any, u: Any, params: LocalizationParams = LocalizationParams()
                ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """UKF time update with control ``u = [D, dTheta]`` (eqs. 37-46).

    Args:
        x: (3,) state estimate at k-1.
        p: (3, 3) its covariance.
        u: (2,) control input u_{k-1}.
        params: filter parameters (process noise Q, eq. 26; alpha, beta, kappa).

    Returns:
        ``(x_prior (3,), P_prior (3, 3), X (2L+1, 3))``, X the propagated state sigma
        points ``X^x_{k|k-1}``, used again by :func:`measurement_update` (eq. 49) when the
        map noise is off.
    """
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float)
    q = process_noise(u, params.noise)  # eq. 26
    x_a = np.concatenate([x, np.zeros(2)])  # eq. 37, E{v} = 0
    p_a = np.zeros((L_AUG, L_AUG))  # eq. 38
    p_a[:3, :3] = p
    p_a[3:, 3:] = q
    w_m, w_c, gamma = _weights(params)
    chi = sigma_points(x_a, p_a, gamma)  # eqs. 39-41
    chi[:, THETA] = wrap_angle(chi[:, THETA])
    x_sig = motion_model(chi[:, :3], u, chi[:, 3:], midpoint=params.midpoint)  # eq. 42
    x_pri, p_pri = unscented_transform(x_sig, w_m, w_c, THETA)  # eqs. 43-48
    return x_pri, _psd(p_pri), x_sig


def state_sigma_points(x: Any, p: Any, params: LocalizationParams = LocalizationParams()
                       ) -> np.ndarray:
    """State sigma points of ``(x, P)`` with the L = 5 weights and zero noise (no motion).

    Used for a measurement update that is not preceded by a time update (the first cycle).
    """
    p_a = np.zeros((L_AUG, L_AUG))
    p_a[:3, :3] = np.asarray(p, dtype=float)
    chi = sigma_points(np.concatenate([np.asarray(x, dtype=float), np.zeros(2)]), p_a,
                       _weights(params)[2])
    chi[:, THETA] = wrap_angle(chi[:, THETA])
    return chi[:, :3]


def map_noise_std(grid: GridMap, params: LocalizationParams = LocalizationParams()) -> float:
    """Std of the map's surface positions in x and y [m]: ``map_sigma`` or ``res / sqrt(12)``."""
    if params.map_sigma is not None:
        return float(params.map_sigma)
    return float(grid.resolution) / math.sqrt(12.0)


def measurement_sigma_points(x: Any, p: Any, map_std: float,
                             params: LocalizationParams = LocalizationParams()
                             ) -> Tuple[np.ndarray, np.ndarray]:
    """Sigma points of the state augmented with the map noise (see the module docstring).

    Args:
        x: (3,) prior mean.
        p: (3, 3) prior covariance.
        map_std: std ``sigma_m`` of the map offset in x and in y [m].
        params: filter parameters (alpha, beta, kappa).

    Returns:
        ``(X (2L+1, 3), poses (2L+1, 3))``: the state sigma points and the poses at which
        the readings are predicted (``X`` shifted by the map offset ``(m_x, m_y)``).
    """
    p_a = np.zeros((L_AUG, L_AUG))
    p_a[:3, :3] = np.asarray(p, dtype=float)
    p_a[3, 3] = p_a[4, 4] = map_std ** 2
    chi = sigma_points(np.concatenate([np.asarray(x, dtype=float), np.zeros(2)]), p_a,
                       _weights(params)[2])  # eqs. 39-41 with [x, m] in place of [x, v]
    chi[:, THETA] = wrap_angle(chi[:, THETA])
    poses = chi[:, :3].copy()
    poses[:, :2] += chi[:, 3:]
    return chi[:, :3], poses


def measurement_update(x_prior: Any, p_prior: Any, x_sigma: Optional[np.ndarray], z: Any,
                       grid: GridMap, mounts: Any,
                       params: LocalizationParams = LocalizationParams()
                       ) -> Tuple[np.ndarray, np.ndarray, Dict[str, Any]]:
    """UKF measurement update with one sonar cycle (eqs. 49-54, 34).

    Args:
        x_prior: (3,) prior mean.
        p_prior: (3, 3) prior covariance.
        x_sigma: (2L+1, 3) propagated sigma points from :func:`time_update`, used when
            the map noise is off (``map_sigma = 0``); None = draw them from the prior
            (:func:`state_sigma_points`). With map noise the sigma points are drawn from
            the prior augmented with it (:func:`measurement_sigma_points`).
        z: (S,) sonar readings [m] (``+inf`` no echo, ``-inf`` too close, ``nan`` missing).
        grid: the occupancy grid.
        mounts: (S, 3) sonar poses in base_link.
        params: filter parameters.

    Returns:
        ``(x (3,), P (3, 3), info)`` with ``info['accepted']`` (S,) bool,
        ``info['z_hat']`` (S,) mean predictions, ``info['innovation']`` (S,).
    """
    x_pri = np.asarray(x_prior, dtype=float)
    p_pri = np.asarray(p_prior, dtype=float)
    z = np.asarray(z, dtype=float).reshape(-1)
    map_std = map_noise_std(grid, params)
    if map_std > 0.0:
        x_sigma, poses = measurement_sigma_points(x_pri, p_pri, map_std, params)
    else:
        if x_sigma is None:
            x_sigma = state_sigma_points(x_pri, p_pri, params)
        poses = x_sigma
    w_m, w_c, _ = _weights(params)
    mounts = np.asarray(mounts, dtype=float).reshape(-1, 3)
    # Only readings that can pass the acceptance test are predicted (saves ray casts).
    cand = np.flatnonzero(usable_readings(z, params))
    zs = np.full((x_sigma.shape[0], z.size), np.nan)
    smooth = np.zeros(z.size, dtype=bool)
    if cand.size:
        zs[:, cand] = predict_ranges(grid, poses, mounts[cand],
                                     **prediction_kwargs(params))  # eq. 49, one call
        # The EKF's discontinuity test (edges, corners: no usable derivative, no Gaussian).
        smooth[cand] = ekf.measurement_prediction(grid, x_pri, mounts[cand], params)[2]
    complete = np.isfinite(zs).all(axis=0) & smooth
    zs = np.where(complete, zs, 0.0)
    z_hat = w_m @ zs  # eq. 50
    z_hat = np.where(complete, z_hat, np.nan)
    dz_all = zs - np.where(complete, z_hat, 0.0)
    r_all = params.measurement_variance(np.where(np.isfinite(z), z, 0.0))
    s_diag = w_c @ dz_all ** 2 + r_all
    ok = accept_readings(z, z_hat, params, s_diag) & complete
    info: Dict[str, Any] = {'accepted': ok, 'z_hat': z_hat, 'innovation': z - z_hat}
    if not ok.any():
        return x_pri.copy(), p_pri.copy(), info  # eqs. 31-32
    dz = dz_all[:, ok]
    dx = residuals(x_sigma, x_pri, THETA)
    p_z = (w_c[:, None] * dz).T @ dz + np.diag(r_all[ok])  # eq. 51
    p_xz = (w_c[:, None] * dx).T @ dz  # eq. 52
    k = np.linalg.solve(p_z, p_xz.T).T  # eq. 53: P_xz P_z^-1 (P_z symmetric)
    x = x_pri + k @ (z[ok] - z_hat[ok])  # eq. 34
    x[THETA] = wrap_angle(x[THETA])
    p = p_pri - k @ p_z @ k.T  # eq. 54
    return x, _psd(p), info
