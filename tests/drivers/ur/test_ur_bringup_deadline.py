"""UR bring-up has a deadline that fires, and Ctrl-C always works (a real ``mmexec run``).

The robot backend's arm points at a controller that misbehaves on 127.0.0.X:30004 (the
one port ur_rtde can use; a fresh loopback address per test):

* ``silent``: a TCP server that accepts and never answers;
* ``garbage``: a TCP server that answers every connection with bytes that are not RTDE;
* ``stalls ur_rtde``: the RTDE stub, serving the first connection (the driver's own
  handshake check) and silent to the next (ur_rtde's constructor, which holds the GIL).

Before the fix, each of them froze ``mmexec run`` for good (more than 40 s; the GIL held
by ur_rtde's constructor kept the deadline and the SIGINT handler from ever running).
What is asserted is the exit code and the output; the subprocess timeouts are generous
bounds (a connect_timeout of 1 s, 60 s to exit), never a measured duration.
"""

from __future__ import annotations

import contextlib
import errno
import os
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from urtest_helpers import host_processes, loopback_host, start_stub, wait_for

from mmexec.drivers.ur.rtde_stub import RTDEStub
from mmexec.executive.eventlog import read_log

EXE = Path(sys.executable).with_name("mmexec")
#: [wall s] generous bound for a loaded machine to start the command and reach the hang
START_LIMIT = 90.0
#: [wall s] generous bound for the command to exit once it should (deadline or signal)
EXIT_LIMIT = 60.0

MISSION = """\
mission: ur_bringup
tree:
  skill: report
  params: {message: connected}
"""


class RawServer:
    """A loopback TCP server on HOST:30004 in this process: ``silent`` accepts and never
    answers; ``garbage`` sends bytes that are not RTDE on every connection and request."""

    GARBAGE = b"\xff\xfe HTTP/1.1 400 Bad Request\r\n\r\n"

    def __init__(self, mode: str) -> None:
        self.mode = mode
        self.accepted = 0
        self._conns: list[socket.socket] = []
        self._stop = threading.Event()
        for _ in range(20):  # another test process may hold 30004 on the address tried
            self.host = loopback_host()
            self._sock = socket.socket()
            try:
                self._sock.bind((self.host, 30004))
                break
            except OSError as e:
                self._sock.close()
                if e.errno != errno.EADDRINUSE:
                    raise
        self._sock.listen(8)
        self._sock.settimeout(0.05)
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            with contextlib.suppress(TimeoutError):
                conn, _ = self._sock.accept()
                conn.settimeout(0.05)
                self._conns.append(conn)
                self.accepted += 1
                if self.mode == "garbage":
                    conn.sendall(self.GARBAGE)
            for conn in self._conns:
                with contextlib.suppress(TimeoutError, OSError):
                    if conn.recv(4096) and self.mode == "garbage":
                        conn.sendall(self.GARBAGE)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        for conn in self._conns:
            conn.close()
        self._sock.close()


@contextlib.contextmanager
def controller(kind: str) -> Iterator[tuple[str, Callable[[], int]]]:
    """(host, number of connections it accepted) of a misbehaving controller."""
    if kind == "stalls ur_rtde":
        stub: RTDEStub = start_stub()
        stub.silence(after=1)
        try:
            yield stub.host, lambda: int(stub.stats()["accepted"])
        finally:
            stub.stop()
    else:
        server = RawServer(kind)
        try:
            yield server.host, lambda: server.accepted
        finally:
            server.close()


def write_run(tmp_path: Path, host: str, connect_timeout: float) -> tuple[Path, Path, Path]:
    mission, config = tmp_path / "mission.yaml", tmp_path / "ur.yaml"
    mission.write_text(MISSION)
    config.write_text(
        "backend: robot\nrate_hz: 20\nrobot:\n"
        f"  arm: {{kind: ur, host: {host}, connect_timeout: {connect_timeout}}}\n"
        "profile: {}\n"
    )
    return mission, config, tmp_path / "run.jsonl"


