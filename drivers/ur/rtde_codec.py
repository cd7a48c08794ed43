"""RTDE wire protocol (Universal Robots, port 30004, protocol version 2): pure functions over bytes.

Every package is ``uint16 size (header included, big-endian) | uint8 type | payload``;
every value is big-endian. Package types:

====  ====  =======================================================================
char  code  payload (request / reply)
====  ====  =======================================================================
V     86    uint16 protocol version / uint8 accepted
v     118   empty / 4 x uint32 major, minor, bugfix, build
O     79    float64 frequency [Hz] + comma-separated names / uint8 recipe id + types
I     73    comma-separated names / uint8 recipe id + types (``IN_USE`` if taken)
S     83    empty / uint8 accepted
P     80    empty / uint8 accepted
U     85    uint8 recipe id + values packed in recipe order (both directions)
M     77    uint8 length + message, uint8 length + source, uint8 level
====  ====  =======================================================================

Nothing here touches a socket: the stub (:mod:`mmexec.drivers.ur.rtde_stub`) and the
bring-up probe (:mod:`mmexec.drivers.ur.bringup`) own the transports.
"""

from __future__ import annotations

import enum
import re
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, NamedTuple

__all__ = [
    "HEADER",
    "IN_USE",
    "NOT_FOUND",
    "PROTOCOL_VERSION",
    "TYPE_FORMATS",
    "ControllerVersion",
    "Package",
    "PackageType",
    "RTDECodecError",
    "TextMessage",
    "decode_accepted",
    "decode_controller_version",
    "decode_data",
    "decode_request_protocol_version",
    "decode_setup_inputs",
    "decode_setup_outputs",
    "decode_setup_reply",
    "decode_text_message",
    "encode_accepted",
    "encode_controller_version",
    "encode_data",
    "encode_get_controller_version",
    "encode_package",
    "encode_pause",
    "encode_request_protocol_version",
    "encode_setup_inputs",
    "encode_setup_outputs",
    "encode_setup_reply",
    "encode_start",
    "encode_text_message",
    "pack_values",
    "split_packages",
    "unpack_values",
    "variable_type",
]

PROTOCOL_VERSION = 2
NOT_FOUND = "NOT_FOUND"
IN_USE = "IN_USE"

#: uint16 size (header included) + uint8 type, big-endian.
HEADER = struct.Struct(">HB")
_MAX_SIZE = 0xFFFF


class RTDECodecError(ValueError):
    """Bytes that do not form a valid RTDE package (bad size, short payload, unknown type)."""


class PackageType(enum.IntEnum):
    """RTDE package type byte (the ASCII code of its letter)."""

    REQUEST_PROTOCOL_VERSION = ord("V")
    GET_URCONTROL_VERSION = ord("v")
    TEXT_MESSAGE = ord("M")
    DATA_PACKAGE = ord("U")
    CONTROL_PACKAGE_SETUP_OUTPUTS = ord("O")
    CONTROL_PACKAGE_SETUP_INPUTS = ord("I")
    CONTROL_PACKAGE_START = ord("S")
    CONTROL_PACKAGE_PAUSE = ord("P")


_PACKAGE_TYPES = frozenset(int(t) for t in PackageType)


class Package(NamedTuple):
    """One framed package: its type byte and its payload (header stripped)."""

    type: int
    payload: bytes


@dataclass(frozen=True)
class ControllerVersion:
    """URControl version reported by ``v`` (e.g. 5.15.0.12345)."""

    major: int
    minor: int
    bugfix: int
    build: int

    def __str__(self) -> str:
        return f"{self.major}.{self.minor}.{self.bugfix}.{self.build}"


@dataclass(frozen=True)
class TextMessage:
    """An ``M`` package: level 0 exception, 1 error, 2 warning, 3 info."""

    message: str
    source: str
    level: int


#: struct format (without byte order) of each RTDE type.
TYPE_FORMATS: dict[str, str] = {
    "BOOL": "?",
    "UINT8": "B",
    "INT32": "i",
    "UINT32": "I",
    "UINT64": "Q",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}
