"""The :class:`~mmexec.drivers.interfaces.Base` capability on a Kobuki.

A thin adapter: everything real (limits, ramps, watchdog, bumper stops, odometry)
happens in :class:`~mmexec.drivers.kobuki.device.KobukiDevice`'s I/O thread, so
every call here returns at once.
"""

from __future__ import annotations

import logging

from mmexec.drivers.interfaces import Base, BaseState, CapabilityError, Pose2D
from mmexec.drivers.kobuki.device import KobukiDevice, LinkState

__all__ = ["KobukiBase"]

log = logging.getLogger(__name__)


class KobukiBase(Base):
    """Differential-drive base capability backed by a :class:`KobukiDevice`.

    Limits come from the device's config (at most 0.7 m/s, pi rad/s). A velocity is
    held for ``command_timeout`` seconds; while a fault is active (bumper, cliff, wheel
    drop, overcurrent, ``link_lost``, ``driver_error``, unsupported firmware)
    :meth:`set_velocity` drives nothing and :meth:`state` names the fault in ``faults``:
    skills check it there. Without a link :meth:`state` reports v = w = 0 (nothing is
    measured; the driver is sending stop frames), so a brake loop does not wait on a
    stale speed.
    """

    radius = 0.178  # m, Kobuki body radius

    def __init__(self, device: KobukiDevice, *, footprint_radius: float | None = None) -> None:
        """``footprint_radius`` [m]: radius of the circle around the base centre that covers
        everything the base carries (a larger platform on a Kobuki-protocol base); navigation
        inflates the map by it. Default: the Kobuki body's 0.178 m; never less than that."""
        if footprint_radius is not None:
            if footprint_radius < KobukiBase.radius:
                raise ValueError(f"footprint_radius {footprint_radius} m is less than the Kobuki body's "
                                 f"{KobukiBase.radius} m")
            self.radius = float(footprint_radius)
        self.device = device
        cfg = device.config
        self.max_linear = cfg.max_linear
        self.max_angular = cfg.max_angular
        self.max_linear_accel = cfg.linear_accel
        self.max_angular_accel = cfg.angular_accel
        self.command_timeout = cfg.command_timeout

    def state(self) -> BaseState:
        """Odometry pose in ``map`` (from the pose given to :meth:`reset_pose`), measured
        v [m/s] and w [rad/s], clock stamp of the last feedback frame, faults."""
        return self.device.base_state()

    def set_velocity(self, v: float, w: float) -> None:
        """Command ``v`` [m/s], ``w`` [rad/s] (clamped, ramped, held ``command_timeout`` s).

        Raises :class:`CapabilityError` only when the driver was never connected or was
        closed (a programming error); faults are reported through :meth:`state`.
        """
        if self.device.link_state is LinkState.CLOSED:
            raise CapabilityError(f"kobuki on {self.device.port}: not connected (call connect() first)")
        self.device.set_velocity(v, w)

    def stop(self) -> None:
        """Zero velocity at once (no ramp)."""
        self.device.stop()

    def reset_pose(self, pose: Pose2D) -> None:
        """Declare the base to be at ``pose`` in ``map``; odometry continues from there."""
        self.device.reset_odometry(pose)

    def close(self) -> None:
        """Stop the base and release the port."""
        self.device.close()
