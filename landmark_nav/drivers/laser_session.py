"""Laser driver sessions: handshake, streaming, REP 117 ranges and stamps (no ROS, no I/O).

A session is the protocol side of a laser driver. The I/O loop calls :meth:`connect` after
the port (re)opened, :meth:`frame` for every decoded frame, :meth:`error` for every protocol
error and :meth:`tick` periodically, always with the host time ``now`` (monotonic seconds).
Each returns an :class:`Output`: bytes to write, scans to publish, problems (WARN-worthy
events), log lines, the sensor's health, diagnostic values, and requests to change the
port's baud rate or reopen the port. The decoder to feed is :attr:`decoder`.

:class:`ScipSession` (Hokuyo SCIP 2.0, ``docs/protocols/scip2.md`` §7), as urg_c connects: ``QT``
(a bare ``E`` means SCIP 1.1: send ``SCIP2.0``; ``0E`` means time-adjust mode: send
``TM2``; no answer: try the next baud rate on a serial link), ``PP`` (geometry), ``VV``
(identity; checksum errors only warned), ``II`` (``STAT`` = hardware status), optionally
``TM0``, ``TM1`` x N, ``TM2`` (sensor clock offset from round trips), then ``MD`` (or ``ME``
with intensities) over the angle window snapped to sensor steps, with cluster and skip.
While streaming it publishes every scan; a gap in the sensor timestamps (more than 1.5
scan periods) is reported as lost scans; no scan for ``restart_after`` restarts the
handshake.

:class:`LmsSession` (SICK LMS2xx, ``docs/protocols/lms2xx.md`` §7), as ARIA connects: ``20 25``
(stop a stream; no reply: try the next baud rate), baud switch to the target (always sent, harmless
when already there), variant ``3B``, configuration ``74``; if the units differ, installation mode
``20 00 SICK_LMS`` and ``77``; type ``3A``; ``20 24`` continuous. A missing ACK is tolerated (only
replies count), a NAK resends the request, a ``B0`` during configuration stops the stream again and
retries the step, a ``90`` (power-on) restarts.

Ranges (REP 117): SCIP error codes are +inf or NaN as :mod:`.scip2` maps them, distances
below DMIN (20 mm < d < DMIN: the UTM-30LX's 23 mm) are -inf, beyond DMAX +inf. LMS: "above
maximum range" +inf, the other special values NaN, a distance of 0 units -inf (too close).

Stamps: the host time of the first value of the window. SCIP: the scan's 24-bit
millisecond timestamp (step 0), unwrapped, mapped to host time by :class:`ClockFilter`
from the arrival time minus the modelled latency (sweep from step 0 to AMAX, plus the
serial transfer time ``bytes * 10 / baud`` on RS-232) and advanced to the first step of
the window. With time calibration, the stamps of the first ``SETTLE_S`` seconds use the
``TM1`` round-trip offset alone; then the filter takes over, less its latency floor measured
against that offset (the unmodelled part of the delay, e.g. USB transfer), so it keeps
following the clock drift without a jump. LMS: the scan count on the 75 Hz revolution grid
(:class:`PeriodCounter`) is the sensor time, the latency is the rest of the sweep after the
first value plus the transfer time. Both add ``time_offset``. An LMS scan delayed by more
than 9/10 of a scan period (24 ms at 0.5 deg, 12 ms at 1 deg) is stamped one period late.
"""

from dataclasses import dataclass, field
import math
import statistics
from typing import Dict, List, Optional, Tuple

from landmark_nav.drivers import lms2xx, scip2
from landmark_nav.drivers.clock_filter import (ClockFilter, CounterUnwrapper,
                                               offset_from_round_trips, PeriodCounter)
from landmark_nav.drivers.errors import ProtocolError
import numpy as np

OK, WARN, ERROR = 0, 1, 2
SCIP_BAUDS = (19200, 38400, 115200)
LMS_BAUDS = (9600, 19200, 38400, 500000)
SETTLE_S = 2.0  # SCIP: stream time before the filter takes over from the TM offset
LMS_REVOLUTION = 1.0 / 75.0
LMS_PASSES = {100: 1, 50: 2, 25: 4}
LMS_VARIANTS = {100: (25, 50, 100), 180: (50, 100)}
_LMS_PER_M = {'mm': 1000, 'cm': 100, '10cm': 10}


