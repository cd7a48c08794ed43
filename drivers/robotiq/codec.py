"""Pure Modbus RTU codec for the Robotiq 2F-85: CRC, frames, register packing, commands, status.

Everything here is a pure function over ``bytes`` (no port, no clock), so it is tested
byte for byte against the examples of docs/protocols.md section 3. Wire facts:

* frame = ``slave | function | data | CRC_L CRC_H``; CRC-16/MODBUS (reflected polynomial
  0xA001, initial 0xFFFF, low byte first; check value 0x4B37); register values and
  addresses big-endian;
* the gripper's two 16-byte arrays (robot output = commands at 0x03E8, robot input = status
  at 0x07D0) are packed two gripper bytes per register, the lower-numbered byte in the HIGH
  half (first on the wire).

Validation failures raise :class:`~mmexec.drivers.robotiq.errors.FrameError`.

SI conversions use the commonly quoted product figures (docs/protocols.md 3.2 and
docs/robots.md 2.4 mark them unconfirmed): position 0..255 is width 0.085..0 m (linear),
speed 0..255 is 0.020..0.150 m/s, force 0..255 is 20..235 N.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

from mmexec.drivers.robotiq.errors import FrameError

__all__ = [
    "DEFAULT_SLAVE",
    "FC_READ_HOLDING",
    "FC_READ_INPUT",
    "FC_READ_WRITE_MULTIPLE",
    "FC_WRITE_MULTIPLE",
    "FC_WRITE_SINGLE",
    "INPUT_BASE",
    "OUTPUT_BASE",
    "Command",
    "Request",
    "Status",
    "append_crc",
    "bytes_to_registers",
    "check_crc",
    "crc16_modbus",
    "decode_read_reply",
    "decode_request",
    "decode_write_multiple_reply",
    "decode_write_single_reply",
    "encode_read",
    "encode_read_reply",
    "encode_read_write",
    "encode_write_multiple",
    "encode_write_multiple_reply",
    "encode_write_single",
    "force_to_raw",
    "position_to_width",
    "raw_to_force",
    "raw_to_speed",
    "read_reply_length",
    "registers_to_bytes",
    "request_length",
    "speed_to_raw",
    "width_to_position",
]

DEFAULT_SLAVE = 9
FC_READ_HOLDING = 0x03
FC_READ_INPUT = 0x04
FC_WRITE_SINGLE = 0x06
FC_WRITE_MULTIPLE = 0x10
FC_READ_WRITE_MULTIPLE = 0x17
#: first register of the robot output (command) array
OUTPUT_BASE = 0x03E8
#: first register of the robot input (status) array
INPUT_BASE = 0x07D0

#: stroke [m] at position 0 (fully open); position 255 is 0 m (commonly quoted, unconfirmed)
STROKE = 0.085
#: speed [m/s] at rSP = 0 and 255 (commonly quoted, unconfirmed)
SPEED_MIN, SPEED_MAX = 0.020, 0.150
#: force [N] at rFR = 0 and 255 (commonly quoted, unconfirmed; rFR sets a current limit)
FORCE_MIN, FORCE_MAX = 20.0, 235.0


# --------------------------------------------------------------------------- CRC


def _crc_table() -> tuple[int, ...]:
    table = []
    for i in range(256):
        crc = i
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16_modbus(data: bytes) -> int:
    """CRC-16/MODBUS of ``data`` (reflected 0xA001, init 0xFFFF); ``b"123456789"`` -> 0x4B37."""
    crc = 0xFFFF
    for b in data:
        crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ b) & 0xFF]
    return crc


def append_crc(body: bytes) -> bytes:
    """``body`` followed by its CRC, low byte first."""
    return body + struct.pack("<H", crc16_modbus(body))


def check_crc(frame: bytes) -> bool:
    """True when the last two bytes of ``frame`` are the CRC of the rest."""
    if len(frame) < 4:
        return False
    return crc16_modbus(frame[:-2]) == struct.unpack("<H", frame[-2:])[0]


# --------------------------------------------------------------------------- registers


def registers_to_bytes(registers: Sequence[int]) -> bytes:
    """Gripper bytes of ``registers``: each register gives its high byte then its low byte."""
    for r in registers:
        if not 0 <= r <= 0xFFFF:
            raise ValueError(f"register value {r} outside 0..0xFFFF")
    return b"".join(struct.pack(">H", r) for r in registers)


def bytes_to_registers(data: bytes) -> tuple[int, ...]:
    """Registers from gripper bytes (lower-numbered byte in the high half); odd length pads 0."""
    if len(data) % 2:
        data = data + b"\x00"
    return tuple(struct.unpack(f">{len(data) // 2}H", data))


def _check_u8(name: str, v: int) -> None:
    if not 0 <= v <= 255:
        raise ValueError(f"{name}={v} outside 0..255")


@dataclass(frozen=True)
class Command:
    """The robot output bytes 0..5: ACTION REQUEST bits and position / speed / force requests.

    ``rPR`` 0 = fully open .. 255 = fully closed; ``rSP`` and ``rFR`` 0 = minimum .. 255 =
    maximum (0 is not zero force). ``rARD``: 0 opening (older 2-finger manual; unconfirmed
    for the 2F-85).
    """

    rACT: bool = False
    rGTO: bool = False
    rATR: bool = False
    rARD: bool = False
    rPR: int = 0
    rSP: int = 0
    rFR: int = 0

    def __post_init__(self) -> None:
        for name in ("rPR", "rSP", "rFR"):
            _check_u8(name, getattr(self, name))

    @property
    def action_request(self) -> int:
        """Byte 0: bit 0 rACT, bit 3 rGTO, bit 4 rATR, bit 5 rARD."""
        return (int(self.rACT) | int(self.rGTO) << 3 | int(self.rATR) << 4
                | int(self.rARD) << 5)

    def to_bytes(self) -> bytes:
        """Bytes 0..5 (reserved bytes 1 and 2 are 0)."""
        return bytes((self.action_request, 0, 0, self.rPR, self.rSP, self.rFR))

    def to_registers(self) -> tuple[int, int, int]:
        r = bytes_to_registers(self.to_bytes())
        return (r[0], r[1], r[2])

    @classmethod
    def from_bytes(cls, data: bytes) -> Command:
        """Decode bytes 0..5 (longer input: the rest is ignored)."""
        if len(data) < 6:
            raise FrameError(f"command needs 6 bytes, got {len(data)}")
        a = data[0]
        return cls(bool(a & 0x01), bool(a & 0x08), bool(a & 0x10), bool(a & 0x20),
                   data[3], data[4], data[5])


@dataclass(frozen=True)
class Status:
    """The robot input bytes 0..5, decoded.

    ``gACT``/``gGTO`` echo rACT/rGTO; ``gSTA`` 0 reset or automatic release, 1 activating,
    3 activated; ``gOBJ`` 0 moving, 1 contact while opening, 2 contact while closing, 3 at
    the requested position (meaningful only with gGTO = 1); ``gFLT`` fault code (0 none);
    ``kFLT`` optional controller's fault; ``gPR`` echo of the accepted rPR; ``gPO`` measured
    position 0..255; ``gCU`` motor current (about 10 mA per unit).
    """

    gACT: bool = False
    gGTO: bool = False
    gSTA: int = 0
    gOBJ: int = 0
    gFLT: int = 0
    kFLT: int = 0
    gPR: int = 0
    gPO: int = 0
    gCU: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.gSTA <= 3 or not 0 <= self.gOBJ <= 3:
            raise ValueError(f"gSTA={self.gSTA} / gOBJ={self.gOBJ} outside 0..3")
        if not 0 <= self.gFLT <= 15 or not 0 <= self.kFLT <= 15:
            raise ValueError(f"gFLT={self.gFLT} / kFLT={self.kFLT} outside 0..15")
        for name in ("gPR", "gPO", "gCU"):
            _check_u8(name, getattr(self, name))

    @property
    def activated(self) -> bool:
        return self.gSTA == 3

    @property
    def status_byte(self) -> int:
        """Byte 0: bit 0 gACT, bit 3 gGTO, bits 4-5 gSTA, bits 6-7 gOBJ."""
        return int(self.gACT) | int(self.gGTO) << 3 | self.gSTA << 4 | self.gOBJ << 6

    def to_bytes(self) -> bytes:
        return bytes((self.status_byte, 0, self.kFLT << 4 | self.gFLT, self.gPR, self.gPO,
                      self.gCU))

    def to_registers(self) -> tuple[int, int, int]:
        r = bytes_to_registers(self.to_bytes())
        return (r[0], r[1], r[2])

    @classmethod
    def from_bytes(cls, data: bytes) -> Status:
        """Decode bytes 0..5 (longer input: the rest is ignored)."""
        if len(data) < 6:
            raise FrameError(f"status needs 6 bytes, got {len(data)}")
        s, f = data[0], data[2]
        return cls(bool(s & 0x01), bool(s & 0x08), (s >> 4) & 0x3, (s >> 6) & 0x3,
                   f & 0x0F, f >> 4, data[3], data[4], data[5])

    @classmethod
    def from_registers(cls, registers: Sequence[int]) -> Status:
        return cls.from_bytes(registers_to_bytes(registers))


# --------------------------------------------------------------------------- SI units


def _finite(name: str, v: float) -> float:
    if not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number, got {v}")
    return float(v)


def width_to_position(width: float) -> int:
    """Finger gap [m] to rPR (0.085 m -> 0, 0 m -> 255), clamped to the stroke."""
    w = min(max(_finite("width", width), 0.0), STROKE)
    return round((STROKE - w) / STROKE * 255)


def position_to_width(position: int) -> float:
    """gPO / rPR 0..255 to finger gap [m] (0 -> 0.085, 255 -> 0)."""
    _check_u8("position", position)
    return STROKE * (255 - position) / 255


def speed_to_raw(speed: float) -> int:
    """Finger speed [m/s] to rSP, clamped to 0.020..0.150 m/s."""
    v = min(max(_finite("speed", speed), SPEED_MIN), SPEED_MAX)
    return round((v - SPEED_MIN) / (SPEED_MAX - SPEED_MIN) * 255)


def raw_to_speed(raw: int) -> float:
    """rSP 0..255 to finger speed [m/s]."""
    _check_u8("speed", raw)
    return SPEED_MIN + (SPEED_MAX - SPEED_MIN) * raw / 255


def force_to_raw(force: float) -> int:
    """Grip force [N] to rFR, clamped to 20..235 N."""
    f = min(max(_finite("force", force), FORCE_MIN), FORCE_MAX)
    return round((f - FORCE_MIN) / (FORCE_MAX - FORCE_MIN) * 255)


def raw_to_force(raw: int) -> float:
    """rFR 0..255 to grip force [N]."""
    _check_u8("force", raw)
    return FORCE_MIN + (FORCE_MAX - FORCE_MIN) * raw / 255


# --------------------------------------------------------------------------- master side


def _u16(name: str, v: int) -> int:
    if not 0 <= v <= 0xFFFF:
        raise ValueError(f"{name}={v} outside 0..0xFFFF")
    return v


def _check_slave(slave: int) -> None:
    if not 0 <= slave <= 247:
        raise ValueError(f"slave id {slave} outside 0..247")


def encode_read(slave: int, function: int, address: int, count: int) -> bytes:
    """FC03 (read holding) or FC04 (read input registers) request."""
    _check_slave(slave)
    if function not in (FC_READ_HOLDING, FC_READ_INPUT):
        raise ValueError(f"function 0x{function:02X} is not a register read (3 or 4)")
    if not 1 <= count <= 125:
        raise ValueError(f"register count {count} outside 1..125")
    return append_crc(struct.pack(">BBHH", slave, function, _u16("address", address), count))


def encode_write_single(slave: int, address: int, value: int) -> bytes:
    """FC06 preset single register."""
    _check_slave(slave)
    return append_crc(struct.pack(">BBHH", slave, FC_WRITE_SINGLE, _u16("address", address),
                                  _u16("value", value)))


def encode_write_multiple(slave: int, address: int, values: Sequence[int]) -> bytes:
    """FC16 preset multiple registers."""
    _check_slave(slave)
    if not 1 <= len(values) <= 123:
        raise ValueError(f"register count {len(values)} outside 1..123")
    data = registers_to_bytes(values)
    return append_crc(struct.pack(">BBHHB", slave, FC_WRITE_MULTIPLE, _u16("address", address),
                                  len(values), len(data)) + data)


def encode_read_write(slave: int, read_address: int, read_count: int, write_address: int,
                      values: Sequence[int]) -> bytes:
    """FC23 read/write multiple registers (the write is applied before the read)."""
    _check_slave(slave)
    if not 1 <= read_count <= 125 or not 1 <= len(values) <= 121:
        raise ValueError(f"FC23 counts read={read_count} write={len(values)} out of range")
    data = registers_to_bytes(values)
    return append_crc(struct.pack(">BBHHHHB", slave, FC_READ_WRITE_MULTIPLE,
                                  _u16("read_address", read_address), read_count,
                                  _u16("write_address", write_address), len(values), len(data))
                      + data)


def read_reply_length(count: int) -> int:
    """Bytes in the reply to a read of ``count`` registers (FC03/04/23)."""
    return 5 + 2 * count


def _validate(frame: bytes, slave: int, function: int, length: int) -> None:
    if len(frame) != length:
        raise FrameError(f"reply has {len(frame)} bytes, expected {length}")
    if not check_crc(frame):
        raise FrameError(f"bad CRC in reply {frame.hex(' ')}")
    if frame[0] != slave:
        raise FrameError(f"reply from slave {frame[0]}, expected {slave}")
    if frame[1] != function:
        if frame[1] == function | 0x80:
            raise FrameError(f"exception reply, code 0x{frame[2]:02X}")
        raise FrameError(f"reply function 0x{frame[1]:02X}, expected 0x{function:02X}")


def decode_read_reply(frame: bytes, slave: int, function: int, count: int) -> tuple[int, ...]:
    """Registers from the reply to a FC03/04/23 read of ``count`` registers."""
    _validate(frame, slave, function, read_reply_length(count))
    if frame[2] != 2 * count:
        raise FrameError(f"byte count {frame[2]}, expected {2 * count}")
    return bytes_to_registers(frame[3:-2])


def decode_write_single_reply(frame: bytes, slave: int, address: int, value: int) -> None:
    """Check the FC06 echo."""
    _validate(frame, slave, FC_WRITE_SINGLE, 8)
    got = struct.unpack(">HH", frame[2:6])
    if got != (address, value):
        raise FrameError(f"FC06 echo {got[0]:#06x}={got[1]:#06x}, expected "
                         f"{address:#06x}={value:#06x}")


def decode_write_multiple_reply(frame: bytes, slave: int, address: int, count: int) -> None:
    """Check the FC16 reply (start address and register count)."""
    _validate(frame, slave, FC_WRITE_MULTIPLE, 8)
    got = struct.unpack(">HH", frame[2:6])
    if got != (address, count):
        raise FrameError(f"FC16 reply {got[0]:#06x} x{got[1]}, expected {address:#06x} x{count}")


# --------------------------------------------------------------------------- slave side


@dataclass(frozen=True)
class Request:
    """A decoded request as a slave sees it. ``read_*`` for FC03/04/23, ``write_*`` for
    FC06/16/23 (``write_values`` empty for pure reads)."""

    slave: int
    function: int
    read_address: int = 0
    read_count: int = 0
    write_address: int = 0
    write_values: tuple[int, ...] = ()


def request_length(buf: bytes) -> int | None:
    """Length of the request frame starting ``buf``, or None if more bytes are needed to
    tell. Raises FrameError for a function code this slave does not implement."""
    if len(buf) < 2:
        return None
    fc = buf[1]
    if fc in (FC_READ_HOLDING, FC_READ_INPUT, FC_WRITE_SINGLE):
        return 8
    if fc == FC_WRITE_MULTIPLE:
        return None if len(buf) < 7 else 9 + buf[6]
    if fc == FC_READ_WRITE_MULTIPLE:
        return None if len(buf) < 11 else 13 + buf[10]
    raise FrameError(f"unsupported function 0x{fc:02X}")


def decode_request(frame: bytes) -> Request:
    """Decode one complete request frame (CRC checked)."""
    n = request_length(frame)
    if n is None or len(frame) != n:
        raise FrameError(f"request has {len(frame)} bytes, expected {n}")
    if not check_crc(frame):
        raise FrameError("bad CRC in request")
    slave, fc = frame[0], frame[1]
    if fc in (FC_READ_HOLDING, FC_READ_INPUT):
        addr, count = struct.unpack(">HH", frame[2:6])
        return Request(slave, fc, read_address=addr, read_count=count)
    if fc == FC_WRITE_SINGLE:
        addr, value = struct.unpack(">HH", frame[2:6])
        return Request(slave, fc, write_address=addr, write_values=(value,))
    if fc == FC_WRITE_MULTIPLE:
        addr, count, nbytes = struct.unpack(">HHB", frame[2:7])
        if nbytes != 2 * count:
            raise FrameError(f"FC16 byte count {nbytes} for {count} registers")
        return Request(slave, fc, write_address=addr,
                       write_values=bytes_to_registers(frame[7:7 + nbytes]))
    raddr, rcount, waddr, wcount, nbytes = struct.unpack(">HHHHB", frame[2:11])
    if nbytes != 2 * wcount:
        raise FrameError(f"FC23 byte count {nbytes} for {wcount} registers")
    return Request(slave, fc, read_address=raddr, read_count=rcount, write_address=waddr,
                   write_values=bytes_to_registers(frame[11:11 + nbytes]))


def encode_read_reply(slave: int, function: int, registers: Sequence[int]) -> bytes:
    """Slave reply carrying ``registers`` (FC03/04/23)."""
    data = registers_to_bytes(registers)
    return append_crc(bytes((slave, function, len(data))) + data)


def encode_write_multiple_reply(slave: int, address: int, count: int) -> bytes:
    """Slave reply to FC16 (start address and count)."""
    return append_crc(struct.pack(">BBHH", slave, FC_WRITE_MULTIPLE, address, count))
