"""ICNN against JCBB on the ``ambiguous`` scenario (closely spaced corners, laser blackout).

Run from the repository root::

    python benchmarks/bench_slam_ambiguous.py [--seeds 0-9]

The ``ambiguous`` scenario (:func:`landmark_nav.sim.scenarios.ambiguous_world`): the robot
maps an irregular row of 0.3 m posts whose corners of the same kind are 0.45-0.77 m apart,
then drives a 72 m loop with the laser blind, so that its pose error grows to tens of
centimetres and degrees, and re-observes the row from 2.5 m. For every seed the same
simulated run goes through the filter with the default :class:`SlamParams` once per method:
``ICNN`` (the chapter's: ``association='icnn'``, ``joint_check=False``), ``JCBB`` and
``ICNN+JOINT`` (the filter's default: ICNN whose hypothesis, when jointly incompatible at a
gross-error level, is decided by JCBB) (nothing else differs), and is scored by
:func:`landmark_nav.evaluation.slam.score_run` (wrong associations via the ground-truth corner
ids). Printed per seed: the odometry error accumulated over the blackout (position, heading),
then per method the wrong associations out of all associations, the ATE RMSE over the scans
after the blackout, the mapped landmarks against the true visible corners, duplicated and
ghost landmarks and the filter time. The last line sums the wrong associations.
"""

import argparse
from pathlib import Path
import sys
import time
from typing import Dict, List

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.evaluation.slam import run_slam, score_run  # noqa: E402
from landmark_nav.geometry import wrap_angle  # noqa: E402
from landmark_nav.sim import run_scenario  # noqa: E402
from landmark_nav.slam import SlamParams  # noqa: E402
import numpy as np  # noqa: E402

METHODS = ('icnn', 'jcbb', 'icnn+joint')


def parse_seeds(text: str) -> List[int]:
    """Return the seeds of ``'0-9'`` or ``'1,4,7'``."""
    if '-' in text:
        a, b = text.split('-', 1)
        return list(range(int(a), int(b) + 1))
    return [int(v) for v in text.split(',')]


def run_seed(seed: int) -> Dict[str, object]:
    """Simulate one seed and run both association methods on the same data."""
    res = run_scenario('ambiguous', seed)
    (b0, b1), = res.blackout
    k0, k1 = [int(np.searchsorted(res.trajectory.stamps_ns, t)) for t in (b0, b1)]
    drift = (res.odometry.poses[k1] - res.odometry.poses[k0]) - (
        res.trajectory.poses[k1] - res.trajectory.poses[k0])
    out: Dict[str, object] = {
        'seed': seed, 'drift_m': float(np.hypot(drift[0], drift[1])),
        'drift_deg': float(np.degrees(wrap_angle(drift[2])))}
    for method in METHODS:
        params = SlamParams(association='jcbb' if method == 'jcbb' else 'icnn',
                            joint_check=method == 'icnn+joint')
        tic = time.perf_counter()
        run = run_slam(res, params)
        seconds = time.perf_counter() - tic
        score = score_run(res, run, params)
        after = run.stamps >= b1
        err = np.hypot(*(run.poses[after, :2] - run.truth[after, :2]).T)
        out[method] = {'score': score, 'ate_after': float(np.sqrt(np.mean(err ** 2))),
                       'seconds': seconds}
    return out


def main() -> None:
    """Run the comparison and print a table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', default='0-9', help="e.g. '0-9' or '1,4,7'")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    head = (f'{"seed":>4} {"blackout drift":>15} | ' + ' | '.join(
        f'{m.upper()}: {"wrong":>9} {"ATE after":>9} {"mapped":>6} {"dup":>3} {"ghost":>5} '
        f'{"s":>4}' for m in METHODS))
    print('ambiguous scenario, default SlamParams, only the association differs')
    print(head)
    total = dict.fromkeys(METHODS, 0)
    for seed in seeds:
        r = run_seed(seed)
        cells = []
        for m in METHODS:
            s, sc = r[m], r[m]['score']
            total[m] += sc.wrong_associations
            cells.append(f'{m.upper()}: {sc.wrong_associations:>4}/{sc.associations:<4} '
                         f'{100 * s["ate_after"]:>6.1f} cm {sc.mapped:>3}/{sc.true_visible:<2} '
                         f'{sc.duplicates:>3} {sc.ghost_landmarks:>5} {s["seconds"]:>4.1f}')
        print(f'{seed:>4} {100 * r["drift_m"]:>6.1f} cm {r["drift_deg"]:>+5.1f} deg | '
              + ' | '.join(cells), flush=True)
    print('wrong associations summed over seeds ' + ', '.join(
        f'{m.upper()} {total[m]}' for m in METHODS)
        + f' ({len(seeds)} seeds; JCBB {"<" if total["jcbb"] < total["icnn"] else ">="} ICNN)')


if __name__ == '__main__':
    main()
