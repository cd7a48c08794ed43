"""Decorators (py_trees' ``decorators.py``): one child whose status they map, repeat,
run once per list element or bound in time, and :class:`Subtree`, the node an
``include`` becomes."""

from __future__ import annotations

from typing import Any

import py_trees
from py_trees.common import Status

from mmexec.executive.nodes.behaviour import (
    FAILURE,
    RUNNING,
    SUCCESS,
    MissionNode,
    Runtime,
    clock_seconds,
)
from mmexec.executive.values import EvalError, Expr
from mmexec.skills.base import FailureKind

__all__ = ["ForceFailure", "ForceSuccess", "Foreach", "Invert", "Repeat", "Retry", "Subtree", "Timeout"]


class _Decorator(MissionNode, py_trees.decorators.Decorator):
    def __init__(self, rt: Runtime, path: str, name: str, child: Any) -> None:
        self._mn_init(rt, path, name, [child])
        self.decorated = child
        self.child = child

    def update(self) -> Status:  # py_trees abstract hook; the executive uses _update
        return self.status


class Subtree(_Decorator):
    """An included file: passes its child's status through (names the include in paths)."""

    def _update(self) -> Status:
        return self.child.step()


class Invert(_Decorator):
    def _update(self) -> Status:
        st = self.child.step()
        if st is SUCCESS:
            return FAILURE
        if st is FAILURE:
            return SUCCESS
        return st


class ForceSuccess(_Decorator):
    def _update(self) -> Status:
        st = self.child.step()
        return SUCCESS if st is FAILURE else st


class ForceFailure(_Decorator):
    def _update(self) -> Status:
        st = self.child.step()
        return FAILURE if st is SUCCESS else st


class Retry(_Decorator):
    """Up to ``attempts`` runs of the child; a failed run is restarted on the next tick."""

    def __init__(self, rt: Runtime, path: str, name: str, child: Any, attempts: int) -> None:
        super().__init__(rt, path, name, child)
        self.attempts = attempts
        self.count = 0

    def _start(self) -> None:
        self.count = 0

    def _update(self) -> Status:
        st = self.child.step()
        if st is FAILURE:
            self.count += 1
            return FAILURE if self.count >= self.attempts else RUNNING
        return st


class Repeat(_Decorator):
    """``times`` successful runs in a row (None: until the child fails)."""

    def __init__(self, rt: Runtime, path: str, name: str, child: Any, times: int | None) -> None:
        super().__init__(rt, path, name, child)
        self.times = times
        self.count = 0

    def _start(self) -> None:
        self.count = 0

    def _update(self) -> Status:
        st = self.child.step()
        if st is SUCCESS:
            self.count += 1
            if self.times is not None and self.count >= self.times:
                return SUCCESS
            return RUNNING
        return st


class Foreach(_Decorator):
    """Runs the child once per element of a list, one run per tick at most (as BT.CPP's
    LoopNode): before each run the element is written to blackboard key ``key``, where
    the child reads it as ``{key}``. SUCCESS after the last element's run succeeded (at
    once for an empty list), FAILURE when a run fails. The list is read when the node
    starts (a change on the blackboard during the loop is not seen); a missing key or a
    value that is not a list fails it with kind precondition. Event: ``foreach_item``
    (``index`` from 0, ``count``) as each run starts."""

    def __init__(self, rt: Runtime, path: str, name: str, child: Any, items: Expr, key: str) -> None:
        super().__init__(rt, path, name, child)
        self.items = items
        self.key = key
        self.index = 0
        self._list: list[Any] = []

    def _start(self) -> None:
        self.index = 0
        self._list = []
        self._bad = None
        try:
            items = self.items.eval(self.rt.bb)
        except EvalError as e:
            self._bad = f"foreach: {e.reason}"
            return
        if not isinstance(items, (list, tuple)):
            self._bad = f"foreach: expected a list, got {type(items).__name__} {items!r:.60}"
            return
        self._list = list(items)

    def _update(self) -> Status:
        if self._bad is not None:
            return self._unmet()
        items = self._list
        if self.index >= len(items):
            return SUCCESS
        if self.child.status is not RUNNING:
            self.rt.bb[self.key] = items[self.index]
            self.rt.emit("foreach_item", self.path, index=self.index, count=len(items))
        st = self.child.step()
        if st is SUCCESS:
            self.index += 1
            return SUCCESS if self.index >= len(items) else RUNNING
        return st


class Timeout(_Decorator):
    """FAILURE (after halting the child) once ``seconds`` clock seconds passed since start."""

    def __init__(self, rt: Runtime, path: str, name: str, child: Any, seconds: Expr) -> None:
        super().__init__(rt, path, name, child)
        self.seconds = seconds
        self.deadline = 0.0
        self._limit = 0.0

    def _start(self) -> None:
        limit = clock_seconds(self.seconds, self.rt.bb, "timeout", positive=True)
        self._bad = limit if isinstance(limit, str) else None
        if isinstance(limit, float):
            self._limit = limit
            self.deadline = self.rt.now() + limit

    def _update(self) -> Status:
        if self._bad is not None:
            return self._unmet()
        if self.rt.now() >= self.deadline:
            return self._expire()
        st = self.child.step()
        if st is RUNNING and self.rt.now() >= self.deadline:
            return self._expire()
        return st

    def _expire(self) -> Status:
        reason = f"{self.path}: timed out after {self._limit:g} s"
        self.rt.fail(self.path, FailureKind.TIMEOUT, reason)
        self.rt.emit("timeout", self.path, seconds=self._limit)
        return self._preempt([self.child], FAILURE)
