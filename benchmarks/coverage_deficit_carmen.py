"""Why the line extractors cover fewer beams than the approxPolyDP baseline on Carmen logs.

Run from the repository root (needs ``../shared/data/carmen``)::

    python benchmarks/coverage_deficit_carmen.py [--detailed] [LOG ...]

On the scans of the PLE figures of ``feature_metrics_carmen.py`` (each log imported with
the defaults, 20 scans drawn with ``numpy.random.default_rng(0)``), every beam with a
return that the baseline's segments cover (its ray hits one) and the extractor's do not
is a *deficit* beam; the reverse is a *gain*. f(method) - f(baseline) = gain - deficit
(shares of the valid beams, mean over the scans). Each deficit beam is put down to the
step of :func:`landmark_nav.laser.lines.extract_lines` after which no extent of the
extractor covers it any more (the extent of a piece or line: its first to its last beam);
the steps are replayed here from the module's internal functions, in the order of its
``_extract``:

* ``fragment``: in a cluster of ``min_points``, but in no piece of the split (split and
  merge: runs of two points; ALFA: points its binary search skips) or in a piece of
  fewer than ``min_points`` points, dropped at the clean-up (step 2);
* ``trim``: in a piece of ``min_points`` or more that lost it at the clean-up (an end
  point more than 3 sigma off, a shared split point given to the neighbour, or the piece
  fell below ``min_points`` by them), not grown back;
* ``false surface``: in a line's extent after growth, outside it after the see-through
  step (the line cut at an opening, or, hiding only its own noise, shrunk to its run of
  support with the most points); in brackets the beams that the baseline itself sees
  through (false-surface beams of the baseline: no extractor may cover them);
* ``occluder``: left out when the extent was cut at an occluder;
* ``size / fit``: the line was dropped at the end (shorter than ``min_length``, RMSE above
  the split tolerance, fewer than ``min_points`` points);
* ``end ray``: inside a kept line's extent, but its ray misses the segment: an end beam
  whose point projects onto the line inside the support's bearings (the end point stays
  at the projection; only an end projecting outside them is moved onto its beam's ray).

Two more figures of the baseline put the target in context (they do not change it): its f
when its segments are held to the extractors' no-false-surface rule (each segment cut at
the beams seen through it by more than ``max(3 sigma_r, 5 cm)``, pieces of at least
``min_points`` beams and ``min_length`` kept, end points on the end beams' rays), and,
for the default profile, its f when a vertex shared by two consecutive segments counts
half for each (the restriction counts it for both; an extractor's piece owns it alone).

``--detailed``: the ``detailed`` profile (``min_points`` 3, ``min_length`` 0.05 m,
segmentation ``min_points`` 1) against the full baseline (issue target 0.9 x its f).
The replay mirrors ``_extract`` as of this commit; if that function changes, so must
:func:`_stages`.
"""

import argparse
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.evaluation.feature_bags import bag_metric_scans, sensor_facts  # noqa: E402
from landmark_nav.evaluation.scan_metrics import (approx_poly_segments,  # noqa: E402
                                                  ray_metrics, ray_ranges, sample_scans,
                                                  segments_of)
from landmark_nav.importers.writer import import_log  # noqa: E402
from landmark_nav.laser.line_extraction.cleanup import (_clean_pieces,  # noqa: E402
                                                        _refine_breaks)
from landmark_nav.laser.line_extraction.growth import _grow  # noqa: E402
from landmark_nav.laser.line_extraction.merge import _merge  # noqa: E402
from landmark_nav.laser.line_extraction.occlusion import _occluded_extents  # noqa: E402
from landmark_nav.laser.line_extraction.scan_batch import (_concat, _COS,  # noqa: E402
                                                           _gather, _PHI, _RNG, _SIN, _TOL)
