"""The ``ekf_slam`` configuration: its parameters, the shipped defaults, the chapter profile.

One description of the ``ekf_slam`` node's parameters serves the node (which declares
them with these defaults, descriptions and limits) and the offline tools (``landmark_nav
evaluate --params-file / --set``, the benchmarks), so that both run one configuration:
:func:`parameters` lists every parameter with its shipped default and
:func:`slam_configuration` turns parameter values into the objects the front end and the
filter take (:class:`SlamConfiguration`), checking names, types, limits and choices as the
node does.

Defaults. The parameter dataclasses' own defaults (:class:`~.slam_params.SlamParams`,
:class:`~.frontend.FrontendParams`) are the corner chapter's filter, the method the
simulator figures and the unit tests measure. The shipped configuration (the node's
declared defaults, ``config/ekf_slam.yaml`` and ``landmark_nav evaluate`` without flags)
sets :data:`REAL_DATA` on top of them: the options measured on the Carmen logs
(consistent heading, line noise from each fit's residuals, the free-space check, recovery
after a scan that paired nothing, no pair whose gate may hold another feature, corners and
lines, the scan-matched motion fused with the odometry). :data:`CHAPTER` gives those
options back their chapter values: the profile ``config/ekf_slam_chapter.yaml``.
"""

from dataclasses import dataclass, replace
import math
from typing import Any, Dict, Mapping, Optional, Tuple

from landmark_nav.laser.lines import LINE_PARAMETERS, LineParams
from landmark_nav.parameter_tables import (check_value, dataclass_parameters, field_value,
                                           name_parameters, Parameter, parameter_values)
from landmark_nav.slam.features import LANDMARK_TYPES
from landmark_nav.slam.frontend import (FrontendParams, odometry_noise_model,
                                        ODOMETRY_NOISE_MODELS)
from landmark_nav.slam.keyframes import KeyframeParams
from landmark_nav.slam.slam_params import JACOBIANS, OdometryNoise, SlamParams

NODE = 'ekf_slam'

