"""EKF-SLAM with corner and line landmarks (corner chapter section 3): filter, association.

Modules:

* :mod:`.ekf_slam` -- :class:`EkfSlam` (the state layout in its module docstring) and the
  filter steps of Fig. 17, one function each, re-exported from the modules that compute
  them: :mod:`.slam_params`, :mod:`.prediction`, :mod:`.observation_models`,
  :mod:`.gating`, :mod:`.update`, :mod:`.consistent_linearisation`, :mod:`.map_management`.
* :mod:`.association` -- ICNN (eqs. 49-55) and JCBB (Neira & Tardos 2001) on innovations.
* :mod:`.consistency` -- NEES (eq. 59), NIS (eq. 60), chi-square gates and bands.
* :mod:`.observations` -- laser corners to base_link range-bearing with propagated ``R``.
* :mod:`.frontend` -- :class:`SlamFrontend`: odometry buffer and checks, interpolation,
  de-skew, predict and update; the one pipeline of the ``ekf_slam`` node and the offline run.
* :mod:`.line_landmarks` -- line landmarks ``(rho, alpha)``: model, Jacobians, extents.
* :mod:`.features` -- a scan's corners and / or lines (``landmarks: corners|lines|both``).
* :mod:`.visibility` -- which landmarks a scan shows to be gone (pruning).
* :mod:`.slam_map` -- :class:`.slam_map.SlamMap`, ``save_map`` / ``load_map`` (file format).
* :mod:`landmark_nav.evaluation.slam` (not in this package) -- runs the filter on a simulated
  scenario or a bag and scores it against a reference.
"""

from .association import icnn, jcbb, joint_mahalanobis, mahalanobis_table
from .consistency import chi2_band, chi2_gate, nees, nis, share_inside
from .ekf_slam import (augment_map, do_data_association, ekf_predict, ekf_update, EkfSlam,
                       map_initialization, observation_model, odometry_check,
                       odometry_increment, odometry_noise, OdometryNoise, SlamParams,
                       UpdateResult)
from .frontend import (Corners, FrontendParams, odometry_noise_model, ODOMETRY_NOISE_MODELS,
                       SlamFrontend)
from .observations import corner_descriptors, corners_to_observations, points_to_observations

__all__ = [
    'augment_map', 'chi2_band', 'chi2_gate', 'corner_descriptors', 'Corners',
    'corners_to_observations', 'do_data_association', 'FrontendParams',
    'EkfSlam', 'ekf_predict', 'ekf_update', 'icnn', 'jcbb', 'joint_mahalanobis',
    'mahalanobis_table', 'map_initialization', 'nees', 'nis', 'observation_model',
    'odometry_check', 'odometry_increment', 'odometry_noise', 'odometry_noise_model',
    'ODOMETRY_NOISE_MODELS', 'OdometryNoise', 'points_to_observations', 'share_inside',
    'SlamFrontend', 'SlamParams', 'UpdateResult',
]
