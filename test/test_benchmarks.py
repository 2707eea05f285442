"""Smoke test of the benchmark suite: every entry point's --help, and a tiny run of each.

``benchmarks/`` holds one script per documented figure group (``common.py`` is their shared
helpers, not an entry point). Each entry point must print its help and exit 0, and must run
on a tiny input (the tiny logs, images and bags of :mod:`tiny_logs`, written in a temporary
folder, or a committed bag with a few scans) printing the line that carries its figures,
exit status 0. No benchmark may touch a private name of the package. A new script needs a
tiny run here (:data:`TINY_RUNS`): the test fails for an entry point without one.

The figures of a tiny run mean nothing; what is checked is that the script runs end to end
on its data argument. To keep the CPU time small the scripts that need no DDS run one after
the other in one child interpreter (imports shared; each as ``__main__``, as from the
command line, its exit status and output kept apart); those that start nodes run each in
its own process on this worker's DDS domain.
"""

import ast
import json
import os
from pathlib import Path
import re
import subprocess
import sys

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import tiny_logs  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
BENCH = REPO / 'benchmarks'
HELPERS = ('common.py', 'slam_real_graph.py')
ENTRY_POINTS = sorted(p.name for p in BENCH.glob('*.py') if p.name not in HELPERS)

# script -> [(arguments, regular expression the output must match)]; {name} are the paths
# of the tiny inputs (fixture ``inputs``). The DDS ones run in their own process.
TINY_RUNS = {
    'bench_corners.py': [
        (['--bag', '{bag}', '--scans', '3', '--repeat', '1'], r'minus_cosine\s+[\d.]+\s+[\d.]+')],
    'bench_lines.py': [
        (['clusters', '--bag', '{bag}', '--scans', '3', '--repeat', '1'],
         r'split_merge\s+[\d.]+\s+[\d.]+\s+\d+'),
        (['logs', '--data', '{carmen}', 'tiny', '--scans', '3', '--repeat', '1'],
         r'\| tiny \(3\) \| 361 \| [\d.]+ \|')],
    'bench_feature_metrics.py': [
        (['metrics', '--data', '{carmen}', 'tiny', '--scans', '3'],
         r'\| tiny \| split_merge \| [\d.]+ \|'),
        (['metrics', '--direct', '{carmen}/tiny-corrected.log.gz', '--scans', '3'],
         r'\| tiny \| alfa \| [\d.]+ \|'),
        (['corner-repeatability', '--data', '{carmen}', 'tiny'],
         r'\| tiny \| [\d.]+ \(\d+/\d+\) \|'),
        (['structural-rule', '--data', '{carmen}', 'tiny', '--lengths', '0.2', '--steps', '5',
          '--min-share', '0'], r'all logs: L 0.2 m, N 5 beam steps: tiny ([\d.]+|nan) '),
        (['quantised-lines', '--data', '{carmen}', 'tiny', '--set', 'trim_sigma=3.0',
          '--gate-costs'],
         r'\| tiny \| [\d.]+ \| [\d.]+ \| 0.05 \| 2 \| [\d.]+ \| [\d.]+ \| ([\d.]+|nan) \| '
         r'([\d.]+|nan) \| \d+ \| \d+ \| (.*\n)+'
         r'\| tiny \| 0.05 \| 2 \| copy( \| ([\d.]+|nan)){6} \|'),
        (['line-covariance', '--data', '{carmen}', 'tiny'],
         r'\| tiny \| [\d.]+ cm \([\d.]+\) \| [\d.]+ / [\d.]+ / [\d.]+ \| 8–14 \| \d+ \| ')],
    'bench_slam.py': [
        (['step-time', '--landmarks', '10', '--steps', '3'], r'\n\s+10\s+23\s+[\d.]+'),
        (['step-time', '--bag', '{small_bag}', '--steps', '8'],
         r'\d+ EKF-SLAM steps through SlamFrontend.*\n.*\n\s+\d+\s+\d+\s+[\d.]+\s+[\d.]+')],
    'bench_slam_real.py': [
        (['evaluate', '--data', '{carmen}', 'tiny', '--landmarks', 'both'],
         r'tiny 0 both 0 \d+ \d+ [\d.]+'),
        (['diagnose', '--data', '{carmen}', 'tiny'], r'\ntiny [\d.]+ '),
        (['grid', '--data', '{carmen}', 'tiny', '--seeds', '0', '--procs', '1'],
         r'1 runs: ellipse median [\d.]+ %'),
        (['scan-matching', '--data', '{carmen}', 'tiny', '--seeds', '0', '--slam'],
         r'tiny-0 \| [\d.]+ / [\d.]+'),
        (['wean', '--data', '{wean}', 'robotdata1', '--corners', '--plot', '{tmp}'],
         r'\nrobotdata1 \d+ [\d.]+ (.*\n)+robotdata1 corners within 10 cm .* structural '
         r'([\d.]+|nan) of \d+ (.*\n)+robotdata1 structural convex ([\d.]+|nan) of \d+, '
         r'concave ([\d.]+|nan) of \d+; off the walls: \d+ of \d+ convex(.*\n)+'
         r'wrote .*robotdata1_structural_corners.png'),
        (['wean', '--data', '{wean}', 'robotdata1', '--backend', 'graph'],
         r'\nrobotdata1( \d+){7} [\d.]+ [\d.]+ ([\d.]+|nan)( \d+){2} ([\d.]+|nan)( \d+){2}\n'),
        (['defaults', '--data', '{carmen}', 'tiny'], r'\ntiny \| [\d.]+ / [\d.]+ \([\d.]+\) \|')],
    'bench_localization.py': [
        (['sonar', '--bag', '{hallway}', '--runs', '3'], r'EKF update\s+[\d.]+'),
        (['model', '--frames', '3'], r'lsd\s+[\d.]+\s+[\d.]+'),
        (['model', '--bag', '{corridor}', '--frames', '2'],
         r'2 frames at 320 x 240.*(\n.*)+\n\s+rwrht\s+[\d.]+\s+\d+')],
    'bench_landmarks.py': [
        (['detector', '--frames', '2', '--repeat', '1'], r'landmark detector\s+[\d.]+'),
        (['detector', '--data', '{photos}', '--frames', '1', '--repeat', '1'],
         r'1 images of .*\n(.*\n)+landmark detector\s+[\d.]+'),
        (['detector', '--versus-apriltag', '--data', '{photos}', '--frames', '1', '--repeat',
          '1'], r'default / AprilTag decimate 1: [\d.]+x'),
        (['real', 'all', '--data', '{photos}', '--per-size', '1', '--sizes', '5',
          '--per-distance', '1', '--false-frames', '2', '--detectors', 'landmark', 'aruco'],
         r'\| 5 px \| 1 \| [\d.]+ \|'),
        (['camera-sim', '--frames', '2'], r'render \(wall \+ landmark .*\s+[\d.]+ ms'),
        # the full samples' figures against their stored bounds: a sample this small
        # regresses, which the run reports (exit 0 with --no-fail)
        (['rates', '--frames', '1', '--views', '1', '--scattered', '1', '--no-fail'],
         r'figures: reads \d+, .*\nREGRESSION: reads = \d+ \(minimum \d+\)\n(.*\n)*rates: FAILED'),
        (['shuttle', '--trips', '1', '--no-fail'],
         r'figures: arrivals 1, .*\nREGRESSION: arrivals = 1 \(minimum \d+\)\n(.*\n)*'
         r'shuttle: FAILED')],
    'bench_vanishing_points.py': [
        (['--data', '{york}', '--repeat', '1', '--scales', '1'],
         r'segmented_hough manhattan\s+[\d.]+'),
        # held out end to end: the noise and the confidence fitted per fold
        (['--data', '{york_cv}', '--confidence', '--folds', '3', '--scales', '0.5'],
         r'\n\s+2\s+[\d.]+\s+[\d.]+\s+\d+(.*\n)+.*3-fold over 4 images(.*\n)+'
         r'  accuracy: axis median [\d.]+ deg')],
    'bench_road.py': [
        (['--scans', '3', '--frames', '2', '--data', '{camvid}'],
         r'vision CamVid 480x360 learned\s+[\d.]+')],
    'bench_corridor.py': [
        (['frames', '--frames', '2', '--repeat', '1', '--speed-only'],
         r'segmented_hough\s+[\d.]+\s+[\d.]+'),
        (['frames', '--data', '{corridor}', '--frames', '2', '--repeat', '1'],
         r'2 images at 320 x 240.*(\n.*)+\n\s+lsd\s+[\d.]+\s+[\d.]+'),
        (['loop', '--distance', '2.5', '--lengths', '1', '--domain', '{domain}'],
         r'lateral after the first 2 m: max [\d.]+ cm')],
    'bench_protocols.py': [
        (['--repeat', '3', '--no-fail'], r'P2OS status packet, P2osDecoder.feed\s+[\d.]+'),
        (['--capture', '{capture}', '--protocol', 'scip2', '--repeat', '3'],
         r'Scip2Decoder.feed of the whole capture: 3 frames, 0 errors\n.*\n\s+[\d.]+\s+[\d.]+')],
    'bench_node_cpu.py': [
        (['{bag}', '--seconds', '2', '--rate', '2', '--domain', '{domain}'],
         r'ekf_slam node CPU / core = [\d.]+')],
    'bench_live.py': [
        # the emulated robot, the memory run: a smoke run of 8 s (no memory bound: the nodes
        # may still be loading at the warm-up on a busy machine)
        (['--memory', '--seconds', '8', '--warmup', '2', '--limit-mb', '1000',
          '--domain', '{domain}', '--out', '{tmp}/live_emulator'],
         r'ekf_slam\s+ATE \(start frame, unaligned\): RMSE [\d.]+ cm, max [\d.]+ cm\n'
         r'ekf_slam\s+ATE SE\(2\)-aligned \(evo\): RMSE [\d.]+ cm(.|\n)*'
         r'\nekf_slam: input: processed [1-9]\d*(.|\n)*\nemulator +\d+ +[\d.]+ MB(.|\n)*'
         r'\nOK: every process grew'),
        # a recorded bag replayed through the nodes
        (['--bag', '{bag}', '--seconds', '4', '--warmup', '1', '--domain', '{domain}',
          '--out', '{tmp}/live_bag'],
         r'ekf_slam\s+ATE SE\(2\)-aligned \(evo\): RMSE [\d.]+ cm, max [\d.]+ cm\n'
         r'odometry\s+ATE SE\(2\)-aligned \(evo\): RMSE [\d.]+ cm(.|\n)*'
         r'\nekf_slam: input: processed [1-9]\d*(.|\n)*\nbag_player +\d+ +[\d.]+ MB')],
    'bench_soak.py': [
        (['--bag', '{small_bag}', '--seconds', '3', '--rate', '1', '--record', '1',
          '--results', '{tmp}/soak.json'], r'ekf_slam.latency_p95_ratio\s+[\d.]+')],
}
# Entry points that start ROS nodes (one process each, this worker's DDS domain).
DDS_RUNS = {('bench_corridor.py', 'loop'), ('bench_node_cpu.py', None),
            ('bench_live.py', None), ('bench_soak.py', None)}

