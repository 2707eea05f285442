"""Parse the BreezySLAM ``.dat`` logs of the Mines ParisTech rover (``exp1``, ``exp2``).

One line per scan, whitespace separated: token 0 the time stamp [us], tokens 2 and 3 the
cumulative left / right wheel encoder counts, tokens 24..705 the 682 ranges [mm] of a
Hokuyo URG-04LX; the line ends with one more token, ignored (as the dataset's own loader
does). Other tokens (robot status) are not imported.

Odometry, with the dataset's geometry (wheel radius r = 77 mm, half axle b = 165 mm) and
its authors' conversion of ticks to wheel angle, phi = ticks * 180 / 2000 deg::

    D   = r (dphi_L + dphi_R)          forward distance per line
    dth = (r / b) (dphi_R - dphi_L)    heading change per line

(the dataset authors' formulas; with 2000 ticks per wheel turn they are the usual
differential-drive ones, D = r' (dL + dR) / 2 and dth = r' (dR - dL) / (2 b), in true wheel
angles), integrated as x += D cos(th + dth/2), y += D sin(th + dth/2), th += dth
(self-localization chapter eqs. 1-3, midpoint heading).

Laser: 682 beams are URG-04LX steps 44..725 (front = step 384, 1024 steps per turn,
counter-clockwise), so angle_min = -340 * 2 pi / 1024 = -119.53 deg; time_increment
0.1 s / 1024 (600 rpm); range_max 5.6 m (DMAX of the sensor's PP reply; the datasheet
guarantees 4 m but the logs hold echoes to 5.58 m). Readings below 20 mm are the URG error
codes, mapped like the SCIP 2.0 driver does
(:data:`landmark_nav.drivers.scip2.ERROR_CODE_RANGES`: 0..6 no return -> +inf, others
NaN); 0 ("possibly at 22 m") is most of them in these logs. The laser sits 145 mm ahead of
the axle. Range noise: the URG-04LX datasheet states an accuracy of +-10 mm from 60 mm to
1 m (+-1 % of the distance beyond), written as ``laser_sigma_range`` 0.01 m.
"""

from dataclasses import replace
import math
from pathlib import Path
from typing import Optional

from landmark_nav.drivers.scip2 import ERROR_CODE_RANGES, step_angles, URG_04LX
import numpy as np

from .common import LineSource, ParsedLog, ScanRecord, Sensor
from .sentinels import mark_scans

__all__ = ['BREEZY_BEAMS', 'RoverGeometry', 'parse_breezyslam', 'ticks_to_odometry']

BREEZY_BEAMS = 682
_FIRST_RANGE = 24
_FIELDS = _FIRST_RANGE + BREEZY_BEAMS + 1
URG_SIGMA_RANGE = 0.01  # [m] URG-04LX datasheet accuracy +-10 mm (60 mm .. 1 m)
_CODES = np.array(ERROR_CODE_RANGES)


class RoverGeometry:
    """The Mines rover: wheel radius, half axle, ticks per 180 deg, laser offset [m]."""

    wheel_radius = 0.077
    half_axle = 0.165
    ticks_per_half_turn = 2000
    laser_x = 0.145


def ticks_to_odometry(left, right, geometry=RoverGeometry) -> np.ndarray:
    """Integrate cumulative encoder counts into poses (n, 3), the first at the origin."""
    left = np.asarray(left, dtype=float)
    right = np.asarray(right, dtype=float)
    to_rad = math.pi / geometry.ticks_per_half_turn  # ticks * 180 / 2000 deg
    dl = np.diff(left) * to_rad
    dr = np.diff(right) * to_rad
    dist = geometry.wheel_radius * (dl + dr)
    dth = geometry.wheel_radius / geometry.half_axle * (dr - dl)
    th = np.concatenate(([0.0], np.cumsum(dth)))
    mid = th[:-1] + 0.5 * dth  # eqs. 1-3 with the midpoint heading
    x = np.concatenate(([0.0], np.cumsum(dist * np.cos(mid))))
    y = np.concatenate(([0.0], np.cumsum(dist * np.sin(mid))))
    return np.column_stack((x, y, np.arctan2(np.sin(th), np.cos(th))))


def parse_breezyslam(path, lenient: bool = False,
                     max_scans: Optional[int] = None) -> ParsedLog:
    """Parse a BreezySLAM ``.dat`` log (optionally gzipped).

    Raises:
        LineError: A malformed line (file and line number), unless ``lenient``.
        ValueError: The log has no valid line.

    """
    path = Path(path)
    source = LineSource(path, lenient)
    angles = step_angles(URG_04LX.amin, BREEZY_BEAMS)
    angle_min = float(angles[0])
    inc = 2.0 * math.pi / URG_04LX.ares
    scans, stamps, ticks, readings = [], [], [], []
    for lineno, tokens in source.lines():
        if max_scans is not None and len(scans) >= max_scans:
            break
        if len(tokens) != _FIELDS:
            source.fail(lineno, f'malformed scan line ({len(tokens)} fields, need {_FIELDS})')
            continue
        try:
            stamp_us = int(tokens[0])
            left, right = int(tokens[2]), int(tokens[3])
            mm = np.array(tokens[_FIRST_RANGE:_FIRST_RANGE + BREEZY_BEAMS], dtype=np.int64)
        except ValueError as err:
            source.fail(lineno, f'malformed scan line ({err})')
            continue
        if np.any(mm < 0):
            source.fail(lineno, 'malformed scan line (negative range)')
            continue
        code = mm < URG_04LX.dmin_mm
        ranges = np.where(code, _CODES[np.minimum(mm, URG_04LX.dmin_mm - 1)], mm / 1000.0)
        stamp = stamp_us * 1e-6
        readings.append(np.where(code, math.nan, mm / 1000.0))  # URG codes: no readings
        scans.append(ScanRecord(stamp, lineno, angle_min, inc, ranges))
        stamps.append(stamp)
        ticks.append((left, right))
    if not scans:
        raise ValueError(f'{path}: no scan lines (not a BreezySLAM .dat log?)')
    sensor = Sensor(model='Hokuyo URG-04LX', range_min=URG_04LX.dmin_mm / 1000.0,
                    range_max=URG_04LX.dmax_mm / 1000.0, sigma_range=URG_SIGMA_RANGE,
                    time_increment=60.0 / URG_04LX.scan_rpm / URG_04LX.ares)
    parts, marks = mark_scans(readings, [sc.ranges for sc in scans])
    scans = [replace(sc, ranges=r) for sc, r in zip(scans, parts)]
    log = ParsedLog('breezyslam', path, sensor, (RoverGeometry.laser_x, 0.0, 0.0), scans=scans,
                    sentinels=marks)
    ticks = np.array(ticks, dtype=float)
    log.odom_stamps = np.array(stamps)
    log.odom_lineno = np.array([s.lineno for s in scans], dtype=int)
    log.odom_poses = ticks_to_odometry(ticks[:, 0], ticks[:, 1])
    log.skipped, log.first_skipped = source.skipped, source.first_skipped
    return log
