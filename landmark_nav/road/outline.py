"""Road outline from one colour image, seeded by the laser's traversable segment (ch. §4.3).

Per pixel ``H_ij`` of the image resampled to the chapter's 320 x 240:

* chromaticity ``c = (r, g) / (r + g + b)`` (eq. 25), or, against shadows, an
  illumination-invariant chromaticity (``chroma='invariant'``, below);
* ``P_c = (1 + w_c(i) (c - c_w)^T Q^-1 (c - c_w))^-1`` (eq. 27): the Mahalanobis distance
  to the mean ``c_w`` and covariance ``Q`` of the seed area, with a weight ``w_c(i)``
  growing linearly from ``w_c_top`` at the top row to ``w_c_bottom`` at the bottom;
* ``P_e = (1 + w_e |grad I|^2)^-1`` (eq. 28) with a Sobel operator of 3 x 3 in the upper
  and 5 x 5 in the lower half of the image (both scaled to grey levels per pixel);
* road where ``P_c + P_e > K_limit`` (eq. 26).

Only the region connected to the seed area is road: growing outwards from the seed visits
exactly the pixels of that region and its border (the chapter evaluates pixels only along
the advancing contour, then follows the border back); here the criterion is evaluated for
the whole frame with numpy (cheaper than a pixel-by-pixel walk in Python) and the region
is the seed's connected component, identical to the contour walk's result. The outline is
the region's outer border (:func:`cv2.findContours`).

Beyond the chapter, on its stated weaknesses:

* *painted markings* (white lines, symbols) are taken as obstacles by eqs. 26-28: the
  region is closed morphologically by ``close_px`` and its holes that are brighter than
  the seed by ``marking_contrast`` grey levels (paint) or tiny are filled, so markings
  inside the road count as road, while darker holes (a cyclist, a car) stay obstacles;
* *shadows*: the Mahalanobis distance of eq. 27 uses ``Q`` plus each pixel's own
  chromaticity noise, ``(chroma_noise / I)^2`` on the diagonal (the chromaticity of a dark,
  shadowed pixel is a ratio of small, noisy numbers), and the gradient of eq. 28 is taken
  on the log intensity (``log_gradient``: a shadow border is a step of one height whatever
  the brightness, a dark shadow interior is as smooth as a lit one). Optionally
  (``chroma='invariant'``) the chromaticity is Finlayson's 1-D illuminant invariant -- the
  log chromaticities ``(log(r / g), log(b / g))`` projected orthogonal to the
  illuminant-colour direction ``invariant_angle`` (a camera constant), paired with the
  eq. 25 ``g`` -- which did not improve the real street frames (README.md at commit
  67eb6cc, Road following).

On drives it was not tuned on, eqs. 26-28 flood across low kerbs onto pavement of the road's
grey and, on overcast frames, over walls and parked cars. ``method='learned'`` replaces
eq. 26 by a learned road probability (:mod:`landmark_nav.road.road_probability`: colour
relative to the seed, texture, image position) above ``p_road``, evaluated at 160 x 120 and
interpolated to the working size; the seed's connected region, the closing and the hole
filling are the same. The default criterion, ``method='cnn'``, averages that probability
with a small fully convolutional network's over the same features
(:mod:`landmark_nav.road.road_cnn`: it judges a pixel from the layout around it).
``method='chapter'`` keeps eqs. 26-28.

Each outline carries a confidence in [0, 1]: the smaller of the model's mean road
probability on the seed (is the seed road at all?) and the contrast of that probability
across the region's border (mean inside minus mean in a band ``ring_px`` wide outside: is
the border clear?); and a row fill (:func:`row_fill`): the share of each row's span, from the
region's leftmost to its rightmost pixel, that the region covers, over the rows from its top
down to the seed. A road seen from above its ground plane is one interval per row; an outline
that floods around parked cars, along pavement and up walls leaves gaps inside the rows it
spans. ``reliable`` when the confidence reaches ``min_confidence`` and the row fill
``min_row_fill`` (the 10 % quantile of the row fill of held-out frames, leave one drive out,
of the default criterion; ``benchmarks/bench_road.py --cross-drive --methods cnn``).
"""

