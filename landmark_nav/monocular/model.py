"""3-D line model of the environment: vertices, edges and faces (self-localization chapter §5.1).

The chapter draws its hallway in Blender as one object listing vertices, edges (two
vertices) and faces (three or four vertices). We keep that notation in a small YAML file:

.. code-block:: yaml

    # landmark_nav 3-D line model
    format: landmark_nav_line_model/1
    frame_id: map            # the frame the vertices are given in
    vertices:                # [x, y, z] in metres, z up from the floor
      - [0.0, -1.0, 0.0]
      - ...
    edges:                   # [i, j]: vertex indices (0-based) of a visible model line
      - [0, 1]
    faces:                   # [i, j, k] or [i, j, k, l]: a planar convex polygon (occluder)
      - [0, 1, 5, 4]

Edges are the lines the camera can see (creases, boundaries of differently coloured
surfaces); faces are only occluders for the visibility test (:mod:`.visibility`), so a wall
may be split into several coplanar faces without creating an edge. Every error names the
file and line.

:func:`hallway_model` builds the default model, the chapter's hallway (about 21.5 m x 2 m
with door niches, our ``hallway`` simulator scenario); :data:`DEFAULT_MODEL_PATH` is the
same model as a file, shipped with the package.
"""

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Dict, List, Sequence, Tuple, Union

import numpy as np
import yaml

FORMAT = 'landmark_nav_line_model/1'
DEFAULT_MODEL_PATH = Path(__file__).with_name('hallway_model.yaml')


class ModelError(ValueError):
    """A line model file or array is invalid; the message names the file and line."""


@dataclass(frozen=True, eq=False)
class LineModel:
    """A 3-D line model.

    Attributes:
        vertices: (V, 3) float64 vertex positions [m] in ``frame_id``.
        edges: (E, 2) int64 vertex indices of the model lines.
        faces: (F, 4) int64 vertex indices of the faces; a triangle repeats its last vertex.
        frame_id: frame of the vertices (``map``).
    """

    vertices: np.ndarray
    edges: np.ndarray
    faces: np.ndarray
    frame_id: str = 'map'

    def __post_init__(self) -> None:
        """Check shapes, indices and planarity."""
        v = np.asarray(self.vertices, dtype=float).reshape(-1, 3)
        e = np.asarray(self.edges, dtype=np.int64).reshape(-1, 2)
        f = np.asarray(self.faces, dtype=np.int64)
        if f.size == 0:
            f = f.reshape(0, 4)
        if f.ndim != 2 or f.shape[1] not in (3, 4):
            raise ModelError(f'faces must be (F, 3) or (F, 4); got {f.shape}')
        if f.shape[1] == 3:
            f = np.column_stack([f, f[:, 2]])
        if not np.all(np.isfinite(v)):
            raise ModelError('vertices must be finite')
        for name, idx in (('edge', e), ('face', f)):
            bad = np.nonzero((idx < 0) | (idx >= v.shape[0]))[0]
            if bad.size:
                raise ModelError(f'{name} {bad[0]} refers to a vertex outside 0..{v.shape[0] - 1}')
        if e.size and np.any(np.linalg.norm(v[e[:, 1]] - v[e[:, 0]], axis=1) <= 0):
            raise ModelError('an edge has zero length')
        for a in (v, e, f):
            a.setflags(write=False)
        object.__setattr__(self, 'vertices', v)
        object.__setattr__(self, 'edges', e)
        object.__setattr__(self, 'faces', f)

    @property
    def edge_points(self) -> np.ndarray:
        """(E, 2, 3) end points of the edges [m]."""
        return self.vertices[self.edges]

    def face_planes(self) -> Tuple[np.ndarray, np.ndarray]:
        """Return unit normals (F, 3) and offsets (F,) of the face planes (``n . x = d``)."""
        p = self.vertices[self.faces]
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        n2 = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])   # quads: use the larger one
        n = np.where((np.linalg.norm(n2, axis=1) > np.linalg.norm(n, axis=1))[:, None], n2, n)
        norm = np.linalg.norm(n, axis=1)
        norm[norm == 0] = 1.0
        n = n / norm[:, None]
        return n, np.einsum('ij,ij->i', n, p[:, 0])

    def bounds(self) -> Tuple[np.ndarray, np.ndarray]:
        """Return the (3,) lower and upper corners of the vertices' bounding box."""
        if self.vertices.shape[0] == 0:
            return np.zeros(3), np.zeros(3)
        return self.vertices.min(axis=0), self.vertices.max(axis=0)


def _fail(path: str, node, message: str) -> ModelError:
    line = node.start_mark.line + 1 if node is not None else 1
    return ModelError(f'{path}:{line}: {message}')


