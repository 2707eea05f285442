"""``landmark_nav import`` on what real logs bring: broken stamps, sentinels, wrong caps.

Each test writes a small synthetic log that reproduces one quirk seen in real logs and
checks that the import repairs it and says so.
"""

import math

from landmark_nav.importers import import_log, parse_log, repair_stamps
from landmark_nav.importers.sentinels import find_spikes, judge_cap, lms_code_band, \
    range_resolution
from landmark_nav.tools.cli import main as cli_main
import numpy as np
import pytest

from test_importers import _flaser, _read, _wean_l, _write


def _param(name, value):
    return f'PARAM {name} {value} host 0\n'


def _scan_stamps(bag):
    topics, _ = _read(bag)
    return np.array([s for s, _ in topics['/scan']]) * 1e-9, topics


# ------------------------------------------------------------------------ stamps

def test_wrapped_stamps_unwrapped_and_negative_ones_shifted():
    # -0.3, -0.2, -0.1 s written as unsigned 32-bit numbers, then 0.1, 0.2 s
    t, rep = repair_stamps([2 ** 32 - 0.3, 2 ** 32 - 0.2, 2 ** 32 - 0.1, 0.1, 0.2])
    np.testing.assert_allclose(t, [0.1, 0.2, 0.3, 0.5, 0.6], atol=1e-6)
    assert (rep.wrapped, rep.wrapped_coarse, rep.negative) == (3, 0, 3)
    assert rep.offset == pytest.approx(0.4, abs=1e-6)
    assert 'unsigned 32-bit wrapped' in rep.describe()
    assert 'all stamps shifted by +0.4 s' in rep.describe()


@pytest.mark.parametrize('first', [(-1.82, -1.36, -0.91, -0.45), (-0.45, -0.91, -1.36, -1.82)])
def test_log_with_coarse_wrapped_stamps_imports(tmp_path, first):
    # a real log's quirk: four negative stamps, then every stamp 4.29497e+09 (a wrapped
    # negative stamp printed with 6 digits: +-5000 s); the line order is all that is left
    stamps = [f'{s:g}' for s in first] + ['4.29497e+09'] * 30
    text = ''.join(_flaser(np.full(180, 3.0), (0.01 * k, 0, 0), s)
                   for k, s in enumerate(stamps))
    result = import_log(_write(tmp_path / 'w-corrected.log', text), tmp_path / 'bag')
    t, _ = _scan_stamps(tmp_path / 'bag')
    assert len(t) == 34 and t[0] > 0 and np.all(np.diff(t) > 0)
    rep = result.repairs['scan']
    assert (rep.wrapped, rep.wrapped_coarse) == (30, 30) and rep.offset > 0
    assert '30 unsigned 32-bit wrapped stamps unwrapped (30 printed too coarsely' in \
        result.summary
    if first[0] < first[-1]:  # increasing: their period (median step) carries on
        np.testing.assert_allclose(np.diff(t)[:3], np.diff(first), atol=1e-6)
        np.testing.assert_allclose(np.diff(t)[3:], 0.46, atol=1e-6)


def test_negative_stamps_shift_every_stream_alike(tmp_path):
    # a Wean log whose clock starts 5 s before 0: odometry and scans keep their spacing
    text = ''
    for k in range(10):
        t = round(-5.0 + 0.1 * k, 2)
        text += f'O {k} 0 0 {t}\n'
        if k % 2:
            r = ' '.join(['300'] * 180)
            text += f'L {k} 0 0 {k + 25} 0 0 {r} {round(t + 0.05, 2)}\n'
    result = import_log(_write(tmp_path / 'robotdata9.log', text), tmp_path / 'bag')
    t, topics = _scan_stamps(tmp_path / 'bag')
    odom = np.array([s for s, _ in topics['/odom']]) * 1e-9
    assert odom[0] == pytest.approx(0.2, abs=1e-6)  # one scan period after 0
    np.testing.assert_allclose(t - odom[1::2], 0.05, atol=1e-6)
    assert result.repairs['odom'].negative == 10 and result.repairs['scan'].negative == 5
    assert 'all stamps shifted by +5.2 s' in result.summary


def _two_runs(jump_cm):
    """Return a Wean log of two runs, the second ``jump_cm`` further on.

    20 Hz odometry, a scan after every other O line; the clock restarts from 10.4 s to 1.0 s.
    """
    text = ''
    for t0, n, x0 in ((10.0, 9, 0.0), (1.0, 8, 8.0 + jump_cm)):
        for k in range(n):
            t = round(t0 + 0.05 * k, 2)
            text += f'O {x0 + k} 0 0 {t}\n'
            if k % 2:
                text += _wean_l(x0 + k, 0, 0, np.full(180, 300), round(t + 0.05, 2))
    return text


