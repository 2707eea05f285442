"""Line segments: :class:`LineSegment` and step 6, the fits kept as segments.

Fits with too few points, too short or with an RMSE above the split tolerance are
dropped; the end points are the projections of the first and last supporting points,
moved onto the ray of their beam where the projection falls outside the supporting
beams (:func:`_build`).
"""

from dataclasses import dataclass
import math
from typing import List

from landmark_nav.laser.line_extraction.params import LineParams
from landmark_nav.laser.line_extraction.scan_batch import _Scan, _TOL
from landmark_nav.laser.line_extraction.tls_fit import _Fit
import numpy as np


@dataclass(frozen=True, eq=False)
class LineSegment:
    """A line fitted to consecutive scan points (laser frame).

    Attributes:
        rho: Distance of the line to the laser origin, >= 0 [m] (eq. 5).
        alpha: Angle of the line normal, wrapped to [-pi, pi) [rad].
        start: (2,) projection of the first supporting point onto the line, or the
            crossing of its beam's ray with the line when that is nearer the middle [m].
        end: (2,) the same at the last supporting point [m].
        num_points: Number of supporting points (the points of the fit; a line that hides
            its own noisy returns at grazing incidence keeps them in the fit but not in
            its extent, see step 5 of :mod:`landmark_nav.laser.lines`).
        rmse: Perpendicular RMSE of the supporting points [m] (eq. 21).
        covariance: (2, 2) covariance of (rho, alpha) [m^2, m rad; m rad, rad^2].
        first_index: Beam index of the first supporting point of the extent.
        last_index: Beam index of the last supporting point of the extent.

    Segments of one surface on both sides of an occluder share one fit (step 5): equal
    ``rho``, ``alpha``, ``covariance``, ``num_points`` and ``rmse``, one extent each: one
    measurement, not two (``LineParams.join_occluded``).
    """

    rho: float
    alpha: float
    start: np.ndarray
    end: np.ndarray
    num_points: int
    rmse: float
    covariance: np.ndarray
    first_index: int
    last_index: int

    @property
    def length(self) -> float:
        """Return the distance between the endpoints [m]."""
        return float(math.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1]))

    @property
    def normal(self) -> np.ndarray:
        """Return the unit normal ``(cos alpha, sin alpha)``."""
        return np.array([math.cos(self.alpha), math.sin(self.alpha)])

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Return the signed distances (K,) of points (K, 2) to the line [m]."""
        return np.asarray(points, dtype=float).reshape(-1, 2) @ self.normal - self.rho


_INWARD = np.array([[1.0], [-1.0]])  # start moves forward along the line, end backward


def _build(scan: _Scan, params: LineParams, f: _Fit, first: np.ndarray,
           last: np.ndarray) -> List[LineSegment]:
    """Drop small or short fits and build the LineSegments (first/last: point indices)."""
    if first.size <= _BUILD_PY:
        try:
            return _build_py(scan, params, f, first, last)
        except (ZeroDivisionError, OverflowError):  # a ray along a line: numpy inf / nan
            pass
    return _build_arrays(scan, params, f, first, last)


# Lines up to which _build_py is faster than _build_arrays (measured).
_BUILD_PY = 40


def _build_py(scan: _Scan, params: LineParams, f: _Fit, first: np.ndarray,
              last: np.ndarray) -> List[LineSegment]:
    """Return :func:`_build_arrays` computed on Python floats (the same operations).

    Raises ZeroDivisionError where a ray runs along its line (the arrays version then
    gives numpy's inf / nan).
    """
    ox, oy = scan.origin
    xs, ys, _, cps, sps = scan.rows()[:_TOL]
    beam = memoryview(scan.beam)
    firsts, lasts = first.tolist(), last.tolist()
    rhos, alphas, nxs, nys = f.params.tolist()
    rmses, counts = f.rmse.tolist(), f.count.tolist()
    covs = f.cov.reshape(-1, 4).tolist()
    min_points, min_length, thr = params.min_points, params.min_length, params.threshold
    isfinite = math.isfinite
    keep, flat = [], []
    for j, (rho, nx, ny) in enumerate(zip(rhos, nxs, nys)):
        cov = covs[j]
        if not (counts[j] >= min_points and rmses[j] <= thr and isfinite(cov[0])
                and isfinite(cov[3])):
            continue
        ends_j = []
        i0, i1 = firsts[j], lasts[j]
        for x, y, cp, sp in ((xs[i0] + ox, ys[i0] + oy, cps[i0], sps[i0]),
                             (xs[i1] + ox, ys[i1] + oy, cps[i1], sps[i1])):
            d = x * nx + y * ny - rho
            px, py = x - d * nx, y - d * ny
            t = rho / (cp * nx + sp * ny)
            ends_j.append((px, py, t, cp, sp, py * nx - px * ny, t * (sp * nx - cp * ny)))
        (px0, py0, t0, cp0, sp0, al0, ar0), (px1, py1, t1, cp1, sp1, al1, ar1) = ends_j
        # End points at the end beams (see _build_arrays)
        sign = 1.0 if al1 >= al0 else -1.0
        span = abs(al1 - al0)
        inward = sign * (ar0 - al0)
        if t0 > 0.0 and inward > 0.0 and inward < span:
            px0, py0 = t0 * cp0, t0 * sp0
        inward = sign * (ar1 - al1) * -1.0
        if t1 > 0.0 and inward > 0.0 and inward < span:
            px1, py1 = t1 * cp1, t1 * sp1
        if not abs(complex(px1 - px0, py1 - py0)) >= min_length:  # C hypot, as np.hypot
            continue
        keep.append(j)
        flat += (px0, py0, px1, py1)
    if not keep:
        return []
    pts = np.array(flat).reshape(-1, 2, 2)
    # the (2,) start and end points and (2, 2) covariances as views, made in one pass each
    return [_segment(rhos[j], alphas[j], p0, p1, int(counts[j]), rmses[j], c,
                     beam[firsts[j]], beam[lasts[j]])
            for j, p0, p1, c in zip(keep, pts[:, 0], pts[:, 1], f.cov.take(keep, axis=0))]


_new = object.__new__


def _segment(rho: float, alpha: float, start: np.ndarray, end: np.ndarray, num_points: int,
             rmse: float, covariance: np.ndarray, first_index: int, last_index: int
             ) -> LineSegment:
    """Return ``LineSegment(...)`` of these values, its fields set without ``__init__``.

    The frozen dataclass's ``__init__`` sets each field through ``object.__setattr__``;
    this writes them to the instance's ``__dict__`` at once (the same object, a third of
    the time).
    """
    seg = _new(LineSegment)
    d = seg.__dict__
    d['rho'], d['alpha'], d['start'], d['end'], d['num_points'] = (rho, alpha, start, end,
                                                                   num_points)
    d['rmse'], d['covariance'], d['first_index'], d['last_index'] = (rmse, covariance,
                                                                     first_index, last_index)
    return seg


def _build_arrays(scan: _Scan, params: LineParams, f: _Fit, first: np.ndarray,
                  last: np.ndarray) -> List[LineSegment]:
    """Return :func:`_build` on arrays (all lines of the scan at once)."""
    ox, oy = scan.origin
    ends = np.empty((2, first.size), dtype=np.int64)
    ends[0] = first
    ends[1] = last
    x, y, _, cp, sp = scan.cols[:_TOL].take(ends, axis=1)
    x += ox
    y += oy
    rho, alpha = f.params[:2]
    # the line parameters once per end point (2, G): no broadcasting in the steps below
    rho2, _, nx, ny = np.concatenate((f.params, f.params), axis=1).reshape(4, 2, first.size)
    d = x * nx + y * ny - rho2
    proj = np.empty((2, first.size, 2))  # end point (first, last), line, (x, y)
    np.subtract(x, d * nx, out=proj[..., 0])
    np.subtract(y, d * ny, out=proj[..., 1])
    # End points at the end beams: where a projection lies outside the bearings of the
    # supporting beams, the end beam's ray meets the line (the segment then covers no beam
    # outside its support). Inside, the projection stays (it does not depend on the range
    # noise along a grazing ray).
    t = rho2 / (cp * nx + sp * ny)
    along = proj[..., 1] * nx - proj[..., 0] * ny  # position along the line (tangent)
    along_ray = t * (sp * nx - cp * ny)
    inward = np.where(along[1] >= along[0], 1.0, -1.0) * (along_ray - along) * _INWARD
    # nan fails; a ray along the line (through the origin) meets it nowhere useful
    inner = (t > 0.0) & (inward > 0.0) & (inward < np.abs(along[1] - along[0]))
    if np.count_nonzero(inner):
        proj[..., 0] = np.where(inner, t * cp, proj[..., 0])
        proj[..., 1] = np.where(inner, t * sp, proj[..., 1])
    length = np.hypot(proj[1, :, 0] - proj[0, :, 0], proj[1, :, 1] - proj[0, :, 1])
    cov = f.cov
    ok = ((f.count >= params.min_points) & (length >= params.min_length)
          & (f.rmse <= params.threshold)
          & np.isfinite(cov[:, 0, 0]) & np.isfinite(cov[:, 1, 1])).nonzero()[0]
    rho, alpha, rmse = rho[ok].tolist(), alpha[ok].tolist(), f.rmse[ok].tolist()
    count = f.count[ok].astype(np.int64).tolist()
    b0, b1 = scan.beam[ends.take(ok, axis=1)].tolist()
    proj, cov = proj.take(ok, axis=1), cov.take(ok, axis=0)
    return [_segment(rho[j], alpha[j], proj[0, j], proj[1, j], count[j], rmse[j], cov[j],
                     b0[j], b1[j]) for j in range(len(rho))]
