"""Differential-drive robot: kinematics (eqs. 1-7), systematic error (eqs. 17-18), odometry.

Source: Ivanjko, Kitanov, Petrovic (2010), section 2.1 and 3.1. The discrete model with
sampling time T (0.1 s in the chapter) is::

    x(k+1) = x(k) + D cos(th(k) + dth/2)                  # eq. 1
    y(k+1) = y(k) + D sin(th(k) + dth/2)                  # eq. 2
    th(k+1) = th(k) + dth                                 # eq. 3
    D = v T,  dth = w T                                   # eqs. 4-5
    v = (wL R + wR R) / 2,  w = (wR R - wL R) / b         # eqs. 6-7

Systematic error: the TRUE robot moves with left/right wheel radii k1 R, k2 R and axle k3 b
(eqs. 17-18); the encoders report the wheel angular velocities; dead-reckoning odometry uses
the nominal R, b (k = 1). Random error: zero-mean Gaussian on the measured wheel speeds with
std ``a |w| + c`` (eqs. 8-9 style), optionally followed by encoder quantisation.
"""

from dataclasses import asdict, dataclass, fields
import math
import numbers
from typing import Any, Dict, Optional, Tuple

import numpy as np

from .world import wrap_angle

NS_PER_S = 1_000_000_000


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class RobotParams:
    """Robot, error-model and motion-limit parameters (SI units, radians).

    Attributes:
        wheel_radius: nominal drive wheel radius R [m] (Pioneer 2-DX: 0.0955).
        axle_length: nominal axle length b [m] (Pioneer 2-DX: 0.330).
        k1: true left wheel radius factor (eq. 17), chapter value 0.9977.
        k2: true right wheel radius factor (eq. 17), chapter value 1.0023.
        k3: true axle length factor (eq. 18), chapter value 1.0095.
        sample_time: T [s], odometry / control period (chapter: 0.1 s).
        wheel_noise_gain: a, relative std of the measured wheel speed noise [-].
        wheel_noise_floor: c, absolute std floor of the wheel speed noise [rad/s].
        encoder_ticks_per_rev: encoder quantisation of the wheel angle, 0 = off.
        odom_sigma_distance: std of the travelled distance per sqrt(metre) [m/sqrt(m)].
        odom_sigma_heading_per_distance: heading std per sqrt(metre) [rad/sqrt(m)].
        odom_sigma_heading_per_rotation: heading std per sqrt(radian) turned [rad/sqrt(rad)].
        max_linear_speed: controller limit [m/s].
        max_angular_speed: controller limit [rad/s].
        max_linear_accel: controller limit [m/s^2].
        max_angular_accel: controller limit [rad/s^2].
    """

    wheel_radius: float = 0.0955
    axle_length: float = 0.330
    k1: float = 0.9977
    k2: float = 1.0023
    k3: float = 1.0095
    sample_time: float = 0.1
    wheel_noise_gain: float = 0.01
    wheel_noise_floor: float = 0.001
    encoder_ticks_per_rev: int = 0
    odom_sigma_distance: float = 0.05
    odom_sigma_heading_per_distance: float = 0.05
    odom_sigma_heading_per_rotation: float = 0.1
    max_linear_speed: float = 0.35
    max_angular_speed: float = math.radians(45.0)
    max_linear_accel: float = 0.3
    max_angular_accel: float = math.radians(90.0)

    def __post_init__(self) -> None:
        """Validate the parameters."""
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
                raise ValueError(f'RobotParams.{f.name} must be a finite number, got {v!r}')
        positive = ('wheel_radius', 'axle_length', 'k1', 'k2', 'k3', 'sample_time',
                    'max_linear_speed', 'max_angular_speed', 'max_linear_accel',
                    'max_angular_accel')
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise ValueError(f'RobotParams.{name} must be > 0')
        for name in ('wheel_noise_gain', 'wheel_noise_floor', 'encoder_ticks_per_rev',
                     'odom_sigma_distance', 'odom_sigma_heading_per_distance',
                     'odom_sigma_heading_per_rotation'):
            if getattr(self, name) < 0:
                raise ValueError(f'RobotParams.{name} must be >= 0')
        if int(self.encoder_ticks_per_rev) != self.encoder_ticks_per_rev:
            raise ValueError('RobotParams.encoder_ticks_per_rev must be an integer')
        if abs(self.sample_time * NS_PER_S - round(self.sample_time * NS_PER_S)) > 1e-3:
            raise ValueError('RobotParams.sample_time must be a whole number of nanoseconds')

    @property
    def step_ns(self) -> int:
        """Sampling time T in integer nanoseconds."""
        return int(round(self.sample_time * NS_PER_S))

    def to_dict(self) -> Dict[str, Any]:
        """Plain dict of all fields (floats / ints)."""
        d = asdict(self)
        d['encoder_ticks_per_rev'] = int(d['encoder_ticks_per_rev'])
        return {k: (float(v) if k != 'encoder_ticks_per_rev' else v) for k, v in d.items()}

    @classmethod
    def from_dict(cls, data: Dict[str, Any]) -> 'RobotParams':
        """Build from a (possibly partial) dict; unknown keys raise ValueError."""
        names = {f.name for f in fields(cls)}
        bad = sorted(set(data) - names)
        if bad:
            raise ValueError(f'unknown RobotParams field(s) {bad}; valid: {sorted(names)}')
        return cls(**data)


