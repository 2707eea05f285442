"""Check a SLAM map against a building's occupancy grid (no trajectory truth needed).

For logs without a reference trajectory but with a map of the building (the CMU Wean Hall
runs and ``wean.dat``), a SLAM result is judged by where its landmarks and poses fall on
the grid after the best rigid alignment (the SLAM map frame is the odometry's start, the
grid has its own origin):

* landmark share: the share of mapped landmarks (corner positions) within ``tolerance``
  (10 cm) of a wall cell (grid value in ``[0, wall_max]``; the distance is to the cell's
  square);
* poses: the number of estimated poses in a wall cell or an unknown cell (value < 0);
* optionally scan end points placed with the estimated poses (:func:`scan_end_points`):
  the share within ``tolerance`` of a wall (bilinear distance transform between cell
  centres minus half a cell). A trajectory that is consistent puts the walls of
  successive scans on top of each other and on the building's walls; comparing that
  share for the filter's poses and for the odometry's tells whether SLAM helped.

Why a landmark is off the walls (:func:`landmark_diagnosis`, per corner of the final map,
under the alignment of the check): ``'on_wall'`` within ``tolerance``; ``'moved'``: its
observations placed with the filter's pose of their step lie on a wall (median within
``tolerance``) but the final estimate does not: later updates moved the map against the
trajectory that placed it (an inconsistent map, a drift corrected late); ``'few_views'``:
detected in the state at most ``confirm_hits`` times (the confirming scan included), i.e.
never re-observed after its candidate stage (clutter seen from one place);
``'off_grid'``: seen often and off the walls already where the filter placed it: a
structure the grid does not hold (an open door, furniture, a partition) or a local misfit
of the trajectory.

The alignment ``T = (t_x, t_y, theta)`` (map frame -> grid frame) maximises
``share of landmarks near a wall + share of poses in known non-wall cells``: for each
``theta`` of a 1 deg grid the score of every translation on the grid's cells is one
cross-correlation (FFT, :func:`scipy.signal.fftconvolve`) of the rasterised landmarks /
poses with the near-wall / open indicator grids; the best ``theta`` is refined on a 0.1 deg
grid, and the translation then continuously (Nelder-Mead on the mean clipped squared
distance of the landmarks to the walls, bilinear on the distance transform).

Grid file (:func:`load_occupancy_grid`): the Carnegie Mellon ``beesoft`` map format of
``wean.dat`` (plain or gzip): header lines ``robot_specifications->resolution <cm>``, then
``global_map[0]: <size_x> <size_y>`` and ``size_x`` lines of ``size_y`` values; ``-1`` is
unknown, the other values lie in [0, 1]. In ``wean.dat`` they are the probability that the
cell is *free* (1 in corridors, 0 on walls; its ``instruct.txt`` says occupied, the image
says otherwise), so walls are the values <= ``wall_max``. Line ``i`` holds the cells of
``x = i * resolution``, value ``j`` the cell of ``y = j * resolution`` (``prob[x][y]``
as the format's reader ``bee-map.c`` fills it).
"""

from dataclasses import dataclass, replace
import gzip
import math
from pathlib import Path
from typing import Dict, Optional, Tuple, Union

