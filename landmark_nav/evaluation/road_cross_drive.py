"""Train the road-probability model from labelled street frames; score it leaving one drive out.

Frames are CamVid-style folders (:mod:`landmark_nav.evaluation.road_outline`); a frame's
drive is the part of its name before the first ``_`` (CamVid: ``0001TP``, ``0006R0``,
``0016E5``). Training samples ``SAMPLES_PER_FRAME`` random pixels of every frame whose seed
band is road (road share of the band >= ``SEED_ROAD_SHARE``; the others would teach the
seed-relative features a wrong reference), skipping unlabelled pixels, with each drive
weighted equally. Leave one drive out: for every drive, a model fitted on the other drives
scores that drive's frames.

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
from landmark_nav.road.road_probability import FEATURE_NAMES, FEATURE_SIZE, pixel_features
from landmark_nav.road.road_probability import RoadModel
from landmark_nav.road.road_training import fit_road_model
import numpy as np

SAMPLES_PER_FRAME = 600
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


def sample_frames(folders: Sequence[Path], per_frame: int = SAMPLES_PER_FRAME,
                  seed: int = 0) -> TrainingSet:
    """Sample labelled pixels of every frame of the folders (see the module text)."""
    rng = np.random.default_rng(seed)
    xs, ys, drives, skipped = [], [], [], []
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
            feats = pixel_features(rgb, seed).reshape(-1, len(FEATURE_NAMES))
            small = cv2.resize(label, FEATURE_SIZE, interpolation=cv2.INTER_NEAREST).ravel()
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


def leave_one_drive_out(folders: Sequence[Path], params: OutlineParams = OutlineParams(),
                        seed: int = 0) -> Dict[str, dict]:
    """Per drive: the summary of its frames scored by a model fitted on the other drives.

    With ``params.method == 'chapter'`` nothing is trained (eqs. 26-28 have no model).
    """
    folders = [Path(f) for f in folders]
    learned = params.method == 'learned'
    data = sample_frames(folders, seed=seed) if learned else None
    drives = sorted({drive_of(n) for f in folders for n in frame_names(f)})
    if len(drives) < 2:
        raise ValueError(f'leave one drive out needs two drives or more; got {drives}')
    out = {}
    for held in drives:
        model = train(data, [d for d in drives if d != held and np.any(data.drive == d)],
                      seed) if learned else None
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
    ``'all'``, the quantile over every drive's frames (the shipped ``min_row_fill``).
    """
    def fills(drives):
        return [f.row_fill for d in drives for f in results[d]['frames'] if f.seed_is_road]
    out = {d: float(np.quantile(fills([o for o in results if o != d]), quantile))
           for d in results}
    out['all'] = float(np.quantile(fills(list(results)), quantile))
    return out
