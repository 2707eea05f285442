"""Corner and line extractors scored on a bag: the runners of ``evaluate-features``.

Runs the extractors directly on the bag's scans (no DDS). Two kinds of bag:

* **Simulator bags** (``ground_truth.yaml`` beside the bag): :func:`evaluate_features`
  compares every scan with the ground-truth corners and walls (see
  :mod:`landmark_nav.evaluation.features` for the matching rules): the corner and line
  tables of docs/laser_features.md.
* **Any other bag with** ``/scan`` (e.g. written by ``landmark_nav import`` from a real
  log), or a simulator bag with ``truth_free``: :func:`evaluate_truth_free`, the metrics
  that need no ground-truth features (:mod:`landmark_nav.evaluation.scan_metrics`): the PLE
  ray metric (f, ray RMSE) and fit residual on ``scans`` scans drawn with ``seed``,
  false-surface beams on every scan, repeatability of lines and corners between
  consecutive scans through the reference poses (``/ground_truth/odom`` or a TUM file,
  read by :func:`landmark_nav.evaluation.trajectory.read_tum`), per method and for the
  approxPolyDP baseline. The laser mount and the sensor's range noise come from the bag's
  custom_data (``landmark_nav.laser_mount``, ``landmark_nav.laser_sigma_range``), else from
  ``ground_truth.yaml``, else from the ``mount`` / ``sigma_r`` arguments (default 0 0 0 and
  0.01 m, with a note): :func:`sensor_facts`.

:func:`evaluate_bag_features` picks one of the two as the command does and writes the JSON.
"""

from dataclasses import asdict, replace
import json
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from landmark_nav.bag import BagReader
from landmark_nav.conversions import scan_to_data
from landmark_nav.evaluation.bags import MOUNT_KEY, read_track, SIGMA_KEY
from landmark_nav.evaluation.features import FeatureRun, score_scan
from landmark_nav.evaluation.scan_metrics import evaluate_scans, MetricScan
from landmark_nav.evaluation.trajectory import read_tum
from landmark_nav.geometry import compose, interpolate_pose
from landmark_nav.sim.record import GROUND_TRUTH_FILE, load_ground_truth
import numpy as np

CORNER_METHODS = ('minus_cosine', 'sliding_window', 'split_merge')
LINE_METHODS = ('split_merge', 'alfa')
#: Parameter values by node name (``corner_extractor``, ``line_extractor``).
NodeValues = Mapping[str, Mapping[str, Any]]


def _truth_track(bag):
    with BagReader(bag) as reader:
        if '/ground_truth/odom' not in reader.topics():
            raise ValueError(f'{bag} has no /ground_truth/odom topic')
        stamps, poses = read_track(reader, '/ground_truth/odom')
    if not stamps.size:
        raise ValueError(f'{bag} has no /ground_truth/odom messages')
    return stamps, poses


def feature_configurations(files: Optional[NodeValues] = None,
                           settings: Optional[NodeValues] = None,
                           stated: Optional[Mapping[str, Any]] = None,
                           sigma_r: Optional[float] = None) -> Dict[str, object]:
    """Return each feature node's configuration by node name, in the command's order.

    The node's defaults, then its values of ``files`` (the ``--params-file`` files), then
    ``stated`` (what the bag states: the simulated laser's noise), then its values of
    ``settings`` (``--set``), then ``sigma_r`` (``--sigma-r``) for both nodes
    (:func:`landmark_nav.laser.extractor_configuration.extractor_configuration`).

    Raises:
        ValueError: A name the node does not declare (naming the nearest one) or a value it
            refuses.
    """
    from landmark_nav.laser.extractor_configuration import EXTRACTORS, extractor_configuration
    out = {}
    for node in EXTRACTORS:
        values = {**(files or {}).get(node, {}), **(stated or {}),
                  **(settings or {}).get(node, {})}
        if sigma_r is not None:
            values['sigma_r'] = float(sigma_r)
        out[node] = extractor_configuration(node, values)
    return out


