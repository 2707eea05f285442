"""Landmarks: the detector against ArUco, against AprilTag on real photographs; the camera sim.

Run from the repository root::

    python benchmarks/bench_landmarks.py detector [--frames N] [--repeat R] [--threads T]
        [--seed S] [--data DIR]
    python benchmarks/bench_landmarks.py detector --versus-apriltag [--data DIR] [--frames N]
        [--repeat R]
    python benchmarks/bench_landmarks.py real [detection|pose|false|stages|all]
        [--data DIR] [--per-size N] ...
    python benchmarks/bench_landmarks.py camera-sim [--frames N]
    python benchmarks/bench_landmarks.py rates [--results FILE] [--no-fail]
    python benchmarks/bench_landmarks.py shuttle [--trips 40] [--results ...] [--no-fail]

``detector``: the landmark detector against OpenCV ArUco on rendered frames of the same
size. Frames: 640 x 480 mono8, rendered by the camera simulator (f = 525 px, noise 2 DN,
defocus 0.5 px) with one landmark (random valid code, 0.175 m frame) at 1.0-2.5 m, turned
up to 40 deg and rolled at random, in front of a wall. The reference frames show an ArUco
marker (DICT_4X4_50, printed as 6 x 6 modules with its black border) of the same printed
module size as the landmark's blocks (2.5 cm) at the same poses, on the same wall, and are
processed by ``cv2.aruco.ArucoDetector.detectMarkers`` (default parameters) -- the in-run
reference of the same image size.

With ``--data DIR`` the frames are the user's instead: a folder of images (png / jpg,
converted to grey) or a bag with ``/camera/image_raw`` or ``/camera/image_raw/compressed``
(``--frames N`` spread over them; default all). Both detectors run on the same images, so
the ArUco reference sees the same size and content; with no ground truth, ``found`` counts
the frames with at least one detection. The poses use a pinhole camera of the image size
(focal length 525 px scaled to the image width, no distortion): their times do not depend
on it, their values are not printed.

Each frame's time is the best of ``--repeat`` runs, both wall clock and CPU time of this
process (``time.process_time``; less sensitive to other load on the machine); the script
prints the medians per frame, frames/s and the ratios to ArUco, for the detector alone, the
detector with the chapter's plain eq. 2 corners (no sub-pixel refinement), and detection +
Gauss-Newton pose (and cv2.solvePnP on the same corners). Targets: >= 30 frames/s and
<= 3x ArUco.

Before/after the vectorisation of the corner stage (eqs. 1-2): the same frames through a
direct numpy (float64) + ``scipy.ndimage`` implementation of the chapter's filters and
8-connected groups, against :func:`corner_pixels` + :func:`corner_groups` (OpenCV 8-bit
array operations, one sparse scan, grouping of the sparse pixels only).

``detector --versus-apriltag`` (needs ``pupil-apriltags``): CPU time per frame on sharp
photographs without a landmark (default: the 51 York Urban training images, 640 x 480, as
they are; or the images of ``--data DIR``) of the landmark detector (default and fast mode,
``decimate=2``) and AprilTag tag36h11 (``pupil_apriltags``, one thread, decimate 1 and 2)
on the same images in one run, best of ``--repeat`` per frame, medians and their ratios;
then the default detector's CPU time per step (``stage_ms`` of its ``debug`` output: corner
candidates, neighbours with the k-d tree, edge chains, frames, code fits and readings).
Targets: default <= 1.0x AprilTag decimate 1, fast <= 1.0x decimate 2.

``real`` (needs the test extra ``pupil-apriltags``, see requirements-test.txt, and the York
Urban photographs in ``../shared/data/york_urban_train`` or any folder of photographs given
with ``--data DIR``): landmarks against AprilTag 3 and OpenCV ArUco composited into real
photographs. The same trials (background, pose, print, blur, gain/gamma, noise, JPEG 70)
are rendered once per marker type and run through the landmark detector, AprilTag tag36h11
at decimate 1 and 2 and ArUco DICT_6X6_250 with sub-pixel corners, single-threaded, in one
run; it prints detection against px per module and tilt, wrong codes, false detections,
pose errors at 1 m and 2.2 m and the time per frame with its ratios. The method and every
option are those of :mod:`landmark_nav.evaluation.landmarks_real` (this subcommand is its
command line with the benchmark's defaults: 100 trials per size, 150 per distance, seed 1).

``camera-sim``: the camera simulator on 640 x 480 frames with a landmark and distractors.
It takes no data argument: what it times is the rendering of synthetic scenes, which no
recording replaces (``detector --data DIR`` times the detector on recorded images).
Three figures (median ms per frame over N frames, after one warm-up frame):

* ``render``: :meth:`CameraSimulator.render` of one fixed scene (a wall, the landmark and
  four distractors at 1.5 m, turned 30 deg; default camera with lens distortion,
  supersampling 2, gamma, vignetting, defocus and pixel noise);
* ``landmark_views``: a complete :func:`landmark_view` (scene sampling, textures, landmark
  texture and mipmaps, random photometry, render, ground truth);
* ``landmark_shuttle``: frames of the shuttle room (floor, four walls, landmark, posters).

Target: render <= 20 ms per frame. As an in-run reference it also times
``cv2.warpPerspective`` of one 640 x 480 uint8 image (the cost of a single full-frame warp).

``rates``: the detection rates of visual navigation §2.3 (Table 2) on the full samples of
their acceptance -- at least 2000 error-free reads from 5 px per block up (rotations 0,
22.5 and 45 deg, 223 frames per cell, seed 11) and 500 landmark-free frames with
distractors (300 ``views``, seed 12, and 200 ``scattered``, seed 13), through
:func:`~landmark_nav.evaluation.vision.detection_vs_size` and
:func:`~landmark_nav.evaluation.vision.false_detections`. The bounds are stored in
``--results`` (``benchmarks/results/landmarks.json``, key ``rates``: reads, P(detect) per
cell, wrong codes, share of correct reads, false detections); a figure outside its bound
(``min_*`` / ``max_*``, inclusive) is a regression and the script exits 1 naming it.
``test/test_landmark_detection_rates.py`` checks the same bounds on a smaller sample.

``shuttle``: the landmark shuttle (§2.3.3) with fixes also on the approach over 40 round
trips (seed 15, :func:`~landmark_nav.evaluation.vision.shuttle`), against the same trips
with fixes at the stops only; bounds under the key ``shuttle``: every arrival, >= 12
approach frames per trip, >= 95 % of them fixes, arrival error <= 5 cm, and max / mean
arrival error below those of the stop-only run (max) and half of them (mean).
``test/test_landmark_shuttle.py`` checks the same bounds over 20 trips.
"""

