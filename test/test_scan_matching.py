"""Tests of the point-to-line ICP used by the evaluation benchmarks."""

import math

from landmark_nav.evaluation.scan_matching import point_to_line_icp
import numpy as np
import pytest


def _room(rng, n=400, noise=0.0):
    # Points on the four walls of a 6 m x 4 m room and a pillar, as a laser at the origin sees.
    walls = [((-3.0, -2.0), (3.0, -2.0)), ((3.0, -2.0), (3.0, 2.0)),
             ((3.0, 2.0), (-3.0, 2.0)), ((-3.0, 2.0), (-3.0, -2.0)),
             ((1.0, 0.5), (1.5, 0.5)), ((1.5, 0.5), (1.5, 1.0))]
    pts = []
    for a, b in walls:
        t = rng.uniform(0.0, 1.0, n // len(walls))[:, None]
        pts.append(np.asarray(a) + t * (np.asarray(b) - np.asarray(a)))
    pts = np.vstack(pts)
    return pts + noise * rng.standard_normal(pts.shape)


def _move(pose, pts):
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return pts @ np.array([[c, s], [-s, c]]) + pose[:2]


def test_icp_recovers_a_known_motion_from_the_odometry_guess():
    rng = np.random.default_rng(3)
    target = _room(rng, noise=0.005)
    truth = np.array([0.12, -0.07, math.radians(4.0)])
    # The source is the room seen from the moved pose: target = R source + t.
    c, s = math.cos(truth[2]), math.sin(truth[2])
    source = (_room(rng, noise=0.005) - truth[:2]) @ np.array([[c, -s], [s, c]])
    guess = truth + np.array([0.08, 0.05, math.radians(-3.0)])   # a drifted odometry guess
    fit = point_to_line_icp(source, target, guess, gates=(0.5, 0.3, 0.15), iterations=20)
    assert fit is not None
    assert np.allclose(fit.pose[:2], truth[:2], atol=0.002)  # about 4 sigma of the fit (0.5 mm)
    assert abs(fit.pose[2] - truth[2]) < math.radians(0.1)  # about 3 sigma (0.03 deg)
    assert np.allclose(_move(fit.pose, source[:5]), _move(truth, source[:5]), atol=0.01)
    assert fit.matches > 300 and 0.0 < fit.rms < 0.01
    # The classic covariance is symmetric, positive definite and of the size of the noise.
    w = np.linalg.eigvalsh(fit.covariance)
    assert np.allclose(fit.covariance, fit.covariance.T) and w.min() > 0.0
    assert 1e-4 < math.sqrt(w.max()) < 0.002


def test_icp_without_enough_points_or_pairs_gives_none():
    rng = np.random.default_rng(4)
    room = _room(rng)
    assert point_to_line_icp(room[:10], room) is None                    # too few points
    far = room + np.array([5.0, 5.0])                                   # nothing within the gate
    assert point_to_line_icp(far, room, gates=(0.15,)) is None


def test_icp_without_a_gate_is_an_error():
    room = _room(np.random.default_rng(5))
    with pytest.raises(ValueError, match='gates'):
        point_to_line_icp(room, room, gates=())
