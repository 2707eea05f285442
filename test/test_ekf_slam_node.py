"""ekf_slam node: office bag through DDS equals the offline run (de-skew on); bad input; QoS."""

from dataclasses import replace
from pathlib import Path
import time
from types import SimpleNamespace

from geometry_msgs.msg import PoseWithCovarianceStamped
from landmark_nav.bag import BagReader
from landmark_nav.conversions import make_odometry, make_scan, stamp_to_ns
from landmark_nav.evaluation.bags import load_bag
from landmark_nav.evaluation.slam import run_slam
from landmark_nav.feature_msgs import feature_cloud_to_arrays, make_feature_cloud
from landmark_nav.laser.corners import CornerParams
from landmark_nav.nodes import ekf_slam as ekf_slam_module
from landmark_nav.nodes.common import ParameterError
from landmark_nav.nodes.corner_extractor import CornerExtractor
from landmark_nav.nodes.ekf_slam import EkfSlamNode
from landmark_nav.slam.configuration import CHAPTER, default_values, slam_configuration
from landmark_nav.slam.ekf_slam import LINE, SlamParams
from landmark_nav.slam.frontend import FrontendParams, ODOMETRY_NOISE_MODELS
from landmark_nav.slam.keyframes import KeyframeParams
from landmark_nav.slam.slam_map import load_map, save_map
from landmark_nav.testing import declared_parameters, parameter_file, RosHarness, shared_data
from nav_msgs.msg import Odometry, Path as PathMsg
import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan, PointCloud2
from std_srvs.srv import Trigger
import yaml

OFFICE = Path(__file__).resolve().parents[1] / 'bags' / 'office'
SECONDS = 40.0


def bag_messages(seconds=SECONDS, bag=OFFICE):
    out = []
    with BagReader(bag) as reader:
        t0 = None
        for topic, _, msg in reader.decoded(['/odom', '/scan']):
            t = stamp_to_ns(msg.header.stamp)
            t0 = t if t0 is None else t0
            if t - t0 > seconds * 1e9:
                break
            out.append((topic, msg))
    return out


def call(ros, node_name, srv):
    """Call a Trigger service and return the response."""
    client = ros._helper.create_client(Trigger, f'{node_name}')
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(Trigger.Request())
    assert ros.wait_until(future.done, 5.0)
    return future.result()


def replay(ros, msgs, slam, odom_qos=10):
    """Publish the bag's messages one by one, each after the previous one was received.

    A scan is done when the node has both its corner set (when it maps corners) and the scan
    (when it subscribes it).
    """
    pub_odom = ros._helper.create_publisher(Odometry, 'odom', odom_qos)
    pub_scan = ros._helper.create_publisher(LaserScan, 'scan', 10)
    assert ros.wait_for_subscribers([pub_odom, pub_scan])
    corners = slam.landmarks != 'lines'
    if corners:
        assert ros.wait_until(lambda: slam.count_publishers('corners/features') > 0, 5)
    scans = 'scan' in slam.join.parts
    n_odom = n_scan = 0
    for topic, msg in msgs:
        if topic == '/odom':
            n_odom += 1
            pub_odom.publish(msg)
            assert ros.wait_until(lambda: slam.odom_count >= n_odom, 5)
        else:
            n_scan += 1
            pub_scan.publish(msg)
            assert ros.wait_until(lambda: (not corners or slam.corner_count >= n_scan)
                                  and (not scans or slam.scan_count >= n_scan), 5)
    return n_scan


def chapter_profile() -> dict:
    """Return the ``ros__parameters`` of config/ekf_slam_chapter.yaml (the chapter's filter)."""
    return yaml.safe_load((OFFICE.parents[1] / 'config' / 'ekf_slam_chapter.yaml')
                          .read_text())['ekf_slam']['ros__parameters']


