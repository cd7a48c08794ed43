"""An RPLIDAR A2 that speaks the real serial protocol on a pseudo-terminal.

Written from the vendor document (docs/protocols.md section 5, Slamtec LR001)::

    with RplidarFake() as fake:            # a 6 m x 4 m room, the lidar in its middle
        dev = RplidarDevice(RplidarConfig(port=fake.port))
        ...
        fake.motor_stopped = True          # the motor jams: no more nodes

or from a shell: ``mmexec hw fake rplidar`` prints the port and serves until Ctrl-C.

What it does (5.4):

* answers GET_INFO (model 0x28 = A2M8), GET_HEALTH, GET_SAMPLERATE and
  GET_ACC_BOARD_FLAG with their descriptors and data; takes SET_MOTOR_PWM when it
  reports motor control; ignores (and counts) requests with a wrong checksum;
* SCAN / FORCE_SCAN: the descriptor ``A5 5A 05 00 00 40 81``, then 5-byte nodes at the
  sample rate while the motor runs: the motor runs while DTR is cleared or PWM > 0 (a pty
  has no DTR line: tests set :attr:`FakeRplidarState.dtr` as the adapter would see it);
  SCAN waits ``spinup`` seconds for a stable speed, FORCE_SCAN does not; the revolution
  rate is ``scan_rate`` at PWM 660 (proportional to the PWM, 2-20 Hz);
* STOP leaves scan mode; RESET also stops the motor's PWM and prints a text banner;
  in health ERROR (protection stop) SCAN is not answered;
* angles clockwise seen from above, with the start flag on the first node of each turn;
  ranges cast from the lidar's pose into a :class:`Room` (walls and round posts), with
  Gaussian noise; posts marked ``reflector`` return quality 63, other surfaces 47 - 2 per
  metre (at least 10); nothing within 0.15-12 m is distance 0, quality 0.

Fault switches: :attr:`silent` and :meth:`unplug` (from :class:`PtyDevice`),
:attr:`garbage` (random bytes instead of answers and nodes), :meth:`set_health`,
:attr:`motor_stopped` (no nodes whatever is commanded), :attr:`no_start_flag`,
:attr:`bad_check_bits` / :attr:`bad_start_bits` (fraction of nodes with C = 0 or
S == not-S), :attr:`truncate` (fraction of nodes cut to 1-4 bytes).
Time is the wall clock (``time.monotonic()``); after a stall the fake skips the nodes it
could not send, as a UART would lose them.
"""

from __future__ import annotations

import logging
import math
import random
import threading
import time
from dataclasses import dataclass, field, replace

from mmexec.drivers.fakes.pty import PtyDevice
from mmexec.drivers.rplidar import codec as c

__all__ = ["FakeRplidarState", "Post", "Room", "RplidarFake"]

log = logging.getLogger(__name__)

RANGE_MIN = 0.15  # m, closer surfaces give no valid return
RANGE_MAX = 12.0  # m
REFLECTOR_QUALITY = 63
BANNER = b"RP LIDAR System.\r\nFirmware Ver 1.29 - rtm, HW Ver 7\r\nModel: 28\r\n"
_MAX_NODES_PER_TICK = 400  # after a stall, send at most this many at once (the rest is lost)


@dataclass(frozen=True)
class Post:
    """A round post at (``x``, ``y``) [m] with ``radius`` [m]; ``reflector``: covered in
    retro-reflective tape (highest quality)."""

    x: float
    y: float
    radius: float
    reflector: bool = False


@dataclass(frozen=True)
class Room:
    """Walls of the rectangle [0, ``width``] x [0, ``depth``] [m] and round posts."""

    width: float = 6.0
    depth: float = 4.0
    posts: tuple[Post, ...] = (
        Post(1.0, 1.0, 0.05, reflector=True),
        Post(5.0, 3.0, 0.05, reflector=True),
        Post(4.5, 1.0, 0.10),
    )

    def cast(self, x: float, y: float, heading: float) -> tuple[float, bool]:
        """Distance [m] from (x, y) along ``heading`` [rad, CCW from the room's +x] to the
        first surface, and whether it is a reflector."""
        dx, dy = math.cos(heading), math.sin(heading)
        best, reflector = math.inf, False
        for pos, d, hi in ((x, dx, self.width), (y, dy, self.depth)):
            if d > 1e-12:
                best = min(best, (hi - pos) / d)
            elif d < -1e-12:
                best = min(best, -pos / d)
        for p in self.posts:
            ox, oy = x - p.x, y - p.y
            b = ox * dx + oy * dy
            disc = b * b - (ox * ox + oy * oy - p.radius * p.radius)
            if disc >= 0.0:
                t = -b - math.sqrt(disc)
                if 0.0 < t < best:
                    best, reflector = t, p.reflector
        return best, reflector


