"""SICK LMS200 emulator speaking LMS2xx telegrams, measuring the simulator world.

:class:`LmsDevice` is the scanner as seen through its RS-232/422 line
(``docs/protocols/lms2xx.md``); :class:`~landmark_nav.emulators.server.DeviceServer` serves
it on a pty and a TCP port (``landmark_nav emulate lms200``).

Requests (CRC checked; a bad CRC is answered with NAK 0x15, a good request with ACK 0x06
after ``ack_delay``, then the reply): ``20 00 'SICK_LMS'`` installation mode (``A0 00``, a
wrong password ``A0 01``), ``20 24`` continuous ``B0`` stream, ``20 25`` output on request
only, ``20 40/41/42/48`` baud 38400/19200/9600/500k (``A0 00`` at the old rate, then the
line switches), ``30 01`` one scan, ``3B`` variant 100/180 deg x 0.25/0.5/1 deg (not
180 deg / 0.25 deg; ``BB`` with the accepted flag), ``31`` status (``B1`` + 152 bytes),
``3A`` type (``BA`` + 20 characters, NUL-padded), ``74`` / ``77`` read / write the
configuration block (units in byte 6, measuring mode in byte 5; writing needs installation
mode), ``10`` reset
(``91``, then after ``reset_delay`` the power-on ``90``, at 9600 baud). Anything else is
answered with a ``92`` telegram.

Timing: the mirror turns at 75 Hz. A scan of resolution 1/0.5/0.25 deg takes 1/2/4
revolutions (interlaced); scan k starts at ``t0 + k * passes / 75`` with its first value
(at -angle/2) and is complete half a revolution (180 deg) or 100/360 of one (100 deg) into
its last pass. In continuous mode every complete scan that finds the line free is sent; it
arrives ``bytes * 10 / baud`` later (at 38400 baud a 0.5 deg scan takes 0.19 s, so about
5 scans/s reach the host), plus an optional exponential ``jitter``.

Encoding of the REP 117 ranges of the scene (:mod:`.laser_scene`): distances in the
configured units (mm, cm or 10 cm); +inf as "above maximum range" (mask - 8); NaN as one of
the error values (invalid, dazzle, overflow, S/N too low, read error, by value index; the
dazzle flag is set with the dazzle value in the default measuring mode); -inf ("too close",
something on the window) as 0. Every scan sent is recorded in :attr:`LmsDevice.sent` with
the REP 117 ranges the driver should publish.

A disconnect leaves the scanner as it was (it has its own power): a streaming scanner keeps
streaming at its baud rate, as a real one does when the host's adapter is unplugged.
"""

from collections import deque
from dataclasses import dataclass
import math
import struct
from typing import Deque, List, Optional

from landmark_nav.drivers import lms2xx
from landmark_nav.drivers.errors import ChecksumError, ProtocolError
from landmark_nav.emulators.laser_scene import (add_scene_arguments, LaserScene, LineQueue,
                                                scene_from_args)
from landmark_nav.emulators.server import Device
import numpy as np

REVOLUTION = 1.0 / 75.0  # mirror period [s]
PASSES = {100: 1, 50: 2, 25: 4}  # resolution (1/100 deg) -> revolutions per scan
VARIANTS = {100: (25, 50, 100), 180: (50, 100)}
BAUD_CODES = {0x40: 38400, 0x41: 19200, 0x42: 9600, 0x48: 500000}
UNITS_CODE = {'cm': 0, 'mm': 1, '10cm': 2}
PASSWORD = b'SICK_LMS'
STATUS_LENGTH = 152
_ERROR_OFFSETS = (0, 1, 2, 4, 5)  # invalid, dazzle, overflow, S/N too low, read error


def range_limits(units: str, mode: str = lms2xx.DEFAULT_MODE):
    """Return ``(range_min, range_max)`` [m] a scanner reports in ``units`` and ``mode``.

    range_min is one unit (a 0 means "too close"); range_max the largest distance below the
    special values (mask - 9 units: 8.182 m in mm, 81.82 m in cm with 13 distance bits).
    """
    per_m = {'mm': 1000, 'cm': 100, '10cm': 10}[units]
    mask = (1 << lms2xx.MEASURING_MODES[mode].range_bits) - 1
    return 1.0 / per_m, (mask - 9) / per_m


def value_count(angle_deg: int, resolution_cdeg: int) -> int:
    """Return the number of values of a variant (e.g. 361 at 180 deg / 0.5 deg)."""
    return angle_deg * 100 // resolution_cdeg + 1


