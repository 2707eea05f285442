"""The range noise of a laser, estimated from its own scans (pure numpy).

The line and corner extractors take the range noise ``sigma_r`` for their thresholds (line
chapter eqs. 2, 7). A laser's datasheet figure may not be what its log holds: loggers round
ranges (5 cm steps in some Radish logs), and at the default 1 cm such a scan breaks walls
into fragments. So ``sigma_r`` can be measured:

* **local fits**: every window of :data:`WINDOW` consecutive valid beams at most
  :data:`MAX_EXTENT` long is fitted with a line (total least squares); the residual of
  each point along its beam (perpendicular residual / cos incidence) estimates the range
  error. Windows on corners, edges and clutter fit badly, so the estimate is the median
  over windows of the mean squared residual, scaled to a variance: with k points and 2
  line parameters, s^2 = sum e^2 / (k - 2) follows sigma^2 chi^2_(k-2) / (k - 2), whose
  median is ``_MEDIAN_CHI2`` sigma^2;
* **quantisation**: the range step q found in the readings (:func:`range_step`); rounding to
  q adds a uniform error of variance q^2 / 12, so sigma_r >= q / sqrt(12) for the share of
  readings on that grid;
* **the stated figure** (the sensor's datasheet noise, when the caller gives it) is a lower
  bound too: the data can show a laser noisier than stated, and a few thousand windows on
  smooth walls cannot show it better (they give 0.4 .. 0.8 cm on LMS logs stated at 1 cm,
  where 1 cm extracts as many walls).

:func:`estimate_range_noise` does both for a set of scans (one scan, a sample of a log);
:class:`RangeNoiseTracker` keeps the windows of the latest scans for a node that estimates
as it goes. Both give the same figure for the same scans.

**Gates on quantised ranges.** The error of a rounded reading is the sensor's noise n ~
N(0, sigma_0^2) plus the rounding error u ~ U(-q/2, q/2): its variance is sigma_0^2 + q^2 / 12
(= sigma_r^2, what covariances use), but its tails are those of a bounded error smeared by
sigma_0, lighter than a Gaussian's of the same variance (5 cm steps on 1 cm noise: the
99.73 % bound is 4.6 cm, not 3 sigma_r = 5.2 cm). A k-sigma gate sized with sigma_r thus
lets points 3-5 cm off a wall (a corner's far side, clutter beside it) join its line.
:func:`gate_sigma` returns the std of the Gaussian whose k-sigma gate has the same tail
probability as the rounded error's, for the extractors' gates.
"""

from collections import deque
from dataclasses import dataclass
from functools import lru_cache
import math
from typing import Iterable, Optional, Tuple

import numpy as np

__all__ = ['MAX_EXTENT', 'MAX_INCIDENCE_DEG', 'RangeNoise', 'RangeNoiseTracker', 'STEPS', 'WINDOW',
           'estimate_range_noise', 'gate_sigma', 'range_step', 'window_variances']

#: Beams per local fit window.
WINDOW = 7
#: Longest window [m] (first to last point): surfaces are flat over a metre, and far
#: windows (1 deg steps at 20 m span 2.4 m) fit clutter and curvature, not noise.
MAX_EXTENT = 1.0
#: Windows whose beams meet the fitted line more obliquely than this are left out.
MAX_INCIDENCE_DEG = 70.0
#: Candidate range steps [m], finest first.
STEPS = (0.001, 0.005, 0.01, 0.02, 0.05, 0.1)
#: A step q is the readings' grid when at least this share lies on it and at least twice
#: the share a finer grid p would put on it by chance (p / q).
STEP_SHARE = 0.5
# median of chi^2 with WINDOW - 2 = 5 degrees of freedom, divided by 5
_MEDIAN_CHI2 = 4.35146 / 5.0


@dataclass(frozen=True)
class RangeNoise:
    """A range-noise estimate [m] and what it rests on."""

    sigma_r: float  # max(fit, floor, stated)
    fit: float  # from the local fits (NaN without windows)
    step: float  # range step q found in the readings [m]
    step_share: float  # share of the readings on that step's grid
    floor: float  # quantisation: sqrt(share q^2 / 12 + (1 - share) p^2 / 12)
    windows: int  # local fit windows used
    stated: float = 0.0  # the sensor's stated noise, a lower bound (0: none given)

    def describe(self) -> str:
        """Return e.g. ``'sigma_r 1.9 cm from the data (fits 1.8 cm over 5000 windows; ...)'``."""
        gates = gate_sigma(self.sigma_r, self.step, self.step_share)
        step = (f'range step {100 * self.step:g} cm on {100 * self.step_share:.0f} % of the '
                f'readings, floor {100 * self.floor:.2f} cm, line gates as for '
                f'{100 * gates:.2f} cm' if self.step else 'ranges not rounded to a step')
        stated = f'; stated {100 * self.stated:.2f} cm' if self.stated else ''
        return (f'sigma_r {100 * self.sigma_r:.2f} cm from the data (local fits '
                f'{100 * self.fit:.2f} cm over {self.windows} windows; {step}{stated})')


