"""RPLIDAR A2 device: the serial link, the motor, the scan reader thread and its watchdog.

:class:`RplidarDevice` composes :mod:`.codec` and :mod:`.scan` with
:class:`~mmexec.drivers.transport.SerialTransport`. Nothing happens in ``__init__``.

* :meth:`RplidarDevice.connect` (setup only, bounded): opens the port (115200 8N1),
  asserts DTR (motor off), sends STOP and discards what was in flight, then asks
  GET_INFO, GET_HEALTH, GET_SAMPLERATE and GET_ACC_BOARD_FLAG, each within
  ``response_timeout``. A health status of ERROR (the device's protection stop) is
  refused with :class:`RplidarHealthError`; WARNING is logged and accepted.
* :meth:`RplidarDevice.start`: motor on (DTR cleared, as the vendor SDK does on the A2's
  USB adapter, plus SET_MOTOR_PWM ``motor_pwm`` when the firmware reports motor control),
  SCAN, its descriptor, then a reader thread.
* The reader thread assembles nodes into revolutions on the start flag, checks each
  (:func:`~.scan.check_revolution`) and publishes it as a
  :class:`~mmexec.drivers.interfaces.LaserScan` (CCW angles in the lidar frame, ranges
  [m], ``inf`` no return, ``nan`` not measured, intensity = quality / 63), stamped with
  the injected clock when the revolution's start node arrived.
* Watchdog: no complete revolution for ``watchdog_revolutions / min_scan_rate`` seconds
  (3 revolutions at the A2's slowest 5 Hz = 0.6 s; the first one is allowed
  ``spinup_timeout`` more) is a fault: :attr:`RplidarDevice.fault` becomes a
  :class:`RplidarWatchdog` naming the cause (no data, corrupt stream, no start flag,
  incomplete revolutions) and :meth:`RplidarDevice.latest_scan` returns None until a
  complete revolution arrives again. A port that fails (cable pulled) is
  :class:`RplidarLinkLost`, latched.
* :meth:`RplidarDevice.stop` / :meth:`RplidarDevice.close`: STOP, motor off (PWM 0 when
  supported, DTR asserted), then the port is closed.

Link timing (deadlines, watchdog) uses ``time.monotonic()``, the time the device spins
in; scan stamps use the injected :class:`~mmexec.drivers.interfaces.Clock`.
"""

from __future__ import annotations

import collections
import enum
import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import Self

import numpy as np

from mmexec.drivers.interfaces import Clock, LaserScan, MonotonicClock
from mmexec.drivers.rplidar import codec as c
from mmexec.drivers.rplidar import scan as sc
from mmexec.drivers.transport import LinkError, SerialSettings, SerialTransport

__all__ = [
    "DeviceState",
    "RplidarConfig",
    "RplidarCorruptStream",
    "RplidarDevice",
    "RplidarError",
    "RplidarHealthError",
    "RplidarInfo",
    "RplidarLinkError",
    "RplidarLinkLost",
    "RplidarMotorError",
    "RplidarNotConnected",
    "RplidarPortError",
    "RplidarStats",
    "RplidarTimeout",
    "RplidarWatchdog",
    "ScanFault",
]

log = logging.getLogger(__name__)

#: the device leaves scan mode within 1 ms of STOP; bytes already in the USB adapter and
#: the driver's buffers still arrive after that, so wait this long before discarding them
STOP_SETTLE = 0.01  # s
#: bytes of unexpected input kept while looking for an answer's descriptor
_SEARCH_WINDOW = 256


# --------------------------------------------------------------------------- errors


class RplidarError(Exception):
    """Base of every RPLIDAR driver error; messages start ``rplidar on PORT:``."""

    def __init__(self, port: str, message: str) -> None:
        super().__init__(f"rplidar on {port}: {message}")
        self.port = port
        self.detail = message


class RplidarNotConnected(RplidarError):
    """An operation needs the link (call connect() first)."""


class RplidarLinkError(RplidarError):
    """The serial link failed (port, cable, timing), not the lidar itself."""


