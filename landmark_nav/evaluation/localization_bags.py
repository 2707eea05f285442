"""Sonar localization on a bag: the offline evaluation behind ``evaluate-localization``.

* :func:`evaluate_localization` -- ``landmark_nav evaluate-localization <bag>``: runs the
  EKF or UKF core (:func:`landmark_nav.evaluation.localization.localize`) directly on a
  bag's odometry and sonar (no DDS) against ``/ground_truth/odom``, with the protocol of
  the core's hallway study: map rasterised from the world in ``ground_truth.yaml`` (or a
  map file), initial estimate drawn from N(truth, diag(initial_std)^2), errors from the
  first stamp at which the robot moves to the end; odometry alone from the true start,
  calibrated (the bag's true k1, k2, k3) and uncalibrated. Writes a JSON and two PNGs
  (trajectory with the map, heading vs time; the chapter's Figs. 16-17).
* :func:`load_bag_input`, :func:`sonar_topics` -- a bag's odometry, sonar and poses as
  arrays (the poses by :func:`landmark_nav.evaluation.bags.read_track`; also used by the
  map tools of :mod:`landmark_nav.tools.localization_tools`).

Bad input (missing bag, bag without sonar or ground truth, unknown filter or scenario)
raises :class:`~landmark_nav.bag.BagError` or ``ValueError`` with a one-line message.
"""

from dataclasses import replace
import json
import math
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

from landmark_nav.bag import BagReader
from landmark_nav.conversions import stamp_to_ns
from landmark_nav.evaluation.bags import read_track
from landmark_nav.evaluation.localization import (draw_initial_pose, first_motion_index,
                                                  localization_errors, LocalizationInput,
                                                  LocalizationRun, localize,
                                                  odometry_trajectory, TARGETS)
from landmark_nav.geometry import interpolate_pose, wrap_angle
from landmark_nav.hardware import SONAR_MOUNTS
from landmark_nav.localization.configuration import localizer_configuration
from landmark_nav.localization.grid import GridMap, load_map_yaml, rasterize_world
from landmark_nav.localization.odometry import control_from_poses
from landmark_nav.localization.params import LocalizationParams
from landmark_nav.localization.tracking import sonar_reading
from landmark_nav.sim.record import load_ground_truth
from landmark_nav.sim.world import World
import numpy as np

FILTERS = ('ekf', 'ukf')
#: Initial pose standard deviations of the evaluation (x [m], y [m], heading [rad]).
INITIAL_STD = (0.055, 0.055, math.radians(5.0))
WHEEL_JOINTS = ('left_wheel_joint', 'right_wheel_joint')


# ---------------------------------------------------------------------- bag reading
def sonar_topics(bag: Path, available: Sequence[str], meta: Optional[dict]) -> list:
    """Sonar topics of a bag in mount order (ground_truth.yaml, else /sonar/range_<i>)."""
    listed = ((meta or {}).get('topics') or {}).get('sonar')
    if listed:
        topics = [t for t in listed if t in available]
    else:
        found = {}
        for t in available:
            if t.startswith('/sonar/range_') and t.rsplit('_', 1)[1].isdigit():
                found[int(t.rsplit('_', 1)[1])] = t
        topics = [found[i] for i in sorted(found)]
    if not topics:
        raise ValueError(f'{bag} has no sonar topics (/sonar/range_0..15)')
    return topics


def _wheel_velocities(reader: BagReader, bag: Path, joints: Sequence[str]
                      ) -> Tuple[np.ndarray, np.ndarray]:
    """Stamps (T,) and wheel speeds (T, 2) of the steps ending there, from JointState."""
    stamps, vel, pos = [], [], []
    for _, _, msg in reader.decoded(['/joint_states']):
        try:
            idx = [list(msg.name).index(j) for j in joints]
        except ValueError:
            raise ValueError(f'{bag}: /joint_states lacks the joints {list(joints)}') from None
        stamps.append(stamp_to_ns(msg.header.stamp))
        vel.append([msg.velocity[i] for i in idx] if len(msg.velocity) else [math.nan] * 2)
        pos.append([msg.position[i] for i in idx] if len(msg.position) else [math.nan] * 2)
    t = np.asarray(stamps, dtype=np.int64)
    w = np.asarray(vel, dtype=float).reshape(-1, 2)
    if not np.isfinite(w[1:]).all():  # no speeds recorded: angle differences / dt
        p = np.asarray(pos, dtype=float).reshape(-1, 2)
        w = np.zeros_like(p)
        w[1:] = np.diff(p, axis=0) / (np.diff(t)[:, None] * 1e-9)
    return t, w


