"""DYNAMIXEL Protocol 2.0 framing: pure functions over bytes, no I/O.

Packet layout (docs/protocols.md section 2.2)::

    Instruction: FF FF FD 00 | ID | LEN_L LEN_H | INST | params...       | CRC_L CRC_H
    Status:      FF FF FD 00 | ID | LEN_L LEN_H | 55   | ERR | params... | CRC_L CRC_H

``LEN`` counts the bytes after itself (instruction byte, parameters, CRC) *after* byte
stuffing; the CRC-16 (poly 0x8005, init 0, no reflection) covers every stuffed byte from the
first ``FF`` to the last parameter and is sent least significant byte first. All
multi-byte values are little-endian.

The streaming :class:`PacketParser` turns arbitrary chunks of a byte stream into
:class:`Packet` objects (stuffing removed) and :class:`BadFrame` records for frames whose
CRC does not match, dropping garbage until a header. Whether a missing packet means
"no reply" or "truncated reply" is decided by the caller at its deadline from
:attr:`PacketParser.pending`.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

__all__ = [
    "BROADCAST_ID",
    "HEADER",
    "MAX_ID",
    "STATUS_INSTRUCTION",
    "BadFrame",
    "CodecError",
    "Instruction",
    "Packet",
    "PacketParser",
    "Status",
    "StatusResult",
    "action",
    "bulk_read",
    "bulk_write",
    "clear_multi_turn",
    "crc16",
    "decode_status",
    "encode_instruction",
    "encode_status",
    "factory_reset",
    "int_from_le",
    "int_to_le",
    "parse_bulk_read",
    "parse_bulk_write",
    "parse_sync_read",
    "parse_sync_write",
    "ping",
    "read",
    "reboot",
    "reg_write",
    "status_from_packet",
    "status_length",
    "stuff",
    "sync_read",
    "sync_write",
    "unstuff",
    "write",
]

HEADER = b"\xff\xff\xfd\x00"
STATUS_INSTRUCTION = 0x55
BROADCAST_ID = 0xFE
MAX_ID = 252
#: longest packet we accept from the wire (bytes after LEN); protects the parser from a
#: corrupted LEN field swallowing the stream
MAX_LEN = 1024
CLEAR_KEY = b"\x44\x58\x4c\x22"


class CodecError(ValueError):
    """An argument cannot be encoded (bad id, address, length) or a packet is malformed."""


class Instruction(enum.IntEnum):
    """Instruction codes (section 2.3)."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    BULK_READ = 0x92
    BULK_WRITE = 0x93


class StatusResult(enum.IntEnum):
    """Result code in bits 0-6 of a status packet's error byte."""

    OK = 0
    RESULT_FAIL = 1
    INSTRUCTION_ERROR = 2
    CRC_ERROR = 3
    DATA_RANGE_ERROR = 4
    DATA_LENGTH_ERROR = 5
    DATA_LIMIT_ERROR = 6
    ACCESS_ERROR = 7

    @property
    def text(self) -> str:
        return _RESULT_TEXT[self]


_RESULT_TEXT = {
    StatusResult.OK: "ok",
    StatusResult.RESULT_FAIL: "result fail (the instruction could not be processed)",
    StatusResult.INSTRUCTION_ERROR: "instruction error (unknown instruction, or Action without Reg Write)",
    StatusResult.CRC_ERROR: "CRC error (the servo received a corrupted packet)",
    StatusResult.DATA_RANGE_ERROR: "data range error (value out of range, or bus watchdog fired)",
    StatusResult.DATA_LENGTH_ERROR: "data length error (wrong number of bytes for the item)",
    StatusResult.DATA_LIMIT_ERROR: "data limit error (value outside the limit registers)",
    StatusResult.ACCESS_ERROR: "access error (read-only/undefined address, or EEPROM write with torque on)",
}

ALERT_BIT = 0x80

# --------------------------------------------------------------------------- CRC


def _make_crc_table(poly: int = 0x8005) -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ poly) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _make_crc_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16/BUYPASS (poly 0x8005, init 0, MSB first, no final XOR) of ``data``."""
    table = _CRC_TABLE
    for b in data:
        crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ b]
    return crc


# --------------------------------------------------------------------------- stuffing


def stuff(body: bytes) -> bytes:
    """Insert an ``FD`` after every ``FF FF FD`` in ``body`` (instruction byte .. last param)."""
    if b"\xff\xff\xfd" not in body:
        return body
    out = bytearray()
    i = 0
    n = len(body)
    while i < n:
        out.append(body[i])
        if i >= 2 and body[i] == 0xFD and body[i - 1] == 0xFF and body[i - 2] == 0xFF:
            out.append(0xFD)
        i += 1
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Remove the ``FD`` that follows every ``FF FF FD`` (inverse of :func:`stuff`)."""
    if b"\xff\xff\xfd\xfd" not in body:
        return body
    return body.replace(b"\xff\xff\xfd\xfd", b"\xff\xff\xfd")


