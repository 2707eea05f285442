"""Tests of the point-to-line ICP and of the scan-matched motion of the SLAM front end."""

import math

from landmark_nav.evaluation.slam import run_slam
from landmark_nav.geometry import compose, inverse, relative
from landmark_nav.slam.ekf_slam import odometry_noise, SlamParams
from landmark_nav.slam.frontend import (Corners, FrontendParams, odometry_noise_model,
                                        SlamFrontend)
from landmark_nav.slam.scan_matching import (base_motion, fit_information,
                                             fused_scan_motion, IcpResult, larger_motion,
                                             point_to_line_icp, scan_motion, scan_points)
from landmark_nav.slam.visibility import ScanGeometry
import numpy as np
import pytest


def _room(rng, n=400, noise=0.0):
    # Points on the four walls of a 6 m x 4 m room and a pillar, as a laser at the origin sees.
    walls = [((-3.0, -2.0), (3.0, -2.0)), ((3.0, -2.0), (3.0, 2.0)),
             ((3.0, 2.0), (-3.0, 2.0)), ((-3.0, 2.0), (-3.0, -2.0)),
             ((1.0, 0.5), (1.5, 0.5)), ((1.5, 0.5), (1.5, 1.0))]
    pts = []
    for a, b in walls:
        t = rng.uniform(0.0, 1.0, n // len(walls))[:, None]
        pts.append(np.asarray(a) + t * (np.asarray(b) - np.asarray(a)))
    pts = np.vstack(pts)
    return pts + noise * rng.standard_normal(pts.shape)


def _move(pose, pts):
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return pts @ np.array([[c, s], [-s, c]]) + pose[:2]


def test_icp_recovers_a_known_motion_from_the_odometry_guess():
    rng = np.random.default_rng(3)
    target = _room(rng, noise=0.005)
    truth = np.array([0.12, -0.07, math.radians(4.0)])
    # The source is the room seen from the moved pose: target = R source + t.
    c, s = math.cos(truth[2]), math.sin(truth[2])
    source = (_room(rng, noise=0.005) - truth[:2]) @ np.array([[c, -s], [s, c]])
    guess = truth + np.array([0.08, 0.05, math.radians(-3.0)])   # a drifted odometry guess
    fit = point_to_line_icp(source, target, guess, gates=(0.5, 0.3, 0.15), iterations=20)
    assert fit is not None
    assert np.allclose(fit.pose[:2], truth[:2], atol=0.002)  # about 4 sigma of the fit (0.5 mm)
    assert abs(fit.pose[2] - truth[2]) < math.radians(0.1)  # about 3 sigma (0.03 deg)
    assert np.allclose(_move(fit.pose, source[:5]), _move(truth, source[:5]), atol=0.01)
    assert fit.matches > 300 and 0.0 < fit.rms < 0.01
    # The classic covariance is symmetric, positive definite and of the size of the noise.
    w = np.linalg.eigvalsh(fit.covariance)
    assert np.allclose(fit.covariance, fit.covariance.T) and w.min() > 0.0
    assert 1e-4 < math.sqrt(w.max()) < 0.002


def test_icp_without_enough_points_or_pairs_gives_none():
    rng = np.random.default_rng(4)
    room = _room(rng)
    assert point_to_line_icp(room[:10], room) is None                    # too few points
    far = room + np.array([5.0, 5.0])                                   # nothing within the gate
    assert point_to_line_icp(far, room, gates=(0.15,)) is None


def test_icp_without_a_gate_is_an_error():
    room = _room(np.random.default_rng(5))
    with pytest.raises(ValueError, match='gates'):
        point_to_line_icp(room, room, gates=())


# A 6 m x 4 m room with an L-shaped pillar (segments), seen by a 361-beam laser.
ROOM = [((-3.0, -2.0), (3.0, -2.0)), ((3.0, -2.0), (3.0, 2.0)), ((3.0, 2.0), (-3.0, 2.0)),
        ((-3.0, 2.0), (-3.0, -2.0)), ((1.0, 0.5), (1.5, 0.5)), ((1.5, 0.5), (1.5, 1.0))]
ANGLE_MIN, INC = -math.pi / 2, math.pi / 360
MOUNT = np.array([0.2, 0.05, 0.1])


def _cast(laser_pose, rng=None, sigma=0.005, room=ROOM):
    """Ranges of the room's first surface along each beam of a laser at ``laser_pose``."""
    a = laser_pose[2] + ANGLE_MIN + INC * np.arange(361)
    d = np.column_stack([np.cos(a), np.sin(a)])
    best = np.full(a.size, np.inf)
    for p0, p1 in room:
        p0, e = np.asarray(p0), np.asarray(p1) - np.asarray(p0)
        w = p0 - laser_pose[:2]
        den = d[:, 0] * e[1] - d[:, 1] * e[0]
        with np.errstate(divide='ignore', invalid='ignore'):
            t = (w[0] * e[1] - w[1] * e[0]) / den
            u = (w[0] * d[:, 1] - w[1] * d[:, 0]) / den
        hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
        best = np.where(hit & (t < best), t, best)
    if rng is not None:
        best = best + sigma * rng.standard_normal(best.size)
    return best


def _geometry(ranges):
    return ScanGeometry(ranges, ANGLE_MIN, INC, 0.05, 30.0, MOUNT, 0.005)


def test_scan_motion_is_the_base_motion_through_the_mount():
    rng = np.random.default_rng(6)
    base0, base1 = np.array([-1.0, -0.5, 0.2]), np.array([-0.6, -0.3, 0.35])
    truth = relative(base0, base1)
    prev = scan_points(_cast(compose(base0, MOUNT), rng), ANGLE_MIN, INC, 0.05, 20.0)
    cur = scan_points(_cast(compose(base1, MOUNT), rng), ANGLE_MIN, INC, 0.05, 20.0)
    u = truth + np.array([0.03, -0.02, math.radians(2.0)])   # drifted odometry
    u_cov = odometry_noise(u, odometry_noise_model('pioneer'))
    v = scan_motion(prev, cur, u, u_cov, MOUNT, gate=16.27)   # chi2(3, 0.999)
    assert v is not None
    assert np.allclose(v[:2], truth[:2], atol=0.003)   # 0.5 cm noise on ~300 returns
    assert abs(v[2] - truth[2]) < math.radians(0.1)
    # The same ICP motion lies outside a much tighter odometry region: not used; unless its
    # own covariance V (the difference of two estimates has U + V) covers the difference.
    assert scan_motion(prev, cur, u, u_cov * 1e-4, MOUNT, gate=16.27) is None
    v2 = scan_motion(prev, cur, u, u_cov * 1e-4, MOUNT, 16.27, lambda m: u_cov)
    assert v2 is not None and np.allclose(v2, v)
    # Too few returns (an empty scan): no motion.
    assert scan_motion(prev, cur[:5], u, u_cov, MOUNT, gate=16.27) is None


# A 20 m x 10 m hall with eight square pillars: at 5-10 m a heading error of 30 deg moves
# the returns metres, beyond ICP's basin.
def _square(cx, cy, h=0.3):
    c = [(cx - h, cy - h), (cx + h, cy - h), (cx + h, cy + h), (cx - h, cy + h)]
    return [(c[i], c[(i + 1) % 4]) for i in range(4)]


HALL = [((-10.0, -5.0), (10.0, -5.0)), ((10.0, -5.0), (10.0, 5.0)),
        ((10.0, 5.0), (-10.0, 5.0)), ((-10.0, 5.0), (-10.0, -5.0))] + [
    seg for cx in (-6.0, -2.0, 2.0, 6.0) for cy in (-2.0, 2.0) for seg in _square(cx, cy)]


def test_scan_motion_restarts_from_other_headings_when_the_odometry_guess_fails():
    rng = np.random.default_rng(0)
    base0 = np.array([-4.0, 0.0, 0.1])
    truth = np.array([0.8, 0.1, math.radians(60.0)])
    prev = scan_points(_cast(compose(base0, MOUNT), rng, room=HALL), ANGLE_MIN, INC, 0.05, 20.0)
    cur = scan_points(_cast(compose(compose(base0, truth), MOUNT), rng, room=HALL), ANGLE_MIN,
                      INC, 0.05, 20.0)
    u = truth + np.array([0.0, 0.0, math.radians(-30.0)])   # the odometry under-turned
    u_cov = odometry_noise(u, odometry_noise_model('k_d=0.05 k_theta=0.05 k_dtheta=0.25'))
    assert 2.5 < math.radians(30.0) / math.sqrt(u_cov[2, 2]) < 3.0   # inside the test region
    first = base_motion(prev, cur, u, MOUNT)   # from the odometry's guess: the wrong structure
    assert first is None or np.hypot(*(first[0][:2] - truth[:2])) > 0.3
    counts = {}
    v = scan_motion(prev, cur, u, u_cov, MOUNT, 16.27, None, counts)
    assert v is not None
    assert np.allclose(v[:2], truth[:2], atol=0.005) and abs(v[2] - truth[2]) < 1e-3
    assert counts == {'restarted': 1, 'recovered': 1}
    # A right guess needs no restart; a region that admits none of the solutions: None.
    counts = {}
    assert scan_motion(prev, cur, truth, u_cov, MOUNT, 16.27, None, counts) is not None
    assert counts == {}
    assert scan_motion(prev, cur, u, u_cov * 1e-2, MOUNT, 16.27, None, counts) is None
    assert counts == {'restarted': 1}


# A ring of 18 pillars every 20 deg around the robot in an off-centre room: turned 20 deg
# short, the pillars line up again (a wrong minimum with half the pairs).
RING = [seg for k in range(18) for seg in _square(3.0 * math.cos(math.radians(20 * k)),
                                                  3.0 * math.sin(math.radians(20 * k)), 0.15)]
RING_ROOM = RING + [((-7.0, -5.0), (9.0, -5.0)), ((9.0, -5.0), (9.0, 6.0)),
                    ((9.0, 6.0), (-7.0, 6.0)), ((-7.0, 6.0), (-7.0, -5.0))]


def test_side_starts_leave_a_wrong_minimum_near_an_odometry_guess_in_its_tail():
    rng = np.random.default_rng(0)
    truth = np.array([0.05, 0.0, math.radians(40.0)])
    prev = scan_points(_cast(MOUNT, rng, room=RING_ROOM), ANGLE_MIN, INC, 0.05, 20.0)
    cur = scan_points(_cast(compose(truth, MOUNT), rng, room=RING_ROOM), ANGLE_MIN, INC,
                      0.05, 20.0)
    u = truth + np.array([0.0, 0.0, math.radians(-14.0)])   # 2 sigma short
    u_cov = np.diag([0.05 ** 2, 0.05 ** 2, math.radians(7.0) ** 2])
    first = base_motion(prev, cur, u, MOUNT)
    assert abs(math.degrees(first[0][2]) - 20.6) < 0.5   # the pillars one step round
    # That wrong motion agrees with the odometry (5.4 deg from it): used without side starts.
    wrong = scan_motion(prev, cur, u, u_cov, MOUNT, 16.27)
    assert wrong is not None and abs(wrong[2] - truth[2]) > math.radians(19.0)
    # From +-2.5 sigma (17.5 deg) one start lands in the true basin, with twice the pairs.
    right = scan_motion(prev, cur, u, u_cov, MOUNT, 16.27, side_starts=2.5)
    assert right is not None and abs(right[2] - truth[2]) < math.radians(0.2)
    assert np.hypot(*(right[:2] - truth[:2])) < 0.01
    fused = fused_scan_motion(prev, cur, u, u_cov, MOUNT, 16.27, lambda m: u_cov, 0.3,
                              side_starts=2.5)
    assert fused is not None and abs(fused[0][2] - truth[2]) < math.radians(0.5)


def test_scan_motion_tests_both_noise_models_at_the_larger_motion():
    """The agreement region is that of the one true motion: U and V at the larger motion.

    The odometry's own error must not shrink its region (freiburg-101, drift seed 1, step
    137: the odometry turned -15.5 deg of a true -30.2 deg, U at that increment had half the
    turn-driven variance and the correct ICP motion was rejected; the filter kept a 15 deg
    heading error for the rest of the run).
    """
    assert np.allclose(larger_motion([0.3, 0.4, -0.2], [0.0, 0.1, 0.5]), [0.5, 0.0, 0.5])
    rng = np.random.default_rng(8)
    base0 = np.array([-1.0, -0.5, 0.2])
    truth = np.array([0.3, 0.0, math.radians(-40.0)])
    base1 = compose(base0, truth)
    prev = scan_points(_cast(compose(base0, MOUNT), rng), ANGLE_MIN, INC, 0.05, 20.0)
    cur = scan_points(_cast(compose(base1, MOUNT), rng), ANGLE_MIN, INC, 0.05, 20.0)
    u = truth + np.array([0.0, 0.0, math.radians(20.0)])   # the odometry turned only -20 deg
    pioneer = odometry_noise_model('pioneer')
    scans = odometry_noise_model('k_d=0.05 k_theta=0.03 k_dtheta=0.06')

    def model(m):
        return odometry_noise(m, pioneer)

    def v_model(m):
        return odometry_noise(m, scans)

    # U at the odometry's own increment: rejected (d^2 17.4 > 16.27).
    assert scan_motion(prev, cur, u, model(u), MOUNT, 16.27, v_model) is None
    # Both at the larger motion (the ICP's 40 deg turn): d^2 11.6, accepted; it is the truth.
    v = scan_motion(prev, cur, u, model, MOUNT, 16.27, v_model)
    assert v is not None and abs(v[2] - truth[2]) < math.radians(0.2)
    # A wrong ICP is still refused: the same odometry against a tight model.
    assert scan_motion(prev, cur, u, lambda m: 1e-2 * model(m), MOUNT, 16.27,
                       lambda m: 1e-2 * v_model(m)) is None


# A corridor 2 m wide and 60 m long along x: the walls fix the cross-track position and the
# heading; along the track only the noise of the walls' normals gives ICP any information.
CORRIDOR = [((-30.0, -1.0), (30.0, -1.0)), ((30.0, 1.0), (-30.0, 1.0))]


def test_fused_scan_motion_takes_along_a_corridor_the_odometry_and_across_it_the_scans():
    rng = np.random.default_rng(11)
    base0 = np.array([0.0, -0.2, 0.05])
    truth = np.array([0.6, 0.03, math.radians(3.0)])
    # Returns within 8 m (at 20 m, grazing returns with noisy normals let ICP slide 40 cm
    # along the corridor, which the agreement test rejects).
    prev = scan_points(_cast(compose(base0, MOUNT), rng, room=CORRIDOR), ANGLE_MIN, INC,
                       0.05, 8.0)
    cur = scan_points(_cast(compose(compose(base0, truth), MOUNT), rng, room=CORRIDOR),
                      ANGLE_MIN, INC, 0.05, 8.0)
    u = truth + np.array([0.08, -0.04, math.radians(-2.0)])   # drifted odometry
    noise = odometry_noise_model('pioneer')

    def model(m):
        return odometry_noise(m, noise)

    def along_across(motion):
        # The end position's error along and across the corridor (world x and y).
        return compose(base0, motion)[:2] - compose(base0, truth)[:2]

    fused = fused_scan_motion(prev, cur, u, model, MOUNT, 16.27, model, pairs=1.0)
    v = scan_motion(prev, cur, u, model, MOUNT, 16.27, model)
    assert fused is not None and v is not None
    m, w = fused
    e_m, e_u, e_v = along_across(m), along_across(u), along_across(v)
    # ICP alone slid along the track (its answer there is the noise's); across the track
    # and in heading it has the scans' answer (0.5 cm noise on ~300 returns).
    assert abs(e_v[0] - e_u[0]) > 0.02
    assert abs(e_v[1]) < 0.005 and abs(v[2] - truth[2]) < math.radians(0.2)
    # Fused: along the track mostly the odometry's (more than 3/4 of the way from the
    # ICP's to it), across it and in heading the scans'.
    assert abs(e_m[0] - e_u[0]) < 0.25 * abs(e_v[0] - e_u[0])
    assert abs(e_m[1]) < 0.005 and abs(e_u[1]) > 0.03
    assert abs(m[2] - truth[2]) < math.radians(0.2)
    # W: along the corridor (base frame: -base0's heading) most of the odometry's variance,
    # across it and in heading a small part.
    u_at = model(larger_motion(u, m))
    a = np.array([math.cos(-base0[2]), math.sin(-base0[2])])
    c = np.array([-a[1], a[0]])
    assert a @ w[:2, :2] @ a > 0.5 * (a @ u_at[:2, :2] @ a)
    assert c @ w[:2, :2] @ c < 0.05 * (c @ u_at[:2, :2] @ c)
    assert w[2, 2] < 0.05 * u_at[2, 2]
    assert np.allclose(w, w.T) and np.linalg.eigvalsh(w).min() > 0.0
    # A motion the odometry rules out: None, as for scan_motion.
    assert fused_scan_motion(prev, cur, u, lambda m: 1e-3 * model(m), MOUNT, 16.27,
                             lambda m: 1e-3 * model(m), pairs=1.0) is None
    with pytest.raises(ValueError, match='pairs'):
        fused_scan_motion(prev, cur, u, model, MOUNT, 16.27, model, pairs=0.0)


def test_fit_information_is_the_fit_covariance_moved_to_the_base():
    fit = IcpResult(np.array([0.5, 0.2, 0.3]), np.eye(3), 10, 0.1,
                    np.array([[3.0, 1.0, 0.5], [1.0, 2.0, 0.2], [0.5, 0.2, 4.0]]))
    info = fit_information(fit, MOUNT, pairs=2.0)
    # The laser-frame covariance s^2 N / pairs (J^T J)^-1 through v = M p M^-1 (numerically).
    jac = np.zeros((3, 3))
    for i in range(3):
        dp = np.zeros(3)
        dp[i] = 1e-6
        jac[:, i] = (compose(compose(MOUNT, fit.pose + dp), inverse(MOUNT))
                     - compose(compose(MOUNT, fit.pose - dp), inverse(MOUNT))) / 2e-6
    cov = 0.01 * 10 / 2.0 * np.linalg.inv(fit.hessian)
    assert np.allclose(np.linalg.inv(info), jac @ cov @ jac.T, atol=1e-9)


def test_scan_points_keeps_valid_returns_below_the_range_limit():
    r = np.array([1.0, np.inf, np.nan, -np.inf, 0.01, 25.0, 2.0])
    pts = scan_points(r, 0.0, 0.5, 0.05, 20.0)
    assert pts.shape == (2, 2)
    assert np.allclose(pts[0], [1.0, 0.0]) and np.allclose(pts[1], 2.0 * np.array(
        [math.cos(3.0), math.sin(3.0)]))


def _drive(scan_matching, scans=lambda k: True, odometry='pioneer', bias=0.004, jump_at=None,
           frontend=None, steps=None):
    """Drive through the room with drifting odometry; return the front end and the truth.

    ``scans(k)``: whether step k's set carries the scan; ``jump_at``: the odometry frame
    jumps by 5 m there (bridged); ``steps``: a list that collects each Step.
    """
    rng = np.random.default_rng(7)
    fe = SlamFrontend(SlamParams(odometry=odometry_noise_model(odometry)), MOUNT,
                      frontend or FrontendParams(scan_matching=scan_matching),
                      on_step=None if steps is None else steps.append)
    base, odo, truth = np.array([-2.5, -1.5, 0.2]), np.array([-2.5, -1.5, 0.2]), []
    t0 = 10 ** 9
    for k in range(40):
        t = t0 + k * 200_000_000
        if k:
            step = np.array([0.08, 0.0, 0.015 if k < 20 else -0.02])   # stays in the room
            base = compose(base, step)
            # The odometry turns 15 % too much and drifts by ``bias`` per step.
            odo = compose(odo, step * np.array([1.0, 1.0, 1.15]) + [0.0, 0.0, bias])
            if k == jump_at:
                odo = odo + np.array([5.0, 0.0, 0.0])
        truth.append(base)
        fe.add_odometry(t, odo)
        fe.add_features(Corners(t, np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0),
                                np.zeros(0), np.zeros(0),
                                scan=_geometry(_cast(compose(base, MOUNT), rng))
                                if scans(k) else None))
    fe.flush()
    return fe, np.array(truth)


