"""Hokuyo URG / UTM laser emulator speaking SCIP 2.0, measuring the simulator world.

:class:`UrgDevice` is the sensor as seen through its port (``docs/protocols/scip2.md``);
:class:`~landmark_nav.emulators.server.DeviceServer` serves it on a pty and a TCP port
(``landmark_nav emulate urg``). Models: UTM-30LX (default: 1081 steps over 270 deg, 1440
steps per revolution, 40 scans/s, 23 mm .. 60 m, intensities with ``ME``/``GE``, USB) and
URG-04LX (682 steps over 239.4 deg from AMIN 44 / AMAX 725 and 1024 steps per
revolution, 10 scans/s, 20 mm .. 5.6 m, RS-232 at 19200 baud after power-up, optionally
booting in SCIP 1.1).

Commands: ``SCIP2.0``, ``VV``, ``PP``, ``II``, ``BM``, ``QT``, ``RS``, ``TM0/1/2`` (time
adjust; ``TM1`` answers the 24-bit millisecond counter, which wraps every 2**24 ms),
``SS`` (RS-232 baud, applied after the reply), ``CR`` (scan speed: 00 default, 01-10
slower by 1 % per level, 99 default), ``MD``/``MS``/``ME`` (continuous: acknowledgement,
then one reply per scan with the remaining-scans field counting down, ``00`` = until
``QT``; every ``skip + 1``-th scan), ``GD``/``GS``/``GE`` (the next scan; status 10 while
the laser is off). Errors: ``0D`` unknown command, ``0C`` missing or malformed parameters,
``0G``/``0H`` a tag too long or with invalid characters, ``01``-``07`` scan parameter
errors, ``0E`` for any command but ``TM`` while in time-adjust mode. In SCIP 1.1 mode every
line but ``SCIP2.0`` is answered with a bare ``E`` status.

Timing: the laser spins continuously; scan k passes step 0 at host time
``t0 + k * period`` (the period from the sensor clock, which may run ``clock_skew_ppm``
fast). The timestamp of a scan is the sensor's millisecond counter at step 0 (truncated to
whole ms, 24 bits). A scan's reply leaves the sensor when the scan has passed the last
measurable step (AMAX); at a serial baud rate (``baud`` > 0) it arrives ``bytes * 10 /
baud`` later and scans that find the line busy are not sent; ``jitter`` adds an
exponentially distributed delay (mean ``jitter`` s) to every frame, in order, as USB and
OS buffering do.

Encoding of the REP 117 ranges of the scene (:mod:`.laser_scene`): distances in mm
(DMIN..DMAX); +inf as error codes 0-6 (no return, by step number), NaN as codes 7-19
(errors), -inf ("too close") as 20 .. DMIN - 1 mm when the model's DMIN is above 20 mm
(UTM-30LX), else as code 19. A cluster value is the smallest distance of its steps, else
the first step's code. Every scan sent is recorded in :attr:`UrgDevice.sent` with the
REP 117 ranges the driver should publish.

A disconnect (client gone, port vanished: the USB sensor loses power) stops streaming and
switches the laser off; the millisecond counter keeps running.
"""

from collections import deque
from dataclasses import dataclass
import math
import re
from typing import Deque, Dict, List, Optional, Tuple

from landmark_nav.drivers import scip2
from landmark_nav.drivers.scip2 import SensorParams
from landmark_nav.emulators.laser_scene import (add_scene_arguments, LaserScene, LineQueue,
                                                scene_from_args)
from landmark_nav.emulators.server import Device
import numpy as np

_WRAP = 1 << 24
_TAG_OK = re.compile(r'[A-Za-z0-9 ._+@]*')
_NO_RETURN_CODES = (0, 1, 2, 3, 4, 5, 6)
_ERROR_CODES = tuple(range(7, 20))
_PARAM_DIGITS = {'MD': 13, 'MS': 13, 'ME': 13, 'GD': 10, 'GS': 10, 'GE': 10, 'SS': 6,
                 'TM': 1, 'CR': 2, 'VV': 0, 'PP': 0, 'II': 0, 'BM': 0, 'QT': 0, 'RS': 0}
_SCAN_FIELDS = ((0, 4, '01'), (4, 8, '02'), (8, 10, '03'), (10, 11, '06'), (11, 13, '07'))


