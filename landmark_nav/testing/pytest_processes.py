"""pytest plugin: every process a test starts is owned, and nothing outlives the run.

Loaded by the suite's ``conftest.py`` (``pytest_plugins``), or ``-p
landmark_nav.testing.pytest_processes``. It gives:

* the ``processes`` fixture (a :class:`~landmark_nav.testing.processes.ChildProcesses`):
  at the end of the test every child still running gets SIGTERM (to its process group),
  SIGKILL 10 s later, and is reaped; a child that had to be killed fails the test;
* a check after every test: a process the test started, at any depth, still running
  (found by the environment mark of :func:`~landmark_nav.testing.processes.mark_descendants`)
  is killed and fails the test;
* a check at the end of the run, by its first process (the xdist controller once its
  workers are gone): anything the run started still running is killed and fails the run.
"""

import os
import time

from landmark_nav.testing.processes import (ChildProcesses, kill_all, mark_descendants,
                                            marked_processes, OWNER_VAR, SESSION_VAR)
import pytest

#: Seconds a child gets between SIGTERM and SIGKILL at the end of its test.
GRACE_S = 10.0

SESSION = mark_descendants()


@pytest.fixture
def processes():
    """Start a test's processes; at its end stop (SIGTERM), kill if needed and reap them."""
    owner = ChildProcesses(grace=GRACE_S)
    yield owner
    killed = owner.close()
    if killed:
        pytest.fail(f'did not stop within {GRACE_S:g} s of SIGTERM, killed: '
                    + '; '.join(killed))


@pytest.fixture(autouse=True)
def _no_process_outlives_its_test():
    """Fail a test after which a process it started (at any depth) still runs."""
    yield
    leaked = marked_processes(OWNER_VAR, str(os.getpid()))
    if leaked:
        kill_all(list(leaked))
        pytest.fail(f'still running after the test (now killed): {leaked}')


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session):
    """Fail the run if a process it started outlives it (checked by the run's first process)."""
    if os.environ.get('PYTEST_XDIST_WORKER'):
        return  # the controller checks, once the workers are gone
    leaked = marked_processes(SESSION_VAR, SESSION)
    end = time.monotonic() + 10.0
    while leaked and time.monotonic() < end:  # xdist workers may take a moment to exit
        time.sleep(0.1)
        leaked = marked_processes(SESSION_VAR, SESSION)
    if leaked:
        kill_all(list(leaked))
        reporter = session.config.pluginmanager.get_plugin('terminalreporter')
        if reporter is not None:
            reporter.write_line(f'error: processes started by the test run outlived it '
                                f'(now killed): {leaked}', red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
