"""Executable ``graph_slam``: the keyframe pose graph with loop closure (GTSAM iSAM2).

The back end of ``landmark_nav evaluate --backend graph``
(:mod:`landmark_nav.slam.keyframe_graph`) as a node: the same per-scan step,
:class:`~landmark_nav.slam.graph_scan_steps.GraphScanSteps`, fed from DDS instead of a bag,
so a bag replayed through the node gives the offline run's poses.

Subscribes ``odom`` (nav_msgs/Odometry; best effort, keep last 200, as ``ekf_slam``) and
``scan`` (sensor_msgs/LaserScan; best effort, keep last 80). Each scan's returns below
``max_range`` (laser frame) wait until the odometry covers the scan's stamp, then go with
the odometry interpolated there to the graph, in stamp order.

The back end runs in a worker thread: the subscriptions only convert and queue, so a slow
keyframe (a loop closure's search takes a fraction of a second) delays the outputs but
loses no scan; the queue holds up to ``max_queue_mb`` of scan points (beyond it the oldest
scan is dropped, ``dropped.queue_full``, with a warning). The result does not depend on the
timing: every scan is processed once, in stamp order, on the odometry around its stamp.

Publishes, per scan (stamp of the scan, frame ``map_frame``):

* ``pose`` (geometry_msgs/PoseWithCovarianceStamped): the scan's keyframe as the graph
  placed it then, composed with the odometry since, and the keyframe's iSAM2 marginal
  composed with the odometry's noise (the offline run's ``online`` trajectory);
* ``map_to_odom`` (geometry_msgs/TransformStamped, ``map_frame`` -> ``odom_frame``): the
  correction ``pose (+) (-)odometry`` (odometry in its frame as it came: after a bridged
  jump, ``pose (+) (-)bridged (+) offset``, :attr:`GraphStep.offset`); also broadcast on
  TF when ``publish_tf`` and tf2_ros is importable (a full ROS install);

and every ``display_period`` after a keyframe, while subscribed: ``path`` (nav_msgs/Path)
the keyframes as the graph places them now, every loop closure applied (the map's
trajectory). ``/diagnostics``: processed and dropped scans (:class:`InputStats`) with
``waiting`` (scans queued), ``keyframes``, ``loops.proposed``, ``loops.accepted``,
``loops.refused.<reason>`` and ``factors.<kind>`` (the motions between consecutive
keyframes: scan_matching, scan_verified, odometry).

Bad input, warned (throttled per kind, :class:`ProblemWarner`) and counted, the node keeps
running: odometry or scans that cannot be read (NaN fields, beam counts that do not match
the angles), with stamp 0 or a non-finite odometry pose (``dropped.malformed``), scans of
more than ``max_beams`` beams (``dropped.oversized``), scans or odometry older than what
was processed (``dropped.out_of_order``), scans older than the odometry kept
(``dropped.odometry_gone``). A failure of the back end is warned and counted too
(``dropped.backend_error`` when it cost a scan, the event ``backend_error`` otherwise) and
its worker goes on.
Scans stamped before the first odometry have no pose: counted as ``before_odometry`` (not
a drop, as ``ekf_slam``). Odometry is checked as ``ekf_slam`` checks it (parameters
``max_speed``, ``max_turn_rate``, ``jump_sigmas``, ``min_step_s``, ``max_backward_s``,
``restart_messages``): a jump beyond the motion model's bound is bridged (the event
``odometry.jump``, warned), a sample stamped in the future is withdrawn once the samples
after it continue those before it (``odometry.retracted``). A restarted odometry source (a
bag replayed in a loop: odometry more than ``max_backward_s`` back in time,
``restart_messages`` samples in a row) starts the graph over, as ``ekf_slam`` restarts its
filter (the event ``restart``, warned; the old run's scans not yet processed are dropped,
``dropped.restarted``, and so are the new run's scans that come before its
``restart_messages``-th odometry sample, ``dropped.out_of_order``; ``path`` then holds the
new graph's keyframes).
"""

import threading
import time

from diagnostic_msgs.msg import KeyValue
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, TransformStamped
from landmark_nav.conversions import (ConversionError, make_pose_with_covariance_stamped,
                                      make_transform, odometry_pose_covariance, set_covariance3,
                                      set_pose_2d, set_stamp)
from landmark_nav.geometry import compose, inverse
from landmark_nav.nodes.common import (declare, declare_table, InputStats, ParameterError,
                                       ProblemWarner, read_scan, reject_undeclared,
                                       require_stamp, run_node)
