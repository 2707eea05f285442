"""Run :class:`~landmark_nav.slam.ekf_slam.EkfSlam` on a scenario and score it against truth.

Pipeline: the scenario's odometry samples and scans go, in time order, through
:class:`~landmark_nav.slam.frontend.SlamFrontend`, the front end the ``ekf_slam`` node uses
(odometry checks judged against elapsed time and noise, bridging, interpolation to the scan
stamp, the increment of eq. 13 for :meth:`~landmark_nav.slam.ekf_slam.EkfSlam.predict`,
de-skew of each feature by the odometry motion up to its beam time). Each scan's features
(:func:`scan_features`: corners and / or lines, ``landmarks``, on ``angle_min + i *
increment`` with REP 117 validity) and its geometry (visibility-aware pruning) go with it
to :meth:`~landmark_nav.slam.ekf_slam.EkfSlam.update`. The estimate is for the scan stamp.

The scenario is a simulated run (:func:`landmark_nav.sim.run_scenario`) or a bag
(:func:`landmark_nav.evaluation.bags.load_bag`: any bag with ``/scan``, ``/odom`` and a
reference); :func:`evaluate_bag` adds the aligned ATE and the RPE
(:mod:`landmark_nav.evaluation.trajectory`, evo's metrics), TUM files, ``slam.json`` and
the figures (``landmark_nav evaluate``).

Scores (:func:`score_run`), all in the map frame, which is the world (reference) frame
because the map is initialised at the first odometry pose (odom == world at the start; a
bag's odometry is re-expressed to start at the reference pose when it does not):

* ATE: robot position error ``|p_est - p_true|`` at the scan stamps (RMSE and max), the
  same for odometry alone (unaligned).
* Landmarks (only with a world, i.e. the simulator's truth; None / NaN otherwise): every
  mapped landmark is paired with its nearest true corner at the end of the run;
  ``landmark_rmse`` is the RMSE of those distances over landmarks whose nearest corner is
  within ``match_distance`` (the others count as ``ghost_landmarks``); a true corner
  claimed by two landmarks adds a ``duplicate``.
* True visible corners: corners the laser sees with both arms in the detector's class
  (:func:`landmark_nav.evaluation.features.corner_truth`, scored) in at least
  ``confirm_hits`` scans, the number of scans a landmark needs to be mapped (scans without
  any return, e.g. during a laser blackout, see nothing).
* Wrong associations: the true identity of an observation is its nearest true corner
  (observation put in the world with the TRUE pose at its beam time) within
  ``match_distance``, else none
  (a ghost); the identity of a landmark is its nearest true corner at the end. A 'matched'
  or 'confirmed' observation whose identity differs from its landmark's (or is a ghost) is
  a wrong association.
* NEES of the robot pose (eq. 59, 3 dof) per scan and the share inside the two-sided 95 %
  band ``[chi2_3(0.025), chi2_3(0.975)]`` (and below the one-sided ``chi2_3(0.95)``).
"""

from dataclasses import asdict, dataclass, field, fields, replace
import json
import math
from pathlib import Path
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from landmark_nav.conversions import classify_ranges
from landmark_nav.evaluation.bags import load_bag
from landmark_nav.evaluation.blas import single_threaded
from landmark_nav.evaluation.features import corner_truth
from landmark_nav.evaluation.trajectory import (aligned, ALIGNMENTS, ate, position_errors, rpe,
                                                STATISTICS, Trajectory, write_tum)
from landmark_nav.geometry import compose, covariance_ellipse, relative, transform_points
from landmark_nav.laser.corners import CornerParams
from landmark_nav.laser.lines import LineParams
from landmark_nav.sim import OdometrySample, run_scenario, ScanSample, ScenarioResult
from landmark_nav.sim.laser import compose as sensor_pose
from landmark_nav.slam.consistency import chi2_band, chi2_gate, nees
from landmark_nav.slam.ekf_slam import (CORNER, EkfSlam, LINE, OdometryNoise, SlamParams,
                                        UpdateResult)
from landmark_nav.slam.features import check_landmarks, extract_scan_features
from landmark_nav.slam.frontend import (Corners, FrontendParams, odometry_noise_model,
                                        SlamFrontend, Step)
from landmark_nav.slam.slam_map import load_map, save_map, SlamMap
from landmark_nav.slam.visibility import ScanGeometry
import numpy as np

ASSOCIATIONS = ('icnn', 'jcbb')
#: Default ATE alignment of ``evaluate`` (the unaligned ATE is always reported too).
ALIGN_DEFAULT = 'se2'
#: Default RPE distance [m].
RPE_DISTANCE_M = 1.0
#: custom_data key of the importer's drift model (imported-bag contract).
DRIFT_KEY = 'landmark_nav.drift_model'


@dataclass(frozen=True, eq=False)
class SlamRun:
    """Per-scan record of a run (S scans, O observations in total)."""

    stamps: np.ndarray        # (S,) scan stamps [ns]
    poses: np.ndarray         # (S, 3) filter pose at the scan stamp
    covariances: np.ndarray   # (S, 3, 3) its covariance
    truth: np.ndarray         # (S, 3) true pose
    odometry: np.ndarray      # (S, 3) odometry pose interpolated to the stamp
    obs_scan: np.ndarray      # (O,) scan index of each observation
    obs_world_true: np.ndarray  # (O, 2) observation in the world via the true pose
    obs_status: np.ndarray    # (O,) association status
    obs_landmark: np.ndarray  # (O,) landmark id or -1
    nis: np.ndarray           # (S,) joint NIS per scan
    nis_dof: np.ndarray       # (S,) its dof
    landmark_ids: np.ndarray  # (N,) final map ids
    landmarks: np.ndarray     # (N, 2) final map
    landmark_covariances: np.ndarray  # (N, 2, 2)
    stats: Dict[str, int]
    resets: int
    seconds: float            # filter time (predict + update) [s]
    reset_reasons: Dict[str, int] = field(default_factory=dict)  # why the filter restarted
    #: Odometry / feature-set events of the front end other than used as they came
    #: (:data:`~landmark_nav.slam.frontend.ODOMETRY_EVENTS`, ``FEATURE_EVENTS``).
    events: Dict[str, int] = field(default_factory=dict)
    #: (S,) index of each step's scan among the scenario's scans (a scan the front end
    #: skipped, e.g. before any odometry, has no step).
    scan_index: Optional[np.ndarray] = None
    # Line landmarks (landmarks 'lines' / 'both'); ``landmarks`` above holds the corners only.
    line_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (L, 2) rho, alpha
    line_ends: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    final_map: Optional[SlamMap] = None  # the filter's map at the end (save_map)
    #: (O, 2) each corner observation placed in the map with the filter's pose after its
    #: step (through the laser mount, not de-skewed): where the filter put it then, to
    #: compare with where the final map has its landmark.
    obs_world: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    #: (S,) whether the front end bridged an odometry jump before the step (``'jump'``:
    #: the odometry frame broke, e.g. two runs in one log).
    bridged: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    #: Steps predicted with each motion (``SlamFrontend.motions``: ``odometry``,
    #: ``scan_matching``).
    motions: Dict[str, int] = field(default_factory=dict)
    #: ``SlamFrontend.icp_restarts``: steps whose first ICP solution failed or was rejected
    #: (``restarted``) and those a restart from other headings made usable (``recovered``).
    icp_restarts: Dict[str, int] = field(default_factory=dict)
    #: (S, 3) the motion each step predicted with (the odometry increment, or the
    #: scan-matched / fused motion), so ``relative(compose(poses[k-1], increments[k]),
    #: poses[k])`` is what step k's update moved the pose (eq. 25; after a restart the
    #: first pose is the odometry's).
    increments: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass(frozen=True)
