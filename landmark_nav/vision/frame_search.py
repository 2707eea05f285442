"""Frame search of the landmark detector: neighbours, edge chains, frames (chapter §2.2.2).

Step 2 of :func:`~.detector.detect_landmarks`, on the corner candidates of
:mod:`.corner_candidates`:

* :func:`corner_neighbours` -- up to eight neighbours per corner within 1/5 of the image
  height;
* :func:`frame_edges` -- frame edges of six collinear corners (eq. 3); :func:`chain_edges`
  the same with missed interior corners bridged (extension, ``DetectorParams.max_gaps``);
* :func:`find_frames` -- frames of four edges sharing their end corners (eq. 4).

Conventions: pixel positions are OpenCV ``(x, y)`` = (column, row), pixel centres at integer
coordinates (the chapter writes ``(r, c)``).

Readings of the chapter that needed a decision (tested in
``test/test_landmark_detector.py``):

* The eight neighbours of a corner are the candidates for the second corner ``h_2`` of an
  edge; the following corners are the corners closest to the eq. 3 prediction among all
  corners (eq. 3 only asks ``h_i in h_n``). Under strong perspective the next corner of a
  foreshortened edge is often not among the eight closest, code-area corners being nearer;
  so by default (``neighbour_mode='sectors'``) the neighbours are the closest corner in each
  of eight 45-degree sectors, still at most eight within 1/5 of the image height
  (``'closest'`` is the chapter's rule; at 60 degrees turn and 2.2 m it finds 4 of 20
  landmarks, the sectors 20 of 20 -- the chapter's own Table 1 has 24 samples of 100 there).
  At strong tilt the two edges of a frame corner can fall into one sector; the second
  closest corner of a sector is then kept as well (``second_neighbour_angle``).
* Eq. 3 is read as a tracker whose prediction starts from the matched corner:
  ``h^_{i+1} = h_i + v_{i+1}`` with ``v_{i+1} = v_i + k_g (h_i - h^_i)``; the printed
  recursion ``h^_{i+1} = h^_i + v_i`` never uses the measured positions and loses a
  perspective-shortened edge after three steps. The test ``|h_i - h^_i| < k_lim |v_i|``
  is applied to every corner after the second, the sixth included.
* Eq. 4 lists three shared corners; the fourth (``F_{3,6} = F_{4,6}``) is required too, so
  that every frame corner is the end point of two edges, as the text says.
"""

import math
from typing import List, Optional, Tuple, TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # scipy.spatial is imported where a tree is built, not at every node start
    from scipy.spatial import cKDTree


def corner_neighbours(points: np.ndarray, max_distance: float, k: int = 8,
                      tree: Optional['cKDTree'] = None, mode: str = 'closest',
                      second_angle: float = 0.0) -> np.ndarray:
    """Return up to k neighbours of every corner within ``max_distance`` (§2.2.2).

    Args:
        points: (N, 2) corner positions [px].
        max_distance: search radius [px].
        k: neighbours per corner.
        tree: a ``cKDTree`` of ``points`` if one exists already.
        mode: ``'closest'``: the k closest corners (the chapter); ``'sectors'``: the closest
            corner in each of k equal direction sectors (k = 8: 45 degrees each), so that the
            next corner of a foreshortened edge is not crowded out by nearer corners in other
            directions.
        second_angle: ``'sectors'`` only: if > 0 [rad], the second closest corner of a
            sector is kept too when its direction differs from the closest one's by more
            than this (k more columns).

    Returns:
        (N, k) indices ((N, 2k) with ``second_angle``); missing neighbours are N (one past
        the last corner).
    """
    n = len(points)
    if n < 2:
        return np.full((n, k), n, dtype=np.int64)
    from scipy.spatial import cKDTree  # on first use: scipy.spatial costs ~0.5 CPU-s
    tree = cKDTree(points) if tree is None else tree
    kk = min((k if mode == 'closest' else 3 * k) + 1, n)
    dist, idx = tree.query(points, k=kk, distance_upper_bound=max_distance)
    idx = np.asarray(idx).reshape(n, kk)[:, 1:]  # drop the corner itself (distance 0)
    if mode == 'closest':
        if idx.shape[1] < k:
            idx = np.hstack([idx, np.full((n, k - idx.shape[1]), n)])
        return idx.astype(np.int64)
    # the tables are built transposed ((columns, n), one row per neighbour rank): the loop
    # below then writes contiguous rows
    idx_t = idx.T.copy()
    valid = idx_t < n
    dx = np.append(points[:, 0], 0.0)[idx_t] - points[:, 0]
    dy = np.append(points[:, 1], 0.0)[idx_t] - points[:, 1]
    ang_t = np.arctan2(dy, dx)
    sector = np.floor((ang_t + math.pi) / (2 * math.pi) * k)
    sector = np.where(valid, np.clip(sector.astype(np.int64), 0, k - 1), k)   # k: none
    # the columns of a row are in order of distance: writing them from the farthest to the
    # nearest leaves each sector's nearest corner in it (column k collects the missing
    # ones); the corner a write replaces is the sector's next nearest, its second. The
    # (n, k + 1) tables are written through flat indices, column by column (one write per
    # row each)
    flat = sector + (k + 1) * np.arange(n)
    out = np.full(n * (k + 1), n, dtype=np.int64)
    first_ang = np.zeros(n * (k + 1))
    extra = second_ang = None
    if second_angle > 0:
        extra = np.full(n * (k + 1), n, dtype=np.int64)
        second_ang = np.zeros(n * (k + 1))
    for c in range(idx.shape[1] - 1, -1, -1):
        f = flat[c]
        if extra is not None:
            extra[f] = out[f]
            second_ang[f] = first_ang[f]
        out[f] = idx_t[c]
        first_ang[f] = ang_t[c]
    out = out.reshape(n, k + 1)[:, :k]
    if extra is not None:
        # extension: also the second nearest corner of a sector when its direction differs
        # from the nearest one's by more than second_angle (two frame edges seen at an
        # acute angle share a sector)
        da = np.abs((second_ang - first_ang + math.pi) % (2 * math.pi) - math.pi)
        da = da.reshape(n, k + 1)[:, :k]
        extra = extra.reshape(n, k + 1)[:, :k]
        extra = np.where((extra < n) & (da > second_angle), extra, n)
        out = np.hstack([out, extra])
    return out.astype(np.int64)


