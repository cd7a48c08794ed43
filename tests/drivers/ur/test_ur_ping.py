"""``mmexec hw ping ur``: fitness (exit 1 when the controller answers but the arm cannot
run), link quality (lost / late frames, a warning above 1 %), exit codes 0 / 1 / 2, one
line on stderr. The controller is the RTDE local_stub process with its vendor-numbered state
switches; on an ephemeral port (our client only) unless the test is about ur_rtde."""

from __future__ import annotations

import argparse

import pytest
from urtest_helpers import start_stub

from mmexec.drivers.ur import bringup
from mmexec.drivers.ur.rtde_stub import RTDEStub


def ping(local_stub: RTDEStub, capsys: pytest.CaptureFixture[str], *extra: str,
         host: str | None = None, port: int | None = None) -> tuple[int, list[str], list[str]]:
    """Run the ping (0.3 s of streaming at 125 Hz); returns (exit status, stdout lines,
    stderr lines). Only a frame 5 s late counts as late unless ``extra`` says otherwise:
    on a loaded test machine the stub and this reader (both Python) are not real-time."""
    p = argparse.ArgumentParser()
    bringup.add_ping_arguments(p)
    args = p.parse_args(["--host", host or local_stub.host, "--port", str(port or local_stub.port),
                         "--duration", "0.3", "--timeout", "5", "--frequency", "125", "--late", "5", *extra])
    code = bringup.ping(args)
    out = capsys.readouterr()
    return code, out.out.splitlines(), out.err.splitlines()


def test_ready_controller(local_stub: RTDEStub, capsys: pytest.CaptureFixture[str]) -> None:
    local_stub.set_joints([0.5, -1.0, 1.0, -1.0, -1.0, 0.25])
    code, out, err = ping(local_stub, capsys)
    assert (code, err) == (0, [])
    where = f"ur {local_stub.host}:{local_stub.port}"
    assert out[0] == f"{where}: controller 5.15.0.12345"
    assert out[1] == "  robot mode 7 (running), safety mode 1 (normal), runtime state 2 (playing)"
    assert out[2] == "  joints [rad]: +0.5000 -1.0000 +1.0000 -1.0000 -1.0000 +0.2500"
    assert out[3].startswith("  link: ") and " 0 lost" in out[3]


@pytest.mark.parametrize(
    ("state", "fault"),
    [
        ({"robot_mode": 3}, "robot mode 3 (power off): power the arm on and release the brakes on the pendant"),
        ({"robot_mode": 5}, "robot mode 5 (idle): release the brakes on the pendant"),
        ({"robot_mode": 1}, "robot mode 1 (confirm safety): confirm the safety configuration on the pendant"),
        ({"safety_mode": 3}, "protective stop: unlock it on the pendant"),
        ({"safety_mode": 7, "robot_mode": 3},
         "emergency stop (robot emergency stop): release the emergency stop button, then reset on the pendant"),
        ({"safety_mode": 6},
         "emergency stop (system emergency stop): release the emergency stop button, then reset on the pendant"),
        ({"safety_mode": 5}, "safeguard stop (safeguard stop): clear the safeguard input"),
        ({"safety_mode": 9}, "safety fault (safety mode 9: fault): see the pendant's safety log"),
    ],
    ids=["power_off", "idle", "confirm_safety", "protective", "robot_estop", "system_estop", "safeguard", "fault"],
)
def test_unfit_controller_exits_1_in_one_line(local_stub: RTDEStub, capsys: pytest.CaptureFixture[str],
                                              state: dict[str, int], fault: str) -> None:
    local_stub.set_state(**state)
    code, out, err = ping(local_stub, capsys)
    assert code == 1
    assert err == [f"ur {local_stub.host}:{local_stub.port}: not fit to run: {fault}"]
    assert out[0].endswith("controller 5.15.0.12345")  # what it read is still shown


@pytest.mark.parametrize("state", [{"safety_mode": 2}, {"runtime_state": 1}, {"runtime_state": 4}],
                         ids=["reduced", "program_stopped", "program_paused"])
def test_reduced_mode_and_no_program_are_fit(local_stub: RTDEStub, capsys: pytest.CaptureFixture[str],
                                             state: dict[str, int]) -> None:
    # ur_rtde's control interface uploads and starts its own script: no program needs to run
    local_stub.set_state(**state)
    code, _out, err = ping(local_stub, capsys)
    assert (code, err) == (0, [])


def test_lost_frames_warn_above_one_percent(local_stub: RTDEStub, capsys: pytest.CaptureFixture[str]) -> None:
    local_stub.set_link(skip_every=10)  # every 10th frame never sent: 10 % lost
    code, out, err = ping(local_stub, capsys)
    assert code == 0
    lost = int(out[3].split(" lost")[0].rsplit(" ", 1)[1])
    frames = int(out[3].split("link: ")[1].split(" ")[0])
    assert lost == pytest.approx(frames / 9, abs=2)
    assert len(err) == 1
    assert err[0].startswith(f"ur {local_stub.host}:{local_stub.port}: warning: link quality ")
    assert "lost or late (above 1 %" in err[0]


def test_late_frames_warn(local_stub: RTDEStub, capsys: pytest.CaptureFixture[str]) -> None:
    local_stub.set_link(hold=0.2)  # frames held back and sent in bursts: most arrive late
    code, out, err = ping(local_stub, capsys, "--late", "0.05")
    assert code == 0
    late = int(out[3].split(" late")[0].rsplit(" ", 1)[1])
    assert late > 0
    assert len(err) == 1 and ": warning: link quality " in err[0]


def test_fault_and_poor_link_are_one_line(local_stub: RTDEStub, capsys: pytest.CaptureFixture[str]) -> None:
    local_stub.set_link(skip_every=5)
    local_stub.protective_stop()
    code, _out, err = ping(local_stub, capsys)
    assert code == 1
    assert len(err) == 1
    assert err[0].startswith(f"ur {local_stub.host}:{local_stub.port}: not fit to run: protective stop: unlock it on the pendant; "
                             "also link quality ")


@pytest.mark.parametrize(
    ("extra", "problem"),
    [
        (["--timeout", "0"], "--timeout must be a number of seconds in (0, 60], got 0.0"),
        (["--duration", "nan"], "--duration must be a number of seconds in (0, 60], got nan"),
        (["--frequency", "600"], "--frequency must be in (0, 500] Hz, got 600.0"),
    ],
)
def test_bad_input_exits_2(local_stub: RTDEStub, capsys: pytest.CaptureFixture[str], extra: list[str], problem: str) -> None:
    code, out, err = ping(local_stub, capsys, *extra)
    assert (code, out, err) == (2, [], [f"ur {local_stub.host}:{local_stub.port}: {problem}"])


def test_cannot_open_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    with RTDEStub("127.0.0.1", 0) as s:
        s.refuse_connections(True)
        code, out, err = ping(s, capsys)
    assert (code, out) == (2, [])
    assert err == [f"ur {s.host}:{s.port}: connection refused (is the controller on and RTDE enabled?)"]


def test_ur_rtde_that_cannot_connect_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    # our handshake is answered, ur_rtde's connection is not: its constructor would hold the
    # GIL for good in this process; in the host process it is killed at the deadline
    local_stub = start_stub()
    try:
        local_stub.silence(after=1)
        code, _out, err = ping(local_stub, capsys, "--timeout", "1", host=local_stub.host, port=30004)
    finally:
        local_stub.stop()
    assert code == 1
    assert err == [f"ur {local_stub.host}:30004: ur_rtde RTDEReceiveInterface() did not return within 1.00 s"]
