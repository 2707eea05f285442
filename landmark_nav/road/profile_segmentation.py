"""Binary segmentation of a stretch of readings by its height profile (§4.2, step 5).

Each stretch (a widened roughness group) is split where the height profile bends or its
roughness changes: the split of best likelihood gain of two profile pieces over one, kept
when the gain beats the Bayesian information criterion's penalty. :func:`_segment_profile`
is the recursive reference, :func:`_segment_profiles` the same pieces of every stretch of a
scan in one pass of array operations per level. :mod:`.road_edges` then rejoins the pieces
that do not differ physically. Used by :func:`landmark_nav.road.terrain.classify_scan`.
"""

import math
from typing import Optional

from landmark_nav.road.profile_fits import _explained, _piece_nll, _poly_sse
from landmark_nav.road.terrain_params import TerrainParams
import numpy as np


def _segment_profile(first: int, last: int, table: np.ndarray, params: TerrainParams,
                     out: list) -> None:
    """Split a stretch of readings where the height profile or its roughness changes.

    Each piece is a quadratic height profile ``z = a + b s + c s^2`` (slope ``F_t``,
    curvature ``F_c``) with its own residual variance (roughness ``F_sigma``), floored by
    the sensor's height noise ``var0``. Binary segmentation: the best split point
    maximises the log-likelihood gain of two such pieces over one (computed for every
    reading from prefix sums, so the edge falls on the reading where the profile bends or
    the roughness changes, not on a window's end); it is kept when the gain exceeds the
    Bayesian information criterion's penalty for the extra piece (3 coefficients, a
    variance and the split point: ``5/2 ln n``). :func:`_merge_pieces` then rejoins the
    neighbours that do not differ physically.

    :func:`classify_scan` uses :func:`_segment_profiles`, the same pieces from fewer numpy
    calls; this one-split-at-a-time form is its reference (and the tests' oracle).
    """
    best, gain = _best_split(first, last, table, params)
    if best is None or gain <= 2.5 * math.log(last - first + 1):
        out.append((first, last))
        return
    _segment_profile(first, best - 1, table, params, out)
    _segment_profile(best, last, table, params, out)


def _best_split(first: int, last: int, table: np.ndarray,
                params: TerrainParams) -> tuple[Optional[int], float]:
    """Return the reading that starts the second of the best two pieces, and the gain.

    ``first`` and ``last`` index the stretch of :func:`_moment_table`.
    """
    n = last - first + 1
    if n < 2 * params.min_points:
        return None, -math.inf
    cum = table[:, first:last + 2] - table[:, first:first + 1]       # sums over [0, k)
    k = np.arange(n + 1)
    # Each piece is a quadratic (a crowned road) or a line (a flat shoulder, a verge: one
    # parameter fewer, 1/2 ln n less penalty), which locates a kink sharply.
    half = 0.5 * math.log(n)
    m = np.concatenate([cum, cum[:, -1:] - cum], axis=1)        # [0, k) then [k, n)
    cnt = m[0]
    with np.errstate(divide='ignore', invalid='ignore'):
        floor = m[9] / cnt
    nll = np.minimum(_piece_nll(_poly_sse(m, 2), cnt, floor) + half,
                     _piece_nll(_poly_sse(m, 1), cnt, floor))
    gain = nll[n] - nll[:n + 1] - nll[n + 1:]
    allowed = (k >= params.min_points) & (k <= n - params.min_points)
    gain[~allowed] = -np.inf
    best = int(np.argmax(gain))
    if not np.isfinite(gain[best]):
        return None, -math.inf
    return first + best, float(gain[best])


def _segment_profiles(tables: list, params: TerrainParams) -> list:
    """Return :func:`_segment_profile`'s pieces of every table, split level by level.

    The same binary segmentation, with the same fits (:func:`_explained`) and likelihoods
    as :func:`_best_split` (:func:`_poly_sse`, :func:`_piece_nll`), but every stretch still
    to split, of every table, is tried in one pass of array operations per level of the
    recursion (the numpy calls, not the readings, are the cost of a scan). Returns one
    list of ``(first, last)`` per table, in reading order. The caller silences numpy's
    floating-point warnings (empty and degenerate pieces divide by zero).
    """
    if not tables:
        return []
    mp = params.min_points
    found = [[] for _ in tables]
    # All tables side by side: a stretch is a range of columns of one of them.
    big = np.concatenate(tables, axis=1)
    offsets = np.cumsum([0] + [t.shape[1] for t in tables]).tolist()
    todo = []                                   # (table, first, last) still to split
    for i, table in enumerate(tables):
        n = table.shape[1] - 1
        if n >= 2 * mp:
            todo.append((i, 0, n - 1))
        else:
            found[i].append((0, n - 1))
    while todo:
        firsts = np.array([offsets[i] + first for i, first, _ in todo])
        lasts = np.array([offsets[i] + last for i, _, last in todo])
        sizes = lasts - firsts + 2 - 2 * mp                 # allowed splits k per stretch
        reps = np.repeat(np.arange(len(todo)), sizes)
        seg = np.cumsum(sizes) - sizes                      # each stretch's first split
        total = int(seg[-1] + sizes[-1])
        cols = np.arange(total) + (firsts + mp - seg)[reps]
        left = big[:, cols] - big[:, firsts[reps]]          # [0, k), the allowed k
        whole = big[:, lasts + 1] - big[:, firsts]
        # Columns: the left pieces, the whole stretches, the right pieces [k, n).
        m = np.concatenate([left, whole, whole[:, reps] - left], axis=1)
        s0 = m[0]
        # Each piece is a quadratic (a crowned road) or a line (a flat shoulder, a verge:
        # one parameter fewer, 1/2 ln n less penalty), which locates a kink sharply; rows
        # of ``sse``: the quadratic, the line. Every piece has >= min_points >= 3 readings:
        # the line is never degenerate, the quadratic only with 3 (its SSE is 0).
        sse = np.maximum(m[8] - np.stack(_explained(m)[::-1]), 0.0)
        if mp < 4:
            sse[0, s0 < 3.5] = 0.0
        v = np.maximum(sse / s0, m[9] / s0)
        nll = 0.5 * (s0 * np.log(v) + sse / v)
        half = np.log(lasts - firsts + 1.0) * 0.5
        nll[0] += half[np.concatenate([reps, np.arange(len(todo)), reps])]
        nll = nll.min(axis=0)
        gain = nll[total + reps] - nll[:total] - nll[total + len(todo):]
        # np.argmax per stretch: the first maximum, or the first NaN if there is one.
        ends = (seg + sizes).tolist()
        at = [int(np.argmax(gain[a:b])) for a, b in zip(seg.tolist(), ends)]
        nxt = []
        for (i, first, last), best, start in zip(todo, at, seg.tolist()):
            value = float(gain[start + best])
            if not math.isfinite(value) or value <= 2.5 * math.log(last - first + 1):
                found[i].append((first, last))
                continue
            for a, b in ((first, first + mp + best - 1), (first + mp + best, last)):
                if b - a + 1 >= 2 * mp:
                    nxt.append((i, a, b))
                else:
                    found[i].append((a, b))
        todo = nxt
    return [sorted(pieces) for pieces in found]
