"""A simulated corridor run: drifting odometry, rendered frames, per-frame vision and the EKF.

The robot drives along the rendered corridor (:mod:`landmark_nav.sim.corridor`) with a
controller on the *estimate* that holds the centre line. Its true wheel distances differ
from the measured ones by Kleeman-model noise and a systematic scale error of the right
wheel (drift); the EKF (:class:`~landmark_nav.corridor.fusion.CorridorEKF`) predicts with
the measured distances at ``odom_rate`` and updates with :func:`~landmark_nav.corridor.
frame.measure_frame` at ``camera_rate`` (prior: the predicted lateral position). Figures:
RMS of the fused lateral and heading errors, and medians of the single-frame errors.

The simulator shares the algorithms' assumptions (straight walls, known width and height):
the figures bound what the method can do, they do not replace real recordings.
"""

from dataclasses import dataclass, field
import math
from typing import Dict, List, Tuple

from landmark_nav.corridor.controller import ControllerParams, CorridorController
from landmark_nav.corridor.frame import CorridorLost, FrameParams, measure_frame
from landmark_nav.corridor.fusion import CorridorEKF, DeadReckoningNoise
from landmark_nav.corridor.lateral import CorridorModel
from landmark_nav.geometry import wrap_angle
from landmark_nav.sim.camera import CameraSimulator, Photometry
from landmark_nav.sim.corridor import (corridor_scene, corridor_view, CorridorConfig,
                                       default_corridor_camera)
import numpy as np


@dataclass(frozen=True)
class RunConfig:
    """A corridor run.

    Attributes:
        corridor: the rendered corridor.
        mount: camera_link in base_link ``[x, y, z, roll, pitch, yaw]``.
        start: true start ``(x, y, theta)`` in the corridor frame.
        distance: distance to drive [m].
        speed: forward speed [m/s].
        odom_rate: odometry samples per second.
        camera_rate: frames per second (the chapter: 5).
        true_noise: the true odometry error (Kleeman) besides the scale error.
        right_scale_error: relative error of the right wheel's measured distance (drift).
        model_noise: the error model the EKF assumes.
        photometry: image noise and blur.
        frame: per-frame pipeline parameters.
        lengths: corridor lengths driven, turning on the spot at the ends in between.
    """

    corridor: CorridorConfig = field(default_factory=CorridorConfig)
    mount: Tuple[float, ...] = (0.1, 0.0, 1.1, 0.0, math.radians(5.0), 0.0)
    start: Tuple[float, float, float] = (1.0, 0.15, math.radians(4.0))
    distance: float = 27.0
    speed: float = 0.5
    odom_rate: float = 20.0
    camera_rate: float = 5.0
    true_noise: DeadReckoningNoise = field(default_factory=lambda: DeadReckoningNoise(
        wheel_separation=0.33, k_left=2e-5, k_right=2e-5, sigma_separation=0.0))
    right_scale_error: float = 0.01
    model_noise: DeadReckoningNoise = field(default_factory=lambda: DeadReckoningNoise(
        wheel_separation=0.33, k_left=1e-4, k_right=1e-4, sigma_separation=0.001))
    photometry: Photometry = field(default_factory=lambda: Photometry(noise_sigma=2.0,
                                                                      defocus_sigma=0.5))
    frame: FrameParams = field(default_factory=FrameParams)
    lengths: int = 1