import json
import math
from pathlib import Path
import statistics
import sys
import time
from typing import Callable, Tuple

from common import load_images, run_subcommand, SHARED_DATA, subcommand_parser
import cv2
from landmark_nav.evaluation import landmarks_real
from landmark_nav.evaluation.vision import (backdrop, detection_vs_size, false_detections,
                                            format_detection, format_false, format_shuttle,
                                            landmark_in_view, random_code, shuttle,
                                            VGA_CAMERA)
from landmark_nav.sim.camera import CameraSimulator, Photometry, Plane
from landmark_nav.sim.camera_scenarios import (CameraFrame, default_camera,
                                               iter_landmark_shuttle, landmark_view,
                                               ShuttleConfig, simulator_for, view_scene,
                                               ViewOptions)
from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
from landmark_nav.vision.detector import (corner_groups, corner_pixels, detect_landmarks,
                                          DetectorParams, smooth)
from landmark_nav.vision.landmark import LandmarkDesign
from landmark_nav.vision.pose import estimate_pose, rotation_matrix, solve_pnp
import numpy as np
from scipy import ndimage

_M = np.asarray(OPTICAL_FROM_BODY)
ARUCO_DICT = cv2.aruco.DICT_4X4_50


def aruco_plane(v: np.ndarray, module: float) -> Plane:
    """Return an ArUco marker (id 7, 6 x 6 modules of ``module`` m + 1 quiet module) at v."""
    dictionary = cv2.aruco.getPredefinedDictionary(ARUCO_DICT)
    px = 16
    img = cv2.aruco.generateImageMarker(dictionary, 7, 6 * px)
    tex = np.full((8 * px, 8 * px), 255, np.uint8)
    tex[px:7 * px, px:7 * px] = img
    return Plane(tex, module / px, _M @ rotation_matrix(v[3:]), _M @ v[:3], label='aruco')


