"""Occupancy-grid check of a SLAM result (landmark_nav.evaluation.occupancy_check)."""

import gzip
import math
from types import SimpleNamespace

from landmark_nav.evaluation.occupancy_check import (landmark_diagnosis, load_occupancy_grid,
                                                     occupancy_check, OccupancyGrid,
                                                     run_segments, scan_end_points)
from landmark_nav.evaluation.slam import SlamRun
import numpy as np
import pytest


def _room_grid():
    """Return a 20 x 12 m room (10 cm cells, walls 1 cell thick, unknown outside, a stub)."""
    v = -np.ones((300, 200))
    v[50:251, 40:161] = 0.0
    v[51:250, 41:160] = 1.0
    v[100, 41:90] = 0.0  # x = 10.05 m, y 4.1 - 9.0 m: no symmetry left
    return OccupancyGrid(v, 0.1, 'room')


def _rot(th):
    return np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])


def test_recovers_a_rigid_transform():
    """Landmarks on the walls and poses inside, seen from a rotated and shifted frame."""
    grid = _room_grid()
    rng = np.random.default_rng(0)
    # Wall centre lines: x = 5.05 / 24.95, y = 4.05 / 15.95 (grid frame).
    lm = np.array([[5.05, 6.0], [5.05, 12.0], [24.95, 8.0], [10.0, 4.05], [18.0, 15.95],
                   [5.05, 4.05], [24.95, 15.95], [13.0, 4.05], [10.05, 6.5], [10.05, 8.5]])
    poses = np.column_stack([rng.uniform(11, 23, 50), rng.uniform(6, 14, 50)])
    th, t = 0.7, np.array([-3.0, 2.5])  # grid -> SLAM frame
    to_slam = (lambda p: p @ _rot(th).T + t)
    r = occupancy_check(grid, to_slam(lm), to_slam(poses), points=to_slam(
        np.vstack([lm, lm + [[0.0, 0.02]]])))
    assert r['landmark_share'] == 1.0 and r['poses_in_wall'] == 0 and r['poses_unknown'] == 0
    assert r['point_share'] == 1.0
    back = to_slam(lm) @ _rot(r['transform'][2]).T + r['transform'][:2]
    assert np.max(np.hypot(*(back - lm).T)) < 0.1  # within the tolerance of the walls


def test_scan_end_points_through_pose_and_mount():
    pts = scan_end_points(np.array([[1.0, 2.0, math.pi / 2]]), np.array([0.25, 0.0, 0.0]),
                          np.array([[1.0, 2.0]]), np.array([0.0, math.pi / 2]),
                          np.array([[True, True]]))
    assert np.allclose(pts, [[1.0, 3.25], [-1.0, 2.25]])


def test_load_errors_name_file_and_line(tmp_path):
    good = 'robot_specifications->resolution 10\nglobal_map[0]: 2 3\n0 1 -1\n1 0.5 0\n'
    p = tmp_path / 'm.dat.gz'
    with gzip.open(p, 'wt') as f:
        f.write(good)
    g = load_occupancy_grid(p)
    assert g.resolution == 0.1 and g.values.shape == (2, 3) and g.values[0, 2] == -1
    bad = tmp_path / 'bad.dat'
    bad.write_text(good.replace('1 0.5 0', '1 0.5'))
    with pytest.raises(ValueError, match=r'bad.dat:4: 2 values, expected 3'):
        load_occupancy_grid(bad)
    bad.write_text('global_map[0]: 1 1\n0\n')
    with pytest.raises(ValueError, match='resolution'):
        load_occupancy_grid(bad)


