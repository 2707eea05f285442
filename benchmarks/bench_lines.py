"""Time the two line extractors against cv2.approxPolyDP, on simulated and on real scans.

Run from the repository root::

    python benchmarks/bench_lines.py clusters [--scans N] [--repeat R] [--bag DIR]
    python benchmarks/bench_lines.py logs [--data DIR] [--scans 200] [--repeat 5] [--sim]
        [LOG ...]

``clusters``: the extractors alone on the same clusters as ``bench_corners.py timing``,
against the in-run C++ reference ``cv2.approxPolyDP`` (epsilon = the split-and-merge
threshold, one call per cluster). Scans of the simulated office run (seed 1) with the
default 361-beam LMS200-like laser and a 1081-beam laser (270 deg, 0.25 deg), or with
``--bag DIR`` the ``/scan`` of a recorded bag (one table). Targets: split_merge <= 1 ms per
1081-beam scan and <= 15x approxPolyDP; alfa <= 5 ms.

``logs``: whole pipelines on real scans against the approxPolyDP baseline pipeline. Per
Carmen log (``--data DIR``, default ``../shared/data/carmen``; a LOG is a name there, e.g.
``aces``, or a path to a Carmen log; 180- and 361-beam SICK scans read by the FLASER
reader, readings >= 40 m = no return), ``--scans`` scans spread evenly over the log. Every
pipeline starts from the raw scan (ranges, angles, validity) and includes the
segmentation, as in ``landmark_nav evaluate-features``:

* baseline: ``segment_scan`` + :func:`~landmark_nav.evaluation.scan_metrics.
  approx_poly_segments` (OpenCV ``approxPolyDP``, epsilon 5 cm, per breakpoint cluster,
  segments with their beam indices);
* ``split_merge`` and ``alfa``: ``segment_scan`` + ``extract_lines`` with the node defaults.

Each scan's time is the best of ``--repeat`` runs, the methods interleaved scan by scan so
that load on the machine hits all of them alike; the table gives the median over the
scans and its ratio to the baseline's median (targets: split_merge <= 2x, alfa <= 3x on
every log). ``--sim`` adds the simulated office run's 1081-beam scans.
"""

import statistics
import sys
from typing import Callable, Dict, List, Tuple

from common import (add_logs_argument, approx_poly, bag_scans, best_ms, CARMEN_LOGS, LASERS,
                    log_paths, office_scans, run_subcommand, spread, subcommand_parser)
from landmark_nav.evaluation.scan_metrics import approx_poly_segments
from landmark_nav.importers.carmen import read_carmen_scans
from landmark_nav.laser.lines import extract_lines, LineParams, METHODS
from landmark_nav.laser.segmentation import segment_scan
import numpy as np

CLUSTER_TARGETS = {'split_merge': (1.0, 15.0), 'alfa': (5.0, None)}
PIPELINE_TARGETS = {'split_merge': 2.0, 'alfa': 3.0}
MAX_RANGE = 40.0  # [m] FLASER readings at or beyond this are no return
Scan = Tuple[np.ndarray, np.ndarray, np.ndarray, float]


def clusters_table(name: str, scans: list, repeat: int) -> None:
    """Print the per-cluster timing table of ``scans``."""
    params = {m: LineParams(method=m) for m in METHODS}
    eps = params['split_merge'].threshold
    times = {k: [] for k in ('approxPolyDP', *METHODS)}
    found = dict.fromkeys(METHODS, 0)
    for s in scans:
        r = s.ranges.astype(float)
        angles = s.angle_min + s.angle_increment * np.arange(r.size)
        clusters = segment_scan(r, angles, np.isfinite(r), s.angle_increment)
        times['approxPolyDP'].append(best_ms(lambda: approx_poly(clusters, eps), repeat))
        for m in METHODS:
            found[m] += len(extract_lines(clusters, params[m]))
            times[m].append(best_ms(lambda: extract_lines(clusters, params[m]), repeat))
    med = {k: statistics.median(v) for k, v in times.items()}
    print(f'{name}: {len(scans)} scans')
    print(f'  {"method":<14s} {"median ms/scan":>15s} {"x approxPolyDP":>15s} {"lines":>7s}')
    for k in ('approxPolyDP', *METHODS):
        extra = f'{found[k]:7d}' if k in found else ''
        print(f'  {k:<14s} {med[k]:15.3f} {med[k] / med["approxPolyDP"]:15.1f} {extra}')
    if '1081' in name:
        for m, (ms, ratio) in CLUSTER_TARGETS.items():
            print(f'  {m}: <= {ms} ms {"met" if med[m] <= ms else "NOT met"}', end='')
            if ratio is not None:
                ok = med[m] <= ratio * med['approxPolyDP']
                print(f', <= {ratio:g}x approxPolyDP {"met" if ok else "NOT met"}', end='')
            print()
    print()


