"""Live SLAM on the emulated robot: ATE of ekf_slam and of the odometry against the truth.

Run from the repository root::

    python benchmarks/bench_live_slam.py [--seconds 120] [--route office] [--laser urg]
        [--skip 3] [--loop] [--rate 1]

Starts, each as its own process on a private DDS domain, exactly what the README shows:
``landmark_nav emulate robot --truth truth.tum`` (the P2OS base and the laser on one
world), ``landmark_nav pipeline slam`` (laser_driver + base_driver + corner_extractor +
ekf_slam with the shipped parameters, ``--profile`` on top; the UTM-30LX's
40 scans/s thinned to 10 with
``laser_driver.skip=3`` unless ``--skip 0``) and ``landmark_nav drive --route office --record
slam.tum`` (cmd_vel closed on ekf_slam's ``/odometry``) for ``--seconds``; this process
also records ``/odom``. Printed: the ATE (position error after interpolating the truth to
each estimate's stamp; no alignment: the truth is written in the start frame, which is the
odom and map frame) of ekf_slam and of the odometry, RMSE and max, over the driven time;
the SE(2)-aligned ATE (evo's metric); the distance driven; and ekf_slam's and the corner
extractor's last ``/diagnostics`` input status (processed, dropped, latency percentiles
over the last 1000 inputs and over the whole run, messages published before a
subscription matched) and every node's RSS after one minute and at the end. ``--loop
--seconds 600 --skip 0`` is a soak through the live drivers (40 scans/s, 10 Hz odometry).

Start-up: corner sets stamped before the first odometry sample are not drops (no odometry
pose exists for them): ekf_slam counts them as ``before_odometry`` on ``/diagnostics`` and
states them in one info line, printed here. Load: the load average (``/proc/loadavg``, every
5 s) and each node's CPU time over the run (``/proc/<pid>/stat``), to tell drops from CPU
starvation on a shared machine.

Drops: each node's ``/diagnostics`` counts by reason (``dropped.<reason>``) and its drop
rate, the drop warnings the nodes logged (throttled; each states the drop rate,
:class:`~landmark_nav.nodes.common.InputStats`) with the first and the last, the laser
driver's lost-scan warnings and what the emulator could not send.
``--rate 10`` runs the devices at ten times their data rates (``emulate robot --rate 10``:
400 scans/s and 100 Hz odometry, ``base_driver.cycle_time`` 0.01 s) with the robot moving
as at rate 1: the 10x soak, where the nodes cannot keep up and must say how much they drop.

Data: none. The run is a closed loop through the live drivers: the emulated devices answer
the drivers' serial commands and the robot moves as ``drive`` commands it from ekf_slam's
estimate, which a recording cannot do. The same pipeline on recorded data is
``bench_node_cpu.py BAG`` (CPU per scan through DDS) and ``bench_soak.py --bag BAG``
(latency, CPU and memory).
"""

import argparse
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from common import live_run


def node_rss(log: Path) -> dict:
    """Return {node: RSS [MB]} of the pipeline's processes (pids from honcho's log)."""
    import re
    out = {}
    for node, pid in re.findall(r'\| (\w+) started \(pid=(\d+)\)', log.read_text()):
        try:
            for line in Path(f'/proc/{pid}/status').read_text().splitlines():
                if line.startswith('VmRSS:'):
                    out[node] = int(line.split()[1]) / 1024.0
        except OSError:
            pass
    return out


def node_cpu_s(log: Path) -> dict:
    """Return {node: user + system CPU time [s]} of the pipeline's processes."""
    import re
    tick = os.sysconf('SC_CLK_TCK')
    out = {}
    for node, pid in re.findall(r'\| (\w+) started \(pid=(\d+)\)', log.read_text()):
        try:
            fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
            out[node] = (int(fields[11]) + int(fields[12])) / tick
        except (OSError, IndexError, ValueError):
            pass
    return out


