"""Score corner and line detections against the simulator's ground truth.

Per scan, the ground truth visible to the laser is derived from the world and the true
sensor pose by casting the scan's beams without noise (:func:`visible_truth`):

* A true corner is *scored* when it is visible from the sensor with both of its faces in
  view (:meth:`World.visible_corners` with ``both_sides``, inside the field of view and
  ``min_range`` .. ``max_range`` away), its corner angle (the smaller of the free-space
  opening and the wall-side angle: 90 deg for a room corner and for a box corner) is in
  the corner class (70-110 deg), and on each side of the corner's beam the noise-free
  scan hits that arm's wall with at least ``min_arm_beams`` consecutive beams at an
  incidence below ~78 deg (a face seen edge-on gives a visible corner that no window
  detector can see). Corners are expressed in the laser pose at the time their beam was
  taken (the robot moves during the sweep).
* A true wall is *visible* with the extent between its outermost hit points.

Matching (:func:`score_corners`, :func:`score_lines`):

* Corners: each detection goes to its nearest true corner (any angle). Farther than
  ``match_distance`` it is a *ghost*; nearest to a corner outside the class (e.g. a 135 deg
  chamfer) it is *wrong*; a second detection of a matched corner is a *duplicate*; a
  detection of an unscored class corner (out of range, an arm too short) is *ignored*.
  Precision = true positives / (true positives + ghosts + wrong + duplicates); recall =
  true positives / scored corners; the position error is over true positives.
* Lines (Nguyen et al. 2007): a detection is a true positive for a visible wall when
  |d rho| <= ``max_drho`` and |d alpha| <= ``max_dalpha`` and their extents overlap;
  TruePos = matched walls / visible walls of at least ``min_wall_length``; FalsePos =
  detections that match no visible wall / all detections; sigma d rho and sigma d alpha
  are the standard deviations of the matched errors.
"""

from dataclasses import dataclass, field
import math
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from landmark_nav.geometry import inverse_transform_points, wrap_angle
import numpy as np

CORNER_CLASS = (math.radians(70.0), math.radians(110.0))
GRAZING_COS = 0.2  # |cos| of ~78 deg incidence: the segmentation splits grazing surfaces


@dataclass(frozen=True)
class CornerTruth:
    """True corners for one scan, in the laser frame at each corner's beam time."""

    xy: np.ndarray        # (A, 2) every true corner
    scored: np.ndarray    # (A,) bool: counted for recall
    in_class: np.ndarray  # (A,) bool: corner angle inside the class band


@dataclass(frozen=True)
class WallTruth:
    """True walls hit by one scan, in the laser frame."""

    ids: np.ndarray          # (W,)
    rho_alpha: np.ndarray    # (W, 2) Hessian normal form
    extent: np.ndarray       # (W,) visible length [m]
    span: np.ndarray         # (W, 2, 2) visible end points
    world_span: np.ndarray   # (W, 2, 2) the same end points in the world frame
    crlb: Optional[np.ndarray] = None  # (W, 2, 2) Cramer-Rao bound of (rho, alpha)


