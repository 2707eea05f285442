"""One MCAP file to look at an EKF-SLAM run in an MCAP viewer (Foxglove, Lichtblick).

:func:`write_slam_view` runs the offline EKF-SLAM of :func:`landmark_nav.evaluation.slam.
run_slam` over a bag (the same extractor and filter as ``landmark_nav evaluate``) and
records the inputs and every output into a rosbag2 directory holding one ``.mcap`` file,
all in standard message types with their schemas embedded, so a viewer opens the file
directly. The layout ``viewer/slam_layout.json`` (Foxglove / Lichtblick: Layouts ->
Import) shows the map, the scans, the corners and the paths in a 3-D panel, the pose
error in a plot and the filter pose:

=====================  ====================================  =====================
topic                  type                                  frame / content
=====================  ====================================  =====================
``/scan``              sensor_msgs/LaserScan                 ``laser``, input
``/odom``              nav_msgs/Odometry                     ``odom`` -> ``base_link``, input
``/ground_truth/odom`` nav_msgs/Odometry                     ``map``, the reference
``/corners``           geometry_msgs/PoseArray               ``laser``, yaw = bisector
``/corners/markers``   visualization_msgs/MarkerArray        ``laser``
``/pose``              geometry_msgs/PoseWithCovarianceStamped  ``map``, per scan
``/path``              nav_msgs/Path                         ``map``, every 2 s
``/odom/path``         nav_msgs/Path                         ``odom`` (== ``map`` at start)
``/ground_truth/path`` nav_msgs/Path                         ``map``
``/landmarks``         visualization_msgs/MarkerArray        ``map``, 2-sigma ellipses
``/world``             visualization_msgs/MarkerArray        ``map``, walls (simulator)
``/tf``, ``/tf_static`` tf2_msgs/TFMessage                   map -> odom -> base_link -> laser
=====================  ====================================  =====================

Without a reference the ground-truth topics are left out; without the simulator's world,
``/world``. ``tf2_msgs`` is not among the pip-installed message packages, so the TF
messages are serialized with the rosbags type store (the same CDR).
"""

from dataclasses import replace
import functools
import math
from pathlib import Path
import shutil
from typing import Dict, List, Optional, Sequence

from geometry_msgs.msg import Point, PoseStamped
from landmark_nav.bag import BagWriter
from landmark_nav.conversions import (make_odometry, make_pose_with_covariance_stamped,
                                      make_scan, ns_to_stamp, pose_msg_from_2d)
from landmark_nav.evaluation.bags import load_bag
from landmark_nav.evaluation.slam import extractor_parameters, run_slam, scan_angles
from landmark_nav.feature_msgs import (make_corner_markers, make_corner_pose_array,
                                       make_landmark_markers)
from landmark_nav.geometry import compose, relative
from landmark_nav.laser.corners import CornerParams, extract_corners
from landmark_nav.sim import OdometrySample, ScanSample
from landmark_nav.slam.ekf_slam import CORNER, LINE, SlamParams
from nav_msgs.msg import Path as PathMsg
import numpy as np
from visualization_msgs.msg import Marker, MarkerArray

TF_TYPE = 'tf2_msgs/msg/TFMessage'
#: Topic -> type name of the viewer file (those that apply to the bag are written).
VIEW_TOPICS: Dict[str, str] = {
    '/scan': 'sensor_msgs/msg/LaserScan', '/odom': 'nav_msgs/msg/Odometry',
    '/ground_truth/odom': 'nav_msgs/msg/Odometry', '/corners': 'geometry_msgs/msg/PoseArray',
    '/corners/markers': 'visualization_msgs/msg/MarkerArray',
    '/pose': 'geometry_msgs/msg/PoseWithCovarianceStamped', '/path': 'nav_msgs/msg/Path',
    '/odom/path': 'nav_msgs/msg/Path', '/ground_truth/path': 'nav_msgs/msg/Path',
    '/landmarks': 'visualization_msgs/msg/MarkerArray',
    '/world': 'visualization_msgs/msg/MarkerArray', '/tf': TF_TYPE, '/tf_static': TF_TYPE}


@functools.lru_cache(maxsize=1)
def _typestore():
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


