"""The graph back end's run judged on a building's occupancy grid (no trajectory truth).

The graph back end (:mod:`.slam_graph`) keeps no landmarks: its map is its trajectory and
the scans placed with it. On a log with a grid of the building (the CMU Wean runs and
``wean.dat``) it is judged as the EKF's run is (:mod:`.occupancy_check`), on its final
trajectory (every loop applied), with every scan's structural corners
(``Corner.structural``: both arms on surfaces the scan supports) placed with that
trajectory standing for the landmarks:

* the alignment to the grid and the scan end points near a wall, of the graph's poses and
  of the odometry's (:func:`.occupancy_check.check_run`);
* poses in wall cells (:func:`.occupancy_check.wall_pose_diagnosis`) and those left once
  one cell of tolerance and the cells the log's own scans see through are excused
  (:func:`.occupancy_check.wall_poses_counted`);
* the share of the structural corners within 10 cm of a wall cell, corners near a wall
  cell the log sees through left out (:func:`.occupancy_check.corner_wall_check`): each
  detection counts, so a place seen from many poses weighs as much as its views;
* the same share per place (:func:`corner_places`): the detections linked into places as
  a landmark map would hold them, one figure per place, as the EKF's landmark share
  counts each landmark once;
* whether the log's own scans agree with the grid at each place
  (:func:`place_scan_agreement`).
"""

from types import SimpleNamespace
from typing import Dict, Tuple

from landmark_nav.evaluation.occupancy_check import (check_run, corner_wall_check,
                                                     OccupancyGrid, point_wall_distance,
                                                     run_scan_points, wall_pose_diagnosis,
                                                     wall_poses_counted)
from landmark_nav.evaluation.slam_run import scan_corners
from landmark_nav.geometry import compose, transform_points
from landmark_nav.sim import ScanSample
import numpy as np


def scan_indices(scan_stamps: np.ndarray, used_stamps: np.ndarray) -> np.ndarray:
    """Return the index among all scans of each scan a run used (in order; stamps may repeat).

    The run used a subsequence of the scans in their order: each used stamp is matched to
    the next scan with that stamp.

    Raises:
        ValueError: A used stamp with no scan left to match (names it).
    """
    out, k = [], 0
    stamps = np.asarray(scan_stamps)
    for t in np.asarray(used_stamps):
        while k < len(stamps) and stamps[k] != t:
            k += 1
        if k == len(stamps):
            raise ValueError(f'scan_indices: no scan left with stamp {int(t)} ns')
        out.append(k)
        k += 1
    return np.array(out, dtype=np.int64)


def placed_run(scenario, run, corner_params=None) -> SimpleNamespace:
    """Return the fields the occupancy checks read, from a :class:`.slam_graph.GraphRun`.

    ``poses`` the final trajectory, ``odometry``, ``stamps``, ``scan_index`` (into the
    scenario's scans) and ``landmarks``: every used scan's structural corners
    (:func:`.slam_run.scan_corners` with ``corner_params``) placed with its final pose and
    the laser mount, (K, 2).
    """
    scans = scenario.of_type(ScanSample)
    index = scan_indices(np.array([s.stamp_ns for s in scans], dtype=np.int64), run.stamps)
    mount = np.asarray(scenario.laser.mount, dtype=float)
    corners = []
    for k, i in enumerate(index):
        found = [c.position for c in scan_corners(scans[int(i)], corner_params) if c.structural]
        if found:
            corners.append(transform_points(compose(run.final[k], mount), np.array(found)))
    return SimpleNamespace(poses=run.final, odometry=run.odometry, stamps=run.stamps,
                           scan_index=index,
                           landmarks=np.vstack(corners) if corners else np.zeros((0, 2)))


