"""Record a drive along the rendered corridor into a rosbag2 (MCAP) for the corridor follower.

Topics (stamps are simulation time, starting at 1 s):

============================  ===========================  ===============================
topic                         type                         content
============================  ===========================  ===============================
/camera/image_raw             sensor_msgs/Image            mono8, frame ``camera_optical``,
                                                           ``camera_rate`` (without
                                                           ``jpeg_quality``)
/camera/image_raw/compressed  sensor_msgs/CompressedImage  the same frames as JPEG (format
                                                           ``jpeg``; with ``jpeg_quality``)
/camera/camera_info           sensor_msgs/CameraInfo       plumb_bob, same stamp (written
                                                           just before the image)
/odom                         nav_msgs/Odometry            measured (drifting) odometry,
                                                           ``odom`` -> ``base_link``
/ground_truth/odom            nav_msgs/Odometry            true pose in the corridor frame
                                                           (``corridor`` -> ``base_link``)
============================  ===========================  ===============================

The robot weaves about the centre line (a lateral set-point ``0.3 sin(2 pi x / 8)`` m)
under a controller on its *true* pose, so that the bag does not depend on the follower
under test. The measured odometry integrates wheel distances with Kleeman noise and the
right wheel's scale error of :class:`~landmark_nav.evaluation.corridor_run.RunConfig`.
``ground_truth.yaml`` beside the MCAP holds the seed, corridor geometry, camera mount,
image size and topic, and the odometry error model.

The ``corridor`` scenario of ``landmark_nav simulate`` (:func:`record_corridor_scenario`)
is a short drive at 320 x 240 with JPEG frames, small enough to commit (``bags/corridor``).
"""

import math
from pathlib import Path
import shutil
from typing import Optional

import cv2

from landmark_nav.bag import BagWriter
from landmark_nav.conversions import (array_to_image, make_camera_info, make_odometry,
                                      ns_to_stamp)
from landmark_nav.sim.camera import CameraSimulator, Photometry
from landmark_nav.sim.corridor import (corridor_scene, corridor_view, CorridorConfig,
                                       default_corridor_camera)
from nav_msgs.msg import Odometry
import numpy as np
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
import yaml

CAMERA_FRAME = 'camera_optical'
IMAGE_TOPIC = '/camera/image_raw'
COMPRESSED_TOPIC = '/camera/image_raw/compressed'
INFO_TOPIC = '/camera/camera_info'
ODOM_TOPIC = '/odom'
TRUTH_TOPIC = '/ground_truth/odom'


def _move(s: np.ndarray, d_l: float, d_r: float, b: float) -> np.ndarray:
    ds, dth = 0.5 * (d_l + d_r), (d_r - d_l) / b
    a = s[2] + 0.5 * dth
    return np.array([s[0] + ds * math.cos(a), s[1] + ds * math.sin(a), s[2] + dth])


