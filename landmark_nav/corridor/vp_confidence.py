"""Support, calibrated uncertainty and a confidence flag for each Manhattan direction.

A vanishing direction estimated from image lines can be wrong in two ways: a little (the
end-point noise of its lines, lens distortion, edges that are not quite straight) or by a
lot (the wrong set of lines won: a frontal facade with few receding lines, clutter). The
first-order covariance of :func:`~.vanishing_point.direction_covariance` only knows the
first. Per direction this module states:

* ``support``: the inlier segments (count, summed weight), ``sigma_cov``, the square
  root of the largest eigenvalue of the first-order covariance [rad], and (reported, not
  used by the model) ``ambiguity``, the MSAC score of the best competing Manhattan
  hypothesis that does *not* contain this direction (none of its columns within 2 deg)
  divided by the chosen frame's score (near or above 1: another frame explains the lines
  about as well; 0 when no hypothesis disagrees).
* ``p_correct``: the probability that the direction is within 2 deg of the truth, a
  logistic model of the spread in pixels at the focal length ``f`` (``sigma_cov f``: the
  same lines give the same value at any image size, where ``sigma_cov`` itself doubles
  when the image is halved, while whether a direction took the wrong lines depends on
  the lines, not on the pixel size), of the number ``n`` of its inlier segments and of
  the frame's weakest direction, the largest finite ``sigma_cov`` of its three directions
  ``sigma_frame`` (a frame one of whose directions has few or short lines fixes its
  rotation, and so the labelling of the other directions' lines, poorly: on York's
  frontal views the corridor direction then often went to the wrong lines; a direction
  without the two lines that fix it takes no lines from the others and does not count,
  as in a corridor seen along its axis with no line across it; York has no such frame)::

      p = 1 / (1 + exp(-(w0 + w1 ln(sigma_cov f / 1 px) + w2 ln n
                          + w3 ln(sigma_frame f / 1 px) + w4 ln(o / 1 rad) + w5 ln i)))

  of the direction's orthogonality residual ``o``, its angle to the normal of the
  frame's other two directions (:func:`orthogonality_residuals`; after the joint
  refinement each direction is refined on its own lines, and one that went to lines of no
  Manhattan direction, such as pavement edges, leaves the triad's orthogonality; York's
  true triads are themselves up to 4 deg off, so this is a soft sign, fitted ``w4`` about
  -0.8), and of its influence ``i`` (:func:`influence`): the largest angle by which the
  direction moves when one of its inlier segments is left out (the jackknife's deleted
  estimates, each refined as the direction was), over its first-order spread
  ``sigma_cov`` -- the deletion diagnostic DFBETAS of regression (Belsley, Kuh, Welsch,
  *Regression Diagnostics*, 1980, §2.1), which the first-order covariance cannot show: it
  assumes every inlier is a line of the direction. Many lines of the direction give a
  value below 1 (York's median 0.8); a direction resting on one or two of its lines,
  whose deletion moves it by more than its stated spread, a larger one (fitted ``w5``
  about -0.8; it is the one feature of the model that depends on how the inliers agree
  with each other rather than on their number and geometry). The ambiguity, the
  a-contrario number below as a value and the angle between the direction and the jointly
  refined triad's did not separate wrong directions from right ones on York; held out
  they changed the confident fraction by a few per cent and the precision not at all or
  for the worse.
* an error model, a two-component mixture of isotropic Gaussians on the tangent plane of
  the sphere (the angular error ``e`` of each component Rayleigh distributed): with
  probability ``p`` the correct mode, ``sigma = sqrt((a sigma_cov)^2 + b^2)`` (the
  first-order spread scaled by ``a`` plus a floor ``b`` for what the line noise model leaves
  out); otherwise the wrong mode, ``sigma_wrong`` (the RMS error of the wrong directions of
  the calibration set). Its 95 % radius solves
  ``p (1 - exp(-r^2 / 2 sigma^2)) + (1 - p) (1 - exp(-r^2 / 2 sigma_wrong^2)) = 0.95``
  (capped at 90 deg). Covariances (rank 2, tangent at ``d``, ``P = I - d d^T``): the
  correct mode's ``a^2 C_cov + b^2 P`` and the mixture's (moment-matched)
  ``p (a^2 C_cov + b^2 P) + (1 - p) sigma_wrong^2 P``.
* ``log10_nfa``: whether the inlier segments meet at the direction by more than chance, an
  a-contrario test (Desolneux, Moisan, Morel 2000; for vanishing points Almansa,
  Desolneux, Vamech 2003). Two segments meet somewhere whatever their directions, so only
  the others check a direction; a segment of length ``L`` whose orientation were random
  would pass the consistency gate (``|z| <= gate``, the direction of a segment with
  end-point noise ``sigma_px`` and direction noise ``sigma_angle`` has the std
  ``s = sqrt(2 sigma_px^2 / L^2 + sigma_angle^2)``) with probability
  ``P = min(1, 2 gate s / pi)``, and the number of false alarms over
  the ``N (N - 1) / 2`` candidate points of ``N`` segments is::

      NFA = N (N - 1) / 2 * prod_{i >= 3} P_i

  (the product over the inliers but the two longest, the ones that fix the point). A
  direction with ``NFA >= 1`` (the test's usual threshold, not fitted) gets ``p = 0``,
  the wrong mode alone: a frontal view with two or three short receding lines gives a
  tight first-order covariance around wherever they happen to meet, and York's calibration
  set has almost no such direction to learn it from; four long corridor edges meeting
  within their noise pass (a long line is a sharp check, a short one a weak check).
* ``confident``: ``p >= p_confident``.

A filter takes the two modes as they are (:meth:`.fusion.CorridorEKF.update`, a Gaussian-sum
update): the correct one with the first-order covariance, to which it adds the floor of its
own camera (the fitted ``b`` holds what York's camera adds: its lens distortion is not
given, so its images are not undistorted), the wrong one with
:attr:`DirectionConfidence.wrong_covariance`, weighted by ``p`` (by 1 for a confident
direction, whose rare errors are left to the filter's innovation gate). A weakly supported
direction then moves the estimate little unless it agrees with the prediction.

The constants (:data:`CALIBRATION`) are fitted on the York Urban training half (both
640 x 480 and 320 x 240, all three directions of each image) by :func:`fit_calibration`:
the logistic weights by ridge-regularised Newton iterations (ridge ``1`` on the
non-constant weights) on the corridor directions (the one closest to the optical axis in
each frame, what the follower steers on; the other directions get the same model),
``a`` and ``b`` by maximum likelihood of the Rayleigh model truncated at 2 deg on all
directions within 2 deg, ``sigma_wrong`` as the RMS error of all the others, and
``p_confident`` as the smallest threshold at which the corridor directions called
confident are >= 98 % within 2 deg.
Refit (and print) them with::

    python benchmarks/bench_vanishing_points.py --calibrate

Held-out (5-fold over images) figures of the same procedure: ``--confidence``.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple

from landmark_nav.corridor.vanishing_point import (direction_covariance,
                                                   leave_one_out_directions, ManhattanFrame,
                                                   VPParams)
import numpy as np

#: Two directions closer than this are the same hypothesis [deg].
SAME_DIRECTION_DEG = 2.0
#: A direction is "correct" for the calibration when within this of the truth [deg].
CORRECT_DEG = 2.0
#: ``log10 NFA`` at or above which a direction is not checked by its lines: p_correct = 0.
MAX_LOG10_NFA = 0.0
#: chi-square quantile used for the radius (2 dof, 95 %) of a single Gaussian mode.
COVERAGE = 0.95
#: Bounds of the influence feature (a direction with fewer than three inliers has no
#: leave-one-out estimate and gets the upper bound) [first-order standard deviations].
INFLUENCE_RANGE = (1e-3, 1e3)


@dataclass(frozen=True)
class VPCalibration:
    """Constants of the confidence model (see the module docstring).

    Attributes:
        weights: logistic weights ``(w0, w1, w2, w3, w4, w5)`` of
            ``(1, ln(sigma_cov f) [px], ln n, ln(sigma_frame f) [px], ln o [rad], ln i)``
            (five weights: without ``i``, the influence; four: without ``o``, the
            orthogonality residual, either).
        scale: ``a``, factor on the first-order spread.
        floor_deg: ``b``, spread added in quadrature [deg].
        sigma_wrong_deg: spread of the wrong mode [deg].
        p_confident: ``p_correct`` at or above which a direction is confident.
    """

    weights: Tuple[float, ...]
    scale: float
    floor_deg: float
    sigma_wrong_deg: float
    p_confident: float


#: Fitted by ``python benchmarks/bench_vanishing_points.py --calibrate`` (York Urban training
#: half, 51 images x 2 sizes x 3 directions, segmented Hough lines, ``VPParams()``).
CALIBRATION = VPCalibration(weights=(3.5018, -1.4254, 0.4824, -1.0867, -0.7728, -0.7858),
                            scale=1.3493, floor_deg=0.2026,
                            sigma_wrong_deg=5.2509, p_confident=0.8201)


@dataclass(frozen=True, eq=False)
class DirectionConfidence:
    """Support and uncertainty of one Manhattan direction.

    Attributes:
        inliers: number of segments labelled with this direction.
        support: their summed weight.
        log10_nfa: a-contrario number of false alarms of the inliers (module docstring).
        sigma_cov: first-order spread (largest std of the direction covariance) [rad].
        sigma_frame: the largest finite ``sigma_cov`` of the frame's directions [rad].
        orthogonality: angle to the normal of the frame's other two directions [rad].
        influence: the largest move of the direction when one inlier is left out, over
            ``sigma_cov`` (module docstring).
        ambiguity: best competing hypothesis' score over the frame's (see the module).
        p_correct: probability of being within 2 deg of the truth.
        sigma: spread of the correct mode [rad].
        radius95: 95 % radius of the error mixture [rad].
        first_order: (3, 3) first-order covariance ``C_cov`` (end-point noise only).
        covariance: (3, 3) calibrated covariance of the correct mode (rank 2).
        mixture_covariance: (3, 3) moment-matched covariance of the error mixture.
        wrong_covariance: (3, 3) covariance of the wrong mode, ``sigma_wrong^2 P``.
        confident: ``p_correct >= p_confident``.
    """

    inliers: int
    support: float
    log10_nfa: float
    sigma_cov: float
    sigma_frame: float
    orthogonality: float
    influence: float
    ambiguity: float
    p_correct: float
    sigma: float
    radius95: float
    first_order: np.ndarray
    covariance: np.ndarray
    mixture_covariance: np.ndarray
    wrong_covariance: np.ndarray
    confident: bool


def _log_spread_px(sigma: float, focal_px: float) -> float:
    s = min(sigma, math.pi / 2) if math.isfinite(sigma) else math.pi / 2
    return math.log(max(s * focal_px, 1e-6))


def features(sigma_cov: float, sigma_frame: float, focal_px: float, inliers: int,
             orthogonality: Optional[float] = None,
             influence: Optional[float] = None) -> np.ndarray:
    """Return the logistic model's features ``(1, ln(sigma_cov f), ln n, ln(sigma_frame f))``.

    Spreads [rad] are capped at pi / 2 (inf: no spread known), ``n`` at least 1. With
    ``orthogonality`` [rad] given, ``ln(max(orthogonality, 1e-4))`` is appended; with
    ``influence`` too, its logarithm (clipped to :data:`INFLUENCE_RANGE`; not a number:
    the upper bound).
    """
    x = [1.0, _log_spread_px(sigma_cov, focal_px), math.log(max(inliers, 1)),
         _log_spread_px(sigma_frame, focal_px)]
    if orthogonality is not None:
        x.append(math.log(max(orthogonality, 1e-4)))
        if influence is not None:
            lo, hi = INFLUENCE_RANGE
            x.append(math.log(hi if math.isnan(influence) else min(max(influence, lo), hi)))
    return np.array(x)


def influence(segments: np.ndarray, K: np.ndarray, direction: np.ndarray,
              inliers: np.ndarray, sigma_cov: float, params: VPParams = VPParams()) -> float:
    """Return the largest move of a direction when one inlier is left out, over ``sigma_cov``.

    The deleted estimates of the jackknife (:func:`~.vanishing_point.leave_one_out_directions`,
    refined as the direction was, with ``params``): the largest angle [rad] between one of
    them and ``direction``, divided by the first-order spread ``sigma_cov`` [rad] (the
    deletion diagnostic DFBETAS of regression, Belsley, Kuh, Welsch 1980, §2.1). inf with
    fewer than three inliers or no finite spread.
    """
    D = leave_one_out_directions(segments, K, direction, inliers, params)
    if D.shape[0] == 0 or not math.isfinite(sigma_cov) or sigma_cov <= 0:
        return math.inf
    cos = np.clip(np.abs(D @ (np.asarray(direction, dtype=float)
                              / np.linalg.norm(direction))), 0.0, 1.0)
    return float(np.max(np.arccos(cos))) / sigma_cov


def orthogonality_residuals(directions: np.ndarray) -> np.ndarray:
    """Return, per column ``d_k``, its angle to the normal of the other two [rad].

    Each direction is refined on its own lines after the triad's joint refinement, so a
    direction that went to lines of no Manhattan direction leaves the triad's orthogonality.
    A direction that is not finite gets pi / 2, the least confident value (not 0, the most).
    """
    D = np.asarray(directions, dtype=float)
    out = np.zeros(3)
    for k in range(3):
        c = np.cross(D[:, (k + 1) % 3], D[:, (k + 2) % 3])
        c /= max(float(np.linalg.norm(c)), 1e-12)
        dot = abs(float(c @ D[:, k]))
        out[k] = math.acos(min(1.0, dot)) if math.isfinite(dot) else math.pi / 2
    return out


def mixture_radius(p: float, sigma: float, sigma_wrong: float,
                   coverage: float = COVERAGE) -> float:
    """Return the radius [rad] covering ``coverage`` of the two-mode error (module docstring).

    Capped at pi / 2 (the largest angle between two axial directions).
    """
    def cdf(r: float) -> float:
        return (p * (1.0 - math.exp(-0.5 * (r / sigma) ** 2))
                + (1.0 - p) * (1.0 - math.exp(-0.5 * (r / sigma_wrong) ** 2)))
    hi = math.pi / 2
    if cdf(hi) < coverage:
        return hi
    lo = 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if cdf(mid) < coverage:
            lo = mid
        else:
            hi = mid
    return hi


def direction_ambiguities(frame: ManhattanFrame) -> np.ndarray:
    """Return, per direction of ``frame``, the competing hypotheses' best relative score."""
    cos_same = math.cos(math.radians(SAME_DIRECTION_DEG))
    out = np.zeros(3)
    if frame.score <= 0:
        return np.full(3, 2.0)
    for score, D in frame.alternatives:
        disagree = np.max(np.abs(D.T @ frame.directions), axis=0) < cos_same   # (3,)
        out = np.where(disagree, np.maximum(out, score / frame.score), out)
    return out


