"""Tests for odometry calibration (section 3.1: eqs. 17-19, Algorithm 1) and its tool."""

import math
from pathlib import Path
import shutil

from landmark_nav.bag import BagError, BagWriter
from landmark_nav.conversions import make_joint_state
from landmark_nav.localization.calibration import (calibrate, calibrate_data_set,
                                                   CalibrationRun, final_errors, final_pose,
                                                   final_pose_covariance,
                                                   final_pose_jacobian, identifiability,
                                                   integrate_run, make_run, pose_error,
                                                   split_data_sets)
from landmark_nav.sim import run_scenario
from landmark_nav.sim.record import record_scenario
from landmark_nav.sim.robot import dead_reckon
from landmark_nav.tools.calibrate_odometry import (calibrate_odometry, load_runs,
                                                   write_base_driver_params)
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from sensor_msgs.msg import JointState
import yaml

REPO = Path(__file__).resolve().parents[1]
BAG = REPO / 'bags' / 'calibration'
TRUE_K = (0.9977, 1.0023, 1.0095)  # simulated factors (the chapter's values)
R, B = 0.0955, 0.330
TOL_K = 0.001  # required recovery of every factor
MIN_HEADING_REDUCTION = 5.0  # required reduction of the mean validation heading error


def _runs(result):
    """Calibration runs of a ScenarioResult (wheel speeds of (start_ns, end_ns])."""
    stamps = result.trajectory.stamps_ns[1:]
    speeds = result.odometry.wheel_speeds
    return [make_run(m.kind, stamps, speeds, m.start_ns, m.end_ns, m.start_pose, m.end_pose,
                     m.group, m.index) for m in result.runs]


def _groups(runs):
    return ([r for r in runs if r.group == 'calibration'],
            [r for r in runs if r.group == 'validation'])


@pytest.fixture(scope='module')
def noise_free():
    res = run_scenario('calibration', 3, robot={'wheel_noise_gain': 0.0,
                                                'wheel_noise_floor': 0.0})
    return res, _runs(res)


def _check_bag(bag, capsys, label):
    factors, report = calibrate_odometry(bag)
    k = np.array([factors['k1'], factors['k2'], factors['k3']])
    runs, robot = load_runs(bag)
    assert tuple(robot[n] for n in ('k1', 'k2', 'k3')) == TRUE_K
    _, val = _groups(runs)
    p0, h0 = final_errors(val, (1.0, 1.0, 1.0), R, B)
    p1, h1 = final_errors(val, k, R, B)
    with capsys.disabled():
        print(f'\n{label}: k - k_sim = {np.round(k - TRUE_K, 6)}; validation heading '
              f'{math.degrees(h0.mean()):.3f} -> {math.degrees(h1.mean()):.3f} deg '
              f'(x{h0.mean() / h1.mean():.1f}), position {p0.mean() * 1e3:.1f} -> '
              f'{p1.mean() * 1e3:.1f} mm (x{p0.mean() / p1.mean():.1f})')
    assert np.all(np.abs(k - TRUE_K) <= TOL_K), k - TRUE_K
    assert h0.mean() >= MIN_HEADING_REDUCTION * h1.mean()
    assert p1.mean() < p0.mean()
    assert 'reduction: heading x' in report and 'k3 = ' in report
    return k


# ---------------------------------------------------------------------- model
def test_integration_reuses_the_kinematics_eqs_1_7_17_18(noise_free):
    res, runs = noise_free
    rp = res.robot
    wheels = res.odometry.wheel_speeds
    whole = make_run('straight', res.trajectory.stamps_ns[1:], wheels,
                     res.trajectory.start_ns, res.trajectory.end_ns,
                     res.trajectory.poses[0], res.trajectory.poses[-1])
    for k in ((1.0, 1.0, 1.0), TRUE_K, (0.99, 1.02, 0.97)):
        ours = integrate_run(whole, k, R, B)
        ref = dead_reckon(res.trajectory.poses[0], wheels, rp, k)
        assert np.abs(ours - ref).max() < 1e-9
    # With the simulated k and exact wheel speeds every run ends on its exact end pose.
    for run in runs:
        assert np.abs(pose_error(run, TRUE_K, R, B)).max() < 1e-9