#: SlamParams fields -> (description, limits, choices[, value standing for None]).
SLAM_PARAMETERS = {
    'sigma_range': ('default range std when a corner has no covariance [m]', None, None),
    'sigma_bearing': ('default bearing std [rad]', None, None),
    'r_scale': ('factor on the corner covariances (>= 1 inflates)', None, None),
    'range_floor': ('std added in quadrature to every range [m]', None, None),
    'bearing_floor': ('std added in quadrature to every bearing [rad]', None, None),
    'position_floor': ('isotropic corner position std added in quadrature [m]', None, None),
    'max_range': ('observations farther than this are rejected [m]', None, None),
    'association': ('data association: icnn or jcbb', None, ['icnn', 'jcbb']),
    'bisector_gate': ('largest bisector difference of a corner pair [rad]', None, None),
    'opening_gate': ('largest opening difference of a corner pair [rad]', None, None),
    'min_view_margin': ('reject corners with an arm seen within this of edge-on [rad]',
                        None, None),
    'gate_probability': ('confidence of the compatibility gate (eq. 55)', None, None),
    'new_landmark_probability': ('gate inside which an unmatched corner is ambiguous',
                                 None, None),
    'candidate_probability': ('gate confidence for matching candidates', None, None),
    'confirm_hits': ('observations a candidate needs to enter the map', None, None),
    'confirm_window': ('...within this many consecutive scans', None, None),
    'max_landmarks': ('map size budget (see map_full)', None, None),
    'map_full': ('when the map is full: evict the least recently seen landmark, or reject',
                 None, ['evict', 'reject']),
    'mode': ('slam, or localization on the load_map map (no new landmarks)', None,
             ['slam', 'localization']),
    'jcbb_max_nodes': ('node budget of JCBB per scan', None, None),
    'psd_tolerance': ('relative jitter of the PSD test of P', None, None),
    'psd_check_interval': ('test P every this many updates', None, None),
    'max_update_iterations': ('largest number of linearisations of one update (1 = plain EKF)',
                              None, None),
    'relinearize_ratio': ('re-linearise when a landmark moves by more than this fraction of its '
                          'range', None, None),
    'jacobians': ("linearisation: standard (the chapter's), observability_gain (consistent "
                  'heading), first_estimates, observability or invariant', None,
                  list(JACOBIANS)),
    'line_residual_factor': ('k: each line end gets an offset std of k times its fit residual '
                             'std', None, None),
    'free_space_check': ('confidence of the free-space check of each hypothesis (needs '
                         'visibility); 0 = off', None, None, 0.0),
    'recovery_probability': ('gate confidence of the second association of a scan that paired '
                             'nothing; 0 = off', None, None, 0.0),
    'recovery_pairs': ('fewest pairs of that recovery', None, None),
    'spurious_limit': ('largest expected number of other features in a pair gate (needs '
                       'visibility); 0 = off', None, None, 0.0),
}
#: OdometryNoise fields (parameters ``odometry.*``) -> description.
ODOMETRY_PARAMETERS = {
    'sigma_xy_per_sqrt_m': 'odometry translation std per sqrt(m) [m/sqrt(m)]',
    'sigma_yaw_per_sqrt_m': 'odometry heading std per sqrt(m) [rad/sqrt(m)]',
    'sigma_yaw_per_sqrt_rad': 'odometry heading std per sqrt(rad) turned [rad/sqrt(rad)]',
    'sigma_xy_floor': 'odometry translation std floor per step [m]',
    'sigma_yaw_floor': 'odometry heading std floor per step [rad]',
}
#: FrontendParams fields -> (description, limits, choices).
FRONTEND_PARAMETERS = {
    'deskew': ('move each corner through the odometry motion up to its beam time', None,
               None),
    'max_speed': ('fastest plausible translation of the base [m/s] (odometry check; '
                  'Pioneer 3-DX: 1.2)', (1e-3, 100.0), None),
    'max_turn_rate': ('fastest plausible rotation of the base [rad/s] (odometry check; '
                      'Pioneer 3-DX: 5.2)', (1e-3, 100.0), None),
    'jump_sigmas': ('odometry noise stds allowed on top of the speed limits', (0.1, 100.0),
                    None),
    'min_step_s': ('smallest elapsed time the odometry check uses [s]', (1e-6, 10.0), None),
    'max_backward_s': ('odometry older than this, restart_messages times in a row, restarts '
                       'the filter (a restarted source) [s]', (1e-3, 1e6), None),
    'restart_messages': ('consecutive odometry samples older than max_backward_s that restart '
                         'the filter (one stamp never does)', (1, 1000), None),
    'buffer_s': ('odometry kept behind the newest sample [s]', (0.1, 3600.0), None),
    'scan_matching': ("predict with the scan's point-to-line ICP motion against the previous "
                      'scan where it agrees with the odometry (needs scan, visibility: true)',
                      None, None),
    'scan_matching_noise': ("U of a scan-matched motion: 'k_d=.. k_theta=.. k_dtheta=..', "
                            'pioneer or simulator', None, None),
    'scan_matching_max_range': ('returns at or beyond this are not matched [m]',
                                (0.1, 1000.0), None),
    'scan_matching_accept': ('confidence of the region the difference of the scan-matched '
                             'motion and the odometry must lie in (chi-square, 3 dof, U + V '
                             'at the larger motion)',
                             (1e-6, 1.0 - 1e-12), None),
    'scan_matching_fit_pairs': ('0: predict with the scan-matched motion and '
                                'scan_matching_noise; > 0: with the odometry and the '
                                "scan-matched motion fused, the latter's covariance from the "
                                'ICP fit worth this many independent residuals',
                                (0.0, 1e6), None),
    'scan_matching_side_starts': ("k > 0: ICP also starts from the odometry's heading +- k "
                                  'heading stds on every step, the solution with the most '
                                  'pairs first (3 ICPs a step); 0: off', (0.0, 100.0), None),
}
#: KeyframeParams fields (parameters ``keyframe.*``) -> (description, limits, choices).
KEYFRAME_PARAMETERS = {
    'min_travel_m': ('a scan is a keyframe (landmark update, map management) once the '
                     'odometry travelled this far since the last one; the scans between only '
                     'move the pose; 0 (with min_turn_rad 0) = every scan [m]',
                     (0.0, 100.0), None),
    'min_turn_rad': ('...or turned this much since it [rad]', (0.0, 10.0), None),
}
#: The other parameters: name -> (default, description, limits, choices).
NODE_PARAMETERS = {
    'odometry.model': ('', "'' = the odometry.* values; else pioneer, simulator or drift gains "
                       "'k_d=.. k_theta=.. k_dtheta=..' (replace them)", None, None),
    'landmarks': ('both', 'landmark types mapped: corners (corners/features), lines (extracted '
                  'from scan) or both', None, list(LANDMARK_TYPES)),
    'max_beams': (20000, 'scans with more beams are dropped as oversized (real 2-D lasers '
                  'have up to a few thousand)', (1, 100000000), None),
    'structural_corners_only': (False, 'map only the corners the extractor labels structural '
                                '(both arms >= 0.2 m and 6 beams; field structural of '
                                'corners/features)',
                                None, None),
    'visibility': (True, 'visibility-aware pruning: a landmark the scan sees through is '
                   'missed (needs scan)', None, None),
    'laser_sigma_range': (0.01, "the laser's stated 1-sigma range noise [m] (visibility "
                          'tolerance)', (0.0, 10.0), None),
    'laser_pose': ([0.0, 0.0, 0.0], 'laser pose [x, y, yaw] in base_link', None, None),
    'map_frame': ('map', 'frame of the estimates', None, None),
    'base_frame': ('base_link', 'robot frame', None, None),
    'map_file': ('landmarks.yaml', 'file written by the save_map service: .npz = the filter '
                 'map (load_map format), else YAML (relative: under $ROS_HOME/landmark_nav, '
                 'default ~/.ros/landmark_nav)', None, None),
    'load_map': ('', "'' = start with an empty map; else a .npz map (save_map with map_file "
                 '*.npz, landmark_nav evaluate --save-map) the filter starts on at the first '
                 'odometry pose (relative: as map_file)', None, None),
    'map_pose_sigma': ([0.0, 0.0, 0.0], '1-sigma [x, y, yaw] of that start pose [m, m, rad]',
                       None, None),
    'path_max_poses': (2000, 'poses kept in the published path (the latest)', (1, 1000000),
                       None),
    'display_period': (0.5, 'period of the path and landmarks topics (published when '
                       'changed) [s]', (0.01, 3600.0), None),
    'odometry_timeout': (1.0, 'wall time without odometry after which waiting corner sets '
                         'the odometry reaches are processed (last pose held) [s]',
                         (0.01, 3600.0), None),
}
#: ``lines.*``: the line extractor's parameters but ``join_occluded`` (each side of an
#: occluder is its own line observation, :func:`.features.extract_scan_features`).
SLAM_LINE_PARAMETERS = {k: v for k, v in LINE_PARAMETERS.items() if k != 'join_occluded'}

