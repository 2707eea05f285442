"""EKF-SLAM on the Carmen logs with corners, lines or both (``landmarks`` parameter).

Run from the repository root (needs ``../shared/data/carmen``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/slam_landmarks_carmen.py [--landmarks corners
        lines both] [--association icnn] [--prune-misses N] [--seed S ...]
        [--line-floor M] [--line-residual-factor K] [--reject-ambiguous]
        [--position-floor M] [--jacobians J] [--joint-probability P]
        [--out DIR] [LOG ...]

Each log is imported with ``landmark_nav import`` defaults (synthetic ``pioneer`` drift,
seed 0; ``--seed`` other drift draws, one row per seed) into a temporary directory and
evaluated as ``landmark_nav evaluate BAG`` does
(:func:`landmark_nav.evaluation.slam.evaluate_bag`) with the default front end
(:mod:`landmark_nav.slam.frontend`: odometry checks against elapsed time and noise, no
absolute jump limit) and the filter's odometry noise model taken from the bag's stated
drift model (the importer's ``pioneer`` gains ``k_d = 0.05 m/sqrt(m)``, ``k_theta = 0.05
rad/sqrt(m)``, ``k_dtheta = 0.1 rad/sqrt(rad)``); ``--prune-misses``, ``--line-floor``,
``--line-residual-factor``, ``--reject-ambiguous``, ``--position-floor``, ``--jacobians``
and ``--joint-probability`` set those :class:`SlamParams` fields on top of the same noise
model (the consistency options of :mod:`landmark_nav.slam.ekf_slam`).

Printed per log and landmark type: filter resets, corner and line landmarks at the end,
the SE(2)-aligned ATE RMSE of EKF-SLAM and of the odometry and their ratio (issue 14 asks
<= 0.2), the RPE over 1 m (translation RMSE) of both and their ratio (asks <= 1), the share
of steps whose reference position lies inside the filter's 95 % position ellipse (asks
>= 0.8), landmarks pruned, filter ms per scan.
"""

import argparse
import json
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.evaluation.slam import evaluate_bag  # noqa: E402
from landmark_nav.importers.writer import import_log  # noqa: E402
from landmark_nav.slam.ekf_slam import JACOBIANS, SlamParams  # noqa: E402
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
    ap.add_argument('--seed', type=int, nargs='+', default=[0],
                    help='drift seeds of the import (default 0, the importer default)')
    ap.add_argument('--line-floor', type=float, default=None)
    ap.add_argument('--line-residual-factor', type=float, default=None)
    ap.add_argument('--reject-ambiguous', action='store_true', default=None)
    ap.add_argument('--position-floor', type=float, default=None)
    ap.add_argument('--jacobians', default=None, choices=JACOBIANS)
    ap.add_argument('--joint-probability', type=float, default=None)
    ap.add_argument('--out', default=None, help='keep slam.json and the PNGs here')
    args = ap.parse_args()
    carmen = SHARED_DATA / 'carmen'
    if not carmen.is_dir():
        print(f'missing {carmen}', file=sys.stderr)
        return 1
    prm = None  # evaluate_bag: SlamParams with the bag's stated noise model
    given = {'prune_misses': args.prune_misses, 'line_floor': args.line_floor,
             'line_residual_factor': args.line_residual_factor,
             'reject_ambiguous': args.reject_ambiguous,
             'position_floor': args.position_floor,
             'jacobians': args.jacobians, 'joint_probability': args.joint_probability}
    extra = {k: v for k, v in given.items() if v is not None}
    if extra:  # the importer's default drift model is 'pioneer'
        prm = SlamParams(odometry=odometry_noise_model('pioneer'), **extra)
    print('log seed landmarks resets corners lines ate_m odom_ate_m ate_ratio rpe_m odom_rpe_m '
          'rpe_ratio ellipse95 pruned ms')
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.logs:
            for seed in args.seed:
                bag = Path(tmp) / f'{name}_{seed}'
                import_log(carmen / f'{name}-corrected.log.gz', bag, seed=seed)
                for lm in args.landmarks:
                    out = (None if args.out is None
                           else Path(args.out) / f'{name}_{seed}_{lm}')
                    r = evaluate_bag(bag, args.association, out, progress=False, params=prm,
                                     landmarks=lm)
                    ate, odo_ate = r['ate_se2_rmse'], r['odom_ate_se2_rmse']
                    rpe, odo_rpe = r['rpe_trans_rmse'], r['odom_rpe_trans_rmse']
                    row = [name, seed, lm, r['resets'], r['mapped'], r['lines_mapped'], ate,
                           odo_ate, ate / odo_ate, rpe, odo_rpe, rpe / odo_rpe,
                           r['ellipse95_share'], r['stats']['pruned'], r['ms_per_scan']]
                    print(' '.join(f'{v:.3f}' if isinstance(v, float) else str(v)
                                   for v in row), flush=True)
                    if out is not None:
                        (out / 'row.json').write_text(json.dumps(row))
    return 0


if __name__ == '__main__':
    sys.exit(main())
