"""Time the line pipelines against the approxPolyDP baseline pipeline on real scans.

Run from the repository root (needs ``../shared/data/carmen``)::

    python benchmarks/bench_lines_real.py [--scans 200] [--repeat 5] [--sim] [LOG ...]

Per Carmen log (180- and 361-beam SICK scans; the FLASER reader, readings >= 40 m = no
return), ``--scans`` scans spread evenly over the log. Every pipeline starts from the raw
scan (ranges, angles, validity) and includes the segmentation, as in
``landmark_nav evaluate-features``:

* baseline: ``segment_scan`` + :func:`~landmark_nav.evaluation.scan_metrics.
  approx_poly_segments` (OpenCV ``approxPolyDP``, epsilon 5 cm, per breakpoint cluster,
  segments with their beam indices);
* ``split_merge`` and ``alfa``: ``segment_scan`` + ``extract_lines`` with the node defaults.

Each scan's time is the best of ``--repeat`` runs, the methods interleaved scan by scan so
that load on the machine hits all of them alike; the table gives the median over the
scans and its ratio to the baseline's median (issue targets: split_merge <= 2x, alfa <=
3x on every log). ``--sim`` adds the simulated office run's 1081-beam scans (270 deg, 0.25
deg), the laser of ``bench_corners.py``.
"""

import argparse
import math
from pathlib import Path
import statistics
import sys
import time
from typing import Callable, Dict, List, Tuple

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.evaluation.scan_metrics import approx_poly_segments  # noqa: E402
from landmark_nav.importers.carmen import read_carmen_scans  # noqa: E402
from landmark_nav.laser.lines import extract_lines, LineParams, METHODS  # noqa: E402
from landmark_nav.laser.segmentation import segment_scan  # noqa: E402
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
import numpy as np  # noqa: E402

LOGS = ('aces', 'seattle', 'belgioioso', 'fhw', 'freiburg-101', 'acapulco')
TARGETS = {'split_merge': 2.0, 'alfa': 3.0}
MAX_RANGE = 40.0  # [m] FLASER readings at or beyond this are no return
Scan = Tuple[np.ndarray, np.ndarray, np.ndarray, float]


def carmen_scans(name: str, count: int) -> List[Scan]:
    """Return ``count`` scans spread evenly over a Carmen log: (ranges, angles, valid, inc)."""
    path = SHARED_DATA / 'carmen' / f'{name}-corrected.log.gz'
    scans = []
    for s in read_carmen_scans(path, max_range=MAX_RANGE):
        r = np.asarray(s.ranges, dtype=float)
        angles = s.angle_min + s.angle_increment * np.arange(r.size)
        scans.append((r, angles, np.isfinite(r) & (r > 0.0), float(s.angle_increment)))
    step = max(1, len(scans) // count)
    return scans[::step][:count]


def sim_scans(count: int) -> List[Scan]:
    """Return ``count`` 1081-beam scans of the simulated office run (seed 1)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_corners import LASERS, scans_of
    laser = LASERS['1081 beams (270 deg, 0.25 deg)']
    out = []
    for s in scans_of(laser, count):
        r = s.ranges.astype(float)
        angles = s.angle_min + s.angle_increment * np.arange(r.size)
        out.append((r, angles, np.isfinite(r), float(s.angle_increment)))
    return out


def pipelines() -> Dict[str, Callable[[Scan], object]]:
    """Return the timed pipelines, baseline first."""
    params = {m: LineParams(method=m) for m in METHODS}

    def baseline(scan: Scan):
        r, a, v, inc = scan
        return approx_poly_segments(segment_scan(r, a, v, inc), 0.05)

    def extractor(method: str) -> Callable[[Scan], object]:
        p = params[method]

        def run(scan: Scan):
            r, a, v, inc = scan
            return extract_lines(segment_scan(r, a, v, inc, sigma_r=p.sigma_r), p)
        return run

    return {'approxPolyDP': baseline, **{m: extractor(m) for m in METHODS}}


def time_scans(scans: List[Scan], repeat: int) -> Dict[str, float]:
    """Return the median over scans of each pipeline's best-of-``repeat`` time [ms]."""
    pipes = pipelines()
    times: Dict[str, List[float]] = {k: [] for k in pipes}
    for scan in scans:
        for k, fn in pipes.items():
            best = math.inf
            for _ in range(repeat):
                t0 = time.perf_counter()
                fn(scan)
                best = min(best, time.perf_counter() - t0)
            times[k].append(1e3 * best)
    return {k: statistics.median(v) for k, v in times.items()}


def main() -> None:
    """Run the benchmark and print one table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS), help='log names (default: all six)')
    ap.add_argument('--scans', type=int, default=200, help='scans per log')
    ap.add_argument('--repeat', type=int, default=5, help='timing repeats per scan (best)')
    ap.add_argument('--sim', action='store_true', help='also the 1081-beam office scans')
    args = ap.parse_args()
    sets = {}
    for name in args.logs:
        path = SHARED_DATA / 'carmen' / f'{name}-corrected.log.gz'
        if not path.exists():
            print(f'{path}: not present')
            continue
        sets[name] = carmen_scans(name, args.scans)
    if args.sim:
        sets['office sim'] = sim_scans(args.scans)
    print('| scans | beams | approxPolyDP ms | split_merge ms (x) | alfa ms (x) | targets |')
    print('| --- | --- | --- | --- | --- | --- |')
    for name, scans in sets.items():
        med = time_scans(scans, args.repeat)
        base = med['approxPolyDP']
        ratio = {m: med[m] / base for m in METHODS}
        met = ', '.join(f'{m} <= {t:g}x {"met" if ratio[m] <= t else "NOT met"}'
                        for m, t in TARGETS.items())
        print(f'| {name} ({len(scans)}) | {scans[0][0].size} | {base:.3f} | '
              f'{med["split_merge"]:.3f} ({ratio["split_merge"]:.2f}) | '
              f'{med["alfa"]:.3f} ({ratio["alfa"]:.2f}) | {met} |', flush=True)


if __name__ == '__main__':
    main()