def test_landmark_diagnosis_categories():
    """One corner per category, in the grid frame (identity transform)."""
    grid = _room_grid()
    # 0 on the wall x = 5.05; 1 off (x = 5.5) but observed on the wall (moved);
    # 2 off, detected twice (few views); 3 off and observed off (off grid).
    lm = np.array([[5.05, 6.0], [5.5, 8.0], [12.0, 10.0], [15.0, 12.0]])
    obs = [(0, [5.05, 6.02], 'confirmed'), (0, [5.06, 6.0], 'matched'),
           (1, [5.07, 8.0], 'confirmed'), (1, [5.1, 8.0], 'matched'),
           (1, [5.3, 8.0], 'matched'), (2, [12.0, 10.0], 'confirmed'),
           (2, [12.0, 10.1], 'matched'), (3, [15.0, 12.0], 'confirmed'),
           (3, [15.0, 12.0], 'matched'), (3, [15.0, 12.1], 'matched'),
           (3, [15.1, 12.0], 'matched'), (-1, [5.05, 7.0], 'new')]
    run = SimpleNamespace(landmark_ids=np.array([10, 11, 12, 13]), landmarks=lm,
                          obs_landmark=np.array([10 + o[0] if o[0] >= 0 else -1 for o in obs]),
                          obs_world=np.array([o[1] for o in obs]),
                          obs_status=np.array([o[2] for o in obs]))
    d = landmark_diagnosis(grid, run, np.zeros(3), confirm_hits=3)
    assert d['category'].tolist() == ['on_wall', 'moved', 'few_views', 'off_grid']
    assert d['detections'].tolist() == [2, 3, 2, 4]
    assert d['distance'][0] == 0.0 and d['distance'][1] == pytest.approx(0.4, abs=1e-9)
    assert d['obs_distance'][1] == pytest.approx(0.0, abs=1e-9)  # median of 0, 0, 0.2
    assert d['neighbour'][0] == pytest.approx(math.hypot(0.45, 2.0))


def test_run_segments_split_at_bridged_jumps():
    """Steps 0-3, a bridged jump before step 4, steps 4-5: two parts and their corners."""
    n = 6
    z = np.zeros((n, 3))
    run = SlamRun(stamps=np.arange(n), poses=np.arange(3 * n, dtype=float).reshape(n, 3),
                  covariances=np.zeros((n, 3, 3)), truth=z, odometry=z + 1.0,
                  obs_scan=np.array([0, 1, 2, 4, 5, 5]),
                  obs_world_true=np.zeros((6, 2)),
                  obs_status=np.array(['confirmed', 'matched', 'confirmed', 'confirmed',
                                       'matched', 'matched']),
                  obs_landmark=np.array([7, 7, 8, 9, 9, 7]), nis=np.zeros(n),
                  nis_dof=np.zeros(n), landmark_ids=np.array([7, 8, 9]),
                  landmarks=np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]),
                  landmark_covariances=np.zeros((3, 2, 2)), stats={}, resets=0, seconds=0.0,
                  scan_index=np.arange(10, 10 + n),
                  obs_world=np.arange(12, dtype=float).reshape(6, 2),
                  bridged=np.array([False, False, False, False, True, False]))
    a, b = run_segments(run)
    assert a.scan_index.tolist() == [10, 11, 12, 13] and b.scan_index.tolist() == [14, 15]
    assert a.landmark_ids.tolist() == [7, 8] and b.landmark_ids.tolist() == [9]
    assert b.poses[0].tolist() == [12.0, 13.0, 14.0]
    assert b.obs_scan.tolist() == [0, 1, 1] and b.obs_landmark.tolist() == [9, 9, 7]
    assert b.obs_world[0].tolist() == [6.0, 7.0]
    # Nothing bridged (or no record): the run itself.
    from dataclasses import replace
    whole = replace(run, bridged=np.zeros(n, dtype=bool))
    assert run_segments(whole) == [whole]


def test_wall_pose_diagnosis_depth_and_crossings():
    """Poses at the edge and in the middle of a wall blob that another scan sees through."""
    from landmark_nav.evaluation.occupancy_check import wall_pose_diagnosis
    from landmark_nav.sim import ScanSample
    grid = _room_grid()
    grid.values[140:143, 100:103] = 0.0  # x 14.0-14.3 m, y 10.0-10.3 m
    poses = np.array([[12.0, 10.15, 0.0],  # free, its beam crosses row y = 10.15
                      [14.05, 10.05, 0.0],  # the blob's corner cell: one cell deep
                      [14.15, 10.15, 0.0]])  # the blob's middle cell: two cells deep

    def scan(r):
        return ScanSample(stamp_ns=0, ranges=np.array([r, np.inf], dtype=np.float32),
                          angle_min=0.0, angle_max=0.1, angle_increment=0.1,
                          time_increment=0.0, scan_time=0.1, range_min=0.02, range_max=30.0)
    scans = [scan(5.0), scan(np.inf), scan(0.2)]  # the last: a return inside the margin
    scenario = SimpleNamespace(of_type=lambda cls: scans if cls is ScanSample else [],
                               laser=SimpleNamespace(mount=(0.0, 0.0, 0.0)))
    run = SimpleNamespace(poses=poses, scan_index=np.arange(3))
    d = wall_pose_diagnosis(grid, scenario, run, np.zeros(3), every=1)
    assert d['steps'].tolist() == [1, 2]
    assert d['depth'] == pytest.approx([0.1, 0.2])
    # Scan 0's beam runs from x = 12.3 to 16.7 at y = 10.15: cells (140-142, 101).
    assert d['crossings'].tolist() == [0, 1]
    assert d['wall_crossings'].tolist() == [1, 1, 1]
    # Issue 41's count: the edge cell is within one cell's tolerance, the deep one is seen
    # through; the deep one counts when no scan sees through it.
    from landmark_nav.evaluation.occupancy_check import wall_poses_counted
    assert wall_poses_counted(d, grid.resolution) == 0
    assert wall_poses_counted(dict(d, crossings=np.zeros(2)), grid.resolution) == 1
    assert wall_poses_counted(dict(d, crossings=np.zeros(2)), grid.resolution, cells=2) == 0


