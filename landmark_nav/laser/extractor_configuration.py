"""The laser feature nodes' configuration: ``corner_extractor`` and ``line_extractor``.

One description of each node's parameters serves the node (which declares them with these
defaults, descriptions and limits: :class:`landmark_nav.nodes.scan_features.ScanFeatureNode`)
and ``landmark_nav evaluate-features --params-file / --set``, so that both run one
configuration: :func:`parameters` lists a node's parameters with their defaults and
:func:`extractor_configuration` turns parameter values into what the node runs (the
segmentation's settings and the extractor's :class:`~.corners.CornerParams` or
:class:`~.lines.LineParams`), checking names, types, limits and choices as the node does.
:class:`ScanSegmenter` is what the node does to each scan before its extractor: the range
noise (tracked with ``sigma_r_from_data``) and the segmentation.
"""

from dataclasses import dataclass, replace
from typing import Any, Dict, List, Mapping, Optional, Tuple, Union

from landmark_nav.laser.corner_detection.params import CORNER_PARAMETERS, CornerParams
from landmark_nav.laser.lines import LINE_PARAMETERS, LineParams
from landmark_nav.laser.range_noise import RangeNoiseTracker
from landmark_nav.laser.segmentation import Cluster, segment_scan
from landmark_nav.parameter_tables import (dataclass_parameters, field_value,
                                           name_parameters, Parameter, parameter_values)
import numpy as np

#: The parameters every laser feature node declares besides its extractor's.
SCAN_PARAMETERS = {
    'segmentation.incidence_deg': Parameter(
        10.0, 'smallest surface incidence angle still treated as continuous [deg] '
        '(adaptive breakpoint threshold)', (1.0, 89.0)),
    'segmentation.min_points': Parameter(5, 'smallest cluster kept [points]', (1, 10000)),
    'max_beams': Parameter(
        20000, 'scans with more beams are dropped with a warning (real 2-D lasers have up '
        'to a few thousand)', (1, 100000000)),
    'sigma_r_from_data': Parameter(
        False, 'estimate the range noise from the scans (local line fits, range step / '
        'sqrt(12)); sigma_r is then its lower bound'),
    'sigma_r_scans': Parameter(50, 'scans the range noise is estimated over (the latest)',
                               (1, 100000)),
}
#: Node name -> (its extractor's parameter dataclass, that dataclass's parameter table).
EXTRACTORS = {'corner_extractor': (CornerParams, CORNER_PARAMETERS),
              'line_extractor': (LineParams, LINE_PARAMETERS)}


def parameters(node: str) -> Dict[str, Parameter]:
    """Return every parameter of ``node`` (a key of :data:`EXTRACTORS`) with its default."""
    cls, table = EXTRACTORS[node]
    return {**dataclass_parameters(table, cls()), **SCAN_PARAMETERS}


@dataclass(frozen=True)
class ExtractorConfiguration:
    """What a laser feature node's parameters configure (:func:`extractor_configuration`).

    Attributes:
        node: ``'corner_extractor'`` or ``'line_extractor'``.
        params: The extractor's parameters (``sigma_r``: the range noise, the lower bound
            of the estimate with ``sigma_r_from_data``).
        incidence_deg: The segmentation's breakpoint incidence angle [deg].
        min_points: The segmentation's smallest cluster [points].
        max_beams: Scans with more beams are dropped.
        sigma_r_from_data: Estimate the range noise from the latest ``sigma_r_scans`` scans.
        sigma_r_scans: Scans of that estimate.
        values: Every parameter's value, by name.
    """

    node: str
    params: Union[CornerParams, LineParams]
    incidence_deg: float
    min_points: int
    max_beams: int
    sigma_r_from_data: bool
    sigma_r_scans: int
    values: Dict[str, Any]


