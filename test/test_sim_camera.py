"""Tests of the camera simulator: geometry of the rendered image, noise, clipping, order."""

import math

import cv2
from landmark_nav.sim.camera import (CameraSimulator, clip_polygon_near, landmark_plane,
                                     motion_kernel, Photometry, Plane, RenderOptions,
                                     rotation_x, rotation_z)
from landmark_nav.sim.camera_scenarios import landmark_view, ViewOptions
from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np
import pytest

CAM = CameraModel(640, 480, np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]]),
                  np.array([-0.12, 0.08, 0.0005, -0.0003, 0.0]))
PINHOLE = CameraModel.from_fov(320, 240, math.radians(70.0))
CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-5)
R_BODY = OPTICAL_FROM_BODY.T  # world = body frame of a camera looking along world x


def flat(value: int, shape=(20, 20)) -> np.ndarray:
    return np.full(shape, value, dtype=np.uint8)


def test_rendered_x_corners_land_on_projections():
    """Every frame X-corner, refined by cv2.cornerSubPix, lies where the model projects it."""
    errs, diffs = [], []
    opts = ViewOptions(distance=(0.6, 1.5), turn_deg=(-30.0, 30.0), photometry=Photometry(),
                       distractors=0)
    for i in range(12):
        frame = landmark_view(11, i, CAM, opts)
        lt = frame.landmarks[0]
        assert lt.in_view
        px = lt.edge_corners_px.reshape(-1, 2)
        ref = cv2.cornerSubPix(frame.image.astype(np.float32),
                               px.astype(np.float32).reshape(-1, 1, 2).copy(), (3, 3),
                               (-1, -1), CRIT).reshape(-1, 2)
        diffs.append(ref - px)
        errs.append(np.linalg.norm(ref - px, axis=1))
    e = np.concatenate(errs)
    bias = np.concatenate(diffs).mean(axis=0)
    assert e.max() < 0.3 and e.mean() < 0.1
    assert np.all(np.abs(bias) < 0.02)  # a half-pixel convention slip would show here


def _read_code(frame, design):
    """Decode the truth's code from the image by sampling the projected cell centres."""
    lt = frame.landmarks[0]
    cells = design.code_cells()
    centres = 0.5 * (cells[..., :2] + cells[..., 2:])
    pts = design.grid_to_landmark(centres.reshape(-1, 2))
    px = frame.camera.project(lt.points_to_camera(pts))
    vals = cv2.remap(frame.image, px[:, 0].astype(np.float32).reshape(-1, 1),
                     px[:, 1].astype(np.float32).reshape(-1, 1), cv2.INTER_LINEAR)
    frame_px = frame.camera.project(lt.points_to_camera(design.grid_to_landmark(
        np.array([[0.5, 0.5], [1.5, 0.5]]))))  # a black and a white outer-ring block
    lo, hi = (float(frame.image[int(round(y)), int(round(x))]) for x, y in frame_px)
    bits = (vals.reshape(centres.shape[:2]) < 0.5 * (lo + hi))
    return design.decode_with_rotation(bits)


@pytest.mark.parametrize('roll', [0.0, 90.0, 180.0, 270.0, 22.5])
def test_rendered_code_reads_upright(roll):
    """The printed face is not mirrored: reading the cells in landmark order gives the code."""
    for kind in ('3x3', '2x2'):
        design = LandmarkDesign(kind)
        code = 123456789 if kind == '3x3' else 345
        opts = ViewOptions(distance=0.8, turn_deg=20.0, tilt_deg=5.0, roll_deg=roll,
                           quarter_turns=False, code=code, design=design,
                           photometry=Photometry(noise_sigma=1.0))
        res = _read_code(landmark_view(3, 0, CAM, opts), design)
        assert res == (code, 0)


def test_in_plane_rotation_is_seen_in_the_image():
    """Roll +90 deg (counter-clockwise as seen by the camera) turns the top edge to the left."""
    design = LandmarkDesign()
    opts = ViewOptions(distance=1.0, turn_deg=0.0, tilt_deg=0.0, roll_deg=90.0,
                       quarter_turns=False, photometry=Photometry(), distractors=0)
    lt = landmark_view(1, 0, PINHOLE, opts).landmarks[0]
    tl, tr, br, bl = lt.corners_px
    assert tl[0] < br[0] and tr[0] < bl[0]  # top edge (tl-tr) is now the left edge
    assert tr[1] < tl[1]  # ... running upwards: turned counter-clockwise
    # and frontal upright: top-left is top-left
    opts = ViewOptions(distance=1.0, turn_deg=0.0, tilt_deg=0.0, roll_deg=0.0,
                       quarter_turns=False, photometry=Photometry(), distractors=0,
                       centre_px=(PINHOLE.cx, PINHOLE.cy))
    lt = landmark_view(1, 0, PINHOLE, opts).landmarks[0]
    tl, tr, br, bl = lt.corners_px
    assert tl[0] < tr[0] and tl[1] < bl[1]
    b = design.half_side
    # fronto-parallel: the projected width is f 2b / depth exactly (no distortion)
    assert tr[0] - tl[0] == pytest.approx(2 * b * PINHOLE.fx / lt.translation[2], rel=1e-9)