@dataclass(frozen=True, eq=False)
class Scan:
    """One scan ready for a sensor_msgs/LaserScan (ranges REP 117, float32)."""

    stamp: float  # host monotonic time of the first value [s]
    angle_min: float
    angle_increment: float
    ranges: np.ndarray
    intensities: Optional[np.ndarray]
    time_increment: float
    scan_time: float
    range_min: float
    range_max: float


@dataclass
class Output:
    """What a session asks the node and the I/O loop to do."""

    writes: List[bytes] = field(default_factory=list)
    scans: List[Scan] = field(default_factory=list)
    problems: List[str] = field(default_factory=list)
    info: List[str] = field(default_factory=list)
    hardware: Optional[Tuple[int, str]] = None
    values: Dict[str, str] = field(default_factory=dict)
    baud: Optional[int] = None  # set the port to this baud rate
    reconnect: Optional[str] = None  # reopen the port, for this reason


def snap_window(angle_min: float, angle_max: float, first: int, last: int,
                angle_of_index) -> Tuple[int, int]:
    """Return the first and last index whose angles lie in ``[angle_min, angle_max]``.

    ``angle_of_index(i)`` is increasing; indices are clamped to ``[first, last]``. The
    window keeps the steps inside the requested angles (a step within 1e-9 rad of a bound
    counts as inside).

    Raises:
        ValueError: If no index lies inside the window.
    """
    lo = next((i for i in range(first, last + 1) if angle_of_index(i) >= angle_min - 1e-9),
              None)
    hi = next((i for i in range(last, first - 1, -1)
               if angle_of_index(i) <= angle_max + 1e-9), None)
    if lo is None or hi is None or lo > hi:
        raise ValueError(f'angle window [{angle_min:.4f}, {angle_max:.4f}] rad holds no step '
                         f'of the sensor ([{angle_of_index(first):.4f}, '
                         f'{angle_of_index(last):.4f}] rad)')
    return lo, hi


class _Gaps:
    """Detect lost scans from the spacing of scan times (median of the recent spacings)."""

    def __init__(self) -> None:
        self.spacings: List[float] = []

    def reset(self) -> None:
        self.spacings.clear()

    def add(self, spacing: float) -> Optional[float]:
        """Add a spacing; return the number of lost scans (as a float) if it is a gap."""
        typical = statistics.median(self.spacings) if len(self.spacings) >= 3 else None
        self.spacings.append(spacing)
        del self.spacings[:-15]
        if typical and spacing > 1.5 * typical:
            return spacing / typical - 1.0
        return None

    def typical(self) -> Optional[float]:
        return statistics.median(self.spacings) if self.spacings else None


# ---------------------------------------------------------------------------- SCIP 2.0


@dataclass(frozen=True)
class ScipConfig:
    """Settings of a SCIP 2.0 session.

    Attributes:
        angle_min: Lowest angle of the window [rad] (snapped inwards to sensor steps).
        angle_max: Highest angle of the window [rad].
        cluster: Steps merged into one value (1-99).
        skip: Scans skipped between published ones (0-9).
        intensity: Request intensities (``ME``); falls back to ``MD`` if refused.
        calibrate_time: Measure the clock offset with ``TM`` at every connection.
        tm_samples: ``TM1`` round trips per calibration.
        time_offset: Added to every stamp [s] (user latency correction).
        baud: Serial line rate for the transfer time and the baud search [bit/s]; 0 for USB
            or TCP links (no transfer time, no baud search).
        reply_timeout: Time to wait for a reply before retrying [s].
        restart_after: No scan for this long while streaming restarts the handshake [s].
        max_skew: Clock-filter skew bound (see :class:`ClockFilter`).
    """

    angle_min: float = -math.pi
    angle_max: float = math.pi
    cluster: int = 1
    skip: int = 0
    intensity: bool = False
    calibrate_time: bool = True
    tm_samples: int = 10
    time_offset: float = 0.0
    baud: int = 0
    reply_timeout: float = 0.5
    restart_after: float = 1.0
    max_skew: float = 2e-4

    def __post_init__(self) -> None:
        """Validate."""
        if not self.angle_min < self.angle_max:
            raise ValueError(f'angle_min ({self.angle_min}) must be < angle_max '
                             f'({self.angle_max})')
        if not 1 <= self.cluster <= 99 or not 0 <= self.skip <= 9:
            raise ValueError('cluster must be in [1, 99] and skip in [0, 9]')
        if self.tm_samples < 1 or self.reply_timeout <= 0.0 or self.restart_after <= 0.0:
            raise ValueError('tm_samples >= 1, reply_timeout > 0 and restart_after > 0')


