"""Loop closure of the graph back end: place recognition and its geometric verification.

A loop is proposed and verified in the laser frame of an old keyframe (the *anchor*), with
the keyframes' scans placed by the graph's estimates:

1. **Search** (:func:`.correlative_matching.correlative_match`): the current keyframe's
   scan against the submap (the chain of old keyframes around the one nearest the current
   estimate, placed by the graph), over every pose
   of a window (coarse to fine) whose half widths are ``window_sigmas`` standard deviations
   of the current keyframe's marginal (the graph's uncertainty: the window grows as the
   pose drifts). The search is exhaustive over the window: the place found does not depend
   on where in the window the estimate lies.
2. **Refinement**: point-to-line ICP (:func:`.scan_matching.point_to_line_icp`) from the
   best pose of the search onto the submap's points.
3. **Verification**, three tests, any failing refuses the loop (the reason is counted):

   * ``score`` / ``fit``: the search's mean likelihood at least ``min_score``; after ICP, at
     least ``min_overlap`` of the scan's points within ``overlap_distance`` of a submap
     point and an RMS residual at most ``max_rms``;
   * ``ambiguous``: the best score elsewhere in the window (``distinct`` away, on the
     coarse search, both scores of the coarse search) at most ``max_ambiguity`` times the
     best: a scan that fits two places (a corridor's length, two alike rooms in the
     window) does not say which;
   * ``free_space``: an independent second check on other data, the *trail* (the scans of
     the keyframes before the current one, placed by the graph relative to it) moved by the
     loop's transform: at most ``max_contradiction`` of each trail scan's points may fall
     in cells the submap's own beams passed through (seen free) away from any submap
     point (per scan: the scans that see what tells two places apart are few). A wrong
     place that looks alike from one pose contradicts the map from the poses before it;
     points in space the submap never saw are neutral (the trail may come from an area
     not mapped yet).

The free-space check scores a hypothesis against data it was not chosen from, the idea of
Olson's validation of loop hypotheses by their mutual consistency (Olson, "Recognizing
places using spectrally clustered local matches", RAS 2009), here with the trail's scans.
"""

from dataclasses import dataclass, field
import math
from typing import Dict, Optional

from landmark_nav.slam.correlative_matching import coarse_to_fine, CorrelativeMatch
from landmark_nav.slam.scan_matching import IcpResult, point_to_line_icp
import numpy as np

#: Reasons a proposed loop is refused (counted in :attr:`LoopCounts.refused`).
REFUSALS = ('score', 'fit', 'ambiguous', 'free_space')


@dataclass(frozen=True)
class LoopParams:
    """Parameters of loop closure (module docstring).

    Attributes:
        min_separation_m: Path travelled between an old keyframe and the current one before
            the old one is a loop candidate [m].
        neighbourhood_m: The old keyframe nearest the current estimate within the search
            window plus this is the anchor [m].
        submap_keyframes: Keyframes in the submap: the anchor's stretch of the chain
            (``submap_keyframes // 2`` either side).
        trail_keyframes: Keyframes before the current one in the free-space check's trail.
        window_sigmas: Window half widths in marginal standard deviations.
        window_xy: ``(min, max)`` translation half width [m].
        window_yaw: ``(min, max)`` heading half width [rad].
        step_xy: Search step in translation [m] (the fine search's).
        step_yaw: Search step in heading [rad] (likewise).
        coarse: The coarse search's field cell, field std and steps are this many times
            the fine ones.
        field_resolution: Likelihood field cell [m].
        field_sigma: Likelihood field std [m].
        max_points: The scan is thinned to at most this many points for the search.
        min_score: Least mean likelihood of the search's best pose.
        min_overlap: Least share of the scan's points near a submap point after ICP.
        overlap_distance: "Near" [m].
        max_rms: Largest ICP RMS residual [m].
        max_ambiguity: Largest ratio of the best score elsewhere to the best.
        distinct: ``(metres, radians)`` a pose this far from the best is elsewhere.
        free_margin: Free cells within this of a submap point are not contradictions [m].
        max_contradiction: Largest share of a trail scan's points in free space.
        min_trail_points: Fewer trail points than this: the check has no data and refuses.
    """

    min_separation_m: float = 10.0
    neighbourhood_m: float = 3.0
    submap_keyframes: int = 12
    trail_keyframes: int = 10
    window_sigmas: float = 3.0
    window_xy: tuple = (0.5, 6.0)
    window_yaw: tuple = (math.radians(5.0), math.radians(30.0))
    step_xy: float = 0.1
    step_yaw: float = math.radians(1.0)
    coarse: int = 4
    field_resolution: float = 0.05
    field_sigma: float = 0.1
    max_points: int = 200
    min_score: float = 0.5
    min_overlap: float = 0.6
    overlap_distance: float = 0.15
    max_rms: float = 0.08
    max_ambiguity: float = 0.9
    distinct: tuple = (1.0, math.radians(20.0))
    free_margin: float = 0.3
    max_contradiction: float = 0.05
    min_trail_points: int = 50

    def __post_init__(self) -> None:
        """Validate the values (one line naming the bad one)."""
        for name in ('min_separation_m', 'neighbourhood_m', 'window_sigmas', 'step_xy',
                     'step_yaw', 'field_resolution', 'field_sigma', 'overlap_distance',
                     'max_rms', 'free_margin'):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f'LoopParams.{name} must be a finite number > 0, got {v!r}')
        for name in ('min_score', 'min_overlap', 'max_ambiguity', 'max_contradiction'):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v <= 1.0):
                raise ValueError(f'LoopParams.{name} must be in [0, 1], got {v!r}')
        for name in ('window_xy', 'window_yaw'):
            lo, hi = getattr(self, name)
            if not (0.0 < lo <= hi):
                raise ValueError(f'LoopParams.{name} must be (min, max) with 0 < min <= max, '
                                 f'got {getattr(self, name)!r}')