def test_determinism_and_seeds():
    a = landmark_view(5, 2)
    b = landmark_view(5, 2)
    c = landmark_view(6, 2)
    np.testing.assert_array_equal(a.image, b.image)
    assert a.landmarks[0].code == b.landmarks[0].code
    assert not np.array_equal(a.image, c.image)
    sim = CameraSimulator(PINHOLE)
    planes = [Plane(flat(200), 0.5, rotation_z(math.pi), [3.0, 0.0, 0.0])]
    ph = Photometry(noise_sigma=2.0)
    x = sim.render(planes, R_BODY, np.zeros(3), ph, np.random.default_rng(1))
    y = sim.render(planes, R_BODY, np.zeros(3), ph, np.random.default_rng(1))
    z = sim.render(planes, R_BODY, np.zeros(3), ph, np.random.default_rng(2))
    np.testing.assert_array_equal(x, y)
    assert not np.array_equal(x, z)
    with pytest.raises(ValueError, match='rng'):
        sim.render(planes, R_BODY, np.zeros(3), ph)


def test_noise_statistics():
    sim = CameraSimulator(PINHOLE, RenderOptions(white=0.6))
    planes = [Plane(flat(255), 1.0, rotation_z(math.pi), [2.0, 0.0, 0.0])]  # fills the view
    clean = sim.render(planes, R_BODY, np.zeros(3)).astype(float)
    assert clean.std() == 0.0 and clean.mean() == pytest.approx(round(0.6 * 255))
    rng = np.random.default_rng(7)
    stack = np.stack([sim.render(planes, R_BODY, np.zeros(3), Photometry(noise_sigma=3.0),
                                 rng).astype(float) for _ in range(4)])
    res = stack - 0.6 * 255
    assert res.mean() == pytest.approx(0.0, abs=0.05)
    assert res.std() == pytest.approx(math.sqrt(3.0 ** 2 + 1 / 12), rel=0.02)  # + quantisation
    # neighbouring pixels are independent
    r = res[0]
    corr = np.corrcoef(r[:, :-1].ravel(), r[:, 1:].ravel())[0, 1]
    assert abs(corr) < 0.02
    # shot noise: variance grows with the signal
    shot = sim.render(planes, R_BODY, np.zeros(3), Photometry(shot_noise=0.5), rng)
    assert shot.astype(float).var() == pytest.approx(0.5 * 0.6 * 255, rel=0.05)


def test_gamma_and_exposure():
    sim = CameraSimulator(PINHOLE, RenderOptions(white=0.5))
    planes = [Plane(flat(255), 1.0, rotation_z(math.pi), [2.0, 0.0, 0.0])]
    img = sim.render(planes, R_BODY, np.zeros(3), Photometry(gamma=2.0, exposure=0.5))
    assert np.all(np.abs(img.astype(int) - 255 * math.sqrt(0.25)) <= 1)
    sat = sim.render(planes, R_BODY, np.zeros(3), Photometry(exposure=5.0))
    assert np.all(sat == 255)
    grad = sim.render(planes, R_BODY, np.zeros(3), Photometry(gradient=(0.3, 0.0)))
    assert grad[:, -1].mean() > grad[:, 0].mean() * 1.6


def _floor_checker_expected(cam, h, square, u, v):
    """Return the analytic colour of pixel (u, v): 0 black, 1 white, -1 sky.

    Camera at height h looking along world x; a 20 m floor checkerboard with ``square`` m
    squares, black where floor(x / s) + floor(y / s) is even.
    """
    ray_opt = cam.back_project(np.array([[u, v]]))[0]
    ray = R_BODY @ ray_opt
    if ray[2] >= -1e-9:
        return -1
    t = h / -ray[2]
    x, y = t * ray[0], t * ray[1]
    if max(abs(x), abs(y)) >= 10.0:  # beyond the 20 m x 20 m floor
        return -1
    return 0 if (math.floor(x / square) + math.floor(y / square)) % 2 == 0 else 1


