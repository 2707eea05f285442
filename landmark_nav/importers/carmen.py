"""Parse Carmen logs (Radish data sets): ``FLASER``, ``RLASER``, ``ODOM``, ``ROBOTLASER1``.

Line formats (ranges in m, angles in rad, stamps in s)::

    FLASER n r1 .. rn x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_ts
    RLASER (same as FLASER, the rear laser)
    ODOM x y theta tv rv accel ipc_timestamp hostname logger_ts
    ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range
        accuracy remission_mode n r1 .. rn m e1 .. em laser_x laser_y laser_theta
        robot_x robot_y robot_theta tv rv forward_safety_dist side_safety_dist turn_axis
        ipc_timestamp hostname logger_ts
    PARAM name value hostname timestamp

The ``ipc_timestamp`` is used. Other line types (``NEFF``, ``SYNC``, ``TRUEPOS``,
``RAWLASER*``, ...) are counted and not imported. When a log has ``ROBOTLASER1`` lines they
are the front scans and ``FLASER`` lines (Carmen writes both for the same reading) are
ignored.

Beam geometry: ``ROBOTLASER1`` carries its own (``start_angle``, ``angular_resolution``)
and ``maximum_range``; the laser mount is the median of ``robot_pose^-1 (+) laser_pose``.
``FLASER`` spans 180 deg from -90 deg: 180 readings are 1 deg steps to +89 deg, 360 are
0.5 deg steps to +89.5 deg, 181 and 361 readings end at +90 deg (:func:`scan_geometry`,
as Carmen's own reader); other counts are refused unless ``fov`` (``--fov DEG``) is given;
its mount is ``(robot_frontlaser_offset, 0, 0)`` from the ``PARAM`` lines (0 when absent;
``RLASER``: ``(robot_rearlaser_offset, 0, pi)``). In a ``FLASER`` line ``x y theta`` is the
laser's pose and ``odom_*`` the robot's odometry; ``ROBOTLASER1`` gives both poses.

Poses: in a *raw* log the robot pose fields are the raw odometry (``/odom`` comes from the
``ODOM`` lines when there are any, else from the laser lines' ``odom_*`` / ``robot_*``
fields); in a *corrected* log (Radish "corrected" variants) the poses are the scan-matched
ones and the reference (``/ground_truth/odom``) is the robot pose under the laser pose,
``laser (+) mount^-1`` (``FLASER``) or ``robot_*`` (``ROBOTLASER1``). The Radish corrected
logs print the same pose in both triples; read as the laser's pose they align consecutive
scans best (freiburg-101, belgioioso: laser 4 cm behind the centre). The ``ODOM`` lines of
such logs are re-anchored to the corrected pose after every scan (an ``ODOM`` line with
stamp 0 repeating the scan's pose, then the wheel odometry since): they are not imported as
such (the importer writes synthetic drift instead), but ``odom_lines=True``
(``--odom-lines``) chains their increments into the raw odometry (:func:`rebuild_odometry`).

Ranges (SICK LMS in cm mode, 1 cm steps): the LMS reserved codes (81.83 .. 81.91 m) map per
:func:`landmark_nav.importers.common.lms_cm_ranges`; other readings at or above the maximum
range are the logger's "no return" (+inf, REP 117). The maximum is ``--max-range`` when
given, else the log's: ``maximum_range`` of a ``ROBOTLASER1`` line, else ``PARAM
robot_front_laser_max``, else 50 m (Carmen's default cap: the Radish logs without that
PARAM write 50, 51.05 or 51.15 m for beams without echo), taken as a hint the readings can
overrule (``range_max_from``, :func:`landmark_nav.importers.sentinels.judge_cap`). Logs at
mm resolution (an LMS in a mm mode) get the reserved band of their mode (e.g. 32.759 ..
32.767 m, :func:`landmark_nav.importers.sentinels.lms_code_band`), and values repeated far
more often than their neighbours at the top of the range are the logger's sentinels
(:func:`landmark_nav.importers.sentinels.find_spikes`): both no return, counted per value
in ``ParsedLog.sentinels``.

Range noise: SICK LMS200 / LMS291 technical data, statistical error (1 sigma) typ. 5 mm
(mm mode, up to 8 m); these logs are in cm mode (1 cm reading steps, +-4 cm systematic
error stated for cm mode), so ``laser_sigma_range`` is written as 0.01 m.
"""

