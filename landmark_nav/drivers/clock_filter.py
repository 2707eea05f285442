"""Sensor-clock to host-clock mapping for laser scans: counter unwrapping and a min filter.

Pure code (no clock reads, no I/O): every call gets the times it needs.

A frame carrying sensor time ``t_s`` arrives at host time ``a = t_s + offset + L + q`` where
``L`` is a latency the driver can model (sweep to the end of the scan, serial transfer time
``bytes * 10 / baud``) and ``q >= 0`` the rest: USB or OS buffering and thread scheduling,
which makes arrival times jitter by milliseconds. :class:`ClockFilter` follows the passive
synchronisation of Olson (2010, "A passive solution to the sensor synchronization problem"):
since ``q >= 0``, ``a - L - t_s >= offset``, so the lowest observed values bound the offset.
At start-up older lows are aged by the largest clock skew ``eps`` the two clocks may have::

    p_k = min(p_{k-1} + eps * (t_s,k - t_s,k-1),  a_k - L_k - t_s,k)

and once enough samples are in, the offset and the skew come from the lower convex hull of
the samples (the line below all of them, closest on average), which follows the clock rate
difference without ageing. The frame's host time is ``t_s,k + p_k``: it jitters only by
the floor of ``q``, far less than the arrival times.

:class:`CounterUnwrapper` turns a wrapping counter (SCIP's 24-bit millisecond timestamp,
wrapping every 2**24 ms, about 4 h 40 min) into a monotonic count and reports restarts
(the counter went back: ``RS`` or a power cycle). :class:`PeriodCounter` gives sensors
without a clock (SICK LMS2xx) a sensor time: scans start on the mirror's revolution grid, so
the number of scan periods between two scans follows from their arrival gap (arrival delays
up to 9/10 of a period are tolerated); the filter then runs on ``k * period``.
"""

from collections import deque
from dataclasses import dataclass
import math
from typing import Deque, List, Optional, Tuple

__all__ = ['ClockFilter', 'CounterUnwrapper', 'PeriodCounter', 'offset_from_round_trips']


class CounterUnwrapper:
    """Unwrap a ``bits``-bit counter that only counts forward.

    A step back of more than ``max_backstep`` counts (or a forward jump of more than half the
    range) is a restart: the unwrapped value starts again from the raw value.
    """

    def __init__(self, bits: int = 24, max_backstep: int = 0) -> None:
        """Create an unwrapper for a ``bits``-bit counter."""
        if bits < 2:
            raise ValueError(f'bits must be >= 2, got {bits}')
        self.modulus = 1 << bits
        self.max_backstep = max_backstep
        self._last: Optional[int] = None
        self._value = 0
        self.wraps = 0
        self.restarts = 0

    def reset(self) -> None:
        """Forget the history (the next value starts a new count)."""
        self._last = None

    def unwrap(self, raw: int) -> Tuple[int, bool]:
        """Return ``(unwrapped value, restarted)`` for a new raw reading.

        Raises:
            ValueError: If ``raw`` is outside ``[0, 2**bits)``.
        """
        raw = int(raw)
        if not 0 <= raw < self.modulus:
            raise ValueError(f'counter value {raw} outside [0, {self.modulus})')
        if self._last is None:
            self._last, self._value = raw, raw
            return raw, False
        step = (raw - self._last) % self.modulus
        half = self.modulus // 2
        if step >= half:  # went back
            if self.modulus - step <= self.max_backstep:
                self._last = raw
                return self._value, False
            self.restarts += 1
            self._last, self._value = raw, raw
            return raw, True
        if raw < self._last:
            self.wraps += 1
        self._last = raw
        self._value += step
        return self._value, False


