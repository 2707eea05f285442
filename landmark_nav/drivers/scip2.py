"""Hokuyo SCIP 2.0 (URG laser range finders): command encoders and reply decoders.

Pure byte-level code following ``docs/protocols/scip2.md`` (§2-§6): bytes in, frames out; no clock,
no I/O. The host sends a 2-letter command with fixed-width decimal parameters, an optional tag
(``;`` + up to 16 characters) and LF. The sensor answers with LF-terminated lines: the echo of the
command, a status line (2 status characters + checksum character), data lines (each ending in its
checksum character) and an empty line. Measurement data is cut into 64-character blocks; a value
may straddle two lines.

Checksum of a line: ``(sum of its bytes & 0x3F) + 0x30``. Values are groups of 6 bits, most
significant first, each + 0x30: 2 characters (12 bits, ``MS``/``GS``), 3 characters (18 bits,
``MD``/``GD``), 4 characters (24 bits, the millisecond timestamp).

Ranges follow REP 117: distances below DMIN (20 mm) are URG error codes, mapped by
:data:`ERROR_CODE_RANGES` to +inf (no return: nothing measurable within range) or NaN (error);
no URG code means "too close", so the decoder never produces -inf.

Frames: :class:`ScanFrame` (``MD``/``MS``/``ME`` scans, ``GD``/``GS``/``GE`` replies with
data), :class:`InfoReply` (``VV``/``PP``/``II``), :class:`TimeReply` (``TM1``) and
:class:`StatusReply` (every reply without data: acknowledgements and error statuses).
:class:`Scip2Decoder` decodes a byte stream incrementally; :func:`decode_reply` decodes exactly
one reply. The ``encode_*_reply`` functions build sensor replies for emulators and tests.
"""

from dataclasses import dataclass
import math
import re
from typing import Dict, List, Optional, Sequence, Tuple, Union

from landmark_nav.drivers.errors import (ChecksumError, EncodeError, FramingError,
                                         ProtocolError, TruncatedError)
from landmark_nav.drivers.stream import StreamDecoder
import numpy as np

__all__ = [
    'BAUD_RATES', 'BLOCK_CHARS', 'DMIN_MM', 'ERROR_CODE_RANGES', 'Frame', 'InfoReply',
    'SCAN_COMMANDS', 'Scip2Decoder', 'ScanFrame', 'SensorParams', 'StatusReply', 'TimeReply',
    'URG_04LX', 'checksum', 'decode_int', 'decode_reply', 'decode_values',
    'encode_baud_request', 'encode_command', 'encode_info_reply', 'encode_int', 'encode_line',
    'encode_reply', 'encode_scan_reply', 'encode_scan_reply_raw', 'encode_scan_request',
    'encode_time_request', 'encode_values', 'ranges_from_raw', 'ranges_to_raw',
    'status_meaning', 'step_angles',
]

BLOCK_CHARS = 64  # data characters per line (the last line of a reply may be shorter)
DMIN_MM = 20  # URG-04LX: values below this are error codes, not distances
_LF = 0x0A

# Scan commands -> characters per value (docs/protocols/scip2.md §4-§5). ME/GE (distance +
# intensity, 3 + 3 characters) exist on the UTM-30LX only (the URG-04LX lacks them).
SCAN_COMMANDS: Dict[str, int] = {'MD': 3, 'MS': 2, 'ME': 6, 'GD': 3, 'GS': 2, 'GE': 6}
_CONTINUOUS = ('MD', 'MS', 'ME')
_INFO_COMMANDS = ('VV', 'PP', 'II')
_SIMPLE_COMMANDS = ('VV', 'PP', 'II', 'BM', 'QT', 'RS', 'SCIP2.0')
BAUD_RATES = (19200, 38400, 57600, 115200, 250000, 500000, 750000)  # SS, scip2.md §5

_TAG_RE = re.compile(r'[A-Za-z0-9 ._+@]{0,16}')
# One echo line: command with its fixed-width parameters, optional tag, LF.
_ECHO_RE = re.compile(
    rb'(SCIP2\.0|(?:MD|MS|ME)[0-9]{13}|(?:GD|GS|GE)[0-9]{10}|SS[0-9]{6}|TM[0-2]'
    rb'|VV|PP|II|BM|QT|RS)(;[A-Za-z0-9 ._+@]{0,16})?\n')
_MAX_ECHO = 15 + 1 + 16 + 1  # longest echo line (MD + tag + LF)

