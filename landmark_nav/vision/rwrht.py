"""Image lines by the Random Window Randomized Hough Transform (self-localization chapter §5.2).

Algorithm 2 of the chapter (after Kälviäinen et al. 1994), on a Canny edge image
(:func:`landmark_nav.vision.image_lines.canny_edges`):

1. ``D`` <- all edge points;
2. ``d_i`` <- a random point of ``D`` (here: the next point of a random permutation of the
   edge points that is still in ``D``);
3. ``m`` <- a random window size, ``m_min <= m <= m_max``;
4. ``W`` <- the edge points of the ``m x m`` neighbourhood of ``d_i``;
5-7. RHT on ``W``, ``R`` times: two random points of ``W`` give one line ``(rho, theta)``
   that votes for one accumulator cell;
8-11. if the best cell has ``>= threshold`` votes its parameters are a detected line,
   otherwise go to 2.

The chapter gives no more; our completions, each a field of :class:`RWRHTParams`:

* ``batch`` windows are drawn and voted at once (vectorised), then taken in order as the
  sequential algorithm would (a window whose voters were taken by a line found earlier in
  the batch is a failure); a pair closer than
  ``min_pair_px`` is not drawn twice but skipped (its angle is too uncertain); the
  accumulator is in window-centred coordinates so its ``rho`` bins do not stretch with the
  distance from the image origin;
* a detected line is completed as in the RHT: its edge points (within ``band_px`` of the
  line, anywhere in ``D`` or taken by an earlier line, since crossing lines share pixels)
  are split into runs at gaps wider than ``max_gap_px``; the run holding the window's
  points is refitted by total least squares (twice, the second time
  with the band around the refitted line), becomes a segment, and its points leave ``D``;
* the search stops after ``max_failures`` windows in a row without a line, when ``D`` has
  fewer than ``threshold`` points, or after ``max_lines`` lines.

Randomness comes only from the ``rng`` passed in (deterministic per seed).

:func:`detect_model_lines` offers the line sources of the monocular localizer behind one
name: ``'rwrht'`` (this module), and ``'hough_p'``, ``'lsd'``, ``'segmented_hough'`` of
:mod:`.image_lines` as in-run references.
"""

from dataclasses import dataclass, field
import math
from typing import Optional

from landmark_nav.vision.image_lines import (canny_edges, CannyParams, detect_lines,
                                             ImageLines, LineParams, METHODS, to_gray)
import numpy as np

MODEL_LINE_METHODS = ('rwrht',) + METHODS


@dataclass(frozen=True)
class RWRHTParams:
    """Parameters of :func:`rwrht` (see the module docstring).

    Attributes:
        window_min: m_min, smallest window side [px] (odd).
        window_max: m_max, largest window side [px].
        trials: R, point pairs drawn per window.
        threshold: votes of the best cell to accept a line (out of ``trials``).
        theta_bin_deg: accumulator bin of the line normal angle [deg].
        rho_bin_px: accumulator bin of the line distance from the window centre [px].
        min_pair_px: pairs of points closer than this [px] do not vote.
        band_px: edge points within this distance [px] of a detected line belong to it.
        max_gap_px: a segment is split at gaps wider than this [px] along the line.
        min_length_px: shorter segments are dropped (their points still leave D).
        max_failures: windows in a row without a line before the search stops.
        max_lines: at most this many lines per image.
        batch: windows whose random trials are drawn and voted at once (speed only).
    """

    window_min: int = 9
    window_max: int = 25
    trials: int = 24
    threshold: int = 6
    theta_bin_deg: float = 3.0
    rho_bin_px: float = 1.0
    min_pair_px: float = 3.0
    band_px: float = 1.5
    max_gap_px: float = 4.0
    min_length_px: float = 12.0
    max_failures: int = 60
    max_lines: int = 80
    batch: int = 32


def _tls(x: np.ndarray, y: np.ndarray) -> tuple:
    """Centroid and unit direction of the total-least-squares line through the points."""
    cx, cy = x.mean(), y.mean()
    dx, dy = x - cx, y - cy
    sxx, syy, sxy = (dx * dx).mean(), (dy * dy).mean(), (dx * dy).mean()
    a = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    return cx, cy, math.cos(a), math.sin(a)


