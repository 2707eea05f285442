"""Landmarks, AprilTags and ArUco markers composited into real photographs, side by side.

Run ``python -m landmark_nav.evaluation.landmarks_real [detection|pose|false|all]`` (see
``--help``; ``benchmarks/bench_landmarks.py real`` runs the same functions with the
benchmark's sizes). Backgrounds are the real photographs of a folder (by default the York
Urban images in ``../shared/data/york_urban_train``, found with
:func:`landmark_nav.testing.shared_data`), converted to grey and cut to 640 x 480.

One *trial* is one background, one marker pose and one set of degradations; the same trial
is rendered three times, once per marker type, so that the three detectors see the same
frames except for the printed pattern:

* ``landmark`` -- the package's landmark (3x3 design), printed by
  :meth:`LandmarkDesign.render` (the code path of ``landmark_nav make-landmark``'s PNG),
  one-block quiet zone: 9 x 9 modules of which 7 x 7 are the frame; ``landmark_fast`` is
  the same detector in its fast mode (``DetectorParams.decimate = 2``);
* ``apriltag`` -- tag36h11 (8 x 8 cells including its black border, one white cell around:
  10 x 10), drawn by OpenCV's ``aruco.generateImageMarker`` with ``DICT_APRILTAG_36h11``
  (the same bit patterns as AprilTag's tag images) and detected by AprilTag 3
  (``pupil_apriltags``, decimate 1 and 2, one thread); its pose is ``cv2.solvePnP``
  (``SOLVEPNP_IPPE_SQUARE``) on its four corners, as for ArUco (AprilTag's own
  ``estimate_tag_pose`` corrupted the heap in a test run, see :class:`Detectors`);
* ``aruco`` -- ``DICT_6X6_250`` (8 x 8 with its border, one white cell around), drawn and
  detected by OpenCV ArUco with sub-pixel corner refinement.

"px per module" is the printed module (landmark block, tag cell) seen head-on at the
marker's distance. The parts, one module each:

* :mod:`.marker_composites` -- backgrounds, printed markers, marker poses and image
  formation (the geometry and degradations in detail);
* :mod:`.marker_detectors` -- the detectors behind one interface (:class:`Detectors`);
* :mod:`.marker_trials` -- trials, their runs and the scoring (and how times are taken);
* :mod:`.marker_free_frames` -- real frames without a landmark (false detections);
* :mod:`.landmark_stages` -- the detector stage that loses a landmark.

This module holds the summaries and tables and the command line (:func:`main`) and
re-exports the public names of the parts.
"""

import argparse
from dataclasses import asdict, dataclass, replace
import json
import math
from pathlib import Path
import sys
from typing import Dict, List, Optional, Sequence, Tuple

from landmark_nav.evaluation.landmark_stages import landmark_stage, stage_counts, STAGES
from landmark_nav.evaluation.marker_composites import (CAMERA, composite, CORNER_MODULES,
                                                       default_backgrounds, degrade,
                                                       draw_photometrics, draw_pose,
                                                       load_backgrounds, marker_corners,
                                                       marker_texture, MODULE, Photometrics,
                                                       PRINTED_MODULES, SUPERSAMPLE,
                                                       texture_homography, TEXTURE_PX)
from landmark_nav.evaluation.marker_detectors import (DETECTORS, Detectors, Found,
                                                      marker_family, release_apriltags)
from landmark_nav.evaluation.marker_free_frames import (checkerboard_texture, chessboard_cache,
                                                        chessboard_photo_dir,
                                                        CHESSBOARD_PHOTOS, chessboard_photos,
                                                        default_extra_photos, false_frames,
                                                        FalseResult,
                                                        fetch_chessboard_photos,
                                                        OPENCV_DOC_DATA, transformed_photo)
from landmark_nav.evaluation.marker_trials import (detection_trials, draw_trial, Outcome,
                                                   pose_trials, render_trial, run_trials,
                                                   score, TAG_IDS, Trial)
from landmark_nav.vision.detector import DetectorParams
from landmark_nav.vision.pose import CHI2_6_999, PoseParams
import numpy as np


# ---------------------------------------------------------------------- summaries


