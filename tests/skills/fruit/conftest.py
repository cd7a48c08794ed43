"""Fixtures for the fruit skill tests (helpers in fruitkit.py)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from mmexec.skills.base import SkillContext


@pytest.fixture
def make_ctx() -> Iterator[Any]:
    """``make_ctx(robot)``: a SkillContext on a mock robot; ``ctx.events`` collects (event, fields)."""
    from mmexec.skills.manipulation.arm import close_workspace

    made: list[SkillContext] = []

    def make(robot: Any) -> SkillContext:
        events: list[tuple[str, dict[str, Any]]] = []

        def emit(event: str, **fields: Any) -> None:
            events.append((event, fields))

        ctx = SkillContext.for_robot(robot, emit=emit)
        ctx.events = events  # type: ignore[attr-defined]
        made.append(ctx)
        return ctx

    yield make
    for ctx in made:
        close_workspace(ctx.world)
        ctx.robot.close()
