"""Executable ``landmark_detector``: artificial visual landmarks in camera images (§2.2).

Subscribes (sensor-data QoS) ``camera/image_raw`` (sensor_msgs/Image: mono8, bgr8, rgb8,
mono16) -- or ``camera/image_raw/compressed`` (sensor_msgs/CompressedImage) with
``compressed: true`` -- and ``camera/camera_info`` (sensor_msgs/CameraInfo). Publishes, with
the image's stamp and frame (the camera optical frame):

* ``landmarks/markers`` (visualization_msgs/MarkerArray): per landmark a plate at its pose
  (marker id = code) and a text marker with the code;
* ``landmarks/poses`` (geometry_msgs/PoseArray): the landmark poses, same order as the
  markers;
* ``landmark_pose`` (geometry_msgs/PoseWithCovarianceStamped, frame ``map_frame``): when a
  ``landmark_map`` is configured, the pose of ``base_link`` implied by each mapped landmark
  (camera mount from ``camera_mount``), with its 6 x 6 covariance. An ambiguous landmark pose
  (a second pose minimum, the planar flip, that the pixels cannot reject; see
  :func:`~landmark_nav.vision.pose.estimate_pose`) is published with an inflated covariance
  that covers both minima, never as a precise pose;
* ``landmarks/debug_image`` (sensor_msgs/Image, bgr8) with ``publish_debug_image: true``.

Bad input (unsupported encoding, undecodable data, size disagreeing with CameraInfo, no
CameraInfo yet, an image without contrast) is dropped with a warning throttled per kind of
problem; saturated images are processed with a warning. Processed and dropped images and
the latency are on ``/diagnostics`` (:class:`~landmark_nav.nodes.common.InputStats`); a
CameraInfo that does not convert is ignored, counted as ``dropped.camera_info_malformed``.
"""

from dataclasses import replace
import math

from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from landmark_nav.conversions import (array_to_image, camera_info_to_model, ConversionError,
                                      stamp_to_ns)
from landmark_nav.landmark_msgs import (compressed_to_gray, draw_detections, image_to_gray,
                                        make_landmark_markers, make_landmark_pose_array,
                                        make_pose_with_covariance_6d)
from landmark_nav.nodes.common import (declare, declare_dataclass, InputStats, ParameterError,
                                       ProblemWarner, reject_undeclared, run_node,
                                       SENSOR_QOS)
from landmark_nav.vision.detector import detect_landmarks, DetectorParams, image_problem
from landmark_nav.vision.landmark import LandmarkDesign
from landmark_nav.vision.localize import (camera_mount_matrix, LandmarkMapError,
                                          load_landmark_map, robot_pose_from_landmark)
from landmark_nav.vision.pose import estimate_pose, PoseError, PoseParams
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from visualization_msgs.msg import MarkerArray

