"""Small helpers shared by the nodes: typed parameters, QoS, warnings, statistics, main().

* :func:`declare` / :func:`declare_dataclass`: read-only typed parameters with descriptors;
  a wrong value or type is a :class:`ParameterError` naming the parameter (one line, exit 2).
* :class:`ProblemWarner`: bad-input warnings throttled per kind of problem.
* :class:`InputStats`: processed / dropped inputs and latency percentiles of a node, on
  ``/diagnostics`` and in throttled warnings.
* :func:`limit_threads`: numerical libraries single-threaded unless configured.
* :func:`~landmark_nav.heap.release_free_heap` runs from the nodes' 1 Hz diagnostics timers
  (:class:`InputStats`, the drivers' ``DiagnosticsPublisher``).
* :func:`run_node`: the standard main (threads, undeclared parameter names refused
  (:func:`reject_undeclared`), spin, clean shutdown on SIGINT / SIGTERM);
  :func:`destroy_and_shutdown` its bounded shutdown.
"""

from collections import Counter, deque
import faulthandler
import math
import os
from pathlib import Path
import re
import signal
import sys
import threading
import time
from typing import Callable, Optional, Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from landmark_nav.conversions import (ConversionError, pose_with_covariance_to_pose,
                                      scan_to_data)
from landmark_nav.heap import release_free_heap
from landmark_nav.parameter_names import unknown_parameter
from landmark_nav.parameter_tables import (dataclass_parameters, field_value, name_parameters,
                                           READ_ONLY_NOTE)
import numpy as np
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType)
import rclpy
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy

SENSOR_QOS = qos_profile_sensor_data
#: Laser scans: the sensor-data QoS (best effort, keep last) with a queue of 0.5 s of a
#: 40 Hz laser instead of its 5 (125 ms): a node that is briefly denied the CPU (another
#: process, its own start-up) catches up instead of losing scans; one that is slower than
#: the laser on average still loses them, counted and warned.
SCAN_DEPTH = 20
SCAN_QOS = QoSProfile(depth=SCAN_DEPTH, reliability=ReliabilityPolicy.BEST_EFFORT,
                      history=HistoryPolicy.KEEP_LAST)
#: Queue of ekf_slam's feature topics (scan, corners/features, and the corner cloud's
#: publisher): 2 s of a 40 Hz laser. Between keyframes a set costs ekf_slam little, a
#: keyframe's update several scan periods, and more on a loaded machine: the queue carries
#: the scans that come meanwhile (with 0.5 s, a 5-minute live run at 40 Hz at load 24 on two
#: cores lost 42 of 3575 sets while ekf_slam used 12 % of one core).
FEATURE_DEPTH = 4 * SCAN_DEPTH
WARN_THROTTLE_S = 5.0
THREADS_ENV = 'LANDMARK_NAV_THREADS'
LIBRARY_THREAD_ENVS = ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS',
                       'BLIS_NUM_THREADS')
_TYPE_NAMES = {ParameterType.PARAMETER_BOOL: 'a bool (true / false)',
               ParameterType.PARAMETER_INTEGER: 'an integer',
               ParameterType.PARAMETER_DOUBLE: 'a double',
               ParameterType.PARAMETER_STRING: 'a string',
               ParameterType.PARAMETER_DOUBLE_ARRAY: 'a list of doubles',
               ParameterType.PARAMETER_STRING_ARRAY: 'a list of strings'}

_TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}


class ParameterError(ValueError):
    """A node parameter has a bad value; the message names it."""


