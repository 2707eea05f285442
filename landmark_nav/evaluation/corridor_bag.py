"""The corridor follower offline on a bag: ``landmark_nav evaluate-corridor``.

:func:`replay_corridor_bag` feeds a corridor bag's ``/camera/camera_info``, frames and
``/odom`` in log-time order to :class:`~landmark_nav.corridor.follower.CorridorTracker`,
the loop the ``corridor_follower`` node runs, and records every pose the node publishes
(after each frame that gives a measurement and after each odometry step once the filter
has started), so that the node replayed in lock step publishes the same poses
(``test/test_corridor_follower_node.py``). :func:`evaluate_corridor_bag` scores them
against ``/ground_truth/odom`` at their stamps: lateral and heading errors, RMS and worst,
over every pose except the first ``skip_poses`` (20: the filter's first 0.8 s at 5 frames
and 20 odometry steps per second), and writes ``corridor.json``.

Parameters: the node's configuration (:func:`follower_config`: its defaults, the parameter
files, the corridor width and height, centre line and camera mount of the bag's
``ground_truth.yaml``, then ``--set``); images from its ``image_topic`` (raw
``sensor_msgs/Image`` or, when the topic ends in ``/compressed``, JPEG).
"""

from dataclasses import dataclass
import json
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple

from landmark_nav.bag import BagReader
from landmark_nav.conversions import (camera_info_to_model, ConversionError,
                                      odometry_to_pose, stamp_to_ns)
from landmark_nav.corridor.configuration import follower_configuration
from landmark_nav.corridor.follower import CorridorTracker, FollowerConfig
from landmark_nav.geometry import wrap_angle
from landmark_nav.landmark_msgs import compressed_to_gray, image_to_gray
from landmark_nav.sim.record import load_ground_truth
import numpy as np

INFO_TOPIC = '/camera/camera_info'
ODOM_TOPIC = '/odom'
TRUTH_TOPIC = '/ground_truth/odom'
#: Poses left out at the start (the filter's first 0.8 s on a simulator recording).
SKIP_POSES = 20


@dataclass(frozen=True, eq=False)
class CorridorReplay:
    """The poses the follower publishes on a bag, and what its frames did.

    Attributes:
        stamps: (P,) stamps of the published poses [ns].
        poses: (P, 3) ``x, y, yaw`` in the corridor frame.
        frames: frames read.
        steps: per frame, :attr:`~landmark_nav.corridor.follower.FrameStep.status`.
    """

    stamps: np.ndarray
    poses: np.ndarray
    frames: int
    steps: List[str]


def follower_config(meta: Dict[str, Any], files: Optional[Mapping[str, Any]] = None,
                    settings: Optional[Mapping[str, Any]] = None) -> FollowerConfig:
    """Return the node's configuration with the geometry of ``ground_truth.yaml``.

    ``corridor_follower``'s defaults, then ``files`` (parameter values), then what the bag
    states (corridor width, height, centre line, camera mount), then ``settings``
    (:func:`landmark_nav.corridor.configuration.follower_configuration`).
    """
    corridor = meta.get('corridor') or {}
    stated = {name: cast(corridor[key]) for name, key, cast in (
        ('corridor_width', 'width', float), ('corridor_height', 'height', float),
        ('centre_line', 'centre_line', bool)) if key in corridor}
    if 'camera_mount' in meta:
        stated['camera_mount'] = [float(v) for v in meta['camera_mount']]
    return follower_configuration({**(files or {}), **stated, **(settings or {})}).follower


def replay_corridor_bag(bag: Any, config: Optional[FollowerConfig] = None) -> CorridorReplay:
    """Run the follower's estimation loop on a bag; return the poses it publishes."""
    bag = Path(bag)
    meta = load_ground_truth(bag)
    config = follower_config(meta) if config is None else config
    image_topic = meta.get('image_topic', '/camera/image_raw')
    decode = compressed_to_gray if image_topic.endswith('/compressed') else image_to_gray
    tracker = CorridorTracker(config)
    camera = None
    stamps: List[int] = []
    poses: List[List[float]] = []
    steps: List[str] = []

    def publish(stamp: int) -> None:
        stamps.append(stamp)
        poses.append(tracker.estimate()[0])

    with BagReader(bag) as reader:
        for topic, _, msg in reader.decoded([INFO_TOPIC, ODOM_TOPIC, image_topic]):
            if topic == INFO_TOPIC:
                try:
                    camera = camera_info_to_model(msg)
                except ConversionError:
                    pass
            elif topic == ODOM_TOPIC:
                pose = odometry_to_pose(msg)
                if tracker.odometry(pose.stamp_ns, pose.pose)[0] == 'predicted':
                    publish(pose.stamp_ns)
            else:
                stamp = stamp_to_ns(msg.header.stamp)
                try:
                    gray = decode(msg)
                except ConversionError:
                    steps.append('dropped')
                    continue
                step = tracker.frame(gray, camera, stamp)
                steps.append(step.status)
                if step.measured:
                    publish(stamp)
    return CorridorReplay(np.array(stamps, dtype=np.int64), np.array(poses, dtype=float),
                          len(steps), steps)


