"""The first gripper command after bring-up waits for activation (both links, both fakes).

Bring-up starts activation and returns at once (it takes seconds: the fingers travel
fully); a mission's first ``close_gripper`` comes right after. The move's goal waits,
nothing written, until the gripper reports gSTA = 3, then starts; it fails with one line
when the activation fails or has not finished by its deadline (the injected clock's).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest
from robotiq_helpers import finish, wait_for

from mmexec.drivers.fakes.robotiq import FakeRobotiq, FakeURCap, GripperModel
from mmexec.drivers.interfaces import Clock, GoalState, GraspState, ManualClock
from mmexec.drivers.robotiq.codec import Command
from mmexec.drivers.robotiq.core import DeviceSettings, RobotiqDevice
from mmexec.drivers.robotiq.device import ModbusSettings, RobotiqModbus
from mmexec.drivers.robotiq.gripper import RobotiqGripper
from mmexec.drivers.robotiq.urcap import RobotiqURCap, URCapSettings


@dataclass
class Link:
    """A fake gripper on one link and a way to make drivers for it."""

    model: GripperModel
    where: str                                  # the driver's device-and-port prefix
    make: Callable[[Clock | None], RobotiqDevice]
    requests: Callable[[], int]                 # requests the fake has received


@pytest.fixture(params=["rtu", "urcap"])
def link(request: pytest.FixtureRequest) -> Iterator[Link]:
    # the vendor's activation (2 s of gripper time by default), run 10x faster than real time
    model = GripperModel(time_scale=10.0)
    if request.param == "rtu":
        with FakeRobotiq(model) as fake:
            yield Link(model, f"robotiq {fake.port}",
                       lambda clock: RobotiqModbus(ModbusSettings(fake.port, latency=0.03),
                                                   clock=clock),
                       lambda: len(fake.request_times))
    else:
        with FakeURCap(model) as server:
            yield Link(model, f"robotiq urcap 127.0.0.1:{server.port}",
                       lambda clock: RobotiqURCap(URCapSettings("127.0.0.1", server.port,
                                                                reply_timeout=0.1),
                                                  clock=clock),
                       lambda: len(server.requests))


def moves(model: GripperModel) -> list[Command]:
    """Commands the gripper received that asked for motion."""
    return [c for c in model.writes if c.rGTO]


def test_first_close_right_after_bring_up_succeeds(link: Link) -> None:
    gripper = RobotiqGripper(link.make(None))
    try:
        activation = gripper.setup()            # returns at once; activation takes seconds
        goal = gripper.close(speed=0.15)        # a mission's first close_gripper
        assert finish(goal, 5.0) is GoalState.SUCCEEDED, goal.reason
        assert activation is not None and activation.state is GoalState.SUCCEEDED
        assert goal.result.grasp is GraspState.AT_POSITION
        # what the gripper saw: reset, rACT, then the move, never during activation
        assert link.model.writes[:2] == [Command(), Command(rACT=True)]
        assert [c.rPR for c in moves(link.model)] == [255]
        assert link.model.delayed_actions == 0
    finally:
        gripper.disconnect()


def test_move_is_held_until_activation_completes(link: Link) -> None:
    link.model.activation_time = math.inf      # activating until the test says otherwise
    gripper = RobotiqGripper(link.make(None))
    try:
        activation = gripper.setup()
        assert activation is not None
        goal = gripper.close(speed=0.15)
        seen = link.requests()
        assert wait_for(lambda: link.requests() >= seen + 10, 2.0)   # several polls later
        assert goal.state is GoalState.ACTIVE and not activation.done()
        assert moves(link.model) == [] and link.model.status().gSTA == 1
        link.model.activation_time = 2.0        # the activation finishes
        assert finish(goal, 5.0) is GoalState.SUCCEEDED, goal.reason
        assert activation.state is GoalState.SUCCEEDED
        assert [c.rPR for c in moves(link.model)] == [255] and link.model.delayed_actions == 0
    finally:
        gripper.disconnect()


def test_activation_that_never_completes_fails_the_move_in_one_line(link: Link) -> None:
    link.model.activation_time = math.inf
    clock = ManualClock(50.0)
    gripper = RobotiqGripper(link.make(clock))
    timeout = DeviceSettings().activation_timeout
    try:
        activation = gripper.setup()
        assert activation is not None
        goal = gripper.close(speed=0.15)
        clock.advance(timeout - 0.5)            # not yet: still waiting
        seen = link.requests()
        assert wait_for(lambda: link.requests() >= seen + 10, 2.0)
        assert goal.state is GoalState.ACTIVE
        clock.advance(1.0)                      # past the activation deadline
        assert finish(goal, 2.0) is GoalState.FAILED
        assert goal.reason == (f"{link.where}: move not started: activation failed: "
                               f"activation did not finish within {timeout:g} s (gSTA=1)")
        assert activation.state is GoalState.FAILED
        assert moves(link.model) == []          # nothing was ever asked of the fingers
    finally:
        gripper.disconnect()


def test_activation_fault_fails_the_waiting_move(link: Link) -> None:
    link.model.activation_fault = True
    gripper = RobotiqGripper(link.make(None))
    try:
        gripper.setup()
        goal = gripper.close(speed=0.15)
        assert finish(goal, 5.0) is GoalState.FAILED
        assert goal.reason.startswith(f"{link.where}: move not started: activation failed: "
                                      "gripper fault 0x0D activation fault (major)")
        assert "\n" not in goal.reason and moves(link.model) == []
    finally:
        gripper.disconnect()


def test_waiting_move_can_be_cancelled_or_stopped(link: Link) -> None:
    link.model.activation_time = math.inf
    gripper = RobotiqGripper(link.make(None))
    try:
        activation = gripper.setup()
        assert activation is not None
        first = gripper.close()
        second = gripper.open()                 # a new move supersedes the waiting one
        assert first.state is GoalState.CANCELLED
        second.cancel()                         # nothing written for it: done at once
        assert second.state is GoalState.CANCELLED
        third = gripper.close()
        gripper.stop()
        assert third.state is GoalState.CANCELLED
        link.model.activation_time = 2.0
        assert finish(activation, 5.0) is GoalState.SUCCEEDED
        assert moves(link.model) == []
    finally:
        gripper.disconnect()
