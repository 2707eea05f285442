"""Corner repeatability misses on the Carmen logs, each put to the check that lost it.

Run from the repository root (needs ``../shared/data/carmen``)::

    python benchmarks/corner_miss_causes_carmen.py [--show N] [LOG ...]

As ``corner_repeatability_carmen.py`` (every scan, FLASER pose as laser pose, node
defaults): every corner of scan k that scan k+1 could observe and that no corner of scan
k+1 re-detects within 10 cm is a miss. The minus-cosine pipeline is traced on scan k+1
around the missed corner's place (samples within 15 cm of it) and the miss goes to the
last stage any window there passed:

* ``segmentation``: no sample of a cluster near the place;
* ``field of view``: no window fits and the place is within ``window // 2`` samples of
  the scan's first or last beam (an arm leaving the field of view: the opportunity rule
  probes 15 cm along each arm, the window needs ``window // 2`` beams);
* ``window``: no window fits (the place within ``window // 2`` samples of a cluster end:
  a cluster break);
* ``cluster end``: no window's ``f`` (eq. 11) inside ``[f_min, f_max]`` and a cluster
  ends near the place (the corner split by the segmentation, an arm occluded or a
  T-junction: the windows there span one straight surface);
* ``gate angle``: no window's ``f`` inside the bounds, no cluster end near the place;
* ``gate arms``: the window's arms, clipped at the cluster end, shorter than half
  ``arm_length``;
* ``midpoint shift``: the ghost check (Figs. 11-12) rejected every candidate;
* ``local minimum``: no local minimum of ``f`` near the place;
* ``significance``, ``arm points / reach / rmse / inliers``, ``fit angle`` (the fitted
  arms' angle outside the bounds), ``offset`` (intersection beyond the window's reach):
  the refinement's checks, in that order, of the refined corner that got furthest;
* ``moved``: a refined corner passed every check but lies more than 10 cm away;
* ``merged``: it passed but was merged into a better one nearby.

For ``fit angle`` misses the fitted angle is printed with its standard deviation
propagated from the arm fits (eq. 7 point noise through eq. 8) and, for ``gate angle``
misses, the window's ``f`` nearest to the bounds.
"""

import argparse
from collections import Counter
from dataclasses import replace
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from feature_metrics_carmen import carmen_logs, LOGS  # noqa: E402
from landmark_nav.evaluation.scan_metrics import corner_observable, in_view  # noqa: E402
from landmark_nav.geometry import inverse_transform_points, transform_points  # noqa: E402
from landmark_nav.laser.corner_detection.corner import _free_side  # noqa: E402
from landmark_nav.laser.corner_detection.refine import _arm_support, _fit_arms  # noqa: E402
from landmark_nav.laser.corner_detection.scan_stack import _stack  # noqa: E402
from landmark_nav.laser.corner_detection.tls_lines import (_arm_directions,  # noqa: E402
                                                           _line_angle_variance)
from landmark_nav.laser.corner_detection.windows import (_local_minima,  # noqa: E402
                                                         _minus_cos, _window_f_sd)
from landmark_nav.laser.corners import CornerParams, detect_corners  # noqa: E402
from landmark_nav.laser.segmentation import segment_scan  # noqa: E402
import numpy as np  # noqa: E402

STAGES = ('segmentation', 'field of view', 'window', 'cluster end', 'gate angle',
          'gate arms', 'midpoint shift', 'local minimum', 'significance', 'arm points',
          'arm reach', 'arm rmse', 'arm inliers', 'fit angle', 'offset', 'moved', 'merged')