from dataclasses import dataclass, replace as _replace
import math
from pathlib import Path
from typing import Dict, Iterator, List, Optional

import numpy as np

from .common import LineError, LineSource, LMS_CM_BAND_M, lms_cm_ranges, open_text, \
    ParsedLog, ScanRecord, Sensor
from .sentinels import find_spikes, judge_cap, lms_code_band, mark_scans, range_resolution

__all__ = ['CARMEN_DEFAULT_MAX_RANGE', 'CarmenScan', 'GeometryError', 'KNOWN_BEAMS',
           'LMS_SIGMA_RANGE', 'default_poses',
           'pair_with_reference', 'parse_carmen', 'read_carmen_scans', 'rebuild_odometry',
           'scan_geometry']

CARMEN_DEFAULT_MAX_RANGE = 50.0  # [m] when neither ROBOTLASER1 nor PARAM states it
LMS_SIGMA_RANGE = 0.01  # [m] SICK LMS2xx, cm mode (see the module docstring)
_LASER_TYPES = {'FLASER', 'RLASER'}


#: FLASER / RLASER beam counts whose geometry is known: Carmen's own reader
#: (``carmen_laser_guess_angle_increment``) spaces 180 / 181 beams at 1 deg and 360 / 361 at
#: 0.5 deg from -90 deg. For 400 / 401 it assumes 0.25 deg from -90 deg although such a
#: laser spans 100 deg, and other counts pi / (n - 1): those need ``fov``.
KNOWN_BEAMS = (180, 181, 360, 361)


class GeometryError(ValueError):
    """A FLASER / RLASER beam count whose geometry the log does not tell."""


def scan_geometry(n: int, fov_deg: Optional[float] = None):
    """Return (angle_min, angle_increment) of an n-beam Carmen ``FLASER`` / ``RLASER``.

    Without ``fov_deg``: the counts of :data:`KNOWN_BEAMS` from -90 deg (180 readings: 1 deg
    steps to +89 deg, 360: 0.5 deg to +89.5 deg, 181 / 361: to +90 deg). With ``fov_deg``
    (``--fov``): n beams spread evenly over the field of view centred ahead, the first at
    -fov/2 and the last at +fov/2.

    Raises:
        GeometryError: Another count without ``fov_deg``, or a bad ``fov_deg``.

    """
    if n <= 0:
        raise ValueError(f'FLASER with {n} readings')
    if fov_deg is not None:
        if not 0 < fov_deg <= 360 or n < 2:
            raise GeometryError(f'--fov {fov_deg:g} deg for {n} readings: need 0 < fov <= 360 '
                                'and >= 2 readings')
        fov = math.radians(fov_deg)
        return -fov / 2, fov / (n - 1)
    if n not in KNOWN_BEAMS:
        raise GeometryError(f'{n} readings: beam geometry unknown (known: '
                            f'{", ".join(map(str, KNOWN_BEAMS))}); give the field of view, '
                            'e.g. --fov 100')
    if n % 2 == 0:  # 180 readings: 1 deg steps from -90 deg, the last at +89 deg
        return -math.pi / 2, math.pi / n
    return -math.pi / 2, math.pi / (n - 1)


def default_poses(path) -> str:
    """Return ``'corrected'`` for files named ``*corrected*``, else ``'raw'``."""
    return 'corrected' if 'corrected' in Path(path).name.lower() else 'raw'


def _floats(tokens: List[str]) -> np.ndarray:
    values = np.array(tokens, dtype=float)
    if not np.all(np.isfinite(values)):
        raise ValueError('non-finite value')
    return values


def _key(values: np.ndarray) -> str:
    """Return a key equal for scans with identical readings (mm, formatting-proof)."""
    return np.rint(np.asarray(values) * 1000.0).astype(np.int64).tobytes().hex()


@dataclass
class _Laser:
    lineno: int
    stamp: float
    values: np.ndarray  # readings as printed [m]
    angle_min: float
    angle_increment: float
    max_range: Optional[float]
    robot: np.ndarray  # robot pose fields
    laser: Optional[np.ndarray] = None  # laser pose fields (ROBOTLASER1)