class SlamScore:
    """Scores of one run (see the module docstring)."""

    ate_rmse: float                    # NaN without a reference (so are odom_ate_*, NEES)
    ate_max: float
    odom_ate_rmse: float
    odom_ate_max: float
    landmark_rmse: float               # NaN without a world (real logs)
    mapped: int
    true_visible: Optional[int]        # None without a world
    ghost_landmarks: Optional[int]     # None without a world
    duplicates: Optional[int]          # None without a world
    associations: int
    wrong_associations: Optional[int]  # None without a world
    nees_share_band: float
    nees_share_gate: float
    mean_nees: float
    mean_nis_per_dof: float
    psd_repairs: int
    ms_per_scan: float


def scan_angles(scan: ScanSample) -> np.ndarray:
    """Return the (N,) beam angles ``angle_min + i * angle_increment`` of a scan."""
    return scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))


def scan_corners(scan: ScanSample, corner_params: Optional[CornerParams] = None) -> list:
    """Corners of one scan as the ``corner_extractor`` node finds them.

    Beams valid per REP 117 (:func:`landmark_nav.conversions.classify_ranges`: finite and
    within ``[range_min, range_max]``), beam angles :func:`scan_angles`, the node's default
    segmentation (incidence 10 deg, 5 points).
    """
    return scan_features(scan, 'corners', corner_params)[0]


def scan_features(scan: ScanSample, landmarks: str = 'corners',
                  corner_params: Optional[CornerParams] = None,
                  line_params: Optional[LineParams] = None) -> Tuple[list, list]:
    """Corners and / or lines of one scan in the laser frame.

    :func:`~landmark_nav.slam.features.extract_scan_features` on the beams valid per REP 117
    (as :func:`scan_corners`).

    Returns:
        ``(corners, lines)`` in the laser frame.
    """
    valid = classify_ranges(scan.ranges, scan.range_min, scan.range_max)[0]
    return extract_scan_features(scan.ranges, scan_angles(scan), valid, scan.angle_increment,
                                 landmarks, corner_params, line_params)


