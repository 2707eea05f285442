"""Train the road-probability model from labelled street frames; score it leaving one drive out.

Frames are CamVid-style folders (:mod:`landmark_nav.evaluation.road_outline`); a frame's
drive is the part of its name before the first ``_`` (CamVid: ``0001TP``, ``0006R0``,
``0016E5``). Training samples ``SAMPLES_PER_FRAME`` random pixels of every frame whose seed
band is road (road share of the band >= ``SEED_ROAD_SHARE``; the others would teach the
seed-relative features a wrong reference), skipping unlabelled pixels, with each drive
weighted equally. The convolutional network (:mod:`landmark_nav.road.road_cnn`) trains on
whole frames instead (:func:`feature_maps`): every such frame's feature maps and
``CNN_COPIES`` altered copies (a random zoom up to ``CNN_MAX_ZOOM`` and a change of light),
unlabelled pixels not scored, each drive weighted equally, cross-entropy plus ``CNN_DICE``
times the soft Dice loss (:func:`train_cnn`, PyTorch). Leave one drive out: for every
drive, a model fitted on the other drives scores that drive's frames.

The outline's row-fill limit (:func:`landmark_nav.road.outline.row_fill`) is calibrated the
same way: for a held-out drive, the ``ROW_FILL_QUANTILE`` quantile of the row fill of the other
drives' held-out frames (:func:`row_fill_limits`); the shipped ``min_row_fill`` is that
quantile over all drives' held-out frames.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Sequence, Tuple

import cv2
from landmark_nav.evaluation.road_outline import (evaluate_folder, frame_names, load_frame,
                                                  ROAD_CLASS, SEED_COLS, SEED_ROAD_SHARE,
                                                  SEED_ROWS, summarize, UNLABELLED_CLASS)
from landmark_nav.road.outline import band_seed, OutlineParams
from landmark_nav.road.road_cnn import MeanProbability
from landmark_nav.road.road_cnn_training import DICE, STEPS
from landmark_nav.road.road_probability import FEATURE_NAMES, FEATURE_SIZE, pixel_features
from landmark_nav.road.road_probability import RoadModel
from landmark_nav.road.road_training import fit_road_model
import numpy as np

SAMPLES_PER_FRAME = 600
CNN_COPIES = 5
CNN_STEPS = STEPS  # the shipped network's training (road_cnn_training)
CNN_MAX_ZOOM = 1.4
CNN_DICE = DICE
ROW_FILL_QUANTILE = 0.1


def drive_of(name: str) -> str:
    """Return the drive of a frame name (the part before the first ``_``)."""
    return name.split('_', 1)[0]


@dataclass(frozen=True, eq=False)
class TrainingSet:
    """Sampled pixels: features (N, F), labels (N,), drive per sample, frames used/skipped."""

    x: np.ndarray
    y: np.ndarray
    drive: np.ndarray
    skipped: Tuple[str, ...]       # frames whose seed band is not road


def _road_seeded_frames(folders: Sequence[Path], skipped: List[str]):
    """Yield (name, RGB, label, label at FEATURE_SIZE, seed band) of the road-seeded frames.

    The names of the others are appended to ``skipped``.
    """
    for folder in map(Path, folders):
        names = frame_names(folder)
        if not names:
            raise FileNotFoundError(f'{folder}: no frames with both images/ and '
                                    'labels_camvid11/ PNGs')
        for name in names:
            rgb, label = load_frame(folder, name)
            seed = band_seed(rgb.shape, SEED_ROWS, SEED_COLS)
            if float(np.mean(label[seed] == ROAD_CLASS)) < SEED_ROAD_SHARE:
                skipped.append(name)
                continue
            yield name, rgb, label, cv2.resize(label, FEATURE_SIZE,
                                               interpolation=cv2.INTER_NEAREST), seed


def sample_frames(folders: Sequence[Path], per_frame: int = SAMPLES_PER_FRAME,
                  seed: int = 0) -> TrainingSet:
    """Sample labelled pixels of every frame of the folders (see the module text)."""
    rng = np.random.default_rng(seed)
    xs, ys, drives, skipped = [], [], [], []
    for name, rgb, _, small, seed_band in _road_seeded_frames(folders, skipped):
        feats = pixel_features(rgb, seed_band).reshape(-1, len(FEATURE_NAMES))
        small = small.ravel()
        usable = np.flatnonzero(small != UNLABELLED_CLASS)
        idx = rng.choice(usable, min(per_frame, len(usable)), replace=False)
        xs.append(feats[idx])
        ys.append((small[idx] == ROAD_CLASS).astype(np.float32))
        drives.append(np.full(len(idx), drive_of(name)))
    if not xs:
        raise ValueError('no frame with a road seed to train on')
    return TrainingSet(np.concatenate(xs), np.concatenate(ys), np.concatenate(drives),
                       tuple(skipped))


def train(data: TrainingSet, drives: Sequence[str] = (), seed: int = 0) -> RoadModel:
    """Fit the model on the samples of ``drives`` (all when empty), each drive weighed equally.

    Raises:
        ValueError: A drive has no samples.
    """
    use = np.isin(data.drive, list(drives)) if drives else np.ones(len(data.y), bool)
    for d in drives:
        if not np.any(data.drive == d):
            raise ValueError(f'drive {d!r} has no training frames (drives: '
                             f'{sorted(set(data.drive))})')
    names, counts = np.unique(data.drive[use], return_counts=True)
    per = dict(zip(names, counts))
    weights = np.array([1.0 / per[d] for d in data.drive[use]])
    return fit_road_model(data.x[use], data.y[use], weights=weights, seed=seed)


@dataclass(frozen=True, eq=False)
class FeatureMaps:
    """Whole frames for the CNN.

    Features (N, 120, 160, F) float16, labels and scored pixels (N, 120, 160) bool, the drive
    of each map; the ``copies`` photometrically altered maps of a frame follow its original.
    """

    x: np.ndarray
    y: np.ndarray
    valid: np.ndarray
    drive: np.ndarray
    skipped: Tuple[str, ...]       # frames whose seed band is not road


def feature_maps(folders: Sequence[Path], copies: int = CNN_COPIES, seed: int = 0,
                 max_zoom: float = CNN_MAX_ZOOM) -> FeatureMaps:
    """Feature maps of every frame whose seed band is road, and ``copies`` altered ones each.

    The alterations (:func:`landmark_nav.road.road_cnn_training.photometric`) change the
    image before its features are computed, as a change of light or camera would; with
    ``max_zoom`` > 1 each copy is first a random zoomed-in part of the frame
    (:func:`landmark_nav.road.road_cnn_training.zoom_crop`: another focal length, camera
    height or pitch), kept when its seed band is still road.
    """
    from landmark_nav.road.road_cnn_training import photometric, zoom_crop
    rng = np.random.default_rng(seed)
    xs, ys, valid, drives, skipped = [], [], [], [], []
    for name, rgb, label, small, seed_band in _road_seeded_frames(folders, skipped):
        for k in range(copies + 1):
            img, lab = rgb, small
            if k and max_zoom > 1.0:
                z_img, z_lab = zoom_crop(rgb, label, rng, max_zoom)
                if float(np.mean(z_lab[seed_band] == ROAD_CLASS)) >= SEED_ROAD_SHARE:
                    img, lab = z_img, cv2.resize(z_lab, FEATURE_SIZE,
                                                 interpolation=cv2.INTER_NEAREST)
            img = img if k == 0 else photometric(img, rng)
            xs.append(pixel_features(img, seed_band).astype(np.float16))
            ys.append(lab == ROAD_CLASS)
            valid.append(lab != UNLABELLED_CLASS)
            drives.append(drive_of(name))
    if not xs:
        raise ValueError('no frame with a road seed to train on')
    return FeatureMaps(np.stack(xs), np.stack(ys), np.stack(valid), np.array(drives),
                       tuple(skipped))


def train_cnn(data: FeatureMaps, drives: Sequence[str] = (), seed: int = 0,
              steps: int = CNN_STEPS, log=None, dice: float = CNN_DICE):
    """Fit the road CNN on the maps of ``drives`` (all when empty), each drive weighed equally.

    Raises:
        ImportError: PyTorch is missing (training only).
        ValueError: A drive has no maps.
    """
    from landmark_nav.road.road_cnn_training import fit_road_cnn
    for d in drives:
        if not np.any(data.drive == d):
            raise ValueError(f'drive {d!r} has no training frames (drives: '
                             f'{sorted(set(data.drive))})')
    use = np.flatnonzero(np.isin(data.drive, list(drives)) if drives else
                         np.ones(len(data.drive), bool))
    return fit_road_cnn(data.x[use], data.y[use], data.valid[use], data.drive[use],
                        steps=steps, seed=seed, dice=dice, log=log)


def leave_one_drive_out(folders: Sequence[Path], params: OutlineParams = OutlineParams(),
                        seed: int = 0, cnn_steps: int = CNN_STEPS,
                        held_out: Sequence[str] = ()) -> Dict[str, dict]:
    """Per drive: the summary of its frames scored by a model fitted on the other drives.

    ``params.method``: 'learned' fits the perceptron, 'cnn' the perceptron and the
    convolutional network (``cnn_steps`` mini-batches; needs PyTorch) and averages their
    probabilities; with 'chapter' nothing is trained (eqs. 26-28 have no model).
    ``held_out``: the drives to hold out in turn (default every drive).

    Raises:
        ValueError: Fewer than two drives, or a ``held_out`` drive that is not among them.
    """
    folders = [Path(f) for f in folders]
    drives = sorted({drive_of(n) for f in folders for n in frame_names(f)})
    if len(drives) < 2:
        raise ValueError(f'leave one drive out needs two drives or more; got {drives}')
    unknown = sorted(set(held_out) - set(drives))
    if unknown:
        raise ValueError(f'held-out drive(s) {unknown} not in the folders (drives: {drives})')
    if params.method != 'chapter':
        data = sample_frames(folders, seed=seed)
    if params.method == 'cnn':
        maps = feature_maps(folders, seed=seed)
    out = {}
    for held in [d for d in drives if not held_out or d in held_out]:
        model = None
        if params.method != 'chapter':
            others = [d for d in drives if d != held and np.any(data.drive == d)]
            model = train(data, others, seed)
        if params.method == 'cnn':
            model = MeanProbability((train_cnn(maps, others, seed, cnn_steps), model))
        scores: List = []
        for folder in folders:
            names = [n for n in frame_names(folder) if drive_of(n) == held]
            if names:
                scores += evaluate_folder(folder, params, names, model)
        out[held] = {'summary': summarize(scores), 'frames': scores}
    return out


def row_fill_limits(results: Dict[str, dict], quantile: float = ROW_FILL_QUANTILE
                    ) -> Dict[str, float]:
    """Per drive of :func:`leave_one_drive_out`'s result: the row-fill limit from the others.

    The ``quantile`` of the row fill of the other drives' frames whose seed is road; under
    ``'all'``, the quantile over every drive's frames (the shipped ``min_row_fill``). NaN
    where there is no other drive (one drive held out alone): nothing is flagged by it.
    """
    def limit(drives):
        fills = [f.row_fill for d in drives for f in results[d]['frames'] if f.seed_is_road]
        return float(np.quantile(fills, quantile)) if fills else float('nan')
    out = {d: limit([o for o in results if o != d]) for d in results}
    out['all'] = limit(list(results))
    return out
