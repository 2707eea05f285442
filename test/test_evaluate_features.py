"""``landmark_nav evaluate-features`` on bags without ground-truth features (truth-free)."""

import json
import math
from pathlib import Path

from landmark_nav.bag import BagWriter
from landmark_nav.conversions import make_odometry, make_scan
from landmark_nav.evaluation.feature_bags import evaluate_truth_free
from landmark_nav.evaluation.trajectory import read_tum
from landmark_nav.geometry import compose
from landmark_nav.sim import World
from landmark_nav.tools.evaluate_features import run
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from sensor_msgs.msg import LaserScan

T0 = 1_700_000_000_000_000_000
MOUNT = np.array([0.5, 0.0, 0.0])
ANGLES = np.radians(np.arange(-90.0, 90.01, 0.5))


def base_poses(n: int = 6) -> np.ndarray:
    """Return the poses of the robot turning in place by 15 deg per scan in a 6 m x 4 m room."""
    return np.array([[3.0, 2.0, math.radians(-40.0 + 15.0 * k)] for k in range(n)])


def write_room_bag(path: Path, mount_data=True, truth=True) -> np.ndarray:
    """Write noise-free scans of the room from the laser at ``MOUNT``; return the poses."""
    world = World('room')
    world.add_room([(0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0)])
    poses = base_poses()
    with BagWriter(path) as bag:
        bag.add_topic('/scan', LaserScan)
        if truth:
            bag.add_topic('/ground_truth/odom', Odometry)
        for k, pose in enumerate(poses):
            stamp = T0 + k * 200_000_000
            laser = compose(pose, MOUNT)
            r = world.raycast(np.repeat(laser[None, :2], ANGLES.size, axis=0),
                              laser[2] + ANGLES, 20.0).ranges
            bag.write('/scan', stamp, make_scan(stamp, 'laser', ANGLES[0], ANGLES[1] - ANGLES[0],
                                                r, 0.05, 20.0))
            if truth:
                bag.write('/ground_truth/odom', stamp,
                          make_odometry(stamp, 'map', 'base_link', pose))
        if mount_data:
            bag.set_custom_data('landmark_nav.laser_mount', ' '.join(str(v) for v in MOUNT))
            bag.set_custom_data('landmark_nav.laser_sigma_range', '0.02')
    return poses


def write_tum(path: Path, poses: np.ndarray) -> None:
    """Write base poses as a TUM file at the scans' stamps."""
    with open(path, 'w') as f:
        f.write('# t x y z qx qy qz qw\n')
        for k, p in enumerate(poses):
            t = (T0 + k * 200_000_000) / 1e9
            f.write(f'{t:.9f} {p[0]} {p[1]} 0 0 0 {math.sin(p[2] / 2)} {math.cos(p[2] / 2)}\n')


def test_static_room_is_repeatable_with_the_stated_mount(tmp_path):
    write_room_bag(tmp_path / 'b')
    res, notes = evaluate_truth_free(tmp_path / 'b', scans=4, seed=0)
    assert notes == []
    assert res['laser_mount'] == [0.5, 0.0, 0.0] and res['sigma_r'] == 0.02
    assert res['false_surface_margin_m'] == pytest.approx(0.06)
    assert res['scans'] == 6 and res['repeat_pairs'] == 5 and res['ple_scans'] == 4
    for m in ('split_merge', 'alfa', 'approxPolyDP'):
        f = res['lines'][m]
        assert f['false_surface_beams'] == 0, m
        assert f['line_opportunities'] >= 10 and f['line_repeatability'] == 1.0, m
        assert f['f'] > 0.95, m
        if m != 'approxPolyDP':  # its vertices are beams next to the room corners: ~1 cm
            assert f['ray_rmse_mean_m'] < 1e-3, m
    # Room corners: every one seen again within 10 cm.
    mc = res['corners']['minus_cosine']
    assert mc['corner_opportunities'] >= 5 and mc['corner_repeatability'] == 1.0
    # the room's corners have walls of metres on both sides: all structural
    assert mc['structural_share'] == 1.0 and mc['corner_opportunities_other'] == 0
    assert (mc['corner_opportunities_structural'], mc['corner_redetected_structural']) == (
        mc['corner_opportunities'], mc['corner_redetected'])
    assert mc['corner_repeatability_other'] != mc['corner_repeatability_other']  # NaN: none


