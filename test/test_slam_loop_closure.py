"""Loop closure of the graph back end: a wrong place that looks alike is refused.

Simulator world: two identical corridors 8 m apart (same length, same door recesses), one
entered from an open room (A), the other from a small closed lobby (B). The map
holds corridor A and its room. The robot is in corridor B while its estimate, drifted,
puts it at the same place in corridor A: the scan there matches A's submap exactly, and a
matcher that checks only the match's score and fit (naive) closes the loop 8 m off. The
free-space check refuses it: the lobby's walls seen from the poses before (the trail),
moved by the loop's transform, lie in the room's space that A's scans saw free. The same
robot really in A, coming from the room, closes the loop to within a few centimetres.
"""

import math

from landmark_nav.geometry import compose, inverse, transform_points, wrap_angle
from landmark_nav.sim.world import World
from landmark_nav.slam.correlative_matching import correlative_match, LikelihoodField
from landmark_nav.slam.keyframe_graph import GraphParams, KeyframeGraph
from landmark_nav.slam.loop_closure import LoopParams, verify_loop
from landmark_nav.slam.slam_params import OdometryNoise
import numpy as np
import pytest

B_OFFSET = 8.0  # corridor B lies this far north of corridor A [m]
BEAMS = np.radians(np.arange(-90.0, 90.5, 1.0))
MAX_RANGE = 8.0


def _corridor(world: World, dy: float) -> None:
    """Add a 12 m corridor along x at y = dy, 1.6 m wide, with three door recesses."""
    north = [(0.0, 0.8), (2.0, 0.8), (2.0, 1.6), (3.0, 1.6), (3.0, 0.8), (6.0, 0.8),
             (6.0, 1.5), (6.8, 1.5), (6.8, 0.8), (12.0, 0.8), (12.0, -0.8)]
    south = [(12.0, -0.8), (10.5, -0.8), (10.5, -1.7), (9.5, -1.7), (9.5, -0.8),
             (0.0, -0.8)]
    world.add_polyline([(x, y + dy) for x, y in north])
    world.add_polyline([(x, y + dy) for x, y in south])


@pytest.fixture(scope='module')
def world() -> World:
    return two_corridors()


def two_corridors() -> World:
    """Return the world of the module docstring."""
    w = World('two_corridors')
    _corridor(w, 0.0)
    _corridor(w, B_OFFSET)
    # A: an open room west of the corridor.
    w.add_polyline([(0.0, 0.8), (0.0, 3.0), (-6.0, 3.0), (-6.0, -3.0), (0.0, -3.0),
                    (0.0, -0.8)])
    # B: a small closed lobby west of the corridor.
    b = B_OFFSET
    w.add_polyline([(0.0, b + 0.8), (0.0, b + 1.5), (-1.2, b + 1.5), (-1.2, b - 1.5),
                    (0.0, b - 1.5), (0.0, b - 0.8)])
    return w


def _scan(world: World, pose) -> np.ndarray:
    """Return the laser-frame points of a 181-beam scan at ``pose`` (no noise)."""
    hits = world.raycast(np.asarray(pose[:2], dtype=float), pose[2] + BEAMS, MAX_RANGE)
    ok = np.isfinite(hits.ranges)
    r = hits.ranges[ok]
    return np.column_stack([r * np.cos(BEAMS[ok]), r * np.sin(BEAMS[ok])])


def _in_frame(frame, poses, world):
    """Return the scans at ``poses`` placed in the frame of pose ``frame``."""
    inv = inverse(np.asarray(frame, dtype=float))
    return [transform_points(compose(inv, p), _scan(world, p)) for p in poses]


@pytest.fixture(scope='module')
def case(world):
    return mapped_corridor(world)


def mapped_corridor(world):
    """Return the map of corridor A and its room, the anchor at x = 4 m in A."""
    xs = (-4.5, -3.0, -1.5, 0.0, 1.5, 3.0, 4.0, 5.0, 6.5)
    mapped = [np.array([x, 0.0, 0.0]) for x in xs]
    anchor = mapped[6]
    hits = _in_frame(anchor, mapped, world)
    origins = np.array([compose(inverse(anchor), p)[:2] for p in mapped])
    return {'anchor': anchor, 'submap': np.vstack(hits), 'hits': hits, 'origins': origins}


