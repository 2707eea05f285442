"""Pioneer P2OS (Pioneer 2-DX): packets, commands, SYNC replies, status packets (SIPs).

Pure byte-level code following ``docs/protocols/p2os.md`` (§2-§6): bytes in, frames out; no clock,
no I/O. A packet is ``0xFA 0xFB | count N | data (N - 2 bytes) | checksum (2 bytes, high byte
first)``, N <= 200. The checksum sums the data as big-endian 16-bit words (16 bits kept); an odd
last byte is XORed into the low byte. Multi-byte data fields are little-endian.

Commands are a command byte, optionally followed by an argument: 0x3B + positive int16,
0x1B + magnitude of a negative int16, or 0x2B + string. Status packets (type 0x32 stopped,
0x33 moving) are decoded into :class:`StatusPacket` holding the raw integers, so that
:func:`encode_status` / :func:`parse_sip` round-trip exactly; conversions to SI units use
:class:`RobotParams` (Pioneer 2-DX defaults from ARIA's ``p2dx.p``). Odometry counters wrap:
:class:`OdometryUnwrapper` turns successive raw positions into continuous ones.

:class:`P2osDecoder` decodes a byte stream incrementally (robot packets by default, host
commands with ``parse=parse_command`` for an emulator).
"""

from dataclasses import dataclass
import math
import struct
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

from landmark_nav.drivers.errors import (ChecksumError, EncodeError, FramingError,
                                         ProtocolError, TruncatedError)
from landmark_nav.drivers.stream import StreamDecoder
from landmark_nav.hardware import P2DX_SONAR_MM_DEG

__all__ = [
    'ARGINT', 'ARGNINT', 'ARGSTR', 'COMMANDS', 'Command', 'HEADER', 'MAX_COUNT',
    'ODOMETRY_MODULUS', 'OdometryUnwrapper', 'P2DX', 'P2DX_SONAR_POSES', 'P2osDecoder',
    'P3DX', 'P3DX_SH', 'Packet', 'ROBOT_MODELS', 'RobotParams', 'STATUS_MOVING',
    'STATUS_STOPPED', 'StatusPacket', 'SyncReply',
    'checksum', 'decode_packet', 'decode_status', 'encode_command', 'encode_packet',
    'encode_status', 'encode_sync_reply', 'encode_vel2', 'parse_command', 'parse_sip',
    'status_from_state', 'vel2_split',
]

HEADER = b'\xFA\xFB'
MAX_COUNT = 200  # largest count byte (data + checksum)
ARGINT = 0x3B  # positive int16 follows (LE)
ARGNINT = 0x1B  # magnitude of a negative int16 follows (LE)
ARGSTR = 0x2B  # string follows
STATUS_STOPPED = 0x32
STATUS_MOVING = 0x33
ODOMETRY_MODULUS = 4096  # wrap rule of docs/protocols/p2os.md §5 (12- and 15-bit firmware)

# Command name -> (code, argument: None, 'int' or 'str'). SYNC0..2 share codes 0..2 with
# PULSE, OPEN and CLOSE; they are told apart by when they are sent.
COMMANDS: Dict[str, Tuple[int, Optional[str]]] = {
    'SYNC0': (0, None), 'SYNC1': (1, None), 'SYNC2': (2, None),
    'PULSE': (0, None), 'OPEN': (1, None), 'CLOSE': (2, None), 'POLLING': (3, 'str'),
    'ENABLE': (4, 'int'), 'SETA': (5, 'int'), 'SETV': (6, 'int'), 'SETO': (7, None),
    'MOVE': (8, 'int'), 'ROTATE': (9, 'int'), 'SETRV': (10, 'int'), 'VEL': (11, 'int'),
    'HEAD': (12, 'int'), 'DHEAD': (13, 'int'), 'SAY': (15, 'str'), 'CONFIG': (18, 'int'),
    'ENCODER': (19, 'int'), 'RVEL': (21, 'int'), 'DCHEAD': (22, 'int'), 'SETRA': (23, 'int'),
    'SONAR': (28, 'int'), 'STOP': (29, None), 'DIGOUT': (30, 'int'), 'VEL2': (32, 'int'),
    'GRIPPER': (33, 'int'), 'BUMPSTALL': (44, 'int'), 'JOYDRIVE': (47, 'int'),
    'HOSTBAUD': (50, 'int'), 'E_STOP': (55, None),
}
_NAMES = {}
for _name, (_code, _kind) in COMMANDS.items():
    _NAMES.setdefault(_code, _name)
