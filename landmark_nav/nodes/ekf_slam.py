"""Executable ``ekf_slam``: EKF-SLAM with corner landmarks (corner chapter section 3).

Subscribes:

* ``odom`` (nav_msgs/Odometry, sensor-data QoS): wheel odometry, buffered;
* ``corners/features`` (sensor_msgs/PointCloud2 from ``corner_extractor``). Not the
  ``corners`` PoseArray: the cloud carries each corner's 2x2 position covariance (the
  observation noise ``R``) and its opening angle and bisector, which the association
  gate (descriptors) uses.

Each corner set is processed once odometry at or after its stamp has arrived: the buffered
odometry is linearly interpolated to the stamp (no message_filters), checked
(:func:`~landmark_nav.slam.ekf_slam.odometry_check`), turned into a prediction, and the
corners go through the laser mount (parameter ``laser_pose``) into the update; this is
the per-scan step of :func:`landmark_nav.evaluation.slam.run_slam` without the sweep
deskewing (the cloud has no beam times).

Corner sets are queued in stamp order, so one arriving late (older than a set still
waiting for odometry) is processed before the newer one; a set older than the last
processed step is skipped (the filter cannot go back in time).

Publishes (frame ``map_frame``, stamp of the corner set): ``pose``
(PoseWithCovarianceStamped) and ``odometry`` (nav_msgs/Odometry, child ``base_frame``) per
step; ``path`` (nav_msgs/Path: the last ``path_max_poses`` poses) and ``landmarks``
(MarkerArray: points and 2-sigma ellipses) every ``display_period`` seconds when they have
changed, so the cost per step and the memory do not grow with the length of the run.

Services (std_srvs/Trigger): ``save_map`` writes the landmarks and their covariances as
YAML to parameter ``map_file`` (a relative name is under ``$ROS_HOME/landmark_nav``,
``~/.ros/landmark_nav`` by default); ``reset`` restarts the filter at the next odometry.

Bad input is reported with a warning throttled per kind of problem and counted on
``/diagnostics`` (:class:`~landmark_nav.nodes.common.InputStats`): odometry going back in
time or jumping resets the filter cleanly; corners with NaN or with a covariance that is
not positive semi-definite are dropped; corner sets before any odometry, older than the
buffered odometry or than the last step are skipped; the oldest waiting set is dropped when
more than ``MAX_PENDING`` wait for odometry.
"""

import bisect
from collections import deque
from dataclasses import replace
from types import SimpleNamespace

from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from landmark_nav.conversions import (ConversionError, make_odometry,
                                      make_pose_with_covariance_stamped, ns_to_stamp,
                                      odometry_to_pose, pose_msg_from_2d, stamp_to_ns)
from landmark_nav.feature_msgs import feature_cloud_to_arrays, make_landmark_markers
from landmark_nav.geometry import interpolate_pose
from landmark_nav.nodes.common import (declare, declare_dataclass, InputStats,
                                       output_path, ParameterError, ProblemWarner, run_node,
                                       SENSOR_QOS)
from landmark_nav.slam.ekf_slam import (EkfSlam, odometry_check, odometry_increment,
                                        OdometryNoise, SlamParams)
from landmark_nav.slam.observations import corner_descriptors, corners_to_observations
from nav_msgs.msg import Odometry, Path as PathMsg
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray
import yaml

