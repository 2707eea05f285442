"""EkfSlam behaviour: ghost protection, landmark cap, bad inputs, PSD guard, reset."""

import math

from landmark_nav.geometry import compose, inverse_transform_points
from landmark_nav.slam import (EkfSlam, odometry_check, odometry_increment, OdometryNoise,
                               SlamParams)
import numpy as np
import pytest

LANDMARKS = np.array([[3.0, 1.0], [4.0, -2.0], [2.0, 3.0], [5.0, 0.5]])
R1 = np.diag([0.01 ** 2, math.radians(0.3) ** 2])


def observe(pose: np.ndarray, points: np.ndarray, rng=None) -> np.ndarray:
    """Range-bearing of world points from a robot pose (optionally noisy)."""
    p = inverse_transform_points(pose, points)
    z = np.column_stack([np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])])
    if rng is not None:
        z += rng.normal(0.0, [0.01, math.radians(0.3)], z.shape)
    return z


def rs(m: int) -> np.ndarray:
    """Return m copies of R1."""
    return np.repeat(R1[None], m, axis=0)


def assert_sym_psd(p: np.ndarray) -> None:
    """P is exactly symmetric and has no negative eigenvalue beyond rounding."""
    assert np.array_equal(p, p.T)
    w = np.linalg.eigvalsh(p)
    assert w.min() >= -1e-12 * max(1.0, w.max())


def test_ghost_never_enters_map_and_real_corner_does_after_n():
    """A one-off corner is dropped after the window; a real one is mapped at its N-th sight."""
    prm = SlamParams(confirm_hits=3, confirm_window=5)
    slam = EkfSlam(prm)
    pose = np.zeros(3)
    ghost = np.array([[2.5, -1.5]])
    statuses = []
    for k in range(8):
        pts = LANDMARKS[:1] if k != 2 else np.vstack([LANDMARKS[:1], ghost])
        res = slam.update(observe(pose, pts), rs(len(pts)))
        statuses.append(res.status.tolist())
        slam.predict(np.zeros(3))
    assert statuses[0] == ['new']
    assert statuses[1] == ['tentative']
    assert statuses[2] == ['confirmed', 'new']  # real corner mapped at its 3rd sight
    assert all(s == ['matched'] for s in statuses[3:])
    assert slam.num_landmarks == 1
    assert slam.landmarks[0] == pytest.approx(LANDMARKS[0], abs=1e-9)
    assert slam.candidates == []  # the ghost candidate expired
    assert slam.stats['dropped_candidates'] == 1


def test_sparse_sightings_outside_the_window_are_not_confirmed():
    """N hits spread over more than M scans never confirm a candidate."""
    slam = EkfSlam(SlamParams(confirm_hits=2, confirm_window=3))
    for k in range(9):
        seen = k % 3 == 0  # every third scan: 2 hits never fit in a 3-scan window
        z = observe(np.zeros(3), LANDMARKS[:1]) if seen else np.zeros((0, 2))
        res = slam.update(z, rs(len(z)))
        assert 'confirmed' not in res.status.tolist()
    assert slam.num_landmarks == 0


def test_landmark_cap_and_stable_ids():
    """No more than max_landmarks enter the map; ids never change."""
    slam = EkfSlam(SlamParams(max_landmarks=3, confirm_hits=1, confirm_window=1))
    res = slam.update(observe(np.zeros(3), LANDMARKS), rs(4))
    assert res.status.tolist() == ['confirmed'] * 3 + ['rejected']
    assert res.reason[3] == 'cap'
    assert slam.landmark_ids.tolist() == [0, 1, 2]
    res = slam.update(observe(np.zeros(3), LANDMARKS[::-1]), rs(4))
    assert res.landmark_id.tolist() == [-1, 2, 1, 0]
    assert res.reason[0] == 'cap'
    assert slam.num_landmarks == 3


