"""Repair the time stamps of real logs (pure numpy).

Real logs carry these kinds of bad stamps, each repaired and counted:

* **wrapped** stamps: a negative stamp written as an unsigned 32-bit number (2**32 - 0.45
  for -0.45 s). A stamp of at least 2**31 s (a date after 2038) is read as one and
  unwrapped (minus 2**32); when it was printed too coarsely to resolve a second after
  unwrapping (a multiple of :data:`WRAP_COARSE` s, e.g. ``4.29497e+09``: +-5000 s) it is
  treated as missing;
* **zero** stamps (the logger had no clock yet) and **non-finite** ones (``nan``, ``inf``:
  the parsers accept what ``float`` reads): treated as missing;
* stamps going **backwards** (below the last good stamp ``t[last]``): the run of
  consecutive good stamps that stay below ``t[last]`` is a **glitch** when a later good stamp
  at or after ``t[last]`` ends it within :data:`GLITCH_MAX` stamps; its stamps are treated
  as missing. A run that lasts longer, or to the end of the stream (two runs concatenated,
  a clock reset), is a **clock reset**: the rest of the stream is shifted to continue one
  nominal period after ``t[last]``;
* **repeated** stamps (printed with too few digits, e.g. ``1.01893e+09``): a run of k equal
  stamps is spread evenly between its value and the next distinct stamp; a run with no later
  distinct stamp is spread at the nominal period.

Missing stamps are then interpolated linearly (by index) between their good neighbours and
extrapolated at the nominal period at the ends. **Negative** stamps left after that (a
clock counting from before the log's start; a bag stamp cannot be before 1970) are counted
and every stamp (every stream of the log, :func:`repair_streams`) is shifted by one offset
so that the first is one nominal period after 0. The nominal period is the median of the
positive steps between successive distinct good stamps, each divided by the number of
entries it spans; ``fallback_period`` when the stream has no two distinct stamps.
"""

from dataclasses import dataclass, replace
from typing import List, Sequence, Tuple

import numpy as np

__all__ = ['GLITCH_MAX', 'StampRepairs', 'WRAP_COARSE', 'clock_resets', 'repair_stamps',
           'repair_streams', 'unwrap_stamps']

#: Unsigned 32-bit wrap: stamps in [2**31, 2**33) s are read as t - 2**32.
_WRAP, _WRAP_FROM, _WRAP_TO = 2.0 ** 32, 2.0 ** 31, 2.0 ** 33
#: A wrapped stamp that is a multiple of this [s] was printed too coarsely to unwrap.
WRAP_COARSE = 1000.0

#: Longest run of backward stamps [entries] still treated as a glitch when the stream
#: comes back to (or past) the last good stamp after it; longer runs are clock resets.
GLITCH_MAX = 10


@dataclass(frozen=True)
class StampRepairs:
    """What :func:`repair_stamps` changed in one stream."""

    repeated: int = 0  # stamps moved off a run of equal stamps
    zero: int = 0
    nonfinite: int = 0  # nan / inf stamps, interpolated
    backward: int = 0  # isolated backward stamps, interpolated
    resets: int = 0  # lasting backward jumps, later stamps shifted
    period: float = 0.0  # nominal period used [s]
    period_fallback: bool = False  # no two distinct stamps: fallback_period used
    wrapped: int = 0  # unsigned 32-bit stamps unwrapped
    wrapped_coarse: int = 0  # of those, printed too coarsely: interpolated
    negative: int = 0  # stamps before 0 after the other repairs
    offset: float = 0.0  # [s] added to every stamp (negative stamps), 0 if none

    @property
    def total(self) -> int:
        """Return the number of stamps changed (resets count once each)."""
        return (self.repeated + self.zero + self.nonfinite + self.backward + self.resets
                + self.wrapped + self.negative)

    def describe(self) -> str:
        """Return e.g. ``'12 repeated stamps spread, 0 zero, 1 backward, 0 clock resets'``.

        Non-finite stamps are named only when there are any (``', 2 non-finite'``).
        """
        text = (f'{self.repeated} repeated stamps spread, {self.zero} zero, '
                f'{self.backward} backward, {self.resets} clock resets')
        if self.nonfinite:
            text += f', {self.nonfinite} non-finite'
        if self.wrapped:
            text += (f', {self.wrapped} unsigned 32-bit wrapped stamps unwrapped '
                     f'({self.wrapped_coarse} printed too coarsely: interpolated)')
        if self.negative:
            text += f', {self.negative} negative'
        if self.offset:
            text += f' (all stamps shifted by {self.offset:+.6g} s)'

        if self.period_fallback:
            text += f' (no distinct stamps: {self.period:g} s period assumed)'
        return text


