"""All clusters of one scan as one batch of points, the input of every step of the lines.

:class:`_Scan` holds the points of the clusters back to back (coordinates relative to
their mean); :func:`_concat` builds it, :func:`_gather` lays out index ranges.
"""

from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple

from landmark_nav.laser.line_extraction.params import LineParams
from landmark_nav.laser.segmentation import Cluster, ScanArrays
import numpy as np


def _gather(starts: np.ndarray, ends: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return the concatenated inclusive index ranges ``[starts[i], ends[i]]`` and offsets."""
    cnt = ends - starts + 1
    offs = np.zeros(cnt.size + 1, dtype=np.int64)
    cnt.cumsum(out=offs[1:])
    idx = np.arange(offs[-1], dtype=np.int64) - (offs[:-1] - starts).repeat(cnt)
    return idx, offs


@dataclass(frozen=True, eq=False)
class _Scan:
    """All clusters of a scan back to back, coordinates relative to ``origin`` (internal).

    ``cols`` holds one row per point attribute (see the ``_X`` .. ``_PHI`` row numbers), so
    that one gather takes all of them; ``x`` and ``y`` are views of its rows.
    """

    cols: np.ndarray  # (7, N)
    x: np.ndarray
    y: np.ndarray
    origin: Tuple[float, float]
    beam: np.ndarray
    cluster: np.ndarray  # (N,) cluster number of each point
    offsets: np.ndarray
    nbeam: int  # largest beam index + 1
    whole: Optional[ScanArrays] = None  # the whole scan, when the clusters share it
    _rows: list = field(default_factory=list, repr=False)  # cache of rows()

    def rows(self) -> List[memoryview]:
        """Return the rows of ``cols`` for the Python-float paths (indexing gives floats).

        Memory views, not lists: those paths read a few points of a row, and a list would
        make a Python float of every point.
        """
        if not self._rows:
            self._rows.extend(memoryview(row) for row in self.cols)
        return self._rows

    def beams(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return range, cos, sin and validity of every beam, by beam index.

        From the whole scan when known (also the beams of no cluster: dropped small
        clusters, returns the segmentation left out), else from the clusters' points alone
        (beams of no cluster count as missing).
        """
        w = self.whole
        if w is not None:
            return w.ranges, w.cos, w.sin, w.valid
        size = self.nbeam
        out = np.zeros((3, size))
        out[:, self.beam] = self.cols[_RNG:_TOL]
        valid = np.zeros(size, dtype=bool)
        valid[self.beam] = np.isfinite(self.cols[_RNG]) & (self.cols[_RNG] > 0.0)
        return out[0], out[1], out[2], valid


# Rows of _Scan.cols: point coordinates relative to the origin, range, cos and sin of the
# bearing, split tolerance (threshold + 3 sigma_phi r), bearing.
_X, _Y, _RNG, _COS, _SIN, _TOL, _PHI = range(7)


def _concat(clusters: Sequence[Cluster], params: LineParams) -> Optional[_Scan]:
    """Stack the non-empty clusters; None if there are none."""
    cl, bounds, sizes = [], [0], []
    for c in clusters:
        size = c.indices.size
        if size:
            cl.append(c)
            sizes.append(size)
            bounds.append(bounds[-1] + size)
    if not cl:
        return None
    offsets = np.array(bounds, dtype=np.int64)
    n = bounds[-1]
    cols = np.empty((7, n))
    whole = cl[0].scan
    one = whole is not None and all(c.scan is whole for c in cl)  # of one segment_scan call
    if one and all(c.points.base is whole.points for c in cl):
        # Clusters of one segment_scan call: gather from its whole-scan arrays.
        beam = np.concatenate([c.indices for c in cl], dtype=np.int64)
        xy = whole.points.take(beam, axis=0)
        whole.ranges.take(beam, out=cols[_RNG])
        whole.cos.take(beam, out=cols[_COS])
        whole.sin.take(beam, out=cols[_SIN])
        whole.angles.take(beam, out=cols[_PHI])
    else:
        beam = np.concatenate([c.indices for c in cl], dtype=np.int64)
        xy = np.concatenate([c.points for c in cl], dtype=float).reshape(-1, 2)
        cols[_RNG] = np.concatenate([c.ranges for c in cl], dtype=float)
        cols[_PHI] = np.concatenate([c.angles for c in cl], dtype=float)
        np.cos(cols[_PHI], out=cols[_COS])
        np.sin(cols[_PHI], out=cols[_SIN])
    ox, oy = (xy.cumsum(axis=0)[-1] / n).tolist()  # the mean (summed in point order)
    np.subtract(xy[:, 0], ox, out=cols[_X])
    np.subtract(xy[:, 1], oy, out=cols[_Y])
    np.multiply(cols[_RNG], 3.0 * params.sigma_phi, out=cols[_TOL])  # split tolerance
    cols[_TOL] += params.threshold
    shared = whole if one and whole.valid is not None else None
    return _Scan(cols, cols[_X], cols[_Y], (ox, oy), beam,
                 np.arange(len(cl)).repeat(sizes), offsets,
                 int(beam.max()) + 1, shared)
