"""Landmarks, AprilTags and ArUco markers composited into real photographs, side by side.

Run ``python -m landmark_nav.evaluation.landmarks_real [detection|pose|false|all]`` (see
``--help``; ``benchmarks/bench_landmarks_real.py`` runs the same functions with the
benchmark's sizes). Backgrounds are the real photographs of a folder (by default the York
Urban images in ``../shared/data/york_urban_train``, found with
:func:`landmark_nav.testing.shared_data`), converted to grey and cut to 640 x 480.

One *trial* is one background, one marker pose and one set of degradations; the same trial
is rendered three times, once per marker type, so that the three detectors see the same
frames except for the printed pattern:

* ``landmark`` -- the package's landmark (3x3 design), printed by
  :meth:`LandmarkDesign.render` (the code path of ``landmark_nav make-landmark``'s PNG),
  one-block quiet zone: 9 x 9 modules of which 7 x 7 are the frame; ``landmark_fast`` is
  the same detector in its fast mode (``DetectorParams.decimate = 2``);
* ``apriltag`` -- tag36h11 (8 x 8 cells including its black border, one white cell around:
  10 x 10), drawn by OpenCV's ``aruco.generateImageMarker`` with ``DICT_APRILTAG_36h11``
  (the same bit patterns as AprilTag's tag images) and detected by AprilTag 3
  (``pupil_apriltags``, decimate 1 and 2, one thread); its pose is ``cv2.solvePnP``
  (``SOLVEPNP_IPPE_SQUARE``) on its four corners, as for ArUco (AprilTag's own
  ``estimate_tag_pose`` corrupted the heap in a test run, see :class:`Detectors`);
* ``aruco`` -- ``DICT_6X6_250`` (8 x 8 with its border, one white cell around), drawn and
  detected by OpenCV ArUco with sub-pixel corner refinement.

"px per module" is the printed module (landmark block, tag cell) seen head-on at the
marker's distance: ``f * module / distance``; tilt foreshortens one direction by its
cosine. Geometry (camera f = 600 px, 640 x 480, no lens distortion): the marker centre is
placed at a uniformly drawn pixel (the whole printed marker, quiet zone included, at least
3 px inside the image) at distance ``f module / px_per_module`` along that pixel's ray; the
marker faces the camera along the ray, is turned about the ray by a uniform angle and then
tilted by ``tilt`` about a random axis perpendicular to the ray (so ``tilt`` is the angle
between the marker normal and the line of sight).

Image formation: the printed pattern is mapped by its exact homography onto a 4 x 4
supersampled patch (bilinear from a 64 px per module texture) and area-averaged, paper
white 150-235 grey levels and ink black 8-15 % of it, alpha-blended into the background
by its coverage; then the whole frame is blurred (Gaussian sigma 0.5-1.2 px), passed
through a gain (0.75-1.25) and gamma (0.75-1.33), noised (Gaussian sigma 2-5 grey levels),
rounded to 8 bits and JPEG-compressed at quality 70 (OpenCV). Every draw comes from one
seeded generator per trial.

Scoring: a marker is *detected* when a detection with the true code has its centre (mean
of its four corners) within one module of the true centre; any other detection in the
frame is counted as a *wrong code* (at the marker) or a *false detection* (elsewhere).
Pose errors are the position error of the marker centre and the rotation angle between
estimated and true marker orientation; for the tags the orientation is compared modulo
quarter turns about the normal (their frame conventions differ from the truth's; the code
fixes the quarter turn). Times are CPU times of the process per call
(``time.process_time``, less sensitive than the wall clock to other load on the machine),
single-threaded (``cv2.setNumThreads(1)``, AprilTag ``nthreads=1``, BLAS limited to one
thread by threadpoolctl in :func:`main`).
"""

import argparse
from dataclasses import asdict, dataclass, replace
import json
import math
from pathlib import Path
import sys
import time
from typing import Dict, List, Optional, Sequence, Tuple
import weakref

import cv2
from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
from landmark_nav.vision.detector import detect_landmarks, DetectorParams
from landmark_nav.vision.landmark import LandmarkDesign
from landmark_nav.vision.pose import (angles_from_rotation, estimate_pose, PoseError,
                                      PoseParams, project_points, rotation_matrix)
import numpy as np
from scipy.spatial.transform import Rotation

_M = np.asarray(OPTICAL_FROM_BODY, dtype=float)

#: The camera of the composites: f = 600 px, 640 x 480, no distortion.
CAMERA = CameraModel(640, 480, np.array([[600.0, 0.0, 319.5], [0.0, 600.0, 239.5],
                                         [0.0, 0.0, 1.0]]), np.zeros(5))
#: Detectors, in table order; ``landmark_fast`` is the landmark detector's fast mode
#: (``DetectorParams.decimate = 2``), ``apriltag2`` AprilTag with ``quad_decimate = 2``.
DETECTORS = ('landmark', 'landmark_fast', 'apriltag1', 'apriltag2', 'aruco')
#: Printed module (landmark block, tag cell) of the pose runs [m]: the default 0.175 m frame.
MODULE = LandmarkDesign().block_size
#: Texture resolution of the printed patterns [px per module].
TEXTURE_PX = 64
#: Supersampling of the rendered patch per image pixel and axis.
SUPERSAMPLE = 4
#: Modules per side of the printed markers including their quiet zone / white border.
PRINTED_MODULES = {'landmark': 9, 'apriltag': 10, 'aruco': 10}
#: Modules per side of the square whose corners each detector reports.
CORNER_MODULES = {'landmark': 5, 'apriltag': 8, 'aruco': 8}
#: Ids of the tag dictionaries drawn from (tag36h11 has 587 codes, DICT_6X6_250 250).
TAG_IDS = {'apriltag': 587, 'aruco': 250}


