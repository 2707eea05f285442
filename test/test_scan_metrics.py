"""Feature metrics without ground-truth features, on hand-built scans with exact answers."""

import math

from landmark_nav.evaluation.scan_metrics import (approx_poly_segments, corner_observable,
                                                  corner_repeatability, in_view,
                                                  line_repeatability, MetricScan,
                                                  ray_metrics, ray_ranges, Repeatability)
from landmark_nav.geometry import inverse_transform_points
from landmark_nav.laser.segmentation import Cluster, segment_scan
import numpy as np
import pytest

PHI = np.radians(np.arange(-60.0, 60.01, 1.0))  # 121 beams, 1 deg


def wall(x: float, y0: float = -10.0, y1: float = 10.0) -> np.ndarray:
    """Return one segment on the line x = ``x`` from y0 to y1, (1, 2, 2)."""
    return np.array([[[x, y0], [x, y1]]])


def wall_scan(x: float = 2.0) -> np.ndarray:
    """Ranges of beams PHI hitting the wall x = ``x`` exactly."""
    return x / np.cos(PHI)


# ---------------------------------------------------------------------------- ray metric
def test_perfect_wall_has_full_coverage_and_zero_error():
    r = wall_scan()
    m = ray_metrics(r, PHI, np.ones(PHI.size, bool), wall(2.0))
    assert (m.valid, m.hits) == (121, 121)
    assert m.f == 1.0
    assert m.rmse == pytest.approx(0.0, abs=1e-12)
    assert m.false_surface.size == 0
    assert np.abs(m.fit_residuals).max() == pytest.approx(0.0, abs=1e-12)
    assert m.fit_residuals.size == 121


def test_half_segment_covers_half_the_beams():
    # A segment ending at y = 0 is hit by the beams at <= 0 deg (61 of 121) and, with the
    # 1e-3 rad tolerance, by no other (the next beam is 1 deg away).
    m = ray_metrics(wall_scan(), PHI, np.ones(PHI.size, bool), wall(2.0, -10.0, 0.0))
    assert m.hits == 61 and m.f == pytest.approx(61 / 121)
    # No segment at all: nothing hit, RMSE undefined.
    none = ray_metrics(wall_scan(), PHI, np.ones(PHI.size, bool), np.zeros((0, 2, 2)))
    assert none.hits == 0 and math.isnan(none.rmse) and none.false_surface.size == 0


def test_occluders_reported_apart():
    # a wall at 2 m with 1 cm residuals and two stray returns 1.5 m in front of it, kept
    # inside the wall's segment: they dominate the ray RMSE; without them it is 1 cm
    r = wall_scan(2.0) + np.where(np.arange(PHI.size) % 2, 0.01, -0.01) / np.cos(PHI)
    r[[30, 90]] = 0.5
    m = ray_metrics(r, PHI, np.ones(PHI.size, bool), wall(2.0), sigma_r=0.01)
    assert m.occluders == 2 and m.hits == 121 and m.margin == pytest.approx(0.05)
    assert m.rmse > 0.15
    kept = np.delete(r - wall_scan(2.0), [30, 90])
    assert m.rmse_without_occluders == pytest.approx(np.sqrt(np.mean(kept ** 2)), rel=1e-9)
    # a beam 4 cm short (inside the 5 cm margin) is noise, not an occluder
    r[30] = wall_scan(2.0)[30] - 0.04
    assert ray_metrics(r, PHI, np.ones(PHI.size, bool), wall(2.0)).occluders == 1


def test_shifted_segment_gives_known_residuals():
    r = wall_scan(2.0)
    valid = np.ones(PHI.size, bool)
    m = ray_metrics(r, PHI, valid, wall(2.1))  # 10 cm behind the wall
    expected = -0.1 / np.cos(PHI)  # measured - predicted range along each ray
    np.testing.assert_allclose(m.residuals, expected, atol=1e-12)
    assert m.rmse == pytest.approx(math.sqrt(np.mean(expected ** 2)), rel=1e-12)
    np.testing.assert_allclose(m.fit_residuals, 0.1, atol=1e-12)  # perpendicular: 10 cm
    assert m.false_surface.size == 0  # the beams stop in front of it
    # 25 cm away: out of the 20 cm fit window.
    assert ray_metrics(r, PHI, valid, wall(2.25)).fit_residuals.size == 0
    # In front of the wall by 3 cm: the beams end 3 cm / cos(phi) beyond it, more than
    # max(3 sigma_r, 5 cm) = 5 cm where cos(phi) < 0.6 (|phi| > 53.13 deg): 7 beams each side.
    near = ray_metrics(r, PHI, valid, wall(1.97), sigma_r=0.01)
    beyond = np.flatnonzero(0.03 / np.cos(PHI) > 0.05)
    assert beyond.size == 14
    np.testing.assert_array_equal(near.false_surface, beyond)
    np.testing.assert_allclose(near.false_surface_excess, 0.03 / np.cos(PHI[beyond]))
    # With sigma_r = 2.1 cm the margin is 6.3 cm: |phi| > 61.6 deg: none of the beams.
    assert ray_metrics(r, PHI, valid, wall(1.97), sigma_r=0.021).false_surface.size == 0


