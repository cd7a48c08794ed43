"""Exceptions of the Robotiq 2F-85 driver: one base class, link errors and device faults beneath.

* :class:`RobotiqError`: base of everything this package raises.
* Link errors (:class:`RobotiqLinkError` and subclasses) are problems of the cable, port or
  socket: the port or socket cannot be opened, no answer before the deadline, corrupt
  frames, link lost. They are also
  :class:`mmexec.drivers.transport.LinkError` subclasses, so they carry ``.port``.
* Device faults (:class:`RobotiqFault` and one subclass per gFLT code) are what the gripper
  reports about itself in its FAULT STATUS byte; each knows its class (priority, minor,
  major) and its recovery rule.
* Precondition errors (:class:`RobotiqNotReady`) are raised synchronously when a call cannot
  be honoured now; their message says what to do ("call activate() first"). They are also
  :class:`mmexec.drivers.interfaces.CapabilityError`.
"""

from __future__ import annotations

from dataclasses import dataclass

from mmexec.drivers.interfaces import CapabilityError
from mmexec.drivers.transport import LinkClosed, LinkError, LinkTimeout

__all__ = [
    "FAULTS",
    "ActionDelayed",
    "ActivationFault",
    "AutoReleaseCompleted",
    "AutoReleaseInProgress",
    "EmergencyStopped",
    "FaultInfo",
    "FrameError",
    "InternalFault",
    "NoCommunication",
    "NotActivated",
    "OverTemperature",
    "Overcurrent",
    "RobotiqCorruptFrame",
    "RobotiqError",
    "RobotiqFault",
    "RobotiqLinkError",
    "RobotiqLinkLost",
    "RobotiqNotReady",
    "RobotiqPortUnavailable",
    "RobotiqTimeout",
    "UnderVoltage",
    "fault_error",
]


class RobotiqError(Exception):
    """Base class of every error raised by :mod:`mmexec.drivers.robotiq`."""


class FrameError(RobotiqError, ValueError):
    """A byte frame failed validation (CRC, slave id, function, length). Raised by the
    pure codec, which knows no port; the device re-raises it as :class:`RobotiqCorruptFrame`."""


class RobotiqLinkError(RobotiqError, LinkError):
    """The link to the gripper failed (port, cable, socket, timing), not the gripper."""


class RobotiqPortUnavailable(RobotiqLinkError):
    """The port or socket could not be opened (no such port, permission denied, busy,
    connection refused, host unreachable): nothing was said to the gripper."""


class RobotiqTimeout(RobotiqLinkError, LinkTimeout):
    """No complete answer before the deadline derived from the link."""


class RobotiqCorruptFrame(RobotiqLinkError):
    """An answer arrived but was corrupt (bad CRC, wrong slave or function, bad length)."""


class RobotiqLinkLost(RobotiqLinkError, LinkClosed):
    """The port or socket went away while open (cable pulled, power off, connection reset)."""


class RobotiqNotReady(RobotiqError, CapabilityError):
    """The gripper cannot do this now; the message says what to do first."""


class EmergencyStopped(RobotiqError):
    """The UR controller is emergency-stopped: the URCap answers ``?`` for every variable."""


@dataclass(frozen=True)
class FaultInfo:
    """One gFLT code: its name, class (priority / minor / major), meaning and recovery rule."""

    code: int
    name: str
    fault_class: str
    meaning: str
    recovery: str


class RobotiqFault(RobotiqError):
    """A fault the gripper reports in gFLT (low nibble of FAULT STATUS)."""

    info: FaultInfo

    def __init__(self, info: FaultInfo, where: str = "robotiq") -> None:
        self.info = info
        self.where = where
        super().__init__(
            f"{where}: gripper fault 0x{info.code:02X} {info.name} ({info.fault_class}): "
            f"{info.meaning}; recovery: {info.recovery}"
        )

    @property
    def code(self) -> int:
        return self.info.code

    @property
    def fault_class(self) -> str:
        return self.info.fault_class


class ActionDelayed(RobotiqFault):
    """0x05, priority: the action waits for (re)activation to finish."""


class NotActivated(RobotiqFault):
    """0x07, priority: an action was requested with rACT = 0."""


class OverTemperature(RobotiqFault):
    """0x08, minor: over-temperature (>= 85 C inside)."""


class NoCommunication(RobotiqFault):
    """0x09, minor: no communication for at least 1 s."""


class UnderVoltage(RobotiqFault):
    """0x0A, major: supply under the minimum operating voltage."""


class AutoReleaseInProgress(RobotiqFault):
    """0x0B, major: automatic release in progress."""


class InternalFault(RobotiqFault):
    """0x0C, major: internal fault."""


class ActivationFault(RobotiqFault):
    """0x0D, major: activation fault (interference during activation)."""


class Overcurrent(RobotiqFault):
    """0x0E, major: overcurrent."""


class AutoReleaseCompleted(RobotiqFault):
    """0x0F, major: automatic release completed."""


#: The gFLT codes of the 2F-85 (docs/protocols.md section 3.2), by code.
FAULTS: dict[int, tuple[FaultInfo, type[RobotiqFault]]] = {
    info.code: (info, cls)
    for info, cls in (
        (FaultInfo(0x05, "action delayed", "priority",
                   "the action waits for (re)activation to finish", "wait"), ActionDelayed),
        (FaultInfo(0x07, "not activated", "priority",
                   "action requested with rACT = 0", "call activate() first"), NotActivated),
        (FaultInfo(0x08, "over-temperature", "minor",
                   "internal temperature >= 85 C", "let it cool below 80 C"), OverTemperature),
        (FaultInfo(0x09, "no communication", "minor",
                   "no communication for at least 1 s",
                   "clears when traffic resumes (unconfirmed)"), NoCommunication),
        (FaultInfo(0x0A, "under-voltage", "major",
                   "supply under the minimum operating voltage",
                   "fix the supply, then call activate() (rising edge on rACT)"), UnderVoltage),
        (FaultInfo(0x0B, "automatic release in progress", "major",
                   "automatic release in progress",
                   "wait for it to finish, then call activate()"), AutoReleaseInProgress),
        (FaultInfo(0x0C, "internal fault", "major", "internal fault",
                   "call activate() (rising edge on rACT); contact Robotiq if it persists"),
         InternalFault),
        (FaultInfo(0x0D, "activation fault", "major",
                   "interference during activation",
                   "clear the fingers' path, then call activate() (rising edge on rACT)"),
         ActivationFault),
        (FaultInfo(0x0E, "overcurrent", "major", "motor overcurrent",
                   "call activate() (rising edge on rACT)"), Overcurrent),
        (FaultInfo(0x0F, "automatic release completed", "major",
                   "automatic release completed", "call activate() (rising edge on rACT)"),
         AutoReleaseCompleted),
    )
}


def fault_error(code: int, where: str = "robotiq") -> RobotiqFault:
    """The named exception for gFLT ``code`` (non-zero); unknown codes get a generic one."""
    entry = FAULTS.get(code)
    if entry is None:
        info = FaultInfo(code, "unknown fault", "unknown", f"undocumented gFLT 0x{code:02X}",
                         "call activate(); contact Robotiq if it persists")
        return RobotiqFault(info, where)
    info, cls = entry
    return cls(info, where)
