"""The waypoint follower of ``landmark_nav drive`` on a simulated unicycle."""

import math

from landmark_nav.sim.robot import step_pose
from landmark_nav.tools.drive import result_line, route_in_start_frame, ROUTES
from landmark_nav.waypoints import FollowerParams, WaypointFollower
import numpy as np
import pytest


def _run(points, pose, params=FollowerParams(), steps=3000):
    follower = WaypointFollower(points, params)
    path = [np.array(pose, dtype=float)]
    for _ in range(steps):
        v, w = follower.command(path[-1])
        assert abs(v) <= params.max_speed + 1e-12 and abs(w) <= params.max_turn_rate + 1e-12
        if follower.done:
            break
        path.append(step_pose(path[-1], v, w, 0.1))
    return follower, np.array(path)


def test_office_route_is_driven_through_every_waypoint_in_the_start_frame():
    start = (1.2, 1.2, math.radians(30.0))
    points = route_in_start_frame(ROUTES['office'], start)
    follower, path = _run(points, (0.0, 0.0, 0.0))
    assert follower.done
    assert follower.command(path[-1]) == (0.0, 0.0)
    end = np.hypot(*(path[-1, :2] - points[-1]))
    assert end < FollowerParams().stop_tolerance
    for p, stop in zip(points, follower.stops):  # every waypoint was passed near enough
        closest = np.hypot(*(path[:, :2] - p).T).min()
        assert closest < (0.05 if stop else 0.25)
    # back in the world: the start frame round-trips
    c, s = math.cos(start[2]), math.sin(start[2])
    world = np.array(start[:2]) + points @ np.array([[c, s], [-s, c]])
    assert world == pytest.approx(np.array(ROUTES['office']), abs=1e-12)


def test_bad_waypoints_are_rejected():
    with pytest.raises(ValueError, match='waypoints'):
        WaypointFollower(np.zeros((0, 2)))
    with pytest.raises(ValueError, match='waypoints'):
        WaypointFollower([[0.0, math.nan]])
    with pytest.raises(ValueError, match='max_speed'):
        FollowerParams(max_speed=0.0)


def test_drive_says_what_it_waits_for_and_what_to_start():
    import os
    from landmark_nav.testing.harness import RosHarness
    from landmark_nav.tools.drive import drive
    topic = f'/no_pose_here_{os.getpid()}'
    said = []
    with RosHarness() as ros:
        with pytest.raises(TimeoutError) as err:
            drive(ROUTES['short'], (0.0, 0.0, 0.0), pose_topic=topic, wait=0.2,
                  context=ros.context, log=said.append)
    assert said == [f'drive: waiting up to 0.2 s for a pose on {topic}']
    assert str(err.value).startswith(f'no pose on {topic} within 0.2 s: start the node')
    assert 'landmark_nav pipeline slam' in str(err.value) and '--pose-topic' in str(err.value)


def test_the_result_line_counts_laps_only_when_looping():
    """A run without --loop printed '0 laps and 10/11 waypoints ...'."""
    result = {'laps': 0, 'reached': 10, 'waypoints': 11, 'seconds': 120.24, 'poses': 1201}
    assert result_line(result, loop=False) == (
        'drive: 10/11 waypoints in 120.2 s, 1201 poses received')
    assert result_line(dict(result, laps=2), loop=True) == (
        'drive: 2 laps and 10/11 waypoints in 120.2 s, 1201 poses received')
