"""End-to-end EKF-SLAM on the simulated office: the issue's accuracy and consistency targets.

Corners come from the package's extractor on every ScanSample, odometry is interpolated to
the scan stamps (see :mod:`landmark_nav.evaluation.slam` for the pipeline and the scoring).
Targets (issue 4): ATE RMSE <= 5 cm and >= 10x better than odometry alone; max position
error <= 15 cm; landmark RMSE <= 5 cm; mapped landmarks within 10 % of the true visible
corners; no wrong association; robot-pose NEES inside the two-sided 95 % chi-square band on
>= 90 % of the scans, pooled over the seeds (a single run's share is a noisy statistic: the
pose error is dominated by the map's slowly varying anchoring error, so one lucky run sits
below the band for hundreds of scans). Two seeds with ICNN and one with JCBB here; the
10-seed table is produced by the same functions.
"""

from typing import Dict, Tuple

from landmark_nav.evaluation.slam import run_slam, score_run, SlamRun, SlamScore
from landmark_nav.sim import run_scenario
from landmark_nav.slam import SlamParams
import numpy as np
import pytest

CASES = [('icnn', 1), ('icnn', 4), ('jcbb', 2)]
_CACHE: Dict[Tuple[str, int], Tuple[SlamRun, SlamScore, Dict[str, float]]] = {}


def run_case(method: str, seed: int):
    """Run (once per process) the office scenario through the filter and score it."""
    key = (method, seed)
    if key not in _CACHE:
        res = run_scenario('office', seed, sonar=None)
        params = SlamParams(association=method)
        worst = {'asym': 0.0, 'min_eig': 0.0}

        def check(k, slam, result) -> None:
            p = slam.covariance
            worst['asym'] = max(worst['asym'], float(np.max(np.abs(p - p.T))))
            w = np.linalg.eigvalsh(p)
            worst['min_eig'] = min(worst['min_eig'], float(w.min() / max(w.max(), 1e-300)))

        run = run_slam(res, params, callback=check)
        _CACHE[key] = (run, score_run(res, run, params), worst)
    return _CACHE[key]


@pytest.mark.slow
@pytest.mark.parametrize('method, seed', CASES)
def test_office_accuracy_targets(method, seed):
    """ATE, max error, landmark RMSE, map size and zero wrong associations."""
    run, score, _ = run_case(method, seed)
    assert score.ate_rmse <= 0.05
    assert score.odom_ate_rmse >= 10.0 * score.ate_rmse
    assert score.ate_max <= 0.15
    assert score.landmark_rmse <= 0.05
    assert abs(score.mapped - score.true_visible) <= 0.1 * score.true_visible
    assert score.true_visible >= 10
    assert score.wrong_associations == 0
    assert score.associations > 1500
    assert score.ghost_landmarks == 0 and score.duplicates == 0
    assert run.resets == 0


@pytest.mark.slow
@pytest.mark.parametrize('method, seed', CASES)
def test_office_covariance_symmetric_psd(method, seed):
    """P is exactly symmetric and PSD after every scan; no repair was needed."""
    _, score, worst = run_case(method, seed)
    assert worst['asym'] == 0.0
    assert worst['min_eig'] >= -1e-12
    assert score.psd_repairs == 0
    assert 0.5 <= score.mean_nees <= 6.0  # neither grossly pessimistic nor optimistic


@pytest.mark.slow
def test_office_nees_share_pooled_over_seeds():
    """Robot-pose NEES inside the two-sided 95 % chi-square band on >= 90 % of all scans."""
    runs = [run_case(method, seed) for method, seed in CASES]
    scans = np.array([len(run.stamps) for run, _, _ in runs])
    share = np.array([score.nees_share_band for _, score, _ in runs])
    assert float(np.sum(share * scans) / np.sum(scans)) >= 0.90
