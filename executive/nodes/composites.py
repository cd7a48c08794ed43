"""Composites (py_trees' ``composites.py``): sequence, fallback, parallel, if/then/else.

Each decides which of its children run, following the halt contract of
:mod:`mmexec.executive.nodes.behaviour`.
"""

from __future__ import annotations

from typing import Any

import py_trees
from py_trees.common import Status

from mmexec.executive.nodes.behaviour import (
    FAILURE,
    INVALID,
    RUNNING,
    SUCCESS,
    MissionNode,
    Runtime,
)

__all__ = ["Fallback", "IfThenElse", "Parallel", "Sequence"]


class _Chain(MissionNode):
    """Sequence and fallback: children in order while they return ``_advance_on``.

    One tick: tick the current child (the first one when ``reactive``); while it returns
    ``_advance_on`` go on to the next; any other status is the node's status. When
    every child returned ``_advance_on`` that is the node's status too. ``reactive``:
    when an earlier child no longer returns ``_advance_on``, the running later child
    is preempted (halted) before that status is returned.
    """

    _advance_on: Status = SUCCESS
    reactive = False
    _index = 0

    def __init__(self, rt: Runtime, path: str, name: str, children: list[Any], reactive: bool = False) -> None:
        self._mn_init(rt, path, name, children)
        self.memory = not reactive
        self.current_child = None
        self.reactive = reactive

    def _start(self) -> None:
        self._index = 0

    def _update(self) -> Status:
        children = self.children
        advance = self._advance_on
        n = len(children)
        i = 0 if self.reactive else self._index
        while i < n:
            st = children[i].step()
            if st is advance:
                i += 1
                continue
            if self.reactive and self._index > i:
                # an earlier child decided again: the later running child is preempted
                self._index = i
                later = [c for c in children[i + 1 :] if c.status is RUNNING]
                if later:
                    return self._preempt(later, st)
            self._index = i
            return st
        self._index = n
        return advance


class Sequence(_Chain, py_trees.composites.Sequence):
    """Children in order; SUCCESS when all succeed. ``reactive``: restart from the first
    child every tick, halting a running later child when an earlier one fails (or is
    RUNNING again)."""

    _advance_on = SUCCESS


class Fallback(_Chain, py_trees.composites.Selector):
    """Children in order until one does not fail. ``reactive``: restart from the first
    child every tick; a higher-priority child that is RUNNING or SUCCESS preempts the
    running lower-priority one."""

    _advance_on = FAILURE


class Parallel(MissionNode, py_trees.composites.Parallel):
    """Ticks every unfinished child each tick. Succeeds once ``threshold`` children
    succeeded, fails once that can no longer happen; the children still running are
    halted before the outcome is returned."""

    def __init__(self, rt: Runtime, path: str, name: str, children: list[Any], threshold: int) -> None:
        n = len(children)
        if n == 0 or not 1 <= threshold <= n:
            raise ValueError(f"{path}: parallel success threshold {threshold} outside 1..{n}")
        if threshold == n:
            policy: py_trees.common.ParallelPolicy.Base = py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=True)
        else:
            policy = py_trees.common.ParallelPolicy.SuccessOnOne()
        self._mn_init(rt, path, name, children)
        self.policy = policy
        self.current_child = None
        self.threshold = threshold
        self._done: list[Status] = []

    def _start(self) -> None:
        self._done = [INVALID] * len(self.children)

    def _update(self) -> Status:
        done = self._done
        succ = fail = 0
        for i, child in enumerate(self.children):
            st = done[i]
            if st is INVALID:
                st = child.step()
                if st is not RUNNING:
                    done[i] = st
            if st is SUCCESS:
                succ += 1
            elif st is FAILURE:
                fail += 1
        if succ >= self.threshold:
            return self._preempt(self.children, SUCCESS)
        if fail > len(self.children) - self.threshold:
            return self._preempt(self.children, FAILURE)
        return RUNNING


class IfThenElse(MissionNode, py_trees.composites.Composite):
    """BehaviorTree.CPP's IfThenElse: a condition picks a branch.

    Children: ``[condition, then]`` or ``[condition, then, else]``. The condition (any
    node) is ticked until it finishes; SUCCESS picks ``then``, FAILURE picks ``else``
    (without one the node fails), and the picked branch is ticked in the same tick. Its
    status is the node's; the condition is not ticked again while the branch runs.
    """

    def __init__(self, rt: Runtime, path: str, name: str, condition: Any, then: Any, orelse: Any | None) -> None:
        self._mn_init(rt, path, name, [condition, then] + ([orelse] if orelse is not None else []))
        self.current_child = None
        self.condition, self.then, self.orelse = condition, then, orelse
        #: the branch this activation picked (None: the condition has not finished)
        self.branch: Any | None = None

    def _start(self) -> None:
        self.branch = None

    def _update(self) -> Status:
        if self.branch is None:
            st = self.condition.step()
            if st is RUNNING:
                return RUNNING
            if st is FAILURE and self.orelse is None:
                return FAILURE
            self.branch = self.then if st is SUCCESS else self.orelse
        return self.branch.step()  # type: ignore[no-any-return]
