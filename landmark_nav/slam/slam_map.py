"""A saved EKF-SLAM map: :class:`SlamMap`, :func:`save_map`, :func:`load_map`.

File format (``.npz``, numpy's documented zip of ``.npy`` arrays, written without pickles
and read with ``allow_pickle=False``), N landmarks, map frame, SI units and radians:

=============== ============ ==========================================================
array           shape, type  meaning
=============== ============ ==========================================================
``format``      () str       ``'landmark_nav.slam_map'``
``version``     () int64     1
``frame``       () str       frame of the map (``'map'``)
``ids``         (N,) int64   landmark ids (unique)
``kinds``       (N,) int8    0 corner, 1 line
``means``       (N, 2)       corner ``(x, y)`` [m]; line ``(rho, alpha)`` [m, rad] with
                             ``x cos(alpha) + y sin(alpha) = rho`` (Hessian normal form)
``covariance``  (2N, 2N)     joint covariance of ``means`` flattened in landmark order
                             (rows ``2k, 2k + 1`` are landmark ``k``)
``ends``        (N, 2, 2)    line segment endpoints ``[start, end][x, y]`` [m]; NaN for
                             corners (display and association only)
``bisectors``   (N, 2)       corners: sum of the unit vectors of the observed free-space
                             bisectors in the map (zeros: unknown); zeros for lines
``openings``    (N,)         corners: mean free-space opening [rad] (NaN: unknown)
``n_openings``  (N,) int64   observations averaged into ``openings``
``hits``        (N,) int64   detections of the landmark
``max_seen``    (N,)         largest distance it was detected at [m] (corner range, line
                             ``rho`` in base_link); used by visibility pruning
``next_id``     () int64     the next free id
=============== ============ ==========================================================

The robot pose is not part of the map: :meth:`~.ekf_slam.EkfSlam.load_map` starts the
filter at a pose and pose covariance given by the user, uncorrelated with the map.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Union
import zipfile

import numpy as np

FORMAT = 'landmark_nav.slam_map'
VERSION = 1


@dataclass(frozen=True, eq=False)
class SlamMap:
    """A landmark map (fields: see the module docstring's table)."""

    ids: np.ndarray
    kinds: np.ndarray
    means: np.ndarray
    covariance: np.ndarray
    ends: np.ndarray
    bisectors: np.ndarray
    openings: np.ndarray
    n_openings: np.ndarray
    hits: np.ndarray
    max_seen: np.ndarray
    next_id: int
    frame: str = 'map'

    def __post_init__(self) -> None:
        """Validate shapes and values; raise ValueError naming the bad field."""
        n = np.asarray(self.ids).size
        shapes = {'ids': (n,), 'kinds': (n,), 'means': (n, 2), 'covariance': (2 * n, 2 * n),
                  'ends': (n, 2, 2), 'bisectors': (n, 2), 'openings': (n,),
                  'n_openings': (n,), 'hits': (n,), 'max_seen': (n,)}
        for name, shape in shapes.items():
            got = np.asarray(getattr(self, name)).shape
            if got != shape:
                raise ValueError(f'SlamMap.{name} has shape {got}, expected {shape} '
                                 f'for {n} landmarks')
        if len(set(np.asarray(self.ids).tolist())) != n:
            raise ValueError('SlamMap.ids are not unique')
        if not np.all(np.isin(self.kinds, (0, 1))):
            raise ValueError('SlamMap.kinds must be 0 (corner) or 1 (line)')
        for name in ('means', 'covariance', 'bisectors', 'max_seen'):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f'SlamMap.{name} is not finite')
        cov = np.asarray(self.covariance)
        if not np.allclose(cov, cov.T, rtol=0.0, atol=1e-9 * max(1.0, np.abs(cov).max(
                initial=0.0))):
            raise ValueError('SlamMap.covariance is not symmetric')
        if n and int(self.next_id) <= int(np.max(self.ids)):
            raise ValueError(f'SlamMap.next_id {self.next_id} is not above the largest id')

    @property
    def size(self) -> int:
        """Number of landmarks."""
        return int(np.asarray(self.ids).size)


def save_map(path: Union[str, Path], slam_map: SlamMap) -> Path:
    """Write a map (module docstring format); ``.npz`` is appended when missing.

    Args:
        path: Output file.
        slam_map: The map.

    Returns:
        The path written.
    """
    path = Path(path)
    if path.suffix != '.npz':
        path = path.with_name(path.name + '.npz')
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, format=np.array(FORMAT), version=np.int64(VERSION),
             frame=np.array(slam_map.frame), ids=np.asarray(slam_map.ids, dtype=np.int64),
             kinds=np.asarray(slam_map.kinds, dtype=np.int8),
             means=np.asarray(slam_map.means, dtype=float),
             covariance=np.asarray(slam_map.covariance, dtype=float),
             ends=np.asarray(slam_map.ends, dtype=float),
             bisectors=np.asarray(slam_map.bisectors, dtype=float),
             openings=np.asarray(slam_map.openings, dtype=float),
             n_openings=np.asarray(slam_map.n_openings, dtype=np.int64),
             hits=np.asarray(slam_map.hits, dtype=np.int64),
             max_seen=np.asarray(slam_map.max_seen, dtype=float),
             next_id=np.int64(slam_map.next_id))
    return path


def load_map(path: Union[str, Path]) -> SlamMap:
    """Read a map written by :func:`save_map`.

    Args:
        path: The ``.npz`` file.

    Returns:
        The map.

    Raises:
        ValueError: One line naming the file and what is wrong (not a map file, another
            version, a missing array, bad shapes or values).
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise ValueError(f'{path}: no such map file') from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ValueError(f'{path}: not a landmark_nav map file ({exc})') from None
    if str(arrays.get('format', '')) != FORMAT:
        raise ValueError(f'{path}: not a landmark_nav map file (format '
                         f'{str(arrays.get("format", "missing"))!r})')
    if int(arrays.get('version', -1)) != VERSION:
        raise ValueError(f'{path}: map file version {arrays.get("version")}, this reader '
                         f'knows {VERSION}')
    names = ('ids', 'kinds', 'means', 'covariance', 'ends', 'bisectors', 'openings',
             'n_openings', 'hits', 'max_seen', 'next_id')
    missing = [k for k in names if k not in arrays]
    if missing:
        raise ValueError(f'{path}: map file lacks {", ".join(missing)}')
    try:
        return SlamMap(ids=arrays['ids'].astype(np.int64), kinds=arrays['kinds'].astype(np.int8),
                       means=arrays['means'], covariance=arrays['covariance'],
                       ends=arrays['ends'], bisectors=arrays['bisectors'],
                       openings=arrays['openings'], n_openings=arrays['n_openings'],
                       hits=arrays['hits'], max_seen=arrays['max_seen'],
                       next_id=int(arrays['next_id']), frame=str(arrays.get('frame', 'map')))
    except ValueError as exc:
        raise ValueError(f'{path}: {exc}') from None


__all__ = ['FORMAT', 'load_map', 'save_map', 'SlamMap', 'VERSION']