SLAM_PARAMETERS = {
    'sigma_range': ('default range std when a corner has no covariance [m]', None, None),
    'sigma_bearing': ('default bearing std [rad]', None, None),
    'r_scale': ('factor on the corner covariances (>= 1 inflates)', None, None),
    'range_floor': ('std added in quadrature to every range [m]', None, None),
    'bearing_floor': ('std added in quadrature to every bearing [rad]', None, None),
    'position_floor': ('isotropic corner position std added in quadrature [m]', None, None),
    'max_range': ('observations farther than this are rejected [m]', None, None),
    'association': ('data association: icnn or jcbb', None, ['icnn', 'jcbb']),
    'bisector_gate': ('largest bisector difference of a corner pair [rad]', None, None),
    'opening_gate': ('largest opening difference of a corner pair [rad]', None, None),
    'min_view_margin': ('reject corners with an arm seen within this of edge-on [rad]',
                        None, None),
    'gate_probability': ('confidence of the compatibility gate (eq. 55)', None, None),
    'new_landmark_probability': ('gate inside which an unmatched corner is ambiguous',
                                 None, None),
    'candidate_probability': ('gate confidence for matching candidates', None, None),
    'confirm_hits': ('observations a candidate needs to enter the map', None, None),
    'confirm_window': ('...within this many consecutive scans', None, None),
    'max_landmarks': ('map size budget (see map_full)', None, None),
    'map_full': ('when the map is full: evict the least recently seen landmark, or reject',
                 None, ['evict', 'reject']),
    'jcbb_max_nodes': ('node budget of JCBB per scan', None, None),
    'psd_tolerance': ('relative jitter of the PSD test of P', None, None),
    'psd_check_interval': ('test P every this many updates', None, None),
    'max_odometry_jump_m': ('odometry increment above this resets the filter [m]', None,
                            None),
    'max_odometry_jump_rad': ('odometry rotation above this resets the filter [rad]', None,
                              None),
    'max_update_iterations': ('largest number of linearisations of one update (1 = plain EKF)',
                              None, None),
    'relinearize_ratio': ('re-linearise when a landmark moves by more than this fraction of its '
                          'range', None, None),
}
ODOMETRY_PARAMETERS = {
    'sigma_xy_per_sqrt_m': ('odometry translation std per sqrt(m)', None, None),
    'sigma_yaw_per_sqrt_m': ('odometry heading std per sqrt(m)', None, None),
    'sigma_yaw_per_sqrt_rad': ('odometry heading std per sqrt(rad)', None, None),
    'sigma_xy_floor': ('odometry translation std floor per step [m]', None, None),
    'sigma_yaw_floor': ('odometry heading std floor per step [rad]', None, None),
}
MAX_BUFFER = 1000
MAX_PENDING = 100


