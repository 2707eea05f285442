"""No input moves a node's state silently: ekf_slam as its own process, fed through DDS.

A teleport claiming a huge covariance is bridged, not taken as motion; stated covariances
that are not usable are replaced and counted; stamp 0 is malformed input (never a reset);
every drop and every input used other than as it came has a count on ``/diagnostics``.
"""

import math
import os
from pathlib import Path
import sys

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from landmark_nav.conversions import make_odometry, make_scan
from landmark_nav.feature_msgs import make_feature_cloud
from landmark_nav.testing import RosHarness
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from sensor_msgs.msg import LaserScan, PointCloud2
from std_srvs.srv import Trigger

REPO = Path(__file__).resolve().parents[1]
T0 = 1_700_000_000_000_000_000
MS = 1_000_000
CORNERS = [[2.0, 1.0, 0.0, 3.0, 1.57, 1e-4, 0.0, 1e-4],
           [3.0, -1.0, 0.0, 2.0, 1.57, 1e-4, 0.0, 1e-4]]
SMALL = np.diag([1e-4, 1e-4, 1e-4])


def corner_cloud(t, rows=CORNERS):
    """Return a corner cloud (``corners/features``) with the given rows."""
    names = ('x', 'y', 'z', 'bisector', 'opening', 'cov_xx', 'cov_xy', 'cov_yy')
    rows = np.asarray(rows, dtype=float).reshape(-1, 8)
    return make_feature_cloud(t, 'laser', names, dict(zip(names, rows.T)))


def scan(t):
    """Return a small valid scan: 181 beams, all at 4 m."""
    return make_scan(t, 'laser', -math.pi / 2, math.pi / 180, np.full(181, 4.0), 0.1, 30.0)


def start_slam(processes, tmp_path, *params):
    """Start ekf_slam as a process (stderr to a file); return the file.

    The chapter profile (corners only, no scan matching): the corner sets alone make steps,
    so a test can feed odometry without scans.
    """
    err = tmp_path / 'ekf_slam.err'
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    args = ['--params-file', str(REPO / 'config' / 'ekf_slam_chapter.yaml'),
            '-p', f'map_file:={tmp_path / "map.yaml"}', '-p', 'confirm_hits:=1',
            '-p', 'confirm_window:=1']
    for p in params:
        args += ['-p', p]
    with open(err, 'w') as f:
        processes.start([sys.executable, '-m', 'landmark_nav.nodes.ekf_slam', '--ros-args',
                         *args], env=env, cwd=REPO, stderr=f)
    return err


class Feeder:
    """The test's side: publishers, the node's poses and input status, save_map."""

    def __init__(self, ros: RosHarness, with_scan: bool) -> None:
        """Create the publishers and wait until the node's subscriptions match them."""
        self.ros = ros
        h = ros._helper
        self.poses = ros.collect('pose', PoseWithCovarianceStamped)
        self.diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        self.odom_pub = h.create_publisher(Odometry, 'odom', 100)
        self.corner_pub = h.create_publisher(PointCloud2, 'corners/features', 100)
        self.scan_pub = h.create_publisher(LaserScan, 'scan', 100) if with_scan else None
        self.save = h.create_client(Trigger, 'save_map')
        pubs = [self.odom_pub, self.corner_pub] + ([self.scan_pub] if with_scan else [])
        assert ros.wait_for_subscribers(pubs, 120.0), 'ekf_slam did not start'
        assert self.save.wait_for_service(60.0)
        # The node's outputs matched this side: its input status has come.
        assert ros.wait_until(lambda: h.count_publishers('pose') and self.status(), 60.0)

    def odom(self, t, x, cov=SMALL):
        """Publish an odometry pose ``[x, 0, 0]``; ``cov`` goes into the message as it is."""
        msg = make_odometry(t, 'odom', 'base_link', [x, 0.0, 0.0])
        c = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)
        c[np.ix_([0, 1, 5], [0, 1, 5])] = cov
        msg.pose.covariance = c.ravel()
        self.odom_pub.publish(msg)

    def step(self, t, x):
        """Publish odometry at ``t`` and ``t + 10 ms``, the set at ``t``; wait for its pose."""
        n = len(self.poses)
        self.odom(t, x)
        self.odom(t + 10 * MS, x)
        self.corner_pub.publish(corner_cloud(t))
        if self.scan_pub is not None:
            self.scan_pub.publish(scan(t))
        assert self.ros.wait_until(lambda: len(self.poses) > n, 30.0), 'no pose'
        return self.poses[-1].pose.pose.position.x

    def map_three_steps(self):
        """Make three steps 1 cm apart; return the last pose's x and the landmarks mapped."""
        for k in range(3):
            x = self.step(T0 + k * 100 * MS, 0.01 * k)
        mapped = self.landmarks()
        assert mapped >= 1
        return x, mapped

    def status(self, wait_for=None) -> dict:
        """Return the latest ``ekf_slam: input`` values (waiting until ``wait_for`` holds)."""
        def latest():
            for arr in reversed(self.diagnostics):
                for s in arr.status:
                    if s.name == 'ekf_slam: input':
                        return {kv.key: kv.value for kv in s.values}
            return {}
        if wait_for is not None:
            self.ros.wait_until(lambda: wait_for(latest()), 30.0)
        return latest()

    def landmarks(self) -> int:
        """Return the number of landmarks the node's save_map reports."""
        future = self.save.call_async(Trigger.Request())
        assert self.ros.wait_until(future.done, 30.0)
        words = future.result().message.split()
        return int(words[words.index('saved') + 1])


