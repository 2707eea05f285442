"""Tests for landmark_nav.localization.sonar_model: eqs. 10-11, 21-23, prediction, mapping."""

import math

from landmark_nav.geometry import compose
from landmark_nav.localization.grid import GridMap, rasterize_world
from landmark_nav.localization.sonar_model import (angular_modulation, build_sonar_map,
                                                   MAX_PREDICT, predict_ranges,
                                                   radial_modulation, RHO_V,
                                                   sonar_global_poses, THETA0)
from landmark_nav.sim import run_scenario
from landmark_nav.sim.scenarios import hallway_world
from landmark_nav.sim.sonar import SONAR_MOUNTS, SonarConfig, SonarRing
import numpy as np
import pytest


def test_angular_modulation_eq10():
    assert THETA0 == pytest.approx(math.radians(12.5))
    t = np.radians([0.0, 6.25, -6.25, 12.5, 12.6, -30.0])
    assert angular_modulation(t) == pytest.approx([1.0, 0.75, 0.75, 0.0, 0.0, 0.0])
    assert angular_modulation(math.radians(5.0)) == pytest.approx(1.0 - (5.0 / 12.5) ** 2)


def test_radial_modulation_eq11():
    assert RHO_V == 1.2
    assert radial_modulation(1.2) == pytest.approx(0.5)
    rho = np.array([0.0, 0.5, 2.0, 3.0])
    expect = 1.0 - (1.0 + np.tanh(2.0 * (rho - 1.2))) / 2.0
    assert radial_modulation(rho) == pytest.approx(expect)
    assert radial_modulation(0.0) == pytest.approx(0.9918, abs=1e-4)
    assert np.all(np.diff(radial_modulation(np.linspace(0, 5, 50))) < 0)


def test_sonar_global_poses_eqs21_23():
    poses = np.array([[1.0, 2.0, 0.3], [-0.5, 0.1, -2.9]])
    s = sonar_global_poses(poses, SONAR_MOUNTS)
    assert s.shape == (2, 16, 3)
    ref = compose(poses[:, None, :], SONAR_MOUNTS[None, :, :])
    assert s[..., :2] == pytest.approx(ref[..., :2])
    assert s[..., 2] == pytest.approx(poses[:, None, 2] + SONAR_MOUNTS[None, :, 2])


def test_predict_ranges_centre_beam_and_discard():
    occ = np.zeros((40, 40), dtype=int)
    occ[:, 30] = 100  # wall with centre line x = 3.05
    g = GridMap(occupancy=occ, resolution=0.1)
    mounts = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, math.pi / 2], [0.1, 0.0, 0.0]])
    poses = np.array([[1.05, 2.0, 0.0], [0.0, 2.0, 0.0]])
    r = predict_ranges(g, poses, mounts)
    assert r.shape == (2, 3)
    assert r[0, 0] == pytest.approx(2.0) and r[0, 2] == pytest.approx(1.9)
    assert np.isnan(r[0, 1])  # leaves the map (unknown)
    assert np.isnan(r[1, 0])  # 3.05 m > MAX_PREDICT: discarded
    assert r[1, 2] == pytest.approx(2.95)
    assert MAX_PREDICT == 3.0


def test_predict_ranges_cone_and_specular():
    occ = np.zeros((60, 60), dtype=int)
    occ[40, :] = 100  # horizontal wall, centre line y = 4.05
    g = GridMap(occupancy=occ, resolution=0.1)
    pose = np.array([[3.0, 3.05, 0.0]])
    # A sonar looking 50 deg off the wall normal: the nearest echo in a 12.5 deg cone comes
    # from the cone edge at 37.5 deg incidence.
    m = np.array([[0.0, 0.0, math.radians(40.0)]])
    centre = predict_ranges(g, pose, m)[0, 0]
    assert centre == pytest.approx(1.0 / math.sin(math.radians(40.0)))
    cone = predict_ranges(g, pose, m, cone_rays=11)[0, 0]
    assert cone == pytest.approx(1.0 / math.cos(math.radians(37.5)))
    assert predict_ranges(g, pose, m, cone_rays=11,
                          specular_angle=math.radians(40.0))[0, 0] == pytest.approx(cone)
    # All rays beyond the specular angle: no echo predicted.
    assert np.isnan(predict_ranges(g, pose, m, cone_rays=11,
                                   specular_angle=math.radians(30.0))[0, 0])


def test_predict_matches_simulated_sonar_on_hallway():
    """Noise-free simulated readings vs the cone + specular prediction at the true poses."""
    res = run_scenario('hallway', 1)
    g = rasterize_world(res.world, 0.1)
    poses = res.trajectory.poses[::10]
    cfg = SonarConfig()
    true_r = SonarRing(res.world, cfg).true_ranges(poses)
    pred = predict_ranges(g, poses, SONAR_MOUNTS, cone_rays=7,
                          specular_angle=cfg.specular_angle)
    both = np.isfinite(pred) & np.isfinite(true_r)
    err = np.abs(pred[both] - true_r[both])
    assert both.sum() > 0.5 * np.isfinite(true_r[:, [0, 1, 6, 7, 8, 9, 14, 15]]).sum()
    assert np.median(err) < 0.01
    assert np.mean(err < 0.1) > 0.95


def test_build_sonar_map_recovers_hallway_walls():
    res = run_scenario('hallway', 3)
    from landmark_nav.evaluation.localization import LocalizationInput
    inp = LocalizationInput.from_result(res)
    m = build_sonar_map(inp.truth, inp.sonar_ranges, inp.mounts, 0.1)
    assert m.occupancy.dtype == np.int8
    assert set(np.unique(m.occupancy)) <= {-1, 0, 100}
    world = hallway_world()
    centres = m.cell_centers(*np.nonzero(m.occupied))
    # Occupied cells lie on the walls (within the arc width and one cell).
    clear = world.clearance(centres)
    assert np.median(clear) < 0.08
    assert np.mean(clear < 0.2) > 0.9
    # The hallway interior along the path is free.
    along = np.stack([np.linspace(1.0, 20.0, 40), np.full(40, 0.6)], axis=1)
    g = m.world_to_map(along).astype(int)
    assert np.mean(m.occupancy[g[:, 1], g[:, 0]] == 0) > 0.9
    # Readings outside the usable range are ignored: an empty input gives an unknown map.
    empty = build_sonar_map(inp.truth[:5], np.full((5, 16), np.inf), inp.mounts,
                            bounds=(0.0, -2.0, 3.0, 2.0))
    assert empty.unknown.all()
