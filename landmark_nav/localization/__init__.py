"""Sonar-based pose tracking on an occupancy grid with an EKF and a UKF (pure numpy).

Source: Ivanjko, Kitanov, Petrovic, "Model based Kalman filter mobile robot
self-localization", sections 2.1-2.2 (kinematics eqs. 1-9, sonar model eqs. 10-11),
3.1 (calibrated odometry eqs. 17-18) and 4 (occupancy grid, measurement prediction
eqs. 21-23, EKF eqs. 24-36, UKF eqs. 37-54). SI units and radians throughout.

State layout (both filters)::

    x = [x, y, Theta]      robot pose in the map frame [m, m, rad], Theta in [-pi, pi)
    P = 3 x 3 covariance in that order
    u = [D, dTheta]        control: distance and rotation during one period T (0.1 s)
    v = [v1, v2]           process noise added to D and dTheta (eq. 25), covariance Q
    x^a = [x, y, Theta, v1, v2]   UKF augmented state, L = 5 (eq. 37)
    z = (S,) sonar ranges [m] in mount order (16 for the Pioneer ring), +inf = no echo

Modules:

* :mod:`.grid` -- :class:`GridMap`, map_server YAML/PGM I/O (``load_map_yaml``,
  ``save_map_yaml``), ``rasterize_world``, vectorised ``raycast_grid``, ``wall_normals``.
* :mod:`.sonar_model` -- alpha / Delta (eqs. 10-11), ``sonar_global_poses``
  (eqs. 21-23), ``predict_ranges`` (one call for all poses x sonars), ``build_sonar_map``.
* :mod:`.odometry` -- ``control_from_wheels`` / ``control_from_poses``, ``motion_model``
  f and ``motion_jacobians``, ``process_noise`` Q (eq. 26), ``dead_reckoning``.
* :mod:`.params` -- :class:`LocalizationParams` (noise, acceptance test, UKF scaling).
* :mod:`.ekf` -- ``time_update`` (eqs. 29-30), ``measurement_update`` (eqs. 31-36).
* :mod:`.ukf` -- ``weights``, ``sigma_points``, ``time_update`` (eqs. 37-48),
  ``measurement_update`` (eqs. 49-54).

The offline runners and scorers (``run_localization``, ``localize``,
``odometry_trajectory``, ``localization_errors``, the hallway study) live in
:mod:`landmark_nav.evaluation.localization`.
"""

from .grid import GridMap, load_map_yaml, rasterize_world, raycast_grid, save_map_yaml
from .odometry import (control_from_poses, control_from_wheels, motion_jacobians,
                       motion_model, process_noise, ProcessNoise)
from .params import LocalizationParams
from .sonar_model import (angular_modulation, build_sonar_map, predict_ranges,
                          radial_modulation, sonar_global_poses)

__all__ = [
    'angular_modulation', 'build_sonar_map', 'control_from_poses', 'control_from_wheels',
    'GridMap', 'load_map_yaml', 'LocalizationParams', 'motion_jacobians', 'motion_model',
    'predict_ranges', 'process_noise', 'ProcessNoise', 'radial_modulation',
    'rasterize_world', 'raycast_grid', 'save_map_yaml', 'sonar_global_poses',
]
