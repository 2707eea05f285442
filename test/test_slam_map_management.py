"""Map management: visibility-aware pruning, the map-size policy, save / load, localization."""

import math

from landmark_nav.geometry import compose, inverse_transform_points
from landmark_nav.slam import EkfSlam, SlamParams
from landmark_nav.slam.slam_map import load_map, save_map, SlamMap
from landmark_nav.slam.visibility import (corners_in_view, corners_missed, lines_missed,
                                          ScanGeometry)
import numpy as np
import pytest

R1 = np.diag([0.01 ** 2, math.radians(0.3) ** 2])
INC = math.radians(0.5)


def observe(pose, points):
    """Exact range-bearing of world points from a pose."""
    p = inverse_transform_points(pose, points)
    return np.column_stack([np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])])


def rs(m):
    """Return m copies of R1."""
    return np.repeat(R1[None], m, axis=0)


def scan_with(ranges_fn, n=361):
    """Return a 180 deg scan (0.5 deg beams) with ranges_fn(angles) as its ranges."""
    angles = -math.pi / 2 + INC * np.arange(n)
    return ScanGeometry(np.asarray(ranges_fn(angles), dtype=float), -math.pi / 2, INC, 0.02,
                        30.0, np.zeros(3), 0.01)


def wall_at(x):
    """Ranges of a wall x = const in front of a robot at the origin."""
    return lambda a: np.where(np.cos(a) > 0.05, x / np.maximum(np.cos(a), 1e-9), np.inf)


# ------------------------------------------------------------------------- visibility
def test_corner_missed_only_when_the_scan_sees_through_its_place():
    xy = np.array([[3.0, 0.0]])
    sig = np.array([[0.01, 0.002]])
    args = (np.zeros(3), xy, np.zeros((1, 2)), np.array([np.nan]), sig)
    # The wall behind it at 6 m: the beams pass where the corner should be -> missed.
    assert corners_missed(*args, scan_with(wall_at(6.0)), 1.96, math.radians(8))[0]
    # A return at the corner (detector failure): not a miss.
    assert not corners_missed(*args, scan_with(wall_at(3.0)), 1.96, math.radians(8))[0]
    # Something in front (occluded): not a miss.
    assert not corners_missed(*args, scan_with(wall_at(1.0)), 1.96, math.radians(8))[0]
    # No return at all (blackout) or sensor errors: unknown, not a miss.
    assert not corners_missed(*args, scan_with(lambda a: np.full(a.shape, np.inf)), 1.96,
                              math.radians(8))[0]
    assert not corners_missed(*args, scan_with(lambda a: np.full(a.shape, np.nan)), 1.96,
                              math.radians(8))[0]
    # Behind the robot (outside the 180 deg field of view): not a miss.
    back = (np.zeros(3), -xy, np.zeros((1, 2)), np.array([np.nan]), sig)
    assert not corners_missed(*back, scan_with(wall_at(6.0)), 1.96, math.radians(8))[0]


def test_convex_corner_edge_beside_the_beam_is_not_a_miss():
    """A beam passing just beside an object's edge hits the background; its neighbour the arm."""
    xy = np.array([[3.0, 0.0]])
    sig = np.array([[0.01, 0.001]])
    # Object to the left of the corner bearing (beams with a > 0.2 deg return at 3.05 m,
    # its arm receding), background at 6 m to the right (including the corner's own beam).
    scan = scan_with(lambda a: np.where(a > math.radians(0.2), 3.05, 6.0))
    assert not corners_missed(np.zeros(3), xy, np.zeros((1, 2)), np.array([np.nan]), sig,
                              scan, 1.96, math.radians(8))[0]


def test_corner_seen_from_outside_its_wedge_is_not_expected():
    xy = np.array([[3.0, 0.0]])
    bis = np.array([[1.0, 0.0]])  # free space toward +x: the robot at the origin is behind it
    assert not corners_missed(np.zeros(3), xy, bis, np.array([math.pi / 2]),
                              np.array([[0.01, 0.002]]), scan_with(wall_at(6.0)), 1.96,
                              math.radians(8))[0]


