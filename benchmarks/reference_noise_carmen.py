"""How precise the Carmen logs' reference poses are, told by the scans alone.

Run from the repository root (needs ``../shared/data/carmen``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/reference_noise_carmen.py [--scans 900]
        [--cache DIR] [LOG ...]

The RPE over 1 m on these logs is about one step between scans, and issue 14 compares the
filter's with that of the drifted odometry, which is built on the reference's own
increments and so carries none of the reference's errors. This benchmark puts a size on
those errors without trusting either side:

- *ICP precision, reference-free*: for each triple of consecutive scans ``k, k+1, k+2``
  (:func:`landmark_nav.slam.scan_matching.base_motion`, the reference's motion as the
  guess), the motions ``a = k->k+1``, ``b = k+1->k+2`` and ``c = k->k+2`` close to
  ``(a (+) b) (-) c = 0``; with independent errors of the same size each of the three
  carries ``1/sqrt(3)`` of the closure's spread. Printed robustly (1.4826 MAD), x / y /
  heading of the base.
- *ICP against the reference*: ``a`` minus the reference's increment, along and across the
  motion and in heading (robust), and the lag-1 correlation of those differences over
  consecutive steps. Per-pose (white) noise of std ``e`` in the reference gives increment
  differences of variance ``2 e^2 + i^2`` (``i`` the ICP's own) and a lag-1 covariance of
  ``-e^2``: the printed ``reference per-pose std`` is ``sqrt(-cov_1)`` (differences
  beyond 5 robust stds left out), and ``i`` what remains.

Same import as ``landmark_nav import`` (the drift does not enter: every motion here is
from the scans or the reference). Triples with a failed ICP are skipped. Errors common to
all three matchings (the scene's structure) do not show in the closure, so the ICP
precision is a lower bound.
"""

import argparse
import math
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from landmark_nav.evaluation.bags import load_bag  # noqa: E402
from landmark_nav.geometry import compose, relative, wrap_angle  # noqa: E402
from landmark_nav.importers.writer import import_log  # noqa: E402
from landmark_nav.sim import ScanSample  # noqa: E402
from landmark_nav.slam.scan_matching import base_motion  # noqa: E402
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
import numpy as np  # noqa: E402
from scan_matching_carmen import laser_points, LOGS  # noqa: E402

MAD = 1.4826


def robust_std(x: np.ndarray) -> np.ndarray:
    """Return 1.4826 times the median absolute deviation, per column."""
    return MAD * np.median(np.abs(x - np.median(x, axis=0)), axis=0)


def along_across(d: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """Return ``d`` (x, y, heading) with its translation along and across ``motion``."""
    h = math.atan2(motion[1], motion[0]) if math.hypot(motion[0], motion[1]) > 0.05 else 0.0
    c, s = math.cos(h), math.sin(h)
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])


def triples(scenario, max_scans: int) -> tuple:
    """Return ``(closures, differences)``: (K, 3) each, for the triples whose ICPs all ran."""
    mount = np.asarray(scenario.laser.mount, dtype=float)
    scans = scenario.of_type(ScanSample)[:max_scans]
    truth = scenario.truth_at(np.array([s.stamp_ns for s in scans], dtype=np.int64))
    points = [laser_points(s) for s in scans]
    closures, differences = [], []
    for k in range(len(scans) - 2):
        r1 = relative(truth[k], truth[k + 1])
        found = [base_motion(points[i], points[j], relative(truth[i], truth[j]), mount)
                 for i, j in ((k, k + 1), (k + 1, k + 2), (k, k + 2))]
        if any(f is None for f in found):
            continue
        a, b, c = (f[0] for f in found)
        closure = relative(compose(a, b), c)
        closure[2] = wrap_angle(closure[2])
        d = a - r1
        d[2] = wrap_angle(d[2])
        closures.append(closure)
        differences.append(along_across(d, r1))
    return np.array(closures).reshape(-1, 3), np.array(differences).reshape(-1, 3)


def reference_std(differences: np.ndarray) -> tuple:
    """Per-pose std of the reference and the ICP's own, from the lag-1 covariance."""
    keep = np.all(np.abs(differences - np.median(differences, axis=0))
                  <= 5.0 * robust_std(differences), axis=1)
    keep = keep[:-1] & keep[1:]
    x0, x1 = differences[:-1][keep], differences[1:][keep]
    x0, x1 = x0 - x0.mean(axis=0), x1 - x1.mean(axis=0)
    var = 0.5 * (np.mean(x0 ** 2, axis=0) + np.mean(x1 ** 2, axis=0))
    cov1 = np.mean(x0 * x1, axis=0)
    e2 = np.maximum(-cov1, 0.0)
    return np.sqrt(e2), np.sqrt(np.maximum(var - 2.0 * e2, 0.0)), cov1 / var


def main() -> int:
    """Parse, run each log, print one line per log."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS))
    ap.add_argument('--scans', type=int, default=900, help='first scans used per log')
    ap.add_argument('--cache', default=None, help='keep the imported bags here')
    args = ap.parse_args()
    if not (SHARED_DATA / 'carmen').is_dir():
        print(f'missing {SHARED_DATA / "carmen"}', file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(args.cache or tmp)
        print('log | triples | ICP closure per step x, y [cm], heading [deg] | ICP - '
              'reference along, across [cm], heading [deg] (lag-1 corr.) | reference '
              'per-pose std along, across [cm], heading [deg] | ICP own std (same)')
        for name in args.logs:
            bag = cache / f'{name}-0'
            if not (bag / 'metadata.yaml').is_file():
                import_log(SHARED_DATA / 'carmen' / f'{name}-corrected.log.gz', bag, seed=0,
                           force=True)
            closures, diffs = triples(load_bag(bag, require_reference=False), args.scans)
            cl = robust_std(closures) / math.sqrt(3.0)
            di = robust_std(diffs)
            ref, own, rho = reference_std(diffs)
            print(f'{name} | {len(diffs)} | {100 * cl[0]:.2f}, {100 * cl[1]:.2f}, '
                  f'{math.degrees(cl[2]):.3f} | {100 * di[0]:.2f} ({rho[0]:+.2f}), '
                  f'{100 * di[1]:.2f} ({rho[1]:+.2f}), {math.degrees(di[2]):.3f} '
                  f'({rho[2]:+.2f}) | {100 * ref[0]:.2f}, {100 * ref[1]:.2f}, '
                  f'{math.degrees(ref[2]):.3f} | {100 * own[0]:.2f}, {100 * own[1]:.2f}, '
                  f'{math.degrees(own[2]):.3f}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