@dataclass
class ClockFilter:
    """Map sensor time to host time from the lowest arrival delays (Olson 2010), in seconds.

    Start-up (until the samples span ``min_span``): the min filter with ageing by
    ``max_skew``. Then the offset line is the lower convex hull of the per-block minima of
    ``d = host - sensor`` over the last ``window`` seconds, evaluated at the newest sensor
    time: the edge spanning the mean sample time is the line below all samples that is
    closest to them on average (the linear-programming estimate of offset and skew), so
    the clock rate difference is followed without the ageing sawtooth. A slope beyond
    ``max_skew`` falls back to the min filter. The estimate never exceeds the newest
    sample (a frame cannot be stamped after it arrived).

    Attributes:
        max_skew: Largest relative rate difference of the two clocks (2e-4 = 200 ppm; quartz
            clocks are within 100 ppm).
        window: Sensor time covered by the hull [s].
        block: Length of the blocks whose minima enter the hull [s].
        min_span: Samples must span this long before the hull is used [s].
        reset_after: A sample more than this above the estimate [s], ``reset_count`` times
            in a row, or once more than this below it, restarts the filter (the sensor clock
            was reset, or the host clock jumped).
        reset_count: See ``reset_after``.
    """

    max_skew: float = 2e-4
    window: float = 20.0
    block: float = 0.25
    min_span: float = 4.0
    reset_after: float = 0.5
    reset_count: int = 5

    def __post_init__(self) -> None:
        """Validate and start empty."""
        if not 0.0 <= self.max_skew < 0.1:
            raise ValueError(f'max_skew must be in [0, 0.1), got {self.max_skew}')
        if not 0.0 < self.block <= self.min_span <= self.window:
            raise ValueError('need 0 < block <= min_span <= window')
        if not self.reset_after > 0.0 or self.reset_count < 1:
            raise ValueError('need reset_after > 0 and reset_count >= 1')
        self.resets = 0
        self.reset()

    def reset(self) -> None:
        """Forget the offset."""
        self.offset: Optional[float] = None
        self._last_sensor = 0.0
        self._high = 0
        self._blocks: Deque[List[float]] = deque()  # [block index, sensor, d] of block minima
        self._closed_hull: Optional[List[Tuple[float, float]]] = None  # all blocks but the last
        self.samples = 0

    def update(self, sensor_s: float, host_s: float) -> float:
        """Add one frame: sensor time and host arrival time minus the modelled latency.

        Returns:
            The host time of ``sensor_s`` (the frame's corrected stamp) [s].
        """
        sample = host_s - sensor_s
        if self.offset is not None and sensor_s >= self._last_sensor:
            aged = self.offset + self.max_skew * (sensor_s - self._last_sensor)
            if sample < aged - self.reset_after:
                self.resets += 1
                self.reset()
            elif sample - aged > self.reset_after:
                self._high += 1
                if self._high >= self.reset_count:
                    self.resets += 1
                    self.reset()
                else:
                    self._last_sensor = sensor_s
                    self.offset = aged
                    return sensor_s + aged  # an outlier until proven otherwise
            else:
                self._high = 0
        else:
            self.reset()
        if self.offset is None:
            self.offset = sample
        olson = min(self.offset + self.max_skew * (sensor_s - self._last_sensor), sample)
        self._add_block(sensor_s, sample)
        line = self._hull_line(sensor_s)
        self.offset = olson if line is None else min(line, sample)
        self._last_sensor = sensor_s
        self.samples += 1
        return sensor_s + self.offset

    def _add_block(self, sensor_s: float, sample: float) -> None:
        index = math.floor(sensor_s / self.block)
        blocks = self._blocks
        if blocks and blocks[-1][0] == index:
            if sample < blocks[-1][2]:
                blocks[-1][1:] = [sensor_s, sample]
        else:
            blocks.append([index, sensor_s, sample])
            self._closed_hull = None
        while blocks and blocks[0][1] < sensor_s - self.window:
            blocks.popleft()
            self._closed_hull = None

    def _hull_line(self, at: float) -> Optional[float]:
        """Return the lower-hull estimate of the offset at sensor time ``at`` (None: not yet)."""
        blocks = self._blocks
        if len(blocks) < 2 or blocks[-1][1] - blocks[0][1] < self.min_span:
            return None
        if self._closed_hull is None:  # once per block: the hull of the closed blocks
            self._closed_hull = _lower_hull([(b[1], b[2]) for b in list(blocks)[:-1]])
            self._mean_closed = sum(b[1] for b in list(blocks)[:-1])
        hull = _lower_hull([(blocks[-1][1], blocks[-1][2])], list(self._closed_hull))
        mean = (self._mean_closed + blocks[-1][1]) / len(blocks)
        for (s0, d0), (s1, d1) in zip(hull, hull[1:]):
            if s1 >= mean:
                slope = (d1 - d0) / (s1 - s0)
                if abs(slope) > self.max_skew:
                    return None
                return d0 + slope * (at - s0)
        return None

    def host_time(self, sensor_s: float) -> Optional[float]:
        """Return the host time of a sensor time with the current offset (None if empty)."""
        if self.offset is None:
            return None
        return sensor_s + self.offset