# URG error codes (range values < DMIN_MM) -> REP 117 value (docs/protocols/scip2.md §6). The
# sensor documents give the codes' meanings only; the classification is ours: codes saying the
# target is beyond the measurable range or returned too little light (0 possibly at 22 m, 1-5
# low intensity, 6 possibly at 5.7 m) mean "no return" (+inf); codes saying a measurement
# failed (7 neighbour steps in error, 8 intensity difference, 9 erred twice, 16 possibly within
# 4096 mm, 18 strong reflector, 19 non-measurable) and the unspecified ones are errors (NaN).
# No code means "too close", so -inf never appears.
ERROR_CODE_RANGES: Tuple[float, ...] = tuple(
    math.inf if code <= 6 else math.nan for code in range(DMIN_MM))
_CODE_LUT = np.array(ERROR_CODE_RANGES, dtype=np.float64)
_NO_RETURN_CODE = 0  # encoder: +inf -> "possibly at 22 m"
_ERROR_CODE = 19  # encoder: NaN -> "non-measurable distance"


# ---------------------------------------------------------------------------- status codes

# (command, status) -> meaning, as docs/protocols/scip2.md §6 lists them.
_SCAN_PARAM_ERRORS = {
    '01': 'starting step has a non-numeric value',
    '02': 'end step has a non-numeric value',
    '03': 'cluster count has a non-numeric value',
    '04': 'end step is out of range',
    '05': 'end step is smaller than the starting step',
}
_STATUS_TABLE: Dict[Tuple[str, str], str] = {}
for _cmd in SCAN_COMMANDS:
    for _code, _text in _SCAN_PARAM_ERRORS.items():
        _STATUS_TABLE[(_cmd, _code)] = _text
for _cmd in _CONTINUOUS:
    _STATUS_TABLE[(_cmd, '06')] = 'scan interval has a non-numeric value'
    _STATUS_TABLE[(_cmd, '07')] = 'number of scans has a non-numeric value'
    _STATUS_TABLE[(_cmd, '99')] = 'scan data follows'
for _cmd in ('GD', 'GS', 'GE'):
    _STATUS_TABLE[(_cmd, '10')] = 'laser is off (send BM first)'
_STATUS_TABLE.update({
    ('BM', '01'): 'unable to switch the laser on: laser malfunction',
    ('BM', '02'): 'laser is already on',
    ('SS', '01'): 'baud rate has a non-numeric value',
    ('SS', '02'): 'invalid baud rate',
    ('SS', '03'): 'the sensor already runs at this baud rate',
    ('SS', '04'): 'baud rate not supported by the sensor',
    ('TM', '01'): 'invalid time-adjust control code',
    ('TM', '02'): 'time-adjust mode requested while already in it',
    ('TM', '03'): 'time-adjust mode left while not in it',
    ('TM', '04'): 'time requested while not in time-adjust mode',
    ('SCIP2.0', '0'): 'switched to SCIP 2.0 (or already in it)',
})


def status_meaning(command: str, status: str) -> str:
    """Return the meaning of a reply status.

    Args:
        command: Command name (``'MD'``, ``'BM'``, ``'SCIP2.0'``, ...).
        status: Status string of the reply (2 characters, or 1 for bare replies).

    Returns:
        A short English description; ``'unknown status ...'`` for codes not in the tables.
    """
    key = (command[:2] if command != 'SCIP2.0' else command, status)
    if key in _STATUS_TABLE:
        return _STATUS_TABLE[key]
    if status == '00':
        return 'command received without error'
    if status == 'E':
        return 'error reply of SCIP 1.1: the sensor must be switched with SCIP2.0'
    if len(status) == 2 and status[0] == '0' and 'A' <= status[1] <= 'I':
        if status == '0I':
            return 'invalid command: sensor in firmware-update mode'
        if status == '0E':
            return 'invalid command in this state (unconfirmed: time-adjust mode)'
        return 'invalid command'
    if status.isdigit() and len(status) == 2:
        code = int(status)
        if 21 <= code <= 49:
            return 'processing stopped to verify an error'
        if 50 <= code <= 97:
            return 'hardware trouble'
        if code == 98:
            return 'resumed after confirming normal laser operation'
    return f'unknown status {status!r}'


# ---------------------------------------------------------------------------- frames


@dataclass(frozen=True)
class StatusReply:
    """A reply without data: acknowledgements (``00``) and error statuses."""

    command: str  # 'BM', 'QT', 'MD', 'SCIP2.0', ...
    parameters: str  # the echoed decimal parameters ('' for commands without any)
    status: str
    tag: str = ''

    @property
    def meaning(self) -> str:
        """Meaning of the status (see :func:`status_meaning`)."""
        return status_meaning(self.command, self.status)


@dataclass(frozen=True)
class InfoReply:
    """Reply to ``VV``, ``PP`` or ``II``: ``KEY:value`` lines in order of arrival.

    Checksum errors on these replies are tolerated (some URG-04LX firmware sends wrong ones on
    the ``VV`` serial line) and listed in ``checksum_warnings`` instead of raised.
    """

    command: str
    status: str
    fields: Tuple[Tuple[str, str], ...]
    checksum_warnings: Tuple[str, ...] = ()
    tag: str = ''

    def as_dict(self) -> Dict[str, str]:
        """Return the fields as a dict (a repeated key keeps its last value)."""
        return dict(self.fields)


