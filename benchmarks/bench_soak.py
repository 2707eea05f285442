"""Soak of the live SLAM nodes at 40 Hz: latency, CPU and memory, checked against stored results.

Run from the repository root (``make bench`` runs it with the defaults)::

    python benchmarks/bench_soak.py [--bag bags/office] [--seconds 45] [--rate 4]
                                    [--results benchmarks/results/soak.json] [--record]

``corner_extractor`` and ``ekf_slam`` run as processes (their console entry points, with
the bag's laser mount, range noise and odometry model) on a DDS domain of their own;
``bag_player`` replays the bag's ``/scan`` and ``/odom`` at ``--rate`` (rate 4 of the office
bag: 40 scans/s and 40 Hz odometry) in a loop for ``--seconds`` wall seconds. Read from
each node's last ``/diagnostics`` input status and ``/proc``: the latency p95 over the run,
the CPU time per scan, the resident memory growth from second 15 to the end, the share of
inputs dropped.

Timing figures are ratios against a reference measured in the same run, so that they
mean the same on a slower or busier machine: the CPU time per step of the same core
(:func:`bench_node_cpu.core_step_ms`: ``SlamFrontend`` + ``EkfSlam`` on the same bag,
offline, back to back, in this process). Printed per node: latency p95 / core step and CPU
per scan / core step; memory growth in MB and the drop share are absolute.

Each figure is compared with ``--results`` (``{figure: {"value": v, "band": b}}``): a
ratio over ``v * (1 + b)``, memory growth over ``v`` MB or a drop share over ``v`` is a
regression, and the script exits 1 naming it. ``--record N`` runs the soak N times on an
idle machine and stores each ratio's median as ``v`` and its noise band as ``b`` = twice
the largest relative deviation of a run from the median (at least 0.2); the memory and
drop bounds are the unit test's former ones (2 MB, 1 %). This is the timed part of what
was the unit suite's soak test; ``test/test_soak.py`` keeps the functional part (every
scan processed or counted, drops warned, a clean stop).
"""

import argparse
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_node_cpu import core_step_ms, cpu_seconds, rss_mb, wait_idle  # noqa: E402

NODES = ('corner_extractor', 'ekf_slam')
RESULTS = REPO / 'benchmarks' / 'results' / 'soak.json'
WARM_UP_S = 15.0


def node_arguments(scenario) -> dict:
    """Return each node's ``--ros-args``: the bag's laser mount, noise and odometry model.

    ``ekf_slam`` runs the chapter profile (``config/ekf_slam_chapter.yaml``), the filter the
    stored results were measured with.
    """
    from landmark_nav.evaluation.slam import DRIFT_KEY
    laser = scenario.laser
    model = scenario.custom_data.get(DRIFT_KEY) or (
        'simulator' if scenario.simulator else 'pioneer')
    mount = ','.join(f'{v!r}' for v in map(float, laser.mount))
    chapter = str(REPO / 'config' / 'ekf_slam_chapter.yaml')
    return {'ekf_slam': ['--ros-args', '--params-file', chapter, '-p', f'odometry.model:={model}',
                         '-p', f'laser_pose:=[{mount}]',
                         '-p', f'laser_sigma_range:={float(laser.sigma_range)!r}'],
            'corner_extractor': ['--ros-args', '-p', f'sigma_r:={float(laser.sigma_range)!r}']}


def last_input_status(diagnostics: list, node: str) -> dict:
    """Return the key/values of the node's last ``<node>: input`` status."""
    for array in reversed(diagnostics):
        for status in array.status:
            if status.name == f'{node}: input':
                return {v.key: v.value for v in status.values}
    raise RuntimeError(f'no /diagnostics input status from {node}')