def test_segment_bridging_a_doorway_counts_the_beams_seen_through_it():
    # Wall at x = 2 with a doorway |y| < 0.45 through which the beams reach x = 8.
    r = wall_scan(2.0)
    door = np.abs(2.0 * np.tan(PHI)) < 0.45
    r[door] = 8.0 / np.cos(PHI[door])
    valid = np.ones(PHI.size, bool)
    bridged = ray_metrics(r, PHI, valid, wall(2.0))
    np.testing.assert_array_equal(bridged.false_surface, np.flatnonzero(door))
    np.testing.assert_allclose(bridged.false_surface_excess, 6.0 / np.cos(PHI[door]))
    assert door.sum() == 25  # |phi| <= 12 deg
    assert bridged.f == 1.0 and bridged.rmse > 1.0
    # The same wall as two segments that end at the last beams on the wall (+-13 deg): no
    # false surface.
    jamb = 2.0 * math.tan(math.radians(13.0))
    split = np.concatenate([wall(2.0, -10.0, -jamb), wall(2.0, jamb, 10.0)])
    clean = ray_metrics(r, PHI, valid, split)
    assert clean.false_surface.size == 0
    assert clean.hits == 121 - 25 and clean.rmse == pytest.approx(0.0, abs=1e-12)
    # A segment behind the measured points is crossed by no beam that saw through it.
    assert ray_metrics(r, PHI, valid, wall(9.0)).false_surface.size == 0


def test_no_return_beams_and_invalid_beams():
    r = wall_scan(2.0)
    r[:10] = np.inf   # no return
    r[10:15] = np.nan  # errors: neither valid nor no-return
    valid = np.isfinite(r)
    m = ray_metrics(r, PHI, valid, wall(2.0, -10.0, 0.0))  # covers beams 0..60
    assert (m.valid, m.no_return) == (106, 10)
    assert m.hits == 61 - 15
    assert m.no_return_clear == 0 and m.f_no_return == 0.0
    # A no-return beam crossing a segment is not a false-surface *measurement*.
    assert m.false_surface.size == 0
    far = ray_metrics(r, PHI, valid, wall(2.0, 0.0, 10.0))
    assert far.no_return_clear == 10 and far.f_no_return == 1.0


def test_first_hit_is_the_nearest_along_the_ray():
    r = wall_scan(2.0)
    segs = np.concatenate([wall(3.0), wall(2.0)])  # the far one first in the list
    cast = ray_ranges(PHI, segs)
    np.testing.assert_allclose(cast[:, 0], 3.0 / np.cos(PHI))
    for order in (segs, segs[::-1]):
        m = ray_metrics(r, PHI, np.ones(PHI.size, bool), order)
        assert m.rmse == pytest.approx(0.0, abs=1e-12)
    # Rays pointing away from a segment, or parallel to it, do not hit it.
    assert np.isinf(ray_ranges(PHI, wall(-2.0))).all()
    parallel = np.array([[[1.0, 1.0], [1.0, 3.0]]])
    assert np.isinf(ray_ranges(np.array([math.pi / 2]), parallel)).all()


def test_length_mismatch_is_an_error():
    with pytest.raises(ValueError, match='differ in length'):
        ray_metrics(np.ones(3), np.zeros(4), np.ones(3, bool), wall(1.0))


