"""EKF-SLAM parameters and constants: :class:`SlamParams`, :class:`OdometryNoise`.

Every option is documented in :class:`SlamParams` with its units; the measurements behind
each one are in the docstring of the module that computes it (:mod:`.prediction`,
:mod:`.observation_models`, :mod:`.update`, :mod:`.consistent_linearisation`,
:mod:`.gating`, :mod:`.map_management`; the state layout in :mod:`.ekf_slam`).
"""

from dataclasses import dataclass, field
import math
from typing import Optional

import numpy as np

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
#: Landmark kinds (values of :attr:`.ekf_slam.EkfSlam.landmark_kinds`).
CORNER, LINE = 0, 1


# ------------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class OdometryNoise:
    """Odometry increment noise ``U`` (:mod:`.prediction`, "Odometry noise").

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
            added to every line observation's ``R`` (:mod:`.observation_models`, "Noise
            models");
            0 (default) disables.
        line_residual_factor: ``k``: each line observation also gets segment-wide end
            offsets of std ``k`` times the segment's own residual std (its beams' scatter
            about the fitted line, :attr:`.line_landmarks.LineObservations.residual_std`),
            added in quadrature to ``line_floor`` (:mod:`.observation_models`, "Noise
            models");
            0 disables.
        line_beam_width: ``delta``, the laser beam's 1-sigma angular spread across the
            beam [rad]: each line observation also gets the footprint term of
            :func:`.line_landmarks.line_footprint_covariance` (end offsets of std
            ``delta |t|``, ``t`` the end's position along the line from its foot point:
            the beam's effective range noise ``r delta / tan(theta)`` at incidence
            ``theta`` projected on the wall's normal; :mod:`.observation_models`, "Noise
            models");
            0 (default) disables.
        max_range: Observations farther than this are rejected [m].
        association: ``'icnn'`` (default) or ``'jcbb'``.
        joint_check: With ICNN, fall back to JCBB when the ICNN hypothesis fails a joint
            compatibility test at ``joint_probability`` (:func:`.gating.do_data_association`).
        reject_ambiguous: Keep only the associated pairs whose observation has one
            landmark and whose landmark has one observation inside the gate
            (:func:`.gating.reject_ambiguous_pairs`); the others are rejected as ``'ambiguous'``.
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
        prune_misses: Visibility-aware pruning (:mod:`.map_management`): a
            landmark that this many consecutive scans should have shown and did not (in
            the field of view and range, facing the robot, and the laser saw through its
            place, :mod:`.visibility`) is removed; 0 disables. Default ``confirm_hits``
            (None): as many scans to leave the map as to enter it. Needs the scan
            geometry passed to :meth:`.ekf_slam.EkfSlam.update`.
        establish_hits: Detections a provisional corner needs after entering the state to
            stay (:mod:`.map_management`); 0 (default) disables. Needs the
            scan geometry passed to :meth:`.ekf_slam.EkfSlam.update`.
        establish_chances: Chances (scans that could have shown it) within which those
            detections must come; default ``confirm_window`` (None).
        line_min_beams: Unoccluded beams a line landmark must cover to count as visible
            (the line extractor's ``min_points``).
        mode: ``'slam'`` or ``'localization'`` (track on the map; no candidates, no new
            landmarks, no pruning or eviction).
        jcbb_max_nodes: Node budget of JCBB per scan.
        psd_tolerance: Relative jitter of the positive semi-definiteness test.
        psd_check_interval: Test P every this many updates (1 = always).
        max_odometry_jump_m: :func:`.prediction.odometry_check` threshold on one increment [m].
        max_odometry_jump_rad: :func:`.prediction.odometry_check` threshold on one increment [rad].
        max_update_iterations: Largest number of linearisations of one update (1 = plain
            EKF; see "Iterated update" in :mod:`.update`).
        jacobians: ``'standard'`` (default): the chapter's, at the latest estimates;
            ``'observability'``: the covariance update uses observability-constrained
            Jacobians, the mean update the chapter's; ``'observability_gain'``: both use the
            constrained ones (Huang et al.'s OC-EKF); ``'first_estimates'``: both use
            Jacobians at the robot's prior and each landmark's first estimate (FEJ-EKF);
            ``'invariant'``: the chapter's Jacobians, with the right-invariant EKF's update
            (the correction applied on SE(2) and the covariance carried to the updated
            estimate); :mod:`.consistent_linearisation`.
        relinearize_ratio: Linearise again when an observed landmark moved, relative to the
            robot, by more than this fraction of its range during the update.
        cartesian_gate: None (default): off. Otherwise a corner pair that the range-bearing
            gate admits and whose predicted range std is at least this fraction of the
            predicted range is also tested in the map frame (the observation put in the
            map, against the landmark), where it is linear in the robot position and the
            landmark, and gated with the larger of the two ``d2``
            (:func:`.gating.cartesian_pair_d2`; :mod:`.gating`, "Cartesian gate"); 0 tests every
            admitted corner pair.
        free_space_check: None (default): off. Otherwise the confidence of a
            negative-information test of each scan's association hypothesis (module
            docstring, "Free-space check"; :func:`.gating.free_space_contradictions`): the corners
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
            remain after the other checks (:mod:`.gating`, "Recovery"); in
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
            region's convex hull); a pair above it is dropped (:mod:`.gating`, "Spurious
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
