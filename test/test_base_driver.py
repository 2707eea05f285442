"""base_driver against the P2OS emulator: handshake, odometry, joints, sonar, commands, faults.

The emulator (in-process :class:`DeviceServer` on a pty, or ``landmark_nav emulate p2os`` over
TCP) is the independent truth: it records every command it received with its time, every
status packet it sent and the true robot pose (eqs. 1-7, 17-18 with the true k1, k2, k3).
"""

from contextlib import contextmanager
from dataclasses import dataclass
import math
import os
from pathlib import Path
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist
from landmark_nav.conversions import odometry_to_pose
from landmark_nav.drivers import p2os
from landmark_nav.emulators.p2os import OPEN, P2osDevice, WAIT_SYNC0
from landmark_nav.emulators.server import DeviceServer, Fault
from landmark_nav.nodes.base_driver import BaseDriver
from landmark_nav.nodes.common import ParameterError
from landmark_nav.sim.robot import RobotParams
from landmark_nav.sim.sonar import SonarRing
from landmark_nav.testing import declared_parameters, parameter_file, RosHarness
from landmark_nav.tools.calibrate_odometry import write_base_driver_params
from nav_msgs.msg import Odometry
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import BatteryState, JointState, Range
from std_srvs.srv import SetBool
import yaml

# real-time driver tests (stamps, watchdog, reconnect within bounds): make test runs them
# after the parallel part, alone, so that the other workers do not starve them of CPU
pytestmark = [pytest.mark.dds, pytest.mark.realtime]

REPO = Path(__file__).resolve().parents[1]
TRUE_K = (RobotParams().k1, RobotParams().k2, RobotParams().k3)
R = RobotParams().wheel_radius
cmd = p2os.encode_command


@dataclass
class Rig:
    """An emulator, its server, a harness and the driver node."""

    device: P2osDevice
    server: DeviceServer
    ros: RosHarness
    node: BaseDriver
    pub: object

    def twist(self, linear: float, angular: float) -> float:
        """Publish one cmd_vel; return the monotonic time."""
        msg = Twist()
        msg.linear.x = float(linear)
        msg.angular.z = float(angular)
        self.pub.publish(msg)
        return time.monotonic()

    def drive(self, linear: float, angular: float, seconds: float) -> float:
        """Publish cmd_vel at 10 Hz for ``seconds``; return the time of the last one."""
        end = time.monotonic() + seconds
        last = self.twist(linear, angular)
        while time.monotonic() < end:
            time.sleep(0.1)
            last = self.twist(linear, angular)
        return last


@contextmanager
def rig(tmp_path, device=None, url=None, **params):
    """Serve ``device`` on a pty and run the driver on it (or on ``url``)."""
    device = device or P2osDevice(sonar_noise=False)
    link = str(tmp_path / 'p2os')
    overrides = [Parameter('port', value=url or link),
                 Parameter('diagnostics_period', value=0.1)]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    with DeviceServer(device, link=link) as server, RosHarness() as ros:
        node = BaseDriver(context=ros.context, parameter_overrides=overrides)
        ros.add_node(node)
        helper = ros.add_node(rclpy.create_node('cmd_source', context=ros.context))
        pub = helper.create_publisher(Twist, '/cmd_vel', 10)
        ros.wait_for_subscribers([pub], timeout=5.0)
        yield Rig(device, server, ros, node, pub)


def timed(ros, topic, cls):
    """Collect (monotonic arrival time, message) pairs."""
    out = []
    helper = ros.add_node(rclpy.create_node(f'timed_{len(ros._nodes)}', context=ros.context))
    helper.create_subscription(cls, topic, lambda m: out.append((time.monotonic(), m)), 100)
    return out


def level(array, name='base_driver: connection'):
    """Return (level, message, values) of the named status in a DiagnosticArray."""
    for status in array.status:
        if status.name == name:
            return status.level[0], status.message, {v.key: v.value for v in status.values}
    return None


