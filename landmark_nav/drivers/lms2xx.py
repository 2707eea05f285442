"""SICK LMS2xx binary telegrams (RS-232/422): builders, CRC, decoders, ``B0`` measured values.

Pure byte-level code following ``docs/protocols/lms2xx.md`` (§2-§6): bytes in, frames out; no
clock, no I/O. A telegram is ``STX 0x02 | ADR | LEN u16 LE | CMD | DATA | STATUS | CRC u16 LE``:
ADR is 0x00 from the host and 0x80 from the LMS, LEN counts CMD through STATUS (replies only carry
STATUS), the CRC covers STX through the last payload byte. A reply code is the request code + 0x80.
The LMS acknowledges a request with ACK 0x06 (NAK 0x15 on a CRC error).

``B0`` measured values: info word (bits 0-9 value count, 11-12 partial-scan index, 13 partial
scan, 14-15 units 00 cm / 01 mm / 10 = 10 cm), one u16 per value (distance in the low bits,
flags above them as the measuring mode defines, see :data:`MEASURING_MODES`), status byte.
Special distance values become REP 117 values: "above maximum range" -> +inf, the others NaN.

:class:`Lms2xxDecoder` decodes a byte stream incrementally; :func:`decode_telegram` and
:func:`parse_telegram` decode one telegram. :func:`encode_measured_values` and
:func:`encode_reply` build LMS telegrams for emulators and tests.
"""

from dataclasses import dataclass
import math
import struct
from typing import Dict, List, Mapping, Optional, Sequence, Tuple, Union

from landmark_nav.drivers.errors import (ChecksumError, EncodeError, FramingError,
                                         ProtocolError, TruncatedError)
from landmark_nav.drivers.stream import StreamDecoder
import numpy as np

__all__ = [
    'ACK', 'Ack', 'DEFAULT_MODE', 'HOST_ADDRESS', 'LMS_ADDRESS', 'Lms2xxDecoder', 'LmsStatus',
    'MAX_PAYLOAD', 'MEASURING_MODES', 'MeasuredValues', 'MeasuringMode', 'ModeSwitchReply',
    'NAK', 'Nak', 'SPECIAL_VALUES', 'STX', 'Telegram', 'TypeReply', 'UNITS', 'VariantReply',
    'config_measuring_mode', 'config_units', 'crc16', 'decode_measured_values',
    'decode_telegram', 'encode_measured_values', 'encode_reply', 'scan_angles',
    'encode_telegram', 'parse_telegram', 'request_baud', 'request_config',
    'request_continuous', 'request_installation_mode', 'request_reset', 'request_scan',
    'request_status', 'request_stop_continuous', 'request_type', 'request_variant',
    'request_write_config', 'with_config',
]

STX = 0x02
ACK = 0x06
NAK = 0x15
HOST_ADDRESS = 0x00  # ADR of host -> LMS telegrams
LMS_ADDRESS = 0x80  # ADR of LMS -> host telegrams
MAX_PAYLOAD = 812  # largest LEN the decoder accepts

# Units code of the B0 info word (bits 14-15) -> (name, units per metre). Distances are
# divided by the integer units per metre, so 1001 mm decodes to exactly the float 1.001.
UNITS: Dict[int, Tuple[str, int]] = {0: ('cm', 100), 1: ('mm', 1000), 2: ('10cm', 10)}
_UNIT_CODES = {name: (code, per_m) for code, (name, per_m) in UNITS.items()}

# Mode-switch (0x20) codes for the baud rates.
_BAUD_CODES = {38400: 0x40, 19200: 0x41, 9600: 0x42, 500000: 0x48}

# Variants accepted by request 0x3B: angle (deg) -> resolutions (1/100 deg).
_VARIANTS = {100: (25, 50, 100), 180: (50, 100)}


@dataclass(frozen=True)
class MeasuringMode:
    """Layout of a ``B0`` value word in one measuring mode.

    Attributes:
        code: Measuring-mode byte of the configuration block.
        range_bits: Low bits holding the distance (13: 8/80 m, 14: 16 m, 15: 32 m, 16:
            immediate).
        flags: ``(name, shift, width)`` of the flag fields above the distance bits.
    """

    code: int
    range_bits: int
    flags: Tuple[Tuple[str, int, int], ...] = ()


