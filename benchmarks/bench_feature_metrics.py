"""Truth-free feature metrics and corner repeatability on real logs (Carmen format).

Run from the repository root (needs ``../shared/data/carmen`` or ``--data DIR``)::

    python benchmarks/bench_feature_metrics.py metrics [--data DIR] [--scans 20] [--seed 0]
        [--json out.json] [--direct] [LOG ...]
    python benchmarks/bench_feature_metrics.py corner-repeatability [--data DIR]
        [--method minus_cosine] [--set NAME=VALUE ...] [LOG ...]
    python benchmarks/bench_feature_metrics.py structural-rule [--data DIR]
        [--min-share 0.3] [--arm-ends required|ignored] [LOG ...]
    python benchmarks/bench_feature_metrics.py quantised-lines [--data DIR] [--step 0.05]
        [--drho 0.05 ...] [--dalpha 2 ...] [--set NAME=VALUE ...] [--misses] [--gate-costs]
        [LOG ...]
    python benchmarks/bench_feature_metrics.py line-covariance [--data DIR] [--bag BAG ...]
        [LOG ...]

A LOG is a log name in ``--data DIR`` (``aces`` -> ``DIR/aces-corrected.log.gz``; default
the six Carmen logs) or a path to a Carmen log.

``metrics``: each log is imported (``landmark_nav import``, defaults, into a temporary
directory) and scored as ``landmark_nav evaluate-features BAG`` does: every extractor with
the node defaults and the approxPolyDP baseline (epsilon 5 cm, per breakpoint cluster; in
full and restricted to the line extractor's minimum size) on every scan; f, ray RMSE, fit
residual on ``--scans`` scans drawn with ``numpy.random.default_rng(--seed)``;
false-surface beams on every scan; repeatability between consecutive scans through the
corrected poses (``/ground_truth/odom`` composed with the laser mount); milliseconds per
scan (segmentation included). See :mod:`landmark_nav.evaluation.scan_metrics` for the
definitions. Also the ray-metric f of the ``detailed`` profile
(``config/line_extractor_detailed.yaml``) on the same sampled scans against 0.9 x the full
baseline's. ``--direct`` reads the logs with the simple FLASER reader instead (FLASER pose
= laser pose, readings >= 40 m = no return), without the importer.

``corner-repeatability``: every scan of each log (the FLASER pose as laser pose, readings
>= 40 m no return, as ``metrics --direct``; node defaults), corners of scan k scored
against scan k+1 through the reference poses as :func:`corner_repeatability` does. Printed
per log, the fraction re-detected within 10 cm (re-detected / opportunities) under three
rules for an opportunity (:func:`corner_observable`):

* ``place + arms`` (the metric): the next scan's beam toward the corner returned within
  10 cm of its distance, and so did its beams toward the point 15 cm along each arm;
* ``place``: only the corner's own beam;
* ``former``: the rule before, shared with the lines: the beam toward the corner not
  occluded (returned at least its distance - 10 cm, or nothing).

Then the misses of the metric split by the distance to the nearest corner of the next scan
(10-50 cm: moved; farther or none: not detected again), corners per scan and the median
detector time (segmentation included). ``--set NAME=VALUE`` (repeatable) changes a
:class:`CornerParams` field; the row then also gives the corners the change adds (per
scan: corners with no corner of the defaults within 5 cm in the same scan) and the share
of those new corners that are re-detected in the next scan themselves (``new: per scan,
re-detected / opportunities``).

``structural-rule``: how ``Corner.structural``'s bounds were chosen. Each log is imported and
its corners found as ``landmark_nav evaluate-features`` does (node defaults, range noise
estimated from the scans); for every rule "both arms >= L m and >= N beam steps"
(``--lengths``, ``--steps``; with ``--arm-ends required`` also neither arm occluded nor
the corner a silhouette, ``Corner.occluded`` / ``Corner.silhouette``: measured, not
adopted) the re-detection of the corners it marks (as
``evaluate-features``' structural column) and the share of corners it marks. Leaving one
log out, the rule with the best worst-log re-detection among those marking at least
``--min-share`` of the corners of every other log is chosen and scored on the log left
out; then the same choice over all logs (the shipped rule).

``quantised-lines``: each log as ``metrics --direct`` reads it, and the same with its
ranges rounded to ``--step`` (5 cm: a quantised laser), scored as ``metrics`` does with
the range noise estimated from the scans (``split_merge`` lines); printed per log and line
repeatability gate (``|d rho| <= --drho``, ``|d alpha| <= --dalpha`` deg, every pair) the
quantised copy's estimated sigma_r and the std its gates use (``LineParams.gate_sigma_r``),
the coverage f, the fit RMS (on the ``metrics`` sample of 20 scans), the false-surface beams
(all scans) and the line repeatability of both and the repeatability's drop; between
them the repeatability of the unquantised log extracted with the quantised copy's settings
(its sigma_r and rounding): the drop from the log to that column is what the settings
cost, the rest what the rounded data lose. ``--set NAME=VALUE`` (repeatable) changes a
:class:`LineParams` field for all three. ``--misses``: how each opportunity ends, for
the log and its copy (:func:`line_misses`). ``--gate-costs``: which of the settings cost
it (:func:`gate_costs`): the log at its own settings with one gate at the copy's, and the
copy at its settings with one gate at the log's.

``line-covariance``: whether the (rho, alpha) covariance of the lines matches their spread
(:func:`halves_d2`). Every line the extractor finds (node defaults, every scan as
``metrics --direct`` reads the log; ``--bag``: a bag's ``/scan``, e.g. the simulator's
bags/office as the control) is refitted on its even and on its odd beams with
:func:`fit_line`: two estimates of one wall with independent noise, so
``d2 = dl^T (C_even + C_odd)^-1 dl`` is chi-square with 2 dof (mean 2, 5 % above 5.99)
when the covariance is right. Printed per log and line size (supporting beams), the mean
d2 and the share above 5.99 with the covariance of three range noises: the node default
``sigma_r``; it with the readings' rounding q (:func:`range_step`: ``sigma_r^2 + share q^2
/ 12``, the finer step's on the rest); the estimate ``sigma_r_from_data`` gives
(:func:`estimate_range_noise`, at least ``sigma_r``).
"""

