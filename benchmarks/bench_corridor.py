"""The corridor follower's per-frame pipeline on rendered frames, and a fused run.

Run from the repository root::

    python benchmarks/bench_corridor.py [--frames N] [--seed S]

Per-frame time of :func:`landmark_nav.corridor.frame.measure_frame` (lines, corridor VP,
heading, lateral position) for each line input, at 640 x 480 and 320 x 240 on the same
rendered corridor frames (``landmark_nav.sim.corridor``), with the ratio to the LSD-input
pipeline in the same run (machines differ), and the single-frame errors; the hard cases;
then a fused 27 m run and a closed loop of three lengths back and forth
(:func:`landmark_nav.evaluation.corridor_run.run_corridor`).
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
from landmark_nav.sim.camera import CameraSimulator, Photometry  # noqa: E402
from landmark_nav.sim.corridor import (corridor_scene, corridor_view,  # noqa: E402
                                       CorridorConfig, default_corridor_camera)
from landmark_nav.vision.camera import CameraModel  # noqa: E402
from landmark_nav.vision.image_lines import METHODS  # noqa: E402
import numpy as np  # noqa: E402


def half(cam: CameraModel) -> CameraModel:
    """Return the camera at half resolution (pixel centres at integer coordinates)."""
    S = np.array([[0.5, 0.0, -0.25], [0.0, 0.5, -0.25], [0.0, 0.0, 1.0]])
    return CameraModel(cam.width // 2, cam.height // 2, S @ cam.K, cam.D)


def main() -> None:
    """Run the benchmark and print the tables."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--frames', type=int, default=40)
    ap.add_argument('--seed', type=int, default=0)
    args = ap.parse_args()
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
    for scale, c in ((1, cam), (2, half(cam))):
        rows = {}
        for m in METHODS:
            p = FrameParams(line_method=m)
            times, eh, ey, lost = [], [], [], 0
            for v in views:
                img = v.image
                if scale != 1:
                    img = cv2.resize(img, (c.width, c.height), interpolation=cv2.INTER_AREA)
                best = math.inf
                for _ in range(3):
                    t0 = time.perf_counter()
                    try:
                        meas = measure_frame(img, c, model, mount, params=p)
                    except CorridorLost:
                        meas = None
                    best = min(best, time.perf_counter() - t0)
                times.append(best)
                if meas is None:
                    lost += 1
                    continue
                eh.append(abs(math.degrees(meas.heading - v.robot[2])))
                ey.append(abs(meas.y - v.robot[1]))
            rows[m] = (statistics.median(times), eh, ey, lost)
        ref = rows['lsd'][0]
        print(f'rendered corridor, {len(views)} frames at {c.width} x {c.height} '
              f'(median per frame; ratio to the LSD-input pipeline = {1e3 * ref:.1f} ms)')
        print(f'  {"lines":<16s}{"ms":>7s}{"fps":>7s}{"x LSD":>7s}{"heading med":>13s}'
              f'{"lateral med":>13s}{"lost":>6s}')
        for m, (t, eh, ey, lost) in rows.items():
            hm = statistics.median(eh) if eh else math.nan
            ym = statistics.median(ey) if ey else math.nan
            print(f'  {m:<16s}{1e3 * t:7.1f}{1 / t:7.1f}{t / ref:7.2f}{hm:11.3f} deg'
                  f'{100 * ym:10.2f} cm{lost:6d}')
        print()
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