_VECTOR_LEN = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}


# --------------------------------------------------------------------------- framing


def encode_package(ptype: int, payload: bytes = b"") -> bytes:
    """Frame ``payload`` as one package of type ``ptype``."""
    size = HEADER.size + len(payload)
    if size > _MAX_SIZE:
        raise RTDECodecError(f"package of {size} bytes exceeds the 65535-byte RTDE limit")
    if not 0 <= int(ptype) <= 0xFF:
        raise RTDECodecError(f"package type {ptype} is not a byte")
    return HEADER.pack(size, int(ptype)) + bytes(payload)


def split_packages(buffer: bytes, *, strict: bool = False) -> tuple[list[Package], bytes]:
    """Cut every complete package off the front of ``buffer``.

    Returns the packages and the unconsumed tail (an incomplete package, to be kept
    and completed by the next read). A size field below 3 cannot be resynchronised
    from (RTDE has no start marker) and raises :class:`RTDECodecError`. With
    ``strict``, so does a type byte that is no :class:`PackageType`, already in the
    header of an incomplete package: a peer that is not an RTDE server is found out by
    its first three bytes instead of a wait for a 'package' of up to 64 kB.
    """
    out: list[Package] = []
    pos = 0
    n = len(buffer)
    while n - pos >= HEADER.size:
        size, ptype = HEADER.unpack_from(buffer, pos)
        if size < HEADER.size:
            raise RTDECodecError(f"package size field {size} < 3 at offset {pos}")
        if strict and ptype not in _PACKAGE_TYPES:
            raise RTDECodecError(f"unknown package type {ptype} (0x{ptype:02x}) at offset {pos}")
        if n - pos < size:
            break
        out.append(Package(ptype, bytes(buffer[pos + HEADER.size : pos + size])))
        pos += size
    return out, bytes(buffer[pos:])


# --------------------------------------------------------------------------- values


@lru_cache(maxsize=256)
def _recipe_struct(types: tuple[str, ...]) -> struct.Struct:
    try:
        return struct.Struct(">" + "".join(TYPE_FORMATS[t] for t in types))
    except KeyError as e:
        raise RTDECodecError(f"unknown RTDE type {e.args[0]!r} in recipe") from None


def pack_values(types: Sequence[str], values: Sequence[Any]) -> bytes:
    """Pack ``values`` (vectors as sequences) in the order and types of a recipe."""
    if len(types) != len(values):
        raise RTDECodecError(f"recipe has {len(types)} fields, got {len(values)} values")
    flat: list[Any] = []
    for t, v in zip(types, values):
        n = _VECTOR_LEN.get(t)
        if n is None:
            flat.append(v)
        else:
            vec = list(v)
            if len(vec) != n:
                raise RTDECodecError(f"{t} needs {n} values, got {len(vec)}")
            flat.extend(vec)
    try:
        return _recipe_struct(tuple(types)).pack(*flat)
    except struct.error as e:
        raise RTDECodecError(f"cannot pack values for recipe {list(types)}: {e}") from e


def unpack_values(types: Sequence[str], data: bytes) -> list[Any]:
    """Unpack recipe values from ``data`` (vectors come back as tuples)."""
    st = _recipe_struct(tuple(types))
    if len(data) != st.size:
        raise RTDECodecError(f"recipe needs {st.size} bytes, package holds {len(data)}")
    flat = st.unpack(data)
    out: list[Any] = []
    i = 0
    for t in types:
        n = _VECTOR_LEN.get(t)
        if n is None:
            out.append(flat[i])
            i += 1
        else:
            out.append(tuple(flat[i : i + n]))
            i += n
    return out


# --------------------------------------------------------------------------- messages


def encode_request_protocol_version(version: int = PROTOCOL_VERSION) -> bytes:
    """``V`` request: uint16 protocol version."""
    return encode_package(PackageType.REQUEST_PROTOCOL_VERSION, struct.pack(">H", version))


def decode_request_protocol_version(payload: bytes) -> int:
    if len(payload) != 2:
        raise RTDECodecError(f"V request payload must be 2 bytes, got {len(payload)}")
    return int(struct.unpack(">H", payload)[0])


