"""Line extractors: TLS fit, covariance, lowess, split-and-merge and ALFA, office and real logs."""

import math
from pathlib import Path

from hypothesis import example, given, settings
from hypothesis import strategies as st
from landmark_nav.evaluation.features import _cut_variance, FeatureRun, line_crlb, score_scan
from landmark_nav.geometry import compose, wrap_angle
from landmark_nav.laser.lines import (explained_points, extract_lines, fit_line, LineParams,
                                      lowess, METHODS, point_covariances, split_pieces)
from landmark_nav.laser.range_noise import gate_sigma
from landmark_nav.laser.segmentation import Cluster, segment_scan
from landmark_nav.sim import run_scenario, ScanSample, World
from landmark_nav.slam.features import extract_scan_features
from landmark_nav.testing import shared_data
import numpy as np
import pytest

SIGMA_PHI = math.radians(0.1)


def wall_points(rho, alpha, t, sigma_r=0.0, sigma_phi=0.0, rng=None):
    """Beams hitting the line x cos a + y sin a = rho at parameters t along it.

    With noise, as the simulator does it: the beam is reported at its nominal bearing but
    travels along a perturbed one (eq. 3) and its range gets eps_d (eq. 2).
    """
    n = np.array([math.cos(alpha), math.sin(alpha)])
    d = np.array([-math.sin(alpha), math.cos(alpha)])
    pts = rho * n + np.outer(t, d)
    r, phi = np.hypot(pts[:, 0], pts[:, 1]), np.arctan2(pts[:, 1], pts[:, 0])
    if rng is not None:
        true_phi = phi + rng.normal(0.0, sigma_phi, r.shape)
        r = rho / np.cos(true_phi - alpha) + rng.normal(0.0, sigma_r, r.shape)
        pts = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    return pts, r, phi


def cluster_of(r, phi):
    """One cluster holding all beams."""
    pts = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    return Cluster(np.arange(len(r)), pts, np.asarray(r, float), np.asarray(phi, float))


# ------------------------------------------------------------------------- TLS fit
@settings(max_examples=300, deadline=None)
@given(st.floats(0.0, 8.0), st.floats(-math.pi, math.pi - 1e-9), st.floats(-3, 3),
       st.floats(0.2, 3))
@example(0.0, 0.99999, -2.930792793592185, 0.201171875)  # a wall along one ray (below)
def test_tls_fit_is_exact_on_noise_free_points(rho, alpha, t0, length):
    pts, r, phi = wall_points(rho, alpha, np.linspace(t0, t0 + length, 30))
    got_rho, got_alpha, cov, rmse = fit_line(pts, r, phi, 0.01, 0.0)
    assert got_rho >= 0.0 and -math.pi <= got_alpha < math.pi
    assert rmse == pytest.approx(0.0, abs=1e-9)
    # the same line: every point on it, and (rho, alpha) equal up to the sign ambiguity of
    # a line through the origin
    n = np.array([math.cos(got_alpha), math.sin(got_alpha)])
    np.testing.assert_allclose(pts @ n, got_rho, atol=1e-9)
    if rho > 1e-6:
        assert got_rho == pytest.approx(rho, abs=1e-9)
        assert float(wrap_angle(got_alpha - alpha)) == pytest.approx(0.0, abs=1e-9)
    # positive semi-definite up to rounding of terms of size sigma_r^2 = 1e-4 m^2: a wall
    # through the laser (rho = 0) lies along one ray, range noise moves its points along
    # it, so the covariance is 0 and came out as -1.3e-18 (CI; an absolute -1e-18 bound)
    assert np.all(np.linalg.eigvalsh(cov) >= -1e-12 * 0.01 ** 2)


@pytest.mark.parametrize('rho,alpha', [(2.0, 0.0), (2.0, math.pi / 2), (2.0, -math.pi / 2),
                                       (2.0, -math.pi), (0.5, 3.0), (1e-3, 1.0)])
def test_axis_aligned_and_near_origin_lines(rho, alpha):
    pts, r, phi = wall_points(rho, alpha, np.linspace(-1.0, 1.0, 21))
    got_rho, got_alpha, _, _ = fit_line(pts)  # ranges and bearings from the points
    assert got_rho == pytest.approx(rho, abs=1e-12)
    assert float(wrap_angle(got_alpha - alpha)) == pytest.approx(0.0, abs=1e-12)
    assert -math.pi <= got_alpha < math.pi


def test_line_through_origin_has_zero_rho():
    pts = np.column_stack([np.linspace(-1, 1, 21), np.linspace(-1, 1, 21)])
    rho, alpha, _, _ = fit_line(pts)
    assert rho == pytest.approx(0.0, abs=1e-12)
    assert abs(float(wrap_angle(alpha - 3 * math.pi / 4))) < 1e-9 or abs(
        float(wrap_angle(alpha + math.pi / 4))) < 1e-9


def test_fit_line_rejects_bad_input():
    with pytest.raises(ValueError):
        fit_line(np.zeros((1, 2)))
    with pytest.raises(ValueError):
        fit_line(np.zeros((3, 3)))


