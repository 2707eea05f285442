"""Tests of ``landmark_nav import``: parsers, stamp repair, drift model, bags, real logs."""

import gzip
import math
from pathlib import Path
import subprocess
import sys

from landmark_nav.bag import BagReader
from landmark_nav.conversions import odometry_to_pose, scan_to_data
from landmark_nav.importers import import_log, LineError, parse_drift_model, parse_log, \
    propagate_covariance, repair_stamps, synthetic_odometry
from landmark_nav.importers.breezyslam import RoverGeometry, ticks_to_odometry
from landmark_nav.importers.carmen import scan_geometry
from landmark_nav.importers.drift import DriftModel
from landmark_nav.importers.stamps import GLITCH_MAX
from landmark_nav.testing import shared_data
from landmark_nav.tools.cli import main as cli_main
import numpy as np
import pytest

F32 = {'rtol': 1e-6, 'atol': 1e-6}


def _read(bag):
    """Return ({topic: [(stamp_ns, msg)]}, custom_data) of a bag."""
    out = {}
    with BagReader(bag) as reader:
        custom = reader.custom_data
        for topic, stamp, msg in reader.decoded():
            out.setdefault(topic, []).append((stamp, msg))
    return out, custom


def _flaser(ranges, pose, stamp, kind='FLASER'):
    r = ' '.join(f'{v:g}' for v in ranges)
    p = ' '.join(f'{v:g}' for v in pose)
    return f'{kind} {len(ranges)} {r} {p} {p} {stamp} host {stamp}\n'


def _write(path, text, gz=False):
    if gz:
        with gzip.open(path, 'wt') as f:
            f.write(text)
    else:
        path.write_text(text)
    return path


def _ranges(n, seed):
    return np.round(np.random.default_rng(seed).uniform(0.5, 20.0, n), 2)


# ------------------------------------------------------------------------------ carmen

def test_carmen_corrected_round_trip(tmp_path):
    r0, r1, r2 = _ranges(180, 0), _ranges(180, 1), _ranges(180, 2)
    r1[5], r1[6], r1[7], r1[8] = 50.0, 81.91, 81.87, 81.83  # cap, no echo, S/N, above max
    poses = [(1.0, 2.0, 0.1), (1.5, 2.1, 0.2), (2.0, 2.3, 0.4)]
    text = ('# comment\nPARAM robot_frontlaser_offset 0.12 nohost 0\n'
            'ODOM 0 0 0 0 0 0 0.5 host 0.5\n'
            + _flaser(r0, poses[0], 1.25) + 'NEFF 30\n' + _flaser(r1, poses[1], 1.5)
            + _flaser(r2, poses[2], 1.75))
    log = _write(tmp_path / 'x-corrected.log.gz', text, gz=True)
    result = import_log(log, tmp_path / 'bag')
    topics, custom = _read(tmp_path / 'bag')
    assert set(topics) == {'/scan', '/odom', '/ground_truth/odom'}
    scans = [scan_to_data(m) for _, m in topics['/scan']]
    assert [s.stamp_ns for s in scans] == [1_250_000_000, 1_500_000_000, 1_750_000_000]
    np.testing.assert_allclose(scans[0].ranges, r0, **F32)
    expected = r1.copy()
    expected[[5, 6, 8]] = np.inf
    expected[7] = np.nan
    np.testing.assert_allclose(scans[1].ranges, expected, **F32)
    assert scans[0].frame_id == 'laser'
    assert scans[0].angle_min == pytest.approx(-math.pi / 2, abs=1e-6)
    assert scans[0].angle_increment == pytest.approx(math.radians(1.0), abs=1e-7)
    assert scans[0].range_max == pytest.approx(50.0)
    gt = np.array([odometry_to_pose(m).pose for _, m in topics['/ground_truth/odom']])
    # the pose fields are the laser's: the robot is 0.12 m behind it
    back = np.column_stack((-0.12 * np.cos(gt[:, 2]), -0.12 * np.sin(gt[:, 2]), 0 * gt[:, 2]))
    np.testing.assert_allclose(gt, np.array(poses) + back, atol=1e-9)
    assert topics['/ground_truth/odom'][0][1].header.frame_id == 'map'
    odom = topics['/odom']
    assert odom[0][1].header.frame_id == 'odom' and odom[0][1].child_frame_id == 'base_link'
    assert custom['landmark_nav.laser_mount'] == '0.12 0 0'
    assert custom['landmark_nav.odometry'] == 'synthetic'
    assert custom['landmark_nav.drift_seed'] == '0'
    assert custom['landmark_nav.drift_model'] == 'k_d=0.05 k_theta=0.05 k_dtheta=0.1'
    assert parse_drift_model(custom['landmark_nav.drift_model']) == DriftModel(name='custom')
    assert custom['landmark_nav.laser_sigma_range'] == '0.01'
    assert custom['landmark_nav.source'] == f'carmen {log.resolve()}'
    assert 'seed 0' in result.summary and 'NEFF x1' in result.summary


