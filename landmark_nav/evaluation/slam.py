"""Run :class:`~landmark_nav.slam.ekf_slam.EkfSlam` on a scenario and score it against truth.

Pipeline (:mod:`.slam_run`): the scenario's odometry samples and scans go, in time order,
through :class:`~landmark_nav.slam.frontend.SlamFrontend`, the front end the ``ekf_slam``
node uses; each scan's features and geometry go with it to the filter.

The scenario is a simulated run (:func:`landmark_nav.sim.run_scenario`) or a bag
(:func:`landmark_nav.evaluation.bags.load_bag`: any bag with ``/scan``, ``/odom`` and a
reference); :func:`evaluate_bag` adds the aligned ATE and the RPE
(:mod:`landmark_nav.evaluation.trajectory`, evo's metrics), TUM files, ``slam.json`` and
the figures (``landmark_nav evaluate``).

Scores: :mod:`.slam_scores` (ATE, landmarks, wrong associations, NEES); figures:
:mod:`.slam_plots`. This module re-exports their public names.
"""

from dataclasses import asdict, fields, replace
import json
import math
from pathlib import Path
import time
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from landmark_nav.evaluation.bags import load_bag
from landmark_nav.evaluation.slam_plots import plot_run
from landmark_nav.evaluation.slam_run import (run_slam, scan_angles, scan_corners,
                                              scan_features, ScanFeatureCache, SlamRun)
from landmark_nav.evaluation.slam_scores import (ALIGN_DEFAULT, ellipse_share, RPE_DISTANCE_M,
                                                 score_run, SlamScore, true_visible_corners,
                                                 update_corrections)
from landmark_nav.evaluation.trajectory import (ALIGNMENTS, ate, rpe, STATISTICS, Trajectory,
                                                write_tum)
from landmark_nav.laser.corners import CornerParams
from landmark_nav.laser.lines import LineParams
from landmark_nav.sim import run_scenario, ScanSample
from landmark_nav.slam.configuration import (ODOMETRY_PARAMETERS, parameters,
                                             slam_configuration, SlamConfiguration)
from landmark_nav.slam.ekf_slam import OdometryNoise, SlamParams
from landmark_nav.slam.frontend import FrontendParams, odometry_noise_model
from landmark_nav.slam.slam_map import load_map, save_map, SlamMap
import numpy as np

ASSOCIATIONS = ('icnn', 'jcbb')
#: custom_data key of the importer's drift model (imported-bag contract).
DRIFT_KEY = 'landmark_nav.drift_model'


def evaluate(name: str, seeds: List[int], params: Optional[SlamParams] = None,
             corner_params: Optional[CornerParams] = None) -> List[SlamScore]:
    """Simulate, run and score a scenario for several seeds.

    Args:
        name: Scenario name (e.g. ``'office'``).
        seeds: Seeds.
        params: Filter parameters.
        corner_params: Corner extractor parameters.

    Returns:
        One score per seed.
    """
    out = []
    for seed in seeds:
        res = run_scenario(name, seed, sonar=None)
        out.append(score_run(res, run_slam(res, params, corner_params), params))
    return out


def _clean(v):
    return None if isinstance(v, float) and math.isnan(v) else v


def _path_length(poses: np.ndarray) -> float:
    return float(np.hypot(*np.diff(poses[:, :2], axis=0).T).sum()) if len(poses) > 1 else 0.0