from dataclasses import replace
import json
import math
from pathlib import Path
import sys
import tempfile
import time

from common import (add_logs_argument, log_paths, parse_set, run_subcommand,
                    subcommand_parser)
from landmark_nav.evaluation.feature_bags import (bag_metric_scans, evaluate_truth_free,
                                                  sensor_facts)
from landmark_nav.evaluation.features import normal_form, segment_per_extractor
from landmark_nav.evaluation.scan_metrics import (corner_observable, corner_repeatability,
                                                  evaluate_scans, line_opportunities,
                                                  line_repeatability, MetricScan, ray_metrics,
                                                  Repeatability, segments_of)
from landmark_nav.geometry import inverse_transform_points, transform_points, wrap_angle
from landmark_nav.importers.carmen import read_carmen_scans
from landmark_nav.importers.writer import import_log
from landmark_nav.laser.corners import CornerParams, detect_corners
from landmark_nav.laser.extractor_configuration import (extractor_configuration,
                                                        ScanSegmenter)
from landmark_nav.laser.lines import extract_lines, fit_line, LineParams
from landmark_nav.laser.range_noise import estimate_range_noise, gate_sigma, range_step
from landmark_nav.laser.segmentation import segment_scan
from landmark_nav.tools.evaluate_features import format_scan_metrics
import numpy as np

# The order of the README's feature tables.
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


def carmen_logs(data: str, logs):
    """Yield ``(name, scans)`` of each log (:func:`log_paths`), :func:`carmen_metric_scans`."""
    for name, path in log_paths(data, logs):
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


def run_metrics(args) -> int:
    """Run the ``metrics`` subcommand: the tables of every log and the summary."""
    results = {}
    for name, path in log_paths(args.data, args.logs):
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
    return 0


