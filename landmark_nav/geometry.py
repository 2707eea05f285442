"""SE(2) pose algebra, point transforms and small helpers (pure numpy).

A pose is an array ``[x, y, theta]`` (m, m, rad) of shape ``(3,)`` or ``(..., 3)``;
functions broadcast over leading axes where that is natural. Frames follow REP 103
(x forward, y left, theta counter-clockwise about z). Every returned angle is wrapped to
the half-open interval ``[-pi, pi)`` by :func:`wrap_angle`.

Equation numbers refer to the corner-extraction / EKF-SLAM chapter, section 3.1-3.3:
eq. 13 (odometry increment), eq. 16 (composition), eq. 17 (inverse), eqs. 27-30
(Jacobians of the composition).

Laser mounting convention
-------------------------
The pose of the laser (or any other 2D sensor) on the robot is a parameter
``laser_pose = [x, y, yaw]`` (m, m, rad): the position of the sensor frame origin and the
orientation of its x axis, both expressed in ``base_link``. It is the transform
``base_link -> laser`` (what ``tf2`` returns for ``lookup_transform('base_link', 'laser')``
and what ``static_transform_publisher --frame-id base_link --child-frame-id laser``
publishes). A point ``p`` measured in the laser frame is expressed in ``base_link`` as
``p_base = transform_points(laser_pose, p)``, i.e. ``p_base = R(yaw) @ p + [x, y]``.
Nodes use :func:`sensor_to_base` for this. Only yaw mounting is modelled: a laser mounted
upside down (roll = pi) must be handled by its driver.
"""

import math
from typing import Sequence, Union

import numpy as np

ArrayLike = Union[float, Sequence[float], np.ndarray]

TWO_PI = 2.0 * math.pi


def wrap_angle(a: ArrayLike) -> Union[float, np.ndarray]:
    """Wrap angle(s) to the half-open interval [-pi, pi).

    Args:
        a: Angle or array of angles (rad); any magnitude.

    Returns:
        A float for scalar input, otherwise an array of the same shape. ``pi`` maps to
        ``-pi``; NaN and +-inf give NaN.
    """
    if isinstance(a, float) and -math.pi <= a < math.pi:  # one angle in range (the usual)
        return float(a)
    arr = np.asarray(a, dtype=float)
    with np.errstate(invalid='ignore'):
        out = np.mod(arr + math.pi, TWO_PI) - math.pi
    # np.mod can round up to exactly 2*pi for tiny negative inputs; keep the interval open.
    out = np.where(out >= math.pi, out - TWO_PI, out)
    # Angles already in range are returned bit-for-bit (no rounding through +-pi).
    out = np.where((arr >= -math.pi) & (arr < math.pi), arr, out)
    if out.ndim == 0:
        return float(out)
    return out


def _as_pose(x: ArrayLike, name: str = 'pose') -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise ValueError(f'{name} must have shape (..., 3) [x, y, theta]; got {arr.shape}')
    return arr


def compose(x1: ArrayLike, x2: ArrayLike) -> np.ndarray:
    """Compose two poses, x1 ⊕ x2 (eq. 16).

    Args:
        x1: Pose of frame 1 in frame 0, shape (..., 3).
        x2: Pose of frame 2 in frame 1, shape (..., 3).

    Returns:
        Pose of frame 2 in frame 0, shape broadcast(x1, x2).
    """
    p1 = _as_pose(x1, 'x1')
    p2 = _as_pose(x2, 'x2')
    c, s = np.cos(p1[..., 2]), np.sin(p1[..., 2])
    x = p1[..., 0] + p2[..., 0] * c - p2[..., 1] * s  # eq. 16, row 1
    y = p1[..., 1] + p2[..., 0] * s + p2[..., 1] * c  # eq. 16, row 2
    th = wrap_angle(p1[..., 2] + p2[..., 2])  # eq. 16, row 3
    if p1.ndim == 1 and p2.ndim == 1:  # two poses: no broadcasting
        return np.array([x, y, th])
    x, y, th = np.broadcast_arrays(x, y, th)
    return np.stack([x, y, th], axis=-1)