def _add_figures_without_reference(result: dict, run: SlamRun, align: str,
                                   rpe_delta: float) -> None:
    """Fill ``result`` for a bag without a reference: error figures None, path figures."""
    for key in ('', 'odom_'):
        for k in STATISTICS + ('pairs', 'scale'):
            result[f'{key}ate_{align}_{k}'] = None
    result['rpe_distance_m'] = float(rpe_delta)
    for key in ('', 'odom_'):
        for k in STATISTICS:
            result[f'{key}rpe_trans_{k}'] = None
            result[f'{key}rpe_rot_{k}_deg'] = None
        result[f'{key}rpe_pairs'] = None
    result['ate_improvement'] = None
    d = run.poses - run.odometry
    dist = np.hypot(d[:, 0], d[:, 1])
    k = int(np.argmax(dist))
    result['path_length_m'] = _path_length(run.poses)
    result['odom_path_length_m'] = _path_length(run.odometry)
    result['max_slam_odom_difference_m'] = float(dist[k])
    result['max_slam_odom_difference_t_s'] = float((run.stamps[k] - run.stamps[0]) * 1e-9)
    result['max_slam_odom_heading_difference_deg'] = float(
        np.degrees(np.abs(np.angle(np.exp(1j * d[:, 2]))).max()))
    result['final_pose_covariance'] = run.covariances[-1].tolist()


def bag_odometry_noise(scenario) -> Tuple[OdometryNoise, str]:
    """Odometry noise model of a bag (:mod:`landmark_nav.slam.frontend`) and its source.

    The imported-bag contract's ``custom_data`` key ``landmark_nav.drift_model`` when present
    (the gains the importer drifted the odometry with), else ``simulator`` for a simulator
    recording, else ``pioneer``.

    Raises:
        ValueError: A malformed drift model (names the bag and the key).
    """
    text = getattr(scenario, 'custom_data', {}).get(DRIFT_KEY)
    if text is not None:
        try:
            return odometry_noise_model(text), f'custom_data {DRIFT_KEY}'
        except ValueError as err:
            raise ValueError(f'{scenario.name}: custom_data {DRIFT_KEY}: {err}') from None
    if getattr(scenario, 'simulator', True):
        return odometry_noise_model('simulator'), 'simulator'
    return odometry_noise_model('pioneer'), 'default pioneer'


#: ``ekf_slam`` parameters that take the laser's range noise ``laser_sigma_range`` when a
#: layer gives it (the bag's statement, ``--set``) and does not give them.
RANGE_NOISE_FOLLOWERS = ('lines.sigma_r',)
#: Extractor nodes whose ``sigma_r`` and ``sigma_phi`` take the laser's stated noise.
EXTRACTOR_NODES = ('corner_extractor', 'line_extractor')


def bag_slam_parameters(bag, sigma_r: Optional[float] = None,
                        laser_pose: Optional[Sequence[float]] = None) -> Dict[str, Any]:
    """Return the ``ekf_slam`` parameters a bag states (``pipeline replay``, ``evaluate``).

    The laser mount (``custom_data`` ``landmark_nav.laser_mount`` or the simulator's
    ``ground_truth.yaml``) as ``laser_pose``, its range noise as ``laser_sigma_range`` and
    ``lines.sigma_r`` and its bearing noise as ``lines.sigma_phi``, and ``odometry.model``:
    ``custom_data`` ``landmark_nav.drift_model``, ``simulator`` for a simulator
    recording, else nothing (the configuration's ``odometry.*``). Nothing for what the bag
    does not state; ``sigma_r`` (``evaluate --sigma-r``) stands for the range noise and
    ``laser_pose`` (``evaluate --laser-pose``) for the mount a bag does not state.

    Raises:
        BagError, ValueError: The bag cannot be read or states a malformed value.
    """
    from landmark_nav.bag import BagReader
    from landmark_nav.evaluation.bags import laser_config
    from landmark_nav.sim.record import GROUND_TRUTH_FILE, read_ground_truth_file
    with BagReader(bag) as reader:
        custom = reader.custom_data
    meta_path = Path(bag) / GROUND_TRUTH_FILE
    meta = read_ground_truth_file(meta_path) if meta_path.is_file() else None
    meta = meta if isinstance(meta, dict) else None
    laser, notes = laser_config(custom, meta, laser_pose, sigma_r)
    out: Dict[str, Any] = {}
    if not any('(default)' in n for n in notes):
        out['laser_pose'] = [float(v) for v in laser.mount]
    if not any('no laser range noise' in n for n in notes):  # lines and visibility
        out.update({'laser_sigma_range': float(laser.sigma_range),
                    'lines.sigma_r': float(laser.sigma_range),
                    'lines.sigma_phi': float(laser.sigma_angle)})
    model = custom.get(DRIFT_KEY) or ('simulator' if meta is not None else None)
    if model:
        out['odometry.model'] = str(model)
    return out


