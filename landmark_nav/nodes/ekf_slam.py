"""Executable ``ekf_slam``: EKF-SLAM with corner and / or line landmarks.

The filter of the corner chapter (section 3); line landmarks:
:mod:`landmark_nav.slam.line_landmarks`.

Subscribes:

* ``odom`` (nav_msgs/Odometry; best-effort, keep last 200: it takes reliable and
  best-effort publishers alike and does not lose samples in a burst);
* ``corners/features`` (sensor_msgs/PointCloud2 from ``corner_extractor``; with
  ``landmarks`` ``corners`` or ``both``). Not the ``corners`` PoseArray: the cloud carries
  each corner's 2x2 position covariance (the observation noise ``R``), its opening angle
  and bisector (the association's descriptors) and its beam time (the de-skew); with
  ``structural_corners_only`` only the corners it labels structural (field ``structural``)
  are used;
* ``scan`` (sensor_msgs/LaserScan, sensor-data QoS; with ``landmarks`` ``lines`` or
  ``both``, or ``visibility``): the line landmarks are extracted from it here with
  :func:`landmark_nav.slam.features.extract_scan_features` (parameters ``lines.*``, those
  of ``line_extractor``), the function the offline evaluation calls: the ``lines`` cloud of
  ``line_extractor`` has float32 values and no beam indices (no de-skew), and that node
  drops clusters under ``segmentation.min_points`` beams, where SLAM's lines grow over
  isolated returns of their wall. The scan's geometry also gives the visibility-aware
  pruning (:mod:`landmark_nav.slam.visibility`; ``laser_sigma_range``).

The corner cloud and the scan of one stamp make one feature set
(:class:`~landmark_nav.nodes.stamp_join.StampJoin`); a set whose scan (or corner cloud)
is lost (a later one came) goes on without it, with a warning (no pruning evidence, no
lines; or no corners); while a topic has no publisher the sets go on without its part
(noted once in the log: e.g. ``visibility`` on but no ``scan``).

Everything between the messages and the filter is :class:`~landmark_nav.slam.frontend.
SlamFrontend`, the same code :func:`landmark_nav.evaluation.slam.run_slam` runs offline: the
odometry buffer and its checks (repeated, backward and implausible stamps; an ``/odom`` gap
is waited for, a discontinuity bridged, the map never reset by the data), each corner set
waiting until the odometry covers its last beam, interpolation at the stamp, de-skew,
prediction, association, update. When no odometry has come for ``odometry_timeout``
seconds (wall clock) the sets the odometry reaches are processed holding its last pose for
later beams. Corner sets arriving out of order are processed in stamp order; a set older
than the last processed step is skipped.

Publishes (frame ``map_frame``, stamp of the corner set): ``pose``
(PoseWithCovarianceStamped) and ``odometry`` (nav_msgs/Odometry, child ``base_frame``) per
step (two reused messages, filled in place); ``path`` (nav_msgs/Path: the last
``path_max_poses`` poses) and ``landmarks`` (MarkerArray: 2-sigma ellipses of corners, the
seen extent of lines) every ``display_period`` seconds when they have changed and have a
subscriber, so the cost per step and the memory do not grow with the length of the run
(path poses are built at display time, the new ones only). The outputs have no rclpy
default QoS-event handlers and each subscription only the incompatible-QoS warning: every
handler is a waitable the executor scans at each wait (``benchmarks/bench_node_cpu.py``).

Services (std_srvs/Trigger): ``save_map`` writes the landmarks and their covariances as
YAML to parameter ``map_file`` (a relative name is under ``$ROS_HOME/landmark_nav``,
``~/.ros/landmark_nav`` by default), or, for a ``.npz`` name, the filter's map in the
:mod:`landmark_nav.slam.slam_map` format; ``reset`` restarts the filter at the next
odometry.

Map reuse: parameter ``load_map`` (a ``.npz`` map: ``save_map`` above or ``landmark_nav
evaluate --save-map``) starts the filter on that map at the first odometry pose (1-sigma
``map_pose_sigma``), again after a reset; with ``mode: localization`` it tracks the robot
on it without adding landmarks.

Parameters: :mod:`landmark_nav.slam.configuration` describes them all (defaults, limits,
choices) and builds the filter's and the front end's parameters from their values, for
this node and for ``landmark_nav evaluate``. The defaults are the configuration measured
on real logs (corners and lines, consistent heading, the free-space, recovery and
spurious-pair checks, the scan-matched motion fused with the odometry); the corner
chapter's filter is the profile ``config/ekf_slam_chapter.yaml``, given after
``config/ekf_slam.yaml``. A parameter the node does not declare is refused at start
(:func:`~landmark_nav.nodes.common.reject_undeclared`).

Odometry noise: the ``odometry.*`` parameters (defaults: the ``pioneer`` model of
:mod:`landmark_nav.slam.frontend`), or ``odometry.model`` = ``pioneer``, ``simulator`` or
the gains ``'k_d=.. k_theta=.. k_dtheta=..'`` an imported bag states.

Scan-matched motion: ``scan_matching: true`` (needs ``visibility``, i.e. the ``scan``
subscription) predicts each step with the point-to-line ICP motion of the scan against
the previous step's scan where it agrees with the odometry (``scan_matching_noise``,
``scan_matching_max_range``, ``scan_matching_accept``; with ``scan_matching_fit_pairs`` >
0 the odometry and that motion fused, its covariance from the ICP fit;
``scan_matching_side_starts``: ICP also from two headings beside the odometry's; the front end's
``FrontendParams``, as ``landmark_nav evaluate --scan-matching`` offline).

Bad input is reported with a warning throttled per kind of problem and counted on
``/diagnostics`` (:class:`~landmark_nav.nodes.common.InputStats`): dropped odometry that
cannot be read, is not finite or has stamp 0 (``dropped.malformed``), older than the last
sample (``dropped.out_of_order``) or repeated (``dropped.repeated``); odometry used but not
as it came: a jump beyond the motion model's bound, whatever covariance the message states
(bridged, ``odometry.jump``), a covariance that is not finite, symmetric, with a
non-negative diagonal and PSD (replaced by the ``odometry.*`` model,
``odometry.covariance_replaced``), held far back in time (``odometry.far_back``: dropped
as out of order unless ``restart_messages`` of them in a row restart, ``odometry.restart``)
or a withdrawn future stamp (``odometry.retracted``); scans and
corner clouds with stamp 0 are ``dropped.malformed``, scans of more than ``max_beams`` beams
``dropped.oversized``; corners with NaN
or with a covariance that is not positive semi-definite are dropped from their set (sets
counted as ``corners.nonfinite`` / ``corners.covariance_not_psd``); a feature set whose scan
or corners were lost goes on without them (``features.incomplete``); corner sets older than
the last step are skipped; the oldest waiting set is dropped when more than ``MAX_PENDING``
wait for odometry (before the first step: when the waiting sets take more than
``MAX_START_BYTES``; the odometry may start seconds after the laser). Corner sets stamped
before the first odometry sample are not drops: no odometry pose exists for them (the front
end's ``before_odometry``; slam_toolbox and AMCL discard such scans in their tf message
filter); they are counted as ``before_odometry`` on ``/diagnostics`` and stated in one info
line when the first step is made. The scan is received best effort and the corner cloud
reliable, each with a queue of ``FEATURE_DEPTH`` = 80 (2 s at 40 Hz; the sensor-data QoS
keeps 5: at start-up, while the first steps run, that lost scans at 40 Hz, and a keyframe's
update on a loaded machine takes several scan periods).
"""

