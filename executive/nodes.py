"""The node library: control flow, decorators, the skill leaf and the recovery node.

Every node is a py_trees behaviour (so py_trees' display and visitors work on it) that
also implements the **halt contract** of docs/missions.md on top of py_trees' lifecycle:

* :meth:`MissionNode.step` runs one tick of the node and returns its new status. It
  never blocks. When the node is not RUNNING it (re)starts first (``_start``, the
  equivalent of py_trees' ``initialise``).
* :meth:`MissionNode.halt` advances the stopping of a node by one tick and returns
  True once the node and every descendant has stopped (status INVALID). The first call
  halts running children deepest first; a skill leaf cancels its skill exactly once and
  then ticks the cancelling skill on each further call. While stopping, the node's
  status stays RUNNING.
* A composite that preempts a running child (:meth:`MissionNode._preempt`) keeps
  returning RUNNING, ticking only the stopping branch, until it stopped, then returns
  the outcome it had decided (or, for a switch, resumes its own logic).

py_trees' own generator ``tick()`` is kept working (it runs :meth:`step` once), but the
executive calls :meth:`step`/:meth:`halt` directly: no generator per node per tick.

Status changes are reported to the tree's listeners (``path, old, new`` as status
names). Events go to ``ExecContext.emit`` with ``node`` (path) and ``t`` (clock seconds).
"""

from __future__ import annotations

import logging
import operator
import uuid
from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any

import py_trees
from py_trees.common import Status

from mmexec.executive.values import MAX_SECONDS, Const, Expr, MissingKey
from mmexec.skills.base import (
    FailureKind,
    SkillContext,
    SkillFailure,
    SkillRun,
    SkillSpec,
    SkillStatus,
)

if TYPE_CHECKING:
    from mmexec.executive.context import ExecContext

__all__ = [
    "Condition",
    "Fallback",
    "ForceFailure",
    "ForceSuccess",
    "Invert",
    "MissionNode",
    "NodeError",
    "Parallel",
    "Recovery",
    "Repeat",
    "Retry",
    "Runtime",
    "Sequence",
    "SkillLeaf",
    "Subtree",
    "Timeout",
    "Wait",
]

log = logging.getLogger(__name__)

SUCCESS, FAILURE, RUNNING, INVALID = Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.INVALID


class NodeError(RuntimeError):
    """A bug surfaced while ticking (an exception escaped a skill); names the node path."""


class Runtime:
    """State shared by all nodes of one tree: the blackboard, the context, listeners."""

    def __init__(self, ctx: ExecContext | None) -> None:
        self.ctx = ctx
        self.bb: dict[str, Any] = {}
        self.listeners: list[Callable[[str, str, str], None]] = []

    def now(self) -> float:
        if self.ctx is None:
            raise RuntimeError("this tree was built for display only (no ExecContext)")
        return self.ctx.clock.now()

    def emit(self, event: str, node: str, **fields: Any) -> None:
        ctx = self.ctx
        if ctx is not None:
            ctx.emit(event, node=node, t=ctx.clock.now(), **fields)

    def fail(self, path: str, kind: FailureKind, reason: str) -> None:
        """Record a failure on the blackboard (``last_failure*`` keys)."""
        bb = self.bb
        bb["last_failure"] = reason
        bb["last_failure_kind"] = kind.value
        bb["last_failure_node"] = path


