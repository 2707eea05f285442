"""Laser features (corners, lines) to and from standard ROS messages.

Encodings (documented in docs/laser_features.md, Topics):

* Corners: ``geometry_msgs/PoseArray`` (position = corner, orientation = yaw of the
  free-space bisector) plus ``sensor_msgs/PointCloud2`` with one point per corner and the
  float64 fields ``x y z bisector opening cov_xx cov_xy cov_yy time structural`` (z = 0;
  covariance of the position in m^2; ``time`` = the corner beam's time after the header
  stamp [s], beam index times the scan's ``time_increment``, 0 when the scan has none;
  ``structural`` 1 when both arms are at least 0.2 m long and 6 beams wide, else 0:
  ``Corner.structural``) -- the PointCloud2 carries what a PoseArray cannot. Float64, so
  that the SLAM node sees the same numbers as the offline evaluation (float32 would move a
  corner by up to 0.1 um).
* Lines: ``sensor_msgs/PointCloud2`` with one point per line and the float32 fields
  ``x y z rho alpha x1 y1 x2 y2 cov_rr cov_ra cov_aa num_points rmse``: (x, y) is the
  segment midpoint (so RViz shows it), (rho, alpha) the Hessian normal form
  ``x cos(alpha) + y sin(alpha) = rho`` with rho >= 0, (x1, y1)-(x2, y2) the endpoints,
  cov_* the covariance of (rho, alpha). Segments of one surface on both sides of an
  occluder carry one fit (equal rho, alpha, cov_*, num_points and rmse; num_points counts
  the points of both sides): one measurement, which a consumer must not count twice.
* RViz: ``visualization_msgs/MarkerArray`` (a DELETEALL then the features).
"""

from typing import Dict, Sequence

from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point, Pose, PoseArray
from landmark_nav.conversions import ConversionError, ns_to_stamp, quaternion_msg_from_yaw
from landmark_nav.geometry import covariance_ellipse
import numpy as np
from sensor_msgs.msg import PointCloud2, PointField
from visualization_msgs.msg import Marker, MarkerArray

CORNER_FIELDS = ('x', 'y', 'z', 'bisector', 'opening', 'cov_xx', 'cov_xy', 'cov_yy', 'time',
                 'structural')
LINE_FIELDS = ('x', 'y', 'z', 'rho', 'alpha', 'x1', 'y1', 'x2', 'y2', 'cov_rr', 'cov_ra',
               'cov_aa', 'num_points', 'rmse')


def make_feature_cloud(stamp_ns: int, frame_id: str, names: Sequence[str],
                       columns: Dict[str, np.ndarray], float64: bool = False) -> PointCloud2:
    """Pack equal-length float columns into an unordered PointCloud2.

    The fields are float32, or float64 with ``float64``.
    """
    n = len(columns[names[0]]) if names else 0
    size, kind = (8, PointField.FLOAT64) if float64 else (4, PointField.FLOAT32)
    table = np.zeros((n, len(names)), dtype=f'<f{size}')
    for j, name in enumerate(names):
        table[:, j] = np.asarray(columns[name], dtype=float)
    msg = PointCloud2()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    msg.height, msg.width = 1, n
    msg.fields = [PointField(name=name, offset=size * j, datatype=kind, count=1)
                  for j, name in enumerate(names)]
    msg.is_bigendian = False
    msg.point_step = size * len(names)
    msg.row_step = msg.point_step * n
    msg.is_dense = True
    msg.data = table.tobytes()
    return msg


