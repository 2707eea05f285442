"""Road CNN (road.road_cnn): numpy forward pass, weights file, and its PyTorch twin."""

from landmark_nav.road.road_cnn import conv2d, LAYERS, RoadCNN, upsample2
from landmark_nav.road.road_probability import FEATURE_NAMES
import numpy as np
import pytest

F = len(FEATURE_NAMES)
WIDTHS = {'e1': 4, 'e2': 5, 'c1': 5, 'c2': 5, 'c3': 5, 'd1': 3, 'h': 3, 'out': 1}


def _random_cnn(rng):
    """Return a small RoadCNN with random weights (the layer layout of :data:`LAYERS`)."""
    ins = {'e1': F, 'e2': 4, 'c1': 5, 'c2': 5, 'c3': 5, 'd1': 5 + 4, 'h': 3 + F, 'out': 3}
    weights = {}
    for name, (k, _, _) in LAYERS.items():
        weights[f'{name}.w'] = rng.normal(0, 0.3, (WIDTHS[name], ins[name], k, k)
                                          ).astype(np.float32)
        weights[f'{name}.b'] = rng.normal(0, 0.1, WIDTHS[name]).astype(np.float32)
    return RoadCNN(rng.normal(0, 1, F).astype(np.float32),
                   rng.uniform(0.5, 2, F).astype(np.float32), weights)


