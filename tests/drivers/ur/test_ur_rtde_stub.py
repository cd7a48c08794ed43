"""The real ur_rtde RTDEReceiveInterface against the RTDE stub process, and bring-up."""

from __future__ import annotations

import argparse
import os
import signal
import threading
import time
from collections.abc import Iterator

import pytest
import rtde_receive
from urtest_helpers import host_processes, start_stub, wait_for

from mmexec.drivers.interfaces import GoalState, ManualClock
from mmexec.drivers.ur import bringup, rtde_client
from mmexec.drivers.ur.arm import MonotonicClock, URArm, URArmConfig, URConnectionError
from mmexec.drivers.ur.fake import FakeURController
from mmexec.drivers.ur.rtde_stub import RTDEStub

VARS = ["timestamp", "actual_q", "robot_mode", "safety_mode", "safety_status_bits", "runtime_state"]


@pytest.fixture
def stub() -> Iterator[RTDEStub]:
    baseline = threading.active_count()
    s = start_stub()
    yield s
    s.stop()
    assert not s.running()
    assert wait_for(lambda: threading.active_count() == baseline)


def _receive(stub: RTDEStub, variables: list[str] = VARS) -> rtde_receive.RTDEReceiveInterface:
    r = rtde_receive.RTDEReceiveInterface(stub.host, 50.0, variables)
    assert wait_for(lambda: r.getTimestamp() > 0.0)
    return r


def test_real_receive_reads_state_and_protective_stop(stub: RTDEStub) -> None:
    q = [0.1, -1.2, 1.3, -1.4, -1.5, 0.6]
    stub.set_joints(q)
    r = _receive(stub)
    try:
        assert wait_for(lambda: r.getActualQ() == pytest.approx(q))
        assert (r.getRobotMode(), r.getSafetyMode(), r.getRuntimeState()) == (7, 1, 2)
        assert not r.isProtectiveStopped()
        stub.protective_stop()
        assert wait_for(r.isProtectiveStopped)
        assert r.getSafetyMode() == 3 and r.getSafetyStatusBits() == 1 << 2
        stub.emergency_stop()
        assert wait_for(r.isEmergencyStopped)
        stats = stub.stats()
        assert stats["output_names"] == VARS and stats["frequency"] == 50.0
    finally:
        r.disconnect()


def test_default_recipe_of_58_variables_is_served(stub: RTDEStub) -> None:
    r = rtde_receive.RTDEReceiveInterface(stub.host, 10.0)
    try:
        assert len(stub.stats()["output_names"]) == 58
        assert wait_for(lambda: r.getRobotMode() == 7)
    finally:
        r.disconnect()


def test_connection_loss_and_not_found_and_refused(stub: RTDEStub) -> None:
    r = _receive(stub)
    assert r.isConnected()
    assert stub.drop_connections() == 1
    assert wait_for(lambda: not r.isConnected())
    r.disconnect()  # after a loss: must return (bounded), never hang
    stub.set_not_found(["safety_status_bits"])
    with pytest.raises(RuntimeError, match=r"not found by the controller: \[safety_status_bits\]"):
        rtde_receive.RTDEReceiveInterface(stub.host, 50.0, VARS)
    stub.refuse_connections(True)
    with pytest.raises(RuntimeError, match="Could not connect to"):
        rtde_receive.RTDEReceiveInterface(stub.host, 50.0, VARS)


def _arm_on_stub(stub: RTDEStub, **cfg: float) -> tuple[URArm, FakeURController]:
    """Real RTDEReceiveInterface on the stub (default factory) + the fake control interface."""
    ctrl = FakeURController(ManualClock())
    # connect_timeout only bounds a failure: generous for a loaded 2-core machine
    config = URArmConfig(host=stub.host, frequency=50.0, connect_timeout=5.0, **cfg)  # type: ignore[arg-type]
    return URArm(config, clock=MonotonicClock(), control_factory=ctrl.control_factory), ctrl


