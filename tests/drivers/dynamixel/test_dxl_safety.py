"""Issue 9 safety gaps of the DYNAMIXEL driver: the Bus Watchdog (fake semantics from the
ROBOTIS e-Manual, armed on the gripper, tripped by a silent host, cleared on reconnect and on
close), baud rates outside the DYNAMIXEL table, and the reboot deadline on the injected clock.

Nothing here asserts how long anything took: the waits are bounded polls, and the checks are
on what the fake servos saw (registers, positions, the instructions received)."""

from __future__ import annotations

import argparse
import re
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from dxl_helpers import until, wait

from mmexec.drivers.dynamixel import bringup
from mmexec.drivers.dynamixel.bus import BusConfig, DxlBus, DynamixelError, ServoError
from mmexec.drivers.dynamixel.codec import Instruction, StatusResult, int_to_le
from mmexec.drivers.dynamixel.control_table import rad_to_pulses
from mmexec.drivers.dynamixel.wx250s import (
    WX250s,
    WX250sConfig,
    gripper_angle_for_width,
)
from mmexec.drivers.fakes.dynamixel import FakeDxlBus, wx250s_servos
from mmexec.drivers.interfaces import GoalState, GraspState, ManualClock
from mmexec.executive import cli

REPO = Path(__file__).resolve().parents[3]
GRIPPER = 9
#: pulses per second per velocity unit (0.229 rev/min), as the vendor's unit defines it
PULSES_S_PER_UNIT = 0.229 * 4096.0 / 60.0
#: watchdog tests: a 30 ms adapter latency (62 ms reply deadlines; the driver wants at least
#: 3 cycles + 4 deadlines = 278 ms), and a 600 ms watchdog, twice that, so that a test process
#: starved of CPU on a loaded machine does not trip it by accident; the slowest finger travel
#: (PWM 150, about 350 pulses/s) in 600 ms still stops far from the end stops
LATENCY = 0.03
WATCHDOG_MS = 600
RATES = "one of 9600, 57600, 115200, 1000000, 2000000, 3000000, 4000000, 4500000"


def config(port: str, **kw: object) -> WX250sConfig:
    kw.setdefault("latency", LATENCY)
    kw.setdefault("bus_watchdog_ms", WATCHDOG_MS)
    return WX250sConfig(port=port, **kw)  # type: ignore[arg-type]


@pytest.fixture
def arm(fake: FakeDxlBus) -> Iterator[WX250s]:
    dev = WX250s(config(fake.port))
    dev.connect()
    try:
        yield dev
    finally:
        dev.close()


def open_stop() -> int:
    """The fake gripper's end stop when opening [pulses] (74 mm between the pads)."""
    return rad_to_pulses(gripper_angle_for_width(0.074))


# --------------------------------------------------------------------------- the fake


def _drive_pwm(bus: DxlBus, pwm: int, units: int) -> None:
    bus.write(GRIPPER, 11, bytes((16,)))  # PWM mode (EEPROM: torque is still off)
    bus.write(GRIPPER, 64, b"\x01")
    bus.write(GRIPPER, 98, bytes((units,)))
    bus.write(GRIPPER, 100, int_to_le(pwm, 2))


def test_fake_watchdog_stops_a_pwm_servo_when_nothing_arrives(bus: DxlBus, fake: FakeDxlBus) -> None:
    _drive_pwm(bus, 200, 5)  # 100 ms
    # the host sends nothing more: the fake's own tick runs the servo
    assert until(lambda: fake.register(GRIPPER, "bus_watchdog") == -1), "watchdog never fired"
    servo = fake.servo(GRIPPER)
    assert fake.register(GRIPPER, "goal_pwm") == 0 and servo.torque  # stopped, torque kept
    assert fake.register(GRIPPER, "present_velocity") == 0
    [(_when, fired_at)] = servo.watchdog_fires
    # it moved for at most the watchdog period after the last instruction, then stopped
    speed = 200 / servo.get("pwm_limit") * servo.get("velocity_limit") * PULSES_S_PER_UNIT
    assert 0 < fired_at - servo.position_at_last_instruction <= speed * 0.100 + 1e-6
    assert fake.register(GRIPPER, "present_position") == round(fired_at) < open_stop()
    # goal writes are refused until 0 is written to the watchdog
    with pytest.raises(ServoError) as ei:
        bus.write(GRIPPER, 100, int_to_le(200, 2))
    assert ei.value.result is StatusResult.DATA_RANGE_ERROR
    bus.write(GRIPPER, 98, b"\x00")
    bus.write(GRIPPER, 100, int_to_le(200, 2))
    assert fake.register(GRIPPER, "goal_pwm") == 200


