"""Named poses of the robot profile (mmexec.skills.poses): base poses by name (home,
places, names skill packages add such as the fetch package's depot) and arm joint poses."""

from __future__ import annotations

import pytest

import mmexec.skills.fetch  # noqa: F401 - adds the depot base pose
from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import FailureKind, SkillContext, SkillFailure
from mmexec.skills.poses import add_base_pose, arm_joints, base_pose, pose_list

DEPOT = {"base": [1.0, 4.0, 1.5708], "place": [1.0, 4.45, 0.25]}


def test_home_places_and_the_fetch_depot_by_name(mock_robot) -> None:
    mock_robot.profile.update({"home": [1, 2, 0], "places": {"shelf": [3, 4, 0.5]}, "fetch": {"depot": DEPOT}})
    ctx = SkillContext.for_robot(mock_robot)
    assert base_pose(ctx, "home") == Pose2D(1.0, 2.0, 0.0)
    assert base_pose(ctx, "shelf") == Pose2D(3.0, 4.0, 0.5)
    assert base_pose(ctx, "depot") == Pose2D(1.0, 4.0, 1.5708)


def test_an_unknown_name_lists_the_known_ones(mock_robot) -> None:
    mock_robot.profile.update({"places": {"shelf": [3, 4, 0.5], "table": [0, 1, 0]}, "fetch": {"depot": DEPOT}})
    ctx = SkillContext.for_robot(mock_robot)
    with pytest.raises(SkillFailure) as e:
        base_pose(ctx, "kitchen", "drive_to")
    assert e.value.kind is FailureKind.PRECONDITION
    assert e.value.reason == ("drive_to: no base pose named 'kitchen' in the robot profile "
                              "(known: home, depot, shelf, table)")
    del mock_robot.profile["fetch"]
    with pytest.raises(SkillFailure, match=r"\(known: home, shelf, table\)"):
        base_pose(ctx, "depot")


def test_a_package_adds_a_base_pose_that_exists_with_its_section(mock_robot, monkeypatch) -> None:
    from mmexec.skills import poses

    monkeypatch.setattr(poses, "_EXTRA", dict(poses._EXTRA))  # the name goes with the test
    add_base_pose("dock", "dock", lambda ctx: pose_list(ctx.profile["dock"], "profile.dock"))
    ctx = SkillContext.for_robot(mock_robot)
    with pytest.raises(SkillFailure, match="no base pose named 'dock'"):
        base_pose(ctx, "dock")
    mock_robot.profile["dock"] = [0.5, 0.5, 3.0]
    assert base_pose(ctx, "dock") == Pose2D(0.5, 0.5, 3.0)
    mock_robot.profile["dock"] = [0.5, 0.5]
    with pytest.raises(SkillFailure, match=r"profile.dock: expected \[x, y, theta\] in map, got \[0.5, 0.5\]"):
        base_pose(ctx, "dock")


def test_arm_joint_poses_by_name(mock_robot) -> None:
    assert arm_joints(mock_robot.profile, "ready") == [0.0, -0.5, 0.6, 0.0, 0.5, 0.0]
    with pytest.raises(SkillFailure, match=r"move_arm: no named pose 'wave' in the robot profile \(known: home, "
                                           r"ready, sleep\)"):
        arm_joints(mock_robot.profile, "wave", "move_arm")
    mock_robot.profile["named_poses"]["bad"] = ["a", 1]
    with pytest.raises(SkillFailure, match="profile pose 'bad' is not a list of numbers"):
        arm_joints(mock_robot.profile, "bad")
