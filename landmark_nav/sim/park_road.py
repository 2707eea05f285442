"""Park road terrain (height field) and a tilted 2-D laser ray-cast on it, with exact truth.

A straight road along the world x axis, centred on ``y = 0``: a crowned (convex) surface
``z = crown (1 - (2 y / W)^2)`` of true width ``W`` (asphalt or gravel), flat shoulders
of ``shoulder`` metres each side (as rough as gravel), then grass (rough). Optional: a
kerb (a step up of ``kerb`` metres at the road edges instead of shoulders), a flat horse
track crossing the road at ``x`` in ``crossing``, and upright cylinders (pedestrians,
posts). Surface roughness is a fixed pseudo-random height field (bilinear between grid
nodes ``cell`` metres apart) with a per-surface amplitude, so the truth is exact and
repeatable for a seed.

Truth classes of a laser reading: road and horse track are traversable; shoulders (a rough
verge), grass, kerb faces and cylinders are not (``landmark_nav.road.terrain`` class
numbers). The road width of Table 3 is the width of the road proper, shoulders excluded.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence

from landmark_nav.road.terrain import LaserMount, NOT_TRAVERSABLE, TRAVERSABLE
import numpy as np

#: Surface codes of :meth:`ParkRoad.surface`.
ROAD, SHOULDER, GRASS, TRACK, KERB, OBJECT = range(6)

#: Road kinds of Table 3: (true width [m], crown [m], roughness amplitude [m]).
ROAD_KINDS = {'asphalt': (4.9, 0.08, 0.002), 'gravel': (4.0, 0.15, 0.006)}


@dataclass(frozen=True)
class ParkRoad:
    """A straight park road with shoulders, grass and optional features (metres)."""

    width: float = 4.9
    crown: float = 0.08
    road_rough: float = 0.002
    shoulder: float = 0.6
    shoulder_rough: float = 0.015
    grass_rough: float = 0.06
    track_rough: float = 0.005
    kerb: float = 0.0
    crossing: Optional[tuple] = None        # (x_min, x_max) of a flat horse track
    cylinders: tuple = ()                   # ((x, y, radius, height), ...)
    cell: float = 0.05
    seed: int = 0

    @classmethod
    def of_kind(cls, kind: str, **kwargs) -> 'ParkRoad':
        """Return the road of a Table 3 kind ('asphalt' or 'gravel')."""
        if kind not in ROAD_KINDS:
            raise ValueError(f'unknown road kind {kind!r}; one of {sorted(ROAD_KINDS)}')
        w, c, rough = ROAD_KINDS[kind]
        return cls(width=w, crown=c, road_rough=rough, **kwargs)

    def _noise(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Return a fixed unit-amplitude random height field, bilinear between grid nodes."""
        gx, gy = x / self.cell, y / self.cell
        ix, iy = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
        fx, fy = gx - ix, gy - iy

        def node(i, j):
            h = (i * 73856093) ^ (j * 19349663) ^ (self.seed * 83492791)
            h = (h ^ (h >> 13)) * 1274126177
            return ((h & 0xFFFF) / 32767.5) - 1.0
        return ((1 - fx) * (1 - fy) * node(ix, iy) + fx * (1 - fy) * node(ix + 1, iy)
                + (1 - fx) * fy * node(ix, iy + 1) + fx * fy * node(ix + 1, iy + 1))

    def surface(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface code at ground points (x, y) (cylinders excluded)."""
        ay = np.abs(y)
        half = 0.5 * self.width
        out = np.full(np.shape(x), GRASS, dtype=np.int8)
        if self.kerb <= 0.0:
            out[ay <= half + self.shoulder] = SHOULDER
        if self.crossing is not None:
            out[(x >= self.crossing[0]) & (x <= self.crossing[1])] = TRACK
        out[ay <= half] = ROAD
        return out

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ground height at (x, y) [m] (cylinders excluded)."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        half = 0.5 * self.width
        surf = self.surface(x, y)
        amp = np.choose(np.minimum(surf, 3), [self.road_rough, self.shoulder_rough,
                                              self.grass_rough, self.track_rough])
        z = amp * self._noise(x, y)
        road = surf == ROAD
        z = np.where(road, z + self.crown * (1.0 - (y / half) ** 2), z)
        if self.kerb > 0.0:
            z = np.where(road, z, z + self.kerb)
        return z

    def edges(self) -> tuple[float, float]:
        """Return the true road edges, right and left of the centre line [m]."""
        return -0.5 * self.width, 0.5 * self.width


@dataclass(frozen=True, eq=False)
class TiltedScan:
    """One simulated scan with its truth (arrays read-only)."""

    angles: np.ndarray       # (N,) [rad]
    ranges: np.ndarray       # (N,) [m]; +inf = no return
    hits: np.ndarray         # (N, 3) true hit points in the world (NaN: none)
    truth: np.ndarray        # (N,) TRAVERSABLE / NOT_TRAVERSABLE / 0 (no hit)
    surface: np.ndarray      # (N,) surface code (-1: none)


def _rotation_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def cast_scan(road: ParkRoad, pose: Sequence[float], mount: LaserMount,
              angles: np.ndarray, range_max: float = 8.0, sigma_range: float = 0.005,
              rng: Optional[np.random.Generator] = None, step: float = 0.01) -> TiltedScan:
    """Ray-cast a tilted 2-D laser at robot pose (x, y, yaw) on the terrain.

    Each beam is marched in ``step`` metres to ``range_max``; the first crossing of the
    height field is refined by linear interpolation; upright cylinders are intersected
    exactly. Range noise is Gaussian with ``sigma_range``.
    """
    a = np.asarray(angles, dtype=float)
    rot = _rotation_z(pose[2]) @ mount.rotation()
    origin = _rotation_z(pose[2]) @ mount.translation() + np.array([pose[0], pose[1], 0.0])
    dirs = (rot @ np.vstack([np.cos(a), np.sin(a), np.zeros_like(a)])).T       # (N, 3)
    # March each beam only through the slab of heights the terrain can have, in at most
    # ``max_steps`` steps of at least ``step`` metres.
    amp = max(road.road_rough, road.shoulder_rough, road.grass_rough)
    z_hi, z_lo = road.crown + road.kerb + amp, -amp
    ranges = np.full(a.size, np.inf)
    down = dirs[:, 2] < -1e-6
    rate = np.where(down, -dirs[:, 2], 1.0)
    t0 = np.clip((origin[2] - z_hi) / rate - step, 0.0, range_max)
    t1 = np.clip((origin[2] - z_lo) / rate + step, 0.0, range_max)
    max_steps = 300
    h = np.maximum((t1 - t0) / max_steps, step)
    t = t0[:, None] + h[:, None] * np.arange(max_steps + 1)[None, :]      # (N, T)
    p = origin + dirs[:, None, :] * t[..., None]                          # (N, T, 3)
    below = (p[..., 2] <= road.height(p[..., 0], p[..., 1])) & (t <= range_max)
    first = np.where(below.any(axis=1) & down, below.argmax(axis=1), -1)
    has = first > 0
    k = first[has]
    rows = np.flatnonzero(has)
    g0 = p[rows, k - 1, 2] - road.height(p[rows, k - 1, 0], p[rows, k - 1, 1])
    g1 = p[rows, k, 2] - road.height(p[rows, k, 0], p[rows, k, 1])
    frac = g0 / np.maximum(g0 - g1, 1e-12)
    ranges[rows] = t[rows, k - 1] + frac * h[rows]
    surf = np.full(a.size, -1, dtype=np.int8)
    for cx, cy, radius, height in road.cylinders:
        d = dirs[:, :2]
        o = origin[:2] - np.array([cx, cy])
        qa = np.sum(d * d, axis=1)
        qb = 2.0 * d @ o
        qc = o @ o - radius ** 2
        disc = qb * qb - 4.0 * qa * qc
        ok = disc >= 0
        tc = np.where(ok, (-qb - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * np.maximum(qa, 1e-12)),
                      np.inf)
        zc = origin[2] + dirs[:, 2] * tc
        hit = ok & (tc > 0) & (tc < ranges) & (zc <= height)
        ranges[hit] = tc[hit]
        surf[hit] = OBJECT
    hits = np.where(np.isfinite(ranges)[:, None], origin + dirs * ranges[:, None], np.nan)
    ground = np.isfinite(ranges) & (surf != OBJECT)
    surf[ground] = road.surface(hits[ground, 0], hits[ground, 1])
    if road.kerb > 0.0:   # readings on the kerb face (within 3 cm of the road edge)
        near = ground & (np.abs(np.abs(hits[:, 1]) - 0.5 * road.width) < 0.03)
        surf[near] = KERB
    truth = np.zeros(a.size, dtype=np.int8)
    truth[np.isin(surf, (ROAD, TRACK))] = TRAVERSABLE
    truth[np.isin(surf, (SHOULDER, GRASS, KERB, OBJECT))] = NOT_TRAVERSABLE
    if rng is not None and sigma_range > 0.0:
        fin = np.isfinite(ranges)
        ranges[fin] += rng.normal(0.0, sigma_range, int(fin.sum()))
    for arr in (a, ranges, hits, truth, surf):
        arr.setflags(write=False)
    return TiltedScan(a.copy(), ranges, hits, truth, surf)


@dataclass(frozen=True)
class Lighting:
    """Light of a rendered view: overcast, or sun with soft or hard shadow bands.

    ``shadows`` are (x_min, x_max) bands across the road in the world (tree shadows), dimmed
    to ``shadow_level`` of the lit intensity and tinted blue by ``shadow_tint`` (skylight);
    ``soft`` metres of linear transition at their borders (0: hard); with ``period`` > 0 the
    bands repeat every ``period`` metres along x (a row of trees).
    """

    shadows: tuple = ()
    period: float = 0.0
    shadow_level: float = 0.45
    shadow_tint: float = 0.08
    soft: float = 0.0


#: Surface colours (RGB, 0-255) and texture amplitudes (the shoulder: a grassy verge).
_COLOURS = {ROAD: ((105, 105, 110), 10.0), SHOULDER: ((105, 118, 72), 18.0),
            GRASS: ((70, 120, 50), 22.0), TRACK: ((140, 120, 90), 14.0)}
_GRAVEL = ((150, 138, 115), 14.0)


_GROUND_RAYS: dict = {}


def _ground_rays(camera, mount: Sequence[float]) -> tuple:
    """Return every pixel ``(u, v)`` (H * W, 2), its ray (base_link) and ground point (x, y).

    The same for every frame of one camera and mount: computed once per camera (its
    parameters) and mount, read-only.
    """
    from landmark_nav.corridor.orientation import mount_rotation
    from landmark_nav.road.fusion import pixels_to_ground
    arrays = (camera.K, camera.D, camera.R, camera.P)
    key = (camera.width, camera.height, camera.distortion_model,
           tuple(None if a is None else np.asarray(a, dtype=float).tobytes() for a in arrays),
           tuple(float(m) for m in mount))
    found = _GROUND_RAYS.get(key)
    if found is None:
        vv, uu = np.mgrid[0:camera.height, 0:camera.width]
        px = np.column_stack([uu.ravel(), vv.ravel()]).astype(float)
        rays = camera.back_project(px) @ mount_rotation(mount).T
        g = pixels_to_ground(camera, mount, px, max_distance=200.0)
        for a in (px, rays, g):
            a.setflags(write=False)
        found = (px, rays, g)
        if len(_GROUND_RAYS) >= 4:
            _GROUND_RAYS.clear()
        _GROUND_RAYS[key] = found
    return found  # not read back: another thread may clear the cache in between


def render_view(road: ParkRoad, pose: Sequence[float], camera, mount: Sequence[float],
                lighting: Lighting = Lighting(), markings: bool = False,
                rng: Optional[np.random.Generator] = None, gravel: bool = False) -> np.ndarray:
    """Render the terrain seen by a camera at robot pose (x, y, yaw): (H, W, 3) uint8 RGB.

    Flat-ground ray casting (the crown's few centimetres are ignored for the image):
    each pixel's ray meets the ground plane; its colour is the surface's colour with a
    fixed texture (the terrain's noise field), lit by ``lighting``; rays above the horizon
    see the sky; upright cylinders (pedestrians) in front of the ground are dark grey.
    ``markings`` paints a dashed white centre line.
    """
    h, w = camera.height, camera.width
    px, rays, g = _ground_rays(camera, mount)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    wx = pose[0] + c * g[:, 0] - s * g[:, 1]
    wy = pose[1] + s * g[:, 0] + c * g[:, 1]
    sky = ~np.isfinite(wx)
    wx = np.where(sky, 0.0, wx)
    wy = np.where(sky, 0.0, wy)
    surf = road.surface(wx, wy)
    img = np.zeros((px.shape[0], 3))
    for code, (rgb, amp) in _COLOURS.items():
        if code == ROAD and gravel:
            rgb, amp = _GRAVEL
        m = surf == code
        tex = amp * road._noise(wx[m] * 7.0, wy[m] * 7.0)
        img[m] = np.array(rgb, dtype=float) + tex[:, None]
    if markings:
        dash = (np.abs(wy) < 0.06) & (np.mod(wx, 3.0) < 1.5) & (surf == ROAD)
        img[dash] = (235, 235, 230)
    light = np.ones(px.shape[0])
    tint = np.zeros(px.shape[0])
    sx = np.mod(wx, lighting.period) if lighting.period > 0.0 else wx
    for x0, x1 in lighting.shadows:
        if lighting.soft > 0.0:
            inside = np.clip(np.minimum(sx - x0, x1 - sx) / lighting.soft + 0.5, 0.0, 1.0)
        else:
            inside = ((sx >= x0) & (sx <= x1)).astype(float)
        light = np.minimum(light, 1.0 - (1.0 - lighting.shadow_level) * inside)
        tint = np.maximum(tint, lighting.shadow_tint * inside)
    img = img * light[:, None]
    img[:, 2] *= 1.0 + tint
    img[sky] = (170, 200, 235)
    if road.cylinders:
        rays_hit = _cylinder_pixels(road, pose, mount, rays, g)
        img[rays_hit] = (45, 40, 50)
    if rng is not None:
        img += rng.normal(0.0, 2.0, img.shape)
    return np.clip(img, 0, 255).reshape(h, w, 3).astype(np.uint8)


def _cylinder_pixels(road: ParkRoad, pose, mount, rays: np.ndarray,
                     ground: np.ndarray) -> np.ndarray:
    """Pixels whose ray (base_link) meets an upright cylinder before the ground."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    d = rays @ rot.T
    o = rot @ np.asarray(mount[:3], dtype=float) + np.array([pose[0], pose[1], 0.0])
    t_ground = np.where(np.isfinite(ground[:, 0]),
                        np.linalg.norm(ground - np.asarray(mount[:2]), axis=1)
                        / np.maximum(np.linalg.norm(rays[:, :2], axis=1), 1e-12), np.inf)
    hit = np.zeros(rays.shape[0], dtype=bool)
    for cx, cy, radius, height in road.cylinders:
        oc = o[:2] - np.array([cx, cy])
        qa = np.sum(d[:, :2] ** 2, axis=1)
        qb = 2.0 * d[:, :2] @ oc
        qc = oc @ oc - radius ** 2
        disc = qb * qb - 4.0 * qa * qc
        t = np.where(disc >= 0, (-qb - np.sqrt(np.maximum(disc, 0.0)))
                     / (2.0 * np.maximum(qa, 1e-12)), np.inf)
        z = o[2] + d[:, 2] * t
        hit |= (t > 0) & (t < t_ground) & (z >= 0.0) & (z <= height)
    return hit
