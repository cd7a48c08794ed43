"""The Modbus driver and the Gripper adapter against the pty fake."""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterator

import pytest
from robotiq_helpers import finish, wait_for

from mmexec.drivers.fakes.robotiq import FakeRobotiq
from mmexec.drivers.interfaces import CapabilityError, GoalState, GraspState
from mmexec.drivers.robotiq import codec
from mmexec.drivers.robotiq.codec import Command
from mmexec.drivers.robotiq.core import DeviceSettings, LinkState
from mmexec.drivers.robotiq.device import ModbusSettings, RobotiqModbus
from mmexec.drivers.robotiq.errors import (
    RobotiqLinkError,
    RobotiqNotReady,
    RobotiqTimeout,
)
from mmexec.drivers.robotiq.gripper import RobotiqGripper

ONE_UNIT = codec.STROKE / 255  # m per position unit


@pytest.fixture
def fake() -> Iterator[FakeRobotiq]:
    with FakeRobotiq(activation_time=0.2, time_scale=10.0) as f:
        yield f


def make(fake: FakeRobotiq, **settings: object) -> RobotiqGripper:
    dev = RobotiqModbus(ModbusSettings(fake.port, latency=0.03),
                        DeviceSettings(**settings))  # type: ignore[arg-type]
    return RobotiqGripper(dev)


@pytest.fixture
def gripper(fake: FakeRobotiq) -> Iterator[RobotiqGripper]:
    g = make(fake)
    act = g.setup()
    assert act is not None and finish(act) is GoalState.SUCCEEDED
    try:
        yield g
    finally:
        g.disconnect()


def test_activation_sequence(fake: FakeRobotiq) -> None:
    g = make(fake)
    try:
        act = g.setup()
        assert act is not None
        assert not act.done()                     # returns at once; activation takes time
        assert finish(act) is GoalState.SUCCEEDED
        assert fake.model.writes[:2] == [Command(), Command(rACT=True)]   # reset, then rACT
        status = g.device.status()
        assert status is not None and status.status_byte == 0x31
        assert act.result.grasp is GraspState.AT_POSITION
        # already activated: succeeds at once, writes nothing (a held object stays held)
        n = len(fake.model.writes)
        again = g.activate()
        assert again.state is GoalState.SUCCEEDED and len(fake.model.writes) == n
    finally:
        g.disconnect()


def test_move_before_activation_says_what_to_do(fake: FakeRobotiq) -> None:
    g = make(fake)
    try:
        assert g.setup(activate=False) is None
        with pytest.raises(RobotiqNotReady, match=r"call activate\(\) first"):
            g.move(0.04)
        act = g.activate()
        assert finish(act) is GoalState.SUCCEEDED
        fake.model.inject_fault(0x0E)
        assert wait_for(lambda: "overcurrent" in g.state().fault, 1.0)
        with pytest.raises(CapabilityError, match=r"overcurrent .*call activate\(\)"):
            g.move(0.04)
    finally:
        g.disconnect()
    with pytest.raises(RobotiqNotReady, match=r"call open\(\) first"):
        g.move(0.04)


def test_move_to_width(fake: FakeRobotiq, gripper: RobotiqGripper) -> None:
    goal = gripper.move(0.05, speed=0.15, force=100.0)
    assert finish(goal) is GoalState.SUCCEEDED
    state = goal.result
    assert state.grasp is GraspState.AT_POSITION and not state.holding
    assert state.width == pytest.approx(0.05, abs=ONE_UNIT)
    cmd = fake.model.command
    assert (cmd.rACT, cmd.rGTO, cmd.rPR, cmd.rSP) == (True, True, codec.width_to_position(0.05), 255)
    assert cmd.rFR == codec.force_to_raw(100.0)


