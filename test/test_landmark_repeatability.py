"""Pose repeatability and accuracy of the landmark detector on rendered data (Table 1).

Table 1 of visual navigation §2.3 with 25 instead of 100 frames per turn, at 1.0 and 2.2 m;
the full run is reported by ``python -m landmark_nav.evaluation.vision``, which runs the
same function.
"""

from landmark_nav.evaluation.vision import repeatability
import pytest


@pytest.mark.slow
# Supersampling as fine as the distance needs: at 2.2 m a head-on landmark turns by about
# 1 deg per 0.05 px of corner error, so the render's own edge error (0.01 px at 16 x 16,
# about twice that at 8 x 8) must stay small; at 1.0 m the angle is 2.2 times less
# sensitive and 8 x 8 gives the same figures (largest angle error 0.26 deg either way)
# at a quarter of the render's time.
@pytest.mark.parametrize('distance, supersample', [(1.0, 8), (2.2, 16)])
def test_table1_repeatability_and_accuracy(distance, supersample):
    rows = repeatability(distance=distance, frames=25, seed=14, supersample=supersample)
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
