"""Executable ``corner_extractor``: corners of each laser scan (corner chapter section 2).

Subscribes ``scan`` (sensor_msgs/LaserScan, sensor-data QoS). Publishes, with the scan's
stamp and frame:

* ``corners`` (geometry_msgs/PoseArray): corner positions, orientation = bisector;
* ``corners/features`` (sensor_msgs/PointCloud2, float64 fields): position, bisector,
  opening angle, the 2x2 position covariance and the beam time after the stamp (for the
  de-skew of ``ekf_slam``) per corner (see :mod:`landmark_nav.feature_msgs`);
* ``corners/markers`` (visualization_msgs/MarkerArray) for RViz.

A malformed scan is dropped with a warning naming the problem (throttled per kind).
"""

from geometry_msgs.msg import PoseArray
from landmark_nav.conversions import ScanData
from landmark_nav.feature_msgs import (make_corner_cloud, make_corner_markers,
                                       make_corner_pose_array)
from landmark_nav.laser.corners import CORNER_PARAMETERS, CornerParams, detect_corners
from landmark_nav.nodes.common import declare_dataclass, FEATURE_DEPTH, run_node
from landmark_nav.nodes.scan_features import ScanFeatureNode
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray


class CornerExtractor(ScanFeatureNode):
    """Thin node: LaserScan -> segmentation -> corner detector -> messages."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters, create the subscription and publishers."""
        super().__init__('corner_extractor', **kwargs)
        self.params = declare_dataclass(self, CornerParams, CORNER_PARAMETERS)
        self.pub_corners = self.create_publisher(PoseArray, 'corners', 10)
        self.pub_features = self.create_publisher(PointCloud2, 'corners/features', FEATURE_DEPTH)
        self.pub_markers = self.create_publisher(MarkerArray, 'corners/markers', 10)
        self.subscribe_scans(self.params.sigma_r)
        self.get_logger().info(f'corner_extractor: method {self.params.method}')

    def process(self, scan: ScanData, clusters: list) -> None:
        """Detect and publish the corners of one scan."""
        corners = detect_corners(clusters, self.at_scan_noise(self.params))
        stamp, frame = scan.stamp_ns, scan.frame_id
        self.pub_corners.publish(make_corner_pose_array(stamp, frame, corners))
        self.pub_features.publish(
            make_corner_cloud(stamp, frame, corners, scan.time_increment))
        self.pub_markers.publish(make_corner_markers(stamp, frame, corners))


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav corner_extractor``."""
    return run_node(CornerExtractor, args)


if __name__ == '__main__':
    raise SystemExit(main())
