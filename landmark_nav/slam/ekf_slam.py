"""EKF-SLAM with corner and line landmarks, corner chapter section 3 (eqs. 12-60, Fig. 17).

State layout (the one place it is defined)
------------------------------------------
``x = [x_r, y_r, psi_r, x_1, y_1, ..., x_N, y_N]`` (m, m, rad, m, ...), length ``3 + 2N``,
and its covariance ``P`` (``3 + 2N`` square). The robot pose is the pose of base_link in the
map frame, ``psi_r`` wrapped to [-pi, pi); landmark ``k`` (0-based, in the order it entered
the map) occupies ``x[3 + 2k : 5 + 2k]`` (a corner's ``x, y`` or a line's ``rho, alpha``,
see "Line landmarks"). Each landmark keeps the integer id it got when it was added (ids
count up from 0 and are never reused until :meth:`EkfSlam.reset`); a landmark leaves the
state only by pruning or eviction ("Map management"), and the others keep their order.
The map frame is the robot pose at step 0 (eqs. 23-24: ``P = 0``);
:class:`EkfSlam` takes that pose as ``initial_pose`` (default ``[0, 0, 0]``) so the map can
be expressed in the frame of the odometry / the simulator.

Filter steps (one function each, named after Fig. 17)
-----------------------------------------------------
* :func:`map_initialization` (eqs. 23-24).
* :func:`odometry_increment` (eq. 13) and :func:`odometry_noise` (``U``, below).
* :func:`ekf_predict` (eqs. 25-30): ``x_r <- x_r (+) u``; ``P_rr <- J1 P_rr J1^T + J2 U J2^T``
  (the chapter's eq. 26 prints ``J1^T`` in the second term; its eq. 28 has a sign typo, the
  Jacobians come from :func:`landmark_nav.geometry.compose_jacobians`) and
  ``P_rm <- J1 P_rm``; landmarks are static (eq. 12). O(N).
* :func:`observation_model` (eqs. 18-20, 37, 50, 53): range and bearing of landmarks from
  base_link with the Jacobians ``H_r`` (2 x 3) and ``H_F`` (2 x 2).
* :func:`do_data_association` (eqs. 49-55): ICNN with a chi-square gate (default) or JCBB,
  see :mod:`.association`.
* :func:`ekf_update` (eqs. 32-36): one batch update with every associated observation,
  re-linearised when the estimate moves far (see "Iterated update").
* :func:`augment_map` (eqs. 38-48): appends landmarks initialised from observations.

Noise models
------------
* Odometry (:class:`OdometryNoise`): the increment ``u = [dx, dy, dpsi]`` (eq. 13) gets the
  diagonal covariance ``U = diag(s_xy^2 d, s_xy^2 d, s_yd^2 d + s_yr^2 |dpsi|)`` with
  ``d = |(dx, dy)|``: variances grow linearly with the distance travelled and the angle
  turned (standard deviations per sqrt(m) and per sqrt(rad)), each diagonal entry raised to
  a floor ``sigma_xy_floor^2`` / ``sigma_yaw_floor^2`` so ``U`` is never singular. The
  defaults follow the simulated Pioneer (:class:`landmark_nav.sim.RobotParams`): each wheel
  speed has a random error of std ``0.01 |omega| + 0.001 rad/s`` per 0.1 s step, so at the
  cruise speed of 0.35 m/s the travelled distance has 1.4 mm/sqrt(m) and the heading
  8.2 mrad/sqrt(m), turning in place at 45 deg/s 6.7 mrad/sqrt(rad); the error across the
  direction of travel is negligible. On top, the uncalibrated robot drifts systematically
  (``k1, k2, k3``: 0.014 rad per metre and 0.95 % of every turn). Defaults: 1.5 mm/sqrt(m)
  (the random distance noise), 0.01 rad/sqrt(m) and 0.01 rad/sqrt(rad) (the random heading
  noise plus the systematic drift over a few scans; over 20 s without landmarks the drift
  exceeds them).
* Observations: ``R`` per observation, either given (e.g. propagated from the corner
  extractor's x-y covariance by :func:`.observations.corners_to_observations`) or the default
  ``diag(sigma_range^2, sigma_bearing^2)`` (eq. 22). The filter uses
  ``R_eff = r_scale R + diag(range_floor^2 + f^2, bearing_floor^2 + f^2 / r^2)`` with
  ``f = position_floor``. On the simulated office (seeds 10-29, 49 475 corners not seen
  grazing, errors against the true corner seen from the true pose) the extractor's
  first-order covariance alone gives a mean squared Mahalanobis error of 3.12 (median 1.81)
  against 2 (1.39) for 2 degrees of freedom, with a heavy tail from corners closer than about
  1 m. Part of the error persists (seeds 1 and 9): the errors of one corner are correlated
  (0.1 in range, 0.2 across the beam) even 50 scans apart, and the two corners of the
  cabinet recess are off by 3-6 mm on average in both runs (arm-fit biases that depend on
  the viewpoint, not on the noise), which a white-noise model would average away. The
  position floor is an isotropic Cartesian error of the corner standing for them; the
  default 3 mm brings the mean to 1.90 (median 1.10). It weighs most on the bearing of close
  corners, which would otherwise turn such a bias into a large heading correction. Without
  a floor the filter is optimistic (office seeds 0-9: mean robot NEES 3.6, three seeds map a
  corner twice; with the former 5 mm/sqrt(m) odometry noise three seeds lose track); the
  former 5 mm floor made ``R_eff`` twice too large (mean 1.29) and, with 5 mm/sqrt(m)
  odometry noise, the robot NEES pessimistic (mean 1.8 instead of 3).
* Lines: the extractor's ``(rho, alpha)`` covariance is a least-squares fit covariance of
  independent beams, so it shrinks with the number of beams; errors common to a segment's
  beams do not (a wall that is not straight, the laser's range bias, mixed returns at the
  ends). ``R_eff = R + line_end_covariance(z, ends, line_floor)``: independent offsets of
  std ``line_floor`` of the segment's two ends along its normal
  (:func:`.line_landmarks.line_end_covariance`; 1 cm is the order of a SICK LMS2xx's
  stated systematic range error). On the Carmen logs (each mapped line's observations put
  in the map with the reference poses) the spread about the line is about 1 cm at the
  middle of the segment and 0.2-0.8 deg in direction (seattle; shorter segments more),
  against a stated std of 2-3 mm and 0.04-0.45 deg: the median squared Mahalanobis error is
  31-93 instead of 2 on the six logs, and 8-30 % of the updates have a joint NIS above its
  95 % bound; with ``line_floor = 0.01`` 4-13 % (benchmarks/slam_consistency_carmen.py).
  The default is 0 (off): over drift seeds 1-2 of the six logs it did not improve ATE or
  RPE (benchmarks/slam_landmarks_carmen.py).
  A fixed floor does not carry from one log to another: the segment-wide error grows with
  how much the beams scatter about the line (a cluttered, uneven wall moves the fit as a
  whole). ``line_residual_factor = k`` gives each segment end offsets of std ``k s`` with
  ``s`` the segment's own unbiased residual std
  (:attr:`.line_landmarks.LineObservations.residual_std`, 5-20 mm median per Carmen log),
  in quadrature with ``line_floor``. With
  the observations the filter associated (drift seed 0), put in the map with the reference
  poses, the median squared Mahalanobis error over the six logs pooled is 5.0 at ``k = 1``,
  1.47 at ``k = 2`` and 0.96 at ``k = 2.5`` (chi-square median 1.39), per log 0.80-2.00 at
  ``k = 2``, against 0.78-4.57 for the fixed floor of 2 cm, which matches the pooled median
  as well. Run with ``k = 2`` (drift seed 0; seed 1 in brackets): line error 1.3-2.4
  [1.2-3.1] (2 expected; the reference poses' own error is in it), updates with a joint NIS
  above the 95 % bound 1.2-4.7 % [1.0-6.5 %] (was 8-30 % [9-28 %]),
  SE(2) ATE ratio to odometry median 0.25 (was 0.34) over drift seeds 0-1, reference inside
  the 95 % ellipse on a median 13 % of the steps (was 5 %), but RPE over 1 m median 2.8x
  the odometry's (was 2.1x; worst 5.0x, was 8.0x). The robot NEES stays far above 3 (the
  heading inconsistency of "Consistency" below), so ``k`` is 0 (off) by default.
  Grazing incidence: with ``k = 2`` the line observations seen less than 15 deg between beam
  and wall still have a median squared Mahalanobis error of 1.8-12 on the Carmen logs
  (0.9-3.5 at 15-60 deg; perfect odometry, reference poses). A beam of angular spread
  ``delta`` returns from a spot of std ``r delta`` across it, which on a wall at incidence
  ``theta`` spans ranges: effective range noise ``sigma_r^2 + (r delta / tan(theta))^2``,
  along the wall's normal ``delta r cos(theta) = delta |t|`` (``t``: the point's position
  along the line from the foot point). ``line_beam_width = delta`` adds it segment-wide at
  the two ends (:func:`.line_landmarks.line_footprint_covariance`; off by default, README
  "EKF-SLAM" for the measured effect).

Iterated update
---------------
After a long stretch without observations (a laser blackout, a loop closure) the first
update can move the robot by tens of centimetres, and ``h`` linearised at the prediction is
then wrong by centimetres: the plain EKF lands off the truth with a collapsed covariance and
rejects the next scans. :func:`ekf_update` therefore re-linearises (iterated EKF,
Gauss-Newton on the prior and the observations) while an observed landmark moves, relative
to the robot, by more than ``relinearize_ratio`` (2 %) of its range, at most
``max_update_iterations`` times. The association is decided once, at the prediction. In
ordinary tracking the moves stay below the ratio (office seeds 0-9: at most 1.8 %), so the
update is the plain EKF there. With any ``jacobians`` but ``'standard'`` the covariance
takes the first linearisation instead (at the prior, see "Consistency"): Jacobians taken at
the iterate, which moved in the unobservable directions too, would add information there;
``'first_estimates'`` and ``'observability_gain'`` do not iterate at all (their gain is not
the Jacobian at the iterate, and Gauss-Newton steps with it diverged).

Consistency (unobservable directions)
-------------------------------------
Moving the robot and the whole map together, or turning them together about the map
origin, changes no observation: the global position and heading are unobservable. The EKF's
Jacobians, taken at estimates that change between the prediction and the update, do not
respect this and the filter gains information about the global heading from relative
observations (Huang, Mourikis and Roumeliotis, "Observability-based rules for designing
consistent EKF SLAM estimators", IJRR 2010). With the drift of real odometry (a few degrees
of heading per metre) and corrections of decimetres per scan the effect is large: on the
Carmen logs the filter's heading std fell to 0.5 deg with errors of 3-5 deg (seattle).
``jacobians`` chooses the linearisation (``'standard'``, the chapter's, is the default):

* ``'observability'``: the prediction's ``J1`` takes its lever arm from the previous prior
  position (so the unobservable directions propagate exactly), a new landmark's ``G_r``
  from the current prior position (so it maps the robot's directions onto the landmark's at
  its first estimate, :func:`augment_map` ``lever_from``), and the covariance update uses
  ``H* = H (I - N (N^T N)^-1 N^T)``, the Jacobians closest to ``H`` that map the
  unobservable directions ``N`` (:func:`unobservable_directions`, taken at the robot's prior
  and at each landmark's estimate when it entered the map) to zero
  (:func:`constrain_jacobians`). The mean update keeps the gain of ``H``. Until the
  augmentation's lever arm was added, each new landmark brought heading information with
  it (``N^T P^-1 N`` grew 2e5-fold over 150 scans of seattle), so the figures measured
  with this option before then were of a filter still overconfident in heading.
* ``'observability_gain'``: the same with the mean update's gain from ``H*`` too (Huang et
  al.'s OC-EKF; the correction is then ``P^-1``-orthogonal to ``N``).
* ``'first_estimates'``: gain and covariance from ``H`` taken at the robot's prior position
  and each landmark's first estimate (Huang et al.'s FEJ-EKF), lever arms as above.
* ``'invariant'``: the chapter's Jacobians with the right-invariant EKF's update (Barrau and
  Bonnabel, arXiv:1510.06263): the correction applied on SE(2)
  (:func:`invariant_retraction`) and the covariance carried to the updated estimate
  (:func:`invariant_transport`); its unobservable directions follow the current estimate,
  no first estimates.

With ``'observability_gain'`` and ``'first_estimates'`` the association (gate, joint check,
JCBB) tests each innovation with the covariance of the update it admits to, from the same
Jacobians as the gain (:func:`do_data_association` ``nullspace`` / ``jacobian_state``).
The chapter's ``H`` at the current estimates stops annihilating ``N`` (taken at the first
estimates) once a landmark has moved, so ``H P H^T`` carried the global-heading uncertainty
these filters keep into the gate: on acapulco (perfect odometry) single pairs entered with
an update NIS of 805 and 1698 for 2 dof and turned the map by 14 and 41 deg.

All four keep ``N^T P^-1 N`` unchanged through updates and new landmarks
(``test/test_slam_consistency.py``). On the Carmen logs (benchmarks/slam_consistency_carmen.py,
six logs, drift seeds 0-1, ``line_residual_factor = 2``; medians over the 12 runs of the
share of steps with the reference inside the 95 % ellipse, the robot NEES median, the
SE(2) ATE and the RPE over 1 m as ratios to the odometry's): standard 10 %, 206, 0.26,
3.2; ``'observability'`` 22 %, 75, 0.81, 17.8 and ``'invariant'`` 20 %, 137, 0.73, 13.0
(the covariance keeps the heading uncertainty, but the mean, corrected with the gain of
``H``, turns along it: whole-run turns of 11-16 deg median); ``'first_estimates'`` 69 %,
6.8, 0.18, 1.8 and ``'observability_gain'`` 74 %, 6.0, 0.18, 1.5 (ellipse >= 80 % on 5
and 6 runs, all three issue targets on 2), better than the standard filter in ellipse
share on all 12 runs and in RPE on 8, but on aces and acapulco far worse (ATE 9-31 m, worse
than the odometry's except on aces seed 1; RPE 0.47-1.4 m), so the default stays
``'standard'``. Measured cause
(README, EKF-SLAM; ``--drift none --filter-noise pioneer``): with the reference's own
increments as odometry the updates alone turn the whole run by 0.5-16 deg while the
reported heading std is 0.4-5 deg; the map's heading was fixed at scan 2 with 4.8-6 deg of
heading std and no observation can reduce that, so the filter gained information in the
unobservable direction; the odometry model (its NEES over 1 m: 1.6-2.3) and the line noise
with ``line_residual_factor = 2`` fit.

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
still be ``'ambiguous'``). Aim: the aces pair of the README (perfect odometry, scan 199:
a corner 3 m away against a landmark predicted at 22.6 m with a range std of 8.6 m,
``d2`` 5.81, map frame 7.32). Measured (README, EKF-SLAM, ``observability_gain``, six
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
JCBB, the hypothesis's posterior (:func:`ekf_update` on a copy: the same Jacobians and
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
refuted. Measured in the README (EKF-SLAM, "Free-space check").

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
joint gates (:meth:`EkfSlam._recover`). The wider individual gate is what admits the pairs
(at 0.99 the scan above pairs the first corner, d2 8.5, and two walls, 9.1 and 7.3; the
second corner, 9.3, stays out); what keeps wrong ones out is the joint test over the pairs'
correlation through the robot and the count: the hypothesis is used only if at least
``recovery_pairs`` pairs remain after ``reject_ambiguous`` (tested at the wider gate) and
the free-space check (default 3: six measurements for a relocation of the three pose dof,
three of them to test it; with two, one redundant dof, acapulco's ATE doubled in one run).
Counted in ``stats['recovered']``. A scan with any pair is not touched, nor is a plain
widening of the gate (``gate_probability`` 0.99 everywhere, README: it broke acapulco).
Measured in the README (EKF-SLAM, "Recovery").

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
per-step trace with each pair labelled through the reference poses, README). With
``spurious_limit`` (off by default) each pair of the hypothesis is kept only when the
expected number of features of its kind inside its gate (the density is estimated with
the observed one counted), ``lambda A`` (the clutter density times the validation volume
of Bar-Shalom's probabilistic data association), is at most the limit
(:meth:`EkfSlam._spurious_check`):

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
Measured in the README (EKF-SLAM, "Spurious pairs").

Tentative landmarks (ghost protection)
--------------------------------------
An observation that no map landmark explains starts a *candidate* that lives OUTSIDE the
state, in a list with its own world position and 2 x 2 covariance (the observation put in
the map frame with the current pose, ``G_r P_rr G_r^T + G_z R G_z^T``, fused with later
hits by the information form). Later observations that no landmark explains are matched to
candidates with a Mahalanobis gate (greedy nearest, one hit per candidate per scan). A
candidate created at scan ``s0`` that collects ``confirm_hits`` hits (its first observation
included) before scan ``s0 + confirm_window`` is confirmed: the observation of the
confirming scan is augmented into the state with eqs. 38-48, so the state only ever sees
that one observation and its correct correlations; the earlier hits only decided that the
corner is real (their information is discarded rather than double counted, which keeps the
filter consistent). Candidates that do not reach the count within the window are dropped.
Candidates never update the robot pose.

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

Line landmarks
--------------
A landmark is a corner (``x, y``) or a line (``rho, alpha``, Hessian normal form, corner
chapter eq. 5), both in two state slots, so the layout above, the prediction, the batch
update and JCBB are shared; :attr:`EkfSlam.landmark_kinds` tells them apart and
:attr:`EkfSlam.line_ends` keeps each line's seen extent (map frame; display and
association only). :func:`observation_model`, :func:`feature_initialization` and
:func:`augment_map` dispatch per kind to :mod:`.line_landmarks` (model, Jacobians and the
mount transform of the extractor's covariance). Association: an observation pairs only
with a landmark of its kind; a line only with a line seen from its front (predicted
``rho_b > 0``) whose extent overlaps the observed segment (endpoints put in the map with
the predicted pose; ``line_extent_sigmas = k``, off by default, widens the landmark's
extent at both ends by ``k`` times the robot's position std along the line), then the same
chi-square gate (eq. 55) decides; JCBB tests the joint
compatibility of the mixed hypothesis. A matched line's extent grows by the observed
segment; candidates of lines work as those of corners (with the extent test). The corner
floors of ``R_eff`` do not apply to lines. ``landmarks: corners|lines|both`` is chosen by
what the caller passes (:func:`.features.extract_scan_features`).

Map management
--------------
Tentative landmarks (above) keep one-off clutter out of the state. A landmark that did
enter it and then disappears (a moved cart, a person, a ghost corner of mixed pixels) is
removed by visibility-aware pruning (:mod:`.visibility`): a scan whose beams pass through
the landmark's place (in view, facing, not occluded, every beam near it returning from
beyond it) is a *miss*; a detection (or an observation inside the
``new_landmark_probability`` gate, ambiguous or grazing) resets the count; after
``prune_misses`` consecutive misses (default ``confirm_hits``) the landmark is
marginalised out (its rows and columns dropped). A detector failure with a return at the
landmark is no miss: on the simulated office no landmark is pruned. Map size:
``max_landmarks`` is a budget; with ``map_full='evict'`` (default) a confirmed landmark
that finds the map full replaces the least recently seen one (ties: fewest detections)
that was not seen in this scan, so mapping never stops in a new area; ``'reject'`` keeps
the former behaviour (reason ``'cap'``).

Establishment (off by default, ``establish_hits > 0``): a corner that entered the state is
*provisional* until it is detected again, as a candidate is confirmed by hits:
``establish_hits`` detections after the one that confirmed it, counted in the scans that
gave it a chance
(:func:`.visibility.corners_in_view`: in view and range, facing, no return in front of it,
no farther than it was ever detected). A provisional corner whose chances reach
``establish_chances`` (default ``confirm_window``) with fewer detections is removed
(marginalised, ``stats['retired']``): the N-of-M rule of the candidates, counted in
opportunities instead of scans, so a corner the robot drove away from stays provisional
(and in the map) rather than being retired unseen. It aims at what the two other rules let
through: corners of clutter confirmed by three views from nearly one place and never again
detected from elsewhere, although their place stays in view and returns there (so no miss
is counted). An ambiguous or grazing observation near it is neither a chance nor a
detection. Lines are not affected (their chance would need the extent test). Why it is off:
on the CMU Wean logs (1 deg beams) real wall corners (door jambs) are as often not
detected again from other viewpoints as clutter is, and with ``establish_hits =
confirm_hits`` the share of corners within 10 cm of a wall of the building's grid fell
on two of the three logs (robotdata1 0.77 -> 0.70, robotdata5 0.62 -> 0.51, robotdata2
0.47 -> 0.58 with its scans 0.563 -> 0.540 near a wall; 16-18 corners retired per log;
``benchmarks/wean_map_check.py --establish-hits 3``).

Map reuse
---------
:meth:`EkfSlam.export_map` returns a :class:`.slam_map.SlamMap` (landmarks, kinds, their
joint covariance, extents, corner descriptors; file format in :mod:`.slam_map`,
:func:`.slam_map.save_map` / :func:`.slam_map.load_map`). :meth:`EkfSlam.load_map` starts
the filter on it at a user-given pose and pose covariance (independent of the map). With
``mode='localization'`` the filter then tracks the robot on the map: associations and
updates as usual (the map is refined by the robot's observations, keeping the joint
covariance consistent), but unexplained observations are rejected (``'localization'``):
no candidates, no new landmarks, no pruning or eviction; :meth:`EkfSlam.reset` keeps the
loaded map.

Association statuses per observation (:class:`UpdateResult`)
-------------------------------------------------------------
``'matched'`` (landmark id), ``'confirmed'`` (confirmed a candidate; new landmark id),
``'tentative'`` (hit of an existing candidate), ``'new'`` (started a candidate),
``'rejected'`` with a reason: ``'invalid'`` (NaN / inf, non-positive range or a
non-positive-definite ``R``), ``'range'`` (beyond ``max_range``), ``'grazing'`` (an arm seen
nearly edge-on, see above), ``'ambiguous'`` (not associated but inside the
``new_landmark_probability`` gate of a landmark: neither matched nor allowed to create a
duplicate), ``'cap'`` (the map holds ``max_landmarks`` and nothing can be evicted, or
``map_full='reject'``), ``'localization'`` (unexplained in localization mode),
``'free_space'`` (a pair dropped by the free-space check, ``free_space_check``).

Numerics
--------
The update uses the symmetric Cholesky form of eq. 35, ``P <- P - W1 W1^T`` with
``W1 = P H^T L^-T`` and ``S = L L^T``, then ``P <- (P + P^T) / 2``. After every update (every
``psd_check_interval``-th) a Cholesky factorisation of ``P + eps I`` (``eps`` =
``psd_tolerance`` times the largest diagonal entry) tests positive semi-definiteness; if it
fails, ``P`` is replaced by its nearest PSD matrix (eigenvalues clipped at 0), the repair is
counted in :attr:`EkfSlam.stats` and in the :class:`UpdateResult`, and the filter goes on
with the repaired matrix. Non-finite inputs are rejected before they reach the state.
"""

