"""``evaluate-features --params-file / --set``: the feature nodes' configuration offline."""

import json
from pathlib import Path

from landmark_nav.laser.extractor_configuration import extractor_configuration, parameters
from landmark_nav.testing import declared_parameters, RosHarness
from landmark_nav.tools.cli import main
from landmark_nav.tools.config_files import config_path
import pytest
from rclpy.parameter import Parameter
from test_evaluate_features import write_room_bag

REPO = Path(__file__).resolve().parents[1]
OFFICE = REPO / 'bags' / 'office'
SHIPPED = ['--params-file', str(config_path('corner_extractor')),
           '--params-file', str(config_path('line_extractor'))]


def figures(bag, tmp_path, *options, every='40'):
    """Run the command; return its figures without the times (they vary run to run)."""
    out = tmp_path / f'figures{len(list(tmp_path.iterdir()))}.json'
    assert main(['evaluate-features', str(bag), '--every', every, '--json', str(out),
                 *options]) == 0
    result = json.loads(out.read_text())
    return {kind: {m: {k: v for k, v in f.items() if 'ms_per_scan' not in k}
                   for m, f in result[kind].items()} for kind in ('corners', 'lines')}


@pytest.fixture(scope='module')
def room(tmp_path_factory):
    """Write a truth-free bag (noise-free scans of a room, laser noise stated 2 cm)."""
    path = tmp_path_factory.mktemp('room') / 'b'
    write_room_bag(path)
    return path


@pytest.mark.parametrize('node', ['corner_extractor', 'line_extractor'])
def test_the_node_and_the_offline_configuration_agree(node):
    from landmark_nav.nodes.corner_extractor import CornerExtractor
    from landmark_nav.nodes.line_extractor import LineExtractor
    given = {'sigma_r': 0.03, 'segmentation.min_points': 7, 'method': 'split_merge',
             'see_through': 0.2}
    with RosHarness() as ros:
        cls = CornerExtractor if node == 'corner_extractor' else LineExtractor
        built = cls(context=ros.context,
                    parameter_overrides=[Parameter(k, value=v) for k, v in given.items()])
        declared = declared_parameters(built)
        params = built.params
        built.destroy_node()
    offline = extractor_configuration(node, given)
    assert offline.params == params
    assert offline.min_points == built.min_cluster_points == 7
    assert {k: declared[k] for k in parameters(node)} == offline.values
    assert set(declared) - set(parameters(node)) <= {'use_sim_time',
                                                     'start_type_description_service'}


@pytest.mark.parametrize('truth_free', [False, True])
def test_the_shipped_files_change_nothing(tmp_path, room, truth_free):
    bag = room if truth_free else OFFICE
    assert figures(bag, tmp_path, *SHIPPED) == figures(bag, tmp_path)


@pytest.mark.parametrize('truth_free', [False, True])
def test_a_set_sigma_r_is_the_shorthand(tmp_path, room, truth_free):
    bag = room if truth_free else OFFICE
    shorthand = figures(bag, tmp_path, '--sigma-r', '0.2')
    assert shorthand != figures(bag, tmp_path)  # the noise changes the figures
    assert figures(bag, tmp_path, '--set', 'sigma_r=0.2') == shorthand
    assert figures(bag, tmp_path, *SHIPPED, '--set', 'corner_extractor.sigma_r=0.2',
                   '--set', 'line_extractor.sigma_r=0.2') == shorthand
    # the shorthand comes after --set
    assert figures(bag, tmp_path, '--set', 'sigma_r=0.02', '--sigma-r', '0.2') == shorthand


def test_each_node_takes_its_own_settings(tmp_path):
    default = figures(OFFICE, tmp_path)
    lines_only = figures(OFFICE, tmp_path, '--set', 'line_extractor.segmentation.min_points=40')
    assert lines_only['corners'] == default['corners']
    assert lines_only['lines'] != default['lines']
    corners_only = figures(OFFICE, tmp_path, '--set', 'corner_extractor.min_arm_length=0.6')
    assert corners_only['lines'] == default['lines']
    assert corners_only['corners'] != default['corners']


def test_a_params_file_section_reaches_its_node(tmp_path):
    path = tmp_path / 'lines.yaml'
    path.write_text('line_extractor:\n  ros__parameters:\n    min_length: 1.5\n')
    via_file = figures(OFFICE, tmp_path, '--params-file', str(path))
    assert via_file == figures(OFFICE, tmp_path, '--set', 'line_extractor.min_length=1.5')
    assert via_file['lines'] != figures(OFFICE, tmp_path)['lines']


@pytest.mark.parametrize('option, needles', [
    ('corner_extractor.windw=7', ["corner_extractor has no parameter 'windw'",
                                  'did you mean window?']),
    ('windw=7', ["corner_extractor or line_extractor has no parameter 'windw'",
                 'did you mean window?']),
    ('line_extractor.window=7', ["line_extractor has no parameter 'window'"]),
    ('window=7.5', ['parameter window: expected an integer, got 7.5']),
])
def test_a_bad_setting_exits_2_naming_it(room, capsys, option, needles):
    assert main(['evaluate-features', str(room), '--set', option]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1
    for needle in needles:
        assert needle in err


def test_an_unknown_name_in_a_file_exits_2(room, tmp_path, capsys):
    path = tmp_path / 'typo.yaml'
    path.write_text('corner_extractor:\n  ros__parameters:\n    midpoint_shfit: 2\n')
    assert main(['evaluate-features', str(room), '--params-file', str(path)]) == 2
    assert ("corner_extractor has no parameter 'midpoint_shfit' (did you mean "
            'midpoint_shift?)') in capsys.readouterr().err


def test_a_value_the_extractor_refuses_names_the_parameter():
    with pytest.raises(ValueError) as err:
        extractor_configuration('corner_extractor', {'window': 12})
    assert str(err.value) == ('corner_extractor: parameter window must be an odd integer '
                              '>= 5, got 12')
