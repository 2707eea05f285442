"""Detection of the artificial visual landmark in a grey image (visual navigation chapter §2.2).

The four steps of §2.2, one module each:

1. :mod:`.corner_candidates` -- :func:`corner_pixels` and :func:`corner_groups`: the corner
   filters C1..C4 (eq. 1) on the 3 x 3 Gaussian-smoothed image and their 8-connected groups
   with intensity-weighted centres (eq. 2); by default (extension) :func:`saddle_corners`
   replaces them;
2. :mod:`.frame_search` -- :func:`corner_neighbours`, :func:`frame_edges` (:func:`chain_edges`)
   and :func:`find_frames`: up to eight neighbours per corner within 1/5 of the image height,
   frame edges of six collinear corners (eq. 3) and frames of four edges sharing their end
   corners (eq. 4);
3. :mod:`.frame_fit` -- :func:`fit_frame`: frame corners from line fits of the edges (eq. 5)
   and the code grid (with :func:`refine_corners` and :func:`edge_points` for sub-pixel
   accuracy);
4. :mod:`.code_reading` -- :func:`read_code`: per-cell mean intensities, the threshold from
   the frame's known black and white cells, orientation from the mark and the code
   (§2.2.3).

This module holds :class:`DetectorParams`, :class:`Detection` and :func:`detect_landmarks`,
which runs them all, and re-exports the public names of the four step modules. Pose
estimation (§2.2.4) is :mod:`.pose`.

Conventions: pixel positions are OpenCV ``(x, y)`` = (column, row), pixel centres at integer
coordinates (the chapter writes ``(r, c)``). Images are 2-D uint8 (mono8) arrays; eq. 1 runs
on the 8-bit smoothed image with OpenCV array operations (saturating arithmetic, see
:func:`~.corner_candidates._filter_pair`), everything after it on the few corner pixels
only.

Readings of the chapter that needed a decision are documented in the module of each step;
those of the whole pipeline (tested in ``test/test_landmark_detector.py``):

* Extensions for 4-5 px per block at strong tilt (``max_gaps``, ``refine_grid``,
  ``block_ring``, ``unblur_margin``): the corner filters miss single frame X-corners
  there, so an edge chain may bridge one missed interior corner at its eq. 3 prediction
  (:func:`chain_edges`); a grid that fails to read is read again after the sub-pixel
  refinement; the frame ring is checked per block rather than per half-block cell; and a
  code that is still ambiguous is read from the pixels with a model of the printed
  pattern and the blur (:func:`unblur_code`).
* Fast mode (``decimate``): the corner filters and groups run on the image averaged over
  2 x 2 pixels, everything after them on the full image.
"""

from dataclasses import dataclass, field
import functools
import math
import time
from typing import Callable, List, Optional, Tuple

import cv2
from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.code_reading import (CodeReading, read_code, sample_cells,
                                              unblur_code, unmix_cells)
from landmark_nav.vision.corner_candidates import (corner_groups, corner_pixels, Corners,
                                                   saddle_corners, smooth)
from landmark_nav.vision.frame_fit import (_Shifted, edge_points, fit_frame, FrameGrid,
                                           refine_corners)
from landmark_nav.vision.frame_search import (chain_edges, corner_neighbours, find_frames,
                                              frame_edges)
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np


