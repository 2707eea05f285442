"""Return the C heap's free memory to the operating system in a long-running process.

A node or an emulator allocates and frees numpy arrays of many sizes at every input
(scans, line fits, the filter's matrices, status packets); glibc keeps the freed chunks
between live ones and returns only the top of its heaps, so the resident size of a long
run creeps up while the live data stays flat (ekf_slam on the emulated robot: malloc's
bytes in use flat at 36.5 MB, its free bytes 2.7 -> 4.7 MB in 4 minutes).
:func:`release_free_heap` calls ``malloc_trim(0)``, which returns every whole free page
(Linux ``madvise``), at most every :data:`HEAP_RELEASE_S`; the nodes call it from their
1 Hz diagnostics timers, ``landmark_nav emulate robot`` from its main loop. Without glibc
(another C library) nothing happens. No ROS here.
"""

import ctypes
import math
import time
from typing import Optional

#: Seconds between two calls of :func:`release_free_heap` that return memory to the OS.
HEAP_RELEASE_S = 10.0
_heap = {'trim': None, 'last': -math.inf}  # glibc's malloc_trim (False: none), last call


def release_free_heap(now: Optional[float] = None) -> bool:
    """Give the C heap's free pages back to the OS, at most every :data:`HEAP_RELEASE_S`.

    Args:
        now: Monotonic time [s] (default: now).

    Returns:
        Whether the heap was trimmed.
    """
    now = time.monotonic() if now is None else now
    if now - _heap['last'] < HEAP_RELEASE_S:
        return False
    _heap['last'] = now
    if _heap['trim'] is None:
        try:
            _heap['trim'] = ctypes.CDLL(None).malloc_trim  # the process's own C library
        except (OSError, AttributeError):
            _heap['trim'] = False
    if not _heap['trim']:
        return False
    _heap['trim'](0)
    return True


__all__ = ['HEAP_RELEASE_S', 'release_free_heap']