# ---------------------------------------------------------------------------- baseline
def test_approx_poly_baseline_on_an_l_shape():
    # An L: 1 m along y at x = 2 (beams toward it) then 0.2 m back toward the sensor.
    y = np.linspace(-1.0, 0.0, 51)
    arm1 = np.column_stack([np.full(51, 2.0), y])
    x = np.linspace(2.0, 1.8, 11)[1:]
    arm2 = np.column_stack([x, np.zeros(10)])
    pts = np.concatenate([arm1, arm2])
    r = np.hypot(*pts.T)
    a = np.arctan2(pts[:, 1], pts[:, 0])
    cl = Cluster(np.arange(len(r)) + 7, pts, r, a)
    segs, idx = approx_poly_segments([cl], epsilon=0.05)
    np.testing.assert_allclose(segs, [[[2.0, -1.0], [2.0, 0.0]], [[2.0, 0.0], [1.8, 0.0]]],
                               atol=1e-6)
    np.testing.assert_array_equal(idx, [[7, 57], [57, 67]])
    # Restricted to the extractors' minimum size (>= 12 points, >= 0.3 m): the long arm.
    segs, idx = approx_poly_segments([cl], epsilon=0.05, min_points=12, min_length=0.3)
    np.testing.assert_array_equal(idx, [[7, 57]])
    assert approx_poly_segments([cl], min_points=52)[0].shape == (0, 2, 2)
    assert approx_poly_segments([])[0].shape == (0, 2, 2)


def test_approx_poly_baseline_on_a_segmented_scan():
    r = wall_scan(2.0)
    door = np.abs(2.0 * np.tan(PHI)) < 0.45
    r[door] = 8.0 / np.cos(PHI[door])
    clusters = segment_scan(r, PHI, np.ones(PHI.size, bool), math.radians(1.0))
    segs, _ = approx_poly_segments(clusters)
    assert len(segs) == 3  # two wall pieces and the back wall
    assert ray_metrics(r, PHI, np.ones(PHI.size, bool), segs).false_surface.size == 0


# ---------------------------------------------------------------------------- repeatability
ROOM = np.array([[[0, 0], [6, 0]], [[6, 0], [6, 4]], [[6, 4], [0, 4]], [[0, 4], [0, 0]]],
                dtype=float)
ROOM_CORNERS = np.array([[0, 0], [6, 0], [6, 4], [0, 4]], dtype=float)
FOV = np.radians(np.arange(-120.0, 120.01, 1.0))


def view_of(pose, segments_map) -> MetricScan:
    """Ray-cast the map segments from ``pose``: a noise-free scan over FOV."""
    segs = inverse_transform_points(pose, segments_map.reshape(-1, 2)).reshape(-1, 2, 2)
    r = ray_ranges(FOV, segs).min(axis=1)
    return MetricScan(r, FOV, np.isfinite(r), np.isinf(r), 0.1, 30.0,
                      np.asarray(pose, float))


def to_laser(pose, pts):
    """Map points (..., 2) into the laser frame at ``pose``."""
    return inverse_transform_points(pose, np.asarray(pts, float).reshape(-1, 2)).reshape(
        np.shape(pts))


A = np.array([3.0, 2.0, 0.0])
B = np.array([3.3, 2.1, 0.1])


def test_static_scene_is_fully_repeatable():
    view_b = view_of(B, ROOM)
    lines = Repeatability()
    line_repeatability(lines, to_laser(A, ROOM), A, to_laser(B, ROOM), view_b)
    # The wall x = 0 is behind B (bearing ~180 deg): three opportunities.
    assert (lines.opportunities, lines.redetected) == (3, 3) and lines.fraction == 1.0
    corners = Repeatability()
    corner_repeatability(corners, to_laser(A, ROOM_CORNERS), A, to_laser(B, ROOM_CORNERS),
                         view_b)
    # (6, 0) and (6, 4) are in front of B; (0, 0) and (0, 4) behind it.
    assert (corners.opportunities, corners.redetected) == (2, 2)