@dataclass(frozen=True)
class DetectorParams:
    """Parameters of the landmark detector (chapter §2.2 values by default).

    Attributes:
        kind: landmark design, ``'3x3'`` (six corners per edge) or ``'2x2'`` (five).
        sigma: standard deviation of the 3 x 3 Gaussian [px] (§2.2.1: 0.95).
        k_min: fixed part of the corner threshold k_c [integer grey levels of 256] (eq. 1:
            7).
        axial_offset: row/column offset of the C1/C2 samples [px] (eq. 1: 2).
        diagonal_offset: offset of the 45-degree C3/C4 samples [px] (see
            :mod:`.corner_candidates`).
        merge_distance: corner groups of different filters closer than this are one corner
            [px].
        neighbour_fraction: neighbour search radius as a fraction of the image height
            (§2.2.2: 1/5).
        max_neighbours: neighbours kept per corner (§2.2.2: 8).
        neighbour_mode: ``'closest'`` (the chapter: the closest corners) or ``'sectors'``
            (the closest corner in each of ``max_neighbours`` direction sectors), see
            :func:`corner_neighbours`.
        k_lim: eq. 3 tolerance of a predicted corner, fraction of the spacing (0.37).
        k_g: eq. 3 gain of the spacing update (0.5).
        k_p: eq. 4 tolerance on opposite edges being parallel and equal (0.5).
        cell_samples: samples per side of each code-grid cell.
        cell_margin: fraction of the cell side left out at each border when sampling.
        min_contrast: smallest mean white minus mean black frame cell [grey levels].
        min_margin: smallest distance of any cell from the threshold, as a fraction of half
            the black-white contrast.
        small_block_px: frames whose smallest corner spacing is below this [px] (code cells
            under half of it) are read only with ``small_block_margin``.
        small_block_margin: the ``min_margin`` for such small frames: blur mixes cells of
            two pixels or less, and reads that would be wrong come with margins below 0.21
            (simulated views at 3-4.5 px per block), so twice that is required. On
            composites in real photographs wrong reads with margins 0.22-0.25 came from
            frames with 4.5-5 px spacing (2 of 300 trials at 4-6 px per block, seeds
            11-14), hence ``small_block_px`` 6.5: the unmixed and pixel readings then
            decide such codes (2 more detections, no wrong code in those 300 trials).
        max_corners: images with more corner groups than this are searched with the
            strongest ones only (bounded time on noise).
        refine_corners: refine the eq. 2 centres of a frame's corners with OpenCV's
            saddle-point refinement (``cv2.cornerSubPix``) before the line fits.
        refine_window: window half-size of the refinement as a fraction of the corner
            spacing (at most 8 px; no refinement below 2 px).
        refine_edges: fit each edge line (eq. 5) to sub-pixel points of the ring boundary
            along the edge rather than to its corners only, and move the interior corners
            of each edge to the crossings of the block boundaries with its line.
        deblur_margin: a grid whose cells are too close to the threshold is read again
            with the cell blur unmixed (:func:`unmix_cells`); its bits are accepted when
            every unmixed code cell is at least this far from the black/white midpoint
            (fraction of half the contrast; 0 turns the second reading off). Composites in
            real photographs at 3-5 px per block: wrong reads had unmixed margins of at
            most 0.01, correct ones 0.31 or more in 95 % of the cases.
        second_neighbour_angle: in ``'sectors'`` mode also keep the second nearest corner of
            a sector when its direction differs from the nearest one's by more than this
            [deg] (0: off). Seen at 60 degrees tilt, the two edges at a frame corner can
            be closer than 45 degrees in the image, and the foreshortened edge's corner
            then hides the other edge's (composites at 60 degrees: 8 px 0.96 -> 1.00, 12 px
            0.90 -> 1.00 of 50 each, 16 % more time).
        deblur_residual: largest RMS misfit of the blur model to the cells, fraction of
            the contrast (correct reads: at most 0.085).
        max_gaps: missed interior corners an edge chain may bridge (:func:`chain_edges`;
            0: the chapter's eq. 3).
        refine_grid: a frame whose grid reads as inconsistent, ambiguous or not a valid
            code is read once more on the grid of the sub-pixel frame fit (the steps of
            ``refine_corners`` / ``refine_edges``).
        block_ring: judge the frame's consistency on the means of its blocks (2 x 2 cells)
            instead of on single half-block cells; the threshold is the same. At 4-5 px
            per block the half-block frame cells beside the code carry up to 0.6 of half
            the contrast of JPEG ringing and neighbour blur on composites in real
            photographs, and most frames lost at 5 px with all their corners found were
            rejected as inconsistent there.
        decimate: fast mode (like AprilTag's ``quad_decimate``): with 2 the corner
            filters and groups (eq. 1-2) run on the image averaged over 2 x 2 pixels, the
            chains, frames, code and sub-pixel steps on the full image; a landmark then
            needs twice the pixels per block (1: off).
        unblur_margin: a code still ambiguous after ``deblur_margin`` (on the refined grid)
            is read from the pixels by :func:`unblur_code`; its bits are accepted when every
            code cell is at least this far from the black/white midpoint (fraction of half
            the contrast; 1 turns it off). Composites in real photographs at 4-5 px per
            block: all 18 such codes read correctly, cell margins 0.09-0.77.
        unblur_residual: largest RMS misfit of the pixel model, fraction of the contrast
            (those 18: at most 0.049).
        unblur_small_px: frames whose mean corner spacing is below this [px] need
            ``unblur_small_margin`` (at least) for a pixel reading.
        unblur_small_margin: the ``unblur_margin`` of such small frames (1: no pixel
            reading). Below 3.25 px the code cells are under 1.6 px and the pixel model
            needs the grid to a fraction of that: the only two wrong pixel reads seen were
            at 3.0 px spacing (composites in real photographs, seeds 1-3, margin 0.31;
            simulated Table 2 views at 3 px, margin 0.45), while the right ones at 4-5 px
            per block all had spacings of 3.26 px or more.
        corner_method: ``'saddle'`` (extension, default): corner candidates are the strong
            saddle points of G (:func:`saddle_corners`); ``'eq1'``: the chapter's corner
            filters and groups (eq. 1-2, :func:`corner_pixels`, :func:`corner_groups`;
            ``k_min``, ``axial_offset``, ``diagonal_offset`` and ``merge_distance`` apply
            to it only). Composites in real photographs, seed 1, 100 per size: 3 / 4 / 5
            px per block 0.38 / 0.82 / 0.95 instead of 0.09 / 0.64 / 0.77, 0 of 1020
            landmark-free frames, 9.2 instead of 16.8 ms per frame.
        saddle_threshold: smallest saddle strength of :func:`saddle_corners` (3 x 3 Sobel
            units; frame X-corners on the composites at 4 px: median 8000, 5th
            percentile 1070).
        saddle_kappa: weight of the squared Hessian trace subtracted from the strength
            (suppresses weak saddles along strong edges; 0.1: spurious candidates within
            5 px of a frame corner at 12 px per block 1.1 instead of 9.7 per frame).
        decode_error_rate: a code is published only when it is resolved at the frame's
            blur and block spacing (``error_rate`` of :func:`read_code`): a threshold
            reading needs a margin above what the neighbour cells' blur can give a cell of
            the other colour (``1 - 2 w``, ``w`` the cell self weight measured on the grid),
            an unmixed or pixel reading a log-likelihood ratio of every code cell's colour
            of at least ``log(36 / decode_error_rate)`` (about this chance of a wrong cell
            per code). 0 turns the check off. Composites in real photographs at 3 px per
            block had 5 wrong codes in 1800 trials without it (margins 0.32-0.55, spacing
            3.07-3.27 px). At 0.001 correct unmixed or pixel readings at 4 px per block and
            30-60 degrees tilt were lost (evidence 7.4-9.9; the wrong ones seen had 1.2 and
            4.8), hence 0.01.
    """

    kind: str = '3x3'
    sigma: float = 0.95
    k_min: int = 7
    axial_offset: int = 2
    diagonal_offset: int = 3
    merge_distance: float = 1.5
    neighbour_fraction: float = 0.2
    max_neighbours: int = 8
    neighbour_mode: str = 'sectors'
    k_lim: float = 0.37
    k_g: float = 0.5
    k_p: float = 0.5
    cell_samples: int = 4
    cell_margin: float = 0.2
    min_contrast: float = 20.0
    min_margin: float = 0.2
    small_block_px: float = 6.5
    small_block_margin: float = 0.4
    max_corners: int = 4000
    refine_corners: bool = True
    refine_window: float = 0.45
    refine_edges: bool = True
    deblur_margin: float = 0.35
    deblur_residual: float = 0.12
    second_neighbour_angle: float = 20.0
    max_gaps: int = 1
    refine_grid: bool = True
    block_ring: bool = True
    decimate: int = 1
    unblur_margin: float = 0.3
    unblur_residual: float = 0.08
    unblur_small_px: float = 3.25
    unblur_small_margin: float = 1.0
    corner_method: str = 'saddle'
    saddle_threshold: float = 1000.0
    saddle_kappa: float = 0.1
    decode_error_rate: float = 0.01

    def __post_init__(self) -> None:
        """Validate the values (ValueError naming the field)."""
        if self.kind not in ('3x3', '2x2'):
            raise ValueError(f"kind must be '3x3' or '2x2'; got {self.kind!r}")
        if self.corner_method not in ('eq1', 'saddle'):
            raise ValueError(f"corner_method must be 'eq1' or 'saddle'; got "
                             f'{self.corner_method!r}')
        if self.neighbour_mode not in ('closest', 'sectors'):
            raise ValueError(f"neighbour_mode must be 'closest' or 'sectors'; got "
                             f'{self.neighbour_mode!r}')
        checks = {
            'sigma': (0.1, 5.0), 'k_min': (0, 255), 'axial_offset': (1, 10),
            'diagonal_offset': (1, 10), 'merge_distance': (0.0, 10.0),
            'neighbour_fraction': (0.01, 1.0), 'max_neighbours': (2, 32),
            'k_lim': (0.01, 1.0), 'k_g': (0.0, 1.0), 'k_p': (0.01, 2.0),
            'cell_samples': (1, 16), 'cell_margin': (0.0, 0.45), 'min_contrast': (0.0, 255.0),
            'min_margin': (0.0, 1.0), 'max_corners': (10, 10 ** 6),
            'small_block_px': (0.0, 100.0), 'small_block_margin': (0.0, 1.0),
            'refine_window': (0.1, 0.5), 'deblur_margin': (0.0, 1.0),
            'deblur_residual': (0.0, 1.0), 'second_neighbour_angle': (0.0, 45.0),
            'max_gaps': (0, 2), 'decimate': (1, 4), 'unblur_margin': (0.0, 1.0),
            'unblur_residual': (0.0, 1.0), 'saddle_threshold': (0.0, 1e6),
            'unblur_small_px': (0.0, 100.0), 'unblur_small_margin': (0.0, 1.0),
            'saddle_kappa': (0.0, 1.0), 'decode_error_rate': (0.0, 0.5)}
        for name, (lo, hi) in checks.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) \
                    or not math.isfinite(v) or not lo <= v <= hi:
                raise ValueError(f'{name} = {v!r} must be a number in [{lo}, {hi}]')
            if isinstance(lo, int) and not isinstance(v, int):
                raise ValueError(f'{name} = {v!r} must be an integer')
        for name in ('refine_corners', 'refine_edges', 'refine_grid', 'block_ring'):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f'{name} = {getattr(self, name)!r} must be a bool')

    @property
    def design(self) -> LandmarkDesign:
        """The landmark design of ``kind`` (frame width does not matter to the detector)."""
        return LandmarkDesign(kind=self.kind)