# Runs each (script, argv) of a JSON list as ``__main__`` in this interpreter; writes
# [[exit status, output], ...] to the file named by argv[2].
_RUNNER = r"""
import contextlib, io, json, runpy, sys, traceback
folder, result = sys.argv[1:3]
sys.path.insert(0, folder)
jobs = json.load(sys.stdin)
out = []
for script, argv in jobs:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        sys.argv = [script] + argv
        try:
            runpy.run_path(script, run_name='__main__')
            code = 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
            if not isinstance(e.code, (int, type(None))):
                print(e.code)
        except BaseException:
            traceback.print_exc()
            code = 'exception'
    out.append([code, buf.getvalue()])
with open(result, 'w') as f:
    json.dump(out, f)
"""


def _is_dds(script: str, argv: list) -> bool:
    return (script, None) in DDS_RUNS or (script, argv[0] if argv else None) in DDS_RUNS


@pytest.fixture(scope='module')
def inputs(tmp_path_factory):
    """Write the tiny inputs; return the substitutions of :data:`TINY_RUNS`."""
    from landmark_nav.importers.writer import import_log
    tmp = tmp_path_factory.mktemp('bench')
    (tmp / 'carmen').mkdir()
    log = tiny_logs.write_carmen(tmp / 'carmen' / 'tiny-corrected.log.gz')
    import_log(log, tmp / 'small_bag')   # 4 s of scans and odometry, with a reference
    tiny_logs.write_wean(tmp / 'wean')
    tiny_logs.write_york(tmp / 'york')
    tiny_logs.write_york(tmp / 'york_cv', images=4, off_deg=5.0)
    tiny_logs.write_camvid(tmp / 'camvid')
    tiny_logs.write_camvid(tmp / 'photos_src')
    (tmp / 'photos').mkdir()
    for p in (tmp / 'photos_src' / 'images').glob('*.png'):
        p.rename(tmp / 'photos' / p.name)
    tiny_logs.write_scip2_capture(tmp / 'capture.bin', frames=3)
    return {'carmen': str(tmp / 'carmen'), 'wean': str(tmp / 'wean'),
            'york': str(tmp / 'york'), 'york_cv': str(tmp / 'york_cv'),
            'camvid': str(tmp / 'camvid'),
            'photos': str(tmp / 'photos'), 'small_bag': str(tmp / 'small_bag'),
            'bag': str(REPO / 'bags' / 'office'), 'hallway': str(REPO / 'bags' / 'hallway'),
            'corridor': str(REPO / 'bags' / 'corridor'), 'capture': str(tmp / 'capture.bin'),
            'tmp': str(tmp), 'domain': os.environ.get('ROS_DOMAIN_ID', '0')}


