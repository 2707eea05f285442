"""Pose of the tilted laser and the readings placed in ``base_link`` (§4.2, step 1).

The readings of a laser scanner pitched slightly down are placed in ``base_link`` (x forward,
y left, z up, z = 0 on the ground plane under the robot) through the laser mount (x, y, z,
roll, pitch, yaw): :class:`LaserMount`, :func:`scan_points`. Entry point:
:mod:`landmark_nav.road.terrain`.
"""

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np


@dataclass(frozen=True)
class LaserMount:
    """Pose of the laser frame in ``base_link`` (REP 103; pitch > 0 tilts the scan down).

    ``z`` is the height of the laser above the ground plane under the robot.
    """

    x: float = 0.3
    y: float = 0.0
    z: float = 0.6
    roll: float = 0.0
    pitch: float = math.radians(14.0)
    yaw: float = 0.0

    def __post_init__(self) -> None:
        """Check that every field is finite and the laser is above the ground."""
        for name in ('x', 'y', 'z', 'roll', 'pitch', 'yaw'):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f'laser mount {name} must be finite; got {value!r}')
        if not self.z > 0.0:
            raise ValueError(f'laser mount z (height above the ground) must be > 0; '
                             f'got {self.z!r}')

    @classmethod
    def from_sequence(cls, values: Sequence[float]) -> 'LaserMount':
        """Build from ``[x, y, z, roll, pitch, yaw]``."""
        if len(values) != 6:
            raise ValueError(f'laser mount needs 6 values (x, y, z, roll, pitch, yaw); '
                             f'got {len(values)}')
        return cls(*(float(v) for v in values))

    def rotation(self) -> np.ndarray:
        """Return R = Rz(yaw) Ry(pitch) Rx(roll), laser frame -> base_link."""
        cr, sr = math.cos(self.roll), math.sin(self.roll)
        cp, sp = math.cos(self.pitch), math.sin(self.pitch)
        cy, sy = math.cos(self.yaw), math.sin(self.yaw)
        rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
        ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
        rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
        return rz @ ry @ rx

    def translation(self) -> np.ndarray:
        """Return the laser origin in ``base_link``."""
        return np.array([self.x, self.y, self.z])

    def ground_range(self, angles: np.ndarray) -> np.ndarray:
        """Range at which each beam meets a flat ground plane z = 0 (inf if it never does)."""
        d = self.rotation() @ np.vstack([np.cos(angles), np.sin(angles), np.zeros_like(angles)])
        with np.errstate(divide='ignore'):
            r = np.where(d[2] < -1e-9, -self.z / np.minimum(d[2], -1e-12), np.inf)
        return r


def scan_points(ranges: np.ndarray, angles: np.ndarray, mount: LaserMount) -> np.ndarray:
    """Place the readings in base_link: (N, 3) [m]; non-finite ranges give NaN rows."""
    r = np.asarray(ranges, dtype=float)
    a = np.asarray(angles, dtype=float)
    local = np.vstack([r * np.cos(a), r * np.sin(a), np.zeros_like(r)])
    return (mount.rotation() @ local).T + mount.translation()


__all__ = ['LaserMount', 'scan_points']
