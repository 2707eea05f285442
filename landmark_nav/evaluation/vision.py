"""Offline evaluation of landmark detection and pose on rendered images (chapter §2.3).

Run ``python -m landmark_nav.evaluation.vision [detection|false|repeatability|shuttle|all]``
(shuttle: ``--procedure stop|approach|both``, ``--approach-rate HZ``) for the full-size
statistics (tables on stdout, ``--json FILE`` for the figures); the
tests run the same functions with the counts the acceptance criteria name.

Experiments (every image is rendered by :class:`~landmark_nav.sim.camera.CameraSimulator`
with a seeded generator; truth comes from the scene, never from the detector):

* :func:`detection_vs_size` -- Table 2: probability of detection against block pixels at
  in-plane rotations 0, 22.5 and 45 degrees, and how many detections decode to the right
  code (chapter camera: f = 525 px, 320 x 240).
* :func:`false_detections` -- landmark-free frames full of distractors (checkerboards of
  every size, line grids, text, tiles, posters); every detection is false.
* :func:`repeatability` -- Table 1: 100 frames each at 2.2 m and turn 0, 10, 30, 60
  degrees (f = 1050 px, 640 x 480, plumb-bob distortion, pixel noise); spread, absolute
  error, and the Gauss-Newton pose against ``cv2.solvePnP`` on the same corners.
* :func:`shuttle` -- §2.3.3: odometry corrected by landmark fixes on ``landmark_shuttle``,
  fixes taken standing at the 1 m point (the chapter's procedure) or also on the way there.

Geometry of a view: the camera sits at the world origin with world = its optical frame; the
landmark pose is given by the pose parameters ``v`` of :mod:`landmark_nav.vision.pose`
(landmark centre in the camera body frame, turn/tilt/roll).
"""

import argparse
from dataclasses import asdict, dataclass, replace
import json
import math
import sys
import time
from typing import Dict, List, Optional, Sequence, Tuple

from landmark_nav.evaluation.blas import single_threaded
from landmark_nav.geometry import relative
from landmark_nav.sim import textures
from landmark_nav.sim.camera import (CameraSimulator, landmark_plane, Photometry, Plane,
                                     RenderOptions)
from landmark_nav.sim.camera_scenarios import (CameraFrame, iter_landmark_shuttle,
                                               landmark_view, oracle_localizer,
                                               ShuttleArrival, ShuttleConfig, ShuttleSample,
                                               ViewOptions)
from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
from landmark_nav.vision.detector import detect_landmarks, DetectorParams
from landmark_nav.vision.landmark import LandmarkDesign
from landmark_nav.vision.localize import (camera_mount_matrix, FixCorrectedOdometry, planar,
                                          robot_pose_from_landmark)
from landmark_nav.vision.pose import (estimate_pose, POINT_SETS, pose_from_optical, PoseError,
                                      PoseParams, rotation_matrix, solve_pnp)
import numpy as np

_M = np.asarray(OPTICAL_FROM_BODY, dtype=float)

#: Table 2 camera of the chapter: focal length 525 px at 320 x 240.
TABLE2_CAMERA = CameraModel(320, 240, np.array([[525.0, 0.0, 159.5], [0.0, 525.0, 119.5],
                                                [0.0, 0.0, 1.0]]), np.zeros(5))
#: Table 1 camera of the chapter (f = 1050 px) at 640 x 480 with a plumb-bob lens.
TABLE1_CAMERA = CameraModel(640, 480, np.array([[1050.0, 0.0, 322.0], [0.0, 1048.0, 236.0],
                                                [0.0, 0.0, 1.0]]),
                            np.array([-0.21, 0.12, 0.0008, -0.0005, 0.0]))
#: A 640 x 480 webcam (f = 525 px) for the distractor scenes.
VGA_CAMERA = CameraModel(640, 480, np.array([[525.0, 0.0, 319.5], [0.0, 525.0, 239.5],
                                             [0.0, 0.0, 1.0]]), np.zeros(5))
#: Image formation of the detection experiments: mild defocus and 2 DN pixel noise.
DEFAULT_PHOTOMETRY = Photometry(noise_sigma=2.0, defocus_sigma=0.5)