from landmark_nav.geometry import compose
from landmark_nav.slam.ekf_slam import CORNER
from landmark_nav.slam.slam_map import load_map
import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A grid map.

    Attributes:
        values: (NX, NY) cell values, ``values[i, j]`` at ``x = (i + 0.5) * resolution``,
            ``y = (j + 0.5) * resolution``; -1 unknown.
        resolution: Cell size [m].
        name: Where it came from (messages).
    """

    values: np.ndarray
    resolution: float
    name: str = 'grid'


def load_occupancy_grid(path: Union[str, Path]) -> OccupancyGrid:
    """Read a beesoft map file (module docstring), plain or ``.gz``.

    Raises:
        ValueError: Malformed file (names the file and line).
    """
    path = Path(path)
    opener = gzip.open if path.suffix == '.gz' else open
    with opener(path, 'rt') as f:
        lines = f.read().splitlines()
    resolution = None
    for n, line in enumerate(lines, 1):
        tok = line.split()
        if len(tok) == 2 and tok[0].endswith('->resolution'):
            try:
                resolution = float(tok[1]) / 100.0
            except ValueError:
                raise ValueError(f'{path}:{n}: resolution {tok[1]!r} is not a number') from None
        if tok and tok[0].startswith('global_map['):
            if len(tok) != 3:
                raise ValueError(f'{path}:{n}: expected "global_map[0]: size_x size_y"')
            try:
                nx, ny = int(tok[1]), int(tok[2])
            except ValueError:
                raise ValueError(f'{path}:{n}: map size {tok[1:]} is not two integers') from None
            rows = lines[n:n + nx]
            if len(rows) != nx:
                raise ValueError(f'{path}: {len(rows)} map lines after line {n}, expected {nx}')
            bad = next((k for k, r in enumerate(rows) if len(r.split()) != ny), None)
            if bad is not None:
                raise ValueError(f'{path}:{n + 1 + bad}: {len(rows[bad].split())} values, '
                                 f'expected {ny}')
            try:
                values = np.array([r.split() for r in rows], dtype=float)
            except ValueError as err:
                raise ValueError(f'{path}: map lines {n + 1}-{n + nx}: {err}') from None
            if resolution is None or not resolution > 0.0:
                raise ValueError(f'{path}: no positive robot_specifications->resolution '
                                 'before the map')
            return OccupancyGrid(values, resolution, str(path))
    raise ValueError(f'{path}: no "global_map[0]:" line')


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _transform(xy: np.ndarray, t: np.ndarray) -> np.ndarray:
    return xy @ _rot(t[2]).T + t[:2]


def _raster(xy: np.ndarray, res: float) -> Tuple[np.ndarray, np.ndarray]:
    """Count points per cell; return the counts and the cell of index (0, 0)."""
    ij = np.floor(xy / res).astype(np.int64)
    lo = ij.min(axis=0)
    ij -= lo
    counts = np.zeros(ij.max(axis=0) + 1)
    np.add.at(counts, (ij[:, 0], ij[:, 1]), 1.0)
    return counts, lo


class _GridCorrelation:
    """Cross-correlations of one grid with point rasters: ``fftconvolve``'s, grid FFT kept.

    :meth:`correlate` returns ``scipy.signal.fftconvolve(grid, counts[::-1, ::-1],
    mode='full')`` by the same operations (the real FFTs of both at the same padded size,
    the product, the inverse, cropped): the grid's FFT at a padded size is the same array
    for every raster padded to that size, so it is computed once per size (the rotations
    of a search mostly share a few sizes) instead of once per raster.
    """

    def __init__(self, grid: np.ndarray) -> None:
        """Correlate with ``grid`` (2-D, float)."""
        self.grid = grid
        self._spectra: Dict[Tuple[int, int], np.ndarray] = {}

    def correlate(self, counts: np.ndarray) -> np.ndarray:
        """Return ``fftconvolve(grid, counts[::-1, ::-1], mode='full')``."""
        from scipy import fft, signal  # here: scipy.signal takes 0.5 s to import
        kernel = counts[::-1, ::-1]
        if 1 in self.grid.shape or 1 in kernel.shape:  # fftconvolve broadcasts such an axis
            return signal.fftconvolve(self.grid, kernel, mode='full')
        shape = [self.grid.shape[a] + kernel.shape[a] - 1 for a in (0, 1)]
        padded = tuple(fft.next_fast_len(n, True) for n in shape)
        spectrum = self._spectra.get(padded)
        if spectrum is None:
            if len(self._spectra) >= 8:  # a few sizes recur; bound the memory
                self._spectra.clear()
            spectrum = self._spectra[padded] = fft.rfftn(self.grid, padded, axes=[0, 1])
        # grid spectrum times the raster's, in that order, as fftconvolve multiplies (a
        # temporary on the right would be multiplied in place, in the other order, which
        # rounds differently)
        raster = fft.rfftn(kernel, padded, axes=[0, 1])
        out = fft.irfftn(spectrum * raster, padded, axes=[0, 1])
        return out[:shape[0], :shape[1]].copy()


def _best_shift(near: _GridCorrelation, open_: _GridCorrelation, lm: np.ndarray,
                poses: np.ndarray, res: float) -> Tuple[float, np.ndarray]:
    """Best integer-cell translation for points already rotated: (score, translation)."""
    cl, lo_l = _raster(lm, res)
    cp, lo_p = _raster(poses, res)
    # score[s] = sum_k near[s + ij_k]: correlation = convolution with the flipped raster.
    sl = near.correlate(cl) / lm.shape[0]
    sp = open_.correlate(cp) / poses.shape[0]
    # sl[a] is the score of shift s = a - (shape(cl) - 1) - lo_l, likewise sp.
    off_l = np.array(cl.shape) - 1 + lo_l
    off_p = np.array(cp.shape) - 1 + lo_p
    d = off_p - off_l  # sp index = sl index + d for the same shift
    total = sl.copy()
    a0 = np.maximum(0, -d)
    a1 = np.minimum(np.array(sl.shape), np.array(sp.shape) - d)
    if np.all(a1 > a0):
        total[a0[0]:a1[0], a0[1]:a1[1]] += sp[a0[0] + d[0]:a1[0] + d[0],
                                              a0[1] + d[1]:a1[1] + d[1]]
    a = np.unravel_index(int(np.argmax(total)), total.shape)
    shift = (np.array(a) - off_l) * res
    return float(total[a]), shift


def _square_distance(grid_xy: np.ndarray, walls: cKDTree, res: float, reach: float
                     ) -> np.ndarray:
    """Distance of points to the nearest wall cell's square (inf beyond ``reach``)."""
    out = np.full(grid_xy.shape[0], np.inf)
    for k, idx in enumerate(walls.query_ball_point(grid_xy, reach + res)):
        if idx:
            c = walls.data[idx]
            dx = np.maximum(np.abs(grid_xy[k, 0] - c[:, 0]) - 0.5 * res, 0.0)
            dy = np.maximum(np.abs(grid_xy[k, 1] - c[:, 1]) - 0.5 * res, 0.0)
            out[k] = float(np.min(np.hypot(dx, dy)))
    return out


