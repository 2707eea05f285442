"""Laser corner detectors of the corner chapter (Namoshe et al., section 2.1).

Three detectors work on the clusters of :func:`~landmark_nav.laser.segmentation.segment_scan`
(a corner never spans a gap between clusters):

* ``'sliding_window'`` (section 2.1.1, the baseline): a window of ``W`` samples (odd, 11 by
  default) slides over each cluster; the vectors ``vi``, ``vj`` run from the midpoint to the
  two terminal points. A window fires when the angle between them (eq. 1) is at most
  ``max_angle_deg`` (120 deg) and the opposite distance ``c`` (terminal to terminal) is at
  least ``min_opposite_distance``; the inward checks (2nd/10th, 3rd/9th, 4th/8th sample
  for ``W = 11``; in general the pairs ``h - 1 .. max(2, h - 3)`` samples from the midpoint,
  ``h = W // 2``, which is the chapter's 2nd/14th .. 4th/12th for ``W = 15``) must satisfy the
  same two conditions. The corner is the midpoint sample, its covariance the point's ``Q_i``.
* ``'split_merge'`` (section 2.1.2): each cluster is split recursively at the point of largest
  distance to the chord (eq. 4) while that distance exceeds ``split_threshold``; adjacent
  pieces whose union still fits one line are merged again. Every piece is fitted by total
  least squares (eqs. 5-10) and a corner is the intersection of the lines of two adjacent
  pieces when both pieces are long enough and their angle is a plausible corner (the same
  ``[f_min, f_max]`` bounds on ``-cos`` as below, i.e. about 70-110 deg).
* ``'minus_cosine'`` (section 2.1.3, the default): for each window ``a = |vi|``, ``b = |vj|``,
  ``c`` = terminal-to-terminal distance and ``f = (c^2 - (a^2 + b^2)) / (2ab)`` (eq. 11, i.e.
  ``-cos`` of the angle at the midpoint). A window is a candidate if ``f_min <= f <= f_max``
  ([-0.3436, 0.3515], about 70-110 deg), and it survives the midpoint-shift check
  (Figs. 11-12) if ``f`` recomputed with the midpoint moved ``midpoint_shift`` samples
  forward AND backward (same terminal points) is still inside the bounds; a single outlier
  midpoint then lands on the straight wall and gives ``f`` close to 1 (a ghost).
  Optionally (``gate_sigmas``, ``fit_sigmas``, off by default) the bounds are tested with
  the uncertainty of ``f`` propagated from eq. 7 (a confidence test instead of the hard
  cut); on the Carmen logs this moved corners across the widened bounds instead of
  steadying them (README, "Real logs").

Design decisions where the chapter is silent (all documented on :class:`CornerParams`):

* Window length. ``sliding_window`` uses exactly ``W`` samples. ``minus_cosine`` widens the
  window so that each arm spans at least ``min_arm_length`` metres (default
  ``max(0.15 m, 10 sigma_r)``): ``h = max(W // 2, ceil(min_arm_length / (r * dphi)))``
  samples, capped at ``max_half_window``, with ``r`` the midpoint range and ``dphi`` the beam
  spacing; the chapter's fixed 5-sample arm spans 2 cm at 0.5 m (0.5 deg beams), where 1 cm
  of range noise makes any angle. Widened arms are clipped at the cluster ends (the
  chapter's ``W // 2`` samples per arm are still required) and must span at least half of
  ``min_arm_length``.
* Midpoint-shift tolerance. At a true vertex the shifted midpoint lies one sample along an
  arm, which changes ``f`` by up to ``step / min(a, b)`` (``step`` = mean sample spacing of
  the arms): 0.2 for a 5-sample arm, not negligible as Fig. 11 assumes. The shifted ``f``
  must lie in the bounds widened by that amount; an outlier midpoint still gives ``f``
  close to 1 and is rejected.
* Non-maximum suppression (both window methods). Consecutive firing windows of one cluster
  form a run; a gap of up to ``h`` samples (half window) between firing windows does not
  break the run. Without refinement each run gives ONE detection, its sharpest window
  (smallest angle, i.e. smallest ``f``): near a corner the angle at the midpoint is
  smallest when the midpoint is on the vertex and opens toward 180 deg along either arm.
  With refinement every local minimum of ``f`` over the firing windows (no neighbouring
  window sharper) is refined: two corners closer than a window (a door frame, a pilaster:
  0.2-0.5 m apart) share one run, and one detection per run kept one of them, which one
  changing from scan to scan (on the six Carmen logs this raised the share of corners
  re-detected in the next scan by 3-5 points); the refinement's checks reject the minima
  that are noise on a straight arm and merge those that refine to the same corner.
* Refinement (``minus_cosine`` with ``refine=True``). (1) Inside the detection window the
  vertex is re-located as the sample that splits the window into the two best TLS lines
  (smallest sum of squared residuals, from moment prefix sums); the sharpest window alone
  can be far off when the arms differ in length. (2) Significance: the two lines must
  explain the window better than one line by ``min_significance * sigma^2`` (sigma the
  point noise), else the "corner" is a bend of noise on a straight wall. (3) Each arm
  (starting ``corner_gap + 1`` samples from the vertex) is extended up to ``fit_length``
  metres and cut where two consecutive samples leave its line by more than
  ``4 sigma + 1 cm`` or before a sample seen through it (an opening: a sample that far off
  the line and beyond it along its ray by more than ``see_through`` plus 3 standard
  deviations of its distance along the ray); isolated samples off the
  line are dropped (outliers), as are samples closer to the other arm's line or within
  ``max(sigma, spacing / 2)`` of the intersection. The lines are refitted (eqs. 8-10, two
  rounds) and intersected. (4) The corner is kept if both arms are real surfaces
  (``real_arms``: enough samples, reach, RMS distance and inlier share, see
  :class:`CornerParams` and ``_arm_support``), the angle between the fitted arms is inside
  the ``f`` bounds and the intersection lies within the window's reach of the vertex
  sample. Refined corners closer than ``max(3 sigma_r, 5 cm)`` are merged (smaller ``f``
  kept). ``Corner.arms`` gives each arm's extent: no beam inside it lies more than
  ``see_through`` beyond it (no false surface); split-and-merge corners get the same
  checks and extents.
* Covariance. Point noise follows the line chapter's eq. 7,
  ``Q_i = sigma_phi^2 D_i^2 t t^T + sigma_r^2 n n^T`` (``n`` along the beam, ``t`` normal
  to it). It is propagated to first order through the TLS fit of each arm (analytic
  Jacobian of eqs. 8-9) and the intersection of the two lines; the two arms share no
  samples, so they are independent. Without refinement (sliding window, ``refine=False``)
  the covariance is ``Q_i`` of the corner sample; split and merge propagates like the
  refinement.

Output conventions (same as :meth:`landmark_nav.sim.World.corners`): ``bisector`` points from
the corner into free space (toward the sensor side); ``opening`` is the angle of the
free-space wedge between the two arms: about pi/2 for a room's concave corner (sensor inside
the wedge of the two walls) and about 3 pi / 2 for a box's convex corner (sensor outside it,
the solid angle being ``2 pi - opening``). The detectors measure the angle ``theta`` between
the arms (the triangle angle at the vertex); ``opening = theta`` when the sensor lies on the
side the arms open to and ``2 pi - theta`` otherwise.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

from landmark_nav.laser.segmentation import Cluster, segment_scan
import numpy as np
from scipy.ndimage import minimum_filter1d

METHODS = ('minus_cosine', 'sliding_window', 'split_merge')
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True, eq=False)
class Corner:
    """One detected corner, in the laser frame.

    Attributes:
        position: (2,) corner position [m] (the refined TLS intersection when refined, else
            the corner sample).
        bisector: direction [rad] of the bisector of the free-space wedge, pointing from the
            corner into free space (toward the sensor side).
        opening: angle of the free-space wedge between the two arms [rad], in (0, 2 pi):
            ``theta`` (about pi/2) for a concave corner seen from inside, ``2 pi - theta``
            (about 3 pi / 2) for a convex corner; ``theta`` is the angle between the arms.
        covariance: (2, 2) position covariance [m^2].
        index: beam index (into the scan) of the corner sample: the vertex of the best
            two-line split when refined, the window midpoint or the split point otherwise.
        f_theta: minus-cosine value of the detecting window (eq. 11); nan for the methods
            that do not compute it (sliding window, split and merge).
        arms: (2, 2, 2) the two arms as segments [arm][inner end, outer end][x, y] [m]:
            for refined and split-and-merge corners the extent of the samples supporting
            each arm's line (ends where the first and last sample's ray meets the line; no
            sample inside is seen through it), for unrefined corners the corner sample and
            the window's terminal samples.
    """

    position: np.ndarray
    bisector: float
    opening: float
    covariance: np.ndarray
    index: int
    f_theta: float
    arms: Optional[np.ndarray] = None


@dataclass(frozen=True)
class CornerParams:
    """Corner detector parameters (SI units; angles in degrees only where the name says so).

    Attributes:
        method: ``'minus_cosine'`` (default), ``'sliding_window'`` or ``'split_merge'``.
        window: window size ``W`` in samples (odd, >= 5; 11 in the chapter).
        f_min: lower bound of the minus-cosine ``f = -cos(theta)`` (eq. 11; -0.3436 ~ 70 deg).
        f_max: upper bound of ``f`` (0.3515 ~ 110.6 deg). Also the angle gate of split and
            merge and of the refined arms.
        midpoint_shift: samples the midpoint is moved (both ways) in the ghost check of
            ``minus_cosine`` (Figs. 11-12); 0 disables the check.
        max_angle_deg: largest corner angle of the sliding window (eq. 1; 120 deg).
        min_opposite_distance: ``c_min`` of the sliding window: smallest terminal-to-terminal
            distance [m].
        split_threshold: split-and-merge distance tolerance [m] (eq. 4); None means
            ``max(0.05, 4 * sigma_r)``.
        min_arm_points: fewest samples an arm (a split-and-merge piece, a refined arm) needs.
        min_arm_length: ``minus_cosine`` widens its window so each arm spans at least this
            many metres; split-and-merge pieces must be at least this long [m]. None means
            ``max(0.15, 10 * sigma_r)`` (see :attr:`arm_length`).
        fit_length: longest arm used by the refinement [m].
        corner_gap: samples next to the vertex left out of the arm fits (refinement, split
            and merge), besides the vertex sample itself.
        max_half_window: cap on the widened half window of ``minus_cosine`` [samples].
        sigma_r: range noise std [m] (eq. 7; also the segmentation noise in
            :func:`extract_corners`).
        sigma_phi: bearing noise std [rad] (eq. 7).
        refine: refine ``minus_cosine`` corners by intersecting TLS lines fitted to the arms.
        min_significance: the two arm lines must reduce the squared TLS residual of the
            detection window by at least this many ``sigma^2`` compared with one line
            (refinement only).
        real_arms: refined and split-and-merge corners need two real surfaces: each arm
            fit uses at least ``min_arm_points`` samples, reaches ``arm_length`` from the
            corner (half of it when the arm ends at its cluster's end: an occlusion or a
            jump), has an RMS distance of its samples of at most ``arm_rmse`` and uses at
            least ``min_arm_inliers`` of the samples between its innermost and outermost
            one. False keeps only the chapter's checks (``min_arm_points``).
        arm_rmse: largest RMS distance of an arm's samples to its line [m]; None means
            ``max(0.03, 3 sigma_r)`` (the line extractor's split tolerance).
        min_arm_inliers: smallest share of an arm's samples its fit uses (the rest are
            outliers farther than ``4 sigma + 1 cm``).
        see_through: an arm never covers a sample more than this beyond its line along
            the sample's ray [m]: the fit stops before an opening (a sample off the line
            and beyond by more than this plus 3 standard deviations along the ray, eq. 7),
            the arm's extent
            (``Corner.arms``) before its own noisy samples at grazing incidence. None means
            ``max(3 sigma_r, 0.05)``.
        gate_sigmas: ``minus_cosine`` candidate gate made statistical: a window is a
            candidate when its ``f`` (eq. 11) lies within ``gate_sigmas`` standard
            deviations of ``[f_min, f_max]`` (``f``'s deviation propagated from the three
            points' noise ``Q_i``, eq. 7; the midpoint-shift bounds widen as much). 0 (the
            default) is the chapter's hard cut. Measured on the six Carmen logs and not
            made the default (README, "Real logs").
        fit_sigmas: the same for the refined corner's angle: the fitted arms' ``f`` may lie
            ``fit_sigmas`` standard deviations (propagated through the TLS fits, eqs. 7-8)
            outside the bounds. 0 (the default) is the hard cut.
    """

    method: str = 'minus_cosine'
    window: int = 11
    f_min: float = -0.3436
    f_max: float = 0.3515
    midpoint_shift: int = 1
    max_angle_deg: float = 120.0
    min_opposite_distance: float = 0.02
    split_threshold: Optional[float] = None
    min_arm_points: int = 3
    min_arm_length: Optional[float] = None
    fit_length: float = 1.5
    corner_gap: int = 0
    max_half_window: int = 200
    sigma_r: float = 0.01
    sigma_phi: float = math.radians(0.1)
    refine: bool = True
    min_significance: float = 25.0
    real_arms: bool = True
    arm_rmse: Optional[float] = None
    min_arm_inliers: float = 0.8
    see_through: Optional[float] = None
    gate_sigmas: float = 0.0
    fit_sigmas: float = 0.0

    def __post_init__(self) -> None:
        """Validate the parameters; raise ValueError naming the bad one."""
        def bad(name: str, rule: str) -> ValueError:
            return ValueError(f'CornerParams.{name} must be {rule}, got {getattr(self, name)!r}')

        def is_int(v: object) -> bool:
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        def is_num(v: object) -> bool:
            return (isinstance(v, (int, float, np.integer, np.floating))
                    and not isinstance(v, bool) and math.isfinite(v))

        if self.method not in METHODS:
            raise bad('method', f'one of {METHODS}')
        if not is_int(self.window) or self.window < 5 or self.window % 2 == 0:
            raise bad('window', 'an odd integer >= 5')
        for name in ('f_min', 'f_max', 'max_angle_deg', 'min_opposite_distance',
                     'fit_length', 'sigma_r', 'sigma_phi', 'min_significance'):
            if not is_num(getattr(self, name)):
                raise bad(name, 'a finite number')
        if not -1.0 <= self.f_min < self.f_max <= 1.0:
            raise bad('f_min', f'< f_max ({self.f_max}) and both in [-1, 1]')
        if not 0.0 < self.max_angle_deg < 180.0:
            raise bad('max_angle_deg', 'in (0, 180)')
        if self.min_opposite_distance < 0.0:
            raise bad('min_opposite_distance', '>= 0')
        if self.split_threshold is not None and (not is_num(self.split_threshold)
                                                 or self.split_threshold <= 0.0):
            raise bad('split_threshold', 'None or a number > 0')
        half = self.window // 2 if is_int(self.window) else 0
        if not is_int(self.midpoint_shift) or not 0 <= self.midpoint_shift < half:
            raise bad('midpoint_shift', f'an integer in [0, window // 2 = {half})')
        if not is_int(self.corner_gap) or not 0 <= self.corner_gap < half - 1:
            raise bad('corner_gap', f'an integer in [0, window // 2 - 1 = {half - 1})')
        if not is_int(self.min_arm_points) or self.min_arm_points < 2:
            raise bad('min_arm_points', 'an integer >= 2')
        if self.min_arm_length is not None and (not is_num(self.min_arm_length)
                                                or self.min_arm_length < 0.0):
            raise bad('min_arm_length', 'None or a number >= 0')
        if not self.fit_length > 0.0:
            raise bad('fit_length', '> 0')
        if not is_int(self.max_half_window) or self.max_half_window < half:
            raise bad('max_half_window', f'an integer >= window // 2 = {half}')
        if not self.sigma_r > 0.0:
            raise bad('sigma_r', '> 0')
        if self.sigma_phi < 0.0:
            raise bad('sigma_phi', '>= 0')
        if self.min_significance < 0.0:
            raise bad('min_significance', '>= 0')
        if not isinstance(self.refine, (bool, np.bool_)):
            raise bad('refine', 'a bool')
        if not isinstance(self.real_arms, (bool, np.bool_)):
            raise bad('real_arms', 'a bool')
        for name in ('arm_rmse', 'see_through'):
            v = getattr(self, name)
            if v is not None and (not is_num(v) or v <= 0.0):
                raise bad(name, 'None or a number > 0')
        if not (is_num(self.min_arm_inliers) and 0.0 <= self.min_arm_inliers <= 1.0):
            raise bad('min_arm_inliers', 'a number in [0, 1]')
        for name in ('gate_sigmas', 'fit_sigmas'):
            v = getattr(self, name)
            if not is_num(v) or v < 0.0:
                raise bad(name, 'a finite number >= 0')

    @property
    def split_tolerance(self) -> float:
        """Return the split-and-merge tolerance in metres (``split_threshold`` or its default)."""
        if self.split_threshold is not None:
            return float(self.split_threshold)
        return max(0.05, 4.0 * self.sigma_r)

    @property
    def arm_tolerance(self) -> float:
        """Return the largest RMS distance of an arm's samples to its line [m]."""
        if self.arm_rmse is not None:
            return float(self.arm_rmse)
        return max(0.03, 3.0 * self.sigma_r)

    @property
    def see_through_tolerance(self) -> float:
        """Return how far beyond an arm a sample may lie along its ray [m]."""
        if self.see_through is not None:
            return float(self.see_through)
        return max(3.0 * self.sigma_r, 0.05)

    @property
    def arm_length(self) -> float:
        """Return the minimum arm length in metres (``min_arm_length`` or its default)."""
        if self.min_arm_length is not None:
            return float(self.min_arm_length)
        return max(0.15, 10.0 * self.sigma_r)


