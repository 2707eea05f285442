"""Vanishing points on York Urban: accuracy and per-frame time for each line input.

Run from the repository root::

    python benchmarks/bench_vanishing_points.py [--data DIR] [--images N] [--repeat R]
        [--scales 1,0.5]

For the 51 training images of ``../shared/data/york_urban_train`` (Denis, Elder, Estrada,
ECCV 2008; or any folder of ``NAME.jpg`` + ``NAME_gt.npz`` in the dataset's format given
with ``--data DIR``, the first ``--images N`` of them), each line input (the chapter's
segmented Hough, OpenCV HoughLinesP, OpenCV LSD) feeds the Manhattan-frame estimator
(:func:`landmark_nav.corridor.vanishing_point.manhattan_frame`); the chapter's own
clustering (§3.1.2) on the segmented Hough lines is reported beside it. Per image at 640 x
480 and 320 x 240 (INTER_AREA resize, K scaled): the angular error of the direction closest
to the optical axis, the errors of all three directions, and the best of ``R`` times of the
line and VP stages. Times are also given as ratios to LSD's line stage on the same frames
in the same run (machines differ).

Acceptance (640 x 480, segmented Hough): axis error <= 2 deg on >= 90 % and median <= 1 deg;
median over all three directions <= 1.3 deg.
"""

import argparse
import statistics
import sys

from common import add_data_argument, data_folder
from landmark_nav.evaluation.vanishing_points import (evaluate_image, load_york_urban,
                                                      summarize)
from landmark_nav.vision.image_lines import METHODS

RUNS = [(m, 'manhattan') for m in METHODS] + [('segmented_hough', 'chapter')]


def main(argv=None) -> int:
    """Run the benchmark and print the tables."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_argument(ap, 'york_urban_train')
    ap.add_argument('--images', type=int, default=None, metavar='N',
                    help='only the first N images (default: all)')
    ap.add_argument('--repeat', type=int, default=3, help='timing repeats per image (best)')
    ap.add_argument('--scales', default='1,0.5', help='image scales (1 = 640 x 480)')
    args = ap.parse_args(argv)
    items = load_york_urban(data_folder(args.data))[:args.images]
    for scale in (float(s) for s in args.scales.split(',')):
        w, h = round(640 * scale), round(480 * scale)
        rows = {}
        for run in RUNS:
            results, t_lines, t_vp = [], [], []
            for it in items:
                reps = [evaluate_image(it, run[0], run[1], scale) for _ in range(args.repeat)]
                results.append(reps[0])
                t_lines.append(min(r.t_lines for r in reps))
                t_vp.append(min(r.t_vp for r in reps))
            rows[run] = (summarize(results), statistics.median(t_lines),
                         statistics.median(t_vp),
                         statistics.median(r.n_lines for r in results))
        ref = rows[('lsd', 'manhattan')][1]
        print(f'York Urban, {len(items)} images at {w} x {h} (median per frame; time ratios '
              f'to the LSD line stage = {1e3 * ref:.1f} ms)')
        print(f'  {"lines":<16s}{"VP":<10s}{"axis med":>9s}{"<=2deg":>8s}{"sel<=2":>8s}'
              f'{"all3 med":>9s}{"lines":>6s}{"lines ms":>9s}{"VP ms":>7s}{"total ms":>9s}'
              f'{"fps":>6s}{"x LSD":>7s}')
        for (lm, vpm), (s, tl, tv, n) in rows.items():
            tot = tl + tv
            within, selected = s['axis_within_2deg'], s['axis_selected_within_2deg']
            print(f'  {lm:<16s}{vpm:<10s}{s["axis_median"]:9.2f}'
                  f'{100 * within:7.1f}%{100 * selected:7.1f}%'
                  f'{s["all_median"]:9.2f}{n:6.0f}{1e3 * tl:9.1f}{1e3 * tv:7.1f}'
                  f'{1e3 * tot:9.1f}{1 / tot:6.1f}{tl / ref:7.2f}')
        if scale == 1.0:
            s = rows[('segmented_hough', 'manhattan')][0]
            ok = (s['axis_within_2deg'] >= 0.9 and s['axis_median'] <= 1.0
                  and s['all_median'] <= 1.3)
            print(f'  acceptance (segmented Hough + Manhattan): {"met" if ok else "NOT met"}')
        print()
    return 0


if __name__ == '__main__':
    sys.exit(main())