from dataclasses import dataclass, field
import math
from typing import Dict, List, Optional, Sequence, Tuple

from landmark_nav.geometry import compose_jacobians, relative, wrap_angle
import numpy as np
from scipy.linalg.lapack import dpotrf
from scipy.stats import binom

from ._linalg import solve_lower
from .association import icnn, jcbb, joint_mahalanobis, mahalanobis_table
from .consistency import chi2_gate
from .line_landmarks import (ends_to_map, extents_overlap, line_end_covariance,
                             line_footprint_covariance,
                             line_initialization,
                             line_observation_model, LineObservations, merge_extent,
                             project_extent)
from .slam_map import SlamMap
from .visibility import (corners_in_view, landmarks_missed, lines_unoccluded, ScanGeometry,
                         swept_region)

ASSOCIATION_METHODS = ('icnn', 'jcbb')
STATUSES = ('matched', 'confirmed', 'tentative', 'new', 'rejected')
#: Filter modes: ``'slam'`` maps and localizes, ``'localization'`` only tracks on the map.
MODES = ('slam', 'localization')
#: Jacobian choices (``SlamParams.jacobians``).
JACOBIANS = ('first_estimates', 'invariant', 'observability', 'observability_gain',
             'standard')
#: The choices that keep the unobservable directions at the robot's prior and the
#: landmarks' first estimates (lever arms of the prediction and of augmentation too).
_FIRST_ESTIMATE_RULES = ('first_estimates', 'observability', 'observability_gain')
#: What to do when a confirmed landmark finds the map at ``max_landmarks``.
MAP_FULL_POLICIES = ('evict', 'reject')
#: Landmark kinds (values of :attr:`EkfSlam.landmark_kinds`).
CORNER, LINE = 0, 1
#: A confidence whose one-dof gate is ~0 (the free-space check's prior-mean test).
_NO_GATE = 1e-12
#: Whether the free-space check counts line landmarks seen through (else corners only).
_FREE_SPACE_LINES = False
_PI = math.pi
_TWO_PI = 2.0 * math.pi


# ------------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class OdometryNoise:
    """Odometry increment noise ``U`` (see the module docstring).

    Attributes:
        sigma_xy_per_sqrt_m: Position std along each axis per sqrt(metre) [m/sqrt(m)].
        sigma_yaw_per_sqrt_m: Heading std per sqrt(metre) travelled [rad/sqrt(m)].
        sigma_yaw_per_sqrt_rad: Heading std per sqrt(radian) turned [rad/sqrt(rad)].
        sigma_xy_floor: Smallest position std of one increment [m].
        sigma_yaw_floor: Smallest heading std of one increment [rad].
    """

    sigma_xy_per_sqrt_m: float = 0.0015
    sigma_yaw_per_sqrt_m: float = 0.01
    sigma_yaw_per_sqrt_rad: float = 0.01
    sigma_xy_floor: float = 1e-4
    sigma_yaw_floor: float = 1e-4

    def __post_init__(self) -> None:
        """Validate: every field a finite number >= 0."""
        for name in self.__dataclass_fields__:
            _check_number(f'OdometryNoise.{name}', getattr(self, name), minimum=0.0)


