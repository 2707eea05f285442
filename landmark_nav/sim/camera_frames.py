"""Camera frames of the camera scenarios: the rendered image and its ground truth.

:class:`CameraFrame` (image + camera model + camera pose + ground truth) and
:class:`LandmarkTruth` (a landmark's pose in the optical frame, its frame corners in
distorted pixels, block size, visibility: :func:`landmark_truth`), the default simulated
camera (:func:`default_camera`) and the cache of renderers (:func:`simulator_for`). The
conventions are those of :mod:`landmark_nav.sim.camera_scenarios`, the entry point.
"""

from dataclasses import dataclass, field
import math
from typing import Any, Dict, Optional, Tuple

from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np

from .camera import CameraSimulator, Photometry, RenderOptions


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


__all__ = ['CameraFrame', 'default_camera', 'landmark_truth', 'LandmarkTruth', 'simulator_for']
