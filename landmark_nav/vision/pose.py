"""6-DOF pose of a detected landmark from its four frame corners (visual navigation §2.2.4).

Parameters (eqs. 6-10): ``v = (x, y, z, roll Omega, tilt Phi, turn kappa)``. ``(x, y, z)``
is the landmark centre in the camera's *body* frame (the chapter's robot coordinates with
the camera at the origin: x forward along the optical axis, y left, z up; REP 103
``camera_link``). The landmark frame (x out of the printed face, y right when looking at it,
z up; see :mod:`.landmark`) is rotated into the body frame by

    R(v) = Rz(pi + kappa) Ry(Phi) Rx(Omega)

i.e. eq. 6 ``B = R_Omega R_Phi R_kappa (A - g)`` with the rotation matrices of eqs. 7-9
(``R_kappa^T R_Phi^T R_Omega^T = Rz Ry Rx``), except that the turn is counted from the
landmark *facing* the camera: the chapter's eq. 9 angle is ``kappa + pi``. So ``v = (d, 0,
0, 0, 0, 0)`` is an upright landmark straight ahead at distance d looking back at the
camera, the "viewing angle kappa = 0" of Table 1. Positive kappa turns the landmark
counter-clockwise seen from above, positive Phi tilts its face down, positive Omega rolls
it to its right (to the left in the image).

Equations (eqs. 11-14): a landmark point ``B = (0, b_y, b_z)`` is seen at ``A = g + R B``
(body frame), i.e. ``X = OPTICAL_FROM_BODY A`` in the REP 103 optical frame, and at the
ideal (undistorted) pixel ``u = cx + fx X_x / X_z + skew X_y / X_z``, ``v = cy + fy X_y /
X_z`` -- eq. 11 with ``h_c = u``, ``h_r = v``, ``c = f``. The eight equations of eq. 14
(two per frame corner) are used divided by their ``f_w`` (a positive factor that does not
change their zeros): ``F = h(v) - h_measured`` in pixels, so the Gauss-Newton step of eq. 18
minimises the pixel error and ``sigma^2 (J^T J)^-1`` is the pose covariance for a pixel noise
sigma. Pixel positions are undistorted with the camera model first (§2.2.4).

Initial guesses (§2.2.4): distance from the apparent size, direction from the corner
centroid, roll from the code orientation (the corner order of the detection), and the four
quadrants ``(+-kappa_0, +-Phi_0)`` of the turn-tilt plane. Each is iterated
``probe_iterations`` times; the one with the least pixel error is continued until the stop
criteria of eq. 19 hold (``|dx, dy, dz| < P_inf`` and ``|dOmega, dPhi, dkappa| < R_inf``).
A step that would put a corner behind the camera or increase the pixel error is halved
(at most ``max_halvings`` times), a safeguard the chapter does not need to mention.

Extension beyond the chapter (``PoseParams.planar_start``, default on): a tilted landmark
far away has two pose minima (the planar ambiguity), and from the quadrant guesses
Gauss-Newton can end in the wrong one or in a spurious minimum (on composites at 2.2 m and
38-56 degrees tilt, 3 of 126 poses were 31-75 degrees off). So it is also started from the
two closed-form planar solutions of the four frame corners (IPPE, ``cv2.solvePnPGeneric``
with ``SOLVEPNP_IPPE_SQUARE``), every start is iterated to convergence and the minimum of
least pixel error is kept. The covariance is the linearised ``sigma^2 (J^T W^2 J)^-1`` at
that minimum. A distinct second minimum (the planar two-fold ambiguity) is tested against
the pose's likelihood confidence region: with ``s^2`` the larger of ``pixel_sigma^2`` and
the residual variance ``SSE / (n - 6)``, a minimum with ``(SSE_2 - SSE) / s^2 <= chi2_6(0.999)``
cannot be rejected by the pixels. The pose is then reported as ambiguous
(``LandmarkPose.ambiguous``, ``LandmarkPose.alternative``) and its covariance is the equal
mixture of both minima about the reported one, ``(C + C_2 + d d^T) / 2`` with ``d`` the
difference of the two, which covers the other minimum (its normalised error is at most 2).
Otherwise the other minimum enters with its likelihood weight ``exp(-stat / 2)``.
On composites in real photographs at 2.2 m (``bench_landmarks.py real pose --seed 101``,
York Urban and CamVid backgrounds) the two poses off by more than 5 degrees (8.9 and 67.7)
are both reported ambiguous, with NEES 28 and 15-17; on seeds 201-203 (1350 poses) none is
off by more than 5 degrees and 61 are reported ambiguous.

Extension beyond the chapter (``PoseParams.point_set = 'edges'``): the four frame corners
carry the perspective convergence of the frame edges only through four points, and near
head-on tilt and turn are weakly observable from them (at 2.2 m about 34 degrees per pixel
of corner error). The interior X-corners of the frame edges have known landmark coordinates
too (:meth:`LandmarkDesign.edge_corners`), so with ``edge_corners_px`` given they are added
as further point equations of the same form (eq. 14, two per corner), each weighted by the
ratio ``frame_sigma / edge_sigma`` of the measured precisions (``edge_corner_weight``):
``F = w (h(v) - h_measured)``, covariance ``sigma^2 (J^T W^2 J)^-1``. This is the default
(on the Table 1 views at 2.2 m head-on it lowers the tilt/turn RMS error from 0.32 to
0.19 degrees); ``point_set = 'frame'`` is the chapter's four-corner form.

:func:`solve_pnp` is the OpenCV comparison path on the same corners.
"""

