"""Split of split-and-merge: recursive split at the point farthest from the chord (eq. 4).

Corner chapter section 2.1.2; :func:`split_pieces` is public, :func:`_split` is the batch
version the extractor runs (all pieces of one recursion level at once).
"""

from typing import List, Tuple

from landmark_nav.laser.line_extraction.scan_batch import _gather
import numpy as np


def split_pieces(xy: np.ndarray, offsets: np.ndarray, tolerance) -> np.ndarray:
    """Split point runs recursively at the point farthest from the chord (eq. 4).

    All runs and all pieces of one recursion level are processed together.

    Args:
        xy: (N, 2) points, runs back to back.
        offsets: (C + 1,) run boundaries: run c is ``xy[offsets[c]:offsets[c + 1]]``.
        tolerance: split while the farthest point is farther than this from the chord
            [m]: a number, or (N,) one tolerance per point.

    Returns:
        (P, 2) int array of inclusive ``[first, last]`` indices of the final pieces, in
        order; neighbouring pieces of a run share the split point.

    """
    xy = np.asarray(xy, dtype=float)
    offsets = np.asarray(offsets, dtype=np.int64)
    keep = offsets[1:] > offsets[:-1]
    return _split(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                  offsets[:-1][keep], offsets[1:][keep] - 1,
                  np.broadcast_to(np.asarray(tolerance, dtype=float), xy.shape[:1])).T


def _split(px: np.ndarray, py: np.ndarray, s: np.ndarray, e: np.ndarray,
           tol: np.ndarray, min_span: int = 0) -> np.ndarray:
    """Split the runs ``s[i]..e[i]`` (inclusive); return the (2, P) first and last points.

    Pieces with ``last - first < min_span`` are left out of the result.

    All pieces of one recursion level in one batch. The farthest point from a chord is
    found on the unnormalised cross product ``|(q - p0) x (p1 - p0)|`` (the distance of
    eq. 4 times the chord length, constant within a piece), compared with the tolerance
    times the chord length: no chord equation is formed. A level's interior points are
    laid out as a (pieces, longest interior) array whose rows are padded with copies of
    their last interior point, so that a row's first maximum is its first farthest point
    (padding repeats a value, never precedes it); when the padding would outweigh the
    points (one long piece among many short ones) the rows are concatenated instead. A
    piece without interior points is padded with its first point, whose cross product is
    0: it is not split. The small per-level reductions run on Python lists (a numpy
    reduction costs more than the list on a few pieces).
    """
    done_s: List[np.ndarray] = []  # final pieces
    done_e: List[np.ndarray] = []
    mixed = False  # pieces out of order
    short = False  # pieces of less than min_span may be among them
    lone = e <= s  # runs of one point: no chord
    if np.count_nonzero(lone):
        short = True
        done_s.append(s[lone])
        done_e.append(e[lone])
        s, e = s[~lone], e[~lone]
    steps = None  # 1, 2, ... (made at the first array level, for the pieces' layout)
    while s.size:
        s_l, e_l = s.tolist(), e.tolist()
        cl = [b - a - 1 for a, b in zip(s_l, e_l)]  # interior points of every piece, >= 0
        width = max(cl)
        if width == 0:
            done_s.append(s)
            done_e.append(e)
            short = True
            break
        if sum(cl) <= _SPLIT_PY:  # few points left: finish piece by piece
            if not mixed:  # the runs themselves: index the points in place
                ps, pe = _split_py(px, py, tol, s_l, e_l, min_span)
                done_s.append(np.array(ps, dtype=np.int64))
                done_e.append(np.array(pe, dtype=np.int64))
                break
            idx, offs = _gather(s, e)  # the pieces' points (a shared split point twice)
            ps, pe = _split_py(px[idx], py[idx], tol[idx], offs[:-1].tolist(),
                               (offs[1:] - 1).tolist(), min_span)
            done_s.append(idx[ps])
            done_e.append(idx[pe])
            break
        if steps is None:  # the later pieces lie within these
            steps = np.arange(1, max(e_l) - min(s_l) + 1)
        x0, y0 = px[s], py[s]
        cx = px[e] - x0
        cy = py[e] - y0
        if s.size * width <= 2 * sum(cl) + 64:
            idx = s[:, None] + steps[:width]
            np.minimum(idx, (e - 1)[:, None], out=idx)  # pad with the last interior point
            cross = (px[idx] - x0[:, None]) * cy[:, None]
            cross -= (py[idx] - y0[:, None]) * cx[:, None]
            np.abs(cross, out=cross)  # eq. 4 distance times the chord length
            at = cross.argmax(axis=1)  # the first farthest point
            cmax = cross.ravel()[at + steps[:s.size] * width - width]
            at += s
            k = at + 1
        else:
            cnt = np.array(cl, dtype=np.int64)
            inner = cnt.nonzero()[0]
            cmax = np.zeros(s.size)
            k = s.copy()
            cnt = cnt[inner]
            offs = cnt.cumsum()
            total = int(offs[-1])
            offs -= cnt
            idx = (s[inner] + 1 - offs).repeat(cnt)
            idx += np.arange(total)
            cross = (px[idx] - x0[inner].repeat(cnt)) * cy[inner].repeat(cnt)
            cross -= (py[idx] - y0[inner].repeat(cnt)) * cx[inner].repeat(cnt)
            np.abs(cross, out=cross)
            cm = np.maximum.reduceat(cross, offs)
            at = (cross == cm.repeat(cnt)).nonzero()[0]
            cmax[inner] = cm
            k[inner] = idx[at[at.searchsorted(offs)]]  # the first farthest point
        split = cmax > tol[k] * np.hypot(cx, cy)
        go = split.nonzero()[0]
        if go.size < split.size:
            stop = ~split
            done_s.append(s[stop])
            done_e.append(e[stop])
            short = True
            if not go.size:
                break
            s, e, k = s[go], e[go], k[go]
        s = np.concatenate((s, k))  # pieces out of order from here on
        e = np.concatenate((k, e))
        mixed = True
    if not done_s:
        return np.zeros((2, 0), dtype=np.int64)
    if len(done_s) == 1 and not mixed:  # the runs' pieces, in order
        out = np.array((done_s[0], done_e[0]))
    else:
        s, e = np.concatenate(done_s), np.concatenate(done_e)
        order = np.lexsort((e, s))
        out = np.empty((2, s.size), dtype=np.int64)
        out[0] = s[order]
        out[1] = e[order]
    if short and min_span > 0:
        out = out[:, out[1] - out[0] >= min_span]
    return out


