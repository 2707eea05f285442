"""Line extractors' sigma d rho against the Cramer-Rao floor over office seeds, by sweep rotation.

Run from the repository root::

    python benchmarks/line_floor_seeds.py [--seeds 1-6] [--every 4] [--bags DIR]

Simulates ``landmark_nav simulate office --seed S`` (into ``--bags``, kept between runs;
a temporary folder by default), scores both line methods as ``landmark_nav
evaluate-features BAG --every 4`` does (:func:`landmark_nav.evaluation.feature_bags.
evaluate_features`) and prints per seed and method sigma d rho, its floor (each matched
wall's error drawn from its Cramer-Rao bound, :func:`landmark_nav.evaluation.features.
line_crlb`) and their ratio; then the same over all seeds, split by how far the laser
turned during the scan's sweep (the extractors fit the beams of one sweep as if taken
from one pose; the floor assumes that too), and the errors over each matched line's own
sigma rho (its eq.-7 covariance) against over the wall's bound (all its beams).
"""

import argparse
import math
from pathlib import Path
import sys
import tempfile

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from landmark_nav.evaluation import feature_bags, features  # noqa: E402
from landmark_nav.tools.cli import main as cli_main  # noqa: E402
import numpy as np  # noqa: E402

TURN_BINS_DEG = (0.0, 0.1, 0.3, 1.0)


def seed_range(text: str) -> list:
    """Parse ``1-6`` or ``1,3,5``."""
    if '-' in text:
        lo, hi = text.split('-')
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(',')]


def score_seed(bag: Path, every: int) -> dict:
    """Return {method: records} of the matched walls.

    A record: d rho, floor variance, turn during the sweep [deg], the matched line's own
    var(rho) and the wall's uncut bound.
    """
    records = {}
    turn = {}
    score_scan, score_lines = feature_bags.score_scan, features.score_lines

    def scan_hook(run, world, sensor_pose_at, scan, **kw):
        n = len(scan.ranges)
        ends = np.array([scan.stamp_ns, scan.stamp_ns + int(n * scan.time_increment * 1e9)])
        pose = np.reshape(sensor_pose_at(ends), (2, 3))
        turn['deg'] = abs(math.degrees(math.remainder(pose[1, 2] - pose[0, 2], 2 * math.pi)))
        return score_scan(run, world, sensor_pose_at, scan, **kw)

    def lines_hook(score, lines, truth, **kw):
        k = len(score.d_rho)
        score_lines(score, lines, truth, **kw)
        rows = records.setdefault(id(score), [])
        turns = [turn['deg']] * (len(score.d_rho) - k)
        rows += list(zip(score.d_rho[k:], score.floor_rho[k:], turns, score.own_rho[k:],
                         score.bound_rho[k:]))

    feature_bags.score_scan, features.score_lines = scan_hook, lines_hook
    try:
        result = feature_bags.evaluate_features(bag, corner_methods=(), every=every)
    finally:
        feature_bags.score_scan, features.score_lines = score_scan, score_lines
    # The LineScore objects are made per method in method order.
    return {m: np.array(rows) for m, rows in zip(result['lines'], records.values())}


def ratio_row(rows: np.ndarray) -> str:
    """Return 'sigma / floor = ratio (n)' of some records."""
    sigma = float(np.std(rows[:, 0]))
    floor = math.sqrt(float(np.mean(rows[:, 1])))
    return f'{100 * sigma:.3f} / {100 * floor:.3f} cm = {sigma / floor:.3f} ({len(rows)})'


def normalised_row(rows: np.ndarray) -> str:
    """Std of d rho over the matched line's own sigma and over the wall's bound."""
    own = float(np.std(rows[:, 0] / np.sqrt(rows[:, 3])))
    bound = float(np.std(rows[:, 0] / np.sqrt(rows[:, 4])))
    share = float(np.mean(rows[:, 3] >= 1.5 * rows[:, 4]))
    return (f"d rho / own sigma: std {own:.3f}; / the wall's bound: std {bound:.3f}; "
            f'own variance >= 1.5 x the bound: {100 * share:.1f} %')


def main() -> None:
    """Simulate, score and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', default='1-6')
    ap.add_argument('--every', type=int, default=4)
    ap.add_argument('--bags', help='folder for the simulated bags (kept); default temporary')
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.bags or tmp)
        folder.mkdir(parents=True, exist_ok=True)
        pooled, ratios = {}, {}
        for seed in seed_range(args.seeds):
            bag = folder / f'office_seed{seed}'
            if not bag.exists():
                cli_main(['simulate', 'office', '--seed', str(seed), '--out', str(bag)])
            for m, rows in score_seed(bag, args.every).items():
                print(f'seed {seed} {m:12s} sigma d rho / floor: {ratio_row(rows)}')
                print(f'    {normalised_row(rows)}')
                pooled.setdefault(m, []).append(rows)
                ratios.setdefault(m, []).append(
                    float(np.std(rows[:, 0])) / math.sqrt(float(np.mean(rows[:, 1]))))
        for m, parts in pooled.items():
            rows = np.vstack(parts)
            print(f'{m}: ratio mean over seeds {np.mean(ratios[m]):.3f}, worst '
                  f'{max(ratios[m]):.3f}; pooled {ratio_row(rows)}')
            bins = TURN_BINS_DEG + (math.inf,)
            for lo, hi in zip(bins[:-1], bins[1:]):
                sel = (rows[:, 2] >= lo) & (rows[:, 2] < hi)
                if sel.any():
                    print(f'   laser turned {lo:.1f}-{hi:.1f} deg during the sweep: '
                          f'{ratio_row(rows[sel])}')


if __name__ == '__main__':
    main()
