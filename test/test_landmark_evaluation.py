"""Acceptance figures of the landmark detector on rendered data (visual navigation §2.3).

The same functions run the full-size statistics from the command line
(``python -m landmark_nav.evaluation.vision``). Sizes here: the 2000 reads and 500 frames the
issue names; Table 1 with 25 instead of 100 frames per turn and the shuttle with 20 (fixes
at the stops) and 40 (fixes also on the approach) instead of 100 round trips (the full runs
are reported by the tool).
"""

from landmark_nav.evaluation.vision import (detection_vs_size, false_detections, repeatability,
                                            shuttle)
import pytest


@pytest.mark.slow
def test_table2_detection_from_five_block_pixels_and_2000_error_free_reads():
    rows = detection_vs_size(block_pixels=(5.0, 6.0, 8.0), frames=223, seed=11)
    reads = sum(r.detected for r in rows)
    assert reads >= 2000
    for r in rows:   # every rotation (0, 22.5, 45 deg) and size >= 5 px per block
        assert r.p_detect >= 0.95, r
    assert sum(r.wrong for r in rows) == 0                   # no read to a wrong code
    assert sum(r.correct for r in rows) >= 0.999 * reads


@pytest.mark.slow
def test_no_false_detections_in_500_landmark_free_frames():
    views = false_detections(frames=300, seed=12, source='views')
    scattered = false_detections(frames=200, seed=13, source='scattered')
    for res in (views, scattered):
        assert res.false_detections == 0, res
        # the distractors did produce landmark-like frames that the code step rejected
        assert res.frame_candidates > res.frames
        assert set(res.distractors) == {'checkerboard', 'grid', 'text', 'tiles', 'poster'}


@pytest.mark.slow
@pytest.mark.parametrize('distance', [1.0, 2.2])
def test_table1_repeatability_and_accuracy(distance):
    rows = repeatability(distance=distance, frames=25, seed=14)
    for r in rows:
        # at 60 deg the foreshortened blocks (about 4.5 px) are near the small-cell rule;
        # the chapter's Table 1 has 24 samples of 100 there
        assert r.detected >= (r.frames if r.turn_deg < 60 else 0.9 * r.frames), r
        assert r.sigma_xy <= 0.0025                          # position sigma <= 2.5 mm
        assert r.max_position_error <= 0.02                  # absolute error <= 2 cm
        assert r.max_angle_error <= 1.0, r                   # angle errors <= 1 deg, per frame
    # the Gauss-Newton pose against cv2.solvePnP (IPPE and ITERATIVE, unweighted) on the
    # same corners: angles at least as accurate (much more head-on than IPPE), positions
    # equal: all carry the same sub-millimetre corner bias, their RMS differ by less than
    # 0.1 mm (exact figures in the report)

    def total(name):
        return sum(getattr(r, name) ** 2 for r in rows) ** 0.5

    assert total('rms_angle_gn') <= total('rms_angle_ippe')
    assert total('rms_angle_gn') <= total('rms_angle_iterative')
    assert total('rms_position_gn') <= total('rms_position_ippe') + 1e-4
    assert total('rms_position_gn') <= total('rms_position_iterative') + 1e-4


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