def _tf_bytes(stamp_ns: int, transforms) -> bytes:
    """Serialize ``[(parent, child, (x, y, yaw)), ...]`` as a tf2_msgs/TFMessage (CDR)."""
    store = _typestore()
    t = store.types
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    out = []
    for parent, child, (x, y, yaw) in transforms:
        header = t['std_msgs/msg/Header'](
            stamp=t['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec), frame_id=parent)
        transform = t['geometry_msgs/msg/Transform'](
            translation=t['geometry_msgs/msg/Vector3'](x=float(x), y=float(y), z=0.0),
            rotation=t['geometry_msgs/msg/Quaternion'](
                x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw)))
        out.append(t['geometry_msgs/msg/TransformStamped'](
            header=header, child_frame_id=child, transform=transform))
    return bytes(store.serialize_cdr(t[TF_TYPE](transforms=out), TF_TYPE))


class _PathTopic:
    """The growing path of one topic: each pose message is built once, not once per path.

    ``path(k)`` is the ``nav_msgs/Path`` of poses ``0..k`` stamped with pose ``k``'s stamp;
    the paths share their ``PoseStamped`` messages (each path holds the whole path so far,
    so building them anew made the viewer file quadratic in the poses).
    """

    def __init__(self, stamps: np.ndarray, poses: np.ndarray, frame: str) -> None:
        self._stamps, self._poses, self._frame = stamps, poses, frame
        self._msgs: List[PoseStamped] = []

    def path(self, k: int) -> PathMsg:
        """Return the path of poses ``0..k``."""
        for i in range(len(self._msgs), k + 1):
            ps = PoseStamped()
            ps.header.stamp = ns_to_stamp(int(self._stamps[i]))
            ps.header.frame_id = self._frame
            ps.pose = pose_msg_from_2d(self._poses[i])
            self._msgs.append(ps)
        msg = PathMsg()
        msg.header.stamp = ns_to_stamp(int(self._stamps[k]))
        msg.header.frame_id = self._frame
        msg.poses = self._msgs[:k + 1]
        return msg


def _world_markers(world, stamp_ns: int) -> MarkerArray:
    """Walls of the simulator's world as one LINE_LIST, round obstacles as cylinders."""
    walls = Marker()
    walls.header.stamp = ns_to_stamp(stamp_ns)
    walls.header.frame_id = 'map'
    walls.ns, walls.id, walls.type, walls.action = 'walls', 0, Marker.LINE_LIST, Marker.ADD
    walls.pose.orientation.w = 1.0
    walls.scale.x = 0.03
    walls.color.r = walls.color.g = walls.color.b = 0.2
    walls.color.a = 1.0
    for x1, y1, x2, y2 in world.walls().segments:
        walls.points += [Point(x=float(x1), y=float(y1)), Point(x=float(x2), y=float(y2))]
    markers = [walls]
    for i, (cx, cy, r) in enumerate(world.circles):
        m = Marker()
        m.header = walls.header
        m.ns, m.id, m.type, m.action = 'posts', i, Marker.CYLINDER, Marker.ADD
        m.pose.position.x, m.pose.position.y = float(cx), float(cy)
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = 2.0 * float(r)
        m.scale.z = 0.3
        m.color.r = m.color.g = m.color.b = 0.3
        m.color.a = 1.0
        markers.append(m)
    return MarkerArray(markers=markers)


def write_slam_view(bag, out_dir, association: str = 'icnn',
                    max_seconds: Optional[float] = None, display_period: float = 0.5,
                    path_period: float = 2.0, force: bool = False, reference=None,
                    laser_pose: Optional[Sequence[float]] = None,
                    sigma_r: Optional[float] = None, config=None) -> dict:
    """Run EKF-SLAM over ``bag`` and write the viewer file into the directory ``out_dir``.

    Args:
        bag: rosbag2 directory with ``/scan`` and ``/odom`` (as ``landmark_nav evaluate``).
        out_dir: rosbag2 directory to create; the viewer opens ``out_dir/<name>.mcap``.
        association: ``icnn`` or ``jcbb``.
        max_seconds: Use only the first seconds of the bag.
        display_period: Period of ``/landmarks`` [s] (as ekf_slam's).
        path_period: Period of the three paths [s] (each holds the whole path so far).
        force: Replace an existing ``out_dir``.
        reference: TUM file of the reference (None: ``/ground_truth/odom`` if any).
        laser_pose: Laser mount when the bag does not state it.
        sigma_r: Laser range noise when the bag does not state it [m].
        config: The ``ekf_slam`` configuration
            (:class:`~landmark_nav.slam.configuration.SlamConfiguration`, as
            ``landmark_nav evaluate`` runs it; ``association`` wins); None: the chapter's
            filter with corners.

    Returns:
        ``{'mcap': path of the .mcap file, 'counts': {topic: messages}}``.

    Raises:
        ValueError: Unusable bag or an existing output without ``force``.
    """
    out = Path(out_dir)
    if out.exists():
        if not force:
            raise ValueError(f'{out} exists already (use force to replace it)')
        shutil.rmtree(out)
    scenario = load_bag(bag, max_seconds, reference, laser_pose, sigma_r,
                        require_reference=False)
    corner_params = CornerParams(sigma_r=float(scenario.laser.sigma_range),
                                 sigma_phi=float(scenario.laser.sigma_angle))
    options = {}
    if config is None:
        params = SlamParams(association=association)
    else:
        params = replace(config.params, association=association)
        corner_params, line_params = extractor_parameters(scenario, config)
        options = {'frontend': config.frontend, 'landmarks': config.landmarks,
                   'visibility': config.visibility, 'line_params': line_params}
    scans: List[ScanSample] = scenario.of_type(ScanSample)
    corners: List[list] = []
    snapshots: List[tuple] = []
    period_ns = int(display_period * 1e9)

    def record(k, slam, res) -> None:
        scan = scans[k]
        corners.append(extract_corners(scan.ranges, scan_angles(scan), np.isfinite(scan.ranges),
                                       scan.angle_increment, corner_params))
        if not snapshots or scan.stamp_ns - snapshots[-1][0] >= period_ns or \
                k == len(scans) - 1:
            c, ln = slam.landmark_kinds == CORNER, slam.landmark_kinds == LINE
            snapshots.append((scan.stamp_ns, k, slam.landmark_ids[c], slam.landmarks[c],
                              slam.landmark_covariances[c], slam.landmark_ids[ln],
                              slam.line_ends[ln]))

    run = run_slam(scenario, params, corner_params, callback=record, **options)
    mount = tuple(float(v) for v in scenario.laser.mount)
    counts: Dict[str, int] = {}
    with BagWriter(out) as writer:
        wanted = dict(VIEW_TOPICS)
        if not scenario.has_reference:
            for topic in ('/ground_truth/odom', '/ground_truth/path'):
                wanted.pop(topic)
        if scenario.world is None:
            wanted.pop('/world')
        for topic, name in wanted.items():
            writer.add_topic(topic, name, latched=topic in ('/world', '/tf_static'))

        def put(topic: str, stamp: int, msg) -> None:
            if isinstance(msg, bytes):
                writer.write_serialized(topic, stamp, msg)
            else:
                writer.write(topic, stamp, msg)
            counts[topic] = counts.get(topic, 0) + 1

        t0 = int(run.stamps[0])
        put('/tf_static', t0, _tf_bytes(t0, [('base_link', 'laser', mount)]))
        if '/world' in wanted:
            put('/world', t0, _world_markers(scenario.world, t0))
        for o in scenario.of_type(OdometrySample):
            put('/odom', o.stamp_ns, make_odometry(o.stamp_ns, 'odom', 'base_link', o.pose,
                                                   o.covariance))
        snap, last_path, path_ns = 0, -math.inf, int(path_period * 1e9)
        paths = {'/path': _PathTopic(run.stamps, run.poses, 'map'),
                 '/odom/path': _PathTopic(run.stamps, run.odometry, 'odom')}
        if scenario.has_reference:
            paths['/ground_truth/path'] = _PathTopic(run.stamps, run.truth, 'map')
        for k, scan in enumerate(scans):
            t = int(scan.stamp_ns)
            put('/scan', t, make_scan(t, 'laser', scan.angle_min, scan.angle_increment,
                                      scan.ranges, scan.range_min, scan.range_max,
                                      scan.time_increment, scan.scan_time))
            put('/corners', t, make_corner_pose_array(t, 'laser', corners[k]))
            put('/corners/markers', t, make_corner_markers(t, 'laser', corners[k]))
            put('/pose', t, make_pose_with_covariance_stamped(t, 'map', run.poses[k],
                                                              run.covariances[k]))
            odom = run.odometry[k]
            map_to_odom = compose(run.poses[k], relative(odom, np.zeros(3)))
            put('/tf', t, _tf_bytes(t, [('map', 'odom', map_to_odom),
                                        ('odom', 'base_link', odom)]))
            if scenario.has_reference:
                put('/ground_truth/odom', t, make_odometry(t, 'map', 'base_link',
                                                           run.truth[k]))
            if snap < len(snapshots) and snapshots[snap][1] == k:
                _, _, ids, means, covs, line_ids, line_ends = snapshots[snap]
                snap += 1
                put('/landmarks', t, make_landmark_markers(t, 'map', ids, means, covs,
                                                           line_ids=line_ids,
                                                           line_ends=line_ends))
            if t - last_path >= path_ns or k == len(scans) - 1:
                last_path = t
                put('/path', t, paths['/path'].path(k))
                put('/odom/path', t, paths['/odom/path'].path(k))
                if scenario.has_reference:
                    put('/ground_truth/path', t, paths['/ground_truth/path'].path(k))
    mcap = next(out.glob('*.mcap'))
    return {'mcap': str(mcap), 'counts': counts}


__all__ = ['VIEW_TOPICS', 'write_slam_view']
