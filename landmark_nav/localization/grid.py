"""Occupancy grid world model (section 4.1): map type, map_server I/O, rasterising, ray casting.

Cell convention (nav_msgs/OccupancyGrid and map_server): ``occupancy[row, col]`` is the cell
whose lower-left corner is ``origin + (col, row) * resolution`` in the map frame; row 0 is
the row at the origin (the BOTTOM of the image), values are ``-1`` (unknown) or an occupancy
probability in percent ``0..100``. A cell is *occupied* if ``value / 100 > occupied_thresh``
(or ``value == 100``), *free* if ``0 <= value / 100 < free_thresh`` and *unknown* otherwise
(``-1`` or in between), the map_server trinary rule.

Ray casting (:func:`raycast_grid`) is an exact grid traversal (every cell a ray crosses,
like Amanatides-Woo DDA) vectorised over rays: the crossings of each ray with the vertical
and horizontal grid lines are computed at once, sorted along the ray, and the cell of every
interval between consecutive crossings is looked up; the traversal starts at the clearance
of the ray's start cell (a cached chessboard distance map), before which nothing can stop
it.
A wall rasterised into the cells it crosses lies, on average, through their centres, so the
reported range is where the ray crosses the wall line through the centre of the first
occupied cell (wall direction from :func:`wall_normals`; at corners and wall ends the line
parallel to the face the ray enters by), at most ``FACE_CAP`` cells past the entry point.
The entry face itself would be up to one cell short: on random rays in the rasterised
hallway (incidence < 60 deg) the mean error is -5 mm and the median 0, against -66 mm for
the entry face.
"""

from dataclasses import dataclass
import math
import os
from pathlib import Path
from typing import Any, Dict, Optional, Tuple, Union

import numpy as np
import yaml

PathLike = Union[str, 'os.PathLike[str]']