def log10_nfa(segments: np.ndarray, inliers: np.ndarray, sigma_px: float,
              gate: float = 3.0, sigma_angle_deg: float = VPParams.sigma_angle_deg) -> float:
    """Return ``log10 NFA`` of a direction's inlier segments (module docstring).

    Args:
        segments: (N, 4) all segments of the frame [px]; ``N`` counts the candidate points.
        inliers: (N,) mask of the direction's segments.
        sigma_px: end-point noise [px].
        gate: the consistency gate on ``|z|``.
        sigma_angle_deg: direction noise of a segment beyond its end-point noise [deg].
    """
    seg = np.asarray(segments, dtype=float).reshape(-1, 4)
    n = len(seg)
    sel = seg[np.asarray(inliers, dtype=bool)]
    length = np.hypot(sel[:, 2] - sel[:, 0], sel[:, 3] - sel[:, 1])
    std = np.sqrt(2.0 * (sigma_px / np.maximum(length, 1e-9)) ** 2
                  + math.radians(sigma_angle_deg) ** 2)
    p = np.minimum(1.0, 2.0 * gate * std / math.pi)
    checks = np.sort(np.log10(p))[2:]           # all but the two longest segments
    return math.log10(max(0.5 * n * (n - 1), 1.0)) + float(np.sum(checks))