def test_line_missed_when_its_beams_see_through():
    line = np.array([[3.0, 0.0]])  # x = 3
    ends = np.array([[[3.0, -1.0], [3.0, 1.0]]])
    sig = np.array([0.01])
    assert lines_missed(np.zeros(3), line, ends, sig, scan_with(wall_at(5.0)), 1.96, 8)[0]
    assert not lines_missed(np.zeros(3), line, ends, sig, scan_with(wall_at(3.0)), 1.96, 8)[0]
    # Half of it still there (a door opened in a wall): its beams on it keep it.
    half = scan_with(lambda a: np.where(a > 0, 3.0 / np.cos(a), 5.0 / np.cos(a)))
    assert not lines_missed(np.zeros(3), line, ends, sig, half, 1.96, 8)[0]
    # Seen from behind (the robot beyond the wall): not expected.
    assert not lines_missed(np.array([4.0, 0.0, math.pi]), line, ends, sig,
                            scan_with(wall_at(5.0)), 1.96, 8)[0]


# ---------------------------------------------------------------------------- pruning
def test_moved_object_is_pruned_after_prune_misses_scans_and_a_real_corner_is_kept():
    """A corner on an object that leaves is removed once N scans see through its place.

    Pruning alone (``establish_hits`` 0, the default): with establishment on, the corner at
    (2, 2) would be a provisional corner that had a chance and was not detected
    (:func:`test_provisional_corner_not_detected_again_is_retired`).
    """
    prm = SlamParams(confirm_hits=1, confirm_window=1, prune_misses=3)
    slam = EkfSlam(prm)
    pts = np.array([[3.0, 0.0], [2.0, 2.0]])
    slam.update(observe(np.zeros(3), pts), rs(2), scan=scan_with(wall_at(3.0)))
    assert slam.num_landmarks == 2
    # The object at (3, 0) is gone: the beams toward it reach a wall at 6 m. The corner at
    # (2, 2) is not detected either, but its beam returns at it (detector failure).

    def ranges(a):
        r = wall_at(6.0)(a)
        return np.where(np.abs(a - math.pi / 4) < math.radians(3), math.hypot(2, 2), r)
    for k in range(3):
        slam.predict(np.zeros(3))
        slam.update(np.zeros((0, 2)), scan=scan_with(ranges))
        assert slam.num_landmarks == (2 if k < 2 else 1)
    assert slam.landmarks[0] == pytest.approx([2.0, 2.0], abs=1e-9)
    assert slam.stats['pruned'] == 1
    # Without the scan geometry nothing is judged.
    slam2 = EkfSlam(prm)
    slam2.update(observe(np.zeros(3), pts), rs(2))
    for _ in range(5):
        slam2.update(np.zeros((0, 2)))
    assert slam2.num_landmarks == 2


# ----------------------------------------------------------------------- establishment
def test_corner_in_view_when_its_place_returns_at_or_beyond_it():
    xy = np.array([[3.0, 0.0]])
    sig = np.array([[0.01, math.radians(0.3)]])
    args = (np.zeros(3), xy, np.zeros((1, 2)), np.array([np.nan]), sig, np.array([4.0]))
    assert corners_in_view(*args, scan_with(wall_at(3.0)), 1.96, math.radians(8))[0]
    assert corners_in_view(*args, scan_with(wall_at(6.0)), 1.96, math.radians(8))[0]
    # Something in front of it (occluded), no return, errors: no chance.
    assert not corners_in_view(*args, scan_with(wall_at(1.5)), 1.96, math.radians(8))[0]
    assert not corners_in_view(*args, scan_with(lambda a: np.full(a.shape, np.inf)), 1.96,
                               math.radians(8))[0]
    assert not corners_in_view(*args, scan_with(lambda a: np.full(a.shape, np.nan)), 1.96,
                               math.radians(8))[0]
    # Farther than it was ever detected: no chance.
    far = args[:5] + (np.array([2.5]),)
    assert not corners_in_view(*far, scan_with(wall_at(3.0)), 1.96, math.radians(8))[0]
    # Its free-space wedge faces away from the robot: no chance.
    bis = np.array([[1.0, 0.0]])
    back = (np.zeros(3), xy, bis, np.array([math.pi / 2]), sig, np.array([4.0]))
    assert not corners_in_view(*back, scan_with(wall_at(3.0)), 1.96, math.radians(8))[0]