class MissionNode:
    """Mixin implementing the executive's tick/halt protocol (see module doc).

    Subclasses implement ``_start()`` (reset per-activation state), ``_update()``
    (one tick's logic, returns a status) and optionally ``_on_halted()``.
    """

    status: Status
    children: list[Any]
    path: str
    rt: Runtime
    name: str
    #: nodes still stopping after this node preempted them (empty: none)
    _stop_list: list[MissionNode] | tuple[()] = ()
    #: running children this node is halting (empty: none)
    _halt_list: list[MissionNode] | tuple[()] = ()
    _pending: Status | None = None
    stopping = False

    def _mn_init(self, rt: Runtime, path: str, name: str, children: list[Any]) -> None:
        """Set the node's state, including every attribute py_trees' constructors set.

        The py_trees constructors are not called: per node they draw a ``uuid4()``,
        build a logger and a tick generator, and re-check each child, which was half
        the cost of instantiating a 1000-node mission. ``id``, ``logger``,
        ``iterator`` and ``qualified_name`` are created on first use instead (the
        display and visitors still find them); a child whose parent is already set is
        refused as py_trees' ``add_child`` does.
        """
        self.rt = rt
        self.path = path
        self.name = name
        self.status = INVALID
        self.parent = None
        self.children = children
        self.blackboards = []
        self.feedback_message = ""
        self.blackbox_level = py_trees.common.BlackBoxLevel.NOT_A_BLACKBOX
        for c in children:
            if c.parent is not None:
                raise RuntimeError(f"{path}: node {c.path!r} already has a parent ({c.parent.path!r})")
            c.parent = self

    # -- py_trees attributes created on first use ------------------------------------
    @property
    def id(self) -> uuid.UUID:
        """py_trees' unique node id (drawn on first use)."""
        nid: uuid.UUID | None = self.__dict__.get("_id")
        if nid is None:
            nid = self.__dict__["_id"] = uuid.uuid4()
        return nid

    @id.setter
    def id(self, value: uuid.UUID) -> None:
        self.__dict__["_id"] = value

    @property
    def logger(self) -> py_trees.logging.Logger:
        """py_trees' per-node logger (built on first use)."""
        lg: py_trees.logging.Logger | None = self.__dict__.get("_logger")
        if lg is None:
            lg = self.__dict__["_logger"] = py_trees.logging.Logger(self.name)
        return lg

    @logger.setter
    def logger(self, value: py_trees.logging.Logger) -> None:
        self.__dict__["_logger"] = value

    @property
    def iterator(self) -> Iterator[py_trees.behaviour.Behaviour]:
        """py_trees' stored tick generator (created on first use; the executive never
        uses it)."""
        it: Iterator[py_trees.behaviour.Behaviour] | None = self.__dict__.get("_iterator")
        if it is None:
            it = self.__dict__["_iterator"] = self.tick()
        return it

    @iterator.setter
    def iterator(self, value: Iterator[py_trees.behaviour.Behaviour]) -> None:
        self.__dict__["_iterator"] = value

    @property
    def qualified_name(self) -> str:
        """py_trees' ``ClassName/name``."""
        return f"{type(self).__qualname__}/{self.name}"

    # -- lifecycle -----------------------------------------------------------------
    def _start(self) -> None:
        """Reset per-activation state (called when ticked while not RUNNING)."""

    def _update(self) -> Status:
        raise TypeError(f"{type(self).__name__} has no tick logic")

    def _on_halted(self) -> None:
        """Called once when a halt completed (before the status becomes INVALID)."""

    def _set(self, new: Status) -> Status:
        old = self.status
        if new is not old:
            self.status = new
            listeners = self.rt.listeners
            if listeners:
                for fn in listeners:
                    fn(self.path, old.name, new.name)
        return new

    def step(self) -> Status:
        """One tick: returns SUCCESS, FAILURE or RUNNING. Never blocks."""
        if self._stop_list:
            self._stop_list = [n for n in self._stop_list if not n.halt()]
            if self._stop_list:
                return RUNNING
            pending = self._pending
            self._pending = None
            if pending is not RUNNING and pending is not None:
                return self._set(pending)
        elif self.status is not RUNNING:
            self._start()
        return self._set(self._update())

    def halt(self) -> bool:
        """Advance this node's stop by one tick; True once stopped (status INVALID)."""
        if self.status is not RUNNING:
            return True
        if not self.stopping:
            self.stopping = True
            self._pending = None
            self._halt_list = [c for c in self.children if c.status is RUNNING]
        if self._halt_list:
            self._halt_list = [c for c in self._halt_list if not c.halt()]
            if self._halt_list:
                return False
        self._stop_list = ()
        self.stopping = False
        self._on_halted()
        self._set(INVALID)
        return True

    def _preempt(self, nodes: list[Any], result: Status) -> Status:
        """Halt the RUNNING ``nodes``; return ``result`` if they stopped at once, else
        RUNNING (the outcome is returned once they have stopped, see :meth:`step`)."""
        still = [n for n in nodes if n.status is RUNNING and not n.halt()]
        if not still:
            return result
        self._stop_list = still
        self._pending = result
        return RUNNING

    # -- py_trees compatibility ----------------------------------------------------
    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        """py_trees' generator tick: one :meth:`step` (children are not yielded)."""
        self.step()
        yield self  # type: ignore[misc]

    def stop(self, new_status: Status = INVALID) -> None:
        """py_trees' synchronous stop: halts until stopped, up to 1000 ticks of stopping
        (prefer :meth:`halt`, which never blocks)."""
        for _ in range(1000):
            if self.halt():
                return
        raise NodeError(f"{self.path}: still stopping after 1000 halt ticks")