@dataclass(frozen=True)
class SlamParams:
    """EKF-SLAM parameters (SI units, radians).

    Attributes:
        odometry: Odometry increment noise ``U``.
        sigma_range: Default range std when no ``R`` is given (eq. 22) [m].
        sigma_bearing: Default bearing std when no ``R`` is given (eq. 22) [rad].
        r_scale: Factor on the given ``R`` (>= 1 inflates an optimistic extractor).
        range_floor: Std added in quadrature to every range [m].
        bearing_floor: Std added in quadrature to every bearing [rad].
        position_floor: Isotropic corner position std added in quadrature (``f^2`` on the
            range, ``f^2 / r^2`` on the bearing) [m].
        line_floor: Std of the offset of each end of an observed line segment along its
            normal, independent between the ends [m]: errors common to a segment's beams
            that its fit covariance ignores (:func:`.line_landmarks.line_end_covariance`);
            added to every line observation's ``R`` (module docstring, "Noise models");
            0 (default) disables.
        line_residual_factor: ``k``: each line observation also gets segment-wide end
            offsets of std ``k`` times the segment's own residual std (its beams' scatter
            about the fitted line, :attr:`.line_landmarks.LineObservations.residual_std`),
            added in quadrature to ``line_floor`` (module docstring, "Noise models");
            0 disables.
        line_beam_width: ``delta``, the laser beam's 1-sigma angular spread across the
            beam [rad]: each line observation also gets the footprint term of
            :func:`.line_landmarks.line_footprint_covariance` (end offsets of std
            ``delta |t|``, ``t`` the end's position along the line from its foot point:
            the beam's effective range noise ``r delta / tan(theta)`` at incidence
            ``theta`` projected on the wall's normal; module docstring, "Noise models");
            0 (default) disables.
        max_range: Observations farther than this are rejected [m].
        association: ``'icnn'`` (default) or ``'jcbb'``.
        joint_check: With ICNN, fall back to JCBB when the ICNN hypothesis fails a joint
            compatibility test at ``joint_probability`` (:func:`do_data_association`).
        reject_ambiguous: Keep only the associated pairs whose observation has one
            landmark and whose landmark has one observation inside the gate
            (:func:`reject_ambiguous_pairs`); the others are rejected as ``'ambiguous'``.
        joint_probability: Confidence of that test; None (default):
            ``new_landmark_probability`` (a gross-error test); ``gate_probability`` makes
            it JCBB's own test.
        bisector_gate: Largest bisector difference of a corner pair (descriptors) [rad].
        opening_gate: Largest opening difference of a corner pair (descriptors) [rad].
        min_view_margin: Reject corners whose arm is seen within this angle of edge-on
            (descriptors needed) [rad]; 0 disables.
        gate_probability: Confidence ``1 - alpha`` of the compatibility gate (eq. 55).
        new_landmark_probability: An unassociated observation inside this gate of some
            landmark is rejected as ambiguous instead of starting a candidate (> gate).
        candidate_probability: Gate confidence for matching candidates.
        confirm_hits: Observations a candidate needs to enter the map (N).
        confirm_window: ...within this many consecutive scans from its first one (M >= N).
        max_landmarks: Map size budget (the state grows as ``3 + 2N``, an update costs
            ``O(N^2)``); what happens when it is reached is ``map_full``.
        map_full: ``'evict'`` (default): a landmark confirmed while the map is full replaces
            the least recently seen landmark (marginalised out of the state), so mapping
            of new areas never stops; ``'reject'``: the observation is rejected ('cap').
        prune_misses: Visibility-aware pruning (module docstring, "Map management"): a
            landmark that this many consecutive scans should have shown and did not (in
            the field of view and range, facing the robot, and the laser saw through its
            place, :mod:`.visibility`) is removed; 0 disables. Default ``confirm_hits``
            (None): as many scans to leave the map as to enter it. Needs the scan
            geometry passed to :meth:`EkfSlam.update`.
        establish_hits: Detections a provisional corner needs after entering the state to
            stay (module docstring, "Map management"); 0 (default) disables. Needs the
            scan geometry passed to :meth:`EkfSlam.update`.
        establish_chances: Chances (scans that could have shown it) within which those
            detections must come; default ``confirm_window`` (None).
        line_min_beams: Unoccluded beams a line landmark must cover to count as visible
            (the line extractor's ``min_points``).
        mode: ``'slam'`` or ``'localization'`` (track on the map; no candidates, no new
            landmarks, no pruning or eviction).
        jcbb_max_nodes: Node budget of JCBB per scan.
        psd_tolerance: Relative jitter of the positive semi-definiteness test.
        psd_check_interval: Test P every this many updates (1 = always).
        max_odometry_jump_m: :func:`odometry_check` threshold on one increment [m].
        max_odometry_jump_rad: :func:`odometry_check` threshold on one increment [rad].
        max_update_iterations: Largest number of linearisations of one update (1 = plain
            EKF; see "Iterated update" in the module docstring).
        jacobians: ``'standard'`` (default): the chapter's, at the latest estimates;
            ``'observability'``: the covariance update uses observability-constrained
            Jacobians, the mean update the chapter's; ``'observability_gain'``: both use the
            constrained ones (Huang et al.'s OC-EKF); ``'first_estimates'``: both use
            Jacobians at the robot's prior and each landmark's first estimate (FEJ-EKF);
            ``'invariant'``: the chapter's Jacobians, with the right-invariant EKF's update
            (the correction applied on SE(2) and the covariance carried to the updated
            estimate); module docstring, "Consistency".
        relinearize_ratio: Linearise again when an observed landmark moved, relative to the
            robot, by more than this fraction of its range during the update.
        cartesian_gate: None (default): off. Otherwise a corner pair that the range-bearing
            gate admits and whose predicted range std is at least this fraction of the
            predicted range is also tested in the map frame (the observation put in the
            map, against the landmark), where it is linear in the robot position and the
            landmark, and gated with the larger of the two ``d2``
            (:func:`cartesian_pair_d2`; module docstring, "Cartesian gate"); 0 tests every
            admitted corner pair.
        free_space_check: None (default): off. Otherwise the confidence of a
            negative-information test of each scan's association hypothesis (module
            docstring, "Free-space check"; :func:`free_space_contradictions`): the corners
            the scan sees through (:func:`.visibility.landmarks_missed`) at the posterior
            the hypothesis would give, and not at the prior, are counted; when so many
            would be unlikely for a right hypothesis, pairs are dropped (reason
            ``'free_space'``) until they are not. Needs the scan geometry.
        line_extent_sigmas: None (default): off. Otherwise ``k``: the extent-overlap test
            of line pairs widens each landmark's extent at both ends by ``k`` times the
            robot's position std along the landmark's direction (the observed segment is
            put in the map with the predicted pose, whose error along the line the plain
            test ignores); ``sqrt(chi2_1(0.95)) = 1.96`` when on. Lines only.
        recovery_probability: None (default): off. Otherwise, in a scan whose association
            pairs nothing, JCBB runs again with this confidence for the individual and the
            joint gates, and its hypothesis is used if at least ``recovery_pairs`` pairs
            remain after the other checks (module docstring, "Recovery"); in
            (``gate_probability``, ``new_landmark_probability``].
        recovery_pairs: Fewest pairs of such a hypothesis (default 3: six measurements for
            the three pose dof it corrects, three to test it).
        spurious_limit: None (default): off. Otherwise the largest expected number of
            features of the scene of a pair's kind that may lie inside its gate (the
            scan's density counts the observed one too, as in the non-parametric PDA):
            ``lambda A`` with ``A`` the gate region (of the confidence the hypothesis was
            made with) put in the plane (a corner) or in ``(rho, alpha)`` (a line) and
            ``lambda`` the scan's density of that kind (its valid corner observations over
            the area its beams sweep, its line observations over the perimeter of that
            region's convex hull); a pair above it is dropped (module docstring, "Spurious
            pairs"). Needs the scan geometry.
    """

    odometry: OdometryNoise = field(default_factory=OdometryNoise)
    sigma_range: float = 0.02
    sigma_bearing: float = math.radians(1.0)
    r_scale: float = 1.0
    range_floor: float = 0.0
    bearing_floor: float = 0.0
    position_floor: float = 0.003
    line_floor: float = 0.0
    line_residual_factor: float = 0.0
    line_beam_width: float = 0.0
    reject_ambiguous: bool = False
    max_range: float = math.inf
    association: str = 'icnn'
    joint_check: bool = True
    joint_probability: Optional[float] = None
    bisector_gate: float = math.radians(45.0)
    opening_gate: float = math.radians(60.0)
    min_view_margin: float = math.radians(8.0)
    gate_probability: float = 0.95
    new_landmark_probability: float = 0.99999
    candidate_probability: float = 0.999
    confirm_hits: int = 3
    confirm_window: int = 5
    max_landmarks: int = 200
    map_full: str = 'evict'
    prune_misses: Optional[int] = None
    establish_hits: int = 0
    establish_chances: Optional[int] = None
    line_min_beams: int = 8
    mode: str = 'slam'
    jcbb_max_nodes: int = 5000
    psd_tolerance: float = 1e-9
    psd_check_interval: int = 1
    max_odometry_jump_m: float = 0.5
    max_odometry_jump_rad: float = 1.0
    max_update_iterations: int = 5
    relinearize_ratio: float = 0.02
    jacobians: str = 'standard'
    cartesian_gate: Optional[float] = None
    free_space_check: Optional[float] = None
    line_extent_sigmas: Optional[float] = None
    recovery_probability: Optional[float] = None
    recovery_pairs: int = 3
    spurious_limit: Optional[float] = None

    def __post_init__(self) -> None:
        """Validate the parameters; raise ValueError naming the bad one."""
        if not isinstance(self.odometry, OdometryNoise):
            raise ValueError(f'SlamParams.odometry must be an OdometryNoise, '
                             f'got {self.odometry!r}')
        for name in ('sigma_range', 'sigma_bearing', 'range_floor', 'bearing_floor',
                     'position_floor', 'line_floor', 'line_residual_factor',
                     'line_beam_width', 'psd_tolerance',
                     'bisector_gate', 'opening_gate', 'min_view_margin'):
            _check_number(f'SlamParams.{name}', getattr(self, name), minimum=0.0)
        for name in ('max_odometry_jump_m', 'max_odometry_jump_rad', 'r_scale',
                     'relinearize_ratio'):
            _check_number(f'SlamParams.{name}', getattr(self, name), minimum=0.0,
                          strict=True)
        if not (isinstance(self.max_range, (int, float)) and self.max_range > 0.0):
            raise ValueError(f'SlamParams.max_range must be > 0, got {self.max_range!r}')
        if self.association not in ASSOCIATION_METHODS:
            raise ValueError(f'SlamParams.association must be one of {ASSOCIATION_METHODS}, '
                             f'got {self.association!r}')
        for name in ('gate_probability', 'new_landmark_probability', 'candidate_probability'):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 < v < 1.0):
                raise ValueError(f'SlamParams.{name} must be in (0, 1), got {v!r}')
        if self.cartesian_gate is not None:
            _check_number('SlamParams.cartesian_gate', self.cartesian_gate, minimum=0.0)
        if self.spurious_limit is not None:
            _check_number('SlamParams.spurious_limit', self.spurious_limit, minimum=0.0,
                          strict=True)
        if self.recovery_probability is not None and not (
                isinstance(self.recovery_probability, (int, float, np.integer, np.floating))
                and not isinstance(self.recovery_probability, bool)
                and self.gate_probability < self.recovery_probability
                <= self.new_landmark_probability):
            raise ValueError(f'SlamParams.recovery_probability must be in (gate_probability '
                             f'{self.gate_probability}, new_landmark_probability '
                             f'{self.new_landmark_probability}], '
                             f'got {self.recovery_probability!r}')
        if self.line_extent_sigmas is not None:
            _check_number('SlamParams.line_extent_sigmas', self.line_extent_sigmas,
                          minimum=0.0)
        if self.free_space_check is not None and not (
                isinstance(self.free_space_check, (int, float, np.integer, np.floating))
                and not isinstance(self.free_space_check, bool)
                and 0.0 < self.free_space_check < 1.0):
            raise ValueError(f'SlamParams.free_space_check must be in (0, 1), '
                             f'got {self.free_space_check!r}')
        if self.jacobians not in JACOBIANS:
            raise ValueError(f'SlamParams.jacobians must be one of {JACOBIANS}, '
                             f'got {self.jacobians!r}')
        if self.mode not in MODES:
            raise ValueError(f'SlamParams.mode must be one of {MODES}, got {self.mode!r}')
        if self.map_full not in MAP_FULL_POLICIES:
            raise ValueError(f'SlamParams.map_full must be one of {MAP_FULL_POLICIES}, '
                             f'got {self.map_full!r}')
        if self.prune_misses is None:
            object.__setattr__(self, 'prune_misses', self.confirm_hits)
        if not isinstance(self.prune_misses, int) or isinstance(self.prune_misses, bool) \
                or self.prune_misses < 0:
            raise ValueError(f'SlamParams.prune_misses must be an integer >= 0, '
                             f'got {self.prune_misses!r}')
        if self.establish_chances is None:
            object.__setattr__(self, 'establish_chances', self.confirm_window)
        for name in ('establish_hits', 'establish_chances'):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise ValueError(f'SlamParams.{name} must be an integer >= 0, got {v!r}')
        if self.establish_hits > 0 and self.establish_chances < self.establish_hits:
            raise ValueError(f'SlamParams.establish_chances ({self.establish_chances}) must '
                             f'be >= establish_hits ({self.establish_hits})')
        if self.joint_probability is None:
            object.__setattr__(self, 'joint_probability', self.new_landmark_probability)
        v = self.joint_probability
        if not (isinstance(v, (int, float)) and 0.0 < v < 1.0):
            raise ValueError(f'SlamParams.joint_probability must be in (0, 1), got {v!r}')
        if self.new_landmark_probability < self.gate_probability:
            raise ValueError('SlamParams.new_landmark_probability must be >= gate_probability')
        for name in ('confirm_hits', 'confirm_window', 'max_landmarks', 'jcbb_max_nodes',
                     'psd_check_interval', 'max_update_iterations', 'line_min_beams',
                     'recovery_pairs'):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f'SlamParams.{name} must be an integer >= 1, got {v!r}')
        if self.confirm_window < self.confirm_hits:
            raise ValueError(f'SlamParams.confirm_window ({self.confirm_window}) must be >= '
                             f'confirm_hits ({self.confirm_hits})')


def _check_number(name: str, v: object, minimum: float, strict: bool = False) -> None:
    ok = (isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
          and math.isfinite(v) and (v > minimum if strict else v >= minimum))
    if not ok:
        rule = f'> {minimum}' if strict else f'>= {minimum}'
        raise ValueError(f'{name} must be a finite number {rule}, got {v!r}')


