"""Shared parts of the serial driver nodes: link health, diagnostics and the device I/O loop.

* :class:`LinkHealth` (no ROS) keeps the counters of one device link (frames, protocol
  errors, reconnects, bytes, published messages) and turns them into a diagnostic level:
  ERROR while the port is closed or silent for ``stale_error_s``, WARN when silent for
  ``stale_warn_s`` or for ``problem_hold_s`` after a protocol error or another reported
  problem (a lost scan, a missing ACK, a hardware warning), else OK.
* :class:`DiagnosticsPublisher` publishes that state as diagnostic_msgs/DiagnosticArray on
  ``/diagnostics`` (one DiagnosticStatus, about 1 Hz) with the key/values connection, port,
  reconnects, frames, errors, bytes, publish rate, seconds since the last frame, last error,
  ``dropped.<reason>`` (device data received but not published, :meth:`LinkHealth.on_drop`)
  and whatever the driver adds (model, firmware, hardware status ...).
* :class:`DeviceLink` runs a thread that keeps the port open
  (:meth:`SerialTransport.ensure_open`, with back-off; a missing port is retried forever),
  reads, feeds a stream decoder (``feed(bytes) -> [frame | ProtocolError]``, ``reset()``),
  hands each frame to the driver with its arrival time, counts protocol errors, calls the
  driver's ``on_tick`` about every ``tick_s`` (handshake timeouts, keep-alives, watchdogs) and
  on reconnect resets the decoder and calls ``on_connect`` so the driver restarts its
  handshake. Callback exceptions are logged (throttled) and never end the thread.

Levels are the byte values of diagnostic_msgs/DiagnosticStatus (OK 0, WARN 1, ERROR 2,
STALE 3).
"""

from collections import Counter, deque
import math
import threading
import time
import traceback
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from landmark_nav.conversions import ns_to_stamp
from landmark_nav.drivers.errors import ProtocolError
from landmark_nav.drivers.transport import SerialTransport, TransportError
from landmark_nav.heap import release_free_heap
from landmark_nav.nodes.common import declare, ParameterError
from rclpy.node import Node

OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}
Status = Tuple[int, str, Dict[str, str]]


