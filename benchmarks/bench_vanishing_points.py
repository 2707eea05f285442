"""Vanishing points on York Urban: accuracy and per-frame time for each line input.

Run from the repository root::

    python benchmarks/bench_vanishing_points.py [--data DIR] [--images N] [--repeat R]
        [--scales 1,0.5] [--confidence | --calibrate | --noise] [--no-orthogonal]

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

``--confidence``: the confidence of each Manhattan direction
(:mod:`landmark_nav.corridor.vp_confidence`), 5-fold over the images (the model fitted on
the other folds' images at every size in ``--scales``, applied to the held-out fold); per
size, held-out figures only: fraction of images whose corridor direction is confident,
fraction within 2 deg among the confident directions, fraction of images whose stated 95 %
radius covers the error; and the per-fold constants. Acceptance per size: >= 98 % within
2 deg among the confident, confident on >= 85 % of the images, 95 % radius covering the
error on >= 90 % of the images. ``--calibrate``: fit on all images and print the constants
for ``landmark_nav/corridor/vp_confidence.py``. ``--noise``: the maximum-likelihood end-point
and direction noise of the segments (``VPParams.sigma_px``, ``sigma_angle_deg``) from their
residuals against the true directions, the segments labelled by the estimator without the
direction noise (:func:`landmark_nav.evaluation.vanishing_points.segment_noise`), per
size. ``--no-orthogonal``: the Manhattan frame
without the joint refinement of its triad (``VPParams(orthogonal=False)``), for comparison.
"""

import argparse
from dataclasses import replace
import statistics
import sys

from common import add_data_argument, data_folder
from landmark_nav.corridor.vanishing_point import VPParams
from landmark_nav.evaluation.vanishing_points import (calibrate, confidence_samples,
                                                      confidence_summary, cross_validate,
                                                      evaluate_image, load_york_urban,
                                                      segment_noise, summarize)
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
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument('--confidence', action='store_true',
                      help='held-out (5-fold) figures of the direction confidence')
    mode.add_argument('--calibrate', action='store_true',
                      help='fit the confidence constants on all images and print them')
    mode.add_argument('--noise', action='store_true',
                      help='fit the segment noise terms to residuals of the true directions')
    ap.add_argument('--no-orthogonal', action='store_true',
                    help='the Manhattan frame without the joint refinement of its triad')
    args = ap.parse_args(argv)
    vp = replace(VPParams(), orthogonal=not args.no_orthogonal)
    items = load_york_urban(data_folder(args.data))[:args.images]
    scales = [float(s) for s in args.scales.split(',')]
    if args.noise:
        for scale in scales:
            sp, sa, n = segment_noise(items, scale, replace(vp, sigma_angle_deg=0.0))
            print(f'{round(640 * scale)} x {round(480 * scale)}: sigma_px {sp:.3f} px, '
                  f'sigma_angle {sa:.3f} deg ({n} segments kept)')
        return 0
    if args.confidence or args.calibrate:
        samples = [s for scale in scales for it in items
                   for s in confidence_samples(it, scale, vp_params=vp)]
        return (_calibrate if args.calibrate else _confidence)(samples, scales)
    for scale in scales:
        w, h = round(640 * scale), round(480 * scale)
        rows = {}
        for run in RUNS:
            results, t_lines, t_vp = [], [], []
            for it in items:
                reps = [evaluate_image(it, run[0], run[1], scale, vp_params=vp)
                        for _ in range(args.repeat)]
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


def _calibrate(samples, scales) -> int:
    cal = calibrate(samples)
    n_img = len({s.image for s in samples})
    print(f'# fitted on {n_img} images x {len(scales)} sizes x 3 directions')
    print(f'CALIBRATION = VPCalibration(weights=({", ".join(f"{w:.4f}" for w in cal.weights)}),')
    print(f'                            scale={cal.scale:.4f}, floor_deg={cal.floor_deg:.4f},')
    print(f'                            sigma_wrong_deg={cal.sigma_wrong_deg:.4f}, '
          f'p_confident={cal.p_confident:.4f})')
    return 0


def _confidence(samples, scales) -> int:
    held, cals = cross_validate(samples)
    print('Per-fold constants (fitted on the other four folds):')
    print(f'  {"fold":>4s}{"w0":>8s}{"w1":>8s}{"w2":>8s}{"w3":>8s}{"a":>7s}{"b deg":>7s}'
          f'{"wrong":>7s}{"p conf":>8s}')
    for f, c in enumerate(cals):
        print(f'  {f:4d}' + ''.join(f'{w:8.3f}' for w in c.weights)
              + f'{c.scale:7.3f}{c.floor_deg:7.3f}{c.sigma_wrong_deg:7.2f}{c.p_confident:8.3f}')
    for scale in scales:
        w, h = round(640 * scale), round(480 * scale)
        rows = [x for x in held if x.sample.scale == scale]
        print(f'York Urban at {w} x {h}, held-out (5-fold over {len(rows) // 3} images):')
        print(f'  {"fold":>4s}{"images":>7s}{"confident":>10s}{"<=2 among":>10s}'
              f'{"covered":>8s}')
        for f in range(len(cals)):
            s = confidence_summary([x for x in rows if x.fold == f])
            print(f'  {f:4d}{s["axis_n"]:7.0f}{100 * s["axis_confident"]:9.1f}%'
                  f'{100 * s["axis_precision"]:9.1f}%{100 * s["axis_coverage"]:7.1f}%')
        s = confidence_summary(rows)
        for key, what in (('axis', 'corridor direction (column 0)'), ('all', 'all directions')):
            print(f'  {what}: within 2 deg {100 * s[key + "_within_2deg"]:.1f} %, confident '
                  f'{100 * s[key + "_confident"]:.1f} %, within 2 deg among the confident '
                  f'{100 * s[key + "_precision"]:.1f} %, 95 % radius covers '
                  f'{100 * s[key + "_coverage"]:.1f} %')
        ok = (s['axis_precision'] >= 0.98 and s['axis_confident'] >= 0.85
              and s['axis_coverage'] >= 0.90)
        print(f'  acceptance (corridor direction): {"met" if ok else "NOT met"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