def _pool(a: np.ndarray, f: int) -> np.ndarray:
    """Max over f x f blocks (the coarse search's grids)."""
    nx, ny = (a.shape[0] + f - 1) // f, (a.shape[1] + f - 1) // f
    pad = np.zeros((nx * f, ny * f))
    pad[:a.shape[0], :a.shape[1]] = a
    return pad.reshape(nx, f, ny, f).max(axis=(1, 3))


def occupancy_check(grid: OccupancyGrid, landmarks: np.ndarray, poses: np.ndarray,
                    points: Optional[np.ndarray] = None, tolerance: float = 0.1,
                    wall_max: float = 0.1, coarse_step_deg: float = 2.0,
                    fine_step_deg: float = 0.2, coarse_factor: int = 2,
                    refine: bool = True) -> Dict[str, object]:
    """Align the SLAM result to the grid and score it (module docstring).

    Args:
        grid: The building's grid.
        landmarks: (L, 2) mapped landmark positions (SLAM map frame) [m].
        poses: (P, 2) estimated robot positions (same frame) [m].
        points: Optional (K, 2) scan end points placed with the estimated poses (same
            frame): when given they, not the landmarks, drive the alignment (a few dozen
            landmarks fit a large building in several places) and their share near a wall
            is reported too.
        tolerance: Distance to a wall counted as on the wall [m].
        wall_max: Largest grid value of a wall cell (values are the free probability).
        coarse_step_deg: Rotation grid of the global search [deg].
        fine_step_deg: Rotation grid of the refinement [deg].
        coarse_factor: The global search runs on cells this many times larger.
        refine: Refine the translation and rotation continuously (module docstring);
            False keeps the search's whole-cell translation and ``fine_step_deg`` rotation.

    Returns:
        ``landmarks``, ``landmarks_near_wall``, ``landmark_share`` (within ``tolerance``),
        ``poses``, ``poses_in_wall``, ``poses_unknown``, ``point_share`` (None without
        points), ``transform`` ``[t_x, t_y, theta]`` (map frame -> grid frame).

    Raises:
        ValueError: Empty or non-finite input.
    """
    lm = np.asarray(landmarks, dtype=float).reshape(-1, 2)
    ps = np.asarray(poses, dtype=float).reshape(-1, 2)
    pts = None if points is None else np.asarray(points, dtype=float).reshape(-1, 2)
    if lm.shape[0] == 0 or ps.shape[0] == 0 or (pts is not None and pts.shape[0] == 0):
        raise ValueError('occupancy_check: needs at least one landmark, pose and point')
    if not all(np.all(np.isfinite(a)) for a in (lm, ps, pts) if a is not None):
        raise ValueError('occupancy_check: landmarks, poses and points must be finite')
    v, res = grid.values, grid.resolution
    wall = (v >= 0.0) & (v <= wall_max)
    if not np.any(wall):
        raise ValueError(f'{grid.name}: no wall cell (value in [0, {wall_max}])')
    dist = ndimage.distance_transform_edt(~wall) * res  # centre to centre
    near = (dist <= tolerance + 0.5 * res).astype(float)
    open_ = (v > wall_max).astype(float)
    fit = lm if pts is None else pts
    centre = ps.mean(axis=0)
    fit0, ps0 = fit - centre, ps - centre

    def search(thetas, near_g, open_g, res_g):
        near_g, open_g = _GridCorrelation(near_g), _GridCorrelation(open_g)
        best = (-np.inf, None, None)
        for th in thetas:
            r = _rot(th)
            score, shift = _best_shift(near_g, open_g, fit0 @ r.T, ps0 @ r.T, res_g)
            if score > best[0]:
                best = (score, th, shift)
        return best

    f = int(coarse_factor)
    coarse = np.radians(np.arange(0.0, 360.0, coarse_step_deg))
    _, th, _ = search(coarse, _pool(near, f), _pool(open_, f), res * f)
    fine = th + np.radians(np.arange(-coarse_step_deg, coarse_step_deg + 1e-9, fine_step_deg))
    _, th, shift = search(fine, near, open_, res)
    # Continuous refinement on the fitted points' clipped distance to the walls.
    clip = 3.0 * tolerance

    def cost(p):
        g = _transform(fit0, np.array([shift[0] + p[0], shift[1] + p[1], th + p[2]])) / res
        d = ndimage.map_coordinates(dist, (g - 0.5).T, order=1, mode='nearest')
        return float(np.mean(np.minimum(d, clip) ** 2))

    from scipy import optimize  # here: scipy.optimize takes 0.35 s to import
    simplex = [[0, 0, 0], [res / 2, 0, 0], [0, res / 2, 0], [0, 0, math.radians(fine_step_deg)]]
    p = np.zeros(3)
    if refine:
        p = optimize.minimize(cost, p, method='Nelder-Mead',
                              options={'xatol': 1e-3, 'fatol': 1e-8,
                                       'initial_simplex': simplex}).x
    th_f = th + p[2]
    t_xy = shift + p[:2] - centre @ _rot(th_f).T
    t = np.array([t_xy[0], t_xy[1], th_f])
    walls = cKDTree((np.argwhere(wall) + 0.5) * res)
    d_lm = _square_distance(_transform(lm, t), walls, res, tolerance)
    ps_g = _transform(ps, t)
    ij = np.floor(ps_g / res).astype(np.int64)
    inside = np.all((ij >= 0) & (ij < np.array(v.shape)), axis=1)
    val = np.full(ps.shape[0], -1.0)
    val[inside] = v[ij[inside, 0], ij[inside, 1]]
    near_lm = int(np.sum(d_lm <= tolerance))
    point_share = None
    if pts is not None:
        g = _transform(pts, t) / res - 0.5
        d_pt = ndimage.map_coordinates(dist, g.T, order=1, mode='nearest')
        point_share = float(np.mean(d_pt <= tolerance + 0.5 * res))
    return {'landmarks': int(lm.shape[0]), 'landmarks_near_wall': near_lm,
            'landmark_share': near_lm / lm.shape[0], 'poses': int(ps.shape[0]),
            'poses_in_wall': int(np.sum((val >= 0.0) & (val <= wall_max))),
            'poses_unknown': int(np.sum(val < 0.0)), 'point_share': point_share,
            'transform': [float(x) for x in t]}


