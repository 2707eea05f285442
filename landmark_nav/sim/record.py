"""Record a simulated scenario into a rosbag2 (MCAP) directory.

Topics written (frames per REP 105; all stamps are simulation time):

=========================  ==============================  ====================================
topic                      type                            content
=========================  ==============================  ====================================
/odom                      nav_msgs/Odometry               wheel odometry, odom -> base_link,
                                                           10 Hz, with covariance
/joint_states              sensor_msgs/JointState          left/right wheel angle and speed
/ground_truth/odom         nav_msgs/Odometry               exact pose, map -> base_link
/scan                      sensor_msgs/LaserScan           2D laser (frame ``laser``)
/sonar/range_<i>           sensor_msgs/Range               sonar i = 0..15 (frame ``sonar_<i>``)
/ground_truth/corners      geometry_msgs/PoseArray         true corners in ``map``, latched;
                                                           orientation = free-space bisector,
                                                           order = ids in ground_truth.yaml
/ground_truth/walls        visualization_msgs/MarkerArray  true walls, latched (marker id =
                                                           wall id)
=========================  ==============================  ====================================

Beside the MCAP file the bag directory holds ``ground_truth.yaml``: the scenario, seed,
world (walls, round obstacles, corners with ids), robot parameters (R, b, k1, k2, k3,
noise), laser and sonar configuration with their mounting poses, and for the calibration
scenario the runs with exact start/end poses. ``ros2 bag`` ignores the extra file.
"""

from pathlib import Path
import shutil

from geometry_msgs.msg import Point, Pose, PoseArray
from landmark_nav.bag import BagWriter
from landmark_nav.conversions import (make_joint_state, make_odometry, make_range, make_scan,
                                      ns_to_stamp, quaternion_msg_from_yaw)
# The bag layout, shared with the camera and park-road recorders (still importable from here).
from landmark_nav.sim.bag_layout import (BASE_FRAME, GROUND_TRUTH_FILE, LASER_FRAME, MAP_FRAME,
                                         ODOM_FRAME, read_ground_truth_file, WHEEL_JOINTS)
from landmark_nav.sim.laser import ScanSample
from landmark_nav.sim.scenarios import OdometrySample, run_scenario, scenario_names, TruthSample
from landmark_nav.sim.sonar import SonarSample
from nav_msgs.msg import Odometry
import numpy as np
from sensor_msgs.msg import JointState, LaserScan, Range
from visualization_msgs.msg import Marker, MarkerArray
import yaml


def sonar_topic(i: int) -> str:
    """Return the topic of sonar i (0..15)."""
    return f'/sonar/range_{i}'


def sonar_frame(i: int) -> str:
    """Return the frame id of sonar i (0..15)."""
    return f'sonar_{i}'


def _corner_poses(world, stamp_ns: int) -> PoseArray:
    corners = world.corners()
    msg = PoseArray()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = MAP_FRAME
    for (x, y), yaw in zip(corners.positions, corners.bisectors):
        pose = Pose()
        pose.position.x, pose.position.y = float(x), float(y)
        pose.orientation = quaternion_msg_from_yaw(float(yaw))
        msg.poses.append(pose)
    return msg


def _wall_markers(world, stamp_ns: int) -> MarkerArray:
    walls = world.walls()
    out = MarkerArray()
    for wall_id, (x1, y1, x2, y2) in zip(walls.ids, walls.segments):
        m = Marker()
        m.header.stamp = ns_to_stamp(stamp_ns)
        m.header.frame_id = MAP_FRAME
        m.ns = 'ground_truth_walls'
        m.id = int(wall_id)
        m.type = Marker.LINE_STRIP
        m.action = Marker.ADD
        m.pose.orientation.w = 1.0
        m.scale.x = 0.03
        m.color.r = m.color.g = m.color.b = 0.2
        m.color.a = 1.0
        m.points = [Point(x=float(x1), y=float(y1)), Point(x=float(x2), y=float(y2))]
        out.markers.append(m)
    return out


