"""What the scan shows beyond each corner arm's end (``Corner.arm_ends``)."""

import math

from landmark_nav.laser.corners import CornerParams, detect_corners, extract_corners
from landmark_nav.laser.segmentation import Cluster
from landmark_nav.sim import World
import numpy as np
import pytest

STEP = math.radians(0.5)
ASK = CornerParams(arm_ends=True)


def _scan(world, pose, fov_deg=180.0):
    """Noise-free ranges of a laser at ``pose`` (x, y, yaw); angles in the laser frame."""
    angles = np.radians(np.arange(-0.5 * fov_deg, 0.5 * fov_deg + 1e-9, 0.5))
    hits = world.raycast(np.array([pose[:2]]), angles + pose[2], max_range=30.0)
    return hits.ranges, angles


def _corner_near(world, pose, point, fov_deg=180.0, params=ASK):
    """Return the corner detected within 5 cm of ``point`` (world frame)."""
    ranges, angles = _scan(world, pose, fov_deg)
    found = extract_corners(ranges, angles, None, STEP, params)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    for f in found:
        p = np.array([pose[0] + c * f.position[0] - s * f.position[1],
                      pose[1] + s * f.position[0] + c * f.position[1]])
        if np.hypot(*(p - point)) < 0.05:
            return f
    raise AssertionError(f'no corner near {point}: {[f.position for f in found]}')


def _room():
    w = World()
    w.add_room([(-6.0, -6.0), (6.0, -6.0), (6.0, 6.0), (-6.0, 6.0)])
    return w


def test_a_free_standing_box_seen_whole_is_a_silhouette():
    w = _room()
    w.add_rectangle(0.0, 0.0, 1.0, 1.0)
    f = _corner_near(w, (3.0, 3.0, 1.25 * math.pi), (0.5, 0.5))
    assert f.opening > math.pi
    assert f.arm_ends == ('farther', 'farther')
    assert f.silhouette and not f.occluded


def test_a_room_corner_has_both_arms_ending_inside_their_walls():
    f = _corner_near(_room(), (3.0, 3.0, 0.25 * math.pi), (6.0, 6.0))
    assert f.arm_ends == ('inside', 'inside')
    assert not f.silhouette and not f.occluded


def test_arm_ends_only_when_asked_for():
    f = _corner_near(_room(), (3.0, 3.0, 0.25 * math.pi), (6.0, 6.0), params=CornerParams())
    assert f.arm_ends is None and not f.occluded and not f.silhouette and f.structural
    with pytest.raises(ValueError, match='arm_ends'):
        CornerParams(arm_ends=1)


def test_an_arm_hidden_by_a_nearer_post_is_occluded():
    w = _room()
    w.add_rectangle(4.0, 4.6, 0.3, 0.3)  # hides the wall y = 6 left of the corner
    f = _corner_near(w, (3.0, 3.0, 0.25 * math.pi), (6.0, 6.0))
    assert sorted(f.arm_ends) == ['inside', 'nearer']
    assert f.occluded and not f.silhouette
    assert f.structural  # the label does not use the arm ends (Corner.structural)


def test_an_arm_that_reaches_the_end_of_the_scan_ends_unknown():
    # A 20 deg field of view: the arms run to its edges.
    f = _corner_near(_room(), (3.0, 3.0, 0.25 * math.pi), (6.0, 6.0), fov_deg=20.0)
    assert 'unknown' in f.arm_ends and not f.occluded


def test_clusters_without_their_scan_give_no_arm_ends():
    ranges, angles = _scan(_room(), (3.0, 3.0, 0.25 * math.pi))
    pts = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])
    cluster = Cluster(indices=np.arange(ranges.size), points=pts, ranges=ranges, angles=angles)
    found = detect_corners([cluster], ASK)
    assert found and all(f.arm_ends is None and not f.occluded and not f.silhouette
                         for f in found)