def feature_cloud_to_arrays(msg: PointCloud2) -> Dict[str, np.ndarray]:
    """Unpack a float32 / float64 PointCloud2 into {field name: (N,) float64 array}.

    Raises:
        ConversionError: Fields neither float32 nor float64 scalars, a field beyond the
            point, big-endian data or inconsistent sizes.

    """
    n = msg.width * msg.height
    if msg.is_bigendian:
        raise ConversionError('PointCloud2: big-endian features are not supported')
    if len(msg.data) != msg.row_step * msg.height or msg.point_step * n > len(msg.data):
        raise ConversionError(f'PointCloud2: {len(msg.data)} data bytes for {n} points of '
                              f'{msg.point_step} bytes')
    out = {}
    sizes = {PointField.FLOAT32: 4, PointField.FLOAT64: 8}
    fields = msg.fields
    size = sizes.get(fields[0].datatype) if fields else None
    if (size is not None and n and msg.point_step == size * len(fields)
            and all(f.datatype == fields[0].datatype and f.count == 1 and f.offset == size * j
                    for j, f in enumerate(fields))):
        # Packed columns of one type (the clouds this package writes): one view, no copy.
        table = np.frombuffer(msg.data, dtype=f'<f{size}', count=n * len(fields))
        table = table.reshape(n, len(fields)).astype(float)
        return {f.name: table[:, j] for j, f in enumerate(fields)}
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    rows = raw[: msg.point_step * n].reshape(n, msg.point_step) if n else raw[:0].reshape(0, 0)
    for field in msg.fields:
        size = sizes.get(field.datatype)
        if size is None or field.count != 1:
            raise ConversionError(f'PointCloud2: field {field.name} is not a float32 or '
                                  f'float64 scalar')
        if field.offset + size > msg.point_step:
            raise ConversionError(f'PointCloud2: field {field.name} at offset {field.offset} '
                                  f'does not fit in a point of {msg.point_step} bytes')
        if n:
            out[field.name] = rows[:, field.offset:field.offset + size].copy().view(
                f'<f{size}')[:, 0].astype(float)
        else:
            out[field.name] = np.zeros(0)
    return out


def make_corner_pose_array(stamp_ns: int, frame_id: str, corners) -> PoseArray:
    """Corners as PoseArray: position and the bisector as yaw."""
    msg = PoseArray()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    for c in corners:
        pose = Pose()
        pose.position.x, pose.position.y = float(c.position[0]), float(c.position[1])
        pose.orientation = quaternion_msg_from_yaw(float(c.bisector))
        msg.poses.append(pose)
    return msg


def make_corner_cloud(stamp_ns: int, frame_id: str, corners,
                      time_increment: float = 0.0) -> PointCloud2:
    """Corners with bisector, opening, covariance, beam time and label as a PointCloud2.

    ``time`` = the corner's beam index times ``time_increment`` (the scan's) [s].
    """
    cols = {
        'x': [c.position[0] for c in corners], 'y': [c.position[1] for c in corners],
        'z': [0.0] * len(corners), 'bisector': [c.bisector for c in corners],
        'opening': [c.opening for c in corners],
        'cov_xx': [c.covariance[0, 0] for c in corners],
        'cov_xy': [c.covariance[0, 1] for c in corners],
        'cov_yy': [c.covariance[1, 1] for c in corners],
        'time': [float(time_increment) * c.index for c in corners],
        'structural': [float(c.structural) for c in corners]}
    return make_feature_cloud(stamp_ns, frame_id, CORNER_FIELDS, cols, float64=True)


def make_line_cloud(stamp_ns: int, frame_id: str, lines) -> PointCloud2:
    """Lines (rho, alpha, endpoints, covariance, support) as a PointCloud2."""
    start = np.array([ln.start for ln in lines]).reshape(-1, 2)
    end = np.array([ln.end for ln in lines]).reshape(-1, 2)
    mid = 0.5 * (start + end)
    cols = {
        'x': mid[:, 0], 'y': mid[:, 1], 'z': np.zeros(len(lines)),
        'rho': [ln.rho for ln in lines], 'alpha': [ln.alpha for ln in lines],
        'x1': start[:, 0], 'y1': start[:, 1], 'x2': end[:, 0], 'y2': end[:, 1],
        'cov_rr': [ln.covariance[0, 0] for ln in lines],
        'cov_ra': [ln.covariance[0, 1] for ln in lines],
        'cov_aa': [ln.covariance[1, 1] for ln in lines],
        'num_points': [ln.num_points for ln in lines], 'rmse': [ln.rmse for ln in lines]}
    return make_feature_cloud(stamp_ns, frame_id, LINE_FIELDS, cols)


