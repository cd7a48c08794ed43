"""The :class:`~mmexec.drivers.interfaces.Arm` and :class:`~mmexec.drivers.interfaces.Gripper`
capabilities on a wx250s.

Thin adapters: everything real (bring-up, streaming, limits, faults, the gripper's PWM and
Bus Watchdog) happens in :class:`~mmexec.drivers.dynamixel.wx250s.WX250s` and its I/O
thread, so every call here returns at once. The device builds one of each
(:attr:`WX250s.arm <mmexec.drivers.dynamixel.wx250s.WX250s.arm>`,
:attr:`WX250s.gripper <mmexec.drivers.dynamixel.wx250s.WX250s.gripper>`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mmexec.drivers.dynamixel.model import FINGER_MAX, FINGER_MIN, LOCOBOT_MOUNT
from mmexec.drivers.interfaces import (
    Arm,
    Goal,
    Gripper,
    GripperState,
    JointLimit,
    JointState,
    JointTrajectory,
)

if TYPE_CHECKING:
    from mmexec.drivers.dynamixel.wx250s import WX250s

__all__ = ["WX250sArm", "WX250sGripper"]


class WX250sArm(Arm):
    """:class:`~mmexec.drivers.interfaces.Arm` over a :class:`WX250s` device."""

    def __init__(self, device: WX250s) -> None:
        self._dev = device

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self._dev.joints)

    @property
    def limits(self) -> tuple[JointLimit, ...]:
        return tuple(j.limit() for j in self._dev.joints)

    @property
    def mount(self) -> np.ndarray:
        """``T_base_armbase``: LoCoBot arm_base_link in base_link, identity for a bare arm."""
        T = np.eye(4)
        if self._dev.config.locobot:
            T[:3, 3] = LOCOBOT_MOUNT
        return T

    def state(self) -> JointState:
        return self._dev.joint_state()

    def follow(self, trajectory: JointTrajectory) -> Goal:
        return self._dev.follow(trajectory)

    def stop(self) -> None:
        self._dev.stop()


class WX250sGripper(Gripper):
    """:class:`~mmexec.drivers.interfaces.Gripper` over the wx250s gripper servo (PWM mode).

    ``speed`` cannot be set in PWM mode (the fingers move at the speed the PWM gives);
    ``force`` [N] maps linearly onto PWM between ``gripper_pwm_min`` and ``gripper_pwm_max``
    (at ``gripper_max_force``), which is also the squeeze kept on a grasped object.
    """

    min_width = 2 * FINGER_MIN
    max_width = 2 * FINGER_MAX

    def __init__(self, device: WX250s) -> None:
        self._dev = device
        self.max_force = device.config.gripper_max_force

    def state(self) -> GripperState:
        return self._dev.gripper_state()

    def move(self, width: float, *, speed: float = 0.1, force: float = 50.0) -> Goal:
        if speed <= 0:
            return Goal.failed("gripper", f"speed must be > 0 m/s, got {speed}")
        return self._dev.gripper_move(width, force)
