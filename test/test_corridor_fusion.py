"""Tests of the corridor EKF (chapter §3.2, eq. 24): propagation, consistency, gating."""

import math

from landmark_nav.corridor.fusion import CorridorEKF, DeadReckoningNoise
from landmark_nav.geometry import wrap_angle
from landmark_nav.slam.consistency import chi2_gate
import numpy as np
import pytest

NOISE = DeadReckoningNoise(wheel_separation=0.4, k_left=4e-4, k_right=2e-4,
                           sigma_separation=0.002)


def move(s, d_l, d_r, b):
    """Return the exact kinematic step (the model the EKF linearises)."""
    ds, dth = 0.5 * (d_l + d_r), (d_r - d_l) / b
    a = s[..., 0] + 0.5 * dth
    return np.stack([s[..., 0] + dth, s[..., 1] + ds * np.cos(a),
                     s[..., 2] + ds * np.sin(a)], axis=-1)


def test_covariance_propagation_matches_monte_carlo():
    rng = np.random.default_rng(1)
    ekf = CorridorEKF([0.1, 0.0, 0.2], np.diag([1e-4, 1e-4, 1e-4]), NOISE)
    n = 20000
    s = rng.multivariate_normal(ekf.s, ekf.p, n)
    steps = [(0.05, 0.052)] * 40 + [(0.02, 0.06)] * 20 + [(-0.03, -0.028)] * 10
    for d_l, d_r in steps:
        ekf.predict_wheels(d_l, d_r)
        nl = d_l + rng.normal(0, math.sqrt(NOISE.k_left * abs(d_l)), n)
        nr = d_r + rng.normal(0, math.sqrt(NOISE.k_right * abs(d_r)), n)
        b = NOISE.wheel_separation + rng.normal(0, NOISE.sigma_separation, n)
        s = move(s, nl, nr, b)
    emp = np.cov(s.T)
    # the EKF mean is the noise-free path; the sample mean differs by the second-order
    # bias of cos/sin of the uncertain heading (and 0.7 % of a std of sampling error)
    assert np.all(np.abs(s.mean(0) - ekf.s) < 0.1 * np.sqrt(np.diag(ekf.p)))
    # sampling error of a variance from 20000 samples: 1 %; linearisation a little more
    np.testing.assert_allclose(np.diag(emp), np.diag(ekf.p), rtol=0.06)
    corr = emp[1, 2] / math.sqrt(emp[1, 1] * emp[2, 2])
    corr_ekf = ekf.p[1, 2] / math.sqrt(ekf.p[1, 1] * ekf.p[2, 2])
    assert abs(corr - corr_ekf) < 0.03


def test_predict_from_increments_matches_wheels():
    a = CorridorEKF([0.2, 1.0, -0.1], np.eye(3) * 1e-3, NOISE)
    b = CorridorEKF([0.2, 1.0, -0.1], np.eye(3) * 1e-3, NOISE)
    a.predict(0.1, 0.05)
    b.predict_wheels(0.1 - 0.5 * 0.05 * 0.4, 0.1 + 0.5 * 0.05 * 0.4)
    np.testing.assert_allclose(a.s, b.s)
    np.testing.assert_allclose(a.p, b.p)


def simulate(rng, ekf, steps, sigma_th, sigma_y, every, reverse=False):
    """Drive a noisy robot along the corridor, update every ``every`` steps; return NEES."""
    truth = ekf.s + rng.multivariate_normal(np.zeros(3), ekf.p)
    nees, rejected = [], 0
    for k in range(steps):
        # steer back towards the centre line (a stand-in controller on the estimate)
        th, _, y = ekf.s
        ahead = math.pi if reverse else 0.0
        turn = -0.5 * wrap_angle(th - ahead) - (-1.5 if reverse else 1.5) * y
        d_l, d_r = 0.04 - 0.1 * turn * 0.04, 0.04 + 0.1 * turn * 0.04
        ekf.predict_wheels(d_l, d_r)
        nl = d_l + rng.normal(0, math.sqrt(NOISE.k_left * abs(d_l)))
        nr = d_r + rng.normal(0, math.sqrt(NOISE.k_right * abs(d_r)))
        bb = NOISE.wheel_separation + rng.normal(0, NOISE.sigma_separation)
        truth = move(truth, nl, nr, bb)
        if k % every == every - 1:
            rev = abs(wrap_angle(truth[0])) > math.pi / 2
            th_v = wrap_angle(truth[0] - math.pi) if rev else truth[0]
            y_v = -truth[2] if rev else truth[2]
            res = ekf.update(th_v + rng.normal(0, sigma_th), y_v + rng.normal(0, sigma_y),
                             np.diag([sigma_th ** 2, sigma_y ** 2]))
            assert res.facing_back == reverse
            rejected += not res.accepted
        e = ekf.s - truth
        e[0] = wrap_angle(e[0])
        nees.append(float(e @ np.linalg.solve(ekf.p, e)))
        assert np.all(np.linalg.eigvalsh(ekf.p) > 0)
    return np.array(nees), truth, rejected


