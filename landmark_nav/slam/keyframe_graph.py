"""Graph back end: a keyframe pose graph optimised incrementally by iSAM2 (ROS free).

Keyframes: a scan becomes a keyframe when the odometry since the last keyframe has moved
``keyframe_distance`` or turned ``keyframe_turn`` (slam_toolbox's
``minimum_travel_distance`` / ``minimum_travel_heading``); the other scans are placed by
the odometry from their keyframe and cost nothing else.

Factors (all ``BetweenFactorPose2`` of GTSAM; Dellaert and Kaess, "Factor graphs for robot
perception", 2017):

* a prior on the first keyframe (the first odometry pose, ``prior_sigmas``);
* between consecutive keyframes, the odometry increment ``u = (-)o_a (+) o_b`` (eq. 13 of
  the corner chapter) with the noise model's ``U``
  (:func:`~landmark_nav.slam.prediction.odometry_noise`), replaced by the scan-matched
  motion fused with it (:func:`~landmark_nav.slam.scan_matching.fused_scan_motion`: the
  new keyframe's scan matched by point-to-line ICP onto the previous keyframes' scans,
  tested against the odometry) when that motion passes the test, as the EKF's front end
  does between scans. The test's noise of the scan-matched motion has floors, 4 cm per
  axis and 0.01 rad: the ICP's error between keyframes against the Carmen references
  (aces and fhw, drift seed 2: 5.5 cm RMS in position, 0.44-0.58 deg in heading). Without
  them a turn in place, whose motion model allows millimetres of translation, refuses
  the ICP's correct turn for its few centimetres of translation, and the odometry's turn
  (13 deg off on aces seed 2) enters the chain. When the test still refuses the scans,
  the scan is searched and verified as a loop is and, if it passes and its translation
  agrees with the odometry's, that motion is the factor (:meth:`KeyframeGraph._verified_motion`);
* loop closures (:mod:`.loop_closure`): the current keyframe relative to an old one, from
  the verified match, with the fit's information and a Cauchy kernel (``loop_kernel``), so
  that a closure the verification let through against the rest of the graph is
  down-weighted rather than believed.

A factor's covariance ``C`` is stated for the increment ``[dx, dy, dpsi]`` in the frame of
the first keyframe; GTSAM's ``BetweenFactorPose2`` measures its error in the tangent space
at the measured increment ``z`` (the frame of the second keyframe, to first order), so
``C`` is rotated by ``-z_psi`` in translation.

Optimisation: GTSAM's iSAM2 (Kaess et al., "iSAM2: incremental smoothing and mapping using
the Bayes tree", IJRR 2012), updated once per keyframe, ``relinearize_skip`` 1, with
``loop_iterations`` more updates after a loop closure (each relinearises what moved).
Covariance: iSAM2's marginal of the keyframe (GTSAM states it in the pose's own frame; it is
rotated into the map frame) plus the odometry's ``U`` since the keyframe, rotated likewise.
"""

from dataclasses import dataclass, field
import math
from typing import Dict, List, Optional, Tuple

import gtsam
from landmark_nav.geometry import (compose, compose_jacobians, inverse, relative,
                                   transform_points, wrap_angle)
from landmark_nav.slam.consistency import chi2_gate
from landmark_nav.slam.loop_closure import LoopCounts, LoopParams, verify_loop
from landmark_nav.slam.prediction import odometry_noise
from landmark_nav.slam.scan_matching import fit_information, fused_scan_motion, larger_motion
from landmark_nav.slam.slam_params import OdometryNoise
import numpy as np


