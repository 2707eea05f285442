"""SLAM front end: odometry as it comes and feature sets in, filter steps out (ROS free).

One pipeline for the ``ekf_slam`` node and the offline evaluation
(:func:`landmark_nav.evaluation.slam.run_slam`): both feed odometry samples and laser
feature sets (corners with their beam times) to :class:`SlamFrontend` in whatever order they
arrive and get the same filter steps, to the last bit, whenever the same messages arrived.

Odometry buffer (:meth:`SlamFrontend.add_odometry`)
---------------------------------------------------
Each sample ``(stamp, pose, covariance)`` is judged against the previous accepted one, by
the checks of :mod:`.odometry_checks`, which never trust the sample itself:

* a pose that is not finite, or stamp 0 (an unset header): dropped (``'invalid'``);
* a stated covariance not finite, symmetric, with a non-negative diagonal and PSD: replaced
  by the noise model (``'covariance'``; ``U`` always comes from the model);
* the same stamp again: dropped (``'repeated'`` when the pose is the same, ``'conflicting'``
  when it differs: the first one stays);
* an older stamp: dropped (``'backward'``). Only a persistent condition restarts: samples
  more than ``max_backward_s`` back are held (``'far_back'``; dropped as ``'backward'``
  when the run ends); when ``restart_messages`` of them come in a row (moving forward among
  themselves), the odometry source restarted (a replayed bag looping, a driver restart) and
  the front end starts over with an empty map from them (``'restart'``, the only reset).
  If instead those samples continue the odometry before
  the last accepted sample, and that one had jumped more than ``max_backward_s`` ahead, it
  was a stamp in the future: it is withdrawn and the samples accepted (``'retracted'``);
* a newer stamp: the increment ``u = (-)o_prev (+) o`` (eq. 13) must be reachable in the
  elapsed time ``dt`` plus the odometry noise::

      |(u_x, u_y)| <= v_max dt + k sigma_xy,   |u_psi| <= w_max dt + k sigma_psi

  with ``dt`` at least ``min_step_s`` (stamp jitter), ``k = jump_sigmas`` and ``sigma`` the
  noise model's (:class:`~landmark_nav.slam.ekf_slam.OdometryNoise` at the increment:
  ``sigma_xy^2 = s_xy^2 d``, ``sigma_psi^2 = s_yd^2 d + s_yr^2 |u_psi|``), whatever
  covariance the message claims. A long gap in ``/odom`` is no jump: the robot had time
  to move, and the motion across the gap is interpolated. An
  increment that fails is a discontinuity of the odometry frame (a driver re-zeroing its
  pose, a teleport), not a motion: it is *bridged* (``'jump'``), i.e. the odometry after
  it is re-expressed so that it continues from the pose before it (zero motion across the
  step), and the prediction over that step gets the variance of the largest plausible
  motion, ``diag((v_max dt)^2, (v_max dt)^2, (w_max dt)^2)``, on top of ``U``. The map is
  kept.

Feature sets (:meth:`SlamFrontend.add_features`)
------------------------------------------------
A set of corners (laser frame, each with its covariance, bisector, opening and beam time
after the set's stamp; optionally line segments with their middle beam's time and the
scan's geometry, :class:`Corners`) waits until the odometry covers its last beam (``stamp +
max(beam_time)``; with de-skew off, the stamp), then is processed in stamp order; a set
older than the last processed step is dropped (``'out_of_order'``).

:meth:`flush` processes the sets still waiting whose stamp the odometry covers, holding
the last odometry pose for beams after it (end of a recording; the node calls it when
odometry stops coming).

Start-up: the filter starts at the first accepted odometry sample. A set stamped at or
after it waits for the odometry at its stamp, however long it takes (the node bounds the
waiting sets by their memory, not by a time); a set stamped before it has no odometry pose
and is not processed (``'before_odometry'``; not a drop: slam_toolbox and AMCL likewise
discard scans stamped before the odom -> base_link transform's first sample).

Keyframes (``FrontendParams.keyframe``, :mod:`.keyframes`): with a travel or turn threshold,
only the sets that far from the last keyframe reach the filter; a set in between gets its
pose from the odometry since the last keyframe (``Step.keyframe`` False).

Per step (one iteration of Fig. 17): the odometry is linearly interpolated to the stamp
(:func:`landmark_nav.geometry.interpolate_pose`, times in seconds since the first odometry
sample), ``u`` (eq. 13) goes to :meth:`EkfSlam.predict` (``U`` from the parameters' noise
model, plus the bridged variance), each corner goes through the odometry motion between
the stamp and its beam time (de-skew) and the laser mount into range and bearing
(:func:`.observations.corners_to_observations`, eqs. 18-22), each line likewise through
the motion at its middle beam (:func:`.line_landmarks.lines_to_observations`), and all go
with the scan's geometry (visibility-aware pruning, :mod:`.visibility`) to
:meth:`EkfSlam.update` (association, update, candidates, augmentation; the core's map
management runs there). With a saved map (``slam_map``, e.g. ``mode: localization``) the
filter starts on it at the first odometry pose (:meth:`EkfSlam.load_map`).

Scan-matched motion (``FrontendParams.scan_matching``, off by default)
----------------------------------------------------------------------
With it on, each step's increment is the base's motion between the previous step's scan and
this one by point-to-line ICP (Censi, ICRA 2008; :func:`.scan_matching.scan_motion`: returns
within ``scan_matching_max_range``, pairs within 50, 30, then 15 cm, the odometry increment
as the initial guess) when that motion agrees with the odometry's: their difference within
the ``scan_matching_accept`` confidence region of two independent estimates of the same
motion (chi-square on 3 degrees of freedom under the sum of the odometry's ``U`` and the
scan-matched motion's own, both noise models evaluated at the larger of the two motions,
:func:`.scan_matching.larger_motion`: the region is that of the one true motion, so that
the odometry's own error cannot shrink it); it is predicted with ``U`` of
``scan_matching_noise`` (default ``k_d=0.05 k_theta=0.03 k_dtheta=0.06``: the ``pioneer``
position gain and 0.6 of its heading gains, chosen on the Carmen logs' first drift seed,
README). Otherwise (the first
step, no scan geometry in the set or in the one before, a bridged odometry jump in the step,
ICP without enough pairs, or a motion the odometry rules out: ICP sliding along a corridor
or locking onto the wrong structure) the odometry increment and its ``U`` are used, as
without the option. ICP from the odometry's guess fails when that heading is several degrees
off (after a turn); it is then restarted from headings across ``U``'s (``scan_motion``).
With ``scan_matching_fit_pairs`` > 0 the step's motion is instead the odometry increment
and the scan-matched motion fused by their information (``fused_scan_motion``), the
scan-matched motion's covariance from the ICP fit (``fit_information``: its shape, so that
along a corridor the odometry decides, and the size of that many independent residuals,
because the ICP's error against the reference does not shrink with the number of pairs);
the prediction then uses the fused covariance. The shipped configuration sets 0.3
(:mod:`.configuration`).
``scan_matching_side_starts`` k > 0 also starts ICP from the odometry's heading +- k heading
stds of ``U`` on every step and takes the solution with the most pairs first: an odometry
increment in its own tail leads ICP into a nearby wrong minimum that can pass the test
(2.5 in the profile).
:attr:`SlamFrontend.motions` counts the steps of each kind, :attr:`SlamFrontend.icp_restarts`
the restarts. The same
scans then give the landmark observations: the scan-matched motion and the update share
their data, so the filter's pose is somewhat overconfident (the Carmen figures in the README
measure how much). The ICP runs on the raw scan (no de-skew).

Odometry noise per robot: :mod:`.odometry_noise_models`.
"""