#: Occupancy value of an unknown cell.
UNKNOWN = -1
#: Occupancy value written for a free / an occupied cell by :func:`rasterize_world`.
FREE = 0
OCCUPIED = 100
#: map_server (ROS 1 map_saver) defaults; 205 (unknown grey) loads back as unknown with these.
OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196
# PGM shades written in trinary mode (map_saver): occupied black, free white-ish, unknown grey.
_PGM_OCCUPIED, _PGM_FREE, _PGM_UNKNOWN = 0, 254, 205
# Cell states used by the ray caster.
_S_FREE, _S_OCC, _S_UNK = 0, 1, 2
#: Accepted values of the ``unknown`` argument of :func:`raycast_grid`.
UNKNOWN_MODES = ('invalid', 'occupied', 'free')
#: Largest distance [cells] between the entry point and the reported hit (grazing rays).
FACE_CAP = 1.5


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class GridMap:
    """An occupancy grid map (immutable).

    Attributes:
        occupancy: (H, W) int8, ``-1`` unknown or ``0..100`` percent; row 0 = the row at
            ``origin`` (map_server / OccupancyGrid convention, i.e. image flipped).
        resolution: cell size [m].
        origin: ``(x, y, yaw)`` of the lower-left corner of cell (0, 0) in the world frame
            [m, m, rad].
        occupied_thresh: probability above which a cell is occupied (map_server rule).
        free_thresh: probability below which a cell is free.
    """

    occupancy: np.ndarray
    resolution: float
    origin: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    occupied_thresh: float = OCCUPIED_THRESH
    free_thresh: float = FREE_THRESH

    def __post_init__(self) -> None:
        """Validate, freeze the array and precompute the cell states."""
        occ = np.asarray(self.occupancy)
        if occ.ndim != 2 or occ.shape[0] < 1 or occ.shape[1] < 1:
            raise ValueError(f'occupancy must be a non-empty (H, W) array, got {occ.shape}')
        occ = np.clip(np.rint(occ), -1, 100).astype(np.int8)
        if not (math.isfinite(self.resolution) and self.resolution > 0.0):
            raise ValueError('resolution must be a positive number')
        origin = tuple(float(v) for v in self.origin)
        if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
            raise ValueError('origin must be three finite numbers (x, y, yaw)')
        if not 0.0 <= self.free_thresh <= self.occupied_thresh <= 1.0:
            raise ValueError('need 0 <= free_thresh <= occupied_thresh <= 1')
        object.__setattr__(self, 'occupancy', _readonly(occ))
        object.__setattr__(self, 'resolution', float(self.resolution))
        object.__setattr__(self, 'origin', origin)
        p = occ.astype(float) / 100.0
        state = np.full(occ.shape, _S_UNK, dtype=np.int8)
        state[(occ >= 0) & (p < self.free_thresh)] = _S_FREE
        state[(occ >= 0) & ((p > self.occupied_thresh) | (occ == 100))] = _S_OCC
        object.__setattr__(self, '_state', _readonly(state))

    @property
    def shape(self) -> Tuple[int, int]:
        """``(H, W)`` in cells."""
        return int(self.occupancy.shape[0]), int(self.occupancy.shape[1])

    @property
    def occupied(self) -> np.ndarray:
        """(H, W) bool, True where the cell counts as occupied."""
        return self._state == _S_OCC  # type: ignore[attr-defined]

    @property
    def unknown(self) -> np.ndarray:
        """(H, W) bool, True where the cell counts as unknown."""
        return self._state == _S_UNK  # type: ignore[attr-defined]

    @property
    def cell_states(self) -> np.ndarray:
        """(H, W) int8: 0 free, 1 occupied, 2 unknown (read-only)."""
        return self._state  # type: ignore[attr-defined]

    def world_to_map(self, points: Any) -> np.ndarray:
        """Return points (..., 2) of the world frame in continuous cell units ``(col, row)``."""
        p = np.asarray(points, dtype=float)
        ox, oy, oyaw = self.origin
        dx, dy = p[..., 0] - ox, p[..., 1] - oy
        c, s = math.cos(oyaw), math.sin(oyaw)
        return np.stack([(c * dx + s * dy) / self.resolution,
                         (-s * dx + c * dy) / self.resolution], axis=-1)

    def cell_centers(self, rows: Any, cols: Any) -> np.ndarray:
        """World coordinates (..., 2) of the centres of cells ``(rows, cols)``."""
        u = (np.asarray(cols, dtype=float) + 0.5) * self.resolution
        v = (np.asarray(rows, dtype=float) + 0.5) * self.resolution
        ox, oy, oyaw = self.origin
        c, s = math.cos(oyaw), math.sin(oyaw)
        return np.stack([ox + c * u - s * v, oy + s * u + c * v], axis=-1)


# ---------------------------------------------------------------------- map_server I/O
def _write_pgm(path: Path, pixels: np.ndarray) -> None:
    h, w = pixels.shape
    with open(path, 'wb') as f:
        f.write(f'P5\n# CREATOR: landmark_nav.localization.grid\n{w} {h}\n255\n'.encode())
        f.write(np.ascontiguousarray(pixels, dtype=np.uint8).tobytes())


def _read_pgm(path: Path) -> np.ndarray:
    """Read a binary (P5) or ASCII (P2) 8-bit PGM; returns (H, W) uint8, top row first."""
    data = path.read_bytes()
    tokens = []
    pos = 0
    while len(tokens) < 4:
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b'#':
            while pos < len(data) and data[pos:pos + 1] not in (b'\n', b'\r'):
                pos += 1
            continue
        start = pos
        while pos < len(data) and not data[pos:pos + 1].isspace():
            pos += 1
        tokens.append(data[start:pos])
    magic, w, h, maxval = tokens[0], int(tokens[1]), int(tokens[2]), int(tokens[3])
    if maxval > 255:
        raise ValueError(f'{path}: only 8-bit PGM images are supported')
    if magic == b'P5':
        raw = np.frombuffer(data, dtype=np.uint8, count=w * h, offset=pos + 1)
    elif magic == b'P2':
        raw = np.array(data[pos:].split(), dtype=np.int64)[:w * h].astype(np.uint8)
    else:
        raise ValueError(f'{path}: not a PGM image (magic {magic!r})')
    img = raw.reshape(h, w)
    if maxval != 255:
        img = np.rint(img.astype(float) * 255.0 / maxval).astype(np.uint8)
    return img


