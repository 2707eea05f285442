"""landmark_detector node: bag replay through DDS against ground truth, bad input, parameters."""

import math
from pathlib import Path

import cv2
from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from landmark_nav.bag import BagReader
from landmark_nav.conversions import (array_to_image, image_to_array, make_camera_info,
                                      stamp_to_ns)
from landmark_nav.nodes.common import ParameterError
from landmark_nav.nodes.landmark_detector import LandmarkDetector
from landmark_nav.sim.camera_record import (IMAGE_TOPIC, INFO_TOPIC, LANDMARKS_TOPIC,
                                            record_camera_scenario)
from landmark_nav.sim.camera_scenarios import ViewOptions
from landmark_nav.testing import declared_parameters, parameter_file, RosHarness
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from visualization_msgs.msg import Marker, MarkerArray
import yaml

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope='module')
def views_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp('bags') / 'views'
    record_camera_scenario('landmark_views', 11, out, n_frames=10,
                           options=ViewOptions(distance=(0.6, 2.5)))
    return out


@pytest.fixture(scope='module')
def shuttle_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp('bags') / 'shuttle'
    record_camera_scenario('landmark_shuttle', 3, out, trips=1)
    return out


def frames_of(bag):
    """Return [(image, camera_info, truth PoseArray)] in recording order."""
    out, cur = [], {}
    with BagReader(bag) as reader:
        for topic, _, msg in reader.decoded([IMAGE_TOPIC, INFO_TOPIC, LANDMARKS_TOPIC]):
            cur[topic] = msg
            if len(cur) == 3:
                out.append((cur[IMAGE_TOPIC], cur[INFO_TOPIC], cur[LANDMARKS_TOPIC]))
                cur = {}
    return out


def feed(ros, node, frames, outputs, compressed=False):
    """Publish each frame (camera_info, then the image) and wait for the node's output."""
    info_pub = ros._helper.create_publisher(CameraInfo, 'camera/camera_info', 10)
    if compressed:
        img_pub = ros._helper.create_publisher(CompressedImage, 'camera/image_raw/compressed',
                                               10)
    else:
        img_pub = ros._helper.create_publisher(Image, 'camera/image_raw', 10)
    assert ros.wait_for_subscribers([info_pub, img_pub])
    for k, (image, info, _) in enumerate(frames, 1):
        info_pub.publish(info)
        assert ros.wait_until(lambda: node.camera is not None, 5)
        if compressed:
            msg = CompressedImage(header=image.header, format='png')
            msg.data = cv2.imencode('.png', image_to_array(image))[1].tobytes()
            img_pub.publish(msg)
        else:
            img_pub.publish(image)
        assert ros.wait_until(lambda: len(outputs) >= k, 10), f'no output for frame {k}'


def _rot(q):
    return Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()


def test_config_file_matches_declared_parameters():
    values = parameter_file(REPO, 'landmark_detector')
    with RosHarness() as ros:
        node = LandmarkDetector(context=ros.context)
        declared = declared_parameters(node)
        node.destroy_node()
    assert set(values) == set(declared)
    for name, value in values.items():
        if isinstance(value, list):
            assert list(declared[name]) == pytest.approx(value)
        else:
            assert declared[name] == pytest.approx(value) if isinstance(value, float) \
                else declared[name] == value


@pytest.mark.dds
@pytest.mark.parametrize('compressed', [False, True])
def test_replays_landmark_views_against_ground_truth(views_bag, compressed):
    frames = frames_of(views_bag)
    meta = yaml.safe_load((views_bag / 'ground_truth.yaml').read_text())
    with RosHarness() as ros:
        node = ros.add_node(LandmarkDetector(
            context=ros.context, parameter_overrides=[
                Parameter('compressed', value=compressed),
                Parameter('publish_debug_image', value=True)]))
        poses = ros.collect('landmarks/poses', PoseArray)
        markers = ros.collect('landmarks/markers', MarkerArray)
        debug = ros.collect('landmarks/debug_image', Image)
        feed(ros, node, frames, poses, compressed)
        assert ros.wait_until(lambda: len(markers) == len(frames)
                              and len(debug) == len(frames), 5)
        assert node.warner.count == 0
    must = 0
    for (image, _, truth), out, mk, dbg, fm in zip(frames, poses, markers, debug,
                                                   meta['frames']):
        assert out.header == image.header and mk.markers[0].header.stamp == image.header.stamp
        assert mk.markers[0].action == Marker.DELETEALL
        assert (dbg.encoding, dbg.width, dbg.height) == ('bgr8', image.width, image.height)
        lm = fm['landmarks'][0]
        if lm['in_view'] and lm['block_px'] >= 5.0:
            must += 1
            assert len(out.poses) == 1, fm
        assert len(out.poses) <= 1
        for got, want in zip(out.poses, truth.poses):
            p = np.array([got.position.x, got.position.y, got.position.z])
            q = np.array([want.position.x, want.position.y, want.position.z])
            assert np.linalg.norm(p - q) < 0.01 * max(1.0, np.linalg.norm(q))
            d = Rotation.from_matrix(_rot(got.orientation).T @ _rot(want.orientation))
            assert math.degrees(d.magnitude()) < 1.0
            codes = sorted({m.id for m in mk.markers[1:]})
            assert codes == [lm['code']]
            texts = [m.text for m in mk.markers if m.type == Marker.TEXT_VIEW_FACING]
            assert texts == [str(lm['code'])]
    assert must >= 5


