"""Corner repeatability on the Carmen logs: opportunities, re-detections and the misses.

Run from the repository root (needs ``../shared/data/carmen``)::

    python benchmarks/corner_repeatability_carmen.py [--method minus_cosine] [LOG ...]

Every scan of each log (the FLASER pose as laser pose, readings >= 40 m no return, as
``feature_metrics_carmen.py --direct``; node defaults), corners of scan k scored against
scan k+1 through the reference poses as :func:`corner_repeatability` does. Printed per
log, the fraction re-detected within 10 cm (re-detected / opportunities) under three rules
for an opportunity (:func:`corner_observable`):

* ``place + arms`` (the metric): the next scan's beam toward the corner returned within
  10 cm of its distance, and so did its beams toward the point 15 cm along each arm;
* ``place``: only the corner's own beam;
* ``former``: the rule before, shared with the lines: the beam toward the corner not
  occluded (returned at least its distance - 10 cm, or nothing).

Then the misses of the metric split by the distance to the nearest corner of the next scan
(10-50 cm: moved; farther or none: not detected again), corners per scan and the median
detector time (segmentation included).

``--set NAME=VALUE`` (repeatable) changes a :class:`CornerParams` field; the row then also
gives the corners the change adds (per scan: corners with no corner of the defaults within
5 cm in the same scan) and the share of those new corners that are re-detected in the next
scan themselves (``new: per scan, re-detected / opportunities``).
"""

import argparse
from pathlib import Path
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from feature_metrics_carmen import carmen_logs, LOGS  # noqa: E402
from landmark_nav.evaluation.scan_metrics import (corner_observable,  # noqa: E402
                                                  corner_repeatability, Repeatability)
from landmark_nav.geometry import transform_points  # noqa: E402
from landmark_nav.laser.corners import CornerParams, detect_corners  # noqa: E402
from landmark_nav.laser.segmentation import segment_scan  # noqa: E402
import numpy as np  # noqa: E402


def main() -> None:
    """Print one row per log."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS), help='log names (default: all six)')
    ap.add_argument('--method', default='minus_cosine', help='corner detector')
    ap.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                    help='a CornerParams field (float, int or bool value)')
    args = ap.parse_args()
    changes = {}
    for item in args.set:
        key, value = item.split('=', 1)
        changes[key] = (value == 'True' if value in ('True', 'False')
                        else int(value) if value.lstrip('-').isdigit() else float(value))
    params = CornerParams(method=args.method, **changes)
    base = CornerParams(method=args.method) if changes else None
    print('| log | place + arms | place | former | '
          'misses: next 10-50 cm / none within 50 cm | corners/scan | ms/scan |'
          + (' new: per scan, re-detected |' if base else ''))
    print('| --- | --- | --- | --- | --- | --- | --- |' + (' --- |' if base else ''))
    for name, scans in carmen_logs(args.logs):
        corners, arms, times, new = [], [], [], []
        for s in scans:
            if base is not None:
                cl = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment,
                                  sigma_r=base.sigma_r)
                old = np.array([c.position for c in detect_corners(cl, base)]).reshape(-1, 2)
            t0 = time.perf_counter()
            cl = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment,
                              sigma_r=params.sigma_r)
            found = detect_corners(cl, params)
            times.append(time.perf_counter() - t0)
            corners.append(np.array([c.position for c in found]).reshape(-1, 2))
            arms.append(np.array([[c.bisector, c.opening] for c in found]).reshape(-1, 2))
            if base is not None:
                d = np.hypot(*(corners[-1][:, None] - old[None]).transpose(2, 0, 1))
                new.append(d.min(axis=1, initial=np.inf) > 0.05)
        score, place, added = Repeatability(), Repeatability(), Repeatability()
        near = []
        for k in range(len(scans) - 1):
            corner_repeatability(score, corners[k], scans[k].pose, corners[k + 1],
                                 scans[k + 1], wedges_k=arms[k])
            corner_repeatability(place, corners[k], scans[k].pose, corners[k + 1],
                                 scans[k + 1])
            if base is not None and new[k].any():
                corner_repeatability(added, corners[k][new[k]], scans[k].pose, corners[k + 1],
                                     scans[k + 1], wedges_k=arms[k][new[k]])
            if len(corners[k]):
                world = transform_points(scans[k].pose, corners[k])
                ang = (scans[k].pose[2] + arms[k][:, :1]
                       + 0.5 * arms[k][:, 1:] * np.array([1.0, -1.0]))
                world = world[corner_observable(scans[k + 1], world, ang)]
                other = transform_points(scans[k + 1].pose, corners[k + 1]).reshape(-1, 2)
                near.append(np.hypot(*(world[:, None] - other[None]).transpose(2, 0, 1)
                                     ).min(axis=1, initial=np.inf))
        near = np.concatenate(near) if near else np.zeros(0)
        n_all = score.opportunities + score.unobserved
        print(f'| {name} | {score.fraction:.3f} ({score.redetected}/{score.opportunities}) | '
              f'{place.fraction:.3f} ({place.redetected}/{place.opportunities}) | '
              f'{score.fraction_with_unobserved:.3f} '
              f'({score.redetected + score.unobserved_redetected}/{n_all}) | '
              f'{np.mean((near > 0.1) & (near <= 0.5)):.3f} / {np.mean(near > 0.5):.3f} | '
              f'{sum(map(len, corners)) / len(scans):.2f} | '
              f'{1e3 * np.median(times):.2f} |'
              + (f' {sum(map(np.sum, new)) / len(scans):.2f}, {added.fraction:.3f} '
                 f'({added.redetected}/{added.opportunities}) |' if base else ''), flush=True)


if __name__ == '__main__':
    main()
