"""Playback timing for bag replay (pure: no clock reads, no ROS).

A message logged at ``t`` (ns) is due ``(t - t_first - offset) / rate`` seconds after
playback starts, where ``t_first`` is the bag's first log time and ``offset`` the start
offset. Messages before the offset are skipped.
"""

from dataclasses import dataclass
import math
from typing import Optional, Tuple


@dataclass(frozen=True)
class ReplayOptions:
    """How to replay a bag, like ``ros2 bag play``.

    Attributes:
        rate: Playback speed factor (> 0); 2.0 plays twice as fast as recorded.
        start_offset_s: Seconds into the bag at which playback starts (>= 0).
        topics: Only these topics (None = all).
        loop: Start again at the end, until interrupted.
        clock_hz: Publish /clock (rosgraph_msgs/Clock) at this rate in bag time; 0 = off.
        delay_s: Wait this long before the first message (after the wait for subscribers).
        wait_for_subscribers_s: Before playing, wait up to this long until the subscribers
            already running are connected: some played topic has a subscriber (every one
            when ``topics`` names them) and every subscriber in the ROS graph on a played
            topic is matched (for 0.2 s in a row,
            so a late-discovered node is not missed); 0 = start at once.
        min_subscribers: ``((topic, n), ...)``: the wait also needs at least ``n`` matched
            subscribers on each of these topics (nodes still starting are not yet in the
            graph; a pipeline knows how many will subscribe).

    """

    rate: float = 1.0
    start_offset_s: float = 0.0
    topics: Optional[Tuple[str, ...]] = None
    loop: bool = False
    clock_hz: float = 0.0
    delay_s: float = 0.0
    wait_for_subscribers_s: float = 5.0
    min_subscribers: Tuple[Tuple[str, int], ...] = ()

    def __post_init__(self) -> None:
        """Validate the options.

        Raises:
            ValueError: An option is out of range.

        """
        checks = [
            (self.rate > 0 and math.isfinite(self.rate), f'rate must be > 0, got {self.rate}'),
            (self.start_offset_s >= 0 and math.isfinite(self.start_offset_s),
             f'start offset must be >= 0 s, got {self.start_offset_s}'),
            (self.clock_hz >= 0 and math.isfinite(self.clock_hz),
             f'clock rate must be >= 0 Hz, got {self.clock_hz}'),
            (self.delay_s >= 0 and math.isfinite(self.delay_s),
             f'delay must be >= 0 s, got {self.delay_s}'),
            (self.wait_for_subscribers_s >= 0 and math.isfinite(self.wait_for_subscribers_s),
             f'wait for subscribers must be >= 0 s, got {self.wait_for_subscribers_s}'),
        ] + [(isinstance(n, int) and n >= 0, f'subscribers on {t} must be >= 0, got {n!r}')
             for t, n in self.min_subscribers]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)


def due_after_start_s(log_time_ns: int, first_log_ns: int, options: ReplayOptions) -> float:
    """Return when a message is due, in seconds after playback start (< 0: skip it)."""
    offset_ns = int(round(options.start_offset_s * 1e9))
    return (log_time_ns - first_log_ns - offset_ns) / 1e9 / options.rate
