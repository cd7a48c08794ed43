"""Shared fixtures of the camera tests."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _no_leaked_threads(no_leaked_threads: None) -> None:
    """Every camera test must leave the thread count where it found it."""
