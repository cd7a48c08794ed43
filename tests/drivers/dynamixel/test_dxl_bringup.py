"""``mmexec hw ping dynamixel`` / ``mmexec hw fake dynamixel`` contract functions: the report,
exit codes (0 ready, 1 answered but not fit or no useful answer, 2 bad input or the port cannot
be opened), hardware errors and alerts, link quality."""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys

import pytest

from mmexec.drivers.dynamixel import bringup
from mmexec.drivers.fakes.dynamixel import FakeDxlBus, wx250s_servos


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


LINK = re.compile(
    r"^dynamixel (\S+): link: (\d+) exchanges with (\d+) servos, (\d+) lost, (\d+) corrupt "
    r"\((\d+\.\d) %\)$"
)


def link(line: str) -> tuple[int, int, int, int, float]:
    """(exchanges, servos, lost, corrupt, percent) of the link line."""
    m = LINK.match(line)
    assert m, line
    return int(m[2]), int(m[3]), int(m[4]), int(m[5]), float(m[6])


def test_ping_lists_servos(fake: FakeDxlBus, capsys: pytest.CaptureFixture[str]) -> None:
    assert bringup.ping(ping_args("--port", fake.port, "--ids", "1-9", "--latency-ms", "20")) == 0
    out, err = capsys.readouterr()
    lines = out.splitlines()
    assert len(lines) == 10 and err == ""
    assert lines[0] == "id 1: XM430-W350 (model 1020), firmware 46"
    assert lines[8] == "id 9: XL430-W250 (model 1060), firmware 46"
    # each servo: the ping it answered and 10 more (the read of Hardware Error Status aside)
    assert link(lines[9]) == (9 * 11, 9, 0, 0, 0.0)


def test_ping_locobot_head(capsys: pytest.CaptureFixture[str], no_leaks: None) -> None:
    with FakeDxlBus(wx250s_servos(locobot=True)) as fake:
        args = ping_args("--port", fake.port, "--ids", "10-11", "--latency-ms", "20")
        assert bringup.ping(args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[:2] == [
        "id 10: 2XL430-W250 (model 1090), firmware 46",
        "id 11: 2XL430-W250 (model 1090), firmware 46",
    ]


@pytest.mark.parametrize("faults", [("overload",), ("input_voltage", "overheating")])
def test_ping_hardware_error_exits_1(
    fake: FakeDxlBus, capsys: pytest.CaptureFixture[str], faults: tuple[str, ...]
) -> None:
    fake.inject_hardware_error(7, *faults)
    assert bringup.ping(ping_args("--port", fake.port, "--ids", "6-8", "--latency-ms", "20")) == 1
    out, err = capsys.readouterr()
    assert f"id 7: XM430-W350 (model 1020), firmware 46, HARDWARE ERROR: {', '.join(faults)}" in out
    assert err.strip() == (
        f"dynamixel {fake.port}: servo fault: id 7 {'+'.join(faults)} (torque is off: find the "
        "cause, then reboot the servo, e.g. power-cycle or WX250s.reboot())"
    )


def test_ping_alert_bit_alone_exits_1(fake: FakeDxlBus, capsys: pytest.CaptureFixture[str]) -> None:
    # a servo whose status packets carry the alert bit is not fit, whatever register 70 says
    # (here: a model whose control table the driver does not know, so 70 is not read)
    from mmexec.drivers.fakes.dynamixel import FakeServo

    odd = FakeServo(20, "XC430-W150")
    odd.fault(0x20, 0.0)  # overload, enabled in the factory Shutdown mask: alert bit set
    fake.servos.append(odd)
    assert bringup.ping(ping_args("--port", fake.port, "--ids", "20", "--latency-ms", "20")) == 1
    out, err = capsys.readouterr()
    assert out.splitlines()[0] == (
        "id 20: unknown model (model 1070), firmware 46, HARDWARE ALERT (alert bit set in its "
        "status packets)"
    )
    assert err.strip().startswith(f"dynamixel {fake.port}: servo fault: id 20 alert (torque is off")


def test_ping_unreadable_hardware_error_status_exits_1(
    fake: FakeDxlBus, capsys: pytest.CaptureFixture[str]
) -> None:
    # Status Return Level 0: the servo answers pings only, so its faults cannot be checked
    fake.servo(6)._set("status_return_level", 0)
    args = ping_args("--port", fake.port, "--ids", "6", "--latency-ms", "5", "--count", "2")
    assert bringup.ping(args) == 1
    assert capsys.readouterr().err.strip() == (
        f"dynamixel {fake.port}: Hardware Error Status unreadable from id 6 (no valid reply to a "
        "read in 3 attempts (Status Return Level 0, or noise?))"
    )


def test_ping_poor_link_warns_but_is_ready(
    fake: FakeDxlBus, capsys: pytest.CaptureFixture[str]
) -> None:
    fake.corrupt_every = 13
    fake.drop_every = 17
    args = ping_args("--port", fake.port, "--ids", "1-4", "--latency-ms", "5", "--count", "30")
    assert bringup.ping(args) == 0
    out, err = capsys.readouterr()
    exchanges, servos, lost, corrupt, percent = link(out.splitlines()[-1])
    assert servos == 4 and lost > 0 and corrupt > 0 and percent > 1.0
    assert percent == pytest.approx(100 * (lost + corrupt) / exchanges, abs=0.05)
    assert err.strip() == (
        f"dynamixel {fake.port}: warning: link quality {percent:.1f} % lost or corrupt (above "
        "1 %: check the cables and connectors, the adapter's latency timer and the baud rate)"
    )


def test_ping_fault_and_poor_link_is_one_line(
    fake: FakeDxlBus, capsys: pytest.CaptureFixture[str]
) -> None:
    fake.inject_hardware_error(2, "overload")
    fake.corrupt_every = 5
    args = ping_args("--port", fake.port, "--ids", "1-2", "--latency-ms", "5", "--count", "20")
    assert bringup.ping(args) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "servo fault: id 2 overload" in err and "; also link quality" in err


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
    assert bringup.ping(ping_args("--port", "/dev/no-such-u2d2")) == 2
    err = capsys.readouterr().err
    assert err.strip() == "dynamixel /dev/no-such-u2d2: no such port (is the device plugged in?)"
    assert bringup.ping(ping_args("--port", "/dev/x", "--ids", "1-x")) == 2
    assert "bad id range" in capsys.readouterr().err
    assert bringup.ping(ping_args("--port", "/dev/x", "--count", "-1")) == 2
    assert capsys.readouterr().err.strip() == "dynamixel /dev/x: --count must be in 0..1000, got -1"


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
