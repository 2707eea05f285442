"""InputStats: every drop warning states the drop rate; the warnings stay throttled."""

import time

from landmark_nav.nodes.common import InputStats, LatencyHistogram, ProblemWarner
from landmark_nav.testing import RosHarness
import numpy as np
from rclpy.node import Node
from std_msgs.msg import String


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


def test_run_latency_percentiles_cover_the_whole_run_within_one_percent():
    """The soak's p95 came from the last 1000 inputs only (about 25 s of a 10-minute run)."""
    rng = np.random.default_rng(0)
    early = rng.uniform(0.050, 0.200, 2000)  # a slow start that the window has forgotten
    late = rng.uniform(0.001, 0.010, 20000)
    hist = LatencyHistogram()
    for x in np.concatenate([early, late]):
        hist.add(float(x))
    every = np.concatenate([early, late])
    for q in (50, 95, 99):
        exact = 1e3 * np.sort(every)[int(np.ceil(q / 100 * every.size)) - 1]
        assert exact <= hist.percentile_ms(q) <= 1.01 * exact, q
    assert hist.percentile_ms(95) > 50.0  # the early latencies are in the run's p95
    assert hist.percentile_ms(100) == 1e3 * every.max()
    assert LatencyHistogram().percentile_ms(95) == 0.0
    with RosHarness() as ros:
        node = Node('latency_probe', context=ros.context)
        stats = InputStats(node, ProblemWarner(node), period_s=60.0, window=1000)
        for x in every:  # received x seconds before its processing ends
            stats.processed(time.time_ns() - int(x * 1e9))
        values = {v.key: v.value for v in stats.status().values}
        assert float(values['latency_p95_ms']) < 12.0  # the window: the last 1000 only
        assert float(values['latency_run_p95_ms']) > 50.0
        node.destroy_node()


def test_messages_published_before_the_subscription_matched_are_reported():
    """A publisher that starts first sends messages the volatile subscription never gets.

    They were the soak's ~100-150 corner sets a run that no counter accounted for.
    """
    with RosHarness() as ros:
        node = ros.add_node(Node('match_probe', context=ros.context))
        stats = InputStats(node, ProblemWarner(node), period_s=60.0)
        got = []
        pub = ros._helper.create_publisher(String, 'early', 10)
        for k in range(7):
            pub.publish(String(data=str(k)))  # nobody listens yet
        stats.subscribe(String, 'early', got.append, 10)
        assert ros.wait_for_subscribers([pub])
        pub.publish(String(data='matched'))
        assert ros.wait_until(lambda: got, timeout=10.0)
        assert [m.data for m in got] == ['matched']
        values = {v.key: v.value for v in stats.status().values}
        assert values['before_match.early'] == '7' and values['dropped'] == '0'
        node.destroy_node()
