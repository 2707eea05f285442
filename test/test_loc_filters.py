"""Unit tests of the EKF (eqs. 24-36) and UKF (eqs. 37-54) steps."""

import dataclasses
import math

from landmark_nav.evaluation.localization import CHAPTER_P0, LocalizationInput
from landmark_nav.localization import ekf, ukf
from landmark_nav.localization.grid import GridMap, rasterize_world
from landmark_nav.localization.params import LocalizationParams
from landmark_nav.localization.sonar_model import predict_ranges, sonar_global_poses
from landmark_nav.sim import run_scenario
from landmark_nav.sim.sonar import SONAR_MOUNTS
import numpy as np
import pytest


@pytest.fixture(scope='module')
def hallway():
    res = run_scenario('hallway', 5)
    return LocalizationInput.from_result(res), rasterize_world(res.world, 0.1)


def assert_sym_psd(p):
    assert np.array_equal(p, p.T)
    assert np.linalg.eigvalsh(p).min() >= -1e-15


@pytest.mark.parametrize('alpha', [1e-3, 0.5, 1.0])
def test_ukf_weights(alpha):
    w_m, w_c, gamma = ukf.weights(5, alpha, 2.0, 1.0)
    lam = alpha ** 2 * 6.0 - 5.0
    assert w_m.shape == (11,) and w_m.sum() == pytest.approx(1.0)
    assert w_c.sum() == pytest.approx(1.0 + 1.0 - alpha ** 2 + 2.0)
    assert gamma == pytest.approx(math.sqrt(5.0 + lam))
    assert w_m[0] == pytest.approx(lam / (5.0 + lam))


@pytest.mark.parametrize('alpha', [1e-2, 0.5, 1.0])
def test_unscented_transform_linear_exact(alpha):
    rng = np.random.default_rng(3)
    a = rng.normal(size=(5, 5))
    p = a @ a.T + 0.1 * np.eye(5)
    m = rng.normal(size=5)
    w_m, w_c, gamma = ukf.weights(5, alpha, 2.0, 1.0)
    chi = ukf.sigma_points(m, p, gamma)
    assert chi.shape == (11, 5)
    a_lin = rng.normal(size=(4, 5))
    b = rng.normal(size=4)
    y = chi @ a_lin.T + b
    mean, cov = ukf.unscented_transform(y, w_m, w_c - np.eye(11)[0] * (1 - alpha ** 2 + 2.0))
    assert mean == pytest.approx(a_lin @ m + b, abs=1e-9)
    assert cov == pytest.approx(a_lin @ p @ a_lin.T, abs=1e-8)
    # With beta != 0 the covariance weights add (1 - alpha^2 + beta) (y0 - mean)^2, which
    # vanishes for a linear map because the central point maps onto the mean.
    _, cov_b = ukf.unscented_transform(y, w_m, w_c)
    assert cov_b == pytest.approx(a_lin @ p @ a_lin.T, abs=1e-8)


def test_ukf_circular_mean_and_wrapped_residuals():
    pts = np.array([[0.0, 0.0, math.pi - 0.01], [0.0, 0.0, -math.pi + 0.01]])
    mean = ukf.unscented_mean(pts, np.array([0.5, 0.5]))
    assert abs(abs(mean[2]) - math.pi) < 1e-12
    res = ukf.residuals(pts, mean)
    assert np.abs(res[:, 2]) == pytest.approx([0.01, 0.01])


def test_ukf_time_update_matches_ekf_for_small_noise():
    x = np.array([1.0, 2.0, 0.3])
    p = np.diag([1e-6, 2e-6, 1e-6])
    u = np.array([0.03, 0.01])
    params = LocalizationParams()
    xe, pe = ekf.time_update(x, p, u, params)
    xu, pu, sig = ukf.time_update(x, p, u, params)
    assert sig.shape == (11, 3)
    assert xu == pytest.approx(xe, abs=1e-7)  # second-order terms D sigma^2
    assert pu == pytest.approx(pe, rel=1e-3, abs=1e-12)


def run_steps(inp, grid, filt, n, params):
    x = inp.truth[0] + np.array([0.05, -0.04, 0.05])
    p = CHAPTER_P0.copy()
    u = inp.controls(inp.true_k)
    out = []
    for k in range(n):
        sig = None
        if k:
            if filt == 'ekf':
                x, p = ekf.time_update(x, p, u[k - 1], params)
            else:
                x, p, sig = ukf.time_update(x, p, u[k - 1], params)
            assert_sym_psd(p)
        if filt == 'ekf':
            x, p, _ = ekf.measurement_update(x, p, inp.sonar_ranges[k], grid, inp.mounts,
                                             params)
        else:
            x, p, _ = ukf.measurement_update(x, p, sig, inp.sonar_ranges[k], grid, inp.mounts,
                                             params)
        assert_sym_psd(p)
        out.append(x)
    return np.array(out)


@pytest.mark.parametrize('filt', ['ekf', 'ukf'])
def test_covariance_symmetric_psd_every_step(hallway, filt):
    inp, grid = hallway
    est = run_steps(inp, grid, filt, 120, LocalizationParams())
    assert np.hypot(*(est[-1, :2] - inp.truth[119, :2])) < 0.05


