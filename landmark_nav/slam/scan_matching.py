"""Point-to-line ICP of two laser scans, and the scan-matched motion of the SLAM front end.

Used by the SLAM front end (``FrontendParams.scan_matching``: each odometry increment
replaced by the scan's motion against the previous scan when the two agree,
:func:`scan_motion`, or fused with it, :func:`fused_scan_motion`) and by the benchmarks:
the reference poses' error between consecutive scans
(``benchmarks/line_repeatability_carmen.py`` of commit 67eb6cc) and how far dead reckoning
by scan matching of consecutive scans gets on a real log (``benchmarks/bench_slam_real.py
scan-matching``).

Method (Censi's point-to-line metric, solved by Gauss-Newton on the linearised rotation;
Censi, "An ICP variant using a point-to-line metric", ICRA 2008): each source point, moved
by the current pose, is paired with its nearest target point within a gate, and the
residual is its distance along the target point's normal (the smallest-eigenvalue
direction of the scatter of its ``neighbours`` nearest target points). The pose minimises
the sum of squared residuals; the gate may shrink over stages (coarse to fine).
"""

from dataclasses import dataclass
import math
from typing import Callable, Dict, List, Optional, Sequence, TYPE_CHECKING

from landmark_nav.geometry import compose, compose_jacobians, inverse, wrap_angle
import numpy as np

if TYPE_CHECKING:  # scipy.spatial is imported where a tree is built, not at every node start
    from scipy.spatial import cKDTree

