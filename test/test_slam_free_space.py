"""Negative information: the free-space check of association hypotheses (issue 14).

``SlamParams.free_space_check`` / :func:`landmark_nav.slam.ekf_slam.free_space_contradictions`:
the aces failure of README.md at commit 67eb6cc ("What goes wrong on aces and acapulco") in
miniature. Two corners are mapped 22 m ahead, then the robot's position becomes uncertain by 8 m
along x and a corner 3 m ahead (not mapped) is seen: the range-bearing gate admits it as the
mapped corner A at 22 m (the only landmark in its gate), and that pair would put the robot
19 m ahead, 5 m from the other mapped corner B, where the scan's beams pass 25 m into free
space (from where the robot is, the scan returns at B).
"""

import math

from landmark_nav.geometry import inverse_transform_points
from landmark_nav.slam import EkfSlam, SlamParams
from landmark_nav.slam.ekf_slam import free_space_contradictions, free_space_significant
from landmark_nav.slam.visibility import lines_unoccluded, ScanGeometry
import numpy as np
import pytest

R1 = np.diag([0.01 ** 2, math.radians(0.3) ** 2])
INC = math.radians(0.5)
MAPPED = np.array([[22.0, 0.0], [22.0, 4.0]])  # A, B


def observe(pose, points):
    """Exact range-bearing of world points from a pose."""
    p = inverse_transform_points(pose, points)
    return np.column_stack([np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])])


def scan_with(ranges_fn, n=361):
    """Return a 180 deg scan (0.5 deg beams) with ranges_fn(angles) as its ranges."""
    angles = -math.pi / 2 + INC * np.arange(n)
    return ScanGeometry(np.asarray(ranges_fn(angles), dtype=float), -math.pi / 2, INC, 0.02,
                        30.0, np.zeros(3), 0.01)


def open_room(a):
    """Return the scan from the origin: a corner 3 m ahead, B where it is, 25 m elsewhere."""
    out = np.where(np.abs(a) < math.radians(5.0), 3.0, 25.0)
    b = math.atan2(MAPPED[1, 1], MAPPED[1, 0])
    out[np.abs(a - b) < math.radians(2.0)] = math.hypot(*MAPPED[1])
    return out


def mapped_filter(check, sigma_x=8.0):
    """Map A and B from the origin, then make the robot's x uncertain (std sigma_x)."""
    prm = SlamParams(confirm_hits=1, confirm_window=1, prune_misses=0,
                     free_space_check=check)
    slam = EkfSlam(prm)
    slam.update(observe(np.zeros(3), MAPPED), np.repeat(R1[None], 2, axis=0))
    assert slam.num_landmarks == 2
    slam.predict(np.zeros(3), np.diag([sigma_x ** 2, 0.3 ** 2, 1e-6]))
    return slam


def test_pair_refuted_by_a_mapped_corner_the_scan_sees_through():
    """Without the check the 3 m corner updates A and the robot jumps ~19 m; with it, not."""
    z = np.array([[3.0, 0.0]])
    r = R1[None]
    off = mapped_filter(None)
    res = off.update(z, r, scan=scan_with(open_room))
    assert res.status.tolist() == ['matched'] and res.landmark_id.tolist() == [0]
    assert off.pose[0] > 15.0  # the wrong pair moved the robot next to A
    # At that posterior B (5 m away, 53 deg) lies where the scan's beams reach 25 m.
    through, view = free_space_contradictions(
        off.state, off.covariance, off.landmark_kinds, off.line_ends,
        np.zeros((2, 2)), np.full(2, np.nan), scan_with(open_room), 0.95,
        off.params.min_view_margin, off.params.line_min_beams)
    assert through.tolist() == [False, True] and view.tolist() == [True, True]

    on = mapped_filter(0.95)
    res = on.update(z, r, scan=scan_with(open_room))
    assert res.status.tolist() == ['rejected'] and res.reason.tolist() == ['free_space']
    assert on.pose[0] == pytest.approx(0.0, abs=1e-9)
    assert on.stats['free_space'] == 1 and on.num_landmarks == 2


def test_ordinary_pair_is_kept():
    """A precise prior and A seen where it is: the posterior sees nothing through."""
    on = mapped_filter(0.95, sigma_x=0.05)
    z = observe(np.zeros(3), MAPPED[:1])

    def ranges(a):  # the scan returns at A and B and at a wall 25 m away elsewhere
        out = np.full(a.shape, 25.0)
        for p in MAPPED:
            out[np.abs(a - math.atan2(p[1], p[0])) < math.radians(2.0)] = math.hypot(*p)
        return out
    res = on.update(z, R1[None], scan=scan_with(ranges))
    assert res.status.tolist() == ['matched'] and on.stats['free_space'] == 0


def test_significance_is_a_binomial_tail():
    """One landmark seen through of one in view refutes at 0.95 (q = 0.025); 1 of 10 not."""
    assert free_space_significant(1, 1, 0.95, 0.95)
    assert not free_space_significant(1, 10, 0.95, 0.95)
    assert free_space_significant(2, 10, 0.95, 0.95)
    assert not free_space_significant(0, 5, 0.95, 0.95)


def test_param_default_off_and_validated():
    """Off by default; a confidence outside (0, 1) is refused."""
    assert SlamParams().free_space_check is None
    for bad in (0.0, 1.0, -0.5, 'x'):
        with pytest.raises(ValueError, match='free_space_check'):
            SlamParams(free_space_check=bad)


def test_lines_unoccluded_needs_beams_reaching_the_segment():
    """A wall x = 3 (|y| <= 1) is reachable when the beams return at or beyond it only."""
    lines = np.array([[3.0, 0.0]])
    ends = np.array([[[3.0, -1.0], [3.0, 1.0]]])
    sigma = np.array([0.02])
    g = math.sqrt(3.841)
    for ranges, want in ((lambda a: 3.0 / np.cos(a), True),  # returns on the wall
                         (lambda a: np.full(a.shape, 25.0), True),  # beyond it (seen through)
                         (lambda a: np.full(a.shape, 1.0), False)):  # something in front
        got = lines_unoccluded(np.zeros(3), lines, ends, sigma, scan_with(ranges), g, 8)
        assert got.tolist() == [want]
    # Seen from behind (rho < 0 in the laser frame): never.
    back = lines_unoccluded(np.array([6.0, 0.0, 0.0]), lines, ends, sigma,
                            scan_with(lambda a: np.full(a.shape, 25.0)), g, 8)
    assert back.tolist() == [False]
