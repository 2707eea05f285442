"""Shared parts of the laser emulators: measurements ray-cast from a world, line timing.

The laser stands in the office world (:func:`landmark_nav.sim.scenarios.office_world`) at a
fixed pose, turns slowly on the spot, or drives a slow circle (``motion``). Each scan is
simulated by :class:`landmark_nav.sim.laser.Laser` with the simulator's noise model (range
and bearing noise, eqs. 2-3 of the noise model, dropouts and spurious short returns) and
motion during the sweep. On top, a fraction ``p_error`` of the beams fails (dazzle, read
error): those become NaN; a fraction ``p_close`` sees something on the window: -inf. Every
beam therefore carries its REP 117 meaning, which the emulators encode as their protocol
does: finite (a distance), +inf (no return), -inf (closer than the minimum range) or NaN
(error). :class:`LineQueue` times the frames an emulator sends (serial line occupancy at a
baud rate, delivery jitter).
"""

from collections import deque
from dataclasses import dataclass, field
import math
from typing import Deque, List, Optional, Sequence, Tuple

from landmark_nav.sim.laser import Laser, LaserConfig
from landmark_nav.sim.robot import NS_PER_S
from landmark_nav.sim.scenarios import office_world
from landmark_nav.sim.world import World
import numpy as np

MOTIONS = ('fixed', 'rotate', 'circle')
_DEFAULT_NOISE = LaserConfig()


@dataclass(frozen=True)
class SceneConfig:
    """Where the emulated laser is and how it measures.

    Attributes:
        pose: Start pose ``(x, y, yaw)`` of the laser in the world [m, m, rad].
        motion: ``fixed``, ``rotate`` (turn on the spot at ``yaw_rate``) or ``circle``
            (drive a circle of radius ``radius`` at ``speed``, centre to the laser's left).
        yaw_rate: Turn rate of ``rotate`` [rad/s].
        speed: Speed of ``circle`` [m/s].
        radius: Radius of ``circle`` [m].
        sigma_range: Range noise std [m] (eq. 2 of the noise model).
        sigma_angle: Bearing noise std [rad] (eq. 3).
        p_dropout: Probability per beam of no return (+inf).
        p_spurious: Probability per beam of a spurious short return.
        p_error: Probability per beam of a failed measurement (dazzle, read error: NaN).
        p_close: Probability per beam of a return closer than the minimum range (dust or an
            insect on the window: -inf).
        seed: Random seed of the noise.
    """

    pose: Tuple[float, float, float] = (5.0, 2.6, 1.2)
    motion: str = 'fixed'
    yaw_rate: float = 0.2
    speed: float = 0.2
    radius: float = 0.6
    sigma_range: float = _DEFAULT_NOISE.sigma_range
    sigma_angle: float = _DEFAULT_NOISE.sigma_angle
    p_dropout: float = _DEFAULT_NOISE.p_dropout
    p_spurious: float = _DEFAULT_NOISE.p_spurious
    p_error: float = 0.002
    p_close: float = 0.001
    seed: int = 1

    def __post_init__(self) -> None:
        """Validate."""
        object.__setattr__(self, 'pose', tuple(float(v) for v in self.pose))
        if len(self.pose) != 3 or not all(math.isfinite(v) for v in self.pose):
            raise ValueError(f'pose must be three finite numbers (x, y, yaw), got {self.pose}')
        if self.motion not in MOTIONS:
            raise ValueError(f'motion {self.motion!r} is not one of {", ".join(MOTIONS)}')
        if not self.radius > 0.0:
            raise ValueError(f'radius must be > 0, got {self.radius}')
        for name in ('sigma_range', 'sigma_angle', 'p_dropout', 'p_spurious', 'p_error',
                     'p_close'):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f'{name} must be >= 0')
        if self.p_dropout + self.p_spurious + self.p_error + self.p_close > 1.0:
            raise ValueError('p_dropout + p_spurious + p_error + p_close must be <= 1')