def record_corridor_drive(out, seed: int = 0, distance: float = 6.0, speed: float = 0.5,
                          odom_rate: float = 20.0, camera_rate: float = 5.0,
                          corridor: CorridorConfig = CorridorConfig(),
                          mount=(0.1, 0.0, 1.1, 0.0, math.radians(5.0), 0.0),
                          right_scale_error: float = 0.01, k_wheel: float = 2e-5,
                          wheel_separation: float = 0.33, force: bool = False,
                          downscale: int = 1, jpeg_quality: Optional[int] = None,
                          photometry: Photometry = Photometry(),
                          scenario: str = 'corridor_drive') -> str:
    """Render a drive into a bag directory; return a one-line summary.

    Args:
        downscale: the camera at 640 x 480 / downscale (1, 2 or 4).
        jpeg_quality: 1-100: JPEG frames on ``/camera/image_raw/compressed``; None: raw
            mono8 frames on ``/camera/image_raw``.
        photometry: image noise, blur and lighting of every frame (noise from a generator
            of its own, so that the odometry noise does not depend on it).
        scenario: the name written into ``ground_truth.yaml``.

    Raises:
        ValueError: bad arguments, or ``out`` exists and is not a bag (with ``force``).
        BagError: the output exists (without ``force``) or cannot be written.
    """
    if not (distance > 0 and speed > 0 and odom_rate > 0 and 0 < camera_rate <= odom_rate):
        raise ValueError('distance, speed and rates must be > 0, camera_rate <= odom_rate')
    if jpeg_quality is not None and not (isinstance(jpeg_quality, int)
                                         and 1 <= jpeg_quality <= 100):
        raise ValueError(f'jpeg_quality must be an integer in 1..100; got {jpeg_quality!r}')
    if distance + 1.0 > corridor.length - 1.0:
        raise ValueError(f'distance {distance} m does not fit the {corridor.length} m corridor '
                         '(the drive starts 1 m in and ends 1 m before its end)')
    out = Path(out)
    if force and out.exists():
        if not (out / 'metadata.yaml').is_file():
            raise ValueError(f'{out} exists and is not a bag; refusing to replace it')
        shutil.rmtree(out)
    rng = np.random.default_rng(seed)
    pixel_rng = np.random.default_rng([seed, 1])     # image noise: its own stream
    planes = corridor_scene(corridor, seed)
    cam = default_corridor_camera(downscale)
    sim = CameraSimulator(cam)
    truth = np.array([1.0, 0.0, 0.0])
    odom = np.zeros(3)
    step = speed / odom_rate
    per_frame = int(round(odom_rate / camera_rate))
    b = wheel_separation
    frames = 0
    with BagWriter(out) as bag:
        image_topic = IMAGE_TOPIC if jpeg_quality is None else COMPRESSED_TOPIC
        for topic, cls in ((image_topic, Image if jpeg_quality is None else CompressedImage),
                           (INFO_TOPIC, CameraInfo), (ODOM_TOPIC, Odometry),
                           (TRUTH_TOPIC, Odometry)):
            bag.add_topic(topic, cls)
        for k in range(int(distance / step)):
            t = 1_000_000_000 + int(round(k * 1e9 / odom_rate))
            target = 0.3 * math.sin(2 * math.pi * truth[0] / 8.0)
            omega = -1.5 * truth[2] - 1.0 * (truth[1] - target)       # [rad/m], on truth
            omega = max(-0.5, min(0.5, omega))
            d_l, d_r = step * (1 - 0.5 * b * omega), step * (1 + 0.5 * b * omega)
            t_l = d_l + rng.normal(0.0, math.sqrt(k_wheel * abs(d_l)))
            t_r = (d_r + rng.normal(0.0, math.sqrt(k_wheel * abs(d_r)))) / (1 + right_scale_error)
            truth = _move(truth, t_l, t_r, b)
            odom = _move(odom, d_l, d_r, b)
            bag.write(ODOM_TOPIC, t, make_odometry(t, 'odom', 'base_link', odom))
            bag.write(TRUTH_TOPIC, t, make_odometry(t, 'corridor', 'base_link', truth))
            if k % per_frame == 0:
                img = corridor_view(sim, planes, truth, mount, photometry, pixel_rng).image
                bag.write(INFO_TOPIC, t, make_camera_info(cam, t, CAMERA_FRAME))
                bag.write(image_topic, t, _image_message(img, t, jpeg_quality))
                frames += 1
    meta = {'scenario': scenario, 'seed': int(seed), 'distance': float(distance),
            'speed': float(speed), 'corridor': {'width': corridor.width,
                                                'height': corridor.height,
                                                'length': corridor.length},
            'camera_mount': [float(v) for v in mount], 'frames': frames,
            'image_size': [cam.width, cam.height],
            'image_topic': image_topic, 'jpeg_quality': jpeg_quality,
            'right_scale_error': float(right_scale_error), 'k_wheel': float(k_wheel),
            'wheel_separation': float(wheel_separation)}
    (out / 'ground_truth.yaml').write_text(yaml.safe_dump(meta, sort_keys=False))
    return (f'{scenario} (seed {seed}): {frames} frames {cam.width} x {cam.height}, '
            f'{distance:.1f} m -> {out}')


def _image_message(img: np.ndarray, stamp_ns: int, jpeg_quality: Optional[int]):
    if jpeg_quality is None:
        return array_to_image(img, 'mono8', stamp_ns, CAMERA_FRAME)
    ok, buf = cv2.imencode('.jpg', img, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
    if not ok:
        raise ValueError('JPEG encoding failed')
    msg = CompressedImage()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = CAMERA_FRAME
    msg.format = 'jpeg'
    msg.data = buf.tobytes()
    return msg


#: The ``corridor`` scenario: 3 m at 0.5 m/s, 320 x 240 JPEG frames at 5 Hz, mild noise.
CORRIDOR_SCENARIO = {'distance': 3.0, 'downscale': 2, 'jpeg_quality': 80}


def record_corridor_scenario(seed: int, out, force: bool = False, distance: Optional[float] = None,
                             downscale: Optional[int] = None,
                             jpeg_quality: Optional[int] = -1) -> str:
    """Record the ``corridor`` scenario of ``landmark_nav simulate`` (see the module docstring).

    Args:
        seed: scene and noise seed.
        out: bag directory to create.
        force: replace an existing bag.
        distance: metres driven (default 3).
        downscale: 1 (640 x 480), 2 (320 x 240, default) or 4.
        jpeg_quality: JPEG quality of the frames (default 80), None for raw mono8.
    """
    d = CORRIDOR_SCENARIO
    return record_corridor_drive(
        out, seed=seed, distance=d['distance'] if distance is None else distance,
        downscale=d['downscale'] if downscale is None else downscale,
        jpeg_quality=d['jpeg_quality'] if jpeg_quality == -1 else jpeg_quality,
        photometry=Photometry(noise_sigma=2.0, defocus_sigma=0.5), force=force,
        scenario='corridor')