from dataclasses import dataclass
import math
from typing import Optional

import cv2
from landmark_nav.road.road_cnn import default_cnn_criterion, ProbabilityModel
from landmark_nav.road.road_probability import FEATURE_SIZE, road_probability
import numpy as np

#: Processing size of the chapter (columns, rows).
WORK_SIZE = (320, 240)


#: Road criteria: learned perceptron, learned CNN, the chapter's eqs. 26-28.
METHODS = ('learned', 'cnn', 'chapter')


class SeedError(ValueError):
    """The seed area is unusable (outside the image, too small)."""


@dataclass(frozen=True)
class OutlineParams:
    """Weights and limits of eqs. 26-28 and of the marking / shadow handling."""

    w_c_top: float = 0.3
    w_c_bottom: float = 0.3
    w_e: float = 0.01
    k_limit: float = 1.35
    chroma: str = 'rg'
    invariant_angle: float = math.radians(150.0)
    log_gradient: bool = True
    close_px: int = 5
    fill_holes: bool = True
    marking_contrast: float = 25.0
    small_hole: int = 12
    regularization: float = 1e-5
    chroma_noise: float = 1.0
    min_seed_pixels: int = 20
    method: str = 'cnn'
    p_road: float = 0.5
    ring_px: int = 6
    min_confidence: float = 0.5
    min_row_fill: float = 0.915

    def __post_init__(self) -> None:
        """Check the ranges."""
        for name in ('w_c_top', 'w_c_bottom', 'w_e', 'k_limit', 'regularization',
                     'chroma_noise'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'outline {name} must be >= 0; got {value!r}')
        if self.chroma not in ('rg', 'invariant'):
            raise ValueError(f"outline chroma must be 'rg' or 'invariant'; got {self.chroma!r}")
        if self.close_px < 0 or self.min_seed_pixels < 1:
            raise ValueError('outline close_px must be >= 0 and min_seed_pixels >= 1')
        if self.method not in METHODS:
            raise ValueError(f"outline method must be one of {', '.join(METHODS)}; got "
                             f'{self.method!r}')
        for name in ('p_road', 'min_confidence', 'min_row_fill'):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f'outline {name} must be in [0, 1]; got {value!r}')
        if self.ring_px < 1:
            raise ValueError(f'outline ring_px must be >= 1; got {self.ring_px!r}')


@dataclass(frozen=True, eq=False)
class RoadOutline:
    """Result at the input image's resolution.

    Attributes:
        mask: (H, W) bool, road pixels.
        polygon: (K, 2) float pixel (u, v) of the outer border of the road region (empty
            when there is none).
        seed: (H, W) bool, the seed area used.
        p_c: (240, 320) float32 eq. 27 at the working size (for debugging; None with the
            learned criterion).
        p_e: (240, 320) float32 eq. 28 at the working size (None with the learned one).
        probability: (120, 160) float32 learned road probability (None with eqs. 26-28).
        confidence: In [0, 1]: min(seed road probability, border contrast); 1.0 with
            eqs. 26-28, which have no such measure.
        row_fill: In [0, 1]: share of the region's row spans it covers (:func:`row_fill`);
            1.0 with eqs. 26-28.
        reliable: ``confidence >= min_confidence`` and ``row_fill >= min_row_fill``.
    """

    mask: np.ndarray
    polygon: np.ndarray
    seed: np.ndarray
    p_c: Optional[np.ndarray]
    p_e: Optional[np.ndarray]
    probability: Optional[np.ndarray] = None
    confidence: float = 1.0
    reliable: bool = True
    row_fill: float = 1.0


