"""Fusion of laser segments and the vision outline (road.fusion, eqs. 29-30) and routes."""

import dataclasses
import math

from landmark_nav.evaluation.road_fusion import (CAMERA, CAMERA_MOUNT, evaluate_vision_road,
                                                 fuse_frame, route_open)
from landmark_nav.road.fusion import (Corridor, extend_with_outline, FusionParams,
                                      ground_to_pixels, Interval, laser_corridors,
                                      pixels_to_ground, plan_routes, polygon_intervals, Route)
from landmark_nav.sim.park_road import ParkRoad
import numpy as np
import pytest


def test_ground_pixels_round_trip():
    pts = np.array([[2.0, 0.0], [5.0, 1.5], [9.0, -2.0]])
    px = ground_to_pixels(CAMERA, CAMERA_MOUNT, pts)
    assert np.all(CAMERA.in_image(px))
    np.testing.assert_allclose(pixels_to_ground(CAMERA, CAMERA_MOUNT, px), pts, atol=1e-6)
    above = np.array([[160.0, 0.0]])            # the top row looks above the horizon
    assert np.all(np.isnan(pixels_to_ground(CAMERA, CAMERA_MOUNT, above)))


def test_laser_corridors_chain_segments_overlapping_by_more_than_the_robot_width():
    # newest first, in the odometry frame; the robot has driven 0.5 m along x since scan 2
    history = [[((3.0, -2.0), (3.0, 2.0))],
               [((2.5, -1.9), (2.5, 2.1)), ((2.5, 3.0), (2.5, 3.4))],
               [((2.0, 1.7), (2.0, 4.0))]]             # overlaps the newest by 0.3 m only
    corridors = laser_corridors(history, (0.5, 0.0, 0.0), FusionParams(robot_width=0.5))
    assert len(corridors) == 1
    iv = corridors[0].intervals
    assert len(iv) == 2                                  # the third scan is not chained
    assert iv[0].x == pytest.approx(2.0) and iv[1].x == pytest.approx(2.5)
    assert (iv[1].lo, iv[1].hi) == pytest.approx((-2.0, 2.0))


def test_outline_extends_the_corridor_until_it_narrows():
    # a road 4 m wide to x = 8, then 0.4 m wide (narrower than the robot) beyond
    poly = np.array([[2.0, -2.0], [8.0, -2.0], [8.0, -0.2], [12.0, -0.2], [12.0, 0.2],
                     [8.0, 0.2], [8.0, 2.0], [2.0, 2.0]])
    assert polygon_intervals(poly, 5.0) == [pytest.approx((-2.0, 2.0))]
    assert polygon_intervals(poly, 10.0) == [pytest.approx((-0.2, 0.2))]
    start = Corridor((Interval(2.5, -1.9, 1.9, 'laser'),))
    c = extend_with_outline(start, poly, FusionParams(line_start=0.5, line_step=0.5))
    xs = [i.x for i in c.intervals]
    assert xs[0] == 2.5 and xs[-1] == pytest.approx(7.5)   # stops before the narrow part
    assert all(i.source == 'vision' for i in c.intervals[1:])


def test_route_keeps_clear_of_an_obstacle_and_starts_turning_early():
    iv = tuple(Interval(x, -2.0, 2.0, 'vision') for x in np.arange(2.5, 10.01, 0.5))
    routes = plan_routes([Corridor(iv)], np.array([[8.0, 0.0]]), FusionParams())
    p = routes[0].points
    at = {round(x, 1): y for x, y in p}
    assert abs(at[8.0]) >= 0.5                          # half width + obstacle margin
    assert np.all(np.abs(np.diff(p[1:, 1]) / np.diff(p[1:, 0])) <= 0.5 + 1e-9)
    assert abs(at[7.5]) >= 0.25 - 1e-9 and at[7.5] * at[8.0] > 0   # starts 1 m before it


def test_pedestrian_beyond_laser_range_gives_an_avoidance_route():
    """Fig. 15: the outline, narrowed by a pedestrian 8 m ahead, bends the route early."""
    clear = fuse_frame(ParkRoad.of_kind('asphalt'), (0.0, 0.0, 0.0),
                       rng=np.random.default_rng(0))
    road = ParkRoad.of_kind('asphalt', cylinders=((8.0, 0.0, 0.25, 1.75),))
    f = fuse_frame(road, (0.0, 0.0, 0.0), rng=np.random.default_rng(0))
    assert np.all(np.abs(clear.route.points[:, 1]) < 0.1)
    p = f.route.points
    laser_x = p[1, 0]                                    # the laser line, 2.7 m ahead
    assert laser_x < 3.0
    near = p[np.abs(p[:, 0] - 8.0) <= 0.3]
    assert np.all(np.abs(near[:, 1]) >= 0.5 + 0.25 - 0.05)   # robot half width + radius
    first_turn = p[np.flatnonzero(np.abs(p[:, 1]) > 0.2)[0], 0]
    assert first_turn < 6.0                              # turning while it is 2+ m away


@pytest.mark.slow
@pytest.mark.parametrize('kind', ['asphalt', 'gravel'])
def test_vision_road_width_overcast_and_soft_shadows(kind):
    """Table 3 style on 60 rendered frames each (docs/road_following.md: 250 frames)."""
    truth = {'asphalt': 4.9, 'gravel': 4.0}[kind]
    for lighting in ('overcast', 'soft_shadows'):
        s = evaluate_vision_road(kind, lighting, 60, seed=2)
        assert s.failures <= {'overcast': 1, 'soft_shadows': 3}[lighting]   # 2 %, 5 %
        assert abs(s.width_mean - truth) < 0.3 and s.width_std <= 0.2
        assert math.isfinite(s.width_mean)


def test_route_open_detects_a_closed_or_off_road_route():
    road = ParkRoad.of_kind('asphalt')
    pose = (1.0, 0.2, math.radians(2.0))
    f = fuse_frame(road, pose, rng=np.random.default_rng(0))
    assert route_open(road, pose, f)
    r = f.route
    short = Route(r.corridor, r.points[:1], r.clearance, r.excursion)
    assert not route_open(road, pose, dataclasses.replace(f, route=short))
    off = Route(r.corridor, r.points + np.array([0.0, 2.4]), r.clearance, r.excursion)
    assert not route_open(road, pose, dataclasses.replace(f, route=off))
    assert not route_open(road, pose, dataclasses.replace(f, route=None))


@pytest.mark.slow
@pytest.mark.parametrize('kind', ['asphalt', 'gravel'])
def test_hard_shadows_and_markings_do_not_close_the_route(kind):
    """Issue acceptance on 60 rendered frames each (docs/road_following.md: 250 frames).

    Hard shadow bands across the road stop the vision outline on most frames (a vision
    failure, reported), yet every route stays open: it reaches at least the laser line and
    keeps the robot on the road (the laser corridor carries it). A dashed centre line
    neither stops the outline nor closes the route.
    """
    s = evaluate_vision_road(kind, 'hard_shadows', 60, seed=2)
    assert s.failures >= 0.5 * s.frames            # the outline does stop at the shadows
    assert s.routes_open == s.frames
    m = evaluate_vision_road(kind, 'overcast', 60, seed=2, markings=True)
    assert m.failures <= 1 and m.routes_open == m.frames
    assert m.reach_median > s.reach_median
