"""A controller that holds a lateral position in the corridor at a set speed (pure Python).

Not from the chapter (it drives along the corridor but does not give its control law).
State feedback on the fused estimate (heading ``theta``, lateral position ``y``, corridor
frame of :mod:`.lateral`) for a unicycle at forward speed ``v``::

    omega = -k_theta theta - k_y v (y - y_ref)          (clipped to +-max_angular_speed)

(``k_y v`` makes the lateral gain per metre driven, so the path does not depend on the
speed.) The linearised lateral dynamics ``y'' + k_theta y' + k_y v^2 y = 0`` are critically
damped for ``k_theta = 2 v sqrt(k_y)``. The forward speed ramps to ``speed`` with
``max_accel`` and drops to 0 at once when the estimate is not usable (lost or stale).
"""

from dataclasses import dataclass
import math
from typing import Tuple


@dataclass(frozen=True)
class ControllerParams:
    """Controller parameters.

    Attributes:
        speed: forward speed set-point [m/s] (> 0).
        lateral_offset: lateral set-point y_ref [m] (0 = the centre line, left positive).
        gain_lateral: k_y [rad/m^2]: heading correction per metre of lateral error per
            metre driven.
        gain_heading: k_theta [1/s].
        max_accel: forward acceleration limit [m/s^2].
        max_angular_speed: angular speed limit [rad/s].
    """

    speed: float = 0.3
    lateral_offset: float = 0.0
    gain_lateral: float = 1.0
    gain_heading: float = 0.6
    max_accel: float = 0.3
    max_angular_speed: float = 0.5

    def __post_init__(self) -> None:
        """Validate."""
        for name in ('speed', 'gain_lateral', 'gain_heading', 'max_accel', 'max_angular_speed'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f'{name} must be > 0; got {v}')


class CorridorController:
    """Speed ramp + the steering law of the module docstring."""

    def __init__(self, params: ControllerParams = ControllerParams()) -> None:
        """Start at rest."""
        self.params = params
        self.v = 0.0

    def step(self, theta: float, y: float, dt: float, usable: bool) -> Tuple[float, float]:
        """Return ``(v, omega)`` for the next ``dt`` seconds (``(0, 0)`` when not usable)."""
        p = self.params
        if not usable or not (math.isfinite(theta) and math.isfinite(y)):
            self.v = 0.0
            return 0.0, 0.0
        dt = max(0.0, float(dt))
        self.v = min(p.speed, self.v + p.max_accel * dt)
        omega = -p.gain_heading * theta - p.gain_lateral * self.v * (y - p.lateral_offset)
        omega = max(-p.max_angular_speed, min(p.max_angular_speed, omega))
        return self.v, omega
