"""EKF-SLAM on real logs: the Carmen logs with synthetic drift, and the CMU Wean logs.

Run from the repository root (needs ``../shared/data/carmen`` and ``../shared/data/wean``,
or ``--data DIR``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_slam_real.py evaluate [--landmarks corners
        lines both] [--association icnn] [--prune-misses N] [--seed S ...]
        [--line-floor M] [--line-residual-factor K] [--reject-ambiguous]
        [--position-floor M] [--jacobians J] [--joint-probability P]
        [--out DIR] [--data DIR] [LOG ...]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_slam_real.py diagnose [--landmarks both]
        [--seed 0] [--drift MODEL] [--filter-noise MODEL] [filter options, see --help]
        [--data DIR] [LOG ...]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_slam_real.py grid [--seeds 0 1]
        [--params-file YAML] [--set NAME=VALUE ...] [--landmarks corners|lines|both]
        [--procs 2] [--cache DIR] [--backend graph] [--data DIR] [LOG ...]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_slam_real.py scan-matching [--seeds 0 1]
        [--drift none] [--slam [--params-file YAML] [--filter-noise MODEL]
        [--landmarks KIND]] [--data DIR] [LOG ...]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_slam_real.py defaults
        [--params-file YAML ...] [--data DIR] [LOG ...]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_slam_real.py wean [--landmarks both]
        [--establish-hits N] [--odometry-scale S] [--set NAME=VALUE ...] [--data DIR]
        [--corners] [--plot DIR] [--backend graph [--cell-alignment]] [LOG ...]

A Carmen LOG is a log name in ``--data DIR`` (default ``../shared/data/carmen``; ``aces``
-> ``DIR/aces-corrected.log.gz``; default the six logs) or a path to a Carmen log; a Wean
LOG a name in ``--data DIR`` (default ``../shared/data/wean``; ``robotdata1`` ->
``DIR/robotdata1.log.gz``, the map ``DIR/wean.dat.gz``) or a path to a Wean log.

``evaluate``:

Each log is imported with ``landmark_nav import`` defaults (``pioneer`` drift, seed 0;
``--seed``: one row per drift draw) and evaluated as ``landmark_nav evaluate BAG`` does
(:func:`landmark_nav.evaluation.slam.evaluate_bag`), the filter's odometry noise from the
bag's stated drift model; the other options set those :class:`SlamParams` fields.

Printed per log and landmark type: filter resets, corner and line landmarks at the end,
the SE(2)-aligned ATE RMSE of EKF-SLAM and of the odometry and their ratio (target
<= 0.2), the RPE over 1 m (translation RMSE) of both and their ratio (target <= 1), the
share of steps whose reference position lies inside the filter's 95 % position ellipse
(target >= 0.8), landmarks pruned, filter ms per scan.

``diagnose``:

Each log is imported as ``landmark_nav import`` does (synthetic ``pioneer`` drift, the given
seed) and run through :func:`landmark_nav.evaluation.slam.run_slam` with the bag's stated
odometry noise model. Isolation of the update side: ``--drift none`` imports the reference's
own increments as odometry (no drift) and ``--filter-noise pioneer`` (any model of
:func:`landmark_nav.slam.frontend.odometry_noise_model`) tells the filter that noise
instead of the bag's; with both, every error of the run comes from the updates. Printed per
log:

* ``odo_nees`` / ``odo_out``: mean and share above the chi-square 95 % bound of the
  odometry's 3-dof NEES over windows of 1 m of reference path, ``odo_nees10`` its mean over
  10 m (:func:`landmark_nav.evaluation.odometry_drift.odometry_window_nees`: the
  odometry's relative motion against the reference's, in the window's start frame, with the
  filter's ``U`` propagated along the window; 3 expected).
* ``line_m2``: median squared Mahalanobis distance (2 expected) of each line observation
  put in the map with the reference pose, from the mean of the observations associated with
  the same landmark (seen >= 5 times), under the covariance the filter gets
  (:func:`landmark_nav.slam.ekf_slam.line_noise_covariance`).
* ``nis95``: share of updates whose joint NIS exceeds its chi-square 95 % bound (0.05
  expected) and ``d2``: mean individual d2 of the accepted pairs (1.6 for a 95 % gate).
* ``nees_med``: median robot NEES (3 dof, unaligned), ``psi_err`` / ``psi_sd``: RMS heading
  error and median heading std of the filter [deg], ``ellipse95``: share of steps with the
  reference inside the 95 % position ellipse.
* ``rot_deg`` / ``ate_se2`` / ``ate_none``: the SE(2) fit's rotation [deg] and the position
  RMSE after it and without it [m]; ``jump5``: the share of the squared per-step error the
  worst 5 % of steps carry; ``rpe`` / ``odo_rpe`` / ``odo_se2``: as ``evaluate`` prints them.

``grid``:

Each log is imported as ``landmark_nav import`` does (synthetic ``pioneer`` drift, one draw
per seed) and run through ``diagnose`` (the filter of
:func:`landmark_nav.evaluation.slam.run_slam` with the bag's stated odometry noise). The
parameters are the ``ekf_slam`` defaults (read as the node reads its file,
``bench_node_cpu.params_file_options``) or ``--params-file``, with ``--set`` (Python
literals, e.g. ``--set association="'jcbb'"``) and ``--landmarks`` on top. Runs go to
``--procs`` processes; ``--cache`` keeps the imported bags between invocations.

Printed per run: the share of steps with the reference inside the 95 % position ellipse,
the SE(2)-aligned ATE of the filter and of the odometry [m] and their ratio, the RPE over
1 m of both [cm] and their ratio, the RMS heading error [deg], and the updates that moved
the pose by more than 20 cm (:func:`landmark_nav.evaluation.slam.update_corrections`: a
loop closed moves it by the drift since the landmark was last seen): their count and
``sqrt(sum of their squares / steps)``, what they alone put into an RPE over one step
(the steps of these logs are about 1 m) [cm], and the ellipse share again with the
reference's own per-pose noise added (``REFERENCE_SD``; the first share takes the
reference as truth: this one tells a filter that misjudges its own error from one the
reference's noise pushes out). Then the summary used in the README: ellipse median (runs
>= 80 %), ATE / odometry median (runs <= 0.2), RPE / odometry median (runs <= 1), runs
meeting all three targets, and the median (runs >= 80 %) of the second ellipse share.
``--backend graph``: the graph back end against its targets (``slam_real_graph.py``).

``scan-matching``:

A yardstick for EKF-SLAM: each log (imported with the given drift seed) has its scans
chained by point-to-line ICP (:func:`landmark_nav.slam.scan_matching.base_motion`), each
onto the previous one from the odometry's motion; the ICP motion is used when it converged
inside the odometry's 99.9 % region under the bag's noise model, else the odometry's. No
landmarks, no loop closure: what pairwise scan matching alone removes of the drift
(``--drift none``: the reference's own increments as odometry). Printed per run: ATE
(SE(2)-aligned) and RPE over 1 m of the odometry and of the chain, the share of steps that
used ICP, median heading errors and the NIS of the ICP's errors under its own covariance.
``--slam`` also runs EKF-SLAM on the bag's odometry and on the chain (its poses as odometry,
``--filter-noise`` as ``U``): ATE, RPE and the 95 % ellipse share of each.

``wean``:

Each log (default ``robotdata1 robotdata2 robotdata5``) is imported with ``landmark_nav
import`` defaults (raw odometry) into a temporary directory and run as the test
``test_evaluate_imported_wean_log_without_reference`` does (the bag's stated odometry
noise, the laser's stated noise); :func:`landmark_nav.evaluation.occupancy_check.check_run`
aligns the result to ``wean.dat`` and :func:`~landmark_nav.evaluation.occupancy_check.
landmark_diagnosis` says why each corner landmark is off the walls. Printed per log:
corner landmarks, the share within 10 cm of a wall cell (target >= 0.9), poses in
wall / unknown cells (target 0), the share of scan end points near a wall with the filter's
and with the odometry's poses, and the count per category (``on_wall``, ``moved``,
``few_views``, ``off_grid``), and for the poses in wall cells
(:func:`~landmark_nav.evaluation.occupancy_check.wall_pose_diagnosis`) the deepest such
cell's depth into its wall region [m] (0.1: all at the region's edge), the median number
of the log's scans that see through those cells, and the same median over every wall cell
any scan sees through (a cell that many of the log's scans see through was free in this
run: the grid holds something that was not there), and the poses in wall cells beyond one
cell of tolerance in cells no scan sees through (``wall_poses_counted``; the target is 0).
``--establish-hits`` sets ``SlamParams.establish_hits``; ``--odometry-scale S`` multiplies
the raw odometry's translations by S before the filter (is the odometry's scale wrong? the
grid says which scale fits). ``--set NAME=VALUE`` (repeatable) any other field of
``SlamParams`` or ``FrontendParams`` (the value read as a Python literal, e.g. ``--set
jacobians="'observability_gain'" --set spurious_limit=0.05 --set scan_matching=True``).
``--backend graph``: the graph back end, its structural corners and poses (``slam_real_graph.py``).
``--corners`` also places every scan's corners with the filter's path
(:func:`~landmark_nav.evaluation.occupancy_check.corner_wall_check`): the share of
structural and other corners within 10 cm of a wall cell, the structural ones split into
convex and concave, and the distance to a wall cell of the structural ones off the walls
(10 / 50 / 90 %), and of the structural corners neither ``Corner.occluded`` nor
``Corner.silhouette``; ``--plot DIR`` draws them over the grid.
A log that holds several runs (the import summary's ``runs``: ``robotdata5``, whose clock
restarts where the robot is elsewhere) is imported and run one run at a time (``name/runK``,
``landmark_nav import --run K``). A log whose odometry the front end had to bridge gets one
more line per part (``name#k``, :func:`~landmark_nav.evaluation.occupancy_check.run_segments`:
each part aligned on its own).
"""