from dataclasses import dataclass, field
import math
from typing import Optional, Sequence, Tuple

import cv2
from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np

_M = np.asarray(OPTICAL_FROM_BODY, dtype=float)
_RZ_PI = np.diag([-1.0, -1.0, 1.0])


#: point sets of the pose equations (PoseParams.point_set)
POINT_SETS = ('frame', 'edges')


class PoseError(ValueError):
    """The pose cannot be estimated from the given corners (the message says why)."""


@dataclass(frozen=True)
class PoseParams:
    """Parameters of the Gauss-Newton pose estimate (§2.2.4).

    Attributes:
        p_inf: eq. 19 position stop criterion, norm of the step in (x, y, z) [m].
        r_inf: eq. 19 rotation stop criterion, norm of the step in the angles [rad].
        max_iterations: iteration limit of the continued estimate.
        probe_iterations: iterations of each of the four initial guesses before choosing.
        initial_turn: |kappa| of the quadrant guesses [rad].
        initial_tilt: |Phi| of the quadrant guesses [rad].
        max_halvings: step halvings when a step increases the pixel error.
        pixel_sigma: standard deviation of the frame-corner pixel positions [px], for the
            covariance.
        point_set: ``'frame'``: the chapter's eight equations of the four frame corners;
            ``'edges'``: also the interior X-corners of the frame edges when they are given
            (extension, see the module docstring).
        edge_corner_weight: weight of an interior X-corner equation relative to a frame
            corner, the ratio of their measured pixel precisions (frame / X-corner). On
            the Table 1 views at 2.2 m (rendered with 16 x 16 samples per pixel, seeds
            20-22, turn 0 and 30 degrees) the frame corners scatter by 0.009-0.010 px and
            the interior X-corners, placed by the detector where the block boundaries
            cross the edge lines, by 0.0065-0.0069 px from frame to frame (ratio 1.4-1.5),
            both with mean errors of at most 0.01 px.
        planar_start: also start Gauss-Newton from the two closed-form planar solutions
            (``cv2.solvePnPGeneric`` with ``SOLVEPNP_IPPE_SQUARE`` on the frame corners) and
            keep the minimum of least pixel error (extension, module docstring).
    """

    p_inf: float = 1e-6
    r_inf: float = 1e-6
    max_iterations: int = 50
    probe_iterations: int = 3
    initial_turn: float = math.radians(20.0)
    initial_tilt: float = math.radians(20.0)
    max_halvings: int = 8
    pixel_sigma: float = 0.05
    point_set: str = 'edges'
    edge_corner_weight: float = 1.5
    planar_start: bool = True

    def __post_init__(self) -> None:
        """Validate the values (ValueError naming the field)."""
        if self.point_set not in POINT_SETS:
            raise ValueError(f'point_set = {self.point_set!r} must be one of {POINT_SETS}')
        w = self.edge_corner_weight
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not 0 < w <= 10:
            raise ValueError(f'edge_corner_weight = {w!r} must be a number in (0, 10]')
        if not isinstance(self.planar_start, bool):
            raise ValueError(f'planar_start = {self.planar_start!r} must be a bool')
        for name in ('p_inf', 'r_inf', 'pixel_sigma'):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f'{name} = {v!r} must be a finite number > 0')
        for name in ('initial_turn', 'initial_tilt'):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0 <= v < math.pi / 2):
                raise ValueError(f'{name} = {v!r} must be in [0, pi/2) rad')
        for name, lo in (('max_iterations', 1), ('probe_iterations', 0), ('max_halvings', 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ValueError(f'{name} = {v!r} must be an integer >= {lo}')


@dataclass(frozen=True, eq=False)
class LandmarkPose:
    """Pose of a landmark relative to the camera.

    Attributes:
        v: (6,) ``(x, y, z, Omega, Phi, kappa)`` [m, rad] (module docstring).
        covariance: (6, 6) covariance of ``v`` for the pixel noise used.
        rms_px: RMS pixel error of the equations at ``v`` (weighted, frame-corner pixels).
        iterations: Gauss-Newton iterations of the continued estimate.
        converged: the eq. 19 stop criteria were met.
        method: ``'gauss_newton'`` or the OpenCV method name.
        alternative_rms_px: RMS pixel error of the best *other* minimum that Gauss-Newton
            reached from its starts (rotation more than 1 degree away; the planar two-fold
            ambiguity), inf if there was none.
        ambiguous: the other minimum lies inside the pose's 99.9 % likelihood confidence
            region (the pixels cannot tell the two apart); ``covariance`` is then the equal
            mixture of both about ``v`` and covers ``alternative``. A consumer must not use
            an ambiguous pose as a precise one.
        alternative: (6,) ``v`` of that other minimum, None if there was none.
    """

    v: np.ndarray
    covariance: np.ndarray = field(repr=False)
    rms_px: float
    iterations: int
    converged: bool
    method: str = 'gauss_newton'
    alternative_rms_px: float = math.inf
    ambiguous: bool = False
    alternative: Optional[np.ndarray] = field(default=None, repr=False)

    @property
    def position(self) -> np.ndarray:
        """Landmark centre in the camera body frame (x forward, y left, z up) [m]."""
        return self.v[:3].copy()

    @property
    def rotation_body(self) -> np.ndarray:
        """(3, 3) rotation landmark frame -> camera body frame, ``Rz(pi + kappa) Ry Rx``."""
        return rotation_matrix(self.v[3:])

    @property
    def translation_optical(self) -> np.ndarray:
        """Landmark centre in the REP 103 camera optical frame [m]."""
        return _M @ self.v[:3]

    @property
    def rotation_optical(self) -> np.ndarray:
        """(3, 3) rotation landmark frame -> camera optical frame."""
        return _M @ self.rotation_body

    @property
    def quaternion_optical(self) -> np.ndarray:
        """Orientation of the landmark in the optical frame as a quaternion (x, y, z, w)."""
        from scipy.spatial.transform import Rotation  # on first use: ~0.6 CPU-s to import
        return Rotation.from_matrix(self.rotation_optical).as_quat()

    @property
    def distance(self) -> float:
        """Distance camera centre -> landmark centre [m]."""
        return float(np.linalg.norm(self.v[:3]))


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _drx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[0.0, 0.0, 0.0], [0.0, -s, -c], [0.0, c, -s]])


