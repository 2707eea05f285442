"""The P2OS emulator: handshake, still-open robot, watchdog, motion, status packets, sonar.

The device is driven directly (bytes in, frames out, clock passed in); the expected values
come from the protocol module's encoders and the simulator's kinematics and ray caster.
"""

import math

from landmark_nav.drivers import p2os
from landmark_nav.emulators.p2os import (CONNECTED, make_device, NO_ECHO_RAW, OPEN,
                                         P2osDevice, WAIT_SYNC0, WAIT_SYNC1)
from landmark_nav.sim.robot import integrate, RobotParams, wheel_to_twist
from landmark_nav.sim.sonar import SonarConfig, SonarRing
from landmark_nav.sim.world import World
import numpy as np
import pytest

cmd = p2os.encode_command
T = 0.1


def frames(device, data=b'', now=0.0):
    """Send bytes; decode the replies."""
    out = []
    for frame in device.receive(data, now) if data else []:
        out += p2os.P2osDecoder().feed(frame)
    return out


def run(device, t0, seconds):
    """Poll the device every 10 ms for ``seconds``; return (decoded SIPs, end time)."""
    dec = p2os.P2osDecoder()
    sips = []
    n = int(round(seconds / 0.01))
    for i in range(1, n + 1):
        for frame in device.poll(t0 + i * 0.01):
            sips += dec.feed(frame)
    return sips, t0 + n * 0.01


def opened(**kwargs):
    """Return a device after SYNC0/1/2 and OPEN at t = 0, and the time."""
    device = P2osDevice(**kwargs)
    for i in range(3):
        assert frames(device, cmd(f'SYNC{i}'), 0.0)
    frames(device, cmd('OPEN'), 0.0)
    assert device.state == OPEN
    return device


def test_handshake_replies_and_state_machine():
    device = P2osDevice(name='MyRobot', model='p3dx-sh')
    assert device.receive(cmd('SYNC1'), 0.0) == []  # out of order: ignored
    assert device.receive(cmd('SYNC0'), 0.0) == [p2os.encode_sync_reply(0)]
    assert device.state == WAIT_SYNC1
    assert device.receive(cmd('SYNC0'), 0.0) == [p2os.encode_sync_reply(0)]  # restart
    assert device.receive(cmd('SYNC1'), 0.0) == [p2os.encode_sync_reply(1)]
    reply = device.receive(cmd('SYNC2'), 0.0)
    assert reply == [p2os.encode_sync_reply(2, 'MyRobot', 'Pioneer', 'p3dx-sh')]
    assert device.state == CONNECTED
    sips, t = run(device, 0.0, 0.5)
    assert sips == []  # nothing streams before OPEN
    device.receive(cmd('OPEN'), t)
    sips, t = run(device, t, 1.0)
    assert 9 <= len(sips) <= 11 and all(isinstance(s, p2os.StatusPacket) for s in sips)
    times = [s.time for s in device.sent]
    assert np.allclose(np.diff(times), T)
    assert not sips[-1].motors_enabled and sips[-1].sonar_arrays  # motors off, sonar on
    assert [c.name for c in device.commands] == ['SYNC1', 'SYNC0', 'SYNC0', 'SYNC1', 'SYNC2',
                                                 'OPEN']


def test_still_open_robot_ignores_sync_until_close():
    device = P2osDevice(start_open=True)
    sips, t = run(device, 0.0, 0.35)
    assert len(sips) >= 2
    for name in ('SYNC0', 'SYNC1'):  # PULSE and OPEN to an open robot ...
        assert device.receive(cmd(name), t) == []
        assert device.state == OPEN
    more, t = run(device, t, 0.3)
    assert len(more) >= 2  # ... it keeps streaming
    device.receive(cmd('CLOSE'), t)
    assert device.state == WAIT_SYNC0
    after, t = run(device, t, 0.5)
    assert after == []
    assert device.receive(cmd('SYNC0'), t) == [p2os.encode_sync_reply(0)]
    assert [c.name for c in device.commands] == ['PULSE', 'OPEN', 'CLOSE', 'SYNC0']


def test_bad_packets_are_ignored_and_commands_recorded():
    device = opened()
    good = cmd('ENABLE', 1)
    bad = bytearray(cmd('VEL', 300))
    bad[-1] ^= 0x01
    assert device.receive(b'\x00\x13junk' + bytes(bad) + good, 1.0) == []
    assert device.bad_packets >= 1 and device.motors_enabled
    last = device.commands[-1]
    assert (last.name, last.command.value, last.raw, last.time) == ('ENABLE', 1, good, 1.0)
    assert device.vel_setpoint == 0.0  # the corrupt VEL did nothing