@dataclass(frozen=True, eq=False)
class Detection:
    """One decoded landmark.

    Attributes:
        code: the decoded code (valid for the design).
        kind: ``'3x3'`` or ``'2x2'``.
        corners: (4, 2) frame corners h'_1..h'_4 [px] (eq. 5) in the order of
            :meth:`LandmarkDesign.frame_corners`: top-left, top-right, bottom-right,
            bottom-left of the upright landmark.
        edge_corners: (4, n, 2) the detected X-corner centres (eq. 2) of each edge [px], edge
            ``e`` running from ``corners[e]`` to ``corners[(e + 1) % 4]`` as in
            :meth:`LandmarkDesign.edge_corner_grid` (n = 6 or 5).
        rotation: quarter turns ``k`` with ``np.rot90(image_bits, k)`` upright.
        contrast: mean white minus mean black frame cell [grey levels].
        margin: smallest distance of a cell from the threshold over half the contrast
            (1 = every cell as far from the threshold as the mean colours; the detector
            rejects below ``min_margin``).
        line_rms: RMS distance of the edge corners from their fitted lines [px].
        block_pixels: mean frame-edge corner spacing [px] (the chapter's "block pixels").
        bits: (2m, 2m) upright code-area bits, True = black.
    """

    code: int
    kind: str
    corners: np.ndarray
    edge_corners: np.ndarray
    rotation: int
    contrast: float
    margin: float
    line_rms: float
    block_pixels: float
    bits: np.ndarray = field(repr=False)


