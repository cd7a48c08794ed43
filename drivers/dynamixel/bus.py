"""A half-duplex DYNAMIXEL Protocol 2.0 bus: one transaction at a time, link-derived deadlines.

:class:`DxlBus` composes :mod:`.codec` with a byte transport
(:class:`mmexec.drivers.transport.SerialTransport` subclass :class:`DxlSerialTransport`).
Every transaction holds the bus lock from the moment the instruction is written until the
last expected status packet arrived or its deadline passed, so the host never transmits
while a servo may still be answering. The reply deadline mirrors DynamixelSDK::

    deadline = byte_time * (bytes out + bytes expected back) + 2 * latency + 2 ms

where ``latency`` [s] is the USB adapter's latency (1 ms for an FTDI U2D2 with the
Interbotix udev rule) plus the servos' Return Delay Time. Link problems ("no reply",
"corrupt reply", "truncated reply", port lost) are :class:`DxlLinkError` subclasses; a
status packet reporting an error is :class:`ServoError`; both derive from
:class:`DynamixelError`. Nothing is retried here; callers decide.
"""

from __future__ import annotations

import logging
import math
import os
import select
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Self

from mmexec.drivers.dynamixel import codec
from mmexec.drivers.dynamixel.codec import BROADCAST_ID, BadFrame, Status, StatusResult
from mmexec.drivers.dynamixel.control_table import (
    MODELS,
    baud_rate_problem,
    common_register,
    decode_hardware_error,
)
from mmexec.drivers.transport import LinkClosed, LinkError, SerialSettings, SerialTransport

