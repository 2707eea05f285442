"""Fit the road-probability perceptron (:class:`landmark_nav.road.road_probability.RoadModel`).

Logistic loss (cross-entropy of the sigmoid output), one tanh hidden layer, mini-batch Adam
(Kingma and Ba 2015, Algorithm 1) with a small L2 weight penalty; deterministic for a given
random seed. Pure numpy.
"""

from typing import Optional

from landmark_nav.road.road_probability import RoadModel
import numpy as np


def fit_road_model(x: np.ndarray, y: np.ndarray, hidden: int = 16, epochs: int = 12,
                   batch: int = 2048, rate: float = 3e-3, l2: float = 1e-4,
                   seed: int = 0, weights: Optional[np.ndarray] = None) -> RoadModel:
    """Fit the perceptron to features ``x`` (N, F) and labels ``y`` (N,) in {0, 1}.

    ``weights`` (N,) optionally weighs each sample's loss (e.g. to balance drives).

    Raises:
        ValueError: Shapes disagree, too few samples, or a label is not 0 / 1.
    """
    x = np.asarray(x, np.float32)
    y = np.asarray(y, np.float32)
    if x.ndim != 2 or y.shape != (x.shape[0],) or x.shape[0] < 10:
        raise ValueError(f'road model fit needs (N, F) features and (N,) labels, N >= 10; '
                         f'got {x.shape} and {y.shape}')
    if not np.all((y == 0) | (y == 1)):
        raise ValueError('road model labels must be 0 or 1')
    wts = np.ones(len(y), np.float32) if weights is None else np.asarray(weights, np.float32)
    wts = wts / wts.mean()
    rng = np.random.default_rng(seed)
    mean = x.mean(axis=0)
    scale = x.std(axis=0)
    scale[scale < 1e-6] = 1.0
    xs = (x - mean) / scale
    f = x.shape[1]
    params = [rng.normal(0.0, 1.0 / np.sqrt(f), (f, hidden)).astype(np.float32),
              np.zeros(hidden, np.float32),
              rng.normal(0.0, 1.0 / np.sqrt(hidden), hidden).astype(np.float32),
              np.zeros(1, np.float32)]
    m = [np.zeros_like(p) for p in params]
    v = [np.zeros_like(p) for p in params]
    b1, b2, eps = 0.9, 0.999, 1e-8
    step = 0
    for _ in range(epochs):
        order = rng.permutation(len(y))
        for start in range(0, len(y), batch):
            idx = order[start:start + batch]
            xb, yb, wb = xs[idx], y[idx], wts[idx]
            w1, c1, w2, c2 = params
            hid = np.tanh(xb @ w1 + c1)
            p = 1.0 / (1.0 + np.exp(-np.clip(hid @ w2 + c2[0], -30.0, 30.0)))
            dz = wb * (p - yb) / len(idx)          # d(mean cross-entropy)/d(logit)
            dh = np.outer(dz, w2) * (1.0 - hid * hid)
            grads = [xb.T @ dh + l2 * w1, dh.sum(axis=0), hid.T @ dz + l2 * w2,
                     np.array([dz.sum()], np.float32)]
            step += 1
            for i, g in enumerate(grads):              # Adam (Algorithm 1)
                m[i] = b1 * m[i] + (1.0 - b1) * g
                v[i] = b2 * v[i] + (1.0 - b2) * g * g
                mh = m[i] / (1.0 - b1 ** step)
                vh = v[i] / (1.0 - b2 ** step)
                params[i] = (params[i] - rate * mh / (np.sqrt(vh) + eps)).astype(np.float32)
    w1, c1, w2, c2 = params
    return RoadModel(mean.astype(np.float32), scale.astype(np.float32), w1, c1, w2,
                     float(c2[0]))