# Measuring modes (docs/protocols/lms2xx.md §4-§5): distance bits per range (13/14/15/16);
# the flag assignment and the mode codes as sicktoolbox implements SICK's telegram listing
# (SICK_MS_MODE_*).
MEASURING_MODES: Dict[str, MeasuringMode] = {
    '8_or_80_fa_fb_dazzle': MeasuringMode(0x00, 13, (('field_a', 13, 1), ('field_b', 14, 1),
                                                     ('dazzle', 15, 1))),
    '8_or_80_reflector': MeasuringMode(0x01, 13, (('reflector', 13, 3),)),
    '8_or_80_fa_fb_fc': MeasuringMode(0x02, 13, (('field_a', 13, 1), ('field_b', 14, 1),
                                                 ('field_c', 15, 1))),
    '16_reflector': MeasuringMode(0x03, 14, (('reflector', 14, 2),)),
    '16_fa_fb': MeasuringMode(0x04, 14, (('field_a', 14, 1), ('field_b', 15, 1))),
    '32_reflector': MeasuringMode(0x05, 15, (('reflector', 15, 1),)),
    '32_fa': MeasuringMode(0x06, 15, (('field_a', 15, 1),)),
    '32_immediate': MeasuringMode(0x0F, 16, ()),
}
DEFAULT_MODE = '8_or_80_fa_fb_dazzle'

# Special distance values, as offsets below the all-ones distance (13-bit: 0x1FFF ...), see
# docs/protocols/lms2xx.md §5: named for 13 bits, the same offsets below the mask are used for
# 14, 15 and 16 bits. The whole band [mask - 8, mask] is reserved: the codes without a name
# (mask - 3, - 6, - 7) are treated as errors too (our choice).
SPECIAL_VALUES: Dict[int, str] = {
    0: 'invalid', 1: 'dazzle', 2: 'overflow', 4: 'S/N too low', 5: 'read error',
    8: 'above maximum range',
}
_SPECIAL_BAND = 8  # mask - 8 .. mask are special
_ABOVE_MAX = 8  # -> +inf (no return); every other special value -> NaN


@dataclass(frozen=True)
class Telegram:
    """One telegram; ``status`` is the last payload byte of LMS replies, None for requests."""

    address: int
    command: int
    data: bytes
    status: Optional[int] = None


@dataclass(frozen=True)
class Ack:
    """ACK byte 0x06: the LMS accepted the last request."""


@dataclass(frozen=True)
class Nak:
    """NAK byte 0x15: the LMS received the last request with a bad CRC."""


@dataclass(frozen=True)
class LmsStatus:
    """The status byte of a reply, split into its fields."""

    raw: int

    @property
    def severity(self) -> int:
        """Bits 0-2: 0 OK ... 4 fatal."""
        return self.raw & 0x07

    @property
    def device_type(self) -> int:
        """Bits 3-4."""
        return (self.raw >> 3) & 0x03

    @property
    def restart(self) -> bool:
        """Bit 5."""
        return bool(self.raw & 0x20)

    @property
    def implausible(self) -> bool:
        """Bit 6: implausible measured value."""
        return bool(self.raw & 0x40)

    @property
    def pollution(self) -> bool:
        """Bit 7: front screen polluted."""
        return bool(self.raw & 0x80)


@dataclass(frozen=True, eq=False)
class MeasuredValues:
    """A decoded ``B0`` telegram (arrays read-only).

    At 180 deg value 0 is at -90 deg (ROS frame), at 100 deg at -50 deg; angles increase
    counter-clockwise by the resolution of the variant.
    """

    units: str  # 'cm', 'mm' or '10cm'
    unit_m: float  # metres per distance unit
    partial_scan: bool  # info bit 13
    partial_index: int  # info bits 11-12
    raw: np.ndarray  # (N,) uint16 distance bits (flags removed)
    ranges_m: np.ndarray  # (N,) float64, REP 117 (+inf above max range, NaN errors)
    flags: Mapping[str, np.ndarray]  # name -> (N,) uint8, per the measuring mode
    status: int
    mode: str = DEFAULT_MODE

    @property
    def count(self) -> int:
        """Number of values."""
        return int(self.raw.size)

    @property
    def lms_status(self) -> LmsStatus:
        """Status byte split into its fields."""
        return LmsStatus(self.status)


