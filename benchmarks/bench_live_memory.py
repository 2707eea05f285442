"""Memory of a live run: the RSS growth of every process, the robot emulator's included.

Run from the repository root::

    python benchmarks/bench_live_memory.py [--minutes 10] [--warmup 1] [--limit-mb 2]

Starts, each as its own process on a private DDS domain, what the README's live run shows:
``landmark_nav emulate robot`` (the P2OS base and the laser on one world), ``landmark_nav
pipeline slam`` (laser_driver, base_driver, corner_extractor, ekf_slam; the UTM-30LX's 40
scans/s thinned to 10 with ``laser_driver.skip=3``) and ``landmark_nav drive --route
office --loop`` (cmd_vel closed on ekf_slam's ``/odometry``) for ``--minutes``. The RSS of
every process (``/proc/<pid>/status`` VmRSS: the emulator, the pipeline's launcher and each
node, the driver) is sampled every 10 s. Printed per process: the RSS after ``--warmup``
minutes (the bounded buffers fill in the first minute: the emulator's 60 s of records,
ekf_slam's queues), at the end, the growth between them, and the growth over the second
half of the run (a leak grows in both halves). Exit status 1 when a process grew by more
than ``--limit-mb`` (or died), else 0.
"""

import argparse
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

from common import live_run

SAMPLE_S = 10.0


def rss_mb(pid: int) -> float:
    """Return the resident set size of a process [MB] (NaN when it is gone)."""
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float('nan')


def pipeline_pids(log: Path) -> dict:
    """Return {node: pid} of the pipeline's nodes (from its launcher's log)."""
    return {node: int(pid) for node, pid in
            re.findall(r'\| (\w+) started \(pid=(\d+)\)', log.read_text())}


def main() -> int:
    """Run the live system; sample and judge every process's RSS."""
    parser = argparse.ArgumentParser(
        description=__doc__.split('\n')[0],
        epilog='No data argument: the run is a closed loop through the emulated robot and the '
               'live drivers (for a recorded bag: bench_node_cpu.py BAG, bench_soak.py --bag '
               'BAG).')
    parser.add_argument('--minutes', type=float, default=10.0, help='length of the run')
    parser.add_argument('--warmup', type=float, default=1.0,
                        help='minutes before the reference RSS is taken (default 1)')
    parser.add_argument('--limit-mb', type=float, default=2.0,
                        help='largest RSS growth allowed per process after the warm-up [MB]')
    parser.add_argument('--domain', type=int, default=102,
                        help="DDS domain (default 102, outside the tests' 20..99)")
    parser.add_argument('--out', default=None, help='keep the logs here')
    args = parser.parse_args()
    if not 0.0 < args.warmup < args.minutes:
        parser.error('need 0 < --warmup < --minutes')

    out, env, cli = live_run(args.domain, args.out, 'live_memory_')
    base_link, laser_link = out / 'p2os', out / 'laser'
    procs = {}
    samples = []  # (seconds since start, {process: RSS MB})
    with open(out / 'emulator.log', 'w') as emu_log, open(out / 'pipeline.log', 'w') as log, \
            open(out / 'drive.log', 'w') as drive_log:
        try:
            procs['emulator'] = subprocess.Popen(
                cli + ['emulate', 'robot', '--link', str(base_link), '--tcp', '0',
                       '--laser-link', str(laser_link)],
                env=env, stdout=emu_log, stderr=subprocess.STDOUT)
            time.sleep(2.0)
            procs['pipeline'] = subprocess.Popen(
                cli + ['pipeline', 'slam', '--set', f'base_driver.port={base_link}',
                       '--set', f'laser_driver.port={laser_link}',
                       '--set', 'laser_driver.skip=3',
                       '--set', 'ekf_slam.odometry.model=simulator'],
                env=env, stdout=log, stderr=subprocess.STDOUT)
            procs['drive'] = subprocess.Popen(
                cli + ['drive', '--route', 'office', '--loop', '--duration',
                       str(60.0 * args.minutes)],
                env=env, stdout=drive_log, stderr=subprocess.STDOUT)
            started = time.monotonic()
            print(f'logs in {out}; {args.minutes:g} min, load average at start '
                  f'{os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)', flush=True)
            period = min(SAMPLE_S, 60.0 * args.minutes / 8.0)   # >= 8 samples a run
            while True:
                time.sleep(period)
                if procs['drive'].poll() is not None:  # the run is over: sample no more
                    break
                pids = {name: p.pid for name, p in procs.items()}
                pids.update(pipeline_pids(out / 'pipeline.log'))
                samples.append((time.monotonic() - started,
                                {name: rss_mb(pid) for name, pid in pids.items()}))
        finally:
            for name in ('drive', 'pipeline', 'emulator'):
                p = procs.get(name)
                if p is not None and p.poll() is None:
                    p.send_signal(signal.SIGINT if name == 'pipeline' else signal.SIGTERM)
                    try:
                        p.wait(timeout=60)
                    except subprocess.TimeoutExpired:
                        p.kill()
                        p.wait()
    return report(samples, args.warmup * 60.0, args.limit_mb)


def report(samples: list, warmup_s: float, limit_mb: float) -> int:
    """Print each process's RSS figures; return 1 if one grew beyond the limit, else 0."""
    ref = next((s for s in samples if s[0] >= warmup_s), None)
    if ref is None or len(samples) < 3:
        print('error: the run ended before the warm-up was over')
        return 1
    end = samples[-1]
    half = min(samples, key=lambda s: abs(s[0] - 0.5 * (ref[0] + end[0])))
    failed = []
    print(f'{"process":18s} {"RSS at " + f"{ref[0] / 60:.1f} min":>14s} '
          f'{"at " + f"{end[0] / 60:.1f} min":>12s} {"growth":>9s} {"2nd half":>9s}')
    for name in sorted(ref[1]):
        a, b, m = ref[1][name], end[1].get(name, float('nan')), half[1].get(name, float('nan'))
        growth = b - a
        print(f'{name:18s} {a:11.1f} MB {b:9.1f} MB {growth:+6.2f} MB {b - m:+6.2f} MB')
        if not growth <= limit_mb:  # NaN (a process gone) fails too
            failed.append(name)
    if failed:
        print(f'FAIL: RSS growth above {limit_mb:g} MB (or the process died): '
              + ', '.join(failed))
        return 1
    print(f'OK: every process grew by at most {limit_mb:g} MB after the warm-up')
    return 0


if __name__ == '__main__':
    sys.exit(main())
