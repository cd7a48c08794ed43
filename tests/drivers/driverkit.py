"""Helpers shared by the driver tests (importable from every folder below tests/drivers:
its conftest.py puts this folder on the path)."""

from __future__ import annotations

import time
from collections.abc import Callable


def wait_for(pred: Callable[[], object], timeout: float = 2.0, poll: float = 0.005) -> bool:
    """Poll ``pred`` every ``poll`` s until it is truthy or ``timeout`` s of real time
    pass (bounded, never forever); whether it became true."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(poll)
    return bool(pred())
