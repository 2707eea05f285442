"""base_driver stamps: strictly increasing even when packets share an arrival time.

Under load two status packets are read in one chunk; the stamp is the ROS clock minus the
packet's age on the monotonic clock, and the two clocks are read apart, so the second
stamp came out 20 us before the first in a live run and ekf_slam restarted its map
("odometry went back in time").
"""

from landmark_nav.nodes import base_driver as module
from landmark_nav.nodes.base_driver import BaseDriver
from landmark_nav.testing import RosHarness
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
