"""Which map landmarks a scan shows to be absent (visibility-aware pruning).

A landmark the scan should have shown and did not counts a *miss*; the filter removes a
landmark after ``prune_misses`` consecutive misses (:class:`~.ekf_slam.SlamParams`, by
default as many scans as a candidate needs to be confirmed). A detector failure is not a
miss: the corner and line extractors miss real features now and then, for many consecutive
scans in a row where the geometry is unfavourable (on the simulated office a corner matched
in 256 of 270 chances was missed in 4 consecutive scans), so "not detected" proves
nothing. What the scan does prove is free space: a beam that passes through the place where
the landmark should be and returns from beyond it. So a miss needs, with no distance or
angle constant of its own:

* Field of view and range: the landmark (a corner) or at least ``line_min_beams`` beams of
  its segment (a line) inside the scan's beams and ``(range_min, range_max)``.
* Facing: a corner's free-space wedge (its mean bisector and opening, when known) contains
  the line of sight by at least the filter's grazing margin (``min_view_margin``); a line
  is seen from its front (``rho > 0`` in the laser frame).
* Seen through, per the scan, with the filter's own uncertainty: ``g = sqrt(chi2_1(p))``
  and the predicted std of the range (corner) or of ``rho`` (line) plus the laser noise.
  A corner is seen through when every beam within ``g`` bearing standard deviations plus
  one beam spacing of its predicted bearing returns beyond the predicted range by more
  than ``g`` range standard deviations plus ``r dphi / sin(min_view_margin)``: a real
  corner has an arm return on a beam next to the vertex, and at the filter's grazing limit
  that return can lie this far beyond the vertex along the beam (``dphi`` the beam
  spacing: 35 cm at 5.5 m with 0.5 deg beams and the default 8 deg margin; a convex
  corner is an object's edge, so the beam nearest the vertex may pass beside it). A line
  is seen through when at least
  ``line_min_beams`` of its beams return beyond it and fewer than ``line_min_beams``
  return on it. No return (+inf: a blackout, a dark or specular surface) and NaN (sensor
  error) are unknown and never count as seen through.
"""

from dataclasses import dataclass
from functools import cached_property
from typing import Tuple

import numpy as np

_PI = np.pi
_TWO_PI = 2.0 * np.pi


def _wrap(a):
    return np.mod(a + _PI, _TWO_PI) - _PI


@dataclass(frozen=True, eq=False)
class ScanGeometry:
    """The scan a landmark could have been seen in (laser frame, REP 117 ranges).

    Attributes:
        ranges: (B,) ranges [m]; +inf no return, -inf closer than range_min, NaN error.
        angle_min: Angle of beam 0 [rad].
        angle_increment: Beam spacing [rad].
        range_min: Smallest valid range [m].
        range_max: Largest valid range [m].
        mount: (3,) laser pose ``[x, y, yaw]`` in base_link.
        sigma_range: The laser's 1-sigma range noise [m].
    """

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    mount: np.ndarray
    sigma_range: float = 0.01

    @property
    def angles(self) -> np.ndarray:
        """(B,) beam angles."""
        return self.angle_min + self.angle_increment * np.arange(np.asarray(self.ranges).size)

    @cached_property
    def has_returns(self) -> bool:
        """Whether any beam returned (a finite range).

        Without one the scan shows nothing: no landmark is seen through (missed) or has a
        chance to be detected (:func:`corners_missed`, :func:`lines_missed`,
        :func:`corners_in_view` need finite returns), as in a laser blackout.
        """
        return bool(np.isfinite(np.asarray(self.ranges, dtype=float)).any())


def swept_region(scan: ScanGeometry) -> Tuple[float, float]:
    """Area [m^2] of the region the scan's beams sweep and the perimeter [m] of its hull.

    The region is the fan of the valid returns (finite, inside ``(range_min, range_max)``:
    a beam with no return shows no area whose features could have been detected): area
    ``sum r^2 dphi / 2``. The perimeter is that of the convex hull of the laser and the
    return points: by Cauchy-Crofton the measure ``drho dalpha`` of the lines meeting a
    region is the perimeter of its convex hull, so lines per hull perimeter is a density of
    lines in ``(rho, alpha)`` as corners per area is one in the plane.
    """
    r = np.asarray(scan.ranges, dtype=float)
    with np.errstate(invalid='ignore'):
        valid = np.isfinite(r) & (r > scan.range_min) & (r < scan.range_max)
    if not np.any(valid):
        return 0.0, 0.0
    a = scan.angles[valid]
    r = r[valid]
    area = 0.5 * abs(scan.angle_increment) * float(np.dot(r, r))
    points = np.vstack([np.zeros((1, 2)), np.column_stack([r * np.cos(a), r * np.sin(a)])])
    return area, _hull_perimeter(points)