from collections import Counter
from dataclasses import replace
import json
import math
from multiprocessing import Pool
import os
from pathlib import Path
import sys
import tempfile

from bench_node_cpu import params_file_options, split_frontend
from common import (add_logs_argument, CARMEN_LOGS, data_folder, log_paths, parse_set,
                    run_subcommand, subcommand_parser)
from landmark_nav.evaluation.bags import load_bag
from landmark_nav.evaluation.occupancy_check import (check_run,
                                                     landmark_diagnosis, load_occupancy_grid,
                                                     run_segments, wall_pose_diagnosis,
                                                     wall_poses_counted)
from landmark_nav.evaluation.odometry_drift import odometry_window_nees
from landmark_nav.evaluation.slam import (bag_odometry_noise, ellipse_share, evaluate_bag,
                                          run_slam, scan_features, update_corrections)
from landmark_nav.evaluation.slam_graph import evaluate_graph_bag
from landmark_nav.evaluation.trajectory import ate, planar_alignment, rpe, Trajectory
from landmark_nav.geometry import compose, interpolate_pose, inverse, relative, wrap_angle
from landmark_nav.importers.writer import import_log
from landmark_nav.laser.corners import CornerParams
from landmark_nav.laser.lines import LineParams
from landmark_nav.sim import OdometrySample, ScanSample
from landmark_nav.slam.consistency import chi2_gate
from landmark_nav.slam.ekf_slam import (ASSOCIATION_METHODS, JACOBIANS, LINE,
                                        line_noise_covariance, odometry_noise, SlamParams)
from landmark_nav.slam.frontend import FrontendParams, odometry_noise_model
from landmark_nav.slam.line_landmarks import line_initialization, lines_to_observations
from landmark_nav.slam.scan_matching import base_motion, scan_points
import numpy as np
from slam_real_graph import corners_on_walls, graph_backend, graph_grid, wean_graph