def run_clusters(args) -> int:
    """Run the ``clusters`` subcommand."""
    if args.bag:
        scans = bag_scans(args.bag, args.scans)
        clusters_table(f'{args.bag} ({len(scans[0].ranges)} beams)', scans, args.repeat)
        return 0
    for name, laser in LASERS.items():
        clusters_table(f'{name}, office', office_scans(laser, args.scans), args.repeat)
    return 0


def carmen_scans(path, count: int) -> List[Scan]:
    """Return ``count`` scans spread evenly over a Carmen log: (ranges, angles, valid, inc)."""
    scans = []
    for s in read_carmen_scans(path, max_range=MAX_RANGE):
        r = np.asarray(s.ranges, dtype=float)
        angles = s.angle_min + s.angle_increment * np.arange(r.size)
        scans.append((r, angles, np.isfinite(r) & (r > 0.0), float(s.angle_increment)))
    return spread(scans, count)


def sim_scans(count: int) -> List[Scan]:
    """Return ``count`` 1081-beam scans of the simulated office run (seed 1)."""
    out = []
    for s in office_scans(LASERS['1081 beams (270 deg, 0.25 deg)'], count):
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
            times[k].append(best_ms(lambda: fn(scan), repeat))
    return {k: statistics.median(v) for k, v in times.items()}


def run_logs(args) -> int:
    """Run the ``logs`` subcommand."""
    sets = {name: carmen_scans(path, args.scans)
            for name, path in log_paths(args.data, args.logs)}
    if args.sim:
        sets['office sim'] = sim_scans(args.scans)
    print('| scans | beams | approxPolyDP ms | split_merge ms (x) | alfa ms (x) | targets |')
    print('| --- | --- | --- | --- | --- | --- |')
    for name, scans in sets.items():
        med = time_scans(scans, args.repeat)
        base = med['approxPolyDP']
        ratio = {m: med[m] / base for m in METHODS}
        met = ', '.join(f'{m} <= {t:g}x {"met" if ratio[m] <= t else "NOT met"}'
                        for m, t in PIPELINE_TARGETS.items())
        print(f'| {name} ({len(scans)}) | {scans[0][0].size} | {base:.3f} | '
              f'{med["split_merge"]:.3f} ({ratio["split_merge"]:.2f}) | '
              f'{med["alfa"]:.3f} ({ratio["alfa"]:.2f}) | {met} |', flush=True)
    return 0


def main(argv=None) -> int:
    """Parse the subcommand and run it."""
    ap, sub = subcommand_parser(__doc__)
    p = sub.add_parser('clusters', help='the extractors alone on simulated clusters')
    p.add_argument('--scans', type=int, default=200, help='scans per laser')
    p.add_argument('--repeat', type=int, default=5, help='timing repeats per scan (best)')
    p.add_argument('--bag', default=None, metavar='DIR',
                   help="a recorded bag's /scan instead of the simulated office scans")
    p.set_defaults(run=run_clusters)
    p = sub.add_parser('logs', help='whole pipelines on real Carmen scans')
    add_logs_argument(p, 'carmen', CARMEN_LOGS)
    p.add_argument('--scans', type=int, default=200, help='scans per log')
    p.add_argument('--repeat', type=int, default=5, help='timing repeats per scan (best)')
    p.add_argument('--sim', action='store_true', help='also the 1081-beam office scans')
    p.set_defaults(run=run_logs)
    return run_subcommand(ap, argv)


if __name__ == '__main__':
    sys.exit(main())
