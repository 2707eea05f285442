"""Consistency diagnosis of EKF-SLAM on the Carmen logs (issue 14).

Run from the repository root (needs ``../shared/data/carmen``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/slam_consistency_carmen.py [--landmarks both]
        [--seed 0] [--line-floor M] [--line-residual-factor K] [--line-beam-width RAD]
        [--reject-ambiguous]
        [--jacobians standard|observability|observability_gain|first_estimates]
        [--gate-probability P] [--joint-probability P] [--association icnn|jcbb]
        [--cartesian-gate F]
        [--free-space-check P] [--line-extent-sigmas K]
        [--recovery-probability P [--recovery-pairs N]] [--spurious-limit L] [--drift MODEL]
        [--filter-noise MODEL] [LOG ...]

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
  put in the map with the reference pose, from the mean of the observations the filter
  associated with the same landmark (landmarks seen at least 5 times), under the stated
  covariance moved to the map (the extractor's through the mount plus the segment-wide
  terms of ``line_floor``, ``line_residual_factor`` and ``line_beam_width``, as the filter
  gets it, :func:`landmark_nav.slam.ekf_slam.line_noise_covariance`; the sweep
  motion is left out). The reference poses are
  scan-matched, a few cm, so this overstates the error a little.
* ``nis95``: share of updates whose joint NIS exceeds its chi-square 95 % bound (0.05
  expected) and ``d2``: mean individual d2 of the accepted pairs (1.6 for a 95 % gate).
* ``nees_med``: median robot NEES (3 dof, unaligned), ``psi_err`` / ``psi_sd``: RMS heading
  error and median heading std of the filter [deg], ``ellipse95``: share of steps with the
  reference inside the 95 % position ellipse.
* ``rot_deg`` / ``ate_se2``: the rotation [deg] of the SE(2) fit of the filter's positions
  onto the reference (:func:`landmark_nav.evaluation.trajectory.planar_alignment`: map and
  path turned together, the unobservable global heading) and the position RMSE after it
  [m], against ``ate_none``, the RMSE without alignment.
* ``jump5``: share of the squared per-step translation error (relative motion against the
  reference's) that the worst 5 % of steps carry (what the RPE over 1 m is made of).
* ``rpe`` / ``odo_rpe``: RPE over 1 m (translation RMSE [m]) of the filter and of the
  odometry, and ``odo_se2``: the odometry's SE(2)-aligned ATE RMSE [m], as
  ``benchmarks/slam_landmarks_carmen.py`` computes them (``evaluate_bag``'s evo metrics).
"""

import argparse
from dataclasses import replace
import math
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_node_cpu import split_frontend  # noqa: E402
from landmark_nav.evaluation.bags import load_bag  # noqa: E402
from landmark_nav.evaluation.odometry_drift import odometry_window_nees  # noqa: E402
from landmark_nav.evaluation.slam import (bag_odometry_noise,  # noqa: E402
                                          ellipse_share, run_slam, scan_features,
                                          update_corrections)
from landmark_nav.evaluation.trajectory import (ate, planar_alignment, rpe,  # noqa: E402
                                                Trajectory)
from landmark_nav.geometry import relative  # noqa: E402
from landmark_nav.importers.writer import import_log  # noqa: E402
from landmark_nav.laser.corners import CornerParams  # noqa: E402
from landmark_nav.laser.lines import LineParams  # noqa: E402
from landmark_nav.sim import OdometrySample, ScanSample  # noqa: E402
from landmark_nav.slam.consistency import chi2_gate  # noqa: E402
from landmark_nav.slam.ekf_slam import (ASSOCIATION_METHODS, JACOBIANS,  # noqa: E402
                                        LINE, line_noise_covariance, odometry_noise,
                                        SlamParams)
from landmark_nav.slam.frontend import odometry_noise_model  # noqa: E402
from landmark_nav.slam.line_landmarks import (line_initialization,  # noqa: E402
                                              lines_to_observations)
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
import numpy as np  # noqa: E402

LOGS = ('aces', 'seattle', 'fhw', 'freiburg-101', 'belgioioso', 'acapulco')
# The reference poses' own per-pose std along / across their heading [m], as
# ``benchmarks/reference_noise_carmen.py`` measures them from the scans (README.md at
# commit 67eb6cc, EKF-SLAM, "Reference noise"): ``ellipse95_ref`` adds them to the filter's
# covariance.
REFERENCE_SD = {'aces': (0.0181, 0.0061), 'seattle': (0.0118, 0.0072),
                'fhw': (0.0204, 0.0120), 'freiburg-101': (0.0136, 0.0174),
                'belgioioso': (0.0095, 0.0095), 'acapulco': (0.0242, 0.0230)}


def log_name(bag: Path) -> str:
    """Return the Carmen log a bag was imported from (``aces-3`` -> ``aces``), or ''."""
    name = Path(bag).name
    return next((g for g in LOGS if name == g or name.startswith(g + '-')), '')


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


def main() -> int:
    """Import, diagnose, print one line per log."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS))
    ap.add_argument('--landmarks', default='both', choices=['corners', 'lines', 'both'])
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--line-floor', type=float, default=None)
    ap.add_argument('--line-residual-factor', type=float, default=None)
    ap.add_argument('--line-beam-width', type=float, default=None,
                    help="SlamParams.line_beam_width: the beam's 1-sigma angular spread [rad]")
    ap.add_argument('--reject-ambiguous', action='store_true', default=None)
    ap.add_argument('--jacobians', default=None, choices=JACOBIANS)
    ap.add_argument('--association', default=None, choices=ASSOCIATION_METHODS)
    ap.add_argument('--gate-probability', type=float, default=None,
                    help="SlamParams.gate_probability: the individual gate's confidence")
    ap.add_argument('--joint-probability', type=float, default=None)
    ap.add_argument('--cartesian-gate', type=float, default=None,
                    help='SlamParams.cartesian_gate (relative range std; 0: every pair)')
    ap.add_argument('--free-space-check', type=float, default=None,
                    help='SlamParams.free_space_check (confidence; e.g. 0.95)')
    ap.add_argument('--line-extent-sigmas', type=float, default=None,
                    help='SlamParams.line_extent_sigmas (e.g. 1.96)')
    ap.add_argument('--recovery-probability', type=float, default=None,
                    help='SlamParams.recovery_probability (e.g. 0.99)')
    ap.add_argument('--recovery-pairs', type=int, default=None,
                    help='SlamParams.recovery_pairs (default 3)')
    ap.add_argument('--spurious-limit', type=float, default=None,
                    help='SlamParams.spurious_limit (e.g. 0.05)')
    ap.add_argument('--drift', default=None,
                    help='import drift model (default pioneer; none: the reference increments)')
    ap.add_argument('--filter-noise', default=None,
                    help="the filter's odometry noise model instead of the bag's")
    args = ap.parse_args()
    filter_noise = None if args.filter_noise is None else odometry_noise_model(args.filter_noise)
    carmen = SHARED_DATA / 'carmen'
    if not carmen.is_dir():
        print(f'missing {carmen}', file=sys.stderr)
        return 1
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
        for name in args.logs:
            bag = Path(tmp) / name
            import_log(carmen / f'{name}-corrected.log.gz', bag, seed=args.seed,
                       drift=args.drift)
            r = diagnose(bag, args.landmarks, extra, filter_noise)
            print(name + ' ' + ' '.join(f'{r[k]:.3g}' for k in keys), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
