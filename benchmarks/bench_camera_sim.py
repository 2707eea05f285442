"""Time the camera simulator on 640 x 480 frames with a landmark and distractors.

Run from the repository root::

    python benchmarks/bench_camera_sim.py [--frames N]

Three figures (median ms per frame over N frames, after one warm-up frame):

* ``render``: :meth:`CameraSimulator.render` of one fixed scene (a wall, the landmark and
  four distractors at 1.5 m, turned 30 deg; default camera with lens distortion,
  supersampling 2, gamma, vignetting, defocus and pixel noise);
* ``landmark_views``: a complete :func:`landmark_view` (scene sampling, textures, landmark
  texture and mipmaps, random photometry, render, ground truth);
* ``landmark_shuttle``: frames of the shuttle room (floor, four walls, landmark, posters).

Target: render <= 20 ms per frame. As an in-run reference it also times
``cv2.warpPerspective`` of one 640 x 480 uint8 image (the cost of a single full-frame warp).
"""

import argparse
from pathlib import Path
import statistics
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402
from landmark_nav.sim.camera import Photometry  # noqa: E402
from landmark_nav.sim.camera_scenarios import (CameraFrame, default_camera,  # noqa: E402
                                               iter_landmark_shuttle, landmark_view,
                                               ShuttleConfig, simulator_for, view_scene,
                                               ViewOptions)
import numpy as np  # noqa: E402


def _median_ms(fn, n: int) -> float:
    fn()
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1000.0 * statistics.median(times)


def main() -> None:
    """Print the timings."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--frames', type=int, default=100)
    args = ap.parse_args()
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


if __name__ == '__main__':
    main()
