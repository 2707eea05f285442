"""Executable ``sonar_localizer``: EKF / UKF pose tracking with a sonar ring on a grid map.

Self-localization chapter, section 4: calibrated odometry as the motion model, sonar
readings predicted by ray casting in an occupancy grid (0.1 m cells), EKF or UKF update.
The synchronisation and the filter steps live in
:class:`landmark_nav.localization.tracking.SonarTracker`; this node converts messages.

Subscribes (sensors with the sensor-data QoS):

* ``odom`` (nav_msgs/Odometry) if ``odometry_source`` is ``odom``: the robot's nominal
  (uncalibrated) odometry; successive poses give the control, recalibrated with k1..k3;
* ``joint_states`` (sensor_msgs/JointState) if ``odometry_source`` is ``joint_states``:
  accumulated angles [rad] of the ``wheel_joints`` (eqs. 4-7, 17-18 with
  ``wheel_radius``, ``axle_length``, k1..k3);
* the ``sonar_topics`` (sensor_msgs/Range, REP 117; default ``/sonar/range_0..15``),
  mounted at ``sonar_mounts`` (x, y, yaw per sonar in ``base_link``: the static transforms
  ``base_link -> sonar_<i>``; default the Pioneer 2-DX ring);
* ``map`` (nav_msgs/OccupancyGrid, transient local) unless ``map_file`` (map_server YAML)
  is set;
* ``initialpose`` (geometry_msgs/PoseWithCovarianceStamped in ``global_frame``, as RViz
  sends it): resets the estimate (pose and covariance) at the current filter time.

Publishes, stamped with the sonar cycle's stamp, in ``global_frame``:

* ``pose`` (geometry_msgs/PoseWithCovarianceStamped);
* ``odometry/filtered`` (nav_msgs/Odometry, child ``base_frame``): the same pose, twist =
  mean odometry velocity since the previous estimate, its covariance from the process noise.

Synchronisation: readings are grouped by stamp; a cycle is processed when the odometry has
reached its stamp and every expected sonar has reported, or once a stamp ``sync_timeout``
newer arrives (missing readings are not used); a sonar missing ``stale_cycles`` cycles in a
row is no longer waited for (warned once). Until a usable map is set the filter only
predicts (dead reckoning, growing covariance, a throttled warning); without sonar readings
for ``sonar_timeout`` it publishes dead reckoning at every odometry sample. Odometry going
back in time (a looped bag) resets the time bookkeeping. Bad messages (NaN or out-of-limit
ranges, a field of view that is not finite and >= 0, malformed odometry, joint states or
maps) are dropped with a warning throttled per kind of problem; the node keeps running.
Estimates published, inputs dropped (with the reasons, e.g. ``dropped.map_malformed``,
``dropped.initialpose_frame``) and the latency are on ``/diagnostics``
(:class:`~landmark_nav.nodes.common.InputStats`).
"""

from dataclasses import replace
import math

from geometry_msgs.msg import PoseWithCovarianceStamped
from landmark_nav.conversions import (ConversionError, grid_to_data, make_odometry,
                                      make_pose_with_covariance_stamped, odometry_to_pose,
                                      range_to_value, stamp_to_ns)
from landmark_nav.localization.configuration import (FILTER_PARAMETERS, NODE_PARAMETERS,
                                                     NOISE_PARAMETERS)
from landmark_nav.localization.grid import GridMap, load_map_yaml
from landmark_nav.localization.odometry import ProcessNoise
from landmark_nav.localization.params import LocalizationParams
from landmark_nav.localization.tracking import sonar_reading, SonarTracker
from landmark_nav.nodes.common import (declare, declare_dataclass, declare_strings,
                                       initial_pose, InputStats, ParameterError, ProblemWarner,
                                       reject_undeclared, run_node, SENSOR_QOS)
from nav_msgs.msg import OccupancyGrid, Odometry
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, Range

