"""Straight line segments in an image: Canny edges + segmented Hough, HoughLinesP or LSD.

Shared by the corridor follower (visual navigation chapter §3.1.1) and the monocular
localizer. Pure numpy/OpenCV; no rclpy.

Every detector returns :class:`ImageLines`: an ``(N, 4)`` float array of segments
``x1 y1 x2 y2`` in pixels (``x`` = column to the right, ``y`` = row down, the centre of the
top-left pixel at ``(0, 0)``, as in :mod:`.camera`) and optional ``(N,)`` per-segment
weights (the number of edge pixels supporting the segment, where the method has it).

Methods (``detect_lines(image, method=...)``):

* ``'segmented_hough'`` -- the chapter's method (§3.1.1): Canny edges (:func:`canny_edges`);
  the image cut into a 10 x 10 grid of sub-images; a Hough transform in each sub-image;
  the pieces traced through the image and merged with collinear pieces of neighbouring
  sub-images (:func:`segmented_hough`). The chapter gives no more detail (its Fig. 6 only
  shows the result); our choices, each a stated constant of :class:`SegmentedHoughParams`:

  1. Hough in every sub-image in local coordinates about the sub-image centre, normal form
     ``x cos t + y sin t = r`` with ``r`` in 1 px bins and ``t`` in bins of ``1 / r_max``
     rad (``r_max`` = half the sub-image diagonal), so that one ``t`` bin moves a line by at
     most 1 px inside the sub-image: the finest useful angular step, no coarser.
  2. Peaks are taken in rounds, all sub-images at once: the strongest bin of each
     sub-image with at least ``min_votes`` pixels; its pixels (within ``band_px`` of the
     peak line) are fitted by total least squares, removed, and their votes subtracted;
     at most ``max_lines_per_cell`` rounds.
  3. Tracing and merging: two pieces of the same or adjacent sub-images are joined when
     the end points are within ``max_gap_px`` and the total-least-squares line through
     the pixels of both has an RMS perpendicular residual <= ``merge_rms_px`` (from
     additive pixel moments, exact). Connected chains are refitted on all their pixels;
     a chain whose fit fails the same test (a curve made of straight pieces) is traced
     greedily from its strongest piece instead.

* ``'hough_p'`` -- OpenCV's probabilistic Hough ``cv2.HoughLinesP`` on the same Canny edges
  (in-run reference; parameters in :class:`HoughPParams`).
* ``'lsd'`` -- OpenCV's Line Segment Detector ``cv2.createLineSegmentDetector`` on the grey
  image (its own a-contrario thresholds, no Canny; in-run reference).

Segments detected in a distorted image can be mapped to ideal pinhole pixels with
:func:`undistort_segments` (end points only: a segment is short enough that its straight
image stays straight to well below a pixel for the usual lens distortions).
"""

from dataclasses import dataclass, field
import math
from typing import Optional, Union

import cv2
from landmark_nav.vision.camera import CameraModel
import numpy as np

METHODS = ('segmented_hough', 'hough_p', 'lsd')


@dataclass(frozen=True, eq=False)
class ImageLines:
    """Line segments found in one image.

    Attributes:
        segments: (N, 4) float64 ``x1 y1 x2 y2`` [px].
        weights: (N,) float64 support of each segment (edge pixels), or None.
    """

    segments: np.ndarray
    weights: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        """Check the shapes."""
        seg = np.asarray(self.segments, dtype=float).reshape(-1, 4)
        object.__setattr__(self, 'segments', seg)
        if self.weights is not None:
            w = np.asarray(self.weights, dtype=float).reshape(-1)
            if w.shape[0] != seg.shape[0]:
                raise ValueError(f'{w.shape[0]} weights for {seg.shape[0]} segments')
            object.__setattr__(self, 'weights', w)

    def __len__(self) -> int:
        """Return the number of segments."""
        return int(self.segments.shape[0])

    @property
    def lengths(self) -> np.ndarray:
        """(N,) segment lengths [px]."""
        d = self.segments[:, 2:] - self.segments[:, :2]
        return np.hypot(d[:, 0], d[:, 1])


