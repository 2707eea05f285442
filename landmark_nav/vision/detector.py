"""Detection of the artificial visual landmark in a grey image (visual navigation chapter §2.2).

The four steps of §2.2, one function each:

1. :func:`corner_pixels` and :func:`corner_groups` -- the corner filters C1..C4 (eq. 1) on
   the 3 x 3 Gaussian-smoothed image and their 8-connected groups with intensity-weighted
   centres (eq. 2); by default (extension, see below) :func:`saddle_corners` replaces them;
2. :func:`corner_neighbours`, :func:`frame_edges` and :func:`find_frames` -- up to eight
   neighbours per corner within 1/5 of the image height, frame edges of six collinear
   corners (eq. 3) and frames of four edges sharing their end corners (eq. 4);
3. :func:`fit_frame` -- frame corners from line fits of the edges (eq. 5) and the code grid
   (with :func:`refine_corners` and :func:`edge_points` for sub-pixel accuracy);
4. :func:`read_code` -- per-cell mean intensities, the threshold from the frame's known black
   and white cells, orientation from the mark and the code (§2.2.3).

:func:`detect_landmarks` runs them all. Pose estimation (§2.2.4) is :mod:`.pose`.

Conventions: pixel positions are OpenCV ``(x, y)`` = (column, row), pixel centres at integer
coordinates (the chapter writes ``(r, c)``). Images are 2-D uint8 (mono8) arrays; eq. 1 runs
on the 8-bit smoothed image with OpenCV array operations (saturating arithmetic, see
:func:`_filter_pair`), everything after it on the few corner pixels only.

Readings of the chapter that needed a decision (documented here, tested in
``test/test_landmark_detector.py``):

* The 45-degree filter set (C3, C4) samples the smoothed image at ``(r -+ d, c)`` and
  ``(r, c -+ d)`` with ``d = diagonal_offset = 3`` pixels, the axial neighbours closest to the
  ``2 sqrt 2`` distance of the C1/C2 samples that keep the one-pixel guard band between the
  four 3 x 3 areas. C3 is bright above and below, C4 bright left and right.
* Groups of different filters (C1 and C3 respond both at 22.5 degrees) whose centres are
  closer than ``merge_distance`` are merged into one corner with the eq. 2 centre of their
  union, so that a corner is not listed twice among a neighbour's eight.
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
* Sub-pixel accuracy (after a frame has been read as a valid code): the eq. 2 centres carry
  errors of 0.1-0.3 px that depend on the sub-pixel phase, the same in every frame, and at
  2.2 m a landmark seen head-on turns by about a degree per 0.05 px of corner error. So the
  frame's corners are refined by OpenCV's saddle-point refinement (``cv2.cornerSubPix`` on
  G, window 0.45 of the corner spacing, ``refine_corners``), and each edge line of eq. 5 is
  fitted to sub-pixel points of the straight ring boundary along the edge
  (:func:`edge_points`, ``refine_edges``) instead of to its six corners only; the interior
  corners of an edge are then placed where the block boundaries across the ring cross the
  edge line (:func:`_edge_crossings`). On simulated views the frame corners are then within
  0.04 px RMS (0.12 px with eq. 2 alone); rendered with 16 x 16 samples per pixel, the
  mean over noisy frames of an interior corner is within 0.01 px of the truth (0.05 px
  with the saddle-point refinement alone) and its spread is 0.007 px (0.012 px).
* With a camera model the line fits (eq. 5) are made on undistorted positions: the printed
  edges are straight only in the ideal image.
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
* Extensions for 4-5 px per block at strong tilt (``max_gaps``, ``refine_grid``,
  ``block_ring``, ``unblur_margin``): the corner filters miss single frame X-corners
  there, so an edge chain may bridge one missed interior corner at its eq. 3 prediction
  (:func:`chain_edges`); a grid that fails to read is read again after the sub-pixel
  refinement; the frame ring is checked per block rather than per half-block cell; and a
  code that is still ambiguous is read from the pixels with a model of the printed
  pattern and the blur (:func:`unblur_code`).
* Fast mode (``decimate``): the corner filters and groups run on the image averaged over
  2 x 2 pixels, everything after them on the full image.
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

from dataclasses import dataclass, field
import functools
import math
from typing import Callable, List, Optional, Sequence, Tuple

import cv2
from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class DetectorParams:
    """Parameters of the landmark detector (chapter §2.2 values by default).

    Attributes:
        kind: landmark design, ``'3x3'`` (six corners per edge) or ``'2x2'`` (five).
        sigma: standard deviation of the 3 x 3 Gaussian [px] (§2.2.1: 0.95).
        k_min: fixed part of the corner threshold k_c [integer grey levels of 256] (eq. 1:
            7).
        axial_offset: row/column offset of the C1/C2 samples [px] (eq. 1: 2).
        diagonal_offset: offset of the 45-degree C3/C4 samples [px] (see module docstring).
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
            'saddle_kappa': (0.0, 1.0)}
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


