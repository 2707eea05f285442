"""Model lines in Hough space, their uncertainty, gating and matching (chapter §5.3).

An image line is ``x cos(gamma) + y sin(gamma) = rho`` (eq. 58) in pixel coordinates with
the origin at the top-left pixel (the chapter's retinal coordinates), ``rho >= 0``,
``gamma`` in ``[0, 2 pi)``. The Hough transform H of a segment (eq. 64) maps its two end
points to ``(rho, gamma)``; its Jacobian ``J_H`` (2 x 4) is analytic here.

A visible model line with world end points ``M1, M2`` projects to pixels whose Jacobians
w.r.t. the robot pose are ``J_P(M1, p)``, ``J_P(M2, p)`` (eq. 62); the predicted Hough point
``h^ = H(P M1, P M2)`` has the covariance (eqs. 63-65)::

    Sigma_rho_gamma = J_H blockdiag(J_P(M1), J_P(M2)) Sigma_p (...)^T J_H^T.

An image line ``h`` is a candidate for a model line when (chapter: bound 2)::

    (h - h^) (Sigma_rho_gamma + V)^-1 (h - h^)^T <= gate

where ``V`` is the image line's own covariance, ``J_H diag(sigma_px^2) J_H^T`` from an end
point noise of ``sigma_px`` (the chapter's xi ~ N(0, V)), and our default gate is the 99 %
chi-square bound for 2 degrees of freedom (9.21) rather than the chapter's 2 (63 %), which
would reject a third of the correct pairs. The image segment must also overlap the
projected model segment along the line (``overlap_margin_px``), so a collinear line of
another part of the model (e.g. a wall line beyond a niche) does not match.

Several candidates (the chapter defers to Kosaka & Kak, 1992): our rule is a global
nearest-neighbour assignment -- the one-to-one pairing of model and image lines that
minimises the sum of Mahalanobis distances among gated pairs (Hungarian algorithm,
``scipy.optimize.linear_sum_assignment``). A model line whose gate holds two image lines
that are not collinear with each other (a line-to-line angle above ``ambiguity_deg``) and
whose distances differ by less than ``ambiguity_ratio`` is ambiguous and left out.

Inseparable model lines (our addition, the same uniqueness argument on the model side): two
visible model lines whose projections overlap, run parallel (within ``ambiguity_deg``) and
lie closer than ``resolve_px`` (3 px, about the support of the detectors' 3 x 3 gradient
with its smoothing: closer edges give one merged or displaced edge chain) cannot be told
apart by the image; a line found there is a mixture of both (and of unmodelled lines beside
them, such as door frames). Both are left out
(:func:`inseparable_lines`). On the hallway these are the far niche edges: from the start,
the wall corner of a niche 17 m ahead and the niche's far corner project 1 px apart, and
pairing them one-to-one with the detected lines put 4 px (0.6 deg of heading) errors into
the update, repeated every frame while the robot stood.

Lines near the image origin: ``(rho, gamma)`` and ``(-rho, gamma + pi)`` are one line; an
image line is compared in the orientation of its predicted line, so the ``rho >= 0`` fold
never shows up as a jump of pi.
"""

from dataclasses import dataclass
import math
from typing import Tuple

import numpy as np

from .model import LineModel
from .visibility import CameraMount, Intrinsics, projection_jacobian, VisibleLines
from ..geometry import wrap_angle


