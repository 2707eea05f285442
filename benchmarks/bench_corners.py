"""Time the three corner detectors against cv2.approxPolyDP on the same clusters.

Run from the repository root::

    python benchmarks/bench_corners.py [--scans N] [--repeat R] [--bag DIR]
    python benchmarks/bench_corners.py --bias [--sigma-r S] [--step-deg D]

Scans come from the simulated office run (seed 1): the default 361-beam LMS200-like laser
(180 deg, 0.5 deg) and a 1081-beam laser (270 deg, 0.25 deg); or, with ``--bag DIR``, from
the ``/scan`` of a recorded bag (one table). Each scan is segmented once
(:func:`segment_scan`, timed separately); the detectors and ``cv2.approxPolyDP`` (points as a
float32 contour, epsilon = the split-and-merge threshold, one call per cluster, the
in-process C++ reference) then run on the same clusters. Each scan's time is the best of
``--repeat`` runs; the script prints the median over scans and the ratio to approxPolyDP.
``minus_cosine raw`` is the detector without refinement (eq. 11, shift check, NMS, ``Q_i``).
Targets: minus-cosine <= 1 ms per 1081-beam scan and <= 15x approxPolyDP.

``--bias``: not timing but where the default detector puts convex and concave corners,
against the simulator's true corners: a corridor wall with a door recess (0.15 m and 0.3 m
deep: convex jambs, concave back corners) seen from 15 places along lines 1, 2, 3 and 5 m
in front, 5 noisy scans each, and a 1 m square box in a room seen from all around at 1.5 -
6 m. Each detection within 0.3 m of a true corner gives its error along the true corner's
bisector (positive: toward free space, i.e. toward the sensor) and across it; printed per
class (convex / concave, both arms at least ``STRUCTURAL_ARM`` long and
``STRUCTURAL_BEAM_STEPS`` wide or not), by range (0-2, 2-4, 4-8 m, all) and by the angle
between the bisector and the sensor (0-20, 20-45, 45-90 deg): the count, the mean and std
along, the mean across, the RMS, and the largest error toward the sensor.
"""

import argparse
import statistics
import sys
from typing import Dict, List

from common import approx_poly, bag_scans, best_ms, LASERS, office_scans
from landmark_nav.laser.corners import CornerParams, detect_corners, extract_corners, METHODS
from landmark_nav.laser.segmentation import segment_scan
from landmark_nav.sim import World
import numpy as np


def _bias_rows(world, poses, step, sigma_r, rng, repeats) -> np.ndarray:
    """Rows (convex, long-armed, range, along, across, view) of detections near true corners.

    ``view``: the angle between the corner's bisector and its direction to the sensor [deg].
    """
    truth = world.corners()
    n = int(round(np.pi / step)) + 1
    local = -0.5 * np.pi + step * np.arange(n)
    rows = []
    for px, py, yaw in poses:
        true_r = world.raycast(np.array([[px, py]]), local + yaw, max_range=30.0).ranges
        c, s = np.cos(yaw), np.sin(yaw)
        for _ in range(repeats):
            r = true_r + rng.normal(0.0, sigma_r, n)
            for f in extract_corners(r, local, np.isfinite(r), step,
                                     CornerParams(sigma_r=sigma_r)):
                p = np.array([px + c * f.position[0] - s * f.position[1],
                              py + s * f.position[0] + c * f.position[1]])
                d = np.hypot(*(truth.positions - p).T)
                j = int(np.argmin(d))
                if d[j] > 0.3:
                    continue
                b, e = truth.bisectors[j], p - truth.positions[j]
                to = np.arctan2(py - truth.positions[j, 1], px - truth.positions[j, 0])
                rows.append((truth.convex[j], f.structural, np.hypot(px - p[0], py - p[1]),
                             e[0] * np.cos(b) + e[1] * np.sin(b),
                             -e[0] * np.sin(b) + e[1] * np.cos(b),
                             np.degrees(abs(np.angle(np.exp(1j * (to - b)))))))
    return np.array(rows, dtype=float).reshape(-1, 6)


def run_bias(sigma_r: float, step_deg: float) -> int:
    """Print the convex / concave position errors (module docstring, ``--bias``)."""
    rng = np.random.default_rng(0)
    step = np.radians(step_deg)
    rows = []
    for depth in (0.15, 0.3):
        w = World()
        w.add_room([(-6, -5), (6, -5), (6, 0), (0.9, 0), (0.9, depth), (0, depth), (0, 0),
                    (-6, 0)])
        poses = [(x, -d, 0.5 * np.pi) for d in (1.0, 2.0, 3.0, 5.0)
                 for x in np.linspace(-3.0, 4.0, 15)]
        rows.append(_bias_rows(w, poses, step, sigma_r, rng, 5))
    w = World()
    w.add_room([(-8, -8), (8, -8), (8, 8), (-8, 8)])
    w.add_rectangle(0.0, 0.0, 1.0, 1.0)
    poses = [(r * np.cos(t), r * np.sin(t), t + np.pi) for r in (1.5, 2.5, 4.0, 6.0)
             for t in np.radians(np.arange(0.0, 360.0, 7.5))]
    rows.append(_bias_rows(w, poses, step, sigma_r, rng, 2))
    a = np.vstack(rows)
    print(f'sigma_r {100 * sigma_r:g} cm, beams {step_deg:g} deg; errors [cm], along the '
          'bisector (+ toward the sensor) / across')
    print('class | arms | range [m] or viewed off the bisector [deg] | n | along mean | '
          'along std | across mean | RMS | largest toward the sensor')
    for convex in (1.0, 0.0):
        for long_armed in (1.0, 0.0):
            for col, lo, hi in ((2, 0, 2), (2, 2, 4), (2, 4, 8), (2, 0, 8), (5, 0, 20),
                                (5, 20, 45), (5, 45, 90)):
                q = (a[:, 0] == convex) & (a[:, 1] == long_armed) & (a[:, col] >= lo) & (
                    a[:, col] < hi) & (a[:, 2] < 8.0)
                if q.sum() < 3:
                    continue
                e = 100.0 * a[q, 3:5]
                print(f"{'convex' if convex else 'concave'} | "
                      f"{'long' if long_armed else 'short'} | {lo}-{hi} "
                      f"{'m' if col == 2 else 'deg'} | {int(q.sum())} | "
                      f'{e[:, 0].mean():+.2f} | {e[:, 0].std():.2f} | {e[:, 1].mean():+.2f} | '
                      f'{np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2)):.2f} | '
                      f'{e[:, 0].max():+.1f}')
    return 0


def main(argv=None) -> int:
    """Run the benchmark and print a table per laser."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--scans', type=int, default=200, help='scans per laser')
    ap.add_argument('--repeat', type=int, default=5, help='timing repeats per scan (best)')
    ap.add_argument('--bag', default=None, metavar='DIR',
                    help="a recorded bag's /scan instead of the simulated office scans")
    ap.add_argument('--bias', action='store_true',
                    help='convex / concave position errors against the simulator (no timing)')
    ap.add_argument('--sigma-r', type=float, default=0.01, help='--bias: range noise [m]')
    ap.add_argument('--step-deg', type=float, default=0.5, help='--bias: beam spacing [deg]')
    args = ap.parse_args(argv)
    if args.bias:
        return run_bias(args.sigma_r, args.step_deg)
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