def _first_rows(a: np.ndarray) -> np.ndarray:
    """Return the indices of the first occurrence of each distinct row of ``a``, ascending.

    The same as ``np.sort(np.unique(a, axis=0, return_index=True)[1])`` (a stable
    lexicographic sort puts the first of equal rows first), several times faster.
    """
    if not len(a):
        return np.zeros(0, dtype=np.int64)
    order = np.lexsort(a.T[::-1])
    srt = a[order]
    new = np.ones(len(a), dtype=bool)
    new[1:] = np.any(srt[1:] != srt[:-1], axis=1)
    return np.sort(order[new])


def frame_edges(points: np.ndarray, neighbours: np.ndarray, n_corners: int = 6,
                k_lim: float = 0.37, k_g: float = 0.5, tree: Optional['cKDTree'] = None,
                filters: Optional[np.ndarray] = None) -> np.ndarray:
    """Return every chain of ``n_corners`` corners along a straight edge (eq. 3).

    Each corner ``h_1`` and each of its neighbours ``h_2`` start a chain (``v_2 = h_2 -
    h_1``); the next corner is the corner closest to the prediction ``h^_{i+1} = h_i +
    v_{i+1}`` (any corner, ``h_i in h_n``); it must lie within ``k_lim |v|`` of it, and the
    spacing is updated ``v <- v + k_g (h_{i+1} - h^_{i+1})`` (see the module docstring for
    this reading of eq. 3). An edge found from either end is returned once in each
    direction. :func:`chain_edges` is the same with missed interior corners bridged.

    Args:
        points: (N, 2) corner positions [px].
        neighbours: (N, K) from :func:`corner_neighbours`.
        n_corners: corners per edge (6, or 5 for the 2x2 landmark).
        k_lim: prediction tolerance (eq. 3).
        k_g: spacing gain (eq. 3).
        tree: a ``cKDTree`` of ``points`` if one exists already.
        filters: (N,) filter (0..3 for C1..C4) of each corner; if given, two corners of the
            same filter do not start an edge, nor follow each other in it: neighbouring
            X-corners of a frame edge have opposite polarity (C1 next to C2, C3 next to
            C4, or one of each pair at in-between rotations).

    Returns:
        (E, n_corners) int64 corner indices, ordered along each edge.
    """
    return chain_edges(points, neighbours, n_corners, k_lim, k_g, tree, filters, 0)[0]