@dataclass(frozen=True)
class ModeSwitchReply:
    """``A0`` reply to a mode switch: result 0 OK, 1 wrong password, 2 fault."""

    result: int
    status: int

    @property
    def ok(self) -> bool:
        """True when the LMS switched."""
        return self.result == 0


@dataclass(frozen=True)
class VariantReply:
    """``BB`` reply to a variant request (angle in deg, resolution in 1/100 deg)."""

    accepted: bool
    angle_deg: int
    resolution_cdeg: int
    status: int


@dataclass(frozen=True)
class TypeReply:
    """``BA`` reply: the type string (e.g. ``'LMS200;30106'``)."""

    text: str
    status: int


Frame = Union[Telegram, Ack, Nak, MeasuredValues, ModeSwitchReply, VariantReply, TypeReply]


def scan_angles(count: int, angle_deg: int = 180, resolution_cdeg: int = 50) -> np.ndarray:
    """Return the angles (rad, ROS frame, CCW) of ``count`` values of a variant.

    Value 0 is at -angle/2 (-90 deg at 180 deg, -50 deg at 100 deg); angles increase by the
    resolution (1/100 deg).
    """
    start = -math.radians(angle_deg / 2.0)
    return start + np.arange(count) * math.radians(resolution_cdeg / 100.0)


# ---------------------------------------------------------------------------- CRC


def crc16(data: bytes) -> int:
    """Return SICK's CRC16 of ``data`` (docs/protocols/lms2xx.md §3).

    register = 0, prev = 0; per byte b: if bit 15 is set, clear it, shift left and XOR 0x8005,
    else shift left (16 bits); then XOR ``prev << 8 | b``; prev = b. ASCII ``123456789`` gives
    0xA656.
    """
    reg = 0
    prev = 0
    for b in data:
        if reg & 0x8000:
            reg = ((reg & 0x7FFF) << 1) ^ 0x8005
        else:
            reg = (reg << 1) & 0xFFFF
        reg ^= (prev << 8) | b
        prev = b
    return reg


# ---------------------------------------------------------------------------- encoders


def encode_telegram(command: int, data: bytes = b'', address: int = HOST_ADDRESS,
                    status: Optional[int] = None) -> bytes:
    """Build a telegram: STX, ADR, LEN, CMD, DATA, [STATUS], CRC.

    Raises:
        EncodeError: If a byte is out of range or the payload exceeds :data:`MAX_PAYLOAD`.
    """
    for name, value in (('command', command), ('address', address)):
        if not 0 <= value <= 0xFF:
            raise EncodeError(f'{name}=0x{value:X} is not a byte')
    payload = bytes((command,)) + bytes(data)
    if status is not None:
        if not 0 <= status <= 0xFF:
            raise EncodeError(f'status={status} is not a byte')
        payload += bytes((status,))
    if len(payload) > MAX_PAYLOAD:
        raise EncodeError(f'payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}')
    head = struct.pack('<BBH', STX, address, len(payload)) + payload
    return head + struct.pack('<H', crc16(head))


def encode_reply(command: int, data: bytes = b'', status: int = 0x10) -> bytes:
    """Build an LMS -> host telegram (ADR 0x80) with a status byte (emulator side)."""
    return encode_telegram(command, data, LMS_ADDRESS, status)


def request_installation_mode(password: str = 'SICK_LMS') -> bytes:
    """Return ``20 00`` + password: switch to installation mode (needed to write config).

    Raises:
        EncodeError: If the password is not 8 ASCII characters.
    """
    if len(password) != 8 or not password.isascii():
        raise EncodeError(f'password {password!r} must be 8 ASCII characters')
    return encode_telegram(0x20, b'\x00' + password.encode('ascii'))


def request_continuous() -> bytes:
    """Return ``20 24``: continuous output of all values (``B0`` stream)."""
    return encode_telegram(0x20, b'\x24')


def request_stop_continuous() -> bytes:
    """Return ``20 25``: output on request only (stops the ``B0`` stream)."""
    return encode_telegram(0x20, b'\x25')


def request_baud(baud: int) -> bytes:
    """Return ``20 40/41/42/48``: switch to 38400/19200/9600/500k baud (after the ``A0``).

    Raises:
        EncodeError: For another baud rate.
    """
    if baud not in _BAUD_CODES:
        raise EncodeError(f'baud {baud!r} is not one of {tuple(_BAUD_CODES)}')
    return encode_telegram(0x20, bytes((_BAUD_CODES[baud],)))


