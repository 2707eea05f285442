"""Record a drive along the rendered corridor into a rosbag2 (MCAP) for the corridor follower.

Topics (stamps are simulation time, starting at 1 s):

========================  ===============================  ==================================
topic                     type                             content
========================  ===============================  ==================================
/camera/image_raw         sensor_msgs/Image                mono8, frame ``camera_optical``,
                                                           ``camera_rate``
/camera/camera_info       sensor_msgs/CameraInfo           plumb_bob, same stamp (written
                                                           just before the image)
/odom                     nav_msgs/Odometry                measured (drifting) odometry,
                                                           ``odom`` -> ``base_link``
/ground_truth/odom        nav_msgs/Odometry                true pose in the corridor frame
                                                           (``corridor`` -> ``base_link``)
========================  ===============================  ==================================

The robot weaves about the centre line (a lateral set-point ``0.3 sin(2 pi x / 8)`` m)
under a controller on its *true* pose, so that the bag does not depend on the follower
under test. The measured odometry integrates wheel distances with Kleeman noise and the
right wheel's scale error of :class:`~landmark_nav.evaluation.corridor_run.RunConfig`.
``ground_truth.yaml`` beside the MCAP holds the seed, corridor geometry and camera mount.
"""

import math
from pathlib import Path
import shutil

from landmark_nav.bag import BagWriter
from landmark_nav.conversions import array_to_image, make_camera_info, make_odometry
from landmark_nav.sim.camera import CameraSimulator
from landmark_nav.sim.corridor import (corridor_scene, corridor_view, CorridorConfig,
                                       default_corridor_camera)
from nav_msgs.msg import Odometry
import numpy as np
from sensor_msgs.msg import CameraInfo, Image
import yaml

CAMERA_FRAME = 'camera_optical'
IMAGE_TOPIC = '/camera/image_raw'
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
                          wheel_separation: float = 0.33, force: bool = False) -> str:
    """Render a drive into a bag directory; return a one-line summary.

    Raises:
        ValueError: bad arguments, or ``out`` exists and is not a bag (with ``force``).
        BagError: the output exists (without ``force``) or cannot be written.
    """
    if not (distance > 0 and speed > 0 and odom_rate > 0 and 0 < camera_rate <= odom_rate):
        raise ValueError('distance, speed and rates must be > 0, camera_rate <= odom_rate')
    out = Path(out)
    if force and out.exists():
        if not (out / 'metadata.yaml').is_file():
            raise ValueError(f'{out} exists and is not a bag; refusing to replace it')
        shutil.rmtree(out)
    rng = np.random.default_rng(seed)
    planes = corridor_scene(corridor, seed)
    cam = default_corridor_camera()
    sim = CameraSimulator(cam)
    truth = np.array([1.0, 0.0, 0.0])
    odom = np.zeros(3)
    step = speed / odom_rate
    per_frame = int(round(odom_rate / camera_rate))
    b = wheel_separation
    frames = 0
    with BagWriter(out) as bag:
        for topic, cls in ((IMAGE_TOPIC, Image), (INFO_TOPIC, CameraInfo),
                           (ODOM_TOPIC, Odometry), (TRUTH_TOPIC, Odometry)):
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
                img = corridor_view(sim, planes, truth, mount).image
                bag.write(INFO_TOPIC, t, make_camera_info(cam, t, CAMERA_FRAME))
                bag.write(IMAGE_TOPIC, t, array_to_image(img, 'mono8', t, CAMERA_FRAME))
                frames += 1
    meta = {'scenario': 'corridor_drive', 'seed': int(seed), 'distance': float(distance),
            'speed': float(speed), 'corridor': {'width': corridor.width,
                                                'height': corridor.height,
                                                'length': corridor.length},
            'camera_mount': [float(v) for v in mount], 'frames': frames}
    (out / 'ground_truth.yaml').write_text(yaml.safe_dump(meta, sort_keys=False))
    return f'corridor_drive seed {seed}: {frames} frames, {distance:.1f} m -> {out}'