def best_ms(fn: Callable[[], object], repeat: int) -> Tuple[float, float]:
    """Return the best-of-``repeat`` wall and CPU times of one call of ``fn`` [ms]."""
    wall = cpu = math.inf
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return 1e3 * wall, 1e3 * cpu


def reference_corner_stage(img: np.ndarray) -> np.ndarray:
    """Eqs. 1-2 written directly in numpy float64 and scipy.ndimage (the "before")."""
    g = cv2.GaussianBlur(img.astype(np.float64), (3, 3), 0.95)
    h, w = g.shape
    o = 3
    sets = [((-2, -2), (2, -2), (-2, 2), (2, 2)), ((2, -2), (-2, -2), (2, 2), (-2, 2)),
            ((-3, 0), (0, -3), (0, 3), (3, 0)), ((0, -3), (-3, 0), (3, 0), (0, 3))]
    centres = []
    for offsets in sets:
        y1, y2, y3, y4 = (g[o + dy:h - o + dy, o + dx:w - o + dx] for dy, dx in offsets)
        stack = np.stack([y1, y2, y3, y4])
        kc = (stack.max(axis=0) - stack.min(axis=0)) / 3.0 + 7.0
        cond = (y1 - y2 > kc) & (y1 - y3 > kc) & (y4 - y2 > kc) & (y4 - y3 > kc)
        weight = np.where(cond, y1 + y4 - y2 - y3, 0.0)
        labels, n = ndimage.label(cond, structure=np.ones((3, 3)))
        if n:
            centres.append(np.array(ndimage.center_of_mass(weight, labels, range(1, n + 1))))
    return np.vstack(centres)[:, ::-1] + o if centres else np.zeros((0, 2))


def rendered_frames(frames: int, seed: int, design: LandmarkDesign):
    """Return ``(landmark frames, ArUco frames, codes)`` rendered at the same random poses."""
    rng = np.random.default_rng(seed)
    sim = CameraSimulator(VGA_CAMERA)
    ph = Photometry(noise_sigma=2.0, defocus_sigma=0.5)
    lm_frames, ar_frames, codes = [], [], []
    for _ in range(frames):
        d = rng.uniform(1.0, 2.5)
        v = np.array([d, rng.uniform(-0.25, 0.25) * d, rng.uniform(-0.15, 0.15) * d,
                      rng.uniform(-math.pi, math.pi), math.radians(rng.uniform(-15, 15)),
                      math.radians(rng.uniform(-40, 40))])
        wall = backdrop(rng, d + 0.5)
        code = random_code(rng, design)
        codes.append(code)
        lm_frames.append(sim.render([wall, landmark_in_view(code, design, v)], np.eye(3),
                                    np.zeros(3), ph, rng))
        ar_frames.append(sim.render([wall, aruco_plane(v, design.block_size)], np.eye(3),
                                    np.zeros(3), ph, rng))
    return lm_frames, ar_frames, codes


def image_camera(img: np.ndarray) -> CameraModel:
    """Return a pinhole camera of ``img``'s size: f = 525 px at 640 px wide, centred."""
    h, w = img.shape[:2]
    f = 525.0 * w / 640.0
    return CameraModel(w, h, np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0],
                                       [0.0, 0.0, 1.0]]), np.zeros(5))


