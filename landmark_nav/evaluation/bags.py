"""``landmark_nav evaluate <bag>``: run EKF-SLAM on a simulator bag and score it.

Reads ``/odom``, ``/scan`` and ``/ground_truth/odom`` of a bag recorded by ``landmark_nav
simulate`` (no DDS) plus the ``ground_truth.yaml`` beside it, and wraps them in a
:class:`BagScenario` that looks like a simulated
:class:`~landmark_nav.sim.scenarios.ScenarioResult` to
:func:`landmark_nav.slam.evaluate.run_slam` and :func:`~landmark_nav.slam.evaluate.score_run`:
the bag path and the simulated path run the same per-scan code (corner extractor with the
bag's laser noise, odometry check, predict, update) and the same scoring. On top of those
scores this module adds the RPE, the real-time factor, TUM trajectories, ``slam.json`` and
two figures like Fig. 19 of the chapter (``slam_map.png``, ``slam_errors.png``).
"""

from dataclasses import asdict, dataclass, fields
import json
import math
from pathlib import Path
import time
from typing import Dict, List, Optional

from landmark_nav.bag import BagReader
from landmark_nav.conversions import odometry_to_pose, scan_to_data
from landmark_nav.geometry import covariance_ellipse, interpolate_pose
from landmark_nav.laser.corners import CornerParams
from landmark_nav.sim.laser import LaserConfig, ScanSample
from landmark_nav.sim.record import load_ground_truth
from landmark_nav.sim.scenarios import OdometrySample
from landmark_nav.sim.world import World
from landmark_nav.slam.ekf_slam import SlamParams
from landmark_nav.slam.evaluate import run_slam, score_run, SlamRun
import numpy as np

ASSOCIATIONS = ('icnn', 'jcbb')
RPE_DISTANCE_M = 1.0
TOPICS = ('/odom', '/scan', '/ground_truth/odom')


class BagScenario:
    """A simulator bag seen through the interface ``run_slam`` / ``score_run`` use.

    Attributes:
        name: bag path (also the cache key of the visible-corner count).
        world: ground-truth world.
        laser: laser configuration (mount, noise).
        robot: None (not needed for SLAM).
        events: odometry and scan samples in time order.
    """

    def __init__(self, name: str, world: World, laser: LaserConfig, events: List,
                 truth_stamps: np.ndarray, truth_poses: np.ndarray) -> None:
        """Wrap the decoded bag content."""
        self.name = name
        self.world = world
        self.laser = laser
        self.robot = None
        self.events = events
        self._t = np.asarray(truth_stamps, dtype=np.int64)
        self._rel = (self._t - self._t[0]).astype(float)
        self._poses = np.asarray(truth_poses, dtype=float)

    @property
    def start_ns(self) -> int:
        """Stamp of the first ground-truth pose."""
        return int(self._t[0])

    @property
    def end_ns(self) -> int:
        """Stamp of the last ground-truth pose."""
        return int(self._t[-1])

    def truth_at(self, stamp_ns) -> np.ndarray:
        """Return the true pose(s) interpolated at stamp(s) [ns]."""
        s = np.asarray(stamp_ns, dtype=np.int64)
        out = interpolate_pose(np.atleast_1d(s - self._t[0]).astype(float), self._rel,
                               self._poses)
        return out[0] if s.ndim == 0 else out

    def of_type(self, cls: type) -> List:
        """Events of one type, in time order."""
        return [e for e in self.events if type(e) is cls]


@dataclass(frozen=True)
class _Stamped:
    stamp_ns: int
    pose: np.ndarray


def _laser_config(meta: dict) -> LaserConfig:
    cfg = dict(meta['laser'])
    names = {f.name for f in fields(LaserConfig)}
    cfg = {k: v for k, v in cfg.items() if k in names}
    cfg['mount'] = tuple(float(v) for v in cfg.get('mount', (0.0, 0.0, 0.0)))
    return LaserConfig(**cfg)


