"""The corridor follower: per-frame pipeline and fused runs offline; closed loop over DDS.

Run from the repository root::

    python benchmarks/bench_corridor.py frames [--frames N] [--seed S] [--repeat R]
        [--speed-only]
    python benchmarks/bench_corridor.py loop [--seed S] [--distance M] [--lengths N]

Both run on rendered frames of the simulated corridor (``landmark_nav.sim.corridor``,
``--seed``).

``frames``: per-frame time of :func:`landmark_nav.corridor.frame.measure_frame` (lines,
corridor VP, heading, lateral position) for each line input, at 640 x 480 and 320 x 240 on
the same rendered corridor frames (``landmark_nav.sim.corridor``), with the ratios to the
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

``loop``: the corridor follower in closed loop over DDS, three lengths of the corridor back
and forth. Starts the ``corridor_follower`` node in a process of its own (its shipped parameters,
with the rendered corridor's camera mount and geometry, ``stamped_cmd_vel: true`` and
``speed`` 0.5 m/s) on a private DDS domain (localhost only), and drives the simulated robot
of :mod:`landmark_nav.sim.corridor_loop` with the node's ``cmd_vel``: 320 x 240 frames at
5 Hz, odometry at 20 Hz with Kleeman noise and a 1 % right-wheel scale error, start 15 cm
off the centre line and 4 deg off the corridor axis, 2 m into the 30 m corridor, legs of
26 m (to 2 m before the far end and back), turning on the spot at the ends with the
follower disabled.

Acceptance (issue): within 5 cm of the centre line on 3 lengths, never touching a wall
(robot radius 0.25 m). The lateral figures are taken after the first 2 m of path (the
start transient from 15 cm off).
"""

import math
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time

from common import REPO, run_subcommand, subcommand_parser
import cv2
from landmark_nav.corridor.frame import CorridorLost, FrameParams, measure_frame
from landmark_nav.corridor.lateral import CorridorModel
from landmark_nav.evaluation.corridor_run import hard_cases, run_corridor, RunConfig
from landmark_nav.nodes.common import limit_threads
from landmark_nav.sim.camera import CameraSimulator, Photometry
from landmark_nav.sim.corridor import (corridor_scene, corridor_view, CorridorConfig,
                                       default_corridor_camera)
from landmark_nav.vision.image_lines import detect_lines, METHODS
import numpy as np
import yaml


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


def run_frames(args) -> int:
    """Run the ``frames`` subcommand: the timing tables, hard cases and fused runs."""
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
        return 0
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
    return 0


def run_closed_loop(args) -> int:
    """Run the ``loop`` subcommand: run the loop and print its figures."""
    os.environ['ROS_DOMAIN_ID'] = str(args.domain)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    import rclpy  # (after the domain is set)
    from landmark_nav.sim.corridor_loop import follower_parameters, LoopConfig, run_loop
    from landmark_nav.tools.config_files import config_path
    cfg = LoopConfig(start=(2.0, 0.15, math.radians(4.0)), distance=args.distance,
                     lengths=args.lengths)
    params = yaml.safe_load(Path(config_path('corridor_follower')).read_text())
    params['corridor_follower']['ros__parameters'].update(follower_parameters(cfg))
    with tempfile.TemporaryDirectory() as tmp:
        pfile = Path(tmp) / 'corridor_follower.yaml'
        pfile.write_text(yaml.safe_dump(params))
        env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep
                   + os.environ.get('PYTHONPATH', ''))
        node = subprocess.Popen([sys.executable, '-m', 'landmark_nav.nodes.corridor_follower',
                                 '--ros-args', '--params-file', str(pfile),
                                 '--log-level', 'error'], env=env, cwd=REPO)
        context = rclpy.Context()
        rclpy.init(context=context)
        try:
            result = run_loop(context, cfg, seed=args.seed)
        finally:
            node.terminate()
            node.wait(timeout=30)
            rclpy.try_shutdown(context=context)
    s = result.summary()
    print(f'closed loop over DDS, {args.lengths} x {args.distance:.0f} m back and forth '
          f'(seed {args.seed}): {s["steps"]:.0f} odometry steps, {s["frames"]:.0f} frames, '
          f'path {s["path_m"]:.1f} m, legs {", ".join(f"{v:.1f}" for v in result.legs)} m, '
          f'{s["wall_seconds"]:.0f} s wall')
    print(f'  lateral after the first 2 m: max {100 * s["max_abs_lateral_after_2m"]:.2f} cm, '
          f'RMS {100 * s["rms_lateral_after_2m"]:.2f} cm (start {100 * cfg.start[1]:.0f} cm '
          f'off); smallest wall clearance {100 * s["min_wall_clearance"]:.1f} cm '
          f'(robot radius {100 * cfg.robot_radius:.0f} cm)')
    ok = (s['max_abs_lateral_after_2m'] <= 0.05 and s['min_wall_clearance'] > 0
          and len(result.legs) == args.lengths)
    print('  acceptance (within 5 cm, no wall touched):', 'met' if ok else 'NOT met')
    return 0


def main(argv=None) -> int:
    """Parse the subcommand and run it."""
    ap, sub = subcommand_parser(__doc__)
    p = sub.add_parser('frames', help='per-frame pipeline, hard cases and fused runs offline')
    p.add_argument('--frames', type=int, default=40)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--repeat', type=int, default=5, help='timing repeats per frame (best)')
    p.add_argument('--speed-only', action='store_true', help='only the timing tables')
    p.set_defaults(run=run_frames)
    p = sub.add_parser('loop', help='the corridor_follower node in closed loop over DDS')
    p.add_argument('--seed', type=int, default=1)
    p.add_argument('--distance', type=float, default=26.0, help='leg length [m]')
    p.add_argument('--lengths', type=int, default=3, help='legs, back and forth')
    p.add_argument('--domain', type=int, default=80 + os.getpid() % 10)
    p.set_defaults(run=run_closed_loop)
    return run_subcommand(ap, argv)


if __name__ == '__main__':
    sys.exit(main())
