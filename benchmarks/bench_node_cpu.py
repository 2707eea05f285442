"""CPU per scan and memory of the live SLAM nodes while a bag is replayed through them.

Run from the repository root::

    python benchmarks/bench_node_cpu.py [bags/office] [--rate 1] [--threads N] [--seconds S]

Starts ``corner_extractor`` and ``ekf_slam`` as processes (their console entry points, on a
private DDS domain), replays the bag's ``/scan`` and ``/odom`` with ``bag_player`` (waiting
for the subscribers) and reads each node's CPU time (user + system, ``/proc/<pid>/stat``)
and resident memory before and after the replay. Printed per node: CPU per scan [ms]
(CPU during the replay / scans replayed), RSS at start and end [MB], and the processed /
dropped counts and latency percentiles of its last ``/diagnostics`` status.

``--threads N`` exports ``LANDMARK_NAV_THREADS=N`` to the nodes (default: unset, i.e. the
nodes' own default of one thread); ``--threads 0`` exports nothing and sets
``OPENBLAS_NUM_THREADS`` / ``OMP_NUM_THREADS`` to the number of CPUs instead (how numpy
behaves without a limit). ``--repo`` runs another checkout's code (e.g. an older commit
exported with ``git archive``), for a before / after comparison. ``--seconds`` stops the
replay after that much bag time. ``--soak S`` loops the bag for S wall seconds instead (a
soak test: at ``--rate 4`` the office bag gives 40 Hz scans and odometry; each loop resets
the filter, as odometry goes back in time) and also prints the RSS growth after the first
minute; the scan count is then the corner extractor's processed + dropped.

Ratio in the same run: after the replay the same bag (same ``--seconds``) goes through the
offline pipeline in this process (:func:`landmark_nav.evaluation.slam.run_slam`, the same
:class:`~landmark_nav.slam.frontend.SlamFrontend` the node runs, with the bag's odometry
noise model, laser mount and noise, which the node also gets as parameters); printed: the
core's time per step (front end + filter with the scan's geometry for the visibility-aware
pruning, and with ``--landmarks lines|both`` the line extraction the node does, without
the corner extraction of ``corner_extractor``), run twice: back to back, and paced at the
bag's stamps over ``--rate`` as the node gets them (sleeping in between, as the node
does); printed: ``ekf_slam``'s CPU per step over the paced core's (the issue's target: at
most 2; what the node spends beyond the same work at the same rate) and over the
back-to-back core's. ``--no-visibility`` runs both without the scan geometry (the
node does not subscribe ``scan``; what the node before the visibility-aware pruning did).
Node and core run the ``ekf_slam`` defaults; ``--params-file YAML`` gives ``ekf_slam`` a
parameter file on top of them (e.g. ``config/ekf_slam_chapter.yaml``, the chapter's filter)
and the core the same ``SlamParams`` (0 = off as in the node; ``--landmarks`` replaces its
``landmarks``).
``--map-landmarks N`` (the issue's figure is at 200): node and core start on a saved map of
N landmarks placed 1 km and more away (never in view: no association, no pruning; the
state and covariance the filter carries are those of an N-landmark map) and map the bag's
landmarks on top, evicting the least recently seen beyond ``max_landmarks`` (200).

``--graph`` runs ``graph_slam`` (the graph back end) alone instead, with the bag's laser
mount and odometry noise model, records every ``pose`` it publishes, waits until it is idle
(its back end works through its queue), then runs ``landmark_nav evaluate --backend graph``'s
run (:func:`landmark_nav.evaluation.slam_graph.run_graph`) on the same bag and prints whether
the node gave the same steps (scan stamps) and the largest distance between its poses and
the offline ``online`` trajectory; exit 1 when a step is missing or more than 1 mm off.

The CPU counters start once both nodes are idle after their start-up (imports, DDS
discovery), so the start-up is not charged to the scans. ``--profile FILE`` runs
``ekf_slam`` under cProfile, timed by its main thread's CPU clock (its CPU figure then
includes the profiler's overhead).

``--imports`` measures start-up instead: the CPU time (user + system) of a fresh interpreter
importing each executable's node module (``setup.py``'s ``EXECUTABLES`` of ``--repo``),
median of ``--runs``, and as the reference in the same run ``import rclpy.node`` (the floor
every node pays); printed per node: CPU [s] and its ratio to the reference.
"""