def chromaticity(rgb: np.ndarray, kind: str = 'rg',
                 invariant_angle: float = math.radians(150.0)) -> np.ndarray:
    """Return the (H, W, 2) float32 chromaticity of an RGB image (eq. 25 or the invariant)."""
    f = rgb.astype(np.float32) + 1.0
    total = f.sum(axis=2)
    g = f[..., 1] / total
    if kind == 'rg':
        return np.dstack([f[..., 0] / total, g])                         # eq. 25
    lr = np.log(f[..., 0] / f[..., 1])
    lb = np.log(f[..., 2] / f[..., 1])
    inv = lr * math.cos(invariant_angle) + lb * math.sin(invariant_angle)
    return np.dstack([inv, g]).astype(np.float32)


def _grey(rgb: np.ndarray) -> np.ndarray:
    """Mean of the three colour planes of a uint8 image, float32.

    Bit for bit ``rgb.astype(np.float32).mean(axis=2)`` (a sum of three integer grey levels
    is exact in any order), without numpy's slow reduction over a last axis of 3.
    """
    r, g, b = cv2.split(rgb)
    return (r.astype(np.float32) + g + b) / 3


def _gradient_squared(intensity: np.ndarray) -> np.ndarray:
    """|grad I|^2 with a 3 x 3 Sobel in the upper half and 5 x 5 in the lower (eq. 28)."""
    out = np.empty_like(intensity)
    h = intensity.shape[0]
    mid = h // 2
    for ksize, rows, scale in ((3, slice(0, mid), 1.0 / 8.0), (5, slice(mid, h), 1.0 / 128.0)):
        # Whole-frame filtering keeps the borders of each half right; scale = 1 / gain of
        # the kernel on a unit ramp, so both sizes give grey levels per pixel.
        gx = cv2.Sobel(intensity, cv2.CV_32F, 1, 0, ksize=ksize, scale=scale)
        gy = cv2.Sobel(intensity, cv2.CV_32F, 0, 1, ksize=ksize, scale=scale)
        out[rows] = (gx * gx + gy * gy)[rows]
    return out


def _fill_marking_holes(mask: np.ndarray, intensity: np.ndarray, road_level: float,
                        contrast: float, small: int) -> np.ndarray:
    """Fill the holes of the road region that are paint (bright) or tiny; keep the others.

    A hole is a connected part of the background not touching the image border. It is
    filled when its mean intensity exceeds ``road_level + contrast`` (white or yellow
    paint on asphalt) or it has at most ``small`` pixels; darker, larger holes (a cyclist,
    a car, a pit) stay out of the road.
    """
    n, labels = cv2.connectedComponents((~mask).astype(np.uint8), connectivity=4)
    if n <= 1:
        return mask
    hole = np.ones(n, bool)
    hole[0] = False                       # label 0 is the region itself
    for edge in (labels[0], labels[-1], labels[:, 0], labels[:, -1]):
        hole[edge] = False
    # areas and intensity sums over the holes' pixels only (in raster order, as over all)
    pixels = np.flatnonzero(hole[labels])
    lab = labels.ravel()[pixels]
    area = np.bincount(lab, minlength=n)
    level = np.bincount(lab, weights=intensity.ravel()[pixels], minlength=n) / \
        np.maximum(area, 1)
    fill = hole & ((level > road_level + contrast) | (area <= small))
    return mask | fill[labels]


