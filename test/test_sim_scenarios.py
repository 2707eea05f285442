"""Tests for landmark_nav.sim.scenarios: event stream, determinism, odometry, calibration runs."""

import dataclasses
import math

from landmark_nav.sim import (dead_reckon, OdometrySample, run_scenario, RunMarker,
                              ScanSample, scenario_names, SonarSample, START_NS, TruthSample,
                              World, wrap_angle)
import numpy as np
import pytest
import yaml

EXACT = {'k1': 1.0, 'k2': 1.0, 'k3': 1.0, 'wheel_noise_gain': 0.0, 'wheel_noise_floor': 0.0}


@pytest.fixture(scope='module')
def office():
    return run_scenario('office', 7)


@pytest.fixture(scope='module')
def calibration():
    return run_scenario('calibration', 3)


def assert_same_stream(a, b):
    assert len(a.events) == len(b.events)
    for x, y in zip(a.events, b.events):
        assert type(x) is type(y)
        for f in dataclasses.fields(x):
            u, v = getattr(x, f.name), getattr(y, f.name)
            if isinstance(u, np.ndarray):
                assert u.dtype == v.dtype and np.array_equal(u, v, equal_nan=True), f.name
            else:
                assert u == v, f.name


def test_names_and_validation():
    assert scenario_names() == ['ambiguous', 'calibration', 'hallway', 'office']
    with pytest.raises(ValueError, match='office'):
        run_scenario('kitchen', 1)
    for bad in (-1, 1.5, '3', True, None):
        with pytest.raises(ValueError):
            run_scenario('calibration', bad)
    with pytest.raises(ValueError):
        run_scenario('calibration', 1, lidar=None)
    with pytest.raises(ValueError):
        run_scenario('calibration', 1, robot={'k9': 1.0})
    run_scenario('calibration', np.int64(2))  # numpy integers are fine


def test_determinism(office):
    assert_same_stream(office, run_scenario('office', 7))


def test_different_seed_differs_but_truth_path_is_the_same(office):
    other = run_scenario('office', 8)
    assert not np.array_equal(office.odometry.poses, other.odometry.poses)
    s1, s2 = office.of_type(ScanSample), other.of_type(ScanSample)
    assert not np.array_equal(s1[10].ranges, s2[10].ranges)
    assert np.array_equal(office.trajectory.poses, other.trajectory.poses)


def test_sensor_streams_are_independent():
    a = run_scenario('hallway', 5)
    b = run_scenario('hallway', 5, laser=None)
    sa, sb = a.of_type(SonarSample), b.of_type(SonarSample)
    assert all(np.array_equal(x.ranges, y.ranges) for x, y in zip(sa, sb))
    assert np.array_equal(a.odometry.poses, b.odometry.poses)
    assert b.counts()['ScanSample'] == 0


def test_event_stream_shape(office):
    ev = office.events
    stamps = [e.stamp_ns for e in ev]
    assert stamps == sorted(stamps) and stamps[0] == START_NS
    c = office.counts()
    assert c['TruthSample'] == c['OdometrySample'] == c['SonarSample']
    assert abs(c['ScanSample'] - 10 * office.duration) <= 2
    assert c['RunMarker'] == 0
    truth = office.of_type(TruthSample)
    assert all(np.diff([t.stamp_ns for t in truth]) == 100_000_000)
    for t in truth[::97]:
        assert np.array_equal(t.pose, office.truth_at(t.stamp_ns))
        assert np.array_equal(t.twist, office.trajectory.twist_at(t.stamp_ns))
    odo = office.of_type(OdometrySample)
    assert odo[0].pose == pytest.approx(office.start_pose) and np.all(odo[0].covariance == 0)
    assert all(-math.pi <= o.pose[2] < math.pi for o in odo)
    scan = office.of_type(ScanSample)[0]
    assert scan.ranges.dtype == np.float32 and scan.ranges.shape == (361,)
    assert not scan.ranges.flags.writeable
    meta = office.to_dict()
    text = yaml.safe_dump(meta)
    back = yaml.safe_load(text)
    assert back['seed'] == 7 and back['robot']['k3'] == 1.0095
    assert np.array_equal(World.from_dict(back['world']).segments, office.world.segments)


def test_office_facts(office):
    assert 25.0 <= office.path_length <= 35.0
    assert 90.0 <= office.duration <= 125.0
    assert len(office.world.corners()) == 17
    assert office.world.bounds() == (0.0, 0.0, 9.0, 7.2)
    end = office.trajectory.poses[-1]
    assert end[:2] == pytest.approx(office.start_pose[:2], abs=0.05)  # loop closes
    assert office.world.clearance(office.trajectory.poses[:, :2]).min() >= 0.5


def test_hallway_facts_and_drift_growth():
    res = run_scenario('hallway', 11, laser=None)
    assert res.path_length == pytest.approx(20.0, abs=0.3)
    assert len(res.world.corners()) == 28
    assert res.world.clearance(res.trajectory.poses[:, :2]).min() >= 0.5
    t, o = res.trajectory.poses, res.odometry.poses
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(t[:, :2], axis=0).T))])
    err = np.hypot(*(o[:, :2] - t[:, :2]).T)
    e25, e50 = err[np.searchsorted(s, 0.25 * s[-1])], err[np.searchsorted(s, 0.5 * s[-1])]
    e100 = err[-1]
    # Systematic heading drift (k2 != k1) makes the position error grow ~ distance^2.
    assert e25 < e50 < e100 and e100 > 2.0 * e50 and e100 > 1.0


