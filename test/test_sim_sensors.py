"""Tests for landmark_nav.sim.laser and .sonar: geometry, noise statistics, REP 117."""

import dataclasses
import math

from landmark_nav.sim.laser import Laser, LaserConfig
from landmark_nav.sim.robot import make_trajectory, RobotParams
from landmark_nav.sim.sonar import SONAR_MOUNTS, SonarConfig, SonarRing
from landmark_nav.sim.world import World
import numpy as np
import pytest

T0 = 1_700_000_000_000_000_000
QUIET = {'sigma_range': 0.0, 'sigma_angle': 0.0, 'p_dropout': 0.0, 'p_spurious': 0.0,
         'keep_true_ranges': True}


def wall_world(x: float = 3.0) -> World:
    w = World('wall')
    w.add_segment(x, -100.0, x, 100.0)
    return w


def still(n: int = 60, pose=(0.0, 0.0, 0.0)):
    return make_trajectory(T0, pose, np.zeros((n, 2)), RobotParams())


def test_laser_defaults_lms200():
    cfg = LaserConfig()
    assert cfg.num_beams == 361
    assert cfg.angle_increment == pytest.approx(math.radians(0.5))
    assert (cfg.range_max, cfg.range_min, cfg.rate_hz) == (8.0, 0.1, 10.0)
    assert cfg.time_increment == pytest.approx(1.0 / 75.0 / 720.0)
    assert LaserConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError):
        LaserConfig(range_min=9.0)


def test_laser_noise_free_geometry():
    laser = Laser(wall_world(3.0), LaserConfig(**QUIET))
    scan = laser.scan(still(), T0, np.random.default_rng(0))
    phi = scan.angle_min + scan.angle_increment * np.arange(361)
    expected = np.where(np.abs(3.0 / np.cos(phi)) <= 8.0, 3.0 / np.cos(phi), np.inf)
    expected[np.cos(phi) <= 1e-12] = np.inf
    assert scan.ranges.dtype == np.float32 and scan.ranges.shape == (361,)
    assert scan.angle_max == pytest.approx(math.pi / 2.0)
    finite = np.isfinite(expected)
    assert scan.ranges[finite] == pytest.approx(expected[finite].astype(np.float32), rel=1e-6)
    assert np.all(np.isposinf(scan.ranges[~finite]))  # REP 117: no return -> +inf
    assert np.array_equal(np.isfinite(scan.true_ranges), finite)
    # Mounting offset and yaw: a laser 0.2 m forward looking left sees the wall at 90 deg.
    cfg = LaserConfig(mount=(0.2, 0.0, math.pi / 2.0), **QUIET)
    s2 = Laser(wall_world(3.0), cfg).scan(still(), T0, np.random.default_rng(0))
    assert s2.ranges[0] == pytest.approx(2.8, rel=1e-6)  # beam 0 at -90 deg -> +x


def test_laser_range_noise_and_dropouts():
    cfg = LaserConfig(sigma_range=0.01, sigma_angle=0.0, p_dropout=0.05, p_spurious=0.0,
                      keep_true_ranges=True, angle_min=-0.5, angle_max=0.5)
    laser = Laser(wall_world(3.0), cfg)
    rng = np.random.default_rng(1)
    scans = [laser.scan(still(), T0 + k * 100_000_000, rng) for k in range(60)]
    meas = np.concatenate([s.ranges for s in scans]).astype(float)
    true = np.concatenate([s.true_ranges for s in scans])
    drop = np.isposinf(meas)
    assert drop.mean() == pytest.approx(0.05, rel=0.1)
    err = meas[~drop] - true[~drop]
    assert abs(err.mean()) < 1e-3
    assert err.std() == pytest.approx(0.01, rel=0.1)


