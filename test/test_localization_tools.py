"""Sonar localization tools: offline evaluation, sonar map building, rasterising; bad input."""

import json
import math
from pathlib import Path
import shutil

from landmark_nav.bag import BagError
from landmark_nav.evaluation.localization import TARGETS
from landmark_nav.evaluation.localization_bags import evaluate_localization, format_evaluation
from landmark_nav.localization.grid import load_map_yaml, rasterize_world
from landmark_nav.sim.scenarios import build_scenario
from landmark_nav.tools.localization_tools import (build_sonar_map, format_map_summary,
                                                   rasterize_map)
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
HALLWAY = REPO / 'bags' / 'hallway'


@pytest.mark.parametrize('filt', ['ekf', 'ukf'])
def test_evaluate_localization_meets_the_targets_on_the_hallway(hallway_bag_localization, filt):
    result = hallway_bag_localization[0][filt]  # evaluate_localization(HALLWAY, filt, out_dir=)
    err = result['errors']['filter']
    max_pos, max_head = TARGETS[filt]
    assert err['max_position'] <= max_pos and err['max_heading'] <= max_head, err
    assert result['within_targets'] is True
    text = format_evaluation(result)
    assert f'{filt.upper()} ' in text and ': met;' in text and files_written(text) == 3
    assert result['errors_from_index'] == 11 and result['cycles'] == 607
    assert result['initial']['seed'] == 1001
    assert result['initial']['pose'] != result['initial']['true_pose']
    # Much better than odometry alone, even calibrated and started from the true pose.
    assert result['end_error_ratio']['odometry_calibrated'] >= 5.0
    assert result['errors']['odometry_uncalibrated']['end_position'] > 1.0
    files = result['files']
    assert json.loads(Path(files['json']).read_text()) == json.loads(json.dumps(result))
    for key in ('trajectory_png', 'heading_png'):
        data = Path(files[key]).read_bytes()
        assert data[:8] == b'\x89PNG\r\n\x1a\n' and len(data) > 20_000


def test_build_sonar_map_writes_a_loadable_map_to_localize_on(hallway_sonar_map_localization):
    # build_sonar_map(HALLWAY, out=folder / 'map.yaml') with its defaults ('/ground_truth/odom',
    # 0.1 m), then evaluate_localization(HALLWAY, 'ukf', map_path=) (shared with test_golden)
    runs, folder = hallway_sonar_map_localization
    out, summary = folder / 'map.yaml', runs['summary']
    assert summary['cycles'] == 607
    assert format_map_summary(summary).startswith(f'wrote {out} + map.pgm: ')
    assert Path(summary['image']).read_bytes()[:2] == b'P5'
    grid = load_map_yaml(out)
    assert grid.shape == (summary['height'], summary['width'])
    assert grid.resolution == pytest.approx(0.1)
    assert int(grid.occupied.sum()) == summary['occupied'] > 300
    assert summary['free'] > 1000 and summary['unknown'] > 0
    # Occupied cells lie on the hallway's walls (within two cells of the true map's).
    true_map = rasterize_world(build_scenario('hallway').world, 0.1)
    occ = grid.cell_centers(*np.nonzero(grid.occupied))
    walls = true_map.cell_centers(*np.nonzero(true_map.occupied))
    dist = np.min(np.hypot(occ[:, None, 0] - walls[None, :, 0],
                           occ[:, None, 1] - walls[None, :, 1]), axis=1)
    assert np.median(dist) <= 0.1 and np.mean(dist <= 0.2) > 0.9
    # Localizing on it (unknown cells free) keeps the UKF within 15 cm / 5 deg.
    result = runs['ukf']
    assert result['params']['unknown'] == 'free'
    err = result['errors']['filter']
    assert err['max_position'] <= 0.15 and err['max_heading'] <= math.radians(5.0), err


def test_rasterize_map_from_a_bag_or_a_scenario(tmp_path):
    a = rasterize_map(HALLWAY, tmp_path / 'a.yaml')
    b = rasterize_map('hallway', tmp_path / 'b.yaml', resolution=0.1)
    ga, gb = load_map_yaml(a['yaml']), load_map_yaml(b['yaml'])
    expected = rasterize_world(build_scenario('hallway').world, 0.1)
    assert np.array_equal(ga.occupancy, expected.occupancy)
    assert np.array_equal(gb.occupancy, expected.occupancy)
    assert ga.origin == pytest.approx(expected.origin) and a['unknown'] == 0
    coarse = rasterize_map('office', tmp_path / 'office.yaml', resolution=0.2)
    assert coarse['resolution'] == 0.2 and coarse['occupied'] > 100


def files_written(text):
    return sum(line.startswith('wrote ') for line in text.splitlines())


def _one_line(excinfo):
    text = str(excinfo.value)
    assert text and '\n' not in text
    return text


def test_bad_input_is_one_line_errors(tmp_path):
    with pytest.raises(BagError) as e:
        evaluate_localization(tmp_path / 'missing', 'ekf')
    assert 'missing' in _one_line(e)
    with pytest.raises(ValueError) as e:
        evaluate_localization(HALLWAY, 'pf')
    assert "unknown filter 'pf'" in _one_line(e)
    with pytest.raises(ValueError) as e:  # the calibration bag has no sonar
        evaluate_localization(REPO / 'bags' / 'calibration', 'ukf')
    assert 'no sonar topics' in _one_line(e)
    with pytest.raises(ValueError) as e:
        build_sonar_map(REPO / 'bags' / 'calibration', out=tmp_path / 'm.yaml')
    assert 'no sonar topics' in _one_line(e)
    plain = tmp_path / 'plain'  # a bag without ground_truth.yaml
    plain.mkdir()
    for name in ('metadata.yaml', 'hallway.mcap'):
        (plain / name).symlink_to(HALLWAY / name)
    with pytest.raises(ValueError) as e:
        evaluate_localization(plain, 'ekf')
    assert 'ground_truth.yaml' in _one_line(e)
    with pytest.raises(ValueError) as e:
        evaluate_localization(HALLWAY, 'ekf', map_path=tmp_path / 'nomap.yaml')
    assert 'no map file' in _one_line(e)
    with pytest.raises(ValueError) as e:
        evaluate_localization(HALLWAY, 'ekf', initial_std=(0.1, -1.0, 0.1))
    assert 'initial_std' in _one_line(e)
    with pytest.raises(ValueError) as e:
        build_sonar_map(HALLWAY, poses_topic='/nothing', out=tmp_path / 'm.yaml')
    assert '/nothing' in _one_line(e)
    with pytest.raises(ValueError) as e:
        build_sonar_map(HALLWAY, out=tmp_path / 'm.png')
    assert '.yaml' in _one_line(e)
    with pytest.raises(ValueError) as e:
        rasterize_map('atlantis', tmp_path / 'm.yaml')
    assert 'hallway' in _one_line(e)
    with pytest.raises(ValueError) as e:
        rasterize_map('hallway', tmp_path / 'm.yaml', resolution=0.0)
    assert 'resolution' in _one_line(e)
    assert not list(tmp_path.glob('m.*'))
    shutil.rmtree(plain)
