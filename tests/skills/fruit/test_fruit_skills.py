"""The fruit mission's skills on the mock backend (no physics): detection and the
priority choice on rendered spheres, the pick's motions (Algorithm 1.1's candidates,
planned for real against the UR5e planning model), the drop, the give-up bookkeeping
and the summary's verdicts."""

from __future__ import annotations

import numpy as np
import pytest
from fruitkit import events_of, fruit_at, run_skill, ur5e_robot

from mmexec.drivers.interfaces import GraspState
from mmexec.skills.base import FailureKind, SkillStatus
from mmexec.skills.fruit.pick import WORLD_TARGET


def test_detect_chooses_the_highest_priority_fruit_and_logs_every_detection(make_ctx):
    spheres = [("apple", fruit_at(1.15, 0.15, 0.8), 0.035), ("yellow_ball", fruit_at(0.85, -0.1, 0.75), 0.035)]
    ctx = make_ctx(ur5e_robot(spheres))
    run_skill(ctx, "fruit_setup")
    run = run_skill(ctx, "detect_fruit")
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert run.outputs["count"] == 2 and run.outputs["label"] == "yellow_ball"  # nearer: higher score
    ev = events_of(ctx, "fruit_detections")[-1]
    scores = [d["score"] for d in ev["detections"]]
    assert ev["chosen"] == int(np.argmax(scores))
    assert np.linalg.norm(ctx.world[WORLD_TARGET].centre - spheres[1][1]) < 0.003


def test_detect_with_nothing_in_view_reports_zero(make_ctx):
    ctx = make_ctx(ur5e_robot([]))
    run_skill(ctx, "fruit_setup")
    run = run_skill(ctx, "detect_fruit")
    assert run.status is SkillStatus.SUCCESS and run.outputs["count"] == 0
    assert WORLD_TARGET not in ctx.world


def test_pick_and_drop_run_the_thesis_motions(make_ctx):
    c = fruit_at(0.72, 0.05, 0.80)
    robot = ur5e_robot([("apple", c, 0.035), ("blue_ball", fruit_at(0.74, -0.12, 0.62), 0.03)])
    ctx = make_ctx(robot)
    run_skill(ctx, "fruit_setup")
    assert run_skill(ctx, "detect_fruit").status is SkillStatus.SUCCESS
    run = run_skill(ctx, "pick_fruit")
    assert run.status is SkillStatus.SUCCESS, run.failure
    g = events_of(ctx, "fruit_grasp")[-1]
    # the thesis's choice: a quarter of the way down the list of reachable candidates
    assert g["used"] == g["thesis_choice"] and 0 < g["feasible"] <= g["candidates"] == 50
    planned = [e["what"] for e in events_of(ctx, "arm_plan")]
    assert planned[-4:] == ["fruit pre-grasp", "fruit approach", "fruit pull", "fruit lift"]
    assert robot.gripper.state().grasp is GraspState.CONTACT_CLOSING
    run = run_skill(ctx, "drop_fruit", {"basket": "robot"})
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert list(robot.arm.state().positions) == pytest.approx(robot.profile["named_poses"]["drop"], abs=0.02)
    assert robot.gripper.state().grasp is not GraspState.CONTACT_CLOSING  # opened: the fruit fell
    assert events_of(ctx, "fruit_dropped")[-1]["picked"] == 1


def test_an_empty_grasp_fails_the_pick_and_give_up_skips_the_fruit_after_its_attempts(make_ctx):
    robot = ur5e_robot([("apple", fruit_at(0.72, 0.0, 0.80), 0.035)], grasps=[False, False])
    ctx = make_ctx(robot)
    run_skill(ctx, "fruit_setup")
    for attempt in (1, 2):
        assert run_skill(ctx, "detect_fruit").outputs["count"] == 1
        run = run_skill(ctx, "pick_fruit")
        assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.POSTCONDITION
        assert "nothing held" in run.failure.reason
        out = run_skill(ctx, "fruit_give_up", {"reason": run.failure.reason}).outputs
        assert out["skipped"] is (attempt == 2)
    # skipped now: the next look chooses nothing, and the summary names it
    run = run_skill(ctx, "detect_fruit")
    assert run.outputs["count"] == 0 or run.outputs["label"] == ""
    assert events_of(ctx, "fruit_detections")[-1]["skipped"] == 1
    run = run_skill(ctx, "fruit_summary")
    assert run.status is SkillStatus.FAILURE
    assert "1 fruit not picked after 2 attempts" in run.failure.reason and "nothing held" in run.failure.reason


def test_summary_succeeds_only_when_the_last_look_found_nothing(make_ctx):
    ctx = make_ctx(ur5e_robot([("apple", fruit_at(0.72, 0.0, 0.80), 0.035)]))
    run_skill(ctx, "fruit_setup")
    run = run_skill(ctx, "fruit_summary")
    assert run.status is SkillStatus.FAILURE and "stopped before the plant was cleared" in run.failure.reason
    ctx.robot.camera.spheres = []
    run_skill(ctx, "detect_fruit")
    assert run_skill(ctx, "fruit_summary").status is SkillStatus.SUCCESS


def test_setup_refuses_an_unknown_basket_and_pick_needs_a_choice(make_ctx):
    ctx = make_ctx(ur5e_robot([]))
    run = run_skill(ctx, "fruit_setup", {"basket": "bucket"})
    assert run.status is SkillStatus.FAILURE and "'robot' or 'marker'" in run.failure.reason
    run = run_skill(ctx, "pick_fruit")
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.PRECONDITION
    assert "no fruit chosen" in run.failure.reason