def test_velocity_ramp_kinematics_and_firmware_odometry():
    robot = RobotParams()
    device = opened(robot=robot, sonar_noise=False)
    t = 0.0
    for c in (cmd('ENABLE', 1), cmd('SETA', 200), cmd('SETA', -400), cmd('SETRA', 60),
              cmd('VEL', 300), cmd('RVEL', 20)):
        device.receive(c, t)
    start = device.true_pose.copy()
    sips = []
    for k in range(40):
        more, t = run(device, t, T)
        sips += more
        if k % 10 == 0:
            device.receive(cmd('PULSE'), t)
    wheels = np.array([s.wheel_velocities_mm_s() for s in sips])
    v = wheels.mean(axis=1)
    # SETA 200 mm/s^2: 20 mm/s per cycle up to 300 mm/s
    assert np.all(np.diff(v) <= 20.0 + 1.0) and v[-1] == pytest.approx(300.0, abs=1.0)
    assert 14 <= np.argmax(v >= 299.0) <= 16
    omega = wheels / 1000.0 / robot.wheel_radius
    # truth: eqs. 17-18 with the true k, eqs. 1-5 (independent batch integration)
    tv, tw = wheel_to_twist(omega[:, 0], omega[:, 1], robot.k1 * robot.wheel_radius,
                            robot.k2 * robot.wheel_radius, robot.k3 * robot.axle_length)
    sent = list(device.sent)
    first = sent.index(next(s for s in sent if s.packet == sips[0]))
    truth = integrate(sent[first - 1].true_pose if first else start, tv, tw, T)
    assert np.allclose(truth[-1], sent[first + len(sips) - 1].true_pose, atol=1e-9)
    # firmware pose: nominal model (k = 1) of the same wheel speeds, in mm
    nv, nw = wheel_to_twist(wheels[:, 0], wheels[:, 1], 1.0, 1.0, robot.axle_length * 1000.0)
    fw = integrate(sent[first - 1].firmware_pose if first else (0, 0, 0), nv, nw, T)
    assert np.allclose(fw[-1], sent[first + len(sips) - 1].firmware_pose, atol=1e-6)
    last = sips[-1]
    x, y, th = sent[first + len(sips) - 1].firmware_pose
    assert last.xpos == round(x / 0.84) % 0x8000 and last.ypos == round(y / 0.84) % 0x8000
    assert last.theta_rad() == pytest.approx(math.remainder(th, 2 * math.pi), abs=0.0008)
    assert last.moving and last.motors_enabled


def test_watchdog_stops_and_a_packet_revives_the_last_setpoints():
    device = opened(watchdog_s=2.0)
    device.receive(cmd('ENABLE', 1) + cmd('VEL', 200), 0.0)
    sips, t = run(device, 0.0, 1.5)
    assert sips[-1].wheel_velocities_mm_s() == (200.0, 200.0)
    sips, t = run(device, t, 2.0)  # 3.5 s without a packet: watchdog at 2 s
    assert any(e == 'watchdog stop' for _, e in device.events)
    stop_t = next(tt for tt, e in device.events if e == 'watchdog stop')
    assert stop_t == pytest.approx(2.0, abs=0.11)
    assert sips[-1].wheel_velocities_mm_s() == (0.0, 0.0)
    assert device.is_open  # stopped, not closed
    device.receive(cmd('PULSE'), t)
    sips, t = run(device, t, 1.5)
    assert sips[-1].wheel_velocities_mm_s() == (200.0, 200.0)


def test_vel2_stop_estop_and_close():
    device = opened()
    device.receive(cmd('ENABLE', 1) + p2os.encode_vel2(-5, 10), 0.0)
    sips, t = run(device, 0.0, 2.0)
    assert sips[-1].wheel_velocities_mm_s() == (-100.0, 200.0)
    device.receive(cmd('STOP'), t)
    sips, t = run(device, t, 0.3)
    assert abs(sips[-1].lvel) < 100 and abs(sips[-1].rvel) < 200  # decelerating
    sips, t = run(device, t, 1.0)
    assert sips[-1].wheel_velocities_mm_s() == (0.0, 0.0)
    device.receive(cmd('VEL', 300), t)
    sips, t = run(device, t, 0.5)
    assert sips[-1].lvel > 0
    device.receive(cmd('E_STOP'), t)
    sips, t = run(device, t, 0.15)
    assert sips[-1].wheel_velocities_mm_s() == (0.0, 0.0)
    device.receive(cmd('VEL', 300), t)
    sips, t = run(device, t, 0.5)
    device.receive(cmd('CLOSE'), t)
    assert device.state == WAIT_SYNC0 and not device.motors_enabled
    assert run(device, t, 0.5)[0] == []
    names = [e for _, e in device.events]
    assert names[0] == 'open' and 'close' in names and 'stopped' in names


