"""Tests of the camera scenarios (landmark_views, landmark_shuttle) and their bag recording."""

from dataclasses import replace
import math

from landmark_nav.bag import BagReader
from landmark_nav.conversions import camera_info_to_model, image_to_array
from landmark_nav.sim.camera import Photometry
from landmark_nav.sim.camera_record import record_camera_scenario
from landmark_nav.sim.camera_scenarios import (CameraFrame, iter_landmark_shuttle,
                                               iter_landmark_views, landmark_view,
                                               oracle_localizer, robot_pose_from_landmark,
                                               sample_spec, ShuttleArrival, ShuttleConfig,
                                               ShuttleSample, ViewOptions)
from landmark_nav.sim.record import load_ground_truth
import numpy as np
import pytest
from scipy.spatial.transform import Rotation


def test_landmark_views_cover_the_requested_ranges():
    frames = list(iter_landmark_views(4, 40))
    dist, turns, rolls, blocks = [], [], set(), []
    for f in frames:
        assert f.image.shape == (480, 640) and f.image.dtype == np.uint8
        (lt,) = f.landmarks
        assert lt.in_view and lt.design.is_valid_code(lt.code)
        p = lt.params
        dist.append(p['distance'])
        turns.append(abs(math.degrees(p['turn'])))
        rolls.add(round(math.degrees(p['roll']) % 90.0, 6))
        assert lt.distance == pytest.approx(p['distance'])
        # turn and tilt are relative to the line of sight
        cos_va = math.cos(p['turn']) * math.cos(p['tilt'])
        assert lt.view_angle == pytest.approx(math.acos(cos_va), abs=1e-9)
        # pixels per block against the estimate f s sqrt(cos(view angle)) / d
        est = f.camera.fx * lt.design.block_size * math.sqrt(cos_va) / lt.distance
        assert 0.8 * est < lt.block_px < 1.35 * est
        blocks.append(lt.block_px)
    assert min(dist) >= 0.5 and max(dist) <= 4.0 and max(dist) - min(dist) > 2.5
    assert max(turns) <= 60.0 and max(turns) > 40.0
    assert rolls == {0.0, 22.5, 45.0}
    assert min(blocks) < 5.0 < max(blocks)  # both sides of the chapter's 5-pixel limit


def test_views_are_reproducible_alone_and_fixed_pose_repeats():
    a = list(iter_landmark_views(9, 3, start=5))
    b = landmark_view(9, 6)
    np.testing.assert_array_equal(a[1].image, b.image)
    assert a[1].stamp_ns == b.stamp_ns and a[1].index == 6
    opts = ViewOptions(distance=2.2, turn_deg=30.0, tilt_deg=0.0, roll_deg=0.0,
                       quarter_turns=False, code=156, centre_px=(319.5, 239.5),
                       photometry=Photometry(gamma=2.2, noise_sigma=2.0))
    rep = list(iter_landmark_views(1, 3, options=opts))
    for f in rep:
        lt = f.landmarks[0]
        np.testing.assert_allclose(lt.rotation, rep[0].landmarks[0].rotation, atol=1e-15)
        np.testing.assert_allclose(lt.translation, [0.0, 0.0, 2.2], atol=1e-12)
        assert math.degrees(lt.view_angle) == pytest.approx(30.0)
        assert lt.code == 156
    assert not np.array_equal(rep[0].image, rep[1].image)  # fresh noise
    # random positions: same distance and viewing angle, different poses
    opts = ViewOptions(distance=2.2, turn_deg=30.0, tilt_deg=0.0, roll_deg=0.0)
    for f in iter_landmark_views(1, 3, options=opts):
        assert f.landmarks[0].distance == pytest.approx(2.2)
        assert math.degrees(f.landmarks[0].view_angle) == pytest.approx(30.0)


def test_landmark_free_views():
    frames = list(iter_landmark_views(2, 10, options=ViewOptions(with_landmark=False)))
    assert all(f.landmarks == () for f in frames)
    kinds = {k for f in frames for k in f.distractors}
    assert {'checkerboard', 'grid', 'text', 'tiles', 'poster'} <= kinds


def test_sample_spec():
    rng = np.random.default_rng(0)
    assert sample_spec(rng, 2.5, 'x') == 2.5
    assert 1.0 <= sample_spec(rng, (1.0, 2.0), 'x') <= 2.0
    assert sample_spec(rng, [7.0], 'x') == 7.0
    for bad in ((2.0, 1.0), [], 'a', (1.0, 2.0, 3.0)):
        with pytest.raises(ValueError):
            sample_spec(rng, bad, 'x')
    with pytest.raises(ValueError):
        landmark_view(-1, 0)


