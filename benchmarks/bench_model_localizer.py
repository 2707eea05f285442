"""The model localizer's per-frame pipeline (image lines + match + EKF) on rendered frames.

Run from the repository root::

    python benchmarks/bench_model_localizer.py [--frames N] [--seed S]

Frames: the rendered hallway (``landmark_nav.sim.model_scene``, people, door frames, pixel
noise) at 320 x 240 with the chapter's intrinsics, at true poses along the ``hallway``
scenario. Per line source: the time of the line detector and of the filter update (the
filter starts each frame from the true pose with the chapter's start covariance, so every
frame runs the full association), end-to-end frames/s, and the ratio of the end-to-end
time to LSD's line detection alone on the same frames (machines differ). Target (issue):
>= 10 frames/s end to end at 320 x 240.
"""

import argparse
from pathlib import Path
import statistics
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.monocular.localizer import CHAPTER_START_COV, ModelLocalizer  # noqa: E402
from landmark_nav.monocular.model import hallway_model  # noqa: E402
from landmark_nav.monocular.visibility import (camera_pose, CameraMount,  # noqa: E402
                                               Intrinsics)
from landmark_nav.nodes.common import limit_threads  # noqa: E402
from landmark_nav.sim.camera import CameraSimulator, Photometry, RenderOptions  # noqa: E402
from landmark_nav.sim.model_scene import (door_frame_planes, model_planes,  # noqa: E402
                                          scene_at, SceneClutter)
from landmark_nav.vision.camera import CameraModel  # noqa: E402
from landmark_nav.vision.rwrht import detect_model_lines, MODEL_LINE_METHODS  # noqa: E402
import numpy as np  # noqa: E402


def main() -> None:
    """Run the benchmark and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--frames', type=int, default=40)
    ap.add_argument('--seed', type=int, default=0)
    a = ap.parse_args()
    limit_threads()                      # as in the node
    model = hallway_model()
    K = Intrinsics.chapter()
    mount = CameraMount()
    sim = CameraSimulator(CameraModel(K.width, K.height, K.K, np.zeros(5)),
                          RenderOptions(supersample=4))
    static = model_planes(model, a.seed) + door_frame_planes(model)
    rng = np.random.default_rng(a.seed)
    frames = []
    for k in range(a.frames):
        t = 0.5 * k
        pose = np.array([1.0 + 17.0 * k / max(1, a.frames - 1), rng.uniform(-0.2, 0.2),
                         rng.uniform(-0.05, 0.05)])
        R, c = camera_pose(pose, mount)
        img = sim.render(scene_at(static, SceneClutter(), t, 21.5, a.seed), R, c,
                         Photometry(noise_sigma=2.0), rng)
        frames.append((pose, img))
    lsd_ms = []
    for _, img in frames:
        tic = time.perf_counter()
        detect_model_lines(img, 'lsd')
        lsd_ms.append(1e3 * (time.perf_counter() - tic))
    lsd_med = statistics.median(lsd_ms)
    print(f'{a.frames} frames 320 x 240; LSD line detection alone: median {lsd_med:.1f} ms')
    print(f'{"lines":>16} {"lines ms":>9} {"filter ms":>10} {"total ms":>9} {"frames/s":>9} '
          f'{"x LSD":>7} {"pairs":>6}')
    for method in MODEL_LINE_METHODS:
        line_ms, filt_ms, pairs = [], [], []
        det_rng = np.random.default_rng(a.seed)
        for pose, img in frames:
            loc = ModelLocalizer(model, K, mount)
            loc.reset(pose, CHAPTER_START_COV, 0.0)
            tic = time.perf_counter()
            lines = detect_model_lines(img, method, rng=det_rng)
            toc = time.perf_counter()
            res = loc.update(lines.segments, 0.1)
            tac = time.perf_counter()
            line_ms.append(1e3 * (toc - tic))
            filt_ms.append(1e3 * (tac - toc))
            pairs.append(len(res.matches) if res.updated else 0)
        lm, fm = statistics.median(line_ms), statistics.median(filt_ms)
        total = lm + fm
        print(f'{method:>16} {lm:9.1f} {fm:10.1f} {total:9.1f} {1e3 / total:9.1f} '
              f'{total / lsd_med:7.2f} {statistics.median(pairs):6.0f}')


if __name__ == '__main__':
    main()
