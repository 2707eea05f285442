"""The shuttle of visual navigation §2.3: landmark fixes keep the robot at its goal.

20 round trips, with fixes at the stops and with fixes also on the approach, instead of
the chapter's 100. The approach over 40 trips, with the same bounds, is checked by
``python benchmarks/bench_landmarks.py shuttle`` (bounds in
``benchmarks/results/landmarks.json``); the full runs are reported by ``python -m
landmark_nav.evaluation.vision``, which runs the same function.
"""

from functools import lru_cache

from landmark_nav.evaluation import vision
import pytest

TRIPS = 20


@lru_cache(maxsize=None)
def shuttle(correction: str, procedure: str = 'stop'):
    """Return (once per process) the shuttle of ``TRIPS`` trips, seed 15; both tests share it."""
    return vision.shuttle(trips=TRIPS, seed=15, correction=correction, procedure=procedure)


@pytest.mark.slow
def test_shuttle_with_landmark_fixes_stays_near_the_one_metre_point():
    # the chapter's procedure: fixes only while standing at the 1 m point
    fixed = shuttle('ekf')
    drift = shuttle('none')
    assert fixed.fixes == fixed.arrivals + 1                 # a fix at every stop
    assert fixed.detected_frames == fixed.frames
    assert fixed.approach_frames == 0
    assert fixed.max_fix_error <= 0.03     # 1 m range: ~1 deg of yaw is 1.7 cm sideways
    # here the arrival error is the odometry drift of a whole round trip: the chapter's
    # 10 cm holds, 5 cm not over 100 trips even with perfect fixes (6.0 cm, see the report)
    assert fixed.max_error <= 0.10
    assert fixed.mean_error <= 0.025
    assert drift.max_error > 2 * fixed.max_error            # odometry alone drifts away


@pytest.mark.slow
def test_shuttle_with_fixes_on_the_approach_stays_within_five_centimetres():
    # fixes also at the 3 m point and while driving to the 1 m point (2 Hz, motion blur of
    # the moving robot rendered), fused by the EKF: the 5 cm radius of the acceptance
    res = shuttle('ekf', 'approach')
    stop = shuttle('ekf')
    assert res.arrivals == TRIPS and res.fixes == TRIPS + 1
    assert res.approach_frames >= 12 * TRIPS               # 1 at 3 m + >= 5.7 s at 2 Hz
    assert res.approach_fixes >= 0.95 * res.approach_frames
    assert res.max_error <= 0.05
    assert res.max_error < stop.max_error and res.mean_error < 0.5 * stop.mean_error