# ------------------------------------------------------------------------- covariance
@pytest.mark.parametrize('rho,alpha,t0,length', [
    (2.0, 0.3, -1.0, 2.0),     # facing the laser
    (5.0, -1.2, 0.5, 1.5),     # far, oblique
    (1.0, 2.5, -0.3, 0.6),     # short
    (1.5, 0.0, 2.0, 3.0),      # grazing: 53-76 deg incidence
    (7.0, -2.0, -2.0, 4.0),    # far and long
])
def test_covariance_matches_monte_carlo(rho, alpha, t0, length):
    rng = np.random.default_rng(4)
    sigma_r = 0.01
    t = np.linspace(t0, t0 + length, 40)
    err, covs = [], []
    for _ in range(500):
        pts, r, phi = wall_points(rho, alpha, t, sigma_r, SIGMA_PHI, rng)
        got_rho, got_alpha, cov, _ = fit_line(pts, r, phi, sigma_r, SIGMA_PHI)
        err.append([got_rho - rho, float(wrap_angle(got_alpha - alpha))])
        covs.append(cov)
    err, cov = np.array(err), np.mean(covs, axis=0)
    ratio = np.diag(np.cov(err.T)) / np.diag(cov)
    assert np.all((ratio > 0.7) & (ratio < 1.3)), ratio
    nees = np.einsum('ni,nij,nj->n', err, np.linalg.inv(np.array(covs)), err)
    assert nees.mean() == pytest.approx(2.0, abs=0.25)


@pytest.mark.parametrize('rho, alpha, t0, length', [
    (2.0, 0.3, -1.0, 2.0),     # about the normal
    (1.5, 0.0, 2.0, 3.0),      # grazing: 53-76 deg incidence
    (7.0, -2.0, -2.0, 4.0),    # far and long
])
def test_crlb_bounds_the_fit_and_is_nearly_reached(rho, alpha, t0, length):
    """line_crlb: the TLS fit's Monte Carlo variances are at least the bound, and close to it.

    With equal weights TLS is not the ML estimator when the points' noise differs, so it
    can only be above the bound; on these walls by at most a few percent.
    """
    rng = np.random.default_rng(5)
    t = np.linspace(t0, t0 + length, 40)
    _, r, phi = wall_points(rho, alpha, t)
    bound = line_crlb(r, phi, rho, alpha, 0.01, SIGMA_PHI)
    assert np.all(np.linalg.eigvalsh(bound) > 0)
    err = []
    for _ in range(2000):
        pts, r_n, _ = wall_points(rho, alpha, t, 0.01, SIGMA_PHI, rng)
        got_rho, got_alpha, _, _ = fit_line(pts, r_n, phi, 0.01, SIGMA_PHI)
        err.append([got_rho - rho, float(wrap_angle(got_alpha - alpha))])
    ratio = np.var(np.array(err), axis=0) / np.diag(bound)
    assert np.all((ratio > 0.9) & (ratio < 1.15)), ratio  # 2000 draws: +-6 % (2 sigma)


def test_cut_variance_is_the_truncated_normal_variance():
    rng = np.random.default_rng(6)
    x = rng.normal(0.0, 2.0, 2_000_000)
    for limit in (1.0, 3.0, 8.0):
        kept = x[np.abs(x) <= limit]
        assert _cut_variance(4.0, limit) == pytest.approx(np.var(kept), rel=0.01)
    assert _cut_variance(0.0, 1.0) == 0.0
    assert _cut_variance(math.inf, 0.3) == pytest.approx(0.03)


def test_point_covariance_is_eq7():
    cov = point_covariances(np.array([2.0]), np.array([0.0]), 0.01, 0.001)[0]
    np.testing.assert_allclose(cov, [[1e-4, 0], [0, 4e-6]], atol=1e-15)
    phi = 0.7
    cov = point_covariances(np.array([3.0]), np.array([phi]), 0.02, 0.003)[0]
    s, c = math.sin(phi), math.cos(phi)
    q = 9 * 0.003 ** 2 / 2 * np.array([[2 * s * s, -math.sin(2 * phi)],
                                       [-math.sin(2 * phi), 2 * c * c]]) + 0.02 ** 2 / 2 * \
        np.array([[2 * c * c, math.sin(2 * phi)], [math.sin(2 * phi), 2 * s * s]])
    np.testing.assert_allclose(cov, q, atol=1e-15)


# ------------------------------------------------------------------------- lowess
def test_lowess_rejects_an_outlier():
    x = np.arange(41.0)
    y = 0.05 * x
    y[20] += 1.0
    smooth = lowess(x, y, span=7, iterations=2)
    assert abs(smooth[20] - 1.0) < 0.01          # the outlier is ignored (eq. 9)
    np.testing.assert_allclose(np.delete(smooth, 20), np.delete(0.05 * x, 20), atol=1e-9)
    plain = lowess(x, y, span=7, iterations=0)   # without robustness it leaks
    assert abs(plain[19] - 0.95) > 0.05


