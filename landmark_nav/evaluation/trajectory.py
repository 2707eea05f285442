"""Trajectory metrics: ATE and RPE as the ``evo`` package computes them, TUM files.

The metrics are evo's (``evo.core.metrics.APE`` / ``RPE``, ``evo.core.sync``,
``PoseTrajectory3D.align``); this module fixes the protocol and reads / writes the files:

* **TUM files**: one pose per line, ``t x y z qx qy qz qw`` (seconds, metres, unit
  quaternion), ``#`` comments and blank lines ignored. :func:`read_tum` reports a bad line
  with its file and line number and keeps the stamps as integer nanoseconds.
* **Association**: estimate and reference poses are paired by nearest stamp within
  ``max_diff`` seconds (``evo.core.sync.associate_trajectories``, evo's ``--t_max_diff``,
  default 0.01 s); unpaired poses are left out, and the counts are reported.
* **ATE** (absolute trajectory error): the translation error ``|t_ref - t_est|`` of the
  paired poses after an alignment of the estimate to the reference: ``'none'``; ``'se2'``
  (rotation about z and a translation in the plane: both trajectories are projected to the
  xy plane and Umeyama-aligned; for planar trajectories this equals evo's ``--align``);
  ``'se3'`` (Umeyama rotation and translation, evo's ``--align``); ``'sim3'`` (with scale,
  evo's ``--align --correct_scale``). Statistics: rmse, mean, median, std, min, max.
* **RPE** (relative pose error) over a travelled distance ``delta`` metres (evo's
  ``--delta_unit m --all_pairs --pairs_from_reference``): every pose ``i`` is paired with the
  pose ``j`` whose path length from ``i`` along the REFERENCE is nearest to ``delta``,
  accepted within ``rel_tol * delta`` (evo's default 10 %); the error of the pair is the
  relative motion error ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``: its translation norm [m] and
  its rotation angle [deg].

Planar poses ``[x, y, yaw]`` become 3-D poses with ``z = 0`` and a rotation about z.
"""

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Dict, Sequence, Tuple, Union

from evo.core import metrics, sync
from evo.core.filters import FilterException
from evo.core.geometry import GeometryException, umeyama_alignment
from evo.core.trajectory import Plane, PoseTrajectory3D
from landmark_nav.geometry import interpolate_pose
import numpy as np

ALIGNMENTS = ('none', 'se2', 'se3', 'sim3')
#: Largest stamp difference of an estimate / reference pair [s] (evo's default).
MAX_DIFF_S = 0.01
#: Accepted deviation of an RPE pair's path length from ``delta``, relative (evo's default).
RPE_REL_TOL = 0.1
STATISTICS = ('rmse', 'mean', 'median', 'std', 'min', 'max')


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Stamped 3-D poses (TUM layout).

    Attributes:
        stamps_ns: (N,) int64 stamps [ns], strictly increasing.
        positions: (N, 3) ``x, y, z`` [m].
        quaternions: (N, 4) ``qx, qy, qz, qw`` (unit).
    """

    stamps_ns: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray

    def __len__(self) -> int:
        """Return the number of poses."""
        return int(self.stamps_ns.shape[0])

    @classmethod
    def from_planar(cls, stamps_ns: np.ndarray, poses: np.ndarray) -> 'Trajectory':
        """Wrap (N,) stamps [ns] and (N, 3) planar poses ``[x, y, yaw]``."""
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        half = 0.5 * poses[:, 2]
        n = poses.shape[0]
        q = np.column_stack([np.zeros(n), np.zeros(n), np.sin(half), np.cos(half)])
        return cls(np.asarray(stamps_ns, dtype=np.int64).reshape(-1),
                   np.column_stack([poses[:, :2], np.zeros(n)]), q)

    def planar(self) -> np.ndarray:
        """(N, 3) ``[x, y, yaw]``: the position's x, y and the heading of the body x axis."""
        qx, qy, qz, qw = self.quaternions.T
        yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        return np.column_stack([self.positions[:, :2], yaw])

    def to_evo(self) -> PoseTrajectory3D:
        """Return the trajectory as an ``evo`` ``PoseTrajectory3D`` (stamps in seconds)."""
        return PoseTrajectory3D(positions_xyz=self.positions.copy(),
                                orientations_quat_wxyz=np.roll(self.quaternions, 1, axis=1),
                                timestamps=self.stamps_ns * 1e-9)


