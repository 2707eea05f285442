"""Odometry calibration: fit the factors k1, k2, k3 of eqs. 17-18 to measured end poses.

Source: Ivanjko, Kitanov, Petrovic (2010), section 2.1 (kinematics, eqs. 1-9) and 3.1
(calibration experiments, eqs. 17-19, Algorithm 1). SI units and radians throughout.

Model. A run is a sequence of measured wheel speeds ``(omega_L, omega_R)`` with their
sampling times T (from the stamps), started at an exactly measured pose. With factors
``k = (k1, k2, k3)`` the estimated final pose is (eqs. 1-7 with 17-18, random errors at
their zero mean)::

    v_t = (k1 omega_L R + k2 omega_R R) / 2              # eq. 17
    omega = (k2 omega_R R - k1 omega_L R) / (k3 b)       # eq. 18
    D = v_t T, dTheta = omega T                          # eqs. 4-5
    X(k+1) = X(k) + [D cos(Theta + dTheta/2), D sin(Theta + dTheta/2), dTheta]   # eqs. 1-3

(``control_from_wheels`` of :mod:`.odometry` gives ``D, dTheta``). ``k = (1, 1, 1)`` is the
nominal model (eqs. 6-7).

Criterion (eq. 19 and section 3.1.2). The chapter defines the criterion as the error between
the final pose estimated with the calibrated model and the exactly measured final pose, and
names the best one for the three-parameter model: the final orientation difference
``I = Theta_est - Theta_exact`` (eq. 19). We use eq. 19 literally for the turn-in-place runs
(the k3 m-function). For the straight runs (the k1, k2 m-function) the orientation alone
cannot work: it depends on k only through ``(k2 omega_R - k1 omega_L) / k3`` and fixes just
``k2 - k1`` (relative to k3 b), not ``k1 + k2``; the travelled distance does. So the
straight-run criterion is the full final pose error ``[dx, dy, dTheta]`` as the chapter's
general definition says. Weights: every run's error is whitened by the covariance of its
final pose predicted from the wheel-speed noise (eqs. 8-9 with std ``gain |omega| + floor``,
linearised about the starting k) plus the pose measurement noise, see :class:`CriterionNoise`;
a turn contributes ``dTheta / sigma_Theta``, a straight run ``L^-1 [dx, dy, dTheta]`` with
``L L^T`` its 3 x 3 covariance. The whitening makes metres and radians commensurable and
weighs long and short runs by what they can tell; its overall scale does not matter.

Algorithm 1 (``method='chapter'``, the default). The calibration runs are split into data
sets (one straight run and one turn each, in recording order, see :func:`split_data_sets`).
Per data set, starting from ``k = (1, 1, 1)``, ``iterations`` times (the chapter found two
enough): k1, k2 minimise the straight-run criterion with k3 fixed; then k3 minimises eq. 19
over the turns of each direction separately with k1, k2 fixed and the directions' values are
averaged. The final factors are the average over the data sets (section 3.1.1).
``method='joint'`` instead fits all three factors to all runs at once (weighted least
squares of the same residuals); it is the statistically efficient variant and gives the
same values up to noise. The chapter's procedure is the default because it is the
documented method and its per-set spread shows how repeatable the calibration is.

Identifiability. From end poses alone the factors are determined only relative to the
nominal R and b (a wheel radius error and k1, k2 are the same thing). The straight runs'
length gives ``(k1 + k2) / 2``, their final heading ``(k2 - k1) / k3`` (times L / b); the
turns' heading gives ``(k1 + k2) / k3``. Headings alone are invariant to ``k -> c k`` (eqs.
18 and 5 are homogeneous of degree 0 in k), so without the straight-run position the
problem has a one-dimensional null space; with straight runs and turns the whitened
Jacobian has full rank (see :func:`identifiability`). Turns in place carry no usable
information on ``k1 + k2`` and straight runs none on k3 separately, which is what the
alternation of Algorithm 1 exploits.
"""

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .odometry import control_from_wheels
from ..geometry import wrap_angle

