"""EKF-SLAM on the simulator: step time against the map size, ICNN against JCBB.

Run from the repository root::

    python benchmarks/bench_slam.py step-time [--landmarks 50 100 200] [--steps 200]
        [--threads 1] [--seed 0] [--bag DIR]
    python benchmarks/bench_slam.py ambiguous [--seeds 0-9]

Both run on generated input by default: a random map (``--seed``) and the simulator's
``ambiguous`` scenario (``--seeds``); ``step-time --bag DIR`` times the steps of a
recorded bag.

``step-time``: one EKF-SLAM step (prediction + ICNN association + update). For each map
size N a filter is built with N landmarks scattered over a 40 m x 40 m area (augmented with
eqs. 38-48 from one pose) and then driven in a circle; every step is
:meth:`EkfSlam.predict` + :meth:`EkfSlam.update` with 10 observations of the 10 landmarks
nearest to the robot (all associated: the update is a 20-row batch), the PSD check of P
included. The script prints the median and 90th percentile step time, the split into
prediction / association / update, the growth against the ``(3 + 2N)^2`` of the covariance
and, as the in-run reference on the same data, the dense textbook update (explicit ``H``,
``K = P H^T S^-1``, Joseph form ``(I - K H) P (I - K H)^T + K R K^T``).

BLAS threads: ``--threads`` (default 1) is exported as ``OPENBLAS_NUM_THREADS`` /
``OMP_NUM_THREADS`` before numpy is imported; with a few hundred states the matrices are
small and threading costs more than it gives. Targets: <= 1 ms (N = 50), <= 2 ms (100),
<= 6 ms (200).

``step-time --bag DIR``: the filter steps of a recorded bag with ``/scan`` and ``/odom``
(e.g. ``bags/office``, or a log imported with ``landmark_nav import``), the first
``--steps`` scans (default all). Each scan's corners (:func:`scan_features`, not timed) go
to :class:`SlamFrontend` with the odometry, as the ``ekf_slam`` node feeds it, default
:class:`SlamParams`; the time of a step is that of the front end's call that made it
(odometry interpolation, de-skew, prediction, association and update, the filter's checks):
a step made while the front end takes an odometry sample (the one that lets a waiting scan
through) or a scan is timed in that call (shared among the steps it made). Here the map
grows as the robot explores, so ``--landmarks`` and ``--seed`` do not apply: the steps are
printed in four consecutive quarters, each with the median map size N, the state size n,
the median and 90th percentile step time and the median corners per scan.

``ambiguous``: the ``ambiguous`` scenario
(:func:`landmark_nav.sim.scenarios.ambiguous_world`): the robot maps an irregular row of
0.3 m posts whose corners of the same kind are 0.45-0.77 m apart, then drives a 72 m loop
with the laser blind, so that its pose error grows to tens of centimetres and degrees, and
re-observes the row from 2.5 m. For every seed the same simulated run goes through the
filter with the default :class:`SlamParams` once per method: ``ICNN`` (the chapter's:
``association='icnn'``, ``joint_check=False``), ``JCBB`` and ``ICNN+JOINT`` (the filter's
default: ICNN whose hypothesis, when jointly incompatible at a gross-error level, is
decided by JCBB) (nothing else differs), and is scored by
:func:`landmark_nav.evaluation.slam.score_run` (wrong associations via the ground-truth
corner ids; a recording has no such truth, which is why this subcommand is synthetic only:
the wrong associations can only be counted where the true landmark of each observation is
known). Printed per seed: the odometry error accumulated over the blackout (position,
heading), then per method the wrong associations out of all associations, the ATE RMSE over
the scans after the blackout, the mapped landmarks against the true visible corners,
duplicated and ghost landmarks and the filter time. The last line sums the wrong
associations.
"""

import math
import os
from pathlib import Path
import statistics
import sys
import time
from typing import Dict, List, Optional, Tuple


def _threads_from_argv() -> str:
    """Return the --threads value from argv (numpy is not imported yet)."""
    for i, a in enumerate(sys.argv):
        if a == '--threads' and i + 1 < len(sys.argv):
            return sys.argv[i + 1]
        if a.startswith('--threads='):
            return a.split('=', 1)[1]
    return '1'


for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ[_var] = _threads_from_argv()
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import run_subcommand, subcommand_parser  # noqa: E402
from landmark_nav.evaluation.slam import run_slam, scan_features, score_run  # noqa: E402
from landmark_nav.geometry import compose, inverse_transform_points, wrap_angle  # noqa: E402
from landmark_nav.sim import OdometrySample, run_scenario, ScanSample  # noqa: E402
from landmark_nav.slam import EkfSlam, SlamParams  # noqa: E402
from landmark_nav.slam.ekf_slam import (do_data_association, ekf_predict,  # noqa: E402
                                        ekf_update, is_psd, observation_model,
                                        odometry_noise)
