"""Roughness ``F_sigma`` of the readings of a scan (§4.2, step 2).

The root of the local variance about a line fitted (total least squares, in the scan plane)
over the readings within ``window`` of path length along the scan, from windowed running
sums. Used by :func:`landmark_nav.road.terrain.classify_scan`.
"""

import numpy as np


def _window_bounds(s: np.ndarray, lo_off: float, hi_off: float) -> tuple[np.ndarray, ...]:
    """Index ranges [lo, hi) of the readings with s in [s_i + lo_off, s_i + hi_off]."""
    lo = np.searchsorted(s, s + lo_off, side='left')
    hi = np.searchsorted(s, s + hi_off, side='right')
    return lo, hi


def _moments(u: np.ndarray, v: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Windowed count, means and central second moments of (u, v)."""
    cs = np.zeros((5, u.size + 1))
    np.cumsum(np.vstack([u, v, u * u, v * v, u * v]), axis=1, out=cs[:, 1:])
    su, sv, suu, svv, suv = cs[:, hi] - cs[:, lo]
    n = (hi - lo).astype(float)
    with np.errstate(invalid='ignore', divide='ignore'):
        mu, mv = su / n, sv / n
        cuu = suu / n - mu * mu
        cvv = svv / n - mv * mv
        cuv = suv / n - mu * mv
    return n, cuu, cvv, cuv


def _roughness(plane: np.ndarray, s: np.ndarray, window: float, min_points: int) -> np.ndarray:
    """F_sigma: rms distance to the total-least-squares line over ``window`` of path length."""
    lo, hi = _window_bounds(s, -0.5 * window, 0.5 * window)
    # Centre the coordinates for numerical accuracy of the running sums.
    u = plane[:, 0] - plane[:, 0].mean()
    v = plane[:, 1] - plane[:, 1].mean()
    n, cuu, cvv, cuv = _moments(u, v, lo, hi)
    tr = cuu + cvv
    det = cuu * cvv - cuv * cuv
    smallest = 0.5 * tr - np.sqrt(np.maximum(0.25 * tr * tr - det, 0.0))
    out = np.sqrt(np.maximum(smallest, 0.0))
    out[n < min_points] = np.inf
    return out
