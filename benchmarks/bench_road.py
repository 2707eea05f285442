"""Speed of the road follower's cores: laser classification per scan, vision outline per frame.

Run from the repository root::

    python benchmarks/bench_road.py [--scans N] [--frames N] [--seed S] [--data DIR]
    python benchmarks/bench_road.py --cross-drive DIR [DIR ...] [--methods M ...]
        [--cnn-steps N] [--held-out DRIVE ...] [--json FILE]

* :func:`landmark_nav.road.terrain.classify_scan` on simulated 361-beam tilted scans of the
  asphalt and gravel park roads; reference in the same run: one ``np.polyfit`` of degree 2
  over the scan's valid points (a floor any per-scan fit pays). Target (issue): <= 2 ms.
* :func:`landmark_nav.road.outline.road_outline` on 320 x 240 rendered park-road frames (the
  chapter's criterion, as in the simulator evaluation) and
  on the real CamVid frames (480 x 360, resampled to 320 x 240 inside) of ``--data DIR``
  (``images/*.png`` and ``labels_camvid11/*.png``; default ``../shared/data/camvid_road``,
  left out when that default is not there);
  reference in the same run: a full-frame OpenCV Sobel 3 x 3 + 5 x 5 and a Mahalanobis pass
  on the eq. 25 chromaticity at 320 x 240. Target (issue): <= 20 ms.
Times are medians of single-threaded calls; the real frames are timed with the packaged
CNN criterion (``cnn``, the default), the packaged learned criterion and the chapter's
(eqs. 26-28).

``--cross-drive DIR ...`` instead scores the outline leaving one drive out
(:func:`landmark_nav.evaluation.road_cross_drive.leave_one_drive_out`): per drive, the
road-probability model fitted on the other drives' frames, the drive's frames scored; the
chapter's criterion (no training) on the same frames for comparison. ``--methods`` picks
the criteria (default ``learned chapter``; ``cnn`` trains the convolutional network per
drive with PyTorch, ``--cnn-steps`` mini-batches, about 6 min per drive on one core);
``--held-out`` scores only the drives named (one fold alone has no row-fill limit: the
limit comes from the other held-out drives).
Frames whose seed band is not road are counted and listed apart. A frame is flagged when
the outline's confidence is below ``min_confidence`` or its row fill below the limit
calibrated on the other drives
(:func:`landmark_nav.evaluation.road_cross_drive.row_fill_limits`); the table counts the
failures flagged and the good frames (IoU >= 0.6) flagged, and prints the limit over all
drives (the shipped ``min_row_fill``).
"""

import argparse
import json
from pathlib import Path
import statistics
import sys
import time

from common import data_folder, SHARED_DATA
import cv2
from landmark_nav.evaluation.road_cross_drive import (CNN_STEPS, leave_one_drive_out,
                                                      row_fill_limits)
from landmark_nav.evaluation.road_fusion import CAMERA, CAMERA_MOUNT, SIM_CONFIG
from landmark_nav.evaluation.road_laser import ANGLES
from landmark_nav.evaluation.road_outline import (CLASS_NAMES, FAIL_IOU, frame_names,
                                                  load_frame, SEED_COLS, SEED_ROWS)
from landmark_nav.road.outline import (band_seed, chromaticity, METHODS, OutlineParams,
                                       road_outline)
from landmark_nav.road.terrain import classify_scan, LaserMount
from landmark_nav.sim.park_road import cast_scan, ParkRoad, render_view
import numpy as np
from threadpoolctl import threadpool_limits


def median_ms(fn, items, repeat: int = 3) -> float:
    """Median time of fn(item) over the items (best of ``repeat`` per item) [ms]."""
    times = []
    for it in items:
        best = float('inf')
        for _ in range(repeat):
            t0 = time.perf_counter()
            fn(it)
            best = min(best, time.perf_counter() - t0)
        times.append(best)
    return 1e3 * statistics.median(times)


