"""Keyframes: which scans the map needs, and the pose of the scans in between (ROS free).

A scan becomes a *keyframe* when the odometry has travelled at least ``min_travel_m`` or
turned at least ``min_turn_rad`` since the last keyframe (as slam_toolbox's
``minimum_travel_distance`` / ``minimum_travel_heading`` and GMapping's ``linearUpdate`` /
``angularUpdate``): only keyframes reach the filter, with one prediction over the whole
motion since the previous keyframe (the odometry increment of eq. 13 over that span, or the
scan-matched motion of this keyframe's scan against the previous keyframe's) and the
landmark update with its map management. A scan in between changes nothing in the filter:
its pose is the last keyframe's composed with the odometry increment since it (eq. 16) and
its covariance the robot block propagated by the prediction (eq. 26) on a copy, so
the pose is still published at every scan. With both thresholds 0 every scan is a keyframe
(the chapter's filter, one step per scan).

The first scan, and a scan whose span holds a bridged odometry jump, is always a keyframe
(the jump's variance must reach the filter).
"""

from dataclasses import dataclass
import math
from typing import Tuple

import numpy as np

from .ekf_slam import UpdateResult
from .prediction import ekf_predict

#: The result of a set between keyframes: no observation went to the filter.
NO_UPDATE = UpdateResult(np.zeros(0, dtype='<U9'), np.zeros(0, dtype=np.int64),
                         np.zeros(0, dtype=np.int64), np.zeros(0, dtype='<U12'), np.zeros(0),
                         0.0, 0, False, 0, np.zeros(0, dtype=np.int8))


@dataclass(frozen=True)
class KeyframeParams:
    """Keyframe thresholds (module docstring; both 0: every scan is a keyframe).

    Attributes:
        min_travel_m: Odometry translation since the last keyframe that makes a keyframe [m].
        min_turn_rad: Odometry rotation since the last keyframe that makes a keyframe [rad].
    """

    min_travel_m: float = 0.0
    min_turn_rad: float = 0.0

    def __post_init__(self) -> None:
        """Validate; raise ValueError naming the bad field."""
        for name in ('min_travel_m', 'min_turn_rad'):
            v = getattr(self, name)
            if (not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v)
                    or v < 0.0):
                raise ValueError(f'KeyframeParams.{name} must be a finite number >= 0 '
                                 f'(0 = every scan), got {v!r}')

    @property
    def enabled(self) -> bool:
        """Whether some scans are skipped (a threshold above 0)."""
        return self.min_travel_m > 0.0 or self.min_turn_rad > 0.0

    def is_keyframe(self, increment: np.ndarray) -> bool:
        """Return whether the odometry ``increment`` since the last keyframe makes one.

        Args:
            increment: (3,) odometry increment ``(-)x_o(kf) (+) x_o(k)`` (eq. 13).
        """
        if not self.enabled:
            return True
        return bool(math.hypot(increment[0], increment[1]) >= self.min_travel_m > 0.0
                    or abs(increment[2]) >= self.min_turn_rad > 0.0)


def pose_between_keyframes(pose: np.ndarray, covariance: np.ndarray, increment: np.ndarray,
                           increment_covariance: np.ndarray
                           ) -> Tuple[np.ndarray, np.ndarray]:
    """Return the robot pose and its covariance a scan between keyframes gets.

    The last keyframe's pose composed with the odometry increment since it (eq. 25) and the
    robot block of the prediction (eq. 26), computed on copies: the filter is unchanged.

    Args:
        pose: (3,) the filter's robot pose at the last keyframe.
        covariance: (3, 3) its covariance.
        increment: (3,) odometry increment since that keyframe (eq. 13).
        increment_covariance: (3, 3) its covariance ``U``.
    """
    x = np.array(pose, dtype=float)
    p = np.array(covariance, dtype=float)
    ekf_predict(x, p, np.asarray(increment, dtype=float), increment_covariance)
    return x, p


__all__ = ['KeyframeParams', 'NO_UPDATE', 'pose_between_keyframes']
