"""Score corner and line detections against the simulator's ground truth.

Per scan, the ground truth visible to the laser is derived from the world and the true
sensor pose by casting the scan's beams without noise (:func:`visible_truth`):

* A true corner is *detectable* when its vertex is in line of sight within
  [min_range, max_range] and the field of view, and each of its two walls is hit by at
  least ``min_arm_beams`` beams within ``arm_length`` of the vertex (a detector needs
  points on both arms). Its *corner angle* is the smaller of the free-space opening and
  the wall-side angle (90 deg for both a room corner and a box corner).
* A true wall is *visible* with the extent between its outermost hit points.

Matching (:func:`score_corners`, :func:`score_lines`):

* Corners: one-to-one assignment (Hungarian) within ``match_distance``. A detection near
  any true corner is correct (precision); a detection farther than ``match_distance`` from
  every true corner is a ghost. Recall and position error are over detectable corners
  whose angle lies in the corner class (70-110 deg by default) and whose range is within
  the evaluated band.
* Lines (Nguyen et al. 2007): a detection is a true positive for a visible wall when
  |d rho| <= ``max_drho`` and |d alpha| <= ``max_dalpha`` and their extents overlap;
  TruePos = matched walls / visible walls of at least ``min_wall_length``; FalsePos =
  detections that match no visible wall / all detections; sigma d rho and sigma d alpha
  are the standard deviations of the matched errors.
"""

from dataclasses import dataclass, field
import math
from typing import List, Sequence

from landmark_nav.geometry import inverse_transform_points, wrap_angle
import numpy as np
from scipy.optimize import linear_sum_assignment


@dataclass(frozen=True)
class VisibleTruth:
    """Ground truth seen by one scan, in the laser frame."""

    corner_ids: np.ndarray        # (C,) ids of detectable corners
    corner_xy: np.ndarray         # (C, 2)
    corner_angle: np.ndarray      # (C,) corner angle [rad]
    all_corner_xy: np.ndarray     # (A, 2) every true corner (for ghost/precision tests)
    wall_ids: np.ndarray          # (W,) ids of walls hit by at least 2 beams
    wall_rho_alpha: np.ndarray    # (W, 2) Hessian normal form in the laser frame
    wall_extent: np.ndarray       # (W,) visible length [m]
    wall_span: np.ndarray         # (W, 2, 2) visible end points in the laser frame