def _read_image(path: Path) -> np.ndarray:
    if path.suffix.lower() in ('.pgm', '.pnm'):
        return _read_pgm(path)
    import cv2  # other formats (png, bmp, ...) through OpenCV, as map_server reads them
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f'cannot read map image {path}')
    if img.ndim == 3:  # colour: average the colour channels (map_server), ignore alpha
        img = np.rint(img[..., :3].astype(float).mean(axis=2)).astype(np.uint8)
    return img.astype(np.uint8)


def load_map_yaml(path: PathLike) -> GridMap:
    """Load a map_server map (YAML + image) into a :class:`GridMap`.

    Supports ``mode`` trinary (default), scale and raw, and ``negate``, with the
    map_server rules: ``p = (255 - shade) / 255`` (``shade / 255`` if negated); trinary:
    ``p > occupied_thresh`` -> 100, ``p < free_thresh`` -> 0, else -1; scale: the same
    ends with ``99 (p - free) / (occ - free)`` in between; raw: the shade is the value
    (``>100`` -> -1). The image's top row becomes the last grid row.

    Args:
        path: the YAML file; a relative ``image`` is resolved against its directory.

    Returns:
        The map.

    Raises:
        ValueError: a required key is missing or the image cannot be read.
    """
    path = Path(path)
    meta = yaml.safe_load(path.read_text())
    if not isinstance(meta, dict):
        raise ValueError(f'{path}: not a map YAML')
    for key in ('image', 'resolution', 'origin'):
        if key not in meta:
            raise ValueError(f'{path}: missing key {key!r}')
    img_path = Path(meta['image'])
    if not img_path.is_absolute():
        img_path = path.parent / img_path
    img = _read_image(img_path)
    occ_t = float(meta.get('occupied_thresh', OCCUPIED_THRESH))
    free_t = float(meta.get('free_thresh', FREE_THRESH))
    mode = str(meta.get('mode', 'trinary'))
    shade = img.astype(float)
    if mode == 'raw':
        grid = np.where(img > 100, UNKNOWN, img.astype(np.int16))
    else:
        p = shade / 255.0 if int(meta.get('negate', 0)) else (255.0 - shade) / 255.0
        if mode == 'trinary':
            mid = np.full(p.shape, UNKNOWN, dtype=np.int16)
        elif mode == 'scale':
            mid = np.rint(99.0 * (p - free_t) / max(occ_t - free_t, 1e-12)).astype(np.int16)
        else:
            raise ValueError(f'{path}: unknown mode {mode!r}')
        grid = np.where(p > occ_t, OCCUPIED, np.where(p < free_t, FREE, mid))
    origin = [float(v) for v in meta['origin']]
    return GridMap(occupancy=np.flipud(grid).astype(np.int8),
                   resolution=float(meta['resolution']), origin=tuple(origin[:3]),
                   occupied_thresh=occ_t, free_thresh=free_t)