@dataclass(frozen=True)
class UrgModel:
    """Identity and geometry of an emulated model."""

    params: SensorParams
    product: str
    firmware: str
    serial: str
    intensity: bool  # supports ME / GE
    default_baud: int  # RS-232 baud after power-up; 0 = USB only
    max_step: int  # largest step a request may name


UTM_30LX = UrgModel(
    params=SensorParams(model='UTM-30LX', dmin_mm=23, dmax_mm=60000, ares=1440, amin=0,
                        amax=1080, afrt=540, scan_rpm=2400),
    product='SOKUIKI Sensor TOP-URG UTM-30LX', firmware='1.19.03(11/Aug./2011)',
    serial='H1000001', intensity=True, default_baud=0, max_step=1080)
URG_04LX = UrgModel(
    params=scip2.URG_04LX, product='SOKUIKI Sensor URG-04LX',
    firmware='3.4.03(17/Dec./2012)', serial='H0000001', intensity=False,
    default_baud=19200, max_step=768)
MODELS: Dict[str, UrgModel] = {'utm-30lx': UTM_30LX, 'urg-04lx': URG_04LX}


@dataclass(frozen=True, eq=False)
class SentScan:
    """One scan reply as sent, with the ranges a driver should publish (REP 117)."""

    command: str
    timestamp_ms: int  # the 24-bit value sent
    start_step: int
    end_step: int
    cluster: int
    raw: np.ndarray  # (N,) values sent (mm or codes)
    expected: np.ndarray  # (N,) float32 REP 117 ranges
    intensities: Optional[np.ndarray]
    step0_time: float  # host time [s] at which the scan passed step 0
    sent_time: float  # host time [s] the reply is handed to the port (after its transfer)


@dataclass
class _Stream:
    command: str
    start: int
    end: int
    cluster: int
    skip: int
    remaining: int  # 0: until QT
    tag: str
    counter: int = 0


@dataclass
class _Pending:
    command: str
    start: int
    end: int
    cluster: int
    tag: str
    after: float  # answer with the first scan passing step 0 at or after this time


def _frame(echo: bytes, status: str, lines: Tuple[bytes, ...] = ()) -> bytes:
    """Build a reply without validating the echo (also for commands the host got wrong)."""
    s = status.encode('ascii')
    out = [echo + b'\n', s + b'\n' if len(s) == 1 else scip2.encode_line(s)]
    out += [scip2.encode_line(line) for line in lines]
    return b''.join(out) + b'\n'