class _Motion:
    """The laser's path as the simulator's laser wants it (``start_ns``, ``pose_at_seconds``)."""

    start_ns = 0

    def __init__(self, config: SceneConfig) -> None:
        self.config = config

    def pose_at_seconds(self, t) -> np.ndarray:
        c = self.config
        t = np.asarray(t, dtype=float)
        x0, y0, yaw0 = c.pose
        if c.motion == 'rotate':
            return np.stack(np.broadcast_arrays(x0, y0, yaw0 + c.yaw_rate * t), axis=-1)
        if c.motion == 'circle':
            w = c.speed / c.radius
            yaw = yaw0 + w * t
            cx, cy = x0 - c.radius * math.sin(yaw0), y0 + c.radius * math.cos(yaw0)
            return np.stack([cx + c.radius * np.sin(yaw), cy - c.radius * np.cos(yaw), yaw],
                            axis=-1)
        return np.stack(np.broadcast_arrays(x0, y0, yaw0 + 0.0 * t), axis=-1)


@dataclass(frozen=True, eq=False)
class Measurement:
    """One simulated sweep: REP 117 ranges and surface incidence per beam."""

    ranges: np.ndarray  # (N,) float64: finite, +inf no return, -inf too close, NaN error
    cos_incidence: np.ndarray  # (N,) |cos| of the incidence angle (NaN: nothing hit)


class LaserScene:
    """Simulate sweeps of an emulated laser in a world (default: the office world).

    The laser's path is ``config.motion`` unless a ``motion`` is given: any object with
    ``start_ns = 0`` and ``pose_at_seconds(t)`` returning the laser pose(s) ``(..., 3)`` in
    the world at ``t`` seconds after the scene started (e.g. the base it is mounted on,
    :mod:`landmark_nav.emulators.robot`). The device calls :meth:`start` with the host time
    at which its scene time 0 lies (:attr:`origin`).
    """

    def __init__(self, config: Optional[SceneConfig] = None,
                 world: Optional[World] = None, motion=None) -> None:
        """Bind the configuration, the world and the path; the noise generator is seeded."""
        self.config = config or SceneConfig()
        self.world = world or office_world()
        self.motion = motion if motion is not None else _Motion(self.config)
        self.rng = np.random.default_rng(self.config.seed)
        self.origin: Optional[float] = None

    def start(self, now: float) -> None:
        """Anchor scene time 0 at host time ``now`` [s] (the first call wins)."""
        if self.origin is None:
            self.origin = float(now)

    def pose_at(self, t: float) -> np.ndarray:
        """Return the laser pose ``(x, y, yaw)`` at ``t`` seconds."""
        return self.motion.pose_at_seconds(float(t))

    def measure(self, t: float, angles: Sequence[float], time_increment: float,
                range_min: float, range_max: float, incidence: bool = False) -> Measurement:
        """Simulate one sweep whose first beam is taken at ``t`` seconds.

        Args:
            t: Time of the first beam [s] since the scene started.
            angles: Equally spaced beam angles in the laser frame [rad], increasing.
            time_increment: Time between beams [s].
            range_min: Returns closer than this are -inf [m].
            range_max: Returns farther than this are +inf [m].
            incidence: Also ray-cast the noise-free beams for the incidence angles
                (intensities); otherwise ``cos_incidence`` is all NaN.
        """
        a = np.asarray(angles, dtype=float)
        c = self.config
        n = a.size
        inc = float(a[1] - a[0]) if n > 1 else 1e-3
        cfg = LaserConfig(angle_min=float(a[0]), angle_max=float(a[0] + (n - 1) * inc),
                          angle_increment=inc, range_min=range_min, range_max=range_max,
                          rate_hz=1.0 / max(2.0 * n * time_increment, 1e-3),
                          time_increment=time_increment,
                          sigma_range=c.sigma_range, sigma_angle=c.sigma_angle,
                          p_dropout=c.p_dropout, p_spurious=c.p_spurious, time_offset=0.0)
        sample = Laser(self.world, cfg).scan(self.motion, int(round(t * NS_PER_S)), self.rng)
        ranges = sample.ranges.astype(np.float64)
        u = self.rng.random(n)
        ranges[u < c.p_close] = -math.inf
        ranges[(u >= c.p_close) & (u < c.p_close + c.p_error)] = math.nan
        cos_incidence = np.full(n, math.nan)
        if incidence:
            poses = self.motion.pose_at_seconds(t + time_increment * np.arange(n))
            cos_incidence = self.world.raycast(poses[:, :2], poses[:, 2] + a,
                                               range_max).cos_incidence
        return Measurement(ranges=ranges, cos_incidence=cos_incidence)