def record_scenario(name: str, seed: int, out, force: bool = False, **overrides) -> str:
    """Simulate a scenario and write it as a bag directory; return a one-paragraph summary.

    ``overrides`` go to :func:`landmark_nav.sim.run_scenario` (e.g. ``laser={'sigma_range':
    0.02}``).

    Raises:
        ValueError: Unknown scenario or bad seed (message lists the valid names).
        BagError: The output exists (without ``force``) or cannot be written.

    """
    if name == 'park_road':  # tilted laser + camera on a 3-D terrain: own recorder
        from landmark_nav.sim.park_road_record import record_park_road
        return record_park_road(seed, out, force=force, **overrides)
    if name in ('landmark_views', 'landmark_shuttle'):  # camera scenarios: own recorder
        from landmark_nav.sim.camera_record import record_camera_scenario
        return record_camera_scenario(name, seed, out, force=force, **overrides)
    if name == 'corridor':                               # rendered corridor: own recorder
        from landmark_nav.sim.corridor_record import record_corridor_scenario
        return record_corridor_scenario(seed, out, force=force, **overrides)
    if name not in scenario_names():
        valid = scenario_names() + ['corridor', 'landmark_shuttle', 'landmark_views']
        raise ValueError(f'unknown scenario {name!r}; valid names: {", ".join(sorted(valid))}')
    result = run_scenario(name, seed, **overrides)
    out = Path(out)
    if force and out.exists():
        if not (out / 'metadata.yaml').is_file():
            raise ValueError(f'{out} exists and is not a bag; refusing to replace it')
        shutil.rmtree(out)
    sonar_cfg = result.sonar
    with BagWriter(out) as bag:
        bag.add_topic('/odom', Odometry)
        bag.add_topic('/joint_states', JointState)
        bag.add_topic('/ground_truth/odom', Odometry)
        bag.add_topic('/ground_truth/corners', PoseArray, latched=True)
        bag.add_topic('/ground_truth/walls', MarkerArray, latched=True)
        if result.laser is not None:
            bag.add_topic('/scan', LaserScan)
        if sonar_cfg is not None:
            for i in range(16):
                bag.add_topic(sonar_topic(i), Range)
        t0 = result.start_ns
        bag.write('/ground_truth/corners', t0, _corner_poses(result.world, t0))
        bag.write('/ground_truth/walls', t0, _wall_markers(result.world, t0))
        for ev in result.events:
            t = ev.stamp_ns
            if isinstance(ev, TruthSample):
                twist = np.array([ev.twist[0], 0.0, ev.twist[1]])
                bag.write('/ground_truth/odom', t, make_odometry(
                    t, MAP_FRAME, BASE_FRAME, ev.pose, np.zeros((3, 3)), twist,
                    np.zeros((3, 3)), unused_variance=0.0))
            elif isinstance(ev, OdometrySample):
                twist = np.array([ev.twist[0], 0.0, ev.twist[1]])
                bag.write('/odom', t, make_odometry(
                    t, ODOM_FRAME, BASE_FRAME, ev.pose, ev.covariance, twist))
                bag.write('/joint_states', t, make_joint_state(
                    t, WHEEL_JOINTS, ev.wheel_positions, ev.wheel_velocities))
            elif isinstance(ev, ScanSample):
                bag.write('/scan', t, make_scan(
                    t, LASER_FRAME, ev.angle_min, ev.angle_increment, ev.ranges,
                    ev.range_min, ev.range_max, time_increment=ev.time_increment,
                    scan_time=ev.scan_time))
            elif isinstance(ev, SonarSample):
                for i, value in enumerate(ev.ranges):
                    bag.write(sonar_topic(i), t, make_range(
                        t, sonar_frame(i), float(value), ev.field_of_view, ev.min_range,
                        ev.max_range))
    meta = result.to_dict()
    meta['frames'] = {'map': MAP_FRAME, 'odom': ODOM_FRAME, 'base_link': BASE_FRAME,
                      'laser': LASER_FRAME, 'sonar': [sonar_frame(i) for i in range(16)]}
    meta['topics'] = {'sonar': [sonar_topic(i) for i in range(16)]}
    with open(out / GROUND_TRUTH_FILE, 'w') as f:
        yaml.safe_dump(meta, f, sort_keys=False)
    counts = ', '.join(f'{k}: {v}' for k, v in result.counts().items())
    return (f'{name} (seed {seed}): {result.duration:.1f} s, path {result.path_length:.1f} m, '
            f'{counts} -> {out}')


def load_ground_truth(bag_dir) -> dict:
    """Load the ground_truth.yaml written beside a simulated bag.

    Raises:
        ValueError: The bag has no ground-truth file (not recorded by the simulator).

    """
    path = Path(bag_dir) / GROUND_TRUTH_FILE
    if not path.is_file():
        raise ValueError(f'{bag_dir} has no {GROUND_TRUTH_FILE} (not a simulator recording)')
    return read_ground_truth_file(path)