def declare(node: Node, name: str, default, description: str,
            limits: Optional[Sequence] = None, choices: Optional[Sequence[str]] = None):
    """Declare a read-only typed parameter with a descriptor and return its value.

    Args:
        node: The node.
        name: Parameter name (snake_case, unit in the name or description).
        default: Default value; its Python type is the parameter type (list = double array).
        description: Shown by ``ros2 param describe``.
        limits: (low, high) inclusive range for numbers.
        choices: Allowed values for strings.

    Raises:
        ParameterError: The value given at start-up is out of range or not a choice.

    """
    descriptor = ParameterDescriptor(description=description + READ_ONLY_NOTE, read_only=True)
    if isinstance(default, list):
        descriptor.type = ParameterType.PARAMETER_DOUBLE_ARRAY
    else:
        descriptor.type = _TYPES[type(default)]
    if limits is not None and isinstance(default, float):
        descriptor.floating_point_range = [
            FloatingPointRange(from_value=float(limits[0]), to_value=float(limits[1]))]
    elif limits is not None and isinstance(default, int) and not isinstance(default, bool):
        descriptor.integer_range = [
            IntegerRange(from_value=int(limits[0]), to_value=int(limits[1]), step=1)]
    if choices is not None:
        descriptor.additional_constraints = 'one of: ' + ', '.join(choices)
    value = _declare(node, name, default, descriptor)
    if choices is not None and value not in choices:
        raise ParameterError(f'parameter {name} = {value!r} is not one of {", ".join(choices)}')
    if isinstance(default, list):
        value = [float(v) for v in value]
    return value


def declare_table(node: Node, table: dict, build: Callable):
    """Declare every parameter of a table ``{name: Parameter}``; return ``build(values)``.

    Raises:
        ParameterError: A value out of its limits or not a choice, or what ``build`` refuses
            with a ValueError (its one-line message).
    """
    values = {name: declare(node, name, p.default, p.description, p.limits, p.choices)
              for name, p in table.items()}
    try:
        return build(values)
    except ValueError as err:
        raise ParameterError(str(err)) from None


def declare_strings(node: Node, name: str, default: list, description: str) -> list:
    """Declare a read-only string-array parameter and return its value."""
    descriptor = ParameterDescriptor(description=description + READ_ONLY_NOTE, read_only=True,
                                     type=ParameterType.PARAMETER_STRING_ARRAY)
    return list(_declare(node, name, default, descriptor))


def _declare(node: Node, name: str, default, descriptor: ParameterDescriptor):
    """Declare one parameter; a bad value or type raises a one-line :class:`ParameterError`."""
    try:
        return node.declare_parameter(name, default, descriptor).value
    except InvalidParameterTypeException as err:
        # the value as given (rclpy keeps the overrides privately; without them, its message)
        given = getattr(node, '_parameter_overrides', {}).get(name)
        kind = None if given is None else _TYPE_NAMES.get(given.type_.value, 'another type')
        got = '' if given is None else f', got {given.value!r} ({kind.split(" (")[0]})'
        if (given is not None and descriptor.type == ParameterType.PARAMETER_DOUBLE
                and given.type_.value == ParameterType.PARAMETER_INTEGER):
            got += f'; write {given.value}.0 for a double'
        raise ParameterError(f'parameter {name}: expected '
                             f'{_TYPE_NAMES.get(descriptor.type, "another type")}{got}') from err
    except InvalidParameterValueException as err:
        # the value as given (rclpy keeps the overrides privately; without them, its message)
        given = getattr(node, '_parameter_overrides', {}).get(name)
        bounds = descriptor.floating_point_range or descriptor.integer_range
        if given is not None and bounds:  # as the offline tools say it (check_value)
            raise ParameterError(f'parameter {name} = {given.value!r} is outside '
                                 f'[{bounds[0].from_value}, {bounds[0].to_value}]') from err
        raise ParameterError(f'parameter {name}: {err}') from err