def extractor_configuration(node: str, overrides: Optional[Mapping[str, Any]] = None
                            ) -> ExtractorConfiguration:
    """Return ``node``'s configuration: its defaults with ``overrides`` on top.

    Args:
        node: ``'corner_extractor'`` or ``'line_extractor'``.
        overrides: Parameter values by name (as a parameter file or ``-p`` gives them).

    Raises:
        ValueError: An unknown name (naming the nearest declared one), a value of the
            wrong type, out of its limits or not a choice, or values the extractor refuses
            together (one line naming the parameter).
    """
    cls, table = EXTRACTORS[node]
    values = parameter_values(node, parameters(node), overrides)
    fields = {name: field_value(p, values[name])
              for name, p in dataclass_parameters(table, cls()).items()}
    try:
        params = cls(**fields)
    except (TypeError, ValueError) as err:
        raise ValueError(f'{node}: {name_parameters(str(err), {cls.__name__: ""})}') from None
    return ExtractorConfiguration(
        node=node, params=params, incidence_deg=values['segmentation.incidence_deg'],
        min_points=values['segmentation.min_points'], max_beams=values['max_beams'],
        sigma_r_from_data=values['sigma_r_from_data'], sigma_r_scans=values['sigma_r_scans'],
        values=values)


class ScanSegmenter:
    """A feature node's work on each scan before its extractor: range noise, segmentation.

    The range noise is the configuration's ``sigma_r``, or with ``sigma_r_from_data`` the
    estimate of the latest ``sigma_r_scans`` scans with ``sigma_r`` as its lower bound
    (:class:`~landmark_nav.laser.range_noise.RangeNoiseTracker`); the segmentation uses it
    with ``segmentation.incidence_deg`` and ``segmentation.min_points``.
    """

    def __init__(self, incidence_deg: float, min_points: int, sigma_r: float,
                 from_data: bool = False, noise_scans: int = 50) -> None:
        """Segment with these settings; ``sigma_r``: the noise (its lower bound if tracked)."""
        self.incidence_deg = incidence_deg
        self.min_points = min_points
        self.sigma_r = sigma_r  # the range noise of the latest scan
        self.range_step = (0.0, 1.0)  # the readings' rounding (step, share) in that noise
        self.noise = RangeNoiseTracker(noise_scans, stated=sigma_r) if from_data else None

    @classmethod
    def of(cls, config: ExtractorConfiguration) -> 'ScanSegmenter':
        """Return the segmenter of a node's configuration."""
        return cls(config.incidence_deg, config.min_points, config.params.sigma_r,
                   config.sigma_r_from_data, config.sigma_r_scans)

    def key(self) -> Tuple[float, int, float]:
        """Return the settings of the latest scan's segmentation (equal: same clusters)."""
        return (self.incidence_deg, self.min_points, self.sigma_r)

    def track(self, ranges: np.ndarray, angles: np.ndarray, valid: np.ndarray) -> float:
        """Take one scan into the range noise; return the noise of this scan [m]."""
        if self.noise is not None:
            estimate = self.noise.add(ranges, angles, valid)
            self.sigma_r = estimate.sigma_r
            self.range_step = (estimate.step, estimate.step_share)
        return self.sigma_r

    def segment(self, ranges: np.ndarray, angles: np.ndarray, valid: np.ndarray,
                angle_increment: float) -> List[Cluster]:
        """Return the clusters of a scan taken in by :meth:`track`."""
        return segment_scan(ranges, angles, valid, angle_increment, self.incidence_deg,
                            self.sigma_r, self.min_points)

    def at_scan_noise(self, params):
        """Return extractor ``params`` with ``sigma_r`` the range noise of the latest scan.

        Line parameters also get the readings' rounding found with it (``range_step``,
        ``range_step_share``: the gates' noise model) when the noise is estimated.
        """
        if isinstance(params, LineParams) and self.noise is not None:
            step, share = self.range_step
            if (params.sigma_r, params.range_step, params.range_step_share) != (
                    self.sigma_r, step, share):
                return replace(params, sigma_r=self.sigma_r, range_step=step,
                               range_step_share=share)
            return params
        if params.sigma_r == self.sigma_r:
            return params
        return replace(params, sigma_r=self.sigma_r)


__all__ = ['EXTRACTORS', 'extractor_configuration', 'ExtractorConfiguration', 'parameters',
           'SCAN_PARAMETERS', 'ScanSegmenter']
