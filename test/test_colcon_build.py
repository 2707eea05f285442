"""A colcon build places every executable where ``ros2 run`` looks for it."""

import ast
import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parents[1]


def _executables():
    """Read the console scripts declared in setup.py."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and getattr(node.targets[0], 'id', '') == 'EXECUTABLES':
            return sorted(ast.literal_eval(node.value))
    raise AssertionError('EXECUTABLES not found in setup.py')


@pytest.mark.slow
def test_colcon_build_installs_executables_into_lib(tmp_path):
    colcon = Path(sys.executable).with_name('colcon')
    if not colcon.exists():
        pytest.skip('colcon is not installed in this environment')
    src = tmp_path / 'src' / 'landmark_nav'
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(
        '.venv', '.git', 'out', 'build', 'install', 'log', '__pycache__', '*.egg-info',
        'bags', '.pytest_cache', '.hypothesis'))
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE='1')
    result = subprocess.run(
        [str(colcon), 'build', '--base-paths', 'src', '--event-handlers', 'console_direct-'],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    prefix = tmp_path / 'install' / 'landmark_nav'
    lib = prefix / 'lib' / 'landmark_nav'
    names = _executables()
    assert names, 'no executables declared'
    for name in names:
        exe = lib / name
        assert exe.is_file() and os.access(exe, os.X_OK), f'{exe} missing or not executable'
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
            / 'landmark_nav').is_file()
    assert (prefix / 'share' / 'landmark_nav' / 'package.xml').is_file()
    configs = sorted(p.name for p in (REPO / 'config').glob('*.yaml'))
    installed = sorted(p.name for p in (prefix / 'share' / 'landmark_nav' / 'config').glob(
        '*.yaml'))
    assert installed == configs
    launches = sorted(p.name for p in (REPO / 'launch').glob('*.launch.py'))
    installed = sorted(p.name for p in (prefix / 'share' / 'landmark_nav' / 'launch').glob(
        '*.launch.py'))
    assert launches and installed == launches
