"""What a bag states: ``--set`` > the bag > the defaults, offline, in the replay and its launch.

The laser noise, the laser mount and the odometry noise model: ``landmark_nav evaluate``,
``landmark_nav pipeline replay`` and ``launch/replay.launch.py`` take them from one function
(:func:`landmark_nav.evaluation.slam.run_parameters`). The bag is the office recording's
first 6 s re-encoded with the imported-bag contract's ``custom_data`` stating a range noise
of 2 cm (the shipped parameters say 1 cm), the mount ``0 0 0`` and a drift model.
"""

import json
from pathlib import Path
import subprocess
import sys
import time

from geometry_msgs.msg import PoseWithCovarianceStamped
from landmark_nav.bag import BagReader
from landmark_nav.conversions import odometry_to_pose
from landmark_nav.evaluation.slam import bag_configuration, evaluate_bag, run_parameters
from landmark_nav.evaluation.trajectory import read_tum
from landmark_nav.testing import RosHarness
from landmark_nav.tools.cli import main as cli_main
from landmark_nav.tools.pipeline import pipeline_commands
import numpy as np
import pytest
from test_evaluate_slam import BAG, reencode

STATED = 0.02  # the bag's range noise [m]
DRIFT = 'k_d=0.05 k_theta=0.05 k_dtheta=0.1'  # the bag's odometry noise model
MOUNT = [0.05, 0.0, 0.02]  # a --set laser mount [m m rad]
GAIN = 'odometry.sigma_xy_per_sqrt_m=0.01'  # a --set odometry gain (the bag's model: 0.05)


@pytest.fixture(scope='module')
def stated_bag(tmp_path_factory) -> Path:
    """Return the office bag's first 6 s stating a 2 cm range noise (read only)."""
    bag = tmp_path_factory.mktemp('stated') / 'bag'
    with BagReader(BAG) as reader:  # the odometry kept where it starts (at the reference)
        start = next(odometry_to_pose(m).pose for _, _, m in reader.decoded(['/odom']))
    reencode(BAG, bag, reference_topic=True, seconds=6, odom_start=start,
             custom={'landmark_nav.laser_mount': '0 0 0',
                     'landmark_nav.laser_sigma_range': str(STATED),
                     'landmark_nav.drift_model': DRIFT})
    return bag


def _evaluate(bag: Path, out: Path, *args: str) -> dict:
    assert cli_main(['evaluate', str(bag), '--max-seconds', '5', '--no-progress',
                     '--out', str(out)] + list(args)) == 0
    return json.loads((out / 'slam.json').read_text())


def test_evaluate_set_wins_over_the_bags_range_noise(stated_bag, tmp_path, capsys):
    """--set laser_sigma_range and --set lines.sigma_r change the run on a bag stating one."""
    runs = {'bag': (), 'range': ('--set', 'laser_sigma_range=0.04'),
            'lines': ('--set', 'lines.sigma_r=0.04')}
    figures = {name: _evaluate(stated_bag, tmp_path / name, *args)
               for name, args in runs.items()}
    text = capsys.readouterr().out
    assert 'sigma_r 0.04 m (the parameter laser_sigma_range) instead of 0.02 m' in text
    assert figures['bag']['laser_sigma_range'] == STATED  # the bag's over the default
    assert figures['range']['laser_sigma_range'] == 0.04  # --set over the bag's
    assert figures['lines']['laser_sigma_range'] == STATED
    tum = {name: (tmp_path / name / 'trajectory_slam.tum').read_text() for name in runs}
    assert tum['range'] != tum['bag'] and tum['lines'] != tum['bag'] != ''
    # The lines follow --set laser_sigma_range unless --set gives their own.
    config = bag_configuration(stated_bag, settings={'laser_sigma_range': 0.04})
    assert config.line_params.sigma_r == 0.04 and config.laser_sigma_range == 0.04
    config = bag_configuration(stated_bag, settings={'laser_sigma_range': 0.04,
                                                     'lines.sigma_r': 0.03})
    assert config.line_params.sigma_r == 0.03
    assert bag_configuration(stated_bag).line_params.sigma_r == STATED


def test_replay_gives_every_node_the_noise_evaluate_takes(stated_bag):
    """corner_extractor gets the bag's noise, or ekf_slam's --set one; its own --set last."""
    def args(settings=()):
        cmds = pipeline_commands('replay', list(settings), bag=str(stated_bag))
        return {node: cmd[cmd.index('--params-file') + 2:] for node, cmd in cmds.items()
                if node != 'bag_player'}
    phi = ['-p', 'sigma_phi:=0.0017453292519943296']
    got = args()
    assert got['corner_extractor'] == ['-p', f'sigma_r:={STATED}'] + phi
    assert ['-p', f'laser_sigma_range:={STATED}', '-p', f'lines.sigma_r:={STATED}'] == \
        got['ekf_slam'][2:6]
    got = args(['ekf_slam.laser_sigma_range=0.04', 'corner_extractor.sigma_phi=0.002'])
    assert got['corner_extractor'] == ['-p', 'sigma_r:=0.04'] + phi + ['-p', 'sigma_phi:=0.002']
    assert got['ekf_slam'][-2:] == ['-p', 'laser_sigma_range:=0.04']
    assert ['-p', 'lines.sigma_r:=0.04'] == got['ekf_slam'][4:6]
    # The same decision as evaluate's: one function.
    assert run_parameters(stated_bag, settings={'laser_sigma_range': 0.04})[
        'corner_extractor'] == {'sigma_r': 0.04, 'sigma_phi': 0.0017453292519943296}