def test_object_caught_closing_and_dropped(fake: FakeRobotiq, gripper: RobotiqGripper) -> None:
    fake.model.object_width = 0.03
    goal = gripper.close(speed=0.15, force=60.0)
    assert finish(goal) is GoalState.SUCCEEDED
    assert goal.result.grasp is GraspState.CONTACT_CLOSING and goal.result.holding
    assert goal.result.width == pytest.approx(0.03, abs=ONE_UNIT)
    assert gripper.state().grasp is GraspState.CONTACT_CLOSING
    fake.model.drop_object()
    assert wait_for(lambda: gripper.state().grasp is GraspState.DROPPED, 1.0)
    assert wait_for(lambda: gripper.state().width < 0.001, 1.0)
    assert gripper.state().grasp is GraspState.DROPPED      # sticky until the next move
    goal = gripper.open(speed=0.15)
    assert finish(goal) is GoalState.SUCCEEDED
    assert goal.result.grasp is GraspState.AT_POSITION


def test_object_caught_opening(fake: FakeRobotiq, gripper: RobotiqGripper) -> None:
    assert finish(gripper.close(speed=0.15)) is GoalState.SUCCEEDED
    fake.model.outer_object_width = 0.06
    goal = gripper.open(speed=0.15)
    assert finish(goal) is GoalState.SUCCEEDED
    assert goal.result.grasp is GraspState.CONTACT_OPENING
    assert goal.result.width == pytest.approx(0.06, abs=ONE_UNIT)


def test_regrasp_same_position_toggles_rgto(fake: FakeRobotiq, gripper: RobotiqGripper) -> None:
    fake.model.object_width = 0.03
    assert finish(gripper.close(speed=0.15)) is GoalState.SUCCEEDED
    n = len(fake.model.writes)
    goal = gripper.close(speed=0.15)
    assert finish(goal) is GoalState.SUCCEEDED and goal.result.grasp is GraspState.CONTACT_CLOSING
    toggled = fake.model.writes[n:]
    assert [c.rGTO for c in toggled] == [False, True]


def test_force_and_range_limits_enforced(fake: FakeRobotiq) -> None:
    g = make(fake, max_force=100.0)
    try:
        act = g.setup()
        assert act is not None and finish(act) is GoalState.SUCCEEDED
        assert finish(g.move(0.5, speed=3.0, force=1000.0)) is GoalState.SUCCEEDED
        cmd = fake.model.command
        assert cmd.rFR == codec.force_to_raw(100.0) and cmd.rPR == 0 and cmd.rSP == 255
        assert finish(g.device.move_raw(10, 255, 255)) is GoalState.SUCCEEDED
        assert fake.model.command.rFR == codec.force_to_raw(100.0)
        with pytest.raises(ValueError, match="finite"):
            g.move(float("nan"))
        with pytest.raises(ValueError, match="0..255"):
            g.device.move_raw(300)
    finally:
        g.disconnect()


def test_cancel_stops_the_fingers(fake: FakeRobotiq) -> None:
    with FakeRobotiq(activation_time=0.1, time_scale=1.0) as slow:
        g = make(slow)
        try:
            act = g.setup()
            assert act is not None and finish(act, 3.0) is GoalState.SUCCEEDED
            goal = g.close(speed=0.02)              # 4 s for the whole stroke
            assert wait_for(lambda: (slow.model.status().gPO or 0) > 2, 1.0)
            goal.cancel()
            assert finish(goal) is GoalState.CANCELLED
            assert not slow.model.command.rGTO
            pos = slow.model.status().gPO
            time.sleep(0.1)
            assert slow.model.status().gPO == pos and pos < 255
        finally:
            g.disconnect()


def test_close_mid_motion_stops(fake: FakeRobotiq) -> None:
    with FakeRobotiq(activation_time=0.1, time_scale=1.0) as slow:
        g = make(slow)
        act = g.setup()
        assert act is not None and finish(act, 3.0) is GoalState.SUCCEEDED
        goal = g.close(speed=0.02)
        assert wait_for(lambda: slow.model.command.rGTO, 1.0)
        g.disconnect()
        assert goal.state is GoalState.FAILED and "driver closed" in goal.reason
        assert not slow.model.command.rGTO           # motion stopped on close