def node_and_offline(tmp_path, bag, seconds, landmarks, noise, extra=None):
    """Replay a bag through corner_extractor + ekf_slam; return the node's and offline runs.

    Both get the bag's laser mount and noise (the node as parameters), ``noise`` as the
    odometry model, ``landmarks`` and ``extra`` (further parameters, e.g. a profile) on top
    of the shipped defaults; the offline run's configuration is
    :func:`~landmark_nav.slam.configuration.slam_configuration` of the same parameters.
    """
    msgs = bag_messages(seconds, bag)
    scenario = load_bag(bag, max_seconds=seconds, require_reference=False)
    laser = scenario.laser
    given = dict(extra or {})
    given.update({'odometry.model': noise, 'landmarks': landmarks,
                  'laser_pose': [float(v) for v in laser.mount],
                  'laser_sigma_range': float(laser.sigma_range),
                  'lines.sigma_r': float(laser.sigma_range),
                  'lines.sigma_phi': float(laser.sigma_angle)})
    with RosHarness() as ros:
        ros.add_node(CornerExtractor(context=ros.context, parameter_overrides=[
            Parameter('sigma_r', value=float(laser.sigma_range)),
            Parameter('sigma_phi', value=float(laser.sigma_angle))]))
        slam = ros.add_node(EkfSlamNode(context=ros.context, parameter_overrides=[
            Parameter('map_file', value=str(tmp_path / 'map.yaml')),
            # The test paces the messages; a stall of the machine is no odometry outage.
            Parameter('odometry_timeout', value=3600.0)]
            + [Parameter(k, value=v) for k, v in given.items()]))
        poses = ros.collect('pose', PoseWithCovarianceStamped)
        clouds = ros.collect('corners/features', PointCloud2)
        n_scan = replay(ros, msgs, slam)
        # Every scan but the last (its sweep ends after the last odometry) is a step.
        assert ros.wait_until(lambda: len(poses) >= n_scan - 1, 5)
        res = call(ros, 'save_map', Trigger)
        assert res.success, res.message
        node = SimpleNamespace(
            poses=poses, clouds=clouds, n_scan=n_scan, warnings=slam.warner.count,
            saved=yaml.safe_load((tmp_path / 'map.yaml').read_text()),
            kinds=slam.slam.landmark_kinds, events=dict(slam.frontend.events),
            stats=dict(slam.slam.stats), markers=slam.landmark_markers(0))
        assert call(ros, 'reset', Trigger).success
        assert slam.slam is None
    config = slam_configuration(given)
    ref = run_slam(scenario, config.params, CornerParams(sigma_r=laser.sigma_range,
                                                         sigma_phi=laser.sigma_angle),
                   deskew=True, landmarks=config.landmarks, frontend=config.frontend,
                   line_params=config.line_params, visibility=config.visibility)
    return node, ref


def assert_node_equals_offline(node, ref):
    """Assert the same steps, poses equal to 1e-9 m, the same map."""
    stamps = np.array([stamp_to_ns(p.header.stamp) for p in node.poses])
    xy = np.array([[p.pose.pose.position.x, p.pose.pose.position.y] for p in node.poses])
    assert len(stamps) == len(ref.stamps) and np.array_equal(stamps, ref.stamps)
    err = np.hypot(*(xy - ref.poses[:, :2]).T)
    print('max node-offline difference', err.max(), 'm over', len(err), 'poses')
    assert err.max() < 1e-9  # measured 0 (the same arithmetic on the same float64 numbers)
    assert node.events['processed'] == len(ref.stamps)
    assert node.stats == ref.stats  # matched, confirmed, pruned, ... alike
    assert node.warnings == 0  # every set complete (corners and scan)
    saved = node.saved['landmarks']
    assert len(saved) == ref.landmarks.shape[0] + ref.lines.shape[0]
    assert sum(s['kind'] == 'line' for s in saved) == ref.lines.shape[0]


@pytest.mark.dds
def test_node_equals_offline_with_deskew_and_services(tmp_path):
    """Node and offline run are one pipeline (SlamFrontend): equal to 1e-9 m, de-skew on."""
    node, ref = node_and_offline(tmp_path, OFFICE, SECONDS, 'corners', 'simulator',
                                 chapter_profile())
    assert len(node.clouds) == node.n_scan
    assert max(np.max(feature_cloud_to_arrays(c)['time'], initial=0.0)
               for c in node.clouds) > 0.0
    assert_node_equals_offline(node, ref)
    assert node.events['jump'] == 0 and ref.landmarks.shape[0] > 5
    assert len(node.saved['landmarks'][0]['covariance']) == 4


@pytest.mark.dds
@pytest.mark.parametrize('landmarks', ['lines', 'both'])
def test_node_equals_offline_with_lines(tmp_path, landmarks):
    """Lines from the scan, visibility-aware pruning: node = offline run (de-skew on)."""
    node, ref = node_and_offline(tmp_path, OFFICE, 20.0, landmarks, 'simulator',
                                 chapter_profile())
    assert_node_equals_offline(node, ref)
    assert ref.lines.shape[0] >= 3 and np.sum(node.kinds == LINE) == ref.lines.shape[0]
    if landmarks == 'both':
        assert ref.landmarks.shape[0] > 3
    lines = [m for m in node.markers.markers if m.ns == 'landmark_lines']
    assert len(lines) == ref.lines.shape[0] and all(len(m.points) == 2 for m in lines)


