"""``mmexec hw``: exit codes and one-line errors for kobuki against the fake, and the
``fake`` subcommand run as a real process."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import pytest
from driverkit import fake_process

from mmexec.drivers import hwcli
from mmexec.drivers.fakes.kobuki import KobukiFake


@pytest.fixture
def fake() -> Iterator[KobukiFake]:
    before = threading.active_count()
    f = KobukiFake().start()
    try:
        yield f  # type: ignore[misc]
    finally:
        f.stop()
    deadline = time.monotonic() + 2.0
    while threading.active_count() > before and time.monotonic() < deadline:
        time.sleep(0.01)
    assert threading.active_count() <= before


def _one_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    assert "Traceback" not in text
    return lines[0]


def test_ping_kobuki_answers(fake: KobukiFake, capsys: pytest.CaptureFixture[str]) -> None:
    assert hwcli.main(["ping", "kobuki", "--port", fake.port]) == 0
    out = capsys.readouterr()
    line = _one_line(out.out)
    assert line.startswith(f"kobuki on {fake.port}: firmware 1.2.0, hardware 1.0.4, battery 16.5 V")
    assert "unique id 0A0B0C0D-11223344-55667788" in line
    assert out.err == ""
    assert fake.snapshot().speed == 0  # ping never moves the base


def test_ping_kobuki_silent(fake: KobukiFake, capsys: pytest.CaptureFixture[str]) -> None:
    fake.silent = True
    assert hwcli.main(["ping", "kobuki", "--port", fake.port, "--timeout", "0.2"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert line == f"kobuki on {fake.port}: no answer within 0.2 s (is the base switched on?)"


def test_ping_kobuki_no_such_port(capsys: pytest.CaptureFixture[str]) -> None:
    assert hwcli.main(["ping", "kobuki", "--port", "/dev/no-kobuki-here"]) == 2  # cannot open
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("kobuki on /dev/no-kobuki-here: no such port")


def test_ping_kobuki_corrupt_frames(fake: KobukiFake, capsys: pytest.CaptureFixture[str]) -> None:
    fake.corrupt_next(10_000)
    assert hwcli.main(["ping", "kobuki", "--port", fake.port, "--timeout", "0.2"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert line.startswith(f"kobuki on {fake.port}: corrupt frames")


def test_ping_kobuki_firmware_2(fake: KobukiFake, capsys: pytest.CaptureFixture[str]) -> None:
    fake.set_firmware(2, 0, 0)
    assert hwcli.main(["ping", "kobuki", "--port", fake.port]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "firmware 2.0.0 is not supported" in line and fake.port in line


def test_unknown_device_and_action(capsys: pytest.CaptureFixture[str]) -> None:
    assert hwcli.main(["ping", "kobuky"]) == 2
    assert "did you mean 'kobuki'?" in _one_line(capsys.readouterr().err)
    assert hwcli.main(["pong", "kobuki"]) == 2
    assert "unknown action 'pong'" in capsys.readouterr().err
    assert hwcli.main([]) == 2


def test_missing_bringup_module_is_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(hwcli.DEVICES, "lidar9000", "a device with no driver package")
    assert hwcli.main(["ping", "lidar9000", "--port", "/dev/x"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "mmexec.drivers.lidar9000.bringup is not installed" in line


def test_fake_kobuki_subprocess_ping_and_sigint() -> None:
    with fake_process("kobuki", stop=signal.SIGINT, exit_timeout=5) as port:
        assert port.startswith("/dev/"), port
        result = subprocess.run(
            [sys.executable, "-m", "mmexec.drivers.hwcli", "ping", "kobuki", "--port", port],
            capture_output=True, text=True, timeout=20, check=False,
        )
        assert result.returncode == 0, result.stderr
        assert result.stdout.startswith(f"kobuki on {port}: firmware 1.2.0")
