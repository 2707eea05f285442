"""Vanishing points on York Urban: accuracy and per-frame time for each line input.

Run from the repository root::

    python benchmarks/bench_vanishing_points.py [--data DIR] [--images N] [--repeat R]
        [--scales 1,0.5] [--confidence [--folds K] [--in-sample-noise] [--noise-per-size]
        [--model-per-size] [--four-features | --no-influence] | --calibrate | --noise]
        [--no-orthogonal]

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

``--confidence``: the accuracy and the confidence of each Manhattan direction
(:mod:`landmark_nav.corridor.vp_confidence`), k-fold over the images (``--folds K``,
default 5; the number of images: leave-one-out), held out end to end
(:func:`landmark_nav.evaluation.vanishing_points.cross_validate_noise`): per fold, the
segment noise (``VPParams.sigma_px``, ``sigma_angle_deg``) is fitted on the other folds'
images at 640 x 480 as ``--noise`` fits it, every image is estimated with it at every size
in ``--scales``, and the confidence model is fitted on the other folds' directions and
applied to the held-out fold. Printed: per fold the fitted noise and constants; per size
and fold the held-out figures (corridor direction within 2 deg, confident, within 2 deg
among the confident, stated 95 % radius covering the error), and pooled over the folds the
accuracy (median and within 2 deg of the direction matched to the true one closest to the
optical axis, as the accuracy table; median over all three directions) and the confidence
figures. Acceptance per size: >= 98 % within 2 deg among the confident, confident on >= 85 %
of the images, 95 % radius covering the error on >= 90 % of the images.
``--in-sample-noise``: with ``--confidence``, every fold uses ``VPParams``' noise (fitted on
all images) and only the confidence model is held out. ``--calibrate``: fit on all images
and print the constants for ``landmark_nav/corridor/vp_confidence.py``. ``--noise``: the
maximum-likelihood end-point and direction noise of the segments (``VPParams.sigma_px``,
``sigma_angle_deg``) from their residuals against the true directions, the segments
labelled by the estimator without the direction noise
(:func:`landmark_nav.evaluation.vanishing_points.segment_noise`), per size.
``--no-orthogonal``: the Manhattan frame without the joint refinement of its triad
(``VPParams(orthogonal=False)``), for comparison. Alternatives of ``--confidence``, for
comparison: ``--noise-per-size`` (the segment noise fitted at each size on that size's
segments and used for it), ``--model-per-size`` (one confidence model per size, fitted on
that size's directions), ``--no-influence`` (the model without the influence of single
segments), ``--four-features`` (without the influence and the orthogonality residual).
"""

import argparse
from dataclasses import replace
import statistics
import sys

