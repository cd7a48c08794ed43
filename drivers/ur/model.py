"""UR5e / UR3e model facts for the UR driver: the UR arm family of the robot descriptions
(:mod:`mmexec.drivers.descriptions.ur`, docs/robots.md section 2), re-exported here so
the driver, its fakes and tools import them as ``drivers.ur.model``.

Frames: the controller reports TCP poses in its ``base`` frame; the ROS description's
``base_link`` is ``base`` rotated by pi about z, so x and y flip sign between them. Joint
angles are the same in both. Poses are ``[x, y, z, rx, ry, rz]``: metres plus a rotation
vector [rad].
"""

from __future__ import annotations

from mmexec.drivers.descriptions.ur import (
    DH,
    JOINT_NAMES,
    MODELS,
    T_BASELINK_BASE,
    forward_kinematics,
    joint_limits,
    matrix_to_pose,
    pose_to_matrix,
    rotation_vector,
)

__all__ = [
    "DH",
    "JOINT_NAMES",
    "MODELS",
    "T_BASELINK_BASE",
    "forward_kinematics",
    "joint_limits",
    "matrix_to_pose",
    "pose_to_matrix",
    "rotation_vector",
]
