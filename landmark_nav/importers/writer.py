"""Write a parsed log into a rosbag2 (MCAP) bag following the imported-bag contract.

Topics: ``/scan`` (sensor_msgs/LaserScan, frame ``laser``), ``/odom`` (nav_msgs/Odometry,
``odom`` -> ``base_link``: the log's raw odometry, or synthetic drift from the reference),
``/ground_truth/odom`` (``map`` -> ``base_link``, when the log has a reference) and
``/scan_rear`` (frame ``laser_rear``, Carmen ``RLASER`` only). No ``/tf``: the laser mount
and the other facts are strings in ``metadata.yaml`` ``custom_data`` (keys
``landmark_nav.*``, see :data:`CUSTOM_KEYS`).
"""

from dataclasses import dataclass, field
from pathlib import Path
import shutil
import time
from typing import Dict, List, Optional

import numpy as np

from .common import ParsedLog
from .drift import DRIFT_MODELS, DriftModel, parse_drift_model, propagate_covariance, \
    synthetic_odometry
from .runs import find_restarts, Restart, RUN_JUMP_M, select_run
from .stamps import repair_streams, StampRepairs

__all__ = ['CUSTOM_KEYS', 'FORMATS', 'ImportResult', 'guess_format', 'import_log',
           'parse_log']

FORMATS = ('carmen', 'wean', 'breezyslam')

#: custom_data keys written into every imported bag, and what they hold.
CUSTOM_KEYS = {
    'landmark_nav.laser_mount': '"x y yaw" (m m rad), base_link -> laser',
    'landmark_nav.laser_sigma_range': "the sensor's stated 1-sigma range noise [m]",
    'landmark_nav.laser_model': 'the laser the log was recorded with',
    'landmark_nav.source': '"<format> <absolute path of the log>"',
    'landmark_nav.odometry': '"raw" (the log\'s odometry) or "synthetic" (drift model)',
    'landmark_nav.drift_model': 'noise model of /odom: its covariance, and the drift when '
                                'synthetic',
    'landmark_nav.drift_seed': 'seed of the synthetic drift (synthetic odometry only)',
    'landmark_nav.odometry_source': 'how raw odometry was rebuilt (Carmen --odom-lines only)',
    'landmark_nav.reference': 'where /ground_truth/odom comes from (when present)',
    'landmark_nav.repairs': 'the stamp repairs, per stream',
    'landmark_nav.laser_rear_mount': '"x y yaw" of the rear laser (Carmen RLASER only)',
    'landmark_nav.runs': 'a log of several runs: their starts (log lines) and the one '
                         'imported (all joined, or --run K)',
}


def guess_format(path) -> str:
    """Guess the format from the file name, else from the first data line.

    Raises:
        ValueError: Neither tells.

    """
    path = Path(path)
    name = path.name.lower()
    stem = name[:-3] if name.endswith('.gz') else name
    if stem.endswith('.clf'):
        return 'carmen'
    if stem.endswith('.dat'):
        return 'breezyslam'
    if stem.startswith('robotdata'):
        return 'wean'
    from .common import open_text
    with open_text(path) as f:
        for line in f:
            tokens = line.split()
            if not tokens or tokens[0].startswith('#'):
                continue
            if tokens[0] in ('FLASER', 'RLASER', 'ODOM', 'ROBOTLASER1', 'PARAM', 'SYNC'):
                return 'carmen'
            if tokens[0] in ('O', 'L'):
                return 'wean'
            if tokens[0].isdigit():
                return 'breezyslam'
            break
    raise ValueError(f'cannot tell the format of {path}; give --format '
                     f'({"|".join(FORMATS)})')


