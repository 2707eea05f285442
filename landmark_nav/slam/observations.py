"""Laser corners to range-bearing observations in base_link (eqs. 18-22).

A corner of :func:`landmark_nav.laser.corners.extract_corners` is a point ``p`` with
covariance ``C`` (2 x 2, m^2) in the laser frame. It is moved to base_link with the laser
mount ``[x, y, yaw]`` (base_link -> laser, see :mod:`landmark_nav.geometry`),
``p_b = R(yaw) p + t``, ``C_b = R(yaw) C R(yaw)^T``, optionally through the robot's motion
during the sweep (``beam_motion``: the base_link pose at each corner's beam time, expressed in
base_link at the scan stamp), and converted to range and bearing (eqs. 19-20 with the robot
at the origin)::

    r = |p_b|,  theta = atan2(y_b, x_b)
    R = J C_b J^T,  J = d(r, theta)/d(x, y) = [[x/r, y/r], [-y/r^2, x/r^2]]
"""

from typing import Optional, Sequence, Tuple

from landmark_nav.geometry import transform_points
import numpy as np


def polar_jacobian(points: np.ndarray) -> np.ndarray:
    """Jacobian of ``(r, theta)`` with respect to ``(x, y)``.

    Args:
        points: (M, 2) Cartesian points (not at the origin).

    Returns:
        (M, 2, 2) Jacobians.
    """
    x, y = points[:, 0], points[:, 1]
    q = x * x + y * y
    r = np.sqrt(q)
    jac = np.empty((points.shape[0], 2, 2))
    jac[:, 0, 0], jac[:, 0, 1] = x / r, y / r
    jac[:, 1, 0], jac[:, 1, 1] = -y / q, x / q
    return jac


def points_to_observations(points: np.ndarray, covariances: np.ndarray
                           ) -> Tuple[np.ndarray, np.ndarray]:
    """Convert base_link points with covariance to range-bearing with propagated ``R``.

    Args:
        points: (M, 2) points in base_link [m].
        covariances: (M, 2, 2) their covariances [m^2].

    Returns:
        ``(z (M, 2) [r (m), theta (rad)], R (M, 2, 2))``.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    c = np.asarray(covariances, dtype=float).reshape(-1, 2, 2)
    z = np.column_stack([np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])])
    jac = polar_jacobian(p)
    r = jac @ c @ np.transpose(jac, (0, 2, 1))
    return z, 0.5 * (r + np.transpose(r, (0, 2, 1)))


def corners_to_observations(corners: Sequence, mount: Sequence[float] = (0.0, 0.0, 0.0),
                            beam_motion: Optional[np.ndarray] = None
                            ) -> Tuple[np.ndarray, np.ndarray]:
    """Convert laser-frame corners to base_link range-bearing observations.

    Args:
        corners: Corners with ``position`` (2,) and ``covariance`` (2, 2) in the laser frame
            (:class:`landmark_nav.laser.corners.Corner`).
        mount: Laser pose ``[x, y, yaw]`` in base_link.
        beam_motion: Optional (M, 3) pose of base_link at each corner's beam time in
            base_link at the scan stamp (motion compensation of the sweep); None = static.

    Returns:
        ``(z (M, 2), R (M, 2, 2))`` in base_link; ``(0, 2)`` / ``(0, 2, 2)`` for no corners.
    """
    if len(corners) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2, 2))
    p = np.array([c.position for c in corners], dtype=float).reshape(-1, 2)
    cov = np.array([c.covariance for c in corners], dtype=float).reshape(-1, 2, 2)
    mount = np.asarray(mount, dtype=float)
    p = transform_points(mount, p)
    rot = _rotations(np.full(p.shape[0], mount[2]))
    if beam_motion is not None:
        motion = np.asarray(beam_motion, dtype=float).reshape(-1, 3)
        p = transform_points(motion, p)
        rot = _rotations(motion[:, 2]) @ rot
    cov = rot @ cov @ np.transpose(rot, (0, 2, 1))
    return points_to_observations(p, cov)


def corner_descriptors(corners: Sequence, mount: Sequence[float] = (0.0, 0.0, 0.0),
                       beam_motion: Optional[np.ndarray] = None) -> np.ndarray:
    """Return the association descriptors ``[bisector, opening]`` of corners in base_link.

    The bisector direction (laser frame, :class:`~landmark_nav.laser.corners.Corner`) is
    rotated by the mount yaw (and the sweep motion); the free-space opening is frame free.
    Two corners at almost the same place (the two roots of a thin partition) differ in them.

    Args:
        corners: Corners with ``bisector`` and ``opening`` [rad].
        mount: Laser pose ``[x, y, yaw]`` in base_link.
        beam_motion: As in :func:`corners_to_observations`.

    Returns:
        (M, 2) ``[bisector in base_link (wrapped), opening]`` [rad].
    """
    if len(corners) == 0:
        return np.zeros((0, 2))
    bis = np.array([c.bisector for c in corners], dtype=float) + float(mount[2])
    if beam_motion is not None:
        bis = bis + np.asarray(beam_motion, dtype=float).reshape(-1, 3)[:, 2]
    opening = np.array([c.opening for c in corners], dtype=float)
    return np.column_stack([np.mod(bis + np.pi, 2.0 * np.pi) - np.pi, opening])


def _rotations(yaw: np.ndarray) -> np.ndarray:
    """Return (M, 2, 2) rotation matrices."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


__all__ = ['corner_descriptors', 'corners_to_observations', 'points_to_observations',
           'polar_jacobian']