WEAN_LOGS = ('robotdata1', 'robotdata2', 'robotdata5')


# The reference poses' own per-pose std along / across their heading [m], measured from the
# scans by ICP over triples of consecutive scans (README, EKF-SLAM, "Reference noise"):
# ``ellipse95_ref`` adds them to the filter's covariance.
REFERENCE_SD = {'aces': (0.0181, 0.0061), 'seattle': (0.0118, 0.0072),
                'fhw': (0.0204, 0.0120), 'freiburg-101': (0.0136, 0.0174),
                'belgioioso': (0.0095, 0.0095), 'acapulco': (0.0242, 0.0230)}


def log_name(bag: Path) -> str:
    """Return the Carmen log a bag was imported from (``aces-3`` -> ``aces``), or ''."""
    name = Path(bag).name
    return next((g for g in CARMEN_LOGS if name == g or name.startswith(g + '-')), '')


JUMP_M = 0.2  # an update that moves the pose further is counted as a jump (a loop closed)


def _wrap(a):
    return np.mod(np.asarray(a) + math.pi, 2.0 * math.pi) - math.pi


def odometry_nees(scenario, noise, horizon: float = 1.0) -> np.ndarray:
    """3-dof NEES of the odometry over windows of ``horizon`` m of reference path."""
    odo = [e for e in scenario.events if isinstance(e, OdometrySample)]
    t = np.array([e.stamp_ns for e in odo], dtype=np.int64)
    pose = np.array([e.pose for e in odo])
    return odometry_window_nees(scenario.truth_at(t), pose,
                                lambda u: odometry_noise(u, noise), horizon)