class LinkHealth:
    """Counters and diagnostic level of one device link (thread-safe, no ROS).

    Args:
        port: Port or URL, reported as is.
        stale_warn_s: WARN when no frame arrived for this long while connected [s].
        stale_error_s: ERROR when no frame arrived for this long while connected [s].
        problem_hold_s: A protocol error or reported problem keeps WARN this long [s].
        rate_window_s: Window of the publish-rate estimate [s].
        clock: Monotonic clock [s].
    """

    def __init__(self, port: str, stale_warn_s: float = 0.5, stale_error_s: float = 2.0,
                 problem_hold_s: float = 2.0, rate_window_s: float = 5.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        """Start in the "not connected" state."""
        if not 0.0 < stale_warn_s <= stale_error_s:
            raise ValueError(f'need 0 < stale_warn_s <= stale_error_s, got {stale_warn_s} '
                             f'and {stale_error_s}')
        self.port = port
        self.stale_warn_s = stale_warn_s
        self.stale_error_s = stale_error_s
        self.problem_hold_s = problem_hold_s
        self.rate_window_s = rate_window_s
        self._clock = clock
        self._lock = threading.Lock()
        self.connected = False
        self.connected_at = -math.inf
        self.last_frame = -math.inf
        self.last_problem = -math.inf
        self.problem = ''
        self.last_error = ''
        self.frames = 0
        self.errors = 0
        self.problems = 0
        self.reconnects = 0
        self.bytes = 0
        self.published = 0
        self.dropped: Counter = Counter()  # device data not published, per reason
        self._publish_times: deque = deque()
        self.hardware: Tuple[int, str] = (OK, '')
        self.values: Dict[str, str] = {}

    # --- events (called from the I/O thread or the node) --------------------------------

    def on_connected(self, now: Optional[float] = None) -> None:
        """Record that the port was (re)opened."""
        now = self._now(now)
        with self._lock:
            if self.connected_at > -math.inf:
                self.reconnects += 1
            self.connected = True
            self.connected_at = now

    def on_disconnected(self, reason: str, now: Optional[float] = None) -> None:
        """Record that the port is closed (``reason`` is the transport's message)."""
        with self._lock:
            self.connected = False
            if reason:
                self.last_error = reason

    def on_bytes(self, count: int) -> None:
        """Count received bytes."""
        with self._lock:
            self.bytes += count

    def on_frame(self, now: Optional[float] = None) -> None:
        """Record a good frame."""
        now = self._now(now)
        with self._lock:
            self.frames += 1
            self.last_frame = now

    def on_error(self, error: BaseException, now: Optional[float] = None) -> None:
        """Record a protocol error (bad checksum, garbage, truncated frame ...)."""
        now = self._now(now)
        with self._lock:
            self.errors += 1
            self.last_problem = now
            self.problem = f'protocol error: {error}'
            self.last_error = str(error)

    def on_problem(self, text: str, now: Optional[float] = None) -> None:
        """Record another problem that deserves a WARN for a while (e.g. a lost scan)."""
        now = self._now(now)
        with self._lock:
            self.problems += 1
            self.last_problem = now
            self.problem = text

    def on_drop(self, reason: str, text: str, now: Optional[float] = None) -> None:
        """Count device data that was received but not published (``dropped.<reason>``)."""
        self.on_problem(text, now)
        with self._lock:
            self.dropped[reason] += 1

    def on_published(self, now: Optional[float] = None) -> None:
        """Count one published output message (for the publish rate)."""
        now = self._now(now)
        with self._lock:
            self.published += 1
            self._publish_times.append(now)
            self._trim(now)

    def set_hardware(self, level: int, message: str) -> None:
        """Set the device's own health (e.g. the sensor's status line); OK clears it."""
        with self._lock:
            self.hardware = (int(level), message)

    def set_value(self, key: str, value: Any) -> None:
        """Add or replace a key/value shown in the diagnostics (model, firmware ...)."""
        with self._lock:
            self.values[key] = str(value)

    # --- state ----------------------------------------------------------------------------

    def _now(self, now: Optional[float]) -> float:
        return self._clock() if now is None else now

    def _trim(self, now: float) -> None:
        times = self._publish_times
        while times and times[0] < now - self.rate_window_s:
            times.popleft()

    def publish_rate(self, now: Optional[float] = None) -> float:
        """Return the output rate over the last window [Hz] (0 with fewer than 2 messages)."""
        now = self._now(now)
        with self._lock:
            self._trim(now)
            times = list(self._publish_times)
        if len(times) < 2 or times[-1] <= times[0]:
            return 0.0
        return (len(times) - 1) / (times[-1] - times[0])

    def since_frame(self, now: Optional[float] = None) -> float:
        """Return the time since the last good frame, or since the connection [s]."""
        now = self._now(now)
        with self._lock:
            return now - max(self.last_frame, self.connected_at)

    def status(self, now: Optional[float] = None) -> Status:
        """Return ``(level, message, key/values)`` of the link at ``now``."""
        now = self._now(now)
        rate = self.publish_rate(now)
        silent = self.since_frame(now)
        with self._lock:
            if not self.connected:
                level, message = ERROR, ('port closed: ' + self.last_error
                                         if self.last_error else 'port closed: connecting')
            elif silent >= self.stale_error_s:
                level, message = ERROR, f'no data for {silent:.1f} s'
            elif silent >= self.stale_warn_s:
                level, message = WARN, f'no data for {silent:.1f} s'
            elif now - self.last_problem < self.problem_hold_s:
                level, message = WARN, self.problem
            else:
                level, message = OK, 'receiving'
            hw_level, hw_message = self.hardware
            if hw_level > level:
                level, message = hw_level, hw_message
            values = {
                'connection': 'open' if self.connected else 'closed',
                'port': self.port,
                'reconnects': str(self.reconnects),
                'frames': str(self.frames),
                'errors': str(self.errors),
                'problems': str(self.problems),
                'bytes': str(self.bytes),
                'published': str(self.published),
                'publish rate [Hz]': f'{rate:.2f}',
                'since last frame [s]': (f'{silent:.2f}' if math.isfinite(silent) else 'never'),
                'last error': self.last_error,
                'hardware status': hw_message or 'OK',
            }
            values.update({f'dropped.{k}': str(v) for k, v in sorted(self.dropped.items())})
            values.update(self.values)
        return level, message, values


def make_diagnostic_array(stamp_ns: int, statuses: Iterable[Tuple[str, str, Status]]
                          ) -> DiagnosticArray:
    """Build a DiagnosticArray from ``(name, hardware_id, (level, message, values))``."""
    msg = DiagnosticArray()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    for name, hardware_id, (level, message, values) in statuses:
        status = DiagnosticStatus(level=bytes((int(level),)), name=name, message=message,
                                  hardware_id=hardware_id)
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg.status.append(status)
    return msg


class DiagnosticsPublisher:
    """Publish a driver's :class:`LinkHealth` on ``/diagnostics`` from a node timer.

    Args:
        node: The driver node.
        name: DiagnosticStatus name, e.g. ``'laser_driver: connection'``.
        hardware_id: E.g. the port or the sensor's serial number.
        health: The link state to report.
        period_s: Publishing period [s] (about 1 Hz by convention).
        extra: Optional callable returning more ``(name, hardware_id, status)`` entries.
    """

    def __init__(self, node: Node, name: str, hardware_id: str, health: LinkHealth,
                 period_s: float = 1.0,
                 extra: Optional[Callable[[], List[Tuple[str, str, Status]]]] = None) -> None:
        """Create the publisher and the timer."""
        self.node = node
        self.name = name
        self.hardware_id = hardware_id
        self.health = health
        self.extra = extra
        self.publisher = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.timer = node.create_timer(period_s, self.publish)
        self.last: Optional[Status] = None

    def publish(self) -> None:
        """Publish the current state now (and return free heap, :func:`release_free_heap`)."""
        release_free_heap()
        status = self.health.status()
        self.last = status
        entries = [(self.name, self.hardware_id, status)]
        if self.extra is not None:
            entries += self.extra()
        self.publisher.publish(make_diagnostic_array(
            self.node.get_clock().now().nanoseconds, entries))


def make_transport(values: Dict[str, Any], timeout: float = 0.02) -> SerialTransport:
    """Build the transport from :func:`declare_link_parameters` values (short read timeout)."""
    backoff_max = float(values['reconnect_max'])
    baud = int(values['baud']) or 115200  # 0: USB/TCP link, the rate does not matter
    return SerialTransport(values['port'], baudrate=baud, timeout=timeout,
                           backoff_min=min(0.25, backoff_max), backoff_max=backoff_max)


def declare_link_parameters(node: Node, default_port: str, default_baud: int,
                            baud_choices: Optional[Iterable[int]] = None,
                            baud_description: str = '') -> Dict[str, Any]:
    """Declare the parameters every serial driver shares and return their values.

    ``port`` (device path or pyserial URL), ``baud`` (0 allowed if ``baud_choices`` holds it:
    a USB or TCP link), ``diagnostics_period`` [s],
    ``stale_warn`` / ``stale_error`` [s] (silence before WARN / ERROR), ``problem_hold`` [s]
    (how long a protocol error keeps WARN), ``reconnect_max`` [s] (largest back-off between
    attempts to open the port).

    Raises:
        ParameterError: For an empty port, a baud rate not in ``baud_choices`` or
            inconsistent timeouts.
    """
    d = declare
    values = {
        'port': d(node, 'port', default_port, 'serial device (/dev/ttyACM0, '
                  '/dev/serial/by-id/...) or pyserial URL (socket://host:port, rfc2217://...)'),
        'baud': d(node, 'baud', default_baud, baud_description or 'serial baud rate [bit/s] '
                  '(ignored by USB and TCP links)', (0, 10_000_000)),
        'diagnostics_period': d(node, 'diagnostics_period', 1.0, 'period of /diagnostics [s]',
                                (0.01, 60.0)),
        'stale_warn': d(node, 'stale_warn', 0.5, 'no frame for this long -> WARN [s]',
                        (0.01, 60.0)),
        'stale_error': d(node, 'stale_error', 2.0, 'no frame for this long -> ERROR, and the '
                         'driver restarts its handshake [s]', (0.01, 600.0)),
        'problem_hold': d(node, 'problem_hold', 2.0, 'a protocol error keeps /diagnostics at '
                          'WARN this long [s]', (0.0, 600.0)),
        'reconnect_max': d(node, 'reconnect_max', 1.0, 'largest delay between attempts to '
                           'open the port [s] (the first retry comes after 0.25 s, then the '
                           'delay doubles)', (0.05, 60.0)),
    }
    if not values['port'].strip():
        raise ParameterError('parameter port: empty; give a device path or a URL')
    choices = tuple(baud_choices) if baud_choices is not None else None
    if values['baud'] == 0 and (choices is None or 0 not in choices):
        raise ParameterError('parameter baud = 0: give the serial baud rate')
    if choices is not None and values['baud'] not in choices:
        raise ParameterError(f'parameter baud = {values["baud"]} is not one of '
                             f'{", ".join(str(c) for c in choices)}')
    if values['stale_warn'] > values['stale_error']:
        raise ParameterError('parameters stale_warn and stale_error: need stale_warn <= '
                             'stale_error')
    return values


class DeviceLink:
    """Thread that owns a :class:`SerialTransport`: open, read, decode, dispatch.

    Args:
        transport: The port (not yet open).
        decoder: Stream decoder with ``feed(bytes) -> list`` and ``reset()``.
        on_frame: ``on_frame(frame, arrival_time)`` for every decoded frame (I/O thread);
            ``arrival_time`` is the clock reading right after the read that completed it.
        health: Counters and level (see :class:`LinkHealth`).
        on_connect: Called after every (re)open, once the decoder is reset: send the
            handshake here.
        on_disconnect: Called when the port was lost (argument: the reason).
        on_tick: ``on_tick(now)`` about every ``tick_s`` while the port is open.
        on_error: ``on_error(error, now)`` for every protocol error (after counting it).
        logger: rclpy logger (or anything with ``info``/``warning``/``error``) or None.
        tick_s: Period of ``on_tick`` [s].
        clock: Monotonic clock [s].
        alive: Whether the node can still publish (e.g. ``node.context.ok``); callback
            failures after it turns False (shutdown in progress) are not logged.
    """

    def __init__(self, transport: SerialTransport, decoder: Any,
                 on_frame: Callable[[Any, float], None], health: LinkHealth,
                 on_connect: Optional[Callable[[], None]] = None,
                 on_disconnect: Optional[Callable[[str], None]] = None,
                 on_tick: Optional[Callable[[float], None]] = None,
                 on_error: Optional[Callable[[ProtocolError, float], None]] = None,
                 logger: Any = None, tick_s: float = 0.02,
                 clock: Callable[[], float] = time.monotonic,
                 alive: Optional[Callable[[], bool]] = None) -> None:
        """Configure; call :meth:`start` to run."""
        self.alive = alive
        self.transport = transport
        self.decoder = decoder
        self.on_frame = on_frame
        self.health = health
        self.on_connect = on_connect
        self.on_disconnect = on_disconnect
        self.on_tick = on_tick
        self.on_error = on_error
        self.logger = logger
        self.tick_s = tick_s
        self._clock = clock
        self._stop = threading.Event()
        self._write_lock = threading.Lock()
        self._thread: Optional[threading.Thread] = None
        self._was_open = False
        self._last_open_error = ''
        self._last_log: Dict[str, float] = {}

    # --- public ----------------------------------------------------------------------------

    def start(self) -> 'DeviceLink':
        """Start the I/O thread; return self."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name='device-link', daemon=True)
        self._thread.start()
        return self

    def stop(self, farewell: bytes = b'', timeout: float = 2.0) -> None:
        """Stop the thread, write ``farewell`` (e.g. stop commands) if open, close the port."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=timeout)
        self._thread = None
        if farewell and self.transport.connected:
            self.write(farewell)
        self.transport.close()

    @property
    def running(self) -> bool:
        """Whether the I/O thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    @property
    def connected(self) -> bool:
        """Whether the port is open."""
        return self.transport.connected

    def write(self, data: bytes) -> bool:
        """Write to the device (any thread); return False if the port is closed or failed."""
        if not data:
            return True
        with self._write_lock:
            if not self.transport.connected:
                return False
            try:
                self.transport.write(data)
                return True
            except TransportError as err:
                self._log('warning', f'write failed: {err}')
                return False

    def set_baudrate(self, baud: int) -> None:
        """Change the line rate of the open port now and of every later (re)open."""
        with self._write_lock:
            self.transport.baudrate = int(baud)
            # SerialTransport keeps no public handle on the open port; pyserial ports apply
            # a new baudrate attribute immediately (URL ports ignore it).
            port = getattr(self.transport, '_port', None)
            if port is not None:
                try:
                    port.baudrate = int(baud)
                except (ValueError, OSError) as err:
                    self._log('warning', f'cannot set {baud} baud: {err}')

    def reconnect(self, reason: str) -> None:
        """Close the port so the thread reopens it (and restarts the handshake)."""
        self._log('warning', f'reopening {self.transport.url}: {reason}')
        with self._write_lock:
            self.transport.close()

    # --- thread ------------------------------------------------------------------------------

    def _log(self, level: str, text: str, throttle_s: float = 0.0) -> None:
        if self.logger is None:
            return
        now = time.monotonic()
        if throttle_s > 0.0:
            key = level + text[:40]
            if now - self._last_log.get(key, -math.inf) < throttle_s:
                return
            self._last_log[key] = now
        # one call site per severity: an rclpy logger refuses a second severity at a site
        if level == 'error':
            self.logger.error(text)
        elif level == 'warning':
            self.logger.warning(text)
        else:
            self.logger.info(text)

    def _call(self, what: str, fn: Callable, *args) -> None:
        """Run a driver callback; log its exceptions (throttled) instead of dying."""
        try:
            fn(*args)
        except Exception as err:  # the I/O thread must survive driver bugs
            if self.alive is not None and not self.alive():
                return  # shutting down: publishing fails by design
            self._log('error', f'{what} failed: {err!r}\n{traceback.format_exc(limit=4)}',
                      throttle_s=5.0)

    def _opened(self) -> None:
        self._was_open = True
        self._last_open_error = ''
        self.decoder.reset()
        self.health.on_connected(self._clock())
        self._log('info', f'opened {self.transport.url}')
        if self.on_connect is not None:
            self._call('on_connect', self.on_connect)

    def _lost(self, reason: str) -> None:
        self._was_open = False
        self.health.on_disconnected(reason, self._clock())
        self._log('warning', f'lost {self.transport.url}: {reason}; reopening')
        if self.on_disconnect is not None:
            self._call('on_disconnect', self.on_disconnect, reason)

    def _run(self) -> None:
        next_tick = self._clock()
        while not self._stop.is_set():
            if not self.transport.connected:
                if self._was_open:
                    self._lost(self.transport.last_error or 'port closed')
                if not self.transport.ensure_open():
                    error = self.transport.last_error
                    self.health.on_disconnected(error)
                    if error and error != self._last_open_error:
                        self._log('error', f'{error}; retrying')
                        self._last_open_error = error
                    self._stop.wait(0.05)
                    continue
                self._opened()
            try:
                data = self.transport.read(65536)
            except TransportError as err:
                self.health.on_disconnected(str(err))
                continue
            now = self._clock()
            if data:
                self.health.on_bytes(len(data))
                self._call('decode', self._dispatch, data, now)
            if self.on_tick is not None and now >= next_tick:
                next_tick = now + self.tick_s
                self._call('on_tick', self.on_tick, now)

    def _dispatch(self, data: bytes, now: float) -> None:
        for item in self.decoder.feed(data):
            if isinstance(item, ProtocolError):
                self.health.on_error(item, now)
                self._log('warning', f'{self.transport.url}: {item}', throttle_s=2.0)
                if self.on_error is not None:
                    self._call('on_error', self.on_error, item, now)
            else:
                self.health.on_frame(now)
                self._call('on_frame', self.on_frame, item, now)
