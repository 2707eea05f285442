"""``evaluate_bag`` on the office bag: files, targets of the issue, bad input."""

import json
from pathlib import Path

from landmark_nav.tools.evaluate_slam import evaluate_bag, relative_pose_error
import numpy as np
import pytest

BAG = Path(__file__).resolve().parents[1] / 'bags' / 'office'
FILES = ('trajectory_slam.tum', 'trajectory_odom.tum', 'trajectory_gt.tum', 'slam.json',
         'slam_map.png', 'slam_errors.png')


@pytest.fixture(scope='module', params=['icnn', 'jcbb'])
def evaluated(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(request.param)
    return evaluate_bag(BAG, request.param, out, progress=False), out


def test_files_written(evaluated):
    result, out = evaluated
    for name in FILES:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    assert json.loads((out / 'slam.json').read_text())['ate_rmse'] == result['ate_rmse']
    rows = np.loadtxt(out / 'trajectory_slam.tum')
    assert rows.shape == (result['scans'], 8)
    np.testing.assert_allclose(np.hypot(rows[:, 6], rows[:, 7]), 1.0, atol=1e-6)
    assert np.all(np.diff(rows[:, 0]) > 0)


# Worst of the 10 office seeds (0-9) in the README's EKF-SLAM table, per association: ATE
# RMSE, max position error, landmark RMSE [m], lowest per-seed share of steps with the robot
# NEES inside the 95 % band. The bag is one more recording of the same scenario; its exact
# ICNN figures are guarded by test_golden.py (bags/office/expected.yaml).
WORST_SEED = {'icnn': (0.0072, 0.0175, 0.0055, 0.868), 'jcbb': (0.0070, 0.0168, 0.0054, 0.880)}


def test_targets(evaluated):
    r, _ = evaluated
    print({k: v for k, v in r.items() if k != 'stats'})
    ate, ate_max, landmark, nees = WORST_SEED[r['association']]
    assert r['ate_rmse'] <= ate
    assert r['ate_rmse'] * 10 <= r['odom_ate_rmse']
    assert r['ate_max'] <= ate_max
    assert r['landmark_rmse'] <= landmark
    assert r['mapped'] == r['true_visible'] == 13
    assert r['wrong_associations'] == 0
    assert r['rpe_trans_rmse'] < r['odom_rpe_trans_rmse']
    assert r['nees_share_band'] >= nees
    # Real-time factor is reported, not asserted (machine dependent).
    assert r['real_time_factor'] > 1.0


def test_rpe_of_truth_is_zero():
    t = np.linspace(0, 5, 51)
    truth = np.column_stack([t, np.zeros_like(t), np.zeros_like(t)])
    r = relative_pose_error(truth, truth)
    assert r['pairs'] > 0 and r['trans_rmse'] == 0.0


def test_bad_input(tmp_path):
    with pytest.raises(ValueError, match='association'):
        evaluate_bag(BAG, 'nearest', progress=False)
    with pytest.raises(ValueError, match='not a bag directory'):
        evaluate_bag(tmp_path / 'missing', progress=False)
    with pytest.raises(ValueError, match='ground_truth.yaml'):
        evaluate_bag(tmp_path, progress=False)
