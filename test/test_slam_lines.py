"""Line landmarks in EKF-SLAM: model and Jacobians, extents, mixed association."""

import math

from landmark_nav.geometry import compose, inverse_transform_points, relative
from landmark_nav.laser.lines import LineSegment
from landmark_nav.slam import EkfSlam, SlamParams
from landmark_nav.slam.ekf_slam import CORNER, LINE, observation_model
from landmark_nav.slam.line_landmarks import (extents_overlap, line_initialization,
                                              line_observation_model, LineObservations,
                                              lines_to_observations, transform_lines)
import numpy as np
import pytest

SIG_RHO, SIG_ALPHA = 0.01, math.radians(0.5)
R_LINE = np.diag([SIG_RHO ** 2, SIG_ALPHA ** 2])
R_PT = np.diag([0.01 ** 2, math.radians(0.3) ** 2])
# A corridor: walls y = 1.5 and y = -1.5 (x 0..12) and an end wall x = 12.
WALLS = np.array([[[0.0, 1.5], [12.0, 1.5]], [[0.0, -1.5], [12.0, -1.5]],
                  [[12.0, -1.5], [12.0, 1.5]]])


def numeric_jacobian(f, x, eps=1e-7):
    """Central differences of f at x, angles in the output wrapped."""
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = eps
        diff = np.asarray(f(x + d)) - np.asarray(f(x - d))
        diff[..., 1] = np.angle(np.exp(1j * diff[..., 1]))
        cols.append(diff / (2 * eps))
    return np.stack(cols, axis=-1)


def wall_lines():
    """(rho, alpha) of the walls (map frame) with rho >= 0 seen from the corridor inside."""
    return np.array([[1.5, math.pi / 2], [1.5, -math.pi / 2], [12.0, 0.0]])


def observe_walls(pose, rng=None, walls=WALLS, max_len=8.0):
    """Line observations (base_link) of the wall segments within max_len of the robot."""
    z, ends = [], []
    for seg in walls:
        p = inverse_transform_points(pose, seg)
        d = p[1] - p[0]
        n = np.array([d[1], -d[0]]) / np.hypot(*d)
        rho = float(n @ p[0])
        if rho < 0:
            n, rho = -n, -rho
        alpha = math.atan2(n[1], n[0])
        # Visible part: the piece of the segment within max_len of the robot.
        t = np.linspace(0.0, 1.0, 400)
        pts = p[0] + t[:, None] * d
        vis = pts[np.hypot(pts[:, 0], pts[:, 1]) < max_len]
        if len(vis) < 2:
            continue
        if rng is not None:
            rho += rng.normal(0.0, SIG_RHO)
            alpha += rng.normal(0.0, SIG_ALPHA)
        z.append([rho, alpha])
        ends.append([vis[0], vis[-1]])
    z = np.array(z).reshape(-1, 2)
    return LineObservations(z, np.repeat(R_LINE[None], len(z), 0),
                            np.array(ends).reshape(-1, 2, 2))


def test_line_model_jacobians_match_finite_differences():
    pose = np.array([1.3, -0.4, 0.7])
    lines = np.array([[2.5, 0.3], [4.0, -2.2], [1.1, 2.9]])
    zhat, hr, hf = line_observation_model(pose, lines)
    num_r = numeric_jacobian(lambda x: line_observation_model(x, lines)[0], pose)
    assert hr == pytest.approx(num_r, abs=1e-6)
    for k in range(3):
        num_f = numeric_jacobian(lambda lm: line_observation_model(pose, lm[None])[0][0],
                                 lines[k])
        assert hf[k] == pytest.approx(num_f, abs=1e-6)


def test_line_initialization_inverts_the_model_and_its_jacobians_are_exact():
    pose = np.array([-0.8, 2.1, -1.2])
    z = np.array([[1.7, 0.4], [3.2, -2.0]])
    g, gr, gz = line_initialization(pose, z)
    zback = line_observation_model(pose, g)[0]
    assert zback == pytest.approx(z, abs=1e-12)
    num_r = numeric_jacobian(lambda x: line_initialization(x, z)[0], pose)
    assert gr == pytest.approx(num_r, abs=1e-6)
    for k in range(2):
        num_z = numeric_jacobian(lambda zz: line_initialization(pose, zz[None])[0][0], z[k])
        assert gz[k] == pytest.approx(num_z, abs=1e-6)