# --------------------------------------------------------------------------- packets


@dataclass(frozen=True)
class Packet:
    """A framed packet with stuffing removed: ``instruction`` 0x55 means a status packet."""

    id: int
    instruction: int
    params: bytes

    @property
    def is_status(self) -> bool:
        return self.instruction == STATUS_INSTRUCTION


@dataclass(frozen=True)
class BadFrame:
    """A frame with a valid header whose CRC did not match (``raw`` is the stuffed frame)."""

    id: int
    raw: bytes
    reason: str


@dataclass(frozen=True)
class Status:
    """A decoded status packet: servo ``id``, ``error`` byte, ``data`` parameters."""

    id: int
    error: int
    data: bytes

    @property
    def alert(self) -> bool:
        """Hardware alert bit: read Hardware Error Status (address 70) for the cause."""
        return bool(self.error & ALERT_BIT)

    @property
    def result(self) -> StatusResult:
        code = self.error & 0x7F
        try:
            return StatusResult(code)
        except ValueError:
            return StatusResult.RESULT_FAIL

    @property
    def ok(self) -> bool:
        return (self.error & 0x7F) == 0


def _check_id(dxl_id: int, *, broadcast_ok: bool = True) -> None:
    if not (0 <= dxl_id <= MAX_ID or (broadcast_ok and dxl_id == BROADCAST_ID)):
        raise CodecError(f"servo id {dxl_id} out of range (0-252, or 254 broadcast)")


def _u16(value: int, what: str) -> bytes:
    if not 0 <= value <= 0xFFFF:
        raise CodecError(f"{what} {value} does not fit in 16 bits")
    return struct.pack("<H", value)


def encode_instruction(dxl_id: int, instruction: int, params: bytes = b"") -> bytes:
    """Frame an instruction packet: header, id, stuffed body, LEN and CRC over the stuffed body."""
    _check_id(dxl_id)
    body = stuff(bytes((instruction,)) + bytes(params))
    length = len(body) + 2
    if length > 0xFFFF:
        raise CodecError(f"packet too long ({length} bytes after LEN)")
    head = HEADER + bytes((dxl_id, length & 0xFF, length >> 8))
    frame = head + body
    crc = crc16(frame)
    return frame + bytes((crc & 0xFF, crc >> 8))


def encode_status(dxl_id: int, error: int, data: bytes = b"") -> bytes:
    """Frame a status packet (the device side; used by the fake and by tests)."""
    _check_id(dxl_id, broadcast_ok=False)
    if not 0 <= error <= 0xFF:
        raise CodecError(f"error byte {error} out of range")
    return encode_instruction(dxl_id, STATUS_INSTRUCTION, bytes((error,)) + bytes(data))


def decode_status(frame: bytes) -> Status:
    """Decode one complete status frame (stuffed, with CRC); raises CodecError if invalid."""
    if len(frame) < 11 or frame[:4] != HEADER:
        raise CodecError(f"not a status frame: {frame.hex(' ')}")
    length = frame[5] | (frame[6] << 8)
    if len(frame) != 7 + length:
        raise CodecError(f"frame length {len(frame)} does not match LEN {length}")
    crc = frame[-2] | (frame[-1] << 8)
    if crc16(frame[:-2]) != crc:
        raise CodecError(f"CRC mismatch in frame from id {frame[4]}")
    if frame[7] != STATUS_INSTRUCTION:
        raise CodecError(f"instruction byte 0x{frame[7]:02X} is not a status (0x55)")
    body = unstuff(frame[7:-2])
    return Status(frame[4], body[1], bytes(body[2:]))


def status_from_packet(packet: Packet) -> Status:
    """View a parsed status :class:`Packet` as a :class:`Status`."""
    if not packet.is_status or not packet.params:
        raise CodecError(f"packet from id {packet.id} is not a status packet")
    return Status(packet.id, packet.params[0], packet.params[1:])


def status_length(data_len: int) -> int:
    """Wire length [bytes] of a status packet carrying ``data_len`` bytes (without stuffing)."""
    return 11 + data_len


