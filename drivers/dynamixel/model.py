"""WX250s servo facts (docs/robots.md 1.2-1.3, docs/protocols.md 2.5), data only, no I/O.

The one place for the arm's servo ids and models (XM430-W350 1020, XL430-W250 1060, the
LoCoBot's 2XL430-W250 pan/tilt 1090, as the ROBOTIS e-Manual tables give them), register
limits [pulses], drive directions and shadow servos. The kinematic facts these servos
drive (URDF joint limits [rad], velocities [rad/s], efforts [N m], the gripper's
horn/arm linkage, the LoCoBot arm mount) live in the robot descriptions
(:mod:`mmexec.drivers.descriptions.wx250s`, :mod:`mmexec.drivers.descriptions.locobot_wx250s`)
and are combined with the servo data here and re-exported, so the driver
(:mod:`mmexec.drivers.dynamixel.wx250s`), the simulator and the planners read the same
numbers. The fake bus (:mod:`mmexec.drivers.fakes.dynamixel`) takes its servo table (ids,
models, limits) from the vendor tables instead, so a wrong fact here shows up as a failed
bring-up in the tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mmexec.drivers.descriptions.locobot_wx250s import MOUNT as LOCOBOT_MOUNT
from mmexec.drivers.descriptions.wx250s import (
    ARM_LENGTH,
    ARM_LIMITS,
    FINGER_MAX,
    FINGER_MIN,
    GRIPPER_LIMIT,
    HORN_RADIUS,
    PAN_TILT_LIMITS,
    finger_offset,
    gripper_angle_for_width,
    gripper_width,
)
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
    limits [pulses], and the description's URDF limits [rad], velocity [rad/s] and
    effort [N m] (build with :meth:`of`)."""

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
        """The joint's :class:`JointLimit` (acceleration unbounded)."""
        return JointLimit(self.name, self.lower, self.upper, self.velocity, effort=self.effort)

    @classmethod
    def of(cls, limit: JointLimit, id: int, model: Model, min_pulses: int, max_pulses: int, *,
           reversed: bool = False, shadow: int | None = None) -> JointSpec:
        """The joint of the description's ``limit`` (name, URDF limits [rad], velocity
        [rad/s], effort [N m]) driven by servo ``id`` of ``model``."""
        return cls(limit.name, id, model, min_pulses, max_pulses, limit.lower, limit.upper,
                   limit.velocity, limit.effort, reversed, shadow)


_LIMIT = {lim.name: lim for lim in (*ARM_LIMITS, GRIPPER_LIMIT, *PAN_TILT_LIMITS)}
ARM_JOINTS: tuple[JointSpec, ...] = (
    JointSpec.of(_LIMIT["waist"], 1, XM430_W350, 0, 4095),
    JointSpec.of(_LIMIT["shoulder"], 2, XM430_W350, 819, 3345, shadow=3),
    JointSpec.of(_LIMIT["elbow"], 4, XM430_W350, 648, 3094, shadow=5),
    JointSpec.of(_LIMIT["forearm_roll"], 6, XM430_W350, 0, 4095),
    JointSpec.of(_LIMIT["wrist_angle"], 7, XM430_W350, 910, 3447, reversed=True),
    JointSpec.of(_LIMIT["wrist_rotate"], 8, XL430_W250, 0, 4095),
)
GRIPPER = JointSpec.of(GRIPPER_LIMIT, 9, XL430_W250, 0, 4095)
#: the LoCoBot head: one 2XL430-W250 (model 1090 on both ids, not the XL430-W250's 1060)
PAN_TILT: tuple[JointSpec, ...] = (
    JointSpec.of(_LIMIT["pan"], 10, TWO_XL430_W250, 1024, 3072),
    JointSpec.of(_LIMIT["tilt"], 11, TWO_XL430_W250, 1024, 3072, reversed=True),
)