class _Session:
    """What both laser sessions share: (re)start the handshake by stopping the stream."""

    def farewell(self) -> bytes:
        """Return the bytes that stop the device's stream."""
        raise NotImplementedError

    def connect(self, now: float) -> Output:
        """Start the handshake (after the port was opened or to recover): stop the stream."""
        out = Output()
        self._reset_timing()
        self.decoder.reset()
        self._send(out, 'stop', self.farewell(), now)
        return out

    def error(self, err: ProtocolError, now: float) -> Output:
        """Note a protocol error; the decoder resynchronises by itself."""
        return Output()

    def _restart(self, now: float, out: Output) -> Output:
        out.writes += self.connect(now).writes
        return out


class ScipSession(_Session):
    """SCIP 2.0 handshake and streaming (see the module docstring)."""

    def __init__(self, config: ScipConfig = ScipConfig()) -> None:
        """Create the session and its decoder; nothing is sent before :meth:`connect`."""
        self.config = config
        self.decoder = scip2.Scip2Decoder()
        self.params: Optional[scip2.SensorParams] = None
        self.state = 'idle'
        self._bauds = [config.baud] + [b for b in SCIP_BAUDS if b != config.baud] \
            if config.baud else [0]
        self._baud_index = 0
        self._unwrap = CounterUnwrapper(24)
        self._filter = ClockFilter(max_skew=config.max_skew)
        self._gaps = _Gaps()
        self._round_trips: List[Tuple[float, float, float]] = []
        self._tm_offset: Optional[float] = None
        self._bias: Optional[float] = None
        self._settle_until = 0.0
        self._command = 'ME' if config.intensity else 'MD'
        self.window: Optional[Tuple[int, int]] = None
        self._reset_timing()

    # --- plumbing ---------------------------------------------------------------------------

    @property
    def baud(self) -> int:
        """The line rate currently tried (0: USB/TCP)."""
        return self._bauds[self._baud_index]

    def _reset_timing(self) -> None:
        self._sent_at = 0.0
        self._attempts = 0
        self._last_scan = None
        self._last_sensor: Optional[float] = None
        self._unwrap.reset()
        self._filter.reset()
        self._gaps.reset()

    def _send(self, out: Output, state: str, data: bytes, now: float,
              first: bool = True) -> None:
        self.state = state
        self._sent_at = now
        if first:
            self._attempts = 0
        out.writes.append(data)

    def _timeout(self) -> float:
        extra = 4000 * 10.0 / self.baud if self.baud else 0.0
        return self.config.reply_timeout + extra

    def farewell(self) -> bytes:
        """Return the bytes to send before closing: ``QT`` (stop, laser off)."""
        return scip2.encode_command('QT')

    # --- entry points ----------------------------------------------------------------------

    def tick(self, now: float) -> Output:
        """Retry requests that got no reply; restart a silent stream."""
        out = Output()
        if self.state in ('idle', 'failed'):
            return out
        if self.state == 'streaming':
            last = self._last_scan if self._last_scan is not None else self._sent_at
            if now - last > self.config.restart_after:
                out.problems.append(f'no scan for {now - last:.1f} s: restarting the '
                                    'handshake')
                return self._restart(now, out)
            return out
        if now - self._sent_at < self._timeout():
            return out
        self._attempts += 1
        if self._attempts >= 3:
            out.problems.append(f'no reply in state {self.state} after 3 tries')
            if self.state == 'stop' and self.config.baud:
                self._baud_index = (self._baud_index + 1) % len(self._bauds)
                out.baud = self.baud
                out.info.append(f'trying {self.baud} baud')
            return self._restart(now, out)
        out.writes.append(self._request_of(self.state))
        self._sent_at = now
        if self.state == 'tm1':
            self._tm_sent = now
        return out

    def _request_of(self, state: str) -> bytes:
        c = self.config
        if state in ('stop', 'scip2', 'tm2', 'tm2x'):
            return {'stop': scip2.encode_command('QT'), 'scip2': scip2.encode_command('SCIP2.0'),
                    'tm2': scip2.encode_time_request(2),
                    'tm2x': scip2.encode_time_request(2)}[state]
        if state in ('pp', 'vv', 'ii'):
            return scip2.encode_command(state.upper())
        if state == 'tm0':
            return scip2.encode_time_request(0)
        if state == 'tm1':
            return scip2.encode_time_request(1)
        lo, hi = self.window
        return scip2.encode_scan_request(self._command, lo, hi, c.cluster, c.skip, 0)

    # --- frames --------------------------------------------------------------------------------

    def frame(self, item, now: float) -> Output:
        """Handle one decoded frame."""
        out = Output()
        if isinstance(item, scip2.ScanFrame):
            if self.state == 'streaming' or (self.state == 'start' and
                                             item.command == self._command):
                self.state = 'streaming'
                self._scan(item, now, out)
            return out
        if isinstance(item, scip2.StatusReply):
            self._status(item, now, out)
        elif isinstance(item, scip2.InfoReply):
            self._info(item, now, out)
        elif isinstance(item, scip2.TimeReply) and self.state == 'tm1':
            self._round_trips.append((self._tm_sent, item.timestamp_ms / 1000.0, now))
            if len(self._round_trips) >= self.config.tm_samples:
                self._send(out, 'tm2', scip2.encode_time_request(2), now)
            else:
                self._tm_sent = now
                self._send(out, 'tm1', scip2.encode_time_request(1), now)
        return out

    def _status(self, reply: scip2.StatusReply, now: float, out: Output) -> None:
        cmd, status, state = reply.command, reply.status, self.state
        if state == 'stop' and cmd == 'QT':
            if status == '00':
                self._send(out, 'pp', scip2.encode_command('PP'), now)
            elif status == 'E':
                out.info.append('sensor speaks SCIP 1.1: switching it to SCIP 2.0')
                self._send(out, 'scip2', scip2.encode_command('SCIP2.0'), now)
            elif status == '0E':
                out.info.append('sensor is in time-adjust mode: leaving it')
                self._send(out, 'tm2x', scip2.encode_time_request(2), now)
        elif state == 'scip2' and cmd == 'SCIP2.0':
            self._send(out, 'stop', scip2.encode_command('QT'), now)
        elif state == 'tm2x' and cmd == 'TM':
            self._send(out, 'stop', scip2.encode_command('QT'), now)
        elif state == 'tm0' and cmd == 'TM':
            if status in ('00', '02'):
                self._round_trips = []
                self._tm_sent = now
                self._send(out, 'tm1', scip2.encode_time_request(1), now)
            else:
                out.problems.append(f'time adjust refused ({status}: {reply.meaning}); '
                                    'stamps without calibration')
                self._start(out, now)
        elif state == 'tm1' and cmd == 'TM':  # TM1 refused
            out.problems.append(f'TM1 refused ({status}: {reply.meaning})')
            self._send(out, 'tm2', scip2.encode_time_request(2), now)
        elif state == 'tm2' and cmd == 'TM':
            if self._round_trips:
                offset, half = offset_from_round_trips(self._round_trips)
                self._tm_offset = offset
                out.values['clock offset [s]'] = f'{offset:.6f} +- {half:.6f}'
            self._start(out, now)
        elif state == 'start' and cmd == self._command:
            if status == '00':
                self.state = 'streaming'
                self._last_scan = now
                out.info.append(f'streaming {self._command} steps {self.window[0]}..'
                                f'{self.window[1]}, cluster {self.config.cluster}, skip '
                                f'{self.config.skip}')
            elif self._command == 'ME':
                out.problems.append(f'ME refused ({status}: {reply.meaning}): no intensities')
                self._command = 'MD'
                self._start(out, now)
            else:
                out.hardware = (ERROR, f'{cmd} refused: {status} ({reply.meaning})')
                self.state = 'failed'
        elif state == 'streaming' and cmd == self._command and status not in ('00', '99'):
            level = ERROR if status.isdigit() and int(status) >= 50 else WARN
            out.hardware = (level, f'sensor status {status}: {reply.meaning}')
            out.problems.append(f'stream stopped with status {status}: restarting')
            self._restart(now, out)

    def _info(self, reply: scip2.InfoReply, now: float, out: Output) -> None:
        fields = reply.as_dict()
        if reply.checksum_warnings:
            out.info.append(f'{reply.command}: {len(reply.checksum_warnings)} checksum '
                            'warning(s) ignored (known firmware quirk)')
        if self.state == 'pp' and reply.command == 'PP':
            try:
                self.params = scip2.SensorParams.from_info(reply)
            except ProtocolError as err:
                out.problems.append(f'bad PP reply: {err}')
                return
            p = self.params
            try:
                self.window = snap_window(self.config.angle_min, self.config.angle_max,
                                          p.amin, p.amax, p.step_angle)
            except ValueError as err:
                out.hardware = (ERROR, str(err))
                self.state = 'failed'
                return
            out.values.update({'model': p.model, 'steps': f'{p.amin}..{p.amax}',
                               'window': f'{self.window[0]}..{self.window[1]}'})
            self._send(out, 'vv', scip2.encode_command('VV'), now)
        elif self.state == 'vv' and reply.command == 'VV':
            for key, name in (('PROD', 'product'), ('FIRM', 'firmware'), ('SERI', 'serial')):
                if key in fields:
                    out.values[name] = fields[key]
            self._send(out, 'ii', scip2.encode_command('II'), now)
        elif self.state == 'ii' and reply.command == 'II':
            stat = fields.get('STAT', '')
            good = not stat or 'well' in stat.lower() or 'normal' in stat.lower()
            out.hardware = (OK, '') if good else (WARN, f'sensor status: {stat}')
            out.values['sensor status'] = stat or 'not reported'
            if self.config.calibrate_time:
                self._send(out, 'tm0', scip2.encode_time_request(0), now)
            else:
                self._start(out, now)

    def _start(self, out: Output, now: float) -> None:
        self._filter.reset()
        self._unwrap.reset()
        self._gaps.reset()
        self._bias = None
        self._settle_until = now + SETTLE_S
        self._send(out, 'start', self._request_of('start'), now)

    # --- scans ---------------------------------------------------------------------------------

    def _scan(self, frame: scip2.ScanFrame, now: float, out: Output) -> None:
        p, c = self.params, self.config
        if p is None or self.window is None:
            return
        lo, hi = self.window
        if (frame.start_step, frame.end_step, frame.cluster) != (lo, hi, max(1, c.cluster)):
            out.problems.append(f'scan for steps {frame.start_step}..{frame.end_step} '
                                f'(cluster {frame.cluster}) does not match the request')
            return
        step_time = 60.0 / (p.scan_rpm * p.ares)
        sensor_ms, restarted = self._unwrap.unwrap(frame.timestamp_ms)
        if restarted:
            self._filter.reset()
            self._gaps.reset()
            out.problems.append('sensor clock went back (reset): clock filter restarted')
        sensor = sensor_ms / 1000.0
        if self._last_sensor is not None and not restarted:
            lost = self._gaps.add(sensor - self._last_sensor)
            if lost is not None:
                out.problems.append(f'about {lost:.0f} scan(s) lost (timestamps '
                                    f'{(sensor - self._last_sensor) * 1e3:.0f} ms apart)')
        self._last_sensor = sensor
        self._last_scan = now
        chars = frame.ranges_m.size * scip2.SCAN_COMMANDS[frame.command]
        size = 40 + chars + 2 * -(-chars // scip2.BLOCK_CHARS)
        latency = (p.amax + 1) * step_time
        if self.baud:
            latency += size * 10.0 / self.baud
        step0 = self._filter.update(sensor, now - latency)
        if self._tm_offset is not None and self._bias is None:
            if now < self._settle_until:
                step0 = sensor + self._tm_offset  # until the filter has seen low delays
            else:
                bias = self._filter.offset - self._tm_offset
                if abs(bias) < 0.1:
                    self._bias = bias
                    out.values['latency floor [s]'] = f'{bias:.6f}'
                else:
                    out.problems.append(f'time-adjust offset disagrees with the stream by '
                                        f'{bias:.3f} s: ignored')
                    self._bias = 0.0
        stamp = step0 - (self._bias or 0.0) + lo * step_time + c.time_offset
        ranges = np.asarray(frame.ranges_m, dtype=np.float64).copy()
        finite = np.isfinite(ranges)
        ranges[finite & (ranges < p.dmin_mm / 1000.0)] = -math.inf
        ranges[finite & (ranges > p.dmax_mm / 1000.0)] = math.inf
        period = 60.0 / p.scan_rpm * (c.skip + 1)
        typical = self._gaps.typical()
        scan_time = typical if typical and typical > 1.5 * period else period
        intensities = (None if frame.intensities is None
                       else np.asarray(frame.intensities, dtype=np.float32))
        out.scans.append(Scan(
            stamp=stamp, angle_min=p.step_angle(lo),
            angle_increment=c.cluster * 2.0 * math.pi / p.ares,
            ranges=ranges.astype(np.float32), intensities=intensities,
            time_increment=c.cluster * step_time, scan_time=scan_time,
            range_min=p.dmin_mm / 1000.0, range_max=p.dmax_mm / 1000.0))


# ---------------------------------------------------------------------------- LMS2xx


@dataclass(frozen=True)
class LmsConfig:
    """Settings of an LMS2xx session.

    Attributes:
        angle_deg: Scanning angle, 100 or 180 [deg].
        resolution_cdeg: Angular resolution, 25, 50 or 100 [1/100 deg] (not 25 at 180 deg).
        units: ``mm`` (8 m range) or ``cm`` (80 m).
        angle_min: Lowest published angle [rad] (snapped inwards to values).
        angle_max: Highest published angle [rad].
        baud: Line rate to run at (9600, 19200, 38400 or 500000) [bit/s].
        time_offset: Added to every stamp [s].
        reply_timeout: Time to wait for a reply before retrying [s] (plus transfer time).
        restart_after: No scan for this long while streaming restarts the handshake [s].
        max_skew: Clock-filter skew bound.
        password: Installation-mode password.
    """

    angle_deg: int = 180
    resolution_cdeg: int = 50
    units: str = 'mm'
    angle_min: float = -math.pi
    angle_max: float = math.pi
    baud: int = 38400
    time_offset: float = 0.0
    reply_timeout: float = 0.5
    restart_after: float = 1.0
    max_skew: float = 2e-4
    password: str = 'SICK_LMS'

    def __post_init__(self) -> None:
        """Validate."""
        if self.resolution_cdeg not in LMS_VARIANTS.get(self.angle_deg, ()):
            raise ValueError(f'variant {self.angle_deg} deg / {self.resolution_cdeg / 100} '
                             'deg is not supported (100 deg: 0.25, 0.5, 1; 180 deg: 0.5, 1)')
        if self.units not in ('mm', 'cm'):
            raise ValueError(f'units {self.units!r} must be mm or cm')
        if self.baud not in LMS_BAUDS:
            raise ValueError(f'baud {self.baud} is not one of {LMS_BAUDS}')
        if not self.angle_min < self.angle_max:
            raise ValueError(f'angle_min ({self.angle_min}) must be < angle_max '
                             f'({self.angle_max})')

    @property
    def count(self) -> int:
        """Values per scan."""
        return self.angle_deg * 100 // self.resolution_cdeg + 1


class LmsSession(_Session):
    """LMS2xx handshake and streaming (see the module docstring)."""

    _STEPS = ('stop', 'baud', 'variant', 'config', 'install', 'write', 'type', 'start')

    def __init__(self, config: LmsConfig = LmsConfig()) -> None:
        """Create the session and its decoder; nothing is sent before :meth:`connect`."""
        self.config = config
        self.decoder = lms2xx.Lms2xxDecoder()
        self.state = 'idle'
        self._bauds = [config.baud] + [b for b in LMS_BAUDS if b != config.baud]
        self._baud_index = 0
        self.line_baud = config.baud  # what the port runs at
        self._counter = PeriodCounter(LMS_PASSES[config.resolution_cdeg] * LMS_REVOLUTION)
        self._filter = ClockFilter(max_skew=config.max_skew)
        self._gaps = _Gaps()
        self._config_block = b''
        self._restarts = 0
        self.window = snap_window(config.angle_min, config.angle_max, 0, config.count - 1,
                                  self._angle)
        self._reset_timing()

    def _angle(self, i: int) -> float:
        c = self.config
        return math.radians(-c.angle_deg / 2.0 + i * c.resolution_cdeg / 100.0)

    def _reset_timing(self) -> None:
        self._sent_at = 0.0
        self._attempts = 0
        self._request = b''
        self._last_scan: Optional[float] = None
        self._counter.reset()
        self._filter.reset()
        self._gaps.reset()

    def farewell(self) -> bytes:
        """Return the bytes to send before closing: ``20 25`` (stop the stream)."""
        return lms2xx.request_stop_continuous()

    def _timeout(self) -> float:
        return self.config.reply_timeout + 1000 * 10.0 / self.line_baud

    def _send(self, out: Output, state: str, request: bytes, now: float) -> None:
        self.state = state
        self._sent_at = now
        self._attempts = 0
        self._request = request
        out.writes.append(request)

    # --- entry points ----------------------------------------------------------------------

    def tick(self, now: float) -> Output:
        """Retry requests that got no reply; restart a silent stream."""
        out = Output()
        if self.state in ('idle', 'failed'):
            return out
        if self.state == 'streaming':
            last = self._last_scan if self._last_scan is not None else self._sent_at
            if now - last > max(self.config.restart_after, 3.0 * self._period_guess()):
                out.problems.append(f'no scan for {now - last:.1f} s: restarting the '
                                    'handshake')
                self._restart(now, out)
            return out
        if now - self._sent_at < self._timeout():
            return out
        self._attempts += 1
        if self._attempts >= 3:
            out.problems.append(f'no reply in state {self.state} after 3 tries')
            if self.state == 'stop':
                self._baud_index = (self._baud_index + 1) % len(self._bauds)
                self.line_baud = self._bauds[self._baud_index]
                out.baud = self.line_baud
                out.info.append(f'trying {self.line_baud} baud')
            self._restarts += 1
            if self._restarts >= 2 * len(self._bauds):
                self._restarts = 0
                out.reconnect = 'the scanner does not answer at any baud rate'
            self._restart(now, out)
            return out
        out.writes.append(self._request)
        self._sent_at = now
        return out

    def _period_guess(self) -> float:
        typical = self._gaps.typical()
        if typical:
            return typical
        return LMS_PASSES[self.config.resolution_cdeg] * LMS_REVOLUTION + (
            (2 * self.config.count + 10) * 10.0 / self.line_baud)

    # --- frames --------------------------------------------------------------------------------

    def frame(self, item, now: float) -> Output:
        """Handle one decoded frame."""
        out = Output()
        c = self.config
        if isinstance(item, lms2xx.Ack):
            return out
        if isinstance(item, lms2xx.Nak):
            if self.state not in ('idle', 'streaming', 'failed'):
                out.problems.append(f'NAK in state {self.state}: resending')
                out.writes.append(self._request)
                self._sent_at = now
            return out
        if isinstance(item, lms2xx.MeasuredValues):
            if self.state == 'streaming' or self.state == 'start':
                self.state = 'streaming'
                self._scan(item, now, out)
            elif self.state not in ('stop', 'idle'):
                out.info.append(f'scan data during {self.state}: stopping the stream again')
                self._send(out, 'stop', lms2xx.request_stop_continuous(), now)
            return out
        if isinstance(item, lms2xx.Telegram) and item.command == 0x90:
            out.problems.append('scanner restarted (power-on telegram): reconnecting')
            self.line_baud = 9600
            self._baud_index = self._bauds.index(9600)
            out.baud = 9600
            self._restart(now, out)
            return out
        if isinstance(item, lms2xx.Telegram) and item.command == 0x92:
            out.problems.append(f'scanner rejected a request in state {self.state}')
            return out
        state = self.state
        if state == 'stop' and isinstance(item, lms2xx.ModeSwitchReply):
            self._send(out, 'baud', lms2xx.request_baud(c.baud), now)
        elif state == 'baud' and isinstance(item, lms2xx.ModeSwitchReply):
            if item.ok:
                self.line_baud = c.baud
                self._baud_index = 0
                out.baud = c.baud
            self._send(out, 'variant', lms2xx.request_variant(c.angle_deg, c.resolution_cdeg),
                       now)
        elif state == 'variant' and isinstance(item, lms2xx.VariantReply):
            if not (item.accepted and item.angle_deg == c.angle_deg
                    and item.resolution_cdeg == c.resolution_cdeg):
                out.hardware = (ERROR, f'variant {c.angle_deg} deg / '
                                f'{c.resolution_cdeg / 100} deg refused by the scanner')
                self.state = 'failed'
                return out
            self._send(out, 'config', lms2xx.request_config(), now)
        elif state == 'config' and isinstance(item, lms2xx.Telegram) and item.command == 0xF4:
            try:
                units = lms2xx.config_units(item.data)
                mode = lms2xx.config_measuring_mode(item.data)
            except ProtocolError as err:
                out.problems.append(f'bad configuration block: {err}')
                return out
            self._config_block = item.data
            self.decoder.mode = mode
            out.values['measuring mode'] = mode
            if units == c.units:
                self._send(out, 'type', lms2xx.request_type(), now)
            else:
                out.info.append(f'switching units from {units} to {c.units}')
                self._send(out, 'install', lms2xx.request_installation_mode(c.password), now)
        elif state == 'install' and isinstance(item, lms2xx.ModeSwitchReply):
            if not item.ok:
                out.hardware = (ERROR, 'installation mode refused (wrong password?)')
                self.state = 'failed'
                return out
            block = lms2xx.with_config(self._config_block, units=c.units)
            self._send(out, 'write', lms2xx.request_write_config(block), now)
        elif state == 'write' and isinstance(item, lms2xx.Telegram) and item.command == 0xF7:
            if not item.data or item.data[0] != 1:
                out.problems.append('configuration write refused: reading it again')
                self._send(out, 'config', lms2xx.request_config(), now)
                return out
            self._send(out, 'config', lms2xx.request_config(), now)  # verify
        elif state == 'type' and isinstance(item, lms2xx.TypeReply):
            out.values['model'] = item.text.strip()
            self._send(out, 'start', lms2xx.request_continuous(), now)
        elif state == 'start' and isinstance(item, lms2xx.ModeSwitchReply):
            if item.ok:
                self.state = 'streaming'
                self._last_scan = now
                self._restarts = 0
                out.info.append(f'streaming {c.angle_deg} deg / {c.resolution_cdeg / 100} deg '
                                f'in {c.units} at {self.line_baud} baud')
        return out

    # --- scans -----------------------------------------------------------------------------------

    def _scan(self, values: lms2xx.MeasuredValues, now: float, out: Output) -> None:
        c = self.config
        if values.count != c.count or values.units != c.units or values.partial_scan:
            out.problems.append(f'scan of {values.count} values in {values.units} does not '
                                f'match the variant ({c.count} values in {c.units})')
            return
        self._last_scan = now
        passes = LMS_PASSES[c.resolution_cdeg]
        size = 2 * values.count + 10
        latency = ((passes - 1) + c.angle_deg / 360.0) * LMS_REVOLUTION \
            + size * 10.0 / self.line_baud
        transfer = size * 10.0 / self.line_baud
        min_steps = max(1, math.ceil(transfer / (passes * LMS_REVOLUTION) - 1e-9))
        sensor, steps = self._counter.advance(now - latency, min_steps)
        first = self._filter.update(sensor, now - latency)
        self._counter.settle(first)
        if steps:
            lost = self._gaps.add(steps * passes * LMS_REVOLUTION)
            if lost is not None:
                out.problems.append(f'about {lost:.0f} scan(s) lost')
        status = values.lms_status
        if status.severity >= 3:
            out.hardware = (ERROR, f'scanner status 0x{values.status:02X}: severity '
                            f'{status.severity}')
        elif status.severity or status.pollution or status.implausible:
            what = ('front screen polluted' if status.pollution else 'implausible values'
                    if status.implausible else f'severity {status.severity}')
            out.hardware = (WARN, f'scanner status 0x{values.status:02X}: {what}')
        else:
            out.hardware = (OK, '')
        lo, hi = self.window
        raw = np.asarray(values.raw)[lo:hi + 1]
        ranges = np.asarray(values.ranges_m, dtype=np.float64)[lo:hi + 1].copy()
        ranges[raw == 0] = -math.inf
        increment = math.radians(c.resolution_cdeg / 100.0)
        time_increment = LMS_REVOLUTION / 360.0 * c.resolution_cdeg / 100.0
        per_m = _LMS_PER_M[c.units]
        mask = (1 << lms2xx.MEASURING_MODES[values.mode].range_bits) - 1
        typical = self._gaps.typical()
        out.scans.append(Scan(
            stamp=first + lo * time_increment + c.time_offset, angle_min=self._angle(lo),
            angle_increment=increment, ranges=ranges.astype(np.float32), intensities=None,
            time_increment=time_increment,
            scan_time=typical if typical else passes * LMS_REVOLUTION,
            range_min=1.0 / per_m, range_max=(mask - 9) / per_m))


def make_session(protocol: str, **settings):
    """Return a :class:`ScipSession` (``scip2``) or :class:`LmsSession` (``lms2xx``).

    Raises:
        ValueError: For an unknown protocol or invalid settings.
    """
    if protocol == 'scip2':
        return ScipSession(ScipConfig(**settings))
    if protocol == 'lms2xx':
        return LmsSession(LmsConfig(**settings))
    raise ValueError(f'protocol {protocol!r} is not scip2 or lms2xx')