def relative(start, pose):
    """Express ``pose`` in the frame of ``start`` (the odometry origin)."""
    c, s = math.cos(start[2]), math.sin(start[2])
    dx, dy = pose[0] - start[0], pose[1] - start[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy,
                     math.remainder(pose[2] - start[2], 2 * math.pi)])


def wait_still(r, timeout=8.0):
    """Wait until the robot has stopped and three more status packets went out."""
    def still():
        sent = list(r.device.sent)
        return len(sent) > 3 and all(s.packet.lvel == 0 and s.packet.rvel == 0
                                     for s in sent[-3:])
    assert r.ros.wait_until(still, timeout)
    time.sleep(0.3)


# ------------------------------------------------------------------------- handshake + data


def test_fresh_handshake_odometry_joints_and_sonar_match_the_emulator(tmp_path):
    k = dict(zip(('k1', 'k2', 'k3'), TRUE_K))
    with rig(tmp_path, **k) as r:
        odom = r.ros.collect('/odom', Odometry)
        joints = r.ros.collect('/joint_states', JointState)
        ranges = {i: r.ros.collect(f'/sonar/range_{i}', Range) for i in range(16)}
        battery = r.ros.collect('/battery', BatteryState)
        assert r.ros.wait_until(lambda: len(odom) >= 3, 5.0)
        names = [c.name for c in r.device.commands]
        assert names[:5] == ['SYNC0', 'SYNC1', 'SYNC2', 'OPEN', 'PULSE']
        assert {'SETV', 'SETRV', 'SETA', 'SETRA', 'STOP', 'ENABLE', 'SONAR'} <= set(names)
        assert names.index('STOP') < names.index('ENABLE')  # no runaway after enabling
        start = np.array(r.device.sent[0].true_pose)
        r.drive(0.3, 0.4, 2.0)
        r.drive(0.2, -0.3, 1.0)
        r.twist(0.0, 0.0)
        wait_still(r)
        # odometry: eqs. 17-18 with the true k from the reported wheel speeds == truth
        got = odometry_to_pose(odom[-1])
        truth = relative(start, r.device.true_pose)
        assert np.linalg.norm(truth[:2]) > 0.5  # it really drove
        assert got.pose[:2] == pytest.approx(truth[:2], abs=1e-6)
        assert got.pose[2] == pytest.approx(truth[2], abs=1e-6)
        print(f'odometry vs truth after {np.linalg.norm(truth[:2]):.2f} m: '
              f'{np.hypot(*(got.pose[:2] - truth[:2])):.1e} m, '
              f'{abs(got.pose[2] - truth[2]):.1e} rad')
        assert (odom[-1].header.frame_id, odom[-1].child_frame_id) == ('odom', 'base_link')
        cov = got.covariance
        assert np.all(np.linalg.eigvalsh(cov) > 0) and cov[0, 0] + cov[1, 1] > 1e-4
        # joint states: every received sample is one sent status packet, in order
        sent = [(s.packet.lvel, s.packet.rvel) for s in list(r.device.sent)]
        vel = [tuple(int(round(v * R * 1000.0)) for v in m.velocity) for m in joints]
        assert all(list(m.name) == ['left_wheel_joint', 'right_wheel_joint'] for m in joints)
        offset = next(o for o in range(len(sent)) if sent[o:o + len(vel)] == vel)
        angles = np.sum(np.array(sent[:offset + len(vel)]) / 1000.0 / R, axis=0) * 0.1
        assert list(joints[-1].position) == pytest.approx(angles, abs=1e-9)
        assert max(abs(v) for pair in vel for v in pair) >= 200
        # every sonar: the last reading equals what the emulator encoded, and the ray caster
        last = r.device.sent[-1]
        truth_r = SonarRing(r.device.world).true_ranges(np.array([last.true_pose]))[0]
        for n, value in last.sonar_m:
            msg = ranges[n][-1]
            assert msg.header.frame_id == f'sonar_{n}'
            if value > 5.0:
                assert msg.range == math.inf and not truth_r[n] <= 5.0
            else:
                assert msg.range == pytest.approx(value, abs=1e-6)
                assert msg.range == pytest.approx(truth_r[n], abs=0.134e-3 + 1e-6)
            assert msg.field_of_view == pytest.approx(math.radians(25.0))
        assert battery and battery[-1].voltage == pytest.approx(12.5)


