"""Fit the road CNN (:class:`landmark_nav.road.road_cnn.RoadCNN`) with PyTorch (optional).

Training only: PyTorch is an optional extra (``pip install torch==2.13.0``, or the package's
``train`` extra); inference is numpy (:mod:`landmark_nav.road.road_cnn`). Binary
cross-entropy of the logistic output per pixel plus ``dice`` times the soft Dice loss
(:func:`soft_dice_loss`), unlabelled pixels weighed 0 and each drive weighed equally (frames
drawn with probability 1 / frames of their drive); mini-batch Adam
(Kingma and Ba 2015) with a cosine-decaying rate; random horizontal flips of the feature
planes (the seed band is centred, so a flipped frame is another plausible frame). The
photometric augmentation (brightness, contrast, gamma, saturation, white balance) and the
random zoom act on the image before its features are computed: :func:`photometric`,
:func:`zoom_crop`. One thread and fixed seeds:
the same data give the same weights.
"""

from typing import Dict

import cv2
from landmark_nav.road.road_cnn import LAYERS, RoadCNN
import numpy as np

TORCH_MISSING = 'training the CNN needs torch: pip install torch==2.13.0'


#: Ranges of :func:`photometric`: uniform factors (brightness, contrast, saturation, gains)
#: and exponent (gamma).
#: Wide enough to take a sunny drive to an overcast one (dark, dull, low contrast).
PHOTOMETRIC = {'brightness': (0.35, 1.4), 'contrast': (0.4, 1.3), 'gamma': (0.7, 1.8),
               'saturation': (0.2, 1.3), 'gains': (0.9, 1.1)}


def photometric(rgb: np.ndarray, rng: np.random.Generator,
                ranges: Dict[str, tuple] = PHOTOMETRIC) -> np.ndarray:
    """Return a random change of light and camera of a (H, W, 3) uint8 image.

    Per-channel gains (white balance, slight hue), saturation (blend with the grey), contrast
    about the mean, brightness and gamma, each uniform in its range of ``ranges`` (default
    :data:`PHOTOMETRIC`: brightness x [0.35, 1.4], contrast x [0.4, 1.3], gamma in [0.7, 1.8],
    saturation x [0.2, 1.3], gains x [0.9, 1.1]).
    """
    x = rgb.astype(np.float32) / 255.0
    x = x * rng.uniform(*ranges['gains'], 3).astype(np.float32)
    grey = x.mean(axis=2, keepdims=True)
    x = grey + rng.uniform(*ranges['saturation']) * (x - grey)
    x = x.mean() + rng.uniform(*ranges['contrast']) * (x - x.mean())
    x = np.clip(x * rng.uniform(*ranges['brightness']), 0.0, 1.0) ** \
        rng.uniform(*ranges['gamma'])
    return np.clip(255.0 * x + 0.5, 0, 255).astype(np.uint8)


def zoom_crop(rgb: np.ndarray, label: np.ndarray, rng: np.random.Generator,
              max_zoom: float) -> tuple:
    """Return a random zoomed-in view of an image and its label, at the image's size.

    A part of ``1 / s`` of the frame's height and width (``s`` uniform in [1, ``max_zoom``]),
    placed at random, resampled to the full size (the image bilinearly, the label by nearest
    neighbour): the road as a longer lens, a lower camera or another pitch would show it.
    """
    h, w = label.shape[:2]
    s = rng.uniform(1.0, max_zoom)
    ch, cw = int(round(h / s)), int(round(w / s))
    y0, x0 = int(rng.integers(0, h - ch + 1)), int(rng.integers(0, w - cw + 1))
    img = cv2.resize(rgb[y0:y0 + ch, x0:x0 + cw], (w, h), interpolation=cv2.INTER_LINEAR)
    lab = cv2.resize(label[y0:y0 + ch, x0:x0 + cw], (w, h), interpolation=cv2.INTER_NEAREST)
    return img, lab


def torch_module():
    """Return PyTorch (an optional extra: training only).

    Raises:
        ImportError: It is missing (:data:`TORCH_MISSING`).
    """
    try:
        import torch
    except ImportError as e:                      # pragma: no cover - depends on the extra
        raise ImportError(TORCH_MISSING) from e
    return torch


