"""Where the landmark detector loses a trial's landmark (:mod:`.landmarks_real` stages).

:func:`landmark_stage` follows the truth's frame X-corners through the detector's stages
(:data:`STAGES`: corner candidates, eq. 3 edges, eq. 4 frames, code grid, code reading) and
returns the first that loses the landmark; :func:`stage_counts` counts them per size.
"""

from typing import Dict, Sequence, Tuple

from landmark_nav.evaluation.marker_composites import (CAMERA, CORNER_MODULES, marker_corners,
                                                       MODULE)
from landmark_nav.evaluation.marker_trials import render_trial, Trial
from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.detector import detect_landmarks, DetectorParams
from landmark_nav.vision.landmark import LandmarkDesign
from landmark_nav.vision.pose import project_points
import numpy as np

#: Stages of the landmark detector, in order (:func:`landmark_stage`).
STAGES = ('corners', 'edges', 'frame', 'grid', 'code', 'detected')


def landmark_stage(gray: np.ndarray, trial: Trial, params: DetectorParams = DetectorParams(),
                   camera: CameraModel = CAMERA, module: float = MODULE,
                   tolerance: float = 0.35) -> Tuple[str, str]:
    """Return the first detector stage that loses the trial's landmark, and why.

    The truth's 20 frame X-corners are matched to the nearest corner group (within
    ``tolerance`` of the block pixels, at least 1 px). Stages: ``corners`` (an X-corner
    has no corner group), ``edges`` (an edge of the matched corners is not among the eq. 3
    chains), ``frame`` (eq. 4 does not join them), ``grid`` (the code grid leaves the
    image), ``code`` (:func:`read_code` rejects it; the reason is returned), ``detected``.
    """
    design = params.design
    debug: dict = {}
    dets = detect_landmarks(gray, params, debug=debug)
    code = trial.codes['landmark']
    truth_c = marker_corners(trial.v, CORNER_MODULES['landmark'] * module, camera).mean(0)
    ppm = camera.fx * module / np.linalg.norm(trial.v[:3])
    for d in dets:
        if d.code == code and np.linalg.norm(d.corners.mean(0) - truth_c) <= ppm:
            return 'detected', ''
    grid_pts = design.edge_corners()                          # (4, n, 3), landmark frame
    d7 = LandmarkDesign(frame_width=7 * module)
    truth = project_points(trial.v, d7.edge_corners().reshape(-1, 3), camera).reshape(
        grid_pts.shape[:2] + (2,))
    pts = debug['points']
    if not len(pts):
        return 'corners', 'no corner groups'
    dist = np.linalg.norm(truth[:, :, None, :] - pts[None, None], axis=3)
    ids = dist.argmin(axis=2)
    tol = max(1.0, tolerance * ppm)
    missing = int(np.sum(dist[:, :-1].min(axis=2) > tol))   # 20 distinct X-corners
    if missing:
        return 'corners', ('1-2' if missing <= 2 else '3-9' if missing < 10 else '10-20') + \
            ' of 20 X-corners without a group'
    edges = {tuple(e) for e in debug['edges'].tolist()}
    lost = sum(tuple(ids[e]) not in edges for e in range(4))
    if lost:
        return 'edges', f'{lost} of 4 edges not chained'
    want = frozenset(ids.ravel().tolist())
    for k, frame in enumerate(debug['frames']):
        if frozenset(frame.ravel().tolist()) == want:
            break
    else:
        return 'frame', 'edges not joined into a frame'
    # the readings follow the frames whose grid is inside the image, in order
    grids = debug['grids']
    for g, r in zip(grids, debug['readings']):
        if np.linalg.norm(g.corners.mean(0) - truth_c) <= ppm:
            if r.code is None:
                return 'code', r.reason
            return 'code', f'read as {r.code}' if r.code != code else 'duplicate'
    return 'grid', 'grid outside the image'


def stage_counts(trials: Sequence[Trial], backgrounds: Sequence[np.ndarray],
                 params: DetectorParams = DetectorParams()) -> Dict[str, Dict[str, int]]:
    """Count per px per module the stage at which each landmark is lost (and the reasons)."""
    out: Dict[str, Dict[str, int]] = {}
    for t in trials:
        stage, why = landmark_stage(render_trial(t, 'landmark', backgrounds), t, params)
        row = out.setdefault(f'{t.px_per_module:g} px', {})
        key = stage if not why else f'{stage}: {why}'
        row[key] = row.get(key, 0) + 1
    return out


__all__ = ['landmark_stage', 'stage_counts', 'STAGES']