@dataclass(frozen=True, eq=False)
class SentScan:
    """One ``B0`` telegram as sent, with the ranges a driver should publish (REP 117)."""

    seq: int
    angle_deg: int
    resolution_cdeg: int
    units: str
    raw: np.ndarray  # (N,) distance words sent (without flags)
    expected: np.ndarray  # (N,) float32 REP 117 ranges
    first_time: float  # host time [s] of the first value
    sent_time: float  # host time [s] the telegram is handed to the port (after its transfer)
    status: int


class LmsDevice(Device):
    """LMS2xx scanner logic (see the module docstring); no I/O, the clock is passed in.

    Args:
        scene: What the scanner sees (default: the office world, fixed pose).
        baud: Line rate after power-up [bit/s] (the LMS starts at 9600).
        angle_deg: Scanning angle after power-up (100 or 180).
        resolution_cdeg: Angular resolution after power-up (25, 50, 100; 1/100 deg).
        units: ``mm``, ``cm`` or ``10cm`` after power-up.
        continuous: Stream ``B0`` telegrams from power-up.
        ack_delay: Delay of the ACK after a request [s] (about 60 ms on the real LMS).
        ack: Send ACK bytes at all (False: a line that loses them, the driver must cope).
        reset_delay: Delay of the power-on telegram after a reset [s] (30-65 s on the real
            LMS).
        jitter: Mean exponential extra delivery delay per frame [s].
        seed: Seed of the delivery jitter.
        type_string: Answer to the type request.
        history: Number of sent scans kept in :attr:`sent`.
    """

    def __init__(self, scene: Optional[LaserScene] = None, baud: int = 9600,
                 angle_deg: int = 180, resolution_cdeg: int = 50, units: str = 'mm',
                 continuous: bool = False, ack_delay: float = 0.03, ack: bool = True,
                 reset_delay: float = 1.0,
                 jitter: float = 0.0, seed: int = 1, type_string: str = 'LMS200;30106',
                 history: int = 400) -> None:
        """Power the scanner up."""
        if baud not in BAUD_CODES.values():
            raise ValueError(f'baud {baud} is not one of {sorted(BAUD_CODES.values())}')
        if resolution_cdeg not in VARIANTS.get(angle_deg, ()):
            raise ValueError(f'variant {angle_deg} deg / {resolution_cdeg / 100} deg is not '
                             'supported')
        if units not in UNITS_CODE:
            raise ValueError(f'units {units!r} not in {tuple(UNITS_CODE)}')
        self.scene = scene or LaserScene()
        self.power_baud = baud
        self.angle_deg, self.resolution_cdeg = angle_deg, resolution_cdeg
        self.units = units
        self.mode = lms2xx.DEFAULT_MODE
        self.continuous = continuous
        self.ack_delay = ack_delay
        self.ack = ack
        self.reset_delay = reset_delay
        self.type_string = type_string
        self.status_byte = 0x10  # device type bits; tests may set severity / pollution
        self.sent: Deque[SentScan] = deque(maxlen=history)
        self.requests: List[int] = []  # command bytes of the requests received, for tests
        self.naks = 0
        self._decoder = lms2xx.Lms2xxDecoder(address=lms2xx.HOST_ADDRESS, parse=False)
        self._queue = LineQueue(baud, jitter, np.random.default_rng(seed))
        self.baud = baud
        self.installation = False
        self._single: List[float] = []  # request times of pending single scans
        self._reset_until = -math.inf
        self._reset_pending = False
        self._t0: Optional[float] = None
        self._k_next = 0
        self._seq = 0

    # --- timing ---------------------------------------------------------------------------

    @property
    def passes(self) -> int:
        """Revolutions per scan of the current variant."""
        return PASSES[self.resolution_cdeg]

    def _start(self, now: float) -> None:
        if self._t0 is None:
            self._t0 = now
            self._k_next = 0
            self.scene.start(now)

    def _scan_start(self, k: int) -> float:
        return self._t0 + k * REVOLUTION

    def _scan_ready(self, k: int) -> float:
        return (self._scan_start(k) + (self.passes - 1) * REVOLUTION
                + self.angle_deg / 360.0 * REVOLUTION)

    def disconnected(self) -> None:
        """Keep the state: the scanner has its own power supply."""

    # --- Device API -------------------------------------------------------------------------

    def receive(self, data: bytes, now: float) -> List[bytes]:
        """Consume request bytes; replies are queued and leave through :meth:`poll`."""
        self._start(now)
        for item in self._decoder.feed(data):
            if now < self._reset_until:
                continue  # resetting: deaf
            if isinstance(item, ChecksumError):
                self.naks += 1
                self._queue.put(bytes((lms2xx.NAK,)), now + self.ack_delay)
            elif isinstance(item, ProtocolError):
                continue  # garbage between telegrams
            else:
                self._request(item, now)
        return self._queue.take(now)

    def next_due(self, now: float) -> Optional[float]:
        """Return the earlier of the next queued frame's delivery and the next scan's end."""
        if self._t0 is None:
            return None
        due = self._queue.next_due()
        ready = self._scan_ready(self._k_next + (-self._k_next) % self.passes)
        return ready if due is None else min(due, ready)

    def poll(self, now: float) -> List[bytes]:
        """Produce the scans completed by ``now``; release frames that are due."""
        self._start(now)
        if self._reset_pending and now >= self._reset_until:
            self._reset_pending = False
            self._queue.put(lms2xx.encode_reply(0x90, self.type_string.encode('ascii')), now)
        passes = self.passes
        self._k_next += (-self._k_next) % passes
        period = passes * REVOLUTION
        if now - self._scan_ready(self._k_next) > 5 * period:  # long pause: catch up
            self._k_next = int((now - self._t0) / REVOLUTION) // passes * passes - passes
        while self._scan_ready(self._k_next) <= now:
            self._scan(self._k_next)
            self._k_next += passes
        return self._queue.take(now)

    # --- requests ---------------------------------------------------------------------------

    def _reply(self, command: int, data: bytes, now: float) -> None:
        self._queue.put(lms2xx.encode_reply(command, data, self.status_byte), now)

    def _request(self, telegram: lms2xx.Telegram, now: float) -> None:
        cmd, data = telegram.command, telegram.data
        self.requests.append(cmd)
        if self.ack:
            self._queue.put(bytes((lms2xx.ACK,)), now + self.ack_delay)
        now = now + self.ack_delay
        if cmd == 0x20 and data:
            self._mode_switch(data, now)
        elif cmd == 0x30 and data == b'\x01':
            self._single.append(now)
        elif cmd == 0x3B and len(data) == 4:
            angle, resolution = struct.unpack('<HH', data)
            ok = resolution in VARIANTS.get(angle, ())
            if ok:
                self.angle_deg, self.resolution_cdeg = angle, resolution
            self._reply(0xBB, struct.pack('<BHH', int(ok), self.angle_deg,
                                          self.resolution_cdeg), now)
        elif cmd == 0x31 and not data:
            self._reply(0xB1, self._status_block(), now)
        elif cmd == 0x3A and not data:
            self._reply(0xBA, self.type_string.encode('ascii').ljust(20, b'\x00')[:20], now)
        elif cmd == 0x74 and not data:
            self._reply(0xF4, self._config_block(), now)
        elif cmd == 0x77 and len(data) >= 7:
            ok = self.installation
            if ok:
                try:
                    self.units = lms2xx.config_units(data)
                    self.mode = lms2xx.config_measuring_mode(data)
                except ProtocolError:
                    ok = False
            self._reply(0xF7, bytes((int(ok),)) + self._config_block(), now)
        elif cmd == 0x10 and not data:
            self._reply(0x91, b'', now)
            self._reset(now)
        else:
            self._reply(0x92, bytes((cmd,)), now)

    def _mode_switch(self, data: bytes, now: float) -> None:
        code = data[0]
        if code == 0x00:
            ok = data[1:] == PASSWORD
            self.installation = ok
            self._reply(0xA0, bytes((0 if ok else 1,)), now)
        elif code == 0x24 and len(data) == 1:
            self.continuous = True
            self._reply(0xA0, b'\x00', now)
        elif code == 0x25 and len(data) == 1:
            self.continuous = False
            self._reply(0xA0, b'\x00', now)
        elif code in BAUD_CODES and len(data) == 1:
            self._reply(0xA0, b'\x00', now)
            self.baud = self._queue.baud = BAUD_CODES[code]  # after the reply
        else:
            self._reply(0xA0, b'\x02', now)

    def _reset(self, now: float) -> None:
        self.continuous = False
        self.installation = False
        self._single.clear()
        self._reset_until = now + self.reset_delay
        self._reset_pending = True
        self.baud = self._queue.baud = self.power_baud

    def _status_block(self) -> bytes:
        block = bytearray(STATUS_LENGTH)
        block[0:7] = b'V02.10 '
        block[7] = 0x24 if self.continuous else 0x25
        block[8] = self.status_byte
        code = {v: k for k, v in BAUD_CODES.items()}[self.baud]
        block[120:122] = struct.pack('<H', code)
        return bytes(block)

    def _config_block(self) -> bytes:
        block = bytearray(32)
        block[0:2] = struct.pack('<H', 8191)  # blanking
        block[5] = lms2xx.MEASURING_MODES[self.mode].code
        block[6] = UNITS_CODE[self.units]
        return bytes(block)

    # --- scans -------------------------------------------------------------------------------

    def _scan(self, k: int) -> None:
        start = self._scan_start(k)
        single = [t for t in self._single if t <= start]
        if not (self.continuous or single):
            return
        ready = self._scan_ready(k)
        if self._queue.busy(ready):
            return  # the line is still busy: this scan is lost
        for t in single:
            self._single.remove(t)
        n = value_count(self.angle_deg, self.resolution_cdeg)
        angles = lms2xx.scan_angles(n, self.angle_deg, self.resolution_cdeg)
        increment = REVOLUTION / 360.0 * self.resolution_cdeg / 100.0
        range_min, range_max = range_limits(self.units, self.mode)
        r = self.scene.measure(start - self._t0, angles, increment, range_min,
                               range_max).ranges
        per_m = {'mm': 1000, 'cm': 100, '10cm': 10}[self.units]
        spec = lms2xx.MEASURING_MODES[self.mode]
        mask = (1 << spec.range_bits) - 1
        q = np.round(np.where(np.isfinite(r), r, 0.0) * per_m).astype(np.int64)
        raw = np.empty(n, dtype=np.int64)
        expected = np.empty(n, dtype=np.float32)
        ok = np.isfinite(r) & (q >= 1) & (q <= mask - 9)
        raw[ok] = q[ok]
        expected[ok] = (q[ok] / per_m).astype(np.float32)
        far = (r == math.inf) | (np.isfinite(r) & (q > mask - 9))
        raw[far] = mask - 8
        expected[far] = math.inf
        close = (r == -math.inf) | (np.isfinite(r) & (q < 1))
        raw[close] = 0
        expected[close] = -math.inf
        bad = np.isnan(r)
        idx = np.flatnonzero(bad)
        raw[bad] = mask - np.take(_ERROR_OFFSETS, idx % len(_ERROR_OFFSETS))
        expected[bad] = math.nan
        words = raw.copy()
        if any(name == 'dazzle' for name, _, _ in spec.flags):
            shift = next(s for name, s, _ in spec.flags if name == 'dazzle')
            words[raw == mask - 1] |= 1 << shift
        info = n | (UNITS_CODE[self.units] << 14)
        data = struct.pack('<H', info) + words.astype('<u2').tobytes()
        frame = lms2xx.encode_reply(0xB0, data, self.status_byte)
        due = self._queue.put(frame, ready)
        self._seq += 1
        for a in (raw, expected):
            a.setflags(write=False)
        self.sent.append(SentScan(self._seq, self.angle_deg, self.resolution_cdeg, self.units,
                                  raw, expected, start, due, self.status_byte))