def test_transform_lines_covariance_and_flip():
    pose = np.array([0.3, -0.1, 0.4])
    rho, alpha = np.array([2.0, 0.1]), np.array([0.5, 2.0])
    cov = np.array([np.diag([1e-4, 1e-4]), [[2e-4, 1e-5], [1e-5, 3e-4]]])
    r2, a2, c2 = transform_lines(pose, rho, alpha, cov)
    for k in range(2):
        jac = numeric_jacobian(
            lambda v: np.array([*transform_lines(pose, v[:1], v[1:])[:2]]).ravel(),
            np.array([rho[k], alpha[k]]))
        assert c2[k] == pytest.approx(jac @ cov[k] @ jac.T, rel=1e-6, abs=1e-14)
    # The second line passes behind the new origin: rho flips sign, alpha turns by pi.
    assert np.all(r2 >= 0.0)
    x = rho[1] * np.array([math.cos(alpha[1]), math.sin(alpha[1])])  # a point on the line
    p = compose(pose, np.array([*x, 0.0]))[:2]
    assert p @ np.array([math.cos(a2[1]), math.sin(a2[1])]) == pytest.approx(r2[1], abs=1e-12)


def test_lines_to_observations_applies_the_mount():
    """A laser-frame segment goes through the mount to the same line in base_link."""
    mount = np.array([0.25, 0.05, 0.1])
    seg = LineSegment(rho=2.0, alpha=0.3, start=np.array([2.0 * math.cos(0.3) + 0.5 * math.sin(
        0.3), 2.0 * math.sin(0.3) - 0.5 * math.cos(0.3)]), end=np.array([
            2.0 * math.cos(0.3) - 0.5 * math.sin(0.3), 2.0 * math.sin(0.3) + 0.5 * math.cos(
                0.3)]), num_points=20, rmse=0.01, covariance=np.diag([1e-4, 4e-5]),
        first_index=10, last_index=29)
    obs = lines_to_observations([seg], mount)
    rho_b, alpha_b = obs.z[0]
    for e in obs.ends[0]:  # the endpoints moved with the mount lie on the moved line
        normal = np.array([math.cos(alpha_b), math.sin(alpha_b)])
        assert e @ normal == pytest.approx(rho_b, abs=1e-12)
    assert obs.beams.tolist() == [19.5]
    assert np.linalg.eigvalsh(obs.r[0]).min() > 0


def test_extents_overlap():
    lines = np.array([[1.5, math.pi / 2]])  # y = 1.5; direction along -x
    lm = np.array([[[0.0, 1.5], [3.0, 1.5]]])
    obs = np.array([[[2.5, 1.5], [5.0, 1.5]], [[3.5, 1.5], [6.0, 1.5]], [[-1.0, 1.5], [0.0, 1.5]]])
    assert extents_overlap(lines, lm, obs)[:, 0].tolist() == [True, False, True]
    # A margin widens the landmark's interval at both ends.
    got = extents_overlap(lines, lm, obs, margin=np.array([0.6]))[:, 0]
    assert got.tolist() == [True, True, True]
    far = np.array([[[4.0, 1.5], [6.0, 1.5]], [[-3.0, 1.5], [-1.5, 1.5]]])
    got = extents_overlap(lines, lm, far, margin=np.array([0.6]))[:, 0]
    assert got.tolist() == [False, False]


def extent_filter(sigmas, sigma_x):
    """Map the wall y = 1.5 over x 0..2, then make the robot's x uncertain (std sigma_x)."""
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1, line_extent_sigmas=sigmas))
    obs = LineObservations(np.array([[1.5, math.pi / 2]]), R_LINE[None],
                           np.array([[[0.0, 1.5], [2.0, 1.5]]]))
    assert slam.update(np.zeros((0, 2)), None, None, obs).status.tolist() == ['confirmed']
    slam.predict(np.zeros(3), np.diag([sigma_x ** 2, 1e-8, 1e-8]))
    return slam