def _odometry_model_gains(model: str, source: str, settings: Mapping[str, Any],
                          notes: Optional[List[str]]) -> Dict[str, Any]:
    """Return ``odometry.model`` ``''`` and ``model``'s gains but those ``settings`` give.

    A non-empty ``odometry.model`` replaces the ``odometry.*`` values
    (:func:`landmark_nav.slam.configuration.slam_configuration`): a ``--set`` gain on top of
    a model a file or the bag gives takes that model's place for its own value, the model's
    other gains kept. Appends to ``notes`` one line naming what was replaced.
    """
    try:
        noise = odometry_noise_model(model)
    except ValueError as err:
        raise ValueError(f'{source} odometry.model: {err}') from None
    gains = {f'odometry.{name}': float(getattr(noise, name)) for name in ODOMETRY_PARAMETERS}
    given = [k for k in gains if k in settings]
    if notes is not None:
        notes.append('{} (--set) instead of {} of the odometry model {!r} ({}), its other '
                     'gains kept'.format(', '.join(f'{k} {settings[k]}' for k in given),
                                         ', '.join(f'{gains[k]:g}' for k in given),
                                         model, source))
    return {'odometry.model': '', **{k: v for k, v in gains.items() if k not in given}}


def run_parameters(bag, parameters: Optional[Mapping[str, Any]] = None,
                   settings: Optional[Mapping[str, Any]] = None,
                   sigma_r: Optional[float] = None,
                   laser_pose: Optional[Sequence[float]] = None,
                   notes: Optional[List[str]] = None) -> Dict[str, Dict[str, Any]]:
    """Return what each node of a run on a bag is given between its files and its ``--set``.

    The one place that decides what a bag states for ``landmark_nav evaluate`` and for the
    nodes of ``landmark_nav pipeline replay`` and ``replay.launch.py``: the laser mount, its
    noise, the odometry noise model. ``ekf_slam``'s layers, a later one winning: its
    ``parameters`` (the ``--params-file`` files, the profiles), what the bag states
    (:func:`bag_slam_parameters`), ``settings`` (``--set``); a layer that gives
    ``laser_sigma_range`` gives :data:`RANGE_NOISE_FOLLOWERS` the same value unless it gives
    them too. So ``--set`` wins over the bag, the bag over the files and the defaults. An
    odometry gain (``odometry.sigma_*``) in ``settings`` without ``odometry.model`` wins over
    the model the bag or a file states: ``ekf_slam`` gets ``odometry.model`` ``''`` and that
    model's other gains, and ``notes`` (a list) a line naming what the setting replaced.

    Returns:
        ``{'ekf_slam': values, 'corner_extractor': values, 'line_extractor': values}``:
        ``ekf_slam`` gets what the bag states and the followers of a ``laser_sigma_range``
        (``settings`` come after them); each extractor its ``sigma_r``, ``ekf_slam``'s
        resulting ``laser_sigma_range`` when a layer gives it, and its ``sigma_phi``, the
        bag's bearing noise when it states it (the node's own ``--set`` comes after them).

    Raises:
        BagError, ValueError: The bag cannot be read or states a malformed value.
    """
    layers = [dict(parameters or {}), bag_slam_parameters(bag, sigma_r, laser_pose),
              dict(settings or {})]
    values: Dict[str, Any] = {}
    for layer in layers:
        values.update({k: layer['laser_sigma_range'] for k in RANGE_NOISE_FOLLOWERS
                       if 'laser_sigma_range' in layer})
        values.update(layer)
    slam = dict(layers[1])
    if any('laser_sigma_range' in layer for layer in layers):
        slam.update({k: values[k] for k in RANGE_NOISE_FOLLOWERS if k not in layers[2]})
    extractor = {}
    if 'laser_sigma_range' in values:
        extractor['sigma_r'] = float(values['laser_sigma_range'])
    if 'lines.sigma_phi' in layers[1]:
        extractor['sigma_phi'] = float(layers[1]['lines.sigma_phi'])
    model = str(layers[1].get('odometry.model', layers[0].get('odometry.model', ''))).strip()
    if model and 'odometry.model' not in layers[2] and any(
            k.startswith('odometry.') for k in layers[2]):
        source = "the bag's" if 'odometry.model' in layers[1] else "the files'"
        slam.update(_odometry_model_gains(model, source, layers[2], notes))
    return {'ekf_slam': slam, **{node: dict(extractor) for node in EXTRACTOR_NODES}}


