"""Laser + vision fusion on the park-road simulator: vision road width, failures, routes.

For each frame the tilted laser is ray-cast and classified, its traversable segment under
the robot projected into the rendered camera view as the seed area, the road outline
found and put on the ground plane, and the laser corridor extended with it (eq. 30). The
vision road width is the median width of the corridor's outline intervals (in the robot's
ground plane, across its heading; Table 3's vision column). A frame is a vision failure
when the outline extends the corridor by fewer than ``MIN_LINES`` intersection lines or its
width is off the truth by more than ``FAIL_WIDTH`` metres (a vision failure, reported per
frame by :attr:`FusedFrame.vision_lines`). The route stays *open* when it exists, reaches
at least the laser line (where vision fails, the laser corridor carries it: the chapter's
"the laser scanner data is used only") and keeps the robot on the true road; a hard shadow
or a painted marking taken for the end of the road or for an obstacle would close it.

The outline here is the chapter's (eqs. 26-28, ``SIM_OUTLINE`` in ``SIM_CONFIG``): the
learned road probability is trained on real street photographs, and rendered frames are
another domain.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence

from landmark_nav.road.configuration import road_configuration, RoadConfiguration
from landmark_nav.road.fusion import (choose_route, Corridor, extend_with_outline,
                                      ground_to_pixels, MIN_VISION_LINES,
                                      pixels_to_ground, plan_routes, road_widths, Route,
                                      segment_interval, vision_lines)
from landmark_nav.road.outline import polyline_seed, road_outline, SeedError
from landmark_nav.road.terrain import classify_scan
from landmark_nav.sim.park_road import cast_scan, Lighting, ParkRoad, render_view
from landmark_nav.vision.camera import CameraModel
import numpy as np

ANGLES = np.radians(np.arange(-90.0, 90.25, 0.5))
CAMERA = CameraModel.from_fov(320, 240, math.radians(70.0))
#: road_classifier's defaults (camera_mount: the rendered camera's pose in base_link).
DEFAULT = road_configuration()
CAMERA_MOUNT = DEFAULT.camera_mount
MIN_LINES = MIN_VISION_LINES
FAIL_WIDTH = 1.0
#: The configuration of the simulated roads: the defaults with the chapter's outline
#: criterion (``outline_method: chapter``; the learned model is trained on photographs).
SIM_OUTLINE = {'outline_method': 'chapter'}
SIM_CONFIG = road_configuration(SIM_OUTLINE)
#: Lighting of the evaluation: overcast; soft and hard shadows of a row of trees across the
#: road (bands of 1.5 m and 1 m every 8 m).
LIGHTING = {'overcast': Lighting(),
            'soft_shadows': Lighting(shadows=((1.0, 2.5), (5.0, 6.0)), soft=0.8, period=8.0),
            'hard_shadows': Lighting(shadows=((1.0, 2.5), (5.0, 6.0)), soft=0.0, period=8.0)}


@dataclass(frozen=True, eq=False)
class FusedFrame:
    """Result of one simulated frame."""

    route: Optional[Route]
    corridor: Optional[Corridor]
    laser_width: Optional[float]
    vision_width: Optional[float]
    vision_lines: int
    image: np.ndarray
    outline: Optional[np.ndarray] = None     # (H, W) bool road mask of the vision outline
    seed: Optional[np.ndarray] = None        # (H, W) bool seed area (the laser segment)


def fuse_frame(road: ParkRoad, pose: Sequence[float], lighting: Lighting = Lighting(),
               markings: bool = False, rng: Optional[np.random.Generator] = None,
               config: RoadConfiguration = SIM_CONFIG) -> FusedFrame:
    """Run laser, vision and fusion on one simulated frame at robot pose (x, y, yaw).

    ``config``: the ``road_classifier`` configuration (laser and camera mounts, terrain,
    fusion and outline parameters), as the node runs it (default :data:`SIM_CONFIG`).
    """
    mount, camera_mount, fusion = config.laser, config.camera_mount, config.fusion
    sc = cast_scan(road, pose, mount, ANGLES, rng=rng)
    ts = classify_scan(sc.ranges, sc.angles, mount, config.terrain)
    img = render_view(road, pose, CAMERA, camera_mount, lighting, markings, rng,
                      gravel=road.crown > 0.1)
    seg = ts.best_segment()
    if seg is None:
        return FusedFrame(None, None, None, None, 0, img)
    corridor = Corridor((segment_interval(seg.start, seg.end),))
    pts = ts.points[seg.first:seg.last + 1]
    px = ground_to_pixels(CAMERA, camera_mount, pts[np.isfinite(pts).all(axis=1)])
    seed = polyline_seed(img.shape, px[np.isfinite(px).all(axis=1)], config.seed_px)
    ground = mask = None
    if seed is not None:
        try:
            out = road_outline(img, seed, config.outline)
            mask = out.mask
            ground = pixels_to_ground(CAMERA, camera_mount, out.polygon, fusion.max_distance)
            ground = ground[np.isfinite(ground).all(axis=1)]
        except SeedError:
            ground = None
    extended = extend_with_outline(corridor, ground, fusion)
    obstacles = np.vstack([o.points[:, :2] for o in ts.obstacles]) if ts.obstacles else None
    route = choose_route(plan_routes([extended], obstacles, fusion))
    lw, vw = road_widths(extended)
    lines = vision_lines(extended)
    return FusedFrame(route, extended, lw, vw, lines, img, mask, seed)


@dataclass(frozen=True)
class VisionRoadScore:
    """Vision road width of one road kind under one lighting."""

    kind: str
    lighting: str
    true_width: float
    frames: int
    width_mean: float
    width_std: float
    widths: int
    failures: int
    routes_open: int = 0            # frames whose route is open (see the module docstring)
    reach_median: float = math.nan  # median distance the route reaches ahead [m]


def route_open(road: ParkRoad, pose: Sequence[float], frame: FusedFrame,
               robot_width: float = DEFAULT.fusion.robot_width) -> bool:
    """Whether a frame's route exists, reaches the laser line and keeps the robot on the road.

    The laser line is the farthest laser interval of the corridor; on the road: every route
    point (base_link, the robot centre) lies at least ``robot_width / 2`` inside the true
    edges (world y).
    """
    if frame.route is None or frame.corridor is None:
        return False
    laser = [i.x for i in frame.corridor.intervals if i.source == 'laser']
    pts = frame.route.points
    if not laser or pts[-1, 0] < max(laser) - 1e-9:
        return False
    c, s = math.cos(pose[2]), math.sin(pose[2])
    y = pose[1] + s * pts[:, 0] + c * pts[:, 1]
    return bool(np.all(np.abs(y) <= 0.5 * (road.width - robot_width) + 1e-9))


def evaluate_vision_road(kind: str, lighting: str = 'overcast', frames: int = 250,
                         seed: int = 0, markings: bool = False,
                         config: RoadConfiguration = SIM_CONFIG) -> VisionRoadScore:
    """Score the vision road width on ``frames`` simulated frames (Table 3 style).

    ``config``: the ``road_classifier`` configuration (:func:`fuse_frame`).
    """
    road = ParkRoad.of_kind(kind, seed=seed)
    rng = np.random.default_rng(seed)
    widths, failures, opened, reach = [], 0, 0, []
    for i in range(frames):
        pose = (0.2 * i, float(rng.normal(0.0, 0.3)), float(rng.normal(0.0, 0.05)))
        f = fuse_frame(road, pose, LIGHTING[lighting], markings, rng, config)
        opened += route_open(road, pose, f, config.fusion.robot_width)
        reach.append(float(f.route.points[-1, 0]) if f.route is not None else 0.0)
        if f.vision_width is None or f.vision_lines < MIN_LINES or \
                abs(f.vision_width * math.cos(pose[2]) - road.width) > FAIL_WIDTH:
            failures += 1
            continue
        widths.append(f.vision_width * math.cos(pose[2]))       # across the road
    w = np.array(widths)
    return VisionRoadScore(kind, lighting, road.width, frames,
                           float(w.mean()) if w.size else math.nan,
                           float(w.std()) if w.size else math.nan, int(w.size), failures,
                           opened, float(np.median(reach)) if reach else math.nan)


#: The five overlay cases of docs/road_following.md: (title, road kind, lighting, markings,
#: pedestrian).
OVERLAY_CASES = (('asphalt, overcast', 'asphalt', 'overcast', False, False),
                 ('asphalt, soft shadows', 'asphalt', 'soft_shadows', False, False),
                 ('asphalt, hard shadows', 'asphalt', 'hard_shadows', False, False),
                 ('gravel, overcast', 'gravel', 'overcast', False, False),
                 ('markings, pedestrian 7 m', 'asphalt', 'overcast', True, True))


def sim_overlay(road: ParkRoad, pose: Sequence[float], frame: FusedFrame,
                title: str = '', camera_mount: Sequence[float] = CAMERA_MOUNT) -> np.ndarray:
    """Return a BGR overlay of one fused frame.

    Vision outline green, seed (the laser segment) blue, the true road edges red, the
    chosen route yellow.
    """
    import cv2
    vis = cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR)
    if frame.outline is not None:
        m = frame.outline
        vis[m] = (0.55 * vis[m] + np.array([0, 110, 0])).astype(np.uint8)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx = np.linspace(0.5, 40.0, 200)      # world x ahead of the robot
    for edge in road.edges():             # world (x, edge) -> base_link
        dy = edge - pose[1]
        pts = np.column_stack([c * dx + s * dy, -s * dx + c * dy])
        px = ground_to_pixels(CAMERA, camera_mount, pts)
        px = px[np.isfinite(px).all(axis=1)].round().astype(np.int32)
        cv2.polylines(vis, [px], False, (0, 0, 255), 1)
    if frame.seed is not None:
        vis[frame.seed] = (255, 60, 0)
    if frame.route is not None:
        px = ground_to_pixels(CAMERA, camera_mount, frame.route.points)
        px = px[np.isfinite(px).all(axis=1)].round().astype(np.int32)
        cv2.polylines(vis, [px], False, (0, 230, 255), 2)
    if title:
        cv2.putText(vis, title, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1)
    return vis


def write_sim_overlays(out, seed: int = 0, scale: float = 0.75, quality: int = 70,
                       config: RoadConfiguration = SIM_CONFIG):
    """Write the five overlays (:data:`OVERLAY_CASES`) as one JPEG montage (``config``).

    They are the overlays of docs/road_following.md.

    Rendered park-road frames (nothing from a data set), the robot 0.2 m left of the
    centre, heading 2 degrees off the road; the pedestrian stands 7 m ahead, 0.6 m left.
    """
    import cv2
    from pathlib import Path
    tiles = []
    for title, kind, light, markings, pedestrian in OVERLAY_CASES:
        road = ParkRoad.of_kind(kind, seed=seed,
                                cylinders=((7.0, 0.6, 0.25, 1.75),) if pedestrian else ())
        pose = (1.0, 0.2, math.radians(2.0))
        frame = fuse_frame(road, pose, LIGHTING[light], markings, np.random.default_rng(seed),
                           config)
        vis = sim_overlay(road, pose, frame, title, config.camera_mount)
        tiles.append(cv2.resize(vis, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA))
    top = np.hstack(tiles[:3])
    bottom = np.hstack(tiles[3:] + [np.zeros_like(tiles[0])])
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), np.vstack([top, bottom]),
                       [cv2.IMWRITE_JPEG_QUALITY, quality]):
        raise OSError(f'{path}: could not write the image')
    return path