@dataclass(frozen=True, eq=False)
class RunResult:
    """Per-frame records of a run (arrays of equal length, one entry per camera frame)."""

    truth: np.ndarray          # (F, 3) x, y, theta
    fused: np.ndarray          # (F, 3) x, y, theta after the update
    visual: np.ndarray         # (F, 2) theta_v, y_v (NaN when lost)
    accepted: np.ndarray       # (F,) bool
    lost: List[str]
    turning: np.ndarray        # (F,) bool: frames while turning at an end

    def summary(self) -> Dict[str, float]:
        """Return RMS / median figures [m, deg] and counts (frames while turning left out)."""
        drive = ~self.turning
        e_y = self.fused[drive, 1] - self.truth[drive, 1]
        e_th = np.degrees(wrap_angle(self.fused[drive, 2] - self.truth[drive, 2]))
        ok = np.isfinite(self.visual[:, 0]) & drive
        v_y = np.abs(self.visual[ok, 1] - self.truth[ok, 1])
        v_th = np.abs(np.degrees(wrap_angle(self.visual[ok, 0] - self.truth[ok, 2])))
        return {'frames': float(len(self.truth)), 'lost': float(len(self.lost)),
                'rejected': float(np.count_nonzero(ok & ~self.accepted)),
                'fused_lateral_rms': float(np.sqrt(np.mean(e_y ** 2))),
                'fused_heading_rms_deg': float(np.sqrt(np.mean(e_th ** 2))),
                'single_lateral_median': float(np.median(v_y)) if v_y.size else math.nan,
                'single_heading_median_deg': float(np.median(v_th)) if v_th.size else math.nan,
                'max_abs_lateral': float(np.max(np.abs(self.truth[drive, 1]))),
                'max_abs_lateral_after_2m': float(np.max(np.abs(
                    self.truth[drive & (np.arange(len(drive)) >= self._frames_2m), 1])))}

    @property
    def _frames_2m(self) -> int:
        """Index of the first frame after the first 2 m (the start transient)."""
        d = np.abs(self.truth[:, 0] - self.truth[0, 0])
        return int(np.argmax(d >= 2.0)) if np.any(d >= 2.0) else len(d)


def _move(s: np.ndarray, d_l: float, d_r: float, b: float) -> np.ndarray:
    ds, dth = 0.5 * (d_l + d_r), (d_r - d_l) / b
    a = s[2] + 0.5 * dth
    return np.array([s[0] + ds * math.cos(a), s[1] + ds * math.sin(a), s[2] + dth])


def run_corridor(config: RunConfig = RunConfig(), seed: int = 0) -> RunResult:
    """Simulate one run (deterministic for a seed).

    The robot follows :class:`~landmark_nav.corridor.controller.CorridorController`'s
    command on the fused estimate (closed loop). With ``config.lengths > 1`` it turns on
    the spot (0.5 rad/s, odometry only) when the estimate passes ``turn_margin`` before
    either end and drives back, ``lengths`` times in all; frames during the turns are kept
    out of the figures (``RunResult.turning``).
    """
    rng = np.random.default_rng(seed)
    c = config
    planes = corridor_scene(c.corridor, seed)
    cam = default_corridor_camera()
    sim = CameraSimulator(cam)
    model = CorridorModel(c.corridor.width, c.corridor.height, c.corridor.centre_line)
    truth = np.array(c.start, dtype=float)
    # the filter starts from a rough guess: 10 cm and 3 deg off, with that uncertainty
    ekf = CorridorEKF([truth[2] + math.radians(3.0), truth[0], truth[1] - 0.1],
                      np.diag([math.radians(3.0) ** 2, 0.05 ** 2, 0.1 ** 2]), c.model_noise)
    ctrl = CorridorController(ControllerParams(speed=c.speed, max_accel=1e3))
    b = c.true_noise.wheel_separation
    dt = 1.0 / c.odom_rate
    per_frame = int(round(c.odom_rate / c.camera_rate))
    rec_t, rec_f, rec_v, rec_a, rec_turn, lost = [], [], [], [], [], []
    ends = (c.start[0] + c.distance, c.start[0])
    leg, travelled, turning, target = 0, 0.0, False, 0.0
    k = 0
    while leg < c.lengths:
        k += 1
        if turning:
            err = wrap_angle(target - ekf.s[0])
            if abs(err) < 0.02:
                turning = False
                continue
            v, w = 0.0, math.copysign(min(0.5, abs(err) * c.odom_rate), err)
        else:
            th, y = ekf.s[0], ekf.visual_prior()[0]
            if ekf.facing_back:
                th = wrap_angle(th - math.pi)
            v, w = ctrl.step(th, y, dt, True)
        d_l, d_r = (v - 0.5 * b * w) * dt, (v + 0.5 * b * w) * dt
        n = c.true_noise
        t_l = d_l + rng.normal(0.0, math.sqrt(n.k_left * abs(d_l)))
        t_r = (d_r + rng.normal(0.0, math.sqrt(n.k_right * abs(d_r)))) / (1 + c.right_scale_error)
        truth = _move(truth, t_l, t_r, b)
        ekf.predict_wheels(d_l, d_r)                              # measured = commanded
        travelled += v * dt
        if not turning and travelled >= c.distance:
            leg += 1
            travelled = 0.0
            if leg < c.lengths:
                turning, target = True, wrap_angle(ekf.s[0] + math.pi)
                target = math.pi if abs(target) > math.pi / 2 else 0.0
        if k % per_frame != 0:
            continue
        view = corridor_view(sim, planes, truth, c.mount, c.photometry, rng)
        visual = (math.nan, math.nan)
        accepted = False
        try:
            m = measure_frame(view.image, cam, model, c.mount, ekf.visual_prior(), c.frame)
            visual = (m.heading, m.y)
            accepted = ekf.update(m.heading, m.y, m.covariance, m.p_correct,
                                  m.wrong_covariance).accepted
        except CorridorLost as err:
            lost.append(str(err))
        back = abs(wrap_angle(truth[2])) > math.pi / 2      # visual values in the truth frame
        rec_t.append(truth.copy())
        rec_f.append([ekf.s[1], ekf.s[2], ekf.s[0]])
        rec_v.append((wrap_angle(visual[0] + math.pi), -visual[1]) if back else visual)
        rec_a.append(accepted)
        rec_turn.append(turning)
    del ends
    return RunResult(np.array(rec_t), np.array(rec_f), np.array(rec_v), np.array(rec_a), lost,
                     np.array(rec_turn))


