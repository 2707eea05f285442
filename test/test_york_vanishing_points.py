"""Vanishing points on real photographs: the York Urban training images (51).

Acceptance (issue: corridor follower, "Real images"): for the ground-truth direction closest
to the optical axis, the detected VP within 2 deg on >= 90 % of the images and a median
<= 1 deg; the Manhattan extension's median over all three directions <= 1.3 deg.

``VPParams.sigma_px = 0.6`` is the end-point noise measured once on every third training
image (a Gaussian + uniform mixture fitted to the z-scores of detected segments against the
true directions: 0.55 px for the segmented Hough and LSD inputs, 0.64 px for HoughLinesP);
``VPParams.sigma_angle_deg = 0.38`` is fitted on all 51 images (maximum likelihood,
``python benchmarks/bench_vanishing_points.py --noise``), so the figures below are
in-sample for it. Held out (the noise fitted per fold on the other four fifths of the
images, ``... --confidence``) the segmented Hough figures are 49/51, median 0.33 and
all-three median 0.67, inside the same bounds. Measured with the defaults
(``python benchmarks/bench_vanishing_points.py --repeat 1``), 640 x 480, in-sample:

=================  ======  ==========  ===============
input              median  <= 2 deg    all-three median
=================  ======  ==========  ===============
segmented Hough    0.32    49/51       0.64
LSD                0.36    46/51       0.54
HoughLinesP        0.75    37/51       1.45
=================  ======  ==========  ===============

The bounds below are these figures with a margin of one image for the fractions and about
a third for the medians (the errors of neighbouring ranks, so one changed image cannot
cross them).
"""

from dataclasses import replace

from landmark_nav.corridor.vanishing_point import consistency, VPParams
from landmark_nav.evaluation.vanishing_points import (accuracy_summary, angular_error_deg,
                                                      confidence_samples,
                                                      cross_validate_noise, evaluate_york,
                                                      fit_segment_noise, image_folds,
                                                      load_york_urban,
                                                      matched_errors, segment_noise,
                                                      summarize, YORK_FLIP, YORK_K)
from landmark_nav.testing import shared_data
import numpy as np
import pytest
import tiny_logs


@pytest.fixture(scope='module')
def york():
    """Return the York Urban training folder (skips when the data is not there)."""
    return shared_data('york_urban_train')


def test_ground_truth_convention(york):
    items = load_york_urban(york)
    assert len(items) == 51
    z_ok, z_flip = [], []
    for it in items:
        for k in range(3):
            seg = it.lines[it.association == k]
            if len(seg):
                z_ok.append(np.abs(consistency(seg, YORK_K @ it.directions[:, k])))
                flipped = YORK_FLIP @ it.directions[:, k]
                z_flip.append(np.abs(consistency(seg, YORK_K @ flipped)))
    # hand-labelled segments pass through their VP (1 px end-point noise: measured median
    # |z| 0.22); without the README's y flip they do not (measured 2.83)
    assert np.median(np.concatenate(z_ok)) < 0.3
    assert np.median(np.concatenate(z_flip)) > 2.0


def test_matched_errors():
    truth = np.eye(3)
    det = np.column_stack([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    np.testing.assert_allclose(matched_errors(det, truth), [0.0, 0.0, 90.0])
    assert angular_error_deg(np.array([1.0, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0])) == 0.0
    assert angular_error_deg(np.array([1.0, 0.0, 0.0]),
                             np.array([1.0, 1.0, 0.0])) == pytest.approx(45.0)


def test_bad_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match='no \\*_gt.npz'):
        load_york_urban(tmp_path)
    np.savez(tmp_path / 'A_gt.npz', vp=np.eye(3), lines=np.zeros((0, 4)),
             vp_association=np.zeros(0))
    with pytest.raises(FileNotFoundError, match='A.jpg is missing'):
        load_york_urban(tmp_path)
    (tmp_path / 'A.jpg').write_bytes(b'')
    np.savez(tmp_path / 'A_gt.npz', vp=np.eye(3), lines=np.zeros((0, 4)))
    with pytest.raises(ValueError, match="A_gt.npz: missing key 'vp_association'"):
        load_york_urban(tmp_path)


def test_empty_inputs_are_refused_by_name():
    # no residual (or only non-finite ones) fits no noise: an error, not the start values
    with pytest.raises(ValueError, match='fit_segment_noise: 0 finite residuals of 0'):
        fit_segment_noise(np.zeros(0), np.zeros(0), np.zeros(0))
    nan = np.full(3, np.nan)
    with pytest.raises(ValueError, match='1 finite residuals of 3'):
        fit_segment_noise(np.array([0.1, 0.2, 0.3]), np.array([1.0, np.nan, 1.0]),
                          np.array([1.0, 1.0, np.nan]))
    with pytest.raises(ValueError, match='0 finite residuals of 3'):
        fit_segment_noise(nan, nan, nan)
    with pytest.raises(ValueError, match='no axis direction among 0 held-out'):
        accuracy_summary([])


@pytest.mark.slow
def test_segmented_hough_meets_the_acceptance(york):
    s = summarize(evaluate_york(york, 'segmented_hough', 'manhattan'))
    assert s['images'] == 51
    assert s['axis_within_2deg'] >= 48 / 51          # measured 49/51 (the acceptance: 90 %)
    assert s['axis_median'] <= 0.4                   # measured 0.32 (acceptance: 1 deg)
    assert s['all_median'] <= 0.75                   # measured 0.64 (acceptance: 1.3 deg)


@pytest.mark.slow
def test_lsd_input(york):
    s = summarize(evaluate_york(york, 'lsd', 'manhattan'))
    assert s['axis_within_2deg'] >= 45 / 51          # measured 46/51
    assert s['axis_median'] <= 0.45                  # measured 0.36
    assert s['all_median'] <= 0.65                   # measured 0.54


@pytest.mark.slow
def test_the_chapter_method_alone_is_far_worse_on_outdoor_images(york):
    # the chapter's image-plane clustering assumes a corridor VP near the image centre;
    # in York Urban the axis direction is often 30-60 deg off axis (measured median 17.9)
    s = summarize(evaluate_york(york, 'segmented_hough', 'chapter'))
    assert s['axis_median'] > 5.0


def test_held_out_noise_is_fitted_without_the_fold(tmp_path):
    # 4 synthetic images in 3 folds (0 and 3 together); the odd ones' true axis direction is
    # 5 deg off, so the confidence model has both sides of 2 deg in every training set
    items = load_york_urban(tiny_logs.write_york(tmp_path, images=4, off_deg=5.0))
    held, cals, noises = cross_validate_noise(items, (1.0,), folds=3)
    assert image_folds([it.name for it in items], 3) == {
        'T000': 0, 'T001': 1, 'T002': 2, 'T003': 0}
    assert len(cals) == len(noises) == 3 and len(held) == 4 * 3
    f = 1                                                     # trained on T000, T002, T003
    train = [it for it in items if it.name != 'T001']
    sp, sa, kept = segment_noise(train, 1.0, VPParams(sigma_angle_deg=0.0))
    assert (noises[f][1.0].sigma_px, noises[f][1.0].sigma_angle_deg,
            noises[f][1.0].segments) == (sp, sa, kept)
    ref = confidence_samples(items[1], 1.0, vp_params=replace(VPParams(), sigma_px=sp,
                                                              sigma_angle_deg=sa))
    assert [h.sample for h in held if h.fold == f] == ref
    assert sum(h.sample.true_axis for h in held) == 4
