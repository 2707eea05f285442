"""InputStats: every drop warning states the drop rate; the warnings stay throttled."""

from landmark_nav.nodes.common import InputStats, ProblemWarner
from landmark_nav.testing import RosHarness
from rclpy.node import Node


class _Logger:
    """Records the warnings a ProblemWarner logs."""

    def __init__(self) -> None:
        self.messages = []

    def warning(self, message: str) -> None:
        self.messages.append(message)


def test_drop_warnings_state_the_drop_rate_and_stay_throttled():
    with RosHarness() as ros:
        node = Node('rate_probe', context=ros.context)
        warner = ProblemWarner(node)
        warner._logger = log = _Logger()
        stats = InputStats(node, warner, period_s=60.0)  # publish() called by hand
        for _ in range(90):
            stats.processed(1)
        stats.drop('lost', 'Lost 9 messages on scan', 9)
        stats.drop('no_odometry', 'Skipping corners: before the odometry')
        assert log.messages == [
            'Lost 9 messages on scan (drop rate: 9 of 99 inputs in this 60 s period (9.09 %), '
            '9 of 99 since start (9.09 %: lost 9))',
            'Skipping corners: before the odometry (drop rate: 10 of 100 inputs in this 60 s '
            'period (10 %), 10 of 100 since start (10 %: lost 9, no_odometry 1))']
        values = {v.key: v.value for v in stats.status().values}
        assert values['drop_rate_percent'] == '10.000' and values['dropped.lost'] == '9'
        stats.publish()  # a new period
        for _ in range(300):
            stats.processed(1)
        stats.drop('lost', 'Lost 100 messages on scan', 100)  # within the throttle period
        assert len(log.messages) == 2 and warner.count == 3
        warner._last.clear()  # the throttle period has passed
        stats.drop('lost', 'Lost 1 messages on scan')
        assert log.messages[-1] == (
            'Lost 1 messages on scan (drop rate: 101 of 401 inputs in this 60 s period '
            '(25.2 %), 111 of 501 since start (22.2 %: lost 110, no_odometry 1)) '
            '(1 more like this in the last 5 s)')
        node.destroy_node()