def test_scan_indices_match_used_scans_in_order_with_repeated_stamps():
    from landmark_nav.evaluation.graph_wall_check import scan_indices
    stamps = np.array([5, 7, 7, 9, 12])
    assert scan_indices(stamps, np.array([7, 7, 12])).tolist() == [1, 2, 4]
    assert scan_indices(stamps, np.array([5, 9])).tolist() == [0, 3]
    with pytest.raises(ValueError, match='stamp 7 ns'):
        scan_indices(stamps, np.array([9, 7]))


def test_corner_places_scores_each_place_once():
    """Five views of a corner on a wall, three of one off it, two of a third: 1 of 2."""
    from landmark_nav.evaluation.graph_wall_check import corner_places
    pts = np.array([[0.0, 0.0], [0.03, 0.0], [0.06, 0.01], [0.09, 0.0], [0.12, 0.0],
                    [5.0, 5.0], [5.02, 5.0], [5.04, 5.0], [9.0, 0.0], [9.01, 0.0]])
    cw = {'points': pts, 'structural': np.ones(10, dtype=bool),
          'wall_distance': np.array([0.0] * 5 + [0.2] * 3 + [0.0] * 2),
          'left_out': np.zeros(10, dtype=bool)}
    p = corner_places(cw)
    assert (p['count'], p['share'], p['left_out'], p['views_median']) == (2, 0.5, 0, 4.0)
    cw['left_out'][5:7] = True  # most views of the off-wall place left out: so is the place
    p = corner_places(cw)
    assert (p['count'], p['share'], p['left_out']) == (1, 1.0, 1)


def test_point_wall_distance_is_to_the_wall_cells_square():
    from landmark_nav.evaluation.occupancy_check import point_wall_distance
    d = point_wall_distance(_room_grid(), np.array([[5.05, 8.0], [5.4, 8.0], [5.12, 8.0]]))
    assert d == pytest.approx([0.0, 0.3, 0.02], abs=1e-9)  # wall cell x 5.0 - 5.1 m


def test_refinement_brings_the_points_closer_to_the_walls():
    """Points 3 cm off the walls: the whole-cell search cannot take them closer, the fit can."""
    from landmark_nav.evaluation.occupancy_check import point_wall_distance
    v = -np.ones((70, 50))  # a 5 x 3 m room, walls 1 cell thick, a stub against symmetry
    v[10:61, 10:41] = 0.0
    v[11:60, 11:40] = 1.0
    v[20, 11:20] = 0.0
    grid = OccupancyGrid(v, 0.1, 'small room')
    y = np.linspace(1.5, 3.5, 30)
    pts = np.vstack([np.column_stack([np.full_like(y, 1.08), y]),
                     np.column_stack([np.full_like(y, 5.98), y]),
                     np.column_stack([np.linspace(2.5, 5.5, 30), np.full(30, 1.08)])])
    poses = np.column_stack([np.linspace(2.5, 5.5, 20), np.full(20, 2.5)])

    def mean_distance(r):
        t = r['transform']
        return point_wall_distance(grid, pts @ _rot(t[2]).T + t[:2]).mean()

    kw = {'coarse_step_deg': 10.0, 'fine_step_deg': 1.0}
    fine = occupancy_check(grid, pts[:5], poses, points=pts, **kw)
    cells = occupancy_check(grid, pts[:5], poses, points=pts, refine=False, **kw)
    assert mean_distance(fine) < mean_distance(cells)


