"""Line extraction from laser scan clusters: split-and-merge and ALFA.

Both methods work on the clusters of :func:`landmark_nav.laser.segmentation.segment_scan`
and return :class:`LineSegment` objects in the laser frame: ``x cos(alpha) + y sin(alpha)
= rho`` (corner chapter eq. 5) with ``rho >= 0`` and ``alpha`` wrapped to [-pi, pi).

* ``split_merge`` (corner chapter, section 2.1.2): recursive split of a cluster at the point
  of largest perpendicular distance to the chord joining its first and last points (eq. 4)
  while that distance exceeds the tolerance; total-least-squares fit of every piece in
  Hessian normal form (eqs. 5-10); adjacent collinear pieces merged.
* ``alfa`` (line chapter, Mavaei 2011, ALFA pseudo code): each cluster's ranges are smoothed
  over the bearing by robust lowess (tricube weights eq. 8, bisquare robustness weights
  eq. 9, see :mod:`landmark_nav.laser.lowess`); the end of each line is then found by
  binary search on the RMSE criterion (eq. 21) with a floating threshold and the
  RMSE-gradient test (:func:`alfa_pieces`). The smoothed points only place the
  breakpoints: the lines are fitted on the ORIGINAL points (the chapter smooths "to
  increase the algorithm efficiency" and says nothing about fitting the smoothed data;
  smoothing would round corners and correlate the noise the covariance assumes).

Shared steps after the breakpoints (both methods), all clusters of a scan in one
vectorised batch (fits from prefix sums of point moments):

1. Break refinement: a break between two adjacent pieces moves, within ``min_points``
   beams, to where the summed squared residuals of both fits are smallest (the farthest
   point from a chord, or the end of a binary search on smoothed data, is often a beam or
   two off the true corner).
2. Endpoint clean-up: leading and trailing points farther than ``trim_sigma`` standard
   deviations from their piece's line (eq. 7 projected on the line normal) are dropped,
   and a split point shared by two pieces stays with the one it fits better. Pieces with
   fewer than ``min_points`` points are dropped here: their (rho, alpha) are too uncertain
   for a linearised merge test, and their points become free for step 4.
3. Merge: two consecutive pieces are merged when they are neighbours (same cluster, or
   clusters whose facing ends are at most ``merge_gap`` or ``merge_gap_angle`` apart, e.g.
   a wall cut by a dropout or a spurious return) and their (rho, alpha) agree in a
   chi-square test, ``d^2 = dp^T (C1 + C2)^-1 dp <= merge_chi2`` with the covariances of
   the two independent fits, each scaled by its a-posteriori variance factor where its
   residuals reject the stated noise (``merge._variance_factor``: a SICK in cm mode or a
   rough wall scatters more than ``sigma_r``, and pieces of one wall would otherwise stay
   apart). Chains of passing pairs are refitted on
   the union of their points (points between them are not used) and kept only if every
   member also passes the test against the merged line and its end points are within
   the split tolerance of it.
4. Growth: each line takes the free points beside its ends (also of small clusters) that
   lie within ``trim_sigma`` standard deviations and the split tolerance of it, e.g. a
   corridor wall seen at grazing angles, whose points the segmentation isolates.
5. No false surfaces: a line never covers a valid beam whose return lies more than
   ``see_through`` (default ``max(3 sigma_r, 5 cm)``) beyond it along the ray, i.e. a beam
   the laser saw through it. The beams checked are all beams between a line's first and
   last supporting beam, also those of no cluster (dropped small clusters, read from the
   whole scan of :func:`~landmark_nav.laser.segmentation.segment_scan`). A line hiding an
   *opening* (a beam beyond it by more than ``see_through`` plus 3 standard deviations
   of its distance along the ray, eq. 7) is cut there and both sides are refitted, until
   no line hides one; thus merging across a cluster break and growth over neighbouring
   beams stand only over beams that are occluded from the front or missing. A line
   hiding only its own noise (a wall seen at grazing incidence, where bearing noise puts
   returns 5 cm or more beyond it) is cut likewise when that leaves two or more lines of
   ``min_points`` and ``min_length``; otherwise it keeps its fit on all its points, and
   its extent shrinks to its run of support between those beams with the most points.
   See ``see_through._cut_seen_through``. A line keeps its fit across an *occluder* (two or more
   neighbouring beams in front of it by more than the opening margin: a table leg, a
   person), but not its extent: it is reported as one segment per side of at least
   ``min_points`` points, each with the line's (rho, alpha), covariance and point count,
   since a segment along the occluder's rays would claim a surface where the laser saw
   something else (the PLE ray metric scores such beams with their full distance to the
   line). A lone beam in front (one return cannot tell an object from a spurious return)
   stays inside. See ``occlusion._occluded_extents``. Lines of one surface on both sides of
   an occluder (or of a gap the merge did not test) then get one fit when they pass the
   merge's chi-square test and no beam between them saw further than the joint line
   (``occlusion._join_occluded``); their extents stay as they were (none dropped), and the
   segments of each side carry the same fit: one measurement, not two.
6. Lines with fewer than ``min_points`` points, shorter than ``min_length`` or with an
   RMSE above the split tolerance are dropped. End points are the projections of the
   first and last supporting points, moved onto the ray of that beam when the projection
   falls outside the supporting beams' bearings: a segment covers no beam outside them.

Choices where the chapters are silent, or misprinted:

* Fits and RMSE use perpendicular (total least squares) residuals, not the vertical
  residuals of the line chapter's eqs. 12-19, which fail on lines parallel to the y axis.
* Lowess combines the two weights by product (the line chapter prints a sum in eq. 10,
  which could not give an outlier the zero weight its Fig. 1 shows).
* The (rho, alpha) covariance propagates the per-point noise of the line chapter's eq. 7
  through first-order derivatives of the total-least-squares solution (:func:`fit_line`).
* Ranges rounded to a step q (``LineParams.range_step``, found by the range-noise estimate):
  the covariances use ``sigma_r`` (sensor noise and rounding, q^2 / 12), the gates above
  (trim, growth, see-through and occluder margins) the std whose 3-sigma gate has the
  rounded error's tail (``LineParams.gate_sigma_r``,
  :func:`landmark_nav.laser.range_noise.gate_sigma`), the split tolerance (4 sigma) the
  bound with the tail of a Gaussian's 4 sigma: a bounded rounding error has lighter tails
  than a Gaussian of its variance.

Code: this module runs the steps (:func:`extract_lines`); each step is a module of
:mod:`landmark_nav.laser.line_extraction` named after what it computes (the names in
double backquotes above are relative to it): ``tls_fit`` (the fits and their covariance,
eqs. 5-10, 7, 21), ``split`` (eq. 4), ``alfa`` (eq. 21), ``cleanup`` (steps 1-2),
``merge`` (step 3), ``growth`` (step 4), ``see_through`` and ``occlusion`` (step 5),
``segments`` (step 6, :class:`LineSegment`), ``params`` (:class:`LineParams`) and
``scan_batch`` (the clusters of a scan as one batch).
"""