def test_lowess_reproduces_lines_and_smooths_noise():
    rng = np.random.default_rng(0)
    x = np.linspace(0, 1, 200)
    np.testing.assert_allclose(lowess(x, 3 * x - 1, 9, 2), 3 * x - 1, atol=1e-12)
    y = np.sin(3 * x) + rng.normal(0, 0.05, x.size)
    assert np.std(lowess(x, y, 15, 2) - np.sin(3 * x)) < 0.6 * np.std(y - np.sin(3 * x))
    unsorted = rng.permutation(x.size)
    np.testing.assert_allclose(lowess(x[unsorted], y[unsorted], 15, 2),
                               lowess(x, y, 15, 2)[unsorted], atol=1e-12)
    with pytest.raises(ValueError, match='span'):
        lowess(x, y, 1)


def test_window_sums_are_numpys_row_sums_bit_for_bit():
    # lowess sums each window over the first axis of a (K, ..., N) array; the sums must be
    # numpy's sums of the (N, K) layout (pairwise from 8 values on) to the last bit.
    from landmark_nav.laser.lowess import _window_sums
    rng = np.random.default_rng(5)
    for k in (1, 2, 3, 7, 8, 9, 15, 16, 17, 40, 128, 130):
        t = rng.normal(size=(k, 5, 37)) * 10.0 ** rng.uniform(-6, 6, size=(k, 5, 37))
        assert np.array_equal(_window_sums(t), np.moveaxis(t, 0, -1).copy().sum(axis=-1))


# ------------------------------------------------------------------------- extraction
def room_scan(sigma_r=0.01, seed=0):
    world = World('room')
    world.add_room([(0, 0), (6, 0), (6, 4), (0, 4)])
    angles = np.radians(np.arange(-180, 180, 0.5))
    hits = world.raycast(np.tile([[3.0, 2.0]], (len(angles), 1)), angles, 20.0)
    rng = np.random.default_rng(seed)
    r = hits.ranges + rng.normal(0, sigma_r, len(angles))
    return r, angles


@pytest.mark.parametrize('method', METHODS)
def test_square_room_gives_four_walls(method):
    r, angles = room_scan()
    clusters = segment_scan(r, angles, np.isfinite(r), math.radians(0.5))
    lines = extract_lines(clusters, LineParams(method=method))
    truth = [(3.0, 0.0), (2.0, math.pi / 2), (3.0, -math.pi), (2.0, -math.pi / 2)]
    # the wall behind the scan's first and last beam is seen as two clusters
    assert len(lines) in (4, 5)
    for rho, alpha in truth:
        best = min(lines, key=lambda ln: abs(ln.rho - rho) + abs(wrap_angle(ln.alpha - alpha)))
        assert best.rho == pytest.approx(rho, abs=0.01)
        assert abs(float(wrap_angle(best.alpha - alpha))) < math.radians(0.5)
        assert best.rmse < 0.015
    for ln in lines:
        assert ln.rho >= 0 and -math.pi <= ln.alpha < math.pi
        assert ln.first_index <= ln.last_index and ln.num_points >= 8
        np.testing.assert_allclose(ln.covariance, ln.covariance.T)
        assert np.all(np.linalg.eigvalsh(ln.covariance) > 0)
        assert ln.length == pytest.approx(np.hypot(*(ln.end - ln.start)))


@pytest.mark.parametrize('method', METHODS)
def test_l_shape_gives_two_lines(method):
    pts = np.vstack([np.column_stack([np.full(60, 2.0), np.linspace(-1.5, 0.0, 60)]),
                     np.column_stack([np.linspace(2.0, 0.5, 60)[1:], np.zeros(59)])])
    rng = np.random.default_rng(1)
    r = np.hypot(*pts.T) + rng.normal(0, 0.005, len(pts))
    phi = np.arctan2(pts[:, 1], pts[:, 0])
    order = np.argsort(phi)
    r, phi = r[order], phi[order]
    clusters = segment_scan(r, phi, np.ones(len(r), bool), float(np.median(np.diff(phi))))
    lines = extract_lines(clusters, LineParams(method=method, sigma_r=0.005))
    assert len(lines) == 2
    got = sorted((round(ln.rho, 2), round(math.degrees(ln.alpha))) for ln in lines)
    assert got == [(0.0, -90), (2.0, 0)] or got == [(0.0, 90), (2.0, 0)]


@pytest.mark.parametrize('method', METHODS)
def test_single_outlier_inside_a_wall_does_not_split_it(method):
    """A 12 cm outlier inside a wall leaves one line.

    ALFA: the robust lowess ignores the outlier. split_merge: eq. 4 splits at it, the pieces
    beside it are too short and are dropped, and the two halves merge again.
    """
    rng = np.random.default_rng(3)
    phi = np.radians(np.arange(-40, 40.01, 0.5))
    r = 3.0 / np.cos(phi) + rng.normal(0, 0.01, phi.size)
    r[87] -= 0.12  # inside the cluster (the breakpoint threshold is ~0.2 m here)
    clusters = segment_scan(r, phi, np.ones(phi.size, bool), math.radians(0.5))
    assert len(clusters) == 1
    lines = extract_lines(clusters, LineParams(method=method))
    assert len(lines) == 1
    (ln,) = lines
    assert (ln.first_index, ln.last_index) == (0, 160)
    assert ln.rho == pytest.approx(3.0, abs=0.005)
    assert abs(math.degrees(ln.alpha)) < 0.2
    if method == 'alfa':
        assert ln.num_points == 161  # every point supports the line (the outlier too)


