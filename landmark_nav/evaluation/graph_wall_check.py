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
  cell the log sees through left out (:func:`.occupancy_check.corner_wall_check`).
"""

from types import SimpleNamespace
from typing import Dict

from landmark_nav.evaluation.occupancy_check import (check_run, corner_wall_check,
                                                     OccupancyGrid, wall_pose_diagnosis,
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


def graph_wall_check(grid: OccupancyGrid, scenario, run,
                     corner_params=None) -> Dict[str, object]:
    """Judge a graph run on the grid (module docstring).

    Args:
        grid: The building's grid.
        scenario: The bag (:func:`landmark_nav.evaluation.bags.load_bag`).
        run: :func:`.slam_graph.run_graph` on it.
        corner_params: The corner extractor's parameters (the laser's noise).

    Returns:
        ``check`` (:func:`.occupancy_check.check_run`: ``'slam'`` the graph's poses,
        ``'odometry'``), ``wall`` (:func:`.occupancy_check.wall_pose_diagnosis` over every
        step), ``poses_in_wall_counted``, ``corners``
        (:func:`.occupancy_check.corner_wall_check`).

    Raises:
        ValueError: No structural corner in the run (the alignment has nothing to score).
    """
    placed = placed_run(scenario, run, corner_params)
    if placed.landmarks.shape[0] == 0:
        raise ValueError('graph_wall_check: no structural corner in any scan of the run')
    fit = check_run(grid, scenario, placed)
    t = np.asarray(fit['slam']['transform'])
    wall = wall_pose_diagnosis(grid, scenario, placed, t, every=1)
    return {'check': fit, 'wall': wall,
            'poses_in_wall_counted': wall_poses_counted(wall, grid.resolution),
            'corners': corner_wall_check(grid, scenario, placed, t, corner_params)}


__all__ = ['graph_wall_check', 'placed_run', 'scan_indices']