from landmark_nav.nodes.ekf_slam import FEATURE_SCAN_QOS, ODOM_QOS
from landmark_nav.slam.graph_configuration import (graph_parameters, graph_params,
                                                   odometry_check_parameters, odometry_limits)
from landmark_nav.slam.graph_scan_steps import GraphScanSteps, GraphStep
from landmark_nav.slam.odometry_noise_models import odometry_noise_model
from landmark_nav.slam.scan_matching import scan_points
from nav_msgs.msg import Odometry, Path as PathMsg
import numpy as np
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from sensor_msgs.msg import LaserScan

try:  # a full ROS install; the PyPI wheels have no tf2_ros
    from tf2_ros import TransformBroadcaster
except ImportError:  # pragma: no cover - depends on the install
    TransformBroadcaster = None

#: Drops of :class:`GraphScanSteps` that are not drops (no pose exists for such a scan).
NOT_DROPS = ('before_odometry',)
#: Odometry of :class:`GraphScanSteps` used other than as it came -> event (as ``ekf_slam``).
ODOMETRY_EVENTS = {'restart': 'restart', 'jump': 'odometry.jump',
                   'retracted': 'odometry.retracted'}
#: The worker waits this long for a scan the odometry covers before it looks again [s].
WAIT_S = 0.2


