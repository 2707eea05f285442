"""Why lines and corners are not re-detected between consecutive Carmen scans.

Run from the repository root (needs ``../shared/data/carmen``)::

    python benchmarks/line_repeatability_carmen.py [LOG ...]

Repeatability as ``landmark_nav evaluate-features`` scores it (lines >= 1 m re-detected
within 5 cm in rho and 2 deg in alpha, rho in the next scan's laser frame, overlapping
extents; corners within 10 cm; the places in view of the next scan) mixes three things:
the extractor, the reference poses (the Radish "corrected" poses) and, for lines, the lever
arm of rho (a line far from its foot point, e.g. a wall at grazing incidence, moves rho by
its angle difference times metres). This script separates them on every pair of
consecutive scans (node defaults; the FLASER pose as laser pose, readings >= 40 m no
return, as ``feature_metrics_carmen.py --direct``):

* ``reference``: the metric as defined;
* ``midpoint``: the line's distance compared at the midpoint of the scan-k segment (the
  midpoint's distance to the partner's line) instead of rho: no lever arm;
* ``ICP``: the relative pose of the pair refined by point-to-line ICP of the two scans
  (returns within 15 m, five-neighbour normals, pairs within 15 cm, 15 Gauss-Newton steps;
  pairs with fewer than 20 matches keep the reference) instead of the reference;
* ``ICP + midpoint``: both: what is left is the extractor's own.

A ``ceiling`` row per method (:func:`redetection_ceiling`) gives the share an extractor
would reach with exact poses if each opportunity's partner were found, unbiased, with the
same covariance as the scan-k line: what the lines' own noise allows at 5 cm / 2 deg.

Each line cell also gives, in brackets, the fraction over the opportunities whose wall
the next scan saw (:func:`seen_again`, placed by the ICP-refined pose: at least
``min_points`` returns of the next scan within 5 cm of the line inside its extent,
spanning ``min_length``); the others are opportunities no extractor of that minimum size
could meet (occluded, out of range, or too few beams on the wall in the next scan).

A second row per method splits the ``ICP`` figure by the number of points of the scan-k
line (all opportunities, and in brackets those seen again): lines of few points have
uncertain angles (a 1 m line of 12 points with 1.5 cm residuals: sigma(alpha) about
0.8 deg, so about 1.2 deg for the difference of two scans, against the 2 deg gate).

The corner row gives in brackets the ICP figure over the corners the next scan saw
again (:func:`corners_seen_again`: both arms have returns of the next scan).

It also prints the ICP corrections (median and 90th percentile of |dx|, |dy| in cm and
|dtheta| in deg): the reference poses' error between consecutive scans; the failures of
the line metric as defined in classes: no overlapping segment at all, or one off only in
rho (> 5 cm), or off in alpha (> 2 deg); and for the corners the share of opportunities
whose nearest corner in the next scan is 10-50 cm away (moved) or farther / absent (not
detected again).
"""

import argparse
import math
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from feature_metrics_carmen import carmen_logs, LOGS  # noqa: E402
from landmark_nav.evaluation.features import normal_form  # noqa: E402
from landmark_nav.evaluation.scan_metrics import (corner_repeatability, in_view,  # noqa: E402
                                                  line_opportunities, Repeatability,
                                                  segments_of)
from landmark_nav.geometry import (compose, inverse_transform_points, relative,  # noqa: E402
                                   transform_points, wrap_angle)
from landmark_nav.laser.corners import CornerParams, detect_corners  # noqa: E402
from landmark_nav.laser.lines import extract_lines, LineParams  # noqa: E402
from landmark_nav.laser.segmentation import segment_scan  # noqa: E402
from landmark_nav.slam.line_landmarks import transform_lines  # noqa: E402
from landmark_nav.slam.scan_matching import point_to_line_icp  # noqa: E402
import numpy as np  # noqa: E402

