"""Data association: ICNN (eqs. 49-55) and JCBB, incl. a case ICNN gets wrong."""

import math

from landmark_nav.slam import (chi2_gate, EkfSlam, icnn, jcbb, joint_mahalanobis,
                               mahalanobis_table, SlamParams)
from landmark_nav.slam.ekf_slam import reject_ambiguous_pairs
import numpy as np
import pytest

GATE = chi2_gate(2, 0.95)
SIG_PSI = 0.08        # robot heading std [rad], shared by every predicted bearing
SIG_B = 0.002         # bearing noise [rad]
SIG_R = 0.01          # range noise [m]


def test_mahalanobis_table_matches_solve():
    """Closed-form 2 x 2 D2 (eq. 54) equals nu^T S^-1 nu; non-PD S gives inf."""
    rng = np.random.default_rng(0)
    nu = rng.normal(size=(4, 3, 2))
    a = rng.normal(size=(4, 3, 2, 2))
    s = a @ np.transpose(a, (0, 1, 3, 2)) + 0.1 * np.eye(2)
    ref = np.einsum('...i,...i->...', nu, np.linalg.solve(s, nu[..., None])[..., 0])
    assert mahalanobis_table(nu, s) == pytest.approx(ref, rel=1e-10)
    assert mahalanobis_table(np.ones(2), -np.eye(2)) == np.inf


def test_icnn_nearest_compatible_and_one_to_one():
    """Nearest compatible feature per observation (eq. 55); one-to-one is greedy in D2."""
    d2 = np.array([[0.5, 3.0, 9.0],
                   [0.4, 2.0, 9.0],
                   [7.0, 8.0, 9.0]])
    assert icnn(d2, GATE, one_to_one=False).tolist() == [0, 0, -1]
    assert icnn(d2, GATE).tolist() == [1, 0, -1]
    assert icnn(np.zeros((0, 3)), GATE).shape == (0,)
    assert icnn(np.zeros((2, 0)), GATE).tolist() == [-1, -1]


def ambiguous_case():
    """Two features 0.1 rad apart at 5 m; the robot heading is off by SIG_PSI.

    All predicted bearings share the heading error (correlation ~1), so both observations
    are shifted by -SIG_PSI. Individually, observation 1 (bearing 0.02) is closest to
    feature 0 (bearing 0) and observation 0 (bearing -0.08) is still inside the gate of
    feature 1 (bearing 0.1); jointly only the common shift is plausible.
    """
    zhat = np.array([[5.0, 0.0], [5.0, 0.1]])
    z = np.array([[5.0, -0.08], [5.0, 0.02]])
    s_pred = np.zeros((2, 2, 2, 2))
    for a in range(2):
        for b in range(2):
            s_pred[a, 1, b, 1] = SIG_PSI ** 2  # shared heading uncertainty
    r = np.array([np.diag([SIG_R ** 2, SIG_B ** 2])] * 2)
    nu = z[:, None, :] - zhat[None, :, :]
    s = np.array([[s_pred[j, :, j, :] + r[i] for j in range(2)] for i in range(2)])
    return nu, s_pred, r, mahalanobis_table(nu, s)


def test_jcbb_resolves_case_where_icnn_is_wrong():
    """ICNN pairs (0 -> 1, 1 -> 0) (both wrong); JCBB pairs (0 -> 0, 1 -> 1)."""
    nu, s_pred, r, d2 = ambiguous_case()
    assert np.all(d2 < GATE)  # every pair is individually compatible
    assert icnn(d2, GATE).tolist() == [1, 0]
    assert icnn(d2, GATE, one_to_one=False).tolist() == [0, 0]
    hyp, d2_joint, nodes = jcbb(nu, s_pred, r, d2)
    assert hyp.tolist() == [0, 1]
    assert d2_joint == pytest.approx(joint_mahalanobis(nu, s_pred, r, hyp), rel=1e-9)
    assert d2_joint < chi2_gate(4, 0.95)
    assert joint_mahalanobis(nu, s_pred, r, np.array([1, 0])) > 100.0  # crossed: absurd
    assert nodes > 0


def test_jcbb_prefers_more_pairings_and_respects_node_budget():
    """An observation with no compatible feature stays unpaired; the budget is honoured."""
    nu, s_pred, r, d2 = ambiguous_case()
    d2 = np.vstack([d2, [np.inf, np.inf]])
    nu = np.concatenate([nu, np.zeros((1, 2, 2))])
    r = np.concatenate([r, r[:1]])
    hyp, _, nodes = jcbb(nu, s_pred, r, d2)
    assert hyp.tolist() == [0, 1, -1]
    hyp1, _, nodes1 = jcbb(nu, s_pred, r, d2, max_nodes=1)
    assert nodes1 == 1 and hyp1.tolist() == [-1, -1, -1]


