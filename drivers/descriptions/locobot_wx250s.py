"""LoCoBot WX250s (Kobuki version): Kobuki base, plate, WX250s arm with its gripper, camera
tower with a pan/tilt RealSense D435, RPLIDAR A2 tower (docs/robots.md section 1).

Frame names follow the Interbotix description. Lengths m, angles rad, masses kg.
"""

from __future__ import annotations

import math

from mmexec.drivers.descriptions import wx250s
from mmexec.drivers.descriptions.description import RobotDescription
from mmexec.drivers.descriptions.linktree import (
    DARK,
    GREY,
    LIGHT,
    X_AXIS,
    Y_AXIS,
    Z_AXIS,
    Geom,
    LinkTree,
)
from mmexec.drivers.descriptions.model_info import ModelInfo

__all__ = ["DESCRIPTION", "INFO", "MOUNT", "urdf_tree"]

PI = math.pi

#: ``T_base_armbase`` of the LoCoBot: arm_base_link in base_footprint (docs/robots.md 1.2)
MOUNT = (0.097277, 0.0, 0.10795)


def _limits(name: str) -> dict[str, float]:
    """URDF limits of a WX250s / LoCoBot head joint from the arm's joint table, so the sim
    and the real arm enforce the same ones."""
    lim = next(j for j in (*wx250s.ARM_LIMITS, *wx250s.PAN_TILT_LIMITS) if j.name == name)
    return {"lower": lim.lower, "upper": lim.upper, "velocity": lim.velocity, "effort": lim.effort}


def _kobuki(m: LinkTree) -> None:
    """Kobuki base: ``base_footprint`` on the floor, ``base_link`` 0.0102 above it."""
    m.link("base_footprint", (), mass=0.01)
    m.link("base_link", (
        Geom("cylinder", (0.178, 0.10938), (0.0, 0.0, 0.05949), rgba=DARK),
        Geom("sphere", (0.017,), (0.115, 0.0, 0.007), rgba=DARK, collide=False),
        Geom("sphere", (0.017,), (-0.135, 0.0, 0.007), rgba=DARK, collide=False),
    ), mass=2.4, com=(0.0, 0.0, 0.05949))
    m.joint("base_joint", "fixed", "base_footprint", "base_link", (0.0, 0.0, 0.0102))
    for side, y in (("left", 0.115), ("right", -0.115)):
        m.link(f"wheel_{side}_link", (Geom("cylinder", (0.035, 0.0206), rgba=DARK, collide=False),), mass=0.01)
        m.joint(f"wheel_{side}_joint", "continuous", "base_link", f"wheel_{side}_link",
                (0.0, y, 0.025), (-PI / 2, 0.0, 0.0), Z_AXIS, velocity=20.0, effort=5.0)