def test_missing_mount_falls_back_to_zero_with_a_note_and_breaks_repeatability(tmp_path):
    write_room_bag(tmp_path / 'b', mount_data=False)
    res, notes = evaluate_truth_free(tmp_path / 'b', scans=4)
    assert any('no laser mount' in n for n in notes)
    assert any('no laser range noise' in n for n in notes)
    # 15 deg turns with the laser 0.5 m ahead: without the mount the poses are 13 cm off.
    assert res['lines']['split_merge']['line_repeatability'] < 0.5
    assert res['corners']['minus_cosine']['corner_repeatability'] < 0.5
    # The option supplies it.
    res, notes = evaluate_truth_free(tmp_path / 'b', scans=4, mount=MOUNT, sigma_r=0.02)
    assert notes == [] and res['lines']['split_merge']['line_repeatability'] == 1.0


def test_tum_reference_and_bag_without_reference(tmp_path):
    poses = write_room_bag(tmp_path / 'b', truth=False)
    res, notes = evaluate_truth_free(tmp_path / 'b', scans=4)
    assert res['repeat_pairs'] == 0 and any('no /ground_truth/odom' in n for n in notes)
    assert res['lines']['split_merge']['line_opportunities'] == 0
    # No repeatability without poses: None (JSON null, 'n/a' in the tables), not NaN.
    assert all(f['line_repeatability'] is None for f in res['lines'].values())
    assert all(f['corner_repeatability'] is None for f in res['corners'].values())
    text = run(tmp_path / 'b', json_out=tmp_path / 'out.json', scans=4)
    # one per line method, three per corner method (all corners, structural, others)
    assert text.count('n/a (no reference poses)') == len(res['lines']) + 3 * len(res['corners'])
    assert json.loads((tmp_path / 'out.json').read_text())['lines']['alfa'][
        'line_repeatability'] is None
    write_tum(tmp_path / 'ref.tum', poses)
    res, _ = evaluate_truth_free(tmp_path / 'b', reference=str(tmp_path / 'ref.tum'), scans=4)
    assert res['repeat_pairs'] == 5
    assert res['lines']['split_merge']['line_repeatability'] == 1.0
    np.testing.assert_allclose(read_tum(tmp_path / 'ref.tum').planar(), poses, atol=1e-12)


def test_bad_reference_and_custom_data_name_the_source(tmp_path):
    # The reference goes through evaluation.trajectory.read_tum (its own tests: test_trajectory).
    write_room_bag(tmp_path / 'room')
    (tmp_path / 'bad.tum').write_text('# header\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n')
    with pytest.raises(ValueError, match=r'bad\.tum:3: expected 8 fields'):
        evaluate_truth_free(tmp_path / 'room', reference=str(tmp_path / 'bad.tum'))
    (tmp_path / 'back.tum').write_text('2.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n')
    with pytest.raises(ValueError, match=r'back\.tum:2: stamp 1.0 is not after the previous'):
        evaluate_truth_free(tmp_path / 'room', reference=str(tmp_path / 'back.tum'))
    with BagWriter(tmp_path / 'b') as bag:
        bag.add_topic('/scan', LaserScan)
        bag.write('/scan', T0, make_scan(T0, 'laser', -1.0, 0.01, np.ones(201), 0.05, 20.0))
        bag.set_custom_data('landmark_nav.laser_mount', '0.2 0')
    with pytest.raises(ValueError, match='laser_mount.*not three finite numbers'):
        evaluate_truth_free(tmp_path / 'b')