# ---------------------------------------------------------------------------- scan arrays
@dataclass(frozen=True, eq=False)
class _Stack:
    """All clusters concatenated (1-D arrays); per-sample cluster bounds keep windows inside."""

    x: np.ndarray       # (N,) point x [m]
    y: np.ndarray       # (N,) point y [m]
    r: np.ndarray       # (N,) ranges
    phi: np.ndarray     # (N,) beam angles
    beam: np.ndarray    # (N,) beam index in the scan
    start: np.ndarray   # (N,) first sample of the sample's cluster
    end: np.ndarray     # (N,) one past the last sample of its cluster
    dphi: np.ndarray    # (N,) beam spacing of its cluster [rad] (0 for one-sample clusters)


def _stack(clusters: Sequence[Cluster]) -> Optional[_Stack]:
    """Concatenate the non-empty clusters, or return None if there are none."""
    cl = [c for c in clusters if len(c.indices) > 0]
    if not cl:
        return None
    sizes = np.array([len(c.indices) for c in cl])
    ends = sizes.cumsum()
    starts = ends - sizes
    phi = np.concatenate([c.angles for c in cl]).astype(float, copy=False)
    dphi = np.abs(phi[ends - 1] - phi[starts]) / np.maximum(sizes - 1, 1)
    xy = np.concatenate([c.points for c in cl]).astype(float, copy=False).reshape(-1, 2)
    x, y = np.array(xy.T)  # contiguous copies
    r = np.concatenate([c.ranges for c in cl]).astype(float, copy=False)
    bad = ~(r > 0.0) | ~np.isfinite(x + y + r)
    if bad.any():  # not a return: nan makes every window and fit through it fail
        x[bad] = y[bad] = math.nan
    return _Stack(x=x, y=y, r=r,
                  phi=phi, beam=np.concatenate([c.indices for c in cl]).astype(np.int64),
                  start=np.repeat(starts, sizes), end=np.repeat(ends, sizes),
                  dphi=np.repeat(dphi, sizes))


