"""``landmark_nav evaluate --backend graph``: the graph back end on the office bag."""

import json
from pathlib import Path

from landmark_nav.tools.cli import main as cli_main

BAG = Path(__file__).resolve().parents[1] / 'bags' / 'office'


def test_cli_graph_backend_prints_and_writes_its_figures(tmp_path, capsys):
    out = tmp_path / 'g'
    assert cli_main(['evaluate', str(BAG), '--backend', 'graph', '--max-seconds', '15',
                     '--out', str(out)]) == 0
    text = capsys.readouterr().out
    r = json.loads((out / 'slam_graph.json').read_text())
    assert 'graph back end' in text and 'final: ATE se2 aligned RMSE' in text
    for name in ('trajectory_graph_online.tum', 'trajectory_graph_final.tum',
                 'trajectory_gt.tum'):
        assert (out / name).is_file()
    # Every keyframe after the first has one factor, scan-matched on this bag (the
    # simulator's scans agree with its odometry).
    assert r['motions']['scan_matching'] == r['keyframes'] - 1 > 5
    # 15 s, no loop yet: the scan-matched keyframes beat the odometry (0.49 vs 1.10 cm).
    assert r['loops_accepted'] == 0
    assert r['final_ate_se2_rmse'] < 0.6 * r['odom_ate_se2_rmse']
    assert r['final_ellipse95_share'] >= 0.95


def test_cli_graph_backend_refuses_what_it_would_ignore(tmp_path, capsys):
    """--set and the ekf filter's options with --backend graph: one line naming them, exit 2.

    The graph back end does not read ekf_slam's parameters (before, it ran without them).
    """
    options = ('--association', 'jcbb', '--scan-matching', '--scan-matching-fit-pairs', '0',
               '--map-pose-sigma', '0.1', '0.1', '0')
    runs = {('--set', 'laser_sigma_range=0.04'): '--set laser_sigma_range=0.04',
            options: ('--association jcbb, --map-pose-sigma 0.1 0.1 0.0, --scan-matching, '
                      '--scan-matching-fit-pairs 0.0')}
    for args, named in runs.items():
        out = tmp_path / args[0].strip('-')
        assert cli_main(['evaluate', str(BAG), '--backend', 'graph', '--max-seconds', '1',
                         '--out', str(out)] + list(args)) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f'--backend graph does not take {named} (' in err[0], err
        assert not out.exists()
