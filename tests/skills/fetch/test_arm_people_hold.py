"""An arm motion among people (skills/manipulation/arm.py ``execute``): with the local
planner's people tracking, the arm stops while someone walks into its way and goes on
to the same goal once they are clear; without it the same walk meets the moving arm."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fetchkit import events_of, run_skill

from mmexec.drivers.interfaces import LaserScan, Lidar
from mmexec.drivers.mock.robot import MockArm, MockRobot
from mmexec.skills.base import SkillStatus
from mmexec.skills.manipulation import wx250s
from mmexec.skills.manipulation.arm import ARM_PERSON_GAP, WORLD_ARM, _person_gap
from mmexec.skills.navigation.obstacles import Circles
from mmexec.skills.navigation.synthetic import cast_scan

PERSON_R = 0.2
WALK = 0.8  # [m/s]


class WalkerLidar(Lidar):
    """A 360-degree scan of the robot's map and one person (radius ``PERSON_R``) at
    ``where(t)``, ``t`` [s] since the arm first moved (pacing far off before that)."""

    def __init__(self, robot: MockRobot, stop_y: float = 0.35) -> None:
        self.robot, self.stop_y = robot, stop_y
        self.t_move: float | None = None

    def person(self) -> tuple[float, float]:
        now = self.robot.clock.now()
        if self.t_move is None:  # pacing 0.9 m off the arm's way, so that the tracker knows them as a person
            return (1.8 + 0.3 * math.sin(2.0 * now), 1.9)
        t = now - self.t_move
        # then south across the arm's reach at WALK m/s, stopping at stop_y (0.65 m south of the base)
        return (1.8, max(self.stop_y, 1.9 - WALK * t))

    def scan(self) -> LaserScan | None:
        assert self.robot.base is not None and self.robot.occupancy is not None
        return cast_scan(self.robot.occupancy, self.robot.base.state().pose, np.array([self.person()]),
                         np.array([PERSON_R]), n_beams=360, stamp=self.robot.clock.now())


@pytest.fixture
def walker_robot(fetch_robot: MockRobot) -> MockRobot:
    kin = wx250s(locobot=True)
    fetch_robot.arm = MockArm(fetch_robot.clock, limits=kin.limits, start=fetch_robot.profile["named_poses"]["tuck"])
    fetch_robot.lidar = WalkerLidar(fetch_robot)
    return fetch_robot


@pytest.mark.parametrize("watched", [True, False])
def test_the_arm_holds_while_a_person_walks_into_its_way(walker_robot, fetch_ctx, watched):
    robot, lidar = walker_robot, walker_robot.lidar
    robot.profile["nav"]["local_planner"] = watched
    target = robot.profile["named_poses"]["home"]  # straight out ahead: the tool 0.55 m past the mount
    moving_gaps: list[float] = []
    last = {"q": list(robot.arm.state().positions)}

    def watch_tick() -> None:
        q = list(robot.arm.state().positions)
        if lidar.t_move is None and q != last["q"]:
            lidar.t_move = robot.clock.now()
        if q != last["q"] and WORLD_ARM in fetch_ctx.world:
            true = Circles(np.array([lidar.person()]), np.array([PERSON_R]))
            moving_gaps.append(_person_gap(fetch_ctx, fetch_ctx.world[WORLD_ARM], true, [q]))
        last["q"] = q

    run = run_skill(fetch_ctx, "arm_pose", {"pose": "home"}, on_tick=watch_tick)
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert list(robot.arm.state().positions) == pytest.approx(target, abs=1e-3)
    holds, resumes = events_of(fetch_ctx, "arm_hold"), events_of(fetch_ctx, "arm_resume")
    if watched:
        assert len(holds) >= 1 and len(resumes) == len(holds)
        assert all(h["gap"] < ARM_PERSON_GAP for h in holds)
        assert robot.arm.cancels == len(holds)
        # the arm never moved with the person nearer its segment than the gap, less what
        # a walking person covers in the two ticks it takes to see them and stop
        assert min(moving_gaps) >= ARM_PERSON_GAP - WALK * 0.1
    else:
        assert holds == [] and robot.arm.cancels == 0
        assert min(moving_gaps) < ARM_PERSON_GAP - 0.1  # the walk does meet the moving arm's way


def test_a_person_who_stays_in_the_arms_way_fails_the_motion(walker_robot, fetch_ctx):
    """Someone stops right in the arm's way (beside where the tool is going) and stays: the
    arm holds ARM_HOLD_LIMIT, then the motion fails (EXECUTION) with the arm stopped short
    of its goal, holding, not moved on into them."""
    from mmexec.skills.base import FailureKind
    from mmexec.skills.manipulation.arm import ARM_HOLD_LIMIT

    robot = walker_robot
    robot.profile["nav"]["local_planner"] = True
    robot.lidar = lidar = WalkerLidar(robot, stop_y=1.2)
    q_seen = {"q": list(robot.arm.state().positions)}

    def watch_tick() -> None:
        q = list(robot.arm.state().positions)
        if lidar.t_move is None and q != q_seen["q"]:
            lidar.t_move = robot.clock.now()
        q_seen["q"] = q

    run = run_skill(fetch_ctx, "arm_pose", {"pose": "home"}, on_tick=watch_tick)
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.EXECUTION
    assert f"for {ARM_HOLD_LIMIT:g} s" in run.failure.reason, run.failure.reason
    assert len(events_of(fetch_ctx, "arm_hold")) == 1 and events_of(fetch_ctx, "arm_resume") == []
    assert robot.clock.now() - lidar.t_move >= ARM_HOLD_LIMIT
    assert list(robot.arm.state().positions) != pytest.approx(robot.profile["named_poses"]["home"], abs=0.05)
    assert not robot.arm.busy