def test_carmen_raw_uses_odom_lines(tmp_path):
    text = ('ODOM 0 0 0 0 0 0 1.0 h 1.0\nODOM 0.1 0 0.01 0 0 0 1.1 h 1.1\n'
            + _flaser(_ranges(181, 3), (0.1, 0, 0.01), 1.15)
            + 'ODOM 0.2 0.01 0.02 0 0 0 1.2 h 1.2\n')
    log = _write(tmp_path / 'run.log', text)
    import_log(log, tmp_path / 'bag')
    topics, custom = _read(tmp_path / 'bag')
    assert set(topics) == {'/scan', '/odom'}
    poses = [odometry_to_pose(m).pose for _, m in topics['/odom']]
    np.testing.assert_allclose(poses, [(0, 0, 0), (0.1, 0, 0.01), (0.2, 0.01, 0.02)],
                               atol=1e-9)
    assert custom['landmark_nav.odometry'] == 'raw'
    assert 'landmark_nav.drift_seed' not in custom
    with pytest.raises(ValueError, match='raw odometry'):
        import_log(log, tmp_path / 'bag2', drift='pioneer')


def test_carmen_max_range_option(tmp_path):
    ranges = np.array([1.0, 8.19, 8.191, 20.0] + [2.0] * 176)
    log = _write(tmp_path / 'mm-corrected.log', _flaser(ranges, (0, 0, 0), 1.0))
    assert np.isfinite(parse_log(log).scans[0].ranges[:4]).all()  # default cap 50 m
    scan = parse_log(log, max_range=8.191).scans[0]
    np.testing.assert_array_equal(scan.ranges[:4], [1.0, 8.19, np.inf, np.inf])
    with pytest.raises(ValueError, match='Carmen logs only'):
        parse_log(_write(tmp_path / 'exp3.dat', _breezy_line(1, 0, 0, np.ones(682) * 900)),
                  max_range=4.0)


@pytest.mark.parametrize('n, angle_max_deg', [(180, 89.0), (181, 90.0), (360, 89.5),
                                              (361, 90.0)])
def test_flaser_beam_geometry(n, angle_max_deg):
    a0, inc = scan_geometry(n)
    assert math.degrees(a0) == pytest.approx(-90.0)
    assert math.degrees(a0 + (n - 1) * inc) == pytest.approx(angle_max_deg)


@pytest.mark.parametrize('n', [400, 401, 90, 182])
def test_flaser_unknown_beam_count_needs_fov(tmp_path, n):
    line = _flaser(np.ones(n), (0, 0, 0), 1.0)
    log = _write(tmp_path / 'f-corrected.log',
                 line + line.replace(' 1.0 host 1.0', ' 2.0 host 2.0'))
    for lenient in (False, True):  # not a malformed line: --lenient does not skip it
        with pytest.raises(LineError, match=rf'f-corrected.log:1: FLASER: {n} readings: '
                                            r'beam geometry unknown.*--fov'):
            parse_log(log, lenient=lenient)
    scan = parse_log(log, fov=100.0).scans[0]
    assert math.degrees(scan.angle_min) == pytest.approx(-50.0, abs=1e-12)
    assert math.degrees(scan.angle_increment) * (n - 1) == pytest.approx(100.0, abs=1e-12)
    with pytest.raises(ValueError, match='--fov applies to Carmen logs only'):
        parse_log(_write(tmp_path / 'exp3.dat', _breezy_line(1, 0, 0, np.ones(682) * 900)),
                  fov=100.0)