def point_covariance(ranges: np.ndarray, angles: np.ndarray, sigma_r: float,
                     sigma_phi: float) -> np.ndarray:
    """Return the (..., 2, 2) covariance ``Q_i`` of scan points (line chapter, eq. 7)."""
    d = np.asarray(ranges, dtype=float)
    c, s = np.cos(angles), np.sin(angles)
    a = (sigma_phi * d) ** 2
    b = sigma_r ** 2
    q = np.empty(d.shape + (2, 2))
    q[..., 0, 0] = a * s * s + b * c * c  # eq. 7
    q[..., 1, 1] = a * c * c + b * s * s
    q[..., 0, 1] = q[..., 1, 0] = (b - a) * s * c
    return q


def _minus_cos(xl: np.ndarray, yl: np.ndarray, xm: np.ndarray, ym: np.ndarray,
               xh: np.ndarray, yh: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``f`` of eq. 11 for triangles (lo, mid, hi), ``a^2`` and ``b^2``.

    ``f`` is nan when an arm has zero length.
    """
    ax, ay = xl - xm, yl - ym
    bx, by = xh - xm, yh - ym
    cx, cy = xh - xl, yh - yl
    a2 = ax * ax + ay * ay
    b2 = bx * bx + by * by
    c2 = cx * cx + cy * cy
    return (c2 - (a2 + b2)) / (2.0 * np.sqrt(a2 * b2)), a2, b2  # eq. 11


def _runs_best(pos: np.ndarray, score: np.ndarray, gap: np.ndarray,
               start: np.ndarray) -> np.ndarray:
    """Return the positions (into ``pos``) of the smallest score of each run.

    ``pos`` are sorted sample indices of firing windows. A run breaks where the next firing
    window is more than ``gap`` samples further on or in another cluster (``start`` differs).
    """
    if pos.size < 2:
        return np.arange(pos.size)
    new = np.empty(pos.size, dtype=bool)
    new[0] = True
    new[1:] = (pos[1:] - pos[:-1] > gap[:-1]) | (start[1:] != start[:-1])
    run = new.cumsum()
    order = np.lexsort((score, run))
    first = np.empty(order.size, dtype=bool)
    first[0] = True
    ro = run[order]
    first[1:] = ro[1:] != ro[:-1]
    return np.sort(order[first])


def _local_minima(pos: np.ndarray, score: np.ndarray, size: int) -> np.ndarray:
    """Return the positions (into ``pos``) of the local minima of ``score``.

    ``pos`` are sorted sample indices (of ``size`` samples) of firing windows; a window is
    a local minimum when neither firing window next to it has a smaller score (equal ones
    are all kept; the refinement merges what coincides). Windows of different clusters
    are at least ``2 * (window // 2)`` samples apart, so they never compare.
    """
    dense = np.full(size, np.inf)
    dense[pos] = score
    return np.flatnonzero(minimum_filter1d(dense, 3, mode='nearest')[pos] >= score)


def _free_side(cx: np.ndarray, cy: np.ndarray, u1x: np.ndarray, u1y: np.ndarray,
               u2x: np.ndarray, u2y: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (bisector angle, opening, cos theta) of corners ``(cx, cy)`` (vectorised).

    ``u1``, ``u2`` are unit vectors from the corner along its arms. The sensor (laser
    origin) on the side the arms open to means a concave corner (opening ``theta``), else
    convex (opening ``2 pi - theta``); the bisector points into free space.
    """
    cos_t = np.clip(u1x * u2x + u1y * u2y, -1.0, 1.0)
    theta = np.arccos(cos_t)
    bx, by = u1x + u2x, u1y + u2y
    concave = cx * bx + cy * by <= 0.0
    sign = np.where(concave, 1.0, -1.0)
    return (np.arctan2(sign * by, sign * bx), np.where(concave, theta, _TWO_PI - theta),
            cos_t)


def _unit(vx: np.ndarray, vy: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    n = np.sqrt(vx * vx + vy * vy)
    return vx / n, vy / n


# ---------------------------------------------------------------------------- TLS lines
@dataclass(frozen=True, eq=False)
class _Lines:
    """TLS lines (any leading shape) from moment sums."""

    alpha: np.ndarray   # normal angle (eq. 8)
    rho: np.ndarray     # signed distance to the origin (eq. 9)
    xm: np.ndarray      # centroid (eq. 10)
    ym: np.ndarray
    n: np.ndarray       # number of points
    num: np.ndarray     # -2 Sxy (numerator of eq. 8)
    den: np.ndarray     # Syy - Sxx (denominator of eq. 8)
    c: np.ndarray       # cos(alpha)
    s: np.ndarray       # sin(alpha)

    def take(self, sel: np.ndarray) -> '_Lines':
        """Return the rows ``sel``."""
        return _Lines(*(getattr(self, f)[sel] for f in self.__dataclass_fields__))


def _lines(m: np.ndarray) -> _Lines:
    """Fit total-least-squares lines (eqs. 5-10) from moment sums ``m`` (6, ...).

    ``m`` holds ``[n, sum x, sum y, sum x^2, sum y^2, sum xy]``.
    """
    n = m[0]
    ns = np.maximum(n, 1.0)
    xm = m[1] / ns  # eq. 10
    ym = m[2] / ns
    sxx = m[3] - m[1] * xm
    syy = m[4] - m[2] * ym
    sxy = m[5] - m[1] * ym
    num = -2.0 * sxy
    den = syy - sxx
    alpha = 0.5 * np.arctan2(num, den)  # eq. 8
    c, s = np.cos(alpha), np.sin(alpha)
    return _Lines(alpha, xm * c + ym * s, xm, ym, n, num, den, c, s)  # eq. 9


def _weighted_moments(w: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Return moment sums (6, ...) of points ``x, y`` (..., M) with weights ``w``."""
    f = np.empty((6,) + x.shape)
    f[0] = w
    np.multiply(w, x, out=f[1])
    np.multiply(w, y, out=f[2])
    np.multiply(f[1], x, out=f[3])
    np.multiply(f[2], y, out=f[4])
    np.multiply(f[1], y, out=f[5])
    return f.sum(axis=-1)


def _smallest_scatter(m: np.ndarray) -> np.ndarray:
    """Return the TLS residual (smallest scatter eigenvalue) of moment sums ``m`` (6, ...)."""
    n = np.maximum(m[0], 1.0)
    sxx = m[3] - m[1] * m[1] / n
    syy = m[4] - m[2] * m[2] / n
    sxy = m[5] - m[1] * m[2] / n
    half = 0.5 * (sxx - syy)
    return 0.5 * (sxx + syy) - np.sqrt(half * half + sxy * sxy)


def _intersect(ln: _Lines) -> Tuple[np.ndarray, np.ndarray]:
    """Intersect line 0 and line 1 of each row (lines of shape (K, 2))."""
    c0, c1, s0, s1 = ln.c[:, 0], ln.c[:, 1], ln.s[:, 0], ln.s[:, 1]
    det = c0 * s1 - s0 * c1  # 0 for parallel lines: inf / nan fail every later check
    r0, r1 = ln.rho[:, 0], ln.rho[:, 1]
    return (s1 * r0 - s0 * r1) / det, (c0 * r1 - c1 * r0) / det


def _arm_directions(ln: _Lines, cx: np.ndarray, cy: np.ndarray
                    ) -> Tuple[np.ndarray, np.ndarray]:
    """Return unit directions (K, 2) of both lines, from the corner toward the centroid."""
    ux, uy = -ln.s, ln.c
    sign = np.where((ln.xm - cx[:, None]) * ux + (ln.ym - cy[:, None]) * uy < 0.0, -1.0, 1.0)
    return sign * ux, sign * uy


def _corner_covariance(x: np.ndarray, y: np.ndarray, w: np.ndarray, ln: _Lines,
                       cx: np.ndarray, cy: np.ndarray, sigma_r: float,
                       sigma_phi: float) -> np.ndarray:
    """First-order covariance (K, 2, 2) of the intersection ``(cx, cy)`` of two TLS lines.

    ``x``, ``y`` (K, 2, M) arm points with 0/1 weights ``w`` and the fitted lines ``ln``
    (K, 2). Each point moves the corner through its own line only: with ``A p = rho`` (rows
    ``[cos a_k, sin a_k]``), ``dp = A^-1[:, k] (d rho_k - t_k d a_k)``, ``t_k = n_k^perp . p``.
    A scan point is ``D_i (cos phi_i, sin phi_i)``, so its range and bearing directions come
    from ``x, y``.
    """
    q = ln.num * ln.num + ln.den * ln.den
    q = np.where(q > 0.0, q, np.inf)[..., None]
    dx = x - ln.xm[..., None]
    dy = y - ln.ym[..., None]
    num, den = ln.num[..., None], ln.den[..., None]
    # Analytic Jacobian of eq. 8 (centroid terms vanish because sum(dx) = sum(dy) = 0).
    da_dx = (num * dx - den * dy) / q
    da_dy = -(den * dx + num * dy) / q
    ca, sa = ln.c, ln.s
    lever = (ln.ym * ca - ln.xm * sa + sa * cx[:, None] - ca * cy[:, None])[..., None]
    ns = np.maximum(ln.n, 1.0)[..., None]
    gx = w * ((ca[..., None] / ns) + lever * da_dx)  # d(rho - t alpha) / dx_i, eq. 9
    gy = w * ((sa[..., None] / ns) + lever * da_dy)
    # g Q_i g^T with Q_i of eq. 7 = sigma_phi^2 D^2 (tangential)^2 + sigma_r^2 (radial)^2,
    # with D (cos phi, sin phi) = (x, y): D * tangential = gy x - gx y, radial = (gx x + gy y) / D
    tang = gy * x - gx * y
    rad = (gx * x + gy * y) / np.maximum(np.sqrt(x * x + y * y), 1e-12)
    var = ((sigma_phi * sigma_phi) * (tang * tang)
           + (sigma_r * sigma_r) * (rad * rad)).sum(axis=-1)  # (K, 2)
    det = ca[:, 0] * sa[:, 1] - sa[:, 0] * ca[:, 1]
    a0x, a0y = sa[:, 1] / det, -ca[:, 1] / det  # A^-1[:, 0]
    a1x, a1y = -sa[:, 0] / det, ca[:, 0] / det  # A^-1[:, 1]
    v0, v1 = var[:, 0], var[:, 1]
    cov = np.empty((ca.shape[0], 2, 2))
    cov[:, 0, 0] = v0 * a0x * a0x + v1 * a1x * a1x
    cov[:, 1, 1] = v0 * a0y * a0y + v1 * a1y * a1y
    cov[:, 0, 1] = cov[:, 1, 0] = v0 * a0x * a0y + v1 * a1x * a1y
    return cov


def _line_angle_variance(x: np.ndarray, y: np.ndarray, w: np.ndarray, ln: _Lines,
                         sigma_r: float, sigma_phi: float) -> np.ndarray:
    """Return (K, 2) first-order variances of the TLS lines' angles ``alpha`` (eq. 8).

    The analytic Jacobian of eq. 8 (as :func:`_corner_covariance`) with the point noise
    ``Q_i`` of eq. 7.
    """
    q = ln.num * ln.num + ln.den * ln.den
    q = np.where(q > 0.0, q, np.inf)[..., None]
    dx = x - ln.xm[..., None]
    dy = y - ln.ym[..., None]
    num, den = ln.num[..., None], ln.den[..., None]
    gx = w * (num * dx - den * dy) / q
    gy = -w * (den * dx + num * dy) / q
    tang = gy * x - gx * y
    rad = (gx * x + gy * y) / np.maximum(np.sqrt(x * x + y * y), 1e-12)
    return ((sigma_phi * sigma_phi) * (tang * tang)
            + (sigma_r * sigma_r) * (rad * rad)).sum(axis=-1)


def _window_f_sd(st: _Stack, lo: np.ndarray, mid: np.ndarray, hi: np.ndarray,
                 p: CornerParams) -> np.ndarray:
    """Return the first-order standard deviation of ``f`` (eq. 11) of windows (lo, mid, hi).

    ``theta = atan2(u x v, u . v)`` with ``u``, ``v`` from the midpoint to the terminal
    points; its gradient is ``-perp(u) / |u|^2`` for the first terminal point,
    ``perp(v) / |v|^2`` for the second and minus their sum for the midpoint, each point
    with its noise ``Q_i`` of eq. 7; ``df = sin(theta) d theta``.
    """
    ux, uy = st.x[lo] - st.x[mid], st.y[lo] - st.y[mid]
    vx, vy = st.x[hi] - st.x[mid], st.y[hi] - st.y[mid]
    u2, v2 = ux * ux + uy * uy, vx * vx + vy * vy
    ga = np.stack([uy / u2, -ux / u2], axis=-1)  # -perp(u) / |u|^2, perp(u) = (-uy, ux)
    gb = np.stack([-vy / v2, vx / v2], axis=-1)
    var = np.zeros(mid.size)
    for i, gr in ((lo, ga), (hi, gb), (mid, -(ga + gb))):
        q = point_covariance(st.r[i], st.phi[i], p.sigma_r, p.sigma_phi)
        var += np.einsum('ki,kij,kj->k', gr, q, gr)
    cos_t = (ux * vx + uy * vy) / np.sqrt(u2 * v2)
    return np.sqrt(np.fmax(1.0 - cos_t * cos_t, 0.0) * var)


def _gather_arms(st: _Stack, first: np.ndarray, count: np.ndarray, fallback: np.ndarray
                 ) -> Tuple[np.ndarray, np.ndarray]:
    """Return padded sample indices (K, 2, M) of two arms and their validity mask.

    Arm 0 runs backward from ``first[:, 0]``, arm 1 forward from ``first[:, 1]``, each
    ``count`` samples long and clipped to the cluster; padding points at ``fallback``.
    """
    big = max(int(count.max()), 1)
    k = np.arange(big)
    idx = first[:, :, None] + _STEP * k
    valid = ((k < count[:, :, None]) & (idx >= st.start[fallback][:, None, None])
             & (idx < st.end[fallback][:, None, None]))
    return np.where(valid, idx, fallback[:, None, None]), valid


_STEP = np.array([-1, 1])[None, :, None]


# ---------------------------------------------------------------------------- methods
def _sliding_window(st: _Stack, p: CornerParams) -> List[Corner]:
    """Sliding-window detector (section 2.1.1) with run-based non-maximum suppression."""
    h = p.window // 2
    m = np.arange(st.x.size)
    mid = np.flatnonzero((m - h >= st.start) & (m + h < st.end))
    if mid.size == 0:
        return []
    cos_max = math.cos(math.radians(p.max_angle_deg))
    cmin2 = p.min_opposite_distance ** 2
    xm, ym = st.x[mid], st.y[mid]
    fire = np.ones(mid.size, dtype=bool)
    cos0 = None
    # Outermost pair (1st / W-th) then the inward checks (2nd / (W-1)-th, ...).
    for d in [h] + list(range(h - 1, max(2, h - 3) - 1, -1)):
        ax, ay = st.x[mid - d] - xm, st.y[mid - d] - ym
        bx, by = st.x[mid + d] - xm, st.y[mid + d] - ym
        nn = np.sqrt((ax * ax + ay * ay) * (bx * bx + by * by))
        cos_t = (ax * bx + ay * by) / nn  # eq. 1, compared as cos
        cx, cy = bx - ax, by - ay
        fire &= (cos_t >= cos_max) & (cx * cx + cy * cy >= cmin2)
        if cos0 is None:
            cos0 = cos_t
    idx = np.flatnonzero(fire)
    if idx.size == 0:
        return []
    g = mid[idx]
    # NMS: one detection per run of firing windows, the sharpest (largest cos theta).
    g = g[_runs_best(g, -cos0[idx], np.full(g.size, h), st.start[g])]
    return _raw_corners(st, g, g - h, g + h, np.full(g.size, math.nan), p)


def _raw_corners(st: _Stack, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, f: np.ndarray,
                 p: CornerParams) -> List[Corner]:
    """Return corners at samples ``g`` with arms toward ``lo`` / ``hi``, covariance ``Q_i``."""
    cx, cy = st.x[g], st.y[g]
    u1x, u1y = _unit(st.x[lo] - cx, st.y[lo] - cy)
    u2x, u2y = _unit(st.x[hi] - cx, st.y[hi] - cy)
    bis, opening, _ = _free_side(cx, cy, u1x, u1y, u2x, u2y)
    cov = point_covariance(st.r[g], st.phi[g], p.sigma_r, p.sigma_phi)
    arms = np.empty((g.size, 2, 2, 2))  # from the corner sample to the terminal samples
    arms[:, :, 0, 0], arms[:, :, 0, 1] = cx[:, None], cy[:, None]
    arms[:, 0, 1, 0], arms[:, 0, 1, 1], arms[:, 1, 1, 0], arms[:, 1, 1, 1] = (
        st.x[lo], st.y[lo], st.x[hi], st.y[hi])
    return _make(cx, cy, bis, opening, cov, st.beam[g], f, arms)


def _minus_cosine(st: _Stack, p: CornerParams) -> List[Corner]:
    """Minus-cosine detector (section 2.1.3, Fig. 14) with midpoint-shift ghost check."""
    h0 = p.window // 2
    m = np.arange(st.x.size)
    spacing = np.fmax(st.r * st.dphi, 1e-9)  # fmax: a nan range gives the widest window
    h = np.minimum(np.maximum(np.ceil(p.arm_length / spacing), h0), p.max_half_window)
    h = h.astype(np.int64)
    lo = np.maximum(m - h, st.start)  # widened arms are clipped at the cluster ends,
    hi = np.minimum(m + h, st.end - 1)  # the chapter's W // 2 samples are required
    mid = np.flatnonzero((m - lo >= h0) & (hi - m >= h0))
    if mid.size == 0:
        return []
    lo, hi = lo[mid], hi[mid]
    x, y = st.x, st.y
    xl, yl, xm, ym, xh, yh = x[lo], y[lo], x[mid], y[mid], x[hi], y[hi]
    f, a2, b2 = _minus_cos(xl, yl, xm, ym, xh, yh)  # eq. 11
    widen = 0.0
    if p.gate_sigmas > 0.0:  # confidence test of eq. 11 with the points' noise (eq. 7)
        widen = p.gate_sigmas * _window_f_sd(st, lo, mid, hi, p)
    # Arms clipped by a cluster end or by max_half_window must still span half the length.
    cand = np.flatnonzero((f >= p.f_min - widen) & (f <= p.f_max + widen)
                          & (np.minimum(a2, b2) >= 0.25 * p.arm_length * p.arm_length))
    if cand.size == 0:
        return []
    mid, lo, hi, f = mid[cand], lo[cand], hi[cand], f[cand]
    if p.gate_sigmas > 0.0:
        widen = widen[cand]
    if p.midpoint_shift:
        xl, yl, xm, ym, xh, yh = xl[cand], yl[cand], xm[cand], ym[cand], xh[cand], yh[cand]
        a, b = np.sqrt(a2[cand]), np.sqrt(b2[cand])
        # A true vertex moved by ds along one arm changes f by at most ds / min(a, b); ds is
        # the shift times the mean sample step of the arms (not the shifted point's actual
        # displacement, which for an outlier midpoint is the outlier's offset).
        step = np.maximum(a / (mid - lo), b / (hi - mid))
        tol = p.midpoint_shift * step / np.minimum(a, b) + widen
        good = np.ones(mid.size, dtype=bool)
        for s in (p.midpoint_shift, -p.midpoint_shift):  # Figs. 11-12: shifted midpoint
            fs = _minus_cos(xl, yl, x[mid + s], y[mid + s], xh, yh)[0]
            good &= (fs >= p.f_min - tol) & (fs <= p.f_max + tol)
        sel = np.flatnonzero(good)
        if sel.size == 0:
            return []
        mid, lo, hi, f = mid[sel], lo[sel], hi[sel], f[sel]
        if p.gate_sigmas > 0.0:
            widen = widen[sel]
    if p.refine:
        # Every local minimum of f is refined (two corners in one run: a door frame, a
        # pilaster); the refinement decides, and merges refined corners that coincide.
        sel = _local_minima(mid, f, st.x.size)
        return _refine(st, mid[sel], lo[sel], hi[sel], f[sel], p)
    # NMS: one detection per run of candidate windows, the sharpest (smallest f).
    sel = _runs_best(mid, f, h[mid], st.start[mid])
    return _raw_corners(st, mid[sel], lo[sel], hi[sel], f[sel], p)


def _two_line_split(st: _Stack, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, gap: int,
                    min_pts: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the vertex sample of each window ``[lo, hi]``, its arm moment sums, success.

    For every split sample ``s`` of the window (each side keeping ``min_pts`` samples after
    ``gap`` samples next to ``s`` are left out) the TLS residuals of ``[lo, s - gap - 1]``
    and ``[s + gap + 1, hi]`` (smallest scatter eigenvalues, from moment prefix sums over
    the window) are added; the smallest sum wins. The sharpest window ``g`` is only a sample
    or two off on clean data but can be far off with noise when the arms differ in length;
    the best two-line split puts the vertex where the data bend.
    """
    width = int((hi - lo).max()) + 1
    j = np.arange(width)
    win = np.minimum(lo[:, None] + j, hi[:, None])  # (K, W) window samples, padded
    x, y = st.x[win], st.y[win]
    cm = np.zeros((6, g.size, width + 1))  # prefix sums of the moments over each window
    cm[0, :, 1:] = 1.0
    cm[1, :, 1:], cm[2, :, 1:] = x, y
    cm[3, :, 1:], cm[4, :, 1:], cm[5, :, 1:] = x * x, y * y, x * y
    np.cumsum(cm, axis=2, out=cm)
    nwin = (hi - lo + 1)[:, None]
    a_end = np.maximum(j - gap, 0)  # arm 0 = window samples [0, j - gap)
    b_beg = np.minimum(j + gap + 1, nwin)  # arm 1 = [j + gap + 1, nwin)
    ok = (a_end >= min_pts) & (nwin - b_beg >= min_pts)
    rows = np.arange(g.size)[:, None]
    both = np.empty((6, 2, g.size, width))
    both[:, 0] = cm[:, :, a_end]
    both[:, 1] = cm[:, rows, nwin] - cm[:, rows, b_beg]
    cost = _smallest_scatter(both)
    cost = np.where(ok, cost[0] + cost[1], np.inf)
    best = np.argmin(cost, axis=1)
    r1 = rows[:, 0]
    found = ok[r1, best]
    sums = both[:, :, r1, best].transpose(0, 2, 1)  # (6, K, 2)
    gain = _smallest_scatter(cm[:, r1, nwin[:, 0]]) - cost[r1, best]  # one line vs two
    return np.where(found, lo + best, g), sums, gain


def _fit_arms(st: _Stack, g: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              p: CornerParams) -> tuple:
    """Split each window ``[lo, hi]`` around ``g`` in two TLS lines and refit the arms.

    Returns ``(g, found, lines, cx, cy, x, y, r, valid, w)``: the split sample, whether the
    split is a significant bend, the refitted lines, their intersection, the arm samples
    (K, 2, M) with ranges, validity and the weights of the final fit. The checks on them
    are :func:`_refine`'s.
    """
    gap = p.corner_gap
    g, sums, gain = _two_line_split(st, g, lo, hi, gap, 2)
    sig = np.sqrt(p.sigma_r ** 2 + (p.sigma_phi * st.r[g]) ** 2)
    found = gain >= p.min_significance * sig * sig  # a bend, not a noisy straight line
    lines = _lines(sums)  # first fit: both arms inside the detection window
    cx, cy = _intersect(lines)
    # Extend the arms to fit_length and keep the samples that stay on the first line.
    spacing = np.maximum(st.r[g] * st.dphi[g], 1e-9)
    n_fit = np.minimum(np.ceil(p.fit_length / spacing), 4 * p.max_half_window)
    count = np.empty((g.size, 2), dtype=np.int64)
    count[:, 0] = np.maximum(n_fit, g - gap - lo)  # at least the window part of each arm
    count[:, 1] = np.maximum(n_fit, hi - g - gap)
    first = np.empty((g.size, 2), dtype=np.int64)
    first[:, 0], first[:, 1] = g - gap - 1, g + gap + 1
    idx, valid = _gather_arms(st, first, count, g)
    x, y = st.x[idx], st.y[idx]
    sig = sig[:, None, None]
    near = np.maximum(sig, 0.5 * spacing[:, None, None])
    two = np.zeros(x.shape, dtype=bool)
    r = np.hypot(x, y)
    for _ in range(2):
        c, s, rho = lines.c[..., None], lines.s[..., None], lines.rho[..., None]
        d = x * c + y * s - rho
        d_own = np.abs(d)
        d_other = np.abs(x * c[:, ::-1] + y * s[:, ::-1] - rho[:, ::-1])
        far = d_own > 4.0 * sig + 0.01
        np.logical_and(far[..., :-1], far[..., 1:], out=two[..., :-1])
        cut = np.logical_or.accumulate(two, axis=-1)  # the arm ends at two consecutive misses
        # ... and before an opening seen through it (no false surface): a sample off the
        # line (far) and beyond it along its ray by more than its noise allows
        cut |= np.logical_or.accumulate(far & _behind(d, r, valid, rho, p)[1], axis=-1)
        ux, uy = _arm_directions(lines, cx, cy)
        along = (x - cx[:, None, None]) * ux[..., None] + (y - cy[:, None, None]) * uy[..., None]
        w = (valid & ~cut & ~far & (d_own <= d_other) & (along > near)).astype(float)
        lines = _lines(_weighted_moments(w, x, y))  # eqs. 8-10 on the kept arm samples
        cx, cy = _intersect(lines)
    return g, found, lines, cx, cy, x, y, r, valid, w


def _refine(st: _Stack, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, fg: np.ndarray,
            p: CornerParams) -> List[Corner]:
    """Refine detections (window ``[lo, hi]`` around ``g``) by intersecting two TLS lines."""
    g, found, lines, cx, cy, x, y, r, valid, w = _fit_arms(st, g, lo, hi, p)
    ux, uy = _arm_directions(lines, cx, cy)
    bis, opening, cos_t = _free_side(cx, cy, ux[:, 0], uy[:, 0], ux[:, 1], uy[:, 1])
    f_fit = -cos_t  # eq. 11 for the fitted arms
    fit_widen = 0.0
    if p.fit_sigmas > 0.0:  # theta = alpha_0 - alpha_1 (+ const), df = sin(theta) d theta
        var_a = _line_angle_variance(x, y, w, lines, p.sigma_r, p.sigma_phi)
        fit_widen = p.fit_sigmas * np.sqrt((1.0 - cos_t * cos_t) * var_a.sum(axis=1))
    px, py = st.x[g], st.y[g]
    reach2 = np.minimum((st.x[lo] - px) ** 2 + (st.y[lo] - py) ** 2,
                        (st.x[hi] - px) ** 2 + (st.y[hi] - py) ** 2)
    shift2 = (cx - px) ** 2 + (cy - py) ** 2
    arms, real = _arm_support(x, y, r, valid, w, lines, p)
    good = (found & real & (f_fit >= p.f_min - fit_widen)
            & (f_fit <= p.f_max + fit_widen) & (shift2 <= reach2))  # nan fails every comparison
    sel = np.flatnonzero(good)
    if sel.size == 0:
        return []
    if sel.size > 1:
        sel = sel[_dedup(cx[sel], cy[sel], fg[sel], max(3.0 * p.sigma_r, 0.05))]
    if sel.size < g.size:
        x, y, w, lines, arms = x[sel], y[sel], w[sel], lines.take(sel), arms[sel]
        cx, cy, g, bis, opening, fg = cx[sel], cy[sel], g[sel], bis[sel], opening[sel], fg[sel]
    cov = _corner_covariance(x, y, w, lines, cx, cy, p.sigma_r, p.sigma_phi)
    return _make(cx, cy, bis, opening, cov, st.beam[g], fg, arms)


def _behind(d: np.ndarray, r: np.ndarray, valid: np.ndarray, rho: np.ndarray,
            p: CornerParams, openings: bool = True):
    """Return the valid samples (K, 2, M) seen through their arm's line, and the openings.

    ``d`` are the samples' signed distances to their arm's line ``x cos a + y sin a = rho``
    (``rho`` (K, 2, 1)), ``r`` their ranges. A sample is seen through when it lies more
    than ``see_through_tolerance`` beyond the line along its ray: ``r - t > tol`` with
    ``t = rho r / (d + rho)`` the range at which the ray meets the line; an opening when
    beyond by more than that plus 3 standard deviations of its distance along the ray
    (eq. 7: ``sigma_r^2 + (r sigma_phi tan(incidence))^2``), else it is the surface's own
    noise (at grazing incidence, or a rare large error). Without ``openings`` only the
    first mask is returned.
    """
    proj = d + rho  # r cos(incidence)
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        t = rho * r / proj
        beyond = r * d / proj  # r - t
        seen = valid & (t > 0.0) & (beyond > p.see_through_tolerance)
    if not openings:
        return seen
    opening = np.zeros_like(seen)
    if seen.any():  # few samples: the noise test only where needed
        idx = np.nonzero(seen)
        c2 = (proj[idx] / r[idx]) ** 2
        var = p.sigma_r ** 2 + (r[idx] * p.sigma_phi) ** 2 * (1.0 - c2) / c2
        opening[idx] = beyond[idx] > p.see_through_tolerance + 3.0 * np.sqrt(var)
    return seen, opening


def _arm_support(x: np.ndarray, y: np.ndarray, r: np.ndarray, valid: np.ndarray,
                 w: np.ndarray, ln: _Lines, p: CornerParams) -> Tuple[np.ndarray, np.ndarray]:
    """Return the arms' extents (K, 2, 2, 2) and whether both arms are real surfaces (K,).

    Samples run from the vertex outward; the arm fits use the samples ``w`` (cut before
    any opening off the line, see :func:`_behind`). Both arms are real surfaces when each
    fit uses at least ``min_arm_points`` samples, reaches ``arm_length`` from the corner
    (half of it when the arm ends at its cluster's end: an occlusion or a jump, as the
    window's own arms), fits them with an RMS distance of at most ``arm_tolerance``, and
    uses at least ``min_arm_inliers`` of the samples between its innermost and outermost
    used one (an arm of scattered points, e.g. furniture clutter, loses its outliers and
    fails). An arm's extent is its run of used samples with the most samples and no sample
    seen through the line (its own noise at grazing incidence) between them, from the
    innermost to the outermost, each end where that sample's ray meets the line.
    """
    size = x.shape[-1]
    used = w > 0.0
    n = used.sum(axis=-1)
    pick = np.empty(x.shape[:-1] + (3,), dtype=np.int64)  # inner, outer, last used sample
    first = used.argmax(axis=-1)
    last = size - 1 - used[..., ::-1].argmax(axis=-1)
    c, s, rho = ln.c[..., None], ln.s[..., None], ln.rho[..., None]
    d = x * c + y * s - rho
    seen = _behind(d, r, valid, rho, p, openings=False)
    if seen.any():
        run = np.cumsum(seen, axis=-1)  # samples seen through the line separate the runs
        good = used & ~seen
        # run sizes by (corner, arm, run number); the run of most samples wins
        arm = np.arange(good.size // size).reshape(good.shape[:-1])[..., None]  # (K, 2, 1)
        key = arm * (size + 1) + run
        counts = np.bincount(key[good], minlength=arm.size * (size + 1))
        best = counts.reshape(good.shape[:-1] + (size + 1,)).argmax(axis=-1)
        in_run = good & (run == best[..., None])
        pick[..., 0] = in_run.argmax(axis=-1)
        pick[..., 1] = size - 1 - in_run[..., ::-1].argmax(axis=-1)
    else:
        pick[..., 0], pick[..., 1] = first, last
    pick[..., 2] = last
    xi = np.take_along_axis(x, pick, axis=-1)
    yi = np.take_along_axis(y, pick, axis=-1)
    with np.errstate(divide='ignore', invalid='ignore'):
        t = rho / (xi * c + yi * s)  # the ray through the sample meets the line
    ends = np.stack([t * xi, t * yi], axis=-1)  # (K, arm, inner / outer / last used, xy)
    cx, cy = _intersect(ln)
    reach = np.hypot(ends[..., 2, 0] - cx[:, None], ends[..., 2, 1] - cy[:, None])
    real = n >= p.min_arm_points
    if p.real_arms:
        with np.errstate(divide='ignore', invalid='ignore'):
            rmse = np.sqrt(np.where(used, d * d, 0.0).sum(axis=-1) / n)
            inliers = n / (last - first + 1)
        # An arm that ends inside its cluster (its samples leave the line: clutter, another
        # surface) must reach arm_length; one cut by the cluster's end (an occlusion, a
        # jump) half of it, as the window's own arms.
        ends_inside = (valid & (np.arange(size) > last[..., None])).any(axis=-1)
        need = np.where(ends_inside, p.arm_length, 0.5 * p.arm_length)
        real &= (reach >= need) & (rmse <= p.arm_tolerance) & (inliers >= p.min_arm_inliers)
    return ends[..., :2, :], real.all(axis=-1)


def _dedup(x: np.ndarray, y: np.ndarray, score: np.ndarray, radius: float) -> np.ndarray:
    """Return the indices kept by greedy suppression of points near a better-scoring one."""
    dx = x[:, None] - x
    dy = y[:, None] - y
    d2 = dx * dx + dy * dy
    np.fill_diagonal(d2, np.inf)
    r2 = radius * radius
    if not d2.min() < r2:
        return np.arange(x.size)
    kept: List[int] = []
    for i in np.argsort(score, kind='stable').tolist():
        if all(d2[i, j] >= r2 for j in kept):
            kept.append(i)
    return np.sort(np.array(kept, dtype=np.int64))


def _split_indices(x: np.ndarray, y: np.ndarray, tol: float) -> List[int]:
    """Break indices (incl. both ends) of recursive splitting at the largest eq. 4 distance."""
    breaks = [0, x.size - 1]
    todo = [(0, x.size - 1)]
    while todo:
        i, j = todo.pop()
        if j - i < 2:
            continue
        xi, yi, xf, yf = x[i], y[i], x[j], y[j]
        a, b = yf - yi, xf - xi  # A x + B y + C = 0 through both ends
        norm = math.hypot(a, b)
        if norm == 0.0:
            continue
        d = np.abs(a * (x[i + 1:j] - xi) - b * (y[i + 1:j] - yi))  # eq. 4 (times norm)
        k = int(np.argmax(d))
        if d[k] > tol * norm:
            s = i + 1 + k
            breaks.append(s)
            todo.extend(((i, s), (s, j)))
    return sorted(breaks)


def _fits_one_line(x: np.ndarray, y: np.ndarray, tol: float) -> bool:
    """Return True if the TLS line (eqs. 8-10) of the points is within ``tol`` of all."""
    ln = _lines(_weighted_moments(np.ones(x.size), x, y))
    return bool(np.abs(x * ln.c + y * ln.s - ln.rho).max() <= tol)  # the terms of eq. 6


def _split_merge(clusters: Sequence[Cluster], st: _Stack, p: CornerParams) -> List[Corner]:
    """Split-and-merge detector (section 2.1.2): corners where adjacent TLS lines meet."""
    tol = p.split_tolerance
    gap = p.corner_gap
    pieces: List[Tuple[int, int, int, int, int]] = []  # arm 0, arm 1 (first, last), joint
    base = 0
    for c in clusters:
        npts = len(c.indices)
        if npts == 0:
            continue
        b0 = base
        base += npts
        if npts < 2 * p.min_arm_points + 1:
            continue
        x, y = st.x[b0:base], st.y[b0:base]
        br = _split_indices(x, y, tol)
        merged = [br[0]]  # merge: drop a break if its two pieces still fit one line
        for j in range(1, len(br) - 1):
            i, k = merged[-1], br[j + 1] + 1
            if not _fits_one_line(x[i:k], y[i:k], tol):
                merged.append(br[j])
        merged.append(br[-1])
        for j in range(1, len(merged) - 1):
            lo = b0 + merged[j - 1] + (gap + 1 if j > 1 else 0)
            hi = b0 + merged[j + 1] - (gap + 1 if j + 1 < len(merged) - 1 else 0)
            jt = b0 + merged[j]
            pieces.append((lo, jt - gap - 1, jt + gap + 1, hi, jt))
    if not pieces:
        return []
    pc = np.array(pieces)
    jt = pc[:, 4]
    first = pc[:, 1:3]  # arm samples nearest the joint
    count = np.maximum(np.stack([pc[:, 1] - pc[:, 0], pc[:, 3] - pc[:, 2]], axis=1) + 1, 0)
    idx, valid = _gather_arms(st, first, count, jt)
    x, y = st.x[idx], st.y[idx]
    w = valid.astype(float)
    lines = _lines(_weighted_moments(w, x, y))  # eqs. 8-10
    cx, cy = _intersect(lines)
    ux, uy = _arm_directions(lines, cx, cy)
    bis, opening, cos_t = _free_side(cx, cy, ux[:, 0], uy[:, 0], ux[:, 1], uy[:, 1])
    last = st.x.size - 1
    far, near = np.clip(pc[:, [0, 3]], 0, last), np.clip(first, 0, last)
    length = np.hypot(st.x[far] - st.x[near], st.y[far] - st.y[near])
    spacing = st.r[jt] * st.dphi[jt]
    off = np.hypot(cx - st.x[jt], cy - st.y[jt])
    arms, real = _arm_support(x, y, np.hypot(x, y), valid, w, lines, p)
    good = ((count.min(axis=1) >= p.min_arm_points) & (length.min(axis=1) >= p.arm_length)
            & real & (-cos_t >= p.f_min) & (-cos_t <= p.f_max)
            & (off <= np.maximum(2.0 * tol, 3.0 * spacing)))  # nan fails every comparison
    sel = np.flatnonzero(good)
    if sel.size == 0:
        return []
    cov = _corner_covariance(x[sel], y[sel], w[sel], lines.take(sel), cx[sel], cy[sel],
                             p.sigma_r, p.sigma_phi)
    return _make(cx[sel], cy[sel], bis[sel], opening[sel], cov, st.beam[jt[sel]],
                 np.full(sel.size, math.nan), arms[sel])


def _make(cx: np.ndarray, cy: np.ndarray, bis: np.ndarray, opening: np.ndarray,
          cov: np.ndarray, index: np.ndarray, f: np.ndarray, arms: np.ndarray
          ) -> List[Corner]:
    """Build Corner objects (read-only arrays); ``arms`` (K, 2, 2, 2) arm segments."""
    pos = np.empty((cx.size, 2))
    pos[:, 0], pos[:, 1] = cx, cy
    cov = np.array(cov, dtype=float)
    arms = np.array(arms, dtype=float)
    pos.setflags(write=False)
    cov.setflags(write=False)
    arms.setflags(write=False)
    return [Corner(position=p_, bisector=b_, opening=o_, covariance=c_, index=i_, f_theta=f_,
                   arms=a_)
            for p_, b_, o_, c_, i_, f_, a_ in zip(pos, bis.tolist(), opening.tolist(), cov,
                                                  index.tolist(), f.tolist(), arms)]


# ---------------------------------------------------------------------------- public API
def detect_corners(clusters: Sequence[Cluster], params: Optional[CornerParams] = None
                   ) -> List[Corner]:
    """Detect corners inside each cluster with the method of ``params``.

    Args:
        clusters: clusters of one scan (see :func:`segment_scan`); empty or short clusters
            simply give no corners, and samples that are not returns (range not finite or
            not positive) never take part in a corner.
        params: detector parameters (defaults: minus-cosine with refinement).

    Returns:
        Corners in scan order (by cluster, then beam), laser frame.

    """
    params = params or CornerParams()
    # Zero-length arms and parallel lines give nan / inf, which fail every bound check.
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        st = _stack(clusters)
        if st is None:
            return []
        if params.method == 'minus_cosine':
            out = _minus_cosine(st, params)
        elif params.method == 'sliding_window':
            out = _sliding_window(st, params)
        else:
            out = _split_merge(clusters, st, params)
    return sorted(out, key=lambda c: c.index) if len(out) > 1 else out


def extract_corners(ranges: np.ndarray, angles: np.ndarray, valid: Optional[np.ndarray],
                    angle_increment: float, params: Optional[CornerParams] = None,
                    incidence_deg: float = 10.0, min_points: int = 5) -> List[Corner]:
    """Segment one scan (:func:`segment_scan`, noise ``params.sigma_r``) and detect corners.

    Args:
        ranges: (N,) ranges [m].
        angles: (N,) beam angles [rad].
        valid: (N,) bool mask of real returns; None means finite and > 0.
        angle_increment: beam spacing [rad].
        params: detector parameters.
        incidence_deg: segmentation incidence angle [deg].
        min_points: smallest cluster kept by the segmentation.

    Returns:
        Corners in the laser frame.

    """
    params = params or CornerParams()
    ranges = np.asarray(ranges, dtype=float)
    if valid is None:
        with np.errstate(invalid='ignore'):
            valid = np.isfinite(ranges) & (ranges > 0.0)
    clusters = segment_scan(ranges, angles, valid, angle_increment, incidence_deg=incidence_deg,
                            sigma_r=params.sigma_r, min_points=min_points)
    return detect_corners(clusters, params)