@dataclass(frozen=True)
class TimeReply:
    """Reply to ``TM1``: the sensor's 24-bit millisecond counter."""

    status: str
    timestamp_ms: int
    tag: str = ''


@dataclass(frozen=True, eq=False)
class ScanFrame:
    """One scan: reply to ``GD``/``GS``/``GE`` or one ``MD``/``MS``/``ME`` scan (arrays read-only).

    ``ranges_m[i]`` belongs to step ``start_step + i * cluster`` (see :func:`step_angles`).
    """

    command: str  # 'MD', 'MS', 'ME', 'GD', 'GS' or 'GE'
    status: str  # '99' for MD/MS/ME scans, '00' for GD/GS/GE
    timestamp_ms: int  # raw 24-bit sensor time of step 0 (wraps every 2**24 ms)
    ranges_m: np.ndarray  # (N,) float64, REP 117 (+inf no return, NaN error)
    raw: np.ndarray  # (N,) uint32, the decoded values (mm, or error codes < DMIN_MM)
    intensities: Optional[np.ndarray]  # (N,) uint32 for ME/GE, else None
    start_step: int
    end_step: int
    cluster: int  # steps per value (an echoed 00 counts as 1)
    scan_interval: Optional[int] = None  # MD/MS/ME: scans skipped between outputs
    remaining_scans: Optional[int] = None  # MD/MS/ME: nn of the echo (00 = continuous)
    tag: str = ''


Frame = Union[ScanFrame, InfoReply, TimeReply, StatusReply]


@dataclass(frozen=True)
class SensorParams:
    """Sensor geometry from the ``PP`` reply (defaults: URG-04LX, docs/protocols/scip2.md §5)."""

    model: str = 'URG-04LX'
    dmin_mm: int = 20
    dmax_mm: int = 5600
    ares: int = 1024  # steps per revolution
    amin: int = 44  # first measurable step
    amax: int = 725  # last measurable step
    afrt: int = 384  # step facing forwards
    scan_rpm: int = 600

    @classmethod
    def from_info(cls, reply: InfoReply) -> 'SensorParams':
        """Build from a ``PP`` reply.

        Raises:
            FramingError: If a field is missing or not an integer.
        """
        fields = reply.as_dict()
        try:
            return cls(model=fields.get('MODL', ''),
                       dmin_mm=int(fields['DMIN']), dmax_mm=int(fields['DMAX']),
                       ares=int(fields['ARES']), amin=int(fields['AMIN']),
                       amax=int(fields['AMAX']), afrt=int(fields['AFRT']),
                       scan_rpm=int(fields['SCAN']))
        except (KeyError, ValueError) as err:
            raise FramingError(f'PP reply: missing or non-integer field ({err})') from err

    def step_angle(self, step: float) -> float:
        """Return the angle (rad, CCW positive, 0 = front) of a step."""
        return (step - self.afrt) * 2.0 * math.pi / self.ares


URG_04LX = SensorParams()


def step_angles(start_step: int, count: int, cluster: int = 1,
                params: SensorParams = URG_04LX) -> np.ndarray:
    """Return the angles (rad) of the values of a scan.

    Value i is placed at step ``start_step + i * cluster``, as urg_node places ``angle_min``
    at the first step and uses ``cluster`` steps per increment.
    """
    steps = start_step + cluster * np.arange(count, dtype=np.float64)
    return (steps - params.afrt) * (2.0 * math.pi / params.ares)


# ---------------------------------------------------------------------------- encodings


def checksum(data: bytes) -> int:
    """Return the SCIP checksum character (as an int) of ``data``: (byte sum & 0x3F) + 0x30."""
    return (sum(data) & 0x3F) + 0x30


def encode_int(value: int, width: int) -> bytes:
    """Encode a non-negative integer in ``width`` characters of 6 bits (+ 0x30 each).

    Raises:
        EncodeError: If the value does not fit in ``6 * width`` bits.
    """
    value = int(value)
    if not 0 <= value < 1 << (6 * width):
        raise EncodeError(f'value {value} does not fit {width} SCIP characters')
    return bytes(((value >> (6 * (width - 1 - i))) & 0x3F) + 0x30 for i in range(width))


def decode_int(chars: bytes) -> int:
    """Decode one value of ``len(chars)`` SCIP characters (6 bits each).

    Raises:
        FramingError: If a character is outside 0x30..0x6F.
    """
    value = 0
    for i, c in enumerate(chars):
        if not 0x30 <= c <= 0x6F:
            raise FramingError(f'invalid SCIP data character 0x{c:02X} at index {i}')
        value = (value << 6) | (c - 0x30)
    return value


