"""The ``road_classifier`` configuration: its parameters, shared by the node and offline.

One description of the node's parameters serves the node (which declares them with these
defaults, descriptions and limits) and the ``landmark_nav evaluate-road-*`` commands'
``--params-file / --set``: :func:`parameters` lists every parameter with its default and
:func:`road_configuration` checks parameter values as the node does and builds the laser
mount, the terrain classifier's :class:`~.terrain_params.TerrainParams`, the fusion's
:class:`~.fusion.FusionParams` and the outline's :class:`~.outline.OutlineParams`.
"""

from dataclasses import dataclass
import math
from typing import Any, Dict, Mapping, Optional, Tuple

from landmark_nav.parameter_tables import Parameter, parameter_values
from landmark_nav.road.fusion import FusionParams
from landmark_nav.road.laser_mount import LaserMount
from landmark_nav.road.outline import METHODS, OutlineParams
from landmark_nav.road.terrain_params import TerrainParams

NODE = 'road_classifier'

#: TerrainParams fields the node exposes -> (description, limits).
TERRAIN_PARAMETERS = {
    'window': ('roughness window along the scan (about a wheel base) [m]', (0.05, 5.0)),
    'roughness_max': ('largest roughness of a traversable reading [m]', (1e-4, 1.0)),
    'step_max': ('largest height step inside a segment [m]', (1e-3, 1.0)),
    'height_max': ('largest |height| of a ground reading [m]', (1e-3, 5.0)),
    'min_width': ('narrowest traversable segment (the robot width) [m]', (0.05, 10.0)),
    'obstacle_height': ('readings higher than this above the ground are obstacles [m]',
                        (1e-3, 5.0)),
    'range_sigma': ("the laser's 1-sigma range noise: floor of a piece's height noise [m]",
                    (1e-5, 1.0)),
}


def parameters() -> Dict[str, Parameter]:
    """Return every ``road_classifier`` parameter by name, in declaration order."""
    laser, terrain = LaserMount(), TerrainParams()
    return {
        'scan_topic': Parameter('tilted_scan', 'topic of the tilted laser scan'),
        'laser_mount': Parameter(
            [laser.x, laser.y, laser.z, laser.roll, laser.pitch, laser.yaw],
            'laser pose in base_link: x, y, z [m] (z above the ground), roll, pitch '
            '(> 0 tilts down), yaw [rad]'),
        'camera_mount': Parameter([0.2, 0.0, 1.0, 0.0, math.radians(12.0), 0.0],
                                  'camera_link pose in base_link: x, y, z [m], roll, pitch, '
                                  'yaw [rad]'),
        **{k: Parameter(getattr(terrain, k), doc, lim)
           for k, (doc, lim) in TERRAIN_PARAMETERS.items()},
        'robot_width': Parameter(FusionParams().robot_width, 'robot width: corridors overlap '
                                 'by more [m]', (0.05, 10.0)),
        'max_distance': Parameter(FusionParams().max_distance, 'farthest intersection line '
                                  'and grid extent ahead [m]', (1.0, 100.0)),
        'history': Parameter(FusionParams().history, 'scans kept for the corridors (eq. 29)',
                             (1, 1000)),
        'outline_method': Parameter(OutlineParams().method, 'road criterion of the vision '
                                    "outline: 'learned' (road probability of the packaged "
                                    "perceptron), 'cnn' (its mean with the packaged "
                                    "convolutional network's) or 'chapter' (eqs. 26-28)",
                                    None,
                                    list(METHODS)),
        'k_limit': Parameter(OutlineParams().k_limit, 'road where P_c + P_e exceeds this '
                             "(eq. 26; outline_method 'chapter')", (0.0, 2.0)),
        'min_outline_confidence': Parameter(OutlineParams().min_confidence, 'an outline of '
                                            'lower confidence (seed road probability, border '
                                            'contrast) is flagged and not fused '
                                            "(outline_method 'learned' or 'cnn')", (0.0, 1.0)),
        'min_outline_row_fill': Parameter(OutlineParams().min_row_fill, 'an outline covering '
                                          "less of its rows' spans (gaps around cars, along "
                                          'pavement) is flagged and not fused '
                                          "(outline_method 'learned' or 'cnn'; calibrated "
                                          "for 'cnn', 0.912 for 'learned')", (0.0, 1.0)),
        'seed_thickness_px': Parameter(9, 'thickness of the seed band [px]', (1, 200)),
        'outline_timeout': Parameter(0.5, 'an outline older than this (scan time) is not '
                                     'fused [s]', (0.0, 60.0)),
        'grid_resolution': Parameter(0.1, 'cell size of road/grid [m]', (0.01, 2.0)),
        'grid_half_width': Parameter(6.0, 'road/grid extends this far left and right [m]',
                                     (0.5, 100.0)),
        'base_frame': Parameter('base_link', 'frame of the outputs'),
        'publish_debug_image': Parameter(False, 'publish road/debug_image'),
    }


@dataclass(frozen=True)
class RoadConfiguration:
    """What the ``road_classifier`` parameters configure (:func:`road_configuration`).

    Attributes:
        laser: The tilted laser's pose in base_link.
        camera_mount: camera_link's pose in base_link (x, y, z, roll, pitch, yaw).
        terrain: The terrain classifier's parameters.
        fusion: The laser corridors' and routes' parameters.
        outline: The vision outline's parameters.
        seed_px: Thickness of the seed band [px].
        values: Every parameter's value, by name.
    """

    laser: LaserMount
    camera_mount: Tuple[float, ...]
    terrain: TerrainParams
    fusion: FusionParams
    outline: OutlineParams
    seed_px: int
    values: Dict[str, Any]


def road_configuration(overrides: Optional[Mapping[str, Any]] = None) -> RoadConfiguration:
    """Return the configuration of the defaults with ``overrides`` (by name) on top.

    Raises:
        ValueError: An unknown name (naming the nearest declared one), a value of the wrong
            type, out of its limits, or values refused together (one line naming the
            parameter).
    """
    v = parameter_values(NODE, parameters(), overrides)
    camera = v['camera_mount']
    if len(camera) != 6 or not all(math.isfinite(x) for x in camera) or camera[2] <= 0:
        raise ValueError(f'parameter camera_mount must be 6 finite numbers with z > 0; got '
                         f'{camera}')
    return RoadConfiguration(
        laser=LaserMount.from_sequence(v['laser_mount']), camera_mount=tuple(camera),
        terrain=TerrainParams(**{k: v[k] for k in TERRAIN_PARAMETERS}),
        fusion=FusionParams(robot_width=v['robot_width'], max_distance=v['max_distance'],
                            history=v['history']),
        outline=OutlineParams(k_limit=v['k_limit'], method=v['outline_method'],
                              min_confidence=v['min_outline_confidence'],
                              min_row_fill=v['min_outline_row_fill']),
        seed_px=v['seed_thickness_px'],
        values=v)


__all__ = ['NODE', 'parameters', 'road_configuration', 'RoadConfiguration',
           'TERRAIN_PARAMETERS']
