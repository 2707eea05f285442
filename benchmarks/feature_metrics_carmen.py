"""Truth-free feature metrics on the Carmen logs: the "before" table of the real-log issue.

Run from the repository root (needs ``../shared/data/carmen``)::

    python benchmarks/feature_metrics_carmen.py [--scans 20] [--seed 0] [--json out.json]
        [LOG ...]

Each log is imported (``landmark_nav import``, defaults, into a temporary directory) and
scored as ``landmark_nav evaluate-features BAG`` does: every extractor with the node
defaults and the approxPolyDP baseline (epsilon 5 cm, per breakpoint cluster; in full and
restricted to the line extractor's minimum size) on every scan; f, ray RMSE, fit residual
on ``--scans`` scans drawn with ``numpy.random.default_rng(--seed)``; false-surface beams
on every scan; repeatability between consecutive scans through the corrected poses
(``/ground_truth/odom`` composed with the laser mount); milliseconds per scan
(segmentation included). See :mod:`landmark_nav.evaluation.scan_metrics` for the
definitions. Also the ray-metric f of the ``detailed`` profile
(``config/line_extractor_detailed.yaml``) on the same sampled scans against 0.9 x the full
baseline's. ``--direct`` reads the logs with the simple FLASER reader instead (FLASER pose
= laser pose, readings >= 40 m = no return), without the importer.
"""
import argparse
import json
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.evaluation.feature_bags import (bag_metric_scans,  # noqa: E402
                                                  evaluate_truth_free, sensor_facts)
from landmark_nav.evaluation.scan_metrics import (evaluate_scans,  # noqa: E402
                                                  format_scan_metrics, MetricScan,
                                                  ray_metrics, segments_of)
from landmark_nav.importers.carmen import read_carmen_scans  # noqa: E402
from landmark_nav.importers.writer import import_log  # noqa: E402
from landmark_nav.laser.lines import extract_lines, LineParams  # noqa: E402
from landmark_nav.laser.segmentation import segment_scan  # noqa: E402
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
import numpy as np  # noqa: E402

CARMEN = SHARED_DATA / 'carmen'
LOGS = ('aces', 'seattle', 'belgioioso', 'fhw', 'freiburg-101', 'acapulco')
MAX_RANGE = 40.0  # the reader's no-return cut [m]


def carmen_metric_scans(path: Path) -> list:
    """Read a Carmen log as :class:`MetricScan` with the corrected pose as laser pose."""
    out = []
    for s in read_carmen_scans(path, max_range=MAX_RANGE):
        r = np.asarray(s.ranges, dtype=float)
        valid = np.isfinite(r) & (r > 0.0)
        out.append(MetricScan(r, s.angles, valid, np.isposinf(r), 0.0, MAX_RANGE,
                              np.asarray(s.pose, dtype=float)))
    return out


def carmen_logs(names):
    """Yield ``(name, scans)`` of each named log read by :func:`carmen_metric_scans`.

    A log not in ``../shared/data/carmen`` is reported (one line) and skipped.
    """
    for name in names:
        path = CARMEN / f'{name}-corrected.log.gz'
        if not path.exists():
            print(f'{path}: not present')
            continue
        yield name, carmen_metric_scans(path)


DETAILED = {'min_points': 3, 'min_length': 0.05}  # config/line_extractor_detailed.yaml
DETAILED_SEGMENTATION_MIN_POINTS = 1


def detailed_f(scans: list, sample, sigma_r: float) -> dict:
    """Return the ray-metric f of the ``detailed`` profile on the sampled scans, per method.

    The profile of ``config/line_extractor_detailed.yaml`` (``min_points`` 3,
    ``min_length`` 0.05 m, segmentation ``min_points`` 1) on the same scans as the PLE
    figures (issue target: f >= 0.9 x the full approxPolyDP baseline's f).
    """
    out = {}
    for method in ('split_merge', 'alfa'):
        params = LineParams(method=method, **DETAILED)
        f = []
        for k in sample:
            s = scans[k]
            clusters = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment,
                                    sigma_r=params.sigma_r,
                                    min_points=DETAILED_SEGMENTATION_MIN_POINTS)
            f.append(ray_metrics(s.ranges, s.angles, s.valid,
                                 segments_of(extract_lines(clusters, params)), sigma_r,
                                 s.no_return).f)
        out[method] = float(np.mean(f))
    return out


