"""Tests of the camera model and the CameraInfo conversions."""

import math

import cv2
from landmark_nav.conversions import camera_info_to_model, ConversionError, make_camera_info
from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo

K = np.array([[520.0, 0.0, 322.3], [0.0, 515.0, 241.7], [0.0, 0.0, 1.0]])
D5 = np.array([-0.28, 0.09, 0.0012, -0.0008, -0.015])
D8 = np.array([-0.28, 0.09, 0.0012, -0.0008, -0.015, 0.05, -0.02, 0.01])


def random_points(rng, n=200):
    """Points in front of the camera, inside a ~60 deg cone."""
    z = rng.uniform(0.3, 6.0, n)
    xy = rng.uniform(-0.55, 0.55, (n, 2)) * z[:, None]
    return np.column_stack([xy, z])


def test_pinhole_hand_computed():
    cam = CameraModel(640, 480, K, np.zeros(5))
    px = cam.project(np.array([[0.5, -0.25, 2.0], [0.0, 0.0, 1.0]]))
    np.testing.assert_allclose(px[0], [520.0 * 0.25 + 322.3, 515.0 * -0.125 + 241.7], atol=1e-12)
    np.testing.assert_allclose(px[1], [322.3, 241.7], atol=1e-12)
    skew = K.copy()
    skew[0, 1] = 2.0
    px = CameraModel(640, 480, skew, np.zeros(5)).project(np.array([[0.5, -0.25, 2.0]]))
    np.testing.assert_allclose(px[0], [520.0 * 0.25 + 2.0 * -0.125 + 322.3,
                                       515.0 * -0.125 + 241.7], atol=1e-12)


def test_distortion_hand_computed():
    k1, k2, p1, p2, k3 = D5
    x, y = 0.3, -0.2
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    cam = CameraModel(640, 480, K, D5)
    px = cam.project(np.array([[x * 3.0, y * 3.0, 3.0]]))[0]
    np.testing.assert_allclose(px, [520.0 * xd + 322.3, 515.0 * yd + 241.7], atol=1e-10)


@pytest.mark.parametrize('D,model', [(D5, 'plumb_bob'), (D8, 'rational_polynomial'),
                                     (np.zeros(0), 'plumb_bob')])
def test_project_matches_opencv(D, model):
    cam = CameraModel(640, 480, K, D, distortion_model=model)
    pts = random_points(np.random.default_rng(1))
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, D if D.size else None)
    np.testing.assert_allclose(cam.project(pts), ref.reshape(-1, 2), atol=1e-9)


def test_project_behind_camera_is_nan():
    cam = CameraModel(640, 480, K, D5)
    px = cam.project(np.array([[0.1, 0.1, -1.0], [0.1, 0.1, 0.0], [np.nan, 0, 1],
                               [0.1, 0.1, 1.0]]))
    assert np.all(np.isnan(px[:3])) and np.all(np.isfinite(px[3]))


@pytest.mark.parametrize('D,model', [(D5, 'plumb_bob'), (D8, 'rational_polynomial')])
def test_undistort_inverts_distort(D, model):
    cam = CameraModel(640, 480, K, D, distortion_model=model)
    pts = random_points(np.random.default_rng(2))
    px = cam.project(pts)
    norm = cam.undistort_pixels(px)
    np.testing.assert_allclose(norm, pts[:, :2] / pts[:, 2:], atol=1e-10)
    ideal = cam.undistort_pixels(px, 'ideal')
    np.testing.assert_allclose(ideal, cam.project(pts, distort=False), atol=1e-7)
    rays = cam.back_project(px)
    np.testing.assert_allclose(rays, pts / np.linalg.norm(pts, axis=1, keepdims=True),
                               atol=1e-10)
    # the other way round: every pixel of the image survives back-projection + projection
    u, v = np.meshgrid(np.linspace(0, 639, 33), np.linspace(0, 479, 25))
    grid = np.column_stack([u.ravel(), v.ravel()])
    np.testing.assert_allclose(cam.project(cam.back_project(grid)), grid, atol=1e-6)


