"""find_panel and approach_panel on the mock backend: the searching movement (views, base
turns, search locations) for the locator marker rendered by the base camera, the panel
pose that follows from it, and the stand-off along the panel's normal."""

from __future__ import annotations

import math

import numpy as np
import pytest
from buttonkit import PanelCamera, events_of, offset, panel_pose, run_skill

from mmexec.skills.base import FailureKind, SkillStatus
from mmexec.skills.buttons.panel import WORLD_DONE, WORLD_PANEL, PanelEstimate


def test_find_panel_turns_until_the_locator_is_in_view(ctx, robot):
    # the panel behind the robot's left: seen after one or two 120 degree turns, not at first
    T = panel_pose(0.6, 1.9, 0.6, math.radians(-66))
    robot.camera = PanelCamera(robot, {20: offset(T, 0.0, -0.25)})
    ctx.world[WORLD_DONE] = {"b1"}
    run = run_skill(ctx, "find_panel")
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert run.outputs["views"] in (2, 3)
    assert abs(robot.base.pose.theta) > math.radians(100)  # the base turned
    est = ctx.world[WORLD_PANEL]
    assert est.source == "locator"
    assert np.linalg.norm(est.T_map_panel[:3, 3] - T[:3, 3]) < 0.03  # the face centre, 0.25 m above the locator
    assert float(est.T_map_panel[:3, 2] @ T[:3, 2]) > math.cos(math.radians(5))
    assert est.T_map_panel[2, 1] == pytest.approx(1.0)  # its y is up
    assert ctx.world[WORLD_DONE] == set()  # a new search starts a new request's presses
    assert events_of(ctx, "panel_found")[0]["marker"] == 20


def test_find_panel_reports_where_it_looked(ctx, robot):
    robot.camera = PanelCamera(robot, {})
    run = run_skill(ctx, "find_panel", {"locations": [[3.0, 3.0, 0.0]]})
    assert run.failure is not None and run.failure.kind is FailureKind.EXECUTION
    assert run.failure.reason == "locator marker 20 not found: 6 views at 2 places"
    assert robot.base.pose.distance_to(type(robot.base.pose)(3.0, 3.0, 0.0)) < 0.1
    assert WORLD_PANEL not in ctx.world


def test_approach_panel_parks_on_the_normal_and_shifts_on_retries(ctx, robot):
    T = panel_pose(4.0, 3.0, 0.6, math.pi)
    ctx.world[WORLD_PANEL] = PanelEstimate(T, "fit")
    for attempt, d in ((0, 0.6), (1, 0.55), (2, 0.65)):
        run = run_skill(ctx, "approach_panel", {"attempt": attempt})
        assert run.status is SkillStatus.SUCCESS, run.failure
        p = robot.base.pose
        assert run.outputs["distance"] == pytest.approx(d)
        assert (p.x, p.y) == (pytest.approx(4.0 - d, abs=0.05), pytest.approx(3.0, abs=0.05))
        assert abs(p.theta) < 0.1  # facing the panel


def test_approach_panel_needs_a_panel(ctx, robot):
    run = run_skill(ctx, "approach_panel")
    assert run.failure is not None and run.failure.kind is FailureKind.PRECONDITION
    assert "find the panel first" in run.failure.reason
