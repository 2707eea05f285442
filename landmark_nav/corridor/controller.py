"""A controller that holds a lateral position in the corridor at a set speed (pure Python).

Not from the chapter (it drives along the corridor but does not give its control law).
State feedback on the fused estimate (heading ``theta``, lateral position ``y``, both
relative to the direction of travel) for a unicycle at forward speed ``v``::

    omega = -v (k_theta theta + k_y (y - y_ref))         (clipped to +-max_angular_speed)

Both gains are per metre driven, so the path does not depend on the speed: along the
distance ``s``, the linearised lateral dynamics are ``y'' + k_theta y' + k_y y = 0``,
critically damped for ``k_theta = 2 sqrt(k_y)`` (the defaults: k_y = 4 / m^2, k_theta =
4 / m, a lateral error halved about every 0.8 m). The forward speed ramps to ``speed``
with ``max_accel`` and drops to 0 at once when the estimate is not usable (lost or stale).
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
        gain_lateral: k_y [1/m^2]: turn per metre driven per metre of lateral error.
        gain_heading: k_theta [1/m]: turn per metre driven per radian of heading error.
        max_accel: forward acceleration limit [m/s^2].
        max_angular_speed: angular speed limit [rad/s].
    """

    speed: float = 0.3
    lateral_offset: float = 0.0
    gain_lateral: float = 4.0
    gain_heading: float = 4.0
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
        omega = -self.v * (p.gain_heading * theta + p.gain_lateral * (y - p.lateral_offset))
        omega = max(-p.max_angular_speed, min(p.max_angular_speed, omega))
        return self.v, omega
