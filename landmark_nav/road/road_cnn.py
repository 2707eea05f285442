"""Road probability from a small fully convolutional network that sees the context (numpy).

The per-pixel perceptron of :mod:`landmark_nav.road.road_probability` judges each pixel from
its own features and box averages around it; held out on an overcast drive it cannot tell
grey pavement beyond a low kerb, or a dark car, from grey road. A segmentation network
decides from the layout around a pixel instead (Long et al. 2015, fully convolutional
networks; Ronneberger et al. 2015, U-Net skip connections; Yu and Koltun 2016, dilated
convolutions for context without losing resolution). Here a tiny one, on the same 18
illumination-robust feature planes at ``FEATURE_SIZE`` (160 x 120), which include the image
row (the ground-plane prior) and colour relative to the seed:

=========  ==========================================  ===========  =================
layer      operation                                   output       receptive field
=========  ==========================================  ===========  =================
``e1``     3 x 3 conv, stride 2, ReLU                  16 @ 60x80   3 px
``e2``     3 x 3 conv, stride 2, ReLU                  32 @ 30x40   7 px
``c1..c3`` 3 x 3 conv, dilation 2, 4, 8, ReLU          32 @ 30x40   119 px
``d1``     bilinear x2, concat ``e1``, 1 x 1, ReLU     16 @ 60x80   119 px
``h``      bilinear x2, concat the input, 1 x 1, ReLU  16 @ 120x160
``out``    1 x 1 conv, logistic                        1 @ 120x160
=========  ==========================================  ===========  =================

(receptive field in 160 x 120 pixels: 119 px is three quarters of the image width). The last
two layers see each pixel's own features next to the context, so borders stay at the
feature resolution. About 37 000 weights, trained with PyTorch by
:mod:`landmark_nav.road.road_cnn_training` (an optional extra) and shipped as float32 numpy
arrays; the forward pass here needs numpy only (and OpenCV's bilinear resize): every 3 x 3
convolution is an im2col and one matrix product, the im2col a single copy of sliding windows
over the rows (a row's taps are k * C contiguous values at dilation 1); a 1 x 1 layer after an
upsampling mixes its coarse input before upsampling it (both are linear) and adds its skip
input's share after, without concatenating. Zero padding and bilinear upsampling with
half-pixel centres (PyTorch's ``align_corners=False``) as in training. The CNN criterion
(features, perceptron, this network and the outline) takes 1.0-1.3 x the OpenCV reference
of ``python benchmarks/bench_road.py --scans 60 --frames 20`` per 480 x 360 frame, the
network itself 0.4-0.9 x (docs/road_following.md, Speed).
"""

from dataclasses import dataclass
import functools
from pathlib import Path
from typing import Dict, Sequence, Union

import cv2
from landmark_nav.road.road_probability import (add_per_channel, default_model, FEATURE_NAMES,
                                                read_weights, RoadModel, write_weights)
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

#: The CNN shipped with the package (trained on all CamVid training drives).
DEFAULT_CNN = Path(__file__).with_name('road_cnn.npz')

#: Layers: name -> (kernel size, stride, dilation); weights ``{name}.w`` (out, in, k, k) and
#: ``{name}.b`` (out,), PyTorch's layout.
LAYERS = {'e1': (3, 2, 1), 'e2': (3, 2, 1), 'c1': (3, 1, 2), 'c2': (3, 1, 4),
          'c3': (3, 1, 8), 'd1': (1, 1, 1), 'h': (1, 1, 1), 'out': (1, 1, 1)}


