"""sonar_localizer node: hallway bag replay through DDS, bad input, parameters, config."""

import copy
import math
from pathlib import Path

from geometry_msgs.msg import PoseWithCovarianceStamped
from landmark_nav.bag import BagReader
from landmark_nav.conversions import (make_occupancy_grid, make_pose_with_covariance_stamped,
                                      make_range, odometry_to_pose,
                                      pose_with_covariance_to_pose, stamp_to_ns)
from landmark_nav.evaluation.localization import (draw_initial_pose, first_motion_index,
                                                  localization_errors, TARGETS)
from landmark_nav.evaluation.localization_bags import (INITIAL_STD, load_bag_input,
                                                       run_bag_localization, world_map)
from landmark_nav.geometry import wrap_angle
from landmark_nav.localization.tracking import SonarTracker
from landmark_nav.nodes.common import ParameterError
from landmark_nav.nodes.sonar_localizer import SonarLocalizer
from landmark_nav.testing import declared_parameters, parameter_file, RosHarness
from landmark_nav.testing.harness import reliable_qos
from nav_msgs.msg import OccupancyGrid, Odometry
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState, Range

REPO = Path(__file__).resolve().parents[1]
HALLWAY = REPO / 'bags' / 'hallway'
SONAR_TOPICS = [f'/sonar/range_{i}' for i in range(16)]
REMAP = ['--ros-args', '-r', 'odom:=/odom', '-r', 'joint_states:=/joint_states',
         '-r', 'map:=/map', '-r', 'initialpose:=/initialpose']


@pytest.fixture(scope='module')
def hallway():
    """Bag input, per-stamp messages, the map and the initial estimate of the evaluation."""
    inp, meta = load_bag_input(HALLWAY)
    cycles = {}
    with BagReader(HALLWAY) as reader:
        for topic, _, msg in reader.decoded(['/odom', '/joint_states'] + SONAR_TOPICS):
            cycle = cycles.setdefault(stamp_to_ns(msg.header.stamp), {'ranges': [None] * 16})
            if topic in ('/odom', '/joint_states'):
                cycle[topic] = msg
            else:
                cycle['ranges'][SONAR_TOPICS.index(topic)] = msg
    stamps = sorted(cycles)
    assert stamps == inp.stamps_ns.tolist()
    cov0 = np.diag(np.square(INITIAL_STD))
    x0 = draw_initial_pose(inp.truth[0], cov0, 1000 + meta['seed'])
    grid = world_map(meta)
    return {'inp': inp, 'cycles': [cycles[s] for s in stamps], 'grid': grid, 'x0': x0,
            'cov0': cov0, 'map_msg': make_occupancy_grid(grid.occupancy, grid.resolution,
                                                         grid.origin)}


def node_params(x0, k, **extra):
    values = {'initial_pose.x': x0[0], 'initial_pose.y': x0[1], 'initial_pose.yaw': x0[2],
              'initial_pose.std_x': INITIAL_STD[0], 'initial_pose.std_y': INITIAL_STD[1],
              'initial_pose.std_yaw': INITIAL_STD[2], 'k1': k[0], 'k2': k[1], 'k3': k[2]}
    values.update(extra)
    return [Parameter(name, value=value) for name, value in values.items()]


class Feeder:
    """Publishers of the node's inputs (reliable, deep queues)."""

    def __init__(self, ros, joint_states=True):
        node = ros._helper
        qos = reliable_qos(1000)
        self.ros = ros
        self.odom = node.create_publisher(Odometry, '/odom', qos)
        self.joints = node.create_publisher(JointState, '/joint_states', qos)
        self.ranges = [node.create_publisher(Range, t, qos) for t in SONAR_TOPICS]
        self.map = node.create_publisher(OccupancyGrid, '/map', reliable_qos(1, latched=True))
        self.initialpose = node.create_publisher(PoseWithCovarianceStamped, '/initialpose',
                                                 reliable_qos(10))
        assert ros.wait_for_subscribers([self.odom, self.initialpose] + self.ranges
                                        + ([self.joints] if joint_states else []))

    def cycle(self, cycle, skip=(), ranges=None):
        self.odom.publish(cycle['/odom'])
        self.joints.publish(cycle['/joint_states'])
        for i, msg in enumerate(ranges or cycle['ranges']):
            if i not in skip:
                self.ranges[i].publish(msg)


