"""Camera simulator: renders textured planar scenes into mono8 (or rgb8) camera images.

Pure numpy/OpenCV (no rclpy). The scene is a list of :class:`Plane` (a textured rectangle
with a pose in the world); a camera pose is the world pose of the REP 103 *optical* frame
(z forward, x right, y down). One :class:`CameraSimulator` per camera model caches the
distortion remap tables; :meth:`CameraSimulator.render` then draws one frame:

1. Ideal pinhole image, ``supersample`` times larger in each direction and, when the lens
   distorts, extended by a margin so the distorted image's corners have a source:
   each plane is clipped in 3D against the near plane ``z = near`` (so planes partly behind
   the camera render correctly), back faces are culled (unless ``two_sided``), and the plane
   is warped with one homography per depth band (texture -> image,
   ``cv2.warpPerspective``; a band spans a factor of 2 in depth) into the bounding box of
   its projection, reading from the mipmap level whose texels are closest to one canvas
   pixel (area filtering against aliasing), and blended in with the coverage of its
   projected outline. Planes are drawn far to near (painter's algorithm): B is drawn after
   A when B lies entirely on the camera's side of A's plane (a poster on a wall, a wall
   standing on the floor), otherwise by mean depth. Planes that interpenetrate inside the
   view are not resolved (no z-buffer); build scenes without. Leading low-detail planes
   (``Plane.detail=False``: plain walls, floors) are drawn without supersampling.
2. Area downsampling (``cv2.INTER_AREA``) to the camera resolution: each output pixel is the
   mean over its footprint. Above :data:`TILED_SUPERSAMPLE` only tiles around the planes
   drawn supersampled go through the large canvas (the same image: bit for bit inside the
   tiles, to float32 rounding elsewhere).
3. Lens distortion: ``cv2.remap`` with the camera's distorted -> ideal pixel map.
4. Photometry (:class:`Photometry`): illumination = exposure x linear gradient x radial
   vignetting on the reflectances; defocus (Gaussian) and linear motion blur; gamma
   encoding ``255 (E)^(1/gamma)``; Gaussian pixel noise (constant plus shot-noise part);
   rounding to 8 bits with clipping.

Textures are uint8 images (0 = black ink, 255 = white paper); a texel value ``t`` has the
reflectance ``black + (white - black) t / 255`` (:class:`RenderOptions`).

Plane frame: origin at the texture centre, x = the normal out of the textured face, y = the
texture's right (columns), z = the texture's up (minus rows) -- the landmark frame of the
visual navigation chapter §2.2.4, so a landmark plane's pose *is* the landmark pose.
Texel ``(c, r)`` (OpenCV pixel-centre coordinates) is at ``y = (c + 0.5) m - W m / 2``,
``z = H m / 2 - (r + 0.5) m`` for a ``W x H`` texture with ``m`` metres per texel.

Everything is deterministic: randomness comes only from the ``rng`` passed in.
"""

from dataclasses import dataclass, field
import math
from typing import List, Optional, Sequence, Tuple

import cv2
from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np


def _ro(a: np.ndarray, dtype=float) -> np.ndarray:
    out = np.array(a, dtype=dtype, copy=True, order='C')
    out.setflags(write=False)
    return out


