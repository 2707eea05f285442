"""graph_slam node: the office bag through DDS equals the offline graph run; bad input."""

import math
from pathlib import Path

from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
from landmark_nav.conversions import make_odometry, make_scan, stamp_to_ns
from landmark_nav.evaluation.bags import load_bag
from landmark_nav.evaluation.slam import bag_odometry_noise
from landmark_nav.evaluation.slam_graph import run_graph
from landmark_nav.geometry import compose, inverse
from landmark_nav.nodes.common import ParameterError
from landmark_nav.nodes.graph_slam import GraphSlamNode
from landmark_nav.slam.graph_scan_steps import GraphScanSteps, odometry_at
from landmark_nav.slam.keyframe_graph import GraphParams
from landmark_nav.slam.odometry_noise_models import odometry_noise_model
from landmark_nav.testing import declared_parameters, parameter_file, RosHarness
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from rclpy.parameter import Parameter
from sensor_msgs.msg import LaserScan
from test_ekf_slam_node import bag_messages

OFFICE = Path(__file__).resolve().parents[1] / 'bags' / 'office'
SECONDS = 20.0


def test_odometry_at_reads_only_the_samples_around_the_stamp():
    times = np.array([0.0, 1.0, 2.0, 3.0])
    poses = np.array([[0, 0, 0], [1, 0, 3.0], [2, 0, -3.0], [3, 1, 0]], dtype=float)
    # between samples: the pair around it, the heading along the shortest arc
    p = odometry_at(1.5, times, poses)
    assert p[0] == 1.5 and abs(abs(p[2]) - math.pi) < 1e-12
    # the same from a buffer that holds only that pair
    assert np.array_equal(odometry_at(1.5, times[1:3], poses[1:3]), p)
    # at a sample: that sample, also when it is the newest
    assert np.array_equal(odometry_at(3.0, times, poses), poses[3])
    with pytest.raises(ValueError, match='outside'):
        odometry_at(3.5, times, poses)


def test_steps_wait_for_the_odometry_and_go_in_stamp_order():
    drops = []
    steps = GraphScanSteps([0.0, 0.0, 0.0], odometry_noise_model('simulator'),
                           on_drop=lambda r, m: drops.append(r))
    s = 10 ** 9  # stamps in seconds: 4 m in 3 s is a plausible motion
    pts = np.zeros((0, 2))
    steps.add_scan(5 * s, pts)  # before any odometry: waits, then has none
    steps.add_odometry(10 * s, [0.0, 0.0, 0.0])
    assert drops == ['before_odometry'] and steps.waiting == 0
    steps.add_scan(30 * s, pts)
    steps.add_scan(20 * s, pts)  # out of arrival order, in stamp order
    assert steps.pop_ready() is None  # the odometry does not reach 20 yet
    steps.add_odometry(40 * s, [4.0, 0.0, 0.0])
    assert [steps.step().stamp_ns for _ in range(2)] == [20 * s, 30 * s]
    assert np.allclose(steps.graph.keyframes[0].odometry, [4.0 / 3.0, 0.0, 0.0])
    steps.add_scan(25 * s, pts)  # older than the last processed scan
    steps.add_odometry(35 * s, [0.0, 0.0, 0.0])  # older than the newest odometry
    steps.add_odometry(50 * s, [np.nan, 0.0, 0.0])
    assert drops[1:] == ['out_of_order', 'out_of_order', 'nonfinite']


def test_a_restarted_odometry_source_starts_a_new_graph():
    events = []
    steps = GraphScanSteps([0.0, 0.0, 0.0], odometry_noise_model('simulator'),
                           on_drop=lambda r, m: events.append(r), restart=True)
    s = 10 ** 9
    pts = np.zeros((0, 2))
    for t in range(10, 21):
        steps.add_odometry(t * s, [float(t), 0.0, 0.0])
    for t in (12, 14, 30):  # 30: waits, the odometry never reaches it in this run
        steps.add_scan(t * s, pts)
    assert [steps.step().stamp_ns for _ in range(2)] == [12 * s, 14 * s]
    late = steps.pop_ready  # a scan taken before the restart and processed after it
    steps.add_scan(16 * s, pts)
    item = late()
    # one far-back sample, then the old time base goes on: dropped, nothing restarts
    steps.add_odometry(2 * s, [0.0, 0.0, 0.0])
    steps.add_odometry(21 * s, [21.0, 0.0, 0.0])
    assert events == ['out_of_order'] and steps.generation == 0
    # three in a row, each newer: a new graph from them, the old run's waiting scan dropped
    for t in (1, 2):
        steps.add_odometry(t * s, [5.0 + t, 0.0, 0.0])
    assert events == ['out_of_order'] and steps.generation == 0  # held so far
    steps.add_odometry(3 * s, [8.0, 0.0, 0.0])
    assert events[1:] == ['restart', 'restarted'] and steps.generation == 1
    assert steps.process(*item) is None and events[-1] == 'restarted'
    steps.add_scan(int(1.5 * s), pts)  # of the new run: its odometry, the new graph
    st = steps.step()
    assert st.stamp_ns == int(1.5 * s) and st.generation == 1
    assert np.allclose(st.odometry, [6.5, 0.0, 0.0]) and len(steps.graph.keyframes) == 1
    # without restart (the offline runner) the same samples are dropped
    plain = GraphScanSteps([0.0, 0.0, 0.0], odometry_noise_model('simulator'))
    plain.add_odometry(10 * s, [0.0, 0.0, 0.0])
    for t in (1, 2, 3):
        plain.add_odometry(t * s, [0.0, 0.0, 0.0])
    assert plain.counts['out_of_order'] == 3 and plain.generation == 0


