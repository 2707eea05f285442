"""model_localizer node: a rendered hallway bag replayed through DDS, lost / recover, bad input."""

import math
from pathlib import Path
from types import SimpleNamespace

from geometry_msgs.msg import PoseWithCovarianceStamped
from landmark_nav.conversions import (array_to_image, make_camera_info,
                                      make_pose_with_covariance_stamped, quaternion_to_yaw)
from landmark_nav.evaluation.model_localization import HallwayRunConfig, write_hallway_bag
from landmark_nav.nodes.common import ParameterError
from landmark_nav.nodes.model_localizer import ModelLocalizerNode
from landmark_nav.testing import declared_parameters, parameter_file, RosHarness
from landmark_nav.vision.camera import CameraModel
import numpy as np
import pytest
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String

REPO = Path(__file__).resolve().parents[1]


def test_config_file_matches_declared_parameters():
    values = parameter_file(REPO, 'model_localizer')
    with RosHarness() as ros:
        node = ModelLocalizerNode(context=ros.context)
        assert declared_parameters(node) == values


def test_bad_parameters(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('format: landmark_nav_line_model/1\nvertices: [[0, 0]]\nedges: []\n'
                   'faces: []\n')
    with RosHarness() as ros:
        with pytest.raises(ParameterError, match=r'model_file: .*bad.yaml:2: vertices\[0\]'):
            ModelLocalizerNode(context=ros.context, parameter_overrides=[
                Parameter('model_file', value=str(bad))])
        with pytest.raises(ParameterError, match='initial_std must be > 0'):
            ModelLocalizerNode(context=ros.context, parameter_overrides=[
                Parameter('initial_std', value=[0.0, 0.1, 0.1])])


def _spy(node):
    """Return the warnings the node's throttled warner logs (after throttling)."""
    logged = []
    node.warner._logger = SimpleNamespace(warning=logged.append)
    return logged


def _pose(msg):
    q = msg.pose.pose.orientation
    return np.array([msg.pose.pose.position.x, msg.pose.pose.position.y,
                     quaternion_to_yaw(q.x, q.y, q.z, q.w)])


@pytest.mark.dds
@pytest.mark.slow
def test_bag_replay_tracks_the_hallway_run_and_reports_lost(tmp_path):
    bag = tmp_path / 'hallway'
    # 9 s: 46 images; the camera is covered for 3 s, from 4 s to 7 s
    n_img = write_hallway_bag(bag, 0, 9.0, HallwayRunConfig(cover=(4.0, 7.0)))
    with RosHarness() as ros:
        node = ros.add_node(ModelLocalizerNode(context=ros.context))
        poses = ros.collect('pose', PoseWithCovarianceStamped)
        status = ros.collect('model_localizer/status', String)
        seen = {'images': 0}

        def wait(topic, stamp):      # one at a time: sensor-data QoS drops a backlog
            if topic == '/camera/image_raw':
                seen['images'] += 1
                assert ros.wait_until(lambda: node.frames >= seen['images'], 30)
            elif topic == '/odom':
                assert ros.wait_until(lambda: node.last_odom is not None
                                      and node.last_odom[0] == stamp, 10)
        counts = ros.play(bag, on_message=wait)
        assert counts['/camera/image_raw'] == n_img
        assert ros.wait_until(lambda: len(poses) == n_img, 10)
    from landmark_nav.bag.reader import BagReader
    from landmark_nav.conversions import odometry_to_pose
    with BagReader(bag) as reader:
        gt = {stamp: odometry_to_pose(msg).pose
              for _, stamp, msg in reader.decoded(['/ground_truth/odom'])}
    errs, t = [], []
    for p in poses:
        stamp = p.header.stamp.sec * 1_000_000_000 + p.header.stamp.nanosec
        e = _pose(p) - gt[stamp]
        errs.append((math.hypot(e[0], e[1]), abs(math.degrees(e[2]))))
        t.append((stamp - min(gt)) * 1e-9)
        assert p.header.frame_id == 'map'
    errs, t = np.array(errs), np.array(t)
    seeing = (t < 4.0) | (t >= 7.0)
    # measured on this bag (start: the true pose with the chapter's covariance): <= 1.7 cm
    # throughout; heading while the camera sees <= 0.19 deg, covered (odometry) <= 1.17 deg
    assert errs[seeing, 0].max() < 0.025 and errs[seeing, 1].max() < 0.25
    assert errs[:, 0].max() < 0.025 and errs[:, 1].max() < 1.5
    assert [s.data for s in status] == ['tracking', 'lost', 'tracking']
    assert node.warner.count > 0


@pytest.mark.dds
@pytest.mark.slow
def test_bad_input_and_initial_pose():
    cam = CameraModel(320, 240, np.array([[379.0, 0, 165.9], [0, 379.0, 140.0], [0, 0, 1]]),
                      np.zeros(5))
    with RosHarness() as ros:
        node = ros.add_node(ModelLocalizerNode(context=ros.context))
        logged = _spy(node)
        poses = ros.collect('pose', PoseWithCovarianceStamped)
        pub_img = ros._helper.create_publisher(Image, 'camera/image_raw', 10)
        pub_info = ros._helper.create_publisher(CameraInfo, 'camera/camera_info', 10)
        pub_init = ros._helper.create_publisher(PoseWithCovarianceStamped, 'initialpose', 10)
        assert ros.wait_for_subscribers([pub_img, pub_info, pub_init])
        black = np.zeros((240, 320), np.uint8)
        # an image before any CameraInfo: dropped with a warning
        pub_img.publish(array_to_image(black, 'mono8', 1_000_000_000, 'camera'))
        assert ros.wait_until(lambda: node.stats.dropped['no_camera_info'] == 1, 10)
        # CameraInfo without a focal length: ignored with a warning, node alive
        bad = make_camera_info(cam)
        bad.k = [0.0] * 9
        n_warn = node.warner.count
        pub_info.publish(bad)
        assert ros.wait_until(lambda: node.warner.count > n_warn, 10)
        assert node.camera is None
        assert logged[-1].startswith('Ignoring camera_info: ') and 'focal' in logged[-1]
        assert node.stats.dropped['camera_info_malformed'] == 1
        pub_info.publish(make_camera_info(cam, 0, 'camera'))
        assert ros.wait_until(lambda: node.camera is not None, 10)
        # frames without lines: a pose (prediction only) each, one warning (throttled)
        n_warn = node.warner.count
        pub_img.publish(array_to_image(black, 'mono8', 2_000_000_000, 'camera'))
        assert ros.wait_until(lambda: len(poses) == 1, 10)
        pub_img.publish(array_to_image(black, 'mono8', 2_100_000_000, 'camera'))
        assert ros.wait_until(lambda: len(poses) == 2, 10)
        assert node.warner.count == n_warn + 2
        assert logged.count('No update: no lines in the image') == 1
        # wrong image size: dropped
        pub_img.publish(array_to_image(np.zeros((10, 10), np.uint8), 'mono8', 3, 'camera'))
        assert ros.wait_until(lambda: node.stats.dropped['size'] == 1, 10)
        # initialpose resets; outside the model: a warning per frame, no crash
        pub_init.publish(make_pose_with_covariance_stamped(0, 'map', [40.0, 0.0, 0.0],
                                                           np.diag([0.01, 0.01, 0.01])))
        assert ros.wait_until(lambda: node.loc.pose[0] == 40.0, 10)
        pub_img.publish(array_to_image(black, 'mono8', 4_000_000_000, 'camera'))
        assert ros.wait_until(lambda: len(poses) == 3, 10)
        assert _pose(poses[-1])[0] == pytest.approx(40.0)
        assert logged[-1] == 'No update: camera pose (40.00, 0.00) is outside the model'


@pytest.mark.dds
@pytest.mark.slow
def test_empty_model_warns_and_keeps_publishing(tmp_path):
    empty = tmp_path / 'empty.yaml'
    empty.write_text('format: landmark_nav_line_model/1\nvertices: []\nedges: []\n'
                     'faces: []\n')
    cam = CameraModel(320, 240, np.array([[379.0, 0, 165.9], [0, 379.0, 140.0], [0, 0, 1]]),
                      np.zeros(5))
    with RosHarness() as ros:
        node = ros.add_node(ModelLocalizerNode(context=ros.context, parameter_overrides=[
            Parameter('model_file', value=str(empty))]))
        assert node.warner.count == 1                  # at start: the model has no edges
        logged = _spy(node)
        poses = ros.collect('pose', PoseWithCovarianceStamped)
        pub_img = ros._helper.create_publisher(Image, 'camera/image_raw', 10)
        pub_info = ros._helper.create_publisher(CameraInfo, 'camera/camera_info', 10)
        assert ros.wait_for_subscribers([pub_img, pub_info])
        pub_info.publish(make_camera_info(cam, 0, 'camera'))
        assert ros.wait_until(lambda: node.camera is not None, 10)
        img = np.full((240, 320), 90, np.uint8)
        img[:, 150:] = 160                                 # a strong vertical line
        for k in range(3):
            pub_img.publish(array_to_image(img, 'mono8', (k + 1) * 200_000_000, 'camera'))
            assert ros.wait_until(lambda: len(poses) == k + 1, 10)
        assert logged == ['No update: the line model has no edges']     # throttled
        assert node.warner.count == 1 + 3
