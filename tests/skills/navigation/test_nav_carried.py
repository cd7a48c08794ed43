"""The held item in navigation (issue 12): where the arm holds it (from the gripper, the
measured joints and the description's kinematics), which map obstacles reach its height
(the robot's scene boxes), the guard's turn and arc checks, and a local drive that brings
the item held out 0.43 m ahead to a stop beside a box without sweeping it through the box
(the LoCoBot's carried item swept into the lab's crate by the depot and dropped)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from test_nav_local_drive import _ctx, _of, _robot, room

import mmexec.skills.navigation.navigate  # noqa: F401 - registers navigate
from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import GraspState, Pose2D, SceneBox
from mmexec.drivers.mock.robot import MockRobot
from mmexec.skills.base import SkillStatus, run_skill
from mmexec.skills.navigation.carried import (
    ITEM_PAD,
    HeldItem,
    ItemGuard,
    held_item,
    layer_floor,
    tall_layer,
)
from mmexec.skills.navigation.costmap import RollingCostmap, StaticLayer

#: the LoCoBot profile's carry pose (config/locobot_sim.yaml)
CARRY = [0.0, -0.2, 0.6, 0.0, 0.5, 0.0]
KOBUKI_RADIUS = 0.178


@pytest.fixture
def events() -> list[tuple[str, dict[str, Any]]]:
    return []


def _box(x0: float, y0: float, x1: float, y1: float, height: float, name: str = "box") -> SceneBox:
    T = np.eye(4)
    T[:3, 3] = ((x0 + x1) / 2, (y0 + y1) / 2, height / 2)
    return SceneBox(name, T, (x1 - x0, y1 - y0, height))


def _hold(robot: MockRobot, q: list[float], width: float = 0.056) -> None:
    """Move the mock arm to ``q`` and close the mock gripper on an item ``width`` wide."""
    assert robot.arm is not None and robot.gripper is not None
    robot.gripper.object_width = width
    goals = [robot.arm.move_to(q, speed_scale=1.0), robot.gripper.close()]
    for _ in range(400):
        robot.spin(0.05)
        if all(g.done() for g in goals):
            break
    assert robot.gripper.state().grasp is GraspState.CONTACT_CLOSING


def test_the_held_item_is_where_the_carry_pose_holds_it():
    robot = MockRobot()
    assert held_item(robot, KOBUKI_RADIUS) is None  # nothing held
    _hold(robot, CARRY)
    item = held_item(robot, KOBUKI_RADIUS)
    assert item is not None
    # the LoCoBot's carry pose holds the grasp point 0.425 m ahead, 0.246 m up
    assert item.points[0] == pytest.approx([0.425, 0.0], abs=0.005)
    assert item.radius == pytest.approx(0.056 / math.sqrt(2) + ITEM_PAD)
    assert item.floor == pytest.approx(0.246 - item.radius - 0.02, abs=0.005)
    assert item.reach == pytest.approx(0.425 + item.radius, abs=0.005)
    # circles every 5 cm back to the footprint, along the base's x axis
    d = np.hypot(item.points[:, 0], item.points[:, 1])
    assert np.all(np.diff(d) < 0) and d.min() <= KOBUKI_RADIUS + item.radius
    # in map: turned with the base
    pts = item.in_map(np.array([1.0, 2.0, math.pi / 2]))
    assert pts[0] == pytest.approx([1.0, 2.425], abs=0.005)


def test_an_item_over_the_footprint_needs_no_guard():
    robot = MockRobot()
    _hold(robot, CARRY)
    assert held_item(robot, 0.6) is None  # a footprint that covers it all


def test_the_tall_layer_leaves_out_what_lies_below_the_item():
    """A basket 0.15 m high and a crate 0.4 m high in the map: above a 0.2 m floor only
    the crate (and the walls, which no box explains) count."""
    basket, crate = (1.0, 1.0, 1.4, 1.3), (2.0, 1.0, 2.35, 1.35)
    grid = room((4.0, 2.5), boxes=(basket, crate))
    scene = [_box(*basket, 0.15, "basket"), _box(*crate, 0.4, "crate")]
    tall = tall_layer(grid, scene, 0.2)
    whole = StaticLayer(grid)
    probe = np.array([[1.2, 1.15], [2.17, 1.17], [0.02, 1.0]])
    assert whole.clearance_at(probe).tolist() == [0.0, 0.0, 0.0]
    assert tall.clearance_at(probe)[0] > 0.3  # the basket is gone (its nearest: the crate, or a wall)
    assert tall.clearance_at(probe)[1:].tolist() == [0.0, 0.0]  # the crate and the wall stay
    # below a 0.1 m floor the basket counts again
    assert tall_layer(grid, scene, 0.1).clearance_at(probe)[0] == 0.0


def _guard(grid_boxes: tuple[tuple[float, float, float, float], ...]) -> ItemGuard:
    grid = room((4.0, 3.0), boxes=grid_boxes)
    item = HeldItem(points=np.array([[0.43, 0.0], [0.38, 0.0], [0.33, 0.0], [0.28, 0.0], [0.23, 0.0]]),
                    radius=0.06, floor=0.17, reach=0.49)
    return ItemGuard(item, RollingCostmap(grid), StaticLayer(grid))


def test_the_guard_sees_which_way_round_a_turn_sweeps_the_item_into_a_box():
    """Facing north with a box north-east of the base: turning right to face east sweeps
    the item through it; the other way round (three quarters of a turn) does not."""
    guard = _guard(((2.25, 1.75, 2.55, 2.05),))
    pose = Pose2D(2.0, 1.5, math.pi / 2)
    assert guard.gaps(np.array([2.0, 1.5, 0.0])) > guard.margin  # facing east: clear
    assert guard.gaps(np.array([2.0, 1.5, math.pi / 4])) < 0  # half way: in the box
    assert not guard.turn_clear(pose, -math.pi / 2)
    assert guard.turn_clear(pose, 1.5 * math.pi)


def test_the_guard_checks_arcs_and_lets_an_item_inside_a_zone_move_out():
    guard = _guard(((2.6, 0.0, 3.0, 3.0),))
    towards = Pose2D(2.0, 1.5, 0.0)  # item 0.17 m from the wall-like box
    assert not guard.arc_clear(towards, 0.3, 0.0, 0.8)  # straight on: into it
    assert guard.arc_clear(towards, -0.2, 0.0, 0.8)  # backing away
    assert guard.arc_clear(Pose2D(1.0, 1.5, 0.0), 0.3, 0.0, 0.8)  # far off: clear
    inside = Pose2D(2.14, 1.5, 0.0)  # the item's circle already overlaps the box: moving out is allowed
    assert guard.gaps(np.array([inside.x, inside.y, inside.theta])) < 0
    assert guard.arc_clear(inside, -0.2, 0.0, 0.8) and not guard.arc_clear(inside, 0.1, 0.0, 0.8)


def test_a_drive_with_an_item_held_keeps_it_clear_of_a_box_beside_the_goal(events):
    """The goal faces north with a tall box just east of it: arriving heading east, or
    turning right there, puts the item held 0.43 m ahead into the box. The drive comes
    in along the goal's heading and turns the way that keeps the item clear; the item,
    followed tick by tick from the base's pose, never enters the box."""
    box = (3.25, 0.9, 3.6, 1.45)
    robot = _robot(room(boxes=(box,)), Pose2D(1.0, 1.5, 0.0))
    _hold(robot, CARRY)
    item = held_item(robot, robot.base.radius)
    assert item is not None
    ctx = _ctx(robot, events)
    poses: list[Pose2D] = []
    run = run_skill("navigate", ctx, {"x": 3.0, "y": 1.5, "theta": math.pi / 2},
                    step=lambda: (robot.spin(0.05), poses.append(robot.base.pose)), max_ticks=6000)
    assert run.status is SkillStatus.SUCCESS, run.failure
    end = robot.base.pose
    assert end.distance_to(Pose2D(3.0, 1.5)) <= 0.09 and abs(wrap_angle(end.theta - math.pi / 2)) <= 0.05
    pts = item.in_map(np.array([[p.x, p.y, p.theta] for p in poses]))  # (ticks, k, 2)
    x0, y0, x1, y1 = box
    dx = np.maximum(np.maximum(x0 - pts[..., 0], pts[..., 0] - x1), 0.0)
    dy = np.maximum(np.maximum(y0 - pts[..., 1], pts[..., 1] - y1), 0.0)
    assert np.hypot(dx, dy).min() > item.radius  # the item's circles never touched the box
    # the path's last stretch runs along the goal's heading into the goal
    last = _of(events, "nav_plan")[0]["points"]
    assert last[-1] == [3.0, 1.5] and last[-2][0] == pytest.approx(3.0, abs=0.03) and last[-2][1] < 1.1


