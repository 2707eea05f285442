"""Line matching and lateral position in the corridor (visual navigation chapter §3.1.4-3.1.5).

Frames: the *corridor frame* has x along the corridor (towards its vanishing point), y to
the left, z up, origin on the floor at the corridor centre; the robot's lateral position is
its ``y`` there. The corridor's long edges are 3-D lines along x at ``(y_line, z_line)``:
the wall/floor edges at ``(+-width / 2, 0)``, the wall/ceiling edges at
``(+-width / 2, height)`` and optionally a floor centre line at ``(0, 0)``.

Camera rotation: from the VP direction ``d`` (optical frame) eq. 21 gives the camera's
heading ``theta`` and tilt ``alpha`` (:func:`~.orientation.eq21_from_direction`; roll 0,
the chapter's ``beta = 0``); ``R`` maps corridor-frame vectors to the optical frame.

Eq. 23, in vector form: a 3-D line through the camera-relative point
``p0 = (0, -y_d, -z_d)`` (``y_d = y_camera - y_line``, ``z_d = z_camera - z_line``, the
chapter's definitions) projects onto the image line ``l`` (eq. 22, ``a x + b y = c`` ->
``l = (a, b, -c)``) iff ``l . K R p0 = 0``; with ``m = R^T K^T l`` this is::

    m_y y_d + m_z z_d = 0        ->        y_d = -z_d m_z / m_y                 (eq. 23)

linear in the only unknown ``y_d`` (the chapter expands ``K R`` in theta, alpha, f', c_x,
c_y; the same equation).

Matching (§3.1.4): a corridor line whose midpoint ray points below the horizon belongs to
the floor (``z_d`` = camera height), above it to the ceiling (``z_d`` = camera height -
corridor height). Each image line then gives one estimate ``y_camera = y_line + y_d`` per
model line on its side that leaves the camera inside the corridor (a floor line on the
right can be the right wall's edge or the centre line: "each lower line is matched also
to the center line").

Robust value (§3.1.5): the estimates are weighted by ``1 / var`` (end-point noise
propagated through eq. 23, numerically) times, with a prior, their likelihood under it
("weighted according to their likelihoods based on the prior estimate"); the estimate
farthest from the weighted mean is removed while it lies more than ``gate`` of its own
standard deviations (plus the mean's) away ("iterative furthest point removal").
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple

from landmark_nav.corridor.orientation import eq21_from_direction, mount_rotation
from landmark_nav.vision.camera import OPTICAL_FROM_BODY
import numpy as np


@dataclass(frozen=True)
class CorridorModel:
    """Known corridor geometry.

    Attributes:
        width: wall-to-wall width [m] (> 0).
        height: floor-to-ceiling height [m] (> 0); ``None``: no ceiling edges are used.
        centre_line: a floor line along the corridor centre (the chapter's corridor had one).
    """

    width: float
    height: Optional[float] = None
    centre_line: bool = False

    def __post_init__(self) -> None:
        """Validate."""
        if not (self.width > 0 and math.isfinite(self.width)):
            raise ValueError(f'corridor width must be > 0; got {self.width}')
        if self.height is not None and not (self.height > 0 and math.isfinite(self.height)):
            raise ValueError(f'corridor height must be > 0 or None; got {self.height}')

    def lines(self) -> np.ndarray:
        """Return (L, 2) model lines ``(y_line, z_line)`` [m]."""
        out = [(self.width / 2, 0.0), (-self.width / 2, 0.0)]
        if self.centre_line:
            out.append((0.0, 0.0))
        if self.height is not None:
            out += [(self.width / 2, self.height), (-self.width / 2, self.height)]
        return np.array(out)


@dataclass(frozen=True, eq=False)
class LateralEstimate:
    """Lateral position from one image.

    Attributes:
        y: lateral position of ``base_link`` in the corridor frame [m] (left positive).
        std: its standard deviation [m] from the end-point noise of the kept lines.
        y_camera: lateral position of the camera [m].
        estimates: (M,) camera positions of all line/model-line pairs [m].
        estimate_std: (M,) their standard deviations [m].
        segment: (M,) index of the image segment of each pair.
        model_line: (M,) index into :meth:`CorridorModel.lines` of each pair.
        kept: (M,) bool, the pairs left by the farthest-point removal.
    """

    y: float
    std: float
    y_camera: float
    estimates: np.ndarray
    estimate_std: np.ndarray
    segment: np.ndarray
    model_line: np.ndarray
    kept: np.ndarray


def corridor_rotation(direction: Sequence[float]) -> Tuple[np.ndarray, float, float]:
    """Return ``R`` (corridor -> optical frame), ``theta`` and ``alpha`` from the VP (eq. 21)."""
    alpha, theta = eq21_from_direction(direction)
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    # camera body frame (x forward, y left, z up) in the corridor frame: yaw theta, pitch
    # alpha (looking down), no roll
    rz = np.array([[ct, -st, 0.0], [st, ct, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[ca, 0.0, sa], [0.0, 1.0, 0.0], [-sa, 0.0, ca]])
    r_corr_body = rz @ ry
    r_opt_corr = np.asarray(OPTICAL_FROM_BODY) @ r_corr_body.T
    return r_opt_corr, theta, alpha


def _lines_h(seg: np.ndarray) -> np.ndarray:
    p1 = np.column_stack([seg[:, :2], np.ones(len(seg))])
    p2 = np.column_stack([seg[:, 2:], np.ones(len(seg))])
    return np.cross(p1, p2)


def _y_d(seg: np.ndarray, M: np.ndarray, z_d: np.ndarray) -> np.ndarray:
    """Eq. 23: ``y_d`` of segments for their ``z_d`` (``M = R^T K^T``)."""
    m = _lines_h(seg) @ M.T
    with np.errstate(divide='ignore', invalid='ignore'):
        return -z_d * m[:, 2] / m[:, 1]


def lateral_position(segments: np.ndarray, K: np.ndarray, direction: Sequence[float],
                     model: CorridorModel,
                     mount: Sequence[float] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                     prior: Optional[Tuple[float, float]] = None,
                     sigma_px: float = 0.6, gate: float = 3.0) -> LateralEstimate:
    """Return the lateral position from the corridor lines of one image (eqs. 22-23).

    Args:
        segments: (N, 4) ideal pixels of the lines labelled as corridor lines (VP inliers).
        K: (3, 3) intrinsics.
        direction: (3,) corridor VP direction in the optical frame.
        model: corridor geometry.
        mount: camera_link pose in base_link ``[x, y, z, roll, pitch, yaw]``; its z is the
            camera height above the floor; x, y move the estimate from camera to base_link.
        prior: optional ``(mean, std)`` of the robot's lateral position [m] (e.g. the
            filter's prediction), used to weight the estimates.
        sigma_px: end-point noise of a segment [px].
        gate: removal bound in standard deviations.

    Raises:
        ValueError: no segment gives an estimate (names why), or bad arguments.
    """
    seg = np.asarray(segments, dtype=float).reshape(-1, 4)
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 3) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f'K must be a 3x3 intrinsic matrix with fx, fy > 0; got {K}')
    m6 = np.asarray(mount, dtype=float).reshape(-1)
    mount_rotation(m6)                                    # validates the mount
    h = float(m6[2])
    if model.height is not None and not 0.0 < h < model.height:
        raise ValueError(f'camera height {h} m must lie between floor and ceiling '
                         f'({model.height} m)')
    R, theta, _ = corridor_rotation(direction)
    M = R.T @ K.T
    # floor or ceiling: midpoint ray below or above the horizon
    mid = 0.5 * (seg[:, :2] + seg[:, 2:])
    ray = np.column_stack([mid, np.ones(len(seg))]) @ np.linalg.inv(K).T @ R   # corridor
    below = ray[:, 2] < 0
    lines = model.lines()
    half = model.width / 2
    est, est_seg, est_line, z_ds = [], [], [], []
    for k, (y_line, z_line) in enumerate(lines):
        z_d = h - z_line
        cand = below if z_d > 0 else ~below
        idx = np.nonzero(cand)[0]
        if idx.size == 0:
            continue
        y_d = _y_d(seg[idx], M, np.full(idx.size, z_d))
        y_c = y_line + y_d
        ok = np.isfinite(y_c) & (np.abs(y_c) < half)
        est.append(y_c[ok])
        est_seg.append(idx[ok])
        est_line.append(np.full(np.count_nonzero(ok), k))
        z_ds.append(np.full(np.count_nonzero(ok), z_d))
    if not est or sum(e.size for e in est) == 0:
        raise ValueError('no corridor line gives a lateral position inside the corridor')
    est = np.concatenate(est)
    est_seg = np.concatenate(est_seg)
    est_line = np.concatenate(est_line)
    z_ds = np.concatenate(z_ds)
    std = _estimate_std(seg[est_seg], M, z_ds, sigma_px)
    # camera -> base_link offset in the corridor frame (eq. 23 gives the camera's y)
    off = m6[0] * math.sin(theta) + m6[1] * math.cos(theta)
    w = 1.0 / np.maximum(std, 1e-6) ** 2
    if prior is not None:
        mu, sd = float(prior[0]), float(prior[1])
        if not (sd > 0 and math.isfinite(mu)):
            raise ValueError(f'prior must be (mean, std > 0); got {prior}')
        var = sd * sd + std * std
        w = w * np.exp(-0.5 * (est - off - mu) ** 2 / var) / np.sqrt(var)
    kept = np.ones(est.size, dtype=bool)
    if np.sum(w) <= 0:
        w = 1.0 / np.maximum(std, 1e-6) ** 2
    while True:
        mean = np.sum(w[kept] * est[kept]) / np.sum(w[kept])
        mean_sd = 1.0 / math.sqrt(np.sum(1.0 / np.maximum(std[kept], 1e-6) ** 2))
        dev = np.where(kept, np.abs(est - mean) / np.hypot(std, mean_sd), -1.0)
        worst = int(np.argmax(dev))
        if np.count_nonzero(kept) <= 1 or dev[worst] <= gate:
            break
        kept[worst] = False
    return LateralEstimate(y=float(mean - off), std=float(mean_sd), y_camera=float(mean),
                           estimates=est, estimate_std=std, segment=est_seg,
                           model_line=est_line, kept=kept)


def _estimate_std(seg: np.ndarray, M: np.ndarray, z_d: np.ndarray, sigma_px: float,
                  step: float = 0.01) -> np.ndarray:
    """Std of eq. 23's ``y_d`` for independent perpendicular end-point noise (numerically)."""
    d = seg[:, 2:] - seg[:, :2]
    n = np.column_stack([-d[:, 1], d[:, 0]]) / np.maximum(
        np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    y0 = _y_d(seg, M, z_d)
    var = np.zeros(len(seg))
    for end in (0, 1):
        s = seg.copy()
        s[:, 2 * end:2 * end + 2] += step * n
        var += ((_y_d(s, M, z_d) - y0) / step * sigma_px) ** 2
    return np.sqrt(var)
