"""Landmark detector core (visual navigation §2.2.1-2.2.3) against independent truth.

Truth comes from the camera simulator's scene (corner pixels projected from the landmark
pose) or from synthetic inputs built here, never from the detector itself.
"""

import math

import cv2
from landmark_nav.sim.camera import Photometry
from landmark_nav.sim.camera_scenarios import default_camera, landmark_view, ViewOptions
from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.code_reading import cell_evidence
from landmark_nav.vision.detector import (chain_edges, corner_groups, corner_neighbours,
                                          corner_pixels, detect_landmarks, DetectorParams,
                                          edge_points, find_frames, frame_edges,
                                          image_problem, read_code, saddle_corners,
                                          sample_cells, smooth, unblur_code, unmix_cells)
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np
import pytest

CAMERA = default_camera()   # 640 x 480, f = 600 px, barrel distortion


def view(code=156, roll=0.0, distance=1.0, turn=0.0, tilt=0.0, design=LandmarkDesign(),
         centre=(330.0, 250.0), noise=1.0, camera=CAMERA, seed=5, index=0):
    opts = ViewOptions(distance=distance, turn_deg=turn, tilt_deg=tilt, roll_deg=roll,
                       quarter_turns=False, code=code, design=design, distractors=0,
                       photometry=Photometry(noise_sigma=noise, defocus_sigma=0.4),
                       centre_px=centre)
    return landmark_view(seed, index, camera, opts)


def x_corner(size=41, centre=(20.3, 19.6), angle=0.0, polarity=1, lo=30, hi=220, ss=8):
    """Return an ideal X-corner (checkerboard crossing), area-sampled, rotated by angle."""
    n = size * ss
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / ss - 0.5
    c, s = math.cos(angle), math.sin(angle)
    u = c * (x - centre[0]) + s * (y - centre[1])
    v = -s * (x - centre[0]) + c * (y - centre[1])
    bright = (u * v > 0) if polarity > 0 else (u * v < 0)
    img = np.where(bright, float(hi), float(lo))
    return cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA).astype(np.uint8)


# ---------------------------------------------------------------------- eq. 1-2


@pytest.mark.parametrize('angle, polarity, expected', [
    (0.0, 1, 0), (0.0, -1, 1),                       # C1: bright upper-left / lower-right
    (math.pi / 4, 1, 2), (math.pi / 4, -1, 3)])      # C3: bright above and below
def test_corner_filter_sets_and_weighted_centre(angle, polarity, expected):
    img = x_corner(angle=angle, polarity=polarity)
    pix = corner_pixels(smooth(img))
    counts = [len(p) for p in pix]
    assert counts[expected] > 0
    assert sum(counts) == counts[expected], counts      # no other filter responds
    assert np.all(pix[expected][:, 2] > 0)               # eq. 1 weights are positive
    groups = corner_groups(pix)
    assert len(groups.points) == 1
    assert groups.filters[0] == expected
    np.testing.assert_allclose(groups.points[0], (20.3, 19.6), atol=0.5)   # eq. 2 centre


def test_eight_bit_filter_is_exactly_eq1():
    # eq. 1 evaluated directly (integers, every pixel) against the fast 8-bit filter
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (60, 70), dtype=np.uint8),
              (rng.random((60, 70)) > 0.5).astype(np.uint8) * 255,
              cv2.resize(rng.integers(0, 256, (8, 9), dtype=np.uint8), (70, 60),
                         interpolation=cv2.INTER_NEAREST)]
    offsets = {0: [(-2, -2), (2, -2), (-2, 2), (2, 2)], 1: [(2, -2), (-2, -2), (2, 2), (-2, 2)],
               2: [(-3, 0), (0, -3), (0, 3), (3, 0)], 3: [(0, -3), (-3, 0), (3, 0), (0, 3)]}
    for img in images:
        for k_min in (0, 7, 40):
            g = smooth(img)
            got = corner_pixels(g, k_min)
            h, w = g.shape
            gi = g.astype(int)
            for f, offs in offsets.items():
                y1, y2, y3, y4 = (gi[3 + dy:h - 3 + dy, 3 + dx:w - 3 + dx] for dy, dx in offs)
                stack = np.stack([y1, y2, y3, y4])
                kc3 = stack.max(0) - stack.min(0) + 3 * k_min        # 3 k_c (eq. 1)
                ok = ((3 * (y1 - y2) > kc3) & (3 * (y1 - y3) > kc3) & (3 * (y4 - y2) > kc3)
                      & (3 * (y4 - y3) > kc3))
                want = {(x + 3, y + 3) for y, x in zip(*np.nonzero(ok))}
                assert {(int(x), int(y)) for x, y, _ in got[f]} == want, (f, k_min)


