"""Range noise estimated from scans: local line fits and the range step."""

import math

from landmark_nav.laser.lines import LineParams
from landmark_nav.laser.range_noise import estimate_range_noise, gate_sigma, range_step, \
    RangeNoiseTracker, window_variances
import numpy as np
import pytest

PHI = np.radians(np.arange(-90.0, 90.0, 0.5))


def room(sigma, seed=0, step=None, n=20):
    """Return n scans (ranges, angles, None) of a 4 x 6 m box with noise and rounding."""
    rng = np.random.default_rng(seed)
    c, s = np.cos(PHI), np.sin(PHI)
    with np.errstate(divide='ignore'):
        d = np.minimum.reduce([np.where(c > 0, 3.0 / c, np.inf),
                               np.where(s > 0, 2.0 / s, np.inf),
                               np.where(s < 0, -2.5 / s, np.inf)])
    out = []
    for _ in range(n):
        r = d + rng.normal(0.0, sigma, d.size)
        if step:
            r = np.round(r / step) * step
        out.append((r, PHI, None))
    return out


@pytest.mark.parametrize('sigma', [0.005, 0.01, 0.03])
def test_fit_estimate_recovers_the_noise(sigma):
    est = estimate_range_noise(room(sigma))
    # 20 scans x ~350 windows: the median-of-chi2 estimate is within a few percent
    assert est.fit == pytest.approx(sigma, rel=0.08)
    assert est.step == 0.0 and est.floor == 0.0 and est.sigma_r == est.fit


def test_quantised_ranges_have_the_step_floor():
    # 2 mm noise rounded to 5 cm: the fits see mostly the rounding, and sigma_r is at least
    # the uniform rounding error's q / sqrt(12) = 1.44 cm
    est = estimate_range_noise(room(0.002, step=0.05))
    assert est.step == 0.05 and est.step_share == pytest.approx(1.0)
    assert est.floor == pytest.approx(0.05 / math.sqrt(12), rel=1e-9)
    assert est.sigma_r >= est.floor
    assert 'range step 5 cm on 100 %' in est.describe()
    assert f'line gates as for {100 * gate_sigma(est.sigma_r, 0.05):.2f} cm' in est.describe()


def test_range_step_of_cm_readings_is_not_a_coarser_grid():
    # 1 cm readings put 20 % on the 5 cm grid and 50 % on the 2 cm grid by chance
    r = np.round(np.random.default_rng(1).uniform(0.5, 20.0, 5000), 2)
    assert range_step(r)[:1] == (0.01,)
    # 87 % on the 5 cm grid (a Radish log): 5 cm, with 1 cm under it
    r[: int(0.87 * r.size)] = np.round(r[: int(0.87 * r.size)] / 0.05) * 0.05
    q, share, fine = range_step(r)
    assert (q, fine) == (0.05, 0.01)
    assert share == pytest.approx(0.87 + 0.13 * 0.2, abs=0.02)  # and 1 in 5 of the rest


def test_windows_with_invalid_or_grazing_beams_are_left_out():
    r, phi, _ = room(0.0)[0]
    n_all = window_variances(r, phi).size
    r = r.copy()
    r[100] = np.inf
    assert window_variances(r, phi).size == n_all - 7
    valid = np.ones(r.size, bool)
    valid[200] = False
    assert window_variances(r, phi, valid).size == n_all - 14
    s2 = window_variances(r, phi)
    assert np.median(s2) < 1e-20  # noise-free walls fit exactly; windows on a corner do not
    assert np.count_nonzero(s2 > 1e-6) <= 2 * 6


def test_tracker_equals_the_batch_estimate_over_its_scans():
    scans = room(0.01, seed=3, n=12)
    tracker = RangeNoiseTracker(scans=5)
    assert tracker.estimate is None
    for ranges, angles, valid in scans:
        last = tracker.add(ranges, angles, valid)
    assert last == estimate_range_noise(scans[-5:]) == tracker.estimate
    with pytest.raises(ValueError, match='scans must be >= 1'):
        RangeNoiseTracker(0)


