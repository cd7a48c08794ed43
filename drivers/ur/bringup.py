"""Bring-up commands for the UR arm: ``mmexec hw ping ur`` and ``mmexec hw fake ur``.

``ping`` first speaks RTDE itself (our codec over a socket with a deadline on every read:
``V``, ``v``, ``O``, ``S``, one ``U``, ``P``), because ur_rtde's constructors hold the GIL
while the OS connect timeout runs and take no port. That gives the controller version and
one-line reasons (connection refused, no answer within the deadline, ``NOT_FOUND``
variables). On port 30004 it then connects the real ``RTDEReceiveInterface`` in a worker
thread with the same deadline and prints what it reads.
"""

from __future__ import annotations

import argparse
import signal
import socket
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from mmexec.drivers.ur import rtde_codec as codec
from mmexec.drivers.ur.rtde_codec import PackageType

__all__ = ["PingResult", "URPingError", "add_fake_arguments", "add_ping_arguments", "ping", "probe", "run_fake"]

PING_VARIABLES: tuple[str, ...] = ("timestamp", "actual_q", "robot_mode", "safety_mode", "runtime_state")


class URPingError(RuntimeError):
    """The controller did not answer as expected; the message is one line naming host:port."""


@dataclass(frozen=True)
class PingResult:
    """What one RTDE round trip read: version, modes, joints [rad]."""

    version: codec.ControllerVersion
    robot_mode: int
    safety_mode: int
    runtime_state: int
    q: tuple[float, ...]


class _Link:
    def __init__(self, sock: socket.socket, where: str, timeout: float) -> None:
        self.sock, self.where, self.timeout, self.buf = sock, where, timeout, b""

    def request(self, frame: bytes, expect: int) -> bytes:
        self.sock.sendall(frame)
        return self.receive(expect)

    def receive(self, expect: int) -> bytes:
        deadline = time.monotonic() + self.timeout
        while True:
            packages, self.buf = codec.split_packages(self.buf)
            for i, p in enumerate(packages):
                if p.type == expect:
                    rest = b"".join(codec.encode_package(q.type, q.payload) for q in packages[i + 1 :])
                    self.buf = rest + self.buf
                    return p.payload
            left = deadline - time.monotonic()
            if left <= 0:
                raise URPingError(f"{self.where}: no answer within {self.timeout:.1f} s (waiting for '{chr(expect)}')")
            self.sock.settimeout(left)
            try:
                chunk = self.sock.recv(65536)
            except TimeoutError:
                continue
            if not chunk:
                raise URPingError(f"{self.where}: controller closed the connection")
            self.buf += chunk


def probe(host: str, port: int = 30004, timeout: float = 2.0, variables: Sequence[str] = PING_VARIABLES) -> PingResult:
    """One RTDE session with a deadline per step; raises :class:`URPingError` (one line)."""
    where = f"{host}:{port}"
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except ConnectionRefusedError:
        raise URPingError(f"{where}: connection refused (is the controller on and RTDE enabled?)") from None
    except TimeoutError:
        raise URPingError(f"{where}: no answer within {timeout:.1f} s") from None
    except OSError as e:
        raise URPingError(f"{where}: {e.strerror or e}") from None
    with sock:
        link = _Link(sock, where, timeout)
        try:
            if not codec.decode_accepted(link.request(codec.encode_request_protocol_version(2), PackageType.REQUEST_PROTOCOL_VERSION)):
                raise URPingError(f"{where}: controller refused RTDE protocol version 2")
            version = codec.decode_controller_version(link.request(codec.encode_get_controller_version(), PackageType.GET_URCONTROL_VERSION))
            rid, types = codec.decode_setup_reply(
                link.request(codec.encode_setup_outputs(10.0, variables), PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS)
            )
            missing = [n for n, t in zip(variables, types) if t == codec.NOT_FOUND]
            if missing or rid == 0:
                raise URPingError(f"{where}: controller answered NOT_FOUND for {', '.join(missing) or 'the recipe'}")
            if not codec.decode_accepted(link.request(codec.encode_start(), PackageType.CONTROL_PACKAGE_START)):
                raise URPingError(f"{where}: controller refused to start streaming")
            _, values = codec.decode_data(link.receive(PackageType.DATA_PACKAGE), {rid: types})
            link.sock.sendall(codec.encode_pause())
        except codec.RTDECodecError as e:
            raise URPingError(f"{where}: corrupt RTDE reply ({e})") from None
        except OSError as e:
            raise URPingError(f"{where}: {e.strerror or e}") from None
    v = dict(zip(variables, values))
    return PingResult(version, int(v["robot_mode"]), int(v["safety_mode"]), int(v["runtime_state"]), tuple(v["actual_q"]))


