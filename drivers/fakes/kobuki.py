"""A Kobuki base that speaks the real serial protocol on a pseudo-terminal.

Use it to test the driver and to rehearse bring-up without a robot::

    with KobukiFake() as fake:            # starts streaming at 50 Hz
        base = KobukiDevice(KobukiConfig(port=fake.port))
        ...
        fake.set_sensors(bumper=0x04)     # press the left bumper (raw bits, section 1.4)
        fake.set_fault("cliff_centre")    # the same by name
        fake.corrupt_next(3)              # next 3 frames with a wrong checksum
        fake.corrupt_stream()             # every frame from now on (until corrupt_stream(False))
        fake.mute = True                  # stops streaming but still obeys commands

or from a shell: ``mmexec hw fake kobuki`` prints the port and serves until Ctrl-C.

What it does (docs/protocols.md 1.6):

* every 20 ms of fake time emits a frame with sub-payloads 1, 3, 4, 5, 6, 13, 16: a
  millisecond timestamp, wrapping uint16 encoders driven by the last Base Control
  command through the inverse speed/radius mapping, and a gyro heading consistent
  with the wheels;
* answers Request Extra with ids 10 / 11 / 19 and Get Controller Gain with id 21 in
  the next frame; records Sound, Sound Sequence, GP output (LED state) and Set
  Controller Gain;
* ignores and counts command frames with a bad checksum;
* lets tests set bumper, cliff, wheel-drop, buttons, charger, battery and overcurrent,
  as raw bits (:meth:`set_sensors`) or by name (:meth:`set_fault`, bit table
  :data:`SAFETY_BITS` from section 1.4);
* fault injection: wrong checksum (:meth:`corrupt_next`, or the whole stream with
  :meth:`corrupt_stream`), stray bytes before the header, truncated frames, dropped
  frames (:meth:`drop_next`: stamped and never sent, so the host sees a timestamp gap),
  unknown sub-payload ids, encoder and timestamp values near wrap-around, any firmware
  version (e.g. major 2), and three kinds of silence:

  - :attr:`mute`: the robot stops streaming but still hears and obeys commands (its
    transmit line or its streaming died); it keeps moving on its last command;
  - :attr:`silent` (from :class:`~mmexec.drivers.fakes.pty.PtyDevice`): powered off,
    neither streams nor hears;
  - :meth:`unplug`: the cable is pulled (the host's port fails with EIO); with a ``link``
    path (like the vendor udev rule's ``/dev/kobuki``) the path disappears too, and
    :meth:`replug` plugs it back in: a new pty behind the same path, the robot still
    driving on its last command.

Like the real firmware (safety controller disabled since 1.1.2), the fake keeps
driving on its last command; stopping on bumpers or a lost host is the driver's job.
Fake time advances 20 ms per frame, independent of how late the frame is sent.
"""

from __future__ import annotations

import logging
import math
import os
import threading
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Self

from mmexec.drivers.fakes.pty import PtyDevice
from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.kobuki import codec as k

__all__ = ["SAFETY_BITS", "FakeKobukiState", "KobukiFake"]

log = logging.getLogger(__name__)

_TICKS_PER_MM = 1.0 / (k.TICK_TO_RAD * k.WHEEL_RADIUS * 1000.0)

#: Safety conditions in the basic sensor data (id 1) as docs/protocols.md 1.4 lays them
#: out, written from that table (not from the driver's codec): name -> (field, bit).
#: Overcurrent has the opposite bit order to bumper and wheel drop (0x01 is the left wheel).
SAFETY_BITS: dict[str, tuple[str, int]] = {
    "bumper_right": ("bumper", 0x01),
    "bumper_centre": ("bumper", 0x02),
    "bumper_left": ("bumper", 0x04),
    "wheel_drop_right": ("wheel_drop", 0x01),
    "wheel_drop_left": ("wheel_drop", 0x02),
    "cliff_right": ("cliff", 0x01),
    "cliff_centre": ("cliff", 0x02),
    "cliff_left": ("cliff", 0x04),
    "overcurrent_left": ("overcurrent", 0x01),
    "overcurrent_right": ("overcurrent", 0x02),
}


