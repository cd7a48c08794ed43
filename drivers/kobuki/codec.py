"""Kobuki serial protocol: pure functions over bytes (no I/O, no clocks).

Frame (both directions)::

    AA 55 | length | payload (length bytes: sub-payloads) | checksum

``checksum`` is the XOR of the length byte and every payload byte, so the XOR of
every byte after the two headers, checksum included, is 0. A sub-payload is
``id | len | data``; multi-byte fields are little-endian, signed fields two's
complement. See ``docs/protocols.md`` section 1.

This module provides:

* :func:`encode_frame` / :func:`checksum` and :class:`FrameParser`, a streaming
  parser that resynchronises after garbage, truncated or corrupted frames;
* :func:`decode_feedback`: every feedback sub-payload (ids 1, 3, 4, 5, 6, 10, 11,
  13, 16, 19, 21) into dataclasses in SI units where sensible; unknown ids are
  skipped by their length byte;
* command encoders (base control, sound, sound sequence, request extra, GP output,
  set / get controller gain) and :func:`decode_commands` for the device side;
* feedback encoders, used by the protocol fake (:mod:`mmexec.drivers.fakes.kobuki`);
* the vendor's (v, w) -> (speed, radius) conversion and its inverse;
* odometry from 16-bit wrapping encoder ticks and timestamps.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field

from mmexec.drivers.geometry import wrap_angle

__all__ = [
    "BASE_CONTROL",
    "BIAS",
    "CLIFF",
    "CONTROLLER_INFO",
    "CORE_SENSORS",
    "CURRENT",
    "FIRMWARE",
    "GET_GAIN",
    "GP_INPUT",
    "GP_OUTPUT",
    "GYRO",
    "HARDWARE",
    "HEADER",
    "MAX_PAYLOAD",
    "MIN_PAYLOAD",
    "REQUEST_EXTRA",
    "REQUEST_FIRMWARE",
    "REQUEST_HARDWARE",
    "REQUEST_UID",
    "SET_GAIN",
    "SOUND",
    "SOUND_SEQUENCE",
    "TICK_TO_RAD",
    "UNIQUE_ID",
    "WHEEL_RADIUS",
    "CliffSensors",
    "CodecError",
    "Command",
    "ControllerInfo",
    "CoreSensors",
    "DockInfrared",
    "Feedback",
    "FrameParser",
    "GpInput",
    "Inertia",
    "Odometry",
    "OdometryStep",
    "ThreeAxisGyro",
    "Version",
    "WheelCurrent",
    "base_control",
    "checksum",
    "decode_commands",
    "decode_feedback",
    "encode_cliff",
    "encode_controller_info",
    "encode_core_sensors",
    "encode_current",
    "encode_dock_ir",
    "encode_frame",
    "encode_gp_input",
    "encode_gyro",
    "encode_inertia",
    "encode_unique_id",
    "encode_version",
    "get_controller_gain",
    "gp_output",
    "request_extra",
    "set_controller_gain",
    "sound",
    "sound_sequence",
    "speed_radius_to_wheels",
    "split_subpayloads",
    "subpayload",
    "velocity_to_speed_radius",
    "wrap_diff16",
]

HEADER = b"\xaa\x55"
#: smallest legal payload: one sub-payload header plus one data byte
MIN_PAYLOAD = 3
#: the length field is one byte; the vendor driver's buffer is 256 bytes
MAX_PAYLOAD = 255

# feedback sub-payload ids (robot -> host)
CORE_SENSORS = 1
DOCK_IR = 3
INERTIA = 4
CLIFF = 5
CURRENT = 6
HARDWARE = 10
FIRMWARE = 11
GYRO = 13
GP_INPUT = 16
UNIQUE_ID = 19
CONTROLLER_INFO = 21

# command sub-payload ids (host -> robot)
BASE_CONTROL = 1
SOUND = 3
SOUND_SEQUENCE = 4
REQUEST_EXTRA = 9
GP_OUTPUT = 12
SET_GAIN = 13
GET_GAIN = 14

# request extra flags
REQUEST_HARDWARE = 0x01
REQUEST_FIRMWARE = 0x02
REQUEST_UID = 0x08

# geometry (docs/protocols.md 1.5)
WHEEL_RADIUS = 0.035  # m
BIAS = 0.230  # m, wheel separation
TICK_TO_RAD = 0.002436916871363930  # rad of wheel per encoder tick

_INT16_MIN, _INT16_MAX = -32768, 32767


class CodecError(ValueError):
    """Malformed bytes: bad frame, sub-payload overrunning its frame, wrong length."""


# --------------------------------------------------------------------------- framing


def checksum(body: bytes) -> int:
    """XOR of ``body`` (the length byte followed by the payload)."""
    c = 0
    for b in body:
        c ^= b
    return c


def subpayload(sub_id: int, data: bytes) -> bytes:
    """``id | len | data`` (``len(data)`` must fit in a byte)."""
    if not 0 <= sub_id <= 255 or len(data) > 253:
        raise CodecError(f"sub-payload id {sub_id} with {len(data)} data bytes does not fit a frame")
    return bytes((sub_id, len(data))) + data


def encode_frame(*subpayloads: bytes) -> bytes:
    """A complete frame ``AA 55 len payload checksum`` from encoded sub-payloads."""
    payload = b"".join(subpayloads)
    if not MIN_PAYLOAD <= len(payload) <= MAX_PAYLOAD:
        raise CodecError(f"payload of {len(payload)} bytes outside {MIN_PAYLOAD}..{MAX_PAYLOAD}")
    body = bytes((len(payload),)) + payload
    return HEADER + body + bytes((checksum(body),))


class FrameParser:
    """Streaming frame finder: :meth:`feed` bytes as they arrive, get whole payloads.

    Scans for ``AA 55``, rejects lengths below :data:`MIN_PAYLOAD`, waits for the whole
    frame, and checks the checksum. On any rejection it drops only the first header
    byte and rescans, so a valid frame hidden after garbage or after a truncated frame
    is still found. Counters tell what was thrown away.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        #: frames accepted
        self.frames = 0
        #: frames rejected for a bad checksum
        self.bad_checksum = 0
        #: frames rejected for an impossible length
        self.bad_length = 0
        #: bytes discarded while looking for a header
        self.discarded = 0

    def reset(self) -> None:
        self._buf.clear()

    @property
    def pending(self) -> int:
        """Bytes buffered but not yet resolved into a frame."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytes]:
        """Add ``data``; return the payloads of every complete valid frame now available."""
        buf = self._buf
        buf += data
        out: list[bytes] = []
        while True:
            start = buf.find(HEADER)
            if start < 0:
                # keep a trailing AA: it may be the first half of a header
                keep = 1 if buf and buf[-1] == 0xAA else 0
                self.discarded += len(buf) - keep
                del buf[: len(buf) - keep]
                return out
            if start:
                self.discarded += start
                del buf[:start]
            if len(buf) < 3:
                return out
            length = buf[2]
            if length < MIN_PAYLOAD:
                self.bad_length += 1
                self.discarded += 1
                del buf[:1]
                continue
            total = 2 + 1 + length + 1
            if len(buf) < total:
                return out
            body = bytes(buf[2 : total - 1])
            if checksum(body) != buf[total - 1]:
                self.bad_checksum += 1
                self.discarded += 1
                del buf[:1]
                continue
            out.append(body[1:])
            self.frames += 1
            del buf[:total]


def split_subpayloads(payload: bytes) -> list[tuple[int, bytes]]:
    """``[(id, data), ...]`` in order; :class:`CodecError` if one overruns the payload."""
    out: list[tuple[int, bytes]] = []
    i, n = 0, len(payload)
    while i < n:
        if i + 2 > n:
            raise CodecError(f"sub-payload header truncated at offset {i} of {n}")
        sub_id, sub_len = payload[i], payload[i + 1]
        if i + 2 + sub_len > n:
            raise CodecError(f"sub-payload id {sub_id} claims {sub_len} bytes, only {n - i - 2} left")
        out.append((sub_id, bytes(payload[i + 2 : i + 2 + sub_len])))
        i += 2 + sub_len
    return out


# --------------------------------------------------------------------------- feedback


@dataclass(frozen=True)
class CoreSensors:
    """Basic sensor data (id 1). Bit fields are raw; the properties name them.

    ``timestamp_ms`` wraps at 65536; encoders are raw wrapping uint16 ticks;
    ``battery`` [V]; ``pwm_*`` raw int8 duty (negative = backwards).
    """

    timestamp_ms: int
    bumper: int
    wheel_drop: int
    cliff: int
    left_encoder: int
    right_encoder: int
    left_pwm: int
    right_pwm: int
    buttons: int
    charger: int
    battery: float
    overcurrent: int

    @property
    def faults(self) -> frozenset[str]:
        """Named safety conditions now active (bumper, cliff, wheel drop, overcurrent)."""
        names: set[str] = set()
        for bit, side in ((0x01, "right"), (0x02, "centre"), (0x04, "left")):
            if self.bumper & bit:
                names.add(f"bumper_{side}")
            if self.cliff & bit:
                names.add(f"cliff_{side}")
        for bit, side in ((0x01, "right"), (0x02, "left")):
            if self.wheel_drop & bit:
                names.add(f"wheel_drop_{side}")
        # overcurrent uses the opposite bit order: 0x01 left, 0x02 right
        for bit, side in ((0x01, "left"), (0x02, "right")):
            if self.overcurrent & bit:
                names.add(f"overcurrent_{side}")
        return frozenset(names)

    @property
    def charging_state(self) -> str:
        """``discharging``, ``charged`` or ``charging`` (low nibble of the charger byte)."""
        return {0: "discharging", 2: "charged", 6: "charging"}.get(self.charger & 0x0F, f"unknown({self.charger & 0x0F})")

    @property
    def charge_source(self) -> str:
        """``adapter`` or ``dock`` (bit 0x10), meaningful only while charging or charged."""
        return "adapter" if self.charger & 0x10 else "dock"


@dataclass(frozen=True)
class DockInfrared:
    """Docking IR (id 3): one bit field per receiver (right, centre, left)."""

    right: int
    centre: int
    left: int


@dataclass(frozen=True)
class Inertia:
    """Factory-calibrated z gyro (id 4): ``heading`` [rad] in (-pi, pi], ``rate`` [rad/s]."""

    heading: float
    rate: float


@dataclass(frozen=True)
class CliffSensors:
    """Cliff PSD ADC readings (id 5), raw 0..4095 (right, centre, left)."""

    right: int
    centre: int
    left: int

    def volts(self) -> tuple[float, float, float]:
        """(right, centre, left) [V], 0..3.3 V."""
        return tuple(x * 3.3 / 4095.0 for x in (self.right, self.centre, self.left))  # type: ignore[return-value]


@dataclass(frozen=True)
class WheelCurrent:
    """Wheel motor current (id 6) [A] (left, right); 10 mA resolution."""

    left: float
    right: float


@dataclass(frozen=True, order=True)
class Version:
    """Hardware (id 10) or firmware (id 11) version."""

    major: int
    minor: int
    patch: int

    def __str__(self) -> str:
        return f"{self.major}.{self.minor}.{self.patch}"


@dataclass(frozen=True)
class ThreeAxisGyro:
    """Raw gyro samples (id 13) rotated into the robot frame, each (x, y, z) [rad/s]."""

    frame_id: int
    samples: tuple[tuple[float, float, float], ...]


@dataclass(frozen=True)
class GpInput:
    """General purpose inputs (id 16): digital bits 0-3, four analog inputs [V]."""

    digital: int
    analog: tuple[float, float, float, float]


@dataclass(frozen=True)
class ControllerInfo:
    """Wheel controller gains (id 21): ``user`` False for factory gains."""

    user: bool
    kp: float
    ki: float
    kd: float


@dataclass(frozen=True)
class Feedback:
    """One decoded feedback frame: a field per sub-payload present, None when absent."""

    core: CoreSensors | None = None
    dock_ir: DockInfrared | None = None
    inertia: Inertia | None = None
    cliff: CliffSensors | None = None
    current: WheelCurrent | None = None
    hardware: Version | None = None
    firmware: Version | None = None
    gyro: ThreeAxisGyro | None = None
    gp_input: GpInput | None = None
    unique_id: tuple[int, int, int] | None = None
    controller: ControllerInfo | None = None
    #: ids found in the frame that this decoder does not know (skipped)
    unknown_ids: tuple[int, ...] = ()


_GYRO_LSB = math.radians(0.00875)  # rad/s per digit
_FIXED_LEN = {
    CORE_SENSORS: 15,
    DOCK_IR: 3,
    INERTIA: 7,
    CLIFF: 6,
    CURRENT: 2,
    HARDWARE: 4,
    FIRMWARE: 4,
    GP_INPUT: 16,
    UNIQUE_ID: 12,
    CONTROLLER_INFO: 13,
}


def decode_feedback(payload: bytes) -> Feedback:
    """Decode every sub-payload of a feedback frame (see :class:`Feedback`).

    Raises :class:`CodecError` when a sub-payload overruns the frame or a known id has
    the wrong length ("malformed sub-payload"). Unknown ids are skipped by length.
    """
    fields: dict[str, object] = {}
    unknown: list[int] = []
    for sub_id, d in split_subpayloads(payload):
        want = _FIXED_LEN.get(sub_id)
        if want is not None and len(d) != want:
            raise CodecError(f"malformed sub-payload id {sub_id}: {len(d)} bytes, expected {want}")
        if sub_id == CORE_SENSORS:
            ts, bump, drop, cliff, le, re, lp, rp, btn, chg, bat, oc = struct.unpack("<HBBBHHbbBBBB", d)
            fields["core"] = CoreSensors(ts, bump, drop, cliff, le, re, lp, rp, btn, chg, bat / 10.0, oc)
        elif sub_id == DOCK_IR:
            fields["dock_ir"] = DockInfrared(d[0], d[1], d[2])
        elif sub_id == INERTIA:
            angle, rate = struct.unpack_from("<hh", d)
            fields["inertia"] = Inertia(wrap_angle(math.radians(angle / 100.0)), math.radians(rate / 100.0))
        elif sub_id == CLIFF:
            fields["cliff"] = CliffSensors(*struct.unpack("<HHH", d))
        elif sub_id == CURRENT:
            fields["current"] = WheelCurrent(d[0] * 0.01, d[1] * 0.01)
        elif sub_id in (HARDWARE, FIRMWARE):
            patch, minor, major, _zero = d
            fields["hardware" if sub_id == HARDWARE else "firmware"] = Version(major, minor, patch)
        elif sub_id == GYRO:
            if len(d) < 2:
                raise CodecError(f"malformed sub-payload id {GYRO}: {len(d)} bytes, expected 2 + 6N")
            frame_id, count = d[0], d[1]
            if count % 3 or len(d) != 2 + 2 * count:
                raise CodecError(f"malformed sub-payload id {GYRO}: count {count} does not match {len(d)} bytes")
            raw = struct.unpack_from(f"<{count}H", d, 2)
            samples = []
            for k in range(0, count, 3):
                rx, ry, rz = (r - 65536 if r >= 32768 else r for r in raw[k : k + 3])
                # sensor axes rotated: robot x = -raw y, robot y = raw x, robot z = raw z
                samples.append((-ry * _GYRO_LSB, rx * _GYRO_LSB, rz * _GYRO_LSB))
            fields["gyro"] = ThreeAxisGyro(frame_id, tuple(samples))
        elif sub_id == GP_INPUT:
            vals = struct.unpack("<8H", d)
            fields["gp_input"] = GpInput(
                vals[0] & 0x0F, tuple(v * 3.3 / 4095.0 for v in vals[1:5])  # type: ignore[arg-type]
            )
        elif sub_id == UNIQUE_ID:
            fields["unique_id"] = struct.unpack("<III", d)
        elif sub_id == CONTROLLER_INFO:
            kind, p, i, dd = struct.unpack("<BIII", d)
            fields["controller"] = ControllerInfo(kind == 1, p / 1000.0, i / 1000.0, dd / 1000.0)
        else:
            unknown.append(sub_id)
    return Feedback(unknown_ids=tuple(unknown), **fields)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- feedback encoders (fake side)


def encode_core_sensors(s: CoreSensors) -> bytes:
    """Sub-payload id 1 from :class:`CoreSensors` (battery rounded to 0.1 V)."""
    return subpayload(
        CORE_SENSORS,
        struct.pack(
            "<HBBBHHbbBBBB",
            s.timestamp_ms & 0xFFFF,
            s.bumper,
            s.wheel_drop,
            s.cliff,
            s.left_encoder & 0xFFFF,
            s.right_encoder & 0xFFFF,
            s.left_pwm,
            s.right_pwm,
            s.buttons,
            s.charger,
            max(0, min(255, round(s.battery * 10))),
            s.overcurrent,
        ),
    )


def encode_dock_ir(ir: DockInfrared) -> bytes:
    return subpayload(DOCK_IR, bytes((ir.right, ir.centre, ir.left)))


def _clamp16(x: float) -> int:
    return max(_INT16_MIN, min(_INT16_MAX, round(x)))


def encode_inertia(heading: float, rate: float) -> bytes:
    """Sub-payload id 4 from ``heading`` [rad] and ``rate`` [rad/s]."""
    h = _clamp16(math.degrees(wrap_angle(heading)) * 100.0)
    r = _clamp16(math.degrees(rate) * 100.0)
    return subpayload(INERTIA, struct.pack("<hh", h, r) + b"\x00\x00\x00")


def encode_cliff(c: CliffSensors) -> bytes:
    return subpayload(CLIFF, struct.pack("<HHH", c.right, c.centre, c.left))


def encode_current(left: float, right: float) -> bytes:
    """Sub-payload id 6 from currents [A]."""
    return subpayload(CURRENT, bytes(max(0, min(255, round(a * 100))) for a in (left, right)))


def encode_version(sub_id: int, v: Version) -> bytes:
    """Sub-payload id 10 (hardware) or 11 (firmware)."""
    return subpayload(sub_id, bytes((v.patch, v.minor, v.major, 0)))


def encode_gyro(frame_id: int, samples: Iterable[tuple[float, float, float]]) -> bytes:
    """Sub-payload id 13 from robot-frame rates (x, y, z) [rad/s]."""
    raw: list[int] = []
    for x, y, z in samples:
        # inverse of the decoder's rotation: raw x = robot y, raw y = -robot x
        for v in (y, -x, z):
            raw.append(_clamp16(v / _GYRO_LSB) & 0xFFFF)
    return subpayload(GYRO, bytes((frame_id & 0xFF, len(raw))) + struct.pack(f"<{len(raw)}H", *raw))


def encode_gp_input(g: GpInput) -> bytes:
    analog = [max(0, min(4095, round(v / 3.3 * 4095))) for v in g.analog]
    return subpayload(GP_INPUT, struct.pack("<8H", g.digital & 0x0F, *analog, 0, 0, 0))


def encode_unique_id(uid: tuple[int, int, int]) -> bytes:
    return subpayload(UNIQUE_ID, struct.pack("<III", *uid))


def encode_controller_info(c: ControllerInfo) -> bytes:
    return subpayload(
        CONTROLLER_INFO,
        struct.pack("<BIII", 1 if c.user else 0, round(c.kp * 1000), round(c.ki * 1000), round(c.kd * 1000)),
    )


# --------------------------------------------------------------------------- commands


def base_control(speed_mm_s: int, radius_mm: int) -> bytes:
    """Sub-payload id 1: ``speed`` [mm/s] and ``radius`` [mm], each clamped to int16."""
    return subpayload(BASE_CONTROL, struct.pack("<hh", _clamp16(speed_mm_s), _clamp16(radius_mm)))


def sound(frequency_hz: float, duration_ms: int) -> bytes:
    """Sub-payload id 3: a tone; note = 1 / (f * 2.75e-6), duration 0..255 ms."""
    if frequency_hz <= 0:
        raise CodecError(f"sound frequency must be > 0 Hz, got {frequency_hz}")
    note = max(0, min(0xFFFF, round(1.0 / (frequency_hz * 2.75e-6))))
    return subpayload(SOUND, struct.pack("<HB", note, max(0, min(255, int(duration_ms)))))


def sound_sequence(sequence: int) -> bytes:
    """Sub-payload id 4: 0 on, 1 off, 2 recharge, 3 button, 4 error, 5/6 cleaning start/end."""
    if not 0 <= sequence <= 6:
        raise CodecError(f"sound sequence must be 0..6, got {sequence}")
    return subpayload(SOUND_SEQUENCE, bytes((sequence,)))


def request_extra(flags: int) -> bytes:
    """Sub-payload id 9: :data:`REQUEST_HARDWARE` | :data:`REQUEST_FIRMWARE` | :data:`REQUEST_UID`."""
    return subpayload(REQUEST_EXTRA, struct.pack("<H", flags & 0xFFFF))


def gp_output(bits: int) -> bytes:
    """Sub-payload id 12: all 16 output bits (digital outputs, power rails, LEDs)."""
    return subpayload(GP_OUTPUT, struct.pack("<H", bits & 0xFFFF))


def set_controller_gain(user: bool, kp: float, ki: float, kd: float) -> bytes:
    """Sub-payload id 13: gains (each sent x1000); ``user`` False restores factory gains."""
    return subpayload(
        SET_GAIN, struct.pack("<BIII", 1 if user else 0, round(kp * 1000), round(ki * 1000), round(kd * 1000))
    )


def get_controller_gain() -> bytes:
    """Sub-payload id 14 (one reserved zero byte)."""
    return subpayload(GET_GAIN, b"\x00")


@dataclass(frozen=True)
class Command:
    """A decoded host command (device side): ``kind`` names it, ``values`` its fields."""

    kind: str
    values: tuple[int | float | bool, ...] = field(default_factory=tuple)


_CMD_LEN = {BASE_CONTROL: 4, SOUND: 3, SOUND_SEQUENCE: 1, REQUEST_EXTRA: 2, GP_OUTPUT: 2, SET_GAIN: 13, GET_GAIN: 1}


def decode_commands(payload: bytes) -> list[Command]:
    """Commands in a host frame. Unknown ids become ``Command("unknown", (id,))``.

    Kinds and values: ``base_control`` (speed mm/s, radius mm), ``sound`` (note, ms),
    ``sound_sequence`` (n,), ``request_extra`` (flags,), ``gp_output`` (bits,),
    ``set_gain`` (user, kp, ki, kd), ``get_gain`` ().
    """
    out: list[Command] = []
    for sub_id, d in split_subpayloads(payload):
        want = _CMD_LEN.get(sub_id)
        if want is None:
            out.append(Command("unknown", (sub_id,)))
            continue
        if len(d) != want:
            raise CodecError(f"malformed command id {sub_id}: {len(d)} bytes, expected {want}")
        if sub_id == BASE_CONTROL:
            out.append(Command("base_control", struct.unpack("<hh", d)))
        elif sub_id == SOUND:
            out.append(Command("sound", struct.unpack("<HB", d)))
        elif sub_id == SOUND_SEQUENCE:
            out.append(Command("sound_sequence", (d[0],)))
        elif sub_id == REQUEST_EXTRA:
            out.append(Command("request_extra", struct.unpack("<H", d)))
        elif sub_id == GP_OUTPUT:
            out.append(Command("gp_output", struct.unpack("<H", d)))
        elif sub_id == SET_GAIN:
            kind, p, i, dd = struct.unpack("<BIII", d)
            out.append(Command("set_gain", (kind == 1, p / 1000.0, i / 1000.0, dd / 1000.0)))
        else:
            out.append(Command("get_gain", ()))
    return out


# --------------------------------------------------------------------------- velocity conversion


def velocity_to_speed_radius(v: float, w: float) -> tuple[int, int]:
    """(v [m/s], w [rad/s]) to the firmware's (speed [mm/s], radius [mm]), vendor rules:

    1. ``|w| < 1e-4``: straight, radius 0, speed = 1000 v;
    2. radius = 1000 v / w; if ``|v| < 1e-4`` or ``|radius| <= 1`` after rounding to
       whole mm (a radius of 1.3 mm sent as 1 would be the marker): pure rotation,
       radius = 1 (a marker), speed = 1000 * 0.230 * w / 2 (positive = CCW);
    3. else speed = (radius + 115) w for radius > 0, (radius - 115) w otherwise
       (the outer wheel's speed; positive radius turns left).

    Both results are rounded to the nearest integer and clamped to int16.
    """
    eps = 1e-4
    if abs(w) < eps:
        return _clamp16(1000.0 * v), 0
    radius = 1000.0 * v / w
    if abs(v) < eps or abs(round(radius)) <= 1:
        return _clamp16(1000.0 * BIAS * w / 2.0), 1
    half = 1000.0 * BIAS / 2.0
    speed = (radius + half) * w if radius > 0 else (radius - half) * w
    return _clamp16(speed), _clamp16(radius)


def speed_radius_to_wheels(speed: int, radius: int) -> tuple[float, float]:
    """Inverse mapping for a fake base: (left, right) wheel speeds [mm/s].

    radius 0: both = speed; radius 1: right = +speed, left = -speed; R > 1:
    w = speed / (R + 115), right = speed, left = w (R - 115); R < -1:
    w = speed / (R - 115), left = speed, right = w (R + 115). (radius -1 is treated
    like a pure rotation as well: the firmware's behaviour there is unpublished.)
    """
    half = 1000.0 * BIAS / 2.0
    if radius == 0:
        return float(speed), float(speed)
    if radius in (1, -1):
        return -float(speed), float(speed)
    if radius > 1:
        w = speed / (radius + half)
        return w * (radius - half), float(speed)
    w = speed / (radius - half)
    return float(speed), w * (radius + half)


# --------------------------------------------------------------------------- odometry


def wrap_diff16(new: int, old: int) -> int:
    """Signed difference of two wrapping uint16 counters: ``(new - old)`` as int16."""
    d = (new - old) & 0xFFFF
    return d - 0x10000 if d >= 0x8000 else d


@dataclass(frozen=True)
class OdometryStep:
    """One odometry update: pose increment in the previous base frame and measured rates.

    ``dx``, ``dy`` [m] and ``dtheta`` [rad] are in the base frame at the previous
    reading; ``dt`` [s] from the firmware timestamp; ``v`` [m/s], ``w`` [rad/s].
    """

    dx: float
    dy: float
    dtheta: float
    dt: float
    v: float
    w: float


class Odometry:
    """Differential-drive odometry from raw wrapping encoder ticks (pure, no I/O).

    ``x``, ``y`` [m] and ``theta`` [rad] are in the odometry frame, starting at the
    given pose. With ``heading`` passed to :meth:`update` (the gyro's, zeroed at its
    first reading) theta follows the gyro and only the distance comes from the wheels.
    """

    def __init__(self, x: float = 0.0, y: float = 0.0, theta: float = 0.0) -> None:
        self.x, self.y, self.theta = x, y, theta
        self._theta0 = theta
        self._last: tuple[int, int, int] | None = None
        self._gyro0: float | None = None

    def reset(self, x: float = 0.0, y: float = 0.0, theta: float = 0.0) -> None:
        """Set the pose; the next reading continues from the last ticks (no jump)."""
        self.x, self.y, self.theta = x, y, theta
        self._theta0 = theta
        self._gyro0 = None

    def update(self, left: int, right: int, timestamp_ms: int, heading: float | None = None) -> OdometryStep:
        """Integrate one reading of raw ticks and firmware time; first call only primes."""
        last, self._last = self._last, (left, right, timestamp_ms)
        if heading is not None and self._gyro0 is None:
            self._gyro0 = heading - (self.theta - self._theta0)
        if last is None:
            return OdometryStep(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        dl = wrap_diff16(left, last[0]) * TICK_TO_RAD * WHEEL_RADIUS
        dr = wrap_diff16(right, last[1]) * TICK_TO_RAD * WHEEL_RADIUS
        dt = ((timestamp_ms - last[2]) & 0xFFFF) / 1000.0
        ds = (dl + dr) / 2.0
        if heading is not None and self._gyro0 is not None:
            new_theta = wrap_angle(self._theta0 + heading - self._gyro0)
            dth = wrap_angle(new_theta - self.theta)
        else:
            dth = (dr - dl) / BIAS
            new_theta = wrap_angle(self.theta + dth)
        mid = self.theta + dth / 2.0
        self.x += ds * math.cos(mid)
        self.y += ds * math.sin(mid)
        self.theta = new_theta
        v = ds / dt if dt > 0 else 0.0
        w = dth / dt if dt > 0 else 0.0
        return OdometryStep(ds * math.cos(dth / 2.0), ds * math.sin(dth / 2.0), dth, dt, v, w)