def test_frontend_predicts_with_the_scan_matched_motion():
    """The ICP motion replaces the drifting odometry; its U is the scan-matching model."""
    steps = []
    fe, truth = _drive(True, steps=steps)
    assert fe.motions == {'odometry': 1, 'scan_matching': 39}   # the first step has no pair
    assert [st.motion for st in steps] == ['odometry'] + ['scan_matching'] * 39
    # Heading: the odometry turns 15 % too much and drifts (8 deg off after 40 steps).
    start = truth[0]
    est = relative(start, fe.slam.pose)
    ref = relative(start, truth[-1])
    assert abs(est[2] - ref[2]) < math.radians(0.2)   # measured 0.07 deg
    assert np.hypot(*(est[:2] - ref[:2])) < 0.02       # measured 0.9 cm
    fo, _ = _drive(False)
    assert fo.motions == {'odometry': 40, 'scan_matching': 0}
    odo = relative(start, fo.slam.pose)
    assert abs(odo[2] - ref[2]) > math.radians(7.5)
    # The scan-matched motion's U (0.6 of the heading gains: 0.36 of the variance) is what
    # was predicted with: the heading variance is about a third of the odometry run's.
    assert fe.slam.pose_covariance[2, 2] < 0.4 * fo.slam.pose_covariance[2, 2]


