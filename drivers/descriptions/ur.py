"""UR e-Series arm facts (docs/robots.md section 2): joint names, limits, DH kinematics, frames.

The arm family shared by the robots built on a UR arm (:mod:`.ur5e_robotiq`) and by the
UR driver (:mod:`mmexec.drivers.ur`, which re-exports this module as its ``model``).

Frames: the controller reports TCP poses in its ``base`` frame; the ROS description's
``base_link`` is ``base`` rotated by pi about z, so x and y flip sign between them. Joint
angles are the same in both. Poses are ``[x, y, z, rx, ry, rz]``: metres plus a rotation
vector [rad].
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from mmexec.drivers.descriptions.chain import ArmChain, dh_to_poe, dh_transform
from mmexec.drivers.interfaces import JointLimit

__all__ = [
    "DH",
    "JOINT_NAMES",
    "MODELS",
    "T_BASELINK_BASE",
    "arm_chain",
    "forward_kinematics",
    "joint_limits",
    "matrix_to_pose",
    "pose_to_matrix",
    "rotation_vector",
]

JOINT_NAMES: tuple[str, ...] = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)

MODELS = ("ur5e", "ur3e")

#: Standard DH per model: (d, a, alpha) per joint [m, m, rad] (docs/robots.md 2.1).
DH: dict[str, tuple[tuple[float, float, float], ...]] = {
    "ur5e": (
        (0.1625, 0.0, math.pi / 2),
        (0.0, -0.425, 0.0),
        (0.0, -0.3922, 0.0),
        (0.1333, 0.0, math.pi / 2),
        (0.0997, 0.0, -math.pi / 2),
        (0.0996, 0.0, 0.0),
    ),
    "ur3e": (
        (0.15185, 0.0, math.pi / 2),
        (0.0, -0.24355, 0.0),
        (0.0, -0.2132, 0.0),
        (0.13105, 0.0, math.pi / 2),
        (0.08535, 0.0, -math.pi / 2),
        (0.0921, 0.0, 0.0),
    ),
}

_TWO_PI = 2.0 * math.pi
#: per model and joint: max torque [N m], max speed [rad/s] (docs/robots.md 2.2)
_EFFORT = {"ur5e": (150.0, 150.0, 150.0, 28.0, 28.0, 28.0), "ur3e": (54.0, 54.0, 28.0, 9.0, 9.0, 9.0)}
_SPEED = {"ur5e": (math.pi,) * 6, "ur3e": (math.pi, math.pi, math.pi, _TWO_PI, _TWO_PI, _TWO_PI)}
#: joints without a position limit in the ROS description, per model
_CONTINUOUS: dict[str, frozenset[str]] = {"ur5e": frozenset(), "ur3e": frozenset({"wrist_3_joint"})}

#: ``T_base_link_base``: the controller's ``base`` frame in ROS ``base_link`` (pi about z).
T_BASELINK_BASE = np.array(
    [[-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


def joint_limits(model: str, acceleration: float = math.inf) -> tuple[JointLimit, ...]:
    """Limits from docs/robots.md 2.2: positions [rad] (ROS description: ±2π, elbow ±π, UR3e
    wrist 3 continuous), max speeds [rad/s], torques [N m]; ``acceleration`` [rad/s^2] is
    not published by UR and comes from the config."""
    if model not in MODELS:
        raise ValueError(f"unknown UR model {model!r} (known: {', '.join(MODELS)})")
    out = []
    for i, name in enumerate(JOINT_NAMES):
        bound = math.pi if name == "elbow_joint" else _TWO_PI
        if name in _CONTINUOUS[model]:
            bound = math.inf
        out.append(JointLimit(name, -bound, bound, _SPEED[model][i], acceleration, _EFFORT[model][i]))
    return tuple(out)


def forward_kinematics(q: Sequence[float], model: str = "ur5e") -> np.ndarray:
    """``T_base_tool0`` (4x4) in the controller's ``base`` frame, joints ``q`` [rad]."""
    T = np.eye(4)
    for (d, a, alpha), theta in zip(DH[model], q):
        T = T @ dh_transform(theta, d, a, alpha)
    return T


def arm_chain(model: str, *, tcp_offset: float, acceleration: float) -> ArmChain:
    """The arm ``model`` in ROS ``base_link`` (the controller's ``base`` turned by pi about
    z) as a PoE chain: the official DH table converted; tool frame ``tool0`` (z out of the
    flange, the approach axis); ``tcp_offset`` [m] along tool z to the gripper's grasp
    point; ``acceleration`` [rad/s^2] per joint for trajectory timing (not published by
    UR). Joint limits from :func:`joint_limits`."""
    S, M = dh_to_poe(DH[model])
    Rz = T_BASELINK_BASE[:3, :3]
    S = np.vstack([Rz @ S[:3], Rz @ S[3:]])
    return ArmChain(model, JOINT_NAMES, S, T_BASELINK_BASE @ M, joint_limits(model), approach_axis=2,
                    tcp_offset=tcp_offset, acceleration=acceleration)


def pose_to_matrix(pose: Sequence[float]) -> np.ndarray:
    """``[x, y, z, rx, ry, rz]`` (m, rotation vector rad) to a 4x4 transform."""
    p = np.asarray(pose, dtype=float)
    rv = p[3:6]
    angle = float(np.linalg.norm(rv))
    R = np.eye(3)
    if angle > 1e-12:
        k = rv / angle
        K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        R = np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p[:3]
    return T


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] of a 3x3 rotation matrix."""
    cos_a = max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0))
    angle = math.acos(cos_a)
    if angle < 1e-9:
        return np.zeros(3)
    if math.pi - angle < 1e-6:
        # near pi: axis from the largest diagonal term of (R + I) / 2
        B = (R + np.eye(3)) / 2.0
        i = int(np.argmax(np.diag(B)))
        axis = B[:, i] / math.sqrt(max(B[i, i], 1e-12))
        return axis / np.linalg.norm(axis) * angle
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (2.0 * math.sin(angle))
    return w * angle


def matrix_to_pose(T: np.ndarray) -> list[float]:
    """4x4 transform to ``[x, y, z, rx, ry, rz]``."""
    return [float(x) for x in T[:3, 3]] + [float(x) for x in rotation_vector(T[:3, :3])]