def road_outline(rgb: np.ndarray, seed: np.ndarray,
                 params: OutlineParams = OutlineParams(),
                 model: Optional[ProbabilityModel] = None) -> RoadOutline:
    """Find the road region connected to a seed area (eqs. 25-28 or the learned criterion).

    Args:
        rgb: (H, W, 3) uint8 image in RGB order.
        seed: (H, W) bool mask of the seed area (the laser's traversable segment).
        params: Weights and limits.
        model: Road-probability model of the learned criteria (default: the packaged
            perceptron with ``method='learned'``; with ``'cnn'`` the packaged network
            averaged with it).

    Returns:
        The road mask and outline at the input resolution.

    Raises:
        ValueError: The image is not (H, W, 3) uint8 or the seed has another size.
        SeedError: The seed has fewer than ``min_seed_pixels`` pixels at the working size.
    """
    img = np.asarray(rgb)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f'road outline needs an (H, W, 3) uint8 RGB image; got {img.shape} '
                         f'{img.dtype}')
    seed = np.asarray(seed, dtype=bool)
    if seed.shape != img.shape[:2]:
        raise ValueError(f'seed mask {seed.shape} differs from the image {img.shape[:2]}')
    h, w = img.shape[:2]
    small = cv2.resize(img, WORK_SIZE, interpolation=cv2.INTER_AREA)
    seed_s = cv2.resize(seed.astype(np.uint8), WORK_SIZE, interpolation=cv2.INTER_NEAREST) > 0
    n_seed = int(seed_s.sum())
    if n_seed < params.min_seed_pixels:
        raise SeedError(f'seed area has {n_seed} pixels at {WORK_SIZE[0]}x{WORK_SIZE[1]} '
                        f'(needs {params.min_seed_pixels})')
    if params.method != 'chapter':
        if model is None and params.method == 'cnn':
            model = default_cnn_criterion()
        prob = road_probability(img, seed, model)
        road = (_work_size(prob) > params.p_road) | seed_s
        p_c = p_e = None
    else:
        prob = None
        p_c, p_e = _chapter_criterion(small, seed_s, params)
        road = ((p_c + p_e) > params.k_limit) | seed_s                      # eq. 26
    region = _seed_region(road, seed_s)
    if params.close_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (params.close_px, params.close_px))
        region = cv2.morphologyEx(region.astype(np.uint8), cv2.MORPH_CLOSE, k) > 0
    if params.fill_holes:
        grey = _grey(small)
        region = _fill_marking_holes(region, grey, float(grey[seed_s].mean()),
                                     params.marking_contrast, params.small_hole)
    mask = cv2.resize(region.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_SIMPLE)
    if contours:
        polygon = max(contours, key=cv2.contourArea).reshape(-1, 2).astype(float)
    else:
        polygon = np.zeros((0, 2))
    if prob is None:
        return RoadOutline(mask, polygon, seed, p_c, p_e)
    confidence = outline_confidence(prob, region, seed_s, params.ring_px)
    fill = row_fill(region, seed_s)
    return RoadOutline(mask, polygon, seed, None, None, prob, confidence,
                       confidence >= params.min_confidence and fill >= params.min_row_fill,
                       fill)


def _work_size(prob: np.ndarray) -> np.ndarray:
    return cv2.resize(prob, WORK_SIZE, interpolation=cv2.INTER_LINEAR)


