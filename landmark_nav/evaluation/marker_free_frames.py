"""Real frames without a landmark for the false-detection count of :mod:`.landmarks_real`.

:func:`false_frames` runs the landmark detector on random views (:func:`transformed_photo`)
of real photographs -- the York Urban backgrounds, the CamVid road frames
(:func:`default_extra_photos`) and OpenCV's photographs of a printed chessboard
(:func:`chessboard_photos`) -- some with a rendered checkerboard
(:func:`checkerboard_texture`) composited like the markers; every detection is false.
"""

from dataclasses import dataclass
from pathlib import Path
import time
from typing import Dict, List, Sequence

import cv2
from landmark_nav.evaluation.marker_composites import (composite, degrade, draw_photometrics,
                                                       draw_pose, MODULE, TEXTURE_PX)
from landmark_nav.vision.detector import detect_landmarks, DetectorParams
import numpy as np


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


__all__ = ['checkerboard_texture', 'CHESSBOARD_PHOTOS', 'chessboard_cache',
           'chessboard_photo_dir', 'chessboard_photos', 'default_extra_photos', 'FalseResult',
           'false_frames', 'fetch_chessboard_photos', 'OPENCV_DOC_DATA', 'transformed_photo']