def run_corner_repeatability(args) -> int:
    """Run the ``corner-repeatability`` subcommand: one row per log."""
    changes = parse_set(args.set)
    params = CornerParams(method=args.method, **changes)
    base = CornerParams(method=args.method) if changes else None
    print('| log | place + arms | place | former | '
          'misses: next 10-50 cm / none within 50 cm | corners/scan | ms/scan |'
          + (' new: per scan, re-detected |' if base else ''))
    print('| --- | --- | --- | --- | --- | --- | --- |' + (' --- |' if base else ''))
    for name, scans in carmen_logs(args.data, args.logs):
        corners, arms, times, new = [], [], [], []
        for s in scans:
            if base is not None:
                cl = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment,
                                  sigma_r=base.sigma_r)
                old = np.array([c.position for c in detect_corners(cl, base)]).reshape(-1, 2)
            t0 = time.perf_counter()
            cl = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment,
                              sigma_r=params.sigma_r)
            found = detect_corners(cl, params)
            times.append(time.perf_counter() - t0)
            corners.append(np.array([c.position for c in found]).reshape(-1, 2))
            arms.append(np.array([[c.bisector, c.opening] for c in found]).reshape(-1, 2))
            if base is not None:
                d = np.hypot(*(corners[-1][:, None] - old[None]).transpose(2, 0, 1))
                new.append(d.min(axis=1, initial=np.inf) > 0.05)
        score, place, added = Repeatability(), Repeatability(), Repeatability()
        near = []
        for k in range(len(scans) - 1):
            corner_repeatability(score, corners[k], scans[k].pose, corners[k + 1],
                                 scans[k + 1], wedges_k=arms[k])
            corner_repeatability(place, corners[k], scans[k].pose, corners[k + 1],
                                 scans[k + 1])
            if base is not None and new[k].any():
                corner_repeatability(added, corners[k][new[k]], scans[k].pose, corners[k + 1],
                                     scans[k + 1], wedges_k=arms[k][new[k]])
            if len(corners[k]):
                world = transform_points(scans[k].pose, corners[k])
                ang = (scans[k].pose[2] + arms[k][:, :1]
                       + 0.5 * arms[k][:, 1:] * np.array([1.0, -1.0]))
                world = world[corner_observable(scans[k + 1], world, ang)]
                other = transform_points(scans[k + 1].pose, corners[k + 1]).reshape(-1, 2)
                near.append(np.hypot(*(world[:, None] - other[None]).transpose(2, 0, 1)
                                     ).min(axis=1, initial=np.inf))
        near = np.concatenate(near) if near else np.zeros(0)
        n_all = score.opportunities + score.unobserved
        print(f'| {name} | {score.fraction:.3f} ({score.redetected}/{score.opportunities}) | '
              f'{place.fraction:.3f} ({place.redetected}/{place.opportunities}) | '
              f'{score.fraction_with_unobserved:.3f} '
              f'({score.redetected + score.unobserved_redetected}/{n_all}) | '
              f'{np.mean((near > 0.1) & (near <= 0.5)):.3f} / {np.mean(near > 0.5):.3f} | '
              f'{sum(map(len, corners)) / len(scans):.2f} | '
              f'{1e3 * np.median(times):.2f} |'
              + (f' {sum(map(np.sum, new)) / len(scans):.2f}, {added.fraction:.3f} '
                 f'({added.redetected}/{added.opportunities}) |' if base else ''), flush=True)

    return 0


def structural_rule_records(bag: Path, rules: list, arm_ends: bool = False) -> tuple:
    """Return per rule the Repeatability of the corners it marks, and the share it marks.

    With ``arm_ends`` a rule marks only corners neither occluded nor a silhouette
    (``Corner.occluded``, ``Corner.silhouette``).
    """
    mount, _, _ = sensor_facts(bag)
    scans, _ = bag_metric_scans(bag, mount)
    noise = estimate_range_noise(((s.ranges, s.angles, s.valid) for s in scans), stated=0.01)
    config = extractor_configuration('corner_extractor')
    params = replace(config.params, sigma_r=noise.sigma_r, arm_ends=arm_ends)
    segmenter = ScanSegmenter(config.incidence_deg, config.min_points, noise.sigma_r,
                              config.sigma_r_from_data, config.sigma_r_scans)
    scores = [Repeatability() for _ in rules]
    marked = np.zeros(len(rules))
    total, prev = 0, None
    for s in scans:
        clusters = segment_per_extractor({'corners': segmenter}, s.ranges, s.angles, s.valid,
                                         s.angle_increment)['corners'][0]
        found = detect_corners(clusters, segmenter.at_scan_noise(params))
        pos = np.array([c.position for c in found]).reshape(-1, 2)
        wedge = np.array([[c.bisector, c.opening] for c in found]).reshape(-1, 2)
        arms = np.array([[min(c.arm_lengths), min(c.arm_beam_steps)] for c in found]
                        ).reshape(-1, 2)
        seen = np.array([not (arm_ends and (c.occluded or c.silhouette)) for c in found],
                        dtype=bool)
        masks = [(arms[:, 0] >= length) & (arms[:, 1] >= steps) & seen
                 for length, steps in rules]
        total += len(found)
        marked += [m.sum() for m in masks]
        if prev is not None and prev[0].pose is not None and s.pose is not None:
            for score, m in zip(scores, prev[3]):
                corner_repeatability(score, prev[1][m], prev[0].pose, pos, s,
                                     wedges_k=prev[2][m])
        prev = (s, pos, wedge, masks)
    return scores, marked / max(total, 1)