@pytest.mark.parametrize("code", [0x0A, 0x0C, 0x0E])
def test_major_fault_fails_goal_until_reactivated(fake: FakeRobotiq, gripper: RobotiqGripper,
                                                  code: int) -> None:
    names = {0x0A: "under-voltage", 0x0C: "internal fault", 0x0E: "overcurrent"}
    fake.model.time_scale = 1.0
    goal = gripper.close(speed=0.02)
    assert wait_for(lambda: fake.model.status().gGTO, 1.0)
    fake.model.inject_fault(code)
    assert finish(goal) is GoalState.FAILED
    assert f"0x{code:02X} {names[code]} (major)" in goal.reason
    assert names[code] in gripper.state().fault
    with pytest.raises(RobotiqNotReady, match=r"call activate\(\)"):
        gripper.close()
    fake.model.time_scale = 10.0
    act = gripper.activate()                                  # reset + rising edge on rACT
    assert finish(act) is GoalState.SUCCEEDED and gripper.state().fault == ""
    assert finish(gripper.move(0.04, speed=0.15)) is GoalState.SUCCEEDED


def test_activation_fault(fake: FakeRobotiq) -> None:
    fake.model.activation_fault = True
    g = make(fake)
    try:
        act = g.setup()
        assert act is not None and finish(act) is GoalState.FAILED
        assert "0x0D activation fault (major)" in act.reason
        fake.model.activation_fault = False
        assert finish(g.activate()) is GoalState.SUCCEEDED
    finally:
        g.disconnect()


def test_minor_fault_recovers_without_activation(fake: FakeRobotiq,
                                                 gripper: RobotiqGripper) -> None:
    fake.model.time_scale = 1.0
    goal = gripper.close(speed=0.02)
    assert wait_for(lambda: fake.model.status().gGTO, 1.0)
    fake.model.inject_fault(0x08)
    assert finish(goal) is GoalState.FAILED and "over-temperature (minor)" in goal.reason
    with pytest.raises(RobotiqNotReady, match="let it cool below 80 C"):
        gripper.open()
    fake.model.cool(75.0)
    assert wait_for(lambda: gripper.state().fault == "", 1.0)
    fake.model.time_scale = 10.0
    assert finish(gripper.open(speed=0.15)) is GoalState.SUCCEEDED


def test_auto_release_then_reactivate(fake: FakeRobotiq, gripper: RobotiqGripper) -> None:
    assert finish(gripper.move(0.02, speed=0.15)) is GoalState.SUCCEEDED
    rel = gripper.device.auto_release()
    assert finish(rel, 2.0) is GoalState.SUCCEEDED
    assert gripper.state().width == pytest.approx(codec.STROKE)
    with pytest.raises(RobotiqNotReady, match="automatic release completed"):
        gripper.close()
    assert finish(gripper.activate()) is GoalState.SUCCEEDED
    assert finish(gripper.close(speed=0.15)) is GoalState.SUCCEEDED


def test_no_reply_is_a_named_timeout(fake: FakeRobotiq, gripper: RobotiqGripper) -> None:
    fake.model.time_scale = 1.0
    goal = gripper.close(speed=0.02)
    fake.no_reply = True
    assert finish(goal, 1.0) is GoalState.FAILED
    # bounded in what the gripper saw: 3 unanswered exchanges, each with the link's deadline
    deadline_ms = gripper.device.reply_deadline(8, 11) * 1000  # type: ignore[attr-defined]
    assert f"{fake.port}: robotiq: no answer within the deadline ({deadline_ms:.0f} ms" \
        in goal.reason
    assert "(3 tries)" in goal.reason
    assert gripper.device.link_state is LinkState.NO_ANSWER
    with pytest.raises(RobotiqNotReady, match="not answering"):
        gripper.open()
    fake.no_reply = False                                   # the link recovers by itself
    assert wait_for(lambda: gripper.device.link_state is LinkState.CONNECTED, 1.0)
    assert gripper.state().fault == ""


def test_bad_crc_reply_is_corrupt_frame(fake: FakeRobotiq, gripper: RobotiqGripper) -> None:
    fake.model.time_scale = 1.0
    goal = gripper.close(speed=0.02)
    fake.corrupt_replies = True
    assert finish(goal, 1.0) is GoalState.FAILED
    assert "robotiq: corrupt frame (bad CRC in reply" in goal.reason
    assert "corrupt frame" in gripper.state().fault