def limit_threads(default: int = 1) -> Optional[int]:
    """Limit the thread pools of the numerical libraries (BLAS, OpenMP, OpenCV) of a node.

    A node handles one small message at a time: BLAS threads spinning on 3x3 to 100x100
    matrices cost far more CPU than they save. The number of threads is ``default``
    unless configured: the environment variable ``LANDMARK_NAV_THREADS`` sets it for every
    library (threadpoolctl for BLAS / OpenMP, ``cv2.setNumThreads`` or
    ``OPENCV_FOR_THREADS_NUM`` for OpenCV); if it is unset and one of ``OMP_NUM_THREADS``,
    ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS`` or ``BLIS_NUM_THREADS`` is set, the
    libraries are left as configured. Libraries loaded later (the cores import scipy's own
    OpenBLAS on first use) read the limit from ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``,
    ``MKL_NUM_THREADS`` and ``BLIS_NUM_THREADS``, which are set to it.

    Returns:
        The thread limit applied, or None when the libraries were left as configured.

    Raises:
        ParameterError: ``LANDMARK_NAV_THREADS`` is not a positive integer.

    """
    from threadpoolctl import threadpool_limits
    text = os.environ.get(THREADS_ENV, '').strip()
    if text:
        try:
            n = int(text)
            if n < 1:
                raise ValueError
        except ValueError:
            raise ParameterError(f'environment variable {THREADS_ENV}={text!r}: expected a '
                                 'positive integer') from None
    elif any(os.environ.get(v) for v in LIBRARY_THREAD_ENVS):
        return None
    else:
        n = default
    threadpool_limits(limits=n)
    for var in LIBRARY_THREAD_ENVS:  # read by a BLAS / OpenMP library when it is loaded
        os.environ[var] = str(n)
    if 'cv2' in sys.modules:
        sys.modules['cv2'].setNumThreads(n)
    else:  # read by OpenCV when it is imported
        os.environ['OPENCV_FOR_THREADS_NUM'] = str(n)
    return n


#: Seconds the node's destruction may take after the spin ended before the process exits
#: anyway (status 1, the stacks dumped to stderr by :mod:`faulthandler`). Destroying an rcl
#: node after SIGINT / SIGTERM has, rarely and with several nodes starting and stopping on
#: a loaded machine, spun in the middleware (Fast DDS) for more than 30 s (once) and more
#: than 10 s (once: ``line_extractor``, SIGTERM); a node must still stop. Generous, so
#: that a slow teardown ends by itself. The watchdog is native, so it fires even if the
#: stuck call holds the GIL.
SHUTDOWN_TIMEOUT_S = 25.0


def reject_undeclared(node: Node) -> None:
    """Refuse an override (``-p``, ``--params-file``) of a parameter the node did not declare.

    rclpy keeps such an override unused and says nothing, so a misspelt name leaves the
    default in force; the node is started only with names it declares. Each node calls it
    in its constructor right after its last declaration, before it starts anything (a timer,
    a thread, a device link, a model load) or logs that it runs: the error is then the
    node's only output. :func:`run_node` calls it again after the constructor.

    Raises:
        ParameterError: The first unknown name, with the nearest declared one.

    """
    declared = set(node.list_parameters([], 0).names)
    for name in node._parameter_overrides:  # rclpy keeps them there (no public accessor)
        if name not in declared:
            raise ParameterError(unknown_parameter(node.get_name(), name, declared))


HELP_FLAGS = ('-h', '--help')


def help_requested(argv: Sequence[str]) -> bool:
    """Return whether a node's command line (``argv[0]`` the program) asks for ``--help``.

    Only the arguments before ``--ros-args`` count (after it, rcl's own).
    """
    args = list(argv[1:])
    if '--ros-args' in args:
        args = args[:args.index('--ros-args')]
    return any(a in HELP_FLAGS for a in args)


