"""Mission primitives and a simple motion controller producing piecewise-constant wheel commands.

The controller runs at the sampling time T. Each step it picks a nominal body twist
``(v, w)`` subject to the speed and acceleration limits of :class:`RobotParams`, converts it
to wheel angular velocities with the NOMINAL R, b (what the robot firmware does), and the
true robot then moves with the systematic error (eqs. 17-18). Closed-loop primitives
(:class:`GoTo`, :class:`TurnTo`) use the TRUE pose as feedback (a perfectly localised robot),
so the ground-truth path stays where the scenario designer put it; :class:`Straight` is open
loop in wheel space (equal wheel speeds, the robot *believes* it drives straight), as in the
odometry calibration experiments.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from .robot import make_trajectory, RobotParams, Trajectory, twist_to_wheels

ALIGN_TOL = 0.02  # rad, turn-in-place phase of GoTo ends below this heading error
TURN_TOL = 1e-4  # rad, TurnTo ends below this heading error
TURN_ENTER = math.radians(30.0)  # GoTo re-enters turn-in-place above this heading error
HEADING_GAIN = 2.0  # 1/s, GoTo heading feedback while driving
FINAL_APPROACH = 0.15  # m, GoTo holds its heading inside this distance of a stop waypoint
DECEL_MARGIN = 0.8  # use this fraction of the acceleration limits for braking profiles
MAX_PRIMITIVE_STEPS = 20000


@dataclass(frozen=True)
class GoTo:
    """Drive to ``(x, y)``: turn in place toward it if needed, then drive (true-pose feedback).

    Attributes:
        x: target x [m].
        y: target y [m].
        tolerance: reached when closer than this [m].
        pass_speed: speed allowed when reaching the point [m/s] (0 = come to a stop).
        tag: optional label carried into the primitive log.
    """

    x: float
    y: float
    tolerance: float = 0.03
    pass_speed: float = 0.0
    tag: Optional[str] = None


@dataclass(frozen=True)
class Straight:
    """Open-loop straight run: equal wheel speeds, nominal distance (odometry believes it).

    Attributes:
        distance: nominal distance [m] (negative = backwards); trapezoidal speed profile.
        speed: cruise speed [m/s] (capped by ``max_linear_speed``).
        tag: optional label.
    """

    distance: float
    speed: float = 0.3
    tag: Optional[str] = None


@dataclass(frozen=True)
class TurnTo:
    """Turn in place until the TRUE heading equals ``heading`` (true-pose feedback).

    Attributes:
        heading: target world heading [rad].
        direction: +1 counter-clockwise, -1 clockwise.
        tag: optional label.
    """

    heading: float
    direction: int = 1
    tag: Optional[str] = None


@dataclass(frozen=True)
class Wait:
    """Brake to a stop (within the acceleration limits) and stand still for ``duration`` [s]."""

    duration: float
    tag: Optional[str] = None


Primitive = Union[GoTo, Straight, TurnTo, Wait]


@dataclass(frozen=True)
class PrimitiveSpan:
    """Step range of one executed primitive: commands ``start_step .. end_step - 1``."""

    index: int
    primitive: Primitive
    start_step: int
    end_step: int


def straight_profile(distance: float, speed: float, accel: float, dt: float) -> np.ndarray:
    """Per-step speeds (>= 0) of a trapezoidal profile covering ``|distance|`` exactly.

    The shortest ramp-cruise-ramp profile reaching at least the distance is scaled down
    uniformly, which preserves the speed and acceleration limits.
    """
    length = abs(float(distance))
    if length == 0.0:
        return np.zeros(0)
    dv = accel * dt
    m = max(1, int(math.ceil(speed / dv - 1e-12)))
    up = np.minimum(dv * np.arange(1, m + 1), speed)
    ramps = dt * (up.sum() + up[:-1].sum())
    if ramps >= length:
        m2 = max(1, int(math.ceil(math.sqrt(length / (dv * dt)) - 1e-12)))
        up = dv * np.arange(1, m2 + 1)
        prof = np.concatenate([up, up[:-1][::-1]])
    else:
        nc = int(math.ceil((length - ramps) / (speed * dt) - 1e-12))
        prof = np.concatenate([up, np.full(nc, speed), up[:-1][::-1]])
    return prof * (length / (dt * prof.sum()))


def waypoint_mission(points: Sequence[Sequence[float]], params: RobotParams,
                     stop_turn: float = math.radians(20.0), pass_tolerance: float = 0.25,
                     stop_tolerance: float = 0.03) -> List[Primitive]:
    """Build :class:`GoTo` primitives; stop at a waypoint only if the path turns sharply there.

    The last waypoint is always a stop point.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    out: List[Primitive] = []
    for i, p in enumerate(pts):
        stop = i == pts.shape[0] - 1
        if not stop:
            d_in = p - pts[i - 1] if i > 0 else None
            d_out = pts[i + 1] - p
            if d_in is not None:
                turn = abs(math.remainder(math.atan2(d_out[1], d_out[0])
                                          - math.atan2(d_in[1], d_in[0]), 2.0 * math.pi))
                stop = turn > stop_turn
            else:
                stop = True
        if stop:
            out.append(GoTo(float(p[0]), float(p[1]), tolerance=stop_tolerance))
        else:
            out.append(GoTo(float(p[0]), float(p[1]), tolerance=pass_tolerance,
                            pass_speed=params.max_linear_speed))
    return out


