"""2D laser range finder simulator (SICK LMS200-like by default).

Noise model after Mavaei (2011), "Sensor noise model", eqs. 1-7: beam i is reported at its
nominal angle phi_i but physically travels along ``phi_i + eps_phi`` (eq. 3) and its range is
``D_i + eps_d`` (eq. 2), both zero-mean Gaussian. On top: dropouts (no return, ``+inf``) and
spurious short returns (uniform between ``range_min`` and the true range). Range encoding
follows REP 117: ``+inf`` = nothing within ``range_max``, ``-inf`` = closer than ``range_min``.
Motion during the sweep is modelled: beam i is taken at ``stamp + i * time_increment`` from
the true pose at that instant.
"""

from dataclasses import asdict, dataclass, fields
import math
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from .robot import NS_PER_S, Trajectory
from .world import World


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class LaserConfig:
    """Laser parameters (SI units, radians).

    Attributes:
        angle_min: angle of the first beam in the laser frame (-90 deg).
        angle_max: angle of the last beam (+90 deg).
        angle_increment: beam spacing (0.5 deg -> 361 beams).
        range_min: smallest reported range [m] (0.1; LMS200 has no useful data below).
        range_max: largest reported range [m] (8 m, LMS200 mm-mode).
        rate_hz: scans per second (10 Hz).
        time_increment: time between beams [s]; LMS200 mirror turns at 75 Hz and a
            revolution spans 720 half-degree steps -> (1/75)/720.
        sigma_range: std of eps_d [m] (eq. 2).
        sigma_angle: std of eps_phi [rad] (eq. 3).
        p_dropout: per-beam probability of no return (+inf).
        p_spurious: per-beam probability of a spurious short return.
        mount: laser pose ``(x, y, yaw)`` in base_link [m, m, rad].
        time_offset: delay of the first scan after the simulation start [s].
        keep_true_ranges: also store the noise-free ranges in each ScanSample (tests).
    """

    angle_min: float = -math.pi / 2.0
    angle_max: float = math.pi / 2.0
    angle_increment: float = math.pi / 360.0
    range_min: float = 0.1
    range_max: float = 8.0
    rate_hz: float = 10.0
    time_increment: float = (1.0 / 75.0) / 720.0
    sigma_range: float = 0.01
    sigma_angle: float = math.radians(0.1)
    p_dropout: float = 0.002
    p_spurious: float = 0.001
    mount: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    time_offset: float = 0.05
    keep_true_ranges: bool = False

    def __post_init__(self) -> None:
        """Validate and normalise the parameters."""
        object.__setattr__(self, 'mount', tuple(float(v) for v in self.mount))
        if len(self.mount) != 3:
            raise ValueError('LaserConfig.mount must be (x, y, yaw)')
        if not self.angle_increment > 0.0 or not self.angle_max >= self.angle_min:
            raise ValueError('LaserConfig needs angle_increment > 0 and angle_max >= angle_min')
        if not 0.0 <= self.range_min < self.range_max:
            raise ValueError('LaserConfig needs 0 <= range_min < range_max')
        if not self.rate_hz > 0.0 or self.time_increment < 0.0:
            raise ValueError('LaserConfig needs rate_hz > 0 and time_increment >= 0')
        if min(self.sigma_range, self.sigma_angle, self.p_dropout, self.p_spurious) < 0.0:
            raise ValueError('LaserConfig noise parameters must be >= 0')
        if self.p_dropout + self.p_spurious > 1.0:
            raise ValueError('LaserConfig p_dropout + p_spurious must be <= 1')
        if self.num_beams * self.time_increment > self.scan_time:
            raise ValueError('LaserConfig sweep longer than the scan period')

    @property
    def num_beams(self) -> int:
        """Number of beams (361 by default)."""
        return int(round((self.angle_max - self.angle_min) / self.angle_increment)) + 1

    @property
    def scan_time(self) -> float:
        """Time between scans [s] (``1 / rate_hz``)."""
        return 1.0 / self.rate_hz

    @property
    def beam_angles(self) -> np.ndarray:
        """Nominal beam angles (N,) in the laser frame."""
        return self.angle_min + self.angle_increment * np.arange(self.num_beams)

    def to_dict(self) -> Dict[str, Any]:
        """Plain dict of all fields plus ``num_beams`` and ``scan_time``."""
        d = asdict(self)
        d['mount'] = [float(v) for v in self.mount]
        d['num_beams'] = self.num_beams
        d['scan_time'] = self.scan_time
        return d

    @classmethod
    def from_dict(cls, data: Dict[str, Any]) -> 'LaserConfig':
        """Build from a (possibly partial) dict; derived keys are ignored."""
        names = {f.name for f in fields(cls)}
        data = {k: v for k, v in data.items() if k not in ('num_beams', 'scan_time')}
        bad = sorted(set(data) - names)
        if bad:
            raise ValueError(f'unknown LaserConfig field(s) {bad}; valid: {sorted(names)}')
        return cls(**data)


