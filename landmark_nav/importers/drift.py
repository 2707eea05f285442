"""Odometry noise model: synthetic drift from a reference, and the odometry covariance.

Model (per step between two consecutive poses; variances grow linearly with the distance
travelled and the angle turned)::

    u_k   = relative(ref_k, ref_k+1) = (dx, dy, dth)    reference increment, robot frame
    D     = hypot(dx, dy),  a = atan2(dy, dx)           distance and its direction
    e_D   ~ N(0, k_d^2 D)                               distance error [m]
    e_th  ~ N(0, k_theta^2 D + k_dtheta^2 |dth|)        heading error [rad]
    u'_k  = (dx + e_D cos a, dy + e_D sin a, dth + e_th)
    odom_k+1 = odom_k (+) u'_k,  odom_0 = ref_0         (composition, eq. 16 / eq. 13)

so sigma_D = k_d sqrt(D) [m] and sigma_th = sqrt(k_theta^2 D + k_dtheta^2 |dth|) [rad] per
step: the two heading terms add as variances. Summed over the steps, the variances follow
the path length and the total |dth| turned, so on a smooth reference the drift hardly
depends on how finely the path is sampled. A jittery reference (a scan-matched corrected
pose whose heading wiggles from scan to scan) is different: its sum of |dth| grows with the
number of steps, and with it the k_dtheta part of the heading drift (the sum of D grows
too, by less, with the position jitter). The covariance written into ``/odom`` is the
first-order propagation of the same model, ``P_k+1 = F P_k F^T + G Q G^T`` with the
Jacobians of the composition (eqs. 27-30), starting from zero at the first pose.

Default ``pioneer``: k_d = 0.05 m/sqrt(m), k_theta = 0.05 rad/sqrt(m),
k_dtheta = 0.1 rad/sqrt(rad), the values of the simulator's Pioneer 2-DX model
(``landmark_nav.sim.robot.RobotParams.odom_sigma_*``). After 10 m straight they give a
distance spread of 16 cm and a heading spread of 9 deg, and 14 deg per full turn on the
spot. That is the order of the drift of an uncalibrated Pioneer-class base: the
self-localization chapter's calibration factors (k1 = 0.9977, k2 = 1.0023, k3 = 1.0095,
eqs. 17-18) alone turn the heading by 8 deg per 10 m and 3.4 deg per full turn, and real
floors add slip. The drift is random here (zero mean), not systematic.
"""

from dataclasses import dataclass
import math
import re

import numpy as np

__all__ = ['DRIFT_MODELS', 'DriftModel', 'parse_drift_model', 'propagate_covariance',
           'synthetic_odometry']


@dataclass(frozen=True)
class DriftModel:
    """Distance- and rotation-driven odometry noise (see the module docstring)."""

    k_d: float = 0.05  # m / sqrt(m)
    k_theta: float = 0.05  # rad / sqrt(m)
    k_dtheta: float = 0.1  # rad / sqrt(rad)
    name: str = 'pioneer'

    def __post_init__(self) -> None:
        """Validate the gains."""
        for key in ('k_d', 'k_theta', 'k_dtheta'):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f'drift model: {key} must be finite and >= 0, got {value}')

    def gains(self) -> str:
        """Return ``'k_d=0.05 k_theta=0.05 k_dtheta=0.1'`` (custom_data; parses back)."""
        return f'k_d={self.k_d:g} k_theta={self.k_theta:g} k_dtheta={self.k_dtheta:g}'

    def describe(self) -> str:
        """Return ``'pioneer: k_d=0.05 k_theta=0.05 k_dtheta=0.1'`` (printed summary)."""
        return f'{self.name}: {self.gains()}'

    def step_variances(self, increments: np.ndarray):
        """Return (var_D, var_theta) of each (dx, dy, dth) increment, shape (n,) each."""
        u = np.asarray(increments, dtype=float).reshape(-1, 3)
        dist = np.hypot(u[:, 0], u[:, 1])
        return (self.k_d ** 2 * dist,
                self.k_theta ** 2 * dist + self.k_dtheta ** 2 * np.abs(u[:, 2]))


DRIFT_MODELS = {'pioneer': DriftModel(), 'none': DriftModel(0.0, 0.0, 0.0, 'none')}
_GAIN = re.compile(r'^(k_d|k_theta|k_dtheta)=([0-9.eE+-]+)$')


