"""Run :class:`~.ekf_slam.EkfSlam` on a simulated scenario and score it against ground truth.

Pipeline per :class:`~landmark_nav.sim.ScanSample` (time order): the odometry is linearly
interpolated to the scan stamp (:func:`landmark_nav.geometry.interpolate_pose`), checked
(:func:`~.ekf_slam.odometry_check`; a failed check resets the filter) and turned into the
increment of eq. 13 for :meth:`~.ekf_slam.EkfSlam.predict`; the scan's corners
(:func:`~landmark_nav.laser.corners.extract_corners` on ``angle_min + i * increment``,
``valid = isfinite``) go through the laser mount and, with ``deskew``, through the odometry
motion between the scan stamp and each corner's beam time (``stamp + index *
time_increment``) into :func:`~.observations.corners_to_observations` and
:meth:`~.ekf_slam.EkfSlam.update`. The estimate is for the scan stamp.

Scores (:func:`score_run`), all in the map frame, which is the world frame because the map
is initialised at the first odometry pose (odom == world at the start):

* ATE: robot position error ``|p_est - p_true|`` at the scan stamps (RMSE and max), the
  same for odometry alone.
* Landmarks: every mapped landmark is paired with its nearest true corner at the end of
  the run; ``landmark_rmse`` is the RMSE of those distances over landmarks whose nearest
  corner is within ``match_distance`` (the others count as ``ghost_landmarks``); a true
  corner claimed by two landmarks adds a ``duplicate``.
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

from dataclasses import dataclass
import math
import time
from typing import Callable, Dict, List, Optional, Tuple

from landmark_nav.evaluation.features import corner_truth
from landmark_nav.geometry import interpolate_pose, relative, transform_points
from landmark_nav.laser.corners import CornerParams, extract_corners
from landmark_nav.sim import OdometrySample, run_scenario, ScanSample, ScenarioResult
from landmark_nav.sim.laser import compose as sensor_pose
import numpy as np

from .consistency import chi2_band, chi2_gate, nees
from .ekf_slam import EkfSlam, odometry_check, odometry_increment, SlamParams, UpdateResult
from .observations import corner_descriptors, corners_to_observations


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


@dataclass(frozen=True)
class SlamScore:
    """Scores of one run (see the module docstring)."""

    ate_rmse: float
    ate_max: float
    odom_ate_rmse: float
    odom_ate_max: float
    landmark_rmse: float
    mapped: int
    true_visible: int
    ghost_landmarks: int
    duplicates: int
    associations: int
    wrong_associations: int
    nees_share_band: float
    nees_share_gate: float
    mean_nees: float
    mean_nis_per_dof: float
    psd_repairs: int
    ms_per_scan: float


def scan_angles(scan: ScanSample) -> np.ndarray:
    """Return the (N,) beam angles ``angle_min + i * angle_increment`` of a scan."""
    return scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))


def run_slam(result: ScenarioResult, params: Optional[SlamParams] = None,
             corner_params: Optional[CornerParams] = None, deskew: bool = True,
             descriptors: bool = True,
             callback: Optional[Callable[[int, EkfSlam, UpdateResult], None]] = None
             ) -> SlamRun:
    """Run the filter over a simulated scenario (module docstring).

    Args:
        result: Output of :func:`landmark_nav.sim.run_scenario` (with a laser).
        params: Filter parameters.
        corner_params: Corner extractor parameters.
        deskew: Compensate the motion during the laser sweep with odometry.
        descriptors: Pass the corners' bisector / opening to the association.
        callback: Called as ``callback(scan index, filter, update result)`` after each scan.

    Returns:
        The per-scan record.
    """
    odo = result.of_type(OdometrySample)
    scans = result.of_type(ScanSample)
    ot = np.array([o.stamp_ns for o in odo], dtype=np.int64)
    op = np.array([o.pose for o in odo])
    t0 = ot[0]
    ots = (ot - t0) * 1e-9
    mount = np.asarray(result.laser.mount, dtype=float)
    slam = EkfSlam(params, initial_pose=op[0])
    prm = slam.params
    prev_t, prev_pose = int(ot[0]), op[0]
    stamps = np.array([s.stamp_ns for s in scans], dtype=np.int64)
    odo_at = interpolate_pose((stamps - t0) * 1e-9, ots, op)
    truth = result.truth_at(stamps)
    poses, covs, nis_v, nis_d = [], [], [], []
    o_scan, o_world, o_status, o_lm = [], [], [], []
    resets = 0
    seconds = 0.0
    for k, scan in enumerate(scans):
        corners = extract_corners(scan.ranges, scan_angles(scan), np.isfinite(scan.ranges),
                                  scan.angle_increment, corner_params)
        motion = None
        if deskew and corners:
            tb = (scan.stamp_ns - t0) * 1e-9 + scan.time_increment * np.array(
                [c.index for c in corners], dtype=float)
            motion = relative(odo_at[k], interpolate_pose(tb, ots, op, extrapolate=True))
        z, r = corners_to_observations(corners, mount, motion)
        desc = corner_descriptors(corners, mount, motion) if descriptors else None
        tic = time.perf_counter()
        bad = odometry_check(prev_t, prev_pose, int(scan.stamp_ns), odo_at[k],
                             prm.max_odometry_jump_m, prm.max_odometry_jump_rad)
        if bad is not None:
            slam.reset(odo_at[k])
            resets += 1
        else:
            slam.predict(odometry_increment(prev_pose, odo_at[k]))
        res: UpdateResult = slam.update(z, r, desc)
        seconds += time.perf_counter() - tic
        prev_t, prev_pose = int(scan.stamp_ns), odo_at[k]
        if callback is not None:
            callback(k, slam, res)
        poses.append(slam.pose)
        covs.append(slam.pose_covariance)
        nis_v.append(res.nis)
        nis_d.append(res.nis_dof)
        if len(corners):
            lp = np.array([c.position for c in corners]).reshape(-1, 2)
            beam_ns = scan.stamp_ns + np.rint(np.array([c.index for c in corners])
                                              * scan.time_increment * 1e9).astype(np.int64)
            beam_ns = np.minimum(beam_ns, result.end_ns)
            o_world.append(transform_points(sensor_pose(result.truth_at(beam_ns), tuple(mount)),
                                            lp))
            o_scan.append(np.full(len(corners), k))
            o_status.append(res.status)
            o_lm.append(res.landmark_id)
    cat = (lambda a, shape, dt=float: np.concatenate(a) if a else np.zeros(shape, dtype=dt))
    return SlamRun(stamps=stamps, poses=np.array(poses), covariances=np.array(covs),
                   truth=truth, odometry=odo_at, obs_scan=cat(o_scan, (0,), np.int64),
                   obs_world_true=cat(o_world, (0, 2)), obs_status=cat(o_status, (0,), '<U9'),
                   obs_landmark=cat(o_lm, (0,), np.int64), nis=np.array(nis_v),
                   nis_dof=np.array(nis_d), landmark_ids=slam.landmark_ids,
                   landmarks=slam.landmarks, landmark_covariances=slam.landmark_covariances,
                   stats=dict(slam.stats), resets=resets, seconds=seconds)


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
    """Score a run against the ground truth (module docstring).

    Args:
        result: The scenario run.
        run: Output of :func:`run_slam`.
        params: The filter parameters used (for ``confirm_hits``).
        match_distance: Largest distance of a landmark / observation to its true corner [m].

    Returns:
        The scores.
    """
    params = params or SlamParams()
    truth = result.world.corners()
    err = np.hypot(*(run.poses[:, :2] - run.truth[:, :2]).T)
    oerr = np.hypot(*(run.odometry[:, :2] - run.truth[:, :2]).T)
    j, d = _nearest(run.landmarks, truth.positions)
    good = d <= match_distance
    lm_true = np.where(good, truth.ids[j], -1)
    dup = len(lm_true[good]) - len(set(lm_true[good].tolist()))
    rmse = float(np.sqrt(np.mean(d[good] ** 2))) if np.any(good) else math.nan
    jo, do = _nearest(run.obs_world_true, truth.positions)
    obs_true = np.where(do <= match_distance, truth.ids[jo], -1)
    assoc = np.isin(run.obs_status, ('matched', 'confirmed'))
    lut = dict(zip(run.landmark_ids.tolist(), lm_true.tolist()))
    lm_of_obs = np.array([lut.get(int(i), -1) for i in run.obs_landmark[assoc]], dtype=np.int64)
    wrong = int(np.sum((lm_of_obs != obs_true[assoc]) | (obs_true[assoc] < 0)))
    ne = np.array([nees(t, p, c) for t, p, c in zip(run.truth, run.poses, run.covariances)])
    lo, hi = chi2_band(3, 0.95)
    dof = run.nis_dof
    return SlamScore(
        ate_rmse=float(np.sqrt(np.mean(err ** 2))), ate_max=float(err.max()),
        odom_ate_rmse=float(np.sqrt(np.mean(oerr ** 2))), odom_ate_max=float(oerr.max()),
        landmark_rmse=rmse, mapped=int(run.landmarks.shape[0]),
        true_visible=int(true_visible_corners(result, params.confirm_hits).size),
        ghost_landmarks=int(np.sum(~good)), duplicates=int(dup),
        associations=int(assoc.sum()), wrong_associations=wrong,
        nees_share_band=float(np.mean((ne >= lo) & (ne <= hi))),
        nees_share_gate=float(np.mean(ne <= chi2_gate(3, 0.95))),
        mean_nees=float(np.mean(ne)),
        mean_nis_per_dof=float(run.nis[dof > 0].sum() / max(dof.sum(), 1)),
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


__all__ = ['evaluate', 'run_slam', 'scan_angles', 'score_run', 'SlamRun', 'SlamScore',
           'true_visible_corners']