def test_robot_pose_from_landmark_inverts_the_camera_pose():
    cfg = ShuttleConfig()
    rng = np.random.default_rng(5)
    for _ in range(10):
        pose = np.array([rng.uniform(1.5, 4.0), rng.uniform(-0.5, 0.5), rng.uniform(-0.4, 0.4)])
        R_wc, t_wc = cfg.camera_pose(pose)
        R_ol = R_wc.T @ cfg.landmark_rotation
        t_ol = R_wc.T @ (cfg.landmark_position - t_wc)
        got = robot_pose_from_landmark(R_ol, t_ol, cfg.landmark_rotation,
                                       cfg.landmark_position, cfg.mount)
        np.testing.assert_allclose(got, pose, atol=1e-12)


def _arrivals(events):
    return [e for e in events if isinstance(e, ShuttleArrival)]


def test_shuttle_odometry_drifts_and_fixes_bound_the_error():
    # uncalibrated odometry: the drift grows trip after trip without landmark fixes
    cfg = ShuttleConfig(trips=8, image_rate=0.0, stop_frames=1, odometry_factors=(1, 1, 1))
    raw = _arrivals(iter_landmark_shuttle(1, cfg, images=False))
    assert len(raw) == 9 and raw[0].error == 0.0
    raw_err = np.array([a.error for a in raw[1:]])
    assert raw_err[-1] > 0.3 and raw_err[-1] > 3 * raw_err[0]
    fixed = _arrivals(iter_landmark_shuttle(1, cfg, localize=oracle_localizer(cfg)))
    fixed_err = np.array([a.error for a in fixed[1:]])
    assert fixed_err.max() < 0.25 and fixed_err[-1] < 0.5 * raw_err[-1]
    for a in fixed:  # a perfect fix makes the estimate equal the truth
        np.testing.assert_allclose(a.fix, a.true_pose, atol=1e-9)
    # calibrated odometry (default): only the encoder noise is left between the fixes
    cal = ShuttleConfig(trips=8, image_rate=0.0, stop_frames=1)
    assert cal.believed_factors == (cal.robot.k1, cal.robot.k2, cal.robot.k3)
    cal_err = np.array([a.error for a in _arrivals(
        iter_landmark_shuttle(1, cal, localize=oracle_localizer(cal)))[1:]])
    assert cal_err.mean() < 0.5 * fixed_err.mean()


def test_shuttle_fixes_while_driving_steer_to_the_near_point():
    cfg = ShuttleConfig(trips=3, image_rate=0.0, stop_frames=1, fix_while_driving=True,
                        approach_image_rate=2.0)
    oracle = oracle_localizer(cfg)
    seen = []

    def localize(frame):
        seen.append(frame)
        return oracle(frame)

    events = list(iter_landmark_shuttle(1, cfg, localize=localize))
    samples = [e for e in events if isinstance(e, ShuttleSample)]
    frames = [e for e in events if isinstance(e, CameraFrame)]
    arrivals = _arrivals(events)
    assert [e.stamp_ns for e in events] == sorted(e.stamp_ns for e in events)
    assert seen == frames          # every frame, stop or approach, went to the localizer
    assert arrivals[0].approach_frames == 0
    # between two arrivals: the approach frames, then the stop frames
    approach, trip_frames = [], []
    for e in events:
        if isinstance(e, CameraFrame):
            trip_frames.append(e)
        elif isinstance(e, ShuttleArrival):
            assert len(trip_frames) == e.approach_frames + cfg.stop_frames
            approach += trip_frames[:e.approach_frames]
            trip_frames = []
    for a in arrivals[1:]:
        # one frame standing at the far point, then 2 Hz over the >= 2 m drive at 0.35 m/s
        assert a.approach_frames >= 1 + int(2.0 * 2.0 / cfg.robot.max_linear_speed)
        assert a.approach_fixes == a.approach_frames
    for f in approach:
        # taken between the far and the near point, facing the landmark
        s = max((s for s in samples if s.stamp_ns <= f.stamp_ns), key=lambda s: s.stamp_ns)
        assert cfg.far_point[0] - 0.05 <= s.true_pose[0] <= cfg.near_point[0] + 0.05
        assert abs(s.true_pose[2]) < 0.2 and f.landmarks[0].in_view
    # perfect fixes on the way in leave only the last centimetres of drift
    assert max(a.error for a in arrivals[1:]) < 0.01
    stop_only = _arrivals(iter_landmark_shuttle(1, replace(cfg, fix_while_driving=False),
                                                localize=oracle_localizer(cfg)))
    assert all(a.approach_frames == 0 for a in stop_only)
    assert max(a.error for a in arrivals[1:]) < 0.5 * max(a.error for a in stop_only[1:])
    with pytest.raises(ValueError):
        ShuttleConfig(approach_image_rate=-1.0)
    with pytest.raises(ValueError):
        ShuttleConfig(image_rate=math.nan)