@pytest.mark.dds
def test_teleport_with_huge_covariance_is_refused_and_bad_covariances_counted(
        processes, tmp_path):
    err = start_slam(processes, tmp_path, 'visibility:=false')
    with RosHarness() as ros:
        feed = Feeder(ros, with_scan=False)
        before, mapped = feed.map_three_steps()
        # +5 m in 0.1 s, claiming a covariance of 1e6 m^2, and back 0.1 s later.
        feed.odom(T0 + 300 * MS, 5.02, np.diag([1e6, 1e6, 1e6]))
        feed.odom(T0 + 400 * MS, 0.02)
        x = feed.step(T0 + 500 * MS, 0.02)
        assert abs(x - before) < 0.01
        values = feed.status(lambda v: v.get('odometry.jump') == '2')
        assert values.get('odometry.jump') == '2', values
        # Negative, NaN and indefinite covariances: the sample is used, the model replaces them.
        bad = [np.diag([-1e-4, 1e-4, 1e-4]), np.diag([np.nan, 1e-4, 1e-4]),
               np.array([[1e-4, 1e-2, 0.0], [1e-2, 1e-4, 0.0], [0.0, 0.0, 1e-4]])]
        for k, cov in enumerate(bad):
            feed.odom(T0 + (600 + 100 * k) * MS, 0.02, cov)
        x = feed.step(T0 + 900 * MS, 0.02)
        assert abs(x - before) < 0.01
        values = feed.status(lambda v: v.get('odometry.covariance_replaced') == '3')
        assert values.get('odometry.covariance_replaced') == '3', values
        assert values['dropped'] == '0' and feed.landmarks() == mapped
    text = err.read_text()
    assert 'Odometry (jump): odometry moved 5.000 m' in text
    for problem in ('negative variance', 'not finite', 'not positive semi-definite'):
        assert f'is {problem}' in text, text


@pytest.mark.dds
def test_stamp_zero_and_malformed_odometry_are_dropped_and_leave_the_map(processes,
                                                                         tmp_path):
    err = start_slam(processes, tmp_path)
    with RosHarness() as ros:
        feed = Feeder(ros, with_scan=True)
        x, mapped = feed.map_three_steps()
        feed.odom(0, 0.0)  # stamp 0 (unset header): used to wipe the map
        feed.scan_pub.publish(scan(0))
        feed.corner_pub.publish(corner_cloud(0))
        nan = make_odometry(T0 + 250 * MS, 'odom', 'base_link', [0.0, 0.0, 0.0])
        nan.pose.pose.position.x = math.nan
        zero_q = make_odometry(T0 + 260 * MS, 'odom', 'base_link', [0.0, 0.0, 0.0])
        zero_q.pose.pose.orientation.w = 0.0
        feed.odom_pub.publish(nan)
        feed.odom_pub.publish(zero_q)
        values = feed.status(lambda v: v.get('dropped.malformed') == '5')
        assert values.get('dropped.malformed') == '5', values
        before = x
        x = feed.step(T0 + 300 * MS, 0.03)
        assert abs(x - before) < 0.01 and feed.landmarks() == mapped
        values = feed.status()
        assert 'odometry.restart' not in values and values['dropped'] == '5', values
    text = err.read_text()
    for what in ('odometry', 'scan', 'corners'):
        assert f'Dropping {what}: ' in text, text
    assert 'stamp 0 ns is not a time' in text and 'restarting' not in text


def input_status(diagnostics, name: str) -> dict:
    """Return the latest ``<name>: input`` values among the collected DiagnosticArrays."""
    for arr in reversed(list(diagnostics)):
        for s in arr.status:
            if s.name == f'{name}: input':
                return {kv.key: kv.value for kv in s.values}
    return {}


@pytest.mark.dds
def test_scan_drops_have_their_true_reason():
    """A scan of 2e5 beams is ``oversized`` (it was counted as ``lost``); stamp 0 ``malformed``."""
    from landmark_nav.nodes.corner_extractor import CornerExtractor
    with RosHarness() as ros:
        node = ros.add_node(CornerExtractor(context=ros.context))
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        pub = ros._helper.create_publisher(LaserScan, 'scan', 10)
        assert ros.wait_for_subscribers([pub])
        said = []
        warn = node.warner.warn
        node.warner.warn = lambda message, detail='': (said.append(message),
                                                       warn(message, detail))
        big = make_scan(T0, 'laser', -math.pi / 2, math.pi / 200_000, np.full(200_000, 4.0),
                        0.1, 30.0)
        negative = scan(T0 + 200 * MS)
        negative.ranges[7] = -0.5  # a beam no laser measures: invalid, the scan is used
        for msg in (scan(T0), big, scan(0), scan(T0 + 100 * MS), negative):
            pub.publish(msg)
        want = {'processed': '3', 'dropped.oversized': '1', 'dropped.malformed': '1',
                'scan.negative_ranges': '1'}
        assert ros.wait_until(lambda: all(input_status(diagnostics, 'corner_extractor').get(k)
                                          == v for k, v in want.items()), 30.0), \
            input_status(diagnostics, 'corner_extractor')
        assert 'dropped.lost' not in input_status(diagnostics, 'corner_extractor')
        assert said == ['Dropping scan: 200000 beams, more than max_beams 20000',
                        'Dropping scan: LaserScan: stamp 0 ns is not a time (an unset header)',
                        'LaserScan: 1 negative ranges treated as invalid (first: ranges[7]=-0.5)']
