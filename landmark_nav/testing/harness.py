"""Run ROS nodes in-process, feed them a bag and collect what they publish.

Isolation from other DDS traffic: :func:`isolate_dds` puts this process (and the
subprocesses it starts with ``os.environ``) on a domain id of its own with discovery
restricted to localhost, so parallel test runs and robots on the network never meet.
"""

import fcntl
import os
from pathlib import Path
import tempfile
import threading
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple

from landmark_nav.bag import BagReader, message_class
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


_DOMAINS = range(20, 100)  # clear of the default domain 0 and of the port-range limit
# (lock directory, domain id) -> the open lock file that holds it
_claimed: Dict[Tuple[str, int], Any] = {}


def claim_domain(start: int, lock_dir: Optional[Path] = None) -> int:
    """Return a DDS domain id no other process on this machine holds, and hold it.

    Each domain of 20..99 has a lock file; the first one from ``start`` on (wrapping)
    whose ``flock`` can be taken is held until this process exits. Two test runs that
    would share a domain (their pids equal modulo 80) would otherwise discover each
    other's nodes and mix their topics.

    Raises:
        RuntimeError: every domain is held by another process.
    """
    lock_dir = Path(lock_dir or tempfile.gettempdir())
    count = len(_DOMAINS)
    for k in range(count):
        domain_id = _DOMAINS[(start - _DOMAINS[0] + k) % count]
        key = (str(lock_dir.resolve()), domain_id)
        if key in _claimed:
            return domain_id
        handle = open(lock_dir / f'landmark_nav-dds-domain-{domain_id}.lock', 'a')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _claimed[key] = handle
        return domain_id
    raise RuntimeError(f'all DDS domains {_DOMAINS[0]}..{_DOMAINS[-1]} are held by other '
                       f'processes (lock files in {lock_dir})')


def isolate_dds(domain_id: Optional[int] = None) -> int:
    """Use a private DDS domain on localhost only.

    Without ``domain_id`` the domain is claimed with :func:`claim_domain`, starting from
    one derived from the pid, so concurrent runs on one machine never share a domain.
    """
    if domain_id is None:
        domain_id = claim_domain(_DOMAINS[0] + os.getpid() % len(_DOMAINS))
    os.environ['ROS_DOMAIN_ID'] = str(domain_id)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.pop('ROS_LOCALHOST_ONLY', None)
    os.environ.pop('ROS_STATIC_PEERS', None)
    return domain_id


def reliable_qos(depth: int = 10000, latched: bool = False) -> QoSProfile:
    """Return a reliable QoS deep enough that a test never drops a message."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def declared_parameters(node: Node) -> Dict[str, Any]:
    """Return the values of the parameters a node declared (without rclpy's own)."""
    return {name: p.value for name, p in node._parameters.items()
            if name not in ('use_sim_time', 'start_type_description_service')}


def parameter_file(repo: Path, node_name: str) -> Dict[str, Any]:
    """Return the ``ros__parameters`` of ``config/<node_name>.yaml`` in the repository."""
    import yaml
    config = yaml.safe_load((Path(repo) / 'config' / f'{node_name}.yaml').read_text())
    return config[node_name]['ros__parameters']


class RosHarness:
    """An rclpy context with a background executor, for tests.

    Example::

        with RosHarness() as ros:
            node = MyNode(context=ros.context)
            ros.add_node(node)
            out = ros.collect('/corners', PoseArray)
            ros.play('bags/office', topics=['/scan'])
            assert ros.wait_until(lambda: len(out) == n_scans, timeout=10)
    """

    def __init__(self) -> None:
        """Create (but do not start) the context."""
        self.context = Context()
        self._nodes: List[Node] = []
        self._executor: Optional[SingleThreadedExecutor] = None
        self._thread: Optional[threading.Thread] = None
        self._lock = threading.Lock()
        self._helper: Optional[Node] = None

    def __enter__(self) -> 'RosHarness':
        """Initialise rclpy in the private context and start spinning."""
        rclpy.init(context=self.context)
        self._executor = SingleThreadedExecutor(context=self.context)
        self._helper = Node('test_harness', context=self.context)
        self.add_node(self._helper)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        return self

    def _spin(self) -> None:
        while self.context.ok():
            try:
                self._executor.spin_once(timeout_sec=0.02)
            except Exception:  # context shut down while spinning
                if self.context.ok():
                    raise
                return

    def __exit__(self, exc_type, exc, tb) -> None:
        """Stop spinning, destroy the nodes and shut the context down."""
        rclpy.try_shutdown(context=self.context)
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        for node in self._nodes:
            node.destroy_node()

    def add_node(self, node: Node) -> Node:
        """Spin a node (created with ``context=harness.context``) in the background."""
        self._nodes.append(node)
        self._executor.add_node(node)
        return node

    def collect(self, topic: str, msg_class: type, qos: Optional[QoSProfile] = None) -> list:
        """Subscribe to a topic and return the list its messages are appended to."""
        received: list = []

        def callback(msg, sink=received):
            with self._lock:
                sink.append(msg)

        self._helper.create_subscription(msg_class, topic, callback, qos or reliable_qos())
        return received

    def wait_until(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Poll a condition until it holds or the timeout passes; return whether it held."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(0.01)
        return bool(predicate())

    def wait_for_subscribers(self, publishers: Iterable, timeout: float = 10.0) -> bool:
        """Wait until every publisher is matched by at least one subscription."""
        pubs = list(publishers)
        return self.wait_until(lambda: all(p.get_subscription_count() > 0 for p in pubs),
                               timeout)

    def play(self, bag_path, topics: Optional[Iterable[str]] = None,
             rate: Optional[float] = None,
             on_message: Optional[Callable[[str, int], None]] = None) -> Dict[str, int]:
        """Publish a bag's messages (raw CDR) from this process; return counts per topic.

        Args:
            bag_path: The rosbag2 directory.
            topics: Only these topics (default: all).
            rate: Recorded timing scaled by this factor; None publishes back to back.
            on_message: Called as ``on_message(topic, log_time_ns)`` after each publish,
                e.g. to wait for the node under test to catch up.

        """
        with BagReader(bag_path) as reader:
            infos = reader.topics()
            names = list(topics) if topics is not None else sorted(infos)
            pubs = {
                name: self._helper.create_publisher(
                    message_class(infos[name].type_name), name,
                    reliable_qos(latched=infos[name].latched))
                for name in names}
            self.wait_for_subscribers(pubs.values())
            counts = dict.fromkeys(names, 0)
            start_wall = time.monotonic()
            first = reader.start_ns
            for item in reader.messages(names):
                if rate is not None:
                    due = start_wall + (item.log_time_ns - first) / 1e9 / rate
                    time.sleep(max(0.0, due - time.monotonic()))
                pubs[item.topic].publish(item.data)
                counts[item.topic] += 1
                if on_message is not None:
                    on_message(item.topic, item.log_time_ns)
        return counts
