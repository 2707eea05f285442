"""Online pose tracking: odometry and sonar cycles in stamp order through the EKF or UKF.

The ROS-free half of the ``sonar_localizer`` node (the node converts messages, calls this
and publishes). Everything runs on message stamps, never on the wall clock, so replaying a
bag gives what the offline loop of :func:`landmark_nav.evaluation.localization.localize` gives.

Odometry: each sample (wheel angles, or a pose of an odometry topic) yields the calibrated
control of the interval since the previous sample (eqs. 4-7, 17-18), queued with its two
stamps. A sample older than the previous one (a looped bag) resets the time bookkeeping
(queues, pending cycles, sonar bookkeeping; the pose estimate is kept); a repeated stamp
is ignored.

Sonar cycles: the readings of one cycle share a stamp and are grouped by it. The oldest
pending cycle is processed once the odometry has reached its stamp and either every
expected sonar has reported or a stamp at least ``sync_timeout`` newer has been seen
(then the missing readings are nan, i.e. not used). Processing: one time update per
queued odometry interval up to the cycle stamp (an interval straddling it is split
proportionally in time), then one measurement update with the cycle if a usable map is
set. With the odometry and the sonar on common 10 Hz stamps this is exactly the offline
loop. A sonar missing from ``stale_cycles`` consecutive cycles is no longer waited for
(reported once) until it reports again. Readings at or before the last processed stamp
are late and dropped. If no sonar reading arrives for ``sonar_timeout`` of odometry time,
the filter dead-reckons to every odometry sample until one does.

Without a usable map (none yet, or no occupied cell) only time updates run: the estimate
is dead reckoning with a growing covariance.
"""

from collections import deque
from dataclasses import dataclass
import math
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import ekf, ukf
from .grid import GridMap
from .odometry import calibrate_control, control_from_poses, control_from_wheels, \
    process_noise
from .params import LocalizationParams
from ..geometry import wrap_angle

NS_PER_S = 1_000_000_000
FILTERS = ('ekf', 'ukf')


@dataclass(frozen=True, eq=False)
class Estimate:
    """One posterior of the tracker.

    Attributes:
        stamp_ns: stamp of the sonar cycle (or of the odometry sample when dead reckoning
            without sonar).
        pose: (3,) ``[x, y, Theta]`` in the map frame.
        covariance: (3, 3) its covariance.
        velocity: (2,) mean ``(v, omega)`` [m/s, rad/s] of the odometry since the previous
            estimate (zeros if no time passed).
        velocity_covariance: (2, 2) from the process noise Q of those steps (eq. 26).
        accepted: readings used by the measurement update; -1 if none ran (no map, no
            sonar).
    """

    stamp_ns: int
    pose: np.ndarray
    covariance: np.ndarray
    velocity: np.ndarray
    velocity_covariance: np.ndarray
    accepted: int


def map_problem(grid: GridMap) -> Optional[str]:
    """Return why a map cannot be localized on (None if it can)."""
    if not grid.occupied.any():
        n_unknown = int(grid.unknown.sum())
        return (f'map has no occupied cell ({n_unknown} of {grid.occupancy.size} cells '
                f'unknown)')
    return None


def sonar_reading(value: float, min_range: float,
                  max_range: float) -> Tuple[float, Optional[str]]:
    """Return the filter reading of a REP 117 range value and the problem if it is bad.

    ``+inf`` (no echo) and ``-inf`` (too close) are kept (the acceptance test skips them);
    NaN and finite values outside ``[min_range, max_range]`` are invalid: nan and a
    description of the problem.
    """
    v = float(value)
    if math.isnan(v):
        return math.nan, 'range is NaN (sensor error)'
    if math.isinf(v):
        return v, None
    if not min_range <= v <= max_range:
        return math.nan, (f'range {v:.3f} m outside [min_range, max_range] = '
                          f'[{min_range:.3f}, {max_range:.3f}] m')
    return v, None


class _Cycle:
    """Readings received so far for one stamp."""

    def __init__(self, n: int) -> None:
        self.z = np.full(n, np.nan)
        self.received = np.zeros(n, dtype=bool)