def _receive_in_thread(host: str, timeout: float) -> dict[str, Any]:
    """Construct ``RTDEReceiveInterface`` in a worker thread with a deadline and read once."""
    out: dict[str, Any] = {}

    def work() -> None:
        import rtde_receive

        try:
            r = rtde_receive.RTDEReceiveInterface(host, 10.0, list(PING_VARIABLES))
        except RuntimeError as e:
            out["error"] = " ".join(str(e).split())
            return
        try:
            deadline = time.monotonic() + timeout
            ev = threading.Event()
            while r.getTimestamp() == 0.0 and time.monotonic() < deadline:
                ev.wait(0.01)
            out.update(q=r.getActualQ(), robot_mode=r.getRobotMode(), safety_mode=r.getSafetyMode())
        finally:
            try:
                r.disconnect()
            except RuntimeError as e:
                out.setdefault("warning", str(e))

    t = threading.Thread(target=work, name="ur-ping", daemon=True)
    t.start()
    t.join(timeout)
    if t.is_alive():
        out["error"] = f"ur_rtde did not connect within {timeout:.1f} s"
    return out


def add_ping_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``mmexec hw ping ur``."""
    parser.add_argument("--host", required=True, help="controller IP address or name")
    parser.add_argument("--port", type=int, default=30004, help="RTDE port (default 30004)")
    parser.add_argument("--timeout", type=float, default=2.0, help="deadline per step in seconds (default 2)")


def ping(args: argparse.Namespace) -> int:
    """``mmexec hw ping ur``: 0 when the controller answers, 1 with one line otherwise."""
    from mmexec.drivers.ur.arm import ROBOT_MODES, RUNTIME_STATES, SAFETY_MODES

    try:
        res = probe(args.host, args.port, args.timeout)
    except URPingError as e:
        print(f"ur {e}", file=sys.stderr)
        return 1
    q = res.q
    if args.port == 30004:
        got = _receive_in_thread(args.host, args.timeout)
        if "error" in got:
            print(f"ur {args.host}:{args.port}: ur_rtde: {got['error']}", file=sys.stderr)
            return 1
        q = tuple(got["q"])
    print(f"ur {args.host}:{args.port}: controller {res.version}")
    print(f"  robot mode {res.robot_mode} ({ROBOT_MODES.get(res.robot_mode, '?')}), "
          f"safety mode {res.safety_mode} ({SAFETY_MODES.get(res.safety_mode, '?')}), "
          f"runtime state {res.runtime_state} ({RUNTIME_STATES.get(res.runtime_state, '?')})")
    print("  joints [rad]: " + " ".join(f"{x:+.4f}" for x in q))
    return 0


def add_fake_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``mmexec hw fake ur``."""
    parser.add_argument("--host", default="127.0.0.1", help="loopback address to listen on (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=30004,
                        help="port (default 30004, the only one ur_rtde can use; 0 = ephemeral)")


def run_fake(args: argparse.Namespace) -> int:
    """``mmexec hw fake ur``: start the RTDE stub process, print HOST:PORT, run until Ctrl-C."""
    from mmexec.drivers.ur.rtde_stub import RTDEStub, StubError

    stub = RTDEStub(args.host, args.port)
    stop = threading.Event()
    # handlers first: a Ctrl-C right after the port is printed still stops the stub process
    previous = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            stub.start()
        except StubError as e:
            print(f"ur fake: {e}", file=sys.stderr)
            return 1
        print(f"{stub.host}:{stub.port}", flush=True)
        while not stop.is_set() and stub.running():
            stop.wait(0.5)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        stub.stop()
    return 0
