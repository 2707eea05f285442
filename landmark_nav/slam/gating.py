"""EKF-SLAM data association (eqs. 49-55) and the checks of an association hypothesis.

:func:`do_data_association` gates every observation-landmark pair (the chi-square gate of
eq. 55, the descriptor and extent masks, the optional map-frame gate) and chooses a
hypothesis with ICNN or JCBB (:mod:`.association`); :class:`HypothesisChecks` holds the
filter's further tests of that hypothesis (recovery, spurious pairs, free space).

Corner descriptors
------------------
Observations may come with descriptors ``[bisector, opening]`` (direction of the corner's
free-space bisector in base_link and the free-space opening angle,
:func:`.observations.corner_descriptors`). Each landmark keeps the mean of its observations'
world bisectors (``psi_r + bisector``) and openings. A landmark (or candidate) is
considered for an observation only if the bisectors differ by less than ``bisector_gate``
and the openings by less than ``opening_gate``; a NaN or missing descriptor passes. This
separates corners that are metrically almost coincident but are different features, such
as the two roots of a 10 cm thick partition seen from its two sides; it never changes the
state, only which pairs the chi-square gate is asked about.

The descriptors also give the viewing geometry: the line of sight from the corner to the
robot makes the angle ``|wrap(theta + pi - bisector)|`` with the bisector, and an arm is
seen edge-on when that angle reaches half the wall-side wedge (``min(opening, 2 pi -
opening) / 2``). Corners seen within ``min_view_margin`` (8 deg) of that limit are rejected
(``'grazing'``): on the simulated office their squared Mahalanobis errors under the
extractor's covariance average 7-9 instead of 2 (one arm has few returns, nearly along the
beam). The margin is kept small because rejecting too much starves the filter: along a wall
the corner ahead is seen with a small margin for metres.

Ambiguous pairs
---------------
With ``reject_ambiguous`` an associated pair is used only when its observation has no other
landmark and its landmark no other observation inside the gate
(:func:`reject_ambiguous_pairs`, mutual exclusion); the others are rejected as
``'ambiguous'`` (no update, no candidate). Off by default: on the six Carmen logs (drift
seeds 0-1) it did not reduce the RPE over 1 m (median 2.9x the odometry's against 2.1x
without; with ``line_residual_factor = 2`` no better than that option alone). The largest
jumps seen there are not choices between two gated landmarks: on seattle (seed 0) a corner
confirmed one scan earlier was re-observed with ``d2 = 0.12`` and, with five lines (joint
NIS 29 for 12 dof, under the ``joint_probability`` check), moved the robot 1.45 m along
the corridor.

Cartesian gate
--------------
``cartesian_gate`` (off by default) also tests a corner pair that the range-bearing gate
admits in the map frame (:func:`cartesian_pair_d2`: the observation put in the map,
against the landmark, linear in the robot position and the landmark, nonlinear in the
heading only through the observed range) when the predicted range std is at least that
fraction of the predicted range, and keeps the larger ``d2`` (so a pair it rejects may
still be ``'ambiguous'``). Aim: the aces pair of README.md at commit 67eb6cc (perfect odometry,
scan 199: a corner 3 m away against a landmark predicted at 22.6 m with a range std of 8.6 m,
``d2`` 5.81, map frame 7.32). Measured (same, EKF-SLAM, ``observability_gain``, six
Carmen logs, drift seeds 0-1, and aces and acapulco with perfect odometry) with ``0``
(every admitted corner pair): it rejects that pair, but 22 scans later a corner 0.85 m
away is paired with the first landmark (predicted 16.6 m, range std 9.2 m, ``d2`` 5.04,
map frame 3.76: the map frame admits it more easily) and the map turns by 42 deg; on
aces the RPE grows from 0.28 to 3.1 m (perfect odometry) and 0.71 to 2.8 m (seed 1). The
other logs are unchanged but for acapulco seed 0 (ATE 14.7 -> 10.8 m) and freiburg-101
seed 0 (within 1 %). What admits these pairs is the width of the prior (the robot's
position relative to the start area, 6 x 11 m), not the shape of the linearised gate:
the unscented transform (Julier and Uhlmann, Proc. IEEE 92(3), 2004; ``n + kappa = 3``)
of ``h`` over the joint Gaussian of the robot and the landmark with the unobservable
directions projected out (they change no observation; rank 2) gives these two pairs
their linear ``d2`` (5.81, 5.03); over the whole ``P`` (``kappa = 0``) it rejects both
(6.5, 11.2) but also a correct pair (aces scan 266, 2 cm off in truth: 6.5 against 4.8,
with the projection 5.0): sigma points along the linearised global turn stretch the
robot-landmark vector by ``sqrt(1 + s^2)``, which a range std of 2 cm does not allow.

Free-space check
----------------
``free_space_check`` (off by default; a confidence, e.g. 0.95) weighs what the gate cannot:
negative information. If the robot were where an association hypothesis puts it, the scan
would have to show the mapped landmarks that would then be in its view; a solid corner or
wall that the scan's beams pass through, returning from beyond it, refutes that pose. The
idea is the "negative information" of Thrun, Burgard and Fox (Probabilistic Robotics, MIT
Press 2005), who use landmarks in the perceptual range that are not seen to weigh a
landmark's existence (FastSLAM feature management; section not re-checked here); here it
weighs a hypothesis, with the free-space test of visibility-aware pruning
(:func:`.visibility.landmarks_missed`; :func:`free_space_contradictions`). After ICNN /
JCBB, the hypothesis's posterior (:func:`.update.ekf_update` on a copy: the same Jacobians and
gain) is computed and the mapped corners not in the hypothesis that the scan sees through
at the posterior mean (predicted std from the posterior covariance, one-dof gate
``sqrt(chi2_1(gate_probability))``) are counted, except those that the scan already sees
through at the prior mean with the same covariance and no gate at all (a lost landmark,
pruning's business, or a borderline case). Out of ``V`` corners the scan could have seen
through (in view and range, facing, nothing in front: :func:`.visibility.corners_in_view`
without its distance limit), a right hypothesis sees each through with probability at
most ``q = (1 - gate_probability) / 2``; ``c`` of them refute it when the binomial tail
``P(X >= c) < 1 - free_space_check`` (:func:`free_space_significant`: at 0.95 one of one
or two, two of 3-14, three of 15-33). Then the pair whose removal leaves the fewest
contradictions (ties: the largest ``d2``) is dropped (reason ``'free_space'``, counted in
``stats['free_space']``), and so on while the rest is refuted, unless no removal lowers
the count (then the map, not a pair, is to blame). Line landmarks are not counted
(``_FREE_SPACE_LINES``; :func:`.visibility.lines_unoccluded` is their denominator): with
them the check dropped 29 right pairs and 23 wrong ones over the 12 Carmen runs, 20 of the
23 it dropped on seattle, fhw, freiburg-101 and belgioioso right, where corners only leave
those eight runs unchanged (perhaps because a line's extent is the hull of its seen
segments and may span a doorway; not verified). Cost: one update on a copy and two
visibility tests of the whole map per scan with a hypothesis, more only when it is
refuted. Measured in README.md at commit 67eb6cc (EKF-SLAM, "Free-space check").

Recovery
--------
A heading error is common to every pair of a scan: after a step whose heading drift is 1.6
sigma of the filter's accumulated heading std (a Carmen log, belgioioso seed 0 scan 152:
-11.7 deg over 1.05 m, a 3.8 sigma draw of the importer's drift model for that step), every
correct pair can lie outside the 95 % individual gate at once (there two corners
matched at d2 0.22 and 0.33 one scan earlier give 8.5 and 9.3), nothing is matched, the
line extents put in the map with the wrong heading stop overlapping (a heading error
``dpsi`` slides an observed extent along its wall by ``rho_b * dpsi``), new landmarks are
confirmed at the wrong heading and the error stays for the rest of the run. With
``recovery_probability`` (off by default) a scan whose association pairs nothing gets a
second one: JCBB (Neira and Tardos 2001) with this confidence for the individual and the
joint gates (:meth:`HypothesisChecks._recover`). The wider individual gate is what admits the pairs
(at 0.99 the scan above pairs the first corner, d2 8.5, and two walls, 9.1 and 7.3; the
second corner, 9.3, stays out); what keeps wrong ones out is the joint test over the pairs'
correlation through the robot and the count: the hypothesis is used only if at least
``recovery_pairs`` pairs remain after ``reject_ambiguous`` (tested at the wider gate) and
the free-space check (default 3: six measurements for a relocation of the three pose dof,
three of them to test it; with two, one redundant dof, acapulco's ATE doubled in one run).
Counted in ``stats['recovered']``. A scan with any pair is not touched, nor is a plain
widening of the gate (``gate_probability`` 0.99 everywhere, it broke acapulco).
Measured in README.md at commit 67eb6cc (EKF-SLAM, "Recovery").

Spurious pairs
--------------
The chi-square gate tests whether an observation *can* be a landmark, not whether it is
more likely that landmark than another feature of the scene: when the robot's uncertainty
relative to a landmark is large (a heading std of 20 deg after a long corridor), the
gate covers many square metres and any corner or wall of the scene that lands in it is
paired. On the Carmen logs with the importer's odometry replaced by the reference's own
increments (no drift), such pairs are what breaks the filter: aces, one corner 25 m from
the landmark it was paired with (d2 5.8, heading std 22 deg) turned the robot by 48 deg;
acapulco, corners 1.3-4.8 m off turned it by 10-16 deg, a wall 17 m off by 35 deg (a
per-step trace with each pair labelled through the reference poses, README.md at commit 67eb6cc).
With ``spurious_limit`` (off by default) each pair of the hypothesis is kept only when the
expected number of features of its kind inside its gate (the density is estimated with
the observed one counted), ``lambda A`` (the clutter density times the validation volume
of Bar-Shalom's probabilistic data association), is at most the limit
(:meth:`HypothesisChecks._spurious_check`):

* ``A``: the gate ``d2 <= chi2_2(gate_probability)`` is an ellipse of area
  ``pi chi2 sqrt(det S)`` in the observation's coordinates, with ``S`` the innovation
  covariance the gate used; a corner's ``(r, theta)`` maps to the plane with
  ``dA = r dr dtheta``, so its area is that times the predicted range; a line's stays in
  ``(rho, alpha)`` [m rad].
* ``lambda``: the scan's own density of features, with no constant of its own: its valid
  corner observations over the area its valid beams sweep, its line observations over the
  perimeter of that region's convex hull (by Cauchy-Crofton the measure ``drho dalpha`` of
  the lines meeting a region is the perimeter of its convex hull)
  (:func:`.visibility.swept_region`). The observed feature counts too (the
  non-parametric PDA's estimate of the clutter density from the validated measurements).
  A recovered hypothesis (above) is judged with the wider gate that admitted it.

``0.05`` (the gate's own miss rate, ``1 - gate_probability``) makes a spurious pair as
likely as a missed right one. A dropped pair lies inside the gate, so its observation is
'ambiguous' (no new landmark); counted in ``stats['spurious']``. Needs the scan geometry.
Measured in README.md at commit 67eb6cc (EKF-SLAM, "Spurious pairs").
"""

