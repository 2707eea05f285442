"""EKF-SLAM with point (corner) landmarks, corner chapter section 3 (eqs. 12-60, Fig. 17).

State layout (the one place it is defined)
------------------------------------------
``x = [x_r, y_r, psi_r, x_1, y_1, ..., x_N, y_N]`` (m, m, rad, m, ...), length ``3 + 2N``,
and its covariance ``P`` (``3 + 2N`` square). The robot pose is the pose of base_link in the
map frame, ``psi_r`` wrapped to [-pi, pi); landmark ``k`` (0-based, in the order it entered
the map) occupies ``x[3 + 2k : 5 + 2k]``. Landmarks never leave the state and each keeps the
integer id it got when it was added (ids count up from 0 and are never reused until
:meth:`EkfSlam.reset`). The map frame is the robot pose at step 0 (eqs. 23-24: ``P = 0``);
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
update is the plain EKF there.

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

Association statuses per observation (:class:`UpdateResult`)
-------------------------------------------------------------
``'matched'`` (landmark id), ``'confirmed'`` (confirmed a candidate; new landmark id),
``'tentative'`` (hit of an existing candidate), ``'new'`` (started a candidate),
``'rejected'`` with a reason: ``'invalid'`` (NaN / inf, non-positive range or a
non-positive-definite ``R``), ``'range'`` (beyond ``max_range``), ``'grazing'`` (an arm seen
nearly edge-on, see above), ``'ambiguous'`` (not associated but inside the
``new_landmark_probability`` gate of a landmark: neither matched nor allowed to create a
duplicate), ``'cap'`` (the map holds ``max_landmarks``).

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

from ._linalg import solve_lower
from .association import icnn, jcbb, mahalanobis_table
from .consistency import chi2_gate

ASSOCIATION_METHODS = ('icnn', 'jcbb')
STATUSES = ('matched', 'confirmed', 'tentative', 'new', 'rejected')
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
        max_range: Observations farther than this are rejected [m].
        association: ``'icnn'`` (default) or ``'jcbb'``.
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
        max_landmarks: Cap on the map size.
        jcbb_max_nodes: Node budget of JCBB per scan.
        psd_tolerance: Relative jitter of the positive semi-definiteness test.
        psd_check_interval: Test P every this many updates (1 = always).
        max_odometry_jump_m: :func:`odometry_check` threshold on one increment [m].
        max_odometry_jump_rad: :func:`odometry_check` threshold on one increment [rad].
        max_update_iterations: Largest number of linearisations of one update (1 = plain
            EKF; see "Iterated update" in the module docstring).
        relinearize_ratio: Linearise again when an observed landmark moved, relative to the
            robot, by more than this fraction of its range during the update.
    """

    odometry: OdometryNoise = field(default_factory=OdometryNoise)
    sigma_range: float = 0.02
    sigma_bearing: float = math.radians(1.0)
    r_scale: float = 1.0
    range_floor: float = 0.0
    bearing_floor: float = 0.0
    position_floor: float = 0.003
    max_range: float = math.inf
    association: str = 'icnn'
    bisector_gate: float = math.radians(45.0)
    opening_gate: float = math.radians(60.0)
    min_view_margin: float = math.radians(8.0)
    gate_probability: float = 0.95
    new_landmark_probability: float = 0.99999
    candidate_probability: float = 0.999
    confirm_hits: int = 3
    confirm_window: int = 5
    max_landmarks: int = 200
    jcbb_max_nodes: int = 5000
    psd_tolerance: float = 1e-9
    psd_check_interval: int = 1
    max_odometry_jump_m: float = 0.5
    max_odometry_jump_rad: float = 1.0
    max_update_iterations: int = 5
    relinearize_ratio: float = 0.02

    def __post_init__(self) -> None:
        """Validate the parameters; raise ValueError naming the bad one."""
        if not isinstance(self.odometry, OdometryNoise):
            raise ValueError(f'SlamParams.odometry must be an OdometryNoise, '
                             f'got {self.odometry!r}')
        for name in ('sigma_range', 'sigma_bearing', 'range_floor', 'bearing_floor',
                     'position_floor', 'psd_tolerance', 'bisector_gate', 'opening_gate',
                     'min_view_margin'):
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
        if self.new_landmark_probability < self.gate_probability:
            raise ValueError('SlamParams.new_landmark_probability must be >= gate_probability')
        for name in ('confirm_hits', 'confirm_window', 'max_landmarks', 'jcbb_max_nodes',
                     'psd_check_interval', 'max_update_iterations'):
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