@pytest.mark.parametrize("fault", ["drop", "freeze"])
def test_adapter_goal_fails_with_connection_lost(stub: RTDEStub, fault: str) -> None:
    stub.set_joints([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
    arm, _ = _arm_on_stub(stub, stale_timeout=0.2)
    try:
        arm.open()
        goal = arm.move_to((1.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0))
        assert wait_for(lambda: goal.state is GoalState.ACTIVE)  # bound only on failure
        t0 = time.monotonic()
        if fault == "drop":
            stub.drop_connections()
        else:
            stub.freeze(True)
        assert wait_for(goal.done, 1.0)
        assert time.monotonic() - t0 < 0.2 + 0.3
        expected = "RTDE link to" if fault == "drop" else "no new RTDE data"
        assert goal.reason.startswith(f"connection lost: {expected}")
        assert not arm.connected
    finally:
        arm.close()


def test_adapter_protective_stop_from_stub(stub: RTDEStub) -> None:
    arm, _ = _arm_on_stub(stub)
    try:
        arm.open()
        goal = arm.move_to((1.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0))
        stub.protective_stop()
        assert wait_for(goal.done, 1.0)
        assert goal.reason == "protective stop"
    finally:
        arm.close()


def test_adapter_refused_and_not_found_are_one_line(stub: RTDEStub) -> None:
    stub.set_not_found(["actual_TCP_pose"])
    arm, _ = _arm_on_stub(stub)
    with pytest.raises(URConnectionError) as e:
        arm.open()
    arm.close()
    # the pre-flight handshake finds it before ur_rtde is asked to construct anything
    assert str(e.value) == f"UR {stub.host}:30004: controller answered NOT_FOUND for actual_TCP_pose"
    stub.refuse_connections(True)
    arm, _ = _arm_on_stub(stub)
    with pytest.raises(URConnectionError) as e:
        arm.open()
    arm.close()
    assert str(e.value) == f"UR {stub.host}:30004: connection refused (is the controller on and RTDE enabled?)"


def test_adapter_open_on_a_stalling_controller_fails_within_its_deadline(stub: RTDEStub) -> None:
    stub.silence(after=1)  # the handshake check is served, ur_rtde's own connection is not
    baseline = threading.active_count()
    arm = URArm(URArmConfig(host=stub.host, connect_timeout=1.0))
    with pytest.raises(URConnectionError) as e:
        arm.open()
    arm.close()
    assert str(e.value) == (f"UR {stub.host}:30004: cannot connect: ur_rtde RTDEReceiveInterface() did not return "
                            "by the connect deadline (connect_timeout 1.0 s)")
    assert wait_for(lambda: host_processes(os.getpid()) == [] and threading.active_count() <= baseline, 30.0)


def test_adapter_open_interrupted_leaves_nothing_behind(stub: RTDEStub) -> None:
    stub.silence(after=1)
    baseline = threading.active_count()
    arm = URArm(URArmConfig(host=stub.host, connect_timeout=600.0))  # only the interrupt ends it

    def ctrl_c_once_ur_rtde_waits() -> None:
        if wait_for(lambda: stub.stats()["accepted"] >= 2 and len(host_processes(os.getpid())) == 1, 60.0):
            os.kill(os.getpid(), signal.SIGALRM)

    def on_alarm(signum: int, frame: object) -> None:  # stands in for Ctrl-C's KeyboardInterrupt
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGALRM, on_alarm)
    try:
        threading.Thread(target=ctrl_c_once_ur_rtde_waits, daemon=True).start()
        with pytest.raises(KeyboardInterrupt):
            arm.open()
    finally:
        signal.signal(signal.SIGALRM, previous)
    # open() closed the adapter: the host process was killed, the worker ended
    assert wait_for(lambda: host_processes(os.getpid()) == [] and threading.active_count() <= baseline, 30.0)
    assert arm.status().fault == "closed"


def _ping_args(host: str, port: int = 30004, timeout: float = 1.0) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    bringup.add_ping_arguments(p)
    return p.parse_args(["--host", host, "--port", str(port), "--timeout", str(timeout)])


def test_ping_answers(stub: RTDEStub, capsys: pytest.CaptureFixture[str]) -> None:
    stub.set_joints([0.5, -1.0, 1.0, -1.0, -1.0, 0.25])
    # a generous per-step deadline: ur_rtde's connect took > 1 s with two suites in parallel
    # on 2 cores (the deadline only bounds a failure; an answering stub returns at once)
    assert bringup.ping(_ping_args(stub.host, timeout=5.0)) == 0
    out = capsys.readouterr().out
    assert f"ur {stub.host}:30004: controller 5.15.0.12345" in out
    assert "robot mode 7 (running), safety mode 1 (normal), runtime state 2 (playing)" in out
    assert "+0.5000 -1.0000 +1.0000 -1.0000 -1.0000 +0.2500" in out


def test_ping_failures_are_one_line(stub: RTDEStub, capsys: pytest.CaptureFixture[str]) -> None:
    stub.set_not_found(["runtime_state"])
    assert bringup.ping(_ping_args(stub.host)) == 1
    stub.set_not_found([])
    stub.freeze(True)
    assert bringup.ping(_ping_args(stub.host, timeout=0.3)) == 1
    stub.refuse_connections(True)
    assert bringup.ping(_ping_args(stub.host)) == 2  # cannot open
    out = capsys.readouterr()
    assert out.out == ""  # errors go to stderr, one line each, like every `mmexec hw ping`
    assert out.err.splitlines() == [
        f"ur {stub.host}:30004: controller answered NOT_FOUND for runtime_state",
        f"ur {stub.host}:30004: no answer within 0.3 s (waiting for 'U')",
        f"ur {stub.host}:30004: connection refused (is the controller on and RTDE enabled?)",
    ]


def test_stub_on_ephemeral_port_with_codec_probe() -> None:
    with RTDEStub("127.0.0.1", 0) as s:
        assert s.port != 0
        res = rtde_client.probe(rtde_client.RTDESession(s.host, s.port, 1.0), bringup.PING_VARIABLES)
        assert res.values["robot_mode"] == 7 and str(res.version) == "5.15.0.12345"
    assert not s.running()