def test_frontend_fuses_the_odometry_and_the_scan_matched_motion():
    """With ``scan_matching_fit_pairs`` the step's motion is the two estimates fused."""
    def increments(frontend=None, scan_matching=True):
        steps = []
        _drive(scan_matching, frontend=frontend, steps=steps)
        return np.array([st.increment for st in steps[1:]]), [st.motion for st in steps]

    icp, _ = increments()
    odo, _ = increments(scan_matching=False)
    # A fit worth a million residuals gives the ICP's motion, one worth almost none the
    # odometry's; both are scan-matched steps (the ICP motion agreed).
    heavy, kinds = increments(FrontendParams(scan_matching=True, scan_matching_fit_pairs=1e6))
    assert kinds == ['odometry'] + ['scan_matching'] * 39
    assert np.allclose(heavy, icp, atol=1e-6)
    light, _ = increments(FrontendParams(scan_matching=True, scan_matching_fit_pairs=1e-9))
    assert np.allclose(light, odo, atol=1e-6)
    # Between: the walls of the room fix the turn, so the turns are much nearer the ICP's
    # than the odometry's (15 % too much and 0.23 deg of drift per step).
    mid, _ = increments(FrontendParams(scan_matching=True, scan_matching_fit_pairs=0.3))

    def rms(d):
        return float(np.sqrt(np.mean(d ** 2)))

    assert rms(mid[:, 2] - icp[:, 2]) < 0.25 * rms(odo[:, 2] - icp[:, 2])
    assert not np.allclose(mid, icp, atol=1e-4) and not np.allclose(mid, odo, atol=1e-4)