def test_fake_watchdog_refreshed_only_by_packets_for_the_servo(
    bus: DxlBus, fake: FakeDxlBus
) -> None:
    _drive_pwm(bus, 100, 25)  # 500 ms
    # traffic for the servo (a Sync Read listing it) keeps it armed ...
    for _ in range(40):
        bus.sync_read(126, 12, [1, GRIPPER])
        time.sleep(0.02)
    assert fake.register(GRIPPER, "bus_watchdog") == 25 and not fake.servo(GRIPPER).watchdog_fires
    # ... traffic for other ids does not (the stricter reading of the e-Manual)

    def ping_another_servo() -> bool:
        bus.ping(1)
        return fake.register(GRIPPER, "bus_watchdog") == -1

    assert until(ping_another_servo), "traffic for id 1 kept the gripper's watchdog armed"
    assert fake.register(GRIPPER, "goal_pwm") == 0


# --------------------------------------------------------------------------- the driver


def test_bring_up_arms_the_watchdog_on_the_gripper_only(arm: WX250s, fake: FakeDxlBus) -> None:
    assert arm.watchdog_ids == (GRIPPER,)
    assert fake.register(GRIPPER, "bus_watchdog") == WATCHDOG_MS // 20
    assert all(fake.register(i, "bus_watchdog") == 0 for i in range(1, 9))
    arm.close()
    assert fake.register(GRIPPER, "bus_watchdog") == 0  # cleared on close


