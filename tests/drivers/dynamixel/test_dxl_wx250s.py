"""WX250s driver against the fake bus: bring-up, streaming, limits, faults, link loss, gripper."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
from dxl_helpers import until, wait

from mmexec.drivers.dynamixel.bus import (
    CorruptReply,
    DynamixelError,
    HardwareFault,
    NoReply,
    PortUnavailable,
)
from mmexec.drivers.dynamixel.codec import BROADCAST_ID, Instruction
from mmexec.drivers.dynamixel.control_table import OperatingMode, pulses_to_rad
from mmexec.drivers.dynamixel.wx250s import (
    WX250s,
    WX250sConfig,
    gripper_angle_for_width,
    gripper_width,
)
from mmexec.drivers.fakes.dynamixel import FakeDxlBus, wx250s_servos
from mmexec.drivers.interfaces import GoalState, GraspState, JointTrajectory

TEST_LATENCY = 0.05  # as in conftest.py: reply deadlines of ~100 ms on a loaded 2-core machine

NAMES = ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate")
HOME = (0.0, -0.5, 0.5, 0.0, 0.3, 0.0)


#: the Bus Watchdog for the generous TEST_LATENCY: WX250sConfig wants at least 3 cycles plus
#: 4 reply deadlines (438 ms at 50 ms latency); a loaded machine gets the same margin again
TEST_WATCHDOG_MS = 1000


def cfg(port: str, **kw: object) -> WX250sConfig:
    kw.setdefault("bus_watchdog_ms", TEST_WATCHDOG_MS)
    return WX250sConfig(port=port, latency=TEST_LATENCY, **kw)  # type: ignore[arg-type]


@pytest.fixture
def arm(fake: FakeDxlBus) -> Iterator[WX250s]:
    dev = WX250s(cfg(fake.port))
    dev.connect()
    try:
        yield dev
    finally:
        dev.close()


def move_home(dev: WX250s) -> None:
    goal = dev.arm.follow(JointTrajectory(NAMES, (0.8,), (HOME,)))
    wait(goal, 3.0)
    assert goal.state is GoalState.SUCCEEDED, goal.reason


def test_construction_does_no_io() -> None:
    dev = WX250s(WX250sConfig(port="/dev/does-not-exist"))
    assert not dev.connected
    with pytest.raises(PortUnavailable, match="/dev/does-not-exist: no such port"):
        dev.connect()
    assert dev.arm.follow(JointTrajectory(NAMES, (1.0,), (HOME,))).state is GoalState.FAILED


def test_bring_up_configures_the_bus(arm: WX250s, fake: FakeDxlBus) -> None:
    assert sorted(arm.found) == list(range(1, 10))
    for dxl_id in range(1, 10):
        s = fake.servo(dxl_id)
        assert s.torque, dxl_id
        assert s.get("return_delay_time") == 0 and s.get("velocity_limit") == 131
    assert fake.servo(3).secondary_id == 2 and fake.servo(5).secondary_id == 4
    assert fake.servo(3).get("drive_mode") == 5 and fake.servo(5).get("drive_mode") == 5
    assert fake.servo(7).get("drive_mode") == 5 and fake.servo(2).get("drive_mode") == 4
    assert fake.servo(9).get("operating_mode") == OperatingMode.PWM
    assert fake.servo(2).get("operating_mode") == OperatingMode.POSITION
    assert (
        fake.servo(2).get("min_position_limit") == 819
        and fake.servo(4).get("max_position_limit") == 3094
    )
    assert (
        fake.servo(1).get("profile_velocity") == 100
        and fake.servo(1).get("profile_acceleration") == 30
    )
    # held where it was: sleep pose, no jump at torque on
    assert arm.arm.state().positions == pytest.approx((0.0, -1.80, 1.55, 0.0, 0.8, 0.0), abs=2e-3)
    assert arm.arm.joint_names == NAMES
    assert [lim.name for lim in arm.arm.limits] == list(NAMES)
    assert arm.arm.limits[1].lower == pytest.approx(math.radians(-108), abs=1e-4)
    assert np.allclose(arm.arm.mount, np.eye(4))


def test_trajectory_streams_and_succeeds(arm: WX250s, fake: FakeDxlBus) -> None:
    q1 = (0.2, -1.2, 1.2, 0.1, 0.6, 0.1)
    writes0 = fake.goal_writes
    t0 = arm.clock.now()
    goal = arm.arm.follow(JointTrajectory(NAMES, (0.3, 0.6), (q1, HOME)))
    wait(goal, 3.0)
    assert goal.state is GoalState.SUCCEEDED, goal.reason
    # on the driver's clock: not before the last waypoint's time (success later than
    # settle_timeout after it would have been a failure)
    assert goal.result.stamp - t0 >= 0.6 - 0.005  # stamped just before the check
    assert fake.goal_writes - writes0 >= 40  # streamed every cycle at ~100 Hz, not one set-point
    assert arm.arm.state().positions == pytest.approx(HOME, abs=0.02)
    # shadows followed their masters through the Secondary ID
    assert fake.servo(3).get("goal_position") == fake.servo(2).get("goal_position")
    assert fake.servo(5).get("goal_position") == fake.servo(4).get("goal_position")
    assert goal.result.names == NAMES


@pytest.mark.parametrize(
    "point, times, what",
    [
        ((0.0, -2.5, 0.5, 0.0, 0.3, 0.0), (2.0,), "shoulder = -2.5000 rad outside its limits"),
        ((0.0, -0.5, 1.9, 0.0, 0.3, 0.0), (2.0,), "elbow = 1.9000 rad outside"),
        (
            (3.0, -0.5, 0.5, 0.0, 0.3, 0.0),
            (0.5,),
            "waist would move at 6.000 rad/s, above its limit",
        ),
    ],
)
def test_limits_rejected_before_anything_is_sent(
    arm: WX250s, fake: FakeDxlBus, point: tuple[float, ...], times: tuple[float, ...], what: str
) -> None:
    move_home(arm)
    time.sleep(0.05)
    writes0 = fake.goal_writes
    goal = arm.arm.follow(JointTrajectory(NAMES, times, (point,)))
    assert (
        goal.state is GoalState.FAILED and what in goal.reason and "nothing was sent" in goal.reason
    )
    time.sleep(0.1)
    assert fake.goal_writes == writes0
    assert arm.arm.state().positions == pytest.approx(HOME, abs=0.02)


def test_cancel_holds_position(arm: WX250s, fake: FakeDxlBus) -> None:
    goal = arm.arm.follow(JointTrajectory(NAMES, (1.5,), ((0.8, -0.5, 0.5, 0.0, 0.3, 0.0),)))
    time.sleep(0.3)
    goal.cancel()
    wait(goal, 0.5)
    assert goal.state is GoalState.CANCELLED
    # the 100 ms profile ends exactly on the held goal (same pulse; bounded wait, not a
    # fixed sleep)
    assert until(lambda: arm.arm.state().positions[0] == pytest.approx(
        pulses_to_rad(fake.servo(1).get("goal_position")), abs=5e-4))
    held = arm.arm.state().positions[0]
    time.sleep(0.2)
    assert arm.arm.state().positions[0] == pytest.approx(held, abs=1e-3)
    assert 0.05 < held < 0.7
    assert pulses_to_rad(fake.servo(1).get("goal_position")) == pytest.approx(held, abs=0.02)


@pytest.mark.parametrize(
    "fault", ["overload", "overheating", "input_voltage", "motor_encoder", "electrical_shock"]
)
def test_hardware_fault_fails_goal_with_name(arm: WX250s, fake: FakeDxlBus, fault: str) -> None:
    goal = arm.arm.follow(JointTrajectory(NAMES, (1.5,), ((0.8, -0.5, 0.5, 0.0, 0.3, 0.0),)))
    time.sleep(0.1)
    n0 = len(fake.instructions)
    fake.inject_hardware_error(4, fault)
    wait(goal, 2.0)
    assert goal.state is GoalState.FAILED
    assert f"servo id 4 (elbow): {fault}" in goal.reason and "reboot" in goal.reason
    # detected in the cycle that first saw the alert bit, in what the bus saw: the driver
    # read Hardware Error Status of id 4 after at most two Sync Reads (one may have been
    # under way when the fault struck)
    after = fake.instructions[n0:]
    first_read = after.index((4, Instruction.READ))
    assert after[:first_read].count((BROADCAST_ID, Instruction.SYNC_READ)) <= 2
    assert arm.faults == {"elbow": (fault,)}
    refused = arm.arm.follow(JointTrajectory(NAMES, (1.0,), (HOME,)))
    assert refused.state is GoalState.FAILED and fault in refused.reason


def test_reboot_clears_fault_and_motion_resumes(arm: WX250s, fake: FakeDxlBus) -> None:
    fake.inject_hardware_error(2, "overload")
    assert until(lambda: arm.faults == {"shoulder": ("overload",)}), arm.faults
    assert not fake.servo(2).torque
    r = arm.reboot("shoulder")
    wait(r, 1.0)
    assert r.state is GoalState.SUCCEEDED and r.result == ("shoulder",)
    assert arm.faults == {} and fake.servo(2).torque and fake.servo(3).hardware_error == 0
    move_home(arm)


def test_smart_reboot_only_faulted_servos(arm: WX250s, fake: FakeDxlBus) -> None:
    fake.inject_hardware_error(7, "overheating")
    assert until(lambda: arm.faults == {"wrist_angle": ("overheating",)}), arm.faults
    r = arm.smart_reboot()
    wait(r, 1.0)
    assert r.state is GoalState.SUCCEEDED and r.result == ("wrist_angle",)
    assert arm.faults == {}
    assert arm.reboot("nose").state is GoalState.FAILED


def test_missing_servo_at_connect_names_id_and_port(fake: FakeDxlBus) -> None:
    fake.servo(5).present = False
    dev = WX250s(cfg(fake.port))
    with pytest.raises(
        NoReply, match=rf"{fake.port}: servo id 5 \(elbow_shadow\) did not answer ping \(3 attempts"
    ):
        dev.connect()
    assert not dev.bus.is_open


def test_faulted_servo_at_connect_is_reported(fake: FakeDxlBus) -> None:
    fake.inject_hardware_error(6, "motor_encoder")
    with pytest.raises(HardwareFault, match=r"servo id 6 \(forearm_roll\) .*motor_encoder"):
        WX250s(cfg(fake.port)).connect()


def test_missing_servo_mid_motion_fails_goal(arm: WX250s, fake: FakeDxlBus) -> None:
    goal = arm.arm.follow(JointTrajectory(NAMES, (1.5,), ((0.8, -0.5, 0.5, 0.0, 0.3, 0.0),)))
    time.sleep(0.1)
    fake.servo(6).present = False
    wait(goal, 1.0)
    assert goal.state is GoalState.FAILED
    assert (
        "no reply from servo id 6" in goal.reason and "(forearm_roll) for 3 cycles" in goal.reason
    )
    assert fake.port in goal.reason


def test_unplug_mid_motion(fake: FakeDxlBus) -> None:
    dev = WX250s(cfg(fake.port))
    dev.connect()
    thread = dev._thread
    goal = dev.arm.follow(JointTrajectory(NAMES, (1.5,), ((0.8, -0.5, 0.5, 0.0, 0.3, 0.0),)))
    time.sleep(0.1)
    fake.unplug()
    wait(goal, 1.0)
    assert goal.state is GoalState.FAILED and goal.reason.startswith("link lost")
    assert thread is not None
    thread.join(1.0)
    assert not thread.is_alive() and not dev.connected
    dev.close()
    assert dev.arm.follow(JointTrajectory(NAMES, (1.0,), (HOME,))).state is GoalState.FAILED


@pytest.mark.parametrize("answers", [True, False])
def test_corrupted_instruction_mid_motion_is_tolerated(
    arm: WX250s, fake: FakeDxlBus, answers: bool
) -> None:
    fake.crc_error_reply = answers
    goal = arm.arm.follow(JointTrajectory(NAMES, (0.5,), (HOME,)))
    time.sleep(0.1)
    fake.corrupt_instructions = 2  # one cycle's Sync Write and Sync Read arrive garbled
    wait(goal, 3.0)
    assert goal.state is GoalState.SUCCEEDED, goal.reason


@pytest.mark.parametrize("answers", [True, False])
def test_corrupted_ping_at_bring_up_is_retried(fake: FakeDxlBus, answers: bool) -> None:
    fake.crc_error_reply = answers
    fake.corrupt_instructions = 2
    dev = WX250s(cfg(fake.port))
    dev.connect()
    try:
        assert sorted(dev.found) == list(range(1, 10))
    finally:
        dev.close()


def test_gripper_width_geometry() -> None:
    assert gripper_width(math.pi / 2) == pytest.approx(2 * (0.014 + 0.024))
    assert gripper_width(0.0) == pytest.approx(2 * math.sqrt(0.024**2 - 0.014**2))
    for w in (0.030, 0.05, 0.074):
        assert gripper_width(gripper_angle_for_width(w)) == pytest.approx(w, abs=1e-9)


def test_gripper_close_open_and_object(arm: WX250s, fake: FakeDxlBus) -> None:
    g = arm.gripper.close()
    wait(g, 2.0)
    assert g.state is GoalState.SUCCEEDED
    assert g.result.grasp is GraspState.AT_POSITION and g.result.width == pytest.approx(
        0.030, abs=0.002
    )
    # free fingers: not pushing. The driver wrote PWM 0 before finishing the goal, but the
    # fake handles the packet on its own thread: wait for it (bounded) rather than racing it.
    assert until(lambda: fake.servo(9).get("goal_pwm") == 0), "gripper PWM not released"
    g = arm.gripper.move(0.06)
    wait(g, 2.0)
    # Opening stops at the first reading past the target, so the reported width is at
    # least the target; the overshoot is the finger travel between two readings (0.4 mm
    # at 100 Hz and 0.038 m/s), larger when a loaded machine delays a cycle: bounded at
    # 0.25 s of travel here, not at one nominal cycle.
    assert g.result.grasp is GraspState.AT_POSITION
    assert 0.06 - 0.002 <= g.result.width <= 0.06 + 0.010
    assert until(lambda: fake.servo(9).get("goal_pwm") == 0), "gripper PWM not released"
    # an object 45 mm wide between the fingers
    from mmexec.drivers.dynamixel.control_table import rad_to_pulses

    fake.set_obstacle(9, rad_to_pulses(gripper_angle_for_width(0.045)))
    g = arm.gripper.close(force=5.0)
    wait(g, 2.0)
    assert g.result.grasp is GraspState.CONTACT_CLOSING and g.result.holding
    assert g.result.width == pytest.approx(0.045, abs=0.002)
    assert fake.servo(9).get("goal_pwm") == -350  # keeps squeezing at the commanded force
    assert arm.gripper.move(0.2).state is GoalState.FAILED


def test_gripper_cancel_stops_pwm(arm: WX250s, fake: FakeDxlBus) -> None:
    g = arm.gripper.open()
    assert until(lambda: fake.servo(9).get("goal_pwm") > 0), "opening PWM never reached the servo"
    g.cancel()
    wait(g, 0.5)
    assert g.state is GoalState.CANCELLED
    assert until(lambda: fake.servo(9).get("goal_pwm") == 0), "gripper PWM not released"


def test_locobot_variant(no_leaks: None) -> None:
    # the fake is a real LoCoBot: pan/tilt is one 2XL430-W250, model 1090 on ids 10 and 11
    # (a driver expecting the XL430-W250's 1060 there refuses to bring the arm up)
    with FakeDxlBus(wx250s_servos(locobot=True)) as fake:
        dev = WX250s(cfg(fake.port, locobot=True))
        dev.connect()
        try:
            assert sorted(dev.found) == list(range(1, 12))
            assert dev.found[10].model == dev.found[11].model == 1090
            assert np.allclose(dev.arm.mount[:3, 3], (0.097277, 0.0, 0.10795))
            assert (
                fake.servo(11).get("drive_mode") == 1
                and fake.servo(10).get("profile_velocity") == 131
            )
            assert fake.servo(10).torque
        finally:
            dev.close()


def test_locobot_with_a_wrong_head_servo_is_refused(no_leaks: None) -> None:
    # an XL430-W250 (1060) where the 2XL430-W250 belongs: named, and nothing is configured
    with FakeDxlBus(wx250s_servos(locobot=True, head="XL430-W250")) as fake:
        dev = WX250s(cfg(fake.port, locobot=True))
        with pytest.raises(DynamixelError) as e:
            dev.connect()
        assert str(e.value) == (
            f"{fake.port}: servo id 10 (pan) is XL430-W250 (1060), expected 2XL430-W250 (1090)"
        )
        assert not dev.connected and fake.goal_writes == 0


def test_close_holds_and_leaves_no_threads(fake: FakeDxlBus) -> None:
    before = threading.active_count()
    dev = WX250s(cfg(fake.port))
    dev.connect()
    assert threading.active_count() == before + 1
    goal = dev.arm.follow(JointTrajectory(NAMES, (1.5,), ((0.8, -0.5, 0.5, 0.0, 0.3, 0.0),)))
    time.sleep(0.2)
    dev.close()
    assert goal.state is GoalState.CANCELLED
    assert threading.active_count() == before
    assert fake.servo(1).torque  # holding, torque on
    dev.close()  # idempotent


def test_stop_without_goal_holds(arm: WX250s, fake: FakeDxlBus) -> None:
    arm.arm.stop()
    time.sleep(0.05)
    assert arm.arm.state().positions == pytest.approx((0.0, -1.80, 1.55, 0.0, 0.8, 0.0), abs=2e-3)


@pytest.mark.parametrize("boot_s, ok", [(0.15, True), (5.0, False)])
def test_reboot_waits_for_the_servo_to_restart(fake: FakeDxlBus, boot_s: float, ok: bool) -> None:
    dev = WX250s(cfg(fake.port, reboot_timeout=0.4))
    dev.connect()
    try:
        fake.inject_hardware_error(8, "overload")
        time.sleep(0.05)
        fake.reboot_time = boot_s
        r = dev.reboot("wrist_rotate")
        wait(r, 2.0)
        if ok:
            assert r.state is GoalState.SUCCEEDED and dev.faults == {}
            assert fake.servo(8).torque
        else:
            assert r.state is GoalState.FAILED
            assert (
                "servo id 8 (wrist_rotate) did not come back within 0.4 s after reboot" in r.reason
            )
    finally:
        dev.close()


def _lose_write_statuses(monkeypatch: pytest.MonkeyPatch, address: int, count: int) -> list[int]:
    """Make the fake corrupt the status of the next ``count`` writes to ``address``."""
    from mmexec.drivers.dynamixel.codec import Instruction
    from mmexec.drivers.fakes import dynamixel as fake_module

    write = fake_module._HANDLERS[Instruction.WRITE]
    lost: list[int] = []

    def losing(bus: FakeDxlBus, packet: object, now: float) -> None:
        if len(lost) < count and int.from_bytes(packet.params[:2], "little") == address:  # type: ignore[attr-defined]
            lost.append(packet.id)  # type: ignore[attr-defined]
            bus.corrupt_replies = 1
        write(bus, packet, now)

    monkeypatch.setitem(fake_module._HANDLERS, Instruction.WRITE, losing)
    return lost


def test_bring_up_retries_a_lost_configuration_status(
    fake: FakeDxlBus, monkeypatch: pytest.MonkeyPatch
) -> None:
    lost = _lose_write_statuses(monkeypatch, 64, 2)  # servo 1: two attempts lost, third ok
    dev = WX250s(cfg(fake.port))
    dev.connect()
    try:
        assert lost == [1, 1] and dev.connected
        assert all(fake.servo(i).torque for i in range(1, 10))
    finally:
        dev.close()


def test_bring_up_gives_up_after_ping_attempts(fake: FakeDxlBus, monkeypatch: pytest.MonkeyPatch) -> None:
    lost = _lose_write_statuses(monkeypatch, 64, 3)  # every attempt on servo 1
    dev = WX250s(cfg(fake.port))
    with pytest.raises(CorruptReply, match=rf"{fake.port}: corrupt reply \(CRC mismatch\) from servo id 1"):
        dev.connect()
    assert lost == [1, 1, 1] and not dev.bus.is_open
