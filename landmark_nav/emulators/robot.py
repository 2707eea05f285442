"""One emulated robot: a Pioneer base (P2OS) carrying a laser (SCIP 2.0 or LMS2xx), one world.

``landmark_nav emulate robot`` serves both devices at once, so the drivers, the extractors
and ``ekf_slam`` run on a live robot that ``cmd_vel`` drives (docs/drivers.md, "One
emulated robot"):

* :class:`RobotBase` is the :class:`~landmark_nav.emulators.p2os.P2osDevice` (the robot that
  ``cmd_vel`` moves through ``base_driver``, with the true k1, k2, k3 of eqs. 17-18) that
  also keeps its true path: every 100 ms cycle's start pose and true twist. Its velocities
  are causal: the ramp toward the setpoints made at one cycle drives the next interval (a
  command takes effect one cycle later). Inside a cycle the pose is the one of eqs. 1-5
  with that twist (:func:`landmark_nav.sim.robot.step_pose` over the part of the cycle
  elapsed), so :meth:`RobotBase.pose_at` gives the pose at any host time, exactly the one
  the status packets report at the cycles. It first runs the cycles due by then (the
  base's server thread may be late under load); within the interval after the last cycle
  it uses the twist planned for it, which only a stall at a wall (or an E_STOP) can still
  change.
* :class:`MountedLaser` is the laser's path for :class:`~landmark_nav.emulators.laser_scene.
  LaserScene`: the base pose at the beam's time composed with the mount ``base_link ->
  laser``; the laser emulator ray-casts the same world the base moves and its sonars
  measure in.
* :class:`TruthWriter` writes the true path as a TUM file (stamps in ROS time, the system
  clock the drivers stamp with), sampled every ``period`` inside the cycles, in the start
  frame (``odom`` of a driver started with the robot at rest there, the ``map`` of
  ``ekf_slam``) or in the world.

Both devices run on the host's monotonic clock (:class:`~landmark_nav.emulators.server.
DeviceServer`), so the laser's beam times and the base's cycles are on one time line.
"""

import argparse
from collections import deque
from dataclasses import replace
import math
from pathlib import Path
import threading
import time
from typing import Callable, IO, List, Optional, Sequence, Tuple

from landmark_nav.emulators import p2os as p2os_emulator
from landmark_nav.emulators.laser_scene import LaserScene, SceneConfig
from landmark_nav.emulators.p2os import OPEN, P2osDevice
from landmark_nav.emulators.server import Device, DeviceServer, FaultInjector
from landmark_nav.geometry import relative
from landmark_nav.heap import release_free_heap
from landmark_nav.sim.laser import compose
from landmark_nav.sim.robot import step_pose, wheel_to_twist
from landmark_nav.sim.scenarios import office_world
from landmark_nav.stop_signals import stop_on_signals
import numpy as np

LASERS = ('urg', 'lms200')
#: Default ``base_link -> laser`` mount [m, m, rad] (the shipped ekf_slam.yaml's laser_pose).
DEFAULT_MOUNT = (0.0, 0.0, 0.0)
#: Seconds of status packets and commands the command's base keeps (:func:`make_from_args`).
CLI_RECORD_S = 2.0
#: Scans sent the command's laser keeps.
CLI_RECORD_SCANS = 20


