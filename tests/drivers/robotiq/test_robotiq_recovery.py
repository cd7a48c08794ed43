"""Issue 9: a move that failed with the link is not finished once the link answers again.

When the link recovers (by itself, or through ``reconnect()``) after a move failed because of
it, the driver's first write is a stop (rGTO = 0), so the gripper does not go on to a position
the caller has given up on. It writes nothing when the gripper reports no move in effect (a
power-cycled gripper would start an activation on rACT = 1), and nothing after a link glitch
that failed no move (a held object stays held). The checks are on what the fake gripper saw.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from robotiq_helpers import finish, wait_for

from mmexec.drivers.fakes.robotiq import FakeRobotiq, FakeURCap, GripperModel
from mmexec.drivers.interfaces import GoalState
from mmexec.drivers.robotiq.codec import Command
from mmexec.drivers.robotiq.core import DeviceSettings, LinkState
from mmexec.drivers.robotiq.device import ModbusSettings, RobotiqModbus
from mmexec.drivers.robotiq.gripper import RobotiqGripper
from mmexec.drivers.robotiq.urcap import RobotiqURCap, URCapSettings


@pytest.fixture
def fake() -> Iterator[FakeRobotiq]:
    with FakeRobotiq(activation_time=0.2, time_scale=10.0) as f:
        yield f


@pytest.fixture
def gripper(fake: FakeRobotiq) -> Iterator[RobotiqGripper]:
    g = RobotiqGripper(RobotiqModbus(ModbusSettings(fake.port, latency=0.03), DeviceSettings()))
    act = g.setup()
    assert act is not None and finish(act) is GoalState.SUCCEEDED
    fake.model.time_scale = 1.0  # a full close now takes over 4 s at the slowest speed
    try:
        yield g
    finally:
        g.disconnect()


def test_link_back_after_a_failed_move_stops_the_fingers(
    fake: FakeRobotiq, gripper: RobotiqGripper
) -> None:
    goal = gripper.close(speed=0.02)
    assert wait_for(lambda: fake.model.status().gGTO, 1.0)
    fake.no_reply = True
    assert finish(goal, 1.0) is GoalState.FAILED and "(3 tries)" in goal.reason
    n = len(fake.model.writes)
    assert fake.model.status().gGTO  # the gripper goes on with the move meanwhile
    fake.no_reply = False
    assert wait_for(lambda: gripper.device.link_state is LinkState.CONNECTED, 1.0)
    assert wait_for(lambda: len(fake.model.writes) > n, 1.0), "no stop written on recovery"
    assert fake.model.writes[n] == Command(rACT=True, rGTO=False, rPR=255, rSP=0,
                                           rFR=fake.model.writes[n - 1].rFR)
    st = fake.model.status()
    assert not st.gGTO and st.gPO < 255 and st.gOBJ == 0  # stopped short, not finished
    # the gripper is usable again at once
    assert finish(gripper.open(speed=0.15), 3.0) is GoalState.SUCCEEDED


def test_power_cycled_gripper_gets_no_stop(fake: FakeRobotiq, gripper: RobotiqGripper) -> None:
    goal = gripper.close(speed=0.02)
    assert wait_for(lambda: fake.model.status().gGTO, 1.0)
    fake.no_reply = True
    assert finish(goal, 1.0) is GoalState.FAILED
    fake.model = GripperModel()  # power-cycled meanwhile: reset, gACT = 0
    fake.no_reply = False
    assert wait_for(lambda: gripper.device.link_state is LinkState.CONNECTED, 1.0)
    reads = len(fake.request_times)
    assert wait_for(lambda: len(fake.request_times) > reads + 3, 1.0)  # a few polls later
    status = gripper.device.status()
    assert status is not None and not status.gACT
    assert fake.model.writes == [] and fake.model.status().gSTA == 0  # no activation started


def test_a_glitch_that_failed_no_move_writes_nothing(
    fake: FakeRobotiq, gripper: RobotiqGripper
) -> None:
    fake.model.object_width = 0.03
    goal = gripper.close(speed=0.15)
    assert finish(goal, 3.0) is GoalState.SUCCEEDED and goal.result.holding
    n = len(fake.model.writes)
    fake.no_reply = True
    assert wait_for(lambda: gripper.device.link_state is LinkState.NO_ANSWER, 1.0)
    fake.no_reply = False
    assert wait_for(lambda: gripper.device.link_state is LinkState.CONNECTED, 1.0)
    reads = len(fake.request_times)
    assert wait_for(lambda: len(fake.request_times) > reads + 3, 1.0)
    assert len(fake.model.writes) == n and fake.model.status().gGTO  # still squeezing


@pytest.fixture
def server() -> Iterator[FakeURCap]:
    with FakeURCap(activation_time=0.2, time_scale=10.0) as s:
        yield s


def urcap(server: FakeURCap) -> RobotiqGripper:
    g = RobotiqGripper(RobotiqURCap(URCapSettings("127.0.0.1", server.port, reply_timeout=0.1)))
    act = g.setup()
    assert act is not None and finish(act) is GoalState.SUCCEEDED
    server.model.time_scale = 1.0
    return g


def test_reconnect_after_a_failed_move_stops_the_fingers(server: FakeURCap) -> None:
    g = urcap(server)
    try:
        goal = g.close(speed=0.02)
        assert wait_for(lambda: server.model.status().gGTO, 1.0)
        server.drop_clients()  # the controller went away
        assert finish(goal, 1.0) is GoalState.FAILED and "link lost" in goal.reason
        assert g.device.link_state is LinkState.LOST and server.model.command.rGTO
        g.device.reconnect()
        assert wait_for(lambda: not server.model.command.rGTO, 1.0), "no stop after reconnect"
        st = server.model.status()
        assert not st.gGTO and st.gPO < 255
        assert server.requests[-8:].count("SET ACT 1 ATR 0 ARD 0 POS 255 SPE 0 FOR "
                                          f"{server.model.command.rFR} GTO 0") == 1
    finally:
        g.disconnect()


def test_estop_released_after_a_failed_move_stops_the_fingers(server: FakeURCap) -> None:
    g = urcap(server)
    try:
        goal = g.close(speed=0.02)
        assert wait_for(lambda: server.model.status().gGTO, 1.0)
        server.estop = True
        assert finish(goal, 1.0) is GoalState.FAILED and "emergency-stopped" in goal.reason
        server.estop = False
        assert wait_for(lambda: g.device.link_state is LinkState.CONNECTED, 1.0)
        assert wait_for(lambda: not server.model.command.rGTO, 1.0), "no stop after the e-stop"
        assert server.model.status().gPO < 255
    finally:
        g.disconnect()
