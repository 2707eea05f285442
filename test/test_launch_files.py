"""ROS 2 launch files, checked structurally (``launch`` is not installable here).

Every launch file starts the nodes of the pipeline of the same name, executables that
setup.py installs, with parameter files that exist and belong to the node, overrides of
parameters the node declares, remappings of topics the node uses and launch arguments that
are declared.
"""

import ast
from pathlib import Path

from landmark_nav.tools.pipeline import PIPELINES
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
LAUNCH = sorted((REPO / 'launch').glob('*.launch.py'))


def _setup_value(name):
    tree = ast.parse((REPO / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and getattr(node.targets[0], 'id', '') == name:
            return node.value
    raise AssertionError(f'{name} not in setup.py')


def _calls(tree, name):
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call)
            and getattr(n.func, 'id', getattr(n.func, 'attr', None)) == name]


def _kwargs(call):
    return {k.arg: k.value for k in call.keywords}


def test_there_is_one_launch_file_per_pipeline_and_setup_installs_them():
    assert sorted(p.name for p in LAUNCH) == sorted(f'{n}.launch.py' for n in PIPELINES)
    setup = (REPO / 'setup.py').read_text()
    assert "(os.path.join('share', PACKAGE, 'launch'), glob('launch/*.launch.py'))" in setup


@pytest.mark.parametrize('path', LAUNCH, ids=[p.name for p in LAUNCH])
def test_launch_file_names_existing_executables_parameters_and_topics(path):
    tree = ast.parse(path.read_text())
    executables = ast.literal_eval(_setup_value('EXECUTABLES'))
    declared_args = {ast.literal_eval(c.args[0]) for c in _calls(tree, 'DeclareLaunchArgument')}
    used_args = {ast.literal_eval(c.args[0]) for c in _calls(tree, 'LaunchConfiguration')}
    assert used_args <= declared_args, used_args - declared_args
    started = []
    for call in _calls(tree, 'Node'):
        kw = _kwargs(call)
        assert ast.literal_eval(kw['package']) == 'landmark_nav'
        exe, name = ast.literal_eval(kw['executable']), ast.literal_eval(kw['name'])
        assert exe in executables, exe
        started.append(exe)
        source = (REPO / executables[exe].split(':')[0].replace('.', '/')).with_suffix('.py')
        params = kw['parameters'].elts if 'parameters' in kw else []
        files = [ast.literal_eval(p.args[1]) for p in params if isinstance(p, ast.Call)]
        overrides = [k for p in params if isinstance(p, ast.Dict)
                     for k in ast.literal_eval(ast.List(elts=p.keys))]
        if exe != 'bag_player':
            assert files == [f'{exe}.yaml'], files
        for f in files:
            config = yaml.safe_load((REPO / 'config' / f).read_text())
            assert list(config) == [name], f'{f} is for {list(config)}, the node is {name}'
            known = config[name]['ros__parameters']
            assert set(overrides) <= set(known), set(overrides) - set(known)
        for pair in (kw['remappings'].elts if 'remappings' in kw else []):
            topic = ast.literal_eval(pair.elts[0]).lstrip('/')
            assert f"'{topic}'" in source.read_text(), f'{exe} uses no topic {topic}'
    assert started == list(PIPELINES[path.name.split('.')[0]])
