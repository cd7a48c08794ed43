"""Kobuki device: the serial link, its I/O thread, safety logic and odometry.

:class:`KobukiDevice` composes :mod:`.codec` with :class:`~mmexec.drivers.transport.SerialTransport`.
Nothing happens in ``__init__``; :meth:`KobukiDevice.connect` opens the port, sends a
stop frame, starts the I/O thread and waits (bounded) for the stream and the version answer.

The I/O thread, per valid feedback frame (50 Hz, the robot's cadence):

1. decodes it; updates sensors, faults and odometry (encoder distance, gyro or
   encoder heading);
2. applies the safety rules: a bumper, cliff, wheel-drop or overcurrent stops the
   base at once (no ramp) and motion is refused until it clears; a velocity older
   than ``command_timeout`` (clock seconds) is replaced by zero;
3. ramps the output towards the target with the acceleration limiter
   (``linear_accel`` m/s^2, ``angular_accel`` rad/s^2, decelerating ``decel_factor``
   times faster), using the firmware timestamps for dt;
4. sends one Base Control frame (vendor cadence), plus Request Extra until the
   versions and unique id arrive, plus any queued command (sound, LEDs, gains).

Liveness means *valid* frames: bytes that never form a valid, decodable frame (noise,
wrong baud rate) are no sign of life. No valid frame for ``link_timeout`` seconds is the
``link_lost`` fault: the output is zeroed, state() reports v = w = 0 (nothing is
measured any more), and the thread writes a stop frame (speed 0) every 20 ms on its own,
whatever arrives, until the link is back (:data:`RECOVERY_FRAMES` consecutive valid
frames) or :meth:`close`. A port that fails (cable pulled) latches ``link_lost``; the
thread then reopens the port every 0.1 s and, once it is back, writes stop frames again
until :meth:`reconnect` or :meth:`close`. An unexpected error in the thread is the
``driver_error`` fault, with stop frames every 20 ms until :meth:`close`.
Link timing uses ``time.monotonic()``; the command watchdog and state stamps use
the injected :class:`~mmexec.drivers.interfaces.Clock`.
"""

from __future__ import annotations

import enum
import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import Self

from mmexec.drivers.interfaces import BaseState, Clock, MonotonicClock, Pose2D
from mmexec.drivers.kobuki import codec as k
from mmexec.drivers.transport import LinkError, SerialSettings, SerialTransport

__all__ = [
    "COMMAND_TIMEOUT_RANGE",
    "LINK_TIMEOUT_RANGE",
    "RECOVERY_FRAMES",
    "SUPPORTED_FIRMWARE_MAJOR",
    "KobukiConfig",
    "KobukiCorruptFrames",
    "KobukiDevice",
    "KobukiError",
    "KobukiFirmwareError",
    "KobukiInfo",
    "KobukiLinkError",
    "KobukiNotConnected",
    "KobukiPortError",
    "KobukiTimeout",
    "LinkState",
    "LinkStats",
]

log = logging.getLogger(__name__)

SUPPORTED_FIRMWARE_MAJOR = 1
#: hardware spec limits; configured limits may only be lower
SPEC_MAX_LINEAR = 0.7  # m/s
SPEC_MAX_ANGULAR = math.pi  # rad/s
_EXTRA_FLAGS = k.REQUEST_HARDWARE | k.REQUEST_FIRMWARE | k.REQUEST_UID
_DEFAULT_GP_OUTPUT = 0x00F0  # all power rails on, LEDs off (vendor driver's start value)
_PERIOD = 0.02  # s, the Kobuki's feedback period (50 Hz); also the cadence of lone stop frames
_STOP_FRAME = k.encode_frame(k.base_control(0, 0))
_FINAL_STOPS = 3  # stop frames close() writes back to back (one may be lost on a noisy line)
_REOPEN_PERIOD = 0.1  # s between attempts to reopen a port that failed
_JOIN_TIMEOUT = 2.0  # s close() waits for the I/O thread (its longest step, a write, is <= 1 s)
#: consecutive valid frames (0.1 s of clean stream) that end a ``link_lost``
RECOVERY_FRAMES = 5
#: [s] accepted ``link_timeout``: at least two feedback periods (one lost frame is no loss
#: of link), at most 0.5 s (0.35 m driven blind at the spec's 0.7 m/s)
LINK_TIMEOUT_RANGE = (0.04, 0.5)
#: [s] accepted ``command_timeout``: longer than a 20 Hz tick, at most 1 s (the vendor uses 0.6)
COMMAND_TIMEOUT_RANGE = (0.05, 1.0)
_SETUP_TIMEOUT_MAX = 60.0  # s, connect_timeout and version_timeout