_NAMES.update({0: 'PULSE', 1: 'OPEN', 2: 'CLOSE'})

# Pioneer 2-DX sonar poses (x mm, y mm, heading deg) relative to the centre of rotation.
P2DX_SONAR_POSES: Tuple[Tuple[float, float, float], ...] = P2DX_SONAR_MM_DEG


@dataclass(frozen=True)
class RobotParams:
    """Robot parameters for unit conversions (defaults: Pioneer 2-DX, ARIA ``p2dx.p``)."""

    angle_conv_factor: float = 0.001534  # rad per THPOS unit
    dist_conv_factor: float = 0.84  # mm per XPOS/YPOS unit
    vel_conv_factor: float = 1.0  # mm/s per LVEL/RVEL unit
    range_conv_factor: float = 0.268  # mm per sonar RANGE unit
    diff_conv_factor: float = 0.0056  # (right - left) mm/s -> rad/s (wheel base ~357 mm)
    vel2_divisor: float = 20.0  # mm/s per VEL2 unit
    max_velocity_mm_s: float = 2200.0
    max_rot_velocity_deg_s: float = 500.0
    robot_radius_mm: float = 250.0
    sonar_poses: Tuple[Tuple[float, float, float], ...] = P2DX_SONAR_POSES


P2DX = RobotParams()
# ARIA p3dx.p / p3dx-sh.p: the same drive and heading units; a P3-DX reports positions in
# 0.485 mm units, a P3-DX with an SH controller (AROS) in millimetres; both report sonar
# ranges in millimetres. The sonar poses of P2DX are kept (ARIA's tables differ slightly).
P3DX = RobotParams(dist_conv_factor=0.485, range_conv_factor=1.0)
P3DX_SH = RobotParams(dist_conv_factor=1.0, range_conv_factor=1.0)
#: Robot subclass (the third SYNC2 string, lower case) -> parameters.
ROBOT_MODELS: Dict[str, RobotParams] = {'p2dx': P2DX, 'p3dx': P3DX, 'p3dx-sh': P3DX_SH}


# ---------------------------------------------------------------------------- packets


def checksum(data: bytes) -> int:
    """Return the P2OS checksum: big-endian word sum (16 bits), odd last byte XORed in."""
    n = len(data)
    words = struct.unpack_from(f'>{n // 2}H', data)
    c = sum(words) & 0xFFFF
    if n & 1:
        c ^= data[-1]
    return c


def encode_packet(data: bytes) -> bytes:
    """Wrap data in a packet: header, count, data, checksum (high byte first).

    Raises:
        EncodeError: If the data is empty or longer than 198 bytes.
    """
    data = bytes(data)
    if not 1 <= len(data) <= MAX_COUNT - 2:
        raise EncodeError(f'packet data of {len(data)} bytes outside [1, {MAX_COUNT - 2}]')
    return HEADER + bytes((len(data) + 2,)) + data + struct.pack('>H', checksum(data))


def decode_packet(raw: bytes) -> bytes:
    """Return the data of exactly one packet after checking header, count and checksum.

    Raises:
        FramingError: For a bad header or count, or bytes after the checksum.
        TruncatedError: If the bytes end before the count says.
        ChecksumError: If the checksum does not match.
    """
    raw = bytes(raw)
    if len(raw) < 3:
        raise TruncatedError(f'packet of {len(raw)} bytes has no complete header', 0)
    if raw[:2] != HEADER:
        raise FramingError(f'packet starts with {raw[:2].hex(" ")}, not fa fb', 0)
    count = raw[2]
    if not 3 <= count <= MAX_COUNT:
        raise FramingError(f'packet count {count} outside [3, {MAX_COUNT}]', 2)
    if len(raw) < 3 + count:
        raise TruncatedError(f'packet needs {3 + count} bytes (count {count}); got {len(raw)}',
                             0)
    if len(raw) > 3 + count:
        raise FramingError(f'{len(raw) - 3 - count} bytes follow the checksum at offset '
                           f'{3 + count}', 3 + count)
    return _checked_data(raw, 0, count, 0)