def establishing_filter(**kw):
    """Two corners confirmed in one scan (3 hits in 3 scans), then the chances."""
    prm = SlamParams(confirm_hits=3, confirm_window=3, prune_misses=0,
                     **{'establish_hits': 3, **kw})
    slam = EkfSlam(prm)
    pts = np.array([[3.0, 0.0], [2.0, 2.0]])
    back = scan_with(wall_at(6.0))
    for _ in range(3):
        slam.update(observe(np.zeros(3), pts), rs(2), scan=back)
    assert slam.num_landmarks == 2 and slam.stats['confirmed'] == 2
    return slam, pts


def in_view_ranges(a):
    """Beams toward (2, 2) return at it, the others reach a wall at 6 m beyond (3, 0)."""
    r = wall_at(6.0)(a)
    return np.where(np.abs(a - math.pi / 4) < math.radians(3), math.hypot(2, 2), r)


def test_provisional_corner_not_detected_again_is_retired():
    """3 detections in 3 chances to stay: (3, 0) is seen each time, (2, 2) never."""
    slam, pts = establishing_filter()
    for k in range(3):
        slam.update(observe(np.zeros(3), pts[:1]), rs(1), scan=scan_with(in_view_ranges))
        assert slam.num_landmarks == (2 if k < 2 else 1)
    assert slam.landmarks[0] == pytest.approx([3.0, 0.0], abs=1e-9)
    assert slam.stats['retired'] == 1
    # Established: further scans without it do not remove (3, 0) (no pruning here).
    for _ in range(5):
        slam.update(np.zeros((0, 2)), scan=scan_with(in_view_ranges))
    assert slam.num_landmarks == 1


def test_provisional_corner_out_of_view_waits_for_its_chances():
    """Scans that cannot show (2, 2) (occluded, no return) do not count against it."""
    slam, pts = establishing_filter()
    blocked = scan_with(lambda a: np.where(np.abs(a - math.pi / 4) < math.radians(3), 1.0,
                                           wall_at(6.0)(a)))
    for _ in range(10):
        slam.update(observe(np.zeros(3), pts[:1]), rs(1), scan=blocked)
    assert slam.num_landmarks == 2 and slam.stats['retired'] == 0
    # Two detections in its next chances are not enough, the third establishes it.
    for k in range(3):
        z = pts if k < 2 else pts[:1]
        slam.update(observe(np.zeros(3), z), rs(len(z)), scan=scan_with(in_view_ranges))
    assert slam.num_landmarks == 1
    slam2, pts = establishing_filter()
    for _ in range(3):
        slam2.update(observe(np.zeros(3), pts), rs(2), scan=scan_with(in_view_ranges))
    for _ in range(10):
        slam2.update(observe(np.zeros(3), pts[:1]), rs(1), scan=scan_with(in_view_ranges))
    assert slam2.num_landmarks == 2 and slam2.stats['retired'] == 0


def test_establishment_off_and_parameter_checks():
    slam, pts = establishing_filter(establish_hits=0)
    for _ in range(5):
        slam.update(observe(np.zeros(3), pts[:1]), rs(1), scan=scan_with(in_view_ranges))
    assert slam.num_landmarks == 2
    assert SlamParams(confirm_hits=4, confirm_window=6).establish_hits == 0
    assert SlamParams(confirm_hits=4, confirm_window=6).establish_chances == 6
    with pytest.raises(ValueError, match='establish_chances'):
        SlamParams(establish_hits=3, establish_chances=2)
    with pytest.raises(ValueError, match='establish_hits'):
        SlamParams(establish_hits=-1)


def test_a_sighting_resets_the_miss_count():
    prm = SlamParams(confirm_hits=1, confirm_window=1, prune_misses=2)
    slam = EkfSlam(prm)
    pt = np.array([[3.0, 0.0]])
    gone = scan_with(wall_at(6.0))
    slam.update(observe(np.zeros(3), pt), rs(1), scan=gone)
    for k in range(6):  # miss, seen, miss, seen, ...: never two in a row
        z = observe(np.zeros(3), pt) if k % 2 else np.zeros((0, 2))
        slam.update(z, rs(len(z)), scan=gone)
    assert slam.num_landmarks == 1
    slam.update(np.zeros((0, 2)), scan=gone)
    slam.update(np.zeros((0, 2)), scan=gone)
    assert slam.num_landmarks == 0