def _parse_flaser(tokens: List[str], fov_deg: Optional[float] = None) -> _Laser:
    n = int(tokens[1])
    if n <= 0:
        raise ValueError(f'{n} readings')
    if len(tokens) < n + 9:
        raise ValueError(f'{len(tokens)} fields for {n} readings (need >= {n + 9})')
    values = _floats(tokens[2:2 + n])
    poses = _floats(tokens[2 + n:8 + n])
    stamp = float(tokens[8 + n])
    a0, inc = scan_geometry(n, fov_deg)
    return _Laser(0, stamp, values, a0, inc, None, poses[3:6], poses[0:3])


def _parse_robotlaser(tokens: List[str]) -> _Laser:
    head = _floats(tokens[2:7])
    start, fov, res, max_range, _accuracy = head
    n = int(tokens[8])
    if n <= 0 or len(tokens) < 10 + n:
        raise ValueError(f'{len(tokens)} fields for {n} readings')
    values = _floats(tokens[9:9 + n])
    m = int(tokens[9 + n])
    base = 10 + n + max(m, 0)
    if m < 0 or len(tokens) < base + 12:
        raise ValueError(f'{len(tokens)} fields for {n} readings and {m} remissions')
    poses = _floats(tokens[base:base + 6])
    stamp = float(tokens[base + 11])
    if not res > 0:
        raise ValueError(f'angular resolution {res}')
    if abs(n * res - fov) > 1.5 * res and abs((n - 1) * res - fov) > 1.5 * res:
        raise ValueError(f'{n} readings at {res} rad do not span the field of view {fov} rad')
    return _Laser(0, stamp, values, float(start), float(res), float(max_range), poses[3:6],
                  poses[0:3])


def _parse_odom(tokens: List[str]):
    if len(tokens) < 8:
        raise ValueError(f'{len(tokens)} fields (need >= 8)')
    pose = _floats(tokens[1:4])
    return float(tokens[7]), pose


def _relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c, s = math.cos(a[2]), math.sin(a[2])
    d = b[:2] - a[:2]
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1],
                     math.atan2(math.sin(b[2] - a[2]), math.cos(b[2] - a[2]))])


def _robot_from_laser(laser: np.ndarray, mount) -> np.ndarray:
    """Return the robot poses whose laser (mounted at ``mount``) has the poses ``laser``."""
    mx, my, myaw = mount
    th = laser[:, 2] - myaw
    c, s = np.cos(th), np.sin(th)
    out = np.column_stack((laser[:, 0] - (c * mx - s * my), laser[:, 1] - (s * mx + c * my),
                           np.arctan2(np.sin(th), np.cos(th))))
    return out


