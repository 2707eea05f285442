"""Trajectory metrics (landmark_nav.evaluation.trajectory) against the evo command line.

The agreement tests (a synthetic pair, the office bag, an imported Carmen log) run evo's
own ``evo_ape`` / ``evo_rpe`` (reading the TUM files, associating the stamps, aligning;
each test's runs through the tools' entry points in one child interpreter) on the same TUM
files our functions read, and compare every statistic to 1e-6 m (1e-6 deg for the RPE
rotation).
"""

import json
import math
from pathlib import Path
import subprocess
import sys

from evo.tools import file_interface
from landmark_nav.evaluation.trajectory import (ate, read_tum, rpe, STATISTICS, Trajectory,
                                                write_tum)
from landmark_nav.geometry import compose
import numpy as np
import pytest

BAG = Path(__file__).resolve().parents[1] / 'bags' / 'office'
#: our alignment -> evo_ape options (se2 = Umeyama after projection to the plane; on planar
#: trajectories evo's SE(3) Umeyama gives the same, projected afterwards).
EVO_ALIGN = {'none': [], 'se2': ['--align', '--project_to_plane', 'xy'], 'se3': ['--align'],
             'sim3': ['--align', '--correct_scale']}
# Runs each [tool, argv] of a JSON list as the evo_ape / evo_rpe scripts do (their entry
# point with that argv), one after the other in one interpreter: evo's imports are most of
# a tool's run (0.43 of 0.49 CPU-s). A failing run exits with its status.
_EVO_RUNNER = r"""
import json, sys
from evo.cli import entry_points
for tool, argv in json.load(sys.stdin):
    sys.argv = ['evo_' + tool] + argv
    getattr(entry_points, tool)()
"""


def evo_stats(runs, tmp_path: Path) -> list:
    """Run evo's command line tools; return each run's statistics (from --save_results).

    ``runs``: ``[(tool, reference, estimate, options)]``, ``tool`` ``'ape'`` or ``'rpe'``.
    """
    jobs, outs = [], []
    for tool, ref, est, options in runs:
        outs.append(tmp_path / f'{tool}_{len(outs)}.zip')
        jobs.append([tool, ['tum', str(ref), str(est), *options, '--save_results',
                            str(outs[-1]), '--no_warnings', '--silent']])
    subprocess.run([sys.executable, '-c', _EVO_RUNNER], input=json.dumps(jobs), check=True,
                   capture_output=True, text=True, timeout=300)
    results = [file_interface.load_res_file(str(out)) for out in outs]
    return [(dict(res.stats), len(res.np_arrays['error_array'])) for res in results]