# --------------------------------------------------------------------------- errors


class KobukiError(Exception):
    """Base of every Kobuki driver error."""


class KobukiNotConnected(KobukiError):
    """An operation needs the link (call connect() first)."""


class KobukiLinkError(KobukiError):
    """The serial link failed: no such port, permission, busy, cable pulled, timeout."""

    def __init__(self, port: str, message: str) -> None:
        super().__init__(f"kobuki on {port}: {message}")
        self.port = port
        self.detail = message


class KobukiPortError(KobukiLinkError):
    """The port cannot be opened: no such port, permission denied, busy."""


class KobukiTimeout(KobukiLinkError):
    """No valid frame (or no version answer) within the deadline."""


class KobukiCorruptFrames(KobukiLinkError):
    """Bytes arrive but never form a valid frame (wrong baud rate, noise, FTDI latency)."""


class KobukiFirmwareError(KobukiError):
    """The robot runs a firmware this driver refuses (major version != 1)."""

    def __init__(self, port: str, version: k.Version) -> None:
        super().__init__(
            f"kobuki on {port}: firmware {version} is not supported (major version must be "
            f"{SUPPORTED_FIRMWARE_MAJOR}; the vendor recommends 1.1.4 or 1.2.0)"
        )
        self.port = port
        self.version = version


# --------------------------------------------------------------------------- config / info