def inverse(x: ArrayLike) -> np.ndarray:
    """Invert a pose, ⊖x (eq. 17).

    Args:
        x: Pose of frame 1 in frame 0, shape (..., 3).

    Returns:
        Pose of frame 0 in frame 1, same shape.
    """
    p = _as_pose(x, 'x')
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    xi = -p[..., 0] * c - p[..., 1] * s  # eq. 17, row 1
    yi = p[..., 0] * s - p[..., 1] * c  # eq. 17, row 2
    th = wrap_angle(-p[..., 2])  # eq. 17, row 3
    if p.ndim == 1:
        return np.array([xi, yi, th])
    return np.stack([xi, yi, np.broadcast_to(th, xi.shape)], axis=-1)


def relative(x1: ArrayLike, x2: ArrayLike) -> np.ndarray:
    """Return ⊖x1 ⊕ x2, the pose of x2 seen from x1 (eq. 13, odometry increment).

    Args:
        x1: Earlier pose (e.g. odometry at k-1), shape (..., 3).
        x2: Later pose (e.g. odometry at k), shape (..., 3).

    Returns:
        The increment u with ``compose(x1, u) == x2``.
    """
    return compose(inverse(x1), x2)  # eq. 13


def compose_jacobians(x1: ArrayLike, x2: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of x1 ⊕ x2 with respect to x1 and x2 (eqs. 27-30).

    Args:
        x1: Pose, shape (..., 3).
        x2: Pose, shape (..., 3).

    Returns:
        (J1, J2), each of shape broadcast(...) + (3, 3).
    """
    p1 = _as_pose(x1, 'x1')
    p2 = _as_pose(x2, 'x2')
    shape = np.broadcast_shapes(p1.shape, p2.shape)[:-1]
    c = np.broadcast_to(np.cos(p1[..., 2]), shape)
    s = np.broadcast_to(np.sin(p1[..., 2]), shape)
    x2_, y2_ = np.broadcast_to(p2[..., 0], shape), np.broadcast_to(p2[..., 1], shape)
    j1 = np.zeros(shape + (3, 3))
    j1[..., 0, 0] = 1.0
    j1[..., 1, 1] = 1.0
    j1[..., 2, 2] = 1.0
    j1[..., 0, 2] = -x2_ * s - y2_ * c  # eq. 28, row 1
    # eq. 28, row 2: the chapter prints -x2 cos(th1) - y2 sin(th1), a typo; the
    # derivative of y1 + x2 sin(th1) + y2 cos(th1) w.r.t. th1 is x2 cos(th1) - y2 sin(th1).
    j1[..., 1, 2] = x2_ * c - y2_ * s
    j2 = np.zeros(shape + (3, 3))  # eq. 30
    j2[..., 0, 0] = c
    j2[..., 0, 1] = -s
    j2[..., 1, 0] = s
    j2[..., 1, 1] = c
    j2[..., 2, 2] = 1.0
    return j1, j2


def inverse_jacobian(x: ArrayLike) -> np.ndarray:
    """Jacobian of ⊖x with respect to x (derivative of eq. 17).

    Args:
        x: Pose, shape (..., 3).

    Returns:
        Array of shape (..., 3, 3).
    """
    p = _as_pose(x, 'x')
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    px, py = p[..., 0], p[..., 1]
    jac = np.zeros(p.shape[:-1] + (3, 3))
    jac[..., 0, 0] = -c
    jac[..., 0, 1] = -s
    jac[..., 0, 2] = px * s - py * c
    jac[..., 1, 0] = s
    jac[..., 1, 1] = -c
    jac[..., 1, 2] = px * c + py * s
    jac[..., 2, 2] = -1.0
    return jac


def transform_points(pose: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Express points given in frame ``pose`` in the parent frame.

    Args:
        pose: Pose of the child frame in the parent frame, shape (3,) (or (..., 3)
            broadcasting against the leading axes of ``points``).
        points: Points in the child frame, shape (N, 2) or (..., 2).

    Returns:
        Points in the parent frame, ``R(theta) p + t``, same shape as ``points``.
    """
    p = _as_pose(pose)
    pts = np.asarray(points, dtype=float)
    if pts.ndim == 0 or pts.shape[-1] != 2:
        raise ValueError(f'points must have shape (..., 2); got {pts.shape}')
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    x = p[..., 0] + c * pts[..., 0] - s * pts[..., 1]
    y = p[..., 1] + s * pts[..., 0] + c * pts[..., 1]
    return np.stack([x, y], axis=-1)


def inverse_transform_points(pose: ArrayLike, points: ArrayLike) -> np.ndarray:
    """Express points given in the parent frame in frame ``pose``.

    Args:
        pose: Pose of the child frame in the parent frame, shape (3,) or (..., 3).
        points: Points in the parent frame, shape (N, 2) or (..., 2).

    Returns:
        Points in the child frame, ``R(theta)^T (p - t)``.
    """
    p = _as_pose(pose)
    pts = np.asarray(points, dtype=float)
    if pts.ndim == 0 or pts.shape[-1] != 2:
        raise ValueError(f'points must have shape (..., 2); got {pts.shape}')
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    dx = pts[..., 0] - p[..., 0]
    dy = pts[..., 1] - p[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)


def sensor_to_base(points: ArrayLike, sensor_pose: ArrayLike) -> np.ndarray:
    """Transform points from a 2D sensor frame into base_link.

    Args:
        points: Points in the sensor frame, shape (N, 2).
        sensor_pose: Mounting ``[x, y, yaw]`` of the sensor in base_link (see module doc).

    Returns:
        Points in base_link, shape (N, 2).
    """
    return transform_points(sensor_pose, points)


def validate_pose_parameter(values: Sequence[float], name: str) -> np.ndarray:
    """Check a ``[x, y, yaw]`` parameter value and return it as a float array.

    Args:
        values: The parameter value, e.g. ``[0.2, 0.0, 0.0]``.
        name: Parameter name, used in the error message.

    Returns:
        Array of shape (3,), dtype float64 (yaw returned as given, not wrapped).

    Raises:
        ValueError: If ``values`` is not 3 finite real numbers.
    """
    expect = f'parameter "{name}" must be a list of 3 finite numbers [x, y, yaw] (m, m, rad)'
    if isinstance(values, (str, bytes)) or not hasattr(values, '__len__'):
        raise ValueError(f'{expect}; got {values!r}')
    if len(values) != 3:
        raise ValueError(f'{expect}; got {len(values)} values: {list(values)!r}')
    out = []
    for v in values:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.number)):
            raise ValueError(f'{expect}; got non-numeric value {v!r}')
        f = float(v)
        if not math.isfinite(f):
            raise ValueError(f'{expect}; got non-finite value {v!r}')
        out.append(f)
    return np.array(out, dtype=float)