@dataclass
class LoopCounts:
    """Loops proposed, accepted and refused (by reason)."""

    proposed: int = 0
    accepted: int = 0
    refused: Dict[str, int] = field(default_factory=lambda: dict.fromkeys(REFUSALS, 0))

    def refuse(self, reason: str) -> None:
        """Count one refusal."""
        self.refused[reason] = self.refused.get(reason, 0) + 1


@dataclass(frozen=True)
class LoopResult:
    """A verified (or refused) loop in the anchor's laser frame.

    Attributes:
        accepted: Whether all tests passed.
        reason: The first failed test (:data:`REFUSALS`), or '' when accepted.
        pose: (3,) the current laser pose in the anchor's laser frame (ICP's when it ran).
        search: The fine correlative search's result.
        fit: ICP's result (None when it failed or did not run).
        overlap: Share of the scan's points near a submap point after ICP.
        contradiction: The largest share of a trail scan's points in the submap's free
            space (nan: not run).
    """

    accepted: bool
    reason: str
    pose: np.ndarray
    search: Optional[CorrelativeMatch]
    fit: Optional[IcpResult]
    overlap: float = math.nan
    contradiction: float = math.nan


def thin(points: np.ndarray, most: int) -> np.ndarray:
    """Return at most ``most`` of the points, evenly spaced in the scan's order."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(p) <= most:
        return p
    return p[np.linspace(0, len(p) - 1, most).round().astype(int)]


def free_cells(origins: np.ndarray, hits: list, resolution: float,
               lo: np.ndarray, shape: tuple) -> np.ndarray:
    """Return the boolean grid of cells the beams passed through before their hits.

    Args:
        origins: (K, 2) laser positions of the submap's keyframes (anchor frame) [m].
        hits: K arrays (N_k, 2) of those scans' points (anchor frame) [m].
        resolution: Cell size [m].
        lo: (2,) position of cell (0, 0) [m].
        shape: Grid shape.
    """
    free = np.zeros(shape, dtype=bool)
    for o, h in zip(origins, hits):
        d = h - o
        length = np.hypot(d[:, 0], d[:, 1])
        n = int(np.ceil(length.max() / resolution)) if len(length) else 0
        if n == 0:
            continue
        s = np.arange(n) * resolution
        frac = s[None, :] / np.maximum(length[:, None], 1e-9)
        keep = s[None, :] < length[:, None] - resolution  # up to one cell short of the hit
        pts = o + frac[..., None] * d[:, None, :]
        ij = np.floor((pts[keep] - lo) / resolution).astype(np.int64)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < shape[0]) & (ij[:, 1] >= 0) & (ij[:, 1] < shape[1])
        free[ij[ok, 0], ij[ok, 1]] = True
    return free


class FreeSpace:
    """The submap's seen-free space, built once per loop hypothesis (``free_space`` test).

    A point contradicts the submap when its cell was passed through by a submap beam and no
    submap point lies within ``margin`` of it (module docstring). Points outside the
    submap's grid count as not contradicting.

    Args:
        submap: (M, 2) the submap's points (anchor frame) [m].
        origins: (K, 2) the submap keyframes' laser positions (anchor frame) [m].
        hits: K arrays (N_k, 2) of those scans' points (anchor frame) [m].
        resolution: Cell size [m].
        margin: Free cells within this of a submap point are not contradictions [m].
    """

    def __init__(self, submap: np.ndarray, origins: np.ndarray, hits: list,
                 resolution: float, margin: float) -> None:
        origins = np.asarray(origins, dtype=float).reshape(-1, 2)
        self.lo = np.minimum(submap.min(axis=0), origins.min(axis=0)) - 1.0
        hi = np.maximum(submap.max(axis=0), origins.max(axis=0)) + 1.0
        self.resolution = float(resolution)
        self.margin = float(margin)
        self.shape = tuple((np.ceil((hi - self.lo) / resolution) + 1).astype(int))
        self.free = free_cells(origins, hits, resolution, self.lo, self.shape)
        from scipy.spatial import cKDTree  # on first use: scipy.spatial costs ~0.5 CPU-s
        self.tree = cKDTree(submap)

    def share(self, points: np.ndarray) -> float:
        """Return the share of ``points`` (anchor frame) that contradict the submap."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(pts) == 0:
            return 0.0
        ij = np.floor((pts - self.lo) / self.resolution).astype(np.int64)
        ok = ((ij[:, 0] >= 0) & (ij[:, 0] < self.shape[0]) & (ij[:, 1] >= 0)
              & (ij[:, 1] < self.shape[1]))
        in_free = np.zeros(len(pts), dtype=bool)
        in_free[ok] = self.free[ij[ok, 0], ij[ok, 1]]
        if in_free.any():
            d, _ = self.tree.query(pts[in_free])
            in_free[np.flatnonzero(in_free)[d <= self.margin]] = False
        return float(in_free.mean())