def run_structural_rule(args) -> int:
    """Run ``structural-rule``: the leave-one-log-out choice of the structural bounds."""
    rules = [(length, steps) for length in args.lengths for steps in args.steps]
    fig = {}
    for name, path in log_paths(args.data, args.logs):
        with tempfile.TemporaryDirectory() as tmp:
            import_log(path, Path(tmp) / name)
            scores, share = structural_rule_records(Path(tmp) / name, rules,
                                                    args.arm_ends == 'required')
        fig[name] = [(sc.fraction, sh) for sc, sh in zip(scores, share)]
        print(f'{name}: {scores[0].opportunities} opportunities of the corners with both '
              f'arms >= {rules[0][0]:g} m and {rules[0][1]:g} beam steps', flush=True)

    def choose(logs):
        ok = [i for i in range(len(rules)) if min(fig[g][i][1] for g in logs) >= args.min_share]
        return max(ok, key=lambda i: min(fig[g][i][0] for g in logs), default=None)

    print('| log left out | rule chosen on the others (arms >= L m, >= N beam steps) | '
          'their worst re-detection | re-detection on the log left out | its share |')
    print('| --- | --- | --- | --- | --- |')
    for out in fig if len(fig) > 1 else ():
        rest = [g for g in fig if g != out]
        i = choose(rest)
        if i is None:
            print(f'| {out} | no rule marks {args.min_share} of every log | | | |')
            continue
        worst = min(fig[g][i][0] for g in rest)
        print(f'| {out} | L {rules[i][0]:g}, N {rules[i][1]:g} | {worst:.3f} | '
              f'{fig[out][i][0]:.3f} | {fig[out][i][1]:.2f} |')
    i = choose(list(fig))
    if i is not None:
        print(f'\nall logs: L {rules[i][0]:g} m, N {rules[i][1]:g} beam steps: ' + ', '.join(
            f'{g} {fig[g][i][0]:.3f} ({fig[g][i][1]:.2f} marked)' for g in fig))
    return 0