def _marker(stamp_ns: int, frame_id: str, ns: str, marker_id: int, kind: int,
            rgb: Sequence[float], scale: float) -> Marker:
    m = Marker()
    m.header.stamp = ns_to_stamp(stamp_ns)
    m.header.frame_id = frame_id
    m.ns, m.id, m.type, m.action = ns, marker_id, kind, Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = scale
    m.color.r, m.color.g, m.color.b = (float(v) for v in rgb)
    m.color.a = 1.0
    m.lifetime = Duration(sec=0, nanosec=0)
    return m


def _clear() -> Marker:
    m = Marker()
    m.action = Marker.DELETEALL
    return m


def make_corner_markers(stamp_ns: int, frame_id: str, corners,
                        arrow_length: float = 0.3) -> MarkerArray:
    """Build RViz markers: corner points and a bisector tick per corner."""
    points = _marker(stamp_ns, frame_id, 'corners', 0, Marker.SPHERE_LIST, (1.0, 0.5, 0.0), 0.08)
    ticks = _marker(stamp_ns, frame_id, 'corner_bisectors', 1, Marker.LINE_LIST,
                    (1.0, 0.5, 0.0), 0.015)
    for c in corners:
        x, y = float(c.position[0]), float(c.position[1])
        points.points.append(Point(x=x, y=y))
        ticks.points.append(Point(x=x, y=y))
        ticks.points.append(Point(x=x + arrow_length * float(np.cos(c.bisector)),
                                  y=y + arrow_length * float(np.sin(c.bisector))))
    return MarkerArray(markers=[_clear(), points, ticks])


def make_line_markers(stamp_ns: int, frame_id: str, lines) -> MarkerArray:
    """Build RViz markers: one LINE_LIST with every segment."""
    segs = _marker(stamp_ns, frame_id, 'lines', 0, Marker.LINE_LIST, (0.1, 0.6, 1.0), 0.03)
    for ln in lines:
        segs.points.append(Point(x=float(ln.start[0]), y=float(ln.start[1])))
        segs.points.append(Point(x=float(ln.end[0]), y=float(ln.end[1])))
    return MarkerArray(markers=[_clear(), segs])


def make_landmark_markers(stamp_ns: int, frame_id: str, ids, positions, covariances,
                          sigmas: float = 2.0, line_ids=(), line_ends=()) -> MarkerArray:
    """Build RViz markers: an ellipse per point landmark, a segment per line landmark.

    The ``sigmas``-sigma ellipse (LINE_STRIP, namespace ``landmark_ellipses``) of each point
    landmark, the seen extent (LINE_STRIP, namespace ``landmark_lines``) of each line
    landmark; marker id = the landmark's id.
    """
    out = MarkerArray(markers=[_clear()])
    for lid, mean, cov in zip(ids, positions, covariances):
        mk = _marker(stamp_ns, frame_id, 'landmark_ellipses', int(lid), Marker.LINE_STRIP,
                     (0.0, 0.0, 1.0), 0.01)
        mk.points = [Point(x=float(x), y=float(y))
                     for x, y in covariance_ellipse(mean, cov, sigmas, 25)]
        out.markers.append(mk)
    for lid, ends in zip(line_ids, line_ends):
        mk = _marker(stamp_ns, frame_id, 'landmark_lines', int(lid), Marker.LINE_STRIP,
                     (0.0, 0.3, 1.0), 0.03)
        mk.points = [Point(x=float(x), y=float(y)) for x, y in np.asarray(ends).reshape(2, 2)]
        out.markers.append(mk)
    return out
