"""2D world: wall segments and round obstacles, vectorised ray casting, ground-truth features.

Conventions (REP 103): world frame x forward/east, y left/north, angles in radians, CCW.

Segments are directed ``(x1, y1) -> (x2, y2)``. A *one-sided* segment has free space on its
LEFT (the side its left normal ``(-ey, ex)`` points to); room outlines are therefore stored
counter-clockwise and obstacle outlines clockwise. A *two-sided* segment (thin partition) has
free space on both sides. Ray casting treats all segments as opaque from both sides.

Ground-truth corners are the joints of consecutive one-sided segments (end of segment ``a``
equals start of segment ``b``). Their free-space opening is ``pi - turn`` where ``turn`` is
the signed heading change from ``a`` to ``b``: a room's concave corner has opening pi/2,
an obstacle's convex corner 3*pi/2 (its wall-side angle is ``2*pi - opening`` = pi/2).
"""

from dataclasses import dataclass
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

TWO_PI = 2.0 * math.pi
# A joint whose heading changes by less than this is collinear, not a corner.
MIN_CORNER_TURN = math.radians(1.0)
# Endpoints closer than this are the same vertex.
VERTEX_TOL = 1e-9
# Ray/segment parameter slack so that rays through a shared vertex never slip through.
_S_SLACK = 1e-9

HIT_NONE = 0
HIT_SEGMENT = 1
HIT_CIRCLE = 2


def wrap_angle(a: Any) -> Any:
    """Wrap angle(s) to [-pi, pi)."""
    return (np.asarray(a, dtype=float) + math.pi) % TWO_PI - math.pi


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class RayHits:
    """Result of :meth:`World.raycast` for N rays.

    Attributes:
        ranges: (N,) distance along each ray to the first hit, ``inf`` if none within range.
        kind: (N,) int8, ``HIT_NONE`` (0), ``HIT_SEGMENT`` (1) or ``HIT_CIRCLE`` (2).
        index: (N,) row of the hit in ``World.segments`` / ``World.circles``, -1 if none.
        ids: (N,) stable id of the hit segment / circle, -1 if none.
        cos_incidence: (N,) ``|cos|`` of the angle between ray and surface normal
            (1 = perpendicular hit, 0 = grazing), ``nan`` if none.
    """

    ranges: np.ndarray
    kind: np.ndarray
    index: np.ndarray
    ids: np.ndarray
    cos_incidence: np.ndarray


@dataclass(frozen=True, eq=False)
class Walls:
    """Ground-truth line segments.

    Attributes:
        ids: (M,) stable integer ids.
        segments: (M, 4) ``[x1, y1, x2, y2]``; for one-sided segments free space is on the left.
        two_sided: (M,) bool, True for thin partitions visible from both sides.
        labels: per-segment label (e.g. ``'room'``, ``'cabinet'``).
    """

    ids: np.ndarray
    segments: np.ndarray
    two_sided: np.ndarray
    labels: Tuple[str, ...]

    def __len__(self) -> int:
        """Return the number of segments."""
        return int(self.ids.shape[0])

    @property
    def lengths(self) -> np.ndarray:
        """Return the length of every segment, (M,) metres."""
        return np.hypot(self.segments[:, 2] - self.segments[:, 0],
                        self.segments[:, 3] - self.segments[:, 1])

    @property
    def normal_form(self) -> np.ndarray:
        """Infinite-line parameters (M, 2) ``[rho, alpha]``: ``x cos(a) + y sin(a) = rho >= 0``."""
        s = self.segments
        alpha = np.arctan2(s[:, 2] - s[:, 0], -(s[:, 3] - s[:, 1]))  # left normal (-ey, ex)
        rho = s[:, 0] * np.cos(alpha) + s[:, 1] * np.sin(alpha)
        alpha = np.where(rho < 0.0, alpha + math.pi, alpha)
        return np.stack([np.abs(rho), wrap_angle(alpha)], axis=1)