#: Pairing distance per ICP stage of :func:`scan_motion` [m] (coarse to fine).
SCAN_MOTION_GATES = (0.5, 0.3, 0.15)
#: Gauss-Newton steps per stage of :func:`scan_motion`.
SCAN_MOTION_ITERATIONS = 10


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
        hessian: (3, 3) ``J^T J`` of the last iteration (its shape: which directions the
            pairs constrain).
    """

    pose: np.ndarray
    covariance: np.ndarray
    matches: int
    rms: float
    hessian: np.ndarray


@dataclass(frozen=True, eq=False)
class IcpTarget:
    """A target scan prepared for :func:`point_to_line_icp`: its k-d tree and normals.

    Built once per target and shared by every ICP start on it (:func:`icp_target`).
    """

    points: np.ndarray
    tree: 'cKDTree'
    normals: np.ndarray


def icp_target(target: np.ndarray, neighbours: int = 5) -> IcpTarget:
    """Return ``target`` (M, 2) prepared: its k-d tree and each point's normal.

    The normal of a point is the smallest-eigenvalue direction of the scatter of its
    ``neighbours`` nearest target points (Censi's point-to-line metric).
    """
    from scipy.spatial import cKDTree  # on first use: scipy.spatial costs ~0.5 CPU-s to import
    q = np.asarray(target, dtype=float).reshape(-1, 2)
    tree = cKDTree(q)
    if len(q) < neighbours:
        return IcpTarget(q, tree, np.zeros((0, 2)))
    _, nb = tree.query(q, k=neighbours)
    nbh = q[nb] - q[nb].mean(axis=1, keepdims=True)
    return IcpTarget(q, tree, np.linalg.eigh(np.einsum('kni,knj->kij', nbh, nbh))[1][:, :, 0])


def point_to_line_icp(source: np.ndarray, target: np.ndarray,
                      guess: Sequence[float] = (0.0, 0.0, 0.0),
                      gates: Sequence[float] = (0.15,), iterations: int = 15,
                      min_matches: int = 20, neighbours: int = 5,
                      tolerance: float = 1e-5) -> Optional[IcpResult]:
    """Return the pose that moves ``source`` onto ``target`` by point-to-line ICP.

    Args:
        source: (N, 2) points [m].
        target: (M, 2) points [m], or an :class:`IcpTarget` (built with ``neighbours``).
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
    return point_to_line_icp_starts(source, target, [guess], gates, iterations, min_matches,
                                    neighbours, tolerance)[0]


def point_to_line_icp_starts(source: np.ndarray, target, guesses: Sequence[Sequence[float]],
                             gates: Sequence[float] = (0.15,), iterations: int = 15,
                             min_matches: int = 20, neighbours: int = 5,
                             tolerance: float = 1e-5) -> List[Optional[IcpResult]]:
    """Return :func:`point_to_line_icp` from each of ``guesses``, run in lockstep.

    Every start takes exactly the steps it takes alone (same pairs, same Gauss-Newton steps,
    same result to the last bit); the starts share one k-d tree query per iteration (the
    moved source points of all active starts at once, searched within the stage's gate:
    a pair farther than it is not used) and one target preparation.
    """
    if len(gates) == 0:
        raise ValueError('point_to_line_icp: gates must hold at least one distance')
    p = np.asarray(source, dtype=float).reshape(-1, 2)
    prepared = target if isinstance(target, IcpTarget) else None
    q = prepared.points if prepared is not None else np.asarray(target, dtype=float).reshape(-1, 2)
    if len(p) < min_matches or len(q) < max(min_matches, neighbours):
        return [None] * len(guesses)
    prepared = prepared or icp_target(q, neighbours)
    tree, normals = prepared.tree, prepared.normals
    ts = [np.array(g, dtype=float) for g in guesses]
    failed = [False] * len(ts)
    last = [None] * len(ts)  # (r, jac) of each start's last iteration
    n_p = len(p)
    for gate in gates:
        active = [k for k in range(len(ts)) if not failed[k]]
        for _ in range(iterations):
            if not active:
                break
            moved = []
            for k in active:
                t = ts[k]
                c, s = math.cos(t[2]), math.sin(t[2])
                moved.append(p @ np.array([[c, s], [-s, c]]) + t[:2])
            dist_all, j_all = tree.query(np.concatenate(moved), distance_upper_bound=gate)
            still = []
            for i, k in enumerate(active):
                pt = moved[i]
                dist, j = dist_all[i * n_p:(i + 1) * n_p], j_all[i * n_p:(i + 1) * n_p]
                m = dist < gate
                if m.sum() < min_matches:
                    failed[k] = True
                    continue
                n = normals[j[m]]
                r = np.einsum('ij,ij->i', pt[m] - q[j[m]], n)
                jac = np.column_stack([n, -pt[m, 1] * n[:, 0] + pt[m, 0] * n[:, 1]])
                step = np.linalg.lstsq(jac, -r, rcond=None)[0]
                ts[k] += step
                last[k] = (r, jac)
                if np.abs(step).max() >= tolerance:
                    still.append(k)
            active = still
    return [None if failed[k] else _icp_result(ts[k], *last[k]) for k in range(len(ts))]


def _icp_result(t: np.ndarray, r: np.ndarray, jac: np.ndarray) -> IcpResult:
    """Return the :class:`IcpResult` of a converged start (its last iteration's pairs)."""
    s2 = float(np.mean(r ** 2))
    hessian = jac.T @ jac
    try:
        cov = s2 * np.linalg.inv(hessian)
    except np.linalg.LinAlgError:
        cov = np.full((3, 3), np.inf)
    return IcpResult(t, cov, int(r.size), math.sqrt(s2), hessian)


def scan_points(ranges: np.ndarray, angle_min: float, angle_increment: float,
                range_min: float, range_max: float) -> np.ndarray:
    """Return a scan's valid returns below ``range_max`` as (N, 2) laser-frame points.

    Args:
        ranges: (B,) ranges [m] (REP 117: +-inf and NaN are not returns).
        angle_min: Angle of beam 0 [rad].
        angle_increment: Beam spacing [rad].
        range_min: Ranges at or below this are not used [m].
        range_max: Ranges at or beyond this are not used [m].
    """
    r = np.asarray(ranges, dtype=float).reshape(-1)
    a = angle_min + angle_increment * np.arange(r.size)
    m = np.isfinite(r) & (r > range_min) & (r < range_max)
    return np.column_stack([r[m] * np.cos(a[m]), r[m] * np.sin(a[m])])


def base_motion(previous, current: np.ndarray, u: Sequence[float],
                mount: Sequence[float]) -> Optional[tuple]:
    """Return the base's motion between two scans by ICP, and the laser-frame ICP result.

    The current scan's points are matched onto the previous scan's
    (:func:`point_to_line_icp`, gates :data:`SCAN_MOTION_GATES`), the odometry increment
    moved into the laser frame (``M^-1 u M``, ``M`` the mount) as the initial guess; the
    result is moved back to the base (``M v M^-1``).

    Args:
        previous: (N, 2) the previous scan's points (laser frame) [m], or them prepared
            (:func:`icp_target`).
        current: (M, 2) this scan's points [m].
        u: (3,) the odometry increment between the two scans (base frame).
        mount: (3,) laser pose in base_link.

    Returns:
        ``(v, fit)``: (3,) the base's motion and the :class:`IcpResult`; None when the ICP
        found no solution.
    """
    return base_motions(previous, current, [u], mount)[0]


def base_motions(previous, current: np.ndarray, guesses: Sequence[Sequence[float]],
                 mount: Sequence[float]) -> List[Optional[tuple]]:
    """Return :func:`base_motion` from each odometry guess (ICP starts in lockstep)."""
    mount = np.asarray(mount, dtype=float)
    unmount = inverse(mount)
    fits = point_to_line_icp_starts(
        current, previous, [compose(compose(unmount, np.asarray(u, dtype=float)), mount)
                            for u in guesses],
        gates=SCAN_MOTION_GATES, iterations=SCAN_MOTION_ITERATIONS)
    return [None if fit is None or not np.all(np.isfinite(fit.pose)) else
            (compose(compose(mount, fit.pose), unmount), fit) for fit in fits]


def larger_motion(u: Sequence[float], v: Sequence[float]) -> np.ndarray:
    """Return ``[max(|u_xy|, |v_xy|), 0, max(|u_psi|, |v_psi|)]``: the larger of two motions.

    The point at which :func:`scan_motion` evaluates distance- and turn-driven noise models
    (:func:`landmark_nav.slam.ekf_slam.odometry_noise`, which read only the distance and
    the turn's size) when it tests two estimates of one motion.
    """
    return np.array([max(math.hypot(u[0], u[1]), math.hypot(v[0], v[1])), 0.0,
                     max(abs(float(u[2])), abs(float(v[2])))])


def scan_motion(previous: np.ndarray, current: np.ndarray, u: Sequence[float],
                u_cov, mount: Sequence[float], gate: float,
                v_cov: Optional[Callable[[np.ndarray], np.ndarray]] = None,
                restarts: Optional[Dict[str, int]] = None,
                side_starts: float = 0.0) -> Optional[np.ndarray]:
    """Return the base's motion between two scans by ICP, or None when it is not usable.

    The motion ``v`` of :func:`base_motion` is used only when it agrees with the odometry:
    its difference ``d`` from ``u``, two estimates of the same motion, must satisfy
    ``d^T (U + V)^-1 d <= gate`` (a chi-square bound on 3 degrees of freedom; ``V`` the
    scan-matched motion's own covariance), which rejects ICP solutions that slid along a
    corridor or locked onto the wrong structure.

    Under that hypothesis both covariances are those of the one true motion, which neither
    estimate knows. When ``u_cov`` is a noise model (a function of the motion), ``U`` and
    ``V`` are both evaluated at :func:`larger_motion` of ``u`` and ``v``: each model at its
    own estimate would let the odometry's error shrink its own region (an odometry turn of
    15 deg for a true 30 deg halves the turn-driven variance, and the scans' correct motion
    is then rejected exactly when the odometry is worst) and give an ICP motion that
    found no translation a region of zero size in translation. With an array ``U``
    (a given covariance), ``V`` is evaluated at ``v``.

    ICP converges only from a guess near the motion; the odometry's heading, off by several
    degrees after a turn, moves points metres away and ICP finds too few pairs or the wrong
    structure. So when the first solution fails or is rejected, ICP is restarted from the
    odometry increment turned by ``j s`` (``s`` the heading std of ``U`` at ``u``, ``j =
    +-1 .. +-ceil(sqrt(gate))``: the odometry's headings at the test's confidence; each
    restart costs one more ICP, up to ``2 ceil(sqrt(gate))`` on a step), and the solution
    with the most pairs is tested (a coarse form of the search over the prior's window of
    correlative scan matching; Olson, ICRA 2009).

    Args:
        previous: (N, 2) the previous scan's points (laser frame) [m].
        current: (M, 2) this scan's points [m].
        u: (3,) the odometry increment between the two scans (base frame).
        u_cov: (3, 3) its covariance ``U``, or ``U`` as a function of a motion (the noise
            model; see above).
        mount: (3,) laser pose in base_link.
        gate: The chi-square bound.
        v_cov: ``V`` as a function of the scan-matched motion (None: zero, the odometry's
            region alone).
        restarts: Optional counts to increment: ``restarted`` (the first solution failed or
            was rejected) and ``recovered`` (a restart gave a usable motion).
        side_starts: k > 0: on every step ICP also starts from the odometry's heading
            ``+- k s`` and the first solution is the one with the most pairs of the three:
            an odometry guess in its own tail leads ICP into a nearby wrong minimum that
            may pass the test (three ICPs a step instead of one); 0: off.

    Returns:
        (3,) the base's motion, or None (ICP failed or disagrees with the odometry).
    """
    u = np.asarray(u, dtype=float)
    found = _search(previous, current, u, u_cov, mount, gate,
                    lambda f: _agrees(u, f[0], u_cov, v_cov, gate), restarts, side_starts)
    return None if found is None else found[0]


def _agrees(u: np.ndarray, v: np.ndarray, u_cov, v_cov, gate: float) -> bool:
    """Return whether ``v`` and ``u`` pass :func:`scan_motion`'s test."""
    d = v - u
    d[2] = wrap_angle(d[2])
    if callable(u_cov):
        at = larger_motion(u, v)
        cov = np.asarray(u_cov(at), dtype=float) + (0.0 if v_cov is None else v_cov(at))
    else:
        cov = np.asarray(u_cov, dtype=float) + (0.0 if v_cov is None else v_cov(v))
    try:
        return float(d @ np.linalg.solve(cov, d)) <= gate
    except np.linalg.LinAlgError:
        return False


def _search(previous: np.ndarray, current: np.ndarray, u: np.ndarray, u_cov,
            mount: Sequence[float], gate: float, agreed: Callable[[tuple], bool],
            restarts: Optional[Dict[str, int]], side_starts: float = 0.0) -> Optional[tuple]:
    """Return the :func:`base_motion` result that ``agreed`` accepts, restarting (above)."""
    restarts = {} if restarts is None else restarts
    previous = icp_target(previous)  # one k-d tree and normals for every start
    u_at_u = np.asarray(u_cov(u) if callable(u_cov) else u_cov, dtype=float)
    s = math.sqrt(max(float(u_at_u[2, 2]), 0.0))
    if side_starts > 0.0 and s > 0.0 and math.isfinite(s):
        # Two more starts beyond the basin of the odometry's guess: a guess in its tail
        # leads ICP into a nearby wrong minimum that may pass the test.
        found = _most_pairs(previous, current, u, mount, (side_starts * s,), None, True)
    else:
        found = base_motion(previous, current, u, mount)
    if found is not None and agreed(found):
        return found
    if not (s > 0.0 and math.isfinite(s)):
        return None
    restarts['restarted'] = restarts.get('restarted', 0) + 1
    best = _most_pairs(previous, current, u, mount,
                       [j * s for j in range(1, math.ceil(math.sqrt(gate)) + 1)], found)
    if best is None or not agreed(best):
        return None
    restarts['recovered'] = restarts.get('recovered', 0) + 1
    return best


def _most_pairs(previous, current: np.ndarray, u: np.ndarray,
                mount: Sequence[float], turns: Sequence[float],
                best: Optional[tuple], from_u: bool = False) -> Optional[tuple]:
    """Return the :func:`base_motion` result with the most pairs.

    The candidates: ``best`` (or, with ``from_u``, ICP from ``u``), then ICP from ``u``
    turned by ``+t`` and ``-t`` for each ``t`` of ``turns`` in order; a tie keeps the
    earlier. All starts run in lockstep (:func:`base_motions`).
    """
    guesses = [u] if from_u else []
    for t in turns:
        for sign in (1.0, -1.0):
            guess = u.copy()
            guess[2] += sign * t
            guesses.append(guess)
    for other in base_motions(previous, current, guesses, mount):
        if other is not None and (best is None or other[1].matches > best[1].matches):
            best = other
    return best


def fit_information(fit: IcpResult, mount: Sequence[float], pairs: float) -> np.ndarray:
    """Return the information (inverse covariance) of the base's motion from an ICP fit.

    In the laser frame ``pairs / (N s^2) J^T J`` (``N`` pairs, ``s`` their RMS residual,
    ``J^T J`` the fit's normal matrix), i.e. the covariance ``s^2 (J^T J / N)^-1 / pairs``:
    the fit's shape (which directions its pairs constrain: none along a corridor) with the
    size of ``pairs`` independent residuals instead of ``N``. The classic ``s^2 (J^T J)^-1``
    (:attr:`IcpResult.covariance`) shrinks as ``1/N``; on the Carmen logs the ICP's per-step
    error against the reference does not (its normalised squared error grows with ``N``,
    median ``NIS / N`` 0.5-1.1 on six logs): the error is common to the scan (sampling,
    skew, the reference's own), not independent per return. Moved to the base frame through
    ``v = M p M^-1`` (``M`` the mount): ``Lambda_v = D^-T Lambda_p D^-1``, ``D = dv/dp``.

    Args:
        fit: The ICP solution (laser frame).
        mount: (3,) laser pose in base_link.
        pairs: The independent residuals the fit is worth (> 0).

    Returns:
        (3, 3) information of the base's motion (singular where the scans fix nothing).

    Raises:
        ValueError: ``pairs`` not > 0.
    """
    if not pairs > 0.0:
        raise ValueError(f'fit_information: pairs must be > 0, got {pairs!r}')
    mount = np.asarray(mount, dtype=float)
    # s floored at 1 um: noise-free simulated scans give a (near) exact fit.
    info_p = pairs / (fit.matches * max(fit.rms, 1e-6) ** 2) * fit.hessian
    # D = dv/dp through v = (M (+) p) (+) M^-1, the chain of the compound Jacobians.
    outer, _ = compose_jacobians(compose(mount, fit.pose), inverse(mount))
    _, inner = compose_jacobians(mount, fit.pose)
    dinv = np.linalg.inv(outer @ inner)
    return dinv.T @ info_p @ dinv


def fused_scan_motion(previous: np.ndarray, current: np.ndarray, u: Sequence[float],
                      u_cov, mount: Sequence[float], gate: float,
                      v_cov: Callable[[np.ndarray], np.ndarray], pairs: float,
                      restarts: Optional[Dict[str, int]] = None,
                      side_starts: float = 0.0) -> Optional[tuple]:
    """Return ``(m, W)``: the odometry and the scan-matched motion fused, or None.

    The scan-matched motion ``v`` is found and tested as in :func:`scan_motion` (the test
    with ``v_cov``, the scan-matched motion's noise model, and the same restarts). When it
    passes, the two independent estimates of the motion are fused by their information
    (``U`` at :func:`larger_motion`, ``V^-1`` from the fit, :func:`fit_information`)::

        W = (U^-1 + V^-1)^-1,   m = u + W V^-1 (v - u)

    so that along a corridor, where the scans fix nothing, the motion and its variance are
    the odometry's, and across it and in heading they are the scans'.

    Args:
        previous: (N, 2) the previous scan's points (laser frame) [m].
        current: (M, 2) this scan's points [m].
        u: (3,) the odometry increment between the two scans (base frame).
        u_cov: (3, 3) its covariance ``U``, or ``U`` as a function of a motion.
        mount: (3,) laser pose in base_link.
        gate: The chi-square bound of the test.
        v_cov: ``V`` of the test as a function of a motion.
        pairs: The independent residuals the fit is worth (:func:`fit_information`).
        restarts: Optional counts, as in :func:`scan_motion`.
        side_starts: As in :func:`scan_motion`.

    Returns:
        ``(m, W)``: (3,) the fused motion and (3, 3) its covariance; None when ICP failed or
        disagrees with the odometry.
    """
    if not pairs > 0.0:
        raise ValueError(f'fused_scan_motion: pairs must be > 0, got {pairs!r}')
    u = np.asarray(u, dtype=float)
    found = _search(previous, current, u, u_cov, mount, gate,
                    lambda f: _agrees(u, f[0], u_cov, v_cov, gate), restarts, side_starts)
    if found is None:
        return None
    v, fit = found
    uc = np.asarray(u_cov(larger_motion(u, v)) if callable(u_cov) else u_cov, dtype=float)
    lam = fit_information(fit, mount, pairs)
    try:
        w = np.linalg.inv(np.linalg.inv(uc) + lam)
    except np.linalg.LinAlgError:
        return None
    d = v - u
    d[2] = wrap_angle(d[2])
    m = u + w @ lam @ d
    m[2] = wrap_angle(m[2])
    return m, w