@dataclass(frozen=True)
class GraphParams:
    """Parameters of the graph back end (module docstring).

    Attributes:
        keyframe_distance: Odometry travel that makes a keyframe [m].
        keyframe_turn: Odometry turn that makes a keyframe [rad].
        max_range: Returns at or beyond this are not used [m].
        match_keyframes: Keyframes in the local submap a new keyframe is matched onto.
        scan_noise: Noise model of the scan-matched motion's test (as the front end's
            ``scan_matching_noise``), with floors of the point-to-line ICP's own error
            between keyframes measured against the Carmen references (module docstring).
        scan_accept: Confidence of that test.
        fit_pairs: Independent residuals an ICP fit is worth
            (:func:`~landmark_nav.slam.scan_matching.fit_information`).
        side_starts: ICP's extra starts in heading stds (``scan_matching_side_starts``).
        prior_sigmas: Std of the first keyframe's prior ``[x, y, yaw]``.
        loop_kernel: Cauchy kernel width of loop factors (in whitened residual units).
        loop_iterations: Extra iSAM2 updates after a loop closure.
        loop_floor: Least std of a loop factor ``[x, y, yaw]`` (an ICP fit on many pairs
            claims less than the submap's own error).
        loops: Try to close loops.
        loop: Loop closure parameters.
    """

    keyframe_distance: float = 0.5
    keyframe_turn: float = 0.5
    max_range: float = 20.0
    match_keyframes: int = 3
    scan_noise: OdometryNoise = OdometryNoise(0.05, 0.03, 0.06, 0.04, 0.01)
    scan_accept: float = 0.999
    fit_pairs: float = 0.3
    side_starts: float = 2.5
    prior_sigmas: tuple = (1e-3, 1e-3, 1e-4)
    loop_kernel: float = 3.0
    loop_iterations: int = 3
    loop_floor: tuple = (0.03, 0.03, math.radians(0.5))
    loops: bool = True
    loop: LoopParams = field(default_factory=LoopParams)

    def __post_init__(self) -> None:
        """Validate the values (one line naming the bad one)."""
        for name in ('keyframe_distance', 'keyframe_turn', 'max_range', 'fit_pairs',
                     'loop_kernel'):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f'GraphParams.{name} must be a finite number > 0, got {v!r}')
        if not (isinstance(self.match_keyframes, int) and self.match_keyframes >= 1):
            raise ValueError('GraphParams.match_keyframes must be an integer >= 1, got '
                             f'{self.match_keyframes!r}')
        if not 0.0 < self.scan_accept < 1.0:
            raise ValueError('GraphParams.scan_accept must be a probability in (0, 1), got '
                             f'{self.scan_accept!r}')


def _noise(cov: np.ndarray, z: np.ndarray):
    """Return GTSAM's Gaussian noise of an increment covariance (module docstring)."""
    c, s = math.cos(z[2]), math.sin(z[2])
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # R(-z_psi) in x, y
    local = rot @ cov @ rot.T
    return gtsam.noiseModel.Gaussian.Covariance(0.5 * (local + local.T))