def line_misses(scans: list, noise, gate: tuple, base: LineParams) -> dict:
    """Return the ``split_merge`` line opportunities of ``scans`` and how they end.

    Lines as ``evaluate_scans`` extracts them with ``base`` at the range noise ``noise`` (its
    sigma_r and rounding); each opportunity of :func:`line_repeatability` is ``re-detected``,
    ``near`` (a next-scan segment overlaps it within twice the gate; ``near d rho`` when only
    |d rho| is over the gate), ``within 4 gates`` or ``lost`` (none within four times the
    gate); ``near`` ones also by the line's incidence at its midpoint (0-15, 15-45, 45-90
    deg). For those ``within 4 gates`` the medians of their length, beams and distance
    (midpoint) and of |d rho|, |d alpha| to the nearest next-scan segment (``far ...``).
    """
    cfg = extractor_configuration('line_extractor')
    segmenter = ScanSegmenter(cfg.incidence_deg, cfg.min_points, noise.sigma_r)
    params = replace(base, sigma_r=noise.sigma_r, range_step=noise.step,
                     range_step_share=noise.step_share)
    segs, beams = [], []
    for s in scans:
        clusters = segmenter.segment(s.ranges, s.angles, s.valid, s.angle_increment)
        lines = extract_lines(clusters, params)
        segs.append(segments_of(lines).reshape(-1, 2, 2))
        beams.append([ln.num_points for ln in lines])
    far = []  # (length, beams, distance, |d rho|, |d alpha|) of those within 4 gates
    out = dict.fromkeys(('opportunities', 're-detected', 'near d rho', 'near d alpha',
                         'within 4 gates', 'lost', 'near 0-15', 'near 15-45', 'near 45-90'), 0)
    for k in range(len(scans) - 1):
        index, world = line_opportunities(segs[k], scans[k].pose, scans[k + 1])
        out['opportunities'] += int(index.size)
        if not index.size:
            continue
        mine = inverse_transform_points(scans[k + 1].pose,
                                        world.reshape(-1, 2)).reshape(-1, 2, 2)
        other = segs[k + 1]
        f_k, f_n = normal_form(mine[:, 0], mine[:, 1]), normal_form(other[:, 0], other[:, 1])
        d_rho = np.abs(f_k[:, None, 0] - f_n[None, :, 0]) / gate[0]
        d_alpha = np.abs(wrap_angle(f_k[:, None, 1] - f_n[None, :, 1])) / gate[1]
        d = mine[:, 1] - mine[:, 0]
        t = np.einsum('bej,aj->abe', other, d)
        t -= np.einsum('aj,aj->a', mine[:, 0], d)[:, None, None]
        t /= np.einsum('ij,ij->i', d, d)[:, None, None]
        overlap = (t.max(axis=2) > 0.0) & (t.min(axis=2) < 1.0)
        mid = inverse_transform_points(scans[k].pose, world.mean(axis=1))
        incidence = np.degrees(np.abs(wrap_angle(np.arctan2(mid[:, 1], mid[:, 0])
                                                 - normal_form(segs[k][index, 0],
                                                               segs[k][index, 1])[:, 1])))
        incidence = np.minimum(incidence, 180.0 - incidence)
        for a in range(index.size):
            if np.any(overlap[a] & (d_rho[a] <= 1.0) & (d_alpha[a] <= 1.0)):
                out['re-detected'] += 1
            elif np.any(near := overlap[a] & (d_rho[a] <= 2.0) & (d_alpha[a] <= 2.0)):
                out['near d alpha' if np.any(near & (d_alpha[a] > 1.0)) else 'near d rho'] += 1
                out['near ' + ('0-15' if incidence[a] < 15 else '15-45' if incidence[a] < 45
                               else '45-90')] += 1
            elif np.any(overlap[a] & (d_rho[a] <= 4.0) & (d_alpha[a] <= 4.0)):
                out['within 4 gates'] += 1
                b = np.flatnonzero(overlap[a])[np.argmin(np.fmax(d_rho[a], d_alpha[a])[
                    overlap[a]])]
                far.append((math.hypot(*d[a]), beams[k][index[a]], math.hypot(*mid[a]),
                            100 * gate[0] * d_rho[a, b], math.degrees(gate[1] * d_alpha[a, b])))
            else:
                out['lost'] += 1
    far = np.array(far).reshape(-1, 5)
    for j, key in enumerate(('far length [m]', 'far beams', 'far distance [m]',
                             'far |d rho| [cm]', 'far |d alpha| [deg]')):
        out[key] = f'{np.median(far[:, j]):.3g}' if far.size else '-'
    return out


#: The gates :func:`gate_costs` moves one at a time, each through public settings.
GATES = ('segmentation', 'split tolerance', 'trim and growth', 'see-through', 'merge test')


def _with_gate(params: LineParams, seg_sigma: float, other: LineParams, other_seg: float,
               gate: str) -> tuple:
    """Return ``(params, segmentation sigma)`` with ``gate`` set as ``other`` sets it.

    ``split tolerance``: ``split_threshold`` = the other's; ``trim and growth``:
    ``trim_sigma`` scaled so that its gate is the other's (``trim_sigma`` times
    ``gate_sigma_r``); ``see-through``: ``see_through`` = the other's tolerance (the margins'
    3-sigma part stays); ``merge test``: ``merge_chi2`` scaled by (other sigma_r / sigma_r)^2,
    the merge and join tests' chi-square as the other's covariances would give it where the
    range noise dominates them.
    """
    if gate == 'segmentation':
        return params, other_seg
    if gate == 'split tolerance':
        return replace(params, split_threshold=other.threshold), seg_sigma
    if gate == 'trim and growth':
        return replace(params, trim_sigma=params.trim_sigma * other.gate_sigma_r
                       / params.gate_sigma_r), seg_sigma
    if gate == 'see-through':
        return replace(params, see_through=other.see_through_tolerance), seg_sigma
    return replace(params, merge_chi2=params.merge_chi2
                   * (other.sigma_r / params.sigma_r) ** 2), seg_sigma


def split_merge_repeatability(scans: list, params: LineParams, seg_sigma: float,
                              gate: tuple) -> Repeatability:
    """Return the line repeatability of ``split_merge`` lines with these settings.

    Segmentation as the ``line_extractor`` node's with range noise ``seg_sigma``; scored as
    ``evaluate_scans`` scores it (:func:`line_repeatability`, ``gate`` = (d rho, d alpha)).
    """
    cfg = extractor_configuration('line_extractor')
    segmenter = ScanSegmenter(cfg.incidence_deg, cfg.min_points, seg_sigma)
    score, prev = Repeatability(), None
    for s in scans:
        segs = segments_of(extract_lines(
            segmenter.segment(s.ranges, s.angles, s.valid, s.angle_increment), params))
        if prev is not None:
            line_repeatability(score, prev[1], prev[0].pose, segs, s, max_drho=gate[0],
                               max_dalpha=gate[1])
        prev = (s, segs)
    return score