#: The shipped configuration's options on top of the dataclasses' (the chapter's) defaults,
#: measured on the Carmen logs (module docstring), as parameter values (0 = off).
REAL_DATA: Dict[str, Any] = {
    'landmarks': 'both',
    'jacobians': 'observability_gain',
    'line_residual_factor': 2.0,
    'free_space_check': 0.95,
    'recovery_probability': 0.99,
    'spurious_limit': 0.05,  # the gate's miss rate, 1 - gate_probability
    'scan_matching': True,
    'scan_matching_fit_pairs': 0.3,
    'scan_matching_side_starts': 2.5,
    'keyframe.min_travel_m': 0.1,
    'keyframe.min_turn_rad': 0.1,
}


def _as_parameter(name: str, value: Any) -> Any:
    """Return a dataclass field value in parameter form (None -> its "off" value)."""
    if value is None:
        return SLAM_PARAMETERS[name][3]
    return value


def _chapter_value(name: str) -> Any:
    """Return the dataclasses' (the chapter's) default of a :data:`REAL_DATA` option."""
    if name == 'landmarks':
        return 'corners'
    if name.startswith('keyframe.'):
        return getattr(KeyframeParams(), name[len('keyframe.'):])
    return _as_parameter(name, getattr(
        SlamParams() if name in SLAM_PARAMETERS else FrontendParams(), name))


#: The chapter profile: the :data:`REAL_DATA` options at the dataclasses' defaults.
CHAPTER: Dict[str, Any] = {name: _chapter_value(name) for name in REAL_DATA}


def parameters() -> Dict[str, Parameter]:
    """Return every ``ekf_slam`` parameter by name, with its shipped default."""
    options = {k: v for k, v in REAL_DATA.items() if k != 'landmarks'}
    slam = SlamParams(**{k: (None if v == 0.0 and SLAM_PARAMETERS[k][3:] else v)
                         for k, v in options.items() if k in SLAM_PARAMETERS})
    keyframe = KeyframeParams(**{k[len('keyframe.'):]: v for k, v in options.items()
                                 if k.startswith('keyframe.')})
    frontend = FrontendParams(keyframe=keyframe, **{k: v for k, v in options.items()
                                                    if k in FRONTEND_PARAMETERS})
    out = dataclass_parameters(SLAM_PARAMETERS, slam)
    pioneer = ODOMETRY_NOISE_MODELS['pioneer']
    for name, description in ODOMETRY_PARAMETERS.items():
        out[f'odometry.{name}'] = Parameter(float(getattr(pioneer, name)), description,
                                            (0.0, 10.0))
    out.update(dataclass_parameters(FRONTEND_PARAMETERS, frontend))
    out.update(dataclass_parameters(KEYFRAME_PARAMETERS, keyframe, 'keyframe.'))
    out.update(dataclass_parameters(SLAM_LINE_PARAMETERS, LineParams(), 'lines.'))
    out.update({k: Parameter(*v) for k, v in NODE_PARAMETERS.items()})
    return out


