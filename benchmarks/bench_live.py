"""Live SLAM through the nodes as processes: ATE, drops, latency, CPU and memory of every process.

Run from the repository root::

    python benchmarks/bench_live.py [--seconds 120] [--route office] [--laser urg] [--skip 3]
        [--loop] [--rate 1] [--profile NAME] [--memory [--warmup 60] [--limit-mb 2]]
    python benchmarks/bench_live.py --bag BAG [--seconds 120] [--rate 1] [--loop] [--memory]

Two sources of data, each process on a private DDS domain:

* the emulated robot (default): ``landmark_nav emulate robot --truth truth.tum`` (the P2OS
  base and the laser on one world), ``landmark_nav pipeline slam`` (laser_driver +
  base_driver + corner_extractor + ekf_slam with the shipped parameters; the UTM-30LX's
  40 scans/s thinned to 10 with ``laser_driver.skip=3`` unless ``--skip 0``) and
  ``landmark_nav drive --route office`` (cmd_vel closed on ekf_slam's ``/odometry``) for
  ``--seconds``: a closed loop through the live drivers. ``--rate 10`` runs the devices at
  ten times their data rates (400 scans/s with ``--skip 0``, 100 Hz odometry,
  ``base_driver.cycle_time`` 0.01 s) with the robot moving as at rate 1: the nodes cannot
  keep up and must say how much they drop. ``--loop --seconds 600 --skip 0`` is a soak.
* a recorded bag (``--bag BAG``, e.g. one written by ``landmark_nav import`` from a Carmen
  log): ``landmark_nav pipeline replay`` (bag_player + corner_extractor + ekf_slam, ekf_slam
  told the bag's laser mount and odometry model) plays its ``/scan`` and ``/odom`` at
  ``--rate`` times the recorded rate, for ``--seconds`` from its first message or until the
  bag is played and the nodes have drained it.

``--profile NAME`` puts a shipped profile on the pipeline (e.g. ``ekf_slam_chapter``).

Printed: the ATE of ekf_slam's ``/odometry`` and of ``/odom`` against the truth (the
emulator's, in the start frame, which is the odom and map frame: unaligned, and SE(2)-aligned
as evo does; a bag's ``/ground_truth/odom``: SE(2)-aligned only, a recorded reference has a
frame of its own; with ``--loop`` the first pass of the bag), the distance driven,
ekf_slam's resets, the load average (every 5 s) and each process's CPU time over the run,
each node's last ``/diagnostics`` input status (processed, dropped by reason, latency
percentiles over the last 1000 inputs and over the run, messages before a subscription
matched; corner sets stamped before the first odometry are counted as ``before_odometry``,
not as drops), the nodes' drop warnings (throttled, each stating the drop rate), the laser
driver's lost scans and what the emulator could not send.

Memory: the RSS of every process (the emulator or the bag player, the pipeline's launcher,
each node, the driver; ``/proc/<pid>/status`` VmRSS) is sampled every 10 s (at least 8
samples a run) and printed per process: after ``--warmup`` seconds (the bounded buffers fill
in the first minute: the emulator's 60 s of records, ekf_slam's queues), at the end, the
growth between them and over the second half of the run (a leak grows in both halves).
``--memory`` is the memory run: the route or the bag is looped (``--seconds 600`` for ten
minutes) and the exit status is 1 when a process grew by more than ``--limit-mb`` after the
warm-up (or died), else 0.

Offline figures on recorded data through DDS without the drivers: ``bench_node_cpu.py BAG``
(CPU per scan) and ``bench_soak.py --bag BAG`` (latency, CPU and memory against stored
results).
"""

import argparse
import math
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time
from typing import Callable

from bench_node_cpu import cpu_seconds, rss_mb
from common import live_run

SAMPLE_S = 10.0
START_S = 120.0   # longest wait for a replay's first /odom [s]
LOAD_S = 5.0


def alive(measure: Callable[[int], float], pid: int) -> float:
    """Return ``measure(pid)`` (:func:`bench_node_cpu.rss_mb`, ``cpu_seconds``); NaN if gone."""
    try:
        return measure(pid)
    except (OSError, IndexError, ValueError):
        return math.nan


