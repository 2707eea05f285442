"""Shared base of the laser feature nodes: validated scan in, clusters out.

Subscribes ``scan`` (sensor_msgs/LaserScan) best effort with a queue of 20 (0.5 s of a
40 Hz laser: :data:`~landmark_nav.nodes.common.SCAN_QOS`), converts it
(REP 117 aware), drops malformed scans (``malformed``: unreadable, empty, stamp 0) and
scans of more than ``max_beams`` beams (``oversized``) with a warning naming the value
(throttled per kind of problem), and segments the rest
(parameters ``segmentation.incidence_deg`` and ``segmentation.min_points``; these and the
range noise's are :data:`~landmark_nav.laser.extractor_configuration.SCAN_PARAMETERS`)
before handing the clusters to :meth:`ScanFeatureNode.process`. With ``sigma_r_from_data``
the range noise of the segmentation and the extractor is estimated from the latest
``sigma_r_scans`` scans (:class:`landmark_nav.laser.range_noise.RangeNoiseTracker`: local
line fits and the range step), the node's ``sigma_r`` being its lower bound (the noise and
the segmentation: :class:`~landmark_nav.laser.extractor_configuration.ScanSegmenter`, as
offline); :meth:`ScanFeatureNode.at_scan_noise` gives the extractor's parameters with it.
Finite negative ranges (no laser measures them; REP 117 reserves -inf for "too close") are
treated as invalid beams, with a warning naming the first one (scans counted as
``scan.negative_ranges``). Processed and dropped scans
and the latency are on ``/diagnostics`` (:class:`~landmark_nav.nodes.common.InputStats`).
"""

import math

from landmark_nav.conversions import ConversionError, scan_to_data, ScanData
from landmark_nav.laser.extractor_configuration import SCAN_PARAMETERS, ScanSegmenter
from landmark_nav.nodes.common import (declare, InputStats, ProblemWarner, reject_undeclared,
                                       require_stamp, SCAN_QOS)
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


class ScanFeatureNode(Node):
    """A node that extracts features from every scan it receives."""

    def __init__(self, name: str, **kwargs) -> None:
        """Declare the segmentation parameters (start with :meth:`subscribe_scans`)."""
        super().__init__(name, **kwargs)
        self.values = {key: declare(self, key, *p[:4]) for key, p in SCAN_PARAMETERS.items()}
        self.incidence_deg = self.values['segmentation.incidence_deg']
        self.min_cluster_points = self.values['segmentation.min_points']
        self.max_beams = self.values['max_beams']
        self.segmenter = None  # ScanSegmenter, from subscribe_scans

    def subscribe_scans(self, sigma_r: float) -> None:
        """Start receiving scans; ``sigma_r`` is the range noise (its lower bound if estimated).

        Called once the subclass has declared its parameters: an undeclared name is refused
        before the diagnostics timer starts.
        """
        reject_undeclared(self)
        self.warner = ProblemWarner(self)
        self.stats = InputStats(self, self.warner)
        v = self.values
        self.segmenter = ScanSegmenter(v['segmentation.incidence_deg'],
                                       v['segmentation.min_points'], sigma_r,
                                       v['sigma_r_from_data'], v['sigma_r_scans'])
        self.stats.subscribe(LaserScan, 'scan', self.on_scan, SCAN_QOS)

    def at_scan_noise(self, params):
        """Return ``params`` with ``sigma_r`` the range noise of the current scan."""
        return self.segmenter.at_scan_noise(params)

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
            self.stats.event('scan.negative_ranges', f'LaserScan: {negative.size} negative '
                             f'ranges treated as invalid (first: ranges[{i}]={scan.ranges[i]:g})')
        self.segmenter.track(scan.ranges, scan.angles, scan.valid)
        clusters = self.segmenter.segment(scan.ranges, scan.angles, scan.valid,
                                          scan.angle_increment)
        self.process(scan, clusters)
        self.stats.processed()

    def process(self, scan: ScanData, clusters: list) -> None:
        """Extract and publish the features of one scan (implemented by subclasses)."""
        raise NotImplementedError
