"""``landmark_nav pipeline``: one command starts the nodes, prefixes output, Ctrl-C stops."""

import importlib.util
from pathlib import Path
import signal
import subprocess
import sys
import time

from geometry_msgs.msg import PoseWithCovarianceStamped
from landmark_nav.testing import RosHarness
from landmark_nav.tools.pipeline import pipeline_commands, PIPELINES
import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize('name', sorted(PIPELINES))
def test_every_pipeline_names_existing_nodes_and_parameter_files(name):
    commands = pipeline_commands(name, bag='bags/office')
    assert list(commands) == list(PIPELINES[name])
    for node, cmd in commands.items():
        assert importlib.util.find_spec(cmd[2]) is not None, cmd
        if node != 'bag_player':
            params = Path(cmd[cmd.index('--params-file') + 1])
            assert params.is_file() and params.name == f'{node}.yaml'


def test_bad_settings_are_one_line_errors():
    with pytest.raises(ValueError, match='expected NODE.PARAMETER=VALUE'):
        pipeline_commands('slam', ['ekf_slam'])
    with pytest.raises(ValueError, match="no node 'sonar_localizer'"):
        pipeline_commands('slam', ['sonar_localizer.filter=ukf'])
    with pytest.raises(ValueError, match='needs --bag'):
        pipeline_commands('replay')
    assert pipeline_commands('slam', ['laser_driver.port=/dev/ttyUSB1'])['laser_driver'][-2:] \
        == ['-p', 'port:=/dev/ttyUSB1']
    # ekf_slam's names are checked before anything starts (the other nodes refuse theirs)
    with pytest.raises(ValueError, match=r"ekf_slam has no parameter 'max_sped' \(did you "
                                         r'mean max_speed\?\)'):
        pipeline_commands('slam', ['ekf_slam.max_sped=1.0'])


def test_a_profile_comes_after_its_nodes_file_and_before_the_settings():
    cmd = pipeline_commands('replay', ['ekf_slam.association=jcbb'], bag='bags/office',
                            profiles=['ekf_slam_chapter'])['ekf_slam']
    files = [Path(cmd[k + 1]).name for k, a in enumerate(cmd) if a == '--params-file']
    assert files == ['ekf_slam.yaml', 'ekf_slam_chapter.yaml']
    assert cmd.index('--params-file') < cmd.index('odometry.model:=simulator') \
        < cmd.index('association:=jcbb')
    with pytest.raises(ValueError, match="--profile 'line_extractor_detailed': not a profile"):
        pipeline_commands('slam', profiles=['line_extractor_detailed'])


@pytest.mark.dds
def test_replay_pipeline_runs_prefixes_output_and_stops_on_ctrl_c(processes):
    with RosHarness() as ros:
        poses = ros.collect('/pose', PoseWithCovarianceStamped)
        proc = processes.start(
            [sys.executable, '-m', 'landmark_nav.tools.cli', 'pipeline', 'replay', '--bag',
             str(REPO / 'bags' / 'office'), '--rate', '2', '--set',
             'ekf_slam.association=jcbb'], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True)
        try:
            assert ros.wait_until(lambda: len(poses) >= 20, 60), 'no SLAM poses'
        finally:
            time.sleep(1.0)
            proc.send_signal(signal.SIGINT)
            out, _ = proc.communicate(timeout=60)
    assert 'Traceback' not in out, out
    assert 'ekf_slam         | ' in out and 'association jcbb' in out, out
    for node in PIPELINES['replay']:
        assert f'{node} stopped (rc=0)' in out, out


