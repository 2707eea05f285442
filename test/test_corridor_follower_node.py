"""corridor_follower node: rendered frames and odometry through DDS, enable, lost, bad input."""

import math
from pathlib import Path

from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
from landmark_nav.conversions import (array_to_image, make_camera_info, make_odometry,
                                      quaternion_to_yaw)
from landmark_nav.geometry import wrap_angle
from landmark_nav.nodes.common import ParameterError
from landmark_nav.nodes.corridor_follower import CorridorFollower
from landmark_nav.sim.camera import CameraSimulator
from landmark_nav.sim.corridor import (corridor_scene, corridor_view, CorridorConfig,
                                       default_corridor_camera)
from landmark_nav.testing import declared_parameters, parameter_file, RosHarness
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import SetBool

REPO = Path(__file__).resolve().parents[1]
MOUNT = [0.1, 0.0, 1.1, 0.0, math.radians(5.0), 0.0]
CAM = default_corridor_camera()


def node_params(**extra):
    """Return the node's parameter overrides for the rendered corridor."""
    values = {'camera_mount': MOUNT, 'corridor_width': 2.0, 'corridor_height': 2.6}
    values.update(extra)
    return [Parameter(k, value=v) for k, v in values.items()]


def test_config_file_matches_declared_parameters():
    values = parameter_file(REPO, 'corridor_follower')
    with RosHarness() as ros:
        node = CorridorFollower(context=ros.context)
        assert declared_parameters(node) == values


def test_bad_parameters():
    with RosHarness() as ros:
        high = [0.0, 0.0, 3.0, 0.0, 0.0, 0.0]
        with pytest.raises(ParameterError, match='between floor and ceiling'):
            CorridorFollower(context=ros.context,
                             parameter_overrides=node_params(camera_mount=high))
        with pytest.raises(ParameterError, match='lateral_offset'):
            CorridorFollower(context=ros.context,
                             parameter_overrides=node_params(lateral_offset=1.5))


def drive(ros, node, images, seconds=3.0, y0=0.25, th0=math.radians(-5.0), speed=0.3,
          before_image=None):
    """Publish odometry (20 Hz) and rendered frames (5 Hz) of a straight drive; return truth."""
    planes = corridor_scene(CorridorConfig(), 1)
    sim = CameraSimulator(CAM)
    pub_info = ros._helper.create_publisher(CameraInfo, 'camera/camera_info', 10)
    pub_img = ros._helper.create_publisher(Image, 'camera/image_raw', 10)
    pub_odom = ros._helper.create_publisher(Odometry, 'odom', 100)
    assert ros.wait_for_subscribers([pub_info, pub_img, pub_odom])
    truth = np.array([2.0, y0, th0])
    odom_origin = np.array([5.0, -3.0, 1.0])         # the odometry frame is elsewhere
    for k in range(int(seconds * 20)):
        stamp = 1_000_000_000 + k * 50_000_000
        if k:
            truth = truth + [speed * 0.05 * math.cos(truth[2]),
                             speed * 0.05 * math.sin(truth[2]), 0.0]
        c, s = math.cos(odom_origin[2]), math.sin(odom_origin[2])
        op = [odom_origin[0] + c * truth[0] - s * truth[1],
              odom_origin[1] + s * truth[0] + c * truth[1], odom_origin[2] + truth[2]]
        pub_odom.publish(make_odometry(stamp, 'odom', 'base_link', op))
        # one at a time: sensor-data QoS drops what a busy node cannot take
        assert ros.wait_until(lambda: node.last_odom is not None
                              and node.last_odom[0] == stamp, 10)
        if k % 4 == 0:
            n_before = node.frames + node.warner.count
            pub_info.publish(make_camera_info(CAM, stamp, 'camera'))
            img = corridor_view(sim, planes, truth, MOUNT).image if images else \
                np.zeros((CAM.height, CAM.width), np.uint8)
            if before_image is not None:
                before_image(k)
            pub_img.publish(array_to_image(img, 'mono8', stamp, 'camera'))
            assert ros.wait_until(lambda: node.frames + node.warner.count > n_before, 20)
    return truth


def call_enable(ros, on):
    """Call ~/enable and return the response."""
    cli = ros._helper.create_client(SetBool, '/corridor_follower/enable')
    assert cli.wait_for_service(timeout_sec=10)
    fut = cli.call_async(SetBool.Request(data=on))
    assert ros.wait_until(fut.done, 10)
    return fut.result()


