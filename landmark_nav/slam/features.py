"""Scan features for EKF-SLAM: corners, lines or both (``landmarks`` parameter).

One function, :func:`extract_scan_features`, turns a scan into the features the filter maps:
corners (:func:`landmark_nav.laser.corners.extract_corners`, corner chapter section 2) and /
or line segments (:func:`landmark_nav.laser.lines.extract_lines` on the clusters of
:func:`landmark_nav.laser.segmentation.segment_scan` with ``min_points=1``, so lines can
grow over isolated returns of their wall). The node and the offline evaluation call it, then
:func:`.observations.corners_to_observations` and
:func:`.line_landmarks.lines_to_observations`.
"""

from dataclasses import replace
from typing import List, Optional, Tuple

from landmark_nav.laser.corners import CornerParams, extract_corners
from landmark_nav.laser.lines import extract_lines, LineParams
from landmark_nav.laser.segmentation import segment_scan
from landmark_nav.slam.frontend import line_beam_times
import numpy as np

#: Values of the ``landmarks`` parameter.
LANDMARK_TYPES = ('corners', 'lines', 'both')


def check_landmarks(landmarks: str) -> str:
    """Return ``landmarks`` if it is one of :data:`LANDMARK_TYPES`, else raise ValueError."""
    if landmarks not in LANDMARK_TYPES:
        raise ValueError(f'landmarks must be one of {", ".join(LANDMARK_TYPES)}, '
                         f'got {landmarks!r}')
    return landmarks


def extract_scan_features(ranges: np.ndarray, angles: np.ndarray, valid: np.ndarray,
                          angle_increment: float, landmarks: str = 'corners',
                          corner_params: Optional[CornerParams] = None,
                          line_params: Optional[LineParams] = None
                          ) -> Tuple[list, list]:
    """Extract the corners and / or lines of one scan (laser frame).

    Args:
        ranges: (N,) ranges [m].
        angles: (N,) beam angles [rad].
        valid: (N,) bool, real returns.
        angle_increment: Beam spacing [rad].
        landmarks: ``'corners'``, ``'lines'`` or ``'both'``.
        corner_params: Corner detector parameters.
        line_params: Line extractor parameters (its ``sigma_r`` also drives the
            segmentation of the lines' clusters); ``join_occluded`` is always off here.

    Returns:
        ``(corners, lines)``: lists of :class:`~landmark_nav.laser.corners.Corner` and
        :class:`~landmark_nav.laser.lines.LineSegment` (empty when not asked for).
    """
    check_landmarks(landmarks)
    corners: List = []
    lines: List = []
    if landmarks in ('corners', 'both'):
        corners = extract_corners(ranges, angles, valid, angle_increment, corner_params)
    if landmarks in ('lines', 'both'):
        # Each side of an occluder is its own observation, fitted on its own beams: a
        # joint fit shared by the two segments would be counted twice by the filter, and
        # one segment across both would leave the two panel landmarks mapped before, from
        # places that saw one side, as one wall mapped twice (the office's y = 0 wall).
        line_params = replace(line_params or LineParams(), join_occluded=False)
        clusters = segment_scan(ranges, angles, valid, angle_increment,
                                sigma_r=line_params.sigma_r, min_points=1)
        lines = extract_lines(clusters, line_params)
    return corners, lines


def scan_lines(ranges: np.ndarray, angles: np.ndarray, valid: np.ndarray,
               angle_increment: float, time_increment: float,
               line_params: Optional[LineParams] = None) -> Tuple[list, np.ndarray]:
    """Return ``(lines, beam_time)``: a scan's lines and their middle beams' times [s].

    :func:`extract_scan_features` with ``landmarks='lines'``; what a keyframe's
    ``Corners.lines_from`` extracts (:mod:`.keyframes`). Arguments as there, plus the
    scan's time between beams [s].
    """
    lines = extract_scan_features(ranges, angles, valid, angle_increment, 'lines', None,
                                  line_params)[1]
    return lines, line_beam_times(lines, time_increment)


__all__ = ['check_landmarks', 'extract_scan_features', 'LANDMARK_TYPES', 'scan_lines']
