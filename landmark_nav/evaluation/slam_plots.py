"""Figures of an EKF-SLAM run: the map over the scans, the paths, the errors."""

import math
from pathlib import Path
from typing import List

from landmark_nav.evaluation.slam_run import scan_angles, SlamRun
from landmark_nav.evaluation.slam_scores import ALIGN_DEFAULT
from landmark_nav.evaluation.trajectory import aligned, Trajectory
from landmark_nav.geometry import covariance_ellipse, transform_points
from landmark_nav.sim import ScanSample
from landmark_nav.sim.laser import compose as sensor_pose
import numpy as np


def _scan_points(scenario, run: SlamRun, max_points: int = 200_000) -> np.ndarray:
    """(P, 2) scan end points in the map frame through the filter poses (a subsample)."""
    scans = scenario.of_type(ScanSample)
    n = sum(int(np.isfinite(s.ranges).sum()) for s in scans)
    step = max(1, int(math.ceil(n / max_points)))
    mount = tuple(float(v) for v in scenario.laser.mount)
    out = []
    index = run.scan_index if run.scan_index is not None else np.arange(len(run.poses))
    for k, i in enumerate(index):
        scan = scans[i]
        ok = np.isfinite(scan.ranges)
        if not np.any(ok):
            continue
        r = scan.ranges[ok].astype(float)
        a = scan_angles(scan)[ok]
        pts = np.column_stack([r * np.cos(a), r * np.sin(a)])[::step]
        out.append(transform_points(sensor_pose(run.poses[k], mount), pts))
    return np.concatenate(out) if out else np.zeros((0, 2))


