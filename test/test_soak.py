"""A short soak of the live SLAM nodes at 40 Hz: latency and memory stay bounded.

``corner_extractor`` and ``ekf_slam`` run as processes (their console entry points, the
shipped defaults plus the office bag's laser mount and noise); ``bag_player`` replays the
office bag's ``/scan`` and ``/odom`` at rate 4 (40 scans/s, 40 Hz odometry) in a loop for
45 s (about 1800 scans; the 120 s bag lasts 30 s at rate 4, so its stamps start again
mid-run: a restarted source, whose sets are new, not late parts of the first run's). It
guards the issue's bounds on a run short enough for the suite; the mechanism found in the
5-minute run (``/path`` never trimmed and republished whole every scan: CPU per scan 22 ->
65-78 ms) has its own test
(``test_ekf_slam_node.py::test_path_is_bounded_and_published_at_the_display_rate``), and a
growth that slow (about 1.2 MB and 10 ms in 45 s) is the 10-minute benchmarks' to find.
Measured here (idle machine): 1821 scans, none dropped, latency p95 over the run 6.9 ms
(corner_extractor) and 4.8 ms (ekf_slam), RSS +0.5 / +0.3 MB from second 15 to 45.

Asserted from each node's ``/diagnostics`` and ``/proc``: the latency p95 over the whole run
and over its last 1000 inputs is at most 100 ms (the issue's target at 1x), the last
window is not slower than the run (no growth), the resident memory grows by at most 2 MB
from second 15 to the end, and what was dropped (a starved CI machine may drop a few) is at
most 1 % and was warned with its drop rate. The 10-minute soaks are
``benchmarks/bench_live_slam.py --loop --seconds 600 --skip 0`` (through the drivers) and
``benchmarks/bench_node_cpu.py --rate 4 --soak 600`` (this set-up).
"""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from landmark_nav.testing import RosHarness
import pytest

pytestmark = pytest.mark.dds
REPO = Path(__file__).resolve().parents[1]
NODES = ('corner_extractor', 'ekf_slam')
SOAK_S = 45.0


def _rss_mb(pid: int) -> float:
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError(f'no VmRSS for {pid}')


def _last_status(diagnostics, node: str) -> dict:
    for array in reversed(diagnostics):
        for status in array.status:
            if status.name == f'{node}: input':
                return {v.key: v.value for v in status.values}
    raise AssertionError(f'no /diagnostics input status from {node}')


def test_live_slam_nodes_at_40_hz_keep_latency_and_memory_bounded(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    for key in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'LANDMARK_NAV_THREADS'):
        env.pop(key, None)  # the nodes' own default: one library thread
    args = {'ekf_slam': ['-p', 'odometry.model:=simulator', '-p', 'laser_pose:=[0.0,0.0,0.0]',
                         '-p', 'laser_sigma_range:=0.01'],
            'corner_extractor': ['-p', 'sigma_r:=0.01']}
    logs = {n: open(tmp_path / f'{n}.log', 'w') for n in NODES}
    procs = {n: subprocess.Popen([sys.executable, '-m', f'landmark_nav.nodes.{n}', '--ros-args']
                                 + args[n], env=env, stdout=logs[n], stderr=subprocess.STDOUT)
             for n in NODES}
    player = None
    try:
        with RosHarness() as ros:
            diagnostics = ros.collect('/diagnostics', DiagnosticArray)
            player = subprocess.Popen(
                [sys.executable, '-m', 'landmark_nav.nodes.bag_player', str(REPO / 'bags/office'),
                 '--topics', '/scan', '/odom', '--rate', '4', '--loop',
                 '--wait-for-subscribers', '30'], env=env, stdout=subprocess.DEVNULL,
                stderr=subprocess.STDOUT)
            assert ros.wait_until(lambda: any(
                s.name == 'ekf_slam: input' and any(
                    v.key == 'processed' and int(v.value) > 0 for v in s.values)
                for a in list(diagnostics) for s in a.status), timeout=60.0), 'no step'
            start = time.monotonic()
            time.sleep(15.0)
            rss0 = {n: _rss_mb(p.pid) for n, p in procs.items()}
            time.sleep(SOAK_S - 15.0)
            rss1 = {n: _rss_mb(p.pid) for n, p in procs.items()}
            assert time.monotonic() - start >= SOAK_S
            player.send_signal(signal.SIGINT)
            player.wait(30)
            time.sleep(2.0)  # the last /diagnostics period
            status = {n: _last_status(list(diagnostics), n) for n in NODES}
    finally:
        if player is not None and player.poll() is None:
            player.kill()
        for p in procs.values():
            p.send_signal(signal.SIGINT)
        for n, p in procs.items():
            p.wait(30)
            logs[n].close()
    print({n: {k: v for k, v in s.items() if 'latency' in k or 'drop' in k or 'proc' in k}
           for n, s in status.items()}, {n: (rss0[n], rss1[n]) for n in NODES})
    scans = int(status['corner_extractor']['processed'])
    assert scans > 30 * SOAK_S  # 40 Hz, less what a loaded machine delays
    for n in NODES:
        values = status[n]
        processed, dropped = int(values['processed']), int(values['dropped'])
        assert float(values['latency_run_p95_ms']) <= 100.0, (n, values)
        assert float(values['latency_p95_ms']) <= 100.0, (n, values)
        assert float(values['latency_p95_ms']) <= 1.5 * float(values['latency_run_p95_ms']) + 5
        assert rss1[n] - rss0[n] <= 2.0, (n, rss0[n], rss1[n])
        assert dropped <= 0.01 * (processed + dropped), (n, values)
        if dropped:  # said, with the rate
            assert 'drop rate' in (tmp_path / f'{n}.log').read_text(), n
        assert 'Traceback' not in (tmp_path / f'{n}.log').read_text()