def range_step(ranges) -> Tuple[float, float, float]:
    """Return (step q [m], share of the readings on q's grid, the finer step p under it).

    Candidates :data:`STEPS`; finite positive readings compared to 0.1 mm. p is the coarsest
    candidate that holds all but 1 % of the readings (0: none does, the readings are not
    rounded to a step); q is the coarsest candidate holding at least :data:`STEP_SHARE` of
    the readings and at least twice the share p's grid would put on it by chance (p / q);
    (0, 1, 0) when there is none.
    """
    r = np.asarray(ranges, dtype=float).ravel()
    r = r[np.isfinite(r) & (r > 0)]
    if not r.size:
        return 0.0, 1.0, 0.0
    units = np.rint(r * 1e4).astype(np.int64)  # 0.1 mm

    def share(q: float) -> float:
        return float(np.mean(units % int(round(q * 1e4)) == 0))

    fine = 0.0
    for q in STEPS:
        if share(q) >= 0.99:
            fine = q
    best, best_share = fine, share(fine) if fine else 1.0
    for q in STEPS:
        if q <= fine:
            continue
        s = share(q)
        if s >= STEP_SHARE and s >= 2.0 * fine / q:
            best, best_share = q, s
    return best, best_share, fine


def window_variances(ranges, angles, valid=None, window: int = WINDOW,
                     max_incidence_deg: float = MAX_INCIDENCE_DEG,
                     max_extent: float = MAX_EXTENT) -> np.ndarray:
    """Return s^2 = sum e^2 / (k - 2) of each local fit window of one scan [m^2].

    Windows are ``window`` consecutive beams, all valid (``valid``, default finite ranges
    > 0); each is fitted by total least squares; e is the residual along the beam
    (perpendicular residual / cos incidence); windows with a beam beyond
    ``max_incidence_deg`` or longer than ``max_extent`` [m] are left out.
    """
    r = np.asarray(ranges, dtype=float).ravel()
    a = np.asarray(angles, dtype=float).ravel()
    ok = np.isfinite(r) & (r > 0)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool).ravel()
    k = int(window)
    if r.size < k:
        return np.zeros(0)
    start = np.flatnonzero(np.convolve(ok.astype(int), np.ones(k, int), 'valid') == k)
    if not start.size:
        return np.zeros(0)
    idx = start[:, None] + np.arange(k)[None, :]                          # (W, k)
    u = np.stack([np.cos(a[idx]), np.sin(a[idx])], axis=-1)              # beam directions
    p = r[idx, None] * u                                                  # (W, k, 2)
    c = p - p.mean(axis=1, keepdims=True)
    cov = np.einsum('wki,wkj->wij', c, c)
    _, vec = np.linalg.eigh(cov)
    n = vec[:, :, 0]                                                      # line normals
    perp = np.einsum('wki,wi->wk', c, n)
    cos_inc = np.abs(np.einsum('wki,wi->wk', u, n))
    steep = cos_inc.min(axis=1) < math.cos(math.radians(max_incidence_deg))
    steep |= np.hypot(*(p[:, -1] - p[:, 0]).T) > max_extent
    e = perp / np.maximum(cos_inc, 1e-9)
    s2 = np.sum(e ** 2, axis=1) / (k - 2)
    return s2[~steep]


def _estimate(s2: np.ndarray, ranges: np.ndarray, stated: Optional[float]) -> RangeNoise:
    q, share, fine = range_step(ranges)
    floor = math.sqrt(share * q ** 2 / 12.0 + (1.0 - share) * fine ** 2 / 12.0)
    fit = math.sqrt(float(np.median(s2)) / _MEDIAN_CHI2) if s2.size else math.nan
    stated = float(stated or 0.0)
    sigma = max(fit if math.isfinite(fit) else 0.0, floor, stated)
    return RangeNoise(sigma, fit, q, share, floor, int(s2.size), stated)


