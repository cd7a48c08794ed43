"""The recovery node (Nav2's RecoveryNode with a give-up branch; docs/missions.md)."""

from __future__ import annotations

from collections.abc import Iterator
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

__all__ = ["Recovery"]

_ACTION, _RECOVERY, _GIVE_UP = 0, 1, 2


class Recovery(MissionNode, py_trees.composites.Composite):
    """Nav2-style recovery node with a give-up branch (docs/missions.md).

    Children: ``[action, recovery]`` or ``[action, recovery, give_up]``. The
    bookkeeping is written to the blackboard under ``<key_prefix>.attempts``,
    ``.recoveries``, ``.last_failure`` and ``.outcome`` (``key_prefix`` defaults to
    ``name``). When the tree's :class:`~mmexec.executive.context.ExecContext` has
    ``recovery_enabled`` false, the bound is 0 for every activation: the action runs
    once and a failure goes straight to ``give_up``.
    """

    def __init__(
        self,
        rt: Runtime,
        path: str,
        name: str,
        action: Any,
        recovery: Any,
        give_up: Any | None,
        max_recoveries: int,
        key_prefix: str | None = None,
    ) -> None:
        children = [action, recovery] + ([give_up] if give_up is not None else [])
        self._mn_init(rt, path, name, children)
        self.current_child = None
        self.action, self.recovery, self.give_up = action, recovery, give_up
        self.max_recoveries = max_recoveries
        #: the bound of the current activation (0 when recovery is disabled)
        self.bound = max_recoveries
        self.recoveries = 0
        self.attempts = 0
        self.phase = _ACTION
        self._outcome = "running"
        prefix = name if key_prefix is None else key_prefix
        self.k_attempts = f"{prefix}.attempts"
        self.k_recoveries = f"{prefix}.recoveries"
        self.k_failure = f"{prefix}.last_failure"
        self.k_outcome = f"{prefix}.outcome"

    def update(self) -> Status:  # py_trees abstract hook; the executive uses _update
        return self.status

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        return MissionNode.tick(self)

    def stop(self, new_status: Status = INVALID) -> None:
        MissionNode.stop(self, new_status)

    def _record(self) -> None:
        bb = self.rt.bb
        bb[self.k_attempts] = self.attempts
        bb[self.k_recoveries] = self.recoveries

    def _start(self) -> None:
        ctx = self.rt.ctx
        self.bound = self.max_recoveries if ctx is None or ctx.recovery_enabled else 0
        self.recoveries = 0
        self.attempts = 0
        self.phase = _ACTION
        bb = self.rt.bb
        bb[self.k_outcome] = "running"
        bb[self.k_failure] = ""
        self._record()

    def _update(self) -> Status:
        rt = self.rt
        if self.phase == _ACTION:
            if self.action.status is not RUNNING:
                self.attempts += 1
                self._record()
            st = self.action.step()
            if st is RUNNING:
                return RUNNING
            if st is SUCCESS:
                rt.bb[self.k_outcome] = "success"
                rt.emit("recovery_success", self.path, attempts=self.attempts, recoveries=self.recoveries)
                self.recoveries = 0
                return SUCCESS
            bb = rt.bb
            node = bb.get("last_failure_node", "")
            if isinstance(node, str) and (node == self.action.path or node.startswith(self.action.path + "/")):
                reason = str(bb.get("last_failure", ""))
            else:
                reason = f"{self.action.path} failed"
            bb[self.k_failure] = reason
            if self.recoveries >= self.bound:
                rt.emit("recovery_give_up", self.path, attempts=self.attempts, recoveries=self.recoveries, reason=reason,
                        max_recoveries=self.bound)
                return self._begin_give_up("gave_up")
            self.recoveries += 1
            self._record()
            rt.emit("recovery_attempt", self.path, attempt=self.recoveries, reason=reason,
                    max_recoveries=self.bound)
            self.phase = _RECOVERY
        if self.phase == _RECOVERY:
            st = self.recovery.step()
            if st is RUNNING:
                return RUNNING
            if st is SUCCESS:
                self.phase = _ACTION
                return RUNNING
            rt.emit("recovery_failed", self.path, attempts=self.attempts, recoveries=self.recoveries,
                    reason=str(rt.bb.get("last_failure", "")))
            return self._begin_give_up("recovery_failed")
        return self._tick_give_up()

    def _begin_give_up(self, outcome: str) -> Status:
        self._outcome = outcome
        self.phase = _GIVE_UP
        return self._tick_give_up()

    def _tick_give_up(self) -> Status:
        if self.give_up is not None:
            st = self.give_up.step()
            if st is RUNNING:
                return RUNNING
        self.rt.bb[self.k_outcome] = self._outcome
        self.recoveries = 0
        return FAILURE

    def _on_halted(self) -> None:
        self.recoveries = 0
        self.rt.bb[self.k_outcome] = "halted"
