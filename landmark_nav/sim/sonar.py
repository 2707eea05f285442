"""Pioneer 2-DX 16-sonar ring simulator.

Each transducer reports the nearest echo inside its cone (``field_of_view``, 25 deg; the
self-localization chapter's Polaroid 6500 has a half-lobe Theta_0 = 12.5 deg, eq. 10). The
cone is sampled by ``num_rays`` rays; a ray whose angle of incidence (from the surface
normal) exceeds ``specular_angle`` is reflected away and gives no echo (specular miss).
Range noise is Gaussian with std ``sigma0 + sigma1 * r``. REP 117 encoding: ``+inf`` = no
echo within ``max_range``, ``-inf`` = closer than ``min_range``. All 16 sonars are fired
once per P2OS SIP cycle (T = 0.1 s) and carry that cycle's stamp (the real firing is
sequential within the cycle; this is ignored).
"""

from dataclasses import asdict, dataclass, fields
import math
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from .laser import compose
from .robot import Trajectory
from .world import World

# Pioneer 2-DX sonar mounting (ARIA p2dx.p, docs/protocols/p2os.md §6): x [mm], y [mm],
# heading [deg] in base_link.
_P2DX_SONAR_MM_DEG = (
    (69, 136, 90), (114, 119, 50), (148, 78, 30), (166, 27, 10),
    (166, -27, -10), (148, -78, -30), (114, -119, -50), (69, -136, -90),
    (-157, -136, -90), (-203, -119, -130), (-237, -78, -150), (-255, -27, -170),
    (-255, 27, 170), (-237, 78, 150), (-203, 119, 130), (-157, 136, 90),
)

#: (16, 3) sonar poses ``[x, y, yaw]`` in base_link [m, m, rad], ARIA p2dx order.
SONAR_MOUNTS = np.array([(x / 1000.0, y / 1000.0, math.radians(h))
                         for x, y, h in _P2DX_SONAR_MM_DEG])
SONAR_MOUNTS.setflags(write=False)
#: Cone width of one transducer [rad].
SONAR_FIELD_OF_VIEW = math.radians(25.0)
#: Default minimum and maximum reported range [m].
SONAR_MIN_RANGE = 0.1
SONAR_MAX_RANGE = 5.0


@dataclass(frozen=True)
class SonarConfig:
    """Sonar ring parameters (SI units, radians).

    Attributes:
        field_of_view: cone width [rad] (25 deg).
        num_rays: rays sampled across the cone (odd, so one lies on the axis).
        specular_angle: max incidence angle from the surface normal that still echoes [rad].
        sigma0: constant range noise std [m].
        sigma1: range-proportional noise std [-] (0.01 = 1 %).
        min_range: minimum reported range [m].
        max_range: maximum reported range [m].
        mounts: (16, 3) transducer poses in base_link; default :data:`SONAR_MOUNTS`.
    """

    field_of_view: float = SONAR_FIELD_OF_VIEW
    num_rays: int = 11
    specular_angle: float = math.radians(40.0)
    sigma0: float = 0.01
    sigma1: float = 0.01
    min_range: float = SONAR_MIN_RANGE
    max_range: float = SONAR_MAX_RANGE
    mounts: Tuple[Tuple[float, float, float], ...] = tuple(
        tuple(float(v) for v in row) for row in SONAR_MOUNTS)

    def __post_init__(self) -> None:
        """Validate and normalise the parameters."""
        mounts = tuple(tuple(float(v) for v in row) for row in self.mounts)
        object.__setattr__(self, 'mounts', mounts)
        if not mounts or any(len(r) != 3 for r in mounts):
            raise ValueError('SonarConfig.mounts must be a non-empty list of (x, y, yaw)')
        if int(self.num_rays) != self.num_rays or self.num_rays < 1:
            raise ValueError('SonarConfig.num_rays must be a positive integer')
        if not 0.0 <= self.field_of_view < math.pi or not 0.0 < self.specular_angle <= math.pi:
            raise ValueError('SonarConfig angles out of range')
        if not 0.0 <= self.min_range < self.max_range:
            raise ValueError('SonarConfig needs 0 <= min_range < max_range')
        if self.sigma0 < 0.0 or self.sigma1 < 0.0:
            raise ValueError('SonarConfig noise parameters must be >= 0')

    @property
    def num_sonars(self) -> int:
        """Number of transducers (16)."""
        return len(self.mounts)

    def to_dict(self) -> Dict[str, Any]:
        """Plain dict of all fields."""
        d = asdict(self)
        d['mounts'] = [list(r) for r in self.mounts]
        d['num_rays'] = int(self.num_rays)
        return d

    @classmethod
    def from_dict(cls, data: Dict[str, Any]) -> 'SonarConfig':
        """Build from a (possibly partial) dict; unknown keys raise ValueError."""
        names = {f.name for f in fields(cls)}
        bad = sorted(set(data) - names)
        if bad:
            raise ValueError(f'unknown SonarConfig field(s) {bad}; valid: {sorted(names)}')
        return cls(**data)


