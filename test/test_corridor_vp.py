"""Tests of the vanishing-point estimators on synthetic line sets with exactly known VPs."""

import math

from landmark_nav.corridor.vanishing_point import (_Geometry, chapter_vanishing_point,
                                                   consistency, corridor_vanishing_point,
                                                   direction_covariance,
                                                   leave_one_out_directions,
                                                   manhattan_frame, refine_direction,
                                                   refine_manhattan, residual_terms,
                                                   vanishing_point, VPParams)
from landmark_nav.corridor.vp_confidence import (assess_direction, assess_frame, CALIBRATION,
                                                 features, fit_calibration, influence,
                                                 log10_nfa, mixture_radius,
                                                 orthogonality_residuals)
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

K = np.array([[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]])
W, H = 640, 480


def angle_deg(a, b):
    """Return the axial angle [deg] between two directions."""
    c = abs(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b))
    return math.degrees(math.acos(min(1.0, c)))


def lines_along(rng, d, n, sigma=0.0):
    """Return (n, 4) image segments of 3-D lines along d, end points jittered across by sigma."""
    out = []
    while len(out) < n:
        p = np.array([rng.uniform(-4, 4), rng.uniform(-3, 3), rng.uniform(2.0, 12.0)])
        a, b = p - rng.uniform(0.3, 2.0) * d, p + rng.uniform(0.3, 2.0) * d
        if a[2] < 0.5 or b[2] < 0.5:
            continue
        pa, pb = (K @ a)[:2] / a[2], (K @ b)[:2] / b[2]
        inside = all(0 <= q[0] < W and 0 <= q[1] < H for q in (pa, pb))
        if not inside or np.linalg.norm(pb - pa) < 25.0:
            continue
        u = (pb - pa) / np.linalg.norm(pb - pa)
        nrm = np.array([-u[1], u[0]])
        pa = pa + rng.normal(0, sigma) * nrm
        pb = pb + rng.normal(0, sigma) * nrm
        out.append(np.concatenate([pa, pb]))
    return np.array(out)


