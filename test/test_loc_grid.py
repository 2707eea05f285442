"""Tests for landmark_nav.localization.grid: map type, map_server I/O, rasterising, ray casting."""

import math

from landmark_nav.localization.grid import (GridMap, load_map_yaml, rasterize_world,
                                            raycast_grid, raycast_grid_hits, save_map_yaml,
                                            wall_normals)
from landmark_nav.sim.scenarios import hallway_world
from landmark_nav.sim.world import World
import numpy as np
import pytest
import yaml


def rotated_room(theta: float):
    """Room with an inner notch, a rotated box and a round pillar, rotated by ``theta``."""
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    w = World('rot')
    pts = np.array([(0, 0), (8, 0), (8, 5), (5, 5), (5, 3), (3, 3), (3, 5), (0, 5)], float)
    w.add_room(pts @ rot.T)
    w.add_circle(*(rot @ [6.5, 2.0]), 0.3)
    w.add_rectangle(*(rot @ [1.5, 2.0]), 0.6, 0.4, yaw=0.4)
    return w, rot


def inside_points(rot, n, rng):
    u = rng.uniform(0.2, 7.8, n)
    v = rng.uniform(0.2, 4.8, n)
    keep = ~((u > 2.8) & (u < 5.2) & (v > 2.8))
    return np.stack([u, v], axis=1)[keep] @ rot.T


def ray_vertex_distance(o, d, length, pts):
    """Smallest distance (N,) from points (M, 2) to the ray segments o + t d, 0 <= t <= L."""
    w = pts[None, :, :] - o[:, None, :]
    t = np.clip(np.sum(w * d[:, None, :], axis=2), 0.0, length[:, None])
    q = o[:, None, :] + t[..., None] * d[:, None, :]
    return np.hypot(pts[None, :, 0] - q[..., 0], pts[None, :, 1] - q[..., 1]).min(axis=1)


def test_gridmap_conventions():
    occ = np.zeros((3, 4), dtype=int)
    occ[0, 1] = 100
    occ[2, 3] = -1
    occ[1, 2] = 50  # between the thresholds: unknown under the trinary rule
    g = GridMap(occupancy=occ, resolution=0.5, origin=(1.0, 2.0, 0.0))
    assert g.shape == (3, 4) and g.occupancy.dtype == np.int8
    assert not g.occupancy.flags.writeable
    assert g.occupied[0, 1] and g.occupied.sum() == 1
    assert g.unknown[2, 3] and g.unknown[1, 2] and g.unknown.sum() == 2
    # Row 0 is the row at the origin; (col, row) cell units.
    assert g.world_to_map([1.75, 2.25]) == pytest.approx([1.5, 0.5])
    assert g.cell_centers(0, 1) == pytest.approx([1.75, 2.25])
    with pytest.raises(ValueError):
        GridMap(occupancy=np.zeros(3), resolution=0.1)
    with pytest.raises(ValueError):
        GridMap(occupancy=np.zeros((2, 2)), resolution=0.0)


def test_map_yaml_pgm_round_trip_exact(tmp_path):
    rng = np.random.default_rng(0)
    occ = rng.choice(np.array([-1, 0, 100]), size=(37, 53))
    g = GridMap(occupancy=occ, resolution=0.05, origin=(-1.2345678901, 3.25, 0.1))
    img = save_map_yaml(g, tmp_path / 'm.yaml')
    assert img == tmp_path / 'm.pgm'
    meta = yaml.safe_load((tmp_path / 'm.yaml').read_text())
    assert meta['mode'] == 'trinary' and meta['image'] == 'm.pgm' and meta['negate'] == 0
    raw = img.read_bytes()
    assert raw.startswith(b'P5')
    pixels = np.frombuffer(raw[-37 * 53:], dtype=np.uint8).reshape(37, 53)
    # map_saver shades, image flipped: the first image row is the LAST grid row.
    expect = np.select([occ == 100, occ == 0], [0, 254], 205)
    assert np.array_equal(pixels, np.flipud(expect))
    g2 = load_map_yaml(tmp_path / 'm.yaml')
    assert np.array_equal(g2.occupancy, g.occupancy)
    assert g2.resolution == g.resolution and g2.origin == g.origin
    assert (g2.occupied_thresh, g2.free_thresh) == (g.occupied_thresh, g.free_thresh)


def test_load_map_negate_and_scale(tmp_path):
    img = np.array([[0, 128, 255]], dtype=np.uint8)
    (tmp_path / 'a.pgm').write_bytes(b'P5\n# c\n3 1\n255\n' + img.tobytes())
    base = {'image': 'a.pgm', 'resolution': 0.1, 'origin': [0.0, 0.0, 0.0],
            'occupied_thresh': 0.65, 'free_thresh': 0.196}
    (tmp_path / 'a.yaml').write_text(yaml.safe_dump({**base, 'negate': 0}))
    assert load_map_yaml(tmp_path / 'a.yaml').occupancy.tolist() == [[100, -1, 0]]
    (tmp_path / 'b.yaml').write_text(yaml.safe_dump({**base, 'negate': 1}))
    assert load_map_yaml(tmp_path / 'b.yaml').occupancy.tolist() == [[0, -1, 100]]
    (tmp_path / 'c.yaml').write_text(yaml.safe_dump({**base, 'negate': 0, 'mode': 'scale'}))
    mid = round(99 * (127 / 255 - 0.196) / (0.65 - 0.196))
    assert load_map_yaml(tmp_path / 'c.yaml').occupancy.tolist() == [[100, mid, 0]]


