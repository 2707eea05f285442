"""Record the ``park_road`` scenario: a drive along a simulated park road into a bag.

The robot drives along the road (world x) at ``speed`` with a small lateral offset; a
pedestrian stands on the road ahead. Topics: ``/tilted_scan`` (sensor_msgs/LaserScan, the
tilted laser of :class:`landmark_nav.road.terrain.LaserMount` defaults, 10 Hz),
``/camera/image_raw`` (rgb8 320 x 240) and ``/camera/camera_info`` (2 Hz), ``/odom`` and
``/ground_truth/odom`` (nav_msgs/Odometry, 20 Hz; odometry = truth here). The road's true
width and edges, the pedestrian and the mounts go to ``ground_truth.yaml``.
"""

import math
from pathlib import Path
import shutil

from landmark_nav.bag import BagWriter
from landmark_nav.conversions import (array_to_image, make_camera_info, make_odometry,
                                      make_scan)
from landmark_nav.road.terrain import LaserMount
from nav_msgs.msg import Odometry
import numpy as np
from sensor_msgs.msg import CameraInfo, Image, LaserScan
import yaml

from .bag_layout import GROUND_TRUTH_FILE
from .park_road import cast_scan, Lighting, ParkRoad, render_view

SCAN_TOPIC = '/tilted_scan'
IMAGE_TOPIC = '/camera/image_raw'
INFO_TOPIC = '/camera/camera_info'
CAMERA_MOUNT = (0.2, 0.0, 1.0, 0.0, math.radians(12.0), 0.0)
ANGLES = np.radians(np.arange(-90.0, 90.25, 0.5))


def record_park_road(seed: int, out, force: bool = False, kind: str = 'asphalt',
                     seconds: float = 6.0, speed: float = 0.5) -> str:
    """Simulate the drive and write the bag; return a one-line summary.

    Raises:
        ValueError: ``out`` exists and is not a bag, or a bad seed / kind.
    """
    from landmark_nav.vision.camera import CameraModel
    if not isinstance(seed, int) or seed < 0:
        raise ValueError(f'seed must be a non-negative integer; got {seed!r}')
    out = Path(out)
    if force and out.exists():
        if not (out / 'metadata.yaml').is_file():
            raise ValueError(f'{out} exists and is not a bag; refusing to replace it')
        shutil.rmtree(out)
    pedestrian = (speed * seconds + 7.0, 0.0, 0.25, 1.75)
    road = ParkRoad.of_kind(kind, seed=seed, cylinders=(pedestrian,))
    camera = CameraModel.from_fov(320, 240, math.radians(70.0))
    mount = LaserMount()
    rng = np.random.default_rng(seed)
    y0 = float(rng.normal(0.0, 0.2))
    t0 = 1_000_000_000
    counts = {'scans': 0, 'images': 0}
    with BagWriter(out) as bag:
        for topic, cls in ((SCAN_TOPIC, LaserScan), (IMAGE_TOPIC, Image),
                           (INFO_TOPIC, CameraInfo), ('/odom', Odometry),
                           ('/ground_truth/odom', Odometry)):
            bag.add_topic(topic, cls)
        for k in range(int(seconds * 20) + 1):
            t = t0 + k * 50_000_000
            pose = (speed * k * 0.05, y0, 0.0)
            twist = np.array([speed, 0.0, 0.0])
            for topic in ('/ground_truth/odom', '/odom'):
                bag.write(topic, t, make_odometry(t, 'odom', 'base_link', pose,
                                                  np.zeros((3, 3)), twist, np.zeros((3, 3))))
            if k % 2 == 0:
                sc = cast_scan(road, pose, mount, ANGLES, rng=rng)
                bag.write(SCAN_TOPIC, t, make_scan(t, 'laser', float(ANGLES[0]),
                                                   math.radians(0.5), sc.ranges, 0.05, 8.0))
                counts['scans'] += 1
            if k % 10 == 0:
                img = render_view(road, pose, camera, CAMERA_MOUNT, Lighting(), rng=rng)
                bag.write(INFO_TOPIC, t, make_camera_info(camera, t, 'camera'))
                bag.write(IMAGE_TOPIC, t, array_to_image(img, 'rgb8', t, 'camera'))
                counts['images'] += 1
    laser = [mount.x, mount.y, mount.z, mount.roll, mount.pitch, mount.yaw]
    truth = {'scenario': 'park_road', 'seed': seed, 'kind': kind, 'width': road.width,
             'edges': list(road.edges()), 'crown': road.crown, 'lateral_offset': y0,
             'pedestrian': list(pedestrian), 'laser_mount': laser,
             'camera_mount': list(CAMERA_MOUNT)}
    with open(out / GROUND_TRUTH_FILE, 'w') as f:
        yaml.safe_dump(truth, f, sort_keys=False)
    return (f'park_road (seed {seed}, {kind} {road.width} m): {seconds:.1f} s, '
            f'{counts["scans"]} scans, {counts["images"]} images -> {out}')
