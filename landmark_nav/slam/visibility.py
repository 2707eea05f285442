"""Which map landmarks a scan should have seen (visibility-aware pruning).

A landmark that should have been detected and was not counts a *miss*; the filter removes a
landmark after ``prune_misses`` consecutive misses (:class:`~.ekf_slam.SlamParams`). "Should
have been detected" is decided from the scan itself and the landmark's own history, with no
distance or angle constant of its own:

* Field of view and range: the predicted position (a corner) or some beam of the segment
  (a line) lies inside the scan's ``[angle_min, angle_max]`` and ``(range_min, range_max)``
  and within the largest distance at which the landmark was ever detected (``max_seen``:
  the extractor's reach for this feature, e.g. a corner whose arms thin out with range).
* Facing: a corner's free-space wedge (its mean bisector and opening, when known) must
  contain the line of sight by at least the grazing margin that the filter itself uses
  (``min_view_margin``); a line must be seen from its front (``rho > 0`` in the laser
  frame). Behind a wall or outside a corner's wedge nothing is expected.
* Occlusion, per the scan: the return on the beam toward the landmark is compared with the
  predicted range ``r``; a return shorter than ``r - g sigma`` (``g = sqrt(chi2_1(p))``,
  ``sigma`` the predicted range std plus the laser noise) is something in front: occluded,
  not expected. A NaN (sensor error) is unknown: not expected. A return at or beyond the
  landmark, or no return (+inf) where the landmark should be, is a chance the detector had.
  A line counts as visible when at least ``line_min_beams`` of its beams pass this test.
"""

from dataclasses import dataclass

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


def _laser_pose(pose: np.ndarray, mount: np.ndarray) -> np.ndarray:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.array([pose[0] + c * mount[0] - s * mount[1], pose[1] + s * mount[0]
                     + c * mount[1], pose[2] + mount[2]])


def _beam_range(scan: ScanGeometry, bearing: np.ndarray) -> np.ndarray:
    """Return the measured range on the beam nearest each bearing (nan outside the scan)."""
    ranges = np.asarray(scan.ranges, dtype=float)
    k = np.rint((bearing - scan.angle_min) / scan.angle_increment)
    inside = (k >= 0) & (k < ranges.size)
    out = np.full(bearing.shape, np.nan)
    out[inside] = ranges[k[inside].astype(np.int64)]
    return out


def _unoccluded(measured: np.ndarray, predicted: np.ndarray, gate_sigma: np.ndarray
                ) -> np.ndarray:
    """Beams on which the detector had a chance: no error, nothing in front (docstring)."""
    with np.errstate(invalid='ignore'):
        return ~np.isnan(measured) & ~(measured < predicted - gate_sigma)


def corners_expected(pose: np.ndarray, xy: np.ndarray, bisector: np.ndarray,
                     opening: np.ndarray, max_seen: np.ndarray, range_sigma: np.ndarray,
                     scan: ScanGeometry, gate: float, min_view_margin: float) -> np.ndarray:
    """Return (K,) whether each corner landmark should be in this scan (module docstring).

    Args:
        pose: (3,) robot pose in the map.
        xy: (K, 2) corner positions (map).
        bisector: (K, 2) sum of world bisector unit vectors (zeros: unknown).
        opening: (K,) mean free-space opening (nan: unknown) [rad].
        max_seen: (K,) largest base_link range the corner was detected at [m].
        range_sigma: (K,) predicted range std of the corner [m].
        scan: The scan.
        gate: ``sqrt(chi2_1(p))``.
        min_view_margin: The filter's grazing margin [rad].
    """
    lp = _laser_pose(pose, np.asarray(scan.mount, dtype=float))
    d = xy - lp[:2]
    r = np.hypot(d[:, 0], d[:, 1])
    b = _wrap(np.arctan2(d[:, 1], d[:, 0]) - lp[2])
    n = np.asarray(scan.ranges).size
    half_inc = 0.5 * abs(scan.angle_increment)
    lo = scan.angle_min + min(0.0, (n - 1) * scan.angle_increment)
    hi = scan.angle_min + max(0.0, (n - 1) * scan.angle_increment)
    rb = np.hypot(xy[:, 0] - pose[0], xy[:, 1] - pose[1])
    ok = (b >= lo - half_inc) & (b <= hi + half_inc) & (r > scan.range_min) & (
        r < scan.range_max) & (rb <= max_seen)
    known = np.any(bisector != 0.0, axis=1) & np.isfinite(opening)
    if np.any(known):
        view = np.abs(_wrap(np.arctan2(-d[:, 1], -d[:, 0])
                            - np.arctan2(bisector[:, 1], bisector[:, 0])))
        half = 0.5 * np.minimum(opening, _TWO_PI - opening)
        with np.errstate(invalid='ignore'):
            ok &= ~known | (half - view >= min_view_margin)
    sigma = np.sqrt(range_sigma ** 2 + scan.sigma_range ** 2)
    ok &= _unoccluded(_beam_range(scan, b), r, gate * sigma)
    return ok