def test_shuttle_stream_is_consistent():
    cfg = ShuttleConfig(trips=1, image_rate=1.0)
    events = list(iter_landmark_shuttle(2, cfg))
    stamps = [e.stamp_ns for e in events]
    assert stamps == sorted(stamps)
    samples = [e for e in events if isinstance(e, ShuttleSample)]
    frames = [e for e in events if isinstance(e, CameraFrame)]
    assert np.all(np.diff([s.stamp_ns for s in samples]) == 100_000_000)
    # the robot visits the far point (2 m from the landmark wall ... 3 m) and comes back
    xs = np.array([s.true_pose[0] for s in samples])
    assert xs.min() == pytest.approx(cfg.far_point[0], abs=0.15)
    assert xs[-1] == pytest.approx(cfg.near_point[0], abs=0.15)
    stops = [f for f in frames if f.landmarks and f.landmarks[0].in_view]
    assert len(stops) >= 2 * cfg.stop_frames
    for f in stops:
        # the truth in the frame agrees with the robot's true pose at that stamp
        s = max((s for s in samples if s.stamp_ns <= f.stamp_ns), key=lambda s: s.stamp_ns)
        lt = f.landmarks[0]
        pose = robot_pose_from_landmark(lt.rotation, lt.translation, cfg.landmark_rotation,
                                        cfg.landmark_position, cfg.mount)
        np.testing.assert_allclose(pose[:2], s.true_pose[:2], atol=1e-9)
    # turning frames are motion blurred, standing frames are not
    assert any(f.photometry.motion_blur > 1.0 for f in frames)
    assert all(f.photometry.motion_blur == 0.0 for f in stops if f.stamp_ns == stamps[0])


def test_record_landmark_views(tmp_path):
    out = tmp_path / 'views'
    summary = record_camera_scenario('landmark_views', 3, out, n_frames=3)
    assert '3 frames' in summary
    truth = load_ground_truth(out)
    assert truth['scenario'] == 'landmark_views' and len(truth['frames']) == 3
    frames = list(iter_landmark_views(3, 3))
    with BagReader(out) as bag:
        msgs = list(bag.decoded(['/camera/image_raw', '/camera/camera_info',
                                 '/ground_truth/landmarks']))
    images = [m for t, _, m in msgs if t == '/camera/image_raw']
    infos = [m for t, _, m in msgs if t == '/camera/camera_info']
    poses = [m for t, _, m in msgs if t == '/ground_truth/landmarks']
    assert len(images) == len(infos) == len(poses) == 3
    for f, img, info, arr, meta in zip(frames, images, infos, poses, truth['frames']):
        np.testing.assert_array_equal(image_to_array(img), f.image)
        assert img.encoding == 'mono8' and img.header.frame_id == 'camera_optical'
        assert camera_info_to_model(info).to_dict() == f.camera.to_dict()
        lt = f.landmarks[0]
        p = arr.poses[0]
        np.testing.assert_allclose([p.position.x, p.position.y, p.position.z], lt.translation)
        q = [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]
        np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), lt.rotation, atol=1e-9)
        assert meta['landmarks'][0]['code'] == lt.code


def test_record_landmark_shuttle(tmp_path):
    out = tmp_path / 'shuttle'
    cfg = ShuttleConfig(trips=1, image_rate=0.0, stop_frames=1)
    record_camera_scenario('landmark_shuttle', 1, out, config=cfg)
    truth = load_ground_truth(out)
    assert list(truth['landmarks']) == [156]
    assert len(truth['arrivals']) == 2
    with BagReader(out) as bag:
        counts = {name: info.count for name, info in bag.topics().items()}
    assert counts['/odom'] == counts['/ground_truth/odom'] == counts['/joint_states'] > 200
    assert counts['/camera/image_raw'] == counts['/camera/camera_info'] == 2
    with pytest.raises(ValueError):
        record_camera_scenario('landmark_bogus', 1, tmp_path / 'x')
