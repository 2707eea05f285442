"""Processes a test starts: owned, stopped and reaped whatever happens; leaks found.

:class:`ChildProcesses` starts each child in a session (process group) of its own and, when
closed, terminates what still runs (SIGTERM to the group), kills what ignores that
(SIGKILL to the group) and reaps it; it reports what it had to kill, which a test fixture
turns into a failure.

Every process a test run starts carries two environment variables (set by
:func:`mark_descendants` in the test process, inherited by everything below it):
``LANDMARK_NAV_TEST_SESSION`` (the run) and ``LANDMARK_NAV_TEST_OWNER`` (the test process
that started it, e.g. one pytest-xdist worker). :func:`marked_processes` finds them in
``/proc`` even after they left their process group or lost their parent, so a check after
each test and one at the end of the run can tell that nothing the suite started outlives it.
"""

import os
from pathlib import Path
import signal
import subprocess
import time
from typing import Dict, List, Optional, Sequence

SESSION_VAR = 'LANDMARK_NAV_TEST_SESSION'
OWNER_VAR = 'LANDMARK_NAV_TEST_OWNER'


def mark_descendants() -> str:
    """Mark the processes this one starts from now on; return the run's session id.

    The first process of a run (pytest, or the pytest-xdist controller) sets the session id
    to its pid; an xdist worker (``PYTEST_XDIST_WORKER`` set) keeps its controller's. The
    owner is always this process.
    """
    if not os.environ.get('PYTEST_XDIST_WORKER'):
        os.environ[SESSION_VAR] = str(os.getpid())
    os.environ.setdefault(SESSION_VAR, str(os.getpid()))
    os.environ[OWNER_VAR] = str(os.getpid())
    return os.environ[SESSION_VAR]


def _environment(pid: int) -> bytes:
    """Return the environment of a process as ``/proc`` has it (b'' when unreadable)."""
    try:
        with open(f'/proc/{pid}/environ', 'rb') as f:
            return f.read()
    except OSError:  # gone, or not ours to read
        return b''


def command_line(pid: int) -> str:
    """Return the command line of a process ('' when it is gone)."""
    try:
        raw = Path(f'/proc/{pid}/cmdline').read_bytes()
    except OSError:
        return ''
    return ' '.join(part.decode(errors='replace') for part in raw.split(b'\0') if part)


def marked_processes(var: str, value: str, exclude: Sequence[int] = ()) -> Dict[int, str]:
    """Return {pid: command line} of the live processes whose environment has ``var=value``.

    Zombies (exited, not yet reaped) have no environment left and are not listed.
    """
    # each NUL-terminated entry of the environment looked up as bytes (run after every test:
    # pathlib and decoding every process's whole environment into a dict were most of it)
    name, entry = f'{var}='.encode(), f'\0{var}={value}\0'.encode()
    found = {}
    for pid_name in os.listdir('/proc'):
        if not pid_name.isdigit():
            continue
        pid = int(pid_name)
        if pid in exclude or pid == os.getpid():
            continue
        env = _environment(pid)
        if name in env and entry in b'\0' + env + b'\0':
            found[pid] = command_line(pid)
    return found


def kill_all(pids: Sequence[int], grace: float = 2.0) -> None:
    """SIGTERM the processes, wait up to ``grace`` seconds, then SIGKILL what is left."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in pids:
            try:
                os.kill(pid, sig)
            except OSError:
                pass
        end = time.monotonic() + grace
        while time.monotonic() < end and any(_alive(pid) for pid in pids):
            time.sleep(0.05)


def _alive(pid: int) -> bool:
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != 'Z'


class ChildProcesses:
    """The processes one test started; :meth:`close` stops and reaps every one of them.

    Example::

        def test_x(processes):
            proc = processes.start([exe, '--flag'], stdout=subprocess.PIPE, text=True)
            ...
            assert processes.stop(proc, signal.SIGINT, timeout=5.0) == 0
    """

    def __init__(self, grace: float = 10.0) -> None:
        """Own no process yet; ``grace`` is what :meth:`close` gives SIGTERM before SIGKILL."""
        self.grace = grace
        self._procs: List[subprocess.Popen] = []
        self._groups: List[int] = []  # the children that lead a process group of their own

    def start(self, args: Sequence[str], sigint_ignored: bool = False,
              **popen_kwargs) -> subprocess.Popen:
        """Start a child in a process group of its own and own it.

        Args:
            args: The command.
            sigint_ignored: Start it with SIGINT ignored, as ``bash -c 'cmd &'`` does to a
                background job (it must still stop on SIGINT); otherwise with SIGINT at its
                default, whatever the test run itself was started with (a test run started
                as a background job has it ignored, and a child would inherit that).
            **popen_kwargs: Passed to :class:`subprocess.Popen`.

        """
        popen_kwargs.setdefault('start_new_session', True)
        if sigint_ignored:
            popen_kwargs['preexec_fn'] = _ignore_sigint
        else:
            popen_kwargs.setdefault('preexec_fn', _default_sigint)
        proc = subprocess.Popen(list(args), **popen_kwargs)
        self._procs.append(proc)
        if popen_kwargs['start_new_session']:
            self._groups.append(proc.pid)
        return proc

    def stop(self, proc: subprocess.Popen, sig: int = signal.SIGTERM,
             timeout: float = 30.0) -> Optional[int]:
        """Send ``sig`` and wait up to ``timeout`` s; return the exit code (None: still runs)."""
        if proc.poll() is None:
            proc.send_signal(sig)
        try:
            return proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def close(self) -> List[str]:
        """Terminate, then kill, then reap every child and its group; return what was killed.

        Returns:
            One line per child that was still running after SIGTERM and ``grace`` seconds
            (its command line): a child that would not stop.

        """
        running = [p for p in self._procs if p.poll() is None]
        for proc in running:
            self._signal(proc, signal.SIGTERM)
        end = time.monotonic() + self.grace
        killed = []
        for proc in running:
            try:
                proc.wait(max(0.0, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                killed.append(f'pid {proc.pid}: {_args(proc)}')
                self._signal(proc, signal.SIGKILL)
                proc.wait()
        for proc in self._procs:  # what is left of each group (a child's own children)
            if proc.pid in self._groups:
                self._signal(proc, signal.SIGKILL)
            for stream in (proc.stdin, proc.stdout, proc.stderr):
                if stream is not None:
                    stream.close()
        self._procs.clear()
        self._groups.clear()
        return killed

    def _signal(self, proc: subprocess.Popen, sig: int) -> None:
        """Signal the child's process group if it leads one, else the child alone."""
        try:
            if proc.pid in self._groups:
                os.killpg(proc.pid, sig)
            else:
                proc.send_signal(sig)
        except OSError:  # gone
            pass


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _args(proc: subprocess.Popen) -> str:
    args = proc.args
    return ' '.join(map(str, args)) if isinstance(args, (list, tuple)) else str(args)
