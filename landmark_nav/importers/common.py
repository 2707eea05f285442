"""Records shared by the log parsers: scans, odometry, parse errors, range codes.

The parsers (``carmen``, ``wean``, ``breezyslam``) turn a text log into a
:class:`ParsedLog` holding plain numpy arrays in SI units (m, rad, s); the writer turns that
into a bag. Nothing here knows about ROS.
"""

from collections import Counter
from dataclasses import dataclass, field
import gzip
import io
import math
from pathlib import Path
from typing import Iterator, List, Optional, TextIO, Tuple

import numpy as np

__all__ = ['LMS_CM_BAND_M', 'LMS_CM_CODES', 'LineError', 'LineSource', 'ParsedLog',
           'ScanRecord', 'Sensor',
           'lms_cm_ranges', 'open_text']


class LineError(ValueError):
    """A malformed log line; the message starts with ``file:line:``."""

    def __init__(self, path, lineno: int, message: str) -> None:
        """Build ``'<path>:<lineno>: <message>'``."""
        super().__init__(f'{path}:{lineno}: {message}')
        self.path = str(path)
        self.lineno = lineno


def open_text(path) -> TextIO:
    """Open a log as text, gunzipping ``*.gz``.

    Raises:
        OSError: The file is missing or not gzip although named ``.gz``.

    """
    path = Path(path)
    if path.suffix == '.gz':
        return io.TextIOWrapper(gzip.open(path, 'rb'), encoding='ascii', errors='replace')
    return open(path, 'rt', encoding='ascii', errors='replace')


class LineSource:
    """Iterate over the lines of a log, counting what is skipped (``--lenient``).

    ``fail(lineno, message)`` raises :class:`LineError` naming the file and line, or, when
    lenient, counts the line as skipped and returns so the parser can go on.
    """

    def __init__(self, path, lenient: bool = False) -> None:
        """Remember the file and the policy for malformed lines."""
        self.path = Path(path)
        self.lenient = lenient
        self.skipped = 0
        self.first_skipped: Optional[str] = None

    def lines(self) -> Iterator[Tuple[int, List[str]]]:
        """Yield ``(line number, tokens)`` for each non-empty, non-comment line."""
        with open_text(self.path) as f:
            try:
                for lineno, line in enumerate(f, 1):
                    tokens = line.split()
                    if tokens and not tokens[0].startswith('#'):
                        yield lineno, tokens
            except (EOFError, gzip.BadGzipFile, OSError) as err:
                raise OSError(f'{self.path}: unreadable ({err})') from err

    def fail(self, lineno: int, message: str) -> None:
        """Raise a :class:`LineError`, or count the line as skipped when lenient."""
        if not self.lenient:
            raise LineError(self.path, lineno, message)
        self.skipped += 1
        if self.first_skipped is None:
            self.first_skipped = f'{self.path}:{lineno}: {message}'


@dataclass(frozen=True)
class Sensor:
    """What the log says (or its format implies) about the laser.

    ``sigma_range`` is the sensor's stated 1-sigma range noise [m] (see the format modules
    for the datasheet figure); ``time_increment`` is the time between beams [s] when known,
    else 0.
    """

    model: str
    range_min: float
    range_max: float
    sigma_range: float
    time_increment: float = 0.0


@dataclass(frozen=True, eq=False)
class ScanRecord:
    """One laser scan as read: REP 117 ranges [m] and the beam geometry."""

    stamp: float  # [s] as printed in the log (repaired later)
    lineno: int
    angle_min: float
    angle_increment: float
    ranges: np.ndarray  # (n,) float64, REP 117: +inf no return, -inf too close, NaN error
    key: str = ''  # the range tokens as printed (pairs raw and corrected Carmen scans)


@dataclass(eq=False)
class ParsedLog:
    """A parsed log: scans, odometry and reference poses, plus facts for custom_data.

    ``odom_*`` hold the robot's raw odometry (base_link in the odom frame) when the log has
    one; ``reference_*`` the corrected robot pose (base_link in the map frame) per scan when
    the log has one (``reference_index[i]`` is the scan it belongs to). ``odom_lineno`` are
    the log lines of the odometry records (the log order of all streams, for clock resets).
    """

    fmt: str
    path: Path
    sensor: Sensor
    mount: Tuple[float, float, float]  # base_link -> laser (x, y, yaw)
    scans: List[ScanRecord] = field(default_factory=list)
    odom_stamps: np.ndarray = field(default_factory=lambda: np.zeros(0))
    odom_poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    odom_lineno: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    reference_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    reference_poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    rear_scans: List[ScanRecord] = field(default_factory=list)
    rear_mount: Optional[Tuple[float, float, float]] = None
    skipped: int = 0
    first_skipped: Optional[str] = None
    ignored: Counter = field(default_factory=Counter)  # line types not imported
    notes: List[str] = field(default_factory=list)
    sentinels: list = field(default_factory=list)  # sentinels.Sentinel, per value
    cap: Optional[object] = None  # sentinels.CapJudgement of the log's stated range cap

    @property
    def scan_stamps(self) -> np.ndarray:
        """Return the scan stamps as read [s]."""
        return np.array([s.stamp for s in self.scans], dtype=float)

    @property
    def has_odometry(self) -> bool:
        """Return whether the log has raw odometry."""
        return len(self.odom_stamps) > 0

    @property
    def has_reference(self) -> bool:
        """Return whether the log has a reference (corrected) trajectory."""
        return len(self.reference_index) > 0


# SICK LMS2xx in cm mode (8 m / 80 m range, 1 cm steps; the Carmen and Wean logs): the top
# of the 13-bit distance word is reserved (see landmark_nav/drivers/lms2xx.py). 8183 cm =
# "measured value above the maximum" -> +inf; 8191 cm (all ones) is what the Carmen and
# CMU loggers write for beams without an echo (e.g. the 81.91 m of the Radish logs), also
# +inf; the others (dazzle, overflow, S/N too low, read error, ...) are errors -> NaN.
# A reading of 0 is the LMS's "no distance" value (an object too close to measure,
# docs/protocols/lms2xx.md): -inf, as the live driver publishes it (drivers/laser_session.py);
# the loggers print it as 0 / 0.00. Negative readings cannot come from the sensor: NaN.
LMS_CM_CODES = {8183: math.inf, 8191: math.inf}
_LMS_CM_BAND = (8183, 8191)
LMS_CM_BAND_M = (81.83, 81.91)  # [m] the same band in metres (sentinels.mark_sentinels)


def lms_cm_ranges(values_cm: np.ndarray, range_max: float) -> np.ndarray:
    """Map LMS cm-mode readings [cm] to REP 117 ranges [m].

    Codes of the reserved band 8183..8191 cm map per :data:`LMS_CM_CODES` (+inf) or to NaN;
    any other reading at or above ``range_max`` [m] is the logger's "no return" (+inf);
    0 is the LMS's "too close" (-inf, REP 117); negative readings are errors (NaN).
    """
    cm = np.asarray(values_cm, dtype=float)
    code = np.rint(cm)
    out = cm / 100.0
    band = (np.abs(cm - code) < 0.25) & (code >= _LMS_CM_BAND[0]) & (code <= _LMS_CM_BAND[1])
    out = np.where(out >= range_max, math.inf, out)
    no_return = band & np.isin(code, list(LMS_CM_CODES))
    out = np.where(band, np.where(no_return, math.inf, math.nan), out)
    out = np.where(cm == 0.0, -math.inf, out)
    return np.where(cm < 0.0, math.nan, out)
