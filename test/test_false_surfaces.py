"""No false surfaces: a line or corner arm never covers a beam seen through it (issue 15).

A beam is seen through a segment when its ray crosses the segment inside its extent and
its return lies more than ``max(3 sigma_r, 5 cm)`` beyond it. Hand-built scenes (a doorway,
a gap with a far wall behind, a table leg in front of a wall, which splits its extent) and
every scan of the six Carmen logs, both line methods and the refined corner detectors,
node defaults.
"""

import math

from landmark_nav.laser.corners import CornerParams, detect_corners
from landmark_nav.laser.lines import extract_lines, LineParams, METHODS
from landmark_nav.laser.segmentation import Cluster, segment_scan
from landmark_nav.testing import shared_data
import numpy as np
import pytest

SIGMA_R = 0.01  # the nodes' default
TOL = max(3.0 * SIGMA_R, 0.05)
STEP = math.radians(0.5)
ANGLES = np.arange(361) * STEP  # 0 .. 180 deg


def _false_beams(segments, ranges, angles, valid, tol=TOL):
    """Return (K,) the number of valid beams seen through each segment (K, 2, 2)."""
    segments = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    c, s, r = np.cos(angles[valid]), np.sin(angles[valid]), ranges[valid]
    out = np.zeros(len(segments), dtype=int)
    for k, (a, b) in enumerate(segments):
        d = b - a
        den = c * d[1] - s * d[0]  # ray x segment direction
        with np.errstate(divide='ignore', invalid='ignore'):
            t = (a[0] * d[1] - a[1] * d[0]) / den  # range of the crossing along the ray
            u = (a[0] * s - a[1] * c) / den  # where on the segment (0 = start, 1 = end)
        out[k] = np.count_nonzero((np.abs(den) > 1e-12) & (t > 0.0) & (u >= 0.0)
                                  & (u <= 1.0) & (r > t + tol))
    return out


def _segments(lines):
    return np.array([[ln.start, ln.end] for ln in lines]).reshape(-1, 2, 2)


def _ray_cast(walls, angles=ANGLES, sigma_r=SIGMA_R, seed=0):
    """Ranges of beams from the origin against wall segments ((x0, y0, x1, y1), ...)."""
    c, s = np.cos(angles), np.sin(angles)
    best = np.full(angles.size, np.inf)
    for x0, y0, x1, y1 in walls:
        dx, dy = x1 - x0, y1 - y0
        den = c * dy - s * dx
        with np.errstate(divide='ignore', invalid='ignore'):
            t = (x0 * dy - y0 * dx) / den
            u = (x0 * s - y0 * c) / den
        hit = (np.abs(den) > 1e-12) & (t > 0.0) & (u >= 0.0) & (u <= 1.0)
        best = np.where(hit, np.minimum(best, t), best)
    noise = np.random.default_rng(seed).normal(0.0, sigma_r, angles.size)
    return np.where(np.isfinite(best), best + noise, np.inf)


def _lines_of(ranges, method, min_points=5, whole_scan=True):
    valid = np.isfinite(ranges)
    clusters = segment_scan(ranges, ANGLES, valid, STEP, sigma_r=SIGMA_R, min_points=min_points)
    if not whole_scan:  # hand-built clusters: the extractor knows only their beams
        clusters = [Cluster(c.indices, c.points, c.ranges, c.angles) for c in clusters]
    return extract_lines(clusters, LineParams(method=method)), valid


# A doorway 0.5 m wide in a wall 8 m ahead (3.6 deg, within merge_gap_angle), the room
# behind it 7 m deeper, seen by 7 beams (a cluster, too few for a line): the two pieces of
# the wall agree and used to be merged across it.
DOORWAY = [(-4.0, 8.0, -0.25, 8.0), (0.25, 8.0, 4.0, 8.0), (-3.0, 15.0, 3.0, 15.0)]


@pytest.mark.parametrize('method', METHODS)
@pytest.mark.parametrize('whole_scan', [True, False])
def test_no_line_across_a_doorway(method, whole_scan):
    ranges = _ray_cast(DOORWAY)
    lines, valid = _lines_of(ranges, method, whole_scan=whole_scan)
    assert _false_beams(_segments(lines), ranges, ANGLES, valid).sum() == 0
    wall = [ln for ln in lines if abs(ln.rho - 8.0) < 0.05]
    # one line on each side of the doorway
    assert len(wall) == 2
    xs = sorted(sorted([ln.start[0], ln.end[0]]) for ln in wall)
    # the inner ends stop at the jambs (x = -+0.25 m), within 3 beams (7 cm apart) of them
    assert -0.25 - 0.21 <= xs[0][1] <= -0.25 + 0.02
    assert 0.25 - 0.02 <= xs[1][0] <= 0.25 + 0.21


