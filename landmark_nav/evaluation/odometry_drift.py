"""Odometry drift against the ground truth of a bag: the README's drift table.

:func:`bag_odometry_drift` reads ``/odom`` and ``/ground_truth/odom`` of a bag (no DDS),
pairs the samples that share a stamp and scores them with :func:`odometry_drift`: path
length, final and largest position / heading errors, the final error as a share of the
distance travelled, and the errors at 25 / 50 / 75 / 100 % of the path
(``landmark_nav demo`` prints them and writes ``drift.json``).
"""

from typing import Tuple

from landmark_nav.bag import BagReader
from landmark_nav.evaluation.bags import read_track
from landmark_nav.geometry import wrap_angle
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