def pipeline_pids(log: Path) -> dict:
    """Return {node: pid} of the pipeline's nodes (from its launcher's log)."""
    return {node: int(pid) for node, pid in
            re.findall(r'\| (\w+) started \(pid=(\d+)\)', log.read_text())}


def parse_arguments() -> argparse.Namespace:
    """Return the command line's arguments (module docstring)."""
    parser = argparse.ArgumentParser(
        description=__doc__.split('\n')[0],
        epilog='Data: --bag BAG replays a recorded bag (e.g. landmark_nav import LOG --out '
               "BAG); without it the emulated robot's world, which a recording cannot "
               "replace for the drivers' closed loop.")
    parser.add_argument('--bag', metavar='BAG', help='replay this bag (a rosbag2 folder with '
                        '/scan and /odom) instead of driving the emulated robot')
    parser.add_argument('--seconds', type=float, default=120.0,
                        help='length of the run [s] (default 120)')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='data rate factor: of the emulated devices (10: the 10x soak) or '
                             "of the bag's replay (default 1: as recorded)")
    parser.add_argument('--loop', action='store_true',
                        help='drive the route or replay the bag again and again (a soak)')
    parser.add_argument('--route', help='emulator: the route drive follows (default office)')
    parser.add_argument('--laser', choices=('urg', 'lms200'),
                        help='emulator: the laser (default urg)')
    parser.add_argument('--skip', type=int,
                        help='emulator: laser_driver.skip for the UTM-30LX (default 3: 10 '
                             'scans/s, as the office bags; 0: all 40)')
    parser.add_argument('--profile', action='append', default=[], metavar='NAME',
                        help='a shipped profile for the pipeline (e.g. ekf_slam_chapter: the '
                        'filter of the figures measured before the real-data defaults)')
    parser.add_argument('--memory', action='store_true',
                        help='the memory run: loop, judge every RSS growth against --limit-mb '
                             '(exit status 1 above it)')
    parser.add_argument('--warmup', type=float, default=60.0,
                        help='seconds before the reference RSS is taken (default 60)')
    parser.add_argument('--limit-mb', type=float, default=2.0,
                        help='--memory: largest RSS growth allowed per process after the '
                             'warm-up [MB] (default 2)')
    parser.add_argument('--domain', type=int, default=101,
                        help="DDS domain (default 101, outside the tests' 20..99: another "
                             "process's odometry on the domain resets the filter)")
    parser.add_argument('--out', default=None, help='keep the logs here')
    args = parser.parse_args()
    emulator_only = [f'--{n}' for n in ('route', 'laser', 'skip') if getattr(args, n) is not None]
    if args.bag and emulator_only:
        parser.error(f'{", ".join(emulator_only)}: for the emulated robot, not with --bag')
    if args.bag and not Path(args.bag, 'metadata.yaml').is_file():
        parser.error(f'--bag {args.bag}: not a rosbag2 folder (no metadata.yaml)')
    if args.memory and not 0.0 < args.warmup < args.seconds:
        parser.error(f'need 0 < --warmup ({args.warmup:g}) < --seconds ({args.seconds:g})')
    args.route, args.laser = args.route or 'office', args.laser or 'urg'
    args.skip = 3 if args.skip is None else args.skip
    args.loop = args.loop or args.memory
    return args


