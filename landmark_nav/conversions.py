"""Conversions between ROS 2 messages and numpy data (the only module knowing both).

Readers (``*_to_*``) validate the message and return frozen dataclasses holding read-only
numpy arrays; builders (``make_*``) validate their arguments and return messages that
serialize. Problems raise :class:`ConversionError` (a ``ValueError``) whose message starts
with the message type and names the offending field.

Conventions:

* Stamps are integer nanoseconds (``stamp_ns``); :func:`ns_to_stamp` uses floor division,
  so negative times get a negative ``sec`` and a ``nanosec`` in [0, 1e9).
* LaserScan beams are classified per REP 117: ``valid`` (finite, within
  [range_min, range_max]), ``no_return`` (+inf or finite > range_max), ``too_close``
  (-inf or finite < range_min), ``error`` (NaN). A scan with ``angle_increment <= 0`` is
  rejected (some drivers emit negative increments for upside-down lasers; configure the
  driver for counter-clockwise scans instead), so beam indices always match the message.
* 2D covariances are the (x, y, yaw) block, indices 0, 1, 5 of the row-major 6x6. Builders
  put ``unused_variance`` (default 1e6, i.e. "unknown", as ROS diff_drive_controller
  does) on the z, roll, pitch diagonal and 0 in every cross term involving them, so
  consumers fusing all six dimensions ignore them instead of trusting a zero variance.
* Images keep the channel order of their encoding (bgr8 stays BGR), like cv_bridge's
  ``passthrough``; 16-bit images are returned in native byte order.
* OccupancyGrid data is (height, width), row-major, row 0 = the row at the map origin
  (the bottom of the image shown by map_server), column = +x of the origin frame.
"""

from dataclasses import dataclass
import math
from typing import NamedTuple, Optional, Sequence

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseWithCovarianceStamped, Quaternion, TransformStamped
from landmark_nav.geometry import quaternion_to_yaw, yaw_to_quaternion
from nav_msgs.msg import OccupancyGrid, Odometry
import numpy as np
from sensor_msgs.msg import CameraInfo, Image, JointState, LaserScan, Range
from std_msgs.msg import Header

NS_PER_S = 1_000_000_000
_MIN_NS = -(2 ** 31) * NS_PER_S
_MAX_NS = (2 ** 31 - 1) * NS_PER_S + NS_PER_S - 1
_IDX3 = (0, 1, 5)  # x, y, yaw in the 6x6 (x, y, z, roll, pitch, yaw) covariance
DEFAULT_UNUSED_VARIANCE = 1e6

# encoding -> (channels, numpy dtype without byte order, bytes per channel)
_ENCODINGS = {
    'mono8': (1, 'u1', 1),
    'rgb8': (3, 'u1', 1),
    'bgr8': (3, 'u1', 1),
    '16UC1': (1, 'u2', 2),
    'mono16': (1, 'u2', 2),
}

STATUS_VALID = 'valid'
STATUS_NO_RETURN = 'no_return'
STATUS_TOO_CLOSE = 'too_close'
STATUS_ERROR = 'error'


class ConversionError(ValueError):
    """A message or value cannot be converted; the message names the problem."""


def _ro(array: np.ndarray) -> np.ndarray:
    """Return a read-only contiguous copy."""
    out = np.array(array, copy=True, order='C')
    out.setflags(write=False)
    return out


def _f32(value: float) -> float:
    """Round to float32, as the wire does, so in-process and received messages agree."""
    with np.errstate(over='ignore'):
        return float(np.float32(value))


def _finite(value: float, what: str) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ConversionError(f'{what}={value!r} must be finite')
    return v


# ---------------------------------------------------------------------------- time