@dataclass
class Row:
    """Detection rate and errors of one detector in one group of trials."""

    detector: str
    group: str
    trials: int
    p_detect: float
    wrong_codes: int
    false_detections: int
    ms_per_frame: float
    median_position_mm: float = math.nan
    median_angle_deg: float = math.nan
    max_angle_deg: float = math.nan
    over_5_deg: int = 0
    poses: int = 0
    over_5_uncovered: int = 0
    ambiguous: int = 0


def summarise(outcomes: Sequence[Outcome], key) -> List[Row]:
    """Group outcomes by ``(detector, key(outcome))`` and summarise each group."""
    groups: Dict[Tuple[str, str], List[Outcome]] = {}
    for o in outcomes:
        groups.setdefault((o.detector, key(o)), []).append(o)
    rows = []
    for (name, grp), os_ in groups.items():
        ang = np.array([o.angle_error_deg for o in os_ if math.isfinite(o.angle_error_deg)])
        pos = np.array([o.position_error for o in os_ if math.isfinite(o.position_error)])
        rows.append(Row(name, grp, len(os_), float(np.mean([o.detected for o in os_])),
                        sum(o.wrong_codes for o in os_), sum(o.false_detections for o in os_),
                        1000.0 * float(np.mean([o.seconds for o in os_])),
                        1000.0 * float(np.median(pos)) if len(pos) else math.nan,
                        float(np.median(ang)) if len(ang) else math.nan,
                        float(ang.max()) if len(ang) else math.nan,
                        int(np.sum(ang > 5.0)), len(ang),
                        sum(1 for o in os_ if o.angle_error_deg > 5.0
                            and not o.nees <= CHI2_6_999),
                        sum(1 for o in os_ if o.ambiguous)))
    return rows


def _group_order(group: str) -> Tuple[float, str]:
    """Sort key of group labels: by their first number."""
    num = ''.join(c if c.isdigit() or c == '.' else ' ' for c in group).split()
    return (float(num[0]) if num else math.inf, group)


