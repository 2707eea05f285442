"""Sonar model (section 2.2) and sonar measurement prediction (section 4.1, eqs. 21-23).

Angles are in radians (the chapter writes degrees; eq. 10 only uses the ratio
``Theta / Theta_0``), lengths in metres. ``mounts`` are the (S, 3) transducer poses
``[x, y, yaw]`` in base_link (:data:`landmark_nav.sim.sonar.SONAR_MOUNTS`).
"""

import math
from typing import Any, Optional, Tuple

import numpy as np

from .grid import GridMap, raycast_grid_hits

#: Half of the main lobe angle, Theta_0 (Polaroid 6500: 12.5 deg) [rad].
THETA0 = math.radians(12.5)
#: Visibility radius rho_v recommended for indoor environments [m].
RHO_V = 1.2
#: Predictions farther than this are discarded (section 4.1) [m].
MAX_PREDICT = 3.0


def angular_modulation(theta: Any, theta0: float = THETA0) -> np.ndarray:
    """Angular modulation alpha(Theta), the main lobe pattern (eq. 10).

    Args:
        theta: angle(s) between the sonar axis and the cell [rad].
        theta0: half main-lobe angle Theta_0 [rad].

    Returns:
        ``1 - (Theta / Theta_0)^2`` for ``|Theta| <= Theta_0``, 0 outside.
    """
    t = np.asarray(theta, dtype=float)
    return np.where(np.abs(t) <= theta0, 1.0 - (t / theta0) ** 2, 0.0)  # eq. 10


def radial_modulation(rho: Any, rho_v: float = RHO_V) -> np.ndarray:
    """Radial modulation Delta(rho) (eq. 11).

    Args:
        rho: distance(s) from the sonar to the cell [m].
        rho_v: visibility radius rho_v [m].

    Returns:
        ``1 - (1 + tanh(2 (rho - rho_v))) / 2`` (1 near the sonar, 0.5 at ``rho_v``).
    """
    r = np.asarray(rho, dtype=float)
    return 1.0 - 0.5 * (1.0 + np.tanh(2.0 * (r - rho_v)))  # eq. 11


def sonar_global_poses(robot_poses: Any, mounts: Any) -> np.ndarray:
    """Sonar poses in the global frame from robot pose(s) (eqs. 21-23).

    With ``S_offD = |(mx, my)|``, ``S_offTheta = atan2(my, mx)`` and ``S_sensTheta = myaw``.

    Args:
        robot_poses: (..., 3) robot poses ``[x, y, Theta]``.
        mounts: (S, 3) sonar poses in base_link.

    Returns:
        (..., S, 3) sonar poses ``[S_XG, S_YG, S_ThetaG]``.
    """
    p = np.asarray(robot_poses, dtype=float)[..., None, :]
    m = np.asarray(mounts, dtype=float).reshape(-1, 3)
    off_d = np.hypot(m[:, 0], m[:, 1])
    off_th = np.arctan2(m[:, 1], m[:, 0])
    sx = p[..., 0] + off_d * np.cos(off_th + p[..., 2])  # eq. 21
    sy = p[..., 1] + off_d * np.sin(off_th + p[..., 2])  # eq. 22
    sth = p[..., 2] + m[:, 2]  # eq. 23
    return np.stack([sx, sy, sth], axis=-1)


