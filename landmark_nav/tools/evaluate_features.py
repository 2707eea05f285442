"""``landmark_nav evaluate-features <bag>``: score corner and line extractors per method.

Runs the extractors directly on the bag's scans (no DDS) and compares every scan with the
ground truth the simulator recorded beside the bag (see
:mod:`landmark_nav.evaluation.features` for the matching rules). Prints one table per
feature type and returns the figures as a dict.
"""

import json
from pathlib import Path
import time
from typing import Dict, Optional, Sequence

from landmark_nav.bag import BagReader
from landmark_nav.conversions import odometry_to_pose, scan_to_data
from landmark_nav.evaluation.features import (corner_truth, CornerScore, LineScore,
                                              score_corners, score_lines, wall_truth)
from landmark_nav.geometry import compose, interpolate_pose
from landmark_nav.laser.segmentation import segment_scan
from landmark_nav.sim.record import load_ground_truth
from landmark_nav.sim.world import World
import numpy as np

CORNER_METHODS = ('minus_cosine', 'sliding_window', 'split_merge')
LINE_METHODS = ('split_merge', 'alfa')


def _truth_track(bag):
    stamps, poses = [], []
    with BagReader(bag) as reader:
        for _, _, msg in reader.decoded(['/ground_truth/odom']):
            d = odometry_to_pose(msg)
            stamps.append(d.stamp_ns)
            poses.append(d.pose)
    if not stamps:
        raise ValueError(f'{bag} has no /ground_truth/odom messages')
    return np.asarray(stamps, dtype=np.int64), np.asarray(poses)


def evaluate_features(bag, corner_methods: Sequence[str] = CORNER_METHODS,
                      line_methods: Sequence[str] = LINE_METHODS,
                      sigma_r: Optional[float] = None, every: int = 1,
                      progress: bool = False) -> Dict[str, dict]:
    """Score every method on every ``every``-th scan of a simulator bag.

    Args:
        bag: rosbag2 directory recorded by ``landmark_nav simulate``.
        corner_methods: Corner detectors to run.
        line_methods: Line extractors to run.
        sigma_r: Range noise the extractors assume [m]; default: the simulated laser's.
        every: Use every n-th scan.
        progress: Show a progress bar.

    Returns:
        {'corners': {method: figures}, 'lines': {method: figures}, 'scans': n}.

    """
    from landmark_nav.laser.corners import CornerParams, detect_corners
    from landmark_nav.laser.lines import extract_lines, LineParams

    if every < 1:
        raise ValueError(f'every must be >= 1, got {every}')
    meta = load_ground_truth(bag)
    if not meta.get('laser'):
        raise ValueError(f'{bag} was recorded without a laser')
    world = World.from_dict(meta['world'])
    mount = np.asarray(meta['laser']['mount'], dtype=float)
    true_sigma = float(meta['laser']['sigma_range'])  # the simulated noise (for the bound)
    sigma = true_sigma if sigma_r is None else float(sigma_r)
    sigma_phi = float(meta['laser'].get('sigma_angle', 0.0))
    t_truth, truth = _truth_track(bag)
    t_rel = (t_truth - t_truth[0]).astype(float)
    corner_params = {m: CornerParams(method=m, sigma_r=sigma, sigma_phi=sigma_phi)
                     for m in corner_methods}
    line_params = {m: LineParams(method=m, sigma_r=sigma, sigma_phi=sigma_phi)
                   for m in line_methods}
    c_scores = {m: CornerScore() for m in corner_methods}
    l_scores = {m: LineScore() for m in line_methods}
    c_times = {m: [] for m in corner_methods}
    l_times = {m: [] for m in line_methods}
    with BagReader(bag) as reader:
        total = reader.topics()['/scan'].count
        messages = reader.decoded(['/scan'])
        if progress:
            from tqdm import tqdm
            messages = tqdm(messages, total=total, unit='scan', desc=Path(bag).name)
        n_used = 0
        for k, (_, _, msg) in enumerate(messages):
            if k % every:
                continue
            scan = scan_to_data(msg)
            t_end = scan.stamp_ns + len(scan.ranges) * scan.time_increment * 1e9
            if not (t_truth[0] <= scan.stamp_ns and t_end <= t_truth[-1]):
                continue

            def sensor_pose_at(stamps):
                rel = (np.asarray(stamps, dtype=np.int64) - t_truth[0]).astype(float)
                return compose(interpolate_pose(rel, t_rel, truth), mount)

            corners_true = corner_truth(world, sensor_pose_at, scan.stamp_ns, scan.angles,
                                        scan.time_increment)
            t_mid = scan.stamp_ns + 0.5 * len(scan.ranges) * scan.time_increment * 1e9
            walls_true = wall_truth(world, sensor_pose_at(np.array([t_mid]))[0], scan.angles,
                                    scan.range_max, sigma_r=true_sigma, sigma_phi=sigma_phi)
            t0 = time.perf_counter()
            clusters = segment_scan(scan.ranges, scan.angles, scan.valid,
                                    scan.angle_increment, sigma_r=sigma)
            t_seg = time.perf_counter() - t0
            for m, params in corner_params.items():
                t0 = time.perf_counter()
                corners = detect_corners(clusters, params)
                c_times[m].append(t_seg + time.perf_counter() - t0)
                xy = np.array([c.position for c in corners]).reshape(-1, 2)
                score_corners(c_scores[m], xy, corners_true)
            for m, params in line_params.items():
                t0 = time.perf_counter()
                lines = extract_lines(clusters, params)
                l_times[m].append(t_seg + time.perf_counter() - t0)
                mid = np.array([0.5 * (ln.first_index + ln.last_index) for ln in lines])
                line_poses = sensor_pose_at(scan.stamp_ns + np.rint(
                    mid * scan.time_increment * 1e9).astype(np.int64)).reshape(-1, 3)
                score_lines(l_scores[m], lines, walls_true, line_poses=line_poses)
            n_used += 1
    result = {'scans': n_used, 'sigma_r': sigma, 'corners': {}, 'lines': {}}
    for m, s in c_scores.items():
        result['corners'][m] = {
            'precision': s.precision, 'recall': s.recall, 'rms_error_m': s.rms_error,
            'ghosts_per_scan': s.ghosts_per_scan, 'true_positives': s.tp,
            'scored_corners': s.truth, 'wrong_class': s.wrong, 'duplicates': s.duplicate,
            'median_ms_per_scan': 1e3 * float(np.median(c_times[m])) if c_times[m] else None}
    for m, s in l_scores.items():
        result['lines'][m] = {
            'true_pos': s.true_pos, 'false_pos': s.false_pos_rate,
            'sigma_drho_m': s.sigma_rho, 'sigma_dalpha_deg': float(np.degrees(s.sigma_alpha)),
            'floor_sigma_drho_m': s.floor_sigma_rho,
            'floor_sigma_dalpha_deg': float(np.degrees(s.floor_sigma_alpha)),
            'detections': s.detections, 'relevant': s.relevant, 'found': s.found,
            'median_ms_per_scan': 1e3 * float(np.median(l_times[m])) if l_times[m] else None}
    return result


