"""EKF-SLAM observation models of corner and line landmarks and their noise.

The direct model ``h`` (range and bearing of a corner, eqs. 18-20, 37, 50, 53; a line's
``(rho_b, alpha_b)`` from :mod:`.line_landmarks`) with its Jacobians, the covariance of
predicted observations (eq. 52), the inverse model ``g`` that puts an observation in the
map (eqs. 39-40, 45-48) and the segment-wide noise the filter adds to a line's ``R``.
(:mod:`.observations` turns the extractors' features into these observations.)

Noise models
------------
* Observations: ``R`` per observation, either given (e.g. propagated from the corner
  extractor's x-y covariance by :func:`.observations.corners_to_observations`) or the default
  ``diag(sigma_range^2, sigma_bearing^2)`` (eq. 22). The filter uses
  ``R_eff = r_scale R + diag(range_floor^2 + f^2, bearing_floor^2 + f^2 / r^2)`` with
  ``f = position_floor``. On the simulated office (seeds 10-29, 49 475 corners not seen
  grazing, errors against the true corner seen from the true pose) the extractor's
  first-order covariance alone gives a mean squared Mahalanobis error of 3.12 (median 1.81)
  against 2 (1.39) for 2 degrees of freedom, with a heavy tail from corners closer than about
  1 m. Part of the error persists (seeds 1 and 9): the errors of one corner are correlated
  (0.1 in range, 0.2 across the beam) even 50 scans apart, and the two corners of the
  cabinet recess are off by 3-6 mm on average in both runs (arm-fit biases that depend on
  the viewpoint, not on the noise), which a white-noise model would average away. The
  position floor is an isotropic Cartesian error of the corner standing for them; the
  default 3 mm brings the mean to 1.90 (median 1.10). It weighs most on the bearing of close
  corners, which would otherwise turn such a bias into a large heading correction. Without
  a floor the filter is optimistic (office seeds 0-9: mean robot NEES 3.6, three seeds map a
  corner twice; with the former 5 mm/sqrt(m) odometry noise three seeds lose track); the
  former 5 mm floor made ``R_eff`` twice too large (mean 1.29) and, with 5 mm/sqrt(m)
  odometry noise, the robot NEES pessimistic (mean 1.8 instead of 3).
* Lines: the extractor's ``(rho, alpha)`` covariance is a least-squares fit covariance of
  independent beams, so it shrinks with the number of beams; errors common to a segment's
  beams do not (a wall that is not straight, the laser's range bias, mixed returns at the
  ends). ``R_eff = R + line_end_covariance(z, ends, line_floor)``: independent offsets of
  std ``line_floor`` of the segment's two ends along its normal
  (:func:`.line_landmarks.line_end_covariance`; 1 cm is the order of a SICK LMS2xx's
  stated systematic range error). On the Carmen logs (each mapped line's observations put
  in the map with the reference poses) the spread about the line is about 1 cm at the
  middle of the segment and 0.2-0.8 deg in direction (seattle; shorter segments more),
  against a stated std of 2-3 mm and 0.04-0.45 deg: the median squared Mahalanobis error is
  31-93 instead of 2 on the six logs, and 8-30 % of the updates have a joint NIS above its
  95 % bound; with ``line_floor = 0.01`` 4-13 % (benchmarks/bench_slam_real.py diagnose).
  The default is 0 (off): over drift seeds 1-2 of the six logs it did not improve ATE or
  RPE (benchmarks/bench_slam_real.py evaluate).
  A fixed floor does not carry from one log to another: the segment-wide error grows with
  how much the beams scatter about the line (a cluttered, uneven wall moves the fit as a
  whole). ``line_residual_factor = k`` gives each segment end offsets of std ``k s`` with
  ``s`` the segment's own unbiased residual std
  (:attr:`.line_landmarks.LineObservations.residual_std`, 5-20 mm median per Carmen log),
  in quadrature with ``line_floor``. With
  the observations the filter associated (drift seed 0), put in the map with the reference
  poses, the median squared Mahalanobis error over the six logs pooled is 5.0 at ``k = 1``,
  1.47 at ``k = 2`` and 0.96 at ``k = 2.5`` (chi-square median 1.39), per log 0.80-2.00 at
  ``k = 2``, against 0.78-4.57 for the fixed floor of 2 cm, which matches the pooled median
  as well. Run with ``k = 2`` (drift seed 0; seed 1 in brackets): line error 1.3-2.4
  [1.2-3.1] (2 expected; the reference poses' own error is in it), updates with a joint NIS
  above the 95 % bound 1.2-4.7 % [1.0-6.5 %] (was 8-30 % [9-28 %]),
  SE(2) ATE ratio to odometry median 0.25 (was 0.34) over drift seeds 0-1, reference inside
  the 95 % ellipse on a median 13 % of the steps (was 5 %), but RPE over 1 m median 2.8x
  the odometry's (was 2.1x; worst 5.0x, was 8.0x). The robot NEES stays far above 3 (the
  heading inconsistency of :mod:`.consistent_linearisation`), so ``k`` is 0 (off) by default.
  Grazing incidence: with ``k = 2`` the line observations seen less than 15 deg between beam
  and wall still have a median squared Mahalanobis error of 1.8-12 on the Carmen logs
  (0.9-3.5 at 15-60 deg; perfect odometry, reference poses). A beam of angular spread
  ``delta`` returns from a spot of std ``r delta`` across it, which on a wall at incidence
  ``theta`` spans ranges: effective range noise ``sigma_r^2 + (r delta / tan(theta))^2``,
  along the wall's normal ``delta r cos(theta) = delta |t|`` (``t``: the point's position
  along the line from the foot point). ``line_beam_width = delta`` adds it segment-wide at
  the two ends (:func:`.line_landmarks.line_footprint_covariance`; off by default, README.md at
  commit 67eb6cc "EKF-SLAM" for the measured effect).

Line landmarks
--------------
A landmark is a corner (``x, y``) or a line (``rho, alpha``, Hessian normal form, corner
chapter eq. 5), both in two state slots, so the state layout (:mod:`.ekf_slam`), the
prediction, the batch update and JCBB are shared; :attr:`.ekf_slam.EkfSlam.landmark_kinds`
tells them apart and :attr:`.ekf_slam.EkfSlam.line_ends` keeps each line's seen extent (map
frame; display and association only). :func:`observation_model`,
:func:`feature_initialization` and :func:`.map_management.augment_map` dispatch per kind to
:mod:`.line_landmarks` (model, Jacobians and the mount transform of the extractor's
covariance). Association: an observation pairs only with a landmark of its kind; a line only
with a line seen from its front (predicted ``rho_b > 0``) whose extent overlaps the observed
segment (endpoints put in the map with the predicted pose; ``line_extent_sigmas = k``, off
by default, widens the landmark's extent at both ends by ``k`` times the robot's position
std along the line), then the same chi-square gate (eq. 55) decides; JCBB tests the joint
compatibility of the mixed hypothesis. A matched line's extent grows by the observed
segment; candidates of lines work as those of corners (with the extent test). The corner
floors of ``R_eff`` do not apply to lines. ``landmarks: corners|lines|both`` is chosen by
what the caller passes (:func:`.features.extract_scan_features`).
"""

