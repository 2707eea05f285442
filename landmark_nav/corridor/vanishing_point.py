"""Vanishing points of image line segments (visual navigation chapter §3.1.2, and beyond).

Frames and units: segments are ``x1 y1 x2 y2`` in ideal (undistorted) pixels, ``x`` right,
``y`` down (see :mod:`landmark_nav.vision.image_lines`); ``K`` is the 3 x 3 intrinsic
matrix. A vanishing point is kept as a *direction* ``d`` (unit 3-vector in the REP 103
camera optical frame: z forward, x right, y down), i.e. a point of the Gaussian sphere; its
homogeneous pixel is ``K d`` and lies at infinity when ``d_z = 0`` (lines parallel in the
image). ``d`` and ``-d`` are the same vanishing point; results are reported with
``d_z >= 0``.

The chapter's method (:func:`chapter_vanishing_point`, §3.1.2): the intersection of every
pair of lines is a candidate; the candidate farthest from the centre of gravity of the
remaining ones is removed, again and again; the VP is the centre of gravity of the few left.
It works in the image plane, so candidates at or near infinity (parallel lines) are lost.

Beyond the chapter (:func:`vanishing_point`, :func:`manhattan_frame`):

* **Projective candidates.** Each segment spans an interpretation plane through the camera
  centre with unit normal ``n = K^-1 p1 x K^-1 p2``; two lines meet in ``d = n_i x n_j``,
  a finite vector also when the lines are parallel in the image (VP at infinity). The
  centre of gravity of axial directions is the principal eigenvector of the weighted
  scatter ``sum w d d^T`` (sign-free), the distance to it the angle ``acos |d . c|``.
* **Weights.** A candidate weighs ``w_i w_j |n_i x n_j|``: segment support (edge pixels,
  or the length when the detector gives none) times the sine of the angle between the two
  planes, which is what makes an intersection well conditioned.
* **Batches.** The chapter removes one candidate per iteration; with thousands of
  candidates we remove the farthest ``removal_fraction`` (5 %) per iteration, down to
  ``final_candidates`` (the chapter's "remaining few"), then one at a time is not needed.
* **Consistency from end-point noise.** A segment agrees with a VP ``v = K d`` when the
  line through its end points, moved by independent perpendicular end-point errors of std
  ``sigma_px``, can pass through ``v``. With the line ``l`` normalised to unit ``(a, b)``,
  unit direction ``u``, length ``L`` and ``v = (v_xy, v_w)`` homogeneous::

      r = l . v,   std(r) = sigma_px sqrt(A^2 + B^2),
      A = ((v_w p2 - v_xy) . u) / L,   B = ((v_xy - v_w p1) . u) / L

  (first-order, exact for straight segments), finite and scale-free also for ``v_w = 0``.
  A real edge is not a perfect straight line (lens distortion, surfaces that are not
  quite flat), so a long segment's direction is not known better than an angle
  ``sigma_angle``: a rotation ``t`` of the segment about its mid-point ``m`` moves the end
  points by ``-/+ t L / 2`` and ``r`` by ``t (v_xy - v_w m) . u`` (``A`` and ``B``
  above), which adds in quadrature::

      std(r)^2 = sigma_px^2 (A^2 + B^2) + sigma_angle^2 ((v_xy - v_w m) . u)^2

  Without it the longest segments (a curb, a roof line) weigh as if they were exact and
  pull a direction off the many shorter lines of the same direction.
  ``z = r / std(r)`` is standard normal for a segment of that direction; ``|z| <= gate``
  (3: 99.7 %) labels the segment a line of that direction (§3.1.2: "lines near the VP
  labelled corridor lines"). The VP is then refined by iteratively reweighted least
  squares on the labelled segments, minimising ``sum z^2`` (smallest eigenvector of
  ``sum (K^T l)(K^T l)^T / std^2``).
* **Manhattan directions.** Given one direction ``d1``, the other two lie on the great
  circle orthogonal to it: each remaining segment proposes ``d2 = d1 x n_i`` (the one
  direction on that circle its plane contains), ``d3 = d1 x d2``; the proposal whose pair
  labels the most segment support wins. ``d1`` hypotheses are the clusters found by
  repeating the candidate clustering on the segments left unlabelled; the triad with the
  largest labelled support is kept and each direction refined on its own segments.

Constants (all in :class:`VPParams`): ``sigma_px = 0.6`` px end-point noise of detected
segments (pixel quantisation 0.29 px plus edge localisation and the wiggle of real edges)
and ``sigma_angle_deg = 0.38`` deg, the maximum-likelihood estimates of the two noise
terms from the residuals of the labelled segmented-Hough segments against York Urban's
true directions (training half, 640 x 480, segments beyond 4 sigma trimmed, labels of the
estimator without the angle term: 0.600 px and 0.380 deg; 0.638 px and 0.388 deg at 320 x 240;
``python benchmarks/bench_vanishing_points.py --noise``; fitted per fold on four fifths of
the images, 0.584-0.606 px and 0.320-0.428 deg, with which the held-out figures of
``... --confidence`` are measured), ``gate = 3.0`` (a 3-sigma
test), ``removal_fraction = 0.05`` and
``final_candidates = 10`` (the chapter's "few"; only speed and the start of the refinement
depend on them), ``max_lines = 150`` longest segments for the candidates (about 11 000
pairs).
"""

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