def _seed_region(road: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Return the connected (4-neighbour) parts of ``road`` that touch the seed."""
    n, labels = cv2.connectedComponents(road.astype(np.uint8), connectivity=4)
    keep = np.zeros(n, bool)
    keep[labels[seed]] = True
    keep[0] = False
    return keep[labels]


def _chapter_criterion(small: np.ndarray, seed_s: np.ndarray,
                       params: OutlineParams) -> tuple[np.ndarray, np.ndarray]:
    """P_c (eq. 27) and P_e (eq. 28) at the working size."""
    c = chromaticity(small, params.chroma, params.invariant_angle)
    cs = c[seed_s].astype(np.float64)
    mean = cs.mean(axis=0)
    q = np.cov(cs.T) + params.regularization * np.eye(2)
    d = c - mean.astype(np.float32)
    intensity = _grey(small)
    # Q plus the pixel's own chromaticity noise: grey-level noise divided by the intensity
    # (dark, e.g. shadowed, pixels have noisier chromaticity), isotropic.
    extra = (params.chroma_noise / (intensity + 1.0)) ** 2
    a, b, cc = q[0, 0] + extra, q[0, 1], q[1, 1] + extra
    det = a * cc - b * b
    m2 = (cc * d[..., 0] ** 2 - 2.0 * b * d[..., 0] * d[..., 1] + a * d[..., 1] ** 2) / det
    rows = np.linspace(params.w_c_top, params.w_c_bottom, WORK_SIZE[1], dtype=np.float32)
    p_c = 1.0 / (1.0 + rows[:, None] * m2)                                  # eq. 27
    if params.log_gradient:
        intensity = 64.0 * np.log1p(intensity)
    p_e = 1.0 / (1.0 + params.w_e * _gradient_squared(intensity))           # eq. 28
    return p_c.astype(np.float32), p_e.astype(np.float32)


def outline_confidence(prob: np.ndarray, region: np.ndarray, seed: np.ndarray,
                       ring_px: int) -> float:
    """Confidence of an outline in [0, 1]: min(seed road probability, border contrast).

    ``prob`` is the (120, 160) road probability, ``region`` and ``seed`` masks at the
    working size; the contrast is the mean probability inside the region minus its mean in
    a band ``ring_px`` (at 160 x 120) wide around it.
    """
    size = FEATURE_SIZE
    reg = cv2.resize(region.astype(np.uint8), size, interpolation=cv2.INTER_AREA) > 0
    sd = cv2.resize(seed.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * ring_px + 1,) * 2)
    ring = (cv2.dilate(reg.astype(np.uint8), k) > 0) & ~reg
    seed_p = float(prob[sd].mean()) if sd.any() else 0.0
    inside = float(prob[reg].mean()) if reg.any() else 0.0
    outside = float(prob[ring].mean()) if ring.any() else 0.0
    return max(0.0, min(seed_p, inside - outside))


def row_fill(region: np.ndarray, seed: np.ndarray) -> float:
    """Share of the region's row spans that the region covers, in [0, 1].

    Over the rows from the region's top down to the seed's lowest row: the number of region
    pixels divided by the summed spans (leftmost to rightmost region pixel, inclusive) of
    those rows. 1.0 when every row is one interval; 0.0 for an empty region.
    """
    seed_rows = np.flatnonzero(seed.any(axis=1))
    rows = region[:seed_rows[-1] + 1] if seed_rows.size else region
    rows = rows[rows.any(axis=1)]
    if not rows.size:
        return 0.0
    w = rows.shape[1]
    first = rows.argmax(axis=1)
    last = w - 1 - rows[:, ::-1].argmax(axis=1)
    return float(rows.sum() / np.sum(last - first + 1))


def band_seed(shape: tuple, rows: tuple, cols: tuple) -> np.ndarray:
    """Return an (H, W) bool seed: rows and columns given as fractions of the image size."""
    h, w = shape[:2]
    seed = np.zeros((h, w), dtype=bool)
    r0, r1 = int(round(rows[0] * h)), int(round(rows[1] * h))
    c0, c1 = int(round(cols[0] * w)), int(round(cols[1] * w))
    seed[r0:r1, c0:c1] = True
    return seed


def polyline_seed(shape: tuple, pixels: np.ndarray, thickness: int) -> Optional[np.ndarray]:
    """Return a seed band of ``thickness`` px along an image polyline (None if off-image).

    ``pixels`` (K, 2) (u, v), e.g. the laser's traversable readings projected through the
    camera model; points outside the image are clipped by the drawing.
    """
    h, w = shape[:2]
    px = np.asarray(pixels, dtype=float)
    inside = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
    if px.shape[0] < 2 or not inside.any():
        return None
    seed = np.zeros((h, w), np.uint8)
    cv2.polylines(seed, [np.round(px).astype(np.int32).reshape(-1, 1, 2)], False, 1,
                  thickness=max(1, int(thickness)))
    return seed > 0