import argparse
import ast
import os
from pathlib import Path
import signal
import statistics
import subprocess
import sys
import time

REPO = Path(__file__).resolve().parents[1]
NODES = ('corner_extractor', 'ekf_slam')
GRAPH_NODES = ('graph_slam',)


def cpu_seconds(pid: int) -> float:
    """Return the user + system CPU time of a process [s]."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def main_thread_seconds(pid: int) -> float:
    """Return the user + system CPU time of a process's main thread (Python) [s]."""
    return cpu_seconds_path(Path(f'/proc/{pid}/task/{pid}/stat'))


def cpu_seconds_path(stat: Path) -> float:
    """Return the user + system CPU time in a /proc stat file [s]."""
    fields = stat.read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def rss_mb(pid: int) -> float:
    """Return the resident set size of a process [MB]."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return float('nan')


def import_cpu(repo: str, module: str, runs: int) -> float:
    """Return the median CPU time [s] of a fresh interpreter importing ``module`` in ``repo``."""
    times = []
    for _ in range(runs):
        before = os.times()
        subprocess.run([sys.executable, '-c', f'import {module}'], cwd=repo, check=True)
        after = os.times()
        times.append(after.children_user - before.children_user
                     + after.children_system - before.children_system)
    return statistics.median(times)


def print_import_cpu(repo: str, runs: int) -> int:
    """Print each node module's import CPU and its ratio to ``import rclpy.node``'s."""
    tree = ast.parse((Path(repo) / 'setup.py').read_text())
    exes = next(ast.literal_eval(n.value) for n in tree.body
                if isinstance(n, ast.Assign) and getattr(n.targets[0], 'id', '') == 'EXECUTABLES')
    reference = import_cpu(repo, 'rclpy.node', runs)
    print(f'import rclpy.node (reference): {reference:.2f} CPU-s (median of {runs})')
    for exe, target in sorted(exes.items()):
        if '.nodes.' in target:
            cpu = import_cpu(repo, target.split(':')[0], runs)
            print(f'{exe:18s} {cpu:5.2f} CPU-s  {cpu / reference:4.1f} x reference')
    return 0


def main() -> int:
    """Run the nodes, replay the bag, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('bag', nargs='?', default=str(REPO / 'bags' / 'office'))
    parser.add_argument('--rate', type=float, default=1.0)
    parser.add_argument('--threads', type=int, default=None)
    parser.add_argument('--seconds', type=float, default=None)
    parser.add_argument('--soak', type=float, default=None, metavar='S')
    parser.add_argument('--repo', default=str(REPO), help='checkout whose code is run')
    parser.add_argument('--domain', type=int, default=90 + os.getpid() % 10)
    parser.add_argument('--landmarks', default=None, choices=('corners', 'lines', 'both'),
                        help="landmark types (default: the configuration's)")
    parser.add_argument('--no-visibility', dest='visibility', action='store_false')
    parser.add_argument('--map-landmarks', type=int, default=0, metavar='N')
    parser.add_argument('--profile', metavar='FILE', default=None,
                        help='run ekf_slam under cProfile, statistics written to FILE')
    parser.add_argument('--graph', action='store_true',
                        help='run graph_slam (the graph back end) instead of corner_extractor '
                             "+ ekf_slam and compare its poses with evaluate --backend graph's")
    parser.add_argument('--params-file', metavar='YAML', default=None,
                        help="ekf_slam's parameters on top of the defaults (e.g. "
                             'config/ekf_slam_chapter.yaml), node and core alike')
    parser.add_argument('--imports', action='store_true',
                        help="print each node module's import CPU instead (start-up cost)")
    parser.add_argument('--runs', type=int, default=5, help='--imports: runs per module')
    args = parser.parse_args()
    if args.imports:
        return print_import_cpu(args.repo, args.runs)
    slam_options = params_file_options(args.params_file)
    landmarks = slam_options.pop('landmarks')
    args.landmarks = args.landmarks or landmarks
    env = dict(os.environ, ROS_DOMAIN_ID=str(args.domain),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               PYTHONPATH=args.repo + os.pathsep + os.environ.get('PYTHONPATH', ''))
    for key in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'LANDMARK_NAV_THREADS'):
        env.pop(key, None)
    if args.threads == 0:
        env['OPENBLAS_NUM_THREADS'] = env['OMP_NUM_THREADS'] = str(os.cpu_count())
    elif args.threads is not None:
        env['LANDMARK_NAV_THREADS'] = str(args.threads)
    sys.path.insert(0, args.repo)
    from landmark_nav.bag import BagReader
    from landmark_nav.evaluation.bags import load_bag
    scenario = load_bag(args.bag, max_seconds=args.seconds, require_reference=False)
    laser = scenario.laser
    files = ['--params-file', str(Path(args.params_file).resolve())] if args.params_file else []
    mount = 'laser_pose:=[' + ','.join(f'{v!r}' for v in map(float, laser.mount)) + ']'
    node_args = {'ekf_slam': ['--ros-args'] + files + [
        '-p', mount,
        '-p', f'landmarks:={args.landmarks}', '-p', f'visibility:={str(args.visibility).lower()}',
        '-p', f'laser_sigma_range:={float(laser.sigma_range)!r}',
        '-p', f'lines.sigma_r:={float(laser.sigma_range)!r}',
        '-p', f'lines.sigma_phi:={float(laser.sigma_angle)!r}'],
        'corner_extractor': ['--ros-args', '-p', f'sigma_r:={float(laser.sigma_range)!r}',
                             '-p', f'sigma_phi:={float(laser.sigma_angle)!r}']}
    slam_map = None
    if args.map_landmarks:
        import tempfile
        from landmark_nav.slam.slam_map import save_map
        slam_map = far_map(args.map_landmarks)
        map_file = Path(tempfile.mkdtemp()) / 'far.npz'
        save_map(map_file, slam_map)
        node_args['ekf_slam'] += ['-p', f'load_map:={map_file}']
    try:
        from landmark_nav.evaluation.slam import bag_odometry_noise, DRIFT_KEY
        model = scenario.custom_data.get(DRIFT_KEY) or (
            'simulator' if scenario.simulator else 'pioneer')
        noise = bag_odometry_noise(scenario)[0]
        node_args['ekf_slam'] += ['-p', f'odometry.model:={model}']
        node_args['graph_slam'] = ['--ros-args', '-p', mount, '-p', f'odometry.model:={model}']
    except ImportError:  # an older checkout (--repo): its defaults
        noise = None
    with BagReader(args.bag) as reader:
        start, scans = reader.start_ns, 0
        for item in reader.messages(('/scan',)):
            if args.seconds is not None and item.log_time_ns - start > args.seconds * 1e9:
                break
            scans += 1
    profile = {'ekf_slam': ['-c', PROFILE, str(Path(args.profile).resolve())]
               } if args.profile else {}
    nodes = GRAPH_NODES if args.graph else NODES
    slam = nodes[-1]
    listener = subprocess.Popen([sys.executable, '-c', POSE_LISTENER], env=env, cwd=args.repo,
                                stdout=subprocess.PIPE, text=True) if args.graph else None
    procs = {n: subprocess.Popen([sys.executable] + profile.get(n, ['-m'])
                                 + [f'landmark_nav.nodes.{n}']
                                 + node_args.get(n, []), env=env,
                                 cwd=args.repo, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL)
             for n in nodes}
    diag = subprocess.Popen([sys.executable, '-c', DIAG_LISTENER], env=env, cwd=args.repo,
                            stdout=subprocess.PIPE, text=True)
    time.sleep(2.0)
    wait_idle([p.pid for p in procs.values()])
    cpu0 = {n: cpu_seconds(p.pid) for n, p in procs.items()}
    main0 = main_thread_seconds(procs[slam].pid)
    rss0 = {n: rss_mb(p.pid) for n, p in procs.items()}
    player = [sys.executable, '-m', 'landmark_nav.nodes.bag_player', args.bag, '--topics',
              '/scan', '/odom', '--rate', str(args.rate), '--wait-for-subscribers', '20']
    wall = time.monotonic()
    try:
        if args.soak is not None:
            play = subprocess.Popen(player + ['--loop'], env=env, cwd=args.repo,
                                    stdout=subprocess.DEVNULL)
            time.sleep(min(60.0, args.soak))
            rss0 = {n: rss_mb(p.pid) for n, p in procs.items()}
            time.sleep(max(0.0, args.soak - 60.0))
            play.send_signal(signal.SIGINT)
            play.wait(30)
        elif args.seconds is None:
            subprocess.run(player, env=env, cwd=args.repo, check=True,
                           stdout=subprocess.DEVNULL)
        else:
            play = subprocess.Popen(player, env=env, cwd=args.repo, stdout=subprocess.DEVNULL)
            time.sleep(args.seconds / args.rate + 2.0)
            play.send_signal(signal.SIGINT)
            play.wait(30)
        wall = time.monotonic() - wall
        time.sleep(3.0)
        if args.graph:  # the back end may still work through its queue
            wait_idle([procs[slam].pid], timeout=600.0)
        cpu1 = {n: cpu_seconds(p.pid) for n, p in procs.items()}
        main1 = main_thread_seconds(procs[slam].pid)
        rss1 = {n: rss_mb(p.pid) for n, p in procs.items()}
    finally:
        for p in procs.values():
            p.send_signal(signal.SIGINT)
        diag.send_signal(signal.SIGINT)
        last = {}
        out, _ = diag.communicate(timeout=30)
        for line in out.splitlines():
            name, _, text = line.partition(' ')
            last[name] = text
        for p in procs.values():
            p.wait(30)
        if listener is not None:
            listener.send_signal(signal.SIGINT)
            poses, _ = listener.communicate(timeout=30)
    if args.soak is not None:
        values = dict(kv.split('=') for kv in last.get('corner_extractor', '').split())
        scans = int(values.get('processed', 0)) + int(values.get('dropped', 0))
    print(f'{args.bag}: {scans} scans at rate {args.rate} in {wall:.1f} s, code {args.repo}, '
          f'threads {args.threads if args.threads is not None else "default"}')
    for n in nodes:
        print(f'{n:18s} CPU {1e3 * (cpu1[n] - cpu0[n]) / scans:7.2f} ms per scan, RSS '
              f'{rss0[n]:.1f} -> {rss1[n]:.1f} MB; diagnostics: {last.get(n, "none")}')
    if args.graph:
        return compare_graph(scenario, noise, poses)
    if args.soak is None and noise is not None:  # (an older --repo has no front end)
        core_ms, size = core_step_ms(scenario, noise, args.landmarks, args.visibility,
                                     slam_map, options=slam_options)
        paced_ms, _ = core_step_ms(scenario, noise, args.landmarks, args.visibility,
                                   slam_map, rate=args.rate, options=slam_options)
        print(f'map at the end: {size} landmarks')
        values = dict(kv.split('=') for kv in last.get('ekf_slam', '').split())
        steps = int(values.get('processed', scans)) or scans  # (steps: the sets processed)
        node_ms = 1e3 * (cpu1['ekf_slam'] - cpu0['ekf_slam']) / steps
        main_ms = 1e3 * (main1 - main0) / steps
        print(f'core (SlamFrontend + EkfSlam, offline, same bag) {core_ms:.2f} ms per step '
              f'back to back, {paced_ms:.2f} ms at the bag rate x {args.rate:g}; '
              f'ekf_slam node CPU / core = {node_ms / paced_ms:.2f} at the rate '
              f'({node_ms / core_ms:.2f} back to back; main thread {main_ms:.2f} ms per step, '
              f'the other threads (DDS) {node_ms - main_ms:.2f} ms)')
    return 0


