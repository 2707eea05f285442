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


@dataclass(frozen=True, eq=False)
class RunResult:
    """Per-frame records of a run (arrays of equal length, one entry per camera frame)."""

    truth: np.ndarray          # (F, 3) x, y, theta
    fused: np.ndarray          # (F, 3) x, y, theta after the update
    visual: np.ndarray         # (F, 2) theta_v, y_v (NaN when lost)
    accepted: np.ndarray       # (F,) bool
    lost: List[str]

    def summary(self) -> Dict[str, float]:
        """Return RMS / median figures [m, deg] and counts."""
        e_y = self.fused[:, 1] - self.truth[:, 1]
        e_th = np.degrees(wrap_angle(self.fused[:, 2] - self.truth[:, 2]))
        ok = np.isfinite(self.visual[:, 0])
        v_y = np.abs(self.visual[ok, 1] - self.truth[ok, 1])
        v_th = np.abs(np.degrees(wrap_angle(self.visual[ok, 0] - self.truth[ok, 2])))
        return {'frames': float(len(self.truth)), 'lost': float(len(self.lost)),
                'rejected': float(np.count_nonzero(ok & ~self.accepted)),
                'fused_lateral_rms': float(np.sqrt(np.mean(e_y ** 2))),
                'fused_heading_rms_deg': float(np.sqrt(np.mean(e_th ** 2))),
                'single_lateral_median': float(np.median(v_y)) if v_y.size else math.nan,
                'single_heading_median_deg': float(np.median(v_th)) if v_th.size else math.nan,
                'max_abs_lateral': float(np.max(np.abs(self.truth[:, 1])))}


def _move(s: np.ndarray, d_l: float, d_r: float, b: float) -> np.ndarray:
    ds, dth = 0.5 * (d_l + d_r), (d_r - d_l) / b
    a = s[2] + 0.5 * dth
    return np.array([s[0] + ds * math.cos(a), s[1] + ds * math.sin(a), s[2] + dth])


def run_corridor(config: RunConfig = RunConfig(), seed: int = 0) -> RunResult:
    """Simulate one run (deterministic for a seed)."""
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
    b = c.true_noise.wheel_separation
    step = c.speed / c.odom_rate
    per_frame = int(round(c.odom_rate / c.camera_rate))
    rec_t, rec_f, rec_v, rec_a, lost = [], [], [], [], []
    n_steps = int(c.distance / step)
    for k in range(n_steps):
        th, _, y = ekf.state
        omega = -1.0 * y - 1.5 * wrap_angle(th)                   # [rad/m] towards centre
        omega = max(-0.5, min(0.5, omega))
        d_l, d_r = step * (1 - 0.5 * b * omega), step * (1 + 0.5 * b * omega)
        n = c.true_noise
        t_l = d_l + rng.normal(0.0, math.sqrt(n.k_left * abs(d_l)))
        t_r = (d_r + rng.normal(0.0, math.sqrt(n.k_right * abs(d_r)))) / (1 + c.right_scale_error)
        truth = _move(truth, t_l, t_r, b)
        ekf.predict_wheels(d_l, d_r)                              # measured = commanded
        if k % per_frame != per_frame - 1:
            continue
        view = corridor_view(sim, planes, truth, c.mount, c.photometry, rng)
        visual = (math.nan, math.nan)
        accepted = False
        try:
            prior = (ekf.s[2], math.sqrt(ekf.p[2, 2]))
            m = measure_frame(view.image, cam, model, c.mount, prior, c.frame)
            visual = (m.heading, m.y)
            accepted = ekf.update(m.heading, m.y, m.covariance).accepted
        except CorridorLost as err:
            lost.append(str(err))
        rec_t.append(truth.copy())
        rec_f.append([ekf.s[1], ekf.s[2], ekf.s[0]])
        rec_v.append(visual)
        rec_a.append(accepted)
    return RunResult(np.array(rec_t), np.array(rec_f), np.array(rec_v), np.array(rec_a), lost)
