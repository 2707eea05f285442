"""Sonar map tools: ``landmark_nav build-sonar-map`` and ``landmark_nav rasterize-map``.

* :func:`build_sonar_map` -- occupancy grid from the sonar readings at known poses
  (section 2.2), saved as map_server YAML + PGM.
* :func:`rasterize_map` -- the simulator's world of a bag or a scenario as a map_server map.

The offline localization evaluation (``evaluate-localization``) lives in
:mod:`landmark_nav.evaluation.localization_bags`. Bad input raises
:class:`~landmark_nav.bag.BagError` or ``ValueError`` with a one-line message.
"""

import math
from pathlib import Path
from typing import Any, Dict, Optional

from landmark_nav.bag import BagReader
from landmark_nav.conversions import stamp_to_ns
from landmark_nav.evaluation.bags import read_track
from landmark_nav.evaluation.localization_bags import sonar_topics
from landmark_nav.geometry import interpolate_pose
from landmark_nav.hardware import SONAR_MOUNTS
from landmark_nav.localization.grid import GridMap, rasterize_world, save_map_yaml
from landmark_nav.localization.sonar_model import build_sonar_map as map_from_sonar
from landmark_nav.localization.tracking import sonar_reading
from landmark_nav.sim.record import load_ground_truth
from landmark_nav.sim.scenarios import build_scenario, scenario_names
from landmark_nav.sim.world import World
import numpy as np


def _map_summary(grid: GridMap, yaml_path: Path, image: Path) -> Dict[str, Any]:
    states = grid.cell_states
    return {'yaml': str(yaml_path), 'image': str(image), 'width': grid.shape[1],
            'height': grid.shape[0], 'resolution': grid.resolution,
            'origin': list(grid.origin), 'occupied': int((states == 1).sum()),
            'free': int((states == 0).sum()), 'unknown': int((states == 2).sum())}


def _check_out(out: Any) -> Path:
    out = Path(out)
    if out.suffix.lower() not in ('.yaml', '.yml'):
        raise ValueError(f'map output must be a .yaml file, got {out}')
    out.parent.mkdir(parents=True, exist_ok=True)
    return out


def build_sonar_map(bag: Any, poses_topic: str = '/ground_truth/odom', out: Any = 'map.yaml',
                    resolution: float = 0.1) -> Dict[str, Any]:
    """Build an occupancy grid from a bag's sonar readings at known poses; write YAML + PGM.

    The poses (nav_msgs/Odometry on ``poses_topic``, interpolated to the sonar stamps) and
    the readings go through the core's sonar mapping
    (:func:`landmark_nav.localization.sonar_model.build_sonar_map`, log-odds with the
    sonar model of eqs. 10-11). Unexplored gaps stay unknown: localize on such a map with
    unknown cells treated as free (the evaluation does so for map files with unknown
    cells). Mounts from ``ground_truth.yaml`` if present, else the Pioneer 2-DX ring.

    Returns:
        Summary: paths, size, resolution, origin, cell counts, cycles used.

    Raises:
        BagError: missing or unreadable bag, missing poses topic.
        ValueError: no sonar, no poses, bad resolution or output name.
    """
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise ValueError(f'resolution must be > 0, got {resolution}')
    out = _check_out(out)
    bag = Path(bag)
    with BagReader(bag) as reader:
        infos = reader.topics()
        try:
            meta: Optional[dict] = load_ground_truth(bag)
        except ValueError:
            meta = None
        topics = sonar_topics(bag, list(infos), meta)
        if poses_topic not in infos:
            raise ValueError(f'{bag} has no {poses_topic} topic')
        t_pose, poses = read_track(reader, poses_topic)
        column = {t: j for j, t in enumerate(topics)}
        cycles: Dict[int, np.ndarray] = {}
        for name, _, msg in reader.decoded(topics):
            s = stamp_to_ns(msg.header.stamp)
            row = cycles.setdefault(s, np.full(len(topics), np.nan))
            row[column[name]] = sonar_reading(msg.range, msg.min_range, msg.max_range)[0]
    if t_pose.size == 0:
        raise ValueError(f'{bag}: no messages on {poses_topic}')
    stamps = np.array(sorted(s for s in cycles if t_pose[0] <= s <= t_pose[-1]),
                      dtype=np.int64)
    if stamps.size == 0:
        raise ValueError(f'{bag}: no sonar cycle within the time span of {poses_topic}')
    at = interpolate_pose(stamps.astype(float), t_pose.astype(float), poses)
    ranges = np.array([cycles[int(s)] for s in stamps])
    mounts = np.asarray(((meta or {}).get('sonar') or {}).get('mounts', SONAR_MOUNTS),
                        dtype=float).reshape(-1, 3)[:len(topics)]
    grid = map_from_sonar(at, ranges, mounts, resolution)
    image = save_map_yaml(grid, out)
    summary = _map_summary(grid, out, image)
    summary.update(bag=str(bag), poses_topic=poses_topic, cycles=int(stamps.size))
    return summary


def rasterize_map(bag_or_scenario: Any, out: Any, resolution: float = 0.1) -> Dict[str, Any]:
    """Rasterise the simulator's world (of a bag's ground_truth.yaml or a scenario) to a map.

    Args:
        bag_or_scenario: bag directory with ``ground_truth.yaml``, or a scenario name
            (``office``, ``hallway``, ``calibration``).
        out: map YAML to write (the PGM goes beside it).
        resolution: cell size [m].

    Returns:
        Summary: paths, size, resolution, origin, cell counts, source.

    Raises:
        ValueError: neither a simulator bag nor a scenario, bad resolution or output name.
    """
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise ValueError(f'resolution must be > 0, got {resolution}')
    src = str(bag_or_scenario)
    if Path(src).is_dir():
        world = World.from_dict(load_ground_truth(src)['world'])
    elif src in scenario_names():
        world = build_scenario(src).world
    else:
        raise ValueError(f'{src} is neither a bag directory with ground_truth.yaml nor a '
                         f'scenario ({", ".join(scenario_names())})')
    out = _check_out(out)
    grid = rasterize_world(world, resolution)
    image = save_map_yaml(grid, out)
    summary = _map_summary(grid, out, image)
    summary['source'] = src
    return summary


def format_map_summary(summary: Dict[str, Any]) -> str:
    """Return one line describing a map written by :func:`build_sonar_map` / ``rasterize_map``."""
    ox, oy = summary['origin'][:2]
    return (f'wrote {summary["yaml"]} + {Path(summary["image"]).name}: {summary["width"]} x '
            f'{summary["height"]} cells of {summary["resolution"]} m, origin ({ox:.3f}, '
            f'{oy:.3f}); {summary["occupied"]} occupied, {summary["free"]} free, '
            f'{summary["unknown"]} unknown')
