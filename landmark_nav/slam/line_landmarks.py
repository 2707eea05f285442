"""Line landmarks for EKF-SLAM: observation model, initialisation, extents.

A line landmark is the infinite line ``x cos(alpha) + y sin(alpha) = rho`` in the map frame
(Hessian normal form, corner chapter eq. 5), stored in the state as ``(rho, alpha)`` in the
two slots a corner uses for ``(x, y)``, so the filter's state layout, prediction, batch
update and JCBB serve both kinds; the line chapter plans SLAM "by fusing corners, edges and
line segments" (its section on simultaneous localization and mapping). The segment actually
seen (its two endpoints, in the map frame) is kept beside the state for association and
display; it never enters the state.

Observation model (the role of the corner chapter's eqs. 18-20, 37, 50 and 53 for a line):
a robot at ``(x_r, y_r, psi_r)`` sees the line in base_link as::

    rho_b   = rho - x_r cos(alpha) - y_r sin(alpha)
    alpha_b = alpha - psi_r                                  (wrapped)

    H_r = d(rho_b, alpha_b) / d(x_r, y_r, psi_r) = [[-cos(alpha), -sin(alpha), 0], [0, 0, -1]]
    H_F = d(rho_b, alpha_b) / d(rho, alpha)      = [[1, x_r sin(alpha) - y_r cos(alpha)], [0, 1]]

A wall is seen from its front only: ``rho_b > 0`` (the normal points from the robot to the
line, as the extractor's ``rho >= 0`` convention gives). A landmark whose predicted
``rho_b <= 0`` is behind the robot's side of the wall (e.g. the other face of a partition)
and is never associated.

Initialisation (eqs. 38-48 with ``g`` of a line, the inverse of the model)::

    alpha = alpha_b + psi_r,  rho = rho_b + x_r cos(alpha) + y_r sin(alpha)
    G_r = [[cos(alpha), sin(alpha), -x_r sin(alpha) + y_r cos(alpha)], [0, 0, 1]]
    G_z = [[1, -x_r sin(alpha) + y_r cos(alpha)], [0, 1]]

Measurements: the extractor (:func:`landmark_nav.laser.lines.extract_lines`) gives
``(rho, alpha)`` with their covariance in the laser frame (first-order propagation of the
line chapter's noise model, eqs. 1-7). :func:`lines_to_observations` moves them through the
laser mount (and optionally the sweep motion) with the same rigid-motion rule: a pose
``(t_x, t_y, theta)`` maps a line to ``alpha' = alpha + theta``,
``rho' = rho + t_x cos(alpha') + t_y sin(alpha')`` with Jacobian
``[[1, -t_x sin(alpha') + t_y cos(alpha')], [0, 1]]``.

Extents: the endpoints ``e`` of a segment project to ``t = e . d`` along the line direction
``d = (-sin(alpha), cos(alpha))``; two segments on (statistically) the same line are the same
landmark only if their intervals overlap (:func:`extents_overlap`).
"""

from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import numpy as np

_PI = np.pi
_TWO_PI = 2.0 * np.pi


def _wrap(a):
    return np.mod(a + _PI, _TWO_PI) - _PI


@dataclass(frozen=True, eq=False)
class LineObservations:
    """Line observations of one scan in base_link.

    Attributes:
        z: (L, 2) ``[rho_b (m), alpha_b (rad)]``, ``rho_b > 0``.
        r: (L, 2, 2) covariance of each.
        ends: (L, 2, 2) segment endpoints ``[start, end]`` in base_link [m].
        beams: (L,) middle beam index of each segment (for the sweep motion), or None.
        residual_std: (L,) std of each segment's beams about its fitted line, ``rmse
            sqrt(n / (n - 2))`` [m] (the fit's unbiased residual std; what
            ``SlamParams.line_residual_factor`` scales), or None (unknown: no such term).
    """

    z: np.ndarray
    r: np.ndarray
    ends: np.ndarray
    beams: Optional[np.ndarray] = None
    residual_std: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        """Check the shapes agree."""
        n = np.asarray(self.z).reshape(-1, 2).shape[0]
        if np.asarray(self.r).shape != (n, 2, 2) or np.asarray(self.ends).shape != (n, 2, 2):
            raise ValueError(f'LineObservations: z has {n} rows but r has shape '
                             f'{np.asarray(self.r).shape} and ends {np.asarray(self.ends).shape}'
                             ' (expected (L, 2, 2) each)')
        if self.residual_std is not None and np.asarray(self.residual_std).shape != (n,):
            raise ValueError(f'LineObservations: z has {n} rows but residual_std has shape '
                             f'{np.asarray(self.residual_std).shape} (expected ({n},))')

    def __len__(self) -> int:
        """Return the number of lines."""
        return int(np.asarray(self.z).reshape(-1, 2).shape[0])

    @staticmethod
    def empty() -> 'LineObservations':
        """Return an observation set without lines."""
        return LineObservations(np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))


