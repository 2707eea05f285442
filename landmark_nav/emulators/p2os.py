"""Pioneer base emulator speaking P2OS, driven by the simulator world.

:class:`P2osDevice` is the robot's microcontroller as seen through its serial port
(``docs/protocols/p2os.md``); :class:`~landmark_nav.emulators.server.DeviceServer` serves it
on a pty and a TCP port (``landmark_nav emulate p2os``, MobileSim-style on port 8101).

Connection states, as the firmware behaves:

* waiting for SYNC0 -> SYNC1 -> SYNC2: each SYNC is echoed; the SYNC2 reply carries the
  robot's name, class ``Pioneer`` and subclass (``p2dx``, ``p3dx``, ``p3dx-sh``). Any
  other packet restarts the sequence; a fresh SYNC0 always restarts it.
* connected, not open: OPEN (1) starts the servers: status packets (SIPs) every 100 ms,
  sonar on, motors disabled (ENABLE 1 enables them), FLASH defaults for speed and
  acceleration limits. CLOSE (2) goes back to waiting for SYNC0.
* open: command codes 0, 1, 2 mean PULSE, OPEN, CLOSE, so a robot that is still open from
  an earlier client takes SYNC0 for a PULSE and SYNC1 for an OPEN: it does not echo them
  and keeps streaming until it receives CLOSE. CLOSE disables the motors and the sonar and
  ends the stream.
* watchdog: with no packet for ``watchdog_s`` (2 s) the open robot stops (decelerates to
  zero) but stays open; the next packet revives it and it accelerates back to its last
  setpoints (so a PULSE alone restarts an abandoned motion: the driver's own cmd_vel
  watchdog must send a stop).

Motion (each 100 ms cycle): VEL (mm/s) / RVEL (deg/s) set the translational and rotational
setpoints (HEAD / DHEAD a heading setpoint held with a proportional rotation), VEL2 the
wheel setpoints (units of Vel2Divisor); STOP zeroes the setpoints, E_STOP stops at once.
The current velocities approach the setpoints within the limits SETV / SETRV (speed) and
SETA / SETRA (positive argument: acceleration, negative: deceleration). The resulting
wheel speeds are whole mm/s (the controller's resolution). The TRUE robot moves with the
systematic error of eqs. 17-18 (left / right wheel radius k1 R, k2 R, axle k3 b) through
eqs. 1-7 (:func:`landmark_nav.sim.robot.step_pose`); it does not enter obstacles (within
``robot_radius`` of a wall it stalls: stall flags and front or rear bumper bits). The
encoders report the wheel speeds (optionally with the simulator's random wheel-speed noise)
as LVEL / RVEL; the firmware dead-reckons its own pose from them with the nominal R, b
(k = 1) and reports it as XPOS / YPOS (wrapping at 15 or 12 bits) and THPOS.

Sonar: ``sonars_per_cycle`` transducers fire per cycle in order 0..15 (16 = all, as the
simulator's sonar ring does); each reading is ray-cast in the world
(:class:`landmark_nav.sim.sonar.SonarRing`, cone and specular model) with optional noise
and reported in RangeConvFactor units; no echo within ``max_range`` is reported as the
largest value (0xFFFF).

Everything received is recorded with its time (:attr:`P2osDevice.commands`), every status
packet sent with the true and firmware poses (:attr:`P2osDevice.sent`), and events such as
open, close, watchdog stop and "wheels stopped" (:attr:`P2osDevice.events`), for tests.
"""

import argparse
from dataclasses import dataclass, replace
import math
import threading
from typing import List, Optional, Sequence, Tuple

from landmark_nav.drivers.errors import ProtocolError
from landmark_nav.drivers.p2os import (Command, encode_packet, encode_status,
                                       encode_sync_reply, P2osDecoder, parse_command,
                                       ROBOT_MODELS, RobotParams as ProtocolParams,
                                       status_from_state, StatusPacket, vel2_split)
from landmark_nav.emulators.server import Device
from landmark_nav.sim.robot import RobotParams, step_pose, wheel_to_twist
from landmark_nav.sim.scenarios import office_world
from landmark_nav.sim.sonar import SonarConfig, SonarRing
from landmark_nav.sim.world import World, wrap_angle
import numpy as np