def encode_values(values: Sequence[int], width: int) -> bytes:
    """Encode non-negative integers in ``width`` characters each (vectorised).

    Raises:
        EncodeError: If a value is negative or too large for ``width`` characters.
    """
    v = np.asarray(values, dtype=np.int64).ravel()
    if v.size and (int(v.min()) < 0 or int(v.max()) >= 1 << (6 * width)):
        bad = int(np.flatnonzero((v < 0) | (v >= 1 << (6 * width)))[0])
        raise EncodeError(f'value {int(v[bad])} at index {bad} does not fit {width} '
                          'SCIP characters')
    shifts = 6 * np.arange(width - 1, -1, -1, dtype=np.int64)
    chars = ((v[:, None] >> shifts) & 0x3F) + 0x30
    return chars.astype(np.uint8).tobytes()


def decode_values(data: bytes, width: int) -> np.ndarray:
    """Decode concatenated ``width``-character values (checksums already removed).

    Returns:
        (len(data) // width,) uint32 array.

    Raises:
        FramingError: If the length is not a multiple of ``width`` or a character is outside
            0x30..0x6F.
    """
    if len(data) % width:
        raise FramingError(f'{len(data)} data characters are not a multiple of {width}')
    a = np.frombuffer(data, dtype=np.uint8) - np.uint8(0x30)  # wraps below 0x30 to >= 0xD0
    if a.size and int(a.max()) > 63:
        bad = int(np.flatnonzero(a > 63)[0])
        raise FramingError(f'invalid SCIP data character 0x{data[bad]:02X} at data index {bad}')
    a = a.reshape(-1, width).astype(np.uint32)
    out = a[:, 0].copy()
    for i in range(1, width):
        out <<= 6
        out |= a[:, i]
    return out


def ranges_from_raw(raw: np.ndarray) -> np.ndarray:
    """Convert decoded values (mm) to metres; error codes become +inf or NaN (REP 117)."""
    raw = np.asarray(raw)
    ranges = raw / 1000.0  # division rounds correctly: 1001 -> 1.001 exactly as typed
    codes = raw < DMIN_MM
    if codes.any():
        ranges[codes] = _CODE_LUT[raw[codes]]
    return ranges


def ranges_to_raw(ranges_m: Sequence[float], width: int = 3) -> np.ndarray:
    """Quantise ranges (m) to the values a sensor sends: mm, +inf -> code 0, NaN -> code 19.

    Raises:
        EncodeError: For -inf, for finite ranges that round below DMIN (the sensor has no
            "too close" code; send a code with :func:`encode_scan_reply_raw` instead) or beyond
            the ``width``-character maximum.
    """
    r = np.asarray(ranges_m, dtype=np.float64).ravel()
    raw = np.empty(r.shape, dtype=np.int64)
    finite = np.isfinite(r)
    with np.errstate(invalid='ignore', over='ignore'):
        mm = np.round(r[finite] * 1000.0)
    limit = (1 << (6 * width)) - 1
    if mm.size and (mm.min() < DMIN_MM or mm.max() > limit):
        idx = np.flatnonzero(finite)[int(np.flatnonzero((mm < DMIN_MM) | (mm > limit))[0])]
        raise EncodeError(f'range {r[idx]!r} m at index {idx} is outside '
                          f'[{DMIN_MM}, {limit}] mm')
    if np.any(r == -np.inf):
        idx = int(np.flatnonzero(r == -np.inf)[0])
        raise EncodeError(f'range -inf at index {idx}: SCIP has no "too close" code')
    raw[finite] = mm.astype(np.int64)
    raw[np.isnan(r)] = _ERROR_CODE
    raw[r == np.inf] = _NO_RETURN_CODE
    return raw


# ---------------------------------------------------------------------------- host encoders


def _tag_suffix(tag: Optional[str]) -> bytes:
    if tag is None:
        return b''
    if not _TAG_RE.fullmatch(tag):
        raise EncodeError(f'tag {tag!r} must be up to 16 letters, digits, spaces or "._+@"')
    return b';' + tag.encode('ascii')


def _digits(value: int, width: int, low: int, high: int, what: str) -> bytes:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise EncodeError(f'{what} must be an integer; got {value!r}')
    if not low <= value <= high:
        raise EncodeError(f'{what}={value} is outside [{low}, {high}]')
    return b'%0*d' % (width, int(value))


