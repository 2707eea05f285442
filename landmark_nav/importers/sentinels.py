"""No-return sentinels and the range cap of a laser log, found from its readings (pure numpy).

Real logs write "no return" as a number: the sensor's code (SICK LMS: the top of the distance
word, e.g. 81.91 m in cm mode, 32.767 m in a mm mode) or whatever the logger chose (50.0,
51.05 m). Such a value shows in the log's readings as a **spike**: one value repeated far more
often than the values around it, at the top of the range. And a log's header may state a cap
(Carmen ``PARAM robot_front_laser_max``) that its readings do not respect (a 10 m cap in a
log with 29 % of its readings between 10 and 40 m). Both are judged here from the readings:

* :func:`range_resolution` -- the reading step (1 mm, 1 cm, ...) from the printed values;
* :func:`lms_code_band` -- the SICK LMS reserved band (sensor model) of a mm-resolution log;
* :func:`find_spikes` -- the data's sentinels (rule in its docstring);
* :func:`judge_cap` -- whether the readings overrule a stated cap, and the cap they imply.

Nothing here knows about ROS or the log formats.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

__all__ = ['CAP_OVERRULE_SHARE', 'CapJudgement', 'LMS_MASKS_MM', 'SPIKE_MIN_COUNT',
           'SPIKE_MAX_SHARE', 'SPIKE_MIN_SHARE', 'SPIKE_RATIO', 'SPIKE_TOP', 'SPIKE_WINDOW',
           'Sentinel', 'Spike',
           'find_spikes', 'judge_cap', 'lms_code_band', 'mark_scans', 'mark_sentinels',
           'range_resolution']

#: A spike is at least this many times the readings per step around it (and than each of
#: the two values one step away).
SPIKE_RATIO = 10.0
#: A spike holds at least this many readings and this share of the finite readings, and at
#: most the other share (a value holding most readings is the scene, e.g. a synthetic log).
SPIKE_MIN_COUNT = 20
SPIKE_MIN_SHARE = 1e-3
SPIKE_MAX_SHARE = 0.5
#: Half width of the window around a value whose readings per step are its background [m].
SPIKE_WINDOW = 0.5
#: "At the top of the range": a spike lies at or above this fraction of the largest reading,
#: and at most this share of the other readings lie above it.
SPIKE_TOP = 0.5
SPIKE_ABOVE_SHARE = 0.01
#: A stated cap is overruled when at least this share of the readings (sentinels and codes
#: left out) lie above it.
CAP_OVERRULE_SHARE = 0.01
#: SICK LMS distance words of 13..16 bits in mm units; the 9 values [mask - 8, mask] are
#: reserved codes (landmark_nav/drivers/lms2xx.py SPECIAL_VALUES).
LMS_MASKS_MM = (8191, 16383, 32767, 65535)
_LMS_BAND = 8
_STEPS = (0.001, 0.01, 0.1)  # [m] candidate reading steps, finest first


@dataclass(frozen=True)
class Spike:
    """A value repeated far more often than its neighbours: a no-return sentinel."""

    value: float  # [m]
    count: int
    background: float  # readings per reading step within the window around it


def _mm(values) -> np.ndarray:
    v = np.asarray(values, dtype=float).ravel()
    return np.rint(v[np.isfinite(v)] * 1000.0).astype(np.int64)


def range_resolution(values) -> float:
    """Return the reading step [m]: the coarsest of 1 mm, 1 cm, 10 cm holding every reading.

    Readings are taken as printed to the mm (finite ones only); 1 mm when there are none.
    """
    mm = _mm(values)
    step = _STEPS[0]
    for s in _STEPS[1:]:
        if mm.size and np.all(mm % int(round(s * 1000)) == 0):
            step = s
    return step


def lms_code_band(values) -> Optional[Tuple[float, float]]:
    """Return the SICK LMS reserved band [low, high] [m] of a mm-resolution log, or None.

    The mask is the smallest of :data:`LMS_MASKS_MM` not below the largest reading: its
    band holds the codes of that mode (e.g. 32.759 .. 32.767 m). None for logs whose
    readings are not at mm resolution (cm mode has its own codes, common.lms_cm_ranges) or
    beyond every mask.
    """
    mm = _mm(values)
    if not mm.size or range_resolution(values) != 0.001:
        return None
    top = int(mm.max())
    for mask in LMS_MASKS_MM:
        if top <= mask:
            return ((mask - _LMS_BAND) / 1000.0, mask / 1000.0)
    return None


def find_spikes(values, ratio: float = SPIKE_RATIO, min_count: int = SPIKE_MIN_COUNT,
                min_share: float = SPIKE_MIN_SHARE, window: float = SPIKE_WINDOW,
                top: float = SPIKE_TOP, above_share: float = SPIKE_ABOVE_SHARE
                ) -> List[Spike]:
    """Return the no-return sentinels among the finite positive readings [m], highest first.

    A value v (readings compared to the mm) is a sentinel when

    * it holds at least ``max(min_count, min_share * N)`` of the N readings and at most
      :data:`SPIKE_MAX_SHARE` of them;
    * it is at least ``ratio`` times its background, the readings per reading step
      (:func:`range_resolution`) within ``window`` of it (itself and the two values one step
      away left out), and it is alone or one of a pair of adjacent values that both pass
      (51.14 / 51.15 m); three or more adjacent values are a surface, not a sentinel;
    * it lies at the top of the range: at or above ``top`` times the largest reading, with
      at most ``above_share`` of the readings above it (values that pass the two tests
      above left out).
    """
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v) & (v > 0)]
    if not v.size:
        return []
    step = range_resolution(v)
    q = int(round(step * 1000))
    keys, counts = np.unique(_mm(v), return_counts=True)
    n = int(counts.sum())
    need = max(min_count, min_share * n)
    half = int(round(window * 1000))
    largest = keys[-1]
    cand = np.flatnonzero((counts >= need) & (counts <= SPIKE_MAX_SHARE * n)
                          & (keys >= top * largest))
    marked = []  # (key, count, background) of the values that pass the two tests
    for i in cand:
        k, c = keys[i], counts[i]
        near = (np.abs(keys - k) <= half) & (np.abs(keys - k) > q)
        density = float(counts[near].sum()) / max(2 * half / q, 1)
        if c >= ratio * max(density, 1.0):
            marked.append((int(k), int(c), density))
    marked.sort()
    keys_marked = [m[0] for m in marked]
    peaks = []
    for j, m in enumerate(marked):  # runs of adjacent values: at most two make a sentinel
        lo = j
        while lo > 0 and keys_marked[lo] - keys_marked[lo - 1] == q:
            lo -= 1
        hi = j
        while hi + 1 < len(marked) and keys_marked[hi + 1] - keys_marked[hi] == q:
            hi += 1
        if hi - lo < 2:
            peaks.append(m)
    out = []
    for k, c, b in peaks:
        above = counts[(keys > k) & ~np.isin(keys, keys_marked)].sum()
        if above <= above_share * n:
            out.append(Spike(k / 1000.0, int(c), b))
    return sorted(out, key=lambda s: -s.value)


@dataclass(frozen=True)
class CapJudgement:
    """What the readings say about a stated range cap."""

    stated: float  # [m]
    used: float  # [m] the cap the import applies
    above: int  # readings above the stated cap, sentinels and codes left out
    share: float  # of the finite positive readings
    overruled: bool
    stated_by: str = 'the stated cap'  # where the stated cap comes from

    def describe(self) -> str:
        """Return e.g. ``'PARAM robot_front_laser_max 10 m overruled by the data (...)'``."""
        text = (f'{self.stated_by} {self.stated:g} m, {self.above} readings '
                f'({100 * self.share:.1f} %) above it')
        if self.overruled:
            return f'{text}: overruled by the data, cap {self.used:g} m'
        return f'{text}: kept'


def judge_cap(values, stated: float, sentinels: Sequence[float] = (),
              codes: Optional[Tuple[float, float]] = None, mode: str = 'auto',
              model_max: float = math.inf, share: float = CAP_OVERRULE_SHARE
              ) -> CapJudgement:
    """Judge a stated cap [m] against the readings [m]; return the cap to apply.

    ``mode`` 'auto': the cap stands unless at least ``share`` of the readings (``sentinels``
    and readings inside ``codes`` left out) lie above it, then the readings set it;
    'header': the stated cap stands; 'data': the readings set it. The readings' cap is the
    lowest sentinel or code above the readings that overflow the stated cap, else
    ``model_max`` (the sensor's largest distance) when finite, else one reading step above
    the largest reading.

    Raises:
        ValueError: Unknown ``mode``.

    """
    if mode not in ('auto', 'header', 'data'):
        raise ValueError(f"range cap source must be 'auto', 'header' or 'data', got {mode!r}")
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v) & (v > 0)]
    mm = _mm(v)
    special = np.isin(mm, _mm(list(sentinels)))
    if codes is not None:
        special |= (mm >= round(codes[0] * 1000)) & (mm <= round(codes[1] * 1000))
    real = v[~special]
    over = real[real >= stated]
    frac = over.size / v.size if v.size else 0.0
    overruled = mode == 'data' or (mode == 'auto' and frac >= share)
    used = float(stated)
    if overruled:
        top = float(real.max()) if real.size else 0.0
        marks = [s for s in sentinels if s > top]
        if codes is not None and codes[0] > top:
            marks.append(codes[0])
        if marks:
            used = float(min(marks))
        elif math.isfinite(model_max) and model_max > top:
            used = float(model_max)
        else:
            used = top + range_resolution(v)
    return CapJudgement(float(stated), used, int(over.size), float(frac), bool(overruled))


@dataclass(frozen=True)
class Sentinel:
    """A reading value imported as "no return" or error, and how often it occurs."""

    value: float  # [m] as printed
    count: int  # readings of the imported scans with this value
    source: str  # 'LMS code' (sensor model) or 'data' (a spike, :func:`find_spikes`)
    code: float = math.inf  # what it becomes: +inf (no return) or NaN (error)


def mark_sentinels(values, ranges, spikes: Sequence[Spike] = (),
                   band: Optional[Tuple[float, float]] = None
                   ) -> Tuple[np.ndarray, List[Sentinel]]:
    """Map the sentinels of one log's readings; return (ranges, what was mapped).

    ``values`` are the readings as printed [m] and ``ranges`` what the format's own rules made
    of them (REP 117), same shape. Readings inside the LMS ``band`` (:func:`lms_code_band`,
    or 81.83 .. 81.91 m in cm mode) become +inf for the band's top and bottom values (no
    echo, above the maximum) and NaN for the others (errors), as the live driver maps them
    (drivers/lms2xx.py, common.lms_cm_ranges); readings equal to a spike outside the band
    become +inf where the format's rules left them finite. Each sentinel is listed with all
    its readings (also those the format's rules had mapped already); values no scan holds
    are not listed.
    """
    values = np.asarray(values, dtype=float)
    out = np.array(ranges, dtype=float, copy=True)
    mm = np.where(np.isfinite(values), np.rint(values * 1000.0), -1).astype(np.int64)
    marks = []
    lo = hi = None
    if band is not None:
        lo, hi = int(round(band[0] * 1000)), int(round(band[1] * 1000))
        for code in np.unique(mm[(mm >= lo) & (mm <= hi)]):
            at = mm == code
            value = math.inf if code in (lo, hi) else math.nan
            out[at] = value
            marks.append(Sentinel(code / 1000.0, int(np.count_nonzero(at)), 'LMS code', value))
    for spike in spikes:
        key = int(round(spike.value * 1000))
        if lo is not None and lo <= key <= hi:
            continue  # a code of the sensor model, listed above
        at = mm == key
        if at.any():
            out[at & np.isfinite(out)] = math.inf
            marks.append(Sentinel(spike.value, int(np.count_nonzero(at)), 'data'))
    return out, marks


def mark_scans(values: Sequence[np.ndarray], ranges: Sequence[np.ndarray],
               spikes: Optional[Sequence[Spike]] = None,
               band: Optional[Tuple[float, float]] = None
               ) -> Tuple[List[np.ndarray], List[Sentinel]]:
    """:func:`mark_sentinels` over a log's scans (readings and ranges per scan) at once.

    ``spikes`` default to :func:`find_spikes` of all the readings.
    """
    if not len(values):
        return [], []
    flat = np.concatenate([np.asarray(v, dtype=float).ravel() for v in values])
    if spikes is None:
        spikes = find_spikes(flat)
    out, marks = mark_sentinels(flat, np.concatenate(ranges), spikes, band)
    return np.split(out, np.cumsum([len(v) for v in values])[:-1]), marks