def run_node(factory: Callable[[], Node], args: Optional[Sequence[str]] = None) -> int:
    """Run a node as a standard main: init, spin, shut down; bad parameters exit with 2.

    ``-h`` / ``--help`` (before ``--ros-args``) prints the usage and the node's parameters
    and exits with status 0 (:func:`~landmark_nav.tools.docs_params.node_help`).

    A bad parameter value or an undeclared parameter name (:func:`reject_undeclared`, in
    the node's constructor) is one line on stderr (``error: ...``) and exit status 2.

    Numerical libraries run single-threaded unless configured (:func:`limit_threads`).
    SIGINT (Ctrl-C) and SIGTERM shut rclpy down (its signal handlers) and end the spin; the
    node is then destroyed without a traceback, exit status 0. A destruction still running
    after :data:`SHUTDOWN_TIMEOUT_S` ends the process with status 1 and the stacks on stderr.
    """
    if help_requested(sys.argv if args is None else args):
        from landmark_nav.tools.docs_params import node_help, node_name
        name = node_name(factory)
        if name is not None:
            sys.stdout.write(node_help(name))
            return 0
    node = None
    try:
        limit_threads()
        rclpy.init(args=args)
        node = factory()
        reject_undeclared(node)
        # SIGINT / SIGTERM during the start-up has shut rclpy down: nothing to spin (rclpy's
        # executor, created on the shut-down context, would fail half-built and print a
        # traceback when collected)
        if rclpy.ok():
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ParameterError as err:
        # one write: a driver's I/O thread may be logging to stderr at the same moment
        sys.stderr.write(f'error: {err}\n')
        sys.stderr.flush()
        return 2
    except Exception:
        if rclpy.ok():
            raise
        # A callback running while SIGINT / SIGTERM shut the context down: not an error.
    finally:
        destroy_and_shutdown(node)
    return 0


def destroy_and_shutdown(node: Optional[Node]) -> None:
    """Destroy the node (if any) and shut rclpy down, within :data:`SHUTDOWN_TIMEOUT_S`.

    A destruction still running after that ends the process with status 1 and the stacks
    on stderr (a native :mod:`faulthandler` watchdog); a node already invalid after a
    signal's shutdown is not an error. A second SIGINT / SIGTERM during it (Ctrl-C pressed
    again, a launcher's escalation) is ignored instead of raising ``KeyboardInterrupt`` in
    whatever the destruction waits on (a driver joining its I/O thread): the watchdog bounds
    the shutdown, and SIGKILL still ends it.
    """
    faulthandler.dump_traceback_later(SHUTDOWN_TIMEOUT_S, exit=True)
    restore = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous = signal.signal(sig, signal.SIG_IGN)
            if previous is not None:  # None: a handler not set from Python (left ignored)
                restore[sig] = previous
    try:
        if node is not None:
            try:
                node.destroy_node()
            except Exception:  # already invalid after the shutdown
                pass
        rclpy.try_shutdown()
    finally:
        faulthandler.cancel_dump_traceback_later()
        for sig, handler in restore.items():   # a caller that goes on (a test) gets them back
            signal.signal(sig, handler)


def declare_dataclass(node: Node, cls, docs: dict, prefix: str = '') -> object:
    """Declare one parameter per documented field of a parameter dataclass and build it.

    The dataclass's defaults are the parameters' defaults (one source of truth); its
    ``__post_init__`` validation turns into a :class:`ParameterError` naming the problem.

    Args:
        node: The node.
        cls: A frozen dataclass of algorithm parameters.
        docs: {field: (description, limits or None, choices or None[, auto])}; fields not
            listed keep their defaults and are not exposed. ``auto`` is the parameter value
            standing for a field default of None ("choose automatically"), e.g. 0.0.
        prefix: Prefix for the parameter names (e.g. ``'segmentation.'``).

    """
    values = {}
    for name, p in dataclass_parameters(docs, cls(), prefix).items():
        value = declare(node, name, p.default, p.description, p.limits, p.choices)
        values[name[len(prefix):]] = field_value(p, value)
    try:
        return cls(**values)
    except (TypeError, ValueError) as err:
        raise ParameterError(f'{node.get_name()}: '
                             f'{name_parameters(str(err), {cls.__name__: prefix})}') from err


_NUMBER = re.compile(r'(?<![\w.])[-+]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|inf|nan)(?![\w.])')