def _save_plan(fig, ax, title: str, path: Path) -> None:
    """Finish a top view in metres (equal axes, labels, legend), write it and close it."""
    import matplotlib.pyplot as plt
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(title)
    ax.legend(loc='best', fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_run(scenario, run: SlamRun, out_dir: Path, title: str, align: str = ALIGN_DEFAULT
             ) -> List[str]:
    """Write the figures of a run; return their file names.

    * ``slam_map.png``: the scans' end points through the filter poses (the map over the
      scans), the mapped landmarks with 2-sigma ellipses and the filter path; with a world,
      also its walls and true corners (Fig. 19 of the chapter).
    * ``slam_trajectory.png``: filter and odometry paths against the reference after the
      ``align`` alignment (each aligned on its own, as the ATE is computed).
    * ``slam_errors.png``: x, y, heading error against the reference with the filter's
      +-2 sigma (unaligned, in the map frame).

    Without a reference (a bag's ``has_reference`` False) only ``slam_map.png``.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 7.5))
    pts = _scan_points(scenario, run)
    ax.plot(pts[:, 0], pts[:, 1], ',', color='0.55', alpha=0.6)
    ax.plot([], [], '.', color='0.55', label='scans through the EKF-SLAM poses')
    if scenario.world is not None:
        for x1, y1, x2, y2 in scenario.world.walls().segments:
            ax.plot([x1, x2], [y1, y2], color='0.3', lw=1.5)
        tc = scenario.world.corners().positions
        ax.plot(tc[:, 0], tc[:, 1], 'k+', ms=9, label='true corners')
    ax.plot(run.poses[:, 0], run.poses[:, 1], 'b-', lw=1, label='EKF-SLAM path')
    if run.landmarks.shape[0]:
        ax.plot(run.landmarks[:, 0], run.landmarks[:, 1], 'ro', mfc='none', ms=5,
                label='mapped landmarks (2 sigma)')
        for m, c in zip(run.landmarks, run.landmark_covariances):
            e = covariance_ellipse(m, c)
            ax.plot(e[:, 0], e[:, 1], 'r-', lw=0.8)
    _save_plan(fig, ax, title, out_dir / 'slam_map.png')
    if not getattr(scenario, 'has_reference', True):
        return ['slam_map.png']  # the other figures are against the reference

    ref = Trajectory.from_planar(run.stamps, run.truth)
    fig, ax = plt.subplots(figsize=(9, 7.5))
    ax.plot(run.truth[:, 0], run.truth[:, 1], 'g-', lw=1.2, label='reference')
    for poses, style, name in ((run.odometry, 'r:', 'odometry'), (run.poses, 'b-', 'EKF-SLAM')):
        try:
            _, est = aligned(Trajectory.from_planar(run.stamps, poses), ref, align)
        except ValueError:
            continue
        ax.plot(est[:, 0], est[:, 1], style, lw=1, label=f'{name} ({align} aligned)')
    _save_plan(fig, ax, title, out_dir / 'slam_trajectory.png')

    t = (run.stamps - run.stamps[0]) * 1e-9
    err = run.poses - run.truth
    err[:, 2] = np.angle(np.exp(1j * err[:, 2]))
    sig = np.sqrt(np.maximum(np.diagonal(run.covariances, axis1=1, axis2=2), 0.0))
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    scale = (100.0, 100.0, 180.0 / math.pi)
    for k, (ax, lab) in enumerate(zip(axes, ('x error [cm]', 'y error [cm]',
                                             'psi error [deg]'))):
        ax.plot(t, scale[k] * err[:, k], 'b-', lw=1, label='error')
        ax.plot(t, 2 * scale[k] * sig[:, k], 'r--', lw=0.8, label='+-2 sigma')
        ax.plot(t, -2 * scale[k] * sig[:, k], 'r--', lw=0.8)
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc='upper right', fontsize=8)
    axes[-1].set_xlabel('time [s]')
    axes[0].set_title(title)
    fig.tight_layout()
    fig.savefig(out_dir / 'slam_errors.png', dpi=120)
    plt.close(fig)
    return ['slam_map.png', 'slam_trajectory.png', 'slam_errors.png']


__all__ = ['plot_corner_wall_check', 'plot_place_crops', 'plot_run']


def plot_corner_wall_check(grid, check: dict, title: str, path: Path) -> None:
    """Draw the grid, the path and the structural corners on / off the walls.

    ``check``: :func:`landmark_nav.evaluation.occupancy_check.corner_wall_check`'s result
    (its ``path`` drawn in the grid frame). The view is cropped to the path
    and the corners.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    v, res = grid.values, grid.resolution
    poses_grid = check['path']
    fig, ax = plt.subplots(figsize=(8, 8))
    shade = np.where(v < 0.0, 0.75, v)  # free 1 white, wall 0 black, unknown grey
    ax.imshow(shade.T, origin='lower', cmap='gray', vmin=0.0, vmax=1.0,
              extent=(0.0, v.shape[0] * res, 0.0, v.shape[1] * res), interpolation='nearest')
    ax.plot(poses_grid[:, 0], poses_grid[:, 1], '-', color='tab:blue', lw=0.8, label='path')
    pts, on, out = check['points'], check['on_wall'], check['left_out']
    s = check['structural'] & ~out
    ax.plot(*pts[s & on].T, '.', color='tab:green', ms=2,
            label=f'structural corner within 10 cm of a wall ({int((s & on).sum())})')
    ax.plot(*pts[s & ~on].T, 'x', color='tab:red', ms=4,
            label=f'structural corner off the walls ({int((s & ~on).sum())})')
    ax.plot(*pts[check['structural'] & out].T, '+', color='tab:orange', ms=4,
            label='structural corner near a wall cell the log sees through (left out, '
            f'{int((check["structural"] & out).sum())})')
    both = np.concatenate([pts[s], poses_grid]) if s.any() else poses_grid
    lo, hi = both.min(axis=0) - 1.0, both.max(axis=0) + 1.0
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    _save_plan(fig, ax, title, path)


def plot_place_crops(grid, check: dict, agreement: dict, scan_points: dict, title: str,
                     path: Path, count: int = 4, half: float = 1.5) -> int:
    """Draw the grid around the places off the walls with the most views; return how many.

    ``check``: :func:`landmark_nav.evaluation.occupancy_check.corner_wall_check`'s result;
    ``agreement``: :func:`landmark_nav.evaluation.graph_wall_check.place_scan_agreement`'s;
    ``scan_points``: ``points`` (grid frame) and their ``wall_distance``. One panel per
    place (up to ``count``), ``half`` metres around it: the grid's cells, the run's scan
    points within 10 cm of a wall cell and the others, and the structural corners.
    Nothing is written when no place is off the walls.
    """
    places = [p for p in agreement['places'] if not p['on_wall']][:count]
    if not places:
        return 0
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    v, res = grid.values, grid.resolution
    cols = min(2, len(places))
    rows = (len(places) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.2 * rows), squeeze=False)
    pts, near = scan_points['points'], scan_points['wall_distance'] <= 0.1
    s = check['structural'] & ~check['left_out']
    shade = np.where(v < 0.0, 0.75, v)
    for ax, p in zip(axes.flat, places):
        c = p['centre']
        ax.imshow(shade.T, origin='lower', cmap='gray', vmin=0.0, vmax=1.0,
                  extent=(0.0, v.shape[0] * res, 0.0, v.shape[1] * res),
                  interpolation='nearest')
        box = np.all(np.abs(pts - c) <= half, axis=1)
        ax.plot(*pts[box & near].T, ',', color='tab:blue', label='scan point on a wall')
        ax.plot(*pts[box & ~near].T, ',', color='tab:orange', label='scan point off the walls')
        for m, mk, col, lab in ((s & check['on_wall'], '.', 'tab:green', 'corner on a wall'),
                                (s & ~check['on_wall'], 'x', 'tab:red', 'corner off')):
            q = m & np.all(np.abs(check['points'] - c) <= half, axis=1)
            ax.plot(*check['points'][q].T, mk, color=col, ms=4, label=lab)
        ax.set_xlim(c[0] - half, c[0] + half)
        ax.set_ylim(c[1] - half, c[1] + half)
        ax.set_aspect('equal')
        ax.set_title(f"({c[0]:.1f}, {c[1]:.1f}) {p['views']} views, "
                     f"{'convex' if p['convex'] else 'concave'}\nscan points on a wall: "
                     f"at it {p['at_share']:.2f}, around {p['ring_share']:.2f}", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(places):]:
        ax.set_visible(False)
    axes.flat[0].legend(loc='lower left', fontsize=6, markerscale=3)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return len(places)
