"""The main job: EKF-SLAM on a recorded bag against ground truth, and the odometry drift.

Reads the bag directly (no DDS). Writes into the output directory: ``world_paths.png``,
``summary.txt`` and ``drift.json`` (odometry drift against ``/ground_truth/odom``, scored by
:func:`landmark_nav.evaluation.odometry_drift.bag_odometry_drift`) and the EKF-SLAM
evaluation of :func:`landmark_nav.evaluation.slam.evaluate_bag` with the chapter profile
(``config/ekf_slam_chapter.yaml``, as ``landmark_nav evaluate --params-file``)
(``slam_map.png``, ``slam_errors.png``, ``slam.json``, TUM trajectories) and the viewer file
``view/view.mcap`` (:func:`landmark_nav.evaluation.viewer.write_slam_view`: inputs and
outputs in standard message types for Foxglove / Lichtblick); returns both summaries.
"""

import json
from pathlib import Path
import sys

from landmark_nav.evaluation.odometry_drift import bag_odometry_drift
from landmark_nav.sim.record import load_ground_truth
from landmark_nav.sim.world import World
import numpy as np

#: The EKF-SLAM profile of the demo: the chapter's filter, which the simulator figures of
#: ``bags/office/expected.yaml`` are measured with.
CHAPTER_PROFILE = 'ekf_slam_chapter'


def plot_world_paths(world: World, truth: np.ndarray, odom: np.ndarray, path: Path,
                     title: str) -> None:
    """Draw walls, round obstacles, true corners and the two paths into a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 7), dpi=110)
    for x1, y1, x2, y2 in world.segments:
        ax.plot([x1, x2], [y1, y2], color='0.15', lw=2)
    for cx, cy, r in world.circles:
        ax.add_patch(plt.Circle((cx, cy), r, color='0.3'))
    corners = world.corners().positions
    if len(corners):
        ax.scatter(corners[:, 0], corners[:, 1], marker='s', s=18, color='tab:orange',
                   label=f'true corners ({len(corners)})', zorder=3)
    ax.plot(truth[:, 0], truth[:, 1], color='tab:green', lw=1.5, label='ground truth')
    ax.plot(odom[:, 0], odom[:, 1], color='tab:red', lw=1.2, ls='--', label='odometry')
    ax.plot(truth[0, 0], truth[0, 1], 'k^', label='start')
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc='best', fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def chapter_config(bag):
    """Return the chapter profile's ``ekf_slam`` configuration on ``bag``.

    ``config/ekf_slam_chapter.yaml`` read as ``landmark_nav evaluate --params-file`` reads
    it, with what the bag states (:func:`landmark_nav.evaluation.slam.bag_configuration`).
    """
    from landmark_nav.evaluation.slam import bag_configuration
    from landmark_nav.tools.config_files import config_path
    from landmark_nav.tools.node_parameters import read_params_file
    return bag_configuration(bag, read_params_file(str(config_path(CHAPTER_PROFILE)),
                                                   'ekf_slam'))


def run_demo(bag, out) -> str:
    """Write world_paths.png, summary.txt, drift.json and the SLAM files; return the summary."""
    bag, out = Path(bag), Path(out)
    truth_meta = load_ground_truth(bag)
    common, truth, odom, drift = bag_odometry_drift(bag)
    out.mkdir(parents=True, exist_ok=True)
    name = truth_meta.get('scenario', bag.name)
    plot_world_paths(World.from_dict(truth_meta['world']), truth, odom, out / 'world_paths.png',
                     f'{name} (seed {truth_meta.get("seed")}): ground truth vs odometry')
    robot = truth_meta.get('robot', {})
    lines = [
        f'bag: {bag}',
        f'scenario: {name}, seed {truth_meta.get("seed")}, '
        f'{(common[-1] - common[0]) / 1e9:.1f} s, {len(common)} odometry samples',
        f'simulated calibration factors: k1={robot.get("k1")}, k2={robot.get("k2")}, '
        f'k3={robot.get("k3")}',
        f'path length: {drift["path_length_m"]:.2f} m',
        f'odometry final position error: {drift["final_position_error_m"]:.3f} m '
        f'({drift["final_error_percent_of_distance"]:.2f} % of distance)',
        f'odometry final heading error: {drift["final_heading_error_deg"]:.2f} deg',
        f'odometry max position error: {drift["max_position_error_m"]:.3f} m, '
        f'max heading error: {drift["max_heading_error_deg"]:.2f} deg',
        'drift along the path:',
    ]
    for key, row in drift['along_path'].items():
        lines.append(f'  {key:>4} ({row["distance_m"]:6.2f} m): position error '
                     f'{row["position_error_m"]:.3f} m, heading error '
                     f'{row["heading_error_deg"]:.2f} deg')
    lines.append(f'plot: {out / "world_paths.png"}')
    summary = '\n'.join(lines)
    (out / 'summary.txt').write_text(summary + '\n')
    (out / 'drift.json').write_text(json.dumps(
        {k: v for k, v in drift.items() if k != 'position_error_m'}, indent=2) + '\n')
    from landmark_nav.evaluation.slam import evaluate_bag, format_summary
    slam = format_summary(evaluate_bag(bag, 'icnn', out, progress=sys.stderr.isatty(),
                                       config=chapter_config(bag)))
    from landmark_nav.evaluation.viewer import write_slam_view
    view = write_slam_view(bag, out / 'view', 'icnn', force=True)
    return (summary + '\n\nEKF-SLAM (ICNN):\n' + slam + f'\nviewer file: {view["mcap"]} '
            '(open in Foxglove or Lichtblick; layout viewer/slam_layout.json)')
