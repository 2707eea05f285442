"""Bad input to the command line: one line on stderr, non-zero exit, never a traceback."""

from pathlib import Path
import subprocess
import sys

import pytest
from test_bag import write_small_bag


def run_cli(*args, cwd=None):
    return subprocess.run([sys.executable, '-m', 'landmark_nav.tools.cli', *map(str, args)],
                          capture_output=True, text=True, timeout=120, cwd=cwd)


def assert_one_line_error(result, *needles):
    assert result.returncode != 0
    assert 'Traceback' not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert 'error' in lines[0]
    for needle in needles:
        assert needle in lines[0], lines[0]


def test_missing_bag(tmp_path):
    for command in ('info', 'replay'):
        assert_one_line_error(run_cli(command, tmp_path / 'nope'), 'nope')
    assert_one_line_error(run_cli('demo', '--bag', tmp_path / 'nope', '--out', tmp_path / 'o'))


def test_evaluate_corridor_bad_bag(tmp_path):
    assert_one_line_error(run_cli('evaluate-corridor', tmp_path / 'nope'), 'nope')
    bag = tmp_path / 'b'
    write_small_bag(bag)
    assert_one_line_error(run_cli('evaluate-corridor', bag, '--out', tmp_path / 'o'),
                          'ground_truth.yaml')


def test_corrupt_mcap(tmp_path):
    bag = tmp_path / 'b'
    write_small_bag(bag)
    mcap = bag / 'b.mcap'
    data = bytearray(mcap.read_bytes())
    for i in range(200, len(data) - 200, 37):  # scramble the body, keep the file size
        data[i] ^= 0x5A
    mcap.write_bytes(bytes(data))
    assert_one_line_error(run_cli('replay', bag, '--rate', '100'))
    assert_one_line_error(run_cli('info', bag))


def test_not_a_bag(tmp_path):
    (tmp_path / 'dir').mkdir()
    assert_one_line_error(run_cli('info', tmp_path / 'dir'), 'metadata.yaml')
    (tmp_path / 'x.mcap').write_bytes(b'not an mcap file at all')
    assert_one_line_error(run_cli('info', tmp_path / 'x.mcap'))


def test_unknown_scenario(tmp_path):
    assert_one_line_error(run_cli('simulate', 'moon', '--out', tmp_path / 'b'), 'moon',
                          'office', 'corridor', 'landmark_views')
    assert not (tmp_path / 'b').exists()


@pytest.mark.parametrize('seed', ['-1', 'abc', '1.5', str(2**32)])
def test_bad_seed(tmp_path, seed):
    assert_one_line_error(run_cli('simulate', 'office', '--seed', seed, '--out', tmp_path / 'b'),
                          'seed')


@pytest.mark.parametrize('args,words', [
    (['office', '--distance', '3'], ('--distance', 'corridor scenario only')),
    (['corridor', '--image-size', '100x100'], ('--image-size', '320x240')),
    (['corridor', '--distance', '40'], ('40', 'does not fit')),
    (['corridor', '--distance', '-1'], ('--distance', 'must be > 0')),
])
def test_bad_corridor_options(tmp_path, args, words):
    assert_one_line_error(run_cli('simulate', *args, '--out', tmp_path / 'b'), *words)
    assert not (tmp_path / 'b').exists()


@pytest.mark.parametrize('args,words', [
    (['--offset', '0.9'], ('0.9', 'into a wall')),
    (['--distance', '29'], ('29', 'does not fit')),
    (['--lengths', '0'], ('--lengths', 'must be >= 1')),
])
def test_bad_corridor_loop_options(args, words):
    assert_one_line_error(run_cli('corridor-loop', *args), *words)


def test_existing_output_is_not_overwritten(tmp_path):
    (tmp_path / 'b').mkdir()
    assert_one_line_error(run_cli('simulate', 'calibration', '--out', tmp_path / 'b'), 'exists')


