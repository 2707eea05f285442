"""Rendered hallway runs of the monocular model localizer (self-localization chapter §5-6).

The robot drives the ``hallway`` scenario (:mod:`landmark_nav.sim.scenarios`: 21.5 m x 2 m,
door niches, 20 m along the hallway) with its drifting nominal odometry; the camera images
are rendered from the true poses on the textured hallway model
(:mod:`landmark_nav.sim.model_scene`) with people walking, unmodelled door frames, slow
lighting changes (exposure and an illumination gradient) and pixel noise. The localizer
(:class:`~landmark_nav.monocular.localizer.ModelLocalizer`) predicts with the calibrated
odometry increments (the scenario's true k1, k2, k3, as a calibration would find them) and
updates with every image.

Start: the chapter starts at one end of its hallway heading along it with
``Sigma_p0 = diag(0.3 dm^2, 0.3 dm^2, 0.008 rad^2)``; the scenario starts at
``(0.75, 0, 0)``, and the initial estimate is drawn from ``N(truth, Sigma_p0)`` with the run
seed (or set ``offset`` for a fixed error).

Figures per run: position / heading error over all frames (max, RMS), NEES (the fraction of
frames inside the 95 % chi-square bound, 3 dof), lost episodes, time per frame of the line
detector and of the filter, and the distance travelled before the error stays within
5 cm / 1 deg. ``python -m landmark_nav.evaluation.model_localization --seeds 10`` prints
the table (``--method`` picks the line source; ``--cover`` covers the camera);
``--write-bag DIR --duration S`` records a run as a small bag instead, and ``--sigma-px S``
prints the calibration table of the image line noise (:func:`pair_residuals`).
"""

import argparse
from dataclasses import dataclass, field, replace
import math
import sys
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from landmark_nav.geometry import wrap_angle
from landmark_nav.localization.odometry import calibrate_control, control_from_poses
from landmark_nav.monocular.localizer import (CHAPTER_START_COV, LocalizerParams, LOST,
                                              ModelLocalizer)
from landmark_nav.monocular.matching import (align_cov, image_line_covariance, innovation,
                                             predict_lines)
from landmark_nav.monocular.model import hallway_model, LineModel
from landmark_nav.monocular.visibility import (camera_pose, CameraMount, Intrinsics,
                                               VisibleLines)
from landmark_nav.sim.camera import CameraSimulator, Photometry, RenderOptions
from landmark_nav.sim.model_scene import (door_frame_planes, model_planes, scene_at,
                                          SceneClutter)
from landmark_nav.sim.scenarios import OdometrySample, run_scenario
from landmark_nav.vision.camera import CameraModel
from landmark_nav.vision.rwrht import detect_model_lines, MODEL_LINE_METHODS
import numpy as np

NS = 1_000_000_000


@dataclass(frozen=True)
class HallwayRunConfig:
    """One rendered hallway run.

    Attributes:
        method: line source (:data:`MODEL_LINE_METHODS`).
        camera_rate: images per second (odometry runs at 10 Hz).
        mount: camera mount.
        intrinsics: camera (default: the chapter's 320 x 240 calibration).
        clutter: people and door frames.
        noise_sigma: pixel noise std [grey levels].
        lighting: amplitude of the slow exposure change (+-) and of the gradient.
        cover: ``(t0, t1)`` [s from the start]: the camera is covered (dark frames).
        offset: fixed initial error ``(dx, dy, dphi)`` instead of a draw from ``init_cov``.
        init_cov: the initial covariance given to the filter (default: the chapter's).
        max_frames: stop after this many frames (0: the whole run).
        supersample: renderer supersampling (4: edges within 0.05 px, see
            :func:`~landmark_nav.sim.model_scene.model_planes`).
        localizer: filter parameters.
    """

    method: str = 'rwrht'
    camera_rate: float = 5.0
    mount: CameraMount = field(default_factory=CameraMount)
    intrinsics: Intrinsics = field(default_factory=Intrinsics.chapter)
    clutter: SceneClutter = field(default_factory=SceneClutter)
    noise_sigma: float = 2.0
    lighting: float = 0.25
    cover: Optional[Tuple[float, float]] = None
    offset: Optional[Tuple[float, float, float]] = None
    init_cov: Tuple[float, ...] = tuple(CHAPTER_START_COV.ravel())
    max_frames: int = 0
    supersample: int = 4
    localizer: LocalizerParams = field(default_factory=LocalizerParams)