def _hull_perimeter(points: np.ndarray) -> float:
    """Perimeter of the convex hull of (N, 2) points (qhull; a segment's twice its length)."""
    from scipy.spatial import ConvexHull, QhullError  # on first use: not at every node start
    try:
        return float(ConvexHull(points).area)  # in 2-D qhull's "area" is the perimeter
    except QhullError:  # fewer than three points or all on one line
        centred = points - points.mean(axis=0)
        axis = np.linalg.svd(centred, full_matrices=False)[2][0]
        return 2.0 * float(np.ptp(centred @ axis))


def _laser_pose(pose: np.ndarray, mount: np.ndarray) -> np.ndarray:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.array([pose[0] + c * mount[0] - s * mount[1], pose[1] + s * mount[0]
                     + c * mount[1], pose[2] + mount[2]])


def _corner_windows(pose: np.ndarray, xy: np.ndarray, bisector: np.ndarray,
                    opening: np.ndarray, sigma: np.ndarray, scan: ScanGeometry, gate: float,
                    min_view_margin: float):
    """Range, eligibility, range tolerance and beam window of each corner (module docstring).

    Returns:
        ``(r (K,), ok (K,) in the field of view and range and facing, tol (K,), k_lo (K,),
        k_hi (K,))``; ``tol`` and the window are those of the "seen through" test.
    """
    lp = _laser_pose(pose, np.asarray(scan.mount, dtype=float))
    d = xy - lp[:2]
    r = np.hypot(d[:, 0], d[:, 1])
    b = _wrap(np.arctan2(d[:, 1], d[:, 0]) - lp[2])
    ok = (r > scan.range_min) & (r < scan.range_max)
    known = np.any(bisector != 0.0, axis=1) & np.isfinite(opening)
    if np.any(known):
        view = np.abs(_wrap(np.arctan2(-d[:, 1], -d[:, 0])
                            - np.arctan2(bisector[:, 1], bisector[:, 0])))
        half = 0.5 * np.minimum(opening, _TWO_PI - opening)
        with np.errstate(invalid='ignore'):
            ok &= ~known | (half - view >= min_view_margin)
    inc = abs(scan.angle_increment)
    half_window = gate * sigma[:, 1] + inc
    tol = gate * np.sqrt(sigma[:, 0] ** 2 + scan.sigma_range ** 2) + r * inc / np.sin(
        min(max(min_view_margin, 1e-9), 0.5 * np.pi))
    k_lo = np.ceil((b - half_window - scan.angle_min) / scan.angle_increment)
    k_hi = np.floor((b + half_window - scan.angle_min) / scan.angle_increment)
    if scan.angle_increment < 0:
        k_lo, k_hi = k_hi, k_lo
    ok &= (k_lo >= 0) & (k_hi < np.asarray(scan.ranges).size) & (k_hi >= k_lo)
    return r, ok, tol, k_lo, k_hi


def _windows_all(scan: ScanGeometry, ok: np.ndarray, k_lo: np.ndarray, k_hi: np.ndarray,
                 bound: np.ndarray, strict: bool) -> np.ndarray:
    """Return (K,) whether each eligible corner's beam window lies wholly beyond ``bound``.

    Every beam finite and ``> bound`` (``strict``) or ``>= bound``; False where not ``ok``.
    """
    ranges = np.asarray(scan.ranges, dtype=float)
    out = np.zeros(ok.shape[0], dtype=bool)
    for i in np.flatnonzero(ok):
        meas = ranges[int(k_lo[i]):int(k_hi[i]) + 1]
        with np.errstate(invalid='ignore'):
            beyond = meas > bound[i] if strict else meas >= bound[i]
            out[i] = bool(np.all(np.isfinite(meas) & beyond))
    return out


