"""The suite's process checks catch what a test leaves running, at each level.

A pytest run of its own (the plugin :mod:`landmark_nav.testing.pytest_processes`, no
xdist) on a file whose tests leak in each way the checks guard against; the run must fail
naming each leak, and afterwards none of the processes it started may still run.
"""

import os
from pathlib import Path
import subprocess
import sys

from landmark_nav.testing.processes import marked_processes, SESSION_VAR

LEAKY = """
import os
import subprocess

# as if another xdist worker had started it: no test of this process owns it, only the
# run's check at its end sees it
other_owner = subprocess.Popen(['sleep', '61'],
                               env=dict(os.environ, LANDMARK_NAV_TEST_OWNER='another'))


def test_leaves_a_process_running():
    subprocess.Popen(['sleep', '62'])


def test_owned_child_ignores_sigterm(processes):
    child = processes.start(['bash', '-c', 'trap "" TERM; echo ready; sleep 63 & wait'],
                            stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline() == 'ready\\n'  # SIGTERM is ignored from here on


def test_owned_child_stops(processes):
    processes.start(['sleep', '64'])


def test_clean():
    assert subprocess.run(['true']).returncode == 0
"""


def test_each_leak_fails_its_test_or_the_run_and_is_killed(tmp_path):
    (tmp_path / 'test_leaky.py').write_text(LEAKY)
    env = {k: v for k, v in os.environ.items() if not k.startswith('PYTEST_XDIST')}
    env['PYTHONPATH'] = str(Path(__file__).resolve().parents[1])
    run = subprocess.Popen([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                            '-p', 'landmark_nav.testing.pytest_processes', '-p', 'no:xdist',
                            '--rootdir', str(tmp_path), str(tmp_path / 'test_leaky.py')],
                           env=env, cwd=tmp_path, stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    out, _ = run.communicate(timeout=120)
    assert run.returncode == 1, out
    assert 'ERROR at teardown of test_leaves_a_process_running' in out, out
    assert 'still running after the test' in out and 'sleep 62' in out, out
    assert 'ERROR at teardown of test_owned_child_ignores_sigterm' in out, out
    assert 'did not stop within 10 s of SIGTERM' in out, out
    # a child that stops on SIGTERM is simply stopped; a clean test has no error
    assert '4 passed, 2 errors' in out, out
    assert 'sleep 61' not in out.split('outlived it')[0], out  # no test's check saw it
    assert 'outlived it' in out and 'sleep 61' in out.split('outlived it')[1], out
    assert marked_processes(SESSION_VAR, str(run.pid)) == {}