class RobotBase(P2osDevice):
    """A :class:`P2osDevice` that records its true path for the sensors it carries.

    Args:
        *args: As :class:`P2osDevice`.
        history: Cycles kept (600: one minute) for :meth:`pose_at`.
        **kwargs: As :class:`P2osDevice`.
    """

    def __init__(self, *args, history: int = 600, **kwargs) -> None:
        """Build the robot at rest; no cycle recorded yet."""
        super().__init__(*args, **kwargs)
        # (end time [s], pose at the cycle's start, true v [m/s], true w [rad/s])
        self._path: deque = deque(maxlen=int(history))
        self.listeners: List[Callable[[float, np.ndarray, float, float], None]] = []
        self._plan: Tuple[float, float, Tuple[int, int]] = (0.0, 0.0, (0, 0))
        self._early: List[bytes] = []  # status packets of cycles run by pose_at
        self.predicted_queries = 0

    def _true_twist(self, wheels: Optional[Tuple[int, int]] = None) -> Tuple[float, float]:
        """Return the true body twist of wheel speeds [mm/s] (eqs. 17-18, as ``_move``)."""
        r, b = self.robot.wheel_radius, self.robot.axle_length
        omega = np.array(self.wheels if wheels is None else wheels, dtype=float) / 1000.0 / r
        v, w = wheel_to_twist(omega[0], omega[1], self.robot.k1 * r, self.robot.k2 * r,
                              self.robot.k3 * b)  # eqs. 17-18
        return float(v), float(w)

    def _cycle(self, t: float) -> Optional[bytes]:
        start = self.true_pose.copy()
        frame = super()._cycle(t)
        moved = not np.array_equal(start, self.true_pose)
        v, w = self._true_twist() if moved else (0.0, 0.0)  # a stalled robot stays put
        self._path.append((t, start, v, w))
        for listener in list(self.listeners):
            listener(t - self.cycle_s, start, v, w)
        return frame

    def _update_velocities(self, dt: float) -> None:
        """Apply the velocities planned at the last cycle; plan the next ones (causal).

        The parent ramps the velocities toward the setpoints at the end of each cycle and
        applies them to the cycle that just ended, so a command would move the robot
        before it arrived. Here the ramp made at cycle k (from the setpoints at t_k) drives
        the interval (t_k, t_k+1]: the motion up to any time is known at that time, which
        the laser riding on the base needs. The response to a command lags one cycle.
        """
        apply = self._plan
        self.v, self.w, self.wheels = apply
        super()._update_velocities(dt)  # ramp from the applied velocities: the next plan
        self._plan = (self.v, self.w, self.wheels)
        self.v, self.w, self.wheels = apply

    def _handle(self, command, raw: bytes, now: float) -> List[bytes]:
        out = super()._handle(command, raw, now)
        if command.name == 'E_STOP' and self.state == OPEN:
            self._plan = (0.0, 0.0, (0, 0))  # at rest from the next cycle on
        return out

    def _predicted_twist(self) -> Tuple[float, float]:
        """Twist of the interval after the last cycle (planned then; a stall stops it)."""
        return self._true_twist(self._plan[2])

    def poll(self, now: float) -> List[bytes]:
        """Send the status packets of cycles run early for the laser, then the due ones."""
        with self._lock:
            early, self._early = self._early, []
            return early + super().poll(now)

    def pose_at(self, t) -> np.ndarray:
        """Return the true pose(s) ``(..., 3)`` at host time(s) ``t`` [s] (module docstring).

        Cycles due by the latest ``t`` are run first (the base's own thread may be late under
        load; their packets go out with its next poll), so only the interval after the last
        cycle is predicted. Times before the kept history get the pose at its start.
        """
        t = np.asarray(t, dtype=float)
        with self._lock:
            latest = float(t.max()) if t.size else -math.inf
            while self._next_tick is not None and latest >= self._next_tick:
                tick = self._next_tick
                self._next_tick += self.cycle_s
                frame = self._cycle(tick)  # its packet goes out late, not never
                if frame is not None:
                    self._early.append(frame)
            path = list(self._path)
            current = self.true_pose.copy()
            predicted = self._predicted_twist()
        out = np.empty(t.shape + (3,))
        later = np.ones(t.shape, dtype=bool)
        if path:
            ends = np.array([p[0] for p in path])
            k = np.searchsorted(ends, t, side='left')  # first cycle ending at or after t
            later = k >= len(path)
            if not np.all(later):
                kk = k[~later]
                starts = np.array([p[1] for p in path])[kk]
                twist = np.array([(p[2], p[3]) for p in path])[kk]
                dt = np.clip(t[~later] - (ends[kk] - self.cycle_s), 0.0, self.cycle_s)
                out[~later] = step_pose(starts, twist[:, 0], twist[:, 1], dt)  # eqs. 1-5
            last = ends[-1]
        else:
            last = -math.inf
        if np.any(later):
            self.predicted_queries += 1
            dt = np.maximum(t[later] - last, 0.0) if path else np.zeros(int(later.sum()))
            out[later] = step_pose(current, predicted[0], predicted[1], dt)
        return out


