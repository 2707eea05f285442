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
for ``stale_timeout`` seconds of message time, or none yet). Bad input gives a warning
throttled per kind of problem and a count on ``/diagnostics``
(:class:`~landmark_nav.nodes.common.InputStats`, ``corridor_follower: input``): images and
odometry that cannot be read (``dropped.malformed``, also an image whose size disagrees with
the CameraInfo), images before a valid CameraInfo (``dropped.no_camera_info``), messages
lost before the callback (``dropped.lost``); frames without a corridor
(``image.corridor_lost``), visual estimates the gate rejects (``image.rejected``) and
odometry going back in time (``odometry.back_in_time``). A CameraInfo that does not
convert (e.g. zero focal length) is ignored with a warning (``dropped.camera_info_malformed``).
"""

import cv2
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped, Twist, TwistStamped
from landmark_nav.conversions import (array_to_image, camera_info_to_model, ConversionError,
                                      make_pose_with_covariance_stamped, odometry_to_pose,
                                      stamp_to_ns)
from landmark_nav.corridor.configuration import follower_configuration, parameters
from landmark_nav.corridor.controller import CorridorController
from landmark_nav.corridor.follower import CorridorTracker
from landmark_nav.landmark_msgs import compressed_to_gray, image_to_gray
from landmark_nav.nodes.common import declare, InputStats, ParameterError, ProblemWarner, \
    reject_undeclared, run_node, SENSOR_QOS
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_srvs.srv import SetBool


class CorridorFollower(Node):
    """Thin node around :class:`~landmark_nav.corridor.follower.CorridorTracker`.

    image -> measure_frame -> EKF update; odom -> EKF predict -> cmd_vel.
    """

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters and create the interfaces."""
        super().__init__('corridor_follower', **kwargs)
        values = {name: declare(self, name, *p[:4]) for name, p in parameters().items()}
        reject_undeclared(self)
        try:
            config = follower_configuration(values)
        except ValueError as err:
            raise ParameterError(str(err)) from None
        self.stale, self.compressed = values['stale_timeout'], values['compressed']
        self.frame_id, self.debug = values['corridor_frame'], values['publish_debug_image']
        stamped, enabled = values['stamped_cmd_vel'], values['enabled']
        self.tracker = CorridorTracker(config.follower)
        self.controller = CorridorController(config.controller)
        self.enabled = enabled
        self.warner = ProblemWarner(self)
        self.stats = InputStats(self, self.warner)
        self.camera = None
        self.pub_pose = self.create_publisher(PoseWithCovarianceStamped, 'corridor/pose', 10)
        self.pub_vp = self.create_publisher(PointStamped, 'corridor/vanishing_point', 10)
        self.pub_debug = self.create_publisher(Image, 'corridor/debug_image', 2) \
            if self.debug else None
        self.twist_type = TwistStamped if stamped else Twist
        self.pub_cmd = self.create_publisher(self.twist_type, 'cmd_vel', 10)
        self.create_service(SetBool, '~/enable', self.on_enable)
        self.create_subscription(CameraInfo, 'camera/camera_info', self.on_info, SENSOR_QOS)
        self.stats.subscribe(Odometry, 'odom', self.on_odom, SENSOR_QOS)
        if self.compressed:
            self.stats.subscribe(CompressedImage, 'camera/image_raw/compressed',
                                 self.on_compressed, SENSOR_QOS)
        else:
            self.stats.subscribe(Image, 'camera/image_raw', self.on_image, SENSOR_QOS)

    @property
    def ekf(self):
        """Return the tracker's EKF (None before the first measurement)."""
        return self.tracker.ekf

    @property
    def last_odom(self):
        """Return ``(stamp_ns, pose)`` of the last odometry message (None before)."""
        return self.tracker.last_odom

    @property
    def frames(self) -> int:
        """Return the number of frames that gave a measurement."""
        return self.tracker.frames

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
            self.stats.drop('camera_info_malformed', f'Ignoring camera_info: {err}')

    def on_image(self, msg: Image) -> None:
        """Convert and process one raw image."""
        try:
            gray = image_to_gray(msg, 'corridor_follower')
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping image: {err}')
            return
        self.process(msg.header, gray)

    def on_compressed(self, msg: CompressedImage) -> None:
        """Decode and process one compressed image."""
        try:
            gray = compressed_to_gray(msg)
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping image: {err}')
            return
        self.process(msg.header, gray)

    def process(self, header, gray: np.ndarray) -> None:
        """Measure heading and lateral position in one frame and update the filter."""
        stamp = stamp_to_ns(header.stamp)
        step = self.tracker.frame(gray, self.camera, stamp)
        if step.status == 'dropped':
            reason = 'no_camera_info' if self.camera is None else 'malformed'
            self.stats.drop(reason, f'Dropping image: {step.message}')
            return
        self.stats.processed()
        if step.status == 'lost':
            self.stats.event('image.corridor_lost', f'Corridor lost: {step.message}')
            self._debug(gray, None, stamp, header.frame_id)
            return
        if step.status == 'rejected':
            self.stats.event('image.rejected', 'Visual estimate rejected by the gate (NIS '
                             f'{step.nis:.1f})')
        m = step.measurement
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
            self.stats.drop('malformed', f'Dropping odometry: {err}')
            return
        stamp = pose.stamp_ns
        status, dt = self.tracker.odometry(stamp, pose.pose)
        self.stats.processed()
        if status == 'back_in_time':
            self.stats.event('odometry.back_in_time', 'Odometry went back in time; restarting '
                             'the increments')
        elif status == 'predicted':
            self._publish_pose(stamp)
        if not self.enabled:
            return
        usable = self.tracker.fresh(stamp, self.stale)
        if not usable:
            self.warner.warn('Stopping: corridor estimate lost or stale')
        th, y = self.tracker.steering_errors()       # relative to the direction of travel
        v, w = self.controller.step(th, y, dt, usable)
        self._publish_cmd(v, w, msg.header.stamp)

    # ------------------------------------------------------------------ outputs
    def _publish_pose(self, stamp: int) -> None:
        pose, cov = self.tracker.estimate()
        self.pub_pose.publish(make_pose_with_covariance_stamped(stamp, self.frame_id, pose,
                                                                cov))

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