def parse_log(path, fmt: Optional[str] = None, poses: Optional[str] = None,
              lenient: bool = False, max_scans: Optional[int] = None,
              max_range: Optional[float] = None, odom_lines: bool = False,
              fov: Optional[float] = None, range_max_from: str = 'auto') -> ParsedLog:
    """Parse a log of any supported format (``fmt`` guessed when None).

    Raises:
        LineError: A malformed line, unless ``lenient``.
        ValueError: Unknown format, or an option that does not apply to the format.
        OSError: The file cannot be read.

    """
    path = Path(path)
    if not path.is_file():
        raise OSError(f'no log file at {path}')
    fmt = fmt or guess_format(path)
    if fmt not in FORMATS:
        raise ValueError(f'unknown format {fmt!r} (one of {", ".join(FORMATS)})')
    if max_scans is not None and max_scans < 1:
        raise ValueError(f'--max-scans must be >= 1, got {max_scans}')
    if fmt == 'carmen':
        from .carmen import parse_carmen
        return parse_carmen(path, poses=poses, lenient=lenient, max_scans=max_scans,
                            max_range=max_range, odom_lines=odom_lines, fov=fov,
                            range_max_from=range_max_from)
    if range_max_from != 'auto':
        raise ValueError(f'--range-max-from applies to Carmen logs only ({fmt} states no cap)')
    if fov is not None:
        raise ValueError(f'--fov applies to Carmen logs only ({fmt} geometry is fixed)')
    if odom_lines:
        raise ValueError(f'--odom-lines applies to Carmen logs only, not {fmt}')
    if max_range is not None:
        raise ValueError(f'--max-range applies to Carmen logs only ({fmt} codes are fixed)')
    if poses not in (None, 'raw'):
        raise ValueError(f'--poses {poses} applies to Carmen logs only ({fmt} odometry is raw)')
    if fmt == 'wean':
        from .wean import parse_wean
        return parse_wean(path, lenient=lenient, max_scans=max_scans)
    from .breezyslam import parse_breezyslam
    return parse_breezyslam(path, lenient=lenient, max_scans=max_scans)


@dataclass
class ImportResult:
    """What :func:`import_log` wrote."""

    out: Path
    log: ParsedLog
    counts: Dict[str, int]
    odometry: str  # 'raw' | 'synthetic'
    drift: DriftModel
    seed: Optional[int]
    repairs: Dict[str, StampRepairs]
    seconds: float
    lines: List[str] = field(default_factory=list)
    restarts: List[Restart] = field(default_factory=list)  # where the log's later runs start
    run: Optional[int] = None  # the run imported alone (1-based), None: all

    @property
    def summary(self) -> str:
        """Return the printed summary."""
        return '\n'.join(self.lines)


