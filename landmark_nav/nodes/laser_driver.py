"""Executable ``laser_driver``: Hokuyo (SCIP 2.0) or SICK LMS2xx laser on a serial port or URL.

Publishes ``scan`` (sensor_msgs/LaserScan, sensor-data QoS, frame ``frame_id``): angles of
the window snapped to sensor steps (SCIP) or values (LMS), ``time_increment`` between
values, ``scan_time`` between published scans, the sensor's range limits, REP 117 ranges
(+inf no return, -inf too close, NaN error) and, with ``intensity`` on a sensor that has
them (UTM-30LX), intensities. The stamp is the time of the first value: sensor clock (SCIP
24-bit millisecond counter, unwrapped) or revolution count (LMS), mapped to host time by a
min filter on arrival time minus sweep and transfer time, plus ``time_offset``.

Publishes ``/diagnostics`` (diagnostic_msgs/DiagnosticArray, every ``diagnostics_period``):
connection, port, reconnects, frames, protocol errors, publish rate, sensor identity and
hardware status; ERROR while the port is closed or silent for ``stale_error``, WARN while
silent for ``stale_warn`` or for ``problem_hold`` after a protocol error or a lost scan.

The port is opened in a background thread and reopened with back-off whenever it fails or
disappears, so a missing port is logged (with the fix for permission problems) and retried,
never fatal. Bad parameters stop the node at start-up with exit code 2. The protocol logic
is in :mod:`landmark_nav.drivers.laser_session`.
"""

import math
import time

from landmark_nav.conversions import ConversionError, make_scan
from landmark_nav.drivers.laser_session import make_session, Output
from landmark_nav.nodes.common import (declare, ParameterError, ProblemWarner, reject_undeclared,
                                       run_node, SENSOR_QOS)
from landmark_nav.nodes.driver_common import (declare_link_parameters, DeviceLink,
                                              DiagnosticsPublisher, LinkHealth, make_transport)
from rclpy.node import Node
from sensor_msgs.msg import LaserScan

DEFAULT_PORTS = {'scip2': '/dev/ttyACM0', 'lms2xx': '/dev/ttyUSB0'}


