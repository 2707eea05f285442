"""Code reading of the landmark detector: cell means, threshold, decoding (chapter §2.2.3).

Step 4 of :func:`~.detector.detect_landmarks`: the cells of a :class:`~.frame_fit.FrameGrid`
are read as the landmark's code:

* :func:`sample_cells` -- the mean intensity of every half-block cell of the grid;
* :func:`read_code` -- the threshold from the frame's known black and white cells, the
  orientation from the mark and the code (:class:`CodeReading`);
* :func:`unmix_cells` and :func:`unblur_code` -- second and third readings of a code whose
  cells are too close to the threshold (extensions, ``DetectorParams.deblur_margin`` and
  ``DetectorParams.unblur_margin``).

Readings of the chapter that needed a decision (tested in
``test/test_landmark_detector.py``):

* Cells are sampled on an ``cell_samples`` x ``cell_samples`` lattice in the inner part of
  each grid cell (a border of ``cell_margin`` of the cell side left out) of the unsmoothed
  image, rather than over every pixel of the cell: at 5 pixels per block a cell is 2.5 pixels
  wide and its border pixels mix both colours.
* The grid must be consistent: every frame cell must fall on its known side of the threshold
  and every cell by at least ``min_margin`` of half the black-white contrast (more,
  ``small_block_margin``, when the corner spacing is under ``small_block_px``); otherwise the
  candidate is rejected (no detection rather than a wrong code).
* Extension (``deblur_margin``): at 4-5 px per block, blur, JPEG and tilt mix each half-block
  code cell with its neighbours, and on composites in real photographs three quarters of the
  lost landmarks at 4 px had a complete frame whose code was rejected as ambiguous. Since the
  frame around the code is known, such a grid is read a second time with the mixing
  unmixed (:func:`unmix_cells`: a 3 x 3 cell-blur model fitted on the same grid, then the
  code whiteness by least squares); its bits are used only when every code cell is clearly
  on one side (``deblur_margin``) and the model fits (``deblur_residual``).
"""

from dataclasses import dataclass
import functools
import math
from typing import Callable, Optional, Sequence, Tuple

import cv2
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np


