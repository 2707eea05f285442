"""Step 5 of the line extractors: occluders in front of a line.

A line's extent is cut at occluders (:func:`_occluded_extents`), and lines of one surface
on both sides of an occluder get one fit when they pass the merge's chi-square test
(:func:`_join_occluded`).
"""

from bisect import bisect_left
import math
from typing import List, Optional, Tuple

from landmark_nav.laser.line_extraction.merge import (_chi2, _variance_factor,
                                                      _variance_factor_py)
from landmark_nav.laser.line_extraction.params import LineParams
from landmark_nav.laser.line_extraction.scan_batch import _gather, _PHI, _Scan, _TOL, _X, _Y
from landmark_nav.laser.line_extraction.see_through import _extent_beams
from landmark_nav.laser.line_extraction.segments import _build
from landmark_nav.laser.line_extraction.tls_fit import (_Fit, _line_py, _SMALL_NO_COV, _solve,
                                                        _wrap, TWO_PI)
import numpy as np


def _shrunk_extents(scan: _Scan, f: _Fit, first: np.ndarray, last: np.ndarray
                    ) -> Optional[List[Tuple[int, int]]]:
    """Return the lines' beam ranges if they lie within those cached on ``f``, else None.

    :func:`_cut_seen_through` shrinks the extents of lines that hide only their noise and
    keeps their fits: the beams of the new extents are then among the cached ones of
    :func:`_extent_beams` (the same values), and a test of those beams needs only to
    keep the ones inside the new ranges. None when nothing is cached for these fits, the
    cache is for these very extents, or a range is not within its line's cached one.
    """
    ext = f.extent
    if ext is None or (ext[0] is first and ext[1] is last) or ext[0].size != first.size:
        return None
    beam = memoryview(scan.beam)
    out = []
    for a, b, a0, b0 in zip(first.tolist(), last.tolist(), ext[0].tolist(), ext[1].tolist()):
        lo, hi = min(beam[a], beam[b]), max(beam[a], beam[b])
        if not min(beam[a0], beam[b0]) <= lo <= hi <= max(beam[a0], beam[b0]):
            return None
        out.append((lo, hi))
    return out


def _occluded_extents(scan: _Scan, f: _Fit, first: np.ndarray, last: np.ndarray,
                      params: LineParams) -> Tuple[Optional[np.ndarray], np.ndarray, np.ndarray]:
    """Cut the lines' extents at occluders (step 5); return (line, first, last) per piece.

    An occluder of a line is a run of two or more neighbouring valid beams inside its
    extent whose returns lie in front of it by more than the opening margin of
    :func:`_seen_through` (``see_through_tolerance`` plus 3 standard deviations of the
    distance along the ray, eq. 7). The extent's points are split at the occluders'
    beams (which leave); pieces of at least ``min_points`` points are kept, each
    pointing to its line's fit. Without occluders every line is one piece and the
    result is ``(None, first, last)``.
    """
    same = None, first, last
    within = _shrunk_extents(scan, f, first, last)
    idx, line, rho, r, cos_in = (_extent_beams(scan, f, first, last) if within is None
                                 else f.extent[2])
    front = rho / cos_in - r  # how far the return lies in front of the line
    # Only a beam in front by more than the tolerance can be in front by the margin.
    hit = ((cos_in > 1e-9) & (front > params.see_through_tolerance)).nonzero()[0]
    if within is not None and hit.size:  # the beams of the earlier extents: keep those
        hit = hit[[within[j][0] <= b <= within[j][1]  # inside the lines' extents now
                   for j, b in zip(line[hit].tolist(), idx[hit].tolist())]]
    if hit.size < 2:
        return same
    r, cos_in = r[hit], cos_in[hit]
    c2 = cos_in * cos_in
    var = params.gate_sigma_r ** 2 + (r * params.sigma_phi) ** 2 * (1.0 - c2) / c2
    hit = hit[front[hit] > params.see_through_tolerance + 3.0 * np.sqrt(var)]
    if hit.size < 2:
        return same
    fl, fb = line[hit], idx[hit]
    pair = (fl[1:] == fl[:-1]) & (fb[1:] - fb[:-1] == 1)
    if not np.count_nonzero(pair):
        return same
    occ = np.zeros(hit.size, dtype=bool)
    occ[1:] |= pair
    occ[:-1] |= pair
    size = scan.nbeam
    key_occ = fl[occ] * size + fb[occ]  # sorted (line-major, beams increasing)
    pts, offs = _gather(first, last)
    own = np.arange(first.size).repeat(offs[1:] - offs[:-1])
    key = own * size + scan.beam[pts]
    cut = np.searchsorted(key_occ, key)  # occluder beams of the line before each point
    keep = (cut >= key_occ.size) | (key_occ[np.minimum(cut, key_occ.size - 1)] != key)
    pts, own, cut = pts[keep], own[keep], cut[keep]
    new = np.empty(pts.size, dtype=bool)
    new[:1] = True
    new[1:] = (own[1:] != own[:-1]) | (cut[1:] != cut[:-1])
    starts = new.nonzero()[0]
    bounds = np.empty(starts.size + 1, dtype=np.int64)
    bounds[:-1] = starts
    bounds[-1] = pts.size
    count = bounds[1:] - bounds[:-1]
    big = count >= params.min_points
    starts, count = starts[big], count[big]
    return own[starts], pts[starts], pts[starts + count - 1]