def _sign_class(match: re.Match) -> str:
    """Replace a number in a message by its class: 0, +, -, +inf, -inf or nan."""
    value = float(match.group(0))
    if math.isnan(value):
        return 'nan'
    if math.isinf(value):
        return '+inf' if value > 0 else '-inf'
    return '0' if value == 0 else ('+' if value > 0 else '-')


def problem_kind(message: str) -> str:
    """Return the kind of a problem: its message with each number reduced to its class.

    ``angle_increment=0.0`` and ``angle_increment=-0.01`` are different kinds (zero,
    negative); ``stamp 12 ns`` and ``stamp 15 ns`` are the same kind.
    """
    return _NUMBER.sub(_sign_class, message)


class ProblemWarner:
    """Warn about bad input, throttled per kind of problem (not per call site).

    The kind of a problem is its message with every number reduced to its class (zero,
    positive, negative, infinite, NaN; :func:`problem_kind`): repeats of one kind are
    reported at most once per ``period_s``, with the number of repeats suppressed since the
    last report; a problem of another kind, or another class of value (a negative
    ``angle_increment`` after a zero one), is reported at once. The node keeps running.
    """

    def __init__(self, node: Node, period_s: float = WARN_THROTTLE_S) -> None:
        """Attach to a node's logger."""
        self._logger = node.get_logger()
        self._period = period_s
        self._last = {}
        self._suppressed = Counter()
        self.count = 0

    def warn(self, message: str, detail: str = '') -> None:
        """Log a warning unless the same kind of problem was reported recently.

        Args:
            message: The problem; its kind decides the throttling.
            detail: Appended in parentheses, not part of the kind (e.g. a drop rate).
        """
        self.count += 1
        key = problem_kind(message)
        if detail:
            message += f' ({detail})'
        now = time.monotonic()
        if now - self._last.get(key, -math.inf) >= self._period:
            self._last[key] = now
            more = self._suppressed.pop(key, 0)
            if more:
                message += f' ({more} more like this in the last {self._period:g} s)'
            self._logger.warning(message)
        else:
            self._suppressed[key] += 1


def _percentile_ms(values: Sequence[float], q: float) -> float:
    """Return a percentile of latencies [s] in milliseconds (0 when there are none)."""
    if not values:
        return 0.0
    ordered = sorted(values)
    return 1e3 * ordered[min(len(ordered) - 1, int(math.ceil(q / 100.0 * len(ordered))) - 1)]


class LatencyHistogram:
    """Latency percentiles over a whole run in constant memory (log-spaced bins).

    Bin edges grow by ``ratio`` from ``low`` to ``high`` seconds (1 % wide by default:
    about 1400 bins from 10 µs to 1000 s); a percentile is the upper edge of the bin that
    holds it, so it is never below the exact value and at most ``ratio`` above it.
    Latencies below ``low`` fall in the first bin, above ``high`` in the last.
    """

    def __init__(self, low: float = 1e-5, high: float = 1e3, ratio: float = 1.01) -> None:
        """Start empty."""
        self._log_low = math.log(low)
        self._log_ratio = math.log(ratio)
        self._nbins = int(math.ceil((math.log(high) - self._log_low) / self._log_ratio))
        self.counts = np.zeros(self._nbins, dtype=np.int64)
        self.count = 0
        self.max = 0.0

    def add(self, seconds: float) -> None:
        """Count one latency [s]."""
        i = 0 if seconds <= 0.0 else int((math.log(seconds) - self._log_low) / self._log_ratio)
        self.counts[min(max(i, 0), self._nbins - 1)] += 1
        self.count += 1
        self.max = max(self.max, seconds)

    def percentile_ms(self, q: float) -> float:
        """Return the q-th percentile [ms] (0 when empty; at most the largest latency)."""
        if not self.count:
            return 0.0
        rank = max(1, int(math.ceil(q / 100.0 * self.count)))
        i = int(np.searchsorted(np.cumsum(self.counts), rank))
        return 1e3 * min(self.max, math.exp(self._log_low + (i + 1) * self._log_ratio))


