"""A recorded bag seen as a scenario: odometry, scans and a reference trajectory.

:func:`load_bag` reads ``/odom`` and ``/scan`` of any rosbag2 directory (no DDS) and a
reference trajectory: ``/ground_truth/odom``, or a TUM file (``reference=``, which wins).
It wraps them in a :class:`BagScenario` that looks like a simulated
:class:`~landmark_nav.sim.scenarios.ScenarioResult` to the runners of
:mod:`landmark_nav.evaluation.slam` (``of_type``, ``truth_at``, ``laser``, ``world``), so a
bag and a simulated run go through the same per-scan code and the same scoring.

Facts about the sensor, in this order of precedence (the imported-bag contract):

* laser mount ``base_link -> laser``: the bag's ``custom_data`` key
  ``landmark_nav.laser_mount`` (``"x y yaw"``), else the simulator's ``ground_truth.yaml``
  (``laser.mount``), else the ``laser_pose`` argument, else ``0 0 0`` with a note;
* range noise sigma_r: ``landmark_nav.laser_sigma_range``, else ``ground_truth.yaml``
  (``laser.sigma_range``), else the ``sigma_r`` argument, else the corner extractor's
  default with a note; the bearing noise comes from ``ground_truth.yaml`` or the extractor's
  default.

The simulator's extras (the world: walls and true corners) are used only when the bag has a
``ground_truth.yaml``; ``world`` is None otherwise.

Frames: the filter's map frame starts at the first odometry pose. In a simulator bag that
is the world frame (odom == world at the start). When the first odometry pose differs from
the reference at its stamp (a real log: raw odometry starts anywhere), the odometry is re-
expressed so that it coincides with the reference at the first stamp both cover (``odometry
<- ref_a (+) (odo_a (-) odo)``, a rigid change of frame that leaves every odometry
increment unchanged) and a note says so; unaligned ATE and NEES are then measured from a
common start.
"""

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

from landmark_nav.bag import BagReader
from landmark_nav.conversions import odometry_to_pose, scan_to_data
from landmark_nav.evaluation.trajectory import read_tum
from landmark_nav.geometry import compose, interpolate_pose, relative
from landmark_nav.laser.corners import CornerParams
from landmark_nav.sim.laser import LaserConfig, ScanSample
from landmark_nav.sim.record import GROUND_TRUTH_FILE, read_ground_truth_file
from landmark_nav.sim.scenarios import OdometrySample
from landmark_nav.sim.world import World
import numpy as np

REFERENCE_TOPIC = '/ground_truth/odom'
TOPICS = ('/odom', '/scan')
MOUNT_KEY = 'landmark_nav.laser_mount'
SIGMA_KEY = 'landmark_nav.laser_sigma_range'
#: First-pose difference above which the odometry is re-expressed at the reference [m, rad].
ANCHOR_TOLERANCE = 1e-6


class BagScenario:
    """A bag seen through the interface ``run_slam`` / ``score_run`` use.

    Attributes:
        name: bag path (also the cache key of the visible-corner count).
        world: ground-truth world (simulator bags), else None.
        laser: laser configuration (mount, noise; the rest defaults for real bags).
        robot: None (not needed for SLAM).
        events: odometry and scan samples in time order.
        reference: where the reference comes from (topic or file); None without one.
        notes: facts the user should read (defaults taken, frames changed).
        scan_period: median time between scans [s].
        custom_data: the bag's ``custom_data`` (imported-bag facts, e.g. the drift model).
        simulator: whether the bag is a simulator recording (has ``ground_truth.yaml``).
    """

    def __init__(self, name: str, world: Optional[World], laser: LaserConfig, events: List,
                 truth_stamps: np.ndarray, truth_poses: Optional[np.ndarray],
                 reference: Optional[str] = '',
                 notes: Sequence[str] = (), scan_period: float = 0.1,
                 custom_data: Optional[Dict[str, str]] = None, simulator: bool = False) -> None:
        """Wrap the decoded bag content (``truth_poses`` None: no reference)."""
        self.name = name
        self.world = world
        self.laser = laser
        self.robot = None
        self.events = events
        self.reference = reference
        self.notes = list(notes)
        self.scan_period = float(scan_period)
        self.custom_data = dict(custom_data or {})
        self.simulator = bool(simulator)
        self._t = np.asarray(truth_stamps, dtype=np.int64)
        self._rel = (self._t - self._t[0]).astype(float)
        self._poses = None if truth_poses is None else np.asarray(truth_poses, dtype=float)

    @property
    def has_reference(self) -> bool:
        """Whether the bag (or a TUM file) gave a reference trajectory."""
        return self._poses is not None

    @property
    def start_ns(self) -> int:
        """Stamp of the first reference pose (without a reference: of the odometry)."""
        return int(self._t[0])

    @property
    def end_ns(self) -> int:
        """Stamp of the last reference pose (without a reference: of the odometry)."""
        return int(self._t[-1])

    @property
    def reference_stamps(self) -> np.ndarray:
        """(R,) stamps of the reference poses [ns]."""
        return self._t

    @property
    def reference_poses(self) -> np.ndarray:
        """(R, 3) reference poses ``[x, y, yaw]``."""
        return self._poses

    def truth_at(self, stamp_ns) -> np.ndarray:
        """Return the reference pose(s) interpolated at stamp(s) [ns] (NaN without one)."""
        s = np.asarray(stamp_ns, dtype=np.int64)
        if self._poses is None:
            return np.full(s.shape + (3,), np.nan)
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
    covariance: Optional[np.ndarray] = None