import bisect
from dataclasses import dataclass, field, replace
import math
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from landmark_nav.geometry import interpolate_pose, relative
import numpy as np

from .consistency import chi2_gate
from .ekf_slam import EkfSlam, odometry_noise, SlamParams, UpdateResult
from .keyframes import KeyframeParams, NO_UPDATE, pose_between_keyframes
from .line_landmarks import lines_to_observations
from .observations import corner_descriptors, corners_to_observations
from .odometry_checks import (BackwardRun, bridge_offset, bridged, covariance_problem,
                              future_stamp, odometry_jump, OdometryLimits)
from .odometry_noise_models import odometry_noise_model, ODOMETRY_NOISE_MODELS
from .scan_matching import fused_scan_motion, scan_motion, scan_points
from .slam_map import SlamMap
from .visibility import ScanGeometry

#: Odometry events counted by :attr:`SlamFrontend.events`.
ODOMETRY_EVENTS = ('accepted', 'invalid', 'covariance', 'repeated', 'conflicting', 'backward',
                   'far_back', 'restart', 'retracted', 'jump')
#: Feature-set events counted by :attr:`SlamFrontend.events`.
FEATURE_EVENTS = ('processed', 'out_of_order', 'before_odometry', 'held')
#: What a step predicted with (:attr:`SlamFrontend.motions`, :attr:`Step.motion`).
MOTION_SOURCES = ('odometry', 'scan_matching')