def test_a_blackout_scan_shows_nothing_and_keeps_the_counts():
    """A scan without returns neither counts a miss nor resets one, nor gives a chance."""
    blackout = scan_with(lambda a: np.full(a.shape, np.inf))
    assert not blackout.has_returns and scan_with(wall_at(6.0)).has_returns
    prm = SlamParams(confirm_hits=1, confirm_window=1, prune_misses=2)
    slam = EkfSlam(prm)
    pt = np.array([[3.0, 0.0]])
    gone = scan_with(wall_at(6.0))
    slam.update(observe(np.zeros(3), pt), rs(1), scan=gone)
    slam.update(np.zeros((0, 2)), scan=gone)  # the first miss
    for _ in range(5):
        slam.predict(np.zeros(3))
        res = slam.update(np.zeros((0, 2)), scan=blackout)
        assert res.status.shape == (0,) and res.nis_dof == 0
    assert slam.num_landmarks == 1 and slam.stats['updates'] == 7
    slam.update(np.zeros((0, 2)), scan=gone)  # the second in a row
    assert slam.num_landmarks == 0 and slam.stats['pruned'] == 1
    est, pts = establishing_filter()
    for _ in range(10):
        est.update(observe(np.zeros(3), pts[:1]), rs(1), scan=blackout)
    assert est.num_landmarks == 2 and est.stats['retired'] == 0


# --------------------------------------------------------------------------- map size
def drive_past_corners(prm, n_corners=12):
    """Drive along a row of corners 1 m apart; each seen only within 3 m."""
    slam = EkfSlam(prm)
    corners = np.column_stack([np.arange(n_corners) + 1.0, np.full(n_corners, 1.0)])
    pose = np.zeros(3)
    reasons = []
    for k in range(10 * n_corners):
        if k:
            pose = compose(pose, np.array([0.1, 0.0, 0.0]))
            slam.predict(np.array([0.1, 0.0, 0.0]))
        z = observe(pose, corners)
        near = z[:, 0] < 3.0
        res = slam.update(z[near], rs(int(near.sum())))
        reasons += res.reason.tolist()
    return slam, reasons


def test_full_map_evicts_the_least_recently_seen_landmark():
    # At most 6 corners are in view at once; a budget of 7 must never block a new one.
    slam, reasons = drive_past_corners(SlamParams(max_landmarks=7))
    assert slam.num_landmarks == 7
    assert 'cap' not in reasons
    assert slam.stats['confirmed'] == 12
    assert slam.stats['evicted'] == 5
    # What is kept is the newest part of the map, where the robot is (x = 12).
    assert sorted(slam.landmarks[:, 0].round(6).tolist()) == [6.0, 7.0, 8.0, 9.0, 10.0, 11.0,
                                                              12.0]


def test_reject_policy_keeps_the_old_behaviour():
    slam, reasons = drive_past_corners(SlamParams(max_landmarks=7, map_full='reject'))
    assert slam.num_landmarks == 7 and slam.stats['evicted'] == 0
    assert sorted(slam.landmarks[:, 0].round(6).tolist()) == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0,
                                                              7.0]
    assert reasons.count('cap') > 0


def test_bad_policy_and_mode_are_rejected():
    with pytest.raises(ValueError, match='map_full'):
        SlamParams(map_full='drop')
    with pytest.raises(ValueError, match='mode'):
        SlamParams(mode='mapping')
    with pytest.raises(ValueError, match='prune_misses'):
        SlamParams(prune_misses=-1)
    assert SlamParams(confirm_hits=4, confirm_window=6).prune_misses == 4


# ---------------------------------------------------------------------------- map reuse
def mapped_filter():
    """Return a filter that mapped four corners and a line from a few poses."""
    slam = EkfSlam(SlamParams(confirm_hits=2, confirm_window=3))
    from landmark_nav.slam.line_landmarks import LineObservations
    pts = np.array([[3.0, 1.0], [4.0, -2.0], [2.0, 3.0], [5.0, 0.5]])
    for k in range(4):
        pose = np.array([0.1 * k, 0.0, 0.02 * k])
        if k:
            slam.predict(np.array([0.1, 0.0, 0.02]), np.diag([1e-6, 1e-6, 1e-6]))
        lines = LineObservations(np.array([[6.0 - 0.1 * k, -0.02 * k]]),
                                 np.diag([1e-4, 1e-5])[None],
                                 np.array([[[6.0 - 0.1 * k, -1.0], [6.0 - 0.1 * k, 1.0]]]))
        slam.update(observe(pose, pts), rs(4), None, lines)
    return slam, pts


