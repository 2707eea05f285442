"""Simulator recordings: determinism at message level, ground truth, committed bags."""

import math
from pathlib import Path

from landmark_nav.bag import BagReader
from landmark_nav.conversions import odometry_to_pose, range_to_value, scan_to_data, stamp_to_ns
from landmark_nav.evaluation.viewer import VIEW_TOPICS
from landmark_nav.landmark_msgs import compressed_to_gray
from landmark_nav.sim.record import load_ground_truth, record_scenario, sonar_topic
from landmark_nav.sim.world import World
from landmark_nav.tools.bag_info import bag_size_bytes
from mcap.reader import make_reader
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
COMMITTED = {'office': 1, 'hallway': 1, 'calibration': 1, 'corridor': 1}  # scenario -> seed
IMAGES = '/camera/image_raw/compressed'                                   # (Makefile)


def content(bag, topics):
    """Decode the given topics into comparable plain arrays."""
    out = {}
    with BagReader(bag) as reader:
        for topic, log_ns, msg in reader.decoded(topics):
            if topic == '/scan':
                d = scan_to_data(msg)
                row = np.concatenate([[d.stamp_ns, log_ns], d.ranges])
            elif topic == IMAGES:
                gray = compressed_to_gray(msg).ravel()
                row = np.concatenate([[stamp_to_ns(msg.header.stamp), log_ns], gray])
            elif topic.startswith('/sonar'):
                r = range_to_value(msg)
                row = np.array([r.stamp_ns, log_ns, r.value])
            else:
                p = odometry_to_pose(msg)
                row = np.concatenate([[p.stamp_ns, log_ns], p.pose, p.covariance.ravel()])
            out.setdefault(topic, []).append(row)
    return {k: np.array(v) for k, v in out.items()}


TOPICS = ['/odom', '/ground_truth/odom', '/scan', sonar_topic(3)]


@pytest.fixture(scope='module')
def office(tmp_path_factory):
    bag = tmp_path_factory.mktemp('rec') / 'office'
    record_scenario('office', 7, bag)
    return bag


def test_same_seed_same_messages(office, tmp_path):
    again = tmp_path / 'again'
    record_scenario('office', 7, again)
    a, b = content(office, TOPICS), content(again, TOPICS)
    assert a.keys() == b.keys() == set(TOPICS)
    for topic in TOPICS:
        np.testing.assert_array_equal(a[topic], b[topic], err_msg=topic)


def test_other_seed_other_messages(office, tmp_path):
    other = tmp_path / 'other'
    record_scenario('office', 8, other)
    a, b = content(office, ['/scan']), content(other, ['/scan'])
    assert not np.array_equal(a['/scan'], b['/scan'])


def test_recording_is_consistent(office):
    meta = load_ground_truth(office)
    world = World.from_dict(meta['world'])
    with BagReader(office) as reader:
        topics = reader.topics()
        corners = next(m for _, _, m in reader.decoded(['/ground_truth/corners']))
        states = [m for _, _, m in reader.decoded(['/joint_states'])]
    assert topics['/ground_truth/corners'].latched
    assert len(corners.poses) == len(world.corners().ids) == len(meta['world']['corners'])
    np.testing.assert_allclose([[p.position.x, p.position.y] for p in corners.poses],
                               world.corners().positions)
    assert all(list(s.name) == ['left_wheel_joint', 'right_wheel_joint'] for s in states)
    c = content(office, TOPICS)
    # Odometry and ground truth at 10 Hz on the same stamps; header stamp == log time.
    np.testing.assert_array_equal(c['/odom'][:, 0], c['/ground_truth/odom'][:, 0])
    assert np.allclose(np.diff(c['/odom'][:, 0]), 1e8)
    for rows in c.values():
        np.testing.assert_array_equal(rows[:, 0], rows[:, 1])
    # Odometry starts at the true pose; truth has zero covariance.
    np.testing.assert_allclose(c['/odom'][0, 2:5], c['/ground_truth/odom'][0, 2:5], atol=1e-12)
    assert not c['/ground_truth/odom'][:, 5:].any()
    # Laser: REP 117 (no-return beams are +inf, no negative or NaN values).
    ranges = c['/scan'][:, 2:]
    assert np.isposinf(ranges).any() and not np.isnan(ranges).any()
    assert (ranges[np.isfinite(ranges)] > 0).all()
    assert ranges.shape[1] == 361


