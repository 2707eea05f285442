"""Parameter reference of the nodes, from their own declarations: ``landmark_nav docs-params``.

Each node declares its parameters in its constructor (:func:`~landmark_nav.nodes.common.declare`
and its relatives, every one through ``Node.declare_parameter`` with a read-only
descriptor), interleaved with the checks that need them, so the declarations are read by
constructing the node: in a private rclpy context with discovery off (nothing leaves the
process), never spun, destroyed at once. ``Node.declare_parameter`` is wrapped meanwhile to
record the *declared* default (not a value given at start-up) and the descriptor. The
drivers are given a port that does not exist, so no device is opened.

The tables sit in the docs pages between the markers ``<!-- BEGIN PARAMETERS node -->`` and
``<!-- END PARAMETERS node -->``; ``landmark_nav docs-params --write`` regenerates them and
``test/test_docs_params.py`` checks that every declared parameter appears in its page with
the declared default.
"""

from contextlib import contextmanager
from dataclasses import dataclass
import importlib
import math
import os
from pathlib import Path
import re
import textwrap
from typing import Dict, Iterator, List, Optional, Sequence

from landmark_nav.parameter_tables import READ_ONLY_NOTE

ROOT = Path(__file__).resolve().parents[2]

#: Node executable -> (module, class, docs page relative to the repository).
NODES = {
    'corner_extractor': ('landmark_nav.nodes.corner_extractor', 'CornerExtractor',
                         'docs/laser_features.md'),
    'line_extractor': ('landmark_nav.nodes.line_extractor', 'LineExtractor',
                       'docs/laser_features.md'),
    'ekf_slam': ('landmark_nav.nodes.ekf_slam', 'EkfSlamNode', 'docs/ekf_slam.md'),
    'graph_slam': ('landmark_nav.nodes.graph_slam', 'GraphSlamNode', 'docs/graph_slam.md'),
    'sonar_localizer': ('landmark_nav.nodes.sonar_localizer', 'SonarLocalizer',
                        'docs/sonar_localization.md'),
    'laser_driver': ('landmark_nav.nodes.laser_driver', 'LaserDriver', 'docs/drivers.md'),
    'base_driver': ('landmark_nav.nodes.base_driver', 'BaseDriver', 'docs/drivers.md'),
    'landmark_detector': ('landmark_nav.nodes.landmark_detector', 'LandmarkDetector',
                          'docs/visual_landmarks.md'),
    'corridor_follower': ('landmark_nav.nodes.corridor_follower', 'CorridorFollower',
                          'docs/corridor_following.md'),
    'road_classifier': ('landmark_nav.nodes.road_classifier', 'RoadClassifier',
                        'docs/road_following.md'),
    'model_localizer': ('landmark_nav.nodes.model_localizer', 'ModelLocalizerNode',
                        'docs/monocular_localization.md'),
}

#: Start-up values for the drivers: a port that cannot be a device (never the default one).
_NO_DEVICE = {'laser_driver': {'port': '/nonexistent/landmark_nav_docs'},
              'base_driver': {'port': '/nonexistent/landmark_nav_docs'}}

BEGIN = '<!-- BEGIN PARAMETERS {} -->'
END = '<!-- END PARAMETERS {} -->'
HEADER = ('| parameter | type | default | range | description |\n'
          '| --- | --- | --- | --- | --- |')


@dataclass(frozen=True)
class DeclaredParameter:
    """One parameter as the node declares it."""

    name: str
    type_name: str
    default: str  # formatted as in a parameter file
    limits: str  # range or choices, as printed
    description: str