class RplidarPortError(RplidarLinkError):
    """The port cannot be opened: no such port, permission denied, busy."""


class RplidarTimeout(RplidarLinkError):
    """No answer within the deadline (unpowered, wrong port, unplugged adapter)."""


class RplidarCorruptStream(RplidarLinkError):
    """Bytes arrive but never form a valid answer (noise, wrong baud rate)."""


class RplidarLinkLost(RplidarLinkError):
    """The port failed while open (cable pulled, adapter reset)."""


class RplidarHealthError(RplidarError):
    """GET_HEALTH reports ERROR: the lidar is in its protection stop and will not scan."""

    def __init__(self, port: str, health: c.Health) -> None:
        super().__init__(
            port,
            f"health ERROR (error code 0x{health.error_code:04X}): the lidar is in its protection "
            "stop and refuses to scan; power-cycle it (or send RESET) and check the motor and window",
        )
        self.health = health


class RplidarMotorError(RplidarError):
    """The motor cannot be switched: no DTR line and no SET_MOTOR_PWM support."""


class ScanFault(enum.Enum):
    """What the watchdog saw since the last complete revolution."""

    NO_DATA = "no_data"              # not a byte: motor stopped, device silent, cable loose
    CORRUPT = "corrupt"              # bytes, but nodes fail their checks or revolutions are mangled
    NO_START_FLAG = "no_start_flag"  # valid nodes, none with the start flag
    INCOMPLETE = "incomplete"        # revolutions too sparse or with wide gaps


class RplidarWatchdog(RplidarError):
    """No complete revolution within the watchdog deadline; :attr:`cause` says why."""

    def __init__(self, port: str, cause: ScanFault, seconds: float, detail: str) -> None:
        super().__init__(port, f"no complete scan for {seconds:.2f} s: {detail}")
        self.cause = cause
        self.seconds = seconds


# --------------------------------------------------------------------------- config / info


@dataclass(frozen=True)
class RplidarConfig:
    """RPLIDAR A2 link, motor and scan settings (SI units; seconds of wall time)."""

    port: str = "/dev/rplidar"
    baudrate: int = 115200           # A2M8: 115200 (A2M12: 256000)
    motor_pwm: int = c.DEFAULT_MOTOR_PWM   # duty 1..1023 with SET_MOTOR_PWM (660: about 10 Hz)
    beams: int = 360                 # bins of the published scan over 360 deg (1 deg)
    range_min: float = 0.15          # m, published in the scan (A2 datasheet)
    range_max: float = 12.0          # m (A2M8 R3 and older: 8 m)
    response_timeout: float = 0.5    # s for each answer at connect and to SCAN
    spinup_timeout: float = 2.0      # s more for the first complete scan after start()
    min_scan_rate: float = 5.0       # Hz, the slowest revolution the A2 makes
    watchdog_revolutions: float = 3.0  # revolutions at min_scan_rate without a complete scan -> fault

    @property
    def watchdog_timeout(self) -> float:
        """Seconds without a complete revolution before the watchdog fault."""
        return self.watchdog_revolutions / self.min_scan_rate

    def validate(self) -> list[str]:
        """Problems with these values ([] when fine)."""
        out = []
        if self.baudrate not in (115200, 256000):
            out.append(f"baudrate: the A2M8 talks at 115200 baud (A2M12: 256000), got {self.baudrate}")
        if not 1 <= self.motor_pwm <= c.MAX_MOTOR_PWM:
            out.append(f"motor_pwm: expected 1..{c.MAX_MOTOR_PWM}, got {self.motor_pwm}")
        if not 8 <= self.beams <= 16000:
            out.append(f"beams: expected 8..16000, got {self.beams}")
        if not 0.0 <= self.range_min < self.range_max:
            out.append(f"range_min / range_max: need 0 <= range_min < range_max, got {self.range_min}, "
                       f"{self.range_max}")
        for name in ("response_timeout", "spinup_timeout"):
            if not getattr(self, name) > 0.0:
                out.append(f"{name}: must be > 0 s, got {getattr(self, name)}")
        if not 0.0 < self.min_scan_rate <= 15.0:
            out.append(f"min_scan_rate: expected (0, 15] Hz (the A2 turns at 5-15 Hz), got {self.min_scan_rate}")
        if not self.watchdog_revolutions >= 1.0:
            out.append(f"watchdog_revolutions: must be >= 1, got {self.watchdog_revolutions}")
        return out


