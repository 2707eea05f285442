"""Names shared by the simulation recorders: the ground-truth file, frame ids, wheel joints.

:mod:`.record` (the 2-D scenarios, and the dispatcher to the other recorders),
:mod:`.camera_record` and :mod:`.park_road_record` write bag directories of one layout: the
MCAP file with ``ground_truth.yaml`` beside it and REP 105 frames. The names live here, below
all three, so that the recorders need not import each other.
"""

from typing import Any

import yaml

GROUND_TRUTH_FILE = 'ground_truth.yaml'
WHEEL_JOINTS = ('left_wheel_joint', 'right_wheel_joint')
MAP_FRAME, ODOM_FRAME, BASE_FRAME, LASER_FRAME = 'map', 'odom', 'base_link', 'laser'

#: PyYAML's safe loader on libyaml's parser where PyYAML was built with it (the same
#: constructor and resolver as ``yaml.safe_load``, the parsing about ten times faster).
_SAFE_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


def read_ground_truth_file(path) -> Any:
    """Return the content of a ``ground_truth.yaml`` file (``yaml.safe_load``'s)."""
    with open(path) as f:
        return yaml.load(f, Loader=_SAFE_LOADER)


__all__ = ['BASE_FRAME', 'GROUND_TRUTH_FILE', 'LASER_FRAME', 'MAP_FRAME', 'ODOM_FRAME',
           'read_ground_truth_file', 'WHEEL_JOINTS']