def _checked_data(buf: bytes, pos: int, count: int, offset: int) -> bytes:
    end = pos + 1 + count  # index of the checksum's high byte
    data = bytes(buf[pos + 3:end])
    got = (buf[end] << 8) | buf[end + 1]
    expected = checksum(data)
    if got != expected:
        raise ChecksumError(f'packet 0x{data[0]:02X} at offset {offset}: checksum 0x{got:04X} '
                            f'!= computed 0x{expected:04X}', offset)
    return data


# ---------------------------------------------------------------------------- commands


@dataclass(frozen=True)
class Command:
    """A decoded host command (emulator side)."""

    code: int
    name: str
    arg_type: Optional[int] = None  # ARGINT, ARGNINT, ARGSTR or None
    value: Optional[int] = None  # signed value of an int argument
    text: Optional[bytes] = None  # string argument


def _int_arg(value: int) -> bytes:
    if isinstance(value, bool) or not isinstance(value, int):
        raise EncodeError(f'integer argument expected; got {value!r}')
    if not -32768 <= value <= 32767:
        raise EncodeError(f'argument {value} does not fit int16')
    if value >= 0:
        return struct.pack('<BH', ARGINT, value)
    return struct.pack('<BH', ARGNINT, -value)


def _str_arg(text: Union[str, bytes], string_format: str) -> bytes:
    s = text.encode('ascii') if isinstance(text, str) else bytes(text)
    if string_format == 'length':
        if len(s) > MAX_COUNT - 5:
            raise EncodeError(f'string of {len(s)} bytes is too long')
        return bytes((ARGSTR, len(s))) + s
    if string_format == 'nul':
        if b'\x00' in s or len(s) > MAX_COUNT - 5:
            raise EncodeError('NUL-terminated string must not contain NUL or exceed 195 bytes')
        return bytes((ARGSTR,)) + s + b'\x00'
    raise EncodeError(f'string_format {string_format!r} must be "length" or "nul"')


def encode_command(command: Union[str, int], argument: Union[None, int, str, bytes] = None,
                   string_format: str = 'length') -> bytes:
    """Encode a command packet.

    Args:
        command: Name from :data:`COMMANDS` or a raw command byte.
        argument: None, an int16 (sent as ARGINT value or ARGNINT magnitude) or a string.
        string_format: ``'length'`` (length byte first, as ARIA sends it) or ``'nul'``
            (NUL-terminated, as the operations manual describes); docs/protocols/p2os.md
            §4.

    Raises:
        EncodeError: For an unknown command, a missing or wrong argument, or a value out of
            range.
    """
    if isinstance(command, str):
        if command not in COMMANDS:
            raise EncodeError(f'unknown P2OS command {command!r}')
        code, kind = COMMANDS[command]
        if kind is None and argument is not None:
            raise EncodeError(f'{command} takes no argument')
        if kind is not None and argument is None:
            raise EncodeError(f'{command} needs an argument')
        if kind == 'int' and not isinstance(argument, int):
            raise EncodeError(f'{command} needs an integer argument; got {argument!r}')
        if kind == 'str' and not isinstance(argument, (str, bytes)):
            raise EncodeError(f'{command} needs a string argument; got {argument!r}')
    else:
        code = command
        if not 0 <= code <= 0xFF:
            raise EncodeError(f'command byte {code} out of range')
    data = bytes((code,))
    if isinstance(argument, (str, bytes)):
        data += _str_arg(argument, string_format)
    elif argument is not None:
        data += _int_arg(argument)
    return encode_packet(data)


def encode_vel2(left: int, right: int) -> bytes:
    """Encode VEL2 (32): wheel velocities in units of Vel2Divisor (signed bytes).

    The argument word holds the right wheel in bits 0-7 and the left one in bits 8-15; it is
    sent as a signed int16 (ARGNINT for a negative left wheel).

    Raises:
        EncodeError: If a velocity is outside [-128, 127].
    """
    for name, v in (('left', left), ('right', right)):
        if not -128 <= v <= 127:
            raise EncodeError(f'VEL2 {name}={v} outside [-128, 127]')
    word = ((left & 0xFF) << 8) | (right & 0xFF)
    return encode_command('VEL2', word - 0x10000 if word & 0x8000 else word)