@pytest.mark.dds
@pytest.mark.slow
def test_estimate_and_cmd_vel_from_rendered_frames():
    with RosHarness() as ros:
        node = ros.add_node(CorridorFollower(context=ros.context,
                                             parameter_overrides=node_params()))
        poses = ros.collect('corridor/pose', PoseWithCovarianceStamped)
        cmds = ros.collect('cmd_vel', Twist)
        assert call_enable(ros, True).success
        truth = drive(ros, node, images=True)
        # a pose after every odometry message once the filter has started, and per frame
        assert ros.wait_until(lambda: len(poses) >= 59 + 15, 10)
        last = poses[-1]
        q = last.pose.pose.orientation
        yaw = quaternion_to_yaw(q.x, q.y, q.z, q.w)
        assert abs(last.pose.pose.position.y - truth[1]) < 0.02
        assert abs(math.degrees(yaw - truth[2])) < 0.3
        assert last.header.frame_id == 'corridor'
        assert node.frames == 15
        # drives forward at the set speed, steering by the control law on the estimate:
        # omega = -v (4 theta + 4 y), here about 0.3 (0.35 - 0.68) rad/s
        assert ros.wait_until(lambda: len(cmds) == 60, 10)
        assert cmds[-1].linear.x == pytest.approx(0.3)
        assert cmds[-1].angular.z == pytest.approx(-0.3 * (4 * truth[2] + 4 * truth[1]),
                                                   abs=0.01)
        speeds = [c.linear.x for c in cmds if c.linear.x > 0]
        assert speeds[0] == pytest.approx(0.3 * 0.05)   # max_accel x the odometry period
        assert np.all(np.diff(speeds) >= 0) and np.max(np.diff(speeds)) <= 0.015 + 1e-9
        assert call_enable(ros, False).success


