"""Printed markers composited into real photographs: the frames of :mod:`.landmarks_real`.

Backgrounds (:func:`load_backgrounds`), the printed patterns (:func:`marker_texture`), the
marker poses (:func:`draw_pose`) and the image formation (:func:`composite`,
:func:`degrade`) of the comparison of landmarks, AprilTags and ArUco markers.

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
"""

from dataclasses import dataclass
import math
from pathlib import Path
from typing import List

import cv2
from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
from landmark_nav.vision.landmark import LandmarkDesign
from landmark_nav.vision.pose import angles_from_rotation, project_points, rotation_matrix
import numpy as np
from scipy.spatial.transform import Rotation

_M = np.asarray(OPTICAL_FROM_BODY, dtype=float)

#: The camera of the composites: f = 600 px, 640 x 480, no distortion.
CAMERA = CameraModel(640, 480, np.array([[600.0, 0.0, 319.5], [0.0, 600.0, 239.5],
                                         [0.0, 0.0, 1.0]]), np.zeros(5))
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


__all__ = ['CAMERA', 'composite', 'CORNER_MODULES', 'default_backgrounds', 'degrade',
           'draw_photometrics', 'draw_pose', 'load_backgrounds', 'marker_corners',
           'marker_texture', 'MODULE', 'Photometrics', 'PRINTED_MODULES', 'SUPERSAMPLE',
           'TEXTURE_PX', 'texture_homography']
