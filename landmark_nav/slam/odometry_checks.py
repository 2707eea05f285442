"""Checks of one odometry sample that do not trust the sample itself (ROS free).

Used by :class:`~landmark_nav.slam.frontend.SlamFrontend` (the ``ekf_slam`` node and the
offline evaluation alike):

* :func:`odometry_jump` (:func:`implausible_motion` on the increment between two
  samples): an increment is judged against the motion model's own bound,
  from the elapsed time and the robot's limits plus ``k`` standard deviations of the
  filter's odometry noise model at that increment, never against the covariance the
  message states (a teleport claiming a covariance of 1e6 m^2 is still a teleport);
* :func:`covariance_problem`: the stated 3x3 (x, y, yaw) covariance must be finite,
  symmetric, with a non-negative diagonal and positive semi-definite; one that is not is
  replaced by the filter's configured noise model (the caller warns and counts);
* :class:`BackwardRun`: "time went back" is a persistent condition: only ``needed``
  consecutive samples, each more than ``max_backward_s`` older than the last accepted one
  and newer than the one before it in the run, mean a restarted source; a single stamp
  never resets anything. Such a run that continues the samples before the last accepted
  one, when that one lay more than ``max_backward_s`` ahead of them, shows that one was
  stamped in the future instead (:func:`future_stamp`): it is withdrawn.

:class:`OdometryLimits` holds the parameters of these checks (the defaults of
:class:`~landmark_nav.slam.frontend.FrontendParams` and of the graph's per-scan step).
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Tuple

from landmark_nav.geometry import compose, inverse, relative
import numpy as np

from .ekf_slam import OdometryNoise

#: Relative tolerance of the symmetry and PSD tests of a stated covariance.
COVARIANCE_RTOL = 1e-9


def implausible_motion(u: np.ndarray, dt: float, noise: OdometryNoise, max_speed: float,
                       max_turn_rate: float, jump_sigmas: float, min_step_s: float
                       ) -> Optional[str]:
    """Return why an increment cannot be a motion in ``dt`` seconds, or None.

    The bounds are ``|(u_x, u_y)| <= v_max dt + k sigma_xy`` and ``|u_psi| <= w_max dt + k
    sigma_psi``, ``dt`` at least ``min_step_s``, with ``sigma_xy^2 = s_xy^2 d`` and
    ``sigma_psi^2 = s_yd^2 d + s_yr^2 |u_psi|`` of the noise model (the filter's ``U``,
    :func:`~landmark_nav.slam.ekf_slam.odometry_noise`) at the increment ``u`` (eq. 13).
    """
    d, turn = math.hypot(u[0], u[1]), abs(float(u[2]))
    var_xy = noise.sigma_xy_per_sqrt_m ** 2 * d
    var_psi = noise.sigma_yaw_per_sqrt_m ** 2 * d + noise.sigma_yaw_per_sqrt_rad ** 2 * turn
    span = max(dt, min_step_s)
    lim_xy = max_speed * span + jump_sigmas * math.sqrt(var_xy)
    lim_psi = max_turn_rate * span + jump_sigmas * math.sqrt(var_psi)
    if d > lim_xy:
        return f'moved {d:.3f} m (> {lim_xy:.3f} m plausible)'
    if turn > lim_psi:
        return f'turned {turn:.3f} rad (> {lim_psi:.3f} rad plausible)'
    return None


@dataclass(frozen=True)
class OdometryLimits:
    """Parameters of the odometry checks (their meaning: :class:`FrontendParams`)."""

    max_speed: float = 1.5
    max_turn_rate: float = 5.3
    jump_sigmas: float = 5.0
    min_step_s: float = 0.02
    max_backward_s: float = 1.0
    restart_messages: int = 3


def odometry_jump(last: np.ndarray, pose: np.ndarray, dt: float, noise: OdometryNoise,
                  limits) -> Optional[str]:
    """Return why odometry ``last`` -> ``pose`` in ``dt`` s is no motion (a jump), or None.

    :func:`implausible_motion` on the increment ``u = (-)last (+) pose`` (eq. 13), the
    limits' ``max_speed``, ``max_turn_rate``, ``jump_sigmas`` and ``min_step_s`` (an
    :class:`OdometryLimits` or a :class:`~landmark_nav.slam.frontend.FrontendParams`).
    """
    return implausible_motion(relative(last, pose), dt, noise, limits.max_speed,
                              limits.max_turn_rate, limits.jump_sigmas, limits.min_step_s)


def bridge_offset(last_bridged: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Return the offset that bridges a jump: ``offset (+) pose`` is ``last_bridged``.

    Odometry after the jump is re-expressed as ``offset (+) o``: it continues from the
    pose before the jump (zero motion across it).
    """
    return compose(last_bridged, inverse(pose))


