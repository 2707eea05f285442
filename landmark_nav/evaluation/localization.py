"""Offline evaluation: run the EKF / UKF over a recorded run, odometry alone, pose errors.

Time alignment (10 Hz, odometry and sonar share the stamps): the wheel speeds of the
odometry sample at stamp k are those of the step that ENDS at k, so the filter does, for
k = 0 .. T-1: a time update with ``u_{k-1}`` from them (k >= 1), then a measurement update
with the sonar cycle stamped k. Row k of the outputs is the posterior at stamp k.
"""

from dataclasses import dataclass, replace
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

from landmark_nav.geometry import wrap_angle
from landmark_nav.localization import ekf, ukf
from landmark_nav.localization.grid import GridMap, rasterize_world
from landmark_nav.localization.odometry import control_from_wheels, dead_reckoning
from landmark_nav.localization.params import LocalizationParams
from landmark_nav.localization.sonar_model import build_sonar_map
from landmark_nav.sim import OdometrySample, run_scenario, SonarSample
import numpy as np

#: Initial pose covariance of the chapter's experiments (section 6.1):
#: diag(0.3 dm^2, 0.3 dm^2, 0.008 rad^2), i.e. 5.5 cm and 5.1 deg standard deviation.
CHAPTER_P0 = np.diag([0.003, 0.003, 0.008])


@dataclass(frozen=True, eq=False)
class LocalizationInput:
    """The arrays a localization run needs (one row per 10 Hz stamp).

    Attributes:
        stamps_ns: (T,) int64 stamps.
        wheel_velocities: (T, 2) measured ``(omega_L, omega_R)`` [rad/s] of the step ending
            at each stamp (row 0 unused).
        sonar_ranges: (T, S) readings [m] (``nan`` rows: no sonar cycle at that stamp).
        mounts: (S, 3) sonar poses in base_link.
        wheel_radius: nominal R [m].
        axle_length: nominal b [m].
        sample_time: T [s].
        truth: (T, 3) true poses, or None.
        true_k: the simulator's true ``(k1, k2, k3)``, or None.
    """

    stamps_ns: np.ndarray
    wheel_velocities: np.ndarray
    sonar_ranges: np.ndarray
    mounts: np.ndarray
    wheel_radius: float
    axle_length: float
    sample_time: float
    truth: Optional[np.ndarray] = None
    true_k: Optional[Tuple[float, float, float]] = None

    @classmethod
    def from_result(cls, result: Any) -> 'LocalizationInput':
        """Extract the arrays from a :class:`landmark_nav.sim.ScenarioResult`."""
        odo = result.of_type(OdometrySample)
        stamps = np.array([e.stamp_ns for e in odo], dtype=np.int64)
        wheels = np.array([e.wheel_velocities for e in odo], dtype=float).reshape(-1, 2)
        sonar_cfg = result.sonar
        mounts = np.array(sonar_cfg.mounts if sonar_cfg is not None else np.zeros((0, 3)),
                          dtype=float).reshape(-1, 3)
        ranges = np.full((stamps.size, mounts.shape[0]), np.nan)
        index = {int(s): i for i, s in enumerate(stamps)}
        for e in result.of_type(SonarSample):
            i = index.get(int(e.stamp_ns))
            if i is not None:
                ranges[i] = np.asarray(e.ranges, dtype=float)
        rp = result.robot
        return cls(stamps_ns=stamps, wheel_velocities=wheels, sonar_ranges=ranges,
                   mounts=mounts, wheel_radius=float(rp.wheel_radius),
                   axle_length=float(rp.axle_length), sample_time=float(rp.sample_time),
                   truth=np.asarray(result.truth_at(stamps), dtype=float),
                   true_k=(float(rp.k1), float(rp.k2), float(rp.k3)))

    def controls(self, k: Sequence[float] = (1.0, 1.0, 1.0)) -> np.ndarray:
        """Control inputs (T-1, 2): row j = ``u_j`` from stamp j to j+1 (eqs. 4-7, 17-18)."""
        return control_from_wheels(self.wheel_velocities[1:], self.wheel_radius,
                                   self.axle_length, self.sample_time,
                                   tuple(k))  # type: ignore[arg-type]


