"""Stop a serving process on SIGINT and SIGTERM, whatever signal disposition it inherited.

A process started as a background job of a non-interactive shell (``bash -c 'cmd &'``)
starts with SIGINT ignored, and Python keeps it ignored: ``kill -INT`` or Ctrl-C sent by a
script would never stop it. Every command that serves until stopped (the emulators, the
drive tool) installs its handlers for both signals explicitly; the ROS nodes get theirs
from ``rclpy.init``, which installs them whatever the inherited disposition.
"""

import signal
import threading

#: The signals that stop a serving command (Ctrl-C and ``kill``'s default).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def stop_on_signals(stop: threading.Event) -> bool:
    """Set ``stop`` on SIGINT or SIGTERM, even if the process started with SIGINT ignored.

    Args:
        stop: Set by the handler; the serving loop waits on it.

    Returns:
        Whether the handlers were installed: only the main thread can install them (a
        command run in a thread, as tests do, is stopped through ``stop`` instead).

    """
    if threading.current_thread() is not threading.main_thread():
        return False
    for sig in STOP_SIGNALS:
        signal.signal(sig, lambda signum, frame: stop.set())
    return True
