"""Recovery after a common heading error (``SlamParams.recovery_probability``, issue 14).

The belgioioso failure of README.md at commit 67eb6cc ("Recovery") in miniature: corners are mapped
from the origin, then the heading becomes uncertain (std 5 deg) while the robot in truth turned by
13 deg (2.6 sigma). Seen from the true pose, every corner's bearing is off by the same
13 deg: each pair alone lies outside the 95 % gate (d2 about 6.7 > 5.99), so nothing is
matched; at the recovery's 99 % gate (9.21) each is admitted, and JCBB's joint test keeps
only the pairs that one pose explains.
"""

import math

from landmark_nav.geometry import inverse_transform_points
from landmark_nav.slam import EkfSlam, SlamParams
from landmark_nav.slam.consistency import chi2_gate
import numpy as np
import pytest

R1 = np.diag([0.01 ** 2, math.radians(0.3) ** 2])
MAPPED = np.array([[5.0, 0.0], [0.0, 5.0], [-5.0, 0.5], [0.5, -5.0]])
TURN = math.radians(13.0)


def observe(pose, points):
    """Exact range-bearing of world points from a pose."""
    p = inverse_transform_points(pose, points)
    return np.column_stack([np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])])


def turned_filter(**kw):
    """Map the corners from the origin, then a heading std of 5 deg (no motion)."""
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1, prune_misses=0, **kw))
    slam.update(observe(np.zeros(3), MAPPED), np.repeat(R1[None], len(MAPPED), axis=0))
    assert slam.num_landmarks == len(MAPPED)
    slam.predict(np.zeros(3), np.diag([1e-6, 1e-6, math.radians(5.0) ** 2]))
    return slam


def seen_after_turn(n):
    """Observations of the first n corners from the true pose (turned by TURN)."""
    return observe(np.array([0.0, 0.0, TURN]), MAPPED[:n]), np.repeat(R1[None], n, axis=0)


def test_every_pair_outside_the_gate_without_recovery():
    """Each pair alone fails the 95 % gate: nothing matched, nothing mapped, no update."""
    slam = turned_filter()
    res = slam.update(*seen_after_turn(3))
    assert res.status.tolist() == ['rejected'] * 3
    assert res.reason.tolist() == ['ambiguous'] * 3
    assert slam.pose[2] == pytest.approx(0.0, abs=1e-12)
    assert slam.num_landmarks == len(MAPPED) and slam.stats['recovered'] == 0


def test_joint_test_recovers_the_heading():
    """With recovery at 0.99 the three pairs are matched and the heading corrected."""
    slam = turned_filter(recovery_probability=0.99)
    res = slam.update(*seen_after_turn(3))
    assert res.status.tolist() == ['matched'] * 3
    assert res.landmark_id.tolist() == [0, 1, 2]
    assert np.all(res.d2 > chi2_gate(2, 0.95)) and np.all(res.d2 < chi2_gate(2, 0.99))
    assert slam.pose[2] == pytest.approx(TURN, abs=math.radians(0.5))
    assert slam.stats['recovered'] == 1


def test_too_few_pairs_are_not_a_recovery():
    """Two pairs do not make the default three; with recovery_pairs 2 they do."""
    slam = turned_filter(recovery_probability=0.99)
    res = slam.update(*seen_after_turn(2))
    assert res.status.tolist() == ['rejected'] * 2 and slam.stats['recovered'] == 0
    slam = turned_filter(recovery_probability=0.99, recovery_pairs=2)
    res = slam.update(*seen_after_turn(2))
    assert res.status.tolist() == ['matched'] * 2 and slam.stats['recovered'] == 1


def test_joint_test_leaves_out_a_pair_of_another_pose():
    """A fourth corner seen as from a turn of -13 deg: inside the 99 % gate alone, not jointly."""
    z, r = seen_after_turn(3)
    odd = observe(np.array([0.0, 0.0, -TURN]), MAPPED[3:])
    slam = turned_filter(recovery_probability=0.99)
    res = slam.update(np.vstack([z, odd]), np.repeat(R1[None], 4, axis=0))
    assert res.status[:3].tolist() == ['matched'] * 3 and res.status[3] != 'matched'
    assert slam.pose[2] == pytest.approx(TURN, abs=math.radians(0.5))


def test_joint_hypothesis_too_small_is_not_a_recovery():
    """Two pairs of one pose and one of another: JCBB pairs two, fewer than three."""
    z, r = seen_after_turn(2)
    odd = observe(np.array([0.0, 0.0, -TURN]), MAPPED[2:3])
    slam = turned_filter(recovery_probability=0.99)
    res = slam.update(np.vstack([z, odd]), np.repeat(R1[None], 3, axis=0))
    assert 'matched' not in res.status.tolist() and slam.stats['recovered'] == 0
    assert slam.pose[2] == pytest.approx(0.0, abs=1e-12)


def test_scan_with_a_pair_in_the_gate_is_not_touched():
    """A scan where ICNN pairs anything is left as it is (same state as with it off)."""
    near = observe(np.array([0.0, 0.0, math.radians(2.0)]), MAPPED[:1])
    obs = np.vstack([near, seen_after_turn(3)[0][1:]])  # one pair in the gate, two not
    r = np.repeat(R1[None], 3, axis=0)
    off, on = turned_filter(), turned_filter(recovery_probability=0.99)
    res_off, res_on = off.update(obs, r), on.update(obs, r)
    assert res_off.status[0] == 'matched' and res_off.status.tolist() == res_on.status.tolist()
    assert np.array_equal(off.state, on.state) and on.stats['recovered'] == 0


@pytest.mark.parametrize('kw', [{'recovery_probability': 0.95},
                                {'recovery_probability': 0.9},
                                {'recovery_probability': 1.0},
                                {'recovery_probability': True},
                                {'recovery_probability': '0.99'},
                                {'recovery_probability': 0.999999},
                                {'recovery_pairs': 0}])
def test_bad_recovery_parameters_are_named(kw):
    """Recovery needs a confidence between the two gates and at least one pair."""
    with pytest.raises(ValueError, match=next(iter(kw))):
        SlamParams(**kw)


def test_off_by_default():
    """Default parameters: no recovery."""
    assert SlamParams().recovery_probability is None
