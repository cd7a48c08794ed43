"""Shared helpers for the executive node/compiler tests (no tests in here).

A fake Robot on a ManualClock, a private registry with the scripted skills, and helpers
to compile a mission from a YAML string and tick it.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

from py_trees.common import Status

from mmexec.config.yamlload import InputError
from mmexec.drivers.interfaces import ManualClock, Robot
from mmexec.executive.compiler import Mission, MissionTree, load_mission
from mmexec.executive.context import ExecContext
from mmexec.executive.scripted import register_scripted
from mmexec.skills.base import SkillRegistry


class FakeRobot(Robot):
    """No capabilities, a manual clock that ``spin`` advances."""

    name = "fake"

    def __init__(self) -> None:
        self.clock = ManualClock()
        self.profile = {}

    def spin(self, period: float) -> None:
        self.clock.advance(period)


def registry() -> SkillRegistry:
    return register_scripted(SkillRegistry())


class Harness:
    """Compile YAML text into a mission in ``tmp``, instantiate it, tick it."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.robot = FakeRobot()
        self.events: list[tuple[str, dict[str, Any]]] = []
        self.registry = registry()
        self.ctx = ExecContext(robot=self.robot, clock=self.robot.clock, registry=self.registry, emit=self._emit)
        self.changes: list[tuple[str, str, str]] = []

    def _emit(self, event: str, **fields: Any) -> None:
        self.events.append((event, fields))

    def write(self, name: str, text: str) -> Path:
        p = self.tmp / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(textwrap.dedent(text))
        return p

    def load(self, text: str, name: str = "m.yaml") -> Mission:
        return load_mission(self.write(name, text), self.registry)

    def problems(self, text: str, name: str = "m.yaml") -> list[str]:
        """The lines of the InputError that compiling ``text`` raises (AssertionError if none)."""
        try:
            self.load(text, name)
        except InputError as e:
            return str(e).splitlines()
        raise AssertionError(f"{name} compiled without problems")

    def tree(self, text: str, request: dict[str, Any] | None = None, params: dict[str, Any] | None = None) -> MissionTree:
        t = self.load(text).instantiate(self.ctx, request or {}, params)
        t.add_status_listener(lambda p, o, n: self.changes.append((p, o, n)))
        return t

    @property
    def journal(self) -> list[tuple[str, str]]:
        return self.ctx.world.setdefault("journal", [])

    def ticks(self, tree: MissionTree, n: int, dt: float = 0.1) -> list[Status]:
        out = []
        for _ in range(n):
            out.append(tree.tick())
            self.robot.spin(dt)
        return out

    def run(self, tree: MissionTree, limit: int = 200, dt: float = 0.1) -> tuple[Status, int]:
        for i in range(1, limit + 1):
            st = tree.tick()
            if st is not Status.RUNNING:
                return st, i
            self.robot.spin(dt)
        raise AssertionError(f"still running after {limit} ticks")

    def names(self, event: str) -> list[str]:
        return [f["node"] for e, f in self.events if e == event]
