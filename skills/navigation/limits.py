"""Velocity and acceleration limits of a differential-drive base, and its dynamic window.

One frozen :class:`BaseLimits` feeds both the DWA (its dynamic window) and the CLF-CBF
filter (its velocity and acceleration bounds), so the two layers never disagree on what
the base can do. Presets for the two target platforms:

- :data:`LOCOBOT_KOBUKI`: Kobuki vendor figures (0.7 m/s, 180 deg/s, about 1.0 m/s^2;
  the angular acceleration is the Base interface's default 3.5 rad/s^2), LoCoBot
  footprint radius 0.178 m;
- :data:`UR5E_PLATFORM`: the UR5e platform as configured in ``config/ur5e.yaml`` (0.4
  m/s and 1.0 rad/s carrying the arm, 0.2 m/s^2, 1.5 rad/s^2), footprint radius 0.405 m
  (the circle around the 0.62 x 0.52 m platform).

Units: m, m/s, rad/s, m/s^2, rad/s^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mmexec.drivers.interfaces import Base
from mmexec.skills.navigation.checks import positive

__all__ = ["LOCOBOT_KOBUKI", "UR5E_PLATFORM", "BaseLimits", "reachable"]


def reachable(current: float, lo: float, hi: float, delta: float) -> tuple[float, float]:
    """The interval of values within ``[lo, hi]`` reachable from ``current`` by a change of
    at most ``delta`` (>= 0). When ``current`` lies so far outside ``[lo, hi]`` that none
    is, the single value closest to the limits (``current`` moved by ``delta`` towards
    them)."""
    a, b = max(lo, current - delta), min(hi, current + delta)
    if a <= b:
        return a, b
    v = current - delta if current > hi else current + delta
    return v, v


@dataclass(frozen=True)
class BaseLimits:
    """A differential base: footprint ``radius`` [m] (circumscribed), forward speed in
    ``[min_v, max_v]`` [m/s] (``min_v`` < 0 allows reversing), yaw rate within
    ``+-max_w`` [rad/s], accelerations ``accel_v`` [m/s^2] and ``accel_w`` [rad/s^2]."""

    radius: float = 0.178
    max_v: float = 0.7
    min_v: float = 0.0
    max_w: float = math.pi
    accel_v: float = 1.0
    accel_w: float = 3.5

    def validate(self) -> list[str]:
        errs = positive(self, "radius", "max_v", "max_w", "accel_v", "accel_w")
        if not self.min_v <= 0:
            errs.append(f"min_v: must be <= 0 m/s, got {self.min_v}")
        return errs

    @classmethod
    def from_base(cls, base: Base, min_v: float = 0.0) -> BaseLimits:
        """The limits a :class:`mmexec.drivers.interfaces.Base` declares."""
        return cls(radius=base.radius, max_v=base.max_linear, min_v=min_v, max_w=base.max_angular,
                   accel_v=base.max_linear_accel, accel_w=base.max_angular_accel)

    def window(self, v: float, w: float, dt: float, v_cap: float | None = None) -> tuple[float, float, float, float]:
        """The dynamic window ``(v_lo, v_hi, w_lo, w_hi)``: velocities reachable within
        ``dt`` [s] from ``(v, w)`` inside the limits, the forward speed also capped at
        ``v_cap`` [m/s] (e.g. near people or the goal) when given."""
        v_hi = self.max_v if v_cap is None else max(0.0, min(self.max_v, v_cap))
        v_lo, v_hi = reachable(v, self.min_v, v_hi, self.accel_v * dt)
        w_lo, w_hi = reachable(w, -self.max_w, self.max_w, self.accel_w * dt)
        return v_lo, v_hi, w_lo, w_hi

    def brake(self, v: float, w: float, dt: float) -> tuple[float, float]:
        """``(v, w)`` moved towards zero by one tick ``dt`` [s] at full deceleration."""
        dv, dw = self.accel_v * dt, self.accel_w * dt
        return math.copysign(max(0.0, abs(v) - dv), v), math.copysign(max(0.0, abs(w) - dw), w)


#: LoCoBot on a Kobuki base (vendor limits, body radius)
LOCOBOT_KOBUKI = BaseLimits(radius=0.178, max_v=0.7, max_w=math.pi, accel_v=1.0, accel_w=3.5)
#: UR5e mobile platform (config/ur5e.yaml limits, platform footprint circle)
UR5E_PLATFORM = BaseLimits(radius=0.405, max_v=0.4, max_w=1.0, accel_v=0.2, accel_w=1.5)