def parse_carmen(path, poses: Optional[str] = None, lenient: bool = False,
                 max_scans: Optional[int] = None, max_range: Optional[float] = None,
                 odom_lines: bool = False, fov: Optional[float] = None,
                 range_max_from: str = 'auto') -> ParsedLog:
    """Parse a Carmen log (``.log``, ``.clf``, optionally gzipped).

    Args:
        path: The log.
        poses: ``'raw'`` or ``'corrected'`` (what the pose fields hold); default from the
            file name (:func:`default_poses`).
        lenient: Skip and count malformed lines instead of raising.
        max_scans: Keep only the first front scans (and the odometry up to the last one).
        max_range: Readings at or above it are "no return" [m] (overrides what the log
            states, e.g. 8.191 or 32.767 for logs of an LMS in a mm mode).
        odom_lines: Corrected logs: rebuild the raw odometry at the scans from the ``ODOM``
            lines (:func:`rebuild_odometry`) instead of leaving it to synthetic drift.
        fov: Field of view of ``FLASER`` / ``RLASER`` lines [deg] (:func:`scan_geometry`);
            needed for beam counts other than :data:`KNOWN_BEAMS`.
        range_max_from: Where the range cap comes from when ``max_range`` is None:
            ``'auto'`` the log's (``maximum_range``, ``PARAM robot_front_laser_max``, else
            50 m) unless the readings overrule it, ``'header'`` the log's always, ``'data'``
            the readings' (:func:`landmark_nav.importers.sentinels.judge_cap`).

    Raises:
        LineError: A malformed line (file and line number), unless ``lenient``; a beam
            count of unknown geometry without ``fov`` (also when ``lenient``).
        ValueError: The log has no laser scans, or ``poses`` is unknown.

    """
    path = Path(path)
    poses = poses or default_poses(path)
    if poses not in ('raw', 'corrected'):
        raise ValueError(f"--poses must be 'raw' or 'corrected', got {poses!r}")
    source = LineSource(path, lenient)
    params: Dict[str, List[tuple]] = {}  # name -> [(line number, value)]
    front: Dict[str, List[_Laser]] = {'FLASER': [], 'ROBOTLASER1': []}
    rear: List[_Laser] = []
    odom: List[tuple] = []
    ignored: Dict[str, int] = {}
    for lineno, tokens in source.lines():
        kind = tokens[0]
        try:
            if kind in ('FLASER', 'RLASER'):
                laser = _parse_flaser(tokens, fov)
            elif kind == 'ROBOTLASER1':
                laser = _parse_robotlaser(tokens)
            elif kind == 'ODOM':
                stamp, pose = _parse_odom(tokens)
                odom.append((lineno, stamp, pose))
                continue
            else:
                if kind == 'PARAM' and len(tokens) >= 3:
                    params.setdefault(tokens[1], []).append((lineno, tokens[2]))
                else:
                    ignored[kind] = ignored.get(kind, 0) + 1
                continue
        except GeometryError as err:  # not a malformed line: --lenient does not skip it
            raise LineError(path, lineno, f'{kind}: {err}') from None
        except (IndexError, ValueError) as err:
            source.fail(lineno, f'malformed {kind} line ({err})')
            continue
        laser.lineno = lineno
        (rear if kind == 'RLASER' else front[kind]).append(laser)

    use = 'ROBOTLASER1' if front['ROBOTLASER1'] else 'FLASER'
    lasers = front[use]
    if use == 'ROBOTLASER1' and front['FLASER']:
        ignored['FLASER'] = len(front['FLASER'])
    if not lasers:
        raise ValueError(f'{path}: no FLASER or ROBOTLASER1 lines (not a Carmen log?)')
    if max_scans is not None:
        lasers = lasers[:max_scans]

    notes = []

    def param(name: str, default: float) -> float:
        given = params.get(name)
        if not given:
            return default
        values = [v for _, v in given]
        if len(set(values)) > 1:
            notes.append(f'PARAM {name} given as {", ".join(values)}: using the last')
        try:
            value = float(values[-1])
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise LineError(path, given[-1][0], f'PARAM {name} {values[-1]!r} is not a number')
        return value

    log_max = param('robot_front_laser_max', CARMEN_DEFAULT_MAX_RANGE)
    stated_by = ('PARAM robot_front_laser_max' if params.get('robot_front_laser_max')
                 else 'the Carmen default cap')
    if use == 'ROBOTLASER1':
        stated_by = 'ROBOTLASER1 maximum_range'
    raw = np.concatenate([s.values for s in lasers])
    mm_band = lms_code_band(raw)  # mm readings: an LMS in a mm mode
    band = mm_band or (LMS_CM_BAND_M if range_resolution(raw) >= 0.01 else None)
    spikes = find_spikes(raw)
    cap = None
    if max_range is not None:
        if not 0 < max_range < math.inf:
            raise ValueError(f'max range must be > 0, got {max_range}')
        log_max = float(max_range)
        lasers = [_replace(s, max_range=None) for s in lasers]
    else:
        stated = max(s.max_range or log_max for s in lasers)
        cap = judge_cap(raw, stated, [p.value for p in spikes], band, mode=range_max_from)
        if cap.overruled:
            log_max = cap.used
            lasers = [_replace(s, max_range=None) for s in lasers]
    if use == 'ROBOTLASER1':
        rel = np.array([_relative(s.robot, s.laser) for s in lasers])
        mount = tuple(float(v) for v in np.median(rel, axis=0))
        spread = float(np.max(np.hypot(*(rel[:, :2] - np.array(mount[:2])).T)))
        if spread > 0.01:
            notes.append(f'laser mount varies by up to {spread:.3f} m between ROBOTLASER1 '
                         'lines: the median is used')
    else:
        mount = (param('robot_frontlaser_offset', 0.0), 0.0, 0.0)
    maxima = {s.max_range or log_max for s in lasers}
    model = f'SICK LMS (mm mode, codes from {mm_band[0]:g} m)' if mm_band else 'SICK LMS (cm mode)'
    sensor = Sensor(model=model, range_min=0.0, range_max=float(max(maxima)),
                    sigma_range=LMS_SIGMA_RANGE)

    def records(scans: List[_Laser]) -> List[ScanRecord]:
        parts, marks = mark_scans([s.values for s in scans],
                                  [lms_cm_ranges(s.values * 100.0, s.max_range or log_max)
                                   for s in scans], spikes, band)
        if scans is lasers:
            log.sentinels = marks
        return [ScanRecord(s.stamp, s.lineno, s.angle_min, s.angle_increment, r,
                           _key(s.values)) for s, r in zip(scans, parts)]

    log = ParsedLog('carmen', path, sensor, mount, notes=notes)
    log.scans = records(lasers)
    if cap is not None:
        log.cap = _replace(cap, stated_by=stated_by)
    last_line = lasers[-1].lineno
    robot = np.array([s.robot for s in lasers])
    if poses == 'corrected':
        log.reference_index = np.arange(len(lasers))
        if use == 'FLASER':  # x y theta is the laser's pose: robot = laser (+) mount^-1
            log.reference_poses = _robot_from_laser(np.array([s.laser for s in lasers]),
                                                    mount)
        else:
            log.reference_poses = robot
        if odom and odom_lines:
            log.odom_stamps = log.scan_stamps
            log.odom_lineno = np.array([s.lineno for s in lasers], dtype=int)
            log.odom_poses, anchors = rebuild_odometry(lasers, odom, path)
            log.notes.append(f'odometry rebuilt from the ODOM increments between scans '
                             f'({anchors} re-anchoring ODOM lines dropped)')
        elif odom_lines:
            raise ValueError(f'{path}: no ODOM lines to rebuild the odometry from')
        elif odom:
            log.ignored['ODOM (corrected log: re-anchored to the reference; '
                        '--odom-lines rebuilds odometry from them)'] = len(odom)
    elif odom_lines:
        raise ValueError('--odom-lines applies to corrected logs (--poses corrected)')
    else:
        if odom:
            kept = [o for o in odom if max_scans is None or o[0] <= last_line]
            log.odom_stamps = np.array([o[1] for o in kept], dtype=float)
            log.odom_lineno = np.array([o[0] for o in kept], dtype=int)
            log.odom_poses = np.array([o[2] for o in kept], dtype=float).reshape(-1, 3)
        else:
            log.odom_stamps = log.scan_stamps
            log.odom_lineno = np.array([s.lineno for s in lasers], dtype=int)
            log.odom_poses = robot
    if rear:
        rear = [s for s in rear if max_scans is None or s.lineno <= last_line]
        log.rear_scans = records(rear)
        log.rear_mount = (param('robot_rearlaser_offset', 0.0), 0.0, math.pi)
    for kind, count in ignored.items():
        log.ignored[kind] += count
    log.skipped, log.first_skipped = source.skipped, source.first_skipped
    return log


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c, s = math.cos(a[2]), math.sin(a[2])
    th = a[2] + b[2]
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1],
                     math.atan2(math.sin(th), math.cos(th))])


