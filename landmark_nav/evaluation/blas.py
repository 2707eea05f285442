"""Offline runs with the numerical libraries' thread pools as the nodes have them."""

import functools
import sys
from typing import Callable, TypeVar

from threadpoolctl import threadpool_limits

F = TypeVar('F', bound=Callable)


def single_threaded(func: F) -> F:
    """Run ``func`` with BLAS (and OpenMP) limited to one thread, as the nodes run.

    The nodes limit their thread pools to one thread (:func:`landmark_nav.nodes.common.
    limit_threads`): their matrices are small. So are those of the offline runs of the same
    code (the SLAM filter, the landmark detector), and there OpenBLAS's threads cost
    far more than they save: its triangular solve (``dtrtrs``, any size) and products of a
    few hundred rows wake a second thread on every call, and on a busy CPU each wake-up
    waits milliseconds for it. The limit is set on each call (for libraries loaded by
    then) and the previous limits are restored on return. OpenCV's pool, when OpenCV is
    loaded, is limited to one thread the same way (``cv2.setNumThreads``, restored on return):
    a 480 x 360 road frame took 99 ms per frame with the default pools on a busy 2-core
    machine against 22 ms with one thread.
    """
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        cv2 = sys.modules.get('cv2')
        threads = cv2.getNumThreads() if cv2 is not None else None
        try:
            if cv2 is not None:
                cv2.setNumThreads(1)
            with threadpool_limits(limits=1):
                return func(*args, **kwargs)
        finally:
            if cv2 is not None:
                cv2.setNumThreads(threads)
    return wrapper  # type: ignore[return-value]


__all__ = ['single_threaded']