@single_threaded
def run_slam(result: ScenarioResult, params: Optional[SlamParams] = None,
             corner_params: Optional[CornerParams] = None, deskew: bool = True,
             descriptors: bool = True,
             callback: Optional[Callable[[int, EkfSlam, UpdateResult], None]] = None,
             frontend: Optional[FrontendParams] = None, landmarks: str = 'corners',
             line_params: Optional[LineParams] = None, visibility: bool = True,
             slam_map: Optional[SlamMap] = None,
             map_pose_covariance: Optional[np.ndarray] = None) -> SlamRun:
    """Run the filter over a simulated scenario or a bag through :class:`SlamFrontend`.

    The odometry samples and each scan's features (:func:`scan_features`: corners and / or
    lines, with the scan's geometry for visibility-aware pruning) go to the front end in
    time order, as the ``ekf_slam`` node receives them; whatever the front end leaves
    waiting at the end is flushed.

    Args:
        result: Output of :func:`landmark_nav.sim.run_scenario` (with a laser) or a
            :class:`~landmark_nav.evaluation.bags.BagScenario`.
        params: Filter parameters.
        corner_params: Corner extractor parameters.
        deskew: Compensate the motion during the laser sweep with odometry (overrides
            ``frontend.deskew``).
        descriptors: Pass the corners' bisector / opening to the association (overrides
            ``frontend.descriptors``).
        callback: Called as ``callback(scan index, filter, update result)`` after each scan.
        frontend: Front-end parameters (odometry checks, scan-matched motion).
        landmarks: ``'corners'``, ``'lines'`` or ``'both'``
            (:func:`landmark_nav.slam.features.extract_scan_features`).
        line_params: Line extractor parameters (default: ``LineParams`` with the corner
            parameters' noise).
        visibility: Pass each scan's geometry to the filter (visibility-aware pruning,
            ``SlamParams.prune_misses``).
        slam_map: Start on this saved map (:meth:`EkfSlam.load_map`), e.g. with
            ``params.mode == 'localization'``; the start pose is the first odometry pose.
        map_pose_covariance: (3, 3) covariance of that start pose (default zeros).

    Returns:
        The per-scan record.

    Raises:
        ValueError: ``frontend.scan_matching`` without ``visibility`` (it needs the scan).
    """
    check_landmarks(landmarks)
    if frontend is not None and frontend.scan_matching and not visibility:
        raise ValueError('run_slam: frontend.scan_matching needs the scans (visibility=True)')
    corner_params = corner_params or CornerParams()
    if line_params is None and landmarks != 'corners':
        line_params = LineParams(sigma_r=corner_params.sigma_r,
                                 sigma_phi=corner_params.sigma_phi)
    fp = replace(frontend or FrontendParams(), deskew=deskew, descriptors=descriptors)
    mount = np.asarray(result.laser.mount, dtype=float)
    fe = SlamFrontend(params, mount, fp, on_step=lambda st: record(st), slam_map=slam_map,
                      map_pose_covariance=map_pose_covariance)
    sigma_laser = float(getattr(result.laser, 'sigma_range', fe.params.sigma_range))
    seconds = record_s = 0.0
    scan_k = 0
    o_scan, o_world, o_status, o_lm, o_est = [], [], [], [], []
    poses, covs, nis_v, nis_d, odo_at, stamps, index = [], [], [], [], [], [], []
    bridged, incs = [], []

    def record(st: Step) -> None:  # right after the step (several may come at once)
        nonlocal record_s
        tic = time.perf_counter()
        k = st.tag
        if callback is not None:
            callback(k, st.slam, st.result)
        stamps.append(st.stamp_ns)
        index.append(k)
        poses.append(st.pose)
        covs.append(st.covariance)
        odo_at.append(st.odometry)
        incs.append(st.increment)
        bridged.append(bool(np.any(np.asarray(st.bridged_variance) > 0.0)))
        nis_v.append(st.result.nis)
        nis_d.append(st.result.nis_dof)
        scan, corners = pending.pop(k)
        if len(corners):
            lp = np.array([c.position for c in corners]).reshape(-1, 2)
            beam_ns = scan.stamp_ns + np.rint(np.array([c.index for c in corners])
                                              * scan.time_increment * 1e9).astype(np.int64)
            beam_ns = np.minimum(beam_ns, result.end_ns)
            o_world.append(transform_points(
                sensor_pose(result.truth_at(beam_ns), tuple(mount)), lp))
            o_est.append(transform_points(sensor_pose(st.pose, tuple(mount)), lp))
            o_scan.append(np.full(len(corners), len(stamps) - 1))
            o_status.append(st.result.status[:len(corners)])  # corners first, then lines
            o_lm.append(st.result.landmark_id[:len(corners)])
        record_s += time.perf_counter() - tic

    pending: Dict[int, Tuple[ScanSample, list]] = {}  # scan index -> scan, corners
    for ev in result.events:
        if isinstance(ev, OdometrySample):
            tic = time.perf_counter()
            fe.add_odometry(ev.stamp_ns, ev.pose, ev.covariance)
            seconds += time.perf_counter() - tic
        elif isinstance(ev, ScanSample):
            corners, segs = scan_features(ev, landmarks, corner_params, line_params)
            pending[scan_k] = (ev, corners)
            geometry = None
            if visibility:
                geometry = ScanGeometry(np.asarray(ev.ranges, dtype=float), ev.angle_min,
                                        ev.angle_increment, ev.range_min, ev.range_max,
                                        mount, sigma_laser)
            tic = time.perf_counter()
            fe.add_features(Corners.from_corners(
                ev.stamp_ns, corners, ev.time_increment, segs,
                None if line_params is None else line_params.sigma_r, geometry), scan_k)
            scan_k += 1
            seconds += time.perf_counter() - tic
    tic = time.perf_counter()
    fe.flush()
    seconds += time.perf_counter() - tic
    seconds -= record_s  # the filter's time only
    slam = fe.slam
    truth = result.truth_at(np.array(stamps, dtype=np.int64))
    events = {k: v for k, v in fe.events.items() if v and k not in ('accepted', 'processed')}
    cat = (lambda a, shape, dt=float: np.concatenate(a) if a else np.zeros(shape, dtype=dt))
    kinds = slam.landmark_kinds
    cn, ln = kinds == CORNER, kinds == LINE
    return SlamRun(stamps=np.array(stamps, dtype=np.int64), poses=np.array(poses).reshape(-1, 3),
                   covariances=np.array(covs).reshape(-1, 3, 3), truth=truth,
                   odometry=np.array(odo_at).reshape(-1, 3),
                   obs_scan=cat(o_scan, (0,), np.int64),
                   obs_world_true=cat(o_world, (0, 2)), obs_status=cat(o_status, (0,), '<U9'),
                   obs_landmark=cat(o_lm, (0,), np.int64), nis=np.array(nis_v),
                   nis_dof=np.array(nis_d), landmark_ids=slam.landmark_ids[cn],
                   landmarks=slam.landmarks[cn],
                   landmark_covariances=slam.landmark_covariances[cn],
                   stats=dict(slam.stats), resets=fe.restarts, seconds=seconds,
                   reset_reasons={'odometry restart': fe.restarts} if fe.restarts else {},
                   events=events, scan_index=np.array(index, dtype=np.int64),
                   line_ids=slam.landmark_ids[ln], lines=slam.landmarks[ln],
                   line_ends=slam.line_ends[ln], final_map=slam.export_map(),
                   obs_world=cat(o_est, (0, 2)), bridged=np.array(bridged, dtype=bool),
                   motions=dict(fe.motions), icp_restarts=dict(fe.icp_restarts),
                   increments=np.array(incs, dtype=float).reshape(-1, 3))