def conv2d(x: np.ndarray, w: np.ndarray, b: np.ndarray, stride: int = 1,
           dilation: int = 1, padded: bool = False) -> np.ndarray:
    """Zero-padded ('same' for stride 1) 2-D convolution of (H, W, C) by (O, C, k, k) weights.

    Cross-correlation as in PyTorch's ``Conv2d`` with ``padding = dilation * (k - 1) / 2``;
    returns (ceil(H / stride), ceil(W / stride), O) float32. ``padded``: ``x`` already has
    that zero border (H and W include it).
    """
    o, c, k, _ = w.shape
    if k == 1 and stride == 1:
        return x @ w[:, :, 0, 0].T + b
    pad = dilation * (k // 2)
    if pad and not padded:
        x = np.pad(x, ((pad, pad), (pad, pad), (0, 0)))
    span = dilation * (k - 1) + 1
    h = (x.shape[0] - span) // stride + 1
    w_ = (x.shape[1] - span) // stride + 1
    # im2col: (H', W', k * k * C) in (ky, kx, c) order, from windows of the rows seen as
    # (H, W * C); one copy, in which numpy moves k * C contiguous values at a time when the
    # taps of a row touch (dilation 1) and C values otherwise
    win = sliding_window_view(x.reshape(x.shape[0], -1), (span, span * c))
    win = win[:(h - 1) * stride + 1:stride, :(w_ - 1) * stride * c + 1:stride * c]
    cols = win.reshape(h, w_, span, span, c)[:, :, ::dilation, ::dilation]
    out = cols.reshape(h * w_, -1) @ w.transpose(2, 3, 1, 0).reshape(-1, o)
    return add_per_channel(out.reshape(h, w_, o), b)


def upsample2(x: np.ndarray) -> np.ndarray:
    """Bilinear x2 upsampling of (H, W, C) with half-pixel centres (``align_corners=False``).

    OpenCV's ``INTER_LINEAR`` samples at half-pixel centres too: output 2i sits at input
    i - 1/4 (weights 3/4, 1/4), the border replicated.
    """
    h, w = x.shape[:2]
    return cv2.resize(np.ascontiguousarray(x, np.float32), (2 * w, 2 * h),
                      interpolation=cv2.INTER_LINEAR).reshape(2 * h, 2 * w, -1)


@dataclass(frozen=True, eq=False)
class RoadCNN:
    """Weights of the network: input standardisation and the layers of :data:`LAYERS`."""

    mean: np.ndarray                  # (F,) feature mean
    scale: np.ndarray                 # (F,) feature standard deviation
    weights: Dict[str, np.ndarray]    # '{layer}.w', '{layer}.b'

    def __post_init__(self) -> None:
        """Check the shapes: input channels of every layer, output of one channel."""
        f = len(FEATURE_NAMES)
        if np.shape(self.mean) != (f,) or np.shape(self.scale) != (f,):
            raise ValueError(f'road CNN mean / scale must have shape ({f},)')
        if not np.all(np.asarray(self.scale) > 0):
            raise ValueError('road CNN scale must be > 0')
        missing = [f'{n}.{p}' for n in LAYERS for p in 'wb' if f'{n}.{p}' not in self.weights]
        if missing:
            raise ValueError(f'road CNN lacks weights {missing}')
        width = {}
        inputs = {'e1': f, 'e2': 'e1', 'c1': 'e2', 'c2': 'c1', 'c3': 'c2',
                  'd1': ('c3', 'e1'), 'h': ('d1', f), 'out': 'h'}
        for name, (k, _, _) in LAYERS.items():
            w = self.weights[f'{name}.w']
            src = inputs[name]
            src = src if isinstance(src, tuple) else (src,)
            c_in = sum(s if isinstance(s, int) else width[s] for s in src)
            if w.ndim != 4 or w.shape[1:] != (c_in, k, k) or \
                    self.weights[f'{name}.b'].shape != (w.shape[0],):
                raise ValueError(f'road CNN layer {name} has weights {w.shape}; expected '
                                 f'(out, {c_in}, {k}, {k}) and a bias per output')
            width[name] = w.shape[0]
        if width['out'] != 1:
            raise ValueError(f'road CNN output has {width["out"]} channels; expected 1')

    @property
    def size(self) -> int:
        """Number of weights and biases."""
        return int(sum(v.size for v in self.weights.values()))

    def save(self, path: Union[str, Path]) -> Path:
        """Write the weights (float32) to an ``.npz`` file."""
        return write_weights(path, {'mean': self.mean, 'scale': self.scale, **self.weights})

    @classmethod
    def load(cls, path: Union[str, Path] = DEFAULT_CNN) -> 'RoadCNN':
        """Read a network written by :meth:`save`.

        Raises:
            FileNotFoundError: No such file.
            ValueError: The file's features differ from :data:`FEATURE_NAMES`.
        """
        z = read_weights(path, 'train-road-outline --kind cnn')
        return cls(z['mean'], z['scale'], {k: v for k, v in z.items() if '.' in k})

    def logits(self, features: np.ndarray) -> np.ndarray:
        """Road logit of (H, W, F) features; H and W multiples of 4."""
        h, w = features.shape[:2]
        if features.ndim != 3 or h % 4 or w % 4:
            raise ValueError(f'road CNN needs (H, W, F) features with H, W multiples of 4; '
                             f'got {features.shape}')
        p = self.weights
        f = features.shape[2]
        # standardised features inside a zero border of one pixel (e1's padding); whole rows
        # against the mean and scale repeated along them (numpy's broadcast of an (F,)
        # vector loops over F values at a time)
        xp = np.zeros((h + 2, w + 2, f), np.float32)
        rows = xp[1:-1].reshape(h, -1)[:, f:-f]
        np.subtract(features.reshape(h, -1), np.tile(self.mean, w), out=rows,
                    dtype=np.float32)
        rows *= np.tile(1.0 / self.scale, w)
        x = xp[1:-1, 1:-1]

        def layer(name: str, a: np.ndarray, relu: bool = True, padded: bool = False):
            _, stride, dilation = LAYERS[name]
            y = conv2d(a, p[f'{name}.w'], p[f'{name}.b'], stride, dilation, padded)
            return np.maximum(y, 0.0, out=y) if relu else y
        e1 = layer('e1', xp, padded=True)
        y = layer('e2', e1)
        for name in ('c1', 'c2', 'c3'):
            y = layer(name, y)
        # 1 x 1 layers on [upsampled coarse, skip]: the upsampling is linear, so the coarse
        # part is mixed before it is upsampled (fewer channels to upsample, no concatenation)
        for name, skip in (('d1', e1), ('h', x)):
            w = p[f'{name}.w'][:, :, 0, 0]
            coarse = w.shape[1] - skip.shape[2]
            y = upsample2(y @ w[:, :coarse].T)
            y += skip @ w[:, coarse:].T
            np.maximum(add_per_channel(y, p[f'{name}.b']), 0.0, out=y)
        return layer('out', y, relu=False)[..., 0]

    def predict(self, features: np.ndarray) -> np.ndarray:
        """Road probability of (H, W, F) features (the same interface as ``RoadModel``)."""
        z = self.logits(features)
        return 1.0 / (1.0 + np.exp(-np.clip(z, -30.0, 30.0)))


@dataclass(frozen=True, eq=False)
class MeanProbability:
    """Road probability as the mean of several models' (an ensemble of unlike models).

    The criterion of ``outline_method: cnn`` averages the network's probability with the
    perceptron's: held out (leave one drive out) the mean scored above the network alone on
    the overcast drive and with fewer failures on 0016E5 (docs/road_following.md).
    """

    models: Sequence

    def predict(self, features: np.ndarray) -> np.ndarray:
        """Mean road probability of (H, W, F) features."""
        total = self.models[0].predict(features)
        for m in self.models[1:]:
            total = total + m.predict(features)
        return total / len(self.models)


#: Anything with a ``predict(features) -> probability`` the outline accepts.
ProbabilityModel = Union[RoadModel, RoadCNN, MeanProbability]


@functools.lru_cache(maxsize=None)
def default_cnn() -> RoadCNN:
    """Return the packaged network (loaded once)."""
    return RoadCNN.load(DEFAULT_CNN)


def default_cnn_criterion() -> MeanProbability:
    """Return the packaged network averaged with the packaged perceptron."""
    return MeanProbability((default_cnn(), default_model()))