def hough(segments: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Hough parameters (eq. 58) of segments and their Jacobian (eq. 64).

    Args:
        segments: (N, 4) ``x1 y1 x2 y2`` [px].

    Returns:
        ``(h (N, 2) = (rho, gamma), J_H (N, 2, 4) = d(rho, gamma) / d(x1, y1, x2, y2))``.
    """
    s = np.asarray(segments, dtype=float).reshape(-1, 4)
    dx, dy = s[:, 2] - s[:, 0], s[:, 3] - s[:, 1]
    l2 = np.maximum(dx * dx + dy * dy, 1e-12)
    gamma = np.arctan2(dx, -dy)                 # normal (-dy, dx) rotated: cos g = -dy/L ...
    c, sn = np.cos(gamma), np.sin(gamma)
    rho = s[:, 0] * c + s[:, 1] * sn
    flip = rho < 0                              # eq. 58: rho >= 0
    rho = np.where(flip, -rho, rho)
    gamma = np.where(flip, gamma + math.pi, gamma) % (2.0 * math.pi)
    c, sn = np.cos(gamma), np.sin(gamma)
    # d gamma = (dx d(dy) - dy d(dx)) / L^2 (the direction angle moves with the normal)
    dg = np.stack([dy / l2, -dx / l2, -dy / l2, dx / l2], axis=1)
    # rho = x1 cos g + y1 sin g: d rho = cos g dx1 + sin g dy1 + (-x1 sin g + y1 cos g) dg
    t1 = -s[:, 0] * sn + s[:, 1] * c
    dr = t1[:, None] * dg
    dr[:, 0] += c
    dr[:, 1] += sn
    return np.column_stack([rho, gamma]), np.stack([dr, dg], axis=1)


def align(h_img: np.ndarray, h_ref: np.ndarray) -> np.ndarray:
    """Return image lines (..., 2) as ``(rho, gamma)`` in the orientation of ``h_ref`` (...)."""
    h = np.array(h_img, dtype=float)
    opposite = np.cos(h[..., 1] - h_ref[..., 1]) < 0
    h[..., 0] = np.where(opposite, -h[..., 0], h[..., 0])
    h[..., 1] = np.where(opposite, h[..., 1] + math.pi, h[..., 1])
    return h


def align_cov(V: np.ndarray, h_img: np.ndarray, h_ref: np.ndarray) -> np.ndarray:
    """Covariances (..., 2, 2) of image lines after :func:`align` (rho negated: cov negated)."""
    opposite = np.cos(np.asarray(h_img)[..., 1] - np.asarray(h_ref)[..., 1]) < 0
    out = np.array(V, dtype=float)
    out[..., 0, 1] = np.where(opposite, -out[..., 0, 1], out[..., 0, 1])
    out[..., 1, 0] = np.where(opposite, -out[..., 1, 0], out[..., 1, 0])
    return out


def innovation(h_img: np.ndarray, h_pred: np.ndarray) -> np.ndarray:
    """``h - h^`` (..., 2) with the image line aligned and the angle wrapped."""
    h = align(h_img, h_pred)
    return np.stack([h[..., 0] - h_pred[..., 0], wrap_angle(h[..., 1] - h_pred[..., 1])],
                    axis=-1)


@dataclass(frozen=True, eq=False)
class PredictedLines:
    """Visible model lines in Hough space with their pose Jacobians (eqs. 62-65).

    Attributes:
        visible: the visible lines (edge indices, world and pixel end points).
        h: (M, 2) predicted ``(rho, gamma)``.
        H: (M, 2, 3) ``d(rho, gamma) / d(p_x, p_y, phi)`` = J_H blockdiag(J_P, J_P).
        cov: (M, 2, 2) Sigma_rho_gamma (eq. 65) for the pose covariance given.
        model_cov: (M, 2, 2) covariance of ``h^`` from the model's own inaccuracy (end
            points uncertain by ``model_sigma_m`` across the viewing ray), added to ``V``.
    """

    visible: VisibleLines
    h: np.ndarray
    H: np.ndarray
    cov: np.ndarray
    model_cov: np.ndarray

    def __len__(self) -> int:
        """Return the number of predicted lines."""
        return int(self.h.shape[0])


def predict_lines(visible: VisibleLines, pose, pose_cov: np.ndarray, mount: CameraMount,
                  K: Intrinsics, model_sigma_m: float = 0.0) -> PredictedLines:
    """Project visible model lines to Hough space with covariance (eqs. 62-65).

    ``model_sigma_m`` [m]: std of the model's end points (our addition: the drawn model
    and the built hallway differ, and unmodelled lines such as door frames sit a few
    centimetres from modelled ones); it enters as ``J_H diag((f sigma / Z)^2) J_H^T``.
    """
    m = len(visible)
    if m == 0:
        return PredictedLines(visible, np.zeros((0, 2)), np.zeros((0, 2, 3)),
                              np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))
    pts = visible.points.reshape(-1, 3)
    uv, J_P = projection_jacobian(pts, pose, mount, K)             # eq. 62
    seg = uv.reshape(m, 4)
    h, J_H = hough(seg)                                            # eq. 64
    J_PP = J_P.reshape(m, 4, 3)                                    # blockdiag(J_P1, J_P2) stacked
    H = J_H @ J_PP                                                 # (M, 2, 3)
    cov = H @ np.asarray(pose_cov, dtype=float) @ np.swapaxes(H, 1, 2)   # eq. 65
    from .visibility import world_to_camera
    depth = np.maximum(world_to_camera(pts, pose, mount)[:, 2], 1e-3).reshape(m, 2)
    sd = model_sigma_m * np.repeat(np.column_stack([K.fx / depth[:, 0], K.fy / depth[:, 0],
                                                    K.fx / depth[:, 1], K.fy / depth[:, 1]]),
                                   1, axis=0)
    model_cov = (J_H * sd[:, None, :] ** 2) @ np.swapaxes(J_H, 1, 2)
    return PredictedLines(visible, h, H, cov, model_cov)


def inseparable_lines(pred: PredictedLines, resolve_px: float, max_angle_deg: float,
                      margin_px: float = 0.0) -> np.ndarray:
    """(M,) whether a predicted model line has a neighbour it cannot be told apart from.

    Lines ``i`` and ``j`` are inseparable when their projected segments overlap (each
    extended by ``margin_px``), differ in direction by less than ``max_angle_deg`` and both
    end points of one lie within ``resolve_px`` of the other's line: closer than the edge
    detector resolves, they give one image line (module docstring).
    """
    m = len(pred)
    out = np.zeros(m, dtype=bool)
    if m < 2:
        return out
    px = pred.visible.pixels
    h = pred.h
    c, s = np.cos(h[:, 1]), np.sin(h[:, 1])
    # distance of line j's end points from line i (eq. 58: x cos g + y sin g - rho)
    d1 = np.abs(px[None, :, 0] * c[:, None] + px[None, :, 1] * s[:, None] - h[:, None, 0])
    d2 = np.abs(px[None, :, 2] * c[:, None] + px[None, :, 3] * s[:, None] - h[:, None, 0])
    near = np.maximum(d1, d2) < resolve_px
    dang = np.abs(wrap_angle(2.0 * (h[:, None, 1] - h[None, :, 1]))) / 2.0
    close = near & (dang < math.radians(max_angle_deg)) & _overlap(px, px, margin_px)
    np.fill_diagonal(close, False)
    return close.any(axis=1) | close.any(axis=0)


@dataclass(frozen=True)
class MatchParams:
    """Gating and assignment (module docstring).

    Attributes:
        gate: Mahalanobis bound on ``d^2`` (chi-square, 2 dof; the chapter: 2).
        sigma_px: std of image line end points [px] (measurement noise V). 0.9: on rendered
            hallway runs (seeds 100-101, not the evaluation seeds; 5459 pairs kept by the
            filter at 1.5 px, residuals at the true pose) the smallest value in steps of
            0.1 px that leaves at most 1 % of the pairs outside the 99 % gate (0.84 %;
            0.8 px: 1.08 %; ``model_localization --sigma-px 1.5 --seeds 2 --first-seed 100``).
            The errors are heavy-tailed: the median d^2 is 0.03 (chi-square median 1.39),
            so the core of the pairs is more accurate than this and the tail is left to the
            gate and the residual test.
        min_length_px: shorter image lines are not used.
        overlap_margin_px: an image segment must overlap the projected model segment
            extended by this much at both ends [px].
        ambiguity_deg: two candidates of one model line further apart in angle than this
            are different lines (not pieces of one) ...
        ambiguity_ratio: ... and if their distances are within this factor, the model line
            is ambiguous and dropped.
        resolve_px: model lines closer to a parallel, overlapping model line than this [px]
            are left out (:func:`inseparable_lines`; 0 = off).
    """

    gate: float = 9.21
    sigma_px: float = 0.9
    min_length_px: float = 15.0
    overlap_margin_px: float = 10.0
    ambiguity_deg: float = 3.0
    ambiguity_ratio: float = 2.0
    resolve_px: float = 3.0


@dataclass(frozen=True, eq=False)
class Matches:
    """Model line - image line pairs (eq. 56).

    Attributes:
        model: (K,) indices into the predicted lines.
        image: (K,) indices into the image lines.
        d2: (K,) squared Mahalanobis distances.
        h: (K, 2) image ``(rho, gamma)`` aligned with the prediction (:func:`align`).
        V: (K, 2, 2) image line covariances, in the same (aligned) convention.
        n_ambiguous: model lines dropped as ambiguous.
    """

    model: np.ndarray
    image: np.ndarray
    d2: np.ndarray
    h: np.ndarray
    V: np.ndarray
    n_ambiguous: int = 0

    def __len__(self) -> int:
        """Return the number of pairs."""
        return int(self.model.shape[0])


def image_line_covariance(segments: np.ndarray, sigma_px: float) -> Tuple[np.ndarray,
                                                                          np.ndarray]:
    """Return image lines' ``(rho, gamma)`` (N, 2) and covariance V (N, 2, 2) (eq. 64)."""
    h, J = hough(segments)
    return h, (sigma_px ** 2) * J @ np.swapaxes(J, 1, 2)


