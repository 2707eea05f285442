"""Calibrated odometry as the motion model: control input, f, Jacobians, process noise Q.

Control input ``u = [D, dTheta]`` (section 4.2): the distance travelled and the rotation
during one sampling period, from the measured wheel speeds with the calibration factors
(eqs. 4-7, 17-18) or from two successive odometry poses.

Motion model (eqs. 24-25): the process noise ``v = [v1, v2]`` is added to ``D`` and
``dTheta``. Eq. 25 as printed puts the whole rotation before the translation,
``cos(Theta + dTheta + v2)``, while the kinematic model it is derived from, eqs. 1-3, moves
along the mean heading ``Theta + dTheta / 2`` (the same model the robot's odometry and the
simulator use). We keep eqs. 1-3::

    f(x, u, v) = [x + (D + v1) cos(Theta + (dTheta + v2) / 2),
                  y + (D + v1) sin(Theta + (dTheta + v2) / 2),
                  Theta + dTheta + v2]

(``midpoint=False`` gives the printed eq. 25 exactly).
"""

from dataclasses import dataclass
from typing import Any, Tuple

import numpy as np

from ..geometry import wrap_angle


@dataclass(frozen=True)
class ProcessNoise:
    """Parameters of the process noise covariance Q (eq. 26 and two documented extensions).

    Eq. 26: ``Q = diag(sigma_D^2, dTheta^2 sigma_dTheta^2)``, i.e. a constant variance of
    the travelled distance per step and a rotation variance proportional to the squared
    rotation. With only these terms a straight drive (``dTheta = 0``) has no heading noise
    at all, although wheel-speed noise turns the robot randomly; the two extension terms
    add variance proportional to the squared step distance (set them to 0 for the chapter's
    Q exactly)::

        Q = diag(sigma_D^2 + (k_D D)^2, dTheta^2 sigma_dTheta^2 + (k_Theta D)^2)

    Attributes:
        sigma_d: sigma_D, std of D per step [m] (eq. 26).
        sigma_dtheta: sigma_dTheta, relative std of dTheta [-] (eq. 26).
        k_d: extension, std of D per metre travelled in the step [-].
        k_theta: extension, heading std per metre travelled in the step [rad/m].
    """

    sigma_d: float = 0.002
    sigma_dtheta: float = 0.05
    k_d: float = 0.02
    k_theta: float = 0.05