def marker_family(detector: str) -> str:
    """Return the printed marker type of a detector name (``apriltag1`` -> ``apriltag``)."""
    if detector.startswith('landmark'):
        return 'landmark'
    return 'apriltag' if detector.startswith('apriltag') else detector


# ---------------------------------------------------------------------- backgrounds


def load_backgrounds(folder: Path, width: int = 640, height: int = 480) -> List[np.ndarray]:
    """Return the ``*.jpg`` / ``*.png`` photographs of a folder as grey ``height x width``.

    Images of another size are scaled to cover ``width x height`` and centre-cropped.

    Raises:
        FileNotFoundError: no image in the folder.
        ValueError: an image that OpenCV cannot read (the message names the file).
    """
    files = sorted(p for p in Path(folder).iterdir()
                   if p.suffix.lower() in ('.jpg', '.jpeg', '.png'))
    if not files:
        raise FileNotFoundError(f'no .jpg/.png images in {folder}')
    out = []
    for p in files:
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise ValueError(f'{p}: not an image OpenCV can read')
        h, w = img.shape
        if (h, w) != (height, width):
            s = max(width / w, height / h)
            img = cv2.resize(img, (max(width, round(w * s)), max(height, round(h * s))),
                             interpolation=cv2.INTER_AREA)
            y0 = (img.shape[0] - height) // 2
            x0 = (img.shape[1] - width) // 2
            img = img[y0:y0 + height, x0:x0 + width]
        out.append(np.ascontiguousarray(img))
    return out


def default_backgrounds() -> List[np.ndarray]:
    """Load the York Urban training photographs of ``../shared/data/york_urban_train``."""
    from landmark_nav.testing import shared_data
    return load_backgrounds(shared_data('york_urban_train'))


# ---------------------------------------------------------------------- printed markers


def marker_texture(family: str, code: int, px_per_module: int = TEXTURE_PX) -> np.ndarray:
    """Return the printed marker, quiet zone included, as a uint8 image (white 255).

    Args:
        family: ``'landmark'``, ``'apriltag'`` or ``'aruco'``.
        code: landmark code or tag id.
        px_per_module: pixels per module of the texture (even).
    """
    if family == 'landmark':
        return LandmarkDesign().render(code, px_per_module, quiet_zone_blocks=1)
    dic = cv2.aruco.getPredefinedDictionary(
        cv2.aruco.DICT_APRILTAG_36h11 if family == 'apriltag' else cv2.aruco.DICT_6X6_250)
    tag = cv2.aruco.generateImageMarker(dic, int(code), 8 * px_per_module, borderBits=1)
    return cv2.copyMakeBorder(tag, px_per_module, px_per_module, px_per_module,
                              px_per_module, cv2.BORDER_CONSTANT, value=255)


def texture_homography(v: np.ndarray, modules: int, module: float, texture_px: int,
                       camera: CameraModel) -> np.ndarray:
    """Return the 3 x 3 homography texture pixel (x, y) -> image pixel of a marker at ``v``.

    The texture is ``modules x modules`` modules of ``texture_px`` pixels, centred on the
    marker centre; texture x runs along the landmark's y axis (right when looking at it),
    texture y down (minus its z axis). ``v`` are the pose parameters of :mod:`.pose`.
    """
    r = rotation_matrix(v[3:])
    a = module / texture_px
    off = module * (0.5 / texture_px - 0.5 * modules)
    cols = np.column_stack([r[:, 1] * a, -r[:, 2] * a,
                            np.asarray(v[:3], float) + r[:, 1] * off - r[:, 2] * off])
    h = camera.K @ _M @ cols
    return h / h[2, 2]


def marker_corners(v: np.ndarray, side: float, camera: CameraModel) -> np.ndarray:
    """Return the (4, 2) image pixels of a square of side ``side`` centred on the marker."""
    b = 0.5 * side
    pts = np.array([[0.0, -b, b], [0.0, b, b], [0.0, b, -b], [0.0, -b, -b]])
    return project_points(np.asarray(v, float), pts, camera)


@dataclass(frozen=True)
class Photometrics:
    """Print and image-formation draws of one trial (module docstring for the ranges)."""

    white: float
    black: float
    blur: float
    gain: float
    gamma: float
    noise: float
    jpeg_quality: int = 70


def draw_photometrics(rng: np.random.Generator, jpeg_quality: int = 70) -> Photometrics:
    """Draw the degradations of one trial."""
    white = float(rng.uniform(150.0, 235.0))
    return Photometrics(white=white, black=white * float(rng.uniform(0.08, 0.15)),
                        blur=float(rng.uniform(0.5, 1.2)), gain=float(rng.uniform(0.75, 1.25)),
                        gamma=float(np.exp(rng.uniform(math.log(0.75), math.log(1.33)))),
                        noise=float(rng.uniform(2.0, 5.0)), jpeg_quality=jpeg_quality)


