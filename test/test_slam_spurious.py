"""Pairs whose gate may hold another feature (``SlamParams.spurious_limit``, issue 14).

The expected number of features other than the observed one inside a pair's 95 % gate is
``lambda A``: ``A`` the gate put in the plane (corners) or in ``(rho, alpha)`` (lines),
``lambda`` the scan's own density of such features (corners over the swept area, lines
over its perimeter). The tests compute ``lambda A`` by hand from the filter's innovation
covariance and check the pair is kept just below the limit and dropped just above it.
"""

import math

from landmark_nav.geometry import inverse_transform_points
from landmark_nav.slam import EkfSlam, SlamParams
from landmark_nav.slam.consistency import chi2_gate
from landmark_nav.slam.ekf_slam import (constrain_jacobians, LINE, observation_model,
                                        predicted_observation_covariance,
                                        unobservable_directions)
from landmark_nav.slam.line_landmarks import LineObservations
from landmark_nav.slam.visibility import ScanGeometry, swept_region
import numpy as np
import pytest

R1 = np.diag([0.01 ** 2, math.radians(0.3) ** 2])
R_LINE = np.diag([0.01 ** 2, math.radians(0.5) ** 2])
CORNER_XY = np.array([[8.0, 1.0]])
WALL = np.array([[[2.0, 3.0], [6.0, 3.0]]])  # a wall y = 3 seen from the origin
SCAN_R = 10.0


def scan(n=181, r=SCAN_R):
    """Return a half-circle scan of ``n`` beams returning at ``r`` (laser at the base)."""
    return ScanGeometry(np.full(n, r), -math.pi / 2, math.pi / (n - 1), 0.1, 30.0,
                        np.zeros(3), 0.01)


def observe(pose, points):
    """Exact range-bearing of world points from a pose."""
    p = inverse_transform_points(pose, points)
    return np.column_stack([np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])])


def wall_observation(pose):
    """Return the wall as a line observation in base_link."""
    ends = inverse_transform_points(pose, WALL[0])
    d = ends[1] - ends[0]
    n = np.array([d[1], -d[0]]) / np.hypot(*d)
    rho = float(n @ ends[0])
    if rho < 0:
        n, rho = -n, -rho
    return LineObservations(np.array([[rho, math.atan2(n[1], n[0])]]), R_LINE[None],
                            ends[None])


MOVED = np.array([0.3, 0.1, 0.05])  # odometry of the first step of move=True
TRUE_MOVED = MOVED + np.array([0.03, -0.02, 0.02])  # where the robot is: the update moves x


def uncertain_filter(heading_std_deg, position_std=0.3, move=False, **kw):
    """Map the corner and the wall from the origin, then make the pose uncertain.

    With ``move`` the robot first drives (odometry ``MOVED``, truly to ``TRUE_MOVED``) and
    re-observes both, so the update moves the state away from the first estimates; then
    the pose is made uncertain there.
    """
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1, prune_misses=0,
                              position_floor=0.0, **kw))  # R as given, for the hand figures
    slam.update(observe(np.zeros(3), CORNER_XY), R1[None], lines=wall_observation(np.zeros(3)))
    assert slam.num_landmarks == 2
    if move:
        slam.predict(MOVED, np.diag([0.02 ** 2, 0.02 ** 2, math.radians(1.0) ** 2]))
        res = slam.update(observe(TRUE_MOVED, CORNER_XY), R1[None],
                          lines=wall_observation(TRUE_MOVED))
        assert res.status.tolist() == ['matched'] * 2
    slam.predict(np.zeros(3), np.diag([position_std ** 2, position_std ** 2,
                                       math.radians(heading_std_deg) ** 2]))
    return slam


def gate_covariance(slam):
    """Predicted observations and innovation covariances of both pairs, as the gate has them.

    The Jacobians of the filter's ``jacobians`` option: the constrained ones for
    ``observability_gain``, the first estimates' for ``first_estimates``.
    """
    index = np.arange(2)
    kinds = slam.landmark_kinds
    zhat, hr, hf = observation_model(slam.state, index, kinds)
    mode = slam.params.jacobians
    if mode == 'observability_gain':
        null = unobservable_directions(slam._prior_xy, slam._first, slam._kind)
        hr, hf = constrain_jacobians(hr, hf, null)
    elif mode == 'first_estimates':
        at = np.concatenate([slam._prior_xy, slam.state[2:3], slam._first.reshape(-1)])
        hr, hf = observation_model(at, index, kinds)[1:]
    return zhat, predicted_observation_covariance(slam.covariance, index, hr, hf) + np.stack(
        [R1, R_LINE])


