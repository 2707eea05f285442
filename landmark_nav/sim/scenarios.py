"""Named scenarios and the time-ordered event stream they produce.

``run_scenario(name, seed, **overrides)`` builds the world and mission, simulates the true
motion, the encoders and odometry, the laser and the sonar ring, and returns a
:class:`ScenarioResult` whose ``events`` are frozen dataclasses ordered by ``stamp_ns``
(ties: TruthSample, OdometrySample, SonarSample, ScanSample, RunMarker).

Randomness: ``root = np.random.default_rng(seed)``; ``root.spawn(3)`` gives independent
generators for the encoders, the laser and the sonar (in that order), so switching one
sensor off does not change the others' noise, and the same seed reproduces every array bit
for bit. The true path does not depend on the seed (closed-loop primitives use the true
pose; noise only enters the measurements).
"""

from dataclasses import dataclass, replace
import math
import numbers
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .control import (GoTo, Primitive, simulate_mission, Straight, TurnTo, Wait,
                      waypoint_mission)
from .laser import Laser, LaserConfig, ScanSample
from .robot import make_odometry, NS_PER_S, OdometryTrack, RobotParams, Trajectory
from .sonar import SonarConfig, SonarRing, SonarSample
from .world import World, wrap_angle

#: Stamp of the first sample of every scenario: 1_700_000_000 s after the Unix epoch.
START_NS = 1_700_000_000 * NS_PER_S


def _ro(a: Any) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class TruthSample:
    """Ground truth at an odometry step boundary (10 Hz).

    Attributes:
        stamp_ns: stamp [ns].
        pose: (3,) true ``[x, y, yaw]`` in the world frame, yaw in [-pi, pi).
        twist: (2,) true ``(v, w)`` [m/s, rad/s] of the step that ENDS at ``stamp_ns``
            (zeros for the first sample).
    """

    stamp_ns: int
    pose: np.ndarray
    twist: np.ndarray


@dataclass(frozen=True, eq=False)
class OdometrySample:
    """Wheel odometry of one SIP cycle (10 Hz); pose in the odom frame (== world at t0).

    Attributes:
        stamp_ns: stamp [ns].
        pose: (3,) dead-reckoned ``[x, y, yaw]`` (nominal R, b), yaw in [-pi, pi).
        covariance: (3, 3) covariance of ``[x, y, yaw]``.
        twist: (2,) ``(v, w)`` from the measured wheel speeds (eqs. 6-7).
        wheel_velocities: (2,) measured ``(omega_l, omega_r)`` [rad/s] over the step that
            ENDS at ``stamp_ns`` (zeros for the first sample); integrating these with eqs. 1-7
            over the samples in ``(t_a, t_b]`` reproduces the odometry from ``t_a`` to ``t_b``.
        wheel_positions: (2,) measured accumulated wheel angles [rad] at ``stamp_ns``.
    """

    stamp_ns: int
    pose: np.ndarray
    covariance: np.ndarray
    twist: np.ndarray
    wheel_velocities: np.ndarray
    wheel_positions: np.ndarray


@dataclass(frozen=True, eq=False)
class RunMarker:
    """One calibration experiment run (emitted at its end, ``stamp_ns == end_ns``).

    Attributes:
        stamp_ns: equals ``end_ns``.
        kind: ``'straight'``, ``'turn_ccw'`` or ``'turn_cw'``.
        group: ``'calibration'`` or ``'validation'``.
        index: 0-based position of the run in the scenario.
        start_ns: stamp at which the run's first wheel command starts (robot at rest).
        end_ns: stamp at which its last wheel command ends; the run's measured wheel speeds
            are those of the OdometrySamples with ``start_ns < stamp_ns <= end_ns``.
        start_pose: (3,) exact true pose at ``start_ns``.
        end_pose: (3,) exact true pose at ``end_ns``.
    """

    stamp_ns: int
    kind: str
    group: str
    index: int
    start_ns: int
    end_ns: int
    start_pose: np.ndarray
    end_pose: np.ndarray


Event = Union[TruthSample, OdometrySample, SonarSample, ScanSample, RunMarker]
_RANK = {TruthSample: 0, OdometrySample: 1, SonarSample: 2, ScanSample: 3, RunMarker: 4}