class LaserDriver(Node):
    """Thin node: serial link -> protocol session -> LaserScan and diagnostics."""

    def __init__(self, **kwargs) -> None:
        """Declare and validate the parameters, create the publishers, start the I/O thread."""
        super().__init__('laser_driver', **kwargs)
        d = declare
        protocol = d(self, 'protocol', 'scip2', 'scip2 (Hokuyo URG/UTM) or lms2xx (SICK '
                     'LMS200/291)', choices=['scip2', 'lms2xx'])
        scip = protocol == 'scip2'
        link = declare_link_parameters(
            self, DEFAULT_PORTS[protocol], 0 if scip else 38400,
            baud_choices=None if not scip else (0, 19200, 38400, 57600, 115200, 250000,
                                                500000, 750000),
            baud_description='scip2: RS-232 baud rate, 0 for USB or TCP (default); lms2xx: '
                             '9600, 19200, 38400 (default) or 500000')
        if not scip and link['baud'] not in (9600, 19200, 38400, 500000):
            raise ParameterError(f'parameter baud = {link["baud"]}: lms2xx needs 9600, 19200, '
                                 '38400 or 500000')
        self.frame_id = d(self, 'frame_id', 'laser', 'frame of the scans')
        common = {
            'angle_min': d(self, 'angle_min', -math.pi, 'first angle of the window [rad] '
                           '(snapped inwards to the sensor steps)', (-math.pi, math.pi)),
            'angle_max': d(self, 'angle_max', math.pi, 'last angle of the window [rad]',
                           (-math.pi, math.pi)),
            'time_offset': d(self, 'time_offset', 0.0, 'added to every stamp [s]', (-1.0, 1.0)),
            'restart_after': link['stale_error'],
        }
        cluster = d(self, 'cluster', 1, 'scip2: adjacent steps merged into one value',
                    (1, 99))
        skip = d(self, 'skip', 0, 'scip2: scans skipped between published scans', (0, 9))
        intensity = d(self, 'intensity', False, 'scip2: publish intensities (ME; falls back '
                      'to MD if the sensor has none)')
        calibrate = d(self, 'calibrate_time', True, 'scip2: measure the sensor clock offset '
                      'with TM round trips at every connection')
        variant = d(self, 'variant', 180, 'lms2xx: scanning angle [deg], 100 or 180', (100, 180))
        resolution = d(self, 'resolution', 0.5, 'lms2xx: angular resolution [deg], 0.25, 0.5 '
                       'or 1 (0.25 only with variant 100)', (0.25, 1.0))
        units = d(self, 'units', 'mm', 'lms2xx: distance units, mm (8 m range) or cm (80 m)',
                  choices=['mm', 'cm'])
        reject_undeclared(self)
        if not scip and variant not in (100, 180):
            raise ParameterError(f'parameter variant = {variant}: must be 100 or 180')
        if not scip and resolution not in (0.25, 0.5, 1.0):
            raise ParameterError(f'parameter resolution = {resolution}: must be 0.25, 0.5 or 1')
        if not scip and (variant, resolution) == (180, 0.25):
            raise ParameterError('parameters variant and resolution: 180 deg / 0.25 deg is not '
                                 'supported by the LMS2xx (use variant 100)')
        if scip:
            settings = dict(common, cluster=cluster, skip=skip, intensity=intensity,
                            calibrate_time=calibrate, baud=link['baud'])
        else:
            settings = dict(common, angle_deg=variant, units=units, baud=link['baud'],
                            resolution_cdeg=int(round(resolution * 100)))
        try:
            self.session = make_session(protocol, **settings)
        except ValueError as err:
            raise ParameterError(f'laser_driver parameters: {err}') from err
        self.warner = ProblemWarner(self)
        self.health = LinkHealth(link['port'], link['stale_warn'], link['stale_error'],
                                 link['problem_hold'])
        self.health.set_value('protocol', protocol)
        self.publisher = self.create_publisher(LaserScan, 'scan', SENSOR_QOS)
        self.diagnostics = DiagnosticsPublisher(
            self, f'{self.get_name()}: laser ({protocol})', link['port'], self.health,
            link['diagnostics_period'])
        s = self.session
        self.link = DeviceLink(
            make_transport(link), s.decoder, lambda f, now: self.apply(s.frame(f, now)),
            self.health, on_connect=lambda: self.apply(s.connect(time.monotonic())),
            on_tick=lambda now: self.apply(s.tick(now)),
            on_error=lambda e, now: self.apply(s.error(e, now)), logger=self.get_logger(),
            alive=self.context.ok)
        self.link.start()
        self.get_logger().info(f'laser_driver: {protocol} on {link["port"]}')

    def apply(self, out: Output) -> None:
        """Carry out what the session asked for (runs in the I/O thread)."""
        if out.baud is not None:
            self.link.set_baudrate(out.baud)
        for data in out.writes:
            self.link.write(data)
        for text in out.info:
            self.get_logger().info(text)
        for text in out.problems:
            self.health.on_problem(text)
            self.warner.warn(text)
        if out.hardware is not None:
            self.health.set_hardware(*out.hardware)
        for key, value in out.values.items():
            self.health.set_value(key, value)
        for scan in out.scans:
            self.publish(scan)
        if out.reconnect:
            self.link.reconnect(out.reconnect)

    def publish(self, scan) -> None:
        """Publish one scan, its monotonic stamp moved onto the ROS clock."""
        stamp_ns = int(round(scan.stamp * 1e9)) + self._monotonic_to_ros()
        try:
            msg = make_scan(stamp_ns, self.frame_id, scan.angle_min, scan.angle_increment,
                            scan.ranges, scan.range_min, scan.range_max, scan.time_increment,
                            scan.scan_time, scan.intensities)
        except ConversionError as err:
            self.health.on_drop('malformed', f'Dropping scan: {err}')
            self.warner.warn(f'Dropping scan: {err}')
            return
        if not self.context.ok():
            return  # shutting down: the I/O thread outlives the context by a few ms
        self.publisher.publish(msg)
        self.health.on_published()

    def _monotonic_to_ros(self) -> int:
        """Return ROS time minus monotonic time [ns], read between two monotonic readings.

        The pair with the shortest bracket is used, so a preemption between the readings
        does not shift the stamp.
        """
        best = None
        for _ in range(3):
            before = time.monotonic_ns()
            ros_now = self.get_clock().now().nanoseconds
            after = time.monotonic_ns()
            if best is None or after - before < best[0]:
                best = (after - before, ros_now - (before + after) // 2)
            if after - before < 20_000:
                break
        return best[1]

    def destroy_node(self) -> None:
        """Stop the stream (QT / 20 25), close the port, destroy the node."""
        link = getattr(self, 'link', None)
        if link is not None:
            link.stop(farewell=self.session.farewell())
        super().destroy_node()


def main(args=None) -> int:
    """Run ``ros2 run landmark_nav laser_driver``."""
    return run_node(LaserDriver, args)


if __name__ == '__main__':
    raise SystemExit(main())