# ---------------------------------------------------------------------- all steps


def image_problem(gray: np.ndarray, min_contrast: float = 20.0,
                  saturated_fraction: float = 0.5) -> Tuple[str, bool]:
    """Describe what is wrong with an image for landmark detection, if anything.

    Args:
        gray: (H, W) uint8 image.
        min_contrast: an image whose grey levels span less than this has no usable content.
        saturated_fraction: an image with more than this fraction of pixels at 255 (or 0)
            is reported as over- (under-) exposed.

    Returns:
        ``(problem, usable)``: ``('', True)`` for a good image; an all-black, all-white or
        flat image gives ``(description, False)``; a saturated one ``(description, True)``
        (it may still show a landmark).
    """
    img = np.asarray(gray)
    if img.size == 0:
        return 'empty image', False
    lo, hi = (float(v) for v in cv2.minMaxLoc(img)[:2])
    if hi - lo < min_contrast:
        return (f'image has no contrast (grey levels {lo:.0f}..{hi:.0f}): all black, all '
                'white or a covered lens?', False)
    n = float(img.size)
    white = np.count_nonzero(img >= 255) / n
    black = np.count_nonzero(img <= 0) / n
    if white > saturated_fraction:
        return f'image is overexposed: {100 * white:.0f} % of the pixels saturated', True
    if black > saturated_fraction:
        return f'image is underexposed: {100 * black:.0f} % of the pixels black', True
    return '', True