@dataclass(frozen=True, eq=False)
class LocalizationRun:
    """Output of :func:`localize`.

    Attributes:
        trajectory: (T, 3) posterior poses.
        covariances: (T, 3, 3) posterior covariances.
        accepted: (T, S) bool, readings used by the measurement update.
        innovations: (T, S) ``z - zhat`` (nan without prediction).
    """

    trajectory: np.ndarray
    covariances: np.ndarray
    accepted: np.ndarray
    innovations: np.ndarray


def _as_input(data: Any) -> LocalizationInput:
    if isinstance(data, LocalizationInput):
        return data
    if isinstance(data, dict):
        return LocalizationInput(**data)
    return LocalizationInput.from_result(data)


def localize(data: Any, filter: str = 'ekf',  # noqa: A002 (name from the API spec)
             grid: Optional[GridMap] = None,
             initial_pose: Any = None, initial_cov: Any = None,
             params: Optional[LocalizationParams] = None,
             k: Optional[Sequence[float]] = None) -> LocalizationRun:
    """Run the EKF or the UKF over a recorded run (see :func:`run_localization`)."""
    inp = _as_input(data)
    if filter not in ('ekf', 'ukf'):
        raise ValueError("filter must be 'ekf' or 'ukf'")
    if grid is None:
        raise ValueError('a GridMap is required')
    params = params or LocalizationParams()
    if k is None:
        k = inp.true_k if inp.true_k is not None else (1.0, 1.0, 1.0)
    if initial_pose is None:
        if inp.truth is None:
            raise ValueError('initial_pose is required when the input has no truth')
        initial_pose = inp.truth[0]
    x = np.asarray(initial_pose, dtype=float).copy()
    x[2] = wrap_angle(x[2])
    p = np.asarray(CHAPTER_P0 if initial_cov is None else initial_cov, dtype=float).copy()
    u_all = inp.controls(k)
    n, n_s = inp.sonar_ranges.shape
    traj = np.empty((n, 3))
    covs = np.empty((n, 3, 3))
    acc = np.zeros((n, n_s), dtype=bool)
    inn = np.full((n, n_s), np.nan)
    for i in range(n):
        x_sig = None
        if i > 0:
            if filter == 'ekf':
                x, p = ekf.time_update(x, p, u_all[i - 1], params)
            else:
                x, p, x_sig = ukf.time_update(x, p, u_all[i - 1], params)
        z = inp.sonar_ranges[i]
        if not np.isnan(z).all():
            if filter == 'ekf':
                x, p, info = ekf.measurement_update(x, p, z, grid, inp.mounts, params)
            else:
                x, p, info = ukf.measurement_update(x, p, x_sig, z, grid, inp.mounts, params)
            acc[i] = info['accepted']
            inn[i] = info['innovation']
        traj[i] = x
        covs[i] = p
    return LocalizationRun(trajectory=traj, covariances=covs, accepted=acc, innovations=inn)