def _steps_node(ros, warnings):
    """Return a node whose warnings go to ``warnings``, each logged (no throttling)."""
    node = GraphSlamNode(context=ros.context)
    node.warner._logger = type('Log', (), {'warning': staticmethod(warnings.append)})
    node.warner._period = 0.0
    return node


def test_an_odometry_jump_is_bridged_counted_and_warned():
    """A driver re-zeroing its pose: the odometry after it continues from the pose before."""
    s = 10 ** 9
    pts = np.zeros((0, 2))
    steps = GraphScanSteps([0.0, 0.0, 0.0], odometry_noise_model('simulator'))
    for t, x in ((1, 10.0), (2, 11.0), (3, 0.0), (4, 1.0)):  # reset to 0 at 3 s
        steps.add_odometry(t * s, [x, 0.0, 0.0])
    for t in (1.5, 3.5):
        steps.add_scan(int(t * s), pts)
    assert steps.counts['jump'] == 1
    assert steps.pop_ready()[4] is None  # before the jump: the odometry as it came
    _, odometry, _, _, offset = steps.pop_ready()
    assert np.allclose(odometry, [11.5, 0.0, 0.0])  # not 0.5: bridged
    # the offset gives the odometry back in its frame as it came (the node's map -> odom)
    assert np.allclose(compose(offset, [0.5, 0.0, 0.0]), odometry)
    warnings = []
    with RosHarness() as ros:
        node = _steps_node(ros, warnings)
        try:
            for t, x in ((1, 10.0), (2, 11.0), (3, 0.0)):
                node.on_odom(make_odometry(t * s, 'odom', 'base_link', [x, 0.0, 0.0]))
        finally:
            node.destroy_node()
    assert node.stats.events['odometry.jump'] == 1 and node.stats.dropped_count == 0
    assert len(warnings) == 1 and 'at 3000000000 ns moved 11.000 m' in warnings[0]


def test_a_future_odometry_stamp_is_withdrawn_counted_and_warned():
    """One sample stamped far ahead, then the clock goes on: it goes, the graph stays."""
    s = 10 ** 9
    warnings = []
    with RosHarness() as ros:
        node = _steps_node(ros, warnings)
        try:
            for t in (1.0, 1.1, 50.0, 1.2, 1.3, 1.4, 1.5):  # 50 s: in the future
                node.on_odom(make_odometry(int(t * s), 'odom', 'base_link', [t, 0.0, 0.0]))
            steps = node.steps
            assert steps.newest_odometry_ns == int(1.5 * s) and steps.generation == 0
        finally:
            node.destroy_node()
    assert node.stats.events['odometry.retracted'] == 1 and 'restart' not in node.stats.events
    assert node.stats.dropped_count == 0 and steps.counts['jump'] == 0
    assert len(warnings) == 1 and 'at 50000000000 ns: lay 48.900 s ahead' in warnings[0]


