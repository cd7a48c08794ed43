"""WX250s model facts (docs/robots.md 1.2-1.3, docs/protocols.md 2.5), data only, no I/O.

The one place for the arm's servo ids and models (XM430-W350 1020, XL430-W250 1060, the
LoCoBot's 2XL430-W250 pan/tilt 1090, as the ROBOTIS e-Manual tables give them), register
limits [pulses], URDF joint limits [rad], efforts [N m], drive directions and shadow servos;
the LoCoBot arm mount; and the gripper's horn/arm linkage (servo angle [rad] <-> finger gap
[m]). The driver (:mod:`mmexec.drivers.dynamixel.wx250s`) and the planning kinematics
(:mod:`mmexec.skills.manipulation.kinematics`) both read them from here; the fake bus
(:mod:`mmexec.drivers.fakes.dynamixel`) takes its servo table (ids, models, limits) from the
vendor tables instead, so a wrong fact here shows up as a failed bring-up in the tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mmexec.drivers.dynamixel.control_table import TWO_XL430_W250, XL430_W250, XM430_W350, Model
from mmexec.drivers.interfaces import JointLimit

__all__ = [
    "ARM_JOINTS",
    "ARM_LENGTH",
    "FINGER_MAX",
    "FINGER_MIN",
    "GRIPPER",
    "HORN_RADIUS",
    "LOCOBOT_MOUNT",
    "PAN_TILT",
    "JointSpec",
    "finger_offset",
    "gripper_angle_for_width",
    "gripper_width",
]

# --------------------------------------------------------------------------- arm description


@dataclass(frozen=True)
class JointSpec:
    """One joint: servo ``id``, model, optional ``shadow`` id, drive direction, register
    limits [pulses], URDF limits [rad], velocity [rad/s] and effort [N m]."""

    name: str
    id: int
    model: Model
    min_pulses: int
    max_pulses: int
    lower: float
    upper: float
    velocity: float = math.pi
    effort: float = math.inf
    reversed: bool = False
    shadow: int | None = None

    def limit(self) -> JointLimit:
        return JointLimit(self.name, self.lower, self.upper, self.velocity, effort=self.effort)


_PI = math.pi - 1e-5
ARM_JOINTS: tuple[JointSpec, ...] = (
    JointSpec("waist", 1, XM430_W350, 0, 4095, -_PI, _PI, effort=10.0),
    JointSpec("shoulder", 2, XM430_W350, 819, 3345, -1.88496, 1.98968, effort=20.0, shadow=3),
    JointSpec("elbow", 4, XM430_W350, 648, 3094, -2.14675, 1.60570, effort=15.0, shadow=5),
    JointSpec("forearm_roll", 6, XM430_W350, 0, 4095, -_PI, _PI, effort=2.0),
    JointSpec(
        "wrist_angle", 7, XM430_W350, 910, 3447, -1.74533, 2.14675, effort=5.0, reversed=True
    ),
    JointSpec("wrist_rotate", 8, XL430_W250, 0, 4095, -_PI, _PI, effort=1.0),
)
GRIPPER = JointSpec("gripper", 9, XL430_W250, 0, 4095, -math.pi, math.pi, effort=1.0)
#: the LoCoBot head: one 2XL430-W250 (model 1090 on both ids, not the XL430-W250's 1060)
PAN_TILT: tuple[JointSpec, ...] = (
    JointSpec("pan", 10, TWO_XL430_W250, 1024, 3072, -math.pi / 2, math.pi / 2, effort=2.0),
    JointSpec(
        "tilt", 11, TWO_XL430_W250, 1024, 3072, -math.pi / 2, 1.309, effort=2.0, reversed=True
    ),
)
#: ``T_base_armbase`` of the LoCoBot: arm_base_link in base_link (docs/robots.md 1.2)
LOCOBOT_MOUNT = (0.097277, 0.0, 0.10795)

# --------------------------------------------------------------------------- gripper geometry

HORN_RADIUS = 0.014  # m
ARM_LENGTH = 0.024  # m
FINGER_MIN = 0.015  # m, one finger's travel from the centre
FINGER_MAX = 0.037  # m


def finger_offset(angle: float) -> float:
    """One finger's distance from the gripper centre [m] for servo ``angle`` [rad]."""
    rs = HORN_RADIUS * math.sin(angle)
    return rs + math.sqrt(ARM_LENGTH**2 - (HORN_RADIUS**2 - rs**2))


def gripper_width(angle: float) -> float:
    """Gap between the two finger pads [m] (fingers mirrored) for servo ``angle`` [rad]."""
    return 2.0 * finger_offset(angle)


def gripper_angle_for_width(width: float) -> float:
    """Servo angle [rad] giving ``width`` [m] (inverse of :func:`gripper_width` on
    [-pi/2, pi/2], where it is monotonic); raises ValueError outside its range."""
    lo, hi = -math.pi / 2, math.pi / 2
    if not gripper_width(lo) <= width <= gripper_width(hi):
        raise ValueError(
            f"gripper width {width:.4f} m outside {gripper_width(lo):.4f}..{gripper_width(hi):.4f}"
        )
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if gripper_width(mid) < width:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
