"""Executable ``bag_player``: publish a rosbag2 (MCAP) bag into the ROS graph.

Like ``ros2 bag play``: recorded timing scaled by a rate factor, a start offset, a topic
filter, optional /clock and looping. Messages go out as the recorded CDR bytes, so the
original header stamps are kept exactly. Latched topics (transient local in the bag's QoS)
are published transient local; with a start offset, the last message of each latched topic
before the offset is published at the start (a late joiner still gets the map or ground
truth).

Unlike ``ros2 bag play``, the first messages are not lost to DDS discovery by default: the
player waits up to ``--wait-for-subscribers`` seconds (default 5; discovery took about 3 s
on a loaded 2-core machine) until the subscribers already running in the ROS graph on the
played topics are connected (with ``--topics``: until each named topic has one), then
plays; with no subscriber at all it plays after that time (a warning says so).
``--wait-for-subscribers 0`` starts at once, like ``ros2 bag play``. SIGINT (Ctrl-C) and
SIGTERM stop playing cleanly. Also available as ``landmark_nav replay``.
"""

import argparse
from collections import Counter
import signal
import sys
import threading
import time
from typing import List, Optional

from landmark_nav.bag import BagError, BagReader, message_class
from landmark_nav.conversions import ns_to_stamp
from landmark_nav.nodes.common import destroy_and_shutdown, reject_undeclared
from landmark_nav.replay import due_after_start_s, ReplayOptions
from landmark_nav.stop_signals import STOP_SIGNALS
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the replay options to an argument parser (shared with ``landmark_nav replay``)."""
    parser.add_argument('bag', help='rosbag2 directory (or .mcap file)')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='playback speed factor (default 1)')
    parser.add_argument('--start-offset', type=float, default=0.0,
                        help='start this many seconds into the bag')
    parser.add_argument('--topics', nargs='+', default=None, help='only these topics')
    parser.add_argument('--loop', action='store_true', help='play again at the end')
    parser.add_argument('--clock', type=float, nargs='?', const=100.0, default=0.0,
                        metavar='HZ', help='publish /clock (default 100 Hz when given)')
    parser.add_argument('--delay', type=float, default=0.0,
                        help='seconds to wait before the first message')
    parser.add_argument('--wait-for-subscribers', type=float, default=5.0, metavar='SECONDS',
                        help='wait up to this long (default 5) until the running subscribers '
                        'of the played topics are connected, so the first messages are not '
                        'lost; 0 = start at once like ros2 bag play')
    parser.add_argument('--min-subscribers', nargs='+', default=[], metavar='TOPIC=N',
                        help='the wait also needs N matched subscribers on TOPIC (nodes '
                        'still starting are not in the graph yet)')


def options_from_args(args: argparse.Namespace) -> ReplayOptions:
    """Build validated ReplayOptions from parsed arguments."""
    return ReplayOptions(rate=args.rate, start_offset_s=args.start_offset,
                         topics=tuple(args.topics) if args.topics else None,
                         loop=args.loop, clock_hz=args.clock, delay_s=args.delay,
                         wait_for_subscribers_s=args.wait_for_subscribers,
                         min_subscribers=tuple(_topic_count(t) for t in args.min_subscribers))


def _topic_count(text: str):
    """Parse ``TOPIC=N`` (``--min-subscribers``)."""
    topic, sep, n = text.rpartition('=')
    if not (sep and topic and n.isdigit()):
        raise ValueError(f'--min-subscribers {text!r}: expected TOPIC=N')
    return topic, int(n)


class BagPlayer(Node):
    """Publish the messages of one bag at recorded timing."""

    def __init__(self, bag_path: str, options: ReplayOptions) -> None:
        """Open the bag and create one publisher per played topic.

        Raises:
            BagError: The bag cannot be read or lacks a requested topic.

        """
        super().__init__('bag_player')
        self.bag_path = bag_path
        self.options = options
        with BagReader(bag_path) as reader:
            topics = reader.topics()
        wanted = options.topics or tuple(sorted(topics))
        missing = [t for t in wanted if t not in topics]
        if missing:
            raise BagError(f'{bag_path} has no topic {", ".join(missing)}')
        self._topic_publishers = {}
        self._latched = {name for name in wanted if topics[name].latched}
        for name in wanted:
            info = topics[name]
            qos = QoSProfile(
                history=HistoryPolicy.KEEP_LAST,
                depth=1 if info.latched else 1000,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=(DurabilityPolicy.TRANSIENT_LOCAL if info.latched
                            else DurabilityPolicy.VOLATILE))
            self._topic_publishers[name] = self.create_publisher(
                message_class(info.type_name), name, qos)
        self._clock_pub = (self.create_publisher(Clock, '/clock', 10)
                           if options.clock_hz > 0 else None)
        self.topic_counts: Counter = Counter()  # messages published per topic
        self._last_clock_ns = 0
        self.stopped = threading.Event()  # set by a stop signal: sleeps end at once

    def _connected(self) -> bool:
        """Return whether the subscribers are connected (see :class:`ReplayOptions`).

        Some played topic is subscribed (every one when ``--topics`` names them) and every
        subscriber the ROS graph knows on a played topic is matched.
        """
        matched = {t: p.get_subscription_count() for t, p in self._topic_publishers.items()}
        wanted = all if self.options.topics else any
        return wanted(matched.values()) and all(
            matched[t] >= self.count_subscribers(t) for t in matched) and all(
            matched.get(t, 0) >= n for t, n in self.options.min_subscribers)

    def wait_for_subscribers(self, settle_s: float = 0.2) -> bool:
        """Wait until the running subscribers are connected, up to the configured time.

        Returns:
            Whether they were (the condition held for ``settle_s`` in a row).

        """
        now = time.monotonic()
        deadline, since = now + self.options.wait_for_subscribers_s, None
        while now < deadline and rclpy.ok():
            if not self._connected():
                since = None
            elif since is None:
                since = now
            elif now - since >= settle_s:
                return True
            self.stopped.wait(0.02)
            now = time.monotonic()
        if not any(p.get_subscription_count() for p in self._topic_publishers.values()):
            self.get_logger().warning(
                f'No subscriber on the played topics after '
                f'{self.options.wait_for_subscribers_s:g} s; playing')
            return False
        return self._connected()

    def _publish_clock(self, bag_ns: int) -> None:
        """Publish /clock, never going backwards within one pass over the bag."""
        bag_ns = max(bag_ns, self._last_clock_ns)
        self._last_clock_ns = bag_ns
        msg = Clock()
        msg.clock = ns_to_stamp(bag_ns)
        self._clock_pub.publish(msg)

    def _sleep_until(self, wall_due: float, due_log_ns: int, wall_start: float,
                     first_ns: int) -> None:
        """Sleep until a message is due, ticking /clock in bag time (not past it) meanwhile."""
        period = 1.0 / self.options.clock_hz if self._clock_pub else None
        offset_ns = int(round(self.options.start_offset_s * 1e9))
        while rclpy.ok():
            remaining = wall_due - time.monotonic()
            if remaining <= 0:
                return
            if period is None:
                self.stopped.wait(remaining)
                return
            self.stopped.wait(min(remaining, period))
            elapsed_ns = int((time.monotonic() - wall_start) * self.options.rate * 1e9)
            self._publish_clock(min(first_ns + offset_ns + elapsed_ns, due_log_ns))

    def _publish(self, item) -> None:
        """Publish one bag message on its topic and count it."""
        self._topic_publishers[item.topic].publish(item.data)
        self.topic_counts[item.topic] += 1

    @property
    def published(self) -> int:
        """Return the number of messages published so far (every topic, every loop)."""
        return sum(self.topic_counts.values())

    def summary(self) -> str:
        """Return 'N messages (TOPIC n, ...)': what was published, per topic."""
        per_topic = ', '.join(f'{t} {n}' for t, n in sorted(self.topic_counts.items()))
        return f'{self.published} messages ({per_topic or "none"})'

    def play_once(self) -> int:
        """Play the bag once; return the number of messages published."""
        count = 0
        with BagReader(self.bag_path) as reader:
            first_ns = reader.start_ns
            wall_start = time.monotonic()
            self._last_clock_ns = 0
            held = {}  # the last message of each latched topic before the start offset
            for item in reader.messages(tuple(self._topic_publishers)):
                due = due_after_start_s(item.log_time_ns, first_ns, self.options)
                if due < 0:
                    if item.topic in self._latched:
                        held[item.topic] = item
                    continue
                for old in sorted(held.values(), key=lambda m: m.log_time_ns):
                    self._publish(old)
                    count += 1
                held = {}
                self._sleep_until(wall_start + due, item.log_time_ns, wall_start, first_ns)
                if not rclpy.ok():
                    break
                if self._clock_pub:
                    self._publish_clock(item.log_time_ns)
                self._publish(item)
                count += 1
            for old in sorted(held.values(), key=lambda m: m.log_time_ns):
                self._publish(old)
                count += 1
        return count

    def play(self) -> int:
        """Play (looping if asked); return the total number of messages published."""
        if self.options.wait_for_subscribers_s > 0:
            self.wait_for_subscribers()
        if self.options.delay_s > 0:
            self.stopped.wait(self.options.delay_s)
        while rclpy.ok():
            self.play_once()
            if not self.options.loop:
                break
        return self.published


def _stopped(player: Optional[BagPlayer], bag: str) -> None:
    """Say what a player stopped by a signal had published (to stdout: rclpy is down)."""
    if player is not None:
        print(f'bag_player: stopped: published {player.summary()} from {bag}', flush=True)


def _stop_between_messages(player: BagPlayer) -> None:
    """Make SIGINT / SIGTERM shut the context down without raising in the player's thread.

    rclpy's own handlers end in a KeyboardInterrupt raised wherever the main thread is, also
    between a message's publish and its count (the count said one message less than the
    subscribers had). These handlers shut the context down and wake the player's sleeps; the
    play loop stops at its next check, between two messages. Only the main thread can
    install them (a player run in a thread is stopped by ``rclpy.shutdown``).
    """
    if threading.current_thread() is not threading.main_thread():
        return

    def stop(signum, frame):
        player.stopped.set()
        rclpy.try_shutdown()

    for sig in STOP_SIGNALS:
        signal.signal(sig, stop)


def run(bag: str, options: ReplayOptions, args: Optional[List[str]] = None) -> int:
    """Initialise rclpy, play the bag, shut down; return messages published."""
    rclpy.init(args=args)
    player = None
    try:
        player = BagPlayer(bag, options)
        _stop_between_messages(player)  # SIGINT / SIGTERM: playing stops, counts exact
        reject_undeclared(player)  # its options are arguments; -p names nothing here
        published = player.play()
        if rclpy.ok():
            # Give reliable transports a moment to deliver the tail of the stream.
            for pub in player._topic_publishers.values():
                pub.wait_for_all_acked(rclpy.duration.Duration(seconds=2.0))
            player.get_logger().info(f'Published {player.summary()} from {bag}')
        else:
            _stopped(player, bag)
        return published
    except (KeyboardInterrupt, ExternalShutdownException):
        _stopped(player, bag)
        return player.published if player else 0
    except Exception:
        if rclpy.ok():
            raise
        # A publish racing the shutdown by SIGINT / SIGTERM: stopped, not an error.
        _stopped(player, bag)
        return player.published if player else 0
    finally:
        destroy_and_shutdown(player)


def main(args: Optional[List[str]] = None) -> int:
    """Entry point of ``ros2 run landmark_nav bag_player <bag> [options]``."""
    argv = rclpy.utilities.remove_ros_args(args if args is not None else sys.argv)[1:]
    parser = argparse.ArgumentParser(prog='bag_player', description=__doc__.split('\n')[0])
    add_replay_arguments(parser)
    parsed = parser.parse_args(argv)
    try:
        options = options_from_args(parsed)
        run(parsed.bag, options, args)
    except (BagError, ValueError) as err:
        print(f'bag_player: error: {err}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