def test_silent_host_stops_the_gripper_and_the_move_fails(arm: WX250s, fake: FakeDxlBus) -> None:
    goal = arm.gripper.move(0.074, force=0.0)  # opening at the lowest PWM
    assert until(lambda: fake.register(GRIPPER, "goal_pwm") == 150), "PWM never reached the servo"
    # the host stalls: its I/O thread blocks on the bus, nothing is sent
    with arm.bus._lock:
        assert until(lambda: fake.register(GRIPPER, "bus_watchdog") == -1), "watchdog never fired"
        assert fake.register(GRIPPER, "goal_pwm") == 0
        stopped = fake.register(GRIPPER, "present_position")
        assert not goal.done()
    assert stopped < open_stop()  # stopped on the way, not run into the end stop
    wait(goal, 3.0)
    assert goal.state is GoalState.FAILED
    assert goal.reason == (
        f"{fake.port}: servo id 9 (gripper): Bus Watchdog fired (no instruction for more than "
        f"{WATCHDOG_MS} ms): the gripper stopped; the move was abandoned"
    )
    # not resumed behind the caller's back, and armed again
    assert until(lambda: fake.register(GRIPPER, "bus_watchdog") == WATCHDOG_MS // 20)
    assert fake.register(GRIPPER, "goal_pwm") == 0 and arm.watchdog_trips == 1
    retry = arm.gripper.move(0.06)
    wait(retry, 3.0)
    assert retry.state is GoalState.SUCCEEDED, retry.reason


def test_squeeze_on_a_grasped_object_is_restored_after_a_trip(
    arm: WX250s, fake: FakeDxlBus
) -> None:
    fake.set_obstacle(GRIPPER, rad_to_pulses(gripper_angle_for_width(0.034)))
    goal = arm.gripper.close(force=5.0)
    wait(goal, 3.0)
    assert goal.state is GoalState.SUCCEEDED and goal.result.grasp is GraspState.CONTACT_CLOSING
    assert fake.register(GRIPPER, "goal_pwm") == -350
    with arm.bus._lock:
        assert until(lambda: fake.register(GRIPPER, "bus_watchdog") == -1), "watchdog never fired"
        assert fake.register(GRIPPER, "goal_pwm") == 0
    assert until(lambda: fake.register(GRIPPER, "goal_pwm") == -350), "squeeze not restored"
    assert fake.register(GRIPPER, "bus_watchdog") == WATCHDOG_MS // 20 and arm.watchdog_trips == 1


def test_trip_while_idle_is_cleared_before_the_next_move(arm: WX250s, fake: FakeDxlBus) -> None:
    fake.expire_watchdog(GRIPPER)  # fired with the gripper at rest (Goal PWM 0)
    goal = arm.gripper.move(0.06)
    wait(goal, 3.0)
    assert goal.state is GoalState.SUCCEEDED, goal.reason
    assert goal.result.width >= 0.06 - 0.002  # the fingers did move (the write was accepted)
    assert fake.register(GRIPPER, "bus_watchdog") == WATCHDOG_MS // 20 and arm.watchdog_trips == 1


def test_unplugged_gripper_stops_and_reconnect_clears_the_watchdog(no_leaks: None) -> None:
    fake = FakeDxlBus(wx250s_servos()).start()
    dev = WX250s(config(fake.port))
    dev.connect()
    try:
        goal = dev.gripper.move(0.074, force=0.0)
        assert until(lambda: fake.register(GRIPPER, "goal_pwm") == 150)
        fake.unplug()
        wait(goal, 3.0)
        assert goal.state is GoalState.FAILED and goal.reason.startswith("link lost")
        # nothing reaches the servos any more: the gripper stops by itself, within the
        # watchdog period of the last packet it got (at most that long of travel at PWM 150)
        assert until(lambda: fake.register(GRIPPER, "bus_watchdog") == -1), "watchdog never fired"
        assert fake.register(GRIPPER, "goal_pwm") == 0
        servo = fake.servo(GRIPPER)
        [(_when, fired_at)] = servo.watchdog_fires
        speed = 150 / servo.get("pwm_limit") * servo.get("velocity_limit") * PULSES_S_PER_UNIT
        travel = fired_at - servo.position_at_last_instruction
        assert 0 < travel <= speed * WATCHDOG_MS / 1000 + 1e-6
        assert fake.register(GRIPPER, "present_position") == round(fired_at) < open_stop()
    finally:
        dev.close()
        fake.stop()
    # plugged in again (the same servos, still in watchdog error): a new bring-up clears it
    # before writing any goal, which the servo would refuse with a data range error
    again = FakeDxlBus(fake.servos).start()
    dev = WX250s(config(again.port))
    try:
        dev.connect()
        assert again.register(GRIPPER, "bus_watchdog") == WATCHDOG_MS // 20
        goal = dev.gripper.move(0.06)
        wait(goal, 3.0)
        assert goal.state is GoalState.SUCCEEDED, goal.reason
    finally:
        dev.close()
        again.stop()


def test_watchdog_off_when_configured_zero(fake: FakeDxlBus) -> None:
    dev = WX250s(config(fake.port, bus_watchdog_ms=0))
    dev.connect()
    try:
        assert dev.watchdog_ids == () and fake.register(GRIPPER, "bus_watchdog") == 0
    finally:
        dev.close()


def test_old_firmware_without_a_watchdog_is_refused(no_leaks: None) -> None:
    servos = wx250s_servos()
    servos[GRIPPER - 1]._set("firmware_version", 37)
    with FakeDxlBus(servos) as fake:
        dev = WX250s(config(fake.port))
        with pytest.raises(DynamixelError, match=r"servo id 9 \(gripper\) has firmware 37, which has no "
                           r"Bus Watchdog \(firmware 38 or later\)"):
            dev.connect()
        assert not dev.connected and fake.goal_writes == 0


def test_reboot_deadline_runs_on_the_injected_clock(fake: FakeDxlBus) -> None:
    clock = ManualClock(100.0)
    dev = WX250s(config(fake.port, reboot_timeout=60.0), clock=clock)
    dev.connect()
    try:
        fake.reboot_time = 600.0  # the servo stays silent after the reboot
        n0 = len(fake.instructions)
        goal = dev.reboot("wrist_rotate")

        def pinging_after_reboot() -> bool:
            seen = fake.instructions[n0:]
            return (8, Instruction.REBOOT) in seen and (8, Instruction.PING) in seen[
                seen.index((8, Instruction.REBOOT)) :
            ]

        assert until(pinging_after_reboot)
        assert not goal.done()  # waiting on the clock, which has not moved
        clock.advance(61.0)
        wait(goal, 3.0)
        assert goal.state is GoalState.FAILED
        assert "servo id 8 (wrist_rotate) did not come back within 60.0 s" in goal.reason
    finally:
        fake.reboot_time = 0.0
        dev.close()


# --------------------------------------------------------------------------- baud rates


@pytest.mark.parametrize("baud", [-5, 0, 123, 10**12])
def test_baud_outside_the_dynamixel_table_is_refused(baud: int) -> None:
    with pytest.raises(ValueError) as ei:
        WX250sConfig(baudrate=baud)
    assert str(ei.value) == f"baudrate: {baud} bit/s is not a DYNAMIXEL baud rate ({RATES})"
    with pytest.raises(ValueError) as ei:
        BusConfig("/dev/ttyDXL", baud)
    assert str(ei.value) == f"baudrate: {baud} bit/s is not a DYNAMIXEL baud rate ({RATES})"
    assert WX250sConfig(baudrate=57600).problems() == []


@pytest.mark.parametrize("baud", ["-5", "123"])
def test_hw_ping_refuses_a_bad_baud(baud: str, capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser()
    bringup.add_ping_arguments(parser)
    assert bringup.ping(parser.parse_args(["--port", "/dev/ttyDXL", "--baud", baud])) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [
        f"dynamixel /dev/ttyDXL: --baud: {baud} bit/s is not a DYNAMIXEL baud rate ({RATES})"
    ]


def validate_locobot_with(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], key: str, value: str
) -> tuple[int, list[str], int]:
    """``mmexec validate`` of the fetch mission with config/locobot.yaml's arm ``key`` set to
    ``value``: (exit status, stderr lines, line of the arm section's ``kind``)."""
    text = (REPO / "config" / "locobot.yaml").read_text()
    cfg = tmp_path / "locobot.yaml"
    old = re.search(rf"(?m)^    {key}: \S+", text[text.index("\n  arm:") :])
    assert old is not None
    cfg.write_text(text.replace(old.group(0), f"    {key}: {value}", 1))
    (tmp_path / "maps").symlink_to(REPO / "config" / "maps")
    kind_line = 1 + text[: text.index("    kind: wx250s ")].count("\n")
    code = cli.main(["validate", str(REPO / "trees" / "fetch_item.yaml"), "--config", str(cfg)])
    return code, capsys.readouterr().err.splitlines(), kind_line


@pytest.mark.parametrize("baud", ["-5", "123456789"])
def test_validate_locates_a_bad_arm_baud(
    baud: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, lines, kind_line = validate_locobot_with(tmp_path, capsys, "baudrate", baud)
    assert code == 2  # an input error, not "internal error" (exit 1)
    cfg = tmp_path / "locobot.yaml"
    assert lines[0] == (
        f"{cfg}:{kind_line}:5: robot.arm: baudrate: {baud} bit/s is not a DYNAMIXEL baud rate "
        f"({RATES})"
    )


def test_watchdog_setting_is_checked_against_the_link() -> None:
    assert WX250sConfig().watchdog_ms == 100  # default on the U2D2 (1 ms latency)
    assert WX250sConfig(latency=0.016).watchdog_ms == 180  # FTDI factory timer: derived
    with pytest.raises(ValueError) as ei:
        WX250sConfig(bus_watchdog_ms=30)
    assert str(ei.value) == "bus_watchdog_ms: must be 0 (off) or 20..2540 ms in steps of 20 ms, got 30"
    with pytest.raises(ValueError) as ei:
        WX250sConfig(latency=0.05, bus_watchdog_ms=100)
    assert str(ei.value) == (
        "bus_watchdog_ms: 100 ms would fire during normal traffic at rate_hz 100 and latency "
        "0.05 s: use at least 438 ms (3 control cycles plus 4 reply deadlines)"
    )
    assert WX250sConfig(bus_watchdog_ms=0).problems() == []