def _stamp_ns(token: str) -> int:
    """Seconds as written in a TUM file -> integer nanoseconds (exact for plain decimals)."""
    if 'e' in token.lower() or token.lower() in ('nan', 'inf', '-inf', '+inf'):
        v = float(token)
        if not math.isfinite(v):
            raise ValueError(f'stamp {token!r} is not finite')
        return int(round(v * 1e9))
    sign = -1 if token.startswith('-') else 1
    whole, _, frac = token.lstrip('+-').partition('.')
    if not (whole or frac) or not (whole or '0').isdigit() or not (frac or '0').isdigit():
        raise ValueError(f'stamp {token!r} is not a number')
    frac = (frac + '000000000')[:9]
    return sign * (int(whole or '0') * 10**9 + int(frac))


def read_tum(path: Union[str, Path]) -> Trajectory:
    """Read a TUM trajectory file (module docstring).

    Args:
        path: File with ``t x y z qx qy qz qw`` lines.

    Returns:
        The trajectory, in file order.

    Raises:
        ValueError: ``<file>:<line>: <problem>`` for a malformed line, a non-unit quaternion
            (norm off by more than 1e-3), a stamp not after the previous one, or an empty
            file.
    """
    stamps, rows = [], []
    with open(path) as f:
        for no, line in enumerate(f, 1):
            text = line.split('#', 1)[0].strip()
            if not text:
                continue
            tok = text.split()
            if len(tok) != 8:
                raise ValueError(f'{path}:{no}: expected 8 fields (t x y z qx qy qz qw), '
                                 f'got {len(tok)}')
            try:
                t = _stamp_ns(tok[0])
                vals = [float(v) for v in tok[1:]]
            except ValueError as e:
                raise ValueError(f'{path}:{no}: {e}') from None
            if not all(math.isfinite(v) for v in vals):
                raise ValueError(f'{path}:{no}: non-finite value')
            norm = math.sqrt(sum(v * v for v in vals[3:]))
            if abs(norm - 1.0) > 1e-3:
                raise ValueError(f'{path}:{no}: quaternion norm {norm:.6f} is not 1')
            if stamps and t <= stamps[-1]:
                raise ValueError(f'{path}:{no}: stamp {tok[0]} is not after the previous one')
            stamps.append(t)
            rows.append(vals)
    if not rows:
        raise ValueError(f'{path}: no poses')
    a = np.array(rows)
    return Trajectory(np.array(stamps, dtype=np.int64), a[:, :3], a[:, 3:])


def write_tum(path: Union[str, Path], traj: Trajectory) -> None:
    """Write a TUM file with 9 decimals (stamps exact to the nanosecond)."""
    with open(path, 'w') as f:
        for t, p, q in zip(traj.stamps_ns, traj.positions, traj.quaternions):
            t = int(t)
            sign = '-' if t < 0 else ''
            f.write(f'{sign}{abs(t) // 10**9}.{abs(t) % 10**9:09d} {p[0]:.9f} {p[1]:.9f} '
                    f'{p[2]:.9f} {q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}\n')


def associate(est: Trajectory, ref: Trajectory, max_diff: float = MAX_DIFF_S
              ) -> Tuple[PoseTrajectory3D, PoseTrajectory3D]:
    """Pair estimate and reference poses by nearest stamp (``evo.core.sync``).

    Args:
        est: Estimate.
        ref: Reference.
        max_diff: Largest stamp difference of a pair [s].

    Returns:
        ``(ref, est)`` as evo trajectories of equal length (the pairs).

    Raises:
        ValueError: No pair within ``max_diff``.
    """
    try:
        r, e = sync.associate_trajectories(ref.to_evo(), est.to_evo(), max_diff=max_diff)
    except sync.SyncException as exc:
        raise ValueError(f'no estimate / reference stamps within {max_diff} s: {exc}') from None
    return r, e