_EPS = 1e-12


@dataclass(frozen=True)
class VPParams:
    """Parameters of the vanishing-point estimators (see the module docstring).

    Attributes:
        sigma_px: end-point noise std of a segment, perpendicular to it [px].
        sigma_angle_deg: direction noise of a segment beyond its end-point noise (edges
            not quite straight, lens distortion) [deg].
        gate: |z| bound that labels a segment as belonging to a VP.
        removal_fraction: fraction of the candidates removed per clustering iteration.
        final_candidates: candidates left when the clustering stops (the chapter's "few").
        max_lines: at most this many segments (the heaviest) make candidates.
        min_length_px: shorter segments are ignored [px].
        refine_iterations: IRLS iterations of the refinement.
        hypotheses: d1 hypotheses tried by :func:`manhattan_frame` (peaks of the candidate
            histogram, besides the clustered dominant direction).
        orthogonal: before each direction of :func:`manhattan_frame` is refined on its own
            lines, refine the triad jointly as one rotation (:func:`refine_manhattan`)
            and label the segments by it: a direction whose own fit went to the wrong
            lines (few receding lines of a frontal facade, clutter) is brought back to
            the one orthogonal to the other two first. York Urban training half,
            corridor direction within 2 deg, held out (noise fitted per fold): 640 x 480
            92.2 -> 96.1 %, 320 x 240 84.3 -> 92.2 % (False: the triad of the hypothesis
            search is refined as it is).
    """

    sigma_px: float = 0.6
    sigma_angle_deg: float = 0.38
    gate: float = 3.0
    removal_fraction: float = 0.05
    final_candidates: int = 10
    max_lines: int = 150
    min_length_px: float = 10.0
    refine_iterations: int = 10
    hypotheses: int = 12
    orthogonal: bool = True


@dataclass(frozen=True, eq=False)
class VanishingPoint:
    """One vanishing direction.

    Attributes:
        direction: (3,) unit vector in the optical frame, ``d_z >= 0``.
        pixel_h: (3,) homogeneous pixel ``K d`` (last entry 0 at infinity).
        inliers: (N,) bool, the segments labelled as lines of this direction.
        support: summed weight of the inlier segments.
    """

    direction: np.ndarray
    pixel_h: np.ndarray
    inliers: np.ndarray
    support: float

    @property
    def pixel(self) -> Optional[np.ndarray]:
        """(2,) pixel of the VP, or None when it lies at infinity (|d_z| < 1e-9)."""
        if abs(self.direction[2]) < 1e-9:
            return None
        return self.pixel_h[:2] / self.pixel_h[2]


@dataclass(frozen=True, eq=False)
class ManhattanFrame:
    """Three (near-)orthogonal vanishing directions.

    Attributes:
        directions: (3, 3) unit directions as columns, each with ``d_z >= 0``; column 0 is
            the one closest to the optical axis (largest ``|d_z|``).
        labels: (N,) index of the direction each segment belongs to, -1 for none.
        points: the three :class:`VanishingPoint` in the column order.
        score: MSAC-scored segment support of the three directions (the triad score).
        alternatives: ``(score, (3, 3) directions)`` of every triad hypothesis tried
            (before the final relabelling), for the confidence of
            :mod:`.vp_confidence`.
    """

    directions: np.ndarray
    labels: np.ndarray
    points: Tuple[VanishingPoint, VanishingPoint, VanishingPoint]
    score: float = 0.0
    alternatives: Tuple[Tuple[float, np.ndarray], ...] = ()


# ----------------------------------------------------------------------------- helpers
def _check(segments: np.ndarray, K: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    seg = np.asarray(segments, dtype=float)
    if seg.ndim != 2 or seg.shape[1] != 4:
        raise ValueError(f'segments must be an (N, 4) array; got shape {seg.shape}')
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f'K must be a finite 3x3 intrinsic matrix with fx, fy > 0; got {K}')
    return seg, K


def _canonical(d: np.ndarray) -> np.ndarray:
    """Return unit direction(s) with d_z >= 0 (ties at d_z = 0 broken by x, then y)."""
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    key = np.where(np.abs(d[..., 2]) > 1e-12, d[..., 2],
                   np.where(np.abs(d[..., 0]) > 1e-12, d[..., 0], d[..., 1]))
    return np.where((key < 0)[..., None], -d, d)