@dataclass(frozen=True)
class RplidarInfo:
    """What the lidar said about itself at connect, and how its motor is driven."""

    device: c.DeviceInfo
    health: c.Health
    sample_rate: c.SampleRate
    motor_pwm_supported: bool   # GET_ACC_BOARD_FLAG bit 0: SET_MOTOR_PWM works
    dtr: bool                   # the port has a DTR line (False on a pseudo-terminal)

    @property
    def motor_control(self) -> str:
        """``DTR+PWM``, ``DTR``, ``PWM`` or ``none``."""
        parts = [name for name, ok in (("DTR", self.dtr), ("PWM", self.motor_pwm_supported)) if ok]
        return "+".join(parts) or "none"


@dataclass(frozen=True)
class RplidarStats:
    """Counters since :meth:`RplidarDevice.start`; rate and points over a recent window."""

    scans: int                       # complete revolutions published
    rejected: int                    # revolutions thrown away (incomplete or corrupt)
    corrupt_bytes: int               # bytes dropped while resynchronising
    scan_rate: float | None          # Hz, revolutions per second over the window
    points_per_scan: float | None    # mean nodes per complete revolution over the window


class DeviceState(enum.Enum):
    CLOSED = "closed"
    IDLE = "idle"          # connected, motor off, not scanning
    SCANNING = "scanning"
    LOST = "lost"          # the port failed while open


@dataclass
class _Since:
    """What the reader saw since the last complete revolution, and when it last saw a
    byte, a valid node and a start flag (time.monotonic()): the watchdog's cause."""

    bytes: int = 0
    dropped: int = 0
    rejected: int = 0
    why: str = ""
    last_byte: float = 0.0
    last_node: float = 0.0
    last_start: float = 0.0

    def restart(self) -> None:
        """A complete revolution arrived: counts start again, the times stay."""
        self.bytes = self.dropped = self.rejected = 0
        self.why = ""


# --------------------------------------------------------------------------- device


