"""The skill test kit: run a skill to completion on a robot, without a tree.

Use it to unit-test your own skills on the mock backend (:mod:`mmexec.drivers.mock`)::

    from mmexec.drivers.mock import MockRobot
    from mmexec.skills.testing import run_with_mock

    robot = MockRobot(profile={"named_poses": {"home": [0, 0, 0, 0, 0, 0]}})
    robot.arm.fail_moves = {1}                      # the first arm move aborts
    run = run_with_mock("move_arm", robot, {"pose": "home"})
    assert run.failure is not None and "scripted" in run.failure.reason

With pytest, the fixtures ``mock_robot``, ``skill_ctx`` and ``run_mock_skill`` are
available automatically once mmexec is installed (:mod:`mmexec.skills.testing.pytest_plugin`,
docs/testing.md). The kit works on any :class:`~mmexec.drivers.interfaces.Robot` (a
simulated one too); only the pytest plugin builds a mock robot, which makes it the one
place under ``skills/`` allowed to import a backend (tests/test_layers.py says so).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from mmexec.drivers.interfaces import Robot
from mmexec.skills.base import SkillContext, SkillRegistry, SkillRun, SkillSpec, run_skill

__all__ = ["run_with_mock"]


def run_with_mock(
    skill: SkillSpec | str,
    robot: Robot,
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
