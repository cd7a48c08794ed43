"""Slamtec RPLIDAR A2 serial protocol: pure functions over bytes (no I/O, no clocks).

Facts from ``docs/protocols.md`` section 5 (Slamtec LR001):

* a request is ``A5 CMD`` or, for commands with bit 7 set, ``A5 CMD SIZE PAYLOAD
  CHECKSUM`` where CHECKSUM is the XOR of every preceding byte, ``A5`` included;
* a response starts with a 7-byte descriptor ``A5 5A`` + uint32 LE (low 30 bits data
  length, high 2 bits send mode) + data type, then the data;
* SCAN answers one descriptor (multiple-response mode) and then 5-byte measurement nodes
  until STOP: start flag S and its inverse, quality, check bit C, ``angle_q6``
  (degrees * 64, clockwise seen from above) and ``distance_q2`` (mm * 4, 0 = invalid).

This module provides request encoders and :class:`RequestParser` (the device side, for
the fake), descriptor encode / decode and :func:`find_response`, the GET_INFO /
GET_HEALTH / GET_SAMPLERATE / GET_ACC_BOARD_FLAG payloads both ways, and the measurement
node codec with :class:`NodeParser`, which resynchronises one byte at a time after a
corrupt node as the document prescribes. EXPRESS_SCAN (optional for mmexec) is not
implemented.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass

from mmexec.drivers.geometry import wrap_angle

__all__ = [
    "ACC_BOARD_MOTOR_CONTROL",
    "DEFAULT_MOTOR_PWM",
    "DESCRIPTOR_SIZE",
    "MAX_MOTOR_PWM",
    "NODE_SIZE",
    "SYNC",
    "SYNC2",
    "CodecError",
    "Command",
    "DataType",
    "Descriptor",
    "DeviceInfo",
    "Health",
    "HealthStatus",
    "MeasurementNode",
    "NodeParser",
    "Request",
    "RequestParser",
    "SampleRate",
    "SendMode",
    "ccw_angle",
    "decode_acc_board_flag",
    "decode_descriptor",
    "decode_health",
    "decode_info",
    "decode_node",
    "decode_sample_rate",
    "encode_acc_board_flag",
    "encode_descriptor",
    "encode_health",
    "encode_info",
    "encode_node",
    "encode_request",
    "encode_sample_rate",
    "find_response",
    "get_acc_board_flag",
    "node_is_valid",
    "response_descriptor",
    "set_motor_pwm",
    "xor_checksum",
]

SYNC = 0xA5        #: first byte of every request and response descriptor
SYNC2 = 0x5A       #: second byte of a response descriptor
DESCRIPTOR_SIZE = 7
NODE_SIZE = 5      #: one standard SCAN measurement node
DEFAULT_MOTOR_PWM = 660   #: the vendor SDK's default duty (about 10 Hz)
MAX_MOTOR_PWM = 1023
ACC_BOARD_MOTOR_CONTROL = 0x1  #: GET_ACC_BOARD_FLAG bit 0: SET_MOTOR_PWM supported


class CodecError(ValueError):
    """Bytes that do not form what the protocol says (wrong size, sync, check bits)."""


class Command(enum.IntEnum):
    """Request command bytes (docs/protocols.md 5.2). Bit 7 set = carries a payload."""

    STOP = 0x25
    RESET = 0x40
    SCAN = 0x20
    FORCE_SCAN = 0x21
    EXPRESS_SCAN = 0x82
    GET_INFO = 0x50
    GET_HEALTH = 0x52
    GET_SAMPLERATE = 0x59
    SET_MOTOR_PWM = 0xF0
    GET_ACC_BOARD_FLAG = 0xFF


class DataType(enum.IntEnum):
    """Response data types (the descriptor's last byte)."""

    INFO = 0x04
    HEALTH = 0x06
    SAMPLERATE = 0x15
    MEASUREMENT = 0x81
    EXPRESS = 0x82
    ACC_BOARD_FLAG = 0xFF


class SendMode(enum.IntEnum):
    """Descriptor send mode: one answer, or a stream until STOP (SCAN)."""

    SINGLE = 0
    MULTIPLE = 1


class HealthStatus(enum.IntEnum):
    """GET_HEALTH status: ERROR is a protection stop (no scanning until RESET)."""

    GOOD = 0
    WARNING = 1
    ERROR = 2


# --------------------------------------------------------------------------- requests


def xor_checksum(data: bytes) -> int:
    """XOR of every byte of ``data``."""
    c = 0
    for b in data:
        c ^= b
    return c


def encode_request(cmd: int, payload: bytes = b"") -> bytes:
    """``A5 CMD`` for a command without payload (bit 7 clear); ``A5 CMD SIZE PAYLOAD
    CHECKSUM`` for one with bit 7 set (the SDK's rule), CHECKSUM = XOR of all before it."""
    if not 0 <= cmd <= 0xFF:
        raise CodecError(f"command byte {cmd} outside 0..255")
    if not cmd & 0x80:
        if payload:
            raise CodecError(f"command 0x{cmd:02X} has bit 7 clear and takes no payload")
        return bytes((SYNC, cmd))
    if len(payload) > 0xFF:
        raise CodecError(f"payload of {len(payload)} bytes does not fit the size byte")
    head = bytes((SYNC, cmd, len(payload))) + payload
    return head + bytes((xor_checksum(head),))


def set_motor_pwm(pwm: int) -> bytes:
    """SET_MOTOR_PWM with ``pwm`` duty 0..1023 (0 stops the motor), uint16 LE."""
    if not 0 <= pwm <= MAX_MOTOR_PWM:
        raise CodecError(f"motor PWM {pwm} outside 0..{MAX_MOTOR_PWM}")
    return encode_request(Command.SET_MOTOR_PWM, struct.pack("<H", pwm))


def get_acc_board_flag() -> bytes:
    """GET_ACC_BOARD_FLAG with its 4-byte zero payload."""
    return encode_request(Command.GET_ACC_BOARD_FLAG, bytes(4))


@dataclass(frozen=True)
class Request:
    """A request as the device sees it: command byte and payload."""

    cmd: int
    payload: bytes = b""


class RequestParser:
    """Device-side request finder for the fake: :meth:`feed` bytes from the host.

    Bytes before ``A5`` are dropped (counted in :attr:`discarded`); a request with a
    payload whose checksum is wrong is dropped (counted in :attr:`bad_checksum`) and the
    search restarts one byte after its ``A5``.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.discarded = 0
        self.bad_checksum = 0

    def feed(self, data: bytes) -> list[Request]:
        buf = self._buf
        buf += data
        out: list[Request] = []
        while True:
            start = buf.find(SYNC)
            if start < 0:
                self.discarded += len(buf)
                buf.clear()
                return out
            if start:
                self.discarded += start
                del buf[:start]
            if len(buf) < 2:
                return out
            cmd = buf[1]
            if not cmd & 0x80:
                out.append(Request(cmd))
                del buf[:2]
                continue
            if len(buf) < 3:
                return out
            total = 3 + buf[2] + 1
            if len(buf) < total:
                return out
            if xor_checksum(bytes(buf[: total - 1])) != buf[total - 1]:
                self.bad_checksum += 1
                del buf[:1]
                continue
            out.append(Request(cmd, bytes(buf[3 : total - 1])))
            del buf[:total]


# --------------------------------------------------------------------------- responses


@dataclass(frozen=True)
class Descriptor:
    """Response descriptor: data ``length`` [bytes] (per node in a stream), send mode,
    data type."""

    length: int
    mode: SendMode
    data_type: int


def encode_descriptor(length: int, mode: SendMode, data_type: int) -> bytes:
    """``A5 5A`` + uint32 LE (length | mode << 30) + data type."""
    if not 0 <= length < 1 << 30:
        raise CodecError(f"response length {length} does not fit 30 bits")
    return bytes((SYNC, SYNC2)) + struct.pack("<IB", length | (int(mode) << 30), data_type)


def decode_descriptor(data: bytes) -> Descriptor:
    """The 7 bytes of a descriptor; :class:`CodecError` on a wrong size, sync or mode."""
    if len(data) != DESCRIPTOR_SIZE:
        raise CodecError(f"a descriptor has {DESCRIPTOR_SIZE} bytes, got {len(data)}")
    if data[0] != SYNC or data[1] != SYNC2:
        raise CodecError(f"descriptor must start A5 5A, got {data[:2].hex(' ').upper()}")
    word, data_type = struct.unpack_from("<IB", data, 2)
    mode = word >> 30
    if mode not in (SendMode.SINGLE, SendMode.MULTIPLE):
        raise CodecError(f"unknown send mode {mode}")
    return Descriptor(word & 0x3FFFFFFF, SendMode(mode), data_type)


#: descriptor each request is answered with (docs/protocols.md 5.2)
_RESPONSES: dict[Command, Descriptor] = {
    Command.GET_INFO: Descriptor(20, SendMode.SINGLE, DataType.INFO),
    Command.GET_HEALTH: Descriptor(3, SendMode.SINGLE, DataType.HEALTH),
    Command.GET_SAMPLERATE: Descriptor(4, SendMode.SINGLE, DataType.SAMPLERATE),
    Command.GET_ACC_BOARD_FLAG: Descriptor(4, SendMode.SINGLE, DataType.ACC_BOARD_FLAG),
    Command.SCAN: Descriptor(NODE_SIZE, SendMode.MULTIPLE, DataType.MEASUREMENT),
    Command.FORCE_SCAN: Descriptor(NODE_SIZE, SendMode.MULTIPLE, DataType.MEASUREMENT),
}


def response_descriptor(cmd: Command) -> Descriptor:
    """The descriptor the device answers ``cmd`` with (KeyError for STOP, RESET, PWM)."""
    return _RESPONSES[cmd]


def find_response(buf: bytes, expected: Descriptor) -> tuple[int, bytes] | None:
    """Look for ``expected``'s descriptor in ``buf`` (bytes before it are skipped).

    Returns ``(end, data)``: the index just past the answer and its data bytes (none for a
    stream: its nodes follow); None while the descriptor or its data is incomplete.
    """
    head = encode_descriptor(expected.length, expected.mode, expected.data_type)
    start = bytes(buf).find(head)
    if start < 0:
        return None
    data_len = expected.length if expected.mode is SendMode.SINGLE else 0
    end = start + DESCRIPTOR_SIZE + data_len
    if len(buf) < end:
        return None
    return end, bytes(buf[start + DESCRIPTOR_SIZE : end])


@dataclass(frozen=True)
class DeviceInfo:
    """GET_INFO: model byte (high nibble = series: A2M8 reports 0x28), firmware
    major.minor, hardware version, 16-byte serial number."""

    model: int
    firmware_major: int
    firmware_minor: int
    hardware: int
    serial: bytes

    @property
    def model_name(self) -> str:
        """``A2M8`` for model 0x28 (series from the high nibble, sub-model the low one)."""
        return f"A{self.model >> 4}M{self.model & 0x0F}"

    @property
    def firmware(self) -> str:
        """``major.minor`` with two minor digits, as the vendor tools print it (1.29)."""
        return f"{self.firmware_major}.{self.firmware_minor:02d}"

    @property
    def serial_text(self) -> str:
        """The serial number as 32 upper-case hex digits."""
        return self.serial.hex().upper()


def decode_info(data: bytes) -> DeviceInfo:
    """GET_INFO's 20 data bytes: model, firmware minor, firmware major, hardware, serial."""
    if len(data) != 20:
        raise CodecError(f"GET_INFO data has 20 bytes, got {len(data)}")
    return DeviceInfo(data[0], data[2], data[1], data[3], bytes(data[4:20]))


def encode_info(info: DeviceInfo) -> bytes:
    if len(info.serial) != 16:
        raise CodecError(f"the serial number has 16 bytes, got {len(info.serial)}")
    return bytes((info.model, info.firmware_minor, info.firmware_major, info.hardware)) + info.serial


@dataclass(frozen=True)
class Health:
    """GET_HEALTH: status and the device's error code (meaningful when not GOOD)."""

    status: HealthStatus
    error_code: int = 0


def decode_health(data: bytes) -> Health:
    """GET_HEALTH's 3 data bytes: status, error code uint16 LE."""
    if len(data) != 3:
        raise CodecError(f"GET_HEALTH data has 3 bytes, got {len(data)}")
    status, code = struct.unpack("<BH", data)
    if status not in (0, 1, 2):
        raise CodecError(f"unknown health status {status}")
    return Health(HealthStatus(status), code)


def encode_health(health: Health) -> bytes:
    return struct.pack("<BH", int(health.status), health.error_code)


@dataclass(frozen=True)
class SampleRate:
    """GET_SAMPLERATE: microseconds per sample in standard and express scan."""

    standard_us: int
    express_us: int

    @property
    def standard_hz(self) -> float:
        """Standard-scan samples per second."""
        return 1e6 / self.standard_us if self.standard_us else 0.0


def decode_sample_rate(data: bytes) -> SampleRate:
    if len(data) != 4:
        raise CodecError(f"GET_SAMPLERATE data has 4 bytes, got {len(data)}")
    return SampleRate(*struct.unpack("<HH", data))


def encode_sample_rate(rate: SampleRate) -> bytes:
    return struct.pack("<HH", rate.standard_us, rate.express_us)


def decode_acc_board_flag(data: bytes) -> int:
    """GET_ACC_BOARD_FLAG's 4 data bytes as a uint32 LE (bit 0: motor control)."""
    if len(data) != 4:
        raise CodecError(f"GET_ACC_BOARD_FLAG data has 4 bytes, got {len(data)}")
    return int(struct.unpack("<I", data)[0])


def encode_acc_board_flag(flags: int) -> bytes:
    return struct.pack("<I", flags)


# --------------------------------------------------------------------------- scan nodes


@dataclass(frozen=True)
class MeasurementNode:
    """One standard SCAN sample: ``start`` (first node of a revolution), ``quality``
    0..63, ``angle_q6`` (degrees * 64, clockwise seen from above), ``distance_q2``
    (mm * 4; 0 = no valid return)."""

    start: bool
    quality: int
    angle_q6: int
    distance_q2: int

    @property
    def angle_deg(self) -> float:
        """Clockwise angle in the device frame [deg]."""
        return self.angle_q6 / 64.0

    @property
    def distance_m(self) -> float:
        """Range [m]; ``inf`` when the device reports no valid return (distance 0)."""
        return self.distance_q2 / 4000.0 if self.distance_q2 else math.inf


def ccw_angle(angle_q6: int) -> float:
    """A device angle (clockwise, degrees * 64) as a counter-clockwise angle [rad] in
    [-pi, pi): the REP-103 convention of the lidar frame."""
    return wrap_angle(-math.radians(angle_q6 / 64.0))


def node_is_valid(data: bytes) -> bool:
    """True when 5 bytes pass the node checks: S != not-S and C == 1."""
    b0, b1 = data[0], data[1]
    return (b0 & 1) != ((b0 >> 1) & 1) and bool(b1 & 1)


def decode_node(data: bytes) -> MeasurementNode:
    """A 5-byte node; :class:`CodecError` when the size or the check bits are wrong."""
    if len(data) != NODE_SIZE:
        raise CodecError(f"a measurement node has {NODE_SIZE} bytes, got {len(data)}")
    if not node_is_valid(data):
        raise CodecError(f"corrupt node {bytes(data).hex(' ').upper()} (S == not-S or C == 0)")
    b0, b1, b2 = data[0], data[1], data[2]
    angle_q6 = (b1 >> 1) | (b2 << 7)
    distance_q2 = data[3] | (data[4] << 8)
    return MeasurementNode(bool(b0 & 1), b0 >> 2, angle_q6, distance_q2)


def encode_node(node: MeasurementNode) -> bytes:
    """The 5 bytes of ``node`` with correct S / not-S and C bits."""
    if not 0 <= node.quality <= 63:
        raise CodecError(f"quality {node.quality} outside 0..63")
    if not 0 <= node.angle_q6 < 1 << 15:
        raise CodecError(f"angle_q6 {node.angle_q6} outside 0..32767")
    if not 0 <= node.distance_q2 <= 0xFFFF:
        raise CodecError(f"distance_q2 {node.distance_q2} outside 0..65535")
    s = 1 if node.start else 0
    b0 = (node.quality << 2) | ((1 - s) << 1) | s
    b1 = ((node.angle_q6 & 0x7F) << 1) | 1
    b2 = node.angle_q6 >> 7
    return bytes((b0, b1, b2)) + struct.pack("<H", node.distance_q2)


class NodeParser:
    """Streaming node finder for the SCAN stream (after its descriptor).

    Takes 5 bytes at a time; after a corrupt node it drops one byte and tries again
    until a valid node is found (the document's resynchronisation). Note the checks are
    weak (two bits): a misaligned window passes them one time in four, so callers judge
    whole revolutions too (see :mod:`mmexec.drivers.rplidar.scan`).
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._skipped = 0
        #: nodes accepted
        self.nodes = 0
        #: bytes dropped while resynchronising
        self.dropped = 0

    def reset(self) -> None:
        self._buf.clear()
        self._skipped = 0

    @property
    def pending(self) -> int:
        """Bytes held back until the rest of a node arrives."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[tuple[int, MeasurementNode]]:
        """Add ``data``; return ``(skipped, node)`` for every valid node now complete, where
        ``skipped`` counts the bytes dropped just before that node."""
        buf = self._buf
        buf += data
        out: list[tuple[int, MeasurementNode]] = []
        i, n = 0, len(buf)
        while n - i >= NODE_SIZE:
            chunk = bytes(buf[i : i + NODE_SIZE])
            if node_is_valid(chunk):
                out.append((self._skipped, decode_node(chunk)))
                self._skipped = 0
                i += NODE_SIZE
            else:
                self.dropped += 1
                self._skipped += 1
                i += 1
        del buf[:i]
        self.nodes += len(out)
        return out