def default_values() -> Dict[str, Any]:
    """Return the shipped default of every parameter (what ``config/ekf_slam.yaml`` holds)."""
    return {name: p.default for name, p in parameters().items()}


@dataclass(frozen=True)
class SlamConfiguration:
    """What the ``ekf_slam`` parameters configure (:func:`slam_configuration`).

    Attributes:
        params: The filter's parameters (odometry noise included).
        frontend: The front end's parameters.
        landmarks: ``'corners'``, ``'lines'`` or ``'both'``.
        visibility: Give the filter each scan's geometry (pruning, checks that need it).
        line_params: The line extractor's parameters for line landmarks (``lines.*``).
        laser_pose: Laser ``(x, y, yaw)`` in ``base_link``.
        laser_sigma_range: The laser's 1-sigma range noise [m].
        values: Every parameter's value, by name.
    """

    params: SlamParams
    frontend: FrontendParams
    landmarks: str
    visibility: bool
    line_params: LineParams
    laser_pose: Tuple[float, float, float]
    laser_sigma_range: float
    values: Dict[str, Any]


def _fields(table: dict, values: Mapping[str, Any], instance,
            prefix: str = '') -> Dict[str, Any]:
    """Dataclass field values of the parameters of ``table`` (the "off" value -> None)."""
    return {name[len(prefix):]: field_value(p, values[name])
            for name, p in dataclass_parameters(table, instance, prefix).items()}


#: The dataclasses of the configuration -> the prefix of their parameters.
PARAMETER_PREFIXES = {'SlamParams': '', 'FrontendParams': '', 'KeyframeParams': 'keyframe.',
                      'LineParams': 'lines.', 'OdometryNoise': 'odometry.'}


def slam_configuration(overrides: Optional[Mapping[str, Any]] = None) -> SlamConfiguration:
    """Return the configuration of the shipped defaults with ``overrides`` on top.

    Args:
        overrides: Parameter values by name (as a parameter file or ``-p`` gives them).

    Raises:
        ValueError: An unknown name (naming the nearest known one), a value of the wrong
            type, out of its limits or not a choice, or values the filter refuses
            together (one line naming the parameter).
    """
    values = parameter_values(NODE, parameters(), overrides)
    model = values['odometry.model'].strip()
    try:
        noise = (odometry_noise_model(model) if model else OdometryNoise(**{
            name: values[f'odometry.{name}'] for name in ODOMETRY_PARAMETERS}))
    except ValueError as err:
        raise ValueError(f'parameter odometry.model: {err}') from None
    try:
        params = SlamParams(odometry=noise, **_fields(SLAM_PARAMETERS, values, SlamParams()))
        keyframe = KeyframeParams(**_fields(KEYFRAME_PARAMETERS, values, KeyframeParams(),
                                            'keyframe.'))
        frontend = FrontendParams(keyframe=keyframe,
                                  **_fields(FRONTEND_PARAMETERS, values, FrontendParams()))
        line_params = replace(LineParams(), **_fields(SLAM_LINE_PARAMETERS, values,
                                                      LineParams(), 'lines.'))
    except (TypeError, ValueError) as err:
        raise ValueError(f'{NODE}: {name_parameters(str(err), PARAMETER_PREFIXES)}') from None
    if frontend.scan_matching and not values['visibility']:
        raise ValueError('parameter scan_matching needs the scan geometry: set '
                         'visibility: true')
    for name in ('laser_pose', 'map_pose_sigma'):
        v = values[name]
        if len(v) != 3 or not all(math.isfinite(x) for x in v):
            raise ValueError(f'parameter {name} must be 3 finite numbers')
    if any(v < 0.0 for v in values['map_pose_sigma']):
        raise ValueError('parameter map_pose_sigma must be 3 finite numbers >= 0')
    return SlamConfiguration(params=params, frontend=frontend, landmarks=values['landmarks'],
                             visibility=values['visibility'], line_params=line_params,
                             laser_pose=tuple(values['laser_pose']),
                             laser_sigma_range=values['laser_sigma_range'], values=values)


def chapter_configuration() -> SlamConfiguration:
    """Return the chapter profile's configuration (:data:`CHAPTER` on the defaults)."""
    return slam_configuration(CHAPTER)


__all__ = ['CHAPTER', 'chapter_configuration', 'check_value', 'default_values',
           'FRONTEND_PARAMETERS', 'KEYFRAME_PARAMETERS', 'NODE_PARAMETERS', 'ODOMETRY_PARAMETERS',
           'Parameter', 'parameters', 'REAL_DATA', 'SLAM_LINE_PARAMETERS', 'SLAM_PARAMETERS',
           'slam_configuration', 'SlamConfiguration']