def trace(s, p: CornerParams) -> dict:
    """Run the minus-cosine pipeline on one scan and keep every stage's outcome."""
    cl = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment, sigma_r=p.sigma_r)
    st = _stack(cl)
    out = {'st': st, 'n_beams': len(s.ranges)}
    if st is None:
        return out
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        h0 = p.window // 2
        m = np.arange(st.x.size)
        spacing = np.fmax(st.r * st.dphi, 1e-9)
        h = np.minimum(np.maximum(np.ceil(p.arm_length / spacing), h0), p.max_half_window)
        h = h.astype(np.int64)
        lo = np.maximum(m - h, st.start)
        hi = np.minimum(m + h, st.end - 1)
        win = (m - lo >= h0) & (hi - m >= h0)
        x, y = st.x, st.y
        f, a2, b2 = _minus_cos(x[lo], y[lo], x, y, x[hi], y[hi])
        widen = 0.0
        if p.gate_sigmas > 0.0:
            widen = p.gate_sigmas * _window_f_sd(st, lo, m, hi, p)
        gate = win & (f >= p.f_min - widen) & (f <= p.f_max + widen)
        arms = gate & (np.minimum(a2, b2) >= 0.25 * p.arm_length ** 2)
        a, b = np.sqrt(a2), np.sqrt(b2)
        step = np.maximum(a / np.maximum(m - lo, 1), b / np.maximum(hi - m, 1))
        tol = p.midpoint_shift * step / np.minimum(a, b) + widen
        shift = arms.copy()
        for sh in (p.midpoint_shift, -p.midpoint_shift):
            mm = np.clip(m + sh, 0, m.size - 1)
            fs = _minus_cos(x[lo], y[lo], x[mm], y[mm], x[hi], y[hi])[0]
            shift &= (fs >= p.f_min - tol) & (fs <= p.f_max + tol)
        mid = np.flatnonzero(shift)
        out.update(win=win, f=f, gate=gate, arms=arms, shift=shift, lo=lo, hi=hi)
        locmin = np.zeros(m.size, dtype=bool)
        if mid.size:
            sel = _local_minima(mid, f[mid], m.size)
            locmin[mid[sel]] = True
            out['ref'] = refine_trace(st, mid[sel], lo[mid[sel]], hi[mid[sel]], f[mid[sel]], p)
        out['locmin'] = locmin
    return out


def refine_trace(st, g, lo, hi, fg, p: CornerParams) -> dict:
    """Return every refinement check of windows ``g`` (the checks of ``refine._refine``)."""
    g0 = g
    g, found, lines, cx, cy, x, y, r, valid, w = _fit_arms(st, g, lo, hi, p)
    ux, uy = _arm_directions(lines, cx, cy)
    _, _, cos_t = _free_side(cx, cy, ux[:, 0], uy[:, 0], ux[:, 1], uy[:, 1])
    f_fit = -cos_t
    px, py = st.x[g], st.y[g]
    reach2 = np.minimum((st.x[lo] - px) ** 2 + (st.y[lo] - py) ** 2,
                        (st.x[hi] - px) ** 2 + (st.y[hi] - py) ** 2)
    shift2 = (cx - px) ** 2 + (cy - py) ** 2
    # the real_arms sub-checks, each alone (see corner_detection.refine._arm_support)
    sub = {}
    big = 1e6
    for name, q in (('arm points', replace(p, real_arms=False)),
                    ('arm reach', replace(p, arm_rmse=big, min_arm_inliers=0.0)),
                    ('arm rmse', replace(p, min_arm_length=0.0, min_arm_inliers=0.0)),
                    ('arm inliers', replace(p, min_arm_length=0.0, arm_rmse=big))):
        sub[name] = _arm_support(x, y, r, valid, w, lines, q)[1]
    var_a = _line_angle_variance(x, y, w, lines, p.sigma_r, p.sigma_phi)
    return {'g0': g0, 'g': g, 'cx': cx, 'cy': cy, 'found': found, 'sub': sub,
            'f_fit': f_fit, 'offset_ok': shift2 <= reach2,
            'sd_theta': np.sqrt(var_a.sum(axis=1))}