def _argv(argv: list, inputs: dict) -> list:
    return [a.format(**inputs) for a in argv]


def _run_in_one_interpreter(jobs: list, tmp: Path) -> list:
    """Run ``[(script path, argv)]`` in one child interpreter; return [(status, output)]."""
    result = tmp / 'results.json'
    child = subprocess.run([sys.executable, '-c', _RUNNER, str(BENCH), str(result)],
                           input=json.dumps(jobs), capture_output=True, text=True,
                           cwd=REPO, timeout=900)
    assert child.returncode == 0 and result.is_file(), child.stdout + child.stderr
    return [tuple(r) for r in json.loads(result.read_text())]


def test_every_entry_point_has_a_tiny_run():
    assert ENTRY_POINTS, 'no benchmark found'
    assert sorted(TINY_RUNS) == ENTRY_POINTS


def _subcommands(script: str) -> list:
    """Return the subcommands of a script's tiny runs (empty: a script without)."""
    names = {argv[0] for argv, _ in TINY_RUNS.get(script, [])
             if argv and not argv[0].startswith('-') and '{' not in argv[0]}
    return sorted(names)


def test_help_of_every_entry_point_and_subcommand(tmp_path):
    jobs = []
    for script in ENTRY_POINTS:
        jobs.append((str(BENCH / script), ['--help']))
        jobs += [(str(BENCH / script), [sub, '--help']) for sub in _subcommands(script)]
    results = _run_in_one_interpreter(jobs, tmp_path)
    for (script, argv), (status, output) in zip(jobs, results):
        name = f'{Path(script).name} {" ".join(argv)}'
        assert status == 0, f'{name}: exit status {status}\n{output[-3000:]}'
        assert 'usage:' in output and '--help' in output, f'{name}: no usage\n{output}'


