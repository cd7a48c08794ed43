"""UR5e with a Robotiq 2F-85 and a wrist RGB-D camera on a differential-drive box base
(docs/robots.md section 2).

The base is not a published product: its numbers (wheels, box body, arm mount, speeds)
are sim assumptions, also listed in docs/sim.md. Lengths m, angles rad, masses kg.
"""

from __future__ import annotations

import math

from mmexec.drivers.descriptions import robotiq_2f85, ur
from mmexec.drivers.descriptions.description import RobotDescription
from mmexec.drivers.descriptions.linktree import BLUE, DARK, GREY, LIGHT, Z_AXIS, Geom, LinkTree
from mmexec.drivers.descriptions.model_info import ModelInfo

__all__ = [
    "BASE_SIZE",
    "BASE_WHEEL_RADIUS",
    "BASE_WHEEL_SEPARATION",
    "DESCRIPTION",
    "INFO",
    "MOUNT",
    "TCP_OFFSET",
    "urdf_tree",
]

PI = math.pi

BASE_WHEEL_RADIUS = 0.08
BASE_WHEEL_SEPARATION = 0.46
BASE_SIZE = (0.62, 0.52, 0.30)  # box body, bottom 0.03 above the floor
MOUNT = (0.12, 0.0, 0.33)       # arm base_link in base_footprint
#: [m] tool0 to the 2F-85's closed-grasp point along tool z: coupling + gripper TCP
#: (robotiq_2f85.COUPLING + robotiq_2f85.TCP_Z)
TCP_OFFSET = 0.155


def urdf_tree() -> LinkTree:
    """UR5e (official DH via the ROS description's joint origins) with a Robotiq 2F-85
    (two prismatic pads) and a wrist RGB-D camera, on a differential-drive box base."""
    m = LinkTree("ur5e_robotiq")
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
    # UR5e
    m.link("base_link", (Geom("cylinder", (0.075, 0.03), (0.0, 0.0, 0.015), rgba=LIGHT),), mass=4.0)
    m.joint("arm_mount", "fixed", "mobile_base_link", "base_link", MOUNT)
    m.link("base_link_inertia", (), mass=0.01)
    m.joint("base_link-base_link_inertia", "fixed", "base_link", "base_link_inertia", rpy=(0.0, 0.0, PI))
    # joint origins of the ROS description, from the official DH (d1, a2, a3, d4, d5, d6)
    # and limits, both from the UR arm facts (mmexec.drivers.descriptions.ur)
    (d1, _, _), (_, a2, _), (_, a3, _), (d4, _, _), (d5, _, _), (d6, _, _) = ur.DH["ur5e"]
    lim = {j.name: {"lower": j.lower, "upper": j.upper, "velocity": j.velocity, "effort": j.effort}
           for j in ur.joint_limits("ur5e")}
    m.link("shoulder_link", (Geom("cylinder", (0.06, 0.12), (0.0, 0.0, -0.02), rgba=BLUE),), mass=3.761)
    m.joint("shoulder_pan_joint", "revolute", "base_link_inertia", "shoulder_link", (0.0, 0.0, d1),
            **lim["shoulder_pan_joint"])
    m.link("upper_arm_link", (
        Geom("cylinder", (0.054, -a2), (a2 / 2, 0.0, 0.138), (0.0, PI / 2, 0.0), rgba=LIGHT),
    ), mass=8.058, com=(a2 / 2, 0.0, 0.138))
    m.joint("shoulder_lift_joint", "revolute", "shoulder_link", "upper_arm_link", rpy=(PI / 2, 0.0, 0.0),
            **lim["shoulder_lift_joint"])
    m.link("forearm_link", (
        Geom("cylinder", (0.04, -a3), (a3 / 2, 0.0, 0.007), (0.0, PI / 2, 0.0), rgba=LIGHT),
    ), mass=2.846, com=(a3 / 2, 0.0, 0.007))
    m.joint("elbow_joint", "revolute", "upper_arm_link", "forearm_link", (a2, 0.0, 0.0), **lim["elbow_joint"])
    m.link("wrist_1_link", (Geom("cylinder", (0.038, 0.09), (0.0, 0.0, 0.0), rgba=BLUE),), mass=1.37)
    m.joint("wrist_1_joint", "revolute", "forearm_link", "wrist_1_link", (a3, 0.0, d4), **lim["wrist_1_joint"])
    m.link("wrist_2_link", (Geom("cylinder", (0.038, 0.09), (0.0, 0.0, 0.0), rgba=BLUE),), mass=1.3)
    m.joint("wrist_2_joint", "revolute", "wrist_1_link", "wrist_2_link", (0.0, -d5, 0.0),
            (PI / 2, 0.0, 0.0), **lim["wrist_2_joint"])
    m.link("wrist_3_link", (Geom("cylinder", (0.038, 0.03), (0.0, 0.0, -0.015), rgba=GREY),), mass=0.365)
    m.joint("wrist_3_joint", "revolute", "wrist_2_link", "wrist_3_link", (0.0, d6, 0.0),
            (PI / 2, PI, PI), **lim["wrist_3_joint"])
    m.link("flange", (), mass=0.001)
    m.joint("wrist_3-flange", "fixed", "wrist_3_link", "flange", rpy=(0.0, -PI / 2, -PI / 2))
    m.link("tool0", (), mass=0.001)
    m.joint("flange-tool0", "fixed", "flange", "tool0", rpy=(PI / 2, 0.0, PI / 2))
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


INFO = ModelInfo(
    name="ur5e_robotiq",
    urdf="ur5e_robotiq.urdf",
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
    sleep_pose=(0.0, -1.9, 2.3, -1.97, -1.5708, 0.0),
)

DESCRIPTION = RobotDescription(
    name="ur5e_robotiq",
    info=INFO,
    arm=ur.arm_chain("ur5e", tcp_offset=TCP_OFFSET, acceleration=3.0),
    arm_mount=MOUNT,
    gripper_links=("robotiq_base_link", "robotiq_tcp", "flange", "tool0"),
    urdf_tree=urdf_tree,
)