def test_moved_features_lower_repeatability_by_a_known_fraction():
    view_b = view_of(B, ROOM)
    moved = ROOM.copy()
    moved[1, :, 0] += 0.06  # the wall x = 6 is re-detected 6 cm off: beyond 5 cm
    lines = Repeatability()
    line_repeatability(lines, to_laser(A, ROOM), A, to_laser(B, moved), view_b)
    assert (lines.opportunities, lines.redetected) == (3, 2)
    within = ROOM.copy()
    within[1, :, 0] += 0.04
    ok = Repeatability()
    line_repeatability(ok, to_laser(A, ROOM), A, to_laser(B, within), view_b)
    assert ok.redetected == 3
    turned = ROOM.copy()
    turned[1, 1, 0] += 4.0 * math.tan(math.radians(2.5))  # 2.5 deg off
    rot = Repeatability()
    line_repeatability(rot, to_laser(A, ROOM), A, to_laser(B, turned), view_b)
    assert rot.redetected == 2
    # A re-detection with no overlap of the extents does not count.
    apart = Repeatability()
    far_piece = np.array([[[6.0, 10.0], [6.0, 12.0]]])
    line_repeatability(apart, to_laser(A, ROOM[1:2]), A, to_laser(B, far_piece), view_b)
    assert (apart.opportunities, apart.redetected) == (1, 0)
    corners = Repeatability()
    c_moved = ROOM_CORNERS.copy()
    c_moved[2] += [0.0, -0.11]
    corner_repeatability(corners, to_laser(A, ROOM_CORNERS), A, to_laser(B, c_moved), view_b)
    assert (corners.opportunities, corners.redetected) == (2, 1)


def test_short_lines_are_no_opportunity_and_occluded_places_are_not_in_view():
    view_b = view_of(B, ROOM)
    short = Repeatability()
    piece = np.array([[[6.0, 1.0], [6.0, 1.9]]])  # 0.9 m < 1 m
    line_repeatability(short, to_laser(A, piece), A, to_laser(B, piece), view_b)
    assert short.opportunities == 0
    # A pillar between B and the corner (6, 4) hides it: one corner opportunity left.
    pillar = np.array([[[4.55, 3.19], [4.75, 2.91]]])
    hidden = view_of(B, np.concatenate([ROOM, pillar]))
    np.testing.assert_array_equal(in_view(hidden, ROOM_CORNERS), [False, True, False, False])
    np.testing.assert_array_equal(in_view(view_b, ROOM_CORNERS), [False, True, True, False])
    # Out of range.
    near = MetricScan(view_b.ranges, FOV, view_b.valid, view_b.no_return, 0.1, 3.0, B)
    assert not in_view(near, ROOM_CORNERS).any()


# The room's corners as a detector reports them: [bisector, opening] in the map frame
# (concave, opening 90 deg, the bisector toward the room's centre).
ROOM_WEDGES = np.array([[math.atan2(1, 1), math.pi / 2], [math.atan2(1, -1), math.pi / 2],
                        [math.atan2(-1, -1), math.pi / 2], [math.atan2(-1, 1), math.pi / 2]])


def wedges_in(pose, wedges):
    """Return the map-frame wedges as scan ``pose`` reports them (bisector in its frame)."""
    return wedges - np.array([pose[2], 0.0])


def test_a_corner_whose_arm_leaves_the_field_of_view_is_no_opportunity():
    # From B the corner (6, 4) is at bearing 29.4 deg; its arm along y = 4 runs to larger
    # bearings (15 cm along it: 31.0 deg), the arm along x = 6 to smaller ones (27.2 deg).
    fov = np.radians(np.arange(-120.0, 30.01, 1.0))  # the last beam at 30 deg
    segs = inverse_transform_points(B, ROOM.reshape(-1, 2)).reshape(-1, 2, 2)
    r = ray_ranges(fov, segs).min(axis=1)
    view = MetricScan(r, fov, np.isfinite(r), np.isinf(r), 0.1, 30.0, B)
    arms = ROOM_WEDGES[:, :1] + 0.25 * np.pi * np.array([1.0, -1.0])
    np.testing.assert_array_equal(in_view(view, ROOM_CORNERS), [False, True, True, False])
    np.testing.assert_array_equal(corner_observable(view, ROOM_CORNERS),
                                  [False, True, True, False])
    np.testing.assert_array_equal(corner_observable(view, ROOM_CORNERS, arms),
                                  [False, True, False, False])
    # Counted: one opportunity, re-detected; the corner that left is counted apart.
    score = Repeatability()
    corner_repeatability(score, to_laser(A, ROOM_CORNERS), A, to_laser(B, ROOM_CORNERS[1:2]),
                         view, wedges_k=wedges_in(A, ROOM_WEDGES))
    assert (score.opportunities, score.redetected) == (1, 1)
    assert (score.unobserved, score.unobserved_redetected) == (1, 0)
    assert score.fraction == 1.0 and score.fraction_with_unobserved == 0.5
    # With the whole field of view both are opportunities.
    full = Repeatability()
    corner_repeatability(full, to_laser(A, ROOM_CORNERS), A, to_laser(B, ROOM_CORNERS[1:2]),
                         view_of(B, ROOM), wedges_k=wedges_in(A, ROOM_WEDGES))
    assert (full.opportunities, full.redetected, full.unobserved) == (2, 1, 0)


