"""Fixtures for the fetch skill tests (helpers in fetchkit.py)."""

from __future__ import annotations

import copy
from collections.abc import Iterator
from typing import Any

import pytest
from fetchkit import FETCH_PROFILE, MarkerCamera, room_grid

from mmexec.drivers.interfaces import Pose2D
from mmexec.drivers.mock.robot import MockRobot
from mmexec.skills.base import SkillContext


@pytest.fixture
def fetch_robot() -> Iterator[MockRobot]:
    """A mock robot at (1, 1, 0) in a 6 x 6 m walled room, with the fetch profile and a
    :class:`MarkerCamera` (no markers yet: set ``robot.camera.markers``)."""
    robot = MockRobot(profile=copy.deepcopy(FETCH_PROFILE))
    assert robot.base is not None
    robot.base.pose = Pose2D(1.0, 1.0, 0.0)
    robot.occupancy = room_grid()
    robot.camera = MarkerCamera(robot, {})
    yield robot
    robot.close()


@pytest.fixture
def fetch_ctx(fetch_robot: MockRobot) -> Iterator[SkillContext]:
    """A SkillContext on ``fetch_robot``; ``ctx.events`` collects (event, fields)."""
    from mmexec.skills.manipulation.arm import close_workspace

    events: list[tuple[str, dict[str, Any]]] = []

    def emit(event: str, **fields: Any) -> None:
        events.append((event, fields))

    ctx = SkillContext.for_robot(fetch_robot, emit=emit)
    ctx.events = events  # type: ignore[attr-defined]
    yield ctx
    close_workspace(ctx.world)