def contradiction_share(trail: np.ndarray, submap: np.ndarray, origins: np.ndarray,
                        hits: list, resolution: float, margin: float) -> float:
    """Return the share of ``trail`` points in the submap's seen-free space (one use).

    :class:`FreeSpace` keeps the grid for several trail scans.
    """
    return FreeSpace(submap, origins, hits, resolution, margin).share(trail)


def verify_loop(scan: np.ndarray, submap: np.ndarray, guess: np.ndarray, window_xy: float,
                window_yaw: float, params: LoopParams, trail: Optional[np.ndarray] = None,
                origins: Optional[np.ndarray] = None, hits: Optional[list] = None,
                check_ambiguity: bool = True, check_free_space: bool = True) -> LoopResult:
    """Search, refine and verify a loop (module docstring).

    Args:
        scan: (N, 2) the current keyframe's scan in its laser frame [m].
        submap: (M, 2) the submap's points in the anchor's laser frame [m].
        guess: (3,) the current laser pose in the anchor's laser frame by the graph.
        window_xy: Search half width in translation [m].
        window_yaw: Search half width in heading [rad].
        params: The parameters.
        trail: The trail's scans, (T_i, 2) points each, in the current laser frame
            (free-space check).
        origins: (K, 2) the submap keyframes' laser positions in the anchor frame.
        hits: Their scans' points in the anchor frame (K arrays).
        check_ambiguity: Run the ambiguity test (off: a naive matcher, for comparison).
        check_free_space: Run the free-space test (off: likewise).

    Returns:
        The result; ``accepted`` only when every test run passed.
    """
    guess = np.asarray(guess, dtype=float)
    thinned = thin(scan, params.max_points)
    coarse, fine = coarse_to_fine(submap, thinned, guess, window_xy, window_yaw,
                                  params.field_resolution, params.field_sigma, params.step_xy,
                                  params.step_yaw, params.coarse, params.distinct)
    found = fine
    ambiguity = coarse.second_score / max(coarse.score, 1e-12)
    if found.score < params.min_score:
        return LoopResult(False, 'score', found.pose, found, None)
    fit = point_to_line_icp(scan, submap, found.pose, gates=(0.3, 0.15), iterations=15)
    if fit is None or not np.all(np.isfinite(fit.pose)):
        return LoopResult(False, 'fit', found.pose, found, None)
    c, s = math.cos(fit.pose[2]), math.sin(fit.pose[2])
    moved = scan @ np.array([[c, s], [-s, c]]) + fit.pose[:2]
    from scipy.spatial import cKDTree  # on first use: scipy.spatial costs ~0.5 CPU-s
    d, _ = cKDTree(submap).query(moved)
    overlap = float(np.mean(d <= params.overlap_distance))
    if overlap < params.min_overlap or fit.rms > params.max_rms:
        return LoopResult(False, 'fit', fit.pose, found, fit, overlap)
    if check_ambiguity and ambiguity > params.max_ambiguity:
        return LoopResult(False, 'ambiguous', fit.pose, found, fit, overlap)
    share = math.nan
    if check_free_space:
        if not trail or sum(len(t) for t in trail) < params.min_trail_points or not hits:
            return LoopResult(False, 'free_space', fit.pose, found, fit, overlap)
        rot = np.array([[c, s], [-s, c]])
        space = FreeSpace(submap, origins, hits, params.field_resolution * 2,
                          params.free_margin)
        share = max(space.share(np.asarray(t) @ rot + fit.pose[:2]) for t in trail)
        if share > params.max_contradiction:
            return LoopResult(False, 'free_space', fit.pose, found, fit, overlap, share)
    return LoopResult(True, '', fit.pose, found, fit, overlap, share)


__all__ = ['contradiction_share', 'free_cells', 'FreeSpace', 'LoopCounts', 'LoopParams',
           'LoopResult', 'REFUSALS', 'thin', 'verify_loop']