@pytest.mark.parametrize('method', METHODS)
def test_a_piece_off_the_wall_leaves_the_chain_and_the_rest_merges(method):
    """A panel 5 mm proud of a wall leaves the merge chain; the wall pieces after it merge.

    Wall y = 1 m in four clusters (dropouts between them); the second, 40 beams, is the
    panel. Neighbours pass the pairwise test (the panel's fit is uncertain enough), but the panel
    fails against the merged line, so it leaves the chain: it stays a line of its own and
    the two pieces after it, which agree, become one line (they used to stay apart).
    """
    phi = np.radians(np.arange(30.0, 150.01, 0.5))
    y = np.ones(phi.size)
    y[81:121] += 0.005
    valid = np.ones(phi.size, bool)
    valid[[80, 121, 161]] = False
    clusters = segment_scan(1.0 * y / np.sin(phi), phi, valid, math.radians(0.5))
    assert [(c.indices[0], c.indices[-1]) for c in clusters] == [
        (0, 79), (81, 120), (122, 160), (162, 240)]
    lines = extract_lines(clusters, LineParams(method=method))
    assert [(ln.first_index, ln.last_index) for ln in lines] == [(0, 79), (81, 120),
                                                                 (122, 240)]
    assert [round(ln.rho, 4) for ln in lines] == [1.0, 1.005, 1.0]


def wall_behind_object(behind: str, seed: int = 5):
    """Wall y = 3 m seen from the origin with an object 0.6 m wide at y = 1.5 m in front.

    ``behind`` 'wall': the object occludes the wall; 'opening': the wall has a doorway
    where the object would be, through which the beams reach y = 5 m (no object).
    Returns ranges, bearings, the beams of the middle part.
    """
    rng = np.random.default_rng(seed)
    phi = np.radians(np.arange(30.0, 150.01, 0.5))
    x_at = 1.5 / np.tan(phi)  # where the beam crosses y = 1.5
    middle = np.abs(x_at) <= 0.3
    depth = np.where(middle, 1.5 if behind == 'wall' else 5.0, 3.0)
    true_phi = phi + rng.normal(0.0, SIGMA_PHI, phi.size)
    r = depth / np.sin(true_phi) + rng.normal(0.0, 0.01, phi.size)
    return r, phi, middle


@pytest.mark.parametrize('method', METHODS)
def test_wall_behind_an_occluder_is_one_fit(method):
    """A wall seen on both sides of an object in front of it is one line (one fit).

    The object cuts the wall into two clusters whose facing ends are 1.2 m / 22 deg apart
    (beyond ``merge_gap`` and ``merge_gap_angle``), with the object's line between them:
    each half used to be a line of its own, with the covariance of half the wall's beams.
    The beams between are occluded from the front, so the halves are joined: one fit of
    both halves' points, reported as one segment per side of the object.
    """
    r, phi, middle = wall_behind_object('wall')
    clusters = segment_scan(r, phi, np.ones(phi.size, bool), math.radians(0.5))
    assert len(clusters) == 3
    lines = extract_lines(clusters, LineParams(method=method))
    wall = [ln for ln in lines if abs(ln.rho - 3.0) < 0.05]
    assert len(wall) == 2
    left, right = sorted(wall, key=lambda ln: ln.first_index)
    assert (left.rho, left.alpha, left.num_points) == (right.rho, right.alpha,
                                                       right.num_points)
    np.testing.assert_array_equal(left.covariance, right.covariance)
    # the fit holds (nearly) every wall beam; its extents stop at the object
    assert left.num_points >= np.count_nonzero(~middle) - 6
    first_mid, last_mid = np.flatnonzero(middle)[[0, -1]]
    assert left.last_index < first_mid and right.first_index > last_mid
    truth = line_crlb(3.0 / np.sin(phi[~middle]), phi[~middle], 3.0, math.pi / 2, 0.01,
                      SIGMA_PHI)
    assert left.covariance[0, 0] < 1.1 * truth[0, 0]
    assert any(abs(ln.rho - 1.5) < 0.05 for ln in lines)  # the object's line stays


@pytest.mark.parametrize('method', METHODS)
def test_wall_with_a_doorway_without_returns_is_not_joined(method):
    """A doorway whose beams return nothing: the halves keep their own fits.

    The dropout is 1.2 m / 22 deg, beyond the merge's 0.3 m / 5 deg rule for missing beams.
    """
    r, phi, middle = wall_behind_object('opening')
    valid = ~middle
    r = np.where(valid, r, np.inf)
    clusters = segment_scan(r, phi, valid, math.radians(0.5))
    wall = sorted((ln for ln in extract_lines(clusters, LineParams(method=method))
                   if abs(ln.rho - 3.0) < 0.05), key=lambda ln: ln.first_index)
    assert len(wall) == 2
    assert wall[0].rho != wall[1].rho
    assert wall[0].num_points + wall[1].num_points <= np.count_nonzero(valid)