def test_laser_angle_noise_and_spurious():
    cfg = LaserConfig(sigma_range=0.0, sigma_angle=0.01, p_dropout=0.0, p_spurious=0.05,
                      keep_true_ranges=True, angle_min=math.radians(40.0),
                      angle_max=math.radians(50.0), angle_increment=math.radians(0.25))
    laser = Laser(wall_world(3.0), cfg)
    rng = np.random.default_rng(2)
    scans = [laser.scan(still(300), T0 + k * 100_000_000, rng) for k in range(250)]
    meas = np.concatenate([s.ranges for s in scans]).astype(float)
    true = np.concatenate([s.true_ranges for s in scans])
    phi = np.tile(scans[0].angle_min + scans[0].angle_increment * np.arange(41), 250)
    spur = meas < true - 0.3
    assert spur.mean() == pytest.approx(0.05, rel=0.15)
    assert np.all(meas[spur] >= cfg.range_min)
    # eq. 6: a bearing error eps_phi moves the range by D tan(phi) eps_phi at a flat wall.
    ok = ~spur
    z = (meas[ok] - true[ok]) / (true[ok] * np.tan(phi[ok]) * 0.01)
    assert z.std() == pytest.approx(1.0, rel=0.1)


def test_laser_motion_during_sweep_and_stamps():
    p = RobotParams()
    v_wheel = 0.3 / p.wheel_radius
    traj = make_trajectory(T0, (0.0, 0.0, 0.0), np.full((30, 2), v_wheel), p)
    cfg = LaserConfig(time_increment=2e-4, **QUIET)
    laser = Laser(wall_world(6.0), cfg)
    stamp = T0 + 1_000_000_000
    scan = laser.scan(traj, stamp, np.random.default_rng(0))
    t_mid = 1.0 + 180 * 2e-4
    x_mid = traj.pose_at_seconds(t_mid)
    phi = scan.angle_min + 180 * scan.angle_increment
    expected = (6.0 - x_mid[0]) / math.cos(x_mid[2] + phi)
    assert scan.true_ranges[180] == pytest.approx(expected, abs=1e-9)
    x_start = traj.pose_at_seconds(1.0)
    assert abs((6.0 - x_start[0]) - expected) > 0.01  # the robot moved during the sweep
    stamps = laser.scan_stamps(traj)
    assert stamps[0] == T0 + 50_000_000 and np.all(np.diff(stamps) == 100_000_000)
    assert stamps[-1] + 360 * 2e-4 * 1e9 <= traj.end_ns


def test_laser_too_close_is_minus_inf():
    laser = Laser(wall_world(0.05), LaserConfig(**QUIET))
    scan = laser.scan(still(), T0, np.random.default_rng(0))
    assert np.isneginf(scan.ranges[180])


def test_sonar_mounts_p2dx():
    assert SONAR_MOUNTS.shape == (16, 3)
    assert SONAR_MOUNTS[3] == pytest.approx([0.166, 0.027, math.radians(10.0)])
    assert SONAR_MOUNTS[11] == pytest.approx([-0.255, -0.027, math.radians(-170.0)])
    assert not SONAR_MOUNTS.flags.writeable
    cfg = SonarConfig()
    assert cfg.field_of_view == pytest.approx(math.radians(25.0))
    assert (cfg.min_range, cfg.max_range, cfg.num_sonars) == (0.1, 5.0, 16)
    assert SonarConfig.from_dict(cfg.to_dict()) == cfg


def single(heading: float = 0.0, **kw) -> SonarConfig:
    cfg = SonarConfig(mounts=((0.0, 0.0, heading),), sigma0=0.0, sigma1=0.0, **kw)
    return cfg


def test_sonar_wall_ahead():
    ring = SonarRing(wall_world(1.5), single())
    assert ring.true_ranges([[0.0, 0.0, 0.0]])[0, 0] == pytest.approx(1.5, abs=1e-12)
    # Pioneer ring: sonars 3 and 4 (+-10 deg) see the wall's perpendicular inside their cone.
    quiet = dataclasses.replace(SonarConfig(), sigma0=0.0, sigma1=0.0)
    ring16 = SonarRing(wall_world(2.0), quiet)
    r = ring16.true_ranges([[0.0, 0.0, 0.0]])[0]
    assert r[3] == pytest.approx(2.0 - 0.166, abs=1e-12)
    assert r[4] == pytest.approx(2.0 - 0.166, abs=1e-12)
    assert np.all(np.isposinf(r[8:16]) | (r[8:16] > 2.0))
    assert np.isposinf(r[11])  # rear sonars look away from the wall


