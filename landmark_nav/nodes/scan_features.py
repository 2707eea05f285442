"""Shared base of the laser feature nodes: validated scan in, clusters out.

Subscribes ``scan`` (sensor_msgs/LaserScan) best effort with a queue of 20 (0.5 s of a
40 Hz laser: :data:`~landmark_nav.nodes.common.SCAN_QOS`), converts it
(REP 117 aware), drops malformed scans (``malformed``: unreadable, empty, stamp 0) and
scans of more than ``max_beams`` beams (``oversized``) with a warning naming the value
(throttled per kind of problem), and segments the rest
(parameters ``segmentation.incidence_deg`` and ``segmentation.min_points``) before handing
the clusters to :meth:`ScanFeatureNode.process`. Finite negative ranges (no laser
measures them; REP 117 reserves -inf for "too close") are treated as invalid beams, with a
warning naming the first one. Processed and dropped scans and the latency are on
``/diagnostics`` (:class:`~landmark_nav.nodes.common.InputStats`).
"""

import math

from landmark_nav.conversions import ConversionError, scan_to_data, ScanData
from landmark_nav.laser.segmentation import segment_scan
from landmark_nav.nodes.common import (declare, InputStats, ProblemWarner, require_stamp,
                                       SCAN_QOS)
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


class ScanFeatureNode(Node):
    """A node that extracts features from every scan it receives."""

    def __init__(self, name: str, **kwargs) -> None:
        """Declare the segmentation parameters (subscribe with :meth:`subscribe_scans`)."""
        super().__init__(name, **kwargs)
        self.sigma_r = 0.01
        self.incidence_deg = declare(
            self, 'segmentation.incidence_deg', 10.0,
            'smallest surface incidence angle still treated as continuous [deg] '
            '(adaptive breakpoint threshold)', (1.0, 89.0))
        self.min_cluster_points = declare(
            self, 'segmentation.min_points', 5, 'smallest cluster kept [points]', (1, 10000))
        self.max_beams = declare(
            self, 'max_beams', 20000, 'scans with more beams are dropped with a warning '
            '(real 2-D lasers have up to a few thousand)', (1, 100000000))
        self.warner = ProblemWarner(self)
        self.stats = InputStats(self, self.warner)

    def subscribe_scans(self, sigma_r: float) -> None:
        """Start receiving scans; ``sigma_r`` is the range noise used by the segmentation."""
        self.sigma_r = sigma_r
        self.stats.subscribe(LaserScan, 'scan', self.on_scan, SCAN_QOS)

    def on_scan(self, msg: LaserScan) -> None:
        """Validate and segment one scan, then process it."""
        if len(msg.ranges) > self.max_beams:
            self.stats.drop('oversized', f'Dropping scan: {len(msg.ranges)} beams, more than '
                            f'max_beams {self.max_beams}')
            return
        try:
            scan = scan_to_data(msg)
            require_stamp(scan.stamp_ns, 'LaserScan')
            if len(scan.ranges) == 0:
                raise ConversionError('LaserScan: empty scan (no ranges)')
            if math.degrees(scan.angle_increment) >= self.incidence_deg:
                raise ConversionError(
                    f'LaserScan: angle_increment {scan.angle_increment} rad is not below '
                    f'segmentation.incidence_deg {self.incidence_deg} deg')
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping scan: {err}')
            return
        negative = np.flatnonzero(np.isfinite(scan.ranges) & (scan.ranges < 0.0))
        if negative.size:  # below range_min: already invalid (too close), but not a reading
            i = int(negative[0])
            self.warner.warn(f'LaserScan: {negative.size} negative ranges treated as invalid '
                             f'(first: ranges[{i}]={scan.ranges[i]:g})')
        clusters = segment_scan(scan.ranges, scan.angles, scan.valid, scan.angle_increment,
                                self.incidence_deg, self.sigma_r, self.min_cluster_points)
        self.process(scan, clusters)
        self.stats.processed()

    def process(self, scan: ScanData, clusters: list) -> None:
        """Extract and publish the features of one scan (implemented by subclasses)."""
        raise NotImplementedError