MAX_DRHO, MAX_DALPHA = 0.05, math.radians(2.0)
POINT_BINS = ((0, 15), (16, 25), (26, 40), (41, 100000))  # points of the scan-k line


def redetection_ceiling(lines_k, pose_k, scan_n, sigma_r: float, draws: np.ndarray
                        ) -> np.ndarray:
    """Chance that each opportunity's line passes the gate if both scans fit it unbiased.

    For the lines of scan k at least 1 m long whose midpoint is in view of scan k+1 (the
    metric's opportunities, reference poses), the covariance of ``(rho, alpha)`` is moved to
    scan k+1's laser frame (:func:`landmark_nav.slam.line_landmarks.transform_lines`: ``rho``
    picks up the angle's error times the lever arm); a partner fitted on the same wall with the
    same covariance makes the difference ``N(0, 2 C')``, and the returned chance is its
    probability to fall inside ``|d rho| <= 5 cm``, ``|d alpha| <= 2 deg`` (Monte Carlo
    over ``draws``, (D, 2) standard normals). Returned (A, 2): with the extractor's own
    covariance (eq. 7, the stated ``sigma_r``), and with it scaled by the fit's a-posteriori
    variance factor ``s^2 / sigma_r^2`` when above 1 (``s`` the residual std of the line's
    points, ``rmse sqrt(n / (n - 2))``). Exact poses, a partner always found and extents
    ignored: an upper bound of the re-detected share for lines of these extents.
    """
    out = []
    for i in line_opportunities(segments_of(lines_k), pose_k, scan_n)[0]:
        ln = lines_k[i]
        cov = transform_lines(relative(scan_n.pose, pose_k), np.array([ln.rho]),
                              np.array([ln.alpha]),
                              np.asarray(ln.covariance, dtype=float)[None])[2][0]
        n = ln.num_points
        factor = max(1.0, ln.rmse ** 2 * n / max(n - 2, 1) / sigma_r ** 2)
        row = []
        for c in (2.0 * cov, 2.0 * factor * cov):
            w, v = np.linalg.eigh(0.5 * (c + c.T))
            d = draws @ (v * np.sqrt(np.maximum(w, 0.0))).T
            row.append(np.mean((np.abs(d[:, 0]) <= MAX_DRHO) & (np.abs(d[:, 1]) <= MAX_DALPHA)))
        out.append(row)
    return np.array(out).reshape(-1, 2)


def icp_correction(scan_k, scan_n) -> np.ndarray:
    """Return the pose (3,) that moves scan k's points, placed by the reference, onto scan n's."""
    def points(s):
        m = s.valid & (s.ranges < 15.0)
        return np.column_stack([s.ranges[m] * np.cos(s.angles[m]),
                                s.ranges[m] * np.sin(s.angles[m])])
    p = inverse_transform_points(scan_n.pose, transform_points(scan_k.pose, points(scan_k)))
    fit = point_to_line_icp(p, points(scan_n))
    return np.zeros(3) if fit is None else fit.pose