# ---------------------------------------------------------------------------- command line


def add_arguments(parser) -> None:
    """Add the LMS200 emulator's options to ``landmark_nav emulate lms200``."""
    parser.add_argument('--baud', type=int, default=9600, choices=sorted(BAUD_CODES.values()),
                        help='line rate after power-up [bit/s] (the LMS starts at 9600; the '
                             'driver switches it)')
    parser.add_argument('--variant', default='180,50', metavar='ANGLE,RES',
                        help='variant after power-up: angle 100|180 [deg], resolution '
                             '25|50|100 [1/100 deg] (default 180,50)')
    parser.add_argument('--units', choices=sorted(UNITS_CODE), default='mm',
                        help='distance units after power-up (default mm)')
    parser.add_argument('--continuous', action='store_true',
                        help='stream B0 telegrams from power-up')
    parser.add_argument('--ack-delay-ms', type=float, default=30.0,
                        help='delay of the ACK after a request [ms] (real LMS: ~60)')
    parser.add_argument('--no-ack', action='store_true',
                        help='never send ACK bytes (the driver must rely on the replies)')
    parser.add_argument('--reset-delay', type=float, default=1.0,
                        help='power-on telegram this long after a reset [s] (real LMS: 30-65)')
    add_scene_arguments(parser)


def make_device(args) -> LmsDevice:
    """Build the device from the parsed options."""
    try:
        angle, resolution = (int(v) for v in args.variant.split(','))
    except ValueError:
        raise ValueError(f'--variant must be ANGLE,RES, got {args.variant!r}') from None
    return LmsDevice(scene_from_args(args), baud=args.baud, angle_deg=angle,
                     resolution_cdeg=resolution, units=args.units,
                     continuous=args.continuous, ack_delay=args.ack_delay_ms / 1000.0,
                     ack=not args.no_ack,
                     reset_delay=args.reset_delay, jitter=args.jitter_ms / 1000.0,
                     seed=args.seed)
