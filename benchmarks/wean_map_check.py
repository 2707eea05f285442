"""EKF-SLAM on the CMU Wean logs judged on the building's grid, with why landmarks miss.

Run from the repository root (needs ``../shared/data/wean``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/wean_map_check.py [--landmarks both]
        [--establish-hits N] [--odometry-scale S] [--set NAME=VALUE ...] [LOG ...]

Each log (default ``robotdata1 robotdata2 robotdata5``) is imported with ``landmark_nav
import`` defaults (raw odometry) into a temporary directory and run as the test
``test_evaluate_imported_wean_log_without_reference`` does (the bag's stated odometry
noise, the laser's stated noise); :func:`landmark_nav.evaluation.occupancy_check.check_run`
aligns the result to ``wean.dat`` and :func:`~landmark_nav.evaluation.occupancy_check.
landmark_diagnosis` says why each corner landmark is off the walls. Printed per log:
corner landmarks, the share within 10 cm of a wall cell (issue 14 asks >= 0.9), poses in
wall / unknown cells (asks 0), the share of scan end points near a wall with the filter's
and with the odometry's poses, and the count per category (``on_wall``, ``moved``,
``few_views``, ``off_grid``), and for the poses in wall cells
(:func:`~landmark_nav.evaluation.occupancy_check.wall_pose_diagnosis`) the deepest such
cell's depth into its wall region [m] (0.1: all at the region's edge), the median number
of the log's scans that see through those cells, and the same median over every wall cell
any scan sees through (a cell that many of the log's scans see through was free in this
run: the grid holds something that was not there). ``--establish-hits`` sets
``SlamParams.establish_hits``;
``--odometry-scale S`` multiplies the raw odometry's translations by S before the filter (is
the odometry's scale wrong? the grid says which scale fits). ``--set NAME=VALUE``
(repeatable) any other field of ``SlamParams`` or ``FrontendParams``
(the value read as a Python literal, e.g. ``--set jacobians="'observability_gain'" --set
spurious_limit=0.05 --set scan_matching=True``).
A log whose odometry the front end had to bridge (``robotdata5``: two runs) gets one more
line per part (``name#k``, :func:`~landmark_nav.evaluation.occupancy_check.run_segments`:
each part aligned on its own).
"""

import argparse
import ast
from collections import Counter
from dataclasses import replace
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_node_cpu import split_frontend  # noqa: E402
from landmark_nav.evaluation.bags import load_bag  # noqa: E402
from landmark_nav.evaluation.occupancy_check import (check_run, landmark_diagnosis,  # noqa: E402
                                                     load_occupancy_grid, run_segments,
                                                     wall_pose_diagnosis)
from landmark_nav.evaluation.slam import bag_odometry_noise, run_slam  # noqa: E402
from landmark_nav.importers.writer import import_log  # noqa: E402
from landmark_nav.laser.corners import CornerParams  # noqa: E402
from landmark_nav.sim.scenarios import OdometrySample  # noqa: E402
from landmark_nav.slam.ekf_slam import SlamParams  # noqa: E402
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
import numpy as np  # noqa: E402

LOGS = ('robotdata1', 'robotdata2', 'robotdata5')
CATEGORIES = ('on_wall', 'moved', 'few_views', 'off_grid')


def scale_odometry(scenario, factor: float) -> None:
    """Scale the odometry's positions (so every increment's translation) in place."""
    for i, e in enumerate(scenario.events):
        if type(e) is OdometrySample:
            pose = np.array(e.pose, dtype=float)
            pose[:2] *= factor
            twist = np.array(e.twist, dtype=float)
            twist[:-1] *= factor  # linear part; the last component is the turn rate
            scenario.events[i] = replace(e, pose=pose, twist=twist)


def main() -> int:
    """Import, run, check, print one line per log."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS))
    ap.add_argument('--landmarks', default='both', choices=['corners', 'lines', 'both'])
    ap.add_argument('--establish-hits', type=int, default=0)
    ap.add_argument('--set', action='append', default=[], metavar='NAME=VALUE')
    ap.add_argument('--odometry-scale', type=float, default=1.0,
                    help='scale the raw odometry translations before the filter (a test of '
                         'the odometry scale against the grid; default 1)')
    args = ap.parse_args()
    extra = {}
    for item in args.set:
        key, _, value = item.partition('=')
        extra[key] = ast.literal_eval(value)
    extra, frontend = split_frontend(extra)
    wean = SHARED_DATA / 'wean'
    if not wean.is_dir():
        print(f'missing {wean}', file=sys.stderr)
        return 1
    grid = load_occupancy_grid(wean / 'wean.dat.gz')
    print('log corners share_10cm poses_in_wall poses_unknown points_slam points_odom '
          + ' '.join(CATEGORIES) + ' retired wall_depth_max wall_scans_median '
          'wall_cells_scans_median')
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.logs:
            bag = Path(tmp) / name
            import_log(wean / f'{name}.log.gz', bag)
            sc = load_bag(bag, require_reference=False)
            if args.odometry_scale != 1.0:
                scale_odometry(sc, args.odometry_scale)
            prm = SlamParams(odometry=bag_odometry_noise(sc)[0],
                             establish_hits=args.establish_hits, **extra)
            run = run_slam(sc, prm, CornerParams(sigma_r=sc.laser.sigma_range,
                                                 sigma_phi=sc.laser.sigma_angle),
                           landmarks=args.landmarks, frontend=frontend)
            parts = run_segments(run)
            named = [(name, run)] + ([(f'{name}#{k}', p) for k, p in enumerate(parts)]
                                     if len(parts) > 1 else [])
            for label, part in named:
                if part.landmarks.shape[0] == 0:
                    print(f'{label}: no corner landmark')
                    continue
                fit = check_run(grid, sc, part)
                s = fit['slam']
                diag = landmark_diagnosis(grid, part, s['transform'],
                                          confirm_hits=prm.confirm_hits)
                count = Counter(diag['category'].tolist())
                wall = wall_pose_diagnosis(grid, sc, part, s['transform'])
                depth = f"{wall['depth'].max():.1f}" if wall['steps'].size else '-'
                seen = f"{np.median(wall['crossings']):.0f}" if wall['steps'].size else '-'
                cells = (f"{np.median(wall['wall_crossings']):.0f}"
                         if wall['wall_crossings'].size else '-')
                print(f'{label} {s["landmarks"]} {s["landmark_share"]:.3f} '
                      f'{s["poses_in_wall"]} {s["poses_unknown"]} {s["point_share"]:.3f} '
                      f'{fit["odometry"]["point_share"]:.3f} '
                      + ' '.join(str(count.get(c, 0)) for c in CATEGORIES)
                      + f' {run.stats.get("retired", 0)} {depth} {seen} {cells}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
