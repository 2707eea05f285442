"""Tests for landmark_nav.conversions (ROS messages <-> numpy)."""

import dataclasses
import math

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovarianceStamped
from hypothesis import given, settings
from hypothesis import strategies as st
from landmark_nav import conversions as c
from landmark_nav.conversions import ConversionError
from nav_msgs.msg import OccupancyGrid, Odometry
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Image, JointState, LaserScan, Range

INF = math.inf
NAN = math.nan


def wire(msg):
    """Serialize and deserialize a message (CDR round trip)."""
    return deserialize_message(serialize_message(msg), type(msg))


# ------------------------------------------------------------------ time


@pytest.mark.parametrize('ns', [0, 1, 999_999_999, 1_000_000_000, 1_700_000_000_123_456_789,
                                (2 ** 31 - 1) * 10 ** 9 + 999_999_999, -1, -(2 ** 31) * 10 ** 9])
def test_stamp_round_trip(ns):
    stamp = c.ns_to_stamp(ns)
    assert 0 <= stamp.nanosec < 10 ** 9
    assert c.stamp_to_ns(stamp) == ns
    assert c.stamp_to_ns(wire(stamp)) == ns
    assert isinstance(c.stamp_to_ns(stamp), int)


def test_stamp_values_and_errors():
    stamp = c.ns_to_stamp(1_700_000_000_123_456_789)
    assert (stamp.sec, stamp.nanosec) == (1_700_000_000, 123_456_789)
    stamp = c.ns_to_stamp(-1)
    assert (stamp.sec, stamp.nanosec) == (-1, 999_999_999)
    assert c.stamp_to_ns(Time(sec=12, nanosec=5)) == 12_000_000_005
    assert c.ns_to_stamp(np.int64(5)).nanosec == 5
    for bad in (2 ** 31 * 10 ** 9, -(2 ** 31) * 10 ** 9 - 1):
        with pytest.raises(ConversionError, match='stamp_ns'):
            c.ns_to_stamp(bad)
    for bad in (1.5, '1', True):
        with pytest.raises(ConversionError, match='integer'):
            c.ns_to_stamp(bad)


@settings(max_examples=200, deadline=None)
@given(st.integers(-(2 ** 31) * 10 ** 9, (2 ** 31) * 10 ** 9 - 1))
def test_stamp_round_trip_property(ns):
    assert c.stamp_to_ns(c.ns_to_stamp(ns)) == ns


# ------------------------------------------------------------------ LaserScan

MASK_RANGES = [1.0, INF, -INF, NAN, 31.0, 0.05, 0.1, 30.0, 0.0, 29.5]


def test_scan_masks_follow_rep117():
    msg = c.make_scan(5, 'laser', -0.5, 0.25, MASK_RANGES, 0.1, 30.0)
    d = c.scan_to_data(msg)
    assert d.valid.tolist() == [1, 0, 0, 0, 0, 0, 1, 1, 0, 1]
    assert d.no_return.tolist() == [0, 1, 0, 0, 1, 0, 0, 0, 0, 0]
    assert d.too_close.tolist() == [0, 0, 1, 0, 0, 1, 0, 0, 1, 0]
    assert d.error.tolist() == [0, 0, 0, 1, 0, 0, 0, 0, 0, 0]
    masks = np.stack([d.valid, d.no_return, d.too_close, d.error])
    assert np.all(masks.sum(axis=0) == 1)
    for m in masks:
        assert m.dtype == bool


def test_scan_points_and_angles():
    msg = c.make_scan(0, 'laser', -math.pi / 2, math.pi / 4, [1.0, NAN, 2.0, INF, 4.0],
                      0.1, 10.0)
    d = c.scan_to_data(wire(msg))  # float32 on the wire
    assert d.angles.dtype == np.float64
    a_min, inc = float(np.float32(-math.pi / 2)), float(np.float32(math.pi / 4))
    assert d.angles == pytest.approx(a_min + inc * np.arange(5), abs=1e-12)
    xy, idx = d.points()
    assert idx.tolist() == [0, 2, 4]
    expected = [[4.0 * math.cos(a_min + 4 * inc), 4.0 * math.sin(a_min + 4 * inc)]]
    assert xy.shape == (3, 2)
    assert xy[0] == pytest.approx([0.0, -1.0], abs=1e-6)
    assert xy[1] == pytest.approx([2.0, 0.0], abs=1e-6)
    assert xy[2] == pytest.approx(expected[0], abs=1e-12)
    assert d.angle_max == pytest.approx(msg.angle_max, abs=1e-6)


