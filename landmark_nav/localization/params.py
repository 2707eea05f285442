"""Parameters shared by the EKF and the UKF (measurement model, acceptance test, UKF scaling)."""

from dataclasses import dataclass, field, fields
import math
from typing import Any, Dict, Optional

import numpy as np

from .odometry import ProcessNoise
from .sonar_model import MAX_PREDICT, THETA0


@dataclass(frozen=True)
class LocalizationParams:
    """Filter parameters (SI units, radians).

    Measurement noise (eq. 28): ``r_i = (sigma_r0 + sigma_r1 z_i)^2``; it covers the sonar's
    own noise and the map discretisation (a 0.1 m grid).

    Acceptance test (sections 4.1 and 4.3): a reading is used only if it is finite,
    within ``[min_range, max_range]``, its prediction exists (a hit within ``max_predict``,
    3.0 m, no unknown cell first), and its innovation ``|z_i - zhat_i|`` does not exceed
    ``gate`` (the chapter's acceptance threshold against corner hits, specular reflections
    and outliers). ``gate_sigmas > 0`` additionally rejects innovations larger than
    ``gate_sigmas * sqrt(S_ii)`` (off by default).

    Attributes:
        noise: process noise parameters (eq. 26).
        sigma_r0: constant range std [m].
        sigma_r1: range-proportional std [-].
        min_range: shortest usable reading [m].
        max_range: longest usable reading [m].
        max_predict: predictions beyond this are discarded [m] (section 4.1).
        gate: acceptance threshold on ``|z - zhat|`` [m].
        gate_sigmas: optional normalised gate (0 = off).
        cone_rays: rays per sonar in the prediction; 1 = the chapter's centre beam.
        theta0: half lobe angle [rad] (used when ``cone_rays > 1``).
        specular_angle: largest angle of incidence that still echoes [rad] (a transducer
            property), None = no specular model; see :func:`~.sonar_model.predict_ranges`.
        jacobian: EKF measurement Jacobian: ``'raycast'`` (central differences of the
            ray-cast range, one call for all sonars and perturbations) or ``'point'``
            (eq. 27 literally: distance to the fixed hit point ``p_i``).
        jac_step_xy: position step of the numerical Jacobian [m].
        jac_step_theta: heading step of the numerical Jacobian [rad].
        jac_max_jump: EKF and UKF: a reading whose second difference over the Jacobian's
            perturbations (first difference without ``jac_central``) exceeds this [m]
            straddles a discontinuity (edge, corner) and is not used.
        jac_central: EKF: central differences (6 perturbed poses) instead of forward
            differences (3 perturbed poses).
        jac_active_ray: EKF with ``cone_rays > 1``: differentiate only the lobe ray that
            gives the prediction (the derivative of a minimum is that of its active
            branch), 1 ray per sonar and perturbation instead of ``cone_rays``; False:
            the whole lobe at every perturbed pose in the same call as the prediction.
        ukf_alpha: UKF spread alpha in [1e-4, 1] (eq. 40); 1 spreads the sigma points to
            ``±sqrt(L + lambda) = ±sqrt(6)`` standard deviations, which averages the
            grid's range discontinuities instead of differentiating them.
        ukf_beta: beta (eq. 47), 2 is optimal for Gaussians.
        ukf_kappa: kappa (eq. 40).
        map_sigma: UKF: std of the map's surface positions in x and in y [m], augmented
            measurement noise (see :mod:`.ukf`); None = ``resolution / sqrt(12)`` of the
            grid (a surface anywhere inside its cell); 0 = off (the chapter's UKF).
        midpoint: motion model heading, see :mod:`.odometry`.
        unknown: treatment of unknown map cells by the ray caster.
    """

    noise: ProcessNoise = field(default_factory=ProcessNoise)
    sigma_r0: float = 0.05
    sigma_r1: float = 0.01
    min_range: float = 0.1
    max_range: float = 5.0
    max_predict: float = MAX_PREDICT
    gate: float = 0.2
    gate_sigmas: float = 0.0
    cone_rays: int = 7
    theta0: float = THETA0
    specular_angle: Optional[float] = math.radians(40.0)
    jacobian: str = 'raycast'
    jac_step_xy: float = 0.1
    jac_step_theta: float = math.radians(5.0)
    jac_max_jump: float = 0.15
    jac_central: bool = True
    jac_active_ray: bool = True
    ukf_alpha: float = 1.0
    ukf_beta: float = 2.0
    ukf_kappa: float = 1.0
    map_sigma: Optional[float] = None
    midpoint: bool = True
    unknown: str = 'invalid'

    def __post_init__(self) -> None:
        """Validate the choices."""
        if self.jacobian not in ('raycast', 'point'):
            raise ValueError("jacobian must be 'raycast' or 'point'")
        if not 1e-4 <= self.ukf_alpha <= 1.0:
            raise ValueError('ukf_alpha must be in [1e-4, 1]')
        if self.gate <= 0.0:
            raise ValueError('gate must be > 0')
        if self.map_sigma is not None and not 0.0 <= self.map_sigma < math.inf:
            raise ValueError('map_sigma must be None or a finite value >= 0')

    def measurement_variance(self, z: np.ndarray) -> np.ndarray:
        """Variances r_i (eq. 28) of readings ``z``."""
        return (self.sigma_r0 + self.sigma_r1 * np.abs(z)) ** 2

    def to_dict(self) -> Dict[str, Any]:
        """Plain dict (the process noise as a nested dict)."""
        out: Dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = {g.name: getattr(v, g.name) for g in fields(v)} if f.name == 'noise' \
                else v
        return out


def usable_readings(z: Any, params: LocalizationParams) -> np.ndarray:
    """(S,) bool: readings that may pass the acceptance test whatever the prediction.

    Finite, within ``[min_range, max_range]`` and not beyond ``max_predict + gate`` (no
    prediction is longer than ``max_predict``).
    """
    z = np.asarray(z, dtype=float)
    with np.errstate(invalid='ignore'):
        return (np.isfinite(z) & (z >= params.min_range) & (z <= params.max_range)
                & (z <= params.max_predict + params.gate))


def accept_readings(z: np.ndarray, z_hat: np.ndarray, params: LocalizationParams,
                    s_diag: Any = None) -> np.ndarray:
    """Apply the acceptance test to the readings (see :class:`LocalizationParams`).

    Args:
        z: (S,) readings (``+-inf`` / ``nan`` allowed).
        z_hat: (S,) predicted readings (``nan`` = no prediction).
        params: filter parameters.
        s_diag: (S,) innovation variances for the optional normalised gate.

    Returns:
        (S,) bool, True for the readings to use.
    """
    z = np.asarray(z, dtype=float)
    z_hat = np.asarray(z_hat, dtype=float)
    ok = usable_readings(z, params)
    with np.errstate(invalid='ignore'):
        ok &= np.isfinite(z_hat)
        nu = np.abs(z - z_hat)
        ok &= nu <= params.gate
        if params.gate_sigmas > 0.0 and s_diag is not None:
            ok &= nu <= params.gate_sigmas * np.sqrt(np.asarray(s_diag, dtype=float))
    return ok


def prediction_kwargs(params: LocalizationParams) -> Dict[str, Any]:
    """Keyword arguments of :func:`~.sonar_model.predict_ranges` from the parameters."""
    return {'max_predict': params.max_predict, 'cone_rays': params.cone_rays,
            'theta0': params.theta0, 'specular_angle': params.specular_angle,
            'unknown': params.unknown}
