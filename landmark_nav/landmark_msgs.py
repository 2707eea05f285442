"""Visual landmarks to and from standard ROS messages (the landmark_detector's encodings).

* Images in: sensor_msgs/Image (mono8, bgr8, rgb8 or mono16) and
  sensor_msgs/CompressedImage (any format OpenCV decodes, e.g. jpeg, png) become a 2-D uint8
  grey image (:func:`image_to_gray`, :func:`compressed_to_gray`).
* Detections out, with the image's stamp and the camera optical frame:
  ``visualization_msgs/MarkerArray`` (:func:`make_landmark_markers`: a DELETEALL, then per
  landmark a thin CUBE of the printed frame at the landmark pose, ``id = code``, namespace
  ``landmarks``, and a TEXT_VIEW_FACING marker with the code, same id, namespace
  ``landmark_codes``) and ``geometry_msgs/PoseArray`` (:func:`make_landmark_pose_array`:
  landmark poses in detection order -- the codes are the marker ids).
* Robot fixes: ``geometry_msgs/PoseWithCovarianceStamped`` of ``base_link`` in ``map`` with
  the full 6 x 6 covariance over (x, y, z, roll, pitch, yaw)
  (:func:`make_pose_with_covariance_6d`).
"""

from typing import Sequence

from builtin_interfaces.msg import Duration
import cv2
from geometry_msgs.msg import Pose, PoseArray, PoseWithCovarianceStamped
from landmark_nav.conversions import ConversionError, image_to_array, ns_to_stamp
from landmark_nav.vision.localize import rpy_matrix
import numpy as np
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

GRAY_ENCODINGS = ('mono8', 'bgr8', 'rgb8', 'mono16')


