"""navigate and approach on the mock backend: A* on a small grid, failure kinds, and the
stand-off pose facing a marker."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fetchkit import events_of, marker_pose, room_grid, run_skill

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import FailureKind, SkillStatus
from mmexec.skills.perception.detect import WORLD_MARKERS, MarkerEstimate

# a wall across the room at x in [2.5, 3.0], open only at the top (y > 4.5)
WALL = (2.5, 0.0, 3.0, 4.5)


def _track(robot):
    trace: list[Pose2D] = []
    return trace, lambda: trace.append(robot.base.pose)


def test_navigate_plans_around_a_wall_and_reaches_the_goal(fetch_robot, fetch_ctx):
    fetch_robot.occupancy = room_grid(boxes=[WALL])
    trace, on_tick = _track(fetch_robot)
    run = run_skill(fetch_ctx, "navigate", {"x": 4.5, "y": 1.0, "theta": -1.5708}, on_tick=on_tick)
    assert run.status is SkillStatus.SUCCESS, run.failure
    end = fetch_robot.base.pose
    assert end.distance_to(Pose2D(4.5, 1.0, 0.0)) < 0.06
    assert abs(math.atan2(math.sin(end.theta + 1.5708), math.cos(end.theta + 1.5708))) < 0.06
    assert run.outputs["pose"] == pytest.approx([end.x, end.y, end.theta])
    # the path went round the wall's open end: through y > 4.5 while crossing x in the wall
    crossing = [p for p in trace if 2.4 <= p.x <= 3.1]
    assert crossing and min(p.y for p in crossing) > 4.5
    # and never touched an occupied cell
    grid = fetch_robot.occupancy
    for p in trace:
        r, c = int(p.y / grid.resolution), int(p.x / grid.resolution)
        assert grid.data[r, c] == 0
    statuses = [e["status"] for e in events_of(fetch_ctx, "base_status")]
    assert statuses == ["to_goal", "goal_ok", "idle"]


def test_navigate_to_named_pose_respects_the_speed_limit(fetch_robot, fetch_ctx):
    fetch_robot.base.pose = Pose2D(4.0, 3.0, 0.0)
    speeds: list[float] = []
    run = run_skill(fetch_ctx, "navigate", {"goal": "home", "max_speed": 0.3},
                    on_tick=lambda: speeds.append(abs(fetch_robot.base.v)))
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert fetch_robot.base.pose.distance_to(Pose2D(1.0, 1.0, 0.0)) < 0.06
    assert max(speeds) <= 0.3 + 1e-6


def test_navigate_no_path_is_a_planning_failure(fetch_robot, fetch_ctx):
    # the goal is in a closed box
    fetch_robot.occupancy = room_grid(boxes=[(3.5, 3.5, 5.5, 3.7), (3.5, 5.3, 5.5, 5.5), (3.5, 3.5, 3.7, 5.5),
                                             (5.3, 3.5, 5.5, 5.5)])
    run = run_skill(fetch_ctx, "navigate", {"x": 4.5, "y": 4.5})
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.PLANNING and run.failure.reason.startswith("no path to (4.50, 4.50)")
    assert fetch_robot.base.commands == 0  # it never moved
    assert [e["status"] for e in events_of(fetch_ctx, "base_status")] == ["goal_fail", "idle"]


def test_navigate_goal_in_an_obstacle_is_a_planning_failure(fetch_robot, fetch_ctx):
    fetch_robot.occupancy = room_grid(boxes=[WALL])
    run = run_skill(fetch_ctx, "navigate", {"x": 2.75, "y": 2.0})
    assert run.failure.kind is FailureKind.PLANNING and "in collision" in run.failure.reason


def test_navigate_goal_in_the_inflation_is_served_from_the_nearest_free_point(fetch_robot, fetch_ctx):
    """A stop 0.1 m in front of the wall (inside the robot-radius inflation, as a depot
    stop with a randomised crate beside it): the base drives to the nearest free point
    within the profile's nav.goal_search (0.3 m) and says so."""
    fetch_robot.occupancy = room_grid(boxes=[WALL])
    run = run_skill(fetch_ctx, "navigate", {"x": 2.4, "y": 2.0, "theta": 0.0})
    assert run.status is SkillStatus.SUCCESS, run.failure
    [adj] = events_of(fetch_ctx, "goal_adjusted")
    assert adj["goal"] == [2.4, 2.0] and 0.0 < adj["shift"] <= 0.3
    end = fetch_robot.base.pose
    assert end.distance_to(Pose2D(*adj["used"], 0.0)) < 0.06
    assert end.x < 2.4 and abs(end.y - 2.0) < 0.06  # straight back from the wall, not round it


