"""Robot pose from a landmark detection, and odometry corrected by landmark fixes (§2.3.3).

Frames (REP 103 / REP 105):

* ``map``: the frame of the landmark map; a landmark's pose in ``map`` is the pose of its
  landmark frame (x out of the printed face, y right when looking at it, z up; origin at the
  frame centre, see :mod:`.landmark`).
* ``base_link``: the robot. The camera mount is the pose ``[x, y, z, roll, pitch, yaw]`` of
  the camera's body frame (``camera_link``: x forward along the optical axis, y left, z up)
  in ``base_link``; the optical frame (z forward, x right, y down) is that frame rotated by
  :data:`~.camera.OPTICAL_FROM_BODY`.
* 6-D poses are ``[x, y, z, roll, pitch, yaw]`` with ``R = Rz(yaw) Ry(pitch) Rx(roll)``
  (fixed axes x, y, z, as in ROS ``tf2`` and the covariance of
  geometry_msgs/PoseWithCovariance); their 6 x 6 covariances are over the same six values.

The robot pose implied by a detection is
``T_map_base = T_map_landmark (T_optical_landmark)^-1 (T_base_optical)^-1`` and its
covariance the detection's 6 x 6 pose covariance propagated through this map with a
numerical Jacobian.

:class:`FixCorrectedOdometry` is the §2.3.3 use: dead reckoning from odometry increments
(an SE(2) EKF prediction with distance-proportional noise) corrected by each landmark fix
(an EKF update with the fix's (x, y, yaw) covariance).
"""

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Dict, Sequence, Tuple, Union

from landmark_nav.geometry import compose, compose_jacobians, wrap_angle
from landmark_nav.vision.camera import OPTICAL_FROM_BODY
from landmark_nav.vision.pose import LandmarkPose, rotation_matrix
import numpy as np
import yaml

_M = np.asarray(OPTICAL_FROM_BODY, dtype=float)


class LandmarkMapError(ValueError):
    """A landmark map file or entry is malformed (the message names file and entry)."""


def _compose_quaternions(p: Tuple[float, ...], q: Tuple[float, ...]) -> Tuple[float, ...]:
    """Return the quaternion product ``p q`` of (x, y, z, w) quaternions."""
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return (pw * qx + qw * px + (py * qz - pz * qy), pw * qy + qw * py + (pz * qx - px * qz),
            pw * qz + qw * pz + (px * qy - py * qx), pw * qw - px * qx - py * qy - pz * qz)


def rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    """Return the 3 x 3 rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` of ``[roll, pitch, yaw]``.

    Bit for bit ``scipy.spatial.transform.Rotation.from_euler('xyz', rpy).as_matrix()`` (its
    elementary quaternions composed, then its matrix formula, in its order of operations;
    tested), without importing scipy.spatial (about 0.6 CPU-s at every node start).
    """
    r, p, y = (float(a) for a in rpy)
    qx = (math.sin(r / 2.0), 0.0, 0.0, math.cos(r / 2.0))
    qy = (0.0, math.sin(p / 2.0), 0.0, math.cos(p / 2.0))
    qz = (0.0, 0.0, math.sin(y / 2.0), math.cos(y / 2.0))
    x, y, z, w = _compose_quaternions(qz, _compose_quaternions(qy, qx))
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return np.array([[x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)],
                     [2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)],
                     [2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2]])


def pose6_to_matrix(pose: Sequence[float]) -> np.ndarray:
    """Return the 4 x 4 transform of ``[x, y, z, roll, pitch, yaw]``."""
    p = np.asarray(pose, dtype=float).reshape(6)
    t = np.eye(4)
    t[:3, :3] = rpy_matrix(p[3:])
    t[:3, 3] = p[:3]
    return t


def matrix_to_pose6(t: np.ndarray) -> np.ndarray:
    """Return ``[x, y, z, roll, pitch, yaw]`` of a 4 x 4 transform."""
    from scipy.spatial.transform import Rotation  # on first use: ~0.6 CPU-s to import
    out = np.zeros(6)
    out[:3] = t[:3, 3]
    out[3:] = Rotation.from_matrix(t[:3, :3]).as_euler('xyz')
    return out


