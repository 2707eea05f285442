"""Tests for landmark_nav.localization.odometry: control input, f, Jacobians, Q (eq. 26)."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from landmark_nav.localization.odometry import (control_from_poses, control_from_wheels,
                                                dead_reckoning, motion_jacobians,
                                                motion_model, process_noise, ProcessNoise)
from landmark_nav.sim import run_scenario
from landmark_nav.sim.robot import dead_reckon
import numpy as np
import pytest

finite = st.floats(-3.0, 3.0, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)


def test_control_from_wheels_eqs_4_7_17_18():
    w = np.array([[10.0, 12.0], [-3.0, 3.0]])
    r, b, t = 0.1, 0.3, 0.1
    u = control_from_wheels(w, r, b, t)
    assert u[0] == pytest.approx([0.5 * (1.0 + 1.2) * t, (1.2 - 1.0) / b * t])
    assert u[1] == pytest.approx([0.0, 0.6 / b * t])
    k = (0.99, 1.01, 1.02)
    uk = control_from_wheels(w[0], r, b, t, k)
    vl, vr = 0.99 * 10.0 * r, 1.01 * 12.0 * r
    assert uk == pytest.approx([0.5 * (vl + vr) * t, (vr - vl) / (1.02 * b) * t])


def test_calibrated_odometry_reproduces_simulator_dead_reckoning():
    res = run_scenario('hallway', 2)
    rp = res.robot
    wheels = res.odometry.wheel_speeds
    k = (rp.k1, rp.k2, rp.k3)
    u = control_from_wheels(wheels, rp.wheel_radius, rp.axle_length, rp.sample_time, k)
    ours = dead_reckoning(res.trajectory.poses[0], u)
    ref = dead_reckon(res.trajectory.poses[0], wheels, rp, k)
    assert ours[:, :2] == pytest.approx(ref[:, :2], abs=1e-9)
    assert np.abs(np.angle(np.exp(1j * (ours[:, 2] - ref[:, 2])))).max() < 1e-9
    # Nominal k reproduces the recorded odometry poses.
    u0 = control_from_wheels(wheels, rp.wheel_radius, rp.axle_length, rp.sample_time)
    assert dead_reckoning(res.trajectory.poses[0], u0)[:, :2] == pytest.approx(
        res.odometry.poses[:, :2], abs=1e-9)


@given(x=finite, y=finite, th=angle, d=st.floats(-0.5, 0.5), dth=st.floats(-0.5, 0.5))
@settings(max_examples=100, deadline=None)
def test_control_from_poses_inverts_f(x, y, th, d, dth):
    a = np.array([x, y, th])
    for midpoint in (True, False):
        b = motion_model(a, [d, dth], midpoint=midpoint)
        u = control_from_poses(a, b, midpoint=midpoint)
        assert u == pytest.approx([d, dth], abs=1e-9)


def test_motion_model_eq25_noise_and_vectorised():
    x = np.array([1.0, 2.0, 0.5])
    u = np.array([0.3, 0.2])
    v = np.array([0.01, -0.02])
    out = motion_model(x, u, v)
    head = 0.5 + 0.5 * (0.2 - 0.02)
    assert out == pytest.approx([1.0 + 0.31 * math.cos(head), 2.0 + 0.31 * math.sin(head),
                                 0.68])
    printed = motion_model(x, u, v, midpoint=False)  # eq. 25 as printed
    assert printed[:2] == pytest.approx([1.0 + 0.31 * math.cos(0.68),
                                         2.0 + 0.31 * math.sin(0.68)])
    xs = np.tile(x, (11, 1))
    vs = np.random.default_rng(0).normal(0.0, 0.01, (11, 2))
    batch = motion_model(xs, u, vs)
    assert batch.shape == (11, 3)
    assert batch[3] == pytest.approx(motion_model(x, u, vs[3]))
    assert motion_model([0.0, 0.0, 3.1], [0.0, 0.2])[2] == pytest.approx(3.3 - 2 * math.pi)


@given(x=finite, y=finite, th=angle, d=st.floats(-0.5, 0.5), dth=st.floats(-1.0, 1.0),
       midpoint=st.booleans())
@settings(max_examples=100, deadline=None)
def test_motion_jacobians_vs_finite_differences(x, y, th, d, dth, midpoint):
    x0 = np.array([x, y, th])
    u = np.array([d, dth])
    f_x, f_u = motion_jacobians(x0, u, midpoint=midpoint)
    eps = 1e-6
    num_x = np.zeros((3, 3))
    num_u = np.zeros((3, 2))
    for i in range(3):
        e = np.zeros(3)
        e[i] = eps
        diff = (motion_model(x0 + e, u, midpoint=midpoint)
                - motion_model(x0 - e, u, midpoint=midpoint))
        diff[2] = math.remainder(diff[2], 2 * math.pi)
        num_x[:, i] = diff / (2 * eps)
    for i in range(2):
        e = np.zeros(2)
        e[i] = eps
        # The noise v enters like u: the same Jacobian (eq. 30's grad f_u).
        diff = motion_model(x0, u, e, midpoint) - motion_model(x0, u, -e, midpoint)
        diff[2] = math.remainder(diff[2], 2 * math.pi)
        num_u[:, i] = diff / (2 * eps)
    assert f_x == pytest.approx(num_x, abs=1e-6)
    assert f_u == pytest.approx(num_u, abs=1e-6)


def test_process_noise_eq26():
    chapter = ProcessNoise(sigma_d=0.01, sigma_dtheta=0.1, k_d=0.0, k_theta=0.0)
    q = process_noise([0.03, 0.2], chapter)
    assert q == pytest.approx(np.diag([0.01 ** 2, 0.2 ** 2 * 0.1 ** 2]))
    assert process_noise([0.03, 0.0], chapter)[1, 1] == 0.0  # eq. 26: no turn, no noise
    ext = ProcessNoise(sigma_d=0.01, sigma_dtheta=0.1, k_d=0.02, k_theta=0.05)
    q2 = process_noise([0.03, 0.0], ext)
    assert q2 == pytest.approx(np.diag([0.01 ** 2 + (0.02 * 0.03) ** 2, (0.05 * 0.03) ** 2]))