def test_corner_filter_threshold_k_min():
    # contrast of 2 * k_min passes, below k_min does not (eq. 1: differences > k_c)
    assert sum(len(p) for p in corner_pixels(smooth(x_corner(lo=100, hi=100 + 30)))) > 0
    assert sum(len(p) for p in corner_pixels(smooth(x_corner(lo=100, hi=100 + 6)))) == 0


def test_corner_groups_merge_filters_at_22_5_degrees():
    img = x_corner(angle=math.radians(22.5))
    groups = corner_groups(corner_pixels(smooth(img)))
    assert len(groups.points) == 1                      # C1 and C3 groups merged
    np.testing.assert_allclose(groups.points[0], (20.3, 19.6), atol=0.5)


def l_corner(size=41, tip=(20.3, 19.6), angle=0.0, lo=0, hi=220, ss=8):
    """Return one dark quadrant on white (an L-corner, e.g. a black block at the quiet zone)."""
    n = size * ss
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / ss - 0.5
    c, s = math.cos(angle), math.sin(angle)
    u = c * (x - tip[0]) + s * (y - tip[1])
    v = -s * (x - tip[0]) + c * (y - tip[1])
    img = np.where((u < 0) & (v < 0), float(lo), float(hi))
    return cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA).astype(np.uint8)


@pytest.mark.parametrize('angle, polarity, expected', [
    (0.0, 1, 0), (0.0, -1, 1), (math.pi / 4, 1, 2), (math.pi / 4, -1, 3)])
def test_saddle_corners_filter_and_saddle_point(angle, polarity, expected):
    # the same X-corners as eq. 1: one candidate with the eq. 1 filter's label, at the
    # saddle point (measured within 0.07 px; the eq. 2 centre test allows 0.5)
    c = saddle_corners(smooth(x_corner(angle=angle, polarity=polarity)), 1000.0, 0.1)
    assert len(c.points) == 1 and c.filters[0] == expected
    np.testing.assert_allclose(c.points[0], (20.3, 19.6), atol=0.1)
    assert c.weights[0] > 10 * 1000.0


@pytest.mark.parametrize('blur', [1.0, 1.5])
def test_saddle_corners_drop_the_tip_of_an_l_corner(blur):
    # an L-corner has a saddle-like Hessian at its tip too, but a gradient there: its
    # Newton step is longer than max_step; an X-corner blurred alike is kept
    def blurred(img):
        return smooth(cv2.GaussianBlur(img, (0, 0), blur))
    for angle in (0.0, 0.5, 1.0):
        lc = blurred(l_corner(angle=angle))
        assert len(saddle_corners(lc, 1000.0, 0.1, max_step=100.0).points) >= 1
        assert len(saddle_corners(lc, 1000.0, 0.1).points) == 0
        xc = saddle_corners(blurred(x_corner(angle=angle, lo=0)), 1000.0, 0.1)
        assert len(xc.points) == 1
        np.testing.assert_allclose(xc.points[0], (20.3, 19.6), atol=0.1)


