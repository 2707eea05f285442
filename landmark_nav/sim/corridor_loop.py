"""The closed loop through the ``corridor_follower`` node: a simulated robot that obeys cmd_vel.

A ROS node (``corridor_sim``) stands in for the robot and its camera in the rendered
corridor (:mod:`landmark_nav.sim.corridor`). In lock step with the follower, on simulation
time (so that the figures do not depend on the machine's speed):

1. every ``1 / odom_rate`` s it publishes the measured (drifting) wheel odometry on
   ``odom`` and the true pose on ``ground_truth/odom``; every ``1 / camera_rate`` s, just
   before, ``camera/camera_info`` and a frame rendered from the true pose on
   ``camera/image_raw`` (mono8);
2. it waits for the follower's ``cmd_vel`` (geometry_msgs/TwistStamped, the follower with
   ``stamped_cmd_vel: true``) stamped with that odometry message, and drives the true
   robot with it for one period: the commanded wheel distances are what the odometry
   measures, the true ones differ by Kleeman noise and a scale error of the right wheel.

As a mission supervisor would, it drives ``lengths`` lengths of ``distance`` metres back
and forth: at each end (by its odometry distance, or earlier when the follower has held
the robot still for ``stall_seconds`` after it had moved on this leg: the follower stops
when it loses the corridor, e.g. within a few metres of an open end) it disables the follower
(``corridor_follower/enable``, std_srvs/SetBool), turns the robot on the spot by pi on
its odometry heading, waiting meanwhile for the follower's ``corridor/pose`` after each
odometry message, and enables it again.

The node under test runs anywhere on the DDS domain (another process, another machine);
only the topic and service names connect them.
"""

from dataclasses import dataclass, field
import math
import threading
import time
from typing import Dict, List, Optional, Tuple

from geometry_msgs.msg import PoseWithCovarianceStamped, TwistStamped
from landmark_nav.conversions import (array_to_image, make_camera_info, make_odometry,
                                      stamp_to_ns)
from landmark_nav.geometry import wrap_angle
from landmark_nav.sim.camera import CameraSimulator, Photometry
from landmark_nav.sim.corridor import (corridor_scene, corridor_view, CorridorConfig,
                                       default_corridor_camera)
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import SetBool


@dataclass(frozen=True)
class LoopConfig:
    """A closed-loop corridor run.

    Attributes:
        corridor: the rendered corridor.
        mount: camera_link in base_link ``[x, y, z, roll, pitch, yaw]`` (the follower's
            ``camera_mount`` must be the same).
        start: true start ``(x, y, theta)`` in the corridor frame.
        distance: length of one leg (odometry distance) [m].
        lengths: legs driven, turning on the spot at the ends in between.
        odom_rate: odometry messages per second of simulation time.
        camera_rate: frames per second.
        downscale: the camera at 640 x 480 / downscale.
        k_wheel: true wheel distance variance per metre [m^2/m] (Kleeman).
        right_scale_error: true right wheel distance = measured / (1 + error).
        wheel_separation: [m].
        turn_speed: angular speed of the turns at the ends [rad/s].
        robot_radius: radius of the robot's footprint, for the wall clearance [m].
        photometry: image noise and blur.
        stall_seconds: a leg ends when the follower held the robot still this long after
            it had moved on the leg [s of simulation time].
        start_timeout: give up when the robot has not moved this long after the start or
            a turn [s of simulation time].
        step_timeout: longest wait for the follower's answer to one message [s] (wall).
        follower: the follower node's name (its service ``<follower>/enable``).
    """

    corridor: CorridorConfig = field(default_factory=CorridorConfig)
    mount: Tuple[float, ...] = (0.1, 0.0, 1.1, 0.0, math.radians(5.0), 0.0)
    start: Tuple[float, float, float] = (1.0, 0.15, math.radians(4.0))
    distance: float = 27.0
    lengths: int = 3
    odom_rate: float = 20.0
    camera_rate: float = 5.0
    downscale: int = 2
    k_wheel: float = 2e-5
    right_scale_error: float = 0.01
    wheel_separation: float = 0.33
    turn_speed: float = 0.5
    robot_radius: float = 0.25
    photometry: Photometry = field(default_factory=lambda: Photometry(noise_sigma=2.0,
                                                                      defocus_sigma=0.5))
    stall_seconds: float = 2.0
    start_timeout: float = 20.0
    step_timeout: float = 30.0
    follower: str = 'corridor_follower'


