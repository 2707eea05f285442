"""What a scan shows beyond the outer end of each arm of a corner (:func:`arm_ends`).

An arm's outer end lies on the ray of its outermost sample (``Corner.arms``). The next
real return beyond it, in the direction the arm runs (no-return beams are skipped), tells
whether the arm's extent is known:

* ``'inside'``: that return is in the arm's own cluster: the surface goes on past the fit
  or bends into another surface (no range jump);
* ``'nearer'``: a range jump (another cluster: the segmentation's adaptive breakpoint,
  Borges & Aldon) to a return in front of the arm's line extended along that ray: a nearer
  surface hides where the arm ends, so its true extent is unknown (**occluded**);
* ``'farther'``: a jump to a return beyond the extended line (or a ray that never meets
  it): the surface ends there, an edge seen against the background;
* ``'unknown'``: no real return beyond before the end of the scan (field of view).

From these, a corner is a **silhouette** when it is convex and both arms end
``'farther'``: the whole object is seen against the background, a free-standing object
(furniture, a bin) rather than the building, whose convex corners (a door jamb, a
corridor junction) have at least one wall running on. A concave corner whose arms both
end ``'farther'`` is a recess seen whole (its surfaces meet behind the vertex as seen from
the sensor, so it cannot be an object's outline seen from outside).
"""

import math
from typing import List, Optional, Sequence

from landmark_nav.laser.segmentation import Cluster
import numpy as np

ARM_ENDS = ('inside', 'nearer', 'farther', 'unknown')


def arm_ends(corners: Sequence, clusters: Sequence[Cluster]) -> Optional[List[tuple]]:
    """Return each corner's ``(end of arm 0, end of arm 1)`` (module docstring), or None.

    Args:
        corners: :class:`~landmark_nav.laser.corner_detection.corner.Corner` with ``arms``.
        clusters: The clusters the corners were detected in, from one
            :func:`~landmark_nav.laser.segmentation.segment_scan` call.

    Returns:
        One pair of :data:`ARM_ENDS` names per corner; None when the clusters do not carry
        the whole scan's arrays (``Cluster.scan`` with ``valid``: built by hand), as the
        beams between the clusters are then unknown.
    """
    scan = clusters[0].scan if clusters else None
    if scan is None or scan.valid is None or any(c.scan is not scan for c in clusters):
        return None
    if not corners:
        return []
    valid = np.asarray(scan.valid, dtype=bool)
    n = valid.size
    label = np.full(n, -1, dtype=np.int64)  # cluster of each beam (-1: none kept)
    sizes = [len(c.indices) for c in clusters]
    label[np.concatenate([c.indices for c in clusters]).astype(np.int64)] = np.repeat(
        np.arange(len(clusters)), sizes)
    # Next / previous real return at or after / before each beam (n / -1: none).
    idx = np.where(valid, np.arange(n), n)
    nxt = np.minimum.accumulate(idx[::-1])[::-1]
    prv = np.maximum.accumulate(np.where(valid, np.arange(n), -1))
    arms = np.array([c.arms for c in corners], dtype=float)  # (K, arm, inner / outer, xy)
    bearing = np.arctan2(arms[..., 1], arms[..., 0])  # (K, 2, 2)
    angles = np.asarray(scan.angles, dtype=float)
    step = (angles[-1] - angles[0]) / max(n - 1, 1)

    def beam(a):
        """Nearest beam of each bearing (an arm's ends lie on rays of its samples)."""
        if step != 0.0:  # evenly spaced beams (a LaserScan's): one division
            k = np.clip(np.rint(np.remainder(a - angles[0], math.copysign(2.0 * math.pi, step))
                                / step).astype(np.int64), 0, n - 1)
            if np.all(np.abs(np.remainder(angles[k] - a + math.pi, 2.0 * math.pi) - math.pi)
                      <= 0.5 * abs(step) + 1e-9):
                return k
        return np.abs(np.remainder(a[..., None] - angles + math.pi, 2.0 * math.pi)
                      - math.pi).argmin(axis=-1)

    outer, inner = beam(bearing[..., 1]), beam(bearing[..., 0])  # (K, 2)
    up = outer >= inner  # the arm runs toward higher beam indices
    beyond = np.where(up, nxt[np.minimum(outer + 1, n - 1)], prv[np.maximum(outer - 1, 0)])
    beyond = np.where(up & (outer + 1 >= n), n, np.where(~up & (outer < 1), -1, beyond))
    found = (beyond >= 0) & (beyond < n)
    b = np.clip(beyond, 0, n - 1)
    # The arm's line (through its two ends) met by the ray of beam b: t = rho / (n . u).
    d = arms[..., 1, :] - arms[..., 0, :]
    nx, ny = -d[..., 1], d[..., 0]
    rho = nx * arms[..., 0, 0] + ny * arms[..., 0, 1]
    with np.errstate(divide='ignore', invalid='ignore'):
        t = rho / (nx * np.asarray(scan.cos)[b] + ny * np.asarray(scan.sin)[b])
    t = np.where(t > 0.0, t, np.inf)  # a ray that never meets the line
    r = np.asarray(scan.ranges, dtype=float)[b]
    own = label[outer]
    code = np.where(~found, 3, np.where((label[b] == own) & (own >= 0), 0,
                                        np.where(r < t, 1, 2)))
    return [tuple(ARM_ENDS[i] for i in row) for row in code.tolist()]


__all__ = ['ARM_ENDS', 'arm_ends']