def _percent(dropped: int, processed: int) -> float:
    """Return ``dropped`` in percent of ``dropped + processed`` (0 when both are 0)."""
    total = dropped + processed
    return 100.0 * dropped / total if total else 0.0


class InputStats:
    """Count a node's processed and dropped inputs and its latency; report them.

    Subscriptions made with :meth:`subscribe` record when DDS received each message and
    detect messages lost before the callback (gaps in the publisher's sequence numbers:
    a full queue when the node is slower than its input, or a message DDS did not deliver,
    e.g. one too large for best-effort delivery between processes; the node cannot tell
    which) while the topic has one publisher. The node calls :meth:`processed` when an
    input has produced its output and :meth:`drop` (with a warning naming the problem) when
    it skips one. Every
    ``period_s`` a diagnostic_msgs/DiagnosticArray goes out on ``/diagnostics`` with one
    DiagnosticStatus ``<node>: input``: the counts ``processed``, ``dropped`` and
    ``dropped.<reason>`` since start, ``drop_rate_percent`` (dropped of processed plus
    dropped since start), ``latency_p50_ms`` / ``latency_p95_ms`` / ``latency_max_ms`` over
    the last ``window`` processed inputs (from the reception of the input, or of the later
    message it waited for, to the end of its processing), the same over the whole run
    (``latency_run_p50_ms`` / ``latency_run_p95_ms`` / ``latency_run_max_ms``, from a
    :class:`LatencyHistogram`: at most 1 % above the exact percentile), and
    ``before_match.<topic>``: messages its publisher sent before this subscription matched
    it (the first received sequence number minus one; DDS does not deliver them to a
    volatile subscription, so they were never received: reported once in an info line, not
    counted as drops), ``lost.<topic>``: the ``dropped.lost`` messages per topic,
    ``matched.<topic>``: the publishers each subscription is matched with, and the
    counts of :meth:`event`: inputs used, but not as they came
    (``odometry.jump``, ``odometry.covariance_replaced``, ...). Level WARN while inputs were
    dropped in the last period, else OK. Each drop's warning (throttled per kind of problem
    by the node's :class:`ProblemWarner`) ends with the drop rate, of the current period and
    since start with the reasons: a node that cannot keep up says how much it loses.
    """

    def __init__(self, node: Node, warner: ProblemWarner, period_s: float = 1.0,
                 window: int = 1000) -> None:
        """Create the ``/diagnostics`` publisher and its timer."""
        self._node = node
        self.warner = warner
        self.period_s = float(period_s)
        self.processed_count = 0
        self.dropped = Counter()
        self.latencies = deque(maxlen=window)
        self.run_latency = LatencyHistogram()
        self.before_match = Counter()
        self.events = Counter()
        self.lost = Counter()  # messages lost per topic (also in dropped['lost'])
        self._subscriptions = {}
        self.received_ns = 0
        self._last_seq = {}
        self._reported_drops = 0
        self._reported_processed = 0
        # No default QoS-event handlers (waitables the executor scans at every wait of the
        # node; a diagnostics aggregator reports an incompatible QoS on its side).
        self._pub = node.create_publisher(
            DiagnosticArray, '/diagnostics', 10,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
        self._timer = node.create_timer(period_s, self.publish)

    @property
    def dropped_count(self) -> int:
        """Return the number of inputs dropped since start (all reasons)."""
        return sum(self.dropped.values())

    def subscribe(self, msg_type, topic: str, callback: Callable, qos, event_callbacks=None):
        """Create a subscription whose callback(msg) runs with the reception recorded.

        ``event_callbacks``: rclpy's SubscriptionEventCallbacks (default: rclpy's).
        """
        def on_message(msg, info, topic=topic):
            self.received_ns = int(info.get('received_timestamp') or time.time_ns())
            self._check_sequence(topic, info.get('publication_sequence_number'))
            callback(msg)
        sub = self._node.create_subscription(msg_type, topic, on_message, qos,
                                             event_callbacks=event_callbacks)
        self._subscriptions[topic] = sub
        return sub

    def _check_sequence(self, topic: str, seq: Optional[int]) -> None:
        """Count the messages lost between two of one publisher (sequence number gap)."""
        if seq is None:
            return
        last = self._last_seq.get(topic)
        self._last_seq[topic] = seq
        if last is None and seq > 1 and self._node.count_publishers(topic) == 1:
            self.before_match[topic] += seq - 1
            self._node.get_logger().info(
                f'{seq - 1} messages on {topic} were published before the subscription of '
                'this node matched their publisher (DDS does not deliver them): never '
                'received, not counted as drops')
        if last is None or seq <= last + 1:
            return
        lost = seq - last - 1
        if self._node.count_publishers(topic) == 1:  # one sequence: a gap is a loss
            self.lost[topic] += lost
            self.drop('lost', f'Lost {lost} messages on {topic}: published but never '
                      'received (the queue overflowed while the node was busy, or a message '
                      'too large for best-effort delivery between processes)', lost)

    def processed(self, received_ns: Optional[int] = None) -> None:
        """Count one processed input; its latency runs from ``received_ns`` (wall clock)."""
        self.processed_count += 1
        start = self.received_ns if received_ns is None else received_ns
        if start:
            latency = max(0.0, (time.time_ns() - start) * 1e-9)
            self.latencies.append(latency)
            self.run_latency.add(latency)

    def drop(self, reason: str, message: str, count: int = 1) -> None:
        """Count ``count`` dropped inputs for ``reason``; warn with the drop rate (throttled)."""
        self.dropped[reason] += count
        self.warner.warn(message, self.drop_rate_text())

    def event(self, key: str, message: str) -> None:
        """Count an input used other than as it came (e.g. ``odometry.jump``); warn (throttled)."""
        self.events[key] += 1
        self.warner.warn(message)

    def status(self) -> DiagnosticStatus:
        """Return the DiagnosticStatus of the inputs so far."""
        lat = list(self.latencies)
        dropped = self.dropped_count
        recent = dropped - self._reported_drops
        values = {'processed': self.processed_count, 'dropped': dropped,
                  'drop_rate_percent': f'{_percent(dropped, self.processed_count):.3f}'}
        values.update({f'dropped.{k}': v for k, v in sorted(self.dropped.items())})
        values.update({'latency_p50_ms': f'{_percentile_ms(lat, 50):.2f}',
                       'latency_p95_ms': f'{_percentile_ms(lat, 95):.2f}',
                       'latency_max_ms': f'{1e3 * max(lat, default=0.0):.2f}',
                       'latency_run_p50_ms': f'{self.run_latency.percentile_ms(50):.2f}',
                       'latency_run_p95_ms': f'{self.run_latency.percentile_ms(95):.2f}',
                       'latency_run_max_ms': f'{1e3 * self.run_latency.max:.2f}'})
        values.update({f'before_match.{k}': v for k, v in sorted(self.before_match.items())})
        values.update({f'lost.{k}': v for k, v in sorted(self.lost.items())})
        values.update({f'matched.{k}': sub.get_publisher_count()
                       for k, sub in sorted(self._subscriptions.items())})
        values.update(sorted(self.events.items()))
        level = DiagnosticStatus.WARN if recent else DiagnosticStatus.OK
        message = (f'{recent} inputs dropped in the last period' if recent else
                   f'{self.processed_count} inputs processed, {dropped} dropped')
        return DiagnosticStatus(
            level=level, name=f'{self._node.get_name()}: input', message=message,
            hardware_id=self._node.get_fully_qualified_name(),
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])

    def drop_rate_text(self) -> str:
        """Return the drop rate of the current period and since start, with the reasons."""
        dropped, processed = self.dropped_count, self.processed_count
        recent = dropped - self._reported_drops
        done = processed - self._reported_processed
        reasons = ', '.join(f'{k} {v}' for k, v in sorted(self.dropped.items()))
        return (f'drop rate: {recent} of {recent + done} inputs in this {self.period_s:g} s '
                f'period ({_percent(recent, done):.3g} %), {dropped} of {dropped + processed} '
                f'since start ({_percent(dropped, processed):.3g} %: {reasons})')

    def publish(self) -> None:
        """Publish the status on ``/diagnostics`` (and free heap: :func:`release_free_heap`)."""
        release_free_heap()
        status = self.status()
        self._reported_drops = self.dropped_count
        self._reported_processed = self.processed_count
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.status = [status]
        self._pub.publish(msg)


