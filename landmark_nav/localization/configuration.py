"""The ``sonar_localizer`` configuration: its parameters, shared by the node and offline.

One description of the node's parameters serves the node (which declares them with these
defaults, descriptions and limits) and ``landmark_nav evaluate-localization --params-file
/ --set``: :func:`parameters` lists every parameter with its default and
:func:`localizer_configuration` checks parameter values as the node does (names, types,
limits, choices) and builds the filter's :class:`~.params.LocalizationParams` (process
noise included).
"""

from dataclasses import dataclass, replace
import math
from typing import Any, Dict, Mapping, Optional

from landmark_nav.hardware import SONAR_MOUNTS
from landmark_nav.localization.odometry import ProcessNoise
from landmark_nav.localization.params import LocalizationParams
from landmark_nav.parameter_tables import (dataclass_parameters, field_value,
                                           name_parameters, Parameter, parameter_values)

NODE = 'sonar_localizer'

FILTER_PARAMETERS = {
    'sigma_r0': ('measurement noise: constant range std [m] (eq. 28)', (0.0, 1.0), None),
    'sigma_r1': ('measurement noise: range-proportional std [-] (eq. 28)', (0.0, 1.0), None),
    'min_range': ('shortest usable sonar reading [m]', (0.0, 100.0), None),
    'max_range': ('longest usable sonar reading [m]', (0.0, 100.0), None),
    'max_predict': ('predicted readings beyond this are discarded [m] (section 4.1)',
                    (0.1, 100.0), None),
    'gate': ('acceptance threshold on |z - zhat| [m] (sections 4.1, 4.3)', (0.001, 10.0),
             None),
    'gate_sigmas': ('optional normalised gate [innovation std devs]; 0 = off', (0.0, 100.0),
                    None),
    'cone_rays': ('rays per sonar lobe in the prediction; 1 = the centre beam only',
                  (1, 101), None),
    'theta0': ('half lobe angle Theta_0 [rad] (eq. 10; used when cone_rays > 1)',
               (0.0, 1.5), None),
    'specular_angle': ('largest angle of incidence that still echoes [rad]; 0 = no specular '
                       'model', (0.0, 1.5708), None, 0.0),
    'jacobian': ('EKF measurement Jacobian: raycast (differences of the ray-cast range) or '
                 'point (eq. 27 literally)', None, ['raycast', 'point']),
    'jac_step_xy': ('EKF Jacobian position step [m]', (1e-4, 1.0), None),
    'jac_step_theta': ('EKF Jacobian heading step [rad]', (1e-4, 1.0), None),
    'jac_max_jump': ('EKF and UKF: readings whose perturbed predictions jump more than this '
                     'are not used [m]', (0.0, 10.0), None),
    'jac_central': ('EKF: central (true) or forward (false) differences', None, None),
    'jac_active_ray': ('EKF with cone_rays > 1: differentiate only the echoing ray', None,
                       None),
    'ukf_alpha': ('UKF sigma-point spread alpha (eq. 40)', (1e-4, 1.0), None),
    'ukf_beta': ('UKF beta (eq. 47), 2 for Gaussians', (0.0, 10.0), None),
    'ukf_kappa': ('UKF kappa (eq. 40)', (-4.0, 100.0), None),
    'map_sigma': ('UKF: std of the map surface positions in x and y [m], augmented '
                  'measurement noise; -1 = map resolution / sqrt(12); 0 = off',
                  (-1.0, 1.0), None, -1.0),
    'midpoint': ('motion model moves along the mean heading (eqs. 1-3); false = eq. 25 as '
                 'printed', None, None),
    'unknown': ('unknown map cells: invalid (no prediction through them), occupied or free '
                '(use free on sonar-built maps)', None, ['invalid', 'occupied', 'free']),
}
NOISE_PARAMETERS = {
    'sigma_d': ('std of the travelled distance per step [m] (eq. 26)', (0.0, 1.0), None),
    'sigma_dtheta': ('relative std of the rotation per step [-] (eq. 26)', (0.0, 10.0),
                     None),
    'k_d': ('distance std per metre travelled [-] (extension of eq. 26)', (0.0, 10.0), None),
    'k_theta': ('heading std per metre travelled [rad/m] (extension of eq. 26)', (0.0, 10.0),
                None),
}
#: The node's other parameters, in the order it declares them (before the filter's).
NODE_PARAMETERS = {
    'filter': Parameter('ekf', 'pose filter: ekf or ukf', None, ['ekf', 'ukf']),
    'odometry_source': Parameter('odom', 'motion input: odom (nav_msgs/Odometry poses) or '
                                 'joint_states (wheel angles)', None,
                                 ['odom', 'joint_states']),
    'wheel_radius': Parameter(0.0955, 'nominal wheel radius R [m] (joint_states)',
                              (0.001, 10.0)),
    'axle_length': Parameter(0.33, 'nominal axle length b [m]', (0.001, 10.0)),
    **{f'k{i}': Parameter(1.0, f'odometry calibration factor k{i} (eqs. 17-18; 1 = nominal)',
                          (0.5, 1.5)) for i in (1, 2, 3)},
    'wheel_joints': Parameter(['left_wheel_joint', 'right_wheel_joint'],
                              'left and right wheel joint names (joint_states)'),
    'sonar_topics': Parameter([f'/sonar/range_{i}' for i in range(16)],
                              'sensor_msgs/Range topics, one per sonar, mount order'),
    'sonar_mounts': Parameter([float(v) for v in SONAR_MOUNTS.ravel()],
                              'x [m], y [m], yaw [rad] of each sonar in base_link (the '
                              'transforms base_link -> sonar_<i>), in sonar_topics order; '
                              'default Pioneer 2-DX'),
    'map_file': Parameter('', 'map_server YAML to load; empty = subscribe to map'),
    'global_frame': Parameter('map', 'frame of the map and the output'),
    'base_frame': Parameter('base_link', 'child frame of the output'),
    **{f'initial_pose.{n}': Parameter(0.0, f'initial {n} in global_frame [{u}]', (-1e6, 1e6))
       for n, u in (('x', 'm'), ('y', 'm'), ('yaw', 'rad'))},
    **{f'initial_pose.std_{n}': Parameter(v, f'initial std of {n} [{u}]', (1e-6, 1e3))
       for n, v, u in (('x', 0.055, 'm'), ('y', 0.055, 'm'), ('yaw', math.radians(5.0), 'rad'))},
    'sync_timeout': Parameter(0.15, 'process an incomplete sonar cycle once a stamp this much '
                              'newer arrived [s]', (0.0, 10.0)),
    'stale_cycles': Parameter(3, 'cycles a sonar may miss before it is no longer waited for',
                              (1, 1000)),
    'sonar_timeout': Parameter(1.0, 'dead reckoning at every odometry sample after this long '
                               'without sonar readings [s]', (0.1, 60.0)),
}


