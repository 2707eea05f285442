"""Tests of the per-frame corridor pipeline on rendered corridors (sim.corridor)."""

import math

from landmark_nav.corridor.frame import CorridorLost, FrameParams, measure_frame
from landmark_nav.corridor.lateral import CorridorModel
from landmark_nav.sim.camera import CameraSimulator, Photometry
from landmark_nav.sim.corridor import (camera_pose, corridor_scene, corridor_view,
                                       CorridorConfig, default_corridor_camera)
from landmark_nav.vision.camera import OPTICAL_FROM_BODY
import numpy as np
import pytest

CFG = CorridorConfig()
CAM = default_corridor_camera()
MOUNT = [0.1, 0.0, 1.1, 0.0, math.radians(5.0), 0.0]
MODEL = CorridorModel(CFG.width, CFG.height)


@pytest.fixture(scope='module')
def scene():
    """Return the planes and a simulator (built once)."""
    return corridor_scene(CFG, 1), CameraSimulator(CAM)


def test_camera_pose_follows_robot_and_mount():
    R, t = camera_pose((3.0, 0.2, math.radians(90.0)), MOUNT)
    np.testing.assert_allclose(t, [3.0, 0.3, 1.1], atol=1e-12)
    forward = R @ [0.0, 0.0, 1.0]                # optical axis in the world
    np.testing.assert_allclose(forward, [0.0, math.cos(math.radians(5.0)),
                                         -math.sin(math.radians(5.0))], atol=1e-12)
    up = R @ OPTICAL_FROM_BODY @ [0.0, 0.0, 1.0]  # camera_link z (up) in the world
    assert up[2] > 0.99


def test_rendered_frames_give_heading_and_lateral_position(scene):
    planes, sim = scene
    rng = np.random.default_rng(0)
    errs_h, errs_y = [], []
    for _ in range(12):
        robot = (rng.uniform(2, 20), rng.uniform(-0.5, 0.5), math.radians(rng.uniform(-15, 15)))
        view = corridor_view(sim, planes, robot, MOUNT,
                             Photometry(noise_sigma=2.0, defocus_sigma=0.5), rng)
        m = measure_frame(view.image, CAM, MODEL, MOUNT)
        errs_h.append(abs(m.heading - robot[2]))
        errs_y.append(abs(m.y - robot[1]))
        assert m.covariance.shape == (2, 2)
        assert m.heading_std >= math.radians(0.3) and m.y_std >= 0.02     # the floors
    # measured over 30 frames: median 0.016 deg and 0.8 mm, worst 0.04 deg and 3 mm
    assert math.degrees(np.median(errs_h)) < 0.05
    assert math.degrees(max(errs_h)) < 0.15
    assert np.median(errs_y) < 0.003
    assert max(errs_y) < 0.01


def test_lost_frames_say_why(scene):
    planes, sim = scene
    with pytest.raises(CorridorLost, match='image lines'):
        measure_frame(np.zeros((480, 640), np.uint8), CAM, MODEL, MOUNT)
    with pytest.raises(CorridorLost, match='image lines'):
        measure_frame(np.full((480, 640), 255, np.uint8), CAM, MODEL, MOUNT)
    # facing a wall: too few lines along any direction near the optical axis
    for deg in (50.0, 70.0, 80.0):
        view = corridor_view(sim, planes, (10.0, 0.0, math.radians(deg)), MOUNT)
        with pytest.raises(CorridorLost, match='corridor lines|off the optical axis'):
            measure_frame(view.image, CAM, MODEL, MOUNT)
    with pytest.raises(ValueError, match='differs from the camera'):
        measure_frame(np.zeros((240, 320), np.uint8), CAM, MODEL, MOUNT)


def test_reference_line_inputs_work_too(scene):
    planes, sim = scene
    view = corridor_view(sim, planes, (8.0, 0.2, math.radians(-6.0)), MOUNT)
    for method in ('hough_p', 'lsd'):
        m = measure_frame(view.image, CAM, MODEL, MOUNT, params=FrameParams(line_method=method))
        assert abs(math.degrees(m.heading) + 6.0) < 0.2
        assert abs(m.y - 0.2) < 0.02


@pytest.mark.slow
def test_fused_run_along_the_rendered_corridor():
    from landmark_nav.evaluation.corridor_run import run_corridor, RunConfig
    s = run_corridor(RunConfig(), seed=0).summary()
    # measured: nothing lost; the gate rejected 1 frame 2.5 m before the open end of the
    # corridor, where the VP came out 22 deg off
    assert s['frames'] == 270 and s['lost'] == 0 and s['rejected'] <= 3
    # measured (seed 0): fused lateral RMS 0.9 mm, heading RMS 0.058 deg (start 10 cm and
    # 3 deg off; every frame confident, also the last ones with only four corridor edges);
    # single frames: medians 0.8 mm and 0.017 deg
    assert s['fused_lateral_rms'] < 0.0015
    assert s['fused_heading_rms_deg'] < 0.1
    assert s['single_lateral_median'] < 0.0015
    assert s['single_heading_median_deg'] < 0.03


@pytest.mark.slow
def test_hard_cases():
    from landmark_nav.evaluation.corridor_run import hard_cases
    res = hard_cases(frames=20, seed=3)
    assert set(res) == {'occluded', 'near_wall', 'one_wall', 'lighting'}
    for case, r in res.items():
        # measured: nothing lost; heading medians 0.018-0.082 deg (worst frame 0.18),
        # lateral medians 1.0-4.2 mm (worst frame 1.5 cm); the issue: within 2x of 0.5 deg
        # and 3 cm
        assert r['lost'] <= 1, case
        assert r['heading_median_deg'] < 0.15, case
        assert r['lateral_median'] < 0.008, case
        assert r['lateral_max'] < 0.03, case


@pytest.mark.slow
def test_closed_loop_there_and_back():
    from landmark_nav.evaluation.corridor_run import run_corridor, RunConfig
    r = run_corridor(RunConfig(distance=8.0, lengths=2), seed=1)
    s = r.summary()
    # turned at the end and came back facing the other way
    assert np.any(np.abs(r.truth[:, 2]) > 3.0) and abs(r.truth[-1, 0] - r.truth[0, 0]) < 1.0
    # measured: within 2.0 cm of the centre after the first 2 m, fused lateral 1.2 mm RMS
    # (the benchmark's 3 x 27 m: 1.9 cm, 1.0 mm)
    assert s['max_abs_lateral_after_2m'] < 0.035
    assert s['fused_lateral_rms'] < 0.002
    assert s['rejected'] <= 4