def rotation_x(a: float) -> np.ndarray:
    """Return the active rotation by ``a`` [rad] about x (right-handed)."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(a: float) -> np.ndarray:
    """Return the active rotation by ``a`` [rad] about y (right-handed)."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(a: float) -> np.ndarray:
    """Return the active rotation by ``a`` [rad] about z (right-handed)."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class Plane:
    """A textured rectangle in the world.

    Attributes:
        texture: (H, W) uint8, row 0 = top of the printed face.
        metres_per_texel: texel size [m] (> 0); the plane is ``W m`` wide, ``H m`` high.
        rotation: (3, 3) world-from-plane rotation; columns = the plane's normal (x), right
            (y) and up (z) directions in the world.
        translation: (3,) world position of the texture centre [m].
        label: free text (e.g. ``'landmark'``, ``'wall'``, ``'checkerboard'``).
        two_sided: draw the texture also when seen from behind (mirrored); default False
            (back faces are culled, like a poster on a wall seen from behind the wall).
        detail: False for low-frequency textures (plain walls, floors): when such planes come
            first in the drawing order they are drawn without supersampling (4x faster for
            a supersampling of 2; the result differs by a slight blur).
    """

    texture: np.ndarray
    metres_per_texel: float
    rotation: np.ndarray
    translation: np.ndarray
    label: str = ''
    two_sided: bool = False
    detail: bool = True
    _mips: list = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        """Validate and freeze the arrays."""
        tex = np.asarray(self.texture)
        if tex.ndim != 2 or tex.dtype != np.uint8 or min(tex.shape) < 1:
            raise ValueError(f'plane texture must be a 2-D uint8 array; got {tex.dtype} '
                             f'{tex.shape}')
        m = float(self.metres_per_texel)
        if not math.isfinite(m) or m <= 0:
            raise ValueError(f'metres_per_texel must be > 0; got {self.metres_per_texel!r}')
        R = np.asarray(self.rotation, dtype=float)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) \
                or np.linalg.det(R) < 0:
            raise ValueError('plane rotation must be a 3x3 rotation matrix')
        t = np.asarray(self.translation, dtype=float).reshape(-1)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ValueError(f'plane translation must be 3 finite values; got {t.shape}')
        object.__setattr__(self, 'texture', _ro(tex, np.uint8))
        object.__setattr__(self, 'metres_per_texel', m)
        object.__setattr__(self, 'rotation', _ro(R))
        object.__setattr__(self, 'translation', _ro(t))

    @property
    def width(self) -> float:
        """Width [m] (along the plane's y axis)."""
        return self.texture.shape[1] * self.metres_per_texel

    @property
    def height(self) -> float:
        """Height [m] (along the plane's z axis)."""
        return self.texture.shape[0] * self.metres_per_texel

    def local_corners(self) -> np.ndarray:
        """Return the (4, 3) plane-frame corners: top-left, top-right, bottom-right, bottom-left.

        (As seen from the front.)
        """
        w, h = 0.5 * self.width, 0.5 * self.height
        return np.array([[0.0, -w, h], [0.0, w, h], [0.0, w, -h], [0.0, -w, -h]])

    def to_world(self, local: np.ndarray) -> np.ndarray:
        """Map (N, 3) plane-frame points to the world."""
        return np.asarray(local, dtype=float) @ self.rotation.T + self.translation

    def mipmaps(self) -> List[Tuple[np.ndarray, float, float]]:
        """Return the cached mipmap levels ``(image (h, w) uint8, sx, sy)``.

        ``sx, sy`` are the level-0 texels per level texel (area-averaged halvings, down to a
        few texels).
        """
        if self._mips is None:
            base = self.texture
            h0, w0 = base.shape
            levels = []
            img = base
            while True:
                h, w = img.shape
                levels.append((img, w0 / w, h0 / h))
                if min(h, w) < 8:
                    break
                img = cv2.resize(img, (max(1, w // 2), max(1, h // 2)),
                                 interpolation=cv2.INTER_AREA)
            object.__setattr__(self, '_mips', levels)
        return self._mips


def landmark_plane(code: int, design: LandmarkDesign, rotation: np.ndarray,
                   translation: np.ndarray, px_per_block: int = 64,
                   quiet_zone_blocks: int = 1) -> Plane:
    """Return the plane of a printed landmark whose landmark-frame pose is (rotation, translation).

    The texture is ``design.render(code, px_per_block, quiet_zone_blocks)`` (centred, so the
    plane frame is the landmark frame of §2.2.4).
    """
    tex = design.render(code, px_per_block, quiet_zone_blocks)
    return Plane(tex, design.block_size / px_per_block, rotation, translation, label='landmark')


@dataclass(frozen=True)
class RenderOptions:
    """Static rendering options of a :class:`CameraSimulator`.

    Attributes:
        supersample: integer supersampling factor per axis (1 = off; 2 default).
        near: near clipping distance [m] along the optical axis.
        background: reflectance where no plane is seen.
        black: reflectance of a texel value 0 (printed black).
        white: reflectance of a texel value 255 (white paper).
    """

    supersample: int = 2
    near: float = 0.02
    background: float = 0.3
    black: float = 0.04
    white: float = 0.85

    def __post_init__(self) -> None:
        """Validate the options."""
        if int(self.supersample) != self.supersample or self.supersample < 1:
            raise ValueError(f'supersample must be a positive integer; got {self.supersample!r}')
        if not self.near > 0:
            raise ValueError(f'near must be > 0; got {self.near!r}')
        for name in ('background', 'black', 'white'):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f'{name} reflectance must be in [0, 1]; got {v!r}')


@dataclass(frozen=True)
class Photometry:
    """Per-frame image formation effects (see the module docstring for the order).

    Attributes:
        exposure: illumination scale on the reflectances (1 = a white sheet reaches 0.85 of
            full scale before the gamma).
        gradient: ``(gx, gy)`` relative illumination change from the image centre to the
            right / bottom edge (e.g. 0.3 = +30 % at the right edge, -30 % at the left).
        vignetting: relative illumination loss at the image corners (0 = none).
        gamma: display gamma of the encoding (1 = linear).
        defocus_sigma: Gaussian blur std [px] (0 = sharp).
        motion_blur: length [px] of a linear motion blur (0 = none).
        motion_angle: direction of the motion blur [rad] in the image (0 = along u).
        noise_sigma: std of the additive Gaussian pixel noise [DN of 255].
        shot_noise: signal-dependent variance per DN (variance = noise_sigma^2 +
            shot_noise * value).
    """

    exposure: float = 1.0
    gradient: Tuple[float, float] = (0.0, 0.0)
    vignetting: float = 0.0
    gamma: float = 1.0
    defocus_sigma: float = 0.0
    motion_blur: float = 0.0
    motion_angle: float = 0.0
    noise_sigma: float = 0.0
    shot_noise: float = 0.0

    def __post_init__(self) -> None:
        """Validate the values."""
        for name in ('exposure', 'gamma'):
            if not getattr(self, name) > 0:
                raise ValueError(f'{name} must be > 0; got {getattr(self, name)!r}')
        for name in ('vignetting', 'defocus_sigma', 'motion_blur', 'noise_sigma', 'shot_noise'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f'{name} must be finite and >= 0; got {v!r}')


# ---------------------------------------------------------------------- polygon helpers
def _clip_edges(pts: list, axis: int, bound: float, keep_ge: bool) -> list:
    """Clip a polygon (a list of coordinate lists) to one side of ``x[axis] = bound``.

    Sutherland-Hodgman on Python floats (the same IEEE double operations as on numpy rows,
    without numpy's per-call cost on 2- and 3-vectors).
    """
    out = []
    n = len(pts)
    for i in range(n):
        a, b = pts[i], pts[(i + 1) % n]
        ina = a[axis] >= bound if keep_ge else a[axis] <= bound
        inb = b[axis] >= bound if keep_ge else b[axis] <= bound
        if ina:
            out.append(a)
        if ina != inb:
            t = (bound - a[axis]) / (b[axis] - a[axis])
            out.append([ak + t * (bk - ak) for ak, bk in zip(a, b)])
    return out


def _as_points(poly: np.ndarray) -> list:
    """Return the rows of a float64 polygon as lists of Python floats."""
    return np.asarray(poly, dtype=np.float64).tolist()


def clip_polygon_near(poly: np.ndarray, near: float, keep_far: bool = True) -> np.ndarray:
    """Clip a 3-D polygon (N, 3) in camera coordinates to ``z >= near`` (Sutherland-Hodgman).

    With ``keep_far=False`` keep ``z <= near`` instead.
    """
    return np.array(_clip_edges(_as_points(poly), 2, float(near), keep_far)).reshape(-1, 3)


def _clip_polygon_rect(poly: np.ndarray, x0: float, y0: float, x1: float,
                       y1: float) -> np.ndarray:
    """Clip a 2-D polygon (N, 2) to an axis-aligned rectangle."""
    pts = _as_points(poly)
    for axis, bound, keep_ge in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        if not pts:
            break
        pts = _clip_edges(pts, axis, float(bound), keep_ge)
    return np.array(pts).reshape(-1, 2)


def _area(poly2: np.ndarray) -> float:
    """Return the area of a 2-D polygon (shoelace formula)."""
    x, y = poly2[:, 0], poly2[:, 1]
    # y and x rolled by one (np.roll's values, without its per-call cost)
    y1, x1 = np.concatenate((y[1:], y[:1])), np.concatenate((x[1:], x[:1]))
    return 0.5 * abs(float(np.dot(x, y1) - np.dot(y, x1)))


# ---------------------------------------------------------------------- simulator
#: Above this supersampling the planes drawn supersampled are rendered in tiles around them,
#: the rest of the image at the camera resolution (:meth:`CameraSimulator._render_tiles`):
#: the supersampled canvas grows with its square (about 90 M pixels at 16 x 16 for
#: 640 x 480) and its round trip, not the planes, took most of a frame's time.
TILED_SUPERSAMPLE = 4


class CameraSimulator:
    """Render planar scenes for one camera model (caches the distortion maps).

    Args:
        camera: the camera model (resolution, K, D).
        options: static rendering options.
    """

    def __init__(self, camera: CameraModel, options: RenderOptions = RenderOptions()) -> None:
        """Prepare the canvas geometry and the distortion remap tables."""
        self.camera = camera
        self.options = options
        W, H = camera.width, camera.height
        if camera.has_distortion:
            mx, my = camera.ideal_to_distorted_map()
            ok = np.isfinite(mx) & np.isfinite(my)
            mx_lo = max(0.0, -float(mx[ok].min()))
            mx_hi = max(0.0, float(mx[ok].max()) - (W - 1))
            my_lo = max(0.0, -float(my[ok].min()))
            my_hi = max(0.0, float(my[ok].max()) - (H - 1))
            self.margin = (min(W, int(math.ceil(max(mx_lo, mx_hi))) + 2),
                           min(H, int(math.ceil(max(my_lo, my_hi))) + 2))
            self._map = (np.where(ok, mx + self.margin[0], -1e4).astype(np.float32),
                         np.where(ok, my + self.margin[1], -1e4).astype(np.float32))
        else:
            self.margin = (0, 0)
            self._map = None
        ex, ey = self.margin
        K = camera.K.copy()
        K[0, 2] += ex
        K[1, 2] += ey
        self.ideal_camera = CameraModel(W + 2 * ex, H + 2 * ey, K, np.zeros(5))
        s = int(options.supersample)
        self.canvas_camera = self.ideal_camera.scaled_size(s)
        v, u = np.mgrid[0:H, 0:W].astype(np.float32)
        self._un = (u - np.float32(camera.cx)) / np.float32(W)
        self._vn = (v - np.float32(camera.cy)) / np.float32(H)
        r2 = self._un ** 2 + self._vn ** 2
        self._r2 = r2 / np.float32(r2.max())

    # ------------------------------------------------------------------ geometry
    @staticmethod
    def _pose(rotation: np.ndarray, position: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        R = np.asarray(rotation, dtype=float)
        t = np.asarray(position, dtype=float).reshape(3)
        if R.shape != (3, 3):
            raise ValueError(f'camera rotation must be 3x3; got {R.shape}')
        return R, t

    def _draw_plane(self, canvas: np.ndarray, cam: CameraModel, plane: Plane,
                    R_cp: np.ndarray, t_cp: np.ndarray, clipped: np.ndarray,
                    origin: Tuple[int, int] = (0, 0)) -> None:
        """Draw a plane in depth bands (a factor of 2 in depth each, 2 % overlap), far first.

        Each band gets its own mipmap level, so a floor running from the robot's feet to the
        far wall is neither blurred nearby nor aliased far away. ``canvas`` may be a tile of
        the image of ``cam``: its pixel (0, 0) is the image's pixel ``origin`` (x, y), and the
        plane's :meth:`_box` lies inside it.
        """
        z = clipped[:, 2]
        z0, z1 = float(z.min()), float(z.max())
        if z1 <= 2.5 * z0:
            self._draw_polygon(canvas, cam, plane, R_cp, t_cp, clipped, origin)
            return
        edges = [z0 * 2.0 ** k for k in range(int(math.ceil(math.log2(z1 / z0))))] + [z1]
        for za, zb in reversed(list(zip(edges[:-1], edges[1:]))):
            band = clip_polygon_near(clipped, za * 0.98)
            band = clip_polygon_near(band, zb * 1.02, keep_far=False) if len(band) else band
            if len(band) >= 3:
                self._draw_polygon(canvas, cam, plane, R_cp, t_cp, band, origin)

    @staticmethod
    def _box(cam: CameraModel, poly2: np.ndarray) -> Tuple[int, int, int, int]:
        """Return the pixels ``(x0, y0, x1, y1)`` (ends excluded) a polygon is drawn into."""
        lo = np.floor(poly2.min(axis=0)) - 1
        hi = np.ceil(poly2.max(axis=0)) + 2
        return (int(max(0, lo[0])), int(max(0, lo[1])), int(min(cam.width, hi[0])),
                int(min(cam.height, hi[1])))

    def _draw_polygon(self, canvas: np.ndarray, cam: CameraModel, plane: Plane,
                      R_cp: np.ndarray, t_cp: np.ndarray, clipped: np.ndarray,
                      origin: Tuple[int, int] = (0, 0)) -> None:
        Hc, Wc = cam.height, cam.width
        poly2 = cam.project(clipped, distort=False)
        x0, y0, x1, y1 = self._box(cam, poly2)
        if x1 <= x0 or y1 <= y0:
            return
        poly_roi = _clip_polygon_rect(poly2, x0 - 1.0, y0 - 1.0, x1 + 1.0, y1 + 1.0)
        if len(poly_roi) < 3:
            return
        # pixels per texel of the visible part -> mipmap level (area filtering)
        m = plane.metres_per_texel
        visible = _clip_polygon_rect(poly2, -0.5, -0.5, Wc - 0.5, Hc - 0.5)
        if len(visible) < 3:
            return
        n = R_cp[:, 0]
        rays = np.column_stack([visible, np.ones(len(visible))]) @ np.linalg.inv(cam.K).T
        denom = rays @ n
        if np.any(np.abs(denom) < 1e-15):
            return
        pts = rays * (float(n @ t_cp) / denom)[:, None]
        local = (pts - t_cp) @ R_cp  # plane-frame coordinates of the visible outline
        area_tex = _area(local[:, 1:]) / (m * m)
        area_px = _area(visible)
        if area_px <= 0 or area_tex <= 0:
            return
        rho = math.sqrt(area_px / area_tex)
        mips = plane.mipmaps()
        level = 0 if rho >= 1.0 else min(len(mips) - 1,
                                         int(math.floor(math.log2(1.0 / rho) + 0.5)))
        img, sx, sy = mips[level]
        h0, w0 = plane.texture.shape
        # texture (level texel) -> plane (y, z) -> camera -> canvas pixel, shifted to the ROI
        A = np.array([[sx * m, 0.0, 0.5 * sx * m - 0.5 * w0 * m],
                      [0.0, -sy * m, 0.5 * h0 * m - 0.5 * sy * m],
                      [0.0, 0.0, 1.0]])
        M = np.column_stack([R_cp[:, 1], R_cp[:, 2], t_cp])
        T = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]])
        Hm = T @ cam.K @ M @ A
        size = (x1 - x0, y1 - y0)
        warped = cv2.warpPerspective(img, Hm, size, flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_REPLICATE)
        # coverage of the (near-clipped) outline: pixel centres inside the polygon, at the
        # supersampled resolution (area-averaged to anti-aliased edges by the downsampling)
        mask = np.zeros((size[1], size[0]), dtype=np.uint8)
        pts = np.round((poly_roi - [x0, y0]) * 256.0).astype(np.int32)
        cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=8)
        # float32(texel) * gain + black through a 256-entry table computed with the same
        # float32 operations (one pass instead of three)
        tex = cv2.LUT(warped, self._reflectance_table())
        roi = canvas[y0 - origin[1]:y1 - origin[1], x0 - origin[0]:x1 - origin[0]]
        if mask.min() == 1:
            roi[...] = tex
        else:
            # the coverage is 0 or 1 (no anti-aliasing at this resolution): the blend
            # roi + coverage (tex - roi) is (tex - roi) + roi where covered (the same float32
            # sum) and roi elsewhere
            tex -= roi
            tex += roi
            np.copyto(roi, tex, where=mask.view(np.bool_))

    def _reflectance_table(self) -> np.ndarray:
        """Return the reflectance of each 8-bit texel value (black .. white), float32."""
        opt = self.options
        key = (opt.black, opt.white)
        if getattr(self, '_table_key', None) != key:
            table = np.arange(256, dtype=np.uint8).astype(np.float32)
            table *= np.float32((opt.white - opt.black) / 255.0)
            table += np.float32(opt.black)
            self._table, self._table_key = table, key
        return self._table

    def _order(self, items: list) -> list:
        """Painter's order: far to near, refined by which side of each other planes lie on.

        Plane B is drawn after plane A if all of B's (clipped) corners lie on the camera's
        side of A's plane (within 0.1 mm) and not vice versa; remaining ties by mean depth.
        """
        n = len(items)
        depth = [-float(it[3][:, 2].mean()) for it in items]
        after = [set() for _ in range(n)]  # after[i] = planes that must be drawn after i

        sides = []  # per plane a: its normal, a point on it, the camera's side of it
        for _, R_a, t_a, _ in items:
            nrm = R_a[:, 0]
            cam_side = -float(nrm @ t_a)  # signed distance of the camera from plane a
            sides.append((nrm, t_a, math.copysign(1.0, cam_side)))

        def in_front(b: int, a: int) -> bool:
            nrm, t_a, sign = sides[a]
            dist = (items[b][3] - t_a) @ nrm
            return bool(np.all(dist * sign >= -1e-4))

        front = [[b != a and in_front(b, a) for a in range(n)] for b in range(n)]
        for i in range(n):
            for j in range(n):
                if front[j][i] and not front[i][j]:
                    after[i].add(j)
        indeg = [0] * n
        for i in range(n):
            for j in after[i]:
                indeg[j] += 1
        remaining = set(range(n))
        order = []
        while remaining:
            ready = [i for i in remaining if indeg[i] == 0]
            if not ready:  # a cycle: fall back to depth for the rest
                ready = list(remaining)
            i = min(ready, key=lambda k: (depth[k], k))
            order.append(i)
            remaining.discard(i)
            for j in after[i]:
                indeg[j] -= 1
        return [items[i] for i in order]

    def render_ideal(self, planes: Sequence[Plane], rotation: np.ndarray,
                     position: np.ndarray) -> np.ndarray:
        """Return the ideal (undistorted, margin-extended) reflectance image, float32.

        The image belongs to :attr:`ideal_camera` (the camera's K with the principal point
        shifted by :attr:`margin`, no distortion).
        """
        R_wc, t_wc = self._pose(rotation, position)
        opt = self.options
        items = []
        for plane in planes:
            R_cp = R_wc.T @ plane.rotation
            t_cp = R_wc.T @ (plane.translation - t_wc)
            if not plane.two_sided and float(R_cp[:, 0] @ t_cp) >= 0.0:
                continue  # back face: the camera is behind the printed side
            corners = plane.local_corners() @ R_cp.T + t_cp
            clipped = clip_polygon_near(corners, opt.near)
            if len(clipped) < 3:
                continue
            items.append((plane, R_cp, t_cp, clipped))
        ordered = self._order(items)
        s = int(opt.supersample)
        low_cam, cam = self.ideal_camera, self.canvas_camera
        k = 0
        if s > 1:  # leading low-detail planes (walls, floor) without supersampling
            canvas = np.full((low_cam.height, low_cam.width), opt.background, dtype=np.float32)
            while k < len(ordered) and not ordered[k][0].detail:
                self._draw_plane(canvas, low_cam, *ordered[k])
                k += 1
            if k == len(ordered):
                return canvas
            if s > TILED_SUPERSAMPLE:
                tiles = self._detail_tiles(ordered[k:], canvas.shape)
                if tiles is not None:
                    return self._render_tiles(canvas, ordered[k:], tiles)
            # into a buffer kept between frames: a new one (hundreds of MB at 16 x 16) was
            # paged in afresh for every frame
            if getattr(self, '_canvas', None) is None or self._canvas.shape != (cam.height,
                                                                                cam.width):
                self._canvas = np.empty((cam.height, cam.width), dtype=np.float32)
            canvas = cv2.resize(canvas, (cam.width, cam.height), dst=self._canvas,
                                interpolation=cv2.INTER_LINEAR)
        else:
            canvas = np.full((cam.height, cam.width), opt.background, dtype=np.float32)
        for item in ordered[k:]:
            self._draw_plane(canvas, cam, *item)
        if s > 1:
            canvas = cv2.resize(canvas, (low_cam.width, low_cam.height),
                                interpolation=cv2.INTER_AREA)
        return canvas

    def _detail_tiles(self, items: list, shape: Tuple[int, int]
                      ) -> Optional[List[Tuple[int, int, int, int, list]]]:
        """Group the supersampled planes into disjoint tiles of the ideal image.

        A tile ``(x0, y0, x1, y1, items)`` (ideal pixels, ends excluded) holds every pixel a
        plane of ``items`` is drawn into, plus a pixel of margin; overlapping tiles are
        merged, so a plane lies in one tile, with the planes it may cover or be covered by.
        None when the tiles cover more than half the image (no gain then).
        """
        s = int(self.options.supersample)
        cam = self.canvas_camera
        tiles = []
        for item in items:
            x0, y0, x1, y1 = self._box(cam, cam.project(item[3], distort=False))
            if x1 <= x0 or y1 <= y0:
                continue  # outside the image: not drawn
            tiles.append([max(0, x0 // s - 1), max(0, y0 // s - 1),
                          min(shape[1], -(-x1 // s) + 1), min(shape[0], -(-y1 // s) + 1), [item]])
        merged = True
        while merged:
            merged = False
            for i in range(len(tiles)):
                for j in range(i + 1, len(tiles)):
                    a, b = tiles[i], tiles[j]
                    if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]:
                        tiles[i] = [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]),
                                    max(a[3], b[3]), a[4] + b[4]]
                        del tiles[j]
                        merged = True
                        break
                if merged:
                    break
        if sum((t[2] - t[0]) * (t[3] - t[1]) for t in tiles) > 0.5 * shape[0] * shape[1]:
            return None
        order = {id(item): n for n, item in enumerate(items)}
        return [(x0, y0, x1, y1, sorted(its, key=lambda it: order[id(it)]))
                for x0, y0, x1, y1, its in tiles]

    def _render_tiles(self, low: np.ndarray, items: list,
                      tiles: List[Tuple[int, int, int, int, list]]) -> np.ndarray:
        """Finish the image with only the tiles of the supersampled planes supersampled.

        Each tile is what the whole supersampled canvas gives there: the low-detail image
        ``low`` upsampled (``cv2.INTER_LINEAR``, from the tile and one pixel around it, which
        is all the interpolation reads), the planes drawn in, area-downsampled. Elsewhere the
        round trip up and down is, per axis, the 3-tap filter ``(a, 1 - 2a, a)`` with ``a``
        the mean interpolation weight on a neighbour over a pixel's ``s`` samples (1/8 for an
        even ``s``), applied directly (the same to float32 rounding).
        """
        s = int(self.options.supersample)
        offsets = (np.arange(s) + 0.5) / s - 0.5
        a = float(np.mean(np.maximum(-offsets, 0.0)))
        taps = np.array([a, 1.0 - 2.0 * a, a], dtype=np.float32)
        out = cv2.sepFilter2D(low, cv2.CV_32F, taps, taps, borderType=cv2.BORDER_REPLICATE)
        H, W = low.shape
        for x0, y0, x1, y1, its in tiles:
            # the low-detail pixels around the tile, upsampled; the tile is the inner part
            ex0, ey0, ex1, ey1 = max(0, x0 - 1), max(0, y0 - 1), min(W, x1 + 1), min(H, y1 + 1)
            up = cv2.resize(low[ey0:ey1, ex0:ex1], ((ex1 - ex0) * s, (ey1 - ey0) * s),
                            interpolation=cv2.INTER_LINEAR)
            tile = up[(y0 - ey0) * s:(y1 - ey0) * s, (x0 - ex0) * s:(x1 - ex0) * s]
            for item in its:
                self._draw_plane(tile, self.canvas_camera, *item, origin=(x0 * s, y0 * s))
            out[y0:y1, x0:x1] = cv2.resize(tile, (x1 - x0, y1 - y0),
                                           interpolation=cv2.INTER_AREA)
        return out

    def render_reflectance(self, planes: Sequence[Plane], rotation: np.ndarray,
                           position: np.ndarray) -> np.ndarray:
        """Return the (H, W) float32 reflectance image as seen through the lens (distorted)."""
        ideal = self.render_ideal(planes, rotation, position)
        if self._map is None:
            return ideal
        return cv2.remap(ideal, self._map[0], self._map[1], interpolation=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE)

    def render(self, planes: Sequence[Plane], rotation: np.ndarray, position: np.ndarray,
               photometry: Photometry = Photometry(), rng: Optional[np.random.Generator] = None,
               encoding: str = 'mono8') -> np.ndarray:
        """Render one camera image.

        Args:
            planes: the scene.
            rotation: (3, 3) world-from-optical rotation of the camera.
            position: (3,) camera centre in the world [m].
            photometry: illumination, blur, gamma and noise of this frame.
            rng: generator for the pixel noise (required if the noise is not zero).
            encoding: ``'mono8'`` -> (H, W) uint8; ``'rgb8'`` -> (H, W, 3) uint8 (grey).

        Returns:
            The 8-bit image.
        """
        if encoding not in ('mono8', 'rgb8'):
            raise ValueError(f"encoding must be 'mono8' or 'rgb8'; got {encoding!r}")
        ph = photometry
        img = self.render_reflectance(planes, rotation, position)
        light = np.float32(ph.exposure)
        gx, gy = ph.gradient
        if gx or gy or ph.vignetting:
            field_ = np.float32(1.0) + np.float32(2.0 * gx) * self._un \
                + np.float32(2.0 * gy) * self._vn
            if ph.vignetting:
                field_ *= np.float32(1.0) - np.float32(ph.vignetting) * self._r2
            img = img * (light * np.maximum(field_, np.float32(0.0)))
        elif ph.exposure != 1.0:
            img = img * light
        if ph.defocus_sigma > 0:
            img = cv2.GaussianBlur(img, (0, 0), ph.defocus_sigma, borderType=cv2.BORDER_REPLICATE)
        if ph.motion_blur > 0:
            img = cv2.filter2D(img, -1, motion_kernel(ph.motion_blur, ph.motion_angle),
                               borderType=cv2.BORDER_REPLICATE)
        np.clip(img, 0.0, 1.0, out=img)
        if ph.gamma != 1.0:
            img = np.power(img, np.float32(1.0 / ph.gamma))
        img = img * np.float32(255.0)
        if ph.noise_sigma > 0 or ph.shot_noise > 0:
            if rng is None:
                raise ValueError('rendering with pixel noise needs an rng')
            z = _standard_normal(rng, img.shape)
            if ph.shot_noise > 0:
                std = np.sqrt(np.float32(ph.noise_sigma ** 2) + np.float32(ph.shot_noise) * img)
                img += std * z
            else:
                img += np.float32(ph.noise_sigma) * z
        out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        if encoding == 'rgb8':
            out = np.repeat(out[:, :, None], 3, axis=2)
        return out


def _standard_normal(rng: np.random.Generator, shape: Tuple[int, int]) -> np.ndarray:
    """Return float32 standard normal noise, seeded from ``rng`` (deterministic).

    Uses OpenCV's per-thread generator (``cv2.randn``, about 5x faster than numpy's float32
    normals here), seeded with a number drawn from ``rng``.
    """
    out = np.empty(shape, dtype=np.float32)
    cv2.setRNGSeed(int(rng.integers(1, 2 ** 31 - 1)))
    cv2.randn(out, 0.0, 1.0)
    return out


def motion_kernel(length: float, angle: float) -> np.ndarray:
    """Return a normalized linear motion-blur kernel of ``length`` px along ``angle`` [rad]."""
    n = int(math.ceil(length)) | 1
    k = np.zeros((n, n), dtype=np.float32)
    c = 0.5 * (n - 1)
    d = np.array([math.cos(angle), math.sin(angle)])
    samples = max(4 * n, 8)
    for t in np.linspace(-0.5 * length, 0.5 * length, samples):
        x, y = c + t * d
        ix, iy = int(math.floor(x)), int(math.floor(y))
        fx, fy = x - ix, y - iy
        for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)),
                          (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
            if 0 <= ix + dx < n and 0 <= iy + dy < n:
                k[iy + dy, ix + dx] += w
    return k / k.sum()


__all__ = ['CameraSimulator', 'clip_polygon_near', 'landmark_plane', 'motion_kernel',
           'Photometry', 'Plane', 'RenderOptions', 'rotation_x', 'rotation_y', 'rotation_z']
