"""The ``corridor_follower`` configuration: its parameters, shared by the node and offline.

One description of the node's parameters serves the node (which declares them with these
defaults, descriptions and limits) and ``landmark_nav evaluate-corridor --params-file /
--set``: :func:`parameters` lists every parameter with its default and
:func:`follower_configuration` checks parameter values as the node does and builds the
estimation's :class:`~.follower.FollowerConfig` and the controller's
:class:`~.controller.ControllerParams`.
"""

from dataclasses import dataclass
import math
from typing import Any, Dict, Mapping, Optional

from landmark_nav.corridor.controller import ControllerParams
from landmark_nav.corridor.follower import FollowerConfig
from landmark_nav.parameter_tables import dataclass_parameters, Parameter, parameter_values

NODE = 'corridor_follower'

#: FollowerConfig fields (the estimation) -> (description, limits, choices).
ESTIMATION_PARAMETERS = {
    'corridor_width': ('wall-to-wall width [m]', (0.3, 20.0), None),
    'corridor_height': ('floor-to-ceiling height [m]; 0: ceiling edges not used',
                        (0.0, 20.0), None),
    'centre_line': ('the floor has a line along the corridor centre', None, None),
    'camera_mount': ('camera_link pose in base_link: x, y, z [m] (z = height above the '
                     'floor), roll, pitch, yaw [rad]', None, None),
    'line_method': ('image lines: segmented_hough (the chapter), hough_p or lsd', None,
                    ['segmented_hough', 'hough_p', 'lsd']),
    'sigma_px': ('end-point noise of image line segments [px]', (0.05, 5.0), None),
    'sigma_angle_deg': ('direction noise of image line segments beyond their end-point noise '
                        '[deg]', (0.0, 10.0), None),
    'heading_std_floor_deg': ('added to the visual heading std [deg]', (0.0, 20.0), None),
    'lateral_std_floor': ('added to the visual lateral std [m]', (0.0, 2.0), None),
    'max_axis_angle_deg': ('the corridor VP must lie within this angle of the optical axis '
                           '[deg]', (1.0, 89.0), None),
    'wheel_separation': ('effective wheel separation [m]', (0.01, 5.0), None),
    'k_left': ('left wheel distance variance per metre [m^2/m]', (0.0, 1.0), None),
    'k_right': ('right wheel distance variance per metre [m^2/m]', (0.0, 1.0), None),
    'sigma_separation': ('std of the wheel separation per step [m]', (0.0, 1.0), None),
    'gate_chi2': ('NIS outlier gate (chi-square 2 dof; 13.8 = 99.9 %)', (1.0, 1000.0), None),
}
#: The node's interface parameters.
NODE_PARAMETERS = {
    'stale_timeout': Parameter(1.0, 'stop when no visual update was accepted for this long '
                               '[s]', (0.05, 60.0)),
    'compressed': Parameter(False, 'subscribe camera/image_raw/compressed'),
    'corridor_frame': Parameter('corridor', 'frame of corridor/pose'),
    'publish_debug_image': Parameter(False, 'publish corridor/debug_image'),
    'stamped_cmd_vel': Parameter(False, 'publish geometry_msgs/TwistStamped on cmd_vel'),
    'enabled': Parameter(False, 'drive at start-up (else wait for ~/enable)'),
}
#: ControllerParams fields -> (description, limits, choices).
CONTROL_PARAMETERS = {
    'speed': ('forward speed set-point [m/s]', (0.01, 3.0), None),
    'lateral_offset': ('lateral set-point [m], left of the direction of travel positive',
                       (-10.0, 10.0), None),
    'gain_lateral': ('turn per m driven per m of lateral error [1/m^2]', (0.01, 100.0), None),
    'gain_heading': ('turn per m driven per rad of heading error [1/m] (critically damped: '
                     '2 sqrt(gain_lateral))', (0.01, 100.0), None),
    'max_accel': ('forward acceleration limit [m/s^2]', (0.01, 10.0), None),
    'max_angular_speed': ('angular speed limit [rad/s]', (0.01, 10.0), None),
}


def parameters() -> Dict[str, Parameter]:
    """Return every ``corridor_follower`` parameter by name, in declaration order."""
    return {**dataclass_parameters(ESTIMATION_PARAMETERS, FollowerConfig()), **NODE_PARAMETERS,
            **dataclass_parameters(CONTROL_PARAMETERS, ControllerParams())}


@dataclass(frozen=True)
class CorridorConfiguration:
    """What the ``corridor_follower`` parameters configure (:func:`follower_configuration`).

    Attributes:
        follower: The estimation's configuration.
        controller: The controller's parameters.
        values: Every parameter's value, by name.
    """

    follower: FollowerConfig
    controller: ControllerParams
    values: Dict[str, Any]


def follower_configuration(overrides: Optional[Mapping[str, Any]] = None
                           ) -> CorridorConfiguration:
    """Return the configuration of the defaults with ``overrides`` (by name) on top.

    Raises:
        ValueError: An unknown name (naming the nearest declared one), a value of the wrong
            type, out of its limits or not a choice, or values refused together (one line
            naming the parameter).
    """
    v = parameter_values(NODE, parameters(), overrides)
    mount, height, width = v['camera_mount'], v['corridor_height'], v['corridor_width']
    if len(mount) != 6 or not all(math.isfinite(x) for x in mount):
        raise ValueError(f'parameter camera_mount must be 6 finite numbers; got {mount}')
    if not mount[2] > 0.0 or (height > 0.0 and mount[2] >= height):
        raise ValueError(f'parameter camera_mount: camera height {mount[2]} m must lie '
                         f'between floor and ceiling ({height} m)')
    if abs(v['lateral_offset']) >= width / 2:
        raise ValueError('parameter lateral_offset must lie inside the corridor')
    follower = FollowerConfig(**{k: (tuple(v[k]) if k == 'camera_mount' else v[k])
                                 for k in ESTIMATION_PARAMETERS})
    return CorridorConfiguration(follower=follower, controller=ControllerParams(
        **{k: v[k] for k in CONTROL_PARAMETERS}), values=v)


__all__ = ['CONTROL_PARAMETERS', 'CorridorConfiguration', 'ESTIMATION_PARAMETERS',
           'follower_configuration', 'NODE', 'NODE_PARAMETERS', 'parameters']