def rebuild_odometry(lasers: List['_Laser'], odom: List[tuple], path) -> tuple:
    """Rebuild raw odometry at each scan from the re-anchored ``ODOM`` lines of a log.

    In the Radish corrected logs the ``ODOM`` line right after each scan repeats the scan's
    corrected pose (stamp 0: the odometry was re-anchored there) and the following ones add
    the wheel odometry measured since. So the raw increment from scan k to scan k+1 is
    ``relative(anchor_k, last ODOM before scan k+1)``, and chaining these increments gives
    the raw odometry (eq. 13 / eq. 16). Returns (poses at the scans (n, 3), anchors
    dropped).

    Raises:
        ValueError: An ODOM line after a scan does not repeat its pose (not re-anchored).

    """
    events = sorted([(s.lineno, 0, i) for i, s in enumerate(lasers)]
                    + [(o[0], 1, j) for j, o in enumerate(odom)])
    base_a = np.zeros(3)  # ODOM pose that maps to base_b in the rebuilt frame
    base_b = np.zeros(3)
    last = None  # last ODOM pose
    out = np.zeros((len(lasers), 3))
    after_scan = None
    anchors = 0
    for lineno, kind, i in events:
        if kind == 0:
            out[i] = (_compose(base_b, _relative(base_a, last)) if last is not None
                      else lasers[i].robot)
            after_scan = i
            continue
        pose = odom[i][2]
        if after_scan is not None:
            scan = lasers[after_scan]
            if np.max(np.abs(pose - scan.robot)) > 1e-6:
                raise ValueError(f'{path}:{lineno}: this ODOM line does not repeat the pose of '
                                 f'the scan at line {scan.lineno}: the log does not re-anchor '
                                 'its odometry, --odom-lines does not apply')
            base_a, base_b = pose, out[after_scan]
            after_scan = None
            anchors += 1
            last = pose
            continue
        last = pose
    return out, anchors


