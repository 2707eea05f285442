"""Camera pose on a planar robot, projection, and visible model lines (chapter §2.3, §5.1).

Camera (eqs. 12-16): pinhole ``u = alpha_x X_c / Z_c + x_0``, ``v = alpha_y Y_c / Z_c + y_0``
(eqs. 14-15; lens distortion is removed from image lines before matching) in the REP 103
optical frame (z forward, x right, y down). The camera sits on the robot at the mount
``(x, y, z)`` [m] in the robot frame, pitched down by ``pitch`` [rad]. With a zero mount
offset and pitch this is the chapter's eq. 16, ``C^-1`` of a camera at height ``h`` on the
robot pose ``p = (p_x, p_y, phi)``; the chapter's matrix measures phi from Blender's camera
axis (a quarter turn from the robot's heading), ours from the heading (REP 103)::

    X_c = sin(phi) dx - cos(phi) dy,  Y_c = h - Z,  Z_c = cos(phi) dx + sin(phi) dy

with ``dx = X - p_x``, ``dy = Y - p_y``.

Visible model lines (§5.1): the chapter takes each edge whose midpoint is inside the
frustum and casts a ray from the camera to that midpoint against every face; the edge is
visible when no face is hit before the midpoint (``dist2`` = ``dist1``). Two loops there,
one (E, F) array here. One change: each edge is first clipped to the frustum (near/far
planes and the four image borders; Liang-Barsky), and the midpoint of the clipped part is
tested, so a long wall line whose middle is behind the camera is still seen.
"""

from dataclasses import dataclass
import math
from typing import Tuple

import numpy as np

from .model import LineModel

#: Rotation of a body-frame vector (x forward, y left, z up) into the optical frame.
OPTICAL_FROM_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class CameraMount:
    """Camera pose on the robot.

    Attributes:
        x: forward offset of the optical centre from the robot origin [m].
        y: left offset [m].
        z: height of the optical centre above the floor [m] (the chapter's h).
        pitch: downward tilt of the optical axis [rad] (0: horizontal, as in the chapter).
    """

    x: float = 0.0
    y: float = 0.0
    z: float = 0.45
    pitch: float = 0.0


@dataclass(frozen=True)
class Intrinsics:
    """Ideal pinhole intrinsics (eq. 15, the chapter's S) and image size.

    Attributes:
        fx, fy: alpha_x, alpha_y [px].
        cx, cy: principal point x_0, y_0 [px].
        width, height: image size [px].
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        """Validate."""
        for name in ('fx', 'fy'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f'camera focal length {name} must be > 0; got {v!r}')
        if self.width < 1 or self.height < 1:
            raise ValueError(f'image size must be positive; got {self.width} x {self.height}')

    @classmethod
    def chapter(cls) -> 'Intrinsics':
        """Return the chapter's calibrated SONY EVI-D31 at 320 x 240 (§3.2)."""
        return cls(379.0, 379.0, 165.9, 140.0, 320, 240)

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def camera_pose(pose, mount: CameraMount) -> Tuple[np.ndarray, np.ndarray]:
    """Return (world-from-optical rotation (3, 3), camera centre (3,)) for a robot pose.

    Eqs. 12-13 with the robot's three degrees of freedom (eq. 16 for a zero offset / pitch).
    """
    px, py, phi = (float(v) for v in pose)
    cp, sp = math.cos(mount.pitch), math.sin(mount.pitch)
    pitch = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])   # R_y(pitch)
    rz = _rz(phi)
    R = rz @ pitch @ OPTICAL_FROM_BODY.T                                  # eq. 12
    c = np.array([px, py, 0.0]) + rz @ np.array([mount.x, mount.y, mount.z])
    return R, c


def world_to_camera(points: np.ndarray, pose, mount: CameraMount) -> np.ndarray:
    """Map (..., 3) world points to the optical frame, ``X_c = R^T (X - c)`` (eqs. 13, 16)."""
    R, c = camera_pose(pose, mount)
    return (np.asarray(points, dtype=float) - c) @ R


def project(points_c: np.ndarray, K: Intrinsics) -> np.ndarray:
    """Pixels (..., 2) of optical-frame points (..., 3) with ``Z_c > 0`` (eqs. 14-15)."""
    p = np.asarray(points_c, dtype=float)
    z = p[..., 2]
    return np.stack([K.fx * p[..., 0] / z + K.cx, K.fy * p[..., 1] / z + K.cy], axis=-1)