from typing import Optional, Tuple

import numpy as np

from ._linalg import _wrap
from .line_landmarks import (line_end_covariance, line_footprint_covariance,
                             line_initialization, line_observation_model)
from .slam_params import LINE, SlamParams


def line_noise_covariance(params: SlamParams, z: np.ndarray, ends: np.ndarray,
                          residual_std: Optional[np.ndarray] = None) -> np.ndarray:
    """Return the segment-wide ``(rho, alpha)`` covariance the filter adds to line ``R``.

    The terms of ``line_floor``, ``line_residual_factor`` (with each segment's residual std;
    None or NaN: no such term) and ``line_beam_width`` (module docstring, "Noise models").

    Args:
        params: The filter parameters.
        z: (L, 2) line observations ``(rho, alpha)`` in the frame of ``ends``.
        ends: (L, 2, 2) their segments' endpoints.
        residual_std: Optional (L,) residual std of each segment [m].

    Returns:
        (L, 2, 2) covariances to add (zeros when every term is off).
    """
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    ends = np.asarray(ends, dtype=float).reshape(-1, 2, 2)
    out = np.zeros((z.shape[0], 2, 2))
    var = np.full(z.shape[0], params.line_floor ** 2)
    if params.line_residual_factor > 0.0 and residual_std is not None:
        res = np.nan_to_num(np.asarray(residual_std, dtype=float).reshape(-1))
        var += (params.line_residual_factor * res) ** 2
    if np.any(var > 0.0):
        out += var[:, None, None] * line_end_covariance(z, ends, 1.0)
    if params.line_beam_width > 0.0:
        out += line_footprint_covariance(z, ends, params.line_beam_width)
    return out