def test_evaluate_set_wins_over_the_bags_mount(stated_bag, tmp_path, capsys):
    """--set laser_pose changes the run on a bag stating its mount; --laser-pose does not."""
    pose = ['--laser-pose', '0.3', '0', '0']
    runs = {'bag': (), 'option': pose, 'set': ('--set', f'laser_pose={MOUNT}'),
            'both': pose + ['--set', f'laser_pose={MOUNT}']}
    figures = {name: _evaluate(stated_bag, tmp_path / name, *args)
               for name, args in runs.items()}
    tum = {name: (tmp_path / name / 'trajectory_slam.tum').read_text() for name in runs}
    assert tum['option'] == tum['bag'] != tum['set'] == tum['both'] != ''
    mounts = {name: figures[name]['laser_mount'] for name in runs}
    assert mounts == {'bag': [0.0] * 3, 'option': [0.0] * 3, 'set': MOUNT, 'both': MOUNT}
    text = capsys.readouterr().out
    assert 'laser mount 0.05 0 0.02 (the parameter laser_pose) instead of 0 0 0' in text
    assert bag_configuration(stated_bag, laser_pose=(0.3, 0, 0)).laser_pose == (0, 0, 0)
    assert run_parameters(stated_bag, settings={'laser_pose': MOUNT})['ekf_slam'][
        'laser_pose'] == [0.0] * 3  # the bag's; the node's --set comes after it


def test_set_wins_over_the_bags_odometry_model(stated_bag):
    """The bag's drift model over the files, --set odometry.model over the bag, alike."""
    from landmark_nav.slam.frontend import odometry_noise_model
    files = {'odometry.model': 'simulator'}
    config = bag_configuration(stated_bag, files)
    assert config.params.odometry == odometry_noise_model(DRIFT)
    config = bag_configuration(stated_bag, files, {'odometry.model': 'pioneer'})
    assert config.params.odometry == odometry_noise_model('pioneer')
    cmd = pipeline_commands('replay', ['ekf_slam.odometry.model=pioneer'],
                            bag=str(stated_bag))['ekf_slam']
    models = [a for a in cmd if a.startswith('odometry.model:=')]
    assert models == [f'odometry.model:={DRIFT}', 'odometry.model:=pioneer']


def test_a_set_odometry_gain_wins_over_the_bags_model(stated_bag, tmp_path, capsys):
    """--set odometry.<gain> replaces the bag's drift model's value, its others kept, noted.

    Before, a non-empty odometry.model (the bag's) replaced every odometry.* value, so the
    --set gain had no effect, silently, in evaluate and in the replay.
    """
    from dataclasses import asdict, replace
    from landmark_nav.slam.frontend import odometry_noise_model
    runs = {'bag': (), 'gain': ('--set', GAIN),
            'same': ('--set', 'odometry.sigma_xy_per_sqrt_m=0.05')}  # the model's own value
    figures = {name: _evaluate(stated_bag, tmp_path / name, *args)
               for name, args in runs.items()}
    text = capsys.readouterr().out
    note = ('odometry.sigma_xy_per_sqrt_m 0.01 (--set) instead of 0.05 of the odometry model '
            f"'{DRIFT}' (the bag's), its other gains kept")
    assert note in text and note in figures['gain']['notes']
    want = replace(odometry_noise_model(DRIFT), sigma_xy_per_sqrt_m=0.01)
    got = {k: v for k, v in figures['gain']['odometry_noise'].items() if k != 'source'}
    assert got == asdict(want)
    tum = {name: (tmp_path / name / 'trajectory_slam.tum').read_text() for name in runs}
    assert tum['gain'] != tum['bag'] == tum['same'] != ''
    # The gains are the --set one's and the model's, not the pioneer default.
    assert figures['same']['odometry_noise']['source'] == 'odometry.*'
    assert not any('no odometry noise model' in n for n in figures['same']['notes'])
    assert bag_configuration(stated_bag, settings={'odometry.sigma_xy_per_sqrt_m': 0.01}
                             ).params.odometry == want
    # The replay: ekf_slam gets the model's gains after its files, the --set gain last.
    cmd = pipeline_commands('replay', [f'ekf_slam.{GAIN}'], bag=str(stated_bag))['ekf_slam']
    stated = run_parameters(stated_bag, settings={'odometry.sigma_xy_per_sqrt_m': 0.01})
    assert stated['ekf_slam']['odometry.model'] == ''
    assert 'odometry.sigma_xy_per_sqrt_m' not in stated['ekf_slam']
    assert [a for a in cmd if a.startswith('odometry.')] == [
        "odometry.model:=''"] + [
            f'odometry.{k}:={v!r}' for k, v in asdict(want).items()
            if k != 'sigma_xy_per_sqrt_m'] + ['odometry.sigma_xy_per_sqrt_m:=0.01']
    assert note in capsys.readouterr().err


