"""Tests of line matching and lateral position (chapter eqs. 22-23) on projected corridors."""

import math

from landmark_nav.corridor.lateral import corridor_rotation, CorridorModel, lateral_position
import numpy as np
import pytest

K = np.array([[400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]])
MODEL = CorridorModel(width=2.0, height=2.6, centre_line=True)


def camera_rotation(theta, alpha):
    """Return R (corridor -> optical) for a camera at heading theta, tilt alpha, roll 0."""
    d = np.array([math.sin(theta), -math.cos(theta) * math.sin(alpha),
                  math.cos(theta) * math.cos(alpha)])
    R, t, a = corridor_rotation(d)
    assert t == pytest.approx(theta) and a == pytest.approx(alpha)
    np.testing.assert_allclose(R @ [1.0, 0.0, 0.0], d, atol=1e-12)
    return R


def corridor_segments(R, cam, lines, x_range=(3.0, 9.0)):
    """Return (L, 4) image segments of the model lines (y, z) seen from camera ``cam``."""
    out = []
    for y, z in lines:
        pts = [R @ (np.array([x, y, z]) - cam) for x in x_range]
        px = [(K @ p)[:2] / (K @ p)[2] for p in pts]
        out.append(np.concatenate(px))
    return np.array(out)


@pytest.mark.parametrize('y_cam', [-0.6, -0.1, 0.0, 0.35, 0.8])
@pytest.mark.parametrize('theta_deg,alpha_deg', [(0.0, 0.0), (-8.0, 5.0), (12.0, -3.0)])
def test_exact_lines_give_the_exact_position(y_cam, theta_deg, alpha_deg):
    theta, alpha = math.radians(theta_deg), math.radians(alpha_deg)
    R = camera_rotation(theta, alpha)
    h = 1.1
    walls = [(1.0, 0.0), (-1.0, 0.0), (1.0, 2.6), (-1.0, 2.6)]
    seg = corridor_segments(R, np.array([0.0, y_cam, h]), walls)
    est = lateral_position(seg, K, R[:, 0], CorridorModel(2.0, 2.6), mount=[0, 0, h, 0, 0, 0])
    assert est.y == pytest.approx(y_cam, abs=1e-9)
    assert np.all(est.kept)
    assert sorted(est.model_line.tolist()) == [0, 1, 2, 3]


def test_centre_line_ambiguity_is_resolved():
    R = camera_rotation(math.radians(4.0), math.radians(2.0))
    y_cam, h = 0.3, 1.0
    lines = MODEL.lines()                     # both floor edges, centre line, ceiling edges
    seg = corridor_segments(R, np.array([0.0, y_cam, h]), lines)
    est = lateral_position(seg, K, R[:, 0], MODEL, mount=[0, 0, h, 0, 0, 0])
    assert est.y == pytest.approx(y_cam, abs=1e-9)
    # lower lines were also matched to the centre line; those wrong pairs were removed
    assert est.estimates.size > len(lines)
    wrong = np.abs(est.estimates - y_cam) > 1e-6
    assert np.any(wrong) and not np.any(est.kept & wrong)


def test_noise_outliers_and_the_stated_std():
    rng = np.random.default_rng(3)
    R = camera_rotation(math.radians(-5.0), math.radians(3.0))
    y_cam, h = -0.25, 1.2
    clean = corridor_segments(R, np.array([0.0, y_cam, h]), MODEL.lines())
    errs, stds = [], []
    for _ in range(200):
        seg = clean.copy()
        d = seg[:, 2:] - seg[:, :2]
        n = np.column_stack([-d[:, 1], d[:, 0]]) / np.hypot(d[:, 0], d[:, 1])[:, None]
        seg[:, :2] += rng.normal(0, 0.5, (len(seg), 1)) * n
        seg[:, 2:] += rng.normal(0, 0.5, (len(seg), 1)) * n
        est = lateral_position(seg, K, R[:, 0], MODEL, mount=[0, 0, h, 0, 0, 0],
                               sigma_px=0.5)
        errs.append(est.y - y_cam)
        stds.append(est.std)
    errs = np.array(errs)
    # the stated std matches the spread (measured ratio 1.01 over 200 runs)
    ratio = np.std(errs) / np.median(stds)
    assert 0.8 < ratio < 1.25
    assert abs(np.mean(errs)) < 3 * np.std(errs) / math.sqrt(len(errs)) + 1e-3
    assert np.sqrt(np.mean(errs ** 2)) < 0.006      # measured 4.3 mm at 0.5 px noise


def test_prior_picks_between_two_consistent_answers():
    # the centre line alone, seen from y = 0.6: as the centre line it says y = 0.6, as the
    # right wall's floor edge y = -0.4 (as the left one 1.6, outside): the prior decides
    R = camera_rotation(0.0, math.radians(4.0))
    h = 1.0
    seg = corridor_segments(R, np.array([0.0, 0.6, h]), [(0.0, 0.0)])    # centre line only
    model = CorridorModel(2.0, None, centre_line=True)
    mount = [0, 0, h, 0, 0, 0]
    near_centre = lateral_position(seg, K, R[:, 0], model, mount, prior=(0.5, 0.1))
    assert near_centre.y == pytest.approx(0.6, abs=1e-9)
    near_wall = lateral_position(seg, K, R[:, 0], model, mount, prior=(-0.4, 0.1))
    assert near_wall.y == pytest.approx(-0.4, abs=1e-9)


def test_mount_offset_moves_the_estimate_to_base_link():
    theta = math.radians(10.0)
    R = camera_rotation(theta, 0.0)
    y_base, h = 0.2, 1.0
    mx, my = 0.3, -0.1                                    # camera ahead and right of base
    y_cam = y_base + mx * math.sin(theta) + my * math.cos(theta)
    seg = corridor_segments(R, np.array([0.0, y_cam, h]), MODEL.lines())
    est = lateral_position(seg, K, R[:, 0], MODEL, mount=[mx, my, h, 0, 0, 0])
    assert est.y_camera == pytest.approx(y_cam, abs=1e-9)
    assert est.y == pytest.approx(y_base, abs=1e-9)


def test_bad_input():
    with pytest.raises(ValueError, match='width'):
        CorridorModel(0.0)
    with pytest.raises(ValueError, match='height'):
        CorridorModel(2.0, -1.0)
    with pytest.raises(ValueError, match='no corridor line'):
        lateral_position(np.zeros((0, 4)), K, [0, 0, 1.0], MODEL, [0, 0, 1.0, 0, 0, 0])
    with pytest.raises(ValueError, match='between floor and ceiling'):
        lateral_position(np.zeros((1, 4)), K, [0, 0, 1.0], MODEL, [0, 0, 3.0, 0, 0, 0])
    with pytest.raises(ValueError, match='fx, fy'):
        lateral_position(np.zeros((1, 4)), np.zeros((3, 3)), [0, 0, 1.0], MODEL)
