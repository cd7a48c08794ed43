"""Robotiq 2F-85 over Modbus RTU (RS-485, Robotiq's USB adapter): codec + serial transport.

:class:`RobotiqModbus` writes the three command registers with FC16 at 0x03E8 and polls
the three status registers at 0x07D0 (FC04 by default, FC03 for the 2016 firmware
edition) from its I/O thread (:class:`~mmexec.drivers.robotiq.core.RobotiqDevice`).

Link timing: 115200 8N1, slave 9; every reply has a deadline of (request + reply bytes) x
byte time + ``latency`` (USB adapter and gripper turnaround); requests are at least
``min_gap`` (5 ms) apart, the gripper's register update period. The gripper sends no
exception frames and ignores corrupt requests, so a bad request shows up as a timeout.
"""

from __future__ import annotations

import logging
import termios
import threading
import time
from dataclasses import dataclass

from mmexec.drivers.interfaces import Clock
from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.codec import Command, Status
from mmexec.drivers.robotiq.core import DeviceSettings, RobotiqDevice
from mmexec.drivers.robotiq.errors import (
    FrameError,
    RobotiqCorruptFrame,
    RobotiqLinkError,
    RobotiqLinkLost,
    RobotiqPortUnavailable,
    RobotiqTimeout,
)
from mmexec.drivers.transport import (
    LinkClosed,
    LinkError,
    LinkTimeout,
    SerialSettings,
    SerialTransport,
)

__all__ = ["ModbusSettings", "RobotiqModbus"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ModbusSettings:
    """Serial link of a directly wired gripper.

    ``port`` e.g. ``/dev/ttyUSB0``; ``baudrate`` 115200; ``slave`` 9; ``read_function`` 4
    (later manual edition) or 3 (2016 edition); ``latency`` [s] allowance on top of the
    bytes' wire time for each reply; ``min_gap`` [s] between requests.
    """

    port: str
    baudrate: int = 115200
    slave: int = codec.DEFAULT_SLAVE
    read_function: int = codec.FC_READ_INPUT
    latency: float = 0.05
    min_gap: float = 0.005

    def __post_init__(self) -> None:
        if self.read_function not in (codec.FC_READ_HOLDING, codec.FC_READ_INPUT):
            raise ValueError(f"read_function must be 3 or 4, got {self.read_function}")
        if not 1 <= self.slave <= 247:
            raise ValueError(f"slave id {self.slave} outside 1..247")
        if not self.latency > 0 or self.min_gap < 0:
            raise ValueError("latency must be > 0 s and min_gap >= 0 s")


class RobotiqModbus(RobotiqDevice):
    """A 2F-85 on a serial port. Construction does no I/O: call :meth:`open`.

    >>> dev = RobotiqModbus(ModbusSettings("/dev/ttyUSB0"))   # doctest: +SKIP
    >>> dev.open(); goal = dev.activate()                       # doctest: +SKIP
    """

    def __init__(self, link: ModbusSettings, settings: DeviceSettings | None = None,
                 clock: Clock | None = None) -> None:
        super().__init__(settings, clock)
        self.link = link
        self._transport = SerialTransport(SerialSettings(link.port, link.baudrate))
        self._xfer_lock = threading.Lock()
        self._last_io = 0.0

    @property
    def where(self) -> str:
        return f"robotiq {self.link.port}"

    def _connect(self) -> None:
        try:
            self._transport.open()
        except LinkError as e:
            raise RobotiqPortUnavailable(self.link.port, f"robotiq: {e.detail}") from e

    def _disconnect(self) -> None:
        self._transport.close()

    def reply_deadline(self, request_len: int, reply_len: int) -> float:
        """Seconds to wait for a reply: wire time of both frames plus the latency."""
        return (request_len + reply_len) * self._transport.settings.byte_time() \
            + self.link.latency

    def exchange(self, request: bytes, reply_len: int) -> bytes:
        """Send ``request`` and return the raw reply of ``reply_len`` bytes.

        Spaces requests by ``min_gap``, discards stale input first, and raises
        :class:`RobotiqTimeout` (no or partial answer before the deadline) or
        :class:`RobotiqLinkLost` (port gone). Used by the I/O thread and by :meth:`open`.
        """
        port = self.link.port
        with self._xfer_lock:
            gap = self._last_io + self.link.min_gap - time.monotonic()
            if gap > 0:
                self._stop_evt.wait(gap)
            budget = self.reply_deadline(len(request), reply_len)
            try:
                self._transport.reset_input()
                self._transport.write(request)
                return self._transport.read(reply_len, time.monotonic() + budget)
            except LinkTimeout as e:
                raise RobotiqTimeout(port, f"robotiq: no answer within the deadline "
                                           f"({budget * 1000:.0f} ms; {e.detail})") from e
            except LinkClosed as e:
                raise RobotiqLinkLost(port, f"robotiq: link lost ({e.detail})") from e
            except LinkError as e:
                raise RobotiqLinkError(port, f"robotiq: {e.detail}") from e
            except (OSError, termios.error) as e:
                # once the device is gone pyserial can also fail outside SerialTransport's
                # translation: tcflush raises termios.error, setting the read timeout raises
                # SerialException "Could not configure port"
                raise RobotiqLinkLost(port, f"robotiq: link lost ({e})") from e
            finally:
                self._last_io = time.monotonic()

    def _corrupt(self, e: FrameError) -> RobotiqCorruptFrame:
        return RobotiqCorruptFrame(self.link.port, f"robotiq: corrupt frame ({e})")

    def _write_command(self, cmd: Command) -> None:
        regs = cmd.to_registers()
        req = codec.encode_write_multiple(self.link.slave, codec.OUTPUT_BASE, regs)
        reply = self.exchange(req, 8)
        try:
            codec.decode_write_multiple_reply(reply, self.link.slave, codec.OUTPUT_BASE, 3)
        except FrameError as e:
            raise self._corrupt(e) from e
        log.debug("%s: wrote %s", self.where, cmd)

    def _read_status(self) -> Status:
        fc = self.link.read_function
        req = codec.encode_read(self.link.slave, fc, codec.INPUT_BASE, 3)
        reply = self.exchange(req, codec.read_reply_length(3))
        try:
            regs = codec.decode_read_reply(reply, self.link.slave, fc, 3)
            return Status.from_registers(regs)
        except FrameError as e:
            raise self._corrupt(e) from e
