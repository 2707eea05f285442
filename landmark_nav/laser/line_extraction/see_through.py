"""Step 5 of the line extractors: no line covers a beam the laser saw through it.

:func:`_seen_through` finds the beams beyond a line (openings: beyond by more than the
tolerance plus 3 standard deviations of the distance along the ray, eq. 7);
:func:`_cut_seen_through` cuts the lines there and refits the sides.
"""

from bisect import bisect_left
import math
from operator import lt
from typing import List, Optional, Tuple

from landmark_nav.laser.line_extraction.params import LineParams
from landmark_nav.laser.line_extraction.scan_batch import _gather, _Scan, _X, _Y
from landmark_nav.laser.line_extraction.tls_fit import _Fit, _solve
import numpy as np


def _extent_beams(scan: _Scan, f: _Fit, first: np.ndarray, last: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return (beam, line, rho, range, cos incidence) of the valid beams in the lines' extents.

    The extent of a line runs from its first to its last supporting beam in beam order;
    ``cos incidence`` is the ray direction dotted with the line's normal. The result is
    kept on ``f`` for the same ``first`` and ``last`` arrays (the see-through and occluder
    steps look at the same extents when no line was cut).
    """
    if f.extent is not None and f.extent[0] is first and f.extent[1] is last:
        return f.extent[2]
    wr, wc, ws, wv = scan.beams()
    # the beams lo..hi of every line, back to back (as _gather), laid out on lists
    beam = memoryview(scan.beam)
    cnt, shift = [], []
    total = 0
    for a, b in zip(first.tolist(), last.tolist()):
        lo, hi = beam[a], beam[b]
        if hi < lo:
            lo, hi = hi, lo
        cnt.append(hi - lo + 1)
        shift.append(total - lo)
        total += hi - lo + 1
    idx = np.arange(total, dtype=np.int64)
    idx -= np.array(shift, dtype=np.int64).repeat(cnt)
    line = np.arange(len(cnt)).repeat(cnt)
    ok = wv[idx]
    idx, line = idx[ok], line[ok]
    rho, _, nx, ny = f.params.take(line, axis=1)
    out = idx, line, rho, wr[idx], wc[idx] * nx + ws[idx] * ny
    f.extent = (first, last, out)
    return out


def _seen_through(scan: _Scan, f: _Fit, first: np.ndarray, last: np.ndarray,
                  params: LineParams) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (line, beam, opening) of the valid beams the lines hide (step 5).

    A beam between the first and the last supporting beam of a line (in beam order) is
    hidden when its return lies more than ``see_through_tolerance`` beyond the line along
    its ray: the laser saw through where the line claims a surface. ``opening`` marks the
    hidden beams beyond the line by more than that tolerance plus 3 standard deviations of
    their distance along the ray (eq. 7 on the ray: ``sigma_r^2 + (r sigma_phi
    tan(incidence))^2``); the others are the wall's own noise (at grazing incidence, or a
    rare large error). Beams in front of the line (occluders) and missing beams are
    allowed here (occluders are left out of the extents by :func:`_occluded_extents`).
    """
    idx, line, rho, r, cos_in = _extent_beams(scan, f, first, last)
    beyond = r - rho / cos_in
    tol = params.see_through_tolerance
    bad = ((cos_in > 1e-9) & (beyond > tol)).nonzero()[0]
    if not bad.size:
        return line[:0], idx[:0], np.zeros(0, dtype=bool)
    line, idx = line[bad], idx[bad]
    if bad.size <= _SEEN_PY:  # the opening test on Python floats (the same operations)
        sr2, sp = params.gate_sigma_r ** 2, params.sigma_phi
        opening = []
        for b, rr, c in zip(*np.array((beyond, r, cos_in)).take(bad, axis=1).tolist()):
            t, c2 = rr * sp, c * c
            opening.append(b > tol + 3.0 * math.sqrt(sr2 + t * t * (1.0 - c2) / c2))
        return line, idx, np.array(opening, dtype=bool)
    beyond, r, cos_in = beyond[bad], r[bad], cos_in[bad]
    c2 = cos_in * cos_in
    var = params.gate_sigma_r ** 2 + (r * params.sigma_phi) ** 2 * (1.0 - c2) / c2
    return line, idx, beyond > tol + 3.0 * np.sqrt(var)


# Hidden beams up to which _seen_through tests them on Python floats (measured).
_SEEN_PY = 16


def _cut_seen_through(scan: _Scan, feats: np.ndarray, sums: np.ndarray, first: np.ndarray,
                      last: np.ndarray, f: _Fit, pieces: Tuple[np.ndarray, ...],
                      params: LineParams) -> Tuple[np.ndarray, np.ndarray, np.ndarray, _Fit]:
    """Keep the lines off the beams they hide (step 5).

    ``pieces`` = (s, e, label, first0, last0): the merged pieces, their lines and the
    lines' first / last points before growing (the support of line j is its pieces and
    the grown runs ``[first[j], first0[j])`` and ``(last0[j], last[j]]``).

    1. A line that hides an opening (see :func:`_seen_through`) is cut there: the support
       on either side becomes a line of its own and is refitted, a supporting point at the
       opening leaves. Repeated on the new fits; support runs shorter than ``min_points``
       are dropped, and so is a line still hiding an opening after ``_MAX_CUTS`` rounds.
    2. A line that hides only beams within their noise (its own points at grazing
       incidence) is cut there too when at least two of the pieces are lines of their own
       (``min_points``, ``min_length``); otherwise it keeps its fit, all points included,
       and its extent shrinks to the run of its support between those beams with the
       most points.
    """
    line, beam, opening = _seen_through(scan, f, first, last, params)
    if not line.size:
        return sums, first, last, f
    s, e, label, first0, last0 = pieces
    if line.size <= _NOISE_PY and not np.count_nonzero(opening):
        ends = _noise_only_py(scan, pieces, first, last, line, beam, params)
        if ends is not None:
            return sums, ends[0], ends[1], f
    if first.size <= _CUT_PY:
        out = _cut_py(scan, feats, sums, first, last, f, pieces, line, beam, opening, params)
        if out is not None:
            return out
    owner = np.full(scan.x.size, -1, dtype=np.int64)
    # a line's support: its pieces and the runs grown before and after (disjoint, so one
    # gather of all of them)
    lines = np.arange(first.size)
    idx, offs = _gather(np.concatenate((s, first, last0 + 1)),
                        np.concatenate((e, first0 - 1, last)))
    owner[idx] = np.concatenate((label, lines, lines)).repeat(offs[1:] - offs[:-1])
    rounds = 0
    two, runs = _splits_in_two(scan, owner, line, beam, first, params)
    opening |= two
    while np.count_nonzero(opening):
        if rounds == _MAX_CUTS:  # give up on the lines that still hide an opening
            ok = np.ones(first.size, dtype=bool)
            ok[line[opening]] = False
            relabel = ok.cumsum() - 1
            owner = np.where((owner >= 0) & ok[np.maximum(owner, 0)],
                             relabel[np.maximum(owner, 0)], -1)
            sums, first, last = sums[:, ok], first[ok], last[ok]
            if not first.size:
                return sums, first, last, f
            f = _solve(sums, scan.origin)
            sel = ok[line]
            line, beam, opening = relabel[line[sel]], beam[sel], opening[sel]
            runs = None
            break
        rounds += 1
        pos, run, starts, size = _support_runs(scan, owner, beam[opening])
        big = size >= params.min_points
        owner[:] = -1
        kept = big[run]
        owner[pos[kept]] = (big.cumsum() - 1)[run[kept]]
        starts, size = starts[big], size[big]
        if not starts.size:
            return sums[:, :0], first[:0], last[:0], f
        first, last = pos[starts], pos[starts + size - 1]
        sums = np.add.reduceat(feats.take(pos[kept], axis=1), size.cumsum() - size, axis=1)
        f = _solve(sums, scan.origin)
        line, beam, opening = _seen_through(scan, f, first, last, params)
        two, runs = _splits_in_two(scan, owner, line, beam, first, params)
        opening |= two
    if line.size:  # only noise: each line's extent becomes its largest run between them
        pos, run, starts, size = (runs if runs is not None
                                  else _support_runs(scan, owner, beam))
        own = owner[pos[starts]]
        best = np.lexsort((-size, own))  # per line, the run of most points first
        head = np.ones(best.size, dtype=bool)
        head[1:] = own[best[1:]] != own[best[:-1]]
        best = best[head]
        first, last = first.copy(), last.copy()
        first[own[best]] = pos[starts[best]]
        last[own[best]] = pos[starts[best] + size[best] - 1]
    return sums, first, last, f


# Hidden beams up to which _noise_only_py is tried first (a few per scan are typical).
_NOISE_PY = 24


def _noise_only_py(scan: _Scan, pieces: Tuple[np.ndarray, ...], first: np.ndarray,
                   last: np.ndarray, line: np.ndarray, beam: np.ndarray, params: LineParams
                   ) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """Return the lines' first and last points when they hide only their noise, else None.

    Step 2 of :func:`_cut_seen_through` for hidden beams that are no opening, on Python
    objects and looking only at the lines that hide beams: a line's support (its pieces
    and grown runs) is cut into runs at its hidden beams (which leave), as by
    :func:`_support_runs`. Returns None when a line has two runs of ``min_points`` points
    and ``min_length`` (:func:`_splits_in_two`: the line is cut, in the array version);
    otherwise each hiding line's extent becomes its run of most points (the first of
    equal ones).
    """
    s, e, label, first0, last0 = pieces
    hidden: dict = {}
    for j, b in zip(line.tolist(), beam.tolist()):  # beams increasing per line
        hidden.setdefault(j, []).append(b)
    s_l, e_l, lab = s.tolist(), e.tolist(), label.tolist()
    f_l, l_l, f0, l0 = first.tolist(), last.tolist(), first0.tolist(), last0.tolist()
    xs, ys = scan.rows()[_X], scan.rows()[_Y]
    new_first, new_last = f_l[:], l_l[:]
    for j, hb in hidden.items():
        ranges = [(f_l[j], f0[j] - 1)]
        ranges += [(a, b) for a, b, k in zip(s_l, e_l, lab) if k == j]
        ranges.append((l0[j] + 1, l_l[j]))
        pts: List[int] = []
        for a, b in ranges:
            pts.extend(range(a, b + 1))
        bps = scan.beam.take(pts).tolist()  # increasing
        runs: List[Tuple[int, int, int]] = []  # (points, first point, last point)
        start = 0
        for h in hb:  # the support between hidden beams; a hidden supporting point leaves
            pos = bisect_left(bps, h, start)
            if pos > start:
                runs.append((pos - start, pts[start], pts[pos - 1]))
            start = pos + 1 if pos < len(bps) and bps[pos] == h else pos
        if start < len(bps):
            runs.append((len(bps) - start, pts[start], pts[-1]))
        good = 0
        for n, a, b in runs:
            if n >= params.min_points and abs(
                    complex(xs[b] - xs[a], ys[b] - ys[a])) >= params.min_length:
                good += 1
        if good >= 2:
            return None
        if runs:
            best = max(runs, key=lambda r: r[0])  # the first run of most points
            new_first[j], new_last[j] = best[1], best[2]
    if new_first == f_l and new_last == l_l:  # the same extents (their beams are cached)
        return first, last
    return np.array(new_first, dtype=np.int64), np.array(new_last, dtype=np.int64)


# Lines up to which _cut_seen_through cuts on Python lists (:func:`_cut_py`).
_CUT_PY = 40


def _runs_at(bps: List[int], hidden: List[int]) -> List[Tuple[int, int]]:
    """Return the runs ``[a, b)`` of a line's support between its hidden beams.

    ``bps`` are the beams of the line's supporting points (increasing), ``hidden`` the
    hidden beams inside its extent (increasing); a supporting point at a hidden beam
    leaves (as in :func:`_support_runs`).
    """
    runs = []
    start = 0
    size = len(bps)
    for h in hidden:
        pos = bisect_left(bps, h, start)
        if pos > start:
            runs.append((start, pos))
        start = pos + 1 if pos < size and bps[pos] == h else pos
    if start < size:
        runs.append((start, size))
    return runs


def _cut_py(scan: _Scan, feats: np.ndarray, sums: np.ndarray, first: np.ndarray,
            last: np.ndarray, f: _Fit, pieces: Tuple[np.ndarray, ...], line: np.ndarray,
            beam: np.ndarray, opening: np.ndarray, params: LineParams
            ) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray, _Fit]]:
    """Return :func:`_cut_seen_through` for the hidden beams of :func:`_seen_through`.

    The same cuts, the same runs and the same fits as its array steps
    (:func:`_support_runs`, :func:`_splits_in_two`): each line's support is a list of its
    points, and only the lines that hide beams are cut into runs (at their hidden beams,
    found by bisection), not the whole scan; the fits of every round are the same
    ``reduceat`` sums and :func:`_solve` of all lines, tested by :func:`_seen_through`.
    This needs the lines' supports in point order, one after the other, with beam indices
    increasing along them (clusters of one ``segment_scan`` call, in beam order): then a
    line's extent holds no other line's point and its hidden beams cut no other line.
    Returns None otherwise (the array steps then run).
    """
    s, e, label, first0, last0 = pieces
    n = first.size
    f_l, l_l = first.tolist(), last.tolist()
    sup: List[List[int]] = [list(range(a, b)) for a, b in zip(f_l, first0.tolist())]
    for a, b, k in zip(s.tolist(), e.tolist(), label.tolist()):
        sup[k].extend(range(a, b + 1))
    for j, (a, b) in enumerate(zip(last0.tolist(), l_l)):
        sup[j].extend(range(a + 1, b + 1))
    pts = [p for ps in sup for p in ps]
    bps = scan.beam.take(pts).tolist()
    if not (all(map(lt, pts, pts[1:])) and all(map(lt, bps, bps[1:]))):
        return None
    bsup = []
    k = 0
    for ps in sup:
        bsup.append(bps[k:k + len(ps)])
        k += len(ps)
    xs, ys = scan.rows()[_X], scan.rows()[_Y]
    least, min_length = params.min_points, params.min_length

    def hidden_by_line(line_l: List[int], beam_l: List[int], sel: Optional[List[bool]]
                       ) -> dict:
        """Return {line: its hidden beams (increasing)}, of the entries ``sel`` (all: None)."""
        out: dict = {}
        for i, (j, b) in enumerate(zip(line_l, beam_l)):
            if sel is None or sel[i]:
                out.setdefault(j, []).append(b)
        return out

    def splits_in_two(hidden: dict) -> Tuple[set, dict]:
        """Return the lines cut into two or more lines at their hidden beams, and the runs."""
        runs, two = {}, set()
        for j, hb in hidden.items():
            ps = sup[j]
            runs[j] = rj = _runs_at(bsup[j], hb)
            good = 0
            for a, b in rj:
                pa, pb = ps[a], ps[b - 1]
                if b - a >= least and abs(
                        complex(xs[pb] - xs[pa], ys[pb] - ys[pa])) >= min_length:
                    good += 1  # C hypot, as np.hypot
            if good >= 2:
                two.add(j)
        return two, runs

    line_l, beam_l, open_l = line.tolist(), beam.tolist(), opening.tolist()
    hidden = hidden_by_line(line_l, beam_l, None)
    two, runs = splits_in_two(hidden)
    open_l = [o or j in two for o, j in zip(open_l, line_l)]
    rounds = 0
    changed = False
    while any(open_l):
        if rounds == _MAX_CUTS:  # give up on the lines that still hide an opening
            drop = {j for j, o in zip(line_l, open_l) if o}
            keep = [j for j in range(n) if j not in drop]
            relabel = {j: i for i, j in enumerate(keep)}
            sums, first, last = sums[:, keep], first[keep], last[keep]
            if not keep:
                return sums, first, last, f
            f = _solve(sums, scan.origin)
            sup, bsup = [sup[j] for j in keep], [bsup[j] for j in keep]
            sel = [j in relabel for j in line_l]
            line_l = [relabel[j] for j, ok in zip(line_l, sel) if ok]
            beam_l = [b for b, ok in zip(beam_l, sel) if ok]
            hidden = hidden_by_line(line_l, beam_l, None)
            runs = splits_in_two(hidden)[1]
            changed = True
            break
        rounds += 1
        cuts = hidden_by_line(line_l, beam_l, open_l)
        new_sup, new_bsup = [], []
        for j, (ps, bs) in enumerate(zip(sup, bsup)):
            for a, b in (_runs_at(bs, cuts[j]) if j in cuts else ((0, len(ps)),)):
                if b - a >= least:
                    new_sup.append(ps[a:b])
                    new_bsup.append(bs[a:b])
        sup, bsup = new_sup, new_bsup
        if not sup:
            return sums[:, :0], first[:0], last[:0], f
        first = np.array([ps[0] for ps in sup], dtype=np.int64)
        last = np.array([ps[-1] for ps in sup], dtype=np.int64)
        n = len(sup)
        starts = [0]
        for ps in sup[:-1]:
            starts.append(starts[-1] + len(ps))
        sums = np.add.reduceat(feats.take([p for ps in sup for p in ps], axis=1), starts,
                               axis=1)
        f = _solve(sums, scan.origin)
        line, beam, opening = _seen_through(scan, f, first, last, params)
        line_l, beam_l, open_l = line.tolist(), beam.tolist(), opening.tolist()
        hidden = hidden_by_line(line_l, beam_l, None)
        two, runs = splits_in_two(hidden)
        open_l = [o or j in two for o, j in zip(open_l, line_l)]
        changed = True
    if line_l:  # only noise: each line's extent becomes its largest run between them
        new_first, new_last = first.tolist(), last.tolist()
        for j, rj in runs.items():
            if rj:
                a, b = max(rj, key=lambda r: r[1] - r[0])  # the first run of most points
                new_first[j], new_last[j] = sup[j][a], sup[j][b - 1]
        if changed or new_first != first.tolist() or new_last != last.tolist():
            first = np.array(new_first, dtype=np.int64)
            last = np.array(new_last, dtype=np.int64)
    return sums, first, last, f