@pytest.mark.dds
def test_shuttle_fixes_match_the_true_robot_pose(shuttle_bag, tmp_path):
    meta = yaml.safe_load((shuttle_bag / 'ground_truth.yaml').read_text())
    (code, lm), = meta['landmarks'].items()
    map_file = tmp_path / 'landmarks.yaml'
    map_file.write_text(yaml.safe_dump({'frame_id': 'map', 'landmarks': {int(code): {
        'position': lm['position'], 'quaternion': lm['orientation_xyzw']}}}))
    mount = meta['camera_mount']['position']
    frames = frames_of(shuttle_bag)
    truth = {}
    with BagReader(shuttle_bag) as reader:
        for _, _, msg in reader.decoded(['/ground_truth/odom']):
            q = msg.pose.pose.orientation
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2))
            truth[stamp_to_ns(msg.header.stamp)] = (msg.pose.pose.position.x,
                                                    msg.pose.pose.position.y, yaw)
    with RosHarness() as ros:
        node = ros.add_node(LandmarkDetector(context=ros.context, parameter_overrides=[
            Parameter('landmark_map', value=str(map_file)),
            Parameter('camera_mount', value=[float(v) for v in mount] + [0.0, 0.0, 0.0])]))
        poses = ros.collect('landmarks/poses', PoseArray)
        fixes = ros.collect('landmark_pose', PoseWithCovarianceStamped)
        feed(ros, node, frames, poses)
        n_seen = sum(len(p.poses) for p in poses)
        assert ros.wait_until(lambda: len(fixes) == n_seen, 5)
    assert n_seen >= 6                               # stops and the approach
    near = 0
    for fix in fixes:
        assert fix.header.frame_id == 'map'
        x, y, yaw = truth[stamp_to_ns(fix.header.stamp)]
        p = fix.pose.pose.position
        q = fix.pose.pose.orientation
        got_yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2 + q.z ** 2))
        err = np.array([p.x - x, p.y - y, math.remainder(got_yaw - yaw, 2 * math.pi)])
        cov = np.array(fix.pose.covariance).reshape(6, 6)
        assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)
        c3 = cov[np.ix_([0, 1, 5], [0, 1, 5])]
        assert err @ np.linalg.solve(c3, err) < 16.27     # chi-square 3 dof, 99.9 %
        if math.hypot(lm['position'][0] - x, lm['position'][1] - y) < 1.2:
            near += 1
            assert math.hypot(err[0], err[1]) < 0.015
            assert abs(math.degrees(err[2])) < 1.0
    assert near >= 3


def _warnings(logs):
    return [m.msg for m in logs if m.level >= Log.WARN]