def test_sonar_specular_miss_at_grazing_incidence():
    w = World()
    w.add_segment(0.5, 0.2, 4.0, 0.9)  # nearly parallel to the sonar axis
    ring = SonarRing(w, single())
    assert np.isposinf(ring.true_ranges([[0.0, 0.0, 0.0]])[0, 0])
    # Same wall, sonar turned to face it: echo.
    facing = SonarRing(w, single(heading=math.radians(101.3)))
    r = facing.true_ranges([[2.0, 0.0, 0.0]])[0, 0]
    assert math.isfinite(r) and r < 1.0
    # Incidence 50 deg > 40 deg specular threshold for every ray of the cone: no echo.
    w2 = World()
    w2.add_segment(2.0 - 10 * math.sin(math.radians(50)), -10 * math.cos(math.radians(50)),
                   2.0 + 10 * math.sin(math.radians(50)), 10 * math.cos(math.radians(50)))
    assert np.isposinf(SonarRing(w2, single(field_of_view=math.radians(10.0)))
                       .true_ranges([[0.0, 0.0, 0.0]])[0, 0])
    lenient = single(field_of_view=math.radians(10.0), specular_angle=math.radians(60.0))
    assert math.isfinite(SonarRing(w2, lenient).true_ranges([[0.0, 0.0, 0.0]])[0, 0])


def test_sonar_nearest_in_cone_wins():
    w = wall_world(3.0)
    w.add_circle(2.0, 0.3, 0.1)  # bearing 8.5 deg: inside the 12.5 deg half-cone
    w.add_circle(1.0, 0.5, 0.1)  # bearing 26.6 deg: outside the cone
    r = SonarRing(w, single()).true_ranges([[0.0, 0.0, 0.0]])[0, 0]
    assert math.hypot(2.0, 0.3) - 0.1 - 1e-9 <= r < 2.0
    w2 = wall_world(3.0)
    w2.add_circle(1.0, 0.5, 0.1)
    assert SonarRing(w2, single()).true_ranges([[0.0, 0.0, 0.0]])[0, 0] == \
        pytest.approx(3.0, abs=1e-12)


def test_sonar_noise_and_limits():
    cfg = SonarConfig(mounts=((0.0, 0.0, 0.0),), sigma0=0.01, sigma1=0.01)
    ring = SonarRing(wall_world(2.0), cfg)
    r = ring.readings(np.zeros((4000, 3)), np.random.default_rng(3))[:, 0]
    assert r.mean() == pytest.approx(2.0, abs=2e-3)
    assert r.std() == pytest.approx(0.03, rel=0.1)
    far = SonarRing(wall_world(6.0), cfg).readings(np.zeros((5, 3)), np.random.default_rng(0))
    assert np.all(np.isposinf(far))
    near = SonarRing(wall_world(0.05), cfg).readings(np.zeros((5, 3)), np.random.default_rng(0))
    assert np.all(np.isneginf(near))


def test_sonar_cycles_follow_trajectory_stamps():
    traj = still(20, pose=(0.0, 0.0, 0.0))
    ring = SonarRing(wall_world(2.0))
    cyc = ring.cycles(traj, np.random.default_rng(0), chunk=7)
    assert [c.stamp_ns for c in cyc] == list(traj.stamps_ns)
    assert all(c.ranges.dtype == np.float32 and c.ranges.shape == (16,) for c in cyc)
    again = ring.cycles(traj, np.random.default_rng(0), chunk=100)
    assert all(np.array_equal(a.ranges, b.ranges) for a, b in zip(cyc, again))
    assert cyc[0].field_of_view == pytest.approx(math.radians(25.0))
