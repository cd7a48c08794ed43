"""Polling helpers for the Robotiq tests (bounded waits, never forever)."""

from __future__ import annotations

from driverkit import wait_for

from mmexec.drivers.interfaces import Goal, GoalState

__all__ = ["finish", "wait_for"]


def finish(goal: Goal, timeout: float = 2.0) -> GoalState:
    """Poll ``goal`` until done (bounded); returns its final state."""
    assert wait_for(goal.done, timeout), f"{goal} not done within {timeout} s"
    return goal.state