def _to_map(cov: np.ndarray, yaw: float) -> np.ndarray:
    """Rotate a pose covariance from the pose's frame (GTSAM's) into the map frame."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ cov @ rot.T


@dataclass
class Keyframe:
    """One keyframe: its odometry pose, scan (laser frame) and path length."""

    odometry: np.ndarray
    points: np.ndarray
    travelled: float
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))


class KeyframeGraph:
    """The graph back end (module docstring).

    Args:
        mount: (3,) laser pose in base_link.
        odometry: The odometry's noise model.
        params: The parameters.
    """

    def __init__(self, mount, odometry: OdometryNoise,
                 params: Optional[GraphParams] = None) -> None:
        self.mount = np.asarray(mount, dtype=float)
        self.noise = odometry
        self.params = params or GraphParams()
        self._isam = gtsam.ISAM2(self._isam_params())
        self.keyframes: List[Keyframe] = []
        self.estimates = np.zeros((0, 3))
        self.loop_counts = LoopCounts()
        #: ``(old keyframe, new keyframe, accepted, reason)`` of every loop proposed.
        self.loop_log: List[Tuple[int, int, bool, str]] = []
        #: Factors between consecutive keyframes: ``scan_matching``, ``scan_verified`` or
        #: ``odometry``.
        self.motions: Dict[str, int] = {'scan_matching': 0, 'scan_verified': 0, 'odometry': 0}
        self.icp_restarts: Dict[str, int] = {}
        self._gate = chi2_gate(3, self.params.scan_accept)
        self._gate_xy = chi2_gate(2, self.params.scan_accept)

    @staticmethod
    def _isam_params():
        p = gtsam.ISAM2Params()
        p.setRelinearizeThreshold(0.01)
        p.relinearizeSkip = 1
        return p

    # ------------------------------------------------------------------ input
    def add_scan(self, odometry_pose, points: np.ndarray) -> bool:
        """Add one scan with the odometry pose at its stamp; return whether it made a keyframe.

        Args:
            odometry_pose: (3,) odometry pose at the scan's stamp.
            points: (N, 2) the scan's returns in the laser frame [m] (rows not finite are
                left out).

        Raises:
            ValueError: An odometry pose that is not three finite numbers (names it).
        """
        o = np.asarray(odometry_pose, dtype=float).reshape(-1)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise ValueError(f'KeyframeGraph.add_scan: odometry pose must be 3 finite numbers, '
                             f'got {odometry_pose!r}')
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if not self.keyframes:
            self._first(o, pts)
            return True
        last = self.keyframes[-1]
        u = relative(last.odometry, o)
        if math.hypot(u[0], u[1]) < self.params.keyframe_distance and \
                abs(u[2]) < self.params.keyframe_turn:
            return False
        self._add_keyframe(o, pts, u)
        return True

    def _first(self, o: np.ndarray, pts: np.ndarray) -> None:
        prior = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(self.params.prior_sigmas))
        g = gtsam.NonlinearFactorGraph()
        g.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*o), prior))
        v = gtsam.Values()
        v.insert(0, gtsam.Pose2(*o))
        self._isam.update(g, v)
        self.keyframes.append(Keyframe(o, pts, 0.0, np.diag(np.square(self.params.prior_sigmas))))
        self.estimates = o[None, :].copy()

    def _add_keyframe(self, o: np.ndarray, pts: np.ndarray, u: np.ndarray) -> None:
        k = len(self.keyframes)
        z, cov = self._motion(pts, u)
        g = gtsam.NonlinearFactorGraph()
        g.add(gtsam.BetweenFactorPose2(k - 1, k, gtsam.Pose2(*z), _noise(cov, z)))
        v = gtsam.Values()
        v.insert(k, gtsam.Pose2(*compose(self.estimates[k - 1], z)))
        self._isam.update(g, v)
        travelled = self.keyframes[-1].travelled + math.hypot(z[0], z[1])
        self.keyframes.append(Keyframe(o, pts, travelled))
        self._read_estimates()
        if self.params.loops:
            self._close_loop(k)
        self.keyframes[k].covariance = self.marginal(k)

    def _motion(self, pts: np.ndarray, u: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return the factor between the last keyframe and a new one: ``(z, C)``."""
        p = self.params
        k = len(self.keyframes)
        previous = self._submap_points(range(max(0, k - p.match_keyframes), k), k - 1)
        cov_fn = (lambda m: odometry_noise(m, self.noise))
        fused = None
        if len(previous) and len(pts):
            fused = fused_scan_motion(previous, pts, u, cov_fn, self.mount, self._gate,
                                      lambda m: odometry_noise(m, p.scan_noise), p.fit_pairs,
                                      self.icp_restarts, p.side_starts)
        if fused is None and len(previous) and len(pts):
            verified = self._verified_motion(previous, pts, u)
            if verified is not None:
                self.motions['scan_verified'] += 1
                return verified
        if fused is None:
            self.motions['odometry'] += 1
            return u, odometry_noise(u, self.noise)
        self.motions['scan_matching'] += 1
        return fused[0], fused[1]

    def _verified_motion(self, previous: np.ndarray, pts: np.ndarray,
                         u: np.ndarray) -> Optional[Tuple[np.ndarray, np.ndarray]]:
        """Return the scans' motion verified as a loop is, when the odometry refuted it.

        The scan test refuses the scans' motion when it and the odometry's differ by more
        than the odometry's model allows; either may be wrong. Here the scan is placed on
        the previous keyframes' scans by loop closure's search and verification
        (:func:`.loop_closure.verify_loop` without the free-space check, whose trail is
        this same chain): an exhaustive search around the odometry's motion over the loop
        window's largest heading half width and, in translation, ``sqrt(gate)`` stds of
        the odometry's (at least the loop window's smallest), ICP, and the score, fit and
        ambiguity tests.
        What odometry gets wrong by more than its model is the turn (a wheel slips);
        its translation still holds: the verified motion's translation must agree with
        the odometry's at the scan test's confidence (chi-square on 2 degrees of freedom,
        ``U + V`` in translation as in the scan test), which refuses a match that slid
        along a corridor. A motion that passes is the factor, with the fit's information
        alone (the odometry's turn it contradicts is left out); None: the odometry stays
        the factor.
        """
        lp = self.params.loop
        guess = compose(compose(inverse(self.mount), u), self.mount)
        cov_u = odometry_noise(u, self.noise)
        wxy = max(lp.window_xy[0], math.sqrt(self._gate * max(
            float(np.linalg.eigvalsh(cov_u[:2, :2]).max()), 0.0)))
        res = verify_loop(pts, previous, guess, wxy, lp.window_yaw[1], lp,
                          check_free_space=False)
        if not res.accepted:
            return None
        z = compose(compose(self.mount, res.pose), inverse(self.mount))
        at = larger_motion(u, z)
        c = (odometry_noise(at, self.noise) + odometry_noise(at, self.params.scan_noise))[:2, :2]
        d = z[:2] - u[:2]
        if float(d @ np.linalg.solve(c, d)) > self._gate_xy:
            return None
        try:
            cov = np.linalg.inv(fit_information(res.fit, self.mount, self.params.fit_pairs))
        except np.linalg.LinAlgError:
            return None
        return z, cov

    # ------------------------------------------------------------------ loops
    def _laser_pose(self, i: int) -> np.ndarray:
        return compose(self.estimates[i], self.mount)

    def _submap_points(self, indices, anchor: int) -> np.ndarray:
        """Return the keyframes' points in the laser frame of keyframe ``anchor``."""
        frame = inverse(self._laser_pose(anchor))
        out = [transform_points(compose(frame, self._laser_pose(i)), self.keyframes[i].points)
               for i in indices if len(self.keyframes[i].points)]
        return np.vstack(out) if out else np.zeros((0, 2))

    def _window(self, k: int) -> Tuple[float, float]:
        """Search half widths from keyframe ``k``'s marginal (:mod:`.loop_closure`)."""
        lp = self.params.loop
        cov = _to_map(self.marginal(k), float(self.estimates[k, 2]))
        sxy = math.sqrt(max(float(np.linalg.eigvalsh(cov[:2, :2]).max()), 0.0))
        syaw = math.sqrt(max(float(cov[2, 2]), 0.0))
        wxy = min(max(lp.window_sigmas * sxy, lp.window_xy[0]), lp.window_xy[1])
        wyaw = min(max(lp.window_sigmas * syaw, lp.window_yaw[0]), lp.window_yaw[1])
        return wxy, wyaw

    def _close_loop(self, k: int) -> None:
        lp = self.params.loop
        kf = self.keyframes
        old = [i for i in range(k) if kf[k].travelled - kf[i].travelled >= lp.min_separation_m]
        if not old or len(kf[k].points) < lp.min_trail_points:
            return
        wxy, wyaw = self._window(k)
        d = np.hypot(*(self.estimates[old, :2] - self.estimates[k, :2]).T)
        near = np.asarray(old)[d <= wxy + lp.neighbourhood_m]
        if len(near) == 0:
            return
        anchor = int(near[np.argmin(d[d <= wxy + lp.neighbourhood_m])])
        # The submap: the anchor's stretch of the chain (consecutive keyframes are placed
        # consistently by their scan-matched factors; keyframes of other passes near the
        # same place carry those passes' drift and would blur it).
        half = lp.submap_keyframes // 2
        near = np.array([i for i in range(max(0, anchor - half), anchor + half + 1)
                         if kf[k].travelled - kf[i].travelled >= lp.min_separation_m])
        submap = self._submap_points(near, anchor)
        frame = inverse(self._laser_pose(anchor))
        origins = np.array([compose(frame, self._laser_pose(i))[:2] for i in near])
        hits = [transform_points(compose(frame, self._laser_pose(i)), kf[i].points)
                for i in near]
        trail = [self._submap_points([i], k) for i in range(max(0, k - lp.trail_keyframes), k)]
        guess = compose(frame, self._laser_pose(k))
        self.loop_counts.proposed += 1
        res = verify_loop(kf[k].points, submap, guess, wxy, wyaw, lp, trail, origins, hits)
        self.loop_log.append((anchor, k, res.accepted, res.reason))
        if not res.accepted:
            self.loop_counts.refuse(res.reason)
            return
        self.loop_counts.accepted += 1
        self._add_loop(anchor, k, res)

    def _add_loop(self, anchor: int, k: int, res) -> None:
        p = self.params
        z = compose(compose(self.mount, res.pose), inverse(self.mount))
        info = fit_information(res.fit, self.mount, p.fit_pairs)
        floor = np.diag(np.square(p.loop_floor))
        try:
            cov = np.linalg.inv(info) + floor
        except np.linalg.LinAlgError:
            cov = floor * 100.0
        robust = gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Cauchy.Create(p.loop_kernel), _noise(cov, z))
        g = gtsam.NonlinearFactorGraph()
        g.add(gtsam.BetweenFactorPose2(anchor, k, gtsam.Pose2(*z), robust))
        self._isam.update(g, gtsam.Values())
        for _ in range(p.loop_iterations):
            self._isam.update()
        self._read_estimates()

    # ------------------------------------------------------------------ output
    def _read_estimates(self) -> None:
        est = self._isam.calculateEstimate()
        self.estimates = np.array([[q.x(), q.y(), q.theta()]
                                   for q in (est.atPose2(i) for i in range(len(self.keyframes)))])

    def marginal(self, i: int) -> np.ndarray:
        """Return keyframe ``i``'s marginal covariance in GTSAM's frame (the pose's own)."""
        return np.asarray(self._isam.marginalCovariance(i), dtype=float)

    def pose_at(self, keyframe: int, odometry_pose,
                covariance: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
        """Return a scan's pose and covariance (map frame) from its keyframe and odometry.

        The keyframe's estimate composed with the odometry since it; the covariance the
        keyframe's (``covariance`` in the map frame, e.g. from :meth:`final_covariances`;
        None: its marginal as stored when the keyframe was made, online) and the
        odometry's ``U`` of that motion, composed (eqs. 27-30 of the corner chapter).
        """
        kf = self.keyframes[keyframe]
        u = relative(kf.odometry, np.asarray(odometry_pose, dtype=float))
        pose = compose(self.estimates[keyframe], u)
        pose[2] = wrap_angle(pose[2])
        j1, j2 = compose_jacobians(self.estimates[keyframe], u)
        p = (_to_map(kf.covariance, float(self.estimates[keyframe, 2])) if covariance is None
             else np.asarray(covariance, dtype=float))
        cov = j1 @ p @ j1.T + j2 @ odometry_noise(u, self.noise) @ j2.T
        return pose, cov

    def final_covariances(self) -> np.ndarray:
        """Return every keyframe's marginal now (after all loops), in the map frame."""
        return np.array([_to_map(self.marginal(i), float(self.estimates[i, 2]))
                         for i in range(len(self.keyframes))])


__all__ = ['GraphParams', 'Keyframe', 'KeyframeGraph']