def load_bag(bag, max_seconds: Optional[float] = None) -> BagScenario:
    """Read a simulator bag into a :class:`BagScenario`.

    Args:
        bag: rosbag2 directory recorded by ``landmark_nav simulate``.
        max_seconds: Keep only the first seconds of odometry / scans (None: all).

    Returns:
        The scenario; scans outside the odometry and ground-truth time span are dropped.

    Raises:
        ValueError: No ground truth / laser, or a required topic is missing or empty.
    """
    meta = load_ground_truth(bag)
    if not meta.get('laser'):
        raise ValueError(f'{bag} was recorded without a laser')
    if not meta.get('world'):
        raise ValueError(f'{bag}: ground_truth.yaml has no world')
    world = World.from_dict(meta['world'])
    laser = _laser_config(meta)
    odo, scans, truth = [], [], []
    with BagReader(bag) as reader:
        topics = reader.topics()
        for t in TOPICS:
            if t not in topics or topics[t].count == 0:
                raise ValueError(f'{bag} has no {t} messages')
        for topic, _, msg in reader.decoded(list(TOPICS)):
            if topic == '/scan':
                d = scan_to_data(msg)
                scans.append(ScanSample(
                    stamp_ns=int(d.stamp_ns), ranges=np.asarray(d.ranges, dtype=np.float32),
                    angle_min=float(d.angle_min), angle_max=float(d.angle_max),
                    angle_increment=float(d.angle_increment),
                    time_increment=float(d.time_increment), scan_time=float(d.scan_time),
                    range_min=float(d.range_min), range_max=float(d.range_max),
                    true_ranges=None))
            else:
                p = odometry_to_pose(msg)
                (odo if topic == '/odom' else truth).append(_Stamped(int(p.stamp_ns), p.pose))
    odo.sort(key=lambda e: e.stamp_ns)
    truth.sort(key=lambda e: e.stamp_ns)
    ts = np.array([e.stamp_ns for e in truth], dtype=np.int64)
    if np.any(np.diff(ts) <= 0) or np.any(np.diff([e.stamp_ns for e in odo]) <= 0):
        raise ValueError(f'{bag}: duplicate stamps in /odom or /ground_truth/odom')
    t_end = min(odo[-1].stamp_ns, ts[-1])
    if max_seconds is not None:
        t_end = min(t_end, odo[0].stamp_ns + int(max_seconds * 1e9))
    odo = [e for e in odo if e.stamp_ns <= t_end or e is odo[0]]
    zero3 = np.zeros(3)
    events = [OdometrySample(stamp_ns=e.stamp_ns, pose=np.asarray(e.pose, dtype=float),
                             covariance=np.zeros((3, 3)), twist=zero3,
                             wheel_velocities=np.zeros(2), wheel_positions=np.zeros(2))
              for e in odo]
    t_start = max(odo[0].stamp_ns, ts[0])
    sweep = [int(round(len(s.ranges) * s.time_increment * 1e9)) for s in scans]
    events += [s for s, w in zip(scans, sweep)
               if t_start <= s.stamp_ns and s.stamp_ns + w <= t_end]
    events.sort(key=lambda e: e.stamp_ns)
    if not any(type(e) is ScanSample for e in events):
        raise ValueError(f'{bag}: no /scan message inside the odometry / ground-truth span')
    return BagScenario(str(bag), world, laser, events, ts,
                       np.array([e.pose for e in truth]))


def relative_pose_error(est: np.ndarray, truth: np.ndarray,
                        distance: float = RPE_DISTANCE_M) -> Dict[str, float]:
    """RPE: error of the relative motion over ``distance`` of true travel.

    Args:
        est: (S, 3) estimated poses.
        truth: (S, 3) true poses.
        distance: True path length of each pair [m].

    Returns:
        {'trans_rmse', 'trans_max' [m], 'rot_rmse_deg', 'pairs'}.
    """
    d = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(truth[:, :2], axis=0).T))])
    j = np.searchsorted(d, d + distance)
    i = np.nonzero(j < len(d))[0]
    if i.size == 0:
        return {'trans_rmse': math.nan, 'trans_max': math.nan, 'rot_rmse_deg': math.nan,
                'pairs': 0}
    j = j[i]

    def rel(p):
        dx, dy = (p[j, :2] - p[i, :2]).T
        c, s = np.cos(p[i, 2]), np.sin(p[i, 2])
        return np.column_stack([c * dx + s * dy, -s * dx + c * dy]), p[j, 2] - p[i, 2]

    te, re_ = rel(est)
    tt, rt = rel(truth)
    et = np.hypot(*(te - tt).T)
    er = np.angle(np.exp(1j * (re_ - rt)))
    return {'trans_rmse': float(np.sqrt(np.mean(et ** 2))), 'trans_max': float(et.max()),
            'rot_rmse_deg': float(np.degrees(np.sqrt(np.mean(er ** 2)))),
            'pairs': int(i.size)}