def _unblur(raw: np.ndarray, grid: np.ndarray, design: LandmarkDesign,
            params: DetectorParams
            ) -> Optional[Callable[[int], Optional[Tuple[np.ndarray, float, float]]]]:
    """Return the :func:`unblur_code` reader of a grid for :func:`read_code` (or None)."""
    if params.unblur_margin >= 1.0:
        return None
    return functools.partial(unblur_code, raw, grid, design, with_std=True)


#: read failures worth a second reading on the refined grid (``refine_grid``)
_REREAD = ('frame cells inconsistent', 'ambiguous code cell', 'no valid code',
           'code not resolved')


def _refined_frame(raw: np.ndarray, pts: np.ndarray, frame: np.ndarray,
                   params: DetectorParams, camera: Optional[CameraModel],
                   grid: bool = False) -> FrameGrid:
    """Fit a frame again after the sub-pixel steps, on float G of the frame's surroundings.

    With ``grid`` False the code grid is not rebuilt (the code has been read); ``grid``
    holds the corners.
    """
    ids = np.unique(frame)
    spacing = float(np.median(np.linalg.norm(np.diff(pts[frame], axis=1), axis=2)))
    reach = 1.5 * float(np.max(np.linalg.norm(np.diff(pts[frame], axis=1), axis=2))) + 4.0
    h, w = raw.shape
    x0 = max(0, int(pts[ids, 0].min() - reach))
    y0 = max(0, int(pts[ids, 1].min() - reach))
    x1 = min(w, int(pts[ids, 0].max() + reach) + 1)
    y1 = min(h, int(pts[ids, 1].max() + reach) + 1)
    off = np.array([x0, y0], dtype=float)
    g = smooth(raw[y0:y1, x0:x1], params.sigma)     # float G for the sub-pixel steps
    local = pts - off
    if params.refine_corners:
        local = local.copy()
        local[ids] = refine_corners(g, local[ids], spacing, params.refine_window)
    if camera is None:
        fine = fit_frame(local, frame, None, g if params.refine_edges else None,
                         params.min_contrast, grid=grid)
        return FrameGrid(fine.corners + off, fine.edge_corners + off, fine.grid + off,
                         fine.line_rms)
    # with a lens model the fit needs pixels of the whole image
    fpts = pts.copy()
    fpts[ids] = local[ids] + off
    return fit_frame(fpts, frame, camera, _Shifted(g, off) if params.refine_edges else None,
                     params.min_contrast, grid=grid)


