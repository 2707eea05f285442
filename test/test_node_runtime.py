"""Every node's main: thread limits, one-line parameter errors, clean shutdown on signals."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time

import pytest

REPO = Path(__file__).resolve().parents[1]
NODES = ['corner_extractor', 'line_extractor', 'ekf_slam', 'sonar_localizer',
         'landmark_detector']

# Run a node's main with rclpy.spin replaced by a probe that prints the thread pools.
PROBE = """
import importlib, sys
import rclpy
from threadpoolctl import threadpool_info
def spin(node):
    import scipy.linalg  # its OpenBLAS loaded after the limit, as the cores load it on first use
    pools = sorted((i['internal_api'], i['num_threads']) for i in threadpool_info())
    import cv2
    print('POOLS', pools, 'cv2', cv2.getNumThreads(), flush=True)
    raise KeyboardInterrupt
rclpy.spin = spin
module = importlib.import_module('landmark_nav.nodes.' + sys.argv[1])
sys.exit(module.main([sys.argv[0]]))
"""


def node_env(**extra) -> dict:
    """Return the environment of a node subprocess (no thread variables unless given)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS',
                        'BLIS_NUM_THREADS', 'LANDMARK_NAV_THREADS')}
    env['PYTHONPATH'] = str(REPO) + os.pathsep + env.get('PYTHONPATH', '')
    env.update(extra)
    return env


