"""The corridor follower's estimation loop: frames and odometry in, fused pose out.

One object, :class:`CorridorTracker`, holds what the ``corridor_follower`` node does with
its inputs besides publishing: a frame goes through :func:`~.frame.measure_frame` (prior:
the filter's predicted lateral position) and starts the EKF (:class:`~.fusion.CorridorEKF`)
on the first measurement or updates it; an odometry pose predicts the EKF with the
increment from the previous one. The node (:mod:`landmark_nav.nodes.corridor_follower`)
and the offline bag evaluation (:mod:`landmark_nav.evaluation.corridor_bag`, ``landmark_nav
evaluate-corridor``) both drive it, so that they publish / score the same poses.

:class:`FollowerConfig` holds the estimation parameters with the node's defaults (the node
declares its parameters with these defaults).
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

from landmark_nav.corridor.frame import CorridorLost, CorridorMeasurement, FrameParams, \
    measure_frame
from landmark_nav.corridor.fusion import CorridorEKF, DeadReckoningNoise
from landmark_nav.corridor.lateral import CorridorModel
from landmark_nav.corridor.vanishing_point import VPParams
from landmark_nav.geometry import relative, wrap_angle
from landmark_nav.vision.camera import CameraModel
import numpy as np


@dataclass(frozen=True)
class FollowerConfig:
    """Estimation parameters of the corridor follower (names and defaults of the node's).

    Attributes:
        corridor_width: wall-to-wall width [m].
        corridor_height: floor-to-ceiling height [m]; 0: ceiling edges not used.
        centre_line: the floor has a line along the corridor centre.
        camera_mount: camera_link in base_link ``[x, y, z, roll, pitch, yaw]``.
        line_method: ``segmented_hough``, ``hough_p`` or ``lsd``.
        sigma_px: end-point noise of image line segments [px].
        sigma_angle_deg: direction noise of a segment beyond its end-point noise [deg].
        heading_std_floor_deg: added to the visual heading std [deg].
        lateral_std_floor: added to the visual lateral std [m].
        max_axis_angle_deg: the corridor VP must lie within this angle of the optical axis.
        wheel_separation: effective wheel separation [m].
        k_left: left wheel distance variance per metre [m^2/m].
        k_right: right wheel distance variance per metre [m^2/m].
        sigma_separation: std of the wheel separation per step [m].
        gate_chi2: NIS outlier gate (chi-square 2 dof).
    """

    corridor_width: float = 2.0
    corridor_height: float = 2.6
    centre_line: bool = False
    camera_mount: Tuple[float, ...] = (0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    line_method: str = 'segmented_hough'
    sigma_px: float = 0.6
    sigma_angle_deg: float = 0.38
    heading_std_floor_deg: float = 0.3
    lateral_std_floor: float = 0.02
    max_axis_angle_deg: float = 45.0
    wheel_separation: float = 0.33
    k_left: float = 1e-4
    k_right: float = 1e-4
    sigma_separation: float = 0.001
    gate_chi2: float = 13.8


@dataclass(frozen=True, eq=False)
class FrameStep:
    """What one frame did.

    Attributes:
        status: ``dropped`` (no camera model yet, or the image size disagrees with it),
            ``lost`` (no corridor in the frame), ``started`` (the first measurement started
            the filter), ``accepted`` or ``rejected`` (by the gate).
        message: why it was dropped or lost.
        measurement: the visual measurement (``started``, ``accepted``, ``rejected``).
        nis: the update's normalised innovation squared (``accepted``, ``rejected``).
    """

    status: str
    message: str = ''
    measurement: Optional[CorridorMeasurement] = None
    nis: float = math.nan

    @property
    def measured(self) -> bool:
        """Return whether the frame gave a measurement (the estimate is then published)."""
        return self.measurement is not None


class CorridorTracker:
    """The follower's filter state: :meth:`frame` per image, :meth:`odometry` per pose."""

    def __init__(self, config: FollowerConfig = FollowerConfig()) -> None:
        """Build the corridor model, frame parameters and odometry noise of ``config``."""
        c = config
        self.config = c
        self.model = CorridorModel(c.corridor_width, c.corridor_height or None, c.centre_line)
        self.mount = [float(v) for v in c.camera_mount]
        vp = VPParams(sigma_px=c.sigma_px, sigma_angle_deg=c.sigma_angle_deg)
        self.params = FrameParams(line_method=c.line_method, vp=vp,
                                  max_axis_angle_deg=c.max_axis_angle_deg,
                                  heading_std_floor=math.radians(c.heading_std_floor_deg),
                                  lateral_std_floor=c.lateral_std_floor)
        self.noise = DeadReckoningNoise(c.wheel_separation, c.k_left, c.k_right,
                                        c.sigma_separation)
        self.gate = c.gate_chi2
        self.ekf: Optional[CorridorEKF] = None
        self.last_odom: Optional[Tuple[int, np.ndarray]] = None     # (stamp_ns, pose)
        self.last_fix_ns: Optional[int] = None
        self.frames = 0

    def frame(self, gray: np.ndarray, camera: Optional[CameraModel], stamp_ns: int) -> FrameStep:
        """Measure heading and lateral position in one mono8 frame and update the filter."""
        if camera is None:
            return FrameStep('dropped', 'no valid CameraInfo received yet')
        if gray.shape != (camera.height, camera.width):
            return FrameStep('dropped', f'size {gray.shape[1]}x{gray.shape[0]} disagrees '
                                        f'with CameraInfo {camera.width}x{camera.height}')
        prior = None if self.ekf is None else self.ekf.visual_prior()
        try:
            m = measure_frame(gray, camera, self.model, self.mount, prior, self.params)
        except CorridorLost as err:
            return FrameStep('lost', str(err))
        if self.ekf is None:
            r = m.mixture_covariance
            self.ekf = CorridorEKF([m.heading, 0.0, m.y], np.diag(
                [r[0, 0], 0.0, r[1, 1]]), self.noise, self.gate)
            step = FrameStep('started', measurement=m)
        else:
            res = self.ekf.update(m.heading, m.y, m.covariance, m.p_correct,
                                  m.wrong_covariance)
            step = FrameStep('accepted' if res.accepted else 'rejected', measurement=m,
                             nis=res.nis)
        if step.status != 'rejected':
            self.last_fix_ns = stamp_ns
        self.frames += 1
        return step

    def odometry(self, stamp_ns: int, pose: Sequence[float]) -> Tuple[str, float]:
        """Predict with the increment from the previous odometry pose ``(x, y, yaw)``.

        Returns:
            ``(status, dt)``: status ``back_in_time`` (the stamp precedes the previous one:
            the increments restart from this pose), ``predicted`` (the filter moved;
            ``dt`` is the time since the previous pose [s]) or ``origin`` (the first pose,
            or no filter yet: only remembered); ``dt`` is 0 unless predicted.
        """
        last = self.last_odom
        status, dt = 'origin', 0.0
        if last is not None and stamp_ns < last[0]:
            status = 'back_in_time'
        elif last is not None and self.ekf is not None:
            inc = relative(last[1], pose)
            self.ekf.predict(float(inc[0]), float(inc[2]))
            status, dt = 'predicted', (stamp_ns - last[0]) * 1e-9
        self.last_odom = (stamp_ns, pose)
        return status, dt

    def fresh(self, stamp_ns: int, stale_timeout: float) -> bool:
        """Return whether a visual update was accepted within ``stale_timeout`` [s]."""
        return (self.ekf is not None and self.last_fix_ns is not None
                and (stamp_ns - self.last_fix_ns) * 1e-9 <= stale_timeout)

    def steering_errors(self) -> Tuple[float, float]:
        """Return heading and lateral position relative to the direction of travel.

        Both are 0 without a filter.
        """
        if self.ekf is None:
            return 0.0, 0.0
        th, y = float(self.ekf.s[0]), self.ekf.visual_prior()[0]
        if self.ekf.facing_back:
            th = wrap_angle(th - math.pi)
        return th, y

    def estimate(self) -> Tuple[List[float], np.ndarray]:
        """Return the pose ``[x, y, yaw]`` in the corridor frame and its (3, 3) covariance."""
        th, x, y = self.ekf.state
        order = [1, 2, 0]                                   # (x, y, yaw) from (theta, x, y)
        return [x, y, th], self.ekf.p[np.ix_(order, order)]
