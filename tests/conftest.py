"""Shared test helpers for the whole suite.

The mock backend's fixtures (``mock_robot``, ``skill_ctx``, ``run_mock_skill``) come from
the installed pytest plugin :mod:`mmexec.skills.testing.pytest_plugin`; this file only adds
repository-level helpers.
"""

from __future__ import annotations

import signal
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]

# A suite started where SIGINT is ignored (a background job of a non-interactive shell:
# `.ci/run &`) would hand that on to every mmexec it spawns (an ignored signal stays
# ignored across exec, and Python then installs no KeyboardInterrupt handler), and the
# Ctrl-C tests would see a run that never heard it. Those tests are about what mmexec
# does when interrupted, so the suite restores the default for its children (a handled
# signal is reset to the default on exec).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture
def repo_root() -> Path:
    """The repository checkout (for shipped missions and configs)."""
    return REPO_ROOT


@dataclass
class CliResult:
    rc: int
    out: str
    err: str


@pytest.fixture
def run_cli(capsys: pytest.CaptureFixture[str]) -> Callable[..., CliResult]:
    """``run_cli("validate", "m.yaml")`` runs ``mmexec`` in-process and returns
    ``CliResult(rc, out, err)``."""
    from mmexec.executive.cli import main

    def run(*argv: str) -> CliResult:
        capsys.readouterr()
        rc = main([str(a) for a in argv])
        captured = capsys.readouterr()
        return CliResult(rc, captured.out, captured.err)

    return run