def require_stamp(stamp_ns: int, what: str) -> int:
    """Return a message's stamp [ns]; stamp 0 (an unset header) is a :class:`ConversionError`."""
    if stamp_ns <= 0:
        raise ConversionError(f'{what}: stamp {stamp_ns} ns is not a time (an unset header)')
    return stamp_ns


def read_scan(msg, max_beams: int, stats: 'InputStats'):
    """Return a LaserScan's :class:`~landmark_nav.conversions.ScanData`, or None when dropped.

    Dropped with a warning and counted by ``stats``: more than ``max_beams`` beams
    (``dropped.oversized``), a scan that cannot be read, is empty or has stamp 0
    (``dropped.malformed``).
    """
    if len(msg.ranges) > max_beams:
        stats.drop('oversized', f'Dropping scan: {len(msg.ranges)} beams, more than '
                   f'max_beams {max_beams}')
        return None
    try:
        scan = scan_to_data(msg)
        if scan.ranges.size == 0:
            raise ConversionError('LaserScan: empty scan (no ranges)')
        require_stamp(scan.stamp_ns, 'LaserScan')
    except ConversionError as err:
        stats.drop('malformed', f'Dropping scan: {err}')
        return None
    return scan


def ros_home() -> Path:
    """Return ``$ROS_HOME`` (default ``~/.ros``), where ROS tools keep their files."""
    return Path(os.environ.get('ROS_HOME') or Path.home() / '.ros').expanduser()