def test_conv2d_is_a_zero_padded_cross_correlation():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(9, 12, 2)).astype(np.float32)
    w = rng.normal(size=(3, 2, 3, 3)).astype(np.float32)
    b = np.array([0.5, -1.0, 0.0], np.float32)
    for stride, dil in ((1, 1), (2, 1), (1, 2), (1, 3)):
        pad = np.pad(x, ((dil, dil), (dil, dil), (0, 0)))
        want = np.zeros((-(-9 // stride), -(-12 // stride), 3))
        for i in range(want.shape[0]):
            for j in range(want.shape[1]):
                for o in range(3):
                    taps = pad[i * stride:i * stride + 2 * dil + 1:dil,
                               j * stride:j * stride + 2 * dil + 1:dil]       # (3, 3, C)
                    want[i, j, o] = np.sum(taps * w[o].transpose(1, 2, 0)) + b[o]
        np.testing.assert_allclose(conv2d(x, w, b, stride, dil), want, rtol=1e-5, atol=1e-5)


def test_upsample2_is_bilinear_with_half_pixel_centres():
    x = np.random.default_rng(1).normal(size=(5, 7, 16)).astype(np.float32)
    # output 2i at input i - 1/4, 2i + 1 at i + 1/4 (weights 3/4, 1/4), borders replicated
    pad = np.pad(x, ((1, 1), (1, 1), (0, 0)), mode='edge')
    rows = np.empty((10, 9, 16), np.float32)
    rows[0::2] = 0.75 * pad[1:-1] + 0.25 * pad[:-2]
    rows[1::2] = 0.75 * pad[1:-1] + 0.25 * pad[2:]
    want = np.empty((10, 14, 16), np.float32)
    want[:, 0::2] = 0.75 * rows[:, 1:-1] + 0.25 * rows[:, :-2]
    want[:, 1::2] = 0.75 * rows[:, 1:-1] + 0.25 * rows[:, 2:]
    np.testing.assert_allclose(upsample2(x), want, atol=1e-5)
    assert upsample2(x[..., :1]).shape == (10, 14, 1)


def test_cnn_save_load_and_refusals(tmp_path):
    rng = np.random.default_rng(2)
    cnn = _random_cnn(rng)
    feats = rng.normal(size=(12, 16, F)).astype(np.float32)
    p = cnn.predict(feats)
    assert p.shape == (12, 16) and np.all((p > 0) & (p < 1))
    loaded = RoadCNN.load(cnn.save(tmp_path / 'c.npz'))
    np.testing.assert_array_equal(loaded.predict(feats), p)
    with pytest.raises(ValueError, match='multiples of 4'):
        cnn.predict(feats[:10])
    bad = dict(cnn.weights)
    bad['c2.w'] = bad['c2.w'][:, :4]
    with pytest.raises(ValueError, match=r'layer c2 has weights \(5, 4, 3, 3\)'):
        RoadCNN(cnn.mean, cnn.scale, bad)
    with pytest.raises(ValueError, match='lacks weights'):
        RoadCNN(cnn.mean, cnn.scale, {k: v for k, v in cnn.weights.items() if k != 'h.b'})


def test_cnn_fit_refuses_shapes_before_needing_torch():
    """Mismatched labels are refused with the shapes named, with or without PyTorch."""
    from landmark_nav.road.road_cnn_training import fit_road_cnn
    rng = np.random.default_rng(4)
    x = rng.normal(size=(2, 8, 12, F)).astype(np.float16)
    y = rng.random((2, 8, 12)) < 0.5
    with pytest.raises(ValueError, match='labels'):
        fit_road_cnn(x, y[:1], np.ones_like(y), np.array(['a', 'b']))


def test_photometric_alteration_and_training_refusals():
    from landmark_nav.evaluation.road_cross_drive import FeatureMaps, train_cnn
    from landmark_nav.road.road_cnn_training import photometric
    rgb = np.random.default_rng(5).integers(0, 256, (12, 16, 3), dtype=np.uint8)
    a = photometric(rgb, np.random.default_rng(6))
    assert a.shape == rgb.shape and a.dtype == np.uint8 and not np.array_equal(a, rgb)
    np.testing.assert_array_equal(a, photometric(rgb, np.random.default_rng(6)))
    maps = FeatureMaps(np.zeros((2, 8, 12, F), np.float16), np.zeros((2, 8, 12), bool),
                       np.ones((2, 8, 12), bool), np.array(['0001TP', '0006R0']), ())
    with pytest.raises(ValueError, match="drive '0016E5' has no training frames"):
        train_cnn(maps, ['0016E5'])


def test_soft_dice_loss_scores_the_valid_pixels_of_each_map():
    from landmark_nav.road.road_cnn_training import soft_dice_loss
    y = np.zeros((2, 4, 6), np.float32)
    y[:, 2:] = 1.0
    valid = np.ones_like(y)
    assert soft_dice_loss(y, y, valid) == pytest.approx(0.0)
    assert soft_dice_loss(1.0 - y, y, valid) == pytest.approx(1.0)
    # half the road found in the first map: 1 - 2 * 6 / (6 + 12) = 1/3; second map perfect
    p = y.copy()
    p[0, 3] = 0.0
    assert soft_dice_loss(p, y, valid) == pytest.approx((1.0 / 3.0) / 2.0)
    valid[0, 3] = 0.0                    # the missed row not scored: both maps perfect
    assert soft_dice_loss(p, y, valid) == pytest.approx(0.0)


def test_zoom_crop_resamples_a_part_of_image_and_label_alike():
    from landmark_nav.road.road_cnn_training import zoom_crop
    rgb = np.zeros((36, 48, 3), np.uint8)
    rgb[:, :24] = 200                                  # left half bright
    label = np.where(rgb[..., 0] > 0, 3, 4).astype(np.uint8)
    same = zoom_crop(rgb, label, np.random.default_rng(0), 1.0)
    np.testing.assert_array_equal(same[0], rgb)
    np.testing.assert_array_equal(same[1], label)
    shares = set()
    for s in range(5):
        img, lab = zoom_crop(rgb, label, np.random.default_rng(s), 1.5)
        assert img.shape == rgb.shape and lab.shape == label.shape
        assert set(np.unique(lab)) <= {3, 4}           # nearest neighbour: no new classes
        # the label stays on its image: they differ at most on the one blended column
        differ = (img[..., 0] > 100) != (lab == 3)
        assert np.sum(differ.any(axis=0)) <= 1
        shares.add(float(np.mean(lab == 3)))
    assert len(shares) > 2                             # crops of other places and sizes


def _conv2d_im2col(x, w, b, stride=1, dilation=1):
    """Oracle: the k x k shifted copies of the zero-padded input side by side, one product."""
    k = w.shape[2]
    pad = dilation * (k // 2)
    x = np.pad(x, ((pad, pad), (pad, pad), (0, 0)))
    h = (x.shape[0] - dilation * (k - 1) - 1) // stride + 1
    w_ = (x.shape[1] - dilation * (k - 1) - 1) // stride + 1
    cols = np.concatenate([x[dy * dilation:dy * dilation + stride * (h - 1) + 1:stride,
                             dx * dilation:dx * dilation + stride * (w_ - 1) + 1:stride]
                           for dy in range(k) for dx in range(k)], axis=2)
    out = cols.reshape(h * w_, -1) @ w.transpose(2, 3, 1, 0).reshape(-1, w.shape[0]) + b
    return out.reshape(h, w_, w.shape[0])


def _logits_as_drawn(cnn, features):
    """Oracle: the network as drawn, each upsampled map concatenated with its skip."""
    p = cnn.weights

    def conv(name, a, relu=True):
        _, stride, dilation = LAYERS[name]
        y = _conv2d_im2col(a, p[f'{name}.w'], p[f'{name}.b'], stride, dilation)
        return np.maximum(y, 0.0) if relu else y
    x = ((features - cnn.mean) / cnn.scale).astype(np.float32)
    e1 = conv('e1', x)
    y = conv('c3', conv('c2', conv('c1', conv('e2', e1))))
    y = conv('d1', np.concatenate([upsample2(y), e1], axis=2))
    y = conv('h', np.concatenate([upsample2(y), x], axis=2))
    return conv('out', y, relu=False)[..., 0]


def test_conv2d_equals_the_im2col_oracle_bit_for_bit():
    """The windowed im2col builds the oracle's matrix: the same product, the same floats."""
    rng = np.random.default_rng(8)
    for c, stride, dil in ((18, 2, 1), (16, 2, 1), (5, 1, 1), (32, 1, 2), (7, 1, 8), (3, 2, 3)):
        x = rng.normal(size=(24, 36, c)).astype(np.float32)
        w = rng.normal(size=(6, c, 3, 3)).astype(np.float32)
        b = rng.normal(size=6).astype(np.float32)
        want = _conv2d_im2col(x, w, b, stride, dil)
        np.testing.assert_array_equal(conv2d(x, w, b, stride, dil), want)
        pad = np.pad(x, ((dil, dil), (dil, dil), (0, 0)))
        np.testing.assert_array_equal(conv2d(pad, w, b, stride, dil, padded=True), want)


@pytest.mark.parametrize('shipped', [False, True])
def test_forward_pass_equals_the_network_as_drawn(shipped):
    """The fast pass and the network as drawn differ by float32 rounding only.

    Random weights (and the shipped ones) on random features; the fast pass splits the 1 x 1
    layers and mixes their coarse part before upsampling. Largest difference seen 1.9e-6
    (shipped network, 120 x 160), a tenth of the bound.
    """
    from landmark_nav.road.road_cnn import default_cnn
    rng = np.random.default_rng(9)
    for h, w in ((12, 16), (20, 28), (120, 160)):
        cnn = default_cnn() if shipped else _random_cnn(rng)
        feats = (cnn.mean + cnn.scale * rng.normal(size=(h, w, F))).astype(np.float32)
        np.testing.assert_allclose(cnn.logits(feats), _logits_as_drawn(cnn, feats),
                                   rtol=1e-5, atol=1e-5)


def test_train_road_outline_takes_cnn_steps_as_the_benchmark_does():
    """``--cnn-steps`` as in ``bench_road.py --cross-drive``; the old ``--steps`` still read."""
    from landmark_nav.tools.cli import build_parser
    parser = build_parser()
    base = ['train-road-outline', '--kind', 'cnn', '--data', 'd', '--out', 'o.npz']
    assert parser.parse_args(base).cnn_steps is None                # CNN_STEPS
    assert parser.parse_args(base + ['--cnn-steps', '7']).cnn_steps == 7
    assert parser.parse_args(base + ['--steps', '9']).cnn_steps == 9