def ekf_predict(x: np.ndarray, p: np.ndarray, u: np.ndarray, u_cov: np.ndarray) -> None:
    """Prediction with the odometry increment as control input (eqs. 25-30), in place.

    Args:
        x: (3 + 2N,) state, modified in place.
        p: (3 + 2N, 3 + 2N) covariance, modified in place.
        u: (3,) odometry increment (eq. 13).
        u_cov: (3, 3) its covariance ``U``.
    """
    j1, j2 = compose_jacobians(x[:3], u)  # eqs. 27-30 (eq. 28 sign typo fixed)
    c, s = math.cos(x[2]), math.sin(x[2])
    x[0] += u[0] * c - u[1] * s  # eq. 25 (x_r (+) u, eq. 16)
    x[1] += u[0] * s + u[1] * c
    x[2] = _wrap(x[2] + u[2])
    # eq. 26 with J2 U J2^T (the chapter prints J1^T in the second term).
    p[:3, :3] = j1 @ p[:3, :3] @ j1.T + j2 @ u_cov @ j2.T
    if p.shape[0] > 3:
        p[:3, 3:] = j1 @ p[:3, 3:]  # eq. 12: static landmarks, cross terms follow J1
        p[3:, :3] = p[:3, 3:].T
    p[:3, :3] = 0.5 * (p[:3, :3] + p[:3, :3].T)