def run_detector(args) -> int:
    """Run the ``detector`` subcommand: render the frames, time both detectors, print the table."""
    if args.threads is not None:
        cv2.setNumThreads(args.threads)
    design = LandmarkDesign()
    if args.data:
        lm_frames = [img for _, img in load_images(args.data, args.frames)]
        ar_frames, codes = lm_frames, [None] * len(lm_frames)
        cameras = [image_camera(img) for img in lm_frames]
        sizes = sorted({f'{img.shape[1]}x{img.shape[0]}' for img in lm_frames})
        source = f'{len(lm_frames)} images of {args.data} ({", ".join(sizes)}) for both'
    else:
        lm_frames, ar_frames, codes = rendered_frames(args.frames or 60, args.seed, design)
        cameras = [VGA_CAMERA] * len(lm_frames)
        source = f'{len(lm_frames)} rendered frames 640x480 mono8 per kind'
    n_frames = len(lm_frames)
    aruco = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(ARUCO_DICT),
                                    cv2.aruco.DetectorParameters())
    plain = DetectorParams(refine_corners=False, refine_edges=False)
    full = DetectorParams()
    names = ['aruco detectMarkers', 'landmark detector', 'landmark detector, eq. 2 corners only',
             'landmark detector + GN pose', 'landmark detector + solvePnP (IPPE)',
             'corner stage eqs. 1-2, numpy/scipy (before)',
             'corner stage eqs. 1-2, OpenCV 8-bit (after)']
    rows = {k: [] for k in names}
    found = dict.fromkeys(names, 0)
    for img_l, img_a, code, camera in zip(lm_frames, ar_frames, codes, cameras):
        rows[names[0]].append(best_ms(lambda: aruco.detectMarkers(img_a), args.repeat))
        found[names[0]] += int(aruco.detectMarkers(img_a)[1] is not None)
        rows[names[1]].append(best_ms(lambda: detect_landmarks(img_l, full, camera),
                                      args.repeat))
        found[names[1]] += any(code is None or d.code == code
                               for d in detect_landmarks(img_l, full, camera))
        rows[names[2]].append(best_ms(lambda: detect_landmarks(img_l, plain, camera),
                                      args.repeat))
        found[names[2]] += any(code is None or d.code == code
                               for d in detect_landmarks(img_l, plain, camera))

        def with_pose(method):
            out = []
            for d in detect_landmarks(img_l, full, camera):
                out.append(estimate_pose(d.corners, camera, design) if method == 'gn'
                           else solve_pnp(d.corners, camera, design))
            return out

        rows[names[3]].append(best_ms(lambda: with_pose('gn'), args.repeat))
        rows[names[4]].append(best_ms(lambda: with_pose('pnp'), args.repeat))
        found[names[3]] = found[names[4]] = found[names[1]]
        before = reference_corner_stage(img_l)
        after = corner_groups(corner_pixels(smooth(img_l))).points
        rows[names[5]].append(best_ms(lambda: reference_corner_stage(img_l), args.repeat))
        rows[names[6]].append(best_ms(lambda: corner_groups(corner_pixels(smooth(img_l))),
                                      args.repeat))
        found[names[5]] += len(before)
        found[names[6]] += len(after)
    ref_wall = statistics.median(t[0] for t in rows[names[0]])
    ref_cpu = statistics.median(t[1] for t in rows[names[0]])
    print(f'{source}, best of {args.repeat}, '
          f'{cv2.getNumThreads()} OpenCV threads, OpenCV {cv2.__version__}')
    print(f'{"":44s} {"wall ms":>8s} {"frames/s":>9s} {"x aruco":>8s} {"cpu ms":>8s} '
          f'{"x aruco":>8s} {"found":>8s}')
    for name in names:
        wall = statistics.median(t[0] for t in rows[name])
        cpu = statistics.median(t[1] for t in rows[name])
        what = (f'{found[name]:4d}/{n_frames}' if 'stage' not in name
                else f'{found[name] / n_frames:5.1f} c')
        print(f'{name:44s} {wall:8.2f} {1e3 / wall:9.1f} {wall / ref_wall:8.2f} {cpu:8.2f} '
              f'{cpu / ref_cpu:8.2f} {what:>8s}')
    wall = statistics.median(t[0] for t in rows[names[1]])
    cpu = statistics.median(t[1] for t in rows[names[1]])
    print('(found: frames with ' + ('a detection' if args.data else 'the right code')
          + '; for the corner stage: corners per frame)')
    print(f'targets: >= 30 frames/s {"met" if 1e3 / wall >= 30.0 else "NOT met"}; '
          f'<= 3x ArUco: wall {wall / ref_wall:.2f}x '
          f'{"met" if wall / ref_wall <= 3.0 else "NOT met"}, CPU {cpu / ref_cpu:.2f}x '
          f'{"met" if cpu / ref_cpu <= 3.0 else "NOT met"}')
    return 0