def save_map_yaml(grid: GridMap, path: PathLike, image: Optional[str] = None) -> Path:
    """Save a map in the map_server format: YAML + binary PGM (trinary mode).

    Pixels (map_saver rule): occupied -> 0, free -> 254, unknown -> 205; the image's top
    row is the grid's LAST row. A map whose values are only -1 / 0 / 100 loads back
    identically with :func:`load_map_yaml` (other percentages are quantised to the three
    classes).

    Args:
        grid: the map.
        path: YAML file to write.
        image: image file name next to the YAML (default: the YAML stem + ``.pgm``).

    Returns:
        Path of the written image.
    """
    path = Path(path)
    img_name = image or (path.stem + '.pgm')
    img_path = path.parent / img_name
    state = grid.cell_states
    pixels = np.full(state.shape, _PGM_UNKNOWN, dtype=np.uint8)
    pixels[state == _S_FREE] = _PGM_FREE
    pixels[state == _S_OCC] = _PGM_OCCUPIED
    _write_pgm(img_path, np.flipud(pixels))
    meta: Dict[str, Any] = {
        'image': img_name,
        'mode': 'trinary',
        'resolution': float(grid.resolution),
        'origin': [float(v) for v in grid.origin],
        'negate': 0,
        'occupied_thresh': float(grid.occupied_thresh),
        'free_thresh': float(grid.free_thresh),
    }
    path.write_text(yaml.safe_dump(meta, sort_keys=False, default_flow_style=None))
    return img_path