# ------------------------------------------------------------------------ composites


class _Chain(MissionNode):
    """Sequence and fallback: children in order while they return ``_advance_on``.

    One tick: tick the current child (the first one when ``reactive``); while it returns
    ``_advance_on`` go on to the next; any other status is the node's status. When
    every child returned ``_advance_on`` that is the node's status too. ``reactive``:
    when an earlier child no longer returns ``_advance_on``, the running later child
    is preempted (halted) before that status is returned.
    """

    _advance_on: Status = SUCCESS
    reactive = False
    _index = 0

    def __init__(self, rt: Runtime, path: str, name: str, children: list[Any], reactive: bool = False) -> None:
        self._mn_init(rt, path, name, children)
        self.memory = not reactive
        self.current_child = None
        self.reactive = reactive

    def _start(self) -> None:
        self._index = 0

    def _update(self) -> Status:
        children = self.children
        advance = self._advance_on
        n = len(children)
        i = 0 if self.reactive else self._index
        while i < n:
            st = children[i].step()
            if st is advance:
                i += 1
                continue
            if self.reactive and self._index > i:
                # an earlier child decided again: the later running child is preempted
                self._index = i
                later = [c for c in children[i + 1 :] if c.status is RUNNING]
                if later:
                    return self._preempt(later, st)
            self._index = i
            return st
        self._index = n
        return advance

    def tip(self) -> py_trees.behaviour.Behaviour | None:
        return _tip(self)


class Sequence(_Chain, py_trees.composites.Sequence):
    """Children in order; SUCCESS when all succeed. ``reactive``: restart from the first
    child every tick, halting a running later child when an earlier one fails (or is
    RUNNING again)."""

    _advance_on = SUCCESS


class Fallback(_Chain, py_trees.composites.Selector):
    """Children in order until one does not fail. ``reactive``: restart from the first
    child every tick; a higher-priority child that is RUNNING or SUCCESS preempts the
    running lower-priority one."""

    _advance_on = FAILURE


class Parallel(MissionNode, py_trees.composites.Parallel):
    """Ticks every unfinished child each tick. Succeeds once ``threshold`` children
    succeeded, fails once that can no longer happen; the children still running are
    halted before the outcome is returned."""

    def __init__(self, rt: Runtime, path: str, name: str, children: list[Any], threshold: int) -> None:
        n = len(children)
        if n == 0 or not 1 <= threshold <= n:
            raise ValueError(f"{path}: parallel success threshold {threshold} outside 1..{n}")
        if threshold == n:
            policy: py_trees.common.ParallelPolicy.Base = py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=True)
        else:
            policy = py_trees.common.ParallelPolicy.SuccessOnOne()
        self._mn_init(rt, path, name, children)
        self.policy = policy
        self.current_child = None
        self.threshold = threshold
        self._done: list[Status] = []

    def _start(self) -> None:
        self._done = [INVALID] * len(self.children)

    def _update(self) -> Status:
        done = self._done
        succ = fail = 0
        for i, child in enumerate(self.children):
            st = done[i]
            if st is INVALID:
                st = child.step()
                if st is not RUNNING:
                    done[i] = st
            if st is SUCCESS:
                succ += 1
            elif st is FAILURE:
                fail += 1
        if succ >= self.threshold:
            return self._preempt(self.children, SUCCESS)
        if fail > len(self.children) - self.threshold:
            return self._preempt(self.children, FAILURE)
        return RUNNING

    def tip(self) -> py_trees.behaviour.Behaviour | None:
        return _tip(self)