class EkfSlamNode(Node):
    """Thin node: odometry + corner clouds -> :class:`EkfSlam` -> pose, path, map."""

    def __init__(self, **kwargs) -> None:
        """Declare the parameters, create subscriptions, publishers and services."""
        super().__init__('ekf_slam', **kwargs)
        params = declare_dataclass(self, SlamParams, SLAM_PARAMETERS)
        noise = declare_dataclass(self, OdometryNoise, ODOMETRY_PARAMETERS, 'odometry.')
        self.params = replace(params, odometry=noise)
        self.laser_pose = np.array(declare(
            self, 'laser_pose', [0.0, 0.0, 0.0], 'laser pose [x, y, yaw] in base_link'))
        if self.laser_pose.shape != (3,) or not np.all(np.isfinite(self.laser_pose)):
            raise ParameterError('parameter laser_pose must be 3 finite numbers [x, y, yaw]')
        self.map_frame = declare(self, 'map_frame', 'map', 'frame of the estimates')
        self.base_frame = declare(self, 'base_frame', 'base_link', 'robot frame')
        self.map_file = declare(self, 'map_file', 'landmarks.yaml',
                                'YAML file written by the save_map service (relative: under '
                                '$ROS_HOME/landmark_nav, default ~/.ros/landmark_nav)')
        self.path_max_poses = declare(self, 'path_max_poses', 2000,
                                      'poses kept in the published path (the latest)',
                                      (1, 1000000))
        display_period = declare(self, 'display_period', 0.5, 'period of the path and '
                                 'landmarks topics (published when changed) [s]',
                                 (0.01, 3600.0))
        self.warner = ProblemWarner(self)
        self.stats = InputStats(self, self.warner)
        self.pub_pose = self.create_publisher(PoseWithCovarianceStamped, 'pose', 10)
        self.pub_odom = self.create_publisher(Odometry, 'odometry', 10)
        self.pub_path = self.create_publisher(PathMsg, 'path', 10)
        self.pub_marks = self.create_publisher(MarkerArray, 'landmarks', 10)
        self.stats.subscribe(Odometry, 'odom', self.on_odom, SENSOR_QOS)
        self.stats.subscribe(PointCloud2, 'corners/features', self.on_corners, 10)
        self.create_timer(display_period, self.publish_display)
        self.create_service(Trigger, 'save_map', self.on_save_map)
        self.create_service(Trigger, 'reset', self.on_reset)
        self.odom_count = 0
        self.corner_count = 0
        self.resets = 0
        self._clear()
        self.get_logger().info(f'ekf_slam: association {self.params.association}')

    def _clear(self) -> None:
        """Forget the filter, odometry buffer, pending corner sets and path."""
        self.slam = None
        self.t0 = None
        self.odo_t, self.odo_p = [], []
        self.pending = []
        self.prev = None
        self.path_poses = deque(maxlen=self.path_max_poses)
        self.display_stamp = None

    def _restart(self, reason: str) -> None:
        self.warner.warn(f'Resetting EKF-SLAM: {reason}')
        self.resets += 1
        self._clear()

    def on_odom(self, msg: Odometry) -> None:
        """Buffer one odometry pose and process the corner sets it completes."""
        self.odom_count += 1
        try:
            d = odometry_to_pose(msg)
        except ConversionError as err:
            self.warner.warn(f'Dropping odometry: {err}')
            return
        t, pose = int(d.stamp_ns), np.asarray(d.pose, dtype=float)
        if not np.all(np.isfinite(pose)):
            self.warner.warn(f'Dropping odometry: pose {pose.tolist()} is not finite')
            return
        if self.odo_t and t <= self.odo_t[-1]:
            self._restart(f'odometry went back in time ({self.odo_t[-1]} -> {t} ns)')
        if self.slam is None:
            self.slam = EkfSlam(self.params, initial_pose=pose)
            self.t0, self.prev = t, (t, pose)
        self.odo_t.append(t)
        self.odo_p.append(pose)
        if len(self.odo_t) > MAX_BUFFER:
            del self.odo_t[0], self.odo_p[0]
        received = self.stats.received_ns
        while self.pending and self.pending[0][0] <= t:
            self._step(*self.pending.pop(0), received)

    def on_corners(self, msg: PointCloud2) -> None:
        """Validate one corner set and queue it until odometry covers its stamp."""
        self.corner_count += 1
        try:
            a = feature_cloud_to_arrays(msg)
            names = ('x', 'y', 'bisector', 'opening', 'cov_xx', 'cov_xy', 'cov_yy')
            missing = [n for n in names if n not in a]
            if missing:
                raise ConversionError(f'PointCloud2: missing fields {", ".join(missing)}')
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping corners: {err}')
            return
        t = stamp_to_ns(msg.header.stamp)
        if self.slam is None:
            self.stats.drop('no_odometry', 'Skipping corners: no odometry received yet')
            return
        if t < self.odo_t[0]:
            self.stats.drop('too_old', f'Skipping corners: stamp {t} ns is older than the '
                            f'buffered odometry (from {self.odo_t[0]} ns)')
            return
        if t < self.prev[0]:
            self.stats.drop('out_of_order', f'Skipping corners: stamp {t} ns is older than '
                            f'the last step at {self.prev[0]} ns (arrived out of order)')
            return
        cols = self._valid_corners(np.column_stack([a[n] for n in names]).reshape(
            -1, len(names)))
        corners = [SimpleNamespace(position=c[:2], bisector=c[2], opening=c[3],
                                   covariance=np.array([[c[4], c[5]], [c[5], c[6]]]))
                   for c in cols]
        received = self.stats.received_ns
        bisect.insort(self.pending, (t, received, corners), key=lambda item: item[0])
        if len(self.pending) > MAX_PENDING:
            old = self.pending.pop(0)
            self.stats.drop('not_covered', f'Dropping corners at {old[0]} ns: more than '
                            f'{MAX_PENDING} corner sets wait for odometry (newest {t} ns, '
                            f'odometry up to {self.odo_t[-1]} ns)')
        while self.pending and self.pending[0][0] <= self.odo_t[-1]:
            self._step(*self.pending.pop(0))

    def _valid_corners(self, cols: np.ndarray) -> np.ndarray:
        """Drop corner rows with NaN / inf or a covariance that is not PSD (with a warning)."""
        finite = np.all(np.isfinite(cols), axis=1)
        if not np.all(finite):
            bad = cols[~finite][0]
            self.warner.warn(f'Dropping {int(np.sum(~finite))} corners with NaN or inf '
                             f'(first: {bad.tolist()})')
        with np.errstate(invalid='ignore'):
            psd = (cols[:, 4] >= 0) & (cols[:, 6] >= 0) & (
                cols[:, 4] * cols[:, 6] - cols[:, 5] ** 2 >= 0)
        bad = finite & ~psd
        if np.any(bad):
            c = cols[bad][0]
            self.warner.warn(f'Dropping {int(np.sum(bad))} corners whose covariance is not '
                             f'positive semi-definite (first: cov_xx={c[4]:g}, '
                             f'cov_xy={c[5]:g}, cov_yy={c[6]:g})')
        return cols[finite & psd]

    def _step(self, t: int, received_ns: int, corners: list,
              odometry_received_ns: int = 0) -> None:
        """Predict to the corner stamp with interpolated odometry and update."""
        rel = (np.asarray(self.odo_t, dtype=np.int64) - self.t0) * 1e-9
        odo = interpolate_pose((t - self.t0) * 1e-9, rel, np.array(self.odo_p))
        odo = np.asarray(odo, dtype=float).reshape(3)
        prm = self.params
        bad = odometry_check(self.prev[0], self.prev[1], t, odo, prm.max_odometry_jump_m,
                             prm.max_odometry_jump_rad)
        if bad is not None:
            self.warner.warn(f'Resetting EKF-SLAM: {bad}')
            self.resets += 1
            self.slam.reset(odo)
            self.path_poses.clear()
        else:
            self.slam.predict(odometry_increment(self.prev[1], odo))
        self.prev = (t, odo)
        z, r = corners_to_observations(corners, self.laser_pose)
        desc = corner_descriptors(corners, self.laser_pose)
        self.slam.update(z, r, desc)
        self._publish(t)
        self.stats.processed(max(received_ns, odometry_received_ns))

    def _publish(self, t: int) -> None:
        """Publish the pose of one step and remember it for the path."""
        pose, cov = self.slam.pose, self.slam.pose_covariance
        self.pub_pose.publish(make_pose_with_covariance_stamped(t, self.map_frame, pose, cov))
        self.pub_odom.publish(make_odometry(t, self.map_frame, self.base_frame, pose, cov))
        self.path_poses.append((t, pose.copy()))
        self.display_stamp = t

    def path_message(self) -> PathMsg:
        """Return the path of the last ``path_max_poses`` steps."""
        path = PathMsg()
        path.header.frame_id = self.map_frame
        for t, pose in self.path_poses:
            ps = PoseStamped()
            ps.header.stamp = ns_to_stamp(t)
            ps.header.frame_id = self.map_frame
            ps.pose = pose_msg_from_2d(pose)
            path.poses.append(ps)
        if path.poses:
            path.header.stamp = path.poses[-1].header.stamp
        return path

    def publish_display(self) -> None:
        """Publish the path and the landmarks if a step was made since the last time."""
        if self.display_stamp is None:
            return
        t, self.display_stamp = self.display_stamp, None
        self.pub_path.publish(self.path_message())
        self.pub_marks.publish(self.landmark_markers(t))

    def landmark_markers(self, t: int) -> MarkerArray:
        """Return the map as one 2-sigma ellipse per landmark."""
        if self.slam is None:
            return make_landmark_markers(t, self.map_frame, [], [], [])
        return make_landmark_markers(t, self.map_frame, self.slam.landmark_ids,
                                     self.slam.landmarks, self.slam.landmark_covariances)

    def map_dict(self) -> dict:
        """Return the map as a YAML-able dict."""
        if self.slam is None:
            return {'frame_id': self.map_frame, 'landmarks': []}
        return {'frame_id': self.map_frame, 'landmarks': [
            {'id': int(i), 'x': float(m[0]), 'y': float(m[1]),
             'covariance': [float(v) for v in np.asarray(c).reshape(4)]}
            for i, m, c in zip(self.slam.landmark_ids, self.slam.landmarks,
                               self.slam.landmark_covariances)]}

    def on_save_map(self, request, response):
        """Write the landmarks and covariances to ``map_file``."""
        data = self.map_dict()
        try:
            path = output_path(self.map_file)
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
