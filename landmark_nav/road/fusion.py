"""Fusion of laser segments and the vision road outline into corridors and a route (§4.4).

* :func:`ground_to_pixels` / :func:`pixels_to_ground`: the camera model and mount between
  the ground plane of ``base_link`` and the image (the laser's traversable segment becomes
  the seed area; the outline becomes a polygon on the ground);
* :func:`laser_corridors` (eq. 29): each traversable segment of the newest scan is chained
  to segments of the previous scans (in the odometry frame, seen from the current pose)
  that overlap it by more than the robot width, across the current heading;
* :func:`extend_with_outline` (eq. 30): intersection lines perpendicular to the heading at
  increasing distances beyond the laser line cut the outline polygon into intervals; the
  corridor is extended by the interval overlapping its last one by more than the robot
  width, line after line, until none does;
* :func:`plan_routes` / :func:`choose_route`: one route per corridor through the middle of
  its free interval at each line, kept ``robot_width / 2`` clear of the obstacles and the
  corridor's borders, its lateral moves started early (``max_lateral_slope``: a
  pedestrian far ahead already bends the route near the robot); the best is the
  longest-reaching one, then the one with the least lateral excursion and the widest
  clearance (corridor statistics). Without a usable
  outline the laser corridors are used alone;
* the road width from the laser (the newest segment of the chosen corridor) and from vision
  (median width of its outline intervals, in the robot's ground plane).

Everything is in ``base_link`` (x forward, y left) of the current pose unless stated.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence

from landmark_nav.corridor.orientation import mount_rotation
from landmark_nav.geometry import inverse_transform_points
import numpy as np


@dataclass(frozen=True)
class FusionParams:
    """Robot and corridor geometry (metres)."""

    robot_width: float = 0.5
    line_start: float = 0.5       # first intersection line beyond the laser line [m]
    line_step: float = 0.5        # spacing of the intersection lines [m]
    max_distance: float = 12.0    # farthest intersection line ahead of base_link [m]
    history: int = 10             # scans kept for eq. 29
    max_lateral_slope: float = 0.5  # route's largest |dy/dx| where the corridor allows
    obstacle_margin: float = 0.25   # kept between the robot's side and an obstacle point

    def __post_init__(self) -> None:
        """Check the ranges."""
        for name in ('robot_width', 'line_step', 'max_distance'):
            if not getattr(self, name) > 0.0:
                raise ValueError(f'fusion {name} must be > 0; got {getattr(self, name)!r}')
        if self.line_start < 0.0 or self.history < 1:
            raise ValueError('fusion line_start must be >= 0 and history >= 1')


@dataclass(frozen=True)
class Interval:
    """A traversable interval across the heading at distance ``x`` ahead: y in [lo, hi]."""

    x: float
    lo: float
    hi: float
    source: str                   # 'laser' or 'vision'

    @property
    def width(self) -> float:
        """Width hi - lo [m]."""
        return self.hi - self.lo


@dataclass(frozen=True)
class Corridor:
    """A chain of intervals, nearest first (eqs. 29-30)."""

    intervals: tuple

    @property
    def reach(self) -> float:
        """Distance ahead of the farthest interval [m]."""
        return max(i.x for i in self.intervals)


@dataclass(frozen=True)
class Route:
    """A route along one corridor: (K, 2) points in base_link, nearest first."""

    corridor: Corridor
    points: np.ndarray
    clearance: float              # smallest free half-width around the route [m]
    excursion: float              # largest |y| of the route [m]


def ground_to_pixels(camera, mount: Sequence[float], points: np.ndarray) -> np.ndarray:
    """Project (N, 2 or 3) base_link points (z = 0 if 2-D) to pixels (NaN behind)."""
    p = np.asarray(points, dtype=float)
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    r = mount_rotation(mount)                        # base <- optical
    cam = (p - np.asarray(mount[:3], dtype=float)) @ r
    return camera.project(cam)


def pixels_to_ground(camera, mount: Sequence[float], px: np.ndarray,
                     max_distance: float = math.inf) -> np.ndarray:
    """Intersect the rays of (N, 2) pixels with the ground z = 0: (N, 2) base_link x, y.

    Rays that do not descend, or meet the ground farther than ``max_distance`` ahead, give
    NaN rows.
    """
    rays = camera.back_project(np.asarray(px, dtype=float)) @ mount_rotation(mount).T
    origin = np.asarray(mount[:3], dtype=float)
    with np.errstate(divide='ignore', invalid='ignore'):
        t = np.where(rays[:, 2] < -1e-9, -origin[2] / rays[:, 2], np.nan)
    g = origin[:2] + rays[:, :2] * t[:, None]
    g[~(g[:, 0] <= max_distance)] = np.nan
    return g


def segment_interval(start: Sequence[float], end: Sequence[float], source: str = 'laser'
                     ) -> Interval:
    """Interval of a segment given by its end points in base_link (x = mean distance)."""
    ys = sorted((float(start[1]), float(end[1])))
    return Interval(0.5 * (float(start[0]) + float(end[0])), ys[0], ys[1], source)


def _overlap(a: Interval, b: Interval) -> float:
    return min(a.hi, b.hi) - max(a.lo, b.lo)


def laser_corridors(history: Sequence[Sequence[tuple]], pose: Sequence[float],
                    params: FusionParams = FusionParams()) -> list:
    """Chain the traversable segments of the newest and the previous scans (eq. 29).

    Args:
        history: Per scan, newest first, the segments as ``((x0, y0), (x1, y1))`` end
            points in the odometry frame.
        pose: Current robot pose (x, y, yaw) in the odometry frame.
        params: Robot width and history length.

    Returns:
        One :class:`Corridor` per segment of the newest scan; its intervals are that
        segment followed by the chained older ones, as seen from ``pose``.
    """
    seen = []
    for scan in list(history)[:params.history]:
        row = []
        for a, b in scan:
            pa, pb = inverse_transform_points(pose, np.array([a, b], dtype=float))
            row.append(segment_interval(pa, pb))
        seen.append(row)
    if not seen:
        return []
    corridors = []
    for seg in seen[0]:
        chain = [seg]
        for row in seen[1:]:
            best = max(row, key=lambda s: _overlap(chain[-1], s), default=None)
            if best is None or _overlap(chain[-1], best) <= params.robot_width:
                break
            chain.append(best)
        corridors.append(Corridor(tuple(sorted(chain, key=lambda i: i.x))))
    return corridors


def polygon_intervals(polygon: np.ndarray, x: float) -> list:
    """Intervals [lo, hi] of y where the line at distance ``x`` lies inside a ground polygon."""
    p = np.asarray(polygon, dtype=float)
    if len(p) < 3:
        return []
    q = np.roll(p, -1, axis=0)
    crosses = (p[:, 0] <= x) != (q[:, 0] <= x)
    with np.errstate(divide='ignore', invalid='ignore'):
        y = p[:, 1] + (x - p[:, 0]) * (q[:, 1] - p[:, 1]) / (q[:, 0] - p[:, 0])
    ys = np.sort(y[crosses])
    return [(float(ys[k]), float(ys[k + 1])) for k in range(0, len(ys) - 1, 2)]


def extend_with_outline(corridor: Corridor, ground_polygon: Optional[np.ndarray],
                        params: FusionParams = FusionParams()) -> Corridor:
    """Extend a corridor beyond the laser with the outline's intersection lines (eq. 30)."""
    if ground_polygon is None or len(ground_polygon) < 3:
        return corridor
    chain = list(corridor.intervals)
    last = max(chain, key=lambda i: i.x)
    x = last.x + params.line_start
    while x <= params.max_distance:
        cands = [Interval(x, lo, hi, 'vision') for lo, hi in polygon_intervals(ground_polygon, x)]
        best = max(cands, key=lambda c: _overlap(last, c), default=None)
        if best is None or _overlap(last, best) <= params.robot_width:
            break
        chain.append(best)
        last = best
        x += params.line_step
    return Corridor(tuple(chain))