def gate_costs(scans: list, rounded: list, own, noise, gate: tuple, base: LineParams
               ) -> list:
    """Return rows (data, settings, repeatability, one per :data:`GATES` moved).

    The log (``scans``, range noise ``own``) at its settings with each gate in turn at the
    rounded copy's (``rounded``, ``noise``), and the copy at its settings with each gate
    at the log's (:func:`_with_gate`); settings as ``evaluate_scans`` derives them from an
    estimate (``sigma_r``, ``range_step``, ``range_step_share``) on ``base``.
    """
    p_own, p_copy = (replace(base, sigma_r=n.sigma_r, range_step=n.step,
                             range_step_share=n.step_share) for n in (own, noise))
    rows = []
    for data, sc, mine, seg, other, other_seg in (
            ('log', scans, p_own, own.sigma_r, p_copy, noise.sigma_r),
            ('copy', rounded, p_copy, noise.sigma_r, p_own, own.sigma_r)):
        row = [data, 'own', split_merge_repeatability(sc, mine, seg, gate).fraction]
        for g in GATES:
            params, seg_g = _with_gate(mine, seg, other, other_seg, g)
            row.append(split_merge_repeatability(sc, params, seg_g, gate).fraction)
        rows.append(row)
    return rows


def run_quantised_lines(args) -> int:
    """Run ``quantised-lines``: line repeatability of a log and its quantised copy per gate."""
    print('| log | sigma_r [cm] | gate sigma [cm] | d rho gate [m] | d alpha gate [deg] | f | '
          'f quantised | fit RMS [cm] | quantised | false-surface beams | quantised | '
          'repeatability | at the quantised settings | quantised | drop |')
    print('|' + ' --- |' * 15)
    base = extractor_configuration('line_extractor')
    base = replace(base, params=replace(base.params, **parse_set(args.set)))
    misses = ['\n| log | d rho gate [m] | d alpha gate [deg] | copy | opportunities | '
              're-detected | near, d rho | near, d alpha | within 4 gates | lost | '
              'near at 0-15 deg | 15-45 deg | 45-90 deg | within 4 gates: length [m] | '
              'beams | distance [m] | d rho [cm] | d alpha [deg] |', '|' + ' --- |' * 18]
    costs = ['\n| log | d rho gate [m] | d alpha gate [deg] | data | repeatability at its '
             'settings | ' + ' | '.join(f"{g} as the other's" for g in GATES) + ' |',
             '|' + ' --- |' * (5 + len(GATES))]
    for name, path in log_paths(args.data, args.logs):
        scans = carmen_metric_scans(path)
        rounded = []
        for s in scans:
            r = np.where(np.isfinite(s.ranges), np.round(s.ranges / args.step) * args.step,
                         s.ranges)
            rounded.append(replace(s, ranges=r, valid=s.valid & (r > 0.0)))
        noise = estimate_range_noise(((s.ranges, s.angles, s.valid)
                                      for s in rounded), stated=0.01)
        own = estimate_range_noise(((s.ranges, s.angles, s.valid) for s in scans), stated=0.01)
        # the quantised log's extractor settings (its noise and rounding) on the log itself
        settings = replace(base, params=replace(base.params, range_step=noise.step,
                                                range_step_share=noise.step_share))
        for drho in args.drho:
            for dalpha in args.dalpha:
                fig = []
                for sc, sigma, configs in ((scans, 'auto', {'line_extractor': base}),
                                           (rounded, 'auto', {'line_extractor': base}),
                                           (scans, noise.sigma_r,
                                            {'line_extractor': settings})):
                    res = evaluate_scans(sc, extractor_sigma_r=sigma,
                                         line_methods=('split_merge',),
                                         corner_methods=('minus_cosine',), configs=configs,
                                         line_gate=(drho, math.radians(dalpha)))
                    lines = res['lines']['split_merge']
                    fig.append((lines['f'], lines['line_repeatability'], lines['fit_rms_m'],
                                lines['false_surface_beams']))
                print(f'| {name} | {100 * noise.sigma_r:.2f} | '
                      f'{100 * gate_sigma(noise.sigma_r, noise.step, noise.step_share):.2f} | '
                      f'{drho:g} | {dalpha:g} | '
                      f'{fig[0][0]:.3f} | {fig[1][0]:.3f} | {100 * fig[0][2]:.2f} | '
                      f'{100 * fig[1][2]:.2f} | {fig[0][3]} | {fig[1][3]} | '
                      f'{fig[0][1]:.3f} | {fig[2][1]:.3f} '
                      f'| {fig[1][1]:.3f} | {fig[0][1] - fig[1][1]:.3f} |', flush=True)
                if args.misses:
                    for label, sc, nz in (('log', scans, own), ('quantised', rounded, noise)):
                        found = line_misses(sc, nz, (drho, math.radians(dalpha)),
                                            base.params)
                        misses.append(f'| {name} | {drho:g} | {dalpha:g} | {label} | '
                                      + ' | '.join(map(str, found.values())) + ' |')
                if args.gate_costs:
                    for row in gate_costs(scans, rounded, own, noise,
                                          (drho, math.radians(dalpha)), base.params):
                        costs.append(f'| {name} | {drho:g} | {dalpha:g} | {row[0]} | '
                                     + ' | '.join(f'{v:.3f}' for v in row[2:]) + ' |')
    if args.misses:
        print('\n'.join(misses))
    if args.gate_costs:
        print('\n'.join(costs))
    return 0


