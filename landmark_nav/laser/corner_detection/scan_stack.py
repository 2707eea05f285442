"""All clusters of one scan back to back (:class:`_Stack`), and the samples of two arms."""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple

from landmark_nav.laser.segmentation import Cluster
import numpy as np


@dataclass(frozen=True, eq=False)
class _Stack:
    """All clusters concatenated (1-D arrays); per-sample cluster bounds keep windows inside."""

    x: np.ndarray       # (N,) point x [m]
    y: np.ndarray       # (N,) point y [m]
    r: np.ndarray       # (N,) ranges
    phi: np.ndarray     # (N,) beam angles
    beam: np.ndarray    # (N,) beam index in the scan
    start: np.ndarray   # (N,) first sample of the sample's cluster
    end: np.ndarray     # (N,) one past the last sample of its cluster
    dphi: np.ndarray    # (N,) beam spacing of its cluster [rad] (0 for one-sample clusters)


def _stack(clusters: Sequence[Cluster]) -> Optional[_Stack]:
    """Concatenate the non-empty clusters, or return None if there are none."""
    cl = [c for c in clusters if len(c.indices) > 0]
    if not cl:
        return None
    sizes = np.array([len(c.indices) for c in cl])
    ends = sizes.cumsum()
    starts = ends - sizes
    beam = np.concatenate([c.indices for c in cl]).astype(np.int64)
    scan = cl[0].scan
    if scan is not None and all(c.scan is scan for c in cl):
        # the clusters' arrays are slices of their scan's: one gather each
        phi = scan.angles[beam].astype(float, copy=False)
        xy = scan.points[beam].astype(float, copy=False)
        r = scan.ranges[beam].astype(float, copy=False)
    else:
        phi = np.concatenate([c.angles for c in cl]).astype(float, copy=False)
        xy = np.concatenate([c.points for c in cl]).astype(float, copy=False).reshape(-1, 2)
        r = np.concatenate([c.ranges for c in cl]).astype(float, copy=False)
    dphi = np.abs(phi[ends - 1] - phi[starts]) / np.maximum(sizes - 1, 1)
    x, y = np.array(xy.T)  # contiguous copies
    bad = ~(r > 0.0) | ~np.isfinite(x + y + r)
    if bad.any():  # not a return: nan makes every window and fit through it fail
        x[bad] = y[bad] = math.nan
    return _Stack(x=x, y=y, r=r,
                  phi=phi, beam=beam,
                  start=np.repeat(starts, sizes), end=np.repeat(ends, sizes),
                  dphi=np.repeat(dphi, sizes))


def _gather_arms(st: _Stack, first: np.ndarray, count: np.ndarray, fallback: np.ndarray
                 ) -> Tuple[np.ndarray, np.ndarray]:
    """Return padded sample indices (K, 2, M) of two arms and their validity mask.

    Arm 0 runs backward from ``first[:, 0]``, arm 1 forward from ``first[:, 1]``, each
    ``count`` samples long and clipped to the cluster; padding points at ``fallback``.
    """
    big = max(int(count.max()), 1)
    k = np.arange(big)
    idx = first[:, :, None] + _STEP * k
    # inside the cluster: arm 0 down to its start, arm 1 up to its end
    room = np.empty_like(count)
    room[:, 0] = first[:, 0] - st.start[fallback] + 1
    room[:, 1] = st.end[fallback] - first[:, 1]
    valid = k < np.minimum(count, room)[:, :, None]
    return np.where(valid, idx, fallback[:, None, None]), valid


_STEP = np.array([-1, 1])[None, :, None]