def bag_configuration(bag, parameters: Optional[Mapping[str, Any]] = None,
                      settings: Optional[Mapping[str, Any]] = None,
                      sigma_r: Optional[float] = None,
                      laser_pose: Optional[Sequence[float]] = None,
                      notes: Optional[List[str]] = None) -> SlamConfiguration:
    """Return the ``ekf_slam`` configuration of a run on a bag, layered as the node's.

    The shipped defaults, then ``parameters`` (e.g. the ``--params-file`` files), then what
    the bag states and the laser noise's followers (:func:`run_parameters`), then
    ``settings`` (``--set``): the order in which ``landmark_nav pipeline replay`` gives them
    to the node (its parameter file, the bag's statements, ``--set``). ``sigma_r`` and
    ``laser_pose``: the range noise and the mount when the bag states none (``evaluate
    --sigma-r``, ``--laser-pose``); ``notes``: :func:`run_parameters`'.

    Raises:
        ValueError: An unknown parameter, a bad value, an unreadable bag.
    """
    values = dict(parameters or {})
    values.update(run_parameters(bag, parameters, settings, sigma_r, laser_pose,
                                 notes)['ekf_slam'])
    values.update(settings or {})
    return slam_configuration(values)


def extractor_parameters(scenario, config: SlamConfiguration
                         ) -> Tuple[CornerParams, LineParams]:
    """Return the corner and line extractors' parameters of an offline run on a bag.

    As :func:`run_parameters` gives them to the replay's nodes: the corner extractor's
    range noise is ``config.laser_sigma_range`` (the bag's, unless ``--set`` gives it), its
    bearing noise the bag's (``scenario.laser``); the lines are ``config.line_params``.
    ``scenario.laser`` takes the same range noise (visibility, ``slam.json``) and the mount
    ``config.laser_pose`` (the front end's, as ``ekf_slam``'s), each with a note when it
    differs from the bag's.
    """
    mount = tuple(float(v) for v in config.laser_pose)
    if mount != tuple(float(v) for v in scenario.laser.mount):
        scenario.notes.append('laser mount {} (the parameter laser_pose) instead of {}'.format(
            *(' '.join(f'{v:g}' for v in m) for m in (mount, scenario.laser.mount))))
        scenario.laser = replace(scenario.laser, mount=mount)
    sigma = float(config.laser_sigma_range)
    if sigma != float(scenario.laser.sigma_range):
        scenario.notes.append(f'sigma_r {sigma:g} m (the parameter laser_sigma_range) instead '
                              f'of {float(scenario.laser.sigma_range):g} m')
        scenario.laser = replace(scenario.laser, sigma_range=sigma)
    return (CornerParams(sigma_r=sigma, sigma_phi=float(scenario.laser.sigma_angle)),
            config.line_params)


def _noise_source(bag, scenario, config: SlamConfiguration) -> str:
    """Where the configuration's odometry noise comes from (``slam.json``)."""
    model = config.values['odometry.model'].strip()
    stated = bag_slam_parameters(bag).get('odometry.model')
    if model and model == stated:
        return f'custom_data {DRIFT_KEY}' if DRIFT_KEY in scenario.custom_data else model
    if model:
        return f'odometry.model {model}'
    pioneer = all(config.values[k] == p.default for k, p in parameters().items()
                  if k.startswith('odometry.'))
    return 'default pioneer' if pioneer and not stated else 'odometry.*'