def start(args, out: Path, env: dict, cli: list, logs: dict) -> dict:
    """Start the run's processes; return them by name (the pipeline's nodes come later)."""
    procs = {}
    profiles = [a for name in args.profile for a in ('--profile', name)]
    loop = ['--loop'] if args.loop else []
    if args.bag:
        procs['pipeline'] = subprocess.Popen(
            cli + ['pipeline', 'replay', '--bag', args.bag, '--rate', str(args.rate)]
            + loop + profiles, env=env, stdout=logs['pipeline'], stderr=subprocess.STDOUT)
        return procs
    base_link, laser_link = out / 'p2os', out / 'laser'
    laser_set = ['--set', f'laser_driver.port={laser_link}']
    if args.laser == 'urg' and args.skip:
        laser_set += ['--set', f'laser_driver.skip={args.skip}']
    if args.laser == 'lms200':
        laser_set += ['--set', 'laser_driver.protocol=lms2xx', '--set', 'laser_driver.baud=38400']
    procs['emulator'] = subprocess.Popen(
        cli + ['emulate', 'robot', '--link', str(base_link), '--tcp', '0', '--laser',
               args.laser, '--laser-link', str(laser_link), '--truth', str(out / 'truth.tum'),
               '--rate', str(args.rate)],
        env=env, stdout=logs['emulator'], stderr=subprocess.STDOUT)
    time.sleep(2.0)
    procs['pipeline'] = subprocess.Popen(
        cli + ['pipeline', 'slam', '--set', f'base_driver.port={base_link}',
               '--set', f'base_driver.cycle_time={0.1 / args.rate!r}',
               '--set', 'ekf_slam.odometry.model=simulator'] + laser_set + profiles,
        env=env, stdout=logs['pipeline'], stderr=subprocess.STDOUT)
    procs['drive'] = subprocess.Popen(
        cli + ['drive', '--route', args.route, '--duration', str(args.seconds)] + loop,
        env=env, stdout=logs['drive'], stderr=subprocess.STDOUT)
    return procs


def stop(procs: dict) -> None:
    """Stop the run's processes: the driver, the pipeline (SIGINT: a clean stop), the rest."""
    for name in ('drive', 'pipeline', 'emulator'):
        p = procs.get(name)
        if p is not None and p.poll() is None:
            p.send_signal(signal.SIGINT if name == 'pipeline' else signal.SIGTERM)
            try:
                p.wait(timeout=60)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def main() -> int:
    """Run the live system; print the SLAM, load and memory figures (module docstring)."""
    args = parse_arguments()
    from landmark_nav.testing import RosHarness
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry

    out, env, cli = live_run(args.domain, args.out, 'live_')
    names = ('pipeline',) + (() if args.bag else ('emulator', 'drive'))
    logs = {n: open(out / f'{n}.log', 'w') for n in names}
    procs, samples, loads = {}, [], []   # samples: (s since start, {process: MB})
    try:
        with RosHarness() as ros:
            odom = ros.collect('/odom', Odometry)
            slam = ros.collect('/odometry', Odometry)
            diags = ros.collect('/diagnostics', DiagnosticArray)
            procs = start(args, out, env, cli, logs)
            leader = procs['pipeline' if args.bag else 'drive']
            started = time.monotonic()
            print(f'logs in {out}; {args.seconds:g} s on '
                  + (f'the bag {args.bag}' if args.bag else f'the emulated robot ({args.route})')
                  + f', load average at start {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)',
                  flush=True)
            period = min(SAMPLE_S, args.seconds / 8.0)
            next_sample, next_load = period, 0.0
            playing = None   # a replay's --seconds count from its first /odom message
            # the driver ends by itself after --seconds of driving; a replay when it is drained
            while True:
                time.sleep(0.5)
                if leader.poll() is not None:   # the run is over: sample no more
                    break
                now = time.monotonic() - started
                if args.bag and playing is None and odom:
                    playing = now
                if args.bag and (now - (playing or 0.0) >= args.seconds if playing is not None
                                 else now > START_S):
                    break
                if now >= next_load:
                    next_load += LOAD_S
                    loads.append(os.getloadavg()[0])
                if now >= next_sample:
                    next_sample += period
                    pids = {n: p.pid for n, p in procs.items() if p.poll() is None}
                    pids.update(pipeline_pids(out / 'pipeline.log'))
                    samples.append((now, {n: alive(rss_mb, pid) for n, pid in pids.items()}))
            run_s = time.monotonic() - started
            pids = {n: p.pid for n, p in procs.items()}
            pids.update(pipeline_pids(out / 'pipeline.log'))
            cpu = {n: alive(cpu_seconds, pid) for n, pid in pids.items()}
            cpu = {n: c for n, c in cpu.items() if c == c}
            time.sleep(1.0)
            odom_msgs, slam_msgs, diag_msgs = list(odom), list(slam), list(diags)
    finally:
        stop(procs)
        for f in logs.values():
            f.close()
    print_slam(args, out, odom_msgs, slam_msgs)
    log_lines = (out / 'pipeline.log').read_text().splitlines()
    print_load(loads, cpu, run_s)
    print_diagnostics(diag_msgs, log_lines)
    if not args.bag:
        drive = (out / 'drive.log').read_text().strip().splitlines()
        print(drive[-1] if drive else 'drive: no output')
        emulator = [line for line in (out / 'emulator.log').read_text().splitlines()
                    if line.startswith('base: ')]
        print('emulator: ' + (emulator[-1][6:] if emulator else 'no summary'))
    return print_memory(samples, args.warmup, args.limit_mb if args.memory else None)


