"""EKF-SLAM maths: Jacobians against finite differences, steps against dense references."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from landmark_nav.geometry import compose, wrap_angle
from landmark_nav.laser.corners import Corner
from landmark_nav.slam import (augment_map, chi2_band, chi2_gate, corners_to_observations,
                               ekf_predict, ekf_update, map_initialization, nees, nis,
                               observation_model, odometry_increment, odometry_noise,
                               OdometryNoise, share_inside)
from landmark_nav.slam.ekf_slam import (feature_initialization, is_psd, nearest_psd,
                                        predicted_observation_covariance)
from landmark_nav.slam.observations import corner_descriptors, polar_jacobian
import numpy as np
import pytest

coord = st.floats(-5.0, 5.0)
angle = st.floats(-math.pi, math.pi - 1e-9)


def random_state(rng: np.random.Generator, n_lm: int) -> np.ndarray:
    """Return a state with landmarks at least 0.5 m from the robot."""
    x = np.concatenate([rng.uniform(-2, 2, 2), [rng.uniform(-math.pi, math.pi)]])
    lm = []
    while len(lm) < n_lm:
        p = rng.uniform(-6, 6, 2)
        if np.hypot(*(p - x[:2])) > 0.5:
            lm.append(p)
    return np.concatenate([x, np.array(lm).reshape(-1)])


def random_cov(rng: np.random.Generator, n: int, scale: float = 0.01) -> np.ndarray:
    """Return a random symmetric positive definite matrix."""
    a = rng.normal(size=(n, n)) * scale
    return a @ a.T + scale ** 2 * np.eye(n)


def numeric_jacobian(f, x0: np.ndarray, angle_rows=(), h: float = 1e-6) -> np.ndarray:
    """Central differences of f at x0 (rows listed in angle_rows are wrapped)."""
    cols = []
    for i in range(x0.size):
        d = np.zeros_like(x0)
        d[i] = h
        diff = f(x0 + d) - f(x0 - d)
        for r in angle_rows:
            diff[..., r] = wrap_angle(diff[..., r])
        cols.append(diff / (2 * h))
    return np.stack(cols, axis=-1)


# ----------------------------------------------------------------------------- Jacobians
@settings(max_examples=60, deadline=None)
@given(coord, coord, angle, coord, coord)
def test_observation_jacobians_match_finite_differences(xr, yr, psi, xl, yl):
    """H_r and H_F of eq. 53 equal central differences of eqs. 19-20."""
    if math.hypot(xl - xr, yl - yr) < 0.3:
        xl += 1.0
    x = np.array([xr, yr, psi, xl, yl])
    idx = np.array([0])
    _, hr, hf = observation_model(x, idx)
    num_r = numeric_jacobian(lambda p: observation_model(np.r_[p, xl, yl], idx)[0][0],
                             x[:3], angle_rows=(1,))
    num_f = numeric_jacobian(lambda q: observation_model(np.r_[x[:3], q], idx)[0][0],
                             x[3:], angle_rows=(1,))
    assert hr[0] == pytest.approx(num_r, abs=1e-6)
    assert hf[0] == pytest.approx(num_f, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(coord, coord, angle, st.floats(0.2, 8.0), angle)
def test_augmentation_jacobians_match_finite_differences(xr, yr, psi, rng, theta):
    """G_r (eq. 46) and G_z (eq. 48) equal central differences of g (eq. 40)."""
    pose, z = np.array([xr, yr, psi]), np.array([[rng, theta]])
    g, gr, gz = feature_initialization(pose, z)
    num_r = numeric_jacobian(lambda p: feature_initialization(p, z)[0][0], pose)
    num_z = numeric_jacobian(lambda q: feature_initialization(pose, q[None])[0][0], z[0])
    assert gr[0] == pytest.approx(num_r, abs=1e-6)
    assert gz[0] == pytest.approx(num_z, abs=1e-6)
    # g inverts the observation model: observing g from the pose gives z back.
    zhat = observation_model(np.r_[pose, g[0]], np.array([0]))[0][0]
    assert zhat[0] == pytest.approx(rng, abs=1e-9)
    assert wrap_angle(zhat[1] - theta) == pytest.approx(0.0, abs=1e-9)


def test_polar_jacobian_matches_finite_differences():
    """The Cartesian -> (r, theta) Jacobian used to propagate R."""
    rng = np.random.default_rng(3)
    for p in rng.uniform(-4, 4, (20, 2)):
        f = (lambda q: np.array([math.hypot(*q), math.atan2(q[1], q[0])]))
        assert polar_jacobian(p[None])[0] == pytest.approx(
            numeric_jacobian(f, p, angle_rows=(1,)), abs=1e-6)


# ------------------------------------------------------------------ steps vs references
def test_predict_matches_dense_propagation():
    """Eqs. 25-30 in place equal F P F^T + G U G^T with F = diag(J1, I), G = [J2; 0]."""
    rng = np.random.default_rng(1)
    x = random_state(rng, 4)
    p = random_cov(rng, x.size)
    u = np.array([0.3, -0.05, 0.2])
    uc = odometry_noise(u, OdometryNoise())
    x1, p1 = x.copy(), p.copy()
    ekf_predict(x1, p1, u, uc)
    f = np.eye(x.size)
    f[:3, :3] = numeric_jacobian(lambda q: compose(q, u), x[:3], angle_rows=(2,))
    g = np.zeros((x.size, 3))
    g[:3] = numeric_jacobian(lambda q: compose(x[:3], q), u, angle_rows=(2,))
    assert x1[:3] == pytest.approx(compose(x[:3], u), abs=1e-12)
    assert x1[3:] == pytest.approx(x[3:], abs=0)  # eq. 12
    assert p1 == pytest.approx(f @ p @ f.T + g @ uc @ g.T, abs=1e-9)
    assert np.array_equal(p1, p1.T)


def test_update_matches_dense_joseph_form():
    """The block-wise batch update equals the dense Joseph-form EKF update (eqs. 32-36)."""
    rng = np.random.default_rng(2)
    x = random_state(rng, 6)
    p = random_cov(rng, x.size, 0.05)
    idx = np.array([4, 1, 3])
    z = observation_model(x, idx)[0] + rng.normal(0, [0.02, 0.01], (3, 2))
    r = np.array([np.diag([0.02 ** 2, 0.01 ** 2])] * 3)
    x1 = x.copy()
    p1, nis_value = ekf_update(x1, p.copy(), z, r, idx)
    zhat, hr, hf = observation_model(x, idx)
    h = np.zeros((6, x.size))
    for k, j in enumerate(idx):
        h[2 * k:2 * k + 2, :3] = hr[k]
        h[2 * k:2 * k + 2, 3 + 2 * j:5 + 2 * j] = hf[k]
    nu = z - zhat
    nu[:, 1] = wrap_angle(nu[:, 1])
    rr = np.kron(np.eye(3), np.zeros((2, 2)))
    for k in range(3):
        rr[2 * k:2 * k + 2, 2 * k:2 * k + 2] = r[k]
    s = h @ p @ h.T + rr  # eq. 33
    w = p @ h.T @ np.linalg.inv(s)  # eq. 32
    ikh = np.eye(x.size) - w @ h
    x_ref = x + w @ nu.reshape(-1)  # eq. 34
    p_ref = ikh @ p @ ikh.T + w @ rr @ w.T  # Joseph form of eq. 35
    assert x1[3:] == pytest.approx(x_ref[3:], abs=1e-10)
    assert x1[:2] == pytest.approx(x_ref[:2], abs=1e-10)
    assert wrap_angle(x1[2] - x_ref[2]) == pytest.approx(0.0, abs=1e-10)
    assert p1 == pytest.approx(p_ref, abs=1e-10)
    assert nis_value == pytest.approx(nis(nu.reshape(-1), s), rel=1e-9)
    assert np.array_equal(p1, p1.T)
    # eq. 52 per landmark equals the diagonal blocks of H P H^T.
    c = predicted_observation_covariance(p, idx, hr, hf)
    for k in range(3):
        assert c[k] == pytest.approx((h @ p @ h.T)[2 * k:2 * k + 2, 2 * k:2 * k + 2],
                                     abs=1e-12)


def test_augment_matches_dense_eq43():
    """Block-wise augmentation equals Y [[P, 0], [0, R]] Y^T (eqs. 43-44) for two landmarks."""
    rng = np.random.default_rng(4)
    x = random_state(rng, 3)
    p = random_cov(rng, x.size)
    z = np.array([[2.0, 0.3], [4.0, -1.0]])
    r = np.array([np.diag([1e-4, 3e-4]), np.diag([4e-4, 1e-4])])
    x1, p1 = augment_map(x, p, z, r)
    g, gr, gz = feature_initialization(x[:3], z)
    n = x.size
    y = np.zeros((n + 4, n + 4))
    y[:n, :n] = np.eye(n)
    for k in range(2):
        y[n + 2 * k:n + 2 * k + 2, :3] = gr[k]  # eq. 44, G_xr
        y[n + 2 * k:n + 2 * k + 2, n + 2 * k:n + 2 * k + 2] = gz[k]  # G_z
    big = np.zeros((n + 4, n + 4))
    big[:n, :n] = p
    big[n:n + 2, n:n + 2], big[n + 2:, n + 2:] = r[0], r[1]
    assert x1[n:] == pytest.approx(g.reshape(-1), abs=1e-12)
    assert p1 == pytest.approx(y @ big @ y.T, abs=1e-12)


def test_map_initialization_and_increment():
    """Eqs. 23-24 (zero covariance) and eq. 13 (increment between odometry poses)."""
    x, p = map_initialization([1.0, 2.0, 4.0])
    assert x == pytest.approx([1.0, 2.0, 4.0 - 2 * math.pi])
    assert not p.any()
    a, b = np.array([1.0, 1.0, 0.5]), np.array([1.5, 1.2, 0.9])
    assert compose(a, odometry_increment(a, b)) == pytest.approx(b, abs=1e-12)


def test_odometry_noise_grows_with_distance_and_rotation():
    """U: variances linear in distance and rotation, floored."""
    nz = OdometryNoise(0.01, 0.02, 0.03, 1e-4, 2e-4)
    u0 = odometry_noise(np.zeros(3), nz)
    assert np.diag(u0) == pytest.approx([1e-8, 1e-8, 4e-8])
    u1 = odometry_noise(np.array([3.0, 4.0, 0.0]), nz)
    assert np.diag(u1) == pytest.approx([5e-4, 5e-4, 2e-3])
    u2 = odometry_noise(np.array([0.0, 0.0, -2.0]), nz)
    assert u2[2, 2] == pytest.approx(1.8e-3)


# ---------------------------------------------------------------------- consistency
def test_chi2_helpers_and_nees_nis():
    """Chi-square gates / bands and eqs. 59-60 on known values."""
    assert chi2_gate(2, 0.95) == pytest.approx(5.991, abs=1e-3)
    lo, hi = chi2_band(3, 0.95)
    assert (lo, hi) == pytest.approx((0.2158, 9.3484), abs=1e-3)
    cov = np.diag([0.04, 0.01, 0.0025])
    # heading error wraps: true -pi + 0.05, estimate pi - 0.05 -> error 0.1 rad
    e = nees([0.2, 0.1, -math.pi + 0.05], [0.0, 0.0, math.pi - 0.05], cov)
    assert e == pytest.approx(1.0 + 1.0 + 4.0, rel=1e-9)
    assert nis([0.3, 0.0], np.diag([0.09, 1.0])) == pytest.approx(1.0)
    assert nees([1.0, 0, 0], [0, 0, 0], np.zeros((3, 3))) == math.inf
    assert share_inside(np.array([0.1, 1.0, 2.0, 20.0]), 3) == pytest.approx(0.5)
    assert share_inside(np.array([0.1, 1.0, 2.0, 20.0]), 3, two_sided=False) == 0.75
    with pytest.raises(ValueError):
        chi2_gate(0)


def test_psd_helpers():
    """is_psd accepts PSD (even singular) matrices and nearest_psd repairs others."""
    assert is_psd(np.zeros((3, 3)))
    assert is_psd(np.diag([1.0, 0.0, 2.0]))
    bad = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3, -1
    assert not is_psd(bad)
    fixed = nearest_psd(bad)
    assert is_psd(fixed)
    assert np.linalg.eigvalsh(fixed) == pytest.approx([0.0, 3.0], abs=1e-12)
    assert not is_psd(np.array([[np.nan]]))


# ---------------------------------------------------------------------- observations
def corner(x: float, y: float, cov: np.ndarray, bisector: float = 0.0) -> Corner:
    """Return a Corner at (x, y) in the laser frame."""
    return Corner(position=np.array([x, y]), bisector=bisector, opening=math.pi / 2,
                  covariance=cov, index=0, f_theta=0.0)


def test_corners_to_observations_mount_and_covariance():
    """Laser -> base_link with the mount, then range-bearing with R = J C J^T."""
    cov = np.array([[4e-4, 1e-4], [1e-4, 1e-4]])
    mount = (0.1, -0.05, math.pi / 2)
    z, r = corners_to_observations([corner(2.0, 0.5, cov, bisector=0.3)], mount)
    pb = np.array([0.1 - 0.5, -0.05 + 2.0])  # R(90 deg) [2, 0.5] + t
    assert z[0] == pytest.approx([math.hypot(*pb), math.atan2(pb[1], pb[0])], abs=1e-12)
    rot = np.array([[0.0, -1.0], [1.0, 0.0]])
    jac = polar_jacobian(pb[None])[0]
    assert r[0] == pytest.approx(jac @ rot @ cov @ rot.T @ jac.T, abs=1e-15)
    # Monte Carlo check of the propagated covariance (first order, small noise).
    rng = np.random.default_rng(5)
    pts = rng.multivariate_normal([2.0, 0.5], cov, 20000)
    zs = corners_to_observations([corner(a, b, cov) for a, b in pts[:4000]], mount)[0]
    assert np.cov(zs.T) == pytest.approx(r[0], rel=0.1, abs=1e-7)
    desc = corner_descriptors([corner(2.0, 0.5, cov, bisector=0.3)], mount)
    assert desc[0] == pytest.approx([0.3 + math.pi / 2, math.pi / 2])
    assert corners_to_observations([], mount)[0].shape == (0, 2)


def test_corners_to_observations_beam_motion():
    """With sweep motion the point moves to base_link at the scan stamp."""
    cov = np.eye(2) * 1e-4
    motion = np.array([[0.2, 0.0, 0.1]])
    z, r = corners_to_observations([corner(1.0, 0.0, cov)], (0.0, 0.0, 0.0), motion)
    p = np.array([0.2 + math.cos(0.1), math.sin(0.1)])
    assert z[0] == pytest.approx([math.hypot(*p), math.atan2(p[1], p[0])], abs=1e-12)
    assert np.trace(r[0] * np.diag([1.0, math.hypot(*p) ** 2])) == pytest.approx(2e-4)