def seen_again(mine: np.ndarray, scan_n, params: LineParams) -> np.ndarray:
    """Return (A,) True for segments (A, 2, 2) in scan n's laser frame that scan n saw.

    Seen: at least ``min_points`` valid beams of scan n whose bearings lie between the
    segment's end points return within ``max(5 cm, 3 sigma_r)`` of its line, and those
    returns span at least ``min_length`` along it, i.e. scan n holds the data of a line
    of the extractor's minimum size on that wall. The others were occluded, out of range
    or seen by too few beams (grazing incidence, a 1-degree scanner) in scan n.
    """
    f = normal_form(mine[:, 0], mine[:, 1])                            # (A, 2)
    nrm = np.stack([np.cos(f[:, 1]), np.sin(f[:, 1])], axis=1)
    b0 = np.arctan2(mine[:, 0, 1], mine[:, 0, 0])
    span = wrap_angle(np.arctan2(mine[:, 1, 1], mine[:, 1, 0]) - b0)
    rel = wrap_angle(scan_n.angles[None, :] - b0[:, None]) * np.where(span < 0, -1.0, 1.0)[:, None]
    inside = (rel >= 0.0) & (rel <= np.abs(span)[:, None]) & scan_n.valid[None, :]
    r = np.where(scan_n.valid, scan_n.ranges, 0.0)
    pts = np.stack([r * np.cos(scan_n.angles), r * np.sin(scan_n.angles)], axis=1)
    on = inside & (np.abs(nrm @ pts.T - f[:, :1]) <= max(0.05, 3.0 * params.sigma_r))
    along = np.stack([-nrm[:, 1], nrm[:, 0]], axis=1) @ pts.T           # (A, N)
    extent = (np.where(on, along, -np.inf).max(axis=1)
              - np.where(on, along, np.inf).min(axis=1))
    return (on.sum(axis=1) >= params.min_points) & (extent >= params.min_length)


def line_matches(seg_k, pose_k, seg_n, scan_n, midpoint, seen_pose=None, params=None):
    """Return (opportunities, re-detected, none, rho only, alpha, seen, seen and re-detected).

    ``seen``: opportunities whose wall scan n saw (:func:`seen_again`, the segment placed
    by ``seen_pose``, e.g. the ICP-refined pose; default ``pose_k``).
    """
    seg_k = seg_k[np.hypot(*(seg_k[:, 1] - seg_k[:, 0]).T) >= 1.0]
    if not len(seg_k):
        return np.zeros(7, dtype=int)
    world = transform_points(pose_k, seg_k.reshape(-1, 2)).reshape(-1, 2, 2)
    look = in_view(scan_n, world.mean(axis=1), 0.1)
    if not look.any():
        return np.zeros(7, dtype=int)
    mine = inverse_transform_points(scan_n.pose, world[look].reshape(-1, 2)).reshape(-1, 2, 2)
    placed = mine
    if seen_pose is not None:
        placed = inverse_transform_points(scan_n.pose, transform_points(
            seen_pose, seg_k[look].reshape(-1, 2))).reshape(-1, 2, 2)
    seen = seen_again(placed, scan_n, params or LineParams())
    if not len(seg_n):
        return np.array([look.sum(), 0, look.sum(), 0, 0, seen.sum(), 0])
    f_k, f_n = normal_form(mine[:, 0], mine[:, 1]), normal_form(seg_n[:, 0], seg_n[:, 1])
    da = np.abs(wrap_angle(f_k[:, None, 1] - f_n[None, :, 1]))
    if midpoint:
        mid = mine.mean(axis=1)
        dr = np.abs(mid[:, None, 0] * np.cos(f_n[None, :, 1])
                    + mid[:, None, 1] * np.sin(f_n[None, :, 1]) - f_n[None, :, 0])
    else:
        dr = np.abs(f_k[:, None, 0] - f_n[None, :, 0])
    d = mine[:, 1] - mine[:, 0]
    length2 = np.einsum('ij,ij->i', d, d)[:, None]
    base = np.einsum('aj,aj->a', mine[:, 0], d)[:, None]
    t0 = (np.einsum('bj,aj->ab', seg_n[:, 0], d) - base) / length2
    t1 = (np.einsum('bj,aj->ab', seg_n[:, 1], d) - base) / length2
    overlap = (np.maximum(t0, t1) > 0.0) & (np.minimum(t0, t1) < 1.0)
    ok = (overlap & (dr <= MAX_DRHO) & (da <= MAX_DALPHA)).any(axis=1)
    none = ~overlap.any(axis=1)
    rho_only = ~ok & ~none & (overlap & (da <= MAX_DALPHA)).any(axis=1)
    return np.array([look.sum(), ok.sum(), none.sum(), rho_only.sum(),
                     (~ok & ~none & ~rho_only).sum(), seen.sum(), (seen & ok).sum()])