@dataclass(frozen=True, eq=False)
class ScenarioSpec:
    """Everything that defines a scenario before simulation."""

    name: str
    description: str
    world: World
    start_pose: Tuple[float, float, float]
    mission: Tuple[Primitive, ...]
    waypoints: np.ndarray
    robot: RobotParams
    laser: Optional[LaserConfig]
    sonar: Optional[SonarConfig]
    #: Laser blackouts as half-open ranges ``(first, stop)`` of mission primitive indices:
    #: every scan that starts while primitives ``first .. stop - 1`` run returns nothing
    #: (all ranges ``+inf``, REP 117 "no return"), e.g. a blinded or obstructed scanner.
    blackout: Tuple[Tuple[int, int], ...] = ()


@dataclass(frozen=True, eq=False)
class ScenarioResult:
    """Output of :func:`run_scenario`.

    Attributes:
        name: scenario name.
        seed: seed used.
        description: one-line description.
        world: the world (ground-truth walls, circles, corners).
        robot: robot parameters used.
        laser: laser configuration, None if the laser was off.
        sonar: sonar configuration, None if the sonar was off.
        start_pose: (3,) true start pose.
        waypoints: (W, 2) mission waypoints (empty for the calibration scenario).
        trajectory: ground-truth trajectory (use :meth:`truth_at` for arbitrary stamps).
        odometry: the full odometry track (same data as the OdometrySamples).
        events: time-ordered event stream.
        runs: RunMarkers (calibration scenario; empty otherwise).
        blackout: laser blackouts as ``(start_ns, end_ns)`` stamp windows: the scans with
            ``start_ns <= stamp_ns < end_ns`` have no returns (empty for most scenarios).
    """

    name: str
    seed: int
    description: str
    world: World
    robot: RobotParams
    laser: Optional[LaserConfig]
    sonar: Optional[SonarConfig]
    start_pose: np.ndarray
    waypoints: np.ndarray
    trajectory: Trajectory
    odometry: OdometryTrack
    events: Tuple[Event, ...]
    runs: Tuple[RunMarker, ...]
    blackout: Tuple[Tuple[int, int], ...] = ()

    @property
    def start_ns(self) -> int:
        """Stamp of the first sample."""
        return self.trajectory.start_ns

    @property
    def end_ns(self) -> int:
        """Stamp of the last odometry / truth sample."""
        return self.trajectory.end_ns

    @property
    def duration(self) -> float:
        """Duration [s]."""
        return (self.end_ns - self.start_ns) / NS_PER_S

    @property
    def path_length(self) -> float:
        """True distance travelled [m]."""
        d = np.diff(self.trajectory.poses[:, :2], axis=0)
        return float(np.hypot(d[:, 0], d[:, 1]).sum())

    def truth_at(self, stamp_ns: Any) -> np.ndarray:
        """Return the true pose(s) ``[x, y, yaw]`` at any stamp(s) in ``[start_ns, end_ns]``."""
        return self.trajectory.pose_at(stamp_ns)

    def of_type(self, cls: type) -> List[Any]:
        """Events of one type, in time order."""
        return [e for e in self.events if type(e) is cls]

    def counts(self) -> Dict[str, int]:
        """Return the number of events per type name."""
        out = {c.__name__: 0 for c in _RANK}
        for e in self.events:
            out[type(e).__name__] += 1
        return out

    def to_dict(self) -> Dict[str, Any]:
        """Plain-dict metadata (no events) for a YAML file next to the bag."""
        return {
            'scenario': self.name,
            'seed': int(self.seed),
            'description': self.description,
            'start_ns': int(self.start_ns),
            'end_ns': int(self.end_ns),
            'duration': float(self.duration),
            'path_length': self.path_length,
            'start_pose': [float(v) for v in self.start_pose],
            'waypoints': [[float(v) for v in p] for p in self.waypoints],
            'world': self.world.to_dict(),
            'robot': self.robot.to_dict(),
            'laser': None if self.laser is None else self.laser.to_dict(),
            'sonar': None if self.sonar is None else self.sonar.to_dict(),
            'runs': [{'kind': r.kind, 'group': r.group, 'index': int(r.index),
                      'start_ns': int(r.start_ns), 'end_ns': int(r.end_ns),
                      'start_pose': [float(v) for v in r.start_pose],
                      'end_pose': [float(v) for v in r.end_pose]} for r in self.runs],
            'counts': self.counts(),
            **({'blackout': [[int(a), int(b)] for a, b in self.blackout]}
               if self.blackout else {}),
        }