class GraphInputStats(InputStats):
    """:class:`InputStats` plus the queue, keyframes, loops and factors of the graph."""

    def status(self):
        """Return the input status with the graph's counts.

        The queue's counts are read under the node's lock, the graph's from the snapshot the
        worker takes after each step (the worker changes the graph outside the lock).
        """
        status = super().status()
        node = self._node
        with node._lock:
            values = {'waiting': node.steps.waiting,
                      'before_odometry': node.steps.counts['before_odometry']}
        values.update(node.graph_counts)
        status.values += [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        return status


def graph_counts(graph) -> dict:
    """Keyframes, loops (proposed, accepted, refused by reason) and factors of ``graph``."""
    values = {'keyframes': len(graph.keyframes),
              'loops.proposed': graph.loop_counts.proposed,
              'loops.accepted': graph.loop_counts.accepted}
    values.update({f'loops.refused.{k}': v
                   for k, v in sorted(graph.loop_counts.refused.items())})
    values.update({f'factors.{k}': v for k, v in sorted(graph.motions.items())})
    return values


class GraphSlamNode(Node):
    """Thin node: odometry + scans -> :class:`GraphScanSteps` (worker thread) -> outputs."""

    def __init__(self, **kwargs) -> None:
        """Declare the parameters, create subscriptions, publishers and the worker."""
        super().__init__('graph_slam', **kwargs)
        params = declare_table(self, graph_parameters(), graph_params)
        model = declare(self, 'odometry.model', 'pioneer', "the odometry's noise model: "
                        "pioneer, simulator or drift gains 'k_d=.. k_theta=.. k_dtheta=..' "
                        '(an imported bag states them)')
        try:
            noise = odometry_noise_model(model)
        except ValueError as err:
            raise ParameterError(f'parameter odometry.model: {err}') from None
        laser_pose = declare(self, 'laser_pose', [0.0, 0.0, 0.0],
                             'laser pose [x, y, yaw] in base_link')
        if len(laser_pose) != 3 or not np.all(np.isfinite(laser_pose)):
            raise ParameterError(f'parameter laser_pose: expected 3 finite numbers, got '
                                 f'{laser_pose!r}')
        self.max_beams = declare(self, 'max_beams', 20000, 'scans with more beams are dropped '
                                 'as oversized', (1, 100_000_000))
        buffer_s = declare(self, 'buffer_s', 60.0, 'odometry kept behind the newest sample '
                           '(and what the waiting scans need) [s]', (0.1, 3600.0))
        self.max_queue_bytes = declare(
            self, 'max_queue_mb', 256.0, 'scan points queued for the back end at most; beyond, '
            'the oldest scan is dropped [MiB]', (0.01, 1e6)) * 2 ** 20
        self.map_frame = declare(self, 'map_frame', 'map', 'frame of the estimates')
        self.odom_frame = declare(self, 'odom_frame', 'odom', 'frame of the odometry')
        publish_tf = declare(self, 'publish_tf', True, 'broadcast map -> odom when tf2_ros is '
                             'importable (it is also published on map_to_odom)')
        self.display_period = declare(self, 'display_period', 0.5, 'least period of the path '
                                      'topic (published after a keyframe) [s]', (0.01, 3600.0))
        limits = declare_table(self, odometry_check_parameters(), odometry_limits)
        reject_undeclared(self)
        self.warner = ProblemWarner(self)
        self.steps = GraphScanSteps(laser_pose, noise, params, buffer_s, self._on_drop,
                                    restart=True, limits=limits)
        self._generation = 0  # of the graph whose keyframes keyframe_stamps holds
        self.params = self.steps.graph.params
        self.graph_counts = graph_counts(self.steps.graph)  # replaced by the worker's snapshots
        self.stats = GraphInputStats(self, self.warner)
        quiet = PublisherEventCallbacks(use_default_callbacks=False)
        self.pub_pose = self.create_publisher(PoseWithCovarianceStamped, 'pose', 10,
                                              event_callbacks=quiet)
        self.pub_tf = self.create_publisher(TransformStamped, 'map_to_odom', 10,
                                            event_callbacks=quiet)
        self.pub_path = self.create_publisher(PathMsg, 'path', 10, event_callbacks=quiet)
        self.tf = (TransformBroadcaster(self) if publish_tf and TransformBroadcaster
                   else None)
        self.stats.subscribe(Odometry, 'odom', self.on_odom, ODOM_QOS)
        self.stats.subscribe(LaserScan, 'scan', self.on_scan, FEATURE_SCAN_QOS)
        self.odom_count = 0
        self.scan_count = 0
        self.keyframe_stamps = []
        self._received = {}  # scan stamp -> reception [ns] (latency)
        self._pose_msg = make_pose_with_covariance_stamped(0, self.map_frame, [0.0] * 3)
        self._path_due = False
        self._next_path = time.monotonic()
        self._lock = threading.Condition()
        self._stop = threading.Event()
        self._worker = threading.Thread(target=self._work, name='graph_slam back end',
                                        daemon=True)
        self._worker.start()
        self.get_logger().info(f'graph_slam: keyframes every {params.keyframe_distance:g} m or '
                               f'{params.keyframe_turn:g} rad, loops {params.loops}, odometry '
                               f'noise {model}')

    # ------------------------------------------------------------------ input
    def _on_drop(self, reason: str, message: str) -> None:
        """Report an input :class:`GraphScanSteps` did not use."""
        if reason in ODOMETRY_EVENTS:
            self.stats.event(ODOMETRY_EVENTS[reason], f'Odometry: {message}')
        elif reason in NOT_DROPS:
            self.stats.event(reason, f'Not processed: {message}')
        else:
            self.stats.drop(reason, f'Dropping {message}')

    def on_odom(self, msg: Odometry) -> None:
        """Buffer one odometry sample; wake the back end."""
        self.odom_count += 1
        try:
            t, pose, _ = odometry_pose_covariance(msg)
            require_stamp(t, 'Odometry')
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping odometry: {err}')
            return
        with self._lock:
            self.steps.add_odometry(t, pose)
            self._forget_dropped()
            self._lock.notify()

    def _forget_dropped(self) -> None:
        """Forget the reception times of scans the steps dropped from their queue (call locked).

        The waiting scans' times are kept until the worker takes them; the scans dropped
        while waiting (stamped before the first odometry, of a restarted source's old run)
        would otherwise stay in ``_received`` for good.
        """
        if len(self._received) > self.steps.waiting:
            waiting = set(self.steps.waiting_stamps)
            self._received = {t: r for t, r in self._received.items() if t in waiting}

    def on_scan(self, msg: LaserScan) -> None:
        """Queue one scan's returns (laser frame); wake the back end."""
        self.scan_count += 1
        scan = read_scan(msg, self.max_beams, self.stats)
        if scan is None:
            return
        pts = scan_points(scan.ranges, scan.angle_min, scan.angle_increment, scan.range_min,
                          min(scan.range_max, self.params.max_range))
        with self._lock:
            if self.steps.add_scan(scan.stamp_ns, pts):
                self._received[scan.stamp_ns] = self.stats.received_ns
            while self.steps.waiting_bytes > self.max_queue_bytes:
                t = self.steps.drop_oldest('queue_full', 'the scans waiting for the back end '
                                           f'take more than {self.max_queue_bytes / 2 ** 20:g} '
                                           f'MiB ({self._queue_cause()})')
                self._received.pop(t, None)
            self._lock.notify()

    def _queue_cause(self) -> str:
        """Say why scans pile up: no odometry (yet, or not past them) or a slow back end."""
        newest = self.steps.newest_odometry_ns
        if newest is None:
            return 'no odometry received yet: each scan waits for the odometry around its stamp'
        if self.steps.waiting and newest < self.steps.oldest_waiting_ns:
            return (f'the newest odometry, at {newest} ns, is older than every waiting scan: '
                    'each waits for the odometry around its stamp')
        return 'the back end is slower than the scans'

    # ------------------------------------------------------------------ back end
    def _stopping(self) -> bool:
        """Whether the node is going: destroyed, or its context shut down (SIGINT, SIGTERM)."""
        return self._stop.is_set() or not self.context.ok()

    def _work(self) -> None:
        """Process the scans the odometry covers, one at a time, until stopped.

        A failure is warned and counted (``dropped.backend_error`` when it cost a scan, the
        event ``backend_error`` otherwise) and the loop goes on: the back end never stops
        while the node runs. Once the node is going nothing is published or warned.
        """
        while not self._stopping():
            item = None
            try:
                with self._lock:
                    item = self.steps.pop_ready()
                    if item is None:
                        self._lock.wait(WAIT_S)
                    received = None if item is None else self._received.pop(item[0], None)
                if item is None:
                    self._publish_path()
                    continue
                step = self.steps.process(*item)
                self.graph_counts = graph_counts(self.steps.graph)
                if self._stopping():
                    return
                if step is None:  # the graph started over before it (counted)
                    continue
                if step.generation != self.steps.generation:  # ... while it was processed
                    self.stats.drop('restarted', f'Dropping scan at {step.stamp_ns} ns: of the '
                                    'odometry source before its restart')
                    continue
                self._publish(step)
            except Exception as err:  # the node keeps running; say what failed
                if self._stopping():  # shutting down: the publishers may be gone
                    return
                failure = f'{type(err).__name__}: {err}'
                if item is None:
                    self.stats.event('backend_error', f'The back end failed between scans '
                                     f'({failure})')
                else:
                    self.stats.drop('backend_error', f'Dropping scan at {item[0]} ns: the '
                                    f'back end failed ({failure})')
                continue
            self.stats.processed(received or 0)

    def _publish(self, step: GraphStep) -> None:
        """Publish one step's pose and the map -> odom correction."""
        msg = self._pose_msg
        set_stamp(msg.header, step.stamp_ns)
        set_pose_2d(msg.pose.pose, step.pose)
        msg.pose.covariance = set_covariance3(msg.pose.covariance, step.covariance)
        self.pub_pose.publish(msg)
        correction = compose(step.pose, inverse(step.odometry))
        if step.offset is not None:  # against the odometry frame as it came (bridged jumps)
            correction = compose(correction, step.offset)
        t = make_transform(step.stamp_ns, self.map_frame, self.odom_frame, correction)
        self.pub_tf.publish(t)
        if self.tf is not None:
            self.tf.sendTransform(t)
        if step.generation != self._generation:  # a new graph: its keyframes only
            self._generation = step.generation
            self.keyframe_stamps = []
        if step.new_keyframe:
            self.keyframe_stamps.append(step.stamp_ns)
            self._path_due = True
        self._publish_path()

    def _publish_path(self) -> None:
        """Publish the keyframes' current poses when due (module docstring)."""
        now = time.monotonic()
        if not self._path_due or now < self._next_path:
            return
        self._next_path = now + self.display_period
        self._path_due = False
        if self.pub_path.get_subscription_count():
            self.pub_path.publish(self.path_message())

    def path_message(self) -> PathMsg:
        """Return the keyframes as the graph places them now (call from the worker)."""
        path = PathMsg()
        path.header.frame_id = self.map_frame
        estimates = self.steps.graph.estimates
        for t, pose in zip(self.keyframe_stamps, estimates):
            ps = PoseStamped()
            set_stamp(ps.header, t)
            ps.header.frame_id = self.map_frame
            set_pose_2d(ps.pose, pose)
            path.poses.append(ps)
        if path.poses:
            path.header.stamp = path.poses[-1].header.stamp
        return path

    def destroy_node(self) -> None:
        """Stop the worker (it ends after its current step), then destroy the node."""
        self._stop.set()
        with self._lock:
            self._lock.notify()
        self._worker.join(timeout=1.5)
        super().destroy_node()


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav graph_slam``."""
    return run_node(GraphSlamNode, args)


if __name__ == '__main__':
    raise SystemExit(main())


__all__ = ['GraphSlamNode', 'main']