from landmark_nav.laser.line_extraction.see_through import _cut_seen_through  # noqa: E402
from landmark_nav.laser.line_extraction.segments import _build  # noqa: E402
from landmark_nav.laser.line_extraction.split import _split  # noqa: E402
from landmark_nav.laser.line_extraction.tls_fit import _features, _Fit, _solve  # noqa: E402
from landmark_nav.laser.lines import alfa_pieces, LineParams, METHODS  # noqa: E402
from landmark_nav.laser.lowess import lowess_groups  # noqa: E402
from landmark_nav.laser.segmentation import segment_scan  # noqa: E402
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
import numpy as np  # noqa: E402

CARMEN = SHARED_DATA / 'carmen'
LOGS = ('aces', 'seattle', 'belgioioso', 'fhw', 'freiburg-101', 'acapulco')
CAUSES = ('fragment', 'trim', 'false surface', 'occluder', 'size / fit', 'end ray')


def _cover(scan, nbeam: int, first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """Return (nbeam,) True for the beams from each first to last point (extents)."""
    out = np.zeros(nbeam + 1, dtype=np.int64)
    a, b = scan.beam[first], scan.beam[last]
    np.add.at(out, np.minimum(a, b), 1)
    np.add.at(out, np.maximum(a, b) + 1, -1)
    return out.cumsum()[:-1] > 0


def _stages(clusters, params: LineParams, nbeam: int):
    """Replay ``lines._extract``; return ({step: covered beams}, lines, small-piece beams)."""
    empty = np.zeros(nbeam, dtype=bool)
    st = {k: empty for k in ('cluster', 'split', 'clean', 'grow', 'seen', 'occluders')}
    scan = _concat(clusters, params)
    if scan is None:
        return st, [], empty
    offsets = scan.offsets
    big = (offsets[1:] - offsets[:-1] >= params.min_points).nonzero()[0]
    if not big.size:
        return st, [], empty
    st['cluster'] = _cover(scan, nbeam, offsets[big], offsets[big + 1] - 1)
    cols = scan.cols
    n = scan.x.size
    feats = _features(scan.x, scan.y, cols[_RNG], cols[_COS], cols[_SIN],
                      params.sigma_r, params.sigma_phi, pad=1)
    pre = np.zeros((5, n + 1))
    feats[1:6, :n].cumsum(axis=1, out=pre[:, 1:])
    if params.method == 'split_merge':
        s, e = _split(scan.x, scan.y, offsets[big], offsets[big + 1] - 1, cols[_TOL])
        keep = e - s >= 2
        s, e = s[keep], e[keep]
    else:
        sub, sub_offs = _gather(offsets[big], offsets[big + 1] - 1)
        r_s = lowess_groups(cols[_PHI][sub], cols[_RNG][sub], sub_offs,
                            params.lowess_span, params.lowess_iterations)
        pieces = alfa_pieces(np.stack([r_s * cols[_COS][sub], r_s * cols[_SIN][sub]],
                                      axis=1), sub_offs, params)
        pieces = sub[pieces] if pieces.size else pieces
        s, e = pieces[:, 0], pieces[:, 1]
    s, e = _refine_breaks(scan, pre, s, e, params.min_points)
    st['split'] = _cover(scan, nbeam, s, e)
    small = e - s + 1 < params.min_points
    small_beams = _cover(scan, nbeam, s[small], e[small])
    s, e = _clean_pieces(scan, pre, s, e, params)
    if not s.size:
        return st, [], small_beams
    st['clean'] = _cover(scan, nbeam, s, e)
    sums, first0, last0, fit, label = _merge(scan, feats, s, e, params)
    sums, first, last, grown = _grow(scan, feats, sums, first0, last0, fit, params)
    if grown or fit.cov is None:
        fit = _solve(sums, scan.origin)
    st['grow'] = _cover(scan, nbeam, first, last)
    sums, first, last, fit = _cut_seen_through(scan, feats, sums, first, last, fit,
                                               (s, e, label, first0, last0), params)
    if not first.size:
        return st, [], small_beams
    st['seen'] = _cover(scan, nbeam, first, last)
    col, first, last = _occluded_extents(scan, fit, first, last, params)
    fit = _Fit(fit.params.take(col, axis=1), fit.rmse[col], fit.count[col],
               fit.cov.take(col, axis=0))
    st['occluders'] = _cover(scan, nbeam, first, last)
    return st, _build(scan, params, fit, first, last), small_beams


_STEPS = ('cluster', 'split', 'clean', 'grow', 'seen', 'occluders', 'kept')
_LOST_AT = {'split': 'fragment', 'clean': 'trim', 'grow': 'trim', 'seen': 'false surface',
            'occluders': 'occluder', 'kept': 'size / fit'}


def _cause(b: int, st: dict, small: np.ndarray) -> str:
    """Return the step after the last one whose extents cover beam b (module docstring)."""
    last = max((k for k, step in enumerate(_STEPS) if st[step][b]), default=0)
    if last == len(_STEPS) - 1:
        return 'end ray'
    lost = _STEPS[last + 1]
    if lost == 'clean' and small[b]:
        return 'fragment'
    return _LOST_AT[lost]


def _cut_segments(scan, seg: np.ndarray, idx: np.ndarray, margin: float, min_points: int,
                  min_length: float) -> np.ndarray:
    """Cut baseline segments at the beams seen through them; keep the pieces of min size."""
    out = []
    for (p, q), (a, b) in zip(seg, idx):
        d = q - p
        beams = np.arange(a, b + 1)
        u = np.column_stack([np.cos(scan.angles[beams]), np.sin(scan.angles[beams])])
        with np.errstate(divide='ignore', invalid='ignore'):
            t = (p[0] * d[1] - p[1] * d[0]) / (u[:, 0] * d[1] - u[:, 1] * d[0])
        hidden = scan.valid[beams] & (scan.ranges[beams] - t > margin)
        cuts = np.flatnonzero(hidden)
        for run in np.split(np.arange(beams.size), cuts):
            run = run[~hidden[run]]
            if run.size >= min_points:
                e0, e1 = t[run[0]] * u[run[0]], t[run[-1]] * u[run[-1]]
                if np.hypot(*(e1 - e0)) >= min_length:
                    out.append([e0, e1])
    return np.array(out, dtype=float).reshape(-1, 2, 2)


def _half_vertex(clusters, segs: np.ndarray, idx: np.ndarray, min_points: int,
                 min_length: float) -> np.ndarray:
    """Return the baseline segments of min size with shared vertices counted half."""
    first_of = {int(c.indices[0]) for c in clusters}
    last_of = {int(c.indices[-1]) for c in clusters}
    own = (idx[:, 1] - idx[:, 0] + 1
           - 0.5 * np.array([a not in first_of for a in idx[:, 0]], dtype=float)
           - 0.5 * np.array([b not in last_of for b in idx[:, 1]], dtype=float))
    ok = (own >= min_points) & (np.hypot(*(segs[:, 1] - segs[:, 0]).T) >= min_length)
    return segs[ok]


def score_log(scans, sigma_r: float, detailed: bool) -> dict:
    """Return per method f, baseline f, gain, deficit by cause, and the baseline variants."""
    kw = {'min_points': 3, 'min_length': 0.05} if detailed else {}
    seg_min = 1 if detailed else 5
    ref = LineParams(**kw)
    margin = max(3.0 * sigma_r, 0.05)
    out = {m: {'f': [], 'base': [], 'gain': 0.0, 'own': 0.0,
               'causes': dict.fromkeys(CAUSES, 0.0)} for m in METHODS}
    variants = {'held to no false surface': [], 'shared vertex half': []}
    for s in scans:
        nb = s.ranges.size
        valid = s.valid.sum()
        w = 1.0 / valid / len(scans)
        base_cl = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment)
        base, idx = approx_poly_segments(base_cl, 0.05)
        if not detailed:
            ok = ((idx[:, 1] - idx[:, 0] + 1 >= ref.min_points)
                  & (np.hypot(*(base[:, 1] - base[:, 0]).T) >= ref.min_length))
            variants['shared vertex half'].append(ray_metrics(
                s.ranges, s.angles, s.valid, _half_vertex(base_cl, base, idx, ref.min_points,
                                                          ref.min_length), sigma_r).f)
            base, idx = base[ok], idx[ok]
        cut = _cut_segments(s, base, idx, margin, max(ref.min_points, 2), ref.min_length)
        variants['held to no false surface'].append(
            ray_metrics(s.ranges, s.angles, s.valid, cut, sigma_r).f)
        hb = s.valid & np.isfinite(ray_ranges(s.angles, base)).any(axis=1)
        own = np.zeros(nb, dtype=bool)
        own[ray_metrics(s.ranges, s.angles, s.valid, base, sigma_r).false_surface] = True
        for m in METHODS:
            params = LineParams(method=m, **kw)
            clusters = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment,
                                    sigma_r=params.sigma_r, min_points=seg_min)
            st, lines, small = _stages(clusters, params, nb)
            kept = np.zeros(nb, dtype=bool)
            for ln in lines:
                kept[min(ln.first_index, ln.last_index):
                     max(ln.first_index, ln.last_index) + 1] = True
            st['kept'] = kept
            hm = s.valid & np.isfinite(ray_ranges(s.angles, segments_of(lines))).any(axis=1)
            r = out[m]
            r['f'].append(hm.sum() / valid)
            r['base'].append(hb.sum() / valid)
            r['gain'] += w * np.count_nonzero(hm & ~hb)
            for b in np.flatnonzero(hb & ~hm):
                cause = _cause(b, st, small)
                r['causes'][cause] += w
                r['own'] += w * (cause == 'false surface' and own[b])
    for r in out.values():
        r['f'], r['base'] = float(np.mean(r['f'])), float(np.mean(r['base']))
    return {'methods': out, 'variants': {k: float(np.mean(v)) for k, v in variants.items()
                                         if v}}


