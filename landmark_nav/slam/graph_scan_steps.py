"""The graph back end fed one message at a time: the per-scan step of node and offline runner.

:class:`GraphScanSteps` takes odometry samples and scans (laser-frame points) in the order
they come and gives the steps of :class:`~landmark_nav.slam.keyframe_graph.KeyframeGraph`:
a scan waits until the odometry covers its stamp (a sample at or after it), is placed on
the odometry interpolated at its stamp (:func:`odometry_at`) and goes to
:meth:`KeyframeGraph.add_scan`; its pose and covariance are the keyframe's estimate and
marginal then, composed with the odometry since (:meth:`KeyframeGraph.pose_at`). Scans are
processed in stamp order, each once, whatever the order or the timing in which scans and
odometry arrive: the ``graph_slam`` node and ``landmark_nav evaluate --backend graph``
(:mod:`landmark_nav.evaluation.slam_graph`) give the same steps from the same messages.

Splitting the step in :meth:`GraphScanSteps.pop_ready` (cheap: which scan is next, its
odometry pose) and :meth:`GraphScanSteps.process` (the back end's work) lets a node queue
scans in one thread while the back end runs in another.

Inputs not used, counted in :attr:`GraphScanSteps.counts` (each with a reason for the
caller's warning, ``on_drop(reason, message)``):

* ``before_odometry``: a scan stamped before the first odometry sample (no pose exists
  for it; the offline runner never used such scans either);
* ``out_of_order``: a scan stamped at or before the last processed one (it would be a
  second step at an older time), an odometry sample older than the newest;
* ``odometry_gone``: a scan older than the oldest odometry sample still buffered (the
  buffer keeps ``buffer_s`` behind the newest sample, and what the waiting scans need);
* ``nonfinite``: an odometry pose or stamp that is not finite.

Odometry used other than as it came, by ``ekf_slam``'s checks (:mod:`.odometry_checks`,
``limits``: :class:`~landmark_nav.slam.odometry_checks.OdometryLimits`), also counted and
reported (``on_drop``):

* ``jump``: an increment the robot cannot have made in the elapsed time
  (:func:`~landmark_nav.slam.odometry_checks.odometry_jump`: a driver re-zeroing its pose,
  a teleport) is a discontinuity of the odometry frame: it is bridged, the odometry after it
  re-expressed to continue from the pose before it (zero motion across the step; the graph
  is kept). A step's :attr:`GraphStep.offset` turns its odometry back into the odometry
  frame as it came (the node's ``map -> odom``);
* ``retracted`` (with ``restart``): a sample stamped in the future, shown by the samples
  after it continuing those before it (:func:`~.odometry_checks.future_stamp`), is
  withdrawn instead of starting the graph over. The scans it covered meanwhile were placed
  on the odometry interpolated across its gap, as ``ekf_slam`` does.

With ``restart`` (the node; the offline runner reads a bag as it is), a restarted odometry
source (a bag replayed in a loop, a driver restarted with its clock) starts the graph over,
as ``ekf_slam``'s front end restarts its filter (``limits``): samples more than
``max_backward_s`` older than the newest are held; when ``restart_messages`` of them come
in a row, each newer than the one before, a new graph starts from them
(``on_drop('restart', ...)``; :attr:`GraphScanSteps.generation` counts the starts) and the
scans of the old run still waiting, or taken by :meth:`GraphScanSteps.pop_ready` before it
and processed after, are dropped (``restarted``). Held samples that a sample of the old
time base interrupts are dropped (``out_of_order``).
"""

import bisect
from collections import Counter
from dataclasses import dataclass
from typing import Callable, List, Optional, Tuple

from landmark_nav.geometry import interpolate_pose
from landmark_nav.slam.keyframe_graph import GraphParams, KeyframeGraph
from landmark_nav.slam.odometry_checks import (BackwardRun, bridge_offset, bridged,
                                               future_stamp, odometry_jump, OdometryLimits)
from landmark_nav.slam.slam_params import OdometryNoise
import numpy as np


