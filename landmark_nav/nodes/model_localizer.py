"""Executable ``model_localizer``: monocular localization against a 3-D line model (EKF).

Self-localization chapter §5: image lines by Canny + RWRHT (Algorithm 2), model lines
visible from the predicted pose, matching in Hough space, EKF with the calibrated odometry
(:class:`landmark_nav.monocular.localizer.ModelLocalizer`; this node converts messages).

Subscribes (sensor-data QoS): ``camera/image_raw`` (sensor_msgs/Image, mono8/bgr8/rgb8...),
``camera/camera_info`` (its K; distorted image lines are undistorted with its D), ``odom``
(nav_msgs/Odometry: successive poses give the increments, recalibrated with k1..k3), and
``initialpose`` (geometry_msgs/PoseWithCovarianceStamped in ``global_frame``, as RViz sends
it): resets the pose and covariance.

Publishes, stamped with the image: ``pose`` (geometry_msgs/PoseWithCovarianceStamped in
``global_frame``) after every image, ``model_localizer/status`` (std_msgs/String:
``tracking`` or ``lost``) when it changes, and with ``publish_debug_image`` the image with
the model lines rendered at the prior pose (red), the matched image lines (green) and the
other image lines (blue) on ``model_localizer/debug_image`` (bgr8). Inputs processed and
dropped (with the reasons: ``dropped.camera_info_malformed``, ``dropped.initialpose_frame``
...) and the latency are on ``/diagnostics``; odometry older than the last sample restarts
the increments (``odometry.back_in_time``).

Bad input -- undecodable images, no CameraInfo yet or one without a focal length, an image
whose size disagrees with it, frames without lines, an empty model, a pose outside the
model, odometry going back in time -- gives a warning throttled per kind of problem; the
node keeps running.
"""

import math

import cv2
from geometry_msgs.msg import PoseWithCovarianceStamped
from landmark_nav.conversions import (array_to_image, camera_info_to_model, ConversionError,
                                      make_pose_with_covariance_stamped, odometry_to_pose,
                                      stamp_to_ns)
from landmark_nav.landmark_msgs import image_to_gray
from landmark_nav.localization.odometry import (calibrate_control, control_from_poses,
                                                ProcessNoise)
from landmark_nav.monocular.localizer import LocalizerParams, LOST, ModelLocalizer
from landmark_nav.monocular.matching import MatchParams
from landmark_nav.monocular.model import DEFAULT_MODEL_PATH, load_model, ModelError
from landmark_nav.monocular.visibility import CameraMount, Intrinsics
from landmark_nav.nodes.common import (declare, initial_pose, InputStats, ParameterError,
                                       ProblemWarner, reject_undeclared, run_node, SENSOR_QOS)
from landmark_nav.vision.image_lines import undistort_segments
from landmark_nav.vision.rwrht import detect_model_lines, MODEL_LINE_METHODS
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String


