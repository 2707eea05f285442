"""``landmark_nav calibrate-odometry <bag>...``: estimate k1, k2, k3 from calibration runs.

Reads every bag recorded by ``landmark_nav simulate calibration`` (or any bag with the same
layout): the runs -- kind, group, exact start and end pose and their stamps -- from the
``ground_truth.yaml`` beside the bag, the nominal R and b from its ``robot`` section, and
the measured wheel speeds from ``/joint_states`` (``left_wheel_joint`` /
``right_wheel_joint`` velocities in rad/s, header stamps; differenced positions when no
velocities are reported). Estimates the factors of eqs. 17-18 on the calibration group with
:func:`landmark_nav.localization.calibration.calibrate` (Algorithm 1 per data set, averaged
over the data sets), reports the final pose errors of the held-out validation runs
dead-reckoned with the nominal model (k = 1) and with the estimate, and optionally writes
the factors into a ROS 2 parameter file for the base driver::

    base_driver:
      ros__parameters:
        k1: 0.9977
        k2: 1.0023
        k3: 1.0095
"""

import math
import os
from pathlib import Path
import tempfile
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

from landmark_nav.bag import BagError, BagReader
from landmark_nav.conversions import stamp_to_ns
from landmark_nav.localization.calibration import (calibrate, CalibrationResult,
                                                   CalibrationRun, final_errors, make_run,
                                                   METHODS, split_data_sets)
from landmark_nav.sim.record import load_ground_truth, WHEEL_JOINTS
import numpy as np
import yaml

JOINT_TOPIC = '/joint_states'
BASE_DRIVER_NODE = 'base_driver'
#: Suggested parameter file (used only when the user passes it explicitly).
DEFAULT_PARAMS_FILE = 'config/base_driver.yaml'

PathLike = Union[str, os.PathLike]


def read_wheel_speeds(bag: PathLike,
                      joints: Sequence[str] = WHEEL_JOINTS) -> Tuple[np.ndarray, np.ndarray]:
    """Read the measured wheel speeds from a bag's ``/joint_states``.

    Args:
        bag: rosbag2 directory.
        joints: names of the left and right wheel joints.

    Returns:
        ``(stamps_ns (N,) int64, speeds (N, 2) [rad/s])`` sorted by header stamp; speed i
        belongs to the period that ends at stamp i.

    Raises:
        BagError: Missing or unreadable bag, or no ``/joint_states`` topic.
        ValueError: No message with both wheel joints.
    """
    stamps, vel, pos = [], [], []
    with BagReader(bag) as reader:
        if JOINT_TOPIC not in reader.topics():
            raise BagError(f'{bag} has no {JOINT_TOPIC} topic (no wheel speeds)')
        for _, _, msg in reader.decoded([JOINT_TOPIC]):
            names = list(msg.name)
            if not all(j in names for j in joints):
                continue
            idx = [names.index(j) for j in joints]
            stamps.append(stamp_to_ns(msg.header.stamp))
            v = list(msg.velocity)
            p = list(msg.position)
            vel.append([v[i] for i in idx] if len(v) == len(names) else [math.nan] * 2)
            pos.append([p[i] for i in idx] if len(p) == len(names) else [math.nan] * 2)
    if not stamps:
        raise ValueError(f'{bag} has no {JOINT_TOPIC} messages with joints {list(joints)}')
    order = np.argsort(np.asarray(stamps, dtype=np.int64), kind='stable')
    st = np.asarray(stamps, dtype=np.int64)[order]
    speeds = np.asarray(vel, dtype=float)[order]
    if not np.all(np.isfinite(speeds)):
        # No velocities reported: difference the wheel angles (first sample: at rest).
        p = np.asarray(pos, dtype=float)[order]
        if not np.all(np.isfinite(p)) or np.any(np.diff(st) <= 0):
            raise ValueError(f'{bag}: {JOINT_TOPIC} reports neither wheel velocities nor '
                             'usable positions')
        speeds = np.vstack([np.zeros((1, 2)), np.diff(p, axis=0) / (np.diff(st) / 1e9)[:, None]])
    return st, speeds


