"""The skill contract: declared parameters and outputs, a registry, and a non-blocking run.

A skill is a generator function ``fn(ctx, **params)``:

* each ``yield`` hands control back to the tree (one tick);
* ``return {...}`` is success; the dict holds the declared outputs;
* ``raise SkillFailure(kind, reason)`` is failure;
* cancellation throws :class:`SkillCancelled` into the generator at its current
  ``yield``. The skill starts stopping its hardware (``goal.cancel()``) and may keep
  yielding while it stops (an arm decelerating, a base braking); when it re-raises
  ``SkillCancelled`` (or returns) it has stopped. ``finally`` blocks run either way.

Skills never import py_trees and never sleep: they read time from ``ctx.clock``.

    @skill("open_gripper", params=[Param("width", float, unit="m", default=None)])
    def open_gripper(ctx, width=None):
        goal = ctx.robot.gripper.open() if width is None else ctx.robot.gripper.move(width)
        yield from wait_goal(ctx, goal)
        return {}
"""

from __future__ import annotations

import difflib
import enum
import importlib
import logging
from collections.abc import Callable, Generator, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from mmexec.drivers.interfaces import Clock, Goal, GoalState, Robot

__all__ = [
    "REGISTRY",
    "FailureKind",
    "Output",
    "Param",
    "SkillCancelled",
    "SkillContext",
    "SkillFailure",
    "SkillRegistry",
    "SkillRun",
    "SkillSpec",
    "SkillStatus",
    "run_skill",
    "skill",
    "wait_goal",
]

log = logging.getLogger(__name__)

SkillGen = Generator[None, None, "Mapping[str, Any] | None"]


class FailureKind(enum.Enum):
    """Why a skill failed (pyrobosim's taxonomy)."""

    PRECONDITION = "precondition"      # could not start: missing capability, bad input
    PLANNING = "planning"              # no path / no IK / no plan found
    EXECUTION = "execution"            # the hardware or world did not do what was asked
    POSTCONDITION = "postcondition"    # it ran, but the result is wrong (e.g. nothing held)
    CANCELLED = "cancelled"            # halted from above
    TIMEOUT = "timeout"                # ran out of its own time budget


class SkillFailure(Exception):
    """A skill failed; ``kind`` classifies it, ``reason`` is for people."""

    def __init__(self, kind: FailureKind, reason: str) -> None:
        super().__init__(f"{kind.value}: {reason}")
        self.kind = kind
        self.reason = reason


class SkillCancelled(BaseException):
    """Thrown into a running skill to cancel it (BaseException so broad handlers pass it)."""


class SkillStatus(enum.Enum):
    RUNNING = "running"
    SUCCESS = "success"
    FAILURE = "failure"
    CANCELLING = "cancelling"
    CANCELLED = "cancelled"


class EventSink(Protocol):
    def __call__(self, event: str, **fields: Any) -> None: ...


def _drop_event(event: str, **fields: Any) -> None:
    return None


@dataclass
class SkillContext:
    """What a running skill may use.

    ``robot``: the backend's capabilities; ``clock``: time; ``profile``: the robot profile
    from the config (named poses, approach distances, mounts); ``world``: a dict shared by
    all skills of one run (planning scene, marker estimates, search state), keyed by
    skill-package-chosen names; ``emit``: writes an event to the run's event log.
    """

    robot: Robot
    clock: Clock
    profile: Mapping[str, Any] = field(default_factory=dict)
    world: dict[str, Any] = field(default_factory=dict)
    emit: EventSink = _drop_event
    node_path: str = ""

    @classmethod
    def for_robot(cls, robot: Robot, **kw: Any) -> SkillContext:
        return cls(robot=robot, clock=robot.clock, profile=getattr(robot, "profile", {}), **kw)


# --------------------------------------------------------------------------- declaration

_TYPES: dict[str, type | tuple[type, ...]] = {}


