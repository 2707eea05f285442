"""EKF-SLAM with the shipped defaults on real logs: ``import`` then ``evaluate`` with no flags.

Run from the repository root (needs ``../shared/data/carmen``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/carmen_defaults.py [LOG ...]
        [--params-file YAML ...]

For each log (default aces, seattle, fhw) this does what a user does on a fresh clone,
``landmark_nav import LOG --out A && landmark_nav evaluate A`` (the same entry points, in
this process), and prints the unaligned ATE RMSE of the filter and of the odometry and
their ratio, the SE(2)-aligned ATE, the filter resets, the RPE over 1 m, the share of
steps with the reference inside the 95 % position ellipse and the time per step. The
target (issue 37): ATE at most a fifth of the odometry's, no reset; the exit status is 1
when a log misses it. ``--params-file`` runs ``evaluate --params-file`` instead (e.g.
``config/ekf_slam_chapter.yaml``: the chapter's filter, the defaults before).
"""

import argparse
import json
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.importers import import_log  # noqa: E402
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
from landmark_nav.tools.cli import main as cli_main  # noqa: E402

LOGS = ('aces', 'seattle', 'fhw')


def run(log: str, work: Path, params_files: list) -> dict:
    """Import one log with the default options, evaluate it; return its slam.json."""
    bag, out = work / log, work / f'{log}-out'
    import_log(SHARED_DATA / 'carmen' / f'{log}-corrected.log.gz', bag)
    files = [a for f in params_files for a in ('--params-file', f)]
    if cli_main(['evaluate', str(bag), '--no-progress', '--out', str(out)] + files) != 0:
        raise SystemExit(f'evaluate {bag} failed')
    return json.loads((out / 'slam.json').read_text())


def main() -> int:
    """Run the logs, print one row each; exit 1 if a log misses the target."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS))
    ap.add_argument('--params-file', action='append', default=[])
    args = ap.parse_args()
    missed = []
    print('log | ATE filter / odometry [m] (ratio) | SE(2) ATE filter / odometry [m] | resets '
          '| RPE 1 m filter / odometry [cm, deg] | 95 % ellipse | ms per step')
    with tempfile.TemporaryDirectory() as tmp:
        for log in args.logs:
            r = run(log, Path(tmp), args.params_file)
            ratio = r['ate_rmse'] / r['odom_ate_rmse']
            share = r.get('ellipse95_share')
            print(f"{log} | {r['ate_rmse']:.2f} / {r['odom_ate_rmse']:.2f} ({ratio:.3f}) | "
                  f"{r['ate_se2_rmse']:.2f} / {r['odom_ate_se2_rmse']:.2f} | {r['resets']} | "
                  f"{100 * r['rpe_trans_rmse']:.1f} / {r['rpe_rot_rmse_deg']:.2f}, "
                  f"{100 * r['odom_rpe_trans_rmse']:.1f} / {r['odom_rpe_rot_rmse_deg']:.2f} | "
                  f"{'n/a' if share is None else f'{100 * share:.1f} %'} | "
                  f"{r['ms_per_step_total']:.1f}", flush=True)
            if ratio > 0.2 or r['resets']:
                missed.append(log)
    if missed:
        print(f'target missed (ATE <= odometry / 5, 0 resets): {", ".join(missed)}')
    return 1 if missed else 0


if __name__ == '__main__':
    sys.exit(main())
