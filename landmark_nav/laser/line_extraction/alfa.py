"""ALFA's line ends: binary search on the RMSE (eq. 21) with a floating threshold.

Line chapter (Mavaei 2011), ALFA pseudo code, on the lowess-smoothed points
(:mod:`landmark_nav.laser.lowess`); see :func:`alfa_pieces`.
"""

import math
from typing import List, Tuple

from landmark_nav.laser.line_extraction.params import LineParams
import numpy as np


def alfa_pieces(xy: np.ndarray, offsets: np.ndarray, params: LineParams) -> np.ndarray:
    """Find line pieces by ALFA's split and merge with binary search (line chapter).

    ``xy`` are the smoothed points. Per run, from ``K_Min`` (its first point) the end
    ``a`` of the line is searched over ``[K_Min + min_points - 1, K_Max]``, starting in
    the middle of the remaining data. The fit of ``K_Min..a`` is judged by its RMSE
    (eq. 21, perpendicular residuals) and by the RMSE gradient, estimated as the RMSE
    growth per added point relative to the current threshold::

        g(a) = (RMSE(a) - RMSE(a - h)) / (h * Max_ERR),  h = max(2, min_points // 2)

    As in the pseudo code: a bad fit (``RMSE > Max_ERR`` or ``g > max_gradient``) moves
    the upper bound below ``a``; when the gradient was the reason, the threshold drops to
    the current RMSE (``Max_ERR = min(RMSE, Max_ERR)``). A good fit moves the lower bound
    to ``a`` and sets ``Max_ERR = mean(RMSE, Max_ERR)``. ``Max_ERR`` starts at ``rmse_max``
    for every line and stays within ``[rmse_min, rmse_max]`` (the floating threshold).
    The next candidate is ``ceil((b1 + b2) / 2)``, so the search always makes progress
    (the pseudo code's ``floor`` after a bad fit can test ``b1`` again). The largest
    accepted ``a`` ends the line; the next search starts at ``a + 1`` (the pseudo code's
    ``K_Min = a + 1``). If even the shortest line ``K_Min..K_Min + min_points - 1`` has
    an RMSE above ``rmse_max``, ``K_Min`` alone is dropped and the search restarts one
    point later (the pseudo code leaves this case open).

    Args:
        xy: (N, 2) smoothed points, runs back to back.
        offsets: (C + 1,) run boundaries.
        params: Line parameters (min_points, rmse bounds, max_gradient).

    Returns:
        (P, 2) int array of inclusive ``[first, last]`` indices, non-overlapping, in order.

    """
    least = params.min_points
    step = max(2, least // 2)
    lo_thr, hi_thr = params.rmse_bounds
    gmax = params.max_gradient
    out: List[Tuple[int, int]] = []
    xy = np.asarray(xy, dtype=float)
    bounds = np.asarray(offsets).tolist()
    sizes = [b - a for a, b in zip(bounds[:-1], bounds[1:])]
    # Each run's points relative to its mean (np.mean's sum and division), and their
    # monomials x, y, x^2, y^2, xy, all runs in one pass; the prefix sums of a run as in
    # _prefix5, as Python floats for the search.
    means = np.zeros((len(sizes), 2))
    for c, (c0, n_pts) in enumerate(zip(bounds, sizes)):
        if n_pts >= least:
            means[c] = np.add.reduce(xy[c0:c0 + n_pts], axis=0) / n_pts
    mono = np.empty((5, xy.shape[0]))
    np.subtract(xy, means.repeat(sizes, axis=0), out=mono[:2].T)
    np.multiply(mono[0], mono[0], out=mono[2])
    np.multiply(mono[1], mono[1], out=mono[3])
    np.multiply(mono[0], mono[1], out=mono[4])
    for c0, n_pts in zip(bounds, sizes):
        if n_pts < least:
            continue
        pre = np.zeros((5, n_pts + 1))
        np.cumsum(mono[:, c0:c0 + n_pts], axis=1, out=pre[:, 1:])
        sx, sy, sxx, syy, sxy = pre.tolist()

        def rmse(i: int, j: int) -> float:
            """Return the RMSE (eq. 21) of the TLS line through points i..j."""
            k = j + 1
            m = k - i
            mx = (sx[k] - sx[i]) / m
            my = (sy[k] - sy[i]) / m
            vxx = (sxx[k] - sxx[i]) / m - mx * mx
            vyy = (syy[k] - syy[i]) / m - my * my
            vxy = (sxy[k] - sxy[i]) / m - mx * my
            half = 0.5 * (vxx - vyy)
            lam = 0.5 * (vxx + vyy) - math.sqrt(half * half + vxy * vxy)
            return math.sqrt(lam) if lam > 0.0 else 0.0

        k_min, k_max = 0, n_pts - 1
        while k_max - k_min + 1 >= least:
            lo = k_min + least - 1
            if rmse(k_min, lo) > hi_thr:
                k_min += 1  # no line starts here
                continue
            max_err = hi_thr
            b1, b2 = lo, k_max
            a = max((k_min + k_max + 1) // 2, b1 + 1)  # the middle of the data
            while b2 > b1:
                err = rmse(k_min, a)
                if err > max_err:  # bad fit: split the recent data
                    b2 = a - 1  # (the gradient would not change Max_ERR: not computed)
                else:
                    grad = (err - rmse(k_min, max(a - step, k_min + 1))) / (step * max_err)
                    if grad > gmax:  # bad fit by the gradient: split, lower the threshold
                        b2 = a - 1
                        max_err = max(min(err, max_err), lo_thr)
                    else:  # satisfied: add a split of the remainder
                        b1 = a
                        max_err = min(max(0.5 * (err + max_err), lo_thr), hi_thr)
                a = (b1 + b2 + 1) // 2
            out.append((c0 + k_min, c0 + b1))
            k_min = b1 + 1
    if not out:
        return np.zeros((0, 2), dtype=np.int64)
    return np.array(out, dtype=np.int64)
