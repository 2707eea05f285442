"""Thresholds of the terrain feature functions (§4.2): :class:`TerrainParams`.

Entry point: :mod:`landmark_nav.road.terrain`.
"""

from dataclasses import dataclass
import math


@dataclass(frozen=True)
class TerrainParams:
    """Thresholds of the feature functions (lengths in metres)."""

    window: float = 0.45
    roughness_max: float = 0.013
    step_max: float = 0.04
    height_max: float = 0.3
    split_rms: float = 0.008
    rough_ratio: float = 1.5
    rough_alpha: float = 0.05
    range_sigma: float = 0.005
    slope_max: float = 0.25
    curvature_max: float = 0.6
    min_width: float = 0.5
    gap_max: float = 0.15
    obstacle_height: float = 0.12
    obstacle_depth: float = 0.06
    min_points: int = 5

    def __post_init__(self) -> None:
        """Check the ranges."""
        for name in ('window', 'roughness_max', 'step_max', 'height_max', 'split_rms',
                     'range_sigma',
                     'slope_max', 'curvature_max', 'min_width', 'obstacle_height',
                     'obstacle_depth'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'terrain {name} must be > 0; got {value!r}')
        if not (math.isfinite(self.gap_max) and self.gap_max >= 0.0):
            raise ValueError(f'terrain gap_max must be >= 0; got {self.gap_max!r}')
        if not self.rough_ratio >= 1.0:
            raise ValueError(f'terrain rough_ratio must be >= 1; got {self.rough_ratio!r}')
        if self.min_points < 3:
            raise ValueError(f'terrain min_points must be >= 3; got {self.min_points!r}')


__all__ = ['TerrainParams']
