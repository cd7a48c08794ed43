"""Fake Robotiq 2F-85 grippers: a Modbus RTU slave on a pty and a URCap text server on TCP.

Users rehearse bring-up with these (``mmexec hw fake robotiq``) and the tests drive the real
driver against them. Both share :class:`GripperModel`, a small model of the gripper's
firmware built from docs/protocols.md section 3:

* states reset (gSTA 0), activating (gSTA 1) and activated (gSTA 3). Activation takes
  ``activation_time`` s of gripper time (default 2 s: "seconds, not milliseconds" in the
  vendor sequence of docs/protocols.md 3.3; the exact figure is not published), during
  which the fingers travel fully: closed in the first half, back open in the second
  (gPO shows it). ``activation_time = math.inf`` is an activation that never completes;
  lowering it later lets a held activation finish;
* finger motion toward rPR at the speed rSP stands for (0.02..0.15 m/s over the 85 mm
  stroke), gCU while moving or squeezing, gPR echoing the accepted rPR;
* an optional object between the fingers (``object_width`` [m]) that stops them while
  closing (gOBJ 2), and one outside them (``outer_object_width``) that stops them while
  opening (gOBJ 1); :meth:`GripperModel.drop_object` takes the object away;
* a gripper stopped on an object moves again only for a new position, a higher force or
  rGTO toggled 0 then 1;
* faults with their recovery rules: 0x05 when rGTO arrives during activation (the move
  then runs once activation ends), 0x07 when rGTO is set with rACT = 0, 0x08 while
  ``temperature`` >= 85 C (clears below 80 C), 0x09 "no communication" once an activated
  gripper has had no request for more than ``comm_timeout`` s (1 s, the vendor's figure);
  traffic clears it, the first ``comm_fault_answers`` answers (default 1) still reporting
  it (whether the very first answer does is unconfirmed, so it is a switch), major faults 0x0A / 0x0C / 0x0E injected with
  :meth:`GripperModel.inject_fault` and 0x0D when ``activation_fault`` is set; majors stay
  until rACT goes 0 then 1; automatic release (rATR) gives 0x0B, then 0x0F.

:class:`FakeRobotiq` is slave 9 on a pseudo-terminal: FC03/04/06/16/23 on the two register
blocks, silence for bad-CRC frames, other slave ids, unknown functions and addresses
outside the blocks; fault switches ``no_reply`` (requests understood, never answered) and
``corrupt_replies`` (answers with a broken CRC), and for link-quality tests ``drop_every``
/ ``corrupt_every`` (every n-th answer lost / with a broken CRC; 0 = off), on top of the
PtyDevice ones (``silent``,
``unplug()``, ``inject()``).

:class:`FakeURCap` serves the URCap's text protocol on 127.0.0.1 (ephemeral port by
default): ``SET VAR n ...`` -> ``ack``, ``GET VAR`` -> ``VAR n``, and ``VAR ?`` for every
GET while ``estop`` is set (writes during the e-stop are acknowledged and dropped, an
assumption). ``GET POS`` answers the measured position (as ur_rtde reads it).
Time runs ``time_scale`` times faster than the wall clock in both fakes (tests use > 1).
"""

from __future__ import annotations

import logging
import selectors
import socket
import threading
import time
from typing import Self

from mmexec.drivers.fakes.pty import PtyDevice
from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.codec import Command, Status
from mmexec.drivers.robotiq.errors import FAULTS, FrameError

__all__ = ["FakeRobotiq", "FakeURCap", "GripperModel"]

log = logging.getLogger(__name__)

_MAJOR = frozenset(c for c, (info, _) in FAULTS.items() if info.fault_class == "major")