# ---------------------------------------------------------------------- scenario builders
def office_world() -> World:
    """9 m x 7.2 m room (corner chapter) with a cabinet, a partition, a pillar and a table.

    Room outline (counter-clockwise, free inside): a 1.5 m x 0.6 m cabinet recess against the
    south wall, a 1.5 m x 0.1 m partition from the north wall, a 45 deg chamfer in the
    north-west corner; a free-standing 0.4 m x 0.4 m pillar rotated 20 deg; four table legs
    (r = 0.025 m) of a 1.2 m x 0.8 m table. 17 corners: 7 concave with 90 deg free-space
    opening (3 room, 2 cabinet recess, 2 partition root), 2 concave 135 deg (chamfer) and
    8 convex with 270 deg opening (2 cabinet, 2 partition end, 4 pillar).
    """
    w = World('office')
    w.add_room([(0.0, 0.0), (6.0, 0.0), (6.0, 0.6), (7.5, 0.6), (7.5, 0.0), (9.0, 0.0),
                (9.0, 7.2), (4.55, 7.2), (4.55, 5.7), (4.45, 5.7), (4.45, 7.2), (0.8, 7.2),
                (0.0, 6.4)], label='room')
    w.add_rectangle(3.0, 3.0, 0.4, 0.4, yaw=math.radians(20.0), label='pillar')
    for x, y in ((6.0, 3.4), (7.2, 3.4), (6.0, 4.2), (7.2, 4.2)):
        w.add_circle(x, y, 0.025, label='table_leg')
    return w


OFFICE_WAYPOINTS = ((5.2, 1.3), (8.2, 1.4), (8.2, 5.6), (5.4, 6.4), (5.3, 4.9), (3.6, 4.9),
                    (1.3, 5.8), (1.3, 4.0), (4.3, 4.0), (4.3, 2.0), (1.2, 1.2))


def _office() -> ScenarioSpec:
    params = RobotParams()
    pts = np.array(OFFICE_WAYPOINTS)
    mission = [Wait(1.0)] + waypoint_mission(pts, params) + [TurnTo(0.0, 1), Wait(1.0)]
    return ScenarioSpec(
        name='office', description='9 m x 7.2 m office room, loop of ~30 m back to the start',
        world=office_world(), start_pose=(1.2, 1.2, 0.0), mission=tuple(mission),
        waypoints=pts, robot=params, laser=LaserConfig(), sonar=SonarConfig())


HALLWAY_LENGTH = 21.5
HALLWAY_WIDTH = 2.0
NICHE_WIDTH = 0.9
NICHE_DEPTH = 0.25
HALLWAY_NICHES_SOUTH = (3.5, 9.5, 15.5)
HALLWAY_NICHES_NORTH = (6.5, 12.5, 18.5)


def hallway_world() -> World:
    """21.5 m x 2 m hallway closed at both ends, three 0.9 m x 0.25 m door niches per side."""
    w = World('hallway')
    hw, hn = 0.5 * HALLWAY_WIDTH, 0.5 * NICHE_WIDTH
    pts: List[Tuple[float, float]] = [(0.0, -hw)]
    for cx in HALLWAY_NICHES_SOUTH:
        pts += [(cx - hn, -hw), (cx - hn, -hw - NICHE_DEPTH), (cx + hn, -hw - NICHE_DEPTH),
                (cx + hn, -hw)]
    pts += [(HALLWAY_LENGTH, -hw), (HALLWAY_LENGTH, hw)]
    for cx in sorted(HALLWAY_NICHES_NORTH, reverse=True):
        pts += [(cx + hn, hw), (cx + hn, hw + NICHE_DEPTH), (cx - hn, hw + NICHE_DEPTH),
                (cx - hn, hw)]
    pts += [(0.0, hw)]
    w.add_room(pts, label='hallway')
    return w


HALLWAY_WAYPOINTS = ((7.0, 0.1), (14.0, -0.1), (20.75, 0.0))


def _hallway() -> ScenarioSpec:
    params = RobotParams()
    pts = np.array(HALLWAY_WAYPOINTS)
    mission = [Wait(1.0)] + waypoint_mission(pts, params) + [Wait(1.0)]
    return ScenarioSpec(
        name='hallway', description='21.5 m x 2 m hallway with door niches, 20 m drive',
        world=hallway_world(), start_pose=(0.75, 0.0, 0.0), mission=tuple(mission),
        waypoints=pts, robot=params, laser=LaserConfig(), sonar=SonarConfig())


