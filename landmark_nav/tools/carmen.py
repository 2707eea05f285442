"""Read laser scans from Carmen log files (Radish datasets), e.g. ``aces-corrected.log.gz``.

Only ``FLASER`` lines are used: ``FLASER n r1 .. rn x y theta odom_x odom_y odom_theta
ipc_timestamp hostname logger_timestamp``. Scans are assumed to span 180 deg starting at
-90 deg; the angular step follows from ``n`` (180 readings -> 1 deg steps starting at
-90 deg; 181 or 361 readings -> 1 deg or 0.5 deg steps from -90 to +90 deg). Readings at
or beyond ``max_range`` (Carmen writes the sensor's maximum, e.g. 50 m or 81.9 m, for no
return) are reported as +inf per REP 117.
"""

from dataclasses import dataclass
import gzip
import math
from pathlib import Path
from typing import Iterator

import numpy as np


@dataclass(frozen=True)
class CarmenScan:
    """One FLASER reading."""

    stamp: float
    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    pose: np.ndarray
    odom_pose: np.ndarray

    @property
    def angles(self) -> np.ndarray:
        """Return the beam angles [rad]."""
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges))


def scan_geometry(n: int):
    """Return (angle_min, angle_increment) of an n-beam Carmen front laser."""
    if n <= 0:
        raise ValueError(f'FLASER with {n} readings')
    if n % 2 == 0:  # 180 readings: 1 deg steps from -90 deg, the last at +89 deg
        return -math.pi / 2, math.pi / n
    return -math.pi / 2, math.pi / (n - 1)


def read_carmen_scans(path, max_range: float = 40.0) -> Iterator[CarmenScan]:
    """Yield the FLASER scans of a (optionally gzipped) Carmen log.

    Raises:
        ValueError: A FLASER line is malformed (message names the line number).

    """
    path = Path(path)
    opener = gzip.open if path.suffix == '.gz' else open
    with opener(path, 'rt') as f:
        for lineno, line in enumerate(f, 1):
            if not line.startswith('FLASER '):
                continue
            fields = line.split()
            try:
                n = int(fields[1])
                values = np.array(fields[2:2 + n], dtype=float)
                rest = np.array(fields[2 + n:8 + n], dtype=float)
                stamp = float(fields[8 + n])
            except (IndexError, ValueError) as err:
                raise ValueError(f'{path}:{lineno}: malformed FLASER line ({err})') from err
            if len(values) != n or len(rest) != 6:
                raise ValueError(f'{path}:{lineno}: FLASER line too short')
            ranges = np.where(values >= max_range, np.inf, values)
            angle_min, inc = scan_geometry(n)
            yield CarmenScan(stamp, ranges, angle_min, inc, rest[:3], rest[3:])
