"""Executable ``corridor_follower``: vanishing point, heading and lateral position, EKF, cmd_vel.

Visual navigation chapter §3. Subscribes (sensor-data QoS) ``camera/image_raw``
(sensor_msgs/Image) -- or ``camera/image_raw/compressed`` with ``compressed: true`` --
``camera/camera_info`` and ``odom`` (nav_msgs/Odometry). Publishes:

* ``corridor/pose`` (geometry_msgs/PoseWithCovarianceStamped, frame ``corridor_frame``):
  the fused estimate, x along the corridor (from where the filter started), y lateral
  (left positive, 0 on the centre line), yaw = heading relative to the corridor; stamped
  with the image (after a visual update) or the odometry (after a prediction);
* ``corridor/vanishing_point`` (geometry_msgs/PointStamped, camera frame): the corridor
  VP in ideal pixels (x = column, y = row, z = 0); not published when it lies at infinity;
* ``corridor/debug_image`` (sensor_msgs/Image bgr8) with ``publish_debug_image: true``;
* ``cmd_vel`` (geometry_msgs/Twist, or TwistStamped with ``stamped_cmd_vel: true``) on
  every odometry message while enabled (service ``~/enable``, std_srvs/SetBool).

The robot is stopped (zero twist) while the estimate is lost (no accepted visual update
for ``stale_timeout`` seconds of message time, or none yet). Bad input (undecodable images,
no CameraInfo, CameraInfo that does not convert, e.g. zero focal length, frames without a
corridor, odometry going back in time) gives a warning throttled per kind of problem.
"""

import math

import cv2
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped, Twist, TwistStamped
from landmark_nav.conversions import (array_to_image, camera_info_to_model, ConversionError,
                                      make_pose_with_covariance_stamped, odometry_to_pose,
                                      stamp_to_ns)
from landmark_nav.corridor.controller import ControllerParams, CorridorController
from landmark_nav.corridor.frame import CorridorLost, FrameParams, measure_frame
from landmark_nav.corridor.fusion import CorridorEKF, DeadReckoningNoise
from landmark_nav.corridor.lateral import CorridorModel
from landmark_nav.corridor.vanishing_point import VPParams
from landmark_nav.geometry import relative, wrap_angle
from landmark_nav.landmark_msgs import compressed_to_gray, image_to_gray
from landmark_nav.nodes.common import declare, ParameterError, ProblemWarner, run_node, \
    SENSOR_QOS
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_srvs.srv import SetBool