def run_segments(run) -> list:
    """Split a run at the odometry jumps its front end bridged (``run.bridged``).

    After such a jump the odometry continues in another frame (the CMU Wean
    ``robotdata5`` holds two runs; its clock and odometry restart 11 m away): the front
    end bridges it as no motion, so the filter puts the next run where the previous one
    ended, and no single rigid transform fits both parts of the map to the building. Each
    part is a run of its own for :func:`check_run`: its steps, and the corners confirmed
    in them.

    Args:
        run: :func:`landmark_nav.evaluation.slam.run_slam`.

    Returns:
        One :class:`~landmark_nav.evaluation.slam.SlamRun` per part (the run itself when
        nothing was bridged); ``poses``, ``odometry``, ``scan_index``, ``stamps``,
        ``landmarks``, ``landmark_ids`` and the observations restricted to the part.
    """
    from dataclasses import replace
    b = np.asarray(getattr(run, 'bridged', np.zeros(0, dtype=bool)), dtype=bool)
    cuts = np.flatnonzero(b[1:]) + 1 if b.size else np.zeros(0, dtype=np.int64)
    if cuts.size == 0:
        return [run]
    edges = np.concatenate([[0], cuts, [b.size]])
    conf = np.asarray(run.obs_status) == 'confirmed'
    first = dict(zip(np.asarray(run.obs_landmark)[conf].tolist(),
                     np.asarray(run.obs_scan)[conf].tolist()))
    born = np.array([first.get(int(j), -1) for j in run.landmark_ids], dtype=np.int64)
    out = []
    for a, e in zip(edges[:-1], edges[1:]):
        lm = (born >= a) & (born < e)
        ob = (np.asarray(run.obs_scan) >= a) & (np.asarray(run.obs_scan) < e)
        ow = np.asarray(run.obs_world)
        out.append(replace(
            run, stamps=run.stamps[a:e], poses=run.poses[a:e], odometry=run.odometry[a:e],
            covariances=run.covariances[a:e], truth=run.truth[a:e], nis=run.nis[a:e],
            nis_dof=run.nis_dof[a:e],
            scan_index=np.asarray(run.scan_index)[a:e], bridged=b[a:e],
            landmark_ids=run.landmark_ids[lm], landmarks=run.landmarks[lm],
            landmark_covariances=run.landmark_covariances[lm],
            obs_scan=run.obs_scan[ob] - a, obs_status=run.obs_status[ob],
            obs_landmark=run.obs_landmark[ob], obs_world_true=run.obs_world_true[ob],
            obs_world=ow[ob] if ow.shape[0] == ob.size else ow))
    return out


