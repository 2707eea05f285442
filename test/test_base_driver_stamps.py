"""base_driver stamps: strictly increasing even when packets share an arrival time.

Under load two status packets are read in one chunk; the stamp is the ROS clock minus the
packet's age on the monotonic clock, and the two clocks are read apart, so the second
stamp came out 20 us before the first in a live run and ekf_slam restarted its map
("odometry went back in time").
"""

from landmark_nav.nodes import base_driver as module
from landmark_nav.nodes.base_driver import BaseDriver
from landmark_nav.testing import RosHarness
import numpy as np
import pytest
from rclpy.parameter import Parameter

pytestmark = pytest.mark.dds


def test_stamps_of_packets_read_together_increase(tmp_path, monkeypatch):
    with RosHarness() as ros:
        node = BaseDriver(context=ros.context, parameter_overrides=[
            Parameter('port', value=str(tmp_path / 'no_robot'))])
        ros.add_node(node)
        arrival = 1000.0
        ages = iter([0.001, 0.003, 0.0031, 0.5])  # the second read found the process late
        monkeypatch.setattr(module.time, 'monotonic', lambda: arrival + next(ages))
        stamps = [node._stamp_ns(arrival) for _ in range(3)]
    assert stamps[1] > stamps[0] and stamps[2] > stamps[1]
    assert stamps[1] - stamps[0] == 1000  # held 1 us after the first, not moved further


def test_cycle_clock_removes_the_arrival_jitter(tmp_path, monkeypatch):
    """Packets every 0.1 s on the robot's clock, arrivals late by 0-80 ms (some 300 ms)."""
    from landmark_nav.drivers.p2os_client import SipUpdate
    rng = np.random.default_rng(3)
    n = 200
    sent = 5000.0 + 0.1 * np.arange(n)
    delay = 0.004 + rng.exponential(0.02, n)
    delay[rng.random(n) < 0.05] += 0.3
    arrival = np.maximum.accumulate(sent + delay)  # a late packet holds up the next ones
    with RosHarness() as ros:
        node = BaseDriver(context=ros.context, parameter_overrides=[
            Parameter('port', value=str(tmp_path / 'no_robot'))])
        ros.add_node(node)
        clock = {'now': 0.0}
        monkeypatch.setattr(module.time, 'monotonic', lambda: clock['now'])
        stamps = []
        ros_now = node.get_clock().now().nanoseconds
        for k in range(n):
            clock['now'] = arrival[k]
            monkeypatch.setattr(node, 'get_clock', lambda k=k: _Clock(
                ros_now + int((arrival[k] - arrival[0]) * 1e9)))
            update = SipUpdate(status=None, cycles=1, lost=0, robot_pose=(0.0, 0.0, 0.0),
                               first=k == 0)
            stamps.append(node._stamp_ns(arrival[k], update))
    # stamp - send time, in the ROS clock: constant up to the floor of the delays
    host = ros_now + (sent - arrival[0]) * 1e9
    err = (np.array(stamps, dtype=float) - host) * 1e-9
    late = err[50:]  # after the filter's start-up (its hull needs 4 s)
    raw = delay[50:]
    assert raw.max() - raw.min() > 0.25  # the arrivals jitter by 0.3 s
    assert late.max() - late.min() < 0.003  # the stamps by less than 3 ms
    assert abs(np.median(late) - delay.min()) < 0.003  # at the lowest delay
    assert np.all(np.diff(stamps) > 0)


class _Clock:
    def __init__(self, ns):
        self.ns = ns

    def now(self):
        return self

    @property
    def nanoseconds(self):
        return self.ns