class MountedLaser:
    """The path of a laser mounted on a :class:`RobotBase` (a scene ``motion``).

    ``pose_at_seconds(t)``: the base pose at host time ``origin + t`` composed with the
    ``base_link -> laser`` mount; ``origin`` is set by :meth:`start` (the laser device's
    scene time 0, :meth:`LaserScene.start`).
    """

    start_ns = 0

    def __init__(self, base: RobotBase, mount: Sequence[float] = DEFAULT_MOUNT) -> None:
        """Bind the base and the mount ``(x, y, yaw)`` [m, m, rad]."""
        self.base = base
        self.mount = tuple(float(v) for v in mount)
        if len(self.mount) != 3 or not all(math.isfinite(v) for v in self.mount):
            raise ValueError(f'laser mount must be three finite numbers, got {mount!r}')
        self.origin = 0.0

    def start(self, now: float) -> None:
        """Anchor scene time 0 at host time ``now``."""
        self.origin = float(now)

    def pose_at_seconds(self, t) -> np.ndarray:
        """Laser pose(s) in the world at scene time(s) ``t`` [s]."""
        return compose(self.base.pose_at(self.origin + np.asarray(t, dtype=float)),
                       self.mount)


class _FollowingScene(LaserScene):
    """A scene whose :meth:`start` also anchors its :class:`MountedLaser`."""

    def start(self, now: float) -> None:
        if self.origin is None:
            self.motion.start(now)
        super().start(now)


def mounted_scene(base: RobotBase, mount: Sequence[float] = DEFAULT_MOUNT,
                  config: Optional[SceneConfig] = None) -> LaserScene:
    """Return a laser scene in the base's world that follows the base (noise of ``config``)."""
    return _FollowingScene(config or SceneConfig(), world=base.world,
                           motion=MountedLaser(base, mount))


class TruthWriter:
    """Write the true path of a :class:`RobotBase` as TUM lines while it moves.

    Every cycle adds the poses at ``period`` steps inside it (eqs. 1-5 with the cycle's
    twist), stamped in ROS time (host monotonic time + ``wall_offset``), expressed in the
    frame of ``origin`` (the start pose; None: the world).
    """

    def __init__(self, stream: IO[str], origin: Optional[Sequence[float]] = None,
                 period: float = 0.01, wall_offset: Optional[float] = None,
                 cycle: float = 0.1) -> None:
        """Bind the output; ``wall_offset`` defaults to ``time.time() - time.monotonic()``."""
        if not 0.0 < period <= cycle:
            raise ValueError(f'truth period must be in (0, {cycle}] s, got {period}')
        self.cycle = float(cycle)
        self.stream = stream
        self.origin = None if origin is None else np.asarray(origin, dtype=float)
        self.period = float(period)
        self.wall_offset = (time.time() - time.monotonic() if wall_offset is None
                            else float(wall_offset))
        self._next: Optional[float] = None
        self._lock = threading.Lock()
        self.rows = 0
        stream.write('# true base pose: t x y z qx qy qz qw (landmark_nav emulate robot)\n')

    def __call__(self, start_t: float, start: np.ndarray, v: float, w: float) -> None:
        """Write the samples of one cycle that starts at ``start_t`` from ``start``."""
        cycle = self.cycle
        with self._lock:
            if self._next is None:
                self._next = math.ceil(start_t / self.period) * self.period
            times = []
            while self._next < start_t + cycle - 1e-9:
                times.append(self._next)
                self._next += self.period
            if not times:
                return
            ts = np.array(times)
            poses = step_pose(np.broadcast_to(start, (len(ts), 3)), v, w,
                              np.clip(ts - start_t, 0.0, cycle))  # eqs. 1-5
            if self.origin is not None:
                poses = relative(self.origin, poses)
            for tt, (x, y, yaw) in zip(ts, poses):
                self.stream.write(f'{tt + self.wall_offset:.6f} {x:.6f} {y:.6f} 0 0 0 '
                                  f'{math.sin(0.5 * yaw):.9f} {math.cos(0.5 * yaw):.9f}\n')
            self.rows += len(ts)


