"""``landmark_nav drive``: drive a robot along waypoints by ``cmd_vel``, closed on a pose topic.

The pose comes from a ``nav_msgs/Odometry`` topic (default ``/odometry``: ekf_slam's
estimate in its ``map`` frame, which is the robot's start frame; ``/odom`` drives on the
drifting odometry). Waypoints are given in the world with the robot's start pose there
(``--start-pose``, as given to ``landmark_nav emulate robot``) and re-expressed in the start
frame; ``--route office`` is the office scenario's loop. Commands go out at 10 Hz
(:class:`landmark_nav.waypoints.WaypointFollower`); the robot stops at the end, after
``--duration`` s, on Ctrl-C or SIGTERM. ``--record FILE.tum`` writes every pose received
(TUM, the topic's stamps) to score against the emulator's truth (``--truth``).
"""

import argparse
import math
from pathlib import Path
import threading
import time
from typing import Optional, Sequence

import numpy as np

ROUTES = {
    # the office scenario's waypoints (landmark_nav.sim.scenarios.OFFICE_WAYPOINTS)
    'office': ((5.2, 1.3), (8.2, 1.4), (8.2, 5.6), (5.4, 6.4), (5.3, 4.9), (3.6, 4.9),
               (1.3, 5.8), (1.3, 4.0), (4.3, 4.0), (4.3, 2.0), (1.2, 1.2)),
    # a short lap in the south of the office (tests)
    'short': ((3.2, 1.3), (3.2, 2.0), (1.8, 2.0), (1.2, 1.2)),
}


def route_in_start_frame(points: Sequence[Sequence[float]],
                         start_pose: Sequence[float]) -> np.ndarray:
    """Express world waypoints ``(W, 2)`` in the frame of the start pose ``(x, y, yaw)``."""
    from landmark_nav.geometry import relative
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    world = np.column_stack([pts, np.zeros(len(pts))])
    return relative(np.asarray(start_pose, dtype=float), world)[:, :2]


def _point(text: str):
    try:
        x, y = (float(v) for v in text.split(','))
    except ValueError:
        raise argparse.ArgumentTypeError(f'waypoint must be X,Y, got {text!r}') from None
    return x, y


def add_parser(sub, parser_class) -> None:
    """Add the ``drive`` subcommand."""
    p = sub.add_parser('drive', help='drive a robot along waypoints with cmd_vel, closed on a '
                       'pose topic (e.g. ekf_slam on an emulated robot)',
                       description=__doc__.split('\n')[0])
    p.add_argument('--route', choices=sorted(ROUTES), default='office',
                   help='named waypoint list in the office world (default office)')
    p.add_argument('--waypoint', type=_point, action='append', default=None, metavar='X,Y',
                   help='a waypoint in the world [m] instead of --route (repeatable)')
    p.add_argument('--start-pose', type=float, nargs=3, default=(1.2, 1.2, 0.0),
                   metavar=('X', 'Y', 'YAW_DEG'),
                   help="the robot's start pose in the world [m, m, deg] (default 1.2 1.2 0)")
    p.add_argument('--pose-topic', default='/odometry',
                   help='nav_msgs/Odometry pose feedback (default /odometry of ekf_slam)')
    p.add_argument('--cmd-vel', default='/cmd_vel', help='Twist topic (default /cmd_vel)')
    p.add_argument('--max-speed', type=float, default=0.3, help='[m/s] (default 0.3)')
    p.add_argument('--max-turn-rate', type=float, default=0.6, help='[rad/s] (default 0.6)')
    p.add_argument('--duration', type=float, default=None,
                   help='stop after this many seconds of driving')
    p.add_argument('--wait', type=float, default=60.0,
                   help='wait this long for the first pose [s] (default 60)')
    p.add_argument('--record', default=None, metavar='FILE.tum',
                   help='write every pose received (TUM)')
    p.add_argument('--loop', action='store_true',
                   help='start the route again when it is done (until --duration)')
    p.set_defaults(func=run)


