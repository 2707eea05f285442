"""Executable ``base_driver``: a Pioneer robot base (P2OS) on a serial port or TCP.

The session logic (handshake incl. the still-open CLOSE-and-retry path, keep-alive,
velocity commands, watchdog) is :class:`landmark_nav.drivers.p2os_client.P2osClient`; the
odometry is :class:`landmark_nav.localization.wheel_odometry.WheelOdometry`; the port and
its reconnects are :class:`landmark_nav.nodes.driver_common.DeviceLink`. This node converts.

Publishes (stamped with the host time of the robot's cycle: the status packets leave every
``cycle_time`` on the robot's clock, so the count of cycles (from the robot's own odometry,
:class:`~landmark_nav.drivers.p2os_client.SipUpdate` ``cycles``) is a sensor clock that
:class:`~landmark_nav.drivers.clock_filter.ClockFilter` maps to host time from the lowest
arrival delays, as the laser driver does with the sensor's counter; arrival times minus
``time_offset`` jitter by the OS scheduling, tens of ms under load, the stamps do not):

* ``odom`` (nav_msgs/Odometry, ``odom_frame`` -> ``base_frame``) every status packet
  (10 Hz): integrated from the wheel velocities with k1, k2, k3 (eqs. 4-7, 17-18, 1-3) or,
  with ``odometry_source: robot``, the robot's own pose (XPOS / YPOS / THPOS unwrapped);
  covariance from a distance-driven error model; twist = (v, 0, w);
* ``joint_states`` (sensor_msgs/JointState): ``wheel_joints`` angle [rad] (accumulated) and
  angular velocity [rad/s] (LVEL / RVEL divided by ``wheel_radius``);
* ``sonar/range_<i>`` (sensor_msgs/Range, frame ``<sonar_frame_prefix><i>``) for every new
  sonar reading, REP 117 (+inf beyond ``sonar_max_range``, -inf below ``sonar_min_range``);
* ``battery`` (sensor_msgs/BatteryState), every ``battery_period``;
* ``/diagnostics``: the link (connection, rate, errors) and the robot (battery, motors,
  sonar, stall, bumpers, e-stop, handshake counters);
* the odom -> base_link transform when ``publish_tf`` and tf2_ros is importable.

Subscribes ``cmd_vel`` (geometry_msgs/Twist: linear.x, angular.z) -> VEL + RVEL or VEL2,
clamped to the speed limits (the robot ramps with the SETA / SETRA limits sent at connect);
STOP after ``cmd_vel_timeout`` without a command. A command is dropped, with a throttled
warning and a count on ``/diagnostics`` (``base_driver: input``,
:class:`~landmark_nav.nodes.common.InputStats`), when it is not finite (``malformed``) or
arrives while the robot is not connected (``not_connected``: it is not sent later); device
data that cannot be used (a sonar number outside the ring) is counted on the connection
status (``dropped.<reason>``). Service ``~/enable_motors`` (std_srvs/SetBool). STOP and
CLOSE on shutdown (also on Ctrl-C: :meth:`destroy_node` runs
in :func:`~landmark_nav.nodes.common.run_node`'s shutdown path and needs no ROS context).
"""

import math
import threading
import time
from typing import List, Optional, Tuple

from geometry_msgs.msg import Twist
from landmark_nav.conversions import (make_joint_state, make_odometry, make_range,
                                      make_transform, ns_to_stamp)
from landmark_nav.drivers.clock_filter import ClockFilter
from landmark_nav.drivers.p2os import P2osDecoder
from landmark_nav.drivers.p2os_client import ClientConfig, P2osClient, SipUpdate
from landmark_nav.hardware import SONAR_FIELD_OF_VIEW, SONAR_MAX_RANGE, SONAR_MIN_RANGE
from landmark_nav.localization.wheel_odometry import WheelOdometry
from landmark_nav.nodes.common import (declare, declare_strings, InputStats, ParameterError,
                                       ProblemWarner, reject_undeclared, run_node)
from landmark_nav.nodes.driver_common import (declare_link_parameters, DeviceLink,
                                              DiagnosticsPublisher, ERROR, LinkHealth,
                                              make_transport, OK, Status, WARN)
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import BatteryState, JointState, Range
from std_srvs.srv import SetBool

try:  # a full ROS install; the PyPI wheels have no tf2_ros
    from tf2_ros import TransformBroadcaster
except ImportError:  # pragma: no cover - depends on the installation
    TransformBroadcaster = None

BAUD_CHOICES = (9600, 19200, 38400, 57600, 115200)
NUM_SONARS = 16