def classify(tr: dict, pt: np.ndarray, detected: np.ndarray, radius: float = 0.15):
    """Return (stage, detail) of the corner at ``pt`` (laser frame of the traced scan)."""
    st = tr['st']
    if st is None:
        return 'segmentation', ''
    d = np.hypot(st.x - pt[0], st.y - pt[1])
    nb = np.flatnonzero(d <= radius)
    if nb.size == 0:
        return 'segmentation', ''
    for stage, key in (('window', 'win'), ('gate angle', 'gate'), ('gate arms', 'arms'),
                       ('midpoint shift', 'shift'), ('local minimum', 'locmin')):
        if not tr[key][nb].any():
            detail = ''
            if stage == 'window':
                h0 = CornerParams().window // 2
                if (st.beam[nb].min() < h0 or st.beam[nb].max() > tr['n_beams'] - 1 - h0):
                    stage = 'field of view'
            if stage == 'gate angle':
                fv = tr['f'][nb][tr['win'][nb]]
                fv = fv[np.isfinite(fv)]
                if fv.size:
                    p = CornerParams()
                    k = np.argmin(np.maximum(p.f_min - fv, fv - p.f_max))
                    detail = f'f {fv[k]:+.3f} ({np.degrees(np.arccos(-fv[k])):.1f} deg)'
                ends = (st.start[nb] == nb) | (st.end[nb] - 1 == nb)
                if ends.any():
                    stage = 'cluster end'
            return stage, detail
    ref = tr['ref']
    p = CornerParams()
    near_g = np.isin(ref['g'], nb) | np.isin(ref['g0'], nb)
    close = np.hypot(ref['cx'] - pt[0], ref['cy'] - pt[1]) <= radius
    cand = np.flatnonzero(near_g | close)
    if cand.size == 0:
        return 'local minimum', 'refined elsewhere'
    best, best_rank, detail = None, -1, ''
    for i in cand:
        checks = [('significance', ref['found'][i])]
        checks += [(k, ref['sub'][k][i]) for k in ('arm points', 'arm reach', 'arm rmse',
                                                   'arm inliers')]
        ff = ref['f_fit'][i]
        checks.append(('fit angle', p.f_min <= ff <= p.f_max))
        checks.append(('offset', ref['offset_ok'][i]))
        dist = np.hypot(ref['cx'][i] - pt[0], ref['cy'][i] - pt[1])
        checks.append(('moved', dist <= 0.1))
        rank = next((j for j, (_, ok) in enumerate(checks) if not ok), len(checks))
        if rank > best_rank:
            best_rank = rank
            best = checks[rank][0] if rank < len(checks) else 'merged'
            th = np.degrees(np.arccos(-np.clip(ff, -1, 1)))
            sd = np.degrees(ref['sd_theta'][i])
            detail = f'fit {th:.1f} +- {sd:.2f} deg, dist {dist:.3f}'
    return best, detail


def main() -> None:
    """Print the miss causes per log."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS), help='log names (default: all six)')
    ap.add_argument('--show', type=int, default=0, help='print the first N misses per log')
    ap.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                    help='a CornerParams field (float value)')
    args = ap.parse_args()
    p = CornerParams(**{k: float(v) for k, v in (a.split('=', 1) for a in args.set)})
    for name, scans in carmen_logs(args.logs):
        found = []
        for s in scans:
            cl = segment_scan(s.ranges, s.angles, s.valid, s.angle_increment, sigma_r=p.sigma_r)
            found.append(detect_corners(cl, p))
        causes, shown, n_opp = Counter(), 0, 0
        fit_angles = []
        for k in range(len(scans) - 1):
            ck = found[k]
            if not ck:
                continue
            pos = np.array([c.position for c in ck])
            wedge = np.array([[c.bisector, c.opening] for c in ck])
            world = transform_points(scans[k].pose, pos).reshape(-1, 2)
            ang = scans[k].pose[2] + wedge[:, :1] + 0.5 * wedge[:, 1:] * np.array([1.0, -1.0])
            view = scans[k + 1]
            look = in_view(view, world) & corner_observable(view, world, ang)
            n_opp += int(look.sum())
            nxt = np.array([c.position for c in found[k + 1]]).reshape(-1, 2)
            other = transform_points(view.pose, nxt).reshape(-1, 2)
            dist = np.hypot(*(world[:, None] - other[None]).transpose(2, 0, 1)).min(
                axis=1, initial=np.inf)
            miss = np.flatnonzero(look & (dist > 0.1))
            if not miss.size:
                continue
            tr = trace(view, p)
            local = inverse_transform_points(view.pose, world[miss]).reshape(-1, 2)
            for i, pt in zip(miss, local):
                stage, detail = classify(tr, pt, nxt)
                causes[stage] += 1
                own = ck[i]
                th = np.degrees(np.arccos(-np.clip(own.f_theta, -1, 1)))
                if stage == 'fit angle':
                    fit_angles.append(detail)
                if shown < args.show:
                    shown += 1
                    print(f'  {name} scan {k} -> {k + 1}: corner beam {own.index} at '
                          f'{np.round(own.position, 2)} (window {th:.1f} deg, opening '
                          f'{np.degrees(own.opening):.1f}): {stage} {detail}')
        total = sum(causes.values())
        print(f'{name}: {total} misses of {n_opp} opportunities')
        for stage in STAGES:
            if causes[stage]:
                print(f'  {stage:15s} {causes[stage]:4d}  {causes[stage] / total:6.1%}'
                      f'  ({causes[stage] / n_opp:5.1%} of opportunities)')
        for d in fit_angles:
            print(f'    fit angle miss: {d}')


if __name__ == '__main__':
    main()
