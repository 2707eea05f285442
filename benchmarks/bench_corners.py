"""Time the three corner detectors against cv2.approxPolyDP on the same clusters.

Run from the repository root::

    python benchmarks/bench_corners.py [--scans N] [--repeat R] [--bag DIR]

Scans come from the simulated office run (seed 1): the default 361-beam LMS200-like laser
(180 deg, 0.5 deg) and a 1081-beam laser (270 deg, 0.25 deg); or, with ``--bag DIR``, from
the ``/scan`` of a recorded bag (one table). Each scan is segmented once
(:func:`segment_scan`, timed separately); the detectors and ``cv2.approxPolyDP`` (points as a
float32 contour, epsilon = the split-and-merge threshold, one call per cluster, the
in-process C++ reference) then run on the same clusters. Each scan's time is the best of
``--repeat`` runs; the script prints the median over scans and the ratio to approxPolyDP.
``minus_cosine raw`` is the detector without refinement (eq. 11, shift check, NMS, ``Q_i``).
Targets: minus-cosine <= 1 ms per 1081-beam scan and <= 15x approxPolyDP.
"""

import argparse
import statistics
import sys
from typing import Dict, List

from common import approx_poly, bag_scans, best_ms, LASERS, office_scans
from landmark_nav.laser.corners import CornerParams, detect_corners, METHODS
from landmark_nav.laser.segmentation import segment_scan
import numpy as np


def main(argv=None) -> int:
    """Run the benchmark and print a table per laser."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--scans', type=int, default=200, help='scans per laser')
    ap.add_argument('--repeat', type=int, default=5, help='timing repeats per scan (best)')
    ap.add_argument('--bag', default=None, metavar='DIR',
                    help="a recorded bag's /scan instead of the simulated office scans")
    args = ap.parse_args(argv)
    params = {m: CornerParams(method=m) for m in METHODS}
    params['minus_cosine raw'] = CornerParams(refine=False)  # eq. 11 + shift check only
    eps = params['split_merge'].split_tolerance
    names = [*METHODS, 'minus_cosine raw']
    if args.bag:
        sets = {str(args.bag): bag_scans(args.bag, args.scans)}
    else:
        sets = {name: office_scans(laser, args.scans) for name, laser in LASERS.items()}
    for name, scans in sets.items():
        times: Dict[str, List[float]] = {k: [] for k in ('segment', 'approxPolyDP', *names)}
        found = dict.fromkeys(names, 0)
        n_clusters = []
        for s in scans:
            r = s.ranges.astype(float)
            angles = s.angle_min + s.angle_increment * np.arange(r.size)
            valid = np.isfinite(r)
            clusters = segment_scan(r, angles, valid, s.angle_increment)
            n_clusters.append(len(clusters))
            times['segment'].append(best_ms(
                lambda: segment_scan(r, angles, valid, s.angle_increment), args.repeat))
            times['approxPolyDP'].append(best_ms(lambda: approx_poly(clusters, eps),
                                                 args.repeat))
            for m in names:
                found[m] += len(detect_corners(clusters, params[m]))
                times[m].append(best_ms(lambda: detect_corners(clusters, params[m]),
                                        args.repeat))
        med = {k: statistics.median(v) for k, v in times.items()}
        print(f'{name}: {len(scans)} scans, median {statistics.median(n_clusters)} '
              f'clusters/scan, {len(scans[0].ranges)} beams')
        print(f'  {"step":<16s} {"median ms/scan":>15s} {"x approxPolyDP":>15s} {"corners":>8s}')
        for k in ('segment', 'approxPolyDP', *names):
            ratio = med[k] / med['approxPolyDP']
            extra = f'{found[k]:8d}' if k in found else ''
            print(f'  {k:<16s} {med[k]:15.3f} {ratio:15.1f} {extra}')
        mc = med['minus_cosine']
        ok = mc <= 1.0 and mc <= 15.0 * med['approxPolyDP']
        print(f'  minus_cosine target (<= 1 ms and <= 15x approxPolyDP): '
              f'{"met" if ok else "NOT met"}\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