def random_code(rng: np.random.Generator, design: LandmarkDesign) -> int:
    """Return a uniformly drawn valid code of the design."""
    while True:
        code = int(rng.integers(0, design.code_limit))
        if design.is_valid_code(code):
            return code


def landmark_in_view(code: int, design: LandmarkDesign, v: Sequence[float]) -> Plane:
    """Return the landmark plane at pose parameters ``v`` (camera = world origin, optical)."""
    v = np.asarray(v, dtype=float)
    return landmark_plane(code, design, _M @ rotation_matrix(v[3:]), _M @ v[:3])


def backdrop(rng: np.random.Generator, distance: float) -> Plane:
    """Return a plain wall facing the camera ``distance`` metres away, filling the view."""
    tex = textures.wall(rng, (150, 300))
    return Plane(tex, 0.012 * distance, _M @ rotation_matrix([0.0, 0.0, 0.0]),
                 _M @ np.array([distance, 0.0, 0.0]), label='wall')


def truth_corners(v: Sequence[float], design: LandmarkDesign, camera: CameraModel) -> np.ndarray:
    """Return the (4, 2) distorted pixels of the frame corners of a landmark at ``v``."""
    v = np.asarray(v, dtype=float)
    pts = design.frame_corners() @ rotation_matrix(v[3:]).T + v[:3]
    return camera.project(pts @ _M.T)


