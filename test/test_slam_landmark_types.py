"""The office bag with line landmarks, corners and lines, and a saved map reused (CLI)."""

import json
import math
from pathlib import Path

from landmark_nav.evaluation.bags import load_bag
from landmark_nav.evaluation.slam import evaluate_bag, run_slam
from landmark_nav.slam.slam_map import load_map
from landmark_nav.tools.cli import main as cli_main
from landmark_nav.tools.demo import chapter_config
import numpy as np
import pytest

BAG = Path(__file__).resolve().parents[1] / 'bags' / 'office'
CHAPTER_FILE = Path(__file__).resolve().parents[1] / 'config' / 'ekf_slam_chapter.yaml'


def _segment_distance(p, seg):
    a, b = np.array(seg[:2]), np.array(seg[2:])
    d = b - a
    t = np.clip((p - a) @ d / (d @ d), 0.0, 1.0)
    return float(np.hypot(*(a + t * d - p)))


def test_office_line_landmarks_lie_on_the_true_walls():
    """Every mapped line is a true wall: within 3 mm and 0.5 deg (measured 1.3 mm, 0.23 deg)."""
    sc = load_bag(BAG, None, None, None, None, require_reference=False)
    run = run_slam(sc, None, None, landmarks='lines')
    segs = sc.world.walls().segments
    assert run.lines.shape[0] == 15 and run.landmarks.shape[0] == 0
    assert run.resets == 0 and run.stats['pruned'] == 0
    for (rho, a), ends in zip(run.lines, run.line_ends):
        n = np.array([math.cos(a), math.sin(a)])
        best = min(segs, key=lambda s: max(abs(np.array(s[:2]) @ n - rho),
                                           abs(np.array(s[2:]) @ n - rho)))
        off = max(abs(np.array(best[:2]) @ n - rho), abs(np.array(best[2:]) @ n - rho))
        wall_dir = math.atan2(best[3] - best[1], best[2] - best[0])
        assert off < 0.003
        assert abs(math.remainder(wall_dir - a - math.pi / 2, math.pi)) < math.radians(0.5)
        # Endpoints on some wall (collinear walls may share one line landmark).
        for e in ends:
            assert min(_segment_distance(e, s) for s in segs) < 0.05


@pytest.mark.parametrize('landmarks,ate_bound,mapped', [('lines', 0.0015, (0, 15)),
                                                        ('both', 0.0012, (13, 15))])
def test_office_with_lines_is_at_least_as_good_as_corners(landmarks, ate_bound, mapped):
    """Office ATE RMSE: corners 2.8 mm (golden), lines 1.1 mm, both 0.8 mm (measured)."""
    r = evaluate_bag(BAG, progress=False, plots=False, landmarks=landmarks,
                     config=chapter_config(BAG))  # the chapter's filter, with lines
    assert (r['mapped'], r['lines_mapped']) == mapped
    assert r['ate_rmse'] < ate_bound
    assert r['wrong_associations'] == 0 and r['ghost_landmarks'] == 0
    assert r['ellipse95_share'] > 0.95  # measured 0.998 / 0.997
    assert r['nees_share_band'] > 0.85  # measured 0.936 / 0.908


def test_cli_save_map_then_localize(tmp_path, capsys):
    """Map 40 s of the office, save; localize on it: no new landmark, the same accuracy.

    The chapter's filter (the profile) with corners and lines.
    """
    assert cli_main(['evaluate', str(BAG), '--max-seconds', '40', '--no-progress',
                     '--params-file', str(CHAPTER_FILE),
                     '--landmarks', 'both', '--save-map', str(tmp_path / 'office'),
                     '--out', str(tmp_path / 'map')]) == 0
    assert 'map written' in capsys.readouterr().out
    saved = load_map(tmp_path / 'office.npz')
    mapped = json.loads((tmp_path / 'map' / 'slam.json').read_text())
    assert saved.size == mapped['mapped'] + mapped['lines_mapped'] > 10
    assert cli_main(['evaluate', str(BAG), '--max-seconds', '60', '--no-progress',
                     '--params-file', str(CHAPTER_FILE),
                     '--landmarks', 'both', '--mode', 'localization', '--map',
                     str(tmp_path / 'office.npz'), '--map-pose-sigma', '0.02', '0.02', '0.01',
                     '--out', str(tmp_path / 'loc')]) == 0
    loc = json.loads((tmp_path / 'loc' / 'slam.json').read_text())
    assert loc['mode'] == 'localization'
    assert loc['mapped'] + loc['lines_mapped'] == saved.size
    assert loc['stats']['confirmed'] == 0 and loc['stats']['new_candidates'] == 0
    assert loc['ate_rmse'] < 0.01 and loc['resets'] == 0
    # Without a map, localization is refused with a one-line error.
    assert cli_main(['evaluate', str(BAG), '--no-progress', '--mode', 'localization']) == 2
    assert '--mode localization needs --map' in capsys.readouterr().err
    assert cli_main(['evaluate', str(BAG), '--no-progress', '--map',
                     str(tmp_path / 'none.npz')]) == 2
    assert 'none.npz: no such map file' in capsys.readouterr().err