def observation_model(x: np.ndarray, index: np.ndarray
                      ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted range-bearing observations of landmarks and their Jacobians.

    ``r = sqrt(dx^2 + dy^2)`` (eq. 19), ``theta = atan2(dy, dx) - psi_r`` (eq. 20) with
    ``(dx, dy) = (x_i - x_r, y_i - y_r)``; eq. 53 splits ``H`` into::

        H_r  = d h / d(x_r, y_r, psi_r) = [[-dx/r, -dy/r, 0], [dy/r^2, -dx/r^2, -1]]
        H_Fj = d h / d(x_i, y_i)        = [[ dx/r,  dy/r],    [-dy/r^2,  dx/r^2]]

    Args:
        x: (3 + 2N,) state.
        index: (K,) landmark indices (0-based positions in the state).

    Returns:
        ``(zhat (K, 2), H_r (K, 2, 3), H_F (K, 2, 2))`` (eqs. 37, 50, 53).
    """
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
                        max_nodes: int = 5000, allowed: Optional[np.ndarray] = None
                        ) -> Tuple[np.ndarray, np.ndarray, int]:
    """Associate observations with map landmarks (eqs. 49-55), ICNN or JCBB.

    Args:
        x: State.
        p: Covariance.
        z: (M, 2) observations [r, theta] in base_link.
        r: (M, 2, 2) their covariances.
        method: ``'icnn'`` or ``'jcbb'``.
        probability: Gate confidence (eq. 55).
        max_nodes: JCBB node budget.
        allowed: Optional (M, N) bool mask of pairs that may be associated (descriptor
            gate); the others get ``D2 = inf``.

    Returns:
        ``(hypothesis (M,) landmark index or -1 (eq. 49), d2 (M, N) eq. 54, jcbb nodes)``.
    """
    m = z.shape[0]
    n_lm = (x.size - 3) // 2
    if m == 0 or n_lm == 0:
        return np.full(m, -1, dtype=np.int64), np.full((m, n_lm), np.inf), 0
    index = np.arange(n_lm)
    zhat, hr, hf = observation_model(x, index)  # eq. 50
    c = predicted_observation_covariance(p, index, hr, hf)
    nu = z[:, None, :] - zhat[None, :, :]  # eq. 51
    nu[..., 1] = _wrap(nu[..., 1])
    d2 = mahalanobis_table(nu, c[None] + r[:, None])  # eqs. 52, 54
    if allowed is not None:
        d2 = np.where(allowed, d2, np.inf)
    gate = chi2_gate(2, probability)
    if method == 'icnn':
        return icnn(d2, gate), d2, 0  # eq. 55 + nearest neighbour
    sub = np.flatnonzero(np.any(d2 < gate, axis=0))
    hyp = np.full(m, -1, dtype=np.int64)
    if sub.size == 0:
        return hyp, d2, 0
    s_pred = joint_observation_covariance(p, sub, hr[sub], hf[sub])
    h_sub, _, nodes = jcbb(nu[:, sub], s_pred, r, d2[:, sub], probability, max_nodes)
    ok = h_sub >= 0
    hyp[ok] = sub[h_sub[ok]]
    return hyp, d2, nodes


def ekf_update(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray,
               index: np.ndarray, max_iterations: int = 1,
               relinearize_ratio: float = 0.02) -> Tuple[np.ndarray, float]:
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
        relinearize_ratio: Relative move that triggers another linearisation.

    Returns:
        ``(P, NIS)``: the symmetrised covariance (a new array) and ``nu^T S^-1 nu`` (eq. 60)
        of the first linearisation (the prior innovation).

    Raises:
        numpy.linalg.LinAlgError: If ``S`` is not positive definite.
    """
    k = index.size
    n = x.size
    if k == 0:
        return p, 0.0
    cols = _landmark_cols(index)
    rows = np.arange(k)
    x0 = x
    x_lin = x
    nis_value = 0.0
    for it in range(max(1, int(max_iterations))):
        zhat, hr, hf = observation_model(x_lin, index)  # eq. 37
        nu = z - zhat  # eq. 36
        nu[:, 1] = _wrap(nu[:, 1])
        if it > 0:  # iterated EKF: nu_i = z - h(x_i) - H_i (x_0 - x_i)
            dx = x0 - x_lin
            dx[2] = _wrap(dx[2])
            nu -= hr @ dx[:3] + np.einsum('kij,kj->ki', hf, dx[cols])
        hr2 = hr.reshape(2 * k, 3)
        # P H^T, (n, 2K): robot part plus each observation's landmark block.
        pht = p[:, :3] @ hr2.T
        p_cols = np.transpose(p[:, cols], (1, 0, 2))  # (K, n, 2)
        pht += np.transpose(p_cols @ np.transpose(hf, (0, 2, 1)), (1, 0, 2)).reshape(n, 2 * k)
        # S = H P H^T + R (eq. 33).
        s = hr2 @ pht[:3] + (hf @ pht[cols]).reshape(2 * k, 2 * k)
        s4 = s.reshape(k, 2, k, 2)
        s4[rows, :, rows, :] += r
        s = 0.5 * (s + s.T)
        low = np.linalg.cholesky(s)
        w1 = solve_lower(low, pht.T).T  # P H^T L^-T
        y = solve_lower(low, nu.reshape(-1))
        if it == 0:
            nis_value = float(y @ y)
        x_new = x0 + w1 @ y  # eqs. 32, 34
        x_new[2] = _wrap(x_new[2])
        if it + 1 >= max_iterations:
            break
        lm_old = x_lin[3:].reshape(-1, 2)[index]
        rel_old = lm_old - x_lin[:2]
        move = x_new[3:].reshape(-1, 2)[index] - x_new[:2] - rel_old
        if np.all(np.hypot(move[:, 0], move[:, 1])
                  <= relinearize_ratio * np.hypot(rel_old[:, 0], rel_old[:, 1])):
            break
        x_lin = x_new
    x[:] = x_new
    p -= w1 @ w1.T  # eq. 35 (in place: no fresh n x n allocation)
    return 0.5 * (p + p.T), nis_value


def feature_initialization(pose: np.ndarray, z: np.ndarray
                           ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return new landmark positions and their Jacobians (eqs. 39-40, 45-48).

    Args:
        pose: (3,) robot pose [x_r, y_r, psi_r].
        z: (L, 2) observations [r, theta].

    Returns:
        ``(g (L, 2), G_r (L, 2, 3), G_z (L, 2, 2))``.
    """
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


def augment_map(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray
                ) -> Tuple[np.ndarray, np.ndarray]:
    """Append landmarks initialised from observations to the state (eqs. 38-48).

    ``P* = Y [[P, 0], [0, R]] Y^T`` (eq. 43) with ``Y`` of eq. 44 evaluated block-wise: the
    new rows are ``G_r P_r.`` and the new diagonal ``G_r P_rr G_r^T + G_z R G_z^T``.

    Args:
        x: State.
        p: Covariance.
        z: (L, 2) observations of the new landmarks.
        r: (L, 2, 2) their covariances.

    Returns:
        ``(x*, P*)`` new arrays of size ``n + 2L``.
    """
    n, nl = x.size, z.shape[0]
    g, gr, gz = feature_initialization(x[:3], z)
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
    """

    def __init__(self, params: Optional[SlamParams] = None,
                 initial_pose: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """Create the filter with the map initialised at ``initial_pose`` (eqs. 23-24)."""
        self.params = params or SlamParams()
        self._initial_pose = np.array(initial_pose, dtype=float).reshape(3)
        self.reset()

    # ------------------------------------------------------------------ state access
    def reset(self, initial_pose: Optional[Sequence[float]] = None) -> None:
        """Forget the map, the candidates and the statistics; restart at a pose.

        Args:
            initial_pose: New start pose (default: the one given to the constructor).
        """
        if initial_pose is not None:
            self._initial_pose = np.array(initial_pose, dtype=float).reshape(3)
        self._x, self._p = map_initialization(self._initial_pose)
        self._ids = np.zeros(0, dtype=np.int64)
        self._bis = np.zeros((0, 2))      # per landmark: sum of world bisector unit vectors
        self._open = np.zeros(0)          # per landmark: mean opening (nan: unknown)
        self._n_open = np.zeros(0, dtype=np.int64)
        self._next_id = 0
        self._candidates: List[_Candidate] = []
        self._next_cid = 0
        self._scan = 0
        self.stats: Dict[str, int] = {'predictions': 0, 'updates': 0, 'psd_repairs': 0,
                                      'matched': 0, 'confirmed': 0, 'new_candidates': 0,
                                      'dropped_candidates': 0, 'rejected': 0}

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
    def landmarks(self) -> np.ndarray:
        """(N, 2) landmark positions in the map frame, state order."""
        return self._x[3:].reshape(-1, 2).copy()

    @property
    def landmark_covariances(self) -> np.ndarray:
        """(N, 2, 2) marginal covariances of the landmarks."""
        cols = _landmark_cols(np.arange(self.num_landmarks))
        return self._p[cols[:, :, None], cols[:, None, :]].copy()

    @property
    def candidates(self) -> List[Tuple[int, np.ndarray, int]]:
        """Tentative landmarks as ``(candidate id, position (2,), hits)``."""
        return [(c.cid, c.xy.copy(), c.hits) for c in self._candidates]

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
        ekf_predict(self._x, self._p, u, u_cov)
        self.stats['predictions'] += 1

    def default_r(self, m: int) -> np.ndarray:
        """Return (m, 2, 2) default observation covariances ``diag(s_r^2, s_b^2)`` (eq. 22)."""
        r = np.zeros((m, 2, 2))
        r[:, 0, 0] = self.params.sigma_range ** 2
        r[:, 1, 1] = self.params.sigma_bearing ** 2
        return r

    def update(self, z: np.ndarray, r: Optional[np.ndarray] = None,
               descriptors: Optional[np.ndarray] = None) -> UpdateResult:
        """Associate, update, manage candidates and augment with one scan's observations.

        Args:
            z: (M, 2) range-bearing observations [m, rad] in base_link (laser mount applied,
                e.g. :func:`.observations.corners_to_observations`).
            r: (M, 2, 2) covariance per observation; None = :meth:`default_r`.
            descriptors: Optional (M, 2) ``[bisector in base_link, opening]`` [rad] per
                observation (:func:`.observations.corner_descriptors`); NaN = unknown.

        Returns:
            The per-observation association result.
        """
        prm = self.params
        z = np.asarray(z, dtype=float).reshape(-1, 2).copy()
        m = z.shape[0]
        r = self.default_r(m) if r is None else np.asarray(r, dtype=float).reshape(m, 2, 2)
        self._scan += 1
        self.stats['updates'] += 1
        status = np.full(m, 'rejected', dtype='<U9')
        reason = np.full(m, '', dtype='<U9')
        lm_id = np.full(m, -1, dtype=np.int64)
        cand_id = np.full(m, -1, dtype=np.int64)
        d2_out = np.full(m, np.nan)

        # Validation: NaN / inf, ranges, covariances.
        with np.errstate(invalid='ignore'):
            finite = np.all(np.isfinite(z), axis=1) & np.all(np.isfinite(r), axis=(1, 2))
            det = r[:, 0, 0] * r[:, 1, 1] - r[:, 0, 1] * r[:, 1, 0]
            valid = finite & (z[:, 0] > 0.0) & (r[:, 0, 0] > 0.0) & (det > 0.0)
        reason[~valid] = 'invalid'
        far = valid & (z[:, 0] > prm.max_range)
        reason[far] = 'range'
        keep = valid & ~far
        if descriptors is not None and prm.min_view_margin > 0.0:
            d_all = np.asarray(descriptors, dtype=float).reshape(m, 2)
            view = np.abs(_wrap(z[:, 1] + _PI - d_all[:, 0]))
            half = 0.5 * np.minimum(d_all[:, 1], _TWO_PI - d_all[:, 1])
            with np.errstate(invalid='ignore'):
                graze = keep & (half - view < prm.min_view_margin)
            reason[graze] = 'grazing'
            keep &= ~graze
        use = np.flatnonzero(keep)
        zu = z[use]
        zu[:, 1] = _wrap(zu[:, 1])
        ru = prm.r_scale * 0.5 * (r[use] + np.transpose(r[use], (0, 2, 1)))
        ru[:, 0, 0] += prm.range_floor ** 2 + prm.position_floor ** 2
        ru[:, 1, 1] += prm.bearing_floor ** 2 + (prm.position_floor / zu[:, 0]) ** 2
        if descriptors is None:
            desc = np.full((use.size, 2), np.nan)
        else:
            desc = np.asarray(descriptors, dtype=float).reshape(m, 2)[use]
        # World bisector unit vectors (zeros where unknown) and openings of the observations.
        wb = desc[:, 0] + self._x[2]
        known = np.isfinite(wb)
        bvec = np.where(known[:, None], np.column_stack([np.cos(wb), np.sin(wb)]), 0.0)

        # Data association (eqs. 49-55) and update (eqs. 32-37).
        allowed = self._descriptor_gate(bvec, desc[:, 1], self._bis, self._open)
        hyp, d2, nodes = do_data_association(self._x, self._p, zu, ru, prm.association,
                                             prm.gate_probability, prm.jcbb_max_nodes,
                                             allowed)
        ok = hyp >= 0
        nis, dof = 0.0, 0
        if np.any(ok):
            self._p, nis = ekf_update(self._x, self._p, zu[ok], ru[ok], hyp[ok],
                                      prm.max_update_iterations, prm.relinearize_ratio)
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
        # Unassociated observations near a landmark are ambiguous: no duplicate landmark.
        rest = np.flatnonzero(~ok)
        if rest.size and d2.shape[1]:
            amb = np.min(d2[rest], axis=1) < chi2_gate(2, prm.new_landmark_probability)
            reason[use[rest[amb]]] = 'ambiguous'
            rest = rest[~amb]
        if rest.size:
            self._handle_candidates(zu[rest], ru[rest], use[rest], bvec[rest],
                                    desc[rest, 1], status, reason, lm_id, cand_id)
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
                            psd_repaired=repaired, jcbb_nodes=nodes)

    def step(self, u: Sequence[float], z: np.ndarray, r: Optional[np.ndarray] = None,
             u_cov: Optional[np.ndarray] = None) -> UpdateResult:
        """Run :meth:`predict` then :meth:`update` (one iteration of Fig. 17)."""
        self.predict(u, u_cov)
        return self.update(z, r)

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

    # ------------------------------------------------------------------ candidates
    def _handle_candidates(self, z: np.ndarray, r: np.ndarray, obs: np.ndarray,
                           bvec: np.ndarray, opening: np.ndarray, status: np.ndarray,
                           reason: np.ndarray, lm_id: np.ndarray,
                           cand_id: np.ndarray) -> None:
        """Match unexplained observations to candidates, start new ones, confirm (augment)."""
        prm = self.params
        if self.num_landmarks >= prm.max_landmarks:
            reason[obs] = 'cap'
            return
        g, gr, gz = feature_initialization(self._x[:3], z)  # eq. 40 with the updated pose
        cov = (gr @ self._p[:3, :3] @ np.transpose(gr, (0, 2, 1))
               + gz @ r @ np.transpose(gz, (0, 2, 1)))
        assigned = np.full(z.shape[0], -1, dtype=np.int64)
        if self._candidates:
            cxy = np.array([c.xy for c in self._candidates])
            ccov = np.array([c.cov for c in self._candidates])
            d2 = mahalanobis_table(g[:, None, :] - cxy[None], cov[:, None] + ccov[None])
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
                c.xy = c.cov @ (info_old @ c.xy + info_new @ g[k])
                c.hits += 1
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
                               n_open=int(has))
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
        take = np.array(confirm[:room], dtype=np.int64)
        for k in confirm[room:]:
            status[obs[k]] = 'rejected'
            reason[obs[k]] = 'cap'
        if take.size == 0:
            return
        self._x, self._p = augment_map(self._x, self._p, z[take], r[take])  # eqs. 38-48
        new_ids = self._next_id + np.arange(take.size, dtype=np.int64)
        self._next_id += take.size
        self._ids = np.concatenate([self._ids, new_ids])
        by_id = {c.cid: c for c in self._candidates}
        new_c = [by_id[int(cand_id[obs[k]])] for k in take]
        self._bis = np.vstack([self._bis, np.array([c.bis for c in new_c])])
        self._open = np.concatenate([self._open, [c.opening for c in new_c]])
        self._n_open = np.concatenate([self._n_open, [c.n_open for c in new_c]])
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


__all__ = ['ASSOCIATION_METHODS', 'augment_map', 'do_data_association', 'EkfSlam',
           'ekf_predict', 'ekf_update', 'feature_initialization', 'is_psd',
           'joint_observation_covariance', 'map_initialization', 'nearest_psd',
           'observation_model', 'odometry_check', 'odometry_increment', 'odometry_noise',
           'OdometryNoise', 'predicted_observation_covariance', 'SlamParams', 'STATUSES',
           'UpdateResult']
