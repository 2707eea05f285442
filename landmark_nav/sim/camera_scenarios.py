"""Camera scenarios for the visual landmark: ``landmark_views`` and ``landmark_shuttle``.

Both are pure-python generators of :class:`CameraFrame` (image + camera model + ground truth)
that tests and evaluations iterate in memory; :mod:`landmark_nav.sim.camera_record` writes
them into bags.

Conventions
-----------
* Camera poses are world poses of the REP 103 optical frame (z forward, x right, y down).
* A landmark's ground truth is ``(rotation, translation)`` with
  ``p_optical = rotation @ p_landmark + translation``, the landmark frame of
  :mod:`landmark_nav.vision.landmark` (origin at the frame centre, x out of the printed
  face, y right when looking at it, z up).
* View angles (``landmark_views``) are relative to the line of sight: in the camera's
  REP 103 body frame (x forward, y left, z up; ``body = OPTICAL_FROM_BODY.T @ optical``)
  the landmark's orientation is ``R = L Rz(pi + turn) Ry(tilt) Rx(roll)`` (active
  rotations), where ``L`` (:func:`line_of_sight_frame`) turns the body x axis onto the
  direction of the landmark centre keeping z up. ``turn = tilt = roll = 0`` is a landmark
  facing the camera upright; ``turn`` rotates it about the vertical, ``tilt > 0`` tips its
  face downward (the visual navigation chapter's "down tilt", §2.2.4), ``roll`` is the
  in-plane rotation, counter-clockwise as seen by the camera. The angle between the
  landmark normal and the line of sight is ``acos(cos(turn) cos(tilt))``.
* Frames and stamps: frame ``i`` has stamp ``START_NS + i * 100 ms`` (landmark_views) or the
  simulation time (landmark_shuttle). Randomness of view ``i`` comes from
  ``np.random.default_rng([seed, i])`` (scene) and ``np.random.default_rng([seed, i, 1])``
  (pixel noise), so any view can be regenerated alone, bit for bit.
"""

from dataclasses import dataclass, field, replace
import math
import numbers
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple, Union

from landmark_nav.geometry import compose, relative, wrap_angle
from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np

from . import textures
from .camera import (CameraSimulator, landmark_plane, Photometry, Plane, RenderOptions,
                     rotation_x, rotation_y, rotation_z)
from .control import brake_speed, DECEL_MARGIN, limit_twist
from .robot import (measure_wheels, NS_PER_S, propagate_covariance, RobotParams, step_pose,
                    twist_to_wheels, wheel_to_twist)
from .scenarios import START_NS

VIEW_STEP_NS = 100_000_000
CAMERA_SCENARIOS = ('landmark_views', 'landmark_shuttle')


def default_camera() -> CameraModel:
    """Return the default simulated camera: 640 x 480, f = 600 px, mild barrel distortion.

    (hfov 56 deg; a frame block of 2.5 cm covers 5 px at 3 m and 3.75 px at 4 m.)
    """
    K = np.array([[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]])
    return CameraModel(640, 480, K, np.array([-0.12, 0.08, 0.0005, -0.0003, 0.0]))


