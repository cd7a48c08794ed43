"""pytest fixtures for testing skills against the mock backend.

Registered through the ``pytest11`` entry point, so any project with mmexec installed
gets them without a conftest:

* ``mock_robot``: a fresh :class:`~mmexec.drivers.mock.MockRobot` with every capability
  and a profile holding ``named_poses.home`` / ``named_poses.ready``; script it in the
  test (``mock_robot.arm.fail_moves = {1, 2}``).
* ``skill_ctx``: a :class:`~mmexec.skills.base.SkillContext` on ``mock_robot`` whose
  ``emit`` appends ``(event, fields)`` to ``skill_ctx.events`` (a list attribute).
* ``run_mock_skill``: ``run_mock_skill(name_or_spec, params=None, period=0.05)`` runs a
  skill to completion on ``mock_robot`` with ``skill_ctx`` and returns the
  :class:`~mmexec.skills.base.SkillRun`.

Kept import-light: the mock package is imported only when a fixture is used.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from mmexec.drivers.mock.robot import MockRobot
    from mmexec.skills.base import SkillContext, SkillRun, SkillSpec

#: Profile given to the ``mock_robot`` fixture (6 joint values per pose, rad).
DEFAULT_PROFILE: dict[str, Any] = {
    "named_poses": {
        "home": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        "ready": [0.0, -0.5, 0.6, 0.0, 0.5, 0.0],
        "sleep": [0.0, -1.1, 1.55, 0.0, 0.5, 0.0],
    },
    "home": [0.0, 0.0, 0.0],
}


@pytest.fixture
def mock_robot() -> Iterator[MockRobot]:
    from mmexec.drivers.mock.robot import MockRobot

    robot = MockRobot(profile=copy.deepcopy(DEFAULT_PROFILE))
    yield robot
    robot.close()


@pytest.fixture
def skill_ctx(mock_robot: MockRobot) -> SkillContext:
    from mmexec.skills.base import SkillContext

    events: list[tuple[str, dict[str, Any]]] = []

    def emit(event: str, **fields: Any) -> None:
        events.append((event, fields))

    ctx = SkillContext.for_robot(mock_robot, emit=emit)
    ctx.events = events  # type: ignore[attr-defined]
    return ctx


@pytest.fixture
def run_mock_skill(
    mock_robot: MockRobot, skill_ctx: SkillContext
) -> Callable[..., SkillRun]:
    from mmexec.skills.testing import run_with_mock

    def run(skill: SkillSpec | str, params: Mapping[str, Any] | None = None, *, period: float = 0.05,
            max_ticks: int = 100_000) -> SkillRun:
        return run_with_mock(skill, mock_robot, params, period=period, ctx=skill_ctx, max_ticks=max_ticks)

    return run