@dataclass
class FakeKobukiState:
    """What the fake robot is doing and what the host asked of it (for assertions)."""

    timestamp_ms: int = 0
    left_encoder: float = 0.0       # ticks, kept as float; sent wrapped to uint16
    right_encoder: float = 0.0
    heading: float = 0.0            # rad, gyro
    x: float = 0.0                  # m, true pose of the fake base in its start frame
    y: float = 0.0
    speed: int = 0                  # last Base Control speed [mm/s]
    radius: int = 0                 # last Base Control radius [mm]
    bumper: int = 0
    wheel_drop: int = 0
    cliff: int = 0
    buttons: int = 0
    charger: int = 0
    battery: float = 16.5           # V
    overcurrent: int = 0
    firmware: k.Version = field(default_factory=lambda: k.Version(1, 2, 0))
    hardware: k.Version = field(default_factory=lambda: k.Version(1, 0, 4))
    unique_id: tuple[int, int, int] = (0x0A0B0C0D, 0x11223344, 0x55667788)
    gains: k.ControllerInfo = field(default_factory=lambda: k.ControllerInfo(False, 100.0, 0.1, 2.0))
    gp_output: int = 0x00F0
    sounds: list[tuple[int, int]] = field(default_factory=list)
    sound_sequences: list[int] = field(default_factory=list)
    base_control_frames: int = 0
    moving_commands: int = 0        # Base Control frames with a non-zero speed
    bad_command_frames: int = 0
    malformed_command_frames: int = 0
    requests: list[int] = field(default_factory=list)
    frames_sent: int = 0            # feedback frames written to the port (corrupt ones included)
    frames_corrupted: int = 0       # of which sent with a wrong checksum or truncated
    frames_dropped: int = 0         # stamped but never sent (drop_next, mute)

    @property
    def frames_stepped(self) -> int:
        """20 ms steps of fake time so far (frames sent or dropped)."""
        return self.frames_sent + self.frames_dropped

    @property
    def leds(self) -> dict[str, str]:
        """LED colours from the GP output bits: ``off``, ``red``, ``green`` or ``orange``."""
        out = {}
        for name, red, green in (("led1", 0x0100, 0x0200), ("led2", 0x0400, 0x0800)):
            r, g = bool(self.gp_output & red), bool(self.gp_output & green)
            out[name] = "orange" if r and g else "red" if r else "green" if g else "off"
        return out


def _every(n: int) -> int:
    if n < 1:
        raise ValueError(f"every must be >= 1 (one frame in every n), got {n}")
    return n


