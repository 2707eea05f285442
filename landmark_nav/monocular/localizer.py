"""EKF pose tracking of a planar robot against a 3-D line model (chapter §5.3, eqs. 55-71).

State layout (as in :mod:`landmark_nav.localization`)::

    p = [p_x, p_y, phi]    robot pose in the model frame (map) [m, m, rad], phi in [-pi, pi)
    Sigma_p = 3 x 3 covariance
    u = [D, dPhi]          odometry increment (calibrated, eqs. 17-18), process noise v ~ Q

Time update (eqs. 55, 66, 68): ``p^ = f(p, u)`` with the calibrated odometry model of
:mod:`landmark_nav.localization.odometry` and ``Sigma = A Sigma A^T + F_u Q F_u^T``.

Measurement (eqs. 59-61): for a pair "model line m - image line i" eq. 59 demands that the
projected model point lies on the image line and eq. 60 that the directions agree; these
are two independent scalar conditions per pair, which we write in the line's Hough
coordinates: ``z = h(i) - H(P M1, P M2)`` (eq. 64), so that ``z^ = 0`` (eq. 67),
``H = d z / d p = -J_H blockdiag(J_P, J_P)`` (eqs. 62, 64) and ``R = V`` (``dz/dh = I``, the
image line covariance of :mod:`.matching` plus the model's own). All pairs of a frame form
one stacked update (eqs. 69-71), relinearised ``iterations`` times (iterated EKF; 1 = the
chapter's EKF).

Correlated pair errors (our addition): the error of one model edge's image line repeats from
frame to frame (the same door frame beside the modelled edge, the same texture and the same
line-fit bias; on the rendered hallway the residuals of one edge at the true pose correlate
0.54 between frames 7 cm apart, 0.36 at 0.56 m, 0.14 at 1.4 m, and more at standstill), so
frames are not independent measurements and a plain EKF grows overconfident, most of all
while the robot stands. We treat the pair error of an edge as a first-order Markov sequence
along the robot's motion ``s`` (path length plus ``turn_m_per_rad`` per radian turned), with
correlation ``rho = error_correlation exp(-(s - s_last) / correlation_length_m)`` to the
edge's previous use at ``s_last``. Whitening that sequence (``z_n - rho z_(n-1)``) leaves a
measurement worth ``(1 - rho) / (1 + rho)`` of an independent one, so the pair's R is
multiplied by ``(1 + rho) / (1 - rho)``; an edge's first use (and every use after a reset)
keeps R. Gating uses the single-frame covariance.

Lost state: when fewer than ``min_matches`` pairs are found for longer than ``lost_after_s``
of image time, the filter reports ``lost`` and inflates its covariance once by
``lost_inflation`` (so the gates open to where the robot may be); odometry keeps predicting.
The first frame with at least ``recover_matches`` pairs that pass the gates updates the pose
and the state returns to ``tracking`` -- no reset needed. The first frame after a reset
and the frames while lost try ``2 heading_hypotheses + 1`` headings
(:meth:`ModelLocalizer._hypotheses`), since a wrong first association is locked in by the
covariance it leaves.
"""

from dataclasses import dataclass, field
import math
from typing import Optional, Sequence, Tuple

import numpy as np

from .matching import (align, align_cov, image_line_covariance, innovation,
                       inseparable_lines, match_lines, Matches, MatchParams, predict_lines,
                       PredictedLines)
from .model import LineModel
from .visibility import CameraMount, Intrinsics, visible_lines, VisibleLines
from ..geometry import wrap_angle
from ..localization.odometry import (motion_jacobians, motion_model, process_noise,
                                     ProcessNoise)

TRACKING = 'tracking'
LOST = 'lost'

#: The chapter's start covariance Sigma_p0 = diag(0.3 dm^2, 0.3 dm^2, 0.008 rad^2) in SI.
CHAPTER_START_COV = np.diag([0.3e-2, 0.3e-2, 0.008])