def encode_accepted(ptype: int, accepted: bool) -> bytes:
    """Reply to ``V``, ``S`` or ``P``: uint8 accepted (1) / refused (0)."""
    return encode_package(ptype, b"\x01" if accepted else b"\x00")


def decode_accepted(payload: bytes) -> bool:
    if len(payload) != 1:
        raise RTDECodecError(f"accepted reply must be 1 byte, got {len(payload)}")
    return payload[0] != 0


def encode_get_controller_version() -> bytes:
    return encode_package(PackageType.GET_URCONTROL_VERSION)


def encode_controller_version(major: int, minor: int, bugfix: int, build: int) -> bytes:
    return encode_package(
        PackageType.GET_URCONTROL_VERSION, struct.pack(">IIII", major, minor, bugfix, build)
    )


def decode_controller_version(payload: bytes) -> ControllerVersion:
    if len(payload) != 16:
        raise RTDECodecError(f"controller version payload must be 16 bytes, got {len(payload)}")
    return ControllerVersion(*struct.unpack(">IIII", payload))


def _names_text(names: Iterable[str], trailing_comma: bool) -> bytes:
    names = list(names)
    for n in names:
        if not n or "," in n:
            raise RTDECodecError(f"invalid RTDE variable name {n!r}")
    text = ",".join(names) + ("," if trailing_comma and names else "")
    return text.encode("ascii")


def _split_names(text: bytes) -> list[str]:
    try:
        s = text.decode("ascii")
    except UnicodeDecodeError as e:
        raise RTDECodecError(f"variable list is not ASCII: {e}") from e
    # ur_rtde appends a trailing comma: empty fields are separators, not names
    return [n for n in s.split(",") if n]


def encode_setup_outputs(
    frequency: float, names: Sequence[str], *, trailing_comma: bool = False
) -> bytes:
    """``O`` request: float64 output frequency [Hz] + comma-separated variable names."""
    return encode_package(
        PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS,
        struct.pack(">d", frequency) + _names_text(names, trailing_comma),
    )


def decode_setup_outputs(payload: bytes) -> tuple[float, list[str]]:
    if len(payload) < 8:
        raise RTDECodecError(f"O request payload too short ({len(payload)} bytes)")
    (freq,) = struct.unpack_from(">d", payload, 0)
    return float(freq), _split_names(payload[8:])


def encode_setup_inputs(names: Sequence[str], *, trailing_comma: bool = False) -> bytes:
    """``I`` request: comma-separated input variable names."""
    return encode_package(PackageType.CONTROL_PACKAGE_SETUP_INPUTS, _names_text(names, trailing_comma))


def decode_setup_inputs(payload: bytes) -> list[str]:
    return _split_names(payload)


def encode_setup_reply(ptype: int, recipe_id: int, types: Sequence[str]) -> bytes:
    """Reply to ``O`` / ``I``: uint8 recipe id + comma-separated type names."""
    if not 0 <= recipe_id <= 0xFF:
        raise RTDECodecError(f"recipe id {recipe_id} is not a byte")
    return encode_package(ptype, bytes([recipe_id]) + ",".join(types).encode("ascii"))


def decode_setup_reply(payload: bytes) -> tuple[int, list[str]]:
    if not payload:
        raise RTDECodecError("setup reply is empty")
    return payload[0], _split_names(payload[1:])


def encode_start() -> bytes:
    return encode_package(PackageType.CONTROL_PACKAGE_START)


def encode_pause() -> bytes:
    return encode_package(PackageType.CONTROL_PACKAGE_PAUSE)


def encode_data(recipe_id: int, types: Sequence[str], values: Sequence[Any]) -> bytes:
    """``U`` data package: uint8 recipe id + values packed in recipe order."""
    if not 0 <= recipe_id <= 0xFF:
        raise RTDECodecError(f"recipe id {recipe_id} is not a byte")
    return encode_package(PackageType.DATA_PACKAGE, bytes([recipe_id]) + pack_values(types, values))