@dataclass(frozen=True)
class FrontendParams:
    """Front-end parameters (SI units; module docstring).

    Attributes:
        deskew: Move each corner through the odometry motion between the stamp and its beam
            time.
        descriptors: Pass the corners' bisector and opening to the association.
        max_speed: Fastest plausible translation of the base [m/s] (Pioneer 3-DX: 1.2).
        max_turn_rate: Fastest plausible rotation [rad/s] (Pioneer 3-DX: 300 deg/s).
        jump_sigmas: Odometry noise standard deviations allowed on top of the speed limits.
        min_step_s: Smallest elapsed time the check uses (stamp jitter) [s].
        max_backward_s: Odometry further back than this, ``restart_messages`` times in a
            row, restarts the front end [s].
        restart_messages: Consecutive far-back odometry samples that restart it (a
            single stamp never does).
        buffer_s: Odometry kept behind the newest sample [s] (bounded memory when no
            feature sets come; a set older than the buffer is dropped as out of order).
        scan_matching: Predict with the scan's motion against the previous step's scan
            (point-to-line ICP, :func:`.scan_matching.scan_motion`) instead of the
            odometry increment when the two agree (module docstring); needs each set's
            scan geometry (``Corners.scan``).
        scan_matching_noise: ``U`` of a scan-matched motion, as
            :func:`odometry_noise_model` reads it.
        scan_matching_max_range: Returns at or beyond this are not matched [m].
        scan_matching_accept: Confidence of the region the difference of the scan-matched
            motion and the odometry increment must lie in (chi-square, 3 degrees of
            freedom, covariance ``U + V``: the two estimates' own).
        scan_matching_fit_pairs: 0: predict with the scan-matched motion and
            ``scan_matching_noise``'s ``U``. > 0: predict with the odometry and the
            scan-matched motion fused (:func:`.scan_matching.fused_scan_motion`), the latter's
            covariance from the ICP fit worth this many independent residuals
            (:func:`.scan_matching.fit_information`; the test still uses
            ``scan_matching_noise``).
        scan_matching_side_starts: k > 0: ICP also starts from the odometry's heading
            ``+- k`` heading stds on every step, the solution with the most pairs first
            (:func:`.scan_matching.scan_motion`); 0: off.
        keyframe: Which sets reach the filter (:mod:`.keyframes`; default: every set).
    """

    deskew: bool = True
    descriptors: bool = True
    max_speed: float = OdometryLimits.max_speed
    max_turn_rate: float = OdometryLimits.max_turn_rate
    jump_sigmas: float = OdometryLimits.jump_sigmas
    min_step_s: float = OdometryLimits.min_step_s
    max_backward_s: float = OdometryLimits.max_backward_s
    restart_messages: int = OdometryLimits.restart_messages
    buffer_s: float = 60.0
    scan_matching: bool = False
    scan_matching_noise: str = 'k_d=0.05 k_theta=0.03 k_dtheta=0.06'
    scan_matching_max_range: float = 20.0
    scan_matching_accept: float = 0.999
    scan_matching_fit_pairs: float = 0.0
    scan_matching_side_starts: float = 0.0
    keyframe: KeyframeParams = KeyframeParams()

    def __post_init__(self) -> None:
        """Validate; raise ValueError naming the bad field."""
        for name in ('max_speed', 'max_turn_rate', 'jump_sigmas', 'min_step_s',
                     'max_backward_s', 'buffer_s', 'scan_matching_max_range'):
            v = getattr(self, name)
            if (not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v)
                    or v <= 0.0):
                raise ValueError(f'FrontendParams.{name} must be a finite number > 0, got {v!r}')
        r = self.restart_messages
        if not isinstance(r, int) or isinstance(r, bool) or r < 1:
            raise ValueError(f'FrontendParams.restart_messages must be an integer >= 1, got {r!r}')
        for name in ('deskew', 'descriptors', 'scan_matching'):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f'FrontendParams.{name} must be a bool')
        a = self.scan_matching_accept
        if not isinstance(a, (int, float)) or isinstance(a, bool) or not 0.0 < a < 1.0:
            raise ValueError('FrontendParams.scan_matching_accept must be a probability in '
                             f'(0, 1), got {a!r}')
        for name in ('scan_matching_fit_pairs', 'scan_matching_side_starts'):
            f = getattr(self, name)
            if (not isinstance(f, (int, float)) or isinstance(f, bool) or not math.isfinite(f)
                    or f < 0.0):
                raise ValueError(f'FrontendParams.{name} must be a finite number >= 0 '
                                 f'(0 = off), got {f!r}')
        if not isinstance(self.keyframe, KeyframeParams):
            raise ValueError('FrontendParams.keyframe must be a KeyframeParams')
        if not isinstance(self.scan_matching_noise, str):
            raise ValueError('FrontendParams.scan_matching_noise must be a string, got '
                             f'{self.scan_matching_noise!r}')
        try:
            odometry_noise_model(self.scan_matching_noise)
        except ValueError as err:
            raise ValueError(f'FrontendParams.scan_matching_noise: {err}') from None


def line_beam_times(lines: Sequence, time_increment: float) -> np.ndarray:
    """Return (L,) the time of each line's middle beam after the scan stamp [s].

    Args:
        lines: :class:`~landmark_nav.laser.lines.LineSegment` objects (``first_index``,
            ``last_index``).
        time_increment: The scan's time between beams [s].
    """
    return float(time_increment) * np.array(
        [0.5 * (ln.first_index + ln.last_index) for ln in lines], dtype=float).reshape(len(lines))