@pytest.mark.parametrize('method', METHODS)
def test_slam_features_fit_each_side_of_an_occluder_on_its_own(method):
    """EKF-SLAM gets the two sides of the wall behind the object as independent fits.

    The joint fit shared by two segments would be one measurement counted twice by the
    filter (each segment matched to its own panel landmark); ``join_occluded=False`` fits
    each side on its own beams, as before the join, and leaves the other lines alike.
    """
    r, phi, middle = wall_behind_object('wall')
    valid = np.ones(phi.size, bool)
    _, slam_lines = extract_scan_features(r, phi, valid, math.radians(0.5), 'lines',
                                          line_params=LineParams(method=method))
    clusters = segment_scan(r, phi, valid, math.radians(0.5), min_points=1)
    alone = extract_lines(clusters, LineParams(method=method, join_occluded=False))
    joined = extract_lines(clusters, LineParams(method=method))
    assert [(ln.rho, ln.alpha, ln.first_index) for ln in slam_lines] == [
        (ln.rho, ln.alpha, ln.first_index) for ln in alone]
    wall = sorted((ln for ln in slam_lines if abs(ln.rho - 3.0) < 0.05),
                  key=lambda ln: ln.first_index)
    assert len(wall) == 2 and wall[0].rho != wall[1].rho
    assert sum(ln.num_points for ln in wall) == sorted(
        (ln for ln in joined if abs(ln.rho - 3.0) < 0.05),
        key=lambda ln: ln.first_index)[0].num_points
    with pytest.raises(ValueError, match='join_occluded'):
        LineParams(join_occluded=1)


@pytest.mark.parametrize('method', METHODS)
def test_wall_with_an_opening_is_not_joined(method):
    """The same wall with a doorway instead of the object: the halves stay two lines.

    The beams between them saw further (no false surface), so no join bridges them.
    """
    r, phi, middle = wall_behind_object('opening')
    clusters = segment_scan(r, phi, np.ones(phi.size, bool), math.radians(0.5))
    lines = extract_lines(clusters, LineParams(method=method))
    wall = sorted((ln for ln in lines if abs(ln.rho - 3.0) < 0.05),
                  key=lambda ln: ln.first_index)
    assert len(wall) == 2
    assert wall[0].rho != wall[1].rho
    first_mid, last_mid = np.flatnonzero(middle)[[0, -1]]
    assert wall[0].last_index < first_mid and wall[1].first_index > last_mid


def test_split_pieces_eq4():
    pts = np.array([[0, 0], [1, 0.01], [2, 0], [2.01, 1], [2, 2]], float)
    assert split_pieces(pts, [0, 5], 0.05).tolist() == [[0, 2], [2, 4]]
    assert split_pieces(pts, [0, 5], 5.0).tolist() == [[0, 4]]
    assert split_pieces(pts, [0, 2, 5], 0.05).tolist() == [[0, 1], [2, 4]]


def test_split_paths_agree_and_leave_out_short_pieces_as_a_filter_would(monkeypatch):
    # _split runs array levels, then _split_py on the runs themselves (none ran) or on the
    # gathered points of the pieces left: all paths give the same pieces. _extract asks
    # for those of 3 or more points (min_span 2): the same as filtering all of them.
    from landmark_nav.laser.line_extraction import split as split_mod
    rng = np.random.default_rng(3)
    for _ in range(20):
        xy = np.cumsum(rng.normal(size=(120, 2)) * 0.05, axis=0)
        offs = np.array([0, 1, 3, 40, 41, 90, 120])
        x, y = np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1])
        tol = np.full(120, 0.03)
        s, e = offs[:-1], offs[1:] - 1
        runs = []
        for py in (10 ** 9, 60, -1):  # Python only; array levels, then Python; arrays only
            monkeypatch.setattr(split_mod, '_SPLIT_PY', py)
            every = split_mod._split(x, y, s, e, tol)
            short = every[1] - every[0] < 2
            assert short.any()
            assert split_mod._split(x, y, s, e, tol, 2).tolist() == every[:, ~short].tolist()
            runs.append(every.tolist())
        assert runs[0] == runs[1] == runs[2]


def test_segment_builds_the_dataclass_fields():
    from landmark_nav.laser.line_extraction.segments import _segment, LineSegment
    a, b, c = np.array([1.0, 2.0]), np.array([3.0, 4.0]), np.eye(2)
    values = (1.5, -0.5, a, b, 12, 0.01, c, 3, 14)
    fast, slow = _segment(*values), LineSegment(*values)
    assert type(fast) is LineSegment and list(vars(fast)) == list(vars(slow))
    assert all(getattr(fast, k) is getattr(slow, k) for k in vars(slow))
    with pytest.raises(AttributeError):
        fast.rho = 2.0
    assert fast.length == slow.length