def _twist(stamps: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Return body-frame (vx, vy, wz) by backward differences (first one zero)."""
    out = np.zeros_like(poses)
    if len(poses) < 2:
        return out
    dt = np.diff(stamps)
    d = np.diff(poses[:, :2], axis=0)
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    dth = np.diff(poses[:, 2])
    dth = np.arctan2(np.sin(dth), np.cos(dth))
    ok = dt > 0
    inv = np.where(ok, 1.0 / np.where(ok, dt, 1.0), 0.0)
    out[1:, 0] = (c * d[:, 0] + s * d[:, 1]) * inv
    out[1:, 1] = (-s * d[:, 0] + c * d[:, 1]) * inv
    out[1:, 2] = dth * inv
    return out


def _range_lines(log: ParsedLog) -> List[str]:
    """Return the summary lines on no-return sentinels and the range cap of a parsed log."""
    out = []
    if log.sentinels:
        out.append('  no-return sentinels: ' + ', '.join(
            f'{m.value:g} m x{m.count} ({m.source}, -> {"+inf" if m.code > 0 else "NaN"})'
            for m in sorted(log.sentinels, key=lambda m: -m.count)))
    if log.cap is not None:
        out.append(f'  range cap: {log.cap.describe()}' + (
            ' (--range-max-from header keeps it)' if log.cap.overruled else ''))
    return out


def _fmt_pose(p) -> str:
    return ' '.join(f'{float(v):.6g}' for v in p)


def import_log(path, out, fmt: Optional[str] = None, poses: Optional[str] = None,
               reference=None, drift: Optional[str] = None, seed: Optional[int] = None,
               lenient: bool = False, force: bool = False, max_scans: Optional[int] = None,
               fallback_period: float = 1.0, progress: bool = False,
               max_range: Optional[float] = None, odom_lines: bool = False,
               fov: Optional[float] = None, range_max_from: str = 'auto',
               run: Optional[int] = None) -> ImportResult:
    """Import a log into a bag directory ``out``; return what was written.

    Args:
        path: The log (``.gz`` or plain).
        out: Bag directory to create.
        fmt: ``carmen``, ``wean`` or ``breezyslam``; guessed from the name when None.
        poses: Carmen only: what the pose fields hold (``raw`` or ``corrected``).
        reference: Carmen only: the corrected log of the same run, for a raw log.
        drift: Drift model for synthetic odometry (``pioneer``, ``none`` or gains);
            only for logs without raw odometry, which get ``pioneer`` when None.
        seed: Seed of the synthetic drift (default 0).
        lenient: Skip and count malformed lines instead of failing.
        force: Replace an existing bag directory at ``out``.
        max_scans: Import only the first scans (and the odometry up to the last one).
        fallback_period: Scan / odometry period [s] assumed when a stream has no two
            distinct stamps.
        progress: Show a tqdm progress bar while writing.
        max_range: Carmen only: readings at or above it are "no return" [m].
        odom_lines: Carmen corrected logs only: rebuild the raw odometry from the
            re-anchored ``ODOM`` lines instead of synthetic drift.
        fov: Carmen only: field of view of ``FLASER`` / ``RLASER`` lines [deg], for beam
            counts other than 180, 181, 360, 361.
        range_max_from: Carmen only: the range cap from the log's header unless its readings
            overrule it (``'auto'``), always from the header (``'header'``) or from the
            readings (``'data'``).
        run: Import only this run (1-based) of a log that holds several
            (:func:`~landmark_nav.importers.runs.find_restarts`); None: all, joined.

    Raises:
        LineError: A malformed line, unless ``lenient``.
        ValueError: Bad options, or a log without odometry and reference.
        BagError: ``out`` exists (without ``force``) or cannot be written.
        OSError: A file cannot be read.

    """
    from landmark_nav.bag import BagError, BagWriter
    from landmark_nav.conversions import make_odometry, make_scan
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import LaserScan

    t0 = time.monotonic()
    path = Path(path).resolve()
    out = Path(out)
    if seed is not None and not 0 <= int(seed) < 2 ** 32:
        raise ValueError(f'seed must be in [0, 2**32), got {seed}')
    if out.exists() and not force:
        raise BagError(f'{out} exists already; use --force to replace it')
    log = parse_log(path, fmt, poses, lenient, max_scans, max_range, odom_lines, fov,
                    range_max_from)
    if reference is not None:
        if log.fmt != 'carmen':
            raise ValueError(f'--reference applies to Carmen logs only, not {log.fmt}')
        if log.has_reference:
            raise ValueError(f'{path} already holds corrected poses; --reference pairs a raw '
                             'log (--poses raw) with its corrected log')
        from .carmen import pair_with_reference, parse_carmen
        ref_log = parse_carmen(reference, poses='corrected', lenient=lenient,
                               max_range=max_range, fov=fov)
        pair_with_reference(log, ref_log)
    restarts = find_restarts(log)
    if run is not None:
        log = select_run(log, restarts, run)

    # One clock for all streams: resets are found on the merged stream (log order) and
    # shift every stream alike; repeated / zero / backward stamps are repaired per stream.
    names = ['scan']
    streams = [log.scan_stamps]
    lines = [np.array([s.lineno for s in log.scans], dtype=int)]
    if log.has_odometry:
        if drift is not None:
            raise ValueError(f'{path.name} has raw odometry; --drift applies only to logs '
                             'without (Carmen corrected logs)')
        names.append('odom')
        streams.append(log.odom_stamps)
        lines.append(log.odom_lineno)
    if log.rear_scans:
        names.append('rear scan')
        streams.append([s.stamp for s in log.rear_scans])
        lines.append(np.array([s.lineno for s in log.rear_scans], dtype=int))
    fixed, reports = repair_streams(streams, lines, fallback_period)
    repaired = dict(zip(names, fixed))
    repairs: Dict[str, StampRepairs] = dict(zip(names, reports))
    scan_t = repaired['scan']
    if log.has_odometry:
        model = DRIFT_MODELS['pioneer']
        odometry, used_seed = 'raw', None
        odom_t = repaired['odom']
        odom_p = log.odom_poses
    elif log.has_reference:
        model = parse_drift_model(drift or 'pioneer')
        odometry, used_seed = 'synthetic', int(seed or 0)
        odom_t = scan_t[log.reference_index]
        odom_p = synthetic_odometry(log.reference_poses, model, used_seed)
    else:
        raise ValueError(f'{path.name} has neither odometry nor a reference')
    if seed is not None and odometry == 'raw':
        raise ValueError('--seed applies to synthetic odometry only')
    odom_cov = propagate_covariance(odom_p, model)
    odom_tw = _twist(odom_t, odom_p)
    rear_t = repaired.get('rear scan')

    def ns(t: float) -> int:
        return int(round(float(t) * 1e9))

    events = [(ns(t), 0, i) for i, t in enumerate(scan_t)]
    events += [(ns(t), 1, i) for i, t in enumerate(odom_t)]
    if log.has_reference:
        events += [(ns(scan_t[k]), 2, j) for j, k in enumerate(log.reference_index)]
    if rear_t is not None:
        events += [(ns(t), 3, i) for i, t in enumerate(rear_t)]
    events.sort()
    if events and events[0][0] < 0:
        raise ValueError(f'{path.name}: stamps before 1970 after repair')

    sensor = log.sensor
    if force and out.exists():
        if not (out / 'metadata.yaml').is_file():
            raise ValueError(f'{out} exists and is not a bag; refusing to replace it')
        shutil.rmtree(out)
    counts = {'/scan': 0, '/odom': 0, '/ground_truth/odom': 0, '/scan_rear': 0}
    no_return = errors = too_close = 0
    items = events
    if progress:
        from tqdm import tqdm
        items = tqdm(events, unit='msg', desc=path.name, leave=False)
    with BagWriter(out) as bag:
        bag.add_topic('/scan', LaserScan)
        bag.add_topic('/odom', Odometry)
        if log.has_reference:
            bag.add_topic('/ground_truth/odom', Odometry)
        if rear_t is not None:
            bag.add_topic('/scan_rear', LaserScan)
        for stamp_ns, kind, i in items:
            if kind in (0, 3):
                scan = (log.scans if kind == 0 else log.rear_scans)[i]
                topic, frame = (('/scan', 'laser') if kind == 0
                                else ('/scan_rear', 'laser_rear'))
                msg = make_scan(stamp_ns, frame, scan.angle_min, scan.angle_increment,
                                scan.ranges, sensor.range_min, sensor.range_max,
                                time_increment=sensor.time_increment)
                if kind == 0:
                    no_return += int(np.count_nonzero(np.isposinf(scan.ranges)))
                    errors += int(np.count_nonzero(np.isnan(scan.ranges)))
                    too_close += int(np.count_nonzero(np.isneginf(scan.ranges)))
            elif kind == 1:
                topic = '/odom'
                msg = make_odometry(stamp_ns, 'odom', 'base_link', odom_p[i], odom_cov[i],
                                    twist=odom_tw[i])
            else:
                topic = '/ground_truth/odom'
                msg = make_odometry(stamp_ns, 'map', 'base_link', log.reference_poses[i])
            bag.write(topic, stamp_ns, msg)
            counts[topic] += 1
        repairs_text = '; '.join(f'{k}: {r.describe()}' for k, r in repairs.items())
        custom = {
            'landmark_nav.laser_mount': _fmt_pose(log.mount),
            'landmark_nav.laser_sigma_range': f'{sensor.sigma_range:g}',
            'landmark_nav.laser_model': sensor.model,
            'landmark_nav.source': f'{log.fmt} {path}',
            'landmark_nav.odometry': odometry,
            'landmark_nav.drift_model': model.gains(),
            'landmark_nav.repairs': repairs_text,
        }
        if used_seed is not None:
            custom['landmark_nav.drift_seed'] = str(used_seed)
        if odom_lines:
            custom['landmark_nav.odometry_source'] = (
                'Carmen ODOM lines re-anchored at each scan: increments between scans chained')
        if log.has_reference:
            custom['landmark_nav.reference'] = (
                f'corrected poses of {Path(reference).resolve()}' if reference is not None
                else f'corrected poses of {path}')
        if log.rear_mount is not None:
            custom['landmark_nav.laser_rear_mount'] = _fmt_pose(log.rear_mount)
        if restarts:
            custom['landmark_nav.runs'] = (
                'starts at lines ' + ' '.join(str(n) for n in [1] + [r.line for r in restarts])
                + (f'; run {run} imported' if run is not None else '; all imported, joined'))
        for key, value in custom.items():
            bag.set_custom_data(key, value)
    seconds = time.monotonic() - t0

    scan0 = log.scans[0]
    beams = sorted({len(s.ranges) for s in log.scans})
    lines = [f'imported {log.fmt} {path} -> {out} in {seconds:.1f} s',
             f'  /scan: {counts["/scan"]} scans of {"/".join(map(str, beams))} beams from '
             f'{np.degrees(scan0.angle_min):.2f} deg in {np.degrees(scan0.angle_increment):.4f}'
             f' deg steps, range_max {sensor.range_max:g} m ({sensor.model}, sigma_range '
             f'{sensor.sigma_range:g} m); {no_return} no-return beams (+inf), {errors} error '
             'beams (NaN)' + (f', {too_close} too-close beams (-inf)' if too_close else '')]
    if odometry == 'raw':
        lines.append(f'  /odom: {counts["/odom"]} raw odometry poses (covariance: '
                     f'{model.describe()})')
    else:
        lines.append(f'  /odom: {counts["/odom"]} synthetic poses, drift {model.describe()}, '
                     f'seed {used_seed}')
    if log.has_reference:
        lines.append(f'  /ground_truth/odom: {counts["/ground_truth/odom"]} corrected poses')
    else:
        lines.append('  reference: none')
    if counts['/scan_rear']:
        lines.append(f'  /scan_rear: {counts["/scan_rear"]} scans, mount '
                     f'{_fmt_pose(log.rear_mount)}')
    lines.append(f'  mount base_link -> laser: {_fmt_pose(log.mount)} (x y yaw)')
    lines.append(f'  repairs: {repairs_text}')
    lines += _range_lines(log)
    if log.skipped:
        lines.append(f'  skipped {log.skipped} malformed lines (--lenient); first: '
                     f'{log.first_skipped}')
    if log.ignored:
        lines.append('  not imported: ' + ', '.join(
            f'{k} x{v}' for k, v in sorted(log.ignored.items())))
    if restarts:
        lines.append(f'  runs: {len(restarts) + 1} in one log (the clock restarts where the '
                     'robot is elsewhere: ' + '; '.join(r.describe() for r in restarts) + '); '
                     + (f'run {run} imported' if run is not None else
                        'all imported, joined at the restart (--run K imports run K alone)'))
    if odometry == 'raw' and len(odom_p) > 1 and (run is not None or not restarts):
        jumps = np.hypot(*np.diff(odom_p[:, :2], axis=0).T)
        k = int(np.argmax(jumps))
        if jumps[k] > RUN_JUMP_M:  # a wheeled base does not move 1 m between two readings
            lines.append(f'  note: the odometry jumps by {jumps[k]:.2f} m at t = '
                         f'{odom_t[k + 1]:.3f} s (record {k + 1}): two runs in one log?')
    lines += [f'  note: {n}' for n in log.notes]
    return ImportResult(out, log, counts, odometry, model, used_seed, repairs, seconds, lines,
                        restarts, run)