@pytest.mark.parametrize('reverse', [False, True])
def test_filter_is_consistent_and_bounded(reverse):
    rng = np.random.default_rng(2 + reverse)
    all_nees, finals, rejected = [], [], 0
    for _ in range(30):
        start = [math.pi if reverse else 0.0, 0.0, 0.05]
        ekf = CorridorEKF(start, np.diag([math.radians(2) ** 2, 0.01, 0.02 ** 2]), NOISE)
        nees, truth, rej = simulate(rng, ekf, 250, math.radians(1.5), 0.1, every=5,
                                    reverse=reverse)
        rejected += rej
        all_nees.append(nees)
        finals.append(abs(ekf.s[2] - truth[2]))
    assert rejected <= 6                         # 1500 updates, 99.9 % gate: measured 1
    nees = np.concatenate(all_nees)
    inside = np.mean(nees <= chi2_gate(3, 0.95))
    assert inside >= 0.92                        # measured 0.948 / 0.956 (reverse)
    assert 2.6 < np.mean(nees) < 3.3             # measured 2.98 / 2.82
    # single frames off by 10 cm (std), fused: measured 2.6 / 2.0 cm RMS at the end
    assert np.sqrt(np.mean(np.square(finals))) < 0.035


def test_outlier_is_gated_and_state_kept():
    ekf = CorridorEKF([0.0, 0.0, 0.0], np.diag([1e-4, 1e-2, 1e-4]), NOISE)
    before = ekf.s.copy()
    res = ekf.update(0.0, 0.5, np.diag([1e-4, 0.01 ** 2]))
    assert not res.accepted and res.nis > 1000
    np.testing.assert_array_equal(ekf.s, before)
    res = ekf.update(0.001, 0.005, np.diag([1e-4, 0.01 ** 2]))
    assert res.accepted and res.nis < 5


def mixture_posterior_by_sampling(ekf, z, r, p, r_w, n=150000, seed=5):
    """Return the posterior mean, std and their standard errors by importance sampling."""
    rng = np.random.default_rng(seed)
    x = rng.multivariate_normal(ekf.s, ekf.p, n)
    nu = np.column_stack([z[0] - x[:, 0], z[1] - x[:, 2]])

    def density(cov):
        q = np.einsum('ni,ij,nj->n', nu, np.linalg.inv(cov), nu)
        return np.exp(-0.5 * q) / math.sqrt(np.linalg.det(2 * math.pi * cov))
    w = p * density(r) + (1 - p) * density(r_w)
    w /= w.sum()
    mean = w @ x
    d2 = (x - mean) ** 2
    var = w @ d2
    se_mean = np.sqrt((w * w) @ d2)                 # delta method, self-normalised weights
    se_var = np.sqrt((w * w) @ (d2 - var) ** 2)
    return mean, np.sqrt(var), se_mean, se_var / (2 * np.sqrt(var))


@pytest.mark.parametrize('z_deg, p', [(0.2, 0.3), (4.0, 0.3), (2.0, 0.8), (1.0, 0.0)])
def test_two_mode_measurement_gives_the_bayes_posterior(z_deg, p):
    # a weak heading (p = 0.3) agreeing with the prediction, the same disagreeing by 4 deg,
    # a likely one 2 deg off, a certainly wrong one: the Gaussian-sum update collapsed to
    # its moments is the exact posterior's mean and covariance
    p0 = np.diag([math.radians(1.0) ** 2, 1e-2, 0.01 ** 2])
    r = np.diag([math.radians(0.3) ** 2, 0.02 ** 2])
    r_w = np.diag([math.radians(5.5) ** 2, 0.02 ** 2])
    ekf = CorridorEKF([0.0, 0.0, 0.0], p0, NOISE)
    z = (math.radians(z_deg), 0.01)
    mean, std, se_mean, se_std = mixture_posterior_by_sampling(ekf, z, r, p, r_w)
    assert ekf.update(z[0], z[1], r, p, r_w).accepted
    # within 4 Monte Carlo standard errors (1e-3 to 1e-2 of the prior std)
    assert np.all(np.abs(ekf.s - mean) <= 4 * se_mean)
    assert np.all(np.abs(np.sqrt(np.diag(ekf.p)) - std) <= 4 * se_std)


