"""Tests for landmark_nav.sim.robot and .control: kinematics, odometry, covariance, motion."""

import math

from landmark_nav.sim.control import simulate_mission, straight_profile, TurnTo, Wait
from landmark_nav.sim.robot import (dead_reckon, integrate, make_odometry, make_trajectory,
                                    measure_wheels, RobotParams, step_pose, wheel_to_twist)
from landmark_nav.sim.world import wrap_angle
import numpy as np
import pytest

T0 = 1_700_000_000_000_000_000
EXACT = {'k1': 1.0, 'k2': 1.0, 'k3': 1.0, 'wheel_noise_gain': 0.0, 'wheel_noise_floor': 0.0}


def test_chapter_defaults():
    p = RobotParams()
    assert (p.k1, p.k2, p.k3) == (0.9977, 1.0023, 1.0095)
    assert (p.wheel_radius, p.axle_length, p.sample_time) == (0.0955, 0.330, 0.1)
    assert p.step_ns == 100_000_000
    assert RobotParams.from_dict(p.to_dict()) == p


def test_params_validation():
    with pytest.raises(ValueError):
        RobotParams(wheel_radius=-1.0)
    with pytest.raises(ValueError):
        RobotParams(wheel_noise_gain=-0.1)
    with pytest.raises(ValueError):
        RobotParams.from_dict({'k4': 1.0})
    with pytest.raises(ValueError):
        RobotParams(k1=float('nan'))


def test_step_model_matches_equations():
    pose = np.array([1.0, 2.0, 0.3])
    v, w, dt = 0.4, 0.5, 0.1
    out = step_pose(pose, v, w, dt)
    mid = 0.3 + 0.5 * w * dt
    assert out == pytest.approx([1.0 + v * dt * math.cos(mid), 2.0 + v * dt * math.sin(mid),
                                 0.3 + w * dt], abs=1e-15)
    vv, ww = wheel_to_twist(3.0, 4.0, 0.1, 0.1, 0.3)
    assert (vv, ww) == pytest.approx((0.35, 0.1 / 0.3))


def test_integrate_equals_stepwise():
    rng = np.random.default_rng(0)
    v = rng.uniform(-0.3, 0.3, 200)
    w = rng.uniform(-1.0, 1.0, 200)
    poses = integrate([0.5, -0.2, 1.0], v, w, 0.1)
    p = np.array([0.5, -0.2, 1.0])
    for k in range(200):
        p = step_pose(p, v[k], w[k], 0.1)
        assert poses[k + 1] == pytest.approx(p, abs=1e-12)


def test_straight_command_curvature_eqs_17_18():
    p = RobotParams(k1=0.99, k2=1.01, k3=1.02, **{k: v for k, v in EXACT.items()
                                                  if k.startswith('wheel')})
    n, om = 400, 3.0
    traj = make_trajectory(T0, [0.0, 0.0, 0.0], np.full((n, 2), om), p)
    r, b = p.wheel_radius, p.axle_length
    v = 0.5 * (p.k1 + p.k2) * om * r  # eq. 17
    w = (p.k2 - p.k1) * om * r / (p.k3 * b)  # eq. 18
    kappa = 2.0 * (p.k2 - p.k1) / (p.k3 * b * (p.k1 + p.k2))
    assert traj.twists[0] == pytest.approx([v, w], abs=1e-15)
    assert w / v == pytest.approx(kappa, rel=1e-12)
    chords = np.hypot(*np.diff(traj.poses[:, :2], axis=0).T)
    assert traj.poses[-1, 2] / chords.sum() == pytest.approx(kappa, rel=1e-9)
    # Eqs. 1-3 with constant D, dth put every pose on one circle (regular polygon).
    dth = w * p.sample_time
    rho = v * p.sample_time / (2.0 * math.sin(0.5 * dth))
    centre = _circle_centre(traj.poses[:3, :2])
    dist = np.hypot(*(traj.poses[:, :2] - centre).T)
    assert dist == pytest.approx(np.full(n + 1, rho), rel=1e-9)
    assert rho == pytest.approx(1.0 / kappa, rel=1e-4)
    assert centre[1] > 0.0  # k2 > k1: turns left (CCW)


def _circle_centre(p):
    (x1, y1), (x2, y2), (x3, y3) = p
    d = 2.0 * (x1 * (y2 - y3) + x2 * (y3 - y1) + x3 * (y1 - y2))
    ux = ((x1**2 + y1**2) * (y2 - y3) + (x2**2 + y2**2) * (y3 - y1)
          + (x3**2 + y3**2) * (y1 - y2)) / d
    uy = ((x1**2 + y1**2) * (x3 - x2) + (x2**2 + y2**2) * (x1 - x3)
          + (x3**2 + y3**2) * (x2 - x1)) / d
    return np.array([ux, uy])


def test_chapter_factors_turn_left_and_overestimate_rotation():
    p = RobotParams()
    straight = make_trajectory(T0, [0, 0, 0], np.full((50, 2), 3.0), p)
    assert straight.poses[-1, 2] > 0.0 and straight.poses[-1, 1] > 0.0
    spin = make_trajectory(T0, [0, 0, 0], np.tile([-2.0, 2.0], (50, 1)), p)
    nominal = dead_reckon([0, 0, 0], np.tile([-2.0, 2.0], (50, 1)), p)
    assert nominal[-1, 2] > spin.poses[-1, 2] > 0.0  # odometry overestimates the rotation