def parameters() -> Dict[str, Parameter]:
    """Return every ``sonar_localizer`` parameter by name, with its default."""
    return {**NODE_PARAMETERS, **dataclass_parameters(FILTER_PARAMETERS, LocalizationParams()),
            **dataclass_parameters(NOISE_PARAMETERS, ProcessNoise(), 'process_noise.')}


@dataclass(frozen=True)
class LocalizerConfiguration:
    """What the ``sonar_localizer`` parameters configure (:func:`localizer_configuration`).

    Attributes:
        params: The filter's parameters, process noise included.
        values: Every parameter's value, by name.
    """

    params: LocalizationParams
    values: Dict[str, Any]


def _fields(table: dict, instance, values: Mapping[str, Any], prefix: str = '') -> dict:
    """Dataclass field values of a table's parameters (the "off" value -> None)."""
    return {name[len(prefix):]: field_value(p, values[name])
            for name, p in dataclass_parameters(table, instance, prefix).items()}


def localizer_configuration(overrides: Optional[Mapping[str, Any]] = None
                            ) -> LocalizerConfiguration:
    """Return the configuration of the defaults with ``overrides`` (by name) on top.

    Raises:
        ValueError: An unknown name (naming the nearest declared one), a value of the wrong
            type, out of its limits or not a choice, or values the filter refuses together.
    """
    values = parameter_values(NODE, parameters(), overrides)
    try:
        noise = ProcessNoise(**_fields(NOISE_PARAMETERS, ProcessNoise(), values,
                                       'process_noise.'))
        params = replace(LocalizationParams(**_fields(FILTER_PARAMETERS, LocalizationParams(),
                                                      values)), noise=noise)
    except (TypeError, ValueError) as err:
        raise ValueError(f'{NODE}: ' + name_parameters(
            str(err), {'ProcessNoise': 'process_noise.', 'LocalizationParams': ''})) from None
    if params.min_range >= params.max_range:
        raise ValueError('parameters min_range and max_range: need min_range < max_range')
    return LocalizerConfiguration(params=params, values=values)


__all__ = ['FILTER_PARAMETERS', 'localizer_configuration', 'LocalizerConfiguration', 'NODE',
           'NODE_PARAMETERS', 'NOISE_PARAMETERS', 'parameters']
