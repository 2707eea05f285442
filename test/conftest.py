"""Shared test set-up: a private DDS domain on localhost; owned processes; shared runs.

Every process a test starts is owned (:mod:`landmark_nav.testing.pytest_processes`): the
``processes`` fixture stops, kills if it must, and reaps it at the end of the test; a test
after which a process it started still runs fails, and so does the run if anything it
started outlives it.
"""

import fcntl
import os
from pathlib import Path
import pickle
import resource
import sys
from typing import Any, Callable, Tuple

from landmark_nav.testing import isolate_dds
import pytest

pytest_plugins = ('landmark_nav.testing.pytest_processes',)

REPO = Path(__file__).resolve().parents[1]

isolate_dds()  # a domain of this process's own (each xdist worker its own), localhost only


@pytest.fixture(scope='session')
def repo() -> Path:
    """Return the repository root."""
    return REPO


@pytest.fixture(scope='session')
def run_once(tmp_path_factory) -> Callable[[str, Callable[[Path], Any]], Tuple[Any, Path]]:
    """Return ``get(key, compute)``: ``compute(folder)`` once per test run, for every worker.

    The pytest-xdist workers of one run share the parent of their temporary folders; the
    first worker to ask for ``key`` computes it (under a file lock) into a folder there
    and stores its return value; the others wait and read it. ``get`` returns that value
    and the folder, which the tests only read. For the runs several test files need (the
    office evaluation, the demo), each done once instead of once per worker.
    """
    base = tmp_path_factory.getbasetemp()
    shared = (base.parent if os.environ.get('PYTEST_XDIST_WORKER') else base) / 'run_once'

    def get(key: str, compute: Callable[[Path], Any]) -> Tuple[Any, Path]:
        shared.mkdir(parents=True, exist_ok=True)
        folder, result = shared / key, shared / f'{key}.pickle'
        with open(shared / f'{key}.lock', 'a') as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not result.exists():
                value = compute(folder)
                partial = result.with_suffix('.partial')
                partial.write_bytes(pickle.dumps(value))
                partial.rename(result)
            return pickle.loads(result.read_bytes()), folder
    return get


@pytest.fixture(scope='session')
def office_evaluation(run_once) -> Callable[[str], Tuple[dict, Path]]:
    """Return ``get(association)``: ``evaluate_bag`` of bags/office, once per test run.

    With the chapter profile (the filter of the simulator figures). ``get`` gives the
    figures and the folder with the written files (TUM, slam.json, plots);
    test_evaluate_slam.py, test_trajectory.py and the golden jcbb run need the same run.
    The ICNN run is the demo's (``office_demo``), which makes that very call.
    """
    from landmark_nav.evaluation.slam import evaluate_bag
    from landmark_nav.tools.demo import chapter_config
    bag = REPO / 'bags' / 'office'

    def get(association: str) -> Tuple[dict, Path]:
        if association == 'icnn':  # the demo's own evaluation: the same call
            (_, result), folder = run_once('office_demo', _office_demo)
            return result, folder
        return run_once(f'office_evaluate_{association}', lambda out: evaluate_bag(
            bag, association, out, progress=False, config=chapter_config(bag)))
    return get


def _office_demo(out: Path) -> Tuple[str, dict]:
    """Return the summary of ``run_demo`` on bags/office and the figures of its evaluation.

    The demo evaluates the bag as ``office_evaluation('icnn')`` does (``evaluate_bag`` with
    ICNN and the chapter profile, its files written into the demo's folder): that call's
    figures are kept, and the call checked to be that one.
    """
    import landmark_nav.evaluation.slam as slam
    from landmark_nav.tools.demo import chapter_config, run_demo
    bag, calls, evaluate_bag = REPO / 'bags' / 'office', [], slam.evaluate_bag

    def recorded(*args, **kwargs):
        calls.append((args, kwargs, evaluate_bag(*args, **kwargs)))
        return calls[-1][2]
    slam.evaluate_bag = recorded
    try:
        summary = run_demo(bag, out)
    finally:
        slam.evaluate_bag = evaluate_bag
    (args, kwargs, result), = calls
    assert args == (bag, 'icnn', out) and sorted(kwargs) == ['config', 'progress'], (
        args, kwargs)
    assert kwargs['config'] == chapter_config(bag)
    return summary, result