class CorridorFollower(Node):
    """Thin node: image -> measure_frame -> EKF update; odom -> EKF predict -> cmd_vel."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters and create the interfaces."""
        super().__init__('corridor_follower', **kwargs)

        def d(*args, **kwargs):
            return declare(self, *args, **kwargs)

        width = d('corridor_width', 2.0, 'wall-to-wall width [m]', (0.3, 20.0))
        height = d('corridor_height', 2.6, 'floor-to-ceiling height [m]; 0: ceiling edges '
                   'not used', (0.0, 20.0))
        centre = d('centre_line', False, 'the floor has a line along the corridor centre')
        mount = d('camera_mount', [0.0, 0.0, 1.0, 0.0, 0.0, 0.0], 'camera_link pose in '
                  'base_link: x, y, z [m] (z = height above the floor), roll, pitch, yaw [rad]')
        method = d('line_method', 'segmented_hough', 'image lines: segmented_hough (the '
                   'chapter), hough_p or lsd', choices=['segmented_hough', 'hough_p', 'lsd'])
        sigma = d('sigma_px', 0.6, 'end-point noise of image line segments [px]', (0.05, 5.0))
        h_floor = d('heading_std_floor_deg', 0.3, 'added to the visual heading std [deg]',
                    (0.0, 20.0))
        y_floor = d('lateral_std_floor', 0.02, 'added to the visual lateral std [m]',
                    (0.0, 2.0))
        max_axis = d('max_axis_angle_deg', 45.0, 'the corridor VP must lie within this angle '
                     'of the optical axis [deg]', (1.0, 89.0))
        b = d('wheel_separation', 0.33, 'effective wheel separation [m]', (0.01, 5.0))
        k_l = d('k_left', 1e-4, 'left wheel distance variance per metre [m^2/m]', (0.0, 1.0))
        k_r = d('k_right', 1e-4, 'right wheel distance variance per metre [m^2/m]', (0.0, 1.0))
        sb = d('sigma_separation', 0.001, 'std of the wheel separation per step [m]',
               (0.0, 1.0))
        gate = d('gate_chi2', 13.8, 'NIS outlier gate (chi-square 2 dof; 13.8 = 99.9 %)',
                 (1.0, 1000.0))
        self.stale = d('stale_timeout', 1.0, 'stop when no visual update was accepted for '
                       'this long [s]', (0.05, 60.0))
        self.compressed = d('compressed', False, 'subscribe camera/image_raw/compressed')
        self.frame_id = d('corridor_frame', 'corridor', 'frame of corridor/pose')
        self.debug = d('publish_debug_image', False, 'publish corridor/debug_image')
        stamped = d('stamped_cmd_vel', False, 'publish geometry_msgs/TwistStamped on cmd_vel')
        enabled = d('enabled', False, 'drive at start-up (else wait for ~/enable)')
        ctrl = {k: d(k, v, doc, lim) for k, v, doc, lim in (
            ('speed', 0.3, 'forward speed set-point [m/s]', (0.01, 3.0)),
            ('lateral_offset', 0.0, 'lateral set-point [m], left of the direction of travel '
             'positive', (-10.0, 10.0)),
            ('gain_lateral', 4.0, 'turn per m driven per m of lateral error [1/m^2]',
             (0.01, 100.0)),
            ('gain_heading', 4.0, 'turn per m driven per rad of heading error [1/m] '
             '(critically damped: 2 sqrt(gain_lateral))', (0.01, 100.0)),
            ('max_accel', 0.3, 'forward acceleration limit [m/s^2]', (0.01, 10.0)),
            ('max_angular_speed', 0.5, 'angular speed limit [rad/s]', (0.01, 10.0)))}
        if len(mount) != 6 or not all(math.isfinite(v) for v in mount):
            raise ParameterError(f'parameter camera_mount must be 6 finite numbers; got {mount}')
        if not mount[2] > 0.0 or (height > 0.0 and mount[2] >= height):
            raise ParameterError(f'parameter camera_mount: camera height {mount[2]} m must lie '
                                 f'between floor and ceiling ({height} m)')
        if abs(ctrl['lateral_offset']) >= width / 2:
            raise ParameterError('parameter lateral_offset must lie inside the corridor')
        self.model = CorridorModel(width, height or None, centre)
        self.mount = mount
        self.params = FrameParams(line_method=method, vp=VPParams(sigma_px=sigma),
                                  max_axis_angle_deg=max_axis,
                                  heading_std_floor=math.radians(h_floor),
                                  lateral_std_floor=y_floor)
        self.noise = DeadReckoningNoise(b, k_l, k_r, sb)
        self.gate = gate
        self.controller = CorridorController(ControllerParams(**ctrl))
        self.enabled = enabled
        self.warner = ProblemWarner(self)
        self.camera = None
        self.ekf = None
        self.last_odom = None            # (stamp_ns, pose)
        self.last_fix_ns = None
        self.frames = 0
        self.pub_pose = self.create_publisher(PoseWithCovarianceStamped, 'corridor/pose', 10)
        self.pub_vp = self.create_publisher(PointStamped, 'corridor/vanishing_point', 10)
        self.pub_debug = self.create_publisher(Image, 'corridor/debug_image', 2) \
            if self.debug else None
        self.twist_type = TwistStamped if stamped else Twist
        self.pub_cmd = self.create_publisher(self.twist_type, 'cmd_vel', 10)
        self.create_service(SetBool, '~/enable', self.on_enable)
        self.create_subscription(CameraInfo, 'camera/camera_info', self.on_info, SENSOR_QOS)
        self.create_subscription(Odometry, 'odom', self.on_odom, SENSOR_QOS)
        if self.compressed:
            self.create_subscription(CompressedImage, 'camera/image_raw/compressed',
                                     self.on_compressed, SENSOR_QOS)
        else:
            self.create_subscription(Image, 'camera/image_raw', self.on_image, SENSOR_QOS)

    # ------------------------------------------------------------------ inputs
    def on_enable(self, request, response):
        """Enable or disable driving (disabling publishes one stop)."""
        self.enabled = bool(request.data)
        if not self.enabled:
            self.controller.step(0.0, 0.0, 0.0, False)
        response.success = True
        response.message = 'enabled' if self.enabled else 'disabled'
        return response

    def on_info(self, msg: CameraInfo) -> None:
        """Keep the latest valid camera model."""
        try:
            self.camera = camera_info_to_model(msg)
        except ConversionError as err:
            self.warner.warn(f'Ignoring camera_info: {err}')

    def on_image(self, msg: Image) -> None:
        """Convert and process one raw image."""
        try:
            self.process(msg.header, image_to_gray(msg))
        except ConversionError as err:
            self.warner.warn(f'Dropping image: {err}')

    def on_compressed(self, msg: CompressedImage) -> None:
        """Decode and process one compressed image."""
        try:
            self.process(msg.header, compressed_to_gray(msg))
        except ConversionError as err:
            self.warner.warn(f'Dropping image: {err}')

    def process(self, header, gray: np.ndarray) -> None:
        """Measure heading and lateral position in one frame and update the filter."""
        cam = self.camera
        if cam is None:
            self.warner.warn('Dropping image: no valid CameraInfo received yet')
            return
        if gray.shape != (cam.height, cam.width):
            self.warner.warn(f'Dropping image: size {gray.shape[1]}x{gray.shape[0]} disagrees '
                             f'with CameraInfo {cam.width}x{cam.height}')
            return
        stamp = stamp_to_ns(header.stamp)
        prior = None if self.ekf is None else self.ekf.visual_prior()
        try:
            m = measure_frame(gray, cam, self.model, self.mount, prior, self.params)
        except CorridorLost as err:
            self.warner.warn(f'Corridor lost: {err}')
            self._debug(gray, None, stamp, header.frame_id)
            return
        if self.ekf is None:
            self.ekf = CorridorEKF([m.heading, 0.0, m.y], np.diag(
                [m.heading_std ** 2, 0.0, m.y_std ** 2]), self.noise, self.gate)
            accepted = True
        else:
            res = self.ekf.update(m.heading, m.y, m.covariance)
            accepted = res.accepted
            if not accepted:
                self.warner.warn(f'Visual estimate rejected by the gate (NIS {res.nis:.1f})')
        if accepted:
            self.last_fix_ns = stamp
        self.frames += 1
        px = m.vp.pixel
        if px is not None:
            vp = PointStamped()
            vp.header = header
            vp.point.x, vp.point.y = float(px[0]), float(px[1])
            self.pub_vp.publish(vp)
        self._publish_pose(stamp)
        self._debug(gray, m, stamp, header.frame_id)

    def on_odom(self, msg: Odometry) -> None:
        """Predict with the odometry increment and publish cmd_vel."""
        try:
            pose = odometry_to_pose(msg)
        except ConversionError as err:
            self.warner.warn(f'Dropping odometry: {err}')
            return
        stamp = pose.stamp_ns
        last = self.last_odom
        dt = 0.0
        if last is not None and stamp < last[0]:
            self.warner.warn('Odometry went back in time; restarting the increments')
        elif last is not None and self.ekf is not None:
            inc = relative(last[1], pose.pose)
            self.ekf.predict(float(inc[0]), float(inc[2]))
            dt = (stamp - last[0]) * 1e-9
            self._publish_pose(stamp)
        self.last_odom = (stamp, pose.pose)
        if not self.enabled:
            return
        usable = (self.ekf is not None and self.last_fix_ns is not None
                  and (stamp - self.last_fix_ns) * 1e-9 <= self.stale)
        if not usable:
            self.warner.warn('Stopping: corridor estimate lost or stale')
        th, y = 0.0, 0.0
        if self.ekf is not None:               # relative to the direction of travel
            th, y = float(self.ekf.s[0]), self.ekf.visual_prior()[0]
            if self.ekf.facing_back:
                th = wrap_angle(th - math.pi)
        v, w = self.controller.step(th, y, dt, usable)
        self._publish_cmd(v, w, msg.header.stamp)

    # ------------------------------------------------------------------ outputs
    def _publish_pose(self, stamp: int) -> None:
        th, x, y = self.ekf.state
        p = self.ekf.p
        order = [1, 2, 0]                                   # (x, y, yaw) from (theta, x, y)
        cov = p[np.ix_(order, order)]
        self.pub_pose.publish(make_pose_with_covariance_stamped(stamp, self.frame_id,
                                                                [x, y, th], cov))

    def _publish_cmd(self, v: float, w: float, stamp) -> None:
        msg = self.twist_type()
        twist = msg.twist if self.twist_type is TwistStamped else msg
        if self.twist_type is TwistStamped:
            msg.header.stamp = stamp
            msg.header.frame_id = 'base_link'
        twist.linear.x, twist.angular.z = float(v), float(w)
        self.pub_cmd.publish(msg)

    def _debug(self, gray: np.ndarray, m, stamp: int, frame: str) -> None:
        if self.pub_debug is None:
            return
        img = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
        if m is not None:
            for k, s in enumerate(m.lines.segments.astype(int)):
                colour = (0, 0, 255) if m.vp.inliers[k] else (0, 160, 0)
                cv2.line(img, (int(s[0]), int(s[1])), (int(s[2]), int(s[3])), colour, 1)
            if m.vp.pixel is not None:
                cv2.drawMarker(img, tuple(int(round(c)) for c in m.vp.pixel), (255, 0, 0),
                               cv2.MARKER_CROSS, 20, 2)
        self.pub_debug.publish(array_to_image(img, 'bgr8', stamp, frame))


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav corridor_follower``."""
    return run_node(CorridorFollower, args)


if __name__ == '__main__':
    raise SystemExit(main())