from collections import deque
from functools import partial
import time

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from landmark_nav.conversions import (ConversionError, make_odometry,
                                      make_pose_with_covariance_stamped,
                                      odometry_pose_covariance, set_covariance3, set_pose_2d,
                                      set_stamp, stamp_to_ns)
from landmark_nav.feature_msgs import feature_cloud_to_arrays, make_landmark_markers
from landmark_nav.nodes.common import (declare_table, FEATURE_DEPTH, InputStats, output_path,
                                       ParameterError, ProblemWarner, read_scan, reject_undeclared,
                                       require_stamp, run_node, SCAN_QOS)
from landmark_nav.nodes.stamp_join import StampJoin
from landmark_nav.slam.configuration import parameters, slam_configuration, SlamConfiguration
from landmark_nav.slam.ekf_slam import CORNER, LINE
from landmark_nav.slam.features import scan_lines
from landmark_nav.slam.frontend import Corners, line_beam_times, SlamFrontend, Step
from landmark_nav.slam.slam_map import load_map, save_map
from landmark_nav.slam.visibility import ScanGeometry
from nav_msgs.msg import Odometry, Path as PathMsg
import numpy as np
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, qos_policy_name_from_kind, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan, PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray
import yaml

#: /odom: best effort takes reliable and best-effort publishers; deep enough for bursts.
ODOM_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.BEST_EFFORT,
                      history=HistoryPolicy.KEEP_LAST)