def transform_lines(pose: np.ndarray, rho: np.ndarray, alpha: np.ndarray,
                    cov: Optional[np.ndarray] = None
                    ) -> Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
    """Express lines given in a frame F in the frame where F sits at ``pose``.

    Args:
        pose: (3,) or (L, 3) pose ``(t_x, t_y, theta)`` of frame F.
        rho: (L,) distances in F.
        alpha: (L,) normal angles in F.
        cov: Optional (L, 2, 2) covariances in F.

    Returns:
        ``(rho', alpha', cov')`` with ``rho' >= 0`` (a line passing the other side of the new
        origin is flipped: ``rho' -> -rho'``, ``alpha' -> alpha' + pi``).
    """
    pose = np.broadcast_to(np.asarray(pose, dtype=float).reshape(-1, 3), (rho.size, 3))
    a = alpha + pose[:, 2]
    c, s = np.cos(a), np.sin(a)
    rho2 = rho + pose[:, 0] * c + pose[:, 1] * s
    out_cov = None
    if cov is not None:
        jac = np.zeros((rho.size, 2, 2))
        jac[:, 0, 0] = 1.0
        jac[:, 0, 1] = -pose[:, 0] * s + pose[:, 1] * c
        jac[:, 1, 1] = 1.0
        out_cov = jac @ cov @ np.transpose(jac, (0, 2, 1))
    flip = rho2 < 0.0
    if np.any(flip):
        rho2 = np.where(flip, -rho2, rho2)
        a = np.where(flip, a + _PI, a)
        if out_cov is not None:  # d(-rho)/d(.) negates the rho row and column
            sign = np.where(flip, -1.0, 1.0)
            out_cov[:, 0, 1] *= sign
            out_cov[:, 1, 0] *= sign
    if out_cov is not None:
        out_cov = 0.5 * (out_cov + np.transpose(out_cov, (0, 2, 1)))
    return rho2, _wrap(a), out_cov


