"""Manipulation algorithms: arm kinematics (:mod:`.kinematics`), the planning scene
(:mod:`.scene`), OMPL planning and trajectory timing (:mod:`.planner`) and the seed
paper's pick/place poses (:mod:`.grasp`). Poses are 4x4 in the arm base frame unless a
docstring says otherwise; m, rad, s."""

from __future__ import annotations

from mmexec.skills.manipulation.grasp import (
    GraspPoses,
    PlacePoses,
    grasp_poses,
    place_poses,
    tool_rotation_in_marker,
)
from mmexec.skills.manipulation.kinematics import ArmKinematics, ur5e, wx250s
from mmexec.skills.manipulation.planner import (
    CANCELLED,
    ArmPlanner,
    PlannerConfig,
    PlanResult,
    time_parametrize,
)
from mmexec.skills.manipulation.scene import ArmModel, PlanningScene

__all__ = [
    "CANCELLED",
    "ArmKinematics",
    "ArmModel",
    "ArmPlanner",
    "GraspPoses",
    "PlacePoses",
    "PlanResult",
    "PlannerConfig",
    "PlanningScene",
    "grasp_poses",
    "place_poses",
    "time_parametrize",
    "tool_rotation_in_marker",
    "ur5e",
    "wx250s",
]