def lines_expected(pose: np.ndarray, lines: np.ndarray, ends: np.ndarray,
                   max_seen: np.ndarray, rho_sigma: np.ndarray, scan: ScanGeometry,
                   gate: float, min_beams: int) -> np.ndarray:
    """Return (K,) whether each line landmark should be in this scan (module docstring).

    Args:
        pose: (3,) robot pose in the map.
        lines: (K, 2) ``(rho, alpha)`` in the map.
        ends: (K, 2, 2) endpoints in the map.
        max_seen: (K,) largest ``rho_b`` the line was detected at [m].
        rho_sigma: (K,) predicted std of ``rho_b`` [m].
        scan: The scan.
        gate: ``sqrt(chi2_1(p))``.
        min_beams: Unoccluded beams needed.
    """
    k = lines.shape[0]
    if k == 0:
        return np.zeros(0, dtype=bool)
    lp = _laser_pose(pose, np.asarray(scan.mount, dtype=float))
    a = lines[:, 1]
    nrm = np.column_stack([np.cos(a), np.sin(a)])
    rho_l = lines[:, 0] - nrm @ lp[:2]
    alpha_l = a - lp[2]
    rho_b = lines[:, 0] - nrm @ np.asarray(pose[:2], dtype=float)
    e = ends - lp[:2]
    u_end = _wrap(np.arctan2(e[..., 1], e[..., 0]) - lp[2] - alpha_l[:, None])  # (K, 2)
    u_lo, u_hi = u_end.min(axis=1), u_end.max(axis=1)
    phi = scan.angles
    u = _wrap(phi[None, :] - alpha_l[:, None])  # (K, B)
    cos_u = np.cos(u)
    on = (u >= u_lo[:, None]) & (u <= u_hi[:, None]) & (cos_u > 0.0)
    with np.errstate(divide='ignore', invalid='ignore'):
        pred = rho_l[:, None] / cos_u
        sigma = np.sqrt((rho_sigma[:, None] / cos_u) ** 2 + scan.sigma_range ** 2)
    meas = np.asarray(scan.ranges, dtype=float)[None, :]
    beam_ok = on & (pred > scan.range_min) & (pred < scan.range_max) & _unoccluded(
        np.broadcast_to(meas, pred.shape), pred, gate * sigma)
    return (rho_l > 0.0) & (rho_b <= max_seen) & (beam_ok.sum(axis=1) >= min_beams)


def expected_visible(pose: np.ndarray, kind: np.ndarray, params: np.ndarray,
                     ends: np.ndarray, bisector: np.ndarray, opening: np.ndarray,
                     max_seen: np.ndarray, sigma: np.ndarray, scan: ScanGeometry,
                     gate: float, min_view_margin: float, line_min_beams: int
                     ) -> np.ndarray:
    """Return (N,) whether each landmark (corner or line) should be in the scan.

    Args:
        pose: (3,) robot pose.
        kind: (N,) 0 corner, 1 line.
        params: (N, 2) landmark parameters (corner ``x, y``; line ``rho, alpha``).
        ends: (N, 2, 2) line endpoints (ignored for corners).
        bisector: (N, 2) corner bisector sums.
        opening: (N,) corner openings.
        max_seen: (N,) largest detection distance.
        sigma: (N,) predicted std of the range (corner) or ``rho_b`` (line).
        scan: The scan.
        gate: ``sqrt(chi2_1(p))``.
        min_view_margin: Corner grazing margin [rad].
        line_min_beams: Beams a line needs.
    """
    out = np.zeros(kind.size, dtype=bool)
    c = np.flatnonzero(kind == 0)
    if c.size:
        out[c] = corners_expected(pose, params[c], bisector[c], opening[c], max_seen[c],
                                  sigma[c], scan, gate, min_view_margin)
    ln = np.flatnonzero(kind == 1)
    if ln.size:
        out[ln] = lines_expected(pose, params[ln], ends[ln], max_seen[ln], sigma[ln], scan,
                                 gate, line_min_beams)
    return out


__all__ = ['corners_expected', 'expected_visible', 'lines_expected', 'ScanGeometry']