def format_value(value) -> str:
    """Format a parameter value as a YAML parameter file writes it."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return "''" if value == '' else value
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(format_value(v) for v in value) + ']'
    if isinstance(value, float) and not math.isfinite(value):
        return '.nan' if math.isnan(value) else ('.inf' if value > 0 else '-.inf')
    return repr(value)


def _type_name(descriptor, default) -> str:
    from rcl_interfaces.msg import ParameterType
    names = {ParameterType.PARAMETER_BOOL: 'bool', ParameterType.PARAMETER_INTEGER: 'int',
             ParameterType.PARAMETER_DOUBLE: 'double', ParameterType.PARAMETER_STRING: 'string',
             ParameterType.PARAMETER_DOUBLE_ARRAY: 'double[]',
             ParameterType.PARAMETER_STRING_ARRAY: 'string[]'}
    return names.get(descriptor.type, type(default).__name__)


def _limits(descriptor) -> str:
    if descriptor.floating_point_range:
        r = descriptor.floating_point_range[0]
        return f'{format_value(r.from_value)} … {format_value(r.to_value)}'
    if descriptor.integer_range:
        r = descriptor.integer_range[0]
        return f'{r.from_value} … {r.to_value}'
    if descriptor.additional_constraints.startswith('one of: '):
        return descriptor.additional_constraints[len('one of: '):]
    return ''


@contextmanager
def _recording(records: list) -> Iterator[None]:
    """Record every ``Node.declare_parameter`` call (declared default, descriptor)."""
    from rclpy.node import Node
    original = Node.declare_parameter

    def declare_parameter(node, name, value=None, descriptor=None, ignore_override=False):
        records.append((name, value, descriptor))
        return original(node, name, value, descriptor, ignore_override)

    Node.declare_parameter = declare_parameter
    try:
        yield
    finally:
        Node.declare_parameter = original


@contextmanager
def _private_context() -> Iterator[object]:
    """Yield an initialised rclpy context with automatic discovery off (in-process only)."""
    import rclpy
    key = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
    before = os.environ.get(key)
    os.environ[key] = 'OFF'
    context = rclpy.Context()
    try:
        rclpy.init(context=context, args=[])
    finally:
        if before is None:
            del os.environ[key]
        else:
            os.environ[key] = before
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


@contextmanager
def _quiet_logger(name: str) -> Iterator[None]:
    """Silence a node's start-up log lines: the node is only read, never run.

    Its summary (INFO) says nothing about the declarations, and a driver's error about the
    port (:data:`_NO_DEVICE`, on purpose no device) is not one.
    """
    from rclpy.logging import LoggingSeverity, set_logger_level
    set_logger_level(name, LoggingSeverity.FATAL)
    try:
        yield
    finally:
        set_logger_level(name, LoggingSeverity.INFO)


def declared_parameters(
        nodes: Optional[Sequence[str]] = None) -> Dict[str, List[DeclaredParameter]]:
    """Return {node: its declared parameters in declaration order}.

    Args:
        nodes: Executables of :data:`NODES` (default: all).

    Raises:
        ValueError: An unknown node name.

    """
    from rclpy.parameter import Parameter
    names = list(NODES) if not nodes else list(nodes)
    unknown = [n for n in names if n not in NODES]
    if unknown:
        raise ValueError(f'unknown node {unknown[0]!r}; nodes: {", ".join(NODES)}')
    result = {}
    with _private_context() as context:
        for name in names:
            module, cls, _ = NODES[name]
            node_class = getattr(importlib.import_module(module), cls)
            overrides = [Parameter(k, value=v) for k, v in _NO_DEVICE.get(name, {}).items()]
            records: list = []
            with _quiet_logger(name):  # until the drivers' I/O thread has stopped
                with _recording(records):
                    node = node_class(context=context, parameter_overrides=overrides)
                node.destroy_node()
            rows = []
            for pname, default, descriptor in records:
                if descriptor is None or not descriptor.description.endswith(READ_ONLY_NOTE):
                    continue  # rclpy's own (use_sim_time, ...)
                rows.append(DeclaredParameter(
                    pname, _type_name(descriptor, default), format_value(default),
                    _limits(descriptor), descriptor.description[:-len(READ_ONLY_NOTE)]))
            result[name] = rows
    return result


def _cell(text: str) -> str:
    return text.replace('|', '\\|').replace('\n', ' ')


def markdown_table(rows: Sequence[DeclaredParameter]) -> str:
    """Return the markdown table of one node's parameters."""
    lines = [HEADER]
    for p in rows:
        rng = f'`{_cell(p.limits)}`' if p.limits else ''
        lines.append(f'| `{p.name}` | {p.type_name} | `{_cell(p.default)}` | {rng} | '
                     f'{_cell(p.description)} |')
    return '\n'.join(lines)


