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
    args = ap.parse_args()
    params = CornerParams(method=args.method)
    print('| log | place + arms | place | former | '
          'misses: next 10-50 cm / none within 50 cm | corners/scan | ms/scan |')
    print('| --- | --- | --- | --- | --- | --- | --- |')
    for name, scans in carmen_logs(args.logs):
        corners, arms, times = [], [], []
        for s in scans:
            t0 = time.perf_counter()
            cl = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment,
                              sigma_r=params.sigma_r)
            found = detect_corners(cl, params)
            times.append(time.perf_counter() - t0)
            corners.append(np.array([c.position for c in found]).reshape(-1, 2))
            arms.append(np.array([[c.bisector, c.opening] for c in found]).reshape(-1, 2))
        score, place = Repeatability(), Repeatability()
        near = []
        for k in range(len(scans) - 1):
            corner_repeatability(score, corners[k], scans[k].pose, corners[k + 1],
                                 scans[k + 1], wedges_k=arms[k])
            corner_repeatability(place, corners[k], scans[k].pose, corners[k + 1],
                                 scans[k + 1])
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
              f'{1e3 * np.median(times):.2f} |', flush=True)


if __name__ == '__main__':
    main()
