"""``mmexec hw ping robotiq`` / ``mmexec hw fake robotiq``: output, exit codes (0 ready, 1 the
gripper answered but is not fit or gave no useful answer, 2 bad input or cannot open), one-line
errors, the transient 0x09 and link quality."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator

import pytest
from robotiq_helpers import wait_for

from mmexec.drivers.fakes.robotiq import FakeRobotiq, FakeURCap
from mmexec.drivers.hwcli import main

#: the link-quality tail of the report line
LINK = r"; link: (\d+) exchanges, (\d+) lost, (\d+) corrupt \((\d+\.\d) %\)$"


@pytest.fixture
def fake() -> Iterator[FakeRobotiq]:
    with FakeRobotiq(activation_time=0.1, time_scale=10.0) as f:
        yield f


def one_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in text, text
    return lines[0]


def link(line: str) -> tuple[int, int, int, float]:
    """(exchanges, lost, corrupt, percent) from a report line."""
    m = re.search(LINK, line)
    assert m, line
    return int(m[1]), int(m[2]), int(m[3]), float(m[4])


def test_ping_reads_status(fake: FakeRobotiq, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ping", "robotiq", "--port", fake.port]) == 0
    out = capsys.readouterr()
    line = one_line(out.out)
    assert line.startswith(f"robotiq on {fake.port}: reset, fault none, position "
                           "0.0850 m (gPO 0), no motion requested; link: ")
    exchanges, lost, corrupt, _ = link(line)
    assert exchanges >= 21 and lost == corrupt == 0       # the first read and 20 more
    assert out.err == ""
    assert fake.model.writes == []          # a plain ping writes nothing


def test_ping_activate(fake: FakeRobotiq, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ping", "robotiq", "--port", fake.port, "--activate"]) == 0
    assert one_line(capsys.readouterr().out).startswith(f"robotiq on {fake.port}: activated, "
                                                        "fault none")
    assert fake.model.status().gSTA == 3


@pytest.mark.parametrize(
    ("switch", "reason"),
    [("silent", "no answer within the deadline"), ("corrupt_replies", "corrupt frame")],
)
def test_ping_link_problems(fake: FakeRobotiq, capsys: pytest.CaptureFixture[str], switch: str,
                            reason: str) -> None:
    setattr(fake, switch, True)
    assert main(["ping", "robotiq", "--port", fake.port, "--timeout", "0.05"]) == 1
    out = capsys.readouterr()
    line = one_line(out.err)
    assert line.startswith(f"robotiq on {fake.port}: {reason}")
    assert out.out == ""


def test_ping_no_such_port(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ping", "robotiq", "--port", "/dev/no-gripper"]) == 2
    assert one_line(capsys.readouterr().err) == (
        "robotiq on /dev/no-gripper: no such port (is the device plugged in?)")


@pytest.mark.parametrize(("code", "name"), [(0x0A, "under-voltage"), (0x08, "over-temperature"),
                                             (0x0E, "overcurrent")])
def test_ping_device_fault(fake: FakeRobotiq, capsys: pytest.CaptureFixture[str], code: int,
                           name: str) -> None:
    fake.model.inject_fault(code)
    assert main(["ping", "robotiq", "--port", fake.port]) == 1
    out = capsys.readouterr()
    assert one_line(out.err) == (
        f"robotiq on {fake.port}: device fault: reset, fault 0x{code:02X} {name}, position "
        "0.0850 m (gPO 0), no motion requested")
    assert one_line(out.out).startswith(f"robotiq on {fake.port}: reset, fault 0x{code:02X}")


@pytest.mark.parametrize("answers", [1, 3])
def test_ping_after_activate_waits_for_no_communication_to_clear(
        fake: FakeRobotiq, capsys: pytest.CaptureFixture[str], answers: int) -> None:
    # ping --activate, then more than a second (of gripper time) without traffic: the
    # gripper raises 0x09, and traffic clears it (after `answers` answers that still say so)
    fake.model.comm_fault_answers = answers
    assert main(["ping", "robotiq", "--port", fake.port, "--activate"]) == 0
    capsys.readouterr()
    assert wait_for(lambda: fake.model.status().gFLT == 0x09, 2.0)
    assert main(["ping", "robotiq", "--port", fake.port]) == 0
    out = capsys.readouterr()
    assert one_line(out.out).startswith(f"robotiq on {fake.port}: activated, fault none")
    assert out.err == ""


def test_ping_no_communication_that_does_not_clear_is_a_fault(
        fake: FakeRobotiq, capsys: pytest.CaptureFixture[str]) -> None:
    fake.model.comm_fault_answers = 10**9
    assert main(["ping", "robotiq", "--port", fake.port, "--activate"]) == 0
    capsys.readouterr()
    assert wait_for(lambda: fake.model.status().gFLT == 0x09, 2.0)
    assert main(["ping", "robotiq", "--port", fake.port, "--reads", "5"]) == 1
    assert one_line(capsys.readouterr().err) == (
        f"robotiq on {fake.port}: device fault: activated, fault 0x09 no communication, "
        "position 0.0850 m (gPO 0), no motion requested (did not clear over 5 reads)")


def test_ping_poor_link_warns_but_is_ready(fake: FakeRobotiq,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    fake.corrupt_every = 7
    fake.drop_every = 11
    assert main(["ping", "robotiq", "--port", fake.port, "--reads", "60"]) == 0
    out = capsys.readouterr()
    exchanges, lost, corrupt, percent = link(one_line(out.out))
    assert lost > 0 and corrupt > 0 and percent > 1.0
    assert percent == pytest.approx(100 * (lost + corrupt) / exchanges, abs=0.05)
    assert one_line(out.err) == (
        f"robotiq on {fake.port}: warning: link quality {percent:.1f} % lost or corrupt "
        "(above 1 %: check the cable, the RS-485 adapter and the baud rate)")


def test_ping_fault_and_poor_link_is_one_line(fake: FakeRobotiq,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    fake.model.inject_fault(0x0A)
    fake.corrupt_every = 3
    assert main(["ping", "robotiq", "--port", fake.port]) == 1
    err = one_line(capsys.readouterr().err)
    assert "device fault: reset, fault 0x0A under-voltage" in err
    assert "; also link quality " in err


def test_ping_bad_reads_is_bad_input(fake: FakeRobotiq, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ping", "robotiq", "--port", fake.port, "--reads", "0"]) == 2
    assert one_line(capsys.readouterr().err) == "robotiq: --reads must be in 1..1000, got 0"


def test_ping_activation_fault(fake: FakeRobotiq, capsys: pytest.CaptureFixture[str]) -> None:
    fake.model.activation_fault = True
    assert main(["ping", "robotiq", "--port", fake.port, "--activate"]) == 1
    line = one_line(capsys.readouterr().err)
    assert line.startswith(f"robotiq on {fake.port}: activation failed: gripper fault 0x0D "
                           "activation fault (major)")


def test_ping_urcap(capsys: pytest.CaptureFixture[str]) -> None:
    with FakeURCap(activation_time=0.1, time_scale=10.0) as server:
        assert main(["ping", "robotiq", "--host", "127.0.0.1", "--tcp-port", str(server.port),
                     "--activate"]) == 0
        assert one_line(capsys.readouterr().out).startswith(
            f"robotiq urcap on 127.0.0.1:{server.port}: activated")
        # 0x09 after silence, cleared by the traffic of the next ping
        assert wait_for(lambda: server.model.status().gFLT == 0x09, 2.0)
        assert main(["ping", "robotiq", "--host", "127.0.0.1", "--tcp-port",
                     str(server.port)]) == 0
        assert "activated, fault none" in one_line(capsys.readouterr().out)
        server.garble_every = 9                  # one answer line in 9 garbled: above 1 %
        assert main(["ping", "robotiq", "--host", "127.0.0.1", "--tcp-port",
                     str(server.port)]) == 0
        out = capsys.readouterr()
        assert link(one_line(out.out))[2] > 0 and "warning: link quality" in one_line(out.err)
        server.garble_every = 0
        server.estop = True
        assert main(["ping", "robotiq", "--host", "127.0.0.1", "--tcp-port",
                     str(server.port)]) == 1
        assert "emergency-stopped" in one_line(capsys.readouterr().err)


def test_ping_urcap_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with FakeURCap() as server:
        port = server.port
    assert main(["ping", "robotiq", "--host", "127.0.0.1", "--tcp-port", str(port)]) == 2
    assert one_line(capsys.readouterr().err) == (
        f"robotiq urcap on 127.0.0.1:{port}: connection refused (is the Robotiq URCap "
        "installed and the controller on?)")


def test_fake_process_prints_port_and_stops_on_sigterm() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "mmexec.drivers.hwcli", "fake", "robotiq", "--activation-time",
         "0.1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        port = proc.stdout.readline().strip()
        if not port.startswith("/dev/pts/"):  # say why the fake ended instead of printing it
            proc.kill()
            _, err = proc.communicate(timeout=10)
            pytest.fail(f"fake printed {port!r}, exit {proc.returncode}, stderr: {err}")
        assert os.path.exists(port)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=5)
    assert proc.stderr is not None and "Traceback" not in proc.stderr.read()