def test_run_prints_the_truth_free_tables_and_json(tmp_path):
    write_room_bag(tmp_path / 'b')
    text = run(tmp_path / 'b', json_out=tmp_path / 'out.json', scans=3, seed=1)
    assert '| approxPolyDP_min_size |' in text and '| minus_cosine |' in text
    assert 'scans: 6 (3 drawn with seed 1' in text
    assert (tmp_path / 'out.json').read_text().startswith('{')


def test_bag_path_equals_the_offline_path_on_a_real_log(tmp_path):
    # 80 scans of a real log written as an imported bag (REP 117 +inf, /ground_truth/odom at
    # the scan stamps, the facts in custom_data) score as the same scans fed directly.
    from landmark_nav.evaluation.scan_metrics import evaluate_scans, MetricScan
    from landmark_nav.testing import shared_data
    from landmark_nav.importers.carmen import read_carmen_scans
    raw = []
    for s in read_carmen_scans(shared_data('carmen', 'seattle-corrected.log.gz')):
        raw.append(s)
        if len(raw) == 80:
            break
    direct = []
    with BagWriter(tmp_path / 'b') as bag:
        bag.add_topic('/scan', LaserScan)
        bag.add_topic('/ground_truth/odom', Odometry)
        for k, s in enumerate(raw):
            stamp = T0 + k * 100_000_000
            msg = make_scan(stamp, 'laser', s.angle_min, s.angle_increment, s.ranges, 1e-3,
                            40.0)
            bag.write('/scan', stamp, msg)
            bag.write('/ground_truth/odom', stamp, make_odometry(stamp, 'map', 'base_link',
                                                                 s.pose))
            r = np.asarray(msg.ranges, dtype=float)  # float32 as in the bag
            angles = np.float32(s.angle_min) + np.float32(s.angle_increment) * np.arange(r.size)
            direct.append(MetricScan(r, angles, np.isfinite(r) & (r > 0.0), np.isposinf(r),
                                     1e-3, 40.0, np.asarray(s.pose, dtype=float)))
        bag.set_custom_data('landmark_nav.laser_mount', '0 0 0')
        bag.set_custom_data('landmark_nav.laser_sigma_range', '0.01')
    via_bag, notes = evaluate_truth_free(tmp_path / 'b', scans=20, seed=0)
    offline = evaluate_scans(direct, sigma_r=0.01, ple_scans=20, seed=0)
    assert notes == [] and via_bag['repeat_pairs'] == offline['repeat_pairs'] == 79
    for kind in ('lines', 'corners'):
        for m, figures in offline[kind].items():
            for key, value in figures.items():
                if 'ms_per_scan' in key:
                    continue
                got = via_bag[kind][m][key]
                if isinstance(value, float):
                    assert got == pytest.approx(value, rel=1e-9, abs=1e-12, nan_ok=True), (
                        m, key)
                else:
                    assert got == value, (m, key)
    assert offline['lines']['split_merge']['line_opportunities'] > 100


def test_imported_real_bag_states_its_facts(tmp_path):
    # A bag written by `landmark_nav import` carries the mount, the noise and the reference:
    # no fallback note, every consecutive pair scored.
    from landmark_nav.importers.writer import import_log
    from landmark_nav.testing import shared_data
    import_log(shared_data('carmen', 'belgioioso-corrected.log.gz'), tmp_path / 'b',
               max_scans=40)
    res, notes = evaluate_truth_free(tmp_path / 'b', scans=10)
    assert notes == []
    assert res['laser_mount'] == pytest.approx([-0.04, 0.0, 0.0])  # PARAM front laser offset
    assert res['scans'] == 40 and res['repeat_pairs'] == 39 and res['ple_scans'] == 10
    assert res['lines']['split_merge']['line_opportunities'] > 50