def ellipse_share(run: SlamRun, probability: float = 0.95,
                  reference_sd: Optional[Tuple[float, float]] = None) -> float:
    """Share of steps whose reference position lies inside the filter's position ellipse.

    The ellipse is ``d^T P_xy^-1 d <= chi2_2(probability)`` with ``d`` the position error
    and ``P_xy`` the filter's 2 x 2 position covariance (the chapter's "error within 2
    sigma" in two dimensions); a step with a singular ``P_xy`` counts as inside only with
    zero error.

    A reference that is itself an estimate (the Radish "corrected" poses) has an error of
    its own, independent of the filter's: ``d`` is then the filter's error plus the
    reference's, and a filter whose covariance is right about its own error contains
    fewer than ``probability`` of the steps (with equal stds, about 78 % instead of 95 %).
    ``reference_sd = (along, across)`` [m], the reference's per-pose std along and across
    its heading (e.g. as ``benchmarks/reference_noise_carmen.py`` measures it), adds
    ``R(theta_ref) diag(along^2, across^2) R^T`` to ``P_xy``: the share then says whether
    the filter's covariance covers its own error. The default (None) is the plain test.

    Args:
        run: Output of :func:`run_slam` (with a reference).
        probability: Ellipse confidence.
        reference_sd: The reference's per-pose position std (along, across) [m], or None.

    Returns:
        The share in [0, 1].
    """
    d = run.poses[:, :2] - run.truth[:, :2]
    c = run.covariances[:, :2, :2]
    if reference_sd is not None:
        sa, sc = (float(v) for v in reference_sd)
        th = run.truth[:, 2]
        ux, uy = np.cos(th), np.sin(th)  # along the reference's heading; across: (-uy, ux)
        c = c + np.stack([np.stack([sa * sa * ux * ux + sc * sc * uy * uy,
                                    (sa * sa - sc * sc) * ux * uy], axis=-1),
                          np.stack([(sa * sa - sc * sc) * ux * uy,
                                    sa * sa * uy * uy + sc * sc * ux * ux], axis=-1)], axis=-2)
    a, b, e = c[:, 0, 0], 0.5 * (c[:, 0, 1] + c[:, 1, 0]), c[:, 1, 1]
    det = a * e - b * b
    with np.errstate(divide='ignore', invalid='ignore'):
        m2 = (e * d[:, 0] ** 2 - 2 * b * d[:, 0] * d[:, 1] + a * d[:, 1] ** 2) / det
    m2 = np.where(det > 0.0, m2, np.where(np.hypot(d[:, 0], d[:, 1]) == 0.0, 0.0, np.inf))
    return float(np.mean(m2 <= chi2_gate(2, probability)))


def update_corrections(run: SlamRun) -> np.ndarray:
    """Return what each step's update moved the pose: ``(-)(x_{k-1} (+) u_k) (+) x_k``.

    ``x_k`` the filter's pose after step k, ``u_k`` the motion step k predicted with
    (:attr:`SlamRun.increments`; eq. 25 composes it onto ``x_{k-1}``): the difference
    between the prediction and the estimate, in the predicted pose's frame. A filter that
    closes a loop moves the pose by the drift accumulated since the landmark was last
    seen; that move shows in the RPE of its trajectory, as the poses before it stay.

    Args:
        run: Output of :func:`run_slam`.

    Returns:
        (S, 3) ``[dx, dy, dpsi]`` per step (zeros for the first).
    """
    out = np.zeros((len(run.poses), 3))
    if len(run.poses) > 1:
        out[1:] = relative(compose(run.poses[:-1], run.increments[1:]), run.poses[1:])
    return out


_VISIBLE: Dict[tuple, Tuple[np.ndarray, np.ndarray]] = {}


def _visible_counts(result: ScenarioResult) -> Tuple[np.ndarray, np.ndarray]:
    """Return (true corner ids, scans in which each is scored) along the true path."""
    key = (result.name, result.laser, result.robot)  # the true path does not depend on the seed
    if key not in _VISIBLE:
        world = result.world
        counts = np.zeros(len(world.corners()), dtype=np.int64)
        mount = tuple(float(v) for v in result.laser.mount)
        for scan in result.of_type(ScanSample):
            if not np.any(np.isfinite(scan.ranges)):
                continue  # a blind scan (laser blackout) sees no corner
            ct = corner_truth(world, lambda s: sensor_pose(result.truth_at(s), mount),
                              scan.stamp_ns, scan_angles(scan), scan.time_increment,
                              min_range=scan.range_min, max_range=scan.range_max)
            counts += ct.scored
        _VISIBLE[key] = (world.corners().ids.copy(), counts)
    return _VISIBLE[key]


def true_visible_corners(result: ScenarioResult, min_scans: int) -> np.ndarray:
    """Ids of true corners scored in at least ``min_scans`` scans of the run.

    Args:
        result: The scenario run.
        min_scans: Scans in which a corner must be scored.

    Returns:
        (V,) corner ids.
    """
    ids, counts = _visible_counts(result)
    return ids[counts >= min_scans]


