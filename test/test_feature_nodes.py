"""corner_extractor and line_extractor nodes: bag replay through DDS and bad input."""

from dataclasses import replace
import math
from pathlib import Path
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
from landmark_nav.bag import BagReader
from landmark_nav.conversions import make_scan, scan_to_data
from landmark_nav.feature_msgs import feature_cloud_to_arrays
from landmark_nav.laser.corners import CornerParams, detect_corners
from landmark_nav.laser.segmentation import segment_scan
from landmark_nav.nodes.common import ParameterError
from landmark_nav.nodes.corner_extractor import CornerExtractor
from landmark_nav.testing import declared_parameters, parameter_file, RosHarness
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from sensor_msgs.msg import LaserScan, PointCloud2

REPO = Path(__file__).resolve().parents[1]
OFFICE = REPO / 'bags' / 'office'
N_SCANS = 150  # the first 15 s of the office bag


def first_scans(n=N_SCANS):
    with BagReader(OFFICE) as reader:
        out = []
        for _, _, msg in reader.decoded(['/scan']):
            out.append(msg)
            if len(out) == n:
                return out
    return out


def play_lockstep(ros, publisher, messages, outputs, timeout=10.0):
    """Publish one message at a time and wait for the node's output to it."""
    assert ros.wait_for_subscribers([publisher])
    for i, msg in enumerate(messages, 1):
        publisher.publish(msg)
        assert ros.wait_until(lambda: len(outputs) >= i, timeout), f'no output for input {i}'


@pytest.mark.dds
def test_corner_extractor_replays_the_office_bag():
    scans = first_scans()
    with RosHarness() as ros:
        node = ros.add_node(CornerExtractor(context=ros.context))
        poses = ros.collect('corners', PoseArray)
        clouds = ros.collect('corners/features', PointCloud2)
        pub = ros._helper.create_publisher(LaserScan, 'scan', 10)
        play_lockstep(ros, pub, scans, poses)
        assert ros.wait_until(lambda: len(clouds) == len(scans), 5)
        params = node.params
    assert len(poses) == len(scans)
    total = 0
    for scan, out, cloud in zip(scans, poses, clouds):
        assert out.header == scan.header and cloud.header == scan.header
        data = scan_to_data(scan)
        expected = detect_corners(segment_scan(data.ranges, data.angles, data.valid,
                                               data.angle_increment, 10.0, params.sigma_r, 5),
                                  params)
        got = np.array([[p.position.x, p.position.y] for p in out.poses]).reshape(-1, 2)
        want = np.array([c.position for c in expected]).reshape(-1, 2)
        np.testing.assert_allclose(got, want, atol=1e-9)
        fields = feature_cloud_to_arrays(cloud)
        np.testing.assert_allclose(fields['cov_xx'], [c.covariance[0, 0] for c in expected],
                                   rtol=1e-6)
        total += len(got)
    assert total > 0


def _bad_scans(good: LaserScan):
    d = scan_to_data(good)

    def scan(**changes):
        msg = make_scan(d.stamp_ns, d.frame_id, d.angle_min, d.angle_increment, d.ranges,
                        d.range_min, d.range_max)
        for key, value in changes.items():
            setattr(msg, key, value)
        return msg

    n = len(d.ranges)
    weird = np.array(d.ranges, dtype=float)
    weird[::7] = np.nan
    weird[1::7] = np.inf
    weird[2::7] = -np.inf
    weird[3::7] = -1.0
    return [
        ('len(ranges)', scan(ranges=[1.0] * (n - 5))),
        ('angle_increment=0.0', scan(angle_increment=0.0)),
        ('angle_increment=-0.0099', scan(angle_increment=-0.01)),  # another value: reported
        ('repeat', scan(angle_increment=0.0)),                   # same kind: throttled
        ('range_max', scan(range_max=0.05)),
        ('intensities', scan(intensities=[1.0] * 3)),
        ('empty', scan(ranges=[], angle_max=d.angle_min)),
        (None, scan(ranges=weird.astype(np.float32).tolist())),   # valid but ugly: processed
    ]


def _corner_extractor(ros):
    """Start a corner extractor; return it, its corners, /rosout and a ready scan publisher."""
    node = ros.add_node(CornerExtractor(context=ros.context))
    poses = ros.collect('corners', PoseArray)
    logs = ros.collect('/rosout', Log)
    pub = ros._helper.create_publisher(LaserScan, 'scan', 10)
    assert ros.wait_for_subscribers([pub])
    return node, poses, logs, pub