def summary(results: dict) -> str:
    """One table, one row per log and method: the issue's figures side by side."""
    rows = ['| log | method | f | ray RMSE mean / median | false-surface beams (scans) '
            '{> 30 cm (scans)} | '
            'fit RMS | lines re-detected | corners re-detected | ms/scan |',
            '| --- | --- | --- | --- | --- | --- | --- | --- | --- |']
    for log, res in results.items():
        for m in ('split_merge', 'alfa', 'approxPolyDP', 'approxPolyDP_min_size'):
            f = res['lines'][m]
            rows.append(
                f'| {log} | {m} | {f["f"]:.3f} | {100 * f["ray_rmse_mean_m"]:.2f} / '
                f'{100 * f["ray_rmse_median_m"]:.2f} cm | {f["false_surface_beams"]} '
                f'({f["false_surface_scans"]}) {{{f["false_surface_beams_over_30cm"]} '
                f'({f["false_surface_scans_over_30cm"]})}} | {100 * f["fit_rms_m"]:.2f} cm | '
                f'{f["line_repeatability"]:.3f} ({f["line_opportunities"]}) | | '
                f'{f["median_ms_per_scan"]:.2f} |')
        for m in ('minus_cosine',):
            f = res['corners'][m]
            rows.append(f'| {log} | {m} | | | | | | {f["corner_repeatability"]:.3f} '
                        f'({f["corner_opportunities"]}; counting the unobserved '
                        f'{f["corner_repeatability_with_unobserved"]:.3f}) | '
                        f'{f["median_ms_per_scan"]:.2f} |')
    return '\n'.join(rows)


def main() -> None:
    """Print the tables of every log and the summary."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS), help='log names (default: all six)')
    ap.add_argument('--scans', type=int, default=20, help='scans drawn for the PLE figures')
    ap.add_argument('--seed', type=int, default=0, help='seed of the draw')
    ap.add_argument('--sigma-r', type=float, default=0.01,
                    help='--direct: sensor range noise for the false-surface margin [m] '
                         '(imported bags state theirs)')
    ap.add_argument('--json', default=None, help='write all figures to this file')
    ap.add_argument('--direct', action='store_true',
                    help='read the logs with the simple FLASER reader, not the importer')
    args = ap.parse_args()
    results = {}
    for name in args.logs:
        path = CARMEN / f'{name}-corrected.log.gz'
        if not path.exists():
            print(f'{path}: not present')
            continue
        if args.direct:
            scans = carmen_metric_scans(path)
            res = evaluate_scans(scans, sigma_r=args.sigma_r,
                                 ple_scans=args.scans, seed=args.seed, progress=name)
            res['detailed_f'] = detailed_f(scans, res['sample'], args.sigma_r)
        else:
            with tempfile.TemporaryDirectory() as tmp:
                import_log(path, Path(tmp) / name)
                res, notes = evaluate_truth_free(Path(tmp) / name, scans=args.scans,
                                                 seed=args.seed, progress=True)
                mount, sigma_r, _ = sensor_facts(Path(tmp) / name)
                scans, _ = bag_metric_scans(Path(tmp) / name, mount)
                res['detailed_f'] = detailed_f(scans, res['sample'], sigma_r)
            for note in notes:
                print(note)
        results[name] = res
        print(format_scan_metrics(res, f'{name}: '), '\n', flush=True)
    print(summary(results))
    print('\n| log | approxPolyDP f | 0.9 x | detailed split_merge f | detailed alfa f |\n'
          '| --- | --- | --- | --- | --- |')
    for log, res in results.items():
        base = res['lines']['approxPolyDP']['f']
        det = res['detailed_f']
        print(f'| {log} | {base:.3f} | {0.9 * base:.3f} | {det["split_merge"]:.3f} | '
              f'{det["alfa"]:.3f} |')
    pooled = {m: [] for m in ('split_merge', 'alfa', 'approxPolyDP', 'approxPolyDP_min_size')}
    for res in results.values():
        for m in pooled:
            f = res['lines'][m]
            pooled[m].append((f['fit_rms_m'] ** 2 * f['fit_beams'], f['fit_beams']))
    print('\npooled fit RMS over the logs: ' + ', '.join(
        f'{m} {100 * np.sqrt(sum(a for a, _ in v) / max(sum(b for _, b in v), 1)):.2f} cm'
        for m, v in pooled.items()))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))


if __name__ == '__main__':
    main()