def request_scan() -> bytes:
    """Return ``30 01``: one scan of all values."""
    return encode_telegram(0x30, b'\x01')


def request_variant(angle_deg: int, resolution_cdeg: int) -> bytes:
    """Return ``3B``: scanning angle 100/180 deg, resolution 25/50/100 (1/100 deg).

    Raises:
        EncodeError: For another combination (180 deg at 0.25 deg is not allowed).
    """
    if resolution_cdeg not in _VARIANTS.get(angle_deg, ()):
        raise EncodeError(f'variant {angle_deg} deg / {resolution_cdeg / 100} deg is not '
                          'supported')
    return encode_telegram(0x3B, struct.pack('<HH', angle_deg, resolution_cdeg))


def request_status() -> bytes:
    """Return ``31``: status request (``B1`` reply)."""
    return encode_telegram(0x31)


def request_type() -> bytes:
    """Return ``3A``: type request (``BA`` reply)."""
    return encode_telegram(0x3A)


def request_config() -> bytes:
    """Return ``74``: read the configuration block (``F4`` reply)."""
    return encode_telegram(0x74)


def request_write_config(block: bytes) -> bytes:
    """Return ``77`` + block: write the configuration block (installation mode; ``F7``)."""
    return encode_telegram(0x77, bytes(block))


def request_reset() -> bytes:
    """Return ``10``: reset (``91`` reply, then the power-on ``90`` after up to 65 s)."""
    return encode_telegram(0x10)


def config_units(block: bytes) -> str:
    """Return the units of a configuration block (byte 6: 0 cm, 1 mm, 2 = 10 cm).

    Raises:
        FramingError: If the block is too short or the code unknown.
    """
    if len(block) < 7 or block[6] not in UNITS:
        raise FramingError(f'configuration block of {len(block)} bytes has no valid units '
                           'byte at index 6')
    return UNITS[block[6]][0]


def config_measuring_mode(block: bytes) -> str:
    """Return the measuring mode of a configuration block (byte 5, docs/protocols/lms2xx.md §4).

    Raises:
        FramingError: If the block is too short or the code unknown.
    """
    if len(block) >= 6:
        for name, mode in MEASURING_MODES.items():
            if mode.code == block[5]:
                return name
    raise FramingError(f'configuration block of {len(block)} bytes has no known measuring '
                       'mode at index 5')


def with_config(block: bytes, units: Optional[str] = None,
                measuring_mode: Optional[str] = None) -> bytes:
    """Return a copy of a configuration block (from ``F4``) with units and/or mode replaced.

    Byte 6 holds the units, byte 5 the measuring mode (docs/protocols/lms2xx.md §4).

    Raises:
        EncodeError: For unknown units or modes, or a block shorter than 7 bytes.
    """
    out = bytearray(block)
    if len(out) < 7:
        raise EncodeError(f'configuration block of {len(out)} bytes is too short')
    if units is not None:
        if units not in _UNIT_CODES:
            raise EncodeError(f'units {units!r} not in {tuple(_UNIT_CODES)}')
        out[6] = _UNIT_CODES[units][0]
    if measuring_mode is not None:
        if measuring_mode not in MEASURING_MODES:
            raise EncodeError(f'measuring mode {measuring_mode!r} unknown')
        out[5] = MEASURING_MODES[measuring_mode].code
    return bytes(out)