def _numbers(path: str, seq, name: str, size: Sequence[int], kind: type) -> List[list]:
    if not isinstance(seq, yaml.SequenceNode):
        raise _fail(path, seq, f'{name} must be a list')
    out = []
    for k, item in enumerate(seq.value):
        if not isinstance(item, yaml.SequenceNode) or len(item.value) not in size:
            raise _fail(path, item, f'{name}[{k}] must be a list of {" or ".join(map(str, size))}'
                                    f' numbers')
        row = []
        for s in item.value:
            try:
                if not isinstance(s, yaml.ScalarNode):
                    raise ValueError
                x = float(s.value) if kind is float else int(s.value)
            except ValueError:
                raise _fail(path, s, f'{name}[{k}]: {s.value!r} is not '
                                     f'{"a number" if kind is float else "an integer"}') from None
            if kind is float and not math.isfinite(x):
                raise _fail(path, s, f'{name}[{k}]: {s.value!r} is not finite')
            row.append(x)
        out.append(row)
    return out


def load_model(path: Union[str, Path]) -> LineModel:
    """Read a line model file (format in the module docstring).

    Raises:
        ModelError: unreadable file, bad syntax or content (message: ``file:line: what``).
    """
    path = str(path)
    try:
        text = Path(path).read_text(encoding='utf-8')
    except OSError as err:
        raise ModelError(f'{path}: cannot read the line model: {err.strerror}') from err
    try:
        root = yaml.compose(text)
    except yaml.YAMLError as err:
        mark = getattr(err, 'problem_mark', None)
        line = mark.line + 1 if mark is not None else 1
        raise ModelError(f'{path}:{line}: not valid YAML: {getattr(err, "problem", err)}') \
            from err
    if not isinstance(root, yaml.MappingNode):
        raise _fail(path, root, 'a line model must be a mapping with vertices, edges, faces')
    items: Dict[str, object] = {}
    for k, v in root.value:
        items[k.value] = v
    fmt = items.get('format')
    if fmt is None or fmt.value != FORMAT:
        raise _fail(path, fmt if fmt is not None else root,
                    f'format must be {FORMAT!r}; got {getattr(fmt, "value", None)!r}')
    for key in ('vertices', 'edges', 'faces'):
        if key not in items:
            raise _fail(path, root, f'missing key {key!r}')
    frame = items.get('frame_id')
    vertices = _numbers(path, items['vertices'], 'vertices', (3,), float)
    edges = _numbers(path, items['edges'], 'edges', (2,), int)
    faces = _numbers(path, items['faces'], 'faces', (3, 4), int)
    nv = len(vertices)
    for name, rows in (('edges', edges), ('faces', faces)):
        for k, row in enumerate(rows):
            if any(i < 0 or i >= nv for i in row):
                raise _fail(path, items[name].value[k],
                            f'{name}[{k}] = {row} refers to a vertex outside 0..{nv - 1}')
    faces = [r + [r[-1]] if len(r) == 3 else r for r in faces]
    try:
        return LineModel(np.array(vertices, dtype=float).reshape(-1, 3),
                         np.array(edges, dtype=np.int64).reshape(-1, 2),
                         np.array(faces, dtype=np.int64).reshape(-1, 4),
                         frame.value if frame is not None else 'map')
    except ModelError as err:
        raise ModelError(f'{path}:1: {err}') from err


def dump_model(model: LineModel, header: str = '') -> str:
    """Return the YAML text of a model (the inverse of :func:`load_model`)."""
    lines = [f'# {s}' for s in header.splitlines()]
    lines += [f'format: {FORMAT}', f'frame_id: {model.frame_id}', 'vertices:']
    lines += [f'  - [{x:.4f}, {y:.4f}, {z:.4f}]' for x, y, z in model.vertices]
    lines.append('edges:')
    lines += [f'  - [{i}, {j}]' for i, j in model.edges]
    lines.append('faces:')
    for f in model.faces:
        row = list(f[:3]) if f[3] == f[2] else list(f)
        lines.append('  - [' + ', '.join(str(int(i)) for i in row) + ']')
    return '\n'.join(lines) + '\n'


class _Builder:
    """Collects vertices (deduplicated), edges and faces."""

    def __init__(self) -> None:
        self.index: Dict[tuple, int] = {}
        self.vertices: List[tuple] = []
        self.edges: List[tuple] = []
        self.faces: List[tuple] = []

    def v(self, x: float, y: float, z: float) -> int:
        key = (round(x, 6), round(y, 6), round(z, 6))
        if key not in self.index:
            self.index[key] = len(self.vertices)
            self.vertices.append(key)
        return self.index[key]

    def edge(self, a: tuple, b: tuple) -> None:
        self.edges.append((self.v(*a), self.v(*b)))

    def face(self, inside: tuple, *pts: tuple) -> None:
        """Add a planar convex polygon, ordered so that its normal points to ``inside``."""
        p = np.array(pts, dtype=float)
        n = np.cross(p[1] - p[0], p[2] - p[0])
        if np.dot(n, np.asarray(inside, dtype=float) - p[0]) < 0:
            pts = pts[::-1]
        self.faces.append(tuple(self.v(*q) for q in pts))

    def model(self) -> LineModel:
        return LineModel(np.array(self.vertices), np.array(self.edges),
                         np.array(self.faces), 'map')


