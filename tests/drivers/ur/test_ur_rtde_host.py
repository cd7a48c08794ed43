"""The ur_rtde host process: the real ``RTDEReceiveInterface`` lives in a child process;
calls come back with its answers or errors, a call that overruns its deadline kills the
host, and the host ignores Ctrl-C and never outlives its parent."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator

import pytest
from urtest_helpers import start_stub, wait_for

from mmexec.drivers.interfaces import ManualClock
from mmexec.drivers.ur.fake import FakeURController
from mmexec.drivers.ur.rtde_host import RTDEHost, RTDEHostError, call_all
from mmexec.drivers.ur.rtde_stub import RTDEStub

VARS = ["timestamp", "actual_q", "robot_mode", "safety_mode"]
#: [wall s] generous bound for the host to start and ur_rtde to connect on a loaded machine
LIMIT = 30.0


@pytest.fixture
def stub() -> Iterator[RTDEStub]:
    s = start_stub()
    yield s
    s.stop()


@pytest.fixture
def rtde_host(stub: RTDEStub) -> Iterator[RTDEHost]:
    h = RTDEHost(stub.host)
    h.start(LIMIT)
    yield h
    h.close()
    assert not h.running


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie is dead
        return f.read().split(") ")[-1][0] != "Z"


def test_calls_answer_and_raise_what_ur_rtde_raised(stub: RTDEStub, rtde_host: RTDEHost) -> None:
    q = [0.1, -1.2, 1.3, -1.4, -1.5, 0.6]
    stub.set_joints(q)
    r = rtde_host.construct("rtde_receive", "RTDEReceiveInterface", (stub.host, 50.0, VARS),
                            timeout=LIMIT, call_timeout=LIMIT, method_timeouts={"disconnect": LIMIT})
    assert wait_for(lambda: r.getTimestamp() > 0.0, LIMIT)
    assert r.getActualQ() == pytest.approx(q)
    connected, mode, got_q = call_all([(r, "isConnected"), (r, "getRobotMode"), (r, "getActualQ")])
    assert (connected, mode, got_q) == (True, 7, pytest.approx(q))
    with pytest.raises(AttributeError, match="noSuchMethod"):
        r.noSuchMethod()
    stub.set_not_found(["actual_q"])
    with pytest.raises(RuntimeError, match=r"not found by the controller: \[actual_q\]") as e:
        rtde_host.construct("rtde_receive", "RTDEReceiveInterface", (stub.host, 50.0, VARS),
                            timeout=LIMIT, call_timeout=LIMIT)
    assert not isinstance(e.value, RTDEHostError)  # ur_rtde's own error, and the host lives on
    assert r.isConnected()
    r.disconnect()
    with pytest.raises(ValueError, match="not a ur_rtde interface"):
        rtde_host.construct("os", "system", ("true",), timeout=1.0, call_timeout=1.0)


def test_a_call_past_its_deadline_kills_the_host(stub: RTDEStub, rtde_host: RTDEHost) -> None:
    stub.silence(0)  # ur_rtde's constructor waits for an answer that never comes, holding its GIL
    pid = rtde_host.pid
    assert pid is not None
    with pytest.raises(RTDEHostError, match=r"^ur_rtde RTDEReceiveInterface\(\) did not return within 0\.50 s$"):
        rtde_host.construct("rtde_receive", "RTDEReceiveInterface", (stub.host, 50.0, VARS),
                            timeout=0.5, call_timeout=0.5)
    assert wait_for(lambda: not _alive(pid), LIMIT)
    assert not rtde_host.running
    with pytest.raises(RTDEHostError, match="is gone"):
        rtde_host.call(1, "getTimestamp", timeout=1.0)


def test_kill_from_another_thread_ends_a_blocked_call(stub: RTDEStub, rtde_host: RTDEHost) -> None:
    stub.silence(0)
    errors: list[Exception] = []

    def construct() -> None:
        try:
            rtde_host.construct("rtde_receive", "RTDEReceiveInterface", (stub.host, 50.0, VARS),
                                timeout=600.0, call_timeout=1.0)
        except RTDEHostError as e:
            errors.append(e)

    t = threading.Thread(target=construct, daemon=True)
    t.start()
    assert wait_for(lambda: stub.stats()["accepted"] >= 1, LIMIT)
    rtde_host.kill("gave up connecting")
    t.join(LIMIT)
    assert not t.is_alive()
    assert [str(e) for e in errors] == ["ur_rtde RTDEReceiveInterface(): gave up connecting"]


def test_host_ignores_ctrl_c(stub: RTDEStub, rtde_host: RTDEHost) -> None:
    pid = rtde_host.pid
    assert pid is not None
    r = rtde_host.construct("rtde_receive", "RTDEReceiveInterface", (stub.host, 50.0, VARS),
                            timeout=LIMIT, call_timeout=LIMIT, method_timeouts={"disconnect": LIMIT})
    os.kill(pid, signal.SIGINT)  # a terminal's Ctrl-C reaches the whole process group
    os.kill(pid, signal.SIGHUP)
    os.kill(pid, signal.SIGTERM)  # so does systemd's stop (every process of the unit)
    assert r.isConnected()  # the parent decides when the arm stops, through the host
    r.disconnect()


PARENT = """\
import sys
from mmexec.drivers.ur.rtde_host import RTDEHost
h = RTDEHost(sys.argv[1])
h.start(30.0)
print(h.pid, flush=True)
h.construct("rtde_receive", "RTDEReceiveInterface", (sys.argv[1], 50.0, ["timestamp"]),
            timeout=600.0, call_timeout=1.0)
"""


def test_host_dies_with_its_parent_even_inside_ur_rtde(stub: RTDEStub) -> None:
    stub.silence(0)  # the host will sit in ur_rtde's constructor, deaf to everything but SIGKILL
    parent = subprocess.Popen([sys.executable, "-c", PARENT, stub.host], stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout is not None
        pid = int(parent.stdout.readline())
        assert wait_for(lambda: stub.stats()["accepted"] >= 1, LIMIT)
        assert _alive(pid)
    finally:
        parent.kill()  # SIGKILL: no cleanup runs in the parent
        parent.communicate()
    assert wait_for(lambda: not _alive(pid), LIMIT)


def test_call_all_with_in_process_objects() -> None:
    ctrl = FakeURController(ManualClock())
    r, c = ctrl.receive_factory("fake"), ctrl.control_factory("fake")
    assert call_all([(r, "getRobotMode"), (c, "isConnected")]) == [7, True]