@dataclass(frozen=True, eq=False)
class HallwayRun:
    """Per-frame results of one run (F frames).

    Attributes:
        t: (F,) time since the start [s].
        travelled: (F,) true distance travelled [m].
        truth, estimate: (F, 3) poses.
        cov: (F, 3, 3) covariances.
        lost: (F,) bool, the filter reported lost.
        matches: (F,) pairs used.
        n_lines: (F,) image lines.
        line_ms, filter_ms: (F,) time per frame of the line detector / the filter [ms].
    """

    t: np.ndarray
    travelled: np.ndarray
    truth: np.ndarray
    estimate: np.ndarray
    cov: np.ndarray
    lost: np.ndarray
    matches: np.ndarray
    n_lines: np.ndarray
    line_ms: np.ndarray
    filter_ms: np.ndarray

    @property
    def position_error(self) -> np.ndarray:
        """(F,) position error [m]."""
        d = self.estimate[:, :2] - self.truth[:, :2]
        return np.hypot(d[:, 0], d[:, 1])

    @property
    def heading_error(self) -> np.ndarray:
        """(F,) absolute heading error [rad]."""
        return np.abs(wrap_angle(self.estimate[:, 2] - self.truth[:, 2]))

    @property
    def nees(self) -> np.ndarray:
        """(F,) normalised estimation error squared."""
        e = self.estimate - self.truth
        e[:, 2] = wrap_angle(e[:, 2])
        return np.einsum('fi,fij,fj->f', e, np.linalg.inv(self.cov), e)

    def lost_episodes(self) -> List[Tuple[float, float]]:
        """``(start, end)`` times [s] of the lost episodes (end = inf if never recovered)."""
        out = []
        start = None
        for t, lost in zip(self.t, self.lost):
            if lost and start is None:
                start = t
            elif not lost and start is not None:
                out.append((float(start), float(t)))
                start = None
        if start is not None:
            out.append((float(start), math.inf))
        return out

    def converged_after(self, pos_tol: float = 0.05, head_tol: float = math.radians(1.0)
                        ) -> float:
        """Return the true distance [m] travelled before the error stays within the tolerances."""
        bad = (self.position_error > pos_tol) | (self.heading_error > head_tol)
        if not bad.any():
            return 0.0
        last = int(np.nonzero(bad)[0][-1])
        if last + 1 >= bad.size:
            return math.inf
        return float(self.travelled[last + 1])


def _photometry(t: float, cfg: HallwayRunConfig, covered: bool) -> Photometry:
    if covered:
        return Photometry(exposure=0.03, noise_sigma=cfg.noise_sigma)
    a = cfg.lighting
    return Photometry(exposure=1.0 + a * math.sin(2 * math.pi * t / 17.0),
                      gradient=(a * 0.6 * math.sin(2 * math.pi * t / 23.0), 0.0),
                      vignetting=0.2, gamma=1.0, noise_sigma=cfg.noise_sigma,
                      shot_noise=0.05)


