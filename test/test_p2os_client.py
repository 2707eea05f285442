"""Host-side P2OS session logic and the calibrated wheel odometry (pure, no ROS)."""

import math

from landmark_nav.drivers import p2os
from landmark_nav.drivers.p2os_client import ClientConfig, CLOSING, OPEN, P2osClient, SYNC
from landmark_nav.localization.wheel_odometry import WheelOdometry
from landmark_nav.sim.robot import (dead_reckon, integrate, propagate_covariance, RobotParams,
                                    wheel_to_twist)
import numpy as np
import pytest

cmd = p2os.encode_command


def split(data):
    """Return the command names of a byte string of command packets."""
    out = p2os.P2osDecoder(parse=p2os.parse_command).feed(data)
    return [c.name for c in out]


def sip(x_mm=0.0, y_mm=0.0, th=0.0, left=0.0, right=0.0, params=p2os.P2DX):
    """Return a status packet for a robot state."""
    return p2os.status_from_state(x_mm, y_mm, th, left, right, 12.5, params)


def opened_client(now=0.0, **config):
    client = P2osClient(ClientConfig(**config))
    assert split(client.connect(now)) == ['PULSE']  # SYNC0 has code 0
    assert client.receive(p2os.SyncReply(0), now)[0] == cmd('SYNC1')
    assert client.receive(p2os.SyncReply(1), now)[0] == cmd('SYNC2')
    data, _ = client.receive(p2os.SyncReply(2, 'r', 'Pioneer', 'p2dx'), now)
    return client, data


def test_handshake_and_open_commands():
    client, data = opened_client(max_linear_speed=0.4, linear_decel=0.5, enable_motors=False,
                                 sonar=False)
    assert client.state == OPEN and client.robot.subclass == 'p2dx'
    names = split(data)
    assert names == ['OPEN', 'PULSE', 'SETV', 'SETRV', 'SETA', 'SETA', 'SETRA', 'SETRA',
                     'STOP', 'ENABLE', 'SONAR']
    values = [c.value for c in p2os.P2osDecoder(parse=p2os.parse_command).feed(data)]
    assert values[2] == 400 and values[5] == -500 and values[9:] == [0, 0]
    assert client.handshakes == 1


def test_auto_model_and_unknown_subclass():
    client = P2osClient()
    client.connect(0.0)
    client.receive(p2os.SyncReply(0), 0.0)
    client.receive(p2os.SyncReply(1), 0.0)
    client.receive(p2os.SyncReply(2, 'r', 'Pioneer', 'P3DX-SH'), 0.0)
    assert client.params is p2os.P3DX_SH
    other = P2osClient()
    other.connect(0.0)
    other.receive(p2os.SyncReply(0), 0.0)
    other.receive(p2os.SyncReply(1), 0.0)
    other.receive(p2os.SyncReply(2, 'r', 'Pioneer', 'x9'), 0.0)
    assert other.params is p2os.P2DX and 'unknown robot subclass' in other.pop_messages()[0]


def test_still_open_robot_gets_close_then_a_new_sync():
    client = P2osClient(ClientConfig(close_wait=0.3))
    client.connect(0.0)
    data, update = client.receive(sip(), 0.05)
    assert data == cmd('CLOSE') and update is None and client.state == CLOSING
    assert client.receive(sip(), 0.15) == (b'', None)  # drained
    assert client.tick(0.3) == b''
    assert client.tick(0.36) == cmd('SYNC0') and client.state == SYNC
    assert client.closes_sent == 1 and client.handshakes == 1


def test_sync_retries_and_dislodge():
    client = P2osClient(ClientConfig(sync_timeout=0.5))
    client.connect(0.0)
    assert client.tick(0.4) == b''
    assert client.tick(0.5) == cmd('SYNC0')
    assert client.tick(1.0) == cmd('SYNC0')
    assert client.tick(1.5) == cmd('CLOSE') + cmd('SYNC0')  # third retry
    assert client.sync_retries == 3
    assert client.receive(p2os.SyncReply(1), 1.6)[0] == cmd('SYNC0')  # wrong echo: restart


def test_keepalive_watchdog_and_lost_stream():
    client, _ = opened_client(cmd_timeout=0.5, pulse_period=1.0, sip_timeout=2.0)
    client.receive(sip(), 0.1)
    assert client.tick(0.5) == b''
    assert client.tick(1.0) == cmd('PULSE')
    assert client.velocity(0.25, -0.5, 1.05) == cmd('VEL', 250) + cmd('RVEL', -29)
    assert client.velocity(0.25, -0.5, 1.2) == b''  # unchanged, within resend_period
    client.receive(sip(), 1.2)
    assert client.tick(1.65) == b''  # 0.45 s after the last command
    assert client.tick(1.7) == cmd('STOP') and client.watchdog_stops == 1
    assert client.tick(1.8) == b''  # only once
    assert client.velocity(0.0, 0.0, 1.9) == cmd('VEL', 0) + cmd('RVEL', 0)
    client.receive(sip(), 1.9)
    assert client.tick(2.85) == b''
    assert client.tick(2.9) == cmd('PULSE')  # zero command: no watchdog STOP
    assert client.tick(4.0) == cmd('SYNC0') and client.state == SYNC  # no SIP for 2.1 s
    assert client.velocity(0.1, 0.0, 3.9) == b''  # not open