def lines_to_observations(lines: Sequence, mount: Sequence[float] = (0.0, 0.0, 0.0),
                          beam_motion: Optional[np.ndarray] = None,
                          sigma_r: Optional[float] = None) -> LineObservations:
    """Convert laser-frame line segments to base_link observations (module docstring).

    Args:
        lines: :class:`landmark_nav.laser.lines.LineSegment` objects (``rho``, ``alpha``,
            ``covariance``, ``start``, ``end``, ``first_index``, ``last_index``).
        mount: Laser pose ``[x, y, yaw]`` in base_link.
        beam_motion: Optional (L, 3) base_link pose at each line's middle beam time in
            base_link at the scan stamp (sweep motion); None = static.
        sigma_r: The laser's stated range noise [m]. When given, a line whose residuals
            exceed it gets its covariance scaled by the a-posteriori variance factor
            ``max(1, rmse^2 n / ((n - 2) sigma_r^2))`` (least-squares practice: the residual
            variance replaces the a-priori one when the points scatter more than the sensor
            model says, e.g. a wall that is not quite straight).

    Returns:
        The observations (empty for no lines), with each segment's residual std.
    """
    if len(lines) == 0:
        return LineObservations.empty()
    rho = np.array([ln.rho for ln in lines], dtype=float)
    alpha = np.array([ln.alpha for ln in lines], dtype=float)
    cov = np.array([ln.covariance for ln in lines], dtype=float).reshape(-1, 2, 2)
    ends = np.array([[ln.start, ln.end] for ln in lines], dtype=float).reshape(-1, 2, 2)
    beams = np.array([0.5 * (ln.first_index + ln.last_index) for ln in lines])
    n = np.array([ln.num_points for ln in lines], dtype=float)
    rmse = np.array([ln.rmse for ln in lines], dtype=float)
    with np.errstate(divide='ignore', invalid='ignore'):
        residual_std = np.where(n > 2, rmse * np.sqrt(n / np.maximum(n - 2.0, 1.0)), np.nan)
    if sigma_r is not None and sigma_r > 0.0:
        with np.errstate(divide='ignore', invalid='ignore'):
            factor = rmse ** 2 * n / ((n - 2.0) * sigma_r ** 2)
        factor = np.where(np.isfinite(factor) & (n > 2), np.maximum(factor, 1.0), 1.0)
        cov = cov * factor[:, None, None]
    mount = np.asarray(mount, dtype=float).reshape(3)
    rho, alpha, cov = transform_lines(mount, rho, alpha, cov)
    ends = _transform_points(np.broadcast_to(mount, (rho.size, 3)), ends)
    if beam_motion is not None:
        motion = np.asarray(beam_motion, dtype=float).reshape(-1, 3)
        rho, alpha, cov = transform_lines(motion, rho, alpha, cov)
        ends = _transform_points(motion, ends)
    return LineObservations(np.column_stack([rho, alpha]), cov, ends, beams, residual_std)


def _transform_points(pose: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Move (L, 2, 2) point pairs by (L, 3) poses."""
    c, s = np.cos(pose[:, 2])[:, None], np.sin(pose[:, 2])[:, None]
    x, y = pts[..., 0], pts[..., 1]
    return np.stack([pose[:, :1] + c * x - s * y, pose[:, 1:2] + s * x + c * y], axis=-1)


def line_end_covariance(z: np.ndarray, ends: np.ndarray, sigma: float) -> np.ndarray:
    """Covariance of ``(rho, alpha)`` from independent offsets of a segment's two ends.

    The fit covariance of a line (the extractor's, from independent beam errors) shrinks
    with the number of beams; errors common to the beams of a segment do not: a wall that is
    not quite straight, the laser's range bias (a SICK LMS2xx states a systematic error of
    the order of its random one), mixed returns at the ends. They are modelled as offsets
    ``e_1, e_2 ~ N(0, sigma^2)`` of the segment's two ends along the normal, independent
    between the ends, so the segment pivots and shifts as a whole. With ``t_i = end_i . d``
    the ends' positions along the direction ``d = (-sin(alpha), cos(alpha))`` (from the foot
    point of ``rho``) and ``L = t_2 - t_1``, the moved line has::

        d rho   = (t_2 e_1 - t_1 e_2) / L      (the offset interpolated to the foot point)
        d alpha = (e_1 - e_2) / L

    so ``C = sigma^2 J J^T`` with ``J = [[t_2, -t_1], [1, -1]] / L``: at the middle of the
    segment the offset has std ``sigma / sqrt(2)``, the direction ``sqrt(2) sigma / L``.

    Args:
        z: (L, 2) lines ``(rho, alpha)`` in the frame of ``ends``.
        ends: (L, 2, 2) endpoints of each segment.
        sigma: Std of each end's offset [m].

    Returns:
        (L, 2, 2) covariances (zeros where the segment has no length).
    """
    jac, _ = _end_jacobian(z, ends)
    return sigma ** 2 * (jac @ np.transpose(jac, (0, 2, 1)))


def _end_jacobian(z: np.ndarray, ends: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``J`` (L, 2, 2) of ``(rho, alpha)`` on the ends' normal offsets, and ``t``.

    ``t`` (L, 2): the ends' positions along the line from its foot point
    (:func:`line_end_covariance`); ``J`` is zero where the segment has no length.
    """
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    d = np.column_stack([-np.sin(z[:, 1]), np.cos(z[:, 1])])
    t = np.einsum('kij,kj->ki', np.asarray(ends, dtype=float).reshape(-1, 2, 2), d)
    length = t[:, 1] - t[:, 0]
    ok = np.isfinite(length) & (np.abs(length) > 0.0)
    inv = np.where(ok, 1.0 / np.where(ok, length, 1.0), 0.0)
    jac = np.zeros((z.shape[0], 2, 2))
    jac[:, 0, 0], jac[:, 0, 1] = t[:, 1] * inv, -t[:, 0] * inv
    jac[:, 1, 0], jac[:, 1, 1] = inv, -inv
    return jac, t