DETECTOR_PARAMETERS = {
    'sigma': ('std of the 3x3 Gaussian smoothing [px] (chapter: 0.95)', (0.1, 5.0), None),
    'k_min': ('eq1 corner method: fixed part of the corner threshold k_c [grey levels] '
              '(eq. 1: 7)', (0, 255), None),
    'neighbour_fraction': ('neighbour search radius as a fraction of the image height '
                           '(chapter: 0.2)', (0.01, 1.0), None),
    'max_neighbours': ('neighbours per corner (chapter: 8)', (2, 32), None),
    'neighbour_mode': ('closest: the closest corners (chapter); sectors: the closest per '
                       'direction sector (finds foreshortened edges)', None,
                       ['closest', 'sectors']),
    'k_lim': ('eq. 3 corner prediction tolerance, fraction of the spacing (0.37)', (0.01, 1.0),
              None),
    'k_g': ('eq. 3 spacing gain (0.5)', (0.0, 1.0), None),
    'k_p': ('eq. 4 tolerance on opposite edges parallel and equal (0.5)', (0.01, 2.0), None),
    'min_contrast': ('smallest white minus black frame cell mean [grey levels]', (0.0, 255.0),
                     None),
    'min_margin': ('smallest cell distance from the threshold, fraction of half the '
                   'contrast (rejects uncertain codes)', (0.0, 1.0), None),
    'small_block_px': ('frames with a corner spacing below this [px] need small_block_margin',
                       (0.0, 100.0), None),
    'small_block_margin': ('min_margin for such small frames', (0.0, 1.0), None),
    'refine_corners': ('refine the frame corners to sub-pixel saddle points', None, None),
    'refine_edges': ('fit the frame edge lines to sub-pixel edge points', None, None),
    'second_neighbour_angle': ('sectors mode: also keep the second nearest corner of a sector '
                               'whose direction differs by more than this [deg] (acute '
                               'frame corners at strong tilt; 0: off)', (0.0, 45.0), None),
    'max_gaps': ('missed interior corners an edge chain may bridge at its eq. 3 prediction '
                 '(0: the chapter)', (0, 2), None),
    'decimate': ('fast mode: corner filters on the image averaged over decimate x decimate '
                 'pixels, the rest at full resolution (1: off; 2 needs twice the pixels per '
                 'block)', (1, 4), None),
    'refine_grid': ('read a grid that fails again on the sub-pixel frame fit', None, None),
    'block_ring': ('judge the frame consistency on its blocks rather than half-block cells',
                   None, None),
    'deblur_margin': ('ambiguous code: read again with the cell blur unmixed, accept if every '
                      'code cell is this far from the midpoint (0: off)', (0.0, 1.0), None),
    'deblur_residual': ('largest misfit of the cell blur model, fraction of the contrast',
                        (0.0, 1.0), None),
    'unblur_margin': ('still ambiguous: read the code from the pixels (pattern, homography, '
                      'blur model), accept if every code cell is this far from the midpoint '
                      '(1: off)', (0.0, 1.0), None),
    'unblur_residual': ('largest misfit of the pixel blur model, fraction of the contrast',
                        (0.0, 1.0), None),
    'unblur_small_px': ('frames with a mean corner spacing below this [px] need '
                        'unblur_small_margin for a pixel reading', (0.0, 100.0), None),
    'unblur_small_margin': ('unblur_margin of such small frames (1: no pixel reading)',
                            (0.0, 1.0), None),
    'corner_method': ('saddle: corner candidates are the strong saddle points of the '
                      'smoothed image (finds 4-5 px blocks at strong tilt); eq1: the '
                      "chapter's corner filters and groups (eq. 1-2)", None,
                      ['saddle', 'eq1']),
    'saddle_threshold': ('saddle method: smallest saddle strength (3x3 Sobel units)',
                         (0.0, 1e6), None),
    'saddle_kappa': ('saddle method: weight of the squared Hessian trace subtracted from the '
                     'strength (suppresses saddles along strong edges)', (0.0, 1.0), None),
    'decode_error_rate': ("publish a code only when it is resolved at the frame's blur and "
                          'block spacing, with about this chance of a wrong cell (0: off)',
                          (0.0, 0.5), None),
}
POSE_PARAMETERS = {
    'pixel_sigma': ('frame corner noise for the pose covariance [px]', (1e-4, 10.0), None),
    'p_inf': ('eq. 19 position stop criterion [m]', (1e-12, 1.0), None),
    'r_inf': ('eq. 19 rotation stop criterion [rad]', (1e-12, 1.0), None),
    'max_iterations': ('Gauss-Newton iteration limit', (1, 1000), None),
    'point_set': ('edges: the frame corners and the interior X-corners of the frame edges; '
                  "frame: the four frame corners only (the chapter's eight equations)", None,
                  ['edges', 'frame']),
    'edge_corner_weight': ('weight of an interior X-corner relative to a frame corner (ratio '
                           'of their pixel precisions)', (0.01, 10.0), None),
    'planar_start': ('also start Gauss-Newton from the closed-form planar (IPPE) solutions '
                     'and keep the best by pixel error', None, None),
}