def predict_ranges(grid: GridMap, robot_poses: Any, mounts: Any,
                   max_predict: float = MAX_PREDICT, cone_rays: int = 1,
                   theta0: float = THETA0, specular_angle: Optional[float] = None,
                   unknown: str = 'invalid', ray_offsets: Any = None,
                   return_ray: bool = False) -> Any:
    """Predicted sonar ranges for P robot poses and S sonars in ONE ray-casting call.

    Section 4.1: the centre of the sound beam is propagated from the sonar (eqs. 21-23)
    through the occupancy grid until it hits an occupied cell; the beam length is the
    predicted reading; predictions beyond ``max_predict`` (3.0 m) are discarded.

    Two optional extensions model what a Polaroid transducer reports, the FIRST echo
    inside its lobe: ``cone_rays > 1`` casts that many rays spread evenly over
    ``[-theta0, theta0]`` and predicts the nearest hit; ``specular_angle`` drops rays that
    meet a wall (normal from :func:`~.grid.wall_normals`) at a larger angle of incidence,
    as a smooth wall reflects them away (corners and wall ends echo from any direction).

    Args:
        grid: the occupancy grid.
        robot_poses: (P, 3) (or (3,)) robot poses.
        mounts: (S, 3) sonar poses in base_link.
        max_predict: predictions beyond this are discarded [m].
        cone_rays: 1 = the chapter's centre beam; n > 1 = nearest echo of n rays.
        theta0: half lobe angle used when ``cone_rays > 1`` [rad].
        specular_angle: largest angle of incidence that still echoes [rad]; None = all.
        unknown: treatment of unknown cells, see :func:`~.grid.raycast_grid`.
        ray_offsets: (S,) if given, cast only the ray at this angle from each sonar's axis
            [rad] (e.g. the echoing ray of the cone, for derivatives); overrides
            ``cone_rays``.
        return_ray: also return the (P, S) angle offset of the ray giving each prediction
            (nan where none).

    Returns:
        (P, S) predicted ranges [m]; ``nan`` where discarded (no echo predicted within
        ``max_predict``, or a ray reaches an unknown cell first). With ``return_ray``, a
        tuple ``(ranges, offsets)``.
    """
    poses = np.asarray(robot_poses, dtype=float).reshape(-1, 3)
    sensors = sonar_global_poses(poses, mounts)  # (P, S, 3), eqs. 21-23
    n_p, n_s = sensors.shape[:2]
    if ray_offsets is not None:
        offs = np.asarray(ray_offsets, dtype=float).reshape(1, n_s, 1)
    elif cone_rays <= 1:
        offs = np.zeros((1, 1, 1))
    else:
        offs = np.linspace(-theta0, theta0, int(cone_rays)).reshape(1, 1, -1)
    n_r = offs.shape[2]
    ang = sensors[:, :, None, 2] + offs
    org = np.broadcast_to(sensors[:, :, None, :2], (n_p, n_s, n_r, 2))
    hits = raycast_grid_hits(grid, org.reshape(-1, 2), ang.reshape(-1), max_predict,
                             unknown=unknown)
    r = hits.ranges
    if specular_angle is not None:
        with np.errstate(invalid='ignore'):
            away = hits.cos_incidence < np.cos(specular_angle)
        r = np.where(away, np.inf, r)
    r = r.reshape(n_p, n_s, n_r)
    bad = np.isnan(r).any(axis=2)
    r = np.where(np.isnan(r), np.inf, r)
    k = np.argmin(r, axis=2)
    best = np.take_along_axis(r, k[..., None], axis=2)[..., 0]
    best = np.where(bad | ~np.isfinite(best), np.nan, best)
    if not return_ray:
        return best
    ray = np.broadcast_to(offs, (n_p, n_s, n_r))
    ray = np.take_along_axis(ray, k[..., None], axis=2)[..., 0]
    return best, np.where(np.isnan(best), np.nan, ray)


