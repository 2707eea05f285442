"""Record the camera scenarios (``landmark_views``, ``landmark_shuttle``) into rosbag2 (MCAP).

Topics (stamps are simulation time):

========================  ===============================  ===================================
topic                     type                             content
========================  ===============================  ===================================
/camera/image_raw         sensor_msgs/Image                mono8, frame ``camera_optical``
/camera/camera_info       sensor_msgs/CameraInfo           plumb_bob, same stamp as the image
/ground_truth/landmarks   geometry_msgs/PoseArray          true landmark poses in
                                                           ``camera_optical`` (landmark frame:
                                                           x out of the face, z up), one per
                                                           landmark in view, order = the codes
                                                           listed for the frame in
                                                           ground_truth.yaml; same stamp
/odom                     nav_msgs/Odometry                (shuttle) wheel odometry, 10 Hz
/joint_states             sensor_msgs/JointState           (shuttle) wheel angles and speeds
/ground_truth/odom        nav_msgs/Odometry                (shuttle) true pose, map ->
                                                           base_link, 10 Hz
========================  ===============================  ===================================

``ground_truth.yaml`` beside the MCAP file holds the scenario, seed, camera model, landmark
design, per-frame truth (codes, poses, pixels per block, view parameters) and, for the
shuttle, the landmark map (code -> pose in ``map``), the camera mount (base_link ->
camera_optical) and the arrivals at the near point.
"""

from pathlib import Path
import shutil
from typing import Any, Dict, List, Optional

from geometry_msgs.msg import Pose, PoseArray
from landmark_nav.bag import BagWriter
from landmark_nav.conversions import (array_to_image, make_camera_info, make_joint_state,
                                      make_odometry, ns_to_stamp)
from landmark_nav.vision.camera import OPTICAL_FROM_BODY
from nav_msgs.msg import Odometry
import numpy as np
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image, JointState
import yaml

from .bag_layout import BASE_FRAME, GROUND_TRUTH_FILE, MAP_FRAME, ODOM_FRAME, WHEEL_JOINTS
from .camera_scenarios import (CameraFrame, iter_landmark_shuttle, iter_landmark_views,
                               LandmarkTruth, oracle_localizer, ShuttleArrival, ShuttleConfig,
                               ShuttleSample, ViewOptions)

CAMERA_FRAME = 'camera_optical'
IMAGE_TOPIC = '/camera/image_raw'
INFO_TOPIC = '/camera/camera_info'
LANDMARKS_TOPIC = '/ground_truth/landmarks'


def quaternion_xyzw(rotation: np.ndarray) -> List[float]:
    """Return the unit quaternion (x, y, z, w) of a rotation matrix (w >= 0)."""
    q = Rotation.from_matrix(np.asarray(rotation, dtype=float)).as_quat()
    if q[3] < 0:
        q = -q
    return [float(v) for v in q]


def _pose_msg(rotation: np.ndarray, translation: np.ndarray) -> Pose:
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in translation)
    x, y, z, w = quaternion_xyzw(rotation)
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = x, y, z, w
    return pose


def _truth_dict(lt: LandmarkTruth) -> Dict[str, Any]:
    return {'code': int(lt.code), 'position': [float(v) for v in lt.translation],
            'orientation_xyzw': quaternion_xyzw(lt.rotation),
            'corners_px': [[float(v) for v in p] for p in lt.corners_px],
            'block_px': float(lt.block_px), 'in_view': bool(lt.in_view),
            'distance': float(lt.distance), 'view_angle': float(lt.view_angle),
            'params': {k: float(v) for k, v in lt.params.items()}}


def _write_frame(bag: BagWriter, frame: CameraFrame) -> Dict[str, Any]:
    t = frame.stamp_ns
    bag.write(IMAGE_TOPIC, t, array_to_image(frame.image, 'mono8', t, CAMERA_FRAME))
    bag.write(INFO_TOPIC, t, make_camera_info(frame.camera, t, CAMERA_FRAME))
    arr = PoseArray()
    arr.header.stamp = ns_to_stamp(t)
    arr.header.frame_id = CAMERA_FRAME
    arr.poses = [_pose_msg(lt.rotation, lt.translation) for lt in frame.landmarks]
    bag.write(LANDMARKS_TOPIC, t, arr)
    ph = frame.photometry
    return {'index': int(frame.index), 'stamp_ns': int(t),
            'landmarks': [_truth_dict(lt) for lt in frame.landmarks],
            'distractors': list(frame.distractors),
            'photometry': {'exposure': ph.exposure, 'gradient': list(ph.gradient),
                           'vignetting': ph.vignetting, 'gamma': ph.gamma,
                           'defocus_sigma': ph.defocus_sigma, 'motion_blur': ph.motion_blur,
                           'motion_angle': ph.motion_angle, 'noise_sigma': ph.noise_sigma,
                           'shot_noise': ph.shot_noise}}


def _prepare(out: Path, force: bool) -> None:
    if force and out.exists():
        if not (out / 'metadata.yaml').is_file():
            raise ValueError(f'{out} exists and is not a bag; refusing to replace it')
        shutil.rmtree(out)


def _camera_topics(bag: BagWriter) -> None:
    bag.add_topic(IMAGE_TOPIC, Image)
    bag.add_topic(INFO_TOPIC, CameraInfo)
    bag.add_topic(LANDMARKS_TOPIC, PoseArray)


