"""Localization: the sonar EKF / UKF core's update times, the model localizer by line source.

Run from the repository root::

    python benchmarks/bench_localization.py sonar [--runs 500] [--bag DIR]
    python benchmarks/bench_localization.py model [--frames N] [--seeds S] [--first-seed K]
        [--bag DIR]

``sonar``: one EKF / UKF update and the ray-cast time per beam. Targets: one UKF
measurement update with 16 sonars <= 3 ms, one EKF update <= 1 ms. Medians over ``--runs``
repetitions (the figures: 500) on the hallway scenario's map (``rasterize_world``, 0.1 m;
the simulated hallway run, seed 1, or with ``--bag DIR`` a recorded simulator bag with its
``ground_truth.yaml``, e.g. ``bags/hallway``), default :class:`LocalizationParams` (7 rays
per sonar cone, EKF central differences: 7 poses x 16 sonars x 7 rays = 784 rays; UKF 11
sigma points x 16 sonars x 7 rays = 1232 rays). Two cases: a recorded sonar cycle
(readings without an echo are not ray cast) and the worst case of 16 usable readings (all
ray cast).

``model``: the model localizer by line source, localization error and time per frame in one
table. Per line source (:data:`~landmark_nav.vision.rwrht.MODEL_LINE_METHODS`) the rendered hallway
run (:func:`landmark_nav.evaluation.model_localization.run_hallway_methods`: 320 x 240,
the chapter's intrinsics, people, door frames, lighting changes and pixel noise; initial
estimate drawn from the chapter's start covariance) for the first ``N`` frames of ``S``
seeds. Every source sees the same rendered frames and the sources take turns on each frame
(rotating order), so their times see the same load. Printed per source: position error
max / RMS and heading max over all frames from the first update on (the standstill frames
after the initial draw included), the position max once the robot has moved 1 cm, the NEES
fraction inside the 95 % bound, the
median time per frame of the line detector and of the filter (tracking: association,
matching and the EKF update), end-to-end frames/s (image lines + filter, the node's work
per image) and the ratio of that end-to-end time to LSD's on the same frames, since
absolute times vary between machines and with load.
Target (issue): >= 10 frames/s end to end at 320 x 240.

``model --bag DIR``: the line sources on recorded images instead: a bag with
``/camera/image_raw`` or ``/camera/image_raw/compressed`` (or a folder of png / jpg
images), the first ``--frames`` images (default all). Printed per source: the median time
per frame of the line detector, the median number of segments, frames/s and the ratio to
LSD's time on the same frames; the sources take turns on each frame, as above. The
localization errors and the filter's time need the map's line model and the true poses,
which a recording does not carry: those columns are the rendered run's only.
"""

import math
from pathlib import Path
import sys
import time
from typing import Callable, List

from common import load_images, run_subcommand, subcommand_parser
from landmark_nav.evaluation.localization import LocalizationInput
from landmark_nav.evaluation.localization_bags import load_bag_input, world_map
from landmark_nav.evaluation.model_localization import (HallwayRunConfig, run_hallway_methods,
                                                        summarize)
from landmark_nav.localization import ekf, ukf
from landmark_nav.localization.grid import rasterize_world, raycast_grid
from landmark_nav.localization.params import LocalizationParams
from landmark_nav.nodes.common import limit_threads
from landmark_nav.sim import run_scenario
from landmark_nav.vision.rwrht import detect_model_lines, MODEL_LINE_METHODS
import numpy as np
from scipy.stats import chi2


def median_ms(fn: Callable[[], object], runs: int) -> float:
    """Return the median wall time of ``fn()`` over ``runs`` calls [ms] (after a warm-up)."""
    for _ in range(5):
        fn()
    times: List[float] = []
    for _ in range(runs):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times) * 1e3)


def run_sonar(args) -> int:
    """Run the ``sonar`` subcommand: the update and ray-cast times."""
    runs = args.runs
    if args.bag:
        if not Path(args.bag, 'metadata.yaml').is_file():
            sys.exit(f'error: bag {args.bag} not found (a rosbag2 folder with metadata.yaml)')
        inp, meta = load_bag_input(Path(args.bag))
        grid = world_map(meta, 0.1)
        source = args.bag
    else:
        res = run_scenario('hallway', 1)
        inp = LocalizationInput.from_result(res)
        grid = rasterize_world(res.world, 0.1)
        source = 'hallway scenario (seed 1)'
    params = LocalizationParams()
    k = min(300, inp.truth.shape[0] - 1)
    x = inp.truth[k] + np.array([0.01, -0.01, 0.005])
    p = np.diag([0.01 ** 2, 0.01 ** 2, math.radians(0.5) ** 2])
    u = inp.controls(inp.true_k)[k - 1]
    cases = {'recorded cycle': inp.sonar_ranges[k], '16 usable readings': np.full(16, 1.0)}
    print(f'{source}: map {grid.shape}, {runs} runs per figure, median [ms]')
    for name, z in cases.items():
        n_use = int(np.sum(np.isfinite(z) & (z <= params.max_predict + params.gate)))
        _, _, sig = ukf.time_update(x, p, u, params)
        t_ekf = median_ms(lambda: ekf.measurement_update(x, p, z, grid, inp.mounts, params),
                          runs)
        t_ukf = median_ms(lambda: ukf.measurement_update(x, p, sig, z, grid, inp.mounts,
                                                         params), runs)
        print(f'{name:20s} ({n_use:2d} ray-cast sonars): EKF update {t_ekf:6.3f} '
              f'(target <= 1)   UKF update {t_ukf:6.3f} (target <= 3)')
    t_ekf_t = median_ms(lambda: ekf.time_update(x, p, u, params), runs)
    t_ukf_t = median_ms(lambda: ukf.time_update(x, p, u, params), runs)
    print(f'time update: EKF {t_ekf_t:6.3f}   UKF {t_ukf_t:6.3f}')
    rng = np.random.default_rng(0)
    for n in (112, 784, 1232):
        o = inp.truth[rng.integers(0, inp.truth.shape[0], n), :2]
        a = rng.uniform(-math.pi, math.pi, n)
        t = median_ms(lambda: raycast_grid(grid, o, a, params.max_predict), runs)
        print(f'ray cast, {n:5d} beams in one call: {t:6.3f} ms = {1e3 * t / n:5.2f} us/beam')
    return 0