# Interior points of a recursion level up to which _split_py is faster than a numpy level
# (measured on 180- and 361-beam Carmen scans: the whole scan of one).
_SPLIT_PY = 400
# Interior points of a piece up to which _split_py finds its farthest point on Python
# floats rather than with array operations (measured).
_SPLIT_PIECE_PY = 48


def _split_py(px: np.ndarray, py: np.ndarray, tol: np.ndarray, s: List[int],
              e: List[int], min_span: int = 0) -> Tuple[List[int], List[int]]:
    """Split the pieces ``s[i]..e[i]`` as :func:`_split` does, one piece at a time.

    The same cross products in the same order (eq. 4 distance times the chord length, the
    first farthest point), on Python floats for small pieces and as arrays for large ones;
    depth first, left piece first. Returns the final pieces' first and last points, in
    order, without those of ``last - first < min_span``. The pieces index ``px``, ``py``
    and ``tol``, whose points are all listed (:func:`_split` passes the runs themselves,
    or the points of the pieces left after array levels).
    """
    pts = list(zip(px.tolist(), py.tolist()))  # (x, y) of every point: one slice a piece
    tol = memoryview(tol)
    small = _SPLIT_PIECE_PY
    out_s: List[int] = []
    out_e: List[int] = []
    stack = list(zip(s, e))
    stack.reverse()
    while stack:
        a, b = stack.pop()
        if b - a < 2:  # no interior point: no split
            if b - a >= min_span:
                out_s.append(a)
                out_e.append(b)
            continue
        x0, y0 = pts[a]
        x1, y1 = pts[b]
        cx, cy = x1 - x0, y1 - y0
        if b - a - 1 <= small:
            cross = [abs((x - x0) * cy - (y - y0) * cx) for x, y in pts[a + 1:b]]
            cmax = max(cross)
            k = a + 1 + cross.index(cmax)
        else:
            cross = px[a + 1:b] - x0
            cross *= cy
            dy = py[a + 1:b] - y0
            dy *= cx
            cross -= dy
            np.abs(cross, out=cross)
            k = int(cross.argmax())  # the first farthest point
            cmax = cross[k].item()
            k += a + 1
        if cmax > tol[k] * abs(complex(cx, cy)):  # C hypot, as np.hypot
            stack.append((k, b))
            stack.append((a, k))
        elif b - a >= min_span:
            out_s.append(a)
            out_e.append(b)
    return out_s, out_e