def expected_others(slam, geometry, n_corners=1, n_lines=1):
    """Return ``lambda A`` of the corner pair and of the wall pair, by hand."""
    zhat, s = gate_covariance(slam)
    ellipse = math.pi * chi2_gate(2, 0.95) * np.sqrt(np.linalg.det(s))
    area, perimeter = swept_region(geometry)
    return (ellipse[0] * zhat[0, 0] * n_corners / area, ellipse[1] * n_lines / perimeter)


def test_swept_region_of_a_half_circle():
    """Area sum r^2 dphi / 2, perimeter through the laser and the returns."""
    n, r = 181, 4.0
    area, perimeter = swept_region(scan(n, r))
    dphi = math.pi / (n - 1)
    assert area == pytest.approx(0.5 * r * r * dphi * n, rel=1e-12)
    assert perimeter == pytest.approx(2 * r + (n - 1) * 2 * r * math.sin(dphi / 2), rel=1e-12)


def test_swept_region_counts_valid_returns_only():
    """No return, NaN and too-near beams show no area; none at all gives zeros."""
    ranges = np.full(181, 4.0)
    ranges[:60] = np.inf
    ranges[60:70] = np.nan
    ranges[70:80] = 0.05  # below range_min
    g = ScanGeometry(ranges, -math.pi / 2, math.pi / 180, 0.1, 30.0, np.zeros(3), 0.01)
    assert swept_region(g)[0] == pytest.approx(0.5 * 16.0 * math.pi / 180 * 101, rel=1e-12)
    g = ScanGeometry(np.full(10, np.inf), 0.0, 0.1, 0.1, 30.0, np.zeros(3), 0.01)
    assert swept_region(g) == (0.0, 0.0)


def test_swept_region_perimeter_is_the_convex_hull():
    """A saw-tooth scan (4 m / 2 m) has the hull of its 4 m returns and the laser."""
    n, dphi = 181, math.pi / 180
    ranges = np.where(np.arange(n) % 2 == 0, 4.0, 2.0)
    g = ScanGeometry(ranges, -math.pi / 2, dphi, 0.1, 30.0, np.zeros(3), 0.01)
    outer = (n + 1) // 2  # the even beams, both ends among them
    hull = 2 * 4.0 + (outer - 1) * 2 * 4.0 * math.sin(dphi)
    assert swept_region(g)[1] == pytest.approx(hull, rel=1e-9)
    # One return at the far end of its range adds its spike to the hull only.
    ranges[90] = 20.0
    spike = ScanGeometry(ranges, -math.pi / 2, dphi, 0.1, 30.0, np.zeros(3), 0.01)
    assert hull < swept_region(spike)[1] < hull + 2 * 16.0


def test_swept_region_range_limits_are_open():
    """Returns at exactly range_min or range_max are no returns (REP 117 drivers)."""
    ranges = np.full(181, 4.0)
    ranges[:10] = 30.0  # range_max
    ranges[10:20] = 0.1  # range_min
    g = ScanGeometry(ranges, -math.pi / 2, math.pi / 180, 0.1, 30.0, np.zeros(3), 0.01)
    assert swept_region(g)[0] == pytest.approx(0.5 * 16.0 * math.pi / 180 * 161, rel=1e-12)


@pytest.mark.parametrize('jacobians', ['standard', 'observability_gain', 'first_estimates'])
@pytest.mark.parametrize('which', [0, 1])
def test_pair_kept_below_the_limit_and_dropped_above(which, jacobians):
    """The corner (which 0) or the wall (1): kept at (1 + 1e-7) lambda A, dropped below.

    After a first step, so that the first estimates differ from the state; ``A`` from the
    innovation covariance of the option's Jacobians, the one its gate uses (the options
    differ by about 1e-5 of ``A`` here: the 1e-7 margin tells them apart).
    """
    geometry = scan()
    both = expected_others(uncertain_filter(10.0, move=True, jacobians=jacobians), geometry)
    mu = both[which]
    assert 1e-3 < mu < 10.0
    z, lines = observe(TRUE_MOVED, CORNER_XY), wall_observation(TRUE_MOVED)
    for factor, kept in ((1.0 + 1e-7, True), (1.0 - 1e-7, False)):
        slam = uncertain_filter(10.0, move=True, jacobians=jacobians,
                                spurious_limit=factor * mu)
        res = slam.update(z, R1[None], lines=lines, scan=geometry)
        assert (res.status[which] == 'matched') == kept
        if not kept:  # inside the gate: ambiguous, never a new landmark
            assert res.reason[which] == 'ambiguous'
            assert slam.num_landmarks == 2
        # The other pair is judged by its own expected others.
        other_kept = both[1 - which] <= factor * mu
        assert (res.status[1 - which] == 'matched') == other_kept
        assert slam.stats['spurious'] == (not kept) + (not other_kept)


