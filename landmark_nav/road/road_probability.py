"""Per-pixel probability of road from colour, texture and image position (a small learned MLP).

The chapter's criterion (eqs. 25-28) compares every pixel with the seed area only; on drives
with low kerbs and pavement of the road's grey, or overcast frames with dull colours, it
floods off the road. Here a pixel's road probability comes from a two-layer perceptron
(numpy; weights trained from labelled street frames by :mod:`landmark_nav.road.road_training`)
over features at ``FEATURE_SIZE`` (160 x 120) that survive a change of light:

* colour independent of brightness, relative to the seed area (so the model adapts to each
  frame's road and light): log chromaticities ``log(R/G)``, ``log(B/G)`` (Finlayson et al.'s
  log-chromaticity; a change of illuminant intensity cancels) and log intensity minus the
  seed's median, the eq. 27 Mahalanobis distance to the seed's chromaticity (log1p), and the
  HSV saturation ``(max - min) / max``;
* texture: local energy of the log-intensity gradient (Sobel, box-averaged over 3 x 3 and
  9 x 9 px) and the local standard deviation of log intensity (9 x 9);
* context: the box-averaged (15 x 15 and 31 x 31 px) log chromaticity and log intensity
  relative to the seed's, and the gradient energy over 15 x 15 px;
* position: image row and column as fractions, and the row distance to the seed band
  (the road is a ground plane below the horizon, widening toward the camera).

No feature is an absolute colour or brightness: trained on sunny drives, such features
misled the model on an overcast one.

Features are standardised with the training mean and standard deviation stored in the model.
"""

from dataclasses import dataclass
import functools
from pathlib import Path
from typing import Optional, Union

import cv2
import numpy as np

#: Size (columns, rows) at which the features and probabilities are computed.
FEATURE_SIZE = (160, 120)

#: Names of the feature channels, in order.
FEATURE_NAMES = (
    'd_log_rg', 'd_log_bg', 'd_log_intensity', 'seed_mahalanobis', 'saturation',
    'grad_energy_3', 'grad_energy_9', 'grad_energy_15', 'log_intensity_std_9',
    'ctx15_d_log_rg', 'ctx15_d_log_bg', 'ctx15_d_log_intensity',
    'ctx31_d_log_rg', 'ctx31_d_log_bg', 'ctx31_d_log_intensity',
    'row', 'column_offset', 'row_to_seed')

#: The model shipped with the package (trained on all CamVid training drives).
DEFAULT_MODEL = Path(__file__).with_name('road_model.npz')


@dataclass(frozen=True, eq=False)
class RoadModel:
    """Weights of the perceptron: standardisation, hidden layer (tanh), logistic output."""

    mean: np.ndarray          # (F,) feature mean
    scale: np.ndarray         # (F,) feature standard deviation
    w1: np.ndarray            # (F, H)
    b1: np.ndarray            # (H,)
    w2: np.ndarray            # (H,)
    b2: float

    def __post_init__(self) -> None:
        """Check the shapes against :data:`FEATURE_NAMES`."""
        f = len(FEATURE_NAMES)
        h = np.shape(self.b1)[0] if np.ndim(self.b1) == 1 else -1
        shapes = {'mean': (f,), 'scale': (f,), 'w1': (f, h), 'b1': (h,), 'w2': (h,)}
        for name, shape in shapes.items():
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f'road model {name} has shape {np.shape(getattr(self, name))}'
                                 f'; expected {shape} ({f} features)')
        if not np.all(np.asarray(self.scale) > 0):
            raise ValueError('road model scale must be > 0')

    def save(self, path: Union[str, Path]) -> Path:
        """Write the weights (float32) to an ``.npz`` file."""
        return write_weights(path, {k: getattr(self, k)
                                    for k in ('mean', 'scale', 'w1', 'b1', 'w2', 'b2')})

    @classmethod
    def load(cls, path: Union[str, Path] = DEFAULT_MODEL) -> 'RoadModel':
        """Read a model written by :meth:`save`.

        Raises:
            FileNotFoundError: No such file.
            ValueError: The file's features differ from :data:`FEATURE_NAMES`.
        """
        z = read_weights(path, 'train-road-outline')
        return cls(z['mean'], z['scale'], z['w1'], z['b1'], z['w2'], float(z['b2']))

    def predict(self, features: np.ndarray) -> np.ndarray:
        """Road probability of (..., F) features."""
        f = np.asarray(features)
        if f.ndim >= 3 and f.flags.c_contiguous:
            # whole image rows against the mean and scale repeated along them (numpy's
            # broadcast of an (F,) vector loops over F values at a time)
            n = f.shape[-2]
            x = f.reshape(-1, n * f.shape[-1]) - np.tile(self.mean, n)
            x /= np.tile(self.scale, n)
            x = x.reshape(f.shape)
        else:
            x = (f - self.mean) / self.scale
        hidden = add_per_channel(x @ self.w1, self.b1)
        z = np.tanh(hidden, out=hidden) @ self.w2 + self.b2
        return 1.0 / (1.0 + np.exp(-np.clip(z, -30.0, 30.0)))