def assess_direction(sigma_cov: float, sigma_frame: float, focal_px: float, inliers: int,
                     nfa: float, calibration: VPCalibration = CALIBRATION,
                     orthogonality: Optional[float] = None,
                     influence: Optional[float] = None) -> Tuple[float, float, float]:
    """Return ``(p_correct, sigma [rad], radius95 [rad])`` of one direction's features.

    ``sigma_cov`` [rad] is its first-order spread, ``sigma_frame`` [rad] the largest of its
    frame's three, ``focal_px`` the focal length [px], ``inliers`` its segment count,
    ``nfa`` its ``log10 NFA`` (:func:`log10_nfa`), ``orthogonality`` its orthogonality
    residual [rad] (:func:`orthogonality_residuals`; needed by a five- or six-weight
    calibration), ``influence`` its :func:`influence` (needed by a six-weight one).

    Raises:
        ValueError: a five- or six-weight calibration and no ``orthogonality``, or a
            six-weight one and no ``influence`` (0 would be the most confident value, not
            a neutral one).
    """
    c = calibration
    if len(c.weights) > 4 and orthogonality is None:
        raise ValueError('assess_direction: the calibration weighs the orthogonality '
                         'residual; give orthogonality [rad]')
    if len(c.weights) > 5 and influence is None:
        raise ValueError('assess_direction: the calibration weighs the influence; '
                         'give influence')
    s_wrong = math.radians(c.sigma_wrong_deg)
    if not math.isfinite(sigma_cov) or not nfa < MAX_LOG10_NFA:
        return 0.0, s_wrong, mixture_radius(0.0, s_wrong, s_wrong)
    z = float(np.asarray(c.weights, dtype=float)
              @ features(sigma_cov, sigma_frame, focal_px, inliers,
                         orthogonality if len(c.weights) > 4 else None,
                         influence if len(c.weights) > 5 else None))
    p = 1.0 / (1.0 + math.exp(-z)) if z > -700 else 0.0
    sigma = math.hypot(c.scale * sigma_cov, math.radians(c.floor_deg))
    return p, sigma, mixture_radius(p, sigma, s_wrong)