def yaw_to_quaternion(yaw: ArrayLike) -> np.ndarray:
    """Quaternion of a rotation by ``yaw`` about z.

    Args:
        yaw: Angle(s) in rad.

    Returns:
        Array ``[x, y, z, w]`` of shape (..., 4); for a scalar yaw, shape (4,) which
        unpacks as ``x, y, z, w = yaw_to_quaternion(yaw)``.
    """
    half = 0.5 * np.asarray(yaw, dtype=float)
    zero = np.zeros_like(half)
    return np.stack([zero, zero, np.sin(half), np.cos(half)], axis=-1)


def quaternion_to_yaw(x: ArrayLike, y: ArrayLike, z: ArrayLike,
                      w: ArrayLike) -> Union[float, np.ndarray]:
    """Yaw (z-y-x Euler, about z) of a possibly non-normalised 3D quaternion.

    The formula is homogeneous in the quaternion, so any non-zero scale gives the same
    yaw. At pitch = +-pi/2 (gimbal lock) yaw is undefined and 0 is returned.

    Args:
        x: Quaternion x component(s).
        y: Quaternion y component(s).
        z: Quaternion z component(s).
        w: Quaternion w component(s).

    Returns:
        Yaw in [-pi, pi); float for scalar input.

    Raises:
        ValueError: If a quaternion is zero or not finite.
    """
    qx, qy, qz, qw = (np.asarray(v, dtype=float) for v in (x, y, z, w))
    norm2 = qx * qx + qy * qy + qz * qz + qw * qw
    if not np.all(np.isfinite(norm2)) or np.any(norm2 == 0.0):
        raise ValueError('quaternion must be finite and non-zero')
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz)
    return wrap_angle(yaw)


