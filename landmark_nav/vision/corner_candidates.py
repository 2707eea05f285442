"""Corner candidates of the landmark detector (visual navigation chapter §2.2.1).

Step 1 of :func:`~.detector.detect_landmarks`, the corners where four blocks of the frame
meet (X-corners), as :class:`Corners`:

* :func:`smooth` -- the 3 x 3 Gaussian-smoothed image G (§2.2.1);
* :func:`corner_pixels` -- the corner filters C1..C4 (eq. 1) on the 8-bit G with OpenCV array
  operations (saturating arithmetic, see :func:`_filter_pair`);
* :func:`corner_groups` -- their 8-connected groups with intensity-weighted centres (eq. 2);
* :func:`saddle_corners` -- the candidates used by default instead (extension,
  ``DetectorParams.corner_method``): the strong saddle points of G.

Conventions: pixel positions are OpenCV ``(x, y)`` = (column, row), pixel centres at integer
coordinates (the chapter writes ``(r, c)``).

Readings of the chapter that needed a decision (tested in
``test/test_landmark_detector.py``):

* The 45-degree filter set (C3, C4) samples the smoothed image at ``(r -+ d, c)`` and
  ``(r, c -+ d)`` with ``d = diagonal_offset = 3`` pixels, the axial neighbours closest to the
  ``2 sqrt 2`` distance of the C1/C2 samples that keep the one-pixel guard band between the
  four 3 x 3 areas. C3 is bright above and below, C4 bright left and right.
* Groups of different filters (C1 and C3 respond both at 22.5 degrees) whose centres are
  closer than ``merge_distance`` are merged into one corner with the eq. 2 centre of their
  union, so that a corner is not listed twice among a neighbour's eight.
* Extension (``corner_method='saddle'``, the default): on composites in real photographs
  at 4-5 px per block nearly all lost landmarks had frame X-corners that the eq. 1
  filters miss (samples 2-3 px out leave a block foreshortened to 2-3 px) or whose eq. 2
  group merged with a neighbour 2 px away. The corner candidates are then the strong
  saddle points of G (:func:`saddle_corners`: the Hessian of G by 3 x 3 Sobel
  derivatives, local maxima of minus its determinant, L-corners and edge noise
  rejected), each with the C1..C4 filter its orientation falls into, and the chains,
  frames and code reading follow unchanged. ``corner_method='eq1'`` is the chapter's
  stage.
"""

from dataclasses import dataclass
import math
from typing import List, Sequence, Tuple

import cv2
import numpy as np


@dataclass(frozen=True, eq=False)
class Corners:
    """Corner groups of one image (eq. 2).

    Attributes:
        points: (N, 2) intensity-weighted centres ``(x, y)`` [px].
        weights: (N,) summed filter weights ``w`` of each group.
        filters: (N,) filter of the group, 0..3 for C1..C4 (the strongest of merged groups).
    """

    points: np.ndarray
    weights: np.ndarray
    filters: np.ndarray


def smooth(gray: np.ndarray, sigma: float = 0.95) -> np.ndarray:
    """Return the 3 x 3 Gaussian-smoothed image G (§2.2.1), same dtype (uint8 or float32)."""
    img = np.asarray(gray)
    if img.dtype != np.uint8:
        img = img.astype(np.float32)
    return cv2.GaussianBlur(img, (3, 3), sigma, borderType=cv2.BORDER_REPLICATE)


def _sample_offsets(axial_offset: int, diagonal_offset: int) -> List[np.ndarray]:
    """Return per filter the (4, 2) (dy, dx) offsets of its samples y1, y2, y3, y4 (eq. 1).

    y1 and y4 are the samples that must be bright, y2 and y3 the dark ones.
    """
    d, e = axial_offset, diagonal_offset
    c1 = np.array([[-d, -d], [d, -d], [-d, d], [d, d]])   # eq. 1: y1, y2, y3, y4
    c3 = np.array([[-e, 0], [0, -e], [0, e], [e, 0]])     # up, left, right, down
    return [c1, c1[[1, 0, 3, 2]], c3, c3[[1, 0, 3, 2]]]