def plane_normals(segments: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N, 3) unit normals of the interpretation planes of the segments (optical frame)."""
    seg, K = _check(segments, K)
    Kinv = np.linalg.inv(K)
    p1 = np.column_stack([seg[:, :2], np.ones(len(seg))]) @ Kinv.T
    p2 = np.column_stack([seg[:, 2:], np.ones(len(seg))]) @ Kinv.T
    n = np.cross(p1, p2)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), _EPS)


def segment_weights(segments: np.ndarray, weights: Optional[np.ndarray] = None) -> np.ndarray:
    """Segment weights: the given support, or the length [px] when None."""
    seg = np.asarray(segments, dtype=float).reshape(-1, 4)
    if weights is not None:
        return np.asarray(weights, dtype=float).reshape(-1)
    return np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])


class _Geometry:
    """Per-segment terms of the consistency test, precomputed for one K (private).

    For directions ``D`` (M, 3) in the optical frame, ``v = K d`` and (module docstring)
    ``r = l . v = d . (K^T l)``, ``v_xy . u = d . (K^T (u, 0))``, ``v_w = d_z``.
    """

    def __init__(self, seg: np.ndarray, K: np.ndarray, sigma_px: float,
                 sigma_angle: float = 0.0) -> None:
        p1, p2 = seg[:, :2], seg[:, 2:]
        dl = p2 - p1
        self.length = np.maximum(np.hypot(dl[:, 0], dl[:, 1]), _EPS)
        u = dl / self.length[:, None]
        nrm = np.column_stack([-u[:, 1], u[:, 0]])
        c = -(nrm * p1).sum(1)                   # l = (nrm, c): l . (x, y, 1) = distance
        self.kl = K.T @ np.vstack([nrm.T, c])    # (3, N) columns K^T l
        self.ku = K.T @ np.vstack([u.T, np.zeros(len(seg))])
        self.pu1 = (p1 * u).sum(1)
        self.pu2 = (p2 * u).sum(1)
        self.sigma = float(sigma_px)
        self.sigma_angle = float(sigma_angle)

    def subset(self, idx: np.ndarray) -> '_Geometry':
        g = object.__new__(_Geometry)
        g.length, g.kl, g.ku = self.length[idx], self.kl[:, idx], self.ku[:, idx]
        g.pu1, g.pu2, g.sigma = self.pu1[idx], self.pu2[idx], self.sigma
        g.sigma_angle = self.sigma_angle
        return g

    def terms(self, D: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return the (M, N) residuals ``r = l . K d`` and their standard deviations."""
        D = np.atleast_2d(D)
        r = D @ self.kl
        vu = D @ self.ku
        vw = D[:, 2:3]
        a = (vw * self.pu2 - vu) / self.length
        b = (vu - vw * self.pu1) / self.length
        along = vu - 0.5 * vw * (self.pu1 + self.pu2)    # (v_xy - v_w m) . u
        return r, np.sqrt(self.sigma ** 2 * (a * a + b * b) + (self.sigma_angle * along) ** 2)

    def z(self, D: np.ndarray) -> np.ndarray:
        """Return the (M, N) z-scores of the segments against directions D (M, 3)."""
        r, std = self.terms(D)
        with np.errstate(divide='ignore', invalid='ignore'):
            z = np.where(std > 0, r / std, np.inf)
        return np.where(np.isnan(z), np.inf, z)


def _geometry(seg: np.ndarray, K: np.ndarray, params: VPParams) -> _Geometry:
    return _Geometry(seg, K, params.sigma_px, np.radians(params.sigma_angle_deg))