def encode_measured_values(ranges_m: Sequence[float], units: str = 'mm',
                           mode: str = DEFAULT_MODE, status: int = 0x10,
                           flags: Optional[Mapping[str, Sequence[int]]] = None,
                           partial_index: int = 0, partial_scan: bool = False) -> bytes:
    """Build a ``B0`` telegram (LMS side) from ranges in metres.

    Ranges are rounded to the unit; +inf is sent as "above maximum range" and NaN as
    "invalid", which decode back to +inf and NaN, so the decoder returns the input after
    quantisation.

    Args:
        ranges_m: One range per value (at most 1023, and 404 to fit a telegram).
        units: ``'cm'``, ``'mm'`` or ``'10cm'``.
        mode: Key of :data:`MEASURING_MODES`: the distance bits and the flag fields.
        status: Status byte.
        flags: Flag name of the mode -> one value per range.
        partial_index: Info bits 11-12 (0..3).
        partial_scan: Info bit 13.

    Raises:
        EncodeError: For -inf (no "too close" value), ranges beyond the distance bits,
            unknown units, modes or flags, or too many values.
    """
    if units not in _UNIT_CODES:
        raise EncodeError(f'units {units!r} not in {tuple(_UNIT_CODES)}')
    if mode not in MEASURING_MODES:
        raise EncodeError(f'measuring mode {mode!r} unknown')
    if not 0 <= partial_index <= 3:
        raise EncodeError(f'partial_index={partial_index} is outside [0, 3]')
    code, per_m = _UNIT_CODES[units]
    spec = MEASURING_MODES[mode]
    mask = (1 << spec.range_bits) - 1
    r = np.asarray(ranges_m, dtype=np.float64).ravel()
    if r.size > 0x3FF:
        raise EncodeError(f'{r.size} values exceed the 10-bit count')
    finite = np.isfinite(r)
    with np.errstate(invalid='ignore', over='ignore'):
        q = np.round(r[finite] * per_m)
    if q.size and (q.min() < 0 or q.max() >= mask - _SPECIAL_BAND):
        idx = np.flatnonzero(finite)[int(np.flatnonzero((q < 0) | (q >= mask - 8))[0])]
        raise EncodeError(f'range {r[idx]!r} m at index {idx} is outside [0, '
                          f'{(mask - _SPECIAL_BAND - 1) / per_m}] m')
    if np.any(r == -np.inf):
        raise EncodeError(f'range -inf at index {int(np.flatnonzero(r == -np.inf)[0])}: the '
                          'LMS has no "too close" value')
    words = np.empty(r.shape, dtype=np.uint32)
    words[finite] = q.astype(np.uint32)
    words[np.isnan(r)] = mask
    words[r == np.inf] = mask - _ABOVE_MAX
    known = {name: (shift, width) for name, shift, width in spec.flags}
    for name, values in (flags or {}).items():
        if name not in known:
            raise EncodeError(f'flag {name!r} does not exist in mode {mode!r}')
        shift, width = known[name]
        v = np.asarray(values, dtype=np.int64).ravel()
        if v.shape != r.shape or (v.size and (v.min() < 0 or v.max() >= 1 << width)):
            raise EncodeError(f'flag {name!r} needs {r.size} values in [0, {(1 << width) - 1}]')
        words |= (v.astype(np.uint32) << shift)
    info = r.size | (partial_index << 11) | (int(bool(partial_scan)) << 13) | (code << 14)
    data = struct.pack('<H', info) + words.astype('<u2').tobytes()
    return encode_reply(0xB0, data, status)


# ---------------------------------------------------------------------------- decoders


def decode_measured_values(data: bytes, status: int,
                           mode: str = DEFAULT_MODE) -> MeasuredValues:
    """Decode the data of a ``B0`` telegram (info word and values, without CMD and STATUS).

    Raises:
        TruncatedError: If the data is shorter than the info word or the declared count.
        FramingError: For extra bytes, reserved units or an unknown mode.
    """
    if mode not in MEASURING_MODES:
        raise FramingError(f'measuring mode {mode!r} unknown')
    if len(data) < 2:
        raise TruncatedError(f'B0 data of {len(data)} bytes has no info word')
    info = data[0] | (data[1] << 8)
    n = info & 0x3FF
    if len(data) != 2 + 2 * n:
        kind = TruncatedError if len(data) < 2 + 2 * n else FramingError
        raise kind(f'B0 info word declares {n} values ({2 + 2 * n} bytes); got {len(data)} '
                   'bytes')
    unit_code = info >> 14
    if unit_code not in UNITS:
        raise FramingError(f'B0 info word 0x{info:04X} has reserved units code {unit_code}')
    units, per_m = UNITS[unit_code]
    spec = MEASURING_MODES[mode]
    words = np.frombuffer(data, dtype='<u2', count=n, offset=2)
    mask = (1 << spec.range_bits) - 1
    raw = (words & mask).astype(np.uint16)
    ranges = raw / float(per_m)
    special = raw >= mask - _SPECIAL_BAND
    if special.any():
        ranges[special] = math.nan
        ranges[raw == mask - _ABOVE_MAX] = math.inf
    flags = {}
    for name, shift, width in spec.flags:
        f = ((words >> shift) & ((1 << width) - 1)).astype(np.uint8)
        f.setflags(write=False)
        flags[name] = f
    raw.setflags(write=False)
    ranges.setflags(write=False)
    return MeasuredValues(units=units, unit_m=1.0 / per_m, partial_scan=bool(info & 0x2000),
                          partial_index=(info >> 11) & 0x3, raw=raw, ranges_m=ranges,
                          flags=flags, status=status, mode=mode)