def _attempt(world, case, dy: float, naive: bool):
    """Verify the loop of the robot at (4.2, dy) whose estimate says (4.2, 0)."""
    truth = np.array([4.2, dy, 0.05])
    trail_poses = [np.array([x, dy, 0.0]) for x in (-0.6, 0.4, 1.4, 2.4, 3.4)]
    trail = _in_frame(truth, trail_poses, world)
    estimate = np.array([4.2 + 0.25, -0.15, 0.05 + math.radians(3.0)])
    guess = compose(inverse(case['anchor']), estimate)
    res = verify_loop(_scan(world, truth), case['submap'], guess, 0.6, math.radians(8.0),
                      LoopParams(), trail, case['origins'], case['hits'],
                      check_ambiguity=not naive, check_free_space=not naive)
    true_rel = compose(inverse(case['anchor']), truth - np.array([0.0, dy, 0.0]))
    return res, true_rel


def test_naive_matcher_closes_the_wrong_corridor(world, case):
    res, rel = _attempt(world, case, B_OFFSET, naive=True)
    assert res.accepted  # the scan in B fits A's submap as well as a scan in A would
    assert res.overlap > 0.9
    # ... at the pose of A's corridor: B_OFFSET from where the robot is.
    assert np.hypot(*(res.pose[:2] - rel[:2])) < 0.05


def test_verified_matcher_refuses_the_wrong_corridor(world, case):
    res, _ = _attempt(world, case, B_OFFSET, naive=False)
    assert not res.accepted
    assert res.reason == 'free_space'
    assert res.contradiction > LoopParams().max_contradiction


def test_verified_matcher_closes_the_right_corridor(world, case):
    res, rel = _attempt(world, case, 0.0, naive=False)
    assert res.accepted, res.reason
    assert res.contradiction <= LoopParams().max_contradiction
    assert np.hypot(*(res.pose[:2] - rel[:2])) < 0.03
    assert abs(res.pose[2] - rel[2]) < math.radians(0.5)


def test_correlative_search_finds_the_pose_anywhere_in_its_window(world, case):
    """The exhaustive search does not depend on where in the window the guess lies."""
    truth = np.array([4.2, 0.0, 0.05])
    rel = compose(inverse(case['anchor']), truth)
    field = LikelihoodField(case['submap'], 0.05, 0.1)
    scan = _scan(world, truth)
    for off in ([0.4, -0.3, 0.1], [-0.35, 0.3, -0.1]):
        found = correlative_match(field, scan, rel + np.array(off), 0.5, math.radians(8.0),
                                  0.05, math.radians(1.0))
        # Translations are whole cells of the field: within one cell on each axis.
        assert np.all(np.abs(found.pose[:2] - rel[:2]) <= 0.05 + 1e-9)
        assert abs(found.pose[2] - rel[2]) <= math.radians(1.0)


def test_graph_params_refuse_bad_values():
    with pytest.raises(ValueError, match='keyframe_distance'):
        GraphParams(keyframe_distance=0.0)
    with pytest.raises(ValueError, match='window_xy'):
        LoopParams(window_xy=(2.0, 1.0))
    with pytest.raises(ValueError, match='min_overlap'):
        LoopParams(min_overlap=1.5)
    graph = KeyframeGraph((0.0, 0.0, 0.0), OdometryNoise(0.05, 0.05, 0.1))
    with pytest.raises(ValueError, match='nan'):
        graph.add_scan([0.0, float('nan'), 0.0], np.zeros((10, 2)))


def test_graph_closes_a_drifted_loop_in_a_room(world):
    """Around the open room once and a quarter with a heading bias: the lap closes.

    Odometry: the true increments with 3 deg of heading error per metre (1.1 m off at the
    end); scans with 3 cm range noise (seed 0). The keyframe factors come from scan
    matching, the loops from :mod:`.loop_closure` (candidates 8 m back along the path).
    With loops the last pose is 1.7 cm off, without 4.7 cm.
    """
    centre, radius = np.array([-3.0, 0.0]), 1.8
    angles = np.linspace(0.0, 1.25 * 2 * math.pi, 48)
    truth = np.column_stack([centre[0] + radius * np.cos(angles),
                             centre[1] + radius * np.sin(angles),
                             angles + math.pi / 2])
    odo = [truth[0].copy()]
    for a, b in zip(truth[:-1], truth[1:]):
        u = compose(inverse(a), b)
        u[2] += math.radians(3.0) * math.hypot(u[0], u[1])
        odo.append(compose(odo[-1], u))
    rng = np.random.default_rng(0)
    scans = []
    for t in truth:
        p = _scan(world, t)
        r = np.hypot(p[:, 0], p[:, 1])
        scans.append(p * ((r + rng.normal(0.0, 0.03, len(r))) / r)[:, None])
    errors = {}
    for loops in (True, False):
        graph = KeyframeGraph((0.0, 0.0, 0.0), OdometryNoise(0.05, 0.05, 0.1),
                              GraphParams(side_starts=0.0, loops=loops, loop=LoopParams(
                                  min_separation_m=8.0, trail_keyframes=3)))
        for o, scan in zip(odo, scans):
            graph.add_scan(o, scan)
        assert (graph.loop_counts.accepted >= 1) == loops
        end = graph.pose_at(len(graph.keyframes) - 1, odo[-1])[0]
        errors[loops] = np.hypot(*(end[:2] - truth[-1][:2]))
    assert np.hypot(*(odo[-1][:2] - truth[-1][:2])) > 1.0
    assert errors[True] < 0.025
    assert errors[True] < 0.6 * errors[False]