def _nearest(points: np.ndarray, targets: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Index of and distance to the nearest target of each point."""
    if points.shape[0] == 0 or targets.shape[0] == 0:
        return np.zeros(points.shape[0], dtype=np.int64), np.full(points.shape[0], np.inf)
    d = np.hypot(points[:, None, 0] - targets[None, :, 0],
                 points[:, None, 1] - targets[None, :, 1])
    j = np.argmin(d, axis=1)
    return j, d[np.arange(points.shape[0]), j]


def score_run(result: ScenarioResult, run: SlamRun, params: Optional[SlamParams] = None,
              match_distance: float = 0.15) -> SlamScore:
    """Score a run against the ground truth or a reference (module docstring).

    Args:
        result: The scenario run, or a :class:`~landmark_nav.evaluation.bags.BagScenario`;
            without a world (a real log) the landmark scores are NaN / None.
        run: Output of :func:`run_slam`.
        params: The filter parameters used (for ``confirm_hits``).
        match_distance: Largest distance of a landmark / observation to its true corner [m].

    Returns:
        The scores.
    """
    params = params or SlamParams()
    if not getattr(result, 'has_reference', True):
        return _score_without_reference(run)
    err = position_errors(run.poses, run.truth)
    oerr = position_errors(run.odometry, run.truth)
    assoc = np.isin(run.obs_status, ('matched', 'confirmed'))
    landmarks: Dict[str, Optional[float]] = {
        'landmark_rmse': math.nan, 'true_visible': None, 'ghost_landmarks': None,
        'duplicates': None, 'wrong_associations': None}
    if result.world is not None:
        truth = result.world.corners()
        j, d = _nearest(run.landmarks, truth.positions)
        good = d <= match_distance
        lm_true = np.where(good, truth.ids[j], -1)
        dup = len(lm_true[good]) - len(set(lm_true[good].tolist()))
        rmse = float(np.sqrt(np.mean(d[good] ** 2))) if np.any(good) else math.nan
        jo, do = _nearest(run.obs_world_true, truth.positions)
        obs_true = np.where(do <= match_distance, truth.ids[jo], -1)
        lut = dict(zip(run.landmark_ids.tolist(), lm_true.tolist()))
        lm_of_obs = np.array([lut.get(int(i), -1) for i in run.obs_landmark[assoc]],
                             dtype=np.int64)
        wrong = int(np.sum((lm_of_obs != obs_true[assoc]) | (obs_true[assoc] < 0)))
        landmarks = {'landmark_rmse': rmse,
                     'true_visible': int(true_visible_corners(result, params.confirm_hits).size),
                     'ghost_landmarks': int(np.sum(~good)), 'duplicates': int(dup),
                     'wrong_associations': wrong}
    ne = np.array([nees(t, p, c) for t, p, c in zip(run.truth, run.poses, run.covariances)])
    lo, hi = chi2_band(3, 0.95)
    dof = run.nis_dof
    return SlamScore(
        ate_rmse=float(np.sqrt(np.mean(err ** 2))), ate_max=float(err.max()),
        odom_ate_rmse=float(np.sqrt(np.mean(oerr ** 2))), odom_ate_max=float(oerr.max()),
        mapped=int(run.landmarks.shape[0]), associations=int(assoc.sum()),
        nees_share_band=float(np.mean((ne >= lo) & (ne <= hi))),
        nees_share_gate=float(np.mean(ne <= chi2_gate(3, 0.95))),
        mean_nees=float(np.mean(ne)),
        mean_nis_per_dof=float(run.nis[dof > 0].sum() / max(dof.sum(), 1)),
        psd_repairs=int(run.stats['psd_repairs']),
        ms_per_scan=1e3 * run.seconds / max(len(run.stamps), 1), **landmarks)


def _score_without_reference(run: SlamRun) -> SlamScore:
    """Scores of a bag without a reference: every error figure NaN / None, never guessed.

    The landmark scores need the true path too (the visible corners, the map frame), so they
    are None / NaN even with the simulator's world.
    """
    assoc = np.isin(run.obs_status, ('matched', 'confirmed'))
    dof = run.nis_dof
    return SlamScore(
        ate_rmse=math.nan, ate_max=math.nan, odom_ate_rmse=math.nan, odom_ate_max=math.nan,
        landmark_rmse=math.nan, mapped=int(run.landmarks.shape[0]), true_visible=None,
        ghost_landmarks=None, duplicates=None, associations=int(assoc.sum()),
        wrong_associations=None, nees_share_band=math.nan, nees_share_gate=math.nan,
        mean_nees=math.nan, mean_nis_per_dof=float(run.nis[dof > 0].sum() / max(dof.sum(), 1)),
        psd_repairs=int(run.stats['psd_repairs']),
        ms_per_scan=1e3 * run.seconds / max(len(run.stamps), 1))


def evaluate(name: str, seeds: List[int], params: Optional[SlamParams] = None,
             corner_params: Optional[CornerParams] = None) -> List[SlamScore]:
    """Simulate, run and score a scenario for several seeds.

    Args:
        name: Scenario name (e.g. ``'office'``).
        seeds: Seeds.
        params: Filter parameters.
        corner_params: Corner extractor parameters.

    Returns:
        One score per seed.
    """
    out = []
    for seed in seeds:
        res = run_scenario(name, seed, sonar=None)
        out.append(score_run(res, run_slam(res, params, corner_params), params))
    return out


def _scan_points(scenario, run: SlamRun, max_points: int = 200_000) -> np.ndarray:
    """(P, 2) scan end points in the map frame through the filter poses (a subsample)."""
    scans = scenario.of_type(ScanSample)
    n = sum(int(np.isfinite(s.ranges).sum()) for s in scans)
    step = max(1, int(math.ceil(n / max_points)))
    mount = tuple(float(v) for v in scenario.laser.mount)
    out = []
    index = run.scan_index if run.scan_index is not None else np.arange(len(run.poses))
    for k, i in enumerate(index):
        scan = scans[i]
        ok = np.isfinite(scan.ranges)
        if not np.any(ok):
            continue
        r = scan.ranges[ok].astype(float)
        a = scan_angles(scan)[ok]
        pts = np.column_stack([r * np.cos(a), r * np.sin(a)])[::step]
        out.append(transform_points(sensor_pose(run.poses[k], mount), pts))
    return np.concatenate(out) if out else np.zeros((0, 2))


def _save_plan(fig, ax, title: str, path: Path) -> None:
    """Finish a top view in metres (equal axes, labels, legend), write it and close it."""
    import matplotlib.pyplot as plt
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(title)
    ax.legend(loc='best', fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_run(scenario, run: SlamRun, out_dir: Path, title: str, align: str = ALIGN_DEFAULT
             ) -> List[str]:
    """Write the figures of a run; return their file names.

    * ``slam_map.png``: the scans' end points through the filter poses (the map over the
      scans), the mapped landmarks with 2-sigma ellipses and the filter path; with a world,
      also its walls and true corners (Fig. 19 of the chapter).
    * ``slam_trajectory.png``: filter and odometry paths against the reference after the
      ``align`` alignment (each aligned on its own, as the ATE is computed).
    * ``slam_errors.png``: x, y, heading error against the reference with the filter's
      +-2 sigma (unaligned, in the map frame).

    Without a reference (a bag's ``has_reference`` False) only ``slam_map.png``.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 7.5))
    pts = _scan_points(scenario, run)
    ax.plot(pts[:, 0], pts[:, 1], ',', color='0.55', alpha=0.6)
    ax.plot([], [], '.', color='0.55', label='scans through the EKF-SLAM poses')
    if scenario.world is not None:
        for x1, y1, x2, y2 in scenario.world.walls().segments:
            ax.plot([x1, x2], [y1, y2], color='0.3', lw=1.5)
        tc = scenario.world.corners().positions
        ax.plot(tc[:, 0], tc[:, 1], 'k+', ms=9, label='true corners')
    ax.plot(run.poses[:, 0], run.poses[:, 1], 'b-', lw=1, label='EKF-SLAM path')
    if run.landmarks.shape[0]:
        ax.plot(run.landmarks[:, 0], run.landmarks[:, 1], 'ro', mfc='none', ms=5,
                label='mapped landmarks (2 sigma)')
        for m, c in zip(run.landmarks, run.landmark_covariances):
            e = covariance_ellipse(m, c)
            ax.plot(e[:, 0], e[:, 1], 'r-', lw=0.8)
    _save_plan(fig, ax, title, out_dir / 'slam_map.png')
    if not getattr(scenario, 'has_reference', True):
        return ['slam_map.png']  # the other figures are against the reference

    ref = Trajectory.from_planar(run.stamps, run.truth)
    fig, ax = plt.subplots(figsize=(9, 7.5))
    ax.plot(run.truth[:, 0], run.truth[:, 1], 'g-', lw=1.2, label='reference')
    for poses, style, name in ((run.odometry, 'r:', 'odometry'), (run.poses, 'b-', 'EKF-SLAM')):
        try:
            _, est = aligned(Trajectory.from_planar(run.stamps, poses), ref, align)
        except ValueError:
            continue
        ax.plot(est[:, 0], est[:, 1], style, lw=1, label=f'{name} ({align} aligned)')
    _save_plan(fig, ax, title, out_dir / 'slam_trajectory.png')

    t = (run.stamps - run.stamps[0]) * 1e-9
    err = run.poses - run.truth
    err[:, 2] = np.angle(np.exp(1j * err[:, 2]))
    sig = np.sqrt(np.maximum(np.diagonal(run.covariances, axis1=1, axis2=2), 0.0))
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    scale = (100.0, 100.0, 180.0 / math.pi)
    for k, (ax, lab) in enumerate(zip(axes, ('x error [cm]', 'y error [cm]',
                                             'psi error [deg]'))):
        ax.plot(t, scale[k] * err[:, k], 'b-', lw=1, label='error')
        ax.plot(t, 2 * scale[k] * sig[:, k], 'r--', lw=0.8, label='+-2 sigma')
        ax.plot(t, -2 * scale[k] * sig[:, k], 'r--', lw=0.8)
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc='upper right', fontsize=8)
    axes[-1].set_xlabel('time [s]')
    axes[0].set_title(title)
    fig.tight_layout()
    fig.savefig(out_dir / 'slam_errors.png', dpi=120)
    plt.close(fig)
    return ['slam_map.png', 'slam_trajectory.png', 'slam_errors.png']


