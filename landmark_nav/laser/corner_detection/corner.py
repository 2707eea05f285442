"""A detected corner: :class:`Corner`, its bisector and opening, and the Corner objects.

See the output conventions in :mod:`landmark_nav.laser.corners`.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Tuple

import numpy as np


_TWO_PI = 2.0 * math.pi
#: A corner is **structural** when each of its arms (``Corner.arms``) is a real surface seen
#: well enough to place the corner again from the next pose: at least ``STRUCTURAL_ARM`` long
#: [m] and spanning at least ``STRUCTURAL_BEAM_STEPS`` beam steps (``Corner.arm_beam_steps``:
#: ``STRUCTURAL_BEAM_STEPS + 1`` beams; the beam count, not a length, is what a line fit
#: needs, and the same length holds fewer beams far away or on a coarser laser). Chosen on
#: the six Carmen dev logs, leaving one log out (the rule with the best worst-log
#: re-detection among those marking >= 30 % of the corners of every other log, scored on
#: the log left out; ``bench_feature_metrics.py structural-rule``): re-detected in the next
#: scan 0.856 .. 0.921 of the time on the log left out (corners of the former rule, both
#: arms >= 0.5 m: 0.79 .. 0.91). Requiring also that the scan show both arms' ends
#: (``Corner.occluded``, ``Corner.silhouette``) was measured and not adopted: with the
#: same selection it marks fewer corners (0.22 .. 0.48 of them instead of 0.37 .. 0.63)
#: and its choice over all logs re-detects 0.773 on acapulco (``structural-rule
#: --arm-ends required``); on Wean it does not bring the corners onto the walls either
#: (docs/laser_features.md).
STRUCTURAL_ARM = 0.2
STRUCTURAL_BEAM_STEPS = 5


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

        beam_step: the scan's beam spacing at the corner [rad] (NaN when unknown).
        arm_ends: what the scan shows beyond each arm's outer end, a pair of
            :data:`~landmark_nav.laser.corner_detection.arm_ends.ARM_ENDS` names
            (``'inside'``, ``'nearer'``, ``'farther'``, ``'unknown'``); None unless asked
            for (``CornerParams.arm_ends``) and the detector has the whole scan (not with
            clusters built by hand).

    ``structural`` labels the corners whose two arms are both at least
    :data:`STRUCTURAL_ARM` long and :data:`STRUCTURAL_BEAM_STEPS` beam steps wide (a
    surface the next scan re-detects, rather than a few returns of clutter).
    :attr:`occluded` and :attr:`silhouette` say whether the scan shows where the arms end
    (not part of the label, see :data:`STRUCTURAL_ARM`).
    """

    position: np.ndarray
    bisector: float
    opening: float
    covariance: np.ndarray
    index: int
    f_theta: float
    arms: Optional[np.ndarray] = None
    beam_step: float = math.nan
    arm_ends: Optional[Tuple[str, str]] = None

    @property
    def arm_lengths(self) -> np.ndarray:
        """Return the (2,) lengths of the arms [m]; NaN without arms."""
        if self.arms is None:
            return np.full(2, np.nan)
        a = np.asarray(self.arms, dtype=float)
        return np.hypot(a[:, 1, 0] - a[:, 0, 0], a[:, 1, 1] - a[:, 0, 1])

    @property
    def arm_beam_steps(self) -> np.ndarray:
        """Return the (2,) beam steps each arm spans (its ends' bearings over ``beam_step``).

        NaN without arms or beam spacing. An arm's ends lie on the rays of its first and
        last sample, so this is its number of beams minus one.
        """
        if self.arms is None or not self.beam_step > 0.0:
            return np.full(2, np.nan)
        a = np.asarray(self.arms, dtype=float)
        bearing = np.arctan2(a[:, :, 1], a[:, :, 0])
        span = np.abs(np.angle(np.exp(1j * (bearing[:, 1] - bearing[:, 0]))))
        return np.rint(span / self.beam_step)

    @property
    def occluded(self) -> bool:
        """Return whether an arm ends at a jump to a nearer surface (its extent unknown).

        False when :attr:`arm_ends` is None (not known).
        """
        return self.arm_ends is not None and 'nearer' in self.arm_ends

    @property
    def silhouette(self) -> bool:
        """Return whether the corner is convex and both arms end at jumps to farther ranges."""
        return (self.arm_ends is not None and self.opening > math.pi
                and all(e == 'farther' for e in self.arm_ends))

    @property
    def structural(self) -> bool:
        """Return whether both arms are :data:`STRUCTURAL_ARM` long and wide enough in beams.

        Wide enough: :data:`STRUCTURAL_BEAM_STEPS` beam steps (:attr:`arm_beam_steps`).
        """
        return bool(np.all(self.arm_lengths >= STRUCTURAL_ARM)
                    and np.all(self.arm_beam_steps >= STRUCTURAL_BEAM_STEPS))


def _free_side(cx: np.ndarray, cy: np.ndarray, u1x: np.ndarray, u1y: np.ndarray,
               u2x: np.ndarray, u2y: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (bisector angle, opening, cos theta) of corners ``(cx, cy)`` (vectorised).

    ``u1``, ``u2`` are unit vectors from the corner along its arms. The sensor (laser
    origin) on the side the arms open to means a concave corner (opening ``theta``), else
    convex (opening ``2 pi - theta``); the bisector points into free space.
    """
    cos_t = np.minimum(np.maximum(u1x * u2x + u1y * u2y, -1.0), 1.0)  # np.clip, cheaper
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
          cov: np.ndarray, index: np.ndarray, f: np.ndarray, arms: np.ndarray,
          beam_step: np.ndarray) -> List[Corner]:
    """Build Corner objects (read-only arrays).

    ``arms`` (K, 2, 2, 2) arm segments; ``beam_step`` (K,) the beam spacing at each [rad].
    """
    pos = np.empty((cx.size, 2))
    pos[:, 0], pos[:, 1] = cx, cy
    cov = np.array(cov, dtype=float)
    arms = np.array(arms, dtype=float)
    pos.setflags(write=False)
    cov.setflags(write=False)
    arms.setflags(write=False)
    return [Corner(position=p_, bisector=b_, opening=o_, covariance=c_, index=i_, f_theta=f_,
                   arms=a_, beam_step=s_)
            for p_, b_, o_, c_, i_, f_, a_, s_ in zip(
                pos, bis.tolist(), opening.tolist(), cov, index.tolist(), f.tolist(), arms,
                np.asarray(beam_step, dtype=float).tolist())]
