"""The names and constants of one robot model that the simulator, planners and skills need."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["ModelInfo"]


@dataclass(frozen=True)
class ModelInfo:
    """Names and constants of one robot model (its link tree: the description's URDF).

    Frames: ``root_link`` is the floor frame (``base_footprint``, the interface's
    ``base_link``); ``arm_base_link`` is the arm mount (``arm_base`` in the interfaces);
    ``tool_link`` the Interbotix/UR tool frame; ``camera_optical_link`` the camera's
    optical frame (z forward, x right, y down); ``lidar_link`` the scan frame.
    ``bump_links``: the base's body links, which stop the base when they touch static
    geometry (the simulated bumper).

    Gripper: ``gripper_joints`` are two prismatic joints. ``gripper_mode`` maps a pad gap
    ``width`` [m] to joint values: ``interbotix``: ``q_left = width/2``, ``q_right =
    -width/2`` (Interbotix finger semantics, 0.015 ... 0.037 per finger); ``robotiq``:
    each joint is the pad's closing travel ``q = (open - width)/2`` with ``open`` the
    largest gap (0 open ... 0.0425 closed on the 2F-85; the real ``finger_joint`` 0 ...
    0.8 rad is monotone in it, see docs/sim.md).
    """

    name: str
    urdf: str                   # file name of the generated URDF (see RobotDescription.urdf_path)
    root_link: str
    arm_joints: tuple[str, ...]
    arm_base_link: str
    tool_link: str
    gripper_joints: tuple[str, str]
    finger_links: tuple[str, str]
    gripper_width_range: tuple[float, float]  # m, pad gap closed ... open
    gripper_mode: Literal["interbotix", "robotiq"]
    gripper_speed: float        # m/s, max pad gap closing speed
    gripper_force: float        # N, max grip force
    camera_link: str
    camera_optical_link: str
    pan_tilt_joints: tuple[str, ...]
    lidar_link: str
    bump_links: tuple[str, ...]
    wheel_radius: float         # m
    wheel_separation: float     # m
    footprint_radius: float     # m, circumscribed
    max_linear: float           # m/s
    max_angular: float          # rad/s
    camera_hfov: float          # rad, default horizontal FOV
    camera_size: tuple[int, int]  # px, width x height
    sleep_pose: tuple[float, ...]  # rad, arm joints in arm_joints order

    def width_to_q(self, width: float) -> tuple[float, float]:
        """Joint values [m] of the two gripper joints for a pad gap ``width`` [m]."""
        if self.gripper_mode == "interbotix":
            return (width / 2.0, -width / 2.0)
        q = (self.gripper_width_range[1] - width) / 2.0
        return (q, q)

    def q_to_width(self, q_left: float, q_right: float) -> float:
        """Pad gap [m] from the two gripper joint values [m]."""
        if self.gripper_mode == "interbotix":
            return q_left - q_right
        return self.gripper_width_range[1] - q_left - q_right