def stamp_to_ns(stamp: Time) -> int:
    """Convert a builtin_interfaces/Time to integer nanoseconds."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def ns_to_stamp(ns: int) -> Time:
    """Convert integer nanoseconds to builtin_interfaces/Time.

    Raises:
        ConversionError: If ``ns`` is not an integer or does not fit int32 seconds.
    """
    if isinstance(ns, (bool, np.bool_)) or not isinstance(ns, (int, np.integer)):
        raise ConversionError(f'Time: stamp_ns must be an integer; got {ns!r}')
    ns = int(ns)
    if not _MIN_NS <= ns <= _MAX_NS:
        raise ConversionError(f'Time: stamp_ns={ns} does not fit int32 seconds')
    sec, nanosec = divmod(ns, NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def _header(stamp_ns: int, frame_id: str) -> Header:
    return Header(stamp=ns_to_stamp(stamp_ns), frame_id=str(frame_id))


# ---------------------------------------------------------------------------- laser scan


@dataclass(frozen=True, eq=False)
class ScanData:
    """A validated LaserScan with per-beam REP 117 masks (arrays are read-only)."""

    stamp_ns: int
    frame_id: str
    angle_min: float
    angle_increment: float
    time_increment: float
    scan_time: float
    range_min: float
    range_max: float
    ranges: np.ndarray  # (N,) float64, raw values
    angles: np.ndarray  # (N,) float64, angle_min + i * angle_increment
    intensities: np.ndarray  # (N,) or (0,) float64
    valid: np.ndarray  # (N,) bool
    no_return: np.ndarray
    too_close: np.ndarray
    error: np.ndarray

    @property
    def angle_max(self) -> float:
        """Angle of the last beam (angle_min for an empty scan)."""
        return self.angle_min + max(self.ranges.size - 1, 0) * self.angle_increment

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Cartesian points of the valid beams in the laser frame.

        Returns:
            (xy, index): xy of shape (M, 2) in metres, and the (M,) beam indices.
        """
        idx = np.flatnonzero(self.valid)
        r = self.ranges[idx]
        a = self.angles[idx]
        return np.column_stack([r * np.cos(a), r * np.sin(a)]), idx


def classify_ranges(ranges: np.ndarray, range_min: float,
                    range_max: float) -> tuple[np.ndarray, ...]:
    """Classify ranges per REP 117.

    Returns:
        (valid, no_return, too_close, error) boolean arrays; exactly one is True per beam.
    """
    r = np.asarray(ranges, dtype=float)
    error = np.isnan(r)
    with np.errstate(invalid='ignore'):
        no_return = (r > range_max) & ~error  # includes +inf
        too_close = (r < range_min) & ~error  # includes -inf
    valid = ~(error | no_return | too_close)
    return valid, no_return, too_close, error


def _check_scan_fields(n: int, angle_min: float, angle_max: float, angle_increment: float,
                       time_increment: float, scan_time: float, range_min: float,
                       range_max: float, n_intensities: int) -> None:
    for name, value in (('angle_min', angle_min), ('angle_max', angle_max),
                        ('angle_increment', angle_increment),
                        ('time_increment', time_increment), ('scan_time', scan_time),
                        ('range_min', range_min), ('range_max', range_max)):
        _finite(value, f'LaserScan: {name}')
    if not angle_increment > 0.0:
        raise ConversionError(
            f'LaserScan: angle_increment={angle_increment!r} must be > 0 (scans with a '
            'negative increment, e.g. from upside-down lasers, are not supported)')
    if angle_max < angle_min:
        raise ConversionError(
            f'LaserScan: angle_max={angle_max!r} < angle_min={angle_min!r}')
    if not range_min >= 0.0:
        raise ConversionError(f'LaserScan: range_min={range_min!r} must be >= 0')
    if not range_max > range_min:
        raise ConversionError(
            f'LaserScan: range_max={range_max!r} must be > range_min={range_min!r}')
    implied = int(round((angle_max - angle_min) / angle_increment)) + 1
    if abs(n - implied) > 1:
        raise ConversionError(
            f'LaserScan: len(ranges)={n} but angle fields imply {implied} beams '
            f'(angle_min={angle_min!r}, angle_max={angle_max!r}, '
            f'angle_increment={angle_increment!r})')
    if n_intensities not in (0, n):
        raise ConversionError(
            f'LaserScan: len(intensities)={n_intensities} must be 0 or len(ranges)={n}')


def scan_to_data(msg: LaserScan) -> ScanData:
    """Validate a LaserScan and convert it to :class:`ScanData`.

    Raises:
        ConversionError: On non-finite angle/time/range fields, angle_increment <= 0,
            angle_max < angle_min, range_max <= range_min or range_min < 0, a beam count
            off by more than one from round((angle_max - angle_min) / inc) + 1, or
            intensities that are neither empty nor len(ranges) long.
    """
    # float32 fields: an unserialized message may hold float64 values, round them first.
    ranges = np.asarray(msg.ranges, dtype=np.float32).astype(np.float64)
    intensities = np.asarray(msg.intensities, dtype=np.float32).astype(np.float64)
    f = {k: _f32(getattr(msg, k)) for k in (
        'angle_min', 'angle_max', 'angle_increment', 'time_increment', 'scan_time',
        'range_min', 'range_max')}
    _check_scan_fields(ranges.size, f['angle_min'], f['angle_max'], f['angle_increment'],
                       f['time_increment'], f['scan_time'], f['range_min'], f['range_max'],
                       intensities.size)
    angles = f['angle_min'] + np.arange(ranges.size) * f['angle_increment']
    masks = classify_ranges(ranges, f['range_min'], f['range_max'])
    return ScanData(
        stamp_ns=stamp_to_ns(msg.header.stamp), frame_id=msg.header.frame_id,
        angle_min=f['angle_min'], angle_increment=f['angle_increment'],
        time_increment=f['time_increment'], scan_time=f['scan_time'],
        range_min=f['range_min'], range_max=f['range_max'],
        ranges=_ro(ranges), angles=_ro(angles), intensities=_ro(intensities),
        valid=_ro(masks[0]), no_return=_ro(masks[1]), too_close=_ro(masks[2]),
        error=_ro(masks[3]))


