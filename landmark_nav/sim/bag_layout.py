"""Names shared by the simulation recorders: the ground-truth file, frame ids, wheel joints.

:mod:`.record` (the 2-D scenarios, and the dispatcher to the other recorders),
:mod:`.camera_record` and :mod:`.park_road_record` write bag directories of one layout: the
MCAP file with ``ground_truth.yaml`` beside it and REP 105 frames. The names live here, below
all three, so that the recorders need not import each other.
"""

GROUND_TRUTH_FILE = 'ground_truth.yaml'
WHEEL_JOINTS = ('left_wheel_joint', 'right_wheel_joint')
MAP_FRAME, ODOM_FRAME, BASE_FRAME, LASER_FRAME = 'map', 'odom', 'base_link', 'laser'

__all__ = ['BASE_FRAME', 'GROUND_TRUTH_FILE', 'LASER_FRAME', 'MAP_FRAME', 'ODOM_FRAME',
           'WHEEL_JOINTS']