def first_pass(stamps, poses):
    """Return the messages up to the first jump back in time (a looped bag starts again)."""
    import numpy as np
    back = np.flatnonzero(np.diff(stamps) < 0)
    n = back[0] + 1 if back.size else len(stamps)
    return stamps[:n], poses[:n]


def print_slam(args, out: Path, odom_msgs: list, slam_msgs: list) -> None:
    """Print the ATE of ekf_slam and of the odometry, the distance driven and the resets."""
    import numpy as np
    from landmark_nav.conversions import odometry_to_pose
    from landmark_nav.evaluation.trajectory import (ate, position_errors_at, read_tum,
                                                    Trajectory)

    def planar(msgs):
        d = [odometry_to_pose(m) for m in msgs]
        return first_pass(np.array([x.stamp_ns for x in d], dtype=np.int64),
                          np.array([x.pose for x in d], dtype=float).reshape(-1, 3))

    if args.bag:
        from landmark_nav.bag.reader import BagReader
        from landmark_nav.evaluation.bags import read_track, REFERENCE_TOPIC
        with BagReader(args.bag) as bag:
            if REFERENCE_TOPIC not in bag.topics():
                print(f'no ATE: the bag has no {REFERENCE_TOPIC}')
                truth = None
            else:
                truth = Trajectory.from_planar(*read_track(bag, REFERENCE_TOPIC))
    else:
        truth = read_tum(out / 'truth.tum')
    ts, ps = planar(slam_msgs)
    if truth is not None and len(ts) >= 3:
        t_slam, e_slam, ref = position_errors_at(truth, ts, ps)
        to, po = planar(odom_msgs)
        keep = (to >= t_slam[0]) & (to <= t_slam[-1])
        t_odom, e_odom, ref_odom = position_errors_at(truth, to[keep], po[keep])
        dist = float(np.sum(np.hypot(*np.diff(ref[:, :2], axis=0).T)))
        print(f'{len(t_slam)} SLAM poses over {(t_slam[-1] - t_slam[0]) * 1e-9:.1f} s of '
              f'data, {dist:.2f} m driven')
        runs = (('ekf_slam', t_slam, ps[np.isin(ts, t_slam)], e_slam, ref),
                ('odometry', t_odom, po[keep][np.isin(to[keep], t_odom)], e_odom, ref_odom))
        for name, t, p, err, r in runs:
            if not args.bag:  # the emulator's truth is in the start frame
                print(f'{name:9s} ATE (start frame, unaligned): RMSE '
                      f'{100 * np.sqrt(np.mean(err ** 2)):.2f} cm, max {100 * err.max():.2f} cm')
            se2 = ate(Trajectory.from_planar(t, p), Trajectory.from_planar(t, r), 'se2')
            print(f'{name:9s} ATE SE(2)-aligned (evo): RMSE {100 * se2["rmse"]:.2f} cm, '
                  f'max {100 * se2["max"]:.2f} cm')
    elif truth is not None:
        print(f'no ATE: {len(ts)} ekf_slam poses received on /odometry')
    resets = [line for line in (out / 'pipeline.log').read_text().splitlines()
              if 'Resetting EKF-SLAM' in line]
    print(f'ekf_slam resets: {len(resets)}' + ''.join(f'\n  {line}' for line in resets[:3]))


def print_load(loads: list, cpu: dict, run_s: float) -> None:
    """Print the load average over the run and each process's CPU time."""
    if loads:
        print(f'load average (1 min, every {LOAD_S:g} s): min {min(loads):.2f}, mean '
              f'{sum(loads) / len(loads):.2f}, max {max(loads):.2f} on {os.cpu_count()} CPUs')
    print('CPU time over the run: ' + ', '.join(
        f'{n} {c:.1f} s ({100 * c / run_s:.1f} % of one CPU)' for n, c in sorted(cpu.items())))


