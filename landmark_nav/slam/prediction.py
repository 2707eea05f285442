"""EKF-SLAM state initialisation and prediction (corner chapter eqs. 12-13, 23-30).

The state layout is defined once, in :mod:`.ekf_slam`.

Odometry noise
--------------
* Odometry (:class:`OdometryNoise`): the increment ``u = [dx, dy, dpsi]`` (eq. 13) gets the
  diagonal covariance ``U = diag(s_xy^2 d, s_xy^2 d, s_yd^2 d + s_yr^2 |dpsi|)`` with
  ``d = |(dx, dy)|``: variances grow linearly with the distance travelled and the angle
  turned (standard deviations per sqrt(m) and per sqrt(rad)), each diagonal entry raised to
  a floor ``sigma_xy_floor^2`` / ``sigma_yaw_floor^2`` so ``U`` is never singular. The
  defaults follow the simulated Pioneer (:class:`landmark_nav.sim.RobotParams`): each wheel
  speed has a random error of std ``0.01 |omega| + 0.001 rad/s`` per 0.1 s step, so at the
  cruise speed of 0.35 m/s the travelled distance has 1.4 mm/sqrt(m) and the heading
  8.2 mrad/sqrt(m), turning in place at 45 deg/s 6.7 mrad/sqrt(rad); the error across the
  direction of travel is negligible. On top, the uncalibrated robot drifts systematically
  (``k1, k2, k3``: 0.014 rad per metre and 0.95 % of every turn). Defaults: 1.5 mm/sqrt(m)
  (the random distance noise), 0.01 rad/sqrt(m) and 0.01 rad/sqrt(rad) (the random heading
  noise plus the systematic drift over a few scans; over 20 s without landmarks the drift
  exceeds them).
"""

import math
from typing import Optional, Sequence, Tuple

from landmark_nav.geometry import compose_jacobians, relative, wrap_angle
import numpy as np

from ._linalg import _wrap
from .slam_params import OdometryNoise


def map_initialization(initial_pose: Sequence[float] = (0.0, 0.0, 0.0)
                       ) -> Tuple[np.ndarray, np.ndarray]:
    """Start the stochastic map at the robot pose with perfect knowledge (eqs. 23-24).

    Args:
        initial_pose: Robot pose at step 0 expressed in the caller's frame (the chapter's
            base reference B is the robot itself, ``[0, 0, 0]``).

    Returns:
        ``(x (3,), P (3, 3) zeros)``.
    """
    x = np.array(initial_pose, dtype=float).reshape(3)  # eq. 23
    if not np.all(np.isfinite(x)):
        raise ValueError(f'initial_pose must be finite, got {initial_pose!r}')
    x[2] = wrap_angle(x[2])
    return x, np.zeros((3, 3))  # eq. 24


def odometry_increment(odom_prev: Sequence[float], odom_now: Sequence[float]) -> np.ndarray:
    """Control input from two dead-reckoned poses, ``u = (-)x_o(k-1) (+) x_o(k)`` (eq. 13).

    Args:
        odom_prev: Odometry pose at k-1, [x, y, psi].
        odom_now: Odometry pose at k.

    Returns:
        (3,) increment in the robot frame at k-1.
    """
    return relative(odom_prev, odom_now)  # eq. 13


def odometry_noise(u: np.ndarray, noise: OdometryNoise) -> np.ndarray:
    """Covariance ``U`` of an odometry increment (module docstring, "Odometry noise").

    Args:
        u: (3,) increment [dx, dy, dpsi].
        noise: The noise parameters.

    Returns:
        (3, 3) diagonal covariance.
    """
    d = math.hypot(u[0], u[1])
    vxy = max(noise.sigma_xy_per_sqrt_m ** 2 * d, noise.sigma_xy_floor ** 2)
    vyaw = max(noise.sigma_yaw_per_sqrt_m ** 2 * d + noise.sigma_yaw_per_sqrt_rad ** 2
               * abs(u[2]), noise.sigma_yaw_floor ** 2)
    return np.diag([vxy, vxy, vyaw])


def ekf_predict(x: np.ndarray, p: np.ndarray, u: np.ndarray, u_cov: np.ndarray,
                lever_from: Optional[np.ndarray] = None) -> None:
    """Prediction with the odometry increment as control input (eqs. 25-30), in place.

    Args:
        x: (3 + 2N,) state, modified in place.
        p: (3 + 2N, 3 + 2N) covariance, modified in place.
        u: (3,) odometry increment (eq. 13).
        u_cov: (3, 3) its covariance ``U``.
        lever_from: Optional (2,) position the heading column of ``J1`` takes its lever arm
            from (observability-constrained: the previous prior,
            :mod:`.consistent_linearisation`); None: the current estimate (eq. 28).
    """
    j1, j2 = compose_jacobians(x[:3], u)  # eqs. 27-30 (eq. 28 sign typo fixed)
    c, s = math.cos(x[2]), math.sin(x[2])
    x[0] += u[0] * c - u[1] * s  # eq. 25 (x_r (+) u, eq. 16)
    x[1] += u[0] * s + u[1] * c
    x[2] = _wrap(x[2] + u[2])
    if lever_from is not None:  # Phi of the OC-EKF: lever arm from the previous prior
        j1[0, 2], j1[1, 2] = -(x[1] - lever_from[1]), x[0] - lever_from[0]
    # eq. 26 with J2 U J2^T (the chapter prints J1^T in the second term).
    p[:3, :3] = j1 @ p[:3, :3] @ j1.T + j2 @ u_cov @ j2.T
    if p.shape[0] > 3:
        p[:3, 3:] = j1 @ p[:3, 3:]  # eq. 12: static landmarks, cross terms follow J1
        p[3:, :3] = p[:3, 3:].T
    p[:3, :3] = 0.5 * (p[:3, :3] + p[:3, :3].T)


def odometry_check(prev_stamp_ns: int, prev_pose: Sequence[float], stamp_ns: int,
                   pose: Sequence[float], max_jump_m: float = 0.5,
                   max_jump_rad: float = 1.0) -> Optional[str]:
    """Check an odometry sample against the previous one before predicting with it.

    Args:
        prev_stamp_ns: Stamp of the previous odometry pose [ns].
        prev_pose: Previous odometry pose [x, y, psi].
        stamp_ns: Stamp of the new pose [ns].
        pose: New odometry pose.
        max_jump_m: Largest plausible translation between the two samples [m].
        max_jump_rad: Largest plausible rotation between them [rad].

    Returns:
        None if the increment can be used, else a message saying why the caller should
        :meth:`.ekf_slam.EkfSlam.reset` (time going backwards, a jump, non-finite values).
    """
    p0 = np.asarray(prev_pose, dtype=float)
    p1 = np.asarray(pose, dtype=float)
    if not (np.all(np.isfinite(p0)) and np.all(np.isfinite(p1))):
        return 'odometry pose is not finite'
    if stamp_ns < prev_stamp_ns:
        return f'odometry went back in time ({prev_stamp_ns} -> {stamp_ns} ns)'
    u = relative(p0, p1)
    d = math.hypot(u[0], u[1])
    if d > max_jump_m:
        return f'odometry jumped {d:.3f} m (> {max_jump_m} m)'
    if abs(u[2]) > max_jump_rad:
        return f'odometry turned {abs(u[2]):.3f} rad in one step (> {max_jump_rad} rad)'
    return None