def probe_pools(node: str, **extra) -> str:
    """Return the POOLS line a node prints when it starts spinning."""
    out = subprocess.run([sys.executable, '-c', PROBE, node], env=node_env(**extra),
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return [line for line in out.stdout.splitlines() if line.startswith('POOLS')][0]


@pytest.mark.parametrize('node', NODES)
def test_numerical_libraries_are_single_threaded_in_every_node(node):
    line = probe_pools(node)
    pools = eval(line.split(' ', 1)[1].rsplit(' cv2', 1)[0])
    assert pools and all(n == 1 for _, n in pools), line
    assert line.endswith('cv2 1'), line


# Heavy libraries a node may load at import (every other one is imported where it is used):
# OpenCV in the image nodes (their conversions and cores), GTSAM in graph_slam.
ALLOWED_AT_IMPORT = {
    'graph_slam': {'gtsam'}, 'road_classifier': {'cv2'},
    'landmark_detector': {'cv2'}, 'model_localizer': {'cv2'}, 'corridor_follower': {'cv2'}}
# One process for all executables: a node is charged with the heavy modules its import adds,
# so the nodes that must load none come first.
HEAVY_PROBE = """
import ast, importlib, sys
def heavy():
    return {'.'.join(m.split('.')[:2]) if m.startswith('scipy.') else m.split('.')[0]
            for m in sys.modules
            if m.split('.')[0] in ('cv2', 'evo', 'gtsam', 'matplotlib', 'pandas', 'sklearn',
                                   'torch')
            or (m.startswith('scipy.') and m[6].isalpha() and m != 'scipy.version')}
tree = ast.parse(open(sys.argv[1]).read())
exes = next(ast.literal_eval(n.value) for n in tree.body
            if isinstance(n, ast.Assign) and n.targets[0].id == 'EXECUTABLES')
nodes = sorted((v.split(':')[0] for v in exes.values() if '.nodes.' in v),
               key=lambda m: m.rsplit('.', 1)[1] in sys.argv[2:])
added = {}
for m in nodes:
    before = heavy()
    importlib.import_module(m)
    added[m.rsplit('.', 1)[1]] = sorted(heavy() - before)
print(added)
"""


def test_node_modules_import_no_heavy_library_they_load_on_first_use():
    """scipy.linalg / spatial / sparse, matplotlib, ... cost up to 0.6 CPU-s per node start."""
    out = subprocess.run([sys.executable, '-c', HEAVY_PROBE, str(REPO / 'setup.py'),
                          *ALLOWED_AT_IMPORT], env=node_env(), capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    added = eval(out.stdout)
    assert len(added) == 12, out.stdout
    assert all(set(mods) <= ALLOWED_AT_IMPORT.get(node, set()) for node, mods in added.items()), \
        out.stdout


def test_thread_limit_can_be_configured():
    line = probe_pools('ekf_slam', LANDMARK_NAV_THREADS='2')
    pools = eval(line.split(' ', 1)[1].rsplit(' cv2', 1)[0])
    assert all(n == 2 for _, n in pools) and line.endswith('cv2 2'), line
    line = probe_pools('ekf_slam', OPENBLAS_NUM_THREADS='2')  # the user's own setting stays
    assert ('openblas', 2) in eval(line.split(' ', 1)[1].rsplit(' cv2', 1)[0]), line


def run_main(node: str, *ros_args: str, cwd=None) -> subprocess.CompletedProcess:
    """Run a node's main with ROS arguments until it exits (it must exit by itself)."""
    return subprocess.run([sys.executable, '-m', f'landmark_nav.nodes.{node}', '--ros-args',
                           *ros_args], env=node_env(), capture_output=True, text=True,
                          timeout=120, cwd=cwd or REPO)


@pytest.mark.parametrize('node, name, value, expected', [
    ('ekf_slam', 'confirm_hits', '2.5', 'expected an integer, got 2.5 (a double'),
    ('ekf_slam', 'r_scale', '5', 'expected a double, got 5 (an integer); write 5.0 for a double'),
    ('laser_driver', 'stale_warn', '5', 'expected a double, got 5 (an integer)'),
    ('base_driver', 'cmd_vel_timeout', 'true', 'expected a double, got True (a bool)'),
    ('sonar_localizer', 'filter', '3', 'expected a string, got 3 (an integer)'),
    ('sonar_localizer', 'sonar_topics', '5', 'expected a list of strings, got 5'),
    ('corner_extractor', 'refine', '1.0', 'expected a bool (true / false), got 1.0'),
])
def test_wrong_parameter_types_are_one_line_errors(node, name, value, expected):
    """A wrong type used to print a 20-line traceback."""
    out = run_main(node, '-p', f'{name}:={value}')
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1, out.stderr
    assert lines[0].startswith('error: ') and f'parameter {name}: expected ' in lines[0]
    assert expected in lines[0], lines[0]


def test_parameters_say_they_are_read_only():
    from landmark_nav.nodes.ekf_slam import EkfSlamNode
    from landmark_nav.testing import RosHarness
    from rclpy.parameter import Parameter
    with RosHarness() as ros:
        node = EkfSlamNode(context=ros.context)
        described = node.describe_parameter('r_scale')
        result = node.set_parameters([Parameter('r_scale', value=2.0)])[0]
        node.destroy_node()
    assert described.read_only and 'read-only: set at start-up' in described.description
    assert not result.successful and 'read-only' in result.reason and 'r_scale' in result.reason


def test_config_paths_work_from_any_directory(tmp_path):
    """README commands with config/... paths only worked from the repository root."""
    out = subprocess.run([sys.executable, '-m', 'landmark_nav.tools.cli', 'config', 'ekf_slam'],
                         env=node_env(), capture_output=True, text=True, timeout=60,
                         cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    path = Path(out.stdout.strip())
    assert path.is_absolute() and path.read_text() == (REPO / 'config/ekf_slam.yaml').read_text()
    readme = (REPO / 'README.md').read_text()
    assert '--params-file config/' not in readme and '$(landmark_nav config' in readme


def test_ekf_slam_says_when_an_absent_scan_publisher_comes():
    """A laser that starts after ekf_slam: its first message says lines are off, not for good."""
    from types import SimpleNamespace
    from landmark_nav.nodes.ekf_slam import EkfSlamNode
    from landmark_nav.testing import RosHarness
    said, sets = [], []
    with RosHarness() as ros:
        node = EkfSlamNode(context=ros.context)
        node.get_logger = lambda: SimpleNamespace(info=said.append)
        node._feature_set = lambda stamp, corners, scan: (stamp, corners, scan)
        node._add_features = sets.append
        publishers = {'corners'}
        node._has_publisher = lambda part: part in publishers
        node._offer('corners', 1000, 'c1')  # no scan publisher yet: the set goes on alone
        publishers.add('scan')
        node._offer('corners', 2000, 'c2')
        node._offer('scan', 2000, 's2')
        node.destroy_node()
    assert sets == [(1000, 'c1', None), (2000, 'c2', 's2')]
    assert said == ['No publisher on scan: feature sets go on without it (no lines, no '
                    'visibility pruning)',
                    'scan arrived: feature sets use it from the set at 2000 ns on']


def test_unknown_config_name_lists_the_shipped_files():
    from landmark_nav.tools.config_files import available, config_path
    with pytest.raises(FileNotFoundError) as err:
        config_path('bag_player')
    message = str(err.value)
    assert 'no parameter file bag_player.yaml' in message
    assert 'the shipped files: ' + ', '.join(available()) in message
    assert 'ekf_slam, ekf_slam_chapter' in message and '--help' in message


def _start(processes, args, env):
    return processes.start([sys.executable, '-m', *args], env=env, cwd=REPO,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


class _Child:
    """A started child whose stdout and stderr threads collect, so a test can wait on them."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.proc = proc
        self._out, self._err = [], []
        self._threads = [threading.Thread(target=self._read, args=(stream, lines), daemon=True)
                         for stream, lines in ((proc.stdout, self._out),
                                               (proc.stderr, self._err))]
        for t in self._threads:
            t.start()

    @staticmethod
    def _read(stream, lines) -> None:
        for line in stream:
            lines.append(line)

    def err(self) -> str:
        """Return the stderr so far (all of it once the child has exited)."""
        if self.proc.poll() is not None:
            for t in self._threads:
                t.join(5.0)
        return ''.join(self._err)

    def communicate(self, timeout: float):
        """Wait for the exit like ``Popen.communicate``; return (stdout, stderr)."""
        self.proc.wait(timeout=timeout)
        for t in self._threads:
            t.join(timeout)
        return ''.join(self._out), ''.join(self._err)


def _wait_for(condition, timeout: float, what: str) -> None:
    """Poll ``condition`` every 0.1 s until it holds; fail after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, f'not within {timeout} s: {what}'
        time.sleep(0.1)


def _signal_all(children: dict, sig) -> dict:
    """Check every child still runs, send ``sig`` to all, check each exits 0 without a traceback.

    Returns:
        Each child's stderr by name.
    """
    assert all(c.proc.poll() is None for c in children.values()), {
        n: c.err() for n, c in children.items() if c.proc.poll() is not None}
    for c in children.values():
        c.proc.send_signal(sig)
    errs = {}
    for name, c in children.items():
        try:
            _, err = c.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            # where it hangs: the children run with faulthandler, which prints every
            # thread's Python stack on SIGABRT
            c.proc.send_signal(signal.SIGABRT)
            _, err = c.communicate(timeout=10)
            pytest.fail(f'{name} still ran 60 s after {signal.Signals(sig).name}; its '
                        f'threads on SIGABRT:\n{err}')
        assert 'Traceback' not in err, f'{name}:\n{err}'
        assert c.proc.returncode == 0, f'{name} exited with {c.proc.returncode}:\n{err}'
        errs[name] = err
    return errs


# the line each node logs once it is constructed (before it spins)
STARTED = {'corner_extractor': 'corner_extractor: method',
           'line_extractor': 'line_extractor: method', 'ekf_slam': 'ekf_slam: landmarks',
           'sonar_localizer': 'sonar_localizer: ', 'landmark_detector': 'landmark_detector: '}


@pytest.mark.dds
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_nodes_and_bag_player_stop_cleanly_on_signals(sig, processes):
    """Ctrl-C or kill printed tracebacks (bag_player, ekf_slam while processing)."""
    env = node_env(PYTHONFAULTHANDLER='1')  # a child that hangs says where (_signal_all)
    nodes = {n: _Child(_start(processes, [f'landmark_nav.nodes.{n}'], env)) for n in NODES}
    # start-up: every node has logged its start line (it slept a fixed 8 s)
    _wait_for(lambda: all(STARTED[n] in c.err() or c.proc.poll() is not None
                          for n, c in nodes.items()), 60.0, 'the nodes start')
    player = _Child(_start(processes, ['landmark_nav.nodes.bag_player',
                                       str(REPO / 'bags' / 'office'), '--rate', '2'], env))
    time.sleep(6.0)  # data flowing through every node
    for name, err in _signal_all(dict(nodes, bag_player=player), sig).items():
        assert 'Error' not in err, f'{name}:\n{err}'


# The bag player's publish sends SIGINT to its own process on its fifth message, as a Ctrl-C
# arriving while a message is being written: the count must include it. (SIGTERM goes to the
# same handler.)
SIGNAL_DURING_PUBLISH = """
import os, signal, sys
from rclpy.publisher import Publisher
from landmark_nav.nodes import bag_player
sent = []
publish = Publisher.publish
def publish_then_signal(self, msg):
    publish(self, msg)
    if self.topic_name != '/scan':
        return  # e.g. /parameter_events
    sent.append(1)
    if len(sent) == 5:
        os.kill(os.getpid(), getattr(signal, sys.argv[2]))
Publisher.publish = publish_then_signal
bag_player.main(['bag_player', sys.argv[1], '--topics', '/scan', '--wait-for-subscribers', '0'])
print('sent', len(sent), flush=True)
"""


def test_bag_player_counts_the_message_a_stop_signal_interrupts():
    """A stop signal during a publish: the count has the message (rclpy's handler lost it)."""
    bag = str(REPO / 'bags' / 'office')
    out = subprocess.run([sys.executable, '-c', SIGNAL_DURING_PUBLISH, bag, 'SIGINT'],
                         env=node_env(), capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert 'bag_player: stopped: published 5 messages (/scan 5)' in out.stdout, out.stdout
    assert 'sent 5' in out.stdout, out.stdout


@pytest.mark.dds
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_drivers_stop_cleanly_on_signals(tmp_path, sig, processes):
    env = node_env()
    urg, p2os = str(tmp_path / 'urg'), str(tmp_path / 'p2os')
    emulate = ['landmark_nav.tools.cli', 'emulate']
    emulators = [_start(processes, emulate + ['urg', '--link', urg], env),
                 _start(processes, emulate + ['p2os', '--link', p2os, '--tcp', '0'], env)]
    # the emulators serve their links (it slept a fixed 4 s)
    _wait_for(lambda: (os.path.islink(urg) and os.path.islink(p2os))
              or any(p.poll() is not None for p in emulators), 30.0, 'the emulators serve')
    drivers = {'laser_driver': _Child(_start(processes, ['landmark_nav.nodes.laser_driver',
                                                         '--ros-args', '-p', f'port:={urg}'],
                                             env)),
               'base_driver': _Child(_start(processes, ['landmark_nav.nodes.base_driver',
                                                        '--ros-args', '-p', f'port:={p2os}'],
                                            env))}

    def connected(c):
        err = c.err()
        return 'connected' in err or 'opened' in err.lower() or c.proc.poll() is not None
    # connected (it slept a fixed 8 s), then publishing for a second
    _wait_for(lambda: all(connected(c) for c in drivers.values()), 60.0, 'the drivers connect')
    time.sleep(1.0)
    for name, err in _signal_all(drivers, sig).items():
        assert 'connected' in err or 'opened' in err.lower(), f'{name} never connected:\n{err}'
    # the emulators stop on the same signal and remove their pty links
    for p in emulators:
        assert processes.stop(p, sig, timeout=30.0) == 0
    assert not os.path.lexists(urg) and not os.path.lexists(p2os)


# A node whose destruction never ends (as rcl's has, rarely, in Fast DDS after SIGINT).
STUCK = """
import sys, time
import rclpy
from rclpy.node import Node
from landmark_nav.nodes import common
common.SHUTDOWN_TIMEOUT_S = 1.0
class Stuck(Node):
    def __init__(self):
        super().__init__('stuck')
        self.create_timer(0.1, lambda: rclpy.try_shutdown())
    def destroy_node(self):
        print('destroying', flush=True)
        time.sleep(60.0)
sys.exit(common.run_node(Stuck, [sys.argv[0]]))
"""


def test_a_node_whose_destruction_hangs_still_exits_with_its_stacks():
    start = time.monotonic()
    out = subprocess.run([sys.executable, '-c', STUCK], env=node_env(), capture_output=True,
                         text=True, timeout=50)
    assert 'destroying' in out.stdout, out.stderr
    assert time.monotonic() - start < 30.0  # not the 60 s sleep
    assert out.returncode == 1, (out.returncode, out.stderr)
    assert 'Timeout' in out.stderr and 'destroy_node' in out.stderr, out.stderr


# Ctrl-C pressed again while a node shuts down: its destruction (a driver joining its I/O
# thread) receives the second SIGINT. It used to raise KeyboardInterrupt there (a traceback,
# exit status 1); now the shutdown ignores it and ends normally.
SECOND_SIGINT = """
import os, signal, sys, time
import rclpy
from rclpy.node import Node
from landmark_nav.nodes import common
class Joining(Node):
    def __init__(self):
        super().__init__('joining')
        self.create_timer(0.1, lambda: os.kill(os.getpid(), signal.SIGINT))
    def destroy_node(self):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)       # where the second signal would raise
        print('destroyed', flush=True)
        super().destroy_node()
before = signal.getsignal(signal.SIGINT)  # SIG_IGN when the test run is a background job
code = common.run_node(Joining, [sys.argv[0]])
print('handler restored:', signal.getsignal(signal.SIGINT) is before)
sys.exit(code)
"""


def test_a_second_sigint_during_the_shutdown_is_not_a_traceback():
    out = subprocess.run([sys.executable, '-c', SECOND_SIGINT], env=node_env(),
                         capture_output=True, text=True, timeout=60)
    assert out.stdout.split('\n')[:2] == ['destroyed', 'handler restored: True'], out
    assert out.returncode == 0 and 'Traceback' not in out.stderr, out


def run_owned(processes, args, cwd=None):
    """Run a command owned by the ``processes`` fixture until it exits; return (code, stderr)."""
    proc = processes.start(args, env=node_env(), stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, cwd=cwd or REPO)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, err


def error_lines(stderr: str) -> list:
    """Return the lines of a node's stderr that are its own errors (not ROS log lines)."""
    return [line for line in stderr.splitlines() if line.startswith('error: ')]


def test_the_ekf_slam_executable_refuses_a_misspelt_parameter(processes):
    """``ros2 run landmark_nav ekf_slam --ros-args -p max_sped:=1.0`` used to run on."""
    exe = str(Path(sys.executable).parent / 'ekf_slam')  # the console script
    code, err = run_owned(processes, [exe, '--ros-args', '-p', 'max_sped:=1.0'])
    assert code == 2, err
    # the error alone: no start-up INFO line before it (the node never ran)
    assert err.splitlines() == [
        "error: ekf_slam has no parameter 'max_sped' (did you mean max_speed?)"], err


def test_a_misspelt_name_in_a_parameter_file_is_refused(processes, tmp_path):
    """Nested keys of a --params-file are checked too (odometry.*)."""
    path = tmp_path / 'params.yaml'
    path.write_text('ekf_slam:\n  ros__parameters:\n    max_speed: 1.0\n'
                    '    odometry:\n      sigma_xy_per_sqrt: 0.1\n')
    code, err = run_owned(processes, [sys.executable, '-m', 'landmark_nav.nodes.ekf_slam',
                                      '--ros-args', '--params-file', str(path)])
    assert code == 2, err
    assert error_lines(err) == ["error: ekf_slam has no parameter 'odometry.sigma_xy_per_sqrt' "
                                '(did you mean odometry.sigma_xy_per_sqrt_m?)'], err


@pytest.mark.parametrize('node, name, near', [
    ('corner_extractor', 'sigma_rr', 'sigma_r'),
    ('line_extractor', 'min_pionts', 'min_points'),
    ('sonar_localizer', 'filtr', 'filter'),
    ('base_driver', 'cmd_vel_timeuot', 'cmd_vel_timeout'),
    ('landmark_detector', 'landmark_mapp', 'landmark_map'),
    ('laser_driver', 'angle_mni', 'angle_min'),
])
def test_every_node_refuses_an_undeclared_parameter(processes, node, name, near):
    """The error is all the node prints: no start-up line, no driver opening its port."""
    code, err = run_owned(processes, [sys.executable, '-m', f'landmark_nav.nodes.{node}',
                                      '--ros-args', '-p', f'{name}:=1.0'])
    assert code == 2, err
    assert err.splitlines() == [
        f"error: {node} has no parameter '{name}' (did you mean {near}?)"], err


#: Run a node's main with rclpy.spin replaced by a probe that prints SPINNING and returns.
SPIN_PROBE = """
import importlib, sys
import rclpy
def spin(node):
    print('SPINNING', flush=True)
    raise KeyboardInterrupt
rclpy.spin = spin
module = importlib.import_module('landmark_nav.nodes.' + sys.argv[1])
sys.exit(module.main([sys.argv[0], '--ros-args'] + sys.argv[2:]))
"""


@pytest.mark.parametrize('profile', ['ekf_slam', 'ekf_slam_chapter'])
def test_the_shipped_parameter_files_pass_the_check(processes, profile):
    """The shipped files hold declared names only: the node starts and spins."""
    proc = processes.start([sys.executable, '-c', SPIN_PROBE, 'ekf_slam', '--params-file',
                            str(REPO / 'config' / 'ekf_slam.yaml'), '--params-file',
                            str(REPO / 'config' / f'{profile}.yaml')],
                           env=node_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True, cwd=REPO)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0 and 'SPINNING' in out and not error_lines(err), err


def test_the_bag_player_refuses_a_parameter(processes):
    """Its options are arguments (--rate); a -p override would be silently unused."""
    code, err = run_owned(processes, [sys.executable, '-m', 'landmark_nav.nodes.bag_player',
                                      str(REPO / 'bags' / 'office'), '--ros-args', '-p',
                                      'rate:=2.0'])
    assert code == 2, err
    assert "bag_player: error: bag_player has no parameter 'rate'" in err.splitlines(), err


#: run_node with a node whose start-up is interrupted (rclpy shut down as SIGTERM does).
STARTUP_SIGNAL_PROBE = """
import sys
import rclpy
from rclpy.node import Node
from landmark_nav.nodes.common import run_node
def factory():
    node = Node('startup_probe')
    rclpy.try_shutdown()  # what SIGINT / SIGTERM during the constructor does
    return node
sys.exit(run_node(factory, [sys.argv[0]]))
"""


def test_a_signal_during_the_start_up_stops_the_node_without_a_traceback(processes):
    """Ctrl-C while a node was constructing: exit 0, and no rclpy Executor.__del__ trace."""
    code, err = run_owned(processes, [sys.executable, '-c', STARTUP_SIGNAL_PROBE])
    assert (code, err) == (0, ''), err
