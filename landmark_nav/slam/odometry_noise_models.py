"""Odometry noise models per robot: the filter's ``U`` by name or by drift gains (ROS free).

The filter's ``U`` (:func:`.ekf_slam.odometry_noise`) is distance- and rotation-driven:
``sigma_xy = s_xy sqrt(d)`` on each axis, ``sigma_psi^2 = s_yd^2 d + s_yr^2 |dpsi|``.

* ``pioneer`` (the default of the node and of bags that state nothing): ``s_xy`` 0.05
  m/sqrt(m), ``s_yd`` 0.05 rad/sqrt(m), ``s_yr`` 0.1 rad/sqrt(rad): an uncalibrated
  Pioneer-class base, 16 cm and 9 deg of spread after 10 m straight and 14 deg per turn on
  the spot (the self-localization chapter's calibration factors alone give 8 deg per 10 m
  and 3.4 deg per turn; real floors add slip). The same numbers as the importer's default
  drift model, whose gains ``k_d, k_theta, k_dtheta`` map one to one onto ``s_xy, s_yd,
  s_yr`` (the importer's distance error lies along the motion; the filter spreads it on both
  axes, which is conservative across the motion).
* ``simulator``: :class:`~.ekf_slam.OdometryNoise` defaults (1.5 mm/sqrt(m), 0.01
  rad/sqrt(m), 0.01 rad/sqrt(rad)), the random wheel noise of the package's simulated
  Pioneer; used for the simulator's bags.
* ``'k_d=.. k_theta=.. k_dtheta=..'``: the gains an imported bag states in its
  ``custom_data`` key ``landmark_nav.drift_model`` (the imported-bag contract).
"""

from dataclasses import replace
import math
import re
from typing import Dict

from .ekf_slam import OdometryNoise

#: Named odometry noise models (module docstring).
ODOMETRY_NOISE_MODELS: Dict[str, OdometryNoise] = {
    'pioneer': OdometryNoise(sigma_xy_per_sqrt_m=0.05, sigma_yaw_per_sqrt_m=0.05,
                             sigma_yaw_per_sqrt_rad=0.1),
    'simulator': OdometryNoise(),
}
_GAIN = re.compile(r'^(k_d|k_theta|k_dtheta)=(\S+)$')
_GAIN_FIELD = {'k_d': 'sigma_xy_per_sqrt_m', 'k_theta': 'sigma_yaw_per_sqrt_m',
               'k_dtheta': 'sigma_yaw_per_sqrt_rad'}


def odometry_noise_model(text: str) -> OdometryNoise:
    """Return the odometry noise of a model name or of drift gains (module docstring).

    Args:
        text: ``'pioneer'``, ``'simulator'`` or ``'k_d=0.05 k_theta=0.05 k_dtheta=0.1'``
            (the importer's ``landmark_nav.drift_model``; gains not given keep the
            ``pioneer`` values).

    Returns:
        The noise model.

    Raises:
        ValueError: Unknown name or malformed gain (one line naming it).
    """
    text = str(text).strip()
    if text in ODOMETRY_NOISE_MODELS:
        return ODOMETRY_NOISE_MODELS[text]
    gains = {}
    for token in text.replace(',', ' ').split():
        m = _GAIN.match(token)
        try:
            value = float(m.group(2)) if m else math.nan
        except ValueError:
            value = math.nan
        if not m or not math.isfinite(value) or value < 0.0:
            raise ValueError(f'odometry noise model: expected {" or ".join(ODOMETRY_NOISE_MODELS)}'
                             f' or k_d=.. k_theta=.. k_dtheta=.. (numbers >= 0), got {token!r}')
        gains[_GAIN_FIELD[m.group(1)]] = value
    if not gains:
        raise ValueError('odometry noise model: empty')
    return replace(ODOMETRY_NOISE_MODELS['pioneer'], **gains)


__all__ = ['ODOMETRY_NOISE_MODELS', 'odometry_noise_model']
