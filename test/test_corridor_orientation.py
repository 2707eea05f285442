"""Tests of heading and tilt from the corridor vanishing point (chapter eq. 21)."""

import math

from landmark_nav.corridor.orientation import (corridor_orientation, eq21, eq21_from_direction,
                                               mount_rotation, vp_direction)
from landmark_nav.vision.camera import CameraModel
import numpy as np
import pytest

K = np.array([[520.0, 0.0, 322.3], [0.0, 515.0, 241.7], [0.0, 0.0, 1.0]])


def seen_direction(theta, mount):
    """Return the corridor direction in the optical frame for robot heading theta."""
    corridor_in_base = np.array([math.cos(theta), -math.sin(theta), 0.0])
    return mount_rotation(mount).T @ corridor_in_base


@pytest.mark.parametrize('theta_deg', [-40.0, -7.0, 0.0, 3.0, 25.0])
@pytest.mark.parametrize('alpha_deg', [-10.0, 0.0, 8.0, 30.0])
def test_heading_and_tilt_recovered_exactly(theta_deg, alpha_deg):
    theta, alpha = math.radians(theta_deg), math.radians(alpha_deg)
    mount = [0.2, 0.0, 0.5, 0.0, alpha, 0.0]          # camera pitched down by alpha
    d = seen_direction(theta, mount)
    o = corridor_orientation(d, mount)
    assert o.heading == pytest.approx(theta, abs=1e-12)
    assert o.tilt == pytest.approx(alpha, abs=1e-12)
    assert o.heading_eq21 == pytest.approx(theta, abs=1e-12)
    assert o.elevation == pytest.approx(0.0, abs=1e-12)
    # the sign of the direction does not matter
    assert corridor_orientation(-d, mount).heading == pytest.approx(theta, abs=1e-12)
    # eq. 21 on the pixel: the same numbers
    px = K @ d
    a, t = eq21(px[:2] / px[2], K[0, 0], K[1, 1], K[0, 2], K[1, 2])
    assert a == pytest.approx(alpha, abs=1e-12)
    assert t == pytest.approx(theta, abs=1e-12)


def test_signs_follow_the_chapter():
    # looking down (alpha > 0): the corridor VP is above the image centre
    d = seen_direction(0.0, [0, 0, 0, 0, math.radians(10), 0])
    assert (K @ d)[1] / (K @ d)[2] < K[1, 2]
    # robot turned left (theta > 0, counter-clockwise): the VP is right of the centre
    d = seen_direction(math.radians(10), [0, 0, 0, 0, 0, 0])
    assert (K @ d)[0] / (K @ d)[2] > K[0, 2]
    assert corridor_orientation(d).heading > 0


def test_mount_yaw_and_roll():
    yaw = math.radians(15.0)
    mount = [0, 0, 0, math.radians(3.0), math.radians(12.0), yaw]
    theta = math.radians(-6.0)
    o = corridor_orientation(seen_direction(theta, mount), mount)
    assert o.heading == pytest.approx(theta, abs=1e-12)
    assert o.elevation == pytest.approx(0.0, abs=1e-12)
    # eq. 21 gives the camera's own heading: off by about the mount yaw
    assert abs(o.heading_eq21 - (theta + yaw)) < math.radians(1.0)
    # a wrong mount pitch shows as elevation: the camera looks 2 deg further down than
    # assumed, so the level corridor seems to rise by 2 deg
    wrong = corridor_orientation(seen_direction(theta, mount),
                                 [0, 0, 0, math.radians(3.0), math.radians(10.0), yaw])
    assert wrong.elevation == pytest.approx(math.radians(2.0), abs=math.radians(0.1))


def test_vp_at_infinity_and_heading_range():
    o = corridor_orientation(np.array([1.0, 0.0, 0.0]))   # corridor across the view
    assert o.heading == pytest.approx(math.pi / 2)
    assert math.isfinite(o.tilt)
    a, t = eq21_from_direction([1.0, 0.0, 0.0])
    assert t == pytest.approx(math.pi / 2) and a == pytest.approx(0.0)
    o = corridor_orientation(seen_direction(math.radians(100.0), [0] * 6))
    assert o.heading == pytest.approx(math.radians(-80.0))  # the corridor is a line


def test_distorted_pixel_is_undistorted_first():
    cam = CameraModel(640, 480, K, np.array([-0.28, 0.09, 0.0012, -0.0008, -0.015]))
    mount = [0, 0, 0, 0, math.radians(5.0), 0]
    d = seen_direction(math.radians(20.0), mount)
    px = cam.project(d[None, :] * 50.0)[0]
    np.testing.assert_allclose(vp_direction(px, cam), d / np.linalg.norm(d), atol=1e-9)
    naive = vp_direction(px, K)                      # ignoring the distortion is wrong
    assert math.degrees(math.acos(naive @ d)) > 0.5
    # homogeneous ideal pixel at infinity
    np.testing.assert_allclose(vp_direction([520.0, 0.0, 0.0], K), [1.0, 0.0, 0.0])


def test_bad_input():
    with pytest.raises(ValueError, match='focal'):
        eq21((300.0, 200.0), 0.0, 500.0, 320.0, 240.0)
    with pytest.raises(ValueError, match='finite'):
        eq21((math.nan, 200.0), 500.0, 500.0, 320.0, 240.0)
    with pytest.raises(ValueError, match='fx, fy > 0'):
        vp_direction((300.0, 200.0), np.zeros((3, 3)))
    with pytest.raises(ValueError, match='finite'):
        vp_direction((math.inf, 200.0), K)
    with pytest.raises(ValueError, match='non-zero'):
        corridor_orientation([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match='6 finite'):
        corridor_orientation([0.0, 0.0, 1.0], [0.0, 0.0])
