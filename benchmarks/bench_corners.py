"""Time the three corner detectors against cv2.approxPolyDP on the same clusters.

Run from the repository root::

    python benchmarks/bench_corners.py [--scans N] [--repeat R]

Scans come from the simulated office run (seed 1): the default 361-beam LMS200-like laser
(180 deg, 0.5 deg) and a 1081-beam laser (270 deg, 0.25 deg). Each scan is segmented once
(:func:`segment_scan`, timed separately); the detectors and ``cv2.approxPolyDP`` (points as a
float32 contour, epsilon = the split-and-merge threshold, one call per cluster, the
in-process C++ reference) then run on the same clusters. Each scan's time is the best of
``--repeat`` runs; the script prints the median over scans and the ratio to approxPolyDP.
``minus_cosine raw`` is the detector without refinement (eq. 11, shift check, NMS, ``Q_i``).
Targets: minus-cosine <= 1 ms per 1081-beam scan and <= 15x approxPolyDP.
"""

import argparse
import math
from pathlib import Path
import statistics
import sys
import time
from typing import Callable, Dict, List

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402
from landmark_nav.laser.corners import CornerParams, detect_corners, METHODS  # noqa: E402
from landmark_nav.laser.segmentation import Cluster, segment_scan  # noqa: E402
from landmark_nav.sim import run_scenario, ScanSample  # noqa: E402
import numpy as np  # noqa: E402

LASERS = {
    '361 beams (180 deg, 0.5 deg)': {},
    '1081 beams (270 deg, 0.25 deg)': {
        'angle_min': -math.radians(135.0), 'angle_max': math.radians(135.0),
        'angle_increment': math.radians(0.25), 'time_increment': (1.0 / 40.0) / 1440.0,
        'range_max': 30.0},
}


def scans_of(laser: Dict, count: int) -> List[ScanSample]:
    """Return ``count`` scans spread over the office run with this laser configuration."""
    res = run_scenario('office', seed=1, laser=laser or True)
    scans = res.of_type(ScanSample)
    step = max(1, len(scans) // count)
    return scans[::step][:count]


def best_ms(fn: Callable[[], object], repeat: int) -> float:
    """Return the best-of-``repeat`` time of one call of ``fn`` [ms] (per-scan sample)."""
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def approx_poly(clusters: List[Cluster], eps: float) -> int:
    """Run cv2.approxPolyDP on every cluster; return the number of vertices."""
    n = 0
    for c in clusters:
        contour = np.ascontiguousarray(c.points, dtype=np.float32).reshape(-1, 1, 2)
        n += len(cv2.approxPolyDP(contour, eps, False))
    return n


def main() -> None:
    """Run the benchmark and print a table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--scans', type=int, default=200, help='scans per laser')
    ap.add_argument('--repeat', type=int, default=5, help='timing repeats per scan (best)')
    args = ap.parse_args()
    params = {m: CornerParams(method=m) for m in METHODS}
    params['minus_cosine raw'] = CornerParams(refine=False)  # eq. 11 + shift check only
    eps = params['split_merge'].split_tolerance
    names = [*METHODS, 'minus_cosine raw']
    for name, laser in LASERS.items():
        scans = scans_of(laser, args.scans)
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
        print(f'{name}: {len(scans)} office scans, median {statistics.median(n_clusters)} '
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


if __name__ == '__main__':
    main()