# --------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False)
class UpdateResult:
    """Outcome of one :meth:`EkfSlam.update` (one scan), per observation where shaped (M,).

    Attributes:
        status: (M,) one of :data:`STATUSES`.
        landmark_id: (M,) id of the map landmark the observation updated ('matched') or
            created ('confirmed'), -1 otherwise.
        candidate_id: (M,) candidate id for 'new' / 'tentative', -1 otherwise.
        reason: (M,) rejection reason ('' unless 'rejected', see the module docstring).
        d2: (M,) individual squared Mahalanobis distance of matched pairs (eq. 54), nan else.
        nis: Joint NIS of the update (eq. 60), 0 when nothing was matched.
        nis_dof: Its degrees of freedom (2 x matched).
        psd_repaired: Whether P had to be projected to the PSD cone after this update.
        jcbb_nodes: Nodes visited by JCBB (0 for ICNN).
        kind: (M,) :data:`CORNER` / :data:`LINE` of each observation (corners first).
    """

    status: np.ndarray
    landmark_id: np.ndarray
    candidate_id: np.ndarray
    reason: np.ndarray
    d2: np.ndarray
    nis: float
    nis_dof: int
    psd_repaired: bool
    jcbb_nodes: int
    kind: Optional[np.ndarray] = None

    @property
    def matched(self) -> np.ndarray:
        """(M,) bool: observations that updated an existing landmark."""
        return self.status == 'matched'


@dataclass
class _Candidate:
    """A tentative landmark outside the state (see the module docstring)."""

    cid: int
    xy: np.ndarray     # (2,) map-frame position estimate
    cov: np.ndarray    # (2, 2) its covariance
    first_scan: int
    hits: int
    bis: np.ndarray    # (2,) sum of unit vectors of the world bisectors (zeros: unknown)
    opening: float     # mean opening (nan: unknown)
    n_open: int        # observations averaged into ``opening``
    kind: int = CORNER
    ends: Optional[np.ndarray] = None  # (2, 2) map-frame extent of a line candidate
    max_seen: float = 0.0  # largest detection distance


# ------------------------------------------------------------------- filter step functions
def map_initialization(initial_pose: Sequence[float] = (0.0, 0.0, 0.0)
                       ) -> Tuple[np.ndarray, np.ndarray]:
    """Start the stochastic map at the robot pose with perfect knowledge (eqs. 23-24).

    Args:
        initial_pose: Robot pose at step 0 expressed in the caller's frame (the chapter's
            base reference B is the robot itself, ``[0, 0, 0]``).

    Returns:
        ``(x (3,), P (3, 3) zeros)``.
    """
    x = np.array(initial_pose, dtype=float).reshape(3)  # eq. 23
    if not np.all(np.isfinite(x)):
        raise ValueError(f'initial_pose must be finite, got {initial_pose!r}')
    x[2] = wrap_angle(x[2])
    return x, np.zeros((3, 3))  # eq. 24


def odometry_increment(odom_prev: Sequence[float], odom_now: Sequence[float]) -> np.ndarray:
    """Control input from two dead-reckoned poses, ``u = (-)x_o(k-1) (+) x_o(k)`` (eq. 13).

    Args:
        odom_prev: Odometry pose at k-1, [x, y, psi].
        odom_now: Odometry pose at k.

    Returns:
        (3,) increment in the robot frame at k-1.
    """
    return relative(odom_prev, odom_now)  # eq. 13


def odometry_noise(u: np.ndarray, noise: OdometryNoise) -> np.ndarray:
    """Covariance ``U`` of an odometry increment (module docstring, "Noise models").

    Args:
        u: (3,) increment [dx, dy, dpsi].
        noise: The noise parameters.

    Returns:
        (3, 3) diagonal covariance.
    """
    d = math.hypot(u[0], u[1])
    vxy = max(noise.sigma_xy_per_sqrt_m ** 2 * d, noise.sigma_xy_floor ** 2)
    vyaw = max(noise.sigma_yaw_per_sqrt_m ** 2 * d + noise.sigma_yaw_per_sqrt_rad ** 2
               * abs(u[2]), noise.sigma_yaw_floor ** 2)
    return np.diag([vxy, vxy, vyaw])


def line_noise_covariance(params: SlamParams, z: np.ndarray, ends: np.ndarray,
                          residual_std: Optional[np.ndarray] = None) -> np.ndarray:
    """Return the segment-wide ``(rho, alpha)`` covariance the filter adds to line ``R``.

    The terms of ``line_floor``, ``line_residual_factor`` (with each segment's residual std;
    None or NaN: no such term) and ``line_beam_width`` (module docstring, "Noise models").

    Args:
        params: The filter parameters.
        z: (L, 2) line observations ``(rho, alpha)`` in the frame of ``ends``.
        ends: (L, 2, 2) their segments' endpoints.
        residual_std: Optional (L,) residual std of each segment [m].

    Returns:
        (L, 2, 2) covariances to add (zeros when every term is off).
    """
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    ends = np.asarray(ends, dtype=float).reshape(-1, 2, 2)
    out = np.zeros((z.shape[0], 2, 2))
    var = np.full(z.shape[0], params.line_floor ** 2)
    if params.line_residual_factor > 0.0 and residual_std is not None:
        res = np.nan_to_num(np.asarray(residual_std, dtype=float).reshape(-1))
        var += (params.line_residual_factor * res) ** 2
    if np.any(var > 0.0):
        out += var[:, None, None] * line_end_covariance(z, ends, 1.0)
    if params.line_beam_width > 0.0:
        out += line_footprint_covariance(z, ends, params.line_beam_width)
    return out


def ekf_predict(x: np.ndarray, p: np.ndarray, u: np.ndarray, u_cov: np.ndarray,
                lever_from: Optional[np.ndarray] = None) -> None:
    """Prediction with the odometry increment as control input (eqs. 25-30), in place.

    Args:
        x: (3 + 2N,) state, modified in place.
        p: (3 + 2N, 3 + 2N) covariance, modified in place.
        u: (3,) odometry increment (eq. 13).
        u_cov: (3, 3) its covariance ``U``.
        lever_from: Optional (2,) position the heading column of ``J1`` takes its lever arm
            from (observability-constrained: the previous prior, module docstring
            "Consistency"); None: the current estimate (eq. 28).
    """
    j1, j2 = compose_jacobians(x[:3], u)  # eqs. 27-30 (eq. 28 sign typo fixed)
    c, s = math.cos(x[2]), math.sin(x[2])
    x[0] += u[0] * c - u[1] * s  # eq. 25 (x_r (+) u, eq. 16)
    x[1] += u[0] * s + u[1] * c
    x[2] = _wrap(x[2] + u[2])
    if lever_from is not None:  # Phi of the OC-EKF: lever arm from the previous prior
        j1[0, 2], j1[1, 2] = -(x[1] - lever_from[1]), x[0] - lever_from[0]
    # eq. 26 with J2 U J2^T (the chapter prints J1^T in the second term).
    p[:3, :3] = j1 @ p[:3, :3] @ j1.T + j2 @ u_cov @ j2.T
    if p.shape[0] > 3:
        p[:3, 3:] = j1 @ p[:3, 3:]  # eq. 12: static landmarks, cross terms follow J1
        p[3:, :3] = p[:3, 3:].T
    p[:3, :3] = 0.5 * (p[:3, :3] + p[:3, :3].T)