@dataclass
class FakeRplidarState:
    """What the fake lidar is doing and what the host asked of it (for assertions)."""

    dtr: bool = True                 # adapter DTR as the device sees it; asserted = motor off
    pwm: int = 0                     # last SET_MOTOR_PWM duty
    scanning: bool = False
    force: bool = False              # FORCE_SCAN (no wait for a stable speed)
    health: c.Health = field(default_factory=lambda: c.Health(c.HealthStatus.GOOD, 0))
    requests: list[int] = field(default_factory=list)  # command bytes, in arrival order
    pwm_commands: list[int] = field(default_factory=list)
    stops: int = 0
    resets: int = 0
    bad_requests: int = 0
    nodes_sent: int = 0
    revolutions: int = 0


class RplidarFake(PtyDevice):
    """RPLIDAR A2 protocol fake on a pty (see the module doc). Thread-safe controls."""

    tick_period = 0.005

    def __init__(
        self,
        *,
        room: Room | None = None,
        pose: tuple[float, float, float] = (3.0, 2.0, 0.0),
        scan_rate: float = 10.0,
        sample_rate: float = 2000.0,
        noise: float = 0.005,
        spinup: float = 0.2,
        motor_control: bool = True,
        info: c.DeviceInfo | None = None,
        seed: int = 0,
        name: str = "rplidar-fake",
    ) -> None:
        """``pose``: the lidar in the room: x, y [m] and the heading [rad, CCW] of its
        0 degree direction; ``scan_rate`` [Hz] at PWM 660; ``sample_rate`` [samples/s]
        (A2 standard scan: 2000); ``noise`` range std [m]; ``spinup`` [s];
        ``motor_control``: GET_ACC_BOARD_FLAG reports SET_MOTOR_PWM support."""
        super().__init__(name)
        self.room = room or Room()
        self.pose = pose
        self.scan_rate = scan_rate
        self.sample_period = 1.0 / sample_rate
        self.noise = noise
        self.spinup = spinup
        self.motor_control = motor_control
        self.info = info or c.DeviceInfo(0x28, 1, 29, 7, bytes(range(0x10, 0x20)))
        self.state = FakeRplidarState()
        self.garbage = False
        self.motor_stopped = False
        self.no_start_flag = False
        self.bad_check_bits = 0.0
        self.bad_start_bits = 0.0
        self.truncate = 0.0
        self._rng = random.Random(seed)
        self._parser = c.RequestParser()
        self._mutex = threading.RLock()
        self._spinning_since: float | None = None
        self._stream_t = 0.0       # time.monotonic() up to which nodes have been sent
        self._phase = 0.0          # deg, clockwise, of the next node

    # ------------------------------------------------------------------ test controls
    def set_health(self, status: c.HealthStatus | int, error_code: int = 0) -> None:
        """What GET_HEALTH reports: 0 good, 1 warning, 2 error (protection stop)."""
        with self._mutex:
            self.state.health = c.Health(c.HealthStatus(status), error_code)

    def set_dtr(self, asserted: bool) -> None:
        """The adapter's DTR line as the device sees it (a pty carries none)."""
        with self._mutex:
            self.state.dtr = asserted

    def snapshot(self) -> FakeRplidarState:
        """A copy of the state, consistent at one instant."""
        with self._mutex:
            s = self.state
            return replace(s, requests=list(s.requests), pwm_commands=list(s.pwm_commands))

    @property
    def motor_running(self) -> bool:
        with self._mutex:
            return self._motor_running()

    def _motor_running(self) -> bool:
        s = self.state
        return not self.motor_stopped and (not s.dtr or s.pwm > 0)

    def revolution_rate(self) -> float:
        """Revolutions per second at the present PWM (``scan_rate`` when DTR alone runs it)."""
        with self._mutex:
            pwm = self.state.pwm
        rate = self.scan_rate * pwm / c.DEFAULT_MOTOR_PWM if pwm > 0 else self.scan_rate
        return min(20.0, max(2.0, rate))

    # ------------------------------------------------------------------ requests
    def on_bytes(self, data: bytes) -> None:
        out = b""
        with self._mutex:
            before = self._parser.bad_checksum
            requests = self._parser.feed(data)
            self.state.bad_requests += self._parser.bad_checksum - before
            for r in requests:
                self.state.requests.append(r.cmd)
                out += self._answer(r)
            if self.garbage:
                out = b""
        self.send(out)

    def _answer(self, r: c.Request) -> bytes:
        s = self.state
        cmd = r.cmd
        if cmd == c.Command.STOP:
            s.scanning = False
            s.stops += 1
        elif cmd == c.Command.RESET:
            s.scanning = False
            s.pwm = 0
            s.resets += 1
            return BANNER
        elif cmd in (c.Command.SCAN, c.Command.FORCE_SCAN):
            if s.health.status is c.HealthStatus.ERROR:
                return b""  # protection stop: no scanning until RESET
            s.scanning, s.force = True, cmd == c.Command.FORCE_SCAN
            self._stream_t = time.monotonic()
            return self._respond(c.Command(cmd), b"")
        elif cmd == c.Command.GET_INFO:
            return self._respond(c.Command.GET_INFO, c.encode_info(self.info))
        elif cmd == c.Command.GET_HEALTH:
            return self._respond(c.Command.GET_HEALTH, c.encode_health(s.health))
        elif cmd == c.Command.GET_SAMPLERATE:
            us = round(self.sample_period * 1e6)
            return self._respond(c.Command.GET_SAMPLERATE, c.encode_sample_rate(c.SampleRate(us, us // 2)))
        elif cmd == c.Command.GET_ACC_BOARD_FLAG:
            flags = c.ACC_BOARD_MOTOR_CONTROL if self.motor_control else 0
            return self._respond(c.Command.GET_ACC_BOARD_FLAG, c.encode_acc_board_flag(flags))
        elif cmd == c.Command.SET_MOTOR_PWM and len(r.payload) == 2:
            pwm = r.payload[0] | (r.payload[1] << 8)
            s.pwm_commands.append(pwm)
            if self.motor_control and pwm <= c.MAX_MOTOR_PWM:
                s.pwm = pwm
        else:
            log.debug("%s: ignoring request 0x%02X %s", self.name, cmd, r.payload.hex())
        return b""

    @staticmethod
    def _respond(cmd: c.Command, data: bytes) -> bytes:
        d = c.response_descriptor(cmd)
        return c.encode_descriptor(d.length, d.mode, d.data_type) + data

    # ------------------------------------------------------------------ stream
    def on_tick(self, now: float) -> None:
        with self._mutex:
            if self.garbage:
                n = max(1, round(10000 * self.tick_period))  # about the line's byte rate
                out = bytes(self._rng.getrandbits(8) for _ in range(n))
            else:
                out = self._stream(now)
        self.send(out)

    def _stream(self, now: float) -> bytes:
        s = self.state
        if not self._motor_running():
            self._spinning_since = None
            self._stream_t = now
            return b""
        if self._spinning_since is None:
            self._spinning_since = now
        if not s.scanning or (not s.force and now - self._spinning_since < self.spinup):
            self._stream_t = now
            return b""
        due = int((now - self._stream_t) / self.sample_period)
        if due <= 0:
            return b""
        self._stream_t += due * self.sample_period
        due = min(due, _MAX_NODES_PER_TICK)
        step = 360.0 * self.revolution_rate() * self.sample_period  # deg per sample
        out = bytearray()
        for _ in range(due):
            start = self._phase < step
            out += self._node(self._phase, start)
            self._phase = (self._phase + step) % 360.0
        return bytes(out)

    def _node(self, angle_deg: float, start: bool) -> bytes:
        s, rng = self.state, self._rng
        s.nodes_sent += 1
        if start:
            s.revolutions += 1
        x, y, yaw = self.pose
        jitter = rng.uniform(-0.05, 0.05)
        angle = min(max(angle_deg + jitter, 0.0), 360.0 - 1.0 / 64.0)
        r, reflector = self.room.cast(x, y, yaw - math.radians(angle))  # clockwise angles
        r += rng.gauss(0.0, self.noise) if self.noise > 0 else 0.0
        if RANGE_MIN <= r <= RANGE_MAX:
            quality = REFLECTOR_QUALITY if reflector else max(10, round(47 - 2 * r))
            dist_q2 = round(r * 4000.0)
        else:
            quality, dist_q2 = 0, 0
        node = c.MeasurementNode(start and not self.no_start_flag, quality, round(angle * 64), dist_q2)
        raw = bytearray(c.encode_node(node))
        if self.bad_check_bits and rng.random() < self.bad_check_bits:
            raw[1] &= 0xFE  # C = 0
        if self.bad_start_bits and rng.random() < self.bad_start_bits:
            raw[0] |= 0x03  # S == not-S
        if self.truncate and rng.random() < self.truncate:
            del raw[rng.randint(1, 4):]
        return bytes(raw)