def random_segments(rng, n):
    """Return (n, 4) outlier segments of random position, direction and length."""
    c = rng.uniform([0, 0], [W, H], (n, 2))
    ang = rng.uniform(0, math.pi, n)
    half = rng.uniform(15, 80, n)[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
    return np.hstack([c - half, c + half])


def corridor_frame(yaw_deg, pitch_deg, roll_deg=0.0):
    """Return (3, 3) Manhattan directions in the optical frame; column 0 near the axis."""
    r = Rotation.from_euler('yxz', [yaw_deg, pitch_deg, roll_deg], degrees=True).as_matrix()
    return r                       # columns: images of the optical x, y, z axes


# ------------------------------------------------------------------ consistency (z-scores)
@pytest.mark.parametrize('d', [np.array([0.1, -0.05, 1.0]),      # finite VP
                               np.array([1.0, 0.2, 0.0])])       # VP at infinity
def test_z_scores_are_standard_normal_for_the_model_noise(d):
    rng = np.random.default_rng(4)
    d = d / np.linalg.norm(d)
    seg = lines_along(rng, d, 2000, sigma=0.5)
    z = consistency(seg, K @ d, sigma_px=0.5)
    assert np.all(np.isfinite(z))
    # std of 2000 N(0, 1) samples: 1 +- 0.016 (1 sigma)
    assert 0.94 < np.std(z) < 1.06
    assert abs(np.mean(z)) < 0.08
    # a wrong noise model shows: twice the assumed sigma doubles the spread
    assert 1.85 < np.std(consistency(seg, K @ d, sigma_px=0.25)) < 2.15


def test_z_score_is_scale_free_and_handles_infinity():
    rng = np.random.default_rng(5)
    d = np.array([1.0, 0.0, 0.0])
    seg = lines_along(rng, d, 50, sigma=0.3)
    v = K @ d
    np.testing.assert_allclose(np.abs(consistency(seg, v)), np.abs(consistency(seg, -7.5 * v)),
                               rtol=1e-12)
    off = K @ np.array([1.0, 0.05, 0.0])             # 2.9 deg away, also at infinity
    # ~100 px segments, end-point sigma 0.3 px: direction std 0.24 deg, so z ~ 12
    assert np.median(np.abs(consistency(seg, off, sigma_px=0.3))) > 9.0
    assert np.median(np.abs(consistency(seg, K @ d, sigma_px=0.3))) < 1.0


def test_direction_noise_of_a_segment_grows_with_its_distance_to_the_vp():
    # a 400 px segment on the line through the VP, its mid-point 300 px from it, turned by
    # t = 0.5 deg about its mid-point (an edge a little bent): the line misses the VP by
    # 300 sin t, and the direction-noise factor of the variance is the distance along the
    # segment from its mid-point to the VP, squared
    v = np.array([400.0, 260.0])
    u = np.array([math.cos(0.3), math.sin(0.3)])
    m = v - 300.0 * u
    t = math.radians(0.5)
    ut = np.array([math.cos(0.3 + t), math.sin(0.3 + t)])
    seg = np.r_[m - 200.0 * ut, m + 200.0 * ut][None]
    d = np.linalg.solve(K, np.r_[v, 1.0])        # K d = v: homogeneous weight 1
    r, a, b = residual_terms(seg, K, d)
    c = 300.0 * math.cos(t)
    assert abs(r[0]) == pytest.approx(300.0 * math.sin(t), rel=1e-9)
    assert b[0] == pytest.approx(c ** 2, rel=1e-9)
    # end points alone: A^2 + B^2 (module docstring)
    assert a[0] == pytest.approx(((200.0 - c) ** 2 + (200.0 + c) ** 2) / 400.0 ** 2, rel=1e-9)
    # end-point noise alone (0.6 px) puts it beyond the gate (z 3.4); with 0.38 deg of
    # direction noise it is a line of that VP (z 1.2)
    z_end = abs(_Geometry(seg, K, 0.6).z(d[None])[0, 0])
    z_both = abs(_Geometry(seg, K, 0.6, math.radians(0.38)).z(d[None])[0, 0])
    assert z_end == pytest.approx(abs(r[0]) / (0.6 * math.sqrt(a[0])), rel=1e-9)
    assert z_end > VPParams().gate > z_both
    assert z_both == pytest.approx(abs(r[0]) / math.sqrt(0.36 * a[0]
                                                         + math.radians(0.38) ** 2 * b[0]))


# ------------------------------------------------------------------ the chapter's method
def test_chapter_method_finds_a_finite_vp():
    rng = np.random.default_rng(1)
    D = corridor_frame(8.0, -5.0)
    seg = np.vstack([lines_along(rng, D[:, 2], 25, 0.5), lines_along(rng, D[:, 0], 8, 0.5),
                     lines_along(rng, D[:, 1], 8, 0.5)])
    vp = chapter_vanishing_point(seg, K)
    # measured 0.05 deg on this set
    assert angle_deg(vp.direction, D[:, 2]) < 0.3
    assert vp.pixel is not None
    assert np.count_nonzero(vp.inliers[:25]) >= 24
    assert np.count_nonzero(vp.inliers[25:]) <= 1


def test_chapter_method_cannot_represent_parallel_image_lines():
    seg = np.array([[0.0, 10.0, 100.0, 10.0], [0.0, 50.0, 100.0, 50.0],
                    [0.0, 90.0, 100.0, 90.0]])
    with pytest.raises(ValueError, match='finite'):
        chapter_vanishing_point(seg, K)
    vp = vanishing_point(seg, K)                     # the projective form can
    assert vp.pixel is None
    assert angle_deg(vp.direction, [1.0, 0.0, 0.0]) < 1e-9


# ------------------------------------------------------------------ the projective form
def test_vp_at_infinity_with_noise_and_outliers():
    rng = np.random.default_rng(2)
    d = np.array([math.cos(0.3), math.sin(0.3), 0.0])
    good = lines_along(rng, d, 30, 0.5)
    seg = np.vstack([good, random_segments(rng, 20)])
    vp = vanishing_point(seg, K)
    # measured 0.37 deg, almost all of it along the lines (d_z = 0.0056): a VP at infinity
    # is poorly fixed in that direction by short segments
    assert angle_deg(vp.direction, d) < 0.6
    assert abs(vp.direction[2]) < 0.01
    exact = vanishing_point(lines_along(rng, d, 30, 0.0), K)
    assert angle_deg(exact.direction, d) < 1e-6
    assert np.count_nonzero(vp.inliers[:30]) >= 29
    assert np.count_nonzero(vp.inliers[30:]) <= 2


def test_weighted_projective_beats_the_chapter_with_outliers():
    rng = np.random.default_rng(3)
    D = corridor_frame(20.0, 10.0)
    errs_ch, errs_w = [], []
    for _ in range(10):
        seg = np.vstack([lines_along(rng, D[:, 2], 15, 0.7), random_segments(rng, 30)])
        errs_ch.append(angle_deg(chapter_vanishing_point(seg, K).direction, D[:, 2]))
        errs_w.append(angle_deg(vanishing_point(seg, K).direction, D[:, 2]))
    # measured: median 0.25 deg, worst 0.69 (the chapter's: median 0.31, worst 0.51)
    assert np.median(errs_w) < 0.35
    assert max(errs_w) < 1.0
    assert np.median(errs_w) < np.median(errs_ch)


def test_bad_input():
    with pytest.raises(ValueError, match=r'\(N, 4\)'):
        vanishing_point(np.zeros((3, 3)), K)
    with pytest.raises(ValueError, match='fx, fy > 0'):
        vanishing_point(np.zeros((3, 4)), np.diag([0.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match='candidates'):
        vanishing_point(np.array([[0.0, 0.0, 100.0, 0.0]]), K)
    with pytest.raises(ValueError, match='candidates'):
        manhattan_frame(np.zeros((0, 4)), K)


# ------------------------------------------------------------------ Manhattan directions
@pytest.mark.parametrize('seed', range(5))
def test_manhattan_frame_recovers_all_three_directions(seed):
    rng = np.random.default_rng(10 + seed)
    D = corridor_frame(rng.uniform(-25, 25), rng.uniform(-15, 15), rng.uniform(-5, 5))
    seg = np.vstack([lines_along(rng, D[:, 2], 20, 0.5), lines_along(rng, D[:, 0], 15, 0.5),
                     lines_along(rng, D[:, 1], 15, 0.5), random_segments(rng, 12)])
    mf = manhattan_frame(seg, K)
    assert mf.directions.shape == (3, 3)
    # column 0 is the one closest to the optical axis: the corridor direction
    # (measured 0.03-0.13 deg over the five seeds; the others 0.03-0.66 deg)
    assert angle_deg(mf.directions[:, 0], D[:, 2]) < 0.25
    for k in range(3):
        assert min(angle_deg(mf.directions[:, j], D[:, k]) for j in range(3)) < 1.0
    assert np.all(mf.directions[2] >= 0)
    true_label = np.repeat([2, 0, 1, -1], [20, 15, 15, 12])
    found = np.array([[angle_deg(mf.directions[:, j], D[:, k]) for k in range(3)]
                      for j in range(3)]).argmin(1)     # detected column -> true index
    mapped = np.where(mf.labels >= 0, found[mf.labels], -1)
    assert np.mean(mapped[:50] == true_label[:50]) >= 0.96
    vp = corridor_vanishing_point(seg, K)
    np.testing.assert_allclose(vp.direction, mf.directions[:, 0])


def test_manhattan_frame_with_a_vertical_vp_at_infinity():
    rng = np.random.default_rng(7)
    D = corridor_frame(30.0, 0.0)                  # level camera: verticals parallel
    assert abs(D[2, 1]) < 1e-12
    seg = np.vstack([lines_along(rng, D[:, 2], 15, 0.5), lines_along(rng, D[:, 0], 15, 0.5),
                     lines_along(rng, D[:, 1], 25, 0.5)])
    mf = manhattan_frame(seg, K)
    vertical = min(range(3), key=lambda j: angle_deg(mf.directions[:, j], D[:, 1]))
    assert angle_deg(mf.directions[:, vertical], D[:, 1]) < 0.2
    assert mf.points[vertical].pixel is None or abs(mf.directions[2, vertical]) < 0.01


def test_parameters_are_used():
    rng = np.random.default_rng(8)
    d = np.array([0.05, 0.02, 1.0]) / np.linalg.norm([0.05, 0.02, 1.0])
    seg = lines_along(rng, d, 30, 2.0)
    loose = vanishing_point(seg, K, params=VPParams(sigma_px=2.0))
    tight = vanishing_point(seg, K, params=VPParams(sigma_px=0.2))
    assert np.count_nonzero(loose.inliers) > np.count_nonzero(tight.inliers) + 10


def test_refine_manhattan_fixes_a_direction_with_two_lines_by_the_other_two():
    rng = np.random.default_rng(4)
    R = corridor_frame(6.0, 3.0, 2.0)
    # a frontal view: 30 lines along each of x and y, two receding ones (no third to check
    # them: on its own lines the direction is where the two happen to meet)
    seg = np.vstack([lines_along(rng, R[:, 0], 30, 0.5), lines_along(rng, R[:, 1], 30, 0.5),
                     lines_along(rng, R[:, 2], 2, 0.5)])
    params = VPParams(sigma_angle_deg=0.0)     # these lines are straight: end-point noise only
    start = Rotation.from_rotvec([0.02, -0.03, 0.01]).as_matrix() @ R     # 2.1 deg off
    out = refine_manhattan(_Geometry(seg, K, params.sigma_px), start, params)
    np.testing.assert_allclose(out.T @ out, np.eye(3), atol=1e-12)
    for k in range(3):                      # columns stay in the start's order
        assert angle_deg(out[:, k], R[:, k]) < 0.3          # measured 0.14 / 0.19 / 0.22
    # on its own two lines the receding direction stays where it started
    own = refine_direction(seg, K, start[:, 2], params=params)[0]
    assert angle_deg(own, R[:, 2]) > 1.9                    # measured 2.0
    # a frame of one direction's lines does not fix a rotation: the start comes back
    one = lines_along(rng, R[:, 0], 30, 0.5)
    same = refine_manhattan(_Geometry(one, K, params.sigma_px), start, params)
    np.testing.assert_allclose(same, start, atol=1e-12)


# ------------------------------------------------------------------ confidence (vp_confidence)
def test_confidence_flags_a_frontal_view_as_weak_and_a_good_frame_as_confident():
    sigma = VPParams().sigma_px
    weak_ones = 0
    for seed in (0, 1, 3):
        rng = np.random.default_rng(seed)
        # a corridor seen along its axis: 25 lines per direction, 0.5 px end-point noise
        R = corridor_frame(8.0, 4.0)
        seg = np.vstack([lines_along(rng, R[:, k], 25, 0.5) for k in range(3)]
                        + [random_segments(rng, 15)])
        mf = manhattan_frame(seg, K)
        good = assess_frame(mf, seg, K, sigma)[0]
        err = math.radians(angle_deg(mf.directions[:, 0], R[:, 2]))
        assert good.confident and good.p_correct >= CALIBRATION.p_confident
        assert good.inliers >= 20 and err <= good.radius95
        assert math.degrees(math.sqrt(np.trace(good.first_order) / 2)) < 0.2
        assert math.degrees(math.sqrt(np.trace(good.wrong_covariance) / 2)) == pytest.approx(
            CALIBRATION.sigma_wrong_deg)
        # a frontal facade: 40 lines along each of x and y, 3 short receding ones
        R = corridor_frame(2.0, 1.0)
        seg = np.vstack([lines_along(rng, R[:, 0], 40, 0.5), lines_along(rng, R[:, 1], 40, 0.5),
                         lines_along(rng, R[:, 2], 3, 0.5), random_segments(rng, 15)])
        mf = manhattan_frame(seg, K)
        weak = assess_frame(mf, seg, K, sigma)[0]
        err = angle_deg(mf.directions[:, 0], R[:, 2])
        if weak.confident:
            # seed 0: a long line of another direction passes the vanishing point too, the
            # a-contrario test counts it (log10 NFA -0.9), and the direction is 0.4 deg off
            assert err <= 2.0
            continue
        weak_ones += 1
        assert weak.p_correct < CALIBRATION.p_confident
        # its error is mostly the wrong mode's (5.3 deg) where the good frame's is its own
        assert math.degrees(math.sqrt(np.trace(weak.mixture_covariance) / 2)) > 4.0
        # p = 0 (its lines do not check it): the 95 % radius of the wrong mode alone, the
        # Rayleigh quantile sigma_wrong sqrt(-2 ln 0.05) (5.3 deg: 13.0 deg)
        assert weak.radius95 == pytest.approx(math.radians(CALIBRATION.sigma_wrong_deg)
                                              * math.sqrt(-2.0 * math.log(0.05)), rel=1e-3)
    assert weak_ones >= 2           # seeds 1 (2.3 deg off) and 3


def test_mixture_radius_and_calibration_fit():
    s = math.radians(0.5)
    # one mode: the Rayleigh 95 % quantile sqrt(-2 ln 0.05) sigma
    assert mixture_radius(1.0, s, 0.1) == pytest.approx(math.sqrt(-2 * math.log(0.05)) * s)
    assert mixture_radius(0.0, s, 0.1) == pytest.approx(math.sqrt(-2 * math.log(0.05)) * 0.1)
    assert mixture_radius(0.0, s, 1.0) == pytest.approx(math.pi / 2)      # capped
    # errors drawn from the model are fitted back: 3000 directions, a = 0.7, b = 0.4 deg,
    # 10 % wrong at 6 deg RMS; p falls with sigma_cov
    rng = np.random.default_rng(2)
    n = 3000
    s_cov = np.radians(np.exp(rng.uniform(np.log(0.05), np.log(3.0), n)))
    wrong = rng.random(n) < 0.1 * (1 + np.log(np.degrees(s_cov) / 0.05))
    spread = np.where(wrong, 6.0 / math.sqrt(2), np.hypot(0.7 * np.degrees(s_cov), 0.4))
    err = spread * np.sqrt(-2 * np.log(rng.random(n)))
    wrong |= err > 2.0
    err = np.where(wrong, np.maximum(err, 2.01), err)
    f, m = np.full(n, 500.0), np.full(n, 10)
    cal = fit_calibration(s_cov, s_cov, f, m, np.full(n, -10.0), err)
    # truncated ML from ~1900 correct ones: measured a 0.70 b 0.397 (seeds 2-7: a 0.70-0.78,
    # b 0.387-0.402)
    assert 0.63 < cal.scale < 0.8 and 0.36 < cal.floor_deg < 0.44
    assert cal.weights[1] + cal.weights[3] < 0      # a larger spread (here both), a smaller p
    p = [assess_direction(x, x, 500.0, 10, -10.0, cal)[0] for x in s_cov]
    conf = np.array(p) >= cal.p_confident
    assert np.mean(err[conf] <= 2.0) >= 0.98
    assert assess_direction(s_cov[0], s_cov[0], 500.0, 10, 0.0, cal)[0] == 0.0  # NFA 1
    with pytest.raises(ValueError, match='differ in length'):
        fit_calibration(s_cov, s_cov, f, np.zeros(3), np.full(n, -10.0), err)


def test_orthogonality_residual_is_the_angle_to_the_other_two_directions_normal():
    R = Rotation.from_euler('xyz', [0.3, -0.2, 0.5]).as_matrix()
    assert np.all(orthogonality_residuals(R) < 1e-7)
    # column 0 tilted by 3 deg towards column 1: 3 deg off the normal of columns 1 and 2,
    # and columns 1 and 2 each 3 deg off the normal of the others (the plane of 0 and 2, of
    # 0 and 1, tilts with column 0)
    D = R.copy()
    D[:, 0] = math.cos(math.radians(3)) * R[:, 0] + math.sin(math.radians(3)) * R[:, 1]
    assert np.degrees(orthogonality_residuals(D)) == pytest.approx([3.0, 3.0, 0.0], abs=1e-9)
    # a direction that is not finite is the least confident, not the most
    D[:, 2] = np.nan
    assert orthogonality_residuals(D) == pytest.approx([math.pi / 2] * 3)
    # the fifth feature of the confidence model, only when given
    assert features(0.01, 0.01, 500.0, 10).shape == (4,)
    assert features(0.01, 0.01, 500.0, 10, math.radians(3))[4] == pytest.approx(
        math.log(math.radians(3)))
    # the sixth, the influence, with the fifth; no leave-one-out estimate: the upper bound
    assert features(0.01, 0.01, 500.0, 10, math.radians(3), 2.0)[5] == pytest.approx(
        math.log(2.0))
    assert features(0.01, 0.01, 500.0, 10, math.radians(3), math.inf)[5] == pytest.approx(
        math.log(1e3))


def _refined(seg, params):
    d, inl = refine_direction(seg, K, corridor_frame(8.0, 4.0)[:, 2], params=params)
    cov = direction_covariance(seg, K, d, inl, params.sigma_px, params.sigma_angle_deg)
    return d, inl, math.sqrt(np.linalg.eigvalsh(cov)[-1])


def test_influence_is_the_largest_leave_one_out_move_over_the_spread():
    params = VPParams()
    d_true = corridor_frame(8.0, 4.0)[:, 2]
    v = (K @ d_true)[:2] / d_true[2]
    for seed in range(4):
        rng = np.random.default_rng(seed)
        # 20 lines of the direction, 0.5 px end-point noise: no line moves it by its spread
        seg = lines_along(rng, d_true, 20, 0.5)
        d, inl, s = _refined(seg, params)
        many = influence(seg, K, d, inl, s, params)
        assert many < 1.0                                   # measured 0.28-0.70
        # the deleted estimates are the direction refined on the other inliers
        loo = leave_one_out_directions(seg, K, d, inl, params)
        first = inl.copy()
        first[np.argmax(inl)] = False
        own = refine_direction(seg, K, d, params=params, allowed=first)[0]
        assert angle_deg(loo[0], own) < 1e-9
        assert many * s == pytest.approx(max(math.radians(angle_deg(x, d)) for x in loo))
        # one long line (300 px) and four short ones (25 px) through the vanishing point:
        # the long line carries the direction, leaving it out moves it far more
        segs = []
        for ang, length, start in [(0.3, 300.0, 40.0)] + [
                (a, 25.0, 150.0) for a in rng.uniform(-2.5, 2.5, 4)]:
            u = np.array([math.cos(ang), math.sin(ang)])
            nrm = np.array([-u[1], u[0]])
            segs.append(np.r_[v + start * u + rng.normal(0, 0.5) * nrm,
                              v + (start + length) * u + rng.normal(0, 0.5) * nrm])
        seg = np.array(segs)
        d, inl, s = _refined(seg, params)
        assert influence(seg, K, d, inl, s, params) > many  # measured 0.68-3.19
    # fewer than three inliers: no deleted estimate to measure it
    assert influence(seg[:2], K, d, np.ones(2, bool), s, params) == math.inf


def test_nfa_counts_long_consistent_lines_not_their_number():
    rng = np.random.default_rng(4)
    sigma, gate = VPParams().sigma_px, VPParams().gate
    v = np.array([330.0, 250.0])                 # the vanishing point [px]

    def through_v(lengths):
        ang = rng.uniform(0, 2 * np.pi, len(lengths))
        u = np.column_stack([np.cos(ang), np.sin(ang)])
        near = v + 30.0 * u
        return np.column_stack([near, near + u * np.asarray(lengths)[:, None]])
    others = random_segments(rng, 95)            # N = 100: 4950 candidate points
    inl = np.r_[np.ones(5, bool), np.zeros(95, bool)]
    # five corridor edges of 300 px: two fix the point, three long ones check it, each
    # passing by chance with the probability of its direction noise (end points and angle)
    edges = np.vstack([through_v([300.0] * 5), others])
    std = math.sqrt(2 * (sigma / 300.0) ** 2 + math.radians(VPParams().sigma_angle_deg) ** 2)
    p = 2 * gate * std / math.pi
    assert log10_nfa(edges, inl, sigma, gate) == pytest.approx(math.log10(4950 * p ** 3))
    assert log10_nfa(edges, inl, sigma, gate) < -1.8             # measured -1.9
    # five short ones (25 px): as many lines, far less evidence (measured log10 NFA 0.1)
    short = np.vstack([through_v([25.0] * 5), others])
    assert log10_nfa(short, inl, sigma, gate) > 0.0
    s, o = math.radians(0.1), math.radians(1.0)       # orthogonality residual 1 deg
    i = 0.8                                           # influence: York's median
    assert assess_direction(s, s, 500.0, 5, log10_nfa(short, inl, sigma, gate),
                            orthogonality=o, influence=i)[0] == 0
    assert assess_direction(s, s, 500.0, 5, log10_nfa(edges, inl, sigma, gate),
                            orthogonality=o, influence=i)[0] > 0.9
    # the shipped model weighs the residual and the influence: not given, neither is taken
    # as 0 (the most confident value)
    with pytest.raises(ValueError, match='orthogonality'):
        assess_direction(s, s, 500.0, 5, log10_nfa(edges, inl, sigma, gate))
    with pytest.raises(ValueError, match='influence'):
        assess_direction(s, s, 500.0, 5, log10_nfa(edges, inl, sigma, gate), orthogonality=o)
    # the two longest fix the point and do not count
    mixed = np.vstack([through_v([400.0, 400.0, 300.0, 300.0, 300.0]), others])
    assert log10_nfa(mixed, inl, sigma, gate) == pytest.approx(math.log10(4950 * p ** 3))