class UrgDevice(Device):
    """SCIP 2.0 sensor logic (see the module docstring); no I/O, the clock is passed in.

    Args:
        model: :data:`UTM_30LX` or :data:`URG_04LX` (or another :class:`UrgModel`).
        scene: What the laser sees (default: the office world, fixed pose).
        baud: RS-232 baud rate the line runs at (0 = USB: no transfer delay); None = the
            model's power-up default.
        scip1_boot: Start in SCIP 1.1 mode (some URG-04LX units do), needing ``SCIP2.0``.
        clock_start_ms: Millisecond counter at start (e.g. near 2**24 to see it wrap).
        clock_skew_ppm: The sensor clock runs this much fast (negative: slow) [ppm].
        jitter: Mean of the exponential extra delivery delay per frame [s].
        seed: Seed of the delivery jitter.
        history: Number of sent scans kept in :attr:`sent`.
    """

    def __init__(self, model: UrgModel = UTM_30LX, scene: Optional[LaserScene] = None,
                 baud: Optional[int] = None, scip1_boot: bool = False,
                 clock_start_ms: int = 0, clock_skew_ppm: float = 0.0, jitter: float = 0.0,
                 seed: int = 1, history: int = 400) -> None:
        """Power the sensor up (laser off, not streaming)."""
        if jitter < 0.0 or not -1e4 < clock_skew_ppm < 1e4:
            raise ValueError('need jitter >= 0 and |clock_skew_ppm| < 1e4')
        self.model = model
        self.params = model.params
        self.scene = scene or LaserScene()
        self.default_baud = model.default_baud if baud is None else int(baud)
        self.scip1_boot = scip1_boot
        self.skew = clock_skew_ppm * 1e-6
        self._clock_start_ms = float(clock_start_ms)
        self._queue = LineQueue(self.default_baud, jitter, np.random.default_rng(seed))
        self.sent: Deque[SentScan] = deque(maxlen=history)
        self.scans_sent = 0
        self.scans_skipped = 0  # scan periods passed over when polled too late (a busy host)
        self.commands: List[str] = []  # every command line received, for tests
        self._buf = b''
        self._t0: Optional[float] = None
        self._clock_h0 = 0.0
        self._speed_level = 0
        self._reset_state()

    # --- state ---------------------------------------------------------------------------

    def _reset_state(self) -> None:
        self.scip2_mode = not self.scip1_boot
        self.laser_on = False
        self.time_adjust = False
        self._stream: Optional[_Stream] = None
        self._pending: List[_Pending] = []
        self._queue.clear()
        self._queue.baud = self.default_baud
        self.baud = self.default_baud

    def disconnected(self) -> None:
        """Stop streaming and switch the laser off (USB power lost / client gone)."""
        self._reset_state()
        self._buf = b''

    def _start(self, now: float) -> None:
        if self._t0 is None:
            self._t0 = self._clock_h0 = now
            self.scene.start(now)
            # scans pass step 0 at a fixed phase within the millisecond (0.37 ms)
            self._base_time, self._base_k = now + 0.37e-3 / (1.0 + self.skew), 0
            self._k_next = 0

    @property
    def step_time(self) -> float:
        """Host time per step [s] at the current scan speed."""
        rpm = self.params.scan_rpm * (1.0 - 0.01 * self._speed_level)
        return 60.0 / (rpm * self.params.ares) / (1.0 + self.skew)

    @property
    def period(self) -> float:
        """Host time per scan [s]."""
        return self.step_time * self.params.ares

    def sensor_ms(self, host: float) -> float:
        """Return the sensor's (unwrapped, fractional) millisecond counter at host time."""
        return self._clock_start_ms + (host - self._clock_h0) * 1000.0 * (1.0 + self.skew)

    def counter(self, host: float) -> int:
        """Return the 24-bit millisecond counter at host time (what TM1 and scans carry)."""
        return int(math.floor(self.sensor_ms(host))) % _WRAP

    def _scan_start(self, k: int) -> float:
        return self._base_time + (k - self._base_k) * self.period

    def _scan_ready(self, k: int) -> float:
        return self._scan_start(k) + (self.params.amax + 1) * self.step_time

    # --- Device API ------------------------------------------------------------------------

    def receive(self, data: bytes, now: float) -> List[bytes]:
        """Consume command bytes; replies are queued and leave through :meth:`poll`."""
        self._start(now)
        self._buf += data
        while True:
            cut = min((i for i in (self._buf.find(b'\n'), self._buf.find(b'\r')) if i >= 0),
                      default=-1)
            if cut < 0:
                break
            line, self._buf = self._buf[:cut], self._buf[cut + 1:]
            if line:
                self._command(line, now)
        if len(self._buf) > 4096:  # no terminator in sight: drop the junk
            self._buf = b''
        return self._queue.take(now)

    def next_due(self, now: float) -> Optional[float]:
        """Return the earlier of the next queued frame's delivery and the next scan's end."""
        if self._t0 is None:
            return None
        due = self._queue.next_due()
        ready = self._scan_ready(self._k_next)
        return ready if due is None else min(due, ready)

    def poll(self, now: float) -> List[bytes]:
        """Produce the scans that completed by ``now``; release frames that are due."""
        self._start(now)
        if now - self._scan_ready(self._k_next) > 5 * self.period:  # long pause: catch up
            k = self._base_k + int((now - self._base_time) / self.period) - 1
            self.scans_skipped += max(0, k - self._k_next)
            self._k_next = k
        while self._scan_ready(self._k_next) <= now:
            self._scan(self._k_next)
            self._k_next += 1
        return self._queue.take(now)

    # --- commands ----------------------------------------------------------------------------

    def _reply(self, echo: bytes, status: str, now: float, lines=()) -> None:
        self._queue.put(_frame(echo, status, tuple(lines)), now)

    def _command(self, line: bytes, now: float) -> None:
        text = line.decode('ascii', 'replace')
        self.commands.append(text)
        if not self.scip2_mode:
            if text == 'SCIP2.0':
                self.scip2_mode = True
                self._reply(line, '0', now)
            else:
                self._reply(line, 'E', now)
            return
        if text == 'SCIP2.0':
            self._reply(line, '0', now)
            return
        body, _, tag = text.partition(';')
        name, params = body[:2], body[2:]
        if len(tag) > 16:
            self._reply(line, '0G', now)
            return
        if not _TAG_OK.fullmatch(tag):
            self._reply(line, '0H', now)
            return
        if name not in _PARAM_DIGITS:
            self._reply(line, '0D', now)
            return
        if self.time_adjust and name != 'TM':
            self._reply(line, '0E', now)
            return
        if len(params) != _PARAM_DIGITS[name]:
            self._reply(line, '0C', now)
            return
        if name in scip2.SCAN_COMMANDS:
            self._scan_command(line, name, params, tag, now)
        elif not params.isdigit() and params:
            self._reply(line, '0C' if name != 'SS' else '01', now)
        else:
            getattr(self, '_cmd_' + name.lower())(line, params, now)

    def _cmd_vv(self, line: bytes, params: str, now: float) -> None:
        m = self.model
        fields = [('VEND', 'Hokuyo Automatic Co.,Ltd.'), ('PROD', m.product),
                  ('FIRM', m.firmware), ('PROT', 'SCIP 2.0'), ('SERI', m.serial)]
        self._info(line, fields, now)

    def _cmd_pp(self, line: bytes, params: str, now: float) -> None:
        p = self.params
        fields = [('MODL', p.model), ('DMIN', str(p.dmin_mm)), ('DMAX', str(p.dmax_mm)),
                  ('ARES', str(p.ares)), ('AMIN', str(p.amin)), ('AMAX', str(p.amax)),
                  ('AFRT', str(p.afrt)), ('SCAN', str(p.scan_rpm))]
        self._info(line, fields, now)

    def _cmd_ii(self, line: bytes, params: str, now: float) -> None:
        rpm = self.params.scan_rpm * (1.0 - 0.01 * self._speed_level)
        mode = 'Ready' if self._stream is None else f'Measuring by {self._stream.command}'
        fields = [('MODL', self.params.model), ('LASR', 'ON' if self.laser_on else 'OFF'),
                  ('SCSP', f'{"Initial" if not self._speed_level else "Changed"}'
                           f'({rpm:g}[rpm])'),
                  ('MESM', mode),
                  ('SBPS', f'{self.baud}[bps]' if self.baud else 'USB only'),
                  ('TIME', f'{self.counter(now):06X}'), ('STAT', 'Sensor works well.')]
        self._info(line, fields, now)

    def _info(self, line: bytes, fields, now: float) -> None:
        lines = []
        for key, value in fields:
            text = f'{key}:{value}'.encode('ascii')
            lines.append(text + b';' + bytes((scip2.checksum(text),)))
        frame = line + b'\n' + scip2.encode_line(b'00') + b''.join(x + b'\n' for x in lines)
        self._queue.put(frame + b'\n', now)

    def _cmd_bm(self, line: bytes, params: str, now: float) -> None:
        status = '02' if self.laser_on else '00'
        self.laser_on = True
        self._reply(line, status, now)

    def _cmd_qt(self, line: bytes, params: str, now: float) -> None:
        self._stream = None
        self._pending.clear()
        self.laser_on = False
        self._reply(line, '00', now)

    def _cmd_rs(self, line: bytes, params: str, now: float) -> None:
        self._stream = None
        self._pending.clear()
        self.laser_on = False
        self._clock_start_ms, self._clock_h0 = 0.0, now
        self._set_speed(0, now)
        self._reply(line, '00', now)
        self.baud = self._queue.baud = self.default_baud

    def _cmd_tm(self, line: bytes, params: str, now: float) -> None:
        code = int(params)
        if code == 0:
            self._reply(line, '02' if self.time_adjust else '00', now)
            self.time_adjust = True
        elif code == 1:
            if not self.time_adjust:
                self._reply(line, '04', now)
            else:
                self._reply(line, '00', now, [scip2.encode_int(self.counter(now), 4)])
        elif code == 2:
            self._reply(line, '00' if self.time_adjust else '03', now)
            self.time_adjust = False
        else:
            self._reply(line, '01', now)

    def _cmd_ss(self, line: bytes, params: str, now: float) -> None:
        baud = int(params)
        if baud not in scip2.BAUD_RATES:
            self._reply(line, '02', now)
        elif self.default_baud == 0:  # USB: accepted, nothing changes on the line
            self._reply(line, '00', now)
        elif baud == self.baud:
            self._reply(line, '03', now)
        else:
            self._reply(line, '00', now)
            self.baud = self._queue.baud = baud  # the reply went out at the old rate

    def _cmd_cr(self, line: bytes, params: str, now: float) -> None:
        level = int(params)
        level = 0 if level == 99 else level
        if not 0 <= level <= 10:
            self._reply(line, '02', now)
        elif level == self._speed_level:
            self._reply(line, '03', now)
        else:
            self._set_speed(level, now)
            self._reply(line, '00', now)

    def _set_speed(self, level: int, now: float) -> None:
        if level == self._speed_level:
            return
        self._base_time, self._base_k = self._scan_start(self._k_next), self._k_next
        self._speed_level = level

    def _scan_command(self, line: bytes, name: str, params: str, tag: str,
                      now: float) -> None:
        continuous = name[0] == 'M'
        for lo, hi, code in _SCAN_FIELDS[:5 if continuous else 3]:
            if not params[lo:hi].isdigit():
                self._reply(line, code, now)
                return
        start, end, cluster = int(params[0:4]), int(params[4:8]), max(1, int(params[8:10]))
        if end > self.model.max_step:
            self._reply(line, '04', now)
            return
        if end < start:
            self._reply(line, '05', now)
            return
        if name in ('ME', 'GE') and not self.model.intensity:
            self._reply(line, '0D', now)
            return
        if continuous:
            self.laser_on = True
            self._stream = _Stream(name, start, end, cluster, int(params[10]),
                                   int(params[11:13]), tag)
            self._reply(line, '00', now)
        elif not self.laser_on:
            self._reply(line, '10', now)
        else:
            self._pending.append(_Pending(name, start, end, cluster, tag, now))

    # --- scans --------------------------------------------------------------------------------

    def _scan(self, k: int) -> None:
        stream, start = self._stream, self._scan_start(k)
        due = [p for p in self._pending if p.after <= start]
        emit = False
        if stream is not None:
            emit = stream.counter % (stream.skip + 1) == 0
            stream.counter += 1
        if not (emit or due):
            return
        ready = self._scan_ready(k)
        if self._queue.busy(ready):
            return  # the line is still busy with the previous scan: this one is lost
        values = self._measure(start)
        for p in due:
            self._pending.remove(p)
            self._send_scan(p.command, p.start, p.end, p.cluster, None, p.tag, values, start,
                            ready)
        if emit:
            remaining = None
            if stream.remaining:
                stream.remaining -= 1
                remaining = stream.remaining
            self._send_scan(stream.command, stream.start, stream.end, stream.cluster,
                            (stream.skip, remaining or 0), stream.tag, values, start, ready)
            if remaining == 0:
                self._stream = None
                self.laser_on = False

    def _measure(self, start: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return raw values, expected REP 117 ranges and intensities of steps 0..max_step."""
        p = self.params
        steps = np.arange(p.amin, p.amax + 1)
        angles = (steps - p.afrt) * (2.0 * math.pi / p.ares)
        m = self.scene.measure(start - self._t0 + p.amin * self.step_time, angles,
                               self.step_time, p.dmin_mm / 1000.0, p.dmax_mm / 1000.0,
                               incidence=self.model.intensity)
        r = m.ranges
        n_all = self.model.max_step + 1
        raw = np.empty(n_all, dtype=np.int64)
        expected = np.empty(n_all, dtype=np.float32)
        idx = np.arange(n_all)
        raw[:] = np.take(_NO_RETURN_CODES, idx % len(_NO_RETURN_CODES))  # outside AMIN..AMAX
        expected[:] = math.inf
        sl = slice(p.amin, p.amax + 1)
        mm = np.round(np.where(np.isfinite(r), r, 0.0) * 1000.0).astype(np.int64)
        finite = np.isfinite(r) & (mm >= p.dmin_mm) & (mm <= p.dmax_mm)
        seg_raw, seg_exp = raw[sl], expected[sl]
        seg_raw[finite] = mm[finite]
        seg_exp[finite] = (mm[finite] / 1000.0).astype(np.float32)
        close = (r == -math.inf) | (np.isfinite(r) & (mm < p.dmin_mm))
        if p.dmin_mm > scip2.DMIN_MM:
            seg_raw[close] = scip2.DMIN_MM + steps[close] % (p.dmin_mm - scip2.DMIN_MM)
            seg_exp[close] = -math.inf
        else:
            seg_raw[close] = 19
            seg_exp[close] = math.nan
        far = (r == math.inf) | (np.isfinite(r) & (mm > p.dmax_mm))
        seg_raw[far] = np.take(_NO_RETURN_CODES, steps[far] % len(_NO_RETURN_CODES))
        seg_exp[far] = math.inf
        bad = np.isnan(r)
        seg_raw[bad] = np.take(_ERROR_CODES, steps[bad] % len(_ERROR_CODES))
        seg_exp[bad] = math.nan
        inten = np.zeros(n_all, dtype=np.int64)
        if self.model.intensity:
            cos = np.nan_to_num(m.cos_incidence, nan=0.0)
            dist = np.where(finite, r, 1.0)
            inten[sl] = np.where(finite, np.clip(np.round(9000.0 * cos / np.maximum(dist, 0.3)
                                                          + 200.0), 0, (1 << 18) - 1), 0)
        return raw, expected, inten

    def _send_scan(self, command: str, start: int, end: int, cluster: int,
                   stream: Optional[Tuple[int, int]], tag: str, values, t_step0: float,
                   ready: float) -> None:
        raw_all, exp_all, inten_all = values
        n = -(-(end - start + 1) // cluster)
        group = start + np.arange(n)[:, None] * cluster + np.arange(cluster)[None, :]
        inside = group <= end
        group = np.minimum(group, end)
        g_raw = raw_all[group]
        valid = inside & (g_raw >= scip2.DMIN_MM)
        key = np.where(valid, g_raw, np.iinfo(np.int64).max)
        pick = np.where(valid.any(axis=1), np.argmin(key, axis=1), 0)
        chosen = group[np.arange(n), pick]  # smallest distance of the cluster, else 1st step
        raw = raw_all[chosen]
        expected = exp_all[chosen].astype(np.float32)
        inten = inten_all[chosen]
        intensities = np.array(inten, dtype=np.int64) if command in ('ME', 'GE') else None
        echo = f'{command}{start:04d}{end:04d}{cluster:02d}'
        if stream is not None:
            echo += f'{stream[0]:01d}{stream[1]:02d}'
        if tag:
            echo += ';' + tag
        stamp = self.counter(t_step0)
        frame = scip2.encode_scan_reply_raw(echo, raw, stamp, intensities)
        due = self._queue.put(frame, ready)
        for a in (raw, expected):
            a.setflags(write=False)
        self.sent.append(SentScan(command, stamp, start, end, cluster, raw, expected,
                                  intensities, t_step0, due))
        self.scans_sent += 1


# ---------------------------------------------------------------------------- command line


def add_arguments(parser) -> None:
    """Add the URG emulator's options to ``landmark_nav emulate urg``."""
    parser.add_argument('--model', choices=sorted(MODELS), default='utm-30lx',
                        help='UTM-30LX (1081 steps, 270 deg, 40 Hz, USB) or URG-04LX (682 '
                             'steps, 239.4 deg, 10 Hz, RS-232 19200 baud)')
    parser.add_argument('--baud', type=int, default=None,
                        help='emulated RS-232 line rate [bit/s] (0: USB, no transfer delay; '
                             'default: the model default)')
    parser.add_argument('--scip1', action='store_true',
                        help='boot in SCIP 1.1 (the driver must send SCIP2.0)')
    parser.add_argument('--clock-start-ms', type=int, default=0,
                        help='initial millisecond counter (e.g. 16770000 to see the 24-bit '
                             'wrap after 7 s)')
    parser.add_argument('--clock-skew-ppm', type=float, default=0.0,
                        help='sensor clock rate error [ppm]')
    add_scene_arguments(parser)


def make_device(args) -> UrgDevice:
    """Build the device from the parsed options."""
    return UrgDevice(MODELS[args.model], scene_from_args(args), baud=args.baud,
                     scip1_boot=args.scip1, clock_start_ms=args.clock_start_ms,
                     clock_skew_ppm=args.clock_skew_ppm, jitter=args.jitter_ms / 1000.0,
                     seed=args.seed)
