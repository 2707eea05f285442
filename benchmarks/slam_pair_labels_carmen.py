"""Every EKF-SLAM pair of a Carmen run labelled right or wrong through the reference poses.

Run from the repository root (needs ``../shared/data/carmen``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/slam_pair_labels_carmen.py LOG [--seed 0]
        [--drift none] [--filter-noise pioneer] [--set NAME=VALUE ...] [--jump DEG]
        [--step-error M]

The log is imported as ``landmark_nav import`` does (``--drift none``: the reference's own
increments as odometry) and run with corners and lines through
:func:`landmark_nav.evaluation.slam.run_slam`; ``--filter-noise`` gives the filter that
odometry noise model instead of the bag's, ``--set`` any ``SlamParams`` or
``FrontendParams`` field (a Python literal, e.g. ``--set jacobians="'observability_gain'"
--set spurious_limit=0.05 --set scan_matching=True``).

Each observation is put in the map with the reference pose of its scan. A landmark's
reference is its confirming observation put there the same way; a later pair is *wrong*
when a corner lies more than 30 cm from it, or a line's angle differs by more than 3 deg
or the observed segment's midpoint lies more than 20 cm off the reference line (the
infinite line: a collinear piece of the same wall is right). Labels are approximate: the
reference poses are scan-matched (a few cm), and a short wall's angle is uncertain by
several degrees (the angle error over its stated std is printed to tell).

Printed: the run's share of steps with the reference inside the 95 % position ellipse,
its ATE (unaligned) and the pair counts; the line pairs' normalised angle error (median,
share above 3; under 1 and near 0 for honest covariances); then one row per step with a
wrong pair, a heading-error change above ``--jump`` degrees or a step whose motion is off
the reference's by more than ``--step-error`` metres (step, position and heading error, the
heading std, the step's motion error, the largest position std, pairs right / wrong, and
each wrong pair: landmark id, its offset and its d2).
"""

import argparse
import ast
import math
from pathlib import Path
import sys
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_node_cpu import split_frontend  # noqa: E402
from landmark_nav.evaluation.bags import load_bag  # noqa: E402
from landmark_nav.evaluation.slam import (bag_odometry_noise, run_slam,  # noqa: E402
                                          scan_features)
from landmark_nav.geometry import relative, transform_points, wrap_angle  # noqa: E402
from landmark_nav.importers.writer import import_log  # noqa: E402
from landmark_nav.laser.corners import CornerParams  # noqa: E402
from landmark_nav.laser.lines import LineParams  # noqa: E402
from landmark_nav.sim import ScanSample  # noqa: E402
from landmark_nav.sim.laser import compose as sensor_pose  # noqa: E402
from landmark_nav.slam.ekf_slam import line_noise_covariance, SlamParams  # noqa: E402
from landmark_nav.slam.frontend import odometry_noise_model  # noqa: E402
from landmark_nav.slam.line_landmarks import (line_initialization,  # noqa: E402
                                              lines_to_observations)
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
import numpy as np  # noqa: E402

CORNER_OFF_M = 0.30
LINE_OFF_DEG = 3.0
LINE_OFF_M = 0.20


def label_run(bag: Path, params: SlamParams, frontend=None) -> dict:
    """Run the filter on the bag; return per-step rows and the labelled line pairs."""
    sc = load_bag(bag, require_reference=False)
    cp = CornerParams(sigma_r=float(sc.laser.sigma_range),
                      sigma_phi=float(sc.laser.sigma_angle))
    lp = LineParams(sigma_r=cp.sigma_r, sigma_phi=cp.sigma_phi)
    mount = np.asarray(sc.laser.mount, dtype=float)
    scans = sc.of_type(ScanSample)
    first_corner, first_line = {}, {}  # landmark id -> reference placement
    rows, line_z = [], []

    def callback(k, slam, res):
        corners, lines = scan_features(scans[k], 'both', cp, lp)
        nc = len(corners)
        ref = sc.truth_at(np.array([scans[k].stamp_ns]))[0]
        right, wrong = 0, []
        if nc:
            xy = np.array([c.position for c in corners]).reshape(-1, 2)
            world = transform_points(sensor_pose(ref, tuple(mount)), xy)
        if lines:
            obs = lines_to_observations(lines, mount, None, lp.sigma_r)
            g = line_initialization(ref, obs.z)[0]
            r = obs.r + line_noise_covariance(params, obs.z, obs.ends, obs.residual_std)
            mids = transform_points(tuple(ref), obs.ends.mean(axis=1))
        for i, (status, lid) in enumerate(zip(res.status, res.landmark_id.tolist())):
            if i < nc:
                if status == 'confirmed':
                    first_corner[lid] = world[i]
                elif status == 'matched' and lid in first_corner:
                    off = float(np.hypot(*(world[i] - first_corner[lid])))
                    if off > CORNER_OFF_M:
                        wrong.append(f'corner {lid} {off:.2f} m d2 {res.d2[i]:.1f}')
                    else:
                        right += 1
                continue
            q = i - nc
            if status == 'confirmed':
                first_line[lid] = (g[q, 1], mids[q], math.sqrt(r[q, 1, 1]))
            elif status == 'matched' and lid in first_line:
                alpha, mid, sd = first_line[lid]
                da = float(wrap_angle(g[q, 1] - alpha))
                off = abs(float(np.array([math.cos(alpha), math.sin(alpha)]) @ (mids[q] - mid)))
                line_z.append(abs(da) / math.hypot(sd, math.sqrt(r[q, 1, 1])))
                if abs(math.degrees(da)) > LINE_OFF_DEG or off > LINE_OFF_M:
                    wrong.append(f'line {lid} {math.degrees(da):+.1f} deg {off:.2f} m '
                                 f'd2 {res.d2[i]:.1f}')
                else:
                    right += 1
        rows.append((right, wrong))

    run = run_slam(sc, params, cp, callback=callback, landmarks='both', frontend=frontend)
    return {'run': run, 'rows': rows, 'line_z': np.array(line_z)}