import math
from typing import Optional, Tuple

import numpy as np

from ._linalg import _wrap
from .association import icnn, jcbb, joint_mahalanobis, mahalanobis_table
from .consistency import chi2_gate
from .consistent_linearisation import constrain_jacobians
from .line_landmarks import extents_overlap
from .observation_models import (_landmark_cols, feature_initialization,
                                 joint_observation_covariance, observation_model,
                                 predicted_observation_covariance)
from .slam_params import CORNER, LINE
from .update import ekf_update
from .visibility import (corners_in_view, landmarks_missed, lines_unoccluded, ScanGeometry,
                         swept_region)

#: A confidence whose one-dof gate is ~0 (the free-space check's prior-mean test).
_NO_GATE = 1e-12
#: Whether the free-space check counts line landmarks seen through (else corners only).
_FREE_SPACE_LINES = False


def do_data_association(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray,
                        method: str = 'icnn', probability: float = 0.95,
                        max_nodes: int = 5000, allowed: Optional[np.ndarray] = None,
                        obs_kind: Optional[np.ndarray] = None,
                        lm_kind: Optional[np.ndarray] = None, joint_check: bool = False,
                        joint_probability: float = 0.99999,
                        nullspace: Optional[np.ndarray] = None,
                        jacobian_state: Optional[np.ndarray] = None,
                        cartesian_ratio: Optional[float] = None
                        ) -> Tuple[np.ndarray, np.ndarray, int]:
    """Associate observations with map landmarks (eqs. 49-55), ICNN or JCBB.

    With kinds, an observation pairs only with a landmark of its kind, and a line only
    with a line it sees from the front (predicted ``rho_b > 0``); JCBB then runs over the
    mixed hypothesis (its joint covariance couples corners and lines through the robot).

    Args:
        x: State.
        p: Covariance.
        z: (M, 2) observations [r, theta] in base_link.
        r: (M, 2, 2) their covariances.
        method: ``'icnn'`` or ``'jcbb'``.
        probability: Gate confidence (eq. 55).
        max_nodes: JCBB node budget.
        allowed: Optional (M, N) bool mask of pairs that may be associated (descriptor
            gate, extent overlap); the others get ``D2 = inf``.
        obs_kind: Optional (M,) kind of each observation (None: all corners).
        lm_kind: Optional (N,) kind of each landmark (None: all corners).
        joint_check: With ICNN, test the joint compatibility of the whole hypothesis
            (``D2_H < chi2_{2p, joint_probability}``, JCBB's statistic) and, when it fails,
            associate with JCBB instead: pairs that pass one by one can be jointly
            impossible (a Carmen log: joint NIS 4600 for 6 dof), and one such batch can move
            the robot by metres.
        joint_probability: Confidence of that check; high (a gross-error test) so that a
            correct ICNN hypothesis is almost never sent to JCBB.
        nullspace: Optional (N, 5, 3) unobservable directions per landmark
            (:func:`.consistent_linearisation.unobservable_directions`): the innovation
            covariance of the gate, the joint check and JCBB takes the constrained Jacobians
            (:func:`.consistent_linearisation.constrain_jacobians`), the ones the OC-EKF's
            gain uses (``SlamParams.jacobians='observability_gain'``).
        jacobian_state: Optional state the Jacobians of that covariance are taken at (the
            FEJ-EKF's first estimates, ``'first_estimates'``); the prediction ``h(x)`` stays
            at ``x``. :mod:`.consistent_linearisation`: a gate must test the innovation with
            the covariance the update will use, or the global uncertainty the filter keeps
            along the unobservable directions widens it.
        cartesian_ratio: Optional: corner pairs inside the gate whose predicted range std
            ``sqrt(S_rr)`` is at least this fraction of the predicted range get
            ``d2 = max(d2, d2_map)`` with ``d2_map`` the pair tested in the map frame
            (:func:`cartesian_pair_d2`, ``SlamParams.cartesian_gate``); None: off.

    Returns:
        ``(hypothesis (M,) landmark index or -1 (eq. 49), d2 (M, N) eq. 54, jcbb nodes)``.
    """
    m = z.shape[0]
    n_lm = (x.size - 3) // 2
    if m == 0 or n_lm == 0:
        return np.full(m, -1, dtype=np.int64), np.full((m, n_lm), np.inf), 0
    index = np.arange(n_lm)
    zhat, hr, hf = observation_model(x, index, lm_kind)  # eq. 50
    if jacobian_state is not None:  # the Jacobians the update's gain will use
        hr, hf = observation_model(jacobian_state, index, lm_kind)[1:]
    elif nullspace is not None:
        hr, hf = constrain_jacobians(hr, hf, nullspace)
    c = predicted_observation_covariance(p, index, hr, hf)
    nu = z[:, None, :] - zhat[None, :, :]  # eq. 51
    nu[..., 1] = _wrap(nu[..., 1])
    d2 = mahalanobis_table(nu, c[None] + r[:, None])  # eqs. 52, 54
    if allowed is not None:
        d2 = np.where(allowed, d2, np.inf)
    if obs_kind is not None or lm_kind is not None:
        ok = (np.zeros(m, dtype=np.int8) if obs_kind is None else obs_kind)[:, None] == (
            np.zeros(n_lm, dtype=np.int8) if lm_kind is None else lm_kind)[None, :]
        if lm_kind is not None:
            ok &= ~((lm_kind == LINE) & ~(zhat[:, 0] > 0.0))[None, :]  # front side only
        d2 = np.where(ok, d2, np.inf)
    gate = chi2_gate(2, probability)
    if cartesian_ratio is not None:
        corner = np.ones((m, n_lm), dtype=bool)
        if obs_kind is not None:
            corner &= (obs_kind == CORNER)[:, None]
        if lm_kind is not None:
            corner &= (lm_kind == CORNER)[None, :]
        s_rr = c[None, :, 0, 0] + r[:, None, 0, 0]
        test = corner & (d2 < gate) & (s_rr >= (cartesian_ratio * zhat[None, :, 0]) ** 2)
        oi, lj = np.nonzero(test)
        if oi.size:
            d2[oi, lj] = np.maximum(d2[oi, lj], cartesian_pair_d2(x, p, z[oi], r[oi], lj))
    if method == 'icnn':
        hyp = icnn(d2, gate)  # eq. 55 + nearest neighbour
        if not joint_check or np.count_nonzero(hyp >= 0) < 2:
            return hyp, d2, 0
        obs = np.flatnonzero(hyp >= 0)
        feat = hyp[obs]
        s_h = joint_observation_covariance(p, feat, hr[feat], hf[feat])
        if joint_mahalanobis(nu[obs][:, feat], s_h, r[obs], np.arange(obs.size)) < chi2_gate(
                2 * obs.size, joint_probability):
            return hyp, d2, 0
        # Individually compatible, jointly not: decide with JCBB (below).
    sub = np.flatnonzero(np.any(d2 < gate, axis=0))
    hyp = np.full(m, -1, dtype=np.int64)
    if sub.size == 0:
        return hyp, d2, 0
    s_pred = joint_observation_covariance(p, sub, hr[sub], hf[sub])
    h_sub, _, nodes = jcbb(nu[:, sub], s_pred, r, d2[:, sub], probability, max_nodes)
    ok = h_sub >= 0
    hyp[ok] = sub[h_sub[ok]]
    return hyp, d2, nodes