def make_scan(stamp_ns: int, frame_id: str, angle_min: float, angle_increment: float,
              ranges: Sequence[float], range_min: float, range_max: float,
              time_increment: float = 0.0, scan_time: float = 0.0,
              intensities: Optional[Sequence[float]] = None) -> LaserScan:
    """Build a LaserScan; angle_max = angle_min + (n - 1) * angle_increment.

    Float fields are rounded to float32 (the message type) before validation.

    Raises:
        ConversionError: If the fields fail the checks of :func:`scan_to_data`.
    """
    r = np.asarray(ranges, dtype=np.float32).ravel()
    inten = (np.zeros(0, np.float32) if intensities is None
             else np.asarray(intensities, dtype=np.float32).ravel())
    a_min, inc = _f32(angle_min), _f32(angle_increment)
    f = {'angle_min': a_min, 'angle_max': _f32(a_min + max(r.size - 1, 0) * inc),
         'angle_increment': inc, 'time_increment': _f32(time_increment),
         'scan_time': _f32(scan_time), 'range_min': _f32(range_min),
         'range_max': _f32(range_max)}
    _check_scan_fields(r.size, f['angle_min'], f['angle_max'], f['angle_increment'],
                       f['time_increment'], f['scan_time'], f['range_min'], f['range_max'],
                       inten.size)
    msg = LaserScan()
    msg.header = _header(stamp_ns, frame_id)
    for name, value in f.items():
        setattr(msg, name, value)
    msg.ranges = r
    msg.intensities = inten
    return msg


def data_to_scan(data: ScanData) -> LaserScan:
    """Build a LaserScan from :class:`ScanData` (inverse of :func:`scan_to_data`)."""
    return make_scan(data.stamp_ns, data.frame_id, data.angle_min, data.angle_increment,
                     data.ranges, data.range_min, data.range_max, data.time_increment,
                     data.scan_time, data.intensities)


# ---------------------------------------------------------------------------- poses


@dataclass(frozen=True, eq=False)
class PoseData:
    """A 2D pose with (x, y, yaw) covariance; twist fields only for Odometry."""

    stamp_ns: int
    frame_id: str
    pose: np.ndarray  # (3,) x, y, yaw
    covariance: np.ndarray  # (3, 3) over (x, y, yaw)
    child_frame_id: str = ''
    twist: Optional[np.ndarray] = None  # (3,) vx, vy, wz in child_frame_id
    twist_covariance: Optional[np.ndarray] = None  # (3, 3) over (vx, vy, wz)


def cov6_to_cov3(cov6: Sequence[float]) -> np.ndarray:
    """Extract the (x, y, yaw) 3x3 block (indices 0, 1, 5) of a row-major 6x6."""
    c = np.asarray(cov6, dtype=float)
    if c.size != 36:
        raise ConversionError(f'covariance must have 36 elements; got {c.size}')
    return c.reshape(6, 6)[np.ix_(_IDX3, _IDX3)]


def cov3_to_cov6(cov3: Optional[np.ndarray], what: str = 'covariance',
                 unused_variance: float = DEFAULT_UNUSED_VARIANCE) -> np.ndarray:
    """Place a 3x3 (x, y, yaw) covariance into a flat row-major 6x6.

    None means a zero 3x3. z, roll and pitch get ``unused_variance`` on the diagonal and 0
    in every cross term.
    """
    c6 = np.zeros((6, 6))
    c6[2, 2] = c6[3, 3] = c6[4, 4] = float(unused_variance)
    if cov3 is not None:
        c3 = np.asarray(cov3, dtype=float)
        if c3.shape != (3, 3):
            raise ConversionError(f'{what} must be 3x3; got shape {c3.shape}')
        if not np.all(np.isfinite(c3)):
            raise ConversionError(f'{what} must be finite')
        if not np.allclose(c3, c3.T, rtol=1e-9, atol=1e-12):
            raise ConversionError(f'{what} must be symmetric')
        c6[np.ix_(_IDX3, _IDX3)] = c3
    return c6.ravel()


