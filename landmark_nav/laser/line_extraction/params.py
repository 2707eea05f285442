"""Parameters and methods of the line extractors (:mod:`landmark_nav.laser.lines`)."""

from dataclasses import dataclass
import math
from typing import Optional, Tuple

from landmark_nav.laser.range_noise import gate_sigma
import numpy as np


METHODS = ('split_merge', 'alfa')
CHI2_2DOF_95 = 5.991


@dataclass(frozen=True)
class LineParams:
    """Line extraction parameters (SI units, radians).

    Attributes:
        method: ``'split_merge'`` (default) or ``'alfa'``.
        split_threshold: Split-and-merge distance tolerance [m] (eq. 4); None means
            ``max(0.03, 4 * sigma_r)`` (rounded readings: their error's 4-sigma-tail bound,
            see :attr:`threshold`). The tolerance of a point at range r is this plus
            ``3 * sigma_phi * r`` (the bearing noise's lateral effect). Also bounds the
            merge, the growth and every line's RMSE (both methods).
        min_points: Fewest points of a line (ALFA's ``least_point_in_line``).
        min_length: Shortest line [m].
        merge_chi2: Chi-square gate (2 dof) of the collinearity test for merging.
        merge_gap: Largest gap between the facing ends of collinear lines of neighbouring
            clusters that are merged into one line [m].
        sigma_r: Range noise std sigma_d [m] (line chapter eqs. 2, 7).
        sigma_phi: Bearing noise std [rad] (eqs. 3, 7).
        lowess_span: ALFA: lowess window in points (odd).
        lowess_iterations: ALFA: robustness iterations (bisquare weights, eq. 9).
        rmse_min: ALFA: lowest floating RMSE threshold [m]; None means ``0.3 * sigma_r``.
        rmse_max: ALFA: highest (and initial) floating RMSE threshold [m]; None means
            ``sigma_r``. Both apply to the smoothed points.
        max_gradient: ALFA: largest RMSE growth per added point, relative to the current
            threshold (see :func:`alfa_pieces`).
        trim_sigma: Endpoint clean-up and growth gate in standard deviations of a point's
            distance to its line (eq. 7); ``inf`` disables both.
        merge_gap_angle: Lines of neighbouring clusters are also neighbours (for merging
            and growing) when their facing ends are at most this bearing apart [rad].
        see_through: Largest distance a valid beam inside a line's extent may lie beyond
            the line along its ray [m] (step 5); None means ``max(3 sigma_r, 0.05)``.
        join_occluded: Give the lines of one surface on both sides of an occluder one fit
            (step 5, :func:`_join_occluded`); their segments then share it. False: each
            side is fitted on its own beams (independent measurements, as a filter that
            maps each segment as a landmark with its extent needs).
        range_step: Range quantisation q of the readings [m] (0: not rounded), e.g. found
            by :func:`~landmark_nav.laser.range_noise.estimate_range_noise`; ``sigma_r``
            then includes the rounding (>= q / sqrt(12)). The gates use
            :attr:`gate_sigma_r`, the covariances ``sigma_r``.
        range_step_share: Share of the readings on the ``range_step`` grid.

    """

    method: str = 'split_merge'
    split_threshold: Optional[float] = None
    min_points: int = 8
    min_length: float = 0.3
    merge_chi2: float = CHI2_2DOF_95
    merge_gap: float = 0.3
    sigma_r: float = 0.01
    sigma_phi: float = math.radians(0.1)
    lowess_span: int = 7
    lowess_iterations: int = 2
    rmse_min: Optional[float] = None
    rmse_max: Optional[float] = None
    max_gradient: float = 0.1
    trim_sigma: float = 3.0
    merge_gap_angle: float = math.radians(5.0)
    see_through: Optional[float] = None
    join_occluded: bool = True
    range_step: float = 0.0
    range_step_share: float = 1.0

    def __post_init__(self) -> None:
        """Validate; raise ValueError naming the bad parameter."""
        def bad(name: str, rule: str) -> ValueError:
            return ValueError(f'LineParams.{name} must be {rule}, got {getattr(self, name)!r}')

        def number(v) -> bool:
            return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(
                v, bool) and not math.isnan(v)

        def positive(v, allow_none: bool = False) -> bool:
            if v is None:
                return allow_none
            return number(v) and math.isfinite(v) and v > 0

        def integer(v) -> bool:
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        if self.method not in METHODS:
            raise bad('method', 'one of ' + ', '.join(METHODS))
        if not positive(self.split_threshold, allow_none=True):
            raise bad('split_threshold', 'None or a number > 0')
        if not integer(self.min_points) or self.min_points < 3:
            raise bad('min_points', 'an integer >= 3')
        if not (number(self.min_length) and math.isfinite(self.min_length)
                and self.min_length >= 0):
            raise bad('min_length', 'a number >= 0')
        if not positive(self.merge_chi2):
            raise bad('merge_chi2', 'a number > 0')
        if not (number(self.merge_gap) and math.isfinite(self.merge_gap)
                and self.merge_gap >= 0):
            raise bad('merge_gap', 'a number >= 0')
        if not positive(self.sigma_r):
            raise bad('sigma_r', 'a number > 0')
        if not (number(self.sigma_phi) and math.isfinite(self.sigma_phi)
                and self.sigma_phi >= 0):
            raise bad('sigma_phi', 'a number >= 0')
        if not integer(self.lowess_span) or self.lowess_span < 3 or self.lowess_span % 2 == 0:
            raise bad('lowess_span', 'an odd integer >= 3')
        if not integer(self.lowess_iterations) or self.lowess_iterations < 0:
            raise bad('lowess_iterations', 'an integer >= 0')
        if not positive(self.rmse_min, allow_none=True):
            raise bad('rmse_min', 'None or a number > 0')
        if not positive(self.rmse_max, allow_none=True):
            raise bad('rmse_max', 'None or a number > 0')
        if self.rmse_bounds[0] > self.rmse_bounds[1]:
            raise bad('rmse_min', f'<= rmse_max ({self.rmse_bounds[1]})')
        if not positive(self.max_gradient):
            raise bad('max_gradient', 'a number > 0')
        if not (number(self.merge_gap_angle) and 0 <= self.merge_gap_angle <= math.pi):
            raise bad('merge_gap_angle', 'an angle in [0, pi]')
        if not positive(self.see_through, allow_none=True):
            raise bad('see_through', 'None or a number > 0')
        if not isinstance(self.join_occluded, (bool, np.bool_)):
            raise bad('join_occluded', 'a bool')
        if not (number(self.range_step) and math.isfinite(self.range_step)
                and self.range_step >= 0):
            raise bad('range_step', 'a number >= 0')
        if not (number(self.range_step_share) and 0 <= self.range_step_share <= 1):
            raise bad('range_step_share', 'a number in [0, 1]')
        if not (number(self.trim_sigma) and self.trim_sigma > 0):
            raise bad('trim_sigma', 'a number > 0 (inf disables the clean-up)')

    @property
    def gate_sigma_r(self) -> float:
        """Return the range noise std the gates use [m] (``sigma_r`` unless rounded).

        Rounded readings (``range_step``) have lighter tails than a Gaussian of std
        ``sigma_r``: the std whose 3-sigma gate has the rounded error's tail
        (:func:`~landmark_nav.laser.range_noise.gate_sigma`).
        """
        return gate_sigma(float(self.sigma_r), float(self.range_step),
                          float(self.range_step_share))

    @property
    def threshold(self) -> float:
        """Return the split tolerance at zero range [m].

        ``max(0.03, 4 sigma)``, the 4-sigma bound of a point's range error: for rounded
        readings the bound their error exceeds as rarely as a Gaussian's exceeds 4 standard
        deviations (:func:`~landmark_nav.laser.range_noise.gate_sigma` with k = 4; 4 times
        the 3-sigma gate std would be wider, the rounding's tail being bounded).
        """
        if self.split_threshold is not None:
            return float(self.split_threshold)
        return max(0.03, 4.0 * gate_sigma(float(self.sigma_r), float(self.range_step),
                                          float(self.range_step_share), k=4.0))

    @property
    def see_through_tolerance(self) -> float:
        """Return the see-through tolerance [m] (``see_through`` or its default)."""
        if self.see_through is not None:
            return float(self.see_through)
        return max(3.0 * self.gate_sigma_r, 0.05)

    @property
    def rmse_bounds(self) -> Tuple[float, float]:
        """Return (rmse_min, rmse_max) of the ALFA floating threshold [m]."""
        lo = 0.3 * self.sigma_r if self.rmse_min is None else float(self.rmse_min)
        hi = self.sigma_r if self.rmse_max is None else float(self.rmse_max)
        return lo, hi