class LandmarkDetector(Node):
    """Thin node: image -> detect_landmarks -> estimate_pose -> messages (and robot fixes)."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters, load the landmark map, create the interfaces."""
        super().__init__('landmark_detector', **kwargs)
        kind = declare(self, 'landmark_kind', '3x3', 'landmark design: 3x3 (28-bit code) or '
                       '2x2 (9 bits)', choices=['3x3', '2x2'])
        width = declare(self, 'frame_width', 0.175, 'printed frame side [m]', (0.005, 10.0))
        self.design = LandmarkDesign(kind=kind, frame_width=width)
        self.params = replace(declare_dataclass(self, DetectorParams, DETECTOR_PARAMETERS,
                                                'detector.'), kind=kind)
        self.pose_params = declare_dataclass(self, PoseParams, POSE_PARAMETERS, 'pose.')
        compressed = declare(self, 'compressed', False, 'subscribe camera/image_raw/compressed '
                             '(sensor_msgs/CompressedImage) instead of camera/image_raw')
        map_file = declare(self, 'landmark_map', '', 'YAML landmark map (code -> pose in '
                           'map_frame); empty: no robot fixes')
        self.map_frame = declare(self, 'map_frame', 'map', 'frame of the landmark map')
        mount = declare(self, 'camera_mount', [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                        'pose of the camera body frame (x forward, z up; the optical frame is '
                        'it rotated to z forward) in base_link: x, y, z [m], roll, pitch, '
                        'yaw [rad]')
        self.debug_image = declare(self, 'publish_debug_image', False,
                                   'publish landmarks/debug_image (bgr8, grid drawn)')
        reject_undeclared(self)
        if len(mount) != 6 or not all(math.isfinite(v) for v in mount):
            raise ParameterError(f'parameter camera_mount must be 6 finite numbers; got {mount}')
        self.mount = camera_mount_matrix(mount)
        self.landmarks = {}
        if map_file:
            try:
                self.landmarks = load_landmark_map(map_file)
            except LandmarkMapError as err:
                raise ParameterError(f'parameter landmark_map: {err}') from err
        self.warner = ProblemWarner(self)
        self.stats = InputStats(self, self.warner)
        self.camera = None
        self.info_frame = ''
        self.frames = 0
        self.pub_markers = self.create_publisher(MarkerArray, 'landmarks/markers', 10)
        self.pub_poses = self.create_publisher(PoseArray, 'landmarks/poses', 10)
        self.pub_fix = self.create_publisher(PoseWithCovarianceStamped, 'landmark_pose', 10)
        self.pub_debug = self.create_publisher(Image, 'landmarks/debug_image', 2) \
            if self.debug_image else None
        self.create_subscription(CameraInfo, 'camera/camera_info', self.on_info, SENSOR_QOS)
        if compressed:
            self.stats.subscribe(CompressedImage, 'camera/image_raw/compressed',
                                 self.on_compressed, SENSOR_QOS)
        else:
            self.stats.subscribe(Image, 'camera/image_raw', self.on_image, SENSOR_QOS)
        self.get_logger().info(f'landmark_detector: {kind} landmarks of {width} m, '
                               f'{len(self.landmarks)} in the map')

    def on_info(self, msg: CameraInfo) -> None:
        """Keep the latest valid camera model."""
        try:
            self.camera = camera_info_to_model(msg)
            self.info_frame = msg.header.frame_id
        except ConversionError as err:
            self.stats.drop('camera_info_malformed', f'Ignoring camera_info: {err}')

    def on_image(self, msg: Image) -> None:
        """Convert and process one raw image."""
        try:
            gray = image_to_gray(msg, 'landmark_detector')
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping image: {err}')
            return
        self.process(msg.header, gray)

    def on_compressed(self, msg: CompressedImage) -> None:
        """Decode and process one compressed image."""
        try:
            gray = compressed_to_gray(msg)
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping image: {err}')
            return
        self.process(msg.header, gray)

    def process(self, header, gray: np.ndarray) -> None:
        """Detect the landmarks of one grey image and publish them."""
        cam = self.camera
        if cam is None:
            self.stats.drop('no_camera_info',
                            'Dropping image: no CameraInfo received yet on camera/camera_info')
            return
        if gray.shape != (cam.height, cam.width):
            self.stats.drop('malformed', f'Dropping image: size {gray.shape[1]}x'
                            f'{gray.shape[0]} disagrees with CameraInfo {cam.width}x'
                            f'{cam.height}')
            return
        problem, usable = image_problem(gray, self.params.min_contrast)
        if problem:
            if not usable:
                self.stats.drop('unusable', 'Dropping image: ' + problem)
                return
            self.warner.warn(problem)
        stamp = stamp_to_ns(header.stamp)
        frame = header.frame_id or self.info_frame
        dets = detect_landmarks(gray, self.params, cam)
        codes, poses = [], []
        for det in dets:
            try:
                pose = estimate_pose(det.corners, cam, self.design, self.pose_params,
                                     edge_corners_px=det.edge_corners)
            except PoseError as err:
                self.warner.warn(f'No pose for landmark {det.code}: {err}')
                continue
            codes.append(det.code)
            poses.append((pose.rotation_optical, pose.translation_optical))
            if det.code in self.landmarks:
                pose6, cov6 = robot_pose_from_landmark(pose, self.landmarks[det.code],
                                                       self.mount)
                self.pub_fix.publish(make_pose_with_covariance_6d(stamp, self.map_frame,
                                                                  pose6, cov6))
        self.pub_markers.publish(make_landmark_markers(stamp, frame, codes, poses,
                                                       self.design.frame_width))
        self.pub_poses.publish(make_landmark_pose_array(stamp, frame, poses))
        if self.pub_debug is not None:
            self.pub_debug.publish(array_to_image(draw_detections(gray, dets), 'bgr8', stamp,
                                                  frame))
        self.frames += 1
        self.stats.processed()


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav landmark_detector``."""
    return run_node(LandmarkDetector, args)


if __name__ == '__main__':
    raise SystemExit(main())
