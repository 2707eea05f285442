"""The model localizer by line source: localization error and time per frame, one table.

Run from the repository root::

    python benchmarks/bench_model_localizer.py [--frames N] [--seeds S] [--first-seed K]

Per line source (:data:`~landmark_nav.vision.rwrht.MODEL_LINE_METHODS`) the rendered hallway
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
"""

import argparse
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.evaluation.model_localization import (HallwayRunConfig,  # noqa: E402
                                                        run_hallway_methods, summarize)
from landmark_nav.nodes.common import limit_threads  # noqa: E402
from landmark_nav.vision.rwrht import MODEL_LINE_METHODS  # noqa: E402
import numpy as np  # noqa: E402
from scipy.stats import chi2  # noqa: E402


def main() -> None:
    """Run the benchmark and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--frames', type=int, default=150)
    ap.add_argument('--seeds', type=int, default=1)
    ap.add_argument('--first-seed', type=int, default=0)
    a = ap.parse_args()
    limit_threads()                      # as in the node
    seeds = range(a.first_seed, a.first_seed + a.seeds)
    by_seed = [run_hallway_methods(s, MODEL_LINE_METHODS, HallwayRunConfig(max_frames=a.frames))
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
    print(f'seeds {list(seeds)}, first {a.frames} frames each, 320 x 240')
    print(f'{"lines":>16} {"pos max cm":>10} {"RMS cm":>7} {"head max":>9} {"moving cm":>9} '
          f'{"NEES 95":>8} '
          f'{"lines ms":>9} {"filter ms":>10} {"total ms":>9} {"frames/s":>9} {"x LSD":>6}')
    for method, (pm, pr, hm, mm, ne, lm, fm, tot) in rows.items():
        print(f'{method:>16} {pm:10.1f} {pr:7.1f} {hm:8.2f}d {mm:9.1f} {ne:7.0f}% {lm:9.1f} '
              f'{fm:10.1f} '
              f'{tot:9.1f} {1e3 / tot:9.1f} {tot / lsd_total:6.2f}')


if __name__ == '__main__':
    main()
