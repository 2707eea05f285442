"""Point-to-line ICP of two laser scans (an evaluation tool, not a filter input).

Used by the benchmarks to refine the relative pose of two scans: the reference poses'
error between consecutive scans (``benchmarks/line_repeatability_carmen.py``) and how far
dead reckoning by scan matching of consecutive scans gets on a real log
(``benchmarks/scan_matching_carmen.py``).

Method (Censi's point-to-line metric, solved by Gauss-Newton on the linearised rotation;
Censi, "An ICP variant using a point-to-line metric", ICRA 2008): each source point, moved
by the current pose, is paired with its nearest target point within a gate, and the
residual is its distance along the target point's normal (the smallest-eigenvalue
direction of the scatter of its ``neighbours`` nearest target points). The pose minimises
the sum of squared residuals; the gate may shrink over stages (coarse to fine).
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence

import numpy as np
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class IcpResult:
    """One ICP solution.

    Attributes:
        pose: (3,) ``[x, y, yaw]`` moving source points into the target frame
            (``R(yaw) p + [x, y]``).
        covariance: (3, 3) ``s^2 (J^T J)^-1``, ``s^2`` the mean squared residual of the last
            iteration: the classic estimate, which treats the residuals as independent (it
            is optimistic on real scans; the benchmarks report its NIS).
        matches: Number of pairs in the last iteration.
        rms: RMS residual of the last iteration [m].
    """

    pose: np.ndarray
    covariance: np.ndarray
    matches: int
    rms: float


def point_to_line_icp(source: np.ndarray, target: np.ndarray,
                      guess: Sequence[float] = (0.0, 0.0, 0.0),
                      gates: Sequence[float] = (0.15,), iterations: int = 15,
                      min_matches: int = 20, neighbours: int = 5,
                      tolerance: float = 1e-5) -> Optional[IcpResult]:
    """Return the pose that moves ``source`` onto ``target`` by point-to-line ICP.

    Args:
        source: (N, 2) points [m].
        target: (M, 2) points [m].
        guess: Initial pose ``[x, y, yaw]``.
        gates: Pairing distances [m], one stage each, in order.
        iterations: Most Gauss-Newton steps per stage.
        min_matches: Fewest pairs; fewer in any iteration: no solution.
        neighbours: Target points per normal.
        tolerance: A stage ends when no component of the step exceeds it.

    Returns:
        The solution, or None (too few points or pairs).

    Raises:
        ValueError: No gate.
    """
    if len(gates) == 0:
        raise ValueError('point_to_line_icp: gates must hold at least one distance')
    p = np.asarray(source, dtype=float).reshape(-1, 2)
    q = np.asarray(target, dtype=float).reshape(-1, 2)
    if len(p) < min_matches or len(q) < max(min_matches, neighbours):
        return None
    tree = cKDTree(q)
    _, nb = tree.query(q, k=neighbours)
    nbh = q[nb] - q[nb].mean(axis=1, keepdims=True)
    normals = np.linalg.eigh(np.einsum('kni,knj->kij', nbh, nbh))[1][:, :, 0]
    t = np.array(guess, dtype=float)
    for gate in gates:
        for _ in range(iterations):
            c, s = math.cos(t[2]), math.sin(t[2])
            pt = p @ np.array([[c, s], [-s, c]]) + t[:2]
            dist, j = tree.query(pt)
            m = dist < gate
            if m.sum() < min_matches:
                return None
            n = normals[j[m]]
            r = np.einsum('ij,ij->i', pt[m] - q[j[m]], n)
            jac = np.column_stack([n, -pt[m, 1] * n[:, 0] + pt[m, 0] * n[:, 1]])
            step = np.linalg.lstsq(jac, -r, rcond=None)[0]
            t += step
            if np.abs(step).max() < tolerance:
                break
    s2 = float(np.mean(r ** 2))
    try:
        cov = s2 * np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        cov = np.full((3, 3), np.inf)
    return IcpResult(t, cov, int(r.size), math.sqrt(s2))