def _overlap(pred_px: np.ndarray, img_seg: np.ndarray, margin: float) -> np.ndarray:
    """(M, N) whether each image segment overlaps each projected model segment (+margin)."""
    p0, p1 = pred_px[:, :2], pred_px[:, 2:]
    d = p1 - p0
    L = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
    u = d / L[:, None]
    q0 = img_seg[None, :, :2] - p0[:, None, :]
    q1 = img_seg[None, :, 2:] - p0[:, None, :]
    t0 = np.einsum('mnk,mk->mn', q0, u)
    t1 = np.einsum('mnk,mk->mn', q1, u)
    lo, hi = np.minimum(t0, t1), np.maximum(t0, t1)
    return (hi >= -margin) & (lo <= L[:, None] + margin)


def match_lines(pred: PredictedLines, segments: np.ndarray,
                params: MatchParams = MatchParams()) -> Matches:
    """Gate image lines against predicted model lines and pair them one-to-one.

    Args:
        pred: predicted model lines (:func:`predict_lines`).
        segments: (N, 4) image segments [px] (undistorted).
        params: gating and assignment parameters.
    """
    seg = np.asarray(segments, dtype=float).reshape(-1, 4)
    empty = Matches(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0),
                    np.zeros((0, 2)), np.zeros((0, 2, 2)))
    if len(pred) == 0 or seg.shape[0] == 0:
        return empty
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    keep = np.nonzero(length >= params.min_length_px)[0]
    if keep.size == 0:
        return empty
    seg = seg[keep]
    h_img, V = image_line_covariance(seg, params.sigma_px)
    M, N = len(pred), seg.shape[0]
    nu = innovation(np.broadcast_to(h_img[None], (M, N, 2)),
                    np.broadcast_to(pred.h[:, None], (M, N, 2)))
    S = (pred.cov + pred.model_cov)[:, None] + V[None]            # (M, N, 2, 2)
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    det = np.where(det > 0, det, np.nan)
    d2 = (S[..., 1, 1] * nu[..., 0] ** 2 - 2 * S[..., 0, 1] * nu[..., 0] * nu[..., 1]
          + S[..., 0, 0] * nu[..., 1] ** 2) / det                 # Mahalanobis (gate)
    ok = np.isfinite(d2) & (d2 <= params.gate)
    ok &= _overlap(pred.visible.pixels, seg, params.overlap_margin_px)
    if params.resolve_px > 0:
        ok[inseparable_lines(pred, params.resolve_px, params.ambiguity_deg)] = False
    # ambiguity: two gated candidates of one model line that are different lines
    n_amb = 0
    amb = np.zeros(M, dtype=bool)
    win = math.radians(params.ambiguity_deg)
    for i in np.nonzero(ok.sum(axis=1) >= 2)[0]:
        cand = np.nonzero(ok[i])[0]
        order = cand[np.argsort(d2[i, cand])]
        a, b = order[0], order[1]
        da = abs(float(wrap_angle(2.0 * (h_img[a, 1] - h_img[b, 1])))) / 2.0
        if da > win and d2[i, b] < params.ambiguity_ratio * max(d2[i, a], 1e-9):
            amb[i] = True
            n_amb += 1
    ok[amb] = False
    if not ok.any():
        return Matches(*(empty.model, empty.image, empty.d2, empty.h, empty.V), n_amb)
    from scipy.optimize import linear_sum_assignment  # here: scipy.optimize takes 0.35 s to import
    big = 1e9
    cost = np.where(ok, d2, big)
    r, c = linear_sum_assignment(cost)                           # global nearest neighbour
    good = cost[r, c] < big
    r, c = r[good], c[good]
    h_al = align(h_img[c], pred.h[r])
    V_al = align_cov(V[c], h_img[c], pred.h[r])
    return Matches(r.astype(np.int64), keep[c].astype(np.int64), d2[r, c], h_al, V_al, n_amb)


def model_is_empty(model: LineModel) -> bool:
    """Return True when a model has no edges (nothing to localize against)."""
    return model.edges.shape[0] == 0