@dataclass
class LineQueue:
    """Outgoing frames with delivery times: serial line occupancy and delivery jitter.

    At ``baud`` > 0 a frame occupies the line for ``bytes * 10 / baud`` and arrives when its
    last byte has; ``jitter`` adds an exponential delay (mean ``jitter`` s). Frames keep
    their order.
    """

    baud: int
    jitter: float
    rng: np.random.Generator
    items: Deque[Tuple[float, bytes]] = field(default_factory=deque)
    line_free: float = -math.inf
    last_due: float = -math.inf

    def busy(self, now: float) -> bool:
        """Return whether the line is still sending at ``now``."""
        return self.baud > 0 and self.line_free > now

    def put(self, frame: bytes, ready: float) -> float:
        """Queue a frame that is ready at ``ready``; return its delivery time."""
        due = ready
        if self.baud > 0:
            due = max(ready, self.line_free) + len(frame) * 10.0 / self.baud
            self.line_free = due
        if self.jitter > 0.0:
            due += float(self.rng.exponential(self.jitter))
        due = max(due, self.last_due)
        self.last_due = due
        self.items.append((due, frame))
        return due

    def next_due(self) -> Optional[float]:
        """Return the delivery time of the oldest queued frame (None: empty)."""
        return self.items[0][0] if self.items else None

    def take(self, now: float) -> List[bytes]:
        """Remove and return the frames delivered by ``now``."""
        out = []
        while self.items and self.items[0][0] <= now:
            out.append(self.items.popleft()[1])
        return out

    def clear(self) -> None:
        """Drop queued frames and free the line."""
        self.items.clear()
        self.line_free = self.last_due = -math.inf


def _pose(text: str) -> Tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(','))
    except ValueError:
        values = ()
    if len(values) != 3:
        raise ValueError(f'pose must be x,y,yaw (m, m, rad), got {text!r}')
    return values


def add_scene_arguments(parser) -> None:
    """Add the options of the simulated scene (shared by the laser emulators)."""
    d = SceneConfig()
    parser.add_argument('--pose', type=_pose, default=d.pose, metavar='X,Y,YAW',
                        help='laser pose in the office world [m, m, rad] (default '
                             f'{",".join(f"{v:g}" for v in d.pose)})')
    parser.add_argument('--motion', choices=MOTIONS, default=d.motion,
                        help='fixed pose, rotate on the spot, or drive a circle')
    parser.add_argument('--yaw-rate', type=float, default=d.yaw_rate,
                        help=f'turn rate of --motion rotate [rad/s] (default {d.yaw_rate})')
    parser.add_argument('--speed', type=float, default=d.speed,
                        help=f'speed of --motion circle [m/s] (default {d.speed})')
    parser.add_argument('--p-error', type=float, default=d.p_error,
                        help='probability per beam of an error (dazzle) value (default '
                             f'{d.p_error})')
    parser.add_argument('--p-close', type=float, default=d.p_close,
                        help='probability per beam of a too-close return (default '
                             f'{d.p_close})')
    parser.add_argument('--jitter-ms', type=float, default=0.0,
                        help='mean extra delivery delay per frame (exponential) [ms], as USB '
                             'and OS buffering add')


def scene_from_args(args) -> LaserScene:
    """Build the scene from :func:`add_scene_arguments` options and ``--seed``."""
    return LaserScene(SceneConfig(pose=args.pose, motion=args.motion, yaw_rate=args.yaw_rate,
                                  speed=args.speed, p_error=args.p_error,
                                  p_close=args.p_close, seed=args.seed))