@dataclass(frozen=True, eq=False)
class RoundObstacles:
    """Ground-truth round obstacles (e.g. table legs).

    Attributes:
        ids: (K,) stable integer ids.
        circles: (K, 3) ``[cx, cy, r]``.
        labels: per-circle label.
    """

    ids: np.ndarray
    circles: np.ndarray
    labels: Tuple[str, ...]

    def __len__(self) -> int:
        """Return the number of circles."""
        return int(self.ids.shape[0])


@dataclass(frozen=True, eq=False)
class Corners:
    """Ground-truth corners (joints of consecutive one-sided segments).

    Attributes:
        ids: (C,) stable integer ids (order of the incoming segment's row).
        positions: (C, 2) corner vertex ``[x, y]``.
        bisectors: (C,) world angle of the bisector of the free-space wedge, i.e. pointing
            from the corner into free space (toward where a robot can see it).
        openings: (C,) free-space opening angle: pi/2 for a room's concave right-angle corner,
            3*pi/2 for an obstacle's convex right-angle corner.
        segment_ids: (C, 2) ids of the incoming and outgoing segment forming the corner.
    """

    ids: np.ndarray
    positions: np.ndarray
    bisectors: np.ndarray
    openings: np.ndarray
    segment_ids: np.ndarray

    def __len__(self) -> int:
        """Return the number of corners."""
        return int(self.ids.shape[0])

    @property
    def convex(self) -> np.ndarray:
        """(C,) True where the corner juts into free space (opening > pi)."""
        return self.openings > math.pi

    @property
    def wall_angles(self) -> np.ndarray:
        """(C,) angle on the solid side, ``2*pi - openings``."""
        return TWO_PI - self.openings