def pair_with_reference(log: ParsedLog, reference: ParsedLog) -> int:
    """Give a raw log the corrected poses of the same run's corrected log; return matches.

    A corrected log keeps a subset of the raw scans: scan j of ``reference`` is paired with
    the next raw scan (in order) whose readings are identical.

    Raises:
        ValueError: ``reference`` has no reference poses, or no scan matches.

    """
    if not reference.has_reference:
        raise ValueError(f'{reference.path} holds no corrected poses (use a corrected log '
                         'or --poses corrected for it)')
    by_key: Dict[str, List[int]] = {}
    for i, scan in enumerate(log.scans):
        by_key.setdefault(scan.key, []).append(i)
    index, poses = [], []
    last = -1
    for j, k in enumerate(reference.reference_index):
        candidates = [i for i in by_key.get(reference.scans[k].key, ()) if i > last]
        if candidates:
            last = candidates[0]
            index.append(last)
            poses.append(reference.reference_poses[j])
    if not index:
        raise ValueError(f'no scan of {reference.path} has the readings of a scan of '
                         f'{log.path}: not the same run?')
    log.reference_index = np.array(index, dtype=int)
    log.reference_poses = np.array(poses, dtype=float).reshape(-1, 3)
    unmatched = len(reference.reference_index) - len(index)
    log.notes.append(f'reference {reference.path.name}: {len(index)} scans paired, '
                     f'{unmatched} reference scans without an identical raw scan')
    return len(index)


# ------------------------------------------------------------------------ simple reader


@dataclass(frozen=True)
class CarmenScan:
    """One FLASER reading (the simple reader used by the feature tests and benchmarks)."""

    stamp: float
    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    pose: np.ndarray
    odom_pose: np.ndarray

    @property
    def angles(self) -> np.ndarray:
        """Return the beam angles [rad]."""
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges))


def read_carmen_scans(path, max_range: float = 40.0) -> Iterator[CarmenScan]:
    """Yield the FLASER scans of a (optionally gzipped) Carmen log, stamps as printed.

    Readings at or beyond ``max_range`` are reported as +inf (REP 117); no code mapping and
    no stamp repair (use :func:`parse_carmen` for that).

    Raises:
        ValueError: A FLASER line is malformed (message names the line number).

    """
    path = Path(path)
    with open_text(path) as f:
        for lineno, line in enumerate(f, 1):
            if not line.startswith('FLASER '):
                continue
            fields = line.split()
            try:
                n = int(fields[1])
                values = np.array(fields[2:2 + n], dtype=float)
                rest = np.array(fields[2 + n:8 + n], dtype=float)
                stamp = float(fields[8 + n])
                angle_min, inc = scan_geometry(n)
            except (IndexError, ValueError) as err:
                raise ValueError(f'{path}:{lineno}: malformed FLASER line ({err})') from err
            if len(values) != n or len(rest) != 6:
                raise ValueError(f'{path}:{lineno}: FLASER line too short')
            ranges = np.where(values >= max_range, np.inf, values)
            yield CarmenScan(stamp, ranges, angle_min, inc, rest[:3], rest[3:])