@pytest.mark.parametrize('filt', ['ekf', 'ukf'])
def test_rejects_invalid_and_outlier_readings(hallway, filt):
    inp, grid = hallway
    params = LocalizationParams()
    x = inp.truth[50] + np.array([0.02, -0.01, 0.01])
    p = np.diag([0.02 ** 2, 0.02 ** 2, 0.02 ** 2])
    z = inp.sonar_ranges[50].copy()
    good = np.flatnonzero(np.isfinite(z) & (z < 2.0))
    assert good.size >= 6
    bad = z.copy()
    bad[good[0]] = np.inf  # no echo
    bad[good[1]] = np.nan  # missing
    bad[good[2]] = -np.inf  # too close (REP 117)
    bad[good[3]] += 1.0  # outlier: innovation far above the acceptance threshold
    bad[good[4]] = 0.05  # below min_range
    ref = z.copy()
    ref[good[:5]] = np.inf

    def update(zz):
        if filt == 'ekf':
            return ekf.measurement_update(x, p, zz, grid, inp.mounts, params)
        return ukf.measurement_update(x, p, None, zz, grid, inp.mounts, params)

    xb, pb, info = update(bad)
    xr, pr, info_r = update(ref)
    assert not info['accepted'][good[:5]].any()
    assert info['accepted'][good[5:]].any()
    assert np.array_equal(info['accepted'], info_r['accepted'])
    assert xb == pytest.approx(xr, abs=1e-12) and pb == pytest.approx(pr, abs=1e-15)
    # All readings rejected: eqs. 31-32, the prior is returned unchanged.
    xn, pn, info_n = update(np.full(16, np.inf))
    assert not info_n['accepted'].any()
    assert np.array_equal(xn, x) and np.array_equal(pn, p)


def wall_grid():
    occ = np.zeros((60, 60), dtype=int)
    occ[:, 40] = 100  # wall x = 4.05 (centre line)
    occ[50, :] = 100  # wall y = 5.05
    return GridMap(occupancy=occ, resolution=0.1)


def test_ekf_raycast_jacobian_vs_finite_differences():
    g = wall_grid()
    mounts = np.array([[0.1, 0.0, 0.0], [0.0, 0.1, math.pi / 2], [0.1, 0.1, 0.6]])
    x = np.array([2.0, 3.0, 0.05])
    params = LocalizationParams(cone_rays=1, specular_angle=None)
    z_hat, h, usable = ekf.measurement_prediction(g, x, mounts, params)
    assert usable.all()
    # Smooth walls: compare with fine central differences of the ray-cast range.
    eps = np.array([1e-4, 1e-4, 1e-5])
    num = np.zeros((3, 3))
    for i in range(3):
        e = np.zeros(3)
        e[i] = eps[i]
        num[:, i] = (predict_ranges(g, x + e, mounts, cone_rays=1)[0]
                     - predict_ranges(g, x - e, mounts, cone_rays=1)[0]) / (2 * eps[i])
    assert h == pytest.approx(num, rel=0.02, abs=2e-3)
    # Sonar 0 faces the wall x = 4.05: d zhat / dx = -1, no dependence on y.
    assert h[0, :2] == pytest.approx([-1.0 / math.cos(0.05), 0.0], abs=1e-3)


def test_ekf_point_jacobian_eq27_vs_finite_differences():
    g = wall_grid()
    mounts = SONAR_MOUNTS[[0, 3, 5]]
    x = np.array([2.0, 3.0, 0.4])
    params = LocalizationParams(jacobian='point', cone_rays=1, specular_angle=None)
    z_hat, h, usable = ekf.measurement_prediction(g, x, mounts, params)
    s = sonar_global_poses(x, mounts)
    p_i = s[:, :2] + z_hat[:, None] * np.stack([np.cos(s[:, 2]), np.sin(s[:, 2])], axis=1)

    def h27(xx):  # eq. 27 with the hit points p_i held fixed, from the sonar positions
        ss = sonar_global_poses(xx, mounts)
        return np.hypot(p_i[:, 0] - ss[:, 0], p_i[:, 1] - ss[:, 1])

    assert h27(x) == pytest.approx(z_hat)
    num = np.zeros((3, 3))
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1e-6
        num[:, i] = (h27(x + e) - h27(x - e)) / 2e-6
    assert h == pytest.approx(num, abs=1e-6)


@pytest.mark.parametrize('filt', ['ekf', 'ukf'])
def test_update_corrects_towards_truth(filt):
    g = wall_grid()
    truth = np.array([2.0, 3.0, 0.0])
    mounts = SONAR_MOUNTS
    z = predict_ranges(g, truth, mounts)[0]
    z = np.where(np.isnan(z), np.inf, z)
    x = truth + np.array([0.08, -0.06, 0.0])
    p = np.diag([0.1 ** 2, 0.1 ** 2, 0.01 ** 2])
    params = dataclasses.replace(LocalizationParams(), cone_rays=1, specular_angle=None)
    for _ in range(5):
        if filt == 'ekf':
            x, p, info = ekf.measurement_update(x, p, z, g, mounts, params)
        else:
            x, p, info = ukf.measurement_update(x, p, None, z, g, mounts, params)
    assert info['accepted'].sum() >= 3
    assert np.hypot(*(x[:2] - truth[:2])) < 0.02
