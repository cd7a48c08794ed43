"""The camera package's exception."""

from __future__ import annotations

from mmexec.drivers.interfaces import CapabilityError

__all__ = ["CameraError"]


class CameraError(CapabilityError):
    """A camera cannot be opened or used; the message names the device and what to do."""
