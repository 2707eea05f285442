"""Cartesian (map-frame) gate of corner pairs with a wide range prediction (issue 14).

``SlamParams.cartesian_gate`` / :func:`landmark_nav.slam.gating.cartesian_pair_d2`: the
aces failure of README.md at commit 67eb6cc ("What goes wrong on aces and acapulco") in miniature:
a landmark 22 m ahead whose predicted range has a std of 40 % of the range, and a corner seen 3 m
away at a bearing of 0.5 rad.
"""

import math

from landmark_nav.slam import chi2_gate, gating, SlamParams
from landmark_nav.slam.ekf_slam import (cartesian_pair_d2, do_data_association,
                                        feature_initialization)
from landmark_nav.slam.line_landmarks import line_observation_model
import numpy as np
import pytest

GATE = chi2_gate(2, 0.95)
R = np.diag([0.02 ** 2, 0.01 ** 2])[None]


def _wide_prior():
    """Robot position std 12 x 3 m (major axis at 135 deg), heading 0.3 rad; landmark 22 m."""
    c, s = math.cos(3 * math.pi / 4), math.sin(3 * math.pi / 4)
    rot = np.array([[c, -s], [s, c]])
    p = np.zeros((5, 5))
    p[:2, :2] = rot @ np.diag([12.0 ** 2, 3.0 ** 2]) @ rot.T
    p[2, 2] = 0.3 ** 2
    p[3:, 3:] = 0.1 ** 2 * np.eye(2)
    return np.array([0.0, 0.0, 0.0, 22.0, 0.0]), p


def _d2_by_hand(x, p, z, r):
    """``e = g(x_r, psi_r, z) - x_i`` with ``A P A^T + G_z R G_z^T`` written out."""
    a = z[1] + x[2]
    g = x[:2] + z[0] * np.array([math.cos(a), math.sin(a)])
    big_a = np.array([[1.0, 0.0, -z[0] * math.sin(a), -1.0, 0.0],
                      [0.0, 1.0, z[0] * math.cos(a), 0.0, -1.0]])
    gz = np.array([[math.cos(a), -z[0] * math.sin(a)], [math.sin(a), z[0] * math.cos(a)]])
    e = g - x[3:5]
    return e @ np.linalg.solve(big_a @ p @ big_a.T + gz @ r @ gz.T, e)


def test_cartesian_pair_d2_matches_the_map_frame_test():
    """The function is the observation put in the map (eq. 40) against the landmark."""
    x, p = _wide_prior()
    z = np.array([[3.0, 0.5], [21.0, -0.1]])
    r = np.concatenate([R, 2.0 * R])
    got = cartesian_pair_d2(x, p, z, r, np.array([0, 0]))
    assert got == pytest.approx([_d2_by_hand(x, p, z[k], r[k]) for k in range(2)], rel=1e-9)
    g = feature_initialization(x[:3], z[:1])[0][0]
    assert g == pytest.approx([3.0 * math.cos(0.5), 3.0 * math.sin(0.5)])


def test_linear_gate_admits_the_far_pair_the_cartesian_gate_rejects():
    """Range std 40 % of the range: range-bearing d2 5.3 (< 5.99), map frame 19.3."""
    x, p = _wide_prior()
    z = np.array([[3.0, 0.5]])
    hyp, d2, _ = do_data_association(x, p, z, R)
    assert hyp.tolist() == [0] and d2[0, 0] == pytest.approx(5.27, abs=0.01)
    d2_map = cartesian_pair_d2(x, p, z, R, np.array([0]))[0]
    assert d2_map == pytest.approx(19.27, abs=0.01) and d2_map > GATE
    for ratio in (0.0, 0.3):  # the predicted range std is 0.40 of the range
        hyp, d2c, _ = do_data_association(x, p, z, R, cartesian_ratio=ratio)
        assert hyp.tolist() == [-1] and d2c[0, 0] == pytest.approx(d2_map)
    hyp, d2c, _ = do_data_association(x, p, z, R, cartesian_ratio=0.5)  # not tested
    assert hyp.tolist() == [0] and d2c[0, 0] == d2[0, 0]


def test_an_ordinary_pair_passes_both_gates_alike():
    """Precise prior, observation near its prediction: both tests agree to a few %."""
    x = np.array([1.0, 2.0, 0.3, 5.0, 3.5])
    p = np.diag([0.05 ** 2, 0.05 ** 2, 0.02 ** 2, 0.03 ** 2, 0.03 ** 2])
    p[0, 3] = p[3, 0] = p[1, 4] = p[4, 1] = 0.5 * 0.05 * 0.03
    dx, dy = x[3] - x[0], x[4] - x[1]
    z = np.array([[math.hypot(dx, dy) + 0.04, math.atan2(dy, dx) - x[2] - 0.01]])
    hyp, d2, _ = do_data_association(x, p, z, R)
    hyp_c, d2_c, _ = do_data_association(x, p, z, R, cartesian_ratio=0.0)
    assert hyp.tolist() == hyp_c.tolist() == [0]
    assert d2[0, 0] < GATE and d2_c[0, 0] < GATE
    assert d2_c[0, 0] == pytest.approx(d2[0, 0], rel=0.05)
    assert d2_c[0, 0] >= d2[0, 0]  # the larger of the two


def test_line_pairs_inside_the_gate_are_untouched(monkeypatch):
    """Only corner pairs are tested again: a line pair inside the gate keeps its d2.

    The state holds the far corner landmark and a line landmark (the wall x = 6 m) under
    the same wide prior; the corner seen 3 m away gets its map-frame d2, the line seen
    near its prediction keeps its range-bearing d2 (below the gate).
    """
    x, p = _wide_prior()
    x = np.concatenate([x, [6.0, 0.0]])
    p = np.pad(p, ((0, 2), (0, 2)))
    p[5, 5], p[6, 6] = 0.05 ** 2, 0.01 ** 2
    zl = line_observation_model(x[:3], x[5:][None])[0][0] + np.array([0.3, 0.05])
    z = np.array([[3.0, 0.5], zl])
    r = np.concatenate([R, R])
    kinds = {'obs_kind': np.array([0, 1], np.int8), 'lm_kind': np.array([0, 1], np.int8)}
    hyp, d2, _ = do_data_association(x, p, z, r, **kinds)
    tested = []

    def spy(x_, p_, z_, r_, index):
        tested.append((z_.tolist(), index.tolist()))
        return cartesian_pair_d2(x_, p_, z_, r_, index)

    monkeypatch.setattr(gating, 'cartesian_pair_d2', spy)  # where it is looked up
    hyp_c, d2_c, _ = do_data_association(x, p, z, r, cartesian_ratio=0.0, **kinds)
    assert tested == [([[3.0, 0.5]], [0])]  # the corner pair only
    assert hyp.tolist() == [0, 1] and hyp_c.tolist() == [-1, 1]
    assert d2[1, 1] < GATE and d2_c[1, 1] == d2[1, 1]
    assert d2_c[0, 0] > GATE > d2[0, 0]  # the corner pair was tested again
    assert np.isinf(d2[0, 1]) and np.isinf(d2[1, 0])  # kinds never pair across


def test_param_default_off_and_validated():
    """Off by default; a negative or non-finite ratio is refused."""
    assert SlamParams().cartesian_gate is None
    assert SlamParams(cartesian_gate=0.0).cartesian_gate == 0.0
    for bad in (-0.1, math.inf, 'x'):
        with pytest.raises(ValueError, match='cartesian_gate'):
            SlamParams(cartesian_gate=bad)