def test_replay_gives_ekf_slam_what_the_bag_states():
    """The simulator bag's laser mount and odometry noise model, before the user's --set."""
    cmd = pipeline_commands('replay', ['ekf_slam.odometry.model=pioneer'],
                            bag=str(REPO / 'bags' / 'office'))['ekf_slam']
    stated = cmd[cmd.index('--params-file') + 2:]  # after the shipped file
    assert stated == ['-p', 'laser_pose:=[0.0,0.0,0.0]', '-p', 'laser_sigma_range:=0.01',
                      '-p', 'lines.sigma_r:=0.01', '-p', 'lines.sigma_phi:=0.0017453292519943296',
                      '-p', 'odometry.model:=simulator',
                      '-p', 'odometry.model:=pioneer']  # the last one wins
    assert pipeline_commands('replay', bag='no/such/bag')['ekf_slam'][-1].endswith('.yaml')


@pytest.mark.dds
def test_replay_ends_when_the_nodes_have_processed_every_scan(processes, office_evaluation):
    """A replay at 3x: one pose per scan, equal to the offline run of the same front end.

    The player's end stopped ekf_slam 1 s later: under load at 3x, 1,482 of 1,988 scans
    reached its output. Now the pipeline waits for the nodes to process what they received.
    The chapter profile on both sides: the offline reference is the suite's ICNN evaluation
    of the bag with config/ekf_slam_chapter.yaml (conftest), its trajectory_slam.tum (stamps
    to the nanosecond, positions to 1e-9 m).
    """
    from landmark_nav.conversions import stamp_to_ns
    from landmark_nav.evaluation.trajectory import read_tum
    import numpy as np
    bag = REPO / 'bags' / 'office'
    ref = read_tum(office_evaluation('icnn')[1] / 'trajectory_slam.tum')
    with RosHarness() as ros:
        poses = ros.collect('/pose', PoseWithCovarianceStamped)
        proc = processes.start(
            [sys.executable, '-m', 'landmark_nav.tools.cli', 'pipeline', 'replay', '--bag',
             str(bag), '--rate', '3', '--profile', 'ekf_slam_chapter'],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True)
        out, _ = proc.communicate(timeout=600)  # ends by itself: 40 s of bag, then the drain
        time.sleep(0.5)
        got = list(poses)
    assert proc.returncode == 0 and 'Traceback' not in out, out
    assert 'replay drained: the nodes handled all 1200 scans' in out, out
    # One pose per scan: ekf_slam made as many steps as the offline run ...
    assert len(ref.stamps_ns) == 1200
    assert 'ekf_slam processed 1200, dropped 0' in out, out
    # ... and the last line says so, with the offline run's ATE (the same poses)
    figures = office_evaluation('icnn')[0]
    last = out.splitlines()[-1]
    assert last.startswith(f'replay: {bag}, 1200 scans played in ') and (
        'ekf_slam published 1200 poses; ATE RMSE '
        f'{100 * figures["ate_rmse"]:.2f} cm (max {100 * figures["ate_max"]:.2f} cm) '
        'against /ground_truth/odom; outputs on /pose') in last, out
    # ... the same ones: the poses this test received (its subscription may match the node
    # after the first steps) are the offline run's at their stamps, to the file's rounding
    # (5e-10 m per coordinate).
    stamps = np.array([stamp_to_ns(p.header.stamp) for p in got])
    first = int(np.searchsorted(ref.stamps_ns, stamps[0]))
    assert len(got) > 1000 and np.array_equal(stamps, ref.stamps_ns[first:])
    xy = np.array([[p.pose.pose.position.x, p.pose.pose.position.y] for p in got])
    err = np.hypot(*(xy - ref.positions[first:, :2]).T)
    assert err.max() < 1e-9, (err.max(), int(np.argmax(err > 0)), [
        line for line in out.splitlines() if 'WARN' in line])