def drive(points, start_pose, pose_topic: str = '/odometry', cmd_vel: str = '/cmd_vel',
          max_speed: float = 0.3, max_turn_rate: float = 0.6,
          duration: Optional[float] = None, wait: float = 60.0, record=None,
          stop: Optional[threading.Event] = None, context=None,
          log=print, loop: bool = False) -> dict:
    """Drive the route; return a summary (waypoints reached, poses received, seconds).

    Raises:
        TimeoutError: No pose arrived within ``wait`` seconds.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from geometry_msgs.msg import Twist
    from landmark_nav.conversions import ConversionError, odometry_to_pose
    from landmark_nav.waypoints import FollowerParams, WaypointFollower
    from nav_msgs.msg import Odometry

    follower = WaypointFollower(route_in_start_frame(points, start_pose),
                                FollowerParams(max_speed=max_speed,
                                               max_turn_rate=max_turn_rate))
    stop = stop or threading.Event()
    own = context is None
    if own:
        context = rclpy.Context()
        rclpy.init(context=context)
    node = rclpy.create_node('drive', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    latest = {}
    out = Path(record).open('w', buffering=1) if record else None
    received = [0]

    def on_pose(msg):
        try:
            d = odometry_to_pose(msg)
        except ConversionError as err:
            log(f'drive: ignoring a pose: {err}')
            return
        latest['pose'] = np.asarray(d.pose, dtype=float)
        received[0] += 1
        if out is not None:
            x, y, yaw = d.pose
            out.write(f'{d.stamp_ns * 1e-9:.9f} {x:.6f} {y:.6f} 0 0 0 '
                      f'{math.sin(0.5 * yaw):.9f} {math.cos(0.5 * yaw):.9f}\n')

    node.create_subscription(Odometry, pose_topic, on_pose, 50)
    pub = node.create_publisher(Twist, cmd_vel, 10)

    def send(v: float, w: float) -> None:
        msg = Twist()
        msg.linear.x, msg.angular.z = float(v), float(w)
        pub.publish(msg)

    started = None
    laps = 0
    try:
        deadline = time.monotonic() + wait
        log(f'drive: waiting up to {wait:g} s for a pose on {pose_topic}')
        while 'pose' not in latest and not stop.is_set():
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f'no pose on {pose_topic} within {wait:g} s: start the node that '
                    'publishes it (ekf_slam: landmark_nav pipeline slam) or name another '
                    'nav_msgs/Odometry topic with --pose-topic')
            executor.spin_once(timeout_sec=0.1)
        started = time.monotonic()
        if 'pose' in latest:  # not when stopped while waiting
            log(f'drive: first pose on {pose_topic}; driving {len(follower.points)} waypoints')
        next_cmd = started
        reached = laps = 0
        while not stop.is_set() and not follower.done:
            if duration is not None and time.monotonic() - started > duration:
                break
            executor.spin_once(timeout_sec=max(0.0, next_cmd - time.monotonic()))
            if time.monotonic() >= next_cmd:
                next_cmd += 0.1
                v, w = follower.command(latest['pose'])
                send(v, w)
                if follower.index > reached:
                    reached = follower.index
                    log(f'drive: waypoint {reached}/{len(follower.points)} reached '
                        f'after {time.monotonic() - started:.1f} s')
                if follower.done and loop:
                    follower.index, reached = 0, 0
                    laps += 1
    finally:
        for _ in range(3):
            send(0.0, 0.0)
            time.sleep(0.05)
        if out is not None:
            out.close()
        executor.shutdown()
        node.destroy_node()
        if own:
            rclpy.shutdown(context=context)
    return {'reached': follower.index, 'waypoints': len(follower.points), 'laps': laps,
            'poses': received[0],
            'seconds': 0.0 if started is None else time.monotonic() - started}


def run(args: argparse.Namespace) -> int:
    """Drive until the route is done, ``--duration`` passes, or Ctrl-C / SIGTERM."""
    from landmark_nav.nodes.common import limit_threads
    from landmark_nav.stop_signals import stop_on_signals
    limit_threads()
    stop = threading.Event()
    stop_on_signals(stop)
    x, y, yaw_deg = args.start_pose
    points = args.waypoint or ROUTES[args.route]
    result = drive(points, (x, y, math.radians(yaw_deg)), args.pose_topic, args.cmd_vel,
                   args.max_speed, args.max_turn_rate, args.duration, args.wait, args.record,
                   stop, log=lambda text: print(text, flush=True), loop=args.loop)
    print(result_line(result, args.loop), flush=True)
    return 0


def result_line(result: dict, loop: bool) -> str:
    """Return drive's last line: waypoints reached (and laps with ``--loop``), time, poses."""
    laps = f'{result["laps"]} laps and ' if loop else ''
    return (f'drive: {laps}{result["reached"]}/{result["waypoints"]} waypoints in '
            f'{result["seconds"]:.1f} s, {result["poses"]} poses received')