def main() -> None:
    """Print one table row per log and method, then the baseline variants."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS), help='log names (default: all six)')
    ap.add_argument('--detailed', action='store_true',
                    help='the detailed profile against the full baseline')
    args = ap.parse_args()
    rows = ['| log | method | f | baseline f | gain | deficit | '
            + ' | '.join(CAUSES) + ' |', '| --- ' * (6 + len(CAUSES)) + '|']
    context = []
    for name in args.logs:
        path = CARMEN / f'{name}-corrected.log.gz'
        if not path.exists():
            print(f'{path}: not present')
            continue
        with tempfile.TemporaryDirectory() as tmp:
            import_log(path, Path(tmp) / name)
            mount, sigma_r, _ = sensor_facts(Path(tmp) / name)
            scans, _ = bag_metric_scans(Path(tmp) / name, mount)
        sample = [scans[k] for k in sample_scans(len(scans), 20, 0)]
        res = score_log(sample, sigma_r, args.detailed)
        for m, r in res['methods'].items():
            deficit = sum(r['causes'].values())
            cells = []
            for c in CAUSES:
                v = r['causes'][c]
                cell = f'{v:.3f} ({100 * v / deficit:.0f} %)' if deficit else '0'
                if c == 'false surface':
                    cell += f' [{r["own"]:.3f}]'
                cells.append(cell)
            rows.append(f'| {name} | {m} | {r["f"]:.3f} | {r["base"]:.3f} | {r["gain"]:.3f} | '
                        f'{deficit:.3f} | ' + ' | '.join(cells) + ' |')
        context.append(f'{name}: baseline ' + ', '.join(
            f'{k} {v:.3f}' for k, v in res['variants'].items()))
        print(f'{name}: done', file=sys.stderr, flush=True)
    print('\n'.join(rows))
    print('\n'.join(context))


if __name__ == '__main__':
    main()
