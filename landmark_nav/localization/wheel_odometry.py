"""Incremental wheel odometry with the calibration factors k1, k2, k3 and its covariance.

Source: Ivanjko, Kitanov, Petrovic (2010), section 2.1 and 3.1. Each sample of measured
wheel angular velocities ``(omega_L, omega_R)`` held for ``dt`` gives the control
``u = [D, dTheta]`` (eqs. 4-7 with eqs. 17-18: left / right wheel radius k1 R, k2 R, axle
k3 b; :func:`~.odometry.control_from_wheels`), and the pose moves along the mean heading
(eqs. 1-3; :func:`~.odometry.motion_model`).

Covariance: a distance-driven error model, the one :func:`landmark_nav.sim.robot.
propagate_covariance` uses for the simulated odometry. Per step, with the Jacobians
``F_x``, ``F_u`` of eqs. 1-3 (:func:`~.odometry.motion_jacobians`)::

    Q = diag(sD^2 |D|, sHD^2 |D| + sHR^2 |dTheta|)
    P(k+1) = F_x P(k) F_x^T + F_u Q F_u^T

so the variances grow linearly with the distance travelled and the angle turned
(``sD`` [m/sqrt(m)], ``sHD`` [rad/sqrt(m)], ``sHR`` [rad/sqrt(rad)]) and not at all while
the robot stands still.
"""

import math
from typing import Any, Optional, Sequence, Tuple

import numpy as np

from .odometry import control_from_poses, control_from_wheels, motion_jacobians, motion_model

__all__ = ['WheelOdometry']


class WheelOdometry:
    """Dead reckoning in the odometry frame from wheel speeds (or pose increments).

    Args:
        wheel_radius: Nominal R [m].
        axle_length: Nominal b [m].
        k: Calibration factors (k1, k2, k3); (1, 1, 1) = nominal model.
        sigma_distance: sD, distance std per sqrt(metre) [m/sqrt(m)].
        sigma_heading_per_distance: sHD, heading std per sqrt(metre) [rad/sqrt(m)].
        sigma_heading_per_rotation: sHR, heading std per sqrt(radian) turned.

    Attributes:
        pose: (3,) x [m], y [m], yaw [rad] in [-pi, pi).
        covariance: (3, 3) pose covariance.
        twist: (2,) v [m/s], w [rad/s] of the last sample.
        wheel_angles: (2,) accumulated measured wheel angles [rad] (left, right).
        wheel_speeds: (2,) last measured wheel angular velocities [rad/s].
        distance: Total distance travelled [m] (absolute values summed).
    """

    def __init__(self, wheel_radius: float, axle_length: float,
                 k: Sequence[float] = (1.0, 1.0, 1.0), sigma_distance: float = 0.05,
                 sigma_heading_per_distance: float = 0.05,
                 sigma_heading_per_rotation: float = 0.1) -> None:
        """Start at the origin with zero covariance."""
        values = (wheel_radius, axle_length, *k)
        if len(k) != 3 or not all(math.isfinite(v) and v > 0.0 for v in values):
            raise ValueError(f'wheel_radius, axle_length and k1..k3 must be finite and > 0; '
                             f'got {wheel_radius}, {axle_length}, {tuple(k)}')
        sigmas = (sigma_distance, sigma_heading_per_distance, sigma_heading_per_rotation)
        if not all(math.isfinite(s) and s >= 0.0 for s in sigmas):
            raise ValueError(f'odometry standard deviations must be finite and >= 0; got '
                             f'{sigmas}')
        self.wheel_radius = float(wheel_radius)
        self.axle_length = float(axle_length)
        self.k = tuple(float(v) for v in k)
        self.sigmas = tuple(float(s) for s in sigmas)
        self.reset()

    def reset(self, pose: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """Restart at ``pose`` with zero covariance, zero wheel angles and distance."""
        self.pose = np.asarray(pose, dtype=float).reshape(3).copy()
        self.covariance = np.zeros((3, 3))
        self.twist = np.zeros(2)
        self.wheel_angles = np.zeros(2)
        self.wheel_speeds = np.zeros(2)
        self.distance = 0.0

    def step_noise(self, u: Any) -> np.ndarray:
        """Return Q (2, 2) of one control ``u = [D, dTheta]`` (distance-driven)."""
        d, dth = abs(float(u[0])), abs(float(u[1]))
        s_d, s_hd, s_hr = self.sigmas
        return np.diag([s_d ** 2 * d, s_hd ** 2 * d + s_hr ** 2 * dth])

    def _apply(self, u: np.ndarray, dt: float) -> None:
        f_x, f_u = motion_jacobians(self.pose, u)
        p = f_x @ self.covariance @ f_x.T + f_u @ self.step_noise(u) @ f_u.T
        self.covariance = 0.5 * (p + p.T)
        self.pose = motion_model(self.pose, u)  # eqs. 1-3
        self.twist = np.asarray(u, dtype=float) / dt
        self.distance += abs(float(u[0]))

    def update_wheels(self, omega_left: float, omega_right: float, dt: float) -> np.ndarray:
        """Add one sample of measured wheel speeds [rad/s] held for ``dt`` [s]; return pose.

        Raises:
            ValueError: For a non-finite speed or a non-positive ``dt``.
        """
        speeds = np.array([omega_left, omega_right], dtype=float)
        if not (np.all(np.isfinite(speeds)) and math.isfinite(dt) and dt > 0.0):
            raise ValueError(f'wheel speeds {speeds.tolist()} and dt {dt} must be finite, '
                             'dt > 0')
        u = control_from_wheels(speeds, self.wheel_radius, self.axle_length, dt,
                                self.k)  # eqs. 4-7, 17-18
        self._apply(u, dt)
        self.wheel_speeds = speeds
        self.wheel_angles = self.wheel_angles + speeds * dt
        return self.pose

    def update_pose(self, new_pose: Sequence[float], dt: float,
                    wheel_speeds: Optional[Sequence[float]] = None) -> np.ndarray:
        """Move to ``new_pose`` given by another odometry (e.g. the robot's own), with covariance.

        The increment is taken as the control of eqs. 1-3 (:func:`~.odometry.
        control_from_poses`); the pose is set exactly to ``new_pose`` (yaw wrapped). Measured
        wheel speeds [rad/s], if given, are held for ``dt`` into the wheel angles.
        """
        new = np.asarray(new_pose, dtype=float).reshape(3)
        if not (np.all(np.isfinite(new)) and math.isfinite(dt) and dt > 0.0):
            raise ValueError(f'pose {new.tolist()} and dt {dt} must be finite, dt > 0')
        u = control_from_poses(self.pose, new)
        self._apply(u, dt)
        if wheel_speeds is not None:
            self.wheel_speeds = np.asarray(wheel_speeds, dtype=float).reshape(2)
            self.wheel_angles = self.wheel_angles + self.wheel_speeds * dt
        self.pose = new.copy()
        self.pose[2] = (self.pose[2] + math.pi) % (2.0 * math.pi) - math.pi
        return self.pose

    @property
    def state(self) -> Tuple[np.ndarray, np.ndarray]:
        """(pose copy, covariance copy)."""
        return self.pose.copy(), self.covariance.copy()
