"""Pinhole camera with plumb_bob (Brown-Conrady) lens distortion, as in sensor_msgs/CameraInfo.

Frames and pixels
-----------------
Points are given in the REP 103 *camera optical frame*: z forward along the optical axis,
x right, y down in the image. Pixel coordinates follow OpenCV / ROS CameraInfo: ``u`` =
column to the right, ``v`` = row down, the centre of the top-left pixel is ``(0, 0)`` (its
outer corner is at ``(-0.5, -0.5)``).

:data:`OPTICAL_FROM_BODY` rotates a vector from a REP 103 body frame (x forward, y left,
z up; e.g. ``camera_link`` or the chapters' robot frames) into the optical frame
(``x_o = -y_b``, ``y_o = -z_b``, ``z_o = x_b``).

Model (``project``)
-------------------
With ``(X, Y, Z)`` in the optical frame, ``x = X / Z``, ``y = Y / Z``, ``r2 = x^2 + y^2``::

    radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
    x' = x radial + 2 p1 x y + p2 (r2 + 2 x^2) + s1 r2 + s2 r2^2
    y' = y radial + p1 (r2 + 2 y^2) + 2 p2 x y + s3 r2 + s4 r2^2
    u  = fx x' + skew y' + cx,   v = fy y' + cy

with ``D = (k1, k2, p1, p2, k3[, k4, k5, k6[, s1, s2, s3, s4]])`` (OpenCV order; ``plumb_bob``
is the first five, ``rational_polynomial`` the first eight; missing terms are zero).

Relation to the self-localization chapter (§2.3, eqs. 12-16): its eqs. 14-15 are this model
without distortion, ``u = alpha_x X_c / Z_c + x_0``, ``v = alpha_y Y_c / Z_c + y_0`` with
``K = [[alpha_x, 0, x_0], [0, alpha_y, y_0], [0, 0, 1]]`` (the chapter's intrinsic matrix
``S``), and its camera coordinate system has the optical axis along z with x and y aligned
with the image axes, i.e. it is the optical frame used here. Its eq. 16 is the extrinsic
world -> optical transform ``C^-1`` of a camera at height ``h`` on a planar robot; in this
package the same transform is ``OPTICAL_FROM_BODY`` composed with the robot pose and the
camera mount. The visual navigation chapter's eq. 11 uses robot-style camera axes (a_x
forward = depth, a_y left = minus columns, a_z up = minus rows), i.e. again
``OPTICAL_FROM_BODY``.

``R`` and ``P`` (rectification and projection of a stereo pair) are kept for round trips of
CameraInfo and used only by ``undistort_pixels(..., output='rectified')``.
"""

from dataclasses import dataclass
import math
from typing import Optional

import cv2
import numpy as np

#: Rotation taking vectors of a REP 103 body frame (x fwd, y left, z up) to the optical frame.
OPTICAL_FROM_BODY = np.array([[0.0, -1.0, 0.0],
                              [0.0, 0.0, -1.0],
                              [1.0, 0.0, 0.0]])
OPTICAL_FROM_BODY.setflags(write=False)

#: Distortion models and the numbers of coefficients they accept.
DISTORTION_MODELS = {'plumb_bob': (0, 4, 5), 'rational_polynomial': (0, 8, 12, 14)}


def _undistort_normalized_cv(xy: np.ndarray, D: np.ndarray, iterations: int,
                             eps: float) -> np.ndarray:
    """Invert the distortion of normalized points with OpenCV's iterative undistortPoints.

    The one place that knows the OpenCV version difference: OpenCV 4 has
    ``undistortPointsIter`` for custom stop criteria, OpenCV 5 takes them in
    ``undistortPoints``.
    """
    src = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, eps)
    eye = np.eye(3)
    if hasattr(cv2, 'undistortPointsIter'):
        out = cv2.undistortPointsIter(src, eye, D, None, None, crit)
    else:
        out = cv2.undistortPoints(src, eye, D, R=None, P=None, criteria=crit)
    return out.reshape(-1, 2).astype(float)