@pytest.mark.parametrize('sigmas, sigma_x, status', [
    (None, 1.0, 'confirmed'),   # off: the piece at x 3..5 does not overlap, a new landmark
    (1.96, 1.0, 'matched'),     # margin 1.96 m: it does
    (1.96, 0.4, 'confirmed'),   # margin 0.78 m: still 1 m short
    (0.0, 1.0, 'confirmed'),    # k = 0: the plain test
])
def test_line_extent_sigmas_widens_the_overlap_by_the_position_std(sigmas, sigma_x, status):
    """The observed piece is 1 m past the mapped extent along the wall."""
    slam = extent_filter(sigmas, sigma_x)
    obs = LineObservations(np.array([[1.5, math.pi / 2]]), R_LINE[None],
                           np.array([[[3.0, 1.5], [5.0, 1.5]]]))
    res = slam.update(np.zeros((0, 2)), None, None, obs)
    assert res.status.tolist() == [status]
    assert slam.num_landmarks == (1 if status == 'matched' else 2)


def test_line_extent_sigmas_margin_is_along_the_line_only():
    """A position std across the wall (y) does not widen the extent test."""
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1, line_extent_sigmas=1.96))
    obs = LineObservations(np.array([[1.5, math.pi / 2]]), R_LINE[None],
                           np.array([[[0.0, 1.5], [2.0, 1.5]]]))
    slam.update(np.zeros((0, 2)), None, None, obs)
    slam.predict(np.zeros(3), np.diag([1e-8, 1.0, 1e-8]))
    piece = LineObservations(obs.z, obs.r, np.array([[[3.0, 1.5], [5.0, 1.5]]]))
    assert slam.update(np.zeros((0, 2)), None, None, piece).status.tolist() == ['confirmed']


@pytest.mark.parametrize('bad', [-1.0, math.nan, math.inf, 'x', True])
def test_line_extent_sigmas_validation(bad):
    with pytest.raises(ValueError, match='line_extent_sigmas'):
        SlamParams(line_extent_sigmas=bad)


def test_corridor_lines_only_maps_three_walls_and_stays_consistent():
    """Driving a corridor with line observations only: three landmarks, consistent pose."""
    rng = np.random.default_rng(3)
    slam = EkfSlam(SlamParams())
    truth = np.zeros(3)
    nees = []
    for k in range(60):
        if k:
            u_true = np.array([0.1, 0.0, 0.01 * math.sin(k / 5)])
            truth = compose(truth, u_true)
            u = u_true + rng.normal(0.0, [0.003, 0.003, 0.003])
            slam.predict(u, np.diag([0.003 ** 2] * 3))
        res = slam.update(np.zeros((0, 2)), None, None, observe_walls(truth, rng))
        assert set(res.reason) <= {'', 'ambiguous'}  # a 3-sigma draw is gated out, not mapped
        err = slam.pose - truth
        err[2] = math.remainder(err[2], 2 * math.pi)
        if k >= 5:
            nees.append(err @ np.linalg.solve(slam.pose_covariance, err))
    assert slam.num_landmarks == 3
    assert np.all(slam.landmark_kinds == LINE)
    order = np.argsort(slam.landmarks[:, 1])
    err = slam.landmarks[order] - wall_lines()[[1, 2, 0]]
    cov = slam.landmark_covariances[order]
    # Each wall within the 99.9 % ellipse of its own marginal covariance (the end wall's
    # rho inherits the robot's along-corridor drift, a few cm), and within 5 cm / 1 deg.
    for e, c in zip(err, cov):
        assert e @ np.linalg.solve(c, e) < 13.8
    assert np.abs(err[:, 0]).max() < 0.05 and np.abs(err[:, 1]).max() < math.radians(1.0)
    # Extents grew with the robot: the side walls are mapped up to about x = 11.9 (6 m ahead
    # of the last pose at 5.9 m).
    ends = slam.line_ends
    side = np.flatnonzero(np.abs(np.abs(slam.landmarks[:, 1]) - math.pi / 2) < 0.1)
    assert ends[side][..., 0].max() > 11.0
    # 3 dof NEES: mean near 3 (55 steps; 99 % band of the mean of 55 chi2_3 is 2.1-4.0).
    assert 1.5 < np.mean(nees) < 4.5