def filter_with_two_landmarks(method: str, joint_check: bool = False) -> EkfSlam:
    """Map two landmarks 0.1 rad apart at 5 m, then make the heading uncertain."""
    slam = EkfSlam(SlamParams(association=method, confirm_hits=1, confirm_window=1,
                              r_scale=1.0, range_floor=0.0, bearing_floor=0.0,
                              joint_check=joint_check))
    r = np.array([np.diag([1e-8, 1e-8])] * 2)
    res = slam.update(np.array([[5.0, 0.0], [5.0, 0.1]]), r)
    assert res.status.tolist() == ['confirmed', 'confirmed']
    slam.predict(np.zeros(3), np.diag([1e-10, 1e-10, SIG_PSI ** 2]))
    return slam


@pytest.mark.parametrize('method, expected', [('icnn', [1, 0]), ('jcbb', [0, 1])])
def test_filter_ambiguity_experiment(method, expected):
    """In the filter: the robot actually turned +SIG_PSI; ICNN swaps the ids, JCBB does not.

    ICNN here is the chapter's (``joint_check=False``); the filter's default joint check
    is :func:`test_icnn_joint_check_repairs_the_swap`.
    """
    slam = filter_with_two_landmarks(method)
    r = np.array([np.diag([SIG_R ** 2, SIG_B ** 2])] * 2)
    res = slam.update(np.array([[5.0, -SIG_PSI], [5.0, 0.1 - SIG_PSI]]), r)
    assert res.status.tolist() == ['matched', 'matched']
    assert res.landmark_id.tolist() == expected
    if method == 'jcbb':
        assert slam.pose[2] == pytest.approx(SIG_PSI, abs=0.005)
        assert res.nis < chi2_gate(4, 0.95)
        assert res.jcbb_nodes > 0
    else:
        assert res.nis > chi2_gate(4, 0.999)  # the swapped pairs cannot both be right
    assert math.isfinite(res.nis)


def test_icnn_joint_check_repairs_the_swap():
    """With the default joint check the swapped ICNN pairs (NIS far beyond the gate) go to JCBB."""
    slam = filter_with_two_landmarks('icnn', joint_check=True)
    r = np.array([np.diag([SIG_R ** 2, SIG_B ** 2])] * 2)
    res = slam.update(np.array([[5.0, -SIG_PSI], [5.0, 0.1 - SIG_PSI]]), r)
    assert res.landmark_id.tolist() == [0, 1]
    assert res.jcbb_nodes > 0 and res.nis < chi2_gate(4, 0.95)
    assert slam.pose[2] == pytest.approx(SIG_PSI, abs=0.005)


def test_reject_ambiguous_pairs_mutual_exclusion():
    """A pair survives only when its row and its column hold one gated entry each."""
    d2 = np.array([[0.5, 3.0, 9.0, np.inf],   # obs 0: two landmarks in the gate
                   [9.0, 9.0, 1.0, np.inf],   # obs 1: alone with landmark 2
                   [9.0, 9.0, 9.0, 0.2],      # obs 2: landmark 3, which obs 3 also gates
                   [9.0, 9.0, 9.0, 4.0]])
    hyp = icnn(d2, GATE)
    assert hyp.tolist() == [0, 2, 3, -1]
    assert reject_ambiguous_pairs(hyp, d2, GATE).tolist() == [-1, 2, -1, -1]
    assert hyp.tolist() == [0, 2, 3, -1]  # the input is not changed
    assert reject_ambiguous_pairs(np.full(2, -1), np.zeros((2, 0)), GATE).tolist() == [-1, -1]


def test_filter_rejects_an_ambiguous_corner_without_mapping_it():
    """An observation inside the gates of two corners is rejected with reject_ambiguous.

    Two mapped corners 0.5 m apart along y, robot y std 0.5 m: the observation of one is
    inside both gates. By default ICNN takes the nearest (it moves the robot); with
    reject_ambiguous it is rejected as 'ambiguous', no landmark is added and P is the
    predicted one.
    """
    base = {'confirm_hits': 1, 'confirm_window': 1, 'min_view_margin': 0.0,
            'position_floor': 0.0}
    r = np.repeat(np.diag([1e-4, 1e-6])[None], 2, axis=0)
    out = {}
    for flag in (False, True):
        slam = EkfSlam(SlamParams(reject_ambiguous=flag, **base))
        slam.update(np.array([[3.0, 0.0], [math.hypot(3.0, 0.5), math.atan2(0.5, 3.0)]]), r)
        slam.predict(np.zeros(3), np.diag([1e-4, 0.25, 1e-8]))
        p_pred = slam.covariance.copy()
        res = slam.update(np.array([[math.hypot(3.0, 0.25), math.atan2(0.25, 3.0)]]), r[:1])
        out[flag] = (res, slam, p_pred)
    res, slam, _ = out[False]
    assert res.status[0] == 'matched'
    res, slam, p_pred = out[True]
    assert (res.status[0], res.reason[0]) == ('rejected', 'ambiguous')
    assert slam.num_landmarks == 2 and np.array_equal(slam.covariance, p_pred)
