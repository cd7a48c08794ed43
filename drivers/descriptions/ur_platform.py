"""The UR mobile manipulator platform (docs/robots.md section 2): a UR e-Series arm with a
Robotiq 2F-85 and a wrist RGB-D camera on a differential-drive box base with a 2D lidar.

The robots built on it (:mod:`.ur5e_robotiq`, :mod:`.ur3e_robotiq`) differ in the arm
model, where the arm is mounted and the arm's rest pose; :func:`description` builds one
from those. The base is not a published product: its numbers (wheels, box body, speeds)
are sim assumptions, also listed in docs/sim.md. Lengths m, angles rad, masses kg.
"""

from __future__ import annotations

import math
from functools import partial

from mmexec.drivers.descriptions import robotiq_2f85, ur
from mmexec.drivers.descriptions.description import RobotDescription
from mmexec.drivers.descriptions.linktree import DARK, Z_AXIS, Geom, LinkTree, Vec3
from mmexec.drivers.descriptions.model_info import ModelInfo

__all__ = [
    "BASE_SIZE",
    "BASE_WHEEL_RADIUS",
    "BASE_WHEEL_SEPARATION",
    "GRIPPER_LINKS",
    "TCP_OFFSET",
    "description",
    "urdf_tree",
]

PI = math.pi

BASE_WHEEL_RADIUS = 0.08
BASE_WHEEL_SEPARATION = 0.46
BASE_SIZE = (0.62, 0.52, 0.30)  # box body, bottom 0.03 above the floor
#: [m] tool0 to the 2F-85's closed-grasp point along tool z: coupling + gripper TCP
#: (robotiq_2f85.COUPLING + robotiq_2f85.TCP_Z)
TCP_OFFSET = 0.155
#: links besides the pads and tool0 that hold or touch a grasped item
GRIPPER_LINKS = ("robotiq_base_link", "robotiq_tcp", "flange", "tool0")


def urdf_tree(name: str, arm_model: str, mount: Vec3) -> LinkTree:
    """The platform called ``name`` with the UR ``arm_model`` (:func:`ur.add_arm
    <mmexec.drivers.descriptions.ur.add_arm>`: official DH via the ROS description's
    joint origins) at ``mount`` [m] in ``mobile_base_link``, a Robotiq 2F-85 (two
    prismatic pads) and a wrist RGB-D camera."""
    m = LinkTree(name)
    bx, _by, bz = BASE_SIZE
    m.link("base_footprint", (), mass=0.01)
    m.link("mobile_base_link", (Geom("box", BASE_SIZE, (0.0, 0.0, 0.03 + bz / 2), rgba=DARK),),
           mass=30.0, com=(0.0, 0.0, 0.03 + bz / 2))
    m.joint("mobile_base_joint", "fixed", "base_footprint", "mobile_base_link")
    for side, y in (("left", BASE_WHEEL_SEPARATION / 2), ("right", -BASE_WHEEL_SEPARATION / 2)):
        m.link(f"wheel_{side}_link", (Geom("cylinder", (BASE_WHEEL_RADIUS, 0.04), rgba=DARK, collide=False),),
               mass=0.5)
        m.joint(f"wheel_{side}_joint", "continuous", "mobile_base_link", f"wheel_{side}_link",
                (0.0, y, BASE_WHEEL_RADIUS), (-PI / 2, 0.0, 0.0), Z_AXIS, velocity=20.0, effort=20.0)
    ur.add_arm(m, arm_model, "mobile_base_link", mount)
    # Robotiq 2F-85 on its coupling; prismatic pads close along +-y of the gripper frame
    robotiq_2f85.add_gripper(m, "tool0")
    # wrist RGB-D camera on the gripper's side, looking along the tool axis
    m.link("camera_link", (Geom("box", (0.025, 0.09, 0.025), rgba=(0.1, 0.1, 0.1, 1.0)),), mass=0.07)
    m.joint("camera_mount", "fixed", "tool0", "camera_link", (0.0, -0.08, 0.03), (0.0, -PI / 2, -PI / 2))
    m.link("camera_depth_link", (), mass=0.001)
    m.joint("camera_depth", "fixed", "camera_link", "camera_depth_link", rpy=(-PI / 2, 0.0, -PI / 2))
    # a 2D lidar at the front of the base, scanning in its own frame
    m.link("laser_frame_link", (Geom("cylinder", (0.03785, 0.0408), (0.0, 0.0, -0.0091), rgba=DARK),), mass=0.19)
    m.joint("laser_frame", "fixed", "mobile_base_link", "laser_frame_link", (bx / 2 - 0.05, 0.0, 0.03 + bz + 0.025))
    return m


def description(name: str, arm_model: str, mount: Vec3, *, sleep_pose: tuple[float, ...],
                acceleration: float = 3.0) -> RobotDescription:
    """The platform robot ``name`` (its URDF: ``name.urdf``) with the UR ``arm_model``
    mounted at ``mount`` [m] (``base_link`` in ``base_footprint``), resting at
    ``sleep_pose`` [rad] (the sim's start pose); ``acceleration`` [rad/s^2] per joint for
    trajectory timing when nothing else is configured (UR publishes none)."""
    info = ModelInfo(
        name=name,
        urdf=f"{name}.urdf",
        root_link="base_footprint",
        arm_joints=ur.JOINT_NAMES,
        arm_base_link="base_link",
        tool_link="tool0",
        gripper_joints=("left_pad_joint", "right_pad_joint"),
        finger_links=("left_pad_link", "right_pad_link"),
        gripper_width_range=(0.0, robotiq_2f85.STROKE),
        gripper_mode="robotiq",
        gripper_speed=robotiq_2f85.SPEED,
        gripper_force=robotiq_2f85.FORCE,
        camera_link="camera_link",
        camera_optical_link="camera_depth_link",
        pan_tilt_joints=(),
        lidar_link="laser_frame_link",
        bump_links=("mobile_base_link",),
        wheel_radius=BASE_WHEEL_RADIUS,
        wheel_separation=BASE_WHEEL_SEPARATION,
        footprint_radius=math.hypot(BASE_SIZE[0] / 2, BASE_SIZE[1] / 2),
        max_linear=0.7,
        max_angular=math.pi / 2,
        camera_hfov=1.2043,  # 69 deg: D435 colour-like wrist camera (sim assumption)
        camera_size=(640, 480),
        sleep_pose=sleep_pose,
    )
    return RobotDescription(
        name=name,
        info=info,
        arm=ur.arm_chain(arm_model, tcp_offset=TCP_OFFSET, acceleration=acceleration),
        arm_mount=mount,
        gripper_links=GRIPPER_LINKS,
        urdf_tree=partial(urdf_tree, name, arm_model, mount),
    )