class GripperModel:
    """The gripper's firmware, stepped by the fakes. Thread-safe; times are
    ``time.monotonic()`` seconds, scaled by ``time_scale``; ``start`` is the time the
    model begins at (default now; a test stepping it by hand passes its own)."""

    def __init__(
        self,
        *,
        activation_time: float = 2.0,
        time_scale: float = 1.0,
        object_width: float | None = None,
        outer_object_width: float | None = None,
        open_limit: int = 0,
        closed_limit: int = 255,
        comm_timeout: float = 1.0,
        comm_fault_answers: int = 1,
        start: float | None = None,
    ) -> None:
        if not 0 <= open_limit < closed_limit <= 255:
            raise ValueError("need 0 <= open_limit < closed_limit <= 255")
        self.activation_time = activation_time
        self.time_scale = time_scale
        self.object_width = object_width
        self.outer_object_width = outer_object_width
        self.open_limit, self.closed_limit = open_limit, closed_limit
        self.comm_timeout = comm_timeout
        self.comm_fault_answers = comm_fault_answers
        self._comm_fault_left = 0
        self.activation_fault = False
        self.temperature = 35.0  # C
        self._lock = threading.RLock()
        self._cmd = Command()
        self._gACT = self._gGTO = False
        self._gSTA = self._gOBJ = self._gFLT = self._gPR = 0
        self._pos = float(open_limit)
        self._target = float(open_limit)
        self._moving = False
        self._releasing = False
        self._pending_move = False
        self._act_elapsed = 0.0  # gripper seconds since the rising edge on rACT
        self._act_from = float(open_limit)
        self._last = time.monotonic() if start is None else start
        self._last_rx = self._last
        self.writes: list[Command] = []
        self.delayed_actions = 0  # moves requested during activation (each raised 0x05)

    # ------------------------------------------------------------------ observers
    def status(self) -> Status:
        with self._lock:
            if self._moving or self._releasing:
                cu = 20 + self._cmd.rFR // 16
            elif self._gOBJ in (1, 2) and self._gGTO:
                cu = 10 + self._cmd.rFR // 4
            else:
                cu = 0
            return Status(self._gACT, self._gGTO, self._gSTA, self._gOBJ, self._gFLT, 0,
                          self._gPR, round(self._pos), min(cu, 255))

    @property
    def command(self) -> Command:
        with self._lock:
            return self._cmd

    # ------------------------------------------------------------------ fault switches
    def inject_fault(self, code: int) -> None:
        """Raise gFLT ``code``: 0x08 heats the gripper to 90 C (cool() clears it), 0x09
        clears after ``comm_fault_answers`` answered requests, majors stop the fingers until
        rACT 0 then 1."""
        with self._lock:
            if code == 0x08:
                self.temperature = 90.0
            elif code not in _MAJOR and code != 0x09:
                raise ValueError(f"cannot inject gFLT 0x{code:02X} (it follows from commands)")
            if code == 0x09:
                self._comm_fault_left = self.comm_fault_answers
            self._gFLT = code
            self._moving = False

    def cool(self, temperature: float = 70.0) -> None:
        """Set the internal temperature [C]; below 80 C an over-temperature fault clears."""
        with self._lock:
            self.temperature = temperature

    def drop_object(self) -> None:
        """Take the object away: held fingers resume toward their target."""
        with self._lock:
            self.object_width = None
            self.outer_object_width = None
            if self._gOBJ in (1, 2) and self._gGTO and self._gSTA == 3:
                self._gOBJ = 0
                self._moving = True

    # ------------------------------------------------------------------ requests
    def touch(self, now: float) -> None:
        """A request arrived: traffic again (0x09 clears after the answers, see
        :meth:`after_request`)."""
        with self._lock:
            self.step(now)
            self._last_rx = now

    def after_request(self) -> None:
        """A request was answered: the ``comm_fault_answers``-th answer since traffic
        resumed was the last to report 0x09."""
        with self._lock:
            if self._gFLT == 0x09:
                self._comm_fault_left -= 1
                if self._comm_fault_left <= 0:
                    self._gFLT = 0

    def write(self, cmd: Command, now: float) -> None:
        """Apply new robot output bytes."""
        with self._lock:
            self.step(now)
            prev, self._cmd = self._cmd, cmd
            self.writes.append(cmd)
            if not cmd.rACT:
                self._gACT = self._gGTO = False
                self._gSTA, self._gOBJ = 0, 0
                self._moving = self._releasing = self._pending_move = False
                if self._gFLT in (0x05, 0x07):
                    self._gFLT = 0
                if cmd.rGTO and self._gFLT == 0:
                    self._gFLT = 0x07
                return
            if not prev.rACT:  # rising edge on rACT
                if self._gFLT in _MAJOR or self._gFLT in (0x05, 0x07):
                    self._gFLT = 0
                self._gACT = True
                self._gSTA = 1
                self._gOBJ = 0
                self._act_elapsed = 0.0
                self._act_from = self._pos
                self._moving = False
            if cmd.rATR:
                if not self._releasing and self._gFLT != 0x0F:
                    self._releasing = True
                    self._moving = False
                    self._gFLT = 0x0B
                    self._gSTA = 0
                return
            if self._gFLT in _MAJOR or self._gFLT == 0x08:
                self._gGTO = cmd.rGTO
                return
            if not cmd.rGTO:
                self._gGTO = False
                self._moving = False
                self._pending_move = False
                return
            if self._gSTA == 1:
                self._gFLT = 0x05
                self._pending_move = True
                self.delayed_actions += 1
                return
            if self._gSTA == 3:
                self._start_move(prev)

    def _start_move(self, prev: Command) -> None:
        cmd = self._cmd
        fresh = (not self._gGTO or cmd.rPR != self._gPR or cmd.rFR > prev.rFR)
        self._gGTO = True
        self._gPR = cmd.rPR
        if self._gOBJ in (1, 2) and not fresh:
            return  # stopped on an object: only a new position / more force / rGTO toggle
        self._target = float(min(max(cmd.rPR, self.open_limit), self.closed_limit))
        self._gOBJ = 0
        self._moving = True

    # ------------------------------------------------------------------ time
    def step(self, now: float) -> None:
        """Advance the firmware to ``now`` (time.monotonic())."""
        with self._lock:
            dt = max(0.0, now - self._last) * self.time_scale
            self._last = now
            if self.temperature >= 85.0 and self._gFLT == 0:
                self._gFLT = 0x08
                self._moving = False
            elif self._gFLT == 0x08 and self.temperature < 80.0:
                self._gFLT = 0
                if self._cmd.rGTO and self._gSTA == 3:
                    self._start_move(self._cmd)
            if (self._gSTA == 3 and self._gFLT == 0
                    and (now - self._last_rx) * self.time_scale > self.comm_timeout):
                self._gFLT = 0x09
                self._comm_fault_left = self.comm_fault_answers
            if self._gSTA == 1:
                self._step_activation(dt)
            if self._releasing:
                self._step_release(dt)
            elif self._moving:
                self._step_motion(dt)

    def _step_activation(self, dt: float) -> None:
        """Fingers travel fully while activating: to closed, then back to open."""
        self._act_elapsed += dt
        if self._act_elapsed >= self.activation_time:
            self._finish_activation()
            return
        half = self.activation_time / 2
        closed, opened = float(self.closed_limit), float(self.open_limit)
        if self._act_elapsed < half:
            self._pos = self._act_from + (closed - self._act_from) * self._act_elapsed / half
        else:
            self._pos = closed + (opened - closed) * (self._act_elapsed - half) / half

    def _finish_activation(self) -> None:
        if self.activation_fault:
            self._gSTA = 0
            self._gFLT = 0x0D
            self._pending_move = False
            return
        self._gSTA = 3
        self._pos = float(self.open_limit)
        if self._pending_move:
            self._pending_move = False
            if self._gFLT == 0x05:
                self._gFLT = 0
            self._start_move(Command(rACT=True))

    def _units_per_s(self, raw_speed: int) -> float:
        return codec.raw_to_speed(raw_speed) / codec.STROKE * 255

    def _step_release(self, dt: float) -> None:
        end = float(self.closed_limit if self._cmd.rARD else self.open_limit)
        step = self._units_per_s(0) * dt
        if abs(end - self._pos) <= step:
            self._pos = end
            self._releasing = False
            self._gFLT = 0x0F
        else:
            self._pos += step if end > self._pos else -step

    def _step_motion(self, dt: float) -> None:
        step = self._units_per_s(self._cmd.rSP) * dt
        pos, target = self._pos, self._target
        if target > pos:  # closing
            new = min(pos + step, target)
            if self.object_width is not None:
                obstacle = codec.width_to_position(self.object_width)
                if pos <= obstacle < target and new >= obstacle:
                    self._pos, self._moving, self._gOBJ = float(obstacle), False, 2
                    return
        else:  # opening
            new = max(pos - step, target)
            if self.outer_object_width is not None:
                obstacle = codec.width_to_position(self.outer_object_width)
                if pos >= obstacle > target and new <= obstacle:
                    self._pos, self._moving, self._gOBJ = float(obstacle), False, 1
                    return
        self._pos = new
        if new == target:
            self._moving, self._gOBJ = False, 3


