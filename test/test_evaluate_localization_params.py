"""``evaluate-localization --params-file / --set``: sonar_localizer's configuration offline."""

import json
import math
from pathlib import Path

from landmark_nav.localization.configuration import localizer_configuration, parameters
from landmark_nav.testing import declared_parameters, RosHarness
from landmark_nav.tools.cli import main
from landmark_nav.tools.config_files import config_path
import pytest
from rclpy.parameter import Parameter

REPO = Path(__file__).resolve().parents[1]
HALLWAY = REPO / 'bags' / 'hallway'


def figures(tmp_path, *options, filt='ekf'):
    """Run the command on the hallway bag; return the figures of ``filt`` (no file names)."""
    out = tmp_path / f'run{len(list(tmp_path.iterdir()))}'
    assert main(['evaluate-localization', str(HALLWAY), '--out', str(out), *options]) == 0
    result = json.loads((out / f'localization_{filt}.json').read_text())
    result.pop('files')
    return result


@pytest.fixture(scope='module')
def default(tmp_path_factory):
    """Return the figures of the EKF without options."""
    return figures(tmp_path_factory.mktemp('default'), '--filter', 'ekf')


def test_the_node_and_the_offline_configuration_agree():
    from landmark_nav.nodes.sonar_localizer import SonarLocalizer
    given = {'gate': 0.3, 'process_noise.k_d': 0.03, 'map_sigma': 0.0, 'filter': 'ukf',
             'wheel_joints': ['l', 'r']}
    with RosHarness() as ros:
        node = SonarLocalizer(context=ros.context,
                              parameter_overrides=[Parameter(k, value=v)
                                                   for k, v in given.items()])
        declared = declared_parameters(node)
        params = node.tracker.params
        node.destroy_node()
    offline = localizer_configuration(given)
    assert offline.params == params
    assert {k: declared[k] for k in parameters()} == offline.values
    assert set(declared) - set(parameters()) <= {'use_sim_time',
                                                 'start_type_description_service'}


def test_the_shipped_file_changes_nothing(tmp_path, default):
    shipped = figures(tmp_path, '--filter', 'ekf', '--params-file',
                      str(config_path('sonar_localizer')))
    assert shipped == default


def test_a_set_is_the_shorthand(tmp_path, default):
    shorthand = figures(tmp_path, '--filter', 'ekf', '--initial-std', '0.2', '0.2', '10')
    assert shorthand['errors'] != default['errors']
    via_set = figures(tmp_path, '--set', 'filter=ekf', '--set', 'initial_pose.std_x=0.2',
                      '--set', 'initial_pose.std_y=0.2',
                      '--set', f'initial_pose.std_yaw={math.radians(10.0)!r}')
    assert via_set == shorthand


def test_a_params_file_sets_the_filter(tmp_path, default):
    path = tmp_path / 'gate.yaml'
    path.write_text('sonar_localizer:\n  ros__parameters:\n    gate: 0.05\n')
    narrow = figures(tmp_path, '--filter', 'ekf', '--params-file', str(path))
    assert narrow['params']['gate'] == 0.05
    assert narrow['mean_accepted_readings'] < default['mean_accepted_readings']


@pytest.mark.parametrize('option, needle', [
    ('gatee=0.1', "sonar_localizer has no parameter 'gatee' (did you mean gate?)"),
    ('sonar_localizer.process_noise.kd=0.1',
     "sonar_localizer has no parameter 'process_noise.kd' (did you mean process_noise.k_d?)"),
    ('filter=pf', "parameter filter = 'pf' is not one of ekf, ukf"),
])
def test_a_bad_setting_exits_2_naming_it(tmp_path, capsys, option, needle):
    assert main(['evaluate-localization', str(HALLWAY), '--out', str(tmp_path),
                 '--set', option]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and needle in err, err