def evaluate_bag(bag, association: Optional[str] = None, out_dir=None, progress: bool = True,
                 params: Optional[SlamParams] = None, max_seconds: Optional[float] = None,
                 reference=None, align: str = ALIGN_DEFAULT,
                 laser_pose: Optional[Sequence[float]] = None, sigma_r: Optional[float] = None,
                 rpe_delta: float = RPE_DISTANCE_M, plots: bool = True,
                 landmarks: Optional[str] = None, slam_map=None, save_map_to=None,
                 map_pose_covariance: Optional[np.ndarray] = None,
                 mode: Optional[str] = None,
                 frontend: Optional[FrontendParams] = None,
                 config: Optional[SlamConfiguration] = None,
                 notes: Sequence[str] = ()) -> dict:
    """Run EKF-SLAM over a bag and score it against its reference.

    Any bag with ``/scan``, ``/odom`` and a reference (``/ground_truth/odom`` or
    ``reference``, a TUM file) will do (:func:`landmark_nav.evaluation.bags.load_bag`);
    the landmark scores need the simulator's ``ground_truth.yaml`` and are None without it.

    Figures (``slam.json``): the :class:`SlamScore` fields (``ate_rmse`` / ``ate_max``:
    unaligned, in the map frame, as the office table of docs/ekf_slam.md);
    ``ate_<align>_<stat>`` and
    ``odom_ate_<align>_<stat>`` with the chosen alignment; ``rpe_trans_<stat>``,
    ``rpe_rot_<stat>_deg``, ``rpe_pairs`` and the ``odom_`` equivalents over ``rpe_delta`` m
    (:mod:`landmark_nav.evaluation.trajectory`: evo's metrics); ``resets`` (filter resets
    after failed odometry checks); timing; the laser facts used and ``notes``.

    Args:
        bag: rosbag2 directory.
        association: ``'icnn'`` or ``'jcbb'`` (None: the configuration's).
        out_dir: Directory for the TUM files, ``slam.json`` and the PNGs (None: nothing
            written).
        progress: Show a tqdm progress bar.
        params: Filter parameters (default: the configuration's; ``association`` and
            ``mode`` win).
        max_seconds: Use only the first seconds of the bag.
        reference: TUM file of the reference (None: ``/ground_truth/odom``).
        align: ATE alignment, one of :data:`~landmark_nav.evaluation.trajectory.ALIGNMENTS`.
        laser_pose: ``(x, y, yaw)`` laser mount when the bag does not state it.
        sigma_r: Laser range noise [m] when the bag does not state it.
        rpe_delta: RPE distance [m].
        plots: Write the PNGs (with ``out_dir``).
        landmarks: ``'corners'``, ``'lines'`` or ``'both'`` (what the filter maps; None:
            the configuration's).
        slam_map: A saved map (path or :class:`~landmark_nav.slam.slam_map.SlamMap`) to
            start on (e.g. with ``params.mode == 'localization'``); the start pose is the
            first odometry pose, with ``map_pose_covariance`` (default zeros).
        save_map_to: Write the final map there (:func:`landmark_nav.slam.slam_map.save_map`).
        map_pose_covariance: (3, 3) covariance of the start pose on ``slam_map``.
        mode: ``'slam'`` or ``'localization'`` (on ``slam_map``); None: ``params.mode``.
        frontend: Front-end parameters (default: the configuration's; ``deskew`` and
            ``descriptors`` are :func:`run_slam`'s defaults whatever it says).
        config: The ``ekf_slam`` configuration (default: :func:`bag_configuration`, the
            shipped defaults with what the bag states); the run takes its ``laser_pose``
            and the corner extractor its ``laser_sigma_range`` (:func:`extractor_parameters`).
        notes: Notes of the configuration (:func:`bag_configuration`'s ``notes``), first in
            the run's.

    Returns:
        The figures (see ``slam.json``).

    Raises:
        ValueError: Bad option or unusable bag (one-line message).
    """
    if association is not None and association not in ASSOCIATIONS:
        raise ValueError(f'association must be one of {", ".join(ASSOCIATIONS)}, '
                         f'got {association!r}')
    if align not in ALIGNMENTS:
        raise ValueError(f'align must be one of {", ".join(ALIGNMENTS)}, got {align!r}')
    scenario = load_bag(bag, max_seconds, reference, laser_pose, sigma_r,
                        require_reference=False)
    scenario.notes[:0] = notes
    cfg = config or bag_configuration(bag, sigma_r=sigma_r, laser_pose=laser_pose)
    noise_source = 'params' if params is not None else _noise_source(bag, scenario, cfg)
    prm = params or cfg.params
    association = association or prm.association
    prm = SlamParams(**{**{f.name: getattr(prm, f.name) for f in fields(SlamParams)},
                        'association': association, 'mode': mode or prm.mode})
    if prm.mode == 'localization' and slam_map is None:
        raise ValueError('mode localization needs a map (slam_map: a file saved with '
                         'save_map_to / --save-map)')
    if noise_source == 'default pioneer':
        scenario.notes.append('no odometry noise model in the bag (custom_data '
                              f'{DRIFT_KEY}): using the pioneer model')
    landmarks = landmarks or cfg.landmarks
    frontend = frontend or cfg.frontend
    corner_params, line_params = extractor_parameters(scenario, cfg)
    n_scans = len(scenario.of_type(ScanSample))
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n_scans, unit='scan', desc=f'{Path(bag).name} {association}')
    callback = None if bar is None else (lambda k, slam, res: bar.update(1))
    tic, cpu_tic = time.perf_counter(), time.process_time()
    try:
        if slam_map is not None and not isinstance(slam_map, SlamMap):
            slam_map = load_map(slam_map)
        run = run_slam(scenario, prm, corner_params, callback=callback, landmarks=landmarks,
                       slam_map=slam_map, map_pose_covariance=map_pose_covariance,
                       frontend=frontend, line_params=line_params,
                       visibility=cfg.visibility)
    finally:
        if bar is not None:
            bar.close()
    wall, cpu = time.perf_counter() - tic, time.process_time() - cpu_tic
    score = score_run(scenario, run, prm)
    duration = (run.stamps[-1] - run.stamps[0]) * 1e-9 + scenario.scan_period
    result = {'bag': str(bag), 'association': association, 'scans': int(len(run.stamps)),
              'duration_s': float(duration), 'resets': int(run.resets),
              'reset_reasons': dict(run.reset_reasons),
              'frontend_events': dict(run.events),
              'motions': dict(run.motions),
              'icp_restarts': dict(run.icp_restarts),
              'keyframes': dict(run.keyframes),
              'odometry_noise': {**asdict(prm.odometry), 'source': noise_source},
              'reference': scenario.reference, 'simulator_truth': scenario.world is not None,
              'laser_mount': [float(v) for v in scenario.laser.mount],
              'laser_sigma_range': float(scenario.laser.sigma_range),
              'landmarks': landmarks, 'mode': prm.mode}
    result.update({k: _clean(v) for k, v in asdict(score).items()})
    result['lines_mapped'] = int(run.lines.shape[0])
    if scenario.has_reference:
        result['ellipse95_share'] = ellipse_share(run)
    if save_map_to is not None and run.final_map is not None:
        result['map_file'] = str(save_map(save_map_to, run.final_map))
    est = {'': Trajectory.from_planar(run.stamps, run.poses),
           'odom_': Trajectory.from_planar(run.stamps, run.odometry)}
    result['align'] = align
    if scenario.has_reference:
        ref = Trajectory.from_planar(run.stamps, run.truth)
        for key, traj in est.items():
            for k, v in ate(traj, ref, align).items():
                result[f'{key}ate_{align}_{k}'] = v
        result['rpe_distance_m'] = float(rpe_delta)
        for key, traj in est.items():
            r = rpe(traj, ref, rpe_delta)
            for k, v in r.items():
                name = k if k.startswith('rot_') or k == 'pairs' else f'trans_{k}'
                result[f'{key}rpe_{name}'] = _clean(v)
        result['ate_improvement'] = (score.odom_ate_rmse / score.ate_rmse
                                     if score.ate_rmse > 0 else None)
    else:
        _add_figures_without_reference(result, run, align, rpe_delta)
    result['seconds_total'] = float(wall)
    result['ms_per_step_total'] = 1e3 * wall / max(len(run.stamps), 1)
    # CPU time of this process (features, front end, filter): on a loaded machine the wall
    # time measures the load as much as the work.
    result['cpu_ms_per_step_total'] = 1e3 * cpu / max(len(run.stamps), 1)
    result['real_time_factor'] = float(duration / wall) if wall > 0 else None
    result['filter_real_time_factor'] = (float(duration / run.seconds) if run.seconds > 0
                                         else None)
    result['stats'] = {k: int(v) for k, v in run.stats.items()}
    result['notes'] = list(scenario.notes)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_tum(out / 'trajectory_slam.tum', est[''])
        write_tum(out / 'trajectory_odom.tum', est['odom_'])
        if scenario.has_reference:
            write_tum(out / 'trajectory_gt.tum', ref)
        (out / 'slam.json').write_text(json.dumps(result, indent=2))
        if plots and not scenario.has_reference:
            plot_run(scenario, run, out, f'EKF-SLAM ({association}) on {Path(bag).name}\n'
                     f'{score.mapped} landmarks, {run.resets} resets (no reference)', align)
        elif plots:
            plot_run(scenario, run, out, f'EKF-SLAM ({association}) on {Path(bag).name}\nATE '
                     f'{100 * score.ate_rmse:.1f} cm ({align} aligned '
                     f'{100 * result[f"ate_{align}_rmse"]:.1f} cm), odometry '
                     f'{100 * score.odom_ate_rmse:.1f} cm, {run.resets} resets', align)
    return result