def output_path(name: str) -> Path:
    """Resolve a file name a node writes: relative names go under ``$ROS_HOME/landmark_nav``.

    Absolute paths and ``~`` are kept; a relative name does not depend on the directory the
    node was started from.
    """
    path = Path(name).expanduser()
    return path if path.is_absolute() else ros_home() / 'landmark_nav' / path


def initial_pose(msg, frame_id: str, stats: 'InputStats', fallback_cov: np.ndarray,
                 fallback_name: str):
    """Read an ``initialpose`` message (RViz "2D Pose Estimate") for a localizer's reset.

    A message that cannot be read, or is in another frame than ``frame_id`` (an empty frame
    is taken as it), is dropped with a warning and counted by ``stats``
    (``dropped.initialpose_malformed``, ``dropped.initialpose_frame``); a covariance that is
    not finite, symmetric and positive definite is replaced by ``fallback_cov`` with a
    warning naming ``fallback_name`` (the parameters it comes from), counted as
    ``initialpose.covariance_replaced``.

    Returns:
        ``((x, y, yaw), (3, 3) covariance)``, or None when the message is dropped.
    """
    try:
        data = pose_with_covariance_to_pose(msg)
    except ConversionError as err:
        stats.drop('initialpose_malformed', f'Dropping initial pose: {err}')
        return None
    if data.frame_id not in ('', frame_id):
        stats.drop('initialpose_frame',
                   f'Dropping initial pose in frame {data.frame_id!r}: expected {frame_id!r}')
        return None
    cov = np.asarray(data.covariance, dtype=float)
    if not (np.isfinite(cov).all() and np.allclose(cov, cov.T)
            and np.linalg.eigvalsh(0.5 * (cov + cov.T)).min() > 0.0):
        stats.event('initialpose.covariance_replaced',
                    f'initial pose covariance is not positive definite: using {fallback_name}')
        cov = fallback_cov
    return data.pose, cov