def test_undistort_rectified_uses_r_and_p():
    R = cv2.Rodrigues(np.array([0.01, -0.02, 0.005]))[0]
    P = np.array([[500.0, 0.0, 300.0, 0.0], [0.0, 500.0, 250.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    cam = CameraModel(640, 480, K, D5, R=R, P=P)
    pts = random_points(np.random.default_rng(3), 50)
    px = cam.project(pts)
    rect = cam.undistort_pixels(px, 'rectified')
    q = pts @ R.T
    np.testing.assert_allclose(rect, q[:, :2] / q[:, 2:] * 500.0 + [300.0, 250.0], atol=1e-6)
    assert np.all(np.isnan(cam.undistort_pixels(np.array([[np.nan, 1.0]]))))
    with pytest.raises(ValueError):
        cam.undistort_pixels(px, 'bogus')


def test_from_fov_and_frames():
    cam = CameraModel.from_fov(640, 480, math.radians(60.0))
    assert cam.hfov == pytest.approx(math.radians(60.0))
    assert cam.fx == pytest.approx(320.0 / math.tan(math.radians(30.0)))
    assert (cam.cx, cam.cy) == (319.5, 239.5)
    # body x forward -> optical z, body y left -> optical -x, body z up -> optical -y
    np.testing.assert_array_equal(OPTICAL_FROM_BODY @ [1, 0, 0], [0, 0, 1])
    np.testing.assert_array_equal(OPTICAL_FROM_BODY @ [0, 1, 0], [-1, 0, 0])
    np.testing.assert_array_equal(OPTICAL_FROM_BODY @ [0, 0, 1], [0, -1, 0])
    assert np.linalg.det(OPTICAL_FROM_BODY) == pytest.approx(1.0)
    # a point ahead and to the left, above the axis, appears left of and above the centre
    px = cam.project((OPTICAL_FROM_BODY @ [2.0, 0.3, 0.2])[None])[0]
    assert px[0] < cam.cx and px[1] < cam.cy


@pytest.mark.parametrize('kwargs', [
    {'width': 0}, {'height': -3}, {'K': np.eye(2)}, {'K': np.diag([0.0, 1.0, 1.0])},
    {'K': np.diag([-1.0, 1.0, 1.0])}, {'D': np.zeros(3)}, {'D': [np.nan] * 5},
    {'distortion_model': 'equidistant'}, {'R': np.eye(4)}, {'P': np.eye(3)},
])
def test_camera_model_validation(kwargs):
    args = {'width': 640, 'height': 480, 'K': K, 'D': D5}
    args.update(kwargs)
    with pytest.raises(ValueError):
        CameraModel(**args)


def test_camera_info_round_trip():
    R = cv2.Rodrigues(np.array([0.01, -0.02, 0.005]))[0]
    cam = CameraModel(640, 480, K, D8, 'rational_polynomial', R=R)
    msg = make_camera_info(cam, 1_700_000_000_123_456_789, 'camera_optical')
    msg = deserialize_message(serialize_message(msg), CameraInfo)
    assert msg.header.frame_id == 'camera_optical' and msg.header.stamp.nanosec == 123456789
    back = camera_info_to_model(msg)
    assert back.to_dict() == cam.to_dict()


def _info(**changes):
    msg = make_camera_info(CameraModel(640, 480, K, D5))
    for k, v in changes.items():
        setattr(msg, k, v)
    return msg


def test_camera_info_defaults():
    msg = _info(r=[0.0] * 9, p=[0.0] * 12)
    cam = camera_info_to_model(msg)
    np.testing.assert_array_equal(cam.R, np.eye(3))
    np.testing.assert_array_equal(cam.P[:, :3], K)
    cam = camera_info_to_model(_info(distortion_model='', d=[]))
    assert not cam.has_distortion


@pytest.mark.parametrize('changes,match', [
    ({'width': 0}, 'width'),
    ({'d': [0.1, 0.2, 0.0]}, 'len'),
    ({'distortion_model': 'equidistant'}, 'distortion_model'),
    ({'distortion_model': '', 'd': [0.1] * 5}, 'distortion_model'),
    ({'k': [0.0] * 9}, 'focal'),
    ({'k': [-500.0, 0, 320, 0, 500, 240, 0, 0, 1]}, 'focal'),
    ({'k': [500.0, 0, 320, 0, 500, 240, 0, 0, 2]}, 'K'),
    ({'d': [float('nan')] * 5}, 'non-finite'),
    ({'binning_x': 2}, 'binning'),
])
def test_camera_info_errors(changes, match):
    with pytest.raises(ConversionError, match=match):
        camera_info_to_model(_info(**changes))


def test_camera_info_roi_rejected():
    msg = _info()
    msg.roi.x_offset = 10
    msg.roi.width = 100
    with pytest.raises(ConversionError, match='region of interest'):
        camera_info_to_model(msg)
    with pytest.raises(ConversionError):
        make_camera_info('not a model')
