"""The corridor follower: per-frame pipeline and fused runs offline; closed loop over DDS.

Run from the repository root::

    python benchmarks/bench_corridor.py frames [--frames N] [--seed S] [--repeat R]
        [--speed-only] [--data DIR]
    python benchmarks/bench_corridor.py loop [--seed S] [--distance M] [--lengths N]

Both run on rendered frames of the simulated corridor (``landmark_nav.sim.corridor``,
``--seed``); ``frames --data DIR`` times the per-frame pipeline on recorded images instead.

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

``frames --data DIR``: the timing table on the user's corridor images: a folder of images
(png / jpg, converted to grey) or a bag with ``/camera/image_raw`` or
``/camera/image_raw/compressed`` (e.g. ``bags/corridor``, or one recorded by the robot's
camera); ``--frames N`` images spread over them (default all). Each image is measured at
its own size with the rendered corridor's camera (70 deg horizontal field of view; its
distortion at 640 x 480 / 1, 2, 4), mount (1.1 m high, pitched 5 deg down) and corridor
model. With no ground truth the heading and lateral errors are not printed (``-``); the
lost frames are. The hard cases and fused runs are simulations and are not run.
Targets (issue): >= 30 frames/s at 320 x 240 and >= 10 at 640 x 480; single frames
heading <= 0.5 deg and lateral <= 3 cm median; fused lateral <= 1.5 cm and heading
<= 0.5 deg RMS.

``loop``: the corridor follower in closed loop over DDS, three lengths of the corridor back
and forth. It takes no data argument: a closed loop needs a world that answers the node's
``cmd_vel``, which a recording cannot; it is the simulated corridor's. Starts the
``corridor_follower`` node in a process of its own (its shipped parameters, with the
rendered corridor's camera mount and geometry, ``stamped_cmd_vel: true`` and ``speed`` 0.5
m/s) on a private DDS domain (localhost only), and drives the simulated robot of
:mod:`landmark_nav.sim.corridor_loop` with the node's ``cmd_vel``: 320 x 240 frames at 5
Hz, odometry at 20 Hz with Kleeman noise and a 1 % right-wheel scale error, start 15 cm off
the centre line and 4 deg off the corridor axis, 2 m into the 30 m corridor, legs of 26 m
(to 2 m before the far end and back), turning on the spot at the ends with the follower
disabled.

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

from common import load_images, REPO, run_subcommand, subcommand_parser
import cv2
from landmark_nav.corridor.frame import CorridorLost, FrameParams, measure_frame
from landmark_nav.corridor.lateral import CorridorModel
from landmark_nav.evaluation.corridor_run import hard_cases, run_corridor, RunConfig
from landmark_nav.nodes.common import limit_threads
from landmark_nav.sim.camera import CameraSimulator, Photometry
from landmark_nav.sim.corridor import (corridor_scene, corridor_view, CorridorConfig,
                                       default_corridor_camera)
from landmark_nav.vision.camera import CameraModel
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


def image_camera(img: np.ndarray) -> CameraModel:
    """Return the rendered corridor's camera at ``img``'s size (70 deg horizontal FOV)."""
    h, w = img.shape[:2]
    for k in (1, 2, 4):
        cam = default_corridor_camera(k)
        if (cam.width, cam.height) == (w, h):
            return cam
    f = (w / 2.0) / math.tan(math.radians(35.0))
    return CameraModel(w, h, np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0],
                                       [0.0, 0.0, 1.0]]), np.zeros(5))


def rendered_views(cfg: CorridorConfig, mount: tuple, frames: int, seed: int) -> list:
    """Return ``frames`` rendered views of the simulated corridor at random poses."""
    sim = CameraSimulator(default_corridor_camera())
    planes = corridor_scene(cfg, seed)
    rng = np.random.default_rng(seed)
    views = []
    for _ in range(frames):
        robot = (rng.uniform(2, 20), rng.uniform(-0.5, 0.5),
                 math.radians(rng.uniform(-15, 15)))
        views.append(corridor_view(sim, planes, robot, mount,
                                   Photometry(noise_sigma=2.0, defocus_sigma=0.5), rng))
    return views


def time_pipelines(frames: list, model, mount, repeat: int) -> dict:
    """Time each line input's pipeline on ``[(image, camera, true robot pose or None)]``.

    Returns:
        ``{method: (CPU s, wall s, line CPU s, heading errors, lateral errors, lost)}``,
        the times as medians over the frames.
    """
    rows = {}
    for m in METHODS:
        p = FrameParams(line_method=m)
        cpu, wall, line_cpu, eh, ey, lost = [], [], [], [], [], 0
        for img, c, robot in frames:
            line_cpu.append(best_time(lambda: detect_lines(img, m, p.lines), repeat)[0])
            t_cpu, t_wall, meas = best_time(lambda: measure(img, c, model, mount, p), repeat)
            cpu.append(t_cpu)
            wall.append(t_wall)
            if meas is None:
                lost += 1
            elif robot is not None:
                eh.append(abs(math.degrees(meas.heading - robot[2])))
                ey.append(abs(meas.y - robot[1]))
        rows[m] = (statistics.median(cpu), statistics.median(wall),
                   statistics.median(line_cpu), eh, ey, lost)
    return rows


def print_table(rows: dict, what: str) -> None:
    """Print the timing table of :func:`time_pipelines` (``what``: the frames' description)."""
    ref_h, ref_l = rows['hough_p'][0], rows['lsd'][0]
    print(f'{what}: per-frame pipeline, CPU ms (frames/s) and wall ms; ratios of the CPU '
          f'times to the HoughLinesP- and LSD-input pipelines of this run')
    print(f'  {"lines":<16s}{"lines ms":>9s}{"CPU ms":>8s}{"fps":>7s}{"wall ms":>9s}'
          f'{"x HLP":>7s}{"x LSD":>7s}{"heading med":>13s}{"lateral med":>13s}{"lost":>6s}')
    for m, (t, tw, tl, eh, ey, lost) in rows.items():
        hm = f'{statistics.median(eh):11.3f} deg' if eh else f'{"-":>15s}'
        ym = f'{100 * statistics.median(ey):10.2f} cm' if ey else f'{"-":>13s}'
        print(f'  {m:<16s}{1e3 * tl:9.1f}{1e3 * t:8.1f}{1 / t:7.1f}{1e3 * tw:9.1f}'
              f'{t / ref_h:7.2f}{t / ref_l:7.2f}{hm}{ym}{lost:6d}')
    print()


def run_frames(args) -> int:
    """Run the ``frames`` subcommand: the timing tables, hard cases and fused runs."""
    threads = limit_threads()
    cfg = CorridorConfig()
    mount = (0.1, 0.0, 1.1, 0.0, math.radians(5.0), 0.0)
    model = CorridorModel(cfg.width, cfg.height)
    print(f'library threads: {threads}; times per frame: best of {args.repeat}, median over '
          'the frames')
    if args.data:
        images = [img for _, img in load_images(args.data, args.frames)]
        sizes = sorted({f'{img.shape[1]} x {img.shape[0]}' for img in images})
        print_table(time_pipelines([(img, image_camera(img), None) for img in images],
                                   model, mount, args.repeat),
                    f'{args.data}, {len(images)} images at {", ".join(sizes)}')
        return 0
    views = rendered_views(cfg, mount, args.frames or 40, args.seed)
    for scale, c in ((1, default_corridor_camera()), (2, default_corridor_camera(2))):
        frames = [(v.image if scale == 1 else
                   cv2.resize(v.image, (c.width, c.height), interpolation=cv2.INTER_AREA),
                   c, v.robot) for v in views]
        print_table(time_pipelines(frames, model, mount, args.repeat),
                    f'rendered corridor, {len(views)} frames at {c.width} x {c.height}')
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
    p.add_argument('--frames', type=int, default=None,
                   help='rendered frames (default 40), or images spread over --data DIR '
                        '(default all)')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--repeat', type=int, default=5, help='timing repeats per frame (best)')
    p.add_argument('--speed-only', action='store_true', help='only the timing tables')
    p.add_argument('--data', default=None, metavar='DIR',
                   help='time the pipeline on these corridor images instead (timing table '
                        'only): a folder of png / jpg images or a bag with '
                        '/camera/image_raw(/compressed), e.g. bags/corridor')
    p.set_defaults(run=run_frames)
    p = sub.add_parser('loop', help='the corridor_follower node in closed loop over DDS in the '
                                    'simulated corridor (no data: a closed loop needs a world '
                                    "that answers the node's cmd_vel)")
    p.add_argument('--seed', type=int, default=1)
    p.add_argument('--distance', type=float, default=26.0, help='leg length [m]')
    p.add_argument('--lengths', type=int, default=3, help='legs, back and forth')
    p.add_argument('--domain', type=int, default=80 + os.getpid() % 10)
    p.set_defaults(run=run_closed_loop)
    return run_subcommand(ap, argv)


if __name__ == '__main__':
    sys.exit(main())
