"""Scan segmentation: adaptive breakpoints, invalid readings break clusters, small ones go."""

import math

from landmark_nav.laser.segmentation import breakpoint_threshold, segment_scan
import numpy as np
import pytest

ANGLES = np.radians(np.arange(-90.0, 90.25, 0.5))
INC = math.radians(0.5)


def test_one_wall_is_one_cluster_even_far_away():
    # A wall 6 m ahead seen at 0.5 deg: gaps grow with range but stay below the threshold.
    r = 6.0 / np.cos(ANGLES[120:241])
    clusters = segment_scan(r, ANGLES[120:241], np.ones(121, bool), INC)
    assert len(clusters) == 1 and len(clusters[0]) == 121
    np.testing.assert_allclose(clusters[0].points[:, 0], 6.0, atol=1e-9)


def test_invalid_readings_and_depth_jumps_break_clusters():
    r = np.full(361, 3.0)
    valid = np.ones(361, bool)
    valid[100:103] = False          # dropouts
    r[200:] = 3.5                   # 0.5 m depth jump
    clusters = segment_scan(r, ANGLES, valid, INC)
    spans = [(c.indices[0], c.indices[-1]) for c in clusters]
    assert spans == [(0, 99), (103, 199), (200, 360)]


def test_small_clusters_are_dropped():
    r = np.full(361, 3.0)
    r[50:53] = 1.0                  # a 3-point table leg
    clusters = segment_scan(r, ANGLES, np.ones(361, bool), INC, min_points=5)
    assert all(len(c) >= 5 for c in clusters)
    assert not any(50 in c.indices for c in clusters)
    kept = segment_scan(r, ANGLES, np.ones(361, bool), INC, min_points=3)
    assert any(list(c.indices) == [50, 51, 52] for c in kept)


def test_threshold_adapts_to_range_and_resolution():
    near, far = breakpoint_threshold(np.array([1.0, 5.0]), INC)
    assert far > near > 0
    coarse = breakpoint_threshold(np.array([5.0]), math.radians(1.0))[0]
    assert coarse > far
    with pytest.raises(ValueError):
        breakpoint_threshold(np.array([1.0]), 0.0)


def test_empty_and_all_invalid_scans():
    assert segment_scan(np.array([]), np.array([]), np.array([], bool), INC) == []
    assert segment_scan(np.full(361, np.nan), ANGLES, np.zeros(361, bool), INC) == []
    with pytest.raises(ValueError):
        segment_scan(np.ones(3), np.ones(4), np.ones(3, bool), INC)