def read_track(reader: BagReader, topic: str) -> Tuple[np.ndarray, np.ndarray]:
    """Header stamps (N,) and poses (N, 3) of an Odometry topic."""
    stamps, poses = [], []
    for _, _, msg in reader.decoded([topic]):
        d = odometry_to_pose(msg)
        stamps.append(d.stamp_ns)
        poses.append(d.pose)
    return np.asarray(stamps, dtype=np.int64), np.asarray(poses, dtype=float).reshape(-1, 3)


def _parse_floats(text: str, n: int, what: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in str(text).split()], dtype=float)
    except ValueError:
        v = np.zeros(0)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ValueError(f'{what}: expected {n} finite numbers, got {text!r}')
    return v


def _simulator_meta(bag: Path) -> Optional[dict]:
    path = bag / GROUND_TRUTH_FILE
    if not path.is_file():
        return None
    meta = read_ground_truth_file(path) or {}
    if not isinstance(meta, dict):
        raise ValueError(f'{path}: not a mapping')
    return meta


def laser_config(custom: Dict[str, str], meta: Optional[dict],
                 laser_pose: Optional[Sequence[float]] = None,
                 sigma_r: Optional[float] = None, where: str = 'bag'):
    """Laser mount and noise by precedence (module docstring).

    Args:
        custom: The bag's ``custom_data``.
        meta: The simulator's ``ground_truth.yaml`` content, or None.
        laser_pose: ``(x, y, yaw)`` from the command line, or None.
        sigma_r: Range noise [m] from the command line, or None.
        where: Bag name for messages.

    Returns:
        ``(LaserConfig, notes)``; ``notes`` lists the defaults taken and the sources.

    Raises:
        ValueError: Malformed custom_data value or option.
    """
    notes = []
    sim_laser = dict((meta or {}).get('laser') or {})
    names = {f.name for f in fields(LaserConfig)}
    cfg = {k: v for k, v in sim_laser.items() if k in names}
    if MOUNT_KEY in custom:
        mount = _parse_floats(custom[MOUNT_KEY], 3, f'{where}: custom_data {MOUNT_KEY}')
        src = f'custom_data {MOUNT_KEY}'
    elif 'mount' in sim_laser:
        mount = np.array([float(v) for v in sim_laser['mount']], dtype=float)
        src = GROUND_TRUTH_FILE
    elif laser_pose is not None:
        mount = _parse_floats(' '.join(str(v) for v in laser_pose), 3, '--laser-pose')
        src = '--laser-pose'
    else:
        mount = np.zeros(3)
        src = 'default'
        notes.append('no laser mount in the bag (custom_data or ground_truth.yaml) nor '
                     '--laser-pose: using 0 0 0')
    if src != 'default' and laser_pose is not None and src != '--laser-pose':
        notes.append(f'--laser-pose ignored: the bag states the mount ({src})')
    cfg['mount'] = tuple(float(v) for v in mount)
    if SIGMA_KEY in custom:
        cfg['sigma_range'] = float(_parse_floats(custom[SIGMA_KEY], 1,
                                                 f'{where}: custom_data {SIGMA_KEY}')[0])
        s_src = f'custom_data {SIGMA_KEY}'
    elif 'sigma_range' in sim_laser:
        s_src = GROUND_TRUTH_FILE
    elif sigma_r is not None:
        if not (np.isfinite(sigma_r) and sigma_r > 0):
            raise ValueError(f'--sigma-r must be a positive number of metres, got {sigma_r}')
        cfg['sigma_range'] = float(sigma_r)
        s_src = '--sigma-r'
    else:
        cfg['sigma_range'] = CornerParams().sigma_r
        s_src = 'default'
        notes.append(f'no laser range noise in the bag nor --sigma-r: using the corner '
                     f'extractor default {CornerParams().sigma_r} m')
    if 'sigma_angle' not in cfg:
        cfg['sigma_angle'] = CornerParams().sigma_phi
    notes.append(f'laser mount {" ".join(f"{v:g}" for v in mount)} ({src}), sigma_r '
                 f'{cfg["sigma_range"]:g} m ({s_src})')
    return LaserConfig(**cfg), notes