@pytest.mark.dds
def test_corner_extractor_survives_bad_input():
    good = first_scans(2)
    with RosHarness() as ros:
        node, poses, logs, pub = _corner_extractor(ros)
        expected_outputs = 0
        for needle, msg in _bad_scans(good[0]):
            before, dropped = len(logs), node.warner.count
            pub.publish(msg)
            if needle is None:
                expected_outputs += 1
                assert ros.wait_until(lambda: len(poses) == expected_outputs, 5)
            elif needle == 'repeat':
                assert ros.wait_until(lambda: node.warner.count == dropped + 1, 5)
                assert len(logs) == before, 'a repeated problem must be throttled'
            else:
                assert ros.wait_until(lambda: len(logs) > before, 5), f'no warning ({needle})'
                text = logs[-1].msg
                assert 'Dropping scan' in text and needle in text, text
        pub.publish(good[1])  # the next good scan is processed normally
        assert ros.wait_until(lambda: len(poses) == expected_outputs + 1, 5)
    assert poses[-1].header == good[1].header


@pytest.mark.dds
def test_scan_problems_are_warned_with_their_values():
    """Negative ranges were accepted silently and a 1 000 000-beam scan never answered."""
    good = first_scans(2)
    d = scan_to_data(good[0])
    negative = np.array(d.ranges)
    negative[3] = -0.5
    with RosHarness() as ros:
        node, poses, logs, pub = _corner_extractor(ros)
        pub.publish(make_scan(d.stamp_ns, d.frame_id, d.angle_min, d.angle_increment,
                              negative, d.range_min, d.range_max))
        assert ros.wait_until(lambda: len(poses) == 1, 10)
        assert ros.wait_until(lambda: any('ranges[3]=-0.5' in m.msg for m in logs), 10)
        huge = make_scan(d.stamp_ns, d.frame_id, -math.pi, 2 * math.pi / 999_999,
                         np.full(1_000_000, 5.0), d.range_min, d.range_max)
        pub.publish(huge)
        assert ros.wait_until(lambda: any('1000000 beams' in m.msg for m in logs), 30)
        pub.publish(good[1])  # the node keeps running
        assert ros.wait_until(lambda: len(poses) == 2, 10)
        assert node.stats.dropped['oversized'] == 1 and node.stats.processed_count == 2


@pytest.mark.dds
def test_scans_lost_in_a_burst_are_counted_warned_and_on_diagnostics():
    """A node slower than its input lost scans in the full queue without a word."""
    scans = first_scans(100)
    with RosHarness() as ros:
        diagnostics = ros.collect('/diagnostics', DiagnosticArray)
        node, poses, logs, pub = _corner_extractor(ros)
        pub.publish(scans[0])  # the first message of a publisher starts its sequence
        assert ros.wait_until(lambda: len(poses) == 1, 10)
        for msg in scans[1:-1]:
            pub.publish(msg)
        time.sleep(1.0)
        pub.publish(scans[-1])  # reveals a loss at the end of the burst
        assert ros.wait_until(lambda: poses and poses[-1].header == scans[-1].header, 30)
        stats = node.stats
        assert stats.processed_count == len(poses)
        assert stats.dropped['lost'] == len(scans) - len(poses) > 0
        assert ros.wait_until(lambda: any(m.msg.startswith('Lost ') for m in logs), 10)

        def reported():
            for array in diagnostics:
                for status in array.status:
                    values = {v.key: v.value for v in status.values}
                    if (status.name == 'corner_extractor: input'
                            and values['processed'] == str(len(poses))):
                        return status, values
            return None
        assert ros.wait_until(reported, 10)
    status, values = reported()
    assert values['dropped.lost'] == str(len(scans) - len(poses))
    assert 0.0 < float(values['latency_p50_ms']) <= float(values['latency_p95_ms'])


def test_corner_extractor_rejects_bad_parameters():
    with RosHarness() as ros:
        for name, value in [('method', 'magic'), ('window', 3), ('f_min', 0.5),
                            ('sigma_r', -1.0)]:
            with pytest.raises(ParameterError, match=name.split('_')[0]):
                CornerExtractor(context=ros.context,
                                parameter_overrides=[Parameter(name, value=value)])


def test_config_file_matches_declared_parameters():
    values = parameter_file(REPO, 'corner_extractor')
    with RosHarness() as ros:
        node = CornerExtractor(context=ros.context)
        declared = declared_parameters(node)
        node.destroy_node()
    assert set(values) == set(declared)
    for name, value in values.items():
        if isinstance(value, float):
            assert declared[name] == pytest.approx(value)
        else:
            assert declared[name] == value
    assert CornerParams().f_min == pytest.approx(-0.3436)
    assert math.isclose(values['f_max'], 0.3515)