def test_nan_and_bad_observations_are_rejected_without_touching_the_state():
    """Reject NaN ranges, inf bearings, NaN or non-PD R and zero ranges as 'invalid'."""
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1, max_range=10.0))
    slam.update(observe(np.zeros(3), LANDMARKS), rs(4))
    slam.predict([0.1, 0.0, 0.01])
    x0, p0 = slam.state, slam.covariance
    z = np.array([[np.nan, 0.1], [2.0, np.inf], [3.0, 0.2], [0.0, 0.1], [2.0, 0.5],
                  [12.0, 0.0]])
    r = rs(6)
    r[2, 0, 0] = np.nan
    r[4] = np.diag([1e-4, -1e-4])
    res = slam.update(z, r)
    assert res.status.tolist() == ['rejected'] * 6
    assert res.reason.tolist() == ['invalid'] * 5 + ['range']
    assert np.array_equal(slam.state, x0) and np.array_equal(slam.covariance, p0)
    with pytest.raises(ValueError):
        slam.predict([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError):
        slam.predict([0.0, 0.0, 0.0], np.eye(2))


def test_covariance_stays_symmetric_psd_on_a_long_noisy_run():
    """P symmetric PSD after every prediction and update; the pose stays near the truth."""
    rng = np.random.default_rng(7)
    world = np.array([[math.cos(a) * 4.0, math.sin(a) * 4.0]
                      for a in np.linspace(0, 2 * math.pi, 12, endpoint=False)])
    slam = EkfSlam(SlamParams(odometry=OdometryNoise(0.02, 0.02, 0.05)))
    truth = np.zeros(3)
    odom = np.zeros(3)
    for k in range(300):
        u_true = np.array([0.05, 0.0, 0.04])
        truth = compose(truth, u_true)
        odom_new = compose(odom, u_true + rng.normal(0, [0.002, 0.002, 0.003]))
        slam.predict(odometry_increment(odom, odom_new))
        odom = odom_new
        assert_sym_psd(slam.covariance)
        p = inverse_transform_points(truth, world)
        vis = (np.hypot(p[:, 0], p[:, 1]) < 6.0) & (p[:, 0] > 0)
        res = slam.update(observe(truth, world[vis], rng), rs(int(vis.sum())))
        assert not res.psd_repaired
        assert_sym_psd(slam.covariance)
    assert slam.num_landmarks == 12
    assert np.hypot(*(slam.pose[:2] - truth[:2])) < 0.05
    assert slam.stats['psd_repairs'] == 0


def test_non_psd_covariance_is_repaired_and_counted():
    """A numerically broken P is projected to the PSD cone at the next update."""
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1))
    slam.update(observe(np.zeros(3), LANDMARKS), rs(4))
    slam.predict([0.1, 0.0, 0.0])
    p = slam.covariance
    p[3, 5] = p[5, 3] = 10.0 * math.sqrt(p[3, 3] * p[5, 5])  # correlation 10: not PSD
    slam._p = p  # inject the fault (no public setter on purpose)
    res = slam.update(np.zeros((0, 2)), rs(0))
    assert res.psd_repaired
    assert slam.stats['psd_repairs'] == 1
    assert np.linalg.eigvalsh(slam.covariance).min() >= -1e-12
    res = slam.update(observe(slam.pose, LANDMARKS), rs(4))
    assert not res.psd_repaired and slam.stats['psd_repairs'] == 1


def test_reset_and_odometry_check():
    """reset() clears map, candidates and statistics; the check flags jumps and time travel."""
    slam = EkfSlam(SlamParams(confirm_hits=2), initial_pose=[1.0, 2.0, 0.5])
    slam.update(observe(np.array([1.0, 2.0, 0.5]), LANDMARKS), rs(4))
    assert len(slam.candidates) == 4
    slam.reset()
    assert slam.num_landmarks == 0 and slam.candidates == []
    assert slam.pose == pytest.approx([1.0, 2.0, 0.5])
    assert not slam.covariance.any()
    slam.reset([0.0, 0.0, 0.0])
    assert slam.pose == pytest.approx([0.0, 0.0, 0.0])
    assert odometry_check(0, [0, 0, 0], 100, [0.1, 0.0, 0.1]) is None
    assert 'back in time' in odometry_check(100, [0, 0, 0], 50, [0.1, 0.0, 0.0])
    assert 'jumped' in odometry_check(0, [0, 0, 0], 100, [2.0, 0.0, 0.0])
    assert 'turned' in odometry_check(0, [0, 0, 0], 100, [0.0, 0.0, 2.0])
    assert 'finite' in odometry_check(0, [0, 0, 0], 100, [np.nan, 0.0, 0.0])


