"""Small numerical helpers shared by the SLAM modules: triangular solve, angle wrap."""

import functools
import math

from landmark_nav.geometry import wrap_angle
import numpy as np


@functools.cache
def lapack():
    """Return ``scipy.linalg.lapack``, imported on first use.

    Importing ``scipy.linalg`` costs about 0.3 CPU-s, which every node process would pay at
    start-up (help, parameter errors included); the cached module keeps the per-call cost
    of the solvers below a dictionary lookup.
    """
    from scipy.linalg import lapack as module
    return module


def solve_lower(low: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve ``L X = B`` for a lower-triangular ``L`` (LAPACK ``dtrtrs``).

    ``scipy.linalg.solve_triangular`` is avoided on purpose: in SciPy 1.17 with a threaded
    OpenBLAS it costs milliseconds even for 6 x 6 systems; the LAPACK routine takes
    microseconds.

    Args:
        low: (n, n) lower-triangular matrix with a non-zero diagonal.
        b: (n,) or (n, k) right-hand side.

    Returns:
        ``X`` with the shape of ``b``.

    Raises:
        numpy.linalg.LinAlgError: If ``L`` is singular.
    """
    if b.size == 0:
        return np.zeros(b.shape)
    x, info = lapack().dtrtrs(low, b, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f'triangular solve failed (LAPACK info {info})')
    return x


_PI = math.pi
_TWO_PI = 2.0 * math.pi


def _wrap(a):
    """Wrap angle(s) to [-pi, pi) (fast path of :func:`landmark_nav.geometry.wrap_angle`)."""
    if isinstance(a, float):
        return a if -_PI <= a < _PI else float(wrap_angle(a))
    return np.mod(a + _PI, _TWO_PI) - _PI