# =========================================================================== Modbus RTU


class FakeRobotiq(PtyDevice):
    """A 2F-85 answering Modbus RTU as slave ``slave`` on a pty (``.port``)."""

    tick_period = 0.005
    #: bus silence [s] after which a partial frame is discarded
    frame_gap = 0.01

    def __init__(self, model: GripperModel | None = None, *, slave: int = codec.DEFAULT_SLAVE,
                 name: str = "fake-robotiq", **model_args: object) -> None:
        super().__init__(name)
        self.model = model or GripperModel(**model_args)  # type: ignore[arg-type]
        self.slave = slave
        self.no_reply = False
        self.corrupt_replies = False
        self.drop_every = 0
        self.corrupt_every = 0
        self._answers = 0  # answers the slave had to give (for the every-n-th switches)
        self._buf = bytearray()
        self._rx_time = 0.0
        self._out_regs = [0] * 8
        self.request_times: list[float] = []
        self.dropped_frames = 0

    def on_tick(self, now: float) -> None:
        self.model.step(now)
        if self._buf and now - self._rx_time > self.frame_gap:
            log.debug("%s: discarding %d stray bytes", self.name, len(self._buf))
            self._buf.clear()
            self.dropped_frames += 1

    def on_bytes(self, data: bytes) -> None:
        now = time.monotonic()
        if self._buf and now - self._rx_time > self.frame_gap:
            self._buf.clear()
        self._rx_time = now
        self._buf += data
        while self._buf:
            try:
                n = codec.request_length(bytes(self._buf))
            except FrameError:
                self._drop()
                return
            if n is None or len(self._buf) < n:
                return
            frame, self._buf = bytes(self._buf[:n]), self._buf[n:]
            if frame[0] != self.slave:
                continue
            try:
                req = codec.decode_request(frame)
            except FrameError:
                self._drop()
                return
            self._serve(req, now)

    def _drop(self) -> None:
        self._buf.clear()
        self.dropped_frames += 1

    def _serve(self, req: codec.Request, now: float) -> None:
        self.request_times.append(now)
        self.model.touch(now)
        fc = req.function
        reply: bytes | None = None
        if req.write_values:
            start = req.write_address - codec.OUTPUT_BASE
            if start < 0 or start + len(req.write_values) > len(self._out_regs):
                return  # outside the output block: no exception frames, silence
            self._out_regs[start:start + len(req.write_values)] = list(req.write_values)
            self.model.write(Command.from_bytes(codec.registers_to_bytes(self._out_regs)), now)
            if fc == codec.FC_WRITE_SINGLE:
                reply = frame_echo(req)
            elif fc == codec.FC_WRITE_MULTIPLE:
                reply = codec.encode_write_multiple_reply(req.slave, req.write_address,
                                                          len(req.write_values))
            else:  # FC23: one control cycle between the write and the read
                self.model.step(now + 0.005 / self.model.time_scale)
        if fc in (codec.FC_READ_HOLDING, codec.FC_READ_INPUT, codec.FC_READ_WRITE_MULTIPLE):
            regs = self._read(fc, req.read_address, req.read_count, now)
            if regs is None:
                return
            reply = codec.encode_read_reply(req.slave, fc, regs)
        if reply is not None:
            self._answers += 1
        if reply is None or self.no_reply or _nth(self._answers, self.drop_every):
            self.model.after_request()
            return
        if self.corrupt_replies or _nth(self._answers, self.corrupt_every):
            reply = reply[:-2] + bytes(((reply[-2] ^ 0xFF), reply[-1]))
        self.send(reply)
        self.model.after_request()

    def _read(self, fc: int, address: int, count: int, now: float) -> list[int] | None:
        self.model.step(now)
        in_regs = list(self.model.status().to_registers()) + [0] * 5
        if codec.INPUT_BASE <= address and address + count <= codec.INPUT_BASE + 8:
            start = address - codec.INPUT_BASE
            return in_regs[start:start + count]
        if (fc != codec.FC_READ_INPUT and codec.OUTPUT_BASE <= address
                and address + count <= codec.OUTPUT_BASE + 8):
            start = address - codec.OUTPUT_BASE
            return self._out_regs[start:start + count]
        return None