# ---------------------------------------------------------------------- kinematics
def wheel_to_twist(omega_l: Any, omega_r: Any, radius_left: float, radius_right: float,
                   axle: float) -> Tuple[np.ndarray, np.ndarray]:
    """Wheel angular velocities [rad/s] to body twist ``(v, w)`` (eqs. 6-7, 17-18)."""
    vl = np.asarray(omega_l, dtype=float) * radius_left
    vr = np.asarray(omega_r, dtype=float) * radius_right
    return 0.5 * (vl + vr), (vr - vl) / axle  # eq. 6 / 17, eq. 7 / 18


def twist_to_wheels(v: Any, w: Any, radius: float, axle: float) -> Tuple[np.ndarray, np.ndarray]:
    """Inverse of eqs. 6-7 with equal radii: body twist to ``(omega_l, omega_r)`` [rad/s]."""
    v = np.asarray(v, dtype=float)
    w = np.asarray(w, dtype=float)
    return (v - 0.5 * axle * w) / radius, (v + 0.5 * axle * w) / radius


def step_pose(pose: Any, v: Any, w: Any, dt: Any) -> np.ndarray:
    """Advance pose(s) ``[..., 3]`` with constant ``(v, w)`` for ``dt`` seconds (eqs. 1-5).

    ``dt`` may be a fraction of the sampling time (truth inside a step).
    """
    p = np.asarray(pose, dtype=float)
    d = np.asarray(v, dtype=float) * dt  # eq. 4
    dth = np.asarray(w, dtype=float) * dt  # eq. 5
    mid = p[..., 2] + 0.5 * dth
    return np.stack([p[..., 0] + d * np.cos(mid),  # eq. 1
                     p[..., 1] + d * np.sin(mid),  # eq. 2
                     p[..., 2] + dth], axis=-1)  # eq. 3


def integrate(pose0: Any, v: Any, w: Any, dt: float) -> np.ndarray:
    """Integrate eqs. 1-5 over n steps (vectorised); returns (n+1, 3), yaw unwrapped."""
    v = np.asarray(v, dtype=float).reshape(-1)
    w = np.asarray(w, dtype=float).reshape(-1)
    p0 = np.asarray(pose0, dtype=float).reshape(3)
    d = v * dt  # eq. 4
    dth = w * dt  # eq. 5
    th = np.concatenate([[p0[2]], p0[2] + np.cumsum(dth)])  # eq. 3
    mid = th[:-1] + 0.5 * dth
    x = np.concatenate([[p0[0]], p0[0] + np.cumsum(d * np.cos(mid))])  # eq. 1
    y = np.concatenate([[p0[1]], p0[1] + np.cumsum(d * np.sin(mid))])  # eq. 2
    return np.stack([x, y, th], axis=1)