def bridged(offset: Optional[np.ndarray], pose: np.ndarray) -> np.ndarray:
    """Return an odometry pose re-expressed by the offset of the last jump (None: none)."""
    return pose if offset is None else compose(offset, pose)


def future_stamp(before_ns: Optional[int], newest_ns: int, run_first_ns: int,
                 max_backward_s: float) -> Optional[float]:
    """Return how far the newest sample lay in the future [s], or None (a restart).

    A complete :class:`BackwardRun` starting at ``run_first_ns`` after ``before_ns`` (the
    accepted sample before the newest; None when there is none) continues the odometry
    before the newest sample: when the newest lay more than ``max_backward_s`` ahead of
    ``before_ns`` it was stamped in the future, and is withdrawn.
    """
    if before_ns is None or run_first_ns <= before_ns:
        return None
    gap = (newest_ns - before_ns) * 1e-9
    return gap if gap > max_backward_s else None


def covariance_problem(cov: np.ndarray) -> Optional[str]:
    """Return what is wrong with a stated (3, 3) covariance, or None when it is usable.

    Usable: finite, symmetric, non-negative diagonal, positive semi-definite (the smallest
    eigenvalue at least ``-COVARIANCE_RTOL`` times the largest magnitude).
    """
    c = np.asarray(cov, dtype=float)
    if not np.all(np.isfinite(c)):
        return f'not finite (diagonal {np.diag(c).tolist()})'
    scale = float(np.max(np.abs(c)))
    if not np.all(np.abs(c - c.T) <= COVARIANCE_RTOL * scale):  # finite: np.allclose's test
        return f'not symmetric (xy {c[0, 1]:g} vs yx {c[1, 0]:g})'
    diag = np.diag(c)
    if np.any(diag < 0.0):
        return f'negative variance (diagonal {diag.tolist()})'
    low = float(np.linalg.eigvalsh(0.5 * (c + c.T))[0])
    if low < -COVARIANCE_RTOL * scale:
        return f'not positive semi-definite (smallest eigenvalue {low:g})'
    return None


class BackwardRun:
    """Consecutive odometry samples far back in time: a restarted source once persistent.

    Args:
        needed: Samples in a row that make the condition persistent (>= 1).
    """

    def __init__(self, needed: int) -> None:
        """Start with no run."""
        self.needed = int(needed)
        self.samples: List[Tuple[int, np.ndarray, Optional[np.ndarray]]] = []

    def clear(self) -> List[Tuple[int, np.ndarray, Optional[np.ndarray]]]:
        """Forget the run and return its samples (e.g. dropped: the old time base goes on)."""
        samples, self.samples = self.samples, []
        return samples

    def continues(self, stamp_ns: int) -> bool:
        """Whether a far-back sample continues the run (none yet, or newer than its last).

        A restarted source's clock moves forward; a sample that does not starts a new run.
        """
        return not self.samples or stamp_ns > self.samples[-1][0]

    def add(self, stamp_ns: int, pose: np.ndarray, cov: Optional[np.ndarray]) -> bool:
        """Add a far-back sample that continues the run; return True when it is complete."""
        self.samples.append((int(stamp_ns), pose, cov))
        return len(self.samples) >= self.needed


__all__ = ['BackwardRun', 'bridge_offset', 'bridged', 'covariance_problem', 'COVARIANCE_RTOL',
           'future_stamp', 'implausible_motion', 'odometry_jump', 'OdometryLimits']