@dataclass(frozen=True, eq=False)
class ScanSample:
    """One laser scan (maps 1:1 onto sensor_msgs/LaserScan).

    Attributes:
        stamp_ns: time of the first beam [ns].
        ranges: (N,) float32 measured ranges [m]; +inf no return, -inf closer than range_min.
        angle_min: angle of beam 0 in the laser frame [rad].
        angle_max: angle of the last beam [rad].
        angle_increment: beam spacing [rad].
        time_increment: time between beams [s].
        scan_time: time between scans [s].
        range_min: minimum valid range [m].
        range_max: maximum valid range [m].
        true_ranges: (N,) float64 noise-free ranges along the nominal beams (inf = no hit
            within range_max), only if ``LaserConfig.keep_true_ranges``; else None.
    """

    stamp_ns: int
    ranges: np.ndarray
    angle_min: float
    angle_max: float
    angle_increment: float
    time_increment: float
    scan_time: float
    range_min: float
    range_max: float
    true_ranges: Optional[np.ndarray] = None


def compose(pose: np.ndarray, mount: Tuple[float, float, float]) -> np.ndarray:
    """Sensor pose(s) (..., 3) in the world from robot pose(s) and a base_link mount."""
    mx, my, myaw = mount
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    return np.stack([pose[..., 0] + c * mx - s * my, pose[..., 1] + s * mx + c * my,
                     pose[..., 2] + myaw], axis=-1)


class Laser:
    """Laser simulator bound to a world and a configuration."""

    def __init__(self, world: World, config: Optional[LaserConfig] = None) -> None:
        """Create a laser for ``world``."""
        self.world = world
        self.config = config or LaserConfig()

    def scan_stamps(self, traj: Trajectory) -> np.ndarray:
        """Stamps [ns] of all scans whose sweep lies inside the trajectory."""
        cfg = self.config
        period = int(round(NS_PER_S / cfg.rate_hz))
        first = traj.start_ns + int(round(cfg.time_offset * NS_PER_S))
        sweep = int(math.ceil((cfg.num_beams - 1) * cfg.time_increment * NS_PER_S))
        last = traj.end_ns - sweep
        if last < first:
            return np.zeros(0, dtype=np.int64)
        return np.arange(first, last + 1, period, dtype=np.int64)

    def scan(self, traj: Trajectory, stamp_ns: int, rng: np.random.Generator) -> ScanSample:
        """Simulate one scan starting at ``stamp_ns`` (vectorised over beams).

        Draws, in this order: ``standard_normal(N)`` (angle), ``standard_normal(N)`` (range),
        ``random(N)`` (dropout / spurious selector), ``random(N)`` (spurious range).
        """
        cfg = self.config
        n = cfg.num_beams
        phi = cfg.beam_angles
        t = (stamp_ns - traj.start_ns) / NS_PER_S + cfg.time_increment * np.arange(n)
        sensor = compose(traj.pose_at_seconds(t), cfg.mount)
        e_phi = rng.standard_normal(n) * cfg.sigma_angle  # eq. 3
        e_d = rng.standard_normal(n) * cfg.sigma_range  # eq. 2
        u = rng.random(n)
        u_spur = rng.random(n)
        hits = self.world.raycast(sensor[:, :2], sensor[:, 2] + phi + e_phi)
        meas = hits.ranges + e_d  # eq. 2: d_i = D_i + eps_d
        true_d = hits.ranges
        spur_hi = np.minimum(true_d, cfg.range_max)
        spur = cfg.range_min + u_spur * (spur_hi - cfg.range_min)
        out = np.where(meas > cfg.range_max, math.inf, meas)
        out = np.where(out < cfg.range_min, -math.inf, out)
        dropout = u < cfg.p_dropout
        spurious = (u >= cfg.p_dropout) & (u < cfg.p_dropout + cfg.p_spurious)
        out = np.where(spurious, spur, out)
        out = np.where(dropout, math.inf, out)
        truth = None
        if cfg.keep_true_ranges:
            clean = self.world.raycast(sensor[:, :2], sensor[:, 2] + phi, cfg.range_max)
            truth = _readonly(clean.ranges.copy())
        return ScanSample(stamp_ns=int(stamp_ns), ranges=_readonly(out.astype(np.float32)),
                          angle_min=float(cfg.angle_min),
                          angle_max=float(cfg.angle_min + (n - 1) * cfg.angle_increment),
                          angle_increment=float(cfg.angle_increment),
                          time_increment=float(cfg.time_increment),
                          scan_time=float(cfg.scan_time), range_min=float(cfg.range_min),
                          range_max=float(cfg.range_max), true_ranges=truth)

    def scans(self, traj: Trajectory, rng: np.random.Generator) -> List[ScanSample]:
        """Simulate all scans along a trajectory (see :meth:`scan_stamps`)."""
        return [self.scan(traj, int(s), rng) for s in self.scan_stamps(traj)]