class World:
    """A planar world of wall segments and round obstacles.

    Build it with the ``add_*`` methods (ids are assigned sequentially, segments and circles
    have separate id spaces), then query :meth:`raycast`, :meth:`corners`,
    :meth:`visible_corners`, :meth:`walls`. :meth:`to_dict` / :meth:`from_dict` round-trip
    exactly through plain lists and floats (YAML safe).
    """

    def __init__(self, name: str = 'world') -> None:
        """Create an empty world."""
        self.name = str(name)
        self._seg: List[Tuple[float, float, float, float]] = []
        self._seg_ids: List[int] = []
        self._seg_two: List[bool] = []
        self._seg_labels: List[str] = []
        self._circ: List[Tuple[float, float, float]] = []
        self._circ_ids: List[int] = []
        self._circ_labels: List[str] = []
        self._cache: Dict[str, Any] = {}

    # ------------------------------------------------------------------ building
    def add_segment(self, x1: float, y1: float, x2: float, y2: float, label: str = 'wall',
                    two_sided: bool = True, segment_id: Optional[int] = None) -> int:
        """Add one segment and return its id (free side left if ``two_sided`` is False)."""
        p = tuple(float(v) for v in (x1, y1, x2, y2))
        if not all(math.isfinite(v) for v in p):
            raise ValueError('segment coordinates must be finite')
        if math.hypot(p[2] - p[0], p[3] - p[1]) <= VERTEX_TOL:
            raise ValueError('degenerate (zero-length) segment')
        if segment_id is None:
            segment_id = max(self._seg_ids, default=-1) + 1
        segment_id = int(segment_id)
        if segment_id in self._seg_ids:
            raise ValueError(f'duplicate segment id {segment_id}')
        self._seg.append(p)  # type: ignore[arg-type]
        self._seg_ids.append(segment_id)
        self._seg_two.append(bool(two_sided))
        self._seg_labels.append(str(label))
        self._cache.clear()
        return segment_id

    def add_polyline(self, points: Sequence[Sequence[float]], closed: bool = False,
                     free_side: str = 'both', label: str = 'wall') -> List[int]:
        """Add a polyline as segments; ``free_side`` is ``'left'``, ``'right'`` or ``'both'``.

        One-sided polylines (``'left'``/``'right'``) are stored with free space on the left,
        so their interior vertices (and the closing vertex) become ground-truth corners.
        """
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
            raise ValueError('points must be (P, 2) with P >= 2')
        if free_side not in ('left', 'right', 'both'):
            raise ValueError("free_side must be 'left', 'right' or 'both'")
        if free_side == 'right':
            pts = pts[::-1]
        if closed:
            pts = np.vstack([pts, pts[:1]])
        two = free_side == 'both'
        return [self.add_segment(*pts[i], *pts[i + 1], label=label, two_sided=two)
                for i in range(pts.shape[0] - 1)]

    def add_room(self, vertices: Sequence[Sequence[float]], label: str = 'room') -> List[int]:
        """Add a closed outline with free space INSIDE (stored counter-clockwise)."""
        pts = np.asarray(vertices, dtype=float)
        ccw = _signed_area(pts) > 0.0
        return self.add_polyline(pts if ccw else pts[::-1], closed=True, free_side='left',
                                 label=label)

    def add_polygon_obstacle(self, vertices: Sequence[Sequence[float]],
                             label: str = 'obstacle') -> List[int]:
        """Add a closed solid polygon with free space OUTSIDE (stored clockwise)."""
        pts = np.asarray(vertices, dtype=float)
        cw = _signed_area(pts) < 0.0
        return self.add_polyline(pts if cw else pts[::-1], closed=True, free_side='left',
                                 label=label)

    def add_rectangle(self, cx: float, cy: float, length: float, width: float,
                      yaw: float = 0.0, label: str = 'box') -> List[int]:
        """Add a solid rectangle (``length`` along its local x axis, rotated by ``yaw``)."""
        if length <= 0.0 or width <= 0.0:
            raise ValueError('rectangle sides must be positive')
        hx, hy = 0.5 * float(length), 0.5 * float(width)
        c, s = math.cos(yaw), math.sin(yaw)
        local = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
        verts = [(cx + c * u - s * v, cy + s * u + c * v) for u, v in local]
        return self.add_polygon_obstacle(verts, label=label)

    def add_circle(self, cx: float, cy: float, radius: float, label: str = 'leg',
                   circle_id: Optional[int] = None) -> int:
        """Add a round obstacle and return its id."""
        c = (float(cx), float(cy), float(radius))
        if not all(math.isfinite(v) for v in c) or c[2] <= 0.0:
            raise ValueError('circle needs finite centre and positive radius')
        if circle_id is None:
            circle_id = max(self._circ_ids, default=-1) + 1
        circle_id = int(circle_id)
        if circle_id in self._circ_ids:
            raise ValueError(f'duplicate circle id {circle_id}')
        self._circ.append(c)
        self._circ_ids.append(circle_id)
        self._circ_labels.append(str(label))
        self._cache.clear()
        return circle_id

    # ------------------------------------------------------------------ arrays
    @property
    def segments(self) -> np.ndarray:
        """(M, 4) segment endpoints ``[x1, y1, x2, y2]`` (read-only)."""
        if 'seg' not in self._cache:
            self._cache['seg'] = _readonly(np.array(self._seg, dtype=float).reshape(-1, 4))
        return self._cache['seg']

    @property
    def circles(self) -> np.ndarray:
        """(K, 3) round obstacles ``[cx, cy, r]`` (read-only)."""
        if 'circ' not in self._cache:
            self._cache['circ'] = _readonly(np.array(self._circ, dtype=float).reshape(-1, 3))
        return self._cache['circ']

    def walls(self) -> Walls:
        """Return all segments with ids (line ground truth)."""
        return Walls(ids=_readonly(np.array(self._seg_ids, dtype=np.int64)),
                     segments=self.segments,
                     two_sided=_readonly(np.array(self._seg_two, dtype=bool)),
                     labels=tuple(self._seg_labels))

    def round_obstacles(self) -> RoundObstacles:
        """Return all round obstacles with ids (point-landmark ground truth)."""
        return RoundObstacles(ids=_readonly(np.array(self._circ_ids, dtype=np.int64)),
                              circles=self.circles, labels=tuple(self._circ_labels))

    def bounds(self) -> Tuple[float, float, float, float]:
        """Axis-aligned bounding box ``(xmin, ymin, xmax, ymax)`` of all geometry."""
        xs = [self.segments[:, 0], self.segments[:, 2],
              self.circles[:, 0] - self.circles[:, 2], self.circles[:, 0] + self.circles[:, 2]]
        ys = [self.segments[:, 1], self.segments[:, 3],
              self.circles[:, 1] - self.circles[:, 2], self.circles[:, 1] + self.circles[:, 2]]
        x = np.concatenate(xs)
        y = np.concatenate(ys)
        return float(x.min()), float(y.min()), float(x.max()), float(y.max())

    # ------------------------------------------------------------------ corners
    def corners(self) -> Corners:
        """Return the ground-truth corners; see the module docstring for the conventions."""
        if 'corners' in self._cache:
            return self._cache['corners']
        seg = self.segments
        one = ~np.array(self._seg_two, dtype=bool)
        rows = np.flatnonzero(one)
        ids = np.array(self._seg_ids, dtype=np.int64)
        # (A, B) matrix: end of segment a coincides with start of segment b.
        end = seg[rows, 2:]
        start = seg[rows, :2]
        gap = np.hypot(end[:, None, 0] - start[None, :, 0], end[:, None, 1] - start[None, :, 1])
        ia, ib = np.nonzero(gap <= VERTEX_TOL)
        a, b = rows[ia], rows[ib]
        da = seg[a, 2:] - seg[a, :2]
        db = seg[b, 2:] - seg[b, :2]
        ha = np.arctan2(da[:, 1], da[:, 0])
        hb = np.arctan2(db[:, 1], db[:, 0])
        turn = wrap_angle(hb - ha)  # signed heading change, + = left
        keep = (np.abs(turn) >= MIN_CORNER_TURN) & (a != b)
        a, b, hb, turn = a[keep], b[keep], hb[keep], turn[keep]
        opening = math.pi - turn
        # Free wedge spans from the outgoing direction CCW to the reversed incoming one.
        bisector = wrap_angle(hb + 0.5 * opening)
        order = np.lexsort((b, a))
        a, b = a[order], b[order]
        out = Corners(ids=_readonly(np.arange(a.shape[0], dtype=np.int64)),
                      positions=_readonly(seg[a, 2:].copy()),
                      bisectors=_readonly(bisector[order]),
                      openings=_readonly(opening[order]),
                      segment_ids=_readonly(np.stack([ids[a], ids[b]], axis=1).reshape(-1, 2)))
        self._cache['corners'] = out
        return out

    def visible_corners(self, sensor_pose: Sequence[float], max_range: float,
                        fov: float = TWO_PI, both_sides: bool = False,
                        tol: float = 1e-6) -> np.ndarray:
        """Return ids of corners visible from ``sensor_pose`` ``[x, y, yaw]``.

        A corner is visible if it lies within ``max_range`` and within +-``fov``/2 of the
        sensor heading, the sensor is inside the corner's free-space wedge, and the line of
        sight is not blocked by any segment or circle (``tol`` metres slack). With
        ``both_sides`` the sensor must also see both walls' faces (for a convex corner: within
        the wedge between the two walls' supporting lines, +-(pi - opening/2) of the bisector).
        """
        c = self.corners()
        if len(c) == 0:
            return np.zeros(0, dtype=np.int64)
        px, py, yaw = (float(v) for v in sensor_pose)
        rel = c.positions - np.array([px, py])
        dist = np.hypot(rel[:, 0], rel[:, 1])
        bearing = wrap_angle(np.arctan2(rel[:, 1], rel[:, 0]) - yaw)
        ok = (dist <= max_range) & (dist > 0.0) & (np.abs(bearing) <= 0.5 * fov + 1e-12)
        back = wrap_angle(np.arctan2(-rel[:, 1], -rel[:, 0]) - c.bisectors)
        half = 0.5 * c.openings
        if both_sides:
            half = np.where(c.openings > math.pi, math.pi - 0.5 * c.openings, half)
        ok &= np.abs(back) < half
        idx = np.flatnonzero(ok)
        if idx.size:
            ang = np.arctan2(rel[idx, 1], rel[idx, 0])
            hits = self.raycast(np.array([[px, py]]), ang)
            clear = hits.ranges >= dist[idx] - tol
            idx = idx[clear]
        return c.ids[idx].copy()

    # ------------------------------------------------------------------ ray casting
    def raycast(self, origins: Any, angles: Any, max_range: float = math.inf) -> RayHits:
        """Cast N rays (vectorised) and return the first hit of each.

        Args:
            origins: (N, 2) ray origins, or (1, 2) / (2,) shared by all rays.
            angles: (N,) world-frame ray directions in radians.
            max_range: hits farther than this are reported as no hit (``inf``).

        Returns:
            RayHits with ranges ``inf`` where nothing is hit within ``max_range``.
        """
        ang = np.asarray(angles, dtype=float).reshape(-1)
        o = np.asarray(origins, dtype=float).reshape(-1, 2)
        o = np.broadcast_to(o, (ang.shape[0], 2))
        n = ang.shape[0]
        dx, dy = np.cos(ang), np.sin(ang)
        best = np.full(n, math.inf)
        kind = np.zeros(n, dtype=np.int8)
        index = np.full(n, -1, dtype=np.int64)
        cosi = np.full(n, math.nan)
        seg = self.segments
        if seg.shape[0] and n:
            ex = seg[:, 2] - seg[:, 0]
            ey = seg[:, 3] - seg[:, 1]
            wx = seg[None, :, 0] - o[:, 0:1]
            wy = seg[None, :, 1] - o[:, 1:2]
            denom = dx[:, None] * ey[None, :] - dy[:, None] * ex[None, :]  # d x e
            with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
                t = (wx * ey[None, :] - wy * ex[None, :]) / denom  # (w x e) / (d x e)
                s = (wx * dy[:, None] - wy * dx[:, None]) / denom  # (w x d) / (d x e)
            valid = (denom != 0.0) & (t > 0.0) & (s >= -_S_SLACK) & (s <= 1.0 + _S_SLACK)
            t = np.where(valid, t, math.inf)
            j = np.argmin(t, axis=1)
            tj = t[np.arange(n), j]
            hit = np.isfinite(tj)
            best = np.where(hit, tj, best)
            kind[hit] = HIT_SEGMENT
            index[hit] = j[hit]
            seg_len = np.hypot(ex, ey)
            cos_seg = np.abs(denom[np.arange(n), j]) / seg_len[j]
            cosi = np.where(hit, cos_seg, cosi)
        circ = self.circles
        if circ.shape[0] and n:
            ox = o[:, 0:1] - circ[None, :, 0]
            oy = o[:, 1:2] - circ[None, :, 1]
            bb = dx[:, None] * ox + dy[:, None] * oy
            cc = ox * ox + oy * oy - circ[None, :, 2] ** 2
            disc = bb * bb - cc
            sq = np.sqrt(np.maximum(disc, 0.0))
            t1 = -bb - sq
            t2 = -bb + sq
            t = np.where(t1 > 0.0, t1, t2)
            t = np.where((disc >= 0.0) & (t > 0.0), t, math.inf)
            j = np.argmin(t, axis=1)
            tj = t[np.arange(n), j]
            closer = tj < best
            best = np.where(closer, tj, best)
            kind[closer] = HIT_CIRCLE
            index[closer] = j[closer]
            # Normal at the hit is (o + t d - c) / r, so |cos| = |b + t| / r.
            cos_c = np.abs(bb[np.arange(n), j] + tj) / circ[j, 2]
            cosi = np.where(closer, np.minimum(cos_c, 1.0), cosi)
        far = best > max_range
        best[far] = math.inf
        kind[far] = HIT_NONE
        index[far] = -1
        cosi[far] = math.nan
        seg_ids = np.array(self._seg_ids, dtype=np.int64)
        circ_ids = np.array(self._circ_ids, dtype=np.int64)
        ids = np.full(n, -1, dtype=np.int64)
        m = kind == HIT_SEGMENT
        ids[m] = seg_ids[index[m]]
        m = kind == HIT_CIRCLE
        ids[m] = circ_ids[index[m]]
        return RayHits(ranges=best, kind=kind, index=index, ids=ids, cos_incidence=cosi)

    def clearance(self, points: Any) -> np.ndarray:
        """Distance (N,) from each point to the nearest obstacle surface (vectorised)."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        out = np.full(p.shape[0], math.inf)
        seg = self.segments
        if seg.shape[0]:
            a = seg[None, :, :2]
            e = seg[None, :, 2:] - a
            w = p[:, None, :] - a
            u = np.clip(np.sum(w * e, axis=2) / np.sum(e * e, axis=2), 0.0, 1.0)
            d = w - u[..., None] * e
            out = np.minimum(out, np.hypot(d[..., 0], d[..., 1]).min(axis=1))
        circ = self.circles
        if circ.shape[0]:
            d = np.hypot(p[:, None, 0] - circ[None, :, 0], p[:, None, 1] - circ[None, :, 1])
            out = np.minimum(out, (d - circ[None, :, 2]).min(axis=1))
        return out

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> Dict[str, Any]:
        """Plain-dict form (lists, floats, ints, strings) for YAML; see :meth:`from_dict`.

        The ``corners`` entry is derived ground truth for convenience; it is ignored by
        :meth:`from_dict` (corners are recomputed from the segments).
        """
        c = self.corners()
        return {
            'format': 'landmark_nav.sim.World',
            'version': 1,
            'name': self.name,
            'segments': [
                {'id': int(i), 'points': [float(v) for v in s], 'two_sided': bool(t),
                 'label': lab}
                for i, s, t, lab in zip(self._seg_ids, self._seg, self._seg_two,
                                        self._seg_labels)],
            'circles': [
                {'id': int(i), 'center': [float(cc[0]), float(cc[1])], 'radius': float(cc[2]),
                 'label': lab}
                for i, cc, lab in zip(self._circ_ids, self._circ, self._circ_labels)],
            'corners': [
                {'id': int(c.ids[k]), 'position': [float(v) for v in c.positions[k]],
                 'bisector': float(c.bisectors[k]), 'opening': float(c.openings[k]),
                 'segment_ids': [int(v) for v in c.segment_ids[k]]}
                for k in range(len(c))],
        }

    @classmethod
    def from_dict(cls, data: Dict[str, Any]) -> 'World':
        """Rebuild a world saved by :meth:`to_dict` (bit-exact geometry and ids)."""
        if not isinstance(data, dict) or 'segments' not in data:
            raise ValueError('not a World dict (missing "segments")')
        w = cls(name=data.get('name', 'world'))
        for s in data['segments']:
            w.add_segment(*s['points'], label=s.get('label', 'wall'),
                          two_sided=bool(s.get('two_sided', True)), segment_id=s['id'])
        for c in data.get('circles', []):
            w.add_circle(c['center'][0], c['center'][1], c['radius'],
                         label=c.get('label', 'leg'), circle_id=c['id'])
        return w


def _signed_area(pts: np.ndarray) -> float:
    """Shoelace signed area (positive for counter-clockwise vertices)."""
    x, y = pts[:, 0], pts[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