def landmark_diagnosis(grid: OccupancyGrid, run, transform: np.ndarray,
                       tolerance: float = 0.1, wall_max: float = 0.1,
                       confirm_hits: int = 3) -> Dict[str, np.ndarray]:
    """Say for each corner landmark of a run why it is (not) on a wall (module docstring).

    Args:
        grid: The building's grid.
        run: :func:`landmark_nav.evaluation.slam.run_slam` (its ``obs_world``: observations
            placed with the filter's poses).
        transform: ``[t_x, t_y, theta]`` map frame -> grid frame (an :func:`occupancy_check`
            result's ``'transform'``).
        tolerance: See :func:`occupancy_check`.
        wall_max: See :func:`occupancy_check`.
        confirm_hits: The filter's ``SlamParams.confirm_hits``.

    Returns:
        Per corner landmark (the run's ``landmark_ids`` order): ``ids``, ``distance`` of
        the final estimate to a wall [m], ``obs_distance`` median distance of its
        observations placed with the filter's poses [m] (nan: none recorded),
        ``detections`` in the state, ``neighbour`` distance to the nearest other corner
        landmark [m], ``category`` (``'on_wall'``, ``'moved'``, ``'few_views'``,
        ``'off_grid'``).
    """
    t = np.asarray(transform, dtype=float).reshape(3)
    v, res = grid.values, grid.resolution
    wall = (v >= 0.0) & (v <= wall_max)
    walls = cKDTree((np.argwhere(wall) + 0.5) * res)
    reach = 100.0 * tolerance  # distances beyond are reported as inf
    ids = np.asarray(run.landmark_ids, dtype=np.int64)
    lm = np.asarray(run.landmarks, dtype=float).reshape(-1, 2)
    dist = _square_distance(_transform(lm, t), walls, res, reach)
    assoc = np.isin(run.obs_status, ('matched', 'confirmed'))
    obs_id = np.asarray(run.obs_landmark)[assoc]
    obs_xy = np.asarray(run.obs_world, dtype=float).reshape(-1, 2)
    obs_xy = obs_xy[assoc] if obs_xy.shape[0] == assoc.size else np.zeros((0, 2))
    obs_d = (_square_distance(_transform(obs_xy, t), walls, res, reach) if obs_xy.size
             else np.zeros(0))
    n = ids.size
    obs_med = np.full(n, np.nan)
    det = np.zeros(n, dtype=np.int64)
    for k, j in enumerate(ids):
        sel = obs_id == j
        det[k] = int(np.count_nonzero(sel))
        if obs_d.size and np.any(sel):
            obs_med[k] = float(np.median(obs_d[sel[:obs_d.size]]))
    nb = np.full(n, np.inf)
    if n > 1:
        nb = cKDTree(lm).query(lm, 2)[0][:, 1]
    cat = np.full(n, 'off_grid', dtype='<U9')
    cat[det <= confirm_hits] = 'few_views'
    with np.errstate(invalid='ignore'):
        cat[obs_med <= tolerance] = 'moved'
    cat[dist <= tolerance] = 'on_wall'
    return {'ids': ids, 'distance': dist, 'obs_distance': obs_med, 'detections': det,
            'neighbour': nb, 'category': cat}


def wall_pose_diagnosis(grid: OccupancyGrid, scenario, run, transform: np.ndarray,
                        wall_max: float = 0.1, every: int = 2, max_range: float = 8.0,
                        margin: float = 0.3) -> Dict[str, np.ndarray]:
    """Say how deep each estimated pose in a wall cell lies and whether the log saw through it.

    A pose counted in a wall cell by :func:`occupancy_check` may be a trajectory that left
    the corridor, or a pose a few centimetres off at the edge of a wall region, or a cell
    the grid calls wall where this log's laser saw free space (an object moved, a door
    opened since the grid was made). Two figures tell them apart: the cell's depth into
    its wall region (distance from the cell to the nearest known non-wall cell, in whole
    cells: one cell at the region's edge), and in how many of the run's scans (every
    ``every``-th step, placed with the filter's poses, returns up to ``max_range``) a ray
    passes through the cell at least ``margin`` before its return and beyond ``margin``
    from the laser (so a pose's own cell is not crossed by its own rays).

    Args:
        grid: The building's grid.
        scenario: The bag (:func:`landmark_nav.evaluation.bags.load_bag`).
        run: :func:`landmark_nav.evaluation.slam.run_slam` on it (or one of
            :func:`run_segments`).
        transform: ``[t_x, t_y, theta]`` map frame -> grid frame (an :func:`occupancy_check`
            result's ``'transform'``).
        wall_max: See :func:`occupancy_check`.
        every: Step subsampling of the rays.
        max_range: Longest return used [m].
        margin: A ray crosses a cell only this far before its return and from the
            laser [m].

    Returns:
        ``steps`` (indices of the run's poses in wall cells), ``depth`` [m] and
        ``crossings`` (scans with a ray through the cell) per such pose, and
        ``wall_crossings``: the count of every wall cell that any ray crossed (for
        comparison).
    """
    t = np.asarray(transform, dtype=float).reshape(3)
    v, res = grid.values, grid.resolution
    wall = (v >= 0.0) & (v <= wall_max)
    depth = ndimage.distance_transform_edt(wall | (v < 0.0)) * res
    shape = np.array(v.shape)
    ij = np.floor(_transform(np.asarray(run.poses, dtype=float)[:, :2], t) / res
                  ).astype(np.int64)
    inside = np.all((ij >= 0) & (ij < shape), axis=1)
    hit = np.zeros(ij.shape[0], dtype=bool)
    hit[inside] = wall[ij[inside, 0], ij[inside, 1]]
    steps = np.flatnonzero(hit)
    crossed = ray_crossings(grid, scenario, run, t, every, max_range, margin)
    return {'steps': steps, 'depth': depth[ij[steps, 0], ij[steps, 1]],
            'crossings': crossed[ij[steps, 0], ij[steps, 1]],
            'wall_crossings': crossed[wall & (crossed > 0)]}


