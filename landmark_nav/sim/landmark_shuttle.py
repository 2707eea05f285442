"""The ``landmark_shuttle`` scenario (visual navigation chapter §2.3.3).

A robot shuttles between a point 1 m and one 3 m in front of a landmark on a wall, driving
on its own estimate (odometry, eqs. 1-7, with the odometry errors of eqs. 17-18) reset by
landmark fixes: :class:`ShuttleConfig` (the set-up and its measured figures),
:func:`shuttle_scene` (the room), :func:`iter_landmark_shuttle` (the run, as
:class:`ShuttleSample`, :class:`~.camera_frames.CameraFrame` and :class:`ShuttleArrival`
events), :func:`robot_pose_from_landmark` and :func:`oracle_localizer` (perfect fixes).
Conventions: :mod:`landmark_nav.sim.camera_scenarios`, the entry point.
"""

from dataclasses import dataclass, replace
import math
import numbers
from typing import Callable, Iterator, List, Optional, Sequence, Tuple, Union

from landmark_nav.geometry import compose, relative, wrap_angle
from landmark_nav.vision.camera import CameraModel, OPTICAL_FROM_BODY
from landmark_nav.vision.landmark import LandmarkDesign
import numpy as np

from . import textures
from .camera import landmark_plane, Photometry, Plane, RenderOptions, rotation_z
from .camera_frames import (_ro, CameraFrame, default_camera, landmark_truth, LandmarkTruth,
                            simulator_for)
from .control import brake_speed, DECEL_MARGIN, limit_twist
from .landmark_views import _place_on_board
from .robot import (measure_wheels, NS_PER_S, propagate_covariance, RobotParams, step_pose,
                    twist_to_wheels, wheel_to_twist)
from .scenarios import START_NS