@pytest.mark.slow
def test_tiny_runs_without_dds(inputs, tmp_path):
    jobs, expected = [], []
    for script, runs in TINY_RUNS.items():
        for argv, pattern in runs:
            if not _is_dds(script, argv):
                jobs.append((str(BENCH / script), _argv(argv, inputs)))
                expected.append(pattern)
    results = _run_in_one_interpreter(jobs, tmp_path)
    for (script, argv), pattern, (status, output) in zip(jobs, expected, results):
        name = f'{Path(script).name} {" ".join(argv)}'
        assert status == 0, f'{name}: exit status {status}\n{output[-3000:]}'
        assert re.search(pattern, output), f'{name}: no {pattern!r} in\n{output[-3000:]}'


@pytest.mark.slow
@pytest.mark.dds
@pytest.mark.parametrize('script, argv, pattern', [
    (s, a, p) for s, runs in TINY_RUNS.items() for a, p in runs if _is_dds(s, a)],
    ids=lambda v: v if isinstance(v, str) and v.endswith('.py') else '')
def test_tiny_runs_with_dds(inputs, script, argv, pattern):
    child = subprocess.run([sys.executable, str(BENCH / script)] + _argv(argv, inputs),
                           capture_output=True, text=True, cwd=REPO, timeout=300)
    output = child.stdout + child.stderr
    assert child.returncode == 0, f'{script}: exit status {child.returncode}\n{output[-3000:]}'
    assert re.search(pattern, output), f'{script}: no {pattern!r} in\n{output[-3000:]}'


