"""Trials of the marker comparison of :mod:`.landmarks_real`: draws, runs and scores.

One *trial* (:class:`Trial`) is one background, one marker pose and one set of
degradations, rendered once per marker family (:func:`render_trial`);
:func:`run_trials` runs every detector on its family's frame and :func:`score` compares
the detections with the truth (:class:`Outcome`).

Scoring: a marker is *detected* when a detection with the true code has its centre (mean
of its four corners) within one module of the true centre; any other detection in the
frame is counted as a *wrong code* (at the marker) or a *false detection* (elsewhere).
Pose errors are the position error of the marker centre and the rotation angle between
estimated and true marker orientation; for the tags the orientation is compared modulo
quarter turns about the normal (their frame conventions differ from the truth's; the code
fixes the quarter turn). Times are CPU times of the process per call
(``time.process_time``, less sensitive than the wall clock to other load on the machine),
single-threaded (``cv2.setNumThreads(1)``, AprilTag ``nthreads=1``, BLAS limited to one
thread by threadpoolctl in :func:`.landmarks_real.main`).
"""

from dataclasses import dataclass
import math
import time
from typing import Dict, List, Sequence, Tuple

import cv2
from landmark_nav.evaluation.marker_composites import (_M, CAMERA, composite, CORNER_MODULES,
                                                       draw_photometrics, draw_pose,
                                                       marker_corners, marker_texture,
                                                       MODULE, Photometrics,
                                                       PRINTED_MODULES)
from landmark_nav.evaluation.marker_detectors import Detectors, Found, marker_family
from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.landmark import LandmarkDesign
from landmark_nav.vision.pose import rotation_matrix
import numpy as np

#: Ids of the tag dictionaries drawn from (tag36h11 has 587 codes, DICT_6X6_250 250).
TAG_IDS = {'apriltag': 587, 'aruco': 250}


@dataclass(frozen=True, eq=False)
class Trial:
    """One background, pose and set of degradations, rendered once per marker family."""

    index: int
    background: int
    px_per_module: float
    tilt_deg: float
    v: np.ndarray
    photo: Photometrics
    codes: Dict[str, int]
    noise_seed: int


def draw_trial(index: int, rng: np.random.Generator, n_backgrounds: int, px_per_module: float,
               tilt_deg: float, module: float = MODULE) -> Trial:
    """Draw a trial (the pose keeps the widest printed marker, 10 modules, in the image)."""
    bg = int(rng.integers(n_backgrounds))
    v = draw_pose(rng, px_per_module, tilt_deg, max(PRINTED_MODULES.values()), module)
    photo = draw_photometrics(rng)
    design = LandmarkDesign()
    while True:
        code = int(rng.integers(0, design.code_limit))
        if design.is_valid_code(code):
            break
    codes = {'landmark': code, 'apriltag': int(rng.integers(TAG_IDS['apriltag'])),
             'aruco': int(rng.integers(TAG_IDS['aruco']))}
    return Trial(index, bg, float(px_per_module), float(tilt_deg), v, photo, codes,
                 int(rng.integers(2 ** 31)))


def render_trial(trial: Trial, family: str, backgrounds: Sequence[np.ndarray],
                 module: float = MODULE) -> np.ndarray:
    """Render the frame of one marker family for a trial."""
    tex = marker_texture(family, trial.codes[family])
    return composite(backgrounds[trial.background], tex, trial.v, PRINTED_MODULES[family],
                     module, trial.photo, trial.noise_seed)


def _rotation_error_deg(r_est: np.ndarray, r_true: np.ndarray, quarter_turns: bool) -> float:
    """Angle of ``r_true^T r_est`` [deg], the smallest over quarter turns about z if asked."""
    best = math.inf
    for k in range(4 if quarter_turns else 1):
        c, s = math.cos(k * math.pi / 2), math.sin(k * math.pi / 2)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        r = (r_true @ rz).T @ r_est
        best = min(best, math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(r) - 1) / 2)))))
    return best


#: landmark frame (x out, y right, z up) -> square-tag frame (x right, y up, z out)
_ARUCO_FROM_LANDMARK = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


@dataclass
class Outcome:
    """What one detector did on one trial's frame."""

    detector: str
    trial: int
    px_per_module: float
    tilt_deg: float
    detected: bool
    wrong_codes: int
    false_detections: int
    seconds: float
    position_error: float = math.nan
    angle_error_deg: float = math.nan
    nees: float = math.nan
    ambiguous: bool = False


