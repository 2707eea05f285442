"""Parameter tables: the node parameters of a parameter dataclass's documented fields.

A table maps a field to ``(description, limits or None, choices or None[, auto])``;
``auto`` is the parameter value standing for a field default of None ("off" or "choose
automatically", e.g. 0.0). The nodes declare these parameters
(:func:`landmark_nav.nodes.common.declare_dataclass`) and the offline tools read parameter
files against them (:mod:`landmark_nav.slam.configuration`).
"""

from typing import Any, Dict, NamedTuple, Optional, Tuple


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


def field_value(parameter: Parameter, value: Any) -> Any:
    """Return the dataclass field value of a parameter value (its ``auto`` value -> None)."""
    return None if parameter.auto and value == parameter.auto[0] else value