def compare_graph(scenario, noise, text: str) -> int:
    """Compare graph_slam's poses with the offline graph run on the same bag; print them.

    Returns:
        0 when the node gave every offline step, each within 1 mm, else 1.
    """
    import numpy as np
    from landmark_nav.evaluation.slam_graph import run_graph
    lines = [line.split() for line in text.splitlines() if line.strip()]
    stamps = np.array([int(v[0]) for v in lines], dtype=np.int64)
    xy = np.array([[float(v[1]), float(v[2])] for v in lines]).reshape(-1, 2)
    tic = time.process_time()
    ref = run_graph(scenario, noise)
    cpu = time.process_time() - tic
    k = len(ref.stamps)
    same = len(stamps) >= k and np.array_equal(stamps[:k], ref.stamps)
    err = np.hypot(*(xy[:k] - ref.online[:, :2]).T) if same and k else np.array([np.inf])
    print(f'graph_slam published {len(stamps)} poses; the offline run (evaluate --backend '
          f'graph, {1e3 * cpu / max(k, 1):.1f} ms CPU per scan) {k} steps; same stamps: '
          f'{same}; largest node - offline distance {err.max():.3g} m; keyframes '
          f'{len(ref.graph.keyframes)}, loops {ref.graph.loop_counts.accepted} accepted of '
          f'{ref.graph.loop_counts.proposed} proposed')
    return 0 if same and err.max() <= 1e-3 else 1