def test_a_corner_the_next_scan_sees_past_is_no_opportunity():
    # The corner (6, 4) is gone in the next scan (a door opened there, the laser sees 8 m
    # further through it): the beam toward it is not occluded, so the line rule keeps it
    # in view, but nothing was returned at its place.
    opened = np.array([[[0, 0], [6, 0]], [[6, 0], [6, 3.5]], [[5.5, 4], [0, 4]],
                       [[0, 4], [0, 0]], [[14, -5], [14, 12]]], dtype=float)
    view = view_of(B, opened)
    np.testing.assert_array_equal(in_view(view, ROOM_CORNERS), [False, True, True, False])
    np.testing.assert_array_equal(in_view(view, ROOM_CORNERS, surface=True),
                                  [False, True, False, False])
    score = Repeatability()
    corner_repeatability(score, to_laser(A, ROOM_CORNERS), A, to_laser(B, ROOM_CORNERS[1:2]),
                         view)
    assert (score.opportunities, score.redetected, score.unobserved) == (1, 1, 1)
    # No return at all there (the room's far side open to the sky) is not seen either.
    blind = MetricScan(np.where(view.ranges > 7.0, np.inf, view.ranges), FOV,
                       view.ranges <= 7.0, view.ranges > 7.0, 0.1, 30.0, B)
    np.testing.assert_array_equal(in_view(blind, ROOM_CORNERS, surface=True),
                                  [False, True, False, False])
    # A corner 5 cm short of its beam's return is still seen (margin 10 cm), 20 cm short is
    # not (its beam hits the wall a few cm from the corner: not exactly 0 cm).
    c = ROOM_CORNERS[1:2]
    near = view_of(B, ROOM)
    toward = (c - B[:2]) / np.hypot(*(c - B[:2]).T)
    assert in_view(near, c - 0.05 * toward, surface=True).all()
    assert not in_view(near, c - 0.2 * toward, surface=True).any()


def test_structural_corners_have_two_arms_long_and_wide_in_beams():
    from landmark_nav.laser.corner_detection.corner import (Corner, STRUCTURAL_ARM,
                                                            STRUCTURAL_BEAM_STEPS)

    def corner(end1, end2, step=0.01):
        c = [3.0, 0.0]  # 3 m ahead of the laser
        arms = np.array([[c, end1], [c, end2]], dtype=float)
        return Corner(np.array(c), 0.0, math.pi / 2, np.eye(2), 0, 0.0, arms, step)

    wall = corner([3.0, 0.6], [2.5, -0.5])  # 0.197 rad each side: 20 beam steps at 0.01
    np.testing.assert_allclose(wall.arm_beam_steps, [20, 20])
    np.testing.assert_allclose(wall.arm_lengths, [0.6, math.hypot(0.5, 0.5)])
    assert wall.structural
    # the same corner on a laser with 5x coarser beams: 4 steps per arm, too few to refit
    assert corner([3.0, 0.6], [2.5, -0.5], step=0.05).arm_beam_steps.tolist() == [4, 4]
    assert not corner([3.0, 0.6], [2.5, -0.5], step=0.05).structural
    # a long arm along the beam (grazing incidence) spans no beam
    assert not corner([3.0, 0.6], [3.8, 0.0]).structural
    # arms at the bounds are structural; a shorter arm is not
    short = STRUCTURAL_ARM - 0.05
    assert not corner([3.0, short], [2.5, -0.5]).structural

    def steps(n):  # an arm of n beam steps of 0.02 rad, longer than STRUCTURAL_ARM
        return corner([3.0, 3.0 * math.tan(n * 0.02)], [2.5, -0.5], step=0.02)

    assert min(steps(STRUCTURAL_BEAM_STEPS - 0.6).arm_lengths) > STRUCTURAL_ARM
    assert steps(STRUCTURAL_BEAM_STEPS + 0.2).structural
    assert not steps(STRUCTURAL_BEAM_STEPS - 0.6).structural
    bare = Corner(np.zeros(2), 0.0, math.pi / 2, np.eye(2), 0, 0.0)
    assert not bare.structural and np.isnan(bare.arm_lengths).all()
    assert np.isnan(bare.arm_beam_steps).all()