@pytest.mark.parametrize('kwargs,name', [({'method': 'hough'}, 'method'),
                                         ({'min_points': 2}, 'min_points'),
                                         ({'min_points': 8.0}, 'min_points'),
                                         ({'sigma_r': 0.0}, 'sigma_r'),
                                         ({'sigma_phi': -1.0}, 'sigma_phi'),
                                         ({'lowess_span': 4}, 'lowess_span'),
                                         ({'lowess_iterations': -1}, 'lowess_iterations'),
                                         ({'rmse_min': 0.05, 'rmse_max': 0.01}, 'rmse_min'),
                                         ({'rmse_max': float('nan')}, 'rmse_max'),
                                         ({'split_threshold': -1.0}, 'split_threshold'),
                                         ({'merge_chi2': 0.0}, 'merge_chi2'),
                                         ({'merge_gap': -0.1}, 'merge_gap'),
                                         ({'merge_gap_angle': -0.1}, 'merge_gap_angle'),
                                         ({'min_length': float('inf')}, 'min_length'),
                                         ({'max_gradient': 0.0}, 'max_gradient'),
                                         ({'trim_sigma': 0.0}, 'trim_sigma'),
                                         ({'range_step': -0.05}, 'range_step'),
                                         ({'range_step_share': 1.5}, 'range_step_share')])
def test_invalid_parameters_name_the_field(kwargs, name):
    with pytest.raises(ValueError, match=name):
        LineParams(**kwargs)


@pytest.mark.parametrize('method', METHODS)
def test_empty_and_tiny_input(method):
    params = LineParams(method=method)
    assert extract_lines([], params) == []
    r = np.full(5, 2.0)
    phi = np.radians(np.arange(5.0))
    assert extract_lines([cluster_of(r, phi)], params) == []


def test_explained_points():
    phi = np.radians(np.arange(-30, 30.01, 0.5))
    r = 2.0 / np.cos(phi)
    r[10] -= 0.2  # in front of the wall (a beam beyond it would cut the line there)
    valid = np.ones(phi.size, bool)
    valid[20] = False
    lines = extract_lines([cluster_of(r, phi)], LineParams())
    ex = explained_points(lines, r, phi, valid)
    assert not ex[10] and not ex[20]
    assert ex.sum() == phi.size - 2


# ------------------------------------------------------------------------- office run
def office_scores(sigma_r: float, step: int = 4):
    """Score both methods on the office run with the evaluation rules (Nguyen et al. 2007).

    A detection is a true positive for a visible wall when |d rho| <= 10 cm, |d alpha| <=
    3 deg and their extents overlap, in the true laser pose at the time of the line's
    middle beam; TruePos = matched visible walls with >= 1 m in view / such walls. The
    scoring path of ``landmark_nav evaluate-features``
    (:func:`landmark_nav.evaluation.features.score_scan`).
    """
    res = run_scenario('office', seed=1, laser={'sigma_range': sigma_r})
    mount = res.laser.mount

    def sensor_pose_at(stamps):
        return compose(res.truth_at(np.minimum(stamps, res.end_ns)), mount)

    run = FeatureRun(corner_params={},
                     line_params={m: LineParams(method=m, sigma_r=sigma_r) for m in METHODS},
                     segment_sigma_r=sigma_r, truth_sigma_r=sigma_r, truth_sigma_phi=SIGMA_PHI)
    for scan in res.of_type(ScanSample)[::step]:
        score_scan(run, res.world, sensor_pose_at, scan)
    return run.lines


def test_office_run_line_targets():
    for method, sc in office_scores(0.01).items():
        print(f'{method}: TruePos {sc.true_pos:.3f} FalsePos {sc.false_pos_rate:.3f} '
              f'sigma drho {100 * sc.sigma_rho:.2f} cm (floor {100 * sc.floor_sigma_rho:.2f}) '
              f'sigma dalpha {math.degrees(sc.sigma_alpha):.3f} deg '
              f'(floor {math.degrees(sc.floor_sigma_alpha):.3f})')
        assert sc.relevant > 1000
        assert sc.true_pos >= 0.95
        assert sc.false_pos_rate <= 0.05
        assert math.degrees(sc.sigma_alpha) <= 0.5
        # sigma d rho is dominated by short lines on far walls seen at grazing incidence,
        # whose rho error is their angle error times a lever arm of metres. The floor, what
        # an efficient extractor would get on the same walls (Cramer-Rao bound from all
        # their beams), is itself 0.99 cm here (0.97-1.01 cm on seeds 1-6), so the 1 cm
        # target cannot be met reliably: ALFA is at 1.02 cm, split_merge at 0.95 cm on this
        # seed, reported in docs/laser_features.md. Asserted: both near-efficient, within a few %
        # of their ratios to the floor on this seed (split_merge 0.956, alfa 1.044; 1.002 and
        # 1.093 without the join across occluders; 0.956-1.147 on seeds 1-6).
        assert 0.0095 <= sc.floor_sigma_rho <= 0.0105
        bound = {'split_merge': 1.0, 'alfa': 1.07}[method]
        assert sc.sigma_rho <= bound * sc.floor_sigma_rho
        if method == 'split_merge':
            assert sc.sigma_rho <= 0.010


