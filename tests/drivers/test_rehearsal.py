"""The bring-up rehearsal of docs/drivers/fakes.md, step by step: start each fake as
``mmexec hw fake DEVICE`` (a real process, as a user would), ``mmexec hw ping`` it, start it
again with a fault switch and see the one-line error and the non-zero exit."""

from __future__ import annotations

import os
import random
import subprocess
import sys

import pytest
from driverkit import fake_process

from mmexec.drivers.hwcli import main

HW = [sys.executable, "-m", "mmexec.drivers.hwcli"]


def ping(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    rc = main(["ping", *args])
    out = capsys.readouterr()
    assert "Traceback" not in out.out + out.err
    return rc, out.out, out.err.strip()


def test_kobuki(capsys: pytest.CaptureFixture[str]) -> None:
    with fake_process("kobuki") as port:
        rc, out, err = ping(capsys, "kobuki", "--port", port)
        assert rc == 0 and out.startswith(f"kobuki on {port}: firmware 1.2.0") and err == ""
    with fake_process("kobuki", "--firmware", "2.0.0") as port:
        # as a process too: the refusal the driver's I/O thread logs is not printed twice
        result = subprocess.run([*HW, "ping", "kobuki", "--port", port], capture_output=True,
                                text=True, timeout=30, check=False)
        assert result.returncode == 1 and result.stdout == ""
        refusal = (f"kobuki on {port}: firmware 2.0.0 is not supported (major version must "
                   "be 1; the vendor recommends 1.1.4 or 1.2.0)")
        assert result.stderr.splitlines() == [refusal]


def test_dynamixel(capsys: pytest.CaptureFixture[str]) -> None:
    with fake_process("dynamixel", "--missing", "5", "--hardware-error", "4:overload") as port:
        rc, out, err = ping(capsys, "dynamixel", "--port", port, "--ids", "1-9", "--latency-ms", "20")
        assert rc == 1 and err == f"dynamixel {port}: no answer within the deadline from ids 5"
        assert "id 4: XM430-W350 (model 1020), firmware 46, HARDWARE ERROR: overload" in out
        rc, out, err = ping(capsys, "dynamixel", "--port", port, "--ids", "1-4", "--latency-ms", "20")
        assert rc == 1 and err.startswith(f"dynamixel {port}: servo fault: id 4 overload (torque is off")
    with fake_process("dynamixel") as port:
        rc, out, err = ping(capsys, "dynamixel", "--port", port, "--latency-ms", "20")
        assert rc == 0 and len(out.splitlines()) == 9 + 1 and err == ""  # servos + link line


def test_dynamixel_bad_fault_switch_is_one_line() -> None:
    result = subprocess.run([*HW, "fake", "dynamixel", "--hardware-error", "4:overlaod"],
                            capture_output=True, text=True, timeout=30, check=False)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.strip() == ("dynamixel fake: --hardware-error: unknown hardware fault "
                                     "'overlaod' (known: input_voltage, overheating, "
                                     "motor_encoder, electrical_shock, overload)")


def test_robotiq(capsys: pytest.CaptureFixture[str]) -> None:
    with fake_process("robotiq", "--activation-time", "0.2") as port:
        rc, out, err = ping(capsys, "robotiq", "--port", port, "--activate")
        assert rc == 0 and out.startswith(f"robotiq on {port}: activated") and err == ""
    with fake_process("robotiq", "--fault", "0x0A") as port:
        rc, out, err = ping(capsys, "robotiq", "--port", port)
        assert rc == 1 and err.startswith(f"robotiq on {port}: device fault: ")
        assert "fault 0x0A under-voltage" in err and "\n" not in err


def test_ur(capsys: pytest.CaptureFixture[str]) -> None:
    # the RTDE port is fixed (30004): a random loopback address keeps parallel runs apart
    host = f"127.0.0.{random.SystemRandom().randrange(2, 250)}"
    with fake_process("ur", "--host", host) as where:
        assert where == f"{host}:30004"
        rc, out, err = ping(capsys, "ur", "--host", host)
        assert rc == 0 and out.startswith(f"ur {host}:30004: controller ") and err == ""
    rc, out, err = ping(capsys, "ur", "--host", host, "--timeout", "0.5")  # the fake is gone
    assert rc == 2 and out == "" and "\n" not in err and err.startswith(f"ur {host}:30004: ")  # cannot open


def test_ping_into_a_closed_pipe_exits_quietly() -> None:
    # `mmexec hw ping kobuki ... | head -0`: the reader is gone before the line is written;
    # the ping closes the device and exits 141 (128 + SIGPIPE) with nothing on stderr,
    # as the other commands do (it printed "BrokenPipeError" and exited 1)
    from mmexec.config.brokenpipe import EXIT_BROKEN_PIPE

    mmexec = os.path.join(os.path.dirname(sys.executable), "mmexec")
    with fake_process("kobuki") as port:
        for argv in ([mmexec, "hw"], HW):
            read_end, write_end = os.pipe()
            os.close(read_end)
            try:
                res = subprocess.run([*argv, "ping", "kobuki", "--port", port], stdout=write_end,
                                     stderr=subprocess.PIPE, text=True, timeout=60, check=False)
            finally:
                os.close(write_end)
            assert (res.returncode, res.stderr) == (EXIT_BROKEN_PIPE, "")
