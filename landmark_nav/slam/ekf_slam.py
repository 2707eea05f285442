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


Where each part is computed
---------------------------
One module per concept; each keeps its equations and the measurements behind its options in
its own docstring. This module holds :class:`EkfSlam` and re-exports the step functions.

* :mod:`.slam_params` -- :class:`SlamParams`, :class:`OdometryNoise`, the constants.
* :mod:`.prediction` -- initialisation, odometry increment and noise, prediction
  ("Odometry noise").
* :mod:`.observation_models` -- ``h``, ``g`` and their Jacobians for corners and lines, the
  predicted observation covariance ("Noise models", "Line landmarks").
* :mod:`.gating` -- data association and the checks of its hypothesis ("Corner
  descriptors", "Ambiguous pairs", "Cartesian gate", "Free-space check", "Recovery",
  "Spurious pairs").
* :mod:`.update` -- the batch update ("Iterated update", "Numerics").
* :mod:`.consistent_linearisation` -- OC-EKF, first-estimates and invariant EKF
  ("Consistency").
* :mod:`.map_management` -- candidates, augmentation, pruning, eviction ("Tentative
  landmarks", "Map management").

Filter steps (one function each, named after Fig. 17)
-----------------------------------------------------
* :func:`.prediction.map_initialization` (eqs. 23-24).
* :func:`.prediction.odometry_increment` (eq. 13) and :func:`.prediction.odometry_noise`
  (``U``, :mod:`.prediction`, "Odometry noise").
* :func:`.prediction.ekf_predict` (eqs. 25-30): ``x_r <- x_r (+) u``;
  ``P_rr <- J1 P_rr J1^T + J2 U J2^T`` (the chapter's eq. 26 prints ``J1^T`` in the second
  term; its eq. 28 has a sign typo, the Jacobians come from
  :func:`landmark_nav.geometry.compose_jacobians`) and ``P_rm <- J1 P_rm``; landmarks are
  static (eq. 12). O(N).
* :func:`.observation_models.observation_model` (eqs. 18-20, 37, 50, 53): range and bearing
  of landmarks from base_link with the Jacobians ``H_r`` (2 x 3) and ``H_F`` (2 x 2).
* :func:`.gating.do_data_association` (eqs. 49-55): ICNN with a chi-square gate (default) or JCBB,
  see :mod:`.association`.
* :func:`.update.ekf_update` (eqs. 32-36): one batch update with every associated
  observation, re-linearised when the estimate moves far (:mod:`.update`, "Iterated
  update").
* :func:`.map_management.augment_map` (eqs. 38-48): appends landmarks initialised from
  observations.


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
nearly edge-on, :mod:`.gating`, "Corner descriptors"), ``'ambiguous'`` (not associated
but inside the ``new_landmark_probability`` gate of a landmark: neither matched nor allowed
to create a duplicate), ``'cap'`` (the map holds ``max_landmarks`` and nothing can be evicted, or
``map_full='reject'``), ``'localization'`` (unexplained in localization mode),
``'free_space'`` (a pair dropped by the free-space check, ``free_space_check``).

"""

from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

from landmark_nav.geometry import wrap_angle
import numpy as np

from ._linalg import _PI, _TWO_PI, _wrap
from .consistency import chi2_gate
from .consistent_linearisation import (constrain_jacobians, invariant_retraction,
                                       invariant_transport, unobservable_directions)
from .gating import (cartesian_pair_d2, do_data_association, free_space_contradictions,
                     free_space_significant, HypothesisChecks, reject_ambiguous_pairs)
from .line_landmarks import ends_to_map, LineObservations
from .map_management import _Candidate, augment_map, MapManagement
from .observation_models import (_landmark_cols, feature_initialization,
                                 joint_observation_covariance, line_noise_covariance,
                                 observation_model, predicted_observation_covariance)
from .prediction import (ekf_predict, map_initialization, odometry_check, odometry_increment,
                         odometry_noise)
from .slam_map import SlamMap
from .slam_params import (_FIRST_ESTIMATE_RULES, ASSOCIATION_METHODS, CORNER, JACOBIANS, LINE,
                          MAP_FULL_POLICIES, MODES, OdometryNoise, SlamParams, STATUSES)
from .update import ekf_update, is_psd, nearest_psd
from .visibility import ScanGeometry


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


# ---------------------------------------------------------------------------- the filter
class EkfSlam(HypothesisChecks, MapManagement):
    """EKF-SLAM filter (state layout: module docstring; the parts: the modules it lists).

    Typical use, per scan::

        slam = EkfSlam(SlamParams(), initial_pose=odom_pose_0)
        slam.predict(odometry_increment(odom_prev, odom_now))
        result = slam.update(z, R)   # z (M, 2) range-bearing in base_link

    Line landmarks, visibility pruning and map reuse: :meth:`update` (``lines``, ``scan``),
    :meth:`export_map` / :meth:`load_map` (:mod:`.observation_models`, "Line landmarks";
    :mod:`.map_management`; module docstring, "Map reuse").
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
        if m == 0:  # a prediction-only step (a laser blackout, no features): bookkeeping
            if self._manages_map(scan):
                nothing = np.zeros(self.num_landmarks, dtype=bool)
                self._manage_by_visibility(scan, nothing, nothing)
            return self._finish_update(status, lm_id, cand_id, reason, d2_out, 0.0, 0, 0,
                                       kind_all)

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
        # Floors: the corner extractor's biases (observation_models, "Noise models").
        ru[cu, 0, 0] += prm.range_floor ** 2 + prm.position_floor ** 2
        ru[cu, 1, 1] += prm.bearing_floor ** 2 + (prm.position_floor / zu[cu, 0]) ** 2
        if not np.all(cu):  # segment-wide errors of lines (observation_models)
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
        if self._manages_map(scan):
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
            self._manage_by_visibility(scan, seen, near)
        if rest.size and prm.mode == 'localization':
            reason[use[rest]] = 'localization'
        elif rest.size:
            self._handle_candidates(zu[rest], ru[rest], use[rest], bvec[rest],
                                    desc[rest, 1], status, reason, lm_id, cand_id, ku[rest],
                                    ends_all[use[rest]])
        return self._finish_update(status, lm_id, cand_id, reason, d2_out, nis, dof, nodes,
                                   kind_all)

    def _finish_update(self, status: np.ndarray, lm_id: np.ndarray, cand_id: np.ndarray,
                       reason: np.ndarray, d2: np.ndarray, nis: float, dof: int, nodes: int,
                       kind: np.ndarray) -> UpdateResult:
        """End every update: expire candidates, check P every few scans, count, report."""
        prm = self.params
        self._expire_candidates()
        repaired = False
        if self._scan % prm.psd_check_interval == 0 and not is_psd(self._p, prm.psd_tolerance):
            self._p = nearest_psd(self._p)
            self.stats['psd_repairs'] += 1
            repaired = True
        self.stats['matched'] += int(np.sum(status == 'matched'))
        self.stats['rejected'] += int(np.sum(status == 'rejected'))
        return UpdateResult(status=status, landmark_id=lm_id, candidate_id=cand_id,
                            reason=reason, d2=d2, nis=nis, nis_dof=dof,
                            psd_repaired=repaired, jcbb_nodes=nodes, kind=kind)

    def step(self, u: Sequence[float], z: np.ndarray, r: Optional[np.ndarray] = None,
             u_cov: Optional[np.ndarray] = None) -> UpdateResult:
        """Run :meth:`predict` then :meth:`update` (one iteration of Fig. 17)."""
        self.predict(u, u_cov)
        return self.update(z, r)


__all__ = ['ASSOCIATION_METHODS', 'augment_map', 'cartesian_pair_d2', 'CORNER',
           'do_data_association', 'EkfSlam', 'constrain_jacobians',
           'free_space_contradictions', 'free_space_significant', 'invariant_retraction',
           'invariant_transport', 'JACOBIANS', 'LINE', 'MAP_FULL_POLICIES', 'MODES',
           'ekf_predict', 'ekf_update', 'feature_initialization', 'is_psd',
           'joint_observation_covariance', 'line_noise_covariance', 'map_initialization',
           'nearest_psd',
           'observation_model', 'odometry_check', 'odometry_increment', 'odometry_noise',
           'OdometryNoise', 'predicted_observation_covariance', 'reject_ambiguous_pairs',
           'SlamParams', 'STATUSES', 'unobservable_directions', 'UpdateResult']