class PacketParser:
    """Streaming Protocol 2.0 deframer.

    :meth:`feed` chunks as they arrive; it returns the complete :class:`Packet` and
    :class:`BadFrame` items found, in order. Bytes before a header are dropped (counted in
    :attr:`dropped`). :attr:`pending` is the number of bytes buffered toward an incomplete
    frame: non-zero at a deadline means a truncated reply, zero means no reply.
    """

    __slots__ = ("_buf", "dropped")

    def __init__(self) -> None:
        self._buf = bytearray()
        self.dropped = 0

    @property
    def pending(self) -> int:
        return len(self._buf)

    def clear(self) -> None:
        self._buf.clear()

    def feed(self, data: bytes) -> list[Packet | BadFrame]:
        buf = self._buf
        buf += data
        out: list[Packet | BadFrame] = []
        while True:
            start = buf.find(HEADER)
            if start < 0:
                # keep a possible partial header at the end
                keep = 0
                for k in (3, 2, 1):
                    if len(buf) >= k and buf[-k:] == HEADER[:k]:
                        keep = k
                        break
                drop = len(buf) - keep
                if drop:
                    self.dropped += drop
                    del buf[:drop]
                return out
            if start:
                self.dropped += start
                del buf[:start]
            if len(buf) < 7:
                return out
            length = buf[5] | (buf[6] << 8)
            if length < 3 or length > MAX_LEN or buf[4] == 0xFD:
                # "FF FF FD 00" inside garbage, or an impossible LEN: skip this header byte
                self.dropped += 1
                del buf[:1]
                continue
            total = 7 + length
            if len(buf) < total:
                return out
            frame = bytes(buf[:total])
            crc = frame[-2] | (frame[-1] << 8)
            if crc16(memoryview(frame)[:-2]) != crc:
                out.append(BadFrame(frame[4], frame, "CRC mismatch"))
                # resync after the header: stuffing guarantees no header inside a body
                self.dropped += 4
                del buf[:4]
                continue
            del buf[:total]
            body = unstuff(frame[7:-2])
            out.append(Packet(frame[4], body[0], bytes(body[1:])))


# --------------------------------------------------------------------------- little-endian values


def int_to_le(value: int, size: int) -> bytes:
    """``value`` as ``size`` little-endian bytes (two's complement for negatives)."""
    if size not in (1, 2, 4):
        raise CodecError(f"register size {size} is not 1, 2 or 4")
    lo, hi = -(1 << (8 * size - 1)), (1 << (8 * size)) - 1
    if not lo <= value <= hi:
        raise CodecError(f"value {value} does not fit in {size} byte(s)")
    return (value & ((1 << (8 * size)) - 1)).to_bytes(size, "little")


def int_from_le(data: bytes, signed: bool = False) -> int:
    """Little-endian bytes to int."""
    return int.from_bytes(data, "little", signed=signed)


# --------------------------------------------------------------------------- instruction encoders


def ping(dxl_id: int) -> bytes:
    """Ping ``dxl_id`` (254 = broadcast ping; every servo answers in turn)."""
    return encode_instruction(dxl_id, Instruction.PING)


def read(dxl_id: int, address: int, length: int) -> bytes:
    """Read ``length`` bytes from control-table ``address``."""
    return encode_instruction(
        dxl_id, Instruction.READ, _u16(address, "address") + _u16(length, "length")
    )


def write(dxl_id: int, address: int, data: bytes) -> bytes:
    """Write ``data`` at control-table ``address``."""
    if not data:
        raise CodecError("write of no data")
    return encode_instruction(dxl_id, Instruction.WRITE, _u16(address, "address") + bytes(data))


def reg_write(dxl_id: int, address: int, data: bytes) -> bytes:
    """Register a write, executed on :func:`action`."""
    if not data:
        raise CodecError("reg write of no data")
    return encode_instruction(dxl_id, Instruction.REG_WRITE, _u16(address, "address") + bytes(data))


def action(dxl_id: int) -> bytes:
    """Execute registered writes."""
    return encode_instruction(dxl_id, Instruction.ACTION)


def reboot(dxl_id: int) -> bytes:
    """Reboot (clears a hardware error; torque comes back off)."""
    return encode_instruction(dxl_id, Instruction.REBOOT)


def factory_reset(dxl_id: int, option: int = 0x02) -> bytes:
    """Factory reset: 0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate."""
    if option not in (0xFF, 0x01, 0x02):
        raise CodecError(f"factory reset option 0x{option:02X} is not 0xFF, 0x01 or 0x02")
    return encode_instruction(dxl_id, Instruction.FACTORY_RESET, bytes((option,)))