@dataclass(frozen=True)
class CannyParams:
    """Edge detection (all methods but LSD).

    Attributes:
        blur_sigma: std [px] of the Gaussian smoothing before Canny (0: none); 1 px
            suppresses pixel noise and JPEG blocking without merging edges 3 px apart.
        low_contrast: hysteresis low threshold as a step contrast [grey levels].
        high_contrast: hysteresis high threshold as a step contrast [grey levels]. The
            Sobel 3 x 3 response to an ideal step of contrast C is 4 C, so the Canny
            thresholds are 4x these; the 1:2.5 ratio is in Canny's recommended 1:2-1:3.
    """

    blur_sigma: float = 1.0
    low_contrast: float = 8.0
    high_contrast: float = 20.0


@dataclass(frozen=True)
class SegmentedHoughParams:
    """The chapter's segmented Hough transform (§3.1.1); see the module docstring.

    Attributes:
        grid: sub-images per side (the chapter: 10 x 10).
        band_px: pixels within this distance [px] of a peak line belong to it (one r bin
            either side of the peak's 1 px bin).
        min_votes: minimum pixels of a piece; None: 40 % of the shorter sub-image side
            (a piece crossing 40 % of its sub-image).
        max_lines_per_cell: peak rounds per sub-image.
        merge_rms_px: maximum RMS perpendicular residual [px] of a merged line: about
            twice the 0.3-0.5 px RMS of a single straight Canny piece (edge localisation
            plus pixel quantisation, sqrt(1/12) = 0.29 px).
        max_gap_px: maximum gap [px] between the facing end points of two joined pieces;
            None: half the shorter sub-image side.
        min_length_px: output segments shorter than this [px] are dropped.
        trace_gap_px: tracing follows a line across gaps of at most this many pixels
            without edge pixels (Canny breaks edges for 1-2 px at junctions).
        gradient_window_deg: with image gradients, a pixel votes only for line normals
            within this angle [deg] of its gradient direction: about the std of the Sobel
            3 x 3 direction at the Canny low threshold (grey-level noise std 2 gives a
            Sobel noise std of 2 sqrt(12) = 6.9 against a response of 4 x 8 = 32, i.e.
            0.22 rad = 12 deg); stronger edges are far more precise.
    """

    grid: int = 10
    band_px: float = 1.0
    min_votes: Optional[int] = None
    max_lines_per_cell: int = 4
    merge_rms_px: float = 0.8
    max_gap_px: Optional[float] = None
    min_length_px: float = 10.0
    trace_gap_px: float = 3.0
    gradient_window_deg: float = 12.0


@dataclass(frozen=True)
class HoughPParams:
    """OpenCV HoughLinesP (reference input; OpenCV-tutorial values, not tuned).

    Attributes:
        rho_px: distance resolution [px].
        theta_rad: angle resolution [rad].
        threshold: accumulator threshold [votes].
        min_length_px: minimum segment length [px] (same as the segmented Hough output).
        max_gap_px: maximum gap joined along a line [px].
    """

    rho_px: float = 1.0
    theta_rad: float = math.pi / 180.0
    threshold: int = 30
    min_length_px: float = 10.0
    max_gap_px: float = 3.0


@dataclass(frozen=True)
class LineParams:
    """Parameters of :func:`detect_lines` (one set for every method)."""

    canny: CannyParams = field(default_factory=CannyParams)
    segmented_hough: SegmentedHoughParams = field(default_factory=SegmentedHoughParams)
    hough_p: HoughPParams = field(default_factory=HoughPParams)