def test_the_replay_result_scores_the_poses_as_evaluate_does(office_evaluation):
    """The ATE of the result line is evaluate's ``ATE RMSE`` (its trajectory_slam.tum)."""
    from landmark_nav.evaluation.trajectory import read_tum
    from landmark_nav.tools.replay_result import reference_ate, result_line
    figures, folder = office_evaluation('icnn')
    traj = read_tum(folder / 'trajectory_slam.tum')
    bag = str(REPO / 'bags' / 'office')
    ate = reference_ate(bag, traj.stamps_ns, traj.planar())
    assert ate['poses'] == 1200
    assert abs(ate['rmse'] - figures['ate_rmse']) < 1e-9  # the file's rounding: 5e-10 m
    assert abs(ate['max'] - figures['ate_max']) < 1e-9
    line = result_line('bags/office', 3.0, 1200, 40.04, traj.stamps_ns, traj.planar(), ate)
    assert line.startswith('replay: bags/office, 1200 scans played in 40.0 s at rate 3; '
                           'ekf_slam published 1200 poses; ATE RMSE ')
    assert '\n' not in line
    assert line.endswith('outputs on /pose, /odometry, /path, /landmarks (not recorded)')


def test_the_replay_result_without_a_reference_or_an_end():
    from landmark_nav.tools.replay_result import reference_ate, result_line
    import numpy as np
    stamps, poses = np.array([1, 2], dtype=np.int64), np.zeros((2, 3))
    assert reference_ate(str(REPO / 'bags' / 'corridor'), stamps, poses) is None  # no pose
    assert result_line('b', 1.0, None, None, stamps, poses, None) == (
        'replay: b, its scans stopped before its end; ekf_slam published 2 poses; outputs on '
        '/pose, /odometry, /path, /landmarks (not recorded)')
    assert result_line('b', 2.0, 5, 1.25, stamps, poses, None) == (
        'replay: b, 5 scans played in 1.2 s at rate 2; ekf_slam published 2 poses; not scored '
        '(no /ground_truth/odom in the bag over their stamps); outputs on /pose, /odometry, '
        '/path, /landmarks (not recorded)')


@pytest.mark.parametrize('bag, message', [
    ('no/such/bag', 'No bag at no/such/bag'),
    (str(REPO / 'bags' / 'corridor'), f'{REPO / "bags" / "corridor"} has no /scan topic '
     '(pipeline replay plays /scan and /odom)'),
])
def test_a_replay_of_a_bag_it_cannot_play_starts_nothing(bag, message):
    """One line and exit status 2, before any node starts (they used to start, then stop)."""
    proc = subprocess.run([sys.executable, '-m', 'landmark_nav.tools.cli', 'pipeline',
                           'replay', '--bag', bag], capture_output=True, text=True,
                          timeout=120)
    assert (proc.returncode, proc.stdout, proc.stderr) == (
        2, '', f'landmark_nav: error: {message}\n')


@pytest.mark.dds
def test_the_replay_result_names_other_publishers_of_pose():
    """The recorder takes /pose from anyone on the domain: the line names the others."""
    import rclpy
    from landmark_nav.tools.replay_result import PoseRecorder, result_line
    import numpy as np
    context = rclpy.Context()
    rclpy.init(context=context)
    nodes = [rclpy.create_node(name, context=context) for name in ('ekf_slam', 'intruder')]
    recorder = PoseRecorder()
    try:
        alone = recorder.connected()  # the replay's player waits until it is matched
        pubs = [n.create_publisher(PoseWithCovarianceStamped, '/pose', 10) for n in nodes]
        deadline = time.monotonic() + 20.0
        while ({n for n, _ in recorder.publishers} != {'/ekf_slam', '/intruder'}
               or not recorder.connected()) and time.monotonic() < deadline:
            time.sleep(0.1)
        matched = recorder.connected()
    finally:
        stamps, poses = recorder.stop()
        del pubs
        for n in nodes:
            n.destroy_node()
        rclpy.try_shutdown(context=context)
    assert not alone and matched
    assert recorder.other_publishers() == ['/intruder']
    line = result_line('b', 1.0, 2, 1.0, np.array([1, 2]), np.zeros((2, 3)), None,
                       recorder.other_publishers())
    assert 'ekf_slam published 2 poses (/pose also published by /intruder: their poses are ' \
        'counted too)' in line
    assert '/pose also' not in result_line('b', 1.0, 2, 1.0, stamps, poses, None, [])