HALF_SIZES = ((8, 15), (15, 40), (40, None))  # supporting beams of a line, per row


def halves_d2(scans: list, params: LineParams, sigmas: list) -> np.ndarray:
    """Return per line (beams, d2 under each range noise of ``sigmas``) of the even / odd refits.

    The beams of each line's extent within ``3 max(sigma_r, rmse)`` of it (8 at least) are
    split into even and odd ones and refitted (:func:`fit_line`, ``params.sigma_phi``); a
    line through the origin (normals 1 rad apart or more) is left out.
    """
    cfg = extractor_configuration('line_extractor')
    seg = ScanSegmenter(cfg.incidence_deg, cfg.min_points, params.sigma_r)
    rows = []
    for sc in scans:
        for line in extract_lines(seg.segment(sc.ranges, sc.angles, sc.valid,
                                              sc.angle_increment), params):
            idx = np.arange(line.first_index, line.last_index + 1)
            idx = idx[sc.valid[idx]]
            r, a = sc.ranges[idx], sc.angles[idx]
            pts = np.column_stack([r * np.cos(a), r * np.sin(a)])
            near = np.abs(pts @ line.normal - line.rho) <= 3 * max(params.sigma_r, line.rmse)
            if near.sum() < 8:
                continue
            r, a, pts = r[near], a[near], pts[near]
            halves = [np.arange(len(r)) % 2 == k for k in (0, 1)]
            row = [len(r)]
            for sigma in sigmas:
                (r0, a0, c0, _), (r1, a1, c1, _) = [
                    fit_line(pts[h], r[h], a[h], sigma, params.sigma_phi) for h in halves]
                dl = np.array([r0 - r1, wrap_angle(a0 - a1)])
                row.append(float(dl @ np.linalg.solve(c0 + c1, dl)))
            if abs(wrap_angle(a0 - a1)) < 1.0:
                rows.append(row)
    return np.array(rows, dtype=float).reshape(-1, 1 + len(sigmas))


def run_line_covariance(args) -> int:
    """Print the even / odd refit d2 of each log's lines per size and range noise."""
    items = [(Path(b).name, bag_metric_scans(b, sensor_facts(b)[0])[0]) for b in args.bag]
    items += list(carmen_logs(args.data, args.logs if not args.bag or args.logs != list(LOGS)
                              else []))
    base = extractor_configuration('line_extractor').params
    print('| log | rounding q (share) | sigma_r: default / with q^2/12 / estimated [cm] | '
          'beams | lines | mean d2 (share > 5.99): default | with q^2/12 | estimated |\n'
          '| --- | --- | --- | --- | --- | --- | --- | --- |')
    for name, scans in items:
        q, share, fine = range_step(np.concatenate([s.ranges[s.valid] for s in scans]))
        sigmas = [base.sigma_r, math.sqrt(base.sigma_r ** 2 + share * q ** 2 / 12
                                          + (1 - share) * fine ** 2 / 12),
                  estimate_range_noise(((s.ranges, s.angles, s.valid) for s in scans),
                                       stated=base.sigma_r).sigma_r]
        d2 = halves_d2(scans, base, sigmas)
        for lo, hi in HALF_SIZES:
            sel = d2[(d2[:, 0] >= lo) & (d2[:, 0] < (hi or np.inf))]
            cells = ' | '.join(f'{np.mean(sel[:, k]):.2f} ({np.mean(sel[:, k] > 5.99):.2f})'
                               if len(sel) else '–' for k in (1, 2, 3))
            print(f'| {name} | {100 * q:g} cm ({share:.2f}) | '
                  + ' / '.join(f'{100 * v:.2f}' for v in sigmas)
                  + f' | {lo}{f"–{hi - 1}" if hi else "+"} | {len(sel)} | {cells} |',
                  flush=True)
    return 0