def _dry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[-s, 0.0, c], [0.0, 0.0, 0.0], [-c, 0.0, -s]])


def _drz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[-s, -c, 0.0], [c, -s, 0.0], [0.0, 0.0, 0.0]])


def rotation_matrix(angles: Sequence[float]) -> np.ndarray:
    """Return ``Rz(pi + kappa) Ry(Phi) Rx(Omega)`` for ``angles = (Omega, Phi, kappa)``.

    This is ``R_kappa^T R_Phi^T R_Omega^T`` of eqs. 7-9 (landmark -> body) with the turn
    counted from facing the camera.
    """
    om, ph, ka = (float(a) for a in angles)
    return _RZ_PI @ _rz(ka) @ _ry(ph) @ _rx(om)


def angles_from_rotation(r_body: np.ndarray) -> np.ndarray:
    """Return ``(Omega, Phi, kappa)`` of a landmark -> body rotation (inverse of above).

    Phi is in [-pi/2, pi/2], Omega and kappa in (-pi, pi].
    """
    r = _RZ_PI.T @ np.asarray(r_body, dtype=float)
    phi = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    kappa = math.atan2(r[1, 0], r[0, 0])
    omega = math.atan2(r[2, 1], r[2, 2])
    return np.array([omega, phi, kappa])


