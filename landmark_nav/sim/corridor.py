"""A rendered corridor for the corridor follower (visual navigation chapter §3): scene and views.

World frame = the corridor frame of :mod:`landmark_nav.corridor.lateral`: x along the
corridor from its start, y to the left (0 on the centre line), z up from the floor. The
scene is a list of :class:`~.camera.Plane`: floor, ceiling, two walls, dark skirting boards
along the wall/floor edges, door niches (darker door leaves set into the walls) and an
optional floor centre line. A robot pose ``(x, y, theta)`` and the camera mount give the
camera pose; :func:`corridor_view` renders one frame with its ground truth.

Drives on drifting odometry into bags: :mod:`.corridor_record`; the closed loop through the
``corridor_follower`` node: :mod:`.corridor_loop`.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

from landmark_nav.corridor.orientation import mount_rotation
from landmark_nav.sim.camera import CameraSimulator, Photometry, Plane, rotation_z
from landmark_nav.sim.textures import wall
from landmark_nav.vision.camera import CameraModel
import numpy as np

#: Plane orientations (columns: normal out of the texture, texture right, texture up).
_FLOOR = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]).T
_CEILING = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]).T
_LEFT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T
_RIGHT = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T


@dataclass(frozen=True)
class CorridorConfig:
    """Geometry and appearance of the rendered corridor.

    Attributes:
        length: corridor length [m].
        width: wall-to-wall width [m].
        height: floor-to-ceiling height [m].
        skirting: height of the dark skirting boards [m] (0: none).
        doors_per_side: door leaves per wall (0.9 m x 2.0 m, set 1 cm into the wall).
        centre_line: a dark 5 cm floor line along the centre.
        texel: texture resolution [m per texel].
        people: people standing in the corridor (0.5 m x 1.7 m two-sided boards with
            blotchy clothing texture, at random places; occluders).
        open_doors: door leaves opened 90 deg into the corridor (0.8 m deep; occluders).
    """

    length: float = 30.0
    width: float = 2.0
    height: float = 2.6
    skirting: float = 0.08
    doors_per_side: int = 4
    centre_line: bool = False
    texel: float = 0.01
    people: int = 0
    open_doors: int = 0


def corridor_scene(config: CorridorConfig, seed: int) -> List[Plane]:
    """Return the planes of the corridor (deterministic for a seed)."""
    rng = np.random.default_rng(seed)
    c = config
    m = c.texel
    nl, nw, nh = int(round(c.length / m)), int(round(c.width / m)), int(round(c.height / m))
    mid = c.length / 2
    planes = [
        Plane(wall(rng, (nl, nw), mean=95.0, contrast=8.0), m, _FLOOR, [mid, 0.0, 0.0],
              'floor', detail=False),
        Plane(wall(rng, (nl, nw), mean=235.0, contrast=4.0), m, _CEILING,
              [mid, 0.0, c.height], 'ceiling', detail=False),
        Plane(wall(rng, (nh, nl), mean=185.0, contrast=8.0), m, _LEFT,
              [mid, c.width / 2, c.height / 2], 'wall', detail=False),
        Plane(wall(rng, (nh, nl), mean=175.0, contrast=8.0), m, _RIGHT,
              [mid, -c.width / 2, c.height / 2], 'wall', detail=False),
    ]
    inset = 0.002
    if c.skirting > 0:
        ns = max(1, int(round(c.skirting / m)))
        for R, y in ((_LEFT, c.width / 2 - inset), (_RIGHT, -c.width / 2 + inset)):
            planes.append(Plane(np.full((ns, nl), 40, np.uint8), m, R,
                                [mid, y, c.skirting / 2], 'skirting'))
    for side, (R, y) in enumerate(((_LEFT, c.width / 2 - 2 * inset),
                                   (_RIGHT, -c.width / 2 + 2 * inset))):
        for k in range(c.doors_per_side):
            x = (k + 0.5 + 0.25 * side) * c.length / c.doors_per_side
            if x + 0.45 > c.length:
                continue
            tex = np.full((int(round(2.0 / m)), int(round(0.9 / m))), 120, np.uint8)
            tex[:, :int(round(0.05 / m))] = 60       # frame
            tex[:, -int(round(0.05 / m)):] = 60
            tex[:int(round(0.05 / m)), :] = 60
            planes.append(Plane(tex, m, R, [x, y, 1.0 + c.skirting / 2], 'door'))
    across = np.column_stack([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    for _ in range(c.people):
        x, y = rng.uniform(4.0, c.length - 2.0), rng.uniform(-c.width / 3, c.width / 3)
        tex = wall(rng, (int(round(1.7 / m)), int(round(0.5 / m))), mean=70.0, contrast=40.0)
        planes.append(Plane(tex, m, across, [x, y, 0.86], 'person', two_sided=True))
    for k in range(c.open_doors):
        side = 1.0 if k % 2 == 0 else -1.0
        x = rng.uniform(4.0, c.length - 2.0)
        tex = np.full((int(round(2.0 / m)), int(round(0.8 / m))), 110, np.uint8)
        tex[:, :int(round(0.04 / m))] = 50
        y = side * (c.width / 2 - 0.4 - inset)
        planes.append(Plane(tex, m, across, [x, y, 1.01], 'open_door', two_sided=True))
    if c.centre_line:
        planes.append(Plane(np.full((nl, max(1, int(round(0.05 / m)))), 20, np.uint8), m,
                            _FLOOR, [mid, 0.0, 0.001], 'centre_line'))
    return planes


def camera_pose(robot: Sequence[float], mount: Sequence[float]) -> Tuple[np.ndarray,
                                                                         np.ndarray]:
    """Return (world-from-optical rotation, camera position) for a robot ``(x, y, theta)``."""
    x, y, th = (float(v) for v in robot)
    m = np.asarray(mount, dtype=float).reshape(6)
    rz = rotation_z(th)
    return rz @ mount_rotation(m), np.array([x, y, 0.0]) + rz @ m[:3]


@dataclass(frozen=True, eq=False)
class CorridorView:
    """One rendered frame and its truth (robot ``(x, y, theta)`` in the corridor frame)."""

    image: np.ndarray
    robot: Tuple[float, float, float]


def corridor_view(sim: CameraSimulator, planes: Sequence[Plane], robot: Sequence[float],
                  mount: Sequence[float], photometry: Photometry = Photometry(),
                  rng: Optional[np.random.Generator] = None) -> CorridorView:
    """Render the corridor from a robot pose."""
    R, t = camera_pose(robot, mount)
    img = sim.render(planes, R, t, photometry, rng)
    return CorridorView(img, tuple(float(v) for v in robot))


def default_corridor_camera(downscale: int = 1) -> CameraModel:
    """Return a 640 x 480 camera with a 70 deg horizontal field of view, mild distortion.

    Args:
        downscale: 1, 2 or 4: the same camera at 640 x 480 / ``downscale`` (binned pixels:
            the intrinsics scaled about the pixel centres, the distortion unchanged).
    """
    if downscale not in (1, 2, 4):
        raise ValueError(f'downscale must be 1, 2 or 4; got {downscale!r}')
    f = 320.0 / math.tan(math.radians(35.0))
    K = np.array([[f, 0.0, 319.5], [0.0, f, 239.5], [0.0, 0.0, 1.0]])
    s = 1.0 / downscale
    S = np.array([[s, 0.0, 0.5 * s - 0.5], [0.0, s, 0.5 * s - 0.5], [0.0, 0.0, 1.0]])
    return CameraModel(640 // downscale, 480 // downscale, S @ K,
                       np.array([-0.08, 0.03, 0.0, 0.0, 0.0]))
