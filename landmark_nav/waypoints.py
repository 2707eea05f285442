"""Follow a list of waypoints with a differential-drive robot: pose in, (v, w) out.

A small go-to-point law (no source chapter; the simulator's mission controller does the
same on the true pose): at each waypoint the robot turns in place when the heading error
exceeds ``turn_enter`` (until it is below ``align``), then drives with ``v = v_max cos(e)``
limited so it can brake at ``decel`` to a stop waypoint, and ``w = k e``. A waypoint where
the path turns by more than ``stop_turn`` (and the last one) is a stop within
``stop_tolerance``; the others are passed within ``pass_tolerance``. Used by
``landmark_nav drive``, which sends the commands on ``cmd_vel``.
"""

from dataclasses import dataclass
import math
from typing import Sequence, Tuple

import numpy as np


@dataclass(frozen=True)
class FollowerParams:
    """Limits and gains of :class:`WaypointFollower` (SI units)."""

    max_speed: float = 0.3
    max_turn_rate: float = 0.6
    heading_gain: float = 1.5
    decel: float = 0.2
    turn_enter: float = math.radians(30.0)
    align: float = math.radians(3.0)
    stop_turn: float = math.radians(20.0)
    stop_tolerance: float = 0.05
    pass_tolerance: float = 0.25

    def __post_init__(self) -> None:
        """Validate."""
        for name in ('max_speed', 'max_turn_rate', 'heading_gain', 'decel', 'align',
                     'stop_tolerance', 'pass_tolerance'):
            if not getattr(self, name) > 0.0:
                raise ValueError(f'{name} must be > 0, got {getattr(self, name)}')


class WaypointFollower:
    """Stateful follower: :meth:`command` maps the current pose to ``(v, w)``."""

    def __init__(self, waypoints: Sequence[Sequence[float]],
                 params: FollowerParams = FollowerParams()) -> None:
        """Bind the ``(W, 2)`` waypoints (frame of the poses given to :meth:`command`)."""
        pts = np.asarray(waypoints, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0 or not np.all(np.isfinite(pts)):
            raise ValueError(f'waypoints must be a non-empty (W, 2) array of finite numbers, '
                             f'got shape {pts.shape}')
        self.points = pts
        self.params = params
        self.stops = np.ones(len(pts), dtype=bool)
        for i in range(1, len(pts) - 1):
            d_in, d_out = pts[i] - pts[i - 1], pts[i + 1] - pts[i]
            turn = abs(math.remainder(math.atan2(d_out[1], d_out[0])
                                      - math.atan2(d_in[1], d_in[0]), 2.0 * math.pi))
            self.stops[i] = turn > params.stop_turn
        self.index = 0
        self.turning = True

    @property
    def done(self) -> bool:
        """Whether the last waypoint has been reached."""
        return self.index >= len(self.points)

    def command(self, pose: Sequence[float]) -> Tuple[float, float]:
        """Return ``(v [m/s], w [rad/s])`` for the pose ``(x, y, yaw)``; (0, 0) when done."""
        p = self.params
        x, y, yaw = (float(v) for v in pose)
        while not self.done:
            gx, gy = self.points[self.index]
            dist = math.hypot(gx - x, gy - y)
            stop = bool(self.stops[self.index])
            if dist < (p.stop_tolerance if stop else p.pass_tolerance):
                self.index += 1
                self.turning = True
                continue
            err = math.remainder(math.atan2(gy - y, gx - x) - yaw, 2.0 * math.pi)
            if self.turning and abs(err) < p.align:
                self.turning = False
            elif not self.turning and abs(err) > p.turn_enter:
                self.turning = True
            w = max(-p.max_turn_rate, min(p.max_turn_rate, p.heading_gain * err))
            if self.turning:
                return 0.0, w
            v = p.max_speed
            if stop:
                v = min(v, math.sqrt(2.0 * p.decel * dist))
            return v * max(0.0, math.cos(err)), w
        return 0.0, 0.0