def test_log_of_two_runs_reported_and_each_run_imported_alone(tmp_path):
    # robotdata5's quirk: a second run appended to the log, its clock restarting near 0 and
    # its odometry 11 m away
    log = _write(tmp_path / 'robotdata9.log', _two_runs(1100.0))
    result = import_log(log, tmp_path / 'all')
    assert [(r.line, r.clock_before, r.clock_after) for r in result.restarts] == \
        [(14, 10.4, 1.0)]  # line 14: the first O line of the second run
    assert result.restarts[0].jump == pytest.approx(11.0, abs=1e-9)
    assert 'runs: 2 in one log (the clock restarts where the robot is elsewhere: line 14: ' \
        'clock 10.400 s -> 1.000 s, pose jumps 11.00 m); all imported, joined' in result.summary
    assert 'two runs in one log?' not in result.summary  # the jump is explained
    topics, custom = _read(tmp_path / 'all')
    assert (len(topics['/scan']), len(topics['/odom'])) == (8, 17)
    assert custom['landmark_nav.runs'] == 'starts at lines 1 14; all imported, joined'
    for run, scans, odom, x0 in ((1, 4, 9, 0.0), (2, 4, 8, 11.08)):
        one = import_log(log, tmp_path / f'run{run}', run=run)
        assert f'run {run} imported' in one.summary and one.repairs['odom'].resets == 0
        topics, custom = _read(tmp_path / f'run{run}')
        assert (len(topics['/scan']), len(topics['/odom'])) == (scans, odom)
        assert topics['/odom'][0][1].pose.pose.position.x == pytest.approx(x0, abs=1e-9)
        assert custom['landmark_nav.runs'].endswith(f'run {run} imported')
    assert cli_main(['import', str(log), '--out', str(tmp_path / 'r3'), '--run', '3']) == 2


def test_clock_reset_without_a_pose_jump_is_one_run(tmp_path):
    # the logger restarted, the robot did not move: one run, the stamps shifted to continue
    result = import_log(_write(tmp_path / 'robotdata9.log', _two_runs(0.0)), tmp_path / 'b')
    assert result.restarts == [] and result.repairs['odom'].resets == 1
    assert 'runs:' not in result.summary
    with pytest.raises(ValueError, match='holds 1 run$'):
        import_log(tmp_path / 'robotdata9.log', tmp_path / 'c', run=2)


# --------------------------------------------------------------------- sentinels

def _mm_log(tmp_path, n_scans=60, seed=0):
    """Write a mm-mode LMS log: returns to 30 m, 2.2 % of the beams 32.763 / 32.767 m."""
    rng = np.random.default_rng(seed)
    text = ''
    for k in range(n_scans):
        r = np.round(rng.uniform(0.5, 30.0, 181), 3)
        hole = rng.random(181) < 0.022
        r[hole] = np.where(rng.random(hole.sum()) < 0.5, 32.763, 32.767)
        text += _flaser(r, (0.01 * k, 0, 0), 1.0 + 0.1 * k)
    return _write(tmp_path / 'mm-corrected.log', text)


def test_lms_mm_codes_are_no_return_not_ranges(tmp_path):
    log = parse_log(_mm_log(tmp_path))
    ranges = np.concatenate([s.ranges for s in log.scans])
    marks = {m.value: m for m in log.sentinels}
    assert set(marks) == {32.763, 32.767}
    assert all(m.source == 'LMS code' for m in marks.values())
    n_code = marks[32.763].count + marks[32.767].count
    assert 0.015 < n_code / ranges.size < 0.03
    assert np.isposinf(ranges).sum() == marks[32.767].count  # no echo: +inf
    assert np.isnan(ranges).sum() == marks[32.763].count  # S/N too low: error
    assert np.nanmax(ranges[np.isfinite(ranges)]) <= 30.0
    assert log.sensor.model == 'SICK LMS (mm mode, codes from 32.759 m)'


def test_lms_code_band_follows_the_largest_reading():
    assert lms_code_band([1.001, 8.191]) == (8.183, 8.191)
    assert lms_code_band([1.001, 20.0, 32.767]) == (32.759, 32.767)
    assert lms_code_band([1.01, 20.0]) is None  # cm readings: the cm-mode codes apply
    assert range_resolution([1.01, 20.0]) == 0.01 and range_resolution([1.001]) == 0.001


def test_logger_sentinel_found_from_the_data(tmp_path):
    # a logger that writes 45 m for "no return", under Carmen's default 50 m cap
    rng = np.random.default_rng(1)
    text = ''
    for k in range(50):
        r = np.round(rng.uniform(0.5, 30.0, 180), 2)
        r[rng.random(180) < 0.05] = 45.0
        text += _flaser(r, (0, 0, 0), 1.0 + k)
    log = parse_log(_write(tmp_path / 's-corrected.log', text))
    ranges = np.concatenate([s.ranges for s in log.scans])
    (mark,) = log.sentinels
    assert (mark.value, mark.source) == (45.0, 'data')
    assert mark.count == np.isposinf(ranges).sum() > 0
    assert np.all(ranges[np.isfinite(ranges)] <= 30.0)


def test_repeated_value_inside_the_range_is_not_a_sentinel():
    # a wall seen from a parked robot: 20 % of the readings at 4.00 m, others up to 30 m
    rng = np.random.default_rng(2)
    values = np.round(rng.uniform(0.5, 30.0, 20000), 2)
    values[:4000] = 4.0
    assert find_spikes(values) == []
    # the same value at the top of the range is one
    values[:4000] = 30.5
    assert [s.value for s in find_spikes(values)] == [30.5]


