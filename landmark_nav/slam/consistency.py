"""Filter consistency checks of the corner chapter, section 3.6 (eqs. 56-60).

* NEES (eq. 59): ``e^T P^-1 e`` with ``e`` the true state minus the estimate; it needs the
  ground truth (simulation). For the robot pose ``e = [x, y, psi]`` with the heading error
  wrapped, ``d = 3``.
* NIS (eq. 60): ``nu^T S^-1 nu`` of the innovations accepted by the data association,
  ``d = dim(nu)``; it needs no ground truth.

Both are chi-square distributed with ``d`` degrees of freedom when the filter is
consistent. :func:`chi2_gate` gives the one-sided gate ``chi2_{d, 1 - alpha}`` (eq. 55, 59,
60) and :func:`chi2_band` the two-sided band ``[chi2_{d, alpha/2}, chi2_{d, 1 - alpha/2}]``
that a single run's NEES should stay inside on a share ``1 - alpha`` of the steps (below
the band the filter is pessimistic, above it optimistic).
"""

from functools import lru_cache
from typing import Tuple

from landmark_nav.geometry import wrap_angle
import numpy as np


@lru_cache(maxsize=256)
def chi2_gate(dof: int, probability: float = 0.95) -> float:
    """Return ``chi2_{dof, probability}``, the one-sided chi-square gate (eq. 55).

    Args:
        dof: Degrees of freedom ``d`` (>= 1).
        probability: Confidence ``1 - alpha`` in (0, 1).

    Returns:
        The ``probability`` quantile of the chi-square distribution with ``dof`` degrees.

    Raises:
        ValueError: If ``dof < 1`` or ``probability`` is not in (0, 1).
    """
    if int(dof) != dof or dof < 1:
        raise ValueError(f'chi2_gate: dof must be an integer >= 1, got {dof!r}')
    if not 0.0 < probability < 1.0:
        raise ValueError(f'chi2_gate: probability must be in (0, 1), got {probability!r}')
    # The quantile as scipy.stats.chi2.ppf computes it, 2 P^-1(d / 2, p) (P the regularised
    # lower incomplete gamma function), without importing scipy.stats (0.3 s); scipy.special
    # itself is imported here, on first use, not by every node start.
    from scipy.special import gammaincinv
    return float(2.0 * gammaincinv(0.5 * int(dof), probability))


def chi2_band(dof: int, probability: float = 0.95) -> Tuple[float, float]:
    """Return the two-sided ``probability`` band ``(chi2_{d, a/2}, chi2_{d, 1 - a/2})``.

    Args:
        dof: Degrees of freedom ``d`` (>= 1).
        probability: Coverage ``1 - a`` of the band, in (0, 1).

    Returns:
        ``(lower, upper)`` quantiles.
    """
    alpha = 1.0 - probability
    return chi2_gate(dof, 0.5 * alpha), chi2_gate(dof, 1.0 - 0.5 * alpha)


def nees(x_true: np.ndarray, x_est: np.ndarray, cov: np.ndarray,
         angle_index: Tuple[int, ...] = (2,)) -> float:
    """Normalised estimation error squared (eq. 59), ``e^T P^-1 e``.

    Args:
        x_true: (d,) true state (for the robot pose ``[x, y, psi]``).
        x_est: (d,) estimate.
        cov: (d, d) estimate covariance ``P``.
        angle_index: Components of ``e`` that are angles (wrapped to [-pi, pi)).

    Returns:
        The NEES; ``inf`` if ``P`` is singular while ``e`` is not in its range.
    """
    e = np.asarray(x_true, dtype=float) - np.asarray(x_est, dtype=float)  # eq. 58
    for i in angle_index:
        e[i] = wrap_angle(e[i])
    return _quadratic(e, np.asarray(cov, dtype=float))


def nis(innovation: np.ndarray, cov: np.ndarray) -> float:
    """Normalised innovation squared (eqs. 54, 60), ``nu^T S^-1 nu``.

    Args:
        innovation: (d,) innovation ``nu`` (bearings already wrapped).
        cov: (d, d) innovation covariance ``S``.

    Returns:
        The NIS; ``inf`` if ``S`` is singular while ``nu`` is not in its range.
    """
    return _quadratic(np.asarray(innovation, dtype=float).reshape(-1),
                      np.asarray(cov, dtype=float))


def _quadratic(e: np.ndarray, cov: np.ndarray) -> float:
    """Return ``e^T cov^-1 e`` through a Cholesky factor (pseudo-inverse if singular)."""
    if e.size == 0:
        return 0.0
    try:
        low = np.linalg.cholesky(cov)
        y = np.linalg.solve(low, e)
        return float(y @ y)
    except np.linalg.LinAlgError:
        w, v = np.linalg.eigh(0.5 * (cov + cov.T))
        tol = max(float(w.max(initial=0.0)), 1e-300) * 1e-12
        proj = v.T @ e
        if np.any((w <= tol) & (np.abs(proj) > 1e-12)):
            return float('inf')
        keep = w > tol
        return float(np.sum(proj[keep] ** 2 / w[keep]))


def share_inside(values: np.ndarray, dof: int, probability: float = 0.95,
                 two_sided: bool = True) -> float:
    """Return the share of ``values`` inside the chi-square band (or below the gate).

    Args:
        values: NEES or NIS values of a run.
        dof: Their degrees of freedom.
        probability: Band coverage / gate confidence.
        two_sided: Use :func:`chi2_band` (True) or the one-sided :func:`chi2_gate`.

    Returns:
        The fraction in [0, 1] (nan for no values).
    """
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return float('nan')
    if two_sided:
        lo, hi = chi2_band(dof, probability)
        return float(np.mean((v >= lo) & (v <= hi)))
    return float(np.mean(v <= chi2_gate(dof, probability)))


__all__ = ['chi2_band', 'chi2_gate', 'nees', 'nis', 'share_inside']