def test_unplug_mid_motion(fake: FakeRobotiq) -> None:
    f = FakeRobotiq(activation_time=0.1, time_scale=1.0).start()
    g = make(f)
    try:
        act = g.setup()
        assert act is not None and finish(act, 3.0) is GoalState.SUCCEEDED
        goal = g.close(speed=0.02)
        assert wait_for(lambda: f.model.status().gGTO, 1.0)
        f.unplug()
        assert finish(goal, 1.0) is GoalState.FAILED
        assert "link lost" in goal.reason and f.port in goal.reason
        assert g.device.link_state is LinkState.LOST
        with pytest.raises(RobotiqNotReady, match=r"reconnect\(\)"):
            g.open()
    finally:
        g.disconnect()
        f.stop()


def test_reconnect_after_power_cycle() -> None:
    f = FakeRobotiq(activation_time=0.1, time_scale=10.0).start()
    g = make(f)
    try:
        g.setup(activate=False)
        f.silent = True
        assert wait_for(lambda: g.device.link_state is LinkState.NO_ANSWER, 1.0)
        f.silent = False
        status = g.device.reconnect()
        assert status.gSTA == 0 and g.device.link_state is LinkState.CONNECTED
        assert finish(g.activate()) is GoalState.SUCCEEDED
    finally:
        g.disconnect()
        f.stop()


def test_open_errors_name_the_port(fake: FakeRobotiq) -> None:
    with pytest.raises(RobotiqLinkError, match="/dev/no-robotiq: robotiq: no such port"):
        make_port("/dev/no-robotiq").open()
    fake.silent = True
    dev = make_port(fake.port)
    deadline_ms = dev.reply_deadline(8, 11) * 1000   # one read, the link's own deadline
    with pytest.raises(RobotiqTimeout, match=rf"no answer within the deadline \({deadline_ms:.0f} ms"):
        dev.open()
    assert dev.link_state is LinkState.CLOSED


def make_port(port: str) -> RobotiqModbus:
    return RobotiqModbus(ModbusSettings(port, latency=0.03))


def test_requests_spaced_and_deadline_from_link(fake: FakeRobotiq,
                                                gripper: RobotiqGripper) -> None:
    assert finish(gripper.move(0.01, speed=0.15)) is GoalState.SUCCEEDED
    times = fake.request_times[-20:]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert min(gaps) >= 0.0045
    dev = gripper.device
    assert isinstance(dev, RobotiqModbus)
    # 8-byte request + 11-byte reply at 115200 8N1, plus the 30 ms latency
    assert dev.reply_deadline(8, 11) == pytest.approx(19 * 10 / 115200 + 0.03)


def test_state_stamps_use_injected_clock(fake: FakeRobotiq) -> None:
    from mmexec.drivers.interfaces import ManualClock

    clock = ManualClock(100.0)
    dev = RobotiqModbus(ModbusSettings(fake.port, latency=0.03), clock=clock)
    try:
        dev.open()
        assert dev.state().stamp == 100.0
        clock.advance(5.0)
        assert wait_for(lambda: dev.state().stamp == 105.0, 1.0)
    finally:
        dev.close()


def test_unexpected_io_error_fails_goals_instead_of_hanging(fake: FakeRobotiq) -> None:
    class Broken(RobotiqModbus):
        broken = False

        def _read_status(self) -> codec.Status:
            if self.broken:
                raise RuntimeError("driver bug")
            return super()._read_status()

    dev = Broken(ModbusSettings(fake.port, latency=0.03))
    g = RobotiqGripper(dev)
    try:
        act = g.setup()
        assert act is not None and finish(act) is GoalState.SUCCEEDED
        fake.model.time_scale = 1.0
        goal = g.close(speed=0.02)
        dev.broken = True
        assert finish(goal, 1.0) is GoalState.FAILED
        assert "I/O thread failed: RuntimeError: driver bug" in goal.reason
        assert dev.link_state is LinkState.LOST
    finally:
        g.disconnect()