def poses_of(msgs):
    out = [pose_with_covariance_to_pose(m) for m in msgs]
    return (np.array([d.stamp_ns for d in out]), np.array([d.pose for d in out]),
            np.array([d.covariance for d in out]))


@pytest.mark.dds
def test_replays_the_hallway_bag_like_the_offline_evaluation(hallway):
    inp, x0, cov0 = hallway['inp'], hallway['x0'], hallway['cov0']
    with RosHarness() as ros:
        ekf = ros.add_node(SonarLocalizer(
            context=ros.context, namespace='ekf', cli_args=REMAP,
            parameter_overrides=node_params(x0, inp.true_k, filter='ekf',
                                            odometry_source='odom')))
        ukf = ros.add_node(SonarLocalizer(
            context=ros.context, namespace='ukf', cli_args=REMAP,
            parameter_overrides=node_params(x0, inp.true_k, filter='ukf',
                                            odometry_source='joint_states')))
        out = {'ekf': ros.collect('/ekf/pose', PoseWithCovarianceStamped),
               'ukf': ros.collect('/ukf/pose', PoseWithCovarianceStamped)}
        filtered = ros.collect('/ukf/odometry/filtered', Odometry)
        feed = Feeder(ros)
        feed.map.publish(hallway['map_msg'])
        assert ros.wait_until(lambda: ekf.tracker.grid is not None
                              and ukf.tracker.grid is not None, 10)
        for k, cycle in enumerate(hallway['cycles'], 1):
            feed.cycle(cycle)
            assert ros.wait_until(lambda: len(out['ekf']) >= k and len(out['ukf']) >= k, 10), \
                f'no pose for cycle {k}'
        assert ros.wait_until(lambda: len(filtered) == len(hallway['cycles']), 5)
        assert ekf.warner.count == 0 and ukf.warner.count == 0
    truth = inp.truth
    i0 = first_motion_index(truth)
    for name in ('ekf', 'ukf'):
        stamps, poses, covs = poses_of(out[name])
        assert stamps.tolist() == inp.stamps_ns.tolist()
        assert all(m.header.frame_id == 'map' for m in out[name])
        _, run, _, _, _ = run_bag_localization(HALLWAY, name, None, x0, cov0)
        # Same algorithm on the same data: the node agrees with the offline loop.
        assert np.abs(poses[:, :2] - run.trajectory[:, :2]).max() <= 1e-3
        assert np.degrees(np.abs(wrap_angle(poses[:, 2] - run.trajectory[:, 2]))).max() <= 0.1
        np.testing.assert_allclose(covs, run.covariances, atol=1e-9)
        err = localization_errors(poses, truth, i0)
        assert err['max_position'] <= TARGETS[name][0], (name, err)
        assert err['max_heading'] <= TARGETS[name][1], (name, err)
    last = odometry_to_pose(filtered[-1])
    assert filtered[-1].child_frame_id == 'base_link'
    np.testing.assert_allclose(last.pose, poses_of(out['ukf'])[1][-1], atol=1e-12)
    mid = odometry_to_pose(filtered[300])  # moving: about 0.35 m/s forward
    assert 0.2 < mid.twist[0] < 0.4 and mid.twist_covariance[0, 0] > 0.0


def _warnings(logs, start=0):
    return [m.msg for m in logs[start:] if m.level >= Log.WARN]


def _wait_for_warning(ros, logs, needle, timeout=5.0):
    ok = ros.wait_until(lambda: any(needle in t for t in _warnings(logs)), timeout)
    assert ok, f'no warning containing {needle!r}: {_warnings(logs)}'