def test_frontend_without_scans_falls_back_to_the_odometry():
    fe, _ = _drive(True, scans=lambda k: False)
    fo, _ = _drive(False)
    assert fe.motions == {'odometry': 40, 'scan_matching': 0}
    np.testing.assert_array_equal(fe.slam.pose, fo.slam.pose)
    # A set without its scan: that step and the next (no previous scan) use the odometry.
    fe, _ = _drive(True, scans=lambda k: k != 20)
    assert fe.motions == {'odometry': 3, 'scan_matching': 37}


def test_frontend_keeps_the_odometry_where_the_scan_disagrees():
    """An ICP motion outside the region of U + V is not used (odometry and V both tight)."""
    tight = FrontendParams(scan_matching=True, scan_matching_noise='k_d=0 k_theta=0 k_dtheta=0')
    steps = []
    fe, _ = _drive(True, odometry='simulator', bias=0.05, frontend=tight, steps=steps)
    assert fe.motions == {'odometry': 40, 'scan_matching': 0}
    # With a bias the simulator's U covers, the same scans are used.
    fe, _ = _drive(True, odometry='simulator', bias=0.0, frontend=tight)
    assert fe.motions['scan_matching'] >= 35


def test_a_bridged_odometry_jump_is_predicted_with_the_odometry():
    """Across a bridged frame jump the increment is unknown: no ICP guess, U keeps its share."""
    steps = []
    fe, _ = _drive(True, jump_at=20, steps=steps)
    jumped = [st for st in steps if np.any(st.bridged_variance > 0.0)]
    assert len(jumped) == 1 and jumped[0].motion == 'odometry'
    assert fe.motions == {'odometry': 2, 'scan_matching': 38}