def block(node: str, rows: Sequence[DeclaredParameter]) -> str:
    """Return the marked block of a node: markers around its table."""
    return f'{BEGIN.format(node)}\n{markdown_table(rows)}\n{END.format(node)}'


def marked_block(text: str, node: str) -> Optional[str]:
    """Return the block of ``node`` in a page's text (markers included), or None."""
    m = re.search(re.escape(BEGIN.format(node)) + r'.*?' + re.escape(END.format(node)),
                  text, re.S)
    return m.group(0) if m else None


_ROW = re.compile(r'^\| `([^`]+)` \| [^|]* \| `((?:[^`\\]|\\.)*)` \|')


def table_defaults(block_text: str) -> Dict[str, str]:
    """Return {parameter: default as printed} of a marked block."""
    out = {}
    for line in block_text.splitlines():
        m = _ROW.match(line)
        if m:
            out[m.group(1)] = m.group(2).replace('\\|', '|')
    return out


def write_pages(tables: Dict[str, List[DeclaredParameter]], root: Path = ROOT) -> List[str]:
    """Replace each node's marked block in its page; return the pages changed.

    Raises:
        ValueError: A page has no markers for one of the nodes.

    """
    changed = []
    for node, rows in tables.items():
        page = root / NODES[node][2]
        text = page.read_text()
        old = marked_block(text, node)
        if old is None:
            raise ValueError(f'{page}: no {BEGIN.format(node)} ... {END.format(node)} markers')
        new = block(node, rows)
        if new != old:
            page.write_text(text.replace(old, new))
            if str(page.relative_to(root)) not in changed:
                changed.append(str(page.relative_to(root)))
    return changed


def node_name(node_class) -> Optional[str]:
    """Return the executable of a node class of :data:`NODES`, or None."""
    for name, (_, cls, _) in NODES.items():
        if cls == node_class.__name__:
            return name
    return None


def node_help(name: str, width: int = 88) -> str:
    """Return the ``--help`` text of a node executable: usage, purpose, parameters, pages.

    The parameters are the node's own declarations (:func:`declared_parameters`).
    """
    module, _, page = NODES[name]
    doc = (importlib.import_module(module).__doc__ or '').strip().split('\n')[0]
    purpose = doc.split(': ', 1)[-1].replace('``', '')
    lines = [f'usage: {name} [--ros-args [--params-file FILE] [-p NAME:=VALUE] '
             '[-r FROM:=TO] ...]', '', f'{name}: {purpose}', '',
             'parameters (read-only: set at start-up with -p NAME:=VALUE or '
             '--params-file FILE):']
    for p in declared_parameters([name])[name]:
        limits = f'; {p.limits}' if p.limits else ''
        lines.append(f'  {p.name} ({p.type_name}, default {p.default}{limits})')
        lines.extend(textwrap.wrap(p.description, width, initial_indent=' ' * 6,
                                   subsequent_indent=' ' * 6))
    lines += ['', f'shipped parameter file: landmark_nav config {name}',
              f'documentation: {page}', '']
    return '\n'.join(lines)


def add_parser(sub, parser_class=None) -> None:
    """Add the ``docs-params`` subcommand to the command line (``sub``'s parser class)."""
    p = sub.add_parser('docs-params', help="print each node's parameter table (markdown) from "
                       'its declarations; --write puts them into the docs pages')
    p.add_argument('nodes', nargs='*', help=f'nodes (default: all): {", ".join(NODES)}')
    p.add_argument('--write', action='store_true',
                   help='replace the tables between the markers of the docs pages')
    p.set_defaults(func=_cmd)


def _cmd(args) -> int:
    tables = declared_parameters(args.nodes)
    if args.write:
        for page in write_pages(tables):
            print(f'updated {page}')
        return 0
    for node, rows in tables.items():
        print(f'## {node} ({NODES[node][2]})\n\n{block(node, rows)}\n')
    return 0
