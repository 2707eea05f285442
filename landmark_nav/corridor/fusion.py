"""EKF fusion of dead reckoning and visual corridor measurements (chapter §3.2, eq. 24).

State (the chapter's order): ``s = [theta, x, y]``: the robot heading relative to the
corridor (counter-clockwise), the position along the corridor and the lateral position
(left positive), in the corridor frame of :mod:`.lateral`; covariance ``P`` (3 x 3).

Time update (every odometry sample): dead reckoning with the distance-driven error model
of Kleeman (2003), as the chapter uses it: the distances of the left and right wheels
``d_L``, ``d_R`` have variances proportional to their magnitudes,
``var(d_L) = k_l |d_L|``, ``var(d_R) = k_r |d_R|``, and the effective wheel separation ``b``
has std ``sigma_b``; with ``ds = (d_R + d_L) / 2`` and ``dtheta = (d_R - d_L) / b``::

    theta' = theta + dtheta
    x'     = x + ds cos(theta + dtheta / 2)
    y'     = y + ds sin(theta + dtheta / 2)

``P' = F P F^T + G diag(k_l |d_L|, k_r |d_R|, sigma_b^2) G^T`` (``F``, ``G`` the Jacobians
w.r.t. the state and to ``(d_L, d_R, b)``). Odometry given as pose increments
``(ds, dtheta)`` is converted with the nominal ``b``.

Measurement update (each image), eq. 24: ``z = [theta_v, y_v] = H s + v``,
``H = [[1, 0, 0], [0, 0, 1]]``, ``v ~ N(0, R)`` with ``R`` from the single-frame standard
deviations (the vision cores propagate the end-point noise; a floor is added by the caller
for what the model leaves out, the chapter's "higher standard deviation"). A VP fixes the
corridor direction only up to its sign, so a robot driving the other way (``|theta| >
pi / 2``) sees ``theta_v = theta - pi`` (wrapped) and ``y_v = -y`` (its left is the
corridor's right): ``H`` then has ``-1`` in the ``y`` row. An update whose normalised
innovation squared exceeds ``gate_chi2`` (chi-square, 2 degrees of freedom, 99.9 % by
default) is rejected as an outlier.

A measurement that may be wrong (the vanishing point's ``p_correct`` < 1,
:mod:`.vp_confidence`) has a two-component noise: ``N(0, R)`` with probability ``p``,
``N(0, R_w)`` (the spread of wrong directions) otherwise. The update is the Gaussian-sum
update of that mixture (Sorenson and Alspach 1971), collapsed to one Gaussian by matching
moments as in probabilistic data association (Bar-Shalom and Tse 1975)::

    beta_j = pi_j N(nu; 0, S_j) / sum_k pi_k N(nu; 0, S_k),  S_j = H P H^T + R_j
    s' = s + sum_j beta_j K_j nu,   P' = sum_j beta_j (P_j + (s_j - s') (s_j - s')^T)

(``pi = (p, 1 - p)``, ``K_j``, ``s_j``, ``P_j`` the Kalman update with ``R_j``). A weak
measurement that agrees with the prediction is thus believed about as much as its
correct mode allows, one that disagrees moves the estimate as little as the wrong mode's
spread allows. It is rejected when its NIS exceeds the gate under both components.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple

from landmark_nav.geometry import wrap_angle
import numpy as np


@dataclass(frozen=True)
class DeadReckoningNoise:
    """Kleeman's distance-driven odometry error model.

    Attributes:
        wheel_separation: effective wheel separation b [m].
        k_left: variance of the left wheel distance per metre driven [m^2/m].
        k_right: variance of the right wheel distance per metre driven [m^2/m].
        sigma_separation: std of the effective wheel separation per step [m].
    """

    wheel_separation: float = 0.33
    k_left: float = 1e-4
    k_right: float = 1e-4
    sigma_separation: float = 0.0

    def __post_init__(self) -> None:
        """Validate."""
        if not self.wheel_separation > 0:
            raise ValueError(f'wheel_separation must be > 0; got {self.wheel_separation}')
        if self.k_left < 0 or self.k_right < 0 or self.sigma_separation < 0:
            raise ValueError('odometry noise parameters must be >= 0')


@dataclass(frozen=True)
class UpdateResult:
    """Outcome of one measurement update.

    Attributes:
        accepted: False when the gate rejected the measurement (state unchanged).
        nis: normalised innovation squared.
        facing_back: True when the robot faced the other way (theta_v = theta - pi, y_v = -y).
    """

    accepted: bool
    nis: float
    facing_back: bool


class CorridorEKF:
    """EKF of ``[theta, x, y]`` in the corridor frame (see the module docstring)."""

    def __init__(self, state: Sequence[float], covariance: np.ndarray,
                 noise: DeadReckoningNoise = DeadReckoningNoise(),
                 gate_chi2: float = 13.8155) -> None:
        """Start from a state and covariance.

        Args:
            state: ``[theta, x, y]`` [rad, m, m].
            covariance: (3, 3) symmetric positive semi-definite.
            noise: odometry error model.
            gate_chi2: NIS bound of the outlier gate (13.8: chi-square 2 dof, 99.9 %).
        """
        s = np.asarray(state, dtype=float).reshape(3).copy()
        p = np.asarray(covariance, dtype=float).reshape(3, 3).copy()
        if not np.all(np.isfinite(s)) or not np.all(np.isfinite(p)):
            raise ValueError('EKF state and covariance must be finite')
        if not np.allclose(p, p.T) or np.min(np.linalg.eigvalsh(p)) < -1e-12:
            raise ValueError('EKF covariance must be symmetric positive semi-definite')
        s[0] = wrap_angle(s[0])
        self.s, self.p, self.noise, self.gate_chi2 = s, p, noise, float(gate_chi2)

    # ------------------------------------------------------------------ time update
    def predict_wheels(self, d_left: float, d_right: float) -> None:
        """Time update with the distances driven by the two wheels [m] (Kleeman)."""
        if not (math.isfinite(d_left) and math.isfinite(d_right)):
            raise ValueError(f'wheel distances must be finite; got {d_left}, {d_right}')
        n = self.noise
        b = n.wheel_separation
        th = self.s[0]
        ds = 0.5 * (d_left + d_right)
        dth = (d_right - d_left) / b
        a = th + 0.5 * dth
        ca, sa = math.cos(a), math.sin(a)
        F = np.array([[1.0, 0.0, 0.0],
                      [-ds * sa, 1.0, 0.0],
                      [ds * ca, 0.0, 1.0]])
        # d(theta', x', y') / d(d_L, d_R, b)
        dds = np.array([0.5, 0.5, 0.0])
        ddth = np.array([-1.0 / b, 1.0 / b, -dth / b])
        G = np.vstack([ddth,
                       dds * ca - ds * sa * 0.5 * ddth,
                       dds * sa + ds * ca * 0.5 * ddth])
        Q = np.diag([n.k_left * abs(d_left), n.k_right * abs(d_right),
                     n.sigma_separation ** 2])
        self.s = np.array([wrap_angle(th + dth), self.s[1] + ds * ca, self.s[2] + ds * sa])
        self.p = F @ self.p @ F.T + G @ Q @ G.T
        self.p = 0.5 * (self.p + self.p.T)

    def predict(self, ds: float, dtheta: float) -> None:
        """Time update with an odometry increment: distance [m] and rotation [rad]."""
        half = 0.5 * dtheta * self.noise.wheel_separation
        self.predict_wheels(ds - half, ds + half)

    # ------------------------------------------------------------------ measurement update
    def update(self, theta_v: float, y_v: float, covariance: np.ndarray,
               p_correct: float = 1.0,
               wrong_covariance: Optional[np.ndarray] = None) -> UpdateResult:
        """Measurement update with a visual heading and lateral position (eq. 24).

        Args:
            theta_v: heading relative to the VP direction ahead [rad], in (-pi/2, pi/2].
            y_v: lateral position in the frame whose x points at that VP [m].
            covariance: (2, 2) measurement covariance R (of a correct measurement).
            p_correct: probability that the measurement is correct (module docstring).
            wrong_covariance: (2, 2) covariance ``R_w`` of a wrong one (needed when
                ``p_correct < 1``).
        """
        r = np.asarray(covariance, dtype=float).reshape(2, 2)
        if not (math.isfinite(theta_v) and math.isfinite(y_v)) or not np.all(np.isfinite(r)):
            raise ValueError('visual measurement and its covariance must be finite')
        if not 0.0 <= p_correct <= 1.0:
            raise ValueError(f'p_correct must be in [0, 1]; got {p_correct}')
        modes = [(p_correct, r)]
        if p_correct < 1.0:
            if wrong_covariance is None:
                raise ValueError('p_correct < 1 needs wrong_covariance')
            r_w = np.asarray(wrong_covariance, dtype=float).reshape(2, 2)
            if not np.all(np.isfinite(r_w)):
                raise ValueError('wrong_covariance must be finite')
            modes.append((1.0 - p_correct, r_w))
        modes = [(w, rj) for w, rj in modes if w > 0.0]
        rev = abs(wrap_angle(self.s[0])) > math.pi / 2
        sign = -1.0 if rev else 1.0
        H = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, sign]])              # eq. 24
        pred_th = wrap_angle(self.s[0] - math.pi) if rev else self.s[0]
        innov = np.array([wrap_angle(theta_v - pred_th), y_v - sign * self.s[2]])
        parts = []
        for w, rj in modes:
            S = H @ self.p @ H.T + rj
            nis = float(innov @ np.linalg.solve(S, innov))
            K = self.p @ H.T @ np.linalg.inv(S)
            ik = np.eye(3) - K @ H
            pj = ik @ self.p @ ik.T + K @ rj @ K.T                       # Joseph form
            log_l = math.log(w) - 0.5 * nis - 0.5 * math.log(np.linalg.det(2 * math.pi * S))
            parts.append((log_l, nis, K @ innov, pj))
        nis = min(nis for _, nis, _, _ in parts)
        if not nis <= self.gate_chi2:
            return UpdateResult(False, nis, rev)
        log_l = np.array([part[0] for part in parts])
        beta = np.exp(log_l - log_l.max())
        beta /= beta.sum()
        mean = sum(b * part[2] for b, part in zip(beta, parts))
        p_new = sum(b * (part[3] + np.outer(part[2] - mean, part[2] - mean))
                    for b, part in zip(beta, parts))
        self.s = self.s + mean
        self.s[0] = wrap_angle(self.s[0])
        self.p = 0.5 * (p_new + p_new.T)
        return UpdateResult(True, nis, rev)

    @property
    def facing_back(self) -> bool:
        """Return whether the robot faces against the corridor's x axis (|theta| > pi/2)."""
        return abs(wrap_angle(self.s[0])) > math.pi / 2

    def visual_prior(self) -> Tuple[float, float]:
        """Return the predicted ``y_v`` (mean, std) in the frame of the VP ahead (eq. 24)."""
        sign = -1.0 if self.facing_back else 1.0
        return sign * float(self.s[2]), math.sqrt(max(float(self.p[2, 2]), 0.0))

    @property
    def state(self) -> Tuple[float, float, float]:
        """Return ``(theta, x, y)``."""
        return float(self.s[0]), float(self.s[1]), float(self.s[2])