def projection_jacobian(points_w: np.ndarray, pose, mount: CameraMount,
                        K: Intrinsics) -> Tuple[np.ndarray, np.ndarray]:
    """Pixels of world points and their Jacobian w.r.t. the robot pose (eq. 62, J_P).

    Args:
        points_w: (N, 3) world points.
        pose: robot pose ``(p_x, p_y, phi)``.
        mount: camera mount.
        K: intrinsics.

    Returns:
        ``(pixels (N, 2), J (N, 2, 3))`` with ``J[n] = d(u, v) / d(p_x, p_y, phi)``.
    """
    P = np.asarray(points_w, dtype=float).reshape(-1, 3)
    R, c = camera_pose(pose, mount)
    phi = float(pose[2])
    Xc = (P - c) @ R
    x, y, z = Xc[:, 0], Xc[:, 1], Xc[:, 2]
    uv = np.column_stack([K.fx * x / z + K.cx, K.fy * y / z + K.cy])
    # d pixel / d X_c (eqs. 14-15)
    J_pix = np.zeros((P.shape[0], 2, 3))
    J_pix[:, 0, 0] = K.fx / z
    J_pix[:, 0, 2] = -K.fx * x / z ** 2
    J_pix[:, 1, 1] = K.fy / z
    J_pix[:, 1, 2] = -K.fy * y / z ** 2
    # d X_c / d pose: X_c = R^T (X - c), R = R_z(phi) A, c = (p_x, p_y, 0) + R_z(phi) m
    S = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    rz = _rz(phi)
    dR = rz @ S @ rz.T @ R                       # dR / dphi
    m = np.array([mount.x, mount.y, mount.z])
    dc = rz @ S @ m                              # dc / dphi
    J_c = np.zeros((P.shape[0], 3, 3))
    J_c[:, :, 0] = -R.T[:, 0]
    J_c[:, :, 1] = -R.T[:, 1]
    J_c[:, :, 2] = (P - c) @ dR - dc @ R
    return uv, J_pix @ J_c


def _frustum_planes(K: Intrinsics, near: float, far: float) -> Tuple[np.ndarray, np.ndarray]:
    """Inward half-spaces ``a . X + b >= 0`` (5 or 6, (k, 3) and (k,)) of the frustum."""
    xl = (-0.5 - K.cx) / K.fx
    xr = (K.width - 0.5 - K.cx) / K.fx
    yt = (-0.5 - K.cy) / K.fy
    yb = (K.height - 0.5 - K.cy) / K.fy
    a = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0],
                  [1.0, 0.0, -xl], [-1.0, 0.0, xr], [0.0, 1.0, -yt], [0.0, -1.0, yb]])
    b = np.array([-near, far, 0.0, 0.0, 0.0, 0.0])
    return a, b


