"""The result line of ``landmark_nav pipeline replay``: what was played and how SLAM did.

While the replay runs, the launcher records ekf_slam's ``/pose`` (:class:`PoseRecorder`,
its own rclpy context in a thread). At the end one line says what was played (the bag, its
scans, the seconds the player took, the rate), how many poses ekf_slam published, and,
when the bag has a reference (``/ground_truth/odom``), their ATE: the positions against the
reference interpolated at their stamps, unaligned, as ``landmark_nav evaluate`` states it
first (``ATE RMSE``; the replayed poses are the offline run's). The recorder takes ``/pose``
from any publisher on the ROS domain; it lists the publishers it sees (every 0.5 s) and the
line names any other than one ``/ekf_slam``, whose poses would be mixed in. The outputs are topics;
the line names them (a user records them with ``ros2 bag record`` or scores the bag
offline with ``landmark_nav evaluate``).
"""

import threading
import time
from typing import List, Optional, Sequence, Set, Tuple

import numpy as np

#: ekf_slam's topics the replay leaves on the ROS graph (recorded by no one).
OUTPUTS = ('/pose', '/odometry', '/path', '/landmarks')


class PoseRecorder:
    """Collect ``/pose`` (PoseWithCovarianceStamped) in a thread: stamps and [x, y, yaw]."""

    def __init__(self, topic: str = '/pose') -> None:
        """Create the subscription in a context of its own and start spinning it."""
        import rclpy
        from geometry_msgs.msg import PoseWithCovarianceStamped
        from landmark_nav.conversions import pose_with_covariance_to_pose
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        self.stamps: List[int] = []
        self.poses: List[np.ndarray] = []
        self.topic = topic
        self.publishers: Set[Tuple[str, Tuple[int, ...]]] = set()  # (node, endpoint gid)
        self._context = rclpy.Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        self._node = rclpy.create_node('pipeline_result', context=self._context)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)

        def on_pose(msg) -> None:
            d = pose_with_covariance_to_pose(msg)
            self.stamps.append(d.stamp_ns)
            self.poses.append(np.asarray(d.pose, dtype=float))

        self._subscription = self._node.create_subscription(
            PoseWithCovarianceStamped, topic, on_pose,
            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name='pose recorder', daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        seen = 0.0
        while not self._stop.is_set():
            self._executor.spin_once(timeout_sec=0.1)
            if time.monotonic() - seen >= 0.5:
                seen = time.monotonic()
                self.publishers |= {
                    (f'{e.node_namespace.rstrip("/")}/{e.node_name}', tuple(e.endpoint_gid))
                    for e in self._node.get_publishers_info_by_topic(self.topic)
                    if e.node_name != '_NODE_NAME_UNKNOWN_'}  # not yet discovered

    def connected(self) -> bool:
        """Whether a publisher of the topic is matched (its poses from now on are received).

        The poses are volatile: those published before the match are not delivered, so the
        replay starts the player only once this holds (1159 of 1200 poses were counted on a
        loaded machine when the player started before).
        """
        return self._subscription.get_publisher_count() > 0

    def other_publishers(self) -> List[str]:
        """Return the publishers of the topic seen besides one ``/ekf_slam`` (node names)."""
        names = sorted(name for name, _ in self.publishers)
        if '/ekf_slam' in names:
            names.remove('/ekf_slam')
        return names

    def stop(self) -> Tuple[np.ndarray, np.ndarray]:
        """Stop recording; return the stamps (N,) [ns] and poses (N, 3)."""
        import rclpy
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._executor.shutdown()
        self._node.destroy_node()
        rclpy.try_shutdown(context=self._context)
        return (np.asarray(self.stamps, dtype=np.int64),
                np.asarray(self.poses, dtype=float).reshape(-1, 3))


def reference_ate(bag: str, stamps: np.ndarray, poses: np.ndarray) -> Optional[dict]:
    """Return ``{'rmse', 'max', 'poses'}`` [m] of the poses against the bag's reference.

    None when the bag has no ``/ground_truth/odom`` or no pose falls in its time span.
    """
    from landmark_nav.bag import BagReader
    from landmark_nav.evaluation.bags import read_track, REFERENCE_TOPIC
    from landmark_nav.evaluation.trajectory import position_errors_at, Trajectory
    with BagReader(bag) as reader:
        if REFERENCE_TOPIC not in reader.topics():
            return None
        ref_stamps, ref_poses = read_track(reader, REFERENCE_TOPIC)
    if len(ref_stamps) < 2 or len(stamps) == 0:
        return None
    _, err, _ = position_errors_at(Trajectory.from_planar(ref_stamps, ref_poses), stamps,
                                   poses)
    if err.size == 0:
        return None
    return {'rmse': float(np.sqrt(np.mean(err ** 2))), 'max': float(err.max()),
            'poses': int(err.size)}


def result_line(bag: str, rate: float, scans: Optional[int], played_s: Optional[float],
                stamps: np.ndarray, poses: np.ndarray, ate: Optional[dict],
                others: Sequence[str] = ()) -> str:
    """Return the replay's one-line result (module docstring).

    Args:
        bag: The bag as given.
        rate: The replay rate.
        scans: The bag's ``/scan`` count (None: unknown, or a looped replay).
        played_s: Seconds from the player's start to its end (None: it did not end by
            itself).
        stamps: Stamps of the poses received [ns].
        poses: The poses received (N, 3).
        ate: :func:`reference_ate` (None: no reference, or not computed).
        others: Other publishers of ``/pose`` (:meth:`PoseRecorder.other_publishers`).
    """
    played = f'{scans} scans' if scans is not None else 'its scans'
    when = (f'played in {played_s:.1f} s at rate {rate:g}' if played_s is not None
            else 'stopped before its end')
    if ate is not None:
        figure = (f'; ATE RMSE {100 * ate["rmse"]:.2f} cm (max {100 * ate["max"]:.2f} cm) '
                  'against /ground_truth/odom')
    elif played_s is not None and len(stamps):
        figure = '; not scored (no /ground_truth/odom in the bag over their stamps)'
    else:
        figure = ''
    mixed = (f' (/pose also published by {", ".join(others)}: their poses are counted too)'
             if others else '')
    return (f'replay: {bag}, {played} {when}; ekf_slam published {len(stamps)} poses'
            f'{mixed}{figure}; outputs on {", ".join(OUTPUTS)} (not recorded)')


__all__ = ['OUTPUTS', 'PoseRecorder', 'reference_ate', 'result_line']
