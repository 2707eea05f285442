"""``evaluate-road-* --params-file / --set``: road_classifier's configuration offline."""

import json
from pathlib import Path
import sys

from landmark_nav.road.configuration import parameters, road_configuration
from landmark_nav.testing import declared_parameters, RosHarness
from landmark_nav.tools.cli import main
from landmark_nav.tools.config_files import config_path
import pytest
from rclpy.parameter import Parameter

sys.path.insert(0, str(Path(__file__).resolve().parent))

import tiny_logs  # noqa: E402


@pytest.fixture(scope='module')
def camvid(tmp_path_factory):
    """Two tiny CamVid-format frames."""
    return str(tiny_logs.write_camvid(tmp_path_factory.mktemp('camvid')))


def command(name: str, camvid: str) -> list:
    """Return the command line of a cheap run of ``evaluate-road-<name>``."""
    return {'outline': ['evaluate-road-outline', camvid],
            'laser': ['evaluate-road-laser', '--kinds', 'gravel', '--scans', '20'],
            'vision': ['evaluate-road-vision', '--kinds', 'asphalt', '--lighting',
                       'overcast', '--frames', '2']}[name]


def figures(capsys, tmp_path, argv: list):
    """Run a command; return what it scores (the outline: per-frame scores, no times)."""
    if argv[0] != 'evaluate-road-outline':
        assert main(argv) == 0
        return capsys.readouterr().out
    path = tmp_path / 'scores.json'
    assert main(argv + ['--json', str(path)]) == 0
    return [{k: v for k, v in frame.items() if k != 'seconds'}
            for frame in json.loads(path.read_text())['frames']]


def test_the_node_and_the_offline_configuration_agree():
    from landmark_nav.nodes.road_classifier import RoadClassifier
    given = {'laser_mount': [0.2, 0.0, 0.7, 0.0, 0.3, 0.0], 'roughness_max': 0.02,
             'history': 4, 'k_limit': 1.1, 'seed_thickness_px': 5, 'robot_width': 0.8,
             'camera_mount': [0.1, 0.0, 1.2, 0.0, 0.25, 0.0], 'outline_method': 'chapter',
             'min_outline_confidence': 0.3}
    with RosHarness() as ros:
        node = RoadClassifier(context=ros.context,
                              parameter_overrides=[Parameter(k, value=v)
                                                   for k, v in given.items()])
        declared = declared_parameters(node)
        ran = (node.laser, node.terrain, node.fusion, node.outline_params,
               tuple(node.camera_mount), node.seed_px)
        node.destroy_node()
    offline = road_configuration(given)
    assert ran == (offline.laser, offline.terrain, offline.fusion, offline.outline,
                   offline.camera_mount, offline.seed_px)
    assert {k: declared[k] for k in parameters()} == offline.values


@pytest.mark.parametrize('name, setting', [
    ('outline', 'outline_method: chapter'), ('laser', 'roughness_max: 0.004'),
    ('vision', 'k_limit: 0.9')])
def test_a_params_file_changes_the_result_as_a_set_does(
        tmp_path, capsys, camvid, name, setting):
    argv = command(name, camvid)
    default = figures(capsys, tmp_path, argv)
    shipped = str(config_path('road_classifier'))
    assert figures(capsys, tmp_path, argv + ['--params-file', shipped]) == default
    path = tmp_path / 'road.yaml'
    path.write_text(f'road_classifier:\n  ros__parameters:\n    {setting}\n')
    changed = figures(capsys, tmp_path, argv + ['--params-file', str(path)])
    assert changed != default
    assert figures(capsys, tmp_path, argv + ['--set', setting.replace(': ', '=')]) == changed


@pytest.mark.parametrize('name', ['outline', 'laser', 'vision'])
def test_an_unknown_name_exits_2_naming_the_nearest(tmp_path, capsys, camvid, name):
    path = tmp_path / 'typo.yaml'
    path.write_text('road_classifier:\n  ros__parameters:\n    k_limt: 1.0\n')
    assert main(command(name, camvid) + ['--params-file', str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and \
        "road_classifier has no parameter 'k_limt' (did you mean k_limit?)" in err, err