def _pose_vec(pose: Sequence[float], what: str) -> np.ndarray:
    p = np.asarray(pose, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ConversionError(f'{what} must be 3 finite numbers [x, y, yaw]; got {pose!r}')
    return p


def quaternion_msg_from_yaw(yaw: float) -> Quaternion:
    """Build a geometry_msgs/Quaternion for a rotation by ``yaw`` about z."""
    x, y, z, w = (float(v) for v in yaw_to_quaternion(float(yaw)))
    return Quaternion(x=x, y=y, z=z, w=w)


def pose_msg_from_2d(pose: Sequence[float]) -> Pose:
    """Build a geometry_msgs/Pose (z = 0) from [x, y, yaw]."""
    p = _pose_vec(pose, 'pose')
    msg = Pose()
    msg.position.x = float(p[0])
    msg.position.y = float(p[1])
    msg.orientation = quaternion_msg_from_yaw(p[2])
    return msg


def pose_msg_to_2d(msg: Pose, what: str = 'Pose') -> np.ndarray:
    """Return [x, y, yaw] of a geometry_msgs/Pose (yaw of the full 3D rotation)."""
    q = msg.orientation
    vals = (msg.position.x, msg.position.y, q.x, q.y, q.z, q.w)
    if not all(math.isfinite(v) for v in vals):
        raise ConversionError(f'{what}: pose contains non-finite values')
    if q.x == 0.0 and q.y == 0.0 and q.z == 0.0 and q.w == 0.0:
        raise ConversionError(f'{what}: orientation quaternion is all zero')
    return np.array([msg.position.x, msg.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w)])


def odometry_to_pose(msg: Odometry) -> PoseData:
    """Convert nav_msgs/Odometry to :class:`PoseData` (x, y, yaw; vx, vy, wz)."""
    pose = pose_msg_to_2d(msg.pose.pose, 'Odometry')
    lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
    twist = np.array([lin.x, lin.y, ang.z], dtype=float)
    return PoseData(
        stamp_ns=stamp_to_ns(msg.header.stamp), frame_id=msg.header.frame_id,
        child_frame_id=msg.child_frame_id, pose=_ro(pose),
        covariance=_ro(cov6_to_cov3(msg.pose.covariance)), twist=_ro(twist),
        twist_covariance=_ro(cov6_to_cov3(msg.twist.covariance)))


_COV3_FLAT = np.array([6 * i + j for i in _IDX3 for j in _IDX3])  # 3x3 in the flat 6x6


def odometry_pose_covariance(msg: Odometry) -> tuple[int, np.ndarray, np.ndarray]:
    """Return ``(stamp_ns, [x, y, yaw], 3x3 covariance)`` of an Odometry, per message.

    The numbers of :func:`odometry_to_pose` without its twist and record (a node's
    odometry callback; the covariance is the message's, unchecked).

    Raises:
        ConversionError: As :func:`pose_msg_to_2d`, or a covariance of another size.
    """
    pose = pose_msg_to_2d(msg.pose.pose, 'Odometry')
    c = np.asarray(msg.pose.covariance, dtype=float)
    if c.size != 36:
        raise ConversionError(f'covariance must have 36 elements; got {c.size}')
    return stamp_to_ns(msg.header.stamp), pose, c.ravel()[_COV3_FLAT].reshape(3, 3)


def set_stamp(header: Header, stamp_ns: int) -> None:
    """Set ``header.stamp`` from integer nanoseconds (in place; no range check)."""
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    header.stamp.sec, header.stamp.nanosec = sec, nanosec


def set_pose_2d(msg: Pose, pose: np.ndarray) -> None:
    """Set a geometry_msgs/Pose in place from a finite ``[x, y, yaw]`` (z = 0)."""
    msg.position.x, msg.position.y = float(pose[0]), float(pose[1])
    half = 0.5 * float(pose[2])
    q = msg.orientation
    q.x, q.y, q.z, q.w = 0.0, 0.0, math.sin(half), math.cos(half)


def set_covariance3(cov6: np.ndarray, cov3: np.ndarray) -> np.ndarray:
    """Write a 3x3 (x, y, yaw) covariance into the flat 6x6 ``cov6`` (in place; returned)."""
    cov6[_COV3_FLAT] = np.asarray(cov3, dtype=float).ravel()
    return cov6