def _hallway_setup(seed: int, cfg: 'HallwayRunConfig', model: Optional[LineModel]):
    """Return (model, scenario, odometry, camera, renderer, static planes, rng) of a run."""
    model = hallway_model() if model is None else model
    scen = run_scenario('hallway', seed, laser=None, sonar=None)
    odo: List[OdometrySample] = scen.of_type(OdometrySample)
    K = cfg.intrinsics
    cam = CameraModel(K.width, K.height, K.K, np.zeros(5))
    sim = CameraSimulator(cam, RenderOptions(supersample=cfg.supersample))
    static = model_planes(model, seed) + (door_frame_planes(model)
                                          if cfg.clutter.door_frames else [])
    return model, scen, odo, cam, sim, static, np.random.default_rng(seed + 1000)


def run_hallway(seed: int, cfg: HallwayRunConfig = HallwayRunConfig(),
                model: Optional[LineModel] = None) -> HallwayRun:
    """Simulate one rendered hallway run and localize along it (module docstring)."""
    return run_hallway_methods(seed, (cfg.method,), cfg, model)[cfg.method]


def run_hallway_methods(seed: int, methods: Sequence[str],
                        cfg: HallwayRunConfig = HallwayRunConfig(),
                        model: Optional[LineModel] = None,
                        on_update: Optional[Callable] = None) -> Dict[str, HallwayRun]:
    """Localize one rendered hallway run with several line sources side by side.

    ``on_update(method, localizer, result, segments, truth)``, if given, is called after
    every image update (e.g. :func:`pair_residuals`).

    Every source gets its own filter and its own RWRHT random stream (seed + 2000), so its
    run equals :func:`run_hallway` with ``cfg.method`` set to it; the frames are rendered
    once and the sources take turns in a rotating order on each frame, so their times per
    frame see the same machine load (``cfg.method`` is ignored).
    """
    for method in methods:
        if method not in MODEL_LINE_METHODS:
            raise ValueError(f'unknown line method {method!r}')
    model, scen, odo, cam, sim, static, rng = _hallway_setup(seed, cfg, model)
    robot = scen.robot
    K = cfg.intrinsics
    t0 = odo[0].stamp_ns
    truth0 = scen.truth_at(t0)
    if cfg.offset is not None:
        start = truth0 + np.asarray(cfg.offset, dtype=float)
    else:
        start = rng.multivariate_normal(truth0, np.reshape(cfg.init_cov, (3, 3)))
    locs, det_rngs = {}, {}
    for method in methods:
        locs[method] = ModelLocalizer(model, K, cfg.mount, cfg.localizer)
        locs[method].reset(start, np.reshape(cfg.init_cov, (3, 3)), 0.0)
        det_rngs[method] = np.random.default_rng(seed + 2000)   # RWRHT's draws: the frames
    every = max(1, int(round(10.0 / cfg.camera_rate)))          # do not depend on the source
    k_cal = (robot.k1, robot.k2, robot.k3)
    rows = {method: [] for method in methods}
    travelled = 0.0
    prev_truth = truth0
    frame = 0
    for i in range(1, len(odo)):
        u = calibrate_control(control_from_poses(odo[i - 1].pose, odo[i].pose),
                              robot.axle_length, k_cal)
        for loc in locs.values():
            loc.predict(u)
        stamp = odo[i].stamp_ns
        truth = scen.truth_at(stamp)
        travelled += float(np.hypot(*(truth[:2] - prev_truth[:2])))
        prev_truth = truth
        if i % every:
            continue
        t = (stamp - t0) / NS
        covered = cfg.cover is not None and cfg.cover[0] <= t < cfg.cover[1]
        R, c = camera_pose(truth, cfg.mount)
        img = sim.render(scene_at(static, cfg.clutter, t, 21.5, seed), R, c,
                         _photometry(t, cfg, covered), rng)
        truth_w = truth.copy()
        truth_w[2] = wrap_angle(truth_w[2])
        for k in range(len(methods)):
            method = methods[(frame + k) % len(methods)]
            tic = time.perf_counter()
            lines = detect_model_lines(img, method, rng=det_rngs[method])
            toc = time.perf_counter()
            res = locs[method].update(lines.segments, t)
            tac = time.perf_counter()
            if on_update is not None:
                on_update(method, locs[method], res, lines.segments, truth_w)
            rows[method].append((t, travelled, truth_w, res.pose, res.cov, res.status == LOST,
                                 len(res.matches) if res.matches is not None and res.updated
                                 else 0, len(lines), 1e3 * (toc - tic), 1e3 * (tac - toc)))
        frame += 1
        if cfg.max_frames and frame >= cfg.max_frames:
            break
    out = {}
    for method, r in rows.items():
        cols = list(zip(*r))
        out[method] = HallwayRun(np.array(cols[0]), np.array(cols[1]), np.array(cols[2]),
                                 np.array(cols[3]), np.array(cols[4]),
                                 np.array(cols[5], dtype=bool), np.array(cols[6]),
                                 np.array(cols[7]), np.array(cols[8]), np.array(cols[9]))
    return out


