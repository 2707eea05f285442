"""Consistent linearisations of EKF-SLAM: OC-EKF, first-estimates and invariant EKF.

Consistency (unobservable directions)
-------------------------------------
Moving the robot and the whole map together, or turning them together about the map
origin, changes no observation: the global position and heading are unobservable. The EKF's
Jacobians, taken at estimates that change between the prediction and the update, do not
respect this and the filter gains information about the global heading from relative
observations (Huang, Mourikis and Roumeliotis, "Observability-based rules for designing
consistent EKF SLAM estimators", IJRR 2010). With the drift of real odometry (a few degrees
of heading per metre) and corrections of decimetres per scan the effect is large: on the
Carmen logs the filter's heading std fell to 0.5 deg with errors of 3-5 deg (seattle).
``jacobians`` chooses the linearisation (``'standard'``, the chapter's, is the default):

* ``'observability'``: the prediction's ``J1`` takes its lever arm from the previous prior
  position (so the unobservable directions propagate exactly), a new landmark's ``G_r``
  from the current prior position (so it maps the robot's directions onto the landmark's at
  its first estimate, :func:`.map_management.augment_map` ``lever_from``), and the
  covariance update uses ``H* = H (I - N (N^T N)^-1 N^T)``, the Jacobians closest to ``H``
  that map the unobservable directions ``N`` (:func:`unobservable_directions`, taken at the
  robot's prior and at each landmark's estimate when it entered the map) to zero
  (:func:`constrain_jacobians`). The mean update keeps the gain of ``H``. Until the
  augmentation's lever arm was added, each new landmark brought heading information with
  it (``N^T P^-1 N`` grew 2e5-fold over 150 scans of seattle), so the figures measured
  with this option before then were of a filter still overconfident in heading.
* ``'observability_gain'``: the same with the mean update's gain from ``H*`` too (Huang et
  al.'s OC-EKF; the correction is then ``P^-1``-orthogonal to ``N``).
* ``'first_estimates'``: gain and covariance from ``H`` taken at the robot's prior position
  and each landmark's first estimate (Huang et al.'s FEJ-EKF), lever arms as above.
* ``'invariant'``: the chapter's Jacobians with the right-invariant EKF's update (Barrau and
  Bonnabel, arXiv:1510.06263): the correction applied on SE(2)
  (:func:`invariant_retraction`) and the covariance carried to the updated estimate
  (:func:`invariant_transport`); its unobservable directions follow the current estimate,
  no first estimates.

With ``'observability_gain'`` and ``'first_estimates'`` the association (gate, joint check,
JCBB) tests each innovation with the covariance of the update it admits to, from the same
Jacobians as the gain (:func:`.gating.do_data_association` ``nullspace`` / ``jacobian_state``).
The chapter's ``H`` at the current estimates stops annihilating ``N`` (taken at the first
estimates) once a landmark has moved, so ``H P H^T`` carried the global-heading uncertainty
these filters keep into the gate: on acapulco (perfect odometry) single pairs entered with
an update NIS of 805 and 1698 for 2 dof and turned the map by 14 and 41 deg.

All four keep ``N^T P^-1 N`` unchanged through updates and new landmarks
(``test/test_slam_consistency.py``). On the Carmen logs (benchmarks/bench_slam_real.py diagnose,
six logs, drift seeds 0-1, ``line_residual_factor = 2``; medians over the 12 runs of the
share of steps with the reference inside the 95 % ellipse, the robot NEES median, the
SE(2) ATE and the RPE over 1 m as ratios to the odometry's): standard 10 %, 206, 0.26,
3.2; ``'observability'`` 22 %, 75, 0.81, 17.8 and ``'invariant'`` 20 %, 137, 0.73, 13.0
(the covariance keeps the heading uncertainty, but the mean, corrected with the gain of
``H``, turns along it: whole-run turns of 11-16 deg median); ``'first_estimates'`` 69 %,
6.8, 0.18, 1.8 and ``'observability_gain'`` 74 %, 6.0, 0.18, 1.5 (ellipse >= 80 % on 5
and 6 runs, all three issue targets on 2), better than the standard filter in ellipse
share on all 12 runs and in RPE on 8, but on aces and acapulco far worse (ATE 9-31 m, worse
than the odometry's except on aces seed 1; RPE 0.47-1.4 m), so the default stays
``'standard'``. Measured cause
(README.md at commit 67eb6cc, EKF-SLAM; ``--drift none --filter-noise pioneer``): with the
reference's own
increments as odometry the updates alone turn the whole run by 0.5-16 deg while the
reported heading std is 0.4-5 deg; the map's heading was fixed at scan 2 with 4.8-6 deg of
heading std and no observation can reduce that, so the filter gained information in the
unobservable direction; the odometry model (its NEES over 1 m: 1.6-2.3) and the line noise
with ``line_residual_factor = 2`` fit.
"""