def test_plane_partly_behind_camera():
    """A floor extending behind the camera renders correctly (clipped at the near plane)."""
    h, square, n = 0.5, 0.5, 40  # 20 m x 20 m floor centred under the camera
    j, i = np.mgrid[0:n, 0:n]
    # texel (col i, row j): plane y = world x, plane z = world y, row 0 = largest y
    xs = (i - n / 2) * square
    ys = (n / 2 - 1 - j) * square
    tex = np.where((np.floor(xs / square) + np.floor(ys / square)) % 2 == 0, 0, 255)
    tex = np.repeat(np.repeat(tex.astype(np.uint8), 32, 0), 32, 1)
    R_floor = np.column_stack([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    floor = Plane(tex, square / 32, R_floor, [0.0, 0.0, -h])
    sim = CameraSimulator(PINHOLE, RenderOptions(background=0.5, black=0.0, white=1.0))
    img = sim.render([floor], R_BODY, np.zeros(3))
    rng = np.random.default_rng(0)
    checked = 0
    for _ in range(400):
        u, v = rng.uniform(0, 319), rng.uniform(0, 239)
        exp = _floor_checker_expected(PINHOLE, h, square, u, v)
        # skip pixels near an edge of the pattern or the horizon (bilinear magnification
        # of the texture blurs edges by half a texel, up to 2 px at the image bottom)
        near_edge = any(_floor_checker_expected(PINHOLE, h, square, u + du, v + dv) != exp
                        for du in (-4, 0, 4) for dv in (-4, 0, 4))
        if near_edge:
            continue
        val = img[int(round(v)), int(round(u))]
        want = 128 if exp == -1 else (0 if exp == 0 else 255)
        assert abs(int(val) - want) <= 1, (u, v, exp, val)
        checked += 1
    assert checked > 200
    # entirely behind the camera: nothing drawn
    behind = Plane(flat(0), 0.1, rotation_z(0.0), [-1.0, 0.0, 0.0], two_sided=True)
    assert np.all(sim.render([behind], R_BODY, np.zeros(3)) == 128)


def test_clip_polygon_near():
    quad = np.array([[-1.0, 0, -1.0], [1.0, 0, -1.0], [1.0, 0, 3.0], [-1.0, 0, 3.0]])
    out = clip_polygon_near(quad, 0.5)
    assert out[:, 2].min() == pytest.approx(0.5)
    assert len(out) == 4
    assert len(clip_polygon_near(quad - [0, 0, 10], 0.5)) == 0


def test_back_faces_and_painter_order():
    sim = CameraSimulator(PINHOLE, RenderOptions(background=0.5, black=0.0, white=1.0))
    facing = rotation_z(math.pi)  # normal -x: faces a camera at the origin looking along x
    wall = Plane(flat(255), 0.5, facing, [3.0, 0.0, 0.0])
    poster = Plane(flat(0), 0.02, facing, [2.999, 0.0, 0.0])
    centre = (120, 160)
    for planes in ([wall, poster], [poster, wall]):
        img = sim.render(planes, R_BODY, np.zeros(3))
        assert img[centre] == 0 and img[5, 5] == 255
    # a wall seen from behind is culled unless two-sided
    back = Plane(flat(0), 0.5, rotation_z(0.0), [3.0, 0.0, 0.0])
    assert np.all(sim.render([back], R_BODY, np.zeros(3)) == 128)
    two = Plane(flat(0), 0.5, rotation_z(0.0), [3.0, 0.0, 0.0], two_sided=True)
    assert np.all(sim.render([two], R_BODY, np.zeros(3)) == 0)
    # a nearer plane hides a farther one whatever the list order (no shared plane)
    near = Plane(flat(0), 0.02, facing, [1.0, 0.0, 0.0])
    far = Plane(flat(255), 0.1, rotation_z(math.pi) @ rotation_x(0.3), [4.0, 0.0, 0.0])
    for planes in ([near, far], [far, near]):
        assert sim.render(planes, R_BODY, np.zeros(3))[centre] == 0


def test_antialiasing_of_edges():
    """A vertical black/white edge at a sub-pixel position gives the area-weighted grey."""
    cam = CameraModel(64, 48, np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]]),
                      np.zeros(5))
    opts = RenderOptions(supersample=4, black=0.0, white=1.0, background=0.0)
    sim = CameraSimulator(cam, opts)
    # white plane whose left edge projects to u = 20.25 - 0.5 (pixel 20 covered 75 %)
    z = 2.0
    edge_u = 20.25 - 0.5
    y_edge = (edge_u - 31.5) / 100.0 * z  # optical x of the edge
    width = 2.0
    centre_opt = np.array([y_edge + width / 2, 0.0, z])
    # plane normal -z (towards the camera), texture right = +x, texture up = -y (image up)
    R_plane = np.column_stack([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    plane = Plane(flat(255, (100, 100)), width / 100, R_plane, centre_opt)
    img = CameraSimulator(cam, opts).render_reflectance([plane], np.eye(3), np.zeros(3))
    assert img[24, 19] == pytest.approx(0.0, abs=0.01)
    assert img[24, 20] == pytest.approx(0.75, abs=0.07)
    assert img[24, 21] == pytest.approx(1.0, abs=0.01)
    del sim


@pytest.mark.parametrize('supersample', [8, 9])
def test_tiled_supersampling_equals_the_whole_canvas(monkeypatch, supersample):
    """Above TILED_SUPERSAMPLE only the planes' tiles are supersampled, with the same image.

    Inside the tiles bit for bit; elsewhere the 3-tap filter stands for the round trip up
    and down (largest relative difference measured 1e-6: float32 rounding).
    """
    import landmark_nav.sim.camera as camera
    from landmark_nav.sim.landmark_views import view_scene
    opts = ViewOptions(distance=1.5, turn_deg=20.0, distractors=4, photometry=Photometry())
    planes = view_scene(np.random.default_rng([3, 0]), CAM, opts)[0]
    sim = CameraSimulator(CAM, RenderOptions(supersample=supersample))
    tiles = []
    monkeypatch.setattr(sim, '_render_tiles', lambda low, items, found: tiles.extend(
        found) or CameraSimulator._render_tiles(sim, low, items, found))
    tiled = sim.render_ideal(planes, np.eye(3), np.zeros(3))
    monkeypatch.setattr(camera, 'TILED_SUPERSAMPLE', supersample)
    whole = sim.render_ideal(planes, np.eye(3), np.zeros(3))
    assert len(tiles) >= 2 and 'landmark' in [it[0].label for t in tiles for it in t[4]]
    inside = np.zeros(whole.shape, dtype=bool)
    for x0, y0, x1, y1, _ in tiles:
        inside[y0:y1, x0:x1] = True
        assert np.array_equal(tiled[y0:y1, x0:x1], whole[y0:y1, x0:x1])
    assert 0.05 < inside.mean() < 0.5
    np.testing.assert_allclose(tiled[~inside], whole[~inside], rtol=2e-6, atol=0.0)


def test_mipmaps_keep_mean_brightness():
    """A fine checker far away renders as its mean grey, not as aliasing noise."""
    tex = np.kron((np.indices((64, 64)).sum(0) % 2).astype(np.uint8) * 255,
                  np.ones((2, 2), np.uint8))
    plane = Plane(tex, 0.002, rotation_z(math.pi), [3.0, 0.0, 0.0])  # 0.256 m, 2 mm squares
    sim = CameraSimulator(PINHOLE, RenderOptions(black=0.0, white=1.0, background=0.5))
    img = sim.render_reflectance([plane], R_BODY, np.zeros(3))
    c = img[110:130, 150:170]
    assert c.mean() == pytest.approx(0.5, abs=0.03) and c.std() < 0.05


def test_blur_kernels():
    k = motion_kernel(5.0, 0.0)
    assert k.sum() == pytest.approx(1.0)
    assert np.allclose(k[:k.shape[0] // 2], 0) and np.allclose(k[k.shape[0] // 2 + 1:], 0)
    kd = motion_kernel(5.0, math.pi / 4)
    assert np.allclose(kd, kd.T, atol=1e-6)
    sim = CameraSimulator(PINHOLE, RenderOptions(black=0.0, white=1.0, background=0.0))
    plane = Plane(flat(255, (10, 10)), 0.005, rotation_z(math.pi), [3.0, 0.0, 0.0])
    sharp = sim.render([plane], R_BODY, np.zeros(3)).astype(float)
    soft = sim.render([plane], R_BODY, np.zeros(3), Photometry(defocus_sigma=2.0)).astype(float)
    assert soft.sum() == pytest.approx(sharp.sum(), rel=0.01)  # blur keeps the energy
    assert soft.max() < sharp.max()


def test_plane_validation():
    with pytest.raises(ValueError):
        Plane(np.zeros((4, 4), np.float32), 0.1, np.eye(3), np.zeros(3))
    with pytest.raises(ValueError):
        Plane(flat(0), 0.0, np.eye(3), np.zeros(3))
    with pytest.raises(ValueError):
        Plane(flat(0), 0.1, np.diag([1.0, 1.0, -1.0]), np.zeros(3))
    with pytest.raises(ValueError):
        Photometry(gamma=0.0)
    with pytest.raises(ValueError):
        RenderOptions(supersample=0)
    p = landmark_plane(156, LandmarkDesign(), rotation_z(math.pi), [1.0, 0, 0], 16)
    assert p.width == pytest.approx(0.225) and p.label == 'landmark'
