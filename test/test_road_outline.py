"""Vision road outline (road.outline, eqs. 25-28) on synthetic images and real street frames."""

from landmark_nav.evaluation.road_outline import evaluate_folder, summarize
from landmark_nav.road.outline import (band_seed, chromaticity, OutlineParams, polyline_seed,
                                       road_outline, SeedError)
from landmark_nav.testing import shared_data
import numpy as np
import pytest


def _scene(rng, marking=False, obstacle=False):
    """Return a grey road (columns 100-219) between green verges, 240 x 320, with texture."""
    img = np.empty((240, 320, 3))
    img[:] = (70, 120, 50)
    img[:, 100:220] = (105, 105, 110)
    img += rng.normal(0.0, 3.0, img.shape)
    truth = np.zeros((240, 320), bool)
    truth[:, 100:220] = True
    if marking:
        img[60:90, 156:164] = (235, 235, 230)        # a white dash: road
    if obstacle:
        img[40:80, 120:140] = (40, 35, 45)           # a dark object: not road
        truth[40:80, 120:140] = False
    return np.clip(img, 0, 255).astype(np.uint8), truth


def test_chromaticity_eq25():
    rgb = np.array([[[255, 0, 0], [10, 20, 30]]], np.uint8)
    c = chromaticity(rgb)
    np.testing.assert_allclose(c[0, 0], [256 / 258, 1 / 258], rtol=1e-6)   # +1 per channel
    np.testing.assert_allclose(c[0, 1], [11 / 63, 21 / 63], rtol=1e-6)


def test_outline_of_a_synthetic_road_with_a_marking_and_an_obstacle():
    rng = np.random.default_rng(0)
    img, truth = _scene(rng, marking=True, obstacle=True)
    seed = band_seed(img.shape, (0.86, 0.92), (0.4, 0.6))
    out = road_outline(img, seed)
    iou = np.sum(out.mask & truth) / np.sum(out.mask | truth)
    assert iou > 0.97
    assert out.mask[60:90, 156:164].all()               # the marking counts as road
    assert not out.mask[45:75, 125:135].any()           # the dark object does not
    assert out.polygon.shape[1] == 2 and len(out.polygon) >= 4
    # eqs. 27-28 at the working size: high on the road, low on the verge / at the border
    assert out.p_c[200, 160] > 0.9 and out.p_c[200, 30] < 0.05
    assert out.p_e[200, 160] > 0.9 and out.p_e[200, 100] < 0.7     # 0.66 at this step


def test_bad_input():
    rng = np.random.default_rng(1)
    img, _ = _scene(rng)
    with pytest.raises(SeedError, match='seed area has 0 pixels'):
        road_outline(img, np.zeros(img.shape[:2], bool))
    with pytest.raises(ValueError, match='RGB image'):
        road_outline(img[..., 0], np.ones(img.shape[:2], bool))
    with pytest.raises(ValueError, match='chroma'):
        OutlineParams(chroma='hsv')
    assert polyline_seed(img.shape, np.array([[-50.0, -5.0], [-10.0, -20.0]]), 5) is None
    seed = polyline_seed(img.shape, np.array([[10.0, 200.0], [300.0, 210.0]]), 5)
    assert seed[205, 160] and not seed[100, 160]


@pytest.mark.slow
def test_real_street_frames_camvid():
    """Acceptance on 101 real CamVid frames; figures measured: median IoU 0.857, 0 failures.

    ``landmark_nav evaluate-road-outline ../shared/data/camvid_road``. Hard-shadow frames
    (>= 2 % of the labelled road darker than half its median): 27, median IoU 0.853.
    """
    folder = shared_data('camvid_road')
    summary = summarize(evaluate_folder(folder))
    s = summary['all']
    assert s['frames'] == 101
    assert s['iou_median'] >= 0.85
    assert s['failure_rate'] <= 0.05 and s['iou_min'] >= 0.6
    assert s['precision_median'] >= 0.96 and s['recall_median'] >= 0.86
    assert summary['hard_shadow']['frames'] == 27
    assert summary['hard_shadow']['iou_median'] >= 0.84
    assert s['seed_purity_min'] >= 0.9