def estimate_range_noise(scans: Iterable[Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]],
                         stated: Optional[float] = None
                         ) -> RangeNoise:
    """Estimate the range noise from scans given as (ranges, angles, valid or None).

    sigma_r = max(fit, floor, stated): the local fits pooled over all scans (module
    docstring), the quantisation floor of the range step found in all their readings and
    the sensor's ``stated`` noise [m] (None: no such bound).
    """
    s2, rr = [], []
    for ranges, angles, valid in scans:
        s2.append(window_variances(ranges, angles, valid))
        rr.append(np.asarray(ranges, dtype=float).ravel())
    return _estimate(np.concatenate(s2) if s2 else np.zeros(0),
                     np.concatenate(rr) if rr else np.zeros(0), stated)


def _rounded_tail(t: float, sigma_0: float, half: float) -> float:
    """Return P(|n + u| > t), n ~ N(0, sigma_0^2), u ~ U(-half, half) (half > 0).

    P = (sigma_0 / half) [G((t - half) / sigma_0) - G((t + half) / sigma_0)] with
    G(x) = integral of the normal upper tail Q from x to inf = phi(x) - x Q(x).
    """
    if sigma_0 <= 0.0:
        return max(0.0, 1.0 - t / half)
    from scipy.special import ndtr  # on first use: scipy.special costs ~0.3 CPU-s to import

    def g(x: float) -> float:
        return math.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi) - x * float(ndtr(-x))
    return sigma_0 / half * (g((t - half) / sigma_0) - g((t + half) / sigma_0))


@lru_cache(maxsize=256)
def gate_sigma(sigma_r: float, step: float = 0.0, share: float = 1.0, k: float = 3.0
               ) -> float:
    """Return the std whose k-sigma gate holds the rounded range error's tail [m].

    The readings' error has variance ``sigma_r^2`` (>= the rounding's ``share * step^2 /
    12``); a share ``share`` of the readings is rounded to ``step`` [m] (error n + u, n ~
    N(0, sigma_0^2), u ~ U(-step/2, step/2), sigma_0^2 = sigma_r^2 - share step^2 / 12),
    the rest carries n alone. Returns t / k, t the bound the error exceeds with the
    probability a Gaussian exceeds k standard deviations (2 Q(k): 0.27 % for k = 3). Without
    rounding (``step`` 0) that is ``sigma_r``; with it, at most ``sigma_r``.
    """
    if step <= 0.0 or share <= 0.0 or sigma_r <= 0.0:
        return sigma_r
    from scipy.special import ndtr  # on first use: scipy.special costs ~0.3 CPU-s to import
    share = min(share, 1.0)
    sigma_0 = math.sqrt(max(sigma_r * sigma_r - share * step * step / 12.0, 0.0))
    target = 2.0 * float(ndtr(-k))
    half = 0.5 * step

    def tail(t: float) -> float:
        gauss = 2.0 * float(ndtr(-t / sigma_0)) if sigma_0 > 0.0 else 0.0
        return share * _rounded_tail(t, sigma_0, half) + (1.0 - share) * gauss

    lo, hi = 0.0, half + (k + 3.0) * sigma_0  # tail(hi) < target
    for _ in range(60):  # bisection: the tail falls with t
        mid = 0.5 * (lo + hi)
        if tail(mid) > target:
            lo = mid
        else:
            hi = mid
    return min(hi / k, sigma_r)


class RangeNoiseTracker:
    """Estimate the range noise as scans come, over the latest ``scans`` scans."""

    def __init__(self, scans: int = 50, stated: Optional[float] = None) -> None:
        """Keep the windows and readings of the latest ``scans`` scans (>= 1)."""
        if scans < 1:
            raise ValueError(f'scans must be >= 1, got {scans}')
        self.stated = stated
        self._s2: deque = deque(maxlen=scans)
        self._r: deque = deque(maxlen=scans)
        self._estimate: Optional[RangeNoise] = None

    def add(self, ranges, angles, valid=None) -> RangeNoise:
        """Add one scan; return the estimate over the scans kept."""
        self._s2.append(window_variances(ranges, angles, valid))
        self._r.append(np.asarray(ranges, dtype=float).ravel())
        self._estimate = _estimate(np.concatenate(self._s2), np.concatenate(self._r),
                                   self.stated)
        return self._estimate

    @property
    def estimate(self) -> Optional[RangeNoise]:
        """Return the latest estimate, None before the first scan."""
        return self._estimate
