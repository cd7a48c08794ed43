"""The Gripper capability on a Robotiq 2F-85 (Modbus RTU or URCap socket).

:class:`RobotiqGripper` adapts a :class:`~mmexec.drivers.robotiq.core.RobotiqDevice` to
:class:`mmexec.drivers.interfaces.Gripper`: widths [m], speeds [m/s] and forces [N] in,
goals and :class:`~mmexec.drivers.interfaces.GripperState` out. The grasp state follows
gOBJ: 1 -> ``CONTACT_OPENING``, 2 -> ``CONTACT_CLOSING``, 3 -> ``AT_POSITION``, 0 ->
``MOVING``, and ``DROPPED`` when an object that was held is lost during the same command.
SI figures are the commonly quoted ones (see :mod:`mmexec.drivers.robotiq.codec`).
"""

from __future__ import annotations

import math

from mmexec.drivers.interfaces import Goal, Gripper, GripperState
from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.core import RobotiqDevice

__all__ = ["RobotiqGripper"]


class RobotiqGripper(Gripper):
    """Gripper capability over a Robotiq device (already constructed; opened by the caller
    or by :meth:`setup`)."""

    min_width = 0.0
    max_width = codec.STROKE

    def __init__(self, device: RobotiqDevice) -> None:
        self.device = device
        self.max_force = device.settings.max_force

    def setup(self, *, activate: bool = True) -> Goal | None:
        """Open the device (blocking: setup only) and start activation when asked; returns
        the activation goal (poll it) or None."""
        self.device.open()
        return self.device.activate() if activate else None

    def activate(self, *, force_reset: bool = False) -> Goal:
        """Activation goal (see :meth:`RobotiqDevice.activate`)."""
        return self.device.activate(force_reset=force_reset)

    def state(self) -> GripperState:
        return self.device.state()

    def move(self, width: float, *, speed: float = 0.1, force: float = 50.0) -> Goal:
        """Go to ``width`` [m] at ``speed`` [m/s] with grip ``force`` [N].

        Out-of-range values are clamped to the gripper's ranges (0..0.085 m, 0.02..0.15
        m/s, 20 N..``max_force``); a non-finite or negative value raises ValueError.
        """
        for name, v in (("width", width), ("speed", speed), ("force", force)):
            if not math.isfinite(v) or v < 0:
                raise ValueError(f"{self.device.where}: {name}={v} must be finite and >= 0")
        force = min(force, self.max_force)
        return self.device.move_raw(codec.width_to_position(width), codec.speed_to_raw(speed),
                                    codec.force_to_raw(force))

    def stop(self) -> None:
        """Stop the fingers where they are; running moves end CANCELLED."""
        self.device.stop()

    def disconnect(self) -> None:
        """Release the link (:meth:`RobotiqDevice.close`; ``close()`` is the Gripper's
        close-the-fingers move)."""
        self.device.close()