MAP_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class SonarLocalizer(Node):
    """Thin node: odometry + Range cycles + map -> SonarTracker -> pose messages."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters, create the subscriptions and publishers."""
        super().__init__('sonar_localizer', **kwargs)
        v = {name: (declare_strings(self, name, p.default, p.description)
                    if p.default and isinstance(p.default, list) and isinstance(p.default[0], str)
                    else declare(self, name, *p[:4])) for name, p in NODE_PARAMETERS.items()}
        filt, source, map_file = v['filter'], v['odometry_source'], v['map_file']
        radius, axle, mounts = v['wheel_radius'], v['axle_length'], v['sonar_mounts']
        k = [v[f'k{i}'] for i in (1, 2, 3)]
        self.wheel_joints, self.topics = v['wheel_joints'], v['sonar_topics']
        self.global_frame, self.base_frame = v['global_frame'], v['base_frame']
        pose0 = [v[f'initial_pose.{n}'] for n in ('x', 'y', 'yaw')]
        std0 = [v[f'initial_pose.std_{n}'] for n in ('x', 'y', 'yaw')]
        sync, stale, sonar_timeout = v['sync_timeout'], v['stale_cycles'], v['sonar_timeout']
        params = declare_dataclass(self, LocalizationParams, FILTER_PARAMETERS)
        noise = declare_dataclass(self, ProcessNoise, NOISE_PARAMETERS, 'process_noise.')
        reject_undeclared(self)
        self._check(source, mounts, params)
        self.initial_cov = np.diag(np.square(std0))
        self.warner = ProblemWarner(self)
        self.stats = InputStats(self, self.warner)
        self.tracker = SonarTracker(
            filt, np.reshape(mounts, (-1, 3)), replace(params, noise=noise), pose0,
            self.initial_cov, radius, axle, k, sync, stale, sonar_timeout,
            sonar_names=self.topics,
            warn=self._tracker_problem, info=self.get_logger().info)
        if map_file:
            try:
                self.tracker.set_map(load_map_yaml(map_file))
            except (OSError, ValueError) as err:
                raise ParameterError(f'parameter map_file: cannot load {map_file}: {err}') \
                    from err
        else:
            self.create_subscription(OccupancyGrid, 'map', self.on_map, MAP_QOS)
        if source == 'odom':
            self.stats.subscribe(Odometry, 'odom', self.on_odom, SENSOR_QOS)
        else:
            self.stats.subscribe(JointState, 'joint_states', self.on_joints, SENSOR_QOS)
        for i, topic in enumerate(self.topics):
            self.stats.subscribe(Range, topic, lambda msg, i=i: self.on_range(i, msg),
                                 SENSOR_QOS)
        self.create_subscription(PoseWithCovarianceStamped, 'initialpose',
                                 self.on_initial_pose, 10)
        self.pub_pose = self.create_publisher(PoseWithCovarianceStamped, 'pose', 10)
        self.pub_odom = self.create_publisher(Odometry, 'odometry/filtered', 10)
        self.get_logger().info(f'sonar_localizer: {filt.upper()}, odometry from {source}, '
                               f'{len(self.topics)} sonars, map '
                               f'{map_file or "from the map topic"}')

    def _check(self, source: str, mounts: list, params: LocalizationParams) -> None:
        """Cross-parameter checks (each message names the parameters)."""
        if not self.topics or len(set(self.topics)) != len(self.topics):
            raise ParameterError('parameter sonar_topics: need one or more distinct topics')
        if len(mounts) != 3 * len(self.topics):
            raise ParameterError(f'parameter sonar_mounts: need 3 values (x, y, yaw) per sonar '
                                 f'topic: {len(self.topics)} topics, {len(mounts)} values')
        if source == 'joint_states' and len(self.wheel_joints) != 2:
            raise ParameterError('parameter wheel_joints: need the left and right joint names')
        if params.min_range >= params.max_range:
            raise ParameterError('parameters min_range and max_range: need min_range < '
                                 'max_range')

    def _tracker_problem(self, message: str) -> None:
        """Warn about a tracker problem; count it as a drop when input was discarded."""
        if any(word in message for word in ('dropped', 'ignored', 'arrived after')):
            self.stats.drop('tracker', message)
        else:
            self.warner.warn(message)

    def on_odom(self, msg: Odometry) -> None:
        """Feed one odometry pose."""
        try:
            data = odometry_to_pose(msg)
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping odometry: {err}')
            return
        self.publish(self.tracker.add_odometry_pose(data.stamp_ns, data.pose))

    def on_joints(self, msg: JointState) -> None:
        """Feed the wheel angles of one joint state."""
        names = list(msg.name)
        missing = [j for j in self.wheel_joints if j not in names]
        if missing or len(msg.position) != len(names):
            self.stats.drop('malformed', 'Dropping joint states: no position for '
                            f'{missing or "every joint"} ({len(msg.position)} positions, '
                            f'{len(names)} names)')
            return
        angles = [msg.position[names.index(j)] for j in self.wheel_joints]
        self.publish(self.tracker.add_wheel_angles(stamp_to_ns(msg.header.stamp), angles))

    def on_range(self, index: int, msg: Range) -> None:
        """Feed one sonar reading (bad values are kept as missing, with a warning)."""
        try:
            reading = range_to_value(msg)
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping sonar reading on {self.topics[index]}: '
                            f'{err}')
            return
        value, problem = sonar_reading(reading.value, msg.min_range, msg.max_range)
        if problem is not None:
            self.warner.warn(f'Rejecting sonar reading on {self.topics[index]}: {problem}')
        self.publish(self.tracker.add_reading(index, reading.stamp_ns, value))

    def on_map(self, msg: OccupancyGrid) -> None:
        """Use a new map."""
        try:
            data = grid_to_data(msg)
            grid = GridMap(occupancy=data.data, resolution=data.resolution,
                           origin=tuple(data.origin))
        except (ConversionError, ValueError) as err:
            self.stats.drop('map_malformed', f'Dropping map: {err}')
            return
        if data.frame_id not in ('', self.global_frame):
            self.stats.event('map.frame', f'map frame {data.frame_id!r} is not '
                             f'{self.global_frame!r}: using it as that frame')
        if self.tracker.set_map(grid):
            self.get_logger().info(f'map: {data.width} x {data.height} cells of '
                                   f'{data.resolution} m')

    def on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        """Reset the estimate to a pose given by the user (e.g. RViz "2D Pose Estimate")."""
        given = initial_pose(msg, self.global_frame, self.stats, self.initial_cov,
                             'the initial_pose.std_* parameters')
        if given is None:
            return
        self.tracker.reset(*given)
        x, y, yaw = given[0]
        self.get_logger().info(f'estimate reset to x={x:.3f} m, y={y:.3f} m, '
                               f'yaw={math.degrees(yaw):.1f} deg')

    def publish(self, estimates: list) -> None:
        """Publish the pose and the filtered odometry of each new estimate."""
        for e in estimates:
            self.stats.processed()
            self.pub_pose.publish(make_pose_with_covariance_stamped(
                e.stamp_ns, self.global_frame, e.pose, e.covariance))
            twist_cov = np.zeros((3, 3))
            twist_cov[np.ix_((0, 2), (0, 2))] = e.velocity_covariance
            self.pub_odom.publish(make_odometry(
                e.stamp_ns, self.global_frame, self.base_frame, e.pose, e.covariance,
                [e.velocity[0], 0.0, e.velocity[1]], twist_cov))


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav sonar_localizer``."""
    return run_node(SonarLocalizer, args)


if __name__ == '__main__':
    raise SystemExit(main())