def test_line_seen_from_behind_is_not_associated():
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1))
    wall = np.array([[[2.0, -1.0], [2.0, 1.0]]])
    slam.update(np.zeros((0, 2)), None, None, observe_walls(np.zeros(3), walls=wall))
    assert slam.num_landmarks == 1
    # Step through the (thin) wall and look back: its other face is a new landmark.
    back = np.array([2.05, 0.0, math.pi])
    slam.predict(relative(np.zeros(3), back), np.diag([1e-8] * 3))
    res = slam.update(np.zeros((0, 2)), None, None, observe_walls(back, walls=wall))
    assert res.status.tolist() == ['confirmed']
    assert slam.num_landmarks == 2


def test_collinear_segments_without_overlap_are_separate_landmarks():
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1))
    obs = LineObservations(np.array([[1.5, math.pi / 2], [1.5, math.pi / 2]]),
                           np.repeat(R_LINE[None], 2, 0),
                           np.array([[[0.0, 1.5], [2.0, 1.5]], [[4.0, 1.5], [6.0, 1.5]]]))
    res = slam.update(np.zeros((0, 2)), None, None, obs)
    assert res.status.tolist() == ['confirmed', 'confirmed']
    # The next scan sees a piece overlapping only the second: it updates the second.
    again = LineObservations(obs.z[1:], obs.r[1:], np.array([[[5.0, 1.5], [7.0, 1.5]]]))
    res = slam.update(np.zeros((0, 2)), None, None, again)
    assert res.status.tolist() == ['matched'] and res.landmark_id.tolist() == [1]
    assert slam.line_ends[1][:, 0].max() == pytest.approx(7.0, abs=1e-6)


@pytest.mark.parametrize('association', ['icnn', 'jcbb'])
def test_mixed_corners_and_lines(association):
    """Corners and lines in one state: kinds never cross, both kinds update the robot."""
    rng = np.random.default_rng(5)
    corners = np.array([[12.0, 1.5], [12.0, -1.5], [6.0, 1.5]])
    slam = EkfSlam(SlamParams(association=association))
    truth = np.zeros(3)
    for k in range(60):
        if k:
            truth = compose(truth, np.array([0.1, 0.0, 0.0]))
            slam.predict(np.array([0.1, 0.0, 0.0]) + rng.normal(0, 0.003, 3),
                         np.diag([0.003 ** 2] * 3))
        p = inverse_transform_points(truth, corners)
        z = np.column_stack([np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])])
        z += rng.normal(0.0, [0.01, math.radians(0.3)], z.shape)
        res = slam.update(z, np.repeat(R_PT[None], 3, 0), None, observe_walls(truth, rng))
        kinds = slam.landmark_kinds
        by_id = dict(zip(slam.landmark_ids.tolist(), kinds.tolist()))
        for lid, kind in zip(res.landmark_id, res.kind):
            if lid >= 0:
                assert by_id[int(lid)] == kind
    assert sorted(slam.landmark_kinds.tolist()) == [CORNER] * 3 + [LINE] * 3
    ck = slam.landmark_kinds == CORNER
    got = slam.landmarks[ck][np.lexsort(slam.landmarks[ck].T[::-1])]  # by x, then y
    assert got == pytest.approx(corners[np.lexsort(corners.T[::-1])], abs=0.05)
    assert np.hypot(*(slam.pose[:2] - truth[:2])) < 0.05
    # observation_model dispatches per kind
    zhat, _, _ = observation_model(slam.state, np.arange(slam.num_landmarks), slam.landmark_kinds)
    assert np.all(zhat[~ck, 0] > 0)  # the robot is in front of every wall


def test_line_covariance_takes_the_residual_variance_when_it_is_larger():
    """A fit scattering 3x the stated noise gets 9 n / (n - 2) times its covariance."""
    def seg(rmse):
        return LineSegment(rho=2.0, alpha=0.0, start=np.array([2.0, -0.5]),
                           end=np.array([2.0, 0.5]), num_points=20, rmse=rmse,
                           covariance=np.diag([1e-4, 4e-5]), first_index=0, last_index=19)
    base = lines_to_observations([seg(0.005)], sigma_r=0.01).r[0]
    assert base == pytest.approx(np.diag([1e-4, 4e-5]), rel=1e-12)  # below the noise: as is
    noisy = lines_to_observations([seg(0.03)], sigma_r=0.01).r[0]
    assert noisy == pytest.approx(base * 9.0 * 20 / 18, rel=1e-12)
    assert lines_to_observations([seg(0.03)]).r[0] == pytest.approx(base, rel=1e-12)
