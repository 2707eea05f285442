"""Correlative scan-to-submap matching over a search window (place recognition).

Olson's real-time correlative scan matching (Olson, "Real-time correlative scan matching",
ICRA 2009): the submap's points are rasterised into a likelihood field, ``L(c) = exp(-d(c)^2
/ (2 sigma^2))`` with ``d(c)`` the distance of cell ``c`` to the nearest submap point
(Olson's eq. 6 with a Gaussian cost of the nearest point), and every pose of a regular
grid over the search window ``[x, y, yaw]`` is scored by the mean likelihood of the
scan's points moved by it. The search is exhaustive, so its result does not depend on
where in the window the estimate was (unlike ICP, which converges to the minimum nearest
its guess); the window's size is the caller's (the graph's uncertainty of the pose).

Besides the best pose, the search returns the best score among poses far from it
(``distinct`` in translation or heading): a second peak nearly as good says the scan fits
the submap in two places (a corridor's length, a repeated room), and the match cannot tell
them apart.
"""

from dataclasses import dataclass
import math
from typing import Tuple

import numpy as np


@dataclass(frozen=True)
class CorrelativeMatch:
    """The result of :func:`correlative_match`.

    Attributes:
        pose: (3,) best ``[x, y, yaw]`` moving the scan's points into the submap's frame.
        score: Its mean likelihood in [0, 1].
        second_score: Best score among poses at least ``distinct`` away from ``pose``
            (0 when there is none in the window).
        poses_scored: Number of poses evaluated.
    """

    pose: np.ndarray
    score: float
    second_score: float
    poses_scored: int