import math
from typing import List, Optional, Sequence

from landmark_nav.laser.line_extraction.alfa import alfa_pieces
from landmark_nav.laser.line_extraction.cleanup import _clean_pieces, _refine_breaks
from landmark_nav.laser.line_extraction.growth import _grow
from landmark_nav.laser.line_extraction.merge import _merge
from landmark_nav.laser.line_extraction.occlusion import _join_occluded, _occluded_extents
from landmark_nav.laser.line_extraction.params import (CHI2_2DOF_95, LINE_PARAMETERS,
                                                       LineParams, METHODS)
from landmark_nav.laser.line_extraction.scan_batch import (_concat, _COS, _gather, _RNG, _SIN,
                                                           _TOL)
from landmark_nav.laser.line_extraction.see_through import _cut_seen_through
from landmark_nav.laser.line_extraction.segments import _build, LineSegment
from landmark_nav.laser.line_extraction.split import _split, split_pieces
from landmark_nav.laser.line_extraction.tls_fit import (_features, _Fit, _solve, fit_line,
                                                        point_covariances)
from landmark_nav.laser.lowess import lowess, lowess_groups
from landmark_nav.laser.segmentation import Cluster
import numpy as np

__all__ = ['alfa_pieces', 'CHI2_2DOF_95', 'explained_points', 'extract_lines', 'fit_line',
           'LINE_PARAMETERS', 'LineParams', 'LineSegment', 'lowess', 'METHODS',
           'point_covariances', 'split_pieces']


def extract_lines(clusters: Sequence[Cluster], params: Optional[LineParams] = None
                  ) -> List[LineSegment]:
    """Extract line segments from the clusters of one scan.

    Args:
        clusters: Clusters of consecutive points of one scan, in beam order (see
            ``segment_scan``), laser frame. Lines start in clusters of at least
            ``min_points`` points and can grow over the points of smaller ones, so pass
            small clusters too (``segment_scan(..., min_points=1)``) to let lines reach
            isolated points on their wall (e.g. a corridor wall seen at grazing angles).
            Clusters of one ``segment_scan`` call carry the whole scan, so no line covers
            a beam seen through it even where that beam's cluster was dropped; for
            clusters built by hand only their own beams are known (step 5).
        params: Method and parameters (default ``LineParams()``).

    Returns:
        Line segments in beam order; empty if no cluster holds a line.

    """
    params = params or LineParams()
    # The fits divide by zero for degenerate point sets (their covariance becomes inf and
    # they are dropped): one error state for the whole scan.
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        return _extract(clusters, params)