@dataclass(frozen=True, eq=False)
class Corners:
    """One scan's features in the laser frame: M corners, optionally L lines and the scan.

    The corner cloud's content, plus what the ``landmarks: lines|both`` setting and the
    visibility-aware pruning need (:mod:`.line_landmarks`, :mod:`.visibility`).

    Attributes:
        stamp_ns: Stamp of the scan (its first beam) [ns].
        positions: (M, 2) corner positions [m].
        covariances: (M, 2, 2) their covariances [m^2].
        bisector: (M,) free-space bisector directions [rad].
        opening: (M,) free-space openings [rad].
        beam_time: (M,) time of each corner's beam after ``stamp_ns`` [s] (index times the
            scan's ``time_increment``; zeros when unknown).
        lines: L line segments (:class:`~landmark_nav.laser.lines.LineSegment`: ``rho``,
            ``alpha``, ``covariance``, ``start``, ``end``, ``num_points``, ``rmse``,
            ``first_index``, ``last_index``); empty: no line observations.
        line_beam_time: (L,) time of each line's middle beam after ``stamp_ns`` [s].
        line_sigma_r: The laser's stated range noise for the lines' a-posteriori variance
            factor (:func:`.line_landmarks.lines_to_observations`); None: not applied.
        scan: The scan's geometry for visibility-aware pruning (None: no pruning evidence).
        lines_from: Extracts ``(lines, line_beam_time)`` when the set reaches the filter
            (:meth:`with_lines`; a set between keyframes needs none); None: ``lines``.
        lines_until: With ``lines_from``: the scan's last beam time after ``stamp_ns`` [s]
            (the set waits for the odometry up to it).
    """

    stamp_ns: int
    positions: np.ndarray
    covariances: np.ndarray
    bisector: np.ndarray
    opening: np.ndarray
    beam_time: np.ndarray
    lines: Tuple = ()
    line_beam_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    line_sigma_r: Optional[float] = None
    scan: Optional[ScanGeometry] = None
    lines_from: Optional[Callable[[], Tuple[Tuple, np.ndarray]]] = None
    lines_until: float = 0.0

    def with_lines(self) -> 'Corners':
        """Return the set with the lines of ``lines_from`` extracted (else itself)."""
        if self.lines_from is None:
            return self
        lines, beam_time = self.lines_from()
        return replace(self, lines=tuple(lines), line_beam_time=beam_time, lines_from=None)

    @classmethod
    def from_corners(cls, stamp_ns: int, corners: Sequence, time_increment: float = 0.0,
                     lines: Sequence = (), line_sigma_r: Optional[float] = None,
                     scan: Optional[ScanGeometry] = None) -> 'Corners':
        """Build from one scan's :class:`~landmark_nav.laser.corners.Corner` objects.

        Args:
            stamp_ns: Scan stamp [ns].
            corners: The corners.
            time_increment: The scan's time between beams [s].
            lines: The scan's line segments (``landmarks: lines|both``).
            line_sigma_r: See the class attributes.
            scan: See the class attributes.
        """
        m = len(corners)
        lines = tuple(lines)
        return cls(int(stamp_ns),
                   np.array([c.position for c in corners], dtype=float).reshape(m, 2),
                   np.array([c.covariance for c in corners], dtype=float).reshape(m, 2, 2),
                   np.array([c.bisector for c in corners], dtype=float).reshape(m),
                   np.array([c.opening for c in corners], dtype=float).reshape(m),
                   float(time_increment) * np.array([c.index for c in corners],
                                                    dtype=float).reshape(m),
                   lines, line_beam_times(lines, time_increment), line_sigma_r, scan)

    def __len__(self) -> int:
        """Return the number of corners."""
        return self.positions.shape[0]

    @property
    def nbytes(self) -> int:
        """Approximate memory of the set [bytes].

        Its arrays, the scan's ranges, 1 KiB per line and 1 KiB for the Python objects.
        """
        arrays = (self.positions, self.covariances, self.bisector, self.opening,
                  self.beam_time, self.line_beam_time)
        scan = 0 if self.scan is None else np.asarray(self.scan.ranges).nbytes
        return sum(a.nbytes for a in arrays) + scan + 1024 * (1 + len(self.lines))

    def items(self) -> List['_Corner']:
        """Per-corner records for :func:`.observations.corners_to_observations`."""
        return [_Corner(p, c, b, o) for p, c, b, o in zip(self.positions, self.covariances,
                                                          self.bisector, self.opening)]


@dataclass(frozen=True, eq=False)
class _Corner:
    position: np.ndarray
    covariance: np.ndarray
    bisector: float
    opening: float


@dataclass(frozen=True, eq=False)
class Step:
    """One processed feature set.

    Attributes:
        stamp_ns: Its stamp [ns].
        odometry: (3,) odometry pose interpolated at the stamp (bridged frame).
        increment: (3,) the increment predicted with: the odometry's (eq. 13) or the
            scan-matched motion (``motion``).
        bridged_variance: (3,) variance added for bridged odometry jumps in the step (such
            a step always predicts with the odometry).
        result: The filter's association result.
        pose: (3,) the filter's robot pose after the step (a copy).
        covariance: (3, 3) its covariance (a copy).
        slam: The filter (the live object: when several steps come back at once it is
            already past the earlier ones; use ``pose`` / ``covariance``, or the
            ``on_step`` callback of :class:`SlamFrontend` for the full state).
        tag: The ``tag`` given to :meth:`SlamFrontend.add_features`.
        motion: What ``increment`` is: ``odometry`` or ``scan_matching``
            (:data:`MOTION_SOURCES`).
        keyframe: False for a set between keyframes (:mod:`.keyframes`): ``increment`` is
            the odometry's since the last keyframe, ``pose`` / ``covariance`` predicted
            from it on a copy, ``result`` empty; the filter did not change.
    """

    stamp_ns: int
    odometry: np.ndarray
    increment: np.ndarray
    bridged_variance: np.ndarray
    result: UpdateResult
    pose: np.ndarray
    covariance: np.ndarray
    slam: EkfSlam
    tag: object = None
    motion: str = 'odometry'
    keyframe: bool = True