def wall_poses_counted(diagnosis: Dict[str, np.ndarray], resolution: float,
                       cells: int = 1) -> int:
    """Count the poses in wall cells that neither a tolerance nor the log's scans excuse.

    Of the poses :func:`wall_pose_diagnosis` found in wall cells, a pose whose cell lies
    within ``cells`` cells of a known non-wall cell (depth at most ``cells`` diagonal
    steps: the grid's walls are drawn to the cell and a pose a few centimetres off the
    corridor's edge lands in one), or whose cell this log's own scans see through
    (``crossings`` > 0: the grid holds something that was not there in this run), is not
    counted; the rest are poses inside walls as the run saw them.

    Args:
        diagnosis: A :func:`wall_pose_diagnosis` result.
        resolution: The grid's cell size [m].
        cells: The tolerance in cells.
    """
    depth = np.asarray(diagnosis['depth'], dtype=float)
    seen = np.asarray(diagnosis['crossings']) > 0
    return int(np.count_nonzero((depth > cells * math.sqrt(2.0) * resolution + 1e-9) & ~seen))


def ray_crossings(grid: OccupancyGrid, scenario, run, transform: np.ndarray, every: int = 2,
                  max_range: float = 8.0, margin: float = 0.3) -> np.ndarray:
    """Count, per grid cell, the run's scans with a ray through the cell.

    Every ``every``-th step's scan, placed with the filter's pose of that step and
    ``transform`` (map frame -> grid frame), returns up to ``max_range``; a ray crosses a
    cell from ``margin`` beyond the laser to ``margin`` before its return. A wall cell
    crossed is one this log saw through (an open door, an object moved since the grid was
    made). Returns an int array of the grid's shape.
    """
    from landmark_nav.conversions import classify_ranges
    from landmark_nav.sim import ScanSample
    t = np.asarray(transform, dtype=float).reshape(3)
    v, res = grid.values, grid.resolution
    shape = np.array(v.shape)
    crossed = np.zeros(v.size, dtype=np.int64)
    scans = scenario.of_type(ScanSample)
    mount = np.asarray(scenario.laser.mount, dtype=float)
    along = np.arange(0.0, max_range, 0.5 * res)
    for k in range(0, len(run.poses), every):
        s = scans[int(run.scan_index[k])]
        r = np.asarray(s.ranges, dtype=float)
        ok = classify_ranges(r, s.range_min, s.range_max)[0]
        with np.errstate(invalid='ignore'):
            ok &= r <= max_range
        if not np.any(ok):
            continue
        lp = compose(np.asarray(run.poses[k], dtype=float), mount)
        a = lp[2] + s.angle_min + s.angle_increment * np.flatnonzero(ok)
        use = (along[None, :] >= margin) & (along[None, :] < (r[ok] - margin)[:, None])
        pts = lp[:2] + along[None, :, None] * np.stack([np.cos(a), np.sin(a)], axis=1)[:, None]
        g = np.floor(_transform(pts[use], t) / res).astype(np.int64)
        g = g[np.all((g >= 0) & (g < shape), axis=1)]
        cells = np.unique(g[:, 0] * shape[1] + g[:, 1])
        crossed[cells] += 1
    return crossed.reshape(v.shape)