@pytest.mark.dds
def test_bad_input_warns_and_keeps_tracking(hallway):
    inp, cycles = hallway['inp'], hallway['cycles']
    with RosHarness() as ros:
        node = ros.add_node(SonarLocalizer(
            context=ros.context, cli_args=REMAP,
            parameter_overrides=node_params(inp.truth[0], inp.true_k)))
        poses = ros.collect('/pose', PoseWithCovarianceStamped)
        logs = ros.collect('/rosout', Log)
        feed = Feeder(ros, joint_states=False)

        def run(cycle_range, **kw):
            for k in cycle_range:
                n = len(poses)
                feed.cycle(cycles[k], **kw)
                assert ros.wait_until(lambda: len(poses) > n, 5), f'no pose for cycle {k}'

        # 1. No map yet: dead reckoning with a growing covariance, a clear warning.
        run(range(0, 4))
        _wait_for_warning(ros, logs, 'no usable map yet: dead reckoning')
        _, p, c = poses_of(poses)
        assert np.all(np.diff(c[:, 0, 0]) > 0.0)
        np.testing.assert_allclose(p, np.repeat(inp.truth[:1], 4, axis=0), atol=1e-3)

        # 2. /initialpose (RViz) resets the estimate; one in another frame is ignored.
        feed.initialpose.publish(make_pose_with_covariance_stamped(
            0, 'odom', [5.0, 5.0, 1.0], np.eye(3)))
        _wait_for_warning(ros, logs, "Dropping initial pose in frame 'odom'")
        assert node.stats.dropped['initialpose_frame'] == 1
        reset_cov = np.diag([0.04, 0.09, 0.01])
        feed.initialpose.publish(make_pose_with_covariance_stamped(
            0, 'map', [1.0, 0.5, 0.3], reset_cov))
        assert ros.wait_until(lambda: np.allclose(node.tracker.pose, [1.0, 0.5, 0.3]), 5)
        run(range(4, 5))  # at rest: the pose stays, the covariance grows by Q only
        _, p, c = poses_of(poses)
        np.testing.assert_allclose(p[-1], [1.0, 0.5, 0.3], atol=1e-4)
        assert 0.04 < c[-1][0, 0] < 0.04 + 1e-5 and 0.09 < c[-1][1, 1] < 0.09 + 1e-5
        feed.initialpose.publish(make_pose_with_covariance_stamped(
            0, 'map', inp.truth[5], np.diag(np.square(INITIAL_STD))))
        assert ros.wait_until(lambda: np.allclose(node.tracker.pose, inp.truth[5]), 5)

        # 3. A map of unknown cells only: a warning, still dead reckoning.
        feed.map.publish(make_occupancy_grid(np.full((20, 30), -1, dtype=np.int8), 0.1,
                                             [-1.0, -1.0, 0.0]))
        _wait_for_warning(ros, logs, 'map has no occupied cell (600 of 600 cells unknown)')
        run(range(5, 7))
        assert node.tracker.grid is None

        # 4. The map arrives: updates start and the covariance shrinks.
        feed.map.publish(hallway['map_msg'])
        assert ros.wait_until(lambda: node.tracker.grid is not None, 5)
        before = poses_of(poses)[2][-1]
        run(range(7, 10))
        after = poses_of(poses)[2][-1]
        assert after[0, 0] < 0.5 * before[0, 0] and after[2, 2] < before[2, 2]

        # 5. Out-of-limit and NaN ranges are rejected with a warning; the cycle goes on.
        bad = list(cycles[10]['ranges'])
        s, frame = stamp_to_ns(bad[0].header.stamp), bad[0].header.frame_id
        bad[0] = make_range(s, frame, 7.5, bad[0].field_of_view, 0.1, 5.0)
        bad[1] = make_range(s, frame, 0.05, bad[1].field_of_view, 0.1, 5.0)
        bad[2] = make_range(s, frame, math.nan, bad[2].field_of_view, 0.1, 5.0)
        malformed = copy.deepcopy(bad[3])
        malformed.min_range, malformed.max_range = 3.0, 2.0
        n = len(poses)
        feed.ranges[3].publish(malformed)
        _wait_for_warning(ros, logs, 'Dropping sonar reading on /sonar/range_')
        feed.cycle(cycles[10], ranges=bad)  # the good reading of sonar 3 completes the cycle
        assert ros.wait_until(lambda: len(poses) > n, 5)
        for needle in ('outside [min_range, max_range]', 'range is NaN'):
            _wait_for_warning(ros, logs, needle)
        assert node.tracker.expected.all()

        # 6. A sonar topic stops: its cycles are processed after the timeout, then it is no
        #    longer waited for (one warning); every cycle still yields a pose.
        n0 = len(poses)
        # Cycle k is processed once a stamp 0.15 s newer arrives until the third miss; then
        # the cycles held back complete at once.
        for k, done in zip(range(11, 19), (0, 0, 1, 2, 5, 6, 7, 8)):
            feed.cycle(cycles[k], skip=(5,))
            assert ros.wait_until(lambda: len(poses) == n0 + done, 5), (k, len(poses) - n0)
        _wait_for_warning(ros, logs, '/sonar/range_5 has not reported for 3 cycles')
        assert not node.tracker.expected[5]
        stamps, p, _ = poses_of(poses)
        assert stamps[n0:].tolist() == inp.stamps_ns[11:19].tolist()
        assert localization_errors(p[n0:], inp.truth[11:19])['max_position'] < 0.1
        run(range(19, 21))  # the sonar reports again: waited for again
        assert node.tracker.expected[5]

        # 7. Odometry jumps back in time (a looped bag): warning, time bookkeeping reset.
        n0 = len(poses)
        feed.odom.publish(cycles[0]['/odom'])
        _wait_for_warning(ros, logs, 'odometry jumped back in time')
        for i, msg in enumerate(cycles[0]['ranges']):
            feed.ranges[i].publish(msg)
        assert ros.wait_until(lambda: len(poses) > n0, 5)
        run(range(1, 3))
        assert poses_of(poses)[0][n0:].tolist() == inp.stamps_ns[0:3].tolist()

        # 8. Malformed joint states / odometry are dropped with a warning.
        broken = copy.deepcopy(cycles[3]['/odom'])
        broken.pose.pose.orientation.w = math.nan
        feed.odom.publish(broken)
        _wait_for_warning(ros, logs, 'Dropping odometry')
        assert node.warner.count >= 9