CALIBRATION_RUN_LENGTH = 5.0
CALIBRATION_CYCLES = 5
CALIBRATION_PAUSE = 1.0


def calibration_world() -> World:
    """Empty 10 m x 6 m room for the odometry calibration runs."""
    w = World('calibration')
    w.add_room([(0.0, 0.0), (10.0, 0.0), (10.0, 6.0), (0.0, 6.0)], label='room')
    return w


def _calibration() -> ScenarioSpec:
    params = RobotParams()
    mission: List[Primitive] = [Wait(CALIBRATION_PAUSE)]
    for _ in range(CALIBRATION_CYCLES):
        mission += [Straight(CALIBRATION_RUN_LENGTH, tag='straight'), Wait(CALIBRATION_PAUSE),
                    TurnTo(math.pi, 1, tag='turn_ccw'), Wait(CALIBRATION_PAUSE),
                    Straight(CALIBRATION_RUN_LENGTH, tag='straight'), Wait(CALIBRATION_PAUSE),
                    TurnTo(0.0, -1, tag='turn_cw'), Wait(CALIBRATION_PAUSE)]
    return ScenarioSpec(
        name='calibration',
        description='odometry calibration: 10 x 5 m straight runs, 5 CCW + 5 CW 180 deg turns',
        world=calibration_world(), start_pose=(2.5, 3.0, 0.0), mission=tuple(mission),
        waypoints=np.zeros((0, 2)), robot=params, laser=None, sonar=None)


AMBIGUOUS_ROOM = (24.0, 14.0)
AMBIGUOUS_POST_SIZE = 0.3
AMBIGUOUS_POST_SPACING = (0.45, 0.75)
AMBIGUOUS_ROW = (6.0, 15.0, 9.0, 0.25)  # x from, x to, y, lateral jitter [m]
AMBIGUOUS_WORLD_SEED = 3
AMBIGUOUS_LEG = ((4.0, 7.0), (16.0, 7.0))
AMBIGUOUS_LOOP = ((21.0, 7.0), (21.0, 12.5), (3.0, 12.5), (3.0, 2.0), (21.0, 2.0), (21.0, 4.5),
                  (10.5, 4.5), (10.5, 6.5))


def ambiguous_world() -> World:
    """24 m x 14 m hall with an irregular row of 0.3 m square posts (closely spaced corners).

    Posts are centred every 0.45-0.75 m (uniform) along ``y = 9 m`` from ``x = 6 m`` to
    ``15 m``, each shifted across the row by up to 0.25 m and turned by a uniform yaw in
    [0, 90) deg, drawn from a fixed generator (the world is the same for every seed): 15
    posts, 60 convex corners. Each post has a corner within 45 deg of any bisector direction,
    so every corner has a corner of the same kind (bisector within 45 deg, opening 270 deg)
    on a neighbouring post, 0.45-0.77 m away (median 0.64 m); the irregular pattern makes
    only the true pairing of a group of corners fit jointly.
    """
    rng = np.random.default_rng(AMBIGUOUS_WORLD_SEED)
    w = World('ambiguous')
    width, height = AMBIGUOUS_ROOM
    w.add_room([(0.0, 0.0), (width, 0.0), (width, height), (0.0, height)], label='room')
    x, x_end, y, jitter = AMBIGUOUS_ROW
    while x < x_end:
        w.add_rectangle(x, y + rng.uniform(-jitter, jitter), AMBIGUOUS_POST_SIZE,
                        AMBIGUOUS_POST_SIZE, yaw=rng.uniform(0.0, 0.5 * math.pi), label='post')
        x += rng.uniform(*AMBIGUOUS_POST_SPACING)
    return w