def test_still_open_robot_is_closed_and_reconnected(tmp_path):
    device = P2osDevice(start_open=True, sonar_noise=False, model='p3dx-sh')
    with rig(tmp_path, device=device) as r:
        odom = r.ros.collect('/odom', Odometry)
        assert r.ros.wait_until(lambda: len(odom) >= 3, 6.0)
        log = [(c.name, c.state) for c in r.device.commands]
        assert log[0] == ('PULSE', OPEN)  # SYNC0 taken as PULSE: no echo
        close = log.index(('CLOSE', OPEN))
        after = [name for name, _ in log[close + 1:close + 5]]
        assert after == ['SYNC0', 'SYNC1', 'SYNC2', 'OPEN']
        assert r.node.client.closes_sent == 1 and r.device.is_open
        assert r.node.client.params is p2os.P3DX_SH  # robot_model auto: from SYNC2


def test_robot_pose_fallback_with_12_bit_positions(tmp_path):
    device = P2osDevice(position_bits=12, sonar_noise=False)
    with rig(tmp_path, device=device, odometry_source='robot', max_linear_speed=1.2,
             max_linear_accel=2.0, max_linear_decel=2.0) as r:
        odom = r.ros.collect('/odom', Odometry)
        assert r.ros.wait_until(lambda: len(odom) >= 2, 5.0)
        fw0 = np.array(r.device.sent[0].firmware_pose)
        r.drive(1.2, 0.05, 3.2)  # > 3.44 m: the 12-bit XPOS wraps
        r.twist(0.0, 0.0)
        wait_still(r)
        fw = np.array(r.device.sent[-1].firmware_pose)
        assert fw[0] - fw0[0] > 4096 * 0.84
        got = odometry_to_pose(odom[-1]).pose
        expected = relative(fw0 * [1e-3, 1e-3, 1.0], fw * [1e-3, 1e-3, 1.0])
        assert got[:2] == pytest.approx(expected[:2], abs=2e-3)  # quantisation 0.84 mm
        assert got[2] == pytest.approx(expected[2], abs=2e-3)


# ------------------------------------------------------------------------- commands


def test_cmd_vel_gives_vel_and_rvel_bytes(tmp_path):
    with rig(tmp_path, max_linear_speed=0.5) as r:
        assert r.ros.wait_until(lambda: r.node.client.is_open, 5.0)
        for linear, angular, vel, rvel in ((0.2, math.radians(30.0), 'FA FB 06 0B 3B C8 00 D3 3B',
                                            'FA FB 06 15 3B 1E 00 33 3B'),
                                           (-0.2, 0.0, 'FA FB 06 0B 1B C8 00 D3 1B', None),
                                           (3.0, 0.0, None, None)):
            n = len(r.device.commands)
            r.twist(linear, angular)
            assert r.ros.wait_until(lambda: len(r.device.commands_named('RVEL')) and
                                    r.device.commands[-1].name == 'RVEL' and
                                    len(r.device.commands) >= n + 2, 2.0)
            got_vel, got_rvel = r.device.commands[-2:]
            if vel:
                assert got_vel.raw == bytes.fromhex(vel)
            if rvel:
                assert got_rvel.raw == bytes.fromhex(rvel)
            expected = int(round(max(-0.5, min(0.5, linear)) * 1000))
            assert (got_vel.name, got_vel.command.value) == ('VEL', expected)
            assert got_rvel.command.value == round(math.degrees(angular))


