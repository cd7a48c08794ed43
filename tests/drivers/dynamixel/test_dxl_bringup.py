"""``mmexec hw ping dynamixel`` / ``mmexec hw fake dynamixel`` contract functions."""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys

import pytest

from mmexec.drivers.dynamixel import bringup
from mmexec.drivers.fakes.dynamixel import FakeDxlBus


def ping_args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    bringup.add_ping_arguments(p)
    return p.parse_args(list(argv))


def test_parse_ids() -> None:
    assert bringup.parse_ids("1-3,7, 9") == [1, 2, 3, 7, 9]
    with pytest.raises(ValueError, match="bad id range 'x'"):
        bringup.parse_ids("1,x")
    with pytest.raises(ValueError, match="0-252"):
        bringup.parse_ids("250-254")


def test_ping_lists_servos(fake: FakeDxlBus, capsys: pytest.CaptureFixture[str]) -> None:
    assert bringup.ping(ping_args("--port", fake.port, "--ids", "1-9", "--latency-ms", "20")) == 0
    out, err = capsys.readouterr()
    lines = out.splitlines()
    assert len(lines) == 9 and err == ""
    assert lines[0] == "id 1: XM430-W350 (model 1020), firmware 46"
    assert lines[8] == "id 9: XL430-W250 (model 1060), firmware 46"


def test_ping_reports_missing_ids_and_faults(
    fake: FakeDxlBus, capsys: pytest.CaptureFixture[str]
) -> None:
    fake.servo(4).present = False
    fake.inject_hardware_error(2, "overload")
    assert bringup.ping(ping_args("--port", fake.port, "--ids", "1-5", "--latency-ms", "20")) == 1
    out, err = capsys.readouterr()
    assert "id 2: XM430-W350 (model 1020), firmware 46, HARDWARE ERROR: overload" in out
    assert err.strip() == f"dynamixel {fake.port}: no answer within the deadline from ids 4"


def test_ping_silent_bus_and_corrupt_frames(
    fake: FakeDxlBus, capsys: pytest.CaptureFixture[str]
) -> None:
    fake.silent = True
    assert bringup.ping(ping_args("--port", fake.port, "--ids", "1-2", "--latency-ms", "5")) == 1
    assert capsys.readouterr().err.strip() == (
        f"dynamixel {fake.port}: no answer within the deadline from any of ids 1-2 at 1000000 baud"
    )
    fake.silent = False
    fake.corrupt_replies = 100
    assert bringup.ping(ping_args("--port", fake.port, "--ids", "1", "--latency-ms", "5")) == 1
    assert "corrupt frames" in capsys.readouterr().err


def test_ping_port_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert bringup.ping(ping_args("--port", "/dev/no-such-u2d2")) == 1
    err = capsys.readouterr().err
    assert err.strip() == "dynamixel /dev/no-such-u2d2: no such port (is the device plugged in?)"
    assert bringup.ping(ping_args("--port", "/dev/x", "--ids", "1-x")) == 2
    assert "bad id range" in capsys.readouterr().err


def test_run_fake_serves_until_sigterm() -> None:
    code = (
        "import argparse, sys\nfrom mmexec.drivers.dynamixel import bringup as b\n"
        "p = argparse.ArgumentParser(); b.add_fake_arguments(p)\n"
        "sys.exit(b.run_fake(p.parse_args(sys.argv[1:])))\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "--locobot"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/pts/") and os.path.exists(port)
        assert bringup.ping(ping_args("--port", port, "--ids", "1-11", "--latency-ms", "20")) == 0
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
