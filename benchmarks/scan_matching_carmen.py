"""How far dead reckoning by scan matching of consecutive scans gets on the Carmen logs.

Run from the repository root (needs ``../shared/data/carmen``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/scan_matching_carmen.py [--seeds 0 1] [--drift none]
        [--slam [--params-file YAML] [--filter-noise MODEL] [--landmarks KIND]] [LOG ...]

A yardstick for EKF-SLAM on these logs (issue 14): each log is imported as ``landmark_nav
import`` does (synthetic drift with the importer's default ``pioneer`` model, the given
seed), and its scans are chained by point-to-line ICP
(:func:`landmark_nav.slam.scan_matching.base_motion`: returns within 20 m,
pairs within 50, 30, then 15 cm) of each scan onto the previous one, the odometry's motion
between the two stamps (through the laser mount) as the initial guess. The ICP motion is
used when it converged and lies inside the odometry's own 99.9 % region (its difference
from the odometry's motion, under the bag's stated noise model ``U``, within
chi2(3, 0.999)); otherwise the odometry's motion is. No landmark, no map, no loop closure:
what pairwise scan matching alone removes of the odometry's drift. With ``--drift none`` the
odometry is the reference's own increments (its RPE 0) and the ICP is gated with the
``pioneer`` model: the chain's RPE is then how far the ICP's motion and the reference's
disagree over 1 m (the ICP's errors and the reference's own together), while the drifted
odometry, built on the reference's increments, carries none of the reference's step errors
in its RPE.

Printed per run: the SE(2)-aligned ATE RMSE [m] of the odometry and of the scan-matched
chain and their ratio (issue 14's SLAM target: at most 0.2), the RPE over 1 m of both
[cm], the share of steps that used ICP, the median per-step heading error [deg] of the
odometry and of the ICP motions against the reference's, and the median NIS of those
errors under the ICP's own covariance (``s^2 (J^T J)^-1``; 3 expected: larger means the
classic covariance is optimistic, and the reference's own few-cm error adds to it), then
the median pairs per step ``N`` and the median of ``NIS / N``: the NIS under the
covariance of :func:`landmark_nav.slam.scan_matching.fit_information` worth ``pairs``
residuals is ``pairs NIS / N`` (the front end's ``scan_matching_fit_pairs``).

``--slam`` also runs EKF-SLAM (:func:`landmark_nav.evaluation.slam.run_slam`, corners and
lines, the ``ekf_slam`` defaults or ``--params-file`` on top; ``--landmarks corners`` or
``lines`` instead of the file's) twice per run: on the
bag's odometry with its stated noise model (and the file's front end: the profile's
``scan_matching`` scan-matches in the filter itself; the README's yardstick figures predate
it), and on the scan-matched chain (its poses as the odometry samples, at the scan stamps;
the front end's own scan matching off) with ``--filter-noise`` as ``U`` (default
``k_d=0.04 k_theta=0.015 k_dtheta=0.03``: about twice the ICP motions' per-step errors
printed by the first part). It prints each one's ATE [m] (and its ratio to the
odometry's), RPE over 1 m [cm] and the share of steps with the reference inside the 95 %
position ellipse: whether the landmark updates add to, or take from, the motion they start
from.
"""

import argparse
from dataclasses import replace
import math
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_node_cpu import params_file_options, split_frontend  # noqa: E402
from landmark_nav.evaluation.bags import load_bag  # noqa: E402
from landmark_nav.evaluation.slam import (bag_odometry_noise, ellipse_share,  # noqa: E402
                                          run_slam)
from landmark_nav.evaluation.trajectory import ate, rpe, Trajectory  # noqa: E402
from landmark_nav.geometry import (compose, interpolate_pose, inverse,  # noqa: E402
                                   relative, wrap_angle)
from landmark_nav.importers.writer import import_log  # noqa: E402
from landmark_nav.laser.corners import CornerParams  # noqa: E402
from landmark_nav.sim import OdometrySample, ScanSample  # noqa: E402
from landmark_nav.slam.consistency import chi2_gate  # noqa: E402
from landmark_nav.slam.ekf_slam import odometry_noise, SlamParams  # noqa: E402
from landmark_nav.slam.frontend import FrontendParams, odometry_noise_model  # noqa: E402
from landmark_nav.slam.scan_matching import base_motion, scan_points  # noqa: E402
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
import numpy as np  # noqa: E402

LOGS = ('aces', 'seattle', 'fhw', 'freiburg-101', 'belgioioso', 'acapulco')
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


def main() -> int:
    """Import each log per seed, chain it, print one line per run."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS))
    ap.add_argument('--seeds', nargs='+', type=int, default=[0, 1])
    ap.add_argument('--drift', default=None,
                    help="the importer's drift model (default pioneer; none: the reference's "
                         'own increments as odometry, the ICP gated with pioneer)')
    ap.add_argument('--slam', action='store_true', help='also EKF-SLAM on both motions')
    ap.add_argument('--params-file', default=None, help='ekf_slam parameter file on top of '
                    'the defaults')
    ap.add_argument('--filter-noise', default='k_d=0.04 k_theta=0.015 k_dtheta=0.03',
                    help="the filter's U on the scan-matched chain")
    ap.add_argument('--landmarks', choices=('corners', 'lines', 'both'), default=None,
                    help="landmark types (default: the parameter file's)")
    args = ap.parse_args()
    if args.slam:
        options = params_file_options(args.params_file)
        chain_noise = odometry_noise_model(args.filter_noise)
        if args.landmarks:
            options['landmarks'] = args.landmarks
    carmen = SHARED_DATA / 'carmen'
    print('run | ATE odometry / ICP [m] (ratio) | RPE 1 m odometry / ICP [cm] | ICP used | '
          'step yaw error odometry / ICP [deg] | ICP NIS (median) | pairs, NIS / pairs'
          + (' | SLAM on odometry / on ICP: ATE [m] (/ odometry ATE), RPE [cm], ellipse'
             if args.slam
             else ''))
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for name in args.logs:
                bag = Path(tmp) / f'{name}-{seed}'
                import_log(carmen / f'{name}-corrected.log.gz', bag, seed=seed,
                           drift=args.drift)
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


if __name__ == '__main__':
    sys.exit(main())
