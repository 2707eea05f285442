"""The extractor nodes on an imported real log replayed through DDS give the offline figures.

An imported Carmen bag (belgioioso, the first 45 scans) is played by ``bag_player`` at
3x real time into ``corner_extractor`` and ``line_extractor``; every scan must come out,
and the truth-free figures computed from what the nodes published (PLE f and ray RMSE,
false-surface beams, line and corner repeatability through the reference poses) must
equal those of ``landmark_nav evaluate-features`` on the same bag (every scan sampled).
"""

import os
from pathlib import Path
import subprocess
import sys

from geometry_msgs.msg import PoseArray
from landmark_nav.evaluation.feature_bags import (bag_metric_scans, evaluate_truth_free,
                                                  sensor_facts)
from landmark_nav.evaluation.scan_metrics import (corner_repeatability, line_repeatability,
                                                  ray_metrics, Repeatability)
from landmark_nav.feature_msgs import feature_cloud_to_arrays
from landmark_nav.importers.writer import import_log
from landmark_nav.nodes.corner_extractor import CornerExtractor
from landmark_nav.nodes.line_extractor import LineExtractor
from landmark_nav.testing import RosHarness, shared_data
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2

REPO = Path(__file__).resolve().parents[1]
SCANS = 45  # belgioioso scans at 1 Hz: 15 s of replay at rate 3


@pytest.fixture(scope='module')
def replayed(tmp_path_factory):
    """Import the log, replay it through the nodes; return the bag and their outputs."""
    bag = tmp_path_factory.mktemp('real') / 'belgioioso'
    import_log(shared_data('carmen', 'belgioioso-corrected.log.gz'), bag, max_scans=SCANS)
    with RosHarness() as ros:
        ros.add_node(CornerExtractor(context=ros.context))
        ros.add_node(LineExtractor(context=ros.context))
        corners = ros.collect('corners', PoseArray)
        features = ros.collect('corners/features', PointCloud2)
        lines = ros.collect('lines', PointCloud2)
        player = subprocess.run(
            [sys.executable, '-m', 'landmark_nav.nodes.bag_player', str(bag), '--topics',
             '/scan', '--rate', '3', '--wait-for-subscribers', '30'],
            env=os.environ, cwd=REPO, capture_output=True, text=True, timeout=120)
        assert player.returncode == 0, player.stderr
        ros.wait_until(lambda: min(len(corners), len(features), len(lines)) >= SCANS, 10.0)
        return bag, list(corners), list(lines), list(features)


@pytest.mark.dds
def test_no_scan_is_lost_at_three_times_real_time(replayed):
    bag, corners, lines, features = replayed
    assert (len(corners), len(lines), len(features)) == (SCANS, SCANS, SCANS)


@pytest.mark.dds
def test_node_figures_equal_the_offline_figures(replayed):
    bag, corner_msgs, line_msgs, feature_msgs = replayed
    # the nodes run at their default sigma_r (0.01 m, not estimated from the data)
    offline, _ = evaluate_truth_free(bag, scans=SCANS, extractor_sigma_r=None)
    mount, sigma_r, _ = sensor_facts(bag)
    scans, _ = bag_metric_scans(bag, mount)
    assert offline['ple_scans'] == SCANS and offline['repeat_pairs'] == SCANS - 1
    f, rmse, false_beams = [], [], 0
    line_rep, corner_rep = Repeatability(), Repeatability()
    prev = None
    for scan, pose_msg, cloud, feats in zip(scans, corner_msgs, line_msgs, feature_msgs):
        fields = feature_cloud_to_arrays(cloud)
        segs = np.stack([np.column_stack([fields['x1'], fields['y1']]),
                         np.column_stack([fields['x2'], fields['y2']])], axis=1)
        pts = np.array([[p.position.x, p.position.y] for p in pose_msg.poses]).reshape(-1, 2)
        cf = feature_cloud_to_arrays(feats)  # the arms' directions: bisector +- opening / 2
        np.testing.assert_array_equal(np.column_stack([cf['x'], cf['y']]).reshape(-1, 2), pts)
        wedges = np.column_stack([cf['bisector'], cf['opening']]).reshape(-1, 2)
        m = ray_metrics(scan.ranges, scan.angles, scan.valid, segs, sigma_r, scan.no_return)
        f.append(m.f)
        rmse.append(m.rmse)
        false_beams += int(m.false_surface.size)
        if prev is not None:
            line_repeatability(line_rep, prev[1], prev[0].pose, segs, scan)
            corner_repeatability(corner_rep, prev[2], prev[0].pose, pts, scan, wedges_k=prev[3])
        prev = (scan, segs, pts, wedges)
    lines, corners = offline['lines']['split_merge'], offline['corners']['minus_cosine']
    # The line cloud carries float32 end points (measured: f equal, RMSE 8e-9 relative).
    assert np.mean(f) == pytest.approx(lines['f'], abs=1e-9)
    assert np.nanmean(rmse) == pytest.approx(lines['ray_rmse_mean_m'], rel=1e-6)
    assert false_beams == lines['false_surface_beams'] == 0
    assert (line_rep.opportunities, line_rep.redetected) == (
        lines['line_opportunities'], lines['line_redetected'])
    assert line_rep.opportunities > 50
    assert (corner_rep.opportunities, corner_rep.redetected) == (
        corners['corner_opportunities'], corners['corner_redetected'])
    assert corner_rep.opportunities > 10
