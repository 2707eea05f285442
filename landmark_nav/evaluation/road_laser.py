"""Tilted-laser terrain classification against the park-road simulator's exact truth.

For one road kind (Table 3: asphalt 4.9 m, gravel 4.0 m) the robot drives along the road
with a lateral offset and heading drawn per scan; every scan is ray-cast on the height field
(:mod:`landmark_nav.sim.park_road`) and classified (:func:`classify_scan`). Scores:

* per-reading accuracy: readings with a true class (a ground or object hit) whose class
  equals the truth (traversable: road, shoulder, horse track; not: grass, kerb faces,
  objects);
* road width: the traversable segment under the robot (:meth:`TerrainScan.best_segment`),
  its end points projected on the true road normal (the world y axis), as Table 3's laser
  column; a scan without a segment under the robot is a failure.
"""

from dataclasses import dataclass
import math
from typing import Optional

from landmark_nav.road.terrain import classify_scan, LaserMount, TerrainParams
from landmark_nav.sim.park_road import cast_scan, ParkRoad
import numpy as np

#: Beams of a SICK LMS at 0.5 degree over 180 degrees.
ANGLES = np.radians(np.arange(-90.0, 90.25, 0.5))


@dataclass(frozen=True)
class LaserRoadScore:
    """Scores of one road kind."""

    kind: str
    true_width: float
    scans: int
    accuracy: float
    accuracy_min: float
    width_mean: float
    width_std: float
    widths: int
    failures: int


def evaluate_laser_road(kind: str, scans: int = 1000, seed: int = 0,
                        mount: LaserMount = LaserMount(),
                        params: TerrainParams = TerrainParams(),
                        lateral_std: float = 0.3, heading_std: float = 0.05,
                        road: Optional[ParkRoad] = None) -> LaserRoadScore:
    """Score the classifier on ``scans`` scans of one road kind."""
    road = ParkRoad.of_kind(kind, seed=seed) if road is None else road
    rng = np.random.default_rng(seed)
    acc, widths, failures = [], [], 0
    for i in range(scans):
        yaw = float(rng.normal(0.0, heading_std))
        pose = (0.05 * i, float(rng.normal(0.0, lateral_std)), yaw)
        sc = cast_scan(road, pose, mount, ANGLES, rng=rng)
        ts = classify_scan(sc.ranges, sc.angles, mount, params)
        known = sc.truth > 0
        acc.append(float(np.mean(ts.classes[known] == sc.truth[known])))
        seg = ts.best_segment()
        if seg is None or not seg.lateral_extent()[0] <= 0.0 <= seg.lateral_extent()[1]:
            failures += 1
            continue
        c, s = math.cos(yaw), math.sin(yaw)
        ys = [s * p[0] + c * p[1] for p in (seg.start, seg.end)]   # world y offsets
        widths.append(abs(ys[1] - ys[0]))
    w = np.array(widths)
    return LaserRoadScore(kind, road.width, scans, float(np.mean(acc)), float(np.min(acc)),
                          float(w.mean()) if w.size else math.nan,
                          float(w.std()) if w.size else math.nan, int(w.size), failures)