def _splits_in_two(scan: _Scan, owner: np.ndarray, line: np.ndarray, beam: np.ndarray,
                   first: np.ndarray, params: LineParams) -> Tuple[np.ndarray, Optional[tuple]]:
    """Mark the hidden beams (all of a line's) that cut it into two or more lines.

    ``owner`` gives the line of each point (-1: none), ``first`` the lines' first points.

    A piece between hidden beams counts as a line when it has ``min_points`` supporting
    points and spans ``min_length``. Also returns the :func:`_support_runs` at all the
    hidden beams (None without hidden beams), which the noise-only case reuses.
    """
    if not line.size:
        return np.zeros(0, dtype=bool), None
    runs = _support_runs(scan, owner, beam)
    pos, _, starts, size = runs
    a, b = pos[starts], pos[starts + size - 1]
    span = np.hypot(scan.x[b] - scan.x[a], scan.y[b] - scan.y[a])
    good = (size >= params.min_points) & (span >= params.min_length)
    n_good = np.bincount(owner[a][good], minlength=first.size)
    return n_good[line] >= 2, runs


def _support_runs(scan: _Scan, owner: np.ndarray, hidden: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Split the lines' support at the hidden beams (beam indices, repeats allowed).

    Returns the supporting points left (the hidden ones leave), the run of each, and the
    runs' starts (into the points) and sizes. Runs are consecutive support of one line
    with no hidden beam between; a hidden beam lies inside the extent of one line only.
    """
    pos = (owner >= 0).nonzero()[0]
    bpos = scan.beam[pos]
    mark = np.zeros(scan.nbeam, dtype=np.int8)  # hidden beams lie within the lines' extents
    mark[hidden] = 1
    keep = mark[bpos] == 0
    pos, bpos = pos[keep], bpos[keep]
    cut = mark.cumsum()[bpos]  # hidden beams before each point
    own = owner[pos]
    new = np.empty(pos.size, dtype=bool)
    new[:1] = True
    np.not_equal(own[1:], own[:-1], out=new[1:])
    new[1:] |= cut[1:] != cut[:-1]
    starts = new.nonzero()[0]
    bounds = np.empty(starts.size + 1, dtype=np.int64)
    bounds[:-1] = starts
    bounds[-1] = pos.size
    return pos, new.cumsum() - 1, starts, bounds[1:] - bounds[:-1]


_MAX_CUTS = 8