def _angle_errors(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    d = np.asarray(est, dtype=float)[..., 3:] - np.asarray(truth, dtype=float)[..., 3:]
    return (d + math.pi) % (2.0 * math.pi) - math.pi


# ---------------------------------------------------------------------- Table 2


@dataclass
class DetectionRow:
    """Detection statistics of one (rotation, block size) cell of Table 2."""

    rotation_deg: float
    block_pixels: float
    distance_m: float
    frames: int
    detected: int          # frames with a detection at the landmark (any code)
    correct: int           # detections at the landmark with the right code
    wrong: int             # detections with a wrong code (anywhere in the frame)
    frames_found: int      # frames with a frame candidate at the landmark (before decoding)

    @property
    def p_detect(self) -> float:
        """Probability of a correct detection per frame."""
        return self.correct / self.frames if self.frames else math.nan


@single_threaded
def detection_vs_size(block_pixels: Sequence[float] = (3.0, 3.5, 4.0, 4.5, 5.0, 6.0, 8.0),
                      rotations_deg: Sequence[float] = (0.0, 22.5, 45.0), frames: int = 100,
                      seed: int = 1, camera: CameraModel = TABLE2_CAMERA,
                      params: DetectorParams = DetectorParams()) -> List[DetectionRow]:
    """Measure detection and decoding against block pixels (Table 2) on ``landmark_views``.

    Each frame is a ``landmark_views`` view (:func:`~landmark_nav.sim.camera_scenarios.
    landmark_view`): a landmark with a random valid code on a wall with 2-5 distractors,
    random photometry (exposure, gradient, vignetting, gamma, defocus, motion blur in 30 %
    of the frames, noise), at the distance giving ``block_pixels`` (``f s / d``), in-plane
    rotation ``rotation +- 1 deg`` plus a random quarter turn, turn uniform in +-10 deg and
    tilt in +-5 deg, at a random place in the image. Default camera: the chapter's Table 2
    camera (f = 525 px, 320 x 240).

    Returns:
        One :class:`DetectionRow` per (rotation, block size).
    """
    design = LandmarkDesign()
    f = 0.5 * (camera.fx + camera.fy)
    rows = []
    for ri, rot in enumerate(rotations_deg):
        for bi, bp in enumerate(block_pixels):
            d = f * design.block_size / bp
            opts = ViewOptions(distance=d, turn_deg=(-10.0, 10.0), tilt_deg=(-5.0, 5.0),
                               roll_deg=(rot - 1.0, rot + 1.0), quarter_turns=True)
            cell_seed = int(seed) * 1000 + ri * 100 + bi
            row = DetectionRow(float(rot), float(bp), d, frames, 0, 0, 0, 0)
            for i in range(frames):
                frame = landmark_view(cell_seed, i, camera, opts)
                truth = frame.landmarks[0]
                tol = 0.5 * bp
                dbg: Dict = {}
                dets = detect_landmarks(frame.image, params, camera, debug=dbg)
                if any(_matches(fg.corners, truth.corners_px, tol, any_order=True)
                       for fg in dbg['grids']):
                    row.frames_found += 1
                hit = [dt for dt in dets if _matches(dt.corners, truth.corners_px, tol)]
                row.detected += bool(hit)
                row.correct += any(dt.code == truth.code for dt in hit)
                row.wrong += sum(dt.code != truth.code for dt in dets)
            rows.append(row)
    return rows


def _matches(corners: np.ndarray, truth: np.ndarray, tol: float, any_order: bool = False) -> bool:
    """Return whether the corners are within ``tol`` px of the truth (in order or rotated)."""
    shifts = range(4) if any_order else (0,)
    return any(float(np.max(np.linalg.norm(np.roll(corners, k, axis=0) - truth, axis=1))) < tol
               for k in shifts)


# ---------------------------------------------------------------------- false detections


@dataclass
class FalseDetectionResult:
    """Landmark-free frames and what the detector made of them."""

    frames: int
    false_detections: int
    frames_with_false: int
    frame_candidates: int          # four-edge frames found (then rejected by the code step)
    distractors: Dict[str, int]    # planes drawn per kind
    rejections: Dict[str, int]     # reasons the code step gave


def distractor_scene(rng: np.random.Generator, count: int) -> List[Plane]:
    """Return a wall and ``count`` random distractors at 0.4-3 m, every kind in turn."""
    planes = [backdrop(rng, 4.0)]
    kinds = textures.DISTRACTOR_KINDS
    first = int(rng.integers(len(kinds)))
    for k in range(count):
        tex, mpt, kind = textures.random_distractor(rng, kinds[(first + k) % len(kinds)])
        d = rng.uniform(0.4, 3.0)
        v = np.array([d, rng.uniform(-0.4, 0.4) * d, rng.uniform(-0.3, 0.3) * d,
                      rng.uniform(-math.pi, math.pi), rng.uniform(-0.5, 0.5),
                      rng.uniform(-1.0, 1.0)])
        planes.append(Plane(tex, mpt, _M @ rotation_matrix(v[3:]), _M @ v[:3], label=kind))
    return planes


@single_threaded
def false_detections(frames: int = 500, seed: int = 2, camera: CameraModel = VGA_CAMERA,
                     params: DetectorParams = DetectorParams(),
                     source: str = 'views') -> FalseDetectionResult:
    """Count detections on landmark-free frames full of distractors.

    Args:
        frames: number of frames.
        seed: random seed.
        camera: camera model.
        params: detector parameters.
        source: ``'views'``: ``landmark_views`` without the landmark (4-8 distractors on a
            wall, random photometry); ``'scattered'``: 2-5 distractors each at its own
            random pose 0.4-3 m away (every kind in turn) in front of a wall, defocus
            0-1 px, noise 1-4 DN, exposure 0.6-1.3.
    """
    if source not in ('views', 'scattered'):
        raise ValueError(f"source must be 'views' or 'scattered'; got {source!r}")
    rng = np.random.default_rng(seed)
    sim = CameraSimulator(camera)
    res = FalseDetectionResult(frames, 0, 0, 0, {}, {})
    opts = ViewOptions(with_landmark=False)
    for i in range(frames):
        if source == 'views':
            frame = landmark_view(int(seed), i, camera, opts)
            img, kinds = frame.image, frame.distractors
        else:
            planes = distractor_scene(rng, int(rng.integers(2, 6)))
            kinds = tuple(p.label for p in planes[1:])
            ph = Photometry(noise_sigma=float(rng.uniform(1.0, 4.0)),
                            defocus_sigma=float(rng.uniform(0.0, 1.0)),
                            exposure=float(rng.uniform(0.6, 1.3)))
            img = sim.render(planes, np.eye(3), np.zeros(3), ph, rng)
        for k in kinds:
            res.distractors[k] = res.distractors.get(k, 0) + 1
        dbg: Dict = {}
        dets = detect_landmarks(img, params, camera, debug=dbg)
        res.false_detections += len(dets)
        res.frames_with_false += bool(dets)
        res.frame_candidates += len(dbg['frames'])
        for r in dbg['readings']:
            key = r.reason or 'accepted'
            res.rejections[key] = res.rejections.get(key, 0) + 1
    return res


# ---------------------------------------------------------------------- Table 1


@dataclass
class RepeatabilityRow:
    """Pose statistics of one turn angle of Table 1 (lengths in m, angles in degrees)."""

    turn_deg: float
    distance_m: float
    frames: int
    detected: int
    block_pixels: float
    sigma_xy: float            # sqrt(var x + var y) of the Gauss-Newton position
    sigma_xyz: float
    sigma_roll: float
    sigma_tilt: float
    sigma_turn: float
    max_position_error: float  # max over frames of |p - p_true|
    max_angle_error: float     # max over frames and angles
    rms_position_gn: float
    rms_position_ippe: float
    rms_position_iterative: float
    rms_angle_gn: float
    rms_angle_ippe: float
    rms_angle_iterative: float
    mean_iterations: float
    pose_ms: float


@single_threaded
def repeatability(turns_deg: Sequence[float] = (0.0, 10.0, 30.0, 60.0), distance: float = 2.2,
                  frames: int = 100, seed: int = 3, camera: CameraModel = TABLE1_CAMERA,
                  params: DetectorParams = DetectorParams(),
                  pose_params: PoseParams = PoseParams(),
                  photometry: Photometry = DEFAULT_PHOTOMETRY,
                  centre_px: Tuple[float, float] = (400.0, 190.0),
                  supersample: int = 16) -> List[RepeatabilityRow]:
    """Measure the pose spread and error over repeated frames of a static view (Table 1).

    Each frame is a ``landmark_views`` view with fixed parameters: the landmark (code 156)
    ``distance`` metres away, its centre at pixel ``centre_px`` (off the optical axis, so
    the lens distortion matters), upright, turned by each angle relative to the line of
    sight, fixed ``photometry``; frames differ by their pixel noise (and the distractors
    around the landmark). The Gauss-Newton pose is compared with ``cv2.solvePnP``
    (IPPE_SQUARE and ITERATIVE) on the same detected corners; the truth comes from the
    scene. With ``pose_params.point_set == 'edges'`` the pose also uses the interior
    X-corners of the frame edges, and so does the comparison (IPPE for planar points in
    place of IPPE_SQUARE, and ITERATIVE, both unweighted).

    The images are rendered with ``supersample`` x ``supersample`` samples per pixel: with
    fewer the simulator places its edges only to a few hundredths of a pixel (at 4 x 4 the
    mean frame corner errors are up to 0.04 px, at 16 x 16 0.01 px), and at 2.2 m a
    landmark seen head-on turns by about 1 degree per 0.05 px of corner error, so the
    rendering and not the estimator would set the angle error.
    """
    design = LandmarkDesign()
    render = RenderOptions(supersample=supersample)
    rows = []
    for ti, turn in enumerate(turns_deg):
        opts = ViewOptions(distance=distance, turn_deg=float(turn), tilt_deg=0.0,
                           roll_deg=0.0, quarter_turns=False, code=156,
                           photometry=photometry, centre_px=centre_px)
        gn, ippe, it, bp, iters, truth = [], [], [], [], [], None
        t_pose = 0.0
        for i in range(frames):
            frame = landmark_view(int(seed) * 100 + ti, i, camera, opts, render)
            lt = frame.landmarks[0]
            truth = pose_from_optical(lt.rotation, lt.translation)
            dets = [d for d in detect_landmarks(frame.image, params, camera) if d.code == 156]
            if not dets:
                continue
            c = dets[0].corners
            # the solvePnP comparison uses the same points as the Gauss-Newton pose
            ec = dets[0].edge_corners if pose_params.point_set == 'edges' else None
            try:
                t0 = time.perf_counter()
                p = estimate_pose(c, camera, design, pose_params, edge_corners_px=ec)
                t_pose += time.perf_counter() - t0
                q = solve_pnp(c, camera, design, 'ippe_square' if ec is None else 'ippe',
                              edge_corners_px=ec)
                r = solve_pnp(c, camera, design, 'iterative', edge_corners_px=ec)
            except PoseError:
                continue
            gn.append(p.v)
            ippe.append(q.v)
            it.append(r.v)
            bp.append(dets[0].block_pixels)
            iters.append(p.iterations)
        n = len(gn)
        if n == 0:
            rows.append(RepeatabilityRow(float(turn), distance, frames, 0, *([math.nan] * 16)))
            continue
        gn, ippe, it = np.array(gn), np.array(ippe), np.array(it)

        def rms_pos(a):
            return float(np.sqrt(np.mean(np.sum((a[:, :3] - truth[:3]) ** 2, axis=1))))

        def rms_ang(a):
            return math.degrees(float(np.sqrt(np.mean(_angle_errors(a, truth) ** 2))))

        ang = np.degrees(_angle_errors(gn, truth))
        rows.append(RepeatabilityRow(
            turn_deg=float(turn), distance_m=distance, frames=frames, detected=n,
            block_pixels=float(np.mean(bp)),
            sigma_xy=float(np.sqrt(np.var(gn[:, 0]) + np.var(gn[:, 1]))),
            sigma_xyz=float(np.sqrt(np.sum(np.var(gn[:, :3], axis=0)))),
            sigma_roll=float(np.std(ang[:, 0])), sigma_tilt=float(np.std(ang[:, 1])),
            sigma_turn=float(np.std(ang[:, 2])),
            max_position_error=float(np.max(np.linalg.norm(gn[:, :3] - truth[:3], axis=1))),
            max_angle_error=float(np.max(np.abs(ang))),
            rms_position_gn=rms_pos(gn), rms_position_ippe=rms_pos(ippe),
            rms_position_iterative=rms_pos(it), rms_angle_gn=rms_ang(gn),
            rms_angle_ippe=rms_ang(ippe), rms_angle_iterative=rms_ang(it),
            mean_iterations=float(np.mean(iters)), pose_ms=1e3 * t_pose / n))
    return rows


# ---------------------------------------------------------------------- §2.3.3 shuttle


@dataclass
class ShuttleResult:
    """Arrivals at the near (1 m) point of ``landmark_shuttle`` (lengths in m)."""

    trips: int
    correction: str             # 'ekf', 'reset', 'oracle' or 'none'
    procedure: str              # 'stop' (fixes at the near point) or 'approach' (also driving)
    arrivals: int
    fixes: int                  # stops with at least one landmark fix
    frames: int                 # frames given to the detector (stops, far point, approach)
    detected_frames: int
    approach_frames: int        # frames at the far point and on the approach
    approach_fixes: int         # fixes applied from them
    max_error: float            # max distance true position -> near point over the trips
    p95_error: float
    mean_error: float
    final_error: float
    max_fix_error: float        # max |fix - true pose| (x, y) over the fixes
    max_fix_yaw_error_deg: float


class LandmarkLocalizer:
    """Robot fixes from camera frames: detect, estimate the pose, chain with map and mount.

    With ``ekf=True`` a :class:`~landmark_nav.vision.localize.FixCorrectedOdometry`
    integrates the odometry increments (:meth:`odometry`) and is updated with each fix and
    its covariance; the robot is then reset to the filter's estimate instead of the plain fix.
    """

    def __init__(self, config: ShuttleConfig, ekf: bool = True,
                 params: DetectorParams = DetectorParams(),
                 pose_params: PoseParams = PoseParams()) -> None:
        """Set up the landmark map (one landmark) and the camera mount of ``config``."""
        self.cfg = config
        t = np.eye(4)
        t[:3, :3] = config.landmark_rotation
        t[:3, 3] = config.landmark_position
        self.landmark = t
        self.mount = camera_mount_matrix([*config.mount, 0.0, 0.0, 0.0])
        self.params = params
        self.pose_params = pose_params
        self.filter = FixCorrectedOdometry(config.near_point, np.diag([1e-6, 1e-6, 1e-8])) \
            if ekf else None
        self.last_odom: Optional[np.ndarray] = None
        self.frames = 0
        self.detected = 0
        self.fixes: List[Tuple[np.ndarray, np.ndarray]] = []   # (fix, true pose)

    def odometry(self, sample: ShuttleSample) -> None:
        """Feed one odometry sample (predict with the increment since the last one)."""
        odom = np.asarray(sample.odom_pose, dtype=float)
        if self.filter is not None and self.last_odom is not None:
            self.filter.predict(relative(self.last_odom, odom))
        self.last_odom = odom

    def __call__(self, frame: CameraFrame) -> Optional[np.ndarray]:
        """Return the robot pose (x, y, yaw) implied by the landmark in ``frame``, or None."""
        self.frames += 1
        dets = [d for d in detect_landmarks(frame.image, self.params, frame.camera)
                if d.code == self.cfg.code]
        if not dets:
            return None
        try:
            pose = estimate_pose(dets[0].corners, frame.camera, self.cfg.design,
                                 self.pose_params, edge_corners_px=dets[0].edge_corners)
        except PoseError:
            return None
        self.detected += 1
        pose6, cov6 = robot_pose_from_landmark(pose, self.landmark, self.mount)
        fix, cov = planar(pose6, cov6)
        truth = self._true_pose(frame)
        self.fixes.append((fix, truth))
        if self.filter is None:
            return fix
        self.filter.update(fix, cov)
        return self.filter.x.copy()

    def _true_pose(self, frame: CameraFrame) -> np.ndarray:
        r_wb = frame.camera_rotation @ np.asarray(OPTICAL_FROM_BODY)
        t_wb = frame.camera_position - r_wb @ np.asarray(self.cfg.mount)
        return np.array([t_wb[0], t_wb[1], math.atan2(r_wb[1, 0], r_wb[0, 0])])


SHUTTLE_PROCEDURES = ('stop', 'approach')


@single_threaded
def shuttle(trips: int = 100, seed: int = 1, correction: str = 'ekf',
            config: Optional[ShuttleConfig] = None,
            params: DetectorParams = DetectorParams(),
            procedure: str = 'stop', approach_rate: float = 2.0) -> ShuttleResult:
    """Run ``landmark_shuttle`` with odometry corrected by landmark fixes (§2.3.3).

    The robot drives on its own estimate; at each stop at the near point it takes the
    scenario's stop frames, and the fixes from them (detector + Gauss-Newton pose + map +
    camera mount) correct it: ``'ekf'`` through
    :class:`~landmark_nav.vision.localize.FixCorrectedOdometry` (odometry increments predict,
    each fix updates with its covariance), ``'reset'`` by the scenario's reset to the mean
    fix, ``'none'`` not at all; ``'oracle'`` resets to the true
    pose (the scenario's perfect fixes: the best any detector can do).

    Procedures: ``'stop'`` (the chapter's) renders images only at the stops;
    ``'approach'`` (``ShuttleConfig.fix_while_driving``) also takes a frame at the far
    point once the robot faces the landmark and frames at ``approach_rate`` [Hz] while it
    drives to the near point (motion blur of the moving robot included), each fix
    correcting the estimate it steers on (with ``'ekf'``: the filter's estimate after the
    update). The figure of merit is the chapter's: the true distance of the robot from the
    near point when it arrives there (before that stop's fix), over all trips.
    """
    if correction not in ('ekf', 'reset', 'none', 'oracle'):
        raise ValueError(f"correction must be 'ekf', 'reset', 'none' or 'oracle'; got "
                         f'{correction!r}')
    if procedure not in SHUTTLE_PROCEDURES:
        raise ValueError(f"procedure must be 'stop' or 'approach'; got {procedure!r}")
    cfg = replace(config or ShuttleConfig(), trips=int(trips), image_rate=0.0,
                  fix_while_driving=procedure == 'approach',
                  approach_image_rate=float(approach_rate))
    loc = LandmarkLocalizer(cfg, ekf=correction == 'ekf', params=params)
    localize = {'none': None, 'oracle': oracle_localizer(cfg)}.get(correction, loc)
    errors = []
    fixes = approach_frames = approach_fixes = 0
    # without fixes the stop frames go to nobody: not rendered (the same run, drift only;
    # the approach frames are counted, so they are rendered)
    images = localize is not None or cfg.fix_while_driving
    for ev in iter_landmark_shuttle(seed, cfg, localize, images=images):
        if isinstance(ev, ShuttleSample):
            loc.odometry(ev)
        elif isinstance(ev, ShuttleArrival):
            if ev.trip > 0:
                errors.append(ev.error)
            fixes += ev.fix is not None
            approach_frames += ev.approach_frames
            approach_fixes += ev.approach_fixes
    err = np.array(errors) if errors else np.array([math.nan])
    fe = np.array([np.hypot(*(f[:2] - t[:2])) for f, t in loc.fixes]) if loc.fixes \
        else np.array([math.nan])
    fy = np.array([abs(math.remainder(f[2] - t[2], 2 * math.pi)) for f, t in loc.fixes]) \
        if loc.fixes else np.array([math.nan])
    return ShuttleResult(
        trips=int(trips), correction=correction, procedure=procedure, arrivals=len(errors),
        fixes=fixes, frames=loc.frames, detected_frames=loc.detected,
        approach_frames=approach_frames, approach_fixes=approach_fixes,
        max_error=float(err.max()),
        p95_error=float(np.percentile(err, 95)), mean_error=float(err.mean()),
        final_error=float(err[-1]), max_fix_error=float(fe.max()),
        max_fix_yaw_error_deg=math.degrees(float(fy.max())))


def format_shuttle(res: ShuttleResult) -> str:
    """Return the shuttle figures as text (cm)."""
    return (f'landmark_shuttle, {res.trips} round trips, fixes {res.procedure:8s} '
            f'correction {res.correction:6s}: arrival at the 1 m point max '
            f'{100 * res.max_error:.2f} cm, 95 % {100 * res.p95_error:.2f} cm, mean '
            f'{100 * res.mean_error:.2f} cm, last {100 * res.final_error:.2f} cm; '
            f'{res.detected_frames}/{res.frames} frames detected, {res.fixes} stop fixes, '
            f'{res.approach_fixes}/{res.approach_frames} approach fixes, '
            f'fix error max {100 * res.max_fix_error:.2f} cm / '
            f'{res.max_fix_yaw_error_deg:.2f} deg')


# ---------------------------------------------------------------------- printing


def format_detection(rows: Sequence[DetectionRow]) -> str:
    """Return Table 2 as text: P(detect) per rotation and block size, reads and errors."""
    sizes = sorted({r.block_pixels for r in rows})
    rots = sorted({r.rotation_deg for r in rows})
    cell = {(r.rotation_deg, r.block_pixels): r for r in rows}
    lines = ['Detection vs block pixels (P of a correct detection per frame; wrong codes):',
             'rotation ' + ''.join(f'{bp:>11.1f}' for bp in sizes)]
    for rot in rots:
        lines.append(f'{rot:6.1f}   ' + ''.join(
            f'{cell[rot, bp].p_detect:8.3f}/{cell[rot, bp].wrong:<2d}' for bp in sizes))
    det = sum(r.detected for r in rows)
    cor = sum(r.correct for r in rows)
    wrong = sum(r.wrong for r in rows)
    lines.append(f'reads: {det} detections, {cor} correct codes, {wrong} wrong codes '
                 f'({cor / det if det else math.nan:.4f} correct)')
    return '\n'.join(lines)


def format_repeatability(rows: Sequence[RepeatabilityRow]) -> str:
    """Return Table 1 as text (mm and degrees)."""
    lines = ['Repeatability at {:.1f} m (mm, deg); RMS error GN / IPPE / ITERATIVE:'.format(
        rows[0].distance_m if rows else math.nan),
        ' turn  n   blk  s_xy  s_xyz  s_roll s_tilt s_turn  maxpos maxang  '
        'pos_rms gn/ippe/it          ang_rms gn/ippe/it    it   ms']
    for r in rows:
        lines.append(
            f'{r.turn_deg:5.0f} {r.detected:3d} {r.block_pixels:5.1f} {1e3 * r.sigma_xy:5.2f} '
            f'{1e3 * r.sigma_xyz:5.2f}  {r.sigma_roll:6.3f} {r.sigma_tilt:6.3f} '
            f'{r.sigma_turn:6.3f}  {1e3 * r.max_position_error:6.2f} {r.max_angle_error:6.3f}  '
            f'{1e3 * r.rms_position_gn:5.2f}/{1e3 * r.rms_position_ippe:5.2f}/'
            f'{1e3 * r.rms_position_iterative:5.2f}  {r.rms_angle_gn:6.3f}/{r.rms_angle_ippe:6.3f}'
            f'/{r.rms_angle_iterative:6.3f}  {r.mean_iterations:4.1f} {r.pose_ms:4.1f}')
    return '\n'.join(lines)


def format_false(res: FalseDetectionResult) -> str:
    """Return the false-detection figures as text."""
    return (f'False detections: {res.false_detections} in {res.frames} landmark-free frames '
            f'({res.frames_with_false} frames); {res.frame_candidates} frame candidates '
            f'rejected by the code step {res.rejections}; distractors drawn {res.distractors}')


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the evaluation from the command line; print the tables."""
    ap = argparse.ArgumentParser(prog='python -m landmark_nav.evaluation.vision',
                                 description=__doc__.splitlines()[0])
    ap.add_argument('experiment', nargs='?', default='all',
                    choices=['detection', 'false', 'repeatability', 'shuttle', 'all'])
    ap.add_argument('--frames', type=int, default=None,
                    help='frames per cell (detection: 200, false: 1000 per source, '
                         'repeatability: 100 per turn) or round trips (shuttle: 100)')
    ap.add_argument('--seed', type=int, default=1, help='random seed (default 1)')
    ap.add_argument('--json', default=None, help='also write the figures to this JSON file')
    ap.add_argument('--procedure', default='both', choices=['stop', 'approach', 'both'],
                    help='shuttle: landmark fixes only standing at the 1 m point (stop, the '
                         "chapter's), also at the 3 m point and while approaching the 1 m "
                         'point (approach), or both (default)')
    ap.add_argument('--point-set', default=PoseParams().point_set, choices=POINT_SETS,
                    help='repeatability: pose from the four frame corners (frame, the '
                         "chapter's) or also the interior X-corners of the edges (edges, "
                         'the default)')
    ap.add_argument('--supersample', type=int, default=16,
                    help='repeatability: rendering samples per pixel and axis (default 16)')
    ap.add_argument('--approach-rate', type=float, default=2.0,
                    help='shuttle: camera rate on the approach [Hz] (default 2)')
    args = ap.parse_args(argv)
    out = {}
    todo = ['detection', 'false', 'repeatability', 'shuttle'] if args.experiment == 'all' \
        else [args.experiment]
    for name in todo:
        t0 = time.perf_counter()
        if name == 'detection':
            rows = detection_vs_size(frames=args.frames or 200, seed=args.seed)
            print(format_detection(rows))
            out[name] = [asdict(r) for r in rows]
        elif name == 'false':
            out[name] = {}
            for source in ('views', 'scattered'):
                res = false_detections(frames=args.frames or 1000, seed=args.seed + 1,
                                       source=source)
                print(f'[{source}] ' + format_false(res))
                out[name][source] = asdict(res)
        elif name == 'repeatability':
            out[name] = {}
            for distance in (2.2, 1.0):
                rows = repeatability(distance=distance, frames=args.frames or 100,
                                     seed=args.seed + 2, supersample=args.supersample,
                                     pose_params=PoseParams(point_set=args.point_set))
                print(format_repeatability(rows))
                out[name][str(distance)] = [asdict(r) for r in rows]
        elif name == 'shuttle':
            out[name] = []
            procs = SHUTTLE_PROCEDURES if args.procedure == 'both' else (args.procedure,)
            for proc in procs:
                # without fixes both procedures are the same run: once, with 'stop'
                for corr in ('ekf', 'reset', 'oracle') + (('none',) if proc == 'stop' else ()):
                    res = shuttle(trips=args.frames or 100, seed=args.seed, correction=corr,
                                  procedure=proc, approach_rate=args.approach_rate)
                    print(format_shuttle(res), flush=True)
                    out[name].append(asdict(res))
        print(f'({name}: {time.perf_counter() - t0:.1f} s)\n')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as fh:
            json.dump(out, fh, indent=2, default=float)
    return 0


if __name__ == '__main__':
    sys.exit(main())