def load_runs(bag: PathLike) -> Tuple[List[CalibrationRun], Dict[str, Any]]:
    """Read the calibration and validation runs of one bag.

    Args:
        bag: rosbag2 directory with ``ground_truth.yaml`` beside the MCAP file.

    Returns:
        ``(runs, robot)``: the runs in recording order and the ``robot`` section of the
        ground truth (``wheel_radius``, ``axle_length``, and for the simulator the true
        ``k1``, ``k2``, ``k3``).

    Raises:
        BagError: Missing or unreadable bag, or no ``/joint_states``.
        ValueError: No ground truth, no runs, no robot R / b, or wheel speeds that do not
            cover a run.
    """
    with BagReader(bag):
        pass  # a missing or broken bag is reported before its side files
    truth = load_ground_truth(bag)
    if not isinstance(truth, dict):
        raise ValueError(f'{bag}: malformed ground_truth.yaml')
    robot = truth.get('robot') or {}
    if not isinstance(robot, dict) or 'wheel_radius' not in robot or 'axle_length' not in robot:
        raise ValueError(f'{bag}: ground_truth.yaml has no robot wheel_radius / axle_length')
    specs = truth.get('runs') or []
    if not specs:
        raise ValueError(f'{bag} has no calibration runs (record the calibration scenario)')
    stamps, speeds = read_wheel_speeds(bag)
    runs = []
    for i, spec in enumerate(specs):
        try:
            start_ns, end_ns = int(spec['start_ns']), int(spec['end_ns'])
            if stamps[0] > start_ns or stamps[-1] < end_ns:
                raise ValueError(f'{bag}: the wheel speeds do not cover run {i} '
                                 f'({spec["kind"]})')
            runs.append(make_run(spec['kind'], stamps, speeds, start_ns, end_ns,
                                 spec['start_pose'], spec['end_pose'],
                                 group=spec.get('group', 'calibration'),
                                 index=int(spec.get('index', i))))
        except (KeyError, TypeError) as err:
            raise ValueError(f'{bag}: malformed run {i} in ground_truth.yaml: {err}') from None
    return runs, robot


def write_base_driver_params(path: PathLike, factors: Dict[str, float],
                             node: str = BASE_DRIVER_NODE) -> Path:
    """Create or update a ROS 2 parameter file with ``k1``, ``k2``, ``k3`` of a node.

    Other nodes and other parameters in the file are kept; the file is replaced atomically.

    Args:
        path: parameter file (YAML); missing parent directories are created.
        factors: ``{'k1': .., 'k2': .., 'k3': ..}``.
        node: node name (top-level key).

    Returns:
        The path written.

    Raises:
        ValueError: The existing file is not a parameter file (not a mapping), or the
            factors are not three finite positive numbers.
    """
    path = Path(path)
    values = {}
    for name in ('k1', 'k2', 'k3'):
        v = float(factors[name])
        if not (math.isfinite(v) and v > 0.0):
            raise ValueError(f'{name} must be a finite number > 0, got {v!r}')
        values[name] = v
    data: Dict[str, Any] = {}
    if path.exists():
        try:
            with open(path) as f:
                data = yaml.safe_load(f) or {}
        except yaml.YAMLError as err:
            raise ValueError(f'{path} is not valid YAML: {str(err).splitlines()[0]}') from None
        if not isinstance(data, dict):
            raise ValueError(f'{path} is not a ROS 2 parameter file (top level is not a map)')
    section = data.setdefault(node, {})
    if section is None:
        section = data[node] = {}
    if not isinstance(section, dict):
        raise ValueError(f'{path}: {node} is not a map')
    params = section.setdefault('ros__parameters', {})
    if params is None:
        params = section['ros__parameters'] = {}
    if not isinstance(params, dict):
        raise ValueError(f'{path}: {node}.ros__parameters is not a map')
    params.update(values)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix='.tmp', dir=path.parent)
    try:
        with os.fdopen(fd, 'w') as f:
            yaml.safe_dump(data, f, sort_keys=False, default_flow_style=False)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def _validation_lines(runs: Sequence[CalibrationRun], k: Sequence[float], r: float,
                      b: float, true_k: Optional[Sequence[float]]) -> List[str]:
    if not runs:
        return ['validation: no validation runs']
    p0, h0 = final_errors(runs, (1.0, 1.0, 1.0), r, b)
    p1, h1 = final_errors(runs, k, r, b)
    lines = ['validation (final pose error of each held-out run, nominal k = 1 -> '
             'calibrated):',
             f'  {"run":>4}  {"kind":<9} {"position [mm]":>19}  {"heading [deg]":>17}']
    for run, a, c, d, e in zip(runs, p0, p1, h0, h1):
        lines.append(f'  {run.index:>4}  {run.kind:<9} {a * 1e3:8.1f} -> {c * 1e3:<8.1f}'
                     f'  {math.degrees(d):7.3f} -> {math.degrees(e):<7.3f}')
    lines.append(f'  {"mean":>4}  {"":<9} {p0.mean() * 1e3:8.1f} -> {p1.mean() * 1e3:<8.1f}'
                 f'  {math.degrees(h0.mean()):7.3f} -> {math.degrees(h1.mean()):<7.3f}')
    ratio_h = h0.mean() / h1.mean() if h1.mean() > 0 else math.inf
    ratio_p = p0.mean() / p1.mean() if p1.mean() > 0 else math.inf
    lines.append(f'  reduction: heading x{ratio_h:.1f}, position x{ratio_p:.1f} '
                 f'({len(runs)} runs)')
    if true_k is not None:
        pt, ht = final_errors(runs, true_k, r, b)
        lines.append(f'  with the simulated k (noise floor): position {pt.mean() * 1e3:.1f} mm, '
                     f'heading {math.degrees(ht.mean()):.3f} deg')
    return lines


