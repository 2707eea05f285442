"""InputStats: a node that drops inputs warns with the drop rate (throttled) and reports it."""

from landmark_nav.nodes.common import InputStats, ProblemWarner
from landmark_nav.testing import RosHarness
from rclpy.node import Node


class _Logger:
    """Records the warnings a ProblemWarner logs."""

    def __init__(self) -> None:
        self.messages = []

    def warning(self, message: str) -> None:
        self.messages.append(message)


def test_drops_give_a_throttled_warning_with_the_drop_rate_and_a_diagnostic_value():
    with RosHarness() as ros:
        node = Node('rate_probe', context=ros.context)
        warner = ProblemWarner(node)
        warner._logger = log = _Logger()
        stats = InputStats(node, warner, period_s=60.0)  # publish() called by hand
        for _ in range(90):
            stats.processed(1)
        stats.drop('lost', 'Lost 9 messages on scan', 9)
        stats.drop('no_odometry', 'Skipping corners: before the odometry')
        stats.publish()
        assert log.messages[-1] == (
            'Dropped 10 of 100 inputs in the last 60 s (10 %); since start 10 of 100 '
            '(10 %: lost 9, no_odometry 1)')
        values = {v.key: v.value for v in stats.status().values}
        assert values['drop_rate_percent'] == '10.000' and values['dropped.lost'] == '9'
        n = len(log.messages)
        stats.publish()  # no drop since: no rate warning
        assert len(log.messages) == n
        for _ in range(300):
            stats.processed(1)
        stats.drop('lost', 'Lost 100 messages on scan', 100)
        stats.publish()  # the same kind of problem within the throttle period: suppressed
        assert len(log.messages) == n
        warner._last.clear()  # the throttle period has passed
        stats.drop('lost', 'Lost 1 messages on scan')
        stats.publish()
        assert log.messages[-1] == (
            'Dropped 1 of 1 inputs in the last 60 s (100 %); since start 111 of 501 '
            '(22.2 %: lost 110, no_odometry 1) (1 more like this in the last 5 s)')
        node.destroy_node()
