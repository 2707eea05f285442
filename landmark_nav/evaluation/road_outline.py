"""Road outline against per-pixel road labels (CamVid-style folders of real street frames).

A folder holds ``images/NAME.png`` (RGB photographs) and ``labels_camvid11/NAME.png`` (8-bit
class index per pixel; class 3 = road, road markings included). For every frame the
outline (:func:`landmark_nav.road.outline.road_outline`) is seeded from a fixed band of
the image where a tilted laser's traversable segment would fall on the road in front of the
vehicle -- rows ``SEED_ROWS`` and columns ``SEED_COLS`` as fractions of the image (about
2-3 m ahead, the width of a lane); the label is never used to place it -- and scored
against the label: IoU, precision and recall of the road pixels, leaving out the pixels
labelled unlabelled (``UNLABELLED_CLASS``; e.g. the car's own bonnet at the bottom of the
0001TP frames), as CamVid's void class is usually left out. A failure is a frame with an IoU
below ``FAIL_IOU``.

The seed is checked against the label: a frame whose seed band is less than
``SEED_ROAD_SHARE`` road (a car close ahead, a junction) is reported apart (``seed_not_road``,
listed by name), not scored with the others. Each frame also carries the outline's own
confidence and ``reliable`` flag (:func:`landmark_nav.road.outline.road_outline`); the
summary counts the frames flagged unreliable and the failures among them.

Hard-shadow frames are reported separately: a frame counts as one when the road label holds
a large dark region (more than ``SHADOW_FRACTION`` of its pixels darker than half the
median road intensity), a rule on the image and label only.
"""

from dataclasses import dataclass
from pathlib import Path
import time
from typing import Dict, List, Optional, Sequence

import cv2
from landmark_nav.evaluation.blas import single_threaded
from landmark_nav.road.outline import band_seed, OutlineParams, road_outline
from landmark_nav.road.road_cnn import ProbabilityModel
import numpy as np

ROAD_CLASS = 3
UNLABELLED_CLASS = 11
#: Names of the CamVid 11-class label indices (``labels_camvid11``).
CLASS_NAMES = ('sky', 'building', 'pole', 'road', 'pavement', 'tree', 'sign', 'fence', 'car',
               'pedestrian', 'cyclist', 'unlabelled')
SEED_ROAD_SHARE = 0.5
SEED_ROWS = (0.86, 0.92)
SEED_COLS = (0.38, 0.62)
FAIL_IOU = 0.6
SHADOW_FRACTION = 0.02


@dataclass(frozen=True)
class FrameScore:
    """Scores of one frame."""

    name: str
    iou: float
    precision: float
    recall: float
    seed_purity: float        # fraction of the seed band on labelled road
    hard_shadow: bool
    seconds: float
    confidence: float = 1.0   # the outline's own confidence
    reliable: bool = True     # the outline's flag: confidence and row fill above their limits
    row_fill: float = 1.0     # the outline's row fill (share of its row spans it covers)
    wrong_pixels: tuple = ()  # pixels outside the road taken as road, per label class

    @property
    def seed_is_road(self) -> bool:
        """The seed band is mostly labelled road (``SEED_ROAD_SHARE``)."""
        return self.seed_purity >= SEED_ROAD_SHARE