def assess_frame(frame: ManhattanFrame, segments: np.ndarray, K: np.ndarray,
                 sigma_px: float, calibration: VPCalibration = CALIBRATION, gate: float = 3.0,
                 sigma_angle_deg: float = VPParams.sigma_angle_deg
                 ) -> Tuple[DirectionConfidence, DirectionConfidence, DirectionConfidence]:
    """Return the support and calibrated uncertainty of each direction of ``frame``.

    Args:
        frame: the result of :func:`~.vanishing_point.manhattan_frame` on ``segments``.
        segments: (N, 4) the segments it was estimated from [ideal px].
        K: (3, 3) intrinsics.
        sigma_px: end-point noise used for the estimate [px].
        calibration: the model's constants.
        gate: the consistency gate the estimate used (``VPParams.gate``).
        sigma_angle_deg: direction noise of a segment used for the estimate [deg].
    """
    amb = direction_ambiguities(frame)
    focal = math.sqrt(float(K[0, 0]) * float(K[1, 1]))
    c = calibration
    s_wrong = math.radians(c.sigma_wrong_deg)
    covs = [direction_covariance(segments, K, vp.direction, vp.inliers, sigma_px,
                                 sigma_angle_deg) for vp in frame.points]
    spreads = [math.sqrt(max(float(np.linalg.eigvalsh(cov)[-1]), 0.0))
               if np.all(np.isfinite(cov)) else math.inf for cov in covs]
    s_frame = max([x for x in spreads if math.isfinite(x)], default=math.inf)
    orth = orthogonality_residuals(frame.directions)
    params = VPParams(sigma_px=sigma_px, sigma_angle_deg=sigma_angle_deg, gate=gate)
    out = []
    for k, vp in enumerate(frame.points):
        d = vp.direction
        tangent = np.eye(3) - np.outer(d, d)
        cov, s_cov = covs[k], spreads[k]
        finite = math.isfinite(s_cov)
        n_in = int(np.count_nonzero(vp.inliers))
        nfa = log10_nfa(segments, vp.inliers, sigma_px, gate, sigma_angle_deg)
        infl = influence(segments, K, d, vp.inliers, s_cov, params)
        p, sigma, r95 = assess_direction(s_cov, s_frame, focal, n_in, nfa, c, float(orth[k]),
                                         infl)
        good_cov = (c.scale ** 2 * cov + math.radians(c.floor_deg) ** 2 * tangent
                    if finite else s_wrong ** 2 * tangent)
        out.append(DirectionConfidence(
            inliers=n_in, support=vp.support, log10_nfa=nfa, sigma_cov=s_cov,
            sigma_frame=s_frame, orthogonality=float(orth[k]), influence=infl,
            ambiguity=float(amb[k]), p_correct=p, sigma=sigma, radius95=r95,
            first_order=cov if finite else s_wrong ** 2 * tangent, covariance=good_cov,
            mixture_covariance=p * good_cov + (1.0 - p) * s_wrong ** 2 * tangent,
            wrong_covariance=s_wrong ** 2 * tangent,
            confident=p >= c.p_confident))
    return tuple(out)