def test_truth_inside_step_is_continuous():
    p = RobotParams()
    wheels = np.array([[2.0, 3.0], [3.0, 2.0], [1.0, 1.0]])
    traj = make_trajectory(T0, [1.0, 1.0, 0.5], wheels, p)
    for k in range(3):
        assert traj.pose_at_seconds(0.1 * k + 1e-12) == pytest.approx(traj.poses[k], abs=1e-9)
        assert traj.pose_at_seconds(0.1 * (k + 1) - 1e-12) == \
            pytest.approx(traj.poses[k + 1], abs=1e-9)
    mid = traj.pose_at(T0 + 150_000_000)
    assert mid == pytest.approx(step_pose(traj.poses[1], *traj.twists[1], 0.05), abs=1e-15)
    assert traj.pose_at(T0 + 300_000_000) == pytest.approx(traj.poses[3], abs=1e-15)
    with pytest.raises(ValueError):
        traj.pose_at(T0 - 1)
    with pytest.raises(ValueError):
        traj.pose_at(T0 + 300_000_001)


def test_odometry_exact_without_errors():
    p = RobotParams(**EXACT)
    rng = np.random.default_rng(1)
    wheels = rng.uniform(-4.0, 4.0, (500, 2))
    traj = make_trajectory(T0, [1.0, 2.0, 3.0], wheels, p)
    odo = make_odometry(traj, p, np.random.default_rng(2))
    assert np.array_equal(odo.poses, traj.poses)
    assert np.array_equal(odo.wheel_speeds, wheels)


def test_dead_reckon_with_true_factors_reproduces_truth():
    p = RobotParams(wheel_noise_gain=0.0, wheel_noise_floor=0.0)
    wheels = np.random.default_rng(3).uniform(-4.0, 4.0, (300, 2))
    traj = make_trajectory(T0, [0.0, 0.0, 0.0], wheels, p)
    assert np.array_equal(dead_reckon([0, 0, 0], wheels, p, (p.k1, p.k2, p.k3)), traj.poses)
    assert not np.allclose(dead_reckon([0, 0, 0], wheels, p), traj.poses)


def test_wheel_noise_statistics_and_quantisation():
    p = RobotParams(wheel_noise_gain=0.02, wheel_noise_floor=0.005)
    true = np.tile([1.0, 3.0], (40000, 1))
    meas, pos = measure_wheels(true, p, np.random.default_rng(4))
    err = meas - true
    assert np.abs(err.mean(axis=0)) == pytest.approx([0.0, 0.0], abs=1e-3)
    assert err.std(axis=0) == pytest.approx([0.025, 0.065], rel=0.03)
    assert pos[1:] == pytest.approx(np.cumsum(meas * 0.1, axis=0))
    q = RobotParams(encoder_ticks_per_rev=500)
    meas_q, pos_q = measure_wheels(true[:100], q, np.random.default_rng(5))
    ticks = pos_q / (2.0 * math.pi / 500)
    assert ticks == pytest.approx(np.round(ticks), abs=1e-6)
    assert pos_q[1:] == pytest.approx(np.cumsum(meas_q * 0.1, axis=0), abs=1e-9)


def test_covariance_grows_and_is_psd():
    p = RobotParams()
    wheels = np.vstack([np.full((100, 2), 3.0), np.tile([-2.0, 2.0], (30, 1)),
                        np.full((100, 2), 3.0)])
    traj = make_trajectory(T0, [0, 0, 0], wheels, p)
    odo = make_odometry(traj, p, np.random.default_rng(0))
    cov = odo.covariances
    assert np.array_equal(cov[0], np.zeros((3, 3)))
    assert np.array_equal(cov, np.transpose(cov, (0, 2, 1)))
    assert np.all(np.linalg.eigvalsh(cov[1:]) > -1e-15)
    assert np.all(np.diff(cov[:, 2, 2]) >= 0.0)  # heading variance never shrinks (eq. 3)
    tr = np.trace(cov, axis1=1, axis2=2)
    assert tr[-1] > tr[130] > tr[100] > tr[50] > 0.0
    # Straight along x: along-track variance = sD^2 * distance (heading nearly 0).
    dist = np.sum(np.abs(odo.twists[:100, 0])) * 0.1
    assert cov[100, 0, 0] == pytest.approx(p.odom_sigma_distance ** 2 * dist, rel=1e-3)
    assert cov[100, 1, 1] > cov[50, 1, 1] > 0.0  # lateral grows via the heading variance


def test_straight_profile_exact_distance_and_limits():
    for dist in (5.0, 0.05, 0.4, 1.234):
        prof = straight_profile(dist, 0.3, 0.3, 0.1)
        assert prof.sum() * 0.1 == pytest.approx(dist, rel=1e-12)
        assert prof.max() <= 0.3 + 1e-12
        assert np.all(np.abs(np.diff(np.concatenate([[0.0], prof, [0.0]]))) <= 0.03 + 1e-12)


def test_turn_to_reaches_true_heading():
    p = RobotParams()
    mission = [TurnTo(math.pi, 1), Wait(0.5), TurnTo(-math.pi / 2.0, -1)]
    traj, spans = simulate_mission(p, [0.0, 0.0, 0.1], mission, T0)
    th1 = traj.poses[spans[0].end_step, 2]
    assert wrap_angle(th1 - math.pi) == pytest.approx(0.0, abs=2e-4)
    assert th1 > 3.0  # went counter-clockwise
    th3 = traj.poses[spans[2].end_step, 2]
    assert wrap_angle(th3 + math.pi / 2.0) == pytest.approx(0.0, abs=2e-4)
    assert th3 == pytest.approx(th1 - 1.5 * math.pi, abs=2e-4)  # clockwise by 270 deg
    w = traj.twists[:, 1]
    assert np.all(np.abs(w) <= p.max_angular_speed * p.k2 / p.k3 * 1.01)
    assert np.all(np.abs(np.diff(traj.wheel_speeds, axis=0)) <=
                  (p.max_angular_accel * p.sample_time * p.axle_length / 2.0
                   / p.wheel_radius) + 1e-9)