def make_robot(laser: str = 'urg', laser_model: str = 'utm-30lx',
               mount: Sequence[float] = DEFAULT_MOUNT, scene: Optional[SceneConfig] = None,
               laser_kwargs: Optional[dict] = None, rate: float = 1.0,
               **base_kwargs) -> Tuple[RobotBase, Device]:
    """Build the base and the laser it carries on one world (default: the office world).

    Args:
        laser: ``urg`` (SCIP 2.0) or ``lms200`` (LMS2xx).
        laser_model: URG model (``utm-30lx`` or ``urg-04lx``; ignored for the LMS200).
        mount: ``base_link -> laser`` (x, y, yaw) [m, m, rad].
        scene: Laser noise (its pose and motion are ignored: the laser rides on the base).
        laser_kwargs: Further arguments of the laser device (baud, jitter, ...).
        rate: Data rate factor for load tests: the URG's scans per second (its motor speed)
            and the base's status packets per second (``cycle_s`` 0.1 / ``rate``; one
            minute of cycles kept) times ``rate``; the robot moves as at rate 1.
        **base_kwargs: Arguments of :class:`RobotBase` (start pose, k, model, ...).

    Returns:
        ``(base, laser device)``.
    """
    if laser not in LASERS:
        raise ValueError(f'laser must be one of {", ".join(LASERS)}, got {laser!r}')
    if not (math.isfinite(rate) and 0.0 < rate <= 100.0) or (laser != 'urg' and rate != 1.0):
        raise ValueError(f'rate must be in (0, 100] (and 1 for the {laser}), got {rate!r}')
    base_kwargs.setdefault('world', office_world())
    base_kwargs.setdefault('cycle_s', 0.1 / rate)
    base_kwargs.setdefault('history', int(round(60.0 / base_kwargs['cycle_s'])))
    base = RobotBase(**base_kwargs)
    sc = mounted_scene(base, mount, scene)
    if laser == 'urg':
        from landmark_nav.emulators.urg import MODELS, UrgDevice
        if laser_model not in MODELS:
            raise ValueError(f'URG model must be one of {", ".join(MODELS)}, '
                             f'got {laser_model!r}')
        model = MODELS[laser_model]
        if rate != 1.0:
            model = replace(model, params=replace(
                model.params, scan_rpm=int(round(model.params.scan_rpm * rate))))
        return base, UrgDevice(model, sc, **(laser_kwargs or {}))
    from landmark_nav.emulators.lms200 import LmsDevice
    return base, LmsDevice(sc, **(laser_kwargs or {}))


# ---------------------------------------------------------------------------- command line


def _triple(text: str) -> Tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(','))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f'expected X,Y,YAW (three numbers), got {text!r}')
    return values


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the robot's options: the P2OS base's, the laser's and the truth file."""
    p2os_emulator.add_arguments(parser)
    parser.add_argument('--laser', choices=LASERS, default='urg',
                        help='laser on the robot: urg (SCIP 2.0, default) or lms200')
    parser.add_argument('--laser-model', choices=('utm-30lx', 'urg-04lx'), default='utm-30lx',
                        help='URG model (default utm-30lx: 40 scans/s, 270 deg)')
    parser.add_argument('--laser-baud', type=int, default=None,
                        help="URG: emulated RS-232 rate (0: USB; default the model's); "
                             'LMS200: power-up baud (default 9600, the driver switches)')
    parser.add_argument('--laser-link', default=None,
                        help='symlink to the laser pty (default /tmp/landmark_nav_urg or '
                             '/tmp/landmark_nav_lms200; "" for none)')
    parser.add_argument('--laser-tcp', type=int, default=None, metavar='PORT',
                        help='also serve the laser on this TCP port (0: any free port)')
    parser.add_argument('--laser-mount', type=_triple, default=DEFAULT_MOUNT,
                        metavar='X,Y,YAW',
                        help='base_link -> laser [m, m, rad] (default 0,0,0 as ekf_slam.yaml '
                             'laser_pose; set both alike)')
    parser.add_argument('--p-error', type=float, default=SceneConfig().p_error,
                        help='laser: probability per beam of an error (dazzle) value')
    parser.add_argument('--p-close', type=float, default=SceneConfig().p_close,
                        help='laser: probability per beam of a too-close return')
    parser.add_argument('--jitter-ms', type=float, default=0.0,
                        help='laser: mean extra delivery delay per frame (exponential) [ms]')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='data rate factor for load tests (URG only): scans/s and base '
                             'status packets/s times RATE, the motion unchanged; start '
                             'base_driver with cycle_time 0.1/RATE (--rate 10: 400 scans/s, '
                             '100 Hz odometry)')
    parser.add_argument('--truth', default=None, metavar='FILE.tum',
                        help='write the true base path here (TUM, ROS time, every 10 ms)')
    parser.add_argument('--truth-frame', choices=('start', 'world'), default='start',
                        help='frame of --truth: start (the odom / ekf_slam map frame of a robot '
                             'started at rest, default) or world (the office world)')