def run_versus_apriltag(args) -> int:
    """Run ``detector --versus-apriltag``: CPU time on landmark-free photos, ratios."""
    from landmark_nav.evaluation.marker_detectors import Detectors
    folder = args.data or str(SHARED_DATA / 'york_urban_train')
    frames = [img for _, img in load_images(folder, args.frames)]
    names = ('landmark', 'landmark_fast', 'apriltag1', 'apriltag2')
    cpu = {k: [] for k in names}
    found = dict.fromkeys(names, 0)
    with Detectors(names) as det:
        for img in frames:
            for name in names:
                cpu[name].append(best_ms(lambda: det.detect(name, img), args.repeat)[1])
                found[name] += len(det.detect(name, img))
    med = {k: statistics.median(v) for k, v in cpu.items()}
    sizes = sorted({f'{img.shape[1]}x{img.shape[0]}' for img in frames})
    print(f'{len(frames)} images of {folder} ({", ".join(sizes)}), CPU ms per frame '
          f'(median of the best of {args.repeat}), one thread each')
    print(f'  {"detector":28s}{"cpu ms":>8s}{"detections":>12s}')
    for name in names:
        print(f'  {name:28s}{med[name]:8.2f}{found[name]:12d}')
    r1 = med['landmark'] / med['apriltag1']
    r2 = med['landmark_fast'] / med['apriltag2']
    print(f'  default / AprilTag decimate 1: {r1:.2f}x ({"met" if r1 <= 1.0 else "NOT met"}: '
          f'<= 1.0x); fast / decimate 2: {r2:.2f}x ({"met" if r2 <= 1.0 else "NOT met"})')
    stages, counts = {}, {'corner candidates': [], 'edges (both directions)': []}
    for img in frames:
        best = {}
        for _ in range(args.repeat):
            dbg = {}
            detect_landmarks(img, debug=dbg)
            for k, v in dbg['stage_ms'].items():
                best[k] = min(best.get(k, math.inf), v)
        for k, v in best.items():
            stages.setdefault(k, []).append(v)
        counts['corner candidates'].append(len(dbg['points']))
        counts['edges (both directions)'].append(len(dbg['edges']))
    print('  default, CPU ms per step (median of the best of each frame): ' + ', '.join(
        f'{k} {statistics.median(v):.2f}' for k, v in stages.items()))
    print('  median per frame: ' + ', '.join(f'{statistics.median(v):.0f} {k}'
                                             for k, v in counts.items()))
    return 0


def _median_ms(fn, n: int) -> float:
    fn()
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1000.0 * statistics.median(times)


