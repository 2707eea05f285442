"""The detectors compared on the composites of :mod:`.landmarks_real`, behind one interface.

:class:`Detectors` runs the package's landmark detector (and its fast mode), AprilTag 3
(``pupil_apriltags``) and OpenCV ArUco on a frame and returns their detections as
:class:`Found` (code, corners and, if asked, the optical pose); :func:`release_apriltags`
frees AprilTag's detectors in the order its C library needs.
"""

from dataclasses import dataclass, replace
from typing import List, Optional, Sequence
import weakref

import cv2
from landmark_nav.evaluation.marker_composites import CAMERA, MODULE
from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.detector import detect_landmarks, DetectorParams
from landmark_nav.vision.landmark import LandmarkDesign
from landmark_nav.vision.pose import estimate_pose, PoseError, PoseParams
import numpy as np

#: Detectors, in table order; ``landmark_fast`` is the landmark detector's fast mode
#: (``DetectorParams.decimate = 2``), ``apriltag2`` AprilTag with ``quad_decimate = 2``.
DETECTORS = ('landmark', 'landmark_fast', 'apriltag1', 'apriltag2', 'aruco')


def marker_family(detector: str) -> str:
    """Return the printed marker type of a detector name (``apriltag1`` -> ``apriltag``)."""
    if detector.startswith('landmark'):
        return 'landmark'
    return 'apriltag' if detector.startswith('apriltag') else detector


@dataclass(frozen=True, eq=False)
class Found:
    """One detection of any detector: code, (4, 2) corners, optional (R, t) optical pose.

    The landmark detector's poses also carry their parameters ``v`` and 6 x 6 covariance
    and whether they were reported as ambiguous (:class:`~landmark_nav.vision.pose.LandmarkPose`).
    """

    code: int
    corners: np.ndarray
    rotation: Optional[np.ndarray] = None
    translation: Optional[np.ndarray] = None
    v: Optional[np.ndarray] = None
    covariance: Optional[np.ndarray] = None
    ambiguous: bool = False


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
                p = None
                if pose:
                    try:
                        p = estimate_pose(d.corners, cam, self.design, self.pose_params,
                                          edge_corners_px=d.edge_corners)
                    except PoseError:
                        pass
                if p is None:
                    out.append(Found(d.code, d.corners))
                else:
                    out.append(Found(d.code, d.corners, p.rotation_optical,
                                     p.translation_optical, p.v, p.covariance, p.ambiguous))
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


__all__ = ['DETECTORS', 'Detectors', 'Found', 'marker_family', 'release_apriltags']
