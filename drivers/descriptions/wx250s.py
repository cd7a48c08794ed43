"""Interbotix WidowX-250 6DOF (WX250s) arm facts (docs/robots.md 1.2-1.3): joint table with
the URDF limits, the LoCoBot pan/tilt head's joints, the gripper's horn/arm linkage, and
the arm's product-of-exponentials kinematics.

Shared by the robots built on the arm (:mod:`.locobot_wx250s`) and by the Dynamixel
driver (:mod:`mmexec.drivers.dynamixel.model` adds the servo ids, servo models and
register limits to these joints). Units: rad, rad/s, N m, m.
"""

from __future__ import annotations

import math

import numpy as np

from mmexec.drivers.descriptions.chain import ArmChain
from mmexec.drivers.interfaces import JointLimit

__all__ = [
    "ARM_LENGTH",
    "ARM_LIMITS",
    "FINGER_MAX",
    "FINGER_MIN",
    "GRIPPER_LIMIT",
    "HORN_RADIUS",
    "LOCOBOT_HEIGHT_OFFSET",
    "PAN_TILT_LIMITS",
    "arm_chain",
    "finger_offset",
    "gripper_angle_for_width",
    "gripper_width",
]

_PI = math.pi - 1e-5
#: The arm joints in chain order: URDF position limits [rad], velocity [rad/s] (the
#: Interbotix description's pi for every joint) and effort [N m].
ARM_LIMITS: tuple[JointLimit, ...] = (
    JointLimit("waist", -_PI, _PI, math.pi, effort=10.0),
    JointLimit("shoulder", -1.88496, 1.98968, math.pi, effort=20.0),
    JointLimit("elbow", -2.14675, 1.60570, math.pi, effort=15.0),
    JointLimit("forearm_roll", -_PI, _PI, math.pi, effort=2.0),
    JointLimit("wrist_angle", -1.74533, 2.14675, math.pi, effort=5.0),
    JointLimit("wrist_rotate", -_PI, _PI, math.pi, effort=1.0),
)
#: The gripper servo's horn angle [rad] (the fingers follow through the linkage below).
GRIPPER_LIMIT = JointLimit("gripper", -math.pi, math.pi, math.pi, effort=1.0)
#: The LoCoBot head: pan and tilt of the camera [rad].
PAN_TILT_LIMITS: tuple[JointLimit, ...] = (
    JointLimit("pan", -math.pi / 2, math.pi / 2, math.pi, effort=2.0),
    JointLimit("tilt", -math.pi / 2, 1.309, math.pi, effort=2.0),
)

# --------------------------------------------------------------------------- gripper linkage

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


# --------------------------------------------------------------------------- kinematics

#: [m] the LoCoBot variant's arm is this much lower than the Interbotix PoE heights
LOCOBOT_HEIGHT_OFFSET = 0.005825


def arm_chain(*, locobot: bool = True, acceleration: float = 5.0) -> ArmChain:
    """The WX250s in its ``arm_base_link`` as a PoE chain: the Interbotix parameters
    (docs/robots.md 1.3), ``locobot=True`` lowering every height by
    :data:`LOCOBOT_HEIGHT_OFFSET`; tool frame ``ee_gripper_link`` (between the finger
    pads, x = approach direction out of the gripper, y = finger travel, z up at the zero
    pose), the grasp point itself. ``acceleration`` [rad/s^2] per joint for trajectory
    timing (not published by Interbotix; a conservative default)."""
    dz = LOCOBOT_HEIGHT_OFFSET if locobot else 0.0
    h1, h2 = 0.11065 - dz, 0.36065 - dz
    screws = np.array([
        [0, 0, 1, 0, 0, 0],
        [0, 1, 0, -h1, 0, 0],
        [0, 1, 0, -h2, 0, 0.04975],
        [1, 0, 0, 0, h2, 0],
        [0, 1, 0, -h2, 0, 0.29975],
        [1, 0, 0, 0, h2, 0],
    ], dtype=float).T
    M = np.eye(4)
    M[:3, 3] = (0.458325, 0.0, h2)
    return ArmChain("wx250s" + ("_locobot" if locobot else ""), tuple(lim.name for lim in ARM_LIMITS),
                    screws, M, ARM_LIMITS, approach_axis=0, tcp_offset=0.0, acceleration=acceleration)
