"""Executable ``road_classifier``: tilted-laser terrain classes, vision road outline, route.

Visual navigation chapter §4. Subscribes (sensor-data QoS) the tilted scan
(sensor_msgs/LaserScan on ``scan_topic``, default ``tilted_scan``; its pose in base_link is
``laser_mount``), ``camera/image_raw`` (sensor_msgs/Image rgb8 or bgr8) with
``camera/camera_info`` (pose ``camera_mount``) and ``odom`` (nav_msgs/Odometry). Publishes,
in ``base_frame`` with the scan's stamp after every scan with valid readings:

* ``road/grid`` (nav_msgs/OccupancyGrid, a local grid ahead of the robot: 0 = traversable
  (laser segments, corridor intervals, inside the vision outline), 100 = not traversable
  (laser readings classed so, obstacles), -1 = unknown): usable as a Nav2 costmap source;
* ``road/segments`` (visualization_msgs/MarkerArray: traversable segments green, obstacle
  readings red, the non-traversable readings grey);
* ``road/route`` (nav_msgs/Path): the chosen route along the best corridor;
* ``road/width`` (geometry_msgs/Vector3Stamped): x = road width from the laser, y = from
  vision (in the robot's ground plane), z = number of corridors; NaN where not measured;

and after every camera frame with a usable seed: ``road/outline`` (geometry_msgs/
PolygonStamped, the outline on the ground plane, z = 0), ``road/outline_confidence``
(geometry_msgs/Vector3Stamped: x = the outline's confidence in [0, 1], y = 1 when reliable,
0 when flagged: below ``min_outline_confidence`` or its row fill, z, below
``min_outline_row_fill``, then not fused, the route follows the laser) and, with
``publish_debug_image``, ``road/debug_image`` (sensor_msgs/Image bgr8).

The seed area of the vision outline is the newest laser's traversable segment under the
robot projected through the camera model (a band ``seed_thickness_px`` thick). Bad input
(no valid readings, a laser tilt that never reaches the ground, a frame without
CameraInfo, a seed area outside the image, undecodable messages) gives a warning throttled
per kind of problem; nothing is republished for it.
"""

import math

import cv2
from geometry_msgs.msg import Point, Point32, PolygonStamped, PoseStamped, Vector3Stamped
from landmark_nav.conversions import (array_to_image, camera_info_to_model, ConversionError,
                                      image_to_array, make_occupancy_grid, ns_to_stamp,
                                      odometry_to_pose, scan_to_data, stamp_to_ns)
from landmark_nav.geometry import transform_points
from landmark_nav.nodes.common import (declare, InputStats, ParameterError, ProblemWarner,
                                       reject_undeclared, run_node, SENSOR_QOS)
from landmark_nav.road.configuration import parameters, road_configuration
from landmark_nav.road.fusion import (choose_route, extend_with_outline,
                                      ground_to_pixels, laser_corridors, MIN_VISION_LINES,
                                      pixels_to_ground, plan_routes, road_widths,
                                      vision_lines)
from landmark_nav.road.outline import polyline_seed, road_outline, SeedError
from landmark_nav.road.road_cnn import default_cnn_criterion
from landmark_nav.road.road_probability import default_model
from landmark_nav.road.terrain import classify_scan, NOT_TRAVERSABLE
from nav_msgs.msg import OccupancyGrid, Odometry, Path
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, LaserScan
from visualization_msgs.msg import Marker, MarkerArray