def make_transform(stamp_ns: int, frame_id: str, child_frame_id: str,
                   pose: Sequence[float]) -> TransformStamped:
    """Build the TransformStamped of a planar pose ``[x, y, yaw]`` of ``child`` in ``frame``."""
    t = TransformStamped()
    t.header.stamp = ns_to_stamp(stamp_ns)
    t.header.frame_id = frame_id
    t.child_frame_id = child_frame_id
    t.transform.translation.x = float(pose[0])
    t.transform.translation.y = float(pose[1])
    t.transform.rotation = quaternion_msg_from_yaw(float(pose[2]))
    return t


def make_odometry(stamp_ns: int, frame_id: str, child_frame_id: str, pose: Sequence[float],
                  covariance3: Optional[np.ndarray] = None,
                  twist: Optional[Sequence[float]] = None,
                  twist_covariance3: Optional[np.ndarray] = None,
                  unused_variance: float = DEFAULT_UNUSED_VARIANCE) -> Odometry:
    """Build nav_msgs/Odometry from [x, y, yaw], [vx, vy, wz] and 3x3 covariances.

    See the module docstring for how the 3x3 blocks are placed in the 6x6 matrices.
    """
    msg = Odometry()
    msg.header = _header(stamp_ns, frame_id)
    msg.child_frame_id = str(child_frame_id)
    msg.pose.pose = pose_msg_from_2d(_pose_vec(pose, 'Odometry: pose'))
    msg.pose.covariance = cov3_to_cov6(covariance3, 'Odometry: covariance3', unused_variance)
    tw = np.zeros(3) if twist is None else _pose_vec(twist, 'Odometry: twist')
    msg.twist.twist.linear.x = float(tw[0])
    msg.twist.twist.linear.y = float(tw[1])
    msg.twist.twist.angular.z = float(tw[2])
    msg.twist.covariance = cov3_to_cov6(twist_covariance3, 'Odometry: twist_covariance3',
                                        unused_variance)
    return msg


def pose_with_covariance_to_pose(msg: PoseWithCovarianceStamped) -> PoseData:
    """Convert geometry_msgs/PoseWithCovarianceStamped to :class:`PoseData` (no twist)."""
    pose = pose_msg_to_2d(msg.pose.pose, 'PoseWithCovarianceStamped')
    return PoseData(stamp_ns=stamp_to_ns(msg.header.stamp), frame_id=msg.header.frame_id,
                    pose=_ro(pose), covariance=_ro(cov6_to_cov3(msg.pose.covariance)))


def make_pose_with_covariance_stamped(
        stamp_ns: int, frame_id: str, pose: Sequence[float],
        covariance3: Optional[np.ndarray] = None,
        unused_variance: float = DEFAULT_UNUSED_VARIANCE) -> PoseWithCovarianceStamped:
    """Build geometry_msgs/PoseWithCovarianceStamped from [x, y, yaw] and a 3x3."""
    msg = PoseWithCovarianceStamped()
    msg.header = _header(stamp_ns, frame_id)
    msg.pose.pose = pose_msg_from_2d(_pose_vec(pose, 'PoseWithCovarianceStamped: pose'))
    msg.pose.covariance = cov3_to_cov6(covariance3, 'PoseWithCovarianceStamped: covariance3',
                                       unused_variance)
    return msg


# ---------------------------------------------------------------------------- range


class RangeReading(NamedTuple):
    """A Range value and its REP 117 status."""

    stamp_ns: int
    frame_id: str
    value: float  # the raw range (m); the message field is named range
    status: str  # 'valid', 'no_return', 'too_close' or 'error'


def range_status(value: float, min_range: float, max_range: float) -> str:
    """Classify one range value per REP 117 (see :func:`classify_ranges`)."""
    v = float(value)
    if math.isnan(v):
        return STATUS_ERROR
    if v > max_range:
        return STATUS_NO_RETURN
    if v < min_range:
        return STATUS_TOO_CLOSE
    return STATUS_VALID


def _check_range_limits(min_range: float, max_range: float) -> None:
    _finite(min_range, 'Range: min_range')
    _finite(max_range, 'Range: max_range')
    if not 0.0 <= min_range <= max_range:
        raise ConversionError(
            f'Range: need 0 <= min_range <= max_range; got {min_range!r}, {max_range!r}')