def test_cmd_vel_gives_vel2_bytes(tmp_path):
    with rig(tmp_path, command_mode='vel2') as r:
        assert r.ros.wait_until(lambda: r.node.client.is_open, 5.0)
        r.twist(0.0, 0.4 / 0.33)  # wheels -0.2 / +0.2 m/s = -10 / +10 units of 20 mm/s
        assert r.ros.wait_until(lambda: r.device.commands_named('VEL2'), 2.0)
        got = r.device.commands_named('VEL2')[-1]
        assert got.raw == bytes.fromhex('FA FB 06 20 1B F6 09 16 24')  # p2os.md §4
        assert p2os.vel2_split(got.command.value) == (-10, 10)
        r.twist(0.3, 0.0)
        assert r.ros.wait_until(lambda: len(r.device.commands_named('VEL2')) == 2, 2.0)
        assert p2os.vel2_split(r.device.commands_named('VEL2')[-1].command.value) == (15, 15)
        assert not r.device.commands_named('VEL', 'RVEL')


def test_watchdog_stops_the_robot_when_cmd_vel_stops(tmp_path):
    with rig(tmp_path) as r:
        assert r.ros.wait_until(lambda: r.node.client.is_open, 5.0)
        last = r.drive(0.3, 0.0, 1.5)
        assert r.ros.wait_until(lambda: any(c.name == 'STOP' and c.time > last
                                            for c in list(r.device.commands)), 2.0)
        stop = next(c for c in r.device.commands if c.name == 'STOP' and c.time > last)
        delay = stop.time - last
        assert delay <= 0.6, f'STOP {delay:.3f} s after the last cmd_vel'
        assert delay >= 0.45  # not before the timeout either
        assert r.ros.wait_until(lambda: any(e == 'stopped' and t > stop.time
                                            for t, e in list(r.device.events)), 3.0)
        stopped = next(t for t, e in r.device.events if e == 'stopped' and t > stop.time)
        # from 0.3 m/s at the 0.3 m/s^2 deceleration the driver sent (SETA -300): 1 s
        assert stopped - stop.time == pytest.approx(1.0, abs=0.25)
        print(f'watchdog: STOP {delay:.3f} s after the last cmd_vel, wheels at rest '
              f'{stopped - last:.3f} s after it')


def test_watchdog_e_stop_has_the_wheels_at_rest_within_0_6_s(tmp_path):
    with rig(tmp_path, cmd_vel_timeout_action='e_stop') as r:
        assert r.ros.wait_until(lambda: r.node.client.is_open, 5.0)
        last = r.drive(0.3, 0.0, 1.5)
        assert r.ros.wait_until(lambda: any(e == 'stopped' and t > last
                                            for t, e in list(r.device.events)), 3.0)
        stopped = next(t for t, e in r.device.events if e == 'stopped' and t > last)
        assert not any(c.name == 'STOP' and c.time > last for c in r.device.commands)
        assert stopped - last <= 0.6, f'wheels at rest {stopped - last:.3f} s after cmd_vel'
        print(f'watchdog e_stop: wheels at rest {stopped - last:.3f} s after the last cmd_vel')