def corners_seen_again(corners_k, pose_k, corners_n, scan_n, params: CornerParams
                       ) -> np.ndarray:
    """Return (seen, seen and re-detected) of scan k's corners in view of scan n.

    Seen: each arm (``Corner.arms``, placed by ``pose_k``) has at least three returns of
    scan n within 5 cm of its line, beside the vertex, reaching ``arm_length`` (the
    detector's smallest arm) from it; re-detected as :func:`corner_repeatability` (a
    corner of scan n within 10 cm).
    """
    if not corners_k:
        return np.zeros(2, dtype=int)
    world = transform_points(pose_k, np.array([c.position for c in corners_k]))
    look = in_view(scan_n, world, 0.1)
    other = transform_points(scan_n.pose, corners_n) if len(corners_n) else np.zeros((0, 2))
    r = np.where(scan_n.valid, scan_n.ranges, 0.0)
    pts = np.stack([r * np.cos(scan_n.angles), r * np.sin(scan_n.angles)], axis=1)
    pts = pts[scan_n.valid]
    out = np.zeros(2, dtype=int)
    for i in look.nonzero()[0]:
        arms = inverse_transform_points(scan_n.pose, transform_points(
            pose_k, corners_k[i].arms.reshape(-1, 2))).reshape(2, 2, 2)
        rel = pts - inverse_transform_points(scan_n.pose, world[i:i + 1])[0]
        both = True
        for arm in arms:
            d = arm[1] - arm[0]
            length = math.hypot(d[0], d[1])
            if length < 1e-9:
                both = False
                break
            t = d / length
            along = rel @ t
            on = ((np.abs(rel @ np.array([-t[1], t[0]])) <= 0.05) & (along > 0.0)
                  & (along <= min(params.fit_length, max(length, params.arm_length) + 0.1)))
            both &= bool(on.sum() >= 3 and along[on].max() >= params.arm_length)
        if both:
            out[0] += 1
            out[1] += bool(len(other)) and np.hypot(*(other - world[i]).T).min() <= 0.1
    return out


def corner_distances(c_k, pose_k, c_n, scan_n) -> np.ndarray:
    """Return the distance of each corner of scan k in view of scan n to n's nearest [m]."""
    if not len(c_k):
        return np.zeros(0)
    world = transform_points(pose_k, c_k)
    world = world[in_view(scan_n, world, 0.1)]
    if not len(c_n):
        return np.full(len(world), np.inf)
    other = transform_points(scan_n.pose, c_n)
    dist = np.hypot(*(world[:, None] - other[None]).transpose(2, 0, 1))
    return dist.min(axis=1, initial=np.inf)


