"""Tests for landmark_nav.geometry (SE(2) algebra, eqs. 13-17 and 27-30)."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from landmark_nav import geometry as g
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

coord = st.floats(-100.0, 100.0, allow_nan=False, allow_infinity=False)
angle = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
poses = st.tuples(coord, coord, angle).map(np.array)
SETTINGS = settings(max_examples=200, deadline=None)


def assert_pose_close(a, b, tol=1e-9):
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    assert a.shape == b.shape
    assert a[..., :2] == pytest.approx(b[..., :2], abs=tol)
    assert np.all(np.abs(g.wrap_angle(a[..., 2] - b[..., 2])) <= tol)


def assert_angle_in_range(th):
    th = np.asarray(th)
    assert np.all(th >= -math.pi) and np.all(th < math.pi)


# ------------------------------------------------------------------ wrap_angle


def test_wrap_angle_boundaries():
    assert g.wrap_angle(math.pi) == -math.pi
    assert g.wrap_angle(-math.pi) == -math.pi
    assert g.wrap_angle(0.0) == 0.0
    assert g.wrap_angle(3 * math.pi) == pytest.approx(-math.pi, abs=1e-12)
    assert g.wrap_angle(-3 * math.pi) == pytest.approx(-math.pi, abs=1e-12)
    assert g.wrap_angle(2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    just_below = np.nextafter(math.pi, 0.0)
    assert g.wrap_angle(just_below) == just_below
    # Just below -pi must wrap to just below +pi, never to +pi itself.
    below_minus_pi = np.nextafter(-math.pi, -10.0)
    w = g.wrap_angle(below_minus_pi)
    assert -math.pi <= w < math.pi
    assert abs(g.wrap_angle(w - below_minus_pi)) < 1e-12


def test_wrap_angle_in_range_values_unchanged():
    for a in (1e-300, -1e-300, 0.5, -3.0, 3.0, -math.pi):
        assert g.wrap_angle(a) == a
    assert isinstance(g.wrap_angle(1.0), float)


def test_wrap_angle_large_multiples():
    for k in (1, 7, 1000, -1000, 10 ** 6):
        assert g.wrap_angle(0.5 + 2 * math.pi * k) == pytest.approx(0.5, abs=1e-9)
        assert g.wrap_angle(-2.0 + 2 * math.pi * k) == pytest.approx(-2.0, abs=1e-9)


def test_wrap_angle_array():
    a = np.array([[0.0, math.pi, -math.pi], [4.0, -4.0, 7 * math.pi + 0.1]])
    w = g.wrap_angle(a)
    assert isinstance(w, np.ndarray) and w.shape == a.shape
    expected = [[0.0, -math.pi, -math.pi], [4.0 - 2 * math.pi, 2 * math.pi - 4.0, -math.pi + 0.1]]
    assert w == pytest.approx(np.array(expected), abs=1e-12)
    assert np.isnan(g.wrap_angle(np.nan))


@SETTINGS
@given(st.floats(-1e6, 1e6, allow_nan=False))
def test_wrap_angle_property(a):
    w = g.wrap_angle(a)
    assert_angle_in_range(w)
    k = (a - w) / (2 * math.pi)
    assert k == pytest.approx(round(k), abs=1e-6)


# ------------------------------------------------------------------ compose / inverse


def test_compose_known_value():
    out = g.compose([1.0, 2.0, math.pi / 2], [3.0, 0.5, 0.25])
    assert out == pytest.approx([1.0 - 0.5, 2.0 + 3.0, math.pi / 2 + 0.25], abs=1e-12)
    inv = g.inverse([1.0, 2.0, math.pi / 2])
    assert inv == pytest.approx([-2.0, 1.0, -math.pi / 2], abs=1e-12)


@SETTINGS
@given(poses)
def test_inverse_laws(x):
    zero = np.zeros(3)
    assert_pose_close(g.compose(x, g.inverse(x)), zero)
    assert_pose_close(g.compose(g.inverse(x), x), zero)
    assert_pose_close(g.inverse(g.inverse(x)), x)
    assert_angle_in_range(g.inverse(x)[2])


@SETTINGS
@given(poses, poses, poses)
def test_associativity(a, b, c):
    assert_pose_close(g.compose(g.compose(a, b), c), g.compose(a, g.compose(b, c)), 1e-8)


@SETTINGS
@given(poses, poses)
def test_relative_recovers_increment(x1, u):
    # eq. 13: u = (-)x(k-1) (+) x(k), with x(k) = x(k-1) (+) u (eq. 15)
    assert_pose_close(g.relative(x1, g.compose(x1, u)), u, 1e-8)
    assert_angle_in_range(g.compose(x1, u)[2])


def test_compose_broadcasts():
    rng = np.random.default_rng(0)
    a = rng.uniform(-5, 5, (4, 3))
    b = rng.uniform(-5, 5, 3)
    out = g.compose(a, b)
    assert out.shape == (4, 3)
    for i in range(4):
        assert_pose_close(out[i], g.compose(a[i], b), 1e-12)
    assert g.inverse(a).shape == (4, 3)
    with pytest.raises(ValueError):
        g.compose([1.0, 2.0], [0.0, 0.0, 0.0])


# ------------------------------------------------------------------ Jacobians


def numeric_jacobian(f, x, h=1e-6):
    x = np.asarray(x, dtype=float)
    jac = np.zeros((3, 3))
    for i in range(3):
        d = np.zeros(3)
        d[i] = h
        diff = f(x + d) - f(x - d)
        diff[2] = g.wrap_angle(diff[2])
        jac[:, i] = diff / (2 * h)
    return jac


@SETTINGS
@given(poses, poses)
def test_compose_jacobians_match_finite_differences(x1, x2):
    j1, j2 = g.compose_jacobians(x1, x2)
    assert j1 == pytest.approx(numeric_jacobian(lambda v: g.compose(v, x2), x1), abs=1e-6)
    assert j2 == pytest.approx(numeric_jacobian(lambda v: g.compose(x1, v), x2), abs=1e-6)


@SETTINGS
@given(poses)
def test_inverse_jacobian_matches_finite_differences(x):
    assert g.inverse_jacobian(x) == pytest.approx(numeric_jacobian(g.inverse, x), abs=1e-6)


def test_jacobian_row2_is_not_the_printed_typo():
    x1 = np.array([0.3, -1.0, 0.7])
    x2 = np.array([2.0, 1.5, -0.4])
    j1, _ = g.compose_jacobians(x1, x2)
    c, s = math.cos(x1[2]), math.sin(x1[2])
    printed = -x2[0] * c - x2[1] * s  # eq. 28 as printed in the chapter
    assert j1[1, 2] == pytest.approx(x2[0] * c - x2[1] * s, abs=1e-12)
    assert abs(j1[1, 2] - printed) > 1.0


def test_jacobians_broadcast():
    rng = np.random.default_rng(1)
    a = rng.uniform(-5, 5, (6, 3))
    b = rng.uniform(-5, 5, (6, 3))
    j1, j2 = g.compose_jacobians(a, b)
    assert j1.shape == (6, 3, 3) and j2.shape == (6, 3, 3)
    for i in range(6):
        k1, k2 = g.compose_jacobians(a[i], b[i])
        assert j1[i] == pytest.approx(k1, abs=1e-15)
        assert j2[i] == pytest.approx(k2, abs=1e-15)
    assert g.inverse_jacobian(a).shape == (6, 3, 3)


# ------------------------------------------------------------------ points


def test_transform_points_known_value():
    out = g.transform_points([1.0, 2.0, math.pi / 2], [[1.0, 0.0], [0.0, 1.0]])
    assert out == pytest.approx(np.array([[1.0, 3.0], [0.0, 2.0]]), abs=1e-12)


@SETTINGS
@given(poses, st.lists(st.tuples(coord, coord), min_size=1, max_size=20))
def test_transform_points_round_trip(pose, pts):
    pts = np.array(pts)
    out = g.transform_points(pose, pts)
    assert out.shape == pts.shape
    assert g.inverse_transform_points(pose, out) == pytest.approx(pts, abs=1e-9)
    # Consistent with composition: a point is a pose with any heading.
    as_pose = np.column_stack([pts, np.zeros(len(pts))])
    assert out == pytest.approx(g.compose(pose, as_pose)[:, :2], abs=1e-9)


def test_sensor_to_base_follows_mounting_convention():
    laser_pose = [0.2, -0.1, math.pi]  # laser 20 cm forward, 10 cm right, facing backwards
    p_laser = np.array([[1.0, 0.0], [0.0, 0.5]])
    p_base = g.sensor_to_base(p_laser, laser_pose)
    assert p_base == pytest.approx(np.array([[-0.8, -0.1], [0.2, -0.6]]), abs=1e-12)
    assert p_base == pytest.approx(g.transform_points(laser_pose, p_laser), abs=0)


def test_validate_pose_parameter():
    out = g.validate_pose_parameter([0.2, 0, -1.5], 'laser_pose')
    assert out.dtype == np.float64 and out.tolist() == [0.2, 0.0, -1.5]
    bad = ([0.1, 0.2], [1, 2, 3, 4], [0.0, float('nan'), 0.0], [0.0, 0.0, float('inf')],
           'abc', None, [0.0, 'x', 0.0], [True, 0.0, 0.0], 3.0)
    for values in bad:
        with pytest.raises(ValueError, match='laser_pose'):
            g.validate_pose_parameter(values, 'laser_pose')


# ------------------------------------------------------------------ quaternions


@SETTINGS
@given(st.floats(-50.0, 50.0, allow_nan=False))
def test_quaternion_round_trip(yaw):
    q = g.yaw_to_quaternion(yaw)
    assert q.shape == (4,)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
    assert abs(g.wrap_angle(g.quaternion_to_yaw(*q) - yaw)) < 1e-9
    # Non-normalised input gives the same yaw.
    assert abs(g.wrap_angle(g.quaternion_to_yaw(*(3.7 * q)) - yaw)) < 1e-9
    assert abs(g.wrap_angle(g.quaternion_to_yaw(*(-0.01 * q)) - yaw)) < 1e-9


def test_yaw_to_quaternion_values_and_arrays():
    x, y, z, w = g.yaw_to_quaternion(math.pi / 2)
    assert (x, y) == (0.0, 0.0)
    assert z == pytest.approx(math.sqrt(0.5), abs=1e-15)
    assert w == pytest.approx(math.sqrt(0.5), abs=1e-15)
    yaws = np.array([-3.0, 0.0, 1.0, 3.1])
    q = g.yaw_to_quaternion(yaws)
    assert q.shape == (4, 4)
    assert g.quaternion_to_yaw(*q.T) == pytest.approx(yaws, abs=1e-12)
    assert g.quaternion_to_yaw(0.0, 0.0, 1.0, 0.0) == -math.pi  # yaw pi, wrapped


@SETTINGS
@given(st.floats(-math.pi, math.pi), st.floats(-1.4, 1.4), st.floats(-math.pi, math.pi))
def test_quaternion_to_yaw_full_3d(roll, pitch, yaw):
    x, y, z, w = Rotation.from_euler('ZYX', [yaw, pitch, roll]).as_quat()
    assert abs(g.wrap_angle(g.quaternion_to_yaw(x, y, z, w) - yaw)) < 1e-9


def test_quaternion_to_yaw_rejects_zero_and_nan():
    with pytest.raises(ValueError):
        g.quaternion_to_yaw(0.0, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        g.quaternion_to_yaw(0.0, 0.0, float('nan'), 1.0)


# ------------------------------------------------------------------ interpolation


def test_interpolate_across_seam():
    times = [0.0, 1.0]
    poses = [[0.0, 0.0, 3.0], [2.0, -4.0, -3.0]]  # shortest arc passes through +-pi
    gap = 2 * math.pi - 6.0
    mid = g.interpolate_pose(0.5, times, poses)
    assert mid.shape == (3,)
    assert mid[:2] == pytest.approx([1.0, -2.0], abs=1e-12)
    assert abs(g.wrap_angle(mid[2] - math.pi)) < 1e-12
    q = g.interpolate_pose(0.25, times, poses)
    assert q == pytest.approx([0.5, -1.0, 3.0 + 0.25 * gap], abs=1e-12)
    q = g.interpolate_pose(0.75, times, poses)
    assert q == pytest.approx([1.5, -3.0, -3.0 - 0.25 * gap], abs=1e-12)
    assert_angle_in_range(g.interpolate_pose(np.linspace(0, 1, 101), times, poses)[:, 2])


def test_interpolate_endpoints_arrays_and_errors():
    times = np.array([1.0, 2.0, 4.0])
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [1.0, 2.0, -1.0]])
    out = g.interpolate_pose(np.array([1.0, 1.5, 2.0, 3.0, 4.0]), times, poses)
    expected = [[0, 0, 0], [0.5, 0, 0.5], [1, 0, 1], [1, 1, 0], [1, 2, -1]]
    assert out == pytest.approx(np.array(expected, dtype=float), abs=1e-12)
    for t in (0.999, 4.001):
        with pytest.raises(ValueError):
            g.interpolate_pose(t, times, poses)
    with pytest.raises(ValueError):
        g.interpolate_pose([1.5, 5.0], times, poses)
    assert g.interpolate_pose(5.0, times, poses, extrapolate=True) == pytest.approx(
        [1.0, 3.0, -2.0], abs=1e-12)
    assert g.interpolate_pose(0.0, times, poses, extrapolate=True) == pytest.approx(
        [-1.0, 0.0, -1.0], abs=1e-12)
    with pytest.raises(ValueError):
        g.interpolate_pose(1.5, [2.0, 1.0], poses[:2])
    with pytest.raises(ValueError):
        g.interpolate_pose(1.5, times, poses[:2])


def test_interpolate_duplicate_and_single_sample():
    times = [0.0, 1.0, 1.0, 2.0]
    poses = [[0, 0, 0], [1, 0, 0], [5, 0, 0], [6, 0, 0]]
    assert g.interpolate_pose(1.0, times, poses)[0] == pytest.approx(5.0, abs=1e-12)
    assert g.interpolate_pose(1.5, times, poses)[0] == pytest.approx(5.5, abs=1e-12)
    assert g.interpolate_pose(2.0, [0.0, 2.0, 2.0], [[0, 0, 0], [1, 0, 0], [2, 0, 0]])[0] == 2.0
    one = g.interpolate_pose(3.0, [3.0], [[1.0, 2.0, 4.0]])
    assert one == pytest.approx([1.0, 2.0, 4.0 - 2 * math.pi], abs=1e-12)
    with pytest.raises(ValueError):
        g.interpolate_pose(3.5, [3.0], [[1.0, 2.0, 0.0]])


def test_covariance_ellipse_lies_at_k_sigma():
    from landmark_nav.geometry import covariance_ellipse
    mean = np.array([1.0, -2.0])
    cov = np.array([[0.04, 0.01], [0.01, 0.02]])
    pts = covariance_ellipse(mean, cov, k=2.0, n=50)
    d = pts - mean
    m2 = np.einsum('ni,ij,nj->n', d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(m2, 4.0, rtol=1e-9)
    np.testing.assert_allclose(pts[0], pts[-1], atol=1e-12)
