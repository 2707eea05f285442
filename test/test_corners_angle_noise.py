"""Propagated angle uncertainty of the corner detector (the optional confidence tests)."""

import math

from landmark_nav.laser.corner_detection.scan_stack import _stack
from landmark_nav.laser.corner_detection.tls_lines import (_line_angle_variance, _lines,
                                                           _weighted_moments)
from landmark_nav.laser.corner_detection.windows import _minus_cos, _window_f_sd
from landmark_nav.laser.corners import CornerParams, detect_corners
from landmark_nav.laser.segmentation import Cluster
import numpy as np
import pytest

RIGHT = math.pi / 2.0


def bend_cluster(theta_deg: float, corner=(2.0, 0.5), heading: float = -0.54,
                 arm: float = 1.0, step: float = 0.02) -> Cluster:
    """Return a noise-free cluster of two straight arms meeting at ``theta_deg``.

    The default heading puts the arms on both sides of the corner's bearing, about 45 deg
    off it (both seen, neither grazing).
    """
    t = np.arange(arm, 0.0, -step)
    th = math.radians(theta_deg)
    u1 = np.array([math.cos(heading), math.sin(heading)])
    u2 = np.array([math.cos(heading + th), math.sin(heading + th)])
    pts = np.concatenate([corner + t[:, None] * u1, [corner], corner + t[::-1, None] * u2])
    ang = np.arctan2(pts[:, 1], pts[:, 0])
    order = np.argsort(ang)
    pts, ang = pts[order], ang[order]
    return Cluster(np.arange(ang.size), pts, np.hypot(pts[:, 0], pts[:, 1]), ang)


def noisy_xy(r: np.ndarray, phi: np.ndarray, sigma_r: float, sigma_phi: float,
             rng: np.random.Generator, n: int):
    """Return ``n`` noisy copies (n, M) of the points: range and bearing noise (eq. 7)."""
    rr = r + rng.normal(0.0, sigma_r, (n, r.size))
    pp = phi + rng.normal(0.0, sigma_phi, (n, r.size))
    return rr * np.cos(pp), rr * np.sin(pp)


@pytest.mark.parametrize('theta_deg,half,sigma_r,sigma_phi', [
    (90.0, 8, 0.01, math.radians(0.1)),
    (110.0, 5, 0.01, math.radians(0.5)),
    (75.0, 12, 0.02, 0.0),
])
def test_window_f_deviation_matches_monte_carlo(theta_deg, half, sigma_r, sigma_phi):
    cl = bend_cluster(theta_deg)
    st = _stack([cl])
    x, y = cl.points[:, 0], cl.points[:, 1]
    mid = int(np.argmin(np.hypot(x - 2.0, y - 0.5)))
    lo, hi = np.array([mid - half]), np.array([mid + half])
    p = CornerParams(sigma_r=sigma_r, sigma_phi=sigma_phi)
    pred = _window_f_sd(st, lo, np.array([mid]), hi, p)[0]
    i = np.array([mid - half, mid, mid + half])
    xs, ys = noisy_xy(st.r[i], st.phi[i], sigma_r, sigma_phi, np.random.default_rng(3), 20000)
    f = _minus_cos(xs[:, 0], ys[:, 0], xs[:, 1], ys[:, 1], xs[:, 2], ys[:, 2])[0]
    assert pred == pytest.approx(np.std(f), rel=0.1)


@pytest.mark.parametrize('sigma_r,sigma_phi', [(0.01, math.radians(0.1)), (0.03, 0.0)])
def test_line_angle_variance_matches_monte_carlo(sigma_r, sigma_phi):
    cl = bend_cluster(90.0)
    x, y = cl.points[:, 0], cl.points[:, 1]
    u2 = np.array([math.cos(-0.54 + RIGHT), math.sin(-0.54 + RIGHT)])  # the second arm
    arm = np.flatnonzero((x - 2.0) * u2[0] + (y - 0.5) * u2[1] > 0.05)[:20]
    r, phi = cl.ranges[arm], cl.angles[arm]
    w = np.ones((1, 1, arm.size))
    ln = _lines(_weighted_moments(w, x[arm][None, None], y[arm][None, None]))
    pred = _line_angle_variance(x[arm][None, None], y[arm][None, None], w, ln,
                                sigma_r, sigma_phi)[0, 0]
    xs, ys = noisy_xy(r, phi, sigma_r, sigma_phi, np.random.default_rng(5), 5000)
    alpha = _lines(_weighted_moments(np.ones_like(xs), xs, ys)).alpha
    d = np.angle(np.exp(2j * (alpha - ln.alpha[0, 0]))) / 2.0  # the normal is mod pi
    assert math.sqrt(pred) == pytest.approx(np.std(d), rel=0.1)


def test_confidence_tests_default_off_and_scale_with_noise():
    p = CornerParams()
    assert (p.gate_sigmas, p.fit_sigmas) == (0.0, 0.0)
    right = [bend_cluster(90.0)]
    base = detect_corners(right, p)
    wide = detect_corners(right, CornerParams(gate_sigmas=3.0, fit_sigmas=3.0))
    assert len(base) == len(wide) == 1
    assert np.allclose(base[0].position, wide[0].position)
    # 114 deg is outside the chapter's 70-110.6 deg; three standard deviations of a fit of
    # 50 samples per arm are a fraction of a degree, so it stays outside.
    obtuse = [bend_cluster(114.0)]
    assert detect_corners(obtuse, p) == []
    assert detect_corners(obtuse, CornerParams(gate_sigmas=3.0, fit_sigmas=3.0)) == []


@pytest.mark.parametrize('name', ['gate_sigmas', 'fit_sigmas'])
@pytest.mark.parametrize('value', [-1.0, math.nan, True])
def test_confidence_parameters_are_validated(name, value):
    with pytest.raises(ValueError, match=rf'CornerParams\.{name}\b'):
        CornerParams(**{name: value})
