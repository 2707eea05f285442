"""Small helpers shared by the nodes: typed parameters with descriptors, QoS, main()."""

import math
import re
import sys
import time
from typing import Callable, Optional, Sequence

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType)
import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data

SENSOR_QOS = qos_profile_sensor_data
WARN_THROTTLE_S = 5.0

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
    descriptor = ParameterDescriptor(description=description, read_only=True)
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
    try:
        value = node.declare_parameter(name, default, descriptor).value
    except InvalidParameterValueException as err:
        raise ParameterError(f'parameter {name}: {err}') from err
    if choices is not None and value not in choices:
        raise ParameterError(f'parameter {name} = {value!r} is not one of {", ".join(choices)}')
    if isinstance(default, list):
        value = [float(v) for v in value]
    return value


def declare_strings(node: Node, name: str, default: list, description: str) -> list:
    """Declare a read-only string-array parameter and return its value."""
    descriptor = ParameterDescriptor(description=description, read_only=True,
                                     type=ParameterType.PARAMETER_STRING_ARRAY)
    try:
        return list(node.declare_parameter(name, default, descriptor).value)
    except (InvalidParameterValueException, InvalidParameterTypeException) as err:
        raise ParameterError(f'parameter {name}: {err}') from err


def run_node(factory: Callable[[], Node], args: Optional[Sequence[str]] = None) -> int:
    """Run a node as a standard main: init, spin, shut down; bad parameters exit with 2."""
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ParameterError as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


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
    defaults = cls()
    values = {}
    for name, (description, limits, choices, *auto) in docs.items():
        default = getattr(defaults, name)
        if default is None:
            default = auto[0]
        if isinstance(default, tuple):
            default = [float(v) for v in default]
        value = declare(node, prefix + name, default, description, limits, choices)
        values[name] = None if auto and value == auto[0] else value
    try:
        return cls(**values)
    except (TypeError, ValueError) as err:
        raise ParameterError(f'{node.get_name()}: {err}') from err


class ProblemWarner:
    """Warn about bad input, throttled per kind of problem (not per call site).

    Repeats of the same problem (its message with the numbers masked) are reported at most
    once per ``period_s``; a different problem is reported at once. The node keeps running.
    """

    def __init__(self, node: Node, period_s: float = WARN_THROTTLE_S) -> None:
        """Attach to a node's logger."""
        self._logger = node.get_logger()
        self._period = period_s
        self._last = {}
        self.count = 0

    def warn(self, message: str) -> None:
        """Log a warning unless the same kind of problem was reported recently."""
        self.count += 1
        key = re.sub(r'[-+0-9.e]+', '#', message)
        now = time.monotonic()
        if now - self._last.get(key, -math.inf) >= self._period:
            self._last[key] = now
            self._logger.warning(message)