MAX_PENDING = 100
#: The scan's QoS with a queue of FEATURE_DEPTH (the corner cloud has the same depth).
FEATURE_SCAN_QOS = QoSProfile(depth=FEATURE_DEPTH, reliability=SCAN_QOS.reliability,
                              history=HistoryPolicy.KEEP_LAST)
#: Before the first step the waiting sets are bounded by their memory (Corners.nbytes): 32 MiB
#: hold about 90 s of a 40 Hz laser with 1081 beams, however late the odometry starts.
MAX_START_BYTES = 32 * 2 ** 20
#: Most feature sets waiting for their other part (corner cloud or scan).
MAX_JOIN = 50
DISCOVERY_S = 10.0  # a part without a publisher is waited for this long (discovery)
CORNER_NAMES = ('x', 'y', 'bisector', 'opening', 'cov_xx', 'cov_xy', 'cov_yy')
#: Front-end events -> /diagnostics drop reason (the input is not used).
_DROPS = {'out_of_order': ('out_of_order', 'Skipping corners'),
          'invalid': ('malformed', 'Dropping odometry'),
          'backward': ('out_of_order', 'Dropping odometry'),
          'repeated': ('repeated', 'Dropping odometry'),
          'conflicting': ('repeated', 'Dropping odometry')}
#: Front-end events -> /diagnostics count of an input used, but not as it came.
_EVENTS = {'jump': 'odometry.jump', 'covariance': 'odometry.covariance_replaced',
           'far_back': 'odometry.far_back',
           'restart': 'odometry.restart', 'retracted': 'odometry.retracted',
           'held': 'corners.held'}