class PeriodCounter:
    """Sensor time ``k * period`` for scans that start on a fixed period grid (LMS mirror).

    The count advances by the number of periods between the arrival (minus the modelled
    latency) and the previous scan's filtered host time. Arrival delays are never negative,
    so the ratio is rounded down after adding ``1 - late_fraction``: delays up to
    ``late_fraction`` of a period do not disturb the count.
    """

    def __init__(self, period: float, late_fraction: float = 0.9) -> None:
        """Create a counter for a scan grid of ``period`` seconds."""
        if not period > 0.0 or not 0.0 < late_fraction < 1.0:
            raise ValueError(f'need period > 0 and 0 < late_fraction < 1, got {period} and '
                             f'{late_fraction}')
        self.period = period
        self.late_fraction = late_fraction
        self.reset()

    def reset(self) -> None:
        """Start counting again."""
        self.count: Optional[int] = None
        self._last_host: Optional[float] = None

    def advance(self, host_s: float, min_steps: int = 1) -> Tuple[float, int]:
        """Return ``(sensor time [s], periods since the previous scan)`` (0 for the first).

        ``min_steps`` is the fewest periods two scans can be apart (a serial line that needs
        longer than a period per scan); a gap that looks shorter means the previous scan
        arrived late, not that the scans came faster.
        """
        if self.count is None or self._last_host is None:
            self.count = 0
            return 0.0, 0
        ratio = (host_s - self._last_host) / self.period
        steps = max(1, min_steps, int(math.floor(ratio + 1.0 - self.late_fraction)))
        self.count += steps
        return self.count * self.period, steps

    def settle(self, host_s: float) -> None:
        """Tell the counter the filtered host time of the scan just counted."""
        self._last_host = host_s


def _cross(o: Tuple[float, float], a: Tuple[float, float], b: Tuple[float, float]) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _lower_hull(points, hull=None) -> List[Tuple[float, float]]:
    """Extend the lower convex hull ``hull`` by ``points`` sorted by x (monotone chain)."""
    hull = [] if hull is None else hull
    for p in points:
        while len(hull) >= 2 and _cross(hull[-2], hull[-1], p) <= 0.0:
            hull.pop()
        hull.append(p)
    return hull


def offset_from_round_trips(samples, resolution: float = 1e-3) -> Tuple[float, float]:
    """Estimate ``host - sensor`` from request/reply round trips (SCIP ``TM1``).

    Each sample is ``(host_send, sensor_time, host_receive)`` [s]; the sensor latched
    ``sensor_time`` (truncated to ``resolution``) between sending and receiving, so the offset
    lies in ``[send - (sensor + resolution), receive - sensor]``. The intervals of all samples
    are intersected; if they do not overlap (clock skew, a delayed reply), the sample with the
    shortest round trip is used alone.

    Returns:
        ``(offset, half width of the interval)`` [s].

    Raises:
        ValueError: Without samples.
    """
    samples = list(samples)
    if not samples:
        raise ValueError('no round-trip samples')
    low = max(send - (sensor + resolution) for send, sensor, _ in samples)
    high = min(recv - sensor for _, sensor, recv in samples)
    if low > high:
        send, sensor, recv = min(samples, key=lambda s: s[2] - s[0])
        low, high = send - (sensor + resolution), recv - sensor
    return 0.5 * (low + high), 0.5 * (high - low)