def test_a_restart_forgets_the_previous_scan():
    fe, _ = _drive(True)
    fe.clear()
    assert fe._scan_points is None
    t = 10 ** 10
    geometry = _geometry(_cast(compose(np.array([-2.5, -1.5, 0.2]), MOUNT)))
    fe.add_odometry(t, [0.0, 0.0, 0.0])
    steps = fe.add_features(Corners(t, np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0),
                                    np.zeros(0), np.zeros(0), scan=geometry))
    assert [st.motion for st in steps] == ['odometry']


def test_scan_matching_parameters_are_validated():
    with pytest.raises(ValueError, match='scan_matching_noise'):
        FrontendParams(scan_matching_noise='k_d=-1')
    with pytest.raises(ValueError, match='scan_matching_accept'):
        FrontendParams(scan_matching_accept=1.0)
    with pytest.raises(ValueError, match='scan_matching_max_range'):
        FrontendParams(scan_matching_max_range=0.0)
    with pytest.raises(ValueError, match='scan_matching must be a bool'):
        FrontendParams(scan_matching=1)
    for bad in (-0.1, math.nan, True):
        for name in ('scan_matching_fit_pairs', 'scan_matching_side_starts'):
            with pytest.raises(ValueError, match=name):
                FrontendParams(**{name: bad})
    with pytest.raises(ValueError, match='visibility'):
        run_slam(None, frontend=FrontendParams(scan_matching=True), visibility=False)
