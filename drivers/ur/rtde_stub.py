"""A small RTDE server (controller side of port 30004) with fault injection, in its own process.

The real ``rtde_receive.RTDEReceiveInterface`` (and ``rtde_io.RTDEIOInterface``) of
ur_rtde 1.6.5 connect to it: it answers ``V``, ``v``, ``O`` (``NOT_FOUND`` for unknown or
injected names), ``I`` (recipe ids 1, 2, 3... per connection in setup order, as the IO
interface assumes), ``S`` and ``P``, and after ``S`` streams ``U`` packages at the recipe
frequency: joint state, robot mode 7 (running), safety mode 1 (normal), runtime state 2
(playing), robot status bits 0b11 (power on, program running), safety status bit 0.
Like the controller, it stamps every package with the time of its sample (``timestamp``
advances by exactly one period per package) and, when it fell behind (a loaded machine),
sends the samples it owes instead of skipping them, up to five seconds' worth.

Why a separate process: ur_rtde's constructors block while holding the Python GIL, so a
server thread in the same interpreter deadlocks them (docs/protocols.md 4.3).

Why port 30004: the ur_rtde 1.6.5 Python constructors take a host but no port, so a stub
the real client talks to must listen on 30004. Tests run several stubs side by side on
distinct loopback addresses (``127.0.0.2``, ``127.0.0.3``, ...: Linux routes all of
127/8 to ``lo``). ``--port 0`` picks an ephemeral port for our own codec-level clients.

Run it standalone (``mmexec hw fake ur`` does this)::

    python -m mmexec.drivers.ur.rtde_stub --host 127.0.0.1 --port 30004

The control channel is the process's stdin / stdout, one JSON object per line. The stub
first prints ``{"event": "listening", "host": H, "port": P}``, then answers each
command line with ``{"ok": true, ...}`` or ``{"ok": false, "error": "..."}``. Commands
(field ``cmd``): ``protective_stop``, ``emergency_stop``, ``program_stopped``,
``clear_faults``, ``state`` (any of ``robot_mode``, ``safety_mode``, ``runtime_state``
by the vendor's numbers; the status bit fields follow, :mod:`mmexec.drivers.ur.states`),
``drop`` (close every client connection), ``refuse`` (``on``: stop / resume listening,
so connects are refused), ``freeze`` (``on``: keep connections but stop streaming, so
data goes stale), ``link`` (``skip_every`` N: every N-th package is never sent, i.e.
lost; ``hold`` S: packages are held back and sent in bursts once the oldest is S
seconds old, i.e. late; 0 turns each off), ``silence`` (``after`` N: the next N new
connections are served, later ones accepted but never answered; null: off),
``garbage`` (``on``: every request is answered with bytes that are not RTDE),
``not_found`` (``names``: variables answered ``NOT_FOUND``), ``set_joints`` (``q``
[rad], optional ``qd`` [rad/s], both held), ``move`` (``qd`` [rad/s]: the arm moves, its
positions advancing over the stub's time while the program runs), ``watchdog``
(``frequency`` [Hz] or null, ``variable``), ``deaf`` (``on``: requests and data from
clients are read and dropped, the stream goes on), ``stats``, ``quit``.
:class:`RTDEStub` drives all of this from the parent process.

The controller's RTDE watchdog (``watchdog``): what URScript
``rtde_set_watchdog(variable, frequency, "stop")`` does, the call ur_rtde's control script
makes for ``setWatchdog`` with ``input_int_register_0``. When no client's data package
updates the variable for ``1 / frequency`` s, the program stops: runtime state 1 (the
program-running bit clears), the arm stops (the stub: at once), the watchdog is removed
with the program, and the stop is recorded (``stats``: ``watchdog_stops``, in the stub's
own time, the ``timestamp`` it streams). The control interface, which feeds register 0
with every command, cannot run against the stub (docs/protocols.md 4.5); a client that
writes the watched variable the same way (ur_rtde's IO interface writes registers 18-22)
stands in for it.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import selectors
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import IO, Any, Self

from mmexec.drivers.ur import rtde_codec as codec
from mmexec.drivers.ur import states
from mmexec.drivers.ur.rtde_codec import PackageType

__all__ = ["RTDEStub", "StubError", "StubServer", "main"]

log = logging.getLogger(__name__)

RTDE_PORT = 30004
_MAX_FREQUENCY = 500.0  # Hz, e-series controller rate
_MAX_BACKLOG = 5.0  # s of owed samples the stub still sends after falling behind
#: what a request is answered with while ``garbage`` is on (a text service's greeting)
GARBAGE = b"Connected: this is not an RTDE server\n"

#: the named fault commands as vendor state numbers (docs/protocols.md 4.2, 4.6)
_NAMED_STATES: dict[str, dict[str, int]] = {
    "protective_stop": {"safety_mode": 3},
    "emergency_stop": {"safety_mode": 7, "robot_mode": 3},  # robot e-stop cuts arm power
    "program_stopped": {"runtime_state": 1},
    "clear_faults": {"safety_mode": 1, "robot_mode": 7, "runtime_state": 2},
}


class StubError(RuntimeError):
    """The stub process failed to start, answer a command in time, or reported an error."""


# --------------------------------------------------------------------------- server side


@dataclass
class _Client:
    sock: socket.socket
    addr: str
    buffer: bytes = b""
    next_recipe_id: int = 1
    output_id: int = 0
    output_names: list[str] = field(default_factory=list)
    output_types: list[str] = field(default_factory=list)
    period: float = 0.002
    streaming: bool = False
    next_send: float = 0.0
    inputs: dict[int, list[str]] = field(default_factory=dict)
    input_names: dict[int, list[str]] = field(default_factory=dict)
    silent: bool = False  # accepted but never answered
    samples: int = 0  # samples taken since S (sent, skipped or held)
    held: list[tuple[float, bytes]] = field(default_factory=list)  # (sample time, package)


class StubServer:
    """The server loop run inside the stub process (single-threaded, selector-based).

    Timing uses ``time.monotonic()``; the stub's ``timestamp`` output is seconds since
    the server started, like the controller's.
    """

    def __init__(self, host: str, port: int, control_in: IO[str], control_out: IO[str]) -> None:
        self.host = host
        self.port = port
        self._in = control_in
        self._out = control_out
        self._sel: selectors.BaseSelector | None = None
        self._listener: socket.socket | None = None
        self._clients: dict[int, _Client] = {}
        self._t0 = 0.0
        self._running = False
        self._frozen = False
        self._not_found: set[str] = set()
        self.version = (5, 15, 0, 12345)
        self.q = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
        self.qd = [0.0] * 6
        self.robot_mode = 7
        self.safety_mode = 1
        self.safety_status_bits = 1
        self.runtime_state = 2
        self.robot_status_bits = states.robot_status_bits(self.robot_mode, self.runtime_state)
        self._accepted = 0
        self._packages_sent = 0
        self._skip_every = 0
        self._hold = 0.0
        self._serve_before_silence: int | None = None
        self._garbage = False
        self._inputs_seen: list[dict[str, Any]] = []
        self._last_output_names: list[str] = []
        self._last_frequency = 0.0
        self._moving = False  # ``move``: q advances by qd over time while the program runs
        self._t_q = 0.0  # when q was last brought up to date (monotonic)
        self._deaf = False
        self._watched = ""  # the watchdog's input variable ("" : not armed)
        self._watch_period = 0.0
        self._last_update = 0.0  # monotonic time of the last data package updating it
        self._watchdog_updates = 0
        self._watchdog_stops: list[dict[str, Any]] = []

    # -- lifecycle
    def _listen(self) -> None:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((self.host, self.port))
        s.listen(8)
        s.setblocking(False)
        self.port = s.getsockname()[1]
        self._listener = s
        assert self._sel is not None
        self._sel.register(s, selectors.EVENT_READ, "listen")

    def _unlisten(self) -> None:
        if self._listener is not None and self._sel is not None:
            self._sel.unregister(self._listener)
            self._listener.close()
            self._listener = None

    def serve(self) -> int:
        """Run until ``quit`` or EOF on the control channel; returns an exit status."""
        self._sel = selectors.DefaultSelector()
        self._t0 = time.monotonic()
        try:
            self._listen()
        except OSError as e:
            self._reply({"event": "error", "error": f"cannot listen on {self.host}:{self.port}: {e.strerror}"})
            return 2
        self._sel.register(self._in, selectors.EVENT_READ, "control")
        self._reply({"event": "listening", "host": self.host, "port": self.port})
        self._running = True
        try:
            while self._running:
                timeout = self._next_deadline() - time.monotonic()
                for key, _ in self._sel.select(max(0.0, min(timeout, 0.1))):
                    if key.data == "listen":
                        self._accept()
                    elif key.data == "control":
                        self._control()
                    else:
                        self._read(key.data)
                self._check_watchdog()
                self._stream()
        finally:
            for c in list(self._clients.values()):
                self._close(c)
            self._unlisten()
            self._sel.close()
        return 0

    def _next_deadline(self) -> float:
        times = [c.next_send for c in self._clients.values() if c.streaming and not c.silent and not self._frozen]
        times += [c.held[0][0] + self._hold for c in self._clients.values() if c.held]
        if self._watched:
            times.append(self._last_update + self._watch_period)
        return min(times) if times else time.monotonic() + 0.1

    # -- control channel
    def _reply(self, obj: dict[str, Any]) -> None:
        self._out.write(json.dumps(obj) + "\n")
        self._out.flush()

    def _control(self) -> None:
        line = self._in.readline()
        if not line:
            self._running = False
            return
        try:
            cmd = json.loads(line)
            result = self._apply(cmd)
        except (ValueError, KeyError, TypeError) as e:
            self._reply({"ok": False, "error": f"bad control command {line.strip()!r}: {e}"})
            return
        self._reply({"ok": True, **result})

    def _apply(self, cmd: dict[str, Any]) -> dict[str, Any]:
        name = cmd["cmd"]
        named = _NAMED_STATES.get(name)
        if named is not None:
            self._set_state(named)
        elif name == "state":
            self._set_state(cmd)
        elif name == "link":
            skip, hold = int(cmd.get("skip_every", 0)), float(cmd.get("hold", 0.0))
            if skip < 0 or skip == 1 or not 0.0 <= hold <= 60.0:
                raise ValueError("skip_every must be 0 (off) or >= 2, hold in [0, 60] s")
            self._skip_every, self._hold = skip, hold
        elif name == "silence":
            after = cmd["after"]
            if after is not None and int(after) < 0:
                raise ValueError("after must be >= 0 or null")
            self._serve_before_silence = None if after is None else int(after)
        elif name == "garbage":
            self._garbage = bool(cmd["on"])
        elif name == "drop":
            n = len(self._clients)
            for c in list(self._clients.values()):
                self._close(c)
            return {"dropped": n}
        elif name == "refuse":
            if cmd["on"]:
                self._unlisten()
            elif self._listener is None:
                self._listen()
        elif name == "freeze":
            self._frozen = bool(cmd["on"])
            now = time.monotonic()
            for c in self._clients.values():
                c.next_send = now
        elif name == "not_found":
            self._not_found = {str(n) for n in cmd["names"]}
        elif name == "set_joints":
            q = [float(x) for x in cmd["q"]]
            qd = [float(x) for x in cmd.get("qd", [0.0] * 6)]
            if len(q) != 6 or len(qd) != 6:
                raise ValueError("q and qd need 6 values")
            self.q, self.qd, self._moving = q, qd, False
        elif name == "move":
            qd = [float(x) for x in cmd["qd"]]
            if len(qd) != 6:
                raise ValueError("qd needs 6 values")
            self._integrate(time.monotonic())
            if self.runtime_state != states.RUNTIME_PLAYING or self._faulted():
                raise ValueError("the arm cannot move: no program running or a safety stop")
            self.qd, self._moving = qd, True
        elif name == "watchdog":
            freq = cmd["frequency"]
            if freq is None:
                self._watched = ""
            else:
                freq, variable = float(freq), str(cmd.get("variable", "input_int_register_0"))
                if not 0.0 < freq < float("inf"):
                    raise ValueError("frequency must be a positive finite number of Hz")
                if not variable.startswith("input_") or codec.variable_type(variable) == codec.NOT_FOUND:
                    raise ValueError(f"{variable!r} is not an RTDE input variable")
                if self.runtime_state != states.RUNTIME_PLAYING:
                    raise ValueError("no program is running (a watchdog is set by the running program)")
                self._watched, self._watch_period, self._last_update = variable, 1.0 / freq, time.monotonic()
        elif name == "deaf":
            self._deaf = bool(cmd["on"])
        elif name == "stats":
            self._integrate(time.monotonic())
            return {
                "q": self.q,
                "qd": self.qd,
                "runtime_state": self.runtime_state,
                "watchdog_updates": self._watchdog_updates,
                "watchdog_stops": self._watchdog_stops,
                "clients": len(self._clients),
                "accepted": self._accepted,
                "packages_sent": self._packages_sent,
                "inputs": self._inputs_seen[-50:],
                "output_names": self._last_output_names,
                "frequency": self._last_frequency,
                "listening": self._listener is not None,
            }
        elif name == "quit":
            self._running = False
        else:
            raise ValueError(f"unknown command {name!r}")
        return {}

    # -- clients
    def _accept(self) -> None:
        assert self._listener is not None and self._sel is not None
        try:
            sock, addr = self._listener.accept()
        except BlockingIOError:
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        c = _Client(sock, f"{addr[0]}:{addr[1]}")
        if self._serve_before_silence is not None:
            if self._serve_before_silence == 0:
                c.silent = True
            else:
                self._serve_before_silence -= 1
        self._clients[sock.fileno()] = c
        self._sel.register(sock, selectors.EVENT_READ, c)
        self._accepted += 1

    def _close(self, c: _Client) -> None:
        self._clients.pop(c.sock.fileno(), None)
        if self._sel is not None:
            try:
                self._sel.unregister(c.sock)
            except (KeyError, ValueError):
                log.debug("client %s was not registered", c.addr)
        try:
            c.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            log.debug("client %s already shut down", c.addr)
        c.sock.close()

    def _send(self, c: _Client, data: bytes) -> None:
        try:
            c.sock.sendall(data)
        except BlockingIOError:
            log.warning("client %s is not reading; dropping it", c.addr)
            self._close(c)
        except OSError as e:
            log.info("client %s gone: %s", c.addr, e)
            self._close(c)

    def _read(self, c: _Client) -> None:
        try:
            data = c.sock.recv(65536)
        except OSError:
            data = b""
        if not data:
            self._close(c)
            return
        if self._deaf:  # the link carries nothing to the controller any more
            return
        try:
            packages, c.buffer = codec.split_packages(c.buffer + data)
            for p in packages:
                self._handle(c, p)
                if c.sock.fileno() < 0:
                    return
        except codec.RTDECodecError as e:
            log.warning("client %s sent a bad package (%s); closing", c.addr, e)
            self._close(c)

    def _handle(self, c: _Client, p: codec.Package) -> None:
        if c.silent:
            return
        if self._garbage and p.type != PackageType.DATA_PACKAGE:
            self._send(c, GARBAGE)
            return
        t = p.type
        if t == PackageType.REQUEST_PROTOCOL_VERSION:
            version = codec.decode_request_protocol_version(p.payload)
            self._send(c, codec.encode_accepted(t, version in (1, 2)))
        elif t == PackageType.GET_URCONTROL_VERSION:
            self._send(c, codec.encode_controller_version(*self.version))
        elif t == PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS:
            freq, names = codec.decode_setup_outputs(p.payload)
            types = [self._type(n) for n in names]
            self._last_output_names, self._last_frequency = names, freq
            if codec.NOT_FOUND in types or not names or not 0 < freq <= _MAX_FREQUENCY:
                self._send(c, codec.encode_setup_reply(t, 0, types))
                return
            c.output_id, c.output_names, c.output_types = c.next_recipe_id, names, types
            c.next_recipe_id += 1
            c.period = 1.0 / freq
            self._send(c, codec.encode_setup_reply(t, c.output_id, types))
        elif t == PackageType.CONTROL_PACKAGE_SETUP_INPUTS:
            names = codec.decode_setup_inputs(p.payload)
            types = [self._type(n) for n in names]
            if codec.NOT_FOUND in types or not names:
                self._send(c, codec.encode_setup_reply(t, 0, types))
                return
            rid = c.next_recipe_id
            c.next_recipe_id += 1
            c.inputs[rid], c.input_names[rid] = types, names
            self._send(c, codec.encode_setup_reply(t, rid, types))
        elif t == PackageType.CONTROL_PACKAGE_START:
            ok = c.output_id != 0 or bool(c.inputs)
            c.streaming = c.output_id != 0
            c.next_send = time.monotonic()
            c.samples = 0
            self._send(c, codec.encode_accepted(t, ok))
        elif t == PackageType.CONTROL_PACKAGE_PAUSE:
            c.streaming = False
            self._send(c, codec.encode_accepted(t, True))
        elif t == PackageType.DATA_PACKAGE:
            rid, values = codec.decode_data(p.payload, c.inputs)
            if self._watched and self._watched in c.input_names[rid]:
                now = time.monotonic()
                self._integrate(now)  # the watchdog may have expired before this package
                self._last_update = now
                self._watchdog_updates += 1
            self._inputs_seen.append(
                {"recipe": rid, "values": dict(zip(c.input_names[rid], [_jsonable(v) for v in values]))}
            )
        else:
            log.info("client %s sent unhandled package type %d", c.addr, t)

    def _set_state(self, cmd: dict[str, Any]) -> None:
        """``state`` command: vendor robot mode / safety mode / runtime state numbers."""
        robot_mode = int(cmd.get("robot_mode", self.robot_mode))
        safety_mode = int(cmd.get("safety_mode", self.safety_mode))
        runtime_state = int(cmd.get("runtime_state", self.runtime_state))
        bits = states.safety_status_bits(safety_mode)  # ValueError for unknown numbers
        status = states.robot_status_bits(robot_mode, runtime_state)
        self._integrate(time.monotonic())
        self.robot_mode, self.safety_mode, self.runtime_state = robot_mode, safety_mode, runtime_state
        self.safety_status_bits, self.robot_status_bits = bits, status
        if self._faulted():
            self.qd, self._moving = [0.0] * 6, False
        if runtime_state != states.RUNTIME_PLAYING:  # the program ended: its watchdog goes with it
            self._watched = ""

    def _faulted(self) -> bool:
        """The arm cannot move: a safety stop, power off, or no program running."""
        return bool(states.running_fault(self.robot_mode, self.safety_mode, self.safety_status_bits,
                                         self.runtime_state))

    def _integrate(self, now: float) -> None:
        """Bring the controller up to ``now`` (monotonic): the watchdog's stop if it
        expired meanwhile, and the moving arm's positions."""
        if self._watched and now > self._last_update + self._watch_period:
            self._watchdog_stop(self._last_update + self._watch_period)
        self._move_to(now)

    def _move_to(self, now: float) -> None:
        if self._moving and now > self._t_q:
            dt = now - self._t_q
            self.q = [x + v * dt for x, v in zip(self.q, self.qd)]
        self._t_q = max(self._t_q, now)

    def _check_watchdog(self) -> None:
        self._integrate(time.monotonic())

    def _watchdog_stop(self, expiry: float) -> None:
        """The watched input went without an update for the watchdog's period: the
        program stops at ``expiry`` (monotonic), the arm with it; recorded."""
        self._move_to(expiry)
        self._watchdog_stops.append({
            "t": expiry - self._t0, "last_update": self._last_update - self._t0, "period": self._watch_period,
            "variable": self._watched, "q": list(self.q), "qd": list(self.qd),
        })
        self.qd, self._moving, self._watched = [0.0] * 6, False, ""
        self.runtime_state = 1
        self.robot_status_bits = states.robot_status_bits(self.robot_mode, self.runtime_state)
        log.info("no update of the watched input for %.3f s: program stopped", self._watch_period)

    def _type(self, name: str) -> str:
        return codec.NOT_FOUND if name in self._not_found else codec.variable_type(name)

    def _value(self, name: str, rtde_type: str, stamp: float) -> Any:
        fixed: dict[str, Any] = {
            "timestamp": stamp,
            "actual_q": self.q,
            "target_q": self.q,
            "actual_qd": self.qd,
            "target_qd": self.qd,
            "robot_mode": self.robot_mode,
            "safety_mode": self.safety_mode,
            "safety_status": self.safety_mode,
            "safety_status_bits": self.safety_status_bits,
            "runtime_state": self.runtime_state,
            "robot_status_bits": self.robot_status_bits,
            "speed_scaling": 1.0,
            "target_speed_fraction": 1.0,
            "joint_mode": [253] * 6,
            "actual_main_voltage": 48.0,
            "actual_robot_voltage": 48.0,
            "joint_temperatures": [30.0] * 6,
        }
        if name in fixed:
            return fixed[name]
        if rtde_type in ("VECTOR3D",):
            return [0.0] * 3
        if rtde_type.startswith("VECTOR6"):
            return [0] * 6 if "INT" in rtde_type else [0.0] * 6
        if rtde_type == "BOOL":
            return False
        return 0.0 if rtde_type == "DOUBLE" else 0

    def _stream(self) -> None:
        if self._frozen:
            return
        now = time.monotonic()
        self._integrate(now)
        for c in list(self._clients.values()):
            if not c.streaming or c.silent:
                continue
            if now - c.next_send > _MAX_BACKLOG:  # fell too far behind: those samples are lost
                c.next_send = now
            while now >= c.next_send and c.sock.fileno() >= 0:
                stamp = c.next_send - self._t0  # the sample's time, as the controller stamps it
                c.next_send += c.period
                c.samples += 1
                if self._skip_every and c.samples % self._skip_every == 0:
                    continue  # injected loss
                values = [self._value(n, t, stamp) for n, t in zip(c.output_names, c.output_types)]
                frame = codec.encode_data(c.output_id, c.output_types, values)
                if self._hold > 0.0:
                    c.held.append((stamp + self._t0, frame))
                else:
                    self._send_frames(c, [frame])
            if c.held and now - c.held[0][0] >= self._hold:
                frames, c.held = [f for _, f in c.held], []
                self._send_frames(c, frames)

    def _send_frames(self, c: _Client, frames: list[bytes]) -> None:
        self._send(c, b"".join(frames))
        self._packages_sent += len(frames)