def add_per_channel(y: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Add a (C,) vector to a C-contiguous (..., W, C) array in place; return the array.

    Whole rows of W * C values against ``v`` repeated W times: the same sums as ``y += v``,
    whose broadcast loops over C values at a time.
    """
    if y.ndim < 2:
        y += v
        return y
    rows = y.reshape(-1, y.shape[-2] * y.shape[-1])
    rows += np.tile(v, y.shape[-2])
    return y


def write_weights(path: Union[str, Path], arrays: dict) -> Path:
    """Write float32 arrays and :data:`FEATURE_NAMES` to an ``.npz`` file."""
    path = Path(path)
    np.savez_compressed(path, features=np.array(FEATURE_NAMES),
                        **{k: np.asarray(v, np.float32) for k, v in arrays.items()})
    return path


def read_weights(path: Union[str, Path], command: str) -> dict:
    """Read the arrays of :func:`write_weights` (float32), checking the feature names.

    Raises:
        FileNotFoundError: No such file.
        ValueError: The file's features differ from :data:`FEATURE_NAMES` (naming the
            ``landmark_nav`` command that retrains it).
    """
    with np.load(Path(path)) as z:
        names = tuple(str(n) for n in z['features'])
        if names != FEATURE_NAMES:
            raise ValueError(f'{path}: road model features {names} differ from '
                             f'{FEATURE_NAMES}; retrain it (landmark_nav {command})')
        return {k: z[k].astype(np.float32) for k in z.files if k != 'features'}


@functools.lru_cache(maxsize=None)
def default_model() -> RoadModel:
    """Return the packaged model (loaded once)."""
    return RoadModel.load(DEFAULT_MODEL)


def _box(img: np.ndarray, k: int) -> np.ndarray:
    return cv2.blur(img, (k, k), borderType=cv2.BORDER_REFLECT)


def pixel_features(rgb: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Return the (120, 160, F) float32 features of an image and its seed area.

    Args:
        rgb: (H, W, 3) uint8 RGB image (any size; resampled to :data:`FEATURE_SIZE`).
        seed: (H, W) bool seed area, or already (120, 160); must not be empty there.
    """
    small = cv2.resize(rgb, FEATURE_SIZE, interpolation=cv2.INTER_AREA)
    if seed.shape != (FEATURE_SIZE[1], FEATURE_SIZE[0]):
        # area resampling: a thin seed band keeps every pixel it touches
        seed = cv2.resize(seed.astype(np.float32), FEATURE_SIZE,
                          interpolation=cv2.INTER_AREA) > 0
    if not seed.any():
        raise ValueError('road features need a non-empty seed area')
    # one plane per colour (numpy's reductions over a last axis of 3 are slow); the sum of
    # three integer grey levels is exact in any order, so the mean is bit for bit numpy's
    r, g, b = (c.astype(np.float32) + 1.0 for c in cv2.split(small))
    log_i = np.log((r + g + b) / 3)
    lrg = np.log(r / g)
    lbg = np.log(b / g)
    mx = np.maximum(np.maximum(r, g), b)
    sat = (mx - np.minimum(np.minimum(r, g), b)) / mx
    s_i, s_rg, s_bg = (float(np.median(a[seed])) for a in (log_i, lrg, lbg))
    # eq. 27's Mahalanobis distance to the seed, here on the log chromaticities
    c = np.stack([lrg[seed], lbg[seed]], axis=1).astype(np.float64)
    q = np.cov(c.T) + 1e-4 * np.eye(2) if len(c) > 2 else 1e-2 * np.eye(2)
    qi = np.linalg.inv(q).astype(np.float32)
    d0, d1 = lrg - float(c[:, 0].mean()), lbg - float(c[:, 1].mean())
    m2 = qi[0, 0] * d0 * d0 + 2.0 * qi[0, 1] * d0 * d1 + qi[1, 1] * d1 * d1
    gx = cv2.Sobel(log_i, cv2.CV_32F, 1, 0, ksize=3, scale=1.0 / 8.0)
    gy = cv2.Sobel(log_i, cv2.CV_32F, 0, 1, ksize=3, scale=1.0 / 8.0)
    g2 = gx * gx + gy * gy
    li_mean = _box(log_i, 9)
    li_std = np.sqrt(np.maximum(_box(log_i * log_i, 9) - li_mean * li_mean, 0.0))
    h, w = log_i.shape
    rows = np.repeat(((np.arange(h, dtype=np.float32) + 0.5) / h)[:, None], w, axis=1)
    cols = np.broadcast_to(((np.arange(w, dtype=np.float32) + 0.5) / w)[None, :], (h, w))
    seed_rows, seed_cols = np.nonzero(seed)
    seed_row = (float(np.median(seed_rows)) + 0.5) / h
    seed_col = (float(np.median(seed_cols)) + 0.5) / w
    d_rg, d_bg, d_i = lrg - s_rg, lbg - s_bg, log_i - s_i
    channels = (
        d_rg, d_bg, d_i, np.log1p(m2), sat,
        np.log1p(1e3 * _box(g2, 3)), np.log1p(1e3 * _box(g2, 9)),
        np.log1p(1e3 * _box(g2, 15)), li_std,
        _box(d_rg, 15), _box(d_bg, 15), _box(d_i, 15),
        _box(d_rg, 31), _box(d_bg, 31), _box(d_i, 31),
        rows, np.abs(cols - seed_col), seed_row - rows)
    # the planes interleaved (all float32): OpenCV's merge is about 4 x np.stack's speed
    return cv2.merge(channels)


def road_probability(rgb: np.ndarray, seed: np.ndarray,
                     model: Optional[RoadModel] = None) -> np.ndarray:
    """Return the (120, 160) float32 probability that each pixel is road.

    ``model``: the packaged perceptron by default, or any model with its ``predict`` on
    (120, 160, F) features (:class:`landmark_nav.road.road_cnn.RoadCNN`).
    """
    model = default_model() if model is None else model
    return model.predict(pixel_features(rgb, seed)).astype(np.float32)