# ------------------------------------------------------------------------ decorators


class _Decorator(MissionNode, py_trees.decorators.Decorator):
    def __init__(self, rt: Runtime, path: str, name: str, child: Any) -> None:
        self._mn_init(rt, path, name, [child])
        self.decorated = child
        self.child = child

    def update(self) -> Status:  # py_trees abstract hook; the executive uses _update
        return self.status

    def tip(self) -> py_trees.behaviour.Behaviour | None:
        return _tip(self)


class Subtree(_Decorator):
    """An included file: passes its child's status through (names the include in paths)."""

    def _update(self) -> Status:
        return self.child.step()


class Invert(_Decorator):
    def _update(self) -> Status:
        st = self.child.step()
        if st is SUCCESS:
            return FAILURE
        if st is FAILURE:
            return SUCCESS
        return st


class ForceSuccess(_Decorator):
    def _update(self) -> Status:
        st = self.child.step()
        return SUCCESS if st is FAILURE else st


class ForceFailure(_Decorator):
    def _update(self) -> Status:
        st = self.child.step()
        return FAILURE if st is SUCCESS else st


class Retry(_Decorator):
    """Up to ``attempts`` runs of the child; a failed run is restarted on the next tick."""

    def __init__(self, rt: Runtime, path: str, name: str, child: Any, attempts: int) -> None:
        super().__init__(rt, path, name, child)
        self.attempts = attempts
        self.count = 0

    def _start(self) -> None:
        self.count = 0

    def _update(self) -> Status:
        st = self.child.step()
        if st is FAILURE:
            self.count += 1
            return FAILURE if self.count >= self.attempts else RUNNING
        return st


class Repeat(_Decorator):
    """``times`` successful runs in a row (None: until the child fails)."""

    def __init__(self, rt: Runtime, path: str, name: str, child: Any, times: int | None) -> None:
        super().__init__(rt, path, name, child)
        self.times = times
        self.count = 0

    def _start(self) -> None:
        self.count = 0

    def _update(self) -> Status:
        st = self.child.step()
        if st is SUCCESS:
            self.count += 1
            if self.times is not None and self.count >= self.times:
                return SUCCESS
            return RUNNING
        return st


class Timeout(_Decorator):
    """FAILURE (after halting the child) once ``seconds`` clock seconds passed since start."""

    def __init__(self, rt: Runtime, path: str, name: str, child: Any, seconds: Expr) -> None:
        super().__init__(rt, path, name, child)
        self.seconds = seconds
        self.deadline = 0.0
        self._limit = 0.0
        self._bad: str | None = None

    def _start(self) -> None:
        self._bad = None
        try:
            limit = self.seconds.eval(self.rt.bb)
        except MissingKey as e:
            self._bad = f"timeout: blackboard key {e.key!r} is not set"
            return
        if isinstance(limit, bool) or not isinstance(limit, (int, float)) or limit <= 0:
            self._bad = f"timeout: seconds must be a number > 0, got {limit!r}"
            return
        self._limit = float(limit)
        self.deadline = self.rt.now() + self._limit

    def _update(self) -> Status:
        if self._bad is not None:
            self.rt.fail(self.path, FailureKind.PRECONDITION, self._bad)
            return FAILURE
        if self.rt.now() >= self.deadline:
            return self._expire()
        st = self.child.step()
        if st is RUNNING and self.rt.now() >= self.deadline:
            return self._expire()
        return st

    def _expire(self) -> Status:
        reason = f"{self.path}: timed out after {self._limit:g} s"
        self.rt.fail(self.path, FailureKind.TIMEOUT, reason)
        self.rt.emit("timeout", self.path, seconds=self._limit)
        return self._preempt([self.child], FAILURE)


# ------------------------------------------------------------------------ leaves


class _Leaf(MissionNode, py_trees.behaviour.Behaviour):
    def __init__(self, rt: Runtime, path: str, name: str) -> None:
        self._mn_init(rt, path, name, [])

    def update(self) -> Status:  # py_trees abstract hook; the executive uses _update
        return self.status

    def halt(self) -> bool:
        if self.status is RUNNING:
            self._set(INVALID)
        return True