def test_robotlaser1_geometry_mount_and_max_range(tmp_path):
    n, res = 241, math.radians(0.5)
    start, max_range = math.radians(-60.0), 30.0
    lines = []
    for k, stamp in enumerate((2.0, 2.2)):
        ranges = _ranges(n, 10 + k)
        ranges[0] = 30.0
        robot = np.array([1.0 + k, 2.0, 0.5])
        # laser 0.2 m ahead and 0.05 m left of the robot centre, yawed by 0.1 rad
        off = np.array([0.2, 0.05])
        c, s = math.cos(robot[2]), math.sin(robot[2])
        laser = (robot[0] + c * off[0] - s * off[1], robot[1] + s * off[0] + c * off[1],
                 robot[2] + 0.1)
        lines.append(
            f'ROBOTLASER1 0 {start} {n * res} {res} {max_range} 0.01 0 {n} '
            + ' '.join(f'{v:g}' for v in ranges) + ' 2 7 7 '
            + ' '.join(f'{v:.9f}' for v in (*laser, *robot))
            + f' 0 0 0.3 0.2 0 {stamp} host {stamp}\n')
        lines.append(_flaser(ranges[:180], robot, stamp))  # duplicate: ignored
    log = _write(tmp_path / 'robot.clf', ''.join(lines))
    parsed = parse_log(log)
    assert len(parsed.scans) == 2 and parsed.ignored['FLASER'] == 2
    scan = parsed.scans[0]
    assert scan.angle_min == pytest.approx(start) and scan.angle_increment == pytest.approx(res)
    assert scan.ranges[0] == math.inf and np.isfinite(scan.ranges[1:]).all()
    np.testing.assert_allclose(parsed.mount, (0.2, 0.05, 0.1), atol=1e-6)
    assert parsed.sensor.range_max == max_range
    np.testing.assert_allclose(parsed.odom_poses[1], (2.0, 2.0, 0.5))  # raw: robot pose


def test_carmen_raw_paired_with_reference(tmp_path):
    ranges = [_ranges(180, 20 + k) for k in range(4)]
    raw = ''.join(_flaser(r, (k * 0.5, 0, 0), 10.0 + k) for k, r in enumerate(ranges))
    corrected = ''.join(_flaser(ranges[k], (k * 0.49, 0.01 * k, 0.002), 10.0 + k)
                        for k in (1, 3))
    raw_log = _write(tmp_path / 'run.clf', raw)
    ref_log = _write(tmp_path / 'run-corrected.log', corrected)
    result = import_log(raw_log, tmp_path / 'bag', reference=ref_log)
    topics, custom = _read(tmp_path / 'bag')
    gt = topics['/ground_truth/odom']
    assert [s for s, _ in gt] == [11_000_000_000, 13_000_000_000]
    np.testing.assert_allclose([odometry_to_pose(m).pose for _, m in gt],
                               [(0.49, 0.01, 0.002), (1.47, 0.03, 0.002)], atol=1e-9)
    assert len(topics['/odom']) == 4 and custom['landmark_nav.odometry'] == 'raw'
    assert '2 scans paired, 0 reference scans without' in result.summary
    other = _write(tmp_path / 'other.log', _flaser(_ranges(180, 99), (0, 0, 0), 1.0))
    with pytest.raises(ValueError, match='not the same run'):
        import_log(raw_log, tmp_path / 'bag2', reference=other, poses='raw')


def _odom(pose, stamp):
    return 'ODOM ' + ' '.join(f'{v:.9f}' for v in pose) + f' 0 0 0 {stamp} h {stamp}\n'


def test_carmen_odometry_rebuilt_from_reanchored_odom_lines(tmp_path):
    from landmark_nav.geometry import compose
    a, b, c = np.array([1.0, 2.0, 0.3]), np.array([1.52, 2.1, 0.33]), np.array([2.0, 2.3, 0.5])
    u1, u2 = np.array([0.5, 0.0, 0.02]), np.array([0.3, 0.05, 0.1])
    text = (_flaser(_ranges(180, 0), a, 1.0) + _odom(a, 0)
            + _odom(compose(a, u1 / 2), 1.5) + _odom(compose(a, u1), 2.0)
            + _flaser(_ranges(180, 1), b, 2.0) + _odom(b, 0) + _odom(compose(b, u2), 3.0)
            + _flaser(_ranges(180, 2), c, 3.0) + _odom(c, 0))
    log = _write(tmp_path / 'o-corrected.log', text)
    result = import_log(log, tmp_path / 'bag', odom_lines=True)
    topics, custom = _read(tmp_path / 'bag')
    odom = np.array([odometry_to_pose(m).pose for _, m in topics['/odom']])
    np.testing.assert_allclose(odom, [a, compose(a, u1), compose(compose(a, u1), u2)],
                               atol=1e-8)
    assert [s for s, _ in topics['/odom']] == [s for s, _ in topics['/scan']]
    assert custom['landmark_nav.odometry'] == 'raw' and len(topics['/ground_truth/odom']) == 3
    assert '3 re-anchoring ODOM lines dropped' in result.summary
    bad = _write(tmp_path / 'p-corrected.log', text.replace(_odom(b, 0), _odom(a, 0)))
    with pytest.raises(ValueError, match=r'p-corrected.log:\d+: this ODOM line does not'):
        import_log(bad, tmp_path / 'bag2', odom_lines=True)