@pytest.mark.dds
def test_node_localization_on_a_saved_map_equals_offline(tmp_path):
    """Localization on a load_map map: node = offline run on the same map; .npz save_map.

    Both run the chapter's filter (the profile).
    """
    scenario = load_bag(OFFICE, max_seconds=SECONDS)
    laser = scenario.laser
    cp = CornerParams(sigma_r=laser.sigma_range, sigma_phi=laser.sigma_angle)
    simulator = SlamParams(odometry=ODOMETRY_NOISE_MODELS['simulator'])
    built = run_slam(scenario, simulator, cp).final_map
    assert built.size > 5
    map_path = save_map(tmp_path / 'built.npz', built)
    seconds = 15.0
    msgs = bag_messages(seconds)
    with RosHarness() as ros:
        ros.add_node(CornerExtractor(context=ros.context))
        slam = ros.add_node(EkfSlamNode(context=ros.context, parameter_overrides=[
            Parameter('mode', value='localization'),
            Parameter('load_map', value=str(map_path)),
            Parameter('map_file', value=str(tmp_path / 'after.npz')),
            Parameter('odometry.model', value='simulator'),
            Parameter('odometry_timeout', value=3600.0)]
            + [Parameter(k, value=v) for k, v in chapter_profile().items()]))
        poses = ros.collect('pose', PoseWithCovarianceStamped)
        n_scan = replay(ros, msgs, slam)
        assert ros.wait_until(lambda: len(poses) >= n_scan - 1, 5)
        res = call(ros, 'save_map', Trigger)
        assert res.success, res.message
        stats = dict(slam.slam.stats)
    after = load_map(tmp_path / 'after.npz')
    ref = run_slam(load_bag(OFFICE, max_seconds=seconds), replace(simulator, mode='localization'),
                   cp, slam_map=built)
    xy = np.array([[p.pose.pose.position.x, p.pose.pose.position.y] for p in poses])
    assert len(xy) == len(ref.stamps) > 50
    err = np.hypot(*(xy - ref.poses[:, :2]).T)
    print('localization: max node-offline difference', err.max(), 'm; stats', stats)
    assert err.max() < 1e-9
    # Localization adds nothing: the saved map has the loaded landmarks only.
    assert np.array_equal(after.ids, built.ids) and stats['confirmed'] == 0
    assert stats['matched'] > 0


def test_localization_without_a_map_is_a_parameter_error():
    with RosHarness() as ros:
        with pytest.raises(ParameterError, match='load_map'):
            EkfSlamNode(context=ros.context,
                        parameter_overrides=[Parameter('mode', value='localization')])
        with pytest.raises(ParameterError, match='load_map'):
            EkfSlamNode(context=ros.context,
                        parameter_overrides=[Parameter('load_map', value='/nonexistent.npz')])


@pytest.mark.dds
def test_odom_from_a_best_effort_publisher():
    """The /odom subscription is best effort: a sensor-data (best-effort) publisher reaches it."""
    t0 = 1_700_000_000_000_000_000
    with RosHarness() as ros:
        slam = ros.add_node(EkfSlamNode(context=ros.context))
        pub = ros._helper.create_publisher(Odometry, 'odom', qos_profile_sensor_data)
        assert ros.wait_for_subscribers([pub])
        for k in range(5):
            pub.publish(make_odometry(t0 + k * 100_000_000, 'odom', 'base_link',
                                      [0.01 * k, 0.0, 0.0]))
        assert ros.wait_until(lambda: slam.odom_count == 5, 5)
        assert slam.frontend.events['accepted'] == 5


def corner_cloud(t, rows):
    """Return a corner cloud with the given rows."""
    names = ('x', 'y', 'z', 'bisector', 'opening', 'cov_xx', 'cov_xy', 'cov_yy')
    rows = np.asarray(rows, dtype=float).reshape(-1, 8)
    return make_feature_cloud(t, 'laser', names, dict(zip(names, rows.T)))


T0 = 1_700_000_000_000_000_000
GOOD_CORNER = [2.0, 1.0, 0.0, 3.0, 1.57, 1e-4, 0.0, 1e-4]  # corner_cloud row


def recording_node(ros, poses=None):
    """Return an ekf_slam node whose published steps' stamps go to the returned list.

    With ``poses`` (a dict), each published step's pose goes there too, by stamp.
    """
    slam = EkfSlamNode(context=ros.context)
    stamps = []

    def publish(t, pose, cov):
        stamps.append(t)
        if poses is not None:
            poses[t] = np.array(pose, dtype=float)
    slam._publish = publish
    return slam, stamps


def test_structural_corners_only_keeps_the_labelled_corners():
    names = ('x', 'y', 'z', 'bisector', 'opening', 'cov_xx', 'cov_xy', 'cov_yy', 'structural')
    rows = np.array([GOOD_CORNER + [1.0], [3.0, -1.0] + GOOD_CORNER[2:] + [0.0]])
    labelled = make_feature_cloud(T0, 'laser', names, dict(zip(names, rows.T)))
    with RosHarness() as ros:
        for only, kept in ((False, 2), (True, 1)):
            slam = EkfSlamNode(context=ros.context, parameter_overrides=[
                Parameter('structural_corners_only', value=only)])
            offered = []
            slam._offer = lambda part, t, cols: offered.append(cols)
            slam.on_corners(labelled)
            assert len(offered[0]) == kept and offered[0][0, 0] == 2.0
            slam.on_corners(corner_cloud(T0, [GOOD_CORNER, GOOD_CORNER]))  # no label: all
            assert len(offered[1]) == 2 and slam.warner.count == int(only)
            slam.destroy_node()