@pytest.mark.dds
def test_node_equals_offline_on_the_office_bag_with_its_outputs():
    """Same steps, same poses and covariances as ``evaluate --backend graph``; nothing lost.

    The messages are published as fast as the node takes them, the back end lags behind
    in its thread (its queue carries the scans).
    """
    scenario = load_bag(OFFICE, max_seconds=SECONDS)
    noise = bag_odometry_noise(scenario)[0]
    ref = run_graph(scenario, noise)
    msgs = bag_messages(SECONDS, OFFICE)
    with RosHarness() as ros:
        node = ros.add_node(GraphSlamNode(context=ros.context, parameter_overrides=[
            Parameter('odometry.model', value='simulator'),
            Parameter('laser_pose', value=[float(v) for v in scenario.laser.mount])]))
        poses = ros.collect('pose', PoseWithCovarianceStamped)
        corrections = ros.collect('map_to_odom', TransformStamped)
        pub_odom = ros._helper.create_publisher(Odometry, 'odom', 10)
        pub_scan = ros._helper.create_publisher(LaserScan, 'scan', 10)
        assert ros.wait_for_subscribers([pub_odom, pub_scan])
        n = {'/odom': 0, '/scan': 0}
        for topic, msg in msgs:
            n[topic] += 1
            (pub_odom if topic == '/odom' else pub_scan).publish(msg)
            count = (lambda: node.odom_count) if topic == '/odom' else (lambda: node.scan_count)
            assert ros.wait_until(lambda: count() >= n[topic], 5)
        assert ros.wait_until(lambda: len(poses) >= len(ref.stamps)
                              and node.steps.waiting <= 1, 60)
        assert ros.wait_until(lambda: len(corrections) == len(poses), 5)
        stats = node.stats
        assert stats.dropped_count == 0 and node.warner.count == 0
        graph = node.steps.graph
        assert len(graph.keyframes) == len(ref.graph.keyframes) > 5
        path = node.path_message()
    stamps = np.array([stamp_to_ns(p.header.stamp) for p in poses])
    # the offline run leaves out a last scan whose sweep ends after the bag's last odometry
    assert np.array_equal(stamps[:len(ref.stamps)], ref.stamps) and \
        len(stamps) - len(ref.stamps) <= 1
    k = len(ref.stamps)
    xy = np.array([[p.pose.pose.position.x, p.pose.pose.position.y] for p in poses])[:k]
    cov = np.array([np.asarray(p.pose.covariance).reshape(6, 6)[[0, 1, 5]][:, [0, 1, 5]]
                    for p in poses])[:k]
    err = np.hypot(*(xy - ref.online[:, :2]).T)
    print(f'max node-offline difference {err.max():.3g} m over {k} poses')
    assert err.max() < 1e-9  # measured 0: the same arithmetic on the same numbers
    assert np.allclose(cov, ref.online_cov, rtol=1e-9, atol=1e-15)
    # map -> odom composes each pose with the inverse odometry
    c = corrections[k - 1].transform
    o = ref.odometry[k - 1]
    expect = compose(ref.online[k - 1], inverse(o))
    assert abs(c.translation.x - expect[0]) < 1e-9 and abs(c.translation.y - expect[1]) < 1e-9
    # the path: the keyframes where the graph places them at the end
    assert len(path.poses) == len(ref.graph.keyframes)
    last = path.poses[-1].pose.position
    assert abs(last.x - ref.graph.estimates[-1, 0]) < 1e-9