def propagate_covariance(poses: np.ndarray, v: np.ndarray, w: np.ndarray, dt: float,
                         params: RobotParams,
                         cov0: Optional[np.ndarray] = None) -> np.ndarray:
    """Propagate the odometry pose covariance through the Jacobians of eqs. 1-3.

    Per step, with D = v T and dth = w T (eqs. 4-5) and phi = th + dth/2::

        F = d(x,y,th)(k+1)/d(x,y,th)(k) = [[1, 0, -D sin phi], [0, 1, D cos phi], [0, 0, 1]]
        G = d(x,y,th)(k+1)/d(D, dth)    = [[cos phi, -D/2 sin phi], [sin phi, D/2 cos phi],
                                           [0, 1]]
        Q = diag(sD^2 |D|, sHD^2 |D| + sHR^2 |dth|)
        P(k+1) = F P(k) F^T + G Q G^T

    with sD, sHD, sHR = ``odom_sigma_distance``, ``odom_sigma_heading_per_distance``,
    ``odom_sigma_heading_per_rotation`` (variance grows linearly with distance / rotation,
    independent of the step size). Returns (n+1, 3, 3).
    """
    n = v.shape[0]
    d = v * dt
    dth = w * dt
    phi = poses[:-1, 2] + 0.5 * dth
    c, s = np.cos(phi), np.sin(phi)
    qd = params.odom_sigma_distance ** 2 * np.abs(d)
    qt = (params.odom_sigma_heading_per_distance ** 2 * np.abs(d)
          + params.odom_sigma_heading_per_rotation ** 2 * np.abs(dth))
    # Noise term G Q G^T for every step (vectorised).
    g = np.zeros((n, 3, 2))
    g[:, 0, 0], g[:, 0, 1] = c, -0.5 * d * s
    g[:, 1, 0], g[:, 1, 1] = s, 0.5 * d * c
    g[:, 2, 1] = 1.0
    q = np.zeros((n, 2, 2))
    q[:, 0, 0], q[:, 1, 1] = qd, qt
    noise = g @ q @ np.transpose(g, (0, 2, 1))
    fx, fy = -d * s, d * c
    out = np.zeros((n + 1, 3, 3))
    p = np.zeros((3, 3)) if cov0 is None else np.array(cov0, dtype=float).reshape(3, 3)
    out[0] = p
    f = np.eye(3)
    for k in range(n):
        f[0, 2], f[1, 2] = fx[k], fy[k]
        p = f @ p @ f.T + noise[k]
        out[k + 1] = p
    return 0.5 * (out + np.transpose(out, (0, 2, 1)))