# ----------------------------------------------------------------------------- fitting
def _logistic(X: np.ndarray, y: np.ndarray, ridge: float = 1.0,
              iterations: int = 100) -> np.ndarray:
    """Ridge-regularised logistic regression by Newton's method (no penalty on w0)."""
    w = np.zeros(X.shape[1])
    pen = np.r_[0.0, np.full(X.shape[1] - 1, ridge)]
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-X @ w))
        g = X.T @ (p - y) + pen * w
        H = (X * (p * (1.0 - p))[:, None]).T @ X + np.diag(pen)
        step = np.linalg.solve(H, g)
        w -= step
        if np.max(np.abs(step)) < 1e-10:
            break
    return w


def _rayleigh_fit(s: np.ndarray, e: np.ndarray, limit: float) -> Tuple[float, float]:
    """ML ``(a, b)`` of ``e ~ Rayleigh(sqrt((a s)^2 + b^2))`` truncated to ``e <= limit``.

    The directions of the correct mode are those within ``limit`` of the truth, so each
    density is divided by its mass below ``limit``, ``1 - exp(-limit^2 / 2 v)`` (s, e and
    limit in the same unit).
    """
    from scipy.optimize import minimize

    def nll(t: np.ndarray) -> float:
        v = (math.exp(t[0]) * s) ** 2 + math.exp(t[1]) ** 2
        mass = -np.expm1(-limit ** 2 / (2.0 * v))
        return float(np.sum(np.log(v) + e ** 2 / (2.0 * v) + np.log(mass)))
    t0 = np.array([0.0, math.log(max(float(np.median(e)), 1e-3))])
    t = minimize(nll, t0, method='Nelder-Mead', options={'xatol': 1e-6, 'fatol': 1e-9}).x
    return math.exp(t[0]), math.exp(t[1])