def _rotations(angles: Sequence[float]):
    om, ph, ka = (float(a) for a in angles)
    rz, ry, rx = _RZ_PI @ _rz(ka), _ry(ph), _rx(om)
    return om, ph, ka, rz, ry, rx


def _pixels(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Ideal pixels of (N, 3) optical-frame points (NaN at or behind the camera)."""
    z = x[:, 2]
    with np.errstate(divide='ignore', invalid='ignore'):
        iz = np.where(z > 0, 1.0 / z, np.nan)
    u = k[0, 2] + (k[0, 0] * x[:, 0] + k[0, 1] * x[:, 1]) * iz
    return np.column_stack([u, k[1, 2] + k[1, 1] * x[:, 1] * iz])


def project_points(v: np.ndarray, points: np.ndarray, camera: CameraModel) -> np.ndarray:
    """Return the (N, 2) ideal pixels of landmark points at pose ``v`` (eqs. 6, 11)."""
    _, _, _, rz, ry, rx = _rotations(v[3:])
    a = v[:3] + points @ (rz @ ry @ rx).T               # A = g + R B (eq. 6)
    return _pixels(a @ _M.T, camera.K)


def project_corners(v: np.ndarray, points: np.ndarray,
                    camera: CameraModel) -> Tuple[np.ndarray, np.ndarray]:
    """Ideal pixels of landmark points and their Jacobian (eqs. 11-14).

    Args:
        v: (6,) pose parameters.
        points: (N, 3) landmark points ``(0, b_y, b_z)`` [m].
        camera: the camera (K only; no distortion here).

    Returns:
        (px, J): (N, 2) ideal pixels ``(u, v)`` and the (2N, 6) Jacobian of the stacked
        ``(u_1, v_1, u_2, ...)`` with respect to ``v``. Pixels of points at or behind the
        camera are NaN.
    """
    om, ph, ka, rz, ry, rx = _rotations(v[3:])
    a = v[:3] + points @ (rz @ ry @ rx).T               # A = g + R B (eq. 6)
    x = a @ _M.T                                       # optical frame (eq. 11)
    k = camera.K
    px = _pixels(x, k)
    fx, skew, fy = k[0, 0], k[0, 1], k[1, 1]
    z = x[:, 2]
    with np.errstate(divide='ignore', invalid='ignore'):
        iz = np.where(z > 0, 1.0 / z, np.nan)
    n = len(points)
    dh = np.zeros((n, 2, 3))                           # d(u, v)/dX
    dh[:, 0, 0] = fx * iz
    dh[:, 0, 1] = skew * iz
    dh[:, 0, 2] = -(fx * x[:, 0] + skew * x[:, 1]) * iz * iz
    dh[:, 1, 1] = fy * iz
    dh[:, 1, 2] = -fy * x[:, 1] * iz * iz
    dhm = dh @ _M                                      # d(u, v)/dA
    dr = (rz @ ry @ _drx(om), rz @ _dry(ph) @ rx, _RZ_PI @ _drz(ka) @ ry @ rx)
    jac = np.empty((n, 2, 6))
    jac[:, :, :3] = dhm                                # dA/dg = I
    for j in range(3):
        jac[:, :, 3 + j] = np.einsum('nij,nj->ni', dhm, points @ dr[j].T)
    return px, jac.reshape(-1, 6)


def _rms(res: np.ndarray) -> float:
    return float(np.sqrt(np.mean(res * res))) if np.all(np.isfinite(res)) else math.inf


def _initial_guess(ideal: np.ndarray, camera: CameraModel, half_side: float) -> np.ndarray:
    """Position from apparent size and centroid, roll from the corner order (kappa=Phi=0)."""
    k_inv = np.linalg.inv(camera.K)
    h = np.column_stack([ideal, np.ones(4)]) @ k_inv.T     # normalized rays
    side_px = np.mean(np.linalg.norm(ideal - np.roll(ideal, -1, axis=0), axis=1))
    f = 0.5 * (camera.fx + camera.fy)
    dist = f * 2.0 * half_side / max(side_px, 1e-9)
    ray = h.mean(axis=0)
    g_opt = dist * ray / np.linalg.norm(ray)
    up = 0.5 * (ideal[0] + ideal[1]) - 0.5 * (ideal[2] + ideal[3])   # top minus bottom
    omega = math.atan2(-up[0], -up[1])
    out = np.zeros(6)
    out[:3] = _M.T @ g_opt
    out[3] = omega
    return out


def _gauss_newton(v: np.ndarray, points: np.ndarray, meas: np.ndarray, camera: CameraModel,
                  iterations: int, params: PoseParams,
                  weights: Optional[np.ndarray] = None) -> Tuple[np.ndarray, float, int, bool]:
    """Run eqs. 16-18 from ``v``; return (v, rms, iterations, converged by eq. 19).

    ``weights`` (N,) scale the two equations of each point (extension, module docstring).
    """
    w = np.ones(2 * len(points)) if weights is None else np.repeat(weights, 2)
    px, jac = project_corners(v, points, camera)
    jac = jac * w[:, None]
    res = (px - meas).ravel() * w
    err = _rms(res)
    for it in range(1, iterations + 1):
        if not math.isfinite(err):
            return v, err, it, False
        try:
            dv = -np.linalg.solve(jac.T @ jac, jac.T @ res)      # eq. 18
        except np.linalg.LinAlgError:
            return v, err, it, False
        step = 1.0
        for _ in range(params.max_halvings + 1):
            cand = v + step * dv                                 # eq. 17
            res_c = (project_points(cand, points, camera) - meas).ravel() * w
            err_c = _rms(res_c)
            if err_c <= err * (1.0 + 1e-12):
                break
            step *= 0.5
        else:
            return v, err, it, False
        d = step * dv
        v, res, err = cand, res_c, err_c
        if np.linalg.norm(d[:3]) < params.p_inf and np.linalg.norm(d[3:]) < params.r_inf:
            return v, err, it, True                              # eq. 19
        _, jac = project_corners(v, points, camera)
        jac = jac * w[:, None]
    return v, err, iterations, False


#: 99.9 % quantile of the chi-square distribution with 6 degrees of freedom
CHI2_6_999 = 22.458

#: minima whose rotations differ by less than this [rad] are the same minimum
_DISTINCT_MINIMUM = math.radians(1.0)


def _rotation_angle(r_a: np.ndarray, r_b: np.ndarray) -> float:
    """Angle of the rotation ``r_a^T r_b`` [rad]."""
    c = 0.5 * (float(np.trace(r_a.T @ r_b)) - 1.0)
    return math.acos(max(-1.0, min(1.0, c)))


def _planar_starts(ideal: np.ndarray, camera: CameraModel, design: LandmarkDesign) -> list:
    """Return the pose parameters of the closed-form planar (IPPE) solutions of 4 corners.

    ``cv2.solvePnPGeneric`` with ``SOLVEPNP_IPPE_SQUARE`` on the ideal (undistorted) frame
    corners gives both minima of the planar pose ambiguity; an empty list if it fails.
    """
    obj = (design.frame_corners() @ _MARKER_FROM_LANDMARK.T).reshape(-1, 1, 3)
    try:
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(
            obj, np.ascontiguousarray(ideal, dtype=np.float64).reshape(-1, 1, 2),
            np.asarray(camera.K, dtype=np.float64), None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    except cv2.error:
        return []
    out = []
    for rvec, tvec in zip(rvecs[:n], tvecs[:n]):
        r = cv2.Rodrigues(rvec)[0] @ _MARKER_FROM_LANDMARK
        v = pose_from_optical(r, tvec)
        if np.all(np.isfinite(v)):
            out.append(v)
    return out


def _local_covariance(v: np.ndarray, points: np.ndarray, camera: CameraModel,
                      weights: Optional[np.ndarray], sigma: float) -> np.ndarray:
    """Return ``sigma^2 (J^T W^2 J)^-1`` at ``v`` (the linearised covariance of eq. 18)."""
    _, jac = project_corners(v, points, camera)
    if weights is not None:
        jac = jac * np.repeat(weights, 2)[:, None]
    return sigma ** 2 * np.linalg.pinv(jac.T @ jac)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _interior_edge_corners(edge_corners_px: np.ndarray, design: LandmarkDesign
                           ) -> Tuple[np.ndarray, np.ndarray]:
    """Return the interior X-corners: ((M, 3) landmark points, (M, 2) distorted pixels)."""
    e = np.asarray(edge_corners_px, dtype=float)
    n = design.corners_per_edge
    if e.shape != (4, n, 2) or not np.all(np.isfinite(e)):
        raise PoseError(f'need (4, {n}, 2) finite edge-corner pixels; got shape {e.shape}')
    return design.edge_corners()[:, 1:-1].reshape(-1, 3), e[:, 1:-1].reshape(-1, 2)


def _with_edge_corners(edge_corners_px: np.ndarray, ideal: np.ndarray, camera: CameraModel,
                       design: LandmarkDesign, weight: float
                       ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, ideal pixels and weights of the frame corners plus the interior X-corners."""
    pts, px = _interior_edge_corners(edge_corners_px, design)
    inner = camera.undistort_pixels(px, 'ideal')
    if not np.all(np.isfinite(inner)):
        raise PoseError('edge corners could not be undistorted')
    weights = np.concatenate([np.ones(4), np.full(len(pts), float(weight))])
    return np.vstack([design.frame_corners(), pts]), np.vstack([ideal, inner]), weights


def estimate_pose(corners_px: np.ndarray, camera: CameraModel,
                  design: LandmarkDesign = LandmarkDesign(),
                  params: PoseParams = PoseParams(),
                  pixel_sigma: Optional[float] = None,
                  edge_corners_px: Optional[np.ndarray] = None) -> LandmarkPose:
    """Estimate the 6-DOF landmark pose from its frame corners by Gauss-Newton (§2.2.4).

    Args:
        corners_px: (4, 2) distorted pixel positions of the frame corners in the order of
            :meth:`LandmarkDesign.frame_corners` (top-left, top-right, bottom-right,
            bottom-left of the upright landmark, as :class:`~.detector.Detection` gives them).
        camera: the camera model (the corners are undistorted with it first).
        design: landmark design (frame width and kind give the corner coordinates).
        params: iteration parameters.
        pixel_sigma: corner noise for the covariance [px] (default ``params.pixel_sigma``).
        edge_corners_px: optional (4, n, 2) distorted pixels of the frame-edge X-corners in
            the order of :meth:`LandmarkDesign.edge_corners` (``Detection.edge_corners``);
            with ``params.point_set == 'edges'`` their interior corners are added to the
            equations (the end corners are the frame corners, taken from ``corners_px``).

    Returns:
        :class:`LandmarkPose`.

    Raises:
        PoseError: non-finite or degenerate corners.
    """
    c = np.asarray(corners_px, dtype=float)
    if c.shape != (4, 2) or not np.all(np.isfinite(c)):
        raise PoseError(f'need (4, 2) finite corner pixels; got shape {c.shape}')
    ideal = camera.undistort_pixels(c, 'ideal')
    if not np.all(np.isfinite(ideal)):
        raise PoseError('corners could not be undistorted')
    edge = ideal - np.roll(ideal, -1, axis=0)
    if np.min(np.linalg.norm(edge, axis=1)) < 1.0:
        raise PoseError('degenerate frame: corners closer than one pixel')
    points = design.frame_corners()
    meas = ideal
    weights = None
    if params.point_set == 'edges' and edge_corners_px is not None:
        # extension: the interior X-corners join the equations from the quadrant probes on
        points, meas, weights = _with_edge_corners(edge_corners_px, ideal, camera, design,
                                                   params.edge_corner_weight)
    base = _initial_guess(ideal, camera, design.half_side)
    best = None
    for sk in (1.0, -1.0):
        for sp in (1.0, -1.0):
            v0 = base.copy()
            v0[4] = sp * params.initial_tilt
            v0[5] = sk * params.initial_turn
            got = _gauss_newton(v0, points, meas, camera, params.probe_iterations, params,
                                weights)
            if best is None or got[1] < best[1]:
                best = got
    starts = [best[0]]
    if params.planar_start:
        starts += _planar_starts(ideal, camera, design)
    # every start is iterated to its minimum; the least pixel error wins (extension)
    ends = [_gauss_newton(v0, points, meas, camera, params.max_iterations, params, weights)
            for v0 in starts]
    ends = [e for e in ends if math.isfinite(e[1])]
    if not ends:
        raise PoseError('pose iteration diverged')
    ends.sort(key=lambda e: e[1])
    v, err, iters, conv = ends[0]
    v = v.copy()
    v[3], v[5] = _wrap(v[3]), _wrap(v[5])
    sigma = params.pixel_sigma if pixel_sigma is None else float(pixel_sigma)
    # noise of the fit: the stated corner noise, or the residual's if that is larger
    # (s^2 = SSE / (n - 6), the unbiased residual variance of a 6-parameter least squares)
    n_eq = 2 * len(points)
    s2 = max(sigma * sigma, n_eq * err * err / max(n_eq - 6, 1))
    sigma = math.sqrt(s2)
    cov = _local_covariance(v, points, camera, weights, sigma)
    # a distinct second minimum (the planar two-fold ambiguity) widens the covariance; one
    # inside the pose's 99.9 % likelihood confidence region is a hypothesis the pixels
    # cannot reject: the pose is ambiguous and the covariance the equal mixture of both
    alt_err, alt_v = math.inf, None
    for va, ea, _, _ in ends[1:]:
        if _rotation_angle(rotation_matrix(va[3:]), rotation_matrix(v[3:])) >= \
                _DISTINCT_MINIMUM and ea < alt_err:
            alt_err, alt_v = ea, va.copy()
    ambiguous = False
    if alt_v is not None:
        alt_v[3], alt_v[5] = _wrap(alt_v[3]), _wrap(alt_v[5])
        d = alt_v - v
        d[3:] = [_wrap(a) for a in d[3:]]
        alt_cov = _local_covariance(alt_v, points, camera, weights, sigma) + np.outer(d, d)
        # likelihood-ratio statistic of the second minimum: the 99.9 % likelihood
        # confidence region of the 6 pose parameters of a least-squares fit with noise
        # variance s^2 is SSE(v) - SSE_min <= s^2 chi2_6(0.999)
        stat = n_eq * (alt_err * alt_err - err * err) / s2
        ambiguous = stat <= CHI2_6_999
        if ambiguous:
            cov = 0.5 * (cov + alt_cov)
        else:
            wa = math.exp(-0.5 * stat)
            cov = (cov + wa * alt_cov) / (1.0 + wa)
    return LandmarkPose(v, 0.5 * (cov + cov.T), err, iters, conv,
                        alternative_rms_px=alt_err, ambiguous=bool(ambiguous),
                        alternative=alt_v)


# ---------------------------------------------------------------------- OpenCV comparison

#: landmark frame (x out, y right, z up) -> OpenCV square-marker frame (x right, y up, z out)
_MARKER_FROM_LANDMARK = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])