def _lines_without_reference(r: dict) -> List[str]:
    """Render the summary lines of a run without a reference (what needs none)."""
    sd = np.sqrt(np.maximum(np.diag(np.asarray(r['final_pose_covariance'])), 0.0))
    rtf = r['real_time_factor']
    return [
        'note: no reference trajectory: ATE, RPE and NEES need one (--reference FILE.tum or '
        '/ground_truth/odom in the bag); judge the map in slam_map.png',
        f'landmarks: {r["mapped"]} mapped; associations {r["associations"]}',
        f'path length: EKF-SLAM {r["path_length_m"]:.2f} m, odometry '
        f'{r["odom_path_length_m"]:.2f} m; largest EKF-SLAM vs odometry difference '
        f'{r["max_slam_odom_difference_m"]:.3f} m (at {r["max_slam_odom_difference_t_s"]:.1f} '
        f's), heading {r["max_slam_odom_heading_difference_deg"]:.2f} deg',
        f'final pose 1 sigma: x {100 * sd[0]:.2f} cm, y {100 * sd[1]:.2f} cm, psi '
        f'{np.degrees(sd[2]):.3f} deg (covariance in slam.json)',
        f'filter {r["ms_per_scan"]:.2f} ms/step, total {r["ms_per_step_total"]:.2f} ms/step, '
        f'real-time factor {"n/a" if rtf is None else f"{rtf:.0f}"}x']


