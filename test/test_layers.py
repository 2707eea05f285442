"""Layering of the package: imports point down, checked on the sources.

The package is layered so that the algorithms run on the robot without the simulator or
the scoring code: at the bottom the algorithm cores (computation on arrays, the device
protocols, the bag file), above them the importers (logs -> bags), the simulator, the
evaluation, the tools and the ROS nodes, which use the cores; the rules below keep the
cores (and the importers) from importing upwards. Every ``import`` / ``from ... import``
of a module, at any depth (module level, inside functions, under ``if``/``try``), is read
with :mod:`ast` and resolved to an absolute module name (relative imports included).
Rules:

* the algorithm cores (``geometry``, ``hardware``, ``laser``, ``slam``, ``localization``,
  ``vision``, ``monocular``, ``corridor``, ``road``, ``drivers``, ``bag``) never import
  ``landmark_nav.sim``, ``landmark_nav.evaluation``, ``landmark_nav.tools``,
  ``landmark_nav.nodes``; and, except ``bag`` (which (de)serializes messages with
  ``rclpy.serialization``), never rclpy;
* the importers are not a core (they build ROS messages through ``conversions`` and show
  a progress bar) but an imported bag must not depend on the simulator or the scorers:
  they never import ``landmark_nav.sim``, ``landmark_nav.evaluation``,
  ``landmark_nav.tools``, ``landmark_nav.nodes``;
* the nodes never import ``landmark_nav.sim`` (a node runs on the real robot);
* the scorers live in ``landmark_nav.evaluation``: no core keeps an ``evaluate`` module.
"""

import ast
from pathlib import Path
from typing import Iterator, List, Tuple

import pytest

ROOT = Path(__file__).resolve().parents[1] / 'landmark_nav'
CORES = ('geometry', 'hardware', 'laser', 'slam', 'localization', 'vision', 'monocular',
         'corridor', 'road', 'drivers', 'bag')
ABOVE_CORES = ('landmark_nav.sim', 'landmark_nav.evaluation', 'landmark_nav.tools',
               'landmark_nav.nodes')
RCLPY_ALLOWED = ('bag',)


def module_name(path: Path, root: Path = ROOT) -> str:
    """Dotted module name of a source file under ``root`` (``__init__`` = the package)."""
    rel = path.relative_to(root.parent).with_suffix('')
    parts = list(rel.parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def imports(path: Path, root: Path = ROOT) -> Iterator[Tuple[int, str]]:
    """Yield ``(line, absolute module name)`` of every import in a file, at any depth."""
    name = module_name(path, root)
    package = name.split('.') if path.name == '__init__.py' else name.split('.')[:-1]
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                mod = '.'.join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ''
            yield node.lineno, mod
            for alias in node.names:  # ``from landmark_nav import sim`` imports a module
                yield node.lineno, f'{mod}.{alias.name}'


def _forbidden(mod: str, prefixes: Tuple[str, ...]) -> bool:
    return any(mod == p or mod.startswith(p + '.') for p in prefixes)


def violations(path: Path, core: str, root: Path = ROOT) -> List[str]:
    """Forbidden imports of one source file of the layer ``core`` (a core or a layer above)."""
    if core == 'nodes':
        banned: Tuple[str, ...] = ('landmark_nav.sim',)
    elif core == 'importers':
        banned = ABOVE_CORES
    else:
        banned = ABOVE_CORES + (() if core in RCLPY_ALLOWED else ('rclpy',))
    return [f'{path.relative_to(root.parent)}:{line}: imports {mod}'
            for line, mod in imports(path, root) if _forbidden(mod, banned)]


def layer_files(core: str, root: Path = ROOT) -> List[Path]:
    """Source files of a layer (a module ``core.py`` or a package ``core/``)."""
    single = root / f'{core}.py'
    return [single] if single.is_file() else sorted((root / core).rglob('*.py'))


@pytest.mark.parametrize('core', CORES + ('importers', 'nodes'))
def test_layer_imports_point_down(core):
    files = layer_files(core)
    assert files, f'no sources for {core}'
    bad = [v for f in files for v in violations(f, core)]
    assert not bad, '\n'.join(bad)


def test_scorers_live_in_evaluation():
    stray = [str(p.relative_to(ROOT.parent)) for c in CORES if (ROOT / c).is_dir()
             for p in (ROOT / c).glob('evaluate*.py')]
    assert not stray, stray
    for name in ('slam', 'localization', 'vision', 'trajectory', 'features'):
        assert (ROOT / 'evaluation' / f'{name}.py').is_file(), name


def test_relative_import_resolution(tmp_path):
    root = tmp_path / 'landmark_nav'
    (root / 'slam').mkdir(parents=True)
    f = root / 'slam' / '__init__.py'
    f.write_text('from . import ekf\nfrom ..sim import world\nfrom .. import tools\n')
    assert [m for _, m in imports(f, root)] == [
        'landmark_nav.slam', 'landmark_nav.slam.ekf', 'landmark_nav.sim',
        'landmark_nav.sim.world', 'landmark_nav', 'landmark_nav.tools']


@pytest.mark.parametrize('core,source,caught', [
    ('slam', 'from landmark_nav.sim import run_scenario\n', True),
    ('laser', 'def f():\n    import landmark_nav.evaluation.features as m\n    return m\n',
     True),
    ('localization', 'try:\n    from ..sim.sonar import SONAR_MOUNTS\nexcept ImportError:\n'
     '    pass\n', True),
    ('vision', 'from .. import tools\n', True),
    ('drivers', 'import rclpy.node\n', True),
    ('geometry', 'from landmark_nav.nodes.common import declare\n', True),
    ('nodes', 'def g():\n    from landmark_nav.sim.sonar import SONAR_MOUNTS\n', True),
    ('monocular', 'from landmark_nav.sim.camera import render\n', True),
    ('importers', 'def h():\n    from landmark_nav.evaluation.bags import load_bag\n', True),
    ('importers', 'from landmark_nav.conversions import make_scan\n', False),
    ('bag', 'from rclpy.serialization import serialize_message\n', False),
    ('nodes', 'import rclpy\nfrom landmark_nav.hardware import SONAR_MOUNTS\n', False),
    ('slam', 'from landmark_nav.simulation_helpers import x\nfrom .consistency import nees\n',
     False),
])
def test_check_catches_an_added_import(tmp_path, core, source, caught):
    """The checker flags a forbidden import added to a temporary source file, at any depth."""
    root = tmp_path / 'landmark_nav'
    pkg = root / core
    pkg.mkdir(parents=True)
    f = pkg / 'added.py'
    f.write_text(source)
    assert bool(violations(f, core, root)) is caught