def evaluate_features(bag, corner_methods: Sequence[str] = CORNER_METHODS,
                      line_methods: Sequence[str] = LINE_METHODS,
                      sigma_r: Optional[Union[float, str]] = None, every: int = 1,
                      progress: bool = False, files: Optional[NodeValues] = None,
                      settings: Optional[NodeValues] = None) -> Dict[str, dict]:
    """Score every method on every ``every``-th scan of a simulator bag.

    Args:
        bag: rosbag2 directory recorded by ``landmark_nav simulate``.
        corner_methods: Corner detectors to run.
        line_methods: Line extractors to run.
        sigma_r: Range noise the extractors assume [m], after ``settings``; default: the
            simulated laser's (what the bag states, after ``files``); ``'auto'``:
            estimated from the scans used, at least the simulated one
            (:func:`landmark_nav.laser.range_noise.estimate_range_noise`).
        every: Use every n-th scan.
        progress: Show a progress bar.
        files: ``corner_extractor`` / ``line_extractor`` parameter values by node name,
            under the bag's statements (the simulated range and bearing noise).
        settings: The same, over the bag's statements
            (:func:`feature_configurations`). Each method runs with its node's
            configuration, ``method`` set per row.

    Returns:
        {'corners': {method: figures}, 'lines': {method: figures}, 'scans': n,
        'sigma_r': the line extractor's range noise, 'corner_sigma_r': the corner
        extractor's}.

    """
    from landmark_nav.laser.extractor_configuration import ScanSegmenter
    from landmark_nav.sim.world import World

    if every < 1:
        raise ValueError(f'every must be >= 1, got {every}')
    meta = load_ground_truth(bag)
    if not meta.get('laser'):
        raise ValueError(f'{bag} was recorded without a laser')
    world = World.from_dict(meta['world'])
    mount = np.asarray(meta['laser']['mount'], dtype=float)
    true_sigma = float(meta['laser']['sigma_range'])  # the simulated noise (for the bound)
    sigma_phi = float(meta['laser'].get('sigma_angle', 0.0))
    estimate = None
    if sigma_r == 'auto':
        estimate = bag_range_noise(bag, every, stated=true_sigma)
        sigma_r = estimate.sigma_r
    configs = feature_configurations(files, settings, {'sigma_r': true_sigma,
                                                       'sigma_phi': sigma_phi}, sigma_r)
    corner, line = configs['corner_extractor'], configs['line_extractor']
    t_truth, truth = _truth_track(bag)
    t_rel = (t_truth - t_truth[0]).astype(float)
    run = FeatureRun(
        corner_params={m: replace(corner.params, method=m) for m in corner_methods},
        line_params={m: replace(line.params, method=m) for m in line_methods},
        truth_sigma_r=true_sigma, truth_sigma_phi=sigma_phi,
        segmenters={'corners': ScanSegmenter.of(corner), 'lines': ScanSegmenter.of(line)})

    def sensor_pose_at(stamps):
        rel = (np.asarray(stamps, dtype=np.int64) - t_truth[0]).astype(float)
        return compose(interpolate_pose(rel, t_rel, truth), mount)

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
            score_scan(run, world, sensor_pose_at, scan)
            n_used += 1
    result = {'scans': n_used, 'sigma_r': line.params.sigma_r,
              'corner_sigma_r': corner.params.sigma_r, 'corners': {}, 'lines': {},
              'sigma_r_estimate': None if estimate is None else asdict(estimate)}
    for m, s in run.corners.items():
        times = run.corner_times[m]
        result['corners'][m] = {
            'precision': s.precision, 'recall': s.recall, 'rms_error_m': s.rms_error,
            'ghosts_per_scan': s.ghosts_per_scan, 'true_positives': s.tp,
            'scored_corners': s.truth, 'wrong_class': s.wrong, 'duplicates': s.duplicate,
            'median_ms_per_scan': 1e3 * float(np.median(times)) if times else None}
    for m, s in run.lines.items():
        times = run.line_times[m]
        result['lines'][m] = {
            'true_pos': s.true_pos, 'false_pos': s.false_pos_rate,
            'sigma_drho_m': s.sigma_rho, 'sigma_dalpha_deg': float(np.degrees(s.sigma_alpha)),
            'floor_sigma_drho_m': s.floor_sigma_rho,
            'floor_sigma_dalpha_deg': float(np.degrees(s.floor_sigma_alpha)),
            'detections': s.detections, 'relevant': s.relevant, 'found': s.found,
            'median_ms_per_scan': 1e3 * float(np.median(times)) if times else None}
    return result