WAIT_SYNC0, WAIT_SYNC1, WAIT_SYNC2, CONNECTED, OPEN = (
    'wait_sync0', 'wait_sync1', 'wait_sync2', 'connected', 'open')
NO_ECHO_RAW = 0xFFFF
DEFAULT_TCP_PORT = 8101  # MobileSim's port
HEADING_GAIN = 2.0  # 1/s, HEAD / DHEAD proportional heading control
#: Status packets of cycles run this late still go out (whatever the cycle time) [s].
LATE_SEND_S = 0.15
MAX_CATCH_UP = 600  # cycles simulated at most when the device was not polled for a while


@dataclass(frozen=True)
class ReceivedCommand:
    """One valid command packet received (time [s], decoded command, raw packet, state)."""

    time: float
    command: Command
    raw: bytes
    state: str  # connection state when it arrived

    @property
    def name(self) -> str:
        """Return the command's name; codes 0..2 are SYNC0..2 while the robot syncs."""
        if (self.command.code in (0, 1, 2) and self.command.arg_type is None
                and self.state in (WAIT_SYNC0, WAIT_SYNC1, WAIT_SYNC2)):
            return f'SYNC{self.command.code}'
        return self.command.name


@dataclass(frozen=True)
class SentStatus:
    """One status packet sent, with the state it was made from.

    Attributes:
        time: Cycle time [s] (device clock).
        seq: Cycle number.
        packet: The status packet as encoded.
        true_pose: True pose (x, y, yaw) [m, m, rad] in the world at the end of the cycle.
        firmware_pose: The firmware's dead-reckoned pose (x mm, y mm, yaw rad), unwrapped.
        sonar_m: (sonar number, range [m] as the packet encodes it) of this packet.
        sonar_true_m: (sonar number, noise-free range [m], +inf = no echo).
    """

    time: float
    seq: int
    packet: StatusPacket
    true_pose: Tuple[float, float, float]
    firmware_pose: Tuple[float, float, float]
    sonar_m: Tuple[Tuple[int, float], ...]
    sonar_true_m: Tuple[Tuple[int, float], ...]


def _ramp(current: float, target: float, accel: float, decel: float, dt: float) -> float:
    """Move ``current`` toward ``target`` by at most accel*dt (speeding up) or decel*dt."""
    speeding_up = abs(target) > abs(current) and target * current >= 0.0
    step = (accel if speeding_up else decel) * dt
    if abs(target - current) <= step:
        return target
    return current + math.copysign(step, target - current)