@pytest.mark.dds
def test_bad_input_is_warned_and_counted_and_the_node_keeps_running():
    with RosHarness() as ros:
        node = ros.add_node(GraphSlamNode(context=ros.context, parameter_overrides=[
            Parameter('max_beams', value=100)]))
        node.warner._period = 0.0  # every warning logged (the throttling is tested apart)
        scan = make_scan(2_000_000_000, 'laser', -1.0, 0.01, [1.0] * 201, 0.1, 30.0)
        bad_scan = make_scan(2_000_000_000, 'laser', -1.0, 0.01, [1.0] * 50, 0.1, 30.0)
        bad_scan.angle_increment = math.nan
        node.on_scan(scan)  # 201 beams > max_beams
        node.on_scan(bad_scan)
        node.on_odom(make_odometry(0, 'odom', 'base_link', [0.0, 0.0, 0.0]))  # stamp 0
        odom = make_odometry(1_000_000_000, 'odom', 'base_link', [0.0, 0.0, 0.0])
        odom.pose.pose.position.x = math.nan
        node.on_odom(odom)
        d = node.stats.dropped
        assert d['oversized'] == 1 and d['malformed'] == 3
        assert node.warner.count == 4
        # still running: a good pair makes a step
        node.on_odom(make_odometry(3_000_000_000, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        node.on_scan(make_scan(3_000_000_000, 'laser', -1.0, 0.01, [1.0] * 50, 0.1, 30.0))
        assert ros.wait_until(lambda: node.stats.processed_count == 1, 10)
        # the diagnostics carry the graph's counts as the worker left them after its step
        values = {kv.key: kv.value for kv in node.stats.status().values}
        assert values['keyframes'] == str(len(node.steps.graph.keyframes)) == '1'
        assert values['waiting'] == '0' and values['loops.proposed'] == '0'
        # a back end that fails on a scan: counted and warned, the next scan is processed
        add_scan, failed = node.steps.graph.add_scan, []

        def fail_once(*args):
            if not failed:
                failed.append(1)
                raise RuntimeError('injected')
            return add_scan(*args)
        node.steps.graph.add_scan = fail_once
        for t in (4_000_000_000, 5_000_000_000):
            node.on_odom(make_odometry(t, 'odom', 'base_link', [0.0, 0.0, 0.0]))
            node.on_scan(make_scan(t, 'laser', -1.0, 0.01, [1.0] * 50, 0.1, 30.0))
        assert ros.wait_until(lambda: node.stats.processed_count == 2, 10)
        assert node.stats.dropped['backend_error'] == 1
        # a failure between scans (the queue's bookkeeping): warned and counted, the worker
        # goes on with the next scan instead of ending
        pop_ready, failed = node.steps.pop_ready, []

        def fail_first(*args):
            if not failed:
                failed.append(1)
                raise RuntimeError('injected between scans')
            return pop_ready(*args)
        node.steps.pop_ready = fail_first
        assert ros.wait_until(lambda: node.stats.events['backend_error'] == 1, 10)
        node.on_odom(make_odometry(6_000_000_000, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        node.on_scan(make_scan(6_000_000_000, 'laser', -1.0, 0.01, [1.0] * 50, 0.1, 30.0))
        assert ros.wait_until(lambda: node.stats.processed_count == 3, 10)
        assert node._worker.is_alive() and node.stats.dropped['backend_error'] == 1


def test_a_full_queue_says_why_the_scans_wait():
    """No odometry, or none as new as the scans: the warning says so (not just its size)."""
    with RosHarness() as ros:
        node = GraphSlamNode(context=ros.context, parameter_overrides=[
            Parameter('max_queue_mb', value=0.01)])  # 10 KiB: two scans of 400 points
        warnings = []
        node.warner._logger = type('Log', (), {'warning': staticmethod(warnings.append)})
        node.warner._period = 0.0
        try:
            for t in (2, 3):
                node.on_scan(make_scan(t * 10 ** 9, 'laser', -1.0, 0.005, [1.0] * 400, 0.1,
                                       30.0))
            node.on_odom(make_odometry(1_000_000_000, 'odom', 'base_link', [0.0, 0.0, 0.0]))
            node.on_scan(make_scan(4 * 10 ** 9, 'laser', -1.0, 0.005, [1.0] * 400, 0.1, 30.0))
        finally:
            node.destroy_node()
    assert node.stats.dropped['queue_full'] == 2 and len(warnings) == 2
    assert 'Dropping scan at 2000000000 ns' in warnings[0]
    assert 'no odometry received yet' in warnings[0]
    assert 'Dropping scan at 3000000000 ns' in warnings[1]
    assert 'the newest odometry, at 1000000000 ns, is older than every waiting scan' \
        in warnings[1]


def test_scans_dropped_while_waiting_leave_no_reception_time_behind():
    with RosHarness() as ros:
        node = GraphSlamNode(context=ros.context)
        try:
            for t in (1, 2, 5):
                node.on_scan(make_scan(t * 10 ** 9, 'laser', -1.0, 0.01, [1.0] * 50, 0.1,
                                       30.0))
            assert sorted(node._received) == [t * 10 ** 9 for t in (1, 2, 5)]
            # the first odometry at 3 s: the scans at 1 and 2 s have no pose, 5 s waits
            node.on_odom(make_odometry(3 * 10 ** 9, 'odom', 'base_link', [0.0, 0.0, 0.0]))
            assert node.steps.counts['before_odometry'] == 2
            assert sorted(node._received) == [5 * 10 ** 9] == node.steps.waiting_stamps
        finally:
            node.destroy_node()


@pytest.mark.parametrize('name, value, match', [
    ('loop_floor', [0.03, 0.03], 'loop_floor'),
    ('loop.window_xy', [0.5], 'loop.window_xy'),
    ('odometry.model', 'k_d=-1', 'odometry.model'),
    ('laser_pose', [0.0, 0.0], 'laser_pose'),
    ('restart_messages', 0, 'restart_messages')])
def test_bad_parameter_is_a_parameter_error_naming_it(name, value, match):
    with RosHarness() as ros:
        with pytest.raises(ParameterError, match=match):
            GraphSlamNode(context=ros.context, parameter_overrides=[Parameter(name,
                                                                              value=value)])


def test_config_file_matches_declared_parameters():
    """config/graph_slam.yaml lists every declared parameter with its default."""
    values = parameter_file(OFFICE.parents[1], 'graph_slam')
    with RosHarness() as ros:
        node = GraphSlamNode(context=ros.context)
        declared = declared_parameters(node)
        params = node.params
        node.destroy_node()
    assert set(values) == set(declared)
    for name, value in values.items():
        assert declared[name] == (pytest.approx(value) if isinstance(value, float) else value)
    assert params == GraphParams()  # the defaults are the offline runner's