def test_raycast_simple_cases():
    occ = np.zeros((20, 20), dtype=int)
    occ[:, 15] = 100  # wall: cells x in [1.5, 1.6), centre line x = 1.55
    occ[5, 2] = -1
    g = GridMap(occupancy=occ, resolution=0.1)
    o = np.array([[0.55, 1.05], [0.55, 1.05], [0.55, 0.55], [0.55, 1.05], [1.05, 0.55]])
    a = np.array([0.0, math.pi, math.pi, math.radians(30.0), math.pi / 2])
    r = raycast_grid(g, o, a, 3.0)
    assert r[0] == pytest.approx(1.0)  # to the wall's centre line
    assert np.isnan(r[1])  # leaves the map: unknown -> invalid
    assert np.isnan(r[2])  # unknown cell (5, 2) first
    assert r[3] == pytest.approx(1.0 / math.cos(math.radians(30.0)))
    assert np.isnan(r[4])
    assert raycast_grid(g, o, a, 0.5)[0] == np.inf  # beyond max_range
    free = raycast_grid(g, o, a, 3.0, unknown='free')
    assert free[1] == np.inf and free[2] == np.inf
    assert raycast_grid(g, o[2:3], a[2:3], 3.0, unknown='occupied')[0] == pytest.approx(0.3)
    with pytest.raises(ValueError):
        raycast_grid(g, o, a, 3.0, unknown='maybe')
    hits = raycast_grid_hits(g, o[:1], a[:1], 3.0)
    assert (hits.rows[0], hits.cols[0]) == (10, 15)
    assert hits.cos_incidence[0] == pytest.approx(1.0)


def test_rasterize_hallway_walls_at_cell_centres():
    w = hallway_world()
    g = rasterize_world(w, 0.1)
    ox, oy, _ = g.origin
    # align=True: the long walls x = 0, 21.5 and y = +-1 lie on cell centre lines.
    for x in (0.0, 21.5):
        assert ((x - ox) / 0.1) % 1.0 == pytest.approx(0.5)
    assert ((1.0 - oy) / 0.1) % 1.0 == pytest.approx(0.5)
    assert g.occupied.any() and not g.unknown.any()
    g2 = rasterize_world(w, 0.1, margin=0.5, align=False)
    assert g2.origin[:2] == pytest.approx((-0.5, -1.75))


@pytest.mark.parametrize('theta', [0.0, 0.3, math.pi / 4])
def test_raycast_matches_world_within_one_cell(theta):
    world, rot = rotated_room(theta)
    g = rasterize_world(world, 0.1)
    rng = np.random.default_rng(1)
    o = inside_points(rot, 6000, rng)
    o = o[world.clearance(o) > 0.15]
    a = rng.uniform(-math.pi, math.pi, o.shape[0])
    d = np.stack([np.cos(a), np.sin(a)], axis=1)
    truth = world.raycast(o, a, 3.0)
    r = raycast_grid(g, o, a, 3.0)
    # Closed room, 4-connected walls: no ray escapes.
    assert np.all(np.isfinite(r[np.isfinite(truth.ranges) & (truth.ranges < 2.8)]))
    # Every grid hit lies within one cell (diagonal) of a true surface.
    hit_pts = o + np.where(np.isfinite(r), r, 0.0)[:, None] * d
    assert world.clearance(hit_pts[np.isfinite(r)]).max() <= 0.1 * math.sqrt(2.0) + 0.1
    # Ranges agree within one cell diagonal, except rays grazing a corner or the pillar
    # (a rasterised corner can stop a ray that passes it) and very oblique incidence.
    length = np.where(np.isfinite(truth.ranges), truth.ranges, 3.0)
    seg = world.segments
    verts = np.concatenate([seg[:, :2], seg[:, 2:]])
    near_corner = ray_vertex_distance(o, d, length, verts) < 0.15
    circ = world.circles
    near_circle = ray_vertex_distance(o, d, length, circ[:, :2]) < circ[0, 2] + 0.15
    sel = (np.isfinite(truth.ranges) & (truth.ranges < 2.8) & (truth.cos_incidence >= 0.5)
           & ~near_corner & ~near_circle)
    assert sel.sum() > 2000
    err = np.abs(r[sel] - truth.ranges[sel])
    assert err.max() <= 0.1 * math.sqrt(2.0)
    assert np.median(err) < 0.05  # half a cell


def test_raycast_vectorised_and_empty():
    g = rasterize_world(hallway_world(), 0.1)
    o = np.tile([[5.0, 0.0]], (64, 1))
    a = np.linspace(-math.pi, math.pi, 64, endpoint=False)
    r = raycast_grid(g, o, a, 3.0)
    assert r.shape == (64,)
    one = np.array([raycast_grid(g, o[i], a[i:i + 1], 3.0)[0] for i in range(64)])
    assert np.array_equal(r, one, equal_nan=True)
    assert raycast_grid(g, np.zeros((0, 2)), np.zeros(0), 3.0).shape == (0,)


def test_wall_normals():
    g = rasterize_world(hallway_world(), 0.1)
    nrm = wall_normals(g)
    ox, oy, _ = g.origin
    # A cell of the long south wall y = -1 (away from niches): normal along y.
    col = int((2.0 - ox) / 0.1)
    row = int((-1.0 - oy) / 0.1)
    assert g.occupied[row, col]
    assert np.abs(nrm[row, col]) == pytest.approx([0.0, 1.0], abs=1e-9)
    # The hallway's corner (0, -1): no defined normal (echoes from any direction).
    col0 = int((0.0 - ox) / 0.1)
    assert np.isnan(nrm[row, col0]).all()
    assert np.isnan(nrm[~g.occupied]).all()