def test_scan_round_trip_through_serialization():
    ranges = np.array([0.5, 1.25, INF, -INF, NAN, 3.0, 7.75], dtype=np.float32)
    inten = np.array([10, 20, 0, 0, 0, 30, 40], dtype=np.float32)
    msg = c.make_scan(1_700_000_000_000_000_001, 'base_scan', -1.5, 0.5, ranges, 0.2, 8.0,
                      time_increment=1e-4, scan_time=0.1, intensities=inten)
    assert msg.angle_max == pytest.approx(-1.5 + 6 * 0.5, abs=1e-6)
    back = wire(msg)
    d = c.scan_to_data(back)
    assert d.stamp_ns == 1_700_000_000_000_000_001
    assert d.frame_id == 'base_scan'
    assert d.angle_min == -1.5 and d.angle_increment == 0.5
    assert d.range_min == pytest.approx(0.2, abs=1e-7) and d.range_max == 8.0
    assert d.time_increment == pytest.approx(1e-4, rel=1e-6)
    assert d.scan_time == pytest.approx(0.1, rel=1e-6)
    np.testing.assert_array_equal(d.ranges, ranges.astype(np.float64))  # NaN == NaN here
    np.testing.assert_array_equal(d.intensities, inten)
    # ScanData -> LaserScan -> ScanData is lossless.
    d2 = c.scan_to_data(wire(c.data_to_scan(d)))
    for f in dataclasses.fields(c.ScanData):
        a, b = getattr(d, f.name), getattr(d2, f.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b, f.name


def test_scan_in_process_equals_received():
    # float32 rounding must not change classification between in-process and wire messages.
    msg = LaserScan(angle_min=-0.3, angle_max=0.3, angle_increment=0.3, range_min=0.1,
                    range_max=30.1, ranges=[30.1, 0.1, 30.100002])
    here, there = c.scan_to_data(msg), c.scan_to_data(wire(msg))
    assert here.valid.tolist() == there.valid.tolist() == [True, True, False]
    assert here.no_return.tolist() == [False, False, True]
    assert here.range_max == there.range_max and here.angle_increment == there.angle_increment
    np.testing.assert_array_equal(here.angles, there.angles)
    r = c.make_range(0, 'sonar', 4.1, 0.5, 0.1, 4.1)
    assert c.range_to_value(r) == c.range_to_value(wire(r))
    assert c.range_to_value(r).status == 'valid'


def test_scan_data_is_frozen_and_read_only():
    d = c.scan_to_data(c.make_scan(0, 'laser', 0.0, 0.1, [1.0, 2.0], 0.1, 5.0))
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.range_max = 3.0
    with pytest.raises(ValueError):
        d.ranges[0] = 5.0
    assert d.intensities.shape == (0,)


def _good_scan(n=11):
    return c.make_scan(0, 'laser', -1.0, 0.2, np.ones(n), 0.1, 10.0)


def test_scan_beam_count_tolerance():
    msg = _good_scan()
    assert c.scan_to_data(msg).ranges.size == 11
    for n in (10, 12):  # the usual off-by-one between drivers is accepted
        msg.ranges = np.ones(n, dtype=np.float32)
        assert c.scan_to_data(msg).ranges.size == n


def _mutated(**fields):
    msg = _good_scan()
    for k, v in fields.items():
        setattr(msg, k, v)
    return msg


@pytest.mark.parametrize('fields, pattern', [
    ({'ranges': np.ones(8, dtype=np.float32)}, r'len\(ranges\)=8 but angle fields imply 11'),
    ({'ranges': np.ones(14, dtype=np.float32)}, r'len\(ranges\)=14 but angle fields imply 11'),
    ({'angle_increment': 0.0}, 'angle_increment=0.0 must be > 0'),
    ({'angle_increment': -0.2}, 'angle_increment=.* must be > 0'),
    ({'angle_increment': NAN}, 'angle_increment=nan must be finite'),
    ({'angle_min': NAN}, 'angle_min=nan must be finite'),
    ({'angle_max': INF}, 'angle_max=inf must be finite'),
    ({'angle_max': -2.0}, 'angle_max=-2.0 < angle_min'),
    ({'range_max': 0.05}, 'range_max=.* must be > range_min'),
    ({'range_max': 0.1}, 'range_max=.* must be > range_min'),
    ({'range_min': -1.0}, 'range_min=-1.0 must be >= 0'),
    ({'range_max': NAN}, 'range_max=nan must be finite'),
    ({'scan_time': INF}, 'scan_time=inf must be finite'),
    ({'intensities': np.ones(3, dtype=np.float32)}, r'len\(intensities\)=3'),
])
def test_scan_bad_inputs_raise(fields, pattern):
    with pytest.raises(ConversionError, match='^LaserScan: ' + pattern):
        c.scan_to_data(_mutated(**fields))


def test_make_scan_rejects_bad_inputs():
    with pytest.raises(ConversionError, match='angle_increment'):
        c.make_scan(0, 'laser', 0.0, -0.1, [1.0, 2.0], 0.1, 5.0)
    with pytest.raises(ConversionError, match='range_max'):
        c.make_scan(0, 'laser', 0.0, 0.1, [1.0, 2.0], 5.0, 1.0)
    with pytest.raises(ConversionError, match='intensities'):
        c.make_scan(0, 'laser', 0.0, 0.1, [1.0, 2.0], 0.1, 5.0, intensities=[1.0])
    with pytest.raises(ConversionError, match='angle_min'):
        c.make_scan(0, 'laser', NAN, 0.1, [1.0, 2.0], 0.1, 5.0)
    assert isinstance(ConversionError('x'), ValueError)


def test_empty_scan():
    msg = c.make_scan(0, 'laser', 0.0, 0.1, [], 0.1, 5.0)
    d = c.scan_to_data(wire(msg))
    assert d.ranges.shape == (0,) and d.points()[0].shape == (0, 2)


# ------------------------------------------------------------------ Odometry / poses


def _spd(rng, n=3):
    a = rng.normal(size=(n, n))
    return a @ a.T + 0.1 * np.eye(n)


def test_odometry_round_trip_and_covariance_placement():
    rng = np.random.default_rng(3)
    cov = _spd(rng)
    tcov = _spd(rng)
    pose = np.array([1.5, -2.25, 3.1])
    twist = np.array([0.4, -0.05, 0.3])
    msg = c.make_odometry(42, 'odom', 'base_link', pose, cov, twist, tcov)
    c6 = np.array(msg.pose.covariance).reshape(6, 6)
    idx = [0, 1, 5]
    assert c6[np.ix_(idx, idx)] == pytest.approx(cov, abs=1e-15)
    assert c6[0, 5] == cov[0, 2] and c6[5, 1] == cov[2, 1] and c6[5, 5] == cov[2, 2]
    assert np.diag(c6)[2:5] == pytest.approx([1e6] * 3, abs=0)
    off = c6.copy()
    off[np.ix_(idx, idx)] = 0.0
    np.fill_diagonal(off, 0.0)
    assert np.all(off == 0.0)
    t6 = np.array(msg.twist.covariance).reshape(6, 6)
    assert t6[np.ix_(idx, idx)] == pytest.approx(tcov, abs=1e-15)
    assert msg.pose.pose.position.z == 0.0

    d = c.odometry_to_pose(wire(msg))
    assert (d.stamp_ns, d.frame_id, d.child_frame_id) == (42, 'odom', 'base_link')
    assert d.pose == pytest.approx(pose, abs=1e-12)
    assert d.covariance == pytest.approx(cov, abs=1e-15)
    assert d.twist == pytest.approx(twist, abs=1e-15)
    assert d.twist_covariance == pytest.approx(tcov, abs=1e-15)


def test_odometry_defaults_unused_variance_and_3d_yaw():
    msg = c.make_odometry(0, 'odom', 'base_link', [0.0, 0.0, -0.5], unused_variance=0.0)
    assert np.all(np.array(msg.pose.covariance) == 0.0)
    d = c.odometry_to_pose(msg)
    assert d.covariance.shape == (3, 3) and np.all(d.covariance == 0.0)
    assert d.twist.tolist() == [0.0, 0.0, 0.0]
    # A tilted robot: yaw of the full 3D rotation.
    x, y, z, w = Rotation.from_euler('ZYX', [2.0, 0.2, -0.3]).as_quat()
    msg.pose.pose.orientation.x, msg.pose.pose.orientation.y = x, y
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = z, w
    assert c.odometry_to_pose(msg).pose[2] == pytest.approx(2.0, abs=1e-12)


def test_odometry_bad_inputs():
    with pytest.raises(ConversionError, match='covariance3 must be 3x3'):
        c.make_odometry(0, 'odom', 'base_link', [0, 0, 0], np.eye(2))
    with pytest.raises(ConversionError, match='covariance3 must be symmetric'):
        c.make_odometry(0, 'odom', 'base_link', [0, 0, 0], [[1, 2, 0], [0, 1, 0], [0, 0, 1]])
    with pytest.raises(ConversionError, match='covariance3 must be finite'):
        c.make_odometry(0, 'odom', 'base_link', [0, 0, 0], np.diag([1.0, NAN, 1.0]))
    with pytest.raises(ConversionError, match='pose'):
        c.make_odometry(0, 'odom', 'base_link', [0, 0])
    with pytest.raises(ConversionError, match='twist'):
        c.make_odometry(0, 'odom', 'base_link', [0, 0, 0], twist=[INF, 0, 0])
    msg = Odometry()
    msg.pose.pose.orientation.w = 0.0
    with pytest.raises(ConversionError, match='^Odometry: orientation quaternion is all zero'):
        c.odometry_to_pose(msg)
    msg.pose.pose.orientation.w = 1.0
    msg.pose.pose.position.x = NAN
    with pytest.raises(ConversionError, match='^Odometry: pose contains non-finite'):
        c.odometry_to_pose(msg)


def test_pose_with_covariance_stamped_round_trip():
    cov = np.array([[0.04, 0.01, 0.002], [0.01, 0.09, -0.003], [0.002, -0.003, 0.0025]])
    msg = c.make_pose_with_covariance_stamped(7_000_000_001, 'map', [3.0, 4.0, -3.0], cov)
    assert isinstance(msg, PoseWithCovarianceStamped)
    c6 = np.array(msg.pose.covariance).reshape(6, 6)
    assert (c6[0, 0], c6[0, 1], c6[1, 5], c6[5, 5]) == (0.04, 0.01, -0.003, 0.0025)
    assert (c6[2, 2], c6[3, 3], c6[4, 4], c6[2, 5]) == (1e6, 1e6, 1e6, 0.0)
    d = c.pose_with_covariance_to_pose(wire(msg))
    assert (d.stamp_ns, d.frame_id) == (7_000_000_001, 'map')
    assert d.pose == pytest.approx([3.0, 4.0, -3.0], abs=1e-12)
    assert d.covariance == pytest.approx(cov, abs=1e-15)
    assert d.twist is None and d.twist_covariance is None


def test_quaternion_msg_from_yaw():
    q = c.quaternion_msg_from_yaw(0.3)
    assert (q.x, q.y) == (0.0, 0.0)
    assert q.z == pytest.approx(math.sin(0.15), abs=1e-15)
    assert q.w == pytest.approx(math.cos(0.15), abs=1e-15)
    wire(q)


# ------------------------------------------------------------------ Range


@pytest.mark.parametrize('value, status', [
    (1.0, 'valid'), (0.02, 'valid'), (4.0, 'valid'),
    (INF, 'no_return'), (4.5, 'no_return'),
    (-INF, 'too_close'), (0.01, 'too_close'),
    (NAN, 'error'),
])
def test_range_statuses(value, status):
    msg = c.make_range(9, 'sonar', value, 0.5, 0.02, 4.0)
    r = c.range_to_value(wire(msg))
    assert r.status == status
    assert (r.stamp_ns, r.frame_id) == (9, 'sonar')
    stamp_ns, frame_id, val, st_ = r  # plain tuple unpacking
    if math.isnan(value):
        assert math.isnan(val)
    else:
        assert val == pytest.approx(value, rel=1e-6)


def test_range_fixed_distance_and_errors():
    msg = c.make_range(0, 'ir', -INF, 0.1, 0.3, 0.3, Range.INFRARED)
    assert msg.radiation_type == Range.INFRARED
    assert c.range_to_value(msg).status == 'too_close'  # detection within fixed distance
    msg.range = INF
    assert c.range_to_value(msg).status == 'no_return'
    msg.range = 0.3
    assert c.range_to_value(msg).status == 'valid'
    with pytest.raises(ConversionError, match='radiation_type'):
        c.make_range(0, 'ir', 1.0, 0.1, 0.1, 2.0, radiation_type=7)
    with pytest.raises(ConversionError, match='min_range'):
        c.make_range(0, 'ir', 1.0, 0.1, 3.0, 2.0)
    with pytest.raises(ConversionError, match='field_of_view'):
        c.make_range(0, 'ir', 1.0, NAN, 0.1, 2.0)
    msg.max_range = NAN
    with pytest.raises(ConversionError, match='^Range: max_range'):
        c.range_to_value(msg)


# ------------------------------------------------------------------ Image


def _random_image(encoding, h=5, w=7, seed=0):
    rng = np.random.default_rng(seed)
    if encoding in ('16UC1', 'mono16'):
        return rng.integers(0, 65536, size=(h, w), dtype=np.uint16)
    shape = (h, w, 3) if encoding in ('rgb8', 'bgr8') else (h, w)
    return rng.integers(0, 256, size=shape, dtype=np.uint8)


@pytest.mark.parametrize('encoding', ['mono8', 'rgb8', 'bgr8', '16UC1', 'mono16'])
def test_image_round_trip(encoding):
    arr = _random_image(encoding)
    msg = c.array_to_image(arr, encoding, stamp_ns=12, frame_id='cam')
    assert (msg.height, msg.width, msg.encoding, msg.is_bigendian) == (5, 7, encoding, 0)
    assert msg.step == 7 * arr.itemsize * (3 if arr.ndim == 3 else 1)
    out = c.image_to_array(wire(msg))
    assert out.dtype == arr.dtype and out.dtype.isnative
    np.testing.assert_array_equal(out, arr)
    assert out.flags.c_contiguous and out.flags.writeable and out.flags.owndata


def test_image_bgr_is_passthrough():
    arr = np.zeros((1, 2, 3), dtype=np.uint8)
    arr[0, 0] = [1, 2, 3]
    msg = c.array_to_image(arr, 'bgr8')
    assert list(msg.data[:3]) == [1, 2, 3]
    assert c.image_to_array(msg)[0, 0].tolist() == [1, 2, 3]


@pytest.mark.parametrize('encoding, pad', [('mono8', 3), ('rgb8', 5), ('bgr8', 1),
                                           ('16UC1', 4), ('mono16', 1)])
def test_image_padded_step(encoding, pad):
    arr = _random_image(encoding, h=4, w=3, seed=1)
    row = arr.reshape(arr.shape[0], -1).astype(arr.dtype.newbyteorder('<'))
    row_bytes = row.shape[1] * arr.itemsize
    buf = bytearray()
    for r in row:
        buf += r.tobytes() + bytes([0xAB] * pad)  # garbage in the padding
    msg = Image(height=4, width=3, encoding=encoding, is_bigendian=0, step=row_bytes + pad,
                data=bytes(buf))
    np.testing.assert_array_equal(c.image_to_array(wire(msg)), arr)


@pytest.mark.parametrize('pad', [0, 2, 3])
def test_image_big_endian_16uc1(pad):
    arr = np.array([[1, 256, 0x1234], [0xFFFF, 0x00FF, 0xFF00]], dtype=np.uint16)
    rows = b''.join(r.astype('>u2').tobytes() + b'\x7f' * pad for r in arr)
    msg = Image(height=2, width=3, encoding='16UC1', is_bigendian=1, step=6 + pad, data=rows)
    out = c.image_to_array(wire(msg))
    assert out.dtype == np.uint16 and out.dtype.isnative
    np.testing.assert_array_equal(out, arr)
    # The writer can produce big-endian too, and it reads back identically.
    big = c.array_to_image(arr, '16UC1', is_bigendian=True)
    assert big.is_bigendian == 1 and bytes(big.data[:2]) == b'\x00\x01'
    np.testing.assert_array_equal(c.image_to_array(big), arr)


def test_image_errors():
    ok = c.array_to_image(np.zeros((2, 3), np.uint8), 'mono8')
    msg = Image(height=2, width=3, encoding='32FC1', step=12, data=bytes(24))
    with pytest.raises(ConversionError, match="^Image: unsupported encoding '32FC1'"):
        c.image_to_array(msg)
    ok.data = bytes(5)
    with pytest.raises(ConversionError, match=r'^Image: len\(data\)=5 but step\*height'):
        c.image_to_array(ok)
    msg = Image(height=2, width=3, encoding='rgb8', step=8, data=bytes(16))
    with pytest.raises(ConversionError, match=r'^Image: step=8 < width\*bytes_per_pixel=9'):
        c.image_to_array(msg)
    with pytest.raises(ConversionError, match='dtype'):
        c.array_to_image(np.zeros((2, 3), np.uint16), 'mono8')
    with pytest.raises(ConversionError, match='shape'):
        c.array_to_image(np.zeros((2, 3), np.uint8), 'rgb8')
    with pytest.raises(ConversionError, match='unsupported encoding'):
        c.array_to_image(np.zeros((2, 3), np.uint8), 'yuv422')


# ------------------------------------------------------------------ OccupancyGrid


def test_occupancy_grid_round_trip_non_square():
    data = np.array([[-1, 0, 100, 50, -1],
                     [0, 0, 0, 0, 0],
                     [100, -1, 7, 0, 1]], dtype=np.int8)
    origin = [-10.0, -5.5, 0.25]
    msg = c.make_occupancy_grid(data, 0.05, origin, stamp_ns=3_000_000_000)
    assert (msg.info.width, msg.info.height, msg.header.frame_id) == (5, 3, 'map')
    assert list(msg.data[:5]) == [-1, 0, 100, 50, -1]  # row 0 first (at the origin)
    d = c.grid_to_data(wire(msg))
    assert d.data.dtype == np.int8 and d.data.shape == (3, 5)
    assert (d.height, d.width) == (3, 5)
    np.testing.assert_array_equal(d.data, data)
    assert d.resolution == pytest.approx(0.05, rel=1e-7)
    assert d.origin == pytest.approx(origin, abs=1e-12)
    assert (d.stamp_ns, d.frame_id) == (3_000_000_000, 'map')
    tall = np.full((7, 2), -1, dtype=np.int16)
    np.testing.assert_array_equal(
        c.grid_to_data(c.make_occupancy_grid(tall, 0.1, [0, 0, 0])).data, tall)


def test_occupancy_grid_errors():
    msg = c.make_occupancy_grid(np.zeros((2, 3), np.int8), 0.1, [0, 0, 0])
    msg.info.width = 4
    with pytest.raises(ConversionError, match=r'^OccupancyGrid: len\(data\)=6 but width\*height'):
        c.grid_to_data(msg)
    msg = OccupancyGrid()
    msg.info.resolution = 0.0
    with pytest.raises(ConversionError, match='resolution'):
        c.grid_to_data(msg)
    with pytest.raises(ConversionError, match=r'\[-1, 100\]'):
        c.make_occupancy_grid(np.array([[0, 101]]), 0.1, [0, 0, 0])
    with pytest.raises(ConversionError, match=r'\[-1, 100\]'):
        c.make_occupancy_grid(np.array([[-2, 0]]), 0.1, [0, 0, 0])
    with pytest.raises(ConversionError, match='2D'):
        c.make_occupancy_grid(np.zeros(4, np.int8), 0.1, [0, 0, 0])
    with pytest.raises(ConversionError, match='resolution'):
        c.make_occupancy_grid(np.zeros((2, 2), np.int8), -0.1, [0, 0, 0])


# ------------------------------------------------------------------ JointState


def test_joint_state():
    msg = c.make_joint_state(11, ['left_wheel', 'right_wheel'], [0.5, -1.0], [2.0, 3.0])
    back = wire(msg)
    assert isinstance(back, JointState)
    assert list(back.name) == ['left_wheel', 'right_wheel']
    assert list(back.position) == [0.5, -1.0] and list(back.velocity) == [2.0, 3.0]
    assert c.stamp_to_ns(back.header.stamp) == 11
    assert list(c.make_joint_state(0, ['a'], [1.0], None).velocity) == []
    with pytest.raises(ConversionError, match=r'len\(positions\)=1'):
        c.make_joint_state(0, ['a', 'b'], [1.0], [1.0, 2.0])
    with pytest.raises(ConversionError, match=r'len\(velocities\)=1'):
        c.make_joint_state(0, ['a', 'b'], [1.0, 2.0], [1.0])


def test_all_builders_serialize():
    msgs = [
        c.make_scan(1, 'laser', -1.0, 0.1, np.ones(21), 0.1, 5.0),
        c.make_odometry(1, 'odom', 'base_link', [1, 2, 3]),
        c.make_pose_with_covariance_stamped(1, 'map', [1, 2, 3]),
        c.make_range(1, 'sonar', 1.0, 0.3, 0.1, 3.0),
        c.array_to_image(np.zeros((2, 2, 3), np.uint8), 'rgb8'),
        c.make_occupancy_grid(np.zeros((2, 2), np.int8), 0.1, [0, 0, 0]),
        c.make_joint_state(1, ['a'], [0.0], [0.0]),
    ]
    types = [LaserScan, Odometry, PoseWithCovarianceStamped, Range, Image, OccupancyGrid,
             JointState]
    for msg, typ in zip(msgs, types):
        assert isinstance(msg, typ)
        assert len(serialize_message(msg)) > 0