class Wait(_Leaf):
    """RUNNING until ``seconds`` clock seconds after it started, then SUCCESS."""

    def __init__(self, rt: Runtime, path: str, name: str, seconds: Expr) -> None:
        super().__init__(rt, path, name)
        self.seconds = seconds
        self.deadline = 0.0
        self._bad: str | None = None

    def _start(self) -> None:
        self._bad = None
        try:
            s = self.seconds.eval(self.rt.bb)
        except MissingKey as e:
            self._bad = f"wait: blackboard key {e.key!r} is not set"
            return
        # A value from the blackboard is checked here as the compiler checks a literal:
        # NaN (never reached: ``now >= nan`` is False) and inf would wait forever.
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not 0 <= s <= MAX_SECONDS:
            self._bad = f"wait: seconds must be a number in 0..{MAX_SECONDS:g}, got {s!r}"
            return
        self.deadline = self.rt.now() + float(s)

    def _update(self) -> Status:
        if self._bad is not None:
            self.rt.fail(self.path, FailureKind.PRECONDITION, self._bad)
            return FAILURE
        return SUCCESS if self.rt.now() >= self.deadline else RUNNING


def _in(a: Any, b: Any) -> bool:
    return a in b


def _exists(a: Any, b: Any) -> bool:
    return True


OPS: dict[str, Callable[[Any, Any], bool]] = {
    "==": operator.eq,
    "!=": operator.ne,
    "<": operator.lt,
    "<=": operator.le,
    ">": operator.gt,
    ">=": operator.ge,
    "in": _in,
    "exists": _exists,
}


class Condition(_Leaf):
    """SUCCESS when ``bb[key] <op> value`` holds; FAILURE otherwise (also when the key is
    not set, or the values cannot be compared)."""

    def __init__(self, rt: Runtime, path: str, name: str, key: str, op: str, value: Expr) -> None:
        super().__init__(rt, path, name)
        self.key = key
        self.op = op
        self._fn = OPS[op]
        self.value = value

    def _update(self) -> Status:
        bb = self.rt.bb
        if self.key not in bb:
            return FAILURE
        try:
            ok = self._fn(bb[self.key], self.value.eval(bb))
        except MissingKey:
            return FAILURE
        except TypeError:
            return FAILURE
        return SUCCESS if ok else FAILURE