def range_to_value(msg: Range) -> RangeReading:
    """Convert sensor_msgs/Range to (stamp_ns, frame_id, range, status).

    +inf (no detection) and finite values > max_range are 'no_return'; -inf (detection
    too close, also "detected" for fixed-distance rangers) and finite values < min_range
    are 'too_close'; NaN is 'error'.

    Raises:
        ConversionError: On bad range limits or a field of view that is not finite, >= 0.
    """
    lo, hi, value = _f32(msg.min_range), _f32(msg.max_range), _f32(msg.range)
    _check_range_limits(lo, hi)
    fov = _f32(msg.field_of_view)
    if not (math.isfinite(fov) and fov >= 0.0):
        raise ConversionError(f'Range: field_of_view={fov!r} must be finite, >= 0')
    return RangeReading(stamp_to_ns(msg.header.stamp), msg.header.frame_id, value,
                        range_status(value, lo, hi))


def make_range(stamp_ns: int, frame_id: str, value: float, field_of_view: float,
               min_range: float, max_range: float,
               radiation_type: int = Range.ULTRASOUND) -> Range:
    """Build sensor_msgs/Range; ``value`` may be +-inf or NaN per REP 117."""
    _check_range_limits(min_range, max_range)
    if not (math.isfinite(field_of_view) and field_of_view >= 0.0):
        raise ConversionError(f'Range: field_of_view={field_of_view!r} must be finite, >= 0')
    if radiation_type not in (Range.ULTRASOUND, Range.INFRARED):
        raise ConversionError(f'Range: unknown radiation_type={radiation_type!r}')
    msg = Range()
    msg.header = _header(stamp_ns, frame_id)
    msg.radiation_type = int(radiation_type)
    msg.field_of_view = float(field_of_view)
    msg.min_range = float(min_range)
    msg.max_range = float(max_range)
    msg.range = float(value)
    return msg


# ---------------------------------------------------------------------------- image


def image_to_array(msg: Image) -> np.ndarray:
    """Convert sensor_msgs/Image to a new contiguous array (H, W) or (H, W, 3).

    Supports mono8, rgb8, bgr8 (uint8) and 16UC1/mono16 (uint16, native byte order);
    honours ``step`` padding and ``is_bigendian``.

    Raises:
        ConversionError: Unsupported encoding, step < width * bytes per pixel, or
            len(data) != step * height.
    """
    enc = msg.encoding
    if enc not in _ENCODINGS:
        raise ConversionError(
            f'Image: unsupported encoding {enc!r}; supported: {sorted(_ENCODINGS)}')
    channels, kind, nbytes = _ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row_bytes = w * channels * nbytes
    if step < row_bytes:
        raise ConversionError(
            f'Image: step={step} < width*bytes_per_pixel={row_bytes} for {enc} {w}x{h}')
    buf = np.frombuffer(msg.data, dtype=np.uint8)
    if buf.size != step * h:
        raise ConversionError(
            f'Image: len(data)={buf.size} but step*height={step}*{h}={step * h}')
    rows = buf.reshape(h, step)[:, :row_bytes]
    order = '>' if (nbytes > 1 and msg.is_bigendian) else '<'
    shape = (h, w) if channels == 1 else (h, w, channels)
    arr = np.ascontiguousarray(rows).view(np.dtype(order + kind)).reshape(shape)
    return arr.astype(np.dtype(kind), order='C', copy=True)  # native byte order, new memory