#: The ``hallway`` scenario geometry (landmark_nav.sim.scenarios), repeated here because a
#: core does not import the simulator; a test checks that the two agree.
HALLWAY_LENGTH = 21.5
HALLWAY_WIDTH = 2.0
HALLWAY_HEIGHT = 2.6
NICHE_WIDTH = 0.9
NICHE_DEPTH = 0.25
NICHE_HEIGHT = 2.0
HALLWAY_NICHES_SOUTH = (3.5, 9.5, 15.5)
HALLWAY_NICHES_NORTH = (6.5, 12.5, 18.5)


def hallway_model(length: float = HALLWAY_LENGTH, width: float = HALLWAY_WIDTH,
                  height: float = HALLWAY_HEIGHT,
                  niches_south: Sequence[float] = HALLWAY_NICHES_SOUTH,
                  niches_north: Sequence[float] = HALLWAY_NICHES_NORTH,
                  niche_width: float = NICHE_WIDTH, niche_depth: float = NICHE_DEPTH,
                  niche_height: float = NICHE_HEIGHT) -> LineModel:
    """Return the hallway: a closed box with door niches (recessed doors) in both long walls.

    Frame: x along the hallway from its west end (0 .. length), y to the left (north),
    0 on the centre line, z up from the floor. Faces have their normals into the hallway.
    Edges: wall/floor and wall/ceiling lines (the floor lines broken at the niches), the
    four vertical corners at the ends, and per niche its 4 vertical edges, 4 floor edges
    and 4 edges at the lintel.
    """
    b = _Builder()
    hw, hn, L, H = 0.5 * width, 0.5 * niche_width, length, height
    centre = (0.5 * L, 0.0, 0.5 * H)
    b.face(centre, (0, -hw, 0), (L, -hw, 0), (L, hw, 0), (0, hw, 0))           # floor
    b.face(centre, (0, -hw, H), (0, hw, H), (L, hw, H), (L, -hw, H))           # ceiling
    b.face(centre, (0, -hw, 0), (0, hw, 0), (0, hw, H), (0, -hw, H))           # west end
    b.face(centre, (L, -hw, 0), (L, -hw, H), (L, hw, H), (L, hw, 0))           # east end
    for x in (0.0, L):
        for y in (-hw, hw):
            b.edge((x, y, 0), (x, y, H))
        b.edge((x, -hw, 0), (x, hw, 0))
        b.edge((x, -hw, H), (x, hw, H))
    zn = niche_height
    for side, niches in ((-1.0, niches_south), (1.0, niches_north)):
        y = side * hw
        yb = side * (hw + niche_depth)
        b.edge((0, y, H), (L, y, H))
        xs = [0.0]
        for cx in sorted(niches):
            x0, x1 = cx - hn, cx + hn
            xs += [x0, x1]
            for x in (x0, x1):
                b.edge((x, y, 0), (x, y, zn))          # vertical edges at the wall
                b.edge((x, yb, 0), (x, yb, zn))        # and at the back (door)
                b.edge((x, y, 0), (x, yb, 0))          # floor edges of the side faces
                b.edge((x, y, zn), (x, yb, zn))        # lintel edges of the side faces
            b.edge((x0, yb, 0), (x1, yb, 0))
            b.edge((x0, y, zn), (x1, y, zn))
            b.edge((x0, yb, zn), (x1, yb, zn))
            inner = (cx, 0.5 * (y + yb), 0.5 * zn)     # inside the niche
            b.face(inner, (x0, yb, 0), (x1, yb, 0), (x1, yb, zn), (x0, yb, zn))    # door
            b.face(inner, (x0, y, 0), (x0, yb, 0), (x0, yb, zn), (x0, y, zn))      # sides
            b.face(inner, (x1, y, 0), (x1, yb, 0), (x1, yb, zn), (x1, y, zn))
            b.face(inner, (x0, y, zn), (x0, yb, zn), (x1, yb, zn), (x1, y, zn))    # lintel
            b.face(inner, (x0, y, 0), (x0, yb, 0), (x1, yb, 0), (x1, y, 0))        # floor
            b.face(centre, (x0, y, zn), (x1, y, zn), (x1, y, H), (x0, y, H))       # above
        xs.append(L)
        for x0, x1 in zip(xs[0::2], xs[1::2]):        # full-height wall pieces and floor lines
            b.edge((x0, y, 0), (x1, y, 0))
            b.face(centre, (x0, y, 0), (x1, y, 0), (x1, y, H), (x0, y, H))
    return b.model()