def test_saddle_corners_find_every_x_corner_of_a_small_landmark_at_60_degrees():
    # 3.5 px per block (mean spacing) seen at 60 degrees: the eq. 1 filters miss 5-9 of the
    # 20 frame X-corners in each view and no landmark is read; the saddle points give all
    # of them and every landmark
    eq1_missed = 0
    for seed in range(6):
        frame = view(code=156, distance=3.0, tilt=60.0, roll=20.0 * seed, seed=seed, noise=2.0)
        lm = frame.landmarks[0]
        truth = lm.edge_corners_px[:, :-1].reshape(-1, 2)
        g = smooth(frame.image)

        def missed(points):
            d = np.linalg.norm(truth[:, None] - points[None], axis=2).min(axis=1)
            return int(np.sum(d > 0.35 * lm.block_px))
        assert missed(saddle_corners(g, 1000.0, 0.1).points) == 0
        eq1_missed += missed(corner_groups(corner_pixels(g)).points) > 0
        assert [d.code for d in detect_landmarks(frame.image, camera=CAMERA)] == [156]
    assert eq1_missed >= 5


# ---------------------------------------------------------------------- eq. 3-4


def _grid_points(h, n=6, step=10.0, origin=(100.0, 80.0)):
    """Points of an n x n grid mapped by homography h (rows: grid row, col)."""
    j, i = np.mgrid[0:n, 0:n].astype(float)
    p = np.stack([origin[0] + step * i, origin[1] + step * j, np.ones_like(i)], -1) @ h.T
    return (p[..., :2] / p[..., 2:]).reshape(-1, 2)


def test_frame_edges_follow_a_perspective_edge_and_reject_a_kink():
    h = np.array([[1.0, 0.1, 0.0], [0.05, 1.0, 0.0], [0.005, 0.0004, 1.0]])
    line = _grid_points(h)[:6]                    # six collinear, shrinking spacing
    spacing = np.linalg.norm(np.diff(line, axis=0), axis=1)
    assert spacing.max() / spacing.min() > 1.15   # a real perspective change
    rng = np.random.default_rng(1)
    clutter = rng.uniform(0, 200, (40, 2))
    clutter = clutter[np.min(np.linalg.norm(clutter[:, None] - line[None], axis=2), 1) > 5]
    pts = np.vstack([line, clutter])
    nb = corner_neighbours(pts, 100.0, 8)
    edges = frame_edges(pts, nb, 6)
    as_sets = [tuple(e) for e in edges]
    assert tuple(range(6)) in as_sets and tuple(range(5, -1, -1)) in as_sets
    # move the fourth corner off the line by half a spacing: |h - h^| > k_lim |v|
    kinked = pts.copy()
    d = line[4] - line[3]
    kinked[3] += 0.5 * np.array([-d[1], d[0]])
    edges = frame_edges(kinked, corner_neighbours(kinked, 100.0, 8), 6)
    assert tuple(range(6)) not in [tuple(e) for e in edges]


def test_find_frames_on_a_corner_ring_but_not_its_mirror():
    h = np.array([[1.0, 0.2, 0.0], [-0.1, 0.9, 0.0], [0.001, -0.0008, 1.0]])
    grid = _grid_points(h).reshape(6, 6, 2)
    ring = np.concatenate([grid[0, :], grid[1:, 5], grid[5, :5], grid[1:5, 0]])
    nb = corner_neighbours(ring, 200.0, 8)
    frames = find_frames(ring, frame_edges(ring, nb, 6))
    assert len(frames) == 1
    f = frames[0]
    assert f[0][0] == f[1][0] and f[1][-1] == f[2][0] and f[0][-1] == f[3][0]   # eq. 4
    assert f[2][-1] == f[3][-1]
    # opposite edges made unequal by more than k_p: no frame
    squeezed = ring.copy()
    right = np.isin(np.arange(len(ring)), list(range(5, 11)))
    squeezed[right, 1] = grid[0, 5, 1] + 0.3 * (squeezed[right, 1] - grid[0, 5, 1])
    assert find_frames(squeezed, frame_edges(squeezed, corner_neighbours(squeezed, 200.0),
                                             6)) == []


# ---------------------------------------------------------------------- code (§2.2.3)


