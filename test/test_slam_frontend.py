"""SLAM front end: odometry as it comes (gaps, repeats, backward stamps, jumps), de-skew, order."""

import math
from types import SimpleNamespace

from landmark_nav.slam.ekf_slam import OdometryNoise, SlamParams
from landmark_nav.slam.frontend import (Corners, FrontendParams, odometry_noise_model,
                                        ODOMETRY_NOISE_MODELS, SlamFrontend)
from landmark_nav.slam.line_landmarks import lines_to_observations
import numpy as np
import pytest

T0 = 1_700_000_000_000_000_000
MS = 1_000_000


def corners(t_ns, xy=((2.0, 1.0),), beam_time=None):
    """Corners at ``xy`` (laser frame) with a small covariance."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    m = len(xy)
    cov = np.tile(np.eye(2) * 1e-4, (m, 1, 1))
    bt = np.zeros(m) if beam_time is None else np.asarray(beam_time, dtype=float)
    return Corners(t_ns, xy, cov, np.full(m, math.pi), np.full(m, math.pi / 2), bt)


def test_noise_models_and_drift_gains():
    assert odometry_noise_model('simulator') == OdometryNoise()
    pioneer = odometry_noise_model('pioneer')
    assert (pioneer.sigma_xy_per_sqrt_m, pioneer.sigma_yaw_per_sqrt_m,
            pioneer.sigma_yaw_per_sqrt_rad) == (0.05, 0.05, 0.1)
    n = odometry_noise_model('k_d=0.02 k_theta=0.05 k_dtheta=0.01')  # the contract's example
    assert (n.sigma_xy_per_sqrt_m, n.sigma_yaw_per_sqrt_m, n.sigma_yaw_per_sqrt_rad) == (
        0.02, 0.05, 0.01)
    assert odometry_noise_model('k_d=0.01').sigma_yaw_per_sqrt_rad == 0.1  # others: pioneer
    for bad in ('fast', 'k_d=-1', 'k_d=abc', 'k_x=1', ''):
        with pytest.raises(ValueError, match='odometry noise model'):
            odometry_noise_model(bad)
    assert set(ODOMETRY_NOISE_MODELS) == {'pioneer', 'simulator'}


def test_large_plausible_step_and_gap_are_motion_not_jump():
    """A 1.05 m step in 2 s (a sparse log) and a 5 s /odom gap are motion, never a reset."""
    fe = SlamFrontend(SlamParams(odometry=ODOMETRY_NOISE_MODELS['pioneer']))
    assert fe.add_odometry(T0, [0, 0, 0])[0] == 'accepted'
    assert fe.add_odometry(T0 + 2000 * MS, [1.05, 0, 0.3])[0] == 'accepted'
    assert fe.add_odometry(T0 + 7000 * MS, [4.0, 0.5, 0.3])[0] == 'accepted'  # gap of 5 s
    steps = fe.add_features(corners(T0 + 4500 * MS))
    assert len(steps) == 1 and fe.restarts == 0 and fe.events['jump'] == 0
    # Interpolated across the gap: halfway between the two samples.
    np.testing.assert_allclose(steps[0].odometry, [2.525, 0.25, 0.3], atol=1e-12)


def test_implausible_step_is_bridged_keeping_the_map():
    f = FrontendParams()
    fe = SlamFrontend(SlamParams(odometry=ODOMETRY_NOISE_MODELS['pioneer'], confirm_hits=1,
                                 confirm_window=1), frontend=f)
    fe.add_odometry(T0, [0, 0, 0])
    fe.add_odometry(T0 + 100 * MS, [0.05, 0, 0])
    fe.add_features(corners(T0 + 100 * MS))
    assert fe.slam.num_landmarks == 1
    # Limit over 0.1 s at 5 sigma of 0.05 m/sqrt(m): 0.15 + 0.25 sqrt(d); 3 m is beyond.
    kind, _ = fe.add_odometry(T0 + 200 * MS, [3.05, 0, 0])
    assert kind == 'jump' and fe.restarts == 0
    fe.add_odometry(T0 + 300 * MS, [3.10, 0, 0])  # motion continues in the new frame
    (step,) = fe.add_features(corners(T0 + 300 * MS))
    assert fe.slam.num_landmarks >= 1  # the map is kept
    np.testing.assert_allclose(step.odometry, [0.10, 0, 0], atol=1e-12)  # jump removed
    np.testing.assert_allclose(step.bridged_variance, [(1.5 * 0.1) ** 2] * 2
                               + [(5.3 * 0.1) ** 2], rtol=1e-12)
    # Just inside the limit is motion: 0.15 + 0.25 * sqrt(0.3) = 0.287 m in 0.1 s.
    fe.add_odometry(T0 + 400 * MS, [3.10 + 0.28, 0, 0])
    assert fe.events['jump'] == 1


def test_turn_limit_and_the_stated_covariance_does_not_widen_the_check():
    fe = SlamFrontend(SlamParams(odometry=OdometryNoise(0.0, 0.0, 0.0)))
    fe.add_odometry(T0, [0, 0, 0], np.zeros((3, 3)))
    # 0.6 rad in 0.1 s is above 5.3 rad/s ...
    assert fe.add_odometry(T0 + 100 * MS, [0, 0, 0.6], np.zeros((3, 3)))[0] == 'jump'
    # ... whatever covariance the sample claims: the check does not trust the suspect sample.
    fe = SlamFrontend(SlamParams(odometry=OdometryNoise(0.0, 0.0, 0.0)))
    fe.add_odometry(T0, [0, 0, 0], np.zeros((3, 3)))
    assert fe.add_odometry(T0 + 100 * MS, [0, 0, 0.6],
                           np.diag([0.0, 0.0, 0.05 ** 2]))[0] == 'jump'


def test_teleport_with_a_huge_covariance_is_bridged_not_motion():
    """+5 m in 0.1 s claiming 1e6 m^2 (issue: accepted as motion); then back: pose kept."""
    fe = SlamFrontend(SlamParams(odometry=ODOMETRY_NOISE_MODELS['pioneer']))
    small, huge = np.diag([1e-4, 1e-4, 1e-4]), np.diag([1e6, 1e6, 1e6])
    fe.add_odometry(T0, [0, 0, 0], small)
    fe.add_odometry(T0 + 100 * MS, [0.01, 0, 0], small)
    assert fe.add_odometry(T0 + 200 * MS, [5.01, 0, 0], huge)[0] == 'jump'
    assert fe.add_odometry(T0 + 300 * MS, [0.02, 0, 0], small)[0] == 'jump'  # and back
    fe.add_odometry(T0 + 400 * MS, [0.03, 0, 0], small)
    (step,) = fe.add_features(corners(T0 + 400 * MS))
    assert abs(step.odometry[0] - 0.02) < 1e-12 and abs(fe.slam.pose[0]) < 0.03


@pytest.mark.parametrize('cov, problem', [
    (np.diag([-1e-4, 1e-4, 1e-4]), 'negative variance'),
    (np.diag([np.nan, 1e-4, 1e-4]), 'not finite'),
    (np.array([[1e-4, 1e-2, 0], [1e-2, 1e-4, 0], [0, 0, 1e-4]]), 'not positive semi-definite'),
    (np.array([[1e-4, 1e-5, 0], [0, 1e-4, 0], [0, 0, 1e-4]]), 'not symmetric'),
])
def test_bad_stated_covariances_are_replaced_and_reported(cov, problem):
    events = []
    fe = SlamFrontend(on_event=lambda kind, message: events.append((kind, message)))
    fe.add_odometry(T0, [0, 0, 0], np.eye(3) * 1e-4)
    assert fe.add_odometry(T0 + 100 * MS, [0.01, 0, 0], cov)[0] == 'accepted'
    assert [k for k, _ in events] == ['covariance'] and problem in events[0][1]
    assert fe.events['covariance'] == 1 and fe._buf.cov_last is None


def test_one_stamp_never_resets_only_a_persistent_backward_run_does():
    fe = SlamFrontend(SlamParams(confirm_hits=1, confirm_window=1))
    fe.add_odometry(T0, [0, 0, 0])
    fe.add_odometry(T0 + 100 * MS, [0.01, 0, 0])
    fe.add_features(corners(T0 + 100 * MS))
    assert fe.slam.num_landmarks == 1
    assert fe.add_odometry(0, [0.02, 0, 0])[0] == 'invalid'  # stamp 0: an unset header
    assert fe.add_odometry(T0 - 2000 * MS, [5.0, 0, 0])[0] == 'far_back'  # one: held
    assert fe.add_odometry(T0 + 200 * MS, [0.02, 0, 0])[0] == 'accepted'  # the run is over
    assert fe.events['backward'] == 1  # ... and the held sample dropped
    assert fe.add_odometry(T0 - 2000 * MS, [5.0, 0, 0])[0] == 'far_back'
    assert fe.add_odometry(T0 - 2100 * MS, [5.0, 0, 0])[0] == 'far_back'  # not a forward run
    assert fe.add_odometry(T0 - 1900 * MS, [5.0, 0, 0])[0] == 'far_back'
    assert fe.events['backward'] == 2 and fe.events['far_back'] == 4
    assert fe.restarts == 0 and fe.slam.num_landmarks == 1
    kind, _ = fe.add_odometry(T0 - 1800 * MS, [5.01, 0, 0])  # the third in a row
    assert kind == 'restart' and fe.restarts == 1 and fe.slam.num_landmarks == 0
    assert fe.odometry_span == (T0 - 2100 * MS, T0 - 1800 * MS)  # the run is the new start


def test_a_stamp_in_the_future_is_withdrawn_not_a_restart():
    fe = SlamFrontend(SlamParams(confirm_hits=1, confirm_window=1))
    fe.add_odometry(T0, [0, 0, 0])
    fe.add_odometry(T0 + 100 * MS, [0.01, 0, 0])
    fe.add_features(corners(T0 + 100 * MS))
    fe.add_odometry(T0 + 3600_000 * MS, [0.02, 0, 0])  # an hour ahead: plausible by time
    kinds = [fe.add_odometry(T0 + (200 + 100 * i) * MS, [0.02 + 0.01 * i, 0, 0])[0]
             for i in range(3)]
    assert kinds == ['far_back', 'far_back', 'retracted']
    assert fe.restarts == 0 and fe.slam.num_landmarks == 1
    # The future sample trimmed the buffer to the sample before it (buffer_s behind it).
    assert fe.odometry_span == (T0 + 100 * MS, T0 + 400 * MS)
    (step,) = fe.add_features(corners(T0 + 350 * MS))
    np.testing.assert_allclose(step.odometry, [0.035, 0, 0], atol=1e-12)


def test_repeated_backward_and_restart():
    fe = SlamFrontend()
    fe.add_odometry(T0, [0, 0, 0])
    fe.add_odometry(T0 + 100 * MS, [0.01, 0, 0])
    assert fe.add_odometry(T0 + 100 * MS, [0.01, 0, 0])[0] == 'repeated'
    assert fe.add_odometry(T0 + 100 * MS, [0.02, 0, 0])[0] == 'conflicting'
    assert fe.add_odometry(T0 + 50 * MS, [0.02, 0, 0])[0] == 'backward'
    assert fe.add_odometry(T0 + 150 * MS, [0.015, 0, 0])[0] == 'accepted'
    assert fe.add_odometry(T0 + 200 * MS, [np.nan, 0, 0])[0] == 'invalid'
    (step,) = fe.add_features(corners(T0 + 125 * MS))
    np.testing.assert_allclose(step.odometry, [0.0125, 0, 0], atol=1e-15)
    assert fe.restarts == 0
    assert fe.add_odometry(T0 - 2000 * MS, [5.0, 0, 0])[0] == 'far_back'
    assert fe.add_odometry(T0 - 1990 * MS, [5.0, 0, 0])[0] == 'far_back'
    assert fe.add_odometry(T0 - 1980 * MS, [5.0, 0, 0])[0] == 'restart'
    assert fe.restarts == 1 and fe.slam.num_landmarks == 0
    np.testing.assert_allclose(fe.slam.pose, [5.0, 0, 0])


def test_sets_wait_for_their_last_beam_and_order_does_not_matter():
    """Same steps whether corners come before or after the odometry that covers them."""
    rng = np.random.default_rng(3)
    odo = [(T0 + k * 100 * MS, [0.03 * k, 0.01 * k * k / 20, 0.02 * k]) for k in range(30)]
    sets = [corners(T0 + 50 * MS + k * 100 * MS, rng.uniform(1, 4, (4, 2)),
                    beam_time=rng.uniform(0, 0.08, 4)) for k in range(25)]

    def run(corners_first):
        fe = SlamFrontend(SlamParams(odometry=ODOMETRY_NOISE_MODELS['pioneer']))
        out = []
        if corners_first:
            fe.add_odometry(*odo[0])
            for c in sets:
                out += fe.add_features(c)
            for o in odo[1:]:
                out += fe.add_odometry(*o)[1]
        else:
            for o in odo:
                out += fe.add_odometry(*o)[1]
            for c in sets:
                out += fe.add_features(c)
        return np.array([s.odometry for s in out]), fe.slam.state

    a_odo, a_state = run(True)
    b_odo, b_state = run(False)
    assert len(a_odo) == 25
    np.testing.assert_array_equal(a_odo, b_odo)
    np.testing.assert_array_equal(a_state, b_state)


def test_deskew_moves_corners_by_the_motion_during_the_sweep():
    """A corner seen 0.1 s after the stamp while driving at 1 m/s is 0.1 m further ahead."""
    prm = SlamParams(confirm_hits=1, confirm_window=1)
    out = {}
    for deskew in (True, False):
        fe = SlamFrontend(prm, frontend=FrontendParams(deskew=deskew))
        fe.add_odometry(T0, [0, 0, 0])
        fe.add_odometry(T0 + 200 * MS, [0.2, 0, 0])
        fe.add_features(corners(T0, [(2.0, 0.5)], beam_time=[0.1]))
        out[deskew] = fe.slam.landmarks[0]
    np.testing.assert_allclose(out[True] - out[False], [0.1, 0.0], atol=1e-12)


def test_a_set_waits_until_the_odometry_covers_its_last_beam_then_flush_holds():
    fe = SlamFrontend()
    fe.add_odometry(T0, [0, 0, 0])
    fe.add_odometry(T0 + 100 * MS, [0.1, 0, 0])
    assert fe.add_features(corners(T0 + 80 * MS, beam_time=[0.05])) == []  # needs 130 ms
    assert [t for t, _ in fe.pending] == [T0 + 80 * MS]
    (step,) = fe.flush()  # odometry stopped: last pose held for the late beam
    assert fe.events['held'] == 1 and not fe.pending
    np.testing.assert_allclose(step.odometry, [0.08, 0, 0], atol=1e-12)


def test_corners_stamped_before_the_first_odometry_have_no_pose_and_are_not_processed():
    """As a tf message filter (slam_toolbox, AMCL): no odometry at the stamp, no step.

    Whether the robot stands or moves at the start does not matter, nor how long before.
    """
    for second in ([0, 0, 0], [0.01, 0, 0]):
        fe = SlamFrontend()
        fe.add_features(corners(T0 - 4000 * MS))
        fe.add_features(corners(T0 - 10 * MS))
        fe.add_features(corners(T0))
        kind, steps = fe.add_odometry(T0, [0, 0, 0])
        assert kind == 'accepted' and [s.stamp_ns for s in steps] == [T0]
        assert fe.events['before_odometry'] == 2 and not fe.pending
        np.testing.assert_array_equal(steps[0].odometry, [0, 0, 0])
        fe.add_odometry(T0 + 100 * MS, second)
        assert fe.add_features(corners(T0 - 5 * MS)) == []  # came late: no pose either
        assert fe.events['before_odometry'] == 3 and fe.events['out_of_order'] == 0
        (step,) = fe.add_features(corners(T0 + 50 * MS))
        np.testing.assert_allclose(step.odometry, np.array(second) / 2, atol=1e-12)
        assert fe.events['processed'] == 2


def test_start_race_of_the_live_pipeline():
    """The live soak's start: the laser path is slower than /odom.

    The first six sets came after the first odometry, stamped 126..1 ms before it: not
    processed (before_odometry), and the later ones give the same filter as if the six had
    never come.
    """
    prm = SlamParams(confirm_hits=1, confirm_window=1)
    first = T0 + 439 * MS
    stamps = [T0 + 313 * MS + k * 25 * MS for k in range(8)]  # 313 .. 488 ms, 40 Hz
    ref = SlamFrontend(prm)  # only the sets the odometry covers
    ref.add_odometry(first, [0, 0, 0])
    fe = SlamFrontend(prm)
    fe.add_odometry(first, [0, 0, 0])
    steps = []
    for t in stamps:
        steps += fe.add_features(corners(t, beam_time=[0.0125]))
        if t >= first:
            ref.add_features(corners(t, beam_time=[0.0125]))
    assert steps == [] and fe.events['before_odometry'] == 6 and len(fe.pending) == 2
    steps += fe.add_odometry(first + 100 * MS, [0, 0, 0])[1]
    ref.add_odometry(first + 100 * MS, [0, 0, 0])
    assert [s.stamp_ns for s in steps] == stamps[6:] and fe.events['out_of_order'] == 0
    np.testing.assert_array_equal(fe.slam.landmarks, ref.slam.landmarks)
    np.testing.assert_array_equal(fe.slam.pose, ref.slam.pose)


def test_sets_wait_for_odometry_that_starts_seconds_after_the_laser():
    """The 10-minute soak: the base's first odometry came 3.1 s after the first scan.

    The front end has no time bound on the wait (the node bounds it by memory): every set
    the odometry covers is processed, however late the odometry comes, even when its
    first sample is older than sets already waiting (delivered late).
    """
    fe = SlamFrontend()
    sets = [T0 - 3100 * MS + k * 25 * MS for k in range(204)]  # 3.1 s before to 2 s after
    for t in sets:
        assert fe.add_features(corners(t)) == []
    size = corners(T0).nbytes
    assert len(fe.pending) == 204 and fe.pending_bytes == 204 * size
    steps = []
    for k in range(22):  # 0 .. 2.1 s, all delivered now
        steps += fe.add_odometry(T0 + k * 100 * MS, [0.01 * k, 0, 0])[1]
    after = [t for t in sets if t >= T0]
    assert [s.stamp_ns for s in steps] == after and len(after) == 80
    assert fe.events['before_odometry'] == 124 and fe.events['processed'] == 80
    assert not fe.pending and fe.pending_bytes == 0


def test_corners_nbytes_counts_the_arrays_and_the_scan():
    c = corners(T0, [(2.0, 1.0), (3.0, 0.5)])
    arrays = 2 * 2 * 8 + 2 * 4 * 8 + 3 * 2 * 8  # positions, covariances, 3 vectors
    assert c.nbytes == arrays + 1024
    scan = SimpleNamespace(ranges=np.zeros(1081))
    with_scan = Corners(T0, c.positions, c.covariances, c.bisector, c.opening, c.beam_time,
                        scan=scan)
    assert with_scan.nbytes == arrays + 1081 * 8 + 1024


def test_frontend_params_are_validated():
    with pytest.raises(ValueError, match='max_speed'):
        FrontendParams(max_speed=0.0)
    with pytest.raises(ValueError, match='deskew'):
        FrontendParams(deskew=1)
    with pytest.raises(ValueError, match='laser_mount'):
        SlamFrontend(laser_mount=[0, 0, np.nan])


def test_steps_made_at_once_carry_their_own_pose():
    """Sets released together (after an /odom gap) each report the pose of their step."""
    seen = []
    fe = SlamFrontend(on_step=lambda st: seen.append(st.slam.pose))
    fe.add_odometry(T0, [0, 0, 0])
    for k in (1, 2, 3):
        assert fe.add_features(corners(T0 + k * 100 * MS)) == []
    _, steps = fe.add_odometry(T0 + 400 * MS, [0.4, 0, 0])
    assert [s.stamp_ns for s in steps] == [T0 + k * 100 * MS for k in (1, 2, 3)]
    np.testing.assert_allclose([s.pose[0] for s in steps], [0.1, 0.2, 0.3], atol=1e-12)
    np.testing.assert_array_equal(np.array([s.pose for s in steps]), np.array(seen))


def test_the_odometry_buffer_is_bounded_without_feature_sets():
    fe = SlamFrontend(frontend=FrontendParams(buffer_s=1.0))
    for k in range(500):  # 50 s at 10 Hz, no scan
        fe.add_odometry(T0 + k * 100 * MS, [0.01 * k, 0, 0])
    first, last = fe.odometry_span
    assert last == T0 + 499 * 100 * MS and last - first <= 1100 * MS
    assert fe.add_features(corners(T0 + 10_000 * MS)) == []  # older than the buffer
    assert fe.events['out_of_order'] == 1
    (step,) = fe.add_features(corners(T0 + 49_850 * MS))
    np.testing.assert_allclose(step.odometry, [4.985, 0, 0], atol=1e-9)


def test_lines_wait_for_their_beams_and_are_deskewed():
    """A set's lines go to the filter, moved by the odometry up to their middle beam."""
    seg = SimpleNamespace(rho=2.0, alpha=0.0, start=np.array([2.0, -1.0]),
                          end=np.array([2.0, 1.0]), num_points=50, rmse=0.005,
                          covariance=np.diag([1e-4, 1e-4]), first_index=100, last_index=300)
    fe = SlamFrontend(SlamParams(odometry=ODOMETRY_NOISE_MODELS['pioneer'], confirm_hits=1,
                                 confirm_window=1))
    seen = []
    fe.add_odometry(T0, [0, 0, 0])
    real = fe.slam.update
    fe.slam.update = lambda z, r, d, lines=None, scan=None: (
        seen.append(lines), real(z, r, d, lines=lines, scan=scan))[1]
    c = Corners.from_corners(T0, [], 1e-4, [seg])  # middle beam 200: 20 ms after the stamp
    assert c.line_beam_time.tolist() == [0.02]
    fe.add_odometry(T0 + 10 * MS, [0.01, 0, 0])
    assert fe.add_features(c) == [] and len(fe.pending) == 1  # odometry ends before 20 ms
    steps = fe.add_odometry(T0 + 40 * MS, [0.04, 0, 0])[1]
    assert len(steps) == 1 and len(seen) == 1 and len(seen[0]) == 1
    # At the middle beam the base was 2 cm further on: seen from the stamp's pose, the wall
    # measured 2 m away then is 2.02 m away.
    motion = np.array([[0.02, 0.0, 0.0]])
    np.testing.assert_allclose(seen[0].z, lines_to_observations([seg], (0, 0, 0), motion).z,
                               atol=1e-12)
    assert seen[0].z[0, 0] == pytest.approx(2.02, abs=1e-12)
    assert fe.slam.num_landmarks == 1  # a line landmark
