"""Find the runs of a log that holds several: the clock restarts where the robot is elsewhere.

A logger started again on another run appends to the same file: the clock restarts (a
lasting backward jump, :func:`landmark_nav.importers.stamps.clock_resets`) and the pose
stream (the raw odometry, else the reference) starts at another place. A clock reset where
the pose jumps by more than a wheeled base moves between two readings
(:data:`RUN_JUMP_M`) starts a new **run**: the import summary reports it and ``--run K``
imports run K alone (the robot's pose in one run says nothing of its pose in the other: a
filter that carries the map across would place the second run where the first ended). A
clock reset with the pose continuing is one run whose logger restarted (the stamps are
shifted to continue, :func:`~landmark_nav.importers.stamps.repair_streams`); a pose jump
without a clock reset is a discontinuity of the odometry frame, left to the consumer (the
SLAM front end bridges it).
"""

from dataclasses import dataclass, replace
from typing import List

import numpy as np

from .common import ParsedLog
from .stamps import clock_resets

__all__ = ['RUN_JUMP_M', 'Restart', 'find_restarts', 'select_run']

#: A pose step larger than this between two successive readings [m] is no motion of a
#: wheeled base (the import summary's odometry-jump note uses the same figure).
RUN_JUMP_M = 1.0


@dataclass(frozen=True)
class Restart:
    """Where a log's next run starts."""

    line: int  # log line of the first record of the new run
    clock_before: float  # last stamp of the previous run, as read [s]
    clock_after: float  # first stamp of the new run, as read [s]
    jump: float  # pose change between the last record before and the first after [m]

    def describe(self) -> str:
        """Return e.g. ``'line 2219: clock 134.998 s -> 0.037 s, pose jumps 11.02 m'``."""
        return (f'line {self.line}: clock {self.clock_before:.3f} s -> '
                f'{self.clock_after:.3f} s, pose jumps {self.jump:.2f} m')


def _pose_stream(log: ParsedLog):
    """Return the log's pose stream: (line numbers, poses) of the odometry or reference."""
    if log.has_odometry:
        return np.asarray(log.odom_lineno), np.asarray(log.odom_poses)
    if log.has_reference:
        lines = np.array([log.scans[k].lineno for k in log.reference_index], dtype=int)
        return lines, np.asarray(log.reference_poses)
    return np.zeros(0, dtype=int), np.zeros((0, 3))


def find_restarts(log: ParsedLog) -> List[Restart]:
    """Return where a parsed log's later runs start (empty for a log of one run)."""
    streams = [log.scan_stamps]
    lines = [np.array([s.lineno for s in log.scans], dtype=int)]
    if log.has_odometry:
        streams.append(log.odom_stamps)
        lines.append(log.odom_lineno)
    pose_lines, poses = _pose_stream(log)
    out = []
    for line, before, after in clock_resets(streams, lines):
        prev = np.flatnonzero(pose_lines < line)
        nxt = np.flatnonzero(pose_lines >= line)
        if not prev.size or not nxt.size:
            continue
        jump = float(np.hypot(*(poses[nxt[0], :2] - poses[prev[-1], :2])))
        if jump > RUN_JUMP_M:
            out.append(Restart(line, before, after, jump))
    return out


def select_run(log: ParsedLog, restarts: List[Restart], run: int) -> ParsedLog:
    """Return the part of ``log`` in run ``run`` (1-based) of the runs ``restarts`` delimit.

    Raises:
        ValueError: ``run`` is not one of the log's runs.

    """
    starts = [0] + [r.line for r in restarts]
    if not 1 <= run <= len(starts):
        raise ValueError(f'--run {run}: {log.path.name} holds {len(starts)} run'
                         f'{"s" if len(starts) > 1 else ""}')
    lo = starts[run - 1]
    hi = starts[run] if run < len(starts) else np.inf

    def inside(n) -> np.ndarray:
        n = np.asarray(n)
        return (n >= lo) & (n < hi)

    keep = inside([s.lineno for s in log.scans])
    if not keep.any():
        raise ValueError(f'--run {run} of {log.path.name} holds no scan')
    new_index = np.cumsum(keep) - 1
    ref = keep[log.reference_index] if log.has_reference else np.zeros(0, dtype=bool)
    odom = inside(log.odom_lineno)
    return replace(
        log, scans=[s for s, k in zip(log.scans, keep) if k],
        odom_stamps=log.odom_stamps[odom], odom_poses=log.odom_poses[odom],
        odom_lineno=log.odom_lineno[odom],
        reference_index=new_index[log.reference_index[ref]] if ref.size else
        log.reference_index, reference_poses=log.reference_poses[ref] if ref.size else
        log.reference_poses,
        rear_scans=[s for s in log.rear_scans if lo <= s.lineno < hi],
        notes=list(log.notes))
