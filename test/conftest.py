"""Shared test set-up: a private DDS domain on localhost; owned processes; shared runs.

Every process a test starts is owned: through the ``processes`` fixture (stopped, killed
if it must be, and reaped at the end of the test), and in any case found again by the
environment mark :func:`~landmark_nav.testing.processes.mark_descendants` gives it. A
test after which a process it started still runs fails (and the process is killed), and
so does the run if anything it started outlives it.
"""

import os
from pathlib import Path
import time
from typing import Callable, Dict, Tuple

from landmark_nav.testing import isolate_dds
from landmark_nav.testing.processes import (ChildProcesses, kill_all, mark_descendants,
                                            marked_processes, OWNER_VAR, SESSION_VAR)
import pytest

REPO = Path(__file__).resolve().parents[1]

isolate_dds()  # a domain of this process's own (each xdist worker its own), localhost only
SESSION = mark_descendants()


@pytest.fixture(scope='session')
def repo() -> Path:
    """Return the repository root."""
    return REPO


@pytest.fixture
def processes():
    """Start a test's processes; at its end stop (SIGTERM), kill if needed and reap them.

    A child still running 10 s after SIGTERM fails the test.
    """
    owner = ChildProcesses(grace=10.0)
    yield owner
    killed = owner.close()
    if killed:
        pytest.fail('did not stop within 10 s of SIGTERM, killed: ' + '; '.join(killed))


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
    if str(os.getpid()) != SESSION:
        return  # an xdist worker: the controller checks once the workers are gone
    leaked = marked_processes(SESSION_VAR, SESSION)
    for _ in range(100):  # xdist workers may take a moment to exit
        if not leaked:
            break
        time.sleep(0.1)
        leaked = marked_processes(SESSION_VAR, SESSION)
    if leaked:
        kill_all(list(leaked))
        reporter = session.config.pluginmanager.get_plugin('terminalreporter')
        if reporter is not None:
            reporter.write_line(f'error: processes started by the test run outlived it (now '
                                f'killed): {leaked}', red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


@pytest.fixture(scope='session')
def office_evaluation(tmp_path_factory) -> Callable[[str], Tuple[dict, Path]]:
    """Return ``get(association)``: ``evaluate_bag`` of bags/office, once per session.

    ``get`` gives the figures and the folder with the written files (TUM, slam.json,
    plots); test_evaluate_slam.py and test_trajectory.py need the same run.
    """
    from landmark_nav.evaluation.slam import evaluate_bag
    done: Dict[str, Tuple[dict, Path]] = {}

    def get(association: str) -> Tuple[dict, Path]:
        if association not in done:
            out = tmp_path_factory.mktemp(f'office_{association}')
            done[association] = (evaluate_bag(REPO / 'bags' / 'office', association, out,
                                              progress=False), out)
        return done[association]
    return get
