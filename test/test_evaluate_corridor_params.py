"""``evaluate-corridor --params-file / --set``: corridor_follower's configuration offline."""

import json
from pathlib import Path

from landmark_nav.corridor.configuration import follower_configuration, parameters
from landmark_nav.testing import declared_parameters, RosHarness
from landmark_nav.tools.cli import main
from landmark_nav.tools.config_files import config_path
import pytest
from rclpy.parameter import Parameter

REPO = Path(__file__).resolve().parents[1]
CORRIDOR = REPO / 'bags' / 'corridor'


def figures(tmp_path, *options):
    """Run the command on the corridor bag; return what it scores, without the bag path."""
    out = tmp_path / f'run{len(list(tmp_path.iterdir()))}'
    assert main(['evaluate-corridor', str(CORRIDOR), '--out', str(out), *options]) == 0
    result = json.loads((out / 'corridor.json').read_text())
    result.pop('bag')
    return result


def test_the_node_and_the_offline_configuration_agree():
    from landmark_nav.corridor.follower import CorridorTracker
    from landmark_nav.nodes.corridor_follower import CorridorFollower
    given = {'sigma_px': 1.5, 'line_method': 'lsd', 'camera_mount': [0.1, 0.0, 0.9, 0.0,
                                                                     0.05, 0.0],
             'speed': 0.5, 'gate_chi2': 9.2, 'sigma_angle_deg': 0.5}
    with RosHarness() as ros:
        node = CorridorFollower(context=ros.context,
                                parameter_overrides=[Parameter(k, value=v)
                                                     for k, v in given.items()])
        declared = declared_parameters(node)
        follower, controller = node.tracker.config, node.controller.params
        node.destroy_node()
    offline = follower_configuration(given)
    assert (offline.follower, offline.controller) == (follower, controller)
    # the segment direction noise reaches the vanishing-point estimator's parameters
    assert CorridorTracker(follower).params.vp.sigma_angle_deg == 0.5
    assert {k: declared[k] for k in parameters()} == offline.values


def test_shipped_file_no_change_and_a_set_is_a_file(tmp_path):
    default = figures(tmp_path)
    assert figures(tmp_path, '--params-file', str(config_path('corridor_follower'))) == default
    via_set = figures(tmp_path, '--set', 'sigma_px=2.0')
    assert via_set['errors'] != default['errors']
    path = tmp_path / 'noise.yaml'
    path.write_text('corridor_follower:\n  ros__parameters:\n    sigma_px: 2.0\n')
    assert figures(tmp_path, '--params-file', str(path)) == via_set


@pytest.mark.parametrize('option, needle', [
    ('corridor_follower.sigma_pix=2.0',
     "corridor_follower has no parameter 'sigma_pix' (did you mean sigma_px?)"),
    ('line_method=canny', "parameter line_method = 'canny' is not one of"),
])
def test_a_bad_setting_exits_2_naming_it(tmp_path, capsys, option, needle):
    assert main(['evaluate-corridor', str(CORRIDOR), '--out', str(tmp_path),
                 '--set', option]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and needle in err, err