def run_model_bag(args) -> int:
    """Run ``model --bag DIR``: the line sources' time per recorded frame."""
    images = [img for _, img in load_images(args.bag)][:args.frames]
    ms = {m: [] for m in MODEL_LINE_METHODS}
    count = {m: [] for m in MODEL_LINE_METHODS}
    n = len(MODEL_LINE_METHODS)
    rngs = {m: np.random.default_rng(2000) for m in MODEL_LINE_METHODS}
    for frame, img in enumerate(images):
        for k in range(n):
            method = MODEL_LINE_METHODS[(frame + k) % n]   # rotating order, as in the run
            tic = time.perf_counter()
            lines = detect_model_lines(img, method, rng=rngs[method])
            ms[method].append(1e3 * (time.perf_counter() - tic))
            count[method].append(len(lines))
    sizes = sorted({f'{img.shape[1]} x {img.shape[0]}' for img in images})
    lsd = float(np.median(ms['lsd']))
    print(f'{args.bag}: {len(images)} frames at {", ".join(sizes)}; line sources only (the '
          "filter needs the map's line model)")
    print(f'{"lines":>16} {"lines ms":>9} {"segments":>9} {"frames/s":>9} {"x LSD":>6}')
    for method in MODEL_LINE_METHODS:
        t = float(np.median(ms[method]))
        print(f'{method:>16} {t:9.1f} {float(np.median(count[method])):9.0f} {1e3 / t:9.1f} '
              f'{t / lsd:6.2f}')
    return 0


def run_model(args) -> int:
    """Run the ``model`` subcommand: one row per line source."""
    limit_threads()                      # as in the node
    if args.bag:
        return run_model_bag(args)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    by_seed = [run_hallway_methods(s, MODEL_LINE_METHODS, HallwayRunConfig(max_frames=args.frames))
               for s in seeds]
    rows = {}
    for method in MODEL_LINE_METHODS:
        runs = [r[method] for r in by_seed]
        s = [summarize(r) for r in runs]
        line_ms = np.concatenate([r.line_ms for r in runs])
        filt_ms = np.concatenate([r.filter_ms for r in runs])
        rows[method] = (max(x['pos_max_cm'] for x in s),
                        float(np.sqrt(np.mean(np.concatenate([r.position_error
                                                              for r in runs]) ** 2))) * 100,
                        max(x['head_max_deg'] for x in s),
                        max(x['pos_max_moving_cm'] for x in s),
                        100 * float(np.mean(np.concatenate([r.nees for r in runs])
                                            <= chi2.ppf(0.95, 3))),
                        float(np.median(line_ms)), float(np.median(filt_ms)),
                        float(np.median(line_ms + filt_ms)))
    lsd_total = rows['lsd'][7]
    print(f'seeds {list(seeds)}, first {args.frames} frames each, 320 x 240')
    print(f'{"lines":>16} {"pos max cm":>10} {"RMS cm":>7} {"head max":>9} {"moving cm":>9} '
          f'{"NEES 95":>8} '
          f'{"lines ms":>9} {"filter ms":>10} {"total ms":>9} {"frames/s":>9} {"x LSD":>6}')
    for method, (pm, pr, hm, mm, ne, lm, fm, tot) in rows.items():
        print(f'{method:>16} {pm:10.1f} {pr:7.1f} {hm:8.2f}d {mm:9.1f} {ne:7.0f}% {lm:9.1f} '
              f'{fm:10.1f} '
              f'{tot:9.1f} {1e3 / tot:9.1f} {tot / lsd_total:6.2f}')
    return 0


def main(argv=None) -> int:
    """Parse the subcommand and run it."""
    ap, sub = subcommand_parser(__doc__)
    p = sub.add_parser('sonar', help="time of the sonar EKF / UKF core's steps")
    p.add_argument('--runs', type=int, default=500, help='repetitions per figure (median)')
    p.add_argument('--bag', default=None, metavar='DIR',
                   help='a recorded simulator bag (with ground_truth.yaml) instead of the '
                        'simulated hallway run')
    p.set_defaults(run=run_sonar)
    p = sub.add_parser('model', help='the model localizer by line source on rendered frames '
                                     '(--bag DIR: the line sources on recorded images)')
    p.add_argument('--frames', type=int, default=150,
                   help='frames per seed (with --bag: the first N images)')
    p.add_argument('--seeds', type=int, default=1, help='number of seeds')
    p.add_argument('--first-seed', type=int, default=0)
    p.add_argument('--bag', default=None, metavar='DIR',
                   help='time the line sources on the images of this bag '
                        '(/camera/image_raw or /camera/image_raw/compressed) or folder '
                        '(png / jpg) instead of the rendered run')
    p.set_defaults(run=run_model)
    return run_subcommand(ap, argv)


if __name__ == '__main__':
    sys.exit(main())