def draw_pose(rng: np.random.Generator, px_per_module: float, tilt_deg: float,
              modules: int = 10, module: float = MODULE, camera: CameraModel = CAMERA,
              margin: float = 3.0) -> np.ndarray:
    """Draw a marker pose ``v`` (pose parameters) with the given scale and tilt.

    The centre pixel is uniform over the positions that keep the ``modules``-wide printed
    square at least ``margin`` px inside the image (tried 200 times, then the image centre).

    Raises:
        ValueError: the marker does not fit in the image even at the centre.
    """
    dist = camera.fx * module / px_per_module
    k_inv = np.linalg.inv(camera.K)
    omega = float(rng.uniform(-math.pi, math.pi))
    az = float(rng.uniform(-math.pi, math.pi))
    t = math.radians(tilt_deg)
    for attempt in range(201):
        if attempt < 200:
            px = np.array([rng.uniform(0, camera.width - 1), rng.uniform(0, camera.height - 1)])
        else:
            px = np.array([camera.cx, camera.cy])
        ray = _M.T @ (k_inv @ np.array([px[0], px[1], 1.0]))
        ray /= np.linalg.norm(ray)
        align = Rotation.align_vectors([ray], [[1.0, 0.0, 0.0]])[0].as_matrix()
        e1 = np.cross(ray, [0.0, 0.0, 1.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(ray, e1)
        axis = math.cos(az) * e1 + math.sin(az) * e2
        rot = Rotation.from_rotvec(t * axis).as_matrix() @ align @ rotation_matrix(
            [omega, 0.0, 0.0])
        v = np.concatenate([dist * ray, angles_from_rotation(rot)])
        c = marker_corners(v, modules * module, camera)
        if np.all(np.isfinite(c)) and c.min() >= margin and c[:, 0].max() <= \
                camera.width - 1 - margin and c[:, 1].max() <= camera.height - 1 - margin:
            return v
    raise ValueError(f'a {modules}-module marker at {px_per_module} px per module and '
                     f'{tilt_deg} deg tilt does not fit in the image')


def composite(background: np.ndarray, texture: np.ndarray, v: np.ndarray, modules: int,
              module: float, photo: Photometrics, noise_seed: int,
              camera: CameraModel = CAMERA) -> np.ndarray:
    """Paste a printed marker into a grey photograph and degrade the frame.

    Args:
        background: (H, W) uint8 photograph.
        texture: the printed marker (:func:`marker_texture`), ``modules`` modules wide.
        v: marker pose parameters.
        modules: modules per side of ``texture``.
        module: printed module size [m].
        photo: the degradations.
        noise_seed: seed of the pixel noise (the same for the three markers of a trial).
        camera: the camera.

    Returns:
        (H, W) uint8 frame after JPEG compression.
    """
    tpx = texture.shape[0] // modules
    h_img = texture_homography(v, modules, module, tpx, camera)
    corners = cv2.perspectiveTransform(
        np.array([[[-0.5, -0.5], [texture.shape[1] - 0.5, -0.5],
                   [texture.shape[1] - 0.5, texture.shape[0] - 0.5],
                   [-0.5, texture.shape[0] - 0.5]]]), h_img)[0]
    hgt, wid = background.shape
    x0 = max(0, int(math.floor(corners[:, 0].min())) - 1)
    y0 = max(0, int(math.floor(corners[:, 1].min())) - 1)
    x1 = min(wid, int(math.ceil(corners[:, 0].max())) + 2)
    y1 = min(hgt, int(math.ceil(corners[:, 1].max())) + 2)
    s = SUPERSAMPLE
    # image pixel centre x -> supersampled centre s (x - x0 + 0.5) - 0.5
    a = np.array([[s, 0.0, s * (0.5 - x0) - 0.5], [0.0, s, s * (0.5 - y0) - 0.5],
                  [0.0, 0.0, 1.0]])
    hs = a @ h_img
    size = (s * (x1 - x0), s * (y1 - y0))
    tex = texture.astype(np.float32) / 255.0
    refl = cv2.warpPerspective(tex, hs, size, flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    cover = cv2.warpPerspective(np.ones_like(tex), hs, size, flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    refl = cv2.resize(refl, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
    cover = cv2.resize(cover, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
    img = background.astype(np.float32)
    patch = photo.black * cover + (photo.white - photo.black) * refl
    img[y0:y1, x0:x1] = img[y0:y1, x0:x1] * (1.0 - cover) + patch
    return degrade(img, photo, noise_seed)


def degrade(img: np.ndarray, photo: Photometrics, noise_seed: int) -> np.ndarray:
    """Blur, gain/gamma, noise, 8 bits and JPEG of a float frame (module docstring)."""
    img = cv2.GaussianBlur(np.asarray(img, np.float32), (0, 0), photo.blur)
    img = 255.0 * np.power(np.clip(photo.gain * img / 255.0, 0.0, None), photo.gamma)
    rng = np.random.default_rng(noise_seed)
    img = img + rng.normal(0.0, photo.noise, img.shape).astype(np.float32)
    img8 = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode('.jpg', img8, [cv2.IMWRITE_JPEG_QUALITY, photo.jpeg_quality])
    if not ok:
        raise ValueError('JPEG encoding failed')
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)


# ---------------------------------------------------------------------- detectors


@dataclass(frozen=True, eq=False)
class Found:
    """One detection of any detector: code, (4, 2) corners, optional (R, t) optical pose."""

    code: int
    corners: np.ndarray
    rotation: Optional[np.ndarray] = None
    translation: Optional[np.ndarray] = None


def release_apriltags(detectors: Sequence[object]) -> None:
    """Free ``pupil_apriltags.Detector`` objects in the order the C library needs.

    ``pupil_apriltags`` 1.0.4's ``Detector.__del__`` frees the tag families first and then
    calls ``apriltag_detector_destroy``, whose ``apriltag_detector_clear_families`` reads
    each family's ``impl`` (``quick_decode_uninit``) from the freed memory: a use after
    free that corrupts the heap or segfaults, now or later (pupil-labs/apriltags issues 34
    and 46; the same wrapper code was fixed in duckietown/lib-dt-apriltags PR 26). This
    destroys the detector first, then its families, and clears ``tag_detector_ptr`` so that
    ``__del__`` does nothing. Reproduced: with glibc's caches off and freed memory filled
    (``GLIBC_TUNABLES=glibc.malloc.tcache_count=0:glibc.malloc.mxfast=0
    MALLOC_PERTURB_=165``) deleting a bare ``Detector`` segfaults in
    ``quick_decode_uninit`` every time (test_landmarks_real).
    """
    for det in detectors:
        ptr = getattr(det, 'tag_detector_ptr', None)
        if ptr is None:
            continue
        det.tag_detector_ptr = None
        det.libc.apriltag_detector_destroy.restype = None
        det.libc.apriltag_detector_destroy(ptr)
        for family, fam in det.tag_families.items():
            destroy = getattr(det.libc, f'{family}_destroy')
            destroy.restype = None
            destroy(fam)
        det.tag_families = {}


class Detectors:
    """The detectors of the comparison, created once (AprilTag and ArUco objects)."""

    def __init__(self, names: Sequence[str] = DETECTORS, camera: CameraModel = CAMERA,
                 module: float = MODULE,
                 landmark_params: DetectorParams = DetectorParams(),
                 pose_params: PoseParams = PoseParams()) -> None:
        """Create the detectors (``pupil_apriltags`` is imported only if asked for).

        Raises:
            ImportError: an AprilTag detector is asked for and ``pupil_apriltags`` is not
                installed (``pip install -r requirements-test.txt``).
        """
        self.names = tuple(names)
        self.camera = camera
        self.module = module
        self.landmark_params = landmark_params
        self.pose_params = pose_params
        self.design = LandmarkDesign(frame_width=7 * module)
        self._april = {}
        for name in self.names:
            if name.startswith('apriltag'):
                from pupil_apriltags import Detector
                self._april[name] = Detector(families='tag36h11', nthreads=1,
                                             quad_decimate=float(name[-1]))
        # released in the right order when this object goes or at interpreter exit
        self._release = weakref.finalize(self, release_apriltags, list(self._april.values()))
        if 'aruco' in self.names:
            p = cv2.aruco.DetectorParameters()
            p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
            self._aruco = cv2.aruco.ArucoDetector(
                cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250), p)

    def close(self) -> None:
        """Release the AprilTag detectors now (:func:`release_apriltags`); idempotent."""
        self._release()
        self._april = {}

    def __enter__(self) -> 'Detectors':
        """Return self; :meth:`close` on leaving the block."""
        return self

    def __exit__(self, *exc) -> None:
        """Release the AprilTag detectors."""
        self.close()

    def detect(self, name: str, gray: np.ndarray, pose: bool = False) -> List[Found]:
        """Run one detector on a frame; with ``pose`` each detection carries its pose."""
        cam = self.camera
        if name in ('landmark', 'landmark_fast'):
            params = self.landmark_params if name == 'landmark' else \
                replace(self.landmark_params, decimate=2)
            out = []
            for d in detect_landmarks(gray, params):
                rot = tr = None
                if pose:
                    try:
                        p = estimate_pose(d.corners, cam, self.design, self.pose_params,
                                          edge_corners_px=d.edge_corners)
                        rot, tr = p.rotation_optical, p.translation_optical
                    except PoseError:
                        pass
                out.append(Found(d.code, d.corners, rot, tr))
            return out
        if name in self._april:
            # AprilTag's own estimate_tag_pose corrupted the heap here (an abort in a later
            # allocation; AprilRobotics/apriltag issues 22 and 59): its corners go through
            # the same IPPE_SQUARE solve as ArUco's (AprilTag lists its corners the other
            # way round; IPPE_SQUARE needs them clockwise in the image)
            res = self._april[name].detect(gray)
            return [self._square_pose(int(r.tag_id), np.asarray(r.corners, float)[::-1], pose)
                    for r in res]
        if name == 'aruco':
            corners, ids, _ = self._aruco.detectMarkers(gray)
            return [self._square_pose(int(i), np.asarray(c, float).reshape(4, 2), pose)
                    for c, i in zip(corners, [] if ids is None else ids.ravel())]
        raise ValueError(f'unknown detector {name!r}; use one of {DETECTORS}')

    def _square_pose(self, code: int, corners: np.ndarray, pose: bool) -> Found:
        """Return a tag detection, with ``cv2.solvePnP`` (IPPE_SQUARE) pose if asked."""
        if not pose:
            return Found(code, corners)
        b = 4 * self.module
        obj = np.array([[-b, b, 0], [b, b, 0], [b, -b, 0], [-b, -b, 0]], float)
        ok, rvec, tvec = cv2.solvePnP(obj, corners, self.camera.K, self.camera.D,
                                      flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not ok:
            return Found(code, corners)
        return Found(code, corners, cv2.Rodrigues(rvec)[0], tvec.ravel())


# ---------------------------------------------------------------------- trials


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


# ---------------------------------------------------------------------- frames without markers


def checkerboard_texture(squares: int, px_per_square: int = TEXTURE_PX) -> np.ndarray:
    """Return a ``squares x squares`` checkerboard with a one-square white margin (uint8)."""
    j, i = np.mgrid[0:squares, 0:squares]
    board = np.where((i + j) % 2 == 0, np.uint8(0), np.uint8(255))
    board = np.pad(board, 1, constant_values=255)
    return np.repeat(np.repeat(board, px_per_square, axis=0), px_per_square, axis=1)


def transformed_photo(photo: np.ndarray, rng: np.random.Generator,
                      width: int = 640, height: int = 480) -> np.ndarray:
    """Return a random view of a photograph: scale 0.6-2, rotation +-30 deg, flips, crop."""
    img = photo
    if rng.random() < 0.5:
        img = img[:, ::-1]
    if rng.random() < 0.25:
        img = img[::-1]
    s = float(rng.uniform(0.6, 2.0))
    ang = float(rng.uniform(-30.0, 30.0))
    h, w = img.shape
    a = cv2.getRotationMatrix2D((w / 2.0, h / 2.0), ang, s)
    a[:, 2] += [width / 2.0 - w / 2.0 + rng.uniform(-0.25, 0.25) * w * s,
                height / 2.0 - h / 2.0 + rng.uniform(-0.25, 0.25) * h * s]
    return cv2.warpAffine(np.ascontiguousarray(img), a, (width, height),
                          flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


@dataclass
class FalseResult:
    """Detections in real frames without landmarks (every detection is false)."""

    frames: Dict[str, int]
    detections: Dict[str, int]
    ms_per_frame: float


def false_frames(photos: Sequence[np.ndarray], count: int = 1020, seed: int = 3,
                 extra: Sequence[np.ndarray] = (), checkerboards: float = 0.3,
                 params: DetectorParams = DetectorParams(),
                 chessboards: Sequence[np.ndarray] = (),
                 chessboard_share: float = 0.3) -> FalseResult:
    """Run the landmark detector on ``count`` real frames without a landmark.

    Each frame is a random view (:func:`transformed_photo`) of one of ``photos``, of
    ``chessboards`` (real photographs of chessboards, :func:`chessboard_photos`; a
    fraction ``chessboard_share`` of the frames when given) or (40 % of the other frames)
    of ``extra`` (other real photographs, e.g. the CamVid road frames), degraded like the
    composites; a fraction ``checkerboards`` of the frames that are not chessboard photos
    also shows a rendered checkerboard of 4-10 squares (the printed pattern closest to a
    landmark frame) at 4-12 px per square and 0-60 deg tilt, composited like the markers.
    Without ``chessboards`` the draws are those of the version before them.
    """
    rng = np.random.default_rng(seed)
    frames: Dict[str, int] = {}
    dets: Dict[str, int] = {}
    spent = 0.0
    cv2.setNumThreads(1)
    for _ in range(count):
        if len(chessboards) and rng.random() < chessboard_share:
            kind = 'chessboard photo'
            src = chessboards[int(rng.integers(len(chessboards)))]
        elif len(extra) and rng.random() < 0.4:
            kind = 'extra'
            src = extra[int(rng.integers(len(extra)))]
        else:
            kind = 'york'
            src = photos[int(rng.integers(len(photos)))]
        img = transformed_photo(src, rng).astype(np.float32)
        photo = draw_photometrics(rng)
        if kind != 'chessboard photo' and rng.random() < checkerboards:
            kind += '+checkerboard'
            squares = int(rng.integers(4, 11))
            v = draw_pose(rng, float(rng.uniform(4.0, 12.0)), float(rng.uniform(0.0, 60.0)),
                          squares + 2)
            gray = composite(img.astype(np.uint8), checkerboard_texture(squares), v,
                             squares + 2, MODULE, photo, int(rng.integers(2 ** 31)))
        else:
            gray = degrade(img, photo, int(rng.integers(2 ** 31)))
        t0 = time.process_time()
        found = detect_landmarks(gray, params)
        spent += time.process_time() - t0
        frames[kind] = frames.get(kind, 0) + 1
        dets[kind] = dets.get(kind, 0) + len(found)
    return FalseResult(frames, dets, 1000.0 * spent / max(count, 1))


#: OpenCV's stereo calibration photographs (``samples/data``, shipped by Debian's
#: ``opencv-doc`` package; Apache-2.0 / BSD-3-Clause as OpenCV): 26 real 640 x 480 grey
#: photographs of a hand-held printed chessboard (9 x 6 inner corners) in an office.
CHESSBOARD_PHOTOS = tuple(f'{side}{i:02d}.jpg' for side in ('left', 'right')
                          for i in (1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14))
#: Where ``opencv-doc`` installs them.
OPENCV_DOC_DATA = Path('/usr/share/doc/opencv-doc/examples/data')


def chessboard_cache() -> Path:
    """Return the cache folder of the fetched photographs (outside the repository).

    ``$LANDMARK_NAV_CACHE/opencv_chessboards``, else ``$XDG_CACHE_HOME`` or ``~/.cache``
    followed by ``landmark_nav/opencv_chessboards``.
    """
    import os
    root = os.environ.get('LANDMARK_NAV_CACHE')
    if root:
        return Path(root) / 'opencv_chessboards'
    base = os.environ.get('XDG_CACHE_HOME') or str(Path.home() / '.cache')
    return Path(base) / 'landmark_nav' / 'opencv_chessboards'


def fetch_chessboard_photos(dest: Path) -> Path:
    """Fetch :data:`CHESSBOARD_PHOTOS` from Debian's ``opencv-doc`` package into ``dest``.

    Runs ``apt-get download opencv-doc`` (about 96 MB, in a temporary folder beside
    ``dest``) and extracts only the 26 photographs and the package's copyright file with
    ``dpkg-deb --fsys-tarfile | tar``; the package file is deleted afterwards.

    Raises:
        FileNotFoundError: the download or extraction failed (the message says why and
            how to get the files by hand).
    """
    import shutil
    import subprocess
    import tempfile
    dest.mkdir(parents=True, exist_ok=True)
    members = [f'./usr/share/doc/opencv-doc/examples/data/{n}' for n in CHESSBOARD_PHOTOS]
    members.append('./usr/share/doc/opencv-doc/copyright')
    with tempfile.TemporaryDirectory(dir=dest.parent) as tmp:
        try:
            got = subprocess.run(['apt-get', 'download', 'opencv-doc'], cwd=tmp,
                                 capture_output=True, text=True, timeout=600)
            debs = sorted(Path(tmp).glob('opencv-doc_*.deb'))
            if got.returncode or not debs:
                raise OSError(f'apt-get download opencv-doc: exit {got.returncode}: '
                              f'{got.stderr.strip()[-500:]}')
            tar = subprocess.run(
                f'dpkg-deb --fsys-tarfile {debs[0].name} | tar -x -f - {" ".join(members)}',
                shell=True, cwd=tmp, capture_output=True, text=True, timeout=600)
            if tar.returncode:
                raise OSError(f'dpkg-deb | tar: {tar.stderr.strip()[-500:]}')
        except (OSError, subprocess.SubprocessError) as err:
            raise FileNotFoundError(
                f'real chessboard photographs not found and not fetched ({err}); get them '
                f'with `apt-get install opencv-doc` (files in {OPENCV_DOC_DATA}) or '
                f'`apt-get download opencv-doc` and extract {", ".join(CHESSBOARD_PHOTOS)} '
                f'into {dest}') from err
        data = Path(tmp) / 'usr/share/doc/opencv-doc/examples/data'
        for n in CHESSBOARD_PHOTOS:
            shutil.move(str(data / n), str(dest / n))
        shutil.move(str(Path(tmp) / 'usr/share/doc/opencv-doc/copyright'),
                    str(dest / 'COPYRIGHT.opencv-doc'))
    return dest


def chessboard_photo_dir(fetch: bool = True) -> Path:
    """Return a folder holding all :data:`CHESSBOARD_PHOTOS`, fetching them if needed.

    Looked for in ``$LANDMARK_NAV_CHESSBOARDS``, :data:`OPENCV_DOC_DATA` (``opencv-doc``
    installed) and :func:`chessboard_cache`; with ``fetch`` they are fetched into the
    cache (:func:`fetch_chessboard_photos`) when found nowhere.

    Raises:
        FileNotFoundError: not found (and not fetched); the message names what is missing.
    """
    import os
    places = [Path(p) for p in (os.environ.get('LANDMARK_NAV_CHESSBOARDS'),) if p]
    places += [OPENCV_DOC_DATA, chessboard_cache()]
    for place in places:
        if all((place / n).is_file() for n in CHESSBOARD_PHOTOS):
            return place
    if not fetch:
        raise FileNotFoundError(
            f'real chessboard photographs {CHESSBOARD_PHOTOS[0]} ... {CHESSBOARD_PHOTOS[-1]} '
            f'(OpenCV samples/data, Debian package opencv-doc) not found in '
            f'{", ".join(map(str, places))}')
    return fetch_chessboard_photos(chessboard_cache())


def chessboard_photos(fetch: bool = True) -> List[np.ndarray]:
    """Load the 26 real chessboard photographs (:func:`chessboard_photo_dir`), grey."""
    folder = chessboard_photo_dir(fetch)
    out = []
    for n in CHESSBOARD_PHOTOS:
        img = cv2.imread(str(folder / n), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise ValueError(f'{folder / n}: not an image OpenCV can read')
        out.append(img)
    return out


def default_extra_photos() -> List[np.ndarray]:
    """Load the CamVid road frames of ``../shared/data/camvid_road/images`` (480 x 360), grey."""
    from landmark_nav.testing import shared_data
    out = []
    for p in sorted(shared_data('camvid_road', 'images').glob('*.png')):
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise ValueError(f'{p}: not an image OpenCV can read')
        out.append(img)
    return out


# ---------------------------------------------------------------------- detector stages

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


# ---------------------------------------------------------------------- summaries


@dataclass
class Row:
    """Detection rate and errors of one detector in one group of trials."""

    detector: str
    group: str
    trials: int
    p_detect: float
    wrong_codes: int
    false_detections: int
    ms_per_frame: float
    median_position_mm: float = math.nan
    median_angle_deg: float = math.nan
    max_angle_deg: float = math.nan
    over_5_deg: int = 0
    poses: int = 0


def summarise(outcomes: Sequence[Outcome], key) -> List[Row]:
    """Group outcomes by ``(detector, key(outcome))`` and summarise each group."""
    groups: Dict[Tuple[str, str], List[Outcome]] = {}
    for o in outcomes:
        groups.setdefault((o.detector, key(o)), []).append(o)
    rows = []
    for (name, grp), os_ in groups.items():
        ang = np.array([o.angle_error_deg for o in os_ if math.isfinite(o.angle_error_deg)])
        pos = np.array([o.position_error for o in os_ if math.isfinite(o.position_error)])
        rows.append(Row(name, grp, len(os_), float(np.mean([o.detected for o in os_])),
                        sum(o.wrong_codes for o in os_), sum(o.false_detections for o in os_),
                        1000.0 * float(np.mean([o.seconds for o in os_])),
                        1000.0 * float(np.median(pos)) if len(pos) else math.nan,
                        float(np.median(ang)) if len(ang) else math.nan,
                        float(ang.max()) if len(ang) else math.nan,
                        int(np.sum(ang > 5.0)), len(ang)))
    return rows


def _group_order(group: str) -> Tuple[float, str]:
    """Sort key of group labels: by their first number."""
    num = ''.join(c if c.isdigit() or c == '.' else ' ' for c in group).split()
    return (float(num[0]) if num else math.inf, group)


def format_table(rows: Sequence[Row], title: str, pose: bool = False) -> str:
    """Return a Markdown table: one line per group, one column per detector."""
    names = [n for n in DETECTORS if any(r.detector == n for r in rows)]
    groups = sorted(dict.fromkeys(r.group for r in rows), key=_group_order)
    by = {(r.detector, r.group): r for r in rows}
    lines = [title, '', '| ' + ' | '.join(['group', 'n'] + names) + ' |',
             '| --- | --- |' + ' --- |' * len(names)]
    for g in groups:
        cells = []
        for n in names:
            r = by.get((n, g))
            if r is None:
                cells.append('')
            elif pose:
                cells.append(f'{r.p_detect:.2f}; {r.median_position_mm:.2f} mm / '
                             f'{r.median_angle_deg:.2f} deg, max {r.max_angle_deg:.1f} deg, '
                             f'{r.over_5_deg} > 5 deg')
            else:
                bad = r.wrong_codes or r.false_detections
                extra = f' (wrong {r.wrong_codes}, false {r.false_detections})' if bad else ''
                cells.append(f'{r.p_detect:.2f}{extra}')
        n = next(r.trials for r in rows if r.group == g)
        lines.append(f'| {g} | {n} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def format_speed(outcomes: Sequence[Outcome]) -> str:
    """Return mean time per frame of each detector and its ratio to the others."""
    names = [n for n in DETECTORS if any(o.detector == n for o in outcomes)]
    ms = {n: 1000.0 * float(np.mean([o.seconds for o in outcomes if o.detector == n]))
          for n in names}
    lines = ['Time per 640 x 480 frame (single thread, mean over the same trials):']
    for n in names:
        ratios = ', '.join(f'{ms[n] / ms[m]:.2f}x {m}' for m in names if m != n)
        lines.append(f'  {n:10s} {ms[n]:7.2f} ms  ({ratios})')
    return '\n'.join(lines)


def tilt_bin(o: Outcome) -> str:
    """Group key: the tilt range of an outcome (0-30, 30-45, 45-55, 55-60 deg)."""
    for lo, hi in ((0, 30), (30, 45), (45, 55)):
        if o.tilt_deg < hi:
            return f'tilt {lo}-{hi}'
    return 'tilt 55-60'


def parse_detector_params(items: Sequence[str]) -> Dict[str, object]:
    """Parse ``NAME=VALUE`` items (YAML scalars) into DetectorParams keyword arguments.

    Raises:
        ValueError: an item without ``=`` or a name that is not a DetectorParams field.
    """
    import yaml
    fields = set(DetectorParams.__dataclass_fields__)
    out = {}
    for item in items:
        name, sep, value = item.partition('=')
        if not sep or name not in fields:
            raise ValueError(f'--set {item!r}: expected NAME=VALUE with NAME one of '
                             f'{", ".join(sorted(fields))}')
        out[name] = yaml.safe_load(value)
    return out


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command line: detection, pose and speed tables on composites of real photographs."""
    ap = argparse.ArgumentParser(
        prog='python -m landmark_nav.evaluation.landmarks_real', description=__doc__.split(
            '\n')[0])
    ap.add_argument('what', nargs='?', default='all',
                    choices=('detection', 'pose', 'false', 'stages', 'all'))
    ap.add_argument('--per-size', type=int, default=100, help='trials per px per module')
    ap.add_argument('--sizes', type=float, nargs='+', default=[3, 4, 5, 6, 8, 12],
                    help='px per module')
    ap.add_argument('--tilt', type=float, nargs=2, default=[0.0, 60.0], metavar=('MIN', 'MAX'),
                    help='tilt range of the detection trials [deg]')
    ap.add_argument('--per-distance', type=int, default=150, help='pose trials per distance')
    ap.add_argument('--distances', type=float, nargs='+', default=[1.0, 2.2])
    ap.add_argument('--false-frames', type=int, default=1020,
                    help='real frames without landmarks (false)')
    ap.add_argument('--no-chessboard-photos', action='store_true',
                    help='false: without the 26 real chessboard photographs (OpenCV '
                    'samples, fetched with apt-get download opencv-doc into the cache)')
    ap.add_argument('--chessboard-share', type=float, default=0.3,
                    help='false: fraction of the frames that are views of the real '
                    'chessboard photographs')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--detectors', nargs='+', default=list(DETECTORS), choices=DETECTORS)
    ap.add_argument('--backgrounds', type=Path, default=None,
                    help='folder of photographs (default ../shared/data/york_urban_train)')
    ap.add_argument('--deblur-margin', type=float, default=DetectorParams().deblur_margin,
                    help='landmark detector deblur_margin (0: the code read before issue 20)')
    ap.add_argument('--second-neighbour-angle', type=float,
                    default=DetectorParams().second_neighbour_angle,
                    help='landmark detector second_neighbour_angle [deg] (0: before issue 20)')
    ap.add_argument('--set', nargs='+', default=[], metavar='NAME=VALUE',
                    help='landmark detector parameters (DetectorParams fields), e.g. '
                    'corner_method=eq1 small_block_px=4.5 (the corner stage of the chapter, '
                    'the default before the saddle candidates), with max_gaps=0 '
                    'refine_grid=false block_ring=false unblur_margin=1 (the detector '
                    'before the small-landmark extensions)')
    ap.add_argument('--no-planar-start', action='store_true',
                    help='landmark pose from the quadrant guesses only (before issue 20)')
    ap.add_argument('--json', type=Path, default=None, help='write every outcome here')
    args = ap.parse_args(argv)
    from threadpoolctl import threadpool_limits
    threadpool_limits(limits=1)             # BLAS single-threaded too (numpy least squares)
    bgs = load_backgrounds(args.backgrounds) if args.backgrounds else default_backgrounds()
    lm_params = DetectorParams(deblur_margin=args.deblur_margin,
                               second_neighbour_angle=args.second_neighbour_angle)
    try:
        lm_params = replace(lm_params, **parse_detector_params(args.set))
    except (TypeError, ValueError) as err:
        ap.error(str(err))
    dets = Detectors(args.detectors, landmark_params=lm_params,
                     pose_params=PoseParams(planar_start=not args.no_planar_start))
    everything: List[Outcome] = []
    if args.what in ('detection', 'all'):
        trials = detection_trials(args.sizes, args.per_size, tuple(args.tilt), args.seed,
                                  len(bgs))
        res = run_trials(trials, bgs, dets)
        everything += res
        print(format_table(summarise(res, lambda o: f'{o.px_per_module:g} px'),
                           f'Detection vs px per module (tilt {args.tilt[0]:g}-'
                           f'{args.tilt[1]:g} deg, seed {args.seed})'))
        print()
        print(format_table(summarise(res, tilt_bin), 'Detection vs tilt (all sizes)'))
        print()
        print(format_speed(res))
        print()
    if args.what in ('pose', 'all'):
        trials = pose_trials(args.distances, args.per_distance, seed=args.seed + 1000,
                             n_backgrounds=len(bgs))
        res = run_trials(trials, bgs, dets, pose=True)
        everything += res
        print(format_table(summarise(res, lambda o: f'{MODULE * CAMERA.fx / o.px_per_module:g}'
                                                    ' m'),
                           'Pose (tilt 0-60 deg): p_detect; median position / angle error, '
                           'worst angle', pose=True))
        print()
    if args.what in ('false', 'all'):
        boards: List[np.ndarray] = []
        if not args.no_chessboard_photos:
            try:
                boards = chessboard_photos()
            except (FileNotFoundError, ValueError) as err:
                print(f'{err}\n(or run without them: --no-chessboard-photos)',
                      file=sys.stderr)
                return 2
        res = false_frames(bgs, args.false_frames, args.seed + 2000,
                           default_extra_photos() if args.backgrounds is None else (),
                           params=lm_params, chessboards=boards,
                           chessboard_share=args.chessboard_share)
        print(f'Landmark-free real frames: {sum(res.frames.values())} '
              f'({", ".join(f"{k} {v}" for k, v in sorted(res.frames.items()))}); '
              f'detections (all false): {sum(res.detections.values())} '
              f'({", ".join(f"{k} {v}" for k, v in sorted(res.detections.items()))}); '
              f'{res.ms_per_frame:.1f} ms per frame')
        print()
    if args.what == 'stages':
        trials = detection_trials(args.sizes, args.per_size, tuple(args.tilt), args.seed,
                                  len(bgs))
        print('Where the landmark detector loses the landmark (first failing stage):')
        for size, row in stage_counts(trials, bgs, lm_params).items():
            items = sorted(row.items(), key=lambda kv: -kv[1])
            print(f'  {size}: ' + '; '.join(f'{k} {v}' for k, v in items))
        print()
    dets.close()
    if args.json:
        args.json.write_text(json.dumps([asdict(o) for o in everything], indent=0))
    return 0


if __name__ == '__main__':
    sys.exit(main())