class LikelihoodField:
    """A submap's likelihood field on a grid (module docstring).

    Args:
        points: (N, 2) submap points [m].
        resolution: Cell size [m].
        sigma: Std of the Gaussian of the distance to the nearest point [m].
        margin: Free border around the points [m] (scan points beyond it score 0).
    """

    def __init__(self, points: np.ndarray, resolution: float = 0.05, sigma: float = 0.1,
                 margin: float = 1.0) -> None:
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(pts) == 0:
            raise ValueError('LikelihoodField: no submap points')
        if not (resolution > 0.0 and sigma > 0.0):
            raise ValueError(f'LikelihoodField: resolution and sigma must be > 0, got '
                             f'{resolution!r}, {sigma!r}')
        self.resolution = float(resolution)
        self.origin = pts.min(axis=0) - margin
        size = np.ceil((pts.max(axis=0) + margin - self.origin) / resolution).astype(int) + 1
        occupied = np.zeros((int(size[0]), int(size[1])), dtype=bool)
        ij = np.floor((pts - self.origin) / resolution).astype(int)
        occupied[ij[:, 0], ij[:, 1]] = True
        from scipy.ndimage import distance_transform_edt  # on first use, not at node start
        d = distance_transform_edt(~occupied) * resolution
        self.field = np.exp(-0.5 * (d / sigma) ** 2)
        self.field_flat = self.field.ravel()
        self.shape = self.field.shape

    def cells(self, points: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return the (N, 2) integer cells of points [m] and whether each is on the grid."""
        ij = np.floor((np.asarray(points, dtype=float) - self.origin)
                      / self.resolution).astype(np.int64)
        inside = ((ij[:, 0] >= 0) & (ij[:, 0] < self.shape[0]) & (ij[:, 1] >= 0)
                  & (ij[:, 1] < self.shape[1]))
        return ij, inside

    def score(self, points: np.ndarray) -> float:
        """Return the mean likelihood of points [m] (0 off the grid)."""
        ij, inside = self.cells(points)
        if len(ij) == 0:
            return 0.0
        return float(self.field[ij[inside, 0], ij[inside, 1]].sum() / len(ij))


def _rotated(points: np.ndarray, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return points @ np.array([[c, s], [-s, c]])


def correlative_match(field: LikelihoodField, points: np.ndarray, centre,
                      window_xy: float, window_yaw: float, step_xy: float = 0.1,
                      step_yaw: float = math.radians(1.0),
                      distinct: Tuple[float, float] = (1.0, math.radians(20.0))
                      ) -> CorrelativeMatch:
    """Search the window around ``centre`` for the pose that best fits ``points`` on ``field``.

    Every pose ``centre + [i step_xy, j step_xy, k step_yaw]`` with ``|i step_xy| <=
    window_xy`` (likewise ``j``) and ``|k step_yaw| <= window_yaw`` is scored by the mean
    likelihood of the points it moves (module docstring); translations are applied as
    cell offsets of the rotated points, so their step is rounded to whole cells.

    Args:
        field: The submap's likelihood field.
        points: (N, 2) scan points in the scan's frame [m].
        centre: (3,) window centre ``[x, y, yaw]`` in the submap's frame.
        window_xy: Half width of the translation window [m].
        window_yaw: Half width of the heading window [rad].
        step_xy: Translation step [m] (at least one cell).
        step_yaw: Heading step [rad].
        distinct: ``(metres, radians)``: a pose is another place when it is at least this
            far from the best in translation or in heading.

    Returns:
        The best pose, its score and the best score elsewhere.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    centre = np.asarray(centre, dtype=float)
    res = field.resolution
    cell_step = max(1, int(round(step_xy / res)))
    n_xy = int(math.floor(window_xy / (cell_step * res)))
    n_yaw = int(math.floor(window_yaw / step_yaw)) if step_yaw > 0 else 0
    offs = np.arange(-n_xy, n_xy + 1) * cell_step
    ox, oy = np.meshgrid(offs, offs, indexing='ij')
    ox, oy = ox.ravel(), oy.ravel()
    yaws = centre[2] + np.arange(-n_yaw, n_yaw + 1) * step_yaw
    scores = np.zeros((len(yaws), len(ox)))
    h, w = field.shape
    for k, yaw in enumerate(yaws):
        q = _rotated(p, float(yaw)) + centre[:2]
        ij, _ = field.cells(q)
        i = ij[:, 0][None, :] + ox[:, None]
        j = ij[:, 1][None, :] + oy[:, None]
        inside = (i >= 0) & (i < h) & (j >= 0) & (j < w)
        flat = np.where(inside, i * w + j, 0)
        scores[k] = np.where(inside, field.field_flat[flat], 0.0).sum(axis=1)
    scores /= max(len(p), 1)
    k, m = np.unravel_index(int(np.argmax(scores)), scores.shape)
    best = float(scores[k, m])
    dxy = np.hypot((ox - ox[m]) * res, (oy - oy[m]) * res)
    dyaw = np.abs(yaws - yaws[k])
    far = (dxy[None, :] >= distinct[0]) | (dyaw[:, None] >= distinct[1])
    second = float(scores[far].max()) if far.any() else 0.0
    pose = np.array([centre[0] + ox[m] * res, centre[1] + oy[m] * res, float(yaws[k])])
    return CorrelativeMatch(pose, best, second, int(scores.size))


def coarse_to_fine(submap: np.ndarray, points: np.ndarray, centre, window_xy: float,
                   window_yaw: float, resolution: float, sigma: float, step_xy: float,
                   step_yaw: float, coarse: int,
                   distinct: Tuple[float, float] = (1.0, math.radians(20.0))
                   ) -> Tuple[CorrelativeMatch, CorrelativeMatch]:
    """Return the coarse and the fine :func:`correlative_match` of ``points`` on ``submap``.

    Olson's multi-resolution search: the window on a field ``coarse`` times coarser (cell,
    std and steps), then one coarse step around its best on the fine field.
    """
    f = coarse
    first = correlative_match(LikelihoodField(submap, resolution * f, sigma * f), points,
                              centre, window_xy, window_yaw, step_xy * f, step_yaw * f,
                              distinct)
    fine = correlative_match(LikelihoodField(submap, resolution, sigma), points, first.pose,
                             step_xy * f, step_yaw * f, step_xy, step_yaw, distinct)
    return first, fine


__all__ = ['coarse_to_fine', 'correlative_match', 'CorrelativeMatch', 'LikelihoodField']