def _invert(t: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def camera_mount_matrix(mount: Sequence[float]) -> np.ndarray:
    """Return ``T_base_optical`` from the camera_link pose ``[x, y, z, roll, pitch, yaw]``."""
    t = pose6_to_matrix(mount)
    t[:3, :3] = t[:3, :3] @ _M.T          # optical axes = body axes rotated
    return t


def landmark_in_optical(v: np.ndarray) -> np.ndarray:
    """Return ``T_optical_landmark`` for pose parameters ``v`` of :mod:`.pose`."""
    t = np.eye(4)
    t[:3, :3] = _M @ rotation_matrix(v[3:])
    t[:3, 3] = _M @ np.asarray(v[:3], dtype=float)
    return t


def _base_pose6(v: np.ndarray, t_map_lm: np.ndarray, t_opt_base: np.ndarray) -> np.ndarray:
    t = t_map_lm @ _invert(landmark_in_optical(v)) @ t_opt_base
    return matrix_to_pose6(t)


def robot_pose_from_landmark(pose: LandmarkPose, landmark_in_map: np.ndarray,
                             camera_mount: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return the robot pose in ``map`` implied by one landmark pose, with its covariance.

    Args:
        pose: the landmark pose relative to the camera (:func:`.pose.estimate_pose`).
        landmark_in_map: 4 x 4 ``T_map_landmark``.
        camera_mount: 4 x 4 ``T_base_optical`` (:func:`camera_mount_matrix`).

    Returns:
        (pose6, cov6): ``[x, y, z, roll, pitch, yaw]`` of ``base_link`` in ``map`` and the
        6 x 6 covariance (``J cov_v J^T``, J by central differences). For an ambiguous
        landmark pose (``pose.ambiguous``) the covariance also holds half the outer product
        of the difference to the robot pose of the other minimum (``pose.alternative``),
        computed exactly rather than through J, so that it covers that pose too (the
        mixture covariance of :func:`.pose.estimate_pose` mapped without linearising a
        difference of tens of degrees).
    """
    t_opt_base = _invert(camera_mount)
    v = np.asarray(pose.v, dtype=float)
    p0 = _base_pose6(v, landmark_in_map, t_opt_base)
    jac = np.zeros((6, 6))
    steps = np.array([1e-6] * 3 + [1e-6] * 3)
    for k in range(6):
        d = np.zeros(6)
        d[k] = steps[k]
        diff = _base_pose6(v + d, landmark_in_map, t_opt_base) - \
            _base_pose6(v - d, landmark_in_map, t_opt_base)
        diff[3:] = (diff[3:] + math.pi) % (2 * math.pi) - math.pi
        jac[:, k] = diff / (2 * steps[k])
    cov = jac @ pose.covariance @ jac.T
    if pose.ambiguous and pose.alternative is not None:
        gap = _base_pose6(np.asarray(pose.alternative, dtype=float), landmark_in_map,
                          t_opt_base) - p0
        gap[3:] = (gap[3:] + math.pi) % (2 * math.pi) - math.pi
        cov = cov + 0.5 * np.outer(gap, gap)
    return p0, 0.5 * (cov + cov.T)


def planar(pose6: np.ndarray, cov6: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``([x, y, yaw], 3 x 3 covariance)`` of a 6-D pose (indices 0, 1, 5)."""
    idx = [0, 1, 5]
    return np.asarray(pose6)[idx].copy(), np.asarray(cov6)[np.ix_(idx, idx)].copy()


# ---------------------------------------------------------------------- landmark map


def _entry_matrix(code: int, entry: object, where: str) -> np.ndarray:
    if not isinstance(entry, dict):
        raise LandmarkMapError(f'{where}: landmark {code} must be a mapping with position and '
                               'rpy or quaternion')
    try:
        pos = np.asarray(entry['position'], dtype=float).reshape(3)
    except (KeyError, TypeError, ValueError) as err:
        raise LandmarkMapError(f'{where}: landmark {code}: position must be [x, y, z] '
                               f'[m]') from err
    if 'rpy' in entry and 'quaternion' in entry:
        raise LandmarkMapError(f'{where}: landmark {code}: give rpy or quaternion, not both')
    try:
        if 'quaternion' in entry:
            q = np.asarray(entry['quaternion'], dtype=float).reshape(4)
            if not np.all(np.isfinite(q)) or np.linalg.norm(q) < 1e-9:
                raise ValueError('zero or non-finite quaternion')
            from scipy.spatial.transform import Rotation  # on first use: ~0.6 CPU-s
            rot = Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()
        else:
            rpy = np.asarray(entry.get('rpy', [0.0, 0.0, 0.0]), dtype=float).reshape(3)
            rot = rpy_matrix(rpy)
    except (TypeError, ValueError) as err:
        raise LandmarkMapError(f'{where}: landmark {code}: bad orientation ({err}); use rpy: '
                               '[roll, pitch, yaw] [rad] or quaternion: [x, y, z, w]') from err
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(rot))):
        raise LandmarkMapError(f'{where}: landmark {code}: non-finite pose')
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = pos
    return t