# Lines per scan up to which _join_occluded's first test runs on Python floats (measured).
_JOIN_PAIRS_PY = 12


def _join_occluded(scan: _Scan, sums: np.ndarray, first: np.ndarray, last: np.ndarray,
                   f: _Fit, pieces: Tuple[np.ndarray, np.ndarray], params: LineParams
                   ) -> _Fit:
    """Fit lines of one surface split by an occluder or a gap as one line (step 5).

    The merge (step 3) tests consecutive pieces only, and neighbouring clusters only
    when their facing ends are within ``merge_gap`` / ``merge_gap_angle``: a wall seen
    on both sides of a table leg or a pillar in front of it (whose pieces lie between
    the wall's) stays two lines, each with the covariance of half the wall's beams. Here
    a line j and a later line k (in beam order) get one fit, on the points of both, when

    * their (rho, alpha) pass the merge test (chi-square with the a-posteriori variance
      factors of :func:`_variance_factor`) and each passes it against the joint fit
      (taken as exact), with its end points within the split tolerance of it;
    * no valid beam from j's first to k's last beam lies beyond the joint line by more
      than ``see_through_tolerance``: the beams between them are occluded from the front
      (or the wall's own returns that no line took), never beams that saw further;
    * no beam between them within that tolerance of the joint line belongs to the
      extent of another line (a line between on the same surface that failed the test);
    * every run of missing beams between them is within ``merge_gap`` or
      ``merge_gap_angle`` of the joint line (the merge's rule for dropouts);
    * every extent that would carry the joint fit still passes step 6 with it (a join
      never drops a segment).

    Consecutive lines whose facing pieces (``pieces``: the first and last points of the
    pieces the merge saw) were consecutive neighbours there are not joined: the merge
    tested them, also against the merged line of the whole chain, which a pair cannot (a
    panel 5 mm proud of a wall must not take one wall piece and keep it from the other).

    A line takes the later lines that pass, in order. The extents stay as they were (the
    joined lines are reported as one segment per extent, each with the joint fit: no
    segment spans the beams between). Returns the fits of the extents ``first``, ``last``
    (the input fits where nothing was joined).
    """
    n = first.size
    if n < 2:
        return f
    gate = params.merge_chi2
    tol = params.see_through_tolerance

    def chi2(r1, a1, c1, r2, a2, c2) -> float:
        """Return :func:`_chi2` of one pair (``c2`` None: line 2 exact)."""
        da = _wrap(a1 - a2)
        sign = 1.0
        if abs(da) > 0.5 * math.pi:
            dr, da, sign = r1 + r2, _wrap(da + math.pi), -1.0
        else:
            dr = r1 - r2
        a00, a01, a11 = c1[0], c1[1], c1[3]
        if c2 is not None:
            a00, a01, a11 = a00 + c2[0], a01 + sign * c2[1], a11 + c2[3]
        det = a00 * a11 - a01 * a01
        if not det > 0.0:
            return math.inf
        d2 = (a11 * dr * dr - 2.0 * a01 * dr * da + a00 * da * da) / det
        return d2 if d2 == d2 else math.inf

    # cheap first test on every pair j < k: the two fits agree (a grown line retests all);
    # on Python floats for a few lines (the same operations as _chi2, the same results)
    rho_l, alpha_l, nx_l, ny_l = f.params.tolist()
    factor = None
    if n <= _JOIN_PAIRS_PY:
        try:
            factor = _variance_factor_py(sums, f, nx_l, ny_l)
        except ZeroDivisionError:  # degenerate fits: numpy's inf / nan below
            pass
    if factor is None:
        factor = _variance_factor(sums, f)
        cov = (f.cov * factor[:, None, None]).reshape(-1, 4).tolist()
    else:
        cov = [[c * k for c in row] for row, k in zip(f.cov.reshape(-1, 4).tolist(), factor)]
    if n <= _JOIN_PAIRS_PY:
        pi, two_pi = math.pi, TWO_PI
        tried = set()
        for j in range(n - 1):
            r1, a1, c1 = rho_l[j], alpha_l[j], cov[j]
            for k in range(j + 1, n):
                r2, c2 = rho_l[k], cov[k]
                da = abs((a1 - alpha_l[k] + pi) % two_pi - pi)
                dr = r1 - r2
                if da > 0.5 * pi:
                    da, dr = pi - da, r1 + r2
                # d2 is at least each part alone, da^2 / (C1 + C2)_aa and dr^2 /
                # (C1 + C2)_rr: most pairs (lines of other walls) fail on these
                if (da * da <= gate * (c1[3] + c2[3]) and dr * dr <= gate * (c1[0] + c2[0])
                        and chi2(r1, a1, c1, r2, alpha_l[k], c2) <= gate):
                    tried.add((j, k))
    else:
        jj, kk = np.triu_indices(n, 1)
        scaled = f.cov * np.asarray(factor)[:, None, None]
        agree = (_chi2(f.rho[jj], f.alpha[jj], scaled[jj], f.rho[kk], f.alpha[kk],
                       scaled[kk]) <= gate).nonzero()[0]
        tried = set(zip(jj[agree].tolist(), kk[agree].tolist()))
    if not tried:
        return f
    wr, wc, ws, wv = scan.beams()
    phi = scan.whole.angles if scan.whole is not None else None
    beam = scan.beam
    xs, ys, tols = scan.rows()[_X], scan.rows()[_Y], scan.rows()[_TOL]
    ox, oy = scan.origin
    first_l, last_l = first.tolist(), last.tolist()
    fits = {j: (rho_l[j], alpha_l[j], cov[j]) for j in range(n)}
    line_sums = {j: sums[:, j] for j in range(n)}
    owner = list(range(n))  # the line whose fit each extent takes
    ends = {j: (first_l[j], last_l[j]) for j in range(n)}  # outermost points of a fit
    gap2 = params.merge_gap ** 2

    def joinable(j: int, k: int) -> Optional[Tuple[np.ndarray, _Fit]]:
        """Return the joint sums and fit of lines j < k if they may be joined, else None."""
        r1, a1, c1 = fits[j]
        r2, a2, c2 = fits[k]
        if chi2(r1, a1, c1, r2, a2, c2) > gate:
            return None
        joint = line_sums[j] + line_sums[k]
        line = None  # the tests need the line only: _solve's, on Python floats if it would be
        if _SMALL_NO_COV >= 1:
            try:
                line = _line_py(joint[:6].tolist(), scan.origin)
            except ZeroDivisionError:  # degenerate sums: numpy's inf / nan below
                pass
        if line is None:
            line = _solve(joint[:6, None], scan.origin, rmse=False).params[:, 0].tolist()
        rg, ag, nx, ny = line
        if not (chi2(r1, a1, c1, rg, ag, None) <= gate and chi2(r2, a2, c2, rg, ag, None)
                <= gate):
            return None
        rel = rg - nx * ox - ny * oy
        for p in ends[j] + (first_l[k], last_l[k]):
            if not abs(xs[p] * nx + ys[p] * ny - rel) <= tols[p]:
                return None
        b0, b1 = int(beam[ends[j][0]]), int(beam[last_l[k]])
        e0, s1 = int(beam[ends[j][1]]), int(beam[first_l[k]])
        if not b0 <= e0 < s1 <= b1:
            return None
        span = slice(b0, b1 + 1)  # the beams from j's first to k's last (views)
        cos_in = wc[span] * nx + ws[span] * ny
        if np.count_nonzero(cos_in <= 1e-9):
            return None
        beyond = wr[span] - rg / cos_in
        ok = wv[span]
        if np.count_nonzero(ok & (beyond > tol)):  # a beam seen through the joint line
            return None
        gap = slice(e0 + 1 - b0, s1 - b0)  # the beams between the two lines
        gv = ok[gap]
        on = gv & (np.abs(beyond[gap]) <= tol)
        if np.count_nonzero(on):  # the wall's free returns, but no other line's beams
            taken = np.zeros(s1 - e0 - 1, dtype=bool)
            for m in range(n):
                if owner[m] != j:
                    lo = max(int(beam[first_l[m]]), e0 + 1)
                    hi = min(int(beam[last_l[m]]), s1 - 1)
                    if lo <= hi:
                        taken[lo - e0 - 1:hi - e0] = True
            if np.count_nonzero(on & taken):
                return None
        if not gv.all():  # runs of missing beams: the merge's rule for dropouts
            miss = np.flatnonzero(~gv) + e0 + 1
            starts = np.flatnonzero(np.diff(miss, prepend=-2) > 1)
            stops = np.append(starts[1:], miss.size) - 1
            for a, b in zip(miss[starts].tolist(), miss[stops].tolist()):
                # the joint line's points on the rays of the beams around the run
                pa, pb = a - 1, b + 1
                ta = rg / (wc[pa] * nx + ws[pa] * ny)
                tb = rg / (wc[pb] * nx + ws[pb] * ny)
                dx, dy = tb * wc[pb] - ta * wc[pa], tb * ws[pb] - ta * ws[pa]
                if not (dx * dx + dy * dy <= gap2 or (
                        phi is not None and abs(phi[pb] - phi[pa]) <= params.merge_gap_angle)):
                    return None
        g = _solve(joint[:, None], scan.origin)
        # every extent that would carry the joint fit must still be a line with it (step
        # 6: its end points on the joint line at least min_length apart, the joint RMSE
        # within the split tolerance), else the join would drop a segment
        owned = [m for m in range(n) if owner[m] == j] + [k]
        col = np.zeros(len(owned), dtype=np.intp)
        shared = _Fit(g.params.take(col, axis=1), g.rmse[col], g.count[col],
                      g.cov.take(col, axis=0))
        if len(_build(scan, params, shared, np.array([first_l[m] for m in owned]),
                      np.array([last_l[m] for m in owned]))) != len(owned):
            return None
        return joint, g

    # Consecutive lines whose facing pieces were consecutive neighbours in the merge were
    # the merge's to join (it also tests each piece against the merged line of the whole
    # chain, which a pair cannot): they are left as they are.
    ps, pe = pieces
    cluster, phis = memoryview(scan.cluster), scan.rows()[_PHI]
    ps_l, pe_l = ps.tolist(), pe.tolist()

    def merge_tested(j: int) -> bool:
        """Return whether lines j and j + 1 met as consecutive neighbouring pieces."""
        a = bisect_left(pe_l, last_l[j] + 1) - 1  # j's last piece, j + 1's first
        b = bisect_left(ps_l, first_l[j + 1])
        ok = a >= 0 and b == a + 1 and b < len(ps_l) and ps_l[a] >= first_l[j] and (
            pe_l[b] <= last_l[j + 1])
        if ok:
            p0, p1 = pe_l[a], ps_l[b]
            ok = (cluster[p0] == cluster[p1]
                  or (xs[p1] - xs[p0]) ** 2 + (ys[p1] - ys[p0]) ** 2 <= gap2
                  or abs(phis[p1] - phis[p0]) <= params.merge_gap_angle)
        return ok

    changed = False
    for j in range(n - 1):  # each line takes the later lines that join it, in order
        if owner[j] != j:
            continue
        grown = False
        for k in range(j + 1, n):
            if owner[k] != k or not (grown or (j, k) in tried) or (
                    k == j + 1 and merge_tested(j)):
                continue
            out = joinable(j, k)
            if out is None:
                continue
            joint, g = out
            line_sums[j] = joint
            fits[j] = (float(g.rho[0]), float(g.alpha[0]),
                       (g.cov[0] * _variance_factor(joint[:, None], g)[0]).reshape(4).tolist())
            ends[j] = (ends[j][0], last_l[k])
            for m in range(k, n):
                if owner[m] == k:
                    owner[m] = j
            changed = grown = True
    if not changed:
        return f
    heads = sorted(set(owner))
    g = _solve(np.stack([line_sums[j] for j in heads], axis=1), scan.origin)
    col = np.searchsorted(np.array(heads), np.array(owner))
    return _Fit(g.params.take(col, axis=1), g.rmse[col], g.count[col], g.cov.take(col, axis=0))