def write_hallway_bag(path, seed: int, duration_s: float,
                      cfg: HallwayRunConfig = HallwayRunConfig(),
                      model: Optional[LineModel] = None) -> int:
    """Record the start of a rendered hallway run as a rosbag2 (MCAP) directory.

    Topics: ``/odom`` (10 Hz, the drifting nominal odometry), ``/ground_truth/odom``,
    ``/camera/camera_info`` and ``/camera/image_raw`` (mono8 at ``cfg.camera_rate``),
    rendered as in :func:`run_hallway` (clutter, lighting, noise, ``cfg.cover``).

    Returns:
        The number of images written.
    """
    from landmark_nav.bag.writer import BagWriter
    from landmark_nav.conversions import array_to_image, make_camera_info, make_odometry
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import CameraInfo, Image
    model, scen, odo, cam, sim, static, rng = _hallway_setup(seed, cfg, model)
    every = max(1, int(round(10.0 / cfg.camera_rate)))
    t0 = odo[0].stamp_ns
    n = 0
    with BagWriter(path) as bag:
        bag.add_topic('/odom', Odometry)
        bag.add_topic('/ground_truth/odom', Odometry)
        bag.add_topic('/camera/camera_info', CameraInfo)
        bag.add_topic('/camera/image_raw', Image)
        for i, sample in enumerate(odo):
            stamp = sample.stamp_ns
            t = (stamp - t0) / NS
            if t > duration_s:
                break
            truth = scen.truth_at(stamp)
            bag.write('/odom', stamp, make_odometry(stamp, 'odom', 'base_link', sample.pose))
            bag.write('/ground_truth/odom', stamp,
                      make_odometry(stamp, 'map', 'base_link', truth))
            if i % every:
                continue
            covered = cfg.cover is not None and cfg.cover[0] <= t < cfg.cover[1]
            R, c = camera_pose(truth, cfg.mount)
            img = sim.render(scene_at(static, cfg.clutter, t, 21.5, seed), R, c,
                             _photometry(t, cfg, covered), rng)
            bag.write('/camera/camera_info', stamp, make_camera_info(cam, stamp, 'camera'))
            bag.write('/camera/image_raw', stamp, array_to_image(img, 'mono8', stamp, 'camera'))
            n += 1
    return n