def _ro(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=float, copy=True, order='C')
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A calibrated monocular camera (arrays are read-only float64).

    Attributes:
        width: image width [px], > 0.
        height: image height [px], > 0.
        K: (3, 3) intrinsic matrix ``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]``, fx, fy > 0.
        D: (n,) distortion coefficients in OpenCV order (see the module docstring);
            n in (0, 4, 5) for plumb_bob, (0, 8, 12, 14) for rational_polynomial.
        distortion_model: ``'plumb_bob'`` or ``'rational_polynomial'``.
        R: (3, 3) rectification rotation (identity for a monocular camera).
        P: (3, 4) projection matrix of the rectified image (``[K | 0]`` by default).
    """

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    distortion_model: str = 'plumb_bob'
    R: Optional[np.ndarray] = None
    P: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        """Validate and freeze the arrays; fill in the default R and P."""
        for name in ('width', 'height'):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
                raise ValueError(f'camera {name} must be a positive integer; got {v!r}')
            object.__setattr__(self, name, int(v))
        K = np.asarray(self.K, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise ValueError(f'camera K must be a finite 3x3 matrix; got shape {K.shape}')
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f'camera focal lengths must be > 0; got fx={K[0, 0]}, fy={K[1, 1]}')
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise ValueError(f'camera K must have last row (0, 0, 1) and K[1, 0] = 0; got {K}')
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(f'unknown distortion model {self.distortion_model!r}; '
                             f'supported: {sorted(DISTORTION_MODELS)}')
        D = np.asarray(self.D, dtype=float).reshape(-1)
        sizes = DISTORTION_MODELS[self.distortion_model]
        if D.size not in sizes or not np.all(np.isfinite(D)):
            raise ValueError(f'{self.distortion_model} needs {" or ".join(map(str, sizes))} '
                             f'finite distortion coefficients; got {D.size}')
        R = np.eye(3) if self.R is None else np.asarray(self.R, dtype=float)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise ValueError(f'camera R must be a finite 3x3 matrix; got shape {R.shape}')
        if self.P is None:
            P = np.hstack([K, np.zeros((3, 1))])
        else:
            P = np.asarray(self.P, dtype=float)
        if P.shape != (3, 4) or not np.all(np.isfinite(P)):
            raise ValueError(f'camera P must be a finite 3x4 matrix; got shape {P.shape}')
        object.__setattr__(self, 'K', _ro(K))
        object.__setattr__(self, 'D', _ro(D))
        object.__setattr__(self, 'R', _ro(R))
        object.__setattr__(self, 'P', _ro(P))

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_fov(cls, width: int, height: int, hfov: float,
                 D: Optional[np.ndarray] = None) -> 'CameraModel':
        """Return a square-pixel camera with the principal point at the image centre.

        Args:
            width: image width [px].
            height: image height [px].
            hfov: horizontal field of view [rad] of the undistorted pinhole, in (0, pi).
            D: optional plumb_bob coefficients ``(k1, k2, p1, p2, k3)`` (default none).

        ``fx = fy = (width / 2) / tan(hfov / 2)``, ``cx = (width - 1) / 2``,
        ``cy = (height - 1) / 2`` (pixel-centre convention).
        """
        if not (isinstance(hfov, (int, float)) and math.isfinite(hfov) and 0 < hfov < math.pi):
            raise ValueError(f'hfov must be in (0, pi) rad; got {hfov!r}')
        if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width <= 0:
            raise ValueError(f'camera width must be a positive integer; got {width!r}')
        f = 0.5 * width / math.tan(0.5 * hfov)
        K = np.array([[f, 0.0, 0.5 * (width - 1)], [0.0, f, 0.5 * (height - 1)],
                      [0.0, 0.0, 1.0]])
        return cls(width=width, height=height, K=K, D=np.zeros(5) if D is None else D)

    def scaled_size(self, factor: int) -> 'CameraModel':
        """Return the same camera for an image ``factor`` times larger in each direction.

        Used for supersampled rendering: pixel ``(u, v)`` here corresponds to
        ``((u + 0.5) factor - 0.5, (v + 0.5) factor - 0.5)`` in the large image. Distortion is
        dropped (it is applied after downsampling).
        """
        f = int(factor)
        if f < 1:
            raise ValueError(f'scale factor must be a positive integer; got {factor!r}')
        K = self.K.copy()
        K[0, :] *= f
        K[1, :] *= f
        K[0, 2] = (self.K[0, 2] + 0.5) * f - 0.5
        K[1, 2] = (self.K[1, 2] + 0.5) * f - 0.5
        return CameraModel(self.width * f, self.height * f, K, np.zeros(5))

    # ------------------------------------------------------------------ properties
    @property
    def fx(self) -> float:
        """Focal length in pixels along u."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Focal length in pixels along v."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """Principal point u [px]."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """Principal point v [px]."""
        return float(self.K[1, 2])

    @property
    def has_distortion(self) -> bool:
        """True if any distortion coefficient is nonzero."""
        return bool(np.any(self.D != 0))

    @property
    def hfov(self) -> float:
        """Horizontal field of view of the undistorted pinhole [rad]."""
        return 2.0 * math.atan(0.5 * self.width / self.fx)

    def _d14(self) -> np.ndarray:
        d = np.zeros(14)
        d[:self.D.size] = self.D
        return d

    # ------------------------------------------------------------------ projection
    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Apply the lens distortion to normalized image coordinates.

        Args:
            xy: (N, 2) ideal normalized coordinates ``(X / Z, Y / Z)``.

        Returns:
            (N, 2) distorted normalized coordinates ``(x', y')`` (module docstring).
        """
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = self._d14()[:12]
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y + r2 * (s3 + s4 * r2)
        return np.column_stack([xd, yd])

    def normalized_to_pixels(self, xy: np.ndarray, distort: bool = True) -> np.ndarray:
        """Map (N, 2) ideal normalized coordinates to (N, 2) pixels (distorted by default)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if distort and self.has_distortion:
            xy = self.distort_normalized(xy)
        K = self.K
        return np.column_stack([K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2],
                                K[1, 1] * xy[:, 1] + K[1, 2]])

    def project(self, points_cam: np.ndarray, distort: bool = True) -> np.ndarray:
        """Project points of the optical frame to pixels.

        Args:
            points_cam: (N, 3) points ``(X, Y, Z)`` [m] in the camera optical frame.
            distort: apply the lens distortion (default); False gives ideal pinhole pixels.

        Returns:
            (N, 2) pixels ``(u, v)``; rows with ``Z <= 0`` (at or behind the camera) or
            non-finite input are NaN. Points far outside the field of view are still
            projected (the polynomial distortion is meaningless there; check
            :meth:`in_image`).
        """
        p = np.asarray(points_cam, dtype=float).reshape(-1, 3)
        z = p[:, 2]
        ok = np.isfinite(p).all(axis=1) & (z > 0)
        zs = np.where(ok, z, 1.0)
        xy = p[:, :2] / zs[:, None]
        out = self.normalized_to_pixels(xy, distort=distort)
        out[~ok] = np.nan
        return out

    def in_image(self, px: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Return an (N,) bool mask: pixel inside the image by at least ``margin`` pixels."""
        px = np.asarray(px, dtype=float).reshape(-1, 2)
        with np.errstate(invalid='ignore'):
            return ((px[:, 0] >= -0.5 + margin) & (px[:, 0] <= self.width - 0.5 - margin)
                    & (px[:, 1] >= -0.5 + margin) & (px[:, 1] <= self.height - 0.5 - margin))

    def undistort_pixels(self, px: np.ndarray, output: str = 'normalized',
                         iterations: int = 40, eps: float = 1e-12) -> np.ndarray:
        """Remove the lens distortion from pixel positions (iterative inverse of project).

        Args:
            px: (N, 2) distorted pixels ``(u, v)``.
            output: ``'normalized'``: ideal ``(X / Z, Y / Z)``; ``'ideal'``: ideal pinhole
                pixels with the same K; ``'rectified'``: pixels of the rectified image
                (R and P of CameraInfo).
            iterations: maximum fixed-point iterations (cv2.undistortPointsIter).
            eps: convergence threshold in normalized units.

        Returns:
            (N, 2) array as selected by ``output``.
        """
        if output not in ('normalized', 'ideal', 'rectified'):
            raise ValueError(f"output must be 'normalized', 'ideal' or 'rectified'; got "
                             f'{output!r}')
        px = np.asarray(px, dtype=float).reshape(-1, 2)
        if px.shape[0] == 0:
            return np.zeros((0, 2))
        bad = ~np.isfinite(px).all(axis=1)
        src = np.where(bad[:, None], 0.0, px)
        K = self.K
        yd = (src[:, 1] - K[1, 2]) / K[1, 1]
        xd = (src[:, 0] - K[0, 2] - K[0, 1] * yd) / K[0, 0]
        target = np.column_stack([xd, yd])
        if self.has_distortion:
            xy = _undistort_normalized_cv(target, self.D, int(iterations), float(eps))
            xy = self._newton_undistort(xy, target, eps)
        else:
            xy = target
        if output == 'ideal':
            out = self.normalized_to_pixels(xy, distort=False)
        elif output == 'rectified':
            h = np.column_stack([xy, np.ones(xy.shape[0])]) @ self.R.T
            with np.errstate(divide='ignore', invalid='ignore'):
                h = h[:, :2] / h[:, 2:3]
            out = np.column_stack([h, np.ones(h.shape[0])]) @ self.P[:, :3].T
            out = out[:, :2]
        else:
            out = xy
        out[bad] = np.nan
        return out

    def _newton_undistort(self, xy: np.ndarray, target: np.ndarray, eps: float,
                          steps: int = 4) -> np.ndarray:
        """Refine ideal normalized points so that distort(xy) == target (Newton, 2x2)."""
        h = 1e-7
        for _ in range(steps):
            f = self.distort_normalized(xy) - target
            if np.all(np.abs(f) < eps):
                break
            jx = (self.distort_normalized(xy + [h, 0.0]) - self.distort_normalized(xy - [h, 0.0]))
            jy = (self.distort_normalized(xy + [0.0, h]) - self.distort_normalized(xy - [0.0, h]))
            a, c = jx[:, 0] / (2 * h), jx[:, 1] / (2 * h)
            b, d = jy[:, 0] / (2 * h), jy[:, 1] / (2 * h)
            det = a * d - b * c
            ok = np.abs(det) > 1e-12
            det = np.where(ok, det, 1.0)
            dx = np.where(ok, (d * f[:, 0] - b * f[:, 1]) / det, 0.0)
            dy = np.where(ok, (-c * f[:, 0] + a * f[:, 1]) / det, 0.0)
            xy = xy - np.column_stack([dx, dy])
        return xy

    def back_project(self, px: np.ndarray) -> np.ndarray:
        """Return (N, 3) unit rays in the optical frame through (N, 2) distorted pixels."""
        xy = self.undistort_pixels(px, 'normalized')
        rays = np.column_stack([xy, np.ones(xy.shape[0])])
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def ideal_to_distorted_map(self):
        """Return cached ``(map_x, map_y)`` float32 remap tables: distorted -> ideal pixel.

        ``cv2.remap(ideal_image, map_x, map_y, ...)`` turns an image rendered with the ideal
        pinhole (same K, no distortion) into the image this camera would record.
        """
        cache = self.__dict__.get('_remap_cache')
        if cache is None:
            u, v = np.meshgrid(np.arange(self.width, dtype=float),
                               np.arange(self.height, dtype=float))
            ideal = self.undistort_pixels(np.column_stack([u.ravel(), v.ravel()]), 'ideal')
            cache = (ideal[:, 0].reshape(self.height, self.width).astype(np.float32),
                     ideal[:, 1].reshape(self.height, self.width).astype(np.float32))
            object.__setattr__(self, '_remap_cache', cache)
        return cache

    def to_dict(self) -> dict:
        """Return a plain dict (YAML-friendly) with every field."""
        return {'width': self.width, 'height': self.height,
                'distortion_model': self.distortion_model,
                'K': [float(v) for v in self.K.ravel()], 'D': [float(v) for v in self.D],
                'R': [float(v) for v in self.R.ravel()], 'P': [float(v) for v in self.P.ravel()]}

    @classmethod
    def from_dict(cls, d: dict) -> 'CameraModel':
        """Inverse of :meth:`to_dict`."""
        return cls(width=int(d['width']), height=int(d['height']),
                   K=np.reshape(d['K'], (3, 3)), D=np.asarray(d['D'], dtype=float),
                   distortion_model=d.get('distortion_model', 'plumb_bob'),
                   R=None if d.get('R') is None else np.reshape(d['R'], (3, 3)),
                   P=None if d.get('P') is None else np.reshape(d['P'], (3, 4)))


__all__ = ['CameraModel', 'DISTORTION_MODELS', 'OPTICAL_FROM_BODY']
