"""Tests for landmark_nav.sim.world: ray casting, corners, visibility, serialisation."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from landmark_nav.sim.world import HIT_CIRCLE, HIT_NONE, HIT_SEGMENT, World, wrap_angle
import numpy as np
import pytest
import yaml


def square_room(half: float = 2.0) -> World:
    w = World('square')
    w.add_room([(-half, -half), (half, -half), (half, half), (-half, half)])
    return w


def test_square_room_from_centre():
    w = square_room()
    ang = np.radians([0.0, 90.0, 180.0, -90.0, 45.0, 135.0, 30.0])
    hits = w.raycast(np.zeros(2), ang)
    expected = [2.0, 2.0, 2.0, 2.0, 2.0 * math.sqrt(2.0), 2.0 * math.sqrt(2.0),
                2.0 / math.cos(math.radians(30.0))]
    assert hits.ranges == pytest.approx(expected, abs=1e-12)
    assert np.all(hits.kind == HIT_SEGMENT)
    assert hits.cos_incidence[:4] == pytest.approx([1.0] * 4, abs=1e-12)
    assert hits.cos_incidence[4] == pytest.approx(math.sqrt(0.5), abs=1e-12)
    assert hits.cos_incidence[6] == pytest.approx(math.cos(math.radians(30.0)), abs=1e-12)
    # The ray at 0 rad hits the east wall (x = 2), which is segment id 1 (CCW order).
    assert hits.ids[0] == 1 and hits.ids[1] == 2 and hits.ids[2] == 3 and hits.ids[3] == 0


def test_parallel_rays_and_max_range():
    w = square_room()
    ys = np.linspace(-1.9, 1.9, 39)
    org = np.stack([np.full_like(ys, -1.0), ys], axis=1)
    hits = w.raycast(org, np.zeros_like(ys))
    assert hits.ranges == pytest.approx(np.full_like(ys, 3.0), abs=1e-12)
    far = w.raycast(org, np.zeros_like(ys), max_range=2.5)
    assert np.all(np.isposinf(far.ranges))
    assert np.all(far.kind == HIT_NONE) and np.all(far.ids == -1)
    assert np.all(np.isnan(far.cos_incidence))


def test_ray_misses_and_collinear():
    w = World()
    w.add_segment(1.0, -1.0, 1.0, 1.0)
    w.add_segment(2.0, 0.0, 4.0, 0.0)  # collinear with the x axis
    hits = w.raycast([[0.0, 0.0], [0.0, 2.0], [1.5, 0.0]], [0.0, 0.0, 0.0])
    assert hits.ranges[0] == pytest.approx(1.0)
    assert np.isposinf(hits.ranges[1])  # passes above the segment
    assert np.isposinf(hits.ranges[2])  # collinear segment is edge-on: no hit
    back = w.raycast([[3.0, 0.0]], [math.pi])
    assert back.ranges[0] == pytest.approx(2.0)  # segments are opaque from both sides


def test_ray_through_shared_vertex():
    w = square_room()
    hits = w.raycast(np.zeros((1, 2)), [math.pi / 4.0])
    assert hits.ranges[0] == pytest.approx(2.0 * math.sqrt(2.0), abs=1e-12)


def test_circle_hits():
    w = World()
    w.add_circle(3.0, 0.0, 0.5)
    hits = w.raycast([[0.0, 0.0], [0.0, 0.3], [0.0, 0.6], [5.0, 0.0]],
                     [0.0, 0.0, 0.0, math.pi])
    assert hits.ranges[0] == pytest.approx(2.5, abs=1e-12)
    assert hits.ranges[1] == pytest.approx(3.0 - 0.4, abs=1e-12)
    assert hits.cos_incidence[1] == pytest.approx(0.8, abs=1e-12)
    assert np.isposinf(hits.ranges[2])
    assert hits.ranges[3] == pytest.approx(1.5, abs=1e-12)
    assert list(hits.kind) == [HIT_CIRCLE, HIT_CIRCLE, HIT_NONE, HIT_CIRCLE]


def test_nearest_of_segment_and_circle():
    w = square_room()
    cid = w.add_circle(1.0, 0.0, 0.1)
    hits = w.raycast(np.zeros(2), [0.0, math.pi])
    assert hits.ranges == pytest.approx([0.9, 2.0], abs=1e-12)
    assert hits.kind[0] == HIT_CIRCLE and hits.ids[0] == cid


@settings(max_examples=100, deadline=None)
@given(st.floats(-1.9, 1.9), st.floats(-1.9, 1.9), st.floats(-math.pi, math.pi))
def test_random_rays_end_on_the_boundary(x, y, a):
    w = square_room()
    r = w.raycast([[x, y]], [a]).ranges[0]
    hx, hy = x + r * math.cos(a), y + r * math.sin(a)
    assert max(abs(hx), abs(hy)) == pytest.approx(2.0, abs=1e-9)


def test_square_room_corners():
    c = square_room().corners()
    assert len(c) == 4
    assert c.openings == pytest.approx([math.pi / 2.0] * 4, abs=1e-12)
    assert not np.any(c.convex)
    assert c.wall_angles == pytest.approx([1.5 * math.pi] * 4, abs=1e-12)
    # Bisectors point from each corner toward the room centre.
    to_centre = np.arctan2(-c.positions[:, 1], -c.positions[:, 0])
    assert np.abs(wrap_angle(c.bisectors - to_centre)) == pytest.approx([0.0] * 4, abs=1e-12)
    assert sorted(map(tuple, np.abs(c.positions))) == [(2.0, 2.0)] * 4
    assert list(c.ids) == [0, 1, 2, 3]
    walls = square_room().walls()
    for (ia, ib), p in zip(c.segment_ids, c.positions):
        sa = walls.segments[list(walls.ids).index(ia)]
        sb = walls.segments[list(walls.ids).index(ib)]
        assert sa[2:] == pytest.approx(p) and sb[:2] == pytest.approx(p)


def test_obstacle_corners_are_convex():
    w = World()
    w.add_rectangle(1.0, 2.0, 0.6, 0.4, yaw=math.radians(30.0))
    c = w.corners()
    assert len(c) == 4
    assert c.openings == pytest.approx([1.5 * math.pi] * 4, abs=1e-12)
    assert np.all(c.convex)
    # Bisectors are at 45 deg to the rectangle's sides and point away from its centre.
    rel = np.degrees(wrap_angle(c.bisectors - math.radians(30.0)))
    assert sorted(rel) == pytest.approx([-135.0, -45.0, 45.0, 135.0], abs=1e-9)
    out = (c.positions - [1.0, 2.0]) * np.stack([np.cos(c.bisectors), np.sin(c.bisectors)], 1)
    assert np.all(out.sum(axis=1) > 0.0)


def test_chamfer_and_two_sided_segments():
    w = World()
    w.add_room([(0, 0), (4, 0), (4, 3), (1, 3), (0, 2)])
    w.add_polyline([(2, 1), (3, 1), (3, 2)])  # two-sided: no corners
    c = w.corners()
    assert len(c) == 5
    assert sorted(np.round(np.degrees(c.openings), 9)) == [90.0, 90.0, 90.0, 135.0, 135.0]


def test_visible_corners_occlusion_fov_range():
    w = square_room(2.0)
    w.add_rectangle(0.0, 0.0, 0.5, 0.5)
    c = w.corners()
    assert len(c) == 8
    ids = dict(zip(map(tuple, c.positions), c.ids))
    pose = [-1.5, 0.0, 0.0]
    vis = set(w.visible_corners(pose, max_range=10.0).tolist())
    # The small box does not hide the room corners (lines of sight pass beside it).
    assert ids[(-2.0, -2.0)] in vis and ids[(-2.0, 2.0)] in vis
    assert ids[(2.0, 2.0)] in vis and ids[(2.0, -2.0)] in vis
    # Near box corners visible, far ones hidden behind the box.
    assert ids[(-0.25, -0.25)] in vis and ids[(-0.25, 0.25)] in vis
    assert ids[(0.25, 0.25)] not in vis and ids[(0.25, -0.25)] not in vis
    # From directly in front of one face, the far corners of a bigger box hide room corners.
    w2 = square_room(2.0)
    w2.add_rectangle(0.0, 0.0, 0.5, 3.0)
    ids2 = dict(zip(map(tuple, w2.corners().positions), w2.corners().ids))
    vis2 = set(w2.visible_corners([-1.5, 0.0, 0.0], max_range=10.0).tolist())
    assert ids2[(2.0, 2.0)] not in vis2 and ids2[(2.0, -2.0)] not in vis2
    # Field of view: facing +x with 90 deg FOV sees neither of the corners behind.
    front = set(w.visible_corners(pose, max_range=10.0, fov=math.pi / 2.0).tolist())
    assert ids[(-2.0, 2.0)] not in front and ids[(-0.25, 0.25)] in front
    # Range limit.
    near = set(w.visible_corners(pose, max_range=1.5).tolist())
    assert near == {ids[(-0.25, -0.25)], ids[(-0.25, 0.25)]}
    # both_sides: from the box's west side only its west face is visible.
    both = set(w.visible_corners(pose, max_range=10.0, both_sides=True).tolist())
    assert ids[(-0.25, 0.25)] not in both and ids[(-2.0, 2.0)] in both
    both_diag = set(w.visible_corners([-1.0, -1.0, 0.0], 10.0, both_sides=True).tolist())
    assert ids[(-0.25, -0.25)] in both_diag


def test_round_trip_dict_and_yaml():
    w = World('mixed')
    w.add_room([(0, 0), (9, 0), (9, 7.2), (0, 7.2)])
    w.add_rectangle(3.3, 2.1, 0.7, 0.3, yaw=0.123456789, label='desk')
    w.add_polyline([(5, 5), (6, 5.5)], label='partition')
    w.add_circle(6.1, 3.3, 0.025)
    d = w.to_dict()
    text = yaml.safe_dump(d)
    for data in (d, yaml.safe_load(text)):
        w2 = World.from_dict(data)
        assert w2.name == 'mixed'
        assert np.array_equal(w2.segments, w.segments)
        assert np.array_equal(w2.circles, w.circles)
        a, b = w.walls(), w2.walls()
        assert np.array_equal(a.ids, b.ids) and np.array_equal(a.two_sided, b.two_sided)
        assert a.labels == b.labels
        c1, c2 = w.corners(), w2.corners()
        for f in ('ids', 'positions', 'bisectors', 'openings', 'segment_ids'):
            assert np.array_equal(getattr(c1, f), getattr(c2, f))
        assert w2.to_dict() == d
    assert len(d['corners']) == 8


def test_normal_form_and_clearance():
    w = square_room()
    nf = w.walls().normal_form
    assert nf[:, 0] == pytest.approx([2.0] * 4)
    assert sorted(np.round(np.degrees(nf[:, 1]), 9)) == [-180.0, -90.0, 0.0, 90.0]
    assert w.clearance([[0.0, 0.0], [1.5, 0.0], [1.9, 1.8]]) == pytest.approx([2.0, 0.5, 0.1])


def test_world_errors():
    w = World()
    w.add_segment(0, 0, 1, 0, segment_id=5)
    with pytest.raises(ValueError):
        w.add_segment(0, 1, 1, 1, segment_id=5)
    with pytest.raises(ValueError):
        w.add_segment(0, 0, 0, 0)
    with pytest.raises(ValueError):
        w.add_circle(0, 0, -1.0)
    with pytest.raises(ValueError):
        World.from_dict({'name': 'x'})