#: The chapter's hard cases (its Fig. 8) and one of ours, as (scene, pose sampler).
HARD_CASES = ('occluded', 'near_wall', 'one_wall', 'lighting')


def _hard_pose(case: str, rng: np.random.Generator) -> Tuple[float, float, float]:
    if case == 'occluded':            # people and open doors between the robot and the VP
        return rng.uniform(1, 3), rng.uniform(-0.4, 0.4), math.radians(rng.uniform(-10, 10))
    if case == 'near_wall':
        return (rng.uniform(2, 20), rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 0.7),
                math.radians(rng.uniform(-10, 10)))
    if case == 'one_wall':            # turned 36-42 deg: one wall only, the end not in view
        return (rng.uniform(2, 20), rng.uniform(-0.3, 0.3),
                math.radians(rng.choice([-1.0, 1.0]) * rng.uniform(36, 42)))
    return rng.uniform(2, 20), rng.uniform(-0.5, 0.5), math.radians(rng.uniform(-15, 15))


def hard_cases(frames: int = 20, seed: int = 3,
               params: FrameParams = FrameParams()) -> Dict[str, Dict[str, float]]:
    """Return single-frame error medians / maxima [deg, m] and losses per hard case.

    ``occluded``: 6 people and 4 open doors in the corridor beyond 4 m, robot 1-3 m from
    the start (at least 1 m before the first occluder);
    ``near_wall``: 0.5-0.7 m off the centre line; ``one_wall``: turned 36-42 deg, so that
    one wall fills the view and the corridor's end is outside it (the chapter's Fig. 8 b,
    c); ``lighting``: exposure 0.4-1.4, illumination gradients, vignetting, gamma 2.2, shot
    noise.
    """
    cam = default_corridor_camera()
    sim = CameraSimulator(cam)
    mount = RunConfig().mount
    out = {}
    for case in HARD_CASES:
        cfg = CorridorConfig(people=6, open_doors=4) if case == 'occluded' else CorridorConfig()
        planes = corridor_scene(cfg, seed)
        model = CorridorModel(cfg.width, cfg.height)
        rng = np.random.default_rng(seed)
        eh, ey, lost = [], [], 0
        for _ in range(frames):
            robot = _hard_pose(case, rng)
            ph = Photometry(noise_sigma=2.0, defocus_sigma=0.5)
            if case == 'lighting':
                ph = Photometry(exposure=rng.uniform(0.4, 1.4),
                                gradient=(rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3)),
                                vignetting=0.3, gamma=2.2, noise_sigma=3.0, shot_noise=0.3,
                                defocus_sigma=0.7)
            view = corridor_view(sim, planes, robot, mount, ph, rng)
            try:
                m = measure_frame(view.image, cam, model, mount, params=params)
            except CorridorLost:
                lost += 1
                continue
            eh.append(abs(math.degrees(wrap_angle(m.heading - robot[2]))))
            ey.append(abs(m.y - robot[1]))
        out[case] = {'frames': float(frames), 'lost': float(lost),
                     'heading_median_deg': float(np.median(eh)) if eh else math.nan,
                     'heading_max_deg': float(np.max(eh)) if eh else math.nan,
                     'lateral_median': float(np.median(ey)) if ey else math.nan,
                     'lateral_max': float(np.max(ey)) if ey else math.nan}
    return out