def load_bag_input(bag: Any, odometry_source: Optional[str] = None
                   ) -> Tuple[LocalizationInput, Dict[str, Any]]:
    """Read a simulator bag into the core's :class:`LocalizationInput` (no DDS).

    Rows are the odometry stamps. Wheel speeds come from ``/joint_states`` (recorded
    speeds, else angle differences) or, with ``odometry_source='odom'`` (the default when
    the bag has no joint states), from successive ``/odom`` poses with the nominal R and b.
    Sonar readings (REP 117; NaN and finite values outside the message's limits become nan)
    go to the row of their stamp; truth is ``/ground_truth/odom`` at the row stamps. Robot
    parameters, the true k and the sonar mounts come from ``ground_truth.yaml``.

    Returns:
        ``(input, meta)`` with ``meta`` the parsed ``ground_truth.yaml`` plus
        ``'sonar_topics'``, ``'odometry_source'`` and ``'unmatched_sonar_cycles'``.

    Raises:
        BagError: missing or unreadable bag.
        ValueError: no ground truth, no sonar, no odometry.
    """
    bag = Path(bag)
    with BagReader(bag) as reader:
        meta = load_ground_truth(bag)
        infos = reader.topics()
        topics = sonar_topics(bag, list(infos), meta)
        if odometry_source is None:
            odometry_source = 'joint_states' if '/joint_states' in infos else 'odom'
        if odometry_source not in ('joint_states', 'odom'):
            raise ValueError(f"odometry_source must be 'joint_states' or 'odom', got "
                             f'{odometry_source!r}')
        topic = '/' + odometry_source
        if topic not in infos or infos[topic].count == 0:
            raise ValueError(f'{bag} has no {topic} messages')
        if '/ground_truth/odom' not in infos:
            raise ValueError(f'{bag} has no /ground_truth/odom (no ground truth to compare)')
        robot = meta['robot']
        r, b = float(robot['wheel_radius']), float(robot['axle_length'])
        if odometry_source == 'joint_states':
            stamps, wheels = _wheel_velocities(reader, bag, WHEEL_JOINTS)
        else:
            stamps, odo = read_track(reader, '/odom')
            u = control_from_poses(odo[:-1], odo[1:])
            dt = np.diff(stamps) * 1e-9
            wheels = np.zeros((stamps.size, 2))
            wheels[1:, 0] = (u[:, 0] - 0.5 * b * u[:, 1]) / (r * dt)  # eqs. 4-7 inverted
            wheels[1:, 1] = (u[:, 0] + 0.5 * b * u[:, 1]) / (r * dt)
        index = {int(s): i for i, s in enumerate(stamps)}
        ranges = np.full((stamps.size, len(topics)), np.nan)
        column = {t: j for j, t in enumerate(topics)}
        unmatched = set()
        for name, _, msg in reader.decoded(topics):
            s = stamp_to_ns(msg.header.stamp)
            i = index.get(s)
            if i is None:
                unmatched.add(s)
                continue
            ranges[i, column[name]] = sonar_reading(msg.range, msg.min_range,
                                                    msg.max_range)[0]
        t_truth, truth = read_track(reader, '/ground_truth/odom')
    if np.isnan(ranges).all():
        raise ValueError(f'{bag}: no sonar reading on an odometry stamp')
    truth_rows = interpolate_pose(stamps.astype(float), t_truth.astype(float), truth,
                                  extrapolate=True)
    mounts = np.asarray((meta.get('sonar') or {}).get('mounts', SONAR_MOUNTS[:len(topics)]),
                        dtype=float).reshape(-1, 3)
    if mounts.shape[0] != len(topics):
        raise ValueError(f'{bag}: {mounts.shape[0]} sonar mounts for {len(topics)} topics')
    sample_time = float(robot.get('sample_time', np.median(np.diff(stamps)) * 1e-9))
    inp = LocalizationInput(
        stamps_ns=stamps, wheel_velocities=wheels, sonar_ranges=ranges, mounts=mounts,
        wheel_radius=r, axle_length=b, sample_time=sample_time, truth=truth_rows,
        true_k=(float(robot['k1']), float(robot['k2']), float(robot['k3'])))
    meta = dict(meta, sonar_topics=topics, odometry_source=odometry_source,
                unmatched_sonar_cycles=len(unmatched))
    return inp, meta


def world_map(meta: Dict[str, Any], resolution: float = 0.1) -> GridMap:
    """Rasterise the world of a parsed ``ground_truth.yaml``."""
    if not meta.get('world'):
        raise ValueError('ground_truth.yaml has no world')
    return rasterize_world(World.from_dict(meta['world']), resolution)