def build_sonar_map(poses: Any, ranges: Any, mounts: Any, resolution: float = 0.1,
                    bounds: Optional[Tuple[float, float, float, float]] = None,
                    margin: float = 0.5, min_range: float = 0.1,
                    max_range: float = MAX_PREDICT, theta0: float = THETA0,
                    rho_v: float = RHO_V, arc_width: Optional[float] = None,
                    l_occ: float = 0.3, l_free: float = -0.5, l_clamp: float = 8.0,
                    l_decide: float = 0.5) -> GridMap:
    """Occupancy-grid mapping from sonar readings taken at known poses (section 2.2).

    Log-odds rule, one cell update per reading, weighted by the sonar model: for a reading
    ``z`` from a sonar at ``(S_XG, S_YG, S_ThetaG)`` and a cell at distance ``rho`` and angle
    ``Theta`` from the sonar axis with ``|Theta| <= Theta_0``:

    * occupied arc, ``z - res / 2 <= rho < z - res / 2 + arc_width`` (1 to 2 cells wide;
      placed so that the innermost arc cells have their centres at ``z`` on average, the
      ray caster measuring to cell centres): ``l += alpha(Theta) Delta(rho) l_occ``;
    * empty space before the arc, ``rho < z - res / 2``:
      ``l += alpha(Theta) Delta(rho) l_free``;

    with alpha eq. 10 and Delta eq. 11 (emphasis on the beam axis and on short ranges).
    Readings outside ``[min_range, max_range]``, ``+-inf`` and ``nan`` are not used (a
    missing echo may be a specular reflection, not free space). Cells with
    ``l >= l_decide`` become occupied (100), ``l <= -l_decide`` free (0), never updated or
    undecided cells unknown (-1). Vectorised over all sonars of a time step (cells of a
    common window around the robot). ``l_free`` outweighs ``l_occ``: the parts of an arc
    where there is no obstacle (a sonar reports the nearest echo in its whole lobe) are
    cleared by the free space of other readings. Such a map keeps unexplored gaps inside
    the free space; localize on it with ``LocalizationParams(unknown='free')``.

    Args:
        poses: (T, 3) robot poses (ground truth or localised).
        ranges: (T, S) sonar readings [m].
        mounts: (S, 3) sonar poses in base_link.
        resolution: cell size [m].
        bounds: ``(xmin, ymin, xmax, ymax)`` of the map; default: the sonar positions
            and all used arcs, plus ``margin``.
        margin: border added to the default bounds [m].
        min_range: shortest usable reading [m].
        max_range: longest usable reading [m] (3.0 m, as for the prediction).
        theta0: half lobe angle Theta_0 [rad].
        rho_v: visibility radius rho_v [m].
        arc_width: width of the occupied arc [m], default 1.5 cells.
        l_occ: log-odds increment of a fully weighted occupied observation.
        l_free: log-odds increment of a fully weighted free observation (negative).
        l_clamp: log-odds are clamped to ``[-l_clamp, l_clamp]``.
        l_decide: decision threshold on the log-odds.

    Returns:
        The map (values -1 / 0 / 100, origin yaw 0).
    """
    res = float(resolution)
    arc = 1.5 * res if arc_width is None else float(arc_width)
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    z = np.asarray(ranges, dtype=float).reshape(p.shape[0], -1)
    m = np.asarray(mounts, dtype=float).reshape(-1, 3)
    sens = sonar_global_poses(p, m)  # (T, S, 3), eqs. 21-23
    with np.errstate(invalid='ignore'):
        use = np.isfinite(z) & (z >= min_range) & (z <= max_range)
    reach = max_range + arc
    if bounds is None:
        xy = sens[..., :2][use]
        if xy.size == 0:
            xy = p[:, :2]
        xmin, ymin = xy.min(axis=0) - reach - margin
        xmax, ymax = xy.max(axis=0) + reach + margin
    else:
        xmin, ymin, xmax, ymax = bounds
    w = int(math.ceil((xmax - xmin) / res))
    h = int(math.ceil((ymax - ymin) / res))
    logodds = np.zeros((h, w))
    seen = np.zeros((h, w), dtype=bool)
    half = int(math.ceil(reach / res)) + 1
    off = np.arange(-half, half + 1)
    for k in range(p.shape[0]):
        sel = np.flatnonzero(use[k])
        if sel.size == 0:
            continue
        zs = z[k, sel]
        s = sens[k, sel]
        # Common window of cells around the robot, centres in world coordinates.
        c0 = int(math.floor((p[k, 0] - xmin) / res))
        r0 = int(math.floor((p[k, 1] - ymin) / res))
        cols = c0 + off
        rows = r0 + off
        cc = (cols + 0.5) * res + xmin
        rc = (rows + 0.5) * res + ymin
        dx = cc[None, None, :] - s[:, 0, None, None]
        dy = rc[None, :, None] - s[:, 1, None, None]
        rho = np.hypot(dx, dy)  # (n, Hw, Ww)
        th = np.arctan2(dy, dx) - s[:, 2, None, None]
        th = (th + math.pi) % (2.0 * math.pi) - math.pi
        wgt = angular_modulation(th, theta0) * radial_modulation(rho, rho_v)  # eqs. 10-11
        near = zs[:, None, None] - 0.5 * res  # inner edge of the occupied arc
        occ = (rho >= near) & (rho < near + arc)
        free = rho < near
        upd = (np.where(occ, l_occ, 0.0) + np.where(free, l_free, 0.0)) * wgt
        touched = ((occ | free) & (wgt > 0.0)).any(axis=0)
        total = upd.sum(axis=0)
        rv = (rows >= 0) & (rows < h)
        cv = (cols >= 0) & (cols < w)
        sub = np.ix_(rows[rv], cols[cv])
        logodds[sub] = np.clip(logodds[sub] + total[np.ix_(rv, cv)], -l_clamp, l_clamp)
        seen[sub] |= touched[np.ix_(rv, cv)]
    occ_grid = np.full((h, w), -1, dtype=np.int8)
    occ_grid[seen & (logodds >= l_decide)] = 100
    occ_grid[seen & (logodds <= -l_decide)] = 0
    return GridMap(occupancy=occ_grid, resolution=res, origin=(float(xmin), float(ymin), 0.0))