def synthetic_pair(tmp_path: Path):
    """Write a 2-loop reference at 10 Hz and a drifting, offset, scaled estimate."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 120.0, 0.1)
    yaw = 2 * math.pi * t / 60.0
    ref = np.column_stack([4.0 * np.sin(yaw), 3.0 * (1 - np.cos(yaw)), yaw])
    ref[:, 2] = np.angle(np.exp(1j * (ref[:, 2] + 0.3 * np.sin(t / 7.0))))
    est = ref.copy()
    est[:, :2] *= 1.02
    est[:, :2] += np.cumsum(rng.normal(0, 0.004, (t.size, 2)), axis=0)
    est[:, 2] += np.cumsum(rng.normal(0, 0.002, t.size))
    est = compose(np.array([0.5, -0.2, 0.1]), est)
    keep = rng.random(t.size) > 0.1          # the estimate misses 10 % of the stamps
    ref_ns = np.rint(t * 1e9).astype(np.int64) + 1_700_000_000 * 10**9
    est_ns = ref_ns + rng.integers(-4_000_000, 4_000_000, t.size)  # +-4 ms jitter
    rp, ep = tmp_path / 'ref.tum', tmp_path / 'est.tum'
    write_tum(rp, Trajectory.from_planar(ref_ns, ref))
    write_tum(ep, Trajectory.from_planar(est_ns[keep], est[keep]))
    return rp, ep


@pytest.fixture(scope='module')
def office_files(office_evaluation):
    out = office_evaluation('icnn')[1]   # the run of test_evaluate_slam.py (its files)
    return out / 'trajectory_gt.tum', out / 'trajectory_slam.tum'


def _check_agreement(rp: Path, ep: Path, tmp_path: Path):
    ref, est = read_tum(rp), read_tum(ep)
    relations = (('trans_part', '', ''), ('angle_deg', 'rot_', '_deg'))
    theirs = iter(evo_stats(
        [('ape', rp, ep, options) for options in EVO_ALIGN.values()]
        + [('rpe', rp, ep, ['--pose_relation', rel, '--delta', '1', '--delta_unit', 'm',
                            '--all_pairs', '--pairs_from_reference'])
           for rel, _, _ in relations], tmp_path))
    for align in EVO_ALIGN:
        ours = ate(est, ref, align)
        stats, n = next(theirs)
        assert ours['pairs'] == n, align
        for k in STATISTICS:
            assert ours[k] == pytest.approx(stats[k], abs=1e-6), (align, k)
    ours = rpe(est, ref, 1.0)
    for rel, prefix, suffix in relations:
        stats, n = next(theirs)
        assert ours['pairs'] == n
        for k in STATISTICS:
            assert ours[f'{prefix}{k}{suffix}'] == pytest.approx(stats[k], abs=1e-6), (rel, k)
    return ours


def test_agrees_with_evo_synthetic(tmp_path):
    rp, ep = synthetic_pair(tmp_path)
    r = _check_agreement(rp, ep, tmp_path)
    assert r['pairs'] > 900
    # the four alignments give different figures on this pair (each option is exercised)
    est, ref = read_tum(ep), read_tum(rp)
    rmse = [ate(est, ref, a)['rmse'] for a in ('none', 'se2', 'sim3')]
    assert rmse[0] > 2 * rmse[1] > 2 * rmse[2]


def test_agrees_with_evo_office(office_files, tmp_path):
    rp, ep = office_files
    r = _check_agreement(rp, ep, tmp_path)
    assert r['pairs'] > 1000


def test_agrees_with_evo_imported_carmen(tmp_path, carmen_evaluation):
    """The output of ``evaluate`` on a real log imported with ``landmark_nav import``.

    The run of test_evaluate_slam.py (conftest ``carmen_evaluation``).
    """
    out = carmen_evaluation[1] / 'out'
    r = _check_agreement(out / 'trajectory_gt.tum', out / 'trajectory_slam.tum', tmp_path)
    assert r['pairs'] > 150


def test_rigid_offset_removed_by_alignment():
    t = np.arange(200) * 10**8
    ref = np.column_stack([np.linspace(0, 10, 200), np.sin(np.linspace(0, 6, 200)),
                           np.linspace(0, 1, 200)])
    est = compose(np.array([1.0, 2.0, 0.5]), ref)
    a, b = Trajectory.from_planar(t, est), Trajectory.from_planar(t, ref)
    assert ate(a, b, 'none')['rmse'] > 1.0
    assert ate(a, b, 'se2')['rmse'] < 1e-9
    assert ate(a, b, 'se3')['rmse'] < 1e-9
    assert rpe(a, b, 1.0)['rmse'] < 1e-9
    scaled = Trajectory.from_planar(t, np.column_stack([2.0 * est[:, :2], est[:, 2]]))
    assert ate(scaled, b, 'se2')['rmse'] > 0.1
    s = ate(scaled, b, 'sim3')
    assert s['rmse'] < 1e-9 and s['scale'] == pytest.approx(0.5)


def test_tum_round_trip_keeps_nanoseconds(tmp_path):
    t = np.array([0, 1, 1_700_000_000_123_456_789], dtype=np.int64)
    poses = np.array([[0.0, 0.0, 3.1], [1.0, -2.0, -3.1], [0.5, 0.25, 0.0]])
    write_tum(tmp_path / 'a.tum', Trajectory.from_planar(t, poses))
    back = read_tum(tmp_path / 'a.tum')
    assert back.stamps_ns.tolist() == t.tolist()
    np.testing.assert_allclose(back.planar(), poses, atol=1e-8)


@pytest.mark.parametrize('text,line,message', [
    ('0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n', 2, 'expected 8 fields'),
    ('# header\n0 0 0 0 0 0 0 1\nx 0 0 0 0 0 0 1\n', 3, "stamp 'x' is not a number"),
    ('0 0 0 0 0 0 0 2\n', 1, 'quaternion norm'),
    ('1 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n', 2, 'stamp 1.0 is not after the previous'),
    ('0 nan 0 0 0 0 0 1\n', 1, 'non-finite'),
])
def test_bad_tum_names_file_and_line(tmp_path, text, line, message):
    p = tmp_path / 'bad.tum'
    p.write_text(text)
    with pytest.raises(ValueError, match=rf'bad\.tum:{line}: {message}'):
        read_tum(p)


def test_bad_arguments():
    t = Trajectory.from_planar(np.arange(5) * 10**8, np.zeros((5, 3)))
    far = Trajectory.from_planar(np.arange(5) * 10**8 + 10**9, np.zeros((5, 3)))
    with pytest.raises(ValueError, match='align must be one of'):
        ate(t, t, 'affine')
    with pytest.raises(ValueError, match='no estimate / reference stamps'):
        ate(t, far)
    with pytest.raises(ValueError, match='delta must be positive'):
        rpe(t, t, 0.0)
    assert rpe(t, t, 1.0)['pairs'] == 0