def run_camera_sim(args) -> int:
    """Run the ``camera-sim`` subcommand: print the timings."""
    n = args.frames
    cam = default_camera()
    sim = simulator_for(cam)
    opts = ViewOptions(distance=1.5, turn_deg=30.0, tilt_deg=5.0, roll_deg=22.5,
                       quarter_turns=False, distractors=4)
    planes, _, kinds = view_scene(np.random.default_rng(1), cam, opts)
    ph = Photometry(exposure=0.9, gradient=(0.2, -0.1), vignetting=0.2, gamma=2.2,
                    defocus_sigma=0.5, noise_sigma=2.0, shot_noise=0.02)
    rng = np.random.default_rng(2)
    eye = np.eye(3)
    render = _median_ms(lambda: sim.render(planes, eye, np.zeros(3), ph, rng), n)
    counter = iter(range(10 ** 9))
    views = _median_ms(lambda: landmark_view(1, next(counter)), n)
    shuttle = iter_landmark_shuttle(1, ShuttleConfig(trips=1000, image_rate=10.0))

    def next_frame():
        for ev in shuttle:
            if isinstance(ev, CameraFrame):
                return ev
        return None

    shuttle_ms = _median_ms(next_frame, n)
    img = (np.random.default_rng(0).random((480, 640)) * 255).astype(np.uint8)
    H = np.array([[1.0, 0.05, 3.0], [0.02, 1.0, 2.0], [1e-5, 2e-5, 1.0]])
    warp = _median_ms(lambda: cv2.warpPerspective(img, H, (640, 480)), n)
    print(f'camera simulator, 640x480 mono8, {n} frames, median per frame:')
    print(f'  render (wall + landmark + {len(kinds)} distractors): {render:7.2f} ms '
          f'(target <= 20 ms)')
    print(f'  landmark_view (scene + render + truth):         {views:7.2f} ms')
    print(f'  landmark_shuttle frame:                          {shuttle_ms:7.2f} ms '
          '(includes 10 Hz robot steps between frames)')
    print(f'  reference cv2.warpPerspective 640x480 uint8:     {warp:7.2f} ms '
          f'(render = {render / warp:.1f} x)')

    return 0


RESULTS = Path(__file__).resolve().parent / 'results' / 'landmarks.json'


def rates_figures(frames: int, false_frames: Tuple[int, int]) -> dict:
    """Return the Table 2 and false-detection figures of the ``rates`` subcommand."""
    rows = detection_vs_size(block_pixels=(5.0, 6.0, 8.0), frames=frames, seed=11)
    print(format_detection(rows), flush=True)
    reads = sum(r.detected for r in rows)
    figures = {'reads': reads, 'min_p_detect': min(r.p_detect for r in rows),
               'wrong_codes': sum(r.wrong for r in rows),
               'correct_share': sum(r.correct for r in rows) / reads if reads else 0.0,
               'false_detections': 0, 'landmark_free_frames': 0}
    for source, n, seed in (('views', false_frames[0], 12), ('scattered', false_frames[1], 13)):
        res = false_detections(frames=n, seed=seed, source=source)
        print(f'[{source}] ' + format_false(res), flush=True)
        figures['false_detections'] += res.false_detections
        figures['landmark_free_frames'] += res.frames
    return figures


def shuttle_figures(trips: int) -> dict:
    """Return the figures of the ``shuttle`` subcommand: approach fixes against stop fixes."""
    res = shuttle(trips=trips, seed=15, correction='ekf', procedure='approach')
    stop = shuttle(trips=trips, seed=15, correction='ekf', procedure='stop')
    print(format_shuttle(res) + '\n' + format_shuttle(stop), flush=True)
    return {'arrivals': res.arrivals if res.fixes == trips + 1 else 0,
            'approach_frames_per_trip': res.approach_frames / trips,
            'approach_fix_share': res.approach_fixes / max(1, res.approach_frames),
            'approach_max_error': res.max_error,
            'max_error_ratio': res.max_error / stop.max_error,
            'mean_error_ratio': res.mean_error / stop.mean_error}


def regressions(figures: dict, bounds: dict) -> list:
    """Return a message per figure outside its stored bound (``min_*`` / ``max_*`` keys)."""
    out = []
    for key, bound in bounds.items():
        kind, name = key.split('_', 1)
        value = figures[name]
        if (kind == 'min' and value < bound) or (kind == 'max' and value > bound):
            out.append(f'{name} = {value} ({kind}imum {bound})')
    return out