def clip_to_frustum(p0: np.ndarray, p1: np.ndarray, K: Intrinsics, near: float,
                    far: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clip optical-frame segments (N, 3) to the view frustum (Liang-Barsky, vectorised).

    Returns:
        ``(ok (N,) bool, q0 (N, 3), q1 (N, 3))``: whether any part is inside, and the
        clipped end points (meaningless where not ok).
    """
    a, b = _frustum_planes(K, near, far)
    f0 = p0 @ a.T + b                      # (N, k) signed inside-ness at t = 0
    f1 = p1 @ a.T + b
    d = f1 - f0
    t0 = np.zeros(p0.shape[0])
    t1 = np.ones(p0.shape[0])
    with np.errstate(divide='ignore', invalid='ignore'):
        t = -f0 / d
    entering = d > 0
    leaving = d < 0
    t0 = np.maximum(t0, np.where(entering, t, -np.inf).max(axis=1))
    t1 = np.minimum(t1, np.where(leaving, t, np.inf).min(axis=1))
    parallel_out = ((d == 0) & (f0 < 0)).any(axis=1)
    ok = (t1 > t0) & ~parallel_out
    seg = p1 - p0
    return ok, p0 + t0[:, None] * seg, p0 + t1[:, None] * seg


@dataclass(frozen=True, eq=False)
class VisibleLines:
    """Model lines seen from a camera pose.

    Attributes:
        index: (M,) indices into ``model.edges``.
        points: (M, 2, 3) world end points of the visible (frustum-clipped) parts [m].
        pixels: (M, 4) their projections ``x1 y1 x2 y2`` [px].
    """

    index: np.ndarray
    points: np.ndarray
    pixels: np.ndarray

    def __len__(self) -> int:
        """Return the number of visible lines."""
        return int(self.index.shape[0])


def visible_lines(model: LineModel, pose, mount: CameraMount, K: Intrinsics,
                  near: float = 0.1, far: float = 30.0, tolerance: float = 0.01,
                  min_length_px: float = 0.0) -> VisibleLines:
    """Return the model lines visible from a robot pose (§5.1, Fig. 12).

    An edge is visible when the midpoint of its frustum-clipped part is not hidden by any
    face: the ray from the camera centre to the midpoint meets no face more than
    ``tolerance`` [m] before it (the chapter's ``dist2 < dist1``).

    Args:
        model: the line model (world frame).
        pose: robot pose ``(p_x, p_y, phi)``.
        mount: camera mount.
        K: intrinsics.
        near: nearest depth [m] (the chapter's nearer frustum plane).
        far: furthest depth [m] (its further plane).
        tolerance: distance [m] below which a face hit counts as the midpoint itself.
        min_length_px: projected parts shorter than this are dropped.
    """
    R, c = camera_pose(pose, mount)
    empty = VisibleLines(np.zeros(0, np.int64), np.zeros((0, 2, 3)), np.zeros((0, 4)))
    if model.edges.shape[0] == 0:
        return empty
    ends = (model.edge_points - c) @ R                         # (E, 2, 3) optical frame
    ok, q0, q1 = clip_to_frustum(ends[:, 0], ends[:, 1], K, near, far)  # IsInsideFrustrum
    idx = np.nonzero(ok)[0]
    q0, q1 = q0[idx], q1[idx]
    mid = 0.5 * (q0 + q1)                                      # the ray direction (cam_pos -> p)
    if model.faces.shape[0]:
        fv = (model.vertices[model.faces] - c) @ R             # (F, 4, 3) faces, optical frame
        n = np.cross(fv[:, 1] - fv[:, 0], fv[:, 2] - fv[:, 0])
        n2 = np.cross(fv[:, 2] - fv[:, 0], fv[:, 3] - fv[:, 0])
        n = np.where((np.linalg.norm(n2, axis=1) > np.linalg.norm(n, axis=1))[:, None], n2, n)
        n /= np.maximum(np.linalg.norm(n, axis=1), 1e-12)[:, None]
        d = np.einsum('fk,fk->f', n, fv[:, 0])
        denom = mid @ n.T                                      # (M, F)
        valid = np.abs(denom) > 1e-12                          # not parallel to the face
        t = np.where(valid, d[None, :] / np.where(valid, denom, 1.0), -1.0)  # P_T = t p
        dist1 = np.linalg.norm(mid, axis=1)
        before = valid & (t > 0) & ((1.0 - t) * dist1[:, None] > tolerance)
        hit = t[:, :, None] * mid[:, None, :]                  # (M, F, 3)
        e = np.roll(fv, -1, axis=1) - fv                       # (F, 4, 3) polygon edges
        # (e_k x (hit - v_k)) . n = (hit - v_k) . (n x e_k): > 0 inside of edge k
        ne = np.cross(np.broadcast_to(n[:, None], e.shape), e)  # (F, 4, 3)
        side = (np.einsum('mfc,fkc->mfk', hit, ne)
                - np.einsum('fkc,fkc->fk', fv, ne)[None])
        degenerate = np.linalg.norm(e, axis=2) < 1e-12         # triangles: repeated vertex
        inside = np.all((side >= -1e-9) | degenerate[None], axis=2)
        visible = ~np.any(before & inside, axis=1)
    else:
        visible = np.ones(idx.size, dtype=bool)
    idx, q0, q1 = idx[visible], q0[visible], q1[visible]
    if idx.size == 0:
        return empty
    pix = np.column_stack([project(q0, K), project(q1, K)])
    if min_length_px > 0:
        keep = np.hypot(pix[:, 2] - pix[:, 0], pix[:, 3] - pix[:, 1]) >= min_length_px
        idx, q0, q1, pix = idx[keep], q0[keep], q1[keep], pix[keep]
    pts = np.stack([q0 @ R.T + c, q1 @ R.T + c], axis=1)
    return VisibleLines(idx, pts, pix)