def main() -> None:
    """Print one table per log."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS), help='log names (default: all six)')
    args = ap.parse_args()
    print('| log | method | reference | midpoint | ICP | ICP + midpoint | failures (reference):'
          ' none / rho only / alpha |')
    print('| --- | --- | --- | --- | --- | --- | --- |')
    for name, scans in carmen_logs(args.logs):
        corr = np.array([icp_correction(a, b) for a, b in zip(scans[:-1], scans[1:])])
        refined = [compose(b.pose, compose(c, relative(b.pose, a.pose)))
                   for a, b, c in zip(scans[:-1], scans[1:], corr)]
        clusters = [segment_scan(s.ranges, s.angles, s.valid, s.angle_increment)
                    for s in scans]
        for method in ('split_merge', 'alfa'):
            params = LineParams(method=method)
            lines = [extract_lines(c, params) for c in clusters]
            segs = [segments_of(ln) for ln in lines]
            npts = [np.array([ln.num_points for ln in lns], dtype=int) for lns in lines]
            tally = {}
            for key, use_icp, mid in (('reference', False, False), ('midpoint', False, True),
                                      ('ICP', True, False), ('ICP + midpoint', True, True)):
                tally[key] = sum(
                    line_matches(segs[k], refined[k] if use_icp else scans[k].pose,
                                 segs[k + 1], scans[k + 1], mid, refined[k], params)
                    for k in range(len(scans) - 1))
            cells = ' | '.join(f'{v[1] / max(v[0], 1):.3f} ({v[6] / max(v[5], 1):.3f})'
                               for v in tally.values())
            ref = tally['reference']
            print(f'| {name} | {method} lines >= 1 m ({ref[0]}, seen {ref[5]}) | {cells} | '
                  f'{ref[2]} / {ref[3]} / {ref[4]} |', flush=True)
            bins = []
            for lo, hi in POINT_BINS:
                v = sum(line_matches(segs[k][(npts[k] >= lo) & (npts[k] <= hi)], refined[k],
                                     segs[k + 1], scans[k + 1], False, refined[k], params)
                        for k in range(len(scans) - 1))
                bins.append(f'{lo}-{hi}: {v[1] / max(v[0], 1):.2f} ({v[0]}), seen '
                            f'{v[6] / max(v[5], 1):.2f} ({v[5]})')
            print(f'| {name} | {method} ICP, by points of the scan-k line | '
                  + '; '.join(bins) + ' | | | | |', flush=True)
            draws = np.random.default_rng(0).standard_normal((4000, 2))
            ceil = np.concatenate([redetection_ceiling(lines[k], scans[k].pose, scans[k + 1],
                                                       params.sigma_r, draws)
                                   for k in range(len(scans) - 1)])
            print(f'| {name} | {method} ceiling: both fits unbiased, exact poses '
                  f'({len(ceil)}) | eq. 7 covariance {ceil[:, 0].mean():.3f}, a-posteriori '
                  f'variance {ceil[:, 1].mean():.3f} | | | | |', flush=True)
        params = CornerParams()
        found = [detect_corners(cl, params) for cl in clusters]
        corners = [np.array([c.position for c in cs]).reshape(-1, 2) for cs in found]
        tally = {}
        for key, use_icp in (('reference', False), ('ICP', True)):
            score = Repeatability()
            for k in range(len(scans) - 1):
                corner_repeatability(score, corners[k], refined[k] if use_icp else scans[k].pose,
                                     corners[k + 1], scans[k + 1])
            tally[key] = score
        near = [corner_distances(corners[k], scans[k].pose, corners[k + 1], scans[k + 1])
                for k in range(len(scans) - 1)]
        near = np.concatenate(near) if near else np.zeros(0)
        seen = np.zeros(2, dtype=int)  # seen again, of which re-detected (ICP)
        for k in range(len(scans) - 1):
            seen += corners_seen_again(found[k], refined[k], corners[k + 1], scans[k + 1],
                                       params)
        print(f'| {name} | minus_cosine corners ({tally["reference"].opportunities}, seen '
              f'{seen[0]}) | {tally["reference"].fraction:.3f} | | {tally["ICP"].fraction:.3f} '
              f'({seen[1] / max(seen[0], 1):.3f}) | | '
              f'next corner 10-50 cm away: {np.mean((near > 0.1) & (near <= 0.5)):.3f}, '
              f'none within 50 cm: {np.mean(near > 0.5):.3f} |')
        a = np.abs(corr)
        print(f'| {name} | ICP corrections of the reference, median (90 %) | '
              f'dx {100 * np.median(a[:, 0]):.1f} ({100 * np.percentile(a[:, 0], 90):.1f}) cm, '
              f'dy {100 * np.median(a[:, 1]):.1f} ({100 * np.percentile(a[:, 1], 90):.1f}) cm, '
              f'dtheta {math.degrees(np.median(a[:, 2])):.2f} '
              f'({math.degrees(np.percentile(a[:, 2], 90)):.2f}) deg | | | | |', flush=True)


if __name__ == '__main__':
    main()