class BaseDriver(Node):
    """Thin node: P2OS status packets -> odometry, joints, sonar, battery; cmd_vel -> P2OS."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate parameters, create the interfaces, start the I/O thread."""
        super().__init__('base_driver', **kwargs)
        self._closed = False
        link = declare_link_parameters(self, '/dev/ttyUSB0', 9600, BAUD_CHOICES)
        d = declare
        try:
            config = ClientConfig(
                robot_model=d(self, 'robot_model', 'auto', 'unit conversions: auto (from the '
                              'SYNC2 subclass), p2dx, p3dx or p3dx-sh',
                              choices=['auto', 'p2dx', 'p3dx', 'p3dx-sh']),
                enable_motors=d(self, 'enable_motors', True, 'enable the motors after '
                                'connecting (also the ~/enable_motors service)'),
                sonar=d(self, 'sonar_enabled', True, 'switch the sonar on after connecting'),
                command_mode=d(self, 'command_mode', 'vel', 'cmd_vel as VEL + RVEL (vel) or '
                               'as VEL2 wheel speeds (vel2)', choices=['vel', 'vel2']),
                max_linear_speed=d(self, 'max_linear_speed', 0.5, 'cmd_vel linear.x limit, '
                                   'also SETV [m/s]', (0.001, 2.2)),
                max_angular_speed=d(self, 'max_angular_speed', math.radians(100.0),
                                    'cmd_vel angular.z limit, also SETRV [rad/s]',
                                    (0.001, 8.7)),
                linear_accel=d(self, 'max_linear_accel', 0.3, 'SETA: acceleration limit '
                               'the robot applies [m/s^2]', (0.001, 5.0)),
                linear_decel=d(self, 'max_linear_decel', 0.3, 'SETA (negative): '
                               'deceleration limit [m/s^2]', (0.001, 5.0)),
                angular_accel=d(self, 'max_angular_accel', math.radians(90.0), 'SETRA: '
                                'rotational acceleration limit [rad/s^2]', (0.001, 30.0)),
                angular_decel=d(self, 'max_angular_decel', math.radians(90.0), 'SETRA '
                                '(negative): rotational deceleration limit [rad/s^2]',
                                (0.001, 30.0)),
                axle_length=d(self, 'axle_length', 0.33, 'nominal axle length b [m]',
                              (0.01, 5.0)),
                cmd_timeout=d(self, 'cmd_vel_timeout', 0.5, 'STOP when cmd_vel stops for '
                              'this long [s]', (0.05, 60.0)),
                watchdog_command=d(self, 'cmd_vel_timeout_action', 'stop', 'what the '
                                   'cmd_vel watchdog sends: stop (decelerate at '
                                   'max_linear_decel) or e_stop (stop at once)',
                                   choices=['stop', 'e_stop']).upper(),
                pulse_period=d(self, 'pulse_period', 1.0, 'PULSE keep-alive when nothing was '
                               'sent for this long [s] (the robot stops after 2 s)',
                               (0.05, 1.9)),
                sync_timeout=d(self, 'sync_timeout', 0.5, 'wait this long for each SYNC '
                               'echo [s]', (0.01, 10.0)),
                close_wait=d(self, 'close_wait', 0.3, 'after CLOSE to a still-open robot, '
                             'wait this long before SYNC0 [s]', (0.0, 10.0)),
                sip_timeout=link['stale_error'],
                cycle_s=d(self, 'cycle_time', 0.1, 'status packet period of the robot [s]',
                          (0.01, 1.0)))
        except ValueError as err:
            raise ParameterError(f'base_driver: {err}') from err
        self.source = d(self, 'odometry_source', 'wheels', 'odometry from the wheel '
                        "velocities with k1..k3 (wheels) or the robot's own pose (robot)",
                        choices=['wheels', 'robot'])
        self.radius = d(self, 'wheel_radius', 0.0955, 'nominal wheel radius R [m]',
                        (0.001, 2.0))
        k = [d(self, f'k{i}', 1.0, f'odometry calibration factor k{i} (eqs. 17-18; 1 = '
               'nominal; written by landmark_nav calibrate-odometry)', (0.5, 1.5))
             for i in (1, 2, 3)]
        sigmas = [d(self, name, value, text, (0.0, 10.0)) for name, value, text in (
            ('odom_sigma_distance', 0.05, 'distance std per sqrt(metre) [m/sqrt(m)]'),
            ('odom_sigma_heading_per_distance', 0.05, 'heading std per sqrt(metre) '
             '[rad/sqrt(m)]'),
            ('odom_sigma_heading_per_rotation', 0.1, 'heading std per sqrt(radian) turned '
             '[rad/sqrt(rad)]'))]
        self.odom_frame = d(self, 'odom_frame', 'odom', 'frame of the odometry')
        self.base_frame = d(self, 'base_frame', 'base_link', 'child frame of the odometry')
        self.sonar_prefix = d(self, 'sonar_frame_prefix', 'sonar_', 'sonar i has frame '
                              '<prefix><i> (static transform from base_frame, see '
                              'docs/drivers.md)')
        self.sonar_fov = d(self, 'sonar_field_of_view', SONAR_FIELD_OF_VIEW, 'sonar cone '
                           'width [rad]', (0.0, 3.0))
        self.sonar_min = d(self, 'sonar_min_range', SONAR_MIN_RANGE, 'shorter readings are '
                           '-inf (too close) [m]', (0.0, 100.0))
        self.sonar_max = d(self, 'sonar_max_range', SONAR_MAX_RANGE, 'longer readings are '
                           '+inf (no echo) [m]', (0.0, 100.0))
        self.joints = declare_strings(self, 'wheel_joints',
                                      ['left_wheel_joint', 'right_wheel_joint'],
                                      'left and right wheel joint names')
        self.battery_period = d(self, 'battery_period', 1.0, 'period of battery [s]',
                                (0.05, 60.0))
        self.battery_warn = d(self, 'battery_warn', 11.75, 'diagnostics WARN below this '
                              'battery voltage [V]', (0.0, 100.0))
        self.battery_error = d(self, 'battery_error', 11.0, 'diagnostics ERROR below this '
                               'battery voltage [V]', (0.0, 100.0))
        self.time_offset = d(self, 'time_offset', 0.0, 'subtracted from the arrival time '
                             'of a status packet (link latency) [s]', (-1.0, 1.0))
        publish_tf = d(self, 'publish_tf', True, 'broadcast odom -> base_link when tf2_ros '
                       'is available')
        reject_undeclared(self)
        if len(self.joints) != 2 or self.sonar_min > self.sonar_max \
                or self.battery_error > self.battery_warn:
            raise ParameterError('base_driver: need two wheel_joints, sonar_min_range <= '
                                 'sonar_max_range and battery_error <= battery_warn')
        self.cycle_s = config.cycle_s
        self.odometry = WheelOdometry(self.radius, config.axle_length, k, *sigmas)
        self.client = P2osClient(config)
        self._lock = threading.Lock()
        self._status = None
        self._last_battery = -math.inf
        self._last_stamp = 0  # ns, of the last status packet (I/O thread)
        self._cycle_clock = ClockFilter()  # robot cycles -> host time
        self._cycles = 0
        self._robot_origin = self._robot_base = (0.0, 0.0, 0.0)
        self.warner = ProblemWarner(self)
        self.stats = InputStats(self, self.warner, link['diagnostics_period'])

        self.pub_odom = self.create_publisher(Odometry, 'odom', 10)
        self.pub_joints = self.create_publisher(JointState, 'joint_states', 10)
        self.pub_battery = self.create_publisher(BatteryState, 'battery', 10)
        self.pub_sonar = [self.create_publisher(Range, f'sonar/range_{i}', 10)
                          for i in range(NUM_SONARS)]
        self.tf = (TransformBroadcaster(self) if publish_tf and TransformBroadcaster
                   else None)
        self.stats.subscribe(Twist, 'cmd_vel', self.on_cmd_vel, 10)
        self.create_service(SetBool, '~/enable_motors', self.on_enable_motors)

        self.health = LinkHealth(link['port'], link['stale_warn'], link['stale_error'],
                                 link['problem_hold'])
        self.link = DeviceLink(make_transport(link), P2osDecoder(), self.on_frame,
                               self.health, on_connect=self.on_connect,
                               on_disconnect=self.on_disconnect, on_tick=self.on_tick,
                               logger=self.get_logger(), alive=self.context.ok)
        self.diagnostics = DiagnosticsPublisher(self, 'base_driver: connection',
                                                link['port'], self.health,
                                                link['diagnostics_period'],
                                                extra=self.robot_status)
        self.link.start()
        self.get_logger().info(f'base_driver: {link["port"]}, {config.command_mode} commands, '
                               f'odometry from {self.source}, k = {k}')

    # --- I/O thread callbacks -------------------------------------------------------------

    def _send(self, data: bytes) -> None:
        if data:
            self.link.write(data)

    def _log_client(self) -> None:
        for text in self.client.pop_messages():
            self.get_logger().info(text)

    def on_connect(self) -> None:
        """Start the handshake on every (re)open."""
        with self._lock:
            data = self.client.connect(time.monotonic())
        self._send(data)

    def on_disconnect(self, reason: str) -> None:
        """Forget the session."""
        with self._lock:
            self.client.disconnect()

    def on_tick(self, now: float) -> None:
        """Timeouts, keep-alive and the cmd_vel watchdog."""
        with self._lock:
            data = self.client.tick(now)
        self._send(data)
        self._log_client()

    def on_frame(self, item, arrival: float) -> None:
        """Handle one robot packet (I/O thread)."""
        with self._lock:
            data, update = self.client.receive(item, arrival)
        self._send(data)
        self._log_client()
        if update is not None:
            self.publish_status(update, arrival)

    # --- conversions ------------------------------------------------------------------------

    def _stamp_ns(self, arrival: float, update: Optional[SipUpdate] = None) -> int:
        host = arrival - self.time_offset
        if update is not None:  # the robot's cycle on the host clock (module docstring)
            if update.first:
                self._cycle_clock.reset()
                self._cycles = 0
            else:
                self._cycles += max(1, int(update.cycles))
            host = self._cycle_clock.update(self._cycles * self.cycle_s, host)
        age = time.monotonic() - host
        stamp = self.get_clock().now().nanoseconds - int(age * 1e9)
        # Packets read in one chunk share an arrival time, and the two clocks are read apart:
        # keep the stamps strictly increasing (1 us apart at least), as ekf_slam restarts on
        # odometry that goes back in time (seen under load: 20 us back).
        stamp = max(stamp, self._last_stamp + 1000)
        self._last_stamp = stamp
        return stamp

    def publish_status(self, update: SipUpdate, arrival: float) -> None:
        """Publish odometry, joint states, sonar ranges and battery of one status packet."""
        status = update.status
        params = self.client.params
        stamp = self._stamp_ns(arrival, update)
        if update.lost:
            self.health.on_problem(f'{update.lost} status packet(s) late or lost')
        dt = update.cycles * self.cycle_s
        left, right = status.wheel_velocities_mm_s(params)
        omega = (left / 1000.0 / self.radius, right / 1000.0 / self.radius)
        with self._lock:
            self._status = status
            if self.source == 'robot':
                if update.first:
                    self._robot_origin = update.robot_pose
                    self._robot_base = self.odometry.pose.copy()
                self.odometry.update_pose(self._robot_in_odom(update.robot_pose), dt, omega)
            else:
                self.odometry.update_wheels(omega[0], omega[1], dt)
            pose, cov = self.odometry.state
            twist = self.odometry.twist
            angles = self.odometry.wheel_angles.copy()
        self.pub_odom.publish(make_odometry(
            stamp, self.odom_frame, self.base_frame, pose, cov,
            twist=(float(twist[0]), 0.0, float(twist[1]))))
        self.pub_joints.publish(make_joint_state(stamp, self.joints, angles, omega))
        if self.tf is not None:
            self._broadcast(stamp, pose)
        for number, raw in status.sonars:
            if 0 <= number < NUM_SONARS:
                value = raw * params.range_conv_factor / 1000.0
                if value > self.sonar_max:
                    value = math.inf
                elif value < self.sonar_min:
                    value = -math.inf
                self.pub_sonar[number].publish(make_range(
                    stamp, f'{self.sonar_prefix}{number}', value, self.sonar_fov,
                    self.sonar_min, self.sonar_max))
            else:
                text = f'Dropping sonar reading: number {number} outside 0..{NUM_SONARS - 1}'
                self.health.on_drop('sonar_number', text)
                self.warner.warn(text)
        if arrival - self._last_battery >= self.battery_period:
            self._last_battery = arrival
            self.pub_battery.publish(self._battery(stamp, status.battery_v))
        self.health.on_published(arrival)

    def _robot_in_odom(self, robot_pose: Tuple[float, float, float]) -> List[float]:
        """Return the robot's own pose relative to where it was when this session began."""
        ox, oy, oth = self._robot_origin
        bx, by, bth = self._robot_base
        dx, dy = robot_pose[0] - ox, robot_pose[1] - oy
        c, s = math.cos(bth - oth), math.sin(bth - oth)
        return [bx + c * dx - s * dy, by + s * dx + c * dy, bth + robot_pose[2] - oth]

    def _battery(self, stamp: int, volts: float) -> BatteryState:
        msg = BatteryState()
        msg.header.stamp = ns_to_stamp(stamp)
        msg.header.frame_id = self.base_frame
        msg.voltage = float(volts)
        msg.temperature = msg.current = msg.charge = msg.capacity = math.nan
        msg.design_capacity = msg.percentage = math.nan
        msg.power_supply_status = BatteryState.POWER_SUPPLY_STATUS_DISCHARGING
        msg.power_supply_health = (BatteryState.POWER_SUPPLY_HEALTH_DEAD
                                   if volts < self.battery_error
                                   else BatteryState.POWER_SUPPLY_HEALTH_GOOD)
        msg.power_supply_technology = BatteryState.POWER_SUPPLY_TECHNOLOGY_UNKNOWN
        msg.present = True
        return msg

    def _broadcast(self, stamp: int, pose) -> None:
        self.tf.sendTransform(make_transform(stamp, self.odom_frame, self.base_frame, pose))

    def robot_status(self) -> List[Tuple[str, str, Status]]:
        """Return the robot's diagnostic entry (battery, motors, stall, bumpers)."""
        client = self.client
        with self._lock:
            status = self._status if client.is_open else None
            robot = client.robot
        values = {'state': client.state, 'handshakes': str(client.handshakes),
                  'sync retries': str(client.sync_retries),
                  'closes sent to a still-open robot': str(client.closes_sent),
                  'watchdog stops': str(client.watchdog_stops),
                  'lost status packets': str(client.lost_packets)}
        if robot is not None:
            values['robot'] = f'{robot.name} ({robot.robot_class} {robot.subclass})'
        if status is None:
            return [('base_driver: robot', self.link.transport.url,
                     (WARN, f'not connected ({client.state})', values))]
        level, problems = OK, []
        volts = status.battery_v
        values.update({'battery [V]': f'{volts:.1f}',
                       'motors': 'enabled' if status.motors_enabled else 'disabled',
                       'sonar arrays': f'{status.sonar_arrays:04b}',
                       'left stall': str(status.left_stall),
                       'right stall': str(status.right_stall),
                       'front bumpers': f'{status.front_bumpers:07b}',
                       'rear bumpers': f'{status.rear_bumpers:07b}',
                       'e-stop': str(status.estop)})
        if volts < self.battery_error:
            level, problems = ERROR, [f'battery {volts:.1f} V']
        elif volts < self.battery_warn:
            level, problems = WARN, [f'battery low {volts:.1f} V']
        for flag, text in ((status.left_stall or status.right_stall, 'wheel stalled'),
                           (status.front_bumpers or status.rear_bumpers, 'bumper pressed'),
                           (status.estop, 'e-stop pressed'),
                           (client.motors_wanted and not status.motors_enabled,
                            'motors disabled (press MOTORS or call ~/enable_motors)')):
            if flag:
                level = max(level, WARN)
                problems.append(text)
        message = '; '.join(problems) if problems else 'OK'
        return [('base_driver: robot', self.link.transport.url, (level, message, values))]

    # --- ROS callbacks ------------------------------------------------------------------------

    def on_cmd_vel(self, msg: Twist) -> None:
        """Send a velocity command (VEL + RVEL or VEL2)."""
        try:
            with self._lock:
                data = self.client.velocity(float(msg.linear.x), float(msg.angular.z),
                                            time.monotonic())
                is_open = self.client.is_open
        except ValueError as err:
            self.stats.drop('malformed', f'Dropping cmd_vel: {err}')
            return
        if not is_open:
            self.stats.drop('not_connected', 'Dropping cmd_vel: the robot is not connected '
                            f'({self.link.transport.url}); send it again once connected')
            return
        self._send(data)
        self.stats.processed()

    def on_enable_motors(self, request: SetBool.Request,
                         response: SetBool.Response) -> SetBool.Response:
        """Enable or disable the motors (remembered across reconnects)."""
        with self._lock:
            data = self.client.set_motors(request.data, time.monotonic())
            is_open = self.client.is_open
        sent = bool(data) and self.link.write(data)
        response.success = bool(sent)
        state = 'enable' if request.data else 'disable'
        response.message = (f'motors: {state} sent' if sent else
                            f'motors: not connected; will {state} them after connecting'
                            if not is_open else 'motors: write failed')
        return response

    # --- shutdown -------------------------------------------------------------------------------

    def shutdown(self) -> None:
        """Send STOP and CLOSE, stop the I/O thread, close the port (idempotent, no ROS)."""
        if self._closed:
            return
        self._closed = True
        with self._lock:
            farewell = self.client.farewell()
        self.link.stop(farewell=farewell)

    def destroy_node(self) -> None:
        """Shut the robot connection down, then destroy the node."""
        self.shutdown()
        super().destroy_node()


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav base_driver``."""
    return run_node(BaseDriver, args)


if __name__ == '__main__':
    raise SystemExit(main())