def wait_idle(pids, timeout: float = 120.0, period: float = 1.0) -> None:
    """Wait until each process uses under 2 % of a CPU over ``period`` (start-up done)."""
    end = time.monotonic() + timeout
    last = [cpu_seconds(p) for p in pids]
    while time.monotonic() < end:
        time.sleep(period)
        now = [cpu_seconds(p) for p in pids]
        if all(b - a < 0.02 * period for a, b in zip(last, now)):
            return
        last = now


def far_map(n: int):
    """Return a map of ``n`` corners 1 km and more from the origin, 1 m apart."""
    import numpy as np
    from landmark_nav.slam.slam_map import SlamMap
    k = np.arange(n)
    means = np.column_stack([1000.0 + (k % 20), 1000.0 + k // 20]).astype(float)
    return SlamMap(ids=k.astype(np.int64), kinds=np.zeros(n, np.int8), means=means,
                   covariance=0.01 * np.eye(2 * n), ends=np.full((n, 2, 2), np.nan),
                   bisectors=np.zeros((n, 2)), openings=np.full(n, np.nan),
                   n_openings=np.zeros(n, np.int64), hits=np.full(n, 5, np.int64),
                   max_seen=np.full(n, 5.0), next_id=n)


def params_file_options(path: str = None) -> dict:
    """Return the ``SlamParams`` and ``FrontendParams`` fields and ``landmarks`` of a run.

    The ``ekf_slam`` defaults with the file (None: none) on top, read as the node reads
    them (``SLAM_PARAMETERS``, ``FRONTEND_PARAMETERS``): a parameter's "auto" value (0)
    stands for the field's None (off). :func:`split_frontend` separates the two kinds.
    """
    from landmark_nav.slam.configuration import (default_values, FRONTEND_PARAMETERS,
                                                 SLAM_PARAMETERS)
    from landmark_nav.tools.node_parameters import read_params_file
    values = default_values()
    if path:
        values.update(read_params_file(path, 'ekf_slam'))
    out = {}
    for k, v in values.items():
        if k in SLAM_PARAMETERS:
            auto = SLAM_PARAMETERS[k][3:]
            out[k] = None if auto and v == auto[0] else v
        elif k in FRONTEND_PARAMETERS:
            out[k] = v
    if 'landmarks' in values:
        out['landmarks'] = values['landmarks']
    return out


def split_frontend(options: dict) -> tuple:
    """Split :func:`params_file_options` output: ``(other options, FrontendParams)``."""
    from dataclasses import fields
    from landmark_nav.slam.frontend import FrontendParams
    names = {f.name for f in fields(FrontendParams)}
    rest = {k: v for k, v in (options or {}).items() if k not in names}
    return rest, FrontendParams(**{k: v for k, v in (options or {}).items() if k in names})


def core_step_ms(scenario, noise, landmarks: str = 'corners', visibility: bool = True,
                 slam_map=None, rate: float = None, options: dict = None) -> tuple:
    """CPU time per step of the offline pipeline on the scenario (corners extracted first).

    The front end gets the bag's odometry and each scan's corners (and lines, extracted
    in the timed part as the node does) with the scan's geometry in the bag's order, as
    :func:`landmark_nav.evaluation.slam.run_slam` gives them; only its calls are timed
    (process CPU time, as the node's figure). With ``rate`` each input is handed over at
    its stamp's time in the bag divided by ``rate`` (the process sleeps in between, as
    the node does between messages; the sleep is not timed), else back to back. A
    process that wakes at sensor rate runs the same code slower than one that runs it
    back to back (caches and the CPU are cold after each sleep: on the office bag at 200
    landmarks 7.0 against 4.7 ms per step): the node's overhead is what it spends beyond
    the core run at the same rate.

    Returns:
        ``(ms per step, landmarks in the map at the end)``.
    """
    from dataclasses import replace
    from landmark_nav.evaluation.slam import scan_features
    from landmark_nav.laser.corners import CornerParams
    from landmark_nav.laser.lines import LineParams
    from landmark_nav.sim import OdometrySample, ScanSample
    from landmark_nav.slam.ekf_slam import SlamParams
    from landmark_nav.slam.frontend import Corners, SlamFrontend
    from landmark_nav.slam.visibility import ScanGeometry
    from threadpoolctl import threadpool_limits
    import numpy as np
    options, fp = split_frontend(options)
    params = SlamParams(**options)
    params = params if noise is None else replace(params, odometry=noise)
    laser = scenario.laser
    cp = CornerParams(sigma_r=laser.sigma_range, sigma_phi=laser.sigma_angle)
    lp = LineParams(sigma_r=laser.sigma_range, sigma_phi=laser.sigma_angle)
    mount = np.asarray(laser.mount, dtype=float)
    inputs = [(True, e, None) if isinstance(e, OdometrySample) else
              (False, e, scan_features(e, 'corners', cp)[0] if landmarks != 'lines' else [])
              for e in scenario.events if isinstance(e, (OdometrySample, ScanSample))]
    fe = SlamFrontend(params, mount, fp, slam_map=slam_map)
    steps, cpu = 0, 0.0
    start_wall, start_ns = time.monotonic(), inputs[0][1].stamp_ns if inputs else 0
    with threadpool_limits(1):  # as the nodes (one thread by default)
        for is_odom, e, corners in inputs:
            if rate:
                time.sleep(max(0.0, start_wall + (e.stamp_ns - start_ns) * 1e-9 / rate
                               - time.monotonic()))
            t0 = time.process_time()
            if is_odom:
                steps += len(fe.add_odometry(e.stamp_ns, e.pose, e.covariance)[1])
            else:
                lines = scan_features(e, 'lines', cp, lp)[1] if landmarks != 'corners' else []
                geometry = (ScanGeometry(np.asarray(e.ranges, dtype=float), e.angle_min,
                                         e.angle_increment, e.range_min, e.range_max, mount,
                                         float(laser.sigma_range)) if visibility else None)
                steps += len(fe.add_features(Corners.from_corners(
                    e.stamp_ns, corners, e.time_increment, lines, lp.sigma_r, geometry)))
            cpu += time.process_time() - t0
        t0 = time.process_time()
        steps += len(fe.flush())
        cpu += time.process_time() - t0
    return 1e3 * cpu / max(steps, 1), fe.slam.num_landmarks


# Run a module under cProfile with the main thread's CPU time as the clock (not the wall).
PROFILE = """
import cProfile, runpy, sys, time
out, module = sys.argv[1], sys.argv[2]
sys.argv = [module] + sys.argv[3:]
prof = cProfile.Profile(time.thread_time)
prof.enable()
try:
    runpy.run_module(module, run_name='__main__')
except SystemExit:
    pass
finally:
    prof.disable()
    prof.dump_stats(out)
"""

# A listener printing every pose of graph_slam at exit: "stamp_ns x y" lines.
POSE_LISTENER = """
import rclpy
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.executors import ExternalShutdownException
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
rclpy.init()
node = rclpy.create_node('bench_poses')
rows = []
def on(msg):
    s = msg.header.stamp
    p = msg.pose.pose.position
    rows.append(f'{s.sec * 1000000000 + s.nanosec} {p.x!r} {p.y!r}')
node.create_subscription(PoseWithCovarianceStamped, 'pose', on, QoSProfile(
    depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_ALL))
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
for row in rows:
    print(row, flush=False)
"""

# A listener printing the last /diagnostics input status of each node.
DIAG_LISTENER = """
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import ExternalShutdownException
rclpy.init()
node = rclpy.create_node('bench_diagnostics')
last = {}
def on(msg):
    for s in msg.status:
        if s.name.endswith(': input'):
            last[s.name.split(':')[0]] = ' '.join(f'{v.key}={v.value}' for v in s.values)
node.create_subscription(DiagnosticArray, '/diagnostics', on, 10)
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
for k, v in last.items():
    print(k, v, flush=True)
"""

if __name__ == '__main__':
    raise SystemExit(main())
