"""The corridor follower's per-frame pipeline on rendered frames, and a fused run.

Run from the repository root::

    python benchmarks/bench_corridor.py [--frames N] [--seed S]

Per-frame time of :func:`landmark_nav.corridor.frame.measure_frame` (lines, corridor VP,
heading, lateral position) for each line input, at 640 x 480 and 320 x 240 on the same
rendered corridor frames (``landmark_nav.sim.corridor``), with the ratios to the
HoughLinesP- and LSD-input pipelines in the same run (machines differ), and the
single-frame errors; the hard cases; then a fused 27 m run and a closed loop of three
lengths back and forth (:func:`landmark_nav.evaluation.corridor_run.run_corridor`).

Times: the numerical libraries single-threaded, as in the node
(:func:`landmark_nav.nodes.common.limit_threads`); per frame the best of ``--repeat`` runs
of the process CPU time (``time.process_time``: what the frame costs, hardly changed by
other jobs on a shared machine) and of the wall time; the medians over the frames.
``--speed-only`` stops after the timing tables.
Targets (issue): >= 30 frames/s at 320 x 240 and >= 10 at 640 x 480; single frames
heading <= 0.5 deg and lateral <= 3 cm median; fused lateral <= 1.5 cm and heading
<= 0.5 deg RMS.
"""

import argparse
import math
from pathlib import Path
import statistics
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402
from landmark_nav.corridor.frame import CorridorLost, FrameParams, measure_frame  # noqa: E402
from landmark_nav.corridor.lateral import CorridorModel  # noqa: E402
from landmark_nav.evaluation.corridor_run import (hard_cases, run_corridor,  # noqa: E402
                                                  RunConfig)
from landmark_nav.nodes.common import limit_threads  # noqa: E402
from landmark_nav.sim.camera import CameraSimulator, Photometry  # noqa: E402
from landmark_nav.sim.corridor import (corridor_scene, corridor_view,  # noqa: E402
                                       CorridorConfig, default_corridor_camera)
from landmark_nav.vision.image_lines import detect_lines, METHODS  # noqa: E402
import numpy as np  # noqa: E402


def best_time(fn, repeat: int):
    """Return (best process CPU time, best wall time) [s] of ``repeat`` calls, last result."""
    cpu, wall, out = math.inf, math.inf, None
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        out = fn()
        cpu, wall = min(cpu, time.process_time() - c0), min(wall, time.perf_counter() - w0)
    return cpu, wall, out


def measure(img, c, model, mount, p):
    """Return the frame's measurement or None when the corridor is lost."""
    try:
        return measure_frame(img, c, model, mount, params=p)
    except CorridorLost:
        return None


def main() -> None:
    """Run the benchmark and print the tables."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--frames', type=int, default=40)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--repeat', type=int, default=5, help='timing repeats per frame (best)')
    ap.add_argument('--speed-only', action='store_true', help='only the timing tables')
    args = ap.parse_args()
    threads = limit_threads()
    cfg = CorridorConfig()
    cam = default_corridor_camera()
    sim = CameraSimulator(cam)
    planes = corridor_scene(cfg, args.seed)
    mount = (0.1, 0.0, 1.1, 0.0, math.radians(5.0), 0.0)
    model = CorridorModel(cfg.width, cfg.height)
    rng = np.random.default_rng(args.seed)
    views = []
    for _ in range(args.frames):
        robot = (rng.uniform(2, 20), rng.uniform(-0.5, 0.5),
                 math.radians(rng.uniform(-15, 15)))
        views.append(corridor_view(sim, planes, robot, mount,
                                   Photometry(noise_sigma=2.0, defocus_sigma=0.5), rng))
    print(f'library threads: {threads}; times per frame: best of {args.repeat}, median over '
          'the frames')
    for scale, c in ((1, cam), (2, default_corridor_camera(2))):
        rows = {}
        for m in METHODS:
            p = FrameParams(line_method=m)
            cpu, wall, line_cpu, eh, ey, lost = [], [], [], [], [], 0
            for v in views:
                img = v.image
                if scale != 1:
                    img = cv2.resize(img, (c.width, c.height), interpolation=cv2.INTER_AREA)
                line_cpu.append(best_time(lambda: detect_lines(img, m, p.lines),
                                          args.repeat)[0])
                t_cpu, t_wall, meas = best_time(lambda: measure(img, c, model, mount, p),
                                                args.repeat)
                cpu.append(t_cpu)
                wall.append(t_wall)
                if meas is None:
                    lost += 1
                    continue
                eh.append(abs(math.degrees(meas.heading - v.robot[2])))
                ey.append(abs(meas.y - v.robot[1]))
            rows[m] = (statistics.median(cpu), statistics.median(wall),
                       statistics.median(line_cpu), eh, ey, lost)
        ref_h, ref_l = rows['hough_p'][0], rows['lsd'][0]
        print(f'rendered corridor, {len(views)} frames at {c.width} x {c.height}: per-frame '
              f'pipeline, CPU ms (frames/s) and wall ms; ratios of the CPU times to the '
              f'HoughLinesP- and LSD-input pipelines of this run')
        print(f'  {"lines":<16s}{"lines ms":>9s}{"CPU ms":>8s}{"fps":>7s}{"wall ms":>9s}'
              f'{"x HLP":>7s}{"x LSD":>7s}{"heading med":>13s}{"lateral med":>13s}{"lost":>6s}')
        for m, (t, tw, tl, eh, ey, lost) in rows.items():
            hm = statistics.median(eh) if eh else math.nan
            ym = statistics.median(ey) if ey else math.nan
            print(f'  {m:<16s}{1e3 * tl:9.1f}{1e3 * t:8.1f}{1 / t:7.1f}{1e3 * tw:9.1f}'
                  f'{t / ref_h:7.2f}{t / ref_l:7.2f}{hm:11.3f} deg{100 * ym:10.2f} cm{lost:6d}')
        print()
    if args.speed_only:
        return
    print('hard cases (20 frames each; medians / worst):')
    for case, r in hard_cases().items():
        print(f'  {case:<10s} lost {r["lost"]:.0f}, heading {r["heading_median_deg"]:.3f} / '
              f'{r["heading_max_deg"]:.3f} deg, lateral {100 * r["lateral_median"]:.2f} / '
              f'{100 * r["lateral_max"]:.2f} cm')
    print()
    s = run_corridor(RunConfig(), args.seed).summary()
    print('fused 27 m run (5 frames/s, 20 Hz odometry, 1 % right-wheel scale error):')
    print('  ' + ', '.join(f'{k} {v:.4g}' for k, v in s.items()))
    s = run_corridor(RunConfig(lengths=3), args.seed).summary()
    print('closed loop, 3 x 27 m back and forth (turning on the spot at the ends):')
    print('  ' + ', '.join(f'{k} {v:.4g}' for k, v in s.items()))


if __name__ == '__main__':
    main()
