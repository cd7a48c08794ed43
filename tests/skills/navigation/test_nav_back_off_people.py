"""Backing off (navigate.back_off_by, the fetch tree's back_off) looks behind with the
lidar when the local planner runs (issue 12): by the static map alone a UR3e backed 0.3 m
into someone standing behind it (1 mm from the footprint), and the turn that followed
swept the arm into them."""

from __future__ import annotations

import math
from typing import Any

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.navigation.local_drive import local_planner
from mmexec.skills.navigation.navigate import BACK_OFF_PERSON_GAP, back_off_by, local_drive_config

START = Pose2D(3.0, 1.5, 0.0)


def _back_off(robot: Any, ctx: Any, distance: float) -> Pose2D:
    gen = back_off_by(ctx, distance)
    try:
        for _ in range(2000):
            next(gen)
            robot.spin(0.05)
    except StopIteration as stop:
        return stop.value
    raise AssertionError("the back-off did not end")


def test_backing_off_stops_short_of_a_person_behind():
    """A person walks up behind the base and stands 0.75 m behind its centre: the back-off
    of 0.5 m is shortened so that they keep their safety radius and BACK_OFF_PERSON_GAP;
    with nothing behind, the base backs the whole way."""
    from test_nav_local_drive import _ctx, _robot, room

    events: list = []
    walker = [2.0, 1.5, 0.2]
    robot = _robot(room(), START, circles=[tuple(walker)])
    ctx = _ctx(robot, events)
    planner = local_planner(ctx, local_drive_config(ctx, robot.base, None).planner)
    for k in range(40):                     # walking west to east, then standing at x = 2.25
        walker[0] = min(2.25, 1.0 + 0.05 * k)
        robot.lidar.circles = [tuple(walker)]
        robot.spin(0.05)
        planner.observe(robot.lidar.scan(), robot.base.state().pose)
    people = planner.circles_at(robot.clock.now())
    assert people.person.any()
    end = _back_off(robot, ctx, 0.5)
    shortened = [f for e, f in events if e == "back_off_shortened"]
    assert shortened and shortened[0]["by"] == "lidar" and shortened[0]["used"] < 0.5
    k = int(people.person.argmax())
    gap = math.hypot(end.x - 2.25, end.y - 1.5) - float(people.safety_radii[k])
    assert gap >= BACK_OFF_PERSON_GAP - 0.06                  # within a costmap step and the tracking

    events.clear()
    robot = _robot(room(), START)
    ctx = _ctx(robot, events)
    end = _back_off(robot, ctx, 0.5)
    assert abs(START.x - end.x - 0.5) <= 0.01 and not [e for e, _ in events if e == "back_off_shortened"]
