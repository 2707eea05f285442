"""Consistency (NEES) of the sonar EKF and UKF on the simulated hallway (issue 13, item 5).

Protocol of :func:`landmark_nav.evaluation.localization.hallway_study` and
``test_loc_accuracy.py``: map ``rasterize_world(result.world, 0.1)``, calibrated odometry,
initial estimate drawn from N(truth, CHAPTER_P0) with generator seed ``1000 + seed`` and
initial covariance CHAPTER_P0; full runs (607 stamps, 20 m), the same runs
docs/sonar_localization.md's 10-seed figures and ``bags/hallway`` (seed 1) come from.

NEES (corner chapter eq. 59, :func:`landmark_nav.slam.consistency.nees`) of the pose
``[x, y, Theta]`` (d = 3, heading error wrapped) at every stamp from the first motion to
the end (596 stamps). The bound: the one-sided ``chi2_{3, 0.95} = 7.81`` (scipy's quantile,
:func:`~landmark_nav.slam.consistency.chi2_gate`); a consistent filter has about 95 % of its
steps below it. Asserted: at least 90 % of the steps on every seed, and the mean NEES in a
band around the measured means.

Measured on seeds 1-5 (mean NEES, share of steps below 7.81):

* EKF: 2.11 / 2.77 / 2.38 / 1.79 / 2.44; 96.0 / 99.2 / 96.5 / 99.5 / 98.7 %.
* UKF before its fix (no discontinuity test, no map noise): 15.2 / 16.1 / 19.4 / 14.0 /
  12.9; 45.1 / 31.5 / 37.9 / 47.0 / 43.8 % (sigma_x 0.9 cm, x error 2.6-3.3 cm RMS).
* UKF now: 1.29 / 1.95 / 3.01 / 2.16 / 2.04; 100.0 / 98.8 / 96.3 / 98.8 / 99.5 %.

Run time: the whole file takes 9 s of CPU time (22 s wall on a loaded 2-core machine): one
simulation per seed and one run per seed and filter, shared by the session fixture
``hallway_localization`` (conftest; test_loc_accuracy.py checks the same runs of seeds 1-3),
so no shortened runs are needed.
"""

import dataclasses
import math

from landmark_nav.localization import ekf, ukf
from landmark_nav.localization.grid import GridMap
from landmark_nav.localization.params import LocalizationParams
from landmark_nav.localization.sonar_model import predict_ranges
from landmark_nav.sim.sonar import SONAR_MOUNTS
from landmark_nav.slam.consistency import chi2_gate, nees, share_inside
import numpy as np
import pytest

SEEDS = (1, 2, 3, 4, 5)
#: Share of the steps below chi2_{3, 0.95} required on every seed.
MIN_INSIDE = 0.90
#: Band of the mean NEES per seed: the measured means (EKF 1.79-2.77, UKF 1.29-3.01)
#: widened by 0.5 on each side.
MEAN_BAND = {'ekf': (1.3, 3.3), 'ukf': (0.8, 3.5)}


def pose_nees(trajectory, truth, covariances):
    """NEES (eq. 59) of every row, d = 3."""
    return np.array([nees(t, x, p) for t, x, p in zip(truth, trajectory, covariances)])


def test_bound_is_the_chi2_quantile():
    assert chi2_gate(3, 0.95) == pytest.approx(7.8147, abs=1e-4)


@pytest.mark.slow
@pytest.mark.parametrize('filt', ['ekf', 'ukf'])
@pytest.mark.parametrize('seed', SEEDS)
def test_nees_inside_95_bound(hallway_localization, seed, filt):
    entry = hallway_localization(seed)  # the runs of test_loc_accuracy.py (conftest)
    (trajectory, covariances), inp, i0 = entry[filt], entry['inp'], entry['i0']
    assert i0 >= 10 and inp.truth.shape[0] - i0 >= 590  # the full run
    values = pose_nees(trajectory[i0:], inp.truth[i0:], covariances[i0:])
    inside = share_inside(values, 3, 0.95, two_sided=False)
    lo, hi = MEAN_BAND[filt]
    assert inside >= MIN_INSIDE, (filt, seed, inside, values.mean())
    assert lo <= values.mean() <= hi, (filt, seed, inside, values.mean())


# ---------------------------------------------------------------------- the UKF's fix
def niche_grid():
    """Wall y = 1.05 for x < 2.0, a 0.5 m deep niche beyond; wall y = -1.05 everywhere."""
    occ = np.zeros((40, 60), dtype=int)  # 4 m x 6 m from (0, -2)
    occ[30, :20] = 100  # y = 1.05, x < 2.0
    occ[35, 20:] = 100  # niche back wall y = 1.55
    occ[9, :] = 100  # y = -1.05
    return GridMap(occupancy=occ, resolution=0.1, origin=(0.0, -2.0, 0.0))


