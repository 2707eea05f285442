"""The ``landmark_views`` scenario: static random views of a landmark on a wall.

A landmark at 0.5-4 m, turned, tilted and rolled relative to the line of sight
(:func:`line_of_sight_frame`), on a wall with distractors (:func:`view_scene`), under random
illumination, blur and noise (:func:`random_photometry`); every value drawn from a spec of
:class:`ViewOptions` (:func:`sample_spec`). View ``i`` of a seed is rendered alone, bit for
bit (:func:`landmark_view`, :func:`iter_landmark_views`). Conventions (view angles, frames,
stamps, random streams): :mod:`landmark_nav.sim.camera_scenarios`, the entry point.
"""

from dataclasses import dataclass, field
import math
import numbers
from typing import Dict, Iterator, List, Optional, Sequence, Tuple, Union

from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np

from . import textures
from .camera import (landmark_plane, Photometry, Plane, RenderOptions, rotation_x, rotation_y,
                     rotation_z)
from .camera_frames import (_ro, CameraFrame, default_camera, landmark_truth, LandmarkTruth,
                            simulator_for)
from .scenarios import START_NS

VIEW_STEP_NS = 100_000_000


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


__all__ = ['iter_landmark_views', 'landmark_view', 'line_of_sight_frame', 'random_code',
           'random_photometry', 'sample_spec', 'ViewOptions', 'view_scene']