def parse_landmark_map(data: object, where: str = 'landmark map') -> Dict[int, np.ndarray]:
    """Return ``{code: T_map_landmark}`` from a parsed landmark map.

    Format (YAML)::

        frame_id: map            # optional, informational
        landmarks:
          156: {position: [2.0, 0.0, 0.3], rpy: [0.0, 0.0, 3.14159]}
          123456789: {position: [0.0, 4.0, 0.3], quaternion: [0.0, 0.0, 0.7071, 0.7071]}

    ``rpy`` (radians, ``Rz(yaw) Ry(pitch) Rx(roll)``) or ``quaternion`` (x, y, z, w) orient
    the landmark frame (x out of the printed face, z up); a landmark on a wall facing the
    map's -x direction has yaw pi.

    Raises:
        LandmarkMapError: malformed map, naming the entry.
    """
    if not isinstance(data, dict) or not isinstance(data.get('landmarks'), dict):
        raise LandmarkMapError(f'{where}: expected a mapping with a "landmarks" mapping of '
                               'code -> pose')
    out = {}
    for key, entry in data['landmarks'].items():
        try:
            code = int(key)
        except (TypeError, ValueError) as err:
            raise LandmarkMapError(f'{where}: landmark key {key!r} is not an integer '
                                   'code') from err
        if code < 0:
            raise LandmarkMapError(f'{where}: landmark code {code} is negative')
        out[code] = _entry_matrix(code, entry, where)
    return out


def load_landmark_map(path: Union[str, Path]) -> Dict[int, np.ndarray]:
    """Read a landmark map YAML file (format: :func:`parse_landmark_map`).

    Raises:
        LandmarkMapError: unreadable file or malformed content.
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except OSError as err:
        raise LandmarkMapError(f'cannot read landmark map {path}: {err}') from err
    except yaml.YAMLError as err:
        raise LandmarkMapError(f'landmark map {path} is not valid YAML: {err}') from err
    return parse_landmark_map(data, str(path))


# ---------------------------------------------------------------------- §2.3.3 correction


@dataclass(frozen=True)
class OdometryNoise:
    """Noise of odometry increments, proportional to the motion (per metre / radian).

    Attributes:
        sigma_distance: std of the travelled distance per metre [m/m].
        sigma_lateral: std of the sideways position per metre travelled [m/m].
        sigma_heading_per_m: std of the heading per metre travelled [rad/m].
        sigma_heading_per_rad: std of the heading per radian turned [rad/rad].
    """

    sigma_distance: float = 0.02
    sigma_lateral: float = 0.01
    sigma_heading_per_m: float = 0.02
    sigma_heading_per_rad: float = 0.03


class FixCorrectedOdometry:
    """SE(2) EKF: odometry increments predict, landmark fixes (x, y, yaw) correct (§2.3.3).

    State ``[x, y, yaw]`` of ``base_link`` in ``map`` with a 3 x 3 covariance.
    """

    def __init__(self, pose: Sequence[float], covariance: np.ndarray,
                 noise: OdometryNoise = OdometryNoise()) -> None:
        """Start from a pose and covariance in ``map``."""
        self.x = np.asarray(pose, dtype=float).reshape(3).copy()
        self.p = np.asarray(covariance, dtype=float).reshape(3, 3).copy()
        self.noise = noise

    def predict(self, increment: Sequence[float]) -> None:
        """Apply an odometry increment ``u = [dx, dy, dyaw]`` in the robot frame (eq. 13)."""
        u = np.asarray(increment, dtype=float).reshape(3)
        d = math.hypot(u[0], u[1])
        n = self.noise
        q = np.diag([(n.sigma_distance * d) ** 2 + 1e-12, (n.sigma_lateral * d) ** 2 + 1e-12,
                     (n.sigma_heading_per_m * d) ** 2
                     + (n.sigma_heading_per_rad * abs(u[2])) ** 2 + 1e-12])
        j1, j2 = compose_jacobians(self.x, u)
        self.x = compose(self.x, u)
        self.p = j1 @ self.p @ j1.T + j2 @ q @ j2.T
        self.p = 0.5 * (self.p + self.p.T)

    def update(self, fix: Sequence[float], covariance: np.ndarray) -> float:
        """Correct with a landmark fix ``[x, y, yaw]`` and its covariance; return its NIS."""
        z = np.asarray(fix, dtype=float).reshape(3)
        r = np.asarray(covariance, dtype=float).reshape(3, 3)
        innov = z - self.x
        innov[2] = wrap_angle(innov[2])
        s = self.p + r
        k = self.p @ np.linalg.inv(s)
        self.x = self.x + k @ innov
        self.x[2] = wrap_angle(self.x[2])
        i_k = np.eye(3) - k
        self.p = i_k @ self.p @ i_k.T + k @ r @ k.T     # Joseph form
        self.p = 0.5 * (self.p + self.p.T)
        return float(innov @ np.linalg.solve(s, innov))


__all__ = ['FixCorrectedOdometry', 'LandmarkMapError', 'OdometryNoise',
           'camera_mount_matrix', 'landmark_in_optical', 'load_landmark_map',
           'matrix_to_pose6', 'parse_landmark_map', 'planar', 'pose6_to_matrix',
           'robot_pose_from_landmark']