def vel2_split(value: int) -> Tuple[int, int]:
    """Return (left, right) signed VEL2 units from a decoded VEL2 argument."""
    word = value & 0xFFFF

    def signed(b: int) -> int:
        return b - 0x100 if b & 0x80 else b
    return signed(word >> 8), signed(word & 0xFF)


def parse_command(data: bytes) -> Command:
    """Decode the data of a host command packet (emulator side).

    Strings are accepted length-prefixed (ARIA) or NUL-terminated (manual).

    Raises:
        FramingError: For an unknown argument type or a malformed argument.
        TruncatedError: If the argument is cut short.
    """
    if not data:
        raise TruncatedError('command packet has no command byte')
    code = data[0]
    name = _NAMES.get(code, f'0x{code:02X}')
    if len(data) == 1:
        return Command(code, name)
    kind = data[1]
    if kind in (ARGINT, ARGNINT):
        if len(data) < 4:
            raise TruncatedError(f'{name}: int argument of {len(data) - 2} bytes; expected 2')
        if len(data) > 4:
            raise FramingError(f'{name}: {len(data) - 4} bytes after the int argument')
        magnitude = data[2] | (data[3] << 8)
        return Command(code, name, kind, magnitude if kind == ARGINT else -magnitude)
    if kind == ARGSTR:
        rest = data[2:]
        if rest and rest[0] == len(rest) - 1:
            return Command(code, name, kind, text=bytes(rest[1:]))
        if rest and rest[-1] == 0 and 0 not in rest[:-1]:
            return Command(code, name, kind, text=bytes(rest[:-1]))
        raise FramingError(f'{name}: string argument is neither length-prefixed nor '
                           'NUL-terminated')
    raise FramingError(f'{name}: unknown argument type 0x{kind:02X}')


# ---------------------------------------------------------------------------- robot packets


@dataclass(frozen=True)
class Packet:
    """A checksum-valid robot packet of a type not decoded here (config, encoder, ...)."""

    kind: int  # the type byte, data[0]
    data: bytes


@dataclass(frozen=True)
class SyncReply:
    """Reply to SYNC0/1/2; SYNC2 carries the robot's name, class and subclass."""

    sync: int
    name: str = ''
    robot_class: str = ''
    subclass: str = ''


# Fixed part of a standard SIP: type, xpos, ypos, thpos, lvel, rvel, battery, stall_bump,
# control, flags, compass, sonar count.
_SIP_HEAD = struct.Struct('<BHHhhhBHhHBB')
_SIP_TAIL = struct.Struct('<5B')


@dataclass(frozen=True)
class StatusPacket:
    """A standard status packet (SIP) with raw integer fields; see the properties for units."""

    moving: bool  # type 0x33 (else 0x32)
    xpos: int  # 15-bit, x dist_conv_factor -> mm, wraps (OdometryUnwrapper)
    ypos: int
    thpos: int  # int16, 4096 per revolution, CCW positive
    lvel: int  # int16, x vel_conv_factor -> mm/s
    rvel: int
    battery: int  # 0.1 V
    stall_bump: int  # u16: low byte bit 0 left stall, 1-7 rear bumpers; high byte right/front
    control: int  # int16 heading setpoint (THPOS units)
    flags: int  # u16: bit 0 motors enabled, 1-4 sonar arrays, 5 e-stop (newer firmware)
    compass: int  # u8, 2 deg units
    sonars: Tuple[Tuple[int, int], ...] = ()  # (sonar number, raw range) read since last SIP
    grip_state: int = 0
    anport: int = 0
    analog: int = 0
    digin: int = 0
    digout: int = 0
    extra: bytes = b''  # newer firmware's extra fields, undecoded

    @property
    def battery_v(self) -> float:
        """Battery voltage (V)."""
        return self.battery / 10.0

    @property
    def left_stall(self) -> bool:
        """Left wheel stalled."""
        return bool(self.stall_bump & 0x0001)

    @property
    def right_stall(self) -> bool:
        """Right wheel stalled."""
        return bool(self.stall_bump & 0x0100)

    @property
    def rear_bumpers(self) -> int:
        """Rear bumper bits (7 bits)."""
        return (self.stall_bump >> 1) & 0x7F

    @property
    def front_bumpers(self) -> int:
        """Front bumper bits (7 bits)."""
        return (self.stall_bump >> 9) & 0x7F

    @property
    def motors_enabled(self) -> bool:
        """Flags bit 0."""
        return bool(self.flags & 0x01)

    @property
    def sonar_arrays(self) -> int:
        """Flags bits 1-4: sonar arrays on."""
        return (self.flags >> 1) & 0x0F

    @property
    def estop(self) -> bool:
        """Flags bit 5: e-stop pressed (newer firmware)."""
        return bool(self.flags & 0x20)

    @property
    def compass_deg(self) -> float:
        """Compass heading (deg)."""
        return self.compass * 2.0

    def theta_rad(self, params: RobotParams = P2DX) -> float:
        """Heading (rad) in [-pi, pi), CCW positive."""
        return _wrap_pi(self.thpos * params.angle_conv_factor)

    def wheel_velocities_mm_s(self, params: RobotParams = P2DX) -> Tuple[float, float]:
        """(left, right) wheel velocities (mm/s)."""
        return self.lvel * params.vel_conv_factor, self.rvel * params.vel_conv_factor

    def sonar_ranges_mm(self, params: RobotParams = P2DX) -> Dict[int, float]:
        """Sonar number -> range (mm) of the readings in this packet (last one wins)."""
        return {number: rng * params.range_conv_factor for number, rng in self.sonars}


