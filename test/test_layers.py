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
* the scorers live in ``landmark_nav.evaluation``: no core keeps an ``evaluate`` module;
* no import circle anywhere in the package (:func:`test_no_import_circle`).
"""

import ast
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Set, Tuple

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


def import_statements(path: Path, root: Path = ROOT
                      ) -> Iterator[Tuple[int, str, Optional[List[str]]]]:
    """Yield ``(line, absolute module name, names)`` of every import statement, at any depth.

    ``names`` is None for ``import a.b`` (one entry per module) and the imported names for
    ``from a.b import x, y`` (relative imports resolved against the file's package).
    """
    name = module_name(path, root)
    package = name.split('.') if path.name == '__init__.py' else name.split('.')[:-1]
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, None
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                mod = '.'.join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ''
            yield node.lineno, mod, [alias.name for alias in node.names]


def imports(path: Path, root: Path = ROOT) -> Iterator[Tuple[int, str]]:
    """Yield ``(line, absolute module name)`` of every import in a file, at any depth."""
    for line, mod, names in import_statements(path, root):
        yield line, mod
        for alias in names or ():  # ``from landmark_nav import sim`` imports a module
            yield line, f'{mod}.{alias}'


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


def import_graph(root: Path = ROOT) -> Dict[str, Dict[str, List[str]]]:
    """Return the imports between the package's modules: ``{importer: {imported: [where]}}``.

    Every import statement of every source file counts, at any depth (module level, inside
    functions, under ``if``/``try``). An import names the module whose code it needs, which
    is the edge:

    * ``import a.b.c`` and ``from a.b.c import x`` need ``a.b.c``;
    * ``from a.b import c`` needs the submodule ``a.b.c`` when ``c`` is one, and the package
      ``a.b`` (its ``__init__``) for every other name (a name the ``__init__`` defines or
      re-exports);
    * the parent packages that Python initialises first (``a``, ``a.b``) are not edges: by
      the time a submodule runs, its packages are already in ``sys.modules``, so a package
      ``__init__`` that imports its submodules for re-export while a submodule imports a
      sibling by its full name (``from a.b.other import x``) is no circle. It is one when
      the submodule imports from the package ``__init__`` itself (``from a.b import x`` or
      ``from . import x`` with ``x`` not a submodule): then the ``__init__`` and the
      submodule need each other.
    """
    files = {module_name(p, root): p for p in sorted(root.rglob('*.py'))}
    graph: Dict[str, Dict[str, List[str]]] = {m: {} for m in files}
    for importer, path in files.items():
        for line, mod, names in import_statements(path, root):
            if names is None:
                targets = [mod]
            else:
                subs = [f'{mod}.{n}' for n in names if f'{mod}.{n}' in files]
                targets = subs + ([mod] if len(subs) < len(names) else [])
            for target in targets:
                if target in files and target != importer:
                    where = f'{path.relative_to(root.parent)}:{line}'
                    graph[importer].setdefault(target, []).append(where)
    return graph


def strongly_connected(graph: Dict[str, Dict[str, List[str]]]) -> List[List[str]]:
    """Strongly connected components of more than one module (Tarjan's, iterative), sorted."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    found = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return sorted(found)


def import_circles(root: Path = ROOT) -> List[str]:
    """Describe each import circle: its modules and the imports between them."""
    graph = import_graph(root)
    out = []
    for component in strongly_connected(graph):
        members = set(component)
        edges = [f'    {a} -> {b} ({", ".join(where)})' for a in component
                 for b, where in sorted(graph[a].items()) if b in members]
        out.append('import circle: ' + ', '.join(component) + '\n' + '\n'.join(edges))
    return out


def test_no_import_circle():
    """No set of the package's modules imports each other (see :func:`import_graph`)."""
    graph = import_graph()
    assert len(graph) > 100 and sum(map(len, graph.values())) > 300, 'graph not built'
    circles = import_circles()
    assert not circles, '\n'.join(circles)


@pytest.mark.parametrize('sources,circle', [
    # a function-level import closes the circle
    ({'sim/a.py': 'from landmark_nav.sim.b import x\n',
      'sim/b.py': 'def f():\n    from landmark_nav.sim.a import y\n'}, ['a', 'b']),
    # three modules, relative imports
    ({'sim/a.py': 'from .b import x\n', 'sim/b.py': 'from . import c\n',
      'sim/c.py': 'import landmark_nav.sim.a\n'}, ['a', 'b', 'c']),
    # a package re-exports its submodule, which imports a sibling by its full name: no circle
    ({'sim/__init__.py': 'from .a import x\nfrom .b import y\n',
      'sim/a.py': 'from landmark_nav.sim.b import y\n', 'sim/b.py': 'y = 1\n'}, []),
    # ``from package import submodule`` needs the submodule, not the package's __init__
    ({'sim/__init__.py': 'from .a import x\n',
      'sim/a.py': 'from landmark_nav.sim import b\nx = 1\n', 'sim/b.py': 'y = 1\n'}, []),
    # ... but importing a name the __init__ re-exports needs the __init__: a circle
    ({'sim/__init__.py': 'from .a import x\nfrom .b import y\n',
      'sim/a.py': 'from landmark_nav.sim import y\nx = 1\n', 'sim/b.py': 'y = 1\n'},
     ['', 'a']),
])
def test_circle_check_catches_a_circle(tmp_path, sources, circle):
    """The circle check flags modules that import each other, and only those."""
    root = tmp_path / 'landmark_nav'
    for rel, text in {'__init__.py': '', 'sim/__init__.py': '', **sources}.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    want = [['.'.join(['landmark_nav.sim', m]).rstrip('.') for m in circle]] if circle else []
    assert strongly_connected(import_graph(root)) == want
