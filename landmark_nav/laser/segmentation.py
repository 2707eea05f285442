"""Split a scan into clusters of consecutive valid points (corner chapter, section 2).

Two consecutive beams belong to the same cluster when both are valid and the distance
between their points is below an adaptive breakpoint threshold (Borges & Aldon 2004)::

    D_max(i) = r_(i-1) * sin(dphi) / sin(lambda - dphi) + 3 * sigma_r

``dphi`` is the angular step, ``lambda`` the smallest incidence angle of a surface still
treated as continuous (10 deg by default) and ``sigma_r`` the range noise. The threshold
grows with range and angular resolution, so far walls stay whole and near gaps still
split. Invalid readings (NaN, +-inf, outside [range_min, range_max]) always break a
cluster. Clusters with fewer than ``min_points`` points are dropped.
"""

from dataclasses import dataclass, field
import math
from typing import List, Optional

import numpy as np


@dataclass(frozen=True, eq=False)
class ScanArrays:
    """Whole-scan arrays shared by the clusters of one :func:`segment_scan` call.

    Feature extractors gather all clusters of a scan from these with one index array
    instead of concatenating per-cluster copies and recomputing the trigonometry.

    Attributes:
        points: (N, 2) Cartesian points in the laser frame [m] (origin at invalid beams).
        ranges: (N,) ranges [m].
        angles: (N,) beam angles [rad].
        cos: (N,) ``cos(angles)``.
        sin: (N,) ``sin(angles)``.
        valid: (N,) bool, the beams that are real returns (None: unknown, e.g. built by
            hand; extractors then know only the beams of the clusters).

    """

    points: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    cos: np.ndarray
    sin: np.ndarray
    valid: Optional[np.ndarray] = None


@dataclass(frozen=True)
class Cluster:
    """Consecutive valid beams of one scan, assumed to come from one object.

    Attributes:
        indices: (K,) beam indices into the scan, increasing and consecutive.
        points: (K, 2) Cartesian points in the laser frame [m].
        ranges: (K,) measured ranges [m].
        angles: (K,) beam angles [rad].
        scan: The arrays of the whole scan when ``points``, ``ranges`` and ``angles`` are
            the slices ``indices`` of them (set by :func:`segment_scan`), else None.

    """

    indices: np.ndarray
    points: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    scan: Optional[ScanArrays] = field(default=None, repr=False, compare=False)

    def __len__(self) -> int:
        """Return the number of points."""
        return len(self.indices)


def breakpoint_threshold(previous_ranges: np.ndarray, angle_increment: float,
                         incidence_deg: float = 10.0, sigma_r: float = 0.01) -> np.ndarray:
    """Return the adaptive breakpoint distance for gaps after beams at these ranges [m]."""
    dphi = abs(angle_increment)
    lam = math.radians(incidence_deg)
    if not 0.0 < dphi < lam:
        raise ValueError(f'angle increment {dphi} rad must be in (0, incidence angle {lam} rad)')
    return previous_ranges * (math.sin(dphi) / math.sin(lam - dphi)) + 3.0 * sigma_r


def segment_scan(ranges: np.ndarray, angles: np.ndarray, valid: np.ndarray,
                 angle_increment: float, incidence_deg: float = 10.0, sigma_r: float = 0.01,
                 min_points: int = 5) -> List[Cluster]:
    """Split one scan into clusters of consecutive valid points.

    Args:
        ranges: (N,) ranges [m] (invalid entries may hold anything).
        angles: (N,) beam angles [rad].
        valid: (N,) bool, True where the range is a real return in [range_min, range_max].
        angle_increment: beam spacing [rad].
        incidence_deg: smallest surface incidence angle still continuous [deg].
        sigma_r: range noise std [m].
        min_points: smallest cluster kept.

    Returns:
        Clusters in beam order.

    """
    ranges = np.asarray(ranges, dtype=float)
    angles = np.asarray(angles, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    if not ranges.shape == angles.shape == valid.shape or ranges.ndim != 1:
        raise ValueError('ranges, angles and valid must be 1-D arrays of equal length')
    if min_points < 1:
        raise ValueError(f'min_points must be >= 1, got {min_points}')
    n = len(ranges)
    if n == 0 or not valid.any():
        return []
    r = np.where(valid, ranges, 0.0)
    cos, sin = np.cos(angles), np.sin(angles)
    xy = np.column_stack([r * cos, r * sin])
    gaps = np.hypot(*(xy[1:] - xy[:-1]).T)
    limits = breakpoint_threshold(r[:-1], angle_increment, incidence_deg, sigma_r)
    joined = valid[:-1] & valid[1:] & (gaps <= limits)  # beam i and i+1 in one cluster
    # Cluster starts: valid beams not joined to their predecessor.
    starts = np.flatnonzero(valid & np.concatenate([[True], ~joined]))
    ends = np.flatnonzero(valid & np.concatenate([~joined, [True]])) + 1
    scan = ScanArrays(xy, ranges, angles, cos, sin, valid)
    clusters = []
    for s, e in zip(starts, ends):
        if e - s >= min_points:
            idx = np.arange(s, e)
            clusters.append(Cluster(idx, xy[s:e], ranges[s:e], angles[s:e], scan))
    return clusters