def _stats(metric: metrics.PE, pairs: int, **extra) -> Dict[str, float]:
    st = metric.get_all_statistics()
    out = {k: float(st[k]) for k in STATISTICS}
    out['pairs'] = int(pairs)
    out.update(extra)
    return out


def _associate_aligned(est: Trajectory, ref: Trajectory, align: str, max_diff: float
                       ) -> Tuple[PoseTrajectory3D, PoseTrajectory3D, float]:
    """Associate ``est`` with ``ref`` and align it (evo); return (ref, est, sim3 scale).

    Raises:
        ValueError: Unknown alignment, no pairs, or too few / degenerate poses to align.
    """
    if align not in ALIGNMENTS:
        raise ValueError(f'align must be one of {", ".join(ALIGNMENTS)}, got {align!r}')
    r, e = associate(est, ref, max_diff)
    scale = 1.0
    if align == 'se2':
        r.project(Plane.XY)
        e.project(Plane.XY)
    if align != 'none':
        if r.num_poses < 3:
            raise ValueError(f'{align} alignment needs at least 3 pose pairs, got {r.num_poses}')
        try:
            _, _, scale = e.align(r, correct_scale=(align == 'sim3'))
        except GeometryException as exc:
            raise ValueError(f'{align} alignment failed: {exc}') from None
    return r, e, float(scale)


def ate(est: Trajectory, ref: Trajectory, align: str = 'none',
        max_diff: float = MAX_DIFF_S) -> Dict[str, float]:
    """Absolute trajectory error of ``est`` against ``ref`` (module docstring).

    Args:
        est: Estimate.
        ref: Reference.
        align: One of :data:`ALIGNMENTS`.
        max_diff: Largest stamp difference of a pair [s].

    Returns:
        ``{'rmse', 'mean', 'median', 'std', 'min', 'max'}`` [m], ``'pairs'`` (associated
        poses) and ``'scale'`` (the sim3 scale, 1 otherwise).

    Raises:
        ValueError: Unknown alignment, no pairs, or too few / degenerate poses to align.
    """
    r, e, scale = _associate_aligned(est, ref, align, max_diff)
    m = metrics.APE(metrics.PoseRelation.translation_part)
    m.process_data((r, e))
    return _stats(m, r.num_poses, scale=scale)


def aligned(est: Trajectory, ref: Trajectory, align: str,
            max_diff: float = MAX_DIFF_S) -> Tuple[np.ndarray, np.ndarray]:
    """Return the associated reference and the aligned estimate as planar poses (plots).

    Args:
        est: Estimate.
        ref: Reference.
        align: One of :data:`ALIGNMENTS`.
        max_diff: Largest stamp difference of a pair [s].

    Returns:
        ``(ref_poses, est_poses)`` ``[x, y, yaw]`` of the pairs, the estimate aligned.

    Raises:
        ValueError: As :func:`ate` (the plot then leaves that path out).
    """
    r, e, _ = _associate_aligned(est, ref, align, max_diff)

    def planar(t: PoseTrajectory3D) -> np.ndarray:
        q = np.roll(t.orientations_quat_wxyz, -1, axis=1)
        return Trajectory(np.zeros(t.num_poses, dtype=np.int64), t.positions_xyz, q).planar()
    return planar(r), planar(e)