def corners_missed(pose: np.ndarray, xy: np.ndarray, bisector: np.ndarray,
                   opening: np.ndarray, sigma: np.ndarray, scan: ScanGeometry, gate: float,
                   min_view_margin: float) -> np.ndarray:
    """Return (K,) whether the scan shows free space where each corner should be.

    Args:
        pose: (3,) robot pose in the map.
        xy: (K, 2) corner positions (map).
        bisector: (K, 2) sum of world bisector unit vectors (zeros: unknown).
        opening: (K,) mean free-space opening (nan: unknown) [rad].
        sigma: (K, 2) predicted std of the corner's range [m] and bearing [rad].
        scan: The scan.
        gate: ``sqrt(chi2_1(p))``.
        min_view_margin: The filter's grazing margin [rad].
    """
    k = xy.shape[0]
    if min_view_margin <= 0.0:
        return np.zeros(k, dtype=bool)  # no grazing limit: an arm return may be anywhere
    r, ok, tol, k_lo, k_hi = _corner_windows(pose, xy, bisector, opening, sigma, scan, gate,
                                             min_view_margin)
    return _windows_all(scan, ok, k_lo, k_hi, r + tol, strict=True)


def corners_in_view(pose: np.ndarray, xy: np.ndarray, bisector: np.ndarray,
                    opening: np.ndarray, sigma: np.ndarray, max_seen: np.ndarray,
                    scan: ScanGeometry, gate: float, min_view_margin: float) -> np.ndarray:
    """Return (K,) whether the scan had a chance to detect each corner (establishment).

    A chance (:class:`~.ekf_slam.SlamParams` ``establish_hits``) needs what a miss needs
    (:func:`corners_missed`: field of view and range, facing the robot, the same beam
    window) except that the beams may return at the corner as well as beyond it: every
    beam of the window returns no closer than the predicted range minus the same tolerance
    (nothing in front of the corner), and the corner lies no farther than it was ever
    detected (``max_seen``: the extractor needs enough returns on both arms, which it has
    shown to get up to that distance). A detection is a chance; a return in front of the
    corner (occlusion), no return or an error is none.

    Args:
        pose: (3,) robot pose in the map.
        xy: (K, 2) corner positions (map).
        bisector: (K, 2) sum of world bisector unit vectors (zeros: unknown).
        opening: (K,) mean free-space opening (nan: unknown) [rad].
        sigma: (K, 2) predicted std of the corner's range [m] and bearing [rad].
        max_seen: (K,) largest distance each corner was detected at [m].
        scan: The scan.
        gate: ``sqrt(chi2_1(p))``.
        min_view_margin: The filter's grazing margin [rad] (> 0).
    """
    k = xy.shape[0]
    if min_view_margin <= 0.0 or k == 0:
        return np.zeros(k, dtype=bool)
    r, ok, tol, k_lo, k_hi = _corner_windows(pose, xy, bisector, opening, sigma, scan, gate,
                                             min_view_margin)
    ok &= r <= max_seen
    return _windows_all(scan, ok, k_lo, k_hi, r - tol, strict=False)