import math
from typing import Optional, Tuple

import numpy as np

from ._linalg import _wrap
from .slam_params import LINE


def _position_slots(kinds: np.ndarray) -> np.ndarray:
    """State indices of the x coordinates of the robot and of every corner."""
    corner = np.flatnonzero(np.asarray(kinds) != LINE)
    return np.concatenate([[0], 3 + 2 * corner]).astype(np.int64)


def invariant_retraction(x: np.ndarray, dx: np.ndarray, kinds: np.ndarray) -> np.ndarray:
    """Apply an EKF correction the right-invariant way: ``exp(xi) X`` on SE_K(2).

    Right-invariant EKF-SLAM (Barrau and Bonnabel, "An EKF-SLAM algorithm with consistency
    properties", arXiv:1510.06263, 2015): the robot's heading and the positions of the
    robot and of every corner form one group element (one rotation, K translations). The
    correction ``dx`` (in the state's own coordinates) is read as ``xi``: the heading part
    ``a = dx_psi`` and ``xi_p = dx_p - a J p`` for each position ``p`` (``J`` the
    90-degree turn), then ``p+ = R(a) p + V(a) xi_p`` with the SE(2) ``V(a) =
    [[sin a, cos a - 1], [1 - cos a, sin a]] / a``: everything turns by ``a`` about the
    map origin, so the correction's rotation is exact. To first order this is ``x + dx``.
    A line ``(rho, alpha)`` is turned by the same rotation, ``rho`` unchanged: additive.

    Args:
        x: (3 + 2N,) state before the correction.
        dx: (3 + 2N,) correction (heading wrapped).
        kinds: (N,) landmark kinds.

    Returns:
        The corrected state (a new array).
    """
    out = x + dx
    a = float(dx[2])
    out[2] = _wrap(x[2] + a)
    if a == 0.0:
        return out
    i = _position_slots(kinds)
    px, py = x[i], x[i + 1]
    xi_x = dx[i] + a * py  # xi_p = dx_p - a J p, J p = (-p_y, p_x)
    xi_y = dx[i + 1] - a * px
    c, s = math.cos(a), math.sin(a)
    if abs(a) > 1e-9:
        v0, v1 = s / a, (1.0 - c) / a
    else:
        v0, v1 = 1.0, 0.5 * a
    out[i] = c * px - s * py + v0 * xi_x - v1 * xi_y
    out[i + 1] = s * px + c * py + v1 * xi_x + v0 * xi_y
    return out