def urdf_tree() -> LinkTree:
    """The LoCoBot's link tree: base, plate, WX250s arm with gripper, camera tower with
    pan/tilt D435, RPLIDAR tower."""
    m = LinkTree("locobot_wx250s")
    _kobuki(m)
    m.link("plate_link", (Geom("cylinder", (0.16, 0.006), rgba=GREY, collide=False),), mass=0.3)
    m.joint("plate_joint", "fixed", "base_link", "plate_link", (0.0, 0.0, 0.08825))
    m.link("arm_base_link", (Geom("box", (0.08, 0.08, 0.05), (0.0, 0.0, 0.03), rgba=DARK),), mass=0.4)
    m.joint("arm_base_joint", "fixed", "plate_link", "arm_base_link", (0.097277, 0.0, 0.0095))
    # WX250s arm, LoCoBot variant (waist origin 0.066175)
    m.link("shoulder_link", (Geom("cylinder", (0.035, 0.03), (0.0, 0.0, 0.02), rgba=DARK),), mass=0.48)
    m.joint("waist", "revolute", "arm_base_link", "shoulder_link", (0.0, 0.0, 0.066175), axis=Z_AXIS,
            **_limits("waist"))
    m.link("upper_arm_link", (
        Geom("box", (0.035, 0.04, 0.25), (0.025, 0.0, 0.125), rgba=DARK),
    ), mass=0.43, com=(0.025, 0.0, 0.125))
    m.joint("shoulder", "revolute", "shoulder_link", "upper_arm_link", (0.0, 0.0, 0.03865), axis=Y_AXIS,
            **_limits("shoulder"))
    m.link("upper_forearm_link", (
        Geom("box", (0.175, 0.035, 0.035), (0.0875, 0.0, 0.0), rgba=DARK),
    ), mass=0.23, com=(0.0875, 0.0, 0.0))
    m.joint("elbow", "revolute", "upper_arm_link", "upper_forearm_link", (0.04975, 0.0, 0.25), axis=Y_AXIS,
            **_limits("elbow"))
    m.link("lower_forearm_link", (
        Geom("box", (0.075, 0.03, 0.03), (0.0375, 0.0, 0.0), rgba=DARK),
    ), mass=0.23, com=(0.0375, 0.0, 0.0))
    m.joint("forearm_roll", "revolute", "upper_forearm_link", "lower_forearm_link", (0.175, 0.0, 0.0),
            axis=X_AXIS, **_limits("forearm_roll"))
    m.link("wrist_link", (Geom("box", (0.05, 0.03, 0.03), (0.03, 0.0, 0.0), rgba=DARK),), mass=0.08,
           com=(0.03, 0.0, 0.0))
    m.joint("wrist_angle", "revolute", "lower_forearm_link", "wrist_link", (0.075, 0.0, 0.0), axis=Y_AXIS,
            **_limits("wrist_angle"))
    m.link("gripper_link", (Geom("box", (0.04, 0.06, 0.03), (0.02, 0.0, 0.0), rgba=DARK),), mass=0.1,
           com=(0.02, 0.0, 0.0))
    m.joint("wrist_rotate", "revolute", "wrist_link", "gripper_link", (0.065, 0.0, 0.0), axis=X_AXIS,
            **_limits("wrist_rotate"))
    m.link("ee_arm_link", (), mass=0.01)
    m.joint("ee_arm", "fixed", "gripper_link", "ee_arm_link", (0.043, 0.0, 0.0))
    m.link("gripper_bar_link", (Geom("box", (0.01, 0.09, 0.02), (0.015, 0.0, 0.0), rgba=GREY),), mass=0.03)
    m.joint("gripper_bar", "fixed", "ee_arm_link", "gripper_bar_link")
    m.link("fingers_link", (), mass=0.01)
    m.joint("ee_bar", "fixed", "gripper_bar_link", "fingers_link", (0.023, 0.0, 0.0))
    # fingers: joint value = distance of the pad's inner face from the centre plane
    for side, sgn in (("left", 1.0), ("right", -1.0)):
        m.link(f"{side}_finger_link", (
            Geom("box", (0.045, 0.008, 0.022), (0.0225, sgn * 0.004, 0.0), rgba=LIGHT),
        ), mass=0.016, com=(0.0225, sgn * 0.004, 0.0))
        lo, hi = (wx250s.FINGER_MIN, wx250s.FINGER_MAX) if sgn > 0 else (-wx250s.FINGER_MAX, -wx250s.FINGER_MIN)
        m.joint(f"{side}_finger", "prismatic", "fingers_link", f"{side}_finger_link", axis=Y_AXIS,
                lower=lo, upper=hi, velocity=1.0, effort=5.0)
    m.link("ee_gripper_link", (), mass=0.01)
    m.joint("ee_gripper", "fixed", "fingers_link", "ee_gripper_link", (0.027575, 0.0, 0.0))
    # camera tower, pan/tilt head, D435 stand-in
    m.link("camera_tower_link", (
        Geom("box", (0.04, 0.04, 0.444), (0.0, 0.0, 0.222), rgba=GREY),
    ), mass=0.5, com=(0.0, 0.0, 0.222))
    m.joint("camera_tower", "fixed", "base_link", "camera_tower_link", (-0.023997, -0.000044, 0.08823))
    m.link("pan_link", (Geom("box", (0.03, 0.04, 0.02), (0.0, 0.0, 0.005), rgba=DARK),), mass=0.05)
    m.joint("pan", "revolute", "camera_tower_link", "pan_link", (0.047228, 0.0, 0.44425), axis=Z_AXIS,
            **_limits("pan"))
    m.link("tilt_link", (Geom("box", (0.02, 0.03, 0.02), rgba=DARK, collide=False),), mass=0.05)
    m.joint("tilt", "revolute", "pan_link", "tilt_link", (0.025034, 0.0, 0.019), axis=Y_AXIS,
            **_limits("tilt"))
    m.link("camera_link", (Geom("box", (0.025, 0.09, 0.025), rgba=(0.1, 0.1, 0.1, 1.0)),), mass=0.07)
    m.joint("camera", "fixed", "tilt_link", "camera_link", (0.05318, 0.0175, 0.000009))
    m.link("camera_depth_link", (), mass=0.001)
    m.joint("camera_depth", "fixed", "camera_link", "camera_depth_link", rpy=(-PI / 2, 0.0, -PI / 2))
    # RPLIDAR A2 tower: the scan frame is yawed pi
    m.link("lidar_tower_link", (Geom("cylinder", (0.01, 0.094), (0.0, 0.0, 0.047), rgba=GREY, collide=False),),
           mass=0.05)
    m.joint("lidar_tower", "fixed", "camera_tower_link", "lidar_tower_link", (-0.074, 0.0, 0.44425))
    m.link("laser_frame_link", (Geom("cylinder", (0.03785, 0.0408), (0.0, 0.0, -0.0091), rgba=DARK),),
           mass=0.19)
    m.joint("laser_frame", "fixed", "lidar_tower_link", "laser_frame_link", (0.0, 0.0, 0.09425), (0.0, 0.0, PI))
    return m


INFO = ModelInfo(
    name="locobot_wx250s",
    urdf="locobot_wx250s.urdf",
    root_link="base_footprint",
    arm_joints=tuple(lim.name for lim in wx250s.ARM_LIMITS),
    arm_base_link="arm_base_link",
    tool_link="ee_gripper_link",
    gripper_joints=("left_finger", "right_finger"),
    finger_links=("left_finger_link", "right_finger_link"),
    gripper_width_range=(2 * wx250s.FINGER_MIN, 2 * wx250s.FINGER_MAX),
    gripper_mode="interbotix",
    gripper_speed=0.1,
    gripper_force=5.0 * 2,
    camera_link="camera_link",
    camera_optical_link="camera_depth_link",
    pan_tilt_joints=tuple(lim.name for lim in wx250s.PAN_TILT_LIMITS),
    lidar_link="laser_frame_link",
    bump_links=("base_link",),
    wheel_radius=0.035,
    wheel_separation=0.230,
    footprint_radius=0.178,
    max_linear=0.7,
    max_angular=math.pi,
    camera_hfov=0.994837,
    camera_size=(640, 480),
    sleep_pose=(0.0, -1.1, 1.55, 0.0, 0.5, 0.0),
)

DESCRIPTION = RobotDescription(
    name="locobot_wx250s",
    info=INFO,
    arm=wx250s.arm_chain(locobot=True),
    arm_mount=MOUNT,
    gripper_links=("gripper_link", "ee_arm_link", "gripper_bar_link", "fingers_link", "ee_gripper_link"),
    urdf_tree=urdf_tree,
)
