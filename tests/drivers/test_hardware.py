"""Hardware-in-the-loop bring-up: ``mmexec hw ping`` and a read-only driver bring-up
against real devices named by environment variables (docs/drivers/bringup.md section 3).

Marked ``hardware``: CI deselects them (``pytest -m "not hardware"``). Run on the robot::

    MMEXEC_KOBUKI_PORT=/dev/kobuki MMEXEC_DXL_PORT=/dev/ttyDXL \\
        pytest -m hardware tests/drivers/test_hardware.py

A test whose variable is unset FAILS, saying which variable to set: a hardware run that
silently checks nothing would read as a pass. Nothing here moves the robot: the base gets
no velocity command, the arm holds the pose it is in (torque on, as at every bring-up),
the gripper is not activated, the UR arm is only read (RTDE receive).
"""

from __future__ import annotations

import os
import time

import pytest

from mmexec.drivers.hwcli import main

pytestmark = pytest.mark.hardware


def device(variable: str, example: str, what: str) -> str:
    """The value of ``variable``, or a test failure telling how to set it."""
    value = os.environ.get(variable, "").strip()
    if not value:
        pytest.fail(
            f"{variable} is not set: set it to the {what}, e.g. `{variable}={example} "
            f"pytest -m hardware tests/drivers/test_hardware.py` "
            "(CI deselects hardware tests with -m 'not hardware')",
            pytrace=False,
        )
    return value


def ping(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    """Run ``mmexec hw ping ARGS``; assert exit 0 and no error line; return stdout."""
    rc = main(["ping", *args])
    out = capsys.readouterr()
    assert rc == 0, f"mmexec hw ping {' '.join(args)}: exit {rc}: {out.err.strip()}"
    assert out.err == ""
    return out.out


def test_kobuki(capsys: pytest.CaptureFixture[str]) -> None:
    from mmexec.drivers.kobuki.device import KobukiConfig, KobukiDevice

    port = device("MMEXEC_KOBUKI_PORT", "/dev/kobuki", "Kobuki base's serial port")
    out = ping(capsys, "kobuki", "--port", port)
    assert out.startswith(f"kobuki on {port}: firmware 1.")
    dev = KobukiDevice(KobukiConfig(port=port))
    try:
        info = dev.connect()
        assert info.firmware is not None and info.firmware.major == 1
        first = dev.base_state().stamp
        deadline = time.monotonic() + 1.0  # feedback streams at 50 Hz
        while dev.base_state().stamp == first and time.monotonic() < deadline:
            time.sleep(0.02)
        assert dev.base_state().stamp > first, "no feedback frame within 1 s"
        assert dev.base_state().v == pytest.approx(0.0, abs=0.02)  # standing still
    finally:
        dev.close()


def test_dynamixel(capsys: pytest.CaptureFixture[str]) -> None:
    from mmexec.drivers.dynamixel.wx250s import WX250s, WX250sConfig

    port = device("MMEXEC_DXL_PORT", "/dev/ttyDXL", "U2D2 port of the WX250s bus")
    locobot = os.environ.get("MMEXEC_DXL_LOCOBOT", "1") == "1"  # 0 for a bare arm
    # adapter latency: 1 ms is the U2D2 with the Interbotix udev rule; raise it for an
    # adapter at the FTDI default (16) or to rehearse against `mmexec hw fake dynamixel` (20)
    latency_ms = float(os.environ.get("MMEXEC_DXL_LATENCY_MS", "1"))
    ids = "1-11" if locobot else "1-9"
    out = ping(capsys, "dynamixel", "--port", port, "--ids", ids, "--latency-ms", str(latency_ms))
    assert len(out.splitlines()) == (11 if locobot else 9) and "HARDWARE ERROR" not in out
    arm = WX250s(WX250sConfig(port=port, locobot=locobot, latency=latency_ms / 1000.0))
    try:
        arm.connect()  # torque on, goal = present position: the arm holds where it is
        state = arm.arm.state()
        for lim, q in zip(arm.arm.limits, state.positions):
            assert lim.lower - 0.05 <= q <= lim.upper + 0.05, f"{lim.name} reads {q:.3f} rad"
        assert arm.faults == {}
    finally:
        arm.close()


def test_robotiq(capsys: pytest.CaptureFixture[str]) -> None:
    port = device("MMEXEC_ROBOTIQ_PORT", "/dev/ttyUSB0", "Robotiq RS-485 adapter's port")
    out = ping(capsys, "robotiq", "--port", port)  # no --activate: the fingers stay put
    assert out.startswith(f"robotiq on {port}: ") and "fault none" in out


def test_ur(capsys: pytest.CaptureFixture[str]) -> None:
    from mmexec.drivers.ur import model as urmodel

    host = device("MMEXEC_UR_HOST", "192.168.1.10", "UR controller's IP address")
    # read-only: the ping reads state through RTDE (our codec, then ur_rtde's receive
    # interface); the control interface is not opened, since it replaces the running program
    out = ping(capsys, "ur", "--host", host).splitlines()
    assert out[0].startswith(f"ur {host}:30004: controller ")
    joints = [line for line in out if line.strip().startswith("joints [rad]:")]
    assert len(joints) == 1, out
    q = [float(x) for x in joints[0].split(":", 1)[1].split()]
    assert len(q) == 6
    for lim, qi in zip(urmodel.joint_limits("ur5e"), q):
        assert lim.lower <= qi <= lim.upper, f"{lim.name} reads {qi:.3f} rad"