def cartesian_pair_d2(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray,
                      index: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distance of corner pairs tested in the map frame.

    The observation ``z`` is put in the map with the robot pose, ``g(x_r, psi_r, z)``
    (eq. 40), and compared with landmark ``index``: ``e = g - x_i`` with covariance
    ``A P_5 A^T + G_z R G_z^T``, ``A = [G_r, -I]`` (eqs. 46, 48) and ``P_5`` the joint
    covariance of the robot pose and that landmark (the whole ``P``, unobservable
    directions included). ``e`` is linear in the robot position and the landmark and
    depends on the heading only through the observed range, so its first-order
    distribution stays accurate where the range-bearing one may not: a predicted range
    whose std is a sizeable fraction of the range (the range-bearing ``H`` is taken at
    the prediction, e.g. 22 m, and a near observation, e.g. 3 m, lies where its
    ``1 / r`` terms are far off). The test is the individual compatibility of Neira and
    Tardos ("Data association in stochastic mapping using the joint compatibility test",
    IEEE T-RA 17(6), 2001, section II) for the implicit measurement function
    ``f(x, z) = g(x_r, psi_r, z) - x_i = 0``, linearised at the estimate and the
    observation; module docstring, "Cartesian gate".

    Args:
        x: State.
        p: Covariance.
        z: (K, 2) corner observations [r, theta] in base_link.
        r: (K, 2, 2) their covariances.
        index: (K,) landmark index of each pair.

    Returns:
        (K,) ``e^T (A P_5 A^T + G_z R G_z^T)^-1 e``.
    """
    g, gr, gz = feature_initialization(x[:3], z)  # eqs. 40, 46, 48
    e = g - x[3:].reshape(-1, 2)[index]
    cols = np.concatenate([np.broadcast_to(np.arange(3), (index.size, 3)),
                           _landmark_cols(index)], axis=1)  # (K, 5)
    p5 = p[cols[:, :, None], cols[:, None, :]]
    a = np.concatenate([gr, np.broadcast_to(-np.eye(2), (index.size, 2, 2))], axis=2)
    cov = a @ p5 @ np.transpose(a, (0, 2, 1)) + gz @ r @ np.transpose(gz, (0, 2, 1))
    return np.einsum('ki,ki->k', e, np.linalg.solve(cov, e[:, :, None])[:, :, 0])


def free_space_contradictions(x: np.ndarray, p: np.ndarray, kind: np.ndarray,
                              ends: np.ndarray, bisector: np.ndarray, opening: np.ndarray,
                              scan: ScanGeometry, gate_probability: float,
                              min_view_margin: float, line_min_beams: int,
                              nullspace: Optional[np.ndarray] = None, lines: bool = True
                              ) -> Tuple[np.ndarray, np.ndarray]:
    """Which map landmarks a scan sees through, and which lie in its view, at a state.

    The negative-information test of ``SlamParams.free_space_check`` (module docstring,
    "Free-space check"): with the state ``x`` and covariance ``p`` that an association
    hypothesis would give (or the prior), a landmark is *seen through* when the scan's beams
    pass its predicted place and return from beyond it (:func:`.visibility.landmarks_missed`,
    the test of visibility-aware pruning, with the predicted observation std from ``p``:
    the landmark's and the robot's uncertainty propagated to the range, at the gate's
    one-dof ``sqrt(chi2_1(gate_probability))``). A solid corner or wall cannot be seen
    through, so each one counts against ``x``.

    Args:
        x: State.
        p: Its covariance.
        kind: (N,) landmark kinds.
        ends: (N, 2, 2) line extents (map).
        bisector: (N, 2) corner bisector sums.
        opening: (N,) corner openings.
        scan: The scan.
        gate_probability: Confidence of the per-landmark test.
        min_view_margin: Corner grazing margin [rad].
        line_min_beams: Beams for a line.
        nullspace: Optional (N, 5, 3) unobservable directions: the predicted std takes the
            constrained Jacobians (those of the gate and the gain with
            ``'observability_gain'``).
        lines: Judge line landmarks too (False: corners only; lines are never in view).

    Returns:
        ``(through (N,), in_view (N,))``: ``in_view`` a landmark the scan could have seen
        through: in view and range, facing, nothing in front of its place
        (:func:`.visibility.corners_in_view` without a distance limit,
        :func:`.visibility.lines_unoccluded`); the landmarks seen through are among them.
    """
    n = kind.size
    if n == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
    index = np.arange(n)
    _, hr, hf = observation_model(x, index, kind)
    if nullspace is not None:
        hr, hf = constrain_jacobians(hr, hf, nullspace)
    var = np.diagonal(predicted_observation_covariance(p, index, hr, hf), 0, 1, 2)
    params = x[3:3 + 2 * n].reshape(-1, 2)
    through = landmarks_missed(x[:3], kind, params, ends, bisector, opening,
                               np.sqrt(np.maximum(var, 0.0)), scan,
                               math.sqrt(chi2_gate(1, gate_probability)), min_view_margin,
                               line_min_beams)
    # Could be seen through: nothing in front of the place (the denominator of the test).
    in_view = np.zeros(n, dtype=bool)
    g = math.sqrt(chi2_gate(1, gate_probability))
    c = np.flatnonzero(kind != LINE)
    if c.size:
        in_view[c] = corners_in_view(x[:3], params[c], bisector[c], opening[c],
                                     np.sqrt(np.maximum(var[c], 0.0)), np.full(c.size, np.inf),
                                     scan, g, min_view_margin)
    ln = np.flatnonzero((kind == LINE) & np.all(np.isfinite(ends), axis=(1, 2)))
    if ln.size:
        in_view[ln] = lines_unoccluded(x[:3], params[ln], ends[ln],
                                       np.sqrt(np.maximum(var[ln, 0], 0.0)), scan, g,
                                       line_min_beams)
    in_view |= through
    if not lines:
        through &= kind != LINE
        in_view &= kind != LINE
    return through, in_view


def free_space_significant(count: int, in_view: int, gate_probability: float,
                           probability: float) -> bool:
    """Whether ``count`` landmarks seen through out of ``in_view`` refute a hypothesis.

    A landmark that is where the hypothesis puts it is seen through only if the beams at
    it all return beyond the one-sided gate, with probability at most
    ``q = (1 - gate_probability) / 2``; the count under a right hypothesis is then at most
    Binomial(``in_view``, ``q``) (independent beams), and the hypothesis is refuted when
    ``P(X >= count) < 1 - probability``.
    """
    if count <= 0:
        return False
    from scipy.stats import binom  # here: scipy.stats takes 0.3 s to import
    q = 0.5 * (1.0 - gate_probability)
    return bool(binom.sf(count - 1, max(int(in_view), int(count)), q) < 1.0 - probability)


def reject_ambiguous_pairs(hyp: np.ndarray, d2: np.ndarray, gate: float) -> np.ndarray:
    """Drop the pairs of a hypothesis that another pair could replace (mutual exclusion).

    A pair ``(i, j)`` is kept only if observation ``i`` has no other landmark inside the
    gate and landmark ``j`` no other observation inside it (``d2 < gate``, eq. 55, with the
    pairs the descriptor, extent and kind masks forbid already at ``inf``): where the gate
    holds two candidates, nearest-neighbour and JCBB choose by a few tenths of a unit of
    ``d2``, and a wrong choice along a corridor of repeated door frames moves the robot by
    the spacing of the features (module docstring, "Ambiguous pairs").

    Args:
        hyp: (M,) landmark index per observation or -1.
        d2: (M, N) squared Mahalanobis distances (eq. 54).
        gate: Chi-square gate.

    Returns:
        (M,) the hypothesis with the ambiguous pairs set to -1.
    """
    out = np.asarray(hyp).copy()
    if d2.size == 0 or not np.any(out >= 0):
        return out
    inside = d2 < gate
    per_obs = inside.sum(axis=1)
    per_lm = inside.sum(axis=0)
    on = np.flatnonzero(out >= 0)
    amb = (per_obs[on] > 1) | (per_lm[out[on]] > 1)
    out[on[amb]] = -1
    return out


class HypothesisChecks:
    """The :class:`~.ekf_slam.EkfSlam` steps that test an association hypothesis."""

    def _recover(self, hyp: np.ndarray, d2: np.ndarray, zu: np.ndarray, ru: np.ndarray,
                 allowed: Optional[np.ndarray], kind: Optional[np.ndarray],
                 null: Optional[np.ndarray], jac_x: Optional[np.ndarray]
                 ) -> Tuple[np.ndarray, np.ndarray, bool]:
        """JCBB at ``recovery_probability`` when nothing was paired (module docstring).

        See "Recovery": the caller still checks that ``recovery_pairs`` pairs survive
        ``reject_ambiguous`` (at this gate) and the free-space check.

        Returns:
            ``(hypothesis, d2, True)``: JCBB's hypothesis and its ``d2`` table if it pairs
            at least ``recovery_pairs`` observations, else ``(hyp, d2, False)``.
        """
        prm = self.params
        if d2.shape[1] == 0 or np.count_nonzero(np.any(
                d2 < chi2_gate(2, prm.recovery_probability), axis=1)) < prm.recovery_pairs:
            return hyp, d2, False
        wide, d2_wide, _ = do_data_association(
            self._x, self._p, zu, ru, 'jcbb', prm.recovery_probability, prm.jcbb_max_nodes,
            allowed, kind, self._kind if kind is not None else None, nullspace=null,
            jacobian_state=jac_x, cartesian_ratio=prm.cartesian_gate)
        if np.count_nonzero(wide >= 0) < prm.recovery_pairs:
            return hyp, d2, False
        return wide, d2_wide, True

    def _spurious_check(self, hyp: np.ndarray, ru: np.ndarray, scan: ScanGeometry,
                        counts: Tuple[int, int], null: Optional[np.ndarray],
                        jac_x: Optional[np.ndarray], gate: float) -> np.ndarray:
        """Drop pairs whose gate may hold another feature (module docstring, "Spurious pairs").

        Args:
            hyp: (M,) hypothesis over the used observations (landmark index or -1).
            ru: (M, 2, 2) their covariances as the gate used them.
            scan: The scan's geometry.
            counts: The scan's valid corner and line observations.
            null: The constrained Jacobians' directions the gate used, or None.
            jac_x: The state the gate's Jacobians were taken at, or None.
            gate: The chi-square bound the hypothesis was made with.

        Returns:
            The hypothesis with those pairs set to -1.
        """
        obs = np.flatnonzero(hyp >= 0)
        area, perimeter = swept_region(scan)
        if obs.size == 0 or not (area > 0.0 and perimeter > 0.0):
            return hyp
        j = hyp[obs]
        kind = self._kind[j]
        zhat, hr, hf = observation_model(self._x, j, kind)
        if jac_x is not None:  # the innovation covariance the gate used
            hr, hf = observation_model(jac_x, j, kind)[1:]
        elif null is not None:
            hr, hf = constrain_jacobians(hr, hf, null[j])
        s = predicted_observation_covariance(self._p, j, hr, hf) + ru[obs]
        det = s[:, 0, 0] * s[:, 1, 1] - s[:, 0, 1] * s[:, 1, 0]
        # The gate d2 <= g is an ellipse of area pi g sqrt(det S) in the observation's
        # coordinates; (r, theta) to the plane: dA = r dr dtheta; lines stay in (rho, alpha).
        area_gate = math.pi * gate * np.sqrt(np.maximum(det, 0.0))
        line = kind == LINE
        area_gate[~line] *= zhat[~line, 0]
        density = np.where(line, counts[1] / perimeter, counts[0] / area)
        crowded = ~(density * area_gate <= self.params.spurious_limit)
        if np.any(crowded):
            hyp = hyp.copy()
            hyp[obs[crowded]] = -1
            self.stats['spurious'] += int(np.count_nonzero(crowded))
        return hyp

    def _descriptor_gate(self, bvec: np.ndarray, opening: np.ndarray, feat_bis: np.ndarray,
                         feat_open: np.ndarray) -> Optional[np.ndarray]:
        """(M, K) mask of observation-feature pairs whose corner descriptors agree."""
        if feat_bis.shape[0] == 0 or bvec.shape[0] == 0:
            return None
        norm = np.hypot(feat_bis[:, 0], feat_bis[:, 1])
        dot = bvec @ feat_bis.T  # |b_obs| (0 or 1) * |b_feat| * cos(difference)
        bad = (dot < math.cos(self.params.bisector_gate) * norm[None, :] - 1e-12) & (
            norm[None, :] > 0.0) & (np.abs(bvec[:, :1]) + np.abs(bvec[:, 1:]) > 0.0)
        with np.errstate(invalid='ignore'):
            bad |= np.abs(opening[:, None] - feat_open[None, :]) > self.params.opening_gate
        return ~bad

    def _extent_gate(self, allowed: Optional[np.ndarray], kind: np.ndarray,
                     ends_w: np.ndarray) -> Optional[np.ndarray]:
        """Add the extent-overlap condition of line pairs to a (M, N) mask."""
        lm_line = np.flatnonzero(self._kind == LINE)
        ob_line = np.flatnonzero(kind == LINE)
        if lm_line.size == 0 or ob_line.size == 0:
            return allowed
        if allowed is None:
            allowed = np.ones((kind.size, self.num_landmarks), dtype=bool)
        lines = self._x[3:].reshape(-1, 2)[lm_line]
        margin = None
        if self.params.line_extent_sigmas is not None:
            # The robot's position std along each landmark's direction (SlamParams).
            d = np.column_stack([-np.sin(lines[:, 1]), np.cos(lines[:, 1])])
            var = np.einsum('ki,ij,kj->k', d, self._p[:2, :2], d)
            margin = self.params.line_extent_sigmas * np.sqrt(np.maximum(var, 0.0))
        ov = extents_overlap(lines, self._ends[lm_line], ends_w[ob_line], margin)
        allowed[np.ix_(ob_line, lm_line)] &= ov
        return allowed

    # ------------------------------------------------------------------ free-space check
    def _free_space_veto(self, hyp: np.ndarray, zu: np.ndarray, ru: np.ndarray,
                         d2: np.ndarray, scan: ScanGeometry, mixed: bool,
                         null: Optional[np.ndarray], jac_x: Optional[np.ndarray]
                         ) -> Tuple[np.ndarray, np.ndarray]:
        """Drop pairs whose posterior the scan refutes (module docstring, "Free-space check").

        Returns:
            ``(hypothesis, dropped observation indices into zu)``.
        """
        prm = self.params
        n = self.num_landmarks
        kind = self._kind[:n]
        gain_null = null if prm.jacobians == 'observability_gain' else None

        def seen(x: np.ndarray, p: np.ndarray, probability: float
                 ) -> Tuple[np.ndarray, np.ndarray]:
            return free_space_contradictions(
                x, p, kind, self._ends[:n], self._bis[:n], self._open[:n], scan,
                probability, prm.min_view_margin, prm.line_min_beams, gain_null,
                _FREE_SPACE_LINES)

        hyp = hyp.copy()
        matched = np.zeros(n, dtype=bool)
        matched[hyp[hyp >= 0]] = True

        def new_count(pairs: np.ndarray) -> Tuple[int, int]:
            if pairs.size == 0:
                return 0, 0
            x = self._x.copy()
            j = hyp[pairs]
            try:
                p, _ = ekf_update(x, self._p.copy(), zu[pairs], ru[pairs], j,
                                  prm.max_update_iterations, prm.relinearize_ratio,
                                  kind[j] if mixed else None,
                                  None if null is None else null[j],
                                  prm.jacobians == 'observability_gain', jac_x,
                                  kind if prm.jacobians == 'invariant' else None)
            except np.linalg.LinAlgError:
                return 0, 0
            through, view = seen(x, p, prm.gate_probability)
            # Only what the move of the mean does counts: a landmark seen through at the
            # prior mean, judged with the same covariance and no gate (g = 0: the beams pass
            # its predicted range at all), is a landmark the map may have lost (pruning's
            # business) or a borderline case, not evidence against the hypothesis.
            new = through & ~seen(self._x, p, _NO_GATE)[0] & ~matched
            return int(new.sum()), int((view & ~matched).sum())

        pairs = np.flatnonzero(hyp >= 0)
        count, view = new_count(pairs)
        dropped = []
        while pairs.size and free_space_significant(count, view, prm.gate_probability,
                                                    prm.free_space_check):
            trials = [new_count(np.delete(pairs, t)) for t in range(pairs.size)]
            # The pair whose removal leaves the fewest contradictions (ties: the worst d2).
            best = min(range(pairs.size),
                       key=lambda t: (trials[t][0], -d2[pairs[t], hyp[pairs[t]]]))
            if trials[best][0] >= count:
                break  # no pair is to blame: the contradiction is the map's
            dropped.append(int(pairs[best]))
            hyp[pairs[best]] = -1
            pairs = np.delete(pairs, best)
            count, view = trials[best]
        self.stats['free_space'] += len(dropped)
        return hyp, np.array(dropped, dtype=np.int64)