def to_gray(image: np.ndarray) -> np.ndarray:
    """Return an 8-bit single-channel image (BGR/BGRA converted, other depths scaled).

    Raises:
        ValueError: for an empty image or one that is not 2-D grey or 3-D with 3/4 channels.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        if img.dtype != np.uint8:
            img = _to_u8(img)
        img = cv2.cvtColor(img, code)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f'expected a non-empty grey (H, W) or BGR(A) (H, W, 3|4) image; '
                         f'got shape {img.shape}')
    return np.ascontiguousarray(_to_u8(img) if img.dtype != np.uint8 else img)


def _to_u8(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint16:
        return (img >> 8).astype(np.uint8)
    if img.dtype.kind == 'f':
        return np.clip(np.nan_to_num(img) * 255.0, 0, 255).astype(np.uint8)
    return np.clip(img, 0, 255).astype(np.uint8)


def canny_edges(gray: np.ndarray, params: CannyParams = CannyParams(),
                with_gradient: bool = False):
    """Return the Canny edge image (uint8, 255 on edges) of an 8-bit grey image (§3.1.1).

    With ``with_gradient`` also the Sobel 3 x 3 gradients (gx, gy) (int16) of the smoothed
    image Canny used, as ``(edges, (gx, gy))``.
    """
    g = gray
    if params.blur_sigma > 0:
        g = cv2.GaussianBlur(gray, (0, 0), params.blur_sigma)
    if not with_gradient:
        return cv2.Canny(g, 4.0 * params.low_contrast, 4.0 * params.high_contrast,
                         L2gradient=True)
    gx = cv2.Sobel(g, cv2.CV_16S, 1, 0, ksize=3)
    gy = cv2.Sobel(g, cv2.CV_16S, 0, 1, ksize=3)
    edges = cv2.Canny(gx, gy, 4.0 * params.low_contrast, 4.0 * params.high_contrast,
                      L2gradient=True)
    return edges, (gx, gy)


def _moments_fit(m: np.ndarray) -> tuple:
    """Total-least-squares lines from pixel moments ``(n, sx, sy, sxx, sxy, syy)`` (..., 6).

    Returns:
        centroid (..., 2), unit direction (..., 2) and RMS perpendicular residual (...,).
    """
    n = np.maximum(m[..., 0], 1.0)
    cx, cy = m[..., 1] / n, m[..., 2] / n
    vxx = m[..., 3] / n - cx * cx
    vxy = m[..., 4] / n - cx * cy
    vyy = m[..., 5] / n - cy * cy
    ang = 0.5 * np.arctan2(2.0 * vxy, vxx - vyy)
    half_tr = 0.5 * (vxx + vyy)
    disc = np.sqrt(np.maximum(0.25 * (vxx - vyy) ** 2 + vxy * vxy, 0.0))
    lam_min = np.maximum(half_tr - disc, 0.0)
    return (np.stack([cx, cy], axis=-1), np.stack([np.cos(ang), np.sin(ang)], axis=-1),
            np.sqrt(lam_min))


def _moments(x: np.ndarray, y: np.ndarray, label: np.ndarray, n_labels: int) -> np.ndarray:
    """Per-label pixel moments ``(n, sx, sy, sxx, sxy, syy)`` as an (n_labels, 6) array."""
    out = np.empty((n_labels, 6))
    for k, v in enumerate((np.ones_like(x), x, y, x * x, x * y, y * y)):
        out[:, k] = np.bincount(label, weights=v, minlength=n_labels)
    return out


def _extent(x: np.ndarray, y: np.ndarray, label: np.ndarray, c: np.ndarray,
            u: np.ndarray, n_labels: int) -> np.ndarray:
    """Segments (n_labels, 4): extreme projections of each label's points on its line."""
    t = (x - c[label, 0]) * u[label, 0] + (y - c[label, 1]) * u[label, 1]
    tmin = np.full(n_labels, np.inf)
    tmax = np.full(n_labels, -np.inf)
    np.minimum.at(tmin, label, t)
    np.maximum.at(tmax, label, t)
    return np.column_stack([c + tmin[:, None] * u, c + tmax[:, None] * u])


