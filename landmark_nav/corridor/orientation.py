"""Camera tilt and robot heading relative to the corridor from its vanishing point (eq. 21).

Visual navigation chapter §3.1.3. Its angles: ``theta`` is the robot's heading relative
to the corridor direction, counter-clockwise positive (the robot turned left sees the
corridor VP right of the image centre); ``alpha`` is the camera's deviation from the
horizon, positive looking down; the camera roll ``beta`` is 0. Eq. 21::

    alpha = arctan((y_vp - c_y) / f'),   theta = -arctan((x_vp - c_x) cos(alpha) / f')

in the chapter's image axes (x to the left, y up: the robot-style camera axes of its
eq. 11). In this package's pixels (``u`` right, ``v`` down, :mod:`landmark_nav.vision.camera`)
and normalised coordinates ``x_n = (u - c_x) / f_x``, ``y_n = (v - c_y) / f_y`` the same
equations read ``alpha = arctan(-y_n)``, ``theta = arctan(x_n cos(alpha))``; they are exact
for a camera with zero roll: the corridor direction seen by a camera tilted by ``alpha`` on
a robot at heading ``theta`` is ``d = (sin theta, -cos theta sin alpha, cos theta cos alpha)``
in the optical frame. From the unit direction ``d`` (finite also for a VP at infinity) they
are ``alpha = atan2(-d_y, d_z)``, ``theta = atan2(d_x, hypot(d_y, d_z))``
(:func:`eq21_from_direction`), with no division by ``d_z``.

With the camera mount known (pose ``[x, y, z, roll, pitch, yaw]`` of ``camera_link`` in
``base_link``, as in :func:`landmark_nav.vision.localize.camera_mount_matrix`) the
corridor direction is rotated into ``base_link`` and the heading taken there
(:func:`corridor_orientation`): ``c = R_base_optical d``, ``theta = atan2(-c_y, c_x)``; this
also handles a mount yaw or roll, and ``elevation = atan2(c_z, hypot(c_x, c_y))`` (0 for a
level floor and a correct mount) checks the mount pitch.

The corridor is a line, not a vector: ``d`` and ``-d`` are the same VP, so the heading is
defined modulo pi and reported in (-pi/2, pi/2] (the direction ahead of the robot).
"""

from dataclasses import dataclass
import math
from typing import Sequence, Tuple, Union

from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
import numpy as np


@dataclass(frozen=True, eq=False)
class CorridorOrientation:
    """Orientation relative to the corridor.

    Attributes:
        heading: robot heading relative to the corridor [rad], CCW positive, in
            (-pi/2, pi/2], from the mount rotation.
        tilt: camera tilt below the horizon [rad] (eq. 21 ``alpha``).
        heading_eq21: eq. 21 ``theta`` [rad]: the heading of the camera itself (the robot's
            when the mount has no yaw or roll).
        elevation: elevation of the corridor direction in ``base_link`` [rad] (0 on a
            level floor with a correct mount pitch).
        direction_base: (3,) unit corridor direction in ``base_link``, ``x >= 0``.
    """

    heading: float
    tilt: float
    heading_eq21: float
    elevation: float
    direction_base: np.ndarray


def eq21(vp: Sequence[float], fx: float, fy: float, cx: float,
         cy: float) -> Tuple[float, float]:
    """Return ``(alpha, theta)`` of eq. 21 from a finite VP pixel ``(u, v)`` (no skew).

    Raises:
        ValueError: non-positive focal length or a non-finite VP.
    """
    if not (fx > 0 and fy > 0):
        raise ValueError(f'focal lengths must be > 0; got fx={fx}, fy={fy}')
    u, v = float(vp[0]), float(vp[1])
    if not (math.isfinite(u) and math.isfinite(v)):
        raise ValueError(f'vanishing point must be finite for eq. 21; got ({u}, {v})')
    alpha = math.atan(-(v - cy) / fy)                        # eq. 21
    theta = math.atan((u - cx) * math.cos(alpha) / fx)       # eq. 21
    return alpha, theta


