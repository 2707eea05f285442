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