def run_localization(result_or_arrays: Any,
                     filter: str = 'ekf',  # noqa: A002 (name from the API spec)
                     grid: Optional[GridMap] = None, initial_pose: Any = None,
                     initial_cov: Any = None, params: Optional[LocalizationParams] = None,
                     k: Optional[Sequence[float]] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Run sonar localization offline with the EKF or the UKF.

    Args:
        result_or_arrays: a :class:`landmark_nav.sim.ScenarioResult`, a
            :class:`LocalizationInput` or a dict of its fields.
        filter: ``'ekf'`` or ``'ukf'``.
        grid: the occupancy grid map.
        initial_pose: (3,) initial estimate (default: the true start pose).
        initial_cov: (3, 3) initial covariance (default :data:`CHAPTER_P0`).
        params: filter parameters (default :class:`LocalizationParams`).
        k: odometry calibration ``(k1, k2, k3)`` (default: the input's true factors if
            known, else nominal).

    Returns:
        ``(trajectory (T, 3), covariances (T, 3, 3))``, the posterior at every stamp.
    """
    run = localize(result_or_arrays, filter, grid, initial_pose, initial_cov, params, k)
    return run.trajectory, run.covariances


def odometry_trajectory(result_or_arrays: Any, initial_pose: Any = None,
                        k: Sequence[float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """Odometry alone: dead reckoning with calibration ``k`` (default nominal) -> (T, 3)."""
    inp = _as_input(result_or_arrays)
    if initial_pose is None:
        initial_pose = inp.truth[0]
    return dead_reckoning(initial_pose, inp.controls(k))


def localization_errors(estimate: Any, truth: Any, start: int = 0) -> Dict[str, float]:
    """Pose error statistics of a trajectory against ground truth.

    Args:
        estimate: (T, 3) estimated poses.
        truth: (T, 3) true poses at the same stamps.
        start: first row included in the statistics (e.g. after an initial settling).

    Returns:
        Dict with ``max_position``, ``rms_position``, ``end_position`` [m] and
        ``max_heading``, ``rms_heading``, ``end_heading`` [rad] (absolute, wrapped), and
        ``max_heading_deg`` / ``end_heading_deg``.
    """
    e = np.asarray(estimate, dtype=float)[start:]
    t = np.asarray(truth, dtype=float)[start:]
    dp = np.hypot(e[:, 0] - t[:, 0], e[:, 1] - t[:, 1])
    dh = np.abs(wrap_angle(e[:, 2] - t[:, 2]))
    return {
        'max_position': float(dp.max()), 'rms_position': float(np.sqrt(np.mean(dp ** 2))),
        'end_position': float(dp[-1]),
        'max_heading': float(dh.max()), 'rms_heading': float(np.sqrt(np.mean(dh ** 2))),
        'end_heading': float(dh[-1]),
        'max_heading_deg': math.degrees(float(dh.max())),
        'end_heading_deg': math.degrees(float(dh[-1])),
    }


def first_motion_index(truth: Any, threshold: float = 1e-3) -> int:
    """Index of the first stamp at which the robot has moved more than ``threshold`` [m]."""
    t = np.asarray(truth, dtype=float)
    moved = np.hypot(t[:, 0] - t[0, 0], t[:, 1] - t[0, 1]) > threshold
    return int(np.argmax(moved)) if moved.any() else 0


def distance_index(truth: Any, distance: float) -> int:
    """Index of the first stamp at which the robot has travelled ``distance`` [m] (path)."""
    t = np.asarray(truth, dtype=float)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(t[:, :2], axis=0).T))])
    idx = np.flatnonzero(s >= distance)
    return int(idx[0]) if idx.size else t.shape[0] - 1


def draw_initial_pose(truth_pose: Any, cov: Any = CHAPTER_P0,
                      rng: Union[int, np.random.Generator, None] = None) -> np.ndarray:
    """Draw an initial estimate from N(truth, cov) (section 6.1)."""
    g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    x = np.asarray(truth_pose, dtype=float) + g.multivariate_normal(np.zeros(3), cov)
    x[2] = wrap_angle(x[2])
    return x


# ---------------------------------------------------------------------- hallway study
#: Acceptance targets (issue 6): max position [m] and heading [rad] error per filter.
TARGETS = {'ukf': (0.10, math.radians(2.0)), 'ekf': (0.15, math.radians(3.0))}


def last_exceedance(estimate: Any, truth: Any, max_position: float,
                    max_heading: float) -> Tuple[float, float]:
    """Distance travelled [m] and time index after which the errors stay within bounds.

    Returns:
        ``(distance, index)`` of the last stamp whose position or heading error exceeds
        the bound (``(0.0, -1)`` if none does); the errors are within the bounds from the
        next stamp on.
    """
    e = np.asarray(estimate, dtype=float)
    t = np.asarray(truth, dtype=float)
    bad = ((np.hypot(e[:, 0] - t[:, 0], e[:, 1] - t[:, 1]) > max_position)
           | (np.abs(wrap_angle(e[:, 2] - t[:, 2])) > max_heading))
    if not bad.any():
        return 0.0, -1
    i = int(np.flatnonzero(bad)[-1])
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(t[:, :2], axis=0).T))])
    return float(s[i]), i


def hallway_study(seeds: Sequence[int], params: Optional[LocalizationParams] = None,
                  two_sigma: bool = True, map_seed: Optional[int] = 100,
                  resolution: float = 0.1) -> Dict[str, Any]:
    """Evaluate both filters on the hallway scenario (the issue's acceptance protocol).

    Per seed: the map is ``rasterize_world(result.world, resolution)``; the initial
    estimate is drawn from N(truth, :data:`CHAPTER_P0`) (generator seed ``1000 + seed``)
    and the filters start with covariance :data:`CHAPTER_P0`; errors are measured from
    the first stamp at which the robot moves (the scenario starts with 1 s = 10 sonar
    cycles at rest) to the end. Odometry alone starts from the true pose, calibrated
    (true k1, k2, k3) and uncalibrated. ``two_sigma``: runs starting 2 sigma away in x, y
    and Theta (all 8 sign combinations) record the distance after which the errors stay
    within :data:`TARGETS`. ``map_seed``: a map built by ``build_sonar_map`` from that
    seed's run with true poses is used for a second UKF / EKF run on every seed
    (unknown cells treated as free).

    Returns:
        Dict of per-seed lists (``'ekf'``, ``'ukf'``, ``'odometry_calibrated'``,
        ``'odometry_uncalibrated'``: error dicts; ``'two_sigma'``; ``'built_map'``).
    """
    params = params or LocalizationParams()
    out: Dict[str, Any] = {k: [] for k in ('seeds', 'ekf', 'ukf', 'odometry_calibrated',
                                           'odometry_uncalibrated', 'two_sigma',
                                           'built_map')}
    built = None
    if map_seed is not None:
        ref = LocalizationInput.from_result(run_scenario('hallway', map_seed))
        built = build_sonar_map(ref.truth, ref.sonar_ranges, ref.mounts, resolution)
    sigma = np.sqrt(np.diag(CHAPTER_P0))
    for seed in seeds:
        res = run_scenario('hallway', seed)
        inp = LocalizationInput.from_result(res)
        grid = rasterize_world(res.world, resolution)
        i0 = first_motion_index(inp.truth)
        x0 = draw_initial_pose(inp.truth[0], CHAPTER_P0, 1000 + seed)
        out['seeds'].append(int(seed))
        for f in ('ekf', 'ukf'):
            run = localize(inp, f, grid, x0, CHAPTER_P0, params)
            err = localization_errors(run.trajectory, inp.truth, i0)
            err['max_position_incl_start'] = localization_errors(run.trajectory,
                                                                 inp.truth)['max_position']
            err['max_heading_incl_start'] = localization_errors(run.trajectory,
                                                                inp.truth)['max_heading']
            out[f].append(err)
        for key, k in (('odometry_calibrated', inp.true_k),
                       ('odometry_uncalibrated', (1.0, 1.0, 1.0))):
            odo = odometry_trajectory(inp, inp.truth[0], k)
            out[key].append(localization_errors(odo, inp.truth, i0))
        if two_sigma:
            conv: Dict[str, Any] = {}
            for f in ('ekf', 'ukf'):
                worst = (0.0, -1)
                for signs in np.array(np.meshgrid([1, -1], [1, -1], [1, -1])).T.reshape(-1, 3):
                    xs = inp.truth[0] + 2.0 * sigma * signs
                    run = localize(inp, f, grid, xs, CHAPTER_P0, params)
                    last = last_exceedance(run.trajectory, inp.truth, *TARGETS[f])
                    worst = max(worst, last)
                conv[f] = {'distance': worst[0],
                           'time': (worst[1] + 1) * inp.sample_time}
            out['two_sigma'].append(conv)
        if built is not None:
            p_map = replace(params, unknown='free')
            entry = {}
            for f in ('ekf', 'ukf'):
                run = localize(inp, f, built, x0, CHAPTER_P0, p_map)
                entry[f] = localization_errors(run.trajectory, inp.truth, i0)
            out['built_map'].append(entry)
    return out


def _parse_seeds(text: str) -> List[int]:
    seeds: List[int] = []
    for part in text.split(','):
        if '-' in part:
            a, b = part.split('-')
            seeds.extend(range(int(a), int(b) + 1))
        elif part:
            seeds.append(int(part))
    return seeds


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Print the hallway study (``python -m landmark_nav.evaluation.localization``)."""
    import argparse
    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument('--seeds', default='1-10', help='e.g. 1-10 or 1,3,5')
    ap.add_argument('--no-two-sigma', action='store_true')
    ap.add_argument('--map-seed', type=int, default=100)
    args = ap.parse_args(argv)
    st = hallway_study(_parse_seeds(args.seeds), two_sigma=not args.no_two_sigma,
                       map_seed=args.map_seed)
    deg = math.degrees
    print(f'hallway, seeds {st["seeds"]}: mean / worst')
    print('method                      max pos [m]    max hdg [deg]  end pos [m]    rms pos [m]')
    for key in ('ekf', 'ukf', 'odometry_calibrated', 'odometry_uncalibrated'):
        rows = st[key]
        mp = np.array([r['max_position'] for r in rows])
        mh = np.array([deg(r['max_heading']) for r in rows])
        ep = np.array([r['end_position'] for r in rows])
        rp = np.array([r['rms_position'] for r in rows])
        print(f'{key:26s} {mp.mean():6.3f}/{mp.max():6.3f} {mh.mean():6.2f}/{mh.max():6.2f}'
              f'  {ep.mean():6.3f}/{ep.max():6.3f} {rp.mean():6.3f}/{rp.max():6.3f}')
    for f in ('ekf', 'ukf'):
        ratio = (np.array([r['end_position'] for r in st['odometry_calibrated']])
                 / np.array([r['end_position'] for r in st[f]]))
        print(f'{f}: end error ratio calibrated odometry / filter: min {ratio.min():.1f}, '
              f'mean {ratio.mean():.1f}; max incl. t0: pos '
              f'{max(r["max_position_incl_start"] for r in st[f]):.3f} m, heading '
              f'{deg(max(r["max_heading_incl_start"] for r in st[f])):.2f} deg')
    if st['two_sigma']:
        for f in ('ekf', 'ukf'):
            d = [c[f]['distance'] for c in st['two_sigma']]
            t = [c[f]['time'] for c in st['two_sigma']]
            print(f'2-sigma start, {f}: within targets after {max(d):.2f} m / {max(t):.1f} s '
                  f'(worst of 8 sign patterns x {len(d)} seeds)')
    if st['built_map']:
        for f in ('ekf', 'ukf'):
            mp = np.array([b[f]['max_position'] for b in st['built_map']])
            mh = np.array([deg(b[f]['max_heading']) for b in st['built_map']])
            print(f'sonar-built map (seed {args.map_seed}), {f}: max pos {mp.mean():.3f}/'
                  f'{mp.max():.3f} m, max heading {mh.mean():.2f}/{mh.max():.2f} deg')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