# A wall 3 m ahead with a gap (15 cm: within merge_gap, 5 beams, a cluster too small for a
# line; 6 cm: 2 beams, a cluster the segmentation drops) through which the laser sees a
# wall 10 m ahead.
@pytest.mark.parametrize('method', METHODS)
@pytest.mark.parametrize('gap', [0.15, 0.06])
def test_no_line_across_a_gap_with_a_far_wall_behind(method, gap):
    walls = [(-3.0, 3.0, 0.5, 3.0), (0.5 + gap, 3.0, 3.0, 3.0), (-5.0, 10.0, 5.0, 10.0)]
    ranges = _ray_cast(walls)
    lines, valid = _lines_of(ranges, method)
    seen = ANGLES[valid & (ranges > 5.0)]
    assert np.any((seen > math.atan2(3.0, 0.5 + gap)) & (seen < math.atan2(3.0, 0.5)))
    assert _false_beams(_segments(lines), ranges, ANGLES, valid).sum() == 0
    assert len([ln for ln in lines if abs(ln.rho - 3.0) < 0.05]) == 2


@pytest.mark.parametrize('method', METHODS)
def test_a_table_leg_in_front_of_a_wall_splits_its_extent_not_its_fit(method):
    # a 4 cm leg 1 m in front of a wall 3 m ahead: the wall is not drawn along the leg's
    # rays (they saw the leg), so it is one segment on either side of the leg, both with
    # the fit of the whole wall
    walls = [(-3.0, 3.0, 3.0, 3.0), (0.48, 2.0, 0.52, 2.0)]
    ranges = _ray_cast(walls)
    lines, valid = _lines_of(ranges, method, min_points=1)
    leg = np.flatnonzero(valid & (ranges < 2.5))
    assert leg.size >= 2  # the leg is seen
    assert _false_beams(_segments(lines), ranges, ANGLES, valid).sum() == 0
    wall = sorted((ln for ln in lines if abs(ln.rho - 3.0) < 0.05),
                  key=lambda ln: ln.first_index)
    assert len(wall) == 2
    assert wall[0].last_index < leg.min() and wall[1].first_index > leg.max()
    # together they still span the wall up to the leg's shadow, with one fit
    assert wall[0].length + wall[1].length > 5.0
    assert (wall[0].rho, wall[0].alpha, wall[0].num_points) == (
        wall[1].rho, wall[1].alpha, wall[1].num_points)


@pytest.mark.parametrize('method', METHODS)
def test_end_points_lie_on_the_rays_of_the_supporting_beams(method):
    # a wall seen at grazing incidence ends where its last beam hit, not beyond
    walls = [(1.0, 0.5, 1.0, 6.0), (-3.0, 7.0, 3.0, 7.0)]
    ranges = _ray_cast(walls)
    lines, _ = _lines_of(ranges, method)
    assert lines
    for ln in lines:
        lo, hi = sorted([ANGLES[ln.first_index], ANGLES[ln.last_index]])
        for p in (ln.start, ln.end):
            assert lo - 1e-9 <= math.atan2(p[1], p[0]) <= hi + 1e-9


CARMEN_LOGS = ['aces', 'seattle', 'belgioioso', 'fhw', 'freiburg-101', 'acapulco']


@pytest.mark.parametrize('name', CARMEN_LOGS)
def test_no_false_surfaces_on_the_carmen_logs(name):
    from landmark_nav.importers.carmen import read_carmen_scans
    path = shared_data('carmen', f'{name}-corrected.log.gz')
    counts = {f'lines {m}': [0, 0] for m in METHODS}  # features, beams seen through them
    for scan in read_carmen_scans(path):
        valid = np.isfinite(scan.ranges) & (scan.ranges > 0.0)
        clusters = segment_scan(scan.ranges, scan.angles, valid, scan.angle_increment,
                                sigma_r=SIGMA_R, min_points=5)
        for method in METHODS:
            lines = extract_lines(clusters, LineParams(method=method))
            seen = _false_beams(_segments(lines), scan.ranges, scan.angles, valid)
            counts[f'lines {method}'][0] += len(lines)
            counts[f'lines {method}'][1] += int(seen.sum())
        for method in ('minus_cosine', 'split_merge'):  # the refined corner detectors
            corners = detect_corners(clusters, CornerParams(method=method))
            arms = np.array([c.arms for c in corners]).reshape(-1, 2, 2)
            key = f'corners {method}'
            counts.setdefault(key, [0, 0])
            counts[key][0] += len(corners)
            counts[key][1] += int(_false_beams(arms, scan.ranges, scan.angles, valid).sum())
    print(name, counts)
    for key, (n_found, n_false) in counts.items():
        assert n_found > (1000 if key.startswith('lines') else 150)
        assert n_false == 0, f'{name} {key}: {n_false} beams seen through them'


@pytest.mark.parametrize('value', [0.0, -0.05, float('nan'), float('inf')])
def test_see_through_must_be_positive(value):
    with pytest.raises(ValueError, match='see_through'):
        LineParams(see_through=value)
    assert LineParams().see_through_tolerance == 0.05
    assert LineParams(sigma_r=0.02).see_through_tolerance == pytest.approx(0.06)
