"""The laser noise of a run: ``--set`` > what the bag states > the defaults, offline and replay.

``landmark_nav evaluate`` and ``landmark_nav pipeline replay`` take it from one function
(:func:`landmark_nav.evaluation.slam.run_parameters`). The bag is the office recording's
first 6 s re-encoded with the imported-bag contract's ``custom_data`` stating a range noise
of 2 cm (the shipped parameters say 1 cm).
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
from landmark_nav.tools.demo import chapter_config
from landmark_nav.tools.pipeline import pipeline_commands
import numpy as np
import pytest
from test_evaluate_slam import BAG, reencode

STATED = 0.02  # the bag's range noise [m]


@pytest.fixture(scope='module')
def stated_bag(tmp_path_factory) -> Path:
    """Return the office bag's first 6 s stating a 2 cm range noise (read only)."""
    bag = tmp_path_factory.mktemp('stated') / 'bag'
    with BagReader(BAG) as reader:  # the odometry kept where it starts (at the reference)
        start = next(odometry_to_pose(m).pose for _, _, m in reader.decoded(['/odom']))
    reencode(BAG, bag, reference_topic=True, seconds=6, odom_start=start,
             custom={'landmark_nav.laser_mount': '0 0 0',
                     'landmark_nav.laser_sigma_range': str(STATED)})
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


@pytest.mark.dds
def test_the_replay_of_a_bag_stating_its_noise_is_evaluates_run(
        stated_bag, processes, tmp_path):
    """The replayed poses are the offline run's on a bag that does not state 1 cm.

    With the shipped 1 cm in corner_extractor (before), the replay's corners carried other
    covariances than evaluate's, so the poses differed.
    """
    from landmark_nav.conversions import stamp_to_ns
    evaluate_bag(stated_bag, 'icnn', tmp_path, progress=False, plots=False,
                 config=chapter_config(stated_bag))
    ref = read_tum(tmp_path / 'trajectory_slam.tum')
    with RosHarness() as ros:
        poses = ros.collect('/pose', PoseWithCovarianceStamped)
        proc = processes.start(
            [sys.executable, '-m', 'landmark_nav.tools.cli', 'pipeline', 'replay', '--bag',
             str(stated_bag), '--rate', '2', '--profile', 'ekf_slam_chapter',
             '--drain-timeout', '5'],  # its last scan comes after the last odometry
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