@dataclass(frozen=True, eq=False)
class LoopResult:
    """Per odometry step of a closed-loop run (arrays of equal length).

    Attributes:
        truth: (K, 3) true pose ``(x, y, theta)`` when the odometry message was sent.
        command: (K, 2) the ``(v, omega)`` driven for the step that followed.
        turning: (K,) bool: steps of the turns at the ends (the follower disabled).
        estimate: (K, 3) the follower's ``corridor/pose`` ``(x, y, yaw)`` received for the
            step (NaN when none came).
        legs: odometry distance of each leg [m].
        wall_seconds: wall-clock time of the run.
        config: the run's configuration.
    """

    truth: np.ndarray
    command: np.ndarray
    turning: np.ndarray
    estimate: np.ndarray
    legs: Tuple[float, ...]
    wall_seconds: float
    config: LoopConfig

    def summary(self) -> Dict[str, float]:
        """Return the lateral figures [m], the wall clearance [m] and counts."""
        c = self.config
        y = self.truth[:, 1]
        path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(self.truth[:, :2], axis=0).T))])
        after = path >= 2.0
        drive = ~self.turning
        clearance = c.corridor.width / 2 - np.abs(y) - c.robot_radius
        return {'steps': float(len(y)), 'frames': float(np.ceil(len(y) * c.camera_rate
                                                                / c.odom_rate)),
                'path_m': float(path[-1]),
                'max_abs_lateral': float(np.max(np.abs(y))),
                'max_abs_lateral_after_2m': float(np.max(np.abs(y[after]))) if after.any()
                else math.nan,
                'rms_lateral_after_2m': float(np.sqrt(np.mean(y[after & drive] ** 2)))
                if (after & drive).any() else math.nan,
                'min_wall_clearance': float(np.min(clearance)),
                'shortest_leg_m': float(min(self.legs)) if self.legs else math.nan,
                'wall_seconds': self.wall_seconds}


def diff_drive(s: np.ndarray, d_l: float, d_r: float, b: float) -> np.ndarray:
    """Return pose ``s = (x, y, theta)`` moved by wheel distances (midpoint heading)."""
    ds, dth = 0.5 * (d_l + d_r), (d_r - d_l) / b
    a = s[2] + 0.5 * dth
    return np.array([s[0] + ds * math.cos(a), s[1] + ds * math.sin(a), s[2] + dth])