def test_navigate_goal_search_zero_keeps_the_strict_check(fetch_robot, fetch_ctx):
    fetch_robot.occupancy = room_grid(boxes=[WALL])
    fetch_robot.profile["nav"] = {"goal_search": 0.0}
    run = run_skill(fetch_ctx, "navigate", {"x": 2.4, "y": 2.0})
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.PLANNING and "in collision" in run.failure.reason
    assert not events_of(fetch_ctx, "goal_adjusted")


def test_navigate_base_fault_is_an_execution_failure(fetch_robot, fetch_ctx):
    fetch_robot.base.blocked = True
    run = run_skill(fetch_ctx, "navigate", {"x": 3.0, "y": 1.0})
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.EXECUTION and "bumper_centre" in run.failure.reason
    assert [e["status"] for e in events_of(fetch_ctx, "base_status")][-2:] == ["goal_fail", "idle"]


def test_navigate_without_a_map_is_a_precondition(fetch_robot, fetch_ctx):
    fetch_robot.occupancy = None
    run = run_skill(fetch_ctx, "navigate", {"goal": "home"})
    assert run.failure.kind is FailureKind.PRECONDITION and "needs a map" in run.failure.reason


def _estimate(ctx, marker: int, T: np.ndarray, distance: float = 0.6) -> None:
    ctx.world.setdefault(WORLD_MARKERS, {})[marker] = MarkerEstimate(marker, T, 3, 0.0, distance)


@pytest.mark.parametrize("params, expected", [
    ({"distance": 0.6}, 0.6),
    ({"distance_index": 1}, 0.7),     # the profile's approach_distances [0.5, 0.7, 0.9]
    ({"distance_index": 7}, 0.9),     # clamped to the last
])
def test_approach_stands_off_at_the_distance_facing_the_marker(fetch_robot, fetch_ctx, params, expected):
    T = marker_pose(5.3, 3.0, 0.5, math.pi)  # on the east side, facing west
    _estimate(fetch_ctx, 7, T)
    run = run_skill(fetch_ctx, "approach", {"marker": 7, **params})
    assert run.status is SkillStatus.SUCCESS, run.failure
    end = fetch_robot.base.pose
    assert run.outputs["distance"] == pytest.approx(expected)
    assert end.distance_to(Pose2D(5.3 - expected, 3.0, 0.0)) < 0.06
    assert abs(math.atan2(math.sin(end.theta), math.cos(end.theta))) < 0.06  # facing east, at the marker
    assert [e["distance"] for e in events_of(fetch_ctx, "standoff")] == [pytest.approx(expected)]


def test_approach_without_a_free_standoff_is_a_planning_failure(fetch_robot, fetch_ctx):
    # a crate fills the floor in front of the marker at every tried distance and angle
    fetch_robot.occupancy = room_grid(boxes=[(3.6, 2.0, 5.4, 4.0)])
    _estimate(fetch_ctx, 7, marker_pose(5.5, 3.0, 0.5, math.pi))
    run = run_skill(fetch_ctx, "approach", {"marker": 7, "distance": 0.6})
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.PLANNING
    assert run.failure.reason == "no path to the stand-off 0.60 m from marker 7: no free stand-off"
    assert fetch_robot.base.commands == 0
    assert [e["status"] for e in events_of(fetch_ctx, "base_status")] == ["goal_fail", "idle"]


def test_approach_unreachable_standoff_says_no_path(fetch_robot, fetch_ctx):
    # the stand-off is free but walled in
    fetch_robot.occupancy = room_grid(boxes=[(3.8, 2.0, 4.0, 4.0), (3.8, 2.0, 6.0, 2.2), (3.8, 3.8, 6.0, 4.0)])
    _estimate(fetch_ctx, 7, marker_pose(5.9, 3.0, 0.5, math.pi))
    run = run_skill(fetch_ctx, "approach", {"marker": 7, "distance": 0.8})
    assert run.failure.kind is FailureKind.PLANNING and run.failure.reason.endswith(": no path")


def test_approach_needs_an_estimate(fetch_robot, fetch_ctx):
    run = run_skill(fetch_ctx, "approach", {"marker": 7})
    assert run.failure.kind is FailureKind.PRECONDITION and "search for it first" in run.failure.reason


