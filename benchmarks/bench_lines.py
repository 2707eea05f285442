"""Time the two line extractors against cv2.approxPolyDP on the same clusters.

Run from the repository root::

    python benchmarks/bench_lines.py [--scans N] [--repeat R]

Same scans, clusters and in-run C++ reference as ``bench_corners.py`` (approxPolyDP with
epsilon = the split-and-merge threshold). Targets: split_merge <= 1 ms per 1081-beam scan
and <= 15x approxPolyDP; alfa <= 5 ms.
"""

import argparse
from pathlib import Path
import statistics
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_corners import approx_poly, best_ms, LASERS, scans_of  # noqa: E402
from landmark_nav.laser.lines import extract_lines, LineParams, METHODS  # noqa: E402
from landmark_nav.laser.segmentation import segment_scan  # noqa: E402
import numpy as np  # noqa: E402

TARGETS = {'split_merge': (1.0, 15.0), 'alfa': (5.0, None)}


def main() -> None:
    """Run the benchmark and print a table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--scans', type=int, default=200, help='scans per laser')
    ap.add_argument('--repeat', type=int, default=5, help='timing repeats per scan (best)')
    args = ap.parse_args()
    params = {m: LineParams(method=m) for m in METHODS}
    eps = params['split_merge'].threshold
    for name, laser in LASERS.items():
        scans = scans_of(laser, args.scans)
        times = {k: [] for k in ('approxPolyDP', *METHODS)}
        found = dict.fromkeys(METHODS, 0)
        for s in scans:
            r = s.ranges.astype(float)
            angles = s.angle_min + s.angle_increment * np.arange(r.size)
            clusters = segment_scan(r, angles, np.isfinite(r), s.angle_increment)
            times['approxPolyDP'].append(best_ms(lambda: approx_poly(clusters, eps),
                                                 args.repeat))
            for m in METHODS:
                found[m] += len(extract_lines(clusters, params[m]))
                times[m].append(best_ms(lambda: extract_lines(clusters, params[m]),
                                        args.repeat))
        med = {k: statistics.median(v) for k, v in times.items()}
        print(f'{name}: {len(scans)} office scans')
        print(f'  {"method":<14s} {"median ms/scan":>15s} {"x approxPolyDP":>15s} {"lines":>7s}')
        for k in ('approxPolyDP', *METHODS):
            extra = f'{found[k]:7d}' if k in found else ''
            print(f'  {k:<14s} {med[k]:15.3f} {med[k] / med["approxPolyDP"]:15.1f} {extra}')
        if '1081' in name:
            for m, (ms, ratio) in TARGETS.items():
                print(f'  {m}: <= {ms} ms {"met" if med[m] <= ms else "NOT met"}', end='')
                if ratio is not None:
                    ok = med[m] <= ratio * med['approxPolyDP']
                    print(f', <= {ratio:g}x approxPolyDP {"met" if ok else "NOT met"}', end='')
                print()
        print()


if __name__ == '__main__':
    main()