def _carmen_metric_scans(name, n, step=None):
    from landmark_nav.evaluation.scan_metrics import MetricScan
    from landmark_nav.importers.carmen import read_carmen_scans
    from landmark_nav.testing import shared_data
    out = []
    for s in read_carmen_scans(shared_data('carmen', name)):
        r = s.ranges.astype(float)
        if step:
            r = np.where(np.isfinite(r), np.round(r / step) * step, r)
        out.append(MetricScan(r, s.angles, np.isfinite(r) & (r > 0), np.isposinf(r), 1e-3,
                              40.0, s.pose))
        if len(out) == n:
            return out
    return out


@pytest.mark.slow
def test_quantised_real_log_keeps_its_walls_with_the_estimate():
    # belgioioso (1 cm readings, 0.5 deg), 120 scans, and the same rounded to 5 cm: with
    # sigma_r estimated, coverage f and line repeatability stay within 0.05 of the
    # unquantised log's (measured 0.669 / 0.858 -> 0.646 / 0.852); at the fixed 1 cm the
    # rounded walls break up (f 0.662 -> 0.604)
    from landmark_nav.evaluation.scan_metrics import evaluate_scans

    def figures(step, sigma):
        res = evaluate_scans(_carmen_metric_scans('belgioioso-corrected.log.gz', 120, step),
                             sigma_r=0.01, extractor_sigma_r=sigma,
                             line_methods=('split_merge',), corner_methods=('minus_cosine',))
        lines = res['lines']['split_merge']
        return res['extractor_sigma_r'], lines['f'], lines['line_repeatability']

    sigma, f, rep = figures(None, 'auto')
    sigma_q, f_q, rep_q = figures(0.05, 'auto')
    assert sigma_q > 0.05 / math.sqrt(12) and sigma_q > sigma
    assert abs(f_q - f) <= 0.05 and abs(rep_q - rep) <= 0.05
    _, f_fixed, _ = figures(None, None)
    _, f_q_fixed, _ = figures(0.05, None)
    assert f_fixed - f_q_fixed > 0.05


@pytest.mark.parametrize('sigma_0, step, share', [(0.01, 0.05, 1.0), (0.003, 0.05, 1.0),
                                                  (0.01, 0.05, 0.8), (0.0, 0.05, 1.0)])
def test_gate_sigma_holds_the_rounded_errors_tail(sigma_0, step, share):
    # 2e6 draws of the error of a reading rounded to `step` (a share of them) on sensor noise
    # sigma_0: 3 gate sigmas hold all but 2 Q(3) = 0.270 % of them (binomial sd 0.004 %), and
    # 4 of the k = 4 gate std (the split tolerance) all but 2 Q(4) = 0.0063 % (sd 0.0006 %)
    rng = np.random.default_rng(0)
    n = 2_000_000
    rounded = np.where(rng.random(n) < share, rng.uniform(-step / 2, step / 2, n), 0.0)
    e = rng.normal(0.0, sigma_0, n) + rounded
    sigma_r = math.sqrt(sigma_0 ** 2 + share * step ** 2 / 12.0)
    g = gate_sigma(sigma_r, step, share)
    assert g < sigma_r
    assert np.mean(np.abs(e) > 3.0 * g) == pytest.approx(0.0027, abs=0.00015)
    g4 = gate_sigma(sigma_r, step, share, k=4.0)
    assert g4 < g and np.mean(np.abs(e) > 4.0 * g4) == pytest.approx(6.33e-5, abs=2e-5)
    assert gate_sigma(sigma_r) == sigma_r  # not rounded: the Gaussian's own


def test_gate_sigma_of_5cm_steps_on_1cm_noise():
    # the figures the docs quote: 99.73 % of the errors within 4.6 cm, not 3 x 1.76 cm; the
    # 4-sigma tail (the split tolerance) beyond 5.7 cm, not 4 x 1.53 = 6.1 cm or 4 x 1.76 cm
    sigma_r = math.sqrt(0.01 ** 2 + 0.05 ** 2 / 12)
    assert 3.0 * gate_sigma(sigma_r, 0.05) == pytest.approx(0.04585, abs=5e-5)
    assert 4.0 * gate_sigma(sigma_r, 0.05, k=4.0) == pytest.approx(0.05742, abs=5e-5)
    assert LineParams(sigma_r=sigma_r, range_step=0.05).threshold == pytest.approx(
        0.05742, abs=5e-5)