def interpolate_pose(t: ArrayLike, times: ArrayLike, poses: ArrayLike,
                     extrapolate: bool = False) -> np.ndarray:
    """Linearly interpolate poses in time; theta follows the shortest arc.

    Args:
        t: Query time(s), scalar or shape (M,).
        times: Sample times, shape (N,), non-decreasing.
        poses: Sample poses, shape (N, 3).
        extrapolate: If True, times outside [times[0], times[-1]] are extrapolated
            linearly from the first/last interval (a single sample is held constant).

    Returns:
        Pose(s), shape (3,) for scalar ``t``, otherwise (M, 3).

    Raises:
        ValueError: On bad shapes, unsorted or non-finite times, or ``t`` out of range
            when ``extrapolate`` is False.
    """
    ts = np.asarray(times, dtype=float)
    ps = np.asarray(poses, dtype=float)
    tq = np.asarray(t, dtype=float)
    if ts.ndim != 1 or ts.size == 0 or ps.shape != (ts.size, 3):
        raise ValueError(f'need times (N,) and poses (N, 3), N >= 1; got {ts.shape}, {ps.shape}')
    if not np.all(np.isfinite(ts)) or np.any(np.diff(ts) < 0):
        raise ValueError('times must be finite and non-decreasing')
    if not np.all(np.isfinite(tq)):
        raise ValueError('query time must be finite')
    if not extrapolate and (np.any(tq < ts[0]) or np.any(tq > ts[-1])):
        raise ValueError(f'query time outside [{ts[0]!r}, {ts[-1]!r}] and extrapolate=False')
    scalar = tq.ndim == 0
    tq = np.atleast_1d(tq)
    if ts.size == 1:
        out = np.repeat(ps[:1], tq.size, axis=0)
        out[:, 2] = wrap_angle(out[:, 2])
        return out[0] if scalar else out
    if scalar:  # one query (the usual): the same arithmetic on scalars
        k = min(max(int(np.searchsorted(ts, tq[0], side='right')) - 1, 0), ts.size - 2)
        dt = ts[k + 1] - ts[k]
        f = (tq[0] - ts[k]) / dt if dt > 0 else 1.0
        xy = ps[k, :2] + f * (ps[k + 1, :2] - ps[k, :2])
        th = wrap_angle(ps[k, 2] + f * wrap_angle(ps[k + 1, 2] - ps[k, 2]))
        return np.array([xy[0], xy[1], th])
    i = np.clip(np.searchsorted(ts, tq, side='right') - 1, 0, ts.size - 2)
    t0, t1 = ts[i], ts[i + 1]
    dt = t1 - t0
    safe_dt = np.where(dt > 0, dt, 1.0)
    frac = np.where(dt > 0, (tq - t0) / safe_dt, 1.0)
    p0, p1 = ps[i], ps[i + 1]
    xy = p0[:, :2] + frac[:, None] * (p1[:, :2] - p0[:, :2])
    dth = wrap_angle(p1[:, 2] - p0[:, 2])
    th = wrap_angle(p0[:, 2] + frac * dth)
    out = np.column_stack([xy, th])
    return out[0] if scalar else out


def covariance_ellipse(mean: ArrayLike, cov: ArrayLike, k: float = 2.0,
                       n: int = 40) -> np.ndarray:
    """Return (n, 2) points of the k-sigma ellipse of a 2-D Gaussian (closed: last = first)."""
    mean = np.asarray(mean, dtype=float).reshape(2)
    cov = np.asarray(cov, dtype=float).reshape(2, 2)
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    a = np.linspace(0.0, 2.0 * math.pi, n)
    circle = np.stack([np.cos(a), np.sin(a)])
    return (mean[:, None] + v @ (k * np.sqrt(np.maximum(w, 0.0))[:, None] * circle)).T
