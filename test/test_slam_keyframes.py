"""Keyframes of the SLAM front end: which sets reach the filter, the pose of the others."""

import math

from landmark_nav.geometry import compose, relative
from landmark_nav.slam.configuration import CHAPTER, default_values, slam_configuration
from landmark_nav.slam.ekf_slam import odometry_noise, SlamParams
from landmark_nav.slam.frontend import (Corners, FrontendParams, ODOMETRY_NOISE_MODELS,
                                        SlamFrontend)
from landmark_nav.slam.keyframes import KeyframeParams
import numpy as np
import pytest

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
PIONEER = ODOMETRY_NOISE_MODELS['pioneer']


def _set(t_ns, calls=None):
    """Two corners; with ``calls``, lines extracted lazily (each extraction recorded)."""
    xy = np.array([[2.0, 1.0], [3.0, -1.0]])
    c = Corners(t_ns, xy, np.tile(np.eye(2) * 1e-4, (2, 1, 1)), np.full(2, math.pi),
                np.full(2, math.pi / 2), np.zeros(2))
    if calls is None:
        return c
    return Corners(c.stamp_ns, c.positions, c.covariances, c.bisector, c.opening,
                   c.beam_time, lines_from=lambda: (calls.append(t_ns) or (), np.zeros(0)))


def _run(keyframe, n=12, step=(0.1, 0.0, 0.05), calls=None):
    """Drive ``n`` sets 0.1 s apart with a constant odometry step; return front end, steps."""
    fe = SlamFrontend(SlamParams(odometry=PIONEER, confirm_hits=1, confirm_window=1),
                      frontend=FrontendParams(keyframe=keyframe))
    pose, steps = np.zeros(3), []
    fe.add_odometry(T0, pose)
    for k in range(1, n + 1):
        pose = compose(pose, step)
        fe.add_odometry(T0 + 100 * k * MS, pose)
        steps += fe.add_features(_set(T0 + 100 * k * MS, calls))
    return fe, steps


def test_keyframe_params():
    assert not KeyframeParams().enabled
    kf = KeyframeParams(min_travel_m=0.25, min_turn_rad=0.2)
    assert kf.is_keyframe(np.array([0.25, 0.0, 0.0]))
    assert kf.is_keyframe(np.array([0.0, 0.0, -0.2]))
    assert not kf.is_keyframe(np.array([0.17, 0.17, 0.19]))  # 0.24 m, 0.19 rad
    assert KeyframeParams(min_travel_m=0.3).is_keyframe(np.array([0.0, 0.0, 3.0])) is False
    for bad in (-0.1, math.nan, True, '1'):
        with pytest.raises(ValueError, match='KeyframeParams.min_travel_m'):
            KeyframeParams(min_travel_m=bad)


def test_every_set_is_a_keyframe_without_thresholds():
    calls = []
    fe, steps = _run(KeyframeParams(), calls=calls)
    assert all(st.keyframe for st in steps) and len(steps) == 12
    assert fe.keyframes == {'keyframes': 12, 'skipped': 0} and len(calls) == 12


def test_sets_between_keyframes_leave_the_filter_unchanged():
    """0.1 m a set, keyframe at 0.29 m: the first set, then every third; the rest predicted."""
    calls = []
    fe, steps = _run(KeyframeParams(min_travel_m=0.29), calls=calls)
    assert [st.keyframe for st in steps] == [True, False, False] * 4
    assert fe.keyframes == {'keyframes': 4, 'skipped': 8}
    assert calls == [st.stamp_ns for st in steps if st.keyframe]  # lines of keyframes only
    assert fe.slam.stats['predictions'] == 4 and fe.events['processed'] == 12
    for k in (1, 2):  # after the first keyframe: its pose composed with the odometry since
        kf, st = steps[0], steps[k]
        np.testing.assert_allclose(st.increment, relative(kf.odometry, st.odometry),
                                   atol=1e-12)  # eq. 13 since the keyframe
        np.testing.assert_allclose(st.pose, compose(kf.pose, st.increment), atol=1e-12)
        # eq. 26: J1 P J1^T + J2 U J2^T, J1 and J2 of x (+) u at the keyframe's pose.
        c, s = math.cos(kf.pose[2]), math.sin(kf.pose[2])
        ux, uy = st.increment[:2]
        j1 = np.array([[1, 0, -s * ux - c * uy], [0, 1, c * ux - s * uy], [0, 0, 1]])
        j2 = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        expected = (j1 @ kf.covariance @ j1.T
                    + j2 @ odometry_noise(st.increment, PIONEER) @ j2.T)
        np.testing.assert_allclose(st.covariance, expected, rtol=1e-9, atol=1e-15)
        assert st.result.status.size == 0 and st.result.nis == 0.0
    # The second keyframe predicts over the whole span since the first (0.3 m), once.
    np.testing.assert_allclose(np.hypot(*steps[3].increment[:2]), 0.3, rtol=0.01)


def test_turning_in_place_makes_keyframes_by_turn():
    fe, steps = _run(KeyframeParams(min_travel_m=0.5, min_turn_rad=0.099),
                     step=(0.0, 0.0, 0.05))
    assert [st.keyframe for st in steps] == [True, False] * 6


def test_configuration_thresholds_and_the_chapter_profile():
    assert CHAPTER['keyframe.min_travel_m'] == 0.0 and CHAPTER['keyframe.min_turn_rad'] == 0.0
    assert not slam_configuration(CHAPTER).frontend.keyframe.enabled
    d = default_values()
    cfg = slam_configuration()
    assert (cfg.frontend.keyframe.min_travel_m, cfg.frontend.keyframe.min_turn_rad) == (
        d['keyframe.min_travel_m'], d['keyframe.min_turn_rad'])
    with pytest.raises(ValueError, match='keyframe.min_turn_rad'):
        slam_configuration({'keyframe.min_turn_rad': -1.0})


def test_update_corrections_are_zero_between_keyframes():
    """What an update moved the pose: predicted from the last keyframe's pose."""
    from types import SimpleNamespace
    from landmark_nav.evaluation.slam import update_corrections
    fe, steps = _run(KeyframeParams(min_travel_m=0.29))
    run = SimpleNamespace(poses=np.array([st.pose for st in steps]),
                          increments=np.array([st.increment for st in steps]),
                          keyframe=np.array([st.keyframe for st in steps]))
    moved = update_corrections(run)
    np.testing.assert_allclose(moved[~run.keyframe], 0.0, atol=1e-12)
    # A keyframe's correction is its update's: pose after it against kf pose (+) increment.
    k = 3
    np.testing.assert_allclose(moved[k], relative(compose(steps[0].pose, steps[k].increment),
                                                  steps[k].pose), atol=1e-12)


def test_a_value_the_filter_refuses_names_the_parameter_as_set():
    from landmark_nav.parameter_tables import name_parameters
    from landmark_nav.slam.configuration import PARAMETER_PREFIXES
    with pytest.raises(ValueError) as err:
        slam_configuration({'sigma_range': -1.0})
    assert str(err.value) == ('ekf_slam: parameter sigma_range must be a finite number '
                              '>= 0.0, got -1.0')
    assert name_parameters('KeyframeParams.min_travel_m must be >= 0', PARAMETER_PREFIXES) == (
        'parameter keyframe.min_travel_m must be >= 0')
