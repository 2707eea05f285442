"""Executable ``line_extractor``: line segments of each laser scan.

Methods: ``split_merge`` (corner chapter section 2.1.2, eqs. 4-10) and ``alfa`` (the line
chapter's adaptive line fitting: lowess smoothing, split and merge with binary search and
the RMSE criterion). Subscribes ``scan`` (sensor_msgs/LaserScan, sensor-data QoS).
Publishes, with the scan's stamp and frame:

* ``lines`` (sensor_msgs/PointCloud2): one point per line with (rho, alpha), endpoints,
  the (rho, alpha) covariance, point count and RMSE (see :mod:`landmark_nav.feature_msgs`;
  the segments of a surface on both sides of an occluder share one fit, one measurement:
  parameter ``join_occluded``);
* ``lines/markers`` (visualization_msgs/MarkerArray) for RViz.

A malformed scan is dropped with a warning naming the problem (throttled per kind).
"""

from landmark_nav.conversions import ScanData
from landmark_nav.feature_msgs import make_line_cloud, make_line_markers
from landmark_nav.laser.lines import extract_lines, LINE_PARAMETERS, LineParams
from landmark_nav.nodes.common import declare_dataclass, run_node
from landmark_nav.nodes.scan_features import ScanFeatureNode
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray


class LineExtractor(ScanFeatureNode):
    """Thin node: LaserScan -> segmentation -> line extractor -> messages."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters, create the subscription and publishers."""
        super().__init__('line_extractor', **kwargs)
        self.params = declare_dataclass(self, LineParams, LINE_PARAMETERS)
        self.pub_lines = self.create_publisher(PointCloud2, 'lines', 10)
        self.pub_markers = self.create_publisher(MarkerArray, 'lines/markers', 10)
        self.subscribe_scans(self.params.sigma_r)
        self.get_logger().info(f'line_extractor: method {self.params.method}')

    def process(self, scan: ScanData, clusters: list) -> None:
        """Extract and publish the lines of one scan."""
        lines = extract_lines(clusters, self.at_scan_noise(self.params))
        self.pub_lines.publish(make_line_cloud(scan.stamp_ns, scan.frame_id, lines))
        self.pub_markers.publish(make_line_markers(scan.stamp_ns, scan.frame_id, lines))


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav line_extractor``."""
    return run_node(LineExtractor, args)


if __name__ == '__main__':
    raise SystemExit(main())
