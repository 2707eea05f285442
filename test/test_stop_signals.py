"""Every executable that serves stops within 2 s of SIGINT, even started as a background job.

A background job of a non-interactive shell (``bash -c 'cmd &'``) starts with SIGINT
ignored; the emulators used to stay ignoring it (they handled SIGTERM only), so a script's
Ctrl-C never stopped them and they outlived the test run. Each executable here is started
that way (SIGINT ignored, as :meth:`ChildProcesses.start` ``sigint_ignored`` does), given
time to be up (its ROS node in the graph, or its endpoints announced), sent SIGINT, and
must exit with status 0 within 2 s, leaving no pty link behind.
"""

import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time

from landmark_nav.testing import RosHarness
from landmark_nav.testing.processes import kill_all
import pytest

REPO = Path(__file__).resolve().parents[1]
CLI = [sys.executable, '-m', 'landmark_nav.tools.cli']
EXIT_WITHIN_S = 2.0
NODES = ('corner_extractor', 'line_extractor', 'ekf_slam', 'graph_slam', 'sonar_localizer',
         'landmark_detector', 'corridor_follower', 'road_classifier', 'model_localizer',
         'laser_driver', 'base_driver')


def _sigint_ignored(pid: int) -> bool:
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('SigIgn:'):
            return bool(int(line.split()[1], 16) & (1 << (signal.SIGINT - 1)))
    raise AssertionError(f'no SigIgn line for {pid}')


def test_a_child_can_start_with_sigint_ignored(processes):
    """The harness really reproduces the background job's disposition."""
    background = processes.start(['sleep', '30'], sigint_ignored=True)
    foreground = processes.start(['sleep', '30'])
    time.sleep(0.2)
    assert _sigint_ignored(background.pid) and not _sigint_ignored(foreground.pid)
    # and a shell's background job has it ignored too
    job = subprocess.run(['bash', '-c', 'sleep 30 > /dev/null 2>&1 & echo $!'],
                         capture_output=True, text=True, timeout=10)
    pid = int(job.stdout)
    try:
        assert _sigint_ignored(pid)
    finally:
        kill_all([pid])  # and wait until it is gone (a loaded machine takes a moment)


def _collect(proc) -> list:
    lines: list = []
    threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True).start()
    return lines


def _stop_with_sigint(processes, proc, lines) -> None:
    assert proc.poll() is None, ''.join(lines)
    sent = time.monotonic()
    code = processes.stop(proc, signal.SIGINT, timeout=30.0)
    took = time.monotonic() - sent
    assert code == 0, (code, ''.join(lines))
    assert took <= EXIT_WITHIN_S, f'exited {took:.2f} s after SIGINT:\n{"".join(lines)}'


def _wait_for(condition, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, f'not within {timeout} s: {what}'
        time.sleep(0.1)


@pytest.mark.parametrize('device', ['urg', 'lms200', 'p2os', 'robot'])
def test_emulators_stop_on_sigint_as_background_jobs(tmp_path, processes, device):
    link = tmp_path / device
    extra = {'p2os': ['--tcp', '0'], 'robot': ['--tcp', '0', '--laser-link',
                                               str(tmp_path / 'laser')]}.get(device, [])
    proc = processes.start(CLI + ['emulate', device, '--link', str(link)] + extra,
                           sigint_ignored=True, stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    lines = _collect(proc)
    _wait_for(lambda: any('pty: ' in line for line in lines) or proc.poll() is not None,
              30.0, 'the emulator serves')
    assert os.path.islink(link)
    _stop_with_sigint(processes, proc, lines)
    assert not os.path.lexists(link) and not os.path.lexists(tmp_path / 'laser')


def _in_graph(ros, names) -> bool:
    return set(names) <= set(ros._helper.get_node_names())


@pytest.mark.dds
@pytest.mark.parametrize('node', NODES)
def test_nodes_stop_on_sigint_as_background_jobs(tmp_path, processes, node):
    args = ['--ros-args', '-p', f'port:={tmp_path / "absent"}'] if 'driver' in node else []
    with RosHarness() as ros:
        proc = processes.start([sys.executable, '-m', f'landmark_nav.nodes.{node}'] + args,
                               sigint_ignored=True, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
        lines = _collect(proc)
        _wait_for(lambda: _in_graph(ros, [node]) or proc.poll() is not None, 60.0,
                  f'{node} in the graph')
        _stop_with_sigint(processes, proc, lines)


# command -> the nodes it starts
COMMANDS = {
    'bag_player': ([sys.executable, '-m', 'landmark_nav.nodes.bag_player',
                    str(REPO / 'bags' / 'office'), '--loop', '--wait-for-subscribers', '0'],
                   ['bag_player']),
    'replay': (CLI + ['replay', str(REPO / 'bags' / 'office'), '--loop',
                      '--wait-for-subscribers', '0'], ['bag_player']),
    'drive': (CLI + ['drive', '--wait', '600'], ['drive']),
    'pipeline': (CLI + ['pipeline', 'slam', '--set', 'laser_driver.port=/nonexistent/laser',
                        '--set', 'base_driver.port=/nonexistent/base'],
                 ['laser_driver', 'base_driver', 'corner_extractor', 'ekf_slam']),
}


@pytest.mark.dds
@pytest.mark.parametrize('command', sorted(COMMANDS))
def test_commands_stop_on_sigint_as_background_jobs(processes, command):
    args, nodes = COMMANDS[command]
    with RosHarness() as ros:
        proc = processes.start(args, sigint_ignored=True, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
        lines = _collect(proc)
        _wait_for(lambda: _in_graph(ros, nodes) or proc.poll() is not None, 60.0,
                  f'{nodes} in the graph')
        _stop_with_sigint(processes, proc, lines)
    if command == 'pipeline':  # every node it started stopped cleanly
        for node in nodes:
            assert f'{node} stopped (rc=0)' in ''.join(lines), ''.join(lines)


def test_every_executable_and_serving_command_is_covered():
    """A new console script or serving command must join the tests above."""
    import ast
    tree = ast.parse((REPO / 'setup.py').read_text())
    table = next(node.value for node in ast.walk(tree) if isinstance(node, ast.Assign)
                 and getattr(node.targets[0], 'id', '') == 'EXECUTABLES')
    scripts = set(ast.literal_eval(table)) - {'landmark_nav'}
    assert scripts == set(NODES) | {'bag_player'}
    from landmark_nav.tools.cli import build_parser
    from landmark_nav.tools.emulate import EMULATORS
    assert set(EMULATORS) == {'urg', 'lms200', 'p2os', 'robot'}
    commands = build_parser()._subparsers._group_actions[0].choices
    # the subcommands that serve until stopped (the others run to completion)
    serving = {'replay', 'drive', 'pipeline', 'emulate'}
    assert serving <= set(commands)
