"""Clock filter: 24-bit counter unwrapping, min filter against arrival jitter, TM round trips."""

import math

from landmark_nav.drivers.clock_filter import (ClockFilter, CounterUnwrapper,
                                               offset_from_round_trips, PeriodCounter)
import numpy as np
import pytest

WRAP = 1 << 24


def test_unwrapper_counts_through_the_24_bit_wrap():
    u = CounterUnwrapper(24)
    raw = (WRAP - 100 + 25 * np.arange(20)) % WRAP  # wraps after 4 steps
    values = [u.unwrap(int(r)) for r in raw]
    assert [v for v, restarted in values] == list(range(WRAP - 100, WRAP - 100 + 25 * 20, 25))
    assert not any(restarted for _, restarted in values)
    assert u.wraps == 1


def test_unwrapper_reports_a_restart_and_starts_over():
    u = CounterUnwrapper(24)
    assert u.unwrap(500_000) == (500_000, False)
    assert u.unwrap(500_025) == (500_025, False)
    assert u.unwrap(30) == (30, True)  # RS or power cycle: the counter went back
    assert u.unwrap(55) == (55, False)
    assert u.restarts == 1
    with pytest.raises(ValueError):
        u.unwrap(WRAP)


def _stream(n, period=0.025, skew=0.0, jitter_mean=0.003, seed=0, spikes=0.02,
            start_ms=WRAP - 30_000.0, offset=1234.5678, phase=0.00037):
    """Return sensor counters (24-bit, whole ms), true host times and jittered arrivals."""
    rng = np.random.default_rng(seed)
    sensor_true_ms = start_ms + phase * 1e3 + period * 1e3 * np.arange(n)
    counters = np.floor(sensor_true_ms).astype(np.int64) % WRAP
    host_true = offset + (sensor_true_ms / 1e3) / (1.0 + skew)  # host time of each step 0
    q = rng.exponential(jitter_mean, n)
    big = rng.random(n) < spikes
    q[big] += rng.uniform(0.01, 0.05, big.sum())  # occasional long delays (USB, scheduler)
    latency = 0.0188  # modelled: sweep to the end of the scan
    arrivals = host_true + latency + q
    return counters, host_true, arrivals, latency


def _run(counters, arrivals, latency, filt=None):
    u = CounterUnwrapper(24)
    filt = filt or ClockFilter()
    out = []
    for c, a in zip(counters, arrivals):
        ms, restarted = u.unwrap(int(c))
        if restarted:
            filt.reset()
        out.append(filt.update(ms / 1000.0, a - latency))
    return np.array(out)


@pytest.mark.parametrize('skew', [0.0, 100e-6, -100e-6])
def test_stamp_jitter_stays_below_1_ms_with_several_ms_of_arrival_jitter(skew):
    # 40 scans/s for 10 min, across the 24-bit wrap (30 s in); arrival delay exponential
    # (mean 3 ms) plus 2 % of 10-50 ms delays.
    n = 24_000
    counters, host_true, arrivals, latency = _stream(n, skew=skew, seed=3)
    stamps = _run(counters, arrivals, latency)
    settled = slice(400, None)  # after 10 s
    err = stamps[settled] - host_true[settled]
    arrival_err = arrivals[settled] - latency - host_true[settled]
    arrival_jitter = np.max(np.abs(arrival_err - np.median(arrival_err)))
    stamp_jitter = np.max(np.abs(err - np.median(err)))
    assert np.std(arrival_err) > 0.003 and arrival_jitter > 0.01  # the premise: ms jitter
    assert stamp_jitter < 1e-3
    # the filter follows the lowest delays: the bias stays at the floor of the jitter
    assert 0.0 <= np.median(err) < 1e-3
    # consecutive stamps are a steady 25 ms apart (scaled by the clock rate)
    d = np.diff(stamps[settled])
    assert np.max(np.abs(d - 0.025 / (1.0 + skew))) < 1e-3


def test_filter_without_skew_allowance_falls_behind_a_fast_host_clock():
    # The ageing rate must cover the real skew: with none, a host clock running 100 ppm
    # fast leaves the estimate behind by the accumulated drift.
    counters, host_true, arrivals, latency = _stream(24_000, skew=-100e-6, seed=4)
    good = _run(counters, arrivals, latency)
    bad = _run(counters, arrivals, latency, ClockFilter(max_skew=0.0))
    assert np.max(np.abs(good[400:] - host_true[400:])) < 1.5e-3
    assert np.max(np.abs(bad[400:] - host_true[400:])) > 0.01