def _ambiguous() -> ScenarioSpec:
    """Map the post row, drive a 72 m loop with the laser blind, re-observe the row.

    The robot (odometry calibrated, ``k1 = k2 = k3 = 1``: only the random wheel noise is
    left, which the filter's odometry model describes) drives 12 m along the row 2 m from it,
    then the laser returns nothing while it drives a 72 m loop around the hall, so the pose
    uncertainty grows to tens of centimetres and degrees, comparable with the corner
    spacing; it stops 2.5 m in front of the middle of the row, where the blackout ends, and
    drives along the row again.
    """
    params = RobotParams(k1=1.0, k2=1.0, k3=1.0)
    (x0, y0), leg_end = AMBIGUOUS_LEG
    mission: List[Primitive] = [Wait(1.0), GoTo(*leg_end, tolerance=0.03)]
    first = len(mission)
    mission += [GoTo(x, y, tolerance=0.03) for x, y in AMBIGUOUS_LOOP]
    stop = len(mission)
    mission += [Wait(2.0), GoTo(*leg_end, tolerance=0.03), Wait(1.0)]
    return ScenarioSpec(
        name='ambiguous',
        description='irregular row of 0.3 m posts; laser blackout during a 72 m loop, '
                    'then re-observation',
        world=ambiguous_world(), start_pose=(x0, y0, 0.0), mission=tuple(mission),
        waypoints=np.array([leg_end, *AMBIGUOUS_LOOP, leg_end]), robot=params,
        laser=LaserConfig(), sonar=None, blackout=((first, stop),))


SCENARIOS: Dict[str, Callable[[], ScenarioSpec]] = {
    'office': _office,
    'hallway': _hallway,
    'calibration': _calibration,
    'ambiguous': _ambiguous,
}


def scenario_names() -> List[str]:
    """Return the valid scenario names."""
    return sorted(SCENARIOS)


def build_scenario(name: str) -> ScenarioSpec:
    """Return the (unsimulated) specification of a named scenario."""
    if not isinstance(name, str) or name not in SCENARIOS:
        raise ValueError(f'unknown scenario {name!r}; valid names: {scenario_names()}')
    return SCENARIOS[name]()


# ---------------------------------------------------------------------- running
OVERRIDE_KEYS = ('robot', 'laser', 'sonar')


def _check_seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise ValueError(f'seed must be a non-negative int, got {seed!r}')
    if seed < 0:
        raise ValueError(f'seed must be non-negative, got {seed}')
    return int(seed)


def _resolve(cls: type, default: Any, value: Any, optional: bool) -> Any:
    """Apply one override: instance, dict of fields, None/False (off) or True (default)."""
    if isinstance(value, cls):
        return value
    if value is None or value is False:
        if not optional:
            raise ValueError(f'{cls.__name__} override cannot be {value!r}')
        return None
    if value is True:
        return default if default is not None else cls()
    if isinstance(value, dict):
        base = default if default is not None else cls()
        try:
            return cls.from_dict({**_fields_dict(base), **value})
        except TypeError as exc:
            raise ValueError(str(exc)) from exc
    raise ValueError(f'cannot use {value!r} as {cls.__name__}')


def _fields_dict(obj: Any) -> Dict[str, Any]:
    return {f: getattr(obj, f) for f in obj.__dataclass_fields__}


def run_scenario(name: str, seed: int, **overrides: Any) -> ScenarioResult:
    """Simulate a named scenario.

    Args:
        name: one of :func:`scenario_names` (``'ambiguous'``, ``'calibration'``, ``'hallway'``,
            ``'office'``).
        seed: non-negative int; all randomness derives from ``np.random.default_rng(seed)``.
        **overrides: ``robot`` (RobotParams or dict of fields), ``laser`` / ``sonar``
            (config, dict of fields, True = default config, None / False = off).

    Returns:
        ScenarioResult with the time-ordered event stream.

    Raises:
        ValueError: unknown scenario, bad seed or bad override.
    """
    seed = _check_seed(seed)
    spec = build_scenario(name)
    bad = sorted(set(overrides) - set(OVERRIDE_KEYS))
    if bad:
        raise ValueError(f'unknown override(s) {bad}; valid: {list(OVERRIDE_KEYS)}')
    robot = _resolve(RobotParams, spec.robot, overrides.get('robot', spec.robot), False)
    laser_cfg = _resolve(LaserConfig, spec.laser, overrides.get('laser', spec.laser), True)
    sonar_cfg = _resolve(SonarConfig, spec.sonar, overrides.get('sonar', spec.sonar), True)
    spec = replace(spec, robot=robot, laser=laser_cfg, sonar=sonar_cfg)
    return simulate(spec, seed)


