"""Acceptance targets of sonar localization on the simulated hallway (issue 6).

Protocol (see :func:`landmark_nav.evaluation.localization.hallway_study`, which runs it on
10 seeds): map ``rasterize_world(result.world, 0.1)``; calibrated odometry (the
simulator's true k1, k2, k3); initial estimate drawn from N(truth, diag(5.5 cm, 5.5 cm,
5.1 deg)^2) and initial covariance the same (chapter section 6.1); errors measured from the
first stamp at which the robot moves (the run starts with 1 s = 10 sonar cycles at rest)
to the end. A few seeds here to stay fast.
"""

import math

from landmark_nav.evaluation.localization import (CHAPTER_P0, distance_index,
                                                  draw_initial_pose, first_motion_index,
                                                  last_exceedance, localization_errors,
                                                  LocalizationInput, localize,
                                                  odometry_trajectory, TARGETS)
from landmark_nav.localization.params import LocalizationParams
from landmark_nav.localization.sonar_model import build_sonar_map
from landmark_nav.sim import run_scenario
import numpy as np
import pytest

SEEDS = (1, 2, 3)


@pytest.mark.slow
@pytest.mark.parametrize('seed', SEEDS)
def test_hallway_targets(hallway_localization, seed):
    run = hallway_localization(seed)  # shared with test_loc_nees.py (conftest)
    inp, i0 = run['inp'], run['i0']
    assert 19.0 < run['path_length'] < 21.0
    assert i0 >= 10
    odo_cal = localization_errors(odometry_trajectory(inp, inp.truth[0], inp.true_k),
                                  inp.truth, i0)
    odo_raw = localization_errors(odometry_trajectory(inp, inp.truth[0]), inp.truth, i0)
    for filt in ('ekf', 'ukf'):
        traj, covs = run[filt]
        assert traj.shape == (inp.truth.shape[0], 3) and covs.shape == (traj.shape[0], 3, 3)
        err = localization_errors(traj, inp.truth, i0)
        max_pos, max_head = TARGETS[filt]
        assert err['max_position'] <= max_pos, (filt, err)
        assert err['max_heading'] <= max_head, (filt, err)
        # At least 5x smaller end-of-run error than odometry alone, even calibrated odometry
        # started from the TRUE pose.
        assert 5.0 * err['end_position'] <= odo_cal['end_position'], (filt, err, odo_cal)
        assert 5.0 * err['end_position'] <= odo_raw['end_position']


@pytest.mark.slow
@pytest.mark.parametrize('filt', ['ekf', 'ukf'])
def test_two_sigma_start_converges_within_5m(hallway_localization, filt):
    run1 = hallway_localization(1)
    inp, grid = run1['inp'], run1['grid']
    sigma = np.sqrt(np.diag(CHAPTER_P0))
    i5 = distance_index(inp.truth, 5.0)
    for signs in ((1, 1, 1), (-1, -1, -1), (1, -1, 1), (-1, 1, -1)):
        x0 = inp.truth[0] + 2.0 * sigma * np.array(signs)
        run = localize(inp, filt, grid, x0, CHAPTER_P0)
        dist, last = last_exceedance(run.trajectory, inp.truth, *TARGETS[filt])
        assert dist < 5.0 and last < i5, (signs, dist)
        err = localization_errors(run.trajectory, inp.truth, i5)
        assert err['max_position'] <= TARGETS[filt][0]
        assert err['max_heading'] <= TARGETS[filt][1]


@pytest.mark.slow
def test_sonar_built_map_keeps_ukf_within_15cm(hallway_localization):
    ref = LocalizationInput.from_result(run_scenario('hallway', 100))
    built = build_sonar_map(ref.truth, ref.sonar_ranges, ref.mounts, 0.1)
    params = LocalizationParams(unknown='free')  # unexplored gaps inside the free space
    inp = hallway_localization(2)['inp']
    x0 = draw_initial_pose(inp.truth[0], CHAPTER_P0, 1002)
    run = localize(inp, 'ukf', built, x0, CHAPTER_P0, params)
    err = localization_errors(run.trajectory, inp.truth, first_motion_index(inp.truth))
    assert err['max_position'] <= 0.15, err
    assert err['max_heading'] <= math.radians(5.0), err
