"""Iterated EKF update: Gauss-Newton fixed point, plain EKF where nothing moves far."""

import math

from landmark_nav.geometry import wrap_angle
from landmark_nav.slam import ekf_update, observation_model
import numpy as np
import pytest

R_OBS = np.diag([0.01 ** 2, 0.002 ** 2])


def scene(offset):
    """Return (truth, prior mean, prior covariance, noise-free z, R, index).

    Six landmarks 2-4 m around the robot, known to 1 mm; the robot prior is broad
    (0.3 m, 0.05 rad) and its mean is ``offset`` away from the true pose.
    """
    rng = np.random.default_rng(5)
    pose = np.array([1.0, -0.5, 0.3])
    ang = np.linspace(-1.2, 1.2, 6) + pose[2]
    rng_m = rng.uniform(2.0, 4.0, 6)
    lm = pose[:2] + np.column_stack([rng_m * np.cos(ang), rng_m * np.sin(ang)])
    truth = np.concatenate([pose, lm.reshape(-1)])
    x0 = truth.copy()
    x0[:3] += offset
    p0 = np.diag(np.concatenate([[0.3 ** 2, 0.3 ** 2, 0.05 ** 2], np.full(12, 1e-6)]))
    idx = np.arange(6)
    z = observation_model(truth, idx)[0]
    return truth, x0, p0, z, np.repeat(R_OBS[None], 6, axis=0), idx


def cost(x, x0, p0, z, r, idx):
    """Return the Gauss-Newton objective of the update (prior + observations)."""
    dx = x - x0
    dx[2] = wrap_angle(dx[2])
    nu = z - observation_model(x, idx)[0]
    nu[:, 1] = wrap_angle(nu[:, 1])
    return float(dx @ np.linalg.solve(p0, dx)
                 + sum(v @ np.linalg.solve(rk, v) for v, rk in zip(nu, r)))


def test_iterated_update_reaches_the_stationary_point_of_the_objective():
    """Far from the truth the iterated update minimises prior + observation cost."""
    truth, x0, p0, z, r, idx = scene(np.array([0.4, -0.3, 0.05]))
    x_plain = x0.copy()
    ekf_update(x_plain, p0.copy(), z, r, idx)
    x_it = x0.copy()
    p_it, _ = ekf_update(x_it, p0.copy(), z, r, idx, max_iterations=30,
                         relinearize_ratio=1e-9)

    # Gradient of the objective by central differences vanishes at the iterated estimate
    # (relative to its size at the plain EKF estimate).
    def grad(x):
        g = np.zeros(x.size)
        for i in range(x.size):
            e = np.zeros(x.size)
            e[i] = 1e-7
            g[i] = (cost(x + e, x0, p0, z, r, idx) - cost(x - e, x0, p0, z, r, idx)) / 2e-7
        return g
    scale = np.sqrt(np.diag(p0))
    g_it = np.abs(grad(x_it) * scale).max()
    g_plain = np.abs(grad(x_plain) * scale).max()
    assert g_it < 1e-3 * g_plain
    assert cost(x_it, x0, p0, z, r, idx) < cost(x_plain, x0, p0, z, r, idx)
    # Noise-free observations and a broad prior: the minimum is next to the truth.
    err_it = math.hypot(*(x_it[:2] - truth[:2]))
    err_plain = math.hypot(*(x_plain[:2] - truth[:2]))
    assert err_it < 0.005
    assert err_plain > 5 * err_it
    assert np.allclose(p_it, p_it.T) and np.all(np.linalg.eigvalsh(p_it) > 0)


def test_default_ratio_keeps_the_plain_update_when_corrections_are_small():
    """A 1 cm prior error moves nothing by 2 % of its range: bit-identical plain EKF."""
    _, x0, p0, z, r, idx = scene(np.array([0.01, -0.005, 0.002]))
    x1, x2 = x0.copy(), x0.copy()
    p1, nis1 = ekf_update(x1, p0.copy(), z, r, idx)
    p2, nis2 = ekf_update(x2, p0.copy(), z, r, idx, max_iterations=5, relinearize_ratio=0.02)
    assert np.array_equal(x1, x2) and np.array_equal(p1, p2) and nis1 == nis2


def test_iterations_keep_the_prior_innovation_nis():
    """The NIS reported is that of the first linearisation (eq. 60 on the prior)."""
    _, x0, p0, z, r, idx = scene(np.array([0.4, -0.3, 0.05]))
    _, nis_plain = ekf_update(x0.copy(), p0.copy(), z, r, idx)
    _, nis_it = ekf_update(x0.copy(), p0.copy(), z, r, idx, max_iterations=10)
    assert nis_it == pytest.approx(nis_plain, rel=1e-12)
    assert nis_plain > 20.0  # the 0.5 m prior error is visible in the innovation