def corner_wall_check(grid: OccupancyGrid, scenario, run, transform: np.ndarray,
                      corner_params=None, every: int = 1, tolerance: float = 0.1,
                      wall_max: float = 0.1) -> Dict[str, object]:
    """Place every scan's corner detections with the run's poses; how many lie on a wall.

    Each ``every``-th step's scan is run through the corner extractor
    (:func:`landmark_nav.evaluation.slam_run.scan_corners` with ``corner_params``), its
    corners placed with the filter's pose of that step and the laser mount, then with
    ``transform`` (map frame -> grid frame, an :func:`occupancy_check` result's). A corner
    is on a wall when it lies within ``tolerance`` of the square of a wall cell. Where the
    log's own scans see through wall cells (:func:`ray_crossings` over every step: an open
    door, an object moved since the grid was made) the grid does not show the building as
    the log saw it: corners within ``tolerance`` of such a cell are left out of the shares.

    Returns:
        ``points`` (K, 2) grid frame, ``structural`` (K,) bool (``Corner.structural``),
        ``convex`` (K,) bool (opening above pi: the corner juts out toward the sensor),
        ``seen_ends`` (K,) bool (neither ``Corner.occluded`` nor ``Corner.silhouette``),
        ``wall_distance`` (K,) distance to the nearest wall cell's square [m] (inf beyond
        1 m), ``on_wall`` (K,) bool, ``left_out`` (K,) bool (near a wall cell seen
        through), ``path`` (P, 2) the run's positions in the grid frame, and per class
        (``structural``, ``other``, the structural ones split into ``structural_convex``
        and ``structural_concave``, and ``structural_seen_ends``) the count judged and the
        share of it on a wall (``<class>_count``, ``<class>_share``) and the count left out
        (``<class>_left_out``); ``seen_through`` the number of wall cells seen through.
        A concave corner placed behind a wall's face stays within a thick wall's cells; a
        convex one placed in front of it leaves them: the split shows which way the grid
        and the scans disagree.
    """
    from landmark_nav.evaluation.slam_run import scan_corners
    from landmark_nav.laser.corners import CornerParams
    from landmark_nav.sim import ScanSample
    corner_params = replace(corner_params or CornerParams(), arm_ends=True)
    t = np.asarray(transform, dtype=float).reshape(3)
    v, res = grid.values, grid.resolution
    crossed = ray_crossings(grid, scenario, run, t, every=1)
    wall = (v >= 0.0) & (v <= wall_max)
    seen = wall & (crossed > 0)
    scans = scenario.of_type(ScanSample)
    mount = np.asarray(scenario.laser.mount, dtype=float)
    pts, label, convex, seen_ends = [], [], [], []
    for k in range(0, len(run.poses), every):
        found = scan_corners(scans[int(run.scan_index[k])], corner_params)
        if not found:
            continue
        lp = compose(np.asarray(run.poses[k], dtype=float), mount)
        c = np.array([f.position for f in found])
        pts.append(c @ _rot(lp[2]).T + lp[:2])
        label.extend(f.structural for f in found)
        convex.extend(f.opening > math.pi for f in found)
        seen_ends.extend(not (f.occluded or f.silhouette) for f in found)
    points = _transform(np.concatenate(pts), t) if pts else np.zeros((0, 2))
    structural = np.array(label, dtype=bool)
    convex = np.array(convex, dtype=bool)
    seen_ends = np.array(seen_ends, dtype=bool)

    def distance(cells, reach):
        if not cells.any():
            return np.full(len(points), np.inf)
        tree = cKDTree((np.argwhere(cells) + 0.5) * res)
        return _square_distance(points, tree, res, reach)

    wall_distance = distance(wall, max(tolerance, 1.0))
    on_wall, left_out = wall_distance <= tolerance, distance(seen, tolerance) <= tolerance
    out: Dict[str, object] = {
        'points': points, 'structural': structural, 'convex': convex, 'seen_ends': seen_ends,
        'wall_distance': wall_distance, 'on_wall': on_wall, 'left_out': left_out,
        'path': _transform(np.asarray(run.poses, dtype=float)[:, :2], t),
        'seen_through': int(np.count_nonzero(seen))}
    for name, m in (('structural', structural), ('other', ~structural),
                    ('structural_convex', structural & convex),
                    ('structural_concave', structural & ~convex),
                    ('structural_seen_ends', structural & seen_ends)):
        judged = m & ~left_out
        out[f'{name}_count'] = int(judged.sum())
        out[f'{name}_left_out'] = int((m & left_out).sum())
        out[f'{name}_share'] = float(on_wall[judged].mean()) if judged.any() else float('nan')
    return out