def sample_cells(g: np.ndarray, grid: np.ndarray, samples: int = 4,
                 margin: float = 0.2) -> np.ndarray:
    """Return the mean intensity of every grid cell (§2.2.3).

    Each cell (quadrilateral of four neighbouring grid points) is sampled bilinearly on a
    ``samples`` x ``samples`` lattice spanning its inner part (``margin`` of the side left
    out at each border).

    Args:
        g: (H, W) float32 image.
        grid: (R, C, 2) grid points [px].
        samples: lattice size per side.
        margin: border fraction left out.

    Returns:
        (R - 1, C - 1) float mean intensities.
    """
    t = margin + (1.0 - 2.0 * margin) * (np.arange(samples) + 0.5) / samples
    s, u = np.meshgrid(t, t, indexing='ij')      # s: along rows, u: along columns
    s, u = s.ravel(), u.ravel()
    p00, p01 = grid[:-1, :-1], grid[:-1, 1:]
    p10, p11 = grid[1:, :-1], grid[1:, 1:]
    w00 = ((1 - s) * (1 - u))[None, None, :, None]
    w01 = ((1 - s) * u)[None, None, :, None]
    w10 = (s * (1 - u))[None, None, :, None]
    w11 = (s * u)[None, None, :, None]
    pts = (w00 * p00[:, :, None] + w01 * p01[:, :, None] + w10 * p10[:, :, None]
           + w11 * p11[:, :, None])
    r, c = pts.shape[:2]
    flat = pts.reshape(1, -1, 2).astype(np.float32)
    vals = cv2.remap(g, flat[..., 0], flat[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    return vals.reshape(r, c, samples * samples).mean(axis=2)


@functools.lru_cache(maxsize=8)
def _blur_operators(kind: str, parity: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linear maps of the cell blur model of :func:`unmix_cells` for one design and parity.

    Returns ``(known, unknown, code_index)``: ``known`` (3, I) the centre, 4-neighbour and
    diagonal-neighbour sums of the known whiteness (code cells 0) at the I grid cells,
    ``unknown`` (3, I, C) the same sums per unit whiteness of each of the C code cells.
    """
    design = LandmarkDesign(kind)
    colour = np.repeat(np.repeat(design.block_colours(), 2, axis=0), 2, axis=1)
    if parity:
        colour = np.where(colour >= 0, 1 - colour, colour)
    band = colour[1:-1, 1:-1]                      # grid cells and one cell around them
    b = band.shape[0]
    known = (band == 0).astype(float).ravel()      # whiteness: 1 white, 0 black or code
    code_index = np.flatnonzero(band.ravel() < 0)
    idx = np.arange(b * b).reshape(b, b)
    inner = idx[1:-1, 1:-1]
    ops = np.zeros((3, inner.size, b * b))
    rows = np.arange(inner.size)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            k = 0 if dy == dx == 0 else (1 if dy == 0 or dx == 0 else 2)
            ops[k, rows, idx[1 + dy:b - 1 + dy, 1 + dx:b - 1 + dx].ravel()] += 1.0
    return ops @ known, ops[:, :, code_index], code_index


def unmix_cells(cells: np.ndarray, design: LandmarkDesign, parity: int = 0,
                iterations: int = 3, with_std: bool = False) -> Optional[tuple]:
    """Read the code cells with the blur between neighbouring cells unmixed (extension).

    At 2-3 px per half-block cell, blur and JPEG mix every cell with its neighbours, and
    an isolated cell is pulled towards the threshold (the per-cell test of §2.2.3 then has
    to give up). The frame around the code is known, so the mixing can be measured on the
    same grid: each cell mean is modelled as ``y = p0 + p1 x + p2 sum(x of the 4 edge
    neighbours) + p3 sum(x of the 4 diagonal ones)`` with ``x`` the whiteness (1 white,
    0 black) of the printed cells -- known for the frame (the inner ring in the grid, the
    outer ring beside it), unknown for the code. Alternately the four ``p`` are fitted by
    least squares over all grid cells and the code whiteness solved by least squares
    given them (a linear deconvolution), starting from the per-cell threshold reading.

    Args:
        cells: the (2(n - 1), 2(n - 1)) cell means of :func:`read_code`.
        design: the landmark design.
        parity: 1 if the frame colouring is inverted (a quarter turn of the 2x2 design).
        iterations: fit/solve rounds.
        with_std: also return the standard errors of the whiteness.

    Returns:
        ``(whiteness, residual)``: the (2m, 2m) unmixed code-cell whiteness and the RMS
        misfit of the model over the contrast ``p1 + 4 p2 + 4 p3``; with ``with_std`` a third
        (2m, 2m) array, the least-squares standard error of each whiteness (the residual
        variance propagated through the unmixing, :func:`whiteness_std`); None if the
        fitted mixing is not centre-weighted (``p1`` the largest weight) or the solve
        fails.
    """
    known, unknown, _ = _blur_operators(design.kind, int(parity))
    y = np.asarray(cells, dtype=float).ravel()
    m2 = 2 * design.code_squares
    ones = np.ones_like(y)
    frame_white = known[0] > 0
    frame_black = (known[0] == 0) & (unknown[0].sum(axis=1) == 0)
    lo, hi = float(y[frame_black].mean()), float(y[frame_white].mean())
    if not hi > lo:
        return None
    x = np.clip((y[unknown[0].argmax(axis=0)] - lo) / (hi - lo), 0.0, 1.0)
    try:
        for _ in range(iterations):
            feats = np.column_stack([ones, *(known + unknown @ x)])
            p = np.linalg.lstsq(feats, y, rcond=None)[0]
            if not (p[1] > 0 and p[1] > abs(p[2]) and p[1] > abs(p[3])):
                return None
            mix = np.tensordot(p[1:], unknown, axes=1)             # (I, C)
            base = p[0] + p[1:] @ known
            x = np.linalg.lstsq(mix, y - base, rcond=None)[0]
    except np.linalg.LinAlgError:
        return None
    contrast = float(p[1] + 4.0 * p[2] + 4.0 * p[3])
    if not contrast > 0:
        return None
    res = y - base - mix @ x
    out = (x.reshape(m2, m2), float(np.sqrt(np.mean(res * res))) / contrast)
    if with_std:
        out += (whiteness_std(mix, res, 1.0).reshape(m2, m2),)
    return out


def whiteness_std(design_matrix: np.ndarray, residuals: np.ndarray, scale: float,
                  columns: slice = slice(None)) -> np.ndarray:
    """Return the standard errors of least-squares coefficients, divided by ``scale``.

    ``sqrt(diag((A^T A)^-1) RSS / (N - P))`` for the ``columns`` of the (N, P) design
    matrix ``A`` (the covariance of a linear least-squares solution); inf where the
    system is singular or has no redundancy.
    """
    a = np.asarray(design_matrix, dtype=float)
    n, p = a.shape
    if n <= p:
        return np.full(len(range(p)[columns]), np.inf)
    s2 = float(np.dot(residuals, residuals)) / (n - p)
    try:
        inv = np.linalg.inv(a.T @ a)
    except np.linalg.LinAlgError:
        return np.full(len(range(p)[columns]), np.inf)
    var = np.diag(inv)[columns] * s2
    return np.sqrt(np.maximum(var, 0.0)) / scale


def cell_self_weight(cells: np.ndarray, design: LandmarkDesign, bits: np.ndarray,
                     parity: int = 0) -> float:
    """Return the weight of a cell's own colour in its mean, measured on the grid.

    The cell means of the frame and of the code as read (``bits``, image orientation, True
    black) are fitted by the blur model of :func:`unmix_cells`, ``y = p0 + p1 x + p2 sum(x
    of the 4 edge neighbours) + p3 sum(x of the 4 diagonal ones)``; the returned
    ``p1 / (p1 + 4 p2 + 4 p3)`` is the share of the contrast that a cell takes from itself
    (1 for a sharp image on an exact grid, less with blur, small cells or a misregistered
    grid). NaN if the fit fails or the contrast is not positive.
    """
    known, unknown, _ = _blur_operators(design.kind, int(parity))
    y = np.asarray(cells, dtype=float).ravel()
    x = 1.0 - np.asarray(bits, dtype=float).ravel()
    feats = np.column_stack([np.ones_like(y), *(known + unknown @ x)])
    try:
        p = np.linalg.lstsq(feats, y, rcond=None)[0]
    except np.linalg.LinAlgError:
        return math.nan
    contrast = float(p[1] + 4.0 * p[2] + 4.0 * p[3])
    return float(p[1]) / contrast if contrast > 0 else math.nan


def _known_pattern(kind: str, parity: int, quiet: int = 2) -> np.ndarray:
    """Half-block cells of a design around its grid: 1 black, 0 white, -1 code (uint8 view).

    The frame (both rings, colours inverted with ``parity``) with ``quiet`` white cells
    around it; cell ``(r, c)`` of the code grid of :class:`FrameGrid` is entry
    ``(r + 2 + quiet, c + 2 + quiet)``.
    """
    colour = np.repeat(np.repeat(LandmarkDesign(kind).block_colours(), 2, axis=0), 2, axis=1)
    if parity:
        colour = np.where(colour >= 0, 1 - colour, colour)
    return np.pad(colour, quiet, constant_values=0)


def unblur_code(image: np.ndarray, grid: np.ndarray, design: LandmarkDesign,
                parity: int = 0, sigmas: Sequence[float] = (0.7, 1.0, 1.3, 1.6),
                supersample: int = 4, with_std: bool = False) -> Optional[tuple]:
    """Read the code cells from the pixels with a model of the printed pattern and the blur.

    Extension for 4-5 px per block, where a half-block code cell covers 2 x 2 pixels or
    less and blur, JPEG and tilt mix it with its neighbours. The frame is known, so every
    pixel around and inside the code area is modelled as the pattern mapped into the
    image by the homography of the fitted grid, averaged over the pixel (``supersample``
    x ``supersample`` points) and blurred by a Gaussian point-spread function::

        I(p) = b + d K_s(p) + sum_c y_c A_{c,s}(p)

    with ``K_s`` the blurred coverage of p by the known white cells, ``A_{c,s}`` that by
    code cell c, ``b`` the black level, ``d`` the black-white contrast and ``y_c / d`` the
    whiteness of code cell c. For each blur ``s`` of ``sigmas`` the model is linear in
    ``(b, d, y)`` and solved by least squares; the blur with the smallest residual is
    kept.

    Args:
        image: (H, W) float32 unsmoothed image.
        grid: (2n - 1, 2n - 1, 2) code grid of :class:`FrameGrid` (sub-pixel fit).
        design: the landmark design.
        parity: 1 if the frame colouring is inverted (a quarter turn of the 2x2 design).
        sigmas: point-spread standard deviations tried [px].
        supersample: sample points per pixel and axis.
        with_std: also return the standard errors of the whiteness.

    Returns:
        ``(whiteness, residual, sigma)``: the (2m, 2m) code-cell whiteness (1 white, 0
        black), the RMS misfit over the contrast and the blur chosen; with ``with_std`` a
        fourth (2m, 2m) array, the least-squares standard error of each whiteness
        (:func:`whiteness_std`); None if the patch leaves the image, the contrast is not
        positive or the solve fails.
    """
    k = grid.shape[0] - 1                               # code grid cells per side
    quiet = 2
    pattern = _known_pattern(design.kind, parity, quiet)
    off = 2 + quiet                                     # pattern index of grid cell 0
    gi, gj = np.mgrid[0:k + 1, 0:k + 1]
    src = np.column_stack([gj.ravel(), gi.ravel()]).astype(np.float64)
    hom, _ = cv2.findHomography(src, grid.reshape(-1, 2).astype(np.float64), 0)
    if hom is None:
        return None
    # pixels of the code area and one cell of frame around it, plus the blur's reach
    pad = 3.0 * max(sigmas) + 1.0
    lo, hi = grid[1:-1, 1:-1].reshape(-1, 2).min(axis=0), grid[1:-1, 1:-1].reshape(-1, 2).max(
        axis=0)
    x0, y0 = (int(math.floor(v - pad)) for v in lo)
    x1, y1 = (int(math.ceil(v + pad)) + 1 for v in hi)
    h, w = image.shape
    if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
        return None
    pw, ph = x1 - x0, y1 - y0
    s = supersample
    sub = (np.arange(s) + 0.5) / s - 0.5
    ys, xs = np.meshgrid(y0 + np.repeat(np.arange(ph), s) + np.tile(sub, ph),
                         x0 + np.repeat(np.arange(pw), s) + np.tile(sub, pw), indexing='ij')
    pts = cv2.perspectiveTransform(np.column_stack([xs.ravel(), ys.ravel()])[None],
                                   np.linalg.inv(hom))[0]
    cj = np.floor(pts[:, 0]).astype(np.int64) + off
    ci = np.floor(pts[:, 1]).astype(np.int64) + off
    n = pattern.shape[0]
    inside = (ci >= 0) & (ci < n) & (cj >= 0) & (cj < n)
    label = np.zeros(len(pts), np.int64)                 # 0 white (quiet zone beyond)
    col = pattern[np.clip(ci, 0, n - 1), np.clip(cj, 0, n - 1)]
    m2 = 2 * design.code_squares
    code = inside & (col < 0)
    label[inside & (col == 1)] = 1                       # 1 black
    label[code] = 2 + (ci[code] - off - 2) * m2 + (cj[code] - off - 2)
    # pixel of every sample point: (row // s) * pw + col // s
    pix = (np.arange(ph * s)[:, None] // s * pw + np.arange(pw * s)[None, :] // s).ravel()
    cover = np.bincount(pix * (2 + m2 * m2) + label, minlength=ph * pw * (2 + m2 * m2))
    cover = cover.reshape(ph, pw, 2 + m2 * m2).astype(np.float32) / (s * s)
    y = image[y0:y1, x0:x1].astype(np.float64).ravel()
    # fit where the pixels see the code area and the ring around it (the frame's inner
    # cells), where the model matters; the far background is not modelled
    ring = cv2.perspectiveTransform(np.array([[[1.0, 1.0], [k - 1.0, 1.0], [k - 1.0, k - 1.0],
                                               [1.0, k - 1.0]]]), hom)[0]
    mask = np.zeros((ph, pw), np.uint8)
    cv2.fillConvexPoly(mask, np.round((ring - [x0, y0]) * 16).astype(np.int32), 1,
                       lineType=cv2.LINE_8, shift=4)
    use = mask.ravel() > 0
    if use.sum() < 2 + m2 * m2 + 8:
        return None
    best = None
    for sig in sigmas:
        blurred = cv2.GaussianBlur(cover, (0, 0), sig, borderType=cv2.BORDER_REPLICATE)
        a = blurred.reshape(-1, 2 + m2 * m2)[use].astype(np.float64)
        feats = np.column_stack([np.ones(len(a)), a[:, 0], a[:, 2:]])   # b, d, y_c
        try:        # normal equations: 38 unknowns, a few hundred pixels
            coef = np.linalg.solve(feats.T @ feats, feats.T @ y[use])
        except np.linalg.LinAlgError:
            return None
        res = y[use] - feats @ coef
        rms = float(np.sqrt(np.mean(res * res)))
        if best is None or rms < best[0]:
            best = (rms, coef, sig, feats, res)
    rms, coef, sig, feats, res = best
    d = float(coef[1])
    if not d > 0:
        return None
    out = ((coef[2:] / d).reshape(m2, m2), rms / d, float(sig))
    if with_std:
        out += (whiteness_std(feats, res, d, slice(2, None)).reshape(m2, m2),)
    return out


@dataclass(frozen=True, eq=False)
class CodeReading:
    """Result of :func:`read_code` for one frame grid.

    ``method`` is how the bits were read (``'threshold'``, ``'unmixed'`` or ``'pixel'``),
    ``self_weight`` the cell self weight of a threshold reading (:func:`cell_self_weight`,
    NaN when not measured) and ``evidence`` the smallest log-likelihood ratio of a code
    cell's colour of an unmixed or pixel reading (:func:`cell_evidence`; inf otherwise).
    """

    code: Optional[int]
    rotation: int
    bits: np.ndarray
    contrast: float
    margin: float
    reason: str
    method: str = 'threshold'
    self_weight: float = math.nan
    evidence: float = math.inf


def read_code(cells: np.ndarray, design: LandmarkDesign, min_contrast: float = 20.0,
              min_margin: float = 0.2, deblur_margin: float = 0.0,
              deblur_residual: float = 0.12, block_ring: bool = False,
              unblur: Optional[Callable[[int], Optional[Tuple[np.ndarray, float, float]]]] = None,
              unblur_margin: float = 0.3, unblur_residual: float = 0.08,
              error_rate: float = 0.0) -> CodeReading:
    """Classify the cells of a frame grid and decode them (§2.2.3).

    ``cells`` covers the inner ring and the code area in half-block cells. Half of the frame
    cells are known black, half white (block ``(i, j)`` black iff ``i + j`` even); the mean
    of their two means is the threshold, below which a code cell is black (a set bit). The
    orientation mark selects the rotation and the bit order (via
    :meth:`LandmarkDesign.decode_with_rotation`). With an even number of blocks (the 2x2
    design) a quarter turn inverts the frame colouring, so both colourings are tried and
    the rotation found from the mark must have the parity the frame shows.

    Args:
        cells: (2(n - 1), 2(n - 1)) mean intensities, ``[row, col]``, row 0 along the edge
            A->B of :class:`FrameGrid` (image orientation).
        design: the landmark design.
        min_contrast: smallest white-black difference of the frame cells.
        min_margin: smallest distance from the threshold, fraction of half the contrast.
        deblur_margin: if > 0, code cells closer to the threshold than ``min_margin`` are
            read again by :func:`unmix_cells`; the unmixed bits are used when every code
            cell is at least ``deblur_margin`` from the midpoint and the blur model fits
            within ``deblur_residual`` of the contrast (the frame cells must still pass
            ``min_margin``).
        deblur_residual: see ``deblur_margin``.
        block_ring: test the frame's consistency on its blocks (the mean of each frame
            block's 2 x 2 cells) rather than on every cell.
        unblur: if given, a code still ambiguous after ``deblur_margin`` is read by
            ``unblur(parity)`` (:func:`unblur_code` on the frame's pixels); its whiteness
            is used when every code cell is at least ``unblur_margin`` from the midpoint
            and the model misfit is at most ``unblur_residual`` of the contrast.
        unblur_margin: see ``unblur``.
        unblur_residual: see ``unblur``.
        error_rate: if > 0, a code is accepted only when it is resolved: a threshold
            reading needs the cell self weight ``w`` measured on the grid
            (:func:`cell_self_weight`) above 1/2 (:func:`threshold_resolves`; otherwise the
            code is read by unmixing), an unmixed or pixel reading a log-likelihood ratio of
            every code cell's colour (:func:`cell_evidence`) of at least ``log(cells /
            error_rate)``.

    Returns:
        :class:`CodeReading`; ``code`` is None with a ``reason`` when the grid is
        inconsistent or the bits are not a valid code.
    """
    m2 = 2 * design.code_squares
    k = cells.shape[0]
    rows, cols = np.mgrid[0:k, 0:k]
    bi, bj = 1 + cols // 2, 1 + rows // 2            # block (column, row) of each cell
    colour = design.block_colours()[bj, bi]          # 1 black, 0 white, -1 code
    code_cells = cells[2:2 + m2, 2:2 + m2]
    empty = np.zeros((m2, m2), bool)
    # an even number of blocks (2x2 design) makes the frame colouring change with every
    # quarter turn: the frame cells then tell the parity of the rotation
    parities = (0, 1) if design.n_blocks % 2 == 0 else (0,)
    best = None
    for parity in parities:
        col = colour if parity == 0 else np.where(colour >= 0, 1 - colour, colour)
        black, white = cells[col == 1], cells[col == 0]
        c = float(white.mean()) - float(black.mean())
        if best is None or c > best[0]:
            best = (c, parity, black, white)
    contrast, parity, black, white = best
    col = colour if parity == 0 else np.where(colour >= 0, 1 - colour, colour)
    if not contrast >= min_contrast:
        return CodeReading(None, 0, empty, contrast, 0.0, 'low contrast')
    thr = 0.5 * (float(black.mean()) + float(white.mean()))
    half = 0.5 * contrast
    if block_ring:
        # each frame block is read as the mean of its 2 x 2 cells (extension, see
        # DetectorParams.block_ring)
        blocks = cells.reshape(k // 2, 2, k // 2, 2).mean(axis=(1, 3))
        bcol = col[::2, ::2]
        black, white = blocks[bcol == 1], blocks[bcol == 0]
    ring_margin = min(float((thr - black).min()), float((white - thr).min())) / half
    code_margin = float(np.abs(code_cells - thr).min()) / half
    margin = min(ring_margin, code_margin)
    if ring_margin < min_margin:
        return CodeReading(None, 0, empty, contrast, margin, 'frame cells inconsistent')
    bits = code_cells < thr
    method, evidence, w_self = 'threshold', math.inf, math.nan
    # smallest log-likelihood ratio that keeps the chance of any wrong cell under error_rate
    need = math.log(m2 * m2 / error_rate) if error_rate > 0 else -math.inf
    resolved = code_margin >= min_margin
    if resolved and error_rate > 0:
        # thresholding reads a cell's own colour only where it outweighs its neighbours';
        # otherwise the code is read by unmixing, with its evidence test
        w_self = cell_self_weight(cells, design, bits, parity)
        resolved = threshold_resolves(w_self)
    if not resolved:
        unmixed = unmix_cells(cells, design, parity, with_std=True) if deblur_margin > 0 \
            else None
        white = None
        if unmixed is not None and unmixed[1] <= deblur_residual:
            m = min(ring_margin, float(np.abs(unmixed[0] - 0.5).min()) * 2.0)
            e = cell_evidence(unmixed[0], unmixed[2])
            if m >= deblur_margin and e >= need:
                white, margin, method, evidence = unmixed[0], m, 'unmixed', e
        if white is None and unblur is not None:
            pixel = unblur(parity)
            if pixel is not None and pixel[1] <= unblur_residual:
                m = min(ring_margin, float(np.abs(pixel[0] - 0.5).min()) * 2.0)
                e = cell_evidence(pixel[0], pixel[3]) if len(pixel) > 3 else math.inf
                if m >= unblur_margin and e >= need:
                    white, margin, method, evidence = pixel[0], m, 'pixel', e
        if white is None:
            reason = 'ambiguous code cell' if code_margin < min_margin else \
                'code not resolved'
            return CodeReading(None, 0, bits, contrast, margin, reason, method, w_self)
        bits = white < 0.5
    got = design.decode_with_rotation(bits)
    if got is None:
        return CodeReading(None, 0, bits, contrast, margin, 'no valid code')
    code, rot = got
    if len(parities) == 2 and rot % 2 != parity:
        return CodeReading(None, 0, bits, contrast, margin, 'orientation disagrees with frame')
    return CodeReading(code, rot, np.rot90(bits, rot), contrast, margin, '', method, w_self,
                       evidence)


def threshold_resolves(self_weight: float) -> bool:
    """Return whether thresholding the cell means reads every cell's own colour.

    With the cell blur model of :func:`cell_self_weight` a cell's mean is ``w x + (1 - w)
    x_n`` of its own whiteness ``x`` and the mean whiteness ``x_n`` of its neighbours (in
    units of the contrast above black). Only for ``w > 1/2`` is every cell on the side of
    the threshold of its own colour whatever its neighbours (a black cell among white ones
    reads ``1 - w < 1/2``). For ``w <= 1/2`` the side is set by the neighbourhood: a cell of
    the other colour than its neighbours reads as theirs, with a margin up to ``1 - 2 w``
    of half the contrast, and a code read by thresholding can be another valid code at
    any margin that blur and block spacing allow. False if ``w`` is not a number.
    """
    return bool(math.isfinite(self_weight) and self_weight > 0.5)


def cell_evidence(whiteness: np.ndarray, std: np.ndarray) -> float:
    """Smallest log-likelihood ratio of a code cell's colour over the other colour.

    A cell estimated at whiteness ``x`` with Gaussian standard error ``s`` is white (1)
    rather than black (0) with log-likelihood ratio ``((x - 0)^2 - (x - 1)^2) / (2 s^2) =
    (x - 1/2) / s^2``; its magnitude is the evidence for the colour read. The chance of a
    wrong colour is about ``exp(-evidence)``; ``inf`` if ``std`` is zero.
    """
    x = np.asarray(whiteness, dtype=float)
    s2 = np.asarray(std, dtype=float) ** 2
    with np.errstate(divide='ignore', invalid='ignore'):
        llr = np.where(s2 > 0, np.abs(x - 0.5) / s2, np.inf)
    return float(np.nan_to_num(llr, nan=0.0).min())


__all__ = ['cell_evidence', 'cell_self_weight', 'CodeReading', 'read_code',
           'threshold_resolves', 'sample_cells', 'unblur_code', 'unmix_cells', 'whiteness_std']