def parse_drift_model(text: str) -> DriftModel:
    """Parse ``pioneer``, ``none`` or ``'k_d=0.02 k_theta=0.05 k_dtheta=0.1'``.

    Gains not given keep the ``pioneer`` values.

    Raises:
        ValueError: Unknown name or malformed gain.

    """
    text = text.strip()
    if text in DRIFT_MODELS:
        return DRIFT_MODELS[text]
    gains = {}
    for token in text.replace(',', ' ').split():
        m = _GAIN.match(token)
        if not m:
            raise ValueError(f'drift model: expected one of {", ".join(DRIFT_MODELS)} or '
                             f'k_d=.. k_theta=.. k_dtheta=.., got {token!r}')
        try:
            gains[m.group(1)] = float(m.group(2))
        except ValueError:
            raise ValueError(f'drift model: {token!r} is not a number') from None
    if not gains:
        raise ValueError('drift model: empty')
    return DriftModel(name='custom', **{**{'k_d': 0.05, 'k_theta': 0.05, 'k_dtheta': 0.1},
                                        **gains})


def _relative(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Return the increments p_k^-1 (+) q_k (robot frame), vectorised (eq. 13)."""
    d = q[:, :2] - p[:, :2]
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    dth = np.arctan2(np.sin(q[:, 2] - p[:, 2]), np.cos(q[:, 2] - p[:, 2]))
    return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], dth))


def _compose_path(start: np.ndarray, increments: np.ndarray) -> np.ndarray:
    """Return start (+) u_0 (+) u_1 ... (eq. 16), headings unwrapped, shape (n+1, 3)."""
    th = start[2] + np.concatenate(([0.0], np.cumsum(increments[:, 2])))
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    dx = c * increments[:, 0] - s * increments[:, 1]
    dy = s * increments[:, 0] + c * increments[:, 1]
    x = start[0] + np.concatenate(([0.0], np.cumsum(dx)))
    y = start[1] + np.concatenate(([0.0], np.cumsum(dy)))
    return np.column_stack((x, y, th))


def propagate_covariance(poses: np.ndarray, model: DriftModel) -> np.ndarray:
    """Return the (n, 3, 3) odometry covariance along a path under ``model``, P_0 = 0."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    n = len(poses)
    out = np.zeros((n, 3, 3))
    if n < 2:
        return out
    u = _relative(poses[:-1], poses[1:])
    var_d, var_t = model.step_variances(u)
    a = np.arctan2(u[:, 1], u[:, 0])
    # Noise of u in (dx, dy, dth): J diag(var_d, var_t) J^T with J = [[cos a, 0],
    # [sin a, 0], [0, 1]]; rotated into the odom frame by R(theta_k) (eq. 30's G).
    th = poses[:-1, 2]
    ca, sa = np.cos(a + th), np.sin(a + th)
    q = np.zeros((n - 1, 3, 3))
    q[:, 0, 0], q[:, 0, 1], q[:, 1, 1] = var_d * ca * ca, var_d * ca * sa, var_d * sa * sa
    q[:, 1, 0] = q[:, 0, 1]
    q[:, 2, 2] = var_t
    # F = d(p (+) u)/dp (eq. 29): identity plus the lever arm of the heading.
    c, s = np.cos(th), np.sin(th)
    fx = -s * u[:, 0] - c * u[:, 1]
    fy = c * u[:, 0] - s * u[:, 1]
    p = np.zeros((3, 3))
    f = np.eye(3)
    for k in range(n - 1):
        f[0, 2], f[1, 2] = fx[k], fy[k]
        p = f @ p @ f.T + q[k]
        out[k + 1] = p
    return 0.5 * (out + np.transpose(out, (0, 2, 1)))


def synthetic_odometry(reference: np.ndarray, model: DriftModel, seed: int) -> np.ndarray:
    """Return odometry poses (n, 3) drifting from ``reference`` (n, 3) under ``model``.

    The first pose equals the reference's; the same seed gives the same drift.
    """
    ref = np.asarray(reference, dtype=float).reshape(-1, 3)
    if len(ref) < 2:
        return ref.copy()
    u = _relative(ref[:-1], ref[1:])
    var_d, var_t = model.step_variances(u)
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((len(u), 2))
    e_d = noise[:, 0] * np.sqrt(var_d)
    e_t = noise[:, 1] * np.sqrt(var_t)
    a = np.arctan2(u[:, 1], u[:, 0])
    noisy = u + np.column_stack((e_d * np.cos(a), e_d * np.sin(a), e_t))
    out = _compose_path(ref[0], noisy)
    out[:, 2] = np.arctan2(np.sin(out[:, 2]), np.cos(out[:, 2]))
    return out