def test_sonar_readings_match_the_ray_caster():
    config = SonarConfig()
    device = opened(sonar=config, sonar_noise=False, start_pose=(2.0, 1.5, 0.3))
    sips, t = run(device, 0.0, 0.35)
    sent = device.sent[-1]
    numbers = [n for n, _ in sips[-1].sonars]
    assert numbers == list(range(16))
    expected = SonarRing(device.world, config).true_ranges(np.array([sent.true_pose]))[0]
    for (n, raw), (_, value) in zip(sips[-1].sonars, sent.sonar_m):
        assert value == raw * 0.268 / 1000.0
        if math.isfinite(expected[n]) and expected[n] <= config.max_range:
            assert value == pytest.approx(expected[n], abs=0.134e-3 + 1e-12)
        else:
            assert raw == NO_ECHO_RAW
    device.receive(cmd('SONAR', 0), t)
    sips, t = run(device, t, 0.3)
    assert sips[-1].sonars == () and sips[-1].sonar_arrays == 0


def test_sonar_firing_order_and_no_echo():
    world = World('empty')
    world.add_room([(0, 0), (20, 0), (20, 20), (0, 20)])
    device = opened(world=world, start_pose=(10, 10, 0), sonars_per_cycle=4)
    sips, t = run(device, 0.0, 0.45)
    got = [[n for n, _ in s.sonars] for s in sips[:4]]
    assert got == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11], [12, 13, 14, 15]]
    assert all(raw == NO_ECHO_RAW for s in sips for _, raw in s.sonars)  # walls 10 m away


def test_stall_against_a_wall_sets_flags():
    world = World('box')
    world.add_room([(0, 0), (3, 0), (3, 3), (0, 3)])
    device = opened(world=world, start_pose=(2.45, 1.5, 0.0))
    device.receive(cmd('ENABLE', 1) + cmd('VEL', 300), 0.0)
    sips, t = run(device, 0.0, 1.9)
    assert device.true_pose[0] <= 3.0 - 0.25 + 1e-9
    last = sips[-1]
    assert last.left_stall and last.right_stall and last.front_bumpers
    assert not last.rear_bumpers and last.wheel_velocities_mm_s() == (0.0, 0.0)


def test_12_bit_positions_wrap_and_unwrap():
    device = opened(position_bits=12, start_pose=(1.2, 3.6, 0.0))
    device.receive(cmd('ENABLE', 1) + cmd('SETA', 2000) + cmd('VEL', 700), 0.0)
    unwrap = p2os.OdometryUnwrapper()
    t = 0.0
    for k in range(12):
        sips, t = run(device, t, 0.5)
        device.receive(cmd('PULSE'), t)
        for s in sips:
            assert s.xpos < 4096
            x, _ = unwrap.update(s.xpos, s.ypos)
    fw = device.sent[-1].firmware_pose
    assert fw[0] > 4096 * 0.84  # wrapped at least once
    assert x == pytest.approx(fw[0], abs=0.84)


def test_cli_options_build_the_device():
    from landmark_nav.tools.cli import build_parser
    args = build_parser().parse_args(['emulate', 'p2os', '--model', 'p3dx', '--start-pose',
                                      '2', '3', '90', '--k', '1.0', '1.01', '1.02',
                                      '--position-bits', '12', '--start-open'])
    assert args.tcp == 8101
    device = make_device(args)
    assert device.model == 'p3dx' and device.params is p2os.P3DX
    assert device.true_pose == pytest.approx([2.0, 3.0, math.pi / 2])
    assert (device.robot.k2, device.robot.k3) == (1.01, 1.02)
    assert device.is_open and device.position_bits == 12
    assert build_parser().parse_args(['emulate', 'p2os', '--tcp', '0']).tcp == 0
