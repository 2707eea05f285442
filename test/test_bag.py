"""rosbag2 MCAP writing and reading: exact round trips and clear errors."""

from pathlib import Path

from geometry_msgs.msg import PoseArray
from landmark_nav.bag import BagError, BagReader, BagWriter, message_class, type_name
from mcap.reader import make_reader
import pytest
from sensor_msgs.msg import LaserScan
import yaml


def write_small_bag(path: Path, n: int = 20) -> list:
    """Write n scans and one latched PoseArray; return the scans."""
    scans = []
    with BagWriter(path) as bag:
        bag.add_topic('/scan', LaserScan)
        bag.add_topic('/ground_truth/corners', PoseArray, latched=True)
        bag.write('/ground_truth/corners', 1_000_000_000, PoseArray())
        for i in range(n):
            msg = LaserScan()
            msg.header.stamp.sec = 1 + i // 10
            msg.header.stamp.nanosec = (i % 10) * 100_000_000
            msg.header.frame_id = 'laser'
            msg.ranges = [float(i), float('inf'), float('nan')]
            bag.write('/scan', 1_000_000_000 + i * 100_000_000, msg)
            scans.append(msg)
    return scans


def test_round_trip_is_exact(tmp_path):
    scans = write_small_bag(tmp_path / 'b')
    with BagReader(tmp_path / 'b') as reader:
        topics = reader.topics()
        assert topics['/scan'].count == 20
        assert topics['/scan'].type_name == 'sensor_msgs/msg/LaserScan'
        assert topics['/ground_truth/corners'].latched
        assert not topics['/scan'].latched
        got = [m for t, _, m in reader.decoded(['/scan'])]
    assert len(got) == len(scans)
    for a, b in zip(got, scans):
        assert a.header == b.header
        assert list(a.ranges[:2]) == list(b.ranges[:2])


def test_bag_is_standard_rosbag2_mcap(tmp_path):
    write_small_bag(tmp_path / 'b')
    meta = yaml.safe_load((tmp_path / 'b' / 'metadata.yaml').read_text())
    info = meta['rosbag2_bagfile_information']
    assert info['storage_identifier'] == 'mcap'
    assert info['version'] == 8
    assert info['message_count'] == 21
    # An independent MCAP reader sees ros2msg schemas and cdr messages.
    with open(tmp_path / 'b' / 'b.mcap', 'rb') as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        encodings = {s.encoding for s in summary.schemas.values()}
        assert encodings == {'ros2msg'}
        assert {c.message_encoding for c in summary.channels.values()} == {'cdr'}
        assert sum(1 for _ in reader.iter_messages()) == 21


def test_missing_bag_is_a_clear_error(tmp_path):
    with pytest.raises(BagError, match='No bag at'):
        BagReader(tmp_path / 'nope')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagError, match='no metadata.yaml'):
        BagReader(tmp_path / 'empty')


def test_corrupt_mcap_is_a_clear_error(tmp_path):
    write_small_bag(tmp_path / 'b')
    mcap = tmp_path / 'b' / 'b.mcap'
    data = bytearray(mcap.read_bytes())
    mcap.write_bytes(bytes(data[: len(data) // 2]))  # truncated file
    with pytest.raises(BagError):
        with BagReader(tmp_path / 'b') as reader:
            list(reader.messages())


def test_unknown_topic_and_type(tmp_path):
    write_small_bag(tmp_path / 'b')
    with BagReader(tmp_path / 'b') as reader:
        with pytest.raises(BagError, match='/nope'):
            list(reader.messages(['/nope']))
    with pytest.raises(BagError):
        message_class('no_such_msgs/msg/Thing')
    with pytest.raises(BagError):
        message_class('LaserScan')
    assert type_name(LaserScan) == 'sensor_msgs/msg/LaserScan'


def test_writer_refuses_to_overwrite(tmp_path):
    (tmp_path / 'b').mkdir()
    with pytest.raises(BagError, match='exists'):
        BagWriter(tmp_path / 'b')


def test_custom_data_round_trip(tmp_path):
    with BagWriter(tmp_path / 'b') as bag:
        bag.add_topic('/scan', LaserScan)
        bag.write('/scan', 1, LaserScan())
        bag.set_custom_data('landmark_nav.laser_mount', '0.25 0 0')
        with pytest.raises(BagError, match='must be a string'):
            bag.set_custom_data('landmark_nav.seed', 3)
    with BagReader(tmp_path / 'b') as reader:
        assert reader.custom_data == {'landmark_nav.laser_mount': '0.25 0 0'}
    write_small_bag(tmp_path / 'c')
    with BagReader(tmp_path / 'c') as reader:
        assert reader.custom_data == {}