class KobukiFake(PtyDevice):
    """Kobuki protocol fake on a pty (see module doc). Thread-safe setters."""

    tick_period = 0.02

    def __init__(self, *, firmware: tuple[int, int, int] = (1, 2, 0), name: str = "kobuki-fake",
                 link: str | os.PathLike[str] | None = None) -> None:
        """``link``: a path kept as a symlink to the pty while plugged in (what the vendor
        udev rule does with ``/dev/kobuki``); :attr:`port` is then that path, and it survives
        :meth:`unplug` / :meth:`replug`. Without it :attr:`port` is the pty itself."""
        super().__init__(name)
        self.state = FakeKobukiState(firmware=k.Version(*firmware))
        self.mute = False
        self._link = Path(link) if link is not None else None
        self._parser = k.FrameParser()
        self._pending_extra = 0
        self._pending_gain = False
        self._corrupt = 0
        self._corrupt_every = 0     # corrupt one frame in this many (0: off)
        self._drop = 0
        self._drop_every = 0        # drop one frame in this many (0: off)
        self._truncate = 0
        self._stray = b""
        self._unknown = 0
        self._gyro_frame = 0
        self._mutex = threading.RLock()

    # ------------------------------------------------------------------ plugging
    @property
    def port(self) -> str:
        """The path for the driver to open: the ``link`` path if one was given, else the pty."""
        if self._link is not None:
            return str(self._link)
        return self.pty_path

    @property
    def pty_path(self) -> str:
        """The pty slave behind :attr:`port` (changes on :meth:`replug`)."""
        return PtyDevice.port.fget(self)  # type: ignore[attr-defined,no-any-return]

    def start(self) -> Self:
        super().start()
        if self._link is not None:
            tmp = self._link.with_name(f".{self._link.name}.{os.getpid()}.tmp")
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(self.pty_path)
            tmp.replace(self._link)
        return self

    def stop(self) -> None:
        super().stop()
        self._remove_link()

    def unplug(self) -> None:
        """Pull the cable: the host's port fails, and the ``link`` path (if any) disappears."""
        super().unplug()
        self._remove_link()

    def replug(self) -> None:
        """Plug the cable back in after :meth:`unplug`: a new pty behind the same ``link``
        path. The robot state (pose, last command, sensors) is kept."""
        if self._link is None:
            raise RuntimeError(f"{self.name}: replug() needs a link path (KobukiFake(link=...))")
        super().stop()  # joins the I/O thread unplug() ended
        with self._mutex:
            self._parser = k.FrameParser()
        self.start()

    def _remove_link(self) -> None:
        if self._link is not None and self._link.is_symlink():
            self._link.unlink(missing_ok=True)

    # ------------------------------------------------------------------ test controls
    def set_sensors(self, **values: object) -> None:
        """Set sensor fields of :class:`FakeKobukiState` (bumper=0x04, battery=15.0, ...)."""
        allowed = {"bumper", "wheel_drop", "cliff", "buttons", "charger", "battery", "overcurrent"}
        bad = set(values) - allowed
        if bad:
            raise ValueError(f"unknown sensor field(s) {sorted(bad)}; expected some of {sorted(allowed)}")
        with self._mutex:
            self.state = replace(self.state, **values)  # type: ignore[arg-type]

    def set_fault(self, name: str, active: bool = True) -> None:
        """Raise (or clear) one safety condition by name: ``bumper_left``, ``cliff_centre``,
        ``wheel_drop_right``, ``overcurrent_left``, ... (see :data:`SAFETY_BITS`)."""
        if name not in SAFETY_BITS:
            raise ValueError(f"unknown Kobuki fault {name!r}; expected one of {sorted(SAFETY_BITS)}")
        fld, bit = SAFETY_BITS[name]
        with self._mutex:
            bits = getattr(self.state, fld)
            setattr(self.state, fld, (bits | bit) if active else (bits & ~bit))

    def set_counters(self, *, encoders: int | None = None, timestamp_ms: int | None = None) -> None:
        """Jump both encoders and / or the timestamp (e.g. to 65530 to test wrap-around)."""
        with self._mutex:
            if encoders is not None:
                self.state.left_encoder = self.state.right_encoder = float(encoders)
            if timestamp_ms is not None:
                self.state.timestamp_ms = timestamp_ms

    def set_firmware(self, major: int, minor: int, patch: int) -> None:
        with self._mutex:
            self.state.firmware = k.Version(major, minor, patch)

    def corrupt_next(self, n: int = 1) -> None:
        """Send the next ``n`` frames with a wrong checksum."""
        with self._mutex:
            self._corrupt += n

    def corrupt_stream(self, on: bool = True, *, every: int = 1) -> None:
        """From now on send one frame in every ``every`` (1: all of them) with a wrong
        checksum (noise, wrong baud rate, a failing cable), until ``corrupt_stream(False)``.
        The robot still hears commands."""
        with self._mutex:
            self._corrupt_every = _every(every) if on else 0

    def drop_next(self, n: int = 1) -> None:
        """Stamp the next ``n`` frames but do not send them (lost on the wire)."""
        with self._mutex:
            self._drop += n

    def drop_stream(self, on: bool = True, *, every: int = 1) -> None:
        """From now on stamp but do not send one frame in every ``every``, until
        ``drop_stream(False)`` (``every=1`` is :attr:`mute`)."""
        with self._mutex:
            self._drop_every = _every(every) if on else 0

    def truncate_next(self, n: int = 1) -> None:
        """Send only the first half of the next ``n`` frames."""
        with self._mutex:
            self._truncate += n

    def stray_bytes(self, data: bytes = b"\x00\xaa\x13\x55\xaa") -> None:
        """Send ``data`` just before the next frame's header."""
        with self._mutex:
            self._stray += data

    def unknown_subpayload_next(self, n: int = 1) -> None:
        """Append a sub-payload with an unknown id (0x30) to the next ``n`` frames."""
        with self._mutex:
            self._unknown += n

    def snapshot(self) -> FakeKobukiState:
        """A copy of the state, consistent at one instant."""
        with self._mutex:
            return replace(
                self.state,
                sounds=list(self.state.sounds),
                sound_sequences=list(self.state.sound_sequences),
                requests=list(self.state.requests),
            )

    @property
    def wheel_speeds(self) -> tuple[float, float]:
        """(left, right) [mm/s] the fake drives with now."""
        with self._mutex:
            return k.speed_radius_to_wheels(self.state.speed, self.state.radius)

    # ------------------------------------------------------------------ device side
    def on_bytes(self, data: bytes) -> None:
        with self._mutex:
            before = self._parser.bad_checksum
            payloads = self._parser.feed(data)
            self.state.bad_command_frames += self._parser.bad_checksum - before
            for payload in payloads:
                try:
                    cmds = k.decode_commands(payload)
                except k.CodecError as e:
                    self.state.malformed_command_frames += 1
                    log.debug("%s: malformed command frame: %s", self.name, e)
                    continue
                for c in cmds:
                    self._apply(c)

    def _apply(self, c: k.Command) -> None:
        s = self.state
        if c.kind == "base_control":
            s.speed, s.radius = int(c.values[0]), int(c.values[1])
            s.base_control_frames += 1
            s.moving_commands += s.speed != 0
        elif c.kind == "request_extra":
            flags = int(c.values[0])
            s.requests.append(flags)
            self._pending_extra |= flags
        elif c.kind == "get_gain":
            self._pending_gain = True
        elif c.kind == "set_gain":
            user, kp, ki, kd = c.values
            s.gains = k.ControllerInfo(bool(user), float(kp), float(ki), float(kd))
        elif c.kind == "gp_output":
            s.gp_output = int(c.values[0])
        elif c.kind == "sound":
            s.sounds.append((int(c.values[0]), int(c.values[1])))
        elif c.kind == "sound_sequence":
            s.sound_sequences.append(int(c.values[0]))
        else:
            log.debug("%s: ignoring unknown command id %s", self.name, c.values)

    def on_tick(self, now: float) -> None:
        with self._mutex:
            n = self.state.frames_stepped
            frame = self._step(0.02)
            dropping = self.mute or bool(self._drop_every and n % self._drop_every == 0)
            if not dropping and self._drop:
                self._drop -= 1
                dropping = True
            if dropping:
                self.state.frames_dropped += 1
                return
            stray, self._stray = self._stray, b""
            if self._truncate:
                self._truncate -= 1
                frame = frame[: len(frame) // 2]
                self.state.frames_corrupted += 1
            elif self._corrupt or (self._corrupt_every and n % self._corrupt_every == 0):
                self._corrupt = max(0, self._corrupt - 1)
                frame = frame[:-1] + bytes((frame[-1] ^ 0x5A,))
                self.state.frames_corrupted += 1
            self.state.frames_sent += 1
        self.send(stray + frame)

    def _step(self, dt: float) -> bytes:
        """Advance the fake robot by ``dt`` seconds and build the next feedback frame."""
        s = self.state
        left, right = k.speed_radius_to_wheels(s.speed, s.radius)  # mm/s
        v = (left + right) / 2000.0
        w = (right - left) / (1000.0 * k.BIAS)
        s.left_encoder += left * dt * _TICKS_PER_MM
        s.right_encoder += right * dt * _TICKS_PER_MM
        mid = s.heading + w * dt / 2.0
        s.x += v * dt * math.cos(mid)
        s.y += v * dt * math.sin(mid)
        s.heading = wrap_angle(s.heading + w * dt)
        s.timestamp_ms = (s.timestamp_ms + round(dt * 1000)) & 0xFFFF
        pwm = max(-127, min(127, round(left / 7.0))), max(-127, min(127, round(right / 7.0)))
        core = k.CoreSensors(
            s.timestamp_ms, s.bumper, s.wheel_drop, s.cliff,
            math.floor(s.left_encoder) & 0xFFFF, math.floor(s.right_encoder) & 0xFFFF,
            pwm[0], pwm[1], s.buttons, s.charger, s.battery, s.overcurrent,
        )
        self._gyro_frame = (self._gyro_frame + 1) & 0xFF
        parts = [
            k.encode_core_sensors(core),
            k.encode_dock_ir(k.DockInfrared(0, 0, 0)),
            k.encode_inertia(s.heading, w),
            k.encode_cliff(k.CliffSensors(0 if s.cliff & 1 else 2000, 0 if s.cliff & 2 else 2000, 0 if s.cliff & 4 else 2000)),
            k.encode_current(abs(left) / 1000.0, abs(right) / 1000.0),
            k.encode_gyro(self._gyro_frame, [(0.0, 0.0, w), (0.0, 0.0, w)]),
            k.encode_gp_input(k.GpInput(0, (0.0, 0.0, 0.0, 0.0))),
        ]
        extra, self._pending_extra = self._pending_extra, 0
        if extra & k.REQUEST_HARDWARE:
            parts.append(k.encode_version(k.HARDWARE, s.hardware))
        if extra & k.REQUEST_FIRMWARE:
            parts.append(k.encode_version(k.FIRMWARE, s.firmware))
        if extra & k.REQUEST_UID:
            parts.append(k.encode_unique_id(s.unique_id))
        if self._pending_gain:
            self._pending_gain = False
            parts.append(k.encode_controller_info(s.gains))
        if self._unknown:
            self._unknown -= 1
            parts.append(k.subpayload(0x30, b"\x01\x02\x03\x04"))
        return k.encode_frame(*parts)