from landmark_nav.slam.frontend import Corners, SlamFrontend  # noqa: E402
from landmark_nav.slam.visibility import ScanGeometry  # noqa: E402
import numpy as np  # noqa: E402

TARGET_MS = {50: 1.0, 100: 2.0, 200: 6.0}
METHODS = ('icnn', 'jcbb', 'icnn+joint')  # the associations of ``ambiguous``
OBS = 10
SIG = np.array([0.01, math.radians(0.3)])


def build(n_lm: int, rng: np.random.Generator) -> EkfSlam:
    """Return a filter whose map holds ``n_lm`` landmarks (all confirmed at once)."""
    slam = EkfSlam(SlamParams(confirm_hits=1, confirm_window=1, max_landmarks=n_lm))
    pts = rng.uniform(-20.0, 20.0, (n_lm, 2))
    pts = pts[np.argsort(np.hypot(pts[:, 0], pts[:, 1]))]
    p = inverse_transform_points(np.zeros(3), pts)
    z = np.column_stack([np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])])
    slam.update(z, np.repeat(np.diag(SIG ** 2)[None], n_lm, axis=0))
    assert slam.num_landmarks == n_lm
    return slam


def observations(slam: EkfSlam, u: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Return (10, 2) noisy observations of the landmarks nearest to the pose after ``u``."""
    x = slam.state
    x[:3] = compose(x[:3], u)
    lm = slam.landmarks
    near = np.argsort(np.hypot(*(lm - x[:2]).T))[:OBS]
    z = observation_model(x, near)[0]
    return z + rng.normal(0.0, SIG, z.shape)


def dense_joseph(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray,
                 idx: np.ndarray) -> np.ndarray:
    """Return P after the textbook dense Joseph-form update (the reference)."""
    zhat, hr, hf = observation_model(x, idx)
    k = idx.size
    h = np.zeros((2 * k, x.size))
    rr = np.zeros((2 * k, 2 * k))
    for i, j in enumerate(idx):
        h[2 * i:2 * i + 2, :3] = hr[i]
        h[2 * i:2 * i + 2, 3 + 2 * j:5 + 2 * j] = hf[i]
        rr[2 * i:2 * i + 2, 2 * i:2 * i + 2] = r[i]
    s = h @ p @ h.T + rr
    gain = p @ h.T @ np.linalg.inv(s)
    ikh = np.eye(x.size) - gain @ h
    return ikh @ p @ ikh.T + gain @ rr @ gain.T


def bench(n_lm: int, steps: int, seed: int) -> Dict[str, float]:
    """Time ``steps`` filter steps with ``n_lm`` landmarks; return median timings [ms]."""
    rng = np.random.default_rng(seed)
    slam = build(n_lm, rng)
    r = np.repeat(np.diag(SIG ** 2)[None], OBS, axis=0)
    u = np.array([0.05, 0.0, 0.01])
    total: List[float] = []
    parts: Dict[str, List[float]] = {'predict': [], 'associate': [], 'update': [], 'psd': [],
                                     'dense': []}
    matched = 0
    for _ in range(steps):
        z = observations(slam, u, rng)
        t0 = time.perf_counter()
        slam.predict(u)
        res = slam.update(z, r)
        total.append(time.perf_counter() - t0)
        matched += int(res.matched.sum())
        # The parts, on a copy of the state (one step later, same kind of data).
        x, p = slam.state, slam.covariance
        z = observations(slam, u, rng)
        t0 = time.perf_counter()
        ekf_predict(x, p, u, odometry_noise(u, slam.params.odometry))
        t1 = time.perf_counter()
        pf = slam.params.position_floor
        reff = r + np.einsum('k,ij->kij', np.ones(OBS), np.diag([pf ** 2, 0.0]))
        reff[:, 1, 1] += (pf / z[:, 0]) ** 2  # as in EkfSlam.update
        hyp, _, _ = do_data_association(x, p, z, reff)
        t2 = time.perf_counter()
        ok = hyp >= 0
        p2, _ = ekf_update(x.copy(), p.copy(), z[ok], reff[ok], hyp[ok])
        t3 = time.perf_counter()
        is_psd(p2)
        t4 = time.perf_counter()
        dense_joseph(x, p, z[ok], reff[ok], hyp[ok])
        t5 = time.perf_counter()
        for name, a, b in (('predict', t0, t1), ('associate', t1, t2), ('update', t2, t3),
                           ('psd', t3, t4), ('dense', t4, t5)):
            parts[name].append(b - a)
    out = {name: 1e3 * statistics.median(v) for name, v in parts.items()}
    out['step'] = 1e3 * statistics.median(total)
    out['p90'] = 1e3 * float(np.quantile(total, 0.9))
    out['matched'] = matched / steps
    return out


def parse_seeds(text: str) -> List[int]:
    """Return the seeds of ``'0-9'`` or ``'1,4,7'``."""
    if '-' in text:
        a, b = text.split('-', 1)
        return list(range(int(a), int(b) + 1))
    return [int(v) for v in text.split(',')]


def run_seed(seed: int) -> Dict[str, object]:
    """Simulate one seed and run both association methods on the same data."""
    res = run_scenario('ambiguous', seed)
    (b0, b1), = res.blackout
    k0, k1 = [int(np.searchsorted(res.trajectory.stamps_ns, t)) for t in (b0, b1)]
    drift = (res.odometry.poses[k1] - res.odometry.poses[k0]) - (
        res.trajectory.poses[k1] - res.trajectory.poses[k0])
    out: Dict[str, object] = {
        'seed': seed, 'drift_m': float(np.hypot(drift[0], drift[1])),
        'drift_deg': float(np.degrees(wrap_angle(drift[2])))}
    for method in METHODS:
        params = SlamParams(association='jcbb' if method == 'jcbb' else 'icnn',
                            joint_check=method == 'icnn+joint')
        tic = time.perf_counter()
        run = run_slam(res, params)
        seconds = time.perf_counter() - tic
        score = score_run(res, run, params)
        after = run.stamps >= b1
        err = np.hypot(*(run.poses[after, :2] - run.truth[after, :2]).T)
        out[method] = {'score': score, 'ate_after': float(np.sqrt(np.mean(err ** 2))),
                       'seconds': seconds}
    return out


def run_ambiguous(args) -> int:
    """Run the ``ambiguous`` subcommand: one line per seed, then the sums."""
    seeds = parse_seeds(args.seeds)
    head = (f'{"seed":>4} {"blackout drift":>15} | ' + ' | '.join(
        f'{m.upper()}: {"wrong":>9} {"ATE after":>9} {"mapped":>6} {"dup":>3} {"ghost":>5} '
        f'{"s":>4}' for m in METHODS))
    print('ambiguous scenario, default SlamParams, only the association differs')
    print(head)
    total = dict.fromkeys(METHODS, 0)
    for seed in seeds:
        r = run_seed(seed)
        cells = []
        for m in METHODS:
            s, sc = r[m], r[m]['score']
            total[m] += sc.wrong_associations
            cells.append(f'{m.upper()}: {sc.wrong_associations:>4}/{sc.associations:<4} '
                         f'{100 * s["ate_after"]:>6.1f} cm {sc.mapped:>3}/{sc.true_visible:<2} '
                         f'{sc.duplicates:>3} {sc.ghost_landmarks:>5} {s["seconds"]:>4.1f}')
        print(f'{seed:>4} {100 * r["drift_m"]:>6.1f} cm {r["drift_deg"]:>+5.1f} deg | '
              + ' | '.join(cells), flush=True)
    print('wrong associations summed over seeds ' + ', '.join(
        f'{m.upper()} {total[m]}' for m in METHODS)
        + f' ({len(seeds)} seeds; JCBB {"<" if total["jcbb"] < total["icnn"] else ">="} ICNN)')

    return 0


def bag_steps(bag: str, max_scans: Optional[int]) -> List[Tuple[float, int, int]]:
    """Return ``(step ms, landmarks after the step, corners)`` of each step over a bag."""
    from landmark_nav.evaluation.bags import load_bag
    if not Path(bag, 'metadata.yaml').is_file():
        sys.exit(f'error: bag {bag} not found (a rosbag2 folder with metadata.yaml)')
    scenario = load_bag(bag, require_reference=False)
    mount = np.asarray(scenario.laser.mount, dtype=float)
    made: List[Tuple[int, int]] = []      # (landmarks after the step, scan index)
    fe = SlamFrontend(SlamParams(), mount,
                      on_step=lambda st: made.append((st.slam.num_landmarks, st.tag)))
    sigma = float(getattr(scenario.laser, 'sigma_range', fe.params.sigma_range))
    out: List[Tuple[float, int, int]] = []
    corners_of: List[int] = []

    def timed(call, *a) -> None:
        """Call the front end; share its time among the steps it made."""
        done = len(made)
        tic = time.perf_counter()
        call(*a)
        ms = 1e3 * (time.perf_counter() - tic)
        for size, scan in made[done:]:
            out.append((ms / (len(made) - done), size, corners_of[scan]))

    for ev in scenario.events:
        if isinstance(ev, OdometrySample):
            timed(fe.add_odometry, ev.stamp_ns, ev.pose, ev.covariance)
        elif isinstance(ev, ScanSample):
            if max_scans is not None and len(corners_of) >= max_scans:
                break
            corners, segs = scan_features(ev)
            geometry = ScanGeometry(np.asarray(ev.ranges, dtype=float), ev.angle_min,
                                    ev.angle_increment, ev.range_min, ev.range_max, mount,
                                    sigma)
            corners_of.append(len(corners))
            timed(fe.add_features, Corners.from_corners(
                ev.stamp_ns, corners, ev.time_increment, segs, None, geometry),
                len(corners_of) - 1)
    timed(fe.flush)
    scans = len(corners_of)
    if not out:
        sys.exit(f'error: bag {bag}: no filter step ({scans} scans; are /scan and /odom '
                 'there?)')
    return out


def run_step_time_bag(args) -> int:
    """Run ``step-time --bag DIR``: the steps in four consecutive quarters."""
    steps = bag_steps(args.bag, args.steps)
    print(f'{args.bag}: {len(steps)} EKF-SLAM steps through SlamFrontend, default SlamParams '
          f'(BLAS threads: {os.environ["OPENBLAS_NUM_THREADS"]})')
    print(f'{"N":>4} {"n":>4} {"step ms":>8} {"p90":>6} {"corners":>7} {"steps":>5}')
    for part in np.array_split(np.array(steps, dtype=float), 4):
        if not len(part):
            continue
        n_lm = int(np.median(part[:, 1]))
        print(f'{n_lm:>4} {3 + 2 * n_lm:>4} {np.median(part[:, 0]):>8.3f} '
              f'{np.quantile(part[:, 0], 0.9):>6.2f} {np.median(part[:, 2]):>7.1f} '
              f'{len(part):>5}')
    return 0


def run_step_time(args) -> int:
    """Run the ``step-time`` subcommand: one line per map size."""
    if args.bag:
        return run_step_time_bag(args)
    args.steps = args.steps or 200
    print(f'EKF-SLAM step = predict + ICNN + update with {OBS} observations '
          f'(BLAS threads: {os.environ["OPENBLAS_NUM_THREADS"]})')
    head = (f'{"N":>4} {"n":>4} {"step ms":>8} {"p90":>6} {"target":>6} {"pred":>6} '
            f'{"assoc":>6} {"upd":>6} {"psd":>6} {"t/t0":>6} {"(n/n0)^2":>8} '
            f'{"dense Joseph":>12} {"dense/ours":>10} {"matched":>7}')
    print(head)
    base = None
    for n_lm in args.landmarks:
        r = bench(n_lm, args.steps, args.seed)
        n = 3 + 2 * n_lm
        if base is None:
            base = (r['step'], n)
        target = TARGET_MS.get(n_lm)
        flag = '' if target is None else ('ok' if r['step'] <= target else 'MISS')
        print(f'{n_lm:>4} {n:>4} {r["step"]:>8.3f} {r["p90"]:>6.2f} '
              f'{(str(target) + " " + flag) if target else "-":>6} {r["predict"]:>6.3f} '
              f'{r["associate"]:>6.3f} {r["update"]:>6.3f} {r["psd"]:>6.3f} '
              f'{r["step"] / base[0]:>6.2f} {(n / base[1]) ** 2:>8.2f} {r["dense"]:>12.3f} '
              f'{r["dense"] / r["update"]:>10.1f} {r["matched"]:>7.1f}')
    return 0


def main(argv=None) -> int:
    """Parse the subcommand and run it."""
    ap, sub = subcommand_parser(__doc__)
    p = sub.add_parser('step-time', help='time of one filter step against the map size')
    p.add_argument('--landmarks', type=int, nargs='+', default=[50, 100, 200])
    p.add_argument('--steps', type=int, default=None,
                   help='timed steps per map size (default 200); with --bag: the first N '
                        'scans (default all)')
    p.add_argument('--threads', default='1', help='BLAS threads (exported before numpy)')
    p.add_argument('--seed', type=int, default=0, help='seed of the random map')
    p.add_argument('--bag', default=None, metavar='DIR',
                   help="time the steps over a recorded bag's /scan and /odom instead (e.g. "
                        'bags/office or an imported log); --landmarks and --seed do not apply')
    p.set_defaults(run=run_step_time)
    p = sub.add_parser('ambiguous', help='ICNN against JCBB on the ambiguous scenario (synthetic '
                                         'only: counting wrong associations needs the true '
                                         'landmark of each observation)')
    p.add_argument('--seeds', default='0-9', help="simulator seeds, e.g. '0-9' or '1,4,7'")
    p.set_defaults(run=run_ambiguous)
    return run_subcommand(ap, argv)


if __name__ == '__main__':
    sys.exit(main())