def _linked(pts: np.ndarray, link: float) -> np.ndarray:
    """Label the points' single-linkage groups (pairs closer than ``link`` joined)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree
    pairs = cKDTree(pts).query_pairs(link, output_type='ndarray')
    adj = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                     shape=(len(pts), len(pts)))
    return connected_components(adj, directed=False)[1]


def corner_places(cw: Dict[str, object], link: float = 0.1, min_views: int = 3,
                  tolerance: float = 0.1) -> Dict[str, object]:
    """Group the structural corner detections into places and score each place once.

    Detections (grid frame, a :func:`.occupancy_check.corner_wall_check` result) closer than
    ``link`` are linked (single linkage: connected components of the pairs within
    ``link``); a place seen at least ``min_views`` times (the EKF's ``confirm_hits``) is a
    landmark. It lies on a wall when the median of its detections' distances to a wall
    cell is within ``tolerance`` (as :func:`.occupancy_check.landmark_diagnosis` judges a
    landmark by its observations), and is left out when most of its detections are.

    Returns:
        ``count`` places judged, ``share`` of them on a wall (nan: none), ``left_out``,
        ``views_median`` detections per place judged.
    """
    sel, label, kept, skipped = _places(cw, link, min_views)
    if sel.size == 0:
        return {'count': 0, 'share': float('nan'), 'left_out': 0, 'views_median': 0.0}
    dist = np.asarray(cw['wall_distance'], dtype=float)[sel]
    judged = [int(np.count_nonzero(label == c)) for c in kept]
    on = [np.median(dist[label == c]) <= tolerance for c in kept]
    return {'count': len(judged), 'share': float(np.mean(on)) if on else float('nan'),
            'left_out': skipped, 'views_median': float(np.median(judged)) if judged else 0.0}


def _places(cw: Dict[str, object], link: float, min_views: int
            ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Group the structural detections into places (:func:`corner_places`).

    Returns:
        ``(sel, label, kept, skipped)``: the structural detections' indices, the place of
        each, the places seen at least ``min_views`` times and not mostly left out, and the
        number of places seen that often but mostly left out.
    """
    sel = np.flatnonzero(np.asarray(cw['structural'], dtype=bool))
    if sel.size == 0:
        return sel, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), 0
    label = _linked(np.asarray(cw['points'], dtype=float)[sel], link)
    views = np.bincount(label)
    out_frac = np.bincount(label, np.asarray(cw['left_out'], dtype=float)[sel]) / views
    seen = views >= min_views
    return sel, label, np.flatnonzero(seen & (out_frac <= 0.5)), \
        int(np.count_nonzero(seen & (out_frac > 0.5)))