def _extract(clusters: Sequence[Cluster], params: LineParams) -> List[LineSegment]:
    """Return the lines of :func:`extract_lines` (floating-point errors ignored)."""
    scan = _concat(clusters, params)
    if scan is None:
        return []
    offsets = scan.offsets
    big = (offsets[1:] - offsets[:-1] >= params.min_points).nonzero()[0]
    if not big.size:
        return []
    cols = scan.cols
    n = scan.x.size
    feats = _features(scan.x, scan.y, cols[_RNG], cols[_COS], cols[_SIN], params.sigma_r,
                      params.sigma_phi, pad=1)
    pre = np.zeros((5, n + 1))  # prefix sums of x, y, x^2, y^2, xy (= _prefix5(x, y))
    feats[1:6, :n].cumsum(axis=1, out=pre[:, 1:])
    if params.method == 'split_merge':
        s, e = _split(scan.x, scan.y, offsets[big], offsets[big + 1] - 1, cols[_TOL], 2)
    else:
        # Smooth each cluster's ranges over the bearing (eqs. 8-10), polar -> Cartesian.
        sub, sub_offs = _gather(offsets[big], offsets[big + 1] - 1)
        rng, cos, sin, _, phi = cols[_RNG:].take(sub, axis=1)
        r_s = lowess_groups(phi, rng, sub_offs, params.lowess_span, params.lowess_iterations)
        pieces = alfa_pieces(np.stack([r_s * cos, r_s * sin], axis=1), sub_offs, params)
        pieces = sub[pieces] if pieces.size else pieces
        s, e = pieces[:, 0], pieces[:, 1]
    s, e = _refine_breaks(scan, pre, s, e, params.min_points)
    s, e = _clean_pieces(scan, pre, s, e, params)
    if not s.size:
        return []
    sums, first0, last0, fit, label = _merge(scan, feats, s, e, params)
    sums, first, last, grown = _grow(scan, feats, sums, first0, last0, fit, params)
    if grown or fit.cov is None:
        fit = _solve(sums, scan.origin)
    sums, first, last, fit = _cut_seen_through(scan, feats, sums, first, last, fit,
                                               (s, e, label, first0, last0), params)
    if not first.size:
        return []
    if params.join_occluded:
        fit = _join_occluded(scan, sums, first, last, fit, (s, e), params)
    col, first, last = _occluded_extents(scan, fit, first, last, params)
    if col is not None:
        fit = _Fit(fit.params.take(col, axis=1), fit.rmse[col], fit.count[col],
                   fit.cov.take(col, axis=0))
    return _build(scan, params, fit, first, last)


def explained_points(lines: Sequence[LineSegment], ranges: np.ndarray, angles: np.ndarray,
                     valid: np.ndarray, sigma_r: float = 0.01,
                     sigma_phi: float = math.radians(0.1), n_sigma: float = 3.0,
                     min_distance: float = 0.05) -> np.ndarray:
    """Return (N,) True for the valid beams that a line explains.

    A valid beam i is explained when some line has ``first_index <= i <= last_index`` and
    the point is within ``max(min_distance, n_sigma * sigma_i)`` of that line, sigma_i
    being the std of the point's distance to the line from eq. 7 (range noise along the
    beam, bearing noise across it, projected on the line normal).

    Args:
        lines: Lines of one scan.
        ranges: (N,) ranges of the scan [m].
        angles: (N,) beam angles [rad].
        valid: (N,) bool, the beams that are real returns.
        sigma_r: Range noise std [m].
        sigma_phi: Bearing noise std [rad].
        n_sigma: Gate in standard deviations.
        min_distance: Smallest gate [m].

    Returns:
        (N,) bool mask (always False where not valid).

    """
    ranges = np.asarray(ranges, dtype=float)
    angles = np.asarray(angles, dtype=float)
    out = np.zeros(ranges.shape, dtype=bool)
    valid = np.asarray(valid, dtype=bool)
    r = np.where(valid, ranges, 0.0)
    c, s = np.cos(angles), np.sin(angles)
    for ln in lines:
        sl = slice(ln.first_index, ln.last_index + 1)
        ca, sa = math.cos(ln.alpha), math.sin(ln.alpha)
        d = r[sl] * (c[sl] * ca + s[sl] * sa) - ln.rho
        n_u = c[sl] * ca + s[sl] * sa
        n_v = c[sl] * sa - s[sl] * ca
        sig = np.sqrt((sigma_r * n_u) ** 2 + (r[sl] * sigma_phi * n_v) ** 2)
        out[sl] |= valid[sl] & (np.abs(d) <= np.maximum(min_distance, n_sigma * sig))
    return out