def array_to_image(array: np.ndarray, encoding: str, stamp_ns: int = 0, frame_id: str = '',
                   is_bigendian: bool = False) -> Image:
    """Build sensor_msgs/Image (unpadded rows) from a uint8 or uint16 array.

    Args:
        array: (H, W) for mono8/16UC1/mono16 or (H, W, 3) for rgb8/bgr8.
        encoding: One of mono8, rgb8, bgr8, 16UC1, mono16.
        stamp_ns: Header stamp in ns.
        frame_id: Header frame_id.
        is_bigendian: Byte order to write 16-bit data in.
    """
    if encoding not in _ENCODINGS:
        raise ConversionError(
            f'Image: unsupported encoding {encoding!r}; supported: {sorted(_ENCODINGS)}')
    channels, kind, nbytes = _ENCODINGS[encoding]
    a = np.asarray(array)
    want_ndim = 2 if channels == 1 else 3
    if a.ndim != want_ndim or (channels > 1 and a.shape[2] != channels):
        raise ConversionError(
            f'Image: {encoding} needs an array of shape '
            f'{"(H, W)" if channels == 1 else "(H, W, 3)"}; got {a.shape}')
    if a.dtype.kind != 'u' or a.dtype.itemsize != nbytes:
        raise ConversionError(f'Image: {encoding} needs dtype {np.dtype(kind)}; got {a.dtype}')
    order = '>' if (nbytes > 1 and is_bigendian) else '<'
    data = np.ascontiguousarray(a.astype(np.dtype(order + kind), copy=False))
    msg = Image()
    msg.header = _header(stamp_ns, frame_id)
    msg.height, msg.width = int(a.shape[0]), int(a.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = int(nbytes > 1 and bool(is_bigendian))
    msg.step = msg.width * channels * nbytes
    msg.data = data.tobytes()
    return msg


# ---------------------------------------------------------------------------- camera info


def camera_info_to_model(msg: CameraInfo):
    """Convert sensor_msgs/CameraInfo to a :class:`landmark_nav.vision.camera.CameraModel`.

    ``distortion_model`` must be ``plumb_bob`` (D of 0, 4 or 5 values) or
    ``rational_polynomial`` (0, 8, 12 or 14); an empty model name with an empty D is taken
    as an undistorted pinhole. An all-zero R (left unset by some drivers) is read as the
    identity and an all-zero P as ``[K | 0]``.

    Raises:
        ConversionError: size not positive, K with non-positive focal length or a bad last
            row, unknown distortion model, wrong number of D values, non-finite values,
            binning or a region of interest (not supported).
    """
    from landmark_nav.vision.camera import CameraModel, DISTORTION_MODELS
    w, h = int(msg.width), int(msg.height)
    if w <= 0 or h <= 0:
        raise ConversionError(f'CameraInfo: width={w}, height={h} must be positive')
    model = str(msg.distortion_model)
    d = np.asarray(msg.d, dtype=float)
    if model == '' and d.size == 0:
        model = 'plumb_bob'
    if model not in DISTORTION_MODELS:
        raise ConversionError(f'CameraInfo: unknown distortion_model {model!r}; supported: '
                              f'{sorted(DISTORTION_MODELS)}')
    if d.size not in DISTORTION_MODELS[model]:
        raise ConversionError(f'CameraInfo: {model} needs len(d) in {DISTORTION_MODELS[model]}; '
                              f'got {d.size}')
    k = np.asarray(msg.k, dtype=float).reshape(-1)
    r = np.asarray(msg.r, dtype=float).reshape(-1)
    p = np.asarray(msg.p, dtype=float).reshape(-1)
    for name, arr in (('d', d), ('k', k), ('r', r), ('p', p)):
        if not np.all(np.isfinite(arr)):
            raise ConversionError(f'CameraInfo: {name} has non-finite values')
    if k.size != 9 or r.size != 9 or p.size != 12:
        raise ConversionError(f'CameraInfo: k, r, p need 9, 9, 12 values; got {k.size}, '
                              f'{r.size}, {p.size}')
    if k[0] <= 0 or k[4] <= 0:
        raise ConversionError(f'CameraInfo: k has non-positive focal length fx={k[0]}, fy={k[4]}')
    if int(msg.binning_x) > 1 or int(msg.binning_y) > 1:
        raise ConversionError(f'CameraInfo: binning {msg.binning_x}x{msg.binning_y} is not '
                              'supported')
    roi = msg.roi
    if int(roi.x_offset) or int(roi.y_offset) or (int(roi.width) and int(roi.width) != w) \
            or (int(roi.height) and int(roi.height) != h):
        raise ConversionError('CameraInfo: a region of interest is not supported')
    R = np.eye(3) if not np.any(r) else r.reshape(3, 3)
    P = None if not np.any(p) else p.reshape(3, 4)
    try:
        return CameraModel(width=w, height=h, K=k.reshape(3, 3), D=d, distortion_model=model,
                           R=R, P=P)
    except ValueError as err:
        raise ConversionError(f'CameraInfo: {err}') from err


def make_camera_info(model, stamp_ns: int = 0, frame_id: str = '') -> CameraInfo:
    """Build sensor_msgs/CameraInfo from a :class:`landmark_nav.vision.camera.CameraModel`."""
    from landmark_nav.vision.camera import CameraModel
    if not isinstance(model, CameraModel):
        raise ConversionError(f'CameraInfo: need a CameraModel; got {type(model).__name__}')
    msg = CameraInfo()
    msg.header = _header(stamp_ns, frame_id)
    msg.width, msg.height = model.width, model.height
    msg.distortion_model = model.distortion_model
    msg.d = [float(v) for v in model.D]
    msg.k = [float(v) for v in model.K.ravel()]
    msg.r = [float(v) for v in model.R.ravel()]
    msg.p = [float(v) for v in model.P.ravel()]
    return msg


# ---------------------------------------------------------------------------- grid


@dataclass(frozen=True, eq=False)
class GridData:
    """An occupancy grid: int8 (H, W), -1 unknown, 0..100 occupied; row 0 at the origin."""

    stamp_ns: int
    frame_id: str
    resolution: float  # m / cell
    origin: np.ndarray  # (3,) x, y, yaw of cell (0, 0)'s outer corner in frame_id
    data: np.ndarray  # (H, W) int8

    @property
    def height(self) -> int:
        """Return the number of rows (cells along the origin's y axis)."""
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        """Return the number of columns (cells along the origin's x axis)."""
        return int(self.data.shape[1])


def grid_to_data(msg: OccupancyGrid) -> GridData:
    """Convert nav_msgs/OccupancyGrid to :class:`GridData` (values are not checked).

    Raises:
        ConversionError: If len(data) != width * height or resolution is not > 0.
    """
    info = msg.info
    w, h = int(info.width), int(info.height)
    data = np.asarray(msg.data, dtype=np.int8)
    if data.size != w * h:
        raise ConversionError(
            f'OccupancyGrid: len(data)={data.size} but width*height={w}*{h}={w * h}')
    if not (math.isfinite(info.resolution) and info.resolution > 0.0):
        raise ConversionError(f'OccupancyGrid: resolution={info.resolution!r} must be > 0')
    origin = pose_msg_to_2d(info.origin, 'OccupancyGrid')
    return GridData(stamp_ns=stamp_to_ns(msg.header.stamp), frame_id=msg.header.frame_id,
                    resolution=float(info.resolution), origin=_ro(origin),
                    data=_ro(data.reshape(h, w)))


def make_occupancy_grid(data: np.ndarray, resolution: float, origin: Sequence[float],
                        frame_id: str = 'map', stamp_ns: int = 0) -> OccupancyGrid:
    """Build nav_msgs/OccupancyGrid from an (H, W) array with values in {-1} or [0, 100].

    Raises:
        ConversionError: On a non-2D array, values outside [-1, 100] or resolution <= 0.
    """
    a = np.asarray(data)
    if a.ndim != 2:
        raise ConversionError(f'OccupancyGrid: data must be 2D (H, W); got shape {a.shape}')
    if a.size and (a.dtype.kind not in 'iu' or a.min() < -1 or a.max() > 100):
        raise ConversionError(
            'OccupancyGrid: data must be integers in [-1, 100] (-1 = unknown)')
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise ConversionError(f'OccupancyGrid: resolution={resolution!r} must be > 0')
    msg = OccupancyGrid()
    msg.header = _header(stamp_ns, frame_id)
    msg.info.map_load_time = ns_to_stamp(stamp_ns)
    msg.info.resolution = float(resolution)
    msg.info.height, msg.info.width = int(a.shape[0]), int(a.shape[1])
    msg.info.origin = pose_msg_from_2d(_pose_vec(origin, 'OccupancyGrid: origin'))
    msg.data = np.ascontiguousarray(a, dtype=np.int8).ravel()
    return msg


# ---------------------------------------------------------------------------- joints


def make_joint_state(stamp_ns: int, names: Sequence[str], positions: Sequence[float],
                     velocities: Optional[Sequence[float]] = None) -> JointState:
    """Build sensor_msgs/JointState; velocities may be None or empty (not reported)."""
    names = [str(n) for n in names]
    pos = [float(v) for v in positions]
    vel = [] if velocities is None else [float(v) for v in velocities]
    if len(pos) != len(names):
        raise ConversionError(
            f'JointState: len(positions)={len(pos)} but len(names)={len(names)}')
    if vel and len(vel) != len(names):
        raise ConversionError(
            f'JointState: len(velocities)={len(vel)} but len(names)={len(names)}')
    msg = JointState()
    msg.header = _header(stamp_ns, '')
    msg.name = names
    msg.position = pos
    msg.velocity = vel
    return msg


__all__ = [
    'ConversionError', 'GridData', 'PoseData', 'RangeReading', 'ScanData',
    'array_to_image', 'camera_info_to_model', 'classify_ranges', 'cov3_to_cov6',
    'cov6_to_cov3', 'data_to_scan', 'grid_to_data', 'image_to_array', 'make_camera_info',
    'make_joint_state', 'make_occupancy_grid',
    'make_odometry', 'make_pose_with_covariance_stamped', 'make_range', 'make_scan',
    'make_transform',
    'ns_to_stamp', 'odometry_to_pose', 'pose_msg_from_2d', 'pose_msg_to_2d',
    'pose_with_covariance_to_pose', 'quaternion_msg_from_yaw', 'range_status',
    'range_to_value', 'scan_to_data', 'stamp_to_ns',
]