def _clean(v):
    return None if isinstance(v, float) and math.isnan(v) else v


def _path_length(poses: np.ndarray) -> float:
    return float(np.hypot(*np.diff(poses[:, :2], axis=0).T).sum()) if len(poses) > 1 else 0.0


def _add_figures_without_reference(result: dict, run: SlamRun, align: str,
                                   rpe_delta: float) -> None:
    """Fill ``result`` for a bag without a reference: error figures None, path figures."""
    for key in ('', 'odom_'):
        for k in STATISTICS + ('pairs', 'scale'):
            result[f'{key}ate_{align}_{k}'] = None
    result['rpe_distance_m'] = float(rpe_delta)
    for key in ('', 'odom_'):
        for k in STATISTICS:
            result[f'{key}rpe_trans_{k}'] = None
            result[f'{key}rpe_rot_{k}_deg'] = None
        result[f'{key}rpe_pairs'] = None
    result['ate_improvement'] = None
    d = run.poses - run.odometry
    dist = np.hypot(d[:, 0], d[:, 1])
    k = int(np.argmax(dist))
    result['path_length_m'] = _path_length(run.poses)
    result['odom_path_length_m'] = _path_length(run.odometry)
    result['max_slam_odom_difference_m'] = float(dist[k])
    result['max_slam_odom_difference_t_s'] = float((run.stamps[k] - run.stamps[0]) * 1e-9)
    result['max_slam_odom_heading_difference_deg'] = float(
        np.degrees(np.abs(np.angle(np.exp(1j * d[:, 2]))).max()))
    result['final_pose_covariance'] = run.covariances[-1].tolist()


def bag_odometry_noise(scenario) -> Tuple[OdometryNoise, str]:
    """Odometry noise model of a bag (:mod:`landmark_nav.slam.frontend`) and its source.

    The imported-bag contract's ``custom_data`` key ``landmark_nav.drift_model`` when present
    (the gains the importer drifted the odometry with), else ``simulator`` for a simulator
    recording, else ``pioneer``.

    Raises:
        ValueError: A malformed drift model (names the bag and the key).
    """
    text = getattr(scenario, 'custom_data', {}).get(DRIFT_KEY)
    if text is not None:
        try:
            return odometry_noise_model(text), f'custom_data {DRIFT_KEY}'
        except ValueError as err:
            raise ValueError(f'{scenario.name}: custom_data {DRIFT_KEY}: {err}') from None
    if getattr(scenario, 'simulator', True):
        return odometry_noise_model('simulator'), 'simulator'
    return odometry_noise_model('pioneer'), 'default pioneer'