def test_real_carmen_odom_lines(tmp_path):
    log = shared_data('carmen', 'aces-corrected.log.gz')
    result = import_log(log, tmp_path / 'a', odom_lines=True)
    assert result.odometry == 'raw' and result.counts['/odom'] == 440
    odom, ref = result.log.odom_poses, result.log.reference_poses
    # raw odometry: the increments differ from the corrected ones by a few cm per scan and
    # drift to metres over the 323 m run (measured: median 5.1 cm per step, 4.2 m at the end)
    from landmark_nav.geometry import relative
    du = np.array([relative(odom[k], odom[k + 1]) - relative(ref[k], ref[k + 1])
                   for k in range(len(odom) - 1)])
    assert np.median(np.hypot(du[:, 0], du[:, 1])) == pytest.approx(0.051, abs=0.001)
    assert np.hypot(*(odom[-1, :2] - ref[-1, :2])) == pytest.approx(4.2, abs=0.1)


# -------------------------------------------------------------------------------- wean

def _wean_l(x, y, th, ranges_cm, ts, offset=25.0):
    xl, yl = x + offset * math.cos(th), y + offset * math.sin(th)
    r = ' '.join(str(int(v)) for v in ranges_cm)
    return f'L {x} {y} {th} {xl} {yl} {th} {r} {ts}\n'


def test_wean_units_mount_and_codes(tmp_path):
    cm = np.arange(100, 280)
    cm[0], cm[1], cm[2] = 8183, 8191, 8187
    text = ('O 100.0 -50.0 0.3 0.05\n' + _wean_l(100.0, -50.0, 0.3, cm, 0.07)
            + 'O 110.0 -48.0 0.32 0.15\n')
    import_log(_write(tmp_path / 'robotdata9.log', text), tmp_path / 'bag')
    topics, custom = _read(tmp_path / 'bag')
    assert set(topics) == {'/scan', '/odom'}
    scan = scan_to_data(topics['/scan'][0][1])
    assert len(scan.ranges) == 180
    assert scan.angle_min == pytest.approx(-math.pi / 2, abs=1e-6)
    assert scan.angle_increment == pytest.approx(math.pi / 180, abs=1e-7)
    assert scan.ranges[0] == math.inf and scan.ranges[1] == math.inf
    assert math.isnan(scan.ranges[2])
    np.testing.assert_allclose(scan.ranges[3:], cm[3:] / 100.0, **F32)
    poses = [odometry_to_pose(m).pose for _, m in topics['/odom']]
    np.testing.assert_allclose(poses, [(1.0, -0.5, 0.3), (1.1, -0.48, 0.32)], atol=1e-9)
    assert custom['landmark_nav.laser_mount'] == '0.25 0 0'


def test_lms_zero_reading_is_too_close(tmp_path):
    # the LMS "no distance" value 0 is -inf (REP 117 too close), as the live LMS driver
    # publishes it; a negative reading cannot come from the sensor: NaN
    ranges = _ranges(180, 3)
    ranges[0], ranges[1] = 0.0, -1.0
    result = import_log(_write(tmp_path / 'z-corrected.log', _flaser(ranges, (0, 0, 0), 1.0)
                               + _flaser(ranges, (0.1, 0, 0), 2.0)), tmp_path / 'bag')
    scan = scan_to_data(_read(tmp_path / 'bag')[0]['/scan'][0][1])
    assert scan.ranges[0] == -math.inf and math.isnan(scan.ranges[1])
    assert '2 error beams (NaN), 2 too-close beams (-inf)' in result.summary
    cm = np.full(180, 300)
    cm[5] = 0
    wean = parse_log(_write(tmp_path / 'robotdata8.log', _wean_l(1, 2, 0.1, cm, 0.5)))
    assert wean.scans[0].ranges[5] == -math.inf


# -------------------------------------------------------------------------- breezyslam

def _breezy_line(stamp_us, left, right, mm):
    return (f'{stamp_us} 0 {left} {right} ' + ' '.join(['0'] * 20) + ' '
            + ' '.join(str(int(v)) for v in mm) + ' 0\n')