def encode_command(command: str, tag: Optional[str] = None) -> bytes:
    """Encode a command without parameters (``VV PP II BM QT RS SCIP2.0``).

    Raises:
        EncodeError: For another command or an invalid tag.
    """
    if command not in _SIMPLE_COMMANDS:
        raise EncodeError(f'{command!r} is not one of {_SIMPLE_COMMANDS}')
    return command.encode('ascii') + _tag_suffix(tag) + b'\n'


def encode_scan_request(command: str, start_step: int, end_step: int, cluster: int = 1,
                        scan_interval: int = 0, num_scans: int = 0,
                        tag: Optional[str] = None) -> bytes:
    """Encode a scan request: ``MDssssEEEEccinn`` (also MS, ME) or ``GDssssEEEEcc`` (GS, GE).

    Args:
        command: One of :data:`SCAN_COMMANDS`.
        start_step: First step, 0..9999.
        end_step: Last step, start_step..9999.
        cluster: Steps merged into one value, 1..99.
        scan_interval: Continuous commands: scans skipped between outputs, 0..9.
        num_scans: Continuous commands: number of scans, 0..99 (0 = until ``QT``).
        tag: Optional tag echoed by the sensor.

    Raises:
        EncodeError: If an argument is out of range.
    """
    if command not in SCAN_COMMANDS:
        raise EncodeError(f'{command!r} is not a scan command {tuple(SCAN_COMMANDS)}')
    out = (command.encode('ascii') + _digits(start_step, 4, 0, 9999, 'start_step')
           + _digits(end_step, 4, int(start_step), 9999, 'end_step')
           + _digits(cluster, 2, 1, 99, 'cluster'))
    if command in _CONTINUOUS:
        out += _digits(scan_interval, 1, 0, 9, 'scan_interval')
        out += _digits(num_scans, 2, 0, 99, 'num_scans')
    return out + _tag_suffix(tag) + b'\n'


def encode_baud_request(baud: int, tag: Optional[str] = None) -> bytes:
    """Encode ``SSbbbbbb`` (RS-232 baud rate, applied after the ``00`` reply).

    Raises:
        EncodeError: If ``baud`` is not one of :data:`BAUD_RATES`.
    """
    if baud not in BAUD_RATES:
        raise EncodeError(f'baud {baud!r} is not one of {BAUD_RATES}')
    return b'SS%06d' % baud + _tag_suffix(tag) + b'\n'


def encode_time_request(mode: int, tag: Optional[str] = None) -> bytes:
    """Encode ``TM0`` (enter time-adjust mode), ``TM1`` (read time) or ``TM2`` (leave).

    Raises:
        EncodeError: If ``mode`` is not 0, 1 or 2.
    """
    return b'TM' + _digits(mode, 1, 0, 2, 'mode') + _tag_suffix(tag) + b'\n'


# ---------------------------------------------------------------------------- sensor encoders


def encode_line(payload: bytes) -> bytes:
    """Return ``payload`` + its checksum character + LF."""
    return bytes(payload) + bytes((checksum(payload), _LF))


def _echo_bytes(echo: Union[str, bytes]) -> bytes:
    e = echo.encode('ascii') if isinstance(echo, str) else bytes(echo)
    e = e.rstrip(b'\r\n')
    if not _ECHO_RE.fullmatch(e + b'\n'):
        raise EncodeError(f'{e!r} is not a valid SCIP 2.0 echo line')
    return e


def encode_reply(echo: Union[str, bytes], status: str, lines: Sequence[bytes] = ()) -> bytes:
    """Build a reply: echo, status line, ``lines`` (checksums appended), empty line.

    A 1-character status (``SCIP2.0`` answers a bare ``0``) is sent without checksum.

    Raises:
        EncodeError: If the echo or the status is invalid.
    """
    s = status.encode('ascii')
    if len(s) not in (1, 2) or b'\n' in s:
        raise EncodeError(f'status {status!r} must have 1 or 2 characters')
    out = [_echo_bytes(echo) + b'\n', s + b'\n' if len(s) == 1 else encode_line(s)]
    out.extend(encode_line(line) for line in lines)
    out.append(b'\n')
    return b''.join(out)


def encode_info_reply(command: str, fields: Sequence[Tuple[str, str]],
                      status: str = '00') -> bytes:
    """Build a ``VV``/``PP``/``II`` reply from ``(key, value)`` pairs.

    Raises:
        EncodeError: For another command.
    """
    if command not in _INFO_COMMANDS:
        raise EncodeError(f'{command!r} is not one of {_INFO_COMMANDS}')
    out = [command.encode('ascii') + b'\n', encode_line(status.encode('ascii'))]
    for key, value in fields:
        text = f'{key}:{value}'.encode('ascii')
        out.append(text + b';' + bytes((checksum(text), _LF)))
    out.append(b'\n')
    return b''.join(out)


def _data_lines(data: bytes) -> List[bytes]:
    return [data[i:i + BLOCK_CHARS] for i in range(0, len(data), BLOCK_CHARS)]