def test_save_and_load_map_round_trip(tmp_path):
    slam, _ = mapped_filter()
    m = slam.export_map()
    assert m.size == 5 and sorted(m.kinds.tolist()) == [0, 0, 0, 0, 1]
    path = save_map(tmp_path / 'office', m)
    assert path.name == 'office.npz'
    back = load_map(path)
    for name in ('ids', 'kinds', 'means', 'covariance', 'ends', 'bisectors', 'openings',
                 'n_openings', 'hits', 'max_seen'):
        assert np.array_equal(getattr(back, name), getattr(m, name), equal_nan=True), name
    assert back.next_id == m.next_id == 5
    # Loading restores the map in a new filter: same landmarks and covariance block.
    other = EkfSlam(SlamParams())
    other.load_map(back, [0.3, 0.0, 0.06], np.diag([1e-4, 1e-4, 1e-5]))
    assert np.array_equal(other.landmarks, slam.landmarks)
    assert np.array_equal(other.covariance[3:, 3:], slam.covariance[3:, 3:])
    assert np.all(other.covariance[:3, 3:] == 0.0)


def test_load_map_errors_name_the_file(tmp_path):
    bad = tmp_path / 'x.npz'
    bad.write_bytes(b'not a zip')
    with pytest.raises(ValueError, match='x.npz: not a landmark_nav map file'):
        load_map(bad)
    with pytest.raises(ValueError, match='missing.npz: no such map file'):
        load_map(tmp_path / 'missing.npz')
    np.savez(tmp_path / 'other.npz', a=np.zeros(3))
    with pytest.raises(ValueError, match='other.npz: not a landmark_nav map file'):
        load_map(tmp_path / 'other.npz')
    slam, _ = mapped_filter()
    m = slam.export_map()
    arrays = {k: getattr(m, k) for k in ('ids', 'kinds', 'means', 'covariance', 'ends',
                                         'bisectors', 'openings', 'n_openings', 'hits',
                                         'max_seen')}
    arrays['means'] = arrays['means'][:3]
    np.savez(tmp_path / 'short.npz', format=np.array('landmark_nav.slam_map'),
             version=np.int64(1), next_id=np.int64(5), **arrays)
    with pytest.raises(ValueError, match=r'short.npz: SlamMap.means has shape \(3, 2\)'):
        load_map(tmp_path / 'short.npz')
    with pytest.raises(ValueError, match='ids are not unique'):
        SlamMap(**{**arrays, 'means': m.means, 'ids': np.zeros(5, dtype=np.int64)},
                next_id=5)


def test_localization_mode_tracks_without_adding_landmarks(tmp_path):
    slam, pts = mapped_filter()
    path = save_map(tmp_path / 'm.npz', slam.export_map())
    loc = EkfSlam(SlamParams(mode='localization', confirm_hits=1, confirm_window=1))
    start = np.array([0.5, 0.2, 0.1])
    guess = start + np.array([0.05, -0.04, 0.02])  # the user's start pose is a little off
    loc.load_map(load_map(path), guess, np.diag([0.1 ** 2, 0.1 ** 2, 0.05 ** 2]))
    unknown = np.array([[1.0, -3.0]])  # a corner that is not in the map
    truth = start.copy()
    for k in range(15):
        if k:
            truth = compose(truth, np.array([0.05, 0.0, 0.01]))
            loc.predict(np.array([0.05, 0.0, 0.01]), np.diag([1e-6, 1e-6, 1e-6]))
        res = loc.update(observe(truth, np.vstack([pts, unknown])), rs(5))
        assert res.status[4] == 'rejected' and res.reason[4] == 'localization'
        assert loc.num_landmarks == 5 and loc.candidates == []
    assert np.hypot(*(loc.pose[:2] - truth[:2])) < 0.01
    assert abs(loc.pose[2] - truth[2]) < math.radians(0.3)
    # A reset in localization mode keeps the map (starts again at the given pose).
    loc.reset(truth)
    assert loc.num_landmarks == 5
    assert loc.pose == pytest.approx(truth)


def test_load_map_rejects_a_bad_pose_covariance():
    slam, _ = mapped_filter()
    with pytest.raises(ValueError, match='pose_covariance'):
        EkfSlam(SlamParams()).load_map(slam.export_map(), [0, 0, 0], -np.eye(3))