#: Fewer vision intersection lines than this in a corridor: the outline stopped short (e.g.
#: at a hard shadow band across the road); the laser corridor carries the route and the node
#: reports a vision failure.
MIN_VISION_LINES = 4


def vision_lines(corridor: Corridor) -> int:
    """Return the number of the corridor's intersection lines from the vision outline."""
    return sum(i.source == 'vision' for i in corridor.intervals)


def _free_interval(iv: Interval, obstacles: np.ndarray, half: float, prev_y: float,
                   band: float, margin: float) -> Optional[tuple]:
    """Free sub-interval (lo, hi) of ``iv`` for the robot centre, nearest ``prev_y``."""
    lo, hi = iv.lo + half, iv.hi - half
    if hi < lo:
        return None
    blocks = []
    if len(obstacles):
        near = obstacles[np.abs(obstacles[:, 0] - iv.x) <= band]
        blocks = sorted((float(y) - half - margin, float(y) + half + margin)
                        for y in near[:, 1])
    free, start = [], lo
    for b0, b1 in blocks:
        if b1 < start or b0 > hi:
            continue
        if b0 > start:
            free.append((start, b0))
        start = max(start, b1)
    if start <= hi:
        free.append((start, hi))
    if not free:
        return None
    return min(free, key=lambda f: 0.0 if f[0] <= prev_y <= f[1] else
               min(abs(f[0] - prev_y), abs(f[1] - prev_y)))


