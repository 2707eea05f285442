"""The shuttle of visual navigation §2.3: landmark fixes keep the robot at its goal.

20 round trips with fixes at the stops and 40 with fixes also on the approach, instead of
the chapter's 100; the full runs are reported by ``python -m
landmark_nav.evaluation.vision``, which runs the same function.
"""

from landmark_nav.evaluation.vision import shuttle
import pytest


@pytest.mark.slow
def test_shuttle_with_landmark_fixes_stays_near_the_one_metre_point():
    # the chapter's procedure: fixes only while standing at the 1 m point
    fixed = shuttle(trips=20, seed=15, correction='ekf')
    drift = shuttle(trips=20, seed=15, correction='none')
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
    trips = 40
    res = shuttle(trips=trips, seed=15, correction='ekf', procedure='approach')
    stop = shuttle(trips=trips, seed=15, correction='ekf', procedure='stop')
    assert res.arrivals == trips and res.fixes == trips + 1
    assert res.approach_frames >= 12 * trips                # 1 at 3 m + >= 5.7 s at 2 Hz
    assert res.approach_fixes >= 0.95 * res.approach_frames
    assert res.max_error <= 0.05
    assert res.max_error < stop.max_error and res.mean_error < 0.5 * stop.mean_error
