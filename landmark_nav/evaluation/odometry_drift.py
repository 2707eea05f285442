"""Odometry drift against the ground truth of a bag: the drift table of docs/ekf_slam.md.

:func:`bag_odometry_drift` reads ``/odom`` and ``/ground_truth/odom`` of a bag (no DDS),
pairs the samples that share a stamp and scores them with :func:`odometry_drift`: path
length, final and largest position / heading errors, the final error as a share of the
distance travelled, and the errors at 25 / 50 / 75 / 100 % of the path
(``landmark_nav demo`` prints them and writes ``drift.json``).

:func:`odometry_window_nees` checks an odometry noise model against the truth: the 3-dof
NEES (corner chapter eq. 59) of the odometry's relative motion over windows of a given
path length, with the model's increment covariance ``U`` propagated along each window
(eqs. 26-30) from zero at its start.
"""

from typing import Callable, Tuple

from landmark_nav.bag import BagReader
from landmark_nav.evaluation.bags import read_track
from landmark_nav.geometry import compose, compose_jacobians, relative, wrap_angle
import numpy as np


def read_poses(bag_dir, topic: str) -> Tuple[np.ndarray, np.ndarray]:
    """Return (stamps_ns (N,), poses (N, 3)) of an Odometry topic.

    Raises:
        ValueError: No message on ``topic``.
    """
    with BagReader(bag_dir) as reader:
        stamps, poses = read_track(reader, topic)
    if not stamps.size:
        raise ValueError(f'{bag_dir} has no messages on {topic}')
    return stamps, poses


def odometry_drift(truth: np.ndarray, odom: np.ndarray) -> dict:
    """Drift figures of odometry vs truth sampled at the same stamps (both (N, 3)).

    The odometry frame coincides with the world at the first sample, so errors are plain
    differences; heading errors are wrapped.
    """
    steps = np.linalg.norm(np.diff(truth[:, :2], axis=0), axis=1)
    travelled = np.concatenate([[0.0], np.cumsum(steps)])
    pos_err = np.linalg.norm(odom[:, :2] - truth[:, :2], axis=1)
    yaw_err = np.abs(wrap_angle(odom[:, 2] - truth[:, 2]))
    at = {}
    for frac in (0.25, 0.5, 0.75, 1.0):
        i = int(np.searchsorted(travelled, frac * travelled[-1]))
        i = min(i, len(travelled) - 1)
        at[f'{int(frac * 100)}%'] = {'distance_m': float(travelled[i]),
                                     'position_error_m': float(pos_err[i]),
                                     'heading_error_deg': float(np.degrees(yaw_err[i]))}
    return {
        'path_length_m': float(travelled[-1]),
        'final_position_error_m': float(pos_err[-1]),
        'final_heading_error_deg': float(np.degrees(yaw_err[-1])),
        'max_position_error_m': float(pos_err.max()),
        'max_heading_error_deg': float(np.degrees(yaw_err.max())),
        'final_error_percent_of_distance': float(100.0 * pos_err[-1] / max(travelled[-1], 1e-9)),
        'along_path': at,
        'position_error_m': pos_err,
    }


def bag_odometry_drift(bag) -> Tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Score a bag's ``/odom`` against its ``/ground_truth/odom`` on their shared stamps.

    Returns:
        (shared stamps [ns], truth (N, 3), odometry (N, 3), :func:`odometry_drift` figures).

    Raises:
        ValueError: A topic without messages, or fewer than 2 shared stamps.
    """
    t_truth, truth = read_poses(bag, '/ground_truth/odom')
    t_odom, odom = read_poses(bag, '/odom')
    common, i_truth, i_odom = np.intersect1d(t_truth, t_odom, return_indices=True)
    if len(common) < 2:
        raise ValueError(f'{bag}: /odom and /ground_truth/odom share fewer than 2 stamps')
    truth, odom = truth[i_truth], odom[i_odom]
    return common, truth, odom, odometry_drift(truth, odom)


__all__ = ['bag_odometry_drift', 'odometry_drift', 'read_poses']


def odometry_window_nees(truth: np.ndarray, odom: np.ndarray,
                         increment_covariance: Callable[[np.ndarray], np.ndarray],
                         horizon: float = 1.0) -> np.ndarray:
    """NEES of the odometry over consecutive windows of ``horizon`` metres of true path.

    For a window from sample ``i`` to ``j`` the odometry's motion ``odom_i^-1 (+) odom_j``
    (eq. 13) is composed increment by increment from the identity at ``odom_i``, its
    covariance propagated as the filter's prediction does it, ``P <- J1 P J1^T + J2 U J2^T``
    (eqs. 26-30, ``U = increment_covariance(u)``). That covariance lives in the frame of the
    window's start, so the error is taken there too: the difference of the two relative
    poses (positions in the start frame, heading wrapped), not the error expressed in the
    end frame (which differs from it by the rotation turned in the window, and would make
    the NEES of a turning window meaningless).

    Args:
        truth: (N, 3) true poses.
        odom: (N, 3) odometry poses at the same stamps.
        increment_covariance: ``U`` of one (3,) increment, e.g.
            ``lambda u: ekf_slam.odometry_noise(u, noise)``.
        horizon: Window length in metres of true path (> 0); ``inf``: one window over the
            whole track.

    Returns:
        (W,) NEES per window (3 expected for a consistent model); empty if the track is
        shorter than one window.
    """
    truth = np.asarray(truth, dtype=float).reshape(-1, 3)
    odom = np.asarray(odom, dtype=float).reshape(-1, 3)
    if truth.shape != odom.shape:
        raise ValueError(f'truth {truth.shape} and odom {odom.shape} differ')
    if not horizon > 0.0:
        raise ValueError(f'horizon must be > 0, got {horizon}')
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(truth[:, :2], axis=0).T))])
    out = []
    i = 0
    while i < len(truth) - 1:
        j = len(truth) - 1 if np.isinf(horizon) else int(np.searchsorted(s, s[i] + horizon))
        if j >= len(truth):
            break
        cov, x = np.zeros((3, 3)), np.zeros(3)
        for k in range(i, j):
            u = relative(odom[k], odom[k + 1])
            j1, j2 = compose_jacobians(x, u)
            cov = j1 @ cov @ j1.T + j2 @ increment_covariance(u) @ j2.T  # eq. 26
            x = compose(x, u)
        e = x - relative(truth[i], truth[j])
        e[2] = wrap_angle(e[2])
        out.append(float(e @ np.linalg.solve(cov, e)))
        i = j
    return np.array(out)