@dataclass
class _Pending:
    stamp_ns: int
    need_ns: int
    corners: Corners
    tag: object = None
    seq: int = 0


@dataclass
class _Buffer:
    """Accepted odometry (bridged frame) and the raw sample before it."""

    t: List[int] = field(default_factory=list)
    pose: List[np.ndarray] = field(default_factory=list)
    extra: List[np.ndarray] = field(default_factory=list)  # bridged variance ending here
    raw_last: Optional[np.ndarray] = None
    cov_last: Optional[np.ndarray] = None
    offset: Optional[np.ndarray] = None  # bridged = offset (+) raw (None: bridged = raw)
    previous: Optional[tuple] = None  # (raw_last, cov_last, offset) before the last sample


class SlamFrontend:
    """Odometry buffer, checks, interpolation, de-skew and the filter (module docstring).

    Args:
        params: Filter parameters (``params.odometry`` is the noise model ``U``).
        laser_mount: Laser pose ``[x, y, yaw]`` in base_link.
        frontend: Front-end parameters.
        on_event: Called as ``on_event(kind, message)`` for every odometry or feature set
            that is not used as it came (kinds of :data:`ODOMETRY_EVENTS` /
            :data:`FEATURE_EVENTS` other than 'accepted' and 'processed').
        on_step: Called as ``on_step(step)`` right after each step, before the next one.
        slam_map: Start the filter on this saved map (:meth:`EkfSlam.load_map`, e.g. with
            ``params.mode == 'localization'``), the first accepted odometry pose being the
            robot's pose on it; after a restart the filter starts on it again.
        map_pose_covariance: (3, 3) covariance of that start pose (default zeros).
    """

    def __init__(self, params: Optional[SlamParams] = None,
                 laser_mount: Sequence[float] = (0.0, 0.0, 0.0),
                 frontend: Optional[FrontendParams] = None,
                 on_event: Optional[Callable[[str, str], None]] = None,
                 on_step: Optional[Callable[['Step'], None]] = None,
                 slam_map: Optional[SlamMap] = None,
                 map_pose_covariance: Optional[np.ndarray] = None) -> None:
        """Start empty: the filter starts at the first accepted odometry sample."""
        self.slam_map = slam_map
        self.map_pose_covariance = (np.zeros((3, 3)) if map_pose_covariance is None else
                                    np.asarray(map_pose_covariance, dtype=float))
        if self.map_pose_covariance.shape != (3, 3):
            raise ValueError('map_pose_covariance must be a (3, 3) matrix, got shape '
                             f'{self.map_pose_covariance.shape}')
        self.params = params or SlamParams()
        self.frontend = frontend or FrontendParams()
        self.mount = np.asarray(laser_mount, dtype=float).reshape(3)
        if not np.all(np.isfinite(self.mount)):
            raise ValueError(f'laser_mount must be 3 finite numbers, got {laser_mount!r}')
        self.on_event = on_event
        self.on_step = on_step
        self.events: Dict[str, int] = dict.fromkeys(ODOMETRY_EVENTS + FEATURE_EVENTS, 0)
        #: Steps predicted with each motion (:data:`MOTION_SOURCES`).
        self.motions: Dict[str, int] = dict.fromkeys(MOTION_SOURCES, 0)
        #: Steps whose first ICP solution failed or was rejected (``restarted``) and those
        #: a restart from other headings made usable (``recovered``):
        #: :func:`.scan_matching.scan_motion`.
        self.icp_restarts: Dict[str, int] = {'restarted': 0, 'recovered': 0}
        #: Sets that went to the filter (``keyframes``) and sets in between (``skipped``).
        self.keyframes: Dict[str, int] = {'keyframes': 0, 'skipped': 0}
        self._scan_noise = odometry_noise_model(self.frontend.scan_matching_noise)
        self._scan_accept = chi2_gate(3, self.frontend.scan_matching_accept)
        self.restarts = 0
        self._seq = 0
        self.clear()

    # ------------------------------------------------------------------ state
    def clear(self) -> None:
        """Forget the filter, the odometry and the waiting feature sets."""
        self.slam: Optional[EkfSlam] = None
        self.t0: Optional[int] = None
        self._buf = _Buffer()
        self._back_run = BackwardRun(self.frontend.restart_messages)
        self._pending: List[_Pending] = []
        self._pending_bytes = 0
        self.last_step: Optional[Tuple[int, np.ndarray]] = None  # the last keyframe's
        self.last_stamp: Optional[int] = None  # the last set processed
        self._keyframed = False  # a keyframe was processed since the start
        self._stepped = False  # a set was processed since the start
        self._extra_since = np.zeros(3)  # bridged variance already predicted with
        self._scan_points: Optional[np.ndarray] = None  # the last step's scan (matching)

    @property
    def pending(self) -> List[Tuple[int, object]]:
        """Feature sets waiting for odometry as ``(stamp_ns, tag)``, stamp order."""
        return [(p.stamp_ns, p.tag) for p in self._pending]

    @property
    def pending_bytes(self) -> int:
        """Approximate memory of the waiting feature sets [bytes] (:attr:`Corners.nbytes`)."""
        return self._pending_bytes

    @property
    def odometry_span(self) -> Optional[Tuple[int, int]]:
        """(first, last) stamp of the buffered odometry [ns], None when empty."""
        return (self._buf.t[0], self._buf.t[-1]) if self._buf.t else None

    def _event(self, kind: str, message: str = '') -> str:
        self.events[kind] += 1
        if self.on_event is not None and kind not in ('accepted', 'processed'):
            self.on_event(kind, message)
        return kind

    # ------------------------------------------------------------------ odometry
    def add_odometry(self, stamp_ns: int, pose: Sequence[float],
                     covariance: Optional[np.ndarray] = None) -> Tuple[str, List[Step]]:
        """Buffer one odometry sample and process the feature sets it completes.

        Args:
            stamp_ns: Stamp [ns].
            pose: (3,) odometry pose ``[x, y, psi]`` (odom frame).
            covariance: Optional (3, 3) stated covariance of the pose (checked only).

        Returns:
            ``(event, steps)``: one of :data:`ODOMETRY_EVENTS` and the steps made.
        """
        stamp_ns = int(stamp_ns)
        pose = np.asarray(pose, dtype=float).reshape(3)
        cov = None if covariance is None else np.asarray(covariance, dtype=float).reshape(3, 3)
        if not np.all(np.isfinite(pose)):
            return self._event('invalid', f'odometry pose {pose.tolist()} is not finite'), []
        if stamp_ns <= 0:
            return self._event('invalid', f'odometry stamp {stamp_ns} ns is not a time (an '
                               'unset header)'), []
        problem = None if cov is None else covariance_problem(cov)
        if problem is not None:
            cov = None
            self._event('covariance', f'odometry covariance at {stamp_ns} ns is {problem}: '
                        'using the odometry noise model')
        b = self._buf
        if not b.t:
            self._accept(stamp_ns, pose, pose.copy(), cov, np.zeros(3), b.offset)
            if self.slam is None:
                self.slam = EkfSlam(self.params, initial_pose=pose)
                if self.slam_map is not None:
                    self.slam.load_map(self.slam_map, pose, self.map_pose_covariance)
                self.t0 = stamp_ns
                self.last_step = (stamp_ns, pose.copy())
                while self._pending and self._pending[0].stamp_ns < stamp_ns:
                    self._before_odometry(self._pop_pending().stamp_ns)
            return self._event('accepted'), self.process()
        last = b.t[-1]
        if stamp_ns == last:
            if np.array_equal(pose, b.raw_last):
                return self._event('repeated', f'odometry stamp {stamp_ns} ns repeated'), []
            return self._event('conflicting', f'odometry stamp {stamp_ns} ns repeated with '
                               f'another pose {pose.tolist()} (kept the first '
                               f'{b.raw_last.tolist()})'), []
        if stamp_ns < last:
            return self._backward(stamp_ns, pose, cov)
        self._drop_back_run()
        dt = (stamp_ns - last) * 1e-9
        f = self.frontend
        why = odometry_jump(b.raw_last, pose, dt, self.params.odometry, f)
        if why is None:
            self._accept(stamp_ns, pose, bridged(b.offset, pose), cov, np.zeros(3), b.offset)
            return self._event('accepted'), self.process()
        span = max(dt, f.min_step_s)
        extra = np.array([(f.max_speed * span) ** 2, (f.max_speed * span) ** 2,
                          (f.max_turn_rate * span) ** 2])
        offset = bridge_offset(b.pose[-1], pose)  # bridged(pose) == last bridged pose
        self._accept(stamp_ns, pose, b.pose[-1].copy(), cov, extra, offset)
        return self._event('jump', f'odometry {why} in {dt:.3f} s: bridged as a '
                           f'discontinuity of the odometry frame (map kept)'), self.process()

    def _backward(self, t: int, pose: np.ndarray, cov: Optional[np.ndarray]
                  ) -> Tuple[str, List[Step]]:
        """Drop an older sample; restart (or withdraw a future stamp) when persistent."""
        b, f = self._buf, self.frontend
        back = (b.t[-1] - t) * 1e-9
        if back <= f.max_backward_s:
            return self._event('backward', f'odometry stamp {t} ns is {back:.3f} s older '
                               f'than the last one ({b.t[-1]} ns): dropped'), []
        if not self._back_run.continues(t):
            self._drop_back_run()
        if not self._back_run.add(t, pose, cov):
            return self._event('far_back', f'odometry stamp {t} ns is {back:.3f} s older than '
                               f'the last one ({b.t[-1]} ns): held, {len(self._back_run.samples)}'
                               f' of {f.restart_messages} in a row restart'), []
        run = self._back_run.clear()
        before = b.t[-2] if len(b.t) >= 2 and b.previous is not None else None
        ahead = future_stamp(before, b.t[-1], run[0][0], f.max_backward_s)
        if ahead is not None:
            kind = self._event('retracted', f'odometry stamp {b.t[-1]} ns lay {ahead:.3f} s '
                               'ahead of the samples around it: withdrawn')
            del b.t[-1], b.pose[-1], b.extra[-1]
            b.raw_last, b.cov_last, b.offset = b.previous
            b.previous = None
        else:
            self.restarts += 1
            self.clear()
            kind = self._event('restart', f'odometry went {back:.3f} s back in time '
                               f'({len(run)} samples in a row, {b.t[-1]} -> {t} ns): '
                               'restarting with an empty map')
        steps = []
        for sample in run:
            steps += self.add_odometry(*sample)[1]
        return kind, steps

    def _drop_back_run(self) -> None:
        """Drop the far-back samples held: the run ended before it restarted anything."""
        for t, _, _ in self._back_run.clear():
            self._event('backward', f'odometry stamp {t} ns lay more than '
                        f'{self.frontend.max_backward_s:g} s back, too few in a row for a '
                        'restart: dropped')

    def _accept(self, t: int, raw: np.ndarray, bridged: np.ndarray,
                cov: Optional[np.ndarray], extra: np.ndarray,
                offset: Optional[np.ndarray]) -> None:
        b = self._buf
        b.previous = (b.raw_last, b.cov_last, b.offset)
        b.t.append(t)
        b.pose.append(bridged)
        b.extra.append(extra)
        b.raw_last, b.cov_last, b.offset = raw, cov, offset
        keep_from = t - int(self.frontend.buffer_s * 1e9)
        drop = bisect.bisect_left(b.t, keep_from) - 1  # keep one sample before keep_from
        if drop > 0:
            del b.t[:drop], b.pose[:drop], b.extra[:drop]

    # ------------------------------------------------------------------ features
    def add_features(self, corners: Corners, tag: object = None) -> List[Step]:
        """Queue one scan's corners; process what the odometry covers.

        Args:
            corners: The scan's corners.
            tag: Anything the caller wants back with the set (e.g. a receive time).

        Returns:
            The steps made (possibly none, possibly older sets too).
        """
        t = int(corners.stamp_ns)
        if self.slam is not None:
            first = self._buf.t[0]
            if t < self.t0:  # no odometry pose for it (module docstring), even after steps
                self._before_odometry(t)
                return []
            if self._stepped and t < self.last_stamp or first != self.t0 and t < first:
                self._event('out_of_order', f'corners at {t} ns are older than the last step '
                            f'({self.last_stamp} ns) or the buffered odometry: skipped')
                return []
        bt = np.concatenate([corners.beam_time, corners.line_beam_time,
                             [corners.lines_until] if corners.lines_from else []])
        need = t + (int(math.ceil(float(np.max(bt)) * 1e9))
                    if self.frontend.deskew and bt.size and np.max(bt) > 0 else 0)
        self._seq += 1
        self._pending_bytes += corners.nbytes
        bisect.insort(self._pending, _Pending(t, need, corners, tag, self._seq),
                      key=lambda p: (p.stamp_ns, p.seq))
        return self.process()

    def drop_oldest_pending(self) -> Optional[Tuple[int, object]]:
        """Remove and return the oldest waiting set ``(stamp_ns, tag)`` (queue bound)."""
        if not self._pending:
            return None
        p = self._pop_pending()
        return p.stamp_ns, p.tag

    def _pop_pending(self) -> _Pending:
        """Remove and return the oldest waiting set."""
        p = self._pending.pop(0)
        self._pending_bytes -= p.corners.nbytes
        return p

    def _before_odometry(self, t: int) -> None:
        """Report a set stamped before the first odometry sample (no pose for it)."""
        self._event('before_odometry', f'corners at {t} ns are {(self.t0 - t) * 1e-6:.1f} ms '
                    f'older than the first odometry ({self.t0} ns): no odometry pose for '
                    'them, not processed')

    def process(self) -> List[Step]:
        """Process waiting feature sets the odometry covers, in stamp order."""
        steps = []
        while self._pending and self._buf.t and self._pending[0].need_ns <= self._buf.t[-1]:
            steps.append(self._step(self._pop_pending()))
        return steps

    def flush(self) -> List[Step]:
        """Process the waiting sets whose stamp the odometry covers (beams after: held)."""
        steps = self.process()
        while self._pending and self._buf.t and self._pending[0].stamp_ns <= self._buf.t[-1]:
            p = self._pop_pending()
            self._event('held', f'corners at {p.stamp_ns} ns: odometry ends before the last '
                        f'beam, holding its last pose for the de-skew')
            steps.append(self._step(p))
        return steps

    def _step(self, p: _Pending) -> Step:
        b = self._buf
        t = p.stamp_ns
        # The samples around [stamp, last beam] (interpolation uses the bracketing pair only).
        lo = max(bisect.bisect_right(b.t, t) - 1, 0)
        hi = min(bisect.bisect_left(b.t, p.need_ns) + 1, len(b.t))
        ts = (np.asarray(b.t[lo:hi], dtype=np.int64) - self.t0) * 1e-9
        ps = np.array(b.pose[lo:hi])
        odo = np.asarray(interpolate_pose((t - self.t0) * 1e-9, ts, ps),
                         dtype=float).reshape(3)
        prev_t, prev_odo = self.last_step
        # Bridged variance of the jumps in (prev_t, t].
        extra = np.zeros(3)
        for k in range(bisect.bisect_right(b.t, prev_t), bisect.bisect_right(b.t, t)):
            extra += b.extra[k]
        u = relative(prev_odo, odo)  # eq. 13
        c = p.corners
        u_cov = None
        if np.any(extra > 0.0):
            u_cov = odometry_noise(u, self.params.odometry) + np.diag(extra)
        elif self._keyframed and not self.frontend.keyframe.is_keyframe(u):
            return self._between_keyframes(p, odo, u)
        self.last_stamp = t
        self._keyframed = True
        c = c.with_lines()
        source = 'odometry'
        if self.frontend.scan_matching:
            # Across a bridged jump the increment is unknown (bridged as no motion): no
            # guess for the ICP, and the jump's variance must stay in U; the odometry's.
            u, u_cov, source = self._scan_matched(c.scan, u, u_cov, bool(np.any(extra > 0.0)))
        self.motions[source] += 1
        self.slam.predict(u, u_cov)
        motion = lmotion = None
        if self.frontend.deskew:
            t_rel = (t - self.t0) * 1e-9
            if len(c) and np.any(c.beam_time != 0.0):
                # Beyond the odometry (flush): hold its last pose.
                tb = np.clip(t_rel + c.beam_time, ts[0], ts[-1])
                motion = relative(odo, interpolate_pose(tb, ts, ps, extrapolate=True))
            if len(c.lines) and np.any(c.line_beam_time != 0.0):
                tb = np.clip(t_rel + c.line_beam_time, ts[0], ts[-1])
                lmotion = relative(odo, interpolate_pose(tb, ts, ps, extrapolate=True))
        items = c.items()
        z, r = corners_to_observations(items, self.mount, motion)
        desc = (corner_descriptors(items, self.mount, motion) if self.frontend.descriptors
                else None)
        lines = (lines_to_observations(c.lines, self.mount, lmotion, c.line_sigma_r)
                 if len(c.lines) else None)
        res = self.slam.update(z, r, desc, lines=lines, scan=c.scan)
        self.last_step = (t, odo)
        self._stepped = True
        self._event('processed')
        return self._stepped_with(Step(
            stamp_ns=t, odometry=odo, increment=u, bridged_variance=extra, result=res,
            pose=self.slam.pose, covariance=self.slam.pose_covariance, slam=self.slam,
            tag=p.tag, motion=source))

    def _between_keyframes(self, p: _Pending, odo: np.ndarray, u: np.ndarray) -> Step:
        """Step a set between keyframes: its pose from the odometry, the filter unchanged."""
        self.last_stamp = p.stamp_ns
        self._stepped = True
        self._event('processed')
        self.keyframes['skipped'] += 1
        pose, cov = pose_between_keyframes(self.slam.pose, self.slam.pose_covariance, u,
                                           odometry_noise(u, self.params.odometry))
        return self._stepped_with(Step(
            stamp_ns=p.stamp_ns, odometry=odo, increment=u, bridged_variance=np.zeros(3),
            result=NO_UPDATE, pose=pose, covariance=cov, slam=self.slam, tag=p.tag,
            keyframe=False))

    def _stepped_with(self, step: Step) -> Step:
        if step.keyframe:
            self.keyframes['keyframes'] += 1
        if self.on_step is not None:
            self.on_step(step)
        return step

    def _scan_matched(self, scan: Optional[ScanGeometry], u: np.ndarray,
                      u_cov: Optional[np.ndarray], bridged: bool
                      ) -> Tuple[np.ndarray, Optional[np.ndarray], str]:
        """Return ``(increment, U, source)``: the scan-matched motion when usable."""
        previous = self._scan_points
        self._scan_points = None
        if scan is None:
            return u, u_cov, 'odometry'
        fp = self.frontend
        self._scan_points = scan_points(scan.ranges, scan.angle_min, scan.angle_increment,
                                        scan.range_min,
                                        min(scan.range_max, fp.scan_matching_max_range))
        if previous is None or bridged:
            return u, u_cov, 'odometry'
        # U as the noise model: the test evaluates U and V at the same (larger) motion.
        cov = (lambda m: odometry_noise(m, self.params.odometry)) if u_cov is None else u_cov
        if self.frontend.scan_matching_fit_pairs > 0.0:
            fused = fused_scan_motion(previous, self._scan_points, u, cov, self.mount,
                                      self._scan_accept,
                                      lambda m: odometry_noise(m, self._scan_noise),
                                      self.frontend.scan_matching_fit_pairs, self.icp_restarts,
                                      self.frontend.scan_matching_side_starts)
            if fused is None:
                return u, u_cov, 'odometry'
            return fused[0], fused[1], 'scan_matching'
        v = scan_motion(previous, self._scan_points, u, cov, self.mount, self._scan_accept,
                        lambda m: odometry_noise(m, self._scan_noise), self.icp_restarts,
                        self.frontend.scan_matching_side_starts)
        if v is None:
            return u, u_cov, 'odometry'
        return v, odometry_noise(v, self._scan_noise), 'scan_matching'


__all__ = ['Corners', 'FEATURE_EVENTS', 'FrontendParams', 'line_beam_times', 'MOTION_SOURCES',
           'ODOMETRY_EVENTS', 'ODOMETRY_NOISE_MODELS', 'odometry_noise_model', 'SlamFrontend',
           'Step']
