"""Fixtures for the button presser's skill tests (helpers in buttonkit.py)."""

from __future__ import annotations

import copy
from collections.abc import Iterator
from typing import Any

import pytest
from buttonkit import PROFILE, room_grid

from mmexec.drivers.interfaces import Pose2D
from mmexec.drivers.mock.robot import MockArm, MockRobot
from mmexec.skills.base import SkillContext
from mmexec.skills.manipulation import wx250s


@pytest.fixture
def robot() -> Iterator[MockRobot]:
    """A mock LoCoBot-jointed robot at (1, 1, 0) in a 6 x 6 m room, arm tucked."""
    r = MockRobot(profile=copy.deepcopy(PROFILE))
    assert r.base is not None
    r.base.pose = Pose2D(1.0, 1.0, 0.0)
    r.occupancy = room_grid()
    r.arm = MockArm(r.clock, limits=wx250s(locobot=True).limits, start=PROFILE["named_poses"]["tuck"])
    yield r
    r.close()


@pytest.fixture
def ctx(robot: MockRobot) -> Iterator[SkillContext]:
    """A SkillContext on ``robot``; ``ctx.events`` collects (event, fields)."""
    from mmexec.skills.manipulation.arm import close_workspace

    events: list[tuple[str, dict[str, Any]]] = []

    def emit(event: str, **fields: Any) -> None:
        events.append((event, fields))

    c = SkillContext.for_robot(robot, emit=emit)
    c.events = events  # type: ignore[attr-defined]
    yield c
    close_workspace(c.world)