def test_the_launch_file_gives_every_node_what_the_replay_gives(stated_bag, monkeypatch):
    """launch/replay.launch.py passes each node the bag's values as pipeline replay does.

    ``launch`` is not installable here: its few names are stubbed, the file's own code runs.
    """
    import runpy
    import types
    from landmark_nav.tools.config_files import config_path
    from landmark_nav.tools.node_parameters import as_ros_arguments

    class Action:
        def __init__(self, *args, **kwargs):
            self.args, self.kwargs = args, kwargs

    class LaunchConfiguration(Action):
        def perform(self, context):
            return context[self.args[0]]

    repo = Path(__file__).resolve().parents[1]
    stubs = {'launch': {'LaunchDescription': list},
             'launch.actions': {'DeclareLaunchArgument': Action, 'OpaqueFunction': Action},
             'launch.substitutions': {'LaunchConfiguration': LaunchConfiguration},
             'launch_ros.actions': {'Node': Action},
             'ament_index_python.packages': {'get_package_share_directory': lambda _: repo}}
    for name, names in stubs.items():
        monkeypatch.setitem(sys.modules, name, types.SimpleNamespace(**names))
    launch = runpy.run_path(str(repo / 'launch' / 'replay.launch.py'))
    nodes = {node.kwargs['name']: node.kwargs
             for action in launch['generate_launch_description']()
             if 'function' in action.kwargs
             for node in action.kwargs['function']({'bag': str(stated_bag)})}
    assert list(nodes) == ['bag_player', 'corner_extractor', 'ekf_slam']
    replay = pipeline_commands('replay', bag=str(stated_bag))
    for name in ('corner_extractor', 'ekf_slam'):
        file, values = nodes[name]['parameters']
        assert Path(file) == config_path(name)
        assert values == run_parameters(stated_bag)[name]
        cmd = replay[name]
        assert as_ros_arguments(values) == cmd[cmd.index('--params-file') + 2:]
    assert nodes['ekf_slam']['parameters'][1]['laser_pose'] == [0.0] * 3
    assert nodes['ekf_slam']['parameters'][1]['odometry.model'] == DRIFT
    assert nodes['corner_extractor']['parameters'][1]['sigma_r'] == STATED


@pytest.mark.dds
@pytest.mark.parametrize('settings', [(), (f'laser_pose={MOUNT}',), (GAIN,)],
                         ids=['bag', 'set-mount', 'set-gain'])
def test_the_replay_of_a_bag_stating_its_noise_is_evaluates_run(
        stated_bag, processes, tmp_path, settings):
    """The replayed poses are the offline run's on a bag that does not state 1 cm.

    With the shipped 1 cm in corner_extractor (before), the replay's corners carried other
    covariances than evaluate's, so the poses differed; with a --set laser mount, evaluate
    kept the bag's (before) and the replay took the --set one.
    """
    from landmark_nav.conversions import stamp_to_ns
    from landmark_nav.tools.config_files import config_path
    from landmark_nav.tools.node_parameters import given_parameters
    profile = given_parameters([str(config_path('ekf_slam_chapter'))], [], 'ekf_slam')
    evaluate_bag(stated_bag, 'icnn', tmp_path, progress=False, plots=False,
                 config=bag_configuration(stated_bag, profile,
                                          given_parameters([], settings, 'ekf_slam')))
    ref = read_tum(tmp_path / 'trajectory_slam.tum')
    with RosHarness() as ros:
        poses = ros.collect('/pose', PoseWithCovarianceStamped)
        proc = processes.start(
            [sys.executable, '-m', 'landmark_nav.tools.cli', 'pipeline', 'replay', '--bag',
             str(stated_bag), '--rate', '2', '--profile', 'ekf_slam_chapter',
             '--drain-timeout', '5'] + [  # its last scan comes after the last odometry
                 a for t in settings for a in ('--set', f'ekf_slam.{t}')],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        out, _ = proc.communicate(timeout=300)
        time.sleep(0.5)
        got = list(poses)
    assert proc.returncode == 0 and 'Traceback' not in out, out
    stamps = np.array([stamp_to_ns(p.header.stamp) for p in got])
    first = int(np.searchsorted(ref.stamps_ns, stamps[0]))
    assert len(got) > len(ref.stamps_ns) // 2
    assert np.array_equal(stamps, ref.stamps_ns[first:])
    xy = np.array([[p.pose.pose.position.x, p.pose.pose.position.y] for p in got])
    err = np.hypot(*(xy - ref.positions[first:, :2]).T)
    assert err.max() < 1e-9, err.max()  # the file's rounding: 5e-10 m per coordinate