class RoadClassifier(Node):
    """Thin node: scan -> classify_scan -> corridors/route; image -> road_outline."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters and create the interfaces."""
        super().__init__('road_classifier', **kwargs)
        values = {name: declare(self, name, *p[:4]) for name, p in parameters().items()}
        reject_undeclared(self)
        try:
            config = road_configuration(values)
            if config.outline.method == 'learned':
                default_model()
            elif config.outline.method == 'cnn':
                default_cnn_criterion()
        except (ValueError, OSError) as err:
            raise ParameterError(f'road_classifier: {err}') from err
        self.laser, self.terrain = config.laser, config.terrain
        self.fusion, self.outline_params = config.fusion, config.outline
        self.camera_mount = list(config.camera_mount)
        self.max_distance, self.seed_px = config.fusion.max_distance, config.seed_px
        self.outline_timeout = values['outline_timeout']
        self.resolution, self.half_width = values['grid_resolution'], values['grid_half_width']
        self.base_frame, self.debug = values['base_frame'], values['publish_debug_image']
        scan_topic = values['scan_topic']
        self.warner = ProblemWarner(self)
        self.stats = InputStats(self, self.warner)
        self.camera = None
        self.pose = None                 # latest odometry pose (x, y, yaw)
        self.history = []                # per scan, newest first: segment ends in odom
        self.vision_short = 0            # scans whose route the outline extended too little
        self.last_terrain = None         # (stamp_ns, TerrainScan)
        self.outline = None              # (stamp_ns, ground polygon (K, 2))
        self.scans = 0
        self.frames = 0
        self.pub_grid = self.create_publisher(OccupancyGrid, 'road/grid', 2)
        self.pub_markers = self.create_publisher(MarkerArray, 'road/segments', 2)
        self.pub_route = self.create_publisher(Path, 'road/route', 2)
        self.pub_width = self.create_publisher(Vector3Stamped, 'road/width', 10)
        self.pub_outline = self.create_publisher(PolygonStamped, 'road/outline', 2)
        self.pub_confidence = self.create_publisher(Vector3Stamped, 'road/outline_confidence',
                                                    10)
        self.unreliable = 0              # outlines flagged unreliable (not fused)
        self.pub_debug = self.create_publisher(Image, 'road/debug_image', 2) \
            if self.debug else None
        self.stats.subscribe(LaserScan, scan_topic, self.on_scan, SENSOR_QOS)
        self.stats.subscribe(Image, 'camera/image_raw', self.on_image, SENSOR_QOS)
        self.create_subscription(CameraInfo, 'camera/camera_info', self.on_info, SENSOR_QOS)
        self.create_subscription(Odometry, 'odom', self.on_odom, SENSOR_QOS)

    # ------------------------------------------------------------------ inputs
    def on_info(self, msg: CameraInfo) -> None:
        """Keep the latest valid camera model."""
        try:
            self.camera = camera_info_to_model(msg)
        except ConversionError as err:
            self.stats.drop('camera_info_malformed', f'Ignoring camera_info: {err}')

    def on_odom(self, msg: Odometry) -> None:
        """Keep the latest odometry pose."""
        try:
            self.pose = np.asarray(odometry_to_pose(msg).pose, dtype=float)
        except ConversionError as err:
            self.stats.drop('malformed', f'Dropping odometry: {err}')

    def on_scan(self, msg: LaserScan) -> None:
        """Classify one scan, fuse, publish grid, markers, route and widths."""
        try:
            scan = scan_to_data(msg)
        except ConversionError as err:
            self.stats.drop('bad_scan', f'Dropping scan: {err}')
            return
        ts = classify_scan(scan.ranges, scan.angles, self.laser, self.terrain,
                           scan.range_min, scan.range_max)
        if not np.any(ts.classes):
            self.stats.drop('no_valid', f'Dropping scan: no valid readings '
                            f'({scan.ranges.size} beams)')
            return
        if ts.ground_hits == 0:
            self.stats.drop('no_ground', 'Dropping scan: no reading reaches the ground; check '
                            'laser_mount (tilt) against the laser height')
            return
        stamp = scan.stamp_ns
        pose = np.zeros(3) if self.pose is None else self.pose
        ends = [(tuple(transform_points(pose, np.array([s.start]))[0]),
                 tuple(transform_points(pose, np.array([s.end]))[0])) for s in ts.segments]
        self.history.insert(0, ends)
        del self.history[self.fusion.history:]
        self.last_terrain = (stamp, ts)
        corridors = laser_corridors(self.history, pose, self.fusion)
        ground = None
        if self.outline is not None and abs(stamp - self.outline[0]) * 1e-9 <= \
                self.outline_timeout:
            ground = self.outline[1]
        corridors = [extend_with_outline(c, ground, self.fusion) for c in corridors]
        obstacles = np.vstack([o.points[:, :2] for o in ts.obstacles]) if ts.obstacles \
            else np.zeros((0, 2))
        route = choose_route(plan_routes(corridors, obstacles, self.fusion))
        if ground is not None and route is not None and \
                vision_lines(route.corridor) < MIN_VISION_LINES:
            # The outline stopped short (a hard shadow band, an unseen border): the laser
            # corridor carries the route; reported, not taken for the end of the road.
            self.vision_short += 1
            self.warner.warn(f'vision outline extends the route by '
                             f'{vision_lines(route.corridor)} intersection lines (< '
                             f'{MIN_VISION_LINES}); the route follows the laser corridor '
                             f'({self.vision_short} scans so far)')
        self.scans += 1
        self._publish(stamp, ts, corridors, route, ground, obstacles)
        self.stats.processed()

    def on_image(self, msg: Image) -> None:
        """Find the road outline seeded by the newest laser segment."""
        cam = self.camera
        if cam is None:
            self.stats.drop('no_camera_info', 'Dropping image: no valid CameraInfo received')
            return
        try:
            img = image_to_array(msg)
        except ConversionError as err:
            self.stats.drop('bad_image', f'Dropping image: {err}')
            return
        if msg.encoding not in ('rgb8', 'bgr8'):
            self.stats.drop('bad_image', f'Dropping image: encoding {msg.encoding} has no '
                            'colour (rgb8 or bgr8 needed for the chromaticity)')
            return
        if img.shape[:2] != (cam.height, cam.width):
            self.stats.drop('bad_image', f'Dropping image: size {img.shape[1]}x{img.shape[0]}'
                            f' disagrees with CameraInfo {cam.width}x{cam.height}')
            return
        rgb = img if msg.encoding == 'rgb8' else cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
        if self.last_terrain is None:
            self.stats.drop('no_seed', 'Dropping image: no laser scan with a traversable '
                            'segment yet (the seed area)')
            return
        ts = self.last_terrain[1]
        seg = ts.best_segment()
        if seg is None:
            self.stats.drop('no_seed', 'Dropping image: the newest scan has no traversable '
                            'segment (the seed area)')
            return
        pts = ts.points[seg.first:seg.last + 1]
        pts = pts[np.isfinite(pts).all(axis=1)]
        px = ground_to_pixels(cam, self.camera_mount, pts)
        px = px[np.isfinite(px).all(axis=1)]
        seed = polyline_seed(rgb.shape, px, self.seed_px) if len(px) else None
        if seed is None:
            self.stats.drop('seed_outside', 'Dropping image: the seed area (laser segment '
                            'through the camera model) lies outside the image; check '
                            'camera_mount and laser_mount')
            return
        try:
            out = road_outline(rgb, seed, self.outline_params)
        except SeedError as err:
            self.stats.drop('seed_outside', f'Dropping image: {err}')
            return
        stamp = stamp_to_ns(msg.header.stamp)
        ground = pixels_to_ground(cam, self.camera_mount, out.polygon, self.max_distance)
        ground = ground[np.isfinite(ground).all(axis=1)]
        conf = Vector3Stamped()
        conf.header.stamp = msg.header.stamp
        conf.header.frame_id = self.base_frame
        conf.vector.x, conf.vector.y = float(out.confidence), float(out.reliable)
        conf.vector.z = float(out.row_fill)
        self.pub_confidence.publish(conf)
        if out.reliable:
            self.outline = (stamp, ground)
        else:
            # A doubtful seed or no clear border: the fusion leans on the laser alone.
            self.outline = None
            self.unreliable += 1
            self.warner.warn(f'vision outline confidence {out.confidence:.2f} (limit '
                             f'{self.outline_params.min_confidence:.2f}: seed road-like, '
                             f'clear border), row fill {out.row_fill:.3f} (limit '
                             f'{self.outline_params.min_row_fill:.3f}: no gaps in its rows): '
                             f'not fused ({self.unreliable} frames so far)')
        self.frames += 1
        poly = PolygonStamped()
        poly.header.stamp = msg.header.stamp
        poly.header.frame_id = self.base_frame
        poly.polygon.points = [Point32(x=float(x), y=float(y), z=0.0) for x, y in ground]
        self.pub_outline.publish(poly)
        if self.pub_debug is not None:
            vis = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
            vis[out.mask] = (0.6 * vis[out.mask] + np.array([0, 100, 0])).astype(np.uint8)
            vis[seed] = (255, 60, 0)
            if len(out.polygon):
                cv2.polylines(vis, [out.polygon.astype(np.int32).reshape(-1, 1, 2)], True,
                              (0, 255, 255), 1)
            self.pub_debug.publish(array_to_image(vis, 'bgr8', stamp, msg.header.frame_id))
        self.stats.processed()

    # ------------------------------------------------------------------ outputs
    def _publish(self, stamp: int, ts, corridors, route, ground, obstacles) -> None:
        self.pub_grid.publish(self._grid(stamp, ts, corridors, ground, obstacles))
        self.pub_markers.publish(self._markers(stamp, ts))
        path = Path()
        path.header.frame_id = self.base_frame
        path.header.stamp = ns_to_stamp(stamp)
        if route is not None:
            for x, y in route.points:
                ps = PoseStamped()
                ps.header = path.header
                ps.pose.position.x, ps.pose.position.y = float(x), float(y)
                ps.pose.orientation.w = 1.0
                path.poses.append(ps)
        self.pub_route.publish(path)
        width = Vector3Stamped()
        width.header = path.header
        lw, vw = road_widths(route.corridor) if route is not None else (None, None)
        width.vector.x = math.nan if lw is None else float(lw)
        width.vector.y = math.nan if vw is None else float(vw)
        width.vector.z = float(len(corridors))
        self.pub_width.publish(width)

    def _grid(self, stamp: int, ts, corridors, ground, obstacles):
        res = self.resolution
        w = int(round(2 * self.half_width / res))
        h = int(round(self.max_distance / res))
        grid = np.full((w, h), -1, dtype=np.int8)         # rows = y, columns = x

        def cell(xy):
            xy = np.asarray(xy, dtype=float).reshape(-1, 2)
            return np.column_stack([(xy[:, 0] / res), (xy[:, 1] + self.half_width) / res])
        if ground is not None and len(ground) >= 3:
            cv2.fillPoly(grid, [np.round(cell(ground)).astype(np.int32).reshape(-1, 1, 2)], 0)
        for c in corridors:
            for iv in c.intervals:
                x0, x1 = iv.x - 0.5 * self.fusion.line_step, iv.x + 0.5 * self.fusion.line_step
                a, b = cell([(x0, iv.lo), (x1, iv.hi)])
                cv2.rectangle(grid, tuple(np.round(a).astype(int)),
                              tuple(np.round(b).astype(int)), 0, -1)
        bad = ts.points[ts.classes == NOT_TRAVERSABLE][:, :2]
        for pts in (bad, obstacles):
            if len(pts):
                ij = np.floor(cell(pts)).astype(int)
                ok = (ij[:, 0] >= 0) & (ij[:, 0] < h) & (ij[:, 1] >= 0) & (ij[:, 1] < w)
                grid[ij[ok, 1], ij[ok, 0]] = 100
        return make_occupancy_grid(grid, res, [0.0, -self.half_width, 0.0], self.base_frame,
                                   stamp)

    def _markers(self, stamp: int, ts) -> MarkerArray:
        out = MarkerArray()
        clear = Marker()
        clear.action = Marker.DELETEALL
        out.markers.append(clear)
        groups = [('traversable', (0.1, 0.8, 0.1), np.concatenate(
            [np.arange(s.first, s.last + 1) for s in ts.segments]) if ts.segments else []),
            ('not_traversable', (0.5, 0.5, 0.5), np.flatnonzero(ts.classes == NOT_TRAVERSABLE)),
            ('obstacles', (0.9, 0.1, 0.1), np.concatenate(
                [np.arange(o.first, o.last + 1) for o in ts.obstacles]) if ts.obstacles
             else [])]
        for k, (ns, rgb, idx) in enumerate(groups):
            m = Marker()
            m.header.frame_id = self.base_frame
            m.header.stamp = ns_to_stamp(stamp)
            m.ns, m.id, m.type, m.action = ns, k, Marker.POINTS, Marker.ADD
            m.scale.x = m.scale.y = 0.04
            m.color.r, m.color.g, m.color.b, m.color.a = (*rgb, 1.0)
            m.pose.orientation.w = 1.0
            for p in ts.points[np.asarray(idx, dtype=int)]:
                if np.all(np.isfinite(p)):
                    m.points.append(Point(x=float(p[0]), y=float(p[1]), z=float(p[2])))
            out.markers.append(m)
        return out


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav road_classifier``."""
    return run_node(RoadClassifier, args)


if __name__ == '__main__':
    raise SystemExit(main())
