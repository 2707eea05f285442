"""Parameter tables: the node parameters of a parameter dataclass's documented fields.

A table maps a field to ``(description, limits or None, choices or None[, auto])``;
``auto`` is the parameter value standing for a field default of None ("off" or "choose
automatically", e.g. 0.0). The nodes declare these parameters
(:func:`landmark_nav.nodes.common.declare_dataclass`) and the offline tools read parameter
files against them (:func:`parameter_values`, :mod:`landmark_nav.slam.configuration`,
:mod:`landmark_nav.laser.extractor_configuration`).
"""

import re
from typing import Any, Dict, Mapping, NamedTuple, Optional, Tuple

from landmark_nav.parameter_names import unknown_parameter

#: The parameters rclpy declares in every node (accepted, no effect on the configuration).
RCLPY_PARAMETERS = ('use_sim_time', 'start_type_description_service')
#: appended to every declared parameter's description (and removed for the docs' tables).
READ_ONLY_NOTE = ' (read-only: set at start-up, e.g. -p or --params-file)'


class Parameter(NamedTuple):
    """One node parameter: its default (parameter form) and descriptor."""

    default: Any
    description: str
    limits: Optional[Tuple[float, float]] = None
    choices: Optional[list] = None
    auto: Tuple = ()  # (the value standing for a field default of None,) or ()


def dataclass_parameters(table: dict, instance, prefix: str = '') -> Dict[str, Parameter]:
    """Return the parameters of a table's fields by name, defaults from ``instance``."""
    out = {}
    for name, (description, limits, choices, *auto) in table.items():
        default = getattr(instance, name)
        if default is None:
            default = auto[0]
        if isinstance(default, tuple):
            default = [float(v) for v in default]
        out[prefix + name] = Parameter(default, description, limits, choices, tuple(auto))
    return out


def name_parameters(message: str, prefixes: Mapping[str, str]) -> str:
    """Return a parameter dataclass's refusal with the parameter names a user sets.

    ``'CornerParams.window must be odd'`` -> ``'parameter window must be odd'``; ``prefixes``
    maps each dataclass's name to its parameters' prefix (e.g. ``{'KeyframeParams':
    'keyframe.'}``).
    """
    for cls, prefix in prefixes.items():
        message = re.sub(rf'\b{re.escape(cls)}\.(?=\w)', f'parameter {prefix}', message)
    return message


def field_value(parameter: Parameter, value: Any) -> Any:
    """Return the dataclass field value of a parameter value (its ``auto`` value -> None)."""
    return None if parameter.auto and value == parameter.auto[0] else value


_TYPE_NAMES = {bool: 'a bool (true / false)', int: 'an integer', float: 'a double',
               str: 'a string', list: 'a list of doubles', 'strings': 'a list of strings'}


def check_value(name: str, value: Any, param: Parameter) -> Any:
    """Check one parameter value as the node's declaration does; return it.

    The value must have the default's type (an integer for a double is refused, as ROS 2
    refuses it), lie within the limits and be one of the choices.

    Raises:
        ValueError: One line naming the parameter, what it expects and what it got.
    """
    kind = type(param.default)
    ok = isinstance(value, kind) and (kind is not int or not isinstance(value, bool))
    if kind is list:  # a list of doubles, or of strings when the default is
        item = str if param.default and isinstance(param.default[0], str) else float
        ok = isinstance(value, list) and all(isinstance(v, item) for v in value)
        kind = 'strings' if item is str else list
    if not ok:
        hint = '; write {}.0 for a double'.format(value) if (
            kind is float and isinstance(value, int) and not isinstance(value, bool)) else ''
        raise ValueError(f'parameter {name}: expected {_TYPE_NAMES[kind]}, got {value!r}'
                         f'{hint}')
    if param.limits is not None and kind in (int, float) and not (
            param.limits[0] <= value <= param.limits[1]):
        raise ValueError(f'parameter {name} = {value!r} is outside [{param.limits[0]}, '
                         f'{param.limits[1]}]')
    if param.choices is not None and value not in param.choices:
        raise ValueError(f'parameter {name} = {value!r} is not one of '
                         f'{", ".join(param.choices)}')
    return value


def parameter_values(node: str, table: Mapping[str, Parameter],
                     overrides: Optional[Mapping[str, Any]] = None) -> Dict[str, Any]:
    """Return every parameter's value: the table's defaults with ``overrides`` on top.

    Each override is checked as ``node`` declares it (:func:`check_value`); the parameters
    rclpy declares in every node are accepted and left out.

    Raises:
        ValueError: An unknown name (naming the nearest declared one), or a value of the
            wrong type, out of its limits or not a choice (one line naming the parameter).
    """
    values = {name: p.default for name, p in table.items()}
    for name, value in (overrides or {}).items():
        if name in RCLPY_PARAMETERS:
            continue  # every node has them; nothing here depends on them
        if name not in table:
            raise ValueError(unknown_parameter(node, name, table))
        values[name] = check_value(name, value, table[name])
    return values