def pose_nees(v_est: np.ndarray, covariance: np.ndarray, v_true: np.ndarray) -> float:
    """Normalised estimation error squared ``d^T P^-1 d`` of a pose ``v`` (angles wrapped)."""
    d = np.asarray(v_est, dtype=float) - np.asarray(v_true, dtype=float)
    d[3:] = (d[3:] + math.pi) % (2.0 * math.pi) - math.pi
    try:
        return float(d @ np.linalg.solve(covariance, d))
    except np.linalg.LinAlgError:
        return math.inf


def score(name: str, trial: Trial, found: List[Found], seconds: float,
          camera: CameraModel = CAMERA, module: float = MODULE) -> Outcome:
    """Score the detections of one frame against the trial's truth (module docstring)."""
    fam = marker_family(name)
    truth = marker_corners(trial.v, CORNER_MODULES[fam] * module, camera)
    centre = truth.mean(axis=0)
    tol = camera.fx * module / np.linalg.norm(trial.v[:3])
    radius = 0.5 * PRINTED_MODULES[fam] * math.sqrt(2.0) * tol
    out = Outcome(name, trial.index, trial.px_per_module, trial.tilt_deg, False, 0, 0, seconds)
    r_opt = _M @ rotation_matrix(trial.v[3:])
    t_opt = _M @ trial.v[:3]
    for f in found:
        dist = float(np.linalg.norm(f.corners.mean(axis=0) - centre))
        if f.code == trial.codes[fam] and dist <= tol and not out.detected:
            out.detected = True
            if f.rotation is not None:
                out.position_error = float(np.linalg.norm(f.translation - t_opt))
                if fam == 'landmark':
                    out.angle_error_deg = _rotation_error_deg(f.rotation, r_opt, False)
                    if f.covariance is not None:
                        out.nees = pose_nees(f.v, f.covariance, trial.v)
                        out.ambiguous = f.ambiguous
                else:
                    out.angle_error_deg = _rotation_error_deg(
                        f.rotation, r_opt @ _ARUCO_FROM_LANDMARK.T, True)
        elif dist <= radius:
            out.wrong_codes += 1
        else:
            out.false_detections += 1
    return out


def run_trials(trials: Sequence[Trial], backgrounds: Sequence[np.ndarray],
               detectors: Detectors, pose: bool = False) -> List[Outcome]:
    """Render every trial per family and run every detector on its family's frame."""
    cv2.setNumThreads(1)
    out = []
    for trial in trials:
        frames = {}
        for name in detectors.names:
            fam = marker_family(name)
            if fam not in frames:
                frames[fam] = render_trial(trial, fam, backgrounds, detectors.module)
            t0 = time.process_time()
            found = detectors.detect(name, frames[fam], pose)
            dt = time.process_time() - t0
            out.append(score(name, trial, found, dt, detectors.camera, detectors.module))
    return out


def detection_trials(px_per_module: Sequence[float] = (3, 4, 5, 6, 8, 12), per_size: int = 100,
                     tilt_range: Tuple[float, float] = (0.0, 60.0), seed: int = 1,
                     n_backgrounds: int = 51) -> List[Trial]:
    """Draw ``per_size`` trials per scale, tilt uniform in ``tilt_range`` [deg]."""
    rng = np.random.default_rng(seed)
    out = []
    for ppm in px_per_module:
        for _ in range(per_size):
            out.append(draw_trial(len(out), rng, n_backgrounds, ppm,
                                  float(rng.uniform(*tilt_range))))
    return out


def pose_trials(distances: Sequence[float] = (1.0, 2.2), per_distance: int = 150,
                tilt_range: Tuple[float, float] = (0.0, 60.0), seed: int = 2,
                n_backgrounds: int = 51, module: float = MODULE,
                camera: CameraModel = CAMERA) -> List[Trial]:
    """Draw trials at fixed distances (px per module ``f module / d``), tilt uniform."""
    rng = np.random.default_rng(seed)
    out = []
    for d in distances:
        for _ in range(per_distance):
            out.append(draw_trial(len(out), rng, n_backgrounds, camera.fx * module / d,
                                  float(rng.uniform(*tilt_range)), module))
    return out


__all__ = ['detection_trials', 'draw_trial', 'Outcome', 'pose_nees', 'pose_trials',
           'render_trial',
           'run_trials', 'score', 'TAG_IDS', 'Trial']
