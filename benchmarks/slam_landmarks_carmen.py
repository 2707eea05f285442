"""EKF-SLAM on the Carmen logs with corners, lines or both (``landmarks`` parameter).

Run from the repository root (needs ``../shared/data/carmen``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/slam_landmarks_carmen.py [--landmarks corners
        lines both] [--association icnn] [--prune-misses N] [--out DIR] [LOG ...]

Each log is imported with ``landmark_nav import`` defaults (synthetic ``pioneer`` drift,
seed 0) into a temporary directory and evaluated as ``landmark_nav evaluate BAG`` does
(:func:`landmark_nav.evaluation.slam.evaluate_bag`) with the default front end
(:mod:`landmark_nav.slam.frontend`: odometry checks against elapsed time and noise, no
absolute jump limit) and the filter's odometry noise model taken from the bag's stated
drift model (the importer's ``pioneer`` gains ``k_d = 0.05 m/sqrt(m)``, ``k_theta = 0.05
rad/sqrt(m)``, ``k_dtheta = 0.1 rad/sqrt(rad)``); ``--prune-misses`` sets that one filter
parameter on top of the same noise model.

Printed per log and landmark type: filter resets, corner and line landmarks at the end,
the SE(2)-aligned ATE RMSE of EKF-SLAM and of the odometry, the RPE over 1 m (translation
RMSE) of both, the share of steps whose reference position lies inside the filter's 95 %
position ellipse, landmarks pruned, filter ms per scan.
"""

import argparse
import json
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.evaluation.slam import evaluate_bag  # noqa: E402
from landmark_nav.importers.writer import import_log  # noqa: E402
from landmark_nav.slam.ekf_slam import SlamParams  # noqa: E402
from landmark_nav.slam.frontend import odometry_noise_model  # noqa: E402
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402

LOGS = ('aces', 'seattle', 'fhw', 'freiburg-101', 'belgioioso', 'acapulco')


def main() -> int:
    """Import, evaluate, print one line per log and landmark type."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS))
    ap.add_argument('--landmarks', nargs='+', default=['corners', 'lines', 'both'])
    ap.add_argument('--association', default='icnn', choices=['icnn', 'jcbb'])
    ap.add_argument('--prune-misses', type=int, default=None)
    ap.add_argument('--out', default=None, help='keep slam.json and the PNGs here')
    args = ap.parse_args()
    carmen = SHARED_DATA / 'carmen'
    if not carmen.is_dir():
        print(f'missing {carmen}', file=sys.stderr)
        return 1
    prm = None  # evaluate_bag: SlamParams with the bag's stated noise model
    if args.prune_misses is not None:  # the importer's default drift model is 'pioneer'
        prm = SlamParams(odometry=odometry_noise_model('pioneer'),
                         prune_misses=args.prune_misses)
    print('log landmarks resets corners lines ate_m odom_ate_m rpe_m odom_rpe_m ellipse95 '
          'pruned ms')
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.logs:
            bag = Path(tmp) / name
            import_log(carmen / f'{name}-corrected.log.gz', bag)
            for lm in args.landmarks:
                out = None if args.out is None else Path(args.out) / f'{name}_{lm}'
                r = evaluate_bag(bag, args.association, out, progress=False, params=prm,
                                 landmarks=lm)
                row = [name, lm, r['resets'], r['mapped'], r['lines_mapped'],
                       r['ate_se2_rmse'], r['odom_ate_se2_rmse'], r['rpe_trans_rmse'],
                       r['odom_rpe_trans_rmse'], r['ellipse95_share'], r['stats']['pruned'],
                       r['ms_per_scan']]
                print(' '.join(f'{v:.3f}' if isinstance(v, float) else str(v) for v in row),
                      flush=True)
                if out is not None:
                    (out / 'row.json').write_text(json.dumps(row))
    return 0


if __name__ == '__main__':
    sys.exit(main())