def simulate(spec: ScenarioSpec, seed: int) -> ScenarioResult:
    """Simulate a scenario specification (see :func:`run_scenario`)."""
    seed = _check_seed(seed)
    rng_odom, rng_laser, rng_sonar = np.random.default_rng(seed).spawn(3)
    traj, spans = simulate_mission(spec.robot, spec.start_pose, spec.mission, START_NS)
    odom = make_odometry(traj, spec.robot, rng_odom)
    stamps = traj.stamps_ns
    events: List[Event] = []
    true_yaw = wrap_angle(traj.poses[:, 2])
    odom_yaw = wrap_angle(odom.poses[:, 2])
    zero2 = np.zeros(2)
    for k, st in enumerate(stamps):
        st = int(st)
        tw = traj.twists[k - 1] if k > 0 else zero2
        events.append(TruthSample(stamp_ns=st, pose=_ro([*traj.poses[k, :2], true_yaw[k]]),
                                  twist=_ro(tw)))
        events.append(OdometrySample(
            stamp_ns=st, pose=_ro([*odom.poses[k, :2], odom_yaw[k]]),
            covariance=_ro(odom.covariances[k]),
            twist=_ro(odom.twists[k - 1] if k > 0 else zero2),
            wheel_velocities=_ro(odom.wheel_speeds[k - 1] if k > 0 else zero2),
            wheel_positions=_ro(odom.wheel_positions[k])))
    if spec.sonar is not None:
        events.extend(SonarRing(spec.world, spec.sonar).cycles(traj, rng_sonar))
    blackout = _blackout_windows(traj, spans, spec.blackout)
    if spec.laser is not None:
        events.extend(_blind(Laser(spec.world, spec.laser).scans(traj, rng_laser), blackout))
    runs = _run_markers(traj, spans)
    events.extend(runs)
    order = sorted(range(len(events)),
                   key=lambda i: (events[i].stamp_ns, _RANK[type(events[i])], i))
    return ScenarioResult(
        name=spec.name, seed=seed, description=spec.description, world=spec.world,
        robot=spec.robot, laser=spec.laser, sonar=spec.sonar, start_pose=_ro(spec.start_pose),
        waypoints=_ro(np.asarray(spec.waypoints, dtype=float).reshape(-1, 2)),
        trajectory=traj, odometry=odom, events=tuple(events[i] for i in order),
        runs=tuple(runs), blackout=blackout)


def _blackout_windows(traj: Trajectory, spans: Sequence[Any],
                      ranges: Sequence[Tuple[int, int]]) -> Tuple[Tuple[int, int], ...]:
    """Convert primitive index ranges ``(first, stop)`` to ``(start_ns, end_ns)`` windows."""
    out = []
    for first, stop in ranges:
        if not 0 <= first < stop <= len(spans):
            raise ValueError(f'blackout {(first, stop)} is not a primitive range of the mission '
                             f'(0 <= first < stop <= {len(spans)})')
        out.append((traj.start_ns + spans[first].start_step * traj.step_ns,
                    traj.start_ns + spans[stop - 1].end_step * traj.step_ns))
    return tuple(out)


def _blind(scans: List[ScanSample], windows: Sequence[Tuple[int, int]]) -> List[ScanSample]:
    """Return the scans with every range set to ``+inf`` inside the blackout windows."""
    if not windows:
        return scans
    out = []
    for scan in scans:
        if any(a <= scan.stamp_ns < b for a, b in windows):
            ranges = np.full_like(scan.ranges, math.inf)
            ranges.setflags(write=False)
            scan = replace(scan, ranges=ranges)
        out.append(scan)
    return out


def _run_markers(traj: Trajectory, spans: Sequence[Any]) -> List[RunMarker]:
    """Build RunMarkers for tagged primitives; first half of the runs = calibration group."""
    tagged = [s for s in spans if getattr(s.primitive, 'tag', None) is not None]
    out = []
    for i, s in enumerate(tagged):
        t0 = traj.start_ns + s.start_step * traj.step_ns
        t1 = traj.start_ns + s.end_step * traj.step_ns
        out.append(RunMarker(
            stamp_ns=t1, kind=s.primitive.tag,
            group='calibration' if i < (len(tagged) + 1) // 2 else 'validation', index=i,
            start_ns=t0, end_ns=t1, start_pose=_ro(traj.pose_at(t0)),
            end_pose=_ro(traj.pose_at(t1))))
    return out


__all__ = ['ambiguous_world', 'build_scenario', 'GoTo', 'OdometrySample', 'run_scenario',
           'RunMarker', 'ScenarioResult', 'ScenarioSpec', 'scenario_names', 'simulate',
           'START_NS', 'Straight', 'TruthSample', 'TurnTo', 'Wait']