def _line_beams(pose: np.ndarray, lines: np.ndarray, ends: np.ndarray, rho_sigma: np.ndarray,
                scan: ScanGeometry, gate: float
                ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return the beams toward line segments: ``rho_l, on, pred, tol, meas``.

    ``rho_l`` (K,): each line's distance from the laser (> 0: seen from the front);
    ``on`` (K, B): the beams that cross the segment inside the scan's range with a return;
    ``pred``: the segment's range along each beam; ``tol``: ``gate`` stds of the return
    about it (the line's ``rho`` std through the incidence, and the range noise);
    ``meas``: the measured ranges.
    """
    lp = _laser_pose(pose, np.asarray(scan.mount, dtype=float))
    a = lines[:, 1]
    nrm = np.column_stack([np.cos(a), np.sin(a)])
    rho_l = lines[:, 0] - nrm @ lp[:2]
    alpha_l = a - lp[2]
    e = ends - lp[:2]
    u_end = _wrap(np.arctan2(e[..., 1], e[..., 0]) - lp[2] - alpha_l[:, None])  # (K, 2)
    u_lo, u_hi = u_end.min(axis=1), u_end.max(axis=1)
    u = _wrap(scan.angles[None, :] - alpha_l[:, None])  # (K, B)
    cos_u = np.cos(u)
    on = (u >= u_lo[:, None]) & (u <= u_hi[:, None]) & (cos_u > 0.0)
    with np.errstate(divide='ignore', invalid='ignore'):
        pred = rho_l[:, None] / cos_u
        tol = gate * np.sqrt((rho_sigma[:, None] / cos_u) ** 2 + scan.sigma_range ** 2)
        meas = np.broadcast_to(np.asarray(scan.ranges, dtype=float)[None, :], pred.shape)
        on &= (pred > scan.range_min) & (pred < scan.range_max) & np.isfinite(meas)
    return rho_l, on, pred, tol, meas


def lines_missed(pose: np.ndarray, lines: np.ndarray, ends: np.ndarray, rho_sigma: np.ndarray,
                 scan: ScanGeometry, gate: float, min_beams: int) -> np.ndarray:
    """Return (K,) whether the scan sees through each line landmark's segment.

    Args:
        pose: (3,) robot pose in the map.
        lines: (K, 2) ``(rho, alpha)`` in the map.
        ends: (K, 2, 2) endpoints in the map.
        rho_sigma: (K,) predicted std of ``rho_b`` [m].
        scan: The scan.
        gate: ``sqrt(chi2_1(p))``.
        min_beams: Beams through (and fewest beams on) the line for a miss.
    """
    if lines.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    rho_l, on, pred, tol, meas = _line_beams(pose, lines, ends, rho_sigma, scan, gate)
    with np.errstate(invalid='ignore'):
        through = on & (meas > pred + tol)
        hit = on & (np.abs(meas - pred) <= tol)
    return (rho_l > 0.0) & (through.sum(axis=1) >= min_beams) & (hit.sum(axis=1) < min_beams)


def lines_unoccluded(pose: np.ndarray, lines: np.ndarray, ends: np.ndarray,
                     rho_sigma: np.ndarray, scan: ScanGeometry, gate: float,
                     min_beams: int) -> np.ndarray:
    """Return (K,) whether at least ``min_beams`` beams reach each line's segment.

    The beams of :func:`lines_missed` (on the segment, seen from the front, inside the
    range) that return no closer than the line minus the same tolerance: the line could
    have been seen, or seen through, by this scan (nothing in front of it).
    """
    if lines.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    rho_l, on, pred, tol, meas = _line_beams(pose, lines, ends, rho_sigma, scan, gate)
    with np.errstate(invalid='ignore'):
        reach = on & (meas >= pred - tol)
    return (rho_l > 0.0) & (reach.sum(axis=1) >= min_beams)


def landmarks_missed(pose: np.ndarray, kind: np.ndarray, params: np.ndarray,
                     ends: np.ndarray, bisector: np.ndarray, opening: np.ndarray,
                     sigma: np.ndarray, scan: ScanGeometry, gate: float,
                     min_view_margin: float, line_min_beams: int) -> np.ndarray:
    """Return (N,) whether the scan shows each landmark (corner or line) to be absent.

    Args:
        pose: (3,) robot pose.
        kind: (N,) 0 corner, 1 line.
        params: (N, 2) landmark parameters (corner ``x, y``; line ``rho, alpha``).
        ends: (N, 2, 2) line endpoints (ignored for corners).
        bisector: (N, 2) corner bisector sums.
        opening: (N,) corner openings.
        sigma: (N, 2) predicted observation std (corner: range, bearing; line: rho, alpha).
        scan: The scan.
        gate: ``sqrt(chi2_1(p))``.
        min_view_margin: Corner grazing margin [rad].
        line_min_beams: Beams for a line miss.
    """
    out = np.zeros(kind.size, dtype=bool)
    c = np.flatnonzero(kind == 0)
    if c.size:
        out[c] = corners_missed(pose, params[c], bisector[c], opening[c], sigma[c], scan, gate,
                                min_view_margin)
    ln = np.flatnonzero(kind == 1)
    if ln.size:
        out[ln] = lines_missed(pose, params[ln], ends[ln], sigma[ln, 0], scan, gate,
                               line_min_beams)
    return out


__all__ = ['corners_in_view', 'corners_missed', 'landmarks_missed', 'lines_missed',
           'lines_unoccluded', 'ScanGeometry']