def format_tables(result: dict) -> str:
    """Render the figures as two Markdown tables."""
    lines = [f'scans: {result["scans"]}, extractor sigma_r = {100 * result["sigma_r"]:.1f} cm',
             '', '| corner method | precision | recall | RMS error | ghosts/scan | ms/scan |',
             '| --- | --- | --- | --- | --- | --- |']
    for m, f in result['corners'].items():
        lines.append(f'| {m} | {f["precision"]:.3f} | {f["recall"]:.3f} | '
                     f'{100 * f["rms_error_m"]:.2f} cm | {f["ghosts_per_scan"]:.3f} | '
                     f'{f["median_ms_per_scan"]:.2f} |')
    lines += ['', '| line method | TruePos | FalsePos | sigma d rho (floor) | '
              'sigma d alpha (floor) | ms/scan |', '| --- | --- | --- | --- | --- | --- |']
    for m, f in result['lines'].items():
        lines.append(f'| {m} | {f["true_pos"]:.3f} | {f["false_pos"]:.3f} | '
                     f'{100 * f["sigma_drho_m"]:.2f} cm ({100 * f["floor_sigma_drho_m"]:.2f}) | '
                     f'{f["sigma_dalpha_deg"]:.3f} deg ({f["floor_sigma_dalpha_deg"]:.3f}) | '
                     f'{f["median_ms_per_scan"]:.2f} |')
    lines += ['', 'floor: what an efficient extractor would get on the same matched walls '
              '(Cramer-Rao bound from all beams on each wall, cut at the matching window)']
    return '\n'.join(lines)


def run(bag, every: int = 1, sigma_r: Optional[float] = None, json_out=None) -> str:
    """Evaluate, optionally write JSON, and return the tables."""
    result = evaluate_features(bag, sigma_r=sigma_r, every=every, progress=True)
    if json_out:
        Path(json_out).write_text(json.dumps(result, indent=2))
    return format_tables(result)