def evaluate_bag(bag, association: str = 'icnn', out_dir=None, progress: bool = True,
                 params: Optional[SlamParams] = None, max_seconds: Optional[float] = None,
                 reference=None, align: str = ALIGN_DEFAULT,
                 laser_pose: Optional[Sequence[float]] = None, sigma_r: Optional[float] = None,
                 rpe_delta: float = RPE_DISTANCE_M, plots: bool = True,
                 landmarks: str = 'corners', slam_map=None, save_map_to=None,
                 map_pose_covariance: Optional[np.ndarray] = None,
                 mode: Optional[str] = None,
                 frontend: Optional[FrontendParams] = None) -> dict:
    """Run EKF-SLAM over a bag and score it against its reference.

    Any bag with ``/scan``, ``/odom`` and a reference (``/ground_truth/odom`` or
    ``reference``, a TUM file) will do (:func:`landmark_nav.evaluation.bags.load_bag`);
    the landmark scores need the simulator's ``ground_truth.yaml`` and are None without it.

    Figures (``slam.json``): the :class:`SlamScore` fields (``ate_rmse`` / ``ate_max``:
    unaligned, in the map frame, as the README's office table); ``ate_<align>_<stat>`` and
    ``odom_ate_<align>_<stat>`` with the chosen alignment; ``rpe_trans_<stat>``,
    ``rpe_rot_<stat>_deg``, ``rpe_pairs`` and the ``odom_`` equivalents over ``rpe_delta`` m
    (:mod:`landmark_nav.evaluation.trajectory`: evo's metrics); ``resets`` (filter resets
    after failed odometry checks); timing; the laser facts used and ``notes``.

    Args:
        bag: rosbag2 directory.
        association: ``'icnn'`` or ``'jcbb'``.
        out_dir: Directory for the TUM files, ``slam.json`` and the PNGs (None: nothing
            written).
        progress: Show a tqdm progress bar.
        params: Filter parameters (default :class:`SlamParams` with the bag's odometry noise
            model, :func:`bag_odometry_noise`; ``association`` and ``mode`` win).
        max_seconds: Use only the first seconds of the bag.
        reference: TUM file of the reference (None: ``/ground_truth/odom``).
        align: ATE alignment, one of :data:`~landmark_nav.evaluation.trajectory.ALIGNMENTS`.
        laser_pose: ``(x, y, yaw)`` laser mount when the bag does not state it.
        sigma_r: Laser range noise [m] when the bag does not state it.
        rpe_delta: RPE distance [m].
        plots: Write the PNGs (with ``out_dir``).
        landmarks: ``'corners'``, ``'lines'`` or ``'both'`` (what the filter maps).
        slam_map: A saved map (path or :class:`~landmark_nav.slam.slam_map.SlamMap`) to
            start on (e.g. with ``params.mode == 'localization'``); the start pose is the
            first odometry pose, with ``map_pose_covariance`` (default zeros).
        save_map_to: Write the final map there (:func:`landmark_nav.slam.slam_map.save_map`).
        map_pose_covariance: (3, 3) covariance of the start pose on ``slam_map``.
        mode: ``'slam'`` or ``'localization'`` (on ``slam_map``); None: ``params.mode``.
        frontend: Front-end parameters (e.g. ``scan_matching``; default
            :class:`FrontendParams`; ``deskew`` and ``descriptors`` are :func:`run_slam`'s
            defaults whatever it says).

    Returns:
        The figures (see ``slam.json``).

    Raises:
        ValueError: Bad option or unusable bag (one-line message).
    """
    if association not in ASSOCIATIONS:
        raise ValueError(f'association must be one of {", ".join(ASSOCIATIONS)}, '
                         f'got {association!r}')
    if align not in ALIGNMENTS:
        raise ValueError(f'align must be one of {", ".join(ALIGNMENTS)}, got {align!r}')
    scenario = load_bag(bag, max_seconds, reference, laser_pose, sigma_r,
                        require_reference=False)
    prm = params or SlamParams()
    prm = SlamParams(**{**{f.name: getattr(prm, f.name) for f in fields(SlamParams)},
                        'association': association, 'mode': mode or prm.mode})
    if prm.mode == 'localization' and slam_map is None:
        raise ValueError('mode localization needs a map (slam_map: a file saved with '
                         'save_map_to / --save-map)')
    noise_source = 'params'
    if params is None:
        noise, noise_source = bag_odometry_noise(scenario)
        prm = replace(prm, odometry=noise)
        if noise_source.startswith('default'):
            scenario.notes.append('no odometry noise model in the bag (custom_data '
                                  f'{DRIFT_KEY}): using the pioneer model')
    corner_params = CornerParams(sigma_r=float(scenario.laser.sigma_range),
                                 sigma_phi=float(scenario.laser.sigma_angle))
    n_scans = len(scenario.of_type(ScanSample))
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n_scans, unit='scan', desc=f'{Path(bag).name} {association}')
    callback = None if bar is None else (lambda k, slam, res: bar.update(1))
    tic = time.perf_counter()
    try:
        if slam_map is not None and not isinstance(slam_map, SlamMap):
            slam_map = load_map(slam_map)
        run = run_slam(scenario, prm, corner_params, callback=callback, landmarks=landmarks,
                       slam_map=slam_map, map_pose_covariance=map_pose_covariance,
                       frontend=frontend)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - tic
    score = score_run(scenario, run, prm)
    duration = (run.stamps[-1] - run.stamps[0]) * 1e-9 + scenario.scan_period
    result = {'bag': str(bag), 'association': association, 'scans': int(len(run.stamps)),
              'duration_s': float(duration), 'resets': int(run.resets),
              'reset_reasons': dict(run.reset_reasons),
              'frontend_events': dict(run.events),
              'motions': dict(run.motions),
              'icp_restarts': dict(run.icp_restarts),
              'odometry_noise': {**asdict(prm.odometry), 'source': noise_source},
              'reference': scenario.reference, 'simulator_truth': scenario.world is not None,
              'laser_mount': [float(v) for v in scenario.laser.mount],
              'laser_sigma_range': float(scenario.laser.sigma_range),
              'landmarks': landmarks, 'mode': prm.mode}
    result.update({k: _clean(v) for k, v in asdict(score).items()})
    result['lines_mapped'] = int(run.lines.shape[0])
    if scenario.has_reference:
        result['ellipse95_share'] = ellipse_share(run)
    if save_map_to is not None and run.final_map is not None:
        result['map_file'] = str(save_map(save_map_to, run.final_map))
    est = {'': Trajectory.from_planar(run.stamps, run.poses),
           'odom_': Trajectory.from_planar(run.stamps, run.odometry)}
    result['align'] = align
    if scenario.has_reference:
        ref = Trajectory.from_planar(run.stamps, run.truth)
        for key, traj in est.items():
            for k, v in ate(traj, ref, align).items():
                result[f'{key}ate_{align}_{k}'] = v
        result['rpe_distance_m'] = float(rpe_delta)
        for key, traj in est.items():
            r = rpe(traj, ref, rpe_delta)
            for k, v in r.items():
                name = k if k.startswith('rot_') or k == 'pairs' else f'trans_{k}'
                result[f'{key}rpe_{name}'] = _clean(v)
        result['ate_improvement'] = (score.odom_ate_rmse / score.ate_rmse
                                     if score.ate_rmse > 0 else None)
    else:
        _add_figures_without_reference(result, run, align, rpe_delta)
    result['seconds_total'] = float(wall)
    result['ms_per_step_total'] = 1e3 * wall / max(len(run.stamps), 1)
    result['real_time_factor'] = float(duration / wall) if wall > 0 else None
    result['filter_real_time_factor'] = (float(duration / run.seconds) if run.seconds > 0
                                         else None)
    result['stats'] = {k: int(v) for k, v in run.stats.items()}
    result['notes'] = list(scenario.notes)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_tum(out / 'trajectory_slam.tum', est[''])
        write_tum(out / 'trajectory_odom.tum', est['odom_'])
        if scenario.has_reference:
            write_tum(out / 'trajectory_gt.tum', ref)
        (out / 'slam.json').write_text(json.dumps(result, indent=2))
        if plots and not scenario.has_reference:
            plot_run(scenario, run, out, f'EKF-SLAM ({association}) on {Path(bag).name}\n'
                     f'{score.mapped} landmarks, {run.resets} resets (no reference)', align)
        elif plots:
            plot_run(scenario, run, out, f'EKF-SLAM ({association}) on {Path(bag).name}\nATE '
                     f'{100 * score.ate_rmse:.1f} cm ({align} aligned '
                     f'{100 * result[f"ate_{align}_rmse"]:.1f} cm), odometry '
                     f'{100 * score.odom_ate_rmse:.1f} cm, {run.resets} resets', align)
    return result