def _filter_pair(y1: np.ndarray, y2: np.ndarray, y3: np.ndarray, y4: np.ndarray,
                 k_min: int) -> Tuple[np.ndarray, np.ndarray]:
    """Apply eq. 1 and its intensity-reversed twin to four equally shaped uint8 sample arrays.

    ``y1``, ``y4`` are the samples that are bright for the first filter, ``y2``, ``y3`` the
    dark ones. Eq. 1 requires every bright-dark difference to exceed
    ``k_c = (max - min) / 3 + k_min``, i.e. ``gap > span / 3 + k_min`` with
    ``gap = min(y1, y4) - max(y2, y3)`` and ``span = max(y1, y4) - min(y2, y3)``. As
    ``span = gap + |y1 - y4| + |y2 - y3|``, the test is ``2 gap > D + 3 k_min`` with
    ``D = |y1 - y4| + |y2 - y3|``, the same D for the reversed filter (whose gap is
    ``min(y2, y3) - max(y1, y4)``). In saturating 8-bit arithmetic this is exact: a positive
    gap bounds ``D <= 255 - gap``, so D never saturates when it matters, ``2 gap`` saturates
    only when the right side is far below 255, and a saturated right side means
    ``2 gap < 255``.

    Returns:
        (mask_a, mask_b): uint8 masks (255 = corner pixel) of the filter and its reverse.
    """
    rhs = cv2.add(cv2.add(cv2.absdiff(y1, y4), cv2.absdiff(y2, y3)), 3 * int(k_min))
    gap_a = cv2.subtract(cv2.min(y1, y4), cv2.max(y2, y3))
    gap_b = cv2.subtract(cv2.min(y2, y3), cv2.max(y1, y4))
    return (cv2.compare(cv2.add(gap_a, gap_a), rhs, cv2.CMP_GT),
            cv2.compare(cv2.add(gap_b, gap_b), rhs, cv2.CMP_GT))


def corner_pixels(g: np.ndarray, k_min: int = 7, axial_offset: int = 2,
                  diagonal_offset: int = 3) -> List[np.ndarray]:
    """Return the corner pixel sets C1..C4 of a smoothed image with their weights (eq. 1).

    C1: bright upper-left and lower-right samples ``G(r -+ d, c -+ d)``, dark lower-left and
    upper-right (eq. 1 with ``d = axial_offset``); C2 the reverse. C3: bright above and
    below (``G(r -+ e, c)``), dark left and right (``G(r, c -+ e)``), ``e = diagonal_offset``;
    C4 the reverse (Fig. 1 (c)). The whole image is filtered at once (OpenCV array
    operations on 8-bit grey levels); pixels closer than the larger offset to the image
    border are never corners.

    Args:
        g: (H, W) uint8 smoothed image (:func:`smooth`); other dtypes are rounded and
            clipped to 0..255.
        k_min: fixed minimum threshold [integer grey levels].
        axial_offset: C1/C2 sample offset [px].
        diagonal_offset: C3/C4 sample offset [px].

    Returns:
        Four (M_k, 3) float arrays, one per filter, of corner pixels ``(x, y, w)`` with the
        eq. 1 weight ``w = y1 + y4 - y2 - y3 > 0`` (bright minus dark samples).
    """
    g = np.asarray(g)
    if g.dtype != np.uint8:
        g = np.clip(np.rint(g), 0, 255).astype(np.uint8)
    h, w = g.shape
    o = max(axial_offset, diagonal_offset)
    empty = [np.zeros((0, 3)) for _ in range(4)]
    if h <= 2 * o or w <= 2 * o:
        return empty
    offsets = _sample_offsets(axial_offset, diagonal_offset)
    code = None
    for pair in (0, 2):
        samples = [g[o + dy:h - o + dy, o + dx:w - o + dx] for dy, dx in offsets[pair]]
        ma, mb = _filter_pair(*samples, int(k_min))
        bits = cv2.bitwise_or(cv2.bitwise_and(ma, 1 << pair), cv2.bitwise_and(mb, 2 << pair))
        code = bits if code is None else cv2.bitwise_or(code, bits)
    rows = np.flatnonzero(code.any(axis=1))
    if not len(rows):
        return empty
    r0 = int(rows[0])
    nz = cv2.findNonZero(code[r0:int(rows[-1]) + 1])
    xy = nz.reshape(-1, 2)
    xy[:, 1] += r0
    which = code[xy[:, 1], xy[:, 0]]
    xs, ys = xy[:, 0] + o, xy[:, 1] + o
    gi = g.astype(np.int32) if len(xs) > 4096 else g
    out = []
    for k in range(4):
        sel = (which & (1 << k)) != 0
        x, y = xs[sel], ys[sel]
        s = [gi[y + dy, x + dx].astype(np.float64) for dy, dx in offsets[k]]
        out.append(np.column_stack([x, y, s[0] + s[3] - s[1] - s[2]]))
    return out