def _min_len(address: int) -> int:
    return 2 if address & 0x80 else 1  # replies carry CMD and STATUS


def decode_telegram(raw: bytes, address: Optional[int] = None) -> Telegram:
    """Decode exactly one telegram (STX through CRC).

    Args:
        raw: The telegram bytes.
        address: Expected ADR (None: any); replies (ADR bit 7 set) carry a status byte.

    Raises:
        FramingError: For a bad STX, ADR or LEN, or bytes after the CRC.
        TruncatedError: If the bytes end before LEN + CRC.
        ChecksumError: If the CRC does not match.
    """
    raw = bytes(raw)
    if len(raw) < 4:
        raise TruncatedError(f'telegram of {len(raw)} bytes has no complete header', 0)
    stx, adr, length = struct.unpack_from('<BBH', raw)
    if stx != STX:
        raise FramingError(f'telegram starts with 0x{stx:02X}, not STX 0x02', 0)
    if address is not None and adr != address:
        raise FramingError(f'telegram address 0x{adr:02X} != expected 0x{address:02X}', 1)
    if not _min_len(adr) <= length <= MAX_PAYLOAD:
        raise FramingError(f'telegram LEN {length} outside [{_min_len(adr)}, {MAX_PAYLOAD}]', 2)
    total = 4 + length + 2
    if len(raw) < total:
        raise TruncatedError(f'telegram needs {total} bytes (LEN {length}); got {len(raw)}', 0)
    if len(raw) > total:
        raise FramingError(f'{len(raw) - total} bytes follow the CRC at offset {total}', total)
    return _telegram(raw, 0, length, adr, 0)


def _telegram(buf: bytes, pos: int, length: int, adr: int, offset: int) -> Telegram:
    """Check the CRC of the telegram at ``buf[pos:]`` (stream offset ``offset``) and split it."""
    end = pos + 4 + length
    got = buf[end] | (buf[end + 1] << 8)
    expected = crc16(buf[pos:end])
    if got != expected:
        raise ChecksumError(f'telegram 0x{buf[pos + 4]:02X} at offset {offset}: CRC '
                            f'0x{got:04X} != computed 0x{expected:04X}', offset)
    if adr & 0x80:
        return Telegram(adr, buf[pos + 4], bytes(buf[pos + 5:end - 1]), buf[end - 1])
    return Telegram(adr, buf[pos + 4], bytes(buf[pos + 5:end]))


def parse_telegram(telegram: Telegram, mode: str = DEFAULT_MODE) -> Frame:
    """Interpret a reply: ``B0``, ``A0``, ``BB``, ``BA``; other telegrams are returned as is.

    Raises:
        TruncatedError: If the data is too short for the reply.
        FramingError: If the data does not fit the reply's layout.
    """
    cmd, data, status = telegram.command, telegram.data, telegram.status
    if status is None:
        return telegram
    if cmd == 0xB0:
        return decode_measured_values(data, status, mode)
    if cmd == 0xA0:
        if len(data) != 1:
            raise FramingError(f'A0 reply has {len(data)} data bytes; expected 1')
        return ModeSwitchReply(data[0], status)
    if cmd == 0xBB:
        if len(data) != 5:
            raise FramingError(f'BB reply has {len(data)} data bytes; expected 5')
        ok, angle, resolution = struct.unpack('<BHH', data)
        return VariantReply(bool(ok), angle, resolution, status)
    if cmd == 0xBA:
        text = data.split(b'\x00', 1)[0]
        if any(c < 0x20 or c > 0x7E for c in text):
            raise FramingError(f'BA reply type string {text!r} is not printable ASCII')
        return TypeReply(text.decode('ascii'), status)
    return telegram


