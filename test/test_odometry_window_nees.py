"""Odometry NEES over path windows (landmark_nav.evaluation.odometry_drift)."""

import math

from landmark_nav.evaluation.odometry_drift import odometry_window_nees
from landmark_nav.evaluation.trajectory import planar_alignment
from landmark_nav.geometry import compose, compose_jacobians, relative, wrap_angle
from landmark_nav.importers.drift import DRIFT_MODELS, synthetic_odometry
from landmark_nav.slam.ekf_slam import odometry_noise
from landmark_nav.slam.frontend import odometry_noise_model
import numpy as np
import pytest

PIONEER = odometry_noise_model('pioneer')


def _arc(radius=3.0, length=60.0, step=0.5):
    t = np.arange(0.0, length + 1e-9, step)
    return np.column_stack([radius * np.sin(t / radius), radius * (1.0 - np.cos(t / radius)),
                            t / radius])


def _u(u):
    return odometry_noise(u, PIONEER)


def test_perfect_odometry_gives_zero():
    ref = _arc()
    assert np.allclose(odometry_window_nees(ref, ref, _u, 1.0), 0.0, atol=1e-12)


def test_turning_windows_consistent_with_the_importer_drift():
    """The importer's pioneer drift against the filter's pioneer U on an arc (3 m radius).

    The filter's U spreads the distance variance on both axes, the drift puts it along the
    motion only: NEES below 3 at 1 m; at 10 m (heading std about 14 deg) the first-order
    covariance is still close. The error expressed in the window's end frame against the
    covariance in its start frame (the former benchmark) is far off on the same windows.
    """
    ref = _arc()
    nees_1, nees_10, end_frame = [], [], []
    for seed in range(100):
        odo = synthetic_odometry(ref, DRIFT_MODELS['pioneer'], seed)
        nees_1.append(odometry_window_nees(ref, odo, _u, 1.0))
        windows = odometry_window_nees(ref, odo, _u, 10.0)
        nees_10.append(windows)
        i = 0
        for _ in windows:  # the same 10 m windows, error in the end frame
            j = i + 20
            e = relative(relative(ref[i], ref[j]), relative(odo[i], odo[j]))
            e[2] = wrap_angle(e[2])
            x, cov = np.zeros(3), np.zeros((3, 3))
            for k in range(i, j):
                u = relative(odo[k], odo[k + 1])
                j1, j2 = compose_jacobians(x, u)
                cov = j1 @ cov @ j1.T + j2 @ _u(u) @ j2.T
                x = compose(x, u)
            end_frame.append(e @ np.linalg.solve(cov, e))
            i = j
    nees_1, nees_10 = np.concatenate(nees_1), np.concatenate(nees_10)
    assert 1.8 < nees_1.mean() < 3.0
    assert 2.0 < nees_10.mean() < 4.5
    assert np.mean(end_frame) > 3.0 * nees_10.mean()


def test_whole_track_window_and_bad_input():
    ref = _arc(length=20.0)
    odo = synthetic_odometry(ref, DRIFT_MODELS['pioneer'], 0)
    assert odometry_window_nees(ref, odo, _u, math.inf).shape == (1,)
    assert odometry_window_nees(ref[:3], odo[:3], _u, 10.0).size == 0
    with pytest.raises(ValueError):
        odometry_window_nees(ref, odo, _u, 0.0)
    with pytest.raises(ValueError):
        odometry_window_nees(ref, odo[:-1], _u, 1.0)


def test_planar_alignment_recovers_a_global_rotation():
    """A path turned as a whole about the origin: the fit gives the turn, rmse 0."""
    ref = _arc()
    a = math.radians(7.5)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    est = ref[:, :2] @ rot.T + [0.3, -0.2]
    angle, t, rmse = planar_alignment(est, ref)
    assert angle == pytest.approx(-a, abs=1e-12)
    assert rmse == pytest.approx(0.0, abs=1e-12)
    assert np.allclose(est @ np.array([[math.cos(angle), -math.sin(angle)],
                                       [math.sin(angle), math.cos(angle)]]).T + t, ref[:, :2])