def _components(n: int, src: np.ndarray, dst: np.ndarray) -> Tuple[int, np.ndarray]:
    """Label the connected components of an undirected graph (n nodes, edges src-dst).

    Returns:
        (count, labels) with labels 0..count-1, numbered in the order of each component's
        smallest node.
    """
    if not len(src):
        return n, np.arange(n)
    from scipy.sparse import coo_matrix, csgraph  # on first use: not at every node start
    graph = coo_matrix((np.ones(len(src), np.int8), (src, dst)), shape=(n, n))
    count, lab = csgraph.connected_components(graph, directed=False)
    _, first = np.unique(lab, return_index=True)      # smallest node of each component
    rank = np.empty(count, np.int64)
    rank[np.argsort(first)] = np.arange(count)
    return count, rank[lab]


def corner_groups(pixels: Sequence[np.ndarray], merge_distance: float = 1.5) -> Corners:
    """Group the corner pixels of each filter 8-connected; return the centres (eq. 2).

    Each group's centre is the weight-averaged pixel position ``sum(a_i w_i) / sum(w_i)``
    (eq. 2). Groups of different filters whose centres are closer than ``merge_distance``
    pixels are merged (centre of the union by eq. 2).

    Args:
        pixels: the four (M_k, 3) arrays of :func:`corner_pixels`.
        merge_distance: merge radius [px]; 0 disables merging.

    Returns:
        :class:`Corners`.
    """
    sizes = [len(p) for p in pixels]
    if sum(sizes) == 0:
        return Corners(np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int8))
    allp = np.vstack([p for p in pixels if len(p)])
    filt = np.repeat(np.arange(len(pixels)), sizes)
    xs, ys, ws = allp[:, 0].astype(np.int64), allp[:, 1].astype(np.int64), allp[:, 2]
    width = int(xs.max()) + 3
    height = int(ys.max()) + 3
    key = (filt * height + ys) * width + xs       # unique per (filter, pixel)
    order = np.argsort(key, kind='stable')
    key, xs, ys, ws, filt = key[order], xs[order], ys[order], ws[order], filt[order]
    m = len(key)
    src, dst = [], []
    for off in (1, width - 1, width, width + 1):  # forward 8-neighbours (E, SW, S, SE)
        j = np.searchsorted(key, key + off)
        j[j >= m] = m - 1
        hit = key[j] == key + off
        src.append(np.flatnonzero(hit))
        dst.append(j[hit])
    n_lab, lab = _components(m, np.concatenate(src), np.concatenate(dst))
    wsum = np.bincount(lab, ws, n_lab)
    sx = np.bincount(lab, ws * xs, n_lab)
    sy = np.bincount(lab, ws * ys, n_lab)
    gfilt = np.zeros(n_lab, np.int8)
    gfilt[lab] = filt
    keep = wsum > 0
    sx, sy, wsum, gfilt = sx[keep], sy[keep], wsum[keep], gfilt[keep]
    pts = np.column_stack([sx / wsum, sy / wsum])                 # eq. 2
    if merge_distance > 0 and len(pts) > 1:
        from scipy.spatial import cKDTree  # on first use: scipy.spatial costs ~0.5 CPU-s
        pairs = cKDTree(pts).query_pairs(merge_distance, output_type='ndarray')
        if len(pairs):
            pairs = pairs[gfilt[pairs[:, 0]] != gfilt[pairs[:, 1]]]
        if len(pairs):
            n_comp, comp = _components(len(pts), pairs[:, 0], pairs[:, 1])
            gw = np.bincount(comp, wsum, n_comp)
            strongest = np.zeros(n_comp, np.int64)
            by_weight = np.argsort(wsum)     # the last write per component is the strongest
            strongest[comp[by_weight]] = by_weight
            pts = np.column_stack([np.bincount(comp, sx, n_comp) / gw,
                                   np.bincount(comp, sy, n_comp) / gw])
            wsum, gfilt = gw, gfilt[strongest]
    return Corners(pts, wsum, gfilt)


