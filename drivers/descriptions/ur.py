"""UR e-Series arm facts (docs/robots.md section 2): joint names, limits, DH kinematics, frames.

The arm family shared by the robots built on a UR arm (:mod:`.ur_platform`:
:mod:`.ur5e_robotiq`, :mod:`.ur3e_robotiq`) and by the UR driver (:mod:`mmexec.drivers.ur`,
which re-exports this module as its ``model``). :func:`add_arm` writes a model's links and
joints into a robot's link tree (the ROS description's frames, primitive collision shapes).

Frames: the controller reports TCP poses in its ``base`` frame; the ROS description's
``base_link`` is ``base`` rotated by pi about z, so x and y flip sign between them. Joint
angles are the same in both. Poses are ``[x, y, z, rx, ry, rz]``: metres plus a rotation
vector [rad].
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.descriptions.chain import ArmChain, dh_to_poe, dh_transform
from mmexec.drivers.descriptions.linktree import BLUE, GREY, LIGHT, Geom, LinkTree, Vec3
from mmexec.drivers.interfaces import JointLimit

__all__ = [
    "DH",
    "JOINT_NAMES",
    "LINKS",
    "MODELS",
    "T_BASELINK_BASE",
    "LinkShapes",
    "add_arm",
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



@dataclass(frozen=True)
class LinkShapes:
    """One UR model's links for a link tree: masses [kg] of ``base_link`` and links 1-6
    (docs/robots.md 2.1; the base mass is the ROS description's), the ROS description's
    ``shoulder_offset`` and ``elbow_offset`` [m] (where the upper arm and forearm tubes
    run, off the DH plane), and primitive collision cylinders (radius, length) [m]:
    ``base``, ``shoulder`` (centred ``shoulder_z`` below the shoulder frame), the tube radii
    of the upper arm and forearm, the wrist 1/2 joint housings (``wrist``) and
    ``wrist_3``. The cylinders are approximations of the arm's outline (sim assumption,
    docs/sim.md), not vendor geometry."""

    masses: tuple[float, float, float, float, float, float, float]
    shoulder_offset: float
    elbow_offset: float
    base: tuple[float, float]
    shoulder: tuple[float, float]
    shoulder_z: float
    upper_arm_radius: float
    forearm_radius: float
    wrist: tuple[float, float]
    wrist_3: tuple[float, float]


#: per model: its links (masses and offsets from the ROS description's physical
#: parameters; collision cylinders sized to the arm's outline)
LINKS: dict[str, LinkShapes] = {
    "ur5e": LinkShapes(masses=(4.0, 3.761, 8.058, 2.846, 1.37, 1.3, 0.365), shoulder_offset=0.138,
                       elbow_offset=0.007, base=(0.075, 0.03), shoulder=(0.06, 0.12), shoulder_z=-0.02,
                       upper_arm_radius=0.054, forearm_radius=0.04, wrist=(0.038, 0.09), wrist_3=(0.038, 0.03)),
    "ur3e": LinkShapes(masses=(2.0, 1.98, 3.4445, 1.437, 0.871, 0.805, 0.261), shoulder_offset=0.120,
                       elbow_offset=0.027, base=(0.064, 0.03), shoulder=(0.045, 0.10), shoulder_z=-0.02,
                       upper_arm_radius=0.045, forearm_radius=0.035, wrist=(0.032, 0.08), wrist_3=(0.032, 0.025)),
}

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


def add_arm(m: LinkTree, model: str, parent: str, mount: Vec3) -> None:
    """Add the UR ``model`` to the link tree ``m``: ``base_link`` fixed at ``mount`` [m] in
    ``parent`` (joint ``arm_mount``), the six joints with the ROS description's origins,
    which carry the official DH offsets (d1, a2, a3, d4, d5, d6; docs/robots.md 2.3), and
    :func:`joint_limits`, then ``flange`` and ``tool0`` (z out of the flange). A joint
    without a position limit (the UR3e's wrist 3) is ``continuous``."""
    (d1, _, _), (_, a2, _), (_, a3, _), (d4, _, _), (d5, _, _), (d6, _, _) = DH[model]
    shp = LINKS[model]
    mb, m1, m2, m3, m4, m5, m6 = shp.masses
    lim = {j.name: {"kind": "revolute" if math.isfinite(j.lower) else "continuous", "lower": j.lower,
                    "upper": j.upper, "velocity": j.velocity, "effort": j.effort}
           for j in joint_limits(model)}
    m.link("base_link", (Geom("cylinder", shp.base, (0.0, 0.0, shp.base[1] / 2), rgba=LIGHT),), mass=mb)
    m.joint("arm_mount", "fixed", parent, "base_link", mount)
    m.link("base_link_inertia", (), mass=0.01)
    m.joint("base_link-base_link_inertia", "fixed", "base_link", "base_link_inertia", rpy=(0.0, 0.0, math.pi))
    m.link("shoulder_link", (Geom("cylinder", shp.shoulder, (0.0, 0.0, shp.shoulder_z), rgba=BLUE),), mass=m1)
    m.joint("shoulder_pan_joint", parent="base_link_inertia", child="shoulder_link", xyz=(0.0, 0.0, d1),
            **lim["shoulder_pan_joint"])
    upper = (a2 / 2, 0.0, shp.shoulder_offset)
    m.link("upper_arm_link", (
        Geom("cylinder", (shp.upper_arm_radius, -a2), upper, (0.0, math.pi / 2, 0.0), rgba=LIGHT),
    ), mass=m2, com=upper)
    m.joint("shoulder_lift_joint", parent="shoulder_link", child="upper_arm_link", rpy=(math.pi / 2, 0.0, 0.0),
            **lim["shoulder_lift_joint"])
    fore = (a3 / 2, 0.0, shp.elbow_offset)
    m.link("forearm_link", (
        Geom("cylinder", (shp.forearm_radius, -a3), fore, (0.0, math.pi / 2, 0.0), rgba=LIGHT),
    ), mass=m3, com=fore)
    m.joint("elbow_joint", parent="upper_arm_link", child="forearm_link", xyz=(a2, 0.0, 0.0), **lim["elbow_joint"])
    m.link("wrist_1_link", (Geom("cylinder", shp.wrist, (0.0, 0.0, 0.0), rgba=BLUE),), mass=m4)
    m.joint("wrist_1_joint", parent="forearm_link", child="wrist_1_link", xyz=(a3, 0.0, d4), **lim["wrist_1_joint"])
    m.link("wrist_2_link", (Geom("cylinder", shp.wrist, (0.0, 0.0, 0.0), rgba=BLUE),), mass=m5)
    m.joint("wrist_2_joint", parent="wrist_1_link", child="wrist_2_link", xyz=(0.0, -d5, 0.0),
            rpy=(math.pi / 2, 0.0, 0.0), **lim["wrist_2_joint"])
    m.link("wrist_3_link", (Geom("cylinder", shp.wrist_3, (0.0, 0.0, -shp.wrist_3[1] / 2), rgba=GREY),), mass=m6)
    m.joint("wrist_3_joint", parent="wrist_2_link", child="wrist_3_link", xyz=(0.0, d6, 0.0),
            rpy=(math.pi / 2, math.pi, math.pi), **lim["wrist_3_joint"])
    m.link("flange", (), mass=0.001)
    m.joint("wrist_3-flange", "fixed", "wrist_3_link", "flange", rpy=(0.0, -math.pi / 2, -math.pi / 2))
    m.link("tool0", (), mass=0.001)
    m.joint("flange-tool0", "fixed", "flange", "tool0", rpy=(math.pi / 2, 0.0, math.pi / 2))


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