def test_enable_motors_service_and_diagnostics(tmp_path):
    with rig(tmp_path) as r:
        diag = r.ros.collect('/diagnostics', DiagnosticArray)
        assert r.ros.wait_until(lambda: r.node.client.is_open and r.device.motors_enabled, 5.0)
        helper = r.ros.add_node(rclpy.create_node('srv_client', context=r.ros.context))
        client = helper.create_client(SetBool, '/base_driver/enable_motors')
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(SetBool.Request(data=False))
        assert r.ros.wait_until(future.done, 3.0) and future.result().success
        assert r.ros.wait_until(lambda: not r.device.motors_enabled, 1.0)
        assert [c.name for c in r.device.commands[-2:]] == ['STOP', 'ENABLE']

        def robot(key=1):
            entry = level(diag[-1], 'base_driver: robot') if diag else None
            return entry[key] if entry else None
        assert r.ros.wait_until(lambda: (robot(2) or {}).get('motors') == 'disabled', 2.0)
        assert robot(0) == 0  # disabled on request: not a problem
        future = client.call_async(SetBool.Request(data=True))
        assert r.ros.wait_until(future.done, 3.0) and future.result().success
        assert r.ros.wait_until(lambda: r.device.motors_enabled, 1.0)
        assert r.ros.wait_until(lambda: (robot(2) or {}).get('motors') == 'enabled', 2.0)
        r.device.motors_enabled = False  # e.g. the MOTORS button
        assert r.ros.wait_until(lambda: 'motors disabled' in (robot() or ''), 2.0)
        assert robot(0) == 1
        r.device.motors_enabled = True

        def robot_says(text):
            return lambda: text in (robot() or '')
        r.device.battery_v = 11.5
        assert r.ros.wait_until(robot_says('battery low 11.5 V'), 2.0)
        r.device.battery_v = 10.5
        assert r.ros.wait_until(robot_says('battery 10.5 V'), 2.0)
        assert level(diag[-1], 'base_driver: robot')[0] == 2
        assert level(diag[-1])[0] == 0  # the link itself is fine


def test_bad_parameters_are_refused(tmp_path):
    with RosHarness() as ros:
        for name, value in (('command_mode', 'vel3'), ('robot_model', 'p9'),
                            ('port', ' '), ('baud', 1234)):
            with pytest.raises(ParameterError, match=name):
                BaseDriver(context=ros.context,
                           parameter_overrides=[Parameter(name, value=value)])
        # a value out of the declared range: one line with the range, as the offline tools
        with pytest.raises(ParameterError) as err:
            BaseDriver(context=ros.context, parameter_overrides=[Parameter('baud', value=-5)])
        assert str(err.value) == 'parameter baud = -5 is outside [0, 10000000]'


def input_counts(diag):
    """Return the values of the latest ``base_driver: input`` status ({} before one)."""
    for array in reversed(diag):
        entry = level(array, 'base_driver: input')
        if entry:
            return entry[2]
    return {}


def test_nan_cmd_vel_is_ignored(tmp_path):
    with rig(tmp_path) as r:
        diag = r.ros.collect('/diagnostics', DiagnosticArray)
        assert r.ros.wait_until(lambda: r.node.client.is_open, 5.0)
        r.twist(math.nan, 0.0)
        r.twist(0.1, math.inf)
        time.sleep(0.3)
        assert not r.device.commands_named('VEL', 'RVEL')
        r.twist(0.1, 0.0)
        assert r.ros.wait_until(lambda: r.device.commands_named('VEL'), 2.0)
        assert r.ros.wait_until(lambda: input_counts(diag).get('processed') == '1', 2.0)
        counts = input_counts(diag)
        assert counts['dropped.malformed'] == '2' and counts['dropped'] == '2'


def test_cmd_vel_without_robot_is_counted_as_not_connected(tmp_path):
    with rig(tmp_path, url=str(tmp_path / 'no_robot')) as r:
        diag = r.ros.collect('/diagnostics', DiagnosticArray)
        r.twist(0.1, 0.0)
        r.twist(0.2, 0.0)
        assert r.ros.wait_until(lambda: input_counts(diag).get('dropped') == '2', 3.0)
        counts = input_counts(diag)
        assert counts['dropped.not_connected'] == '2' and counts['processed'] == '0'
        assert not r.node.client.is_open


# ------------------------------------------------------------------------- shutdown