def test_exact_model_odometry_equals_truth():
    res = run_scenario('office', 4, robot=EXACT, laser=None, sonar=None)
    truth = res.of_type(TruthSample)
    odo = res.of_type(OdometrySample)
    assert len(truth) == len(odo) > 1000
    for t, o in zip(truth, odo):
        assert t.stamp_ns == o.stamp_ns
        assert o.pose[:2] == pytest.approx(t.pose[:2], abs=1e-9)
        assert abs(wrap_angle(o.pose[2] - t.pose[2])) <= 1e-9
        assert o.twist == pytest.approx(t.twist, abs=1e-12)


def test_calibration_run_markers(calibration):
    runs = calibration.runs
    assert calibration.of_type(RunMarker) == list(runs)
    kinds = [r.kind for r in runs]
    assert kinds.count('straight') == 10
    assert kinds.count('turn_ccw') == 5 and kinds.count('turn_cw') == 5
    assert kinds[:4] == ['straight', 'turn_ccw', 'straight', 'turn_cw']
    groups = [r.group for r in runs]
    assert groups == ['calibration'] * 10 + ['validation'] * 10
    for g in ('calibration', 'validation'):
        assert sum(r.group == g and r.kind == 'straight' for r in runs) == 5
    assert calibration.counts()['ScanSample'] == calibration.counts()['SonarSample'] == 0
    for prev, r in zip(runs, runs[1:]):
        assert r.start_ns - prev.end_ns == pytest.approx(1.0e9, abs=1e8)  # ~1 s stop
    traj = calibration.trajectory
    for r in runs:
        assert r.stamp_ns == r.end_ns > r.start_ns
        assert np.array_equal(r.start_pose, calibration.truth_at(r.start_ns))
        assert np.array_equal(r.end_pose, calibration.truth_at(r.end_ns))
        k0 = (r.start_ns - traj.start_ns) // traj.step_ns
        k1 = (r.end_ns - traj.start_ns) // traj.step_ns
        wheels = traj.wheel_speeds[k0:k1]
        if r.kind == 'straight':
            assert np.array_equal(wheels[:, 0], wheels[:, 1])
            nominal = wheels[:, 0].sum() * calibration.robot.wheel_radius * 0.1
            assert nominal == pytest.approx(5.0, rel=1e-12)
            d = np.hypot(*(r.end_pose[:2] - r.start_pose[:2]))
            assert d == pytest.approx(5.0, abs=0.01)
        else:
            turn = wrap_angle(r.end_pose[2] - r.start_pose[2])
            assert abs(abs(turn) - math.pi) < math.radians(6.0)
            assert np.allclose(wheels[:, 0], -wheels[:, 1])
            assert np.all(np.sign(wheels[:, 1]) == (1 if r.kind == 'turn_ccw' else -1))
    # Robot at rest between runs: no wheel motion outside the runs.
    moving = np.zeros(traj.num_steps, dtype=bool)
    for r in runs:
        moving[(r.start_ns - traj.start_ns) // traj.step_ns:
               (r.end_ns - traj.start_ns) // traj.step_ns] = True
    assert np.all(traj.wheel_speeds[~moving] == 0.0)


def test_calibration_runs_reproducible_from_wheel_speeds(calibration):
    """Integrating a run's measured wheel speeds with the true k1..k3 lands on its end pose."""
    p = calibration.robot
    odo = calibration.of_type(OdometrySample)
    stamps = np.array([o.stamp_ns for o in odo])
    wv = np.array([o.wheel_velocities for o in odo])
    exact = run_scenario('calibration', 3,
                         robot={'wheel_noise_gain': 0.0, 'wheel_noise_floor': 0.0})
    odo_x = exact.of_type(OdometrySample)
    wv_x = np.array([o.wheel_velocities for o in odo_x])
    nominal_err = []
    for r, rx in zip(calibration.runs, exact.runs):
        sel = (stamps > r.start_ns) & (stamps <= r.end_ns)
        end_x = dead_reckon(rx.start_pose, wv_x[sel], p, (p.k1, p.k2, p.k3))[-1]
        assert end_x[:2] == pytest.approx(rx.end_pose[:2], abs=1e-9)
        assert abs(wrap_angle(end_x[2] - rx.end_pose[2])) < 1e-9
        end = dead_reckon(r.start_pose, wv[sel], p, (p.k1, p.k2, p.k3))[-1]
        assert np.hypot(*(end[:2] - r.end_pose[:2])) < 0.3  # wheel noise only
        if r.kind == 'straight':
            nom = dead_reckon(rx.start_pose, wv_x[sel], p)[-1]
            nominal_err.append(abs(wrap_angle(nom[2] - rx.end_pose[2])))
    # Uncalibrated odometry misses the true heading change of every 5 m run by ~4 deg.
    kappa = 2 * (p.k2 - p.k1) / (p.k3 * p.axle_length * (p.k1 + p.k2))
    assert nominal_err == pytest.approx([5.0 * kappa] * 10, rel=0.01)