class ModelLocalizerNode(Node):
    """Thin node: odom -> predict; image -> lines -> match + update -> pose."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters, load the model, create the interfaces."""
        super().__init__('model_localizer', **kwargs)

        def d(*args, **kw):
            return declare(self, *args, **kw)

        model_file = d('model_file', '', '3-D line model (YAML, landmark_nav_line_model/1); '
                       'empty: the packaged hallway model')
        self.method = d('line_method', 'rwrht', 'image lines: rwrht (the chapter), hough_p, '
                        'lsd or segmented_hough', choices=list(MODEL_LINE_METHODS))
        mount = d('camera_mount', [0.0, 0.0, 0.45, 0.0], 'camera optical centre in base_link: '
                  'x, y, z [m] (z = height above the floor) and downward pitch [rad]')
        pose0 = d('initial_pose', [0.75, 0.0, 0.0], 'initial x, y [m], yaw [rad] in '
                  'global_frame')
        std0 = d('initial_std', [0.0548, 0.0548, 0.0894], 'initial std of x, y [m] and yaw '
                 '[rad] (the chapter: 0.3 dm^2, 0.3 dm^2, 0.008 rad^2)')
        self.axle = d('axle_length', 0.33, 'nominal axle length b [m]', (0.01, 5.0))
        self.k = tuple(d(f'k{i}', 1.0, f'odometry calibration factor k{i} (eqs. 17-18)',
                         (0.5, 2.0)) for i in (1, 2, 3))
        noise = ProcessNoise(
            d('sigma_d', 0.002, 'std of the distance per odometry step [m]', (0.0, 1.0)),
            d('sigma_dtheta', 0.05, 'relative std of the rotation per step', (0.0, 1.0)),
            d('k_d', 0.02, 'distance std per metre travelled', (0.0, 1.0)),
            d('k_theta', 0.05, 'heading std per metre travelled [rad/m]', (0.0, 1.0)))
        match = MatchParams(
            gate=d('gate_chi2', 9.21, 'Mahalanobis gate of a pair (chi-square 2 dof)',
                   (0.5, 100.0)),
            sigma_px=d('sigma_px', 0.9, 'end-point noise of image lines [px]', (0.05, 10.0)),
            min_length_px=d('min_line_px', 15.0, 'shortest image / model line used [px]',
                            (1.0, 1000.0)),
            resolve_px=d('resolve_px', 3.0, 'model lines closer than this to a parallel '
                         'model line are not matched [px] (0: off)', (0.0, 50.0)))
        params = LocalizerParams(
            noise=noise, match=match, min_line_px=match.min_length_px,
            model_sigma_m=d('model_sigma_m', 0.02, 'std of the model vertices [m]',
                            (0.0, 1.0)),
            min_matches=d('min_matches', 2, 'pairs needed for an update', (1, 100)),
            lost_after_s=d('lost_after', 1.0, 'report lost after this long without an '
                           'update [s]', (0.01, 600.0)),
            recover_matches=d('recover_matches', 4, 'pairs needed to leave the lost state',
                              (1, 100)))
        self.frame_id = d('global_frame', 'map', 'frame of pose and initialpose')
        self.debug = d('publish_debug_image', False, 'publish model_localizer/debug_image')
        reject_undeclared(self)
        for name, vec, n in (('camera_mount', mount, 4), ('initial_pose', pose0, 3),
                             ('initial_std', std0, 3)):
            if len(vec) != n or not all(math.isfinite(v) for v in vec):
                raise ParameterError(f'parameter {name} must be {n} finite numbers; got {vec}')
        if min(std0) <= 0:
            raise ParameterError(f'parameter initial_std must be > 0; got {std0}')
        try:
            model = load_model(model_file or DEFAULT_MODEL_PATH)
        except ModelError as err:
            raise ParameterError(f'parameter model_file: {err}') from err
        self.warner = ProblemWarner(self)
        self.stats = InputStats(self, self.warner)
        self.initial_cov = np.diag(np.square(std0))
        self.loc = ModelLocalizer(model, Intrinsics.chapter(), CameraMount(*mount), params)
        self.loc.reset(pose0, self.initial_cov)
        self.camera = None
        self.rng = np.random.default_rng(0)
        self.last_odom = None            # (stamp_ns, pose)
        self.status = None
        self.frames = 0
        if model.edges.shape[0] == 0:
            self.warner.warn(f'the line model {model_file or DEFAULT_MODEL_PATH} has no edges')
        self.pub_pose = self.create_publisher(PoseWithCovarianceStamped, 'pose', 10)
        self.pub_status = self.create_publisher(String, 'model_localizer/status', 10)
        self.pub_debug = self.create_publisher(Image, 'model_localizer/debug_image', 2) \
            if self.debug else None
        self.create_subscription(CameraInfo, 'camera/camera_info', self.on_info, SENSOR_QOS)
        self.stats.subscribe(Odometry, 'odom', self.on_odom, SENSOR_QOS)
        self.stats.subscribe(Image, 'camera/image_raw', self.on_image, SENSOR_QOS)
        self.create_subscription(PoseWithCovarianceStamped, 'initialpose',
                                 self.on_initial_pose, 10)

    def on_info(self, msg: CameraInfo) -> None:
        """Keep the latest valid camera model."""
        try:
            cam = camera_info_to_model(msg)
            K = cam.K
            intr = Intrinsics(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]),
                              cam.width, cam.height)
        except (ConversionError, ValueError) as err:
            self.stats.drop('camera_info_malformed', f'Ignoring camera_info: {err}')
            return
        self.camera = cam
        self.loc.set_intrinsics(intr)

    def on_odom(self, msg: Odometry) -> None:
        """Predict with the calibrated odometry increment."""
        try:
            data = odometry_to_pose(msg)
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping odometry: {err}')
            return
        last = self.last_odom
        if last is not None and data.stamp_ns < last[0]:
            self.stats.event('odometry.back_in_time', 'Odometry went back in time; restarting '
                             'the increments')
        elif last is not None:
            u = calibrate_control(control_from_poses(last[1], data.pose), self.axle, self.k)
            self.loc.predict(u)
        self.last_odom = (data.stamp_ns, np.array(data.pose))
        self.stats.processed()

    def on_image(self, msg: Image) -> None:
        """Find the image lines, match them to the model and update the pose."""
        cam = self.camera
        if cam is None:
            self.stats.drop('no_camera_info', 'Dropping image: no valid CameraInfo received '
                            'yet')
            return
        try:
            gray = image_to_gray(msg, 'model_localizer')
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping image: {err}')
            return
        if gray.shape != (cam.height, cam.width):
            self.stats.drop('size', f'Dropping image: size {gray.shape[1]}x{gray.shape[0]} '
                            f'disagrees with CameraInfo {cam.width}x{cam.height}')
            return
        stamp = stamp_to_ns(msg.header.stamp)
        lines = undistort_segments(detect_model_lines(gray, self.method, rng=self.rng), cam)
        res = self.loc.update(lines.segments, stamp * 1e-9)
        if res.problem:
            self.warner.warn(f'No update: {res.problem}')
        if res.became_lost:
            self.warner.warn('Lost: too few model lines matched for '
                             f'{self.loc.params.lost_after_s} s; covariance inflated')
        if res.recovered:
            self.get_logger().info(f'Recovered: {len(res.matches)} model lines matched')
        if res.status != self.status:
            self.status = res.status
            self.pub_status.publish(String(data=res.status))
        self.frames += 1
        self.pub_pose.publish(make_pose_with_covariance_stamped(stamp, self.frame_id,
                                                                res.pose, res.cov))
        self.stats.processed()
        self._debug(gray, lines.segments, res, stamp, msg.header.frame_id)

    def on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        """Reset the estimate (e.g. RViz "2D Pose Estimate")."""
        given = initial_pose(msg, self.frame_id, self.stats, self.initial_cov, 'initial_std')
        if given is None:
            return
        self.loc.reset(*given)
        x, y, yaw = given[0]
        self.get_logger().info(f'estimate reset to x={x:.3f} m, y={y:.3f} m, '
                               f'yaw={math.degrees(yaw):.1f} deg')

    def _debug(self, gray: np.ndarray, segments: np.ndarray, res, stamp: int,
               frame: str) -> None:
        if self.pub_debug is None:
            return
        img = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
        matched = set()
        if res.matches is not None and res.updated:
            matched = {int(j) for j in res.matches.image}
        for j, s in enumerate(segments):
            colour = (0, 200, 0) if j in matched else (255, 120, 0)
            cv2.line(img, (int(s[0]), int(s[1])), (int(s[2]), int(s[3])), colour, 1)
        if res.predicted is not None:
            for s in res.predicted.visible.pixels:
                cv2.line(img, (int(s[0]), int(s[1])), (int(s[2]), int(s[3])), (0, 0, 255), 1)
        if res.status == LOST:
            cv2.putText(img, 'LOST', (5, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 255), 2)
        self.pub_debug.publish(array_to_image(img, 'bgr8', stamp, frame))


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav model_localizer``."""
    return run_node(ModelLocalizerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
