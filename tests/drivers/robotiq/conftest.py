"""Shared helpers for the Robotiq tests: fast fakes, goal polling, thread-leak check."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _no_leaked_threads(no_leaked_threads: None) -> None:
    """Every test must leave the thread count where it found it (tests/drivers/conftest.py)."""
