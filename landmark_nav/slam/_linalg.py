"""Small dense linear-algebra helpers shared by the SLAM modules."""

import numpy as np
from scipy.linalg.lapack import dtrtrs


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
    x, info = dtrtrs(low, b, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f'triangular solve failed (LAPACK info {info})')
    return x