def test_breezyslam_ticks_geometry_and_codes(tmp_path):
    mm = np.full(682, 1500)
    mm[0], mm[1], mm[2] = 0, 7, 19  # URG codes: no return, error, error
    text = (_breezy_line(1_000_000, 100, 200, mm) + _breezy_line(1_100_000, 2100, 2200, mm)
            + _breezy_line(1_200_000, 2100, 4200, mm))
    import_log(_write(tmp_path / 'exp9.dat', text), tmp_path / 'bag')
    topics, custom = _read(tmp_path / 'bag')
    scan = scan_to_data(topics['/scan'][0][1])
    assert len(scan.ranges) == 682
    assert math.degrees(scan.angle_min) == pytest.approx(-340 * 360 / 1024, abs=1e-4)
    assert math.degrees(scan.angle_increment) == pytest.approx(360 / 1024, abs=1e-5)
    assert scan.ranges[0] == math.inf and np.isnan(scan.ranges[1:3]).all()
    np.testing.assert_allclose(scan.ranges[3:], 1.5, **F32)
    poses = np.array([odometry_to_pose(m).pose for _, m in topics['/odom']])
    # 2000 ticks = 180 deg on both wheels: D = r (pi + pi), no turn; then the right wheel
    # alone turns 180 deg: D = r pi, dth = (r / b) pi.
    r, b = RoverGeometry.wheel_radius, RoverGeometry.half_axle
    np.testing.assert_allclose(poses[1], (2 * math.pi * r, 0, 0), atol=1e-9)
    dth = r / b * math.pi
    np.testing.assert_allclose(poses[2], (2 * math.pi * r + math.pi * r * math.cos(dth / 2),
                                          math.pi * r * math.sin(dth / 2), dth), atol=1e-9)
    assert custom['landmark_nav.laser_mount'] == '0.145 0 0'
    assert [s for s, _ in topics['/scan']] == [1_000_000_000, 1_100_000_000, 1_200_000_000]


def test_ticks_to_odometry_turns_left_when_right_wheel_leads():
    poses = ticks_to_odometry([0, 0, 0], [0, 100, 200])
    assert poses[-1, 2] > 0 and poses[-1, 1] > 0


# ------------------------------------------------------------------------ stamp repair

def test_repeated_stamps_spread_between_neighbours():
    t, rep = repair_stamps([10.0, 10.0, 10.0, 10.0, 12.0, 13.0])
    np.testing.assert_allclose(t, [10.0, 10.5, 11.0, 11.5, 12.0, 13.0])
    assert rep.repeated == 3 and rep.total == 3


