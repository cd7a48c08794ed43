"""User skills the hostile-input tests load through a config's ``skills.modules``.

* ``fail_with(message)``: fails with ``message`` as its reason (user text that reaches
  the result line, the event log and ``mmexec log summary`` / ``replay``);
* ``exit_now()``: calls ``sys.exit(0)`` in the middle of a run;
* ``spoil_file(path, how)``: makes ``path`` unreadable between two requests of a
  ``--watch`` run: ``fifo`` (a named pipe nobody writes), ``loop`` (a symlink to
  itself) or ``folder`` (a directory). It does nothing when ``path`` is already spoiled,
  so the previous version of a mission that runs it can be served again.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Generator
from pathlib import Path
from typing import Any

from mmexec.skills.base import FailureKind, Param, SkillContext, SkillFailure, skill


@skill("fail_with", params=[Param("message", str, required=True, doc="the failure reason")])
def fail_with(ctx: SkillContext, message: str) -> Generator[None, None, dict[str, Any]]:
    """Fail at once with ``message``."""
    yield from ()
    raise SkillFailure(FailureKind.EXECUTION, message)


@skill("exit_now")
def exit_now(ctx: SkillContext) -> Generator[None, None, dict[str, Any]]:
    """End the interpreter from inside a tick, as careless user code might."""
    yield
    sys.exit(0)


@skill("spoil_file", params=[Param("path", str, required=True), Param("how", str, required=True,
                                                                       choices=("fifo", "loop", "folder"))])
def spoil_file(ctx: SkillContext, path: str, how: str) -> Generator[None, None, dict[str, Any]]:
    """Replace the regular file ``path`` by something that cannot be read (see the module doc)."""
    yield from ()
    p = Path(path)
    if p.is_symlink() or not p.is_file():
        return {}
    p.unlink()
    if how == "fifo":
        os.mkfifo(p)
    elif how == "loop":
        p.symlink_to(p.name)
    else:
        p.mkdir()
    return {}