def saddle_corners(g: np.ndarray, threshold: float = 1000.0, kappa: float = 0.0,
                   max_step: float = 1.5, relative: float = 0.1, radius: float = 8.0,
                   border: int = 3) -> Corners:
    """Return X-corner candidates as strong saddle points of the smoothed image (extension).

    Extension for small and strongly tilted landmarks (``DetectorParams.corner_method``
    ``'saddle'``, the default; ``'eq1'`` is the chapter's eq. 1-2). The eq. 1 filters
    sample G 2-3 px from the corner, outside a block foreshortened to 2-3 px, and the
    8-connected groups (eq. 2) of two X-corners 2 px apart merge into one centre between
    them. At an X-corner the grey levels of G form a saddle whose strength needs no
    sample outside the blocks: with the second derivatives of G (3 x 3 Sobel) the
    strength is ``S = Gxy^2 - Gxx Gyy - kappa (Gxx + Gyy)^2`` (minus the Hessian
    determinant, less a multiple of the squared trace, which is zero at a symmetric
    X-corner but large across a straight edge, whose noise otherwise makes weak saddles
    along every strong edge). Every pixel where S is a 3 x 3 local maximum above
    ``threshold`` is a candidate, placed at the saddle point of the local quadratic model
    (one Newton step ``-H^-1 grad G``); a candidate whose step is longer than
    ``max_step`` is dropped: the gradient vanishes at an X-corner, but not at the tip of
    an L-corner (one dark quadrant, e.g. a black block's corner at the quiet zone), whose
    model saddle lies about 1.8 blur sigmas away. The filter (C1..C4, for the polarity
    test of the edge chains) is the quarter of the saddle orientation ``atan2(Gxy, (Gyy -
    Gxx) / 2)``: C3 (bright above and below) around 0 degrees, C1 (bright upper-left and
    lower-right) around 90, C4 around 180, C2 around -90.

    Composites in real photographs (``landmarks_real``, seed 1): a frame X-corner without
    a candidate within 0.35 block in 3 / 1 of 50 trials at 4 / 5 px per block (every
    second trial), where eq. 1-2 leave one in 33 / 20 of the 100 trials, with fewer
    candidates (median 230-370 per frame instead of about 880).

    Args:
        g: (H, W) smoothed image (:func:`smooth`), uint8 or float.
        threshold: smallest strength S, in the units of the 3 x 3 Sobel derivatives
            of grey levels (16 (grey level / px^2)^2).
        kappa: weight of the squared trace in S.
        max_step: longest Newton step to the saddle point [px].
        relative: candidates weaker than this fraction of another candidate within
            ``radius`` [px] are dropped (0: off).
        radius: see ``relative``.
        border: pixels at the image border that are never corners.

    Returns:
        :class:`Corners` with the strengths S as weights.
    """
    g = np.asarray(g)
    if g.dtype != np.uint8:
        g = g.astype(np.float32)
    h, w = g.shape
    empty = Corners(np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int8))
    if h <= 2 * border + 2 or w <= 2 * border + 2:
        return empty
    depth = cv2.CV_16S if g.dtype == np.uint8 else cv2.CV_32F     # exact for 8 bits
    gxx = cv2.Sobel(g, depth, 2, 0, ksize=3, borderType=cv2.BORDER_REPLICATE)
    gyy = cv2.Sobel(g, depth, 0, 2, ksize=3, borderType=cv2.BORDER_REPLICATE)
    gxy = cv2.Sobel(g, depth, 1, 1, ksize=3, borderType=cv2.BORDER_REPLICATE)
    # S = Gxy^2 + ((Gxx - Gyy) / 2)^2 - (1/4 + kappa) (Gxx + Gyy)^2 <= 2 max(|Gxy|,
    # |Gxx - Gyy| / 2)^2: only pixels where that bound exceeds the threshold (a few % of a
    # photograph) can be corners, so S is evaluated there only (the others are 0 below)
    bound = math.sqrt(max(float(threshold), 0.0) / 2.0)
    if depth == cv2.CV_16S:
        # integer derivatives: |x| > b is |x| > floor(b) (OpenCV's saturating array
        # operations; no 16-bit derivative of 8-bit grey levels reaches the saturation)
        maybe = cv2.bitwise_or(
            cv2.compare(cv2.absdiff(gxy, 0), math.floor(bound), cv2.CMP_GT),
            cv2.compare(cv2.absdiff(gxx, gyy), math.floor(2.0 * bound), cv2.CMP_GT))
        maybe = cv2.bitwise_and(maybe, 1).view(bool)
    else:
        maybe = (np.abs(gxy) > bound) | (np.abs(cv2.subtract(gxx, gyy)) > 2.0 * bound)
    maybe[:border] = False
    maybe[h - border:] = False
    maybe[:, :border] = False
    maybe[:, w - border:] = False
    idx = np.flatnonzero(maybe)
    fxx = gxx.ravel()[idx].astype(np.float64)
    fyy = gyy.ravel()[idx].astype(np.float64)
    fxy = gxy.ravel()[idx].astype(np.float64)
    tr = fxx + fyy
    strength = fxy * fxy - fxx * fyy - kappa * tr * tr
    sel = np.flatnonzero(strength > threshold)
    # a pixel below the threshold cannot be the larger of two strong neighbours: only the
    # strong pixels go into the image of S compared below
    s = np.zeros(h * w)
    s[idx[sel]] = strength[sel]
    # 3 x 3 local maxima (ties kept) among the strong pixels (none is at the border)
    for off in (-w - 1, -w, -w + 1, -1, 1, w - 1, w, w + 1):
        sel = sel[strength[sel] >= s[idx[sel] + off]]
    if not len(sel):
        return empty
    idx = idx[sel]
    y, x = np.divmod(idx, w)
    xy = np.column_stack([x, y])
    sxx, syy, sxy, wgt = fxx[sel], fyy[sel], fxy[sel], strength[sel]
    # gradient at the pixel (3 x 3 Sobel: 8 grad, and 4 Hessian, in these units)
    patch = g[y[:, None, None] + np.arange(-1, 2)[None, :, None],
              x[:, None, None] + np.arange(-1, 2)[None, None, :]].astype(np.float64)
    gx = (patch[:, :, 2] - patch[:, :, 0]) @ np.array([1.0, 2.0, 1.0]) / 8.0
    gy = (patch[:, 2, :] - patch[:, 0, :]) @ np.array([1.0, 2.0, 1.0]) / 8.0
    hxx, hyy, hxy = sxx / 4.0, syy / 4.0, sxy / 4.0
    det = hxx * hyy - hxy * hxy                                  # < 0 at a saddle
    with np.errstate(divide='ignore', invalid='ignore'):
        dx = -(hyy * gx - hxy * gy) / det                        # -H^-1 grad
        dy = -(hxx * gy - hxy * gx) / det
    step = np.column_stack([dx, dy]).astype(np.float64)
    # the gradient vanishes at an X-corner (its saddle point lies within the peak pixel)
    # but not at the tip of an L-corner (one dark quadrant: a black block's corner at the
    # quiet zone), whose quadratic model puts the saddle point about 1.8 blur sigmas away
    keep = np.all(np.isfinite(step), axis=1) & (np.hypot(step[:, 0], step[:, 1]) <= max_step)
    pts = xy[keep].astype(np.float64) + step[keep]
    sxx, syy, sxy, wgt = sxx[keep], syy[keep], sxy[keep], wgt[keep]
    if relative > 0 and len(pts) > 1:
        # a candidate weaker than ``relative`` of a candidate within ``radius`` is dropped:
        # noise and JPEG make weak saddles on the arms of a large, sharp X-corner that
        # crowd its neighbours out of their direction sectors (composites at 12-15 px per
        # block: 4-7 % of the corner's strength, 5-8 px away; frame X-corners at 3-5 px
        # per block are at least 17 % of any candidate near them)
        # (the pairs' order does not matter to the maxima: the unbalanced tree builds faster)
        from scipy.spatial import cKDTree  # on first use: scipy.spatial costs ~0.5 CPU-s
        pairs = cKDTree(pts, balanced_tree=False, compact_nodes=False).query_pairs(
            radius, output_type='ndarray')
        if len(pairs):
            near = wgt.copy()
            np.maximum.at(near, pairs[:, 0], wgt[pairs[:, 1]])
            np.maximum.at(near, pairs[:, 1], wgt[pairs[:, 0]])
            strong = wgt >= relative * near
            pts, sxx, syy, sxy, wgt = (a[strong] for a in (pts, sxx, syy, sxy, wgt))
    ang = np.arctan2(sxy, 0.5 * (syy - sxx))                     # orientation of the saddle
    quarter = np.floor((ang + 0.25 * math.pi) / (0.5 * math.pi)).astype(np.int64) % 4
    filt = np.array([2, 0, 3, 1], np.int8)[quarter]              # 0 deg C3, 90 C1, 180 C4, -90 C2
    return Corners(pts, wgt.astype(np.float64), filt)


__all__ = ['corner_groups', 'corner_pixels', 'Corners', 'saddle_corners', 'smooth']