# ---------------------------------------------------------------------- 2.2.1 corners


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
    graph = coo_matrix((np.ones(len(src), np.int8), (src, dst)), shape=(n, n))
    count, lab = connected_components(graph, directed=False)
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
    s = np.zeros(h * w)
    s[idx] = strength
    sel = np.flatnonzero(strength > threshold)
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
        pairs = cKDTree(pts).query_pairs(radius, output_type='ndarray')
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


# ---------------------------------------------------------------------- 2.2.2 frames


def corner_neighbours(points: np.ndarray, max_distance: float, k: int = 8,
                      tree: Optional[cKDTree] = None, mode: str = 'closest',
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
    tree = cKDTree(points) if tree is None else tree
    kk = min((k if mode == 'closest' else 3 * k) + 1, n)
    dist, idx = tree.query(points, k=kk, distance_upper_bound=max_distance)
    idx = np.asarray(idx).reshape(n, kk)[:, 1:]  # drop the corner itself (distance 0)
    if mode == 'closest':
        if idx.shape[1] < k:
            idx = np.hstack([idx, np.full((n, k - idx.shape[1]), n)])
        return idx.astype(np.int64)
    valid = idx < n
    ext = np.vstack([points, [[0.0, 0.0]]])
    d = ext[np.where(valid, idx, n)] - points[:, None, :]
    ang = np.arctan2(d[..., 1], d[..., 0])
    sector = np.floor((ang + math.pi) / (2 * math.pi) * k)
    sector = np.where(valid, np.clip(sector.astype(np.int64), 0, k - 1), k)   # k: none
    rows = np.arange(n)
    cols = idx.shape[1]
    out = np.full((n, k), n, dtype=np.int64)
    extra = np.full((n, k), n, dtype=np.int64) if second_angle > 0 else None
    # the columns of a row are in order of distance: the first column of a sector is its
    # nearest corner, the next one of the same sector its second nearest
    for s in range(k):
        in_s = sector == s
        first = np.argmax(in_s, axis=1)
        has = in_s[rows, first]
        out[has, s] = idx[rows[has], first[has]]
        if extra is None:
            continue
        # extension: also the second nearest corner of a sector when its direction differs
        # from the nearest one's by more than second_angle (two frame edges seen at an
        # acute angle share a sector)
        later = in_s & (np.arange(cols)[None, :] > first[:, None])
        second = np.argmax(later, axis=1)
        has2 = later[rows, second]
        da = np.abs((ang[rows, second] - ang[rows, first] + math.pi) % (2 * math.pi) - math.pi)
        has2 &= da > second_angle
        extra[has2, s] = idx[rows[has2], second[has2]]
    if extra is not None:
        out = np.hstack([out, extra])
    return out.astype(np.int64)


def frame_edges(points: np.ndarray, neighbours: np.ndarray, n_corners: int = 6,
                k_lim: float = 0.37, k_g: float = 0.5, tree: Optional[cKDTree] = None,
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
                k_lim: float = 0.37, k_g: float = 0.5, tree: Optional[cKDTree] = None,
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
    tree = cKDTree(points) if tree is None else tree
    h2 = neighbours.ravel()
    h1 = np.repeat(np.arange(n), neighbours.shape[1])
    ok = h2 < n
    if filters is not None:
        f = np.append(np.asarray(filters), -1)
        ok &= f[h1] != f[np.minimum(h2, n)]
    chain = [h1[ok], h2[ok]]
    pos = points[chain[1]]
    v = pos - points[chain[0]]                                    # v_2 = h_2 - h_1
    gaps = np.zeros(len(v), np.int64)
    was_virtual = np.zeros(len(v), bool)
    virtual_pos = []                              # per step: positions (-1 entries)
    for step in range(n_corners - 2):
        if not len(v):
            break
        pred = pos + v                                            # eq. 3 prediction
        dist, best = tree.query(pred, k=1)
        good = dist < k_lim * np.linalg.norm(v, axis=1)           # |h_i - h^_i| < k_lim |v_i|
        if filters is not None:
            # neighbouring corners of an edge alternate in polarity, as h_1 and h_2 (a
            # bridged corner, index -1, has no filter: f[-1] = -1)
            good &= f[np.minimum(best, n)] != f[chain[-1]]
        virt = np.zeros_like(good)
        if max_gaps > 0 and 1 <= step < n_corners - 3:
            virt = ~good & (gaps < max_gaps) & ~was_virtual
        keep = good | virt
        chain = [c[keep] for c in chain]
        virtual_pos = [p[keep] for p in virtual_pos]
        best, pred, v, good, virt = best[keep], pred[keep], v[keep], good[keep], virt[keep]
        gaps = gaps[keep] + virt
        was_virtual = virt
        best = np.where(good, best, -1)
        corr = np.where(good[:, None], points[np.maximum(best, 0)] - pred, 0.0)
        v = v + k_g * corr                                        # v_{i+1} = v_i + k_g (...)
        pos = np.where(good[:, None], points[np.maximum(best, 0)], pred)
        chain.append(best)
        virtual_pos.append(np.where(virt[:, None], pred, np.nan))
    if len(chain) < n_corners or not len(chain[0]):
        return none
    edges = np.column_stack(chain)
    vpos = np.stack(virtual_pos, axis=1) if virtual_pos else np.zeros((len(edges), 0, 2))
    real = edges >= 0
    srt = np.sort(np.where(real, edges, -1 - np.arange(n_corners)), axis=1)
    distinct = np.all(srt[:, 1:] != srt[:, :-1], axis=1)
    edges, vpos, real = edges[distinct], vpos[distinct], real[distinct]
    full = real.all(axis=1)
    complete = edges[full]
    # every edge in both directions, once each (a chain may be found from one end only)
    both = np.vstack([complete, complete[:, ::-1]])
    _, first = np.unique(both, axis=0, return_index=True)
    out = both[np.sort(first)]
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
    _, first_of = np.unique(flat[good], axis=0, return_index=True)
    return [ids[i] for i in good[np.sort(first_of)]]


# ---------------------------------------------------------------------- 2.2.3 code


def _fit_line(pts: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Total least-squares line through points: (centroid, unit direction).

    The direction is the principal axis of the 2 x 2 scatter matrix, in closed form.
    """
    c = pts.mean(axis=0)
    q = pts - c
    sxx, syy, sxy = float(q[:, 0] @ q[:, 0]), float(q[:, 1] @ q[:, 1]), float(q[:, 0] @ q[:, 1])
    a = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    return c, np.array([math.cos(a), math.sin(a)])


def _intersect(p1: np.ndarray, d1: np.ndarray, p2: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Intersection of lines p1 + s d1 and p2 + t d2 (arrays broadcast over leading axes)."""
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        cross = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
        w = p2 - p1
        s = (w[..., 0] * d2[..., 1] - w[..., 1] * d2[..., 0]) / cross
        return p1 + s[..., None] * d1


@dataclass(frozen=True, eq=False)
class FrameGrid:
    """A frame with fitted edges and its code grid (image orientation, before decoding).

    Attributes:
        corners: (4, 2) frame corners A, B, C, D (eq. 5) [px]: start of f_1, end of f_1,
            end of f_3, end of f_2, i.e. clockwise in the image.
        edge_corners: (4, n, 2) corner centres of the edges A->B, B->C, C->D, D->A.
        grid: (2n - 1, 2n - 1, 2) grid points at half-block steps, ``[row, col]``, row 0 on
            edge A->B, col 0 on edge A->D.
        line_rms: RMS distance of the corners from their fitted lines [px].
    """

    corners: np.ndarray
    edge_corners: np.ndarray
    grid: np.ndarray
    line_rms: float


def _ideal_to_distorted(camera: CameraModel, px: np.ndarray) -> np.ndarray:
    """Map ideal (undistorted) pixels of ``camera`` to the pixels its lens records."""
    shape = px.shape
    p = px.reshape(-1, 2)
    k = camera.K
    y = (p[:, 1] - k[1, 2]) / k[1, 1]
    x = (p[:, 0] - k[0, 2] - k[0, 1] * y) / k[0, 0]
    return camera.normalized_to_pixels(np.column_stack([x, y]), distort=True).reshape(shape)


def refine_corners(image: np.ndarray, points: np.ndarray, spacing: float,
                   window_fraction: float = 0.45) -> np.ndarray:
    """Refine X-corner positions with ``cv2.cornerSubPix`` (saddle point of the gradients).

    Args:
        image: (H, W) float32 image.
        points: (N, 2) corner positions [px].
        spacing: corner spacing [px]; the window half-size is ``window_fraction`` of it,
            at most 8 px, so that a window never reaches the next corner.
        window_fraction: see ``spacing``.

    Returns:
        (N, 2) refined positions; a corner that moves by more than the window half-size
        keeps its input position, and with a window below 2 px (spacing under
        ``2 / window_fraction``) nothing is refined.
    """
    w = int(min(8, math.floor(window_fraction * spacing)))
    if w < 2:
        return np.asarray(points, dtype=float).copy()
    h, wd = image.shape
    pts = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 1, 2)
    inside = ((pts[:, 0, 0] >= w + 1) & (pts[:, 0, 0] <= wd - w - 2)
              & (pts[:, 0, 1] >= w + 1) & (pts[:, 0, 1] <= h - w - 2))
    out = np.asarray(points, dtype=float).copy()
    if not inside.any():
        return out
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 20, 0.005)
    ref = cv2.cornerSubPix(image, pts[inside].copy(), (w, w), (-1, -1), crit).reshape(-1, 2)
    moved = np.linalg.norm(ref - out[inside], axis=1) <= w
    idx = np.flatnonzero(inside)[moved]
    out[idx] = ref[moved]
    return out


def edge_points(image: np.ndarray, starts: np.ndarray, ends: np.ndarray, depth: np.ndarray,
                positions: int = 6, min_contrast: float = 20.0) -> Tuple[np.ndarray, np.ndarray]:
    """Return sub-pixel points of straight grey-level edges between pairs of X-corners.

    Between two neighbouring X-corners of a frame edge the outer and the inner ring meet
    in a straight black-white edge (its polarity alternates from block to block). Across
    it, at ``positions`` places in the middle half of every block, a profile of
    ``+-0.4 depth`` is sampled (bilinear, half-pixel steps); the edge lies where the
    profile's area matches a step between its two end levels (``s_e = L - sum(r) ds`` with
    ``r`` the profile scaled to 0..1), which is exact for an area-sampled or symmetrically
    blurred step, unlike a gradient peak.

    Args:
        image: (H, W) float32 image (a symmetric blur does not move the result).
        starts: (S, 2) first corner of each block segment [px].
        ends: (S, 2) second corner [px].
        depth: (S,) block size across the edge at each segment [px]; segments under 2.5 px
            are skipped.
        positions: profiles per segment.
        min_contrast: profiles whose end levels differ by less are dropped.

    Returns:
        (points, segment): (P, 2) edge points [px] and the (P,) index of their segment.
    """
    seg = ends - starts
    length = np.linalg.norm(seg, axis=1)
    ok = (length > 1e-9) & (depth >= 2.5)
    if not ok.any():
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    index = np.flatnonzero(ok)
    a, seg, length, depth = starts[ok], seg[ok], length[ok], depth[ok]
    tang = seg / length[:, None]
    normal = np.column_stack([-tang[:, 1], tang[:, 0]])
    t = 0.25 + 0.5 * (np.arange(positions) + 0.5) / positions          # middle half
    half = 0.4 * depth                                                  # (S,)
    k = np.maximum(6, np.ceil(2.0 * half / 0.5).astype(int))
    kmax = int(k.max())
    ds = 2.0 * half / k                     # s_i = -L + (i + 0.5) ds, i < k (masked beyond)
    i = np.arange(kmax)
    valid_i = i[None, :] < k[:, None]
    offs = np.where(valid_i, -half[:, None] + (i[None, :] + 0.5) * ds[:, None], 0.0)
    base = a[:, None, :] + t[None, :, None] * seg[:, None, :]           # (S, J, 2)
    pts = base[:, :, None, :] + offs[:, None, :, None] * normal[:, None, None, :]
    if isinstance(image, _Shifted):
        pts_img, image = pts - image.offset, image.image
    else:
        pts_img = pts
    flat = pts_img.reshape(-1, 2).astype(np.float32)
    # cv2.remap maps need fewer than 32767 columns: a frame with blocks of a hundred pixels
    # and more (a candidate in a cluttered view) asks for more samples than that
    vals = np.concatenate([
        cv2.remap(image, flat[None, i:i + 32000, 0], flat[None, i:i + 32000, 1],
                  cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel()
        for i in range(0, len(flat), 32000)]).reshape(pts.shape[:3]).astype(float)
    rows = np.arange(len(k))[:, None]
    tail = k[:, None] - 1 - np.arange(3)[None, :]                       # last three samples
    lo = vals[:, :, :3].mean(axis=2)                                   # (S, J)
    hi = vals[rows, :, tail].mean(axis=1)
    span = hi - lo
    good = np.abs(span) >= min_contrast
    with np.errstate(divide='ignore', invalid='ignore'):
        r = (vals - lo[:, :, None]) / span[:, :, None]
    r = np.where(valid_i[:, None, :], r, 0.0)
    s_e = half[:, None] - ds[:, None] * r.sum(axis=2)                   # (S, J)
    good &= np.abs(s_e) < half[:, None]
    out = base + s_e[:, :, None] * normal[:, None, :]
    segment = np.broadcast_to(index[:, None], good.shape)
    return out[good], segment[good]


def _robust_line(pts: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """TLS line through points, refitted once without points beyond 3 robust sigmas."""
    c, d = _fit_line(pts)
    q = pts - c
    res = np.abs(q[:, 0] * d[1] - q[:, 1] * d[0])
    mad = float(np.partition(res, len(res) // 2)[len(res) // 2])     # median |residual|
    keep = res <= max(3.0 * 1.4826 * mad, 1e-3)
    if keep.sum() >= 2 and not keep.all():
        c, d = _fit_line(pts[keep])
    return c, d


def fit_frame(points: np.ndarray, frame: np.ndarray, camera: Optional[CameraModel] = None,
              image: Optional[np.ndarray] = None, min_contrast: float = 20.0,
              grid: bool = True) -> FrameGrid:
    """Fit lines to the four edges, intersect them (eq. 5) and build the code grid.

    The frame corners are the crossings of adjacent fitted edge lines (eq. 5). The corners
    of each edge are projected onto its line, the end corners replaced by the crossings,
    and every corner spacing is halved (§2.2.3: "dividing the distance between two adjacent
    corners on every frame edge in two ... the distance between the corners are not
    equalized"). Grid point ``[i, j]`` is the crossing of the line joining the j-th points of
    the top and bottom edges with the line joining the i-th points of the left and right
    edges.

    Args:
        points: (N, 2) corner positions [px].
        frame: (4, n) ``[f_1, f_2, f_3, f_4]`` from :func:`find_frames`.
        camera: if given, the fits are made in its ideal (undistorted) image, where the
            printed edges are straight, and the corners and grid are mapped back to the
            recorded (distorted) pixels.
        image: if given (float32), each edge line is fitted to the sub-pixel
            points of the ring boundary along the edge (:func:`edge_points`) instead of to
            its six corners; the corners are still projected onto it for the grid.
        min_contrast: contrast of a usable edge profile (with ``image``).
        grid: False skips the code grid (``FrameGrid.grid`` is then the (2, 2, 2) array of
            the frame corners).

    Returns:
        :class:`FrameGrid` (pixels of the recorded image).
    """
    measured = points[frame]                                  # (4, n, 2)
    edges = measured if camera is None else \
        camera.undistort_pixels(measured.reshape(-1, 2), 'ideal').reshape(measured.shape)
    f1, f2, f3, f4 = edges
    if image is not None:
        along, across = _edge_samples(image, measured, camera, min_contrast)
        lines = _edge_lines(*along, measured.shape[1], edges)
    else:
        lines = [_fit_line(p) for p in (f1, f2, f3, f4)]
    res = []
    for (c, d), p in zip(lines, (f1, f2, f3, f4)):
        q = p - c
        res.append(q[:, 0] * d[1] - q[:, 1] * d[0])
    line_rms = float(np.sqrt(np.mean(np.concatenate(res) ** 2)))
    a = _intersect(*lines[0], *lines[1])   # f_1 x f_2 (eq. 5)
    b = _intersect(*lines[0], *lines[3])   # f_1 x f_4
    c = _intersect(*lines[2], *lines[3])   # f_3 x f_4
    d = _intersect(*lines[1], *lines[2])   # f_2 x f_3

    def on_line(pts, line, start, end):
        cen, dirn = line
        t = (pts - cen) @ dirn
        proj = cen + t[:, None] * dirn
        proj[0], proj[-1] = start, end
        full = np.empty((2 * len(proj) - 1, 2))
        full[0::2] = proj
        full[1::2] = 0.5 * (proj[:-1] + proj[1:])
        return full

    if image is not None:
        measured = _edge_crossings(*across, measured, lines, camera)
    m1, m2, m3, m4 = measured
    edge_corners = np.stack([m1, m4, m3[::-1], m2[::-1]])
    corners = np.array([a, b, c, d])
    if not grid:
        if camera is not None:
            corners = _ideal_to_distorted(camera, corners)
        return FrameGrid(corners, edge_corners, corners[[0, 1, 3, 2]].reshape(2, 2, 2),
                         line_rms)
    top = on_line(f1, lines[0], a, b)
    left = on_line(f2, lines[1], a, d)
    bottom = on_line(f3, lines[2], d, c)
    right = on_line(f4, lines[3], b, c)
    # grid[i, j] = (left[i] -> right[i]) x (top[j] -> bottom[j])
    shape = (len(left), len(top), 2)
    grid_pts = _intersect(np.broadcast_to(left[:, None, :], shape),
                          np.broadcast_to((right - left)[:, None, :], shape),
                          np.broadcast_to(top[None, :, :], shape),
                          np.broadcast_to((bottom - top)[None, :, :], shape))
    if camera is not None:
        corners = _ideal_to_distorted(camera, corners)
        grid_pts = _ideal_to_distorted(camera, grid_pts)
    return FrameGrid(corners, edge_corners, grid_pts, line_rms)


def _block_depth(measured: np.ndarray) -> np.ndarray:
    """Return the (4, n - 1) block size across each edge at each of its blocks [px].

    It is the first/last block of the edges crossing edge e (f_1, f_3 are crossed by f_2,
    f_4 and vice versa), interpolated along e.
    """
    n = measured.shape[1]
    spacing = np.linalg.norm(np.diff(measured, axis=1), axis=2)        # (4, n - 1)
    t = np.linspace(0.0, 1.0, n - 1)
    depth = np.empty((4, n - 1))
    for e, (cross, j) in enumerate((((1, 3), 0), ((0, 2), 0), ((1, 3), n - 2),
                                    ((0, 2), n - 2))):
        depth[e] = spacing[cross[0], j] + t * (spacing[cross[1], j] - spacing[cross[0], j])
    return depth


def _edge_samples(image: np.ndarray, measured: np.ndarray, camera: Optional[CameraModel],
                  min_contrast: float) -> Tuple[Tuple[np.ndarray, np.ndarray],
                                                Tuple[np.ndarray, np.ndarray]]:
    """Sample the straight grey-level edges of a frame with one :func:`edge_points` call.

    Returns ``(points, segment)`` pairs in the fit's image (ideal with a lens model): first
    of the ring boundary along each edge (segment ``e * (n - 1) + j``: block j of edge e),
    then of the block boundaries across the ring at the interior corners (segment ``side *
    4 * (n - 2) + e * (n - 2) + j - 1``: corner j of edge e, side 0 outward, 1 inward,
    profiles along the edge; see :func:`_edge_crossings`).
    """
    n = measured.shape[1]
    depth = _block_depth(measured)
    starts = [measured[:, :-1].reshape(-1, 2)]
    ends = [measured[:, 1:].reshape(-1, 2)]
    sizes = [depth.ravel()]
    if n >= 3:
        inner = measured[:, 1:-1]                                      # (4, n - 2, 2)
        tang = measured[:, 2:] - measured[:, :-2]
        tang = tang / np.maximum(np.linalg.norm(tang, axis=2, keepdims=True), 1e-9)
        normal = np.stack([-tang[..., 1], tang[..., 0]], axis=-1)
        across = 0.5 * (depth[:, :-1] + depth[:, 1:])                  # at the corners
        along = np.linalg.norm(np.diff(measured, axis=1), axis=2)
        along = 0.5 * (along[:, :-1] + along[:, 1:])
        reach = (across[..., None] * normal)[None] * np.array([1.0, -1.0])[:, None, None, None]
        first = np.broadcast_to(inner, reach.shape).reshape(-1, 2)
        starts.append(first)
        ends.append(first + reach.reshape(-1, 2))
        sizes.append(np.broadcast_to(along, reach.shape[:3]).ravel())
    pts, seg = edge_points(image, np.concatenate(starts), np.concatenate(ends),
                           np.concatenate(sizes), min_contrast=min_contrast)
    if camera is not None and len(pts):
        pts = camera.undistort_pixels(pts, 'ideal')
    split = 4 * (n - 1)
    first_set = seg < split
    return ((pts[first_set], seg[first_set]),
            (pts[~first_set], seg[~first_set] - split))


def _edge_lines(pts: np.ndarray, seg: np.ndarray, n: int, edges: np.ndarray) -> list:
    """Fit the four edge lines to ring-boundary edge points (see :func:`fit_frame`).

    ``pts``/``seg`` are the first pair of :func:`_edge_samples`; an edge with fewer than
    two points per block keeps the line through its corners ``edges[e]``.
    """
    edge = seg // (n - 1)
    out = []
    for e in range(4):
        p = pts[edge == e]
        out.append(_robust_line(p) if len(p) >= 2 * (n - 1) else _fit_line(edges[e]))
    return out


def _edge_crossings(pts: np.ndarray, seg: np.ndarray, measured: np.ndarray, lines: list,
                    camera: Optional[CameraModel]) -> np.ndarray:
    """Place the interior X-corners of each edge where the block boundaries cross its line.

    At an interior X-corner of an edge the boundary between two neighbouring blocks runs
    straight across the ring: through the outer and the inner block row, with opposite
    polarity in the two. It is measured with :func:`edge_points` on the two half-segments
    from the corner across the ring (profiles along the edge, in the middle half of each
    row; the second pair of :func:`_edge_samples`), a total-least-squares line is fitted to
    those points, and the corner becomes its crossing with the fitted edge line (both in
    the ideal image when there is a lens model). The saddle-point refinement alone leaves
    these corners 0.04-0.07 px off on simulated views, in a pattern that tilts a head-on
    pose by tenths of a degree; the crossings are within 0.01 px. Corners with fewer than
    four usable points keep their measured position; so do the end corners (the frame
    corners come from eq. 5).

    Args:
        pts: (P, 2) boundary points in the fit's image.
        seg: (P,) their half-segment index (see :func:`_edge_samples`).
        measured: (4, n, 2) corners of the edges f_1..f_4 [px, recorded image].
        lines: the four fitted edge lines (centre, unit direction) in the fit's image.
        camera: lens model of the fit (None: the fit is in recorded pixels).

    Returns:
        (4, n, 2) corners [px, recorded image].
    """
    n = measured.shape[1]
    if n < 3:
        return measured
    out = measured.copy()
    if not len(pts):
        return out
    k = 4 * (n - 2)
    corner = seg % k                                   # (edge, corner) index of each point
    count = np.bincount(corner, minlength=k)
    ok = count >= 4
    if not ok.any():
        return out
    safe = np.maximum(count, 1)
    c = np.stack([np.bincount(corner, pts[:, i], k) / safe for i in (0, 1)], axis=1)
    q = pts - c[corner]
    sxx = np.bincount(corner, q[:, 0] * q[:, 0], k)
    syy = np.bincount(corner, q[:, 1] * q[:, 1], k)
    sxy = np.bincount(corner, q[:, 0] * q[:, 1], k)
    ang = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)                        # TLS directions
    d = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    edge = np.repeat(np.arange(4), n - 2)
    lc = np.array([ln[0] for ln in lines])[edge]
    ld = np.array([ln[1] for ln in lines])[edge]
    cross = _intersect(lc, ld, c, d)
    if camera is not None:
        cross = _ideal_to_distorted(camera, cross)
    ok &= np.isfinite(cross).all(axis=1)
    flat = out[:, 1:-1].reshape(-1, 2)
    flat[ok] = cross[ok]
    out[:, 1:-1] = flat.reshape(4, n - 2, 2)
    return out


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
                iterations: int = 3) -> Optional[Tuple[np.ndarray, float]]:
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

    Returns:
        ``(whiteness, residual)``: the (2m, 2m) unmixed code-cell whiteness and the RMS
        misfit of the model over the contrast ``p1 + 4 p2 + 4 p3``; None if the fitted
        mixing is not centre-weighted (``p1`` the largest weight) or the solve fails.
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
    return x.reshape(m2, m2), float(np.sqrt(np.mean(res * res))) / contrast


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
                supersample: int = 4) -> Optional[Tuple[np.ndarray, float, float]]:
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

    Returns:
        ``(whiteness, residual, sigma)``: the (2m, 2m) code-cell whiteness (1 white, 0
        black), the RMS misfit over the contrast and the blur chosen; None if the patch
        leaves the image, the contrast is not positive or the solve fails.
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
            best = (rms, coef, sig)
    rms, coef, sig = best
    d = float(coef[1])
    if not d > 0:
        return None
    return (coef[2:] / d).reshape(m2, m2), rms / d, float(sig)


@dataclass(frozen=True, eq=False)
class CodeReading:
    """Result of :func:`read_code` for one frame grid."""

    code: Optional[int]
    rotation: int
    bits: np.ndarray
    contrast: float
    margin: float
    reason: str


def read_code(cells: np.ndarray, design: LandmarkDesign, min_contrast: float = 20.0,
              min_margin: float = 0.2, deblur_margin: float = 0.0,
              deblur_residual: float = 0.12, block_ring: bool = False,
              unblur: Optional[Callable[[int], Optional[Tuple[np.ndarray, float, float]]]] = None,
              unblur_margin: float = 0.3, unblur_residual: float = 0.08) -> CodeReading:
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
    if code_margin < min_margin:
        unmixed = unmix_cells(cells, design, parity) if deblur_margin > 0 else None
        white = None
        if unmixed is not None and unmixed[1] <= deblur_residual:
            m = min(ring_margin, float(np.abs(unmixed[0] - 0.5).min()) * 2.0)
            if m >= deblur_margin:
                white, margin = unmixed[0], m
        if white is None and unblur is not None:
            pixel = unblur(parity)
            if pixel is not None and pixel[1] <= unblur_residual:
                m = min(ring_margin, float(np.abs(pixel[0] - 0.5).min()) * 2.0)
                if m >= unblur_margin:
                    white, margin = pixel[0], m
        if white is None:
            return CodeReading(None, 0, bits, contrast, margin, 'ambiguous code cell')
        bits = white < 0.5
    got = design.decode_with_rotation(bits)
    if got is None:
        return CodeReading(None, 0, bits, contrast, margin, 'no valid code')
    code, rot = got
    if len(parities) == 2 and rot % 2 != parity:
        return CodeReading(None, 0, bits, contrast, margin, 'orientation disagrees with frame')
    return CodeReading(code, rot, np.rot90(bits, rot), contrast, margin, '')


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
    return functools.partial(unblur_code, raw, grid, design)


#: read failures worth a second reading on the refined grid (``refine_grid``)
_REREAD = ('frame cells inconsistent', 'ambiguous code cell', 'no valid code')


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


class _Shifted:
    """An image crop that :func:`edge_points` samples in full-image pixel coordinates."""

    def __init__(self, image: np.ndarray, offset: np.ndarray) -> None:
        """Keep the crop and its top-left pixel."""
        self.image = image
        self.offset = offset


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
            ``frames``, ``grids``, ``readings``).

    Returns:
        The detections, strongest (largest margin) first; overlapping detections (sharing
        corners) are reduced to the best one.

    Raises:
        ValueError: ``gray`` is not a 2-D array.
    """
    img = np.asarray(gray)
    if img.ndim != 2:
        raise ValueError(f'detect_landmarks needs a 2-D grey image; got shape {img.shape}')
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
    pts, filt = corners.points, corners.filters
    if len(pts) > params.max_corners:
        keep = np.argsort(corners.weights)[::-1][:params.max_corners]
        pts, filt = pts[keep], filt[keep]
    tree = cKDTree(pts) if len(pts) else None
    nbrs = corner_neighbours(pts, params.neighbour_fraction * img.shape[0],
                             params.max_neighbours, tree, params.neighbour_mode,
                             math.radians(params.second_neighbour_angle))
    edges, virtual = chain_edges(pts, nbrs, n, params.k_lim, params.k_g, tree, filt,
                                 params.max_gaps)
    if debug is not None:
        debug.update(corners=corners, points=pts, virtual=virtual)
    if len(virtual):
        pts = np.vstack([pts, virtual])
    frames = find_frames(pts, edges, params.k_p)
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
                            params.deblur_residual, params.block_ring)
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
                                    unblur_margin, params.unblur_residual)
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
           'smooth', 'unmix_cells']
