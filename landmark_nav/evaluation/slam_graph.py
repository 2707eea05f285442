"""Run the graph back end (:mod:`landmark_nav.slam.keyframe_graph`) on a bag and score it.

``landmark_nav evaluate BAG --backend graph``: the bag's odometry samples and each scan's
returns below ``max_range`` (:func:`landmark_nav.slam.scan_matching.scan_points`) go, in
the bag's order, to :class:`~landmark_nav.slam.graph_scan_steps.GraphScanSteps`, the
per-scan step the ``graph_slam`` node runs: each scan with the odometry interpolated at its
stamp goes to :meth:`KeyframeGraph.add_scan`. Two trajectories are scored against the
reference, with the EKF's metrics (:mod:`.trajectory`, evo's ATE and RPE;
:func:`.slam_scores.ellipse_share`):

* ``online``: each scan's pose as the graph gave it when the scan came (its keyframe's
  estimate then, plus the odometry since), with the keyframe's marginal then: what a node
  would have published;
* ``final``: each scan placed on its keyframe's estimate after the whole run (every loop
  applied), with the keyframes' final marginals: the map's trajectory.

Scans before the first or after the last odometry sample are not used, nor odometry
samples that are not finite (counted by reason in the summary's notes).
"""

from dataclasses import dataclass, field
import json
import math
from pathlib import Path
import time
from typing import Optional

from landmark_nav.evaluation.bags import load_bag
from landmark_nav.evaluation.blas import single_threaded
from landmark_nav.evaluation.slam_scores import ellipse_share
from landmark_nav.evaluation.trajectory import ate, rpe, Trajectory, write_tum
from landmark_nav.sim import OdometrySample, ScanSample
from landmark_nav.slam.graph_scan_steps import GraphScanSteps
from landmark_nav.slam.keyframe_graph import GraphParams, KeyframeGraph
from landmark_nav.slam.scan_matching import scan_points
import numpy as np


@dataclass(frozen=True, eq=False)
class GraphRun:
    """Per-scan record of a graph run (S scans)."""

    stamps: np.ndarray            # (S,) scan stamps [ns]
    odometry: np.ndarray          # (S, 3) odometry at the stamps
    truth: np.ndarray             # (S, 3) reference at the stamps (NaN without one)
    keyframe: np.ndarray          # (S,) keyframe index of each scan
    online: np.ndarray            # (S, 3) pose when the scan came
    online_cov: np.ndarray        # (S, 3, 3)
    final: np.ndarray             # (S, 3) pose after the run
    final_cov: np.ndarray         # (S, 3, 3)
    graph: KeyframeGraph
    seconds: float                # back end time [s]
    skipped: dict = field(default_factory=dict)  # inputs not used, by reason
    not_covered: int = 0          # scans after the last odometry sample


@dataclass(frozen=True)
class _Posed:
    """The fields :func:`ellipse_share` reads."""

    poses: np.ndarray
    truth: np.ndarray
    covariances: np.ndarray


@single_threaded
def run_graph(scenario, noise, params: Optional[GraphParams] = None) -> GraphRun:
    """Run the graph back end over a scenario (module docstring).

    Args:
        scenario: A :class:`~landmark_nav.evaluation.bags.BagScenario` or simulated run.
        noise: The odometry's :class:`~landmark_nav.slam.slam_params.OdometryNoise`.
        params: Graph parameters.
    """
    params = params or GraphParams()
    steps = GraphScanSteps(scenario.laser.mount, noise, params)
    graph = steps.graph
    stamps, odometry, keyframe, online, online_cov = [], [], [], [], []
    seconds = 0.0
    for ev in scenario.events:
        if isinstance(ev, OdometrySample):
            steps.add_odometry(ev.stamp_ns, ev.pose)
        elif isinstance(ev, ScanSample):
            steps.add_scan(ev.stamp_ns, scan_points(ev.ranges, ev.angle_min,
                                                    ev.angle_increment, ev.range_min,
                                                    min(ev.range_max, params.max_range)))
        else:
            continue
        while True:
            tic = time.perf_counter()
            st = steps.step()
            seconds += time.perf_counter() - tic
            if st is None:
                break
            stamps.append(st.stamp_ns)
            odometry.append(st.odometry)
            keyframe.append(st.keyframe)
            online.append(st.pose)
            online_cov.append(st.covariance)
    tic = time.perf_counter()
    kf_cov = graph.final_covariances()
    final, final_cov = [], []
    for k, o in zip(keyframe, odometry):  # the final estimates and marginals
        pose, cov = graph.pose_at(k, o, kf_cov[k])
        final.append(pose)
        final_cov.append(cov)
    seconds += time.perf_counter() - tic
    stamps_a = np.array(stamps, dtype=np.int64)
    return GraphRun(stamps=stamps_a, odometry=np.array(odometry).reshape(-1, 3),
                    truth=scenario.truth_at(stamps_a), keyframe=np.array(keyframe),
                    online=np.array(online).reshape(-1, 3),
                    online_cov=np.array(online_cov).reshape(-1, 3, 3),
                    final=np.array(final).reshape(-1, 3),
                    final_cov=np.array(final_cov).reshape(-1, 3, 3), graph=graph,
                    seconds=seconds, skipped=dict(steps.counts),
                    not_covered=steps.waiting)


