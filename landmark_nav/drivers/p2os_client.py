"""Host side of a P2OS connection: handshake, keep-alive, velocity commands, watchdog.

A pure state machine (the clock is passed in, bytes come back to be written; no I/O) used
by the ``base_driver`` node; ``docs/protocols/p2os.md`` describes the protocol (§7: this
session).

States: ``disconnected`` -> ``sync`` (SYNC0, SYNC1, SYNC2, each sent after the previous
echo; a missing echo restarts at SYNC0 after ``sync_timeout``, every third retry preceded
by a CLOSE to dislodge a half-open robot) -> ``open`` (after the SYNC2 reply: OPEN, the
speed and acceleration limits SETV / SETRV / SETA / SETRA, STOP so that old setpoints
cannot start the wheels, ENABLE and SONAR as configured). A status packet arriving during
the sync means the robot is still open from an earlier client and takes SYNC0 for a PULSE:
the client sends CLOSE, waits ``close_wait`` (``closing``) and starts again. While open:
PULSE whenever nothing was sent for ``pulse_period``; a STOP when velocity commands stop
for ``cmd_timeout`` (the robot's own watchdog is slower, and a later PULSE would restart
its last setpoints); a new handshake when no status packet came for ``sip_timeout``.

Each status packet is returned with the number of 100 ms robot cycles it stands for: a lost
packet is detected from the robot's own odometry (the distance or rotation since the
previous packet against what one cycle at the reported wheel speeds covers), and from the
arrival times for the diagnostics.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Tuple, Union

from landmark_nav.drivers.errors import EncodeError
from landmark_nav.drivers.p2os import (encode_command, encode_vel2, OdometryUnwrapper, P2DX,
                                       Packet, ROBOT_MODELS, RobotParams, StatusPacket,
                                       SyncReply)

__all__ = ['ClientConfig', 'DISCONNECTED', 'OPEN', 'P2osClient', 'SipUpdate', 'SYNC',
           'CLOSING']

DISCONNECTED, SYNC, CLOSING, OPEN = 'disconnected', 'sync', 'closing', 'open'
#: Smallest per-cycle motion that lets lost cycles be counted from the robot's odometry.
_MIN_CYCLE_DISTANCE_MM = 10.0
_MIN_CYCLE_ROTATION_RAD = math.radians(1.0)
_MAX_LOST_CYCLES = 20


@dataclass(frozen=True)
class ClientConfig:
    """Settings of a P2OS session (SI units).

    Attributes:
        robot_model: ``auto`` (from the SYNC2 subclass) or a key of ``ROBOT_MODELS``.
        enable_motors: Enable the motors after opening.
        sonar: Sonar on after opening.
        command_mode: ``vel`` (VEL mm/s + RVEL deg/s) or ``vel2`` (VEL2 wheel speeds).
        max_linear_speed: Commands are clamped to this, also sent as SETV [m/s].
        max_angular_speed: Commands are clamped to this, also sent as SETRV [rad/s].
        linear_accel: SETA (the robot ramps its velocity) [m/s^2].
        linear_decel: SETA with a negative argument [m/s^2].
        angular_accel: SETRA [rad/s^2].
        angular_decel: SETRA with a negative argument [rad/s^2].
        axle_length: Nominal axle length b [m] (VEL2 wheel speeds, lost-cycle check).
        cmd_timeout: STOP after this long without a velocity command [s].
        watchdog_command: What the watchdog sends: ``STOP`` (the robot decelerates at
            ``linear_decel``) or ``E_STOP`` (the robot stops at once, overriding the
            deceleration limits).
        pulse_period: PULSE when nothing was sent for this long [s].
        sync_timeout: Wait this long for a SYNC echo [s].
        close_wait: After CLOSE to a still-open robot, wait this long before SYNC0 [s].
        sip_timeout: Restart the handshake after this long without a status packet [s].
        resend_period: An unchanged velocity command is sent again at most this often [s].
        cycle_s: The robot's status packet period [s].
    """

    robot_model: str = 'auto'
    enable_motors: bool = True
    sonar: bool = True
    command_mode: str = 'vel'
    max_linear_speed: float = 0.5
    max_angular_speed: float = math.radians(100.0)
    linear_accel: float = 0.3
    linear_decel: float = 0.3
    angular_accel: float = math.radians(90.0)
    angular_decel: float = math.radians(90.0)
    axle_length: float = 0.33
    cmd_timeout: float = 0.5
    watchdog_command: str = 'STOP'
    pulse_period: float = 1.0
    sync_timeout: float = 0.5
    close_wait: float = 0.3
    sip_timeout: float = 2.0
    resend_period: float = 0.5
    cycle_s: float = 0.1

    def __post_init__(self) -> None:
        """Validate the settings."""
        if self.robot_model != 'auto' and self.robot_model not in ROBOT_MODELS:
            raise ValueError(f'robot_model {self.robot_model!r} is not auto or one of '
                             f'{", ".join(ROBOT_MODELS)}')
        if self.watchdog_command not in ('STOP', 'E_STOP'):
            raise ValueError(f'watchdog_command {self.watchdog_command!r} must be STOP or E_STOP')
        if self.command_mode not in ('vel', 'vel2'):
            raise ValueError(f'command_mode {self.command_mode!r} must be vel or vel2')
        for name in ('max_linear_speed', 'max_angular_speed', 'linear_accel', 'linear_decel',
                     'angular_accel', 'angular_decel', 'axle_length', 'cmd_timeout',
                     'pulse_period', 'sync_timeout', 'sip_timeout', 'cycle_s'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a finite number > 0, got {value!r}')
        if not (math.isfinite(self.close_wait) and self.close_wait >= 0.0):
            raise ValueError(f'close_wait must be >= 0, got {self.close_wait!r}')


@dataclass(frozen=True)
class SipUpdate:
    """A status packet as the driver uses it.

    Attributes:
        status: The decoded packet.
        cycles: Robot cycles since the previous packet (> 1 after lost packets); 1 for the
            first packet of a session.
        lost: Packets judged lost before this one (from odometry or arrival times).
        robot_pose: The robot's own pose, unwrapped: x [m], y [m], yaw [rad] in [-pi, pi).
        first: First packet since the handshake.
    """

    status: StatusPacket
    cycles: int
    lost: int
    robot_pose: Tuple[float, float, float]
    first: bool


class P2osClient:
    """The host side of one P2OS session (see the module docstring)."""

    def __init__(self, config: ClientConfig = ClientConfig()) -> None:
        """Start disconnected."""
        self.config = config
        self.state = DISCONNECTED
        self.params: RobotParams = (P2DX if config.robot_model == 'auto'
                                    else ROBOT_MODELS[config.robot_model])
        self.robot: Optional[SyncReply] = None
        self.motors_wanted = config.enable_motors
        self.sonar_wanted = config.sonar
        self.messages: List[str] = []
        self.handshakes = 0
        self.sync_retries = 0
        self.closes_sent = 0
        self.watchdog_stops = 0
        self.lost_packets = 0
        self._step = 0
        self._deadline = math.inf
        self._last_sent = -math.inf
        self._last_sip = -math.inf
        self._opened_at = -math.inf
        self._cmd_time = -math.inf
        self._cmd_moving = False
        self._last_cmd: bytes = b''
        self._last_cmd_sent = -math.inf
        self._unwrapper = OdometryUnwrapper(self.params.dist_conv_factor)
        self._prev_pose: Optional[Tuple[float, float, float]] = None

    # --- session -----------------------------------------------------------------------

    def _note(self, text: str) -> None:
        self.messages.append(text)

    def pop_messages(self) -> List[str]:
        """Return and forget the log messages collected since the last call."""
        out, self.messages = self.messages, []
        return out

    def _sent(self, data: bytes, now: float) -> bytes:
        if data:
            self._last_sent = now
        return data

    def connect(self, now: float) -> bytes:
        """Start (or restart) the handshake: return SYNC0."""
        self.handshakes += 1
        return self._sync0(now)

    def _sync0(self, now: float) -> bytes:
        self.state = SYNC
        self._step = 0
        self._deadline = now + self.config.sync_timeout
        self._prev_pose = None
        return self._sent(encode_command('SYNC0'), now)

    def disconnect(self) -> None:
        """Forget the session (the port was lost)."""
        self.state = DISCONNECTED
        self._deadline = math.inf

    @property
    def is_open(self) -> bool:
        """Whether the robot's servers are open (status packets expected)."""
        return self.state == OPEN

    def _open_commands(self) -> bytes:
        c = self.config
        out = [encode_command('OPEN'), encode_command('PULSE'),
               encode_command('SETV', _clip16(c.max_linear_speed * 1000.0)),
               encode_command('SETRV', _clip16(math.degrees(c.max_angular_speed))),
               encode_command('SETA', _clip16(c.linear_accel * 1000.0)),
               encode_command('SETA', -_clip16(c.linear_decel * 1000.0)),
               encode_command('SETRA', _clip16(math.degrees(c.angular_accel))),
               encode_command('SETRA', -_clip16(math.degrees(c.angular_decel))),
               encode_command('STOP'),
               encode_command('ENABLE', int(self.motors_wanted)),
               encode_command('SONAR', int(self.sonar_wanted))]
        return b''.join(out)

    def receive(self, item: Union[StatusPacket, SyncReply, Packet],
                now: float) -> Tuple[bytes, Optional[SipUpdate]]:
        """Handle one decoded robot packet; return (bytes to send, status update or None)."""
        if self.state == SYNC:
            if isinstance(item, StatusPacket):
                self.closes_sent += 1
                self.state = CLOSING
                self._deadline = now + self.config.close_wait
                self._note('robot is still open (status packets during the handshake): '
                           'sent CLOSE, retrying')
                return self._sent(encode_command('CLOSE'), now), None
            if isinstance(item, SyncReply):
                if item.sync != self._step:
                    self._note(f'SYNC{item.sync} reply while waiting for SYNC{self._step}; '
                               'restarting the handshake')
                    return self._sync0(now), None
                if item.sync < 2:
                    self._step += 1
                    self._deadline = now + self.config.sync_timeout
                    return self._sent(encode_command(f'SYNC{self._step}'), now), None
                return self._opened(item, now), None
            return b'', None
        if self.state == OPEN and isinstance(item, StatusPacket):
            return b'', self._status(item, now)
        return b'', None

    def _opened(self, reply: SyncReply, now: float) -> bytes:
        self.robot = reply
        if self.config.robot_model == 'auto':
            subclass = reply.subclass.lower()
            if subclass in ROBOT_MODELS:
                self.params = ROBOT_MODELS[subclass]
            else:
                self.params = P2DX
                self._note(f'unknown robot subclass {reply.subclass!r}: using the p2dx unit '
                           'conversions (set robot_model)')
        self._unwrapper = OdometryUnwrapper(self.params.dist_conv_factor)
        self.state = OPEN
        self._opened_at = now
        self._last_sip = now
        self._last_cmd = b''
        self._cmd_moving = False
        self._note(f'connected to {reply.name!r} ({reply.robot_class} {reply.subclass})')
        return self._sent(self._open_commands(), now)

    def _status(self, status: StatusPacket, now: float) -> SipUpdate:
        p = self.params
        gap = now - self._last_sip
        self._last_sip = now
        x_mm, y_mm = self._unwrapper.update(status.xpos, status.ypos)
        pose = (x_mm / 1000.0, y_mm / 1000.0, status.theta_rad(p))
        first = self._prev_pose is None
        cycles = 1
        if not first:
            cycles = self._cycles(status, pose)
        self._prev_pose = pose
        by_time = 0 if first else max(0, int(round(gap / self.config.cycle_s)) - 1)
        lost = max(cycles - 1, by_time)
        self.lost_packets += lost
        return SipUpdate(status, cycles, lost, pose, first)

    def _cycles(self, status: StatusPacket, pose: Tuple[float, float, float]) -> int:
        """Count the robot cycles since the previous packet from the robot's own odometry."""
        prev = self._prev_pose
        left, right = status.wheel_velocities_mm_s(self.params)
        per_cycle = abs(left + right) / 2.0 * self.config.cycle_s  # mm
        per_cycle_rot = abs(right - left) / (1000.0 * self.config.axle_length) \
            * self.config.cycle_s  # rad
        if per_cycle >= _MIN_CYCLE_DISTANCE_MM:
            moved = 1000.0 * math.hypot(pose[0] - prev[0], pose[1] - prev[1])
            n = round(moved / per_cycle)
        elif per_cycle_rot >= _MIN_CYCLE_ROTATION_RAD:
            turned = abs((pose[2] - prev[2] + math.pi) % (2.0 * math.pi) - math.pi)
            n = round(turned / per_cycle_rot)
        else:
            return 1
        return int(min(max(n, 1), _MAX_LOST_CYCLES))

    # --- periodic ----------------------------------------------------------------------

    def tick(self, now: float) -> bytes:
        """Handle timeouts: SYNC retries, the wait after CLOSE, lost stream, watchdog, PULSE."""
        c = self.config
        if self.state == SYNC and now >= self._deadline:
            self.sync_retries += 1
            self._note(f'no reply to SYNC{self._step} within {c.sync_timeout:g} s; retrying')
            dislodge = encode_command('CLOSE') if self.sync_retries % 3 == 0 else b''
            return dislodge + self._sync0(now)
        if self.state == CLOSING and now >= self._deadline:
            return self._sync0(now)
        if self.state != OPEN:
            return b''
        if now - self._last_sip >= c.sip_timeout:
            self._note(f'no status packet for {now - self._last_sip:.1f} s; restarting the '
                       'handshake')
            return self.connect(now)
        out = b''
        if self._cmd_moving and now - self._cmd_time >= c.cmd_timeout:
            self._cmd_moving = False
            self._last_cmd = b''
            self.watchdog_stops += 1
            self._note(f'no velocity command for {now - self._cmd_time:.2f} s: '
                       f'{c.watchdog_command}')
            out += encode_command(c.watchdog_command)
        if not out and now - self._last_sent >= c.pulse_period:
            out = encode_command('PULSE')
        return self._sent(out, now)

    # --- commands ----------------------------------------------------------------------

    def velocity(self, linear: float, angular: float, now: float) -> bytes:
        """Encode a body velocity command [m/s, rad/s] (clamped to the limits).

        Returns b'' when the robot is not open or the same command went out less than
        ``resend_period`` ago.

        Raises:
            ValueError: For a NaN or infinite velocity.
        """
        if not (math.isfinite(linear) and math.isfinite(angular)):
            raise ValueError(f'velocity command must be finite, got ({linear}, {angular})')
        c = self.config
        v = min(max(linear, -c.max_linear_speed), c.max_linear_speed)
        w = min(max(angular, -c.max_angular_speed), c.max_angular_speed)
        self._cmd_time = now
        self._cmd_moving = v != 0.0 or w != 0.0
        if self.state != OPEN:
            return b''
        if c.command_mode == 'vel2':
            data = self._vel2(v, w)
        else:
            data = (encode_command('VEL', _clip16(v * 1000.0))
                    + encode_command('RVEL', _clip16(math.degrees(w))))
        if data == self._last_cmd and now - self._last_cmd_sent < c.resend_period:
            return b''
        self._last_cmd = data
        self._last_cmd_sent = now
        return self._sent(data, now)

    def _vel2(self, v: float, w: float) -> bytes:
        """VEL2 from the nominal wheel speeds (eqs. 6-7 inverted), in Vel2Divisor units."""
        half_b = 0.5 * self.config.axle_length
        units = [int(round((v + s * w * half_b) * 1000.0 / self.params.vel2_divisor))
                 for s in (-1.0, 1.0)]
        left, right = (min(max(u, -128), 127) for u in units)
        try:
            return encode_vel2(left, right)
        except EncodeError:  # cannot happen after the clamp; keep the robot stopped
            return encode_command('STOP')

    def set_motors(self, enable: bool, now: float) -> bytes:
        """Enable or disable the motors (STOP first, so old setpoints cannot start them)."""
        self.motors_wanted = bool(enable)
        if self.state != OPEN:
            return b''
        self._last_cmd = b''
        data = encode_command('STOP') + encode_command('ENABLE', int(self.motors_wanted))
        return self._sent(data, now)

    def set_sonar(self, on: bool, now: float) -> bytes:
        """Switch the sonar on or off."""
        self.sonar_wanted = bool(on)
        if self.state != OPEN:
            return b''
        return self._sent(encode_command('SONAR', int(self.sonar_wanted)), now)

    def farewell(self) -> bytes:
        """Return STOP and CLOSE (on shutdown; harmless to a robot that is not open)."""
        self.state = DISCONNECTED
        return encode_command('STOP') + encode_command('CLOSE')


def _clip16(value: float) -> int:
    return int(min(max(round(value), -32767), 32767))
