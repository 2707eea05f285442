"""Replay round trip: bag -> ``landmark_nav replay`` -> a subscriber gets every message."""

import subprocess
import sys
import time

from landmark_nav.bag import BagReader
from landmark_nav.replay import due_after_start_s, ReplayOptions
from landmark_nav.testing import RosHarness
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import LaserScan
from test_bag import write_small_bag


def test_schedule_scales_with_rate_and_offset():
    opts = ReplayOptions(rate=2.0, start_offset_s=1.0)
    first = 5_000_000_000
    assert due_after_start_s(first + 3_000_000_000, first, opts) == pytest.approx(1.0)
    assert due_after_start_s(first + 500_000_000, first, opts) < 0  # before the offset


@pytest.mark.parametrize('kwargs', [{'rate': 0}, {'rate': -1}, {'rate': float('nan')},
                                    {'start_offset_s': -1}, {'clock_hz': -5},
                                    {'delay_s': -0.1}])
def test_bad_options_are_rejected(kwargs):
    with pytest.raises(ValueError):
        ReplayOptions(**kwargs)


@pytest.mark.dds
def test_replay_delivers_every_message_in_order_with_original_stamps(tmp_path, processes):
    bag = tmp_path / 'b'
    write_small_bag(bag, n=50)
    with BagReader(bag) as reader:
        recorded = [m.data for m in reader.messages(['/scan'])]
    with RosHarness() as ros:
        got = ros.collect('/scan', LaserScan)
        proc = processes.start(
            [sys.executable, '-m', 'landmark_nav.tools.cli', 'replay', str(bag),
             '--topics', '/scan', '--rate', '5', '--wait-for-subscribers', '20'],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 0, out
        assert ros.wait_until(lambda: len(got) >= len(recorded), timeout=10), \
            f'{len(got)} of {len(recorded)} messages arrived'
        # Every message, in order, bit-identical to the recording (stamps included).
        assert len(got) == len(recorded)
        # Compare decoded content (CDR padding bytes are not part of a message's value).
        for i, (received, data) in enumerate(zip(got, recorded)):
            original = deserialize_message(data, LaserScan)
            assert received.header == original.header, f'message {i}: header differs'
            np.testing.assert_array_equal(received.ranges, original.ranges)


@pytest.mark.dds
def test_replay_timing_follows_rate(tmp_path, processes):
    bag = tmp_path / 'b'
    write_small_bag(bag, n=20)  # 1.9 s of scans
    with RosHarness() as ros:
        arrivals = []
        got = ros.collect('/scan', LaserScan)
        proc = processes.start(
            [sys.executable, '-m', 'landmark_nav.tools.cli', 'replay', str(bag),
             '--topics', '/scan', '--rate', '2', '--wait-for-subscribers', '20'],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        seen = 0
        deadline = time.monotonic() + 60
        while seen < 20 and time.monotonic() < deadline:
            if len(got) > seen:
                arrivals.extend([time.monotonic()] * (len(got) - seen))
                seen = len(got)
            time.sleep(0.002)
        proc.communicate(timeout=30)
    assert seen == 20
    span = arrivals[-1] - arrivals[0]
    assert span == pytest.approx(1.9 / 2, abs=0.15)


@pytest.mark.dds
def test_replay_start_offset_clock_and_loop(tmp_path, processes):
    from rosgraph_msgs.msg import Clock
    bag = tmp_path / 'b'
    write_small_bag(bag, n=20)  # scans logged at 1.0, 1.1, ..., 2.9 s
    with RosHarness() as ros:
        got = ros.collect('/scan', LaserScan)
        clock = ros.collect('/clock', Clock)
        proc = processes.start(
            [sys.executable, '-m', 'landmark_nav.tools.cli', 'replay', str(bag),
             '--topics', '/scan', '--rate', '4', '--start-offset', '1.0', '--clock', '50',
             '--loop', '--wait-for-subscribers', '20'],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            # Offset 1.0 s skips the first 10 scans; looping replays the other 10 again.
            assert ros.wait_until(lambda: len(got) >= 20, timeout=30), f'{len(got)} arrived'
        finally:
            proc.terminate()
            proc.communicate(timeout=30)
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in got[:20]]
    assert stamps[:10] == pytest.approx([1.0 + 0.1 * i for i in range(10, 20)])
    assert stamps[10:20] == stamps[:10]
    ticks = [c.clock.sec + c.clock.nanosec * 1e-9 for c in clock]
    assert len(ticks) > 10
    assert min(ticks) >= 2.0 - 1e-9 and max(ticks) <= 2.9 + 1e-9  # bag time, after offset
    first_pass = ticks[:next(i for i in range(1, len(ticks)) if ticks[i] < ticks[i - 1])]
    assert first_pass == sorted(first_pass)  # /clock never goes back within a pass


def _replay(processes, bag, *options):
    return processes.start([sys.executable, '-m', 'landmark_nav.tools.cli', 'replay', str(bag),
                            *options], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           text=True)


@pytest.mark.dds
def test_replay_waits_for_running_subscribers_by_default(tmp_path, processes):
    """Without --wait-for-subscribers the first messages were lost to DDS discovery."""
    bag = tmp_path / 'b'
    write_small_bag(bag, n=20)
    with RosHarness() as ros:
        got = ros.collect('/scan', LaserScan)
        proc = _replay(processes, bag, '--rate', '5')  # no option: the default waits
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 0, out
        assert ros.wait_until(lambda: len(got) >= 20, timeout=10), f'{len(got)} of 20 arrived'
    assert [m.ranges[0] for m in got] == [float(i) for i in range(20)]


@pytest.mark.dds
def test_replay_start_offset_still_publishes_the_latched_topics(tmp_path, processes):
    """--start-offset skipped the latched ground truth recorded at the start of the bag."""
    from geometry_msgs.msg import PoseArray
    from landmark_nav.testing.harness import reliable_qos
    bag = tmp_path / 'b'
    write_small_bag(bag, n=20)  # the latched PoseArray is logged at 1.0 s, the scans after
    with RosHarness() as ros:
        got = ros.collect('/scan', LaserScan)
        latched = ros.collect('/ground_truth/corners', PoseArray, reliable_qos(latched=True))
        proc = _replay(processes, bag, '--rate', '5', '--start-offset', '1.5',
                       '--wait-for-subscribers', '20')
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 0, out
        assert ros.wait_until(lambda: len(got) >= 5 and latched, timeout=10), \
            (len(got), len(latched), out)
    assert len(latched) == 1
    assert [m.ranges[0] for m in got] == [float(i) for i in range(15, 20)]