class CorridorLoop:
    """The simulated robot of the closed loop (see the module docstring).

    Create it with a started context, spin :attr:`node` in an executor on another thread,
    then call :meth:`run`.
    """

    def __init__(self, context, config: LoopConfig = LoopConfig(), seed: int = 0) -> None:
        """Build the scene and the node (name ``corridor_sim``)."""
        c = config
        if not (0.0 < c.start[0] and c.distance + c.start[0] <= c.corridor.length - 1.0):
            raise ValueError(f'a {c.distance} m leg from x = {c.start[0]} does not fit the '
                             f'{c.corridor.length} m corridor (1 m clear of its far end)')
        if abs(c.start[1]) + c.robot_radius >= c.corridor.width / 2:
            raise ValueError(f'a start {c.start[1]} m off the centre line puts the robot '
                             f'(radius {c.robot_radius} m) into a wall')
        self.config = c
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.pixel_rng = np.random.default_rng([seed, 1])
        self.planes = corridor_scene(c.corridor, seed)
        self.camera = default_corridor_camera(c.downscale)
        self.sim = CameraSimulator(self.camera)
        self.node = Node('corridor_sim', context=context)
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        n = self.node
        self.pub_info = n.create_publisher(CameraInfo, 'camera/camera_info', reliable)
        self.pub_image = n.create_publisher(Image, 'camera/image_raw', reliable)
        self.pub_odom = n.create_publisher(Odometry, 'odom', reliable)
        self.pub_truth = n.create_publisher(Odometry, 'ground_truth/odom', reliable)
        self._cond = threading.Condition()
        self._cmds: Dict[int, Tuple[float, float]] = {}
        self._poses: Dict[int, Tuple[float, float, float]] = {}
        n.create_subscription(TwistStamped, 'cmd_vel', self._on_cmd, reliable)
        n.create_subscription(PoseWithCovarianceStamped, 'corridor/pose', self._on_pose,
                              reliable)
        self.enable_client = n.create_client(SetBool, f'{c.follower}/enable')

    # ------------------------------------------------------------------ callbacks
    def _on_cmd(self, msg: TwistStamped) -> None:
        with self._cond:
            self._cmds[stamp_to_ns(msg.header.stamp)] = (msg.twist.linear.x,
                                                         msg.twist.angular.z)
            self._cond.notify_all()

    def _on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        p = msg.pose.pose
        yaw = 2.0 * math.atan2(p.orientation.z, p.orientation.w)
        with self._cond:
            self._poses[stamp_to_ns(msg.header.stamp)] = (p.position.x, p.position.y, yaw)
            self._cond.notify_all()

    def _wait(self, table: Dict, stamp: int, what: str):
        deadline = time.monotonic() + self.config.step_timeout
        with self._cond:
            while stamp not in table:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f'no {what} stamped {stamp * 1e-9:.2f} s from the '
                                       f'follower within {self.config.step_timeout} s')
                self._cond.wait(left)
            return table.pop(stamp)

    def _enable(self, on: bool) -> None:
        if not self.enable_client.wait_for_service(timeout_sec=self.config.step_timeout):
            raise TimeoutError(f'service {self.config.follower}/enable not available')
        future = self.enable_client.call_async(SetBool.Request(data=on))
        deadline = time.monotonic() + self.config.step_timeout
        while not future.done():
            if time.monotonic() > deadline:
                raise TimeoutError(f'{self.config.follower}/enable did not answer')
            time.sleep(0.001)
        if not future.result().success:
            raise RuntimeError(f'{self.config.follower}/enable refused: '
                               f'{future.result().message}')

    def wait_for_follower(self, timeout: float = 30.0) -> None:
        """Wait until the follower subscribes to the sensors and offers its service."""
        pubs = (self.pub_info, self.pub_image, self.pub_odom)
        deadline = time.monotonic() + timeout
        while not all(p.get_subscription_count() > 0 for p in pubs):
            if time.monotonic() > deadline:
                raise TimeoutError('the follower did not subscribe to camera/image_raw, '
                                   'camera/camera_info and odom')
            time.sleep(0.01)
        if not self.enable_client.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f'service {self.config.follower}/enable not available')

    # ------------------------------------------------------------------ the run
    def run(self) -> LoopResult:
        """Drive the mission; return the per-step records.

        Raises:
            TimeoutError: the follower did not answer a message within ``step_timeout``,
                or did not move the robot within ``start_timeout`` of the start or a turn.
        """
        c = self.config
        self.wait_for_follower()
        self._enable(True)
        wall0 = time.monotonic()
        truth = np.array(c.start, dtype=float)
        odom = np.zeros(3)
        b = c.wheel_separation
        dt = 1.0 / c.odom_rate
        per_frame = int(round(c.odom_rate / c.camera_rate))
        rec_t: List[np.ndarray] = []
        rec_c: List[Tuple[float, float]] = []
        rec_turn: List[bool] = []
        rec_e: List[Tuple[float, float, float]] = []
        leg, travelled, turning, target = 0, 0.0, False, 0.0
        legs: List[float] = []
        still, stall = 0, int(round(c.stall_seconds * c.odom_rate))
        k = 0
        while leg < c.lengths:
            t = 1_000_000_000 + int(round(k * 1e9 / c.odom_rate))
            if k % per_frame == 0:
                img = corridor_view(self.sim, self.planes, truth, c.mount, c.photometry,
                                    self.pixel_rng).image
                self.pub_info.publish(make_camera_info(self.camera, t, 'camera_optical'))
                self.pub_image.publish(array_to_image(img, 'mono8', t, 'camera_optical'))
            self.pub_truth.publish(make_odometry(t, 'corridor', 'base_link', truth))
            self.pub_odom.publish(make_odometry(t, 'odom', 'base_link', odom))
            if turning:
                est = self._wait(self._poses, t, 'corridor/pose')
                err = wrap_angle(target - odom[2])
                if abs(err) < 1e-3:
                    turning = False
                    self._enable(True)
                    v, w = 0.0, 0.0
                else:
                    v, w = 0.0, math.copysign(min(c.turn_speed, abs(err) / dt), err)
            else:
                v, w = self._wait(self._cmds, t, 'cmd_vel')
                with self._cond:
                    est = self._poses.pop(t, (math.nan,) * 3)
            rec_t.append(truth.copy())
            rec_c.append((v, w))
            rec_turn.append(turning)
            rec_e.append(est)
            with self._cond:                 # poses of earlier stamps are of no use now
                for s in [s for s in self._poses if s <= t]:
                    del self._poses[s]
            d_l, d_r = (v - 0.5 * b * w) * dt, (v + 0.5 * b * w) * dt
            t_l = d_l + self.rng.normal(0.0, math.sqrt(c.k_wheel * abs(d_l)))
            t_r = (d_r + self.rng.normal(0.0, math.sqrt(c.k_wheel * abs(d_r)))) \
                / (1 + c.right_scale_error)
            truth = diff_drive(truth, t_l, t_r, b)
            odom = diff_drive(odom, d_l, d_r, b)
            travelled += v * dt
            k += 1
            still = still + 1 if not turning and v == 0.0 else 0
            if still * dt > c.start_timeout and travelled == 0.0:
                raise TimeoutError(f'the follower did not move the robot within '
                                   f'{c.start_timeout} s (simulation time) on leg {leg + 1}')
            if not turning and (travelled >= c.distance or (travelled > 0 and still >= stall)):
                leg += 1
                legs.append(travelled)
                still = 0
                travelled = 0.0
                if leg < c.lengths:
                    self._enable(False)
                    turning, target = True, wrap_angle(odom[2] + math.pi)
        self._enable(False)
        return LoopResult(np.array(rec_t), np.array(rec_c), np.array(rec_turn),
                          np.array(rec_e, dtype=float), tuple(legs), time.monotonic() - wall0, c)