@pytest.mark.dds
def test_joint_state_input_checks():
    with RosHarness() as ros:
        node = ros.add_node(SonarLocalizer(
            context=ros.context, cli_args=REMAP,
            parameter_overrides=[Parameter('odometry_source', value='joint_states')]))
        logs = ros.collect('/rosout', Log)
        pub = ros._helper.create_publisher(JointState, '/joint_states', reliable_qos())
        assert ros.wait_for_subscribers([pub])
        msg = JointState(name=['left_wheel_joint', 'caster'], position=[0.0, 0.0])
        pub.publish(msg)
        _wait_for_warning(ros, logs, 'Dropping joint states: no position for '
                                     "['right_wheel_joint']")
        assert node.tracker.stamp_ns is None


def test_tracker_dead_reckons_without_sonar_and_splits_odometry():
    tr = SonarTracker('ekf', np.zeros((2, 3)), sonar_timeout=0.5)
    out = []
    for k in range(12):  # 1 m/s straight, no sonar at all
        out += tr.add_odometry_pose(k * 100_000_000, [0.1 * k, 0.0, 0.0])
    assert [e.stamp_ns * 1e-9 for e in out] == pytest.approx([0.5 + 0.1 * i for i in range(7)])
    assert out[-1].pose == pytest.approx([1.1, 0.0, 0.0])
    assert out[-1].velocity == pytest.approx([1.0, 0.0])
    # A sonar cycle between two odometry stamps: the interval is split in time.
    tr.add_reading(0, 1_150_000_000, 1.0)
    out = tr.add_reading(1, 1_150_000_000, 2.0)
    assert out == []  # odometry has not reached 1.15 s yet
    out = tr.add_odometry_pose(1_200_000_000, [1.2, 0.0, 0.0])
    assert [e.stamp_ns for e in out] == [1_150_000_000]
    assert out[0].pose == pytest.approx([1.15, 0.0, 0.0]) and out[0].accepted == -1