@dataclass(frozen=True)
class KobukiConfig:
    """Kobuki link and safety settings (SI units; seconds are clock seconds).

    Limits above the hardware spec (0.7 m/s, pi rad/s) are rejected by :meth:`validate`.
    """

    port: str = "/dev/kobuki"
    baudrate: int = 115200
    max_linear: float = 0.7          # m/s
    max_angular: float = math.pi     # rad/s
    linear_accel: float = 0.3        # m/s^2
    angular_accel: float = 3.5       # rad/s^2
    decel_factor: float = 1.2        # deceleration limit = factor x acceleration limit
    command_timeout: float = 0.6     # s without a new velocity -> zero
    link_timeout: float = 0.1        # s without a valid frame -> link_lost, stop frames
    connect_timeout: float = 0.5     # s to see the first valid frame
    version_timeout: float = 1.0     # s to get the firmware version after that
    gyro_heading: bool = True        # heading from the factory-calibrated gyro (id 4)

    def validate(self) -> list[str]:
        """Problems with these values ([] when fine). Every number must be finite: an
        infinite timeout would disable the watchdog it sets."""
        out = []
        if not 0.0 < self.max_linear <= SPEC_MAX_LINEAR:
            out.append(f"max_linear: {self.max_linear} m/s outside (0, {SPEC_MAX_LINEAR}]")
        if not 0.0 < self.max_angular <= SPEC_MAX_ANGULAR + 1e-9:
            out.append(f"max_angular: {self.max_angular} rad/s outside (0, pi]")
        for name in ("linear_accel", "angular_accel"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                out.append(f"{name}: must be a finite number > 0, got {value}")
        for name, (lo, hi), why in (
            ("command_timeout", COMMAND_TIMEOUT_RANGE, "a velocity older than this becomes zero"),
            ("link_timeout", LINK_TIMEOUT_RANGE, "no valid frame for this long stops the base"),
            ("connect_timeout", (_PERIOD, _SETUP_TIMEOUT_MAX), "wait for the first valid frame"),
            ("version_timeout", (_PERIOD, _SETUP_TIMEOUT_MAX), "wait for the version answer"),
        ):
            value = getattr(self, name)
            if not lo <= value <= hi:  # False for NaN as well
                out.append(f"{name}: must be {lo:g}..{hi:g} s ({why}), got {value}")
        if not (math.isfinite(self.decel_factor) and self.decel_factor >= 1.0):
            out.append(f"decel_factor: must be a finite number >= 1, got {self.decel_factor}")
        if self.baudrate != 115200:
            out.append(f"baudrate: the Kobuki talks at 115200 baud, got {self.baudrate}")
        return out


@dataclass(frozen=True)
class KobukiInfo:
    """What the robot told about itself (filled once the answers arrive)."""

    firmware: k.Version | None
    hardware: k.Version | None
    unique_id: tuple[int, int, int] | None
    battery: float | None  # V
    frames: int
    bad_frames: int

    @property
    def unique_id_text(self) -> str:
        return "-".join(f"{x:08X}" for x in self.unique_id) if self.unique_id else "unknown"


@dataclass(frozen=True)
class LinkStats:
    """Feedback link quality since :meth:`KobukiDevice.connect`, in frames."""

    frames: int   # valid feedback frames
    corrupt: int  # rejected: bad checksum, impossible length, malformed sub-payloads
    lost: int     # stamped by the base (every 20 ms) but never arrived, not even corrupt
    late: int     # valid frames that came more than link_timeout after the previous one

    @property
    def expected(self) -> int:
        """Frames the base sent, as far as the host can tell."""
        return self.frames + self.corrupt + self.lost

    @property
    def error_ratio(self) -> float:
        """(corrupt + lost + late) / expected; 0 when nothing was expected."""
        n = self.expected
        return (self.corrupt + self.lost + self.late) / n if n else 0.0


class LinkState(enum.Enum):
    CLOSED = "closed"
    CONNECTING = "connecting"
    STREAMING = "streaming"
    LOST = "lost"



# --------------------------------------------------------------------------- device


class KobukiDevice:
    """One Kobuki base on a serial port (see module doc). Thread-safe."""

    def __init__(self, config: KobukiConfig, clock: Clock | None = None) -> None:
        problems = config.validate()
        if problems:
            raise ValueError(f"kobuki on {config.port}: " + "; ".join(problems))
        self.config = config
        self.clock: Clock = clock or MonotonicClock()
        self._transport = SerialTransport(SerialSettings(config.port, config.baudrate))
        self._lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._first_frame = threading.Event()
        self._versions = threading.Event()
        self._link = LinkState.CLOSED
        self._reset_state()

    def _reset_state(self) -> None:
        self._parser = k.FrameParser()
        self._odom = k.Odometry()
        self._feedback: k.Feedback | None = None
        self._core: k.CoreSensors | None = None
        self._firmware: k.Version | None = None
        self._hardware: k.Version | None = None
        self._uid: tuple[int, int, int] | None = None
        self._controller: k.ControllerInfo | None = None
        self._malformed = 0
        self._sensor_faults: frozenset[str] = frozenset()
        self._link_lost = False       # no valid frame for link_timeout (clears on recovery)
        self._good_run = 0            # consecutive valid frames while link_lost
        self._rejected = 0            # frames rejected so far (parser + malformed)
        self._driver_error = ""       # the I/O thread failed: latched until close()
        self._firmware_bad = False
        self._target = (0.0, 0.0)
        self._target_stamp = -math.inf
        self._out = (0.0, 0.0)
        self._measured = (0.0, 0.0)
        self._stamp = 0.0
        self._last_ts: int | None = None
        self._last_valid = time.monotonic()
        self._gap_frames = 0          # frames missing between valid frames' timestamps
        self._late = 0
        self._queue: list[bytes] = []
        self._gp_output = _DEFAULT_GP_OUTPUT
        self._refused_logged = False
        self._error: str = ""
        self.commands_sent = 0

    # ------------------------------------------------------------------ lifecycle
    @property
    def port(self) -> str:
        return self.config.port

    @property
    def link_state(self) -> LinkState:
        with self._lock:
            return self._link

    def connect(self) -> KobukiInfo:
        """Open the port, start streaming, check the firmware. Blocks at most
        ``connect_timeout + version_timeout`` seconds (setup only, never on a tick).

        Raises :class:`KobukiPortError` (no such port, permission, busy),
        :class:`KobukiLinkError` (the port failed), :class:`KobukiTimeout` (no answer),
        :class:`KobukiCorruptFrames`, :class:`KobukiFirmwareError`; the port is closed
        again on any of them.
        """
        with self._lock:
            if self._thread is not None:
                return self.info()
            self._reset_state()
            self._first_frame.clear()
            self._versions.clear()
            try:
                self._transport.open()
            except LinkError as e:
                self._transport.close()
                raise KobukiPortError(self.port, e.detail) from e
            try:
                self._transport.reset_input()
                # a base left driving (a crashed host, a previous run) stops now, even if
                # its feedback never becomes valid
                self._transport.write(_STOP_FRAME)
            except LinkError as e:
                self._transport.close()
                raise KobukiLinkError(self.port, e.detail) from e
            self._link = LinkState.CONNECTING
            self._stop.clear()
            self._last_valid = time.monotonic()
            self._thread = threading.Thread(target=self._run, name=f"kobuki-io {self.port}", daemon=True)
            self._thread.start()
        try:
            cfg = self.config
            if not self._first_frame.wait(cfg.connect_timeout):
                with self._lock:
                    err, bad = self._error, self._rejected_locked()
                    seen = self._parser.discarded + self._parser.pending
                if err:
                    raise KobukiLinkError(self.port, err)
                if bad or seen:
                    raise KobukiCorruptFrames(
                        self.port,
                        f"corrupt frames: {bad} rejected, no valid frame within {cfg.connect_timeout:g} s "
                        "(wrong baud rate, noise, or FTDI latency timer not 1 ms?)",
                    )
                raise KobukiTimeout(
                    self.port, f"no answer within {cfg.connect_timeout:g} s (is the base switched on?)"
                )
            if not self._versions.wait(cfg.version_timeout):
                raise KobukiTimeout(self.port, f"no version answer within {cfg.version_timeout:g} s")
            with self._lock:
                fw = self._firmware
            if fw is not None and fw.major != SUPPORTED_FIRMWARE_MAJOR:
                raise KobukiFirmwareError(self.port, fw)
        except KobukiError:
            self.close()
            raise
        log.info("kobuki on %s: firmware %s, hardware %s", self.port, self._firmware, self._hardware)
        return self.info()

    def close(self) -> None:
        """Zero the output, stop the I/O thread (bounded: 2 s), write stop frames, close
        the port. Idempotent."""
        with self._lock:
            self._zero_locked()
            t, self._thread = self._thread, None
        self._stop.set()
        if t is not None and t is not threading.current_thread():
            t.join(_JOIN_TIMEOUT)
            if t.is_alive():
                log.error("kobuki on %s: the I/O thread did not stop within %g s; closing the port under it",
                          self.port, _JOIN_TIMEOUT)
        if self._transport.is_open:
            try:
                self._transport.write(_STOP_FRAME * _FINAL_STOPS)
            except LinkError as e:
                log.warning("kobuki on %s: could not send the final stop: %s", self.port, e.detail)
        self._transport.close()
        with self._lock:
            self._link = LinkState.CLOSED

    def reconnect(self) -> KobukiInfo:
        """Close and connect again (after a pulled cable, for example)."""
        self.close()
        return self.connect()

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ API (any thread)
    def info(self) -> KobukiInfo:
        with self._lock:
            return KobukiInfo(
                self._firmware, self._hardware, self._uid,
                self._core.battery if self._core else None,
                self._parser.frames, self._rejected_locked(),
            )

    def link_stats(self) -> LinkStats:
        """Feedback link quality since :meth:`connect` (see :class:`LinkStats`)."""
        with self._lock:
            corrupt = self._rejected_locked()
            return LinkStats(self._parser.frames - self._malformed, corrupt,
                             max(0, self._gap_frames - corrupt), self._late)

    def _rejected_locked(self) -> int:
        return self._parser.bad_checksum + self._parser.bad_length + self._malformed

    @property
    def faults(self) -> frozenset[str]:
        """Active safety conditions (see :class:`~mmexec.drivers.interfaces.BaseState`)."""
        with self._lock:
            return self._faults_locked()

    def _faults_locked(self) -> frozenset[str]:
        f = set(self._sensor_faults)
        if self._link_lost or self._link is LinkState.LOST:
            f.add("link_lost")
        if self._driver_error:
            f.add("driver_error")
        if self._firmware_bad:
            f.add("firmware_unsupported")
        return frozenset(f)

    def set_velocity(self, v: float, w: float) -> bool:
        """Target ``v`` [m/s], ``w`` [rad/s], clamped to the limits and held for
        ``command_timeout`` seconds. Returns False (and drives nothing) when refused:
        a fault is active, or the link is not streaming. Zero is always accepted."""
        cfg = self.config
        if not (math.isfinite(v) and math.isfinite(w)):
            raise ValueError(f"kobuki: velocity must be finite, got v={v}, w={w}")
        v = max(-cfg.max_linear, min(cfg.max_linear, v))
        w = max(-cfg.max_angular, min(cfg.max_angular, w))
        with self._lock:
            if v == 0.0 and w == 0.0:
                self._target, self._target_stamp = (0.0, 0.0), self.clock.now()
                return True
            faults = self._faults_locked()
            if faults or self._link is not LinkState.STREAMING:
                if not self._refused_logged:
                    why = ", ".join(sorted(faults)) or f"link {self._link.value} (call connect() first)"
                    log.warning("kobuki on %s: motion refused: %s", self.port, why)
                    self._refused_logged = True
                self._target = (0.0, 0.0)
                return False
            self._refused_logged = False
            self._target, self._target_stamp = (v, w), self.clock.now()
            return True

    def stop(self) -> None:
        """Zero velocity now: target and output, no ramp."""
        with self._lock:
            self._target, self._out = (0.0, 0.0), (0.0, 0.0)
            self._target_stamp = self.clock.now()

    def base_state(self) -> BaseState:
        """Odometry pose, measured (v, w), clock stamp of the last valid frame, faults.

        Without a link (``link_lost``, ``driver_error``) nothing is measured: v and w are
        reported as 0, the value the driver is commanding with its stop frames, instead of
        the last measurement going stale; the pose and ``stamp`` stay at the last valid
        frame."""
        with self._lock:
            blind = self._link_lost or self._link is LinkState.LOST or bool(self._driver_error)
            v, w = (0.0, 0.0) if blind else self._measured
            return BaseState(
                Pose2D(self._odom.x, self._odom.y, self._odom.theta), v, w, self._stamp, self._faults_locked(),
            )

    def reset_odometry(self, pose: Pose2D | None = None) -> None:
        """Set the odometry pose (e.g. to the robot's known start pose in ``map``; the
        origin when None)."""
        pose = pose if pose is not None else Pose2D()
        with self._lock:
            self._odom.reset(pose.x, pose.y, pose.theta)

    @property
    def output(self) -> tuple[float, float]:
        """(v, w) after the limiter, as last sent to the robot."""
        with self._lock:
            return self._out

    @property
    def feedback(self) -> k.Feedback | None:
        """The latest decoded feedback frame."""
        with self._lock:
            return self._feedback

    @property
    def controller_gains(self) -> k.ControllerInfo | None:
        with self._lock:
            return self._controller

    def _require_link(self) -> None:
        if self._thread is None:
            raise KobukiNotConnected(f"kobuki on {self.port}: not connected (call connect() first)")

    def play_sound_sequence(self, sequence: int) -> None:
        """Queue a built-in sound (0 on, 1 off, 2 recharge, 3 button, 4 error, 5, 6)."""
        self._enqueue(k.sound_sequence(sequence))

    def play_tone(self, frequency_hz: float, duration_s: float) -> None:
        """Queue a tone of ``frequency_hz`` [Hz] for ``duration_s`` [s] (<= 0.255 s)."""
        self._enqueue(k.sound(frequency_hz, round(duration_s * 1000)))

    def set_leds(self, led1: str | None = None, led2: str | None = None) -> None:
        """Set LED colours (``off``, ``red``, ``green``, ``orange``), keeping other GP bits."""
        bits = {"off": (0, 0), "red": (1, 0), "green": (0, 1), "orange": (1, 1)}
        with self._lock:
            value = self._gp_output
            for colour, red, green in ((led1, 0x0100, 0x0200), (led2, 0x0400, 0x0800)):
                if colour is None:
                    continue
                if colour not in bits:
                    raise ValueError(f"kobuki: LED colour {colour!r} not one of {sorted(bits)}")
                r, g = bits[colour]
                value = (value & ~(red | green)) | (red if r else 0) | (green if g else 0)
            self._gp_output = value
        self._enqueue(k.gp_output(value))

    def request_gains(self) -> None:
        """Ask for the controller gains; :attr:`controller_gains` fills in (firmware >= 1.2)."""
        self._enqueue(k.get_controller_gain())

    def set_gains(self, kp: float, ki: float, kd: float, *, user: bool = True) -> None:
        """Set wheel controller gains (``user=False`` restores the factory gains)."""
        self._enqueue(k.set_controller_gain(user, kp, ki, kd))

    def _enqueue(self, sub: bytes) -> None:
        with self._lock:
            self._require_link()
            self._queue.append(sub)

    # ------------------------------------------------------------------ I/O thread
    def _zero_locked(self) -> None:
        self._target, self._out = (0.0, 0.0), (0.0, 0.0)

    def _run(self) -> None:
        try:
            self._serve()
        except Exception as e:  # a bug in here must not leave the base driving
            log.exception("kobuki on %s: the I/O thread failed; sending stop frames until close()", self.port)
            with self._lock:
                self._driver_error = self._error = f"driver error: {type(e).__name__}: {e}"
                self._zero_locked()
            self._send_stops_until_closed()

    def _serve(self) -> None:
        """Read, answer each valid frame, and keep the link deadline (see module doc)."""
        next_stop = 0.0
        while not self._stop.is_set():
            if not self._transport.is_open and not self._reopen():
                self._stop.wait(_REOPEN_PERIOD)
                continue
            try:
                data = self._transport.wait_readable(_PERIOD)
                now = time.monotonic()
                replies = self._receive(data, now)
                if self._link_deadline(now) and now >= next_stop:
                    replies.append(_STOP_FRAME)
                    next_stop = now + _PERIOD
                for frame in replies:
                    self._transport.write(frame)
            except LinkError as e:
                self._port_failed(e.detail)

    def _receive(self, data: bytes, now: float) -> list[bytes]:
        """Parse ``data``; the command frames that answer its valid frames."""
        with self._lock:
            payloads = self._parser.feed(data) if data else []
        replies = []
        for payload in payloads:
            frame = self._on_frame(payload, now)
            if frame is not None:
                replies.append(frame)
        with self._lock:
            rejected = self._rejected_locked()
            if rejected != self._rejected:
                self._rejected, self._good_run = rejected, 0
        return replies

    def _link_deadline(self, now: float) -> bool:
        """Raise ``link_lost`` when no valid frame came for ``link_timeout``; True while
        stop frames are due regardless of feedback (lost link, failed port, or a port
        that has not yet delivered a valid frame for that long)."""
        cfg = self.config
        with self._lock:
            if self._link is LinkState.LOST:
                return True
            silent_for = now - self._last_valid
            if silent_for <= cfg.link_timeout:
                return self._link_lost
            if self._link is LinkState.STREAMING and not self._link_lost:
                log.warning("kobuki on %s: no valid frame for %.0f ms (%d rejected so far): link lost, "
                            "sending stop frames", self.port, silent_for * 1e3, self._rejected_locked())
                self._link_lost = True
                self._good_run = 0
                self._zero_locked()
            return True

    def _port_failed(self, detail: str) -> None:
        """The port failed (cable pulled): latch ``link_lost`` until :meth:`reconnect`."""
        with self._lock:
            first = self._link is not LinkState.LOST
            self._error = f"link failed: {detail}"
            self._link = LinkState.LOST
            self._zero_locked()
        self._transport.close()
        if first:
            log.error("kobuki on %s: link failed: %s; reopening the port every %g s to send stop frames "
                      "(reconnect() to drive again)", self.port, detail, _REOPEN_PERIOD)

    def _reopen(self) -> bool:
        """Try to open the port again after a failure; True once it is open."""
        try:
            self._transport.open()
        except LinkError as e:
            log.debug("kobuki on %s: port still unavailable: %s", self.port, e.detail)
            return False
        with self._lock:
            self._parser.reset()
        log.warning("kobuki on %s: the port is back: sending stop frames (link_lost stays until reconnect())",
                    self.port)
        return True

    def _send_stops_until_closed(self) -> None:
        """After a driver error: a stop frame every period until :meth:`close`."""
        while not self._stop.wait(_PERIOD):
            try:
                self._transport.write(_STOP_FRAME)
            except LinkError as e:
                log.error("kobuki on %s: cannot send stop frames any more: %s", self.port, e.detail)
                return

    def _on_frame(self, payload: bytes, now: float) -> bytes | None:
        """Handle one feedback payload that arrived at ``now`` (time.monotonic()); return
        the command frame to send."""
        try:
            fb = k.decode_feedback(payload)
        except k.CodecError as e:
            with self._lock:
                self._malformed += 1
            log.debug("kobuki on %s: %s", self.port, e)
            return None
        cfg = self.config
        with self._lock:
            self._on_valid_frame_locked(now)
            self._feedback = fb
            self._stamp = self.clock.now()
            if fb.firmware is not None and self._firmware is None:
                self._firmware = fb.firmware
                if fb.firmware.major != SUPPORTED_FIRMWARE_MAJOR:
                    self._firmware_bad = True
                    # connect() raises it to the caller: logging it too would say it twice
                    log.debug("%s", KobukiFirmwareError(self.port, fb.firmware))
            if fb.hardware is not None:
                self._hardware = fb.hardware
            if fb.unique_id is not None:
                self._uid = fb.unique_id
            if fb.controller is not None:
                self._controller = fb.controller
            dt = 0.02
            if fb.core is not None:
                core = fb.core
                self._core = core
                if self._last_ts is not None:
                    dt = ((core.timestamp_ms - self._last_ts) & 0xFFFF) / 1000.0
                    self._gap_frames += max(0, round(dt / _PERIOD) - 1)
                self._last_ts = core.timestamp_ms
                heading = fb.inertia.heading if (cfg.gyro_heading and fb.inertia is not None) else None
                step = self._odom.update(core.left_encoder, core.right_encoder, core.timestamp_ms, heading)
                self._measured = (step.v, step.w)
                new_faults = core.faults
                if new_faults - self._sensor_faults:
                    log.warning("kobuki on %s: stopping: %s", self.port, ", ".join(sorted(new_faults)))
                self._sensor_faults = new_faults
            if self._link is LinkState.CONNECTING:
                self._link = LinkState.STREAMING
            # safety, watchdog, limiter
            if self._faults_locked():
                self._target, self._out = (0.0, 0.0), (0.0, 0.0)
            elif self.clock.now() - self._target_stamp > cfg.command_timeout:
                self._target = (0.0, 0.0)
            self._out = (
                _ramp(self._out[0], self._target[0], cfg.linear_accel, cfg.decel_factor, min(dt, 0.1)),
                _ramp(self._out[1], self._target[1], cfg.angular_accel, cfg.decel_factor, min(dt, 0.1)),
            )
            subs = [k.base_control(*k.velocity_to_speed_radius(*self._out))]
            need_versions = self._firmware is None or self._hardware is None or self._uid is None
            if need_versions:
                subs.append(k.request_extra(_EXTRA_FLAGS))
            size = sum(len(s) for s in subs)
            while self._queue and size + len(self._queue[0]) <= k.MAX_PAYLOAD:
                sub = self._queue.pop(0)
                subs.append(sub)
                size += len(sub)
            self.commands_sent += 1
        self._first_frame.set()
        if self._firmware is not None and (not need_versions or self._firmware_bad):
            self._versions.set()
        return k.encode_frame(*subs)


    def _on_valid_frame_locked(self, now: float) -> None:
        """Liveness bookkeeping for a valid frame: late count, ``link_lost`` recovery."""
        if self._link is LinkState.STREAMING and now - self._last_valid > self.config.link_timeout:
            self._late += 1
        self._last_valid = now
        if self._link_lost and self._link is not LinkState.LOST:
            self._good_run += 1
            if self._good_run >= RECOVERY_FRAMES:
                log.info("kobuki on %s: %d valid frames in a row: link back", self.port, self._good_run)
                self._link_lost = False


def _ramp(current: float, target: float, accel: float, decel_factor: float, dt: float) -> float:
    """Move ``current`` towards ``target`` by at most accel*dt (speeding up) or
    decel_factor*accel*dt (slowing down or reversing through zero)."""
    if target == current:
        return current
    speeding_up = (current >= 0.0 and target > current) or (current <= 0.0 and target < current)
    step = accel * dt * (1.0 if speeding_up else decel_factor)
    if abs(target - current) <= step:
        return target
    return current + math.copysign(step, target - current)