def image_to_gray(msg: Image, reader: str = 'this node') -> np.ndarray:
    """Return a sensor_msgs/Image as a 2-D uint8 grey image.

    mono8 as is; bgr8/rgb8 converted with OpenCV's luma weights; mono16 scaled by 1/257.
    ``reader`` (e.g. the node's name) is named in the error of an unsupported encoding.

    Raises:
        ConversionError: an encoding other than mono8, bgr8, rgb8, mono16, or a malformed
            message (see :func:`landmark_nav.conversions.image_to_array`).
    """
    if msg.encoding not in GRAY_ENCODINGS:
        raise ConversionError(f'Image: encoding {msg.encoding!r} is not supported by '
                              f'{reader}; use one of {", ".join(GRAY_ENCODINGS)}')
    arr = image_to_array(msg)
    if msg.encoding == 'bgr8':
        return cv2.cvtColor(arr, cv2.COLOR_BGR2GRAY)
    if msg.encoding == 'rgb8':
        return cv2.cvtColor(arr, cv2.COLOR_RGB2GRAY)
    if msg.encoding == 'mono16':
        return (arr.astype(np.uint32) * 255 // 65535).astype(np.uint8)
    return arr


def compressed_to_gray(msg: CompressedImage) -> np.ndarray:
    """Decode a sensor_msgs/CompressedImage to a 2-D uint8 grey image.

    Raises:
        ConversionError: empty or undecodable data.
    """
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if data.size == 0:
        raise ConversionError('CompressedImage: empty data')
    img = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ConversionError(f'CompressedImage: cannot decode {data.size} bytes of format '
                              f'{msg.format!r}')
    return img


def _header(stamp_ns: int, frame_id: str) -> Header:
    return Header(stamp=ns_to_stamp(stamp_ns), frame_id=str(frame_id))


def pose_msg(rotation: np.ndarray, translation: np.ndarray) -> Pose:
    """Return a geometry_msgs/Pose for a 3 x 3 rotation and a translation (w >= 0)."""
    from scipy.spatial.transform import Rotation  # on first use: ~0.6 CPU-s to import
    q = Rotation.from_matrix(np.asarray(rotation, dtype=float)).as_quat()
    if q[3] < 0:
        q = -q
    msg = Pose()
    msg.position.x, msg.position.y, msg.position.z = (float(v) for v in translation)
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = \
        (float(v) for v in q)
    return msg


def make_landmark_pose_array(stamp_ns: int, frame_id: str, poses: Sequence) -> PoseArray:
    """Return the landmark poses (each ``(rotation, translation)``) as a PoseArray."""
    msg = PoseArray()
    msg.header = _header(stamp_ns, frame_id)
    msg.poses = [pose_msg(r, t) for r, t in poses]
    return msg


def make_landmark_markers(stamp_ns: int, frame_id: str, codes: Sequence[int], poses: Sequence,
                          frame_width: float, lifetime_s: float = 0.5) -> MarkerArray:
    """Return RViz markers: a DELETEALL, then a plate and a code label per landmark.

    Args:
        stamp_ns: image stamp [ns].
        frame_id: camera optical frame.
        codes: landmark codes (marker ids; a code is at most 28 bits, an int32).
        poses: ``(rotation, translation)`` of each landmark in ``frame_id``.
        frame_width: printed frame side [m] (plate size).
        lifetime_s: marker lifetime [s].
    """
    out = MarkerArray()
    clear = Marker()
    clear.header = _header(stamp_ns, frame_id)
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    life = Duration(sec=int(lifetime_s), nanosec=int((lifetime_s % 1.0) * 1e9))
    for code, (rot, trans) in zip(codes, poses):
        plate = Marker()
        plate.header = _header(stamp_ns, frame_id)
        plate.ns, plate.id, plate.type, plate.action = 'landmarks', int(code), Marker.CUBE, \
            Marker.ADD
        plate.pose = pose_msg(rot, trans)
        plate.scale.x, plate.scale.y, plate.scale.z = 0.005, float(frame_width), \
            float(frame_width)
        plate.color.r, plate.color.g, plate.color.b, plate.color.a = 0.1, 0.8, 0.2, 0.8
        plate.lifetime = life
        text = Marker()
        text.header = plate.header
        text.ns, text.id, text.type, text.action = 'landmark_codes', int(code), \
            Marker.TEXT_VIEW_FACING, Marker.ADD
        text.pose = pose_msg(np.eye(3), np.asarray(trans, dtype=float)
                             + np.asarray(rot, dtype=float) @ [0.0, 0.0, 0.6 * frame_width])
        text.scale.z = 0.3 * float(frame_width)
        text.color.r = text.color.g = text.color.b = text.color.a = 1.0
        text.text = str(int(code))
        text.lifetime = life
        out.markers += [plate, text]
    return out


def make_pose_with_covariance_6d(stamp_ns: int, frame_id: str, pose6: Sequence[float],
                                 covariance6: np.ndarray) -> PoseWithCovarianceStamped:
    """Return a PoseWithCovarianceStamped of ``[x, y, z, roll, pitch, yaw]`` and a 6 x 6.

    Raises:
        ConversionError: non-finite pose or a covariance that is not a finite 6 x 6.
    """
    p = np.asarray(pose6, dtype=float).reshape(-1)
    c = np.asarray(covariance6, dtype=float)
    if p.shape != (6,) or not np.all(np.isfinite(p)):
        raise ConversionError('PoseWithCovarianceStamped: pose must be 6 finite values')
    if c.shape != (6, 6) or not np.all(np.isfinite(c)):
        raise ConversionError('PoseWithCovarianceStamped: covariance must be a finite 6x6')
    msg = PoseWithCovarianceStamped()
    msg.header = _header(stamp_ns, frame_id)
    msg.pose.pose = pose_msg(rpy_matrix(p[3:]), p[:3])
    msg.pose.covariance = [float(v) for v in (0.5 * (c + c.T)).ravel()]
    return msg


def draw_detections(gray: np.ndarray, detections: Sequence) -> np.ndarray:
    """Return a bgr8 copy of the image with each detection's frame, grid corners and code."""
    out = cv2.cvtColor(np.asarray(gray, dtype=np.uint8), cv2.COLOR_GRAY2BGR)
    for det in detections:
        quad = np.round(det.corners * 16).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(out, [quad], True, (0, 220, 0), 1, cv2.LINE_AA, shift=4)
        for p in det.edge_corners.reshape(-1, 2):
            cv2.circle(out, (int(round(p[0] * 16)), int(round(p[1] * 16))), 2 * 16,
                       (0, 0, 255), 1, cv2.LINE_AA, shift=4)
        tl = det.corners[0]
        cv2.circle(out, (int(round(tl[0] * 16)), int(round(tl[1] * 16))), 4 * 16,
                   (255, 0, 0), 1, cv2.LINE_AA, shift=4)
        org = (int(det.corners[:, 0].min()), max(10, int(det.corners[:, 1].min()) - 4))
        cv2.putText(out, str(det.code), org, cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 255, 255), 1,
                    cv2.LINE_AA)
    return out


__all__ = ['GRAY_ENCODINGS', 'compressed_to_gray', 'draw_detections', 'image_to_gray',
           'make_landmark_markers', 'make_landmark_pose_array', 'make_pose_with_covariance_6d',
           'pose_msg']
