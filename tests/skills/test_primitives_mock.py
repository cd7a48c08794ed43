"""Primitive skills against the mock backend (uses the public pytest fixtures)."""

from __future__ import annotations

import math

import pytest

import mmexec.skills.primitives  # noqa: F401 - registers the primitives
from mmexec.drivers.interfaces import BaseState
from mmexec.drivers.mock import MockRobot
from mmexec.skills.base import (
    REGISTRY,
    FailureKind,
    SkillContext,
    SkillFailure,
    SkillRun,
    SkillStatus,
)
from mmexec.skills.primitives import Step, motion_loop


def test_registered_with_declared_params() -> None:
    for name in ("wait", "report", "move_arm", "open_gripper", "close_gripper", "drive_to", "stop_base"):
        assert name in REGISTRY
    assert REGISTRY.get("move_arm").needs == ("arm",)
    assert REGISTRY.get("close_gripper").output("holding") is not None
    assert REGISTRY.get("wait").param("seconds").required


def test_wait_takes_clock_time(run_mock_skill, mock_robot) -> None:
    run = run_mock_skill("wait", {"seconds": 1.0}, period=0.1)
    assert run.status is SkillStatus.SUCCESS
    assert mock_robot.clock.now() == pytest.approx(1.0)


def test_wait_rejects_negative(run_mock_skill) -> None:
    run = run_mock_skill("wait", {"seconds": -1})
    assert run.failure.kind is FailureKind.PRECONDITION


def test_report_emits_event(run_mock_skill, skill_ctx) -> None:
    run = run_mock_skill("report", {"message": "hello", "level": "warning"})
    assert run.status is SkillStatus.SUCCESS
    assert skill_ctx.events == [("report", {"message": "hello", "level": "warning", "node": ""})]


def test_move_arm_named_pose(run_mock_skill, mock_robot) -> None:
    run = run_mock_skill("move_arm", {"pose": "ready", "speed_scale": 1.0})
    assert run.status is SkillStatus.SUCCESS
    assert run.outputs["joints"] == pytest.approx([0.0, -0.5, 0.6, 0.0, 0.5, 0.0])
    # 0.6 rad at pi rad/s: about 0.19 s, so a handful of 0.05 s ticks
    assert mock_robot.clock.now() == pytest.approx(0.2, abs=0.051)


def test_move_arm_first_two_moves_fail(run_mock_skill, mock_robot) -> None:
    mock_robot.arm.fail_moves = {1, 2}
    runs = [run_mock_skill("move_arm", {"joints": [0.3, 0, 0, 0, 0, 0]}) for _ in range(3)]
    assert [r.status for r in runs] == [SkillStatus.FAILURE, SkillStatus.FAILURE, SkillStatus.SUCCESS]
    assert runs[0].failure.kind is FailureKind.EXECUTION and "scripted, move 1" in runs[0].failure.reason


@pytest.mark.parametrize(
    ("params", "needle"),
    [
        ({"pose": "nowhere"}, "no named pose 'nowhere'"),
        ({"pose": "home", "joints": [0] * 6}, "exactly one"),
        ({}, "exactly one"),
        ({"joints": [0, 0]}, "2 joint values"),
        ({"joints": [0, 3.0, 0, 0, 0, 0]}, "'shoulder'"),
        ({"pose": "home", "speed_scale": 1.5}, "speed_scale"),
    ],
)
def test_move_arm_preconditions(run_mock_skill, mock_robot, params, needle) -> None:
    run = run_mock_skill("move_arm", params)
    assert run.failure is not None and run.failure.kind is FailureKind.PRECONDITION
    assert needle in run.failure.reason
    assert mock_robot.arm.moves == 0


def test_move_arm_needs_an_arm() -> None:
    robot = MockRobot(capabilities={"base"})
    from mmexec.skills.testing import run_with_mock

    run = run_with_mock("move_arm", robot, {"pose": "home"})
    assert run.failure.kind is FailureKind.PRECONDITION and "needs a arm" in run.failure.reason