def pair_residuals(seeds: Sequence[int], cfg: HallwayRunConfig = HallwayRunConfig()
                   ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Residuals at the true pose of the pairs the filter kept, for calibrating ``sigma_px``.

    Returns:
        ``(nu (K, 2), V1 (K, 2, 2), model_cov (K, 2, 2))``: the pairs' Hough residuals
        against the model lines projected at the true pose, their image line covariance
        for an end-point noise of 1 px and the model noise, so that the pairs' ``d^2`` for
        a given ``sigma_px`` is ``nu^T (sigma_px^2 V1 + model_cov)^-1 nu``
        (:func:`sigma_px_table`).
    """
    nus, v1s, mcs = [], [], []

    def collect(method, loc, res, segments, truth):
        m = res.matches
        if not res.updated or m is None or len(m) == 0:
            return
        pr = res.predicted
        vis = VisibleLines(pr.visible.index[m.model], pr.visible.points[m.model],
                           np.zeros((len(m), 4)))
        lin = predict_lines(vis, truth, np.zeros((3, 3)), loc.mount, loc.K,
                            loc.params.model_sigma_m)
        seg = np.asarray(segments, dtype=float)[m.image]
        h, V1 = image_line_covariance(seg, 1.0)
        nus.append(innovation(m.h, lin.h))
        v1s.append(align_cov(V1, h, lin.h))
        mcs.append(lin.model_cov)

    for seed in seeds:
        run_hallway_methods(seed, (cfg.method,), cfg, on_update=collect)
    return (np.concatenate(nus), np.concatenate(v1s), np.concatenate(mcs))


def sigma_px_table(nu: np.ndarray, V1: np.ndarray, model_cov: np.ndarray,
                   sigmas: Sequence[float], gate: float = 9.21) -> List[Tuple[float, ...]]:
    """Return ``(sigma_px, mean d^2, median d^2, fraction outside the gate)`` per sigma."""
    out = []
    for sd in sigmas:
        S = sd * sd * V1 + model_cov
        d2 = np.einsum('ki,kij,kj->k', nu, np.linalg.inv(S), nu)
        out.append((float(sd), float(d2.mean()), float(np.median(d2)),
                    float(np.mean(d2 > gate))))
    return out


def summarize(run: HallwayRun,
              lost_inflation_rad: float = LocalizerParams().lost_inflation[2]) -> dict:
    """Return the figures of one run.

    ``pos_max_moving_cm`` counts from the first frame after the robot has moved 1 cm (the
    standstill frames after the initial draw apart; nan for a run that never moved);
    ``pos_over_5cm`` / ``head_over_1deg`` count the frames above the acceptance bounds from
    the first update on.
    ``head_lost_z_max`` is the largest heading error while lost in units of the heading std
    the filter would have from odometry alone, i.e. without the lost state's inflation by
    ``lost_inflation_rad`` (exact, since the heading row of the motion Jacobian is
    ``[0, 0, 1]``): below about 2 the drift while lost is what the odometry model predicts.
    """
    from scipy.stats import chi2  # here: scipy.stats takes 0.3 s to import
    bound = chi2.ppf(0.95, 3)
    track = ~run.lost
    moving = run.travelled > 0.01
    sd_odo = np.sqrt(np.maximum(run.cov[:, 2, 2] - lost_inflation_rad ** 2, 1e-12))
    return {
        'pos_max_cm': 100 * float(run.position_error.max()),
        'pos_max_moving_cm': 100 * float(run.position_error[moving].max())
        if moving.any() else math.nan,
        'pos_over_5cm': int(np.count_nonzero(run.position_error > 0.05)),
        'head_over_1deg': int(np.count_nonzero(run.heading_error > math.radians(1.0))),
        'head_lost_z_max': float((run.heading_error / sd_odo)[run.lost].max())
        if run.lost.any() else 0.0,
        'pos_max_trk_cm': 100 * float(run.position_error[track].max()),
        'head_max_trk_deg': math.degrees(float(run.heading_error[track].max())),
        'nees_in_95_trk': float(np.mean(run.nees[track] <= bound)),
        'pos_rms_cm': 100 * float(np.sqrt(np.mean(run.position_error ** 2))),
        'head_max_deg': math.degrees(float(run.heading_error.max())),
        'nees_in_95': float(np.mean(run.nees <= bound)),
        'lost_episodes': len(run.lost_episodes()),
        'converged_m': run.converged_after(),
        'line_ms': float(np.median(run.line_ms)),
        'filter_ms': float(np.median(run.filter_ms)),
        'frames': int(run.t.size),
    }


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Print per-seed figures and their mean / worst."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--seeds', type=int, default=10)
    ap.add_argument('--first-seed', type=int, default=0)
    ap.add_argument('--method', default='rwrht', choices=MODEL_LINE_METHODS)
    ap.add_argument('--offset', type=float, nargs=3, metavar=('DX', 'DY', 'DPHI_DEG'))
    ap.add_argument('--cover', type=float, nargs=2, metavar=('T0', 'T1'))
    ap.add_argument('--max-frames', type=int, default=0)
    ap.add_argument('--write-bag', metavar='DIR', help='record the first --duration seconds '
                    'of seed --first-seed as a rosbag2 (MCAP) directory instead')
    ap.add_argument('--duration', type=float, default=10.0)
    ap.add_argument('--sigma-px', type=float, metavar='FILTER_SIGMA_PX',
                    help='instead of the figures: d^2 at the true pose of the pairs kept by a '
                    'filter with this end-point noise, per candidate end-point noise '
                    '(calibration of MatchParams.sigma_px; use seeds other than the '
                    'evaluation seeds)')
    a = ap.parse_args(argv)
    cfg = HallwayRunConfig(method=a.method, max_frames=a.max_frames,
                           cover=tuple(a.cover) if a.cover else None)
    if a.sigma_px is not None:
        loc = replace(cfg.localizer, match=replace(cfg.localizer.match, sigma_px=a.sigma_px))
        nu, V1, mc = pair_residuals(range(a.first_seed, a.first_seed + a.seeds),
                                    replace(cfg, localizer=loc))
        print(f'{len(nu)} pairs; sigma_px, mean d2, median d2, outside the 99 % gate')
        for row in sigma_px_table(nu, V1, mc, np.arange(0.5, 1.55, 0.1)):
            print(f'{row[0]:4.1f} {row[1]:6.2f} {row[2]:6.3f} {100 * row[3]:6.2f} %')
        return 0
    if a.write_bag:
        n = write_hallway_bag(a.write_bag, a.first_seed, a.duration, cfg)
        print(f'{a.write_bag}: {n} images, {a.duration} s')
        return 0
    if a.offset:
        sd = (0.3, 0.3, math.radians(10.0))
        cfg = replace(cfg, offset=(a.offset[0], a.offset[1], math.radians(a.offset[2])),
                      init_cov=tuple(np.diag(np.square(sd)).ravel()))
    keys = ('pos_max_cm', 'pos_max_moving_cm', 'pos_rms_cm', 'head_max_deg',
            'pos_max_trk_cm', 'head_max_trk_deg', 'nees_in_95', 'nees_in_95_trk',
            'pos_over_5cm', 'head_over_1deg', 'head_lost_z_max', 'lost_episodes',
            'converged_m', 'line_ms', 'filter_ms', 'frames')
    widths = [max(13, len(k)) for k in keys]  # whole names: the columns are read by them
    print('seed ' + ' '.join(f'{k:>{w}}' for k, w in zip(keys, widths)))
    table = []
    for seed in range(a.first_seed, a.first_seed + a.seeds):
        run = run_hallway(seed, cfg)
        s = summarize(run)
        table.append([s[k] for k in keys])
        print(f'{seed:4d} ' + ' '.join(f'{s[k]:{w}.3f}' for k, w in zip(keys, widths)),
              flush=True)
        episodes = ', '.join(f'{a:.1f}-{b:.1f} s' for a, b in run.lost_episodes())
        print(f'     lost: {episodes or "never"}', flush=True)
    arr = np.array(table, dtype=float)
    print('mean ' + ' '.join(f'{v:{w}.3f}' for v, w in zip(arr.mean(axis=0), widths)))
    worst = [arr[:, j].min() if k.startswith('nees') else arr[:, j].max()
             for j, k in enumerate(keys)]
    print('worst' + ' '.join(f'{v:{w}.3f}' for v, w in zip(worst, widths)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