def test_make_run_selects_samples_and_times():
    stamps = np.arange(10, dtype=np.int64) * 100_000_000
    speeds = np.arange(20, dtype=float).reshape(10, 2)
    run = make_run('turn_cw', stamps, speeds, 250_000_000, 500_000_000, [0, 0, 0], [0, 0, 1],
                   'validation', 4)
    assert run.wheel_speeds.tolist() == speeds[3:6].tolist()  # start_ns < stamp <= end_ns
    assert run.sample_times == pytest.approx([0.05, 0.1, 0.1])  # T from the stamps
    assert run.is_turn and run.group == 'validation' and run.index == 4
    with pytest.raises(ValueError, match='no wheel speed samples'):
        make_run('straight', stamps, speeds, 1, 40, [0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match='unknown run kind'):
        make_run('spiral', stamps, speeds, 0, 550_000_000, [0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError):
        CalibrationRun('straight', np.zeros((3, 2)), [0.1, 0.0, 0.1], [0, 0, 0], [0, 0, 0])


def test_jacobian_and_covariance(noise_free):
    _, runs = noise_free
    k = np.array([0.99, 1.01, 1.02])
    for run in (runs[0], runs[1]):
        jac = final_pose_jacobian(run, k, R, B)
        num = np.stack([(final_pose(run, k + d, R, B) - final_pose(run, k - d, R, B)) / 2e-6
                        for d in np.eye(3) * 1e-6], axis=1)
        assert jac == pytest.approx(num, abs=1e-6 * max(1.0, np.abs(num).max()))
        cov = final_pose_covariance(run, k, R, B)
        assert np.all(np.linalg.eigvalsh(cov) > 0.0)
    # Heading std of a straight 5 m run vs the Monte-Carlo spread of the simulator.
    sims = [_runs(run_scenario('calibration', s)) for s in range(1, 9)]
    straight = [r for runs_s in sims for r in runs_s if r.kind == 'straight']
    err = np.array([pose_error(r, TRUE_K, R, B)[2] for r in straight])
    sd = math.sqrt(final_pose_covariance(straight[0], TRUE_K, R, B)[2, 2])
    assert 0.6 * sd < np.sqrt(np.mean(err ** 2)) < 1.5 * sd


# ---------------------------------------------------------------------- identifiability
def test_identifiability_and_scale_ambiguity(noise_free):
    _, runs = noise_free
    cal, _ = _groups(runs)
    ident = identifiability(cal, R, B, TRUE_K)
    assert ident.identifiable and ident.condition < 10.0
    assert ident.heading_only_rank == 2  # eq. 19 alone cannot fix the scale of k
    k = np.array(TRUE_K)
    for run in cal:  # headings are invariant to k -> c k (eqs. 5, 18) ...
        assert final_pose(run, 1.1 * k, R, B)[2] == pytest.approx(final_pose(run, k, R, B)[2])
    straight = [r for r in cal if r.kind == 'straight'][0]  # ... distances are not
    assert np.hypot(*pose_error(straight, 1.1 * k, R, B)[:2]) > 0.4
    with pytest.raises(ValueError, match='no turn in place'):
        calibrate([r for r in cal if not r.is_turn], R, B)
    with pytest.raises(ValueError, match='no straight run'):
        calibrate([r for r in cal if r.is_turn], R, B)
    with pytest.raises(ValueError, match='unknown calibration method'):
        calibrate(cal, R, B, method='magic')


# ---------------------------------------------------------------------- Algorithm 1
def test_noise_free_recovery_within_1e6(noise_free):
    _, runs = noise_free
    cal, _ = _groups(runs)
    sets = split_data_sets(cal)
    assert len(sets) == 5 and all(len(s) == 2 for s in sets)
    assert all([r.kind == 'straight' for r in s] == [True, False] for s in sets)
    for method in ('chapter', 'joint'):
        res = calibrate(cal, R, B, method=method)
        assert np.abs(np.array(res.k) - TRUE_K).max() < 1e-6, (method, res.k)
    res = calibrate(cal, R, B)
    assert res.set_estimates.shape == (5, 3)
    assert np.abs(res.set_estimates - TRUE_K).max() < 1e-6  # every data set on its own
    # One pass of Algorithm 1 leaves k2 - k1 scaled by the wrong k3; two are enough.
    one = calibrate_data_set(sets[0], R, B, iterations=1)
    assert 1e-6 < np.abs(one - TRUE_K).max() < 1e-4


def test_calibration_bag_recovers_k_and_validation_improves(capsys):
    k = _check_bag(BAG, capsys, 'bags/calibration (seed 1)')
    joint, _ = calibrate_odometry(BAG, method='joint')
    assert np.all(np.abs(np.array(list(joint.values())) - TRUE_K) <= TOL_K)
    assert np.abs(np.array(list(joint.values())) - k).max() < 2e-4


def test_recorded_second_seed_and_pooled_bags(tmp_path, capsys):
    bag = tmp_path / 'cal2'
    record_scenario('calibration', 2, bag)
    _check_bag(bag, capsys, 'recorded seed 2')
    factors, report = calibrate_odometry([BAG, bag])
    assert '20 runs' in report and '10 data sets' in report
    assert np.all(np.abs(np.array(list(factors.values())) - TRUE_K) <= TOL_K)


# ---------------------------------------------------------------------- parameter file
def test_parameter_file_round_trip_preserves_other_keys(tmp_path):
    path = tmp_path / 'config' / 'base_driver.yaml'
    factors = {'k1': 0.9977, 'k2': 1.0023, 'k3': 1.0095}
    write_base_driver_params(path, factors)  # creates the directory and the file
    assert yaml.safe_load(path.read_text()) == {'base_driver': {'ros__parameters': factors}}
    other = {'base_driver': {'ros__parameters': {'port': '/dev/ttyS0', 'k1': 1.0,
                                                 'wheel_radius': 0.0955}},
             'ekf_node': {'ros__parameters': {'use_sim_time': True}}}
    path.write_text(yaml.safe_dump(other))
    new = {'k1': 0.998, 'k2': 1.002, 'k3': 1.01}
    write_base_driver_params(path, new)
    data = yaml.safe_load(path.read_text())
    assert data['ekf_node'] == other['ekf_node']
    assert data['base_driver']['ros__parameters'] == {'port': '/dev/ttyS0', 'k1': 0.998,
                                                      'wheel_radius': 0.0955, 'k2': 1.002,
                                                      'k3': 1.01}
    assert list(tmp_path.joinpath('config').iterdir()) == [path]  # no temporary left
    factors_bag, report = calibrate_odometry(BAG, write_params=path)
    params = yaml.safe_load(path.read_text())['base_driver']['ros__parameters']
    assert {n: params[n] for n in ('k1', 'k2', 'k3')} == factors_bag
    assert params['port'] == '/dev/ttyS0' and f'wrote k1, k2, k3 to {path}' in report
    bad = tmp_path / 'bad.yaml'
    bad.write_text('- just\n- a list\n')
    with pytest.raises(ValueError, match='not a ROS 2 parameter file'):
        write_base_driver_params(bad, new)
    with pytest.raises(ValueError, match='k3'):
        write_base_driver_params(path, {'k1': 1.0, 'k2': 1.0, 'k3': float('nan')})


# ---------------------------------------------------------------------- bad input
def _bag_without_wheels(path: Path, joint_names) -> Path:
    with BagWriter(path) as bag:
        if joint_names is None:
            bag.add_topic('/odom', Odometry)
            bag.write('/odom', 1, Odometry())
        else:
            bag.add_topic('/joint_states', JointState)
            bag.write('/joint_states', 1, make_joint_state(1, joint_names, [0.0]))
    shutil.copy(BAG / 'ground_truth.yaml', path / 'ground_truth.yaml')
    return path


def test_bad_input_one_line_errors(tmp_path):
    with pytest.raises(BagError, match='No bag at'):
        calibrate_odometry(tmp_path / 'missing')
    no_runs = tmp_path / 'no_runs'
    shutil.copytree(BAG, no_runs)
    truth = yaml.safe_load((no_runs / 'ground_truth.yaml').read_text())
    truth['runs'] = []
    (no_runs / 'ground_truth.yaml').write_text(yaml.safe_dump(truth))
    with pytest.raises(ValueError, match='has no calibration runs'):
        calibrate_odometry(no_runs)
    (no_runs / 'ground_truth.yaml').unlink()
    with pytest.raises(ValueError, match='no ground_truth.yaml'):
        calibrate_odometry(no_runs)
    with pytest.raises(BagError, match='no /joint_states topic'):
        calibrate_odometry(_bag_without_wheels(tmp_path / 'odom_only', None))
    with pytest.raises(ValueError, match='no /joint_states messages'):
        calibrate_odometry(_bag_without_wheels(tmp_path / 'caster', ['caster_joint']))
    with pytest.raises(ValueError, match='unknown calibration method'):
        calibrate_odometry(BAG, method='magic')
    for exc in (BagError, ValueError):
        try:
            calibrate_odometry(tmp_path / 'missing' if exc is BagError else no_runs)
        except exc as err:
            assert '\n' not in str(err)
