"""Parameters and methods of the corner detectors (:mod:`landmark_nav.laser.corners`)."""

from dataclasses import dataclass
import math
from typing import Optional

import numpy as np


METHODS = ('minus_cosine', 'sliding_window', 'split_merge')


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
            made the default (README.md at commit 67eb6cc, "Real logs").
        fit_sigmas: the same for the refined corner's angle: the fitted arms' ``f`` may lie
            ``fit_sigmas`` standard deviations (propagated through the TLS fits, eqs. 7-8)
            outside the bounds. 0 (the default) is the hard cut.
        arm_ends: also tell what the scan shows beyond each arm's outer end
            (``Corner.arm_ends``; evaluation, not the label): off by default, it costs
            about a sixth of the detector's time.
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
    arm_ends: bool = False

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
        if not isinstance(self.arm_ends, (bool, np.bool_)):
            raise bad('arm_ends', 'a bool')
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


#: The ``corner_extractor`` node's parameters: field -> (description, limits, choices[,
#: parameter value standing for a field default of None]).
CORNER_PARAMETERS = {
    'method': ('corner detector: minus_cosine (the proposed method of the chapter), '
               'sliding_window or split_merge', None,
               ['minus_cosine', 'sliding_window', 'split_merge']),
    'window': ('sliding window size in beams (odd, the chapter uses 11)', (5, 101), None),
    'f_min': ('lower bound of the minus-cosine f(theta) (eq. 11), -0.3436 ~ 70 deg',
              (-1.0, 1.0), None),
    'f_max': ('upper bound of f(theta), 0.3515 ~ 110 deg; also the angle gate of '
              'split_merge and of refined arms', (-1.0, 1.0), None),
    'midpoint_shift': ('minus_cosine ghost check: beams the midpoint is shifted (Figs. '
                       '11-12); 0 disables it', (0, 10), None),
    'max_angle_deg': ('sliding_window: largest corner angle [deg] (eq. 1)', (1.0, 179.0),
                      None),
    'min_opposite_distance': ('sliding_window: smallest opposite distance c [m]',
                              (0.0, 10.0), None),
    'split_threshold': ('split_merge: split distance tolerance [m] (eq. 4); 0 = automatic, '
                        'max(0.05, 4 sigma_r)', (0.0, 10.0), None, 0.0),
    'min_arm_points': ('fewest beams on each arm of a corner', (2, 1000), None),
    'min_arm_length': ('shortest arm of a corner [m]; 0 = automatic, max(0.15, 10 sigma_r)',
                       (0.0, 10.0), None, 0.0),
    'fit_length': ('longest arm used to refine a corner by line fits [m]', (0.01, 10.0),
                   None),
    'corner_gap': ('beams next to the corner left out of the arm fits', (0, 50), None),
    'max_half_window': ('cap on the widened half window of minus_cosine [beams]', (2, 1000),
                        None),
    'sigma_r': ('laser range noise std [m] (covariances, thresholds, segmentation)',
                (0.0, 1.0), None),
    'sigma_phi': ('laser bearing noise std [rad] (covariances)', (0.0, 0.1), None),
    'refine': ('refine minus_cosine corners as the intersection of lines fitted to the arms',
               None, None),
    'real_arms': ('refined and split_merge corners need two real surfaces (arm reach, RMS, '
                  'inlier share); false keeps only min_arm_points', None, None),
    'arm_rmse': ("largest RMS distance of an arm's beams to its line [m]; 0 = automatic, "
                 'max(0.03, 3 sigma_r)', (0.0, 1.0), None, 0.0),
    'min_arm_inliers': ("smallest share of an arm's beams its line fit uses", (0.0, 1.0),
                        None),
    'see_through': ('an arm never covers a beam more than this beyond it along the ray [m]; '
                    '0 = automatic, max(3 sigma_r, 0.05)', (0.0, 10.0), None, 0.0),
}
