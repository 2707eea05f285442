"""Upper bound on the share of each Radish scan that any line extractor could explain.

Run from the repository root (needs ``../shared/data/carmen``)::

    python benchmarks/radish_line_bound.py [--window K] [--rmse M]

A valid return counts as explainable when it belongs to some window of ``K`` consecutive
valid returns (beam order) whose total-least-squares line has an RMSE <= ``M``. The windows
may overlap and need not form consistent lines, and no minimum length applies, so no line
extractor with lines of at least ``K`` points and that RMSE can explain more. Prints, per
log, the mean and worst scan and how many scans stay under 85 %.
"""

import argparse
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.importers.carmen import read_carmen_scans  # noqa: E402
from landmark_nav.laser.line_extraction.tls_fit import _prefix5, _sse  # noqa: E402
from landmark_nav.testing import shared_data  # noqa: E402
import numpy as np  # noqa: E402


def window_rmse(x: np.ndarray, y: np.ndarray, k: int) -> np.ndarray:
    """Return the TLS RMSE of every window of k consecutive points."""
    lo = np.arange(x.size - k + 1)
    return np.sqrt(_sse(_prefix5(x, y), lo, lo + k - 1) / k)


def coverage(ranges: np.ndarray, angles: np.ndarray, k: int, rmse: float) -> float:
    """Return the explainable share of the valid returns of one scan."""
    valid = np.isfinite(ranges) & (ranges > 0)
    r, a = ranges[valid], angles[valid]
    if r.size < k:
        return 0.0
    x, y = r * np.cos(a), r * np.sin(a)
    x, y = x - x.mean(), y - y.mean()
    good = window_rmse(x, y, k) <= rmse
    covered = np.zeros(r.size + 1, dtype=np.int64)
    starts = np.flatnonzero(good)
    np.add.at(covered, starts, 1)
    np.add.at(covered, starts + k, -1)
    return float(np.count_nonzero(np.cumsum(covered)[:-1]) / r.size)


def main() -> None:
    """Print the bound for both logs."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--window', type=int, nargs='+', default=[4, 5, 8],
                    help='points per window (default 4 5 8; 8 = LineParams.min_points)')
    ap.add_argument('--rmse', type=float, default=0.03, help='largest window RMSE [m]')
    args = ap.parse_args()
    for name in ('aces-corrected.log.gz', 'seattle-corrected.log.gz'):
        try:
            path = shared_data('carmen', name)
        except FileNotFoundError as e:
            print(e)
            continue
        scans = list(read_carmen_scans(path))
        for k in args.window:
            share = np.array([coverage(s.ranges, s.angles, k, args.rmse) for s in scans])
            print(f'{name}: {k}-point windows, RMSE <= {100 * args.rmse:g} cm: explainable '
                  f'mean {share.mean():.3f}, worst scan {share.min():.3f}, scans under 85 %: '
                  f'{int((share < 0.85).sum())} of {share.size}')


if __name__ == '__main__':
    main()