def soak(bag: str, seconds: float, rate: float) -> dict:
    """Run the soak; return the figures (see the module docstring)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from landmark_nav.evaluation.bags import load_bag
    from landmark_nav.evaluation.slam import bag_odometry_noise
    from landmark_nav.testing import isolate_dds, RosHarness
    isolate_dds()
    scenario = load_bag(bag, require_reference=False)
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    for key in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'LANDMARK_NAV_THREADS'):
        env.pop(key, None)  # the nodes' own default: one library thread
    args = node_arguments(scenario)
    procs = {n: subprocess.Popen([sys.executable, '-m', f'landmark_nav.nodes.{n}'] + args[n],
                                 env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for n in NODES}
    player = None
    try:
        with RosHarness() as ros:
            diagnostics = ros.collect('/diagnostics', DiagnosticArray)
            wait_idle([p.pid for p in procs.values()])
            cpu0 = {n: cpu_seconds(p.pid) for n, p in procs.items()}
            player = subprocess.Popen(
                [sys.executable, '-m', 'landmark_nav.nodes.bag_player', bag, '--topics',
                 '/scan', '/odom', '--rate', str(rate), '--loop', '--wait-for-subscribers',
                 '30'], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            time.sleep(min(WARM_UP_S, seconds))
            rss0 = {n: rss_mb(p.pid) for n, p in procs.items()}
            time.sleep(max(0.0, seconds - WARM_UP_S))
            rss1 = {n: rss_mb(p.pid) for n, p in procs.items()}
            player.send_signal(signal.SIGINT)
            player.wait(30)
            time.sleep(3.0)  # the queues drain, the last /diagnostics period
            cpu1 = {n: cpu_seconds(p.pid) for n, p in procs.items()}
            status = {n: last_input_status(list(diagnostics), n) for n in NODES}
    finally:
        for p in ([player] if player is not None else []) + list(procs.values()):
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in ([player] if player is not None else []) + list(procs.values()):
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    core_ms, _ = core_step_ms(scenario, bag_odometry_noise(scenario)[0])
    figures = {'core_step_ms': core_ms}
    for n in NODES:
        values = status[n]
        processed, dropped = int(values['processed']), int(values['dropped'])
        figures[f'{n}.latency_p95_ms'] = float(values['latency_run_p95_ms'])
        figures[f'{n}.latency_p95_ratio'] = float(values['latency_run_p95_ms']) / core_ms
        figures[f'{n}.cpu_per_scan_ratio'] = (1e3 * (cpu1[n] - cpu0[n])
                                              / max(processed, 1) / core_ms)
        figures[f'{n}.rss_growth_mb'] = rss1[n] - rss0[n]
        figures[f'{n}.drop_share'] = dropped / max(processed + dropped, 1)
        figures[f'{n}.processed'] = processed
    return figures


def regressions(figures: dict, stored: dict) -> list:
    """Return a line per figure worse than its stored value (ratios: beyond the band)."""
    out = []
    for name, ref in stored.items():
        value = figures.get(name)
        if value is None:
            out.append(f'{name}: not measured')
        elif name.endswith('_ratio'):
            limit = ref['value'] * (1.0 + ref['band'])
            if value > limit:
                out.append(f'{name} = {value:.3f} > {limit:.3f} (stored {ref["value"]:.3f}, '
                           f'band {100 * ref["band"]:.0f} %)')
        elif value > ref['value']:
            out.append(f'{name} = {value:.4g} > {ref["value"]:.4g} (stored bound)')
    return out


def record(runs: list) -> dict:
    """Return the stored results of repeated soaks (see the module docstring)."""
    import statistics
    stored = {}
    for name in runs[0]:
        if name.endswith('_ratio'):
            values = [r[name] for r in runs]
            mid = statistics.median(values)
            spread = max(abs(v / mid - 1.0) for v in values) if mid > 0 else 0.0
            stored[name] = {'value': round(mid, 3), 'band': round(max(0.2, 2.0 * spread), 3),
                            'runs': [round(v, 3) for v in values]}
        elif name.endswith('rss_growth_mb'):
            stored[name] = {'value': 2.0}
        elif name.endswith('drop_share'):
            stored[name] = {'value': 0.01}
    return stored


def main() -> int:
    """Run the soak, print the figures, compare with (or record) the stored results."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--bag', default=str(REPO / 'bags' / 'office'),
                        help='rosbag2 directory with /scan and /odom (default bags/office)')
    parser.add_argument('--seconds', type=float, default=45.0, help='soak length [s]')
    parser.add_argument('--rate', type=float, default=4.0, help='replay rate (default 4)')
    parser.add_argument('--results', default=str(RESULTS), help='stored results (JSON)')
    parser.add_argument('--record', type=int, default=0, metavar='N',
                        help='run N soaks and store their figures as the new results')
    args = parser.parse_args()
    runs = []
    for _ in range(max(1, args.record)):
        runs.append(soak(args.bag, args.seconds, args.rate))
        for name, value in runs[-1].items():
            print(f'{name:36s} {value:.4g}')
    path = Path(args.results)
    if args.record:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(record(runs), indent=2) + '\n')
        print(f'recorded {args.record} runs in {path}')
        return 0
    if not path.exists():
        print(f'error: no stored results at {path} (make them with --record 3)')
        return 2
    bad = regressions(runs[0], json.loads(path.read_text()))
    for line in bad:
        print(f'REGRESSION {line}')
    print('OK: no regression' if not bad else f'{len(bad)} regressions')
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