def test_place_scan_agreement_tells_a_surface_the_grid_lacks():
    """A place on a wall with its points on it; one off with its points off, walls around on."""
    from landmark_nav.evaluation.graph_wall_check import place_scan_agreement
    corners = np.array([[0.0, 0.0]] * 3 + [[5.0, 5.0]] * 4)
    cw = {'points': corners, 'structural': np.ones(7, dtype=bool),
          'left_out': np.zeros(7, dtype=bool), 'convex': np.array([False] * 3 + [True] * 4),
          'wall_distance': np.array([0.0] * 3 + [0.25] * 4)}
    at = np.array([[0.02, 0.0], [0.0, 0.03], [5.03, 5.0], [5.0, 4.98]])
    ring = np.array([[1.0, 0.0], [0.0, -1.0], [6.0, 5.0], [5.0, 6.2]])
    points = np.vstack([at, ring])
    d = np.array([0.0, 0.0, 0.25, 0.22, 0.0, 0.0, 0.0, 0.3])
    a = place_scan_agreement(cw, points, d)
    assert [(p['views'], p['on_wall'], p['convex']) for p in a['places']] == [
        (4, False, True), (3, True, False)]
    off, on = a['places']
    assert (off['at_share'], off['at_points'], off['ring_share']) == (0.0, 2, 0.5)
    assert (on['at_share'], on['ring_share']) == (1.0, 1.0)
    assert off['at_distance'] == pytest.approx(0.235)
    assert a['off']['scans_off'] == 1 and a['on']['scans_off'] == 0
    assert a['overall'] == pytest.approx(5 / 8)


def test_plot_place_crops_draws_the_places_off_the_walls(tmp_path):
    from landmark_nav.evaluation.slam_plots import plot_place_crops
    grid = _room_grid()
    cw = {'points': np.array([[5.05, 8.0], [6.0, 8.0]]), 'structural': np.ones(2, dtype=bool),
          'left_out': np.zeros(2, dtype=bool), 'on_wall': np.array([True, False])}
    place = {'centre': np.array([6.0, 8.0]), 'views': 3, 'on_wall': False, 'convex': True,
             'at_share': 0.0, 'ring_share': 1.0}
    scan = {'points': np.array([[5.05, 7.5], [6.0, 8.05]]), 'wall_distance': np.array([0.0, 0.9])}
    out = tmp_path / 'crops.png'
    assert plot_place_crops(grid, cw, {'places': [dict(place, on_wall=True)]}, scan, 't',
                            out) == 0 and not out.exists()
    assert plot_place_crops(grid, cw, {'places': [place]}, scan, 't', out) == 1
    assert out.stat().st_size > 0


def test_place_scan_agreement_judges_the_places_corner_places_judges():
    """A place mostly left out is skipped by both, its other detections included."""
    from landmark_nav.evaluation.graph_wall_check import corner_places, place_scan_agreement
    # 7 views off the walls, 4 of them left out (skipped as a place, as corner_places does,
    # not kept as a place of its 3 others), and 3 views on a wall
    cw = {'points': np.array([[5.0, 5.0]] * 7 + [[0.0, 0.0]] * 3),
          'structural': np.ones(10, dtype=bool),
          'left_out': np.array([True] * 4 + [False] * 6), 'convex': np.ones(10, dtype=bool),
          'wall_distance': np.array([0.25] * 7 + [0.0] * 3)}
    a = place_scan_agreement(cw, np.array([[5.0, 5.0], [0.0, 0.0]]), np.array([0.25, 0.0]))
    p = corner_places(cw)
    assert (p['count'], p['left_out']) == (1, 1)
    assert [(q['views'], q['on_wall']) for q in a['places']] == [(3, True)]
    assert (a['on']['count'], a['off']['count']) == (1, 0)


def test_grid_correlation_is_fftconvolve_bit_for_bit():
    """The kept grid FFT changes nothing: equal arrays, one-cell-wide rasters included."""
    from landmark_nav.evaluation.occupancy_check import _GridCorrelation
    from scipy import signal
    rng = np.random.default_rng(3)
    grid = (rng.random((90, 70)) < 0.2).astype(float)
    corr = _GridCorrelation(grid)
    for shape in [(12, 9), (13, 9), (12, 9), (1, 7), (6, 1), (25, 30), (12, 10)] * 2:
        counts = rng.integers(0, 3, shape).astype(float)
        got = corr.correlate(counts)
        assert np.array_equal(got, signal.fftconvolve(grid, counts[::-1, ::-1], 'full'))
    assert 1 <= len(corr._spectra) <= 8
