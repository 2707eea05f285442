"""A textured scene rendered from a 3-D line model (monocular localization, chapter §5).

Every face of a :class:`~landmark_nav.monocular.model.LineModel` that is a rectangle becomes
a textured :class:`~.camera.Plane` (normal = the face's normal; the hallway model's faces
point into the hallway). The grey level depends on the face's orientation and place, so the
model's edges (creases between floor, walls, doors, niche sides, lintels) show as image
edges, while coplanar faces of one wall share one level and show none:

=================================  ==========
face                               mean grey
=================================  ==========
floor (normal up, z = 0)           95
ceiling / lintel underside (down)  230 / 205
walls facing +-y at the hallway    180
doors (facing +-y, set back)       120
niche sides and end walls (+-x)    150 / 215
=================================  ==========

Optional clutter (:class:`SceneClutter`): people (two-sided 0.5 m x 1.7 m boards) walking
along the hallway at their own speed, and unmodelled door frames. The photometry (exposure,
gradient, noise) is set per frame by the caller
(:mod:`landmark_nav.evaluation.model_localization`).
"""

from dataclasses import dataclass
from typing import List, Sequence

from landmark_nav.monocular.model import LineModel
from landmark_nav.sim.camera import Plane
from landmark_nav.sim.textures import wall
import numpy as np

TEXEL = 0.01


def _face_grey(n: np.ndarray, centre: np.ndarray, half_width: float) -> float:
    if n[2] > 0.9:
        return 95.0
    if n[2] < -0.9:
        return 230.0 if centre[2] > 2.3 else 205.0
    if abs(n[1]) > 0.9:
        return 120.0 if abs(centre[1]) > half_width + 0.05 else 180.0
    return 150.0 if 0.5 < centre[0] < 21.0 else 215.0


def model_planes(model: LineModel, seed: int, texel: float = TEXEL,
                 detail: bool = True) -> List[Plane]:
    """Return textured planes for the rectangular faces of a model (deterministic per seed).

    ``detail=True`` (default) makes the renderer supersample them: its polygon coverage
    (``cv2.fillPoly``) includes boundary pixels, which moves the edges of planes drawn last
    outwards by up to one (canvas) pixel; without supersampling that shifted the hallway's
    vertical wall edges by 0.44 px on average and biased the localizer by about -2 cm.
    """
    rng = np.random.default_rng(seed)
    lo, hi = model.bounds()
    half_width = 0.5 * min(hi[1] - lo[1], 2.0) if hi[1] > lo[1] else 1.0
    half_width = 1.0 if abs(half_width - 1.0) < 0.3 else half_width
    planes = []
    for f in model.faces:
        v = model.vertices[f]
        right, up = v[1] - v[0], v[3] - v[0]
        w, h = float(np.linalg.norm(right)), float(np.linalg.norm(up))
        if w < texel or h < texel or abs(np.dot(right, up)) > 1e-6 * w * h:
            continue                               # triangles / non-rectangles: not drawn
        r, u = right / w, up / h
        n = np.cross(r, u)
        centre = v[0] + 0.5 * (right + up)
        grey = _face_grey(n, centre, half_width)
        tex = wall(rng, (max(1, int(round(h / texel))), max(1, int(round(w / texel)))),
                   mean=grey, contrast=6.0)
        planes.append(Plane(tex, texel, np.column_stack([n, r, u]), centre,
                            'floor' if n[2] > 0.9 else 'wall', detail=detail))
    return planes


@dataclass(frozen=True)
class SceneClutter:
    """Unmodelled things in the rendered hallway.

    Attributes:
        people: people walking along the hallway (boards 0.5 m x 1.7 m).
        person_speed: walking speed [m/s] (each walks back and forth at this speed).
        door_frames: draw a dark 5 cm frame on each door (lines the model does not have).
    """

    people: int = 2
    person_speed: float = 0.6
    door_frames: bool = True


def people_planes(clutter: SceneClutter, t: float, length: float, seed: int) -> List[Plane]:
    """Return the people's boards at time ``t`` [s] (deterministic per seed)."""
    rng = np.random.default_rng(seed + 7919)
    out = []
    across = np.column_stack([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    for _ in range(clutter.people):
        x0 = rng.uniform(2.0, length - 2.0)
        y = rng.uniform(-0.6, 0.6)
        span = length - 4.0
        s = (x0 - 2.0 + clutter.person_speed * t) % (2 * span)
        x = 2.0 + (s if s < span else 2 * span - s)
        tex = wall(rng, (170, 50), mean=70.0, contrast=40.0)
        out.append(Plane(tex, TEXEL, across, [x, y, 0.86], 'person', two_sided=True))
    return out


def door_frame_planes(model: LineModel, half_width: float = 1.0) -> List[Plane]:
    """Return thin dark frames in front of the door faces (unmodelled lines)."""
    out = []
    for f in model.faces:
        v = model.vertices[f]
        right, up = v[1] - v[0], v[3] - v[0]
        w, h = float(np.linalg.norm(right)), float(np.linalg.norm(up))
        if w < TEXEL or h < TEXEL:
            continue
        n = np.cross(right / w, up / h)
        centre = v[0] + 0.5 * (right + up)
        if abs(n[1]) < 0.9 or abs(centre[1]) <= half_width + 0.05 or centre[2] > 1.5:
            continue
        tex = np.full((int(round(h / TEXEL)), int(round(w / TEXEL))), 130, np.uint8)
        b = int(round(0.05 / TEXEL))
        tex[:, :b] = 55                 # frame: both sides and the top
        tex[:, -b:] = 55
        tex[:b, :] = 55
        out.append(Plane(tex, TEXEL, np.column_stack([n, right / w, up / h]),
                         centre + 0.003 * n, 'door'))
    return out


def scene_at(static: Sequence[Plane], clutter: SceneClutter, t: float, length: float,
             seed: int) -> List[Plane]:
    """Return the static planes plus the people at time ``t``."""
    return list(static) + people_planes(clutter, t, length, seed)