@dataclass(frozen=True, eq=False)
class GraphStep:
    """One processed scan.

    Attributes:
        stamp_ns: The scan's stamp [ns].
        odometry: (3,) the odometry pose at the stamp.
        keyframe: Index of the scan's keyframe.
        new_keyframe: Whether the scan made that keyframe.
        pose: (3,) the scan's pose in the map frame when it was processed.
        covariance: (3, 3) its covariance.
        generation: :attr:`GraphScanSteps.generation` of its graph.
        offset: (3,) ``odometry = offset (+) o`` for the odometry pose ``o`` as it came, when
            a jump was bridged before the stamp (None: none, ``odometry`` is as it came).
    """

    stamp_ns: int
    odometry: np.ndarray
    keyframe: int
    new_keyframe: bool
    pose: np.ndarray
    covariance: np.ndarray
    generation: int = 0
    offset: Optional[np.ndarray] = None


def odometry_at(t_s: float, times: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Return the odometry pose at ``t_s`` from the samples around it (times non-decreasing).

    The last sample stamped at or before ``t_s`` and the next one, linearly
    (:func:`~landmark_nav.geometry.interpolate_pose`); a sample stamped exactly at ``t_s``
    is the pose (heading wrapped). Only those samples are read, so a buffer that holds them
    gives the pose the whole log gives.

    Raises:
        ValueError: ``t_s`` outside the samples.
    """
    i = int(np.searchsorted(times, t_s, side='right')) - 1
    if i < 0 or t_s > times[-1]:
        raise ValueError(f'odometry_at: {t_s!r} outside [{times[0]!r}, {times[-1]!r}]')
    if times[i] == t_s:
        return interpolate_pose(t_s, times[i:i + 1], poses[i:i + 1])
    return interpolate_pose(t_s, times[i:i + 2], poses[i:i + 2])


class GraphScanSteps:
    """Odometry and scans in, steps of the graph back end out (module docstring).

    Args:
        mount: (3,) laser pose in base_link.
        noise: The odometry's noise model.
        params: The graph's parameters.
        buffer_s: Odometry kept behind the newest sample [s] (at least what the waiting
            scans need).
        on_drop: Called ``(reason, message)`` for each input not used.
        restart: Start the graph over when the odometry source restarts (module docstring).
        limits: Parameters of the odometry checks (module docstring).
    """

    def __init__(self, mount, noise: OdometryNoise, params: Optional[GraphParams] = None,
                 buffer_s: float = 60.0,
                 on_drop: Optional[Callable[[str, str], None]] = None,
                 restart: bool = False, limits: OdometryLimits = OdometryLimits()) -> None:
        self.graph = KeyframeGraph(mount, noise, params)
        self.buffer_s = float(buffer_s)
        self._on_drop = on_drop or (lambda reason, message: None)
        self.counts: Counter = Counter()
        self.restart = bool(restart)
        self.generation = 0  # the graph's starts after the first (restarted sources)
        self.limits = limits
        self._back_run = BackwardRun(limits.restart_messages)
        self.processed = 0
        self._start()

    def _start(self) -> None:
        """Forget the odometry, the queue and the last step (a new graph or the first)."""
        self._t0: Optional[int] = None  # first odometry stamp: times are relative to it
        self._times: List[float] = []  # odometry stamps - t0 [s]
        self._poses: List[np.ndarray] = []
        self._offsets: List[Optional[np.ndarray]] = []  # each sample's bridge offset
        self._newest_ns: Optional[int] = None
        self._raw_last: Optional[np.ndarray] = None  # the newest sample's pose as it came
        self._offset: Optional[np.ndarray] = None  # of the last bridged jump
        self._previous: Optional[tuple] = None  # (stamp, raw, offset) before the newest
        self._waiting: List[Tuple[int, np.ndarray]] = []  # scans in stamp order
        self.last_stamp_ns: Optional[int] = None  # the last processed scan's

    # ------------------------------------------------------------------ input
    def _drop(self, reason: str, message: str) -> None:
        self.counts[reason] += 1
        self._on_drop(reason, message)

    def add_odometry(self, stamp_ns: int, pose) -> bool:
        """Buffer one odometry sample; return whether it was used (else counted, reported)."""
        p = np.asarray(pose, dtype=float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            self._drop('nonfinite', f'odometry at {stamp_ns} ns: pose {p.tolist()} is not '
                       'three finite numbers')
            return False
        if self._newest_ns is not None and stamp_ns < self._newest_ns:
            back = (self._newest_ns - stamp_ns) * 1e-9
            if self.restart and back > self.limits.max_backward_s:
                return self._far_back(int(stamp_ns), p, back)
            self._drop_held()
            self._drop('out_of_order', f'odometry at {stamp_ns} ns: older than the newest '
                       f'sample ({self._newest_ns} ns)')
            return False
        self._drop_held()
        if self._t0 is None:
            self._t0 = int(stamp_ns)
            early = [s for s in self._waiting if s[0] < stamp_ns]
            self._waiting = [s for s in self._waiting if s[0] >= stamp_ns]
            for t, _ in early:
                self._drop('before_odometry', f'scan at {t} ns: stamped before the first '
                           f'odometry sample ({stamp_ns} ns)')
        previous = (self._newest_ns, self._raw_last, self._offset)
        pose_used = bridged(self._offset, p)
        if self._newest_ns is not None:
            dt = (stamp_ns - self._newest_ns) * 1e-9
            why = odometry_jump(self._raw_last, p, dt, self.graph.noise, self.limits)
            if why is not None:
                self._offset = bridge_offset(self._poses[-1], p)
                pose_used = self._poses[-1].copy()
                self._drop('jump', f'odometry at {stamp_ns} ns {why} in {dt:.3f} s: bridged as '
                           'a discontinuity of the odometry frame (graph kept)')
        self._previous = previous
        self._newest_ns = int(stamp_ns)
        self._raw_last = p
        self._times.append((stamp_ns - self._t0) * 1e-9)
        self._poses.append(pose_used)
        self._offsets.append(self._offset)
        self._trim()
        return True

    def _drop_held(self) -> None:
        """Drop the far-back samples held: the old time base went on (module docstring)."""
        for t, _, _ in self._back_run.clear():
            self._drop('out_of_order', f'odometry at {t} ns: more than '
                       f'{self.limits.max_backward_s:g} s '
                       f'older than the newest sample ({self._newest_ns} ns), and the samples '
                       'after it did not go on from it')

    def _far_back(self, stamp_ns: int, pose: np.ndarray, back: float) -> bool:
        """Hold a far-back sample; once persistent, withdraw a future stamp or start over."""
        if not self._back_run.continues(stamp_ns):
            self._drop_held()
        if not self._back_run.add(stamp_ns, pose, None):
            return True
        run, old = self._back_run.clear(), self._waiting
        before = self._previous[0] if self._previous is not None else None
        ahead = future_stamp(before, self._newest_ns, run[0][0], self.limits.max_backward_s)
        if ahead is not None:
            self._drop('retracted', f'odometry at {self._newest_ns} ns: lay {ahead:.3f} s ahead '
                       'of the samples around it: withdrawn')
            del self._times[-1], self._poses[-1], self._offsets[-1]
            self._newest_ns, self._raw_last, self._offset = self._previous
            self._previous = None
        else:
            self._on_drop('restart', f'odometry went {back:.3f} s back in time ({len(run)} '
                          f'samples in a row, {self._newest_ns} -> {run[0][0]} ns): the '
                          'source restarted, the graph starts over')
            self.graph = KeyframeGraph(self.graph.mount, self.graph.noise, self.graph.params)
            self.generation += 1
            self._start()
            for t, _ in old:
                self._drop('restarted', f'scan at {t} ns: of the odometry source before its '
                           'restart')
        for t, p, _ in run:
            self.add_odometry(t, p)
        return True

    def add_scan(self, stamp_ns: int, points: np.ndarray) -> bool:
        """Queue one scan's laser-frame points (N, 2); return whether it was queued."""
        if self.last_stamp_ns is not None and stamp_ns <= self.last_stamp_ns:
            self._drop('out_of_order', f'scan at {stamp_ns} ns: not after the last processed '
                       f'scan ({self.last_stamp_ns} ns)')
            return False
        if self._t0 is not None and stamp_ns < self._t0:
            self._drop('before_odometry', f'scan at {stamp_ns} ns: stamped before the first '
                       f'odometry sample ({self._t0} ns)')
            return False
        if self._times and (stamp_ns - self._t0) * 1e-9 < self._times[0]:
            self._drop('odometry_gone', f'scan at {stamp_ns} ns: older than the odometry '
                       f'kept ({self.buffer_s:g} s behind the newest sample)')
            return False
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        k = len(self._waiting)
        while k and self._waiting[k - 1][0] > stamp_ns:
            k -= 1
        if k and self._waiting[k - 1][0] == stamp_ns:
            self._drop('out_of_order', f'scan at {stamp_ns} ns: a scan with this stamp is '
                       'already waiting')
            return False
        self._waiting.insert(k, (int(stamp_ns), pts))
        return True

    @property
    def waiting(self) -> int:
        """Scans queued, not yet processed."""
        return len(self._waiting)

    @property
    def oldest_waiting_ns(self) -> Optional[int]:
        """Stamp of the oldest waiting scan [ns] (None when none waits)."""
        return self._waiting[0][0] if self._waiting else None

    @property
    def newest_odometry_ns(self) -> Optional[int]:
        """Stamp of the newest odometry sample [ns] (None before the first)."""
        return self._newest_ns

    @property
    def waiting_stamps(self) -> List[int]:
        """Stamps of the queued scans [ns], oldest first."""
        return [t for t, _ in self._waiting]

    @property
    def waiting_bytes(self) -> int:
        """Memory of the queued scans' points [bytes]."""
        return sum(p.nbytes for _, p in self._waiting)

    def drop_oldest(self, reason: str, message: str) -> Optional[int]:
        """Drop the oldest waiting scan (a full queue); return its stamp."""
        if not self._waiting:
            return None
        t, _ = self._waiting.pop(0)
        self._drop(reason, f'scan at {t} ns: {message}')
        return t

    def _trim(self) -> None:
        """Forget odometry older than ``buffer_s`` and than what the next scan needs."""
        if len(self._times) < 3:
            return
        keep_s = self._times[-1] - self.buffer_s
        if self._waiting:
            keep_s = min(keep_s, (self._waiting[0][0] - self._t0) * 1e-9)
        if self.last_stamp_ns is not None:
            keep_s = min(keep_s, (self.last_stamp_ns - self._t0) * 1e-9)
        # keep the last sample at or before keep_s (the left end of its interval)
        i = int(np.searchsorted(self._times, keep_s, side='right')) - 1
        if i > 0:
            del self._times[:i]
            del self._poses[:i]
            del self._offsets[:i]

    # ------------------------------------------------------------------ steps
    def pop_ready(self) -> Optional[Tuple[int, np.ndarray, np.ndarray, int,
                                          Optional[np.ndarray]]]:
        """Return the next scan the odometry covers, or None.

        ``(stamp_ns, odometry pose, points, generation, offset)`` (``offset``: the bridge
        offset of the first sample at or after the stamp, :attr:`GraphStep.offset`); None
        when no waiting scan is covered yet (or no odometry came).
        """
        if not self._waiting or self._newest_ns is None or \
                self._waiting[0][0] > self._newest_ns:
            return None
        t, pts = self._waiting.pop(0)
        t_s = (t - self._t0) * 1e-9
        # the samples around the stamp only (the buffer holds up to buffer_s of odometry)
        lo = max(bisect.bisect_right(self._times, t_s) - 1, 0)
        o = odometry_at(t_s, np.asarray(self._times[lo:lo + 2]),
                        np.asarray(self._poses[lo:lo + 2]))
        offset = self._offsets[bisect.bisect_left(self._times, t_s)]
        self.last_stamp_ns = t
        return t, o, pts, self.generation, offset

    def process(self, stamp_ns: int, odometry: np.ndarray, points: np.ndarray,
                generation: int = 0, offset: Optional[np.ndarray] = None
                ) -> Optional[GraphStep]:
        """Run the back end on one scan :meth:`pop_ready` gave; return its step.

        None (the scan dropped as ``restarted``) when the graph started over since.
        """
        graph = self.graph
        if generation != self.generation:
            self._drop('restarted', f'scan at {stamp_ns} ns: of the odometry source before '
                       'its restart')
            return None
        new = graph.add_scan(odometry, points)
        k = len(graph.keyframes) - 1
        pose, cov = graph.pose_at(k, odometry)
        self.processed += 1
        return GraphStep(stamp_ns, odometry, k, new, pose, cov, generation, offset)

    def step(self) -> Optional[GraphStep]:
        """Process the next covered scan (:meth:`pop_ready` then :meth:`process`), if any."""
        while True:
            item = self.pop_ready()
            if item is None:
                return None
            step = self.process(*item)
            if step is not None:
                return step


__all__ = ['GraphScanSteps', 'GraphStep', 'odometry_at']