NS_PER_S = 1_000_000_000
RUN_KINDS = ('straight', 'turn_ccw', 'turn_cw')
TURN_KINDS = ('turn_ccw', 'turn_cw')
NOMINAL_K = (1.0, 1.0, 1.0)
METHODS = ('chapter', 'joint')
#: Tolerances of scipy.optimize.least_squares (far below any physical resolution).
_TOL = {'xtol': 1e-13, 'ftol': 1e-13, 'gtol': 1e-13}


@dataclass(frozen=True, eq=False)
class CalibrationRun:
    """One calibration experiment: measured wheel speeds and the exact start and end pose.

    Attributes:
        kind: ``'straight'``, ``'turn_ccw'`` or ``'turn_cw'``.
        wheel_speeds: (n, 2) measured ``(omega_L, omega_R)`` [rad/s], sample i held over
            ``sample_times[i]``.
        sample_times: (n,) sampling times T [s] (from the stamps).
        start_pose: (3,) exact start pose ``[x, y, Theta]``.
        end_pose: (3,) exact final pose.
        group: ``'calibration'`` or ``'validation'``.
        index: position of the run in its recording (orders the data sets).
    """

    kind: str
    wheel_speeds: np.ndarray
    sample_times: np.ndarray
    start_pose: np.ndarray
    end_pose: np.ndarray
    group: str = 'calibration'
    index: int = 0

    def __post_init__(self) -> None:
        """Validate and freeze the arrays.

        Raises:
            ValueError: Unknown kind, bad shapes, non-finite values or T <= 0.
        """
        if self.kind not in RUN_KINDS:
            raise ValueError(f'unknown run kind {self.kind!r}; valid: {list(RUN_KINDS)}')
        w = np.array(self.wheel_speeds, dtype=float)
        t = np.array(self.sample_times, dtype=float).reshape(-1)
        if w.ndim != 2 or w.shape[1] != 2 or w.shape[0] == 0:
            raise ValueError(f'run {self.index}: wheel_speeds must be (n>0, 2), got {w.shape}')
        if t.shape[0] != w.shape[0]:
            raise ValueError(f'run {self.index}: {t.shape[0]} sample times for '
                             f'{w.shape[0]} wheel speed samples')
        p0 = np.array(self.start_pose, dtype=float).reshape(-1)
        p1 = np.array(self.end_pose, dtype=float).reshape(-1)
        if p0.shape != (3,) or p1.shape != (3,):
            raise ValueError(f'run {self.index}: start and end pose must have 3 elements')
        if not all(np.all(np.isfinite(a)) for a in (w, t, p0, p1)):
            raise ValueError(f'run {self.index}: non-finite wheel speeds, times or poses')
        if np.any(t <= 0.0):
            raise ValueError(f'run {self.index}: sampling times must be > 0')
        for name, arr in (('wheel_speeds', w), ('sample_times', t), ('start_pose', p0),
                          ('end_pose', p1)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def is_turn(self) -> bool:
        """True for a turn in place (either direction)."""
        return self.kind in TURN_KINDS

    @property
    def duration(self) -> float:
        """Duration of the run [s]."""
        return float(np.sum(self.sample_times))


def make_run(kind: str, stamps_ns: Any, wheel_speeds: Any, start_ns: int, end_ns: int,
             start_pose: Any, end_pose: Any, group: str = 'calibration',
             index: int = 0) -> CalibrationRun:
    """Cut one run out of a wheel-speed stream (Algorithm 1, lines 1-3).

    Sample i holds the speed of the period that ENDS at ``stamps_ns[i]`` (as the odometry
    and ``/joint_states`` report it); the run uses the samples with
    ``start_ns < stamp <= end_ns`` and ``T_i = stamp_i - stamp_(i-1)`` (``start_ns`` for the
    first).

    Args:
        kind: run kind, see :class:`CalibrationRun`.
        stamps_ns: (N,) int stamps of the whole stream, increasing.
        wheel_speeds: (N, 2) measured ``(omega_L, omega_R)`` [rad/s].
        start_ns: stamp of the exact start pose.
        end_ns: stamp of the exact end pose.
        start_pose: (3,) exact start pose.
        end_pose: (3,) exact end pose.
        group: ``'calibration'`` or ``'validation'``.
        index: position of the run in the recording.

    Returns:
        The run.

    Raises:
        ValueError: No samples inside the run, or inconsistent input.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    w = np.asarray(wheel_speeds, dtype=float).reshape(-1, 2)
    if stamps.shape[0] != w.shape[0]:
        raise ValueError(f'{stamps.shape[0]} stamps for {w.shape[0]} wheel speed samples')
    if int(end_ns) <= int(start_ns):
        raise ValueError(f'run {index}: end_ns {end_ns} is not after start_ns {start_ns}')
    sel = (stamps > int(start_ns)) & (stamps <= int(end_ns))
    if not np.any(sel):
        raise ValueError(f'run {index} ({kind}): no wheel speed samples in '
                         f'({start_ns}, {end_ns}]')
    st = stamps[sel]
    t = np.diff(np.concatenate([[int(start_ns)], st])) / NS_PER_S
    return CalibrationRun(kind=kind, wheel_speeds=w[sel], sample_times=t,
                          start_pose=start_pose, end_pose=end_pose, group=group,
                          index=int(index))


@dataclass(frozen=True)
class CriterionNoise:
    """Noise model that weights the criterion (not a property of the estimate itself).

    The measured wheel speed of each wheel has std ``gain |omega| + floor`` (the random
    errors of eqs. 8-9); the exact poses have std ``pose_sigma_xy`` / ``pose_sigma_theta``.
    Only the ratios matter. Defaults: the simulator's encoder noise and 0.1 mm / 0.1 mrad.

    Attributes:
        gain: relative wheel speed std [-].
        floor: absolute wheel speed std [rad/s].
        pose_sigma_xy: position std of a measured pose [m].
        pose_sigma_theta: heading std of a measured pose [rad].
    """

    gain: float = 0.01
    floor: float = 0.001
    pose_sigma_xy: float = 1e-4
    pose_sigma_theta: float = 1e-4

    def __post_init__(self) -> None:
        """Validate.

        Raises:
            ValueError: Negative or non-finite values, or no noise at all.
        """
        vals = (self.gain, self.floor, self.pose_sigma_xy, self.pose_sigma_theta)
        if not all(np.isfinite(v) and v >= 0.0 for v in vals):
            raise ValueError(f'CriterionNoise values must be finite and >= 0, got {vals}')
        if self.pose_sigma_xy <= 0.0 or self.pose_sigma_theta <= 0.0:
            raise ValueError('CriterionNoise pose sigmas must be > 0')


def _check_k(k: Any) -> Tuple[float, float, float]:
    kk = tuple(float(v) for v in np.asarray(k, dtype=float).reshape(-1))
    if len(kk) != 3 or not all(np.isfinite(v) and v > 0.0 for v in kk):
        raise ValueError(f'calibration factors must be three finite numbers > 0, got {k!r}')
    return kk


def _controls(run: CalibrationRun, k: Sequence[float], wheel_radius: float,
              axle_length: float) -> np.ndarray:
    """Return (n, 2) ``[D, dTheta]`` of a run (eqs. 4-5, 17-18)."""
    return control_from_wheels(run.wheel_speeds, wheel_radius, axle_length,
                               run.sample_times, tuple(k))


def integrate_run(run: CalibrationRun, k: Sequence[float], wheel_radius: float,
                  axle_length: float) -> np.ndarray:
    """Integrate a run from its exact start pose with factors k (Algorithm 1, lines 4-6).

    Args:
        run: the run.
        k: ``(k1, k2, k3)``.
        wheel_radius: nominal R [m].
        axle_length: nominal b [m].

    Returns:
        (n+1, 3) estimated poses, Theta unwrapped (continues from the start heading).
    """
    u = _controls(run, k, wheel_radius, axle_length)
    d, dth = u[:, 0], u[:, 1]
    p0 = run.start_pose
    th = p0[2] + np.concatenate([[0.0], np.cumsum(dth)])  # eq. 3
    mid = th[:-1] + 0.5 * dth
    x = p0[0] + np.concatenate([[0.0], np.cumsum(d * np.cos(mid))])  # eq. 1
    y = p0[1] + np.concatenate([[0.0], np.cumsum(d * np.sin(mid))])  # eq. 2
    return np.stack([x, y, th], axis=1)


def final_pose(run: CalibrationRun, k: Sequence[float], wheel_radius: float,
               axle_length: float) -> np.ndarray:
    """Return the estimated final pose (3,) of a run with factors k, Theta unwrapped."""
    return integrate_run(run, k, wheel_radius, axle_length)[-1]


def pose_error(run: CalibrationRun, k: Sequence[float], wheel_radius: float,
               axle_length: float) -> np.ndarray:
    """Return the final pose error ``estimated - exact`` (3,); [2] is eq. 19 (wrapped, rad)."""
    e = final_pose(run, k, wheel_radius, axle_length) - run.end_pose
    e[2] = wrap_angle(e[2])  # eq. 19
    return e


def _sensitivities(run: CalibrationRun, k: Sequence[float], wheel_radius: float,
                   axle_length: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the final pose and its derivatives with respect to every step's D and dTheta.

    Returns:
        ``(p_final (3,), dp/dD (n, 3), dp/ddTheta (n, 3))`` (differentiating eqs. 1-3).
    """
    u = _controls(run, k, wheel_radius, axle_length)
    d, dth = u[:, 0], u[:, 1]
    poses = integrate_run(run, k, wheel_radius, axle_length)
    mid = poses[:-1, 2] + 0.5 * dth
    c, s = np.cos(mid), np.sin(mid)
    pf = poses[-1]
    n = d.shape[0]
    dd = np.stack([c, s, np.zeros(n)], axis=1)
    # dTheta_i turns every later step and half of step i.
    dt = np.stack([-0.5 * d * s - (pf[1] - poses[1:, 1]),
                   0.5 * d * c + (pf[0] - poses[1:, 0]),
                   np.ones(n)], axis=1)
    return pf, dd, dt


def final_pose_jacobian(run: CalibrationRun, k: Sequence[float], wheel_radius: float,
                        axle_length: float) -> np.ndarray:
    """Return the Jacobian (3, 3) of the final pose in ``(k1, k2, k3)`` (eqs. 1-5, 17-18)."""
    k = _check_k(k)
    _, dd, dt = _sensitivities(run, k, wheel_radius, axle_length)
    r, b = wheel_radius, axle_length
    wl = run.wheel_speeds[:, 0] * r * run.sample_times
    wr = run.wheel_speeds[:, 1] * r * run.sample_times
    dth = (k[1] * wr - k[0] * wl) / (k[2] * b)
    j1 = dd.T @ (0.5 * wl) + dt.T @ (-wl / (k[2] * b))  # eq. 17 / 18 in k1
    j2 = dd.T @ (0.5 * wr) + dt.T @ (wr / (k[2] * b))  # in k2
    j3 = dt.T @ (-dth / k[2])  # eq. 18 in k3
    return np.stack([j1, j2, j3], axis=1)


def final_pose_covariance(run: CalibrationRun, k: Sequence[float], wheel_radius: float,
                          axle_length: float,
                          noise: CriterionNoise = CriterionNoise()) -> np.ndarray:
    """Covariance (3, 3) of the final pose error from the random errors (eqs. 8-9).

    Linearised propagation of independent wheel speed errors with std
    ``noise.gain |omega| + noise.floor`` through eqs. 1-5 and 17-18, plus the pose
    measurement noise.
    """
    k = _check_k(k)
    _, dd, dt = _sensitivities(run, k, wheel_radius, axle_length)
    r, b, t = wheel_radius, axle_length, run.sample_times
    sig = noise.gain * np.abs(run.wheel_speeds) + noise.floor
    # d(D, dTheta)/d(omega_L, omega_R) per step (eqs. 4-5, 17-18).
    a_l = dd * (0.5 * k[0] * r * t)[:, None] - dt * (k[0] * r * t / (k[2] * b))[:, None]
    a_r = dd * (0.5 * k[1] * r * t)[:, None] + dt * (k[1] * r * t / (k[2] * b))[:, None]
    cov = (a_l * sig[:, 0:1] ** 2).T @ a_l + (a_r * sig[:, 1:2] ** 2).T @ a_r
    cov += np.diag([noise.pose_sigma_xy ** 2, noise.pose_sigma_xy ** 2,
                    noise.pose_sigma_theta ** 2])
    return 0.5 * (cov + cov.T)


class _Criterion:
    """Whitened residuals of a set of runs (the optimisation m-function of Algorithm 1).

    A straight run contributes ``L^-1 [dx, dy, dTheta]`` (``L L^T`` = its final pose
    covariance), a turn ``dTheta / sigma_Theta`` (eq. 19). The weights are computed once,
    at ``k_weights``.
    """

    def __init__(self, runs: Sequence[CalibrationRun], wheel_radius: float,
                 axle_length: float, noise: CriterionNoise,
                 k_weights: Sequence[float]) -> None:
        self.runs = list(runs)
        self.r = float(wheel_radius)
        self.b = float(axle_length)
        self.weights = []
        for run in self.runs:
            cov = final_pose_covariance(run, k_weights, self.r, self.b, noise)
            if run.is_turn:
                self.weights.append(np.array([[0.0, 0.0, 1.0 / np.sqrt(cov[2, 2])]]))
            else:
                self.weights.append(np.linalg.inv(np.linalg.cholesky(cov)))

    def residuals(self, k: Sequence[float]) -> np.ndarray:
        """Stacked whitened residuals at k."""
        return np.concatenate([w @ pose_error(run, k, self.r, self.b)
                               for run, w in zip(self.runs, self.weights)])

    def jacobian(self, k: Sequence[float]) -> np.ndarray:
        """Jacobian (m, 3) of :meth:`residuals` with respect to k."""
        return np.vstack([w @ final_pose_jacobian(run, k, self.r, self.b)
                          for run, w in zip(self.runs, self.weights)])

    def cost(self, k: Sequence[float]) -> float:
        """Sum of squared whitened residuals."""
        return float(np.sum(self.residuals(k) ** 2))


def _fit(criterion: _Criterion, k: Sequence[float], free: Sequence[int]) -> np.ndarray:
    """Minimise the criterion over the factors ``free`` (indices), the others fixed."""
    from scipy.optimize import least_squares  # here: scipy.optimize takes 0.35 s to import
    k = np.array(k, dtype=float)
    free = list(free)

    def full(p: np.ndarray) -> np.ndarray:
        kk = k.copy()
        kk[free] = p
        return kk

    sol = least_squares(lambda p: criterion.residuals(full(p)), k[free],
                        jac=lambda p: criterion.jacobian(full(p))[:, free],
                        bounds=(0.5, 2.0), method='trf', x_scale=1.0, **_TOL)
    return full(sol.x)


def _require_kinds(runs: Sequence[CalibrationRun], what: str) -> None:
    if not any(r.kind == 'straight' for r in runs):
        raise ValueError(f'{what} has no straight run: k1 + k2 is not identifiable')
    if not any(r.is_turn for r in runs):
        raise ValueError(f'{what} has no turn in place: k3 is not identifiable')


def calibrate_data_set(runs: Sequence[CalibrationRun], wheel_radius: float,
                       axle_length: float, iterations: int = 2,
                       k0: Sequence[float] = NOMINAL_K,
                       noise: CriterionNoise = CriterionNoise()) -> np.ndarray:
    """Algorithm 1 on one data set: alternate the k1, k2 and the k3 m-functions.

    Each iteration: (k1, k2) minimise the straight-run criterion (full final pose error)
    with k3 fixed; then k3 minimises eq. 19 over the CCW turns and over the CW turns
    separately, with k1, k2 fixed, and the directions' values are averaged.

    Args:
        runs: the data set (at least one straight run and one turn).
        wheel_radius: nominal R [m].
        axle_length: nominal b [m].
        iterations: number of alternations (the chapter: two).
        k0: starting factors (the chapter: 1.0, the nominal model).
        noise: weights of the criterion.

    Returns:
        (3,) ``[k1, k2, k3]``.

    Raises:
        ValueError: No straight run, no turn, or iterations < 1.
    """
    if int(iterations) < 1:
        raise ValueError(f'iterations must be >= 1, got {iterations}')
    _require_kinds(runs, 'data set')
    k = np.array(_check_k(k0))
    straight = _Criterion([r for r in runs if not r.is_turn], wheel_radius, axle_length,
                          noise, k)
    turns = [_Criterion([r for r in runs if r.kind == kind], wheel_radius, axle_length,
                        noise, k) for kind in TURN_KINDS
             if any(r.kind == kind for r in runs)]
    for _ in range(int(iterations)):
        k = _fit(straight, k, [0, 1])  # k1, k2 from the straight runs (k3 fixed)
        k[2] = np.mean([_fit(c, k, [2])[2] for c in turns])  # k3 per direction, averaged
    return k


def split_data_sets(runs: Sequence[CalibrationRun]) -> List[List[CalibrationRun]]:
    """Split calibration runs into data sets of one straight run and one turn each.

    Runs are taken in recording order (``index``); with n = min(#straight, #turns) sets,
    the j-th straight run and the j-th turn go to set ``j mod n``. The chapter's data set
    holds a straight run and turns in both directions; the simulator's calibration group
    (5 straight runs, 3 CCW and 2 CW turns) pairs each straight run with the turn after it.

    Raises:
        ValueError: No straight run or no turn.
    """
    _require_kinds(runs, 'calibration group')
    ordered = sorted(runs, key=lambda r: r.index)
    straight = [r for r in ordered if not r.is_turn]
    turns = [r for r in ordered if r.is_turn]
    n = min(len(straight), len(turns))
    sets: List[List[CalibrationRun]] = [[] for _ in range(n)]
    for group in (straight, turns):
        for j, run in enumerate(group):
            sets[j % n].append(run)
    return [sorted(s, key=lambda r: r.index) for s in sets]


@dataclass(frozen=True)
class Identifiability:
    """Local identifiability of k from the criterion (whitened Jacobian at the estimate).

    Attributes:
        singular_values: (3,) singular values of the whitened Jacobian, descending.
        condition: ratio of the largest to the smallest singular value.
        std: (3,) standard deviations of ``(k1, k2, k3)`` implied by the weights (the
            inverse of ``J^T J``; valid when the noise model is right).
        heading_only_rank: rank of the Jacobian of the final headings alone (2: eq. 19
            cannot fix the common scale of k).
    """

    singular_values: np.ndarray
    condition: float
    std: np.ndarray
    heading_only_rank: int

    @property
    def identifiable(self) -> bool:
        """True when the Jacobian has full rank (condition < 1e8)."""
        return bool(np.isfinite(self.condition) and self.condition < 1e8)


def identifiability(runs: Sequence[CalibrationRun], wheel_radius: float, axle_length: float,
                    k: Sequence[float] = NOMINAL_K,
                    noise: CriterionNoise = CriterionNoise()) -> Identifiability:
    """Check how well the runs determine k (rank and conditioning of the criterion).

    Args:
        runs: runs of any kinds.
        wheel_radius: nominal R [m].
        axle_length: nominal b [m].
        k: linearisation point.
        noise: weights of the criterion.

    Returns:
        The :class:`Identifiability` figures.
    """
    k = _check_k(k)
    crit = _Criterion(runs, wheel_radius, axle_length, noise, k)
    jac = crit.jacobian(k)
    sv = np.linalg.svd(jac, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0.0 else float('inf')
    with np.errstate(all='ignore'):
        try:
            std = np.sqrt(np.diag(np.linalg.inv(jac.T @ jac)))
        except np.linalg.LinAlgError:
            std = np.full(3, np.inf)
    heads = np.array([final_pose_jacobian(r, k, wheel_radius, axle_length)[2] for r in runs])
    hsv = np.linalg.svd(heads, compute_uv=False)
    rank = int(np.sum(hsv > 1e-9 * max(hsv[0], 1e-300)))
    return Identifiability(singular_values=sv, condition=cond, std=std,
                           heading_only_rank=rank)


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """Estimated calibration factors.

    Attributes:
        k: ``(k1, k2, k3)``.
        method: ``'chapter'`` (Algorithm 1 per data set, averaged) or ``'joint'``.
        set_estimates: (m, 3) per data set factors (``'chapter'``); (1, 3) for ``'joint'``.
        iterations: Algorithm 1 iterations (``'chapter'``).
        cost: criterion (sum of squared whitened residuals) of all runs at k.
        identifiability: rank / conditioning figures at k.
    """

    k: Tuple[float, float, float]
    method: str
    set_estimates: np.ndarray
    iterations: int
    cost: float
    identifiability: Identifiability

    @property
    def set_std(self) -> np.ndarray:
        """(3,) standard deviation of the factors over the data sets (0 for one set)."""
        if self.set_estimates.shape[0] < 2:
            return np.zeros(3)
        return np.std(self.set_estimates, axis=0, ddof=1)

    def as_dict(self) -> Dict[str, float]:
        """Return ``{'k1': .., 'k2': .., 'k3': ..}``."""
        return {'k1': self.k[0], 'k2': self.k[1], 'k3': self.k[2]}


def calibrate(runs: Sequence[CalibrationRun], wheel_radius: float, axle_length: float,
              method: str = 'chapter', iterations: int = 2,
              noise: CriterionNoise = CriterionNoise(),
              data_sets: Optional[Sequence[Sequence[CalibrationRun]]] = None
              ) -> CalibrationResult:
    """Estimate ``(k1, k2, k3)`` from calibration runs (section 3.1.2).

    Args:
        runs: the calibration group (straight runs and turns in place).
        wheel_radius: nominal R [m].
        axle_length: nominal b [m].
        method: ``'chapter'``: Algorithm 1 on every data set, factors averaged over the
            sets (default, as the chapter does); ``'joint'``: one weighted least-squares
            fit of all three factors to all runs.
        iterations: Algorithm 1 iterations (``'chapter'``; the chapter uses two).
        noise: weights of the criterion, see :class:`CriterionNoise`.
        data_sets: explicit data sets for ``'chapter'`` (default :func:`split_data_sets`).

    Returns:
        The :class:`CalibrationResult`.

    Raises:
        ValueError: Unknown method, no straight run or no turn, or k not identifiable.
    """
    if method not in METHODS:
        raise ValueError(f'unknown calibration method {method!r}; valid: {list(METHODS)}')
    if not (np.isfinite(wheel_radius) and wheel_radius > 0.0
            and np.isfinite(axle_length) and axle_length > 0.0):
        raise ValueError('wheel radius and axle length must be finite and > 0')
    runs = list(runs)
    _require_kinds(runs, 'calibration group')
    if method == 'chapter':
        sets = split_data_sets(runs) if data_sets is None else [list(s) for s in data_sets]
        est = np.array([calibrate_data_set(s, wheel_radius, axle_length, iterations,
                                           noise=noise) for s in sets])
        k = np.mean(est, axis=0)  # average over the calibration data sets
    else:
        crit = _Criterion(runs, wheel_radius, axle_length, noise, NOMINAL_K)
        k = _fit(crit, NOMINAL_K, [0, 1, 2])
        est = k[None, :]
    k_t = _check_k(k)
    ident = identifiability(runs, wheel_radius, axle_length, k_t, noise)
    if not ident.identifiable:
        raise ValueError(f'calibration factors are not identifiable from these runs '
                         f'(condition number {ident.condition:.3g})')
    cost = _Criterion(runs, wheel_radius, axle_length, noise, NOMINAL_K).cost(k_t)
    return CalibrationResult(k=k_t, method=method, set_estimates=est,
                             iterations=int(iterations), cost=cost, identifiability=ident)


def final_errors(runs: Sequence[CalibrationRun], k: Sequence[float], wheel_radius: float,
                 axle_length: float) -> Tuple[np.ndarray, np.ndarray]:
    """Return the final position and heading errors of runs dead-reckoned with k.

    Returns:
        ``(position_error (n,) [m], heading_error (n,) [rad])``, both absolute values;
        the heading error is |eq. 19|.
    """
    k = _check_k(k)
    errs = np.array([pose_error(r, k, wheel_radius, axle_length) for r in runs]).reshape(-1, 3)
    return np.hypot(errs[:, 0], errs[:, 1]), np.abs(errs[:, 2])


__all__ = ['calibrate', 'calibrate_data_set', 'CalibrationResult', 'CalibrationRun',
           'CriterionNoise', 'final_errors', 'final_pose', 'final_pose_covariance',
           'final_pose_jacobian', 'Identifiability', 'identifiability', 'integrate_run',
           'make_run', 'METHODS', 'NOMINAL_K', 'pose_error', 'RUN_KINDS', 'split_data_sets']
