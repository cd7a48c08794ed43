"""Test-only skills for the campaign tests (loaded through a test config's
``skills: modules:``; its ``skills: paths: [.]`` puts this folder on the import path).

* ``ct_coin``: waits ``item`` x 0.5 s of clock time, then fails (postcondition) when
  ``item`` is odd: each trial's outcome follows from the item its seed drew;
* ``ct_crash``: kills its own process with SIGKILL when ``item == crash_on`` (a trial
  that crashes mid-run, as a segfaulting simulator would);
* ``ct_hang``: blocks the tick in a real sleep when ``item == hang_on`` (a hung driver
  call, which only the campaign's ``--trial-timeout`` can end). Test-only: real skills
  never block.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Generator
from typing import Any

from mmexec.skills.base import FailureKind, Param, SkillContext, SkillFailure, skill


@skill("ct_coin", params=[Param("item", int, required=True, doc="request item")])
def ct_coin(ctx: SkillContext, item: int) -> Generator[None, None, dict[str, Any]]:
    """Wait item x 0.5 clock seconds; fail when item is odd."""
    end = ctx.clock.now() + 0.5 * item
    while ctx.clock.now() < end:
        yield
    if item % 2:
        raise SkillFailure(FailureKind.POSTCONDITION, f"item {item} is odd")
    return {}


@skill("ct_crash", params=[Param("item", int, required=True, doc="request item"),
                           Param("crash_on", int, required=True, doc="item that kills the process")])
def ct_crash(ctx: SkillContext, item: int, crash_on: int) -> Generator[None, None, dict[str, Any]]:
    """SIGKILL this process when item == crash_on, else succeed after one tick."""
    yield
    if item == crash_on:
        os.kill(os.getpid(), signal.SIGKILL)
    return {}


@skill("ct_hang", params=[Param("item", int, required=True, doc="request item"),
                          Param("hang_on", int, required=True, doc="item that hangs the process")])
def ct_hang(ctx: SkillContext, item: int, hang_on: int) -> Generator[None, None, dict[str, Any]]:
    """Block for 120 wall seconds when item == hang_on, else succeed after one tick."""
    yield
    if item == hang_on:
        time.sleep(120.0)
    return {}