@dataclass(frozen=True)
class Param:
    """A declared skill parameter.

    ``type`` is one of ``float, int, bool, str, list, dict`` (an int is accepted for a
    float). ``unit`` is documentation ("m", "rad", "s", "N"). A parameter with no
    default and ``required=True`` must be given by the mission.
    """

    name: str
    type: type
    unit: str = ""
    default: Any = None
    required: bool = False
    doc: str = ""
    choices: tuple[Any, ...] = ()

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` has this parameter's type (None is accepted when not required)."""
        if value is None:
            return not self.required
        if self.type is float:
            return isinstance(value, (int, float)) and not isinstance(value, bool)
        if self.type is int:
            return isinstance(value, int) and not isinstance(value, bool)
        if self.type is list:
            return isinstance(value, (list, tuple))
        return isinstance(value, self.type)

    def type_name(self) -> str:
        return self.type.__name__ + (f" [{self.unit}]" if self.unit else "")


@dataclass(frozen=True)
class Output:
    """A declared skill output, bound to a blackboard key by the mission."""

    name: str
    type: type = object
    doc: str = ""


@dataclass(frozen=True)
class SkillSpec:
    name: str
    fn: Callable[..., SkillGen]
    params: tuple[Param, ...] = ()
    outputs: tuple[Output, ...] = ()
    doc: str = ""
    needs: tuple[str, ...] = ()  # capabilities used: "base", "arm", "gripper", "camera", "lidar"

    def param(self, name: str) -> Param | None:
        for p in self.params:
            if p.name == name:
                return p
        return None

    def output(self, name: str) -> Output | None:
        for o in self.outputs:
            if o.name == name:
                return o
        return None

    def resolve(self, given: Mapping[str, Any]) -> dict[str, Any]:
        """Fill defaults; raise SkillFailure(PRECONDITION) on unknown, missing or mistyped."""
        out: dict[str, Any] = {}
        for key in given:
            if self.param(key) is None:
                raise SkillFailure(FailureKind.PRECONDITION, f"{self.name}: unknown parameter {key!r}")
        for p in self.params:
            if p.name in given:
                value = given[p.name]
            elif p.required:
                raise SkillFailure(FailureKind.PRECONDITION, f"{self.name}: missing parameter {p.name!r}")
            else:
                value = p.default
            if not p.accepts(value):
                raise SkillFailure(
                    FailureKind.PRECONDITION,
                    f"{self.name}: parameter {p.name!r} expects {p.type_name()}, got {value!r}",
                )
            if p.choices and value not in p.choices:
                raise SkillFailure(
                    FailureKind.PRECONDITION,
                    f"{self.name}: parameter {p.name!r} must be one of {list(p.choices)}",
                )
            out[p.name] = float(value) if p.type is float and value is not None else value
        return out


class SkillRegistry:
    """Maps skill names to specs. One process-wide default: :data:`REGISTRY`."""

    def __init__(self) -> None:
        self._specs: dict[str, SkillSpec] = {}

    def register(self, spec: SkillSpec, *, replace: bool = False) -> SkillSpec:
        if spec.name in self._specs and not replace and self._specs[spec.name].fn is not spec.fn:
            raise ValueError(f"skill {spec.name!r} is already registered")
        self._specs[spec.name] = spec
        return spec

    def get(self, name: str) -> SkillSpec | None:
        return self._specs.get(name)

    def __contains__(self, name: object) -> bool:
        return name in self._specs

    def names(self) -> list[str]:
        return sorted(self._specs)

    def suggest(self, name: str) -> str | None:
        """Closest known name, for "did you mean ...?" messages."""
        hits = difflib.get_close_matches(name, self.names(), n=1, cutoff=0.6)
        return hits[0] if hits else None

    def copy(self) -> SkillRegistry:
        new = SkillRegistry()
        new._specs = dict(self._specs)
        return new

    def load_module(self, module: str) -> None:
        """Import a user module named in a config; its ``@skill`` decorators register
        into :data:`REGISTRY`, and a module-level ``register(registry)`` function, if
        present, is called with this registry."""
        mod = importlib.import_module(module)
        hook = getattr(mod, "register", None)
        if callable(hook):
            hook(self)
        if self is not REGISTRY:
            for name in REGISTRY.names():
                spec = REGISTRY.get(name)
                if spec is not None and spec.fn.__module__ == mod.__name__:
                    self.register(spec, replace=True)


REGISTRY = SkillRegistry()


def skill(
    name: str,
    *,
    params: Iterable[Param] = (),
    outputs: Iterable[Output] = (),
    needs: Iterable[str] = (),
    registry: SkillRegistry | None = None,
) -> Callable[[Callable[..., SkillGen]], Callable[..., SkillGen]]:
    """Declare and register a generator function as a skill (docstring = its doc)."""

    def deco(fn: Callable[..., SkillGen]) -> Callable[..., SkillGen]:
        spec = SkillSpec(
            name=name,
            fn=fn,
            params=tuple(params),
            outputs=tuple(outputs),
            doc=(fn.__doc__ or "").strip(),
            needs=tuple(needs),
        )
        (registry or REGISTRY).register(spec, replace=True)
        fn.spec = spec  # type: ignore[attr-defined]
        return fn

    return deco


# --------------------------------------------------------------------------- running


def wait_goal(ctx: SkillContext, goal: Goal, *, timeout: float | None = None) -> Generator[None, None, Goal]:
    """Yield until ``goal`` finishes; on cancellation cancel the goal and keep yielding
    until the backend reports it stopped, then re-raise. Returns the finished goal;
    raises SkillFailure(EXECUTION) if it failed, SkillFailure(TIMEOUT) past ``timeout``
    clock seconds (after cancelling it and waiting for it to stop)."""
    deadline = None if timeout is None else ctx.clock.now() + timeout
    try:
        while not goal.done():
            if deadline is not None and ctx.clock.now() > deadline:
                goal.cancel()
                while not goal.done():
                    yield
                raise SkillFailure(FailureKind.TIMEOUT, f"{goal.name} took longer than {timeout:g} s")
            yield
    except SkillCancelled:
        goal.cancel()
        while not goal.done():
            try:
                yield
            except SkillCancelled:
                continue  # cancelling already; keep waiting for the device to stop
        raise
    if goal.state is GoalState.FAILED:
        raise SkillFailure(FailureKind.EXECUTION, f"{goal.name}: {goal.reason}")
    if goal.state is GoalState.CANCELLED:
        raise SkillFailure(FailureKind.EXECUTION, f"{goal.name} was cancelled: {goal.reason}")
    return goal


class SkillRun:
    """One execution of a skill, advanced one step per tick. Used by the executive's leaf
    and by tests (see :func:`run_skill`).

    ``start()`` creates the generator, ``tick()`` advances it once, ``cancel()`` throws
    :class:`SkillCancelled` into it (then keep calling ``tick()`` while
    :attr:`status` is CANCELLING). ``failure`` holds the SkillFailure on FAILURE, and
    ``outputs`` the returned dict on SUCCESS.
    """

    def __init__(self, spec: SkillSpec, ctx: SkillContext, params: Mapping[str, Any]) -> None:
        self.spec = spec
        self.ctx = ctx
        self.params = dict(params)
        self.status = SkillStatus.RUNNING
        self.failure: SkillFailure | None = None
        self.outputs: dict[str, Any] = {}
        self._gen: SkillGen | None = None

    def start(self) -> SkillStatus:
        try:
            resolved = self.spec.resolve(self.params)
            for cap in self.spec.needs:
                if getattr(self.ctx.robot, cap, None) is None:
                    raise SkillFailure(
                        FailureKind.PRECONDITION, f"{self.spec.name} needs a {cap}, and this robot has none"
                    )
            self._gen = self.spec.fn(self.ctx, **resolved)
        except SkillFailure as e:
            self._finish_failure(e)
            return self.status
        if not hasattr(self._gen, "send"):
            raise TypeError(f"skill {self.spec.name!r} is not a generator function")
        return self.tick()

    def tick(self) -> SkillStatus:
        if self.status not in (SkillStatus.RUNNING, SkillStatus.CANCELLING) or self._gen is None:
            return self.status
        try:
            next(self._gen)
        except StopIteration as stop:
            if self.status is SkillStatus.CANCELLING:
                self.status = SkillStatus.CANCELLED
            else:
                self._finish_success(stop.value)
        except SkillCancelled:
            self.status = SkillStatus.CANCELLED
        except SkillFailure as e:
            if self.status is SkillStatus.CANCELLING:
                self.status = SkillStatus.CANCELLED
            else:
                self._finish_failure(e)
        return self.status

    def cancel(self) -> SkillStatus:
        """Begin cancellation. Returns CANCELLED when the skill stopped at once,
        CANCELLING when it needs more ticks (keep calling :meth:`tick`)."""
        if self.status is not SkillStatus.RUNNING:
            return self.status
        if self._gen is None:
            self.status = SkillStatus.CANCELLED
            return self.status
        self.status = SkillStatus.CANCELLING
        try:
            self._gen.throw(SkillCancelled())
        except (SkillCancelled, StopIteration, SkillFailure):
            self.status = SkillStatus.CANCELLED
        return self.status

    def kill(self) -> None:
        """Last resort: close the generator now (runs ``finally`` blocks only)."""
        if self._gen is not None:
            self._gen.close()
        if self.status in (SkillStatus.RUNNING, SkillStatus.CANCELLING):
            self.status = SkillStatus.CANCELLED

    def _finish_success(self, value: Any) -> None:
        outputs = dict(value or {})
        for key in outputs:
            if self.spec.output(key) is None:
                self._finish_failure(
                    SkillFailure(FailureKind.POSTCONDITION, f"{self.spec.name} returned undeclared output {key!r}")
                )
                return
        self.outputs = outputs
        self.status = SkillStatus.SUCCESS

    def _finish_failure(self, e: SkillFailure) -> None:
        self.failure = e
        self.status = SkillStatus.FAILURE


def run_skill(
    spec_or_name: SkillSpec | str,
    ctx: SkillContext,
    params: Mapping[str, Any] | None = None,
    *,
    step: Callable[[], None] | None = None,
    max_ticks: int = 100_000,
    registry: SkillRegistry | None = None,
) -> SkillRun:
    """Run a skill to completion outside any tree (tests, scripts). ``step`` is called
    between ticks, typically ``lambda: robot.spin(0.05)``."""
    spec = spec_or_name if isinstance(spec_or_name, SkillSpec) else (registry or REGISTRY).get(spec_or_name)
    if spec is None:
        raise KeyError(f"unknown skill {spec_or_name!r}")
    run = SkillRun(spec, ctx, params or {})
    status = run.start()
    ticks = 0
    while status in (SkillStatus.RUNNING, SkillStatus.CANCELLING):
        if ticks >= max_ticks:
            run.cancel()
            raise RuntimeError(f"skill {spec.name} still running after {max_ticks} ticks")
        if step is not None:
            step()
        status = run.tick()
        ticks += 1
    return run