@pytest.mark.dds
def test_bad_input():
    t0 = 1_700_000_000_000_000_000
    good = [2.0, 1.0, 0.0, 3.0, 1.57, 1e-4, 0.0, 1e-4]
    with RosHarness() as ros:
        slam = ros.add_node(EkfSlamNode(context=ros.context))
        poses = ros.collect('pose', PoseWithCovarianceStamped)
        pub_odom = ros._helper.create_publisher(Odometry, 'odom', 10)
        pub_c = ros._helper.create_publisher(PointCloud2, 'corners/features', 10)
        assert ros.wait_for_subscribers([pub_odom, pub_c])

        def odom(t, x):
            """Publish an odometry pose."""
            pub_odom.publish(make_odometry(t, 'odom', 'base_link', [x, 0.0, 0.0]))

        pub_c.publish(corner_cloud(t0 - 10_000_000, [good]))  # waits for the first odometry
        assert ros.wait_until(lambda: slam.corner_count == 1, 5)
        assert slam.warner.count == 0 and len(slam.pending) == 1
        odom(t0, 0.0)  # ... which comes later: the set is older, no pose for it (not a drop)
        odom(t0 + 100_000_000, 0.01)
        assert ros.wait_until(lambda: slam.odom_count == 2, 5)
        assert slam.warner.count == 0 and not slam.pending
        assert slam.stats.before_odometry == 1 and slam.stats.dropped_count == 0
        pub_c.publish(corner_cloud(t0 + 50_000_000, [good, [np.nan] * 8]))  # NaN row dropped
        assert ros.wait_until(lambda: len(poses) == 1, 5)
        assert slam.warner.count == 1
        assert abs(poses[0].pose.pose.position.x - 0.005) < 1e-9
        odom(t0 + 50_000_000, 0.02)  # back in time (by 50 ms): dropped, no reset
        assert ros.wait_until(lambda: slam.odom_count == 3, 5)
        assert slam.resets == 0 and slam.frontend.events['backward'] == 1
        assert slam.warner.count == 2
        odom(t0 + 200_000_000, 2.0)  # 1.99 m in 0.1 s: a frame jump, bridged (map kept)
        assert ros.wait_until(lambda: slam.odom_count == 4, 5)
        pub_c.publish(corner_cloud(t0 + 200_000_000, [good]))
        assert ros.wait_until(lambda: len(poses) == 2, 5)
        assert slam.resets == 0 and slam.frontend.events['jump'] == 1
        assert abs(poses[1].pose.pose.position.x - 0.01) < 1e-9  # no motion across the jump
        assert poses[1].pose.covariance[0] > 0.1 ** 2  # ... but its uncertainty
        filt = slam.slam
        odom(t0 - 2_000_000_000, 0.0)  # 2.2 s back: one sample is held, never a reset ...
        assert ros.wait_until(lambda: slam.odom_count == 5, 5)
        assert slam.resets == 0 and slam.slam is filt
        odom(t0 - 1_900_000_000, 0.0)  # ... three in a row: the source restarted, so does
        odom(t0 - 1_800_000_000, 0.0)  # the filter
        assert ros.wait_until(lambda: slam.odom_count == 7, 5)
        assert slam.resets == 1 and slam.slam.num_landmarks == 0