def record_camera_scenario(name: str, seed: int, out, force: bool = False,
                           n_frames: int = 20, trips: int = 1, image_rate: float = 0.5,
                           options: Optional[ViewOptions] = None,
                           config: Optional[ShuttleConfig] = None) -> str:
    """Render a camera scenario into a bag directory; return a one-line summary.

    Args:
        name: ``'landmark_views'`` or ``'landmark_shuttle'``.
        seed: non-negative int.
        out: bag directory to create.
        force: replace an existing bag directory.
        n_frames: landmark_views: number of views (20 x 300 kB by default).
        trips: landmark_shuttle: round trips (default 1: a short bag).
        image_rate: landmark_shuttle: camera rate while moving [Hz].
        options: landmark_views: view options (default :class:`ViewOptions`).
        config: landmark_shuttle: full set-up (overrides ``trips`` and ``image_rate``).

    Raises:
        ValueError: unknown scenario, bad seed or options, or ``out`` is not a bag.
        BagError: the output exists (without ``force``) or cannot be written.
    """
    out = Path(out)
    if name == 'landmark_views':
        frames_meta = []
        opts = options if options is not None else ViewOptions()
        _prepare(out, force)
        camera = None
        with BagWriter(out) as bag:
            _camera_topics(bag)
            for frame in iter_landmark_views(seed, n_frames, options=opts):
                camera = frame.camera
                frames_meta.append(_write_frame(bag, frame))
        meta = {'scenario': name, 'seed': int(seed),
                'description': 'static views of a landmark at 0.5-4 m with distractors',
                'camera': None if camera is None else camera.to_dict(),
                'camera_frame': CAMERA_FRAME,
                'design': {'kind': opts.design.kind, 'frame_width': opts.design.frame_width},
                'frames': frames_meta}
        summary = f'{name} (seed {seed}): {len(frames_meta)} frames -> {out}'
    elif name == 'landmark_shuttle':
        cfg = config if config is not None else ShuttleConfig(trips=trips, image_rate=image_rate)
        _prepare(out, force)
        frames_meta, arrivals = [], []
        n_odom = 0
        with BagWriter(out) as bag:
            _camera_topics(bag)
            bag.add_topic('/odom', Odometry)
            bag.add_topic('/joint_states', JointState)
            bag.add_topic('/ground_truth/odom', Odometry)
            # the recorded robot corrects its odometry with perfect fixes (an oracle), so
            # the bag shows the intended shuttle; /odom itself is never corrected
            for ev in iter_landmark_shuttle(seed, cfg, localize=oracle_localizer(cfg)):
                if isinstance(ev, ShuttleSample):
                    t = ev.stamp_ns
                    tw = np.array([ev.odom_twist[0], 0.0, ev.odom_twist[1]])
                    bag.write('/odom', t, make_odometry(
                        t, ODOM_FRAME, BASE_FRAME, ev.odom_pose, ev.odom_covariance, tw))
                    bag.write('/joint_states', t, make_joint_state(
                        t, WHEEL_JOINTS, ev.wheel_positions, ev.wheel_velocities))
                    ttw = np.array([ev.true_twist[0], 0.0, ev.true_twist[1]])
                    bag.write('/ground_truth/odom', t, make_odometry(
                        t, MAP_FRAME, BASE_FRAME, ev.true_pose, np.zeros((3, 3)), ttw,
                        np.zeros((3, 3)), unused_variance=0.0))
                    n_odom += 1
                elif isinstance(ev, CameraFrame):
                    frames_meta.append(_write_frame(bag, ev))
                elif isinstance(ev, ShuttleArrival):
                    arrivals.append({'trip': ev.trip, 'stamp_ns': int(ev.stamp_ns),
                                     'true_pose': [float(v) for v in ev.true_pose],
                                     'error': float(ev.error)})
        cam = cfg.camera_model()
        meta = {'scenario': name, 'seed': int(seed),
                'description': 'robot shuttles 1 m <-> 3 m in front of a landmark (chapter 2.3.3)',
                'camera': cam.to_dict(), 'camera_frame': CAMERA_FRAME,
                'camera_mount': {'parent': BASE_FRAME, 'child': CAMERA_FRAME,
                                 'position': [float(v) for v in cfg.mount],
                                 'orientation_xyzw': quaternion_xyzw(OPTICAL_FROM_BODY.T)},
                'design': {'kind': cfg.design.kind, 'frame_width': cfg.design.frame_width},
                'landmarks': {int(cfg.code): {
                    'frame_id': MAP_FRAME,
                    'position': [float(v) for v in cfg.landmark_position],
                    'orientation_xyzw': quaternion_xyzw(cfg.landmark_rotation)}},
                'near_point': [float(v) for v in cfg.near_point],
                'far_point': [float(v) for v in cfg.far_point],
                'trips': int(cfg.trips), 'robot': cfg.robot.to_dict(),
                'odometry_factors': [float(v) for v in cfg.believed_factors],
                'arrivals': arrivals, 'frames': frames_meta}
        summary = (f'{name} (seed {seed}): {cfg.trips} trips, {n_odom} odometry samples, '
                   f'{len(frames_meta)} frames -> {out}')
    else:
        raise ValueError(f"unknown camera scenario {name!r}; valid: 'landmark_views', "
                         "'landmark_shuttle'")
    with open(out / GROUND_TRUTH_FILE, 'w') as f:
        yaml.safe_dump(meta, f, sort_keys=False)
    return summary


__all__ = ['CAMERA_FRAME', 'IMAGE_TOPIC', 'INFO_TOPIC', 'LANDMARKS_TOPIC', 'quaternion_xyzw',
           'record_camera_scenario']