def normal_form(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """Return (N, 2) [rho >= 0, alpha] of the lines through p1 (N,2) and p2 (N,2)."""
    d = p2 - p1
    alpha = np.arctan2(d[:, 0], -d[:, 1])
    rho = p1[:, 0] * np.cos(alpha) + p1[:, 1] * np.sin(alpha)
    alpha = np.where(rho < 0.0, alpha + math.pi, alpha)
    return np.column_stack([np.abs(rho), wrap_angle(alpha)])


def visible_truth(world, sensor_pose: np.ndarray, angles: np.ndarray, max_range: float,
                  min_range: float = 0.0, arm_length: float = 1.0,
                  min_arm_beams: int = 5) -> VisibleTruth:
    """Derive the ground truth visible from ``sensor_pose`` [x, y, yaw] (world frame)."""
    sensor_pose = np.asarray(sensor_pose, dtype=float)
    origins = np.repeat(sensor_pose[None, :2], len(angles), axis=0)
    hits = world.raycast(origins, sensor_pose[2] + angles, max_range)
    hit = np.isfinite(hits.ranges) & (hits.kind == 1)
    hit_xy = origins[hit] + hits.ranges[hit, None] * np.column_stack(
        [np.cos(sensor_pose[2] + angles[hit]), np.sin(sensor_pose[2] + angles[hit])])
    hit_ids = hits.ids[hit]

    corners = world.corners()
    fov = float(angles[-1] - angles[0]) if len(angles) > 1 else 0.0
    center = sensor_pose.copy()
    center[2] += 0.5 * float(angles[0] + angles[-1]) if len(angles) else 0.0
    visible = set(world.visible_corners(center, max_range, fov + 1e-9).tolist())
    keep = []
    for k, cid in enumerate(corners.ids):
        if cid not in visible:
            continue
        vertex = corners.positions[k]
        if np.hypot(*(vertex - sensor_pose[:2])) < min_range:
            continue
        ok = True
        for seg_id in corners.segment_ids[k]:
            near = hit_xy[hit_ids == seg_id]
            if np.count_nonzero(np.hypot(*(near - vertex).T) <= arm_length) < min_arm_beams:
                ok = False
                break
        if ok:
            keep.append(k)
    keep = np.array(keep, dtype=int)
    angle = np.minimum(corners.openings, 2 * math.pi - corners.openings)

    walls = world.walls()
    wall_rows = {int(i): r for r, i in enumerate(walls.ids)}
    w_ids, w_form, w_ext, w_span = [], [], [], []
    for wid in np.unique(hit_ids):
        pts = hit_xy[hit_ids == wid]
        if len(pts) < 2:
            continue
        seg = walls.segments[wall_rows[int(wid)]]
        direction = (seg[2:] - seg[:2]) / np.hypot(*(seg[2:] - seg[:2]))
        t = (pts - seg[:2]) @ direction
        ends = seg[:2] + np.outer([t.min(), t.max()], direction)
        ends_l = inverse_transform_points(sensor_pose, ends)
        w_ids.append(int(wid))
        w_form.append(normal_form(ends_l[:1], ends_l[1:])[0])
        w_ext.append(float(t.max() - t.min()))
        w_span.append(ends_l)
    return VisibleTruth(
        corner_ids=corners.ids[keep],
        corner_xy=inverse_transform_points(sensor_pose, corners.positions[keep]).reshape(-1, 2),
        corner_angle=angle[keep],
        all_corner_xy=inverse_transform_points(sensor_pose, corners.positions).reshape(-1, 2),
        wall_ids=np.array(w_ids, dtype=np.int64),
        wall_rho_alpha=np.array(w_form).reshape(-1, 2),
        wall_extent=np.array(w_ext),
        wall_span=np.array(w_span).reshape(-1, 2, 2))


@dataclass
class CornerScore:
    """Accumulated corner-detection figures over many scans."""

    scans: int = 0
    detections: int = 0
    correct: int = 0          # detections within match distance of some true corner
    ghosts: int = 0
    relevant: int = 0         # detectable true corners in the class and range band
    found: int = 0            # of those, matched
    errors: List[float] = field(default_factory=list)

    @property
    def precision(self) -> float:
        """Correct detections / detections."""
        return self.correct / self.detections if self.detections else float('nan')

    @property
    def recall(self) -> float:
        """Matched relevant true corners / relevant true corners."""
        return self.found / self.relevant if self.relevant else float('nan')

    @property
    def ghosts_per_scan(self) -> float:
        """Ghost detections per scan."""
        return self.ghosts / self.scans if self.scans else float('nan')

    @property
    def rms_error(self) -> float:
        """RMS position error of matched relevant corners [m]."""
        return float(np.sqrt(np.mean(np.square(self.errors)))) if self.errors else float('nan')


def score_corners(score: CornerScore, detected_xy: np.ndarray, truth: VisibleTruth,
                  match_distance: float = 0.1,
                  angle_band: Sequence[float] = (math.radians(70), math.radians(110)),
                  range_band: Sequence[float] = (0.3, 6.0)) -> None:
    """Add one scan's corner detections (laser frame, (D, 2)) to ``score``."""
    detected_xy = np.asarray(detected_xy, dtype=float).reshape(-1, 2)
    score.scans += 1
    score.detections += len(detected_xy)
    if len(detected_xy):
        if len(truth.all_corner_xy):
            d_all = np.hypot(*(detected_xy[:, None, :] - truth.all_corner_xy[None]).transpose(
                2, 0, 1))
            near = d_all.min(axis=1) <= match_distance
        else:
            near = np.zeros(len(detected_xy), bool)
        score.correct += int(near.sum())
        score.ghosts += int((~near).sum())
    rng = np.hypot(truth.corner_xy[:, 0], truth.corner_xy[:, 1])
    rel = ((truth.corner_angle >= angle_band[0]) & (truth.corner_angle <= angle_band[1])
           & (rng >= range_band[0]) & (rng <= range_band[1]))
    targets = truth.corner_xy[rel]
    score.relevant += len(targets)
    if len(targets) and len(detected_xy):
        cost = np.hypot(*(targets[:, None, :] - detected_xy[None]).transpose(2, 0, 1))
        rows, cols = linear_sum_assignment(cost)
        ok = cost[rows, cols] <= match_distance
        score.found += int(ok.sum())
        score.errors.extend(cost[rows, cols][ok].tolist())


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


def _overlap(span: np.ndarray, start: np.ndarray, end: np.ndarray) -> bool:
    """Whether a detected segment overlaps a wall's visible span (projected on the wall)."""
    d = span[1] - span[0]
    length2 = float(d @ d)
    if length2 <= 0:
        return False
    t = sorted([float((start - span[0]) @ d) / length2, float((end - span[0]) @ d) / length2])
    return t[1] > 0.0 and t[0] < 1.0


def score_lines(score: LineScore, lines: Sequence, truth: VisibleTruth,
                max_drho: float = 0.1, max_dalpha: float = math.radians(3.0),
                min_wall_length: float = 1.0) -> None:
    """Add one scan's line detections (objects with rho, alpha, start, end) to ``score``."""
    score.scans += 1
    score.detections += len(lines)
    n_w = len(truth.wall_ids)
    match = np.zeros((len(lines), n_w), dtype=bool)
    err = np.zeros((len(lines), n_w, 2))
    for i, ln in enumerate(lines):
        for j in range(n_w):
            rho, alpha = truth.wall_rho_alpha[j]
            drho = float(ln.rho - rho)
            dalpha = float(wrap_angle(ln.alpha - alpha))
            if abs(drho) <= max_drho and abs(dalpha) <= max_dalpha and _overlap(
                    truth.wall_span[j], np.asarray(ln.start), np.asarray(ln.end)):
                match[i, j] = True
                err[i, j] = (drho, dalpha)
    score.false_pos += int((~match.any(axis=1)).sum()) if n_w else len(lines)
    for j in range(n_w):
        if truth.wall_extent[j] < min_wall_length:
            continue
        score.relevant += 1
        cands = np.flatnonzero(match[:, j])
        if len(cands):
            best = cands[np.argmin(np.abs(err[cands, j, 0]))]
            score.found += 1
            score.d_rho.append(float(err[best, j, 0]))
            score.d_alpha.append(float(err[best, j, 1]))