def normal_form(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """Return (N, 2) [rho >= 0, alpha] of the lines through p1 (N,2) and p2 (N,2)."""
    d = p2 - p1
    alpha = np.arctan2(d[:, 0], -d[:, 1])
    rho = p1[:, 0] * np.cos(alpha) + p1[:, 1] * np.sin(alpha)
    alpha = np.where(rho < 0.0, alpha + math.pi, alpha)
    return np.column_stack([np.abs(rho), wrap_angle(alpha)])


def line_crlb(ranges: np.ndarray, angles: np.ndarray, rho: float, alpha: float,
              sigma_r: float, sigma_phi: float) -> np.ndarray:
    """Return the (2, 2) Cramer-Rao bound of (rho, alpha) from beams hitting a line.

    The beams (noise-free ``ranges`` and ``angles``, laser frame) end on the line
    ``x cos(alpha) + y sin(alpha) = rho``. Each measured point is off the line by a normal
    error of variance ``s_i^2 = n^T Q_i n`` (line chapter eq. 7: ``sigma_r`` along the
    beam, ``r_i sigma_phi`` across it); its residual ``p_i.n - rho`` has the derivatives
    -1 and ``p_i.t`` (``t = dn/dalpha``), so the Fisher information is ``sum_i [1, -a_i;
    -a_i, a_i^2] / s_i^2`` with ``a_i = p_i.t``. No unbiased extractor that fits these
    beams has a smaller covariance; a line fitted to part of them has a larger one.
    """
    r = np.asarray(ranges, dtype=float)
    phi = np.asarray(angles, dtype=float)
    n_u = np.cos(phi - alpha)  # n . u_i: u_i the beam direction
    n_v = np.sin(phi - alpha)  # n . v_i up to sign: v_i across the beam
    w = 1.0 / np.maximum((sigma_r * n_u) ** 2 + (r * sigma_phi * n_v) ** 2, 1e-24)
    a = r * n_v  # p_i . t
    info = np.array([[w.sum(), -(w * a).sum()], [-(w * a).sum(), (w * a * a).sum()]])
    if np.linalg.det(info) <= 0.0:
        return np.full((2, 2), np.inf)
    return np.linalg.inv(info)


def _arm_runs(ids: np.ndarray, cos_inc: np.ndarray, beam: int,
              max_run: int = 60) -> Tuple[Tuple[int, int], Tuple[int, int]]:
    """Return ((wall id, run length), (wall id, run length)) right and left of ``beam``."""
    out = []
    for side in (-1, 1):
        seq = np.arange(beam + side, beam + side * (max_run + 1), side)
        seq = seq[(seq >= 0) & (seq < ids.size)]
        if seq.size == 0:
            out.append((-1, 0))
            continue
        wall = int(ids[seq[0]])
        ok = (ids[seq] == wall) & (cos_inc[seq] >= GRAZING_COS)
        out.append((wall, int(np.argmin(ok)) if not ok.all() else int(ok.size)))
    return out[0], out[1]


def corner_truth(world, sensor_pose_at: Callable[[np.ndarray], np.ndarray], stamp_ns: int,
                 angles: np.ndarray, time_increment: float, min_range: float = 0.3,
                 max_range: float = 6.0, min_arm_beams: int = 5,
                 band: Sequence[float] = CORNER_CLASS) -> CornerTruth:
    """Return the true corners of one scan and which of them are scored (module docstring).

    Args:
        world: The simulator world.
        sensor_pose_at: Maps stamps (ns, array) to true laser poses (N, 3) in the world.
        stamp_ns: Stamp of the scan's first beam.
        angles: (N,) beam angles.
        time_increment: Time between beams [s].
        min_range: Closest scored corner [m].
        max_range: Farthest scored corner [m].
        min_arm_beams: Consecutive beams needed on each arm.
        band: Corner-angle class [rad].

    """
    truth = world.corners()
    n = len(angles)
    pose0 = np.asarray(sensor_pose_at(np.array([stamp_ns])), dtype=float).reshape(3)
    rel = inverse_transform_points(pose0, truth.positions).reshape(-1, 2)
    bearing = np.arctan2(rel[:, 1], rel[:, 0])
    beam = np.clip(np.rint((bearing - angles[0]) / (angles[1] - angles[0]) if n > 1 else 0),
                   0, max(n - 1, 0)).astype(np.int64)
    stamps = stamp_ns + np.rint(beam * time_increment * 1e9).astype(np.int64)
    poses = np.asarray(sensor_pose_at(stamps), dtype=float).reshape(-1, 3)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    d = truth.positions - poses[:, :2]
    xy = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
    fov = float(angles[-1] - angles[0]) if n > 1 else 0.0
    center = pose0.copy()
    center[2] += 0.5 * float(angles[0] + angles[-1]) if n else 0.0
    visible = np.isin(truth.ids, world.visible_corners(center, max_range, fov + 1e-9,
                                                       both_sides=True))
    theta = np.minimum(truth.openings, 2.0 * math.pi - truth.openings)
    in_class = (theta >= band[0]) & (theta <= band[1])
    scored = visible & in_class & (np.hypot(xy[:, 0], xy[:, 1]) >= min_range)
    if scored.any():
        hits = world.raycast(np.repeat(pose0[None, :2], n, axis=0), pose0[2] + angles,
                             max_range + 2.0)
        for k in np.flatnonzero(scored):
            (w1, n1), (w2, n2) = _arm_runs(hits.ids, hits.cos_incidence, int(beam[k]))
            arms = {int(v) for v in truth.segment_ids[k]}
            scored[k] = {w1, w2} == arms and min(n1, n2) >= min_arm_beams
    return CornerTruth(xy=xy, scored=scored, in_class=in_class)


def wall_truth(world, sensor_pose: np.ndarray, angles: np.ndarray, max_range: float,
               sigma_r: Optional[float] = None, sigma_phi: float = 0.0) -> WallTruth:
    """Return the walls hit by the noise-free beams from ``sensor_pose`` (laser frame).

    With ``sigma_r`` the walls carry the Cramer-Rao bound of (rho, alpha) from their beams
    (:func:`line_crlb`, the laser's range and bearing noise).
    """
    sensor_pose = np.asarray(sensor_pose, dtype=float)
    origins = np.repeat(sensor_pose[None, :2], len(angles), axis=0)
    hits = world.raycast(origins, sensor_pose[2] + angles, max_range)
    hit = np.isfinite(hits.ranges) & (hits.kind == 1)
    xy = origins[hit] + hits.ranges[hit, None] * np.column_stack(
        [np.cos(sensor_pose[2] + angles[hit]), np.sin(sensor_pose[2] + angles[hit])])
    ids = hits.ids[hit]
    r_hit, phi_hit = hits.ranges[hit], angles[hit]
    walls = world.walls()
    rows = {int(i): r for r, i in enumerate(walls.ids)}
    w_ids, forms, extents, spans, world_spans, bounds = [], [], [], [], [], []
    for wid in np.unique(ids):
        on = ids == wid
        pts = xy[on]
        if len(pts) < 2:
            continue
        seg = walls.segments[rows[int(wid)]]
        direction = (seg[2:] - seg[:2]) / np.hypot(*(seg[2:] - seg[:2]))
        t = (pts - seg[:2]) @ direction
        ends_world = seg[:2] + np.outer([t.min(), t.max()], direction)
        ends = inverse_transform_points(sensor_pose, ends_world)
        world_spans.append(ends_world)
        w_ids.append(int(wid))
        forms.append(normal_form(ends[:1], ends[1:])[0])
        extents.append(float(t.max() - t.min()))
        spans.append(ends)
        if sigma_r is not None:
            bounds.append(line_crlb(r_hit[on], phi_hit[on], *forms[-1], sigma_r, sigma_phi))
    return WallTruth(ids=np.array(w_ids, dtype=np.int64),
                     rho_alpha=np.array(forms).reshape(-1, 2), extent=np.array(extents),
                     span=np.array(spans).reshape(-1, 2, 2),
                     world_span=np.array(world_spans).reshape(-1, 2, 2),
                     crlb=np.array(bounds).reshape(-1, 2, 2) if sigma_r is not None else None)


@dataclass
class CornerScore:
    """Accumulated corner-detection figures over many scans."""

    scans: int = 0
    truth: int = 0
    tp: int = 0
    ghost: int = 0
    wrong: int = 0
    duplicate: int = 0
    ignored: int = 0
    errors: List[float] = field(default_factory=list)

    @property
    def false_positives(self) -> int:
        """Ghosts, wrong-class and duplicate detections."""
        return self.ghost + self.wrong + self.duplicate

    @property
    def precision(self) -> float:
        """True positives / (true positives + false positives)."""
        total = self.tp + self.false_positives
        return self.tp / total if total else float('nan')

    @property
    def recall(self) -> float:
        """True positives / scored true corners."""
        return self.tp / self.truth if self.truth else float('nan')

    @property
    def ghosts_per_scan(self) -> float:
        """Ghost detections per scan."""
        return self.ghost / self.scans if self.scans else float('nan')

    @property
    def rms_error(self) -> float:
        """RMS position error of the true positives [m]."""
        return float(np.sqrt(np.mean(np.square(self.errors)))) if self.errors else float('nan')


def score_corners(score: CornerScore, detected_xy: np.ndarray, truth: CornerTruth,
                  match_distance: float = 0.1) -> None:
    """Add one scan's corner detections (laser frame, (D, 2)) to ``score``."""
    detected_xy = np.asarray(detected_xy, dtype=float).reshape(-1, 2)
    score.scans += 1
    score.truth += int(truth.scored.sum())
    if not len(detected_xy):
        return
    if not len(truth.xy):
        score.ghost += len(detected_xy)
        return
    dist = np.hypot(*(detected_xy[:, None, :] - truth.xy[None]).transpose(2, 0, 1))
    matched = np.zeros(len(truth.xy), bool)
    for i in np.argsort(dist.min(axis=1), kind='stable'):
        k = int(np.argmin(dist[i]))
        if dist[i, k] > match_distance:
            score.ghost += 1
        elif not truth.in_class[k]:
            score.wrong += 1
        elif matched[k]:
            score.duplicate += 1
        else:
            matched[k] = True
            if truth.scored[k]:
                score.tp += 1
                score.errors.append(float(dist[i, k]))
            else:
                score.ignored += 1


@dataclass
class LineScore:
    """Accumulated line-extraction figures over many scans."""

    scans: int = 0
    detections: int = 0
    false_pos: int = 0
    relevant: int = 0          # visible walls of at least min_wall_length
    found: int = 0
    d_rho: List[float] = field(default_factory=list)
    d_alpha: List[float] = field(default_factory=list)
    floor_rho: List[float] = field(default_factory=list)    # see floor_sigma_rho
    floor_alpha: List[float] = field(default_factory=list)
    own_rho: List[float] = field(default_factory=list)      # matched line's own var(rho)
    bound_rho: List[float] = field(default_factory=list)    # wall's var(rho) bound, uncut

    @property
    def true_pos(self) -> float:
        """Matched relevant walls / relevant walls."""
        return self.found / self.relevant if self.relevant else float('nan')

    @property
    def false_pos_rate(self) -> float:
        """Detections matching no visible wall / detections."""
        return self.false_pos / self.detections if self.detections else float('nan')

    @property
    def sigma_rho(self) -> float:
        """Std of rho errors of matched relevant walls [m]."""
        return float(np.std(self.d_rho)) if self.d_rho else float('nan')

    @property
    def sigma_alpha(self) -> float:
        """Std of alpha errors of matched relevant walls [rad]."""
        return float(np.std(self.d_alpha)) if self.d_alpha else float('nan')

    @property
    def floor_sigma_rho(self) -> float:
        """Sigma d rho an efficient extractor would get on the same matched walls [m].

        Each matched wall's rho error drawn from its Cramer-Rao bound (all beams on the
        wall, :func:`line_crlb`), cut at the matching window as the measured errors are:
        the RMS over the walls. NaN without bounds (``wall_truth`` without ``sigma_r``).
        """
        return math.sqrt(float(np.mean(self.floor_rho))) if self.floor_rho else float('nan')

    @property
    def floor_sigma_alpha(self) -> float:
        """The same for sigma d alpha [rad]."""
        return (math.sqrt(float(np.mean(self.floor_alpha))) if self.floor_alpha
                else float('nan'))


def _cut_variance(var: float, limit: float) -> float:
    """Return the variance of N(0, var) restricted to [-limit, limit]."""
    if not var > 0.0:
        return 0.0
    if not math.isfinite(var):
        return limit * limit / 3.0  # uniform over the window
    k = limit / math.sqrt(var)
    mass = math.erf(k / math.sqrt(2.0))  # 2 Phi(k) - 1
    pdf = math.exp(-0.5 * k * k) / math.sqrt(2.0 * math.pi)
    return var * (1.0 - 2.0 * k * pdf / mass) if mass > 0.0 else 0.0


def _overlap(span: np.ndarray, start: np.ndarray, end: np.ndarray) -> bool:
    """Whether a detected segment overlaps a wall's visible span (projected on the wall)."""
    d = span[1] - span[0]
    length2 = float(d @ d)
    if length2 <= 0:
        return False
    t = sorted([float((start - span[0]) @ d) / length2, float((end - span[0]) @ d) / length2])
    return t[1] > 0.0 and t[0] < 1.0


def score_lines(score: LineScore, lines: Sequence, truth: WallTruth,
                max_drho: float = 0.1, max_dalpha: float = math.radians(3.0),
                min_wall_length: float = 1.0, line_poses: Optional[np.ndarray] = None
                ) -> None:
    """Add one scan's line detections (objects with rho, alpha, start, end) to ``score``.

    ``line_poses`` (D, 3), when given, are the true laser poses at the time each line's
    points were measured (its middle beam): the walls are then compared in that pose, so
    the robot's motion during the sweep does not count as extraction error.
    """
    score.scans += 1
    score.detections += len(lines)
    n_w = len(truth.ids)
    match = np.zeros((len(lines), n_w), dtype=bool)
    err = np.zeros((len(lines), n_w, 2))
    for i, ln in enumerate(lines):
        forms = truth.rho_alpha
        if line_poses is not None and n_w:
            ends = inverse_transform_points(line_poses[i], truth.world_span.reshape(-1, 2))
            ends = ends.reshape(-1, 2, 2)
            forms = normal_form(ends[:, 0], ends[:, 1])
        for j in range(n_w):
            rho, alpha = forms[j]
            drho = float(ln.rho - rho)
            dalpha = float(wrap_angle(ln.alpha - alpha))
            if abs(drho) <= max_drho and abs(dalpha) <= max_dalpha and _overlap(
                    truth.span[j], np.asarray(ln.start), np.asarray(ln.end)):
                match[i, j] = True
                err[i, j] = (drho, dalpha)
    score.false_pos += int((~match.any(axis=1)).sum()) if n_w else len(lines)
    for j in range(n_w):
        if truth.extent[j] < min_wall_length:
            continue
        score.relevant += 1
        cands = np.flatnonzero(match[:, j])
        if len(cands):
            best = cands[np.argmin(np.abs(err[cands, j, 0]))]
            score.found += 1
            score.d_rho.append(float(err[best, j, 0]))
            score.d_alpha.append(float(err[best, j, 1]))
            cov = getattr(lines[best], 'covariance', None)
            score.own_rho.append(float(cov[0, 0]) if cov is not None else float('nan'))
            if truth.crlb is not None:
                score.floor_rho.append(_cut_variance(float(truth.crlb[j, 0, 0]), max_drho))
                score.bound_rho.append(float(truth.crlb[j, 0, 0]))
                score.floor_alpha.append(_cut_variance(float(truth.crlb[j, 1, 1]),
                                                       max_dalpha))


@dataclass
class FeatureRun:
    """Scores and per-scan times of several extractors over the scans of one run.

    Attributes:
        corner_params: Corner detector settings by name.
        line_params: Line extractor settings by name.
        segment_sigma_r: Range noise the segmentation assumes [m] (without ``segmenters``).
        truth_sigma_r: The sensor's true range noise [m] (Cramer-Rao floor of the walls).
        truth_sigma_phi: The sensor's true bearing noise [rad].
        segmenters: ``{'corners': ..., 'lines': ...}``: the range noise and segmentation of
            each node (:class:`~landmark_nav.laser.extractor_configuration.ScanSegmenter`);
            default: the node defaults at ``segment_sigma_r``.

    """

    corner_params: Dict[str, object]
    line_params: Dict[str, object]
    segment_sigma_r: float = 0.01
    truth_sigma_r: Optional[float] = None
    truth_sigma_phi: float = 0.0
    segmenters: Dict[str, object] = field(default_factory=dict)
    corners: Dict[str, CornerScore] = field(default_factory=dict)
    lines: Dict[str, LineScore] = field(default_factory=dict)
    corner_times: Dict[str, List[float]] = field(default_factory=dict)
    line_times: Dict[str, List[float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Create an empty score and time list per method and the default segmenters."""
        from landmark_nav.laser.extractor_configuration import SCAN_PARAMETERS, ScanSegmenter
        for m in self.corner_params:
            self.corners.setdefault(m, CornerScore())
            self.corner_times.setdefault(m, [])
        for m in self.line_params:
            self.lines.setdefault(m, LineScore())
            self.line_times.setdefault(m, [])
        for kind in ('corners', 'lines'):
            self.segmenters.setdefault(kind, ScanSegmenter(
                SCAN_PARAMETERS['segmentation.incidence_deg'].default,
                SCAN_PARAMETERS['segmentation.min_points'].default, self.segment_sigma_r))


def segment_per_extractor(segmenters: Dict[str, object], ranges: np.ndarray,
                          angles: np.ndarray, valid: np.ndarray, angle_increment: float
                          ) -> Dict[str, Tuple[list, float]]:
    """Return each segmenter's clusters of one scan and the seconds they took.

    Each segmenter takes the scan into its range noise first (as the node does); those
    with the same settings at this scan share one segmentation.
    """
    shared: Dict[tuple, Tuple[list, float]] = {}
    out = {}
    for kind, segmenter in segmenters.items():
        t0 = time.perf_counter()
        segmenter.track(ranges, angles, valid)
        t_track = time.perf_counter() - t0
        key = segmenter.key()
        if key not in shared:
            t0 = time.perf_counter()
            shared[key] = (segmenter.segment(ranges, angles, valid, angle_increment),
                           time.perf_counter() - t0)
        out[kind] = (shared[key][0], shared[key][1] + t_track)
    return out


def score_scan(run: FeatureRun, world, sensor_pose_at: Callable[[np.ndarray], np.ndarray],
               scan, corner_gate: float = 0.1) -> None:
    """Extract features from one simulated scan and add their scores to ``run``.

    The one scoring path of the simulator figures (``landmark_nav evaluate-features`` and
    the office tests): valid beams per REP 117, the segmentation, each extractor, then
    :func:`score_corners` against :func:`corner_truth` and :func:`score_lines` against
    :func:`wall_truth` (true laser pose at the middle of the sweep; each line compared in
    the pose of its middle beam).
    Each extractor runs on its node's segmentation (``run.segmenters``:
    :func:`segment_per_extractor`) at its node's range noise of the scan.

    Args:
        run: Settings and accumulated scores.
        world: The simulator world.
        sensor_pose_at: Maps stamps (ns, array) to true laser poses (N, 3) in the world.
        scan: Object with ``stamp_ns``, ``ranges``, ``angle_min``, ``angle_increment``,
            ``time_increment``, ``range_min``, ``range_max`` (a LaserScan's fields).
        corner_gate: Corner match distance [m].

    """
    from landmark_nav.conversions import classify_ranges
    from landmark_nav.laser.corners import detect_corners
    from landmark_nav.laser.lines import extract_lines

    r = np.asarray(scan.ranges, dtype=float)
    angles = scan.angle_min + scan.angle_increment * np.arange(r.size)
    valid = classify_ranges(r, scan.range_min, scan.range_max)[0]
    segmented = segment_per_extractor(run.segmenters, r, angles, valid, scan.angle_increment)
    if run.corner_params:
        clusters, t_seg = segmented['corners']
        at_noise = run.segmenters['corners'].at_scan_noise
        truth = corner_truth(world, sensor_pose_at, scan.stamp_ns, angles,
                             scan.time_increment)
        for m, params in run.corner_params.items():
            t0 = time.perf_counter()
            corners = detect_corners(clusters, at_noise(params))
            run.corner_times[m].append(t_seg + time.perf_counter() - t0)
            xy = np.array([c.position for c in corners]).reshape(-1, 2)
            score_corners(run.corners[m], xy, truth, corner_gate)
    if run.line_params:
        clusters, t_seg = segmented['lines']
        at_noise = run.segmenters['lines'].at_scan_noise
        t_mid = scan.stamp_ns + int(0.5 * r.size * scan.time_increment * 1e9)
        walls = wall_truth(world, np.reshape(sensor_pose_at(np.array([t_mid])), 3), angles,
                           scan.range_max, sigma_r=run.truth_sigma_r,
                           sigma_phi=run.truth_sigma_phi)
        for m, params in run.line_params.items():
            t0 = time.perf_counter()
            lines = extract_lines(clusters, at_noise(params))
            run.line_times[m].append(t_seg + time.perf_counter() - t0)
            mid = np.array([0.5 * (ln.first_index + ln.last_index) for ln in lines])
            stamps = scan.stamp_ns + np.rint(mid * scan.time_increment * 1e9).astype(np.int64)
            score_lines(run.lines[m], lines, walls,
                        line_poses=np.reshape(sensor_pose_at(stamps), (-1, 3)))
