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
from landmark_nav.laser.corners import CornerParams, detect_corners
from landmark_nav.nodes.common import declare_dataclass, run_node
from landmark_nav.nodes.scan_features import ScanFeatureNode
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray

CORNER_PARAMETERS = {
    'method': ('corner detector: minus_cosine (the proposed method of the chapter), '
               'sliding_window or split_merge', None,
               ['minus_cosine', 'sliding_window', 'split_merge']),
    'window': ('sliding window size in beams (odd, the chapter uses 11)', (5, 101), None),
    'f_min': ('lower bound of the minus-cosine f(theta) (eq. 11), -0.3436 ~ 70 deg',
              (-1.0, 1.0), None),
    'f_max': ('upper bound of f(theta), 0.3515 ~ 110 deg; also the angle gate of '
              'split_merge and of refined arms', (-1.0, 1.0), None),
    'midpoint_shift': ('minus_cosine ghost check: beams the midpoint is shifted (Figs. '
                       '11-12); 0 disables it', (0, 10), None),
    'max_angle_deg': ('sliding_window: largest corner angle [deg] (eq. 1)', (1.0, 179.0),
                      None),
    'min_opposite_distance': ('sliding_window: smallest opposite distance c [m]',
                              (0.0, 10.0), None),
    'split_threshold': ('split_merge: split distance tolerance [m] (eq. 4); 0 = automatic, '
                        'max(0.05, 4 sigma_r)', (0.0, 10.0), None, 0.0),
    'min_arm_points': ('fewest beams on each arm of a corner', (2, 1000), None),
    'min_arm_length': ('shortest arm of a corner [m]; 0 = automatic, max(0.15, 10 sigma_r)',
                       (0.0, 10.0), None, 0.0),
    'fit_length': ('longest arm used to refine a corner by line fits [m]', (0.01, 10.0),
                   None),
    'corner_gap': ('beams next to the corner left out of the arm fits', (0, 50), None),
    'max_half_window': ('cap on the widened half window of minus_cosine [beams]', (2, 1000),
                        None),
    'sigma_r': ('laser range noise std [m] (covariances, thresholds, segmentation)',
                (0.0, 1.0), None),
    'sigma_phi': ('laser bearing noise std [rad] (covariances)', (0.0, 0.1), None),
    'refine': ('refine minus_cosine corners as the intersection of lines fitted to the arms',
               None, None),
    'real_arms': ('refined and split_merge corners need two real surfaces (arm reach, RMS, '
                  'inlier share); false keeps only min_arm_points', None, None),
    'arm_rmse': ("largest RMS distance of an arm's beams to its line [m]; 0 = automatic, "
                 'max(0.03, 3 sigma_r)', (0.0, 1.0), None, 0.0),
    'min_arm_inliers': ("smallest share of an arm's beams its line fit uses", (0.0, 1.0),
                        None),
    'see_through': ('an arm never covers a beam more than this beyond it along the ray [m]; '
                    '0 = automatic, max(3 sigma_r, 0.05)', (0.0, 10.0), None, 0.0),
}


class CornerExtractor(ScanFeatureNode):
    """Thin node: LaserScan -> segmentation -> corner detector -> messages."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters, create the subscription and publishers."""
        super().__init__('corner_extractor', **kwargs)
        self.params = declare_dataclass(self, CornerParams, CORNER_PARAMETERS)
        self.pub_corners = self.create_publisher(PoseArray, 'corners', 10)
        self.pub_features = self.create_publisher(PointCloud2, 'corners/features', 10)
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