def _ro(a: Any) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class LandmarkTruth:
    """Ground truth of one landmark in one frame.

    Attributes:
        code: the printed code.
        design: the landmark design.
        rotation: (3, 3) optical-from-landmark rotation.
        translation: (3,) landmark centre in the optical frame [m].
        corners_px: (4, 2) distorted pixels of the frame corners h'_1..h'_4 (top-left,
            top-right, bottom-right, bottom-left of the upright landmark, eq. 5); NaN if
            behind the camera.
        edge_corners_px: (4, k, 2) distorted pixels of every frame X-corner (k = 6 or 5),
            order of :meth:`LandmarkDesign.edge_corners`.
        block_px: pixels per frame block: ``sqrt(area of the corner quad) / (n_blocks - 2)``.
        in_view: True if every frame X-corner is in the image (1 px margin) and the camera
            sees the printed face.
        distance: distance camera centre -> landmark centre [m].
        view_angle: angle between the landmark normal and the direction to the camera [rad].
        params: the view parameters used (e.g. ``turn``, ``tilt``, ``roll`` [rad]).
    """

    code: int
    design: LandmarkDesign
    rotation: np.ndarray
    translation: np.ndarray
    corners_px: np.ndarray
    edge_corners_px: np.ndarray
    block_px: float
    in_view: bool
    distance: float
    view_angle: float
    params: Dict[str, float] = field(default_factory=dict)

    def points_to_camera(self, points: np.ndarray) -> np.ndarray:
        """Map (N, 3) landmark-frame points to the optical frame."""
        return np.asarray(points, dtype=float) @ self.rotation.T + self.translation


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One rendered camera image with its ground truth.

    Attributes:
        index: frame number in its scenario.
        stamp_ns: stamp [ns].
        image: (H, W) uint8 mono8 image.
        camera: the camera model that took it.
        landmarks: ground truth of every landmark of the scene that faces the camera and is
            at least partly in front of it (check ``in_view``).
        camera_rotation: (3, 3) world-from-optical rotation.
        camera_position: (3,) optical centre in the world [m].
        photometry: the image-formation effects of this frame.
        distractors: kinds of the distractors in the scene.
    """

    index: int
    stamp_ns: int
    image: np.ndarray
    camera: CameraModel
    landmarks: Tuple[LandmarkTruth, ...]
    camera_rotation: np.ndarray
    camera_position: np.ndarray
    photometry: Photometry
    distractors: Tuple[str, ...] = ()


def landmark_truth(code: int, design: LandmarkDesign, rotation: np.ndarray,
                   translation: np.ndarray, camera: CameraModel,
                   params: Optional[Dict[str, float]] = None) -> LandmarkTruth:
    """Build the ground truth of a landmark at (rotation, translation) in the optical frame."""
    R = np.asarray(rotation, dtype=float)
    t = np.asarray(translation, dtype=float).reshape(3)
    corners = camera.project(design.frame_corners() @ R.T + t)
    edges = design.edge_corners()
    edge_px = camera.project(edges.reshape(-1, 3) @ R.T + t).reshape(edges.shape[:2] + (2,))
    facing = float(R[:, 0] @ t) < 0.0
    ok = bool(facing and np.all(np.isfinite(edge_px))
              and np.all(camera.in_image(edge_px.reshape(-1, 2), margin=1.0)))
    if np.all(np.isfinite(corners)):
        x, y = corners[:, 0], corners[:, 1]
        area = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
        block_px = math.sqrt(area) / (design.n_blocks - 2)
    else:
        block_px = float('nan')
    dist = float(np.linalg.norm(t))
    cosang = float(-(R[:, 0] @ t) / dist) if dist > 0 else 1.0
    return LandmarkTruth(code=int(code), design=design, rotation=_ro(R), translation=_ro(t),
                         corners_px=_ro(corners), edge_corners_px=_ro(edge_px),
                         block_px=float(block_px), in_view=ok, distance=dist,
                         view_angle=math.acos(max(-1.0, min(1.0, cosang))),
                         params=dict(params or {}))


def random_photometry(rng: np.random.Generator) -> Photometry:
    """Return random but realistic image-formation effects for one frame.

    exposure U(0.6, 1.2), illumination gradient U(-0.3, 0.3) per axis, vignetting U(0, 0.3),
    gamma U(1.8, 2.4), defocus sigma U(0, 0.7) px, motion blur U(0, 2) px in 30 % of the
    frames, noise sigma U(1, 3) DN plus shot noise 0.02 DN^2 per DN.
    """
    blur = float(rng.uniform(0.0, 2.0)) if rng.random() < 0.3 else 0.0
    return Photometry(exposure=float(rng.uniform(0.6, 1.2)),
                      gradient=(float(rng.uniform(-0.3, 0.3)), float(rng.uniform(-0.3, 0.3))),
                      vignetting=float(rng.uniform(0.0, 0.3)), gamma=float(rng.uniform(1.8, 2.4)),
                      defocus_sigma=float(rng.uniform(0.0, 0.7)), motion_blur=blur,
                      motion_angle=float(rng.uniform(0.0, math.pi)),
                      noise_sigma=float(rng.uniform(1.0, 3.0)), shot_noise=0.02)


Spec = Union[float, Tuple[float, float], Sequence[float]]


def sample_spec(rng: np.random.Generator, spec: Spec, what: str) -> float:
    """Draw a value: a number is fixed, a 2-tuple ``(lo, hi)`` uniform, a list a random choice."""
    if isinstance(spec, numbers.Real) and not isinstance(spec, bool):
        return float(spec)
    if isinstance(spec, tuple) and len(spec) == 2:
        lo, hi = float(spec[0]), float(spec[1])
        if not lo <= hi:
            raise ValueError(f'{what}: need lo <= hi; got {spec}')
        return float(rng.uniform(lo, hi)) if hi > lo else lo
    if isinstance(spec, list) and spec:
        return float(spec[int(rng.integers(len(spec)))])
    raise ValueError(f'{what} must be a number, a (lo, hi) tuple or a non-empty list; '
                     f'got {spec!r}')


def random_code(rng: np.random.Generator, design: LandmarkDesign) -> int:
    """Draw a code uniformly from the valid codes of ``design``."""
    while True:
        code = int(rng.integers(design.code_limit))
        if design.is_valid_code(code):
            return code


def _place_on_board(rng: np.random.Generator, board_R: np.ndarray, board_t: np.ndarray,
                    keep_out: List[Tuple[float, float, float]], reach: float, offset: float,
                    kind: Optional[str] = None) -> Optional[Plane]:
    """Place one random distractor on a board, clear of the keep-out circles (y, z, r)."""
    tex, mpt, kind = textures.random_distractor(rng, kind)
    h, w = tex.shape
    radius = 0.5 * math.hypot(h * mpt, w * mpt)
    for _ in range(20):
        y, z = rng.uniform(-reach, reach, 2)
        if all(math.hypot(y - ky, z - kz) > radius + kr for ky, kz, kr in keep_out):
            keep_out.append((float(y), float(z), radius))
            R = board_R @ rotation_x(float(rng.uniform(-math.pi, math.pi)))
            t = board_t + board_R @ np.array([offset, y, z])
            return Plane(tex, mpt, R, t, label=kind)
    return None


@dataclass(frozen=True)
class ViewOptions:
    """What :func:`landmark_view` draws (see :func:`sample_spec` for the value specs).

    Attributes:
        distance: camera -> landmark centre [m] (default U(0.5, 4)).
        turn_deg: turn about the vertical [deg] (default U(-60, 60)).
        tilt_deg: down tilt [deg] (default U(-20, 20)).
        roll_deg: in-plane rotation [deg] (default one of 0, 22.5, 45).
        quarter_turns: add a random multiple of 90 deg to the roll (exercises all four code
            orientations; the corner filters see the same angles).
        code: fixed code, or None for a random valid code per frame.
        design: landmark design.
        with_landmark: False renders the same kind of scene without the landmark.
        distractors: number of distractors (spec; default 2..5, 4..8 without landmark).
        photometry: fixed :class:`Photometry`, or None for :func:`random_photometry`.
        px_per_block: texture resolution of the printed landmark.
        centre_px: fixed (u, v) pixel of the landmark centre (then the same parameters give
            the same pose in every frame), or None for a random position that keeps the
            landmark and its quiet zone in the image.
    """

    distance: Spec = (0.5, 4.0)
    turn_deg: Spec = (-60.0, 60.0)
    tilt_deg: Spec = (-20.0, 20.0)
    roll_deg: Spec = field(default_factory=lambda: [0.0, 22.5, 45.0])
    quarter_turns: bool = True
    code: Optional[int] = None
    design: LandmarkDesign = LandmarkDesign()
    with_landmark: bool = True
    distractors: Optional[Spec] = None
    photometry: Optional[Photometry] = None
    px_per_block: int = 64
    centre_px: Optional[Tuple[float, float]] = None


def line_of_sight_frame(direction: np.ndarray) -> np.ndarray:
    """Return the body-frame rotation whose x axis points along ``direction``, z kept up.

    Columns: x = the unit direction, y = up x x normalized (left), z = x x y (up as far as
    possible). The identity for a direction along the body x axis.
    """
    x = np.asarray(direction, dtype=float)
    x = x / np.linalg.norm(x)
    y = np.cross([0.0, 0.0, 1.0], x)
    n = np.linalg.norm(y)
    y = np.array([0.0, 1.0, 0.0]) if n < 1e-9 else y / n
    return np.column_stack([x, y, np.cross(x, y)])


def view_scene(rng: np.random.Generator, camera: CameraModel, opts: ViewOptions
               ) -> Tuple[List[Plane], Optional[Tuple[int, np.ndarray, np.ndarray, Dict]],
                          Tuple[str, ...]]:
    """Sample one landmark_views scene; the camera optical frame is the world frame.

    Returns:
        ``(planes, landmark, distractor_kinds)`` with ``landmark = (code, R, t, params)`` in
        the optical frame, or None without a landmark.
    """
    design = opts.design
    d = sample_spec(rng, opts.distance, 'distance')
    turn = math.radians(sample_spec(rng, opts.turn_deg, 'turn_deg'))
    tilt = math.radians(sample_spec(rng, opts.tilt_deg, 'tilt_deg'))
    roll = math.radians(sample_spec(rng, opts.roll_deg, 'roll_deg'))
    if opts.quarter_turns:
        roll += 0.5 * math.pi * int(rng.integers(4))
    if not d > 0:
        raise ValueError(f'distance must be > 0; got {d}')
    code = opts.code if opts.code is not None else random_code(rng, design)
    design.check_code(code)
    # orientation relative to the line of sight (turn = tilt = 0: facing the camera)
    R_view = rotation_z(math.pi + turn) @ rotation_y(tilt)
    R_roll = rotation_x(roll)
    # place the centre at a random image position that keeps the frame (and most of the
    # quiet zone) inside the image; fall back to the optical axis
    half = 0.5 * design.printed_width
    quiet = design.grid_to_landmark(np.array([[-1.0, -1.0], [design.n_blocks + 1.0, -1.0],
                                              [design.n_blocks + 1.0, design.n_blocks + 1.0],
                                              [-1.0, design.n_blocks + 1.0]]))
    t = np.array([0.0, 0.0, d])
    R_los = np.eye(3)
    for _ in range(30 if opts.centre_px is None else 1):
        if opts.centre_px is None:
            u = rng.uniform(0.1, 0.9) * camera.width
            v = rng.uniform(0.1, 0.9) * camera.height
        else:
            u, v = (float(c) for c in opts.centre_px)
        ray = camera.back_project(np.array([[u, v]]))[0]
        los = line_of_sight_frame(OPTICAL_FROM_BODY.T @ ray)
        R_try = OPTICAL_FROM_BODY @ los @ R_view @ R_roll
        px = camera.project(quiet @ R_try.T + ray * d)
        fits = bool(np.all(np.isfinite(px)) and np.all(camera.in_image(px, margin=2.0)))
        if fits or opts.centre_px is not None:
            t, R_los = ray * d, los
            break
    R = OPTICAL_FROM_BODY @ R_los @ R_view @ R_roll
    n_dis = opts.distractors
    if n_dis is None:
        n_dis = (2.0, 5.0) if opts.with_landmark else (4.0, 8.0)
    count = int(round(sample_spec(rng, n_dis, 'distractors')))
    reach = max(0.6, 0.7 * t[2] * camera.width / camera.fx)
    # the wall carrying the landmark (not rolled with it) fills the view
    board_w = 2.0 + 6.0 * d
    wall_tex = textures.wall(rng, (300, 300), mean=float(rng.uniform(150, 230)))
    board_R = OPTICAL_FROM_BODY @ R_los @ R_view
    board_t = t - R[:, 0] * 0.003
    planes = [Plane(wall_tex, board_w / 300.0, board_R, board_t, label='wall', detail=False)]
    keep_out = [(0.0, 0.0, half * math.sqrt(2.0) + 0.01)] if opts.with_landmark else []
    kinds = []
    for _ in range(count):
        p = _place_on_board(rng, board_R, board_t, keep_out, reach, 0.0015)
        if p is not None:
            planes.append(p)
            kinds.append(p.label)
    landmark = None
    if opts.with_landmark:
        planes.append(landmark_plane(code, design, R, t, opts.px_per_block))
        landmark = (int(code), R, t, {'distance': d, 'turn': turn, 'tilt': tilt, 'roll': roll})
    return planes, landmark, tuple(kinds)


_SIMULATORS: Dict[Tuple, CameraSimulator] = {}


def simulator_for(camera: CameraModel, options: RenderOptions = RenderOptions()
                  ) -> CameraSimulator:
    """Return a cached :class:`CameraSimulator` for a camera (keyed by its parameters)."""
    key = (camera.width, camera.height, tuple(camera.K.ravel()), tuple(camera.D),
           camera.distortion_model, options)
    sim = _SIMULATORS.get(key)
    if sim is None:
        if len(_SIMULATORS) > 8:
            _SIMULATORS.clear()
        sim = CameraSimulator(camera, options)
        _SIMULATORS[key] = sim
    return sim


def landmark_view(seed: int, index: int, camera: Optional[CameraModel] = None,
                  options: ViewOptions = ViewOptions(),
                  render: RenderOptions = RenderOptions()) -> CameraFrame:
    """Render view ``index`` of the ``landmark_views`` scenario (see the module docstring).

    Args:
        seed: scenario seed (non-negative int).
        index: frame number (non-negative int); view ``i`` does not depend on the others.
        camera: camera model (default :func:`default_camera`).
        options: view parameter ranges, code, distractors, photometry.
        render: static rendering options.
    """
    for name, value in (('seed', seed), ('index', index)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
            raise ValueError(f'{name} must be a non-negative int; got {value!r}')
    camera = camera if camera is not None else default_camera()
    rng = np.random.default_rng([int(seed), int(index)])
    planes, lm, kinds = view_scene(rng, camera, options)
    ph = options.photometry if options.photometry is not None else random_photometry(rng)
    sim = simulator_for(camera, render)
    eye = np.eye(3)
    image = sim.render(planes, eye, np.zeros(3), ph, np.random.default_rng([seed, index, 1]))
    truths: Tuple[LandmarkTruth, ...] = ()
    if lm is not None:
        code, R, t, params = lm
        truths = (landmark_truth(code, options.design, R, t, camera, params),)
    image.setflags(write=False)
    return CameraFrame(index=int(index), stamp_ns=START_NS + int(index) * VIEW_STEP_NS,
                       image=image, camera=camera, landmarks=truths,
                       camera_rotation=_ro(eye), camera_position=_ro(np.zeros(3)),
                       photometry=ph, distractors=kinds)


def iter_landmark_views(seed: int, n_frames: int, start: int = 0,
                        camera: Optional[CameraModel] = None,
                        options: ViewOptions = ViewOptions(),
                        render: RenderOptions = RenderOptions()) -> Iterator[CameraFrame]:
    """Yield views ``start .. start + n_frames - 1`` of ``landmark_views`` (static views).

    Static views of a landmark at 0.5-4 m, turn 0-60 deg either way, tilt, in-plane rotation
    0 / 22.5 / 45 deg (plus quarter turns), on a wall with distractors, with random
    illumination, blur and noise; ``ViewOptions(with_landmark=False)`` gives landmark-free
    frames with distractors. Fix any parameter through ``options`` (e.g. Table 1 of the
    chapter: ``ViewOptions(distance=2.2, turn_deg=30.0, tilt_deg=0.0, roll_deg=0.0,
    quarter_turns=False, code=156, centre_px=(319.5, 239.5))`` gives the same pose in every
    frame, with fresh noise and photometry).
    """
    if isinstance(n_frames, bool) or not isinstance(n_frames, numbers.Integral) or n_frames < 0:
        raise ValueError(f'n_frames must be a non-negative int; got {n_frames!r}')
    for i in range(int(start), int(start) + int(n_frames)):
        yield landmark_view(seed, i, camera, options, render)


# ---------------------------------------------------------------------- landmark shuttle
@dataclass(frozen=True)
class ShuttleConfig:
    """The ``landmark_shuttle`` set-up (visual navigation chapter §2.3.3).

    A 6 m x 4 m room (x in [-1, 5], y in [-2, 2]); the landmark hangs on the wall x = 5,
    facing -x, its centre at ``(5 - 0.003, 0, landmark_height)``. The robot shuttles between
    ``near_point`` (1 m in front of the landmark, facing it) and ``far_point`` (3 m), turning
    in place at both ends (alternately counter-clockwise and clockwise), driving and turning
    on its own pose estimate: odometry (eqs. 1-7 with the wheel radii and axle the robot
    believes in, ``odometry_factors``) composed with the last landmark fix. The true robot
    moves with the systematic errors k1, k2, k3 of :class:`RobotParams` (eqs. 17-18) and
    noisy encoders, so its odometry drifts.

    Measured with perfect fixes (:func:`oracle_localizer`), seed 1, 100 trips: a calibrated
    robot (default, odometry factors = the true k1, k2, k3; only the encoder noise is left)
    arrives within 6.0 cm of the near point (95 % within 3.2 cm, mean 1.5 cm; without fixes
    28 cm off after 100 trips); an uncalibrated one (``odometry_factors=(1, 1, 1)``) within
    16.5 cm (mean 11.4 cm; 1.9 m off after 100 trips without fixes) -- the chapter reports
    10 cm. The arrival error is the odometry drift of one round trip: a landmark detector
    cannot do better than the oracle (stop-only procedure, the chapter's).

    With ``fix_while_driving`` the robot also takes fixes on the way back: one standing at
    the far point once it has turned to face the landmark, then frames at
    ``approach_image_rate`` while it drives to the near point (facing the landmark, turning
    motion blurred as any moving frame). Each fix corrects the estimate the robot steers and
    stops on, so the arrival error is the drift of the last few centimetres plus the fix
    error instead of the drift of a whole round trip. Measured with the landmark detector and
    the EKF of :mod:`landmark_nav.vision.localize` (2 Hz, 100 trips): max 1.8 cm (seed 1),
    0.9 cm (seed 2), 1.3 cm (seed 3); with perfect fixes 0.2 cm (seed 2).

    Attributes:
        trips: number of round trips (near -> far -> near).
        robot: robot and odometry error parameters.
        camera: camera model (default :func:`default_camera`).
        mount: (x, y, z) of the optical centre in ``base_link`` [m]; the camera looks along
            the robot's x axis (optical = ``OPTICAL_FROM_BODY`` of base_link).
        landmark_height: height of the landmark centre above the floor [m].
        code: the landmark's code.
        design: landmark design.
        near_distance: distance of the near point from the wall [m] (1 m, the chapter's).
        far_distance: distance of the far point from the wall [m] (3 m).
        stop_frames: frames taken while standing at the near point (landmark fixes).
        stop_seconds: standing time at the near point [s].
        image_rate: camera rate while moving [Hz] (0 = images only at the stops).
        exposure_time: exposure [s] for the motion blur of the turning robot.
        photometry: base photometry of every frame (noise, gamma ...).
        odometry_factors: (k1, k2, k3) the robot's odometry believes in; None (default) =
            the true ones of ``robot`` (a calibrated robot), (1, 1, 1) = uncalibrated.
        fix_while_driving: also take landmark fixes at the far point (after turning to the
            landmark) and while approaching the near point; False (default) = fixes only
            while standing at the near point (the chapter's procedure).
        approach_image_rate: camera rate [Hz] while approaching the near point with
            ``fix_while_driving`` (replaces ``image_rate`` there; 0 = only the far-point
            frame).
    """

    trips: int = 100
    robot: RobotParams = RobotParams()
    camera: Optional[CameraModel] = None
    mount: Tuple[float, float, float] = (0.10, 0.0, 0.40)
    landmark_height: float = 0.40
    code: int = 156
    design: LandmarkDesign = LandmarkDesign()
    near_distance: float = 1.0
    far_distance: float = 3.0
    stop_frames: int = 3
    stop_seconds: float = 1.0
    image_rate: float = 1.0
    exposure_time: float = 0.01
    photometry: Photometry = Photometry(gamma=2.2, noise_sigma=2.0, shot_noise=0.02)
    odometry_factors: Optional[Tuple[float, float, float]] = None
    fix_while_driving: bool = False
    approach_image_rate: float = 2.0

    WALL_X = 5.0

    def __post_init__(self) -> None:
        """Validate the camera rates."""
        for name in ('image_rate', 'approach_image_rate'):
            v = getattr(self, name)
            if not (isinstance(v, numbers.Real) and math.isfinite(v) and v >= 0):
                raise ValueError(f'ShuttleConfig.{name} must be a finite rate >= 0 [Hz]; '
                                 f'got {v!r}')

    @property
    def believed_factors(self) -> Tuple[float, float, float]:
        """Return the (k1, k2, k3) the robot's odometry uses (the true ones if None)."""
        if self.odometry_factors is None:
            return (self.robot.k1, self.robot.k2, self.robot.k3)
        return tuple(float(v) for v in self.odometry_factors)

    @property
    def near_point(self) -> np.ndarray:
        """Robot pose (x, y, yaw) at the near point, facing the landmark."""
        return np.array([self.WALL_X - self.near_distance, 0.0, 0.0])

    @property
    def far_point(self) -> np.ndarray:
        """Robot position (x, y, yaw) of the far point, facing the landmark."""
        return np.array([self.WALL_X - self.far_distance, 0.0, 0.0])

    @property
    def landmark_rotation(self) -> np.ndarray:
        """World-from-landmark rotation (the landmark faces -x)."""
        return rotation_z(math.pi)

    @property
    def landmark_position(self) -> np.ndarray:
        """World position of the landmark centre [m]."""
        return np.array([self.WALL_X - 0.003, 0.0, self.landmark_height])

    def camera_model(self) -> CameraModel:
        """Return the camera model in use."""
        return self.camera if self.camera is not None else default_camera()

    def camera_pose(self, pose: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
        """Return (world-from-optical rotation, optical centre) for a robot pose (x, y, yaw)."""
        x, y, yaw = (float(v) for v in pose)
        Rz = rotation_z(yaw)
        return Rz @ OPTICAL_FROM_BODY.T, np.array([x, y, 0.0]) + Rz @ np.asarray(self.mount)


def shuttle_scene(config: ShuttleConfig, seed: int) -> List[Plane]:
    """Return the planes of the shuttle room: floor, four walls, landmark, wall posters."""
    rng = np.random.default_rng([int(seed), 0, 7])
    x0, x1, y0, y1, hgt = -1.0, config.WALL_X, -2.0, 2.0, 2.5
    planes = []
    floor = textures.floor_tiles(rng, 20, 30, 30)  # 0.2 m tiles of 30 texels + 1 grout
    mpt = 0.2 / 31.0
    # floor: normal +z, texture right = +x, texture up = +y; cropped to the room
    floor = floor[:int((y1 - y0) / mpt), :int((x1 - x0) / mpt)]
    R_floor = np.column_stack([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    planes.append(Plane(floor, mpt, R_floor,
                        [0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0], label='floor', detail=False))

    def wall(normal_yaw: float, centre_xy: Tuple[float, float], length: float) -> Plane:
        n = 300
        tex = textures.wall(rng, (int(n * hgt / length), n), mean=float(rng.uniform(170, 220)))
        R = rotation_z(normal_yaw)
        return Plane(tex, length / n, R, [centre_xy[0], centre_xy[1], 0.5 * tex.shape[0]
                                          * length / n], label='wall', detail=False)

    planes.append(wall(math.pi, (x1, 0.0), y1 - y0))  # landmark wall, faces -x
    planes.append(wall(0.0, (x0, 0.0), y1 - y0))
    planes.append(wall(0.5 * math.pi, (0.5 * (x0 + x1), y0), x1 - x0))
    planes.append(wall(-0.5 * math.pi, (0.5 * (x0 + x1), y1), x1 - x0))
    R_lm = config.landmark_rotation
    planes.append(landmark_plane(config.code, config.design, R_lm, config.landmark_position))
    # a few distractors on the landmark wall, clear of the landmark
    board_R = R_lm
    board_t = np.array([x1 - 0.002, 0.0, config.landmark_height])
    keep = [(0.0, 0.0, 0.5 * config.design.printed_width * math.sqrt(2.0) + 0.05)]
    for kind in ('poster', 'checkerboard', 'text', 'grid'):
        p = _place_on_board(rng, board_R, board_t, keep, 0.7, 0.0, kind)
        if p is not None and np.all(p.to_world(p.local_corners())[:, 2] > 0.05):
            planes.append(p)
    return planes


def robot_pose_from_landmark(rotation: np.ndarray, translation: np.ndarray,
                             landmark_rotation: np.ndarray, landmark_position: np.ndarray,
                             mount: Sequence[float]) -> np.ndarray:
    """Return the robot pose (x, y, yaw) implied by a landmark seen at (rotation, translation).

    Args:
        rotation: (3, 3) optical-from-landmark rotation (a detection or the truth).
        translation: (3,) landmark centre in the optical frame.
        landmark_rotation: (3, 3) world-from-landmark rotation (the landmark map).
        landmark_position: (3,) landmark centre in the world.
        mount: (x, y, z) of the optical centre in base_link (camera looking along x).

    The 3-D robot pose ``world_from_base = world_from_landmark * inv(optical_from_landmark) *
    inv(base_from_optical)`` is projected to the floor (yaw of its x axis).
    """
    R_wl = np.asarray(landmark_rotation, dtype=float)
    t_wl = np.asarray(landmark_position, dtype=float)
    R_ol = np.asarray(rotation, dtype=float)
    t_ol = np.asarray(translation, dtype=float)
    R_wo = R_wl @ R_ol.T
    t_wo = t_wl - R_wo @ t_ol
    R_bo = OPTICAL_FROM_BODY.T
    R_wb = R_wo @ R_bo.T
    t_wb = t_wo - R_wb @ np.asarray(mount, dtype=float)
    return np.array([t_wb[0], t_wb[1], math.atan2(R_wb[1, 0], R_wb[0, 0])])


@dataclass(frozen=True, eq=False)
class ShuttleSample:
    """Robot state at one control step (10 Hz) of ``landmark_shuttle``.

    Attributes:
        stamp_ns: stamp [ns].
        true_pose: (3,) true pose in the world (map) frame, yaw wrapped.
        odom_pose: (3,) raw wheel odometry (odom frame == world at the start), yaw wrapped.
        odom_covariance: (3, 3) odometry covariance (grows without bound).
        estimate: (3,) the robot's own estimate: odometry composed with the last fix.
        true_twist: (2,) true (v, w) of the step that ends here.
        odom_twist: (2,) (v, w) from the measured wheel speeds of that step.
        wheel_positions: (2,) measured accumulated wheel angles [rad].
        wheel_velocities: (2,) measured wheel speeds [rad/s] of that step.
    """

    stamp_ns: int
    true_pose: np.ndarray
    odom_pose: np.ndarray
    odom_covariance: np.ndarray
    estimate: np.ndarray
    true_twist: np.ndarray
    odom_twist: np.ndarray
    wheel_positions: np.ndarray
    wheel_velocities: np.ndarray


@dataclass(frozen=True, eq=False)
class ShuttleArrival:
    """The robot stopped at the near point (believing it is there), before the fix.

    Attributes:
        trip: 0 for the start, then 1..trips.
        stamp_ns: stamp of the arrival [ns].
        true_pose: (3,) where the robot really is.
        estimate: (3,) where it believes it is (near point up to the stop tolerance).
        error: distance true -> near point [m] (the chapter's "position at the one-meter
            point").
        fix: (3,) the landmark fix applied (mean of the stop frames' fixes), or None.
        approach_frames: frames taken at the far point and on the approach since the last
            stop (``fix_while_driving``).
        approach_fixes: landmark fixes applied from them.
    """

    trip: int
    stamp_ns: int
    true_pose: np.ndarray
    estimate: np.ndarray
    error: float
    fix: Optional[np.ndarray]
    approach_frames: int = 0
    approach_fixes: int = 0


ShuttleEvent = Union[ShuttleSample, CameraFrame, ShuttleArrival]
Localizer = Callable[[CameraFrame], Optional[np.ndarray]]


class _ShuttleRobot:
    """Step simulation: true robot (eqs. 17-18), encoders, odometry and the estimate."""

    def __init__(self, config: ShuttleConfig, rng: np.random.Generator, start_ns: int) -> None:
        self.cfg = config
        self.p = config.robot
        self.factors = config.believed_factors
        self.rng = rng
        pose0 = config.near_point
        self.true = pose0.copy()
        self.odom = pose0.copy()
        self.cov = np.zeros((3, 3))
        self.correction = np.zeros(3)  # map <- odom
        self.v = 0.0
        self.w = 0.0
        self.stamp_ns = int(start_ns)
        self.wheel_pos = np.zeros(2)
        self.true_twist = np.zeros(2)
        self.odom_twist = np.zeros(2)
        self.wheel_vel = np.zeros(2)

    @property
    def estimate(self) -> np.ndarray:
        """Return the robot's own pose estimate in the map frame."""
        return compose(self.correction, self.odom)

    def apply_fix(self, fix: np.ndarray) -> None:
        """Reset the estimate to a landmark fix: correction = fix (-) odom."""
        self.correction = compose(fix, relative(self.odom, np.zeros(3)))

    def step(self, v_des: float, w_des: float) -> ShuttleSample:
        p = self.p
        dt = p.sample_time
        v, w = self.v, self.w = limit_twist(p, v_des, w_des, self.v, self.w)
        wl, wr = twist_to_wheels(v, w, p.wheel_radius, p.axle_length)
        cmd = np.array([[float(wl), float(wr)]])
        r, b = p.wheel_radius, p.axle_length
        vt, wt = wheel_to_twist(cmd[:, 0], cmd[:, 1], p.k1 * r, p.k2 * r, p.k3 * b)  # eq. 17-18
        self.true = step_pose(self.true, float(vt[0]), float(wt[0]), dt)
        meas, pos = measure_wheels(cmd, p, self.rng)
        f1, f2, f3 = self.factors
        vo, wo = wheel_to_twist(meas[:, 0], meas[:, 1], f1 * r, f2 * r, f3 * b)  # eqs. 6-7
        new_odom = step_pose(self.odom, float(vo[0]), float(wo[0]), dt)
        self.cov = propagate_covariance(np.vstack([self.odom, new_odom]), vo, wo, dt, p,
                                        self.cov)[-1]
        self.odom = new_odom
        self.wheel_pos = self.wheel_pos + pos[-1]
        self.wheel_vel = meas[0]
        self.true_twist = np.array([float(vt[0]), float(wt[0])])
        self.odom_twist = np.array([float(vo[0]), float(wo[0])])
        self.stamp_ns += p.step_ns
        return self.sample()

    def sample(self) -> ShuttleSample:
        def wrapped(a: np.ndarray) -> np.ndarray:
            return _ro([a[0], a[1], wrap_angle(a[2])])
        return ShuttleSample(stamp_ns=self.stamp_ns, true_pose=wrapped(self.true),
                             odom_pose=wrapped(self.odom), odom_covariance=_ro(self.cov),
                             estimate=wrapped(self.estimate), true_twist=_ro(self.true_twist),
                             odom_twist=_ro(self.odom_twist),
                             wheel_positions=_ro(self.wheel_pos),
                             wheel_velocities=_ro(self.wheel_vel))


def iter_landmark_shuttle(seed: int, config: ShuttleConfig = ShuttleConfig(),
                          localize: Optional[Localizer] = None,
                          render: RenderOptions = RenderOptions(),
                          images: bool = True) -> Iterator[ShuttleEvent]:
    """Run ``landmark_shuttle`` (§2.3.3) and yield its events in time order.

    The robot starts at the near point with a perfect estimate, then for each trip: turns
    to face away (counter-clockwise), drives to the far point, turns back (clockwise),
    drives to the near point and turns to face the landmark -- all on its own estimate --,
    stops (a :class:`ShuttleArrival` with the true position error), takes
    ``stop_frames`` images and, if ``localize`` returns robot poses for them, resets its
    estimate to their mean (a landmark fix). With ``config.fix_while_driving`` it also
    takes a frame standing at the far point once it faces the landmark and frames at
    ``approach_image_rate`` while driving to the near point, and resets its estimate to
    each pose ``localize`` returns for them, right after the frame (the next control step
    steers on it).

    Args:
        seed: non-negative int (encoder noise, image noise, scene textures).
        config: the set-up.
        localize: ``localize(frame) -> (x, y, yaw)`` world pose of the robot implied by the
            frame (e.g. a landmark detection composed with the landmark map, see
            :func:`robot_pose_from_landmark`), or None when nothing was found. Without it
            the robot runs on raw odometry (drift grows without bound).
        render: rendering options.
        images: False skips rendering (no CameraFrames; ``localize`` is then never called).

    Yields:
        :class:`ShuttleSample` every 0.1 s, :class:`CameraFrame` at ``image_rate`` while
        moving (``approach_image_rate`` on the approach with ``fix_while_driving``) and at
        the stops, :class:`ShuttleArrival` at each stop. A frame is yielded before
        ``localize`` sees it, and after the sample of its stamp.
    """
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f'seed must be a non-negative int; got {seed!r}')
    cfg = config
    cam = cfg.camera_model()
    rng_odom = np.random.default_rng([int(seed), 1])
    sim = simulator_for(cam, render) if images else None
    planes = shuttle_scene(cfg, seed) if images else []
    robot = _ShuttleRobot(cfg, rng_odom, START_NS)
    p = cfg.robot
    dt = p.sample_time
    frame_index = [0]
    next_image_ns = [START_NS]
    image_step_ns = int(round(NS_PER_S / cfg.image_rate)) if cfg.image_rate > 0 else 0
    approach_step_ns = int(round(NS_PER_S / cfg.approach_image_rate)) \
        if cfg.approach_image_rate > 0 else 0
    approach = [0, 0]   # frames, fixes since the last stop

    def frame() -> CameraFrame:
        i = frame_index[0]
        frame_index[0] += 1
        R_wc, t_wc = cfg.camera_pose(robot.true)
        ph = cfg.photometry
        blur = abs(robot.true_twist[1]) * cam.fx * cfg.exposure_time
        if blur > 0.05:
            ph = replace(ph, motion_blur=float(blur), motion_angle=0.0)
        img = sim.render(planes, R_wc, t_wc, ph, np.random.default_rng([int(seed), 2, i]))
        img.setflags(write=False)
        R_ol = R_wc.T @ cfg.landmark_rotation
        t_ol = R_wc.T @ (cfg.landmark_position - t_wc)
        truths: Tuple[LandmarkTruth, ...] = ()
        if float(R_ol[:, 0] @ t_ol) < 0 and t_ol[2] > 0:
            truths = (landmark_truth(cfg.code, cfg.design, R_ol, t_ol, cam),)
        return CameraFrame(index=i, stamp_ns=robot.stamp_ns, image=img, camera=cam,
                           landmarks=truths, camera_rotation=_ro(R_wc),
                           camera_position=_ro(t_wc), photometry=ph)

    def drive_fix(f: CameraFrame) -> None:
        # a fix taken on the move resets the estimate the next control step steers on
        approach[0] += 1
        res = localize(f) if localize is not None else None
        if res is not None:
            robot.apply_fix(np.asarray(res, dtype=float).reshape(3))
            approach[1] += 1

    def tick(v: float, w: float, fixing: bool = False) -> Iterator[ShuttleEvent]:
        yield robot.step(v, w)
        step_ns = approach_step_ns if fixing else image_step_ns
        if images and step_ns and robot.stamp_ns >= next_image_ns[0]:
            next_image_ns[0] = robot.stamp_ns + step_ns
            f = frame()
            yield f
            if fixing:
                drive_fix(f)

    def turn_rate(err: float) -> float:
        mag = min(p.max_angular_speed,
                  brake_speed(abs(err), DECEL_MARGIN * p.max_angular_accel, dt),
                  abs(err) / dt)
        return math.copysign(mag, err)

    def turn_to(heading: float, direction: int) -> Iterator[ShuttleEvent]:
        th = robot.estimate[2]
        e0 = (heading - th) % (2 * math.pi) if direction > 0 else \
            -((th - heading) % (2 * math.pi))
        target = th + e0
        th_unwrapped = th
        for _ in range(5000):
            err = target - th_unwrapped
            if abs(err) < 1e-3 and abs(robot.w) < 1e-3:
                break
            prev = robot.estimate[2]
            yield from tick(0.0, turn_rate(err))
            th_unwrapped += math.remainder(robot.estimate[2] - prev, 2 * math.pi)
        yield from brake()

    def go_to(target: np.ndarray, fixing: bool = False) -> Iterator[ShuttleEvent]:
        for _ in range(20000):
            est = robot.estimate
            dx, dy = target[0] - est[0], target[1] - est[1]
            dist = math.hypot(dx, dy)
            heading = math.atan2(dy, dx)
            along = dx * math.cos(est[2]) + dy * math.sin(est[2])
            if dist < 0.005 or along <= 0.0:
                break
            err = math.remainder(heading - est[2], 2 * math.pi)
            v = min(p.max_linear_speed,
                    brake_speed(along, DECEL_MARGIN * p.max_linear_accel, dt), along / dt)
            w = 0.0 if dist < 0.15 else max(-p.max_angular_speed,
                                            min(p.max_angular_speed, 2.0 * err))
            yield from tick(v * max(0.0, math.cos(err)), w, fixing)
        yield from brake(fixing)

    def brake(fixing: bool = False) -> Iterator[ShuttleEvent]:
        while abs(robot.v) > 1e-9 or abs(robot.w) > 1e-9:
            yield from tick(0.0, 0.0, fixing)

    def approach_near() -> Iterator[ShuttleEvent]:
        fixing = bool(cfg.fix_while_driving and images)
        if fixing:   # standing at the far point, facing the landmark
            f = frame()
            yield f
            drive_fix(f)
            next_image_ns[0] = robot.stamp_ns + approach_step_ns
        yield from go_to(cfg.near_point, fixing)
        if fixing:
            next_image_ns[0] = robot.stamp_ns + image_step_ns

    def stop(trip: int) -> Iterator[ShuttleEvent]:
        true = robot.true.copy()
        near = cfg.near_point
        fixes = []
        n_wait = int(round(cfg.stop_seconds / dt))
        shots = set(np.linspace(0, max(n_wait - 1, 0), cfg.stop_frames).round().astype(int)) \
            if images and cfg.stop_frames > 0 else set()
        frames = []
        for k in range(n_wait):
            yield robot.step(0.0, 0.0)
            if k in shots:
                f = frame()
                frames.append(f)
                yield f
        if localize is not None:
            for f in frames:
                res = localize(f)
                if res is not None:
                    fixes.append(np.asarray(res, dtype=float).reshape(3))
        fix = None
        if fixes:
            arr = np.array(fixes)
            yaw = math.atan2(np.sin(arr[:, 2]).mean(), np.cos(arr[:, 2]).mean())
            fix = np.array([arr[:, 0].mean(), arr[:, 1].mean(), yaw])
            robot.apply_fix(fix)
        yield ShuttleArrival(trip=trip, stamp_ns=robot.stamp_ns, true_pose=_ro(
            [true[0], true[1], wrap_angle(true[2])]), estimate=_ro(robot.sample().estimate),
            error=float(math.hypot(true[0] - near[0], true[1] - near[1])),
            fix=None if fix is None else _ro(fix), approach_frames=approach[0],
            approach_fixes=approach[1])
        approach[:] = [0, 0]

    yield robot.sample()
    if images and image_step_ns:
        next_image_ns[0] = robot.stamp_ns + image_step_ns
    yield from stop(0)
    for trip in range(1, int(cfg.trips) + 1):
        yield from turn_to(math.pi, 1)
        yield from go_to(cfg.far_point)
        yield from turn_to(0.0, -1)
        yield from approach_near()
        yield from turn_to(0.0, 1 if math.remainder(robot.estimate[2], 2 * math.pi) < 0 else -1)
        yield from stop(trip)


def oracle_localizer(config: ShuttleConfig, sigma_xy: float = 0.0, sigma_yaw: float = 0.0,
                     seed: int = 0) -> Localizer:
    """Return a localizer that reads the true robot pose from the frame (+ Gaussian noise).

    For testing the scenario mechanics without a detector: the pose is recovered from the
    frame's camera pose with the mount, i.e. exactly what a perfect landmark fix gives.
    Frames without an in-view landmark give None.
    """
    rng = np.random.default_rng([int(seed), 99])

    def localize(frame: CameraFrame) -> Optional[np.ndarray]:
        if not frame.landmarks or not frame.landmarks[0].in_view:
            return None
        lt = frame.landmarks[0]
        pose = robot_pose_from_landmark(lt.rotation, lt.translation, config.landmark_rotation,
                                        config.landmark_position, config.mount)
        return pose + rng.normal(0.0, 1.0, 3) * [sigma_xy, sigma_xy, sigma_yaw]

    return localize


__all__ = ['CAMERA_SCENARIOS', 'CameraFrame', 'default_camera', 'iter_landmark_shuttle',
           'iter_landmark_views', 'landmark_truth', 'landmark_view', 'LandmarkTruth',
           'line_of_sight_frame',
           'oracle_localizer', 'random_code', 'random_photometry', 'robot_pose_from_landmark',
           'sample_spec', 'ShuttleArrival', 'ShuttleConfig', 'ShuttleSample', 'shuttle_scene',
           'simulator_for', 'ViewOptions', 'view_scene']