class RplidarDevice:
    """One RPLIDAR A2 on a serial port (see the module doc). Thread-safe."""

    def __init__(self, config: RplidarConfig, clock: Clock | None = None) -> None:
        problems = config.validate()
        if problems:
            raise ValueError(f"rplidar on {config.port}: " + "; ".join(problems))
        self.config = config
        self.clock: Clock = clock or MonotonicClock()
        self._transport = SerialTransport(SerialSettings(config.port, config.baudrate))
        self._lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._halt = threading.Event()
        self._state = DeviceState.CLOSED
        self._info: RplidarInfo | None = None
        self._reset_scan_state()

    def _reset_scan_state(self) -> None:
        self._scan: LaserScan | None = None
        self._fault: RplidarError | None = None
        self._last_good = math.inf  # time.monotonic() of the last complete revolution
        self._scans = 0
        self._rejected = 0
        self._corrupt = 0
        self._recent: collections.deque[tuple[float, int]] = collections.deque(maxlen=200)
        self._since = _Since()

    # ------------------------------------------------------------------ lifecycle
    @property
    def port(self) -> str:
        return self.config.port

    @property
    def state(self) -> DeviceState:
        with self._lock:
            return self._state

    def connect(self) -> RplidarInfo:
        """Open the port, stop any scan in progress and read info, health, sample rate
        and motor control. Setup only: blocks at most about ``4 * response_timeout``.

        Raises :class:`RplidarPortError` (cannot open), :class:`RplidarTimeout`,
        :class:`RplidarCorruptStream`, :class:`RplidarLinkLost` or
        :class:`RplidarHealthError` (status ERROR); the port is closed again on any.
        """
        if self.state is DeviceState.LOST:
            self.close()
        with self._lock:
            if self._state is not DeviceState.CLOSED and self._info is not None:
                return self._info
            try:
                self._transport.open()
            except LinkError as e:
                self._transport.close()
                raise RplidarPortError(self.port, e.detail) from e
            self._state = DeviceState.IDLE
        try:
            info = self._identify()
        except (RplidarError, LinkError) as e:
            self._transport.close()
            with self._lock:
                self._state = DeviceState.CLOSED
            if isinstance(e, LinkError):
                raise RplidarLinkLost(self.port, f"link failed: {e.detail}") from e
            raise
        with self._lock:
            self._info = info
        d = info.device
        log.info("rplidar on %s: %s firmware %s hardware %d serial %s, health %s, motor %s",
                 self.port, d.model_name, d.firmware, d.hardware, d.serial_text,
                 info.health.status.name, info.motor_control)
        return info

    def _identify(self) -> RplidarInfo:
        t = self._transport
        dtr = t.set_dtr(True)  # asserted DTR stops the motor (vendor SDK)
        if not dtr:
            log.debug("rplidar on %s: the port has no DTR line (a pseudo-terminal?)", self.port)
        t.write(c.encode_request(c.Command.STOP))
        time.sleep(STOP_SETTLE)
        t.reset_input()
        device = c.decode_info(self._ask(c.Command.GET_INFO)[0])
        health = c.decode_health(self._ask(c.Command.GET_HEALTH)[0])
        if health.status is c.HealthStatus.ERROR:
            raise RplidarHealthError(self.port, health)
        if health.status is c.HealthStatus.WARNING:
            log.warning("rplidar on %s: health WARNING (error code 0x%04X)", self.port, health.error_code)
        rate = c.decode_sample_rate(self._ask(c.Command.GET_SAMPLERATE)[0])
        try:
            flags = c.decode_acc_board_flag(self._ask(c.Command.GET_ACC_BOARD_FLAG, c.get_acc_board_flag())[0])
        except RplidarTimeout:
            # the vendor SDK's rule: firmware without the accessory board does not answer
            log.info("rplidar on %s: no answer to GET_ACC_BOARD_FLAG: no SET_MOTOR_PWM", self.port)
            flags = 0
        return RplidarInfo(device, health, rate, bool(flags & c.ACC_BOARD_MOTOR_CONTROL), dtr)

    def _ask(self, cmd: c.Command, request: bytes | None = None) -> tuple[bytes, bytes]:
        """Send ``cmd`` and wait up to ``response_timeout`` for its descriptor (and data).

        Returns ``(data, rest)``: the answer's data and the bytes that followed it."""
        t, timeout = self._transport, self.config.response_timeout
        expected = c.response_descriptor(cmd)
        t.write(request if request is not None else c.encode_request(cmd))
        deadline = time.monotonic() + timeout
        buf = bytearray()
        seen = 0
        while True:
            found = c.find_response(buf, expected)
            if found is not None:
                end, data = found
                return data, bytes(buf[end:])
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                if seen:
                    raise RplidarCorruptStream(
                        self.port, f"no valid answer to {cmd.name} within {timeout:g} s, {seen} bytes of "
                        "something else (noise, wrong baud rate, another device on this port?)")
                raise RplidarTimeout(
                    self.port, f"no answer to {cmd.name} within {timeout:g} s (is the lidar powered "
                    "and its USB adapter plugged in?)")
            chunk = t.wait_readable(min(remaining, 0.05))
            seen += len(chunk)
            buf += chunk
            if len(buf) > _SEARCH_WINDOW:
                del buf[: len(buf) - _SEARCH_WINDOW]

    def start(self) -> None:
        """Motor on, SCAN, and the reader thread. Returns at once once the SCAN descriptor
        arrived (within ``response_timeout``); scans follow after the motor spun up.

        Raises :class:`RplidarNotConnected`, :class:`RplidarMotorError`,
        :class:`RplidarTimeout` / :class:`RplidarCorruptStream` (no SCAN descriptor; the
        motor is switched off again) or :class:`RplidarLinkLost`."""
        with self._lock:
            if self._state is DeviceState.SCANNING:
                return
            if self._state is not DeviceState.IDLE or self._info is None:
                raise RplidarNotConnected(self.port, f"link {self._state.value} (call connect() first)")
            info = self._info
        cfg = self.config
        try:
            dtr = self._transport.set_dtr(False)
            if info.motor_pwm_supported:
                self._transport.write(c.set_motor_pwm(cfg.motor_pwm))
            if not (dtr or info.motor_pwm_supported):
                raise RplidarMotorError(
                    self.port, "cannot start the motor: the port has no DTR line and the firmware "
                    "reports no motor control (GET_ACC_BOARD_FLAG)")
            _data, rest = self._ask(c.Command.SCAN)
        except (RplidarError, LinkError) as e:
            self._motor_off()
            if isinstance(e, LinkError):
                raise RplidarLinkLost(self.port, f"link failed: {e.detail}") from e
            raise
        with self._lock:
            self._reset_scan_state()
            now = time.monotonic()
            self._last_good = now + cfg.spinup_timeout
            self._since.last_byte = self._since.last_node = self._since.last_start = now
            self._state = DeviceState.SCANNING
            self._halt.clear()
            self._thread = threading.Thread(target=self._run, args=(rest,), name=f"rplidar-scan {self.port}",
                                            daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop the reader, send STOP and switch the motor off; the link stays open."""
        self._join_reader()
        with self._lock:
            if self._state is DeviceState.SCANNING:
                self._state = DeviceState.IDLE
        self._motor_off()

    def close(self) -> None:
        """STOP, motor off, close the port. Idempotent; never raises."""
        self._join_reader()
        self._motor_off()
        self._transport.close()
        with self._lock:
            self._state = DeviceState.CLOSED
            self._info = None

    def _join_reader(self) -> None:
        with self._lock:
            th, self._thread = self._thread, None
        self._halt.set()
        if th is not None and th is not threading.current_thread():
            th.join(timeout=2.0)

    def _motor_off(self) -> None:
        """STOP, PWM 0 when supported, DTR asserted; link errors are logged (the port may
        be gone: then the device is unpowered or has lost its host anyway)."""
        if not self._transport.is_open:
            return
        info = self._info
        try:
            self._transport.write(c.encode_request(c.Command.STOP))
            time.sleep(STOP_SETTLE)
            if info is not None and info.motor_pwm_supported:
                self._transport.write(c.set_motor_pwm(0))
            self._transport.set_dtr(True)
            self._transport.reset_input()
        except LinkError as e:
            log.warning("rplidar on %s: could not stop the scan and the motor: %s", self.port, e.detail)

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ API (any thread)
    def info(self) -> RplidarInfo | None:
        """What connect() read (None before)."""
        with self._lock:
            return self._info

    @property
    def fault(self) -> RplidarError | None:
        """The active fault (:class:`RplidarWatchdog`, :class:`RplidarLinkLost`), or None."""
        with self._lock:
            self._check_stale_locked()
            return self._fault

    def latest_scan(self) -> LaserScan | None:
        """The newest complete scan; None before the first one and while a fault is
        active. Never blocks (beyond a lock held for microseconds)."""
        with self._lock:
            self._check_stale_locked()
            if self._fault is not None or self._state is not DeviceState.SCANNING:
                return None
            return self._scan

    def stats(self, window: float = 2.0) -> RplidarStats:
        """Counters, and scan rate / points per revolution over the last ``window`` s."""
        with self._lock:
            now = time.monotonic()
            recent = [(t, n) for t, n in self._recent if now - t <= window]
            rate = points = None
            if len(recent) >= 2 and recent[-1][0] > recent[0][0]:
                rate = (len(recent) - 1) / (recent[-1][0] - recent[0][0])
            if recent:
                points = sum(n for _t, n in recent) / len(recent)
            return RplidarStats(self._scans, self._rejected, self._corrupt, rate, points)

    def _check_stale_locked(self) -> None:
        """The watchdog, also from the caller's side (the reader might be starved)."""
        if self._fault is None and self._state is DeviceState.SCANNING:
            late = time.monotonic() - self._last_good
            if late > self.config.watchdog_timeout:
                self._raise_watchdog_locked(late)

    # ------------------------------------------------------------------ reader thread
    def _run(self, first: bytes) -> None:
        parser = c.NodeParser()
        assembler = sc.RevolutionAssembler()
        data = first
        while not self._halt.is_set():
            stamp = self.clock.now()
            before = parser.dropped
            parsed = parser.feed(data) if data else []
            for skipped, node in parsed:
                rev = assembler.push(skipped, node, stamp)
                if rev is not None:
                    self._finish(rev)
            now = time.monotonic()
            with self._lock:
                dropped = parser.dropped - before
                self._corrupt += dropped
                since = self._since
                since.bytes += len(data)
                since.dropped += dropped
                if data:
                    since.last_byte = now
                if parsed:
                    since.last_node = now
                if any(node.start for _skipped, node in parsed):
                    since.last_start = now
                self._check_stale_locked()
            try:
                data = self._transport.wait_readable(0.02)
            except LinkError as e:
                with self._lock:
                    self._fault = RplidarLinkLost(self.port, f"link failed: {e.detail}")
                    self._state = DeviceState.LOST
                log.error("%s", self._fault)
                return

    def _finish(self, rev: sc.Revolution) -> None:
        """Check one revolution and publish it as the newest scan."""
        nodes = sc.drop_out_of_order(rev.nodes)
        corrupt = rev.corrupt_bytes + c.NODE_SIZE * (len(rev.nodes) - len(nodes))
        why = sc.check_revolution(nodes, corrupt, rev.travel_q6)
        if why:
            self._reject(why)
            return
        cfg = self.config
        ranges, intensities = sc.resample(nodes, cfg.beams)
        ranges.flags.writeable = False
        intensities.flags.writeable = False
        scan = LaserScan(angle_min=-math.pi, angle_increment=2.0 * math.pi / cfg.beams, ranges=ranges,
                         range_min=cfg.range_min, range_max=cfg.range_max, stamp=rev.stamp,
                         T_base_lidar=np.eye(4), intensities=intensities)
        now = time.monotonic()
        with self._lock:
            self._scan = scan
            self._scans += 1
            self._recent.append((now, len(nodes)))
            self._last_good = now
            self._since.restart()
            if isinstance(self._fault, RplidarWatchdog):
                log.info("rplidar on %s: complete scans again", self.port)
                self._fault = None

    def _reject(self, why: str) -> None:
        log.debug("rplidar on %s: revolution rejected: %s", self.port, why)
        with self._lock:
            self._rejected += 1
            self._since.rejected += 1
            self._since.why = why

    def _raise_watchdog_locked(self, late: float) -> None:
        """Set the watchdog fault, its cause from the second half of the window: what
        stopped (bytes, valid nodes, start flags) or what arrives mangled."""
        since, now = self._since, time.monotonic()
        recent = self.config.watchdog_timeout / 2.0
        if now - since.last_byte > recent:
            cause, detail = ScanFault.NO_DATA, (f"no data for {now - since.last_byte:.2f} s (motor stopped, "
                                                "lidar silent or cable loose?)")
        elif now - since.last_node > recent:
            cause, detail = ScanFault.CORRUPT, (f"bytes without one valid measurement node for "
                                                f"{now - since.last_node:.2f} s (noise or wrong baud rate?)")
        elif since.dropped:  # a clean stream drops no byte at all
            cause, detail = ScanFault.CORRUPT, (f"corrupt stream: {since.dropped} of {since.bytes} bytes "
                                                f"dropped, {since.rejected} revolutions rejected "
                                                f"(last: {since.why or 'none finished'})")
        elif now - since.last_start > recent:
            cause, detail = ScanFault.NO_START_FLAG, (f"nodes without a start flag for "
                                                      f"{now - since.last_start:.2f} s")
        else:
            cause, detail = ScanFault.INCOMPLETE, (f"{since.rejected} revolutions incomplete "
                                                   f"(last: {since.why or 'none finished'})")
        self._fault = RplidarWatchdog(self.port, cause, late, detail)
        log.warning("%s", self._fault)