def run_bag_localization(bag: Any, filter: str,  # noqa: A002 (name from the API spec)
                         map_path: Any = None, initial_pose: Any = None,
                         initial_cov: Any = None,
                         params: Optional[LocalizationParams] = None,
                         odometry_source: Optional[str] = None
                         ) -> Tuple[LocalizationInput, LocalizationRun, GridMap,
                                    LocalizationParams, Dict[str, Any]]:
    """Run the core filter over a bag (the engine of :func:`evaluate_localization`).

    Args:
        bag: simulator bag directory.
        filter: ``'ekf'`` or ``'ukf'``.
        map_path: map_server YAML; default: the rasterised world of ``ground_truth.yaml``.
        initial_pose: (3,) initial estimate (default: the true start pose).
        initial_cov: (3, 3) initial covariance (default ``diag(INITIAL_STD)^2``).
        params: filter parameters; default :class:`LocalizationParams`, with
            ``unknown='free'`` for a map file with unknown cells (a sonar-built map).
        odometry_source: see :func:`load_bag_input`.

    Returns:
        ``(input, run, grid, params, meta)``.
    """
    if filter not in FILTERS:
        raise ValueError(f"unknown filter {filter!r}; use 'ekf' or 'ukf'")
    inp, meta = load_bag_input(bag, odometry_source)
    grid, params = _map_and_params(meta, map_path, params)
    if initial_cov is None:
        initial_cov = np.diag(np.square(INITIAL_STD))
    run = localize(inp, filter, grid, initial_pose, initial_cov, params)
    return inp, run, grid, params, meta


def _map_and_params(meta: Dict[str, Any], map_path: Any,
                    params: Optional[LocalizationParams],
                    files: Optional[Mapping[str, Any]] = None,
                    settings: Optional[Mapping[str, Any]] = None
                    ) -> Tuple[GridMap, LocalizationParams]:
    """Return the evaluation map and the filter parameters for it (sets ``meta['map']``).

    Without ``params``: ``sonar_localizer``'s configuration of the defaults, ``files``,
    ``unknown: free`` when the map file has unknown cells (a sonar-built map), then
    ``settings`` (:func:`landmark_nav.localization.configuration.localizer_configuration`).
    """
    if map_path is None:
        grid = world_map(meta)
        meta['map'] = 'rasterised world of ground_truth.yaml (0.1 m)'
    else:
        if not Path(map_path).is_file():
            raise ValueError(f'no map file at {map_path}')
        grid = load_map_yaml(map_path)
        meta['map'] = str(map_path)
    if params is None:
        stated = {'unknown': 'free'} if map_path is not None and grid.unknown.any() else {}
        params = localizer_configuration({**(files or {}), **stated,
                                          **(settings or {})}).params
    return grid, params


# ---------------------------------------------------------------------- evaluation
def _with_degrees(err: Dict[str, float]) -> Dict[str, float]:
    out = dict(err)
    out['rms_heading_deg'] = math.degrees(err['rms_heading'])
    return out


