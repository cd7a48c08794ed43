"""Polling helpers for the Robotiq tests (bounded waits, never forever)."""

from __future__ import annotations

import time
from collections.abc import Callable

from mmexec.drivers.interfaces import Goal, GoalState


def wait_for(pred: Callable[[], object], timeout: float = 2.0) -> bool:
    """Poll ``pred`` until true or ``timeout`` s pass; returns its last value."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.005)
    return bool(pred())


def finish(goal: Goal, timeout: float = 2.0) -> GoalState:
    """Poll ``goal`` until done (bounded); returns its final state."""
    assert wait_for(goal.done, timeout), f"{goal} not done within {timeout} s"
    return goal.state