def clear_multi_turn(dxl_id: int) -> bytes:
    """Clear instruction, option 0x01: reset the multi-turn count (servo must be stopped)."""
    return encode_instruction(dxl_id, Instruction.CLEAR, b"\x01" + CLEAR_KEY)


def sync_read(address: int, length: int, ids: Sequence[int]) -> bytes:
    """Sync Read ``length`` bytes at ``address`` from ``ids`` (answered in list order)."""
    if not ids:
        raise CodecError("sync read of no servos")
    for i in ids:
        _check_id(i, broadcast_ok=False)
    return encode_instruction(
        BROADCAST_ID,
        Instruction.SYNC_READ,
        _u16(address, "address") + _u16(length, "length") + bytes(ids),
    )


def sync_write(
    address: int, length: int, data: Mapping[int, bytes] | Iterable[tuple[int, bytes]]
) -> bytes:
    """Sync Write the same ``length``-byte item at ``address`` to several servos (no reply)."""
    items = list(data.items()) if isinstance(data, Mapping) else list(data)
    if not items:
        raise CodecError("sync write to no servos")
    params = bytearray(_u16(address, "address") + _u16(length, "length"))
    for dxl_id, value in items:
        _check_id(dxl_id, broadcast_ok=False)
        if len(value) != length:
            raise CodecError(f"sync write: {len(value)} bytes for id {dxl_id}, expected {length}")
        params.append(dxl_id)
        params += value
    return encode_instruction(BROADCAST_ID, Instruction.SYNC_WRITE, bytes(params))


def bulk_read(items: Sequence[tuple[int, int, int]]) -> bytes:
    """Bulk Read: per servo ``(id, address, length)``; one status per servo in list order."""
    if not items:
        raise CodecError("bulk read of no servos")
    params = bytearray()
    for dxl_id, address, length in items:
        _check_id(dxl_id, broadcast_ok=False)
        params.append(dxl_id)
        params += _u16(address, "address") + _u16(length, "length")
    return encode_instruction(BROADCAST_ID, Instruction.BULK_READ, bytes(params))


def bulk_write(items: Sequence[tuple[int, int, bytes]]) -> bytes:
    """Bulk Write: per servo ``(id, address, data)`` (no reply)."""
    if not items:
        raise CodecError("bulk write to no servos")
    params = bytearray()
    for dxl_id, address, data in items:
        _check_id(dxl_id, broadcast_ok=False)
        params.append(dxl_id)
        params += _u16(address, "address") + _u16(len(data), "length") + bytes(data)
    return encode_instruction(BROADCAST_ID, Instruction.BULK_WRITE, bytes(params))


# --------------------------------------------------------------------------- instruction parameter decoders (device side)


def parse_sync_read(params: bytes) -> tuple[int, int, list[int]]:
    """``(address, length, ids)`` of a Sync Read's parameters."""
    if len(params) < 5:
        raise CodecError("sync read parameters too short")
    address, length = struct.unpack_from("<HH", params)
    return address, length, list(params[4:])


def parse_sync_write(params: bytes) -> tuple[int, int, dict[int, bytes]]:
    """``(address, length, {id: data})`` of a Sync Write's parameters."""
    if len(params) < 4:
        raise CodecError("sync write parameters too short")
    address, length = struct.unpack_from("<HH", params)
    rest = params[4:]
    step = 1 + length
    if length == 0 or len(rest) % step:
        raise CodecError(f"sync write body of {len(rest)} bytes is not a multiple of {step}")
    return (
        address,
        length,
        {rest[i]: bytes(rest[i + 1 : i + step]) for i in range(0, len(rest), step)},
    )


def parse_bulk_read(params: bytes) -> list[tuple[int, int, int]]:
    """``[(id, address, length), ...]`` of a Bulk Read's parameters."""
    if not params or len(params) % 5:
        raise CodecError(f"bulk read body of {len(params)} bytes is not a multiple of 5")
    return [
        (params[i], *struct.unpack_from("<HH", params, i + 1)) for i in range(0, len(params), 5)
    ]


def parse_bulk_write(params: bytes) -> list[tuple[int, int, bytes]]:
    """``[(id, address, data), ...]`` of a Bulk Write's parameters."""
    out = []
    i = 0
    while i < len(params):
        if i + 5 > len(params):
            raise CodecError("bulk write body truncated")
        dxl_id = params[i]
        address, length = struct.unpack_from("<HH", params, i + 1)
        data = params[i + 5 : i + 5 + length]
        if len(data) != length:
            raise CodecError("bulk write body truncated")
        out.append((dxl_id, address, bytes(data)))
        i += 5 + length
    return out