def _support(xs: np.ndarray, ys: np.ndarray, alive: np.ndarray, index_img: np.ndarray,
             cx: float, cy: float, ux: float, uy: float, seed_t: float,
             p: RWRHTParams) -> np.ndarray:
    """Return the indices of the alive points of the run along the line that holds ``seed_t``.

    The edge points within ``band_px`` of the line are looked up in ``index_img`` along
    the line (half-pixel steps across the whole image), not searched among all points.
    Points already taken by another line count for the run (crossing lines share pixels)
    but are not returned.
    """
    h, w = index_img.shape
    lo, hi = -math.hypot(h, w), math.hypot(h, w)      # t range inside the image (slabs)
    for c, u, size in ((cx, ux, w), (cy, uy, h)):
        if abs(u) > 1e-12:
            ta, tb = (-1.0 - c) / u, (size - c) / u
            lo, hi = max(lo, min(ta, tb)), min(hi, max(ta, tb))
    t = np.arange(lo - 2.0, hi + 2.0, 0.5)
    off = np.arange(-math.ceil(p.band_px), math.ceil(p.band_px) + 0.5, 0.5)
    px = np.rint(cx + t[:, None] * ux - off[None, :] * uy).ravel().astype(np.int64)
    py = np.rint(cy + t[:, None] * uy + off[None, :] * ux).ravel().astype(np.int64)
    inside = (px >= 0) & (px < w) & (py >= 0) & (py < h)
    idx = index_img[py[inside], px[inside]]
    idx = np.unique(idx[idx >= 0])
    dx, dy = xs[idx] - cx, ys[idx] - cy
    idx = idx[np.abs(-uy * dx + ux * dy) <= p.band_px]
    if idx.size == 0:
        return idx
    t = (xs[idx] - cx) * ux + (ys[idx] - cy) * uy
    order = np.argsort(t)
    idx, t = idx[order], t[order]
    cut = np.nonzero(np.diff(t) > p.max_gap_px)[0]
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut + 1, [t.size]])
    k = int(np.searchsorted(t[starts], seed_t, side='right')) - 1
    k = min(max(k, 0), starts.size - 1)
    run = idx[starts[k]:ends[k]]
    return run[alive[run]]