@dataclass(frozen=True)
class ShuttleConfig:
    """The ``landmark_shuttle`` set-up (visual navigation chapter §2.3.3).

    A 6 m x 4 m room (x in [-1, 5], y in [-2, 2]); the landmark hangs on the wall x = 5,
    facing -x, its centre at ``(5 - 0.003, 0, landmark_height)``. The robot shuttles between
    ``near_point`` (1 m in front of the landmark, facing it) and ``far_point`` (3 m), turning
    in place at both ends (alternately counter-clockwise and clockwise), driving and turning
    on its own pose estimate: odometry (eqs. 1-7 with the wheel radii and axle the robot
    believes in, ``odometry_factors``) composed with the last landmark fix. The true robot
    moves with the systematic errors k1, k2, k3 of :class:`RobotParams` (eqs. 17-18) and
    noisy encoders, so its odometry drifts.

    Measured with perfect fixes (:func:`oracle_localizer`), seed 1, 100 trips: a calibrated
    robot (default, odometry factors = the true k1, k2, k3; only the encoder noise is left)
    arrives within 6.0 cm of the near point (95 % within 3.2 cm, mean 1.5 cm; without fixes
    28 cm off after 100 trips); an uncalibrated one (``odometry_factors=(1, 1, 1)``) within
    16.5 cm (mean 11.4 cm; 1.9 m off after 100 trips without fixes) -- the chapter reports
    10 cm. The arrival error is the odometry drift of one round trip: a landmark detector
    cannot do better than the oracle (stop-only procedure, the chapter's).

    With ``fix_while_driving`` the robot also takes fixes on the way back: one standing at
    the far point once it has turned to face the landmark, then frames at
    ``approach_image_rate`` while it drives to the near point (facing the landmark, turning
    motion blurred as any moving frame). Each fix corrects the estimate the robot steers and
    stops on, so the arrival error is the drift of the last few centimetres plus the fix
    error instead of the drift of a whole round trip. Measured with the landmark detector and
    the EKF of :mod:`landmark_nav.vision.localize` (2 Hz, 100 trips): max 1.8 cm (seed 1),
    0.9 cm (seed 2), 1.3 cm (seed 3); with perfect fixes 0.2 cm (seed 2).

    Attributes:
        trips: number of round trips (near -> far -> near).
        robot: robot and odometry error parameters.
        camera: camera model (default :func:`default_camera`).
        mount: (x, y, z) of the optical centre in ``base_link`` [m]; the camera looks along
            the robot's x axis (optical = ``OPTICAL_FROM_BODY`` of base_link).
        landmark_height: height of the landmark centre above the floor [m].
        code: the landmark's code.
        design: landmark design.
        near_distance: distance of the near point from the wall [m] (1 m, the chapter's).
        far_distance: distance of the far point from the wall [m] (3 m).
        stop_frames: frames taken while standing at the near point (landmark fixes).
        stop_seconds: standing time at the near point [s].
        image_rate: camera rate while moving [Hz] (0 = images only at the stops).
        exposure_time: exposure [s] for the motion blur of the turning robot.
        photometry: base photometry of every frame (noise, gamma ...).
        odometry_factors: (k1, k2, k3) the robot's odometry believes in; None (default) =
            the true ones of ``robot`` (a calibrated robot), (1, 1, 1) = uncalibrated.
        fix_while_driving: also take landmark fixes at the far point (after turning to the
            landmark) and while approaching the near point; False (default) = fixes only
            while standing at the near point (the chapter's procedure).
        approach_image_rate: camera rate [Hz] while approaching the near point with
            ``fix_while_driving`` (replaces ``image_rate`` there; 0 = only the far-point
            frame).
    """

    trips: int = 100
    robot: RobotParams = RobotParams()
    camera: Optional[CameraModel] = None
    mount: Tuple[float, float, float] = (0.10, 0.0, 0.40)
    landmark_height: float = 0.40
    code: int = 156
    design: LandmarkDesign = LandmarkDesign()
    near_distance: float = 1.0
    far_distance: float = 3.0
    stop_frames: int = 3
    stop_seconds: float = 1.0
    image_rate: float = 1.0
    exposure_time: float = 0.01
    photometry: Photometry = Photometry(gamma=2.2, noise_sigma=2.0, shot_noise=0.02)
    odometry_factors: Optional[Tuple[float, float, float]] = None
    fix_while_driving: bool = False
    approach_image_rate: float = 2.0

    WALL_X = 5.0

    def __post_init__(self) -> None:
        """Validate the camera rates."""
        for name in ('image_rate', 'approach_image_rate'):
            v = getattr(self, name)
            if not (isinstance(v, numbers.Real) and math.isfinite(v) and v >= 0):
                raise ValueError(f'ShuttleConfig.{name} must be a finite rate >= 0 [Hz]; '
                                 f'got {v!r}')

    @property
    def believed_factors(self) -> Tuple[float, float, float]:
        """Return the (k1, k2, k3) the robot's odometry uses (the true ones if None)."""
        if self.odometry_factors is None:
            return (self.robot.k1, self.robot.k2, self.robot.k3)
        return tuple(float(v) for v in self.odometry_factors)

    @property
    def near_point(self) -> np.ndarray:
        """Robot pose (x, y, yaw) at the near point, facing the landmark."""
        return np.array([self.WALL_X - self.near_distance, 0.0, 0.0])

    @property
    def far_point(self) -> np.ndarray:
        """Robot position (x, y, yaw) of the far point, facing the landmark."""
        return np.array([self.WALL_X - self.far_distance, 0.0, 0.0])

    @property
    def landmark_rotation(self) -> np.ndarray:
        """World-from-landmark rotation (the landmark faces -x)."""
        return rotation_z(math.pi)

    @property
    def landmark_position(self) -> np.ndarray:
        """World position of the landmark centre [m]."""
        return np.array([self.WALL_X - 0.003, 0.0, self.landmark_height])

    def camera_model(self) -> CameraModel:
        """Return the camera model in use."""
        return self.camera if self.camera is not None else default_camera()

    def camera_pose(self, pose: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
        """Return (world-from-optical rotation, optical centre) for a robot pose (x, y, yaw)."""
        x, y, yaw = (float(v) for v in pose)
        Rz = rotation_z(yaw)
        return Rz @ OPTICAL_FROM_BODY.T, np.array([x, y, 0.0]) + Rz @ np.asarray(self.mount)


def shuttle_scene(config: ShuttleConfig, seed: int) -> List[Plane]:
    """Return the planes of the shuttle room: floor, four walls, landmark, wall posters."""
    rng = np.random.default_rng([int(seed), 0, 7])
    x0, x1, y0, y1, hgt = -1.0, config.WALL_X, -2.0, 2.0, 2.5
    planes = []
    floor = textures.floor_tiles(rng, 20, 30, 30)  # 0.2 m tiles of 30 texels + 1 grout
    mpt = 0.2 / 31.0
    # floor: normal +z, texture right = +x, texture up = +y; cropped to the room
    floor = floor[:int((y1 - y0) / mpt), :int((x1 - x0) / mpt)]
    R_floor = np.column_stack([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    planes.append(Plane(floor, mpt, R_floor,
                        [0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0], label='floor', detail=False))

    def wall(normal_yaw: float, centre_xy: Tuple[float, float], length: float) -> Plane:
        n = 300
        tex = textures.wall(rng, (int(n * hgt / length), n), mean=float(rng.uniform(170, 220)))
        R = rotation_z(normal_yaw)
        return Plane(tex, length / n, R, [centre_xy[0], centre_xy[1], 0.5 * tex.shape[0]
                                          * length / n], label='wall', detail=False)

    planes.append(wall(math.pi, (x1, 0.0), y1 - y0))  # landmark wall, faces -x
    planes.append(wall(0.0, (x0, 0.0), y1 - y0))
    planes.append(wall(0.5 * math.pi, (0.5 * (x0 + x1), y0), x1 - x0))
    planes.append(wall(-0.5 * math.pi, (0.5 * (x0 + x1), y1), x1 - x0))
    R_lm = config.landmark_rotation
    planes.append(landmark_plane(config.code, config.design, R_lm, config.landmark_position))
    # a few distractors on the landmark wall, clear of the landmark
    board_R = R_lm
    board_t = np.array([x1 - 0.002, 0.0, config.landmark_height])
    keep = [(0.0, 0.0, 0.5 * config.design.printed_width * math.sqrt(2.0) + 0.05)]
    for kind in ('poster', 'checkerboard', 'text', 'grid'):
        p = _place_on_board(rng, board_R, board_t, keep, 0.7, 0.0, kind)
        if p is not None and np.all(p.to_world(p.local_corners())[:, 2] > 0.05):
            planes.append(p)
    return planes


def robot_pose_from_landmark(rotation: np.ndarray, translation: np.ndarray,
                             landmark_rotation: np.ndarray, landmark_position: np.ndarray,
                             mount: Sequence[float]) -> np.ndarray:
    """Return the robot pose (x, y, yaw) implied by a landmark seen at (rotation, translation).

    Args:
        rotation: (3, 3) optical-from-landmark rotation (a detection or the truth).
        translation: (3,) landmark centre in the optical frame.
        landmark_rotation: (3, 3) world-from-landmark rotation (the landmark map).
        landmark_position: (3,) landmark centre in the world.
        mount: (x, y, z) of the optical centre in base_link (camera looking along x).

    The 3-D robot pose ``world_from_base = world_from_landmark * inv(optical_from_landmark) *
    inv(base_from_optical)`` is projected to the floor (yaw of its x axis).
    """
    R_wl = np.asarray(landmark_rotation, dtype=float)
    t_wl = np.asarray(landmark_position, dtype=float)
    R_ol = np.asarray(rotation, dtype=float)
    t_ol = np.asarray(translation, dtype=float)
    R_wo = R_wl @ R_ol.T
    t_wo = t_wl - R_wo @ t_ol
    R_bo = OPTICAL_FROM_BODY.T
    R_wb = R_wo @ R_bo.T
    t_wb = t_wo - R_wb @ np.asarray(mount, dtype=float)
    return np.array([t_wb[0], t_wb[1], math.atan2(R_wb[1, 0], R_wb[0, 0])])


@dataclass(frozen=True, eq=False)
class ShuttleSample:
    """Robot state at one control step (10 Hz) of ``landmark_shuttle``.

    Attributes:
        stamp_ns: stamp [ns].
        true_pose: (3,) true pose in the world (map) frame, yaw wrapped.
        odom_pose: (3,) raw wheel odometry (odom frame == world at the start), yaw wrapped.
        odom_covariance: (3, 3) odometry covariance (grows without bound).
        estimate: (3,) the robot's own estimate: odometry composed with the last fix.
        true_twist: (2,) true (v, w) of the step that ends here.
        odom_twist: (2,) (v, w) from the measured wheel speeds of that step.
        wheel_positions: (2,) measured accumulated wheel angles [rad].
        wheel_velocities: (2,) measured wheel speeds [rad/s] of that step.
    """

    stamp_ns: int
    true_pose: np.ndarray
    odom_pose: np.ndarray
    odom_covariance: np.ndarray
    estimate: np.ndarray
    true_twist: np.ndarray
    odom_twist: np.ndarray
    wheel_positions: np.ndarray
    wheel_velocities: np.ndarray


@dataclass(frozen=True, eq=False)
class ShuttleArrival:
    """The robot stopped at the near point (believing it is there), before the fix.

    Attributes:
        trip: 0 for the start, then 1..trips.
        stamp_ns: stamp of the arrival [ns].
        true_pose: (3,) where the robot really is.
        estimate: (3,) where it believes it is (near point up to the stop tolerance).
        error: distance true -> near point [m] (the chapter's "position at the one-meter
            point").
        fix: (3,) the landmark fix applied (mean of the stop frames' fixes), or None.
        approach_frames: frames taken at the far point and on the approach since the last
            stop (``fix_while_driving``).
        approach_fixes: landmark fixes applied from them.
    """

    trip: int
    stamp_ns: int
    true_pose: np.ndarray
    estimate: np.ndarray
    error: float
    fix: Optional[np.ndarray]
    approach_frames: int = 0
    approach_fixes: int = 0


ShuttleEvent = Union[ShuttleSample, CameraFrame, ShuttleArrival]
Localizer = Callable[[CameraFrame], Optional[np.ndarray]]


class _ShuttleRobot:
    """Step simulation: true robot (eqs. 17-18), encoders, odometry and the estimate."""

    def __init__(self, config: ShuttleConfig, rng: np.random.Generator, start_ns: int) -> None:
        self.cfg = config
        self.p = config.robot
        self.factors = config.believed_factors
        self.rng = rng
        pose0 = config.near_point
        self.true = pose0.copy()
        self.odom = pose0.copy()
        self.cov = np.zeros((3, 3))
        self.correction = np.zeros(3)  # map <- odom
        self.v = 0.0
        self.w = 0.0
        self.stamp_ns = int(start_ns)
        self.wheel_pos = np.zeros(2)
        self.true_twist = np.zeros(2)
        self.odom_twist = np.zeros(2)
        self.wheel_vel = np.zeros(2)

    @property
    def estimate(self) -> np.ndarray:
        """Return the robot's own pose estimate in the map frame."""
        return compose(self.correction, self.odom)

    def apply_fix(self, fix: np.ndarray) -> None:
        """Reset the estimate to a landmark fix: correction = fix (-) odom."""
        self.correction = compose(fix, relative(self.odom, np.zeros(3)))

    def step(self, v_des: float, w_des: float) -> ShuttleSample:
        p = self.p
        dt = p.sample_time
        v, w = self.v, self.w = limit_twist(p, v_des, w_des, self.v, self.w)
        wl, wr = twist_to_wheels(v, w, p.wheel_radius, p.axle_length)
        cmd = np.array([[float(wl), float(wr)]])
        r, b = p.wheel_radius, p.axle_length
        vt, wt = wheel_to_twist(cmd[:, 0], cmd[:, 1], p.k1 * r, p.k2 * r, p.k3 * b)  # eq. 17-18
        self.true = step_pose(self.true, float(vt[0]), float(wt[0]), dt)
        meas, pos = measure_wheels(cmd, p, self.rng)
        f1, f2, f3 = self.factors
        vo, wo = wheel_to_twist(meas[:, 0], meas[:, 1], f1 * r, f2 * r, f3 * b)  # eqs. 6-7
        new_odom = step_pose(self.odom, float(vo[0]), float(wo[0]), dt)
        self.cov = propagate_covariance(np.vstack([self.odom, new_odom]), vo, wo, dt, p,
                                        self.cov)[-1]
        self.odom = new_odom
        self.wheel_pos = self.wheel_pos + pos[-1]
        self.wheel_vel = meas[0]
        self.true_twist = np.array([float(vt[0]), float(wt[0])])
        self.odom_twist = np.array([float(vo[0]), float(wo[0])])
        self.stamp_ns += p.step_ns
        return self.sample()

    def sample(self) -> ShuttleSample:
        def wrapped(a: np.ndarray) -> np.ndarray:
            return _ro([a[0], a[1], wrap_angle(a[2])])
        return ShuttleSample(stamp_ns=self.stamp_ns, true_pose=wrapped(self.true),
                             odom_pose=wrapped(self.odom), odom_covariance=_ro(self.cov),
                             estimate=wrapped(self.estimate), true_twist=_ro(self.true_twist),
                             odom_twist=_ro(self.odom_twist),
                             wheel_positions=_ro(self.wheel_pos),
                             wheel_velocities=_ro(self.wheel_vel))


def iter_landmark_shuttle(seed: int, config: ShuttleConfig = ShuttleConfig(),
                          localize: Optional[Localizer] = None,
                          render: RenderOptions = RenderOptions(),
                          images: bool = True) -> Iterator[ShuttleEvent]:
    """Run ``landmark_shuttle`` (§2.3.3) and yield its events in time order.

    The robot starts at the near point with a perfect estimate, then for each trip: turns
    to face away (counter-clockwise), drives to the far point, turns back (clockwise),
    drives to the near point and turns to face the landmark -- all on its own estimate --,
    stops (a :class:`ShuttleArrival` with the true position error), takes
    ``stop_frames`` images and, if ``localize`` returns robot poses for them, resets its
    estimate to their mean (a landmark fix). With ``config.fix_while_driving`` it also
    takes a frame standing at the far point once it faces the landmark and frames at
    ``approach_image_rate`` while driving to the near point, and resets its estimate to
    each pose ``localize`` returns for them, right after the frame (the next control step
    steers on it).

    Args:
        seed: non-negative int (encoder noise, image noise, scene textures).
        config: the set-up.
        localize: ``localize(frame) -> (x, y, yaw)`` world pose of the robot implied by the
            frame (e.g. a landmark detection composed with the landmark map, see
            :func:`robot_pose_from_landmark`), or None when nothing was found. Without it
            the robot runs on raw odometry (drift grows without bound).
        render: rendering options.
        images: False skips rendering (no CameraFrames; ``localize`` is then never called).

    Yields:
        :class:`ShuttleSample` every 0.1 s, :class:`CameraFrame` at ``image_rate`` while
        moving (``approach_image_rate`` on the approach with ``fix_while_driving``) and at
        the stops, :class:`ShuttleArrival` at each stop. A frame is yielded before
        ``localize`` sees it, and after the sample of its stamp.
    """
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f'seed must be a non-negative int; got {seed!r}')
    cfg = config
    cam = cfg.camera_model()
    rng_odom = np.random.default_rng([int(seed), 1])
    sim = simulator_for(cam, render) if images else None
    planes = shuttle_scene(cfg, seed) if images else []
    robot = _ShuttleRobot(cfg, rng_odom, START_NS)
    p = cfg.robot
    dt = p.sample_time
    frame_index = [0]
    next_image_ns = [START_NS]
    image_step_ns = int(round(NS_PER_S / cfg.image_rate)) if cfg.image_rate > 0 else 0
    approach_step_ns = int(round(NS_PER_S / cfg.approach_image_rate)) \
        if cfg.approach_image_rate > 0 else 0
    approach = [0, 0]   # frames, fixes since the last stop

    def frame() -> CameraFrame:
        i = frame_index[0]
        frame_index[0] += 1
        R_wc, t_wc = cfg.camera_pose(robot.true)
        ph = cfg.photometry
        blur = abs(robot.true_twist[1]) * cam.fx * cfg.exposure_time
        if blur > 0.05:
            ph = replace(ph, motion_blur=float(blur), motion_angle=0.0)
        img = sim.render(planes, R_wc, t_wc, ph, np.random.default_rng([int(seed), 2, i]))
        img.setflags(write=False)
        R_ol = R_wc.T @ cfg.landmark_rotation
        t_ol = R_wc.T @ (cfg.landmark_position - t_wc)
        truths: Tuple[LandmarkTruth, ...] = ()
        if float(R_ol[:, 0] @ t_ol) < 0 and t_ol[2] > 0:
            truths = (landmark_truth(cfg.code, cfg.design, R_ol, t_ol, cam),)
        return CameraFrame(index=i, stamp_ns=robot.stamp_ns, image=img, camera=cam,
                           landmarks=truths, camera_rotation=_ro(R_wc),
                           camera_position=_ro(t_wc), photometry=ph)

    def drive_fix(f: CameraFrame) -> None:
        # a fix taken on the move resets the estimate the next control step steers on
        approach[0] += 1
        res = localize(f) if localize is not None else None
        if res is not None:
            robot.apply_fix(np.asarray(res, dtype=float).reshape(3))
            approach[1] += 1

    def tick(v: float, w: float, fixing: bool = False) -> Iterator[ShuttleEvent]:
        yield robot.step(v, w)
        step_ns = approach_step_ns if fixing else image_step_ns
        if images and step_ns and robot.stamp_ns >= next_image_ns[0]:
            next_image_ns[0] = robot.stamp_ns + step_ns
            f = frame()
            yield f
            if fixing:
                drive_fix(f)

    def turn_rate(err: float) -> float:
        mag = min(p.max_angular_speed,
                  brake_speed(abs(err), DECEL_MARGIN * p.max_angular_accel, dt),
                  abs(err) / dt)
        return math.copysign(mag, err)

    def turn_to(heading: float, direction: int) -> Iterator[ShuttleEvent]:
        th = robot.estimate[2]
        e0 = (heading - th) % (2 * math.pi) if direction > 0 else \
            -((th - heading) % (2 * math.pi))
        target = th + e0
        th_unwrapped = th
        for _ in range(5000):
            err = target - th_unwrapped
            if abs(err) < 1e-3 and abs(robot.w) < 1e-3:
                break
            prev = robot.estimate[2]
            yield from tick(0.0, turn_rate(err))
            th_unwrapped += math.remainder(robot.estimate[2] - prev, 2 * math.pi)
        yield from brake()

    def go_to(target: np.ndarray, fixing: bool = False) -> Iterator[ShuttleEvent]:
        for _ in range(20000):
            est = robot.estimate
            dx, dy = target[0] - est[0], target[1] - est[1]
            dist = math.hypot(dx, dy)
            heading = math.atan2(dy, dx)
            along = dx * math.cos(est[2]) + dy * math.sin(est[2])
            if dist < 0.005 or along <= 0.0:
                break
            err = math.remainder(heading - est[2], 2 * math.pi)
            v = min(p.max_linear_speed,
                    brake_speed(along, DECEL_MARGIN * p.max_linear_accel, dt), along / dt)
            w = 0.0 if dist < 0.15 else max(-p.max_angular_speed,
                                            min(p.max_angular_speed, 2.0 * err))
            yield from tick(v * max(0.0, math.cos(err)), w, fixing)
        yield from brake(fixing)

    def brake(fixing: bool = False) -> Iterator[ShuttleEvent]:
        while abs(robot.v) > 1e-9 or abs(robot.w) > 1e-9:
            yield from tick(0.0, 0.0, fixing)

    def approach_near() -> Iterator[ShuttleEvent]:
        fixing = bool(cfg.fix_while_driving and images)
        if fixing:   # standing at the far point, facing the landmark
            f = frame()
            yield f
            drive_fix(f)
            next_image_ns[0] = robot.stamp_ns + approach_step_ns
        yield from go_to(cfg.near_point, fixing)
        if fixing:
            next_image_ns[0] = robot.stamp_ns + image_step_ns

    def stop(trip: int) -> Iterator[ShuttleEvent]:
        true = robot.true.copy()
        near = cfg.near_point
        fixes = []
        n_wait = int(round(cfg.stop_seconds / dt))
        shots = set(np.linspace(0, max(n_wait - 1, 0), cfg.stop_frames).round().astype(int)) \
            if images and cfg.stop_frames > 0 else set()
        frames = []
        for k in range(n_wait):
            yield robot.step(0.0, 0.0)
            if k in shots:
                f = frame()
                frames.append(f)
                yield f
        if localize is not None:
            for f in frames:
                res = localize(f)
                if res is not None:
                    fixes.append(np.asarray(res, dtype=float).reshape(3))
        fix = None
        if fixes:
            arr = np.array(fixes)
            yaw = math.atan2(np.sin(arr[:, 2]).mean(), np.cos(arr[:, 2]).mean())
            fix = np.array([arr[:, 0].mean(), arr[:, 1].mean(), yaw])
            robot.apply_fix(fix)
        yield ShuttleArrival(trip=trip, stamp_ns=robot.stamp_ns, true_pose=_ro(
            [true[0], true[1], wrap_angle(true[2])]), estimate=_ro(robot.sample().estimate),
            error=float(math.hypot(true[0] - near[0], true[1] - near[1])),
            fix=None if fix is None else _ro(fix), approach_frames=approach[0],
            approach_fixes=approach[1])
        approach[:] = [0, 0]

    yield robot.sample()
    if images and image_step_ns:
        next_image_ns[0] = robot.stamp_ns + image_step_ns
    yield from stop(0)
    for trip in range(1, int(cfg.trips) + 1):
        yield from turn_to(math.pi, 1)
        yield from go_to(cfg.far_point)
        yield from turn_to(0.0, -1)
        yield from approach_near()
        yield from turn_to(0.0, 1 if math.remainder(robot.estimate[2], 2 * math.pi) < 0 else -1)
        yield from stop(trip)


def oracle_localizer(config: ShuttleConfig, sigma_xy: float = 0.0, sigma_yaw: float = 0.0,
                     seed: int = 0) -> Localizer:
    """Return a localizer that reads the true robot pose from the frame (+ Gaussian noise).

    For testing the scenario mechanics without a detector: the pose is recovered from the
    frame's camera pose with the mount, i.e. exactly what a perfect landmark fix gives.
    Frames without an in-view landmark give None.
    """
    rng = np.random.default_rng([int(seed), 99])

    def localize(frame: CameraFrame) -> Optional[np.ndarray]:
        if not frame.landmarks or not frame.landmarks[0].in_view:
            return None
        lt = frame.landmarks[0]
        pose = robot_pose_from_landmark(lt.rotation, lt.translation, config.landmark_rotation,
                                        config.landmark_position, config.mount)
        return pose + rng.normal(0.0, 1.0, 3) * [sigma_xy, sigma_xy, sigma_yaw]

    return localize


__all__ = ['iter_landmark_shuttle', 'oracle_localizer', 'robot_pose_from_landmark',
           'ShuttleArrival', 'ShuttleConfig', 'ShuttleSample', 'shuttle_scene']