def _nominal_period(t: np.ndarray, idx: np.ndarray) -> float:
    """Return the median step per index between distinct increasing stamps, 0 if none.

    ``t`` are the good stamps and ``idx`` their positions in the stream (missing stamps in
    between count as steps).
    """
    if len(t) < 2:
        return 0.0
    first = np.concatenate(([True], np.diff(t) != 0))
    t, idx = t[first], idx[first]
    steps, gaps = np.diff(t), np.diff(idx)
    ok = steps > 0
    if not ok.any():
        return 0.0
    return float(np.median(steps[ok] / gaps[ok]))


def _backward(t: np.ndarray, bad: np.ndarray, good_idx: np.ndarray,
              period: float) -> Tuple[int, List[Tuple[int, float]]]:
    """Mark backward glitches in ``bad`` and shift ``t`` at clock resets (both in place).

    Returns the number of glitch stamps and the resets as ``(position, shift [s])``.
    """
    n_back, resets = 0, []
    last = None
    for pos, i in enumerate(good_idx):
        if bad[i]:  # inside a glitch run found below
            continue
        if last is not None and t[i] < t[last]:
            ahead = good_idx[pos:pos + GLITCH_MAX + 1]
            back = np.flatnonzero(t[ahead] >= t[last])
            if len(back):  # the stream comes back within GLITCH_MAX stamps: a glitch
                run = ahead[:back[0]]
                bad[run] = True
                n_back += len(run)
                continue
            shift = t[last] - t[i] + period
            t[good_idx[pos:]] += shift
            resets.append((int(i), float(shift)))
        last = i
    return n_back, resets