def control_from_wheels(wheel_velocities: Any, wheel_radius: float, axle_length: float,
                        sample_time: float,
                        k: Tuple[float, float, float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """Control input(s) ``u = [D, dTheta]`` from measured wheel speeds (eqs. 4-7, 17-18).

    Args:
        wheel_velocities: (..., 2) measured ``(omega_L, omega_R)`` [rad/s].
        wheel_radius: nominal R [m].
        axle_length: nominal b [m].
        sample_time: T [s].
        k: calibration factors ``(k1, k2, k3)``; ``(1, 1, 1)`` = nominal model.

    Returns:
        (..., 2) ``[D, dTheta]`` [m, rad].
    """
    w = np.asarray(wheel_velocities, dtype=float)
    vl = k[0] * w[..., 0] * wheel_radius
    vr = k[1] * w[..., 1] * wheel_radius
    v_t = 0.5 * (vl + vr)  # eqs. 6 / 17
    omega = (vr - vl) / (k[2] * axle_length)  # eqs. 7 / 18
    return np.stack([v_t * sample_time, omega * sample_time], axis=-1)  # eqs. 4-5


def control_from_poses(pose_a: Any, pose_b: Any, midpoint: bool = True) -> np.ndarray:
    """Control input(s) ``u = [D, dTheta]`` that move ``pose_a`` to ``pose_b`` under f.

    Inverts eqs. 1-3 (or eq. 25 with ``midpoint=False``); ``D`` is negative for a
    backwards step.

    Args:
        pose_a: (..., 3) odometry pose at k.
        pose_b: (..., 3) odometry pose at k + 1.
        midpoint: True for eqs. 1-3, False for eq. 25 as printed.

    Returns:
        (..., 2) ``[D, dTheta]``.
    """
    a = np.asarray(pose_a, dtype=float)
    b = np.asarray(pose_b, dtype=float)
    dth = wrap_angle(b[..., 2] - a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    head = a[..., 2] + (0.5 * dth if midpoint else dth)
    d = dx * np.cos(head) + dy * np.sin(head)  # signed distance along the motion heading
    return np.stack([d, np.broadcast_to(dth, np.shape(d))], axis=-1)


def motion_model(x: Any, u: Any, v: Any = None, midpoint: bool = True) -> np.ndarray:
    """State transition f(x, u, v) (eqs. 1-3 / 24-25), vectorised over leading axes.

    Args:
        x: (..., 3) state(s) ``[x, y, Theta]``.
        u: (..., 2) control ``[D, dTheta]`` (broadcasts against ``x``).
        v: (..., 2) process noise ``[v1, v2]`` (default 0 = its mean, eq. 29).
        midpoint: heading of the translation: ``Theta + dTheta / 2`` (eqs. 1-3, default)
            or ``Theta + dTheta`` (eq. 25 as printed).

    Returns:
        (..., 3) next state, Theta wrapped to [-pi, pi).
    """
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float)
    d = u[..., 0]
    dth = u[..., 1]
    if v is not None:
        v = np.asarray(v, dtype=float)
        d = d + v[..., 0]
        dth = dth + v[..., 1]
    head = x[..., 2] + (0.5 * dth if midpoint else dth)
    nx = x[..., 0] + d * np.cos(head)  # eq. 1 / 25 row 1
    ny = x[..., 1] + d * np.sin(head)  # eq. 2 / 25 row 2
    nth = wrap_angle(x[..., 2] + dth)  # eq. 3 / 25 row 3
    nx, ny, nth = np.broadcast_arrays(nx, ny, nth)
    return np.stack([nx, ny, nth], axis=-1)


def motion_jacobians(x: Any, u: Any, midpoint: bool = True) -> Tuple[np.ndarray, np.ndarray]:
    """Jacobians of f at ``v = 0`` with respect to the state and the control (eq. 30).

    Since v is added to u, the Jacobian with respect to v equals the one with respect to u.

    Args:
        x: (3,) state.
        u: (2,) control ``[D, dTheta]``.
        midpoint: as in :func:`motion_model`.

    Returns:
        ``(F_x (3, 3), F_u (3, 2))``.
    """
    x = np.asarray(x, dtype=float)
    d, dth = float(u[0]), float(u[1])
    c_half = 0.5 if midpoint else 1.0
    head = x[2] + c_half * dth
    c, s = np.cos(head), np.sin(head)
    f_x = np.array([[1.0, 0.0, -d * s],
                    [0.0, 1.0, d * c],
                    [0.0, 0.0, 1.0]])
    f_u = np.array([[c, -c_half * d * s],
                    [s, c_half * d * c],
                    [0.0, 1.0]])
    return f_x, f_u


def process_noise(u: Any, noise: ProcessNoise = ProcessNoise()) -> np.ndarray:
    """Process noise covariance Q_k of ``v = [v1, v2]`` (eq. 26 + extensions, see ProcessNoise).

    Args:
        u: (2,) control ``[D, dTheta]``.
        noise: parameters.

    Returns:
        (2, 2) diagonal Q.
    """
    d, dth = float(u[0]), float(u[1])
    q_d = noise.sigma_d ** 2 + (noise.k_d * d) ** 2  # eq. 26 (1, 1) + extension
    q_th = dth ** 2 * noise.sigma_dtheta ** 2 + (noise.k_theta * d) ** 2  # eq. 26 (2, 2) + ext.
    return np.diag([q_d, q_th])


def dead_reckoning(pose0: Any, controls: Any, midpoint: bool = True) -> np.ndarray:
    """Integrate controls (T-1, 2) from ``pose0`` with f at ``v = 0`` (odometry alone).

    Returns:
        (T, 3) poses, Theta wrapped.
    """
    u = np.asarray(controls, dtype=float).reshape(-1, 2)
    out = np.empty((u.shape[0] + 1, 3))
    out[0] = np.asarray(pose0, dtype=float)
    out[0, 2] = wrap_angle(out[0, 2])
    for k in range(u.shape[0]):
        out[k + 1] = motion_model(out[k], u[k], midpoint=midpoint)
    return out


def calibrate_control(u_nominal: Any, axle_length: float,
                      k: Tuple[float, float, float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """Apply calibration factors to control input(s) of the nominal model (eqs. 17-18).

    A nominal odometry increment ``[D, dTheta]`` (eqs. 4-7 with k = 1, e.g. from two
    successive poses of an uncalibrated odometry topic, :func:`control_from_poses`) is
    split into the wheel arc lengths ``s_L = D - b dTheta / 2``, ``s_R = D + b dTheta / 2``,
    which are then recombined with ``k1 R``, ``k2 R``, ``k3 b``. Equals
    :func:`control_from_wheels` with ``k`` on the wheel speeds behind the nominal increment.

    Args:
        u_nominal: (..., 2) nominal ``[D, dTheta]`` [m, rad].
        axle_length: nominal b [m].
        k: calibration factors ``(k1, k2, k3)``.

    Returns:
        (..., 2) calibrated ``[D, dTheta]``.
    """
    u = np.asarray(u_nominal, dtype=float)
    s_l = u[..., 0] - 0.5 * axle_length * u[..., 1]
    s_r = u[..., 0] + 0.5 * axle_length * u[..., 1]
    d = 0.5 * (k[0] * s_l + k[1] * s_r)  # eqs. 4, 17
    dth = (k[1] * s_r - k[0] * s_l) / (k[2] * axle_length)  # eqs. 5, 18
    return np.stack([d, dth], axis=-1)