def line_footprint_covariance(z: np.ndarray, ends: np.ndarray,
                              beam_width: float) -> np.ndarray:
    """Covariance of ``(rho, alpha)`` from the laser beam's footprint at the segment's ends.

    A beam of angular spread ``delta`` (1-sigma, across the beam) at range ``r`` returns from
    somewhere in a spot of std ``r delta`` across the beam. On a wall seen at incidence
    ``theta`` (angle between beam and wall) the spot spans ranges: the effective range
    noise of the beam is ``sigma_eff^2 = sigma_r^2 + (r delta / tan(theta))^2``, the
    extractor's eq.-7 term plus a footprint term that grows without bound at grazing
    incidence. Along the wall's normal the footprint term is
    ``r delta / tan(theta) * sin(theta) = r delta cos(theta) = delta |t|``, with ``t`` the
    point's position along the line from the foot point of the sensor's perpendicular
    (``r cos(theta) = |t|``, ``r sin(theta) = rho``). The part of it that the fit's
    independent-beam covariance does not average away is taken segment-wide, as the
    offsets of :func:`line_end_covariance`, with the std of each end its own
    ``delta |t_i|`` (independent between the ends): ``C = J diag(delta^2 t_1^2,
    delta^2 t_2^2) J^T``. A segment near the foot point (seen head-on) gets almost nothing;
    one far along its wall (grazing) about ``delta`` in direction and ``delta |t|`` in
    offset. ``t`` is measured from the foot point of the frame of ``z`` (base_link: the
    laser's mount offset, centimetres, is neglected).

    Args:
        z: (L, 2) lines ``(rho, alpha)`` in the frame of ``ends``.
        ends: (L, 2, 2) endpoints of each segment.
        beam_width: ``delta``, the 1-sigma angular spread of the return across the beam
            [rad].

    Returns:
        (L, 2, 2) covariances (zeros where the segment has no length).
    """
    jac, t = _end_jacobian(z, ends)
    var = (beam_width * np.nan_to_num(t)) ** 2
    return np.einsum('kij,kj,klj->kil', jac, var, jac)