from common import add_data_argument, data_folder
from landmark_nav.corridor.vanishing_point import VPParams
from landmark_nav.evaluation.vanishing_points import (accuracy_summary, calibrate,
                                                      confidence_samples, confidence_summary,
                                                      cross_validate, cross_validate_noise,
                                                      evaluate_image, FoldNoise,
                                                      load_york_urban, segment_noise,
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
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument('--confidence', action='store_true',
                      help='held-out (k-fold) accuracy and direction confidence, the '
                      'segment noise fitted per fold')
    mode.add_argument('--calibrate', action='store_true',
                      help='fit the confidence constants on all images and print them')
    mode.add_argument('--noise', action='store_true',
                      help='fit the segment noise terms to residuals of the true directions')
    ap.add_argument('--folds', type=int, default=5, metavar='K',
                    help='folds of images of --confidence (default 5)')
    ap.add_argument('--in-sample-noise', action='store_true',
                    help="--confidence with VPParams' noise (fitted on all images) in every fold")
    ap.add_argument('--no-orthogonal', action='store_true',
                    help='the Manhattan frame without the joint refinement of its triad')
    ap.add_argument('--noise-per-size', action='store_true',
                    help='--confidence with the segment noise fitted at each size for that size')
    ap.add_argument('--model-per-size', action='store_true',
                    help='--confidence with one confidence model per size')
    ap.add_argument('--four-features', action='store_true',
                    help='--confidence without the orthogonality residual and the influence '
                    'as features')
    ap.add_argument('--no-influence', action='store_true',
                    help='--confidence without the influence as a feature')
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
    if args.in_sample_noise and not args.confidence:
        ap.error('--in-sample-noise goes with --confidence')
    if args.confidence and not 2 <= args.folds <= len(items):
        ap.error(f'--folds {args.folds}: give 2 to the number of images ({len(items)})')
    if (args.noise_per_size or args.model_per_size or args.four_features
            or args.no_influence) and not args.confidence:
        ap.error('--noise-per-size, --model-per-size, --four-features and --no-influence go '
                 'with --confidence')
    if args.in_sample_noise and (args.noise_per_size or args.model_per_size):
        ap.error('--in-sample-noise goes without --noise-per-size and --model-per-size')
    if args.confidence and not args.in_sample_noise:
        return _confidence(*cross_validate_noise(
            items, scales, vp, args.folds, noise_scale=None if args.noise_per_size else 1.0,
            per_size=args.model_per_size, orthogonality=not args.four_features,
            influence=not args.no_influence), scales)
    if args.confidence or args.calibrate:
        samples = [s for scale in scales for it in items
                   for s in confidence_samples(it, scale, vp_params=vp)]
        if args.calibrate:
            return _calibrate(samples, scales)
        held, cals = cross_validate(samples, args.folds, not args.four_features,
                                    not args.no_influence)
        noise = FoldNoise(vp.sigma_px, vp.sigma_angle_deg, 0)
        return _confidence(held, [{sc: c for sc in scales} for c in cals],
                           [{sc: noise for sc in scales}] * len(cals), scales, in_sample=True)
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


def _confidence(held, cals, noises, scales, in_sample=False) -> int:
    if in_sample:
        n = noises[0][scales[0]]
        print(f'Segment noise of every fold: VPParams (fitted on all images): sigma_px '
              f'{n.sigma_px:.3f} px, sigma_angle {n.sigma_angle_deg:.3f} deg')
    print(f'Per-fold constants (fitted on the other {len(cals) - 1} folds), per size:')
    print(f'  {"fold":>4s}{"size":>5s}{"sig px":>8s}{"sig deg":>8s}{"segs":>6s}{"w0":>8s}'
          f'{"w1":>8s}{"w2":>8s}{"w3":>8s}{"w4":>8s}{"w5":>8s}{"a":>7s}{"b deg":>7s}{"wrong":>7s}'
          f'{"p conf":>8s}')
    for f, (cal, noise) in enumerate(zip(cals, noises)):
        for scale in scales:
            c, n = cal[scale], noise[scale]
            print(f'  {f:4d}{round(640 * scale):5d}{n.sigma_px:8.3f}{n.sigma_angle_deg:8.3f}'
                  f'{n.segments:6d}' + ''.join(f'{w:8.3f}' for w in c.weights)
                  + f'{"-":>8s}' * (6 - len(c.weights))
                  + f'{c.scale:7.3f}{c.floor_deg:7.3f}{c.sigma_wrong_deg:7.2f}'
                  f'{c.p_confident:8.3f}')
    for scale in scales:
        w, h = round(640 * scale), round(480 * scale)
        rows = [x for x in held if x.sample.scale == scale]
        what = 'confidence held out, noise in-sample' if in_sample else 'held out'
        print(f'York Urban at {w} x {h}, {what} ({len(cals)}-fold over {len(rows) // 3} '
              'images):')
        print(f'  {"fold":>4s}{"images":>7s}{"<=2deg":>8s}{"confident":>10s}{"<=2 among":>10s}'
              f'{"covered":>8s}')
        for f in range(len(cals)):
            fold = [x for x in rows if x.fold == f]
            s, a = confidence_summary(fold), accuracy_summary(fold)
            print(f'  {f:4d}{s["axis_n"]:7.0f}{100 * a["axis_within_2deg"]:7.1f}%'
                  f'{100 * s["axis_confident"]:9.1f}%'
                  f'{100 * s["axis_precision"]:9.1f}%{100 * s["axis_coverage"]:7.1f}%')
        s, a = confidence_summary(rows), accuracy_summary(rows)
        print(f'  accuracy: axis median {a["axis_median"]:.2f} deg, within 2 deg '
              f'{100 * a["axis_within_2deg"]:.1f} %, all three median {a["all_median"]:.2f} deg')
        for key, what in (('axis', 'corridor direction (column 0)'), ('all', 'all directions')):
            print(f'  {what}: within 2 deg {100 * s[key + "_within_2deg"]:.1f} %, confident '
                  f'{100 * s[key + "_confident"]:.1f} %, within 2 deg among the confident '
                  f'{100 * s[key + "_precision"]:.1f} %, 95 % radius covers '
                  f'{100 * s[key + "_coverage"]:.1f} %')
        off = [x for x in rows if x.sample.column == 0 and x.sample.error > 2.0]
        print('  corridor directions more than 2 deg off: ' + (', '.join(
            f'{x.sample.image} (fold {x.fold}, {x.sample.error:.1f} deg, '
            f'{"confident" if x.confident else "not confident"})' for x in off) or 'none'))
        ok = (s['axis_precision'] >= 0.98 and s['axis_confident'] >= 0.85
              and s['axis_coverage'] >= 0.90)
        print(f'  acceptance (corridor direction): {"met" if ok else "NOT met"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