def test_out_of_order_corner_sets_are_processed_in_stamp_order():
    """A corner set older than one already queued used to crash the node (extrapolation)."""
    t0, good, poses = T0, GOOD_CORNER, {}
    with RosHarness() as ros:
        slam, stamps = recording_node(ros, poses)
        slam.on_odom(make_odometry(t0, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        slam.on_odom(make_odometry(t0 + 100_000_000, 'odom', 'base_link', [0.01, 0.0, 0.0]))
        slam.on_corners(corner_cloud(t0 + 200_000_000, [good]))  # waits for odometry
        slam.on_corners(corner_cloud(t0 + 50_000_000, [good]))  # older, covered: processed
        assert stamps == [t0 + 50_000_000]
        assert [p[0] for p in slam.pending] == [t0 + 200_000_000]
        slam.on_corners(corner_cloud(t0 + 20_000_000, [good]))  # before the last step
        assert stamps == [t0 + 50_000_000] and slam.stats.dropped['out_of_order'] == 1
        slam.on_odom(make_odometry(t0 + 300_000_000, 'odom', 'base_link', [0.03, 0.0, 0.0]))
        assert stamps == [t0 + 50_000_000, t0 + 200_000_000] and not slam.pending
        # each set at the odometry interpolated to its stamp (between keyframes too)
        assert abs(poses[t0 + 50_000_000][0] - 0.005) < 1e-12
        assert abs(poses[t0 + 200_000_000][0] - 0.02) < 1e-12
        # 1.5 cm from the last keyframe (the default keyframe.min_travel_m is 0.1 m): the
        # filter stays at the first set's step
        assert abs(slam.slam.pose[0] - 0.005) < 1e-12
        slam.destroy_node()


def test_corner_sets_stamped_before_the_first_odometry_are_counted_apart_not_dropped():
    """The live soak's start: sets stamped 126..1 ms before the first odometry came after it.

    No odometry pose exists for them: not processed, counted as ``before_odometry`` on
    /diagnostics and stated in one info line, not as drops.
    """
    t0, good = T0, GOOD_CORNER
    with RosHarness() as ros:
        slam, stamps = recording_node(ros)
        infos = []
        slam.get_logger = lambda: SimpleNamespace(info=infos.append)
        slam.on_odom(make_odometry(t0, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        for dt in (-126_000_000, -101_000_000, -1_000_000, 24_000_000):
            slam.on_corners(corner_cloud(t0 + dt, [good]))
        assert stamps == [] and len(slam.pending) == 1
        slam.on_odom(make_odometry(t0 + 100_000_000, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        assert stamps == [t0 + 24_000_000] and slam.stats.dropped_count == 0
        assert slam.stats.before_odometry == 3 and slam.warner.count == 0
        (line,) = [text for text in infos if 'before_odometry' in text]
        assert '3 corner set(s) stamped before it' in line and 'came 0.13 s before' in line
        values = {v.key: v.value for v in slam.stats.status().values}
        assert (values['before_odometry'], values['dropped'], values['processed']) == (
            '3', '0', '1')
        slam.destroy_node()


def test_a_base_that_starts_seconds_after_the_laser_loses_no_set_it_covers(monkeypatch):
    """The 10-minute live soak: the first odometry came 3.1 s after the first corner set.

    Before the first step the node dropped the sets more than start_hold_s (3 s) older than
    the newest as no_odometry, although the odometry, delivered late, covered them. Now the
    wait is bounded by memory only (MAX_START_BYTES).
    """
    t0, good = T0, GOOD_CORNER
    with RosHarness() as ros:
        slam, stamps = recording_node(ros)
        sets = [t0 - 3_100_000_000 + k * 25_000_000 for k in range(284)]  # 3.1 s + 4 s
        for t in sets:
            slam.on_corners(corner_cloud(t, [good]))
        assert len(slam.pending) == 284 and slam.stats.dropped_count == 0
        for k in range(42):  # odometry from t0 to 4.1 s, delivered after the sets
            slam.on_odom(make_odometry(t0 + k * 100_000_000, 'odom', 'base_link',
                                       [0.0, 0.0, 0.0]))
        assert stamps == [t for t in sets if t >= t0] and len(stamps) == 160
        assert slam.stats.dropped_count == 0 and slam.stats.before_odometry == 124
        assert not slam.pending and slam.frontend.pending_bytes == 0
        slam.destroy_node()
    monkeypatch.setattr(ekf_slam_module, 'MAX_START_BYTES', 10.5 * corner_set_bytes())
    with RosHarness() as ros:
        slam, stamps = recording_node(ros)
        for t in sets[:12]:  # no odometry: the memory bound drops the oldest two
            slam.on_corners(corner_cloud(t, [good]))
        assert slam.stats.dropped['no_odometry'] == 2 and len(slam.pending) == 10
        assert [p[0] for p in slam.pending] == sets[2:12]
        slam.destroy_node()


def corner_set_bytes() -> int:
    """Return the memory of a one-corner feature set without a scan (Corners.nbytes)."""
    return 5 * 8 + 4 * 8 + 1024  # position, covariance, bisector, opening, beam time


def test_a_scan_before_its_corners_makes_one_step_not_two():
    """The live soak's first 35 stamps were processed twice at start-up.

    Discovery had not yet matched the corner extractor, so each scan went on alone
    (corners "absent"), then its corners came and made a second step at the same stamp.
    Now the corners are waited for during discovery, and a part whose set already went on
    without it is dropped as late.
    """
    t0, good = T0, GOOD_CORNER

    def scan(t):
        return make_scan(t, 'laser', -1.5, 0.01, [4.0] * 301, 0.1, 30.0)

    with RosHarness() as ros:
        slam, stamps = recording_node(ros)
        slam.on_odom(make_odometry(t0, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        slam.on_odom(make_odometry(t0 + 200_000_000, 'odom', 'base_link', [0.02, 0.0, 0.0]))
        slam.on_scan(scan(t0 + 50_000_000))  # no corner publisher yet: discovery
        assert stamps == []
        slam.on_corners(corner_cloud(t0 + 50_000_000, [good]))
        assert stamps == [t0 + 50_000_000] and slam.stats.dropped_count == 0
        slam._started -= 60.0  # long after start, still no corner publisher: not waited for
        slam.on_scan(scan(t0 + 100_000_000))
        assert stamps == [t0 + 50_000_000, t0 + 100_000_000]
        slam.on_corners(corner_cloud(t0 + 100_000_000, [good]))  # came after all: late
        assert stamps == [t0 + 50_000_000, t0 + 100_000_000]
        assert slam.stats.dropped['late'] == 1
        slam.destroy_node()


def test_a_looping_bag_replays_the_stamps_of_incomplete_sets_without_late_drops():
    """The soak in CI dropped 100 parts as late: the office bag, looping, replayed the stamps.

    The sets at the first 50 stamps had gone on without their corners (discovery); when the
    bag looped, its scans and corners at those stamps came again and were taken for late
    parts of the sets handed on (50 scans + 50 corner sets). A part more than
    ``max_backward_s`` older than the newest is from a restarted source: a new set.
    """
    t0, good = T0, GOOD_CORNER

    def scan(t):
        return make_scan(t, 'laser', -1.5, 0.01, [4.0] * 301, 0.1, 30.0)

    with RosHarness() as ros:
        slam, stamps = recording_node(ros)
        slam._started -= 60.0  # no corner publisher, long after start: sets go on without
        for k in range(3):
            slam.on_odom(make_odometry(t0 + k * 100_000_000, 'odom', 'base_link',
                                       [0.01 * k, 0.0, 0.0]))
        slam.on_scan(scan(t0 + 50_000_000))
        assert stamps == [t0 + 50_000_000]
        later = t0 + 5_000_000_000
        slam.on_odom(make_odometry(later, 'odom', 'base_link', [0.5, 0.0, 0.0]))
        slam.on_scan(scan(later - 50_000_000))
        assert stamps == [t0 + 50_000_000, later - 50_000_000]
        slam.on_corners(corner_cloud(later - 50_000_000, [good]))  # the same run: late
        assert slam.stats.dropped['late'] == 1
        # The source restarts (the bag loops): the same stamps again, a new step.
        for k in range(3):
            slam.on_odom(make_odometry(t0 + k * 100_000_000, 'odom', 'base_link',
                                       [0.01 * k, 0.0, 0.0]))
        assert slam.resets == 1
        slam.on_scan(scan(t0 + 50_000_000))  # was taken as late
        assert stamps[2:] == [t0 + 50_000_000]
        assert slam.stats.dropped_count == 1 and slam.stats.dropped['late'] == 1
        slam.destroy_node()


@pytest.mark.dds
def test_path_is_bounded_and_published_at_the_display_rate():
    """The path was republished whole at every step and never trimmed (cost grew per scan)."""
    t0 = 1_700_000_000_000_000_000
    good = [2.0, 1.0, 0.0, 3.0, 1.57, 1e-4, 0.0, 1e-4]
    steps, keep = 300, 50
    with RosHarness() as ros:
        slam = ros.add_node(EkfSlamNode(context=ros.context, parameter_overrides=[
            Parameter('path_max_poses', value=keep), Parameter('display_period', value=0.2)]))
        paths = ros.collect('path', PathMsg)
        poses = ros.collect('pose', PoseWithCovarianceStamped)
        pub_odom = ros._helper.create_publisher(Odometry, 'odom', 10)
        pub_c = ros._helper.create_publisher(PointCloud2, 'corners/features', 10)
        assert ros.wait_for_subscribers([pub_odom, pub_c])
        stamps = [t0 + k * 25_000_000 for k in range(steps)]
        wall = time.monotonic()
        for k, t in enumerate(stamps):
            pub_odom.publish(make_odometry(t, 'odom', 'base_link', [0.01 * k, 0.0, 0.0]))
            assert ros.wait_until(lambda: slam.odom_count == k + 1, 10)
            if k:
                pub_c.publish(corner_cloud(t, [good]))
                assert ros.wait_until(lambda: len(poses) == k, 10)
        assert ros.wait_until(
            lambda: paths and stamp_to_ns(paths[-1].header.stamp) == stamps[-1], 10)
        wall = time.monotonic() - wall
    last = paths[-1]
    assert [stamp_to_ns(p.header.stamp) for p in last.poses] == stamps[-keep:]
    assert max(len(p.poses) for p in paths) == keep
    # At the display rate (one per 0.2 s of the run, which a loaded machine stretches), not
    # once per step.
    assert len(paths) <= wall / 0.2 + 2 and len(paths) < steps // 2
    assert slam.stats.processed_count == steps - 1 and slam.stats.dropped_count == 0


def test_save_map_puts_a_relative_map_file_under_ros_home(tmp_path, monkeypatch):
    """A relative map_file used to land in whatever directory the node was started from."""
    (tmp_path / 'cwd').mkdir()
    monkeypatch.chdir(tmp_path / 'cwd')
    monkeypatch.setenv('ROS_HOME', str(tmp_path / 'ros_home'))
    with RosHarness() as ros:
        slam = EkfSlamNode(context=ros.context, parameter_overrides=[
            Parameter('map_file', value='maps/office.yaml')])
        res = slam.on_save_map(Trigger.Request(), Trigger.Response())
        slam.destroy_node()
    target = tmp_path / 'ros_home' / 'landmark_nav' / 'maps' / 'office.yaml'
    assert res.success and str(target) in res.message, res.message
    assert yaml.safe_load(target.read_text()) == {'frame_id': 'map', 'landmarks': []}
    assert not any((tmp_path / 'cwd').iterdir())


def test_negative_corner_covariance_is_warned_with_its_value():
    """A corner with a negative covariance used to go into the filter without a word."""
    t0 = 1_700_000_000_000_000_000
    good = [2.0, 1.0, 0.0, 3.0, 1.57, 1e-4, 0.0, 1e-4]
    bad = [4.0, 1.0, 0.0, 3.0, 1.57, -1e-4, 0.0, 1e-4]
    with RosHarness() as ros:
        slam = EkfSlamNode(context=ros.context)
        warnings = []
        slam.warner._logger = SimpleNamespace(warning=warnings.append)
        updates = []
        slam.on_odom(make_odometry(t0, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        slam.on_odom(make_odometry(t0 + 100_000_000, 'odom', 'base_link', [0.01, 0.0, 0.0]))
        real_update = slam.slam.update
        slam.slam.update = lambda z, r, d, **kw: (updates.append(len(z)),
                                                  real_update(z, r, d, **kw))
        slam.on_corners(corner_cloud(t0 + 50_000_000, [good, bad]))
        assert updates == [1]  # the good corner only
        assert len(warnings) == 1 and 'cov_xx=-0.0001' in warnings[0], warnings
        assert slam.stats.events['corners.covariance_not_psd'] == 1  # on /diagnostics
        slam.destroy_node()


def test_config_file_matches_declared_parameters():
    """config/ekf_slam.yaml lists every declared parameter with its default."""
    values = parameter_file(OFFICE.parents[1], 'ekf_slam')
    with RosHarness() as ros:
        node = EkfSlamNode(context=ros.context)
        declared = declared_parameters(node)
        noise = node.params.odometry
        node.destroy_node()
    assert set(values) == set(declared)
    for name, value in values.items():
        if isinstance(value, float):
            assert declared[name] == pytest.approx(value)
        else:
            assert declared[name] == value
    assert noise == ODOMETRY_NOISE_MODELS['pioneer']


def test_odometry_model_parameter_sets_the_noise_and_rejects_bad_gains():
    with RosHarness() as ros:
        node = EkfSlamNode(context=ros.context, parameter_overrides=[
            Parameter('odometry.model', value='k_d=0.02 k_theta=0.03 k_dtheta=0.04')])
        noise = node.params.odometry
        node.destroy_node()
        with pytest.raises(ParameterError, match='odometry.model'):
            EkfSlamNode(context=ros.context, parameter_overrides=[
                Parameter('odometry.model', value='k_d=fast')])
    assert (noise.sigma_xy_per_sqrt_m, noise.sigma_yaw_per_sqrt_m,
            noise.sigma_yaw_per_sqrt_rad) == (0.02, 0.03, 0.04)


def test_waiting_sets_are_processed_when_odometry_stops():
    """A set whose last beam the odometry never reaches is processed after odometry_timeout."""
    t0 = 1_700_000_000_000_000_000
    names = ('x', 'y', 'z', 'bisector', 'opening', 'cov_xx', 'cov_xy', 'cov_yy', 'time')
    row = [2.0, 1.0, 0.0, 3.0, 1.57, 1e-4, 0.0, 1e-4, 0.05]
    with RosHarness() as ros:
        slam = EkfSlamNode(context=ros.context)
        stamps = []
        slam._publish = lambda t, pose, cov: stamps.append((t, pose[0]))
        slam.on_odom(make_odometry(t0, 'odom', 'base_link', [0.0, 0.0, 0.0]))
        slam.on_odom(make_odometry(t0 + 100_000_000, 'odom', 'base_link', [0.1, 0.0, 0.0]))
        slam.on_corners(make_feature_cloud(t0 + 80_000_000, 'laser', names,
                                           dict(zip(names, np.array([row]).T)), True))
        slam.check_odometry_timeout()
        assert stamps == [] and len(slam.pending) == 1  # its last beam is at 130 ms
        slam.last_odom_wall -= slam.odometry_timeout + 0.1  # no odometry for that long
        slam.check_odometry_timeout()
        assert stamps == [(t0 + 80_000_000, pytest.approx(0.08, abs=1e-12))]
        assert slam.frontend.events['held'] == 1 and not slam.pending
        slam.destroy_node()


@pytest.fixture(scope='module')
def aces_bag(tmp_path_factory):
    """Return the first 100 scans of the aces log imported into a bag (once per module)."""
    from landmark_nav.importers.writer import import_log
    bag = tmp_path_factory.mktemp('carmen') / 'aces'
    import_log(shared_data('carmen', 'aces-corrected.log.gz'), bag, max_scans=100)
    return bag


@pytest.mark.dds
def test_node_equals_offline_on_an_imported_carmen_log(tmp_path, aces_bag):
    """A real log (aces, corridors, 1 m steps): corners and lines, landmarks pruned alike."""
    from landmark_nav.evaluation.slam import DRIFT_KEY
    bag = aces_bag
    model = load_bag(bag, require_reference=False).custom_data[DRIFT_KEY]
    node, ref = node_and_offline(tmp_path, bag, 1e6, 'both', model, chapter_profile())
    assert_node_equals_offline(node, ref)
    # The scans' geometry reached the node: visibility-aware pruning removed landmarks
    # (measured 2; none without the scans).
    assert ref.stats['pruned'] > 0 and ref.lines.shape[0] > 10


REAL_DATA_OPTIONS = {'jacobians': 'observability_gain', 'line_residual_factor': 2.0,
                     'free_space_check': 0.95, 'recovery_probability': 0.99,
                     'spurious_limit': 0.05}
REAL_DATA_FRONTEND = {'scan_matching': True, 'scan_matching_fit_pairs': 0.3,
                      'scan_matching_side_starts': 2.5}
REAL_DATA_KEYFRAME = {'min_travel_m': 0.1, 'min_turn_rad': 0.1}


def test_chapter_profile_names_the_options_measured_on_real_logs():
    """The profile sets landmarks corners and those options off, nothing else."""
    profile = chapter_profile()
    assert set(profile) == (set(REAL_DATA_OPTIONS) | set(REAL_DATA_FRONTEND) | {'landmarks'}
                            | {f'keyframe.{k}' for k in REAL_DATA_KEYFRAME})
    assert profile == CHAPTER
    default = parameter_file(OFFICE.parents[1], 'ekf_slam')
    assert all(default[k] != v for k, v in profile.items())


def test_defaults_are_the_real_data_options_and_the_chapter_profile_the_chapter_filter():
    """Declared defaults: the options measured on real logs; the profile: SlamParams()."""
    with RosHarness() as ros:
        node = EkfSlamNode(context=ros.context, parameter_overrides=[
            Parameter(k, value=v) for k, v in chapter_profile().items()])
        params, landmarks, frontend = node.params, node.landmarks, node.frontend_params
        node.destroy_node()
        node = EkfSlamNode(context=ros.context)
        default, default_frontend, default_landmarks = (node.params, node.frontend_params,
                                                        node.landmarks)
        node.destroy_node()
    assert landmarks == 'corners' and default_landmarks == 'both'
    assert frontend == FrontendParams() and not frontend.scan_matching
    assert default_frontend == FrontendParams(**REAL_DATA_FRONTEND,
                                              keyframe=KeyframeParams(**REAL_DATA_KEYFRAME))
    assert params == SlamParams(odometry=params.odometry)  # the chapter's filter
    assert (params.free_space_check, params.recovery_probability, params.spurious_limit,
            params.jacobians) == (None, None, None, 'standard')
    assert default == SlamParams(odometry=default.odometry, **REAL_DATA_OPTIONS)


def test_declared_defaults_equal_the_offline_defaults_and_the_config_file():
    """The node, config/ekf_slam.yaml and the offline tools (evaluate) start alike."""
    values = parameter_file(OFFICE.parents[1], 'ekf_slam')
    with RosHarness() as ros:
        node = EkfSlamNode(context=ros.context)
        declared = declared_parameters(node)
        built = (node.params, node.frontend_params, node.landmarks, node.visibility,
                 node.line_params, tuple(node.laser_pose), node.laser_sigma_range)
        node.destroy_node()
    offline = slam_configuration()
    assert declared == default_values() == values
    assert built == (offline.params, offline.frontend, offline.landmarks, offline.visibility,
                     offline.line_params, offline.laser_pose, offline.laser_sigma_range)


@pytest.mark.parametrize('name, value', [('jacobians', 'exact'), ('free_space_check', 1.5),
                                         ('spurious_limit', -0.1),
                                         ('recovery_probability', 0.5)])
def test_bad_real_data_option_is_a_parameter_error(name, value):
    with RosHarness() as ros:
        with pytest.raises(ParameterError, match=name):
            EkfSlamNode(context=ros.context, parameter_overrides=[Parameter(name, value=value)])


@pytest.mark.parametrize('overrides, match', [
    ({'scan_matching': True, 'visibility': False}, 'visibility'),
    ({'scan_matching_noise': 'k_d=fast'}, 'scan_matching_noise'),
    ({'scan_matching_accept': 1.0}, 'scan_matching_accept'),
    ({'scan_matching_max_range': 0.0}, 'scan_matching_max_range'),
    ({'scan_matching_fit_pairs': -1.0}, 'scan_matching_fit_pairs'),
    ({'scan_matching_side_starts': -1.0}, 'scan_matching_side_starts')])
def test_bad_scan_matching_setting_is_a_parameter_error(overrides, match):
    with RosHarness() as ros:
        with pytest.raises(ParameterError, match=match):
            EkfSlamNode(context=ros.context, parameter_overrides=[
                Parameter(k, value=v) for k, v in overrides.items()])


@pytest.mark.dds
def test_node_equals_offline_with_the_default_configuration(tmp_path, aces_bag):
    """The defaults' checks run in the node as offline (imported aces, 100 scans)."""
    from landmark_nav.evaluation.slam import DRIFT_KEY
    bag = aces_bag
    model = load_bag(bag, require_reference=False).custom_data[DRIFT_KEY]
    node, ref = node_and_offline(tmp_path, bag, 1e6, 'both', model)
    assert_node_equals_offline(node, ref)
    # The scan-matched motion was used (measured: 98 of the 100 steps; the first has no pair).
    assert ref.motions['scan_matching'] >= 95
    assert ref.stats['spurious'] > 0  # the check acted (measured 8 pairs dropped)