PNP_METHODS = {'ippe_square': cv2.SOLVEPNP_IPPE_SQUARE, 'ippe': cv2.SOLVEPNP_IPPE,
               'iterative': cv2.SOLVEPNP_ITERATIVE}


def pose_from_optical(rotation_optical: np.ndarray, translation_optical: np.ndarray) -> np.ndarray:
    """Return ``v`` for a landmark -> optical rotation and the landmark centre (optical)."""
    r_body = _M.T @ np.asarray(rotation_optical, dtype=float)
    v = np.zeros(6)
    v[:3] = _M.T @ np.asarray(translation_optical, dtype=float).reshape(3)
    v[3:] = angles_from_rotation(r_body)
    return v


def solve_pnp(corners_px: np.ndarray, camera: CameraModel,
              design: LandmarkDesign = LandmarkDesign(), method: str = 'ippe_square',
              pixel_sigma: float = 0.05,
              edge_corners_px: Optional[np.ndarray] = None) -> LandmarkPose:
    """Estimate the same pose with ``cv2.solvePnP`` on the same corners (comparison path).

    Args:
        corners_px: (4, 2) distorted frame-corner pixels (order of ``frame_corners()``).
        camera: camera model (K and D go to OpenCV, which undistorts itself).
        design: landmark design.
        method: ``'ippe_square'`` (SOLVEPNP_IPPE_SQUARE, four corners only), ``'ippe'``
            (SOLVEPNP_IPPE, planar points) or ``'iterative'`` (SOLVEPNP_ITERATIVE,
            Levenberg-Marquardt on the pixel error).
        pixel_sigma: pixel noise for the covariance [px].
        edge_corners_px: optional (4, n, 2) edge X-corners (as for :func:`estimate_pose`);
            given, their interior corners are added to the points (unweighted).

    Returns:
        :class:`LandmarkPose` (``iterations`` 0, ``converged`` = OpenCV's success flag).

    Raises:
        PoseError: OpenCV finds no pose, or an unknown method.
    """
    if method not in PNP_METHODS:
        raise PoseError(f'unknown solvePnP method {method!r}; use one of {sorted(PNP_METHODS)}')
    points = design.frame_corners()
    img = np.asarray(corners_px, dtype=np.float64).reshape(4, 2)
    if edge_corners_px is not None:
        if method == 'ippe_square':
            raise PoseError("solvePnP 'ippe_square' takes the four frame corners only")
        pts, px = _interior_edge_corners(edge_corners_px, design)
        points, img = np.vstack([points, pts]), np.vstack([img, px])
    c = np.ascontiguousarray(img).reshape(-1, 1, 2)
    obj = (points @ _MARKER_FROM_LANDMARK.T).reshape(-1, 1, 3)
    ok, rvec, tvec = cv2.solvePnP(obj, c, np.asarray(camera.K), np.asarray(camera.D),
                                  flags=PNP_METHODS[method])
    if not ok:
        raise PoseError(f'cv2.solvePnP ({method}) found no pose')
    r_marker = cv2.Rodrigues(rvec)[0]
    v = pose_from_optical(r_marker @ _MARKER_FROM_LANDMARK, tvec)
    px, jac = project_corners(v, points, camera)
    ideal = camera.undistort_pixels(img, 'ideal')
    err = _rms((px - ideal).ravel())
    cov = pixel_sigma ** 2 * np.linalg.pinv(jac.T @ jac)
    return LandmarkPose(v, 0.5 * (cov + cov.T), err, 0, bool(ok), method)


__all__ = ['CHI2_6_999', 'LandmarkPose', 'PNP_METHODS', 'POINT_SETS', 'PoseError', 'PoseParams',
           'angles_from_rotation',
           'estimate_pose', 'pose_from_optical', 'project_corners', 'project_points',
           'rotation_matrix', 'solve_pnp']