# ------------------------------------------------------------------------- real logs
CARMEN_SIGMA_R = 0.02  # the SICK scanners of both logs: line RMSE 1-2 cm; one setting for both


def carmen_figures(path: Path, method: str):
    """Per scan: explained fraction of the valid points and RMSE of the supporting points."""
    from landmark_nav.importers.carmen import read_carmen_scans
    params = LineParams(method=method, sigma_r=CARMEN_SIGMA_R)
    explained, rmse = [], []
    for scan in read_carmen_scans(path):
        valid = np.isfinite(scan.ranges) & (scan.ranges > 0)
        clusters = segment_scan(scan.ranges, scan.angles, valid, scan.angle_increment,
                                sigma_r=CARMEN_SIGMA_R, min_points=1)
        lines = extract_lines(clusters, params)
        for ln in lines:
            assert np.isfinite([ln.rho, ln.alpha, ln.rmse]).all()
            assert np.all(np.linalg.eigvalsh(ln.covariance) > 0)
        ex = explained_points(lines, scan.ranges, scan.angles, valid, params.sigma_r,
                              params.sigma_phi)
        explained.append(ex.sum() / max(valid.sum(), 1))
        n = sum(ln.num_points for ln in lines)
        rmse.append(math.sqrt(sum(ln.num_points * ln.rmse ** 2 for ln in lines) / n) if n
                    else 0.0)
    return np.array(explained), np.array(rmse)


@pytest.mark.parametrize('name', ['aces-corrected.log.gz', 'seattle-corrected.log.gz'])
def test_carmen_logs(name):
    path = shared_data('carmen', name)
    for method in METHODS:
        explained, rmse = carmen_figures(path, method)
        print(f'{name} {method}: explained mean {explained.mean():.3f} '
              f'min {explained.min():.3f}, scans >= 0.85: {(explained >= 0.85).mean():.2f}; '
              f'RMSE mean {100 * rmse.mean():.2f} cm max {100 * rmse.max():.2f} cm')
        # The issue asks for >= 85 % explained and RMSE <= 3 cm on EVERY scan. Not reached
        # (README.md at commit 67eb6cc); every scan runs and gives finite lines with
        # positive-definite covariances (asserted above), and that README's figures are guarded:
        # explained mean / worst scan, RMSE mean / max [m], scans. A fixed log gives the same
        # figures on every run, so the margin only covers floating-point differences.
        want = {
            ('aces-corrected.log.gz', 'split_merge'): (0.6564549041505786, 0.05027932960893855,
                                                       0.018129567332187818,
                                                       0.0266024917038544, 440),
            ('aces-corrected.log.gz', 'alfa'): (0.6565693102482232, 0.05027932960893855,
                                                0.01791894465557827, 0.025944137711420873,
                                                440),
            ('seattle-corrected.log.gz', 'split_merge'): (0.843348509666264,
                                                          0.6094182825484764,
                                                          0.009378008809379943,
                                                          0.02487958366427969, 241),
            ('seattle-corrected.log.gz', 'alfa'): (0.8418632726578638, 0.6061452513966481,
                                                   0.00809124356949539, 0.01562691175120255,
                                                   241),
        }[name, method]
        got = (explained.mean(), explained.min(), rmse.mean(), rmse.max(), explained.size)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=0)


PY_PATHS = ('_SMALL', '_SMALL_NO_COV', '_SPLIT_PY', '_SPLIT_PIECE_PY', '_CLEAN_PY', '_PAIRS_PY',
            '_GROW_PY', '_NOISE_PY', '_BUILD_PY', '_JOIN_PAIRS_PY', '_SEEN_PY', '_CUT_PY')


def _py_path_switches():
    """Return (module, name) of every PY_PATHS switch in the modules of the line steps.

    A switch used by a module other than its own (imported by name) is set there too.
    """
    import importlib
    import pkgutil

    from landmark_nav.laser import line_extraction
    mods = [importlib.import_module(f'{line_extraction.__name__}.{m.name}')
            for m in pkgutil.iter_modules(line_extraction.__path__)]
    out = [(mod, name) for name in PY_PATHS for mod in mods if hasattr(mod, name)]
    assert {name for _, name in out} == set(PY_PATHS)
    return out


def _line_tuples(lines):
    return [(ln.rho, ln.alpha, *ln.start, *ln.end, ln.num_points, ln.rmse,
             *ln.covariance.ravel(), ln.first_index, ln.last_index) for ln in lines]