def observation_model(x: np.ndarray, index: np.ndarray, kind: Optional[np.ndarray] = None
                      ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted observations of landmarks and their Jacobians (corners and lines).

    Corners (``kind`` 0, or ``kind`` None) are seen as range and bearing; lines (``kind``
    1) as ``(rho_b, alpha_b)`` (:func:`.line_landmarks.line_observation_model`). In both
    the second component is an angle (wrapped in innovations).

    ``r = sqrt(dx^2 + dy^2)`` (eq. 19), ``theta = atan2(dy, dx) - psi_r`` (eq. 20) with
    ``(dx, dy) = (x_i - x_r, y_i - y_r)``; eq. 53 splits ``H`` into::

        H_r  = d h / d(x_r, y_r, psi_r) = [[-dx/r, -dy/r, 0], [dy/r^2, -dx/r^2, -1]]
        H_Fj = d h / d(x_i, y_i)        = [[ dx/r,  dy/r],    [-dy/r^2,  dx/r^2]]

    Args:
        x: (3 + 2N,) state.
        index: (K,) landmark indices (0-based positions in the state).
        kind: Optional (K,) kind of each indexed landmark (:data:`CORNER` / :data:`LINE`).

    Returns:
        ``(zhat (K, 2), H_r (K, 2, 3), H_F (K, 2, 2))`` (eqs. 37, 50, 53).
    """
    if kind is not None and np.any(kind == LINE):
        with np.errstate(divide='ignore', invalid='ignore'):  # rows overwritten below
            zhat, hr, hf = _corner_model(x, index)
        ln = np.flatnonzero(kind == LINE)
        zl, hrl, hfl = line_observation_model(x[:3], x[3:].reshape(-1, 2)[index[ln]])
        zhat[ln], hr[ln], hf[ln] = zl, hrl, hfl
        return zhat, hr, hf
    return _corner_model(x, index)


def _corner_model(x: np.ndarray, index: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Range-bearing model of :func:`observation_model` for every indexed landmark."""
    lm = x[3:].reshape(-1, 2)[index]
    dx = lm[:, 0] - x[0]
    dy = lm[:, 1] - x[1]
    q = dx * dx + dy * dy
    r = np.sqrt(q)
    zhat = np.empty((index.size, 2))
    zhat[:, 0] = r  # eq. 19
    zhat[:, 1] = _wrap(np.arctan2(dy, dx) - x[2])  # eq. 20
    hf = np.empty((index.size, 2, 2))
    hf[:, 0, 0], hf[:, 0, 1] = dx / r, dy / r
    hf[:, 1, 0], hf[:, 1, 1] = -dy / q, dx / q
    hr = np.zeros((index.size, 2, 3))
    hr[:, :, :2] = -hf
    hr[:, 1, 2] = -1.0
    return zhat, hr, hf


def _landmark_cols(index: np.ndarray) -> np.ndarray:
    """(K, 2) state columns of landmarks ``index``."""
    return 3 + 2 * index[:, None] + np.arange(2)[None, :]


def predicted_observation_covariance(p: np.ndarray, index: np.ndarray, hr: np.ndarray,
                                     hf: np.ndarray) -> np.ndarray:
    """``H P H^T`` per landmark (eq. 52 without ``R``), vectorised over landmarks.

    Args:
        p: Covariance of the state.
        index: (K,) landmark indices.
        hr: (K, 2, 3) robot Jacobians.
        hf: (K, 2, 2) landmark Jacobians.

    Returns:
        (K, 2, 2) covariances of the predicted observations.
    """
    cols = _landmark_cols(index)
    p_rf = np.transpose(p[:3][:, cols], (1, 0, 2))  # (K, 3, 2)
    p_ff = p[cols[:, :, None], cols[:, None, :]]  # (K, 2, 2)
    hft = np.transpose(hf, (0, 2, 1))
    cross = hr @ p_rf @ hft
    c = hr @ p[:3, :3] @ np.transpose(hr, (0, 2, 1)) + cross + np.transpose(cross, (0, 2, 1))
    c += hf @ p_ff @ hft
    return c


def joint_observation_covariance(p: np.ndarray, index: np.ndarray, hr: np.ndarray,
                                 hf: np.ndarray) -> np.ndarray:
    """Joint covariance ``H P H^T`` of several predicted observations (for JCBB).

    Args:
        p: Covariance of the state.
        index: (K,) landmark indices.
        hr: (K, 2, 3) robot Jacobians.
        hf: (K, 2, 2) landmark Jacobians.

    Returns:
        (K, 2, K, 2) covariance (block (a, b) = cov(zhat_a, zhat_b)).
    """
    h = _dense_h(p.shape[0], index, hr, hf)
    return (h @ p @ h.T).reshape(index.size, 2, index.size, 2)


def _dense_h(n: int, index: np.ndarray, hr: np.ndarray, hf: np.ndarray) -> np.ndarray:
    """Dense (2K, n) observation Jacobian (eq. 53)."""
    k = index.size
    h = np.zeros((k, 2, n))
    h[:, :, :3] = hr
    cols = _landmark_cols(index)
    rows = np.arange(k)
    h[rows, :, cols[:, 0]] = hf[:, :, 0]
    h[rows, :, cols[:, 1]] = hf[:, :, 1]
    return h.reshape(2 * k, n)


def _relative_points(x: np.ndarray, index: np.ndarray, kind: Optional[np.ndarray]
                     ) -> np.ndarray:
    """(K, 2) landmark positions relative to the robot (a line: its foot point)."""
    lm = x[3:].reshape(-1, 2)[index]
    rel = lm - x[:2]
    if kind is not None and np.any(kind == LINE):
        ln = np.flatnonzero(kind == LINE)
        a = lm[ln, 1]
        n = np.column_stack([np.cos(a), np.sin(a)])
        rho_b = lm[ln, 0] - n @ x[:2]
        rel[ln] = rho_b[:, None] * n
    return rel


def feature_initialization(pose: np.ndarray, z: np.ndarray, kind: Optional[np.ndarray] = None
                           ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return new landmark positions and their Jacobians (eqs. 39-40, 45-48).

    Args:
        pose: (3,) robot pose [x_r, y_r, psi_r].
        z: (L, 2) observations [r, theta] (lines: [rho_b, alpha_b]).
        kind: Optional (L,) kinds (None: corners); lines use
            :func:`.line_landmarks.line_initialization`.

    Returns:
        ``(g (L, 2), G_r (L, 2, 3), G_z (L, 2, 2))``.
    """
    if kind is not None and np.any(kind == LINE):
        g, gr, gz = feature_initialization(pose, z)
        ln = np.flatnonzero(kind == LINE)
        g[ln], gr[ln], gz[ln] = line_initialization(pose, z[ln])
        return g, gr, gz
    rng, a = z[:, 0], z[:, 1] + pose[2]
    c, s = np.cos(a), np.sin(a)
    g = np.column_stack([pose[0] + rng * c, pose[1] + rng * s])  # eq. 40
    gr = np.zeros((z.shape[0], 2, 3))
    gr[:, 0, 0] = gr[:, 1, 1] = 1.0
    gr[:, 0, 2], gr[:, 1, 2] = -rng * s, rng * c  # eq. 46
    gz = np.empty((z.shape[0], 2, 2))
    gz[:, 0, 0], gz[:, 0, 1] = c, -rng * s  # eq. 48
    gz[:, 1, 0], gz[:, 1, 1] = s, rng * c
    return g, gr, gz