def write_tum(path: Path, stamps_ns: np.ndarray, poses: np.ndarray) -> None:
    """Write a TUM trajectory ``t x y z qx qy qz qw`` (planar: z = qx = qy = 0)."""
    with open(path, 'w') as f:
        for t, (x, y, yaw) in zip(stamps_ns, poses):
            f.write(f'{int(t) // 10**9}.{int(t) % 10**9:09d} {x:.6f} {y:.6f} 0.0 0.0 0.0 '
                    f'{math.sin(0.5 * yaw):.9f} {math.cos(0.5 * yaw):.9f}\n')


def plot_run(scenario: BagScenario, run: SlamRun, out_dir: Path, title: str) -> None:
    """Write ``slam_map.png`` and ``slam_errors.png`` (Fig. 19 of the chapter)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 7.5))
    for x1, y1, x2, y2 in scenario.world.walls().segments:
        ax.plot([x1, x2], [y1, y2], color='0.4', lw=1.5)
    tc = scenario.world.corners().positions
    ax.plot(tc[:, 0], tc[:, 1], 'k+', ms=9, label='true corners')
    ax.plot(run.truth[:, 0], run.truth[:, 1], 'g-', lw=1, label='ground truth')
    ax.plot(run.odometry[:, 0], run.odometry[:, 1], 'r:', lw=1, label='odometry')
    ax.plot(run.poses[:, 0], run.poses[:, 1], 'b-', lw=1, label='EKF-SLAM')
    if run.landmarks.shape[0]:
        ax.plot(run.landmarks[:, 0], run.landmarks[:, 1], 'bo', mfc='none', ms=5,
                label='mapped landmarks (2 sigma)')
        for m, c in zip(run.landmarks, run.landmark_covariances):
            e = covariance_ellipse(m, c)
            ax.plot(e[:, 0], e[:, 1], 'b-', lw=0.8)
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(title)
    ax.legend(loc='best', fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / 'slam_map.png', dpi=120)
    plt.close(fig)

    t = (run.stamps - run.stamps[0]) * 1e-9
    err = run.poses - run.truth
    err[:, 2] = np.angle(np.exp(1j * err[:, 2]))
    sig = np.sqrt(np.maximum(np.diagonal(run.covariances, axis1=1, axis2=2), 0.0))
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    scale = (100.0, 100.0, 180.0 / math.pi)
    for k, (ax, lab) in enumerate(zip(axes, ('x error [cm]', 'y error [cm]',
                                             'psi error [deg]'))):
        ax.plot(t, scale[k] * err[:, k], 'b-', lw=1, label='error')
        ax.plot(t, 2 * scale[k] * sig[:, k], 'r--', lw=0.8, label='+-2 sigma')
        ax.plot(t, -2 * scale[k] * sig[:, k], 'r--', lw=0.8)
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc='upper right', fontsize=8)
    axes[-1].set_xlabel('time [s]')
    axes[0].set_title(title)
    fig.tight_layout()
    fig.savefig(out_dir / 'slam_errors.png', dpi=120)
    plt.close(fig)


def evaluate_bag(bag, association: str = 'icnn', out_dir=None, progress: bool = True,
                 params: Optional[SlamParams] = None,
                 max_seconds: Optional[float] = None) -> dict:
    """Run EKF-SLAM over a simulator bag and score it against the ground truth.

    Args:
        bag: rosbag2 directory recorded by ``landmark_nav simulate``.
        association: ``'icnn'`` or ``'jcbb'``.
        out_dir: Directory for the TUM files, ``slam.json`` and the PNGs (None: nothing
            written).
        progress: Show a tqdm progress bar.
        params: Filter parameters (default :class:`SlamParams`; ``association`` wins).
        max_seconds: Use only the first seconds of the bag.

    Returns:
        The figures (see ``slam.json``).

    Raises:
        ValueError: Bad association or unusable bag (one-line message).
    """
    if association not in ASSOCIATIONS:
        raise ValueError(f'association must be one of {", ".join(ASSOCIATIONS)}, '
                         f'got {association!r}')
    if not Path(bag).is_dir():
        raise ValueError(f'{bag} is not a bag directory')
    scenario = load_bag(bag, max_seconds)
    prm = params or SlamParams()
    prm = SlamParams(**{**{f.name: getattr(prm, f.name) for f in fields(SlamParams)},
                        'association': association})
    corner_params = CornerParams(sigma_r=float(scenario.laser.sigma_range),
                                 sigma_phi=float(scenario.laser.sigma_angle))
    n_scans = len(scenario.of_type(ScanSample))
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n_scans, unit='scan', desc=f'{Path(bag).name} {association}')
    callback = None if bar is None else (lambda k, slam, res: bar.update(1))
    tic = time.perf_counter()
    try:
        run = run_slam(scenario, prm, corner_params, callback=callback)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - tic
    score = score_run(scenario, run, prm)
    duration = (run.stamps[-1] - run.stamps[0]) * 1e-9 + 1.0 / float(scenario.laser.rate_hz)
    result = {'bag': str(bag), 'association': association, 'scans': int(len(run.stamps)),
              'duration_s': float(duration), 'resets': int(run.resets)}
    result.update({k: (None if isinstance(v, float) and math.isnan(v) else v)
                   for k, v in asdict(score).items()})
    result['rpe_distance_m'] = RPE_DISTANCE_M
    for key, poses in (('rpe', run.poses), ('odom_rpe', run.odometry)):
        for k, v in relative_pose_error(poses, run.truth).items():
            result[f'{key}_{k}'] = v
    result['ate_improvement'] = (score.odom_ate_rmse / score.ate_rmse
                                 if score.ate_rmse > 0 else None)
    result['seconds_total'] = float(wall)
    result['ms_per_step_total'] = 1e3 * wall / max(len(run.stamps), 1)
    result['real_time_factor'] = float(duration / wall) if wall > 0 else None
    result['filter_real_time_factor'] = (float(duration / run.seconds) if run.seconds > 0
                                         else None)
    result['stats'] = {k: int(v) for k, v in run.stats.items()}
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_tum(out / 'trajectory_slam.tum', run.stamps, run.poses)
        write_tum(out / 'trajectory_odom.tum', run.stamps, run.odometry)
        write_tum(out / 'trajectory_gt.tum', run.stamps, run.truth)
        (out / 'slam.json').write_text(json.dumps(result, indent=2))
        plot_run(scenario, run, out, f'EKF-SLAM ({association}) on {Path(bag).name}: ATE '
                 f'{100 * score.ate_rmse:.1f} cm, odometry {100 * score.odom_ate_rmse:.1f} cm')
    return result


def format_summary(r: dict) -> str:
    """Render the main figures as a few lines of text."""
    def cm(v):
        return 'n/a' if v is None else f'{100 * v:.2f} cm'
    return '\n'.join([
        f'{r["bag"]} ({r["association"]}): {r["scans"]} scans, {r["duration_s"]:.1f} s',
        f'ATE RMSE {cm(r["ate_rmse"])} (max {cm(r["ate_max"])}); odometry '
        f'{cm(r["odom_ate_rmse"])} (max {cm(r["odom_ate_max"])})',
        f'RPE over {r["rpe_distance_m"]:g} m: {cm(r["rpe_trans_rmse"])} / '
        f'{r["rpe_rot_rmse_deg"]:.2f} deg (odometry {cm(r["odom_rpe_trans_rmse"])})',
        f'landmarks: {r["mapped"]} mapped / {r["true_visible"]} true visible, RMSE '
        f'{cm(r["landmark_rmse"])}, ghosts {r["ghost_landmarks"]}, duplicates '
        f'{r["duplicates"]}',
        f'associations {r["associations"]}, wrong {r["wrong_associations"]}; NEES in 95 % '
        f'band {100 * r["nees_share_band"]:.1f} %',
        f'filter {r["ms_per_scan"]:.2f} ms/step, total {r["ms_per_step_total"]:.2f} ms/step, '
        f'real-time factor {r["real_time_factor"]:.0f}x'])


def run(bag, association: str = 'icnn', out_dir=None) -> str:
    """Evaluate with a progress bar and return the summary text (CLI entry)."""
    return format_summary(evaluate_bag(bag, association, out_dir, progress=True))


__all__ = ['BagScenario', 'evaluate_bag', 'format_summary', 'load_bag', 'relative_pose_error',
           'run', 'write_tum']
