"""Scripted skills for testing trees and benchmarking the executive (py_trees ships its
scripted behaviours as library code the same way).

:func:`register_scripted` adds these skills to a registry (keep them out of the default
:data:`~mmexec.skills.base.REGISTRY`: pass a private ``SkillRegistry()``):

* ``succeed`` (ticks=0, value=None): RUNNING for ``ticks`` ticks after the start tick,
  then SUCCESS with output ``value``.
* ``fail`` (ticks=0, kind="execution", reason="scripted failure"): RUNNING for
  ``ticks`` ticks, then FAILURE with that kind and reason.
* ``hold`` (ticks=-1, stop_ticks=0): RUNNING for ``ticks`` ticks (forever when < 0),
  then SUCCESS; when cancelled it keeps yielding ``stop_ticks`` more ticks before it has
  stopped (an arm decelerating).
* ``flaky`` (counter, fail_times, reason): fails its first ``fail_times`` runs (counted
  in ``ctx.world[counter]``), then succeeds.
* ``script`` (counter, outcomes): run k (counted in ``ctx.world[counter]``) succeeds
  when ``outcomes[k]`` is ``"s"`` and fails when it is ``"f"`` (the last entry repeats).
* ``boom``: raises RuntimeError (a bug in a skill).

Every skill appends ``(ctx.node_path, event)`` to the list ``ctx.world["journal"]``,
events being ``start``, ``success``, ``failure``, ``cancel`` (cancellation received) and
``stopped`` (cancellation finished), so tests can check exactly what ran and stopped,
and in which order.
"""

from __future__ import annotations

from collections.abc import Generator
from typing import Any

from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillCancelled,
    SkillContext,
    SkillFailure,
    SkillRegistry,
    SkillSpec,
)

__all__ = ["journal", "register_scripted"]

_KINDS = tuple(k.value for k in FailureKind)


def journal(ctx: SkillContext) -> list[tuple[str, str]]:
    """The run's journal of scripted-skill events (created on first use)."""
    j = ctx.world.setdefault("journal", [])
    return j  # type: ignore[no-any-return]


def _succeed(ctx: SkillContext, ticks: int = 0, value: Any = None) -> Generator[None, None, dict[str, Any]]:
    j = journal(ctx)
    j.append((ctx.node_path, "start"))
    for _ in range(ticks):
        yield
    j.append((ctx.node_path, "success"))
    return {"value": value}


def _fail(
    ctx: SkillContext, ticks: int = 0, kind: str = "execution", reason: str = "scripted failure"
) -> Generator[None, None, dict[str, Any]]:
    j = journal(ctx)
    j.append((ctx.node_path, "start"))
    for _ in range(ticks):
        yield
    j.append((ctx.node_path, "failure"))
    raise SkillFailure(FailureKind(kind), reason)


def _hold(ctx: SkillContext, ticks: int = -1, stop_ticks: int = 0) -> Generator[None, None, dict[str, Any]]:
    j = journal(ctx)
    j.append((ctx.node_path, "start"))
    n = 0
    try:
        while ticks < 0 or n < ticks:
            n += 1
            yield
    except SkillCancelled:
        j.append((ctx.node_path, "cancel"))
        for _ in range(stop_ticks):
            try:
                yield
            except SkillCancelled:
                j.append((ctx.node_path, "cancel-again"))
        j.append((ctx.node_path, "stopped"))
        raise
    j.append((ctx.node_path, "success"))
    return {}


def _flaky(
    ctx: SkillContext, counter: str = "flaky", fail_times: int = 1, reason: str = "flaky failure"
) -> Generator[None, None, dict[str, Any]]:
    j = journal(ctx)
    j.append((ctx.node_path, "start"))
    runs = ctx.world.get(counter, 0)
    ctx.world[counter] = runs + 1
    yield
    if runs < fail_times:
        j.append((ctx.node_path, "failure"))
        raise SkillFailure(FailureKind.EXECUTION, f"{reason} (run {runs + 1})")
    j.append((ctx.node_path, "success"))
    return {"runs": runs + 1}


def _script(ctx: SkillContext, counter: str = "script", outcomes: str = "s") -> Generator[None, None, dict[str, Any]]:
    j = journal(ctx)
    j.append((ctx.node_path, "start"))
    runs = ctx.world.get(counter, 0)
    ctx.world[counter] = runs + 1
    outcome = outcomes[min(runs, len(outcomes) - 1)] if outcomes else "s"
    yield
    if outcome == "f":
        j.append((ctx.node_path, "failure"))
        raise SkillFailure(FailureKind.EXECUTION, f"scripted failure (run {runs + 1})")
    j.append((ctx.node_path, "success"))
    return {"runs": runs + 1}


def _boom(ctx: SkillContext) -> Generator[None, None, dict[str, Any]]:
    journal(ctx).append((ctx.node_path, "start"))
    yield
    raise RuntimeError("scripted bug")


def register_scripted(registry: SkillRegistry) -> SkillRegistry:
    """Register the scripted skills into ``registry`` and return it."""
    specs = [
        SkillSpec("succeed", _succeed, (Param("ticks", int, default=0), Param("value", object)),
                  (Output("value"),), "RUNNING for `ticks` ticks, then SUCCESS with output `value`."),
        SkillSpec("fail", _fail, (Param("ticks", int, default=0),
                                  Param("kind", str, default="execution", choices=_KINDS),
                                  Param("reason", str, default="scripted failure")),
                  (), "RUNNING for `ticks` ticks, then FAILURE."),
        SkillSpec("hold", _hold, (Param("ticks", int, default=-1), Param("stop_ticks", int, default=0)),
                  (), "RUNNING for `ticks` ticks (forever if < 0); takes `stop_ticks` ticks to stop."),
        SkillSpec("flaky", _flaky, (Param("counter", str, default="flaky"), Param("fail_times", int, default=1),
                                    Param("reason", str, default="flaky failure")),
                  (Output("runs", int),), "Fails its first `fail_times` runs, then succeeds."),
        SkillSpec("script", _script, (Param("counter", str, default="script"), Param("outcomes", str, default="s")),
                  (Output("runs", int),), "Run k succeeds or fails as `outcomes[k]` says ('s' / 'f')."),
        SkillSpec("boom", _boom, (), (), "Raises RuntimeError (a bug)."),
    ]
    for s in specs:
        registry.register(s, replace=True)
    return registry