def chain_edges(points: np.ndarray, neighbours: np.ndarray, n_corners: int = 6,
                k_lim: float = 0.37, k_g: float = 0.5, tree: Optional['cKDTree'] = None,
                filters: Optional[np.ndarray] = None, max_gaps: int = 0
                ) -> Tuple[np.ndarray, np.ndarray]:
    """Chain corners into frame edges (eq. 3), bridging up to ``max_gaps`` missed corners.

    As :func:`frame_edges`; in addition (extension), when no corner lies within ``k_lim
    |v|`` of a prediction ``h^_{i+1}`` of an interior corner, the chain may go on from the
    prediction itself (a *virtual* corner, the spacing not updated), at most ``max_gaps``
    times per chain and never twice in a row; the first three and the last corner are
    always detected corners, so that frames are still joined at shared corners (eq. 4)
    and clutter does not start bridged chains (a missed interior corner is the fourth or
    fifth corner of the edge followed from one of its two ends).
    Seen at 40-60 degrees tilt with 4-5 px per block, the corner filters (eq. 1) miss one
    or two of the 20 frame X-corners in a third of the lost landmarks; the virtual corner
    is refined like every frame corner once the frame reads as a valid code.

    Args:
        points, neighbours, n_corners, k_lim, k_g, tree, filters: see :func:`frame_edges`.
        max_gaps: virtual corners allowed per chain (0: the chapter's eq. 3).

    Returns:
        ``(edges, virtual)``: (E, n_corners) int64 indices into ``points`` stacked on
        ``virtual``, the (V, 2) positions of the virtual corners (index ``N + k``). An
        edge with virtual corners is kept only if no edge without one joins the same two
        end corners, and once per end-corner pair.
    """
    n = len(points)
    none = (np.zeros((0, n_corners), np.int64), np.zeros((0, 2)))
    if n < n_corners or neighbours.size == 0:
        return none
    from scipy.spatial import cKDTree  # on first use: scipy.spatial costs ~0.5 CPU-s
    tree = cKDTree(points) if tree is None else tree
    h2 = neighbours.ravel()
    h1 = np.repeat(np.arange(n), neighbours.shape[1])
    ok = h2 < n
    if filters is not None:
        f = np.append(np.asarray(filters), -1)
        ok &= f[h1] != f[np.minimum(h2, n)]
    h1, h2 = h1[ok], h2[ok]
    # the chains' corners are written into one table; each step works on the rows of the
    # chains still alive (``rows``) and their current position, spacing and gap count
    ids = np.empty((len(h1), n_corners), np.int64)
    ids[:, 0], ids[:, 1] = h1, h2
    vtab = np.full((len(h1), n_corners - 2, 2), np.nan)           # virtual corner positions
    rows = np.arange(len(h1))
    last = h2
    pos = points[h2]
    v = pos - points[h1]                                          # v_2 = h_2 - h_1
    gaps = np.zeros(len(v), np.int64)
    was_virtual = np.zeros(len(v), bool)
    for step in range(n_corners - 2):
        if not len(rows):
            return none
        pred = pos + v                                            # eq. 3 prediction
        dist, best = tree.query(pred, k=1)
        good = dist < k_lim * np.linalg.norm(v, axis=1)           # |h_i - h^_i| < k_lim |v_i|
        if filters is not None:
            # neighbouring corners of an edge alternate in polarity, as h_1 and h_2 (a
            # bridged corner, index -1, has no filter: f[-1] = -1)
            good &= f[np.minimum(best, n)] != f[last]
        if max_gaps > 0 and 1 <= step < n_corners - 3:
            virt = ~good & (gaps < max_gaps) & ~was_virtual
            alive = np.flatnonzero(good | virt)
            virt, good = virt[alive], good[alive]
        else:
            virt = None
            alive = np.flatnonzero(good)
        rows, best, pred, v = rows[alive], best[alive], pred[alive], v[alive]
        hit = points[np.minimum(best, n - 1)]     # (n: no corner, for a non-finite pred)
        if virt is None:
            gaps = gaps[alive]
            was_virtual = np.zeros(len(rows), bool)
            last = best
            v = v + k_g * (hit - pred)                            # v_{i+1} = v_i + k_g (...)
            pos = hit
        else:
            gaps = gaps[alive] + virt
            was_virtual = virt
            last = np.where(good, best, -1)
            v = v + k_g * np.where(good[:, None], hit - pred, 0.0)
            pos = np.where(good[:, None], hit, pred)
            vtab[rows[virt], step] = pred[virt]
        ids[rows, step + 2] = last
    if not len(rows):
        return none
    edges, vpos = ids[rows], vtab[rows]
    real = edges >= 0
    srt = np.sort(np.where(real, edges, -1 - np.arange(n_corners)), axis=1)
    distinct = np.all(srt[:, 1:] != srt[:, :-1], axis=1)
    edges, vpos, real = edges[distinct], vpos[distinct], real[distinct]
    full = real.all(axis=1)
    complete = edges[full]
    # every edge in both directions, once each (a chain may be found from one end only)
    both = np.vstack([complete, complete[:, ::-1]])
    out = both[_first_rows(both)]
    if full.all():
        return out, np.zeros((0, 2))
    # bridged edges: one per unordered end-corner pair, none where a complete edge exists
    part, ppos = edges[~full], vpos[~full]
    lo = np.minimum(part[:, 0], part[:, -1])
    hi = np.maximum(part[:, 0], part[:, -1])
    pair = lo * n + hi
    done = np.minimum(complete[:, 0], complete[:, -1]) * n + \
        np.maximum(complete[:, 0], complete[:, -1])
    _, first = np.unique(pair, return_index=True)
    first = first[~np.isin(pair[first], done)]
    part, ppos = part[first], ppos[first]
    holes = part < 0
    part = part.copy()
    part[holes] = n + np.arange(int(holes.sum()))
    virtual = ppos[holes[:, 2:]]
    return np.vstack([out, part, part[:, ::-1]]), virtual