def print_diagnostics(diag_msgs: list, log_lines: list) -> None:
    """Print each node's last input status, the start-up line and the drop warnings."""
    last = {}
    for array in diag_msgs:
        for status in array.status:
            if status.name.endswith(': input'):
                last[status.name] = {v.key: v.value for v in status.values}
    for line in log_lines:
        if 'before_odometry' in line and '[INFO]' in line:
            print('start-up: ' + line.split(']: ', 1)[-1])
    keys = ('processed', 'dropped', 'drop_rate_percent', 'before_odometry', 'latency_p50_ms',
            'latency_p95_ms', 'latency_max_ms', 'latency_run_p50_ms', 'latency_run_p95_ms',
            'latency_run_max_ms')
    for name, values in sorted(last.items()):
        shown = keys + tuple(k for k in sorted(values) if k.startswith('before_match.'))
        reasons = ', '.join(f'{k[8:]} {v}' for k, v in sorted(values.items())
                            if k.startswith('dropped.'))
        print(f'{name}: ' + ', '.join(f'{k} {values[k]}' for k in shown if k in values)
              + f' (reasons: {reasons or "none"})')
    rates, lost_scans = {}, 0
    for line in log_lines:
        m = re.match(r'\S+ (\w+)\s+\| \[WARN\].*?\]: (.*)$', line)
        if not m:
            continue
        node, text = m.groups()
        if '(drop rate: ' in text:
            rates.setdefault(node, []).append(text)
        elif node == 'laser_driver' and 'scan(s) lost' in text:
            n = re.search(r'about (\d+) scan', text)
            lost_scans += int(n.group(1)) if n else 1
    for node, texts in sorted(rates.items()):
        print(f'{node}: {len(texts)} drop warnings with the drop rate (throttled); first: '
              f'{texts[0]}' + (f'\n  last: {texts[-1]}' if len(texts) > 1 else ''))
    if any(' laser_driver ' in line for line in log_lines):
        print(f'laser_driver: {lost_scans} scans reported lost before publishing')
    dropped = sum(int(v.get('dropped', 0)) for v in last.values())
    p95 = float(last.get('ekf_slam: input', {}).get('latency_run_p95_ms', 'nan'))
    print(f'dropped by the nodes: {dropped} (target 0); ekf_slam latency p95 over the run '
          f'{p95:.1f} ms (target <= 100)')


def print_memory(samples: list, warmup_s: float, limit_mb) -> int:
    """Print each process's RSS figures; with ``limit_mb``, judge the growth.

    A process's reference is its first sample after the warm-up (a node starts a few seconds
    after its launcher). Returns 1 when ``limit_mb`` is given and a process grew beyond it
    (or died) after the warm-up, or when the run ended before the warm-up was over; else 0.
    """
    after = [s for s in samples if s[0] >= warmup_s]
    if len(after) < 2:
        print(f'memory: the run ended before the warm-up ({warmup_s:g} s) was over')
        return 0 if limit_mb is None else 1
    end = after[-1]
    failed = []
    print(f'{"process":18s} {"from s":>6s} {"RSS then":>11s} {"at " + f"{end[0]:.0f} s":>11s} '
          f'{"growth":>9s} {"2nd half":>9s}')
    for name in sorted({n for _, rss in after for n in rss}):
        ref = next(s for s in after if s[1].get(name, float('nan')) > 0.0)
        half = min(after, key=lambda s: abs(s[0] - 0.5 * (ref[0] + end[0])))
        a, b = ref[1][name], end[1].get(name, float('nan'))
        growth, second = b - a, b - half[1].get(name, float('nan'))
        print(f'{name:18s} {ref[0]:6.0f} {a:8.1f} MB {b:8.1f} MB {growth:+6.2f} MB '
              f'{second:+6.2f} MB')
        if not growth <= (limit_mb if limit_mb is not None else math.inf):
            failed.append(name)   # NaN (a process gone) fails too
    if limit_mb is None:
        return 0
    if failed:
        print(f'FAIL: RSS growth above {limit_mb:g} MB (or the process died): '
              + ', '.join(failed))
        return 1
    print(f'OK: every process grew by at most {limit_mb:g} MB after the warm-up')
    return 0


if __name__ == '__main__':
    sys.exit(main())