def test_shutdown_sends_stop_and_close(tmp_path):
    with rig(tmp_path) as r:
        assert r.ros.wait_until(lambda: r.node.client.is_open, 5.0)
        r.drive(0.2, 0.0, 0.3)
        r.node.shutdown()
        assert r.ros.wait_until(lambda: r.device.state == WAIT_SYNC0, 2.0)
        assert [c.name for c in r.device.commands[-2:]] == ['STOP', 'CLOSE']
        assert not r.node.link.running


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_ctrl_c_sends_stop_and_close_over_tcp(sig, processes):
    device = P2osDevice(sonar_noise=False)
    with DeviceServer(device, tcp_port=0) as server:
        proc = processes.start(
            [sys.executable, '-m', 'landmark_nav.nodes.base_driver', '--ros-args',
             '-p', f'port:={server.url}', '-p', 'publish_tf:=false'],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=dict(os.environ))
        deadline = time.monotonic() + 15.0
        while not device.is_open and time.monotonic() < deadline:
            time.sleep(0.05)
        assert device.is_open, proc.stdout.read1().decode() if proc.poll() else ''
        time.sleep(0.3)
        proc.send_signal(sig)
        out, _ = proc.communicate(timeout=10.0)
        assert proc.returncode == 0, out.decode()
        names = [c.name for c in device.commands]
        assert names[-2:] == ['STOP', 'CLOSE'], names
        assert device.state == WAIT_SYNC0


def test_emulate_command_over_tcp(processes):
    proc = processes.start(
        [sys.executable, '-m', 'landmark_nav.tools.cli', 'emulate', 'p2os', '--link', '',
         '--tcp', '0', '--no-sonar-noise'], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True)
    try:
        lines = []
        reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
        reader.start()
        deadline = time.monotonic() + 15.0
        url = None
        while url is None and time.monotonic() < deadline:
            found = [re.search(r'socket://\S+', line) for line in list(lines)]
            url = next((m.group(0) for m in found if m), None)
            time.sleep(0.05)
        assert url, ''.join(lines)
        with RosHarness() as ros:
            node = BaseDriver(context=ros.context,
                              parameter_overrides=[Parameter('port', value=url)])
            ros.add_node(node)
            odom = ros.collect('/odom', Odometry)
            sonar = ros.collect('/sonar/range_3', Range)
            sonar4 = ros.collect('/sonar/range_4', Range)
            assert ros.wait_until(lambda: len(odom) >= 5 and sonar and sonar4, 10.0)
            assert node.client.robot.subclass == 'p2dx'
            # The robot stands at the emulator's default start pose: its noise-free ray
            # caster gives sonar 3 no echo (+inf, REP 117) and sonar 4 a wall at 4.67 m,
            # sent in raw units of 0.268 mm.
            still = P2osDevice(sonar_noise=False)
            truth = still.sonar_ring.true_ranges(still.true_pose[None, :])[0]
            assert truth[3] == math.inf and sonar[-1].range == math.inf
            assert sonar4[-1].range == pytest.approx(truth[4], abs=0.134e-3 + 1e-6)
    finally:
        exit_code = processes.stop(proc, signal.SIGINT, timeout=10.0)
    assert exit_code == 0, ''.join(lines)


# ------------------------------------------------------------------------- faults


def test_lost_packets_while_driving_keep_the_odometry(tmp_path):
    k = dict(zip(('k1', 'k2', 'k3'), TRUE_K))
    with rig(tmp_path, **k) as r:
        odom = r.ros.collect('/odom', Odometry)
        assert r.ros.wait_until(lambda: len(odom) >= 2, 5.0)
        start = np.array(r.device.sent[0].true_pose)
        r.drive(0.3, 0.2, 1.5)
        for _ in range(3):
            r.server.inject(Fault('drop'))
            r.drive(0.3, 0.2, 0.4)
        r.twist(0.0, 0.0)
        wait_still(r)
        assert r.node.client.lost_packets >= 3
        got = odometry_to_pose(odom[-1]).pose
        truth = relative(start, r.device.true_pose)
        # a lost packet is bridged with the next packet's wheel speeds (ramp: <= 3 mm)
        print(f'3 lost status packets while driving: odometry error '
              f'{1e3 * np.hypot(*(got[:2] - truth[:2])):.2f} mm, '
              f'{math.degrees(abs(got[2] - truth[2])):.3f} deg')
        assert got[:2] == pytest.approx(truth[:2], abs=0.005)
        assert got[2] == pytest.approx(truth[2], abs=0.005)