def load_bag(bag, max_seconds: Optional[float] = None, reference=None,
             laser_pose: Optional[Sequence[float]] = None,
             sigma_r: Optional[float] = None,
             require_reference: bool = True) -> BagScenario:
    """Read a bag with ``/odom``, ``/scan`` and a reference into a :class:`BagScenario`.

    Args:
        bag: rosbag2 directory (a simulator recording or an imported log).
        max_seconds: Keep only the first seconds of odometry / scans (None: all).
        reference: TUM file of the reference trajectory (None: ``/ground_truth/odom``).
        laser_pose: Laser mount when the bag does not state it (module docstring).
        sigma_r: Range noise when the bag does not state it [m].
        require_reference: False: a bag without ``/ground_truth/odom`` (and no ``reference``)
            is read without a reference (``has_reference`` False, ``truth_at`` NaN, the odometry
            as it is); True: that is an error.

    Returns:
        The scenario; scans outside the odometry and reference time span are dropped.

    Raises:
        ValueError: Not a bag, a required topic missing or empty, no reference, or a
            malformed fact (one-line message).
    """
    bag = Path(bag)
    if not bag.is_dir():
        raise ValueError(f'{bag} is not a bag directory')
    meta = _simulator_meta(bag)
    world = None
    if meta is not None and meta.get('world'):
        world = World.from_dict(meta['world'])
    if meta is not None and 'laser' in meta and not meta.get('laser'):
        raise ValueError(f'{bag} was recorded without a laser')
    odo, scans, truth = [], [], []
    order = []  # (is scan, index) in log-time order: the order a subscriber gets them
    with BagReader(bag) as reader:
        topics = reader.topics()
        custom = reader.custom_data
        laser, notes = laser_config(custom, meta, laser_pose, sigma_r, str(bag))
        wanted = list(TOPICS)
        for t in TOPICS:
            if t not in topics or topics[t].count == 0:
                raise ValueError(f'{bag} has no {t} messages')
        has_ref = reference is not None
        if reference is None:
            if REFERENCE_TOPIC in topics and topics[REFERENCE_TOPIC].count > 0:
                wanted.append(REFERENCE_TOPIC)
                has_ref = True
            elif require_reference:
                raise ValueError(f'{bag} has no {REFERENCE_TOPIC} messages: give a reference '
                                 f'trajectory with --reference FILE.tum')
        for topic, _, msg in reader.decoded(wanted):
            if topic == '/scan':
                d = scan_to_data(msg)
                order.append((True, len(scans)))
                scans.append(ScanSample(
                    stamp_ns=int(d.stamp_ns), ranges=np.asarray(d.ranges, dtype=np.float32),
                    angle_min=float(d.angle_min), angle_max=float(d.angle_max),
                    angle_increment=float(d.angle_increment),
                    time_increment=float(d.time_increment), scan_time=float(d.scan_time),
                    range_min=float(d.range_min), range_max=float(d.range_max),
                    true_ranges=None))
            else:
                p = odometry_to_pose(msg)
                if topic == '/odom':
                    order.append((False, len(odo)))
                (odo if topic == '/odom' else truth).append(
                    _Stamped(int(p.stamp_ns), p.pose, p.covariance))
    if reference is not None:
        tum = read_tum(reference)
        truth = [_Stamped(int(t), p) for t, p in zip(tum.stamps_ns, tum.planar())]
        ref_name = str(reference)
    elif has_ref:
        ref_name = REFERENCE_TOPIC
    else:
        ref_name = None
    # /odom stays in log-time order (repeated or backward stamps included): the SLAM front
    # end judges them as the node does; spans and the anchor use it sorted.
    by_time = sorted(odo, key=lambda e: e.stamp_ns)
    if not has_ref:  # the odometry span stands for the reference span below
        truth = [_Stamped(by_time[0].stamp_ns, np.zeros(3)),
                 _Stamped(by_time[-1].stamp_ns, np.zeros(3))]
        if truth[1].stamp_ns == truth[0].stamp_ns:
            truth = truth[:1]
    truth.sort(key=lambda e: e.stamp_ns)
    ts = np.array([e.stamp_ns for e in truth], dtype=np.int64)
    if np.any(np.diff(ts) <= 0):
        raise ValueError(f'{bag}: duplicate stamps in the reference')
    t_end = min(by_time[-1].stamp_ns, ts[-1])
    if max_seconds is not None:
        t_end = min(t_end, by_time[0].stamp_ns + int(max_seconds * 1e9))
    use_odo = [e.stamp_ns <= t_end or e is by_time[0] for e in odo]
    by_time = [e for e in by_time if e.stamp_ns <= t_end or e is by_time[0]]
    t_start = max(by_time[0].stamp_ns, ts[0])
    sweep = [int(round(len(s.ranges) * s.time_increment * 1e9)) for s in scans]
    use_scan = [t_start <= s.stamp_ns and s.stamp_ns + w <= t_end for s, w in zip(scans, sweep)]
    kept = [s for s, u in zip(scans, use_scan) if u]
    if not kept:
        raise ValueError(f'{bag}: no /scan message inside the odometry / reference span'
                         if has_ref else f'{bag}: no /scan message inside the odometry span')
    if len(kept) < len(scans):
        why = '' if max_seconds is None else f' or after the first {max_seconds:g} s'
        span = 'odometry / reference' if has_ref else 'odometry'
        notes.append(f'{len(scans) - len(kept)} of {len(scans)} scans are not used (outside '
                     f'the {span} time span{why})')
    op = np.array([e.pose for e in odo], dtype=float)
    truth_poses = np.array([e.pose for e in truth])
    t_a = max(by_time[0].stamp_ns, int(ts[0]))  # first stamp with odometry and reference
    if has_ref and t_a <= min(by_time[-1].stamp_ns, int(ts[-1])):
        o_t = np.array([e.stamp_ns for e in by_time], dtype=np.int64)
        odo_a = interpolate_pose(float(t_a - o_t[0]), (o_t - o_t[0]).astype(float),
                                 np.array([e.pose for e in by_time], dtype=float))
        ref_a = interpolate_pose(float(t_a - ts[0]), (ts - ts[0]).astype(float), truth_poses)
        d = relative(odo_a, ref_a)
        if np.hypot(d[0], d[1]) > ANCHOR_TOLERANCE or abs(d[2]) > ANCHOR_TOLERANCE:
            op = compose(ref_a, relative(odo_a, op))
            notes.append('odometry re-expressed to start at the reference pose (it was '
                         f'{np.hypot(d[0], d[1]):.3f} m / {np.degrees(d[2]):.1f} deg away)')
    zero3 = np.zeros(3)
    events = []
    for is_scan, i in order:
        if is_scan and use_scan[i]:
            events.append(scans[i])
        elif not is_scan and use_odo[i]:
            e = odo[i]
            events.append(OdometrySample(
                stamp_ns=e.stamp_ns, pose=op[i], twist=zero3, wheel_velocities=np.zeros(2),
                covariance=np.zeros((3, 3)) if e.covariance is None
                else np.asarray(e.covariance, dtype=float), wheel_positions=np.zeros(2)))
    st = np.array([s.stamp_ns for s in kept], dtype=np.int64)
    period = float(np.median(np.diff(st))) * 1e-9 if st.size > 1 else 1.0 / laser.rate_hz
    if meta is not None and meta.get('laser'):
        period = 1.0 / float(laser.rate_hz)
    return BagScenario(str(bag), world, laser, events, ts, truth_poses if has_ref else None,
                       ref_name, notes, period, custom, meta is not None)


__all__ = ['BagScenario', 'laser_config', 'load_bag', 'read_track', 'REFERENCE_TOPIC']