def test_bad_replay_options(tmp_path):
    write_small_bag(tmp_path / 'b')
    assert_one_line_error(run_cli('replay', tmp_path / 'b', '--rate', '0'), 'rate')
    assert_one_line_error(run_cli('replay', tmp_path / 'b', '--topics', '/nope'), '/nope')


def test_usage_errors_are_one_line():
    assert_one_line_error(run_cli())
    assert_one_line_error(run_cli('frobnicate'))


def test_parameter_files_are_read_as_ros2_run_reads_them(tmp_path):
    """The node's sections (wildcard first), nested keys joined; a later file wins."""
    from landmark_nav.tools.node_parameters import given_parameters, read_params_file
    first = tmp_path / 'a.yaml'
    first.write_text('ekf_slam:\n  ros__parameters:\n    max_speed: 2.0\n'
                     '/**:\n  ros__parameters:\n    max_speed: 9.0\n    use_sim_time: true\n'
                     'corner_extractor:\n  ros__parameters:\n    sigma_r: 0.02\n'
                     '/robot/ekf_slam:\n  ros__parameters:\n    odometry:\n'
                     '      model: pioneer\n')
    assert read_params_file(str(first), 'ekf_slam') == {
        'max_speed': 2.0, 'use_sim_time': True, 'odometry.model': 'pioneer'}
    second = tmp_path / 'b.yaml'
    second.write_text('ekf_slam:\n  ros__parameters:\n    max_speed: 1.0\n')
    assert given_parameters([str(first), str(second)], ['ekf_slam.landmarks=corners',
                                                        "odometry.model='k_d=0.1'",
                                                        'laser_pose=[0.1, 0.0, 0.0]'],
                            'ekf_slam') == {
        'max_speed': 1.0, 'use_sim_time': True, 'odometry.model': 'k_d=0.1',
        'landmarks': 'corners', 'laser_pose': [0.1, 0.0, 0.0]}


@pytest.mark.parametrize('text, words', [
    ('ekf_slam: 3\n', ["section 'ekf_slam' has no ros__parameters"]),
    ('- a\n- b\n', ['expected node names at the top level']),
    ('ekf_slam: [\n', ['not YAML']),
])
def test_bad_parameter_files_are_one_line_errors(tmp_path, text, words, capsys):
    from landmark_nav.tools.cli import main
    path = tmp_path / 'p.yaml'
    path.write_text(text)
    bag = Path(__file__).resolve().parents[1] / 'bags' / 'office'
    assert main(['evaluate', str(bag), '--params-file', str(path)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('landmark_nav: error: --params-file ')
    for word in [str(path)] + words:
        assert word in lines[0], lines[0]


def test_help_texts_print_no_rest_markup():
    from landmark_nav.tools.cli import build_parser
    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices
    texts = {'landmark_nav': parser.format_help()}
    texts.update((name, sub.format_help()) for name, sub in commands.items())
    marked = [name for name, text in texts.items() if '``' in text]
    assert not marked, f'reST literals in the --help of {marked}'
    assert 'start a whole pipeline of nodes' in texts['pipeline']
    # what each pipeline starts, and what the demo does (it said 'the main job')
    assert ('slam = laser_driver + base_driver + corner_extractor + ekf_slam'
            in ' '.join(texts['pipeline'].split()))
    assert 'replay = bag_player + corner_extractor + ekf_slam' in ' '.join(
        texts['pipeline'].split())
    assert 'main job' not in texts['landmark_nav'] and 'EKF-SLAM (chapter profile) on a' in (
        ' '.join(texts['landmark_nav'].split()))


@pytest.mark.parametrize('command', ['evaluate', 'evaluate-features'])
def test_missing_reference_file_is_refused_before_the_run(command, tmp_path, capsys):
    from landmark_nav.tools.cli import build_parser
    missing = tmp_path / 'truth.tum'
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args([command, str(tmp_path), '--reference', str(missing)])
    assert stop.value.code == 2
    assert capsys.readouterr().err == (f'landmark_nav {command}: error: argument --reference: '
                                       f'no such file: {missing}\n')