def calibrate_odometry(bags: Union[PathLike, Sequence[PathLike]],
                       write_params: Optional[PathLike] = None, method: str = 'chapter',
                       iterations: int = 2) -> Tuple[Dict[str, float], str]:
    """Estimate k1, k2, k3 from the calibration runs of one or more bags.

    Args:
        bags: bag directory or list of bag directories; their runs are pooled (data sets
            are formed per bag).
        write_params: if given, write the factors into this ROS 2 parameter file
            (``base_driver: ros__parameters: {k1, k2, k3}``, other keys kept).
        method: ``'chapter'`` (Algorithm 1 per data set, averaged; default) or ``'joint'``.
        iterations: Algorithm 1 iterations (the chapter: two).

    Returns:
        ``(factors, report)``: ``{'k1': .., 'k2': .., 'k3': ..}`` and a printable report.

    Raises:
        BagError: Missing or unreadable bag, or a bag without ``/joint_states``.
        ValueError: A bag without runs or ground truth, differing R / b between bags, no
            calibration runs, or bad options.
    """
    if isinstance(bags, (str, os.PathLike)):
        bags = [bags]
    bags = list(bags)
    if not bags:
        raise ValueError('no bag given')
    if method not in METHODS:
        raise ValueError(f'unknown calibration method {method!r}; valid: {list(METHODS)}')
    if isinstance(iterations, bool) or int(iterations) != iterations or iterations < 1:
        raise ValueError(f'iterations must be an integer >= 1, got {iterations!r}')
    cal: List[CalibrationRun] = []
    val: List[CalibrationRun] = []
    sets: List[List[CalibrationRun]] = []
    geometry = None
    true_k = None
    for bag in bags:
        runs, robot = load_runs(bag)
        rb = (float(robot['wheel_radius']), float(robot['axle_length']))
        if geometry is not None and not np.allclose(rb, geometry, rtol=0.0, atol=1e-12):
            raise ValueError(f'{bag}: wheel radius / axle length {rb} differ from the first '
                             f'bag {geometry}')
        geometry = rb
        bag_cal = [r for r in runs if r.group == 'calibration']
        val += [r for r in runs if r.group == 'validation']
        if bag_cal:
            sets += split_data_sets(bag_cal)
            cal += bag_cal
        if all(n in robot for n in ('k1', 'k2', 'k3')):
            k_sim = tuple(float(robot[n]) for n in ('k1', 'k2', 'k3'))
            true_k = k_sim if true_k in (None, k_sim) else None
    if not cal:
        raise ValueError('no calibration runs in ' + ', '.join(str(b) for b in bags))
    r, b = geometry
    result: CalibrationResult = calibrate(cal, r, b, method=method, iterations=int(iterations),
                                          data_sets=sets)
    k = result.k
    factors = result.as_dict()
    n_straight = sum(not x.is_turn for x in cal)
    lines = [f'odometry calibration (section 3.1) of {", ".join(str(x) for x in bags)}',
             f'nominal model: R = {r:.6g} m, b = {b:.6g} m',
             f'calibration group: {len(cal)} runs ({n_straight} straight, '
             f'{len(cal) - n_straight} turns in place), {len(sets)} data sets',
             f'method: {method}' + (f' (Algorithm 1, {result.iterations} iterations, '
                                    'averaged over the data sets)' if method == 'chapter'
                                    else ' (all runs in one weighted least-squares fit)')]
    spread = result.set_std
    for i, name in enumerate(('k1', 'k2', 'k3')):
        text = f'  {name} = {k[i]:.6f}'
        if result.set_estimates.shape[0] > 1:
            text += f'  (data sets: std {spread[i]:.6f})'
        if true_k is not None:
            text += f'  simulated {true_k[i]:.6f}, error {k[i] - true_k[i]:+.6f}'
        lines.append(text)
    ident = result.identifiability
    lines.append(f'identifiability: condition number {ident.condition:.1f}, predicted std '
                 + ', '.join(f'{s:.5f}' for s in ident.std)
                 + f' (final headings alone: rank {ident.heading_only_rank} of 3)')
    lines += _validation_lines(val, k, r, b, true_k)
    if write_params is not None:
        out = write_base_driver_params(write_params, factors)
        lines.append(f'wrote k1, k2, k3 to {out} ({BASE_DRIVER_NODE}.ros__parameters)')
    return factors, '\n'.join(line.rstrip() for line in lines)


__all__ = ['BASE_DRIVER_NODE', 'calibrate_odometry', 'DEFAULT_PARAMS_FILE', 'load_runs',
           'read_wheel_speeds', 'write_base_driver_params']