def test_descriptor_gate_separates_coincident_corners():
    """Two corners 10 cm apart whose bisectors differ by 57 deg map as two landmarks."""
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1))
    pts = np.array([[5.0, 0.0], [5.0, 0.1]])
    z = observe(np.zeros(3), pts)
    right, left = [[math.pi - 0.5, math.pi / 2]], [[-math.pi + 0.5, math.pi / 2]]
    slam.update(z[:1], rs(1), np.array(right))
    res = slam.update(z[1:], rs(1), np.array(left))
    assert res.status.tolist() == ['confirmed']
    res = slam.update(z, rs(2), np.array(right + left))
    assert res.landmark_id.tolist() == [0, 1]
    # Without descriptors the second corner is too close to be new: ambiguous.
    plain = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1))
    plain.update(z[:1], rs(1))
    res = plain.update(z[1:], rs(1))
    assert res.status.tolist() == ['rejected'] and res.reason.tolist() == ['ambiguous']


def test_grazing_corners_are_rejected():
    """A corner whose line of sight runs almost along one arm is not used."""
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1))
    z = observe(np.zeros(3), np.array([[4.0, 0.0], [4.0, 1.0]]))
    # Concave 90 deg corners: seen 40 deg off the bisector (5 deg margin) and on it.
    desc = np.array([[math.pi + math.radians(40.0), math.pi / 2],
                     [z[1, 1] + math.pi, math.pi / 2]])
    res = slam.update(z, rs(2), desc)
    assert res.status.tolist() == ['rejected', 'confirmed']
    assert res.reason[0] == 'grazing'


def test_parameter_validation():
    """Bad parameters raise ValueError naming the field."""
    with pytest.raises(ValueError, match='association'):
        SlamParams(association='nn')
    with pytest.raises(ValueError, match='confirm_window'):
        SlamParams(confirm_hits=4, confirm_window=3)
    with pytest.raises(ValueError, match='sigma_xy_per_sqrt_m'):
        OdometryNoise(sigma_xy_per_sqrt_m=-1.0)
    with pytest.raises(ValueError, match='gate_probability'):
        SlamParams(gate_probability=1.0)


def test_icnn_jointly_incompatible_batch_goes_to_jcbb():
    """Two pairs that pass one by one but imply opposite robot shifts are not both used."""
    from landmark_nav.slam.ekf_slam import do_data_association
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1))
    pts = np.array([[3.0, 2.0], [3.0, -2.0]])
    slam.update(observe(np.zeros(3), pts), rs(2))
    # A large, purely translational robot uncertainty (0.3 m per axis), no heading error.
    slam.predict(np.zeros(3), np.diag([0.09, 0.09, 1e-12]))
    # Landmark 0 seen 0.3 m farther along x, landmark 1 0.3 m nearer: each within its gate
    # (d2 about 1), jointly impossible (they share the robot's translation).
    z = np.vstack([observe(np.zeros(3), pts[:1] - [0.3, 0.0]),
                   observe(np.zeros(3), pts[1:] + [0.3, 0.0])])
    r = rs(2)
    x, p = slam.state, slam.covariance
    hyp, d2, _ = do_data_association(x, p, z, r, 'icnn', 0.95, 5000, joint_check=False)
    assert hyp.tolist() == [0, 1] and np.all(np.diag(d2) < 5.99)
    hyp, _, nodes = do_data_association(x, p, z, r, 'icnn', 0.95, 5000, joint_check=True)
    assert nodes > 0 and sorted(hyp.tolist()) in ([-1, 0], [-1, 1])
    # The filter (joint_check on by default) updates with one pair only.
    res = slam.update(z, r)
    assert int(np.sum(res.status == 'matched')) == 1
    assert SlamParams().joint_check