def bag_range_noise(bag, every: int = 1, stated: Optional[float] = None):
    """Estimate the range noise from every ``every``-th scan of a bag's ``/scan``."""
    from landmark_nav.laser.range_noise import estimate_range_noise

    def scans():
        with BagReader(bag) as reader:
            for k, (_, _, msg) in enumerate(reader.decoded(['/scan'])):
                if k % every == 0:
                    s = scan_to_data(msg)
                    yield s.ranges, s.angles, s.valid

    return estimate_range_noise(scans(), stated)


def _parse_mount(text: str, where: str) -> np.ndarray:
    try:
        mount = np.array([float(v) for v in str(text).split()], dtype=float)
    except ValueError as err:
        raise ValueError(f'{where}: laser mount {text!r} is not "x y yaw" ({err})') from err
    if mount.shape != (3,) or not np.all(np.isfinite(mount)):
        raise ValueError(f'{where}: laser mount {text!r} is not three finite numbers "x y yaw"')
    return mount


def _parse_sigma(text, where: str) -> float:
    try:
        sigma = float(text)
    except ValueError as err:
        raise ValueError(f'{where}: laser sigma_range {text!r} is not a number') from err
    if not (np.isfinite(sigma) and sigma > 0.0):
        raise ValueError(f'{where}: laser sigma_range {text!r} must be > 0')
    return sigma


def sensor_facts(bag, mount: Optional[Sequence[float]] = None,
                 sigma_r: Optional[float] = None) -> Tuple[np.ndarray, float, List[str]]:
    """Return the laser mount (x, y, yaw), the range noise [m] and notes on their sources.

    Order: the bag's custom_data, then ``ground_truth.yaml`` (simulator bags), then the
    given ``mount`` / ``sigma_r``, then 0 0 0 and 0.01 m (with a note).
    """
    with BagReader(bag) as reader:
        custom = reader.custom_data
    meta = {}
    if (Path(bag) / GROUND_TRUTH_FILE).is_file():
        meta = (load_ground_truth(bag) or {}).get('laser') or {}
    notes = []
    if MOUNT_KEY in custom:
        m = _parse_mount(custom[MOUNT_KEY], f'{bag} custom_data {MOUNT_KEY}')
    elif 'mount' in meta:
        m = np.asarray(meta['mount'], dtype=float)
    elif mount is not None:
        m = np.asarray(mount, dtype=float)
    else:
        m = np.zeros(3)
        notes.append(f'note: {bag} states no laser mount; using 0 0 0 (base_link = laser)')
    if SIGMA_KEY in custom:
        s = _parse_sigma(custom[SIGMA_KEY], f'{bag} custom_data {SIGMA_KEY}')
    elif 'sigma_range' in meta:
        s = float(meta['sigma_range'])
    elif sigma_r is not None:
        s = float(sigma_r)
    else:
        s = 0.01
        notes.append(f'note: {bag} states no laser range noise; using sigma_r = 0.01 m')
    return m, s, notes


def bag_metric_scans(bag, mount: np.ndarray, reference: Optional[str] = None,
                     every: int = 1) -> Tuple[List[MetricScan], List[str]]:
    """Read a bag's ``/scan`` as :class:`MetricScan` with laser poses from the reference.

    The reference is ``reference`` (a TUM file) or the bag's ``/ground_truth/odom``;
    without either, or for scans outside its time span, the poses are None (no
    repeatability). The pose is the reference at the scan's stamp composed with ``mount``.
    """
    notes = []
    track = None
    if reference is not None:
        tum = read_tum(reference)
        track = (tum.stamps_ns, tum.planar())
    else:
        with BagReader(bag) as reader:
            has_truth = '/ground_truth/odom' in reader.topics()
        if has_truth:
            track = _truth_track(bag)
        else:
            notes.append(f'note: {bag} has no /ground_truth/odom and no --reference was '
                         'given: no repeatability')
    scans = []
    with BagReader(bag) as reader:
        if '/scan' not in reader.topics():
            raise ValueError(f'{bag} has no /scan topic')
        for k, (_, _, msg) in enumerate(reader.decoded(['/scan'])):
            if k % every:
                continue
            s = scan_to_data(msg)
            pose = None
            if track is not None and track[0][0] <= s.stamp_ns <= track[0][-1]:
                rel = float(s.stamp_ns - track[0][0])
                pose = compose(interpolate_pose(rel, (track[0] - track[0][0]).astype(float),
                                                track[1]), mount)
            scans.append(MetricScan(s.ranges, s.angles, s.valid, s.no_return, s.range_min,
                                    s.range_max, pose))
    if track is not None:
        missing = sum(s.pose is None for s in scans)
        if missing:
            notes.append(f'note: {missing} of {len(scans)} scans lie outside the reference '
                         'and take no part in repeatability')
    return scans, notes