def format_summary(r: dict) -> str:
    """Render the main figures as a few lines of text."""
    def cm(v):
        return 'n/a' if v is None else f'{100 * v:.2f} cm'

    def num(v, fmt='{}'):
        return 'n/a' if v is None else fmt.format(v)
    a = r['align']
    why = ', '.join(f'{k}: {v}' for k, v in sorted(r.get('reset_reasons', {}).items()))
    events = ', '.join(f'{v} {k}' for k, v in sorted(r.get('frontend_events', {}).items()))
    lines = [f'{r["bag"]} ({r["association"]}): {r["scans"]} scans, {r["duration_s"]:.1f} s, '
             f'reference {r["reference"] or "none"}, {r["resets"]} filter resets'
             + (f' ({why})' if why else '')
             + (f'; inputs not used as they came: {events}' if events else '')]
    motions = r.get('motions', {})
    if motions.get('scan_matching'):
        restarts = r.get('icp_restarts', {})
        lines.append(f'motion: {motions["scan_matching"]} steps scan-matched, '
                     f'{motions.get("odometry", 0)} odometry (ICP restarted from other '
                     f'headings on {restarts.get("restarted", 0)} steps, usable after '
                     f'{restarts.get("recovered", 0)})')
    keyframes = r.get('keyframes', {})
    if keyframes.get('skipped'):
        lines.append(f'keyframes: {keyframes["keyframes"]} steps updated the map, '
                     f'{keyframes["skipped"]} between keyframes (pose from the odometry)')
    lines += [f'note: {n}' for n in r.get('notes', [])]
    if r['reference'] is None:
        return '\n'.join(lines + _lines_without_reference(r))
    lines += [
        f'ATE RMSE {cm(r["ate_rmse"])} (max {cm(r["ate_max"])}); odometry '
        f'{cm(r["odom_ate_rmse"])} (max {cm(r["odom_ate_max"])})',
        f'ATE {a} aligned: RMSE {cm(r[f"ate_{a}_rmse"])} (mean {cm(r[f"ate_{a}_mean"])}, '
        f'median {cm(r[f"ate_{a}_median"])}, max {cm(r[f"ate_{a}_max"])}); odometry RMSE '
        f'{cm(r[f"odom_ate_{a}_rmse"])}',
        f'RPE over {r["rpe_distance_m"]:g} m ({r["rpe_pairs"]} pairs): '
        f'{cm(r["rpe_trans_rmse"])} / {num(r["rpe_rot_rmse_deg"], "{:.2f}")} deg (odometry '
        f'{cm(r["odom_rpe_trans_rmse"])} / {num(r["odom_rpe_rot_rmse_deg"], "{:.2f}")} deg)']
    if r['true_visible'] is not None:
        lines.append(
            f'landmarks: {r["mapped"]} mapped / {r["true_visible"]} true visible, RMSE '
            f'{cm(r["landmark_rmse"])}, ghosts {r["ghost_landmarks"]}, duplicates '
            f'{r["duplicates"]}')
        lines.append(f'associations {r["associations"]}, wrong {r["wrong_associations"]}; '
                     f'NEES in 95 % band {100 * r["nees_share_band"]:.1f} %')
    else:
        lines.append(f'landmarks: {r["mapped"]} mapped (no true corners: not a simulator bag); '
                     f'associations {r["associations"]}; NEES against the reference in the '
                     f'95 % band {100 * r["nees_share_band"]:.1f} %')
    if r.get('lines_mapped') or r.get('landmarks', 'corners') != 'corners':
        share = r.get('ellipse95_share')
        lines.append(f'landmark types {r.get("landmarks")}: {r["mapped"]} corners, '
                     f'{r.get("lines_mapped", 0)} lines; reference inside the 95 % position '
                     f'ellipse {"n/a" if share is None else f"{100 * share:.1f} %"} of steps')
    lines.append(f'filter {r["ms_per_scan"]:.2f} ms/step, total {r["ms_per_step_total"]:.2f} '
                 f'ms/step (CPU {r["cpu_ms_per_step_total"]:.2f} ms/step), real-time factor '
                 f'{num(r["real_time_factor"], "{:.0f}")}x')
    return '\n'.join(lines)


__all__ = ['ALIGN_DEFAULT', 'ASSOCIATIONS', 'bag_configuration', 'bag_odometry_noise',
           'bag_slam_parameters', 'DRIFT_KEY', 'ellipse_share', 'extractor_parameters',
           'evaluate', 'evaluate_bag', 'format_summary', 'plot_run', 'RPE_DISTANCE_M',
           'run_parameters', 'run_slam', 'scan_angles', 'scan_corners', 'scan_features',
           'ScanFeatureCache', 'score_run', 'SlamRun', 'SlamScore', 'true_visible_corners',
           'update_corrections']