@pytest.fixture(scope='module')
def faulty(tmp_path_factory):
    """One emulator and driver for all fault kinds (short WARN hold)."""
    path = tmp_path_factory.mktemp('faults')
    with rig(path, problem_hold=1.0) as r:
        r.odom = timed(r.ros, '/odom', Odometry)
        r.diag = timed(r.ros, '/diagnostics', DiagnosticArray)
        yield r


FAULTS = [('garbage', 0.0), ('corrupt', 0.0), ('truncate', 0.0), ('drop', 0.0),
          ('silence', 1.0), ('vanish', 1.5)]


@pytest.mark.parametrize('kind,duration', FAULTS, ids=[k for k, _ in FAULTS])
def test_fault_is_survived_and_reported(faulty, kind, duration):
    r = faulty

    def status_since(t):
        """Return the connection statuses received after ``t`` (other arrays skipped)."""
        found = [level(m) for when, m in list(r.diag) if when > t]
        return [s for s in found if s is not None]
    assert r.ros.wait_until(lambda: (status_since(time.monotonic() - 0.25) or [(9,)])[-1][0]
                            == 0, 8.0), status_since(time.monotonic() - 1.0)
    injected = time.monotonic()
    r.server.inject(Fault(kind, duration))
    end = injected + duration
    assert r.ros.wait_until(lambda: any(s[0] in (1, 2) for s in status_since(injected)),
                            duration + 2.0), f'{kind}: no WARN/ERROR'
    bad = [s for s in status_since(injected) if s[0] in (1, 2)]
    assert r.ros.wait_until(lambda: any(t > end for t, _ in list(r.odom)), duration + 3.0)
    resumed = next(t for t, _ in list(r.odom) if t > end) - end
    assert resumed <= 2.0, f'{kind}: publishing resumed {resumed:.2f} s after the fault'
    assert r.ros.wait_until(lambda: (status_since(end) or [(9,)])[-1][0] == 0, 5.0), \
        f'{kind}: not OK after the fault: {status_since(end)[-3:]}'
    assert r.node.link.running
    print(f'{kind}: {bad[0]}; publishing {resumed:.2f} s after the fault ended')


# ------------------------------------------------------------------------- parameters file


def test_config_file_matches_declared_parameters_and_calibration_writes_it(tmp_path):
    values = parameter_file(REPO, 'base_driver')
    with RosHarness() as ros:
        node = BaseDriver(context=ros.context)
        declared = declared_parameters(node)
        node.destroy_node()
    assert set(values) == set(declared)
    for name, value in values.items():
        if isinstance(value, float):
            assert declared[name] == pytest.approx(value, abs=1e-6)
        else:
            assert declared[name] == value
    copy = tmp_path / 'base_driver.yaml'
    shutil.copy(REPO / 'config' / 'base_driver.yaml', copy)
    write_base_driver_params(copy, {'k1': 0.998, 'k2': 1.002, 'k3': 1.01})
    written = yaml.safe_load(copy.read_text())['base_driver']['ros__parameters']
    assert (written['k1'], written['k2'], written['k3']) == (0.998, 1.002, 1.01)
    assert {k: v for k, v in written.items() if k not in ('k1', 'k2', 'k3')} == \
        {k: v for k, v in values.items() if k not in ('k1', 'k2', 'k3')}
    with RosHarness() as ros:
        node = BaseDriver(context=ros.context, parameter_overrides=[
            Parameter(k, value=v) for k, v in written.items()])
        assert node.odometry.k == (0.998, 1.002, 1.01)
        node.destroy_node()