def plan_routes(corridors: Sequence[Corridor], obstacles: Optional[np.ndarray] = None,
                params: FusionParams = FusionParams()) -> list:
    """One route per corridor, ``robot_width / 2`` clear of its borders and the obstacles.

    Obstacle points block ``robot_width / 2 + obstacle_margin`` either side.

    Args:
        corridors: Corridors (intervals nearest first).
        obstacles: (M, 2) obstacle points in base_link (laser obstacles; may be empty).
        params: Robot width and line spacing.

    Returns:
        A :class:`Route` for each corridor with a free interval at its nearest line; the
        route stops at the first line without one.
    """
    obs = np.zeros((0, 2)) if obstacles is None else np.asarray(obstacles, float)[:, :2]
    half = 0.5 * params.robot_width
    routes = []
    for c in corridors:
        pts, frees, clear, y = [(0.0, 0.0)], [(0.0, 0.0)], math.inf, 0.0
        for iv in sorted(c.intervals, key=lambda i: i.x):
            free = _free_interval(iv, obs, half, y, 0.5 * params.line_step,
                                  params.obstacle_margin)
            if free is None:
                break
            y = 0.5 * (free[0] + free[1])
            pts.append((iv.x, y))
            frees.append(free)
            clear = min(clear, half + 0.5 * (free[1] - free[0]))
        if len(pts) > 1:
            p = _limit_lateral_slope(np.array(pts), frees, params.max_lateral_slope)
            routes.append(Route(c, p, float(clear), float(np.max(np.abs(p[:, 1])))))
    return routes


def _limit_lateral_slope(p: np.ndarray, frees: list, slope: float) -> np.ndarray:
    """Start lateral moves early: |dy/dx| <= slope between route points.

    Inside the free intervals where possible: a backward pass from the far end, then a
    forward one from the robot.
    """
    p = p.copy()
    n = len(p)
    for i in range(n - 2, 0, -1):
        step = slope * (p[i + 1, 0] - p[i, 0])
        y = min(max(p[i, 1], p[i + 1, 1] - step), p[i + 1, 1] + step)
        p[i, 1] = min(max(y, frees[i][0]), frees[i][1])
    for i in range(1, n):
        step = slope * (p[i, 0] - p[i - 1, 0])
        y = min(max(p[i, 1], p[i - 1, 1] - step), p[i - 1, 1] + step)
        p[i, 1] = min(max(y, frees[i][0]), frees[i][1])
    return p


def choose_route(routes: Sequence[Route]) -> Optional[Route]:
    """Return the best route: farthest reach, least lateral excursion, widest clearance."""
    if not routes:
        return None
    return max(routes, key=lambda r: (round(float(r.points[-1, 0]), 3), -round(r.excursion, 2),
                                      r.clearance))


def road_widths(corridor: Corridor) -> tuple[Optional[float], Optional[float]]:
    """(laser width, vision width) of a corridor [m]; None where it has no such interval.

    The laser width is the newest scan's segment (the one nearest the laser line, i.e. the
    farthest laser interval); the vision width the median of its outline intervals.
    """
    laser = [i for i in corridor.intervals if i.source == 'laser']
    vision = [i.width for i in corridor.intervals if i.source == 'vision']
    lw = max(laser, key=lambda i: i.x).width if laser else None
    vw = float(np.median(vision)) if vision else None
    return lw, vw
