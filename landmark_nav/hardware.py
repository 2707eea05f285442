"""Description of the robot's hardware shared by the driver, the nodes and the simulator.

The Pioneer 2-DX sonar ring (ARIA ``p2dx.p``): transducer poses, cone width and the range
limits. The simulator (:mod:`landmark_nav.sim.sonar`), the P2OS driver
(:mod:`landmark_nav.drivers.p2os`) and the nodes import these from here, so a node running
on the real robot never imports the simulator.
"""

import math
from typing import Tuple

import numpy as np

#: ARIA p2dx.p sonar mounting (docs/protocols/p2os.md §6): x [mm], y [mm], heading [deg] in
#: base_link (relative to the centre of rotation), in ARIA's transducer order.
P2DX_SONAR_MM_DEG: Tuple[Tuple[float, float, float], ...] = (
    (69, 136, 90), (114, 119, 50), (148, 78, 30), (166, 27, 10),
    (166, -27, -10), (148, -78, -30), (114, -119, -50), (69, -136, -90),
    (-157, -136, -90), (-203, -119, -130), (-237, -78, -150), (-255, -27, -170),
    (-255, 27, 170), (-237, 78, 150), (-203, 119, 130), (-157, 136, 90),
)

#: (16, 3) sonar poses ``[x, y, yaw]`` in base_link [m, m, rad], ARIA p2dx order.
SONAR_MOUNTS = np.array([(x / 1000.0, y / 1000.0, math.radians(h))
                         for x, y, h in P2DX_SONAR_MM_DEG])
SONAR_MOUNTS.setflags(write=False)
#: Cone width of one transducer [rad].
SONAR_FIELD_OF_VIEW = math.radians(25.0)
#: Default minimum and maximum reported range [m].
SONAR_MIN_RANGE = 0.1
SONAR_MAX_RANGE = 5.0

__all__ = ['P2DX_SONAR_MM_DEG', 'SONAR_FIELD_OF_VIEW', 'SONAR_MAX_RANGE', 'SONAR_MIN_RANGE',
           'SONAR_MOUNTS']