@dataclass(frozen=True, eq=False)
class SonarSample:
    """One sonar cycle (maps onto 16 sensor_msgs/Range messages, one per transducer).

    Attributes:
        stamp_ns: cycle stamp [ns] (same as the odometry sample of that SIP cycle).
        ranges: (16,) float32 ranges [m] from each transducer; +inf no echo, -inf too close.
        field_of_view: cone width [rad].
        min_range: minimum valid range [m].
        max_range: maximum valid range [m].
    """

    stamp_ns: int
    ranges: np.ndarray
    field_of_view: float = SONAR_FIELD_OF_VIEW
    min_range: float = SONAR_MIN_RANGE
    max_range: float = SONAR_MAX_RANGE


class SonarRing:
    """Sonar ring simulator bound to a world and a configuration."""

    def __init__(self, world: World, config: Optional[SonarConfig] = None) -> None:
        """Create a sonar ring for ``world``."""
        self.world = world
        self.config = config or SonarConfig()

    def true_ranges(self, robot_poses: Any) -> np.ndarray:
        """Return noise-free ranges (C, S) for robot poses (C, 3), vectorised over poses/rays."""
        cfg = self.config
        poses = np.asarray(robot_poses, dtype=float).reshape(-1, 3)
        mounts = np.array(cfg.mounts)
        c, s_n, r_n = poses.shape[0], mounts.shape[0], int(cfg.num_rays)
        sensors = compose(poses[:, None, :], tuple(mounts.T))  # (C, S, 3)
        offs = (np.linspace(-0.5, 0.5, r_n) if r_n > 1 else np.zeros(1)) * cfg.field_of_view
        ang = sensors[:, :, None, 2] + offs[None, None, :]  # (C, S, R)
        org = np.broadcast_to(sensors[:, :, None, :2], (c, s_n, r_n, 2))
        hits = self.world.raycast(org.reshape(-1, 2), ang.reshape(-1), cfg.max_range)
        echo = hits.cos_incidence >= math.cos(cfg.specular_angle)  # specular miss otherwise
        rng_ = np.where(echo, hits.ranges, math.inf).reshape(c, s_n, r_n)
        return rng_.min(axis=2)

    def readings(self, robot_poses: Any, rng: np.random.Generator) -> np.ndarray:
        """Return noisy ranges (C, S) float64; draws ``standard_normal((C, S))`` once."""
        true_r = self.true_ranges(robot_poses)
        return self._noisy(true_r, rng.standard_normal(true_r.shape))

    def _noisy(self, true_r: np.ndarray, z: np.ndarray) -> np.ndarray:
        cfg = self.config
        finite = np.isfinite(true_r)
        r = np.where(finite, true_r, 0.0)
        meas = np.where(finite, r + (cfg.sigma0 + cfg.sigma1 * r) * z, math.inf)
        meas = np.where(meas > cfg.max_range, math.inf, meas)
        return np.where(meas < cfg.min_range, -math.inf, meas)

    def cycles(self, traj: Trajectory, rng: np.random.Generator,
               chunk: int = 128) -> List[SonarSample]:
        """One :class:`SonarSample` per step boundary of the trajectory (10 Hz)."""
        cfg = self.config
        stamps = traj.stamps_ns
        poses = traj.poses
        z = rng.standard_normal((poses.shape[0], cfg.num_sonars))
        out: List[SonarSample] = []
        for i0 in range(0, poses.shape[0], chunk):
            true_r = self.true_ranges(poses[i0:i0 + chunk])
            meas = self._noisy(true_r, z[i0:i0 + chunk]).astype(np.float32)
            for j in range(meas.shape[0]):
                row = meas[j].copy()
                row.setflags(write=False)
                out.append(SonarSample(stamp_ns=int(stamps[i0 + j]), ranges=row,
                                       field_of_view=float(cfg.field_of_view),
                                       min_range=float(cfg.min_range),
                                       max_range=float(cfg.max_range)))
        return out
