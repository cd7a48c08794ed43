"""Polling helpers for the DYNAMIXEL tests (bounded waits in real time, never fixed sleeps)."""

from __future__ import annotations

import time
from collections.abc import Callable

from mmexec.drivers.interfaces import Goal


def wait(goal: Goal, timeout: float) -> float:
    """Poll a goal like a tick loop would; return the seconds it took."""
    t0 = time.monotonic()
    while not goal.done():
        assert time.monotonic() - t0 < timeout, f"{goal} not done within {timeout} s"
        time.sleep(0.005)
    return time.monotonic() - t0


def until(pred: Callable[[], bool], timeout: float = 2.0) -> bool:
    """Poll ``pred`` until true or ``timeout`` s of real time pass (bounded, never fixed)."""
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True