class SonarTracker:
    """EKF / UKF pose tracking fed one message at a time (see the module docstring).

    Every ``add_*`` method returns the estimates it produced (possibly none), oldest first.
    """

    def __init__(self, filter: str, mounts: Any,  # noqa: A002 (name from the API spec)
                 params: Optional[LocalizationParams] = None,
                 initial_pose: Any = (0.0, 0.0, 0.0), initial_cov: Any = None,
                 wheel_radius: float = 0.0955, axle_length: float = 0.33,
                 k: Sequence[float] = (1.0, 1.0, 1.0), sync_timeout: float = 0.15,
                 stale_cycles: int = 3, sonar_timeout: float = 1.0, max_pending: int = 50,
                 sonar_names: Optional[Sequence[str]] = None,
                 warn: Optional[Callable[[str], None]] = None,
                 info: Optional[Callable[[str], None]] = None) -> None:
        """Set up the tracker.

        Args:
            filter: ``'ekf'`` or ``'ukf'``.
            mounts: (S, 3) sonar poses in base_link, in reading index order.
            params: filter parameters.
            initial_pose: (3,) initial estimate (taken at the first odometry stamp).
            initial_cov: (3, 3) its covariance (default ``diag(0.055, 0.055, 5 deg)^2``).
            wheel_radius: nominal R [m] (wheel angles only).
            axle_length: nominal b [m].
            k: odometry calibration ``(k1, k2, k3)`` (eqs. 17-18).
            sync_timeout: a cycle is processed incomplete once a stamp this much newer has
                been seen [s].
            stale_cycles: cycles a sonar may miss before it is no longer waited for.
            sonar_timeout: dead reckoning after this long without sonar readings [s].
            max_pending: cycles kept while waiting for odometry (the oldest are dropped).
            sonar_names: names used in messages (default ``sonar <i>``).
            warn: callback for warnings (bad or missing input).
            info: callback for information (a sonar resumed, a map set).

        Raises:
            ValueError: a bad argument.
        """
        if filter not in FILTERS:
            raise ValueError(f"filter must be 'ekf' or 'ukf', got {filter!r}")
        self.filter = filter
        self.mounts = np.asarray(mounts, dtype=float).reshape(-1, 3)
        n = self.mounts.shape[0]
        if n == 0:
            raise ValueError('need at least one sonar mount')
        self.params = params or LocalizationParams()
        self.wheel_radius = float(wheel_radius)
        self.axle_length = float(axle_length)
        self.k = tuple(float(v) for v in k)
        if len(self.k) != 3 or min(self.k) <= 0.0 or self.wheel_radius <= 0.0 \
                or self.axle_length <= 0.0:
            raise ValueError('wheel_radius, axle_length and k1, k2, k3 must be > 0')
        self.sync_timeout_ns = int(round(sync_timeout * NS_PER_S))
        self.sonar_timeout_ns = int(round(sonar_timeout * NS_PER_S))
        self.stale_cycles = int(stale_cycles)
        self.max_pending = int(max_pending)
        self.names = list(sonar_names) if sonar_names is not None else [
            f'sonar {i}' for i in range(n)]
        self._warn = warn or (lambda message: None)
        self._info = info or (lambda message: None)
        self.grid: Optional[GridMap] = None
        if initial_cov is None:
            initial_cov = np.diag([0.055, 0.055, np.radians(5.0)]) ** 2
        self.reset(initial_pose, initial_cov)
        self.reset_time()

    # ------------------------------------------------------------------ state
    @property
    def pose(self) -> np.ndarray:
        """(3,) current estimate."""
        return self._x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """(3, 3) current covariance."""
        return self._p.copy()

    @property
    def stamp_ns(self) -> Optional[int]:
        """Stamp of the current estimate (None before the first odometry sample)."""
        return self._t

    @property
    def expected(self) -> np.ndarray:
        """(S,) bool: sonars the synchronisation waits for."""
        return self._expected.copy()

    def reset(self, pose: Any, cov: Any) -> None:
        """Replace the estimate (e.g. an initial pose from the user); stamps are kept."""
        x = np.asarray(pose, dtype=float).reshape(3).copy()
        p = np.asarray(cov, dtype=float).reshape(3, 3)
        if not (np.isfinite(x).all() and np.isfinite(p).all()):
            raise ValueError('pose and covariance must be finite')
        x[2] = wrap_angle(x[2])
        self._x = x
        self._p = ekf.symmetrize_psd(p.copy())

    def reset_time(self) -> None:
        """Forget all stamps: queues, pending cycles, sonar bookkeeping (not the pose)."""
        n = self.mounts.shape[0]
        self._t: Optional[int] = None  # stamp of the estimate
        self._anchor: Optional[int] = None  # first odometry stamp
        self._done: Optional[int] = None  # stamp of the last processed sonar cycle
        self._odo_prev: Optional[Tuple[int, np.ndarray]] = None
        self._intervals: deque = deque()  # [t_a, t_b, u] covering (t, latest odometry]
        self._latest_odo: Optional[int] = None
        self._latest: Optional[int] = None  # newest stamp seen on any input
        self._pending: Dict[int, _Cycle] = {}
        self._expected = np.ones(n, dtype=bool)
        self._missed = np.zeros(n, dtype=int)
        self._last_sonar: Optional[int] = None
        self._silent = False

    def set_map(self, grid: Optional[GridMap]) -> bool:
        """Use a map from now on; False (with a warning) if it is unusable."""
        if grid is not None:
            problem = map_problem(grid)
            if problem is not None:
                self._warn(f'{problem}: dead reckoning until a usable map arrives')
                grid = None
        self.grid = grid
        return grid is not None

    # ------------------------------------------------------------------ inputs
    def add_wheel_angles(self, stamp_ns: int, angles: Any) -> List[Estimate]:
        """Feed accumulated wheel angles ``(phi_L, phi_R)`` [rad] measured at a stamp."""
        return self._add_odometry(int(stamp_ns), np.asarray(angles, dtype=float).reshape(2),
                                  self._wheel_control)

    def add_odometry_pose(self, stamp_ns: int, pose: Any) -> List[Estimate]:
        """Feed a pose ``[x, y, Theta]`` of an (uncalibrated, nominal) odometry topic."""
        return self._add_odometry(int(stamp_ns), np.asarray(pose, dtype=float).reshape(3),
                                  self._pose_control)

    def add_reading(self, index: int, stamp_ns: int, value: float) -> List[Estimate]:
        """Feed one sonar reading [m] (``+inf`` no echo, ``-inf`` too close, nan invalid)."""
        stamp_ns = int(stamp_ns)
        if not 0 <= index < self.mounts.shape[0]:
            raise ValueError(f'sonar index {index} out of range')
        name = self.names[index]
        if (self._done is not None and stamp_ns <= self._done) or \
                (self._t is not None and stamp_ns < self._t):
            self._warn(f'{name}: reading stamped {stamp_ns * 1e-9:.3f} s arrived after the '
                       f'filter passed that time ({self._t * 1e-9:.3f} s): dropped')
            return []
        self._last_sonar = stamp_ns
        self._silent = False
        if not self._expected[index]:
            self._expected[index] = True
            self._info(f'{name} reports again')
        self._missed[index] = 0
        cycle = self._pending.get(stamp_ns)
        if cycle is None:
            if len(self._pending) >= self.max_pending:
                oldest = min(self._pending)
                del self._pending[oldest]
                self._warn(f'sonar cycle stamped {oldest * 1e-9:.3f} s dropped: no odometry '
                           'up to that stamp')
            cycle = self._pending[stamp_ns] = _Cycle(self.mounts.shape[0])
        if cycle.received[index]:
            self._warn(f'{name}: second reading for stamp {stamp_ns * 1e-9:.3f} s ignored')
            return []
        cycle.z[index] = float(value)
        cycle.received[index] = True
        self._latest = stamp_ns if self._latest is None else max(self._latest, stamp_ns)
        return self._advance()

    # ------------------------------------------------------------------ odometry
    def _wheel_control(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        # Wheel angle increments over the interval = speeds x T with T = 1 (eqs. 4-7, 17-18).
        return control_from_wheels(b - a, self.wheel_radius, self.axle_length, 1.0,
                                   self.k)  # type: ignore[arg-type]

    def _pose_control(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        # Odometry topics integrate eqs. 1-3 (midpoint heading) with the nominal model.
        return calibrate_control(control_from_poses(a, b, midpoint=True), self.axle_length,
                                 self.k)  # type: ignore[arg-type]

    def _add_odometry(self, stamp_ns: int, value: np.ndarray,
                      control: Callable[[np.ndarray, np.ndarray], np.ndarray]
                      ) -> List[Estimate]:
        if not np.isfinite(value).all():
            self._warn('odometry sample with non-finite values: dropped')
            return []
        if self._odo_prev is not None:
            t_prev, v_prev = self._odo_prev
            if stamp_ns < t_prev:
                self._warn(f'odometry jumped back in time from {t_prev * 1e-9:.3f} s to '
                           f'{stamp_ns * 1e-9:.3f} s (looped bag?): time bookkeeping reset')
                self.reset_time()
            elif stamp_ns == t_prev:
                self._warn(f'odometry sample with a repeated stamp {stamp_ns * 1e-9:.3f} s: '
                           'ignored')
                return []
            else:
                self._intervals.append([t_prev, stamp_ns, control(v_prev, value)])
        self._odo_prev = (stamp_ns, value)
        if self._t is None:
            self._t = self._anchor = stamp_ns  # the first sample anchors the filter time
        self._latest_odo = stamp_ns
        self._latest = stamp_ns if self._latest is None else max(self._latest, stamp_ns)
        out = self._advance()
        if not self._silent and not self._pending:
            since = self._anchor if self._last_sonar is None else self._last_sonar
            if stamp_ns - since >= self.sonar_timeout_ns:
                self._silent = True
                self._warn(f'no sonar reading for {(stamp_ns - since) * 1e-9:.1f} s: dead '
                           'reckoning on odometry')
        if self._silent and stamp_ns > self._t:
            out.append(self._estimate_at(stamp_ns, None))
        return out

    # ------------------------------------------------------------------ filter
    def _advance(self) -> List[Estimate]:
        """Process every pending cycle that is ready, oldest first."""
        out: List[Estimate] = []
        while self._pending and self._t is not None:
            s = min(self._pending)
            if s < self._t:
                del self._pending[s]
                self._warn(f'sonar cycle stamped {s * 1e-9:.3f} s precedes the odometry '
                           f'({self._t * 1e-9:.3f} s): dropped')
                continue
            cycle = self._pending[s]
            complete = bool(np.all(cycle.received | ~self._expected))
            timed_out = self._latest is not None and self._latest - s >= self.sync_timeout_ns
            if not (complete or timed_out):
                break
            if self._latest_odo is None or self._latest_odo < s:
                break  # wait for the odometry to reach the cycle
            del self._pending[s]
            out.append(self._process(s, cycle))
        return out

    def _process(self, stamp_ns: int, cycle: _Cycle) -> Estimate:
        missing = self._expected & ~cycle.received
        self._missed[missing] += 1
        for i in np.flatnonzero(missing & (self._missed >= self.stale_cycles)):
            self._expected[i] = False
            self._warn(f'{self.names[i]} has not reported for {self._missed[i]} cycles: its '
                       'readings are treated as missing')
        self._done = stamp_ns
        return self._estimate_at(stamp_ns, cycle.z)

    def _estimate_at(self, stamp_ns: int, z: Optional[np.ndarray]) -> Estimate:
        """Predict to ``stamp_ns`` with the queued odometry, then update with ``z``."""
        t_start = self._t
        x_sig = None
        u_sum = np.zeros(2)
        q_sum = np.zeros((2, 2))
        while self._intervals and self._intervals[0][0] < stamp_ns:
            t_a, t_b, u = self._intervals[0]
            if t_b <= stamp_ns:
                self._intervals.popleft()
                step = u
            else:  # split the interval straddling the stamp
                frac = (stamp_ns - t_a) / (t_b - t_a)
                step = frac * u
                self._intervals[0] = [stamp_ns, t_b, u - step]
            if self.filter == 'ekf':
                self._x, self._p = ekf.time_update(self._x, self._p, step, self.params)
            else:
                self._x, self._p, x_sig = ukf.time_update(self._x, self._p, step, self.params)
            u_sum += step
            q_sum += process_noise(step, self.params.noise)
        self._t = stamp_ns
        accepted = -1
        if z is not None:
            if self.grid is None:
                self._warn('no usable map yet: dead reckoning (covariance grows)')
            elif not np.isnan(z).all():
                if self.filter == 'ekf':
                    self._x, self._p, info = ekf.measurement_update(
                        self._x, self._p, z, self.grid, self.mounts, self.params)
                else:
                    self._x, self._p, info = ukf.measurement_update(
                        self._x, self._p, x_sig, z, self.grid, self.mounts, self.params)
                accepted = int(np.count_nonzero(info['accepted']))
        dt = (stamp_ns - t_start) * 1e-9 if t_start is not None else 0.0
        if dt > 0.0:
            vel, vel_cov = u_sum / dt, q_sum / dt ** 2
        else:
            vel, vel_cov = np.zeros(2), np.zeros((2, 2))
        return Estimate(stamp_ns=stamp_ns, pose=self._x.copy(), covariance=self._p.copy(),
                        velocity=vel, velocity_covariance=vel_cov, accepted=accepted)