def test_weak_measurement_moves_the_estimate_only_where_it_agrees():
    p0 = np.diag([math.radians(1.0) ** 2, 1e-2, 0.01 ** 2])
    r = np.diag([math.radians(0.3) ** 2, 0.02 ** 2])
    r_w = np.diag([math.radians(5.5) ** 2, 0.02 ** 2])
    moved, accepted = {}, {}
    for p in (1.0, 0.3, 0.0):
        for z_deg in (0.5, 4.0):
            ekf = CorridorEKF([0.0, 0.0, 0.0], p0, NOISE)
            accepted[p, z_deg] = ekf.update(math.radians(z_deg), 0.0, r, p, r_w).accepted
            moved[p, z_deg] = math.degrees(ekf.s[0])
    # agreeing (0.5 deg, within the 1 deg prior): measured 0.31 deg for the weak frame,
    # 0.46 for a sure one, 0.016 for a certainly wrong one
    assert moved[0.3, 0.5] > 0.6 * moved[1.0, 0.5] and moved[0.3, 0.5] > 10 * moved[0.0, 0.5]
    # 4 deg off: a sure frame is gated out; the weak one moves the estimate about as much as
    # a certainly wrong one (measured 0.135 and 0.128 deg)
    assert not accepted[1.0, 4.0] and accepted[0.3, 4.0]
    assert moved[0.3, 4.0] < 1.1 * moved[0.0, 4.0]
    ekf = CorridorEKF([0.0, 0.0, 0.0], p0, NOISE)
    with pytest.raises(ValueError, match='wrong_covariance'):
        ekf.update(0.0, 0.0, r, 0.5)
    with pytest.raises(ValueError, match='p_correct'):
        ekf.update(0.0, 0.0, r, 1.5, r_w)


def test_bad_input():
    with pytest.raises(ValueError, match='finite'):
        CorridorEKF([math.nan, 0, 0], np.eye(3))
    with pytest.raises(ValueError, match='positive semi-definite'):
        CorridorEKF([0, 0, 0], -np.eye(3))
    ekf = CorridorEKF([0, 0, 0], np.eye(3))
    with pytest.raises(ValueError, match='finite'):
        ekf.predict_wheels(math.inf, 0.0)
    with pytest.raises(ValueError, match='finite'):
        ekf.update(0.0, math.nan, np.eye(2))
    with pytest.raises(ValueError, match='wheel_separation'):
        DeadReckoningNoise(wheel_separation=0.0)


# ------------------------------------------------------------------ controller
def test_controller_ramps_steers_and_stops():
    from landmark_nav.corridor.controller import ControllerParams, CorridorController
    p = ControllerParams(speed=0.4, lateral_offset=0.1, gain_lateral=2.0, gain_heading=0.5,
                         max_accel=0.2, max_angular_speed=0.3)
    c = CorridorController(p)
    v, w = c.step(0.0, 0.1, 0.5, True)               # on the set-point: straight
    assert v == pytest.approx(0.1) and w == pytest.approx(0.0)
    for _ in range(10):
        v, w = c.step(math.radians(5.0), 0.1, 0.5, True)
    assert v == pytest.approx(0.4)
    assert w == pytest.approx(-0.4 * 0.5 * math.radians(5.0))
    v, w = c.step(0.0, 0.3, 0.1, True)               # 20 cm left of the set-point
    assert w == pytest.approx(-0.4 * 2.0 * 0.2)
    assert c.step(0.0, 5.0, 0.1, True)[1] == pytest.approx(-0.3)   # clipped
    assert c.step(0.0, 0.0, 0.1, False) == (0.0, 0.0)
    assert c.step(0.0, 0.0, 0.1, True)[0] == pytest.approx(0.02)   # ramps again from 0
    with pytest.raises(ValueError, match='speed'):
        ControllerParams(speed=0.0)