def test_ukf_skips_a_reading_that_straddles_an_edge():
    """A lobe straddling a wall end is not used by the UKF, as by the EKF.

    Sonar 0 (90 deg) sees the wall 7 cm before its end, its lobe straddling the niche: the
    EKF's discontinuity test rejects it, and so must the UKF (its state sigma points,
    +-2.4 cm in x, all see the same wall, so the chapter's UKF used it).
    """
    g = niche_grid()
    params = LocalizationParams()
    mounts = SONAR_MOUNTS
    x = np.array([1.86, 0.0, 0.0])
    p = np.diag([0.01 ** 2, 0.01 ** 2, math.radians(0.5) ** 2])
    z = predict_ranges(g, x, mounts, **{'cone_rays': params.cone_rays,
                                        'specular_angle': params.specular_angle})[0]
    z = np.where(np.isnan(z), np.inf, z)
    _, _, usable = ekf.measurement_prediction(g, x, mounts, params)
    assert not usable[0] and usable[7]  # 7: -90 deg, head-on to the wall y = -1.05
    zs = predict_ranges(g, ukf.state_sigma_points(x, p, params), mounts[[0]],
                        cone_rays=params.cone_rays, specular_angle=params.specular_angle)
    assert np.ptp(zs) < 0.06  # y spread only: the sigma points do not see the edge
    _, _, info = ukf.measurement_update(x, p, None, z, g, mounts, params)
    _, _, info_e = ekf.measurement_update(x, p, z, g, mounts, params)
    assert not info['accepted'][0] and info['accepted'][7]
    assert np.array_equal(info['accepted'], info_e['accepted'])


def test_ukf_map_noise_from_the_grid_resolution():
    g = niche_grid()
    assert ukf.map_noise_std(g) == pytest.approx(0.1 / math.sqrt(12.0))
    assert ukf.map_noise_std(g, LocalizationParams(map_sigma=0.02)) == 0.02
    with pytest.raises(ValueError):
        LocalizationParams(map_sigma=-0.01)
    # A head-on reading of the wall y = -1.05 from a pose offset in x and y: the map noise
    # enters P_z (a shift of the wall in y changes the range 1:1), so the update trusts the
    # reading less: a larger posterior y variance, the same x variance (no x information).
    x = np.array([1.0, 0.05, 0.0])
    p = np.diag([0.03 ** 2, 0.03 ** 2, math.radians(1.0) ** 2])
    z = np.full(16, np.inf)
    z[7] = 0.95
    off = LocalizationParams(map_sigma=0.0)
    _, p_on, info_on = ukf.measurement_update(x, p, None, z, g, SONAR_MOUNTS)
    _, p_off, info_off = ukf.measurement_update(x, p, None, z, g, SONAR_MOUNTS, off)
    assert info_on['accepted'][7] and info_off['accepted'][7]
    r = LocalizationParams().measurement_variance(np.array([0.95]))[0]
    sigma_m2 = ukf.map_noise_std(g) ** 2
    # One linear reading z = -y + c: posterior var_y = P R' / (P + R'), R' = R (+ sigma_m^2).
    assert p_off[1, 1] == pytest.approx(p[1, 1] * r / (p[1, 1] + r), rel=0.02)
    assert p_on[1, 1] == pytest.approx(p[1, 1] * (r + sigma_m2) / (p[1, 1] + r + sigma_m2),
                                       rel=0.02)
    assert p_on[0, 0] == pytest.approx(p[0, 0], rel=1e-6)


def test_ukf_without_map_noise_uses_the_propagated_sigma_points():
    """``map_sigma = 0``: the chapter's UKF, eq. 49 on the sigma points of the time update."""
    g = niche_grid()
    params = dataclasses.replace(LocalizationParams(), map_sigma=0.0)
    x = np.array([1.0, 0.0, 0.0])
    p = np.diag([0.02 ** 2, 0.02 ** 2, math.radians(1.0) ** 2])
    xp, pp, sig = ukf.time_update(x, p, np.array([0.035, 0.0]), params)
    z = predict_ranges(g, np.array([1.04, 0.01, 0.0]), SONAR_MOUNTS, cone_rays=7,
                       specular_angle=params.specular_angle)[0]
    z = np.where(np.isnan(z), np.inf, z)
    a = ukf.measurement_update(xp, pp, sig, z, g, SONAR_MOUNTS, params)
    b = ukf.measurement_update(xp, pp, None, z, g, SONAR_MOUNTS, params)
    assert a[2]['accepted'].any()
    assert not np.allclose(a[0], b[0], rtol=0.0, atol=1e-9)  # different sigma points
    c = ukf.measurement_update(xp, pp, sig, z, g, SONAR_MOUNTS)  # map noise: redrawn
    d = ukf.measurement_update(xp, pp, None, z, g, SONAR_MOUNTS)
    assert np.array_equal(c[0], d[0]) and np.array_equal(c[1], d[1])