def fit_calibration(sigma_cov: Sequence[float], sigma_frame: Sequence[float],
                    focal_px: Sequence[float], inliers: Sequence[int], nfa: Sequence[float],
                    error_deg: Sequence[float],
                    precision: float = 0.98,
                    threshold_on: Optional[Sequence[bool]] = None,
                    orthogonality: Optional[Sequence[float]] = None,
                    influence: Optional[Sequence[float]] = None) -> VPCalibration:
    """Fit the confidence model on directions with known errors (module docstring).

    Args:
        sigma_cov: first-order spreads [rad].
        sigma_frame: the largest spread of each one's frame [rad].
        focal_px: the focal lengths of their images [px].
        inliers: their inlier segment counts.
        nfa: their ``log10 NFA`` (``>= MAX_LOG10_NFA``: p = 0, left out of the threshold).
        error_deg: the true angular errors [deg].
        precision: fraction within 2 deg wanted among the confident directions.
        threshold_on: the directions the logistic weights and ``p_confident`` are fitted
            on (default: all), e.g. the corridor directions only; ``a``, ``b`` and
            ``sigma_wrong`` use all.
        orthogonality: with it, their :func:`orthogonality_residuals` [rad] are a fifth
            feature.
        influence: with it (and ``orthogonality``), their :func:`influence` is a sixth.

    Raises:
        ValueError: inputs of different lengths, or no direction (of ``threshold_on``) on
            either side of 2 deg.
    """
    s = np.asarray(sigma_cov, dtype=float)
    sf = np.asarray(sigma_frame, dtype=float)
    f = np.asarray(focal_px, dtype=float)
    m = np.asarray(inliers, dtype=float)
    n = np.asarray(nfa, dtype=float)
    e = np.asarray(error_deg, dtype=float)
    if not (s.shape == sf.shape == f.shape == m.shape == n.shape == e.shape):
        raise ValueError(f'inputs differ in length: {s.shape}, {sf.shape}, {f.shape}, '
                         f'{m.shape}, {n.shape}, {e.shape}')
    good = e <= CORRECT_DEG
    on = np.ones(e.shape, dtype=bool) if threshold_on is None else \
        np.asarray(threshold_on, dtype=bool)
    if good[on].all() or not good[on].any():
        raise ValueError('calibration needs directions both within and beyond 2 deg')
    o = [None] * len(e) if orthogonality is None else list(orthogonality)
    i = [None] * len(e) if influence is None else list(influence)
    X = np.array([features(*v) for v in zip(s, sf, f, m, o, i)])
    w = _logistic(X[on], good[on].astype(float))
    ok = good & np.isfinite(s)
    scale, floor = _rayleigh_fit(np.degrees(s[ok]), e[ok], CORRECT_DEG)
    sigma_wrong = float(np.sqrt(np.mean(e[~good] ** 2)))
    sel = on & (n < MAX_LOG10_NFA)
    p = (1.0 / (1.0 + np.exp(-X @ w)))[sel]
    good = good[sel]
    thr = float(np.max(p))
    for t in np.sort(p):
        if np.mean(good[p >= t]) >= precision:
            thr = float(t)
            break
    return VPCalibration(weights=tuple(float(v) for v in w), scale=float(scale),
                         floor_deg=float(floor), sigma_wrong_deg=sigma_wrong,
                         p_confident=thr)