def test_the_carried_item_passes_over_the_depot_basket():
    """The lab's basket walls are 0.15 m high; the LoCoBot's carried item reaches down
    to 0.166 m: the layer built for the item leaves the basket out (a layer for a floor
    rounded to 5 cm, 0.15 m, kept it, and the guard stopped every drive short of the
    depot stop)."""
    robot = MockRobot()
    _hold(robot, CARRY)
    item = held_item(robot, KOBUKI_RADIUS)
    assert item is not None and 0.15 < item.floor < 0.2
    basket = (1.0, 1.0, 1.4, 1.3)
    grid = room((4.0, 2.5), boxes=(basket,))
    tall = tall_layer(grid, [_box(*basket, 0.15, "basket")], layer_floor(item.floor))
    assert tall.clearance_at(np.array([[1.2, 1.15]]))[0] > 0.3
    assert layer_floor(0.166) == 0.16 and layer_floor(0.15) == 0.15


def test_a_drive_with_an_item_held_brings_it_over_a_low_basket(events):
    """The depot: the stop faces a basket 0.15 m high whose middle is 0.43 m ahead of it,
    where the carried item is released. The map has the basket; the robot's scene says
    it is low, so the drive brings the item over it to the stop."""
    basket = (2.8, 1.78, 3.2, 2.08)
    robot = _robot(room(boxes=(basket,)), Pose2D(1.0, 1.0, 0.0))
    robot.scene = (_box(*basket, 0.15, "basket"),)
    _hold(robot, CARRY)
    ctx = _ctx(robot, events)
    run = run_skill("navigate", ctx, {"x": 3.0, "y": 1.5, "theta": math.pi / 2},
                    step=lambda: robot.spin(0.05), max_ticks=6000)
    assert run.status is SkillStatus.SUCCESS, run.failure
    end = robot.base.pose
    assert end.distance_to(Pose2D(3.0, 1.5)) <= 0.05 and abs(wrap_angle(end.theta - math.pi / 2)) <= 0.05
