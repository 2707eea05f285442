#!/usr/bin/env python3
"""Benchmark of the sonar localization core: one EKF / UKF update, ray-cast time per beam.

Run from the repository root::

    python benchmarks/bench_localization.py [--runs 500]

Targets (issue 6): one UKF measurement update with 16 sonars <= 3 ms, one EKF update
<= 1 ms. Medians over ``--runs`` repetitions (>= 200) on the hallway scenario map
(``rasterize_world``, 0.1 m), default :class:`LocalizationParams` (7 rays per sonar cone,
EKF central differences: 7 poses x 16 sonars x 7 rays = 784 rays; UKF 11 sigma points x 16
sonars x 7 rays = 1232 rays). Two cases: a recorded sonar cycle (readings without an echo
are not ray cast) and the worst case of 16 usable readings (all ray cast).
"""

import argparse
import math
from pathlib import Path
import sys
import time
from typing import Callable, List

import numpy as np


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


def main() -> int:
    """Run the benchmark and print the medians."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--runs', type=int, default=500)
    args = ap.parse_args()
    runs = max(200, args.runs)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout
    from landmark_nav.localization import ekf, ukf
    from landmark_nav.evaluation.localization import LocalizationInput
    from landmark_nav.localization.grid import rasterize_world, raycast_grid
    from landmark_nav.localization.params import LocalizationParams
    from landmark_nav.sim import run_scenario
    res = run_scenario('hallway', 1)
    inp = LocalizationInput.from_result(res)
    grid = rasterize_world(res.world, 0.1)
    params = LocalizationParams()
    k = 300
    x = inp.truth[k] + np.array([0.01, -0.01, 0.005])
    p = np.diag([0.01 ** 2, 0.01 ** 2, math.radians(0.5) ** 2])
    u = inp.controls(inp.true_k)[k - 1]
    cases = {'recorded cycle': inp.sonar_ranges[k], '16 usable readings': np.full(16, 1.0)}
    print(f'hallway map {grid.shape}, {runs} runs per figure, median [ms]')
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


if __name__ == '__main__':
    raise SystemExit(main())
