"""``mmexec hw ping robotiq`` / ``mmexec hw fake robotiq``: output, exit codes, one-line errors."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator

import pytest

from mmexec.drivers.fakes.robotiq import FakeRobotiq, FakeURCap
from mmexec.drivers.hwcli import main


@pytest.fixture
def fake() -> Iterator[FakeRobotiq]:
    with FakeRobotiq(activation_time=0.1, time_scale=10.0) as f:
        yield f


def one_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in text, text
    return lines[0]


def test_ping_reads_status(fake: FakeRobotiq, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ping", "robotiq", "--port", fake.port]) == 0
    out = capsys.readouterr()
    assert one_line(out.out) == (f"robotiq on {fake.port}: reset, fault none, position "
                                 "0.0850 m (gPO 0), no motion requested")
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
    assert main(["ping", "robotiq", "--port", "/dev/no-gripper"]) == 1
    assert one_line(capsys.readouterr().err) == (
        "robotiq on /dev/no-gripper: no such port (is the device plugged in?)")


def test_ping_device_fault(fake: FakeRobotiq, capsys: pytest.CaptureFixture[str]) -> None:
    fake.model.inject_fault(0x0A)
    assert main(["ping", "robotiq", "--port", fake.port]) == 1
    assert one_line(capsys.readouterr().err) == (
        f"robotiq on {fake.port}: device fault: reset, fault 0x0A under-voltage, position "
        "0.0850 m (gPO 0), no motion requested")


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
        server.estop = True
        assert main(["ping", "robotiq", "--host", "127.0.0.1", "--tcp-port",
                     str(server.port)]) == 1
        assert "emergency-stopped" in one_line(capsys.readouterr().err)


def test_ping_urcap_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with FakeURCap() as server:
        port = server.port
    assert main(["ping", "robotiq", "--host", "127.0.0.1", "--tcp-port", str(port)]) == 1
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