def follower_parameters(config: LoopConfig, speed: float = 0.5) -> Dict[str, object]:
    """Return the ``corridor_follower`` parameters that match a loop configuration."""
    c = config
    return {'camera_mount': [float(v) for v in c.mount], 'corridor_width': c.corridor.width,
            'corridor_height': c.corridor.height, 'centre_line': c.corridor.centre_line,
            'wheel_separation': c.wheel_separation, 'stamped_cmd_vel': True, 'speed': speed}


def run_loop(context, config: LoopConfig = LoopConfig(), seed: int = 0,
             executor=None) -> LoopResult:
    """Run a loop against a follower already on the graph; spin with ``executor`` or own one.

    Args:
        context: a started rclpy context.
        config: the run.
        seed: scene and noise seed.
        executor: an executor already spinning on another thread (the loop's node is added
            to it), or None to spin one here.
    """
    from rclpy.executors import SingleThreadedExecutor
    loop = CorridorLoop(context, config, seed)
    own: Optional[SingleThreadedExecutor] = None
    thread = None
    if executor is None:
        own = executor = SingleThreadedExecutor(context=context)
        stop = threading.Event()

        def spin() -> None:
            while not stop.is_set() and context.ok():
                own.spin_once(timeout_sec=0.02)
        executor.add_node(loop.node)
        thread = threading.Thread(target=spin, daemon=True)
        thread.start()
    else:
        executor.add_node(loop.node)
    try:
        return loop.run()
    finally:
        executor.remove_node(loop.node)
        if thread is not None:
            stop.set()
            thread.join(timeout=5.0)
        loop.node.destroy_node()