def main() -> int:
    """Import, run, label, print."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('log')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--drift', default=None)
    ap.add_argument('--filter-noise', default=None)
    ap.add_argument('--set', action='append', default=[], metavar='NAME=VALUE')
    ap.add_argument('--jump', type=float, default=1.5,
                    help='also print steps whose heading error changes by more [deg]')
    ap.add_argument('--step-error', type=float, default=math.inf,
                    help='also print steps whose motion differs from the reference motion '
                         'by more [m] (the RPE jumps)')
    args = ap.parse_args()
    carmen = SHARED_DATA / 'carmen'
    if not carmen.is_dir():
        print(f'missing {carmen}', file=sys.stderr)
        return 1
    extra = {}
    for item in args.set:
        key, _, value = item.partition('=')
        extra[key] = ast.literal_eval(value)
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / args.log
        import_log(carmen / f'{args.log}-corrected.log.gz', bag, seed=args.seed,
                   drift=args.drift)
        noise = (odometry_noise_model(args.filter_noise) if args.filter_noise else
                 bag_odometry_noise(load_bag(bag, require_reference=False))[0])
        extra, frontend = split_frontend(extra)
        out = label_run(bag, SlamParams(odometry=noise, **extra), frontend)
    run, rows, line_z = out['run'], out['rows'], out['line_z']
    err = run.poses - run.truth
    err[:, 2] = wrap_angle(err[:, 2])
    cov = run.covariances
    d2 = np.einsum('ki,ki->k', err[:, :2],
                   np.linalg.solve(cov[:, :2, :2], err[:, :2, None])[:, :, 0])
    right = sum(r for r, _ in rows)
    wrong = sum(len(w) for _, w in rows)
    print(f'{args.log} seed {args.seed}: {len(err)} steps, reference inside the 95 % '
          f'ellipse {np.mean(d2 <= 5.991):.3f}, ATE (unaligned) '
          f'{math.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1))):.2f} m; pairs right '
          f'{right}, wrong {wrong}')
    if line_z.size:
        print(f'line pairs {line_z.size}: angle error / stated std median '
              f'{np.median(line_z):.2f}, above 3 on {np.mean(line_z > 3):.3f}')
    psi = np.degrees(err[:, 2])
    p, t = run.poses, run.truth
    for k, (ok, bad) in enumerate(rows[:len(err)]):
        change = psi[k] - (psi[k - 1] if k else 0.0)
        step = (math.hypot(*(relative(p[k - 1], p[k])[:2] - relative(t[k - 1], t[k])[:2]))
                if k else 0.0)
        if bad or abs(change) > args.jump or step > args.step_error:
            print(f'{k:5d} pos {math.hypot(*err[k, :2]):6.2f} m psi {psi[k]:7.2f} '
                  f'({change:+6.2f}) sd {math.degrees(math.sqrt(cov[k, 2, 2])):5.2f} deg '
                  f'step error {step:5.2f} m position sd '
                  f'{math.sqrt(max(np.linalg.eigvalsh(cov[k, :2, :2]))):6.2f} m '
                  f'right {ok:2d} wrong {len(bad)} {"; ".join(bad)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