def main(argv=None) -> int:
    """Parse the subcommand and run it."""
    ap, sub = subcommand_parser(__doc__)
    p = sub.add_parser('metrics', help='the truth-free feature metrics of every log')
    add_logs_argument(p, 'carmen', LOGS)
    p.add_argument('--scans', type=int, default=20, help='scans drawn for the PLE figures')
    p.add_argument('--seed', type=int, default=0, help='seed of the draw')
    p.add_argument('--sigma-r', type=float, default=0.01,
                   help='--direct: sensor range noise for the false-surface margin [m] '
                        '(imported bags state theirs)')
    p.add_argument('--json', default=None, help='write all figures to this file')
    p.add_argument('--direct', action='store_true',
                   help='read the logs with the simple FLASER reader, not the importer')
    p.set_defaults(run=run_metrics)
    p = sub.add_parser('corner-repeatability',
                       help='corner re-detection between consecutive scans, and the misses')
    add_logs_argument(p, 'carmen', LOGS)
    p.add_argument('--method', default='minus_cosine', help='corner detector')
    p.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                   help='a CornerParams field (the value a Python literal)')
    p.set_defaults(run=run_corner_repeatability)
    p = sub.add_parser('quantised-lines',
                       help='line repeatability of each log and of its quantised copy, per '
                            'repeatability gate')
    add_logs_argument(p, 'carmen', LOGS)
    p.add_argument('--step', type=float, default=0.05, help='range quantisation [m]')
    p.add_argument('--drho', type=float, nargs='+', default=[0.05],
                   help='repeatability gates on |d rho| [m] (the metric: 0.05)')
    p.add_argument('--dalpha', type=float, nargs='+', default=[2.0],
                   help='repeatability gates on |d alpha| [deg] (the metric: 2)')
    p.add_argument('--misses', action='store_true',
                   help='also how the opportunities end: re-detected, near (within twice '
                        'the gate), within four times the gate, or lost')
    p.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                   help='a LineParams field for the log and its copy (a Python literal)')
    p.add_argument('--gate-costs', action='store_true',
                   help="also the repeatability of the log with each gate at the copy's "
                        "setting, and of the copy with each gate at the log's")
    p.set_defaults(run=run_quantised_lines)
    p = sub.add_parser('structural-rule',
                       help="how Corner.structural's bounds were chosen (leave one log out)")
    add_logs_argument(p, 'carmen', LOGS)
    p.add_argument('--lengths', type=float, nargs='+', default=[0.2, 0.3, 0.4, 0.5, 0.6],
                   help='arm length bounds L [m]')
    p.add_argument('--steps', type=float, nargs='+', default=[0, 3, 4, 5, 6, 7, 8, 10, 12],
                   help='arm beam-step bounds N')
    p.add_argument('--min-share', type=float, default=0.3,
                   help='a rule must mark at least this share of the corners of each log')
    p.add_argument('--arm-ends', choices=('required', 'ignored'), default='ignored',
                   help='required: a rule also needs no occluded arm and no silhouette '
                        '(Corner.occluded, Corner.silhouette; measured, not adopted); '
                        'ignored (default, as Corner.structural): arm length and beam steps')
    p.set_defaults(run=run_structural_rule)
    p = sub.add_parser('line-covariance',
                       help='line (rho, alpha) covariance against the spread of even / odd '
                            'refits, with and without the rounding of the ranges')
    add_logs_argument(p, 'carmen', LOGS)
    p.add_argument('--bag', action='append', default=[],
                   help='a bag instead (repeatable; with no LOG given, the bags only), e.g. '
                        'bags/office as the control')
    p.set_defaults(run=run_line_covariance)
    return run_subcommand(ap, argv)


if __name__ == '__main__':
    sys.exit(main())
