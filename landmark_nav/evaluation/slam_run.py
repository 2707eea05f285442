"""Run :class:`~landmark_nav.slam.ekf_slam.EkfSlam` on a scenario and record every step.

Pipeline: the scenario's odometry samples and scans go, in time order, through
:class:`~landmark_nav.slam.frontend.SlamFrontend`, the front end the ``ekf_slam`` node uses
(odometry checks judged against elapsed time and noise, bridging, interpolation to the scan
stamp, the increment of eq. 13 for :meth:`~landmark_nav.slam.ekf_slam.EkfSlam.predict`,
de-skew of each feature by the odometry motion up to its beam time). Each scan's features
(:func:`scan_features`: corners and / or lines, ``landmarks``, on ``angle_min + i *
increment`` with REP 117 validity) and its geometry (visibility-aware pruning) go with it
to :meth:`~landmark_nav.slam.ekf_slam.EkfSlam.update`. The estimate is for the scan stamp.

The record (:class:`SlamRun`) is scored by :mod:`landmark_nav.evaluation.slam_scores`.
"""

from dataclasses import dataclass, field, replace
from functools import partial
import time
from typing import Callable, Dict, Optional, Tuple

from landmark_nav.conversions import classify_ranges
from landmark_nav.evaluation.blas import single_threaded
from landmark_nav.geometry import transform_points
from landmark_nav.laser.corners import CornerParams
from landmark_nav.laser.lines import LineParams
from landmark_nav.sim import OdometrySample, ScanSample, ScenarioResult
from landmark_nav.sim.laser import compose as sensor_pose
from landmark_nav.slam.ekf_slam import CORNER, EkfSlam, LINE, SlamParams, UpdateResult
from landmark_nav.slam.features import check_landmarks, extract_scan_features, scan_lines
from landmark_nav.slam.frontend import Corners, FrontendParams, SlamFrontend, Step
from landmark_nav.slam.slam_map import SlamMap
from landmark_nav.slam.visibility import ScanGeometry
import numpy as np


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
    #: ``SlamFrontend.keyframes``: steps that reached the filter (``keyframes``) and steps
    #: between keyframes (``skipped``: pose from the odometry, no update).
    keyframes: Dict[str, int] = field(default_factory=dict)
    #: (S, 3) the motion each step predicted with (the odometry increment, or the
    #: scan-matched / fused motion), so ``relative(compose(poses[k-1], increments[k]),
    #: poses[k])`` is what step k's update moved the pose (eq. 25; after a restart the
    #: first pose is the odometry's).
    increments: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    #: (S,) whether the step was a keyframe (``Step.keyframe``: else ``increments`` is the
    #: odometry's since the last keyframe and the filter did not change).
    keyframe: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))


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


class ScanFeatureCache:
    """The features of one scenario's scans, extracted once for several runs on it.

    Runs that differ only in the filter (e.g. the association method) see the same
    features: ``cache = ScanFeatureCache(result)`` and ``run_slam(result, ...,
    features=cache)`` for each run extract each scan's features (:func:`scan_features`)
    once per landmark types and extractor parameters, and hand every run the same
    (immutable) corners and lines.
    """

    def __init__(self, result: ScenarioResult) -> None:
        """Keep the features of ``result``'s scans."""
        self.result = result
        self._features: Dict[tuple, Tuple[list, list]] = {}

    def get(self, k: int, scan: ScanSample, landmarks: str,
            corner_params: Optional[CornerParams] = None,
            line_params: Optional[LineParams] = None) -> Tuple[list, list]:
        """Return :func:`scan_features` of ``scan``, the ``k``-th scan of the scenario."""
        key = (k, landmarks, corner_params, line_params)
        got = self._features.get(key)
        if got is None:
            got = self._features[key] = scan_features(scan, landmarks, corner_params,
                                                      line_params)
        return got


@single_threaded
def run_slam(result: ScenarioResult, params: Optional[SlamParams] = None,
             corner_params: Optional[CornerParams] = None, deskew: bool = True,
             descriptors: bool = True,
             callback: Optional[Callable[[int, EkfSlam, UpdateResult], None]] = None,
             frontend: Optional[FrontendParams] = None, landmarks: str = 'corners',
             line_params: Optional[LineParams] = None, visibility: bool = True,
             slam_map: Optional[SlamMap] = None,
             map_pose_covariance: Optional[np.ndarray] = None,
             features: Optional[ScanFeatureCache] = None) -> SlamRun:
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
        features: The scans' features kept for other runs on ``result``
            (:class:`ScanFeatureCache`); by default each run extracts its own.

    Returns:
        The per-scan record.

    Raises:
        ValueError: ``frontend.scan_matching`` without ``visibility`` (it needs the scan);
            ``features`` kept for another scenario.
    """
    check_landmarks(landmarks)
    if features is not None and features.result is not result:
        raise ValueError('run_slam: features is the ScanFeatureCache of another scenario')
    extract = features.get if features is not None else (
        lambda k, scan, *args: scan_features(scan, *args))
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
    bridged, incs, keyframe = [], [], []
    lazy_lines = fp.keyframe.enabled and landmarks != 'corners'

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
        keyframe.append(st.keyframe)
        bridged.append(bool(np.any(np.asarray(st.bridged_variance) > 0.0)))
        nis_v.append(st.result.nis)
        nis_d.append(st.result.nis_dof)
        scan, corners = pending.pop(k)
        if len(corners) and st.keyframe:  # a set between keyframes went to no update
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
            if lazy_lines:  # extracted for the keyframes only
                corners = (extract(scan_k, ev, 'corners', corner_params)[0]
                           if landmarks == 'both' else [])
                segs = ()
            else:
                corners, segs = extract(scan_k, ev, landmarks, corner_params, line_params)
            pending[scan_k] = (ev, corners)
            geometry = None
            if visibility:
                geometry = ScanGeometry(np.asarray(ev.ranges, dtype=float), ev.angle_min,
                                        ev.angle_increment, ev.range_min, ev.range_max,
                                        mount, sigma_laser)
            tic = time.perf_counter()
            features = Corners.from_corners(
                ev.stamp_ns, corners, ev.time_increment, segs,
                None if line_params is None else line_params.sigma_r, geometry)
            if lazy_lines:
                features = replace(features, lines_from=partial(
                    scan_lines, ev.ranges, scan_angles(ev), classify_ranges(
                        ev.ranges, ev.range_min, ev.range_max)[0], ev.angle_increment,
                    ev.time_increment, line_params),
                    lines_until=ev.time_increment * max(len(ev.ranges) - 1, 0))
            fe.add_features(features, scan_k)
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
                   keyframes=dict(fe.keyframes),
                   increments=np.array(incs, dtype=float).reshape(-1, 3),
                   keyframe=np.array(keyframe, dtype=bool))


__all__ = ['run_slam', 'scan_angles', 'scan_corners', 'scan_features', 'ScanFeatureCache',
           'SlamRun']