def decode_data(payload: bytes, recipes: Mapping[int, Sequence[str]]) -> tuple[int, list[Any]]:
    """Decode a ``U`` payload using the recipe types registered under its id."""
    if not payload:
        raise RTDECodecError("data package is empty")
    rid = payload[0]
    types = recipes.get(rid)
    if types is None:
        raise RTDECodecError(f"data package for unknown recipe id {rid}")
    return rid, unpack_values(types, payload[1:])


def encode_text_message(message: str, source: str, level: int) -> bytes:
    """``M`` package: uint8 length + message, uint8 length + source, uint8 level."""
    m, s = message.encode("utf-8"), source.encode("utf-8")
    if len(m) > 255 or len(s) > 255 or not 0 <= level <= 255:
        raise RTDECodecError("text message, source or level too long for one byte")
    return encode_package(PackageType.TEXT_MESSAGE, bytes([len(m)]) + m + bytes([len(s)]) + s + bytes([level]))


def decode_text_message(payload: bytes) -> TextMessage:
    try:
        n = payload[0]
        msg = payload[1 : 1 + n]
        k = payload[1 + n]
        src = payload[2 + n : 2 + n + k]
        level = payload[2 + n + k]
    except IndexError:
        raise RTDECodecError(f"text message truncated ({len(payload)} bytes)") from None
    if len(msg) != n or len(src) != k or len(payload) != 3 + n + k:
        raise RTDECodecError(f"text message length fields disagree with its {len(payload)} bytes")
    return TextMessage(msg.decode("utf-8", "replace"), src.decode("utf-8", "replace"), level)


# --------------------------------------------------------------------------- variables

_FIXED_TYPES: dict[str, str] = {
    # outputs (controller -> client)
    "timestamp": "DOUBLE",
    "target_q": "VECTOR6D",
    "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D",
    "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D",
    "actual_qd": "VECTOR6D",
    "actual_current": "VECTOR6D",
    "actual_current_window": "VECTOR6D",
    "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D",
    "actual_TCP_speed": "VECTOR6D",
    "actual_TCP_force": "VECTOR6D",
    "target_TCP_pose": "VECTOR6D",
    "target_TCP_speed": "VECTOR6D",
    "actual_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D",
    "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32",
    "elbow_position": "VECTOR3D",
    "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",
    "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "io_current": "DOUBLE",
    "euromap67_input_bits": "UINT32",
    "euromap67_output_bits": "UINT32",
    "euromap67_24V_voltage": "DOUBLE",
    "euromap67_24V_current": "DOUBLE",
    "tool_mode": "UINT32",
    "tool_analog_input_types": "UINT32",
    "tool_analog_input0": "DOUBLE",
    "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32",
    "tool_output_current": "DOUBLE",
    "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE",
    "output_bit_registers0_to_31": "UINT32",
    "output_bit_registers32_to_63": "UINT32",
    "ft_raw_wrench": "VECTOR6D",
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "payload_inertia": "VECTOR6D",
    "script_control_line": "UINT32",
    "tool_output_mode": "UINT8",
    "tool_digital_output0_mode": "UINT8",
    "tool_digital_output1_mode": "UINT8",
    # inputs (client -> controller)
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8",
    "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8",
    "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE",
    "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": "VECTOR6D",
}

_REGISTER = re.compile(r"^(input|output)_(int|double|bit)_register_(\d+)$")


def variable_type(name: str) -> str:
    """RTDE type of a variable name, or ``NOT_FOUND`` (what the controller answers).

    Registers: ``{input,output}_int_register_N`` INT32 and ``..._double_register_N``
    DOUBLE for N in 0..47, ``..._bit_register_N`` BOOL for N in 64..127.
    """
    t = _FIXED_TYPES.get(name)
    if t is not None:
        return t
    m = _REGISTER.match(name)
    if m is None:
        return NOT_FOUND
    kind, n = m.group(2), int(m.group(3))
    if kind == "bit":
        return "BOOL" if 64 <= n <= 127 else NOT_FOUND
    if n > 47:
        return NOT_FOUND
    return "INT32" if kind == "int" else "DOUBLE"
