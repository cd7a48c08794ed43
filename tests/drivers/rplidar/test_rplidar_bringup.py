"""``mmexec hw ping rplidar`` exit codes (0 ready, 1 fault, 2 cannot open) with one line,
and ``mmexec hw fake rplidar`` as a real process."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from collections.abc import Callable

import pytest
from driverkit import fake_process

from mmexec.drivers import hwcli
from mmexec.drivers.fakes.rplidar import RplidarFake


def _one_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    assert "Traceback" not in text
    return lines[0]


def _ping(port: str, *extra: str) -> int:
    return hwcli.main(["ping", "rplidar", "--port", port, "--duration", "0.5", *extra])


def test_ping_a_ready_lidar_prints_identity_and_measured_scans(
        fake: RplidarFake, capsys: pytest.CaptureFixture[str], wait_until: Callable[..., bool]) -> None:
    assert _ping(fake.port) == 0
    out = capsys.readouterr()
    line = _one_line(out.out)
    assert out.err == ""
    assert line.startswith(f"rplidar on {fake.port}: A2M8 (model 0x28), firmware 1.29, hardware 7, "
                           "serial 101112131415161718191A1B1C1D1E1F, health good, ")
    m = re.search(r", ([\d.]+) Hz, (\d+) points/rev, motor PWM 660$", line)
    assert m, line
    # the fake: 10 Hz of wall time (a loose bound, arrival times jitter), 2000 samples/s
    assert 5.0 < float(m.group(1)) < 20.0 and 198 <= int(m.group(2)) <= 202
    # stopped on exit (the fake reads in its own thread: a bounded wait for what it saw)
    assert wait_until(lambda: not fake.motor_running and fake.snapshot().stops >= 2, 1.0)


def test_ping_shows_a_health_warning_and_still_passes(fake: RplidarFake,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    fake.set_health(1, 0x0012)
    assert _ping(fake.port) == 0
    assert "health WARNING (code 0x0012)" in _one_line(capsys.readouterr().out)


@pytest.mark.parametrize("switch, value, text", [
    ("silent", True, "no answer to GET_INFO within 0.5 s"),
    ("garbage", True, "no valid answer to GET_INFO within 0.5 s"),
    ("motor_stopped", True, "no complete scan for "),
    ("no_start_flag", True, "nodes without a start flag"),
    ("bad_check_bits", 1.0, "corrupt stream"),
])
def test_ping_a_faulty_lidar_exits_1_with_one_line(fake: RplidarFake, capsys: pytest.CaptureFixture[str],
                                                   switch: str, value: object, text: str) -> None:
    setattr(fake, switch, value)
    assert _ping(fake.port) == 1
    out = capsys.readouterr()
    line = _one_line(out.err)
    assert line.startswith(f"rplidar on {fake.port}: ") and text in line, line
    assert out.out == ""


def test_ping_refuses_a_health_error(fake: RplidarFake, capsys: pytest.CaptureFixture[str]) -> None:
    fake.set_health(2, 0x8001)
    assert _ping(fake.port) == 1
    assert "health ERROR (error code 0x8001)" in _one_line(capsys.readouterr().err)
    assert fake.snapshot().pwm_commands == []            # the motor was never started


def test_ping_a_port_that_cannot_be_opened_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert _ping("/dev/no-such-rplidar") == 2
    assert _one_line(capsys.readouterr().err) == (
        "rplidar on /dev/no-such-rplidar: no such port (is the device plugged in?)")


def test_ping_bad_options_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert _ping("/dev/x", "--timeout", "0") == 2
    assert "must be > 0" in _one_line(capsys.readouterr().err)
    assert _ping("/dev/x", "--pwm", "5000") == 2
    assert "motor_pwm: expected 1..1023" in _one_line(capsys.readouterr().err)


def test_fake_rplidar_subprocess_ping_and_sigterm() -> None:
    with fake_process("rplidar", stop=signal.SIGTERM, exit_timeout=10) as port:
        assert port.startswith("/dev/"), port
        result = subprocess.run(
            [sys.executable, "-m", "mmexec.drivers.hwcli", "ping", "rplidar", "--port", port, "--duration", "0.5"],
            capture_output=True, text=True, timeout=30, check=False)
        assert result.returncode == 0, result.stderr
        assert result.stdout.startswith(f"rplidar on {port}: A2M8")
