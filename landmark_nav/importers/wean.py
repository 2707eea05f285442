"""Parse the CMU Wean Hall logs (``robotdata*.log``): ``O`` and ``L`` lines.

Line formats (x, y in cm, angles in rad, ranges in cm, stamps in s from the run's start)::

    O x y theta ts
    L x y theta xl yl thetal r1 .. r180 ts

``O`` lines are the raw odometry (``/odom``); ``L`` lines carry 180 readings spanning 180 deg
counter-clockwise from the robot's right, i.e. 1 deg steps from -90 deg to +89 deg (the
180-reading convention of the Carmen FLASER logs of the same laser family), the robot pose
(``x y theta``) and the laser pose (``xl yl thetal``), both interpolated to the scan time.
The laser mount is measured from the ``L`` lines (the median of ``robot^-1 (+) laser``;
the dataset states 25 cm ahead of the centre). There is no reference trajectory.

Ranges: the laser reports in cm with the SICK LMS cm-mode codes (8183 = above the maximum,
8191 = no echo -> +inf; 8187 S/N too low, 8189 overflow -> NaN, see
:func:`landmark_nav.importers.common.lms_cm_ranges`); ``laser_sigma_range`` is the LMS
cm-mode figure of :data:`landmark_nav.importers.carmen.LMS_SIGMA_RANGE` (0.01 m).
"""

from dataclasses import replace
import math
from pathlib import Path
from typing import Optional

import numpy as np

from .carmen import LMS_SIGMA_RANGE
from .common import LineSource, LMS_CM_BAND_M, lms_cm_ranges, ParsedLog, ScanRecord, Sensor
from .sentinels import mark_scans

__all__ = ['WEAN_BEAMS', 'WEAN_RANGE_MAX', 'parse_wean']

WEAN_BEAMS = 180
WEAN_RANGE_MAX = 81.82  # [m] largest LMS cm-mode distance (8182 cm); above it are codes
_CM = 0.01
_FIELDS = {'O': 5, 'L': 8 + WEAN_BEAMS}  # tokens per line, the type included


def _values(source: LineSource, lineno: int, tokens) -> Optional[np.ndarray]:
    """Return the numbers of an ``O`` / ``L`` line, or None after ``source.fail``."""
    kind, need = tokens[0], _FIELDS[tokens[0]]
    if len(tokens) != need:
        source.fail(lineno, f'malformed {kind} line ({len(tokens)} fields, need {need})')
        return None
    try:
        values = np.array(tokens[1:], dtype=float)
    except ValueError as err:
        source.fail(lineno, f'malformed {kind} line ({err})')
        return None
    if not np.all(np.isfinite(values)):
        source.fail(lineno, f'malformed {kind} line (non-finite value)')
        return None
    return values


def parse_wean(path, lenient: bool = False, max_scans: Optional[int] = None) -> ParsedLog:
    """Parse a Wean Hall log (optionally gzipped).

    Raises:
        LineError: A malformed line (file and line number), unless ``lenient``.
        ValueError: The log has no ``L`` lines.

    """
    path = Path(path)
    source = LineSource(path, lenient)
    scans, robot, laser, readings = [], [], [], []
    odom_t, odom_p, odom_n = [], [], []
    ignored = {}
    angle_min, inc = -math.pi / 2, math.pi / WEAN_BEAMS
    for lineno, tokens in source.lines():
        kind = tokens[0]
        if kind not in _FIELDS:
            ignored[kind] = ignored.get(kind, 0) + 1
            continue
        if max_scans is not None and len(scans) >= max_scans:
            break
        values = _values(source, lineno, tokens)
        if values is None:
            continue
        if kind == 'O':
            odom_t.append(values[3])
            odom_n.append(lineno)
            odom_p.append((values[0] * _CM, values[1] * _CM, values[2]))
        else:
            cm = values[6:6 + WEAN_BEAMS]
            readings.append(cm * _CM)
            scans.append(ScanRecord(float(values[-1]), lineno, angle_min, inc,
                                    lms_cm_ranges(cm, WEAN_RANGE_MAX)))
            robot.append((values[0] * _CM, values[1] * _CM, values[2]))
            laser.append((values[3] * _CM, values[4] * _CM, values[5]))
    if not scans:
        raise ValueError(f'{path}: no L lines (not a Wean Hall log?)')
    robot, laser = np.array(robot), np.array(laser)
    d = laser[:, :2] - robot[:, :2]
    c, s = np.cos(robot[:, 2]), np.sin(robot[:, 2])
    rel = np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1],
                           np.arctan2(np.sin(laser[:, 2] - robot[:, 2]),
                                      np.cos(laser[:, 2] - robot[:, 2]))))
    mount = tuple(float(v) for v in np.round(np.median(rel, axis=0), 4))  # cm data
    sensor = Sensor(model='SICK LMS (cm mode)', range_min=0.0, range_max=WEAN_RANGE_MAX,
                    sigma_range=LMS_SIGMA_RANGE)
    parts, marks = mark_scans(readings, [sc.ranges for sc in scans], band=LMS_CM_BAND_M)
    scans = [replace(sc, ranges=r) for sc, r in zip(scans, parts)]
    log = ParsedLog('wean', path, sensor, mount, scans=scans, sentinels=marks)
    log.odom_stamps = np.array(odom_t, dtype=float)
    log.odom_lineno = np.array(odom_n, dtype=int)
    log.odom_poses = np.array(odom_p, dtype=float).reshape(-1, 3)
    spread = float(np.max(np.hypot(rel[:, 0] - mount[0], rel[:, 1] - mount[1])))
    if spread > 0.005:
        log.notes.append(f'laser offset varies by up to {spread:.3f} m between L lines: '
                         'the median is used')
    for kind, count in ignored.items():
        log.ignored[kind] += count
    log.skipped, log.first_skipped = source.skipped, source.first_skipped
    return log
