"""Deterministic simulator: world, robot, odometry, laser and sonar, named scenarios.

Pure numpy (no rclpy, no ROS messages). SI units, radians, REP 103 frames (x forward,
y left, CCW yaw), REP 117 ranges (+inf = no return, -inf = too close). Yaw in outputs is
wrapped to [-pi, pi). All stamps are int nanoseconds; every scenario starts at
:data:`START_NS` (1_700_000_000 s). Same seed -> identical arrays, bit for bit.

Main entry point::

    from landmark_nav.sim import run_scenario
    res = run_scenario('office', seed=1)          # or 'hallway', 'calibration'
    for ev in res.events:                         # ordered by ev.stamp_ns
        ...                                       # TruthSample / OdometrySample / ...
    res.truth_at(stamp_ns)                        # true pose at any stamp in the run
    meta = res.to_dict()                          # plain dict for a YAML next to the bag
    world = World.from_dict(meta['world'])        # exact world round trip

Events (frozen dataclasses, numpy arrays are read-only):

* :class:`TruthSample` ``(stamp_ns, pose (3,), twist (2,))`` at every odometry step.
* :class:`OdometrySample` ``(stamp_ns, pose (3,), covariance (3, 3), twist (2,),
  wheel_velocities (2,), wheel_positions (2,))``, 10 Hz, odom frame == world at t0.
* :class:`ScanSample` ``(stamp_ns, ranges float32 (N,), angle_min, angle_max,
  angle_increment, time_increment, scan_time, range_min, range_max, true_ranges)``.
* :class:`SonarSample` ``(stamp_ns, ranges float32 (16,), field_of_view, min_range,
  max_range)``, 10 Hz, same stamps as odometry.
* :class:`RunMarker` ``(stamp_ns, kind, group, index, start_ns, end_ns, start_pose,
  end_pose)``, calibration scenario only.

Modules:

* :mod:`.world` -- :class:`World` (segments, circles, ``raycast``, ``corners``,
  ``visible_corners``, ``walls``, ``round_obstacles``, ``clearance``, ``to_dict``).
* :mod:`.robot` -- :class:`RobotParams`, kinematics eqs. 1-7 / 17-18 (``step_pose``,
  ``integrate``, ``wheel_to_twist``, ``dead_reckon``), :class:`Trajectory`,
  :class:`OdometryTrack`, ``propagate_covariance``.
* :mod:`.control` -- mission primitives ``GoTo``, ``Straight``, ``TurnTo``, ``Wait`` and
  ``simulate_mission``.
* :mod:`.laser` -- :class:`LaserConfig`, :class:`Laser`, :class:`ScanSample`.
* :mod:`.sonar` -- :data:`SONAR_MOUNTS`, :class:`SonarConfig`, :class:`SonarRing`,
  :class:`SonarSample`.
* :mod:`.scenarios` -- ``run_scenario``, ``build_scenario``, ``scenario_names``,
  :class:`ScenarioResult` and the event classes.
"""

from .control import GoTo, simulate_mission, Straight, TurnTo, Wait
from .laser import Laser, LaserConfig, ScanSample
from .robot import (dead_reckon, integrate, OdometryTrack, RobotParams, step_pose, Trajectory,
                    wheel_to_twist)
from .scenarios import (build_scenario, OdometrySample, run_scenario, RunMarker,
                        scenario_names, ScenarioResult, ScenarioSpec, simulate, START_NS,
                        TruthSample)
from .sonar import (SONAR_FIELD_OF_VIEW, SONAR_MAX_RANGE, SONAR_MIN_RANGE, SONAR_MOUNTS,
                    SonarConfig, SonarRing, SonarSample)
from .world import Corners, RayHits, RoundObstacles, Walls, World, wrap_angle

__all__ = [
    'build_scenario', 'Corners', 'dead_reckon', 'GoTo', 'integrate', 'Laser', 'LaserConfig',
    'OdometrySample', 'OdometryTrack', 'RayHits', 'RobotParams', 'RoundObstacles',
    'run_scenario', 'RunMarker', 'ScanSample', 'ScenarioResult', 'ScenarioSpec',
    'scenario_names', 'simulate', 'simulate_mission', 'SONAR_FIELD_OF_VIEW', 'SONAR_MAX_RANGE',
    'SONAR_MIN_RANGE', 'SONAR_MOUNTS', 'SonarConfig', 'SonarRing', 'SonarSample',
    'START_NS', 'step_pose', 'Straight', 'Trajectory', 'TruthSample', 'TurnTo', 'Wait',
    'Walls', 'wheel_to_twist', 'World', 'wrap_angle',
]