def test_approach_reestimates_a_far_marker_on_the_way(fetch_robot, fetch_ctx):
    T_true = marker_pose(5.3, 1.0, 0.5, math.pi)
    fetch_robot.camera.markers = {7: T_true}
    T_off = T_true.copy()
    T_off[1, 3] += 0.10  # the far estimate is 10 cm off sideways
    _estimate(fetch_ctx, 7, T_off, distance=4.3)
    run = run_skill(fetch_ctx, "approach", {"marker": 7, "distance": 0.5})
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert fetch_robot.camera.headings  # it looked again from the intermediate viewpoint
    end = fetch_robot.base.pose
    assert end.distance_to(Pose2D(4.8, 1.0, 0.0)) < 0.06  # the stand-off of the true marker


@pytest.mark.parametrize("redetect", [True, False])
def test_approach_redetects_from_the_standoff_when_the_profile_asks(fetch_robot, fetch_ctx, redetect):
    T_true = marker_pose(5.3, 1.0, 0.5, math.pi)
    fetch_robot.camera.markers = {7: T_true}
    T_off = T_true.copy()
    T_off[1, 3] += 0.03  # seen from 0.9 m (no intermediate look): 3 cm off sideways
    _estimate(fetch_ctx, 7, T_off, distance=0.9)
    fetch_robot.profile["nav"]["redetect_at_standoff"] = redetect
    run = run_skill(fetch_ctx, "approach", {"marker": 7, "distance": 0.5})
    assert run.status is SkillStatus.SUCCESS, run.failure
    est = fetch_ctx.world[WORLD_MARKERS][7]
    err = np.linalg.norm(est.T_map_marker[:3, 3] - T_true[:3, 3])
    looks = events_of(fetch_ctx, "marker_estimate")
    if redetect:
        assert err < 0.01, f"estimate still {err * 1e3:.0f} mm off"
        assert len(looks) == 1 and looks[0]["distance"] < 0.6
    else:
        assert err == pytest.approx(0.03)
        assert looks == []


def _drive(ctx, gen, period=0.05, max_ticks=2000):
    """Run a skill-helper generator to its return value, spinning the mock robot."""
    for _ in range(max_ticks):
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value
        ctx.robot.spin(period)
    raise AssertionError("helper still running")


@pytest.mark.parametrize("behind,expected", [(None, 0.25), (1.0, None)])
def test_back_off_stays_in_the_free_part_of_the_map(fetch_robot, fetch_ctx, behind, expected):
    """After a pick the base backs off straight; with an obstacle behind it (not the way it
    came) it stops where the inflated map stops being free, and logs by how much."""
    from mmexec.skills.navigation.navigate import back_off_by

    fetch_robot.base.pose = Pose2D(2.0, 3.0, 0.0)
    boxes = [] if behind is None else [(1.0, 2.5, 1.2, 3.5)]  # a wall 0.8-1.0 m behind
    fetch_robot.occupancy = room_grid(boxes=boxes)
    end = _drive(fetch_ctx, back_off_by(fetch_ctx, 0.25 if behind is None else 0.9))
    moved = Pose2D(2.0, 3.0, 0.0).distance_to(end)
    shortened = events_of(fetch_ctx, "back_off_shortened")
    if expected is not None:
        assert moved == pytest.approx(expected, abs=0.01) and not shortened
    else:
        [ev] = shortened
        assert ev["asked"] == 0.9 and 0.0 < ev["used"] < 0.9
        assert moved == pytest.approx(ev["used"], abs=0.01)
        from mmexec.skills.navigation.navigate import costmap

        assert costmap(fetch_ctx).is_free(end.x, end.y)


def test_back_off_skill_drives_straight_back(fetch_robot, fetch_ctx):
    fetch_robot.base.pose = Pose2D(2.0, 3.0, 0.0)
    run = run_skill(fetch_ctx, "back_off", {"distance": 0.3})
    assert run.status is SkillStatus.SUCCESS, run.failure
    x, y, _th = run.outputs["pose"]
    assert x == pytest.approx(1.7, abs=0.01) and y == pytest.approx(3.0, abs=0.01)
    bad = run_skill(fetch_ctx, "back_off", {"distance": -0.1})
    assert bad.failure.kind is FailureKind.PRECONDITION and "distance must be >= 0 m" in bad.failure.reason