class P2osDevice(Device):
    """A Pioneer 2/3-DX microcontroller in a simulated world (see the module docstring).

    Args:
        world: World to move and ray-cast in (default: the office scenario's world).
        robot: Kinematics: nominal R, b, true k1, k2, k3, wheel-speed noise, FLASH default
            acceleration limits (``max_linear_accel``, ``max_angular_accel``).
        model: Robot subclass: ``p2dx``, ``p3dx`` or ``p3dx-sh`` (unit conversions).
        start_pose: True start pose (x, y, yaw) [m, m, rad].
        name: Robot name sent in the SYNC2 reply.
        sonar: Sonar ring configuration (mounts, cone, noise, range limits).
        sonar_noise: Add the sonar range noise of ``sonar``.
        wheel_noise: Add the simulator's random wheel-speed noise to LVEL / RVEL.
        sonars_per_cycle: Transducers fired per 100 ms cycle (1..16).
        battery_v: Battery voltage [V] (attribute ``battery_v`` may be changed later).
        battery_drain_v_per_h: Linear battery drain while open [V/h].
        watchdog_s: Stop after this long without a packet while open (0 = never) [s].
        position_bits: 15 or 12: XPOS / YPOS wrap (older firmware: 12 bits).
        max_speed: FLASH default of SETV [m/s].
        max_rot_speed: FLASH default of SETRV [rad/s].
        robot_radius: Stall when the centre comes closer than this to an obstacle [m].
        start_open: Start already open and streaming (a client crashed without CLOSE).
        cycle_s: SIP period [s].
        seed: Random seed of the noise.
        record_s: The records (``sent``: the status packets with the true pose and sonar
            values, about 5 kB a cycle; ``commands``) keep the last ``record_s`` seconds of
            cycles and four commands per cycle of them: bounded memory on a long live run
            (they kept 20000 packets and every command: 3.2 MB a minute at 10 Hz).
    """

    def __init__(self, world: Optional[World] = None, robot: RobotParams = RobotParams(),
                 model: str = 'p2dx', start_pose: Sequence[float] = (1.2, 1.2, 0.0),
                 name: str = 'landmark_nav', sonar: SonarConfig = SonarConfig(),
                 sonar_noise: bool = True, wheel_noise: bool = False,
                 sonars_per_cycle: int = 16, battery_v: float = 12.5,
                 battery_drain_v_per_h: float = 0.0, watchdog_s: float = 2.0,
                 position_bits: int = 15, max_speed: float = 0.75,
                 max_rot_speed: float = math.radians(100.0), robot_radius: float = 0.25,
                 start_open: bool = False, cycle_s: float = 0.1, seed: int = 1,
                 record_s: float = 60.0) -> None:
        """Build the robot at rest in ``world``."""
        if model not in ROBOT_MODELS:
            raise ValueError(f'unknown robot model {model!r}; one of {", ".join(ROBOT_MODELS)}')
        if position_bits not in (12, 15):
            raise ValueError(f'position_bits must be 12 or 15, got {position_bits}')
        if not 1 <= sonars_per_cycle <= sonar.num_sonars:
            raise ValueError(f'sonars_per_cycle must be in [1, {sonar.num_sonars}]')
        if not cycle_s > 0.0 or watchdog_s < 0.0 or not record_s > 0.0:
            raise ValueError('need cycle_s > 0, watchdog_s >= 0 and record_s > 0')
        pose = np.asarray(start_pose, dtype=float).reshape(3)
        if not np.all(np.isfinite(pose)):
            raise ValueError(f'start pose {start_pose!r} must be finite')
        self.world = world if world is not None else office_world()
        self.robot = robot
        self.model = model
        self.params: ProtocolParams = ROBOT_MODELS[model]
        self.name = name
        self.sonar_ring = SonarRing(self.world, sonar)
        self.sonar_noise = sonar_noise
        self.wheel_noise = wheel_noise
        self.sonars_per_cycle = int(sonars_per_cycle)
        self.battery_v = float(battery_v)
        self.battery_drain_v_per_h = float(battery_drain_v_per_h)
        self.watchdog_s = float(watchdog_s)
        self.position_bits = position_bits
        self.flash_max_speed_mm_s = max_speed * 1000.0
        self.flash_max_rot_deg_s = math.degrees(max_rot_speed)
        self.robot_radius = robot_radius
        self.cycle_s = cycle_s
        self.packets_not_sent = 0  # status packets of cycles run too late (a busy host)
        self._rng = np.random.default_rng(seed)
        self._lock = threading.RLock()
        self._decoder = P2osDecoder(parse=lambda data: (bytes(data), parse_command(data)))
        # truth and firmware odometry
        self.true_pose = pose.copy()
        self.firmware_pose = np.zeros(3)  # x mm, y mm, yaw rad (SETO zeroes it)
        # records
        cycles = int(math.ceil(record_s / cycle_s))
        self.commands: List[ReceivedCommand] = _Ring(4 * cycles)
        self.sent: List[SentStatus] = _Ring(cycles)
        self.events: List[Tuple[float, str]] = []
        self.bad_packets = 0
        self.seq = 0
        self._now = 0.0
        self._next_tick: Optional[float] = None
        self._sonar_next = 0
        self.state = WAIT_SYNC0
        self.v = 0.0  # mm/s, current translational velocity (nominal model)
        self.w = 0.0  # deg/s
        self.wheels = (0, 0)  # mm/s, current wheel speeds (whole mm/s)
        self.stall_bump = 0
        self._reset_servers()
        if start_open:
            self._open(0.0, record=False)
            self.motors_enabled = True

    # --- server state ------------------------------------------------------------------

    def _reset_servers(self) -> None:
        """FLASH defaults, setpoints zero, motors and sonar off (after CLOSE / at power-up)."""
        self.motors_enabled = False
        self.sonar_on = False
        self.mode = 'vel'  # 'vel' (VEL/RVEL), 'head' (HEAD/DHEAD) or 'vel2'
        self.vel_setpoint = 0.0  # mm/s
        self.rvel_setpoint = 0.0  # deg/s
        self.heading_setpoint = 0.0  # rad, firmware frame
        self.wheel_setpoints = (0.0, 0.0)  # mm/s
        self.max_vel = self.flash_max_speed_mm_s
        self.max_rvel = self.flash_max_rot_deg_s
        self.trans_accel = self.trans_decel = self.robot.max_linear_accel * 1000.0
        self.rot_accel = self.rot_decel = math.degrees(self.robot.max_angular_accel)
        self.watchdog_tripped = False
        self.last_packet = self._now

    def _open(self, now: float, record: bool = True) -> None:
        self._reset_servers()
        self.state = OPEN
        self.sonar_on = True
        self.last_packet = now
        if record:
            self.events.append((now, 'open'))

    def _close(self, now: float, why: str) -> None:
        self._reset_servers()
        self.state = WAIT_SYNC0
        self.events.append((now, why))

    @property
    def is_open(self) -> bool:
        """Whether the servers are open (SIPs streaming)."""
        return self.state == OPEN

    def commands_named(self, *names: str) -> List[ReceivedCommand]:
        """Return the recorded commands with these names, in order."""
        return [c for c in list(self.commands) if c.name in names]

    # --- Device interface ----------------------------------------------------------------

    def receive(self, data: bytes, now: float) -> List[bytes]:
        """Decode command packets; return the SYNC replies (commands are never ACKed)."""
        with self._lock:
            self._now = now
            if self._next_tick is None:
                self._next_tick = now + self.cycle_s
            out: List[bytes] = []
            for item in self._decoder.feed(data):
                if isinstance(item, ProtocolError):
                    self.bad_packets += 1  # the firmware silently ignores bad packets
                    continue
                data_, command = item
                out += self._handle(command, encode_packet(data_), now)
            return out

    def poll(self, now: float) -> List[bytes]:
        """Run the 100 ms cycles due by ``now``; return the status packets to send."""
        with self._lock:
            self._now = now
            if self._next_tick is None:
                self._next_tick = now + self.cycle_s
                return []
            behind = int((now - self._next_tick) // self.cycle_s)
            if behind > MAX_CATCH_UP:  # not polled for minutes: skip, do not simulate
                self._next_tick += (behind - MAX_CATCH_UP) * self.cycle_s
            frames: List[bytes] = []
            while now >= self._next_tick:
                t = self._next_tick
                self._next_tick += self.cycle_s
                frame = self._cycle(t)
                # Packets of cycles run up to 150 ms late (a busy host; 1.5 cycles at 100 ms)
                # go out late; older ones went out while nobody listened.
                if frame is not None and t >= now - max(1.5 * self.cycle_s, LATE_SEND_S):
                    frames.append(frame)
                elif frame is not None:
                    self.packets_not_sent += 1
            return frames

    def disconnected(self) -> None:
        """Forget a partial packet; the robot itself does not notice a lost cable."""
        with self._lock:
            self._decoder.reset()

    # --- commands -------------------------------------------------------------------------

    def _handle(self, command: Command, raw: bytes, now: float) -> List[bytes]:
        self.commands.append(ReceivedCommand(now, command, raw, self.state))
        code = command.code
        no_arg = command.arg_type is None
        if self.state != OPEN:
            if code == 0 and no_arg:
                self.state = WAIT_SYNC1
                return [encode_sync_reply(0)]
            if code == 1 and no_arg and self.state == WAIT_SYNC1:
                self.state = WAIT_SYNC2
                return [encode_sync_reply(1)]
            if code == 2 and no_arg and self.state == WAIT_SYNC2:
                self.state = CONNECTED
                return [encode_sync_reply(2, self.name, 'Pioneer', self.model)]
            if code == 1 and self.state == CONNECTED:
                self._open(now)
            elif code == 2 and self.state == CONNECTED:
                self._close(now, 'close')
            else:
                self.state = WAIT_SYNC0
            return []
        self.last_packet = now
        if self.watchdog_tripped:
            self.watchdog_tripped = False
            self.events.append((now, 'watchdog revived'))
        value = command.value if command.value is not None else 0
        name = command.name
        if name == 'CLOSE':
            self._close(now, 'close')
        elif name == 'ENABLE':
            self.motors_enabled = bool(value)
        elif name == 'SONAR':
            self.sonar_on = bool(value)
        elif name == 'SETO':
            self.firmware_pose = np.zeros(3)
        elif name == 'SETV':
            self.max_vel = float(min(abs(value), self.params.max_velocity_mm_s))
        elif name == 'SETRV':
            self.max_rvel = float(min(abs(value), self.params.max_rot_velocity_deg_s))
        elif name == 'SETA' and value:
            if value > 0:
                self.trans_accel = float(value)
            else:
                self.trans_decel = float(-value)
        elif name == 'SETRA' and value:
            if value > 0:
                self.rot_accel = float(value)
            else:
                self.rot_decel = float(-value)
        elif name == 'VEL':
            self._leave_vel2()
            self.vel_setpoint = float(value)
        elif name in ('RVEL', 'ROTATE'):
            self._leave_vel2()
            self.mode = 'vel'
            self.rvel_setpoint = float(value)
        elif name in ('HEAD', 'DHEAD'):
            self._leave_vel2()
            base = self.firmware_pose[2] if name == 'DHEAD' else 0.0
            self.heading_setpoint = float(wrap_angle(base + math.radians(value)))
            self.mode = 'head'
        elif name == 'VEL2':
            left, right = vel2_split(value)
            self.mode = 'vel2'
            self.wheel_setpoints = (left * self.params.vel2_divisor,
                                    right * self.params.vel2_divisor)
        elif name == 'STOP':
            self._leave_vel2()
            self.mode = 'vel'
            self.vel_setpoint = self.rvel_setpoint = 0.0
        elif name == 'E_STOP':
            if self.wheels != (0, 0):
                self.events.append((now, 'stopped'))
            self.mode = 'vel'
            self.vel_setpoint = self.rvel_setpoint = 0.0
            self.wheel_setpoints = (0.0, 0.0)
            self.v = self.w = 0.0
            self.wheels = (0, 0)
        return []  # PULSE, OPEN while open and unsupported commands: no effect

    def _leave_vel2(self) -> None:
        if self.mode == 'vel2':
            self.mode = 'vel'
            self.vel_setpoint = self.rvel_setpoint = 0.0

    # --- one 100 ms cycle ------------------------------------------------------------------

    def _cycle(self, t: float) -> Optional[bytes]:
        dt = self.cycle_s
        self.seq += 1
        if (self.state == OPEN and self.watchdog_s > 0.0 and not self.watchdog_tripped
                and t - self.last_packet > self.watchdog_s):
            self.watchdog_tripped = True
            self.events.append((t, 'watchdog stop'))
        was_moving = self.wheels != (0, 0)
        self._update_velocities(dt)
        left, right = self._move(dt)
        if was_moving and self.wheels == (0, 0):
            self.events.append((t, 'stopped'))
        elif not was_moving and self.wheels != (0, 0):
            self.events.append((t, 'moving'))
        if self.state != OPEN:
            return None
        self.battery_v = max(0.0, self.battery_v - self.battery_drain_v_per_h * dt / 3600.0)
        sonar_m, sonar_true, sonar_mm = self._fire_sonars()
        x_mm, y_mm, th = self.firmware_pose
        packet = status_from_state(
            x_mm, y_mm, th, left, right, min(self.battery_v, 25.5), self.params,
            sonar_mm=sonar_mm, motors_enabled=self.motors_enabled,
            sonar_arrays=0b11 if self.sonar_on else 0, stall_bump=self.stall_bump)
        if self.position_bits == 12:
            packet = replace(packet, xpos=packet.xpos % 4096, ypos=packet.ypos % 4096)
        self.sent.append(SentStatus(
            t, self.seq, packet, tuple(float(v) for v in self.true_pose),
            tuple(float(v) for v in self.firmware_pose), sonar_m, sonar_true))
        return encode_status(packet)

    def _update_velocities(self, dt: float) -> None:
        """Move the current velocities toward the setpoints within the limits."""
        active = self.state == OPEN and self.motors_enabled and not self.watchdog_tripped
        half_b = 500.0 * self.robot.axle_length  # mm
        if self.mode == 'vel2':
            targets = self.wheel_setpoints if active else (0.0, 0.0)
            limit = self.params.max_velocity_mm_s
            wheels = [_ramp(cur, float(np.clip(tgt, -limit, limit)), self.trans_accel,
                            self.trans_decel, dt)
                      for cur, tgt in zip(self.wheels, targets)]
            self.wheels = (int(round(wheels[0])), int(round(wheels[1])))
            self.v = 0.5 * (self.wheels[0] + self.wheels[1])
            self.w = math.degrees((self.wheels[1] - self.wheels[0]) / (2.0 * half_b))
            return
        v_t, w_t = 0.0, 0.0
        if active:
            v_t = float(np.clip(self.vel_setpoint, -self.max_vel, self.max_vel))
            if self.mode == 'head':
                err = float(wrap_angle(self.heading_setpoint - self.firmware_pose[2]))
                w_t = math.degrees(HEADING_GAIN * err)
            else:
                w_t = self.rvel_setpoint
            w_t = float(np.clip(w_t, -self.max_rvel, self.max_rvel))
        self.v = _ramp(self.v, v_t, self.trans_accel, self.trans_decel, dt)
        self.w = _ramp(self.w, w_t, self.rot_accel, self.rot_decel, dt)
        w_rad = math.radians(self.w)
        self.wheels = (int(round(self.v - w_rad * half_b)), int(round(self.v + w_rad * half_b)))

    def _move(self, dt: float) -> Tuple[int, int]:
        """Move the true robot and the firmware odometry; return the reported LVEL, RVEL."""
        r, b = self.robot.wheel_radius, self.robot.axle_length
        omega = np.array(self.wheels, dtype=float) / 1000.0 / r  # rad/s, whole mm/s
        v, w = wheel_to_twist(omega[0], omega[1], self.robot.k1 * r, self.robot.k2 * r,
                              self.robot.k3 * b)  # eqs. 17-18
        new = step_pose(self.true_pose, float(v), float(w), dt)  # eqs. 1-5
        self.stall_bump = 0
        if self.wheels != (0, 0):
            now_clear, new_clear = self.world.clearance(np.stack([self.true_pose[:2],
                                                                  new[:2]]))
            if new_clear < self.robot_radius and new_clear < now_clear:
                forward = self.wheels[0] + self.wheels[1] >= 0
                # both wheels stalled; bumper bits 1..5 of the front (high) or rear (low) byte
                self.stall_bump = 0x0101 | (0x3E00 if forward else 0x003E)
                return 0, 0  # the wheels do not turn against the wall
        self.true_pose = new
        if self.wheel_noise:
            std = (self.robot.wheel_noise_gain * np.abs(omega)
                   + self.robot.wheel_noise_floor) * r * 1000.0
            measured = np.array(self.wheels) + std * self._rng.standard_normal(2)
            left, right = int(round(measured[0])), int(round(measured[1]))
        else:
            left, right = self.wheels
        # the firmware's dead reckoning: nominal model (eqs. 1-7, k = 1) in mm
        fw_v = 0.5 * (left + right)
        fw_w = (right - left) / (1000.0 * b)
        self.firmware_pose = step_pose(self.firmware_pose, fw_v, fw_w, dt)
        return left, right

    def _fire_sonars(self):
        """Fire this cycle's transducers; return (encoded m, true m, mm for the packet)."""
        if not self.sonar_on:
            return (), (), ()
        cfg = self.sonar_ring.config
        n = cfg.num_sonars
        fired = [(self._sonar_next + i) % n for i in range(self.sonars_per_cycle)]
        self._sonar_next = (self._sonar_next + self.sonars_per_cycle) % n
        true_r = self.sonar_ring.true_ranges(self.true_pose[None, :])[0][fired]
        if self.sonar_noise:
            z = self._rng.standard_normal(len(fired))
            finite = np.isfinite(true_r)
            meas = np.where(finite, true_r + (cfg.sigma0 + cfg.sigma1 * np.where(
                finite, true_r, 0.0)) * z, np.inf)
        else:
            meas = true_r.copy()
        conv = self.params.range_conv_factor
        encoded, mm = [], []
        for i, value in zip(fired, meas):
            if not math.isfinite(value) or value > cfg.max_range:
                raw = NO_ECHO_RAW
            else:
                raw = min(NO_ECHO_RAW - 1, int(round(max(0.0, value) * 1000.0 / conv)))
            encoded.append((i, raw * conv / 1000.0))
            mm.append((i, raw * conv))
        return (tuple(encoded), tuple((i, float(v)) for i, v in zip(fired, true_r)),
                tuple(mm))


class _Ring(list):
    """A list that keeps only the newest ``size`` items (append only)."""

    def __init__(self, size: int) -> None:
        super().__init__()
        self.size = size

    def append(self, item) -> None:
        """Append, dropping the oldest items beyond ``size``."""
        super().append(item)
        if len(self) > self.size:
            del self[:len(self) - self.size]


# ---------------------------------------------------------------------------- command line


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the P2OS emulator's options (TCP defaults to MobileSim's port 8101)."""
    parser.set_defaults(tcp=DEFAULT_TCP_PORT)
    parser.add_argument('--model', choices=sorted(ROBOT_MODELS), default='p2dx',
                        help='robot subclass reported in SYNC2 (unit conversions)')
    parser.add_argument('--name', default='landmark_nav', help='robot name reported in SYNC2')
    parser.add_argument('--start-pose', type=float, nargs=3, default=(1.2, 1.2, 0.0),
                        metavar=('X', 'Y', 'YAW_DEG'),
                        help='true start pose in the office world [m, m, deg] '
                             '(default 1.2 1.2 0)')
    parser.add_argument('--k', type=float, nargs=3, default=None, metavar=('K1', 'K2', 'K3'),
                        help="true odometry factors of eqs. 17-18 (default the simulator's "
                             '0.9977 1.0023 1.0095)')
    parser.add_argument('--wheel-noise', action='store_true',
                        help="add the simulator's random wheel-speed noise to LVEL/RVEL")
    parser.add_argument('--no-sonar-noise', action='store_true',
                        help='report noise-free sonar ranges')
    parser.add_argument('--sonars-per-cycle', type=int, default=16,
                        help='transducers fired per 100 ms status packet (1..16, default 16)')
    parser.add_argument('--battery', type=float, default=12.5, help='battery voltage [V]')
    parser.add_argument('--battery-drain', type=float, default=0.0,
                        help='battery drain while open [V/h]')
    parser.add_argument('--watchdog', type=float, default=2.0,
                        help='stop after this long without a packet [s] (0 = never)')
    parser.add_argument('--position-bits', type=int, choices=(12, 15), default=15,
                        help='XPOS/YPOS wrap (12: older firmware)')
    parser.add_argument('--start-open', action='store_true',
                        help='start already open and streaming (a client that crashed '
                             "without CLOSE), to try the driver's CLOSE-and-retry path")


def device_kwargs(args: argparse.Namespace) -> dict:
    """Return the :class:`P2osDevice` arguments of the parsed options."""
    robot = RobotParams()
    if args.k is not None:
        robot = replace(robot, k1=args.k[0], k2=args.k[1], k3=args.k[2])
    x, y, yaw_deg = args.start_pose
    return {'robot': robot, 'model': args.model,
            'start_pose': (x, y, math.radians(yaw_deg)), 'name': args.name,
            'sonar_noise': not args.no_sonar_noise, 'wheel_noise': args.wheel_noise,
            'sonars_per_cycle': args.sonars_per_cycle, 'battery_v': args.battery,
            'battery_drain_v_per_h': args.battery_drain, 'watchdog_s': args.watchdog,
            'position_bits': args.position_bits, 'start_open': args.start_open,
            'seed': args.seed}


def make_device(args: argparse.Namespace) -> P2osDevice:
    """Build the device from the parsed options."""
    return P2osDevice(**device_kwargs(args))


__all__ = ['add_arguments', 'CONNECTED', 'device_kwargs', 'make_device', 'OPEN', 'P2osDevice',
           'ReceivedCommand', 'SentStatus', 'WAIT_SYNC0', 'WAIT_SYNC1', 'WAIT_SYNC2']