def evaluate_localization(bag: Any, filter: str,  # noqa: A002 (name from the API spec)
                          map_path: Any = None, seed_for_initial: Optional[int] = None,
                          initial_std: Sequence[float] = INITIAL_STD,
                          out_dir: Any = None, odometry_source: Optional[str] = None,
                          files: Optional[Mapping[str, Any]] = None,
                          settings: Optional[Mapping[str, Any]] = None) -> Dict[str, Any]:
    """Evaluate sonar localization with the EKF or UKF on a simulator bag, offline.

    Args:
        bag: bag directory recorded by ``landmark_nav simulate`` (with ground_truth.yaml).
        filter: ``'ekf'`` or ``'ukf'``.
        map_path: map_server YAML (e.g. from :func:`build_sonar_map`); default: the
            world of ``ground_truth.yaml`` rasterised at 0.1 m.
        seed_for_initial: generator seed of the initial estimate drawn from
            N(truth, diag(initial_std)^2); default ``1000 + `` the bag's scenario seed
            (the core's hallway study).
        initial_std: standard deviations (x [m], y [m], heading [rad]) of the initial
            estimate; also the filter's initial covariance.
        out_dir: if given, write ``localization_<filter>.json``,
            ``localization_<filter>_trajectory.png`` and ``localization_<filter>_heading.png``.
        odometry_source: ``'joint_states'`` or ``'odom'`` (see :func:`load_bag_input`).
        files: ``sonar_localizer`` parameter values of parameter files: the filter's
            parameters and process noise (under the map's ``unknown: free``, see
            :func:`_map_and_params`).
        settings: Values over what the bag and the map state (``--set``): also the
            odometry's ``wheel_radius``, ``axle_length`` and ``k1``..``k3`` (default the
            bag's).

    Returns:
        The figures (also the JSON): ``filter``, ``odometry_calibrated`` and
        ``odometry_uncalibrated`` error dicts (max / RMS / end position [m] and heading
        [rad and deg]), ``end_error_ratio`` (odometry end error / filter end error),
        ``targets`` and ``within_targets``, the initial pose, the data used.

    Raises:
        BagError: missing or unreadable bag.
        ValueError: unknown filter, bag without sonar or ground truth, bad ``initial_std``.
    """
    if filter not in FILTERS:
        raise ValueError(f"unknown filter {filter!r}; use 'ekf' or 'ukf'")
    std = np.asarray(initial_std, dtype=float).reshape(-1)
    if std.shape != (3,) or not (np.isfinite(std).all() and (std > 0.0).all()):
        raise ValueError(f'initial_std must be three positive numbers, got {initial_std!r}')
    inp, meta = load_bag_input(bag, odometry_source)
    grid, params = _map_and_params(meta, map_path, None, files, settings)
    settings = settings or {}
    robot = {name: settings[name] for name in ('wheel_radius', 'axle_length')
             if name in settings}
    k = None
    if any(f'k{i}' in settings for i in (1, 2, 3)):
        stated = inp.true_k if inp.true_k is not None else (1.0, 1.0, 1.0)
        k = tuple(settings.get(f'k{i}', stated[i - 1]) for i in (1, 2, 3))
    seed = int(1000 + int(meta.get('seed', 0)) if seed_for_initial is None
               else seed_for_initial)
    cov0 = np.diag(std ** 2)
    x0 = draw_initial_pose(inp.truth[0], cov0, seed)
    run = localize(replace(inp, **robot), filter, grid, x0, cov0, params, k=k)
    truth = inp.truth
    i0 = first_motion_index(truth)
    odo_cal = odometry_trajectory(inp, truth[0], inp.true_k)
    odo_raw = odometry_trajectory(inp, truth[0])
    err = _with_degrees(localization_errors(run.trajectory, truth, i0))
    e_cal = _with_degrees(localization_errors(odo_cal, truth, i0))
    e_raw = _with_degrees(localization_errors(odo_raw, truth, i0))
    max_pos, max_head = TARGETS[filter]
    end = max(err['end_position'], 1e-12)
    result: Dict[str, Any] = {
        'bag': str(bag), 'scenario': meta.get('scenario'), 'seed': meta.get('seed'),
        'filter': filter, 'map': meta['map'], 'odometry_source': meta['odometry_source'],
        'calibration_k': list(inp.true_k),
        'cycles': int(inp.stamps_ns.size),
        'errors_from_index': int(i0), 'errors_from_time_s': float(i0 * inp.sample_time),
        'path_length': float(np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T))),
        'initial': {'seed': seed, 'std': std.tolist(), 'pose': x0.tolist(),
                    'true_pose': truth[0].tolist()},
        'mean_accepted_readings': float(run.accepted.sum(axis=1).mean()),
        'errors': {'filter': err, 'odometry_calibrated': e_cal,
                   'odometry_uncalibrated': e_raw},
        'end_error_ratio': {'odometry_calibrated': e_cal['end_position'] / end,
                            'odometry_uncalibrated': e_raw['end_position'] / end},
        'targets': {'max_position': max_pos, 'max_heading_deg': math.degrees(max_head)},
        'within_targets': bool(err['max_position'] <= max_pos
                               and err['max_heading'] <= max_head),
        'params': params.to_dict(),
    }
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        stem = out / f'localization_{filter}'
        files = {'json': str(stem) + '.json', 'trajectory_png': str(stem) + '_trajectory.png',
                 'heading_png': str(stem) + '_heading.png'}
        result['files'] = files
        _plot(inp, run.trajectory, odo_cal, odo_raw, grid, filter, files)
        Path(files['json']).write_text(json.dumps(result, indent=2) + '\n')
    return result