@pytest.mark.dds
@pytest.mark.slow
def test_lost_estimate_stops_the_robot_and_bad_camera_info_is_survived():
    with RosHarness() as ros:
        node = ros.add_node(CorridorFollower(
            context=ros.context, parameter_overrides=node_params(enabled=True)))
        cmds = ros.collect('cmd_vel', Twist)
        drive(ros, node, images=False, seconds=1.0)
        assert ros.wait_until(lambda: len(cmds) >= 20, 10)
        assert all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in cmds)
        assert node.ekf is None and node.warner.count > 0
        bad = make_camera_info(CAM)
        bad.k = [0.0] * 9
        pub = ros._helper.create_publisher(CameraInfo, 'camera/camera_info', 10)
        assert ros.wait_for_subscribers([pub])
        before = node.warner.count
        pub.publish(bad)
        assert ros.wait_until(lambda: node.warner.count > before, 10)
        assert node.stats.dropped['camera_info_malformed'] == 1  # counted on /diagnostics
        said = []
        warn = node.warner.warn
        node.warner.warn = lambda message: (said.append(message), warn(message))
        # a saturated frame (no edges) after a good CameraInfo: lost, warned, still stopped
        pub.publish(make_camera_info(CAM, 9_000_000_000, 'camera'))
        pub_img = ros._helper.create_publisher(Image, 'camera/image_raw', 10)
        assert ros.wait_for_subscribers([pub_img])
        white = np.full((CAM.height, CAM.width), 255, np.uint8)
        pub_img.publish(array_to_image(white, 'mono8', 9_000_000_000, 'camera'))
        assert ros.wait_until(lambda: any(m.startswith('Corridor lost') for m in said), 10)
        assert node.ekf is None and node.frames == 0
        # odometry going back in time: warned, the increments restart, the robot stays stopped
        pub_odom = ros._helper.create_publisher(Odometry, 'odom', 10)
        assert ros.wait_for_subscribers([pub_odom])
        last = node.last_odom[0]
        n_cmds = len(cmds)
        pub_odom.publish(make_odometry(last - 500_000_000, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        assert ros.wait_until(lambda: node.last_odom[0] == last - 500_000_000, 10)
        assert any('went back in time' in m for m in said)
        assert ros.wait_until(lambda: len(cmds) > n_cmds, 10)
        assert all(c.linear.x == 0.0 and c.angular.z == 0.0 for c in cmds)


@pytest.fixture(scope='module')
def drive_bag(tmp_path_factory):
    """Return a 6 m rendered corridor drive (60 frames, drifting odometry), made once."""
    from landmark_nav.sim.corridor_record import record_corridor_drive
    out = tmp_path_factory.mktemp('bags') / 'corridor_drive'
    record_corridor_drive(out, seed=0)
    return out


def replay(bag, **params):
    """Replay a corridor bag into the node in lock step; return it, lateral and heading errors.

    Errors of every published pose (after images and after each odometry step) against
    ``/ground_truth/odom`` at its stamp, after the first 20 poses (the filter's first
    0.8 s); images are those of ``ground_truth.yaml``'s ``image_topic`` (raw by default).
    The node's attribute ``published`` holds every pose as (stamp_ns, x, y, yaw).
    """
    from landmark_nav.bag import BagReader
    from landmark_nav.conversions import odometry_to_pose, stamp_to_ns
    from landmark_nav.sim.record import load_ground_truth
    meta = load_ground_truth(bag)
    image_topic = meta.get('image_topic', '/camera/image_raw')
    truth = {}
    with BagReader(bag) as reader:
        for _, _, msg in reader.decoded(['/ground_truth/odom']):
            p = odometry_to_pose(msg)
            truth[p.stamp_ns] = p.pose
    with RosHarness() as ros:
        node = ros.add_node(CorridorFollower(context=ros.context, parameter_overrides=node_params(
            camera_mount=meta['camera_mount'], **params)))
        poses = ros.collect('corridor/pose', PoseWithCovarianceStamped)
        done = {'n': 0}

        def wait_for_node(topic, log_time_ns):
            if topic == '/camera/camera_info':
                assert ros.wait_until(lambda: node.camera is not None, 10)
            elif topic == image_topic:
                done['n'] += 1
                assert ros.wait_until(lambda: node.frames + node.warner.count >= done['n'], 20)
            elif topic == '/odom':
                assert ros.wait_until(lambda: node.last_odom is not None
                                      and node.last_odom[0] == log_time_ns, 10)

        counts = ros.play(bag, topics=['/camera/camera_info', '/odom', image_topic],
                          on_message=wait_for_node)
        assert counts[image_topic] == meta['frames']
        n_odom = counts['/odom']
        # one pose per frame and per odometry message after the first frame (the filter
        # starts on the first frame, the first odometry message only sets the origin)
        assert ros.wait_until(lambda: len(poses) >= meta['frames'] + n_odom - 1, 10)
        err_y, err_th, published = [], [], []
        for msg in poses:
            t = stamp_to_ns(msg.header.stamp)
            q = msg.pose.pose.orientation
            yaw = quaternion_to_yaw(q.x, q.y, q.z, q.w)
            published.append((t, msg.pose.pose.position.x, msg.pose.pose.position.y, yaw))
            err_y.append(msg.pose.pose.position.y - truth[t][1])
            err_th.append(math.degrees(yaw - truth[t][2]))
    node.published = published
    return node, np.array(err_y[20:]), np.array(err_th[20:])    # after the first 0.8 s


def assert_node_equals_offline(node, bag):
    """Check that the node published the poses of ``landmark_nav evaluate-corridor``."""
    from landmark_nav.evaluation.corridor_bag import replay_corridor_bag
    ref = replay_corridor_bag(bag)
    got = np.array(node.published)
    assert got.shape == (len(ref.stamps), 4)
    assert [int(t) for t in got[:, 0]] == [int(t) for t in ref.stamps]
    assert np.abs(got[:, 1:3] - ref.poses[:, :2]).max() <= 1e-12
    assert np.abs(wrap_angle(got[:, 3] - ref.poses[:, 2])).max() <= 1e-12


@pytest.mark.dds
@pytest.mark.slow
def test_bag_replay_against_ground_truth(drive_bag):
    node, err_y, err_th = replay(drive_bag)
    assert node.frames == 60
    assert_node_equals_offline(node, drive_bag)
    # measured over every pose (after images and after each odometry step): lateral
    # 1.2 mm RMS (worst 2.6 mm), heading 0.27 deg RMS (worst 0.86 deg: the 1 % wheel
    # scale error turns the odometry heading by 0.17 deg between two frames)
    assert np.sqrt(np.mean(err_y ** 2)) < 0.003
    assert np.abs(err_y).max() < 0.006
    assert np.sqrt(np.mean(err_th ** 2)) < 0.4
    assert np.abs(err_th).max() < 1.2


COMMITTED = REPO / 'bags' / 'corridor'


@pytest.mark.dds
@pytest.mark.slow
def test_committed_bag_replay_compressed():
    """bags/corridor: 320 x 240 JPEG frames on camera/image_raw/compressed.

    The node publishes the poses of ``landmark_nav evaluate-corridor bags/corridor``, whose
    figures ``bags/corridor/expected.yaml`` guards (test_golden.py).
    """
    node, err_y, err_th = replay(COMMITTED, compressed=True)
    assert node.frames == 30 and node.warner.count == 0
    assert_node_equals_offline(node, COMMITTED)
    # measured (deterministic in lock step): lateral 2.06 mm RMS (worst 3.34 mm), heading
    # 0.254 deg RMS (worst 0.886 deg, the odometry heading drift between two frames)
    assert np.sqrt(np.mean(err_y ** 2)) < 0.0025
    assert np.abs(err_y).max() < 0.004
    assert np.sqrt(np.mean(err_th ** 2)) < 0.3
    assert np.abs(err_th).max() < 1.0


@pytest.mark.dds
@pytest.mark.slow
def test_closed_loop_through_cmd_vel():
    """The simulated robot obeys the node's cmd_vel: 2 x 4 m back and forth, one turn.

    Starts 15 cm off the centre line, 10 m into the 30 m corridor; the full 3 x 26 m run
    is ``benchmarks/bench_corridor.py loop``.
    """
    from landmark_nav.sim.corridor_loop import follower_parameters, LoopConfig, run_loop
    cfg = LoopConfig(start=(10.0, 0.15, math.radians(4.0)), distance=4.0, lengths=2)
    with RosHarness() as ros:
        node = ros.add_node(CorridorFollower(context=ros.context, parameter_overrides=[
            Parameter(k, value=v) for k, v in follower_parameters(cfg).items()]))
        result = run_loop(ros.context, cfg, seed=2, executor=ros._executor)
    s = result.summary()
    assert result.turning.any() and not result.turning[-1]
    # facing back at the end (measured 4.3 deg off the axis, still converging after 4 m)
    assert abs(math.degrees(wrap_angle(result.truth[-1, 2] - math.pi))) < 6.0
    # both legs driven to their full odometry length (none ended by a stall)
    assert len(result.legs) == 2 and min(result.legs) >= 4.0
    assert abs(result.truth[-1, 0] - 10.0) < 0.1 and s['path_m'] > 7.9
    # measured: within 1.32 cm of the centre line after the first 2 m (lateral RMS
    # 0.76 cm); the issue asks for 5 cm on the full run
    assert s['max_abs_lateral_after_2m'] < 0.02
    assert s['rms_lateral_after_2m'] < 0.01
    assert s['min_wall_clearance'] > 0.55
    assert node.frames > 90


def test_drops_and_events_are_counted_on_diagnostics_under_its_own_name():
    """The node published no input status, and its image warnings named the landmark detector."""
    from diagnostic_msgs.msg import DiagnosticArray
    with RosHarness() as ros:
        node = ros.add_node(CorridorFollower(context=ros.context,
                                             parameter_overrides=node_params()))
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pub_img = ros._helper.create_publisher(Image, 'camera/image_raw', 10)
        pub_odom = ros._helper.create_publisher(Odometry, 'odom', 10)
        assert ros.wait_for_subscribers([pub_img, pub_odom])
        said = []
        warn = node.warner.warn
        node.warner.warn = lambda message, detail='': (said.append(message),
                                                       warn(message, detail))
        grey = np.zeros((CAM.height, CAM.width), np.uint8)
        pub_img.publish(array_to_image(grey, 'mono8', 1_000_000_000, 'camera'))  # no info
        yuv = array_to_image(grey, 'mono8', 1_100_000_000, 'camera')
        yuv.encoding = 'yuv422'
        pub_img.publish(yuv)
        nan = make_odometry(1_000_000_000, 'odom', 'base_link', [0.0, 0.0, 0.0])
        nan.pose.pose.position.x = math.nan
        pub_odom.publish(nan)
        pub_odom.publish(make_odometry(1_100_000_000, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        pub_odom.publish(make_odometry(1_000_000_000, 'odom', 'base_link', [0.0, 0.0, 0.0]))

        def status():
            for arr in reversed(list(diagnostics)):
                for s in arr.status:
                    if s.name == 'corridor_follower: input':
                        return {kv.key: kv.value for kv in s.values}
            return {}
        want = {'dropped.no_camera_info': '1', 'dropped.malformed': '2',
                'odometry.back_in_time': '1', 'processed': '2'}
        assert ros.wait_until(lambda: all(status().get(k) == v for k, v in want.items()),
                              30.0), status()
        assert any("encoding 'yuv422' is not supported by corridor_follower" in m
                   for m in said), said
        assert not any('landmark detector' in m for m in said)