def observation_model(x: np.ndarray, index: np.ndarray, kind: Optional[np.ndarray] = None
                      ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted observations of landmarks and their Jacobians (corners and lines).

    Corners (``kind`` 0, or ``kind`` None) are seen as range and bearing; lines (``kind``
    1) as ``(rho_b, alpha_b)`` (:func:`.line_landmarks.line_observation_model`). In both
    the second component is an angle (wrapped in innovations).

    ``r = sqrt(dx^2 + dy^2)`` (eq. 19), ``theta = atan2(dy, dx) - psi_r`` (eq. 20) with
    ``(dx, dy) = (x_i - x_r, y_i - y_r)``; eq. 53 splits ``H`` into::

        H_r  = d h / d(x_r, y_r, psi_r) = [[-dx/r, -dy/r, 0], [dy/r^2, -dx/r^2, -1]]
        H_Fj = d h / d(x_i, y_i)        = [[ dx/r,  dy/r],    [-dy/r^2,  dx/r^2]]

    Args:
        x: (3 + 2N,) state.
        index: (K,) landmark indices (0-based positions in the state).
        kind: Optional (K,) kind of each indexed landmark (:data:`CORNER` / :data:`LINE`).

    Returns:
        ``(zhat (K, 2), H_r (K, 2, 3), H_F (K, 2, 2))`` (eqs. 37, 50, 53).
    """
    if kind is not None and np.any(kind == LINE):
        with np.errstate(divide='ignore', invalid='ignore'):  # rows overwritten below
            zhat, hr, hf = _corner_model(x, index)
        ln = np.flatnonzero(kind == LINE)
        zl, hrl, hfl = line_observation_model(x[:3], x[3:].reshape(-1, 2)[index[ln]])
        zhat[ln], hr[ln], hf[ln] = zl, hrl, hfl
        return zhat, hr, hf
    return _corner_model(x, index)


def _corner_model(x: np.ndarray, index: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Range-bearing model of :func:`observation_model` for every indexed landmark."""
    lm = x[3:].reshape(-1, 2)[index]
    dx = lm[:, 0] - x[0]
    dy = lm[:, 1] - x[1]
    q = dx * dx + dy * dy
    r = np.sqrt(q)
    zhat = np.empty((index.size, 2))
    zhat[:, 0] = r  # eq. 19
    zhat[:, 1] = _wrap(np.arctan2(dy, dx) - x[2])  # eq. 20
    hf = np.empty((index.size, 2, 2))
    hf[:, 0, 0], hf[:, 0, 1] = dx / r, dy / r
    hf[:, 1, 0], hf[:, 1, 1] = -dy / q, dx / q
    hr = np.zeros((index.size, 2, 3))
    hr[:, :, :2] = -hf
    hr[:, 1, 2] = -1.0
    return zhat, hr, hf


def _landmark_cols(index: np.ndarray) -> np.ndarray:
    """(K, 2) state columns of landmarks ``index``."""
    return 3 + 2 * index[:, None] + np.arange(2)[None, :]


def predicted_observation_covariance(p: np.ndarray, index: np.ndarray, hr: np.ndarray,
                                     hf: np.ndarray) -> np.ndarray:
    """``H P H^T`` per landmark (eq. 52 without ``R``), vectorised over landmarks.

    Args:
        p: Covariance of the state.
        index: (K,) landmark indices.
        hr: (K, 2, 3) robot Jacobians.
        hf: (K, 2, 2) landmark Jacobians.

    Returns:
        (K, 2, 2) covariances of the predicted observations.
    """
    cols = _landmark_cols(index)
    p_rf = np.transpose(p[:3][:, cols], (1, 0, 2))  # (K, 3, 2)
    p_ff = p[cols[:, :, None], cols[:, None, :]]  # (K, 2, 2)
    hft = np.transpose(hf, (0, 2, 1))
    cross = hr @ p_rf @ hft
    c = hr @ p[:3, :3] @ np.transpose(hr, (0, 2, 1)) + cross + np.transpose(cross, (0, 2, 1))
    c += hf @ p_ff @ hft
    return c


def joint_observation_covariance(p: np.ndarray, index: np.ndarray, hr: np.ndarray,
                                 hf: np.ndarray) -> np.ndarray:
    """Joint covariance ``H P H^T`` of several predicted observations (for JCBB).

    Args:
        p: Covariance of the state.
        index: (K,) landmark indices.
        hr: (K, 2, 3) robot Jacobians.
        hf: (K, 2, 2) landmark Jacobians.

    Returns:
        (K, 2, K, 2) covariance (block (a, b) = cov(zhat_a, zhat_b)).
    """
    h = _dense_h(p.shape[0], index, hr, hf)
    return (h @ p @ h.T).reshape(index.size, 2, index.size, 2)


def _dense_h(n: int, index: np.ndarray, hr: np.ndarray, hf: np.ndarray) -> np.ndarray:
    """Dense (2K, n) observation Jacobian (eq. 53)."""
    k = index.size
    h = np.zeros((k, 2, n))
    h[:, :, :3] = hr
    cols = _landmark_cols(index)
    rows = np.arange(k)
    h[rows, :, cols[:, 0]] = hf[:, :, 0]
    h[rows, :, cols[:, 1]] = hf[:, :, 1]
    return h.reshape(2 * k, n)


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
            (:func:`unobservable_directions`): the innovation covariance of the gate, the
            joint check and JCBB takes the constrained Jacobians (:func:`constrain_jacobians`),
            the ones the OC-EKF's gain uses (``SlamParams.jacobians='observability_gain'``).
        jacobian_state: Optional state the Jacobians of that covariance are taken at (the
            FEJ-EKF's first estimates, ``'first_estimates'``); the prediction ``h(x)`` stays
            at ``x``. Module docstring, "Consistency": a gate must test the innovation with
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


def ekf_update(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray,
               index: np.ndarray, max_iterations: int = 1,
               relinearize_ratio: float = 0.02, kind: Optional[np.ndarray] = None,
               nullspace: Optional[np.ndarray] = None, constrained_gain: bool = False,
               jacobian_state: Optional[np.ndarray] = None,
               invariant_kinds: Optional[np.ndarray] = None) -> Tuple[np.ndarray, float]:
    """Batch EKF update with observations of map landmarks (eqs. 32-37), in place.

    ``nu = z - h(x)`` (eqs. 36-37, bearings wrapped), ``S = H P H^T + R`` (eq. 33),
    ``W = P H^T S^-1`` (eq. 32), ``x += W nu`` (eq. 34), ``P -= W S W^T`` (eq. 35) evaluated
    as ``P -= W1 W1^T`` with ``W1 = P H^T L^-T``, ``S = L L^T``. ``H`` is never formed: each
    observation touches the robot and one landmark, so ``P H^T`` is gathered block-wise.

    Iterated form (module docstring, "Iterated update"): with ``max_iterations > 1``, if an
    observed landmark moved relative to the robot by more than ``relinearize_ratio`` times
    its range, ``h`` and ``H`` are evaluated again at the new estimate ``x_i`` and the update
    is recomputed from the prior ``x_0, P`` with ``nu_i = z - h(x_i) - H_i (x_0 - x_i)``
    (Gauss-Newton); ``P`` takes the last ``H_i``. Otherwise the result is the plain update.

    Args:
        x: State (modified in place).
        p: Covariance (overwritten with the unsymmetrised result).
        z: (K, 2) observations.
        r: (K, 2, 2) their covariances.
        index: (K,) landmark index of each observation (distinct).
        max_iterations: Largest number of linearisations (1 = plain EKF).
        relinearize_ratio: Relative move that triggers another linearisation (a line's
            "position" relative to the robot is its foot point ``rho_b (cos, sin)(alpha)``).
        kind: Optional (K,) kind of each observed landmark (None: corners).
        nullspace: Optional (K, 5, 3) unobservable directions of ``[robot, landmark]`` per
            observation (:func:`unobservable_directions`); each ``[H_r, H_F]`` is replaced
            by the closest matrix that maps them to zero (observability-constrained EKF) in
            the covariance update (taken at the first linearisation), and with
            ``constrained_gain`` in the mean update too (at every linearisation).
        constrained_gain: With ``nullspace``: the mean update's gain from the constrained
            Jacobians as well (Huang et al.'s OC-EKF); one linearisation (no iteration).
        jacobian_state: Optional state the Jacobians (not ``h``) are taken at, for the gain
            and the covariance (first-estimates Jacobians: the robot's prior and each
            landmark's first estimate; module docstring, "Consistency"); the innovation
            stays ``z - h(x)``; one linearisation (no iteration).
        invariant_kinds: Optional kinds of every landmark in the state: right-invariant
            update (:func:`invariant_retraction`, :func:`invariant_transport`; the
            covariance from the first linearisation).

    Returns:
        ``(P, NIS)``: the symmetrised covariance (a new array) and ``nu^T S^-1 nu`` (eq. 60)
        of the first linearisation (the prior innovation).

    Raises:
        numpy.linalg.LinAlgError: If ``S`` is not positive definite.
    """
    if index.size == 0:
        return p, 0.0
    cols = _landmark_cols(index)
    x0 = x
    x_prior = x.copy() if invariant_kinds is not None else x
    x_lin = x
    nis_value = 0.0
    if jacobian_state is not None or constrained_gain:
        # Gauss-Newton steps need the Jacobian at the iterate; with first-estimate or
        # constrained ones they are not (iterated, each ran the state off, to 1e12 m on
        # aces, on 11 of 24 Carmen runs), so these take one linearisation.
        max_iterations = 1
    for it in range(max(1, int(max_iterations))):
        zhat, hr, hf = observation_model(x_lin, index, kind)  # eq. 37
        nu = z - zhat  # eq. 36
        nu[:, 1] = _wrap(nu[:, 1])
        # FEJ-EKF (Huang, Mourikis, Roumeliotis, IJRR 2010, the FEJ-EKF section): H_k at
        # p_R(k|k-1) and each landmark's first estimate p_Li; OC-EKF (same paper): H* the
        # closest to H with H* N = 0 (:func:`constrain_jacobians`).
        if jacobian_state is not None:
            hr, hf = observation_model(jacobian_state, index, kind)[1:]
        elif nullspace is not None and constrained_gain:
            hr, hf = constrain_jacobians(hr, hf, nullspace)
        if it > 0:  # iterated EKF: nu_i = z - h(x_i) - H_i (x_0 - x_i)
            dx = x0 - x_lin
            dx[2] = _wrap(dx[2])
            nu -= hr @ dx[:3] + np.einsum('kij,kj->ki', hf, dx[cols])
        w1, low = _gain_factor(p, hr, hf, r, cols)
        y = solve_lower(low, nu.reshape(-1))
        if it == 0:
            nis_value = float(y @ y)
            if jacobian_state is not None or constrained_gain or invariant_kinds is not None:
                w1_cov = w1
            elif nullspace is not None:  # covariance: constrained Jacobians at the prior
                w1_cov = _gain_factor(p, *constrain_jacobians(hr, hf, nullspace), r, cols)[0]
        x_new = x0 + w1 @ y  # eqs. 32, 34
        x_new[2] = _wrap(x_new[2])
        if it + 1 >= max_iterations:
            break
        rel_old = _relative_points(x_lin, index, kind)
        move = _relative_points(x_new, index, kind) - rel_old
        if np.all(np.hypot(move[:, 0], move[:, 1])
                  <= relinearize_ratio * np.hypot(rel_old[:, 0], rel_old[:, 1])):
            break
        x_lin = x_new
    if invariant_kinds is not None:
        dx = x_new - x_prior
        dx[2] = _wrap(dx[2])
        x_new = invariant_retraction(x_prior, dx, invariant_kinds)
    x[:] = x_new
    if nullspace is None and jacobian_state is None and invariant_kinds is None:
        w1_cov = w1  # the last linearisation (the iterated EKF's covariance)
    p -= w1_cov @ w1_cov.T  # eq. 35 (in place: no fresh n x n allocation)
    if invariant_kinds is not None:
        p = invariant_transport(p, x_prior, x, invariant_kinds)
    return 0.5 * (p + p.T), nis_value


def _position_slots(kinds: np.ndarray) -> np.ndarray:
    """State indices of the x coordinates of the robot and of every corner."""
    corner = np.flatnonzero(np.asarray(kinds) != LINE)
    return np.concatenate([[0], 3 + 2 * corner]).astype(np.int64)


def invariant_retraction(x: np.ndarray, dx: np.ndarray, kinds: np.ndarray) -> np.ndarray:
    """Apply an EKF correction the right-invariant way: ``exp(xi) X`` on SE_K(2).

    Right-invariant EKF-SLAM (Barrau and Bonnabel, "An EKF-SLAM algorithm with consistency
    properties", arXiv:1510.06263, 2015): the robot's heading and the positions of the
    robot and of every corner form one group element (one rotation, K translations). The
    correction ``dx`` (in the state's own coordinates) is read as ``xi``: the heading part
    ``a = dx_psi`` and ``xi_p = dx_p - a J p`` for each position ``p`` (``J`` the
    90-degree turn), then ``p+ = R(a) p + V(a) xi_p`` with the SE(2) ``V(a) =
    [[sin a, cos a - 1], [1 - cos a, sin a]] / a``: everything turns by ``a`` about the
    map origin, so the correction's rotation is exact. To first order this is ``x + dx``.
    A line ``(rho, alpha)`` is turned by the same rotation, ``rho`` unchanged: additive.

    Args:
        x: (3 + 2N,) state before the correction.
        dx: (3 + 2N,) correction (heading wrapped).
        kinds: (N,) landmark kinds.

    Returns:
        The corrected state (a new array).
    """
    out = x + dx
    a = float(dx[2])
    out[2] = _wrap(x[2] + a)
    if a == 0.0:
        return out
    i = _position_slots(kinds)
    px, py = x[i], x[i + 1]
    xi_x = dx[i] + a * py  # xi_p = dx_p - a J p, J p = (-p_y, p_x)
    xi_y = dx[i + 1] - a * px
    c, s = math.cos(a), math.sin(a)
    if abs(a) > 1e-9:
        v0, v1 = s / a, (1.0 - c) / a
    else:
        v0, v1 = 1.0, 0.5 * a
    out[i] = c * px - s * py + v0 * xi_x - v1 * xi_y
    out[i + 1] = s * px + c * py + v1 * xi_x + v0 * xi_y
    return out


def invariant_transport(p: np.ndarray, x_old: np.ndarray, x_new: np.ndarray,
                        kinds: np.ndarray) -> np.ndarray:
    """Carry the covariance from ``x_old`` to ``x_new`` in the right-invariant error.

    The right-invariant error ``xi`` (:func:`invariant_retraction`) relates to the state's
    error by ``dx = T(x) xi``: the robot's heading error turns every position ``p`` by
    ``J p``. Its unobservable directions are constant in ``xi`` (a turn of the world is
    ``xi_psi`` alone, a shift is the same ``xi_p`` for all positions), and the update's
    Jacobians at ``x_old`` annihilate them there, so the update gains no information on
    them; keeping ``P_xi`` after the estimate moved to ``x_new`` means
    ``P <- M P M^T`` with ``M = T(x_new) T(x_old)^-1 = I + c e_psi^T``,
    ``c = J (p_new - p_old)`` at every position (zero for lines and the heading). The
    standard EKF leaves ``P`` at ``x_old``'s directions while the prediction and later
    updates linearise at ``x_new``: the information it gains on the global heading.

    Args:
        p: (n, n) covariance at ``x_old`` (after the update's ``P - W S W^T``).
        x_old: State the update linearised at.
        x_new: Updated state.
        kinds: (N,) landmark kinds.

    Returns:
        The carried covariance (a new array).
    """
    i = _position_slots(kinds)
    c = np.zeros(p.shape[0])
    c[i] = -(x_new[i + 1] - x_old[i + 1])
    c[i + 1] = x_new[i] - x_old[i]
    row = p[2].copy()
    return p + np.outer(c, row) + np.outer(row, c) + p[2, 2] * np.outer(c, c)


def _gain_factor(p: np.ndarray, hr: np.ndarray, hf: np.ndarray, r: np.ndarray,
                 cols: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``W1 = P H^T L^-T`` and ``L`` (``S = H P H^T + R = L L^T``, eq. 33)."""
    k, n = hr.shape[0], p.shape[0]
    rows = np.arange(k)
    hr2 = hr.reshape(2 * k, 3)
    # P H^T, (n, 2K): robot part plus each observation's landmark block.
    pht = p[:, :3] @ hr2.T
    p_cols = np.transpose(p[:, cols], (1, 0, 2))  # (K, n, 2)
    pht += np.transpose(p_cols @ np.transpose(hf, (0, 2, 1)), (1, 0, 2)).reshape(n, 2 * k)
    s = hr2 @ pht[:3] + (hf @ pht[cols]).reshape(2 * k, 2 * k)
    s4 = s.reshape(k, 2, k, 2)
    s4[rows, :, rows, :] += r
    s = 0.5 * (s + s.T)
    low = np.linalg.cholesky(s)
    return solve_lower(low, pht.T).T, low


def unobservable_directions(robot_xy: np.ndarray, first: np.ndarray,
                            kind: Optional[np.ndarray] = None) -> np.ndarray:
    """Unobservable directions of ``[x_r, y_r, psi_r, landmark]`` (module docstring).

    Moving the whole map and robot by ``(dx, dy)`` and turning it by ``dtheta`` about the
    map origin changes no observation. Columns: ``x``, ``y``, rotation; rows: the robot
    ``[[1, 0, -y_r], [0, 1, x_r], [0, 0, 1]]``, a corner ``[[1, 0, -y], [0, 1, x]]``, a line
    ``(rho, alpha)`` ``[[cos(alpha), sin(alpha), 0], [0, 0, 1]]``.

    Args:
        robot_xy: (2,) robot position the directions are taken at.
        first: (K, 2) landmark parameters they are taken at.
        kind: Optional (K,) kinds (None: corners).

    Returns:
        (K, 5, 3) directions.
    """
    k = first.shape[0]
    n = np.zeros((k, 5, 3))
    n[:, 0, 0] = n[:, 1, 1] = n[:, 2, 2] = 1.0
    n[:, 0, 2], n[:, 1, 2] = -robot_xy[1], robot_xy[0]
    n[:, 3, 0] = n[:, 4, 1] = 1.0
    n[:, 3, 2], n[:, 4, 2] = -first[:, 1], first[:, 0]
    if kind is not None and np.any(kind == LINE):
        ln = np.flatnonzero(kind == LINE)
        a = first[ln, 1]
        n[ln, 3:] = 0.0
        n[ln, 3, 0], n[ln, 3, 1] = np.cos(a), np.sin(a)
        n[ln, 4, 2] = 1.0
    return n


def constrain_jacobians(hr: np.ndarray, hf: np.ndarray, nullspace: np.ndarray
                        ) -> Tuple[np.ndarray, np.ndarray]:
    """Closest ``[H_r, H_F]`` (Frobenius) with ``[H_r, H_F] N = 0`` (OC-EKF).

    ``H* = H (I - N (N^T N)^-1 N^T)`` per observation.

    Args:
        hr: (K, 2, 3) robot Jacobians.
        hf: (K, 2, 2) landmark Jacobians.
        nullspace: (K, 5, 3) directions ``N`` (:func:`unobservable_directions`).

    Returns:
        ``(H_r*, H_F*)``.
    """
    h = np.concatenate([hr, hf], axis=2)  # (K, 2, 5)
    nt = np.transpose(nullspace, (0, 2, 1))
    hn = h @ nullspace  # (K, 2, 3)
    h = h - hn @ np.linalg.solve(nt @ nullspace, nt)
    return h[:, :, :3], h[:, :, 3:]


def _relative_points(x: np.ndarray, index: np.ndarray, kind: Optional[np.ndarray]
                     ) -> np.ndarray:
    """(K, 2) landmark positions relative to the robot (a line: its foot point)."""
    lm = x[3:].reshape(-1, 2)[index]
    rel = lm - x[:2]
    if kind is not None and np.any(kind == LINE):
        ln = np.flatnonzero(kind == LINE)
        a = lm[ln, 1]
        n = np.column_stack([np.cos(a), np.sin(a)])
        rho_b = lm[ln, 0] - n @ x[:2]
        rel[ln] = rho_b[:, None] * n
    return rel


def feature_initialization(pose: np.ndarray, z: np.ndarray, kind: Optional[np.ndarray] = None
                           ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return new landmark positions and their Jacobians (eqs. 39-40, 45-48).

    Args:
        pose: (3,) robot pose [x_r, y_r, psi_r].
        z: (L, 2) observations [r, theta] (lines: [rho_b, alpha_b]).
        kind: Optional (L,) kinds (None: corners); lines use
            :func:`.line_landmarks.line_initialization`.

    Returns:
        ``(g (L, 2), G_r (L, 2, 3), G_z (L, 2, 2))``.
    """
    if kind is not None and np.any(kind == LINE):
        g, gr, gz = feature_initialization(pose, z)
        ln = np.flatnonzero(kind == LINE)
        g[ln], gr[ln], gz[ln] = line_initialization(pose, z[ln])
        return g, gr, gz
    rng, a = z[:, 0], z[:, 1] + pose[2]
    c, s = np.cos(a), np.sin(a)
    g = np.column_stack([pose[0] + rng * c, pose[1] + rng * s])  # eq. 40
    gr = np.zeros((z.shape[0], 2, 3))
    gr[:, 0, 0] = gr[:, 1, 1] = 1.0
    gr[:, 0, 2], gr[:, 1, 2] = -rng * s, rng * c  # eq. 46
    gz = np.empty((z.shape[0], 2, 2))
    gz[:, 0, 0], gz[:, 0, 1] = c, -rng * s  # eq. 48
    gz[:, 1, 0], gz[:, 1, 1] = s, rng * c
    return g, gr, gz


def augment_map(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray,
                kind: Optional[np.ndarray] = None, lever_from: Optional[np.ndarray] = None
                ) -> Tuple[np.ndarray, np.ndarray]:
    """Append landmarks initialised from observations to the state (eqs. 38-48).

    ``P* = Y [[P, 0], [0, R]] Y^T`` (eq. 43) with ``Y`` of eq. 44 evaluated block-wise: the
    new rows are ``G_r P_r.`` and the new diagonal ``G_r P_rr G_r^T + G_z R G_z^T``.

    Args:
        x: State.
        p: Covariance.
        z: (L, 2) observations of the new landmarks.
        r: (L, 2, 2) their covariances.
        kind: Optional (L,) kinds (None: corners).
        lever_from: Optional (2,) robot position the heading column of ``G_r`` takes its
            lever arm from (observability-constrained: the robot's prior position, so
            that ``G_r`` maps the robot's unobservable directions onto the new landmark's
            at its first estimate, module docstring "Consistency"); None: the current
            estimate (eq. 46).

    Returns:
        ``(x*, P*)`` new arrays of size ``n + 2L``.
    """
    n, nl = x.size, z.shape[0]
    g, gr, gz = feature_initialization(x[:3], z, kind)
    if lever_from is not None:  # G_r N_r(prior) = N_new(g): no information on them
        line = np.zeros(nl, dtype=bool) if kind is None else np.asarray(kind) == LINE
        gr[~line, 0, 2] = -(g[~line, 1] - lever_from[1])
        gr[~line, 1, 2] = g[~line, 0] - lever_from[0]
        a = g[line, 1]
        gr[line, 0, 2] = -lever_from[0] * np.sin(a) + lever_from[1] * np.cos(a)
    gr2 = gr.reshape(2 * nl, 3)
    x_new = np.concatenate([x, g.reshape(-1)])  # eqs. 38-39, 41
    p_new = np.empty((n + 2 * nl, n + 2 * nl))
    p_new[:n, :n] = p
    cross = gr2 @ p[:3, :]  # eqs. 43-46: G_r [P_rr P_rm]
    p_new[n:, :n] = cross
    p_new[:n, n:] = cross.T
    block = gr2 @ p[:3, :3] @ gr2.T
    b4 = block.reshape(nl, 2, nl, 2)
    rows = np.arange(nl)
    b4[rows, :, rows, :] += gz @ r @ np.transpose(gz, (0, 2, 1))  # eq. 47-48
    p_new[n:, n:] = 0.5 * (block + block.T)
    return x_new, p_new


def odometry_check(prev_stamp_ns: int, prev_pose: Sequence[float], stamp_ns: int,
                   pose: Sequence[float], max_jump_m: float = 0.5,
                   max_jump_rad: float = 1.0) -> Optional[str]:
    """Check an odometry sample against the previous one before predicting with it.

    Args:
        prev_stamp_ns: Stamp of the previous odometry pose [ns].
        prev_pose: Previous odometry pose [x, y, psi].
        stamp_ns: Stamp of the new pose [ns].
        pose: New odometry pose.
        max_jump_m: Largest plausible translation between the two samples [m].
        max_jump_rad: Largest plausible rotation between them [rad].

    Returns:
        None if the increment can be used, else a message saying why the caller should
        :meth:`EkfSlam.reset` (time going backwards, a jump, non-finite values).
    """
    p0 = np.asarray(prev_pose, dtype=float)
    p1 = np.asarray(pose, dtype=float)
    if not (np.all(np.isfinite(p0)) and np.all(np.isfinite(p1))):
        return 'odometry pose is not finite'
    if stamp_ns < prev_stamp_ns:
        return f'odometry went back in time ({prev_stamp_ns} -> {stamp_ns} ns)'
    u = relative(p0, p1)
    d = math.hypot(u[0], u[1])
    if d > max_jump_m:
        return f'odometry jumped {d:.3f} m (> {max_jump_m} m)'
    if abs(u[2]) > max_jump_rad:
        return f'odometry turned {abs(u[2]):.3f} rad in one step (> {max_jump_rad} rad)'
    return None


def _wrap(a):
    """Wrap angle(s) to [-pi, pi) (fast path of :func:`landmark_nav.geometry.wrap_angle`)."""
    if isinstance(a, float):
        return a if -_PI <= a < _PI else float(wrap_angle(a))
    return np.mod(a + _PI, _TWO_PI) - _PI


def nearest_psd(p: np.ndarray) -> np.ndarray:
    """Nearest symmetric positive semi-definite matrix in the Frobenius norm (Higham 1988).

    Args:
        p: Square matrix.

    Returns:
        ``V max(L, 0) V^T`` of the eigen-decomposition of ``(P + P^T) / 2``.
    """
    w, v = np.linalg.eigh(0.5 * (p + p.T))
    out = (v * np.maximum(w, 0.0)) @ v.T
    return 0.5 * (out + out.T)


def is_psd(p: np.ndarray, tolerance: float = 1e-9) -> bool:
    """Test positive semi-definiteness by a Cholesky factorisation of ``P + eps I``.

    Args:
        p: Symmetric matrix.
        tolerance: ``eps`` relative to the largest diagonal entry.

    Returns:
        True if the factorisation succeeds (no eigenvalue below about ``-eps``).
    """
    if p.size == 0:
        return True
    if not np.all(np.isfinite(p)):
        return False
    eps = tolerance * max(float(np.max(np.abs(np.diag(p)))), 1e-300) + 1e-300
    q = p.T.copy(order='F')  # P symmetric: a plain memory copy in LAPACK order
    q.flat[::q.shape[0] + 1] += eps
    _, info = dpotrf(q, lower=1, clean=0, overwrite_a=1)  # LAPACK: far faster than numpy's
    return info == 0


# ---------------------------------------------------------------------------- the filter
class EkfSlam:
    """EKF-SLAM filter (state layout, noise models and ghost protection: module docstring).

    Typical use, per scan::

        slam = EkfSlam(SlamParams(), initial_pose=odom_pose_0)
        slam.predict(odometry_increment(odom_prev, odom_now))
        result = slam.update(z, R)   # z (M, 2) range-bearing in base_link

    Line landmarks, visibility pruning and map reuse: :meth:`update` (``lines``, ``scan``),
    :meth:`export_map` / :meth:`load_map` (module docstring, "Line landmarks", "Map
    management", "Map reuse").
    """

    def __init__(self, params: Optional[SlamParams] = None,
                 initial_pose: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """Create the filter with the map initialised at ``initial_pose`` (eqs. 23-24)."""
        self.params = params or SlamParams()
        self._initial_pose = np.array(initial_pose, dtype=float).reshape(3)
        self._loaded: Optional[Tuple[SlamMap, np.ndarray]] = None
        self.reset()

    # ------------------------------------------------------------------ state access
    def reset(self, initial_pose: Optional[Sequence[float]] = None) -> None:
        """Forget the map, the candidates and the statistics; restart at a pose.

        In ``'localization'`` mode with a map given to :meth:`load_map`, the map is kept
        (loaded again) and the pose restarts with the covariance given there.

        Args:
            initial_pose: New start pose (default: the one given to the constructor).
        """
        if initial_pose is not None:
            self._initial_pose = np.array(initial_pose, dtype=float).reshape(3)
        self._x, self._p = map_initialization(self._initial_pose)
        self._ids = np.zeros(0, dtype=np.int64)
        self._kind = np.zeros(0, dtype=np.int8)
        self._ends = np.zeros((0, 2, 2))   # per landmark: line extent in the map (nan: corner)
        self._bis = np.zeros((0, 2))      # per landmark: sum of world bisector unit vectors
        self._open = np.zeros(0)          # per landmark: mean opening (nan: unknown)
        self._n_open = np.zeros(0, dtype=np.int64)
        self._hits = np.zeros(0, dtype=np.int64)
        self._misses = np.zeros(0, dtype=np.int64)   # consecutive expected-but-unseen scans
        self._rehits = np.zeros(0, dtype=np.int64)   # detections since entering (establish)
        self._chances = np.zeros(0, dtype=np.int64)  # scans that could have shown it since
        self._last_seen = np.zeros(0, dtype=np.int64)
        self._max_seen = np.zeros(0)
        self._first = np.zeros((0, 2))     # per landmark: estimate when it entered (OC-EKF)
        self._prior_xy = self._x[:2].copy()  # robot position of the latest prior (OC-EKF)
        self._next_id = 0
        self._candidates: List[_Candidate] = []
        self._next_cid = 0
        self._scan = 0
        self.stats: Dict[str, int] = {'predictions': 0, 'updates': 0, 'psd_repairs': 0,
                                      'matched': 0, 'confirmed': 0, 'new_candidates': 0,
                                      'dropped_candidates': 0, 'rejected': 0, 'pruned': 0,
                                      'evicted': 0, 'retired': 0, 'free_space': 0,
                                      'recovered': 0, 'spurious': 0}
        if self._loaded is not None and self.params.mode == 'localization':
            self._install_map(self._loaded[0], self._initial_pose, self._loaded[1])

    @property
    def state(self) -> np.ndarray:
        """(3 + 2N,) copy of the state vector."""
        return self._x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """(3 + 2N, 3 + 2N) copy of the covariance."""
        return self._p.copy()

    @property
    def pose(self) -> np.ndarray:
        """(3,) robot pose estimate [x, y, psi] in the map frame."""
        return self._x[:3].copy()

    @property
    def pose_covariance(self) -> np.ndarray:
        """(3, 3) robot pose covariance."""
        return self._p[:3, :3].copy()

    @property
    def num_landmarks(self) -> int:
        """Number of landmarks in the map (tentative ones excluded)."""
        return self._ids.size

    @property
    def landmark_ids(self) -> np.ndarray:
        """(N,) landmark ids in state order."""
        return self._ids.copy()

    @property
    def landmark_kinds(self) -> np.ndarray:
        """(N,) kind of each landmark: :data:`CORNER` (0) or :data:`LINE` (1)."""
        return self._kind.copy()

    @property
    def landmarks(self) -> np.ndarray:
        """(N, 2) landmark parameters in the map frame, state order.

        Corners: position ``(x, y)``; lines: ``(rho, alpha)`` (see :attr:`landmark_kinds`).
        """
        return self._x[3:].reshape(-1, 2).copy()

    @property
    def line_ends(self) -> np.ndarray:
        """(N, 2, 2) endpoints of each line landmark's extent in the map (NaN: corners)."""
        return self._ends.copy()

    @property
    def landmark_covariances(self) -> np.ndarray:
        """(N, 2, 2) marginal covariances of the landmarks."""
        cols = _landmark_cols(np.arange(self.num_landmarks))
        return self._p[cols[:, :, None], cols[:, None, :]].copy()

    @property
    def candidates(self) -> List[Tuple[int, np.ndarray, int]]:
        """Tentative landmarks as ``(candidate id, position (2,), hits)``."""
        return [(c.cid, c.xy.copy(), c.hits) for c in self._candidates]

    # ------------------------------------------------------------------ map reuse
    def export_map(self) -> SlamMap:
        """Return the current map (landmarks and their joint covariance, no robot)."""
        n = self.num_landmarks
        return SlamMap(ids=self._ids.copy(), kinds=self._kind.copy(),
                       means=self.landmarks, covariance=self._p[3:, 3:].copy(),
                       ends=self._ends.copy(), bisectors=self._bis.copy(),
                       openings=self._open.copy(), n_openings=self._n_open.copy(),
                       hits=self._hits.copy(), max_seen=self._max_seen.copy(),
                       next_id=int(max(self._next_id, int(self._ids.max()) + 1 if n else 0)))

    def load_map(self, slam_map: SlamMap, pose: Sequence[float],
                 pose_covariance: np.ndarray) -> None:
        """Start on a saved map at a given pose (module docstring, "Map reuse").

        The state becomes ``[pose, map]`` with ``P = blkdiag(pose_covariance, map
        covariance)`` (the pose guess is independent of the map). In ``'slam'`` mode the
        map then grows as usual; in ``'localization'`` mode it is only used (and refined).

        Args:
            slam_map: The map (:func:`.slam_map.load_map`).
            pose: (3,) initial robot pose in the map frame.
            pose_covariance: (3, 3) its covariance (how well the user knows it).

        Raises:
            ValueError: If the pose or its covariance is not finite, or the covariance is
                not symmetric positive semi-definite.
        """
        pose = np.asarray(pose, dtype=float).reshape(3)
        pc = np.asarray(pose_covariance, dtype=float)
        if not np.all(np.isfinite(pose)):
            raise ValueError(f'load_map: pose must be finite, got {pose!r}')
        if pc.shape != (3, 3) or not np.all(np.isfinite(pc)) or not np.allclose(pc, pc.T) \
                or not is_psd(pc):
            raise ValueError('load_map: pose_covariance must be a finite symmetric PSD (3, 3)')
        self._loaded = (slam_map, pc.copy())
        self._initial_pose = pose.copy()
        saved, self._loaded = self._loaded, None
        self.reset(pose)
        self._loaded = saved
        self._install_map(slam_map, pose, pc)

    def _install_map(self, m: SlamMap, pose: np.ndarray, pc: np.ndarray) -> None:
        n = m.size
        self._x = np.concatenate([pose, np.asarray(m.means, dtype=float).reshape(-1)])
        self._x[2] = wrap_angle(self._x[2])
        self._p = np.zeros((3 + 2 * n, 3 + 2 * n))
        self._p[:3, :3] = pc
        self._p[3:, 3:] = m.covariance
        self._ids = np.asarray(m.ids, dtype=np.int64).copy()
        self._kind = np.asarray(m.kinds, dtype=np.int8).copy()
        self._ends = np.asarray(m.ends, dtype=float).copy()
        self._bis = np.asarray(m.bisectors, dtype=float).copy()
        self._open = np.asarray(m.openings, dtype=float).copy()
        self._n_open = np.asarray(m.n_openings, dtype=np.int64).copy()
        self._hits = np.asarray(m.hits, dtype=np.int64).copy()
        self._misses = np.zeros(n, dtype=np.int64)
        # A saved map's landmarks are established.
        self._rehits = np.full(n, self.params.establish_hits, dtype=np.int64)
        self._chances = np.zeros(n, dtype=np.int64)
        self._last_seen = np.zeros(n, dtype=np.int64)
        self._max_seen = np.asarray(m.max_seen, dtype=float).copy()
        self._first = np.asarray(m.means, dtype=float).reshape(-1, 2).copy()
        self._prior_xy = self._x[:2].copy()
        self._next_id = int(m.next_id)

    # ------------------------------------------------------------------ filter steps
    def predict(self, u: Sequence[float], u_cov: Optional[np.ndarray] = None) -> None:
        """Predict with an odometry increment (eqs. 25-30).

        Args:
            u: (3,) increment ``(-)x_o(k-1) (+) x_o(k)`` (eq. 13, :func:`odometry_increment`).
            u_cov: (3, 3) its covariance; None = :func:`odometry_noise` of the parameters.

        Raises:
            ValueError: If ``u`` or ``u_cov`` is not finite or has the wrong shape.
        """
        u = np.asarray(u, dtype=float).reshape(-1)
        if u.shape != (3,) or not np.all(np.isfinite(u)):
            raise ValueError(f'predict: u must be 3 finite numbers, got {u!r}')
        if u_cov is None:
            u_cov = odometry_noise(u, self.params.odometry)
        else:
            u_cov = np.asarray(u_cov, dtype=float)
            if u_cov.shape != (3, 3) or not np.all(np.isfinite(u_cov)):
                raise ValueError('predict: U must be a finite (3, 3) matrix')
        oc = self.params.jacobians in _FIRST_ESTIMATE_RULES
        ekf_predict(self._x, self._p, u, u_cov, self._prior_xy if oc else None)
        self._prior_xy = self._x[:2].copy()
        self.stats['predictions'] += 1

    def default_r(self, m: int) -> np.ndarray:
        """Return (m, 2, 2) default observation covariances ``diag(s_r^2, s_b^2)`` (eq. 22)."""
        r = np.zeros((m, 2, 2))
        r[:, 0, 0] = self.params.sigma_range ** 2
        r[:, 1, 1] = self.params.sigma_bearing ** 2
        return r

    def update(self, z: np.ndarray, r: Optional[np.ndarray] = None,
               descriptors: Optional[np.ndarray] = None,
               lines: Optional[LineObservations] = None,
               scan: Optional[ScanGeometry] = None) -> UpdateResult:
        """Associate, update, manage candidates and augment with one scan's observations.

        Args:
            z: (M, 2) range-bearing corner observations [m, rad] in base_link (laser mount
                applied, e.g. :func:`.observations.corners_to_observations`).
            r: (M, 2, 2) covariance per observation; None = :meth:`default_r`.
            descriptors: Optional (M, 2) ``[bisector in base_link, opening]`` [rad] per
                observation (:func:`.observations.corner_descriptors`); NaN = unknown.
            lines: Optional line observations in base_link
                (:func:`.line_landmarks.lines_to_observations`).
            scan: Optional geometry of the scan the observations come from; with it (and
                ``prune_misses > 0``) landmarks that should have been seen and were not
                count misses (:mod:`.visibility`).

        Returns:
            The per-observation association result: the M corners first, then the lines.
        """
        prm = self.params
        z = np.asarray(z, dtype=float).reshape(-1, 2).copy()
        mc = z.shape[0]
        r = self.default_r(mc) if r is None else np.asarray(r, dtype=float).reshape(mc, 2, 2)
        if descriptors is None:
            desc_all = np.full((mc, 2), np.nan)
        else:
            desc_all = np.asarray(descriptors, dtype=float).reshape(mc, 2)
        kind_all = np.zeros(mc, dtype=np.int8)
        ends_all = np.full((mc, 2, 2), np.nan)
        res_all = np.full(mc, np.nan)  # lines' residual std (None / NaN: no such term)
        if lines is not None and len(lines):
            nl = len(lines)
            res_all = np.concatenate([res_all, np.full(nl, np.nan) if lines.residual_std is None
                                      else np.asarray(lines.residual_std, dtype=float)])
            z = np.vstack([z, np.asarray(lines.z, dtype=float).reshape(nl, 2)])
            r = np.concatenate([r, np.asarray(lines.r, dtype=float).reshape(nl, 2, 2)])
            desc_all = np.vstack([desc_all, np.full((nl, 2), np.nan)])
            kind_all = np.concatenate([kind_all, np.full(nl, LINE, dtype=np.int8)])
            ends_all = np.concatenate([ends_all, np.asarray(lines.ends, dtype=float)])
        m = z.shape[0]
        self._scan += 1
        self.stats['updates'] += 1
        status = np.full(m, 'rejected', dtype='<U9')
        reason = np.full(m, '', dtype='<U12')
        lm_id = np.full(m, -1, dtype=np.int64)
        cand_id = np.full(m, -1, dtype=np.int64)
        d2_out = np.full(m, np.nan)
        is_line = kind_all == LINE

        # Validation: NaN / inf, ranges, covariances.
        with np.errstate(invalid='ignore'):
            finite = np.all(np.isfinite(z), axis=1) & np.all(np.isfinite(r), axis=(1, 2))
            finite &= ~is_line | np.all(np.isfinite(ends_all), axis=(1, 2))
            det = r[:, 0, 0] * r[:, 1, 1] - r[:, 0, 1] * r[:, 1, 0]
            valid = finite & (z[:, 0] > 0.0) & (r[:, 0, 0] > 0.0) & (det > 0.0)
        reason[~valid] = 'invalid'
        far = valid & (z[:, 0] > prm.max_range)
        reason[far] = 'range'
        keep = valid & ~far
        if descriptors is not None and prm.min_view_margin > 0.0:
            view = np.abs(_wrap(z[:, 1] + _PI - desc_all[:, 0]))
            half = 0.5 * np.minimum(desc_all[:, 1], _TWO_PI - desc_all[:, 1])
            with np.errstate(invalid='ignore'):
                graze = keep & (half - view < prm.min_view_margin)
            reason[graze] = 'grazing'
            keep &= ~graze
        else:
            graze = np.zeros(m, dtype=bool)
        use = np.flatnonzero(keep)
        zu = z[use]
        zu[:, 1] = _wrap(zu[:, 1])
        ku = kind_all[use]
        cu = ku == CORNER
        ru = prm.r_scale * 0.5 * (r[use] + np.transpose(r[use], (0, 2, 1)))
        # Floors stand for the corner extractor's biases (module docstring): corners only.
        ru[cu, 0, 0] += prm.range_floor ** 2 + prm.position_floor ** 2
        ru[cu, 1, 1] += prm.bearing_floor ** 2 + (prm.position_floor / zu[cu, 0]) ** 2
        if not np.all(cu):  # segment-wide errors of lines (module docstring, "Noise models")
            lu = ~cu
            ru[lu] += line_noise_covariance(prm, zu[lu], ends_all[use[lu]], res_all[use[lu]])
        desc = desc_all[use]
        ends_w = ends_to_map(self._x[:3], ends_all[use])  # observed extents, predicted pose
        # World bisector unit vectors (zeros where unknown) and openings of the observations.
        wb = desc[:, 0] + self._x[2]
        known = np.isfinite(wb)
        bvec = np.where(known[:, None], np.column_stack([np.cos(wb), np.sin(wb)]), 0.0)
        lm_before = self.num_landmarks

        # Data association (eqs. 49-55) and update (eqs. 32-37).
        allowed = self._descriptor_gate(bvec, desc[:, 1], self._bis, self._open)
        allowed = self._extent_gate(allowed, ku, ends_w)
        mixed = bool(np.any(ku == LINE) or np.any(self._kind == LINE))
        # The linearisation of the consistent options ("Consistency"), for the gate (with
        # the gain's Jacobians) and the update alike.
        null, jac_x = None, None
        if prm.jacobians in ('observability', 'observability_gain') and self.num_landmarks:
            null = unobservable_directions(self._prior_xy, self._first, self._kind)
        elif prm.jacobians == 'first_estimates' and self.num_landmarks:
            jac_x = np.concatenate([self._prior_xy, self._x[2:3], self._first.reshape(-1)])
        gain_null = null if prm.jacobians == 'observability_gain' else None
        hyp, d2, nodes = do_data_association(
            self._x, self._p, zu, ru, prm.association, prm.gate_probability,
            prm.jcbb_max_nodes, allowed, ku if mixed else None, self._kind if mixed else None,
            prm.joint_check, prm.joint_probability, gain_null, jac_x, prm.cartesian_gate)
        recovered = False
        if prm.recovery_probability is not None and not np.any(hyp >= 0):
            hyp, d2, recovered = self._recover(hyp, d2, zu, ru, allowed,
                                               ku if mixed else None, gain_null, jac_x)
        # The gate the hypothesis was made with (the recovery's when it made it).
        pair_gate = chi2_gate(2, prm.recovery_probability if recovered else prm.gate_probability)
        if prm.reject_ambiguous:
            hyp = reject_ambiguous_pairs(hyp, d2, pair_gate)
        if prm.spurious_limit is not None and scan is not None and np.any(hyp >= 0):
            counts = (np.count_nonzero(valid & ~is_line), np.count_nonzero(valid & is_line))
            hyp = self._spurious_check(hyp, ru, scan, counts, gain_null, jac_x, pair_gate)
        veto = np.zeros(0, dtype=np.int64)
        if prm.free_space_check is not None and scan is not None and np.any(hyp >= 0):
            hyp, veto = self._free_space_veto(hyp, zu, ru, d2, scan, mixed, null, jac_x)
        if recovered:  # still enough pairs after the checks?
            if np.count_nonzero(hyp >= 0) < prm.recovery_pairs:
                hyp = np.full_like(hyp, -1)
            else:
                self.stats['recovered'] += 1
        ok = hyp >= 0
        nis, dof = 0.0, 0
        if np.any(ok):
            self._p, nis = ekf_update(self._x, self._p, zu[ok], ru[ok], hyp[ok],
                                      prm.max_update_iterations, prm.relinearize_ratio,
                                      self._kind[hyp[ok]] if mixed else None,
                                      None if null is None else null[hyp[ok]],
                                      prm.jacobians == 'observability_gain', jac_x,
                                      self._kind if prm.jacobians == 'invariant' else None)
            dof = 2 * int(ok.sum())
            sel = use[ok]
            status[sel] = 'matched'
            lm_id[sel] = self._ids[hyp[ok]]
            d2_out[sel] = d2[ok, hyp[ok]]
            j = hyp[ok]
            self._bis[j] += bvec[ok]
            o = desc[ok, 1]
            has = np.isfinite(o)
            jo = j[has]
            prev = np.where(self._n_open[jo] > 0, self._open[jo], 0.0)
            self._n_open[jo] += 1
            self._open[jo] = prev + (o[has] - prev) / self._n_open[jo]
            self._hits[j] += 1
            self._misses[j] = 0
            self._rehits[j] += 1
            self._last_seen[j] = self._scan
            self._max_seen[j] = np.maximum(self._max_seen[j], zu[ok, 0])
            self._grow_extents(j, ends_all[use[ok]])
        # Unassociated observations near a landmark are ambiguous: no duplicate landmark.
        rest = np.flatnonzero(~ok)
        near = np.zeros(lm_before, dtype=bool)  # landmarks some observation may have seen
        if d2.shape[1]:
            near = np.any(d2 < chi2_gate(2, prm.new_landmark_probability), axis=0)
        if rest.size and d2.shape[1]:
            amb = np.min(d2[rest], axis=1) < chi2_gate(2, prm.new_landmark_probability)
            reason[use[rest[amb]]] = 'ambiguous'
            rest = rest[~amb]
        if veto.size:  # inside the gate, so not a candidate either
            reason[use[veto]] = 'free_space'
            rest = np.setdiff1d(rest, veto)
        manage = scan is not None and prm.mode == 'slam' and lm_before > 0
        if manage and (prm.prune_misses > 0 or prm.establish_hits > 0):
            seen = np.zeros(lm_before, dtype=bool)
            seen[hyp[ok]] = True
            gz = np.flatnonzero(graze)
            if gz.size:  # a corner rejected as grazing was still seen
                zg = z[gz].copy()
                zg[:, 1] = _wrap(zg[:, 1])
                rg = prm.r_scale * r[gz]
                _, d2g, _ = do_data_association(self._x, self._p, zg, rg, 'icnn',
                                                prm.gate_probability, 0, None,
                                                kind_all[gz], self._kind)
                near |= np.any(d2g < chi2_gate(2, prm.new_landmark_probability), axis=0)
            drop = np.zeros(0, dtype=np.int64)
            if prm.prune_misses > 0:
                drop = self._count_misses(scan, seen | near)
            if prm.establish_hits > 0:
                retire = np.setdiff1d(self._count_chances(scan, seen, near), drop)
                self.stats['retired'] += int(retire.size)
                drop = np.union1d(drop, retire)
            if drop.size:
                self._remove_landmarks(drop)
        if rest.size and prm.mode == 'localization':
            reason[use[rest]] = 'localization'
        elif rest.size:
            self._handle_candidates(zu[rest], ru[rest], use[rest], bvec[rest],
                                    desc[rest, 1], status, reason, lm_id, cand_id, ku[rest],
                                    ends_all[use[rest]])
        self._expire_candidates()

        repaired = False
        if self._scan % prm.psd_check_interval == 0 and not is_psd(self._p, prm.psd_tolerance):
            self._p = nearest_psd(self._p)
            self.stats['psd_repairs'] += 1
            repaired = True
        self.stats['matched'] += int(np.sum(status == 'matched'))
        self.stats['rejected'] += int(np.sum(status == 'rejected'))
        return UpdateResult(status=status, landmark_id=lm_id, candidate_id=cand_id,
                            reason=reason, d2=d2_out, nis=nis, nis_dof=dof,
                            psd_repaired=repaired, jcbb_nodes=nodes, kind=kind_all)

    def step(self, u: Sequence[float], z: np.ndarray, r: Optional[np.ndarray] = None,
             u_cov: Optional[np.ndarray] = None) -> UpdateResult:
        """Run :meth:`predict` then :meth:`update` (one iteration of Fig. 17)."""
        self.predict(u, u_cov)
        return self.update(z, r)

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

    def _grow_extents(self, index: np.ndarray, ends_b: np.ndarray) -> None:
        """Extend matched line landmarks by their observed segments (updated pose)."""
        ln = np.flatnonzero(self._kind[index] == LINE)
        if ln.size == 0:
            return
        ends_w = ends_to_map(self._x[:3], ends_b[ln])
        lm = self._x[3:].reshape(-1, 2)
        for k, j in enumerate(index[ln]):
            self._ends[j] = merge_extent(lm[j], self._ends[j], ends_w[k])

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

    # ------------------------------------------------------------------ map management
    def _count_misses(self, scan: ScanGeometry, seen: np.ndarray) -> np.ndarray:
        """Count misses of landmarks the scan should have shown; return those to prune."""
        prm = self.params
        n = seen.size
        index = np.arange(n)
        kind = self._kind[:n]
        zhat, hr, hf = observation_model(self._x, index, kind)
        var = np.diagonal(predicted_observation_covariance(self._p, index, hr, hf), 0, 1, 2)
        miss = landmarks_missed(self._x[:3], kind, self._x[3:3 + 2 * n].reshape(-1, 2),
                                self._ends[:n], self._bis[:n], self._open[:n],
                                np.sqrt(np.maximum(var, 0.0)), scan,
                                math.sqrt(chi2_gate(1, prm.gate_probability)),
                                prm.min_view_margin, prm.line_min_beams)
        miss &= ~seen
        self._misses[:n][miss] += 1
        self._misses[:n][seen] = 0
        drop = np.flatnonzero(self._misses[:n] >= prm.prune_misses)
        self.stats['pruned'] += int(drop.size)
        return drop

    def _count_chances(self, scan: ScanGeometry, seen: np.ndarray, near: np.ndarray
                       ) -> np.ndarray:
        """Count chances of provisional corners; return those to retire (module docstring).

        Args:
            scan: The scan's geometry.
            seen: (n,) landmarks detected in this scan (the first n of the state).
            near: (n,) landmarks an unassociated observation lay near (no chance, no hit).
        """
        prm = self.params
        n = seen.size
        # Detections of this scan are already in _rehits (a corner they establish is done).
        prov = np.flatnonzero((self._kind[:n] == CORNER) & (self._rehits[:n] < prm.establish_hits)
                              & (self._chances[:n] < prm.establish_chances))
        if prov.size == 0:
            return prov
        chance = seen[prov].copy()
        look = ~chance & ~near[prov]
        if np.any(look):
            idx = prov[look]
            zhat, hr, hf = observation_model(self._x, idx)
            var = np.diagonal(predicted_observation_covariance(self._p, idx, hr, hf), 0, 1, 2)
            chance[look] = corners_in_view(
                self._x[:3], self._x[3:].reshape(-1, 2)[idx], self._bis[idx], self._open[idx],
                np.sqrt(np.maximum(var, 0.0)), self._max_seen[idx], scan,
                math.sqrt(chi2_gate(1, prm.gate_probability)), prm.min_view_margin)
        self._chances[prov[chance]] += 1
        out = (self._chances[prov] >= prm.establish_chances) & (
            self._rehits[prov] < prm.establish_hits)
        return prov[out]

    def _remove_landmarks(self, index: np.ndarray) -> None:
        """Marginalise landmarks out of the state (drop their rows and columns)."""
        keep = np.ones(self.num_landmarks, dtype=bool)
        keep[index] = False
        cols = np.concatenate([np.arange(3), _landmark_cols(np.flatnonzero(keep)).reshape(-1)])
        self._x = self._x[cols]
        self._p = self._p[np.ix_(cols, cols)]
        for name in ('_ids', '_kind', '_ends', '_bis', '_open', '_n_open', '_hits', '_misses',
                     '_rehits', '_chances', '_last_seen', '_max_seen', '_first'):
            setattr(self, name, getattr(self, name)[keep])

    def _make_room(self, need: int, protect: np.ndarray) -> int:
        """Evict up to ``need`` least recently seen landmarks; return the room made."""
        cand = np.setdiff1d(np.arange(self.num_landmarks), protect)
        if cand.size == 0 or need <= 0:
            return 0
        order = np.lexsort((self._hits[cand], self._last_seen[cand]))  # oldest, fewest hits
        drop = cand[order[:need]]
        self._remove_landmarks(drop)
        self.stats['evicted'] += int(drop.size)
        return int(drop.size)

    # ------------------------------------------------------------------ candidates
    def _handle_candidates(self, z: np.ndarray, r: np.ndarray, obs: np.ndarray,
                           bvec: np.ndarray, opening: np.ndarray, status: np.ndarray,
                           reason: np.ndarray, lm_id: np.ndarray, cand_id: np.ndarray,
                           kind: np.ndarray, ends_b: np.ndarray) -> None:
        """Match unexplained observations to candidates, start new ones, confirm (augment)."""
        prm = self.params
        if self.num_landmarks >= prm.max_landmarks and prm.map_full == 'reject':
            reason[obs] = 'cap'
            return
        line = kind == LINE
        g, gr, gz = feature_initialization(self._x[:3], z, kind)  # eq. 40, updated pose
        cov = (gr @ self._p[:3, :3] @ np.transpose(gr, (0, 2, 1))
               + gz @ r @ np.transpose(gz, (0, 2, 1)))
        ends_w = ends_to_map(self._x[:3], ends_b)
        assigned = np.full(z.shape[0], -1, dtype=np.int64)
        if self._candidates:
            cxy = np.array([c.xy for c in self._candidates])
            ccov = np.array([c.cov for c in self._candidates])
            ckind = np.array([c.kind for c in self._candidates])
            diff = g[:, None, :] - cxy[None]
            diff[..., 1] = np.where(line[:, None], _wrap(diff[..., 1]), diff[..., 1])
            d2 = mahalanobis_table(diff, cov[:, None] + ccov[None])
            d2 = np.where(kind[:, None] == ckind[None, :], d2, np.inf)
            cl = np.flatnonzero(ckind == LINE)
            if cl.size and np.any(line):
                ov = extents_overlap(cxy[cl], np.array([self._candidates[i].ends for i in cl]),
                                     ends_w[line])
                sub = d2[np.ix_(np.flatnonzero(line), cl)]
                d2[np.ix_(np.flatnonzero(line), cl)] = np.where(ov, sub, np.inf)
            allowed = self._descriptor_gate(
                bvec, opening, np.array([c.bis for c in self._candidates]),
                np.array([c.opening for c in self._candidates]))
            if allowed is not None:
                d2 = np.where(allowed, d2, np.inf)
            assigned = icnn(d2, chi2_gate(2, prm.candidate_probability))
        confirm: List[int] = []
        for k in range(z.shape[0]):
            i = int(obs[k])
            if assigned[k] >= 0:
                c = self._candidates[int(assigned[k])]
                info_old, info_new = np.linalg.inv(c.cov), np.linalg.inv(cov[k])
                c.cov = np.linalg.inv(info_old + info_new)
                c.cov = 0.5 * (c.cov + c.cov.T)
                dg = g[k] - c.xy
                if line[k]:
                    dg[1] = _wrap(dg[1])
                c.xy = c.xy + c.cov @ info_new @ dg  # information-form fusion
                if line[k]:
                    c.xy[1] = _wrap(c.xy[1])
                    c.ends = merge_extent(c.xy, c.ends, ends_w[k])
                c.hits += 1
                c.max_seen = max(c.max_seen, float(z[k, 0]))
                c.bis = c.bis + bvec[k]
                if np.isfinite(opening[k]):
                    prev = c.opening if c.n_open else 0.0
                    c.n_open += 1
                    c.opening = prev + (opening[k] - prev) / c.n_open
                cand_id[i] = c.cid
                status[i] = 'tentative'
                if c.hits >= prm.confirm_hits:
                    confirm.append(k)
            else:
                has = bool(np.isfinite(opening[k]))
                c = _Candidate(cid=self._next_cid, xy=g[k].copy(), cov=cov[k].copy(),
                               first_scan=self._scan, hits=1, bis=bvec[k].copy(),
                               opening=float(opening[k]) if has else math.nan,
                               n_open=int(has), kind=int(kind[k]),
                               ends=project_extent(g[k], ends_w[k]) if line[k] else None,
                               max_seen=float(z[k, 0]))
                self._next_cid += 1
                self._candidates.append(c)
                self.stats['new_candidates'] += 1
                cand_id[i] = c.cid
                status[i] = 'new'
                if prm.confirm_hits <= 1:
                    confirm.append(k)
        if not confirm:
            return
        room = prm.max_landmarks - self.num_landmarks
        if room < len(confirm) and prm.map_full == 'evict':
            matched = np.flatnonzero(self._last_seen == self._scan)
            room += self._make_room(len(confirm) - room, matched)
        room = max(room, 0)
        take = np.array(confirm[:room], dtype=np.int64)
        for k in confirm[room:]:
            status[obs[k]] = 'rejected'
            reason[obs[k]] = 'cap'
        if take.size == 0:
            return
        oc = prm.jacobians in _FIRST_ESTIMATE_RULES
        self._x, self._p = augment_map(self._x, self._p, z[take], r[take], kind[take],
                                       self._prior_xy if oc else None)  # eqs. 38-48
        new_ids = self._next_id + np.arange(take.size, dtype=np.int64)
        self._next_id += take.size
        self._ids = np.concatenate([self._ids, new_ids])
        by_id = {c.cid: c for c in self._candidates}
        new_c = [by_id[int(cand_id[obs[k]])] for k in take]
        self._kind = np.concatenate([self._kind, kind[take].astype(np.int8)])
        lm_new = self._x[3:].reshape(-1, 2)[-take.size:]
        ends_new = np.full((take.size, 2, 2), np.nan)
        for q, (k, c) in enumerate(zip(take, new_c)):
            if line[k]:
                ends_new[q] = merge_extent(lm_new[q], c.ends, ends_w[k])
        self._ends = np.concatenate([self._ends, ends_new])
        self._bis = np.vstack([self._bis, np.array([c.bis for c in new_c])])
        self._open = np.concatenate([self._open, [c.opening for c in new_c]])
        self._n_open = np.concatenate([self._n_open, [c.n_open for c in new_c]])
        self._hits = np.concatenate([self._hits, [c.hits for c in new_c]])
        self._misses = np.concatenate([self._misses, np.zeros(take.size, dtype=np.int64)])
        self._rehits = np.concatenate([self._rehits, np.zeros(take.size, dtype=np.int64)])
        self._chances = np.concatenate([self._chances, np.zeros(take.size, dtype=np.int64)])
        self._last_seen = np.concatenate([self._last_seen,
                                          np.full(take.size, self._scan, dtype=np.int64)])
        self._max_seen = np.concatenate([self._max_seen, [c.max_seen for c in new_c]])
        self._first = np.vstack([self._first, self._x[3:].reshape(-1, 2)[-take.size:]])
        done = {int(cand_id[obs[k]]) for k in take}
        self._candidates = [c for c in self._candidates if c.cid not in done]
        status[obs[take]] = 'confirmed'
        lm_id[obs[take]] = new_ids
        cand_id[obs[take]] = -1
        self.stats['confirmed'] += int(take.size)

    def _expire_candidates(self) -> None:
        """Drop candidates whose confirmation window has passed."""
        keep = [c for c in self._candidates
                if self._scan - c.first_scan + 1 < self.params.confirm_window]
        self.stats['dropped_candidates'] += len(self._candidates) - len(keep)
        self._candidates = keep


__all__ = ['ASSOCIATION_METHODS', 'augment_map', 'CORNER', 'do_data_association', 'EkfSlam',
           'constrain_jacobians', 'invariant_retraction', 'invariant_transport', 'JACOBIANS',
           'LINE', 'MAP_FULL_POLICIES', 'MODES',
           'ekf_predict', 'ekf_update', 'feature_initialization', 'is_psd',
           'joint_observation_covariance', 'line_noise_covariance', 'map_initialization',
           'nearest_psd',
           'observation_model', 'odometry_check', 'odometry_increment', 'odometry_noise',
           'OdometryNoise', 'predicted_observation_covariance', 'SlamParams', 'STATUSES',
           'unobservable_directions', 'UpdateResult']