@contextlib.contextmanager
def mmexec_run(mission: Path, config: Path, log: Path) -> Iterator[subprocess.Popen[str]]:
    """``mmexec run`` in its own process group (as a terminal runs it); killed if left."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env.pop("MMEXEC_DEBUG", None)
    proc = subprocess.Popen([str(EXE), "run", str(mission), "--config", str(config), "--log", str(log)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()


KINDS = ["silent", "garbage", "stalls ur_rtde"]
#: what each failure says after "UR HOST:30004: "
REASONS = {
    "silent": "no answer within 1.0 s (waiting for 'V')",
    "garbage": "corrupt RTDE reply (unknown package type 32 (0x20) at offset 0): not an RTDE server?",
    "stalls ur_rtde": ("cannot connect: ur_rtde RTDEReceiveInterface() did not return by the connect deadline "
                       "(connect_timeout 1.0 s)"),
}


@pytest.mark.parametrize("kind", KINDS)
def test_bring_up_fails_in_one_line_naming_host_and_port(tmp_path: Path, kind: str) -> None:
    with controller(kind) as (host, _accepted):
        mission, config, log = write_run(tmp_path, host, connect_timeout=1.0)
        with mmexec_run(mission, config, log) as proc:
            out, err = proc.communicate(timeout=EXIT_LIMIT)
            assert proc.returncode == 2, (out, err)
            assert host_processes(proc.pid) == []
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0] == f"{config}:4:8: robot.arm: UR {host}:30004: {REASONS[kind]}"
    run_end = read_log(log)[-1]
    assert (run_end["event"], run_end["exit_code"]) == ("run_end", 2)


#: halting signal -> (exit code, the one line on stderr); each sent to the whole process
#: group: a terminal's Ctrl-C and hang-up do that, and so does systemd's stop
HALTS = {
    signal.SIGINT: (130, "mmexec: interrupted"),
    signal.SIGTERM: (143, "mmexec: interrupted (SIGTERM)"),
    signal.SIGHUP: (129, "mmexec: interrupted (SIGHUP)"),
}


@pytest.mark.parametrize("sig", list(HALTS), ids=[s.name for s in HALTS])
@pytest.mark.parametrize("kind", ["silent", "stalls ur_rtde"])
def test_a_halting_signal_during_the_hang_ends_bring_up(tmp_path: Path, kind: str, sig: signal.Signals) -> None:
    """Before the fix only SIGINT ended the bring-up; SIGTERM and SIGHUP waited out the
    connect deadline (here 600 s: the test's bound of 60 s fails first)."""
    code, line = HALTS[sig]
    with controller(kind) as (host, accepted):
        # a deadline far beyond the test's bounds: only the signal can end the bring-up
        mission, config, log = write_run(tmp_path, host, connect_timeout=600.0)
        with mmexec_run(mission, config, log) as proc:
            # the driver's handshake check, then (stalls ur_rtde) ur_rtde's connection
            hung = 2 if kind == "stalls ur_rtde" else 1
            assert wait_for(lambda: accepted() >= hung or proc.poll() is not None, START_LIMIT)
            assert proc.poll() is None, proc.communicate()
            if kind == "stalls ur_rtde":
                assert wait_for(lambda: len(host_processes(proc.pid)) == 1, START_LIMIT)
            os.killpg(proc.pid, sig)
            out, err = proc.communicate(timeout=EXIT_LIMIT)
            assert proc.returncode == code, (out, err)
            assert wait_for(lambda: host_processes(proc.pid) == [], EXIT_LIMIT)  # what was opened is closed
    assert err.strip().splitlines() == [line]
    run_end = read_log(log)[-1]
    assert run_end == {**run_end, "event": "run_end", "outcome": "interrupted", "signal": sig.name, "exit_code": code}
