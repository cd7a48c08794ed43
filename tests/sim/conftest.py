from __future__ import annotations

from pathlib import Path

import pytest

from mmexec.config.yamlload import load_yaml_text

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def sim_section():
    """Parse a ``sim:`` section as the config loader would hand it over (a YDict with marks)."""
    return lambda text: load_yaml_text(text, "config.yaml")


@pytest.fixture(scope="session")
def bench_world() -> str:
    return str(DATA / "bench.yaml")