class SkillLeaf(_Leaf):
    """Runs one skill through :class:`~mmexec.skills.base.SkillRun`.

    Start (not RUNNING when ticked): evaluate the parameters against the blackboard,
    ``SkillRun.start()``. Each further tick: ``SkillRun.tick()``. Halt: ``cancel()``
    once, then ``tick()`` while the skill is CANCELLING. On success the declared outputs
    are written to their blackboard keys; on failure ``last_failure*``. Events:
    ``skill_start``, ``skill_success``, ``skill_failure`` (kind, reason),
    ``skill_cancel`` and ``skill_stopped`` (ticks the stop took).
    """

    def __init__(
        self,
        rt: Runtime,
        path: str,
        name: str,
        spec: SkillSpec,
        params: Mapping[str, Expr],
        outputs: Mapping[str, str],
    ) -> None:
        super().__init__(rt, path, name)
        self.spec = spec
        self.params = dict(params)
        self._static = all(isinstance(v, Const) for v in self.params.values())
        self._static_params = {k: v.value for k, v in self.params.items() if isinstance(v, Const)}
        self.outputs = dict(outputs)
        self.run: SkillRun | None = None
        self.cancels = 0
        self._stop_ticks = 0
        self._sctx: SkillContext | None = None

    def _skill_ctx(self) -> SkillContext:
        if self._sctx is None:
            ctx = self.rt.ctx
            if ctx is None:
                raise RuntimeError("this tree was built for display only (no ExecContext)")
            self._sctx = SkillContext(
                robot=ctx.robot, clock=ctx.clock, profile=ctx.profile, world=ctx.world, emit=ctx.emit,
                node_path=self.path,
            )
        return self._sctx

    def _start(self) -> None:
        self.run = None
        self.cancels = 0

    def _update(self) -> Status:
        run = self.run
        if run is None:
            if self._static:
                params = self._static_params
            else:
                try:
                    params = {k: v.eval(self.rt.bb) for k, v in self.params.items()}
                except MissingKey as e:
                    self.rt.emit("skill_start", self.path, skill=self.spec.name)
                    return self._failed(
                        SkillFailure(
                            FailureKind.PRECONDITION,
                            f"{self.spec.name}: blackboard key {e.key!r} is not set (nothing wrote it yet)",
                        )
                    )
            run = self.run = SkillRun(self.spec, self._skill_ctx(), params)
            self.rt.emit("skill_start", self.path, skill=self.spec.name)
            try:
                st = run.start()
            except Exception as e:
                raise self._bug(e, "") from e
        else:
            try:
                st = run.tick()
            except Exception as e:
                raise self._bug(e, "") from e
        if st is SkillStatus.RUNNING:
            return RUNNING
        if st is SkillStatus.SUCCESS:
            return self._succeeded(run)
        if st is SkillStatus.FAILURE:
            assert run.failure is not None
            return self._failed(run.failure)
        return FAILURE  # CANCELLED without a cancel from us: treat as failure

    def _succeeded(self, run: SkillRun) -> Status:
        bb = self.rt.bb
        outs = run.outputs
        for out, key in self.outputs.items():
            if out not in outs:
                return self._failed(
                    SkillFailure(FailureKind.POSTCONDITION, f"{self.spec.name} did not return output {out!r}")
                )
            bb[key] = outs[out]
        self.rt.emit("skill_success", self.path, skill=self.spec.name, outputs=sorted(outs))
        return SUCCESS

    def _bug(self, e: Exception, when: str) -> NodeError:
        self.status = FAILURE
        self.run = None
        return NodeError(f"{self.path}: skill {self.spec.name!r} raised {type(e).__name__}{when}: {e}")

    def _failed(self, failure: SkillFailure) -> Status:
        self.rt.fail(self.path, failure.kind, failure.reason)
        self.rt.emit("skill_failure", self.path, skill=self.spec.name, kind=failure.kind.value, reason=failure.reason)
        return FAILURE

    def halt(self) -> bool:
        if self.status is not RUNNING:
            return True
        run = self.run
        try:
            if run is None:
                done = True
            elif self.cancels == 0:
                self.cancels = 1
                self._stop_ticks = 0
                self.rt.emit("skill_cancel", self.path, skill=self.spec.name)
                done = run.cancel() is not SkillStatus.CANCELLING
            else:
                self._stop_ticks += 1
                done = run.tick() is not SkillStatus.CANCELLING
        except Exception as e:
            raise self._bug(e, " while stopping") from e
        if not done:
            return False
        if run is not None:
            self.rt.emit("skill_stopped", self.path, skill=self.spec.name, ticks=self._stop_ticks)
        self.run = None
        self._set(INVALID)
        return True


# ------------------------------------------------------------------------ recovery

_ACTION, _RECOVERY, _GIVE_UP = 0, 1, 2


