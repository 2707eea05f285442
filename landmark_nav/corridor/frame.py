"""One camera frame -> corridor heading and lateral position (the per-frame pipeline, §3.1).

Image lines (:mod:`landmark_nav.vision.image_lines`, undistorted with the camera model),
the corridor vanishing point (:func:`~.vanishing_point.corridor_vanishing_point`: the
Manhattan direction closest to the optical axis), heading and tilt (eq. 21,
:mod:`.orientation`) and the lateral position from the corridor lines (eqs. 22-23,
:mod:`.lateral`). The node and the offline evaluation call :func:`measure_frame`.

Standard deviations: the heading's from the VP direction, in two modes
(:mod:`.vp_confidence`): correct, with the first-order covariance of the direction
(end-point noise), and wrong, with the spread of wrong directions; the filter weighs the two
(:meth:`.fusion.CorridorEKF.update`) by the probability that the direction is correct: 1 for
a confident direction (its rare errors are left to the filter's innovation gate),
``p_correct`` otherwise. The lateral
position's from :mod:`.lateral`; both are floored by :attr:`FrameParams.heading_std_floor`
and :attr:`FrameParams.lateral_std_floor` for what the line noise model leaves out (the
chapter: single frames off by 10-15 cm now and then, "a higher standard deviation for the
assumed measured error").

Failures raise :class:`CorridorLost` with the reason (no lines, no VP, VP too far off the
optical axis, no lateral estimate).
"""

from dataclasses import dataclass, field
import math
from typing import Optional, Sequence, Tuple

from landmark_nav.corridor.lateral import CorridorModel, lateral_position, LateralEstimate
from landmark_nav.corridor.orientation import corridor_orientation, CorridorOrientation
from landmark_nav.corridor.vanishing_point import manhattan_frame, VanishingPoint, VPParams
from landmark_nav.corridor.vp_confidence import assess_frame, DirectionConfidence
from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.image_lines import (detect_lines, ImageLines, LineParams,
                                             undistort_segments)
import numpy as np


class CorridorLost(ValueError):
    """No corridor estimate from this frame (the message says why)."""


@dataclass(frozen=True)
class FrameParams:
    """Parameters of the per-frame pipeline.

    Attributes:
        line_method: ``'segmented_hough'`` (the chapter), ``'hough_p'`` or ``'lsd'``.
        lines: line detector parameters.
        vp: vanishing-point parameters.
        max_axis_angle_deg: the corridor VP must lie within this angle of the camera's
            forward direction [deg] (a forward-looking camera in a corridor).
        min_corridor_lines: fewer corridor lines -> lost (3: two lines always meet
            somewhere, a third one confirms the VP).
        heading_std_floor: added in quadrature to the heading std [rad].
        lateral_std_floor: added in quadrature to the lateral std [m].
    """

    line_method: str = 'segmented_hough'
    lines: LineParams = field(default_factory=LineParams)
    vp: VPParams = field(default_factory=VPParams)
    max_axis_angle_deg: float = 45.0
    min_corridor_lines: int = 3
    heading_std_floor: float = math.radians(0.3)
    lateral_std_floor: float = 0.02


@dataclass(frozen=True, eq=False)
class CorridorMeasurement:
    """The visual measurement of one frame (eq. 24's ``z``) with its parts.

    Attributes:
        heading: robot heading relative to the corridor [rad] (``theta_v``).
        heading_std: its standard deviation [rad].
        y: lateral position of base_link [m] (``y_v``).
        y_std: its standard deviation [m].
        vp: the corridor vanishing point (ideal pixels).
        confidence: its support, calibrated uncertainty and confident flag.
        p_correct: probability the filter gives the VP direction of being correct: 1 when
            confident, else ``confidence.p_correct`` (module docstring).
        heading_std_wrong: the heading's std if it is not (the wrong mode's spread) [rad].
        orientation: heading, tilt and elevation (eq. 21, mount).
        lateral: the line matching and lateral estimate.
        lines: the undistorted image lines.
    """

    heading: float
    heading_std: float
    y: float
    y_std: float
    vp: VanishingPoint
    confidence: DirectionConfidence
    p_correct: float
    heading_std_wrong: float
    orientation: CorridorOrientation
    lateral: LateralEstimate
    lines: ImageLines

    @property
    def covariance(self) -> np.ndarray:
        """Return the (2, 2) covariance of ``(heading, y)`` (taken as uncorrelated)."""
        return np.diag([self.heading_std ** 2, self.y_std ** 2])

    @property
    def wrong_covariance(self) -> np.ndarray:
        """Return the (2, 2) covariance of ``(heading, y)`` if the direction is wrong."""
        return np.diag([self.heading_std_wrong ** 2, self.y_std ** 2])

    @property
    def mixture_covariance(self) -> np.ndarray:
        """Return the moment-matched (2, 2) covariance of the two modes."""
        p = self.p_correct
        return p * self.covariance + (1.0 - p) * self.wrong_covariance


