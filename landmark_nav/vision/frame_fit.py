"""Frame fit and sub-pixel refinement of the landmark detector (chapter §2.2.3, eq. 5).

Step 3 of :func:`~.detector.detect_landmarks`: a frame of :mod:`.frame_search` becomes a
:class:`FrameGrid`, its corners and the code grid:

* :func:`fit_frame` -- the frame corners as crossings of line fits of the four edges (eq. 5)
  and the code grid at half-block steps;
* :func:`refine_corners` -- the saddle-point refinement of the corners (``cv2.cornerSubPix``,
  ``DetectorParams.refine_corners``);
* :func:`edge_points` -- sub-pixel points of the straight grey-level edges, to which the edge
  lines are fitted (``DetectorParams.refine_edges``); :func:`_edge_crossings` places the
  interior corners where the block boundaries cross the edge lines.

Conventions: pixel positions are OpenCV ``(x, y)`` = (column, row), pixel centres at integer
coordinates (the chapter writes ``(r, c)``).

Readings of the chapter that needed a decision (tested in
``test/test_landmark_detector.py``):

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
"""

from dataclasses import dataclass
import math
from typing import Optional, Tuple

import cv2
from landmark_nav.vision.camera import CameraModel
import numpy as np


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


class _Shifted:
    """An image crop that :func:`edge_points` samples in full-image pixel coordinates."""

    def __init__(self, image: np.ndarray, offset: np.ndarray) -> None:
        """Keep the crop and its top-left pixel."""
        self.image = image
        self.offset = offset


__all__ = ['edge_points', 'fit_frame', 'FrameGrid', 'refine_corners']