class _StageClock:
    """CPU time of the steps of :func:`detect_landmarks` into ``debug['stage_ms']``."""

    def __init__(self, debug: Optional[dict]) -> None:
        self.out = None if debug is None else debug.setdefault('stage_ms', {})
        self.t = time.process_time() if self.out is not None else 0.0

    def mark(self, stage: str) -> None:
        """Book the time since the previous mark to ``stage``."""
        if self.out is not None:
            t = time.process_time()
            self.out[stage] = 1e3 * (t - self.t)
            self.t = t


def _grid_inside(grid: np.ndarray, width: int, height: int) -> bool:
    """Return whether every grid point is finite and inside the image."""
    if not np.all(np.isfinite(grid)):
        return False
    gx, gy = grid[..., 0], grid[..., 1]
    return bool(gx.min() >= 0 and gy.min() >= 0 and gx.max() <= width - 1
                and gy.max() <= height - 1)


def detect_landmarks(gray: np.ndarray, params: DetectorParams = DetectorParams(),
                     camera: Optional[CameraModel] = None,
                     debug: Optional[dict] = None) -> List[Detection]:
    """Detect and decode every landmark in a grey image (§2.2.1-2.2.3).

    Args:
        gray: (H, W) uint8 image (mono8); other numeric dtypes are used as grey levels of 256.
        params: detector parameters.
        camera: optional camera model; with a lens that distorts, the edge line fits (eq. 5)
            are made on undistorted corner positions (see :func:`fit_frame`).
        debug: if a dict, filled with the intermediate results (``corners``, ``edges``,
            ``frames``, ``grids``, ``readings``) and ``stage_ms``, the CPU time of this
            process per step [ms]: ``corners`` (smoothing and candidates), ``neighbours``
            (with the k-d tree), ``chains``, ``frames``, ``codes`` (fits and readings).

    Returns:
        The detections, strongest (largest margin) first; overlapping detections (sharing
        corners) are reduced to the best one.

    Raises:
        ValueError: ``gray`` is not a 2-D array.
    """
    img = np.asarray(gray)
    if img.ndim != 2:
        raise ValueError(f'detect_landmarks needs a 2-D grey image; got shape {img.shape}')
    clock = _StageClock(debug)
    design = params.design
    n = design.corners_per_edge
    if img.dtype != np.uint8:
        img = np.clip(np.nan_to_num(img.astype(np.float64)), 0, 255).astype(np.uint8)
    if params.decimate > 1:
        # fast mode: corners (eq. 1-2) on the image averaged over f x f pixel blocks, their
        # centres mapped to full-resolution pixels (block of f pixels -> centre f i + (f-1)/2);
        # everything after the corners runs on the full-resolution image
        f = params.decimate
        small = cv2.resize(img, (img.shape[1] // f, img.shape[0] // f),
                           interpolation=cv2.INTER_AREA)
        g8 = smooth(small, params.sigma)
    else:
        g8 = smooth(img, params.sigma)
    if params.corner_method == 'saddle':
        # in fast mode a feature's second derivatives per (decimated) pixel are up to
        # decimate^2 larger and the averaged noise smaller: the threshold scales with
        # decimate^2 (composites at 8 px per block, 50 trials: every frame X-corner found
        # at 1000 x 4 as at 1000, with a quarter of the candidates)
        corners = saddle_corners(g8, params.saddle_threshold * params.decimate ** 2,
                                 params.saddle_kappa)
    else:
        pixels = corner_pixels(g8, params.k_min, params.axial_offset, params.diagonal_offset)
        corners = corner_groups(pixels, params.merge_distance)
    if params.decimate > 1:
        corners = Corners(corners.points * f + 0.5 * (f - 1), corners.weights,
                          corners.filters)
    clock.mark('corners')
    pts, filt = corners.points, corners.filters
    if len(pts) > params.max_corners:
        keep = np.argsort(corners.weights)[::-1][:params.max_corners]
        pts, filt = pts[keep], filt[keep]
    from scipy.spatial import cKDTree  # on first use: scipy.spatial costs ~0.5 CPU-s
    tree = cKDTree(pts) if len(pts) else None
    nbrs = corner_neighbours(pts, params.neighbour_fraction * img.shape[0],
                             params.max_neighbours, tree, params.neighbour_mode,
                             math.radians(params.second_neighbour_angle))
    clock.mark('neighbours')
    edges, virtual = chain_edges(pts, nbrs, n, params.k_lim, params.k_g, tree, filt,
                                 params.max_gaps)
    clock.mark('chains')
    if debug is not None:
        debug.update(corners=corners, points=pts, virtual=virtual)
    if len(virtual):
        pts = np.vstack([pts, virtual])
    frames = find_frames(pts, edges, params.k_p)
    clock.mark('frames')
    if debug is not None:
        debug.update(edges=edges, frames=frames, grids=[], readings=[])
    found = []
    h, w = img.shape
    use_camera = camera if camera is not None and camera.has_distortion else None
    raw = img.astype(np.float32) if frames else None
    for frame in frames:
        # eq. 5 on the eq. 2 centres, cells and code; only a frame that reads as a valid code
        # is refined and fitted again (most candidates in clutter are rejected here)
        fg = fit_frame(pts, frame, use_camera)
        if not _grid_inside(fg.grid, w, h):
            continue
        cells = sample_cells(raw, fg.grid, params.cell_samples, params.cell_margin)
        spacings = np.linalg.norm(np.diff(fg.edge_corners, axis=1), axis=2)
        smallest = float(np.min(spacings))
        unblur_margin = params.unblur_margin if float(np.mean(spacings)) >= \
            params.unblur_small_px else max(params.unblur_margin, params.unblur_small_margin)
        margin = params.min_margin if smallest >= params.small_block_px else \
            max(params.min_margin, params.small_block_margin)
        reading = read_code(cells, design, params.min_contrast, margin, params.deblur_margin,
                            params.deblur_residual, params.block_ring,
                            error_rate=params.decode_error_rate)
        if reading.code is None and params.refine_grid and reading.reason in _REREAD:
            # extension: read again on the grid of the sub-pixel frame fit (see the module
            # docstring); at 4-5 px per block the eq. 2 centres and bridged corners are
            # tenths of a cell off, and the inner cell samples reach the neighbour cells
            fine = _refined_frame(raw, pts, frame, params, use_camera, grid=True)
            if _grid_inside(fine.grid, w, h):
                fg = fine
                cells = sample_cells(raw, fg.grid, params.cell_samples, params.cell_margin)
                reading = read_code(cells, design, params.min_contrast, margin,
                                    params.deblur_margin, params.deblur_residual,
                                    params.block_ring, _unblur(raw, fg.grid, design, params),
                                    unblur_margin, params.unblur_residual,
                                    params.decode_error_rate)
        if debug is not None:
            debug['grids'].append(fg)
            debug['readings'].append(reading)
        if reading.code is None:
            continue
        if params.refine_corners or params.refine_edges:
            fine = _refined_frame(raw, pts, frame, params, use_camera)
            if _grid_inside(fine.corners, w, h):
                fg = fine
        # image order A, B, C, D is the upright order rolled by the rotation
        order = [(i + reading.rotation) % 4 for i in range(4)]
        edge_corners = fg.edge_corners[order]
        spacing = np.linalg.norm(np.diff(fg.edge_corners, axis=1), axis=2).mean()
        found.append((frame, Detection(
            code=reading.code, kind=design.kind, corners=fg.corners[order],
            edge_corners=edge_corners, rotation=reading.rotation,
            contrast=reading.contrast, margin=reading.margin, line_rms=fg.line_rms,
            block_pixels=float(spacing), bits=reading.bits)))
    clock.mark('codes')
    found.sort(key=lambda fd: -fd[1].margin)
    out, used = [], set()
    for frame, det in found:
        ids = set(frame.ravel().tolist())
        if ids & used:
            continue
        used |= ids
        out.append(det)
    return out


__all__ = ['CodeReading', 'Corners', 'Detection', 'DetectorParams', 'FrameGrid',
           'chain_edges', 'corner_groups', 'corner_neighbours', 'corner_pixels',
           'detect_landmarks', 'edge_points', 'find_frames', 'fit_frame', 'frame_edges',
           'image_problem', 'read_code', 'refine_corners', 'saddle_corners', 'sample_cells',
           'smooth', 'unblur_code', 'unmix_cells']