def test_rejects_bad_parameters():
    with RosHarness() as ros:
        for name, value, needle in [
                ('filter', 'pf', 'filter'), ('odometry_source', 'gps', 'odometry_source'),
                ('wheel_radius', -1.0, 'wheel_radius'), ('k1', 2.0, 'k1'),
                ('sonar_mounts', [0.0] * 5, 'sonar_mounts'), ('gate', 0.0, 'gate'),
                ('stale_cycles', 0, 'stale_cycles'), ('unknown', 'maybe', 'unknown'),
                ('map_file', '/nonexistent/map.yaml', 'map_file'),
                ('min_range', 6.0, 'min_range'), ('sonar_topics', ['/a', '/a'], 'sonar_topics'),
                ('process_noise.sigma_d', -0.1, 'process_noise.sigma_d'),
                ('initial_pose.std_x', 0.0, 'initial_pose.std_x')]:
            with pytest.raises(ParameterError, match=name.replace('.', r'\.')):
                SonarLocalizer(context=ros.context,
                               parameter_overrides=[Parameter(name, value=value)])


def test_map_file_parameter(tmp_path, hallway):
    from landmark_nav.localization.grid import save_map_yaml
    save_map_yaml(hallway['grid'], tmp_path / 'hallway.yaml')
    with RosHarness() as ros:
        node = SonarLocalizer(context=ros.context, parameter_overrides=[
            Parameter('map_file', value=str(tmp_path / 'hallway.yaml'))])
        assert np.array_equal(node.tracker.grid.occupancy, hallway['grid'].occupancy)
        node.destroy_node()


def test_config_file_matches_declared_parameters():
    values = parameter_file(REPO, 'sonar_localizer')
    with RosHarness() as ros:
        node = SonarLocalizer(context=ros.context)
        declared = declared_parameters(node)
        node.destroy_node()
    assert set(values) == set(declared)
    for name, value in values.items():
        got = declared[name]
        if isinstance(value, float):
            assert got == pytest.approx(value), name
        elif isinstance(value, list):
            assert list(got) == pytest.approx(value) if value and isinstance(value[0], float) \
                else list(got) == value, name
        else:
            assert got == value, name


def test_calibrating_nominal_odometry_equals_calibrated_wheel_odometry():
    from landmark_nav.localization.odometry import calibrate_control, control_from_wheels
    w = np.random.default_rng(4).normal(size=(50, 2))
    k = (0.9977, 1.0023, 1.0095)
    nominal = control_from_wheels(w, 0.0955, 0.33, 0.1)
    np.testing.assert_allclose(calibrate_control(nominal, 0.33, k),
                               control_from_wheels(w, 0.0955, 0.33, 0.1, k), atol=1e-15)
    np.testing.assert_allclose(calibrate_control(nominal, 0.33), nominal, rtol=1e-12, atol=0)


class _Recorder:
    """A logger stand-in that keeps the warnings."""

    def __init__(self):
        self.warnings = []

    def warning(self, text):
        self.warnings.append(text)


def test_nan_field_of_view_is_warned_with_its_value():
    """A Range with a NaN field of view used to be accepted without a word."""
    with RosHarness() as ros:
        node = SonarLocalizer(context=ros.context)
        log = node.warner._logger = _Recorder()
        msg = Range(header=make_range(1_000_000_000, 'sonar_0', 1.0, 0.5, 0.1, 5.0).header,
                    radiation_type=Range.ULTRASOUND, field_of_view=math.nan, min_range=0.1,
                    max_range=5.0, range=1.0)
        node.on_range(0, msg)
        msg.field_of_view = -0.2
        node.on_range(0, msg)  # another value class right after: reported too
        msg.field_of_view = 0.5
        node.on_range(0, msg)  # a good reading goes on
        assert len(log.warnings) == 2, log.warnings
        assert 'field_of_view=nan' in log.warnings[0] and '/sonar/range_0' in log.warnings[0]
        assert 'field_of_view=-0.2' in log.warnings[1]
        assert node.stats.dropped['malformed'] == 2
        node.destroy_node()
