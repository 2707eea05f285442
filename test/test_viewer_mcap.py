"""The viewer MCAP of ``make demo`` read back with the ``mcap`` package.

:func:`landmark_nav.evaluation.viewer.write_slam_view` (what ``landmark_nav demo`` writes to
``out/view``) on the first seconds of ``bags/office``: every channel is typed (a ``ros2msg``
schema with its definition, ``cdr`` messages), the counts match, the messages decode, and
their content agrees with itself: the TF chain map -> odom -> base_link is the filter pose,
the last ``/path`` ends on the last ``/pose``, the landmarks are 2-sigma ellipses in
``map``. The shipped layout names only topics of the file.
"""

import json
import math
from pathlib import Path

from landmark_nav.bag.messages import deserialize
from landmark_nav.conversions import pose_msg_to_2d
from landmark_nav.evaluation.viewer import VIEW_TOPICS, write_slam_view
from landmark_nav.geometry import compose
from mcap.reader import make_reader
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope='module')
def view(tmp_path_factory):
    out = tmp_path_factory.mktemp('view') / 'view'
    result = write_slam_view(REPO / 'bags' / 'office', out, max_seconds=8.0)
    with open(result['mcap'], 'rb') as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = {}
        for schema, channel, message in reader.iter_messages():
            messages.setdefault(channel.topic, []).append((schema, message))
    return result, summary, messages


def _tf(store, data):
    msg = store.deserialize_cdr(data, 'tf2_msgs/msg/TFMessage')
    out = {}
    for t in msg.transforms:
        q = t.transform.rotation
        out[(t.header.frame_id, t.child_frame_id)] = np.array(
            [t.transform.translation.x, t.transform.translation.y,
             2.0 * math.atan2(q.z, q.w)])
    return out


def test_every_channel_is_typed_and_counted(view):
    result, summary, messages = view
    topics = {c.topic: c for c in summary.channels.values()}
    assert set(topics) == set(VIEW_TOPICS)  # a simulator bag: every topic
    for topic, channel in topics.items():
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == 'cdr'
        assert schema.encoding == 'ros2msg' and schema.name == VIEW_TOPICS[topic]
        assert schema.data  # the definition travels with the file
        count = summary.statistics.channel_message_counts[channel.id]
        assert count == result['counts'][topic] == len(messages[topic]) > 0
    assert b'float32[] ranges' in summary.schemas[topics['/scan'].schema_id].data
    assert result['counts']['/scan'] == 80  # 8 s of 10 Hz scans


def test_messages_decode_and_agree(view):
    from landmark_nav.evaluation.viewer import _typestore
    _, _, messages = view
    decoded = {topic: [deserialize(m.data, VIEW_TOPICS[topic]) for _, m in rows]
               for topic, rows in messages.items() if not topic.startswith('/tf')}
    scan = decoded['/scan'][-1]
    assert scan.header.frame_id == 'laser' and len(scan.ranges) == 361
    poses = [pose_msg_to_2d(m.pose.pose) for m in decoded['/pose']]
    assert all(m.header.frame_id == 'map' for m in decoded['/pose'])
    store = _typestore()
    tfs = [_tf(store, m.data) for _, m in messages['/tf']]
    assert len(tfs) == len(poses)
    for tf, pose in zip(tfs, poses):
        chain = compose(tf[('map', 'odom')], tf[('odom', 'base_link')])
        assert chain[:2] == pytest.approx(pose[:2], abs=1e-9)
        assert math.remainder(chain[2] - pose[2], 2 * math.pi) == pytest.approx(0, abs=1e-9)
    static = _tf(store, messages['/tf_static'][0][1].data)
    assert list(static) == [('base_link', 'laser')]
    path = decoded['/path'][-1]
    assert pose_msg_to_2d(path.poses[-1].pose) == pytest.approx(poses[-1], abs=1e-9)
    assert len(path.poses) == len(poses)
    truth = [pose_msg_to_2d(m.pose.pose) for m in decoded['/ground_truth/odom']]
    err = np.hypot(*(np.array(poses)[:, :2] - np.array(truth)[:, :2]).T)
    assert err.max() < 0.02  # the office run's filter is within 1 cm of the truth
    landmarks = decoded['/landmarks'][-1].markers
    assert landmarks[0].action == 3  # DELETEALL, then one ellipse per landmark
    ellipses = landmarks[1:]
    assert len(ellipses) >= 4
    for mk in ellipses:
        assert mk.header.frame_id == 'map' and mk.type == 4 and len(mk.points) == 25
        assert mk.points[0].x == pytest.approx(mk.points[-1].x)  # closed
    corners = decoded['/corners'][-1]
    assert corners.header.frame_id == 'laser' and len(corners.poses) >= 1
    walls = decoded['/world'][0].markers[0]
    assert walls.type == 5 and len(walls.points) >= 2 * 13  # LINE_LIST of the office walls


def test_shipped_layout_uses_topics_of_the_file(view):
    layout = json.loads((REPO / 'viewer' / 'slam_layout.json').read_text())
    names = set()
    for panel in layout['configById'].values():
        names |= set(panel.get('topics', {}))
        names |= {p['value'].split('.')[0] for p in panel.get('paths', [])}
        if 'topicPath' in panel:
            names.add(panel['topicPath'])
    assert names and names <= set(VIEW_TOPICS)
    assert layout['configById']['3D!slam']['followTf'] == 'map'


def test_existing_output_is_not_overwritten(tmp_path):
    (tmp_path / 'v').mkdir()
    with pytest.raises(ValueError, match='exists already'):
        write_slam_view(REPO / 'bags' / 'office', tmp_path / 'v', max_seconds=1.0)


def test_rviz_config_shows_the_slam_topics_in_map():
    import yaml
    config = yaml.safe_load((REPO / 'rviz' / 'slam.rviz').read_text())
    manager = config['Visualization Manager']
    topics = {d['Topic']['Value'] for d in manager['Displays'] if 'Topic' in d}
    assert manager['Global Options']['Fixed Frame'] == 'map'
    assert {'/scan', '/landmarks', '/path', '/pose'} <= topics <= set(VIEW_TOPICS)


def test_the_view_of_evaluate_runs_its_configuration(tmp_path):
    """``evaluate --view`` with the defaults: the lines are drawn, the path is evaluate's."""
    from landmark_nav.evaluation.slam import bag_configuration, evaluate_bag
    bag = REPO / 'bags' / 'office'
    config = bag_configuration(bag)
    assert config.landmarks == 'both'
    result = write_slam_view(bag, tmp_path / 'view', 'icnn', max_seconds=8.0, config=config)
    with open(result['mcap'], 'rb') as f:
        rows = [(channel.topic, message) for _, channel, message
                in make_reader(f).iter_messages(topics=['/landmarks', '/pose'])]
    last = [deserialize(m.data, VIEW_TOPICS[t]) for t, m in rows if t == '/landmarks'][-1]
    kinds = [mk.ns for mk in last.markers[1:]]
    assert 'landmark_lines' in kinds and 'landmark_ellipses' in kinds
    pose = pose_msg_to_2d([deserialize(m.data, VIEW_TOPICS[t]) for t, m in rows
                           if t == '/pose'][-1].pose.pose)
    evaluate_bag(bag, 'icnn', tmp_path / 'eval', progress=False, max_seconds=8.0,
                 config=config)
    last_tum = (tmp_path / 'eval' / 'trajectory_slam.tum').read_text().splitlines()[-1]
    x, y = (float(v) for v in last_tum.split()[1:3])
    assert (x, y) == pytest.approx(tuple(pose[:2]), abs=1e-9)