def _wrap_pi(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def decode_status(data: bytes) -> StatusPacket:
    """Decode the data of a standard status packet (type 0x32/0x33 first).

    XPOS/YPOS keep 15 bits (as ARIA reads them); the wrap rule of :class:`OdometryUnwrapper`
    gives the same deltas with or without bit 15.

    Raises:
        FramingError: If the type is not 0x32/0x33.
        TruncatedError: If the data ends before the fields and sonar readings it declares.
    """
    if not data or data[0] not in (STATUS_STOPPED, STATUS_MOVING):
        raise FramingError(f'not a status packet: type {data[:1].hex() or "missing"}')
    if len(data) < _SIP_HEAD.size:
        raise TruncatedError(f'status packet of {len(data)} bytes; needs at least '
                             f'{_SIP_HEAD.size + _SIP_TAIL.size}')
    (kind, xpos, ypos, thpos, lvel, rvel, battery, stall_bump, control, flags, compass,
     count) = _SIP_HEAD.unpack_from(data)
    pos = _SIP_HEAD.size
    need = pos + 3 * count + _SIP_TAIL.size
    if len(data) < need:
        raise TruncatedError(f'status packet of {len(data)} bytes declares {count} sonar '
                             f'readings; needs {need} bytes')
    sonars = tuple(struct.unpack_from('<BH', data, pos + 3 * i) for i in range(count))
    pos += 3 * count
    grip, anport, analog, digin, digout = _SIP_TAIL.unpack_from(data, pos)
    return StatusPacket(kind == STATUS_MOVING, xpos & 0x7FFF, ypos & 0x7FFF, thpos, lvel,
                        rvel, battery, stall_bump, control, flags, compass, sonars, grip,
                        anport, analog, digin, digout, bytes(data[pos + _SIP_TAIL.size:]))


def _parse_sync2(data: bytes) -> SyncReply:
    parts = bytes(data[1:]).split(b'\x00')
    if len(parts) < 4 or any(c < 0x20 or c > 0x7E for c in b''.join(parts[:3])):
        raise FramingError('SYNC2 reply must hold three NUL-terminated ASCII strings')
    name, robot_class, subclass = (p.decode('ascii') for p in parts[:3])
    return SyncReply(2, name, robot_class, subclass)


def parse_sip(data: bytes) -> Union[StatusPacket, SyncReply, Packet]:
    """Interpret the data of a robot packet: status packet, SYNC reply or other packet.

    Raises:
        FramingError: If a status or SYNC2 packet is malformed.
        TruncatedError: If a status packet is cut short.
    """
    if not data:
        raise TruncatedError('robot packet has no type byte')
    kind = data[0]
    if kind in (STATUS_STOPPED, STATUS_MOVING):
        return decode_status(data)
    if kind in (0, 1) and len(data) == 1:
        return SyncReply(kind)
    if kind == 2:
        return SyncReply(2) if len(data) == 1 else _parse_sync2(data)
    return Packet(kind, bytes(data))


# ---------------------------------------------------------------------------- robot encoders


def _field(value: int, low: int, high: int, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise EncodeError(f'status field {name}={value!r} outside [{low}, {high}]')
    return value


def encode_status(packet: StatusPacket) -> bytes:
    """Build the packet of a status packet (robot side); :func:`parse_sip` inverts it exactly.

    Raises:
        EncodeError: If a field is out of range or the packet exceeds 200 bytes.
    """
    p = packet
    head = _SIP_HEAD.pack(
        STATUS_MOVING if p.moving else STATUS_STOPPED,
        _field(p.xpos, 0, 0x7FFF, 'xpos'), _field(p.ypos, 0, 0x7FFF, 'ypos'),
        _field(p.thpos, -32768, 32767, 'thpos'), _field(p.lvel, -32768, 32767, 'lvel'),
        _field(p.rvel, -32768, 32767, 'rvel'), _field(p.battery, 0, 255, 'battery'),
        _field(p.stall_bump, 0, 0xFFFF, 'stall_bump'),
        _field(p.control, -32768, 32767, 'control'), _field(p.flags, 0, 0xFFFF, 'flags'),
        _field(p.compass, 0, 255, 'compass'), _field(len(p.sonars), 0, 255, 'sonar count'))
    body = b''.join(struct.pack('<BH', _field(n, 0, 255, 'sonar number'),
                                _field(r, 0, 0xFFFF, 'sonar range')) for n, r in p.sonars)
    tail = _SIP_TAIL.pack(*(_field(v, 0, 255, name) for v, name in (
        (p.grip_state, 'grip_state'), (p.anport, 'anport'), (p.analog, 'analog'),
        (p.digin, 'digin'), (p.digout, 'digout'))))
    return encode_packet(head + body + tail + bytes(p.extra))


def status_from_state(x_mm: float, y_mm: float, theta_rad: float, left_mm_s: float,
                      right_mm_s: float, battery_v: float, params: RobotParams = P2DX,
                      sonar_mm: Sequence[Tuple[int, float]] = (), moving: Optional[bool] = None,
                      motors_enabled: bool = True, sonar_arrays: int = 0,
                      stall_bump: int = 0) -> StatusPacket:
    """Quantise a robot state into a status packet (emulator side).

    Positions wrap modulo 2**15 units, the heading to [0, 4096) units; ``moving`` defaults to
    "a wheel velocity is non-zero after quantisation".

    Raises:
        EncodeError: If a velocity, the battery voltage or a sonar range does not fit.
    """
    lvel = round(left_mm_s / params.vel_conv_factor)
    rvel = round(right_mm_s / params.vel_conv_factor)
    revolution = round(2.0 * math.pi / params.angle_conv_factor)
    return StatusPacket(
        moving=bool(lvel or rvel) if moving is None else moving,
        xpos=round(x_mm / params.dist_conv_factor) % 0x8000,
        ypos=round(y_mm / params.dist_conv_factor) % 0x8000,
        thpos=round(theta_rad / params.angle_conv_factor) % revolution,
        lvel=_field(lvel, -32768, 32767, 'lvel'), rvel=_field(rvel, -32768, 32767, 'rvel'),
        battery=_field(round(battery_v * 10.0), 0, 255, 'battery'),
        stall_bump=stall_bump, control=0,
        flags=int(bool(motors_enabled)) | (_field(sonar_arrays, 0, 15, 'sonar_arrays') << 1),
        compass=0,
        sonars=tuple((n, _field(round(mm / params.range_conv_factor), 0, 0xFFFF, 'sonar'))
                     for n, mm in sonar_mm))


def encode_sync_reply(sync: int, name: str = '', robot_class: str = 'Pioneer',
                      subclass: str = 'p2dx') -> bytes:
    """Build the robot's reply to SYNC0/1 (an echo) or SYNC2 (name, class, subclass).

    Raises:
        EncodeError: For another sync number or non-ASCII / NUL characters.
    """
    if sync in (0, 1):
        return encode_packet(bytes((sync,)))
    if sync != 2:
        raise EncodeError(f'sync {sync} is not 0, 1 or 2')
    parts = [name, robot_class, subclass]
    if any(not s.isascii() or '\x00' in s for s in parts):
        raise EncodeError(f'SYNC2 strings {parts!r} must be ASCII without NUL')
    return encode_packet(b'\x02' + b''.join(s.encode('ascii') + b'\x00' for s in parts))


# ---------------------------------------------------------------------------- odometry


class OdometryUnwrapper:
    """Turn successive raw XPOS/YPOS into continuous positions.

    docs/protocols/p2os.md §5: ``delta = ((new - old + 2048) mod 4096) - 2048``, valid for 12- and
    15-bit firmware as long as the robot moves less than 2048 units (1.7 m on a 2-DX) between
    two packets. The first sample sets the position to its raw value.
    """

    def __init__(self, dist_conv_factor: float = P2DX.dist_conv_factor,
                 modulus: int = ODOMETRY_MODULUS) -> None:
        """Create an unwrapper (mm per unit, wrap modulus of the rule)."""
        self.dist_conv_factor = dist_conv_factor
        self.modulus = modulus
        self.reset()

    def reset(self) -> None:
        """Forget the history: the next sample restarts from its raw value."""
        self._last: Optional[Tuple[int, int]] = None
        self.x_units = 0
        self.y_units = 0

    def _delta(self, new: int, old: int) -> int:
        half = self.modulus // 2
        return (new - old + half) % self.modulus - half

    def update(self, xpos: int, ypos: int) -> Tuple[float, float]:
        """Add one raw sample; return the continuous (x, y) in mm."""
        if self._last is None:
            self.x_units, self.y_units = xpos, ypos
        else:
            self.x_units += self._delta(xpos, self._last[0])
            self.y_units += self._delta(ypos, self._last[1])
        self._last = (xpos, ypos)
        return self.x_units * self.dist_conv_factor, self.y_units * self.dist_conv_factor


# ---------------------------------------------------------------------------- stream decoder


class P2osDecoder(StreamDecoder):
    """Incremental decoder of a P2OS byte stream.

    :meth:`feed` returns, in stream order, the packets interpreted by ``parse`` (default
    :func:`parse_sip`; :func:`parse_command` for an emulator decoding host commands) and the
    errors met as :class:`ProtocolError` objects (not raised). It resynchronises on
    ``FA FB``: a header with a count outside [3, 200] is skipped, a packet with a bad
    checksum is reported as a :class:`ChecksumError` (a :class:`TruncatedError` when another
    header lies inside it) and decoding restarts one byte after its header. Skipped bytes are
    reported once, as a :class:`FramingError`, before the next valid packet. The output does
    not depend on how the stream is cut into chunks.
    """

    unit = 'packet'

    def __init__(self, parse: Callable[[bytes], Any] = parse_sip) -> None:
        """Create a decoder returning ``parse(data)`` for every valid packet."""
        super().__init__()
        self.parse = parse

    def feed(self, data: bytes) -> List[Union[Any, ProtocolError]]:
        """Add bytes; return the decoded packets and the errors, in stream order."""
        buf = self._buf
        buf += data
        out: List[Any] = []
        pos = 0
        n = len(buf)
        while pos < n:
            p = buf.find(HEADER, pos)
            if p < 0:
                keep = n - 1 if buf[n - 1] == HEADER[0] else n  # may be the first header byte
                self._skip(pos, keep)
                pos = keep
                break
            self._skip(pos, p)
            pos = p
            if n - p < 3:
                break
            count = buf[p + 2]
            if not 3 <= count <= MAX_COUNT:
                self._skip(p, p + 1)
                pos = p + 1
                continue
            if n - p < 3 + count:
                break
            offset = self._base + p
            try:
                data_ = _checked_data(buf, p, count, offset)
            except ChecksumError as err:
                inner = buf.find(HEADER, p + 1, p + 3 + count)
                if 0 <= inner and inner + 2 < p + 3 + count and 3 <= buf[inner + 2] <= MAX_COUNT:
                    err = TruncatedError(
                        f'packet at offset {offset} fails its checksum and holds a packet '
                        f'header at offset {self._base + inner}: truncated', offset)
                self._report(out, err)
                self._quiet = True
                self._skip(p, p + 1)
                pos = p + 1
                continue
            try:
                item = self.parse(data_)
            except ProtocolError as err:
                item = type(err)(f'packet 0x{data_[0]:02X} at offset {offset}: {err}', offset)
            self._report(out, item)
            pos = p + 3 + count
        self._consume(pos)
        return out