@pytest.mark.dds
def test_bad_input_warns_and_the_next_good_frame_is_processed(views_bag):
    image, info, _ = frames_of(views_bag)[0]
    gray = image_to_array(image)
    stamp = stamp_to_ns(image.header.stamp)
    with RosHarness() as ros:
        node = ros.add_node(LandmarkDetector(context=ros.context))
        poses = ros.collect('landmarks/poses', PoseArray)
        logs = ros.collect('/rosout', Log)
        info_pub = ros._helper.create_publisher(CameraInfo, 'camera/camera_info', 10)
        img_pub = ros._helper.create_publisher(Image, 'camera/image_raw', 10)
        assert ros.wait_for_subscribers([info_pub, img_pub])

        def expect(msg, needle, processed=False):
            before_logs, before_out, count = len(logs), len(poses), node.warner.count
            img_pub.publish(msg)
            assert ros.wait_until(lambda: node.warner.count > count, 5), needle
            assert ros.wait_until(lambda: any(needle in t for t in _warnings(logs[before_logs:])),
                                  5), (needle, _warnings(logs))
            if processed:
                assert ros.wait_until(lambda: len(poses) == before_out + 1, 5)
            else:
                assert len(poses) == before_out

        expect(image, 'no CameraInfo')                           # nothing received yet
        info_pub.publish(info)
        assert ros.wait_until(lambda: node.camera is not None, 5)
        yuv = Image(header=image.header, height=image.height, width=image.width,
                    encoding='yuv422', step=2 * image.width)
        yuv.data = bytes(2 * image.width * image.height)
        expect(yuv, 'encoding')
        short = Image(header=image.header, height=image.height, width=image.width,
                      encoding='mono8', step=image.width)
        short.data = bytes(100)                                  # corrupt: too few bytes
        expect(short, 'Dropping image')
        expect(array_to_image(gray[:240, :320].copy(), 'mono8', stamp, 'camera_optical'),
               'disagrees with CameraInfo')
        expect(array_to_image(np.zeros_like(gray), 'mono8', stamp, 'cam'), 'no contrast')
        saturated = np.clip(gray.astype(int) * 4, 0, 255).astype(np.uint8)
        expect(array_to_image(saturated, 'mono8', stamp, 'cam'), 'overexposed', processed=True)
        bad_info = make_camera_info(node.camera, stamp, 'cam')
        bad_info.k = [0.0] * 9
        count = node.warner.count
        info_pub.publish(bad_info)
        assert ros.wait_until(lambda: node.warner.count > count, 5)
        assert any('Ignoring camera_info' in t for t in _warnings(logs))
        assert node.stats.dropped['camera_info_malformed'] == 1
        assert {'dropped.camera_info_malformed': '1'}.items() <= {
            v.key: v.value for v in node.stats.status().values}.items()
        # the same problem again (all black) is throttled: counted, not logged, and dropped
        n_logs, count, n_out = len(logs), node.warner.count, len(poses)
        img_pub.publish(array_to_image(np.zeros_like(gray), 'mono8', stamp, 'cam'))
        assert ros.wait_until(lambda: node.warner.count == count + 1, 5)
        assert not any('no contrast' in t for t in _warnings(logs[n_logs:]))
        assert len(poses) == n_out
        # another value of it (all white after all black) is reported at once, and dropped
        img_pub.publish(array_to_image(np.full_like(gray, 255), 'mono8', stamp, 'cam'))
        assert ros.wait_until(lambda: any('grey levels 255..255' in t
                                          for t in _warnings(logs[n_logs:])), 5)
        assert len(poses) == n_out and node.stats.dropped['unusable'] == 3
        # a colour image of the same scene is processed like the mono one
        bgr = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
        n = len(poses)
        img_pub.publish(array_to_image(bgr, 'bgr8', stamp, 'camera_optical'))
        assert ros.wait_until(lambda: len(poses) == n + 1, 5)
        img_pub.publish(image)                                    # the next good frame
        assert ros.wait_until(lambda: len(poses) == n + 2, 5)
    assert poses[-1].header == image.header and len(poses[-1].poses) == len(poses[-2].poses)


@pytest.mark.dds
def test_garbage_compressed_image_warns():
    with RosHarness() as ros:
        node = ros.add_node(LandmarkDetector(context=ros.context, parameter_overrides=[
            Parameter('compressed', value=True)]))
        pub = ros._helper.create_publisher(CompressedImage, 'camera/image_raw/compressed', 10)
        assert ros.wait_for_subscribers([pub])
        msg = CompressedImage(format='jpeg')
        msg.data = b'\xff\xd8not a jpeg at all'
        pub.publish(msg)
        assert ros.wait_until(lambda: node.warner.count == 1, 5)


@pytest.mark.parametrize('name, value, needle', [
    ('landmark_kind', '4x4', 'landmark_kind'),
    ('frame_width', -0.1, 'frame_width'),
    ('camera_mount', [0.0, 0.0, 0.0], 'camera_mount'),
    ('landmark_map', '/nonexistent/map.yaml', 'landmark_map'),
    ('detector.k_lim', 0.0, 'k_lim'),
    ('detector.neighbour_mode', 'all', 'neighbour_mode'),
    ('pose.pixel_sigma', -1.0, 'pixel_sigma')])
def test_bad_parameters_are_rejected(name, value, needle):
    with RosHarness() as ros:
        with pytest.raises(ParameterError, match=needle):
            LandmarkDetector(context=ros.context,
                             parameter_overrides=[Parameter(name, value=value)])