@pytest.mark.parametrize('method', METHODS)
def test_python_float_paths_give_the_array_paths_lines(monkeypatch, method):
    # The line steps run small batches on Python floats and large ones as arrays, the same
    # operations in the same order; the size switches are speed choices only. Every step
    # forced onto one path, then onto the other, must give the same lines bit for bit
    # (office bag: 361 beams, clutter, occlusions).
    from landmark_nav.bag import BagReader
    from landmark_nav.conversions import scan_to_data
    params = LineParams(method=method)
    inputs = []
    with BagReader(Path(__file__).resolve().parents[1] / 'bags' / 'office') as reader:
        for k, (_, _, msg) in enumerate(reader.decoded(['/scan'])):
            if k % 40 == 0:
                scan = scan_to_data(msg)
                r = np.asarray(scan.ranges, dtype=float)
                angles = scan.angle_min + scan.angle_increment * np.arange(r.size)
                valid = np.isfinite(r) & (r >= scan.range_min) & (r <= scan.range_max)
                inputs.append(segment_scan(r, angles, valid, scan.angle_increment))
    runs = []
    for size in (10 ** 9, -1):            # every batch on Python floats; every batch as arrays
        for mod, name in _py_path_switches():
            monkeypatch.setattr(mod, name, size)
        runs.append([_line_tuples(extract_lines(c, params)) for c in inputs])
    assert sum(map(len, runs[0])) >= 3 * len(inputs)
    assert runs[0] == runs[1]


@pytest.mark.parametrize('method', METHODS)
def test_the_join_across_occluders_drops_no_extent_on_a_real_log(method):
    """belgioioso, every scan, sigma_r 2 cm: the join keeps every extent of the lines alone.

    A joint fit can move an extent's end points (their projections onto the line): one
    extent of 0.301 m came out 0.299 m and was dropped under ``min_length`` before the join
    tested it. The join may keep a piece that is too short or rough on its own (a superset).
    """
    from landmark_nav.importers.carmen import read_carmen_scans
    path = shared_data('carmen', 'belgioioso-corrected.log.gz')
    joined = LineParams(method=method, sigma_r=CARMEN_SIGMA_R)
    alone = LineParams(method=method, sigma_r=CARMEN_SIGMA_R, join_occluded=False)
    shared = scans = 0
    for scan in read_carmen_scans(path):
        valid = np.isfinite(scan.ranges) & (scan.ranges > 0)
        clusters = segment_scan(scan.ranges, scan.angles, valid, scan.angle_increment,
                                sigma_r=CARMEN_SIGMA_R, min_points=1)
        with_join = extract_lines(clusters, joined)
        extents = {(ln.first_index, ln.last_index) for ln in with_join}
        assert extents >= {(ln.first_index, ln.last_index)
                           for ln in extract_lines(clusters, alone)}, scans
        shared += len(with_join) - len({(ln.rho, ln.alpha) for ln in with_join})
        scans += 1
    assert scans > 300 and shared > 0  # the join did happen on this log


def test_rounded_ranges_gate_a_wall_off_a_surface_proud_of_it():
    # A wall 2 m ahead (beams -20..20 deg) and beyond it a surface 6 cm proud (20..26 deg),
    # 1 cm noise rounded to 5 cm, 40 scans. sigma_r = sqrt(1 + 5^2 / 12) = 1.75 cm either
    # way; with the rounding known the gates hold the rounded error's tails (99.73 % within
    # 4.6 cm, not 5.2 cm), and the wall's line runs onto the proud surface in 5 scans, not
    # 14; its mean |alpha| error is 0.33 deg, not 0.62 deg (measured, 0.13 CPU-s).
    phi = np.radians(np.arange(-20.0, 26.01, 0.5))
    x = np.where(phi > np.radians(20.01), 1.94, 2.0)
    sigma_r = math.sqrt(0.01 ** 2 + 0.05 ** 2 / 12.0)
    onto, err, whole = {0.0: 0, 0.05: 0}, {0.0: [], 0.05: []}, {0.0: 0, 0.05: 0}
    for seed in range(40):
        rng = np.random.default_rng(seed)
        r = np.round((x / np.cos(phi) + rng.normal(0.0, 0.01, phi.size)) / 0.05) * 0.05
        for step in onto:
            lines = extract_lines([cluster_of(r, phi)], LineParams(sigma_r=sigma_r,
                                                                   range_step=step))
            wall = [ln for ln in lines if ln.first_index == 0]
            assert len(wall) == 1
            onto[step] += wall[0].last_index > 81
            whole[step] += wall[0].last_index >= 78
            err[step].append(abs(math.degrees(wall[0].alpha)))
    assert onto[0.05] <= 6 and onto[0.0] >= 12
    assert np.mean(err[0.05]) < 0.4 and np.mean(err[0.0]) > 0.55
    # and the wall itself keeps its end beams (up to beam 78 of 80) as often: 25 vs 26 scans
    assert whole[0.05] >= whole[0.0] - 1 >= 24


def test_gate_sigma_of_unrounded_ranges_is_sigma_r():
    p = LineParams(sigma_r=0.02)
    assert p.gate_sigma_r == 0.02 and p.threshold == 0.08 and p.see_through_tolerance == 0.06
    q = LineParams(sigma_r=0.02, range_step=0.05)
    # the split tolerance: the rounded error's 4-sigma-tail bound, below 4 of its 3-sigma
    # gate std (the bounded rounding's tail shortens faster than a Gaussian's)
    assert q.gate_sigma_r < 0.02 and q.threshold == 4.0 * gate_sigma(0.02, 0.05, k=4.0)
    assert q.threshold < 4.0 * q.gate_sigma_r
