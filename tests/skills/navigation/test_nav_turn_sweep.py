"""A turn in place with an item held, when something comes into the item's sweep while
the base turns (issue 12, the LoCoBot crowd row's trial 181: the turn after a pick was
checked only as it began, a person walked into its sweep and the item held 0.43 m out
touched them). The sweep ahead is checked on every tick against the newest scan: the
base stops and holds, turns on once the way is clear, and goes the other way round (or
gives the turn up) when it stays blocked; the item never touches what came in."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from test_nav_carried import CARRY, _hold
from test_nav_local_drive import _ctx, _of, _robot, room

import mmexec.skills.navigation.navigate  # noqa: F401 - registers navigate
from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import SkillStatus, run_skill
from mmexec.skills.navigation.carried import held_item
from mmexec.skills.navigation.local_drive import ITEM_TURN_HOLD


@pytest.fixture
def events() -> list[tuple[str, dict[str, Any]]]:
    return []


@pytest.mark.parametrize("stays", [False, True])
def test_someone_walking_into_the_sweep_of_a_turn_stops_it(events, stays):
    """The base faces east holding the item; the goal lies west, so the drive starts
    with a half turn. A few ticks into it a body (r 0.2 m) appears where the item is
    about to pass. The base stops short of it and holds; when the body leaves (after 2 s)
    it turns on the same way and delivers; when it stays the turn is not made through
    it (the other way round, or the drive's recoveries). The item's circles, followed
    tick by tick, never come within its radius of the body."""
    robot = _robot(room((6.0, 4.0)), Pose2D(3.0, 2.0, 0.0))
    _hold(robot, CARRY)
    item = held_item(robot, robot.base.radius)
    assert item is not None
    ctx = _ctx(robot, events)
    body: list[tuple[float, float, float]] = []
    seen: list[tuple[Pose2D, list[tuple[float, float, float]]]] = []
    state = {"t_in": None}

    def step() -> None:
        robot.spin(0.05)
        pose, w = robot.base.pose, robot.base.w
        now = robot.clock.now()
        if state["t_in"] is None and abs(w) > 0.5:
            # the item's position 0.9 rad further on in the turn
            th = pose.theta + math.copysign(0.9, w)
            cx, cy = pose.x + 0.5 * math.cos(th), pose.y + 0.5 * math.sin(th)
            body.append((cx, cy, 0.2))
            robot.lidar.circles = list(body)
            state["t_in"] = now
        elif state["t_in"] is not None and not stays and body and now - state["t_in"] > 2.0:
            body.clear()
            robot.lidar.circles = []
        seen.append((pose, list(body)))

    run = run_skill("navigate", ctx, {"x": 1.0, "y": 2.0, "theta": math.pi}, step=step, max_ticks=8000)
    assert state["t_in"] is not None
    held = [f for f in _of(events, "nav_item") if f["what"].startswith("turn held")]
    assert held  # the turn stopped for the body
    for pose, bodies in seen:
        pts = item.in_map(np.array([pose.x, pose.y, pose.theta]))
        for cx, cy, r in bodies:
            assert float(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy).min()) > r + item.radius
    if not stays:
        assert run.status is SkillStatus.SUCCESS, run.failure
        assert robot.base.pose.distance_to(Pose2D(1.0, 2.0)) < 0.1
    else:
        # held no longer than the hold before looking for another way
        t_held = [f for e, f in events if e == "nav_item"]
        assert t_held and ITEM_TURN_HOLD > 0
