"""Score an EKF-SLAM run (:class:`~.slam_run.SlamRun`) against the truth or a reference.

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

from dataclasses import dataclass
import math
from typing import Dict, Optional, Tuple

from landmark_nav.evaluation.features import corner_truth
from landmark_nav.evaluation.slam_run import scan_angles, SlamRun
from landmark_nav.evaluation.trajectory import position_errors
from landmark_nav.geometry import compose, relative
from landmark_nav.sim import ScanSample, ScenarioResult
from landmark_nav.sim.laser import compose as sensor_pose
from landmark_nav.slam.consistency import chi2_band, chi2_gate, nees
from landmark_nav.slam.ekf_slam import SlamParams
import numpy as np

#: Default ATE alignment of ``evaluate`` (the unaligned ATE is always reported too).
ALIGN_DEFAULT = 'se2'
#: Default RPE distance [m].
RPE_DISTANCE_M = 1.0


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
    its heading (e.g. as ``benchmarks/reference_noise_carmen.py`` of commit 67eb6cc measured
    it), adds ``R(theta_ref) diag(along^2, across^2) R^T`` to ``P_xy``: the share then says whether
    the filter's covariance covers its own error. The default (None) is the plain test.

    Args:
        run: Output of :func:`.slam_run.run_slam` (with a reference).
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
    (:attr:`SlamRun.increments`; eq. 25 composes it onto ``x_{k-1}``, with keyframes onto
    the last keyframe's pose): the difference between the prediction and the estimate, in
    the predicted pose's frame (0 between keyframes). A filter that
    closes a loop moves the pose by the drift accumulated since the landmark was last
    seen; that move shows in the RPE of its trajectory, as the poses before it stay.

    Args:
        run: Output of :func:`.slam_run.run_slam`.

    Returns:
        (S, 3) ``[dx, dy, dpsi]`` per step (zeros for the first).
    """
    n = len(run.poses)
    out = np.zeros((n, 3))
    if n > 1:
        key = run.keyframe if len(run.keyframe) == n else np.ones(n, dtype=bool)
        # The step each one predicted from: the previous step's keyframe (itself or earlier).
        last = np.maximum.accumulate(np.where(key, np.arange(n), 0))
        out[1:] = relative(compose(run.poses[last[:-1]], run.increments[1:]), run.poses[1:])
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
        run: Output of :func:`.slam_run.run_slam`.
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


__all__ = ['ALIGN_DEFAULT', 'ellipse_share', 'RPE_DISTANCE_M', 'score_run', 'SlamScore',
           'true_visible_corners', 'update_corrections']