class Lms2xxDecoder(StreamDecoder):
    """Incremental decoder of an LMS2xx byte stream.

    :meth:`feed` returns, in stream order, :class:`Ack`/:class:`Nak` events, parsed replies (see
    :func:`parse_telegram`) and the errors met as :class:`ProtocolError` objects (not raised).
    Resynchronisation (docs/protocols/lms2xx.md §7): hunt for STX + ADR, reject LEN > 812, check
    the CRC, and after a failure restart one byte after that STX. A telegram with a bad CRC is
    reported as a :class:`ChecksumError`, or as a :class:`TruncatedError` when another telegram
    header lies inside it. Skipped bytes are reported once, as a :class:`FramingError`, before the
    next valid telegram. ACK/NAK bytes are recognised only between frames (at the start of the
    stream or right after a frame), never while hunting for STX, since 0x06 and 0x15 are common in
    measured values.

    The output does not depend on how the stream is cut into chunks.
    """

    unit = 'telegram'

    def __init__(self, mode: str = DEFAULT_MODE, address: int = LMS_ADDRESS,
                 parse: bool = True) -> None:
        """Create a decoder.

        Args:
            mode: Measuring mode for ``B0`` telegrams (key of :data:`MEASURING_MODES`).
            address: ADR of the telegrams to decode (0x80: LMS replies; 0x00 for an emulator
                decoding host requests).
            parse: Return parsed replies (True) or plain :class:`Telegram` objects.

        Raises:
            ValueError: For an unknown mode or an address that is not a byte.
        """
        if mode not in MEASURING_MODES:
            raise ValueError(f'measuring mode {mode!r} unknown')
        if not 0 <= address <= 0xFF:
            raise ValueError(f'address {address} is not a byte')
        super().__init__()
        self.mode = mode
        self.address = address
        self.parse = parse
        self._min_len = _min_len(address)
        self._synced = True

    def reset(self) -> None:
        """Drop buffered bytes (e.g. after a reconnect); offsets keep counting."""
        super().reset()
        self._synced = True

    def _skip(self, pos: int, end: int) -> None:
        if end > pos:
            self._synced = False
        super()._skip(pos, end)

    def _header_ok(self, buf: bytearray, q: int) -> bool:
        return (buf[q] == STX and buf[q + 1] == self.address
                and self._min_len <= (buf[q + 2] | buf[q + 3] << 8) <= MAX_PAYLOAD)

    def feed(self, data: bytes) -> List[Union[Frame, ProtocolError]]:
        """Add bytes; return the completed frames and the errors, in stream order."""
        buf = self._buf
        buf += data
        out: List[Union[Frame, ProtocolError]] = []
        pos = 0
        n = len(buf)
        while pos < n:
            b = buf[pos]
            if self._synced and b in (ACK, NAK):
                self._report(out, Ack() if b == ACK else Nak())
                pos += 1
                continue
            if b != STX:
                nxt = buf.find(STX, pos)
                self._skip(pos, n if nxt < 0 else nxt)
                pos = n if nxt < 0 else nxt
                continue
            if n - pos < 4:
                break  # wait for the header
            if not self._header_ok(buf, pos):
                self._skip(pos, pos + 1)
                pos += 1
                continue
            length = buf[pos + 2] | (buf[pos + 3] << 8)
            total = 4 + length + 2
            if n - pos < total:
                break  # wait for the rest
            offset = self._base + pos
            try:
                telegram = _telegram(buf, pos, length, self.address, offset)
            except ChecksumError as err:
                inner = next((q for q in range(pos + 1, pos + total - 3)
                              if buf[q] == STX and self._header_ok(buf, q)), None)
                if inner is not None:
                    err = TruncatedError(
                        f'telegram 0x{buf[pos + 4]:02X} at offset {offset} fails its CRC and '
                        f'holds a telegram header at offset {self._base + inner}: truncated',
                        offset)
                self._report(out, err)
                self._synced = False
                self._quiet = True
                self._skip(pos, pos + 1)
                pos += 1
                continue
            try:
                item = parse_telegram(telegram, self.mode) if self.parse else telegram
            except ProtocolError as err:
                item = type(err)(f'telegram 0x{telegram.command:02X} at offset {offset}: '
                                 f'{err}', offset)
            self._report(out, item)
            self._synced = True
            pos += total
        self._consume(pos)
        return out