__all__ = [
    "BusConfig",
    "CorruptReply",
    "DxlBus",
    "DxlLinkError",
    "DxlSerialTransport",
    "DynamixelError",
    "HardwareFault",
    "LinkLost",
    "NoReply",
    "NotConnected",
    "PingInfo",
    "PortUnavailable",
    "ServoError",
    "TruncatedReply",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- errors


class DynamixelError(Exception):
    """Base of every error raised by the DYNAMIXEL driver package."""


class NotConnected(DynamixelError):
    """A call needs an open bus / a connected device (the message says which call to make)."""


class DxlLinkError(DynamixelError):
    """The link failed (port, cable, no or garbled answer), as opposed to a servo fault."""

    def __init__(self, port: str, message: str, dxl_id: int | None = None) -> None:
        super().__init__(f"{port}: {message}")
        self.port = port
        self.id = dxl_id
        self.detail = message


class PortUnavailable(DxlLinkError):
    """The port could not be opened (missing, permission, busy); ``cause`` says which."""

    def __init__(self, cause: LinkError) -> None:
        super().__init__(cause.port, cause.detail)
        self.cause = cause


class LinkLost(DxlLinkError):
    """The port went away while open (cable pulled, adapter unplugged)."""


class NoReply(DxlLinkError):
    """No byte of the expected status packet arrived before the deadline."""


class CorruptReply(DxlLinkError):
    """A status packet arrived with a CRC that does not match."""


class TruncatedReply(CorruptReply):
    """Part of a status packet arrived, the rest did not before the deadline."""


class ServoError(DynamixelError):
    """A servo answered with a non-zero result code in its status packet."""

    def __init__(self, port: str, dxl_id: int, result: StatusResult, what: str) -> None:
        super().__init__(f"servo id {dxl_id} on {port}: {what}: {result.text}")
        self.port = port
        self.id = dxl_id
        self.result = result


class HardwareFault(DynamixelError):
    """A servo reports a hardware error (alert bit; Hardware Error Status names the cause)."""

    def __init__(self, port: str, dxl_id: int, faults: Sequence[str], joint: str = "") -> None:
        who = f"servo id {dxl_id}" + (f" ({joint})" if joint else "")
        names = ", ".join(faults) or "unknown"
        super().__init__(
            f"{who} on {port}: hardware fault: {names} (torque is off; reboot the servo)"
        )
        self.port = port
        self.id = dxl_id
        self.faults = tuple(faults)
        self.joint = joint


# --------------------------------------------------------------------------- transport


class DxlSerialTransport(SerialTransport):
    """:class:`SerialTransport` with a select()-based :meth:`wait_readable`.

    The base class sets pyserial's timeout per call, which reprograms the termios settings
    twice per wait; a 100 Hz bus loop waits several times per cycle, so this subclass waits
    on the file descriptor instead (same semantics, no reconfiguration).
    """

    def wait_readable(self, timeout: float) -> bytes:
        ser = self._require()
        try:
            fd = ser.fileno()
            ready, _, _ = select.select([fd], [], [], max(timeout, 0.0))
            if not ready:
                return b""
            data = os.read(fd, 4096)
        except (OSError, ValueError) as e:
            raise LinkClosed(self.port, f"read failed: {e}") from e
        if not data:
            raise LinkClosed(self.port, "read failed: end of file (device gone)")
        return data

    def discard_input(self) -> int:
        """Drop whatever is waiting (late replies); returns how many bytes were dropped."""
        ser = self._require()
        dropped = 0
        try:
            fd = ser.fileno()
            while select.select([fd], [], [], 0.0)[0]:
                chunk = os.read(fd, 4096)
                if not chunk:
                    raise LinkClosed(self.port, "read failed: end of file (device gone)")
                dropped += len(chunk)
        except (OSError, ValueError) as e:
            raise LinkClosed(self.port, f"read failed: {e}") from e
        return dropped


# --------------------------------------------------------------------------- bus


@dataclass(frozen=True)
class BusConfig:
    """Bus settings: ``port`` path, ``baudrate`` [bit/s, one of the DYNAMIXEL rates 9600 ..
    4.5M], ``latency`` [s] of the adapter (USB latency timer plus Return Delay Time); reply
    deadlines derive from these. ValueError names a bad value."""

    port: str
    baudrate: int = 1_000_000
    latency: float = 0.001

    def __post_init__(self) -> None:
        problem = baud_rate_problem(self.baudrate)
        if problem:
            raise ValueError(f"baudrate: {problem}")
        if not (math.isfinite(self.latency) and self.latency >= 0):
            raise ValueError(f"latency must be a finite number >= 0 s, got {self.latency}")


@dataclass(frozen=True)
class PingInfo:
    """What a servo reports to Ping: ``model`` number and ``firmware`` version; ``alert``:
    the hardware alert bit was set in its status (read Hardware Error Status for why)."""

    id: int
    model: int
    firmware: int
    alert: bool = False


@dataclass
class BusStats:
    """Counters for diagnostics: packets out, statuses in, timeouts, corrupt frames, bytes dropped."""

    tx_packets: int = 0
    rx_status: int = 0
    timeouts: int = 0
    corrupt: int = 0
    dropped_bytes: int = 0
    extra: dict[str, int] = field(default_factory=dict)


#: Hardware Error Status: one address in every known model, so it is read without asking
#: which model a servo is
_HARDWARE_ERROR_STATUS = common_register(MODELS.values(), "hardware_error_status")


class DxlBus:
    """One DYNAMIXEL bus. Construction does no I/O: call :meth:`open` (or use ``with``).

    All methods are thread-safe (one transaction at a time under a real lock) and bounded
    by the link-derived deadline; they are meant for a driver's I/O thread or for bring-up
    tools, never for a behaviour-tree tick.
    """

    def __init__(self, config: BusConfig, transport: DxlSerialTransport | None = None) -> None:
        self.config = config
        settings = SerialSettings(config.port, baudrate=config.baudrate)
        self._link = transport if transport is not None else DxlSerialTransport(settings)
        self._byte_time = settings.byte_time()
        self._lock = threading.Lock()
        self._parser = codec.PacketParser()
        self.stats = BusStats()

    @property
    def port(self) -> str:
        return self.config.port

    @property
    def is_open(self) -> bool:
        return self._link.is_open

    def open(self) -> None:
        """Open the port; raises :class:`PortUnavailable` naming the port and the reason."""
        try:
            self._link.open()
        except LinkError as e:
            raise PortUnavailable(e) from e

    def close(self) -> None:
        with self._lock:
            self._link.close()

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def reply_timeout(self, tx_len: int, rx_len: int) -> float:
        """Seconds to wait for ``rx_len`` bytes after writing ``tx_len`` bytes."""
        return self._byte_time * (tx_len + rx_len) + 2.0 * self.config.latency + 0.002

    # -- core transaction
    def transact(
        self, packet: bytes, expected: Sequence[tuple[int, int]] = ()
    ) -> dict[int, Status]:
        """Write ``packet``; collect one status per ``(id, data_length)`` in ``expected``.

        Returns ``{id: Status}``. Raises :class:`NoReply`, :class:`CorruptReply` or
        :class:`TruncatedReply` naming the first id that did not answer properly (its
        ``received`` attribute holds the statuses that did arrive), :class:`LinkLost` when the
        port fails. Result codes in the statuses are *not* checked here.
        """
        port = self.config.port
        with self._lock:
            link = self._link
            if not link.is_open:
                raise NotConnected(f"{port}: bus is not open (call open() first)")
            parser = self._parser
            try:
                stale = link.discard_input()
                if stale:
                    self.stats.dropped_bytes += stale
                    log.debug("%s: dropped %d stale bytes before transmitting", port, stale)
                parser.clear()
                link.write(packet)
                self.stats.tx_packets += 1
                if not expected:
                    return {}
                want = {i: n for i, n in expected}
                rx_len = sum(11 + n for _, n in expected)
                deadline = time.monotonic() + self.reply_timeout(len(packet), rx_len)
                got: dict[int, Status] = {}
                corrupt_ids: list[int] = []
                while True:
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        break
                    data = link.wait_readable(remaining)
                    if not data:
                        continue
                    for item in parser.feed(data):
                        if isinstance(item, BadFrame):
                            self.stats.corrupt += 1
                            corrupt_ids.append(item.id)
                            continue
                        if not item.is_status or item.id not in want or item.id in got:
                            self.stats.extra["unexpected"] = (
                                self.stats.extra.get("unexpected", 0) + 1
                            )
                            continue
                        if not item.params:
                            corrupt_ids.append(item.id)
                            continue
                        got[item.id] = Status(item.id, item.params[0], item.params[1:])
                        self.stats.rx_status += 1
                    if len(got) == len(want):
                        return got
            except LinkError as e:
                raise LinkLost(port, f"link lost: {e.detail}") from e
            missing = [i for i, _ in expected if i not in got]
            first = missing[0]
            err: DxlLinkError
            if corrupt_ids:
                bad = corrupt_ids[0]
                err = CorruptReply(port, f"corrupt reply (CRC mismatch) from servo id {bad}", bad)
            elif parser.pending:
                err = TruncatedReply(
                    port,
                    f"truncated reply from servo id {first} ({parser.pending} bytes, then silence)",
                    first,
                )
            else:
                self.stats.timeouts += 1
                ms = self.reply_timeout(len(packet), rx_len) * 1e3
                err = NoReply(port, f"no reply from servo id {first} within {ms:.1f} ms", first)
            err.received = got  # type: ignore[attr-defined]
            raise err

    def _one(self, packet: bytes, dxl_id: int, data_len: int, what: str) -> Status | None:
        if dxl_id == BROADCAST_ID:
            self.transact(packet)
            return None
        st = self.transact(packet, ((dxl_id, data_len),))[dxl_id]
        if not st.ok:
            raise ServoError(self.config.port, dxl_id, st.result, what)
        return st

    # -- instructions
    def ping(self, dxl_id: int) -> PingInfo:
        """Ping one servo (not broadcast); returns its model number and firmware version."""
        if dxl_id == BROADCAST_ID:
            raise ValueError("use broadcast_ping() for the broadcast id")
        st = self.transact(codec.ping(dxl_id), ((dxl_id, 3),))[dxl_id]
        if not st.ok:
            raise ServoError(self.config.port, dxl_id, st.result, "ping")
        if len(st.data) < 3:
            raise CorruptReply(
                self.config.port, f"ping reply from servo id {dxl_id} too short", dxl_id
            )
        return PingInfo(dxl_id, st.data[0] | (st.data[1] << 8), st.data[2], st.alert)

    def broadcast_ping(self, max_ids: int = 253) -> list[PingInfo]:
        """Broadcast ping: collect every answer until the deadline for ``max_ids`` replies."""
        pkt = codec.ping(BROADCAST_ID)
        found: list[PingInfo] = []
        with self._lock:
            link = self._link
            if not link.is_open:
                raise NotConnected(f"{self.config.port}: bus is not open (call open() first)")
            try:
                link.discard_input()
                self._parser.clear()
                link.write(pkt)
                deadline = time.monotonic() + self.reply_timeout(len(pkt), 14 * max_ids)
                while (remaining := deadline - time.monotonic()) > 0:
                    for item in self._parser.feed(link.wait_readable(remaining)):
                        if (
                            isinstance(item, codec.Packet)
                            and item.is_status
                            and len(item.params) >= 4
                        ):
                            p = item.params
                            alert = bool(p[0] & codec.ALERT_BIT)
                            found.append(PingInfo(item.id, p[1] | (p[2] << 8), p[3], alert))
            except LinkError as e:
                raise LinkLost(self.config.port, f"link lost: {e.detail}") from e
        return sorted(found, key=lambda p: p.id)

    def read(self, dxl_id: int, address: int, length: int) -> bytes:
        """Read ``length`` bytes at ``address``; :class:`ServoError` on an error result."""
        st = self._one(
            codec.read(dxl_id, address, length), dxl_id, length, f"read {length} bytes at {address}"
        )
        if st is None:
            raise ValueError("a Read to the broadcast id gets no reply")
        if len(st.data) != length:
            raise CorruptReply(
                self.config.port,
                f"servo id {dxl_id} returned {len(st.data)} of {length} bytes",
                dxl_id,
            )
        return st.data

    def read_status(self, dxl_id: int, address: int, length: int) -> Status:
        """Like :meth:`read` but returns the whole status (error byte included, unchecked)."""
        return self.transact(codec.read(dxl_id, address, length), ((dxl_id, length),))[dxl_id]

    def write(self, dxl_id: int, address: int, data: bytes, *, expect_reply: bool = True) -> None:
        """Write ``data`` at ``address``; waits for the (empty) status unless broadcast or
        ``expect_reply`` is False (Status Return Level below 2)."""
        pkt = codec.write(dxl_id, address, data)
        if not expect_reply:
            self.transact(pkt)
            return
        self._one(pkt, dxl_id, 0, f"write {len(data)} bytes at {address}")

    def reg_write(self, dxl_id: int, address: int, data: bytes) -> None:
        self._one(codec.reg_write(dxl_id, address, data), dxl_id, 0, f"reg write at {address}")

    def action(self, dxl_id: int = BROADCAST_ID) -> None:
        self._one(codec.action(dxl_id), dxl_id, 0, "action")

    def reboot(self, dxl_id: int) -> None:
        """Reboot a servo (clears a hardware error; torque comes back off)."""
        self._one(codec.reboot(dxl_id), dxl_id, 0, "reboot")

    def factory_reset(self, dxl_id: int, option: int = 0x02) -> None:
        self._one(codec.factory_reset(dxl_id, option), dxl_id, 0, "factory reset")

    def clear_multi_turn(self, dxl_id: int) -> None:
        self._one(codec.clear_multi_turn(dxl_id), dxl_id, 0, "clear")

    def sync_write(
        self, address: int, length: int, data: Mapping[int, bytes] | Iterable[tuple[int, bytes]]
    ) -> None:
        """Sync Write (no reply)."""
        self.transact(codec.sync_write(address, length, data))

    def sync_read(self, address: int, length: int, ids: Sequence[int]) -> dict[int, Status]:
        """Sync Read ``length`` bytes at ``address`` from ``ids``; statuses unchecked."""
        return self.transact(codec.sync_read(address, length, ids), [(i, length) for i in ids])

    def bulk_write(self, items: Sequence[tuple[int, int, bytes]]) -> None:
        self.transact(codec.bulk_write(items))

    def bulk_read(self, items: Sequence[tuple[int, int, int]]) -> dict[int, Status]:
        return self.transact(codec.bulk_read(items), [(i, n) for i, _, n in items])

    def hardware_error(self, dxl_id: int) -> tuple[str, ...]:
        """Named faults in a servo's Hardware Error Status (address 70 in every model)."""
        reg = _HARDWARE_ERROR_STATUS
        return decode_hardware_error(codec.int_from_le(self.read(dxl_id, reg.address, reg.size)))