def test_velocity_limits_and_vel2():
    client, _ = opened_client(max_linear_speed=0.5, max_angular_speed=1.0)
    assert client.velocity(2.0, -5.0, 0.1) == cmd('VEL', 500) + cmd('RVEL', -57)
    with pytest.raises(ValueError, match='finite'):
        client.velocity(math.nan, 0.0, 0.2)
    vel2, _ = opened_client(command_mode='vel2', max_linear_speed=2.2, axle_length=0.33)
    assert vel2.velocity(0.0, 0.4 / 0.33, 0.1) == p2os.encode_vel2(-10, 10)
    assert vel2.velocity(2.2, 0.0, 0.2) == p2os.encode_vel2(110, 110)
    big, _ = opened_client(command_mode='vel2', max_linear_speed=2.2, max_angular_speed=8.0)
    assert big.velocity(2.2, 8.0, 0.1) == p2os.encode_vel2(44, 127)  # right wheel clamped
    assert big.farewell() == cmd('STOP') + cmd('CLOSE')


def test_set_motors_sends_stop_first():
    client = P2osClient(ClientConfig(enable_motors=False))
    assert client.set_motors(True, 0.0) == b''  # remembered for the next OPEN
    client.connect(0.0)
    client.receive(p2os.SyncReply(0), 0.0)
    client.receive(p2os.SyncReply(1), 0.0)
    data, _ = client.receive(p2os.SyncReply(2, 'r', 'Pioneer', 'p2dx'), 0.0)
    decoded = p2os.P2osDecoder(parse=p2os.parse_command).feed(data)
    assert (decoded[-2].name, decoded[-2].value) == ('ENABLE', 1)
    assert client.set_motors(False, 0.1) == cmd('STOP') + cmd('ENABLE', 0)


def test_lost_status_packets_are_counted_from_the_robot_odometry():
    client, _ = opened_client(axle_length=0.33)
    first = client.receive(sip(0.0, 0.0, 0.0, 300, 300), 0.1)[1]
    assert first.first and first.cycles == 1
    step = client.receive(sip(30.0, 0.0, 0.0, 300, 300), 0.2)[1]
    assert step.cycles == 1 and step.lost == 0 and step.robot_pose[0] == pytest.approx(
        round(30 / 0.84) * 0.84e-3)
    two_lost = client.receive(sip(120.0, 0.0, 0.0, 300, 300), 0.5)[1]
    assert two_lost.cycles == 3 and two_lost.lost == 2
    turn = client.receive(sip(120.0, 0.0, math.radians(10.0), -100, 100), 0.7)[1]
    per_cycle = 200 / 330 * 0.1  # rad
    assert turn.cycles == round(math.radians(10.0) / per_cycle)
    still = client.receive(sip(120.0, 0.0, math.radians(10.0)), 1.0)[1]
    assert still.cycles == 1 and still.lost == 2  # at rest: counted from arrival times only
    assert client.lost_packets == 2 + turn.lost + 2


# ------------------------------------------------------------------------- wheel odometry


def test_wheel_odometry_matches_the_simulator_model():
    params = RobotParams()
    rng = np.random.default_rng(3)
    speeds = np.cumsum(rng.normal(0.0, 0.3, (200, 2)), axis=0)  # rad/s, wandering
    k = (params.k1, params.k2, params.k3)
    odo = WheelOdometry(params.wheel_radius, params.axle_length, k,
                        params.odom_sigma_distance, params.odom_sigma_heading_per_distance,
                        params.odom_sigma_heading_per_rotation)
    poses = [odo.pose.copy()]
    covs = [odo.covariance.copy()]
    for w in speeds:
        odo.update_wheels(w[0], w[1], params.sample_time)
        poses.append(odo.pose.copy())
        covs.append(odo.covariance.copy())
    expected = dead_reckon((0.0, 0.0, 0.0), speeds, params, k)  # eqs. 1-7, 17-18
    poses = np.array(poses)
    assert poses[:, :2] == pytest.approx(expected[:, :2], abs=1e-9)
    assert np.allclose(np.cos(poses[:, 2] - expected[:, 2]), 1.0)
    v, w = wheel_to_twist(speeds[:, 0], speeds[:, 1], k[0] * params.wheel_radius,
                          k[1] * params.wheel_radius, k[2] * params.axle_length)
    ref = propagate_covariance(integrate((0, 0, 0), v, w, params.sample_time), v, w,
                               params.sample_time, params)
    assert np.allclose(np.array(covs), ref, rtol=1e-9, atol=1e-15)
    assert odo.wheel_angles == pytest.approx(speeds.sum(axis=0) * params.sample_time)
    assert odo.twist == pytest.approx([v[-1], w[-1]])
    still = odo.covariance.copy()
    odo.update_wheels(0.0, 0.0, 0.1)
    assert np.array_equal(odo.covariance, still)  # no growth at rest


def test_wheel_odometry_from_poses_and_bad_input():
    odo = WheelOdometry(0.1, 0.3)
    odo.update_pose((0.1, 0.0, 0.0), 0.1, (1.0, 1.0))
    odo.update_pose((0.2, 0.05, 0.5), 0.1)
    assert odo.pose == pytest.approx([0.2, 0.05, 0.5])
    assert odo.covariance[2, 2] > 0 and odo.wheel_angles == pytest.approx([0.1, 0.1])
    with pytest.raises(ValueError, match='finite'):
        odo.update_wheels(math.nan, 0.0, 0.1)
    with pytest.raises(ValueError, match='dt'):
        odo.update_wheels(0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match='k1'):
        WheelOdometry(0.1, 0.3, (1.0, -1.0, 1.0))