def _plot(inp: LocalizationInput, est: np.ndarray, odo_cal: np.ndarray, odo_raw: np.ndarray,
          grid: GridMap, filter: str, files: Dict[str, str]) -> None:  # noqa: A002
    """Trajectory with the map and heading vs time (the chapter's Figs. 16-17)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    name = filter.upper()
    truth = inp.truth
    fig, ax = plt.subplots(figsize=(12, 3.6), constrained_layout=True)
    rows, cols = np.nonzero(grid.occupied)
    if grid.origin[2] == 0.0:
        h, w = grid.shape
        ox, oy = grid.origin[:2]
        img = np.where(grid.occupied, 0.0, np.where(grid.unknown, 0.75, 1.0))
        ax.imshow(img, cmap='gray', vmin=0.0, vmax=1.0, origin='lower', interpolation='nearest',
                  extent=(ox, ox + w * grid.resolution, oy, oy + h * grid.resolution))
    else:
        pts = grid.cell_centers(rows, cols)
        ax.scatter(pts[:, 0], pts[:, 1], s=2, c='k', marker='s', label='map')
    ax.plot(truth[:, 0], truth[:, 1], 'k-', lw=1, label='ground truth', zorder=3)
    ax.plot(odo_cal[:, 0], odo_cal[:, 1], '-.', color='tab:orange', lw=1,
            label='odometry (calibrated)')
    ax.plot(odo_raw[:, 0], odo_raw[:, 1], ':', color='tab:red', lw=1,
            label='odometry (uncalibrated)')
    ax.plot(est[:, 0], est[:, 1], '.', color='tab:blue', ms=2.5, label=f'{name}')
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(f'Sonar localization with the {name}: trajectory')
    ax.legend(loc='upper center', ncol=4, fontsize=8, bbox_to_anchor=(0.5, -0.25))
    fig.savefig(files['trajectory_png'], dpi=110)
    plt.close(fig)

    t = (inp.stamps_ns - inp.stamps_ns[0]) * 1e-9
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True, constrained_layout=True)
    for traj, style, color, label in ((truth, '-', 'k', 'ground truth'),
                                      (odo_cal, '-.', 'tab:orange', 'odometry (calibrated)'),
                                      (odo_raw, ':', 'tab:red', 'odometry (uncalibrated)'),
                                      (est, '.', 'tab:blue', name)):
        kw = {'ms': 2.5} if style == '.' else {'lw': 1}
        ax1.plot(t, np.degrees(traj[:, 2]), style, color=color, label=label, **kw)
        if traj is not truth:
            ax2.plot(t, np.degrees(np.abs(wrap_angle(traj[:, 2] - truth[:, 2]))), style,
                     color=color, label=label, **kw)
    ax2.axhline(math.degrees(TARGETS[filter][1]), color='gray', lw=0.8, ls='--',
                label='target')
    ax1.set_ylabel('heading [deg]')
    ax1.set_title(f'Sonar localization with the {name}: heading')
    ax1.legend(fontsize=8)
    ax2.set_ylabel('|heading error| [deg]')
    ax2.set_xlabel('time [s]')
    ax2.legend(fontsize=8)
    fig.savefig(files['heading_png'], dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------- reports
def format_evaluation(result: Dict[str, Any]) -> str:
    """Return the figures of :func:`evaluate_localization` as a small text table."""
    name = result['filter'].upper()
    lines = [f'{result["bag"]}: {name}, map {result["map"]}, initial estimate seed '
             f'{result["initial"]["seed"]}; errors from t = {result["errors_from_time_s"]:.1f} s'
             f' ({result["path_length"]:.1f} m path)',
             f'{"method":26s} {"max pos":>8s} {"rms pos":>8s} {"end pos":>8s} '
             f'{"max hdg":>8s} {"rms hdg":>8s}']
    for key, label in (('filter', name), ('odometry_calibrated', 'odometry (calibrated)'),
                       ('odometry_uncalibrated', 'odometry (uncalibrated)')):
        e = result['errors'][key]
        lines.append(f'{label:26s} {e["max_position"]:7.3f}m {e["rms_position"]:7.3f}m '
                     f'{e["end_position"]:7.3f}m {e["max_heading_deg"]:6.2f}deg '
                     f'{e["rms_heading_deg"]:6.2f}deg')
    t = result['targets']
    ratio = result['end_error_ratio']
    lines.append(f'targets: max {t["max_position"]:.2f} m / {t["max_heading_deg"]:.1f} deg: '
                 f'{"met" if result["within_targets"] else "NOT met"}; end error '
                 f'{ratio["odometry_calibrated"]:.1f}x (calibrated) and '
                 f'{ratio["odometry_uncalibrated"]:.0f}x (uncalibrated) below odometry')
    for key in ('json', 'trajectory_png', 'heading_png'):
        if key in result.get('files', {}):
            lines.append(f'wrote {result["files"][key]}')
    return '\n'.join(lines)
