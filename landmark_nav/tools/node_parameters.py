"""Node parameters on the command line: ``--params-file FILE`` and ``--set NAME=VALUE``.

The offline commands take a node's configuration as the node does, so that a node and its
offline run use one configuration:

* ``--params-file FILE`` (repeatable): a ROS 2 parameter file. The sections that apply to
  the node are read as ``ros2 run`` reads them: ``/**`` (every node), then the node's own
  (``ekf_slam``, ``/ekf_slam``, ``/**/ekf_slam``, ``/ns/ekf_slam``); nested keys are
  joined with dots (``odometry: {model: pioneer}`` is ``odometry.model``). Files are read
  in the order given and a later value wins, as with several ``--params-file`` of
  ``ros2 run``.
* ``--set NODE.NAME=VALUE`` or ``--set NAME=VALUE`` (repeatable, after the files): the
  value is read as YAML, as ``-p NAME:=VALUE`` reads it (``2`` is an integer, ``2.0`` a
  double, ``'both'`` a string, ``[0.1, 0.0, 0.0]`` a list).

Names the node does not declare are refused by the caller with
:func:`landmark_nav.parameter_names.unknown_parameter` (the nearest declared name).
"""

import argparse
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping

import yaml


def add_arguments(parser: argparse.ArgumentParser, node: str) -> None:
    """Add ``--params-file`` and ``--set`` for ``node``'s parameters to a parser."""
    parser.add_argument('--params-file', action='append', default=[], metavar='FILE',
                        help=f'{node} parameter file (ROS 2 YAML, as ros2 run --params-file; '
                        'repeatable, a later file wins; e.g. "$(landmark_nav config '
                        f'{node})")')
    parser.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                        help=f'one {node} parameter, after the files ({node}.NAME=VALUE or '
                        'NAME=VALUE; the value as YAML, as -p NAME:=VALUE; repeatable)')


def _flatten(values: Mapping, prefix: str = '') -> Dict[str, Any]:
    """Join nested parameter keys with dots."""
    out = {}
    for key, value in values.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            out.update(_flatten(value, name + '.'))
        else:
            out[name] = value
    return out


def _applies(section: str, node: str) -> int:
    """Return 1 for a wildcard section, 2 for the node's own, 0 for another node's."""
    name = str(section).strip('/')
    if name == '**':
        return 1
    parts = name.split('/')
    return 2 if parts[-1] == node else 0


def read_params_file(path: str, node: str) -> Dict[str, Any]:
    """Return the parameters a ROS 2 parameter file gives ``node`` (module docstring).

    Raises:
        ValueError: Unreadable file, not a parameter file, or a section of the node
            without ``ros__parameters`` (one line naming the file).
    """
    try:
        data = yaml.safe_load(Path(path).read_text())
    except OSError as err:
        raise ValueError(f'--params-file {path}: {err.strerror or err}') from None
    except yaml.YAMLError as err:
        raise ValueError(f'--params-file {path}: not YAML ({str(err).splitlines()[0]})') from None
    if not isinstance(data, dict):
        raise ValueError(f'--params-file {path}: expected node names at the top level '
                         '(NODE: ros__parameters: ...)')
    out: Dict[str, Any] = {}
    for rank in (1, 2):  # the wildcard first, the node's own section wins
        for section, body in data.items():
            if _applies(section, node) != rank:
                continue
            if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
                raise ValueError(f'--params-file {path}: section {section!r} has no '
                                 'ros__parameters mapping')
            out.update(_flatten(body['ros__parameters']))
    return out


def parse_setting(text: str, node: str) -> tuple:
    """Return ``(name, value)`` of ``NODE.NAME=VALUE`` or ``NAME=VALUE`` (value as YAML).

    Raises:
        ValueError: Not ``NAME=VALUE``, or a value that is not YAML.
    """
    key, sep, raw = text.partition('=')
    key = key.strip()
    if not (sep and key):
        raise ValueError(f'--set {text!r}: expected {node}.NAME=VALUE or NAME=VALUE')
    if key.startswith(node + '.'):
        key = key[len(node) + 1:]
    try:
        value = yaml.safe_load(raw) if raw.strip() else ''
    except yaml.YAMLError:
        raise ValueError(f'--set {text!r}: the value is not YAML') from None
    return key, value


def given_parameters(files: Iterable[str], settings: Iterable[str], node: str
                     ) -> Dict[str, Any]:
    """Return the parameters of the files, then the settings, a later value winning."""
    out: Dict[str, Any] = {}
    for path in files:
        out.update(read_params_file(path, node))
    for text in settings:
        name, value = parse_setting(text, node)
        out[name] = value
    return out


def _ros_value(value: Any) -> str:
    """Write a parameter value as ``-p NAME:=VALUE`` reads it back (YAML, shortest repr)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ','.join(_ros_value(v) for v in value) + ']'
    if isinstance(value, (int, float)):
        return repr(value)
    return str(value) if value != '' else "''"


def as_ros_arguments(values: Mapping[str, Any]) -> List[str]:
    """Return ``-p NAME:=VALUE`` arguments giving a node these parameter values."""
    out = []
    for name, value in values.items():
        out += ['-p', f'{name}:={_ros_value(value)}']
    return out