def _lines_without_reference(r: dict) -> List[str]:
    """Render the summary lines of a run without a reference (what needs none)."""
    sd = np.sqrt(np.maximum(np.diag(np.asarray(r['final_pose_covariance'])), 0.0))
    rtf = r['real_time_factor']
    return [
        'note: no reference trajectory: ATE, RPE and NEES need one (--reference FILE.tum or '
        '/ground_truth/odom in the bag); judge the map in slam_map.png',
        f'landmarks: {r["mapped"]} mapped; associations {r["associations"]}',
        f'path length: EKF-SLAM {r["path_length_m"]:.2f} m, odometry '
        f'{r["odom_path_length_m"]:.2f} m; largest EKF-SLAM vs odometry difference '
        f'{r["max_slam_odom_difference_m"]:.3f} m (at {r["max_slam_odom_difference_t_s"]:.1f} '
        f's), heading {r["max_slam_odom_heading_difference_deg"]:.2f} deg',
        f'final pose 1 sigma: x {100 * sd[0]:.2f} cm, y {100 * sd[1]:.2f} cm, psi '
        f'{np.degrees(sd[2]):.3f} deg (covariance in slam.json)',
        f'filter {r["ms_per_scan"]:.2f} ms/step, total {r["ms_per_step_total"]:.2f} ms/step, '
        f'real-time factor {"n/a" if rtf is None else f"{rtf:.0f}"}x']


def format_summary(r: dict) -> str:
    """Render the main figures as a few lines of text."""
    def cm(v):
        return 'n/a' if v is None else f'{100 * v:.2f} cm'

    def num(v, fmt='{}'):
        return 'n/a' if v is None else fmt.format(v)
    a = r['align']
    why = ', '.join(f'{k}: {v}' for k, v in sorted(r.get('reset_reasons', {}).items()))
    events = ', '.join(f'{v} {k}' for k, v in sorted(r.get('frontend_events', {}).items()))
    lines = [f'{r["bag"]} ({r["association"]}): {r["scans"]} scans, {r["duration_s"]:.1f} s, '
             f'reference {r["reference"] or "none"}, {r["resets"]} filter resets'
             + (f' ({why})' if why else '')
             + (f'; inputs not used as they came: {events}' if events else '')]
    motions = r.get('motions', {})
    if motions.get('scan_matching'):
        restarts = r.get('icp_restarts', {})
        lines.append(f'motion: {motions["scan_matching"]} steps scan-matched, '
                     f'{motions.get("odometry", 0)} odometry (ICP restarted from other '
                     f'headings on {restarts.get("restarted", 0)} steps, usable after '
                     f'{restarts.get("recovered", 0)})')
    lines += [f'note: {n}' for n in r.get('notes', [])]
    if r['reference'] is None:
        return '\n'.join(lines + _lines_without_reference(r))
    lines += [
        f'ATE RMSE {cm(r["ate_rmse"])} (max {cm(r["ate_max"])}); odometry '
        f'{cm(r["odom_ate_rmse"])} (max {cm(r["odom_ate_max"])})',
        f'ATE {a} aligned: RMSE {cm(r[f"ate_{a}_rmse"])} (mean {cm(r[f"ate_{a}_mean"])}, '
        f'median {cm(r[f"ate_{a}_median"])}, max {cm(r[f"ate_{a}_max"])}); odometry RMSE '
        f'{cm(r[f"odom_ate_{a}_rmse"])}',
        f'RPE over {r["rpe_distance_m"]:g} m ({r["rpe_pairs"]} pairs): '
        f'{cm(r["rpe_trans_rmse"])} / {num(r["rpe_rot_rmse_deg"], "{:.2f}")} deg (odometry '
        f'{cm(r["odom_rpe_trans_rmse"])} / {num(r["odom_rpe_rot_rmse_deg"], "{:.2f}")} deg)']
    if r['true_visible'] is not None:
        lines.append(
            f'landmarks: {r["mapped"]} mapped / {r["true_visible"]} true visible, RMSE '
            f'{cm(r["landmark_rmse"])}, ghosts {r["ghost_landmarks"]}, duplicates '
            f'{r["duplicates"]}')
        lines.append(f'associations {r["associations"]}, wrong {r["wrong_associations"]}; '
                     f'NEES in 95 % band {100 * r["nees_share_band"]:.1f} %')
    else:
        lines.append(f'landmarks: {r["mapped"]} mapped (no true corners: not a simulator bag); '
                     f'associations {r["associations"]}; NEES against the reference in the '
                     f'95 % band {100 * r["nees_share_band"]:.1f} %')
    if r.get('lines_mapped') or r.get('landmarks', 'corners') != 'corners':
        share = r.get('ellipse95_share')
        lines.append(f'landmark types {r.get("landmarks")}: {r["mapped"]} corners, '
                     f'{r.get("lines_mapped", 0)} lines; reference inside the 95 % position '
                     f'ellipse {"n/a" if share is None else f"{100 * share:.1f} %"} of steps')
    lines.append(f'filter {r["ms_per_scan"]:.2f} ms/step, total {r["ms_per_step_total"]:.2f} '
                 f'ms/step, real-time factor {num(r["real_time_factor"], "{:.0f}")}x')
    return '\n'.join(lines)


__all__ = ['ALIGN_DEFAULT', 'ASSOCIATIONS', 'bag_odometry_noise', 'DRIFT_KEY', 'ellipse_share',
           'evaluate', 'evaluate_bag', 'format_summary', 'plot_run', 'RPE_DISTANCE_M',
           'run_slam', 'scan_angles', 'scan_corners', 'scan_features', 'score_run', 'SlamRun',
           'SlamScore', 'true_visible_corners', 'update_corrections']
