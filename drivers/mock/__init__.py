"""Mock backend: in-memory capabilities with scriptable outcomes (public testing module).

Use it to unit-test your own skills without a simulator or a robot::

    from mmexec.drivers.mock import MockRobot, run_with_mock
    from mmexec.skills.base import SkillContext

    robot = MockRobot(profile={"named_poses": {"home": [0, 0, 0, 0, 0, 0]}})
    robot.arm.fail_moves = {1}                      # the first arm move aborts
    run = run_with_mock("move_arm", robot, {"pose": "home"})
    assert run.failure is not None and "scripted" in run.failure.reason

With pytest, the fixtures ``mock_robot``, ``skill_ctx`` and ``run_mock_skill`` are
available automatically once mmexec is installed (see :mod:`mmexec.drivers.mock.pytest_plugin`
and docs/testing.md). In a run config, ``backend: mock`` selects this backend and the
``mock:`` section scripts it (see :mod:`mmexec.drivers.mock.backend`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from mmexec.drivers.mock.backend import MockConfig, build, parse_section, robot_from_config
from mmexec.drivers.mock.robot import (
    DEFAULT_ARM_LIMITS,
    MockArm,
    MockBase,
    MockCamera,
    MockGripper,
    MockLidar,
    MockRobot,
)
from mmexec.skills.base import SkillContext, SkillRegistry, SkillRun, SkillSpec, run_skill

__all__ = [
    "DEFAULT_ARM_LIMITS",
    "MockArm",
    "MockBase",
    "MockCamera",
    "MockConfig",
    "MockGripper",
    "MockLidar",
    "MockRobot",
    "build",
    "parse_section",
    "robot_from_config",
    "run_with_mock",
]


def run_with_mock(
    skill: SkillSpec | str,
    robot: MockRobot,
    params: Mapping[str, Any] | None = None,
    *,
    period: float = 0.05,
    ctx: SkillContext | None = None,
    max_ticks: int = 100_000,
    registry: SkillRegistry | None = None,
) -> SkillRun:
    """Run ``skill`` to completion on ``robot``, spinning it ``period`` [s] between ticks.

    Returns the finished :class:`SkillRun`: ``.status``, ``.outputs``, ``.failure``.
    Importing :mod:`mmexec.skills.primitives` first makes the primitive skills available
    by name; this helper does so.
    """
    import mmexec.skills.primitives  # noqa: F401  - registers the primitive skills

    context = ctx if ctx is not None else SkillContext.for_robot(robot)
    return run_skill(skill, context, params, step=lambda: robot.spin(period), max_ticks=max_ticks,
                     registry=registry)