def _private_uses(path: Path) -> list:
    """Return ``line: name`` of each private name of landmark_nav that a script uses.

    Private: a ``_name`` imported from a landmark_nav module, a module path with a
    ``_part``, or a ``_name`` attribute of a landmark_nav module (or of a name imported
    from one).
    """
    tree = ast.parse(path.read_text(), filename=str(path))
    out, package_names = [], set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or '').startswith('landmark_nav'):
            if any(p.startswith('_') and p != '__init__' for p in node.module.split('.')):
                out.append(f'{node.lineno}: {node.module}')
            for alias in node.names:
                if alias.name.startswith('_'):
                    out.append(f'{node.lineno}: {node.module}.{alias.name}')
                package_names.add(alias.asname or alias.name)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith('landmark_nav'):
                    package_names.add((alias.asname or alias.name).split('.')[0])
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and node.attr.startswith('_')
                and not node.attr.startswith('__')):
            base = node.value
            while isinstance(base, (ast.Attribute, ast.Call, ast.Subscript)):
                base = base.func if isinstance(base, ast.Call) else base.value
            if isinstance(base, ast.Name) and base.id in package_names:
                out.append(f'{node.lineno}: {base.id}...{node.attr}')
    return sorted(out, key=lambda s: int(s.split(':')[0]))


def test_private_name_check_finds_private_uses(tmp_path):
    script = tmp_path / 'bench_x.py'
    script.write_text('from landmark_nav.laser.line_extraction.tls_fit import _sse, fit\n'
                      'import landmark_nav.laser.lines as L\n'
                      'from landmark_nav.laser import corners\n'
                      'L._extract(1)\ncorners.detect_corners(2)._cache\n'
                      'corners._free_side\n')
    assert _private_uses(script) == [
        '1: landmark_nav.laser.line_extraction.tls_fit._sse', '4: L..._extract',
        '5: corners..._cache', '6: corners..._free_side']


@pytest.mark.parametrize('script', ENTRY_POINTS + list(HELPERS))
def test_no_benchmark_touches_a_private_name(script):
    assert _private_uses(BENCH / script) == []
