"""Thin byte transports shared by the serial drivers: open, close, write, read with a deadline.

No protocol knowledge lives here. Every read takes an explicit deadline (seconds of
``time.monotonic()``, the robot's clock for link timing) and raises :class:`LinkTimeout`
when it passes; nothing waits forever. Link problems are :class:`LinkError` subclasses,
kept apart from faults a device reports about itself (each driver defines those).
"""

from __future__ import annotations

import errno
import logging
import os
import termios
import time
from dataclasses import dataclass
from typing import Self

import serial

__all__ = [
    "LinkClosed",
    "LinkError",
    "LinkTimeout",
    "PortBusy",
    "PortNotFound",
    "PortPermission",
    "SerialSettings",
    "SerialTransport",
]

log = logging.getLogger(__name__)

#: what pyserial raises when the device vanishes: its own exception, plain OS errors,
#: and termios.error from reconfiguring a port whose tty is gone.
_PORT_ERRORS = (OSError, serial.SerialException, termios.error)


class LinkError(IOError):
    """The link to a device failed (port, cable, timing), not the device itself."""

    def __init__(self, port: str, message: str) -> None:
        super().__init__(f"{port}: {message}")
        self.port = port
        self.detail = message


class PortNotFound(LinkError):
    """The port does not exist (unplugged, wrong path)."""


class PortPermission(LinkError):
    """The port exists but this user may not open it (add yourself to 'dialout')."""


class PortBusy(LinkError):
    """Another process holds the port."""


class LinkTimeout(LinkError):
    """No (complete) answer before the deadline."""


class LinkClosed(LinkError):
    """The port went away while open (cable pulled, device powered off) or was closed."""


@dataclass(frozen=True)
class SerialSettings:
    """Serial line settings: 8N1 by default, no flow control."""

    port: str
    baudrate: int = 115200
    bytesize: int = 8
    parity: str = "N"
    stopbits: int = 1

    def byte_time(self) -> float:
        """Seconds on the wire per byte (start + data + parity + stop bits)."""
        bits = 1 + self.bytesize + (0 if self.parity == "N" else 1) + self.stopbits
        return bits / self.baudrate


class SerialTransport:
    """A serial port through pyserial. Construction does no I/O; call :meth:`open`."""

    def __init__(self, settings: SerialSettings) -> None:
        self.settings = settings
        self._ser: serial.Serial | None = None

    @property
    def port(self) -> str:
        return self.settings.port

    @property
    def is_open(self) -> bool:
        return self._ser is not None and self._ser.is_open

    def open(self) -> None:
        """Open the port; raises PortNotFound / PortPermission / PortBusy / LinkError."""
        if self.is_open:
            return
        s = self.settings
        try:
            self._ser = serial.Serial(
                port=s.port,
                baudrate=s.baudrate,
                bytesize=s.bytesize,
                parity=s.parity,
                stopbits=s.stopbits,
                timeout=0,
                write_timeout=1.0,
                exclusive=True,
            )
        except serial.SerialException as e:
            self._ser = None
            raise _classify_open_error(s.port, e) from e
        log.debug("opened %s at %d baud", s.port, s.baudrate)

    def close(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except _PORT_ERRORS as e:
                log.warning("%s: error while closing: %s", self.port, e)

    def _require(self) -> serial.Serial:
        if self._ser is None or not self._ser.is_open:
            raise LinkClosed(self.port, "port is not open (call open() first)")
        return self._ser

    def write(self, data: bytes) -> None:
        ser = self._require()
        try:
            ser.write(data)
        except _PORT_ERRORS as e:
            raise LinkClosed(self.port, f"write failed: {e}") from e

    def read_available(self, max_bytes: int = 4096) -> bytes:
        """Whatever bytes are waiting now (possibly b""); never blocks."""
        ser = self._require()
        try:
            n = ser.in_waiting
            return ser.read(min(n, max_bytes)) if n else b""
        except _PORT_ERRORS as e:
            raise LinkClosed(self.port, f"read failed: {e}") from e

    def read(self, n: int, deadline: float) -> bytes:
        """Exactly ``n`` bytes, or LinkTimeout at ``deadline`` (time.monotonic())."""
        ser = self._require()
        buf = bytearray()
        while len(buf) < n:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise LinkTimeout(self.port, f"no answer within the deadline ({len(buf)} of {n} bytes)")
            try:
                ser.timeout = min(remaining, 0.05)
                chunk = ser.read(n - len(buf))
            except _PORT_ERRORS as e:
                raise LinkClosed(self.port, f"read failed: {e}") from e
            buf += chunk
        try:
            ser.timeout = 0
        except _PORT_ERRORS as e:
            raise LinkClosed(self.port, f"read failed: {e}") from e
        return bytes(buf)

    def wait_readable(self, timeout: float) -> bytes:
        """Block up to ``timeout`` s for at least one byte; returns what arrived (maybe b"").

        For driver I/O threads only (never on the tick thread).
        """
        ser = self._require()
        try:
            ser.timeout = max(timeout, 0.0)
            first = ser.read(1)
            ser.timeout = 0
            if not first:
                return b""
            rest = ser.read(ser.in_waiting or 0)
            return first + rest
        except _PORT_ERRORS as e:
            raise LinkClosed(self.port, f"read failed: {e}") from e

    def reset_input(self) -> None:
        ser = self._require()
        try:
            ser.reset_input_buffer()
        except _PORT_ERRORS as e:
            raise LinkClosed(self.port, f"flush failed: {e}") from e

    def set_dtr(self, active: bool) -> bool:
        """Drive the DTR modem line (some adapters wire it to a device input, e.g. the
        RPLIDAR A2's motor enable). Returns False when the port has no modem lines (a
        pseudo-terminal answers ENOTTY); raises LinkClosed when the port failed."""
        ser = self._require()
        try:
            ser.dtr = active
        except _PORT_ERRORS as e:  # SerialException is an OSError too, without an errno
            if isinstance(e, OSError) and e.errno in (errno.ENOTTY, errno.EINVAL):
                return False
            raise LinkClosed(self.port, f"setting DTR failed: {e}") from e
        return True

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _classify_open_error(port: str, e: serial.SerialException) -> LinkError:
    code = getattr(e, "errno", None)
    text = str(e)
    if code == errno.ENOENT or (not os.path.exists(port) and "://" not in port):
        return PortNotFound(port, "no such port (is the device plugged in?)")
    if code == errno.EACCES or "Permission denied" in text:
        return PortPermission(port, "permission denied (add your user to the 'dialout' group)")
    if code == errno.EBUSY or "busy" in text.lower() or "lock" in text.lower():
        return PortBusy(port, "port is busy (another process has it open)")
    return LinkError(port, f"cannot open: {text}")
