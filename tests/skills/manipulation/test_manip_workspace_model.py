"""The arm workspace plans with the robot's description (``Robot.description``), never by
a model name: the kinematics and planning scene are the description's, ``profile.arm.model``
checks it (or names it for a backend that gives none), and every way it can be missing or
wrong is a PRECONDITION failure that says what to set."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from mmexec.drivers import descriptions
from mmexec.drivers.mock.robot import MockRobot
from mmexec.skills.base import FailureKind, SkillContext, SkillFailure
from mmexec.skills.manipulation.arm import ArmSettings, close_workspace, workspace

HOME = [0.0] * 6


def _ctx(description: descriptions.RobotDescription | None, arm: dict[str, Any]) -> SkillContext:
    robot = MockRobot(profile={"named_poses": {"sleep": HOME}, "arm": arm}, description=description)
    return SkillContext.for_robot(robot, emit=lambda event, **fields: None)


@pytest.fixture
def contexts() -> Iterator[list[SkillContext]]:
    made: list[SkillContext] = []
    yield made
    for ctx in made:
        close_workspace(ctx.world)


def test_the_workspace_is_the_robots_description(contexts: list[SkillContext]) -> None:
    locobot = descriptions.get("locobot_wx250s")
    contexts.append(ctx := _ctx(locobot, {}))
    ws = workspace(ctx)
    assert ws.kin.joint_names == locobot.info.arm_joints
    assert np.array_equal(ws.kin.M, locobot.arm.M)  # type: ignore[union-attr]
    assert ws.scene.model.urdf == str(locobot.urdf_path)
    assert ws.scene.model.grasp_links == locobot.grasp_links
    assert all(lim.acceleration == locobot.arm.acceleration for lim in ws.kin.limits)  # type: ignore[union-attr]


def test_the_profile_model_names_it_for_a_robot_without_one(contexts: list[SkillContext]) -> None:
    contexts.append(ctx := _ctx(None, {"model": "locobot_wx250s"}))
    assert workspace(ctx).scene.model.urdf == str(descriptions.get("locobot_wx250s").urdf_path)


@pytest.mark.parametrize(("description", "arm", "message"), [
    (None, {}, (r"the robot has no description to plan with: name its model in the config \(robot.description, "
               rf"sim.robot or profile.arm.model: one of {', '.join(descriptions.names())}\)")),
    ("locobot_wx250s", {"model": "ur5e_robotiq"}, (r"profile.arm.model 'ur5e_robotiq' is not this robot's "
                                                  r"model 'locobot_wx250s'")),
    ("ur5e_robotiq", {}, (r"robot model 'ur5e_robotiq' plans joints \['shoulder_pan_joint', .*but the arm has "
                         r"\['waist', ")),
])
def test_a_missing_or_wrong_model_is_a_precondition(description: str | None, arm: dict[str, Any],
                                                    message: str) -> None:
    ctx = _ctx(descriptions.get(description) if description else None, arm)
    with pytest.raises(SkillFailure, match=message) as ei:
        workspace(ctx)
    assert ei.value.kind is FailureKind.PRECONDITION


def test_an_unknown_profile_model_is_refused_when_the_profile_loads() -> None:
    assert ArmSettings(model="locobot_wx250s").validate() == []
    assert ArmSettings(model="ur5e_robotik").validate() == [
        ("model: unknown robot model 'ur5e_robotik'; did you mean 'ur5e_robotiq'? "
        f"(known: {', '.join(descriptions.names())})")]
    with pytest.raises(SkillFailure, match=r"profile.arm: model: unknown robot model 'ur5e_robotik'") as ei:
        workspace(_ctx(descriptions.get("ur5e_robotiq"), {"model": "ur5e_robotik"}))
    assert ei.value.kind is FailureKind.PRECONDITION