class Recovery(MissionNode, py_trees.composites.Composite):
    """Nav2-style recovery node with a give-up branch (docs/missions.md).

    Children: ``[action, recovery]`` or ``[action, recovery, give_up]``. The
    bookkeeping is written to the blackboard under ``<key_prefix>.attempts``,
    ``.recoveries``, ``.last_failure`` and ``.outcome`` (``key_prefix`` defaults to
    ``name``). When the tree's :class:`~mmexec.executive.context.ExecContext` has
    ``recovery_enabled`` false, the bound is 0 for every activation: the action runs
    once and a failure goes straight to ``give_up``.
    """

    def __init__(
        self,
        rt: Runtime,
        path: str,
        name: str,
        action: Any,
        recovery: Any,
        give_up: Any | None,
        max_recoveries: int,
        key_prefix: str | None = None,
    ) -> None:
        children = [action, recovery] + ([give_up] if give_up is not None else [])
        self._mn_init(rt, path, name, children)
        self.current_child = None
        self.action, self.recovery, self.give_up = action, recovery, give_up
        self.max_recoveries = max_recoveries
        #: the bound of the current activation (0 when recovery is disabled)
        self.bound = max_recoveries
        self.recoveries = 0
        self.attempts = 0
        self.phase = _ACTION
        self._outcome = "running"
        prefix = name if key_prefix is None else key_prefix
        self.k_attempts = f"{prefix}.attempts"
        self.k_recoveries = f"{prefix}.recoveries"
        self.k_failure = f"{prefix}.last_failure"
        self.k_outcome = f"{prefix}.outcome"

    def update(self) -> Status:  # py_trees abstract hook; the executive uses _update
        return self.status

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        return MissionNode.tick(self)

    def stop(self, new_status: Status = INVALID) -> None:
        MissionNode.stop(self, new_status)

    def tip(self) -> py_trees.behaviour.Behaviour | None:
        return _tip(self)

    def _record(self) -> None:
        bb = self.rt.bb
        bb[self.k_attempts] = self.attempts
        bb[self.k_recoveries] = self.recoveries

    def _start(self) -> None:
        ctx = self.rt.ctx
        self.bound = self.max_recoveries if ctx is None or ctx.recovery_enabled else 0
        self.recoveries = 0
        self.attempts = 0
        self.phase = _ACTION
        bb = self.rt.bb
        bb[self.k_outcome] = "running"
        bb[self.k_failure] = ""
        self._record()

    def _update(self) -> Status:
        rt = self.rt
        if self.phase == _ACTION:
            if self.action.status is not RUNNING:
                self.attempts += 1
                self._record()
            st = self.action.step()
            if st is RUNNING:
                return RUNNING
            if st is SUCCESS:
                rt.bb[self.k_outcome] = "success"
                rt.emit("recovery_success", self.path, attempts=self.attempts, recoveries=self.recoveries)
                self.recoveries = 0
                return SUCCESS
            bb = rt.bb
            node = bb.get("last_failure_node", "")
            if isinstance(node, str) and (node == self.action.path or node.startswith(self.action.path + "/")):
                reason = str(bb.get("last_failure", ""))
            else:
                reason = f"{self.action.path} failed"
            bb[self.k_failure] = reason
            if self.recoveries >= self.bound:
                rt.emit("recovery_give_up", self.path, attempts=self.attempts, recoveries=self.recoveries, reason=reason,
                        max_recoveries=self.bound)
                return self._begin_give_up("gave_up")
            self.recoveries += 1
            self._record()
            rt.emit("recovery_attempt", self.path, attempt=self.recoveries, reason=reason,
                    max_recoveries=self.bound)
            self.phase = _RECOVERY
        if self.phase == _RECOVERY:
            st = self.recovery.step()
            if st is RUNNING:
                return RUNNING
            if st is SUCCESS:
                self.phase = _ACTION
                return RUNNING
            rt.emit("recovery_failed", self.path, attempts=self.attempts, recoveries=self.recoveries,
                    reason=str(rt.bb.get("last_failure", "")))
            return self._begin_give_up("recovery_failed")
        return self._tick_give_up()

    def _begin_give_up(self, outcome: str) -> Status:
        self._outcome = outcome
        self.phase = _GIVE_UP
        return self._tick_give_up()

    def _tick_give_up(self) -> Status:
        if self.give_up is not None:
            st = self.give_up.step()
            if st is RUNNING:
                return RUNNING
        self.rt.bb[self.k_outcome] = self._outcome
        self.recoveries = 0
        return FAILURE

    def _on_halted(self) -> None:
        self.recoveries = 0
        self.rt.bb[self.k_outcome] = "halted"


def _tip(node: Any) -> py_trees.behaviour.Behaviour | None:
    """Deepest RUNNING descendant (py_trees' ``tip()`` semantics for our nodes)."""
    if node.status is not RUNNING:
        return None
    cur = node
    while True:
        nxt = None
        for c in cur.children:
            if c.status is RUNNING:
                nxt = c
                break
        if nxt is None:
            return cur  # type: ignore[no-any-return]
        cur = nxt