@dataclass(frozen=True)
class LocalizerParams:
    """Parameters of :class:`ModelLocalizer`.

    Attributes:
        noise: odometry process noise (eq. 26 + extensions).
        match: gating / assignment.
        near, far: frustum depth range [m].
        min_line_px: projected model lines shorter than this [px] are not matched.
        iterations: relinearisations of the measurement update (1 = plain EKF).
        min_matches: a frame with fewer pairs does not update (and counts towards lost).
        lost_after_s: image time [s] without an update before the state becomes lost.
        lost_inflation: (3,) standard deviations [m, m, rad] added (as variances) to the
            covariance when the filter gets lost.
        recover_matches: pairs needed in one frame to leave the lost state.
        model_sigma_m: std [m] of the model's end points (:func:`~.matching.predict_lines`).
        heading_hypotheses: heading hypotheses per side tried in the first frame after a
            reset and when lost (:meth:`ModelLocalizer._hypotheses`; 0 = off).
        association_rounds: rounds of :meth:`ModelLocalizer.associate` (0 = plain gating
            and assignment at the prior).
        error_correlation: correlation of an edge's pair errors between two uses without
            motion (module docstring; 0 = independent frames, the chapter's EKF).
        correlation_length_m: motion [m] over which that correlation decays by 1/e.
        turn_m_per_rad: motion [m] counted per radian of turning.
    """

    noise: ProcessNoise = field(default_factory=ProcessNoise)
    match: MatchParams = field(default_factory=MatchParams)
    near: float = 0.2
    far: float = 25.0
    min_line_px: float = 15.0
    iterations: int = 2
    min_matches: int = 2
    lost_after_s: float = 1.0
    lost_inflation: Tuple[float, float, float] = (0.15, 0.15, math.radians(5.0))
    recover_matches: int = 4
    association_rounds: int = 2
    heading_hypotheses: int = 2
    model_sigma_m: float = 0.02
    error_correlation: float = 0.6
    correlation_length_m: float = 1.0
    turn_m_per_rad: float = 1.0

    def __post_init__(self) -> None:
        """Check the error correlation model."""
        if not 0.0 <= self.error_correlation < 1.0:
            raise ValueError(f'error_correlation must be in [0, 1); got '
                             f'{self.error_correlation}')
        if self.correlation_length_m <= 0 or self.turn_m_per_rad < 0:
            raise ValueError('correlation_length_m must be > 0 and turn_m_per_rad >= 0')


@dataclass(frozen=True, eq=False)
class FrameResult:
    """Outcome of one image update.

    Attributes:
        pose: (3,) pose after the update.
        cov: (3, 3) covariance after the update.
        status: ``'tracking'`` or ``'lost'``.
        predicted: model lines predicted at the prior pose.
        matches: the pairs used (empty when none or too few).
        updated: whether the pose was corrected.
        became_lost: the filter got lost in this frame.
        recovered: the filter left the lost state in this frame.
        problem: a one-line description of bad input ('' if none).
    """

    pose: np.ndarray
    cov: np.ndarray
    status: str
    predicted: Optional[PredictedLines]
    matches: Optional[Matches]
    updated: bool
    became_lost: bool = False
    recovered: bool = False
    problem: str = ''