class SlamInputStats(InputStats):
    """:class:`InputStats` plus ``before_odometry``, ``received.*``, ``waiting``, ``keyframes``.

    ``before_odometry``: the corner sets stamped before the first odometry sample: not
    processed, and not drops (no odometry pose exists for them). ``received.corners`` /
    ``received.scan``: the messages received on each feature topic; ``waiting``: the feature
    sets not yet processed (waiting for their other part or for odometry), so that a replay
    can tell when the node has processed what it received. ``keyframes`` /
    ``between_keyframes``: the processed sets that reached the filter and those between
    keyframes (their pose from the odometry).
    """

    def __init__(self, node: Node, warner: ProblemWarner) -> None:
        """Start with no set before the odometry."""
        super().__init__(node, warner)
        self.before_odometry = 0

    def status(self) -> DiagnosticStatus:
        """Return the input status with the ``before_odometry`` count."""
        status = super().status()
        node = self._node
        values = {'before_odometry': self.before_odometry,
                  'received.corners': node.corner_count, 'received.scan': node.scan_count,
                  'waiting': len(node.join) + len(node.frontend.pending),
                  'keyframes': node.frontend.keyframes['keyframes'],
                  'between_keyframes': node.frontend.keyframes['skipped']}
        status.values += [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        return status


def declare_configuration(node: Node) -> SlamConfiguration:
    """Declare every parameter of :mod:`landmark_nav.slam.configuration`; return the result.

    Defaults, descriptions, limits and choices come from there, the objects from
    :func:`~landmark_nav.slam.configuration.slam_configuration`: the offline tools read a
    parameter file with the same code.
    """
    return declare_table(node, parameters(), slam_configuration)


class EkfSlamNode(Node):
    """Thin node: odometry + corner clouds -> :class:`SlamFrontend` -> pose, path, map."""

    def __init__(self, **kwargs) -> None:
        """Declare the parameters, create subscriptions, publishers and services."""
        super().__init__('ekf_slam', **kwargs)
        config = declare_configuration(self)
        reject_undeclared(self)
        values = config.values
        self.params = config.params
        self.frontend_params = config.frontend
        self.landmarks = config.landmarks
        self.structural_only = values['structural_corners_only']
        self.max_beams = values['max_beams']
        self.visibility = config.visibility
        self.laser_sigma_range = config.laser_sigma_range
        self.line_params = config.line_params
        self.laser_pose = np.array(config.laser_pose)
        self.map_frame = values['map_frame']
        self.base_frame = values['base_frame']
        self.map_file = values['map_file']
        load_file = values['load_map']
        pose_sigma = np.array(values['map_pose_sigma'])
        self.slam_map = None
        if load_file:
            try:
                self.slam_map = load_map(output_path(load_file))
            except (OSError, ValueError) as err:
                raise ParameterError(f'parameter load_map: {err}') from None
        elif self.params.mode == 'localization':
            raise ParameterError('parameter mode localization needs load_map (a .npz map)')
        self.path_max_poses = values['path_max_poses']
        display_period = values['display_period']
        self.odometry_timeout = values['odometry_timeout']
        self.warner = ProblemWarner(self)
        self.stats = SlamInputStats(self, self.warner)
        # Outputs without rclpy's default QoS-event handlers (two waitables each, which its
        # executor scans at every wait: a third of the node's CPU per step went there); an
        # incompatible subscriber still reports it on its side.
        quiet = PublisherEventCallbacks(use_default_callbacks=False)
        self.pub_pose = self.create_publisher(PoseWithCovarianceStamped, 'pose', 10,
                                              event_callbacks=quiet)
        self.pub_odom = self.create_publisher(Odometry, 'odometry', 10, event_callbacks=quiet)
        self.pub_path = self.create_publisher(PathMsg, 'path', 10, event_callbacks=quiet)
        self.pub_marks = self.create_publisher(MarkerArray, 'landmarks', 10,
                                               event_callbacks=quiet)
        self.stats.subscribe(Odometry, 'odom', self.on_odom, ODOM_QOS, self._sub_events('odom'))
        parts = []
        if self.landmarks in ('corners', 'both'):
            parts.append('corners')
            self.stats.subscribe(PointCloud2, 'corners/features', self.on_corners, FEATURE_DEPTH,
                                 self._sub_events('corners/features'))
        if self.landmarks in ('lines', 'both') or self.visibility:
            parts.append('scan')
            self.stats.subscribe(LaserScan, 'scan', self.on_scan, FEATURE_SCAN_QOS,
                                 self._sub_events('scan'))
        self.join = StampJoin(parts, MAX_JOIN)
        self._topics = {'corners': 'corners/features', 'scan': 'scan'}
        self._absent_noted = set()
        self._publisher_counts = {}  # part -> (monotonic time, publisher count)
        self._publisher_seen = {}  # part -> monotonic time it last had a publisher
        self._handed = set()  # stamps of the last incomplete sets handed on
        self._handed_order = deque()
        self._newest_part_ns = None  # newest stamp offered since the source (re)started
        self._started = time.monotonic()
        # Reused per step (publish serialises at once); only stamp, pose, covariance change.
        self._pose_msg = make_pose_with_covariance_stamped(0, self.map_frame, [0.0] * 3)
        self._odom_msg = make_odometry(0, self.map_frame, self.base_frame, [0.0] * 3)
        # One timer for both periodic checks (every timer is scanned at each executor wait).
        self.display_period = display_period
        self._next_display = time.monotonic()
        self.create_timer(min(display_period, 0.5 * self.odometry_timeout), self.on_timer)
        self.create_service(Trigger, 'save_map', self.on_save_map)
        self.create_service(Trigger, 'reset', self.on_reset)
        self.odom_count = 0
        self.corner_count = 0
        self.scan_count = 0
        self.resets = 0
        self._before_logged = 0  # before_odometry sets already stated in the log
        self.last_odom_wall = time.monotonic()
        self.frontend = SlamFrontend(self.params, self.laser_pose, self.frontend_params,
                                     self._on_event, slam_map=self.slam_map,
                                     map_pose_covariance=np.diag(pose_sigma ** 2))
        self._clear()  # also _first_set_ns: stamp of the first feature set (info line)
        self.get_logger().info(f'ekf_slam: landmarks {self.landmarks}, visibility '
                               f'{self.visibility}, association {self.params.association}, '
                               'odometry noise ' + ', '.join(
                                   f'{k} {v:g}' for k, v in vars(self.params.odometry).items()))

    @property
    def slam(self):
        """The filter (None before the first odometry)."""
        return self.frontend.slam

    @property
    def pending(self) -> list:
        """Corner sets waiting for odometry, ``(stamp_ns, received_ns)`` in stamp order."""
        return self.frontend.pending

    def _clear(self) -> None:
        """Forget the filter, odometry buffer, pending corner sets and path."""
        self.frontend.clear()
        self._first_set_ns = None
        self.join.clear()
        self._forget_handed()
        self._clear_path()
        self.display_stamp = None

    def _forget_handed(self) -> None:
        self._handed.clear()
        self._handed_order.clear()
        self._newest_part_ns = None

    def _clear_path(self) -> None:
        # The last path_max_poses steps in a ring written in place (np.full touches every
        # page now: the memory of a long run does not grow with it), 32 bytes a pose.
        n = self.path_max_poses
        self._path_t = np.full(n, 0, dtype=np.int64)  # stamp [ns] of step k at k % n
        self._path_pose = np.full((n, 3), 0.0)  # its pose
        self._path_count = 0  # steps since the clear
        self.path_poses = deque(maxlen=n)  # PoseStamped, built at display
        self._path_new = 0  # steps not yet in path_poses

    def _on_event(self, kind: str, message: str) -> None:
        """Report a front-end event (an input not used as it came)."""
        if kind in _DROPS:
            reason, what = _DROPS[kind]
            self.stats.drop(reason, f'{what}: {message}')
            return
        if kind == 'before_odometry':  # not a drop (module docstring); logged at a step
            self.stats.before_odometry += 1
            return
        if kind == 'restart':
            self.resets += 1
            self._clear_path()
            self._first_set_ns = None
        self.stats.event(_EVENTS[kind], f'Odometry ({kind}): {message}')

    def on_odom(self, msg: Odometry) -> None:
        """Give one odometry sample to the front end; publish the steps it completes."""
        self.odom_count += 1
        self.last_odom_wall = time.monotonic()
        try:
            t, pose, cov = odometry_pose_covariance(msg)
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping odometry: {err}')
            return
        _, steps = self.frontend.add_odometry(t, pose, cov)
        self._publish_steps(steps, self.stats.received_ns)

    def on_corners(self, msg: PointCloud2) -> None:
        """Validate one corner set and give it to the front end."""
        self.corner_count += 1
        try:
            a = feature_cloud_to_arrays(msg)
            missing = [n for n in CORNER_NAMES if n not in a]
            if missing:
                raise ConversionError(f'PointCloud2: missing fields {", ".join(missing)}')
            t = require_stamp(stamp_to_ns(msg.header.stamp), 'PointCloud2')
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping corners: {err}')
            return
        if self.structural_only:
            if 'structural' in a:
                a = {k: v[a['structural'] > 0.5] for k, v in a.items()}
            else:
                self.warner.warn('corners/features has no field structural: every corner is '
                                 'used (structural_corners_only needs a corner_extractor '
                                 'that labels them)')
        cols = np.column_stack([a[n] for n in CORNER_NAMES]
                               + [a.get('time', np.zeros(len(a['x'])))])
        cols = self._valid_corners(cols.reshape(-1, len(CORNER_NAMES) + 1))
        self._offer('corners', t, cols)

    def on_scan(self, msg: LaserScan) -> None:
        """Validate one scan (lines, visibility) and join it to its corner set."""
        self.scan_count += 1
        scan = read_scan(msg, self.max_beams, self.stats)
        if scan is None:
            return
        self._offer('scan', scan.stamp_ns, scan)

    def _offer(self, part: str, t: int, item) -> None:
        """Join one part of a feature set; give the sets it completes to the front end.

        A part whose set already went on without it is dropped (``'late'``): processing it
        again would make a second step at the same stamp. A part more than
        ``max_backward_s`` older than the newest one comes from a restarted source (a bag
        replayed in a loop gives the same stamps again): the stamps handed before it are
        forgotten, else its sets would be taken for late parts of the last run's.
        """
        newest = self._newest_part_ns
        if newest is not None and newest - t > self.frontend_params.max_backward_s * 1e9:
            self._forget_handed()
            newest = None
        self._newest_part_ns = t if newest is None else max(newest, t)
        if t in self._handed:
            self.stats.drop('late', f'Dropping {self._topics[part]} at {t} ns: its feature '
                            'set was processed without it (it came after the set went on)')
            return
        for stamp, have, missing in self.join.add(part, t, item, self._has_publisher):
            if missing:
                self._handed.add(stamp)
                self._handed_order.append(stamp)
                if len(self._handed_order) > MAX_JOIN:
                    self._handed.discard(self._handed_order.popleft())
            lost = [p for p in missing if self._has_publisher(p)]
            if lost:
                self.stats.event('features.incomplete', f'Feature set at {stamp} ns without its '
                                 f'{" and ".join(lost)} (lost: a later one came): using what '
                                 'came')
            for p in set(missing) - set(lost) - self._absent_noted:
                self._absent_noted.add(p)
                self.get_logger().info(f'No publisher on {self._topics[p]}: feature sets go '
                                       f'on without it (no lines, no visibility pruning)')
            for p in self._absent_noted & set(have):  # its publisher came after all
                self._absent_noted.discard(p)
                self.get_logger().info(f'{self._topics[p]} arrived: feature sets use it from '
                                       f'the set at {stamp} ns on')
            self._add_features(self._feature_set(stamp, have.get('corners'),
                                                 have.get('scan')))

    def _has_publisher(self, part: str) -> bool:
        """Whether the part may still come (graph queried at most once a second).

        It may when its topic has a publisher, or, for the corners (the landmarks), had one
        or the node started less than ``DISCOVERY_S`` ago.

        Without the grace, sets went on without their corners while discovery had not yet
        matched the corner extractor (the live soak's first 35 steps; the corners then came
        for sets already processed).
        """
        now = time.monotonic()
        known = self._publisher_counts.get(part)
        if known is None or now - known[0] > 1.0:
            known = (now, self.count_publishers(self._topics[part]))
            self._publisher_counts[part] = known
            if known[1] > 0:
                self._publisher_seen[part] = now
        if known[1] > 0 or part != 'corners':
            return known[1] > 0
        return now - self._publisher_seen.get(part, self._started) < DISCOVERY_S

    def _feature_set(self, t: int, cols, scan) -> Corners:
        """Build the front end's feature set from corner rows and / or a scan."""
        if cols is None:
            cols = np.zeros((0, len(CORNER_NAMES) + 1))
        lines, time_increment, geometry, lazy = (), 0.0, None, None
        if scan is not None:
            if self.landmarks != 'corners':
                time_increment = scan.time_increment
                lazy = partial(scan_lines, scan.ranges, scan.angles, scan.valid,
                               scan.angle_increment, time_increment, self.line_params)
                if not self.frontend_params.keyframe.enabled:
                    lines, lazy = lazy()[0], None
            if self.visibility:
                geometry = ScanGeometry(scan.ranges, scan.angle_min, scan.angle_increment,
                                        scan.range_min, scan.range_max, self.laser_pose,
                                        self.laser_sigma_range)
        return Corners(t, cols[:, :2], np.stack([cols[:, [4, 5]], cols[:, [5, 6]]], axis=1),
                       cols[:, 2], cols[:, 3], cols[:, 7], tuple(lines),
                       line_beam_times(lines, time_increment),
                       self.line_params.sigma_r if lines or lazy else None, geometry,
                       lazy, time_increment * max(scan.ranges.size - 1, 0) if lazy else 0.0)

    def _add_features(self, corners: Corners) -> None:
        """Give one feature set to the front end; publish the steps it completes."""
        t = corners.stamp_ns
        steps = self.frontend.add_features(corners, self.stats.received_ns)
        if self._first_set_ns is None:
            self._first_set_ns = t
        if not self.frontend.events['processed']:
            # No step yet: the odometry may start seconds after the laser (a base driver or
            # a DDS match that comes late), so the wait is bounded by memory, not by a time.
            while self.frontend.pending_bytes > MAX_START_BYTES:
                old = self.frontend.drop_oldest_pending()
                self.stats.drop('no_odometry', f'Dropping corners at {old[0]} ns: no step yet, '
                                'and the sets waiting for odometry take more than '
                                f'{MAX_START_BYTES / 2 ** 20:g} MiB (newest {t} ns)')
        elif len(self.frontend.pending) > MAX_PENDING:
            old = self.frontend.drop_oldest_pending()
            span = self.frontend.odometry_span
            self.stats.drop('not_covered', f'Dropping corners at {old[0]} ns: more than '
                            f'{MAX_PENDING} corner sets wait for odometry (newest {t} ns, '
                            f'odometry up to {span[1] if span else None} ns)')
        self._publish_steps(steps)

    def _sub_events(self, topic: str) -> SubscriptionEventCallbacks:
        """Only the incompatible-QoS warning of rclpy's default event handlers (one waitable)."""
        def warn(event) -> None:
            self.get_logger().warning(
                f'New publisher on {topic} offers an incompatible QoS '
                f'({qos_policy_name_from_kind(event.last_policy_kind)}): none of its messages '
                'will arrive')
        return SubscriptionEventCallbacks(incompatible_qos=warn, use_default_callbacks=False)

    def on_timer(self) -> None:
        """Check the odometry timeout; publish the display every ``display_period``."""
        self.check_odometry_timeout()
        now = time.monotonic()
        if now >= self._next_display:
            self._next_display = now + self.display_period - 1e-3
            self.publish_display()

    def check_odometry_timeout(self) -> None:
        """Process waiting sets the odometry reaches when it has stopped coming."""
        if (self.frontend.pending
                and time.monotonic() - self.last_odom_wall > self.odometry_timeout):
            self._publish_steps(self.frontend.flush())

    def _valid_corners(self, cols: np.ndarray) -> np.ndarray:
        """Drop corner rows with NaN / inf or a covariance that is not PSD (with a warning)."""
        finite = np.all(np.isfinite(cols), axis=1)
        if not np.all(finite):
            bad = cols[~finite][0]
            self.stats.event('corners.nonfinite', f'Dropping {int(np.sum(~finite))} corners '
                             f'with NaN or inf (first: {bad.tolist()})')
        with np.errstate(invalid='ignore'):
            psd = (cols[:, 4] >= 0) & (cols[:, 6] >= 0) & (
                cols[:, 4] * cols[:, 6] - cols[:, 5] ** 2 >= 0)
        bad = finite & ~psd
        if np.any(bad):
            c = cols[bad][0]
            self.stats.event('corners.covariance_not_psd', f'Dropping {int(np.sum(bad))} '
                             'corners whose covariance is not positive semi-definite (first: '
                             f'cov_xx={c[4]:g}, cov_xy={c[5]:g}, cov_yy={c[6]:g})')
        return cols[finite & psd]

    def _publish_steps(self, steps: list, odometry_received_ns: int = 0) -> None:
        """Publish each step's pose and count it."""
        if steps and self.stats.before_odometry > self._before_logged:
            self._log_before_odometry()
        for st in steps:
            st: Step
            self._publish(st.stamp_ns, st.pose, st.covariance)
            self.stats.processed(max(int(st.tag or 0), odometry_received_ns))

    def _log_before_odometry(self) -> None:
        """State the sets stamped before the first odometry (one line at the first step)."""
        n = self.stats.before_odometry - self._before_logged
        self._before_logged = self.stats.before_odometry
        t0 = self.frontend.t0
        span = ('' if self._first_set_ns is None or t0 is None else
                f'; the first corner set came {(t0 - self._first_set_ns) * 1e-9:.2f} s before it')
        self.get_logger().info(
            f'Odometry starts at {t0} ns: {n} corner set(s) stamped before it were not processed '
            f'(no odometry pose for them; counted as before_odometry on /diagnostics, not as '
            f'drops){span}')

    def _publish(self, t: int, pose: np.ndarray, cov: np.ndarray) -> None:
        """Publish the pose of one step and remember it for the path."""
        for msg in (self._pose_msg, self._odom_msg):
            p = msg.pose
            set_stamp(msg.header, t)
            set_pose_2d(p.pose, pose)
            p.covariance = set_covariance3(p.covariance, cov)
        self.pub_pose.publish(self._pose_msg)
        self.pub_odom.publish(self._odom_msg)
        k = self._path_count % self.path_max_poses
        self._path_t[k], self._path_pose[k] = t, pose
        self._path_count += 1
        self._path_new += 1
        self.display_stamp = t

    def path_message(self) -> PathMsg:
        """Return the path of the last ``path_max_poses`` steps."""
        n = min(self._path_new, self.path_max_poses, self._path_count)
        for i in range(self._path_count - n, self._path_count):
            k = i % self.path_max_poses
            ps = PoseStamped()  # built once per step: the path message only lists them
            set_stamp(ps.header, int(self._path_t[k]))
            ps.header.frame_id = self.map_frame
            set_pose_2d(ps.pose, self._path_pose[k])
            self.path_poses.append(ps)
        self._path_new = 0
        path = PathMsg()
        path.header.frame_id = self.map_frame
        path.poses = list(self.path_poses)
        if path.poses:
            path.header.stamp = path.poses[-1].header.stamp
        return path

    def publish_display(self) -> None:
        """Publish the path and the landmarks if a step was made since the last time.

        Each only while it has a subscriber (the cost of a display nobody looks at is
        skipped; a display that subscribes gets the next change).
        """
        if self.display_stamp is None:
            return
        t, self.display_stamp = self.display_stamp, None
        if self.pub_path.get_subscription_count():
            self.pub_path.publish(self.path_message())
        if self.pub_marks.get_subscription_count():
            self.pub_marks.publish(self.landmark_markers(t))

    def landmark_markers(self, t: int) -> MarkerArray:
        """Return the map: a 2-sigma ellipse per corner, the seen extent of each line."""
        if self.slam is None:
            return make_landmark_markers(t, self.map_frame, [], [], [])
        s = self.slam
        kinds = s.landmark_kinds
        c, ln = kinds == CORNER, kinds == LINE
        return make_landmark_markers(t, self.map_frame, s.landmark_ids[c], s.landmarks[c],
                                     s.landmark_covariances[c], line_ids=s.landmark_ids[ln],
                                     line_ends=s.line_ends[ln])

    def map_dict(self) -> dict:
        """Return the map as a YAML-able dict (corners: x, y; lines: rho, alpha, ends)."""
        if self.slam is None:
            return {'frame_id': self.map_frame, 'landmarks': []}
        s = self.slam
        out = []
        for i, k, m, c, e in zip(s.landmark_ids, s.landmark_kinds, s.landmarks,
                                 s.landmark_covariances, s.line_ends):
            cov = [float(v) for v in np.asarray(c).reshape(4)]
            if k == LINE:
                out.append({'id': int(i), 'kind': 'line', 'rho': float(m[0]),
                            'alpha': float(m[1]), 'covariance': cov,
                            'ends': [[float(v) for v in p] for p in e]})
            else:
                out.append({'id': int(i), 'kind': 'corner', 'x': float(m[0]),
                            'y': float(m[1]), 'covariance': cov})
        return {'frame_id': self.map_frame, 'landmarks': out}

    def on_save_map(self, request, response):
        """Write the landmarks and covariances to ``map_file``."""
        data = self.map_dict()
        path = output_path(self.map_file)
        try:
            if path.suffix == '.npz':
                if self.slam is None:
                    response.success, response.message = False, 'no map yet (no odometry)'
                    return response
                path = save_map(path, self.slam.export_map())
            else:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(yaml.safe_dump(data, sort_keys=False))
        except OSError as err:
            response.success, response.message = False, f'cannot write {path}: {err}'
            return response
        response.success = True
        response.message = f'saved {len(data["landmarks"])} landmarks to {path}'
        return response

    def on_reset(self, request, response):
        """Forget the map; the filter restarts at the next odometry."""
        self._clear()
        self.resets += 1
        response.success, response.message = True, 'EKF-SLAM reset'
        return response


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav ekf_slam``."""
    return run_node(EkfSlamNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