def test_move_arm_cancel_waits_for_stop(skill_ctx, mock_robot) -> None:
    mock_robot.arm.stop_time = 0.2
    run = SkillRun(REGISTRY.get("move_arm"), skill_ctx, {"joints": [1.0, 0, 0, 0, 0, 0], "speed_scale": 0.1})
    assert run.start() is SkillStatus.RUNNING
    mock_robot.spin(0.05)
    assert run.tick() is SkillStatus.RUNNING
    assert run.cancel() is SkillStatus.CANCELLING
    ticks = 0
    while run.status is SkillStatus.CANCELLING:
        mock_robot.spin(0.05)
        run.tick()
        ticks += 1
    assert run.status is SkillStatus.CANCELLED
    assert ticks == 4  # 0.2 s of stopping at 0.05 s per tick
    assert mock_robot.arm.cancels == 1 and not mock_robot.arm.busy


def test_close_gripper_holding_and_expectations(run_mock_skill, mock_robot) -> None:
    mock_robot.gripper.grasps = [True, False, False]
    assert run_mock_skill("close_gripper").outputs == {"holding": True}
    assert run_mock_skill("open_gripper").status is SkillStatus.SUCCESS
    assert run_mock_skill("close_gripper").outputs == {"holding": False}
    run_mock_skill("open_gripper")
    run = run_mock_skill("close_gripper", {"expect": "object"})
    assert run.failure.kind is FailureKind.POSTCONDITION and "closed on nothing" in run.failure.reason


def test_open_gripper_to_width(run_mock_skill, mock_robot) -> None:
    run = run_mock_skill("open_gripper", {"width": 0.04})
    assert run.status is SkillStatus.SUCCESS
    assert mock_robot.gripper.state().width == pytest.approx(0.04)


def test_drive_to_pose(run_mock_skill, mock_robot) -> None:
    run = run_mock_skill("drive_to", {"x": 1.0, "y": -0.5, "theta": math.pi / 2})
    assert run.status is SkillStatus.SUCCESS, run.failure
    x, y, th = run.outputs["pose"]
    assert math.hypot(x - 1.0, y + 0.5) < 0.1
    assert abs(th - math.pi / 2) < 0.06
    st = mock_robot.base.state()
    assert abs(st.v) < 1e-3 and abs(st.w) < 1e-3


def test_drive_to_home_place(run_mock_skill, mock_robot) -> None:
    mock_robot.profile["home"] = [0.5, 0.5, 0.0]
    run = run_mock_skill("drive_to", {"place": "home"})
    assert run.status is SkillStatus.SUCCESS
    assert math.hypot(run.outputs["pose"][0] - 0.5, run.outputs["pose"][1] - 0.5) < 0.1


def test_drive_to_unknown_place(run_mock_skill) -> None:
    run = run_mock_skill("drive_to", {"place": "kitchen"})
    assert run.failure.kind is FailureKind.PRECONDITION and "'kitchen'" in run.failure.reason


def test_drive_to_blocked_fails_with_fault(run_mock_skill, mock_robot) -> None:
    mock_robot.base.blocked = True
    run = run_mock_skill("drive_to", {"x": 1.0, "y": 0.0})
    assert run.failure.kind is FailureKind.EXECUTION and "bumper_centre" in run.failure.reason


def test_drive_to_timeout(run_mock_skill, mock_robot) -> None:
    run = run_mock_skill("drive_to", {"x": 5.0, "y": 0.0, "timeout": 1.0})
    assert run.failure.kind is FailureKind.TIMEOUT
    assert abs(mock_robot.base.state().v) < 1e-3  # braked before failing


def test_drive_to_cancel_brakes_to_rest(skill_ctx, mock_robot) -> None:
    run = SkillRun(REGISTRY.get("drive_to"), skill_ctx, {"x": 5.0, "y": 0.0})
    run.start()
    for _ in range(30):
        mock_robot.spin(0.05)
        run.tick()
    assert mock_robot.base.state().v > 0.2
    run.cancel()
    ticks = 0
    while run.status is SkillStatus.CANCELLING:
        mock_robot.spin(0.05)
        run.tick()
        ticks += 1
        assert ticks < 100
    assert run.status is SkillStatus.CANCELLED
    assert ticks > 1  # braking took several ticks
    assert abs(mock_robot.base.state().v) < 1e-3


def test_stop_base(run_mock_skill, mock_robot) -> None:
    for _ in range(10):
        mock_robot.base.set_velocity(0.5, 0.2)
        mock_robot.spin(0.05)
    run = run_mock_skill("stop_base")
    assert run.status is SkillStatus.SUCCESS
    assert abs(mock_robot.base.state().v) < 1e-3 and abs(mock_robot.base.state().w) < 1e-3