# ---------------------------------------------------------------------- trajectories
@dataclass(frozen=True, eq=False)
class Trajectory:
    """Ground-truth motion sampled at the step boundaries ``start_ns + k * step_ns``.

    Attributes:
        start_ns: stamp of pose 0 [ns].
        step_ns: sampling time T [ns].
        poses: (n+1, 3) true poses at the step boundaries (yaw unwrapped).
        twists: (n, 2) true ``(v, w)`` during step k, i.e. on ``[t_k, t_k+1)`` (eqs. 17-18).
        wheel_speeds: (n, 2) true wheel angular velocities ``(omega_l, omega_r)`` [rad/s]
            during step k (the commanded, piecewise-constant values).
    """

    start_ns: int
    step_ns: int
    poses: np.ndarray
    twists: np.ndarray
    wheel_speeds: np.ndarray

    @property
    def num_steps(self) -> int:
        """Number of steps n."""
        return int(self.twists.shape[0])

    @property
    def end_ns(self) -> int:
        """Stamp of the last pose."""
        return self.start_ns + self.num_steps * self.step_ns

    @property
    def stamps_ns(self) -> np.ndarray:
        """(n+1,) int64 stamps of the step boundaries."""
        return self.start_ns + self.step_ns * np.arange(self.num_steps + 1, dtype=np.int64)

    def pose_at_seconds(self, t: Any) -> np.ndarray:
        """Return the true pose(s) at ``t`` seconds after ``start_ns`` (yaw unwrapped, clamped).

        Inside step k the same step model is evaluated with the fractional duration
        (eqs. 1-5 with ``dt = t - t_k``), so the result is continuous at step boundaries.
        """
        t = np.asarray(t, dtype=float)
        dt_step = self.step_ns / NS_PER_S
        n = self.num_steps
        tc = np.clip(t, 0.0, n * dt_step)
        k = np.clip(np.floor(tc / dt_step).astype(np.int64), 0, max(n - 1, 0))
        if n == 0:
            return np.broadcast_to(self.poses[0], t.shape + (3,)).copy()
        tau = tc - k * dt_step
        return step_pose(self.poses[k], self.twists[k, 0], self.twists[k, 1], tau)

    def pose_at(self, stamp_ns: Any) -> np.ndarray:
        """Return the true pose(s) ``[x, y, yaw]`` at int stamp(s) [ns], yaw in [-pi, pi).

        Raises:
            ValueError: if a stamp lies outside ``[start_ns, end_ns]``.
        """
        s = np.asarray(stamp_ns, dtype=np.int64)
        if np.any(s < self.start_ns) or np.any(s > self.end_ns):
            raise ValueError(f'stamp outside trajectory [{self.start_ns}, {self.end_ns}]')
        rel = s - self.start_ns
        k = np.minimum(rel // self.step_ns, max(self.num_steps - 1, 0))
        tau = (rel - k * self.step_ns) / NS_PER_S  # fraction of step k (T at end_ns)
        if self.num_steps == 0:
            p = np.broadcast_to(self.poses[0], s.shape + (3,)).copy()
        else:
            p = step_pose(self.poses[k], self.twists[k, 0], self.twists[k, 1], tau)
        p[..., 2] = wrap_angle(p[..., 2])
        return p

    def twist_at(self, stamp_ns: Any) -> np.ndarray:
        """Return the true ``(v, w)`` at stamp(s), causal convention (as TruthSample.twist).

        A stamp in ``(t_k, t_k+1]`` gets step k's twist; ``start_ns`` gets zeros (at rest).
        """
        s = np.asarray(stamp_ns, dtype=np.int64)
        if np.any(s < self.start_ns) or np.any(s > self.end_ns):
            raise ValueError(f'stamp outside trajectory [{self.start_ns}, {self.end_ns}]')
        k = -((self.start_ns - s) // self.step_ns) - 1  # ceil(rel / T) - 1
        padded = np.vstack([np.zeros((1, 2)), self.twists])
        return padded[k + 1].copy()


@dataclass(frozen=True, eq=False)
class OdometryTrack:
    """Dead-reckoning odometry at the step boundaries (same stamps as the trajectory).

    Attributes:
        poses: (n+1, 3) odometry poses, nominal model (k = 1), yaw unwrapped; pose 0 is the
            true start pose (odom frame == world frame at the start).
        covariances: (n+1, 3, 3) pose covariance, see :func:`propagate_covariance`.
        twists: (n, 2) ``(v, w)`` from the measured wheel speeds of step k (eqs. 6-7).
        wheel_speeds: (n, 2) measured ``(omega_l, omega_r)`` [rad/s] of step k.
        wheel_positions: (n+1, 2) measured accumulated wheel angles [rad], 0 at the start.
    """

    poses: np.ndarray
    covariances: np.ndarray
    twists: np.ndarray
    wheel_speeds: np.ndarray
    wheel_positions: np.ndarray


def measure_wheels(true_speeds: np.ndarray, params: RobotParams,
                   rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray]:
    """Simulate the encoders: noisy (optionally quantised) wheel speeds and wheel angles.

    Draws exactly one ``standard_normal((n, 2))`` from ``rng``. Returns
    ``(speeds (n, 2) [rad/s], positions (n+1, 2) [rad])``.
    """
    w = np.asarray(true_speeds, dtype=float).reshape(-1, 2)
    n = w.shape[0]
    z = rng.standard_normal((n, 2))
    std = params.wheel_noise_gain * np.abs(w) + params.wheel_noise_floor
    meas = w + std * z
    dt = params.sample_time
    pos = np.vstack([np.zeros((1, 2)), np.cumsum(meas * dt, axis=0)])
    ticks = int(params.encoder_ticks_per_rev)
    if ticks > 0:
        q = 2.0 * math.pi / ticks
        pos = np.floor(pos / q + 0.5) * q
        meas = np.diff(pos, axis=0) / dt
    return meas, pos


def dead_reckon(pose0: Any, wheel_speeds: np.ndarray, params: RobotParams,
                k: Tuple[float, float, float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """Integrate wheel speeds (n, 2) from ``pose0`` with factors ``k = (k1, k2, k3)``.

    With the default ``k`` this is the nominal odometry; with the true factors it reproduces
    the ground-truth motion model (eqs. 17-18). Returns (n+1, 3), yaw unwrapped.
    """
    r, b = params.wheel_radius, params.axle_length
    v, w = wheel_to_twist(wheel_speeds[:, 0], wheel_speeds[:, 1], k[0] * r, k[1] * r, k[2] * b)
    return integrate(pose0, v, w, params.sample_time)


def make_odometry(traj: Trajectory, params: RobotParams,
                  rng: np.random.Generator) -> OdometryTrack:
    """Simulate encoders and nominal dead reckoning along a true trajectory."""
    meas, pos = measure_wheels(traj.wheel_speeds, params, rng)
    r, b = params.wheel_radius, params.axle_length
    v, w = wheel_to_twist(meas[:, 0], meas[:, 1], r, r, b)  # eqs. 6-7, k = 1
    poses = integrate(traj.poses[0], v, w, params.sample_time)
    cov = propagate_covariance(poses, v, w, params.sample_time, params)
    return OdometryTrack(poses=_readonly(poses), covariances=_readonly(cov),
                         twists=_readonly(np.stack([v, w], axis=1).reshape(-1, 2)),
                         wheel_speeds=_readonly(meas), wheel_positions=_readonly(pos))


def true_twist(wheel_speeds: np.ndarray, params: RobotParams) -> np.ndarray:
    """Return the true twist (n, 2) of wheel speeds (n, 2): k1 R, k2 R, k3 b (eqs. 17-18)."""
    r, b = params.wheel_radius, params.axle_length
    v, w = wheel_to_twist(wheel_speeds[:, 0], wheel_speeds[:, 1], params.k1 * r,
                          params.k2 * r, params.k3 * b)
    return np.stack([v, w], axis=1).reshape(-1, 2)


def make_trajectory(start_ns: int, pose0: Any, wheel_speeds: np.ndarray,
                    params: RobotParams) -> Trajectory:
    """Ground truth from piecewise-constant true wheel speeds (n, 2) (eqs. 1-5, 17-18)."""
    ws = np.asarray(wheel_speeds, dtype=float).reshape(-1, 2).copy()
    tw = true_twist(ws, params)
    poses = integrate(pose0, tw[:, 0], tw[:, 1], params.sample_time)
    return Trajectory(start_ns=int(start_ns), step_ns=params.step_ns, poses=_readonly(poses),
                      twists=_readonly(tw), wheel_speeds=_readonly(ws))