def brake_speed(dist: float, accel: float, dt: float, final: float = 0.0) -> float:
    """Largest speed that can still brake to ``final`` within ``dist`` in steps of ``dt``.

    With per-step decrements ``dv = accel dt`` the braking distance from speed ``u`` is
    about ``dt (u^2 / (2 dv) + u / 2)``; solving for ``u`` avoids the overshoot of the
    continuous-time ``sqrt(2 a d)`` profile.
    """
    dv = accel * dt
    extra = final * final / (2.0 * dv) + 0.5 * final
    return dv * (-0.5 + math.sqrt(0.25 + 2.0 * (dist / dt + extra) / dv))


def limit_twist(p: RobotParams, v_des: float, w_des: float, v: float, w: float
                ) -> Tuple[float, float]:
    """Return the command (v, w) closest to the desired one within one step of (v, w).

    Each speed changes by at most its acceleration times ``p.sample_time`` and stays within
    its maximum.
    """
    dt = p.sample_time
    dv, dw = p.max_linear_accel * dt, p.max_angular_accel * dt
    return (min(max(v_des, v - dv, -p.max_linear_speed), v + dv, p.max_linear_speed),
            min(max(w_des, w - dw, -p.max_angular_speed), w + dw, p.max_angular_speed))


class _Controller:
    """Stepwise controller state (true pose feedback, last nominal command)."""

    def __init__(self, params: RobotParams, pose0: Sequence[float]) -> None:
        self.p = params
        self.x, self.y, self.th = (float(v) for v in pose0)
        self.v = 0.0
        self.w = 0.0
        self.wheels: List[Tuple[float, float]] = []

    def apply(self, v_des: float, w_des: float) -> None:
        """Limit, convert to wheel speeds and advance the internal true pose one step."""
        p = self.p
        dt = p.sample_time
        v, w = limit_twist(p, v_des, w_des, self.v, self.w)
        wl, wr = twist_to_wheels(v, w, p.wheel_radius, p.axle_length)
        wl, wr = float(wl), float(wr)
        r, b = p.wheel_radius, p.axle_length
        vt = 0.5 * (p.k1 * r * wl + p.k2 * r * wr)  # eq. 17
        wt = (p.k2 * r * wr - p.k1 * r * wl) / (p.k3 * b)  # eq. 18
        mid = self.th + 0.5 * wt * dt
        self.x += vt * dt * math.cos(mid)  # eq. 1
        self.y += vt * dt * math.sin(mid)  # eq. 2
        self.th += wt * dt  # eq. 3
        self.v, self.w = v, w
        self.wheels.append((wl, wr))

    def turn_rate(self, err: float) -> float:
        """Braking-limited turn rate toward a remaining heading error."""
        p = self.p
        mag = min(p.max_angular_speed,
                  brake_speed(abs(err), DECEL_MARGIN * p.max_angular_accel, p.sample_time),
                  abs(err) / p.sample_time)
        return math.copysign(mag, err)

    def run(self, prim: Primitive) -> None:
        """Execute one primitive to completion."""
        if isinstance(prim, Wait):
            for _ in range(int(round(prim.duration / self.p.sample_time))):
                self.apply(0.0, 0.0)
        elif isinstance(prim, Straight):
            speed = min(prim.speed, self.p.max_linear_speed)
            prof = straight_profile(prim.distance, speed, self.p.max_linear_accel,
                                    self.p.sample_time)
            sign = 1.0 if prim.distance >= 0 else -1.0
            for v in prof:
                self.apply(sign * float(v), 0.0)
        elif isinstance(prim, TurnTo):
            self._turn_to(prim)
        elif isinstance(prim, GoTo):
            self._goto(prim)
        else:
            raise TypeError(f'unknown primitive {prim!r}')

    def _turn_to(self, prim: TurnTo) -> None:
        if prim.direction not in (1, -1):
            raise ValueError('TurnTo.direction must be +1 or -1')
        two_pi = 2.0 * math.pi
        if prim.direction > 0:
            e0 = (prim.heading - self.th) % two_pi
        else:
            e0 = -((self.th - prim.heading) % two_pi)
        target = self.th + e0
        for _ in range(MAX_PRIMITIVE_STEPS):
            err = target - self.th
            if abs(err) < TURN_TOL:
                return
            self.apply(0.0, self.turn_rate(err))
        raise RuntimeError('TurnTo did not converge')

    def _goto(self, prim: GoTo) -> None:
        p = self.p
        dt = p.sample_time
        turning = None
        for _ in range(MAX_PRIMITIVE_STEPS):
            dx, dy = prim.x - self.x, prim.y - self.y
            dist = math.hypot(dx, dy)
            err = math.remainder(math.atan2(dy, dx) - self.th, 2.0 * math.pi)
            if dist < prim.tolerance:
                return
            if dist < FINAL_APPROACH and abs(err) > 0.5 * math.pi:
                return  # passed it: accept rather than circle back
            if turning is None:
                turning = abs(err) > math.radians(10.0)
            if turning and abs(err) < ALIGN_TOL:
                turning = False
            elif not turning and abs(err) > TURN_ENTER and dist > FINAL_APPROACH:
                turning = True
            if turning:
                self.apply(0.0, self.turn_rate(err))
                continue
            v = min(p.max_linear_speed,
                    brake_speed(dist, DECEL_MARGIN * p.max_linear_accel, dt, prim.pass_speed))
            if prim.pass_speed == 0.0:
                v = min(v, dist / dt)
            v *= max(0.0, math.cos(err))
            w = 0.0 if (dist < FINAL_APPROACH and prim.pass_speed == 0.0) else \
                max(-p.max_angular_speed, min(p.max_angular_speed, HEADING_GAIN * err))
            self.apply(v, w)
        raise RuntimeError(f'GoTo({prim.x}, {prim.y}) did not converge')


def simulate_mission(params: RobotParams, start_pose: Sequence[float],
                     mission: Sequence[Primitive],
                     start_ns: int) -> Tuple[Trajectory, List[PrimitiveSpan]]:
    """Run the mission from rest; return the true trajectory and each primitive's step span."""
    ctl = _Controller(params, start_pose)
    spans: List[PrimitiveSpan] = []
    for i, prim in enumerate(mission):
        s0 = len(ctl.wheels)
        ctl.run(prim)
        spans.append(PrimitiveSpan(index=i, primitive=prim, start_step=s0,
                                   end_step=len(ctl.wheels)))
    wheels = np.array(ctl.wheels, dtype=float).reshape(-1, 2)
    traj = make_trajectory(start_ns, start_pose, wheels, params)
    return traj, spans