def test_skill_ctx_is_plain_context(skill_ctx) -> None:
    assert isinstance(skill_ctx, SkillContext)


def test_drive_to_fails_at_once_when_the_base_goes_blind(skill_ctx, mock_robot) -> None:
    # A base whose link is gone reports link_lost and a velocity that is no measurement
    # (here a stale 0.3 m/s): the skill commands the stop and fails in the same tick
    # instead of waiting BRAKE_LIMIT seconds for a rest it cannot observe.
    base = mock_robot.base
    run = SkillRun(REGISTRY.get("drive_to"), skill_ctx, {"x": 5.0, "y": 0.0})
    run.start()
    for _ in range(10):
        mock_robot.spin(0.05)
        run.tick()
    stale = BaseState(base.pose, 0.3, 0.0, 0.0, frozenset({"link_lost"}))
    base.state = lambda: stale  # type: ignore[method-assign]
    t0 = mock_robot.clock.now()
    run.tick()
    assert run.status is SkillStatus.FAILURE
    assert "link_lost" in run.failure.reason
    assert mock_robot.clock.now() == t0
    assert base._cmd == (0.0, 0.0)  # the stop was commanded


# --------------------------------------------------------------------------- the motion loop


def _run_loop(ctx: SkillContext, robot: MockRobot, gen, *, cancel_at: int | None = None,
              max_ticks: int = 500) -> tuple[object, int]:
    """Drive a motion-loop generator tick by tick (throwing SkillCancelled into it at tick
    ``cancel_at``); (its return value or the exception it ended with, ticks taken)."""
    from mmexec.skills.base import SkillCancelled

    for tick in range(max_ticks):
        try:
            if tick == cancel_at:
                gen.throw(SkillCancelled())
            else:
                next(gen)
        except StopIteration as stop:
            return stop.value, tick
        except (SkillFailure, SkillCancelled) as e:
            return e, tick
        robot.spin(0.05)
    raise AssertionError("motion loop still running")


def test_motion_loop_sends_commands_until_arrived_then_brakes(skill_ctx, mock_robot) -> None:
    base = mock_robot.base
    sent: list[float] = []

    def step(st: BaseState, now: float):
        sent.append(now)
        if st.pose.x >= 0.3:
            return Step.ARRIVED
        return Step.HOLD if len(sent) % 2 else (0.3, 0.0)

    rested, _ticks = _run_loop(skill_ctx, mock_robot, motion_loop(
        skill_ctx, base, step, fault="base fault", deadline=None, timeout="unused"))
    assert rested is True and base.pose.x >= 0.3 and abs(base.state().v) < 1e-3


@pytest.mark.parametrize("case", ["fault", "timeout"])
def test_motion_loop_brakes_then_fails_on_a_fault_or_timeout(skill_ctx, mock_robot, case: str) -> None:
    base = mock_robot.base
    reasons: list[str] = []
    deadline = mock_robot.clock.now() + 1.0

    def step(st: BaseState, now: float):
        if case == "fault" and st.pose.x > 0.2:
            base.blocked = True
        return 0.4, 0.0

    err, _ticks = _run_loop(skill_ctx, mock_robot, motion_loop(
        skill_ctx, base, step, fault="base fault while testing", deadline=deadline, timeout="not done in 1 s",
        timeout_kind=FailureKind.TIMEOUT, on_failure=reasons.append))
    assert isinstance(err, SkillFailure)
    if case == "fault":
        assert err.kind is FailureKind.EXECUTION and err.reason == "base fault while testing: bumper_centre"
        assert reasons == ["base fault: bumper_centre"]
    else:
        assert (err.kind, err.reason, reasons) == (FailureKind.TIMEOUT, "not done in 1 s", ["timeout"])
        assert mock_robot.clock.now() > deadline
    assert abs(base.state().v) < 1e-3  # braked before failing


def test_motion_loop_cancelled_brakes_to_rest_then_reraises(skill_ctx, mock_robot) -> None:
    from mmexec.skills.base import SkillCancelled

    base = mock_robot.base
    err, ticks = _run_loop(skill_ctx, mock_robot, motion_loop(
        skill_ctx, base, lambda st, now: (0.4, 0.0), fault="base fault", deadline=None, timeout="unused"),
        cancel_at=30)
    assert isinstance(err, SkillCancelled) and ticks > 30  # braking took ticks
    assert abs(base.state().v) < 1e-3