def _heading_std(vp: VanishingPoint, cov: np.ndarray, mount: Sequence[float]) -> float:
    """Propagate a (3, 3) direction covariance to the heading (numerical gradient)."""
    if not np.all(np.isfinite(cov)):
        return math.inf
    h0 = corridor_orientation(vp.direction, mount).heading
    grad = np.zeros(3)
    eps = 1e-7
    for k in range(3):
        d = vp.direction.copy()
        d[k] += eps
        grad[k] = (corridor_orientation(d, mount).heading - h0) / eps
    return float(math.sqrt(max(grad @ cov @ grad, 0.0)))


def measure_frame(image: np.ndarray, camera: CameraModel, model: CorridorModel,
                  mount: Sequence[float],
                  prior: Optional[Tuple[float, float]] = None,
                  params: FrameParams = FrameParams()) -> CorridorMeasurement:
    """Return heading and lateral position from one image.

    Args:
        image: (H, W) grey or BGR image of ``camera`` (same size).
        camera: the calibrated camera (lines are undistorted with it).
        model: corridor width, height, centre line.
        mount: camera_link pose in base_link ``[x, y, z, roll, pitch, yaw]``.
        prior: optional ``(mean, std)`` of the lateral position (the filter's prediction).
        params: see :class:`FrameParams`.

    Raises:
        CorridorLost: no estimate from this frame (the reason in the message).
        ValueError: an image whose size differs from the camera's.
    """
    img = np.asarray(image)
    if img.ndim < 2 or img.shape[:2] != (camera.height, camera.width):
        raise ValueError(f'image size {img.shape[:2][::-1]} differs from the camera '
                         f'({camera.width} x {camera.height})')
    lines = undistort_segments(detect_lines(img, params.line_method, params.lines), camera)
    if len(lines) < 2:
        raise CorridorLost(f'{len(lines)} image lines')
    K = camera.K
    try:
        frame = manhattan_frame(lines.segments, K, lines.weights, params.vp)
    except ValueError as err:
        raise CorridorLost(f'no vanishing point: {err}') from None
    vp = frame.points[0]            # the corridor: the direction closest to the optical axis
    axis = math.degrees(math.acos(min(1.0, abs(float(vp.direction[2])))))
    if axis > params.max_axis_angle_deg:
        raise CorridorLost(f'vanishing point {axis:.0f} deg off the optical axis '
                           f'(> {params.max_axis_angle_deg:.0f})')
    n_in = int(np.count_nonzero(vp.inliers))
    if n_in < params.min_corridor_lines:
        raise CorridorLost(f'{n_in} corridor lines (< {params.min_corridor_lines})')
    orient = corridor_orientation(vp.direction, mount)
    try:
        lat = lateral_position(lines.segments[vp.inliers], K, vp.direction, model, mount,
                               prior, params.vp.sigma_px)
    except ValueError as err:
        raise CorridorLost(f'no lateral position: {err}') from None
    conf = assess_frame(frame, lines.segments, K, params.vp.sigma_px, gate=params.vp.gate,
                        sigma_angle_deg=params.vp.sigma_angle_deg)[0]
    h_std = _heading_std(vp, conf.first_order, mount)
    return CorridorMeasurement(
        heading=orient.heading, heading_std=math.hypot(h_std, params.heading_std_floor),
        y=lat.y, y_std=math.hypot(lat.std, params.lateral_std_floor), vp=vp,
        confidence=conf, p_correct=1.0 if conf.confident else conf.p_correct,
        heading_std_wrong=_heading_std(vp, conf.wrong_covariance, mount),
        orientation=orient, lateral=lat, lines=lines)