def make_from_args(args: argparse.Namespace) -> Tuple[RobotBase, Device]:
    """Build the base and its laser from the parsed options.

    The devices' records (status packets and commands, :data:`CLI_RECORD_S`; scans sent,
    :data:`CLI_RECORD_SCANS`) are short: nothing reads them in the command (the tests build
    the devices in-process), and full within seconds they keep a live run's memory flat.
    """
    kwargs = dict(p2os_emulator.device_kwargs(args), record_s=CLI_RECORD_S)
    scene = SceneConfig(p_error=args.p_error, p_close=args.p_close, seed=args.seed + 1)
    laser_kwargs = {'jitter': args.jitter_ms / 1000.0, 'seed': args.seed,
                    'history': CLI_RECORD_SCANS}
    if args.laser_baud is not None:
        laser_kwargs['baud'] = args.laser_baud
    return make_robot(args.laser, args.laser_model, args.laser_mount, scene, laser_kwargs,
                      rate=args.rate, **kwargs)


def serve(args: argparse.Namespace, announce: Callable[[str], None] = print,
          stop: Optional[threading.Event] = None) -> int:
    """Serve the base and the laser until Ctrl-C / SIGTERM (or ``stop`` is set)."""
    base, laser = make_from_args(args)
    laser_link = (args.laser_link if args.laser_link is not None
                  else f'/tmp/landmark_nav_{args.laser}')
    servers = [
        DeviceServer(base, link=args.link or None, tcp_port=args.tcp, tcp_host=args.tcp_host,
                     faults=FaultInjector(seed=args.seed, rate=args.fault_rate)),
        DeviceServer(laser, link=laser_link or None, tcp_port=args.laser_tcp,
                     tcp_host=args.tcp_host,
                     faults=FaultInjector(seed=args.seed + 1, rate=args.fault_rate),
                     options=('--laser-link', '--laser-tcp')),
    ]
    truth_file = None
    if args.truth:
        truth_file = Path(args.truth).open('w', buffering=1)
        start = base.true_pose.copy() if args.truth_frame == 'start' else None
        base.listeners.append(TruthWriter(truth_file, origin=start, cycle=base.cycle_s,
                                          period=min(0.01, base.cycle_s)))
    stop = stop or threading.Event()

    stop_on_signals(stop)  # SIGINT stops it even if it started ignored (a background job)
    try:
        for server, what in zip(servers, ('base (P2OS)', f'laser ({args.laser})')):
            server.start()
            if server.link is not None:
                announce(f'{what} pty: {server.link} -> {server.pty_path}')
            if server.tcp_port is not None:
                announce(f'{what} tcp: socket://{server.tcp_host}:{server.tcp_port}')
        x, y, yaw = base.true_pose
        announce(f'robot at ({x:g}, {y:g}, {math.degrees(yaw):g} deg) in the office world; '
                 f'laser mount {",".join(f"{v:g}" for v in args.laser_mount)}'
                 + (f'; truth -> {args.truth}' if args.truth else '')
                 + (f'; data rate x{args.rate:g} (base cycle {1e3 * base.cycle_s:g} ms, '
                    f'{1.0 / laser.period:.0f} scans/s)' if args.rate != 1.0 else ''))
        if args.fault:
            threading.Thread(target=_schedule, args=(servers, args.fault, stop),
                             daemon=True).start()
        while not stop.wait(0.5):
            release_free_heap()  # at most every HEAP_RELEASE_S
    finally:
        for server in servers:
            server.stop()
        if truth_file is not None:
            truth_file.close()
        announce(f'base: {base.seq} cycles, {base.packets_not_sent} status packets not sent '
                 f'(cycles run too late), {servers[0].bytes_dropped} bytes not written (pty '
                 f'full); laser: {getattr(laser, "scans_sent", "?")} scans sent, '
                 f'{getattr(laser, "scans_skipped", 0)} scans skipped (polled '
                 f'too late), {servers[1].bytes_dropped} bytes not written (pty full)')
    return 0


def _schedule(servers: Sequence[DeviceServer], faults, stop: threading.Event) -> None:
    start = time.monotonic()
    for at, fault in sorted(faults, key=lambda item: item[0]):
        if stop.wait(max(0.0, start + at - time.monotonic())):
            return
        print(f'injecting {fault.kind} ({fault.duration:g} s) on both ports', flush=True)
        for server in servers:
            server.inject(fault)


__all__ = ['add_arguments', 'DEFAULT_MOUNT', 'LASERS', 'make_from_args', 'make_robot',
           'mounted_scene', 'MountedLaser', 'RobotBase', 'serve', 'TruthWriter']