@pytest.fixture(scope='session')
def office_demo(run_once) -> Tuple[str, Path]:
    """Return the summary and the folder of ``run_demo`` on bags/office, once per test run.

    The folder also holds the files of ``office_evaluation('icnn')``: the demo's evaluation.
    """
    (summary, _), folder = run_once('office_demo', _office_demo)
    return summary, folder


@pytest.fixture(scope='session')
def carmen_evaluation(run_once) -> Tuple[Tuple[dict, dict], Path]:
    """Return ``((per-topic counts, figures), folder)``: a real log evaluated once per test run.

    ``import_log`` of the Freiburg 101 CARMEN log into ``folder / 'bag'`` and
    ``evaluate_bag`` of that bag with its defaults (files and plots in ``folder / 'out'``);
    test_evaluate_slam.py and test_trajectory.py check the same run.
    """
    from landmark_nav.evaluation.slam import evaluate_bag
    from landmark_nav.importers import import_log
    from landmark_nav.testing import shared_data

    def compute(out: Path) -> Tuple[dict, dict]:
        imported = import_log(shared_data('carmen', 'freiburg-101-corrected.log.gz'),
                              out / 'bag')
        return dict(imported.counts), evaluate_bag(out / 'bag', out_dir=out / 'out',
                                                   progress=False)
    return run_once('carmen_evaluate', compute)


@pytest.fixture(scope='session')
def hallway_localization(run_once) -> Callable[[int], dict]:
    """Return ``get(seed)``: a simulated hallway and its sonar localization, once per test run.

    The protocol of ``hallway_study``, test_loc_accuracy.py and test_loc_nees.py: the map
    ``rasterize_world(world, 0.1)``, the start drawn from ``CHAPTER_P0`` with generator seed
    ``1000 + seed``, the EKF and the UKF through ``run_localization``. ``get`` gives
    ``inp`` (the LocalizationInput), ``grid``, ``path_length``, ``i0`` (the first motion),
    ``x0`` and per filter (``'ekf'``, ``'ukf'``) ``(trajectory, covariances)``.
    """
    from landmark_nav.evaluation.localization import (CHAPTER_P0, draw_initial_pose,
                                                      first_motion_index, LocalizationInput,
                                                      run_localization)
    from landmark_nav.localization.grid import rasterize_world
    from landmark_nav.sim import run_scenario

    def compute(seed: int) -> dict:
        res = run_scenario('hallway', seed)
        inp = LocalizationInput.from_result(res)
        grid = rasterize_world(res.world, 0.1)
        x0 = draw_initial_pose(inp.truth[0], CHAPTER_P0, 1000 + seed)
        out = {'inp': inp, 'grid': grid, 'path_length': float(res.path_length),
               'i0': first_motion_index(inp.truth), 'x0': x0}
        for filt in ('ekf', 'ukf'):
            out[filt] = run_localization(res, filt, grid, x0, CHAPTER_P0)
        return out
    return lambda seed: run_once(f'hallway_localization_{seed}', lambda _: compute(seed))[0]


@pytest.fixture(scope='session')
def hallway_bag_localization(run_once) -> Tuple[dict, Path]:
    """Return ``({filter: result}, folder)``: ``evaluate_localization`` of bags/hallway.

    The EKF and the UKF with the defaults, their files written into ``folder``: the
    ``localization`` run of bags/hallway/expected.yaml, once per test run for
    test_golden.py and test_localization_tools.py.
    """
    from landmark_nav.evaluation.localization_bags import evaluate_localization
    bag = REPO / 'bags' / 'hallway'
    return run_once('hallway_bag_localization', lambda out: {
        filt: evaluate_localization(bag, filt, out_dir=out) for filt in ('ekf', 'ukf')})


@pytest.fixture(scope='session')
def hallway_sonar_map_localization(run_once) -> Tuple[dict, Path]:
    """Return ``({'summary', 'ekf', 'ukf'}, folder)``: a sonar map of bags/hallway, localized on.

    ``build_sonar_map`` of bags/hallway with its defaults into ``folder / 'map.yaml'``, then
    ``evaluate_localization`` on that map (EKF and UKF, files in ``folder / 'localization'``):
    the ``sonar_map_localization`` run of bags/hallway/expected.yaml, once per test run for
    test_golden.py and test_localization_tools.py.
    """
    from landmark_nav.evaluation.localization_bags import evaluate_localization
    from landmark_nav.tools.localization_tools import build_sonar_map
    bag = REPO / 'bags' / 'hallway'

    def compute(out: Path) -> dict:  # build_sonar_map creates the folder
        got = {'summary': build_sonar_map(bag, out=out / 'map.yaml')}
        for filt in ('ekf', 'ukf'):
            got[filt] = evaluate_localization(bag, filt, map_path=out / 'map.yaml',
                                              out_dir=out / 'localization')
        return got
    return run_once('hallway_sonar_map_localization', compute)