def evaluate_graph_bag(bag, out_dir=None, params: Optional[GraphParams] = None,
                       max_seconds: Optional[float] = None, reference=None,
                       align: str = 'se2', laser_pose=None, sigma_r: Optional[float] = None,
                       rpe_delta: float = 1.0, reference_sd=None) -> dict:
    """Run the graph back end on a bag and return its figures (``slam_graph.json``).

    Figures for ``online`` and ``final`` (module docstring): ``<which>_ate_<align>_rmse``,
    ``<which>_rpe_trans_rmse`` / ``<which>_rpe_rot_rmse_deg`` over ``rpe_delta`` m,
    ``<which>_ellipse95_share``; the odometry's ATE and RPE; keyframes, the factors between
    consecutive keyframes by kind, loops proposed / accepted / refused by reason. With
    ``reference_sd`` (the reference's per-pose std along / across its heading [m]) also
    ``<which>_ellipse95_ref_share``: the ellipse with the reference's noise added
    (:func:`.slam_scores.ellipse_share`).
    """
    from landmark_nav.evaluation.slam import bag_odometry_noise
    scenario = load_bag(bag, max_seconds, reference, laser_pose, sigma_r)
    noise, source = bag_odometry_noise(scenario)
    tic = time.perf_counter()
    run = run_graph(scenario, noise, params)
    wall = time.perf_counter() - tic
    g = run.graph
    result = {'bag': str(bag), 'backend': 'graph', 'scans': int(len(run.stamps)),
              'keyframes': len(g.keyframes), 'odometry_noise_source': source,
              'motions': dict(g.motions), 'icp_restarts': dict(g.icp_restarts),
              'loops_proposed': g.loop_counts.proposed,
              'loops_accepted': g.loop_counts.accepted,
              'loops_refused': dict(g.loop_counts.refused), 'align': align,
              'rpe_distance_m': float(rpe_delta), 'notes': list(scenario.notes)}
    for reason, n in sorted(run.skipped.items()):
        result['notes'].append(f'{n} inputs not used: {reason.replace("_", " ")}')
    if run.not_covered:
        result['notes'].append(f'{run.not_covered} scans after the last odometry sample not '
                               'used')
    ref = Trajectory.from_planar(run.stamps, run.truth)
    tracks = {'online': (run.online, run.online_cov), 'final': (run.final, run.final_cov),
              'odom': (run.odometry, None)}
    for name, (poses, covs) in tracks.items():
        traj = Trajectory.from_planar(run.stamps, poses)
        result[f'{name}_ate_{align}_rmse'] = ate(traj, ref, align)['rmse']
        r = rpe(traj, ref, rpe_delta)
        result[f'{name}_rpe_trans_rmse'] = r['rmse']
        result[f'{name}_rpe_rot_rmse_deg'] = r['rot_rmse_deg']
        if covs is not None:
            result[f'{name}_ellipse95_share'] = ellipse_share(_Posed(poses, run.truth, covs))
            if reference_sd is not None:
                result[f'{name}_ellipse95_ref_share'] = ellipse_share(
                    _Posed(poses, run.truth, covs), reference_sd=reference_sd)
    result['seconds_total'] = float(wall)
    result['ms_per_scan'] = 1e3 * run.seconds / max(len(run.stamps), 1)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        for name in ('online', 'final'):
            write_tum(out / f'trajectory_graph_{name}.tum',
                      Trajectory.from_planar(run.stamps, getattr(run, name)))
        write_tum(out / 'trajectory_gt.tum', ref)
        (out / 'slam_graph.json').write_text(json.dumps(result, indent=2))
    return result


def format_graph_summary(r: dict) -> str:
    """Render the main figures of :func:`evaluate_graph_bag` as a few lines."""
    a = r['align']

    def cm(v):
        return 'n/a' if v is None or (isinstance(v, float) and math.isnan(v)) \
            else f'{100 * v:.2f} cm'
    refused = ', '.join(f'{v} {k}' for k, v in r['loops_refused'].items() if v) or 'none'
    lines = [f'{r["bag"]} (graph back end): {r["scans"]} scans, {r["keyframes"]} keyframes; '
             f'factors {r["motions"].get("scan_matching", 0)} scan-matched, '
             f'{r["motions"].get("scan_verified", 0)} scan-verified, '
             f'{r["motions"].get("odometry", 0)} odometry; loops {r["loops_accepted"]} '
             f'accepted of {r["loops_proposed"]} proposed (refused: {refused})']
    lines += [f'note: {n}' for n in r.get('notes', [])]
    for name in ('final', 'online'):
        lines.append(f'{name}: ATE {a} aligned RMSE {cm(r[f"{name}_ate_{a}_rmse"])}, RPE over '
                     f'{r["rpe_distance_m"]:g} m {cm(r[f"{name}_rpe_trans_rmse"])} / '
                     f'{r[f"{name}_rpe_rot_rmse_deg"]:.2f} deg, reference inside the 95 % '
                     f'ellipse {100 * r[f"{name}_ellipse95_share"]:.1f} % of scans')
    lines.append(f'odometry: ATE {a} aligned RMSE {cm(r[f"odom_ate_{a}_rmse"])}, RPE '
                 f'{cm(r["odom_rpe_trans_rmse"])} / {r["odom_rpe_rot_rmse_deg"]:.2f} deg')
    lines.append(f'back end {r["ms_per_scan"]:.2f} ms/scan, total {r["seconds_total"]:.1f} s')
    return '\n'.join(lines)


__all__ = ['evaluate_graph_bag', 'format_graph_summary', 'GraphRun', 'run_graph']