def _jsonable(v: Any) -> Any:
    return list(v) if isinstance(v, tuple) else v


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the stub process (see the module docstring for the control channel)."""
    ap = argparse.ArgumentParser(prog="python -m mmexec.drivers.ur.rtde_stub", description=__doc__.splitlines()[0])
    ap.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    ap.add_argument("--port", type=int, default=RTDE_PORT, help="TCP port (default 30004; 0 = ephemeral)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="rtde_stub: %(message)s")
    server = StubServer(args.host, args.port, sys.stdin, sys.stdout)
    try:
        return server.serve()
    except KeyboardInterrupt:
        return 0


# --------------------------------------------------------------------------- parent side


class RTDEStub:
    """Runs :class:`StubServer` in a child process and drives its control channel.

    ``with RTDEStub("127.0.0.7") as stub: ...`` starts it (listening on
    ``stub.host:stub.port``) and joins the process on exit. Every command waits for the
    stub's answer at most ``timeout`` seconds and raises :class:`StubError` otherwise.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = RTDE_PORT, *, timeout: float = 5.0) -> None:
        self.host = host
        self.port = port
        self.timeout = timeout
        self._proc: subprocess.Popen[str] | None = None
        self._sel: selectors.BaseSelector | None = None
        self._pending = ""

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    def start(self) -> RTDEStub:
        """Start the stub process and wait (bounded) until it listens."""
        if self._proc is not None:
            raise StubError("stub already started")
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "mmexec.drivers.ur.rtde_stub", "--host", self.host, "--port", str(self.port)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            bufsize=1,
        )
        assert self._proc.stdout is not None
        os.set_blocking(self._proc.stdout.fileno(), False)
        self._sel = selectors.DefaultSelector()
        self._sel.register(self._proc.stdout, selectors.EVENT_READ)
        try:
            first = self._read_line(self.timeout * 2)
        except StubError:
            self.stop()
            raise
        if first.get("event") != "listening":
            self.stop()
            raise StubError(first.get("error", f"stub did not start: {first}"))
        self.port = int(first["port"])
        return self

    def _read_line(self, timeout: float) -> dict[str, Any]:
        assert self._proc is not None and self._proc.stdout is not None and self._sel is not None
        deadline = time.monotonic() + timeout
        while "\n" not in self._pending:
            left = deadline - time.monotonic()
            if left <= 0:
                raise StubError(f"RTDE stub at {self.address} did not answer within {timeout:.1f} s")
            if not self._sel.select(left):
                continue
            try:
                chunk = os.read(self._proc.stdout.fileno(), 65536)
            except BlockingIOError:
                continue
            if not chunk:
                raise StubError(f"RTDE stub at {self.address} exited (status {self._proc.poll()})")
            self._pending += chunk.decode("utf-8", "replace")
        line, self._pending = self._pending.split("\n", 1)
        result: dict[str, Any] = json.loads(line)
        return result

    def command(self, cmd: str, **fields: Any) -> dict[str, Any]:
        """Send one control command and return the stub's answer."""
        if self._proc is None or self._proc.stdin is None:
            raise StubError("stub not started: call start() first")
        try:
            self._proc.stdin.write(json.dumps({"cmd": cmd, **fields}) + "\n")
            self._proc.stdin.flush()
        except BrokenPipeError as e:
            raise StubError(f"RTDE stub at {self.address} is gone") from e
        reply = self._read_line(self.timeout)
        if not reply.get("ok"):
            raise StubError(str(reply.get("error", reply)))
        return reply

    # -- fault injection and state
    def protective_stop(self) -> None:
        """Safety mode 3, safety status bit 2."""
        self.command("protective_stop")

    def emergency_stop(self) -> None:
        """Safety mode 7 (robot e-stop), status bits 6 and 7, robot mode 3 (power off)."""
        self.command("emergency_stop")

    def program_stopped(self) -> None:
        """Runtime state 1 (stopped), program-running status bit cleared."""
        self.command("program_stopped")

    def clear_faults(self) -> None:
        self.command("clear_faults")

    def set_state(self, *, robot_mode: int | None = None, safety_mode: int | None = None,
                  runtime_state: int | None = None) -> None:
        """Robot mode, safety mode and/or runtime state by the vendor's numbers
        (docs/protocols.md 4.2); both status bit fields follow. E.g. power off:
        ``robot_mode=3``; brakes engaged: ``robot_mode=5``; safeguard stop: ``safety_mode=5``."""
        given = {"robot_mode": robot_mode, "safety_mode": safety_mode, "runtime_state": runtime_state}
        self.command("state", **{k: v for k, v in given.items() if v is not None})

    def set_link(self, *, skip_every: int = 0, hold: float = 0.0) -> None:
        """Link faults: never send every ``skip_every``-th package (lost); hold packages
        back until the oldest is ``hold`` s old, then send them at once (late). 0 = off."""
        self.command("link", skip_every=skip_every, hold=hold)

    def silence(self, after: int | None = 0) -> None:
        """Serve the next ``after`` new connections, then accept connections and never
        answer them (None: serve every connection again)."""
        self.command("silence", after=after)

    def garbage(self, on: bool = True) -> None:
        """Answer every request with bytes that are not RTDE (:data:`GARBAGE`)."""
        self.command("garbage", on=on)

    def drop_connections(self) -> int:
        """Close every client connection (the stub keeps listening); returns how many."""
        return int(self.command("drop")["dropped"])

    def refuse_connections(self, on: bool = True) -> None:
        """Stop listening (connects are refused) or listen again."""
        self.command("refuse", on=on)

    def freeze(self, on: bool = True) -> None:
        """Keep connections open but stop streaming (the client's data goes stale)."""
        self.command("freeze", on=on)

    def set_not_found(self, names: Sequence[str]) -> None:
        """Answer ``NOT_FOUND`` for these variable names from now on."""
        self.command("not_found", names=list(names))

    def set_joints(self, q: Sequence[float], qd: Sequence[float] | None = None) -> None:
        """Joint positions [rad] (and velocities [rad/s]) streamed from now on."""
        self.command("set_joints", q=list(q), qd=list(qd) if qd is not None else [0.0] * 6)

    def move(self, qd: Sequence[float]) -> None:
        """The arm moves at ``qd`` [rad/s]: its positions advance over the stub's time
        while the program runs (a fault, a program stop or the watchdog stops it)."""
        self.command("move", qd=list(qd))

    def watchdog(self, frequency: float | None, variable: str = "input_int_register_0") -> None:
        """Arm the running program's RTDE watchdog on the input ``variable`` (None: remove
        it): no update for ``1 / frequency`` s stops the program and the arm (see the
        module doc; ``stats()["watchdog_stops"]`` records it)."""
        self.command("watchdog", frequency=frequency, variable=variable)

    def deaf(self, on: bool = True) -> None:
        """The link stops carrying anything to the controller: every client's requests
        and data packages are dropped (connections stay open, the stream goes on)."""
        self.command("deaf", on=on)

    def stats(self) -> dict[str, Any]:
        """Clients, accepted connections, packages sent, input packages seen, last recipe;
        the arm's ``q``, ``qd``, ``runtime_state``; ``watchdog_updates`` (data packages
        that fed the watchdog) and ``watchdog_stops`` (each: ``t`` and ``last_update`` in
        the stub's time [s], ``period``, ``variable``, ``q`` and ``qd`` as it stopped)."""
        return self.command("stats")

    def stop(self) -> None:
        """Ask the process to quit, join it (bounded), kill it if it does not."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            if proc.stdin is not None:
                proc.stdin.write('{"cmd": "quit"}\n')
                proc.stdin.flush()
                proc.stdin.close()
        except (BrokenPipeError, OSError):
            log.debug("stub stdin already closed")
        try:
            proc.wait(timeout=self.timeout)
        except subprocess.TimeoutExpired:
            log.warning("RTDE stub %s did not quit; killing it", self.address)
            proc.kill()
            proc.wait(timeout=self.timeout)
        if proc.stdout is not None:
            proc.stdout.close()
        if self._sel is not None:
            self._sel.close()
            self._sel = None

    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


if __name__ == "__main__":
    raise SystemExit(main())
