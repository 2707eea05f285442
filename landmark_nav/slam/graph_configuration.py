"""Node parameters of the graph back end: the documented fields of its parameter dataclasses.

Tables ``{field: (description, limits or None, choices or None)}`` of
:class:`~landmark_nav.slam.keyframe_graph.GraphParams` (parameters named as the fields) and
of :class:`~landmark_nav.slam.loop_closure.LoopParams` (``loop.`` + the field); the
defaults are the dataclasses' (:mod:`landmark_nav.parameter_tables`). The ``graph_slam``
node declares them (:func:`graph_parameters`) and builds the parameters from their values
(:func:`graph_params`); fields not listed keep their defaults. The odometry checks take
``ekf_slam``'s parameters (:func:`odometry_check_parameters`).
"""

import math
from typing import Any, Dict, Mapping

from landmark_nav.parameter_tables import dataclass_parameters, name_parameters, Parameter
from landmark_nav.slam.configuration import FRONTEND_PARAMETERS
from landmark_nav.slam.keyframe_graph import GraphParams
from landmark_nav.slam.loop_closure import LoopParams
from landmark_nav.slam.odometry_checks import OdometryLimits

GRAPH_PARAMETERS = {
    'keyframe_distance': ('a scan is a keyframe once the odometry travelled this far since '
                          'the last one (slam_toolbox minimum_travel_distance) [m]',
                          (0.001, 100.0), None),
    'keyframe_turn': ('...or turned this much since it (minimum_travel_heading) [rad]',
                      (0.001, 10.0), None),
    'max_range': ('returns at or beyond this are not used [m]', (0.1, 1000.0), None),
    'match_keyframes': ("previous keyframes whose scans a new keyframe's scan is matched "
                        'onto (point-to-line ICP)', (1, 100), None),
    'scan_accept': ('confidence of the region the difference of the scan-matched motion and '
                    'the odometry must lie in (chi-square, 3 dof)', (1e-6, 0.999999999999),
                    None),
    'fit_pairs': ('independent residuals an ICP fit is worth (its information)',
                  (1e-6, 1e6), None),
    'side_starts': ("ICP also starts from the odometry's heading +- this many heading stds; "
                    '0 = off', (0.0, 100.0), None),
    'loop_kernel': ('Cauchy kernel width of loop factors (whitened residual units)',
                    (1e-3, 1e3), None),
    'loop_iterations': ('extra iSAM2 updates after a loop closure', (0, 100), None),
    'loop_floor': ('least std [x, y, yaw] of a loop factor [m, m, rad]', None, None),
    'loops': ('close loops (place recognition and verification)', None, None),
}

LOOP_PARAMETERS = {
    'min_separation_m': ('path travelled between an old keyframe and the current one before '
                         'the old one is a loop candidate [m]', (0.01, 1e6), None),
    'neighbourhood_m': ('the old keyframe nearest the estimate within the search window plus '
                        'this anchors the submap [m]', (0.01, 1e3), None),
    'submap_keyframes': ('the submap is the anchor and half this many keyframes either side '
                         'along the chain', (1, 1000), None),
    'trail_keyframes': ("previous keyframes' scans the free-space check moves by the loop",
                        (0, 1000), None),
    'window_sigmas': ("search window half widths in the keyframe marginal's stds",
                      (0.01, 100.0), None),
    'window_xy': ('(min, max) translation half width of the search [m]', None, None),
    'window_yaw': ('(min, max) heading half width of the search [rad]', None, None),
    'min_score': ("least mean likelihood of the search's best pose", (0.0, 1.0), None),
    'min_overlap': ("least share of the scan's points near the submap after ICP",
                    (0.0, 1.0), None),
    'max_rms': ('largest ICP RMS residual of a loop [m]', (1e-4, 10.0), None),
    'max_ambiguity': ('largest ratio of the best score elsewhere to the best (ambiguous)',
                      (0.0, 1.0), None),
    'max_contradiction': ("largest share of a trail scan's points in the submap's free space",
                          (0.0, 1.0), None),
}


#: Parameters holding a list of this many numbers > 0.
LIST_LENGTHS = {'loop_floor': 3, 'loop.window_xy': 2, 'loop.window_yaw': 2}


def graph_parameters() -> Dict[str, Parameter]:
    """Return every graph parameter by name (``loop.`` for loop closure's), with its default."""
    out = dataclass_parameters(GRAPH_PARAMETERS, GraphParams())
    out.update(dataclass_parameters(LOOP_PARAMETERS, LoopParams(), 'loop.'))
    return out


def odometry_check_parameters() -> Dict[str, Parameter]:
    """Return the odometry checks' parameters (``ekf_slam``'s, same names and limits)."""
    table = {}
    for k in OdometryLimits.__dataclass_fields__:
        description, limits, choices = FRONTEND_PARAMETERS[k]
        table[k] = (description.replace('the filter', 'the graph'), limits, choices)
    return dataclass_parameters(table, OdometryLimits())


def odometry_limits(values: Mapping[str, Any]) -> OdometryLimits:
    """Return the odometry checks' parameters from their values by name."""
    return OdometryLimits(**values)


def graph_params(values: Mapping[str, Any]) -> GraphParams:
    """Return the graph's parameters from parameter values by name (defaults for the rest).

    Raises:
        ValueError: A list of another length or with a value that is not a finite number
            > 0, or a value the dataclasses refuse (one line naming the parameter).
    """
    for name, n in LIST_LENGTHS.items():
        value = values.get(name)
        if value is not None and (len(value) != n or not all(
                math.isfinite(v) and v > 0 for v in value)):
            raise ValueError(f'parameter {name}: expected {n} finite numbers > 0, got '
                             f'{list(value)!r}')
    as_field = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    try:
        loop = LoopParams(**{k[5:]: v for k, v in as_field.items() if k.startswith('loop.')})
        return GraphParams(loop=loop, **{k: v for k, v in as_field.items()
                                         if not k.startswith('loop.')})
    except (TypeError, ValueError) as err:
        raise ValueError('graph_slam: ' + name_parameters(
            str(err), {'LoopParams': 'loop.', 'GraphParams': ''})) from None


__all__ = ['GRAPH_PARAMETERS', 'graph_parameters', 'graph_params', 'LOOP_PARAMETERS',
           'odometry_check_parameters', 'odometry_limits']