#: The ``line_extractor`` node's parameters (also ``ekf_slam``'s ``lines.*``): field ->
#: (description, limits, choices[, parameter value standing for a field default of None]).
LINE_PARAMETERS = {
    'method': ('line extractor: split_merge or alfa', None, ['split_merge', 'alfa']),
    'split_threshold': ('split_merge: split distance tolerance [m] (eq. 4); 0 = automatic, '
                        'max(0.03, 4 sigma_r), on rounded ranges the 4-sigma tail of the rounded '
                        'error', (0.0, 10.0), None, 0.0),
    'min_points': ('fewest points of a line', (2, 10000), None),
    'min_length': ('shortest line [m]', (0.0, 100.0), None),
    'merge_chi2': ('chi-square gate (2 dof) of the collinearity test for merging',
                   (0.001, 1000.0), None),
    'merge_gap': ('largest gap between collinear lines of neighbouring clusters merged '
                  'into one [m]', (0.0, 100.0), None),
    'sigma_r': ('laser range noise std [m] (covariances, thresholds, segmentation)',
                (0.0001, 1.0), None),
    'sigma_phi': ('laser bearing noise std [rad] (covariances)', (0.0, 0.1), None),
    'lowess_span': ('alfa: lowess window [points] (odd)', (3, 1001), None),
    'lowess_iterations': ('alfa: lowess robustness iterations', (0, 20), None),
    'rmse_min': ('alfa: lowest floating RMSE threshold [m]; 0 = automatic, 0.3 sigma_r',
                 (0.0, 1.0), None, 0.0),
    'rmse_max': ('alfa: highest floating RMSE threshold [m]; 0 = automatic, sigma_r',
                 (0.0, 1.0), None, 0.0),
    'max_gradient': ('alfa: largest RMSE growth per added point, relative to the threshold',
                     (0.0001, 100.0), None),
    'see_through': ('a line never covers a beam more than this beyond it along the ray [m]; '
                    '0 = automatic, max(3 sigma_r, 0.05)', (0.0, 10.0), None, 0.0),
    'join_occluded': ('one fit for the lines of a surface on both sides of an occluder '
                      '(their segments share it)', None, None),
}