def test_demo_writes_plot_and_summary(office_demo):
    summary, out = office_demo  # run_demo of bags/office (shared with test_golden.py)
    png = out / 'world_paths.png'
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    drift = (out / 'summary.txt').read_text().strip()
    assert summary.startswith(drift) and 'odometry final position error' in drift
    assert 'EKF-SLAM' in summary and 'ATE RMSE' in summary
    for name in ('slam_map.png', 'slam_errors.png', 'slam.json', 'trajectory_slam.tum',
                 'view/view.mcap'):
        assert (out / name).is_file(), name
    assert 'viewer file: ' in summary  # its content in detail: test_viewer_mcap.py
    with open(out / 'view' / 'view.mcap', 'rb') as f:
        view = make_reader(f).get_summary()
    channels = {c.topic: c for c in view.channels.values()}
    assert set(channels) == set(VIEW_TOPICS)  # every topic typed: a ros2msg schema
    assert all(view.schemas[c.schema_id].encoding == 'ros2msg' and
               view.schemas[c.schema_id].name == VIEW_TOPICS[t] for t, c in channels.items())
    counts = view.statistics.channel_message_counts
    assert counts[channels['/scan'].id] == counts[channels['/pose'].id] == 1200


def test_ground_truth_files_read_as_yaml_safe_load_reads_them():
    import yaml
    for scenario in sorted(COMMITTED):
        path = REPO / 'bags' / scenario / 'ground_truth.yaml'
        got, expected = load_ground_truth(path.parent), yaml.safe_load(path.read_text())
        assert got == expected and repr(got) == repr(expected), scenario  # values and order


@pytest.mark.parametrize('scenario', sorted(COMMITTED))
def test_committed_bag_is_small_and_reproducible(scenario, tmp_path):
    bag = REPO / 'bags' / scenario
    assert (bag / 'metadata.yaml').is_file(), f'{bag} missing: run `make bags`'
    assert bag_size_bytes(bag) < 10 * 1024 * 1024
    meta = load_ground_truth(bag)
    assert meta['scenario'] == scenario and meta['seed'] == COMMITTED[scenario]
    fresh = tmp_path / scenario
    record_scenario(scenario, COMMITTED[scenario], fresh)
    with BagReader(bag) as reader:
        topics = [t for t in ('/odom', '/scan', sonar_topic(0), IMAGES) if t in reader.topics()]
    a, b = content(bag, topics), content(fresh, topics)
    for topic in topics:
        np.testing.assert_array_equal(a[topic], b[topic], err_msg=topic)
    assert_same_metadata(load_ground_truth(fresh), meta)


def assert_same_metadata(fresh, committed, where: str = 'ground_truth') -> None:
    """Equal structure, strings and integers; floats equal to 1e-12 (relative or absolute).

    The world's derived values (corner bisectors and openings from atan2 of the segments)
    come from libm, whose result can differ by one ulp between CPUs (glibc picks an
    FMA / AVX2 variant at run time): a bag recorded on one machine and re-recorded on
    another differs there, e.g. an opening of 2.356194490192345 against
    2.3561944901923457 and a bisector 8 ulp apart after the arithmetic that follows, and
    nowhere else (the recorded messages are compared exactly).
    """
    if isinstance(committed, dict):
        assert isinstance(fresh, dict) and fresh.keys() == committed.keys(), where
        for k in committed:
            assert_same_metadata(fresh[k], committed[k], f'{where}.{k}')
    elif isinstance(committed, (list, tuple)):
        assert isinstance(fresh, (list, tuple)) and len(fresh) == len(committed), where
        for i, (x, y) in enumerate(zip(fresh, committed)):
            assert_same_metadata(x, y, f'{where}[{i}]')
    elif isinstance(committed, float):
        assert isinstance(fresh, (float, int)), where
        assert math.isclose(fresh, committed, rel_tol=1e-12, abs_tol=1e-12), (
            f'{where}: {fresh!r} != {committed!r}')
    else:
        assert fresh == committed and type(fresh) is type(committed), where


def test_metadata_comparison_allows_ulps_only():
    """Last-place differences pass; a changed value (1e-11), key or type does not."""
    base = {'world': {'corners': [{'opening': 2.356194490192345, 'id': 10}]}, 'seed': 1}
    assert_same_metadata({'world': {'corners': [{'opening': 2.3561944901923457, 'id': 10}]},
                          'seed': 1}, base)
    for bad in ({'world': {'corners': [{'opening': 2.3561944902159, 'id': 10}]}, 'seed': 1},
                {'world': {'corners': [{'opening': 2.356194490192345, 'id': 11}]}, 'seed': 1},
                {'world': {'corners': []}, 'seed': 1},
                {'world': {'corners': [{'opening': 2.356194490192345, 'id': 10}]},
                 'seed': '1'}):
        with pytest.raises(AssertionError):
            assert_same_metadata(bad, base)


def test_corridor_bag_stays_small():
    """bags/corridor holds images: 320 x 240 JPEG frames keep it under 0.5 MB (440 KB)."""
    bag = REPO / 'bags' / 'corridor'
    assert bag_size_bytes(bag) < 512 * 1024
    meta = load_ground_truth(bag)
    assert meta['image_size'] == [320, 240] and meta['frames'] == 30