def pytest_configure(config):
    """Before the pytest-xdist workers start, write the bytecode caches they all need.

    Each worker rewrites and compiles every test module and compiles the package's modules
    where no cache exists (a fresh clone): done once here, on every CPU, instead. Not where
    the environment says not to write bytecode, nor with the assertion pass hook (pytest's
    rewriting of the test modules then depends on the configuration).
    """
    if (os.environ.get('PYTEST_XDIST_WORKER') or not config.getoption('numprocesses', None)
            or sys.dont_write_bytecode or config.getini('enable_assertion_pass_hook')):
        return
    from landmark_nav.testing.bytecode_caches import write_bytecode_caches
    tests = REPO / 'test'
    write_bytecode_caches(sorted(tests.glob('test_*.py')), sorted(
        [*(REPO / 'landmark_nav').rglob('*.py'),
         *(p for p in tests.glob('*.py') if not p.name.startswith(('test_', 'conftest')))]))


_CPU_LOG = os.environ.get('LANDMARK_NAV_TEST_CPU')


def _cpu_seconds() -> float:
    """Return the CPU time of this process and of its reaped children [s]."""
    me, children = (resource.getrusage(w) for w in (
        resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return me.ru_utime + me.ru_stime + children.ru_utime + children.ru_stime


if _CPU_LOG:  # where the suite's CPU goes: LANDMARK_NAV_TEST_CPU=FILE make test
    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        """Append the test's id and its CPU seconds (fixtures included) to the file."""
        start = _cpu_seconds()
        yield
        with open(_CPU_LOG, 'a') as log:
            log.write(f'{item.nodeid}\t{_cpu_seconds() - start:.3f}\n')


#: the files that cost the most CPU, most first: CPU seconds per file of
#: ``LANDMARK_NAV_TEST_CPU=FILE make test`` (each test's CPU, its module fixtures and the
#: runs it computes for others included) on an idle fresh clone: evaluate_slam 82,
#: benchmarks 44, golden 44, node_runtime 32, landmark_repeatability 32,
#: slam_landmark_types 30, slam_ambiguous 29, corridor_frame 28, flake8 28 (one process),
#: ekf_slam_node 25 ... lines 8.6, soak 8.4 (a shared run lands on the file that asks
#: first); a file missing from the list only runs later
LONGEST_FILES = (
    'test_evaluate_slam.py', 'test_benchmarks.py', 'test_golden.py', 'test_node_runtime.py',
    'test_landmark_repeatability.py', 'test_slam_landmark_types.py', 'test_slam_ambiguous.py',
    'test_corridor_frame.py', 'test_flake8.py', 'test_ekf_slam_node.py',
    'test_loc_accuracy.py', 'test_road_fusion.py', 'test_landmark_detection_rates.py',
    'test_protocol_lms2xx.py', 'test_pipeline.py', 'test_laser_noise_precedence.py',
    'test_landmark_shuttle.py',
    'test_corridor_follower_node.py', 'test_false_surfaces.py', 'test_monocular.py',
    'test_cli.py', 'test_sonar_localizer_node.py', 'test_protocol_p2os.py', 'test_record.py',
    'test_slam_office.py', 'test_york_vanishing_points.py', 'test_stop_signals.py',
    'test_landmark_pose.py', 'test_trajectory.py', 'test_protocol_scip2.py',
    'test_emulator_robot.py', 'test_evaluate_features_params.py', 'test_landmarks_real.py',
    'test_lines.py', 'test_evaluate_localization_params.py', 'test_soak.py')


def pytest_collection_modifyitems(items):
    """Order the files longest first: the listed ones, then other slow ones, then the rest.

    ``make test`` gives each pytest-xdist worker whole files in collection order
    (``--no-loadscope-reorder``: xdist would otherwise order files by their number of
    tests, so that a long file of two tests started last and ran alone at the end while
    the other workers idled).
    """
    slow_files = {item.path for item in items if item.get_closest_marker('slow')}

    def rank(item) -> Tuple[int, int]:
        if item.path.name in LONGEST_FILES:
            return 0, LONGEST_FILES.index(item.path.name)
        return (1 if item.path in slow_files else 2), 0
    items.sort(key=rank)
