"""A detected corner: :class:`Corner`, its bisector and opening, and the Corner objects.

See the output conventions in :mod:`landmark_nav.laser.corners`.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Tuple

import numpy as np


_TWO_PI = 2.0 * math.pi
#: A corner is **structural** when both its arms (``Corner.arms``) are at least this long
#: [m]: two surfaces of a building (walls, pillars) rather than furniture or clutter. On the
#: six Carmen logs the corners with both arms >= 0.5 m are re-detected in the next scan
#: 0.79 .. 0.91 of the time, the others 0.63 .. 0.82 (0.3 m: 0.76 .. 0.89 and 0.65 .. 0.80).
STRUCTURAL_ARM = 0.5


@dataclass(frozen=True, eq=False)
class Corner:
    """One detected corner, in the laser frame.

    Attributes:
        position: (2,) corner position [m] (the refined TLS intersection when refined, else
            the corner sample).
        bisector: direction [rad] of the bisector of the free-space wedge, pointing from the
            corner into free space (toward the sensor side).
        opening: angle of the free-space wedge between the two arms [rad], in (0, 2 pi):
            ``theta`` (about pi/2) for a concave corner seen from inside, ``2 pi - theta``
            (about 3 pi / 2) for a convex corner; ``theta`` is the angle between the arms.
        covariance: (2, 2) position covariance [m^2].
        index: beam index (into the scan) of the corner sample: the vertex of the best
            two-line split when refined, the window midpoint or the split point otherwise.
        f_theta: minus-cosine value of the detecting window (eq. 11); nan for the methods
            that do not compute it (sliding window, split and merge).
        arms: (2, 2, 2) the two arms as segments [arm][inner end, outer end][x, y] [m]:
            for refined and split-and-merge corners the extent of the samples supporting
            each arm's line (ends where the first and last sample's ray meets the line; no
            sample inside is seen through it), for unrefined corners the corner sample and
            the window's terminal samples.

    ``structural`` labels the corners whose two arms are both at least
    :data:`STRUCTURAL_ARM` long (a building's corner rather than clutter).
    """

    position: np.ndarray
    bisector: float
    opening: float
    covariance: np.ndarray
    index: int
    f_theta: float
    arms: Optional[np.ndarray] = None

    @property
    def arm_lengths(self) -> np.ndarray:
        """Return the (2,) lengths of the arms [m]; NaN without arms."""
        if self.arms is None:
            return np.full(2, np.nan)
        a = np.asarray(self.arms, dtype=float)
        return np.hypot(a[:, 1, 0] - a[:, 0, 0], a[:, 1, 1] - a[:, 0, 1])

    @property
    def structural(self) -> bool:
        """Return whether both arms are at least :data:`STRUCTURAL_ARM` long."""
        return bool(np.all(self.arm_lengths >= STRUCTURAL_ARM))


def _free_side(cx: np.ndarray, cy: np.ndarray, u1x: np.ndarray, u1y: np.ndarray,
               u2x: np.ndarray, u2y: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (bisector angle, opening, cos theta) of corners ``(cx, cy)`` (vectorised).

    ``u1``, ``u2`` are unit vectors from the corner along its arms. The sensor (laser
    origin) on the side the arms open to means a concave corner (opening ``theta``), else
    convex (opening ``2 pi - theta``); the bisector points into free space.
    """
    cos_t = np.clip(u1x * u2x + u1y * u2y, -1.0, 1.0)
    theta = np.arccos(cos_t)
    bx, by = u1x + u2x, u1y + u2y
    concave = cx * bx + cy * by <= 0.0
    sign = np.where(concave, 1.0, -1.0)
    return (np.arctan2(sign * by, sign * bx), np.where(concave, theta, _TWO_PI - theta),
            cos_t)


def _unit(vx: np.ndarray, vy: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    n = np.sqrt(vx * vx + vy * vy)
    return vx / n, vy / n


def _make(cx: np.ndarray, cy: np.ndarray, bis: np.ndarray, opening: np.ndarray,
          cov: np.ndarray, index: np.ndarray, f: np.ndarray, arms: np.ndarray
          ) -> List[Corner]:
    """Build Corner objects (read-only arrays); ``arms`` (K, 2, 2, 2) arm segments."""
    pos = np.empty((cx.size, 2))
    pos[:, 0], pos[:, 1] = cx, cy
    cov = np.array(cov, dtype=float)
    arms = np.array(arms, dtype=float)
    pos.setflags(write=False)
    cov.setflags(write=False)
    arms.setflags(write=False)
    return [Corner(position=p_, bisector=b_, opening=o_, covariance=c_, index=i_, f_theta=f_,
                   arms=a_)
            for p_, b_, o_, c_, i_, f_, a_ in zip(pos, bis.tolist(), opening.tolist(), cov,
                                                  index.tolist(), f.tolist(), arms)]
