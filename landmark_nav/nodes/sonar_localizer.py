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
Estimates published, inputs dropped and the latency are on ``/diagnostics``
(:class:`~landmark_nav.nodes.common.InputStats`).
"""

from dataclasses import replace
import math

from geometry_msgs.msg import PoseWithCovarianceStamped
from landmark_nav.conversions import (ConversionError, grid_to_data, make_odometry,
                                      make_pose_with_covariance_stamped, odometry_to_pose,
                                      range_to_value, stamp_to_ns)
from landmark_nav.hardware import SONAR_MOUNTS
from landmark_nav.localization.grid import GridMap, load_map_yaml
from landmark_nav.localization.odometry import ProcessNoise
from landmark_nav.localization.params import LocalizationParams
from landmark_nav.localization.tracking import sonar_reading, SonarTracker
from landmark_nav.nodes.common import (declare, declare_dataclass, declare_strings,
                                       initial_pose, InputStats, ParameterError, ProblemWarner,
                                       run_node, SENSOR_QOS)
from nav_msgs.msg import OccupancyGrid, Odometry
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, Range

MAP_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)

FILTER_PARAMETERS = {
    'sigma_r0': ('measurement noise: constant range std [m] (eq. 28)', (0.0, 1.0), None),
    'sigma_r1': ('measurement noise: range-proportional std [-] (eq. 28)', (0.0, 1.0), None),
    'min_range': ('shortest usable sonar reading [m]', (0.0, 100.0), None),
    'max_range': ('longest usable sonar reading [m]', (0.0, 100.0), None),
    'max_predict': ('predicted readings beyond this are discarded [m] (section 4.1)',
                    (0.1, 100.0), None),
    'gate': ('acceptance threshold on |z - zhat| [m] (sections 4.1, 4.3)', (0.001, 10.0),
             None),
    'gate_sigmas': ('optional normalised gate [innovation std devs]; 0 = off', (0.0, 100.0),
                    None),
    'cone_rays': ('rays per sonar lobe in the prediction; 1 = the centre beam only',
                  (1, 101), None),
    'theta0': ('half lobe angle Theta_0 [rad] (eq. 10; used when cone_rays > 1)',
               (0.0, 1.5), None),
    'specular_angle': ('largest angle of incidence that still echoes [rad]; 0 = no specular '
                       'model', (0.0, 1.5708), None, 0.0),
    'jacobian': ('EKF measurement Jacobian: raycast (differences of the ray-cast range) or '
                 'point (eq. 27 literally)', None, ['raycast', 'point']),
    'jac_step_xy': ('EKF Jacobian position step [m]', (1e-4, 1.0), None),
    'jac_step_theta': ('EKF Jacobian heading step [rad]', (1e-4, 1.0), None),
    'jac_max_jump': ('EKF and UKF: readings whose perturbed predictions jump more than this '
                     'are not used [m]', (0.0, 10.0), None),
    'jac_central': ('EKF: central (true) or forward (false) differences', None, None),
    'jac_active_ray': ('EKF with cone_rays > 1: differentiate only the echoing ray', None,
                       None),
    'ukf_alpha': ('UKF sigma-point spread alpha (eq. 40)', (1e-4, 1.0), None),
    'ukf_beta': ('UKF beta (eq. 47), 2 for Gaussians', (0.0, 10.0), None),
    'ukf_kappa': ('UKF kappa (eq. 40)', (-4.0, 100.0), None),
    'map_sigma': ('UKF: std of the map surface positions in x and y [m], augmented '
                  'measurement noise; -1 = map resolution / sqrt(12); 0 = off',
                  (-1.0, 1.0), None, -1.0),
    'midpoint': ('motion model moves along the mean heading (eqs. 1-3); false = eq. 25 as '
                 'printed', None, None),
    'unknown': ('unknown map cells: invalid (no prediction through them), occupied or free '
                '(use free on sonar-built maps)', None, ['invalid', 'occupied', 'free']),
}
NOISE_PARAMETERS = {
    'sigma_d': ('std of the travelled distance per step [m] (eq. 26)', (0.0, 1.0), None),
    'sigma_dtheta': ('relative std of the rotation per step [-] (eq. 26)', (0.0, 10.0),
                     None),
    'k_d': ('distance std per metre travelled [-] (extension of eq. 26)', (0.0, 10.0), None),
    'k_theta': ('heading std per metre travelled [rad/m] (extension of eq. 26)', (0.0, 10.0),
                None),
}


class SonarLocalizer(Node):
    """Thin node: odometry + Range cycles + map -> SonarTracker -> pose messages."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters, create the subscriptions and publishers."""
        super().__init__('sonar_localizer', **kwargs)
        d = declare
        filt = d(self, 'filter', 'ekf', 'pose filter: ekf or ukf', choices=['ekf', 'ukf'])
        source = d(self, 'odometry_source', 'odom', 'motion input: odom (nav_msgs/Odometry '
                   'poses) or joint_states (wheel angles)', choices=['odom', 'joint_states'])
        radius = d(self, 'wheel_radius', 0.0955, 'nominal wheel radius R [m] (joint_states)',
                   (0.001, 10.0))
        axle = d(self, 'axle_length', 0.33, 'nominal axle length b [m]', (0.001, 10.0))
        k = [d(self, f'k{i}', 1.0, f'odometry calibration factor k{i} (eqs. 17-18; '
               '1 = nominal)', (0.5, 1.5)) for i in (1, 2, 3)]
        self.wheel_joints = declare_strings(self, 'wheel_joints',
                                            ['left_wheel_joint', 'right_wheel_joint'],
                                            'left and right wheel joint names (joint_states)')
        self.topics = declare_strings(self, 'sonar_topics',
                                      [f'/sonar/range_{i}' for i in range(16)],
                                      'sensor_msgs/Range topics, one per sonar, mount order')
        mounts = d(self, 'sonar_mounts', [float(v) for v in SONAR_MOUNTS.ravel()],
                   'x [m], y [m], yaw [rad] of each sonar in base_link (the transforms '
                   'base_link -> sonar_<i>), in sonar_topics order; default Pioneer 2-DX')
        map_file = d(self, 'map_file', '', 'map_server YAML to load; empty = subscribe to map')
        self.global_frame = d(self, 'global_frame', 'map', 'frame of the map and the output')
        self.base_frame = d(self, 'base_frame', 'base_link', 'child frame of the output')
        pose0 = [d(self, f'initial_pose.{n}', 0.0, f'initial {n} in global_frame [{u}]',
                   (-1e6, 1e6)) for n, u in (('x', 'm'), ('y', 'm'), ('yaw', 'rad'))]
        std0 = [d(self, f'initial_pose.std_{n}', v, f'initial std of {n} [{u}]', (1e-6, 1e3))
                for n, v, u in (('x', 0.055, 'm'), ('y', 0.055, 'm'),
                                ('yaw', math.radians(5.0), 'rad'))]
        sync = d(self, 'sync_timeout', 0.15, 'process an incomplete sonar cycle once a stamp '
                 'this much newer arrived [s]', (0.0, 10.0))
        stale = d(self, 'stale_cycles', 3, 'cycles a sonar may miss before it is no longer '
                  'waited for', (1, 1000))
        sonar_timeout = d(self, 'sonar_timeout', 1.0, 'dead reckoning at every odometry '
                          'sample after this long without sonar readings [s]', (0.1, 60.0))
        params = declare_dataclass(self, LocalizationParams, FILTER_PARAMETERS)
        noise = declare_dataclass(self, ProcessNoise, NOISE_PARAMETERS, 'process_noise.')
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
            self.warner.warn(f'Dropping map: {err}')
            return
        if data.frame_id not in ('', self.global_frame):
            self.warner.warn(f'map frame {data.frame_id!r} is not {self.global_frame!r}: using '
                             'it as that frame')
        if self.tracker.set_map(grid):
            self.get_logger().info(f'map: {data.width} x {data.height} cells of '
                                   f'{data.resolution} m')

    def on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        """Reset the estimate to a pose given by the user (e.g. RViz "2D Pose Estimate")."""
        given = initial_pose(msg, self.global_frame, self.warner, self.initial_cov,
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
