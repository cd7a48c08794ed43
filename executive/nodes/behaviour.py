"""The behaviour base of the node library: :class:`MissionNode`, its :class:`Runtime`
and :class:`NodeError` (py_trees' ``behaviour.py``).

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
import uuid
from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any

import py_trees
from py_trees.common import Status

from mmexec.executive.values import MAX_SECONDS, Expr, MissingKey
from mmexec.skills.base import FailureKind

if TYPE_CHECKING:
    from mmexec.executive.context import ExecContext

__all__ = [
    "FAILURE",
    "INVALID",
    "RUNNING",
    "SUCCESS",
    "MissionNode",
    "NodeError",
    "Runtime",
    "clock_seconds",
    "running_tip",
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
    #: why the current activation cannot run (set by ``_start``; see :meth:`_unmet`)
    _bad: str | None = None

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

    def _unmet(self) -> Status:
        """FAILURE of kind precondition with the reason ``_start`` found (``_bad``)."""
        self.rt.fail(self.path, FailureKind.PRECONDITION, str(self._bad))
        return FAILURE

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
    def tip(self) -> py_trees.behaviour.Behaviour | None:
        """py_trees' ``tip()``: the deepest RUNNING descendant, see :func:`running_tip`."""
        return running_tip(self)

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


def clock_seconds(expr: Expr, bb: Mapping[str, Any], what: str, positive: bool) -> float | str:
    """``expr`` evaluated on ``bb`` as clock seconds in 0..MAX_SECONDS (> 0 when
    ``positive``), or the reason it is not such a number. A value from the blackboard
    is checked here as the compiler checks a literal: NaN (``now >= nan`` is never true)
    and inf would never end."""
    try:
        s = expr.eval(bb)
    except MissingKey as e:
        return f"{what}: blackboard key {e.key!r} is not set"
    if isinstance(s, bool) or not isinstance(s, (int, float)) or not 0 <= s <= MAX_SECONDS or (positive and s == 0):
        wanted = f"> 0 and <= {MAX_SECONDS:g}" if positive else f"in 0..{MAX_SECONDS:g}"
        return f"{what}: seconds must be a number {wanted}, got {s!r}"
    return float(s)


def running_tip(node: Any) -> py_trees.behaviour.Behaviour | None:
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