def test_sensor_clock_reset_restarts_the_filter():
    counters, host_true, arrivals, latency = _stream(2000, seed=5, start_ms=100_000.0)
    counters = counters.copy()
    counters[1000:] = counters[1000:] - counters[1000] + 7  # RS: the counter restarts at 7
    stamps = _run(counters, arrivals, latency)
    err = stamps - host_true
    assert np.max(np.abs(err[1100:] - np.median(err[1100:]))) < 1e-3
    assert np.median(err[1100:]) == pytest.approx(0.0, abs=1e-3)


def test_filter_restarts_after_a_persistent_jump_of_the_host_clock():
    f = ClockFilter(reset_after=0.5, reset_count=5)
    for k in range(100):
        f.update(k * 0.025, 10.0 + k * 0.025)
    for k in range(100, 104):  # host clock jumped 2 s: 4 samples are not enough
        assert f.update(k * 0.025, 12.0 + k * 0.025) == pytest.approx(10.0 + k * 0.025,
                                                                      abs=1e-3)
    assert f.update(104 * 0.025, 12.0 + 104 * 0.025) == pytest.approx(12.0 + 104 * 0.025)
    assert f.resets == 1


def test_round_trip_offset_intersects_the_intervals():
    rng = np.random.default_rng(7)
    offset = 5000.123456
    samples = []
    t = 100.0
    for _ in range(10):
        send = t
        latch = send + rng.uniform(0.0002, 0.001)
        recv = latch + rng.uniform(0.0002, 0.001)
        sensor_ms = math.floor((latch - offset) * 1000.0)
        samples.append((send, sensor_ms / 1000.0, recv))
        t = recv + rng.uniform(0.0, 0.002)
    est, half = offset_from_round_trips(samples)
    assert abs(est - offset) <= half + 1e-12
    best_single = min(recv - send + 0.001 for send, _, recv in samples) / 2.0
    assert half < 0.75 * best_single  # intersecting the samples beats the best one alone


def test_round_trip_offset_falls_back_to_the_shortest_round_trip():
    samples = [(0.0, -9.9995, 0.002), (1.0, -8.0, 1.0005)]  # inconsistent intervals
    est, half = offset_from_round_trips(samples)
    assert est == pytest.approx(0.5 * ((1.0 - (-8.0 + 0.001)) + (1.0005 + 8.0)))
    with pytest.raises(ValueError):
        offset_from_round_trips([])


def test_period_counter_counts_scans_through_arrival_delays():
    rng = np.random.default_rng(9)
    period = 2.0 / 75.0  # 0.5 deg scans: two mirror revolutions
    steps = rng.choice([1, 1, 1, 2, 8], 500)  # regular, a lost scan, a slow line
    k = np.concatenate([[0], np.cumsum(steps)])
    delays = rng.uniform(0.0, 0.89 * period, k.size)  # up to 9/10 of a period late
    delays[::7] = 0.0002  # now and then a prompt one
    arrivals = 50.0 + k * period + delays
    counter, filt = PeriodCounter(period), ClockFilter()
    got = []
    for a in arrivals:
        sensor, n = counter.advance(a)
        counter.settle(filt.update(sensor, a))
        got.append(n)
    assert got[1:] == steps.tolist()
    assert counter.count == k[-1]


def test_period_counter_does_not_undercount_after_a_late_scan():
    # A serial line needs 7.3 periods per scan, so scans are at least 8 periods apart; the
    # first one arrives 2.6 periods late: the next gap looks like 5.4 periods.
    period = 1.0 / 75.0
    k = 8 * np.arange(20)
    arrivals = 10.0 + k * period + 0.0002
    arrivals[0] += 2.6 * period
    counter, filt = PeriodCounter(period), ClockFilter()
    got, stamps = [], []
    for a in arrivals:
        sensor, n = counter.advance(a, min_steps=8)
        stamps.append(filt.update(sensor, a))
        counter.settle(stamps[-1])
        got.append(n)
    assert got[1:] == [8] * 19
    truth = 10.0 + k * period
    assert np.all(np.abs(np.array(stamps[1:]) - truth[1:]) < 0.5e-3)
    counter.reset()
    counter.advance(0.0)
    counter.settle(0.0)
    assert counter.advance(5.4 * period)[1] == 5  # without the bound: one scan every 5