def evaluate_truth_free(bag, reference: Optional[str] = None,
                        mount: Optional[Sequence[float]] = None,
                        sigma_r: Optional[float] = None,
                        extractor_sigma_r: Optional[Union[float, str]] = None,
                        scans: int = 20, seed: int = 0, every: int = 1, progress: bool = False,
                        configs: Optional[Mapping[str, object]] = None
                        ) -> Tuple[dict, List[str]]:
    """Score every method on a bag with the truth-free metrics (module docstring).

    ``extractor_sigma_r``: the range noise the extractors assume [m] (one value or one per
    node name), None for the configuration's (the node default 0.01 m), or ``'auto'`` (the
    command's default, :func:`evaluate_bag_features`): estimated from the bag's scans, at
    least the sensor's stated noise. ``configs``: the nodes' configurations by node name
    (:func:`feature_configurations`; default the node defaults). See
    :func:`landmark_nav.evaluation.scan_metrics.evaluate_scans`.

    Returns:
        (figures of :func:`landmark_nav.evaluation.scan_metrics.evaluate_scans` plus
        'laser_mount', notes on the sources of the mount and noise).

    """
    if every < 1:
        raise ValueError(f'every must be >= 1, got {every}')
    m, s, notes = sensor_facts(bag, mount, sigma_r)
    items, more = bag_metric_scans(bag, m, reference, every)
    result = evaluate_scans(items, sigma_r=s, ple_scans=scans, seed=seed,
                            extractor_sigma_r=extractor_sigma_r,
                            progress=Path(bag).name if progress else None, configs=configs)
    result['laser_mount'] = [float(v) for v in m]
    return result, notes + more


def evaluate_bag_features(bag, every: int = 1, sigma_r: Optional[Union[float, str]] = None,
                          json_out=None, reference: Optional[str] = None,
                          mount: Optional[Sequence[float]] = None,
                          sensor_sigma_r: Optional[float] = None, scans: int = 20,
                          seed: int = 0, truth_free: bool = False, progress: bool = False,
                          files: Optional[NodeValues] = None,
                          settings: Optional[NodeValues] = None
                          ) -> Tuple[dict, List[str], bool]:
    """Evaluate a bag as ``landmark_nav evaluate-features`` does; optionally write the JSON.

    With ground-truth features (a simulator bag) and not ``truth_free``:
    :func:`evaluate_features`; otherwise :func:`evaluate_truth_free`, ``sigma_r`` then being
    the range noise the extractors assume (default ``'auto'``: estimated from the scans, at
    least the sensor's stated noise) and ``sensor_sigma_r`` the sensor's. ``progress``: a
    tqdm bar. ``files`` and ``settings``: the nodes' parameter values
    (:func:`feature_configurations`): defaults, then ``files``, then what the bag states
    (the simulated noise; on other bags the estimated one unless ``settings`` give
    ``sigma_r``), then ``settings``, then ``sigma_r``.

    Returns:
        (figures, notes, whether the figures are the truth-free ones).

    """
    if not truth_free and (Path(bag) / GROUND_TRUTH_FILE).is_file():
        result = evaluate_features(bag, sigma_r=sigma_r, every=every, progress=progress,
                                   files=files, settings=settings)
        notes, free = [], False
    else:
        configs = feature_configurations(files, settings)
        spec = sigma_r if sigma_r is not None else {
            node: None if 'sigma_r' in (settings or {}).get(node, {}) else 'auto'
            for node in configs}
        result, notes = evaluate_truth_free(bag, reference, mount, sensor_sigma_r, spec,
                                            scans, seed, every, progress=progress,
                                            configs=configs)
        free = True
    if json_out:
        Path(json_out).write_text(json.dumps(result, indent=2))
    return result, notes, free


__all__ = ['bag_metric_scans', 'bag_range_noise', 'CORNER_METHODS', 'evaluate_bag_features',
           'evaluate_features', 'evaluate_truth_free', 'feature_configurations',
           'LINE_METHODS', 'NodeValues', 'sensor_facts']