def main() -> int:
    """Run the emulator, the pipeline and the driver; print the figures."""
    parser = argparse.ArgumentParser(
        description=__doc__.split('\n')[0],
        epilog='No data argument: the run is a closed loop through the live drivers (the '
               "emulated devices answer the drivers' commands, the robot moves as drive "
               "commands it from ekf_slam's estimate), which a recording cannot replace. On "
               'recorded data: bench_node_cpu.py BAG and bench_soak.py --bag BAG.')
    parser.add_argument('--seconds', type=float, default=120.0)
    parser.add_argument('--route', default='office')
    parser.add_argument('--laser', default='urg', choices=('urg', 'lms200'))
    parser.add_argument('--skip', type=int, default=3,
                        help='laser_driver.skip for the UTM-30LX (default 3: 10 scans/s, '
                             'as the office bags; 0: all 40)')
    parser.add_argument('--loop', action='store_true',
                        help='drive the route again and again (a soak: --seconds 600)')
    parser.add_argument('--domain', type=int, default=101,
                        help="DDS domain (default 101, outside the tests' 20..99: another "
                             "process's odometry on the domain resets the filter)")
    parser.add_argument('--rate', type=float, default=1.0,
                        help='data rate factor of the emulated devices (10: the 10x soak, '
                             '400 scans/s with --skip 0 and 100 Hz odometry)')
    parser.add_argument('--out', default=None, help='keep the files here')
    parser.add_argument('--profile', action='append', default=[], metavar='NAME',
                        help='a shipped profile for the pipeline (e.g. ekf_slam_chapter: the '
                        'filter of the figures measured before the real-data defaults)')
    args = parser.parse_args()

    import numpy as np
    from landmark_nav.conversions import odometry_to_pose
    from landmark_nav.evaluation.trajectory import ate, position_errors_at, read_tum, Trajectory
    from landmark_nav.testing import RosHarness
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry

    out, env, cli = live_run(args.domain, args.out, 'live_slam_')
    base_link, laser_link = out / 'p2os', out / 'laser'
    laser_set = ['--set', f'laser_driver.port={laser_link}']
    if args.laser == 'urg' and args.skip:
        laser_set += ['--set', f'laser_driver.skip={args.skip}']
    if args.laser == 'lms200':
        laser_set += ['--set', 'laser_driver.protocol=lms2xx', '--set', 'laser_driver.baud=38400']
    procs = []
    with open(out / 'emulator.log', 'w') as emu_log, open(out / 'pipeline.log', 'w') as log:
        procs.append(subprocess.Popen(
            cli + ['emulate', 'robot', '--link', str(base_link), '--tcp', '0', '--laser',
                   args.laser, '--laser-link', str(laser_link), '--truth',
                   str(out / 'truth.tum'), '--rate', str(args.rate)],
            env=env, stdout=emu_log, stderr=subprocess.STDOUT))
        time.sleep(2.0)
        procs.append(subprocess.Popen(
            cli + ['pipeline', 'slam', '--set', f'base_driver.port={base_link}',
                   '--set', f'base_driver.cycle_time={0.1 / args.rate!r}',
                   '--set', 'ekf_slam.odometry.model=simulator'] + laser_set
            + [a for name in args.profile for a in ('--profile', name)],
            env=env, stdout=log, stderr=subprocess.STDOUT))
        started = time.monotonic()
        try:
            with RosHarness() as ros:
                odom = ros.collect('/odom', Odometry)
                diags = ros.collect('/diagnostics', DiagnosticArray)
                drive = subprocess.Popen(
                    cli + ['drive', '--route', args.route, '--duration', str(args.seconds),
                           '--record', str(out / 'slam.tum')] + (['--loop'] if args.loop
                                                                 else []),
                    env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
                rss, loads, next_load = {}, [], 0.0
                print(f'load average at start: {os.getloadavg()[0]:.2f} '
                      f'({os.cpu_count()} CPUs)', flush=True)
                while drive.poll() is None:
                    time.sleep(1.0)
                    if time.monotonic() >= next_load:
                        next_load = time.monotonic() + 5.0
                        loads.append(os.getloadavg()[0])
                    if not rss and time.monotonic() - started > 60.0:
                        rss = node_rss(out / 'pipeline.log')
                text, _ = drive.communicate()
                print(text.strip().splitlines()[-1] if text.strip() else 'drive: no output')
                rss_end = node_rss(out / 'pipeline.log')
                cpu = node_cpu_s(out / 'pipeline.log')
                run_s = time.monotonic() - started
                time.sleep(1.0)
                odom_msgs, diag_msgs = list(odom), list(diags)
        finally:
            procs[1].send_signal(signal.SIGINT)
            procs[1].wait(timeout=60)
            procs[0].send_signal(signal.SIGTERM)
            procs[0].wait(timeout=30)

    est, truth = read_tum(out / 'slam.tum'), read_tum(out / 'truth.tum')
    ts, ps = est.stamps_ns, est.planar()
    t_slam, e_slam, ref = position_errors_at(truth, ts, ps)
    od = [odometry_to_pose(m) for m in odom_msgs]
    to = np.array([d.stamp_ns for d in od], dtype=np.int64)
    po = np.array([d.pose for d in od])
    keep = (to >= t_slam[0]) & (to <= t_slam[-1])
    t_odom, e_odom, _ = position_errors_at(truth, to[keep], po[keep])
    dist = float(np.sum(np.hypot(*np.diff(ref[:, :2], axis=0).T)))
    span = (t_slam[-1] - t_slam[0]) * 1e-9
    print(f'files in {out}; {len(t_slam)} SLAM poses over {span:.1f} s, {dist:.2f} m driven')
    for name, err in (('ekf_slam', e_slam), ('odometry', e_odom)):
        rmse = 100 * np.sqrt(np.mean(err ** 2))
        print(f'{name:9s} ATE (start frame, unaligned): RMSE {rmse:.2f} cm, '
              f'max {100 * err.max():.2f} cm')
    se2 = ate(Trajectory.from_planar(t_slam, ps[np.isin(ts, t_slam)]),
              Trajectory.from_planar(t_slam, ref), 'se2')
    print(f'ekf_slam ATE SE(2)-aligned (evo): RMSE {100 * se2["rmse"]:.2f} cm, '
          f'max {100 * se2["max"]:.2f} cm')
    last = {}
    for array in diag_msgs:
        for status in array.status:
            if status.name.endswith(': input'):
                last[status.name] = {v.key: v.value for v in status.values}
    log_lines = (out / 'pipeline.log').read_text().splitlines()
    resets = [line for line in log_lines if 'Resetting EKF-SLAM' in line]
    print(f'ekf_slam resets: {len(resets)}' + ''.join(f'\n  {line}' for line in resets[:3]))
    for node in sorted(rss_end):
        if node in rss:
            print(f'{node}: RSS {rss[node]:.1f} MB at 1 min, {rss_end[node]:.1f} MB at the end '
                  f'({rss_end[node] - rss[node]:+.1f} MB)')
    if loads:
        print(f'load average (1 min, every 5 s): min {min(loads):.2f}, mean '
              f'{sum(loads) / len(loads):.2f}, max {max(loads):.2f} on {os.cpu_count()} CPUs')
    print('CPU time over the run: ' + ', '.join(
        f'{n} {c:.1f} s ({100 * c / run_s:.1f} % of one CPU)' for n, c in sorted(cpu.items())))
    for line in log_lines:
        if 'before_odometry' in line and '[INFO]' in line:
            print('start-up: ' + line.split(']: ', 1)[-1])
    for name, values in sorted(last.items()):
        keys = ('processed', 'dropped', 'drop_rate_percent', 'before_odometry',
                'latency_p50_ms', 'latency_p95_ms', 'latency_max_ms', 'latency_run_p50_ms',
                'latency_run_p95_ms', 'latency_run_max_ms')
        keys += tuple(k for k in sorted(values) if k.startswith('before_match.'))
        reasons = ', '.join(f'{k[8:]} {v}' for k, v in sorted(values.items())
                            if k.startswith('dropped.'))
        print(f'{name}: ' + ', '.join(f'{k} {values[k]}' for k in keys if k in values)
              + f' (reasons: {reasons or "none"})')
    report_warnings(log_lines)
    growth = {n: rss_end[n] - rss[n] for n in rss_end if n in rss}
    dropped = {n.split(':')[0]: int(v.get('dropped', 0)) for n, v in last.items()}
    p95 = float(last.get('ekf_slam: input', {}).get('latency_run_p95_ms', 'nan'))
    before = last.get('ekf_slam: input', {}).get('before_odometry', 'n/a')
    print(f'soak targets (issue 16, at 1x): dropped {sum(dropped.values())} (target 0; '
          f'ekf_slam: {before} sets stamped before the first odometry, not drops), '
          f'ekf_slam latency p95 over the run {p95:.1f} ms (target <= 100), largest RSS growth '
          + (f'{max(growth.values()):+.1f} MB (target <= 5)' if growth else 'n/a (< 1 min)'))
    emulator = [line for line in (out / 'emulator.log').read_text().splitlines()
                if line.startswith('base: ')]
    print('emulator: ' + (emulator[-1][6:] if emulator else 'no summary'))
    return 0


def report_warnings(log_lines) -> None:
    """Print the nodes' drop warnings (they state the drop rate) and the driver's lost scans."""
    import re
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
    print(f'laser_driver: {lost_scans} scans reported lost before publishing')


if __name__ == '__main__':
    sys.exit(main())