def test_three_adjacent_values_are_a_surface():
    rng = np.random.default_rng(3)
    values = np.round(rng.uniform(0.5, 30.0, 20000), 2)
    values[:3000] = np.repeat([30.49, 30.5, 30.51], 1000)
    assert find_spikes(values) == []
    pair = np.concatenate([np.repeat([30.5, 30.51], 1000), values[3000:]])
    assert sorted(s.value for s in find_spikes(pair)) == [30.5, 30.51]  # 51.14 / 51.15 m


# ----------------------------------------------------------------- range cap

def _capped_log(tmp_path, cap=10.0, seed=4):
    """Write a log whose header states a 10 m cap while 29 % of its readings lie in 10..40 m."""
    rng = np.random.default_rng(seed)
    text = _param('robot_front_laser_max', cap)
    for k in range(40):
        far = rng.random(180) < 0.29
        r = np.where(far, rng.uniform(10.01, 40.0, 180), rng.uniform(0.5, 9.99, 180))
        text += _flaser(np.round(r, 2), (0, 0, 0), 1.0 + k)
    return _write(tmp_path / 'cap-corrected.log', text)


def test_header_cap_overruled_by_the_data(tmp_path):
    log = parse_log(_capped_log(tmp_path))
    ranges = np.concatenate([s.ranges for s in log.scans])
    assert np.isfinite(ranges).all()  # the readings beyond 10 m are returns
    assert log.cap.overruled and 0.25 < log.cap.share < 0.33
    assert log.cap.used == pytest.approx(81.83)  # the LMS cm-mode code band
    assert log.sensor.range_max == pytest.approx(81.83)
    assert 'PARAM robot_front_laser_max 10 m' in log.cap.describe()


def test_header_cap_forced(tmp_path, capsys):
    log = _capped_log(tmp_path)
    header = parse_log(log, range_max_from='header')
    ranges = np.concatenate([s.ranges for s in header.scans])
    assert not header.cap.overruled and np.all(ranges[np.isfinite(ranges)] < 10.0)
    assert 0.25 < np.isposinf(ranges).mean() < 0.33
    assert cli_main(['import', str(log), '--out', str(tmp_path / 'b'),
                     '--range-max-from', 'header']) == 0
    assert 'overruled' not in capsys.readouterr().out


def test_header_cap_kept_when_the_data_agrees(tmp_path):
    log = parse_log(_capped_log(tmp_path, cap=45.0))
    assert not log.cap.overruled and log.cap.above == 0
    # forcing the data: the cap becomes the sensor's code band
    data = parse_log(_capped_log(tmp_path, cap=45.0), range_max_from='data')
    assert data.cap.overruled and data.cap.used == pytest.approx(81.83)


def test_judge_cap_ignores_sentinels_and_codes():
    values = np.concatenate([np.full(500, 5.0), np.full(100, 32.767), np.full(100, 50.0)])
    cap = judge_cap(values, 10.0, sentinels=[50.0], codes=(32.759, 32.767))
    assert (cap.overruled, cap.above) == (False, 0)
    cap = judge_cap(values, 10.0, sentinels=[50.0], mode='data')
    assert cap.overruled and cap.used == 50.0  # the sentinel above the readings
    with pytest.raises(ValueError, match='range cap source'):
        judge_cap(values, 10.0, mode='log')


def test_range_max_from_is_carmen_only(tmp_path):
    r = ' '.join(['300'] * 180)
    log = _write(tmp_path / 'robotdata9.log', f'O 0 0 0 1.0\nL 0 0 0 25 0 0 {r} 1.05\n')
    with pytest.raises(ValueError, match='Carmen logs only'):
        parse_log(log, range_max_from='data')


# ------------------------------------------------------------------ summary

def test_summary_fits_one_screen_and_names_each_repair(tmp_path):
    rng = np.random.default_rng(5)
    text = _param('robot_front_laser_max', 10.0)
    stamps = ['4.29497e+09'] * 3 + ['0', '12.0', '12.0', '13.0'] + [
        str(14.0 + k) for k in range(33)]
    for k, s in enumerate(stamps):
        r = np.where(rng.random(181) < 0.3, rng.uniform(10.01, 30.0, 181),
                     rng.uniform(0.5, 9.99, 181)).round(3)
        r[rng.random(181) < 0.03] = 32.767
        text += _flaser(r, (0.01 * k, 0, 0), s)
    result = import_log(_write(tmp_path / 'q-corrected.log', text), tmp_path / 'bag')
    lines = result.summary.splitlines()
    assert len(lines) <= 12 and max(map(len, lines)) <= 400
    text = result.summary
    for part in ('3 unsigned 32-bit wrapped', '1 repeated', '1 zero',
                 'no-return sentinels: 32.767 m', 'LMS code',
                 'PARAM robot_front_laser_max 10 m', 'overruled by the data, cap 32.759 m'):
        assert part in text, part
    assert math.isfinite(result.repairs['scan'].period)