def eq21_from_direction(d: Sequence[float]) -> Tuple[float, float]:
    """Return ``(alpha, theta)`` of eq. 21 from the VP direction (optical frame, any sign)."""
    d = np.asarray(d, dtype=float).reshape(3)
    n = np.linalg.norm(d)
    if not np.isfinite(n) or n == 0:
        raise ValueError(f'vanishing direction must be a finite non-zero 3-vector; got {d}')
    d = d / n
    if d[2] < 0 or (d[2] == 0 and d[0] < 0):
        d = -d
    alpha = math.atan2(-d[1], d[2])
    theta = math.atan2(d[0], math.hypot(d[1], d[2]))
    return alpha, theta


def vp_direction(vp: Sequence[float], camera: Union[CameraModel, np.ndarray]) -> np.ndarray:
    """Return the unit optical-frame direction of a VP pixel.

    Args:
        vp: ``(u, v)`` pixel in the (distorted) camera image, or a homogeneous ``(u, v, w)``
            in ideal pixels (``w = 0``: at infinity).
        camera: a :class:`CameraModel` (a finite 2-D pixel is undistorted first) or a 3 x 3
            K (ideal pixels).

    Raises:
        ValueError: zero focal length, or a non-finite VP.
    """
    v = np.asarray(vp, dtype=float).reshape(-1)
    if isinstance(camera, CameraModel):
        K = camera.K
    else:
        K = np.asarray(camera, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f'K must be a finite 3x3 matrix with fx, fy > 0; got {K}')
    if v.size not in (2, 3) or not np.all(np.isfinite(v)):
        raise ValueError(f'vanishing point must be a finite (u, v) or (u, v, w); got {v}')
    if v.size == 2 and isinstance(camera, CameraModel) and camera.has_distortion:
        d = camera.back_project(v[None, :])[0]
    else:
        h = np.append(v, 1.0) if v.size == 2 else v
        d = np.linalg.solve(K, h)
    n = np.linalg.norm(d)
    if n == 0:
        raise ValueError('vanishing point (0, 0, 0) has no direction')
    return d / n


def mount_rotation(mount: Sequence[float]) -> np.ndarray:
    """Return ``R_base_optical`` for a camera_link mount ``[x, y, z, roll, pitch, yaw]``.

    Only the angles are used (``R = Rz(yaw) Ry(pitch) Rx(roll)``, fixed axes, as in
    :mod:`landmark_nav.vision.localize`); a positive pitch looks down (REP 103).
    """
    m = np.asarray(mount, dtype=float).reshape(-1)
    if m.size != 6 or not np.all(np.isfinite(m)):
        raise ValueError(f'camera mount must be 6 finite numbers [x, y, z, roll, pitch, yaw];'
                         f' got {m}')
    cr, sr = math.cos(m[3]), math.sin(m[3])
    cp, sp = math.cos(m[4]), math.sin(m[4])
    cy, sy = math.cos(m[5]), math.sin(m[5])
    r = np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],     # Rz Ry Rx
                  [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                  [-sp, cp * sr, cp * cr]])
    return r @ np.asarray(OPTICAL_FROM_BODY).T


def corridor_orientation(direction: Sequence[float],
                         mount: Sequence[float] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
                         ) -> CorridorOrientation:
    """Return heading and tilt relative to the corridor from its VP direction.

    Args:
        direction: (3,) corridor VP direction in the optical frame (either sign).
        mount: camera_link pose in base_link ``[x, y, z, roll, pitch, yaw]`` [m, rad].
    """
    alpha, theta_cam = eq21_from_direction(direction)
    d = np.asarray(direction, dtype=float).reshape(3)
    c = mount_rotation(mount) @ (d / np.linalg.norm(d))
    if c[0] < 0 or (c[0] == 0 and c[1] > 0):
        c = -c
    heading = math.atan2(-c[1], c[0])
    if heading <= -math.pi / 2:
        heading += math.pi
    elevation = math.atan2(c[2], math.hypot(c[0], c[1]))
    return CorridorOrientation(heading=heading, tilt=alpha, heading_eq21=theta_cam,
                               elevation=elevation, direction_base=c)