# ---------------------------------------------------------------------- grid traversal
def _traverse(g0: np.ndarray, d: np.ndarray, length: np.ndarray,
              max_len: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact cell traversal of N rays in cell units, vectorised over rays.

    Args:
        g0: (N, 2) start points ``(col, row)`` in continuous cell units.
        d: (N, 2) unit directions.
        length: (N,) traversal length per ray [cells].
        max_len: an upper bound of ``length`` [cells] (sets the number of crossings).

    Returns:
        ``(t0, t1, col, row)``, each (N, K): the parameter interval ``[t0, t1]`` [cells] of
        the k-th cell crossed and its integer indices, in order along the ray; intervals past
        ``length`` (and empty ones) have ``t0 == t1 == length``.
    """
    n = g0.shape[0]
    k = int(math.ceil(max_len)) + 1  # crossings per axis within max_len, at most
    # Distance (in cells, > 0) to the first grid line ahead along each axis, then 1 per line.
    first = np.where(d > 0.0, np.floor(g0) + 1.0 - g0, g0 - np.ceil(g0) + 1.0)
    with np.errstate(divide='ignore'):
        inv = 1.0 / np.abs(d)  # inf for an axis the ray does not move along
    j = np.arange(k, dtype=float)
    t1 = np.empty((n, 2 * k))
    np.multiply(first[:, 0:1] + j, inv[:, 0:1], out=t1[:, :k])
    np.multiply(first[:, 1:2] + j, inv[:, 1:2], out=t1[:, k:])
    t1.sort(axis=1)
    np.minimum(t1, length[:, None], out=t1)
    t0 = np.empty_like(t1)
    t0[:, 0] = 0.0
    t0[:, 1:] = t1[:, :-1]
    tm = 0.5 * (t0 + t1)
    col = np.floor(g0[:, 0:1] + tm * d[:, 0:1]).astype(np.int64)
    row = np.floor(g0[:, 1:2] + tm * d[:, 1:2]).astype(np.int64)
    return t0, t1, col, row


@dataclass(frozen=True, eq=False)
class GridHits:
    """Result of :func:`raycast_grid_hits` for N rays.

    Attributes:
        ranges: (N,) ranges [m], as returned by :func:`raycast_grid`.
        rows: (N,) row of the cell that stopped the ray, -1 if none.
        cols: (N,) column of that cell, -1 if none.
        cos_incidence: (N,) ``|cos|`` of the angle between the ray and the wall normal at
            the hit cell (:func:`wall_normals`), 1 where the cell has no defined normal
            (corner, isolated cell: echoes from any direction), nan without a hit.
    """

    ranges: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    cos_incidence: np.ndarray


def _clearance(grid: GridMap, unknown_stops: bool, max_cells: int = 40) -> np.ndarray:
    """Lower bound [cells] of the distance to the nearest stopping cell (cached), padded.

    Chessboard (Chebyshev) distance between cell centres, which never exceeds the
    Euclidean one, by repeated 3x3 dilation, capped at ``max_cells``. Stopping cells are
    the occupied ones and, if ``unknown_stops``, the unknown ones and the outside of the
    map (the one-cell border of the padded result).
    """
    key = '_clearance_unknown' if unknown_stops else '_clearance_free'
    out = grid.__dict__.get(key)
    if out is None:
        states = np.pad(grid.cell_states, 1, constant_values=_S_UNK)
        reached = states == _S_OCC
        if unknown_stops:
            reached |= states == _S_UNK
        out = np.full(reached.shape, float(max_cells))
        out[reached] = 0.0
        for dist in range(1, max_cells):
            if reached.all():
                break
            grown = reached.copy()
            grown[1:, :] |= reached[:-1, :]
            grown[:-1, :] |= reached[1:, :]
            ring = grown.copy()
            ring[:, 1:] |= grown[:, :-1]
            ring[:, :-1] |= grown[:, 1:]
            out[ring & ~reached] = float(dist)
            reached = ring
        out.setflags(write=False)
        grid.__dict__[key] = out
    return out


def _first_stop(grid: GridMap, g0: np.ndarray, d: np.ndarray, length: np.ndarray,
                unknown: str) -> Tuple[np.ndarray, ...]:
    """First cell that stops each ray within ``length`` (N,) cells (see raycast_grid).

    Returns:
        ``(found, t_in, t_out, row, col, state)``, each (N,): whether a cell stops the ray,
        the ray parameters [cells] where it enters and leaves that cell, its indices
        (clipped to -1 .. H / W outside the map) and its state.
    """
    n = g0.shape[0]
    t0, t1, col, row = _traverse(g0, d, length, float(length.max()))
    h, w = grid.shape
    # States padded with one unknown cell all around: clipped indices stay outside.
    padded = grid.__dict__.get('_padded_states')
    if padded is None:
        padded = np.pad(grid.cell_states, 1, constant_values=_S_UNK)
        grid.__dict__['_padded_states'] = padded
    np.clip(col, -1, w, out=col)
    np.clip(row, -1, h, out=row)
    state = padded[row + 1, col + 1]
    nonempty = t1 > t0
    stop = nonempty & (state == _S_OCC)
    if unknown != 'free':
        stop |= nonempty & (state == _S_UNK)
    found = stop.any(axis=1)
    k = np.argmax(stop, axis=1)
    idx = np.arange(n)
    return found, t0[idx, k], t1[idx, k], row[idx, k], col[idx, k], state[idx, k]


def raycast_grid_hits(grid: GridMap, origins: Any, angles: Any, max_range: float,
                      unknown: str = 'invalid') -> GridHits:
    """Like :func:`raycast_grid`, also returning the hit cells and the angle of incidence."""
    if unknown not in UNKNOWN_MODES:
        raise ValueError(f'unknown must be one of {UNKNOWN_MODES}, got {unknown!r}')
    ang = np.asarray(angles, dtype=float).reshape(-1)
    o = np.broadcast_to(np.asarray(origins, dtype=float).reshape(-1, 2), (ang.shape[0], 2))
    n = ang.shape[0]
    if n == 0:
        empty = np.zeros(0)
        return GridHits(empty, empty.astype(np.int64), empty.astype(np.int64), empty)
    res = grid.resolution
    g0 = grid.world_to_map(o)
    a_map = ang - grid.origin[2]
    d = np.stack([np.cos(a_map), np.sin(a_map)], axis=1)
    h, w = grid.shape
    # Traverse a little past max_range so that a cell straddling it is found. Nothing can
    # stop a ray before the clearance of its start cell (chessboard distance between cell
    # centres, minus the start's and the obstacle cell's half diagonals), so the traversal
    # starts there.
    lim = float(max_range) / res + 1.5
    clear = _clearance(grid, unknown != 'free')
    ci = np.clip(np.floor(g0).astype(np.int64), -1, [w, h]) + 1
    t_skip = np.clip(clear[ci[:, 1], ci[:, 0]] - 1.5, 0.0, lim)
    length = np.maximum(lim - t_skip, 0.0)
    any_stop, t_in, t_out, rk, ck, st = _first_stop(grid, g0 + t_skip[:, None] * d, d, length,
                                                    unknown)
    t_in = t_in + t_skip
    t_out = t_out + t_skip
    # Hit point: where the ray crosses the wall line through the hit cell's centre (wall
    # direction from wall_normals); without a defined wall direction (corner, wall end),
    # the cell's centre line parallel to the face the ray enters by. Never before the
    # entry point nor more than FACE_CAP cells past it. Exact for walls through cell
    # centres.
    p_in = g0 + t_in[:, None] * d
    on_x = np.abs(p_in[:, 0] - np.rint(p_in[:, 0])) <= np.abs(p_in[:, 1] - np.rint(p_in[:, 1]))
    d_n = np.where(on_x, np.abs(d[:, 0]), np.abs(d[:, 1]))
    with np.errstate(divide='ignore'):
        extra = np.minimum(0.5 / d_n, FACE_CAP)
    occ_hit = any_stop & (st == _S_OCC) & (rk >= 0) & (rk < h) & (ck >= 0) & (ck < w)
    nrm = np.full((n, 2), np.nan)
    if occ_hit.any():
        nrm[occ_hit] = wall_normals(grid)[rk[occ_hit], ck[occ_hit]]
    nd = nrm[:, 0] * d[:, 0] + nrm[:, 1] * d[:, 1]
    with np.errstate(divide='ignore', invalid='ignore'):
        t_line = (nrm[:, 0] * (ck + 0.5 - g0[:, 0]) + nrm[:, 1] * (rk + 0.5 - g0[:, 1])) / nd
    extra = np.where(np.isfinite(t_line), np.clip(t_line - t_in, 0.0, FACE_CAP), extra)
    extra = np.where(t_in > 0.0, extra, 0.5 * (t_out - t_in))  # origin inside the cell
    rng = np.where(any_stop, (t_in + extra) * res, np.inf)
    if unknown == 'invalid':
        rng = np.where(any_stop & (st == _S_UNK), np.nan, rng)
    with np.errstate(invalid='ignore'):
        far = rng > max_range
    rng = np.where(far, np.inf, rng)
    hit = any_stop & ~far & (rk >= 0) & (rk < h) & (ck >= 0) & (ck < w)
    rows = np.where(hit, rk, -1)
    cols = np.where(hit, ck, -1)
    cos_i = np.where(hit, np.where(np.isnan(nd), 1.0, np.abs(nd)), np.nan)
    return GridHits(ranges=rng, rows=rows, cols=cols, cos_incidence=cos_i)


def raycast_grid(grid: GridMap, origins: Any, angles: Any, max_range: float,
                 unknown: str = 'invalid') -> np.ndarray:
    """Cast N rays through the grid to the first occupied cell (vectorised over rays).

    Args:
        grid: the map.
        origins: (N, 2) ray origins in the world frame [m] (or (2,) shared by all rays).
        angles: (N,) world-frame ray directions [rad].
        max_range: maximum range [m]; farther hits are reported as ``inf``.
        unknown: how unknown cells (``-1`` / between the thresholds) and the outside of the
            map are treated: ``'invalid'`` (default) -- the ray stops there and its range is
            ``nan`` (no prediction possible); ``'occupied'`` -- they stop the ray like an
            obstacle; ``'free'`` -- rays pass through (leaving the map gives ``inf``).

    Returns:
        (N,) ranges [m] to the first occupied cell (measured to its centre line, see the
        module docstring), ``inf`` if none within ``max_range``, ``nan`` as described for
        ``unknown``.
    """
    return raycast_grid_hits(grid, origins, angles, max_range, unknown).ranges


def wall_normals(grid: GridMap, window: int = 2, line_ratio: float = 0.25) -> np.ndarray:
    """Estimate unit wall normals (H, W, 2) in the map frame from the local wall shape.

    For every occupied cell, the occupied cells of the surrounding ``(2 window + 1)^2``
    window give a 2x2 scatter matrix; if they form a line (eigenvalue ratio below
    ``line_ratio``) the normal is perpendicular to its main axis, otherwise (a corner, the
    end of a wall, an isolated cell) it is undefined (nan). Cached per map.

    Args:
        grid: the map.
        window: half size of the window [cells].
        line_ratio: largest ``lambda_min / lambda_max`` still counted as a line.

    Returns:
        (H, W, 2) normals ``(n_col, n_row)`` (sign arbitrary), nan where undefined.
    """
    cache = grid.__dict__.setdefault('_normals', {})
    key = (int(window), float(line_ratio))
    if key in cache:
        return cache[key]
    occ = grid.occupied.astype(float)
    h, w = occ.shape
    pad = np.pad(occ, window)
    s = {name: np.zeros((h, w)) for name in ('n', 'x', 'y', 'xx', 'yy', 'xy')}
    for dy in range(-window, window + 1):
        for dx in range(-window, window + 1):
            m = pad[window + dy:window + dy + h, window + dx:window + dx + w]
            s['n'] += m
            s['x'] += m * dx
            s['y'] += m * dy
            s['xx'] += m * dx * dx
            s['yy'] += m * dy * dy
            s['xy'] += m * dx * dy
    n = np.maximum(s['n'], 1.0)
    a = s['xx'] / n - (s['x'] / n) ** 2
    c = s['yy'] / n - (s['y'] / n) ** 2
    b = s['xy'] / n - (s['x'] / n) * (s['y'] / n)
    half_tr = 0.5 * (a + c)
    rad = np.sqrt((0.5 * (a - c)) ** 2 + b ** 2)
    lam_max, lam_min = half_tr + rad, half_tr - rad
    with np.errstate(invalid='ignore', divide='ignore'):
        line = (occ > 0.0) & (lam_max > 0.0) & (lam_min <= line_ratio * lam_max)
    phi = 0.5 * np.arctan2(2.0 * b, a - c)  # direction of the main axis (the wall)
    out = np.full((h, w, 2), np.nan)
    out[line, 0] = -np.sin(phi[line])
    out[line, 1] = np.cos(phi[line])
    out.setflags(write=False)
    cache[key] = out
    return out


# ---------------------------------------------------------------------- rasterising
def _aligned_offset(values: np.ndarray, weights: np.ndarray, res: float) -> float:
    """Grid-line offset in ``[0, res)`` putting axis-aligned walls at cell centres.

    Minimises the length-weighted distance of the walls from the centres of the cells
    they occupy (candidates: the offset that centres each wall), so that the bulk of the
    wall length is represented exactly; walls at other sub-cell positions keep an error of
    up to half a cell.
    """
    if values.size == 0:
        return 0.0
    cand = np.mod(values - 0.5 * res, res)
    diff = np.mod(values[None, :] - 0.5 * res - cand[:, None] + 0.5 * res, res) - 0.5 * res
    cost = (np.abs(diff) * weights[None, :]).sum(axis=1)
    best = float(cand[int(np.argmin(cost))])
    return 0.0 if abs(best - res) < 1e-9 else best


def rasterize_world(world: Any, resolution: float = 0.1, margin: float = 0.5,
                    align: bool = True) -> GridMap:
    """Rasterise a simulator :class:`~landmark_nav.sim.world.World` into an occupancy grid.

    Every cell crossed by a wall segment is occupied (exact traversal, the same as the ray
    caster's); where a segment passes diagonally through a cell corner the side cell is
    added too, so walls are 4-connected and at least one cell thick: no ray can slip
    through them. Cells intersecting a round obstacle (disk) are occupied; all other cells
    are free (the map is fully known).

    Args:
        world: the world (``segments`` (M, 4), ``circles`` (K, 3), ``bounds()``).
        resolution: cell size [m] (the chapter uses 0.1 m).
        margin: free border around the world's bounding box [m].
        align: shift the grid by a fraction of a cell so that axis-aligned walls lie at
            cell centres, as much wall length as possible (:func:`_aligned_offset`); the
            ray caster measures to cell centres, so these walls are then represented
            without error. False: the origin is exactly the bounding box corner minus the
            margin.

    Returns:
        The map (values 0 / 100, origin yaw 0).
    """
    res = float(resolution)
    seg = np.asarray(world.segments, dtype=float).reshape(-1, 4)
    circ = np.asarray(world.circles, dtype=float).reshape(-1, 3)
    xmin, ymin, xmax, ymax = world.bounds()
    ox, oy = xmin - margin, ymin - margin
    if align:
        tol = 1e-9
        vert = np.abs(seg[:, 0] - seg[:, 2]) < tol
        horz = np.abs(seg[:, 1] - seg[:, 3]) < tol
        lens = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
        off_x = _aligned_offset(seg[vert, 0], lens[vert], res)
        off_y = _aligned_offset(seg[horz, 1], lens[horz], res)
        ox = math.floor((ox - off_x) / res) * res + off_x
        oy = math.floor((oy - off_y) / res) * res + off_y
    w = int(math.ceil((xmax + margin - ox) / res - 1e-9))
    h = int(math.ceil((ymax + margin - oy) / res - 1e-9))
    occ = np.zeros((h, w), dtype=np.int8)
    grid0 = GridMap(occupancy=occ, resolution=res, origin=(ox, oy, 0.0))
    if seg.shape[0]:
        g0 = grid0.world_to_map(seg[:, :2])
        g1 = grid0.world_to_map(seg[:, 2:])
        vec = g1 - g0
        length = np.hypot(vec[:, 0], vec[:, 1])
        d = vec / length[:, None]
        t0, t1, col, row = _traverse(g0, d, length, float(length.max()))
        keep = t1 > t0
        keep[:, 0] = True  # the start cell even for a zero-length segment
        # 4-connectivity: where consecutive crossed cells touch only at a corner (the
        # segment passes exactly through a grid vertex) add the side cell as well.
        last = np.maximum.accumulate(np.where(keep, np.arange(keep.shape[1]), 0), axis=1)
        rf = np.take_along_axis(row, last, axis=1)
        cf = np.take_along_axis(col, last, axis=1)
        diag = (rf[:, 1:] != rf[:, :-1]) & (cf[:, 1:] != cf[:, :-1])
        rr = np.concatenate([row[keep], rf[:, :-1][diag]])
        cc = np.concatenate([col[keep], cf[:, 1:][diag]])
        ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
        occ[rr[ok], cc[ok]] = OCCUPIED
    for cx, cy, r in circ:
        gc = grid0.world_to_map([cx, cy])
        rad = r / res
        c0, c1 = int(math.floor(gc[0] - rad)), int(math.floor(gc[0] + rad))
        r0, r1 = int(math.floor(gc[1] - rad)), int(math.floor(gc[1] + rad))
        cols, rows = np.meshgrid(np.arange(c0, c1 + 1), np.arange(r0, r1 + 1))
        nx = np.clip(gc[0], cols, cols + 1)
        ny = np.clip(gc[1], rows, rows + 1)
        hit = np.hypot(nx - gc[0], ny - gc[1]) <= rad
        ok = hit & (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        occ[rows[ok], cols[ok]] = OCCUPIED
    return GridMap(occupancy=occ, resolution=res, origin=(ox, oy, 0.0))
