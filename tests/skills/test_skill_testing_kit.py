"""The documented testing workflow of docs/testing.md, run as written (fixtures from the
installed pytest plugin)."""

from __future__ import annotations

from mmexec.drivers.mock import MockRobot
from mmexec.skills.base import (
    REGISTRY,
    FailureKind,
    Output,
    Param,
    SkillFailure,
    SkillRun,
    SkillStatus,
    skill,
    wait_goal,
)
from mmexec.skills.testing import run_with_mock

REG = REGISTRY.copy()


@skill("present_t", params=[Param("pose", str, required=True)], outputs=[Output("holding", bool)],
       needs=("arm", "gripper"), registry=REG)
def present(ctx, pose):
    q = ctx.profile["named_poses"][pose]
    yield from wait_goal(ctx, ctx.robot.arm.move_to(q))
    if not ctx.robot.gripper.state().holding:
        raise SkillFailure(FailureKind.POSTCONDITION, "dropped the item on the way")
    return {"holding": True}


def test_present_succeeds_when_holding(run_mock_skill, mock_robot) -> None:
    run_mock_skill("close_gripper")
    run = run_mock_skill(REG.get("present_t"), {"pose": "ready"})
    assert run.status is SkillStatus.SUCCESS and run.outputs == {"holding": True}


def test_present_postcondition_when_empty(run_mock_skill, mock_robot) -> None:
    run = run_mock_skill(REG.get("present_t"), {"pose": "ready"})
    assert run.failure.kind is FailureKind.POSTCONDITION


def test_present_reports_arm_failure(run_mock_skill, mock_robot) -> None:
    mock_robot.arm.fail_moves = {1}
    run = run_mock_skill(REG.get("present_t"), {"pose": "ready"})
    assert run.failure.kind is FailureKind.EXECUTION and "scripted, move 1" in run.failure.reason


def test_present_cancels_cleanly(skill_ctx, mock_robot) -> None:
    mock_robot.arm.stop_time = 0.2
    run = SkillRun(REG.get("present_t"), skill_ctx, {"pose": "ready"})
    run.start()
    run.cancel()
    ticks = 0
    while run.status is SkillStatus.CANCELLING:
        mock_robot.spin(0.05)
        run.tick()
        ticks += 1
    assert run.status is SkillStatus.CANCELLED and mock_robot.arm.cancels == 1 and ticks == 4


def test_fixture_profile_and_fresh_robot(mock_robot, skill_ctx) -> None:
    assert set(mock_robot.profile["named_poses"]) == {"home", "ready", "sleep"}
    assert mock_robot.clock.now() == 0.0 and skill_ctx.robot is mock_robot and skill_ctx.events == []
    mock_robot.profile["named_poses"]["ready"][0] = 9.0  # must not leak into the next test


def test_fixture_profile_not_shared(mock_robot) -> None:
    assert mock_robot.profile["named_poses"]["ready"][0] == 0.0


def test_run_with_mock_without_pytest_fixtures() -> None:
    robot = MockRobot(capabilities={"base"})
    run = run_with_mock("move_arm", robot, {"pose": "home"})
    assert run.failure.kind is FailureKind.PRECONDITION