def test_the_options_jacobians_change_the_gate_area():
    """The three linearisations give different A here: the check follows the option's."""
    geometry = scan()
    mus = [expected_others(uncertain_filter(10.0, move=True, jacobians=j), geometry)[0]
           for j in ('standard', 'observability_gain', 'first_estimates')]
    assert min(abs(a - b) for a, b in ((mus[0], mus[1]), (mus[0], mus[2]),
                                       (mus[1], mus[2]))) > 1e-6 * mus[0]


def test_invalid_and_grazing_observations_before_the_pair():
    """Observations dropped before the association do not shift the pair's index."""
    geometry = scan()
    mu = expected_others(uncertain_filter(10.0), geometry)[0]  # the invalid one not counted
    z = np.vstack([[np.nan, 0.1], observe(np.zeros(3), CORNER_XY)])
    r = np.repeat(R1[None], 2, axis=0)
    for factor, kept in ((1.01, True), (0.99, False)):
        slam = uncertain_filter(10.0, spurious_limit=factor * mu)
        res = slam.update(z, r, scan=geometry)
        assert res.reason[0] == 'invalid'
        assert (res.status[1] == 'matched') == kept


def test_denser_scenes_shrink_the_gate_allowed():
    """Four corners in the same scan make the corner pair's expected others four times."""
    geometry = scan()
    one = expected_others(uncertain_filter(10.0), geometry)[0]
    four = expected_others(uncertain_filter(10.0), geometry, n_corners=4)[0]
    assert four == pytest.approx(4 * one, rel=1e-12)
    others = np.array([[-3.0, 6.0], [-6.0, 4.0], [-2.0, -7.0]])  # unmapped, far from the pair
    z = observe(np.zeros(3), np.vstack([CORNER_XY, others]))
    slam = uncertain_filter(10.0, spurious_limit=2 * one)
    res = slam.update(z, np.repeat(R1[None], 4, axis=0), lines=wall_observation(np.zeros(3)),
                      scan=geometry)
    assert res.status[0] == 'rejected' and res.reason[0] == 'ambiguous'
    slam = uncertain_filter(10.0, spurious_limit=2 * one)
    res = slam.update(z[:1], R1[None], lines=wall_observation(np.zeros(3)), scan=geometry)
    assert res.status[0] == 'matched'


def test_a_large_heading_error_stops_a_far_pair():
    """At 25 deg heading std the corner 8 m away is dropped at 0.05 (0.13); 2 deg: kept (0.015)."""
    geometry = scan()
    z, lines = observe(np.zeros(3), CORNER_XY), wall_observation(np.zeros(3))
    for std, kept in ((25.0, False), (2.0, True)):
        slam = uncertain_filter(std, spurious_limit=0.05)
        res = slam.update(z, R1[None], lines=lines, scan=geometry)
        assert (res.status[0] == 'matched') == kept


def test_off_by_default_and_without_a_scan():
    """No limit, or no scan geometry: the pair is matched however wide its gate."""
    z, lines = observe(np.zeros(3), CORNER_XY), wall_observation(np.zeros(3))
    slam = uncertain_filter(25.0)
    assert slam.params.spurious_limit is None
    assert slam.update(z, R1[None], lines=lines, scan=scan()).status.tolist() == ['matched'] * 2
    slam = uncertain_filter(25.0, spurious_limit=1e-9)
    assert slam.update(z, R1[None], lines=lines).status.tolist() == ['matched'] * 2
    assert slam.stats['spurious'] == 0 and slam.landmark_kinds.tolist() == [0, LINE]


@pytest.mark.parametrize('bad', [0.0, -0.1, math.nan, 'x', True])
def test_bad_limit_is_refused(bad):
    with pytest.raises(ValueError, match='spurious_limit'):
        SlamParams(spurious_limit=bad)