def paired_ms(fn, ref, items, repeat: int = 3):
    """Median times of fn and ref [ms] and the median of their per-item ratio.

    Each item's fn and ref are timed back to back (best of ``repeat`` each), so a change of
    the machine's load during the run weighs on both alike.
    """
    pairs = [(median_ms(fn, [it], repeat), median_ms(ref, [it], repeat)) for it in items]
    t, r = np.array(pairs).T
    return float(np.median(t)), float(np.median(r)), float(np.median(t / r))


def reference_pass(rgb: np.ndarray) -> None:
    """Full-frame Sobel 3x3 + 5x5 and a Mahalanobis pass on the chromaticity (320 x 240)."""
    small = cv2.resize(rgb, (320, 240), interpolation=cv2.INTER_AREA)
    grey = small.astype(np.float32).mean(axis=2)
    for k in (3, 5):
        cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=k)
        cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=k)
    c = chromaticity(small)
    d = c - c.reshape(-1, 2).mean(axis=0)
    q = np.linalg.inv(np.cov(d.reshape(-1, 2).T)).astype(np.float32)
    np.einsum('...i,ij,...j->...', d, q, d)


def main(argv=None) -> int:
    """Run the benchmark and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--scans', type=int, default=100)
    ap.add_argument('--frames', type=int, default=30)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--data', default=None, metavar='DIR',
                    help='CamVid-format frames (default: ../shared/data/camvid_road if there)')
    ap.add_argument('--cross-drive', nargs='+', metavar='DIR', help='score the outline '
                    'leaving one drive out over these CamVid-format folders (e.g. '
                    '../shared/data/camvid_train ../shared/data/camvid_road)')
    ap.add_argument('--methods', nargs='+', choices=METHODS, default=['learned', 'chapter'],
                    help='with --cross-drive: road criteria to score (default: learned '
                    'chapter; cnn needs PyTorch)')
    ap.add_argument('--cnn-steps', type=int, default=CNN_STEPS,
                    help=f'with --cross-drive: CNN training mini-batches (default {CNN_STEPS})')
    ap.add_argument('--held-out', nargs='+', metavar='DRIVE', default=(),
                    help='with --cross-drive: hold out only these drives (e.g. 0001TP; '
                    'default every drive in turn)')
    ap.add_argument('--json', help='with --cross-drive: write the per-frame scores here')
    args = ap.parse_args(argv)
    if args.cross_drive:
        return cross_drive([data_folder(d) for d in args.cross_drive], args.json,
                           args.methods, args.cnn_steps, args.held_out)
    cv2.setNumThreads(1)
    threadpool_limits(1)
    rng = np.random.default_rng(args.seed)
    mount = LaserMount()
    print(f'{"case":34s} {"ms":>7s} {"ref ms":>7s} {"ratio":>6s}')
    for kind in ('asphalt', 'gravel'):
        road = ParkRoad.of_kind(kind, seed=args.seed)
        scans = [cast_scan(road, (0.1 * i, rng.normal(0, 0.3), rng.normal(0, 0.05)), mount,
                           ANGLES, rng=rng) for i in range(args.scans)]
        t = median_ms(lambda s: classify_scan(s.ranges, s.angles, mount), scans)

        def ref(s):
            ok = np.isfinite(s.ranges)
            np.polyfit(s.angles[ok], s.ranges[ok], 2)
        r = median_ms(ref, scans)
        print(f'{"laser " + kind + " (361 beams)":34s} {t:7.2f} {r:7.3f} {t / r:6.1f}')
    road = ParkRoad.of_kind('asphalt', seed=args.seed)
    frames = [render_view(road, (0.2 * i, rng.normal(0, 0.3), rng.normal(0, 0.05)), CAMERA,
                          CAMERA_MOUNT, rng=rng) for i in range(args.frames)]
    seed = band_seed(frames[0].shape, (0.8, 0.84), (0.3, 0.7))
    t = median_ms(lambda f: road_outline(f, seed, SIM_CONFIG.outline), frames)
    r = median_ms(reference_pass, frames)
    print(f'{"vision rendered 320x240":34s} {t:7.2f} {r:7.2f} {t / r:6.1f}')
    if args.data is None and not (SHARED_DATA / 'camvid_road').is_dir():
        print(f'(CamVid left out: {SHARED_DATA / "camvid_road"} not found; --data DIR)')
        return 0
    folder = data_folder(args.data or str(SHARED_DATA / 'camvid_road'))
    if not frame_names(folder):
        sys.exit(f'error: {folder}: no frame with both images/NAME.png and '
                 'labels_camvid11/NAME.png')
    real = [load_frame(folder, n)[0] for n in frame_names(folder)[:args.frames]]
    seed = band_seed(real[0].shape, SEED_ROWS, SEED_COLS)
    for name in METHODS:
        params = OutlineParams(method=name)
        t, r, ratio = paired_ms(lambda f: road_outline(f, seed, params), reference_pass, real)
        print(f'{"vision CamVid 480x360 " + name:34s} {t:7.2f} {r:7.2f} {ratio:6.1f}')
    return 0


def cross_drive(folders, json_path=None, methods=('learned', 'chapter'),
                cnn_steps=CNN_STEPS, held_out=()) -> int:
    """Print the leave-one-drive-out table of each criterion of ``methods``."""
    print(f'{"criterion":9s} {"held out":8s} {"frames":>6s} {"IoU med":>7s} {"prec":>6s} '
          f'{"recall":>6s} {"fail<0.6":>9s} {"fill lim":>8s} {"fail&flag":>9s} '
          f'{"good&flag":>9s} {"kept":>5s} {"IoU med":>7s} {"fail<0.6":>9s} '
          f'{"seed not road":>13s}')
    results = {}
    for name in methods:
        params = OutlineParams(method=name, min_row_fill=0.0)
        results[name] = leave_one_drive_out(folders, params, cnn_steps=cnn_steps,
                                            held_out=held_out)
        # eqs. 26-28 have no row fill (1.0): nothing to calibrate
        limits = row_fill_limits(results[name]) if name != 'chapter' else \
            dict.fromkeys(list(results[name]) + ['all'], 0.0)
        for drive, res in results[name].items():
            s, frames = res['summary'], res['frames']
            a = s['all']
            road = [f for f in frames if f.seed_is_road]
            flag = [not f.reliable or f.row_fill < limits[drive] for f in road]
            flagged = [f.iou < FAIL_IOU for f, g in zip(road, flag) if g]
            kept = np.array([f.iou for f, g in zip(road, flag) if not g] or [np.nan])
            bad = s['seed_not_road']
            print(f'{name:9s} {drive:8s} {a["frames"]:6d} {a["iou_median"]:7.3f} '
                  f'{a["precision_median"]:6.3f} {a["recall_median"]:6.3f} '
                  f'{a["failures"]:4d} ({100 * a["failure_rate"]:2.0f}%) {limits[drive]:8.3f} '
                  f'{sum(flagged):9d} {len(flagged) - sum(flagged):9d} '
                  f'{len(road) - len(flagged):5d} '
                  f'{np.median(kept):7.3f} {int(np.sum(kept < FAIL_IOU)):4d} '
                  f'({100 * np.mean(kept < FAIL_IOU):2.0f}%) '
                  f'{bad["frames"]:13d} {" ".join(bad.get("names", []))}')
        if name != 'chapter' and len(results[name]) > 1:     # not of one fold alone
            print(f'row-fill limit over all drives (min_row_fill): {limits["all"]:.3f}')
        for drive, res in results[name].items():
            wrong = np.sum([f.wrong_pixels for f in res['frames'] if f.seed_is_road], axis=0)
            share = ', '.join(f'{CLASS_NAMES[i]} {100 * wrong[i] / wrong.sum():.0f} %'
                              for i in np.argsort(wrong)[::-1][:4] if wrong[i])
            print(f'{name} {drive}: pixels wrongly taken as road: {share}')
    if json_path:
        Path(json_path).write_text(json.dumps(
            {k: {d: {'summary': r['summary'], 'frames': [f.__dict__ for f in r['frames']]}
                 for d, r in v.items()} for k, v in results.items()}, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