def residual_terms(segments: np.ndarray, K: np.ndarray, d: np.ndarray
                   ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return, per segment against direction ``d``, ``r`` and the two variance factors.

    ``std(r)^2 = sigma_px^2 a + sigma_angle^2 b`` (module docstring) with the returned
    ``(r, a, b)``, each (N,), for fitting the two noise terms to residuals of known
    directions.
    """
    seg, K = _check(segments, K)
    geo = _Geometry(seg, K, 1.0)
    r, s_end = (t[0] for t in geo.terms(np.asarray(d, dtype=float)))
    geo.sigma, geo.sigma_angle = 0.0, 1.0
    return r, s_end ** 2, geo.terms(np.asarray(d, dtype=float))[1][0] ** 2


def consistency(segments: np.ndarray, v: np.ndarray, sigma_px: float = 1.0) -> np.ndarray:
    """Return z-scores of segments against homogeneous VP pixels (see the module docstring).

    Args:
        segments: (N, 4) end points [px].
        v: (3,) or (M, 3) homogeneous pixels (``w = 0`` at infinity).
        sigma_px: perpendicular end-point noise std [px].

    Returns:
        (N,) or (M, N) z-scores (``|z|`` large = inconsistent; inf for a degenerate case).
    """
    seg = np.asarray(segments, dtype=float).reshape(-1, 4)
    v = np.asarray(v, dtype=float)
    z = _Geometry(seg, np.eye(3), sigma_px).z(v.reshape(-1, 3))
    return z[0] if v.ndim == 1 else z


def _axial_mean(d: np.ndarray, w: np.ndarray) -> np.ndarray:
    s = (d * w[:, None]).T @ d
    _, vec = np.linalg.eigh(s)
    return vec[:, -1]


def _pair_candidates(n: np.ndarray, w: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    i, j = np.triu_indices(n.shape[0], 1)
    d = np.cross(n[i], n[j])
    s = np.linalg.norm(d, axis=1)
    ok = s > 1e-9
    return d[ok] / s[ok, None], (w[i] * w[j] * s)[ok]


def cluster_directions(d: np.ndarray, w: np.ndarray, params: VPParams = VPParams()) -> np.ndarray:
    """Find the dominant cluster by farthest-candidate removal on the sphere (§3.1.2).

    Args:
        d: (M, 3) unit candidate directions (sign irrelevant).
        w: (M,) candidate weights >= 0.
        params: ``removal_fraction`` and ``final_candidates``.

    Returns:
        (3,) unit centre of gravity of the remaining candidates.
    """
    if d.shape[0] == 0:
        raise ValueError('no vanishing-point candidates (fewer than two non-parallel lines)')
    keep = np.arange(d.shape[0])
    dw = d * w[:, None]
    scatter = dw.T @ d
    c = np.linalg.eigh(scatter)[1][:, -1]
    while keep.size > params.final_candidates:
        cosang = np.abs(d[keep] @ c)
        n_rm = max(1, int(params.removal_fraction * keep.size))
        n_rm = min(n_rm, keep.size - params.final_candidates)
        order = np.argpartition(cosang, n_rm)       # smallest |cos| = farthest
        gone, keep = keep[order[:n_rm]], keep[order[n_rm:]]
        scatter = scatter - dw[gone].T @ d[gone]    # downdate: same as recomputing
        if np.sum(w[keep]) <= 0:
            break
        c = np.linalg.eigh(scatter)[1][:, -1]
    return c


def refine_direction(segments: np.ndarray, K: np.ndarray, d: np.ndarray,
                     weights: Optional[np.ndarray] = None,
                     params: VPParams = VPParams(),
                     allowed: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Refine a direction by IRLS on its consistent segments.

    Each iteration minimises ``sum z_i^2`` over the consistent segments (``|z| <= gate``,
    and ``allowed`` when given) with the variances of the previous direction, then
    relabels. ``weights`` are not used: the end-point noise model already weighs each
    segment by its geometry (``1 / std(r)^2``).

    Returns:
        (unit direction (3,), inlier mask (N,)). The direction is unchanged when fewer than
        two segments are consistent with it.
    """
    seg, K = _check(segments, K)
    del weights
    D, inl = _refine_many(_geometry(seg, K, params), np.asarray(d, dtype=float)[None],
                          params, None if allowed is None else np.asarray(allowed)[None])
    return D[0], inl[0]


def _refine_many(geo: _Geometry, D0: np.ndarray, params: VPParams,
                 allowed: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """:func:`refine_direction` of M starts at once: (M, 3) directions, (M, N) inliers.

    Each row iterates on its own (it stops when it has fewer than two usable inliers or
    its labels and direction no longer change); the normal matrices of all rows are
    formed in one product and their eigenvectors in one call.
    """
    D = np.asarray(D0, dtype=float).reshape(-1, 3)
    D = D / np.linalg.norm(D, axis=1, keepdims=True)
    m, n = D.shape[0], geo.kl.shape[1]
    ok = np.ones((m, n), dtype=bool) if allowed is None else \
        np.broadcast_to(np.asarray(allowed, dtype=bool), (m, n))
    inl = ok & (np.abs(geo.z(D)) <= params.gate)
    active = np.ones(m, dtype=bool)
    for _ in range(params.refine_iterations):
        active &= np.count_nonzero(inl, axis=1) >= 2
        idx = np.nonzero(active)[0]
        if idx.size == 0:
            break
        std2 = geo.terms(D[idx])[1] ** 2
        good = inl[idx] & np.isfinite(std2) & (std2 > 0)
        enough = np.count_nonzero(good, axis=1) >= 2
        active[idx[~enough]] = False
        idx, good, std2 = idx[enough], good[enough], std2[enough]
        if idx.size == 0:
            break
        w = np.where(good, 1.0 / np.where(good, std2, 1.0), 0.0)
        normal = (w[:, None, :] * geo.kl[None]) @ geo.kl.T          # (A, 3, 3)
        d_new = np.linalg.eigh(normal)[1][:, :, 0]
        d_old = D[idx]
        d_new = np.where((np.sum(d_new * d_old, axis=1) >= 0)[:, None], d_new, -d_new)
        moved = np.linalg.norm(d_new - d_old, axis=1)
        D[idx] = d_new
        new_inl = ok[idx] & (np.abs(geo.z(d_new)) <= params.gate)
        done = np.all(new_inl == inl[idx], axis=1) & (moved < 1e-9)
        inl[idx] = new_inl
        active[idx[done]] = False
    return _canonical(D), inl


def direction_covariance(segments: np.ndarray, K: np.ndarray, d: np.ndarray,
                         inliers: np.ndarray, sigma_px: float = 0.6,
                         sigma_angle_deg: float = VPParams.sigma_angle_deg) -> np.ndarray:
    """Return the (3, 3) covariance of a VP direction refined on its inlier segments.

    First order: the direction minimises ``sum z_i^2`` over the inliers (IRLS), whose
    information matrix on the sphere is ``J = sum (K^T l_i)(K^T l_i)^T / std_i^2``; the
    covariance is its pseudo-inverse on the plane tangent at ``d`` (rank 2).
    """
    seg, K = _check(segments, K)
    d = np.asarray(d, dtype=float) / np.linalg.norm(d)
    inl = np.asarray(inliers, dtype=bool)
    geo = _Geometry(seg[inl], K, sigma_px, np.radians(sigma_angle_deg))
    std = geo.terms(d)[1][0]
    ok = np.isfinite(std) & (std > 0)
    m = geo.kl[:, ok] / std[ok]
    J = m @ m.T
    T = np.linalg.svd(d[None, :])[2][1:]          # (2, 3) tangent basis
    Jt = T @ J @ T.T
    if np.count_nonzero(ok) < 2 or np.linalg.cond(Jt) > 1e12:
        return np.full((3, 3), np.inf)
    return T.T @ np.linalg.inv(Jt) @ T


def leave_one_out_directions(segments: np.ndarray, K: np.ndarray, d: np.ndarray,
                             inliers: np.ndarray, params: VPParams = VPParams()) -> np.ndarray:
    """Return the direction refined without each of its inlier segments in turn.

    Row ``i`` is :func:`refine_direction` from ``d`` on the inliers but the ``i``-th (in
    index order), for the influence of single segments on the direction (the jackknife's
    deleted estimates); (n, 3) for ``n`` inliers, (0, 3) when fewer than three.
    """
    seg, K = _check(segments, K)
    idx = np.nonzero(np.asarray(inliers, dtype=bool))[0]
    if idx.size < 3:
        return np.zeros((0, 3))
    allowed = np.zeros((idx.size, len(seg)), dtype=bool)
    allowed[:, idx] = True
    allowed[np.arange(idx.size), idx] = False
    d = np.asarray(d, dtype=float)
    return _refine_many(_geometry(seg, K, params), np.repeat(d[None], idx.size, 0), params,
                        allowed)[0]


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rotation_information(geo: _Geometry, R: np.ndarray, labels: np.ndarray
                          ) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``(J, b)``: normal equations of ``sum z^2`` in a rotation ``w`` of the frame.

    Column ``k`` of ``R`` rotated by ``w`` is ``d_k + w x d_k``, so a residual of its
    segment ``i`` moves by ``w . (d_k x K^T l_i)``: with ``g_i = d_k x K^T l_i`` and the
    variance ``std_i^2`` at ``R`` (module docstring), ``J = sum g g^T / std^2`` and
    ``b = sum g r / std^2`` over the segments labelled ``k``.
    """
    J, b = np.zeros((3, 3)), np.zeros(3)
    for k in range(3):
        idx = np.nonzero(labels == k)[0]
        if idx.size == 0:
            continue
        sub = geo.subset(idx)
        r, std = (t[0] for t in sub.terms(R[:, k]))
        ok = np.isfinite(std) & (std > 0)
        g = np.cross(R[:, k], sub.kl[:, ok].T)
        w = 1.0 / std[ok] ** 2
        J += (g * w[:, None]).T @ g
        b += g.T @ (w * r[ok])
    return J, b


def refine_manhattan(geo: _Geometry, D: np.ndarray, params: VPParams) -> np.ndarray:
    """Refine three directions jointly as the columns of one rotation (IRLS, Gauss-Newton).

    Extension (Manhattan world): the nearest rotation to ``D`` (columns) is refined by
    minimising ``sum z^2`` of the exclusively labelled segments of all three directions
    (:func:`_labels`) over a rotation ``w`` (:func:`_rotation_information`,
    ``w = -J^-1 b``), relabelling after each step. Stops when the step is below 1e-9
    rad, after ``refine_iterations`` steps, or when the lines do not fix the rotation
    (``J`` singular).

    Returns:
        (3, 3) orthonormal columns, in the order of ``D``'s.
    """
    U, _, Vt = np.linalg.svd(D)
    R = U @ Vt
    for _ in range(params.refine_iterations):
        J, b = _rotation_information(geo, R, _labels(geo, R, params, exclusive=True))
        if np.linalg.cond(J) > 1e12:
            break
        w = -np.linalg.solve(J, b)
        th = float(np.linalg.norm(w))
        S = _skew(w / max(th, _EPS))
        R = (np.eye(3) + np.sin(th) * S + (1.0 - np.cos(th)) * S @ S) @ R   # Rodrigues
        if th < 1e-9:
            break
    return R


def _pair_starts(D: np.ndarray, support: np.ndarray) -> list:
    """Return the orthonormal starts of :func:`refine_manhattan` from a triad ``D``.

    ``D``'s nearest rotation, and for each pair of columns the better supported one kept
    as it is, the other made orthogonal to it (Gram-Schmidt) and the third their cross
    product: a wrong or weakly supported direction does not then pull a well supported
    one off its lines (with the two directions made orthogonal symmetrically instead, a
    rendered corridor frame at 320 x 240 with two and three lines along the cross
    directions lost its six corridor lines).
    """
    U, _, Vt = np.linalg.svd(D)
    out = [U @ Vt]
    for a, b in ((0, 1), (0, 2), (1, 2)):
        if support[b] > support[a]:
            a, b = b, a
        x = D[:, a] / np.linalg.norm(D[:, a])
        y = D[:, b] - (D[:, b] @ x) * x
        y /= max(np.linalg.norm(y), _EPS)
        R = np.empty((3, 3))
        R[:, a], R[:, b] = x, y
        R[:, 3 - a - b] = np.cross(x, y) if (a, b) in ((0, 1), (1, 2), (2, 0)) else \
            np.cross(y, x)
        out.append(R)
    return out


def _make_vp(seg: np.ndarray, K: np.ndarray, d: np.ndarray, inl: np.ndarray,
             w: np.ndarray) -> VanishingPoint:
    d = _canonical(d)
    return VanishingPoint(direction=d, pixel_h=K @ d, inliers=inl,
                          support=float(np.sum(w[inl])))


def _usable(seg: np.ndarray, w: np.ndarray, params: VPParams) -> np.ndarray:
    L = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    ok = (L >= params.min_length_px) & np.all(np.isfinite(seg), axis=1) & (w > 0)
    idx = np.nonzero(ok)[0]
    if idx.size > params.max_lines:
        idx = idx[np.argsort(-w[idx], kind='stable')[:params.max_lines]]
    return idx


# ----------------------------------------------------------------------------- methods
def chapter_vanishing_point(segments: np.ndarray, K: np.ndarray,
                            params: VPParams = VPParams()) -> VanishingPoint:
    """Find the VP by the chapter's method (§3.1.2): image plane, unweighted, no refinement.

    Candidates are the pixel intersections of all pairs of the (at most ``max_lines``
    longest) segments; pairs parallel in the image (no finite intersection) are skipped,
    as the chapter cannot represent them. The candidate farthest (Euclidean) from the centre
    of gravity is removed (in batches of ``removal_fraction``) until ``final_candidates``
    are left; their centre of gravity is the VP. Lines with ``|z| <= gate`` are labelled.

    Raises:
        ValueError: fewer than two non-parallel segments.
    """
    seg, K = _check(segments, K)
    L = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    idx = _usable(seg, L, params)
    p1 = np.column_stack([seg[idx, :2], np.ones(idx.size)])
    p2 = np.column_stack([seg[idx, 2:], np.ones(idx.size)])
    lines = np.cross(p1, p2)
    i, j = np.triu_indices(idx.size, 1)
    x = np.cross(lines[i], lines[j])
    scale = np.maximum(np.abs(x[:, :2]).max(1), _EPS)
    ok = np.abs(x[:, 2]) > 1e-9 * scale
    if not np.any(ok):
        raise ValueError('no finite vanishing-point candidates (fewer than two '
                         'non-parallel lines)')
    pts = x[ok, :2] / x[ok, 2:3]
    keep = np.arange(pts.shape[0])
    c = pts.mean(0)
    while keep.size > params.final_candidates:
        dist = np.hypot(*(pts[keep] - c).T)
        n_rm = max(1, int(params.removal_fraction * keep.size))
        n_rm = min(n_rm, keep.size - params.final_candidates)
        keep = keep[np.argpartition(-dist, n_rm)[n_rm:]]
        c = pts[keep].mean(0)
    v = np.array([c[0], c[1], 1.0])
    d = np.linalg.solve(K, v)
    inl = np.abs(consistency(seg, v, params.sigma_px)) <= params.gate
    return _make_vp(seg, K, d, inl, L)


def vanishing_point(segments: np.ndarray, K: np.ndarray, weights: Optional[np.ndarray] = None,
                    params: VPParams = VPParams(),
                    exclude: Optional[np.ndarray] = None) -> VanishingPoint:
    """Find the dominant vanishing direction: weighted projective clustering + IRLS.

    Starts: the chapter's farthest-removal cluster (on the sphere, weighted) and the
    ``hypotheses`` strongest peaks of the candidate histogram (the removal alone follows
    the centre of gravity of all candidates, so it loses a VP far from it, e.g. at
    infinity among clutter near the image centre). Each start is refined (IRLS) and the
    one with the largest MSAC-scored segment support is returned.

    Args:
        segments: (N, 4) ideal pixels.
        K: (3, 3) intrinsics.
        weights: (N,) segment support, or None for the lengths.
        params: see :class:`VPParams`.
        exclude: (N,) bool, segments not to use for candidates (e.g. already labelled).

    Raises:
        ValueError: fewer than two usable non-parallel segments.
    """
    seg, K = _check(segments, K)
    w = segment_weights(seg, weights)
    if w.shape[0] != seg.shape[0]:
        raise ValueError(f'{w.shape[0]} weights for {seg.shape[0]} segments')
    w_use = w if exclude is None else np.where(exclude, 0.0, w)
    idx = _usable(seg, w_use, params)
    n = plane_normals(seg[idx], K)
    d, cw = _pair_candidates(n, w[idx])
    if d.shape[0] == 0:
        raise ValueError('no vanishing-point candidates (fewer than two non-parallel lines)')
    geo = _geometry(seg, K, params)
    sub = geo.subset(idx)
    starts = np.vstack([cluster_directions(d, cw, params)[None],
                        sphere_peaks(d, cw, params.hypotheses)])
    refined = _refine_many(sub, starts, params)[0]
    scores = np.sum(w_use * _msac(np.abs(geo.z(refined)), params.gate), axis=1)
    best = refined[int(np.argmax(scores))]              # the first of equal scores
    inl_all = np.abs(geo.z(best)[0]) <= params.gate
    return _make_vp(seg, K, best, inl_all, w)


def _orthogonal_pair(geo: _Geometry, normals: np.ndarray, d1: np.ndarray, free: np.ndarray,
                     w: np.ndarray, params: VPParams) -> Tuple[np.ndarray, np.ndarray, float]:
    """Best (d2, d3) on the great circle orthogonal to d1; returns (d2, d3, support)."""
    idx = np.nonzero(free)[0]
    if idx.size > params.max_lines:
        idx = idx[np.argsort(-w[idx], kind='stable')[:params.max_lines]]
    if idx.size == 0:
        e = np.linalg.svd(d1[None, :])[2]
        return e[1], e[2], 0.0
    prop = np.cross(d1, normals[idx])
    s = np.linalg.norm(prop, axis=1)
    ok = s > 1e-9
    prop = prop[ok] / s[ok, None]
    if prop.shape[0] == 0:
        e = np.linalg.svd(d1[None, :])[2]
        return e[1], e[2], 0.0
    prop3 = np.cross(d1, prop)
    sub = geo.subset(idx)
    z2 = np.abs(sub.z(prop))
    z3 = np.abs(sub.z(prop3))
    score = (_msac(np.minimum(z2, z3), params.gate) * w[idx]).sum(1)
    k = int(np.argmax(score))
    return prop[k], prop3[k], float(score[k])


def sphere_peaks(d: np.ndarray, w: np.ndarray, count: int,
                 bin_deg: float = 2.0) -> np.ndarray:
    """Return the ``count`` strongest local maxima of a weighted histogram of axial directions.

    The half sphere ``d_z >= 0`` is binned in polar angle and azimuth (``bin_deg`` bins;
    directions on the rim are entered at both azimuths, which are the same point), each
    candidate spread over its 3 x 3 neighbourhood by the maximum filter's plateau test.

    Returns:
        (k, 3) unit directions (bin-weighted means of the candidates in each peak bin),
        k <= count, strongest first.
    """
    d = _canonical(d)
    n_p = int(np.ceil(90.0 / bin_deg)) + 1
    n_a = int(np.ceil(360.0 / bin_deg))
    polar = np.degrees(np.arccos(np.clip(d[:, 2], -1.0, 1.0)))
    azim = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 360.0
    ip = np.minimum((polar / bin_deg).astype(np.int64), n_p - 1)
    ia = np.minimum((azim / bin_deg).astype(np.int64), n_a - 1)
    rim = polar > 90.0 - bin_deg
    ia2 = np.minimum((((azim + 180.0) % 360.0) / bin_deg).astype(np.int64), n_a - 1)
    flat = np.concatenate([ip * n_a + ia, (ip * n_a + ia2)[rim]])
    wt = np.concatenate([w, w[rim]])
    hist = np.bincount(flat, weights=wt, minlength=n_p * n_a).reshape(n_p, n_a)
    from scipy.ndimage import maximum_filter, uniform_filter  # on first use, not at node start
    sm = uniform_filter(hist, size=3, mode=('nearest', 'wrap'))
    peak = (sm == maximum_filter(sm, size=5, mode=('nearest', 'wrap'))) & (sm > 0)
    cells = np.nonzero(peak.ravel())[0]
    cells = cells[np.argsort(-sm.ravel()[cells], kind='stable')][:count]
    out = []
    cell_of = ip * n_a + ia
    for c in cells:
        pr, az = divmod(int(c), n_a)
        near = ((np.abs(ip - pr) <= 1)
                & (np.minimum(np.abs(ia - az), n_a - np.abs(ia - az)) <= 1))
        if not np.any(near):
            near = cell_of == c
        if np.any(near):
            out.append(_axial_mean(d[near], w[near]))
    return np.array(out).reshape(-1, 3)


def _msac(z: np.ndarray, gate: float) -> np.ndarray:
    """Return the truncated quadratic score of |z|: 1 at z = 0, 0 beyond the gate (MSAC)."""
    return np.maximum(0.0, 1.0 - (z / gate) ** 2)


def _labels(geo: _Geometry, D: np.ndarray, params: VPParams, exclusive: bool) -> np.ndarray:
    """Direction index of each segment (the smallest |z| within the gate), -1 for none.

    With ``exclusive`` a segment consistent with two or more directions gets -1 too (it
    cannot tell them apart: e.g. a segment pointing at both VPs).
    """
    z = np.abs(geo.z(D.T))
    lab = np.argmin(z, axis=0)
    within = z <= params.gate
    ok = within[lab, np.arange(z.shape[1])]
    if exclusive:
        ok &= within.sum(0) == 1
    return np.where(ok, lab, -1)


def _triad_support(geo: _Geometry, D: np.ndarray, w: np.ndarray, params: VPParams) -> float:
    """Return the MSAC-scored weight of the segments consistent with a column of D."""
    z = np.abs(geo.z(D.T)).min(0)
    return float(np.sum(w * _msac(z, params.gate)))


def manhattan_frame(segments: np.ndarray, K: np.ndarray, weights: Optional[np.ndarray] = None,
                    params: VPParams = VPParams()) -> ManhattanFrame:
    """Three orthogonal vanishing directions (see the module docstring), each refined.

    Raises:
        ValueError: fewer than two usable non-parallel segments.
    """
    seg, K = _check(segments, K)
    w = segment_weights(seg, weights)
    idx = _usable(seg, w, params)
    geo = _geometry(seg, K, params)
    normals = plane_normals(seg, K)
    cand, cw = _pair_candidates(normals[idx], w[idx])
    if cand.shape[0] == 0:
        raise ValueError('no vanishing-point candidates (fewer than two non-parallel lines)')
    sub = geo.subset(idx)
    starts = np.vstack([cluster_directions(cand, cw, params)[None],
                        sphere_peaks(cand, cw, params.hypotheses)])
    hyps = []
    for d1 in _refine_many(sub, starts, params)[0]:
        if not any(abs(d1 @ e) > 1.0 - 1e-12 for e in hyps):   # same start, same triad
            hyps.append(d1)
    in1 = np.abs(geo.z(np.array(hyps))) <= params.gate
    triads = []
    for d1, used in zip(hyps, in1):
        d2, d3, _ = _orthogonal_pair(geo, normals, d1, ~used, w, params)
        triads += [d1, d2, d3]
    refined = _refine_many(geo, np.array(triads), params)[0]
    scored = [(_triad_support(geo, refined[3 * h:3 * h + 3].T, w, params),
               refined[3 * h:3 * h + 3].T) for h in range(len(hyps))]
    D = max(scored, key=lambda sd: sd[0])[1]       # the first of equal scores
    if params.orthogonal:
        # the triad refined jointly as a rotation from each start (the best MSAC triad score
        # wins) labels the segments as a Manhattan frame would; each direction is then
        # refined on its own lines below, so a frame that is not quite orthogonal in the
        # image (an unmodelled lens distortion) keeps its own directions
        lab = _labels(geo, D, params, exclusive=True)
        support = np.bincount(lab[lab >= 0], w[lab >= 0], minlength=3)
        rotations = [refine_manhattan(geo, R0, params) for R0 in _pair_starts(D, support)]
        D = max(rotations, key=lambda R: _triad_support(geo, R, w, params))
    for _ in range(params.refine_iterations):      # exclusive labels, then refine each
        lab = _labels(geo, D, params, exclusive=True)
        D_new = _refine_many(geo, D.T, params, lab[None, :] == np.arange(3)[:, None])[0].T
        if np.allclose(np.abs(np.sum(D_new * D, axis=0)), 1.0, atol=1e-12):
            D = D_new
            break
        D = D_new
    lab = _labels(geo, D, params, exclusive=False)
    order = np.argsort(-np.abs(D[2]), kind='stable')
    D = D[:, order]
    new_lab = np.full_like(lab, -1)
    for new, old in enumerate(order):
        new_lab[lab == old] = new
    points = tuple(_make_vp(seg, K, D[:, k], new_lab == k, w) for k in range(3))
    return ManhattanFrame(directions=np.column_stack([p.direction for p in points]),
                          labels=new_lab, points=points,
                          score=_triad_support(geo, D, w, params), alternatives=tuple(scored))


def corridor_vanishing_point(segments: np.ndarray, K: np.ndarray,
                             weights: Optional[np.ndarray] = None,
                             params: VPParams = VPParams()) -> VanishingPoint:
    """Return the corridor direction: the Manhattan direction closest to the optical axis.

    A forward-looking camera in a corridor sees the corridor's vanishing point near the
    image centre, while the vertical and cross-corridor directions lie far out (often at
    infinity); the dominant cluster alone may be the vertical one (door frames).
    """
    return manhattan_frame(segments, K, weights, params).points[0]