def _cell_hough(xs: np.ndarray, ys: np.ndarray, normal: np.ndarray, shape: tuple,
                p: SegmentedHoughParams) -> tuple:
    """Step 1-2: pieces of every sub-image; returns (moments, segments, cell (col, row)).

    ``normal`` is each pixel's gradient direction in [0, pi) or NaN when unknown (then
    the pixel votes for every angle).
    """
    h, w = shape
    cw, ch = w / p.grid, h / p.grid
    col = np.minimum((xs / cw).astype(np.int64), p.grid - 1)
    row = np.minimum((ys / ch).astype(np.int64), p.grid - 1)
    cell = row * p.grid + col
    lx = xs - (col + 0.5) * cw + 0.5      # pixel centres about the sub-image centre
    ly = ys - (row + 0.5) * ch + 0.5
    r_max = 0.5 * math.hypot(cw, ch)
    n_t = max(int(math.ceil(math.pi * r_max)), 8)   # bin 1 / r_max rad
    n_r = 2 * int(math.ceil(r_max)) + 1
    r_off = int(math.ceil(r_max))
    theta = np.arange(n_t) * (math.pi / n_t)
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    n_cells = p.grid * p.grid
    min_votes = p.min_votes
    if min_votes is None:
        min_votes = max(int(math.ceil(0.4 * min(cw, ch))), 3)

    half = int(math.ceil(math.radians(p.gradient_window_deg) * n_t / math.pi))
    if half * 2 + 1 >= n_t or np.isnan(normal).any():
        t0 = np.zeros(xs.size, dtype=np.int64)
        offs = np.arange(n_t)
    else:
        t0 = np.rint(normal * (n_t / math.pi)).astype(np.int64)
        offs = np.arange(-half, half + 1)

    def votes(sel: np.ndarray) -> np.ndarray:
        """Return the accumulator bins the pixels ``sel`` vote for (one entry per vote)."""
        tb = t0[sel, None] + offs
        # a line normal at t + pi is the same line with r negated
        flip = np.where((tb < 0) | (tb >= n_t), -1.0, 1.0)
        tb = tb % n_t
        rho = flip * (lx[sel, None] * cos_t[tb] + ly[sel, None] * sin_t[tb])
        rb = np.rint(rho).astype(np.int64) + r_off
        return ((cell[sel, None] * n_t + tb) * n_r + rb).ravel()

    alive = np.ones(xs.size, dtype=bool)
    acc = np.bincount(votes(alive), minlength=n_cells * n_t * n_r).reshape(n_cells, n_t * n_r)
    bins = acc.reshape(-1)  # the same counts, flat
    mom, segs, cells = [], [], []
    for _ in range(p.max_lines_per_cell):
        peak = np.argmax(acc, axis=1)
        best = acc[np.arange(n_cells), peak]
        good = best >= min_votes
        if not np.any(good):
            break
        t_pk = peak // n_r
        r_pk = (peak % n_r) - r_off
        pc = cell[alive]
        ok = good[pc]
        idx_alive = np.nonzero(alive)[0][ok]
        pc = pc[ok]
        rho = lx[idx_alive] * cos_t[t_pk[pc]] + ly[idx_alive] * sin_t[t_pk[pc]]
        member = np.abs(rho - r_pk[pc]) <= p.band_px
        if offs.size < n_t:       # pixels that voted for the peak's angle only
            dt = np.abs(t0[idx_alive] - t_pk[pc])
            member &= np.minimum(dt, n_t - dt) <= half
        mi = idx_alive[member]
        if mi.size == 0:
            break
        # withdraw their votes: only the bins they voted for change
        drop, count = np.unique(votes(mi), return_counts=True)
        bins[drop] -= count
        alive[mi] = False
        lab_cell = cell[mi]
        used_cells, lab = np.unique(lab_cell, return_inverse=True)
        m = _moments(xs[mi], ys[mi], lab, used_cells.size)
        keep = m[:, 0] >= min_votes
        c, u, _ = _moments_fit(m)
        s = _extent(xs[mi], ys[mi], lab, c, u, used_cells.size)
        mom.append(m[keep])
        segs.append(s[keep])
        cells.append(np.column_stack([used_cells % p.grid, used_cells // p.grid])[keep])
    if not mom:
        return np.zeros((0, 6)), np.zeros((0, 4)), np.zeros((0, 2), dtype=np.int64)
    return np.concatenate(mom), np.concatenate(segs), np.concatenate(cells)


def _gap(si: np.ndarray, sj: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Gap [px] between two segments' extents along direction ``u`` (0 if they overlap)."""
    ti = np.stack([(si[:, 0:2] * u).sum(1), (si[:, 2:4] * u).sum(1)], axis=1)
    tj = np.stack([(sj[:, 0:2] * u).sum(1), (sj[:, 2:4] * u).sum(1)], axis=1)
    lo_i, hi_i = ti.min(1), ti.max(1)
    lo_j, hi_j = tj.min(1), tj.max(1)
    return np.maximum(np.maximum(lo_j - hi_i, lo_i - hi_j), 0.0)


def _merge_group(mom: np.ndarray, segs: np.ndarray) -> tuple:
    """Return the merged moments and segment of a group of pieces (extent of all ends)."""
    m = mom.sum(axis=0)
    c, u, rms = _moments_fit(m)
    pts = segs.reshape(-1, 2)
    t = (pts - c) @ u
    return m, np.concatenate([c + t.min() * u, c + t.max() * u]), float(rms)


def _trace(mom: np.ndarray, segs: np.ndarray, max_gap: float, max_rms: float) -> list:
    """Greedy tracing of a chain: grow from the strongest piece while the fit stays straight."""
    free = np.ones(mom.shape[0], dtype=bool)
    out = []
    for s in np.argsort(-mom[:, 0]):
        if not free[s]:
            continue
        free[s] = False
        m, seg = mom[s].copy(), segs[s].copy()
        while True:
            cand = np.nonzero(free)[0]
            if cand.size == 0:
                break
            _, u, _ = _moments_fit(m)
            gap = _gap(np.broadcast_to(seg, (cand.size, 4)), segs[cand], u)
            mm = m + mom[cand]
            _, _, rms = _moments_fit(mm)
            ok = (gap <= max_gap) & (rms <= max_rms)
            if not np.any(ok):
                break
            k = cand[ok][np.argmin(rms[ok])]
            free[k] = False
            m, seg, _ = _merge_group(np.stack([m, mom[k]]), np.stack([seg, segs[k]]))
        out.append((m, seg))
    return out


def segmented_hough(edges: np.ndarray,
                    params: SegmentedHoughParams = SegmentedHoughParams(),
                    gradient: Optional[tuple] = None) -> ImageLines:
    """Lines of an edge image by the chapter's segmented Hough transform (§3.1.1).

    Args:
        edges: (H, W) edge image, non-zero on edge pixels (e.g. :func:`canny_edges`).
        params: see :class:`SegmentedHoughParams`.
        gradient: optional (gx, gy) (H, W) image gradients; each edge pixel then votes only
            for line angles within ``params.gradient_window_deg`` of its gradient direction
            (the full angle range without it).

    Returns:
        Segments with their supporting pixel counts as weights.
    """
    edges = np.asarray(edges)
    if edges.ndim != 2:
        raise ValueError(f'edge image must be 2-D; got shape {edges.shape}')
    h, w = edges.shape
    if params.grid < 1 or h < params.grid or w < params.grid:
        raise ValueError(f'a {params.grid} x {params.grid} grid needs an image of at least '
                         f'that many pixels per side; got {w} x {h}')
    ys, xs = np.nonzero(edges)
    if gradient is None:
        normal = np.full(xs.size, np.nan)
    else:
        gx, gy = gradient
        normal = np.arctan2(gy[ys, xs], gx[ys, xs]) % math.pi
    xs, ys = xs.astype(float), ys.astype(float)
    normal_img = None
    if gradient is not None:
        normal_img = np.full(edges.shape, np.nan)
        normal_img[ys.astype(np.int64), xs.astype(np.int64)] = normal
    mom, segs, cells = _cell_hough(xs, ys, normal, (h, w), params)
    n = mom.shape[0]
    if n == 0:
        return ImageLines(np.zeros((0, 4)), np.zeros(0))
    cw, ch = w / params.grid, h / params.grid
    max_gap = params.max_gap_px if params.max_gap_px is not None else 0.5 * min(cw, ch)
    # step 3: candidate pairs in the same or adjacent sub-images (the gap bound keeps
    # pieces further apart from joining directly; chains join them through others)
    near = ((np.abs(cells[:, None, 0] - cells[None, :, 0]) <= 1)
            & (np.abs(cells[:, None, 1] - cells[None, :, 1]) <= 1))
    i, j = np.nonzero(np.triu(near, 1))
    mom, segs = _join(mom, segs, i, j, max_gap, params.merge_rms_px)
    # tracing: each line followed along the edge image beyond its ends, then lines that
    # now meet are joined (e.g. an edge running along a sub-image border, whose pieces on
    # either side were too short to be found)
    ext, traced = _follow(segs, edges, normal_img, params)
    mom = mom + traced
    c, u, _ = _moments_fit(mom)           # refit with the traced pixels, ends on the line
    t = ((ext.reshape(-1, 2, 2) - c[:, None, :]) * u[:, None, :]).sum(-1)
    segs = np.column_stack([c + t[:, :1] * u, c + t[:, 1:] * u])
    i, j = np.triu_indices(segs.shape[0], 1)
    mom, segs = _join(mom, segs, i, j, params.trace_gap_px, params.merge_rms_px)
    d = segs[:, 2:] - segs[:, :2]
    keep = np.hypot(d[:, 0], d[:, 1]) >= params.min_length_px
    return ImageLines(segs[keep], mom[keep, 0])


def _join(mom: np.ndarray, segs: np.ndarray, i: np.ndarray, j: np.ndarray, max_gap: float,
          max_rms: float) -> tuple:
    """Join pairs (i, j) that pass the gap and straightness tests; chains are refitted."""
    n = mom.shape[0]
    mm = mom[i] + mom[j]
    _, u, rms = _moments_fit(mm)
    ok = (rms <= max_rms) & (_gap(segs[i], segs[j], u) <= max_gap)
    i, j = i[ok], j[ok]
    from scipy.sparse import coo_matrix, csgraph  # on first use: not at every node start
    graph = coo_matrix((np.ones(i.size), (i, j)), shape=(n, n))
    n_comp, label = csgraph.connected_components(graph, directed=False)
    cm = np.zeros((n_comp, 6))
    np.add.at(cm, label, mom)
    c, u, rms = _moments_fit(cm)
    pts_t = ((segs.reshape(n, 2, 2) - c[label, None, :]) * u[label, None, :]).sum(-1)
    tmin = np.full(n_comp, np.inf)
    tmax = np.full(n_comp, -np.inf)
    np.minimum.at(tmin, label, pts_t.min(1))
    np.maximum.at(tmax, label, pts_t.max(1))
    out_seg = np.column_stack([c + tmin[:, None] * u, c + tmax[:, None] * u])
    straight = rms <= max_rms
    seg_list, mom_list = [out_seg[straight]], [cm[straight]]
    for k in np.nonzero(~straight)[0]:      # bent chains: trace greedily instead
        members = np.nonzero(label == k)[0]
        for m, sg in _trace(mom[members], segs[members], max_gap, max_rms):
            seg_list.append(sg[None, :])
            mom_list.append(m[None, :])
    return np.concatenate(mom_list), np.concatenate(seg_list)


def _follow(segs: np.ndarray, edges: np.ndarray, normal_img: Optional[np.ndarray],
            params: SegmentedHoughParams) -> tuple:
    """Extend each segment along its line while edge pixels continue it.

    From each end, points at 1 px steps along the line (up to the image border) are hits
    when an edge pixel lies within ``band_px`` across the line (and, with gradients, has a
    normal within ``gradient_window_deg`` of the line's); the end moves to the last hit
    before the first run of more than ``trace_gap_px`` misses.

    Returns:
        (extended segments (S, 4), pixel moments of the traced edge pixels (S, 6)).
    """
    h, w = edges.shape
    s_n = segs.shape[0]
    if s_n == 0:
        return segs, np.zeros(0)
    reach = int(math.ceil(math.hypot(w, h)))
    gap = int(math.floor(params.trace_gap_px))
    block = 32
    d = segs[:, 2:] - segs[:, :2]
    L = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    u = d / L[:, None]
    nrm = np.column_stack([-u[:, 1], u[:, 0]])
    line_normal = np.arctan2(nrm[:, 1], nrm[:, 0]) % math.pi
    offs = np.arange(-int(params.band_px), int(params.band_px) + 1, dtype=float)
    win = math.radians(params.gradient_window_deg)
    new = segs.copy()
    extra = np.zeros((s_n, 6))

    def hits(idx: np.ndarray, origin: np.ndarray, sign: float, steps: np.ndarray):
        base = origin[idx, None, :] + sign * steps[None, :, None] * u[idx, None, :]
        pts = base[:, :, None, :] + offs[None, None, :, None] * nrm[idx, None, None, :]
        xi = np.rint(pts[..., 0]).astype(np.int64)
        yi = np.rint(pts[..., 1]).astype(np.int64)
        inside = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
        xi, yi = np.clip(xi, 0, w - 1), np.clip(yi, 0, h - 1)
        hit = inside & (edges[yi, xi] > 0)
        if normal_img is not None:
            da = np.abs(normal_img[yi, xi] - line_normal[idx, None, None])
            hit &= np.minimum(da, math.pi - da) <= win
        return hit, inside.any(axis=2), xi, yi

    for end, sign in ((1, 1.0), (0, -1.0)):
        origin = segs[:, 2:] if end == 1 else segs[:, :2]
        last = np.zeros(s_n)                 # steps [px] of the last hit so far
        active = np.arange(s_n)
        start = 1
        while active.size and start <= reach:
            # the block plus the gap steps before it, so that runs across blocks count
            steps = np.arange(max(1, start - gap), start + block, dtype=float)
            hit3, inside, xi, yi = hits(active, origin, sign, steps)
            hit = hit3.any(axis=2)
            miss = ~hit
            cs = np.concatenate([np.zeros((active.size, 1)), np.cumsum(miss, axis=1)], 1)
            run = (cs[:, gap + 1:] - cs[:, :-(gap + 1)]) >= gap + 1
            stop = run.any(axis=1) | ~inside[:, -1]
            first = np.where(run.any(axis=1), np.argmax(run, axis=1), steps.size)
            ok = hit & (np.arange(steps.size)[None, :] < first[:, None])
            ok &= steps[None, :] >= start            # the gap steps were counted before
            # moments of the traced edge pixels (each pixel once per step)
            take = hit3 & ok[:, :, None]
            take &= np.cumsum(take, axis=2) == 1
            row = np.broadcast_to(np.arange(active.size)[:, None, None], take.shape)[take]
            px, py = xi[take].astype(float), yi[take].astype(float)
            extra[active] += _moments(px, py, row, active.size)
            has = ok.any(axis=1)
            k = steps.size - 1 - np.argmax(ok[:, ::-1], axis=1)
            last[active[has]] = steps[k[has]]
            active = active[~stop]
            start += block
        pos = origin + sign * last[:, None] * u
        if end == 1:
            new[:, 2:] = pos
        else:
            new[:, :2] = pos
    return new, extra


def hough_p(edges: np.ndarray, params: HoughPParams = HoughPParams()) -> ImageLines:
    """Lines of an edge image by OpenCV's probabilistic Hough transform (reference)."""
    out = cv2.HoughLinesP(np.ascontiguousarray(edges, dtype=np.uint8), params.rho_px,
                          params.theta_rad, int(params.threshold),
                          minLineLength=params.min_length_px, maxLineGap=params.max_gap_px)
    seg = np.zeros((0, 4)) if out is None else out.reshape(-1, 4).astype(float)
    return ImageLines(seg, None)


_LSD = None


def lsd(gray: np.ndarray) -> ImageLines:
    """Lines of a grey image by OpenCV's Line Segment Detector (reference, default params)."""
    global _LSD
    if _LSD is None:
        _LSD = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD)
    out = _LSD.detect(gray)[0]
    seg = np.zeros((0, 4)) if out is None else out.reshape(-1, 4).astype(float)
    return ImageLines(seg, None)


def detect_lines(image: np.ndarray, method: str = 'segmented_hough',
                 params: LineParams = LineParams()) -> ImageLines:
    """Return the line segments of an image by one of :data:`METHODS`.

    Args:
        image: (H, W) grey or (H, W, 3|4) BGR(A) image, any integer or [0, 1] float depth.
        method: ``'segmented_hough'`` (the chapter), ``'hough_p'`` or ``'lsd'``.
        params: edge and method parameters.

    Raises:
        ValueError: unknown method or unusable image.
    """
    if method not in METHODS:
        raise ValueError(f'unknown line method {method!r}; expected one of {METHODS}')
    gray = to_gray(image)
    if method == 'lsd':
        return lsd(gray)
    if method == 'hough_p':
        return hough_p(canny_edges(gray, params.canny), params.hough_p)
    edges, grad = canny_edges(gray, params.canny, with_gradient=True)
    return segmented_hough(edges, params.segmented_hough, grad)


def undistort_segments(lines: Union[ImageLines, np.ndarray], camera: CameraModel) -> ImageLines:
    """Map segment end points from the distorted image to ideal pinhole pixels (same K)."""
    il = lines if isinstance(lines, ImageLines) else ImageLines(lines)
    if not camera.has_distortion or len(il) == 0:
        return il
    pts = camera.undistort_pixels(il.segments.reshape(-1, 2), output='ideal')
    return ImageLines(pts.reshape(-1, 4), il.weights)