def run_checked(args) -> int:
    """Run ``rates`` or ``shuttle``: the figures, checked against the stored bounds."""
    path = Path(args.results)
    if not path.is_file():
        print(f'error: no stored results at {path}')
        return 1
    bounds = json.loads(path.read_text())[args.command]
    figures = (rates_figures(args.frames, (args.views, args.scattered))
               if args.command == 'rates' else shuttle_figures(args.trips))
    print('figures: ' + ', '.join(f'{k} {v:.4g}' for k, v in figures.items()))
    failed = regressions(figures, bounds)
    for msg in failed:
        print(f'REGRESSION: {msg}')
    print(f'{args.command}: ' + ('FAILED' if failed else 'all figures within their stored bounds'))
    return 1 if failed and not args.no_fail else 0


def main(argv=None) -> int:
    """Parse the subcommand and run it (``real``: the options of ``landmarks_real``)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    ap, sub = subcommand_parser(__doc__)
    p = sub.add_parser('detector', help='the detector against ArUco on rendered frames or '
                                        'on images of --data DIR')
    p.add_argument('--frames', type=int, default=None,
                   help='frames of each kind (default 60), or images spread over --data DIR '
                        '(default all)')
    p.add_argument('--repeat', type=int, default=5, help='timing repeats per frame (best)')
    p.add_argument('--seed', type=int, default=1)
    p.add_argument('--threads', type=int, default=None,
                   help='OpenCV threads (cv2.setNumThreads) for both detectors; default: '
                        "OpenCV's choice")
    p.add_argument('--data', default=None, metavar='DIR',
                   help='time both detectors on these images instead: a folder of png / jpg '
                        'images or a bag with /camera/image_raw(/compressed)')
    p.add_argument('--versus-apriltag', action='store_true',
                   help='CPU time against AprilTag decimate 1 and 2 on landmark-free photos '
                        '(--data DIR, default the York Urban training images)')
    p.set_defaults(run=lambda a: (run_versus_apriltag if a.versus_apriltag else
                                  run_detector)(a))
    sub.add_parser('real', add_help=False,
                   help='against AprilTag and ArUco on real photographs (real --help: options)')
    p = sub.add_parser('camera-sim', help='the camera simulator per frame (synthetic scenes: '
                                          'what it times is their rendering, so it takes no '
                                          'data; detector --data DIR times recorded images)')
    p.add_argument('--frames', type=int, default=100)
    p.set_defaults(run=run_camera_sim)
    p = sub.add_parser('rates', help='detection rates and false detections on the full '
                                     'samples of their acceptance, against stored bounds')
    p.add_argument('--frames', type=int, default=223,
                   help='frames per (rotation, block size) cell (default 223: 9 cells, '
                        '>= 2000 reads)')
    p.add_argument('--views', type=int, default=300, help='landmark-free views (default 300)')
    p.add_argument('--scattered', type=int, default=200,
                   help='landmark-free frames of scattered distractors (default 200)')
    p.add_argument('--results', default=str(RESULTS), help='stored bounds (JSON)')
    p.add_argument('--no-fail', action='store_true',
                   help='report regressions but exit 0 (a run on a small sample)')
    p.set_defaults(run=run_checked)
    p = sub.add_parser('shuttle', help='the shuttle with fixes on the approach against fixes '
                                       'at the stops, against stored bounds')
    p.add_argument('--trips', type=int, default=40, help='round trips (default 40)')
    p.add_argument('--results', default=str(RESULTS), help='stored bounds (JSON)')
    p.add_argument('--no-fail', action='store_true',
                   help='report regressions but exit 0 (a run on a small sample)')
    p.set_defaults(run=run_checked)
    if argv[:1] == ['real']:
        return landmarks_real.main(argv[1:], prog=f'{ap.prog} real')
    return run_subcommand(ap, argv)


if __name__ == '__main__':
    sys.exit(main())