def _nth(count: int, every: int) -> bool:
    """True for every ``every``-th ``count`` (never when ``every`` is 0)."""
    return every > 0 and count % every == 0


def frame_echo(req: codec.Request) -> bytes:
    """The FC06 reply: an echo of the request."""
    return codec.encode_write_single(req.slave, req.write_address, req.write_values[0])


# =========================================================================== URCap socket

_WRITABLE = ("ACT", "GTO", "ATR", "ARD", "POS", "SPE", "FOR")
_READABLE = _WRITABLE + ("STA", "PRE", "OBJ", "FLT")


class FakeURCap:
    """The URCap gripper server (text protocol of TCP port 63352) on 127.0.0.1.

    ``port`` 0 picks a free ephemeral port (read it back from :attr:`port` after
    :meth:`start`). Switches: ``estop`` (GET answers ``VAR ?``), ``silent`` (requests
    are read, never answered), :meth:`drop_clients` (connection reset), and for
    link-quality tests ``drop_every`` / ``garble_every`` (every n-th answer lost / garbled;
    0 = off); ``answer_delay`` [s] before each answer (a busy controller; it delays the
    whole server, which has one thread)."""

    def __init__(self, model: GripperModel | None = None, *, host: str = "127.0.0.1",
                 port: int = 0, **model_args: object) -> None:
        self.model = model or GripperModel(**model_args)  # type: ignore[arg-type]
        self.host = host
        self._want_port = port
        self.port = 0
        self.estop = False
        self.silent = False
        self.drop_every = 0
        self.garble_every = 0
        self.answer_delay = 0.0
        self._answers = 0
        self._server: socket.socket | None = None
        self._sel: selectors.BaseSelector | None = None
        self._clients: dict[socket.socket, bytearray] = {}
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self.requests: list[str] = []

    def start(self) -> FakeURCap:
        srv = socket.create_server((self.host, self._want_port))
        srv.setblocking(False)
        self._server = srv
        self.port = srv.getsockname()[1]
        self._sel = selectors.DefaultSelector()
        self._sel.register(srv, selectors.EVENT_READ)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="fake-urcap", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        t, self._thread = self._thread, None
        if t is not None:
            t.join(timeout=2.0)
        self.drop_clients()
        if self._sel is not None:
            self._sel.close()
            self._sel = None
        if self._server is not None:
            self._server.close()
            self._server = None

    def drop_clients(self) -> None:
        """Close every client connection (the controller went away)."""
        with self._lock:
            for c in list(self._clients):
                if self._sel is not None:
                    try:
                        self._sel.unregister(c)
                    except (KeyError, ValueError):
                        log.debug("fake-urcap: client already unregistered")
                c.close()
            self._clients.clear()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.is_set():
            sel = self._sel
            if sel is None:
                return
            try:
                events = sel.select(timeout=0.005)
            except (OSError, ValueError):
                return
            now = time.monotonic()
            self.model.step(now)
            for key, _ in events:
                sock = key.fileobj
                assert isinstance(sock, socket.socket)
                if sock is self._server:
                    try:
                        conn, _addr = sock.accept()
                    except OSError:
                        continue
                    conn.setblocking(False)
                    with self._lock:
                        self._clients[conn] = bytearray()
                        sel.register(conn, selectors.EVENT_READ)
                    continue
                self._read_client(sock, now)

    def _read_client(self, conn: socket.socket, now: float) -> None:
        try:
            data = conn.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        with self._lock:
            buf = self._clients.get(conn)
            if buf is None:
                return
            if not data:
                if self._sel is not None:
                    self._sel.unregister(conn)
                conn.close()
                del self._clients[conn]
                return
            buf += data
            lines = []
            while b"\n" in buf:
                line, _, rest = bytes(buf).partition(b"\n")
                buf[:] = rest
                lines.append(line.decode("ascii", "replace").strip())
        for line in lines:
            answer = self.handle(line, now)
            if answer is not None:
                self._answers += 1
                if _nth(self._answers, self.drop_every):
                    continue
                if _nth(self._answers, self.garble_every):
                    answer = answer.replace(" ", "\x7f", 1)
            if answer is not None and not self.silent:
                if self.answer_delay > 0:
                    time.sleep(self.answer_delay)
                try:
                    conn.sendall(answer.encode("ascii") + b"\n")
                except OSError as e:
                    log.debug("fake-urcap: send failed: %s", e)

    def handle(self, line: str, now: float) -> str | None:
        """Answer one request line (without its newline); None: no answer."""
        self.requests.append(line)
        self.model.touch(now)
        try:
            return self._answer(line, now)
        finally:
            self.model.after_request()

    def _answer(self, line: str, now: float) -> str | None:
        words = line.split()
        if len(words) == 2 and words[0] == "GET" and words[1] in _READABLE:
            var = words[1]
            if self.estop:
                return f"{var} ?"
            st, cmd = self.model.status(), self.model.command
            value = {"ACT": int(st.gACT), "GTO": int(st.gGTO), "ATR": int(cmd.rATR),
                     "ARD": int(cmd.rARD), "POS": st.gPO, "SPE": cmd.rSP, "FOR": cmd.rFR,
                     "STA": st.gSTA, "PRE": st.gPR, "OBJ": st.gOBJ, "FLT": st.gFLT}[var]
            return f"{var} {value}"
        if len(words) >= 3 and words[0] == "SET" and len(words) % 2 == 1:
            pairs = list(zip(words[1::2], words[2::2]))
            try:
                values = {k: int(v) for k, v in pairs}
            except ValueError:
                return "nack"
            if any(k not in _WRITABLE or not 0 <= v <= 255 for k, v in values.items()):
                return "nack"
            if self.estop:
                return "ack"
            c = self.model.command
            fields = {"ACT": c.rACT, "GTO": c.rGTO, "ATR": c.rATR, "ARD": c.rARD,
                      "POS": c.rPR, "SPE": c.rSP, "FOR": c.rFR}
            for k, v in values.items():
                fields[k] = v
            self.model.write(Command(bool(fields["ACT"]), bool(fields["GTO"]),
                                     bool(fields["ATR"]), bool(fields["ARD"]),
                                     int(fields["POS"]), int(fields["SPE"]),
                                     int(fields["FOR"])), now)
            return "ack"
        return "nack"
