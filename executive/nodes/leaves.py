"""Leaves (py_trees' ``behaviours.py``): :class:`Wait`, :class:`Condition` and
:class:`SkillLeaf`, the leaf that runs one skill."""

from __future__ import annotations

from collections.abc import Mapping

import py_trees
from py_trees.common import Status

from mmexec.executive.nodes.behaviour import (
    FAILURE,
    INVALID,
    RUNNING,
    SUCCESS,
    MissionNode,
    NodeError,
    Runtime,
    clock_seconds,
)
from mmexec.executive.values import OPS, Const, EvalError, Expr
from mmexec.skills.base import (
    FailureKind,
    SkillContext,
    SkillFailure,
    SkillRun,
    SkillSpec,
    SkillStatus,
)

__all__ = ["Condition", "SkillLeaf", "Wait"]


class _Leaf(MissionNode, py_trees.behaviour.Behaviour):
    def __init__(self, rt: Runtime, path: str, name: str) -> None:
        self._mn_init(rt, path, name, [])

    def update(self) -> Status:  # py_trees abstract hook; the executive uses _update
        return self.status

    #: a leaf keeps py_trees' ``tip()`` (itself unless INVALID), not MissionNode's
    tip = py_trees.behaviour.Behaviour.tip

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

    def _start(self) -> None:
        s = clock_seconds(self.seconds, self.rt.bb, "wait", positive=False)
        self._bad = s if isinstance(s, str) else None
        if isinstance(s, float):
            self.deadline = self.rt.now() + s

    def _update(self) -> Status:
        if self._bad is not None:
            return self._unmet()
        return SUCCESS if self.rt.now() >= self.deadline else RUNNING


class Condition(_Leaf):
    """SUCCESS when ``bb[key] <op> value`` holds; FAILURE otherwise (also when the key is
    not set, a value cannot be formatted, or the values cannot be compared)."""

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
        except (EvalError, TypeError):
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
                except EvalError as e:
                    self.rt.emit("skill_start", self.path, skill=self.spec.name)
                    return self._failed(SkillFailure(FailureKind.PRECONDITION, f"{self.spec.name}: {e.reason}"))
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