def scan_end_points(poses: np.ndarray, mount: np.ndarray, ranges: np.ndarray,
                    angles: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Scan end points in the map frame: each scan's valid returns through its pose.

    Args:
        poses: (S, 3) robot poses.
        mount: (3,) laser pose in base_link.
        ranges: (S, B) ranges [m].
        angles: (B,) beam angles [rad].
        valid: (S, B) bool.

    Returns:
        (K, 2) points.
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    mount = np.asarray(mount, dtype=float).reshape(3)
    lx = mount[0] + np.cos(mount[2]) * (ranges * np.cos(angles)) - np.sin(mount[2]) * (
        ranges * np.sin(angles))
    ly = mount[1] + np.sin(mount[2]) * (ranges * np.cos(angles)) + np.cos(mount[2]) * (
        ranges * np.sin(angles))
    c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
    x = poses[:, 0:1] + c * lx - s * ly
    y = poses[:, 1:2] + s * lx + c * ly
    return np.column_stack([x[valid], y[valid]])


def occupancy_check_files(grid: Union[str, Path, OccupancyGrid], map_file: Union[str, Path],
                          trajectory_tum: Union[str, Path], tolerance: float = 0.1,
                          wall_max: float = 0.1, points: Optional[np.ndarray] = None
                          ) -> Dict[str, object]:
    """:func:`occupancy_check` on a saved SLAM map (its corners) and a TUM trajectory."""
    m = load_map(map_file)
    lm = np.asarray(m.means, dtype=float).reshape(-1, 2)[np.asarray(m.kinds) == CORNER]
    tum = np.loadtxt(trajectory_tum, ndmin=2)
    if not isinstance(grid, OccupancyGrid):
        grid = load_occupancy_grid(grid)
    return occupancy_check(grid, lm, tum[:, 1:3], points, tolerance, wall_max)


def check_run(grid: OccupancyGrid, scenario, run, every: int = 2, max_range: float = 8.0,
              tolerance: float = 0.1, wall_max: float = 0.1,
              refine: bool = True) -> Dict[str, Dict[str, object]]:
    """:func:`occupancy_check` of a SLAM run and of its odometry on the same grid.

    The scan end points (every ``every``-th step, valid returns up to ``max_range``: far
    returns amplify heading errors and leave the building through doors) are placed once
    with the filter's poses and once with the odometry, each set aligned on its own; the
    landmarks are the filter's corners in both (their share is meaningful for ``'slam'``).

    Args:
        grid: The building's grid.
        scenario: The bag (:func:`landmark_nav.evaluation.bags.load_bag`).
        run: :func:`landmark_nav.evaluation.slam.run_slam` on it.
        every: Step subsampling of the scan points.
        max_range: Longest range used [m].
        tolerance: See :func:`occupancy_check`.
        wall_max: See :func:`occupancy_check`.
        refine: See :func:`occupancy_check`.

    Returns:
        ``{'slam': figures, 'odometry': figures}``.
    """
    out = {}
    for name, poses in (('slam', run.poses), ('odometry', run.odometry)):
        pts = run_scan_points(scenario, run.scan_index, poses, every, max_range)
        out[name] = occupancy_check(grid, run.landmarks, poses[:, :2], pts, tolerance,
                                    wall_max, refine=refine)
    return out


def run_scan_points(scenario, scan_index: np.ndarray, poses: np.ndarray, every: int = 2,
                    max_range: float = 8.0) -> np.ndarray:
    """Scan end points (map frame) of every ``every``-th step placed with ``poses``.

    Step ``k`` uses scan ``scan_index[k]`` of the scenario and pose ``poses[k]``; valid
    returns (REP 117) up to ``max_range`` (:func:`scan_end_points`).
    """
    from landmark_nav.conversions import classify_ranges
    from landmark_nav.sim import ScanSample
    scans = scenario.of_type(ScanSample)
    sel = np.asarray(scan_index)[::every]
    ranges = np.array([scans[k].ranges for k in sel], dtype=float)
    valid = np.array([classify_ranges(scans[k].ranges, scans[k].range_min,
                                      scans[k].range_max)[0] for k in sel])
    with np.errstate(invalid='ignore'):
        valid &= ranges <= max_range
    s0 = scans[int(sel[0])]
    angles = s0.angle_min + s0.angle_increment * np.arange(ranges.shape[1])
    mount = np.asarray(scenario.laser.mount, dtype=float)
    return scan_end_points(np.asarray(poses)[::every], mount, np.where(valid, ranges, 0.0),
                           angles, valid)


def point_wall_distance(grid: OccupancyGrid, points_grid: np.ndarray,
                        wall_max: float = 0.1) -> np.ndarray:
    """Distance of grid-frame points to a wall cell's square [m] (approximate).

    As :func:`occupancy_check`'s ``point_share``: the distance transform between cell
    centres, bilinear at the point, minus half a cell (0 inside a wall cell).
    """
    v, res = grid.values, grid.resolution
    wall = (v >= 0.0) & (v <= wall_max)
    dist = ndimage.distance_transform_edt(~wall) * res
    g = np.asarray(points_grid, dtype=float).reshape(-1, 2) / res - 0.5
    d = ndimage.map_coordinates(dist, g.T, order=1, mode='nearest')
    return np.maximum(d - 0.5 * res, 0.0)


__all__ = ['check_run', 'corner_wall_check', 'landmark_diagnosis', 'load_occupancy_grid',
           'occupancy_check',
           'occupancy_check_files', 'run_segments',
           'OccupancyGrid', 'point_wall_distance', 'ray_crossings', 'run_scan_points',
           'scan_end_points', 'wall_pose_diagnosis', 'wall_poses_counted']