def unwrap_stamps(stamps) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (stamps with unsigned 32-bit wraps undone, wrapped mask, too-coarse mask).

    A stamp in [2**31, 2**33) s is taken for an unsigned 32-bit wrap of a negative one and
    unwrapped (minus 2**32); one that is a multiple of :data:`WRAP_COARSE` was printed with
    too few digits to tell its value after unwrapping (the caller treats it as missing).
    """
    t = np.array(stamps, dtype=float).ravel()
    with np.errstate(invalid='ignore'):   # non-finite stamps: neither wrapped nor coarse
        wrapped = np.isfinite(t) & (t >= _WRAP_FROM) & (t < _WRAP_TO)
        coarse = wrapped & (np.fmod(t, WRAP_COARSE) == 0.0)
    t[wrapped] -= _WRAP
    return t, wrapped, coarse


def _repair(t: np.ndarray, coarse: np.ndarray, n_wrapped: int,
            fallback_period: float) -> Tuple[np.ndarray, StampRepairs]:
    """Repair unwrapped stamps ``t`` (``coarse`` ones missing); no negative-stamp shift."""
    n = len(t)
    bad = ~np.isfinite(t) | (t == 0.0) | coarse
    n_zero = int(np.count_nonzero(t == 0.0))
    n_nonfinite = int(np.count_nonzero(~np.isfinite(t)))
    good_idx = np.flatnonzero(~bad)
    period = _nominal_period(t[good_idx], good_idx)
    fallback = period <= 0.0
    if fallback:
        period = float(fallback_period)

    # Backward stamps: short runs (glitches) become missing, lasting jumps shift the rest.
    n_back, resets = _backward(t, bad, good_idx, period)
    n_reset = len(resets)

    # Runs of equal stamps: spread between the run's value and the next distinct stamp.
    good_idx = np.flatnonzero(~bad)
    if not fallback:  # again, without the backward stamps
        period = _nominal_period(t[good_idx], good_idx) or period
    n_rep = 0
    if len(good_idx) > 1:
        g = t[good_idx]
        starts = np.flatnonzero(np.concatenate(([True], np.diff(g) != 0)))
        ends = np.concatenate((starts[1:], [len(g)]))
        for a, b in zip(starts, ends):
            k = b - a
            if k < 2:
                continue
            gap = good_idx[a:b] - good_idx[a]  # missing stamps in between count too
            step = (g[b] - g[a]) / (good_idx[b] - good_idx[a]) if b < len(g) else period
            t[good_idx[a:b]] = g[a] + step * gap
            n_rep += k - 1

    # Missing stamps: interpolate by index, extrapolate at the nominal period.
    if bad.any():
        good_idx = np.flatnonzero(~bad)
        idx = np.arange(n, dtype=float)
        if len(good_idx) == 0:
            t = period * (idx + 1.0)
        else:
            filled = np.interp(idx, good_idx, t[good_idx])
            lo, hi = good_idx[0], good_idx[-1]
            filled[:lo] = t[lo] - period * (lo - idx[:lo])
            filled[hi + 1:] = t[hi] + period * (idx[hi + 1:] - hi)
            t = filled
    repairs = StampRepairs(repeated=n_rep, zero=n_zero, nonfinite=n_nonfinite, backward=n_back,
                           resets=n_reset, period=period, period_fallback=bool(fallback and n > 1),
                           wrapped=n_wrapped, wrapped_coarse=int(np.count_nonzero(coarse)),
                           negative=int(np.count_nonzero(t < 0.0)))
    return t, repairs


def _first_at_one_period(streams: Sequence[np.ndarray], period: float) -> float:
    """Return the offset [s] that puts the earliest stamp at ``period``; 0 if none is < 0."""
    lows = [float(t.min()) for t in streams if len(t)]
    if not lows or min(lows) >= 0.0:
        return 0.0
    return period - min(lows)


def repair_stamps(stamps, fallback_period: float = 1.0) -> Tuple[np.ndarray, StampRepairs]:
    """Return (repaired stamps, what was repaired) for one stream of stamps [s].

    The result is non-decreasing, has no zeros, no negative stamps and no runs of equal
    values (unless the stream has fewer than two entries); good stamps keep their values up
    to clock-reset shifts and the one offset of negative stamps.

    Raises:
        ValueError: ``fallback_period`` is not positive.

    """
    if not fallback_period > 0:
        raise ValueError(f'fallback period must be > 0, got {fallback_period}')
    t, wrapped, coarse = unwrap_stamps(stamps)
    t, repairs = _repair(t, coarse, int(np.count_nonzero(wrapped)), fallback_period)
    offset = _first_at_one_period([t], repairs.period)
    if offset:
        t = t + offset
        repairs = replace(repairs, offset=offset)
    return t, repairs


def _merged(streams: Sequence, lines: Sequence) -> tuple:
    """Return the streams unwrapped, and their stamps merged in log order.

    Returns ``(unwrapped, order, t, n, bad)``: :func:`unwrap_stamps` of each stream, the
    permutation of the concatenated streams into log order, the merged stamps, their log
    lines and which are missing (zero, non-finite or too coarse to unwrap).

    Raises:
        ValueError: A stream and its line numbers differ in length.

    """
    unwrapped = [unwrap_stamps(t) for t in streams]
    lines = [np.asarray(n, dtype=float).ravel() for n in lines]
    for k, (u, n) in enumerate(zip(unwrapped, lines)):
        if len(u[0]) != len(n):
            raise ValueError(f'stream {k}: {len(u[0])} stamps but {len(n)} line numbers')
    if not unwrapped:
        return [], np.zeros(0, int), np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool)
    order = np.argsort(np.concatenate(lines), kind='stable')
    t = np.concatenate([u[0] for u in unwrapped])[order]
    bad = ~np.isfinite(t) | (t == 0.0) | np.concatenate([u[2] for u in unwrapped])[order]
    return unwrapped, order, t, np.concatenate(lines)[order], bad


def clock_resets(streams: Sequence, lines: Sequence) -> List[Tuple[int, float, float]]:
    """Return the clock resets of a log's streams (merged in log order) as they were read.

    The resets are those :func:`repair_streams` shifts the later stamps at (a lasting
    backward jump of the clock, not a glitch): one ``(line, before, after)`` each, the log
    line of the first stamp after the reset, the last good stamp before it and that stamp
    [s], unshifted.
    """
    _, _, t, n, bad = _merged(streams, lines)
    good_idx = np.flatnonzero(~bad)
    raw = t.copy()
    period = _nominal_period(t[good_idx], good_idx) or 1.0
    _, resets = _backward(t, bad, good_idx, period)
    out = []
    for i, _ in resets:
        before = good_idx[good_idx < i]
        out.append((int(n[i]), float(raw[before[-1]]) if before.size else float('nan'),
                    float(raw[i])))
    return out


def repair_streams(streams: Sequence, lines: Sequence,
                   fallback_period: float = 1.0) -> Tuple[List[np.ndarray], List[StampRepairs]]:
    """Repair several streams of one log with one clock: resets found on the merged stream.

    ``lines[k]`` are the log line numbers of the entries of ``streams[k]`` (the log order).
    The streams are merged in log order and clock resets are detected on the merged stream
    (as in :func:`repair_stamps`), so one reset shifts every stream by the same amount
    (stream by stream, each would get its own shift from its own last stamp and period).
    Each shifted stream is then repaired on its own (wrapped, repeated, zero, non-finite,
    backward stamps); its ``resets`` count the merged resets that fall inside it. Negative
    stamps left then shift every stream by one offset (the first stamp of the log one
    nominal period of the first stream after 0).

    Raises:
        ValueError: A stream and its line numbers differ in length, or
            ``fallback_period`` is not positive.

    """
    if not fallback_period > 0:
        raise ValueError(f'fallback period must be > 0, got {fallback_period}')
    unwrapped, order, t, _, bad = _merged(streams, lines)
    streams = [u[0] for u in unwrapped]
    good_idx = np.flatnonzero(~bad)
    period = _nominal_period(t[good_idx], good_idx) or float(fallback_period)
    _, resets = _backward(t, bad, good_idx, period)
    step = np.zeros(len(t))
    for pos, shift in resets:
        step[pos] += shift
    shift_sorted = np.cumsum(step)
    shift = np.empty_like(shift_sorted)
    shift[order] = shift_sorted
    out, reports = [], []
    start = 0
    for s, (_, wrapped, coarse) in zip(streams, unwrapped):
        sh = shift[start:start + len(s)]
        changes = int(np.count_nonzero(np.diff(sh) != 0))
        start += len(s)
        ok = np.isfinite(s) & (s != 0.0)  # zero and non-finite stamps stay missing
        fixed, rep = _repair(np.where(ok, s + sh, s), coarse, int(np.count_nonzero(wrapped)),
                             fallback_period)
        out.append(fixed)
        reports.append(replace(rep, resets=rep.resets + changes))
    offset = _first_at_one_period(out, reports[0].period if reports else 1.0)
    if offset:
        out = [t + offset for t in out]
        reports = [replace(r, offset=offset) for r in reports]
    return out, reports