def line_observation_model(pose: np.ndarray, lines: np.ndarray
                           ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted ``(rho_b, alpha_b)`` of map lines and the Jacobians (module docstring).

    Args:
        pose: (3,) robot pose.
        lines: (K, 2) map lines ``(rho, alpha)``.

    Returns:
        ``(zhat (K, 2), H_r (K, 2, 3), H_F (K, 2, 2))``; ``zhat[:, 0] <= 0`` means the robot
        is behind the line.
    """
    a = lines[:, 1]
    c, s = np.cos(a), np.sin(a)
    zhat = np.empty((a.size, 2))
    zhat[:, 0] = lines[:, 0] - pose[0] * c - pose[1] * s  # eq. 5 in base_link (eq. 19 role)
    zhat[:, 1] = _wrap(a - pose[2])                       # eq. 20 role
    hr = np.zeros((a.size, 2, 3))
    hr[:, 0, 0], hr[:, 0, 1] = -c, -s                     # eq. 53 role
    hr[:, 1, 2] = -1.0
    hf = np.zeros((a.size, 2, 2))
    hf[:, 0, 0] = 1.0
    hf[:, 0, 1] = pose[0] * s - pose[1] * c
    hf[:, 1, 1] = 1.0
    return zhat, hr, hf


def line_initialization(pose: np.ndarray, z: np.ndarray
                        ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Map lines from base_link observations and their Jacobians (eqs. 39-40, 45-48 roles).

    Args:
        pose: (3,) robot pose.
        z: (L, 2) observations ``(rho_b, alpha_b)``.

    Returns:
        ``(g (L, 2), G_r (L, 2, 3), G_z (L, 2, 2))``.
    """
    a = _wrap(z[:, 1] + pose[2])
    c, s = np.cos(a), np.sin(a)
    g = np.column_stack([z[:, 0] + pose[0] * c + pose[1] * s, a])
    k = -pose[0] * s + pose[1] * c
    gr = np.zeros((z.shape[0], 2, 3))
    gr[:, 0, 0], gr[:, 0, 1], gr[:, 0, 2] = c, s, k  # eq. 46 role
    gr[:, 1, 2] = 1.0
    gz = np.zeros((z.shape[0], 2, 2))
    gz[:, 0, 0], gz[:, 0, 1] = 1.0, k                 # eq. 48 role
    gz[:, 1, 1] = 1.0
    return g, gr, gz


def ends_to_map(pose: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Move (L, 2, 2) base_link endpoints into the map frame with the robot pose (3,)."""
    return _transform_points(np.broadcast_to(np.asarray(pose, dtype=float), (ends.shape[0], 3)),
                             ends)


def extent_interval(lines: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Return the (K, 2) sorted positions of endpoints along each line's direction.

    Args:
        lines: (K, 2) ``(rho, alpha)``.
        ends: (K, 2, 2) endpoints (same frame as the lines).
    """
    d = np.column_stack([-np.sin(lines[:, 1]), np.cos(lines[:, 1])])
    t = np.einsum('kij,kj->ki', ends, d)
    return np.sort(t, axis=1)


def extents_overlap(lines: np.ndarray, lm_ends: np.ndarray, obs_ends: np.ndarray,
                    margin: Optional[np.ndarray] = None) -> np.ndarray:
    """(M, K) whether observed segments overlap landmark segments along the landmark lines.

    Args:
        lines: (K, 2) landmark lines (map frame).
        lm_ends: (K, 2, 2) landmark endpoints (map frame).
        obs_ends: (M, 2, 2) observed endpoints (map frame).
        margin: None (none) or (K,) lengths [m] by which landmark k's interval is widened
            at both ends (``SlamParams.line_extent_sigmas``).

    Returns:
        (M, K) bool: the intervals of the observed endpoints projected on landmark k's
        direction and of k's own endpoints (widened by ``margin``) intersect.
    """
    d = np.column_stack([-np.sin(lines[:, 1]), np.cos(lines[:, 1])])  # (K, 2)
    lm_t = np.sort(np.einsum('kij,kj->ki', lm_ends, d), axis=1)  # (K, 2)
    ob_t = np.einsum('mij,kj->mki', obs_ends, d)  # (M, K, 2)
    lo, hi = ob_t.min(axis=2), ob_t.max(axis=2)
    if margin is not None:
        lm_t = lm_t + np.asarray(margin, dtype=float)[:, None] * np.array([-1.0, 1.0])
    return (hi >= lm_t[None, :, 0]) & (lo <= lm_t[None, :, 1])


def merge_extent(line: np.ndarray, ends_a: np.ndarray, ends_b: np.ndarray) -> np.ndarray:
    """Union of two segments' extents as endpoints on ``line`` (2,): returns (2, 2)."""
    rho, a = float(line[0]), float(line[1])
    n = np.array([np.cos(a), np.sin(a)])
    d = np.array([-n[1], n[0]])
    t = np.concatenate([ends_a @ d, ends_b @ d])
    t = t[np.isfinite(t)]
    return np.array([rho * n + t.min() * d, rho * n + t.max() * d])


def project_extent(line: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Move (2, 2) endpoints onto ``line`` (2,) keeping their positions along it."""
    return merge_extent(line, ends, ends[:0])


__all__ = ['ends_to_map', 'extent_interval', 'extents_overlap', 'line_end_covariance',
           'line_footprint_covariance', 'line_initialization',
           'line_observation_model', 'LineObservations', 'lines_to_observations',
           'merge_extent', 'project_extent', 'transform_lines']
