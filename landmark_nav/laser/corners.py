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
  steadying them (README.md at commit 67eb6cc, "Real logs").

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

Code: this module dispatches to the detectors (:func:`detect_corners`); their parts are
modules of :mod:`landmark_nav.laser.corner_detection` named after what they compute:
``windows`` (``sliding_window``, eq. 1; ``minus_cosine``, eq. 11), ``refine`` (the
refinement and the arm checks), ``split_merge`` (eq. 4), ``tls_lines`` (the TLS lines,
eqs. 5-10, and their noise from eq. 7), ``corner`` (:class:`Corner`), ``params``
(:class:`CornerParams`), ``scan_stack`` (the clusters of a scan back to back) and
``arm_ends`` (what the scan shows beyond each arm, ``Corner.arm_ends``).
"""

from dataclasses import replace
from typing import List, Optional, Sequence

from landmark_nav.laser.corner_detection.arm_ends import arm_ends
from landmark_nav.laser.corner_detection.corner import Corner
from landmark_nav.laser.corner_detection.params import CORNER_PARAMETERS, CornerParams, METHODS
from landmark_nav.laser.corner_detection.scan_stack import _stack
from landmark_nav.laser.corner_detection.split_merge import _split_merge
from landmark_nav.laser.corner_detection.tls_lines import point_covariance
from landmark_nav.laser.corner_detection.windows import _minus_cosine, _sliding_window
from landmark_nav.laser.segmentation import Cluster, segment_scan
import numpy as np

__all__ = ['Corner', 'CORNER_PARAMETERS', 'CornerParams', 'detect_corners', 'extract_corners',
           'METHODS', 'point_covariance']


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
        Corners in scan order (by cluster, then beam), laser frame; with
        ``params.arm_ends`` and clusters that carry their scan's arrays, with ``arm_ends``
        (:func:`~landmark_nav.laser.corner_detection.arm_ends.arm_ends`).

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
    out = sorted(out, key=lambda c: c.index) if len(out) > 1 else out
    ends = arm_ends(out, clusters) if params.arm_ends else None
    if ends is None:
        return out
    return [replace(c, arm_ends=e) for c, e in zip(out, ends)]


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
