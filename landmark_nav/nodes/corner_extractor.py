"""Executable ``corner_extractor``: corners of each laser scan (corner chapter section 2).

Subscribes ``scan`` (sensor_msgs/LaserScan, sensor-data QoS). Publishes, with the scan's
stamp and frame:

* ``corners`` (geometry_msgs/PoseArray): corner positions, orientation = bisector;
* ``corners/features`` (sensor_msgs/PointCloud2): position, bisector, opening angle and
  the 2x2 position covariance per corner (see :mod:`landmark_nav.feature_msgs`);
* ``corners/markers`` (visualization_msgs/MarkerArray) for RViz.

A malformed scan is dropped with a throttled warning naming the problem.
"""

import math

from geometry_msgs.msg import PoseArray
from landmark_nav.conversions import ConversionError, scan_to_data
from landmark_nav.feature_msgs import (make_corner_cloud, make_corner_markers,
                                       make_corner_pose_array)
from landmark_nav.laser.corners import CornerParams, detect_corners
from landmark_nav.laser.segmentation import segment_scan
from landmark_nav.nodes.common import (declare, declare_dataclass, ProblemWarner, run_node,
                                       SENSOR_QOS)
from rclpy.node import Node
from sensor_msgs.msg import LaserScan, PointCloud2
from visualization_msgs.msg import MarkerArray

CORNER_PARAMETERS = {
    'method': ('corner detector: minus_cosine (the proposed method of the chapter), '
               'sliding_window or split_merge', None,
               ['minus_cosine', 'sliding_window', 'split_merge']),
    'window': ('sliding window size in beams (odd)', (5, 101), None),
    'f_min': ('lower bound of the minus-cosine f(theta) (eq. 11), -0.3436 ~ 110 deg',
              (-1.0, 1.0), None),
    'f_max': ('upper bound of f(theta), 0.3515 ~ 70 deg', (-1.0, 1.0), None),
    'max_angle_deg': ('sliding_window: largest corner angle [deg]', (1.0, 179.0), None),
    'min_opposite_distance': ('sliding_window: smallest opposite distance c [m]',
                              (0.0, 10.0), None),
    'min_arm_points': ('fewest points on each arm of a corner', (2, 1000), None),
    'min_arm_length': ('shortest arm of a corner [m]', (0.0, 10.0), None),
    'fit_length': ('arm length used to refine the corner by line fits [m]', (0.01, 10.0),
                   None),
    'sigma_r': ('laser range noise std [m] (covariances, thresholds)', (0.0, 1.0), None),
    'sigma_phi': ('laser bearing noise std [rad]', (0.0, 0.1), None),
    'refine': ('refine corners as the intersection of lines fitted to the arms', None, None),
}


class CornerExtractor(Node):
    """Thin node: LaserScan -> segmentation -> corner detector -> messages."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters, create the subscription and publishers."""
        super().__init__('corner_extractor', **kwargs)
        self.params = declare_dataclass(self, CornerParams, CORNER_PARAMETERS)
        self.incidence_deg = declare(
            self, 'segmentation.incidence_deg', 10.0,
            'smallest surface incidence angle still treated as continuous [deg] '
            '(adaptive breakpoint threshold)', (1.0, 89.0))
        self.min_cluster_points = declare(
            self, 'segmentation.min_points', 5, 'smallest cluster kept [points]', (1, 10000))
        self.warner = ProblemWarner(self)
        self.pub_corners = self.create_publisher(PoseArray, 'corners', 10)
        self.pub_features = self.create_publisher(PointCloud2, 'corners/features', 10)
        self.pub_markers = self.create_publisher(MarkerArray, 'corners/markers', 10)
        self.create_subscription(LaserScan, 'scan', self.on_scan, SENSOR_QOS)
        self.get_logger().info(f'corner_extractor: method {self.params.method}')

    def on_scan(self, msg: LaserScan) -> None:
        """Extract and publish the corners of one scan."""
        try:
            scan = scan_to_data(msg)
            if len(scan.ranges) == 0:
                raise ConversionError('LaserScan: empty scan (no ranges)')
            if math.degrees(scan.angle_increment) >= self.incidence_deg:
                raise ConversionError(
                    f'LaserScan: angle_increment {scan.angle_increment} rad is not below '
                    f'segmentation.incidence_deg {self.incidence_deg} deg')
        except ConversionError as err:
            self.warner.warn(f'Dropping scan: {err}')
            return
        clusters = segment_scan(scan.ranges, scan.angles, scan.valid, scan.angle_increment,
                                self.incidence_deg, self.params.sigma_r,
                                self.min_cluster_points)
        corners = detect_corners(clusters, self.params)
        stamp, frame = scan.stamp_ns, scan.frame_id
        self.pub_corners.publish(make_corner_pose_array(stamp, frame, corners))
        self.pub_features.publish(make_corner_cloud(stamp, frame, corners))
        self.pub_markers.publish(make_corner_markers(stamp, frame, corners))


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav corner_extractor``."""
    return run_node(CornerExtractor, args)


if __name__ == '__main__':
    raise SystemExit(main())
