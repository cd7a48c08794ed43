"""What a running mission tree needs from the outside world: :class:`ExecContext`.

The runner builds one per run and passes it to :meth:`Mission.instantiate`; every skill
leaf derives its :class:`~mmexec.skills.base.SkillContext` from it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from mmexec.drivers.interfaces import Clock, Robot
from mmexec.skills.base import REGISTRY, SkillRegistry

__all__ = ["ExecContext", "drop_event"]


def drop_event(event: str, **fields: Any) -> None:
    """An event sink that discards everything (the default)."""


@dataclass
class ExecContext:
    """Run-wide context of a mission tree.

    ``robot``: the backend's capabilities; ``clock``: the time source every timeout and
    wait reads [s]; ``registry``: the skills leaves may run; ``emit``: the event sink,
    called as ``emit(event, **fields)`` (fields always include ``node``, the node path,
    and ``t``, the clock time [s]); ``world``: a dict shared by every skill of the run
    (across requests); ``profile``: the robot profile from the config;
    ``recovery_enabled``: false disables every recovery node (its bound becomes 0:
    the action runs once and a failure runs ``give_up`` and fails), for ablation
    runs such as ``mmexec campaign --no-recovery``.
    """

    robot: Robot
    clock: Clock
    registry: SkillRegistry = REGISTRY
    emit: Callable[..., None] = drop_event
    world: dict[str, Any] = field(default_factory=dict)
    profile: Mapping[str, Any] = field(default_factory=dict)
    recovery_enabled: bool = True