def rwrht(edges: np.ndarray, params: RWRHTParams = RWRHTParams(),
          rng: Optional[np.random.Generator] = None) -> ImageLines:
    """Lines of an edge image by the Random Window RHT (Algorithm 2).

    Args:
        edges: (H, W) edge image, non-zero on edge pixels.
        params: see :class:`RWRHTParams`.
        rng: random generator (default: seeded with 0, so repeatable).

    Returns:
        Segments with their supporting edge-pixel counts as weights.
    """
    p = params
    edges = np.asarray(edges)
    if edges.ndim != 2:
        raise ValueError(f'edge image must be 2-D; got shape {edges.shape}')
    if not 3 <= p.window_min <= p.window_max:
        raise ValueError(f'need 3 <= window_min <= window_max; got {p.window_min}, '
                         f'{p.window_max}')
    rng = np.random.default_rng(0) if rng is None else rng
    h, w = edges.shape
    ys_i, xs_i = np.nonzero(edges)                          # 1: D
    xs, ys = xs_i.astype(float), ys_i.astype(float)
    n = xs.size
    alive = np.ones(n, dtype=bool)
    index_img = np.full((h, w), -1, dtype=np.int64)
    index_img[ys_i, xs_i] = np.arange(n)
    n_theta = int(round(180.0 / p.theta_bin_deg))
    segs, weights = [], []
    failures = 0
    n_alive = n
    perm, ptr = rng.permutation(n), 0
    half_lo, half_hi = p.window_min // 2, p.window_max // 2
    R = p.trials
    while failures < p.max_failures and n_alive >= p.threshold and len(segs) < p.max_lines:
        # steps 2-8 for a batch of windows at once (vectorised); the windows are then taken
        # in order, as the sequential algorithm would, skipping any whose line lost its
        # points to a line found earlier in the batch
        B = int(min(p.batch, max(1, p.max_failures - failures)))
        seeds = []
        while len(seeds) < B:                               # 2: d_i, random alive points
            if ptr == n:
                if not alive[perm].any():
                    break
                perm, ptr = rng.permutation(n), 0
            d = perm[ptr]
            ptr += 1
            if alive[d]:
                seeds.append(d)
        if not seeds:
            break
        B = len(seeds)
        U = rng.random((B, 2 * R + 1))
        pa, pb, wid, x0s, y0s = [], [], [], [], []
        for k, d in enumerate(seeds):
            m = half_lo + int(U[k, 0] * (half_hi - half_lo + 1))   # 3: half the size m
            x0, y0 = int(xs_i[d]), int(ys_i[d])
            win = index_img[max(0, y0 - m):y0 + m + 1, max(0, x0 - m):x0 + m + 1]
            wi = win[win >= 0]
            wi = wi[alive[wi]]                               # 4: W
            if wi.size < p.threshold:
                continue
            pick = (U[k, 1:] * wi.size).astype(np.int64)     # 5-7: R point pairs
            pa.append(wi[pick[:R]])
            pb.append(wi[pick[R:]])
            wid.append(k)
            x0s.append(x0)
            y0s.append(y0)
        best_cell = {}
        if wid:
            a, b = np.concatenate(pa), np.concatenate(pb)
            win_of = np.repeat(np.arange(len(wid)), R)
            ddx, ddy = xs[b] - xs[a], ys[b] - ys[a]
            ok = ddx * ddx + ddy * ddy >= p.min_pair_px ** 2
            theta = np.arctan2(ddx, -ddy) % math.pi          # line normal in [0, pi)
            ox = np.array(x0s, float)[win_of]
            oy = np.array(y0s, float)[win_of]
            rho = (xs[a] - ox) * np.cos(theta) + (ys[a] - oy) * np.sin(theta)
            tb = (theta * (n_theta / math.pi)).astype(np.int64) % n_theta
            rb = np.floor(rho / p.rho_bin_px + 0.5).astype(np.int64) + 50000
            code = (win_of * n_theta + tb) * 100003 + rb
            cells, inv, counts = np.unique(code[ok], return_inverse=True, return_counts=True)
            cw = cells // (n_theta * 100003)                 # window of each cell
            for j in np.nonzero(counts >= p.threshold)[0]:   # 8: accumulator >= threshold
                w_ = int(cw[j])
                if w_ not in best_cell or counts[j] > counts[best_cell[w_]]:
                    best_cell[w_] = j
        for w_ in range(len(seeds)):
            j = best_cell.get(wid.index(w_) if w_ in wid else -1)
            if j is None:
                failures += 1                                # 11: goto 2
                continue
            sel = np.nonzero(ok)[0][inv == j]
            voters = np.unique(np.concatenate([a[sel], b[sel]]))
            voters = voters[alive[voters]]
            d = seeds[w_]
            if voters.size < 2 or not alive[d]:
                failures += 1
                continue
            # 9: the detected line; completed from all of D and refitted
            cx, cy, ux, uy = _tls(xs[voters], ys[voters])
            seed_t = (xs[d] - cx) * ux + (ys[d] - cy) * uy
            sup = voters
            for _ in range(2):
                sup = _support(xs, ys, alive, index_img, cx, cy, ux, uy, seed_t, p)
                if sup.size < 2:
                    break
                cx, cy, ux, uy = _tls(xs[sup], ys[sup])
                seed_t = (xs[d] - cx) * ux + (ys[d] - cy) * uy
            if sup.size < p.threshold:
                failures += 1
                continue
            alive[sup] = False
            n_alive -= sup.size
            t = (xs[sup] - cx) * ux + (ys[sup] - cy) * uy
            if t.max() - t.min() >= p.min_length_px:
                segs.append([cx + t.min() * ux, cy + t.min() * uy, cx + t.max() * ux,
                             cy + t.max() * uy])
                weights.append(float(sup.size))
            failures = 0
            if len(segs) >= p.max_lines:
                break
    return ImageLines(np.array(segs).reshape(-1, 4), np.array(weights))


@dataclass(frozen=True)
class ModelLineParams:
    """Line sources of the monocular localizer: Canny + RWRHT, or a reference method."""

    canny: CannyParams = field(default_factory=CannyParams)
    rwrht: RWRHTParams = field(default_factory=RWRHTParams)
    reference: LineParams = field(default_factory=LineParams)


def detect_model_lines(image: np.ndarray, method: str = 'rwrht',
                       params: ModelLineParams = ModelLineParams(),
                       rng: Optional[np.random.Generator] = None) -> ImageLines:
    """Return the line segments of an image by one of :data:`MODEL_LINE_METHODS`.

    Raises:
        ValueError: unknown method or unusable image.
    """
    if method not in MODEL_LINE_METHODS:
        raise ValueError(f'unknown line method {method!r}; expected one of '
                         f'{MODEL_LINE_METHODS}')
    if method != 'rwrht':
        return detect_lines(image, method, params.reference)
    return rwrht(canny_edges(to_gray(image), params.canny), params.rwrht, rng)
