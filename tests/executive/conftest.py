"""Shared fixtures of the executive tests."""

from __future__ import annotations

import pytest
from test_nodes_support import Harness


@pytest.fixture
def h(tmp_path):
    """A :class:`~test_nodes_support.Harness` writing its files below ``tmp_path``
    (a module needing files written first defines its own ``h``)."""
    return Harness(tmp_path)