def _turn_in_place(world, start, turn: float, odometry_turn: float, slip: float,
                   odometry: OdometryNoise, scan_noise: OdometryNoise):
    """Return the graph after a turn in place by ``turn`` [rad] from ``start`` in the room.

    The odometry's turn is ``odometry_turn`` [rad] with ``slip`` [m] of translation on
    each axis. Scans with 1 cm range noise.
    """
    rng = np.random.default_rng(1)
    truth = [np.array(start, dtype=float), np.array(start, dtype=float) + [0.0, 0.0, turn]]
    scans = []
    for t in truth:
        p = _scan(world, t)
        r = np.hypot(p[:, 0], p[:, 1])
        scans.append(p * ((r + rng.normal(0.0, 0.01, len(r))) / r)[:, None])
    odo = [truth[0], truth[0] + [slip, slip, odometry_turn]]
    graph = KeyframeGraph((0.0, 0.0, 0.0), odometry, GraphParams(scan_noise=scan_noise))
    for o, scan in zip(odo, scans):
        graph.add_scan(o, scan)
    assert len(graph.keyframes) == 2
    return graph


def test_graph_keeps_the_scans_turn_in_place_against_slipping_odometry(world):
    """A 0.75 rad turn in place, the odometry 13 deg short with 4 cm of slip.

    As aces seed 2's keyframe 130. The odometry's model (3.3 deg std on this turn) allows
    millimetres of translation on a turn in place. With the default floors of the
    scan-matched motion's noise (the ICP's error, 4 cm and 0.01 rad) the scans' turn passes
    the test and is fused with the odometry's; without a floor (the motion-driven model
    alone: 1 cm) the test refuses it for its 4 cm, and the odometry's turn, 13 deg off,
    becomes the factor.
    """
    errors = {}
    for kind, scan_noise in (('scan_matching', GraphParams().scan_noise),
                             ('odometry', OdometryNoise(0.05, 0.03, 0.06))):
        graph = _turn_in_place(world, (-3.0, 0.0, 0.0), 0.75, 0.75 - math.radians(13.0), 0.03,
                               OdometryNoise(0.0015, 0.01, 0.08), scan_noise)
        assert graph.motions[kind] == 1, (kind, graph.motions)
        errors[kind] = abs(math.degrees(wrap_angle(graph.estimates[1, 2] - 0.75)))
    # Fused with the odometry's turn (weighted by their information): 0.58 deg.
    assert errors['scan_matching'] < 0.75
    assert errors['odometry'] > 12.0


def test_graph_verifies_the_scans_turn_the_odometry_refutes(world):
    """A 0.95 rad turn in place in the room's corner, the odometry's 25 deg short.

    6 stds of the scan test: it refuses the scans' turn; the scan is then searched and
    verified as a loop is, and its turn kept with the fit's information (0.05 deg off).
    With 0.7 m of slip on each axis as well, the verified motion's translation disagrees
    with the odometry's and the odometry's turn stays the factor.
    """
    odometry = OdometryNoise(0.0015, 0.01, 0.04)  # 2.2 deg std on this turn
    start = (-4.5, -2.0, 0.3)
    graph = _turn_in_place(world, start, 0.95, 0.95 - math.radians(25.0), 0.0, odometry,
                           GraphParams().scan_noise)
    assert graph.motions['scan_verified'] == 1, graph.motions
    assert abs(math.degrees(wrap_angle(graph.estimates[1, 2] - 0.3 - 0.95))) < 0.1
    graph = _turn_in_place(world, start, 0.95, 0.95 - math.radians(25.0), 0.7, odometry,
                           GraphParams().scan_noise)
    assert graph.motions['odometry'] == 1, graph.motions