def test_zero_and_isolated_backward_stamps_interpolated():
    t, rep = repair_stamps([0.0, 1.0, 2.0, 1.5, 4.0, 0.0, 6.0])
    np.testing.assert_allclose(t, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    assert (rep.zero, rep.backward, rep.resets) == (2, 1, 0)


def test_clock_reset_shifts_the_rest():
    t, rep = repair_stamps([5.0, 5.1, 5.2, 0.1, 0.2])
    np.testing.assert_allclose(t, [5.0, 5.1, 5.2, 5.3, 5.4])
    assert rep.resets == 1 and rep.backward == 0


def test_backward_glitch_of_several_samples_is_not_a_reset():
    # a two-sample glitch: the later stamps 4, 5, 6 are correct and must not move
    t, rep = repair_stamps([1.0, 2.0, 3.0, 1.5, 1.6, 4.0, 5.0, 6.0])
    np.testing.assert_allclose(t, [1.0, 2.0, 3.0, 3 + 1 / 3, 3 + 2 / 3, 4.0, 5.0, 6.0])
    assert (rep.backward, rep.resets) == (2, 0)


def test_backward_run_longer_than_glitch_max_is_a_reset():
    # the new clock passes the old one after GLITCH_MAX + 1 stamps: a reset, not a glitch
    n = GLITCH_MAX + 1
    stamps = [10.0, 11.0, 12.0] + [1.0 + k for k in range(n + 3)]
    t, rep = repair_stamps(stamps)
    np.testing.assert_allclose(t, 10.0 + np.arange(len(stamps)))
    assert (rep.backward, rep.resets) == (0, 1)


def test_non_finite_stamps_counted():
    t, rep = repair_stamps([1.0, 2.0, 3.0, math.nan, 5.0, math.inf, 7.0])
    np.testing.assert_allclose(t, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
    assert rep.nonfinite == 2 and rep.total == 2
    assert rep.describe().endswith(', 2 non-finite')


def test_all_equal_stamps_use_fallback_period():
    t, rep = repair_stamps([7.0] * 4, fallback_period=0.5)
    np.testing.assert_allclose(t, [7.0, 7.5, 8.0, 8.5])
    assert rep.period_fallback and rep.repeated == 3
    assert 'no distinct stamps: 0.5 s period assumed' in rep.describe()


def test_good_stamps_untouched():
    stamps = np.cumsum(np.random.default_rng(1).uniform(0.05, 0.2, 50))
    t, rep = repair_stamps(stamps)
    np.testing.assert_array_equal(t, stamps)
    assert rep.total == 0


def test_repairs_reported_in_bag(tmp_path):
    text = ''.join(_flaser(_ranges(180, k), (0.1 * k, 0, 0), s)
                   for k, s in enumerate((3.0, 3.0, 0.0, 4.0, 5.0)))
    result = import_log(_write(tmp_path / 'r-corrected.log', text), tmp_path / 'bag')
    topics, custom = _read(tmp_path / 'bag')
    assert [s for s, _ in topics['/scan']] == [3_000_000_000, 3_333_333_333, 3_666_666_667,
                                               4_000_000_000, 5_000_000_000]
    assert custom['landmark_nav.repairs'] == ('scan: 1 repeated stamps spread, 1 zero, '
                                              '0 backward, 0 clock resets')
    assert custom['landmark_nav.repairs'] in result.summary


def test_clock_reset_shifts_all_streams_alike(tmp_path):
    # odometry at 20 Hz, a scan 50 ms after every other O line; the clock restarts at 1 s
    # after a last O line at 10.4 s. Stream by stream the odometry would be shifted by
    # 10.4 - 1.0 + 0.05 = 9.45 s and the scans by 10.4 - 1.1 + 0.1 = 9.4 s.
    text, raw, first = '', [], []
    for run, (t0, n) in enumerate(((10.0, 9), (1.0, 8))):
        first.append(len(first) and first[-1] + 9)
        for k in range(n):
            t = round(t0 + 0.05 * k, 2)
            text += f'O {k} 0 0 {t}\n'
            if k % 2:
                text += _wean_l(k, 0, 0, np.full(180, 300), round(t + 0.05, 2))
                raw.append((first[run] + k, round(t + 0.05, 2) - t))
    result = import_log(_write(tmp_path / 'robotdata9.log', text), tmp_path / 'w')
    assert result.repairs['scan'].resets == 1 and result.repairs['odom'].resets == 1
    topics, _ = _read(tmp_path / 'w')
    odom = [s for s, _ in topics['/odom']]
    scans = [s for s, _ in topics['/scan']]
    assert len(scans) == len(raw) == 8 and len(odom) == 17
    for (j, delay), s in zip(raw, scans):
        assert s - odom[j] == round(delay * 1e9)  # 50 ms after its O line, as logged


# ---------------------------------------------------------------------- malformed lines

@pytest.mark.parametrize('name, good, bad, rest', [
    ('a-corrected.log', _flaser(np.ones(180), (0, 0, 0), 1.0), 'FLASER 180 1.0 2.0 0 0 0\n',
     _flaser(np.ones(180), (0, 0, 0), 2.0)),
    ('robotdata7.log', _wean_l(1, 2, 0.1, np.full(180, 300), 0.6), 'O 1 2 x 0.7\n',
     'O 1 2 0.1 0.8\n'),
    ('exp7.dat', _breezy_line(1, 0, 0, np.full(682, 900)), '12 0 1 2 3\n',
     _breezy_line(2, 0, 0, np.full(682, 900))),
])
def test_malformed_line_names_file_and_line(tmp_path, capsys, name, good, bad, rest):
    log = _write(tmp_path / name, good + bad + rest)
    with pytest.raises(LineError, match=rf'{name}:2: malformed'):
        parse_log(log)
    assert cli_main(['import', str(log), '--out', str(tmp_path / 'bag')]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and f'{name}:2: malformed' in err
    parsed = parse_log(log, lenient=True)
    assert parsed.skipped == 1
    assert cli_main(['import', str(log), '--out', str(tmp_path / 'bag'), '--lenient']) == 0
    assert 'skipped 1 malformed lines (--lenient)' in capsys.readouterr().out


def test_bad_param_names_its_line(tmp_path):
    log = _write(tmp_path / 'p-corrected.log', 'PARAM robot_frontlaser_offset 0.0 h 0\n'
                 'PARAM robot_frontlaser_offset abc h 0\n'
                 + _flaser(np.ones(180), (0, 0, 0), 1.0))
    with pytest.raises(LineError, match=r'p-corrected.log:2: PARAM robot_frontlaser_offset'):
        parse_log(log)


def test_parsers_do_not_import_ros():
    code = ('import sys; import landmark_nav.importers.carmen, landmark_nav.importers.wean, '
            'landmark_nav.importers.breezyslam, landmark_nav.importers; '
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('rclpy', 'rosbags', 'sensor_msgs', 'nav_msgs') or m == 'landmark_nav.sim'))")
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.strip() == '[]'


def test_cli_errors_are_one_line(tmp_path, capsys):
    assert cli_main(['import', str(tmp_path / 'missing.log'), '--out',
                     str(tmp_path / 'b')]) == 2
    assert 'no log file' in capsys.readouterr().err
    odd = _write(tmp_path / 'odd.txt', 'hello world\n')
    assert cli_main(['import', str(odd), '--out', str(tmp_path / 'b')]) == 2
    assert 'give --format' in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        cli_main(['import', str(odd), '--out', str(tmp_path / 'b'), '--max-scans', '0'])
    assert info.value.code == 2


# ------------------------------------------------------------------------- drift model

def _straight(length, steps):
    x = np.linspace(0.0, length, steps + 1)
    return np.column_stack((x, np.zeros_like(x), np.zeros_like(x)))


def test_drift_spread_matches_model():
    model = DriftModel(k_d=0.05, k_theta=0.05, k_dtheta=0.1)
    n_seeds, length = 2000, 10.0
    ref = _straight(length, 50)
    ref[25:, 2] = 1.0  # a 1 rad turn on the spot half way
    ref = np.vstack((ref[:26], ref[25:]))  # ... as its own step
    finals = np.array([synthetic_odometry(ref, model, s)[-1] for s in range(n_seeds)])
    # heading error: var = k_theta^2 D + k_dtheta^2 |dth| (exact, the errors add up)
    sd_heading = np.std(finals[:, 2] - ref[-1, 2])
    expected = math.sqrt(model.k_theta ** 2 * length + model.k_dtheta ** 2 * 1.0)
    tol = 3.0 / math.sqrt(2 * (n_seeds - 1))  # 3 standard errors of a sample std
    assert sd_heading == pytest.approx(expected, rel=tol)
    # the first-order covariance of /odom describes the spread of the final pose (gains
    # small enough for the linearisation to hold: heading spread ~3 deg)
    small = DriftModel(k_d=0.01, k_theta=0.01, k_dtheta=0.02)
    finals = np.array([synthetic_odometry(ref, small, s)[-1] for s in range(n_seeds)])
    cov = propagate_covariance(ref, small)[-1]
    sample = np.cov((finals - ref[-1]).T)
    for i in range(3):  # sample variance: relative standard error sqrt(2 / (n - 1))
        assert sample[i, i] == pytest.approx(cov[i, i], rel=3 * math.sqrt(2 / (n_seeds - 1)))


def test_drift_along_track_spread():
    model = DriftModel(k_d=0.05, k_theta=0.0, k_dtheta=0.0)
    finals = np.array([synthetic_odometry(_straight(9.0, 30), model, s)[-1, 0]
                       for s in range(2000)])
    assert np.std(finals) == pytest.approx(0.05 * 3.0, rel=3.0 / math.sqrt(2 * 1999))
    assert abs(np.mean(finals) - 9.0) < 3 * 0.15 / math.sqrt(2000)


def test_heading_drift_depends_on_sampling_only_on_a_jittery_reference():
    # sigma_th^2 = k_theta^2 D + k_dtheta^2 |dth| per step (drift.py): on a smooth arc the
    # final heading variance is the same at 10 or 40 poses per metre; with a heading that
    # wiggles by +-1 deg from pose to pose the summed |dth| grows with the sampling
    model = DriftModel(0.0, 0.05, 0.1)

    def var_theta(per_m, jitter):
        s = np.linspace(0.0, 2.0, int(2 * per_m) + 1)
        th = 0.5 * s + jitter * (-1.0) ** np.arange(len(s))
        return propagate_covariance(np.column_stack((np.cos(s), np.sin(s), th)), model)[-1, 2, 2]

    expected = 0.05 ** 2 * 2.0 + 0.1 ** 2 * 1.0  # D = 2 m (chord ~ arc), turned 1 rad
    jitter = math.radians(1.0)
    for per_m in (10, 40):
        assert var_theta(per_m, 0.0) == pytest.approx(expected, rel=5e-4)
    # 10 / m: steps of 0.05 +- 2 jitter rad never change sign: sum |dth| = 1 rad as smooth;
    # 40 / m: 0.0125 +- 2 jitter do, and the 80 steps sum to 80 * 2 jitter = 2.79 rad
    assert var_theta(10, jitter) == pytest.approx(expected, rel=5e-4)
    assert var_theta(40, jitter) == pytest.approx(0.05 ** 2 * 2.0 + 0.1 ** 2 * 80 * 2 * jitter,
                                                  rel=5e-4)


def test_drift_reproducible_by_seed():
    ref = _straight(5.0, 20)
    model = parse_drift_model('pioneer')
    a, b = synthetic_odometry(ref, model, 3), synthetic_odometry(ref, model, 3)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - synthetic_odometry(ref, model, 4)).max() > 1e-3
    np.testing.assert_array_equal(synthetic_odometry(ref, parse_drift_model('none'), 3), ref)


def test_parse_drift_model():
    m = parse_drift_model('k_d=0.02 k_dtheta=0.01')
    assert (m.k_d, m.k_theta, m.k_dtheta) == (0.02, 0.05, 0.01)
    with pytest.raises(ValueError, match='drift model'):
        parse_drift_model('wobbly')


def test_synthetic_odometry_in_bag_follows_seed(tmp_path):
    text = ''.join(_flaser(_ranges(180, k), (0.3 * k, 0.02 * k, 0.05 * k), 1.0 + k)
                   for k in range(6))
    log = _write(tmp_path / 's-corrected.log', text)
    import_log(log, tmp_path / 'a', seed=7)
    import_log(log, tmp_path / 'b', seed=7, drift='k_d=0.1')
    (ta, ca), (_, cb) = _read(tmp_path / 'a'), _read(tmp_path / 'b')
    pa = np.array([odometry_to_pose(m).pose for _, m in ta['/odom']])
    ref = np.array([odometry_to_pose(m).pose for _, m in ta['/ground_truth/odom']])
    np.testing.assert_allclose(pa, synthetic_odometry(ref, DriftModel(), 7), atol=1e-9)
    cov = np.array([odometry_to_pose(m).covariance for _, m in ta['/odom']])
    np.testing.assert_allclose(cov, propagate_covariance(pa, DriftModel()), rtol=1e-6,
                               atol=1e-15)
    assert ca['landmark_nav.drift_seed'] == '7'
    assert cb['landmark_nav.drift_model'] == 'k_d=0.1 k_theta=0.05 k_dtheta=0.1'


# --------------------------------------------------------------------------- real logs

def _check_real(bag, scans, odom, gt, custom_expected):
    topics, custom = _read(bag)
    counts = {t: len(v) for t, v in topics.items()}
    assert counts == {k: v for k, v in
                      {'/scan': scans, '/odom': odom, '/ground_truth/odom': gt}.items() if v}
    for key, value in custom_expected.items():
        assert custom[key] == value
    stamps = [s for s, _ in topics['/scan']]
    assert np.all(np.diff(stamps) > 0)
    return topics, custom


def test_real_carmen_aces(tmp_path):
    log = shared_data('carmen', 'aces-corrected.log.gz')
    import_log(log, tmp_path / 'aces')
    topics, _ = _check_real(tmp_path / 'aces', 440, 440, 440, {
        'landmark_nav.odometry': 'synthetic', 'landmark_nav.laser_mount': '0 0 0',
        'landmark_nav.drift_seed': '0'})
    # the 50 m readings are the log's "no return": 620 of them (counted in the raw file)
    n_inf = sum(int(np.isposinf(scan_to_data(m).ranges).sum()) for _, m in topics['/scan'])
    assert n_inf == 620


def test_real_carmen_belgioioso_repeated_stamps(tmp_path):
    log = shared_data('carmen', 'belgioioso-corrected.log.gz')
    result = import_log(log, tmp_path / 'b', max_scans=100)
    _check_real(tmp_path / 'b', 100, 100, 100, {'landmark_nav.laser_mount': '-0.04 0 0'})
    assert result.repairs['scan'].repeated == 99 and result.repairs['scan'].period_fallback


def test_real_wean_robotdata1(tmp_path):
    log = shared_data('wean', 'robotdata1.log.gz')
    import_log(log, tmp_path / 'w')
    _check_real(tmp_path / 'w', 713, 1505, 0, {'landmark_nav.odometry': 'raw',
                                               'landmark_nav.laser_mount': '0.25 0 0'})


def test_real_wean_robotdata5_clock_reset(tmp_path):
    log = shared_data('wean', 'robotdata5.log.gz')
    result = import_log(log, tmp_path / 'w5')
    assert result.repairs['scan'].resets == 1 and result.repairs['odom'].resets == 1
    # robotdata5 is robotdata1 (lines 1-2218) followed by a second run
    assert [(r.line, round(r.jump, 2)) for r in result.restarts] == [(2219, 11.02)]
    assert 'runs: 2 in one log (the clock restarts where the robot is elsewhere: line 2219: ' \
        'clock 134.998 s -> 0.037 s, pose jumps 11.02 m)' in result.summary


def test_real_breezyslam_exp2(tmp_path, capsys):
    log = shared_data('breezyslam', 'exp2.dat.gz')
    assert cli_main(['import', str(log), '--out', str(tmp_path / 'e')]) == 0
    _check_real(tmp_path / 'e', 641, 641, 0, {'landmark_nav.laser_mount': '0.145 0 0',
                                              'landmark_nav.laser_model': 'Hokuyo URG-04LX'})
    capsys.readouterr()
    assert cli_main(['info', str(tmp_path / 'e')]) == 0
    info = capsys.readouterr().out
    assert '/scan  sensor_msgs/msg/LaserScan  641 msgs' in info
    assert '/odom  nav_msgs/msg/Odometry  641 msgs' in info