def format_table(rows: Sequence[Row], title: str, pose: bool = False) -> str:
    """Return a Markdown table: one line per group, one column per detector."""
    names = [n for n in DETECTORS if any(r.detector == n for r in rows)]
    groups = sorted(dict.fromkeys(r.group for r in rows), key=_group_order)
    by = {(r.detector, r.group): r for r in rows}
    lines = [title, '', '| ' + ' | '.join(['group', 'n'] + names) + ' |',
             '| --- | --- |' + ' --- |' * len(names)]
    for g in groups:
        cells = []
        for n in names:
            r = by.get((n, g))
            if r is None:
                cells.append('')
            elif pose:
                cov = (f' ({r.over_5_uncovered} not covered, {r.ambiguous} ambiguous)'
                       if r.detector == 'landmark' else '')
                cells.append(f'{r.p_detect:.2f}; {r.median_position_mm:.2f} mm / '
                             f'{r.median_angle_deg:.2f} deg, max {r.max_angle_deg:.1f} deg, '
                             f'{r.over_5_deg} > 5 deg{cov}')
            else:
                bad = r.wrong_codes or r.false_detections
                extra = f' (wrong {r.wrong_codes}, false {r.false_detections})' if bad else ''
                cells.append(f'{r.p_detect:.2f}{extra}')
        n = next(r.trials for r in rows if r.group == g)
        lines.append(f'| {g} | {n} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def format_speed(outcomes: Sequence[Outcome]) -> str:
    """Return mean time per frame of each detector and its ratio to the others."""
    names = [n for n in DETECTORS if any(o.detector == n for o in outcomes)]
    ms = {n: 1000.0 * float(np.mean([o.seconds for o in outcomes if o.detector == n]))
          for n in names}
    lines = ['Time per 640 x 480 frame (single thread, mean over the same trials):']
    for n in names:
        ratios = ', '.join(f'{ms[n] / ms[m]:.2f}x {m}' for m in names if m != n)
        lines.append(f'  {n:10s} {ms[n]:7.2f} ms  ({ratios})')
    return '\n'.join(lines)


def tilt_bin(o: Outcome) -> str:
    """Group key: the tilt range of an outcome (0-30, 30-45, 45-55, 55-60 deg)."""
    for lo, hi in ((0, 30), (30, 45), (45, 55)):
        if o.tilt_deg < hi:
            return f'tilt {lo}-{hi}'
    return 'tilt 55-60'


def parse_detector_params(items: Sequence[str]) -> Dict[str, object]:
    """Parse ``NAME=VALUE`` items (YAML scalars) into DetectorParams keyword arguments.

    Raises:
        ValueError: an item without ``=`` or a name that is not a DetectorParams field.
    """
    import yaml
    fields = set(DetectorParams.__dataclass_fields__)
    out = {}
    for item in items:
        name, sep, value = item.partition('=')
        if not sep or name not in fields:
            raise ValueError(f'--set {item!r}: expected NAME=VALUE with NAME one of '
                             f'{", ".join(sorted(fields))}')
        out[name] = yaml.safe_load(value)
    return out


def main(argv: Optional[Sequence[str]] = None,
         prog: str = 'python -m landmark_nav.evaluation.landmarks_real') -> int:
    """Command line: detection, pose and speed tables on composites of real photographs."""
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split('\n')[0])
    ap.add_argument('what', nargs='?', default='all',
                    choices=('detection', 'pose', 'false', 'stages', 'all'))
    ap.add_argument('--per-size', type=int, default=100, help='trials per px per module')
    ap.add_argument('--sizes', type=float, nargs='+', default=[3, 4, 5, 6, 8, 12],
                    help='px per module')
    ap.add_argument('--tilt', type=float, nargs=2, default=[0.0, 60.0], metavar=('MIN', 'MAX'),
                    help='tilt range of the detection trials [deg]')
    ap.add_argument('--per-distance', type=int, default=150, help='pose trials per distance')
    ap.add_argument('--distances', type=float, nargs='+', default=[1.0, 2.2])
    ap.add_argument('--false-frames', type=int, default=1020,
                    help='real frames without landmarks (false)')
    ap.add_argument('--no-chessboard-photos', action='store_true',
                    help='false: without the 26 real chessboard photographs (OpenCV '
                    'samples, fetched with apt-get download opencv-doc into the cache)')
    ap.add_argument('--chessboard-share', type=float, default=0.3,
                    help='false: fraction of the frames that are views of the real '
                    'chessboard photographs')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--detectors', nargs='+', default=list(DETECTORS), choices=DETECTORS)
    ap.add_argument('--backgrounds', '--data', type=Path, default=None, metavar='DIR',
                    help='folder of photographs (default ../shared/data/york_urban_train)')
    ap.add_argument('--deblur-margin', type=float, default=DetectorParams().deblur_margin,
                    help='landmark detector deblur_margin (0: the code read before issue 20)')
    ap.add_argument('--second-neighbour-angle', type=float,
                    default=DetectorParams().second_neighbour_angle,
                    help='landmark detector second_neighbour_angle [deg] (0: before issue 20)')
    ap.add_argument('--set', nargs='+', default=[], metavar='NAME=VALUE',
                    help='landmark detector parameters (DetectorParams fields), e.g. '
                    'corner_method=eq1 small_block_px=4.5 (the corner stage of the chapter, '
                    'the default before the saddle candidates), with max_gaps=0 '
                    'refine_grid=false block_ring=false unblur_margin=1 (the detector '
                    'before the small-landmark extensions)')
    ap.add_argument('--no-planar-start', action='store_true',
                    help='landmark pose from the quadrant guesses only (before issue 20)')
    ap.add_argument('--json', type=Path, default=None, help='write every outcome here')
    args = ap.parse_args(argv)
    from threadpoolctl import threadpool_limits
    threadpool_limits(limits=1)             # BLAS single-threaded too (numpy least squares)
    bgs = load_backgrounds(args.backgrounds) if args.backgrounds else default_backgrounds()
    lm_params = DetectorParams(deblur_margin=args.deblur_margin,
                               second_neighbour_angle=args.second_neighbour_angle)
    try:
        lm_params = replace(lm_params, **parse_detector_params(args.set))
    except (TypeError, ValueError) as err:
        ap.error(str(err))
    dets = Detectors(args.detectors, landmark_params=lm_params,
                     pose_params=PoseParams(planar_start=not args.no_planar_start))
    everything: List[Outcome] = []
    if args.what in ('detection', 'all'):
        trials = detection_trials(args.sizes, args.per_size, tuple(args.tilt), args.seed,
                                  len(bgs))
        res = run_trials(trials, bgs, dets)
        everything += res
        print(format_table(summarise(res, lambda o: f'{o.px_per_module:g} px'),
                           f'Detection vs px per module (tilt {args.tilt[0]:g}-'
                           f'{args.tilt[1]:g} deg, seed {args.seed})'))
        print()
        print(format_table(summarise(res, tilt_bin), 'Detection vs tilt (all sizes)'))
        print()
        print(format_speed(res))
        print()
    if args.what in ('pose', 'all'):
        trials = pose_trials(args.distances, args.per_distance, seed=args.seed + 1000,
                             n_backgrounds=len(bgs))
        res = run_trials(trials, bgs, dets, pose=True)
        everything += res
        print(format_table(summarise(res, lambda o: f'{MODULE * CAMERA.fx / o.px_per_module:g}'
                                                    ' m'),
                           'Pose (tilt 0-60 deg): p_detect; median position / angle error, '
                           'worst angle; landmark: poses > 5 deg off whose covariance does not '
                           'cover them (NEES above the chi2_6 99.9 % bound), poses reported '
                           'ambiguous', pose=True))
        print()
    if args.what in ('false', 'all'):
        boards: List[np.ndarray] = []
        if not args.no_chessboard_photos:
            try:
                boards = chessboard_photos()
            except (FileNotFoundError, ValueError) as err:
                print(f'{err}\n(or run without them: --no-chessboard-photos)',
                      file=sys.stderr)
                return 2
        res = false_frames(bgs, args.false_frames, args.seed + 2000,
                           default_extra_photos() if args.backgrounds is None else (),
                           params=lm_params, chessboards=boards,
                           chessboard_share=args.chessboard_share)
        print(f'Landmark-free real frames: {sum(res.frames.values())} '
              f'({", ".join(f"{k} {v}" for k, v in sorted(res.frames.items()))}); '
              f'detections (all false): {sum(res.detections.values())} '
              f'({", ".join(f"{k} {v}" for k, v in sorted(res.detections.items()))}); '
              f'{res.ms_per_frame:.1f} ms per frame')
        print()
    if args.what == 'stages':
        trials = detection_trials(args.sizes, args.per_size, tuple(args.tilt), args.seed,
                                  len(bgs))
        print('Where the landmark detector loses the landmark (first failing stage):')
        for size, row in stage_counts(trials, bgs, lm_params).items():
            items = sorted(row.items(), key=lambda kv: -kv[1])
            print(f'  {size}: ' + '; '.join(f'{k} {v}' for k, v in items))
        print()
    dets.close()
    if args.json:
        args.json.write_text(json.dumps([asdict(o) for o in everything], indent=0))
    return 0


__all__ = ['CAMERA', 'checkerboard_texture', 'CHESSBOARD_PHOTOS', 'chessboard_cache',
           'chessboard_photo_dir', 'chessboard_photos', 'composite', 'CORNER_MODULES',
           'default_backgrounds', 'default_extra_photos', 'degrade', 'detection_trials',
           'DETECTORS', 'Detectors', 'draw_photometrics', 'draw_pose', 'draw_trial',
           'FalseResult', 'false_frames', 'fetch_chessboard_photos', 'format_speed',
           'format_table', 'Found', 'landmark_stage', 'load_backgrounds', 'main',
           'marker_corners', 'marker_family', 'marker_texture', 'MODULE', 'OPENCV_DOC_DATA',
           'Outcome', 'parse_detector_params', 'Photometrics', 'pose_trials',
           'PRINTED_MODULES', 'release_apriltags', 'render_trial', 'Row', 'run_trials',
           'score', 'stage_counts', 'STAGES', 'summarise', 'SUPERSAMPLE', 'TAG_IDS',
           'TEXTURE_PX', 'texture_homography', 'tilt_bin', 'transformed_photo', 'Trial']


if __name__ == '__main__':
    sys.exit(main())