def load_frame(folder: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Return (RGB uint8 image, label uint8) of one frame.

    Raises:
        FileNotFoundError: A file is missing or unreadable (naming it).
        ValueError: The image and label sizes differ.
    """
    paths = (folder / 'images' / f'{name}.png', folder / 'labels_camvid11' / f'{name}.png')
    bgr = cv2.imread(str(paths[0]), cv2.IMREAD_COLOR)
    label = cv2.imread(str(paths[1]), cv2.IMREAD_UNCHANGED)
    for path, data in zip(paths, (bgr, label)):
        if data is None:
            raise FileNotFoundError(f'{path}: missing or not an image')
    if label.ndim != 2 or label.shape != bgr.shape[:2]:
        raise ValueError(f'{paths[1]}: label {label.shape} does not match image '
                         f'{bgr.shape[:2]}')
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), label


def frame_names(folder: Path) -> List[str]:
    """Names of the frames that have both an image and a label, sorted."""
    images = {p.stem for p in (folder / 'images').glob('*.png')}
    labels = {p.stem for p in (folder / 'labels_camvid11').glob('*.png')}
    return sorted(images & labels)


def is_hard_shadow(rgb: np.ndarray, road: np.ndarray) -> bool:
    """Return True when a large part of the labelled road is in hard shadow."""
    if not road.any():
        return False
    grey = rgb.astype(np.float32).mean(axis=2)[road]
    return float(np.mean(grey < 0.5 * np.median(grey))) > SHADOW_FRACTION


def score_frame(rgb: np.ndarray, label: np.ndarray, params: OutlineParams,
                name: str = '', model: Optional[ProbabilityModel] = None
                ) -> tuple[FrameScore, np.ndarray]:
    """Run the outline on one frame and score it; returns (score, road mask)."""
    truth = label == ROAD_CLASS
    seed = band_seed(rgb.shape, SEED_ROWS, SEED_COLS)
    t0 = time.perf_counter()
    out = road_outline(rgb, seed, params, model)
    dt = time.perf_counter() - t0
    pred = out.mask & (label != UNLABELLED_CLASS)    # unlabelled pixels are not scored
    inter = float(np.sum(pred & truth))
    union = float(np.sum(pred | truth))
    iou = inter / union if union else 1.0
    precision = inter / float(pred.sum()) if pred.any() else 0.0
    recall = inter / float(truth.sum()) if truth.any() else 1.0
    wrong = np.bincount(label[pred & ~truth], minlength=len(CLASS_NAMES))
    return FrameScore(name, iou, precision, recall, float(truth[seed].mean()),
                      is_hard_shadow(rgb, truth), dt, float(out.confidence),
                      bool(out.reliable), float(out.row_fill),
                      tuple(int(n) for n in wrong[:len(CLASS_NAMES)])), pred


@single_threaded
def evaluate_folder(folder: Path, params: OutlineParams = OutlineParams(),
                    names: Optional[Sequence[str]] = None,
                    model: Optional[ProbabilityModel] = None) -> List[FrameScore]:
    """Score every frame of a folder (or the ``names`` given; ``model``: the packaged one)."""
    folder = Path(folder)
    names = frame_names(folder) if names is None else list(names)
    if not names:
        raise FileNotFoundError(f'{folder}: no frames with both images/ and '
                                'labels_camvid11/ PNGs')
    scores = []
    for name in names:
        rgb, label = load_frame(folder, name)
        scores.append(score_frame(rgb, label, params, name, model)[0])
    return scores


def summarize(scores: Sequence[FrameScore]) -> Dict[str, Dict[str, float]]:
    """Median / mean IoU, precision, recall and the failure rate per frame set.

    ``all`` and the shadow sets hold the frames whose seed is road; ``seed_not_road`` the
    others (with their names in ``names``); ``unreliable`` the frames with a road seed the
    outline flagged.
    """
    road = [s for s in scores if s.seed_is_road]
    sets = {'all': road, 'hard_shadow': [s for s in road if s.hard_shadow],
            'no_hard_shadow': [s for s in road if not s.hard_shadow],
            'unreliable': [s for s in road if not s.reliable],
            'seed_not_road': [s for s in scores if not s.seed_is_road]}
    out = {}
    for key, group in sets.items():
        if not group:
            out[key] = {'frames': 0}
            continue
        iou = np.array([s.iou for s in group])
        out[key] = {'frames': len(group), 'iou_median': float(np.median(iou)),
                    'iou_mean': float(iou.mean()), 'iou_min': float(iou.min()),
                    'precision_median': float(np.median([s.precision for s in group])),
                    'recall_median': float(np.median([s.recall for s in group])),
                    'failures': int(np.sum(iou < FAIL_IOU)),
                    'failure_rate': float(np.mean(iou < FAIL_IOU)),
                    'seed_purity_min': float(min(s.seed_purity for s in group)),
                    'unreliable': int(sum(not s.reliable for s in group)),
                    'ms_median': 1e3 * float(np.median([s.seconds for s in group]))}
    if out['seed_not_road']['frames']:
        out['seed_not_road']['names'] = [s.name for s in sets['seed_not_road']]
    return out


def format_summary(summary: Dict[str, Dict[str, float]]) -> str:
    """Render :func:`summarize` as a small text table."""
    lines = [f'{"set":16s} {"frames":>6s} {"IoU med":>8s} {"mean":>6s} {"min":>6s} '
             f'{"prec":>6s} {"recall":>6s} {"fail<0.6":>8s} {"flagged":>7s} {"ms":>6s}']
    for key, s in summary.items():
        if not s['frames']:
            lines.append(f'{key:16s} {0:6d}')
            continue
        lines.append(f'{key:16s} {s["frames"]:6d} {s["iou_median"]:8.3f} {s["iou_mean"]:6.3f} '
                     f'{s["iou_min"]:6.3f} {s["precision_median"]:6.3f} '
                     f'{s["recall_median"]:6.3f} {s["failures"]:4d} '
                     f'({100 * s["failure_rate"]:.0f}%) {s["unreliable"]:7d} '
                     f'{s["ms_median"]:6.1f}')
    bad = summary.get('seed_not_road', {}).get('names', [])
    lines.append(f'seed band rows {SEED_ROWS} cols {SEED_COLS} of the image; '
                 + (f'{len(bad)} frames whose seed is not road (< {SEED_ROAD_SHARE:.0%} road, '
                    f'scored apart above): {" ".join(bad)}' if bad else
                    f'the seed is road (>= {SEED_ROAD_SHARE:.0%}) on every frame'))
    return '\n'.join(lines)


def overlay(rgb: np.ndarray, label: np.ndarray, mask: np.ndarray, seed: np.ndarray,
            text: str = '') -> np.ndarray:
    """Return a BGR overlay: outline region green, labelled road border red, seed blue."""
    vis = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    vis[mask] = (0.55 * vis[mask] + np.array([0, 110, 0])).astype(np.uint8)
    truth, _ = cv2.findContours((label == ROAD_CLASS).astype(np.uint8), cv2.RETR_EXTERNAL,
                                cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(vis, truth, -1, (0, 0, 255), 2)
    vis[seed] = (255, 60, 0)
    if text:
        cv2.putText(vis, text, (8, 26), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2)
    return vis


def write_overlays(folder: Path, names: Sequence[str], out: Path,
                   params: OutlineParams = OutlineParams(), scale: float = 0.5) -> Path:
    """Write one montage (a column of overlays, each scaled by ``scale``) to ``out``."""
    tiles = []
    for name in names:
        rgb, label = load_frame(Path(folder), name)
        score, mask = score_frame(rgb, label, params, name)
        seed = band_seed(rgb.shape, SEED_ROWS, SEED_COLS)
        vis = overlay(rgb, label, mask, seed, f'{name} IoU {score.iou:.2f}')
        tiles.append(cv2.resize(vis, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), np.vstack(tiles)):
        raise OSError(f'{out}: could not write the image')
    return out