def _ideal_cells(design, code, black=40.0, white=200.0):
    """Cell means of a perfectly read frame: inner ring + code area in half blocks."""
    k = 2 * (design.n_blocks - 2)
    rows, cols = np.mgrid[0:k, 0:k]
    colour = design.block_colours()[1 + rows // 2, 1 + cols // 2]
    cells = np.where(colour == 1, black, white).astype(float)
    m2 = 2 * design.code_squares
    cells[2:2 + m2, 2:2 + m2] = np.where(design.encode(code), black, white)
    return cells


@pytest.mark.parametrize('kind, code', [('3x3', 156), ('3x3', 123456789), ('3x3', 0),
                                        ('2x2', 0), ('2x2', 511), ('2x2', 300)])
def test_read_code_in_all_rotations(kind, code):
    design = LandmarkDesign(kind)
    cells = _ideal_cells(design, code)
    for k in range(4):
        seen = np.rot90(cells, -k)                # the landmark turned by k quarter turns
        r = read_code(seen, design)
        assert r.code == code and r.rotation == k % 4
        assert r.contrast == pytest.approx(160.0)
        assert r.margin == pytest.approx(1.0)


def test_read_code_rejects_inconsistent_grids():
    design = LandmarkDesign()
    cells = _ideal_cells(design, 156)
    bad = cells.copy()
    bad[0, 0] = 200.0                            # a black frame cell reads white
    assert read_code(bad, design).reason == 'frame cells inconsistent'
    grey = cells.copy()
    grey[5, 5] = 120.0                           # a code cell right at the threshold
    assert read_code(grey, design).reason == 'ambiguous code cell'
    flat = np.full_like(cells, 120.0)
    assert read_code(flat, design).reason == 'low contrast'
    nomark = cells.copy()
    nomark[2:4, 2:4] = 200.0                     # orientation mark erased
    assert read_code(nomark, design).code is None


# ---------------------------------------------------------------------- whole images


@pytest.mark.parametrize('code', [156, 123456789])
@pytest.mark.parametrize('roll', [0.0, 22.5, 45.0, 90.0, 200.0, 292.5])
def test_figure_codes_round_trip_with_ordered_corners(code, roll):
    frame = view(code, roll=roll)
    truth = frame.landmarks[0]
    dets = detect_landmarks(frame.image, camera=CAMERA)
    assert [d.code for d in dets] == [code]
    d = dets[0]
    # corners in the order of LandmarkDesign.frame_corners(): the roll is resolved
    np.testing.assert_allclose(d.corners, truth.corners_px, atol=0.15)
    np.testing.assert_allclose(d.edge_corners, truth.edge_corners_px, atol=0.5)
    assert d.block_pixels == pytest.approx(truth.block_px, rel=0.05)
    assert d.bits.shape == (6, 6) and np.array_equal(d.bits, LandmarkDesign().encode(code))


def test_small_landmark_variant():
    design = LandmarkDesign('2x2')
    params = DetectorParams(kind='2x2')
    for i, code in enumerate((0, 5, 300, 511)):
        frame = view(code, roll=30.0 * i, design=design, distance=0.8)
        dets = detect_landmarks(frame.image, params, CAMERA)
        assert [d.code for d in dets] == [code]
        assert dets[0].edge_corners.shape == (4, 5, 2)
        np.testing.assert_allclose(dets[0].corners, frame.landmarks[0].corners_px, atol=0.2)
    # a large landmark is not a small one and vice versa
    assert detect_landmarks(view(156).image, params, CAMERA) == []
    assert detect_landmarks(view(5, design=design).image, camera=CAMERA) == []


def test_mirror_image_is_not_a_landmark():
    for code in (156, 123456789):
        img = np.ascontiguousarray(view(code, centre=(319.5, 239.5)).image[:, ::-1])
        assert detect_landmarks(img) == []


def test_distortion_aware_fit_is_more_accurate():
    cam = CameraModel(640, 480, CAMERA.K, np.array([-0.35, 0.15, 0.0, 0.0, 0.0]))
    frame = view(156, distance=0.6, centre=(520.0, 380.0), camera=cam)
    truth = frame.landmarks[0].corners_px
    with_cam = detect_landmarks(frame.image, camera=cam)[0].corners
    without = detect_landmarks(frame.image)[0].corners
    err_with = np.abs(with_cam - truth).max()
    err_without = np.abs(without - truth).max()
    assert err_with < 0.15 < err_without


def test_sub_pixel_steps_improve_on_plain_eq2_centres():
    errs = {True: [], False: []}
    for i in range(6):
        frame = view(156, distance=2.0, roll=7.0 * i, turn=10.0 * i - 25, index=i)
        truth = frame.landmarks[0].corners_px
        for refine in (True, False):
            params = DetectorParams(refine_corners=refine, refine_edges=refine)
            d = detect_landmarks(frame.image, params, CAMERA)[0]
            errs[refine].append(np.sqrt(np.mean(np.sum((d.corners - truth) ** 2, axis=1))))
    assert np.mean(errs[True]) < 0.5 * np.mean(errs[False])
    assert max(errs[True]) < 0.08


def test_image_problems_and_bad_arrays():
    assert image_problem(np.zeros((48, 64), np.uint8))[1] is False
    assert image_problem(np.full((48, 64), 255, np.uint8))[1] is False
    assert image_problem(np.full((48, 64), 128, np.uint8))[1] is False
    sat = np.full((48, 64), 255, np.uint8)
    sat[:10] = 0
    problem, usable = image_problem(sat)
    assert usable and 'overexposed' in problem
    assert image_problem(view().image) == ('', True)
    assert detect_landmarks(np.zeros((48, 64), np.uint8)) == []
    assert detect_landmarks(np.zeros((3, 3), np.uint8)) == []
    with pytest.raises(ValueError, match='2-D'):
        detect_landmarks(np.zeros((4, 4, 3), np.uint8))
    noisy = np.nan_to_num(view().image.astype(float))
    noisy[0, 0] = np.nan                                # float input, NaN tolerated
    assert [d.code for d in detect_landmarks(noisy, camera=CAMERA)] == [156]


@pytest.mark.parametrize('field, value', [('kind', '4x4'), ('k_lim', 0.0), ('k_min', 7.5),
                                          ('neighbour_mode', 'all'), ('max_neighbours', 1),
                                          ('refine_edges', 1), ('corner_method', 'harris'),
                                          ('saddle_kappa', -0.1)])
def test_detector_params_are_validated(field, value):
    with pytest.raises(ValueError, match=field):
        DetectorParams(**{field: value})


def test_unmixing_reads_a_blurred_code_that_the_cell_threshold_cannot():
    # a cell keeps half of its own whiteness and takes the rest from its 8 neighbours:
    # isolated cells sit on the threshold, the known frame tells the mixing
    design = LandmarkDesign()
    rng = np.random.default_rng(5)
    kernel = np.array([[0.025, 0.1, 0.025], [0.1, 0.5, 0.1], [0.025, 0.1, 0.025]])
    codes = [int(c) for c in rng.integers(0, design.code_limit, 40) if design.is_valid_code(c)]
    ambiguous = read = 0
    for code in codes[:20]:
        white = 1.0 - design.half_block_image(code, 0).astype(float)      # 14 x 14 cells
        seen = 30.0 + 170.0 * cv2.filter2D(white, -1, kernel,
                                           borderType=cv2.BORDER_REPLICATE)[2:12, 2:12]
        seen += rng.normal(0.0, 2.0, seen.shape)
        ambiguous += read_code(seen, design).reason == 'ambiguous code cell'
        whiteness, residual = unmix_cells(seen, design)
        assert residual < 0.02                      # noise 2 / contrast 170 = 0.012
        assert np.array_equal(whiteness > 0.5, white[4:10, 4:10] > 0.5)
        read += read_code(seen, design, deblur_margin=0.35).code == code
    assert ambiguous >= 10 and read == 20          # 14 of 20 ambiguous per cell


def test_second_neighbour_of_a_sector_finds_an_edge_at_an_acute_frame_corner():
    # two frame edges 25 deg apart in the image (strong tilt) share a 45-degree sector:
    # the nearer, foreshortened edge hides the other unless the second neighbour is kept
    corner = np.zeros((1, 2))
    along = np.arange(1, 6)[:, None] * np.array([[10.0, 0.0]])
    short = np.arange(1, 6)[:, None] * 6.0 * np.array([[math.cos(math.radians(25.0)),
                                                        math.sin(math.radians(25.0))]])
    pts = np.vstack([corner, along, short])
    filters = np.array([0, 1, 0, 1, 0, 1, 1, 0, 1, 0, 1])
    for angle, found in ((0.0, False), (math.radians(20.0), True)):
        nb = corner_neighbours(pts, 100.0, 8, mode='sectors', second_angle=angle)
        assert (1 in nb[0]) == found and 6 in nb[0]
        nb[1:] = len(pts)                     # chains may start at the frame corner only
        edges = frame_edges(pts, nb, 6, filters=filters)
        assert any(list(e) == [0, 1, 2, 3, 4, 5] for e in edges.tolist()) == found


def test_chain_edges_bridge_one_missed_interior_corner():
    h = np.array([[1.0, 0.1, 0.0], [0.05, 1.0, 0.0], [0.005, 0.0004, 1.0]])
    line = _grid_points(h)[:6]
    spacing = float(np.linalg.norm(np.diff(line, axis=0), axis=1).mean())
    rng = np.random.default_rng(1)
    clutter = rng.uniform(0, 200, (40, 2))
    clutter = clutter[np.min(np.linalg.norm(clutter[:, None] - line[None], axis=2), 1) > 5]
    for missing in (1, 2, 3, 4):
        pts = np.vstack([np.delete(line, missing, axis=0), clutter])
        nb = corner_neighbours(pts, 100.0, 8)
        assert len(frame_edges(pts, nb, 6)) == 0 or not any(
            e[0] == 0 and e[-1] == 4 for e in frame_edges(pts, nb, 6).tolist())
        edges, virtual = chain_edges(pts, nb, 6, max_gaps=1)
        n = len(pts)
        want = [0, 1, 2, 3, 4]
        want.insert(missing, n)
        hits = [e for e in edges.tolist() if e == want or e == want[::-1]]
        assert len(hits) == 2                                   # once in each direction
        # the bridged corner is the eq. 3 prediction: within the k_lim tolerance a detected
        # corner would have (0.10-0.2 of the spacing here, perspective shrinks it by 15 %)
        assert np.linalg.norm(virtual[0] - line[missing]) < 0.37 * spacing
        assert len(virtual) == 1
    # two neighbouring corners missed, or an end corner: no edge
    for gone in ([2, 3], [5]):
        pts = np.vstack([np.delete(line, gone, axis=0), clutter])
        edges, _ = chain_edges(pts, corner_neighbours(pts, 100.0, 8), 6, max_gaps=1)
        ends = {(e[0], e[-1]) for e in edges.tolist()}
        assert (0, 6 - len(gone) - 1) not in ends or gone == [5]
        assert not any(e[0] == 0 and len(set(e) & set(range(6 - len(gone)))) >= 4
                       and e[-1] < 6 - len(gone) for e in edges.tolist() if gone == [5])


def test_block_ring_tolerates_a_noisy_half_cell_but_not_a_wrong_block():
    design = LandmarkDesign()
    cells = _ideal_cells(design, 156)             # black 40, white 200, threshold 120
    noisy = cells.copy()
    noisy[0, 1] = 130.0                           # one half cell of a black block near grey
    assert read_code(noisy, design).reason == 'frame cells inconsistent'
    assert read_code(noisy, design, block_ring=True).code == 156
    wrong = cells.copy()
    wrong[0:2, 0:2] = 200.0                       # a whole black frame block reads white
    assert read_code(wrong, design, block_ring=True).reason == 'frame cells inconsistent'


def _small_view(code, design, blur, rng, noise=3.0):
    """Return a landmark at 4 px per block, blurred and noisy, and its true code grid.

    Rendered at 8 px per block and 2 x 2 area-averaged; the grid is FrameGrid's (half-block
    steps between the frame corners).
    """
    img = cv2.resize(design.render(code, 8, 1).astype(np.float32), None, fx=0.5, fy=0.5,
                     interpolation=cv2.INTER_AREA)
    img = cv2.copyMakeBorder(img, 10, 10, 10, 10, cv2.BORDER_CONSTANT, value=255)
    img = 30.0 + 170.0 / 255.0 * img
    img = cv2.GaussianBlur(img, (0, 0), blur) + rng.normal(0.0, noise, img.shape)
    k = 2 * (design.n_blocks - 2)
    i, j = np.mgrid[0:k + 1, 0:k + 1]
    # grid point (u, v) blocks -> rendered pixel (u + 1) 8 - 0.5 -> (x + 0.5) / 2 - 0.5 + 10
    u, v = 1.0 + 0.5 * j, 1.0 + 0.5 * i
    grid = np.stack([(u + 1) * 4.0 - 0.5 + 10.0, (v + 1) * 4.0 - 0.5 + 10.0], axis=-1)
    return img.astype(np.float32), grid


def test_unblur_reads_small_blurred_codes_that_the_cells_cannot():
    design = LandmarkDesign()
    rng = np.random.default_rng(7)
    codes = [int(c) for c in rng.integers(0, design.code_limit, 30) if design.is_valid_code(c)]
    ambiguous = 0
    for code in codes[:12]:
        img, grid = _small_view(code, design, 1.3, rng)
        cells = sample_cells(img, grid)
        plain = read_code(cells, design, min_margin=0.4, deblur_margin=0.35)
        ambiguous += plain.code is None
        white, residual, sigma = unblur_code(img, grid, design)
        assert residual < 0.025                     # noise 3 / contrast 170 = 0.018
        assert sigma == 1.3                         # the tried blur nearest the true 1.3
        assert np.array_equal(white < 0.5, design.encode(code))
        assert np.abs(white - 0.5).min() > 0.25     # every cell clear (0.3 measured)
        got = read_code(cells, design, min_margin=0.4, deblur_margin=0.35, block_ring=True,
                        unblur=lambda parity: unblur_code(img, grid, design, parity))
        assert got.code == code and got.rotation == 0
    assert ambiguous >= 6                           # 6 of 12 lost by the cell reading
    # blurred beyond reach (sigma 1.7 at 2 px per cell): no reading, never a wrong one
    lost = 0
    for code in codes[12:24]:
        img, grid = _small_view(code, design, 1.7, rng)
        got = read_code(sample_cells(img, grid), design, min_margin=0.4, deblur_margin=0.35,
                        block_ring=True,
                        unblur=lambda parity: unblur_code(img, grid, design, parity))
        assert got.code in (None, code)
        lost += got.code is None
    assert lost >= 3


def test_fast_mode_finds_the_same_landmarks_with_full_resolution_corners():
    # corners on the 2 x 2-averaged image, everything after them at full resolution: the
    # sub-pixel frame corners agree with those of the full-resolution run
    for roll, distance in ((0.0, 1.0), (30.0, 1.2), (200.0, 0.8)):
        frame = view(123456789, roll=roll, distance=distance, tilt=20.0)
        full = detect_landmarks(frame.image, camera=CAMERA)
        fast = detect_landmarks(frame.image, DetectorParams(decimate=2), camera=CAMERA)
        assert [d.code for d in fast] == [d.code for d in full] == [123456789]
        assert np.abs(fast[0].corners - full[0].corners).max() < 1e-3    # 4e-5 measured
        assert fast[0].rotation == full[0].rotation


def test_edge_points_of_large_blocks_beyond_the_remap_limit():
    # 40 segments of 400 px blocks ask for 76 800 profile samples, more than one
    # cv2.remap call takes (fewer than 32 767 columns); a crash on a cluttered view before
    img = np.zeros((600, 600), np.float32)
    img[:, 300:] = 200.0
    img = cv2.GaussianBlur(img, (0, 0), 1.0)
    starts = np.tile([300.0, 10.0], (40, 1))
    ends = np.tile([300.0, 590.0], (40, 1))
    pts, seg = edge_points(img, starts, ends, np.full(40, 400.0))
    assert len(pts) == 240 and np.array_equal(np.unique(seg), np.arange(40))
    np.testing.assert_allclose(pts[:, 0], 299.5, atol=1e-3)    # between columns 299 and 300


def _mixed_cells(code, self_weight, noise=0.0, rng=None):
    """Cell means of the frame ring and code area, each cell mixed with its 8 neighbours.

    A cell keeps ``self_weight`` of its own whiteness and takes the rest equally from its
    neighbours (black 40, white 200 grey levels), plus Gaussian noise.
    """
    colour = np.repeat(np.repeat(DESIGN_3X3.block_colours(), 2, axis=0), 2, axis=1)
    white = np.where(colour == 0, 1.0, 0.0)
    white[4:10, 4:10] = 1.0 - DESIGN_3X3.encode(code)
    kernel = np.full((3, 3), (1.0 - self_weight) / 8.0)
    kernel[1, 1] = self_weight
    cells = 40.0 + 160.0 * cv2.filter2D(white, -1, kernel, borderType=cv2.BORDER_REPLICATE)
    cells = cells[2:-2, 2:-2]
    return cells if noise == 0 else cells + rng.normal(0.0, noise, cells.shape)


DESIGN_3X3 = LandmarkDesign('3x3')


def test_code_at_the_resolvability_edge_is_not_read_as_another_code():
    # an isolated black code cell keeping 0.3 of its contrast reads white at a margin of
    # 0.46: thresholding reads the valid code 0 instead of 1 << 24; the cell self weight
    # measured on the grid (0.31 < 1/2) sends the grid to unmixing, whose evidence test
    # reads the right code or nothing
    code = 1 << 24
    cells = _mixed_cells(code, 0.3)
    before = read_code(cells, DESIGN_3X3, min_margin=0.2, block_ring=True, deblur_margin=0.35)
    assert before.code == 0 and before.margin > 0.45          # the failure guarded against
    after = read_code(cells, DESIGN_3X3, min_margin=0.2, block_ring=True, deblur_margin=0.35,
                      error_rate=1e-3)
    assert after.code == code and after.method == 'unmixed'
    assert 0.28 < after.self_weight < 0.35                    # measured 0.31
    rng = np.random.default_rng(3)
    wrong_before = right = wrong = 0
    for _ in range(40):              # noise of 4 grey levels: 1/40 of the contrast
        noisy = _mixed_cells(code, 0.3, 4.0, rng)
        r0 = read_code(noisy, DESIGN_3X3, min_margin=0.2, block_ring=True, deblur_margin=0.35)
        r1 = read_code(noisy, DESIGN_3X3, min_margin=0.2, block_ring=True, deblur_margin=0.35,
                       error_rate=1e-3)
        wrong_before += r0.code is not None and r0.code != code
        right += r1.code == code
        wrong += r1.code is not None and r1.code != code
    assert wrong_before >= 30                  # measured 38 of 40
    assert wrong == 0 and right >= 5           # measured 11 right, 29 dropped


def test_clear_code_is_read_by_threshold_as_before():
    cells = _mixed_cells(1 << 24, 0.8)
    before = read_code(cells, DESIGN_3X3, min_margin=0.2, block_ring=True, deblur_margin=0.35)
    after = read_code(cells, DESIGN_3X3, min_margin=0.2, block_ring=True, deblur_margin=0.35,
                      error_rate=1e-3)
    assert before.code == after.code == 1 << 24
    assert after.method == 'threshold' and after.margin == before.margin
    assert after.self_weight == pytest.approx(0.8, abs=0.02)


def test_cell_evidence_is_the_log_likelihood_ratio_of_the_colour():
    x = np.array([0.9, 0.2, 0.5])
    s = np.array([0.1, 0.2, 0.1])
    # (x - 1/2) / s^2: 40, 7.5, 0
    assert cell_evidence(x[:2], s[:2]) == pytest.approx(7.5)
    assert cell_evidence(x, s) == 0.0