def rpe(est: Trajectory, ref: Trajectory, delta: float = 1.0, rel_tol: float = RPE_REL_TOL,
        max_diff: float = MAX_DIFF_S) -> Dict[str, float]:
    """Relative pose error over ``delta`` metres of reference path (module docstring).

    Args:
        est: Estimate.
        ref: Reference.
        delta: Path length of a pair along the reference [m].
        rel_tol: Accepted relative deviation of a pair's path length from ``delta``.
        max_diff: Largest stamp difference of an estimate / reference pair [s].

    Returns:
        Translation statistics ``{'rmse', 'mean', 'median', 'std', 'min', 'max'}`` [m],
        the rotation statistics under ``'rot_<stat>_deg'``, and ``'pairs'``; with no pair
        over ``delta`` (a short run) the statistics are NaN and ``'pairs'`` is 0.

    Raises:
        ValueError: ``delta`` not positive or no associated stamps.
    """
    if not delta > 0:
        raise ValueError(f'RPE delta must be positive, got {delta}')
    r, e = associate(est, ref, max_diff)
    out: Dict[str, float] = {}
    for rel, suffix in ((metrics.PoseRelation.translation_part, ''),
                        (metrics.PoseRelation.rotation_angle_deg, '_deg')):
        m = metrics.RPE(rel, delta=delta, delta_unit=metrics.Unit.meters, rel_delta_tol=rel_tol,
                        all_pairs=True, pairs_from_reference=True)
        try:
            m.process_data((r, e))
        except FilterException:  # no pair over delta (a short run)
            return {**{k: math.nan for k in STATISTICS},
                    **{f'rot_{k}_deg': math.nan for k in STATISTICS}, 'pairs': 0}
        st = m.get_all_statistics()
        prefix = 'rot_' if suffix else ''
        out.update({f'{prefix}{k}{suffix}': float(st[k]) for k in STATISTICS})
        out['pairs'] = int(len(m.error))
    return out


def position_errors(est: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(N,) planar position errors ``|p_est - p_ref|`` of poses at the same stamps."""
    est = np.asarray(est, dtype=float)
    ref = np.asarray(ref, dtype=float)
    return np.hypot(*(est[:, :2] - ref[:, :2]).T)


def position_errors_at(ref: Trajectory, stamps_ns: np.ndarray, poses: np.ndarray
                       ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Planar position errors of poses against the reference interpolated at their stamps.

    Args:
        ref: Reference.
        stamps_ns: (N,) stamps of the estimate [ns].
        poses: (N, 3) estimated ``[x, y, yaw]``.

    Returns:
        ``(stamps, errors, ref_poses)`` of the estimates inside the reference's time span:
        their stamps [ns], ``|p_est - p_ref|`` [m] and the reference ``[x, y, yaw]``
        (linear in time, the heading along the shorter arc).
    """
    tt, tp = ref.stamps_ns, ref.planar()
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    keep = (stamps >= tt[0]) & (stamps <= tt[-1])
    at = interpolate_pose((stamps[keep] - tt[0]) * 1e-9, (tt - tt[0]) * 1e-9, tp)
    return stamps[keep], position_errors(np.asarray(poses, dtype=float)[keep], at), at


def planar_alignment(est: np.ndarray, ref: np.ndarray) -> Tuple[float, np.ndarray, float]:
    """Umeyama SE(2) fit of planar positions at the same stamps (the ``'se2'`` alignment).

    Args:
        est: (N, >=2) estimated positions (first two columns used).
        ref: (N, >=2) reference positions.

    Returns:
        ``(rotation [rad], translation (2,), rmse [m])``: ``ref ~ R(rotation) est + t``. The
        rotation is the estimate's global heading error as a whole (map and path turned
        together, which no relative observation sees).
    """
    a = np.asarray(est, dtype=float)[:, :2]
    b = np.asarray(ref, dtype=float)[:, :2]
    rot, t, _ = umeyama_alignment(a.T, b.T, False)           # evo's, as e.align
    err = (a @ rot.T + t) - b
    return (math.atan2(rot[1, 0], rot[0, 0]), t,
            float(np.sqrt(np.mean(np.sum(err ** 2, axis=1)))))


def summary(stats: Dict[str, float], keys: Sequence[str] = ('rmse', 'max')) -> str:
    """``rmse 1.23 cm, max 4.56 cm`` for the given statistics [m]."""
    return ', '.join(f'{k} {100 * stats[k]:.2f} cm' for k in keys)


__all__ = ['ALIGNMENTS', 'aligned', 'associate', 'ate', 'MAX_DIFF_S', 'planar_alignment',
           'position_errors', 'position_errors_at', 'read_tum', 'rpe', 'RPE_REL_TOL',
           'STATISTICS', 'summary', 'Trajectory', 'write_tum']