def _scan_geometry(params: bytes) -> Tuple[int, int, int]:
    start, end, cluster = int(params[0:4]), int(params[4:8]), int(params[8:10])
    cluster = max(cluster, 1)  # an echoed cluster count of 00 behaves as 1
    return start, end, cluster


def _value_count(start: int, end: int, cluster: int) -> int:
    return max(0, -(-(end - start + 1) // cluster))


def encode_scan_reply_raw(echo: Union[str, bytes], raw: Sequence[int], timestamp_ms: int,
                          intensities: Optional[Sequence[int]] = None,
                          status: Optional[str] = None) -> bytes:
    """Build a scan reply (sensor side) from raw values (mm or error codes).

    Args:
        echo: The echo line (with or without LF), e.g. ``b'GD0384038701'``; it fixes the
            command, the steps and the cluster count, hence the number of values.
        raw: One value per cluster, ``ceil((end - start + 1) / cluster)`` of them.
        timestamp_ms: Sensor time, taken modulo 2**24.
        intensities: ``ME``/``GE`` only: one intensity per value.
        status: Status; default ``'99'`` for ``MD``/``MS``/``ME``, ``'00'`` otherwise.

    Raises:
        EncodeError: If the echo is not a scan command, the count does not match or a value
            does not fit.
    """
    e = _echo_bytes(echo)
    command = e[:2].decode('ascii')
    if command not in SCAN_COMMANDS:
        raise EncodeError(f'echo {e!r} is not a scan command')
    start, end, cluster = _scan_geometry(e[2:])
    n = _value_count(start, end, cluster)
    values = np.asarray(raw, dtype=np.int64).ravel()
    if values.size != n:
        raise EncodeError(f'echo {e!r} needs {n} values; got {values.size}')
    width = SCAN_COMMANDS[command]
    if width == 6:
        if intensities is None:
            raise EncodeError(f'{command} needs intensities')
        inten = np.asarray(intensities, dtype=np.int64).ravel()
        if inten.size != n:
            raise EncodeError(f'{command} needs {n} intensities; got {inten.size}')
        data = encode_values(np.stack([values, inten], axis=1), 3)
    else:
        if intensities is not None:
            raise EncodeError(f'{command} carries no intensities')
        data = encode_values(values, width)
    if status is None:
        status = '99' if command in _CONTINUOUS else '00'
    time_line = encode_int(int(timestamp_ms) % (1 << 24), 4)
    return encode_reply(e, status, [time_line] + _data_lines(data))


def encode_scan_reply(echo: Union[str, bytes], ranges_m: Sequence[float], timestamp_ms: int,
                      intensities: Optional[Sequence[int]] = None,
                      status: Optional[str] = None) -> bytes:
    """Build a scan reply (sensor side) from ranges in metres.

    Ranges are rounded to mm; +inf is sent as code 0 and NaN as code 19, which decode back to
    +inf and NaN, so :func:`decode_reply` returns the input after mm quantisation.

    Raises:
        EncodeError: See :func:`ranges_to_raw` and :func:`encode_scan_reply_raw`.
    """
    e = _echo_bytes(echo)
    width = SCAN_COMMANDS.get(e[:2].decode('ascii'), 3)
    return encode_scan_reply_raw(e, ranges_to_raw(ranges_m, 3 if width == 6 else width),
                                 timestamp_ms, intensities, status)


# ---------------------------------------------------------------------------- reply parsing


def _ascii(data: bytes, what: str, offset: int) -> str:
    if any(c < 0x20 or c > 0x7E for c in data):
        raise FramingError(f'{what} {bytes(data)!r} at offset {offset} is not printable ASCII',
                           offset)
    return data.decode('ascii')


def _check_line(line: bytes, what: str, offset: int) -> bytes:
    """Return the payload of a line after verifying its checksum character."""
    if len(line) < 2:
        raise FramingError(f'{what} {bytes(line)!r} at offset {offset} has no checksum', offset)
    payload = line[:-1]
    expected = checksum(payload)
    if line[-1] != expected:
        raise ChecksumError(f'{what} at offset {offset}: checksum {chr(line[-1])!r} != '
                            f'expected {chr(expected)!r}', offset)
    return payload


def _parse_reply(m: 're.Match[bytes]', body: bytes, offset: int) -> Frame:
    """Parse one reply: ``m`` matched its echo line, ``body`` = lines up to the empty line."""
    text = m.group(1).decode('ascii')
    tag = (m.group(2) or b';')[1:].decode('ascii')
    command = text if text == 'SCIP2.0' else text[:2]
    params = '' if text == 'SCIP2.0' else text[2:]
    where = f'reply to {text} at offset {offset}'
    if not body:
        raise FramingError(f'{where}: no status line', offset)
    lines = body.split(b'\n')
    offsets = [offset + m.end() - m.start()]
    for line in lines[:-1]:
        offsets.append(offsets[-1] + len(line) + 1)
    status_line = lines[0]
    warnings = []
    if len(status_line) == 1:  # bare status: SCIP2.0 answers '0', SCIP 1.1 answers 'E'
        status = _ascii(status_line, 'status', offsets[0])
    elif len(status_line) == 3:
        status = _ascii(status_line[:2], 'status', offsets[0])
        try:
            _check_line(status_line, f'{where}: status line', offsets[0])
        except ChecksumError as err:
            if command not in _INFO_COMMANDS:
                raise
            warnings.append(str(err))
    else:
        raise FramingError(f'{where}: status line {bytes(status_line)!r} must have 1 or 3 '
                           'characters', offsets[0])
    data_lines, data_offsets = lines[1:], offsets[1:]

    if command in _INFO_COMMANDS and status == '00':
        return _parse_info(command, status, data_lines, data_offsets, warnings, tag, where)
    if command == 'TM' and params == '1' and status == '00':
        if len(data_lines) != 1 or len(data_lines[0]) != 5:
            raise FramingError(f'{where}: expected one time line of 4 characters + checksum',
                               offset)
        stamp = _check_line(data_lines[0], f'{where}: time line', data_offsets[0])
        return TimeReply(status, decode_int(stamp), tag)
    if command in SCAN_COMMANDS and status == ('99' if command in _CONTINUOUS else '00'):
        return _parse_scan(command, params, status, data_lines, data_offsets, tag, where)
    if data_lines:
        raise FramingError(f'{where}: status {status!r} with {len(data_lines)} unexpected '
                           'data line(s)', offset)
    return StatusReply(command, params, status, tag)


def _parse_info(command: str, status: str, lines: List[bytes], offsets: List[int],
                warnings: List[str], tag: str, where: str) -> InfoReply:
    fields = []
    for line, off in zip(lines, offsets):
        # "KEY:VALUE;C": the checksum C is the last byte and may itself be ';'
        text, sep, ck = line[:-2], line[-2:-1], line[-1:]
        if sep != b';':
            warnings.append(f'{where}: info line at offset {off} has no checksum')
            text = line
        elif ck[0] != checksum(text):
            warnings.append(f'{where}: info line at offset {off}: checksum {chr(ck[0])!r} != '
                            f'expected {chr(checksum(text))!r}')
        key, colon, value = _ascii(text, 'info line', off).partition(':')
        if not colon:
            raise FramingError(f'{where}: info line {bytes(line)!r} at offset {off} has no '
                               '":"', off)
        fields.append((key, value))
    return InfoReply(command, status, tuple(fields), tuple(warnings), tag)


def _parse_scan(command: str, params: str, status: str, lines: List[bytes],
                offsets: List[int], tag: str, where: str) -> ScanFrame:
    start, end, cluster = _scan_geometry(params.encode('ascii'))
    width = SCAN_COMMANDS[command]
    if not lines:
        raise TruncatedError(f'{where}: no timestamp line', offsets[0] if offsets else None)
    if len(lines[0]) != 5:
        raise FramingError(f'{where}: timestamp line at offset {offsets[0]} must have 4 '
                           'characters + checksum', offsets[0])
    timestamp = decode_int(_check_line(lines[0], f'{where}: timestamp line', offsets[0]))
    chunks = []
    for i, (line, off) in enumerate(zip(lines[1:], offsets[1:]), 1):
        if len(line) > BLOCK_CHARS + 1:
            raise FramingError(f'{where}: data line {i} at offset {off} has {len(line) - 1} '
                               f'characters (max {BLOCK_CHARS})', off)
        chunks.append(_check_line(line, f'{where}: data line {i}', off))
    data = b''.join(chunks)
    n = _value_count(start, end, cluster)
    # ceil((end - start + 1) / cluster) values (docs/protocols/scip2.md §5); a final partial
    # cluster dropped by some firmware (floor) is tolerated.
    n_floor = max(0, (end - start + 1) // cluster)
    if len(data) not in (n * width, n_floor * width):
        kind = TruncatedError if len(data) < n_floor * width else FramingError
        raise kind(f'{where}: {len(data)} data characters; expected {n * width}', offsets[0])
    try:
        values = decode_values(data, 3 if width == 6 else width)
    except FramingError as err:
        raise FramingError(f'{where}: {err}', offsets[0]) from err
    intensities = None
    if width == 6:
        values = values.reshape(-1, 2)
        intensities = values[:, 1].copy()
        intensities.setflags(write=False)
        values = values[:, 0].copy()
    ranges = ranges_from_raw(values)
    values.setflags(write=False)
    ranges.setflags(write=False)
    continuous = command in _CONTINUOUS
    return ScanFrame(command=command, status=status, timestamp_ms=timestamp,
                     ranges_m=ranges, raw=values, intensities=intensities,
                     start_step=start, end_step=end, cluster=cluster,
                     scan_interval=int(params[10]) if continuous else None,
                     remaining_scans=int(params[11:13]) if continuous else None, tag=tag)


def _reply_bound(m: 're.Match[bytes]') -> int:
    """Return the most bytes a well-formed reply starting with echo ``m`` can have."""
    text = m.group(1)
    base = m.end() - m.start() + 4 + 1 + 8  # echo, status line, empty line, slack
    command = text[:2].decode('ascii')
    if command in SCAN_COMMANDS:
        start, end, cluster = _scan_geometry(text[2:])
        chars = _value_count(start, end, cluster) * SCAN_COMMANDS[command]
        return base + 6 + chars + 2 * (-(-chars // BLOCK_CHARS))
    if command in _INFO_COMMANDS:
        return 4096
    return base + 6  # TM1 time line


def decode_reply(data: bytes) -> Frame:
    """Decode exactly one complete reply (echo line through the empty line).

    Raises:
        FramingError: If ``data`` does not start with a valid echo line, a line is malformed
            or bytes follow the empty line.
        TruncatedError: If the empty line (or required data) is missing.
        ChecksumError: If a status, timestamp or data line has a wrong checksum.
    """
    data = bytes(data)
    m = _ECHO_RE.match(data)
    if m is None:
        raise FramingError(f'no valid SCIP 2.0 echo line at the start of {data[:20]!r}', 0)
    t = data.find(b'\n\n', m.end() - 1)
    if t < 0:
        raise TruncatedError(f'reply to {m.group(1).decode()} has no terminating empty line',
                             0)
    if t + 2 != len(data):
        raise FramingError(f'{len(data) - t - 2} bytes follow the end of the reply at '
                           f'offset {t + 2}', t + 2)
    return _parse_reply(m, data[m.end():t], 0)


class Scip2Decoder(StreamDecoder):
    """Incremental decoder of the sensor -> host byte stream.

    :meth:`feed` returns the frames completed by the new bytes and, in stream order, the
    errors met on the way as :class:`ProtocolError` objects (not raised):

    * bytes before a valid echo line are skipped and reported once as a :class:`FramingError`
      when the next reply starts (the decoder resynchronises on the next valid echo line);
    * a reply with a bad checksum is reported as a :class:`ChecksumError` and skipped;
    * a reply cut short by the start of the next one is reported as a :class:`TruncatedError`
      and the next reply is decoded.

    The output does not depend on how the stream is cut into chunks. Offsets in the errors
    count bytes since the decoder was created.
    """

    unit = 'echo line'

    def __init__(self) -> None:
        """Create a decoder with an empty buffer."""
        super().__init__()

    def feed(self, data: bytes) -> List[Union[Frame, ProtocolError]]:
        """Add bytes; return the completed frames and the errors, in stream order."""
        buf = self._buf
        buf += data
        out: List[Union[Frame, ProtocolError]] = []
        pos = 0
        while True:
            m = _ECHO_RE.search(buf, pos)
            if m is None:
                # Keep what may be the start of an echo line: an echo cannot contain LF.
                keep = max(pos, len(buf) - _MAX_ECHO, buf.rfind(b'\n') + 1)
                self._skip(pos, keep)
                pos = keep
                break
            start = m.start()
            self._skip(pos, start)
            offset = self._base + start
            bound = m.start() + _reply_bound(m)
            t = buf.find(b'\n\n', m.end() - 1, bound)
            if t < 0:
                if len(buf) < bound:
                    pos = start
                    break  # wait for the rest of the reply
                nxt = _ECHO_RE.search(buf, start + 1, bound)
                self._report(out, TruncatedError(
                    f'reply to {m.group(1).decode()} at offset {offset} has no end within '
                    f'{bound - start} bytes', offset))
                pos = nxt.start() if nxt else start + 1
                self._quiet = nxt is None
                continue
            try:
                frame = _parse_reply(m, bytes(buf[m.end():t]), offset)
            except ProtocolError as err:
                # Resynchronise one byte after the failed echo: its tag may hide a real echo.
                nxt = _ECHO_RE.search(buf, start + 1, t + 1)
                if nxt is not None:
                    err = TruncatedError(
                        f'reply to {m.group(1).decode()} at offset {offset} cut short by the '
                        f'next reply at offset {self._base + nxt.start()} ({err})', offset)
                self._report(out, err)
                pos = nxt.start() if nxt else t + 2
                continue
            self._report(out, frame)
            pos = t + 2
        self._consume(pos)
        return out