def torch_network(c_in: int, widths: Dict[str, int]):
    """Return the PyTorch twin of :class:`RoadCNN` (``widths``: channels per layer)."""
    torch = torch_module()
    nn = torch.nn
    f = nn.functional

    class Net(nn.Module):
        def __init__(self):
            super().__init__()
            ins = {'e1': c_in, 'e2': widths['e1'], 'c1': widths['e2'], 'c2': widths['c1'],
                   'c3': widths['c2'], 'd1': widths['c3'] + widths['e1'],
                   'h': widths['d1'] + c_in, 'out': widths['h']}
            self.layers = nn.ModuleDict({
                n: nn.Conv2d(ins[n], widths.get(n, 1), k, stride=s, dilation=d,
                             padding=d * (k // 2))
                for n, (k, s, d) in LAYERS.items()})

        def forward(self, x):
            L = self.layers
            up = {'scale_factor': 2, 'mode': 'bilinear', 'align_corners': False}
            e1 = f.relu(L['e1'](x))
            y = f.relu(L['e2'](e1))
            for n in ('c1', 'c2', 'c3'):
                y = f.relu(L[n](y))
            y = f.relu(L['d1'](torch.cat([f.interpolate(y, **up), e1], 1)))
            y = f.relu(L['h'](torch.cat([f.interpolate(y, **up), x], 1)))
            return L['out'](y)[:, 0]
    return Net()


WIDTHS = {'e1': 16, 'e2': 32, 'c1': 32, 'c2': 32, 'c3': 32, 'd1': 16, 'h': 16}
#: Mini-batches and soft Dice weight of the shipped network's training (``landmark_nav
#: train-road-outline --kind cnn``, the leave-one-drive-out benchmark).
STEPS = 2000
DICE = 1.0


def soft_dice_loss(p, y, valid):
    """1 - soft Dice of probabilities ``p`` against labels ``y`` over the ``valid`` pixels.

    Milletari et al. 2016 (V-Net, eq. 1): ``1 - 2 sum(p y) / (sum(p^2) + sum(y^2))`` per
    (N, H, W) map, averaged over the batch; it weighs a map's road as a whole, however few
    its pixels. Torch tensors in training; numpy arrays work alike.
    """
    dims = (1, 2)
    inter = (p * y * valid).sum(dims)
    total = (p * p * valid).sum(dims) + (y * y * valid).sum(dims)
    return (1.0 - 2.0 * inter / total.clip(min=1.0)).mean()


def export(net, mean: np.ndarray, scale: np.ndarray) -> RoadCNN:
    """Return the numpy :class:`RoadCNN` of a trained :func:`torch_network`."""
    weights = {}
    for name, layer in net.layers.items():
        weights[f'{name}.w'] = layer.weight.detach().cpu().numpy().astype(np.float32)
        weights[f'{name}.b'] = layer.bias.detach().cpu().numpy().astype(np.float32)
    return RoadCNN(np.asarray(mean, np.float32), np.asarray(scale, np.float32), weights)


def fit_road_cnn(x: np.ndarray, y: np.ndarray, valid: np.ndarray, group: np.ndarray,
                 steps: int = STEPS, batch: int = 8, rate: float = 3e-3,
                 weight_decay: float = 1e-4, seed: int = 0,
                 widths: Dict[str, int] = WIDTHS, dice: float = DICE, log=None) -> RoadCNN:
    """Fit the network to feature maps ``x`` (N, H, W, F), labels ``y`` (N, H, W) in {0, 1}.

    ``valid`` (N, H, W) bool marks the scored pixels; ``group`` (N,) the drive of each map
    (maps drawn so that each drive is seen equally often). ``log(step, loss)`` is called every
    100 steps when given.

    Raises:
        ImportError: PyTorch is not installed (:data:`TORCH_MISSING`).
        ValueError: Shapes disagree.
    """
    n, h, w, c = x.shape
    if y.shape != (n, h, w) or valid.shape != (n, h, w) or np.shape(group) != (n,):
        raise ValueError(f'road CNN fit needs (N, H, W, F) features and (N, H, W) labels '
                         f'and masks, (N,) groups; got {x.shape}, {y.shape}, {valid.shape}, '
                         f'{np.shape(group)}')
    torch = torch_module()
    torch.manual_seed(seed)
    torch.set_num_threads(1)
    rng = np.random.default_rng(seed)
    sub = x[rng.choice(n, min(n, 64), replace=False)].astype(np.float32).reshape(-1, c)
    mean, scale = sub.mean(axis=0), sub.std(axis=0)
    scale[scale < 1e-6] = 1.0
    _, inverse, counts = np.unique(group, return_inverse=True, return_counts=True)
    draw = 1.0 / counts[inverse]
    draw /= draw.sum()
    net = torch_network(c, widths)
    opt = torch.optim.Adam(net.parameters(), lr=rate, weight_decay=weight_decay)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    m_t = torch.from_numpy(mean.astype(np.float32)).view(1, c, 1, 1)
    s_t = torch.from_numpy(scale.astype(np.float32)).view(1, c, 1, 1)
    running = 0.0
    for step in range(steps):
        idx = rng.choice(n, batch, p=draw)
        xb = torch.from_numpy(x[idx].astype(np.float32)).permute(0, 3, 1, 2)
        yb = torch.from_numpy(y[idx].astype(np.float32))
        vb = torch.from_numpy(valid[idx].astype(np.float32))
        flip = torch.from_numpy(rng.random(batch) < 0.5)
        xb[flip] = xb[flip].flip(-1)
        yb[flip] = yb[flip].flip(-1)
        vb[flip] = vb[flip].flip(-1)
        z = net((xb - m_t) / s_t)
        loss = (torch.nn.functional.binary_cross_entropy_with_logits(
            z, yb, reduction='none') * vb).sum() / vb.sum().clamp(min=1.0)
        if dice:
            loss = loss + dice * soft_dice_loss(torch.sigmoid(z), yb, vb)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        running += float(loss.detach())
        if log is not None and (step + 1) % 100 == 0:
            log(step + 1, running / 100)
            running = 0.0
    net.eval()
    cnn = export(net, mean, scale)
    # The exported numpy pass must be the network PyTorch trained (layer order, padding,
    # dilation, upsampling): checked on the first training map at every fit.
    check = x[0].astype(np.float32)
    with torch.no_grad():
        want = net(torch.from_numpy(((check - mean) / scale).astype(np.float32))
                   .permute(2, 0, 1)[None])[0].numpy()
    got = cnn.logits(check)
    if got.shape != want.shape:
        raise RuntimeError(f'exported road CNN gives logits of shape {got.shape}, the trained '
                           f'network {want.shape}')
    if not np.allclose(got, want, atol=1e-3):
        raise RuntimeError(f'exported road CNN differs from the trained network: largest logit '
                           f'difference {np.max(np.abs(got - want)):.3g}')
    return cnn