def find_frames(points: np.ndarray, edges: np.ndarray, k_p: float = 0.5) -> List[np.ndarray]:
    """Return the frames: four edges sharing their end corners, opposite edges alike (eq. 4).

    A frame is ``(f_1, f_2, f_3, f_4)`` with ``f_1`` from corner A to B, ``f_2`` from A to D,
    ``f_3`` from D to C and ``f_4`` from B to C (eq. 4's ``F_{1,1} = F_{2,1}``,
    ``F_{2,6} = F_{3,1}``, ``F_{1,6} = F_{4,1}``, and ``F_{3,6} = F_{4,6}``), with
    ``|v_1 - v_3| <= k_p |v_1|`` and ``|v_2 - v_4| <= k_p |v_2|`` where ``v_n = F_{n,6} -
    F_{n,1}``. ``f_2`` is clockwise of ``f_1`` in the image (y down) so mirror images are
    not frames. Each frame is returned once.

    Args:
        points: (N, 2) corner positions [px].
        edges: (E, n) from :func:`frame_edges`.
        k_p: parallel/equal tolerance.

    Returns:
        List of (4, n) index arrays ``[f_1, f_2, f_3, f_4]``.
    """
    if len(edges) < 4:
        return []
    first, last = edges[:, 0], edges[:, -1]
    vec = (points[last] - points[first]).astype(float)
    norm = np.hypot(vec[:, 0], vec[:, 1])
    # every (e1, e2, e3, e4) in lexicographic order, as nested loops over the edges would
    # give them (the first of equal frames is kept); ranges of edges by start corner and
    # by (start, end) corner pair come from stable sorts
    by_first = np.argsort(first, kind='stable')
    sorted_first = first[by_first]
    n_pts = int(max(first.max(), last.max())) + 1
    pair_key = first.astype(np.int64) * n_pts + last
    by_pair = np.argsort(pair_key, kind='stable')
    sorted_pair = pair_key[by_pair]

    def expand(keys: np.ndarray, sorted_keys: np.ndarray, order: np.ndarray
               ) -> Tuple[np.ndarray, np.ndarray]:
        """Return (row, edge): every edge whose key equals ``keys[row]``, rows in order."""
        lo = np.searchsorted(sorted_keys, keys, 'left')
        hi = np.searchsorted(sorted_keys, keys, 'right')
        cnt = hi - lo
        row = np.repeat(np.arange(len(keys)), cnt)
        start = np.repeat(lo - np.concatenate([[0], np.cumsum(cnt)[:-1]]), cnt)
        return row, order[start + np.arange(len(row))]

    r, e2 = expand(first, sorted_first, by_first)
    e1 = r
    v1, v2 = vec[e1], vec[e2]
    keep = v1[:, 0] * v2[:, 1] - v1[:, 1] * v2[:, 0] > 0.0     # f_2 clockwise of f_1 (y down)
    e1, e2 = e1[keep], e2[keep]
    r, e3 = expand(last[e2], sorted_first, by_first)
    e1, e2 = e1[r], e2[r]
    c = last[e3]
    keep = (c != first[e1]) & (c != last[e1]) & \
        (np.hypot(*(vec[e1] - vec[e3]).T) <= k_p * norm[e1])             # eq. 4
    e1, e2, e3 = e1[keep], e2[keep], e3[keep]
    r, e4 = expand(last[e1].astype(np.int64) * n_pts + last[e3], sorted_pair, by_pair)
    e1, e2, e3 = e1[r], e2[r], e3[r]
    keep = np.hypot(*(vec[e2] - vec[e4]).T) <= k_p * norm[e2]             # eq. 4
    e1, e2, e3, e4 = e1[keep], e2[keep], e3[keep], e4[keep]
    if not len(e1):
        return []
    ids = np.stack([edges[e1], edges[e2], edges[e3], edges[e4]], axis=1)   # (F, 4, n)
    flat = np.sort(ids.reshape(len(ids), -1), axis=1)
    distinct = 1 + np.count_nonzero(np.diff(flat, axis=1), axis=1)
    good = np.flatnonzero(distinct == 4 * (edges.shape[1] - 1))
    if not len(good):
        return []
    # frames with the same corner set are one frame: keep the first (the shared corners
    # appear twice in every frame, so equal sets have equal sorted id lists)
    return [ids[i] for i in good[_first_rows(flat[good])]]


__all__ = ['chain_edges', 'corner_neighbours', 'find_frames', 'frame_edges']