def read_truth(bag: Any) -> Dict[int, np.ndarray]:
    """Return ``/ground_truth/odom`` as ``{stamp_ns: (x, y, yaw)}``."""
    truth = {}
    with BagReader(bag) as reader:
        for _, _, msg in reader.decoded([TRUTH_TOPIC]):
            p = odometry_to_pose(msg)
            truth[p.stamp_ns] = np.asarray(p.pose, dtype=float)
    return truth


def pose_errors(replay: CorridorReplay, truth: Dict[int, np.ndarray]
                ) -> Tuple[np.ndarray, np.ndarray]:
    """Return lateral [m] and heading [deg] errors of every pose against the truth."""
    missing = [int(t) for t in replay.stamps if int(t) not in truth]
    if missing:
        raise ValueError(f'{len(missing)} poses without ground truth at their stamp '
                         f'(first {missing[0]} ns)')
    ref = np.array([truth[int(t)] for t in replay.stamps]).reshape(-1, 3)
    err_y = replay.poses[:, 1] - ref[:, 1] if len(ref) else np.zeros(0)
    err_th = np.degrees(wrap_angle(replay.poses[:, 2] - ref[:, 2])) if len(ref) else \
        np.zeros(0)
    return err_y, err_th


def evaluate_corridor_bag(bag: Any, out_dir: Any = None, skip_poses: int = SKIP_POSES,
                          files: Optional[Mapping[str, Any]] = None,
                          settings: Optional[Mapping[str, Any]] = None) -> Dict[str, Any]:
    """Score the follower's poses on a bag; write ``<out_dir>/corridor.json`` if given.

    ``files`` and ``settings``: ``corridor_follower`` parameter values under and over what
    the bag states (:func:`follower_config`).

    Returns:
        ``{'bag', 'frames', 'frames_measured', 'frames_lost', 'frames_rejected',
        'frames_dropped', 'poses', 'skip_poses', 'errors': {'lateral_rms_m',
        'lateral_max_m', 'heading_rms_deg', 'heading_max_deg'}}`` (maxima of the absolute
        errors).

    Raises:
        ValueError: no ground_truth.yaml, a pose without ground truth at its stamp, or no
            pose left after ``skip_poses``.
    """
    bag = Path(bag)
    replay = replay_corridor_bag(bag, follower_config(load_ground_truth(bag), files, settings))
    err_y, err_th = pose_errors(replay, read_truth(bag))
    err_y, err_th = err_y[skip_poses:], err_th[skip_poses:]
    if not err_y.size:
        raise ValueError(f'{bag}: no pose after the first {skip_poses} '
                         f'({len(replay.stamps)} published)')
    result = {
        'bag': str(bag), 'frames': replay.frames,
        'frames_measured': sum(s in ('started', 'accepted', 'rejected') for s in replay.steps),
        'frames_lost': replay.steps.count('lost'),
        'frames_rejected': replay.steps.count('rejected'),
        'frames_dropped': replay.steps.count('dropped'),
        'poses': int(len(replay.stamps)), 'skip_poses': int(skip_poses),
        'errors': {'lateral_rms_m': float(np.sqrt(np.mean(err_y ** 2))),
                   'lateral_max_m': float(np.max(np.abs(err_y))),
                   'heading_rms_deg': float(np.sqrt(np.mean(err_th ** 2))),
                   'heading_max_deg': float(np.max(np.abs(err_th)))}}
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / 'corridor.json').write_text(json.dumps(result, indent=2) + '\n')
    return result


def format_corridor_evaluation(result: Dict[str, Any]) -> str:
    """Return the printed summary of :func:`evaluate_corridor_bag`."""
    e = result['errors']
    return (f'{result["bag"]}: {result["frames"]} frames ({result["frames_lost"]} lost, '
            f'{result["frames_rejected"]} rejected by the gate, {result["frames_dropped"]} '
            f'dropped), {result["poses"]} poses, scored after the first '
            f'{result["skip_poses"]}\n'
            f'lateral {e["lateral_rms_m"] * 1000:.2f} mm RMS (worst '
            f'{e["lateral_max_m"] * 1000:.1f} mm), heading {e["heading_rms_deg"]:.2f} deg RMS '
            f'(worst {e["heading_max_deg"]:.2f} deg)')