def diagnose(bag: Path, landmarks: str, extra: dict, filter_noise=None) -> dict:
    """Run the filter on one bag and return the figures of the module docstring."""
    scenario = load_bag(bag, require_reference=False)
    noise = filter_noise or bag_odometry_noise(scenario)[0]
    extra, frontend = split_frontend(extra)
    prm = replace(SlamParams(**extra), odometry=noise)
    cp = CornerParams(sigma_r=float(scenario.laser.sigma_range),
                      sigma_phi=float(scenario.laser.sigma_angle))
    lp = LineParams(sigma_r=cp.sigma_r, sigma_phi=cp.sigma_phi)
    mount = np.asarray(scenario.laser.mount, dtype=float)
    scans = scenario.of_type(ScanSample)
    groups, nis, d2 = {}, [], []

    def callback(k, slam, res):
        if res.nis_dof:
            nis.append(res.nis > chi2_gate(res.nis_dof, 0.95))
        d2.extend(res.d2[res.status == 'matched'].tolist())
        if landmarks == 'corners':
            return
        corners, lines = scan_features(scans[k], landmarks, cp, lp)
        if not lines:
            return
        obs = lines_to_observations(lines, mount, None, lp.sigma_r)
        ref = scenario.truth_at(np.array([scans[k].stamp_ns]))[0]
        g, _, gz = line_initialization(ref, obs.z)
        r_eff = obs.r + line_noise_covariance(prm, obs.z, obs.ends, obs.residual_std)
        cov = gz @ r_eff @ np.transpose(gz, (0, 2, 1))
        ids = res.landmark_id[len(corners):]
        for q in np.flatnonzero((res.status[len(corners):] == 'matched')
                                & (res.kind[len(corners):] == LINE)):
            groups.setdefault(int(ids[q]), []).append((g[q], cov[q]))

    run = run_slam(scenario, prm, cp, callback=callback, landmarks=landmarks,
                   frontend=frontend)
    m2 = []
    for obs in groups.values():
        if len(obs) < 5:
            continue
        g = np.array([o[0] for o in obs])
        g[:, 1] = g[0, 1] + _wrap(g[:, 1] - g[0, 1])
        mean = g.mean(axis=0)
        f = len(g) / (len(g) - 1.0)
        m2 += [f * (v - mean) @ np.linalg.solve(c, v - mean) for v, (_, c) in zip(g, obs)]
    odo = odometry_nees(scenario, noise)
    err = run.poses - run.truth
    err[:, 2] = _wrap(err[:, 2])
    nees = np.einsum('ki,ki->k', err, np.linalg.solve(
        run.covariances + 1e-12 * np.eye(3), err[:, :, None])[:, :, 0])
    step = np.array([np.hypot(*(relative(run.poses[k], run.poses[k + 1])[:2]
                                - relative(run.truth[k], run.truth[k + 1])[:2]))
                     for k in range(len(run.poses) - 1)])
    sq = np.sort(step ** 2)[::-1]
    odo10 = odometry_nees(scenario, noise, 10.0)
    rot, _, ate_se2 = planar_alignment(run.poses, run.truth)
    moved = np.hypot(*update_corrections(run)[:, :2].T)  # what each update moved the pose
    ref = Trajectory.from_planar(run.stamps, run.truth)
    est = Trajectory.from_planar(run.stamps, run.poses)
    odo_traj = Trajectory.from_planar(run.stamps, run.odometry)
    return {'odo_nees': float(odo.mean()), 'odo_out': float(np.mean(odo > chi2_gate(3, 0.95))),
            'odo_nees10': float(odo10.mean()) if odo10.size else math.nan,
            'line_m2': float(np.median(m2)) if m2 else math.nan,
            'nis95': float(np.mean(nis)) if nis else math.nan,
            'd2': float(np.mean(d2)) if d2 else math.nan,
            'nees_med': float(np.median(nees)),
            'psi_err': float(np.degrees(np.sqrt(np.mean(err[:, 2] ** 2)))),
            'psi_sd': float(np.degrees(np.median(np.sqrt(run.covariances[:, 2, 2])))),
            'ellipse95': ellipse_share(run),
            'ellipse95_ref': (ellipse_share(run, reference_sd=REFERENCE_SD[log_name(bag)])
                              if log_name(bag) in REFERENCE_SD else math.nan),
            'rot_deg': math.degrees(rot), 'ate_se2': ate_se2,
            'ate_none': float(np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1)))),
            'jump5': float(sq[:max(1, len(sq) // 20)].sum() / sq.sum()),
            'rpe': rpe(est, ref, 1.0)['rmse'], 'odo_rpe': rpe(odo_traj, ref, 1.0)['rmse'],
            'jumps': int(np.sum(moved > JUMP_M)),
            'jump_rms': float(np.sqrt(np.sum(moved[moved > JUMP_M] ** 2)
                                      / max(1, len(moved) - 1))),
            'odo_se2': ate(odo_traj, ref, 'se2')['rmse']}


def run_one(job: tuple) -> tuple:
    """Import one log with one drift seed (unless cached) and diagnose it (or run the graph)."""
    name, path, seed, options, cache = job
    bag = Path(cache) / f'{name}-{seed}'
    if not (bag / 'metadata.yaml').is_file():
        import_log(path, bag, seed=seed, force=True)
    options = dict(options)
    if options.pop('backend', 'ekf') == 'graph':
        sd = REFERENCE_SD.get(log_name(bag))
        return name, seed, dict(evaluate_graph_bag(bag, reference_sd=sd), reference_sd=sd)
    landmarks = options.pop('landmarks', 'both')
    return name, seed, diagnose(bag, landmarks, options)


def summary(results: list) -> str:
    """Return the summary line of the module docstring."""
    el = np.array([r['ellipse95'] for _, _, r in results])
    at = np.array([r['ate_se2'] / r['odo_se2'] for _, _, r in results])
    rp = np.array([r['rpe'] / r['odo_rpe'] for _, _, r in results])
    er = np.array([r['ellipse95_ref'] for _, _, r in results])
    met = (el >= 0.8) & (at <= 0.2) & (rp <= 1.0)
    return (f'{len(results)} runs: ellipse median {100 * np.median(el):.1f} % '
            f'({int(np.sum(el >= 0.8))}), ATE / odometry {np.median(at):.2f} '
            f'({int(np.sum(at <= 0.2))}), RPE / odometry {np.median(rp):.2f} '
            f'({int(np.sum(rp <= 1.0))}), all three {int(np.sum(met))}; with the '
            f'reference noise in the ellipse {100 * np.median(er):.1f} % '
            f'({int(np.sum(er >= 0.8))})')


MAX_RANGE = FrontendParams().scan_matching_max_range   # [m] returns used by the ICP
ACCEPT = chi2_gate(3, 0.999)


def laser_points(scan: ScanSample) -> np.ndarray:
    """Return the scan's valid returns within MAX_RANGE as (N, 2) laser-frame points."""
    return scan_points(scan.ranges, scan.angle_min, scan.angle_increment, scan.range_min,
                       min(MAX_RANGE, scan.range_max))


def chain(scenario) -> tuple:
    """Dead-reckon an imported bag by odometry and by ICP: the figures, stamps, ICP poses."""
    noise = bag_odometry_noise(scenario)[0]
    if noise == odometry_noise_model('k_d=0 k_theta=0 k_dtheta=0'):
        noise = odometry_noise_model('pioneer')  # --drift none: gate with the default model
    mount = np.asarray(scenario.laser.mount, dtype=float)
    unmount = inverse(mount)
    scans = scenario.of_type(ScanSample)
    odo = scenario.of_type(OdometrySample)
    stamps = np.array([s.stamp_ns for s in scans], dtype=np.int64)
    odometry = interpolate_pose(stamps.astype(float),
                                np.array([o.stamp_ns for o in odo], dtype=float),
                                np.array([o.pose for o in odo]), extrapolate=True)
    truth = scenario.truth_at(stamps)
    poses = [odometry[0]]
    used, yaw_odo, yaw_icp, nis, pairs = 0, [], [], [], []
    previous = laser_points(scans[0])
    for k in range(1, len(scans)):
        u = relative(odometry[k - 1], odometry[k])
        current = laser_points(scans[k])
        # The front end's ICP (the laser's motion M^-1 u M as the guess), gated here on the
        # odometry's region alone (the yardstick as first measured).
        found = base_motion(previous, current, u, mount)
        step = u
        if found is not None:
            v, fit = found
            d = v - u
            d[2] = wrap_angle(d[2])
            if d @ np.linalg.solve(odometry_noise(u, noise), d) <= ACCEPT:
                step, used = v, used + 1
                ref = relative(truth[k - 1], truth[k])
                e = compose(compose(unmount, ref), mount)  # the laser's true motion
                e = fit.pose - e
                e[2] = wrap_angle(e[2])
                nis.append(e @ np.linalg.solve(fit.covariance, e))
                pairs.append(fit.matches)
                yaw_icp.append(abs(wrap_angle(v[2] - ref[2])))
                yaw_odo.append(abs(wrap_angle(u[2] - ref[2])))
        poses.append(compose(poses[-1], step))
        previous = current
    ref = Trajectory.from_planar(stamps, truth)
    out = {}
    for name, track in (('odo', odometry), ('icp', np.array(poses))):
        est = Trajectory.from_planar(stamps, track)
        out[f'{name}_ate'] = ate(est, ref, 'se2')['rmse']
        out[f'{name}_rpe'] = rpe(est, ref, 1.0)['rmse']
    out.update(used=used / max(1, len(scans) - 1),
               yaw_odo=math.degrees(np.median(yaw_odo)) if yaw_odo else math.nan,
               yaw_icp=math.degrees(np.median(yaw_icp)) if yaw_icp else math.nan,
               nis=float(np.median(nis)) if nis else math.nan,
               pairs=float(np.median(pairs)) if pairs else math.nan,
               nis_per_pair=float(np.median(np.array(nis) / np.array(pairs)))
               if nis else math.nan)
    return out, stamps, np.array(poses)


def slam_figures(scenario, options: dict, noise=None) -> tuple:
    """Run EKF-SLAM on the scenario; return its SE(2)-aligned ATE [m], RPE over 1 m [m], ellipse.

    The ellipse figure is the share of steps with the reference inside the 95 % position
    ellipse (:func:`landmark_nav.evaluation.slam.ellipse_share`).

    With ``noise`` (the filter on the scan-matched chain) the front end's own scan matching
    is off whatever ``options`` say: the chain is already scan-matched.
    """
    options, frontend = split_frontend(options)
    landmarks = options.pop('landmarks', 'both')
    if noise is not None:
        frontend = replace(frontend, scan_matching=False)
    noise = noise or bag_odometry_noise(scenario)[0]
    cp = CornerParams(sigma_r=float(scenario.laser.sigma_range),
                      sigma_phi=float(scenario.laser.sigma_angle))
    run = run_slam(scenario, replace(SlamParams(**options), odometry=noise), cp,
                   landmarks=landmarks, frontend=frontend)
    ref = Trajectory.from_planar(run.stamps, run.truth)
    est = Trajectory.from_planar(run.stamps, run.poses)
    return ate(est, ref, 'se2')['rmse'], rpe(est, ref, 1.0)['rmse'], ellipse_share(run)


def with_odometry(scenario, stamps: np.ndarray, poses: np.ndarray):
    """Make ``poses`` at ``stamps`` the scenario's only odometry samples (in place); return it."""
    samples = [OdometrySample(int(t), p, np.zeros((3, 3)), np.zeros(2), np.zeros(2),
                              np.zeros(2)) for t, p in zip(stamps, poses)]
    events = [e for e in scenario.events if not isinstance(e, OdometrySample)]
    scenario.events = sorted(events + samples, key=lambda e: e.stamp_ns)
    return scenario


CATEGORIES = ('on_wall', 'moved', 'few_views', 'off_grid')


def scale_odometry(scenario, factor: float) -> None:
    """Scale the odometry's positions (so every increment's translation) in place."""
    for i, e in enumerate(scenario.events):
        if type(e) is OdometrySample:
            pose = np.array(e.pose, dtype=float)
            pose[:2] *= factor
            twist = np.array(e.twist, dtype=float)
            twist[:-1] *= factor  # linear part; the last component is the turn rate
            scenario.events[i] = replace(e, pose=pose, twist=twist)


def run_evaluate(args) -> int:
    """Run the ``evaluate`` subcommand: one line per log, seed and landmark type."""
    logs = log_paths(args.data, args.logs)
    prm = None  # evaluate_bag: SlamParams with the bag's stated noise model
    given = {'prune_misses': args.prune_misses, 'line_floor': args.line_floor,
             'line_residual_factor': args.line_residual_factor,
             'reject_ambiguous': args.reject_ambiguous,
             'position_floor': args.position_floor,
             'jacobians': args.jacobians, 'joint_probability': args.joint_probability}
    extra = {k: v for k, v in given.items() if v is not None}
    if extra:  # the importer's default drift model is 'pioneer'
        prm = SlamParams(odometry=odometry_noise_model('pioneer'), **extra)
    print('log seed landmarks resets corners lines ate_m odom_ate_m ate_ratio rpe_m odom_rpe_m '
          'rpe_ratio ellipse95 pruned ms')
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in logs:
            for seed in args.seed:
                bag = Path(tmp) / f'{name}_{seed}'
                import_log(path, bag, seed=seed)
                for lm in args.landmarks:
                    out = (None if args.out is None
                           else Path(args.out) / f'{name}_{seed}_{lm}')
                    r = evaluate_bag(bag, args.association, out, progress=False, params=prm,
                                     landmarks=lm)
                    ate, odo_ate = r['ate_se2_rmse'], r['odom_ate_se2_rmse']
                    rpe, odo_rpe = r['rpe_trans_rmse'], r['odom_rpe_trans_rmse']
                    row = [name, seed, lm, r['resets'], r['mapped'], r['lines_mapped'], ate,
                           odo_ate, ate / odo_ate, rpe, odo_rpe, rpe / odo_rpe,
                           r['ellipse95_share'], r['stats']['pruned'], r['ms_per_scan']]
                    print(' '.join(f'{v:.3f}' if isinstance(v, float) else str(v)
                                   for v in row), flush=True)
                    if out is not None:
                        (out / 'row.json').write_text(json.dumps(row))
    return 0


def run_diagnose(args) -> int:
    """Run the ``diagnose`` subcommand: one line per log."""
    filter_noise = None if args.filter_noise is None else odometry_noise_model(args.filter_noise)
    logs = log_paths(args.data, args.logs)
    given = {'line_floor': args.line_floor,
             'line_residual_factor': args.line_residual_factor,
             'line_beam_width': args.line_beam_width,
             'reject_ambiguous': args.reject_ambiguous, 'jacobians': args.jacobians,
             'association': args.association,
             'gate_probability': args.gate_probability,
             'joint_probability': args.joint_probability,
             'cartesian_gate': args.cartesian_gate,
             'free_space_check': args.free_space_check,
             'line_extent_sigmas': args.line_extent_sigmas,
             'recovery_probability': args.recovery_probability,
             'recovery_pairs': args.recovery_pairs,
             'spurious_limit': args.spurious_limit}
    extra = {k: v for k, v in given.items() if v is not None}
    keys = ('odo_nees', 'odo_out', 'odo_nees10', 'line_m2', 'nis95', 'd2', 'nees_med',
            'psi_err', 'psi_sd', 'ellipse95', 'rot_deg', 'ate_se2', 'ate_none', 'jump5',
            'rpe', 'odo_rpe', 'odo_se2')
    print('log ' + ' '.join(keys))
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in logs:
            bag = Path(tmp) / name
            import_log(path, bag, seed=args.seed, drift=args.drift)
            r = diagnose(bag, args.landmarks, extra, filter_noise)
            print(name + ' ' + ' '.join(f'{r[k]:.3g}' for k in keys), flush=True)
    return 0


def run_grid(args) -> int:
    """Run the ``grid`` subcommand: one line per run, then the summary."""
    logs = log_paths(args.data, args.logs)
    options = params_file_options(args.params_file)
    options.update(parse_set(args.set))
    if args.landmarks:
        options['landmarks'] = args.landmarks
    options['backend'] = graph_backend(args)
    os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
    with tempfile.TemporaryDirectory() as tmp:
        cache = args.cache or tmp
        jobs = [(name, path, seed, options, cache) for seed in args.seeds
                for name, path in logs]
        if args.procs <= 1:
            results = [run_one(job) for job in jobs]
        else:
            with Pool(args.procs) as pool:
                results = pool.map(run_one, jobs, chunksize=1)
    if args.backend == 'graph':
        return graph_grid(results)
    print('run | ellipse | ATE filter / odometry [m] (ratio) | RPE filter / odometry [cm] '
          '(ratio) | heading error [deg] | updates moving the pose > 20 cm: count, RMS over '
          "the steps [cm] | ellipse with the reference's noise")
    for name, seed, r in results:
        print(f"{name}-{seed} | {100 * r['ellipse95']:.1f} % | {r['ate_se2']:.3g} / "
              f"{r['odo_se2']:.3g} ({r['ate_se2'] / r['odo_se2']:.2f}) | {100 * r['rpe']:.2g} / "
              f"{100 * r['odo_rpe']:.2g} ({r['rpe'] / r['odo_rpe']:.2f}) | {r['psi_err']:.1f} | "
              f"{r['jumps']}, {100 * r['jump_rms']:.2g} | {100 * r['ellipse95_ref']:.1f} %")
    print(summary(results))
    return 0


def run_scan_matching(args) -> int:
    """Run the ``scan-matching`` subcommand: one line per run."""
    if args.slam:
        options = params_file_options(args.params_file)
        chain_noise = odometry_noise_model(args.filter_noise)
        if args.landmarks:
            options['landmarks'] = args.landmarks
    logs = log_paths(args.data, args.logs)
    print('run | ATE odometry / ICP [m] (ratio) | RPE 1 m odometry / ICP [cm] | ICP used | '
          'step yaw error odometry / ICP [deg] | ICP NIS (median) | pairs, NIS / pairs'
          + (' | SLAM on odometry / on ICP: ATE [m] (/ odometry ATE), RPE [cm], ellipse'
             if args.slam
             else ''))
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for name, path in logs:
                bag = Path(tmp) / f'{name}-{seed}'
                import_log(path, bag, seed=seed, drift=args.drift)
                scenario = load_bag(bag)
                r, stamps, poses = chain(scenario)
                ratios.append(r['icp_ate'] / r['odo_ate'] if r['odo_ate'] > 1e-9 else math.nan)
                slam = ''
                if args.slam:
                    a0, r0, e0 = slam_figures(scenario, options)
                    a1, r1, e1 = slam_figures(with_odometry(scenario, stamps, poses), options,
                                              chain_noise)
                    slam = (f" | {a0:.2f} ({a0 / r['odo_ate']:.3f}), {100 * r0:.1f}, "
                            f"{100 * e0:.1f} % / {a1:.2f} ({a1 / r['odo_ate']:.3f}), "
                            f'{100 * r1:.1f}, {100 * e1:.1f} %')

                print(f"{name}-{seed} | {r['odo_ate']:.2f} / {r['icp_ate']:.2f} "
                      f"({ratios[-1]:.2f}) | {100 * r['odo_rpe']:.1f} / {100 * r['icp_rpe']:.1f}"
                      f" | {100 * r['used']:.0f} % | {r['yaw_odo']:.2f} / {r['yaw_icp']:.2f} | "
                      f"{r['nis']:.0f} | {r['pairs']:.0f}, {r['nis_per_pair']:.2f}{slam}",
                      flush=True)
    print(f'ATE ratio median {np.median(ratios):.2f}, runs <= 0.2: '
          f'{int(np.sum(np.array(ratios) <= 0.2))} of {len(ratios)}')
    return 0


def run_defaults(args) -> int:
    """Run ``defaults``: ``landmark_nav import LOG`` then ``evaluate`` with no flags, per log.

    One row per log (default aces, seattle, fhw): unaligned ATE of the filter and of the
    odometry and their ratio, SE(2) ATE, resets, RPE over 1 m, the share of steps with the
    reference inside the 95 % ellipse, time per step; exit 1 when a log misses ATE <=
    odometry / 5 with no reset. ``--params-file`` is given to ``evaluate`` (e.g.
    ``config/ekf_slam_chapter.yaml``: the chapter's filter).
    """
    from landmark_nav.tools.cli import main as cli_main
    files = [a for f in args.params_file for a in ('--params-file', f)]
    missed = []
    print('log | ATE filter / odometry [m] (ratio) | SE(2) ATE filter / odometry [m] | resets '
          '| RPE 1 m filter / odometry [cm, deg] | 95 % ellipse | ms per step')
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in log_paths(args.data, args.logs):
            bag, out = Path(tmp) / name, Path(tmp) / f'{name}-out'
            import_log(path, bag)
            if cli_main(['evaluate', str(bag), '--no-progress', '--out', str(out)] + files):
                sys.exit(f'error: landmark_nav evaluate {bag} failed')
            r = json.loads((out / 'slam.json').read_text())
            ratio = r['ate_rmse'] / r['odom_ate_rmse']
            share = r.get('ellipse95_share')
            print(f"{name} | {r['ate_rmse']:.2f} / {r['odom_ate_rmse']:.2f} ({ratio:.3f}) | "
                  f"{r['ate_se2_rmse']:.2f} / {r['odom_ate_se2_rmse']:.2f} | {r['resets']} | "
                  f"{100 * r['rpe_trans_rmse']:.1f} / {r['rpe_rot_rmse_deg']:.2f}, "
                  f"{100 * r['odom_rpe_trans_rmse']:.1f} / {r['odom_rpe_rot_rmse_deg']:.2f} | "
                  f"{'n/a' if share is None else f'{100 * share:.1f} %'} | "
                  f"{r['ms_per_step_total']:.1f}", flush=True)
            if ratio > 0.2 or r['resets']:
                missed.append(name)
    if missed:
        print(f'target missed (ATE <= odometry / 5, 0 resets): {", ".join(missed)}')
    return 1 if missed else 0


def run_wean(args) -> int:
    """Run the ``wean`` subcommand: one line per log (and per part of a bridged log)."""
    extra = parse_set(args.set)
    extra, frontend = split_frontend(extra)
    logs = log_paths(args.data, args.logs, suffix='.log.gz')
    map_file = Path(args.map) if args.map else data_folder(args.data) / 'wean.dat.gz'
    if not map_file.is_file():
        sys.exit(f'error: occupancy map {map_file} not found (give one with --map FILE)')
    grid = load_occupancy_grid(map_file)
    if graph_backend(args) == 'graph':
        print('log keyframes loops_accepted loops_proposed poses poses_in_wall '
              'poses_in_wall_counted poses_unknown points_graph points_odom structural_share '
              'structural_count structural_left_out places_share places_count ms_per_scan')
    else:
        print('log corners share_10cm poses_in_wall poses_unknown points_slam points_odom '
              + ' '.join(CATEGORIES) + ' retired wall_depth_max wall_scans_median '
              'wall_cells_scans_median poses_in_wall_counted')
    with tempfile.TemporaryDirectory() as tmp:
        for name, path, bag in wean_bags(logs, Path(tmp)):
            sc = load_bag(bag, require_reference=False)
            if args.odometry_scale != 1.0:
                scale_odometry(sc, args.odometry_scale)
            if args.backend == 'graph':
                wean_graph(grid, sc, name, args)
                continue
            prm = SlamParams(odometry=bag_odometry_noise(sc)[0],
                             establish_hits=args.establish_hits, **extra)
            corner_params = CornerParams(sigma_r=sc.laser.sigma_range,
                                         sigma_phi=sc.laser.sigma_angle)
            run = run_slam(sc, prm, corner_params, landmarks=args.landmarks,
                           frontend=frontend)
            parts = run_segments(run)
            named = [(name, run)] + ([(f'{name}#{k}', p) for k, p in enumerate(parts)]
                                     if len(parts) > 1 else [])
            for label, part in named:
                if part.landmarks.shape[0] == 0:
                    print(f'{label}: no corner landmark')
                    continue
                fit = check_run(grid, sc, part)
                s = fit['slam']
                diag = landmark_diagnosis(grid, part, s['transform'],
                                          confirm_hits=prm.confirm_hits)
                count = Counter(diag['category'].tolist())
                wall = wall_pose_diagnosis(grid, sc, part, s['transform'])
                depth = f"{wall['depth'].max():.1f}" if wall['steps'].size else '-'
                seen = f"{np.median(wall['crossings']):.0f}" if wall['steps'].size else '-'
                cells = (f"{np.median(wall['wall_crossings']):.0f}"
                         if wall['wall_crossings'].size else '-')
                print(f'{label} {s["landmarks"]} {s["landmark_share"]:.3f} '
                      f'{s["poses_in_wall"]} {s["poses_unknown"]} {s["point_share"]:.3f} '
                      f'{fit["odometry"]["point_share"]:.3f} '
                      + ' '.join(str(count.get(c, 0)) for c in CATEGORIES)
                      + f' {run.stats.get("retired", 0)} {depth} {seen} {cells} '
                      f'{wall_poses_counted(wall, grid.resolution)}', flush=True)
                if args.corners or args.plot:
                    corners_on_walls(grid, sc, part, s['transform'], corner_params, label, args)
    return 0


def wean_bags(logs, tmp: Path):
    """Yield ``(label, log, bag)`` per log, and per run of a log that holds several.

    A log whose clock restarts where the robot is elsewhere
    (:func:`landmark_nav.importers.runs.find_restarts`, ``robotdata5``) is imported one run
    at a time (``import --run K``, label ``name/runK``): the filter starts each run afresh
    from its own odometry.
    """
    for name, path in logs:
        bag = tmp / name
        result = import_log(path, bag)
        if not result.restarts:
            yield name, path, bag
            continue
        for k in range(1, len(result.restarts) + 2):
            bag = tmp / f'{name}-run{k}'
            import_log(path, bag, run=k)
            yield f'{name}/run{k}', path, bag


def main(argv=None) -> int:
    """Parse the subcommand and run it."""
    ap, sub = subcommand_parser(__doc__)
    p = sub.add_parser('evaluate', help='landmark_nav evaluate on each imported log')
    add_logs_argument(p, 'carmen', CARMEN_LOGS)
    p.add_argument('--landmarks', nargs='+', default=['corners', 'lines', 'both'])
    p.add_argument('--association', default='icnn', choices=['icnn', 'jcbb'])
    p.add_argument('--prune-misses', type=int, default=None)
    p.add_argument('--seed', type=int, nargs='+', default=[0],
                   help='drift seeds of the import (default 0, the importer default)')
    p.add_argument('--line-floor', type=float, default=None)
    p.add_argument('--line-residual-factor', type=float, default=None)
    p.add_argument('--reject-ambiguous', action='store_true', default=None)
    p.add_argument('--position-floor', type=float, default=None)
    p.add_argument('--jacobians', default=None, choices=JACOBIANS)
    p.add_argument('--joint-probability', type=float, default=None)
    p.add_argument('--out', default=None, help='keep slam.json and the PNGs here')
    p.set_defaults(run=run_evaluate)
    p = sub.add_parser('diagnose',
                       help='consistency figures of the filter on each imported log')
    add_logs_argument(p, 'carmen', CARMEN_LOGS)
    p.add_argument('--landmarks', default='both', choices=['corners', 'lines', 'both'])
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--line-floor', type=float, default=None)
    p.add_argument('--line-residual-factor', type=float, default=None)
    p.add_argument('--line-beam-width', type=float, default=None,
                   help="SlamParams.line_beam_width: the beam's 1-sigma angular spread [rad]")
    p.add_argument('--reject-ambiguous', action='store_true', default=None)
    p.add_argument('--jacobians', default=None, choices=JACOBIANS)
    p.add_argument('--association', default=None, choices=ASSOCIATION_METHODS)
    p.add_argument('--gate-probability', type=float, default=None,
                   help="SlamParams.gate_probability: the individual gate's confidence")
    p.add_argument('--joint-probability', type=float, default=None)
    p.add_argument('--cartesian-gate', type=float, default=None,
                   help='SlamParams.cartesian_gate (relative range std; 0: every pair)')
    p.add_argument('--free-space-check', type=float, default=None,
                   help='SlamParams.free_space_check (confidence; e.g. 0.95)')
    p.add_argument('--line-extent-sigmas', type=float, default=None,
                   help='SlamParams.line_extent_sigmas (e.g. 1.96)')
    p.add_argument('--recovery-probability', type=float, default=None,
                   help='SlamParams.recovery_probability (e.g. 0.99)')
    p.add_argument('--recovery-pairs', type=int, default=None,
                   help='SlamParams.recovery_pairs (default 3)')
    p.add_argument('--spurious-limit', type=float, default=None,
                   help='SlamParams.spurious_limit (e.g. 0.05)')
    p.add_argument('--drift', default=None,
                   help='import drift model (default pioneer; none: the reference increments)')
    p.add_argument('--filter-noise', default=None,
                   help="the filter's odometry noise model instead of the bag's")
    p.set_defaults(run=run_diagnose)
    p = sub.add_parser('grid', help='drift runs with a parameter file: per run and summary')
    add_logs_argument(p, 'carmen', CARMEN_LOGS)
    p.add_argument('--seeds', nargs='+', type=int, default=[0, 1])
    p.add_argument('--params-file', default=None,
                   help='ekf_slam parameter file on top of the defaults')
    p.add_argument('--set', action='append', default=[], metavar='NAME=VALUE')
    p.add_argument('--landmarks', choices=('corners', 'lines', 'both'), default=None)
    p.add_argument('--procs', type=int, default=2)
    p.add_argument('--cache', default=None, help='keep the imported bags here')
    p.add_argument('--backend', choices=('ekf', 'graph'), default='ekf',
                   help='graph: the pose graph against its targets (module doc; exit 1 on a miss)')
    p.set_defaults(run=run_grid)
    p = sub.add_parser('scan-matching',
                       help='dead reckoning by ICP of consecutive scans (and SLAM on it)')
    add_logs_argument(p, 'carmen', CARMEN_LOGS)
    p.add_argument('--seeds', nargs='+', type=int, default=[0, 1])
    p.add_argument('--drift', default=None,
                   help="the importer's drift model (default pioneer; none: the reference's "
                        'own increments as odometry, the ICP gated with pioneer)')
    p.add_argument('--slam', action='store_true', help='also EKF-SLAM on both motions')
    p.add_argument('--params-file', default=None, help='ekf_slam parameter file (default: '
                   'the defaults)')
    p.add_argument('--filter-noise', default='k_d=0.04 k_theta=0.015 k_dtheta=0.03',
                   help="the filter's U on the scan-matched chain")
    p.add_argument('--landmarks', choices=('corners', 'lines', 'both'), default=None,
                   help="landmark types (default: the parameter file's)")
    p.set_defaults(run=run_scan_matching)
    p = sub.add_parser('defaults', help='import, then evaluate with no flags (the shipped '
                       'defaults): ATE <= odometry / 5 and no reset, or exit 1')
    add_logs_argument(p, 'carmen', ('aces', 'seattle', 'fhw'))
    p.add_argument('--params-file', action='append', default=[],
                   help='given to evaluate (repeatable)')
    p.set_defaults(run=run_defaults)
    p = sub.add_parser('wean', help='EKF-SLAM on the Wean logs judged on the occupancy map')
    add_logs_argument(p, 'wean', WEAN_LOGS)
    p.add_argument('--map', default=None, metavar='FILE',
                   help='beesoft occupancy map (default: DATA/wean.dat.gz)')
    p.add_argument('--landmarks', default='both', choices=['corners', 'lines', 'both'])
    p.add_argument('--establish-hits', type=int, default=0)
    p.add_argument('--set', action='append', default=[], metavar='NAME=VALUE')
    p.add_argument('--odometry-scale', type=float, default=1.0,
                   help='scale the raw odometry translations before the filter (a test of '
                        'the odometry scale against the grid; default 1)')
    p.add_argument('--corners', action='store_true',
                   help="also place every scan's corners with the SLAM path: the share of "
                        'structural and other corners within 10 cm of a wall cell the log '
                        'does not see through, convex / concave, distances of the off-wall ones')
    p.add_argument('--backend', choices=('ekf', 'graph'), default='ekf',
                   help='graph: the pose graph, its poses and structural corners')
    p.add_argument('--cell-alignment', action='store_true', help='with --backend graph: '
                   'align to the grid in whole cells (no refinement)')
    p.add_argument('--plot', default=None, metavar='DIR',
                   help='with --corners: draw them into DIR/<log>_structural_corners.png')
    p.set_defaults(run=run_wean)
    return run_subcommand(ap, argv)


if __name__ == '__main__':
    sys.exit(main())