def invariant_transport(p: np.ndarray, x_old: np.ndarray, x_new: np.ndarray,
                        kinds: np.ndarray) -> np.ndarray:
    """Carry the covariance from ``x_old`` to ``x_new`` in the right-invariant error.

    The right-invariant error ``xi`` (:func:`invariant_retraction`) relates to the state's
    error by ``dx = T(x) xi``: the robot's heading error turns every position ``p`` by
    ``J p``. Its unobservable directions are constant in ``xi`` (a turn of the world is
    ``xi_psi`` alone, a shift is the same ``xi_p`` for all positions), and the update's
    Jacobians at ``x_old`` annihilate them there, so the update gains no information on
    them; keeping ``P_xi`` after the estimate moved to ``x_new`` means
    ``P <- M P M^T`` with ``M = T(x_new) T(x_old)^-1 = I + c e_psi^T``,
    ``c = J (p_new - p_old)`` at every position (zero for lines and the heading). The
    standard EKF leaves ``P`` at ``x_old``'s directions while the prediction and later
    updates linearise at ``x_new``: the information it gains on the global heading.

    Args:
        p: (n, n) covariance at ``x_old`` (after the update's ``P - W S W^T``).
        x_old: State the update linearised at.
        x_new: Updated state.
        kinds: (N,) landmark kinds.

    Returns:
        The carried covariance (a new array).
    """
    i = _position_slots(kinds)
    c = np.zeros(p.shape[0])
    c[i] = -(x_new[i + 1] - x_old[i + 1])
    c[i + 1] = x_new[i] - x_old[i]
    row = p[2].copy()
    return p + np.outer(c, row) + np.outer(row, c) + p[2, 2] * np.outer(c, c)


def unobservable_directions(robot_xy: np.ndarray, first: np.ndarray,
                            kind: Optional[np.ndarray] = None) -> np.ndarray:
    """Unobservable directions of ``[x_r, y_r, psi_r, landmark]`` (module docstring).

    Moving the whole map and robot by ``(dx, dy)`` and turning it by ``dtheta`` about the
    map origin changes no observation. Columns: ``x``, ``y``, rotation; rows: the robot
    ``[[1, 0, -y_r], [0, 1, x_r], [0, 0, 1]]``, a corner ``[[1, 0, -y], [0, 1, x]]``, a line
    ``(rho, alpha)`` ``[[cos(alpha), sin(alpha), 0], [0, 0, 1]]``.

    Args:
        robot_xy: (2,) robot position the directions are taken at.
        first: (K, 2) landmark parameters they are taken at.
        kind: Optional (K,) kinds (None: corners).

    Returns:
        (K, 5, 3) directions.
    """
    k = first.shape[0]
    n = np.zeros((k, 5, 3))
    n[:, 0, 0] = n[:, 1, 1] = n[:, 2, 2] = 1.0
    n[:, 0, 2], n[:, 1, 2] = -robot_xy[1], robot_xy[0]
    n[:, 3, 0] = n[:, 4, 1] = 1.0
    n[:, 3, 2], n[:, 4, 2] = -first[:, 1], first[:, 0]
    if kind is not None and np.any(kind == LINE):
        ln = np.flatnonzero(kind == LINE)
        a = first[ln, 1]
        n[ln, 3:] = 0.0
        n[ln, 3, 0], n[ln, 3, 1] = np.cos(a), np.sin(a)
        n[ln, 4, 2] = 1.0
    return n


def constrain_jacobians(hr: np.ndarray, hf: np.ndarray, nullspace: np.ndarray
                        ) -> Tuple[np.ndarray, np.ndarray]:
    """Closest ``[H_r, H_F]`` (Frobenius) with ``[H_r, H_F] N = 0`` (OC-EKF).

    ``H* = H (I - N (N^T N)^-1 N^T)`` per observation.

    Args:
        hr: (K, 2, 3) robot Jacobians.
        hf: (K, 2, 2) landmark Jacobians.
        nullspace: (K, 5, 3) directions ``N`` (:func:`unobservable_directions`).

    Returns:
        ``(H_r*, H_F*)``.
    """
    h = np.concatenate([hr, hf], axis=2)  # (K, 2, 5)
    nt = np.transpose(nullspace, (0, 2, 1))
    hn = h @ nullspace  # (K, 2, 3)
    h = h - hn @ np.linalg.solve(nt @ nullspace, nt)
    return h[:, :, :3], h[:, :, 3:]