def place_scan_agreement(cw: Dict[str, object], points: np.ndarray, wall_distance: np.ndarray,
                         link: float = 0.1, min_views: int = 3, tolerance: float = 0.1,
                         at: float = 0.1, near: float = 0.5, ring: float = 1.5
                         ) -> Dict[str, object]:
    """Ask, at each structural-corner place, whether the log's own scans agree with the grid.

    Places as :func:`corner_places` groups them (``link``, ``min_views``; those mostly left
    out are skipped). For each, the run's scan end points (grid frame, ``points``, with
    their ``wall_distance``, :func:`.occupancy_check.point_wall_distance`) within ``at`` of
    the place (the surfaces that make the corner) and those in the square ring between
    ``near`` and ``ring`` around it (the walls nearby): the share within ``tolerance`` of a
    wall cell of each. A corner off the walls whose own scan points are off the walls too,
    while the walls nearby agree, is a surface the log saw and the grid does not hold (made
    at another time, an object, a finer detail than its cells), not a misplaced corner; one
    whose scan points lie on the walls is a corner the extractor placed off them.

    Returns:
        ``places``: a list (views, descending) of dicts ``centre`` (2,), ``views``,
        ``on_wall``, ``convex`` (most detections convex), ``distance`` (the detections'
        median distance to a wall cell), ``at_share``, ``at_points``, ``at_distance`` (the
        median distance to a wall cell of the points within ``at``), ``ring_share``;
        ``on`` / ``off``: per group of places (on / off the walls) ``count``, the mean
        ``at_share`` and ``ring_share``, and ``scans_off``: the places whose points within
        ``at`` are mostly off the walls (``at_share`` below 0.5); ``overall``: the share
        of all points.
    """
    sel, label, kept, _ = _places(cw, link, min_views)
    pts = np.asarray(cw['points'], dtype=float)[sel]
    wd = np.asarray(wall_distance, dtype=float)
    pw = wd <= tolerance
    out: Dict[str, object] = {'places': [], 'overall': float(pw.mean()) if pw.size else
                              float('nan')}
    if kept.size:
        from scipy.spatial import cKDTree
        tree = cKDTree(points)
        dist = np.asarray(cw['wall_distance'], dtype=float)[sel]
        convex = np.asarray(cw['convex'], dtype=bool)[sel]
        for c in kept:
            m = label == c
            centre = np.median(pts[m], axis=0)
            at_i = tree.query_ball_point(centre, at)
            box = np.array(tree.query_ball_point(centre, ring * np.sqrt(2.0)), dtype=np.int64)
            off = np.abs(points[box] - centre).max(axis=1)
            ring_i = box[(off > near) & (off <= ring)]
            out['places'].append({
                'centre': centre, 'views': int(m.sum()),
                'on_wall': bool(np.median(dist[m]) <= tolerance),
                'convex': bool(convex[m].mean() > 0.5), 'distance': float(np.median(dist[m])),
                'at_share': float(pw[at_i].mean()) if at_i else float('nan'),
                'at_points': len(at_i),
                'at_distance': float(np.median(wd[at_i])) if at_i else float('nan'),
                'ring_share': float(pw[ring_i].mean()) if ring_i.size else float('nan')})
    out['places'].sort(key=lambda p: -p['views'])
    for key, on in (('on', True), ('off', False)):
        group = [p for p in out['places'] if p['on_wall'] == on]
        out[key] = {'count': len(group), 'scans_off': sum(p['at_share'] < 0.5 for p in group)}
        for share in ('at_share', 'ring_share'):  # the mean of the places with points there
            known = [p[share] for p in group if np.isfinite(p[share])]
            out[key][share] = float(np.mean(known)) if known else float('nan')
    return out


def graph_wall_check(grid: OccupancyGrid, scenario, run, corner_params=None,
                     refine: bool = True) -> Dict[str, object]:
    """Judge a graph run on the grid (module docstring).

    Args:
        grid: The building's grid.
        scenario: The bag (:func:`landmark_nav.evaluation.bags.load_bag`).
        run: :func:`.slam_graph.run_graph` on it.
        corner_params: The corner extractor's parameters (the laser's noise).
        refine: The alignment's continuous refinement (:func:`.occupancy_check.occupancy_check`).

    Returns:
        ``check`` (:func:`.occupancy_check.check_run`: ``'slam'`` the graph's poses,
        ``'odometry'``), ``wall`` (:func:`.occupancy_check.wall_pose_diagnosis` over every
        step), ``poses_in_wall_counted``, ``corners``
        (:func:`.occupancy_check.corner_wall_check`), ``places`` (:func:`corner_places`),
        ``agreement`` (:func:`place_scan_agreement`, every other scan's points) and
        ``scan_points`` (those points in the grid frame, with ``wall_distance``).

    Raises:
        ValueError: No structural corner in the run (the alignment has nothing to score).
    """
    placed = placed_run(scenario, run, corner_params)
    if placed.landmarks.shape[0] == 0:
        raise ValueError('graph_wall_check: no structural corner in any scan of the run')
    fit = check_run(grid, scenario, placed, refine=refine)
    t = np.asarray(fit['slam']['transform'])
    wall = wall_pose_diagnosis(grid, scenario, placed, t, every=1)
    cw = corner_wall_check(grid, scenario, placed, t, corner_params)
    pts = transform_points(t, run_scan_points(scenario, placed.scan_index, placed.poses))
    d = point_wall_distance(grid, pts)
    return {'check': fit, 'wall': wall,
            'poses_in_wall_counted': wall_poses_counted(wall, grid.resolution),
            'corners': cw, 'places': corner_places(cw),
            'agreement': place_scan_agreement(cw, pts, d),
            'scan_points': {'points': pts, 'wall_distance': d}}


__all__ = ['corner_places', 'graph_wall_check', 'place_scan_agreement', 'placed_run',
           'scan_indices']