class ModelLocalizer:
    """The EKF of §5.3 with a lost state (module docstring).

    Args:
        model: the 3-D line model (map frame).
        intrinsics: ideal pinhole intrinsics of the (undistorted) image lines.
        mount: camera mount on the robot.
        params: filter parameters.
    """

    def __init__(self, model: LineModel, intrinsics: Intrinsics, mount: CameraMount,
                 params: LocalizerParams = LocalizerParams()) -> None:
        """Store the model; call :meth:`reset` before use."""
        self.model = model
        self.K = intrinsics
        self.mount = mount
        self.params = params
        self.pose = np.zeros(3)
        self.cov = np.eye(3)
        self.status = TRACKING
        self.initialised = False
        self._last_update_s: Optional[float] = None
        self._motion = 0.0                  # s: path length + turn_m_per_rad |turn| [m]
        self._edge_motion: dict = {}        # edge index -> s at its last update
        lo, hi = model.bounds()
        self._lo, self._hi = lo, hi

    def reset(self, pose: Sequence[float], cov: np.ndarray, stamp_s: Optional[float] = None
              ) -> None:
        """Set the pose and covariance (initial pose or RViz ``initialpose``)."""
        p = np.array(pose, dtype=float).reshape(3)
        c = np.array(cov, dtype=float).reshape(3, 3)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(c))):
            raise ValueError('initial pose and covariance must be finite')
        if np.any(np.linalg.eigvalsh(0.5 * (c + c.T)) <= 0):
            raise ValueError('initial covariance must be positive definite')
        p[2] = wrap_angle(p[2])
        self.pose, self.cov = p, 0.5 * (c + c.T)
        self.status = TRACKING
        self.initialised = True
        self._fresh = True
        self._last_update_s = stamp_s
        self._edge_motion = {}

    def set_intrinsics(self, intrinsics: Intrinsics) -> None:
        """Replace the camera intrinsics (CameraInfo changed)."""
        self.K = intrinsics

    def predict(self, u: Sequence[float]) -> None:
        """Time update with one odometry increment ``u = [D, dPhi]`` (eqs. 55, 66, 68)."""
        u = np.asarray(u, dtype=float).reshape(2)
        A, F_u = motion_jacobians(self.pose, u)                     # A = df/dp (eq. 68)
        Q = F_u @ process_noise(u, self.params.noise) @ F_u.T
        self.pose = motion_model(self.pose, u)                      # eq. 66
        self.cov = A @ self.cov @ A.T + Q                           # eq. 68
        self.cov = 0.5 * (self.cov + self.cov.T)
        self._motion += abs(u[0]) + self.params.turn_m_per_rad * abs(u[1])

    def inside_model(self, pose: Sequence[float]) -> bool:
        """Whether the camera centre lies inside the model's bounding box (x, y)."""
        return bool(self._lo[0] <= pose[0] <= self._hi[0] and self._lo[1] <= pose[1]
                    <= self._hi[1])

    def predict_lines(self, pose: Optional[np.ndarray] = None,
                      cov: Optional[np.ndarray] = None) -> PredictedLines:
        """Visible model lines in Hough space at a pose (default: the current estimate)."""
        pose = self.pose if pose is None else pose
        cov = self.cov if cov is None else cov
        vis = visible_lines(self.model, pose, self.mount, self.K, self.params.near,
                            self.params.far, min_length_px=self.params.min_line_px)
        return predict_lines(vis, pose, cov, self.mount, self.K, self.params.model_sigma_m)

    def update(self, segments: np.ndarray, stamp_s: float) -> FrameResult:
        """Measurement update with the image line segments of one frame (eqs. 56-71).

        Args:
            segments: (N, 4) undistorted image segments ``x1 y1 x2 y2`` [px].
            stamp_s: image time [s] (for the lost timer).
        """
        if not self.initialised:
            raise RuntimeError('ModelLocalizer.update before reset')
        p = self.params
        problem = ''
        if self._last_update_s is None:
            self._last_update_s = stamp_s
        if self.model.edges.shape[0] == 0:
            problem = 'the line model has no edges'
        elif not self.inside_model(self.pose):
            problem = (f'camera pose ({self.pose[0]:.2f}, {self.pose[1]:.2f}) is outside the '
                       f'model')
        pred = matches = None
        updated = False
        if not problem:
            need = p.recover_matches if self.status == LOST else p.min_matches
            if (self._fresh or self.status == LOST) and p.heading_hypotheses > 0:
                pred, matches, best = self._hypotheses(segments)
                if best is not None and len(matches) >= need:
                    self.pose, self.cov = best
                    updated = True
            else:
                pred = self.predict_lines()
                matches = self.associate(pred, segments)
                if len(matches) >= need:
                    matches = self._correct(pred, matches)
                    updated = True
            if updated:
                self._fresh = False
                for e in pred.visible.index[matches.model]:
                    self._edge_motion[int(e)] = self._motion
            elif len(segments) == 0:
                problem = 'no lines in the image'
        became_lost = recovered = False
        if updated:
            self._last_update_s = stamp_s
            if self.status == LOST:
                self.status = TRACKING
                recovered = True
        elif self.status == TRACKING and stamp_s - self._last_update_s > p.lost_after_s:
            self.status = LOST                                      # reported, inflated
            self.cov = self.cov + np.diag(np.square(p.lost_inflation))
            became_lost = True
        return FrameResult(self.pose.copy(), self.cov.copy(), self.status, pred, matches,
                           updated, became_lost, recovered, problem)

    def _hypotheses(self, segments: np.ndarray) -> tuple:
        """Association and update from several heading hypotheses (first frame, lost).

        A wrong association in the first frame after a reset, or when leaving the lost
        state, is locked in by the covariance it leaves. The prior is therefore tried at
        the headings ``phi + k sigma_phi`` (``|k| <= heading_hypotheses``) with the heading
        variance of each reduced to ``(sigma_phi / 2)^2``; the hypothesis whose update
        keeps the most pairs wins (ties: the smaller sum of d^2).

        Returns:
            ``(predicted lines, pairs, (pose, cov) or None)`` of the winner.
        """
        pose0, cov0 = self.pose.copy(), self.cov.copy()
        sd = math.sqrt(cov0[2, 2])
        best = None
        try:
            for k in range(-self.params.heading_hypotheses, self.params.heading_hypotheses + 1):
                x = pose0.copy()
                x[2] = wrap_angle(x[2] + k * sd)
                P = cov0.copy()
                P[2, :] *= 0.5
                P[:, 2] *= 0.5
                self.pose, self.cov = x, P
                pred = self.predict_lines()
                matches = self.associate(pred, segments)
                if len(matches) == 0:
                    key = (0, 0.0)
                    result = (pred, matches, None)
                else:
                    xk, Pk, kept = self._robust(pred, matches)
                    key = (len(kept), -float(kept.d2.sum()))
                    result = (pred, kept, (xk, Pk))
                if best is None or key > best[0]:
                    best = (key, result)
        finally:
            self.pose, self.cov = pose0, cov0
        return best[1]

    def associate(self, pred: PredictedLines, segments: np.ndarray) -> Matches:
        """Pairs for one frame: unique pairs first, then gating + assignment (§5.3).

        The pose uncertainty moves many predicted lines together (5 deg of heading shift
        every vertical line by about 34 px at the chapter's focal length), so such a line's
        gate holds several image lines, and independent nearest neighbours can pick a
        consistent but wrong set. Our rule, after Kosaka & Kak's sequential matching (match
        what is unambiguous, propagate the reduced uncertainty, match the rest):

        1. pairs whose model line has exactly one gated image line that is gated to no other
           model line are *unique*; a tentative update with them (eqs. 69-71) shrinks the
           covariance;
        2. every line is predicted again at the tentative pose with the reduced covariance
           and matched by :func:`~.matching.match_lines` (gate + one-to-one assignment);
           steps 1-2 repeat ``association_rounds`` times from the new pairs;
        3. the final pairs, re-expressed at the prior's predicted lines and gated there
           too, go to the update.

        Without unique pairs this is :func:`~.matching.match_lines` at the prior.
        """
        p = self.params
        base = match_lines(pred, segments, p.match)
        seg = np.asarray(segments, dtype=float).reshape(-1, 4)
        if len(pred) == 0 or seg.shape[0] == 0 or p.association_rounds < 1:
            return base
        h_img, V = image_line_covariance(seg, p.match.sigma_px)
        length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
        usable = length >= p.match.min_length_px
        M = len(pred)
        nu = innovation(np.broadcast_to(h_img[None], (M, seg.shape[0], 2)),
                        np.broadcast_to(pred.h[:, None], (M, seg.shape[0], 2)))
        S = (pred.cov + pred.model_cov)[:, None] + V[None]
        d2 = np.einsum('mni,mnij,mnj->mn', nu, np.linalg.inv(S), nu)
        gated = (d2 <= p.match.gate) & usable[None]
        if p.match.resolve_px > 0:
            gated[inseparable_lines(pred, p.match.resolve_px, p.match.ambiguity_deg)] = False
        unique = (gated.sum(axis=1) == 1)[:, None] & gated & (gated.sum(axis=0) == 1)[None]
        rows, cols = np.nonzero(unique)
        if rows.size == 0:
            return base
        edge_to_pred = {int(e): k for k, e in enumerate(pred.visible.index)}
        for _ in range(p.association_rounds):
            pairs = Matches(rows, cols, d2[rows, cols], align(h_img[cols], pred.h[rows]),
                            align_cov(V[cols], h_img[cols], pred.h[rows]))
            x1, P1, _ = self._robust(pred, pairs)
            pr1 = self.predict_lines(x1, P1)
            m1 = match_lines(pr1, seg, p.match)
            r_new, c_new = [], []
            for mi, ij in zip(m1.model, m1.image):
                k = edge_to_pred.get(int(pr1.visible.index[mi]))
                if k is not None:
                    r_new.append(k)
                    c_new.append(int(ij))
            if not r_new:
                return base
            rows, cols = np.array(r_new), np.array(c_new)
            ok = d2[rows, cols] <= p.match.gate                    # gated at the prior too
            rows, cols = rows[ok], cols[ok]
            if rows.size == 0:
                return base
        return Matches(rows, cols, d2[rows, cols], align(h_img[cols], pred.h[rows]),
                       align_cov(V[cols], h_img[cols], pred.h[rows]), m1.n_ambiguous)

    def _correct(self, pred: PredictedLines, matches: Matches) -> Matches:
        """Apply the stacked update of :meth:`_robust`; return the pairs kept."""
        self.pose, self.cov, kept = self._robust(pred, matches)
        return kept

    def _robust(self, pred: PredictedLines, matches: Matches) -> Tuple[np.ndarray, np.ndarray,
                                                                       Matches]:
        """Stacked update that drops pairs the updated pose does not explain.

        After each update (:meth:`_corrected`) the pair with the largest residual
        ``d^2 = nu^T S^-1 nu`` at the new pose is dropped when ``d^2`` exceeds the gate,
        and the update is redone from the prior (at most half the pairs are dropped). A
        wrong pair that passed the gates at a loose prior is thus removed once the other
        pairs have pinned the pose down. ``S = V + model_cov - H P+ H^T`` is the covariance
        of a residual after an update that included the pair (the update pulls the pose
        towards every pair, so ``V + model_cov`` alone understates d^2 of a wrong pair by
        the share the pose took up); where that difference is not positive definite
        (numerically) ``V + model_cov`` is used.
        """
        gate = self.params.match.gate
        keep = np.arange(len(matches))
        while True:
            sub = _subset(matches, keep)
            x, P = self._corrected(pred, sub)
            vis = VisibleLines(pred.visible.index[sub.model], pred.visible.points[sub.model],
                               np.zeros((len(sub), 4)))
            lin = predict_lines(vis, x, P, self.mount, self.K, self.params.model_sigma_m)
            nu = innovation(sub.h, lin.h)
            S = align_cov(sub.V, sub.h, lin.h) + lin.model_cov
            S_post = S - lin.H @ P @ np.swapaxes(lin.H, 1, 2)     # residual covariance
            ok = np.all(np.linalg.eigvalsh(S_post) > 1e-3 * np.linalg.eigvalsh(S), axis=1)
            S = np.where(ok[:, None, None], S_post, S)
            d2 = np.einsum('ki,kij,kj->k', nu, np.linalg.inv(S), nu)
            worst = int(np.argmax(d2))
            floor = max(self.params.min_matches, len(matches) // 2)
            if d2[worst] <= gate or len(keep) <= floor:
                return x, P, sub
            keep = np.delete(keep, worst)

    def _corrected(self, pred: PredictedLines, matches: Matches) -> Tuple[np.ndarray,
                                                                          np.ndarray]:
        """Stacked EKF update (eqs. 69-71), relinearised ``iterations`` times."""
        prior, P = self.pose.copy(), self.cov
        edges = pred.visible.index[matches.model]
        pts = pred.visible.points[matches.model]
        vis = VisibleLines(edges, pts, np.zeros((len(edges), 4)))
        x = prior.copy()
        scale = self.correlation_factors(edges)[:, None, None]
        for _ in range(max(1, self.params.iterations)):
            lin = predict_lines(vis, x, P, self.mount, self.K, self.params.model_sigma_m)
            # the image lines in the orientation of the lines predicted at x (rho >= 0 fold)
            nu = innovation(matches.h, lin.h).reshape(-1)
            V = scale * (align_cov(matches.V, matches.h, lin.h) + lin.model_cov)
            R = np.zeros((2 * len(matches), 2 * len(matches)))
            for k in range(len(matches)):
                R[2 * k:2 * k + 2, 2 * k:2 * k + 2] = V[k]          # R = V (dz/dh = I)
            H = lin.H.reshape(-1, 3)                                # d h^ / dp = -dz/dp
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T                        # eq. 69
            # eq. 70 (iterated form: relinearised at x, corrected from the prior)
            dx = prior - x
            dx[2] = wrap_angle(dx[2])
            x = prior + K @ (nu - H @ dx)
            x[2] = wrap_angle(x[2])
        I_KH = np.eye(3) - K @ H
        cov = I_KH @ P @ I_KH.T + K @ R @ K.T                       # eq. 71 (Joseph form)
        return x, 0.5 * (cov + cov.T)

    def correlation_factors(self, edges: np.ndarray) -> np.ndarray:
        """Return the factors ``(1 + rho) / (1 - rho)`` on R of pairs of these edges.

        ``rho`` is the correlation with the edge's previous use (module docstring); 1 for an
        edge not used since the last reset.
        """
        p = self.params
        last = np.array([self._edge_motion.get(int(e), -np.inf) for e in edges], dtype=float)
        rho = p.error_correlation * np.exp(-(self._motion - last)
                                           / max(p.correlation_length_m, 1e-9))
        return (1.0 + rho) / (1.0 - rho)


def _subset(m: Matches, keep: np.ndarray) -> Matches:
    """Return the pairs ``keep`` of ``m``."""
    return Matches(m.model[keep], m.image[keep], m.d2[keep], m.h[keep], m.V[keep],
                   m.n_ambiguous)