# ------------------------------------------------------------------------- line_extractor
@pytest.mark.dds
def test_line_extractor_replays_the_office_bag():
    from landmark_nav.laser.lines import extract_lines
    from landmark_nav.nodes.line_extractor import LineExtractor
    scans = first_scans()
    with RosHarness() as ros:
        node = ros.add_node(LineExtractor(context=ros.context))
        clouds = ros.collect('lines', PointCloud2)
        pub = ros._helper.create_publisher(LaserScan, 'scan', 10)
        play_lockstep(ros, pub, scans, clouds)
        params = node.params
    assert len(clouds) == len(scans)
    total = 0
    for scan, cloud in zip(scans, clouds):
        assert cloud.header == scan.header
        data = scan_to_data(scan)
        expected = extract_lines(segment_scan(data.ranges, data.angles, data.valid,
                                              data.angle_increment, 10.0, params.sigma_r, 5),
                                 params)
        fields = feature_cloud_to_arrays(cloud)
        np.testing.assert_allclose(fields['rho'], [ln.rho for ln in expected], atol=1e-5)
        np.testing.assert_allclose(fields['alpha'], [ln.alpha for ln in expected], atol=1e-5)
        np.testing.assert_allclose(fields['num_points'], [ln.num_points for ln in expected])
        total += len(expected)
    assert total > 0


@pytest.mark.dds
def test_line_extractor_estimates_the_range_noise_when_asked():
    # the office scans rounded to 5 cm: the node's lines are those of the extractor at the
    # noise and rounding the tracker measures on the scans so far (more than the stated 1 cm)
    from landmark_nav.laser.lines import extract_lines
    from landmark_nav.laser.range_noise import RangeNoiseTracker
    from landmark_nav.nodes.line_extractor import LineExtractor
    scans = []
    for msg in first_scans():
        r = np.asarray(msg.ranges, dtype=float)
        msg.ranges = np.where(np.isfinite(r), np.round(r / 0.05) * 0.05, r).astype(
            np.float32).tolist()
        scans.append(msg)
    with RosHarness() as ros:
        node = ros.add_node(LineExtractor(context=ros.context, parameter_overrides=[
            Parameter('sigma_r_from_data', value=True), Parameter('sigma_r_scans', value=3)]))
        clouds = ros.collect('lines', PointCloud2)
        pub = ros._helper.create_publisher(LaserScan, 'scan', 10)
        play_lockstep(ros, pub, scans, clouds)
        params = node.params
    assert len(clouds) == len(scans) and params.sigma_r == 0.01
    tracker = RangeNoiseTracker(3, stated=params.sigma_r)
    for scan, cloud in zip(scans, clouds):
        data = scan_to_data(scan)
        noise = tracker.add(data.ranges, data.angles, data.valid)
        sigma = noise.sigma_r
        assert sigma > 0.014  # at least the 5 cm step's q / sqrt(12)
        assert noise.step == 0.05  # and the rounding, for the gates
        at = replace(params, sigma_r=sigma, range_step=noise.step,
                     range_step_share=noise.step_share)
        expected = extract_lines(segment_scan(data.ranges, data.angles, data.valid,
                                              data.angle_increment, 10.0, sigma, 5), at)
        fields = feature_cloud_to_arrays(cloud)
        np.testing.assert_allclose(fields['rho'], [ln.rho for ln in expected], atol=1e-5)
        np.testing.assert_allclose(fields['num_points'], [ln.num_points for ln in expected])


@pytest.mark.dds
def test_line_extractor_survives_bad_input():
    from landmark_nav.nodes.line_extractor import LineExtractor
    good = first_scans(2)
    with RosHarness() as ros:
        node = ros.add_node(LineExtractor(context=ros.context))
        clouds = ros.collect('lines', PointCloud2)
        logs = ros.collect('/rosout', Log)
        pub = ros._helper.create_publisher(LaserScan, 'scan', 10)
        assert ros.wait_for_subscribers([pub])
        outputs = 0
        for needle, msg in _bad_scans(good[0]):
            before, dropped = len(logs), node.warner.count
            pub.publish(msg)
            if needle is None:
                outputs += 1
                assert ros.wait_until(lambda: len(clouds) == outputs, 5)
            elif needle == 'repeat':
                assert ros.wait_until(lambda: node.warner.count == dropped + 1, 5)
            else:
                assert ros.wait_until(lambda: len(logs) > before, 5), f'no warning ({needle})'
                assert needle in logs[-1].msg, logs[-1].msg
        pub.publish(good[1])
        assert ros.wait_until(lambda: len(clouds) == outputs + 1, 5)


def test_line_extractor_parameters_and_config():
    from landmark_nav.nodes.line_extractor import LineExtractor
    with RosHarness() as ros:
        for name, value in [('method', 'hough'), ('min_points', 1), ('rmse_min', 0.5)]:
            with pytest.raises(ParameterError, match=name.split('_')[0]):
                LineExtractor(context=ros.context,
                              parameter_overrides=[Parameter(name, value=value)])
        node = LineExtractor(context=ros.context)
        declared = declared_parameters(node)
        node.destroy_node()
    values = parameter_file(REPO, 'line_extractor')
    assert set(values) == set(declared)
    for name, value in values.items():
        assert declared[name] == (pytest.approx(value) if isinstance(value, float) else value)
