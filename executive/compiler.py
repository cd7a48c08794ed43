"""Compile mission YAML into py_trees trees, in two phases (BehaviorTree.CPP style).

Public API (used by the runner and the CLI)::

    mission = load_mission(path, registry=REGISTRY)      # parse + validate, or InputError
    mission.path, mission.name, mission.files, mission.sha256
    mission.params            # name -> ParamDecl (type, default, has_default, doc)
    mission.request_fields    # name -> type
    mission.request_defaults  # name -> default, for the optional request fields
    request = mission.validate_request({"item": "3"})    # -> {"item": 3}, or ValueError
    tree = mission.instantiate(ctx, request, params=None) # a fresh MissionTree

:func:`load_mission` reads every file (the mission and what it includes), validates
everything and collects every problem into one
:class:`~mmexec.config.yamlload.InputError` (``FILE:LINE:COL: message`` per line). It
builds no py_trees objects. :meth:`Mission.instantiate` builds a fresh tree for one
request; :class:`MissionTree` ticks it without ever blocking and implements the halt
contract of docs/missions.md.
"""

from __future__ import annotations

import copy
import hashlib
import logging
import math
import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from py_trees.common import Status

import mmexec.trees
from mmexec.config.yamlload import (
    InputError,
    Mark,
    Problem,
    Problems,
    did_you_mean,
    is_within,
    load_yaml_bytes,
    load_yaml_text,
    read_file,
)
from mmexec.executive import nodes as N
from mmexec.executive.context import ExecContext
from mmexec.executive.schema import (
    FAILURE_KEYS,
    RECOVERY_SUFFIXES,
    TYPE_NAMES,
    FileSpec,
    NodeSpec,
    ParamDecl,
    parse_file,
    recovery_key_prefix,
    recovery_writes,
    type_compatible,
)
from mmexec.executive.values import KEY_RE, Const, Expr, format_problem, substitute
from mmexec.skills.base import REGISTRY, SkillRegistry

__all__ = [
    "MAX_INCLUDE_DEPTH",
    "MAX_TREE_NODES",
    "TREES_DIR",
    "Mission",
    "MissionTree",
    "convert_value",
    "include_roots",
    "load_mission",
]

log = logging.getLogger(__name__)

#: how deep includes may nest (a file including a file including ...)
MAX_INCLUDE_DEPTH = 16
#: most nodes a mission may have once includes are expanded
MAX_TREE_NODES = 50_000
#: the project's shipped missions and subtrees (``trees/``): any mission may include them
TREES_DIR = Path(os.path.realpath(next(iter(mmexec.trees.__path__))))


def include_roots(mission: str | Path, extra: Iterable[str | Path] = ()) -> tuple[Path, ...]:
    """The folders a mission's includes may come from: the mission's own folder tree,
    the project's ``trees/`` and ``extra`` (the config's ``roots:``), symlinks resolved."""
    own = Path(os.path.realpath(mission)).parent
    return (own, TREES_DIR, *(Path(os.path.realpath(r)) for r in extra))


def _finite(value: Any, what: str) -> Any:
    """``value``, or ValueError when it is or holds (in a list or mapping) a NaN or an infinity."""
    stack = [value]
    while stack:
        v = stack.pop()
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{what}: expected a finite number, got {value!r}")
        if isinstance(v, dict):
            stack.extend(v.values())
        elif isinstance(v, list):
            stack.extend(v)
    return value


def convert_value(tp: type, value: Any, what: str) -> Any:
    """Convert ``value`` (a typed value, or a command-line string like ``"3"``) to
    declared type ``tp``. Raises ValueError with a one-line message, also for a NaN or
    an infinity (``nan``, ``inf``, ``1e999``, or one inside a list or mapping)."""
    return _finite(_convert(tp, value, what), what)


def _convert(tp: type, value: Any, what: str) -> Any:
    if isinstance(value, str) and tp is not str:
        text = value.strip()
        try:
            if tp is int:
                return int(text)
            if tp is float:
                return float(text)
            if tp is bool:
                low = text.lower()
                if low in ("true", "yes", "on", "1"):
                    return True
                if low in ("false", "no", "off", "0"):
                    return False
                raise ValueError(text)
            if tp in (list, dict):
                try:
                    parsed = load_yaml_text(text, what)
                except InputError as e:
                    raise ValueError(str(e).splitlines()[0]) from None
                if isinstance(parsed, tp):
                    return tp(parsed)
                raise ValueError(text)
        except ValueError:
            raise ValueError(f"{what}: expected {tp.__name__}, got {value!r}") from None
    if tp is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if tp in (int, float) and isinstance(value, bool):
        raise ValueError(f"{what}: expected {tp.__name__}, got {value!r}")
    if not isinstance(value, tp):
        # bad user input, not a programming error: every caller turns ValueError into a
        # located InputError (exit 2), which a TypeError would bypass
        raise ValueError(f"{what}: expected {tp.__name__}, got {value!r}")  # noqa: TRY004
    return value


@dataclass
class Mission:
    """A validated mission: everything needed to build trees, and nothing built yet."""

    path: Path
    name: str
    description: str
    files: list[Path]
    sha256: str
    params: dict[str, ParamDecl]
    request_fields: dict[str, type]
    root_file: FileSpec
    registry: SkillRegistry
    node_count: int = 0
    #: the declared defaults of the optional request fields (a subset of request_fields)
    request_defaults: dict[str, Any] = field(default_factory=dict)
    _hashes: dict[Path, str] = field(default_factory=dict, repr=False)

    def validate_request(self, request: Mapping[str, Any]) -> dict[str, Any]:
        """Check a request against the declared fields and convert CLI strings ("3")
        to the declared types; a field left out takes its declared default (a fresh
        copy). Raises ValueError (one line) on unknown, missing (required) or wrongly
        typed fields."""
        out: dict[str, Any] = {}
        for k in request:
            if k not in self.request_fields:
                known = ", ".join(self.request_fields) or "none"
                raise ValueError(f"request: unknown field {k!r}{did_you_mean(k, self.request_fields)} (mission {self.name} takes: {known})")
        for k, tp in self.request_fields.items():
            if k in request:
                out[k] = convert_value(tp, request[k], f"request field {k!r}")
            elif k in self.request_defaults:
                out[k] = copy.deepcopy(self.request_defaults[k])
            else:
                raise ValueError(f"request: missing field {k!r} ({tp.__name__})")
        return out

    def resolve_params(self, params: Mapping[str, Any] | None) -> dict[str, Any]:
        """Declared defaults overridden by ``params`` (CLI strings converted). ValueError."""
        params = params or {}
        for k in params:
            if k in self.request_fields and k not in self.params:
                raise ValueError(f"params: {k!r} is a request field of mission {self.name}, not a parameter (give it per request: --request {k}=...)")
            if k not in self.params:
                raise ValueError(f"params: unknown parameter {k!r}{did_you_mean(k, self.params)} (mission {self.name} declares: {', '.join(self.params) or 'none'})")
        out: dict[str, Any] = {}
        for k, d in self.params.items():
            if k in params:
                out[k] = convert_value(d.type, params[k], f"parameter {k!r}")
            elif d.has_default:
                out[k] = d.default
            else:
                raise ValueError(f"params: missing required parameter {k!r} ({d.type.__name__})")
        return out

    def instantiate(
        self, ctx: ExecContext | None, request: Mapping[str, Any], params: Mapping[str, Any] | None = None
    ) -> MissionTree:
        """Build a fresh tree for one request. ``ctx`` None builds a tree for display
        only (it cannot be ticked). Raises ValueError on a bad request or parameter."""
        req = self.validate_request(request)
        values = self.resolve_params(params)
        rt = N.Runtime(ctx)
        for k, v in req.items():
            rt.bb[f"request.{k}"] = v
        env: dict[str, Expr] = {k: Const(v) for k, v in values.items()}
        assert self.root_file.tree is not None
        root = _Builder(rt, self.registry).build(self.root_file.tree, env, "", self.root_file.tree.name or self.name)
        return MissionTree(root, rt, self)

    def display_tree(self) -> MissionTree:
        """A tree for rendering only: default (else placeholder) request, default parameters."""
        req = {k: _placeholder(tp) for k, tp in self.request_fields.items() if k not in self.request_defaults}
        params = {k: _placeholder(d.type) for k, d in self.params.items() if not d.has_default}
        return self.instantiate(None, req, params)


def _placeholder(tp: type) -> Any:
    return {int: 0, float: 0.0, str: "", bool: False, list: [], dict: {}}[tp]


class MissionTree:
    """One instantiated mission tree, ticked by the runner.

    ``tick()`` runs one tick and never blocks. ``request_halt()`` starts a multi-tick
    halt of the whole tree: each following ``tick()`` advances the stop and returns
    RUNNING until every skill has stopped, then INVALID (``stopped`` becomes true).
    """

    def __init__(self, root: Any, rt: N.Runtime, mission: Mission) -> None:
        self.root = root
        self.rt = rt
        self.mission = mission
        self.halting = False
        self.stopped = False

    @property
    def status(self) -> Status:
        """The root's status (RUNNING while a halt is in progress, INVALID once stopped)."""
        return self.root.status  # type: ignore[no-any-return]

    def tick(self) -> Status:
        """One tick. Raises :class:`~mmexec.executive.nodes.NodeError` when an
        exception escaped a skill (the message names the node path)."""
        if self.stopped:
            return Status.INVALID
        if self.halting:
            if self.root.halt():
                self.stopped = True
                return Status.INVALID
            return Status.RUNNING
        return self.root.step()  # type: ignore[no-any-return]

    def request_halt(self) -> None:
        """Begin halting the whole tree (every running skill is cancelled exactly once)."""
        if not self.halting:
            self.halting = True
            if self.root.status is not Status.RUNNING:
                self.root.halt()
                self.stopped = True

    def tip_path(self) -> str:
        """Path of the deepest RUNNING node ("" when nothing runs)."""
        tip = N.running_tip(self.root)
        return "" if tip is None else tip.path  # type: ignore[no-any-return]

    def nodes(self) -> list[Any]:
        """Every node, depth-first pre-order."""
        out: list[Any] = []
        stack = [self.root]
        while stack:
            n = stack.pop()
            out.append(n)
            stack.extend(reversed(n.children))
        return out

    def snapshot(self) -> list[tuple[str, str]]:
        """(node path, status name) for every node, pre-order (for replay)."""
        return [(n.path, n.status.name) for n in self.nodes()]

    def add_status_listener(self, fn: Callable[[str, str, str], None]) -> None:
        """Call ``fn(path, old, new)`` (status names) on every node status change."""
        self.rt.listeners.append(fn)

    def blackboard(self) -> dict[str, Any]:
        """A copy of the blackboard (key -> value)."""
        return dict(self.rt.bb)


_DECORATORS: dict[str, Any] = {"invert": N.Invert, "force_success": N.ForceSuccess, "force_failure": N.ForceFailure}


class _Builder:
    """Builds the py_trees nodes of one tree from validated specs (one pass, no copies).

    Each node kind has one method ``b_<kind>(spec, env, path, name)``; the path of a
    node is its parent's path, ``/``, its name. Inside an include that the compiler
    namespaced (a second include of a file with a recovery, see :func:`_recovery_names`)
    the recoveries' bookkeeping keys, and every use of them, get the namespace.
    """

    def __init__(self, rt: N.Runtime, registry: SkillRegistry) -> None:
        self.rt = rt
        self.registry = registry
        #: recovery key prefix as the file being built spells it -> its prefix in the tree
        #: (empty outside namespaced includes)
        self.prefixes: dict[str, str] = {}
        self.kinds: dict[str, Callable[[NodeSpec, Mapping[str, Expr], str, str], Any]] = {
            "sequence": self.b_sequence,
            "fallback": self.b_fallback,
            "parallel": self.b_parallel,
            "if": self.b_if,
            "foreach": self.b_foreach,
            "recovery": self.b_recovery,
            "include": self.b_include,
            "retry": self.b_retry,
            "timeout": self.b_timeout,
            "repeat": self.b_repeat,
            "invert": self.b_simple_decorator,
            "force_success": self.b_simple_decorator,
            "force_failure": self.b_simple_decorator,
            "condition": self.b_condition,
            "wait": self.b_wait,
            "skill": self.b_skill,
        }

    def build(self, spec: NodeSpec, env: Mapping[str, Expr], parent: str, name: str | None = None) -> Any:
        nm = name or spec.name or self.default_name(spec)
        return self.kinds[spec.kind](spec, env, f"{parent}/{nm}" if parent else nm, nm)

    def key(self, key: str) -> str:
        """A blackboard key as the file being built spells it -> the key in the tree."""
        prefix, dot, suffix = key.rpartition(".")
        new = self.prefixes.get(prefix) if dot and suffix in RECOVERY_SUFFIXES else None
        return key if new is None else f"{new}.{suffix}"

    def value(self, expr: Expr, env: Mapping[str, Expr]) -> Expr:
        """``expr`` with the parameters of ``env`` and the keys of the tree."""
        return substitute(expr, env, self.key if self.prefixes else None)

    def b_sequence(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        return N.Sequence(self.rt, path, nm, self.build_children(spec.children, env, path), reactive=spec.opts["reactive"])

    def b_fallback(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        return N.Fallback(self.rt, path, nm, self.build_children(spec.children, env, path), reactive=spec.opts["reactive"])

    def b_parallel(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        kids = self.build_children(spec.children, env, path)
        return N.Parallel(self.rt, path, nm, kids, threshold=min(spec.opts["threshold"], len(kids)))

    def b_if(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        kids = self.build_children(spec.children, env, path)
        return N.IfThenElse(self.rt, path, nm, kids[0], kids[1], kids[2] if spec.opts["has_else"] else None)

    def b_foreach(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        o = spec.opts
        child = self.build(spec.children[0], env, path)
        return N.Foreach(self.rt, path, nm, child, self.value(o["items"], env), self.key(o["key"]))

    def b_recovery(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        kids = self.build_children(spec.children, env, path)
        o = spec.opts
        give_up = kids[2] if o["has_give_up"] else None
        prefix = recovery_key_prefix(spec)
        return N.Recovery(self.rt, path, nm, kids[0], kids[1], give_up, o["max_recoveries"],
                          key_prefix=self.prefixes.get(prefix, prefix))

    def b_include(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        sub: FileSpec = spec.opts["file"]
        bindings = spec.opts["bindings"]
        sub_env: dict[str, Expr] = {}
        for pname, d in sub.params.items():
            sub_env[pname] = self.value(bindings[pname], env) if pname in bindings else Const(d.default)
        assert sub.tree is not None
        ns = spec.opts.get("namespace")
        outer = self.prefixes
        if ns is not None:
            self.prefixes = {**outer, **{p: outer.get(f"{ns}.{p}", f"{ns}.{p}") for p in spec.opts["prefixes"]}}
        child = self.build(sub.tree, sub_env, path)
        self.prefixes = outer
        return N.Subtree(self.rt, path, nm, child)

    def b_retry(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        return N.Retry(self.rt, path, nm, self.build(spec.children[0], env, path), spec.opts["attempts"])

    def b_timeout(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        child = self.build(spec.children[0], env, path)
        return N.Timeout(self.rt, path, nm, child, self.value(spec.opts["seconds"], env))

    def b_repeat(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        return N.Repeat(self.rt, path, nm, self.build(spec.children[0], env, path), spec.opts["times"])

    def b_simple_decorator(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        return _DECORATORS[spec.kind](self.rt, path, nm, self.build(spec.children[0], env, path))

    def b_condition(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        o = spec.opts
        return N.Condition(self.rt, path, nm, self.key(o["key"]), o["op"], self.value(o["value"], env))

    def b_wait(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        return N.Wait(self.rt, path, nm, self.value(spec.opts["seconds"], env))

    def b_skill(self, spec: NodeSpec, env: Mapping[str, Expr], path: str, nm: str) -> Any:
        o = spec.opts
        params = {k: self.value(v, env) for k, v in o["params"].items()}
        outputs = {k: self.key(v) for k, v in o["outputs"].items()} if self.prefixes else o["outputs"]
        return N.SkillLeaf(self.rt, path, nm, o["skill"], params, outputs)

    @staticmethod
    def default_name(spec: NodeSpec) -> str:
        if spec.kind == "skill":
            sk = spec.opts.get("skill")
            if sk is not None:
                return sk.name  # type: ignore[no-any-return]
        return spec.kind

    def build_children(self, specs: list[NodeSpec], env: Mapping[str, Expr], path: str) -> list[Any]:
        seen: dict[str, int] = {}
        out = []
        for s in specs:
            nm = s.name or self.default_name(s)
            k = seen.get(nm, 0) + 1
            seen[nm] = k
            out.append(self.build(s, env, path, nm if k == 1 else f"{nm}#{k}"))
        return out


class _Loader:
    """Reads files, resolves includes (cached, cycle- and depth-checked, and confined to
    ``roots``: an include outside them is never opened, so its content is never shown)."""

    def __init__(self, registry: SkillRegistry, problems: Problems, roots: tuple[Path, ...]) -> None:
        self.registry = registry
        self.p = problems
        self.roots = roots
        self.files: dict[Path, FileSpec | None] = {}
        self.hashes: dict[Path, str] = {}
        self.order: list[Path] = []
        self.stack: list[Path] = []
        self.display: dict[Path, str] = {}

    def load(self, path: Path, display: str, mark: Mark | None, label: str = "") -> FileSpec | None:
        key = Path(os.path.realpath(path))  # a symlink loop stays as it is; reading it reports the loop
        if key in self.stack:
            chain = " -> ".join(self.display[p] for p in self.stack[self.stack.index(key):]) + f" -> {display}"
            assert mark is not None
            self.p.add(mark, f"include cycle: {chain}")
            return None
        if key in self.files:
            return self.files[key]
        if len(self.stack) > MAX_INCLUDE_DEPTH:
            assert mark is not None
            self.p.add(mark, f"includes nest deeper than {MAX_INCLUDE_DEPTH} files")
            return None
        try:
            data = read_file(path)
        except InputError as e:
            # the top file's own problem as it is; an include's at the include line
            self.p.extend(e.problems if mark is None else
                          [Problem(mark, f"include {label or repr(display)}: {p.message}") for p in e.problems])
            self.files[key] = None
            return None
        self.display[key] = display
        self.hashes[key] = hashlib.sha256(data).hexdigest()
        self.order.append(key)
        try:
            doc = load_yaml_bytes(data, display)
        except InputError as e:
            self.p.extend(e.problems)
            self.files[key] = None
            return None
        self.stack.append(key)
        try:
            spec = parse_file(doc, key, display, self.p, self.registry,
                              lambda rel, m, node: self.include(key, display, rel, m))
        finally:
            self.stack.pop()
        self.files[key] = spec
        return spec

    def include(self, base: Path, base_display: str, rel: str, mark: Mark) -> FileSpec | None:
        target = (base.parent / rel)
        shown = str(Path(base_display).parent / rel)
        if not is_within(target, self.roots):
            self.p.add(mark, f"include {rel!r}: outside the folders a mission may include from "
                             f"({', '.join(map(str, self.roots))}); name its folder in the config's 'roots:' to allow it")
            return None
        return self.load(target, shown, mark, repr(rel))


def _recovery_names(
    fs: FileSpec, problems: Problems, memo: dict[Path, dict[str, Mark]], busy: set[Path]
) -> dict[str, Mark]:
    """Key prefix -> mark of every recovery node in ``fs``'s tree once includes are
    expanded (memoised per file).

    An include that brings recoveries already in the tree from the same file (the file
    is included again, directly or through another file) is *namespaced*: its
    recoveries' prefixes become ``<include name>.<prefix>`` (``opts["namespace"]`` and
    ``opts["prefixes"]`` for the builder; the keys are added to ``fs.writes``). The first
    include keeps its prefixes, so a mission that includes such a file once is unchanged.
    A prefix met twice otherwise (two recoveries with one name, in the file or from an
    include, or a namespace already taken) is a problem, recorded where the second one
    appears: at the recovery node, or at the include that brings it in."""
    key = fs.path
    if key in memo:
        return memo[key]
    if key in busy:  # an include cycle, reported by the loader
        return {}
    busy.add(key)
    names: dict[str, Mark] = {}
    items: list[tuple[Mark, NodeSpec]] = [(r.mark, r) for r in fs.recoveries] + [(i.mark, i) for i in fs.includes]
    items.sort(key=lambda it: (it[0].line, it[0].col))
    for mark, spec in items:
        if spec.kind == "recovery":
            prefix = recovery_key_prefix(spec)
            if prefix in names:
                problems.add(mark, f"recovery name {prefix!r} is already used by the recovery at {names[prefix]}; "
                                   f"both would write {_recovery_keys(prefix)}: give each recovery a distinct `name:`")
            else:
                names[prefix] = mark
            continue
        sub = spec.opts.get("file")
        if sub is None:
            continue
        inner = _recovery_names(sub, problems, memo, busy)
        path = spec.opts["path"]
        clashes = [(p, w) for p, w in inner.items() if p in names and names[p] != w]
        for prefix, where in clashes:
            problems.add(mark, f"include {path!r}: its recovery {prefix!r} at {where} is already in the tree "
                               f"(recovery at {names[prefix]}); both would write {_recovery_keys(prefix)}: "
                               f"give each recovery a distinct `name:`")
        again = next(((p, w) for p, w in inner.items() if names.get(p) == w), None)
        if clashes:
            continue
        if again is not None:
            inner = _namespace(fs, spec, inner, again, problems)
        taken = [p for p in inner if p in names]
        if taken:  # one problem per include: its name is taken (also for the others it brings)
            more = f" (and {len(taken) - 1} more of its recoveries)" if len(taken) > 1 else ""
            problems.add(mark, f"include {path!r}: {taken[0]!r} is already in the tree (recovery at {names[taken[0]]})"
                               f"{more}: {_again(again)}; give this include a distinct `name:`")
        for prefix, where in inner.items():
            names.setdefault(prefix, where)
    busy.discard(key)
    memo[key] = names
    return names


def _namespace(
    fs: FileSpec, spec: NodeSpec, inner: dict[str, Mark], again: tuple[str, Mark], problems: Problems
) -> dict[str, Mark]:
    """Put the recoveries an include brings (``inner``) under the include's name: the
    prefixes the tree sees (empty when the name cannot start a key: a problem)."""
    ns = spec.name or ""
    if not KEY_RE.fullmatch(f"{ns}.x"):
        problems.add(spec.mark, f"include {spec.opts['path']!r}: the include's name {ns!r} cannot start a blackboard "
                                f"key: {_again(again)}; give this include a `name:` (a letter or _ first)")
        return {}
    spec.opts["namespace"] = ns
    spec.opts["prefixes"] = tuple(inner)
    for prefix in inner:
        fs.writes.update(recovery_writes(f"{ns}.{prefix}"))
    return {f"{ns}.{prefix}": where for prefix, where in inner.items()}


def _again(again: tuple[str, Mark]) -> str:
    return f"it brings the recovery {again[0]!r} at {again[1]} again, so its recovery keys go under the include's name"


def _recovery_keys(prefix: str) -> str:
    return ", ".join(recovery_writes(prefix))


def load_mission(path: str | Path, registry: SkillRegistry = REGISTRY, roots: Iterable[str | Path] = ()) -> Mission:
    """Parse and validate a mission and every file it includes. Raises InputError
    listing every problem (``FILE:LINE:COL: message``). Includes may come from the
    mission's folder tree, the project's ``trees/`` and ``roots`` (see :func:`include_roots`)."""
    problems = Problems()
    loader = _Loader(registry, problems, include_roots(path, roots))
    p = Path(path)
    top = loader.load(p, str(path), None)
    if top is None or top.tree is None:
        problems.raise_if_any()
        raise InputError.at(Mark(str(path), 1, 1), "mission has no tree")
    specs = [s for s in loader.files.values() if s is not None]
    _recovery_names(top, problems, {}, set())  # first: it adds the keys of namespaced includes to writes
    # every blackboard key read must be written by something in the mission
    writes: dict[str, type | None] = dict(FAILURE_KEYS)
    for s in specs:
        writes.update(s.writes)
    for r, d in top.requests.items():
        writes[f"request.{r}"] = d.type
    known: list[str] | None = None
    for s in specs:
        for key, mark in s.reads:
            if key not in writes:
                if known is None:
                    known = sorted(set(writes) | {k for s in specs for k in s.params})
                hint = did_you_mean(key, known)
                if key.startswith("request."):
                    fields = ", ".join(top.requests) or "none"
                    msg = f"unknown request field {key[8:]!r}{did_you_mean(key[8:], top.requests)} (the mission declares: {fields})"
                else:
                    msg = f"blackboard key {key!r} is read but nothing writes it{hint or ''} (a skill output, request.<field>, a parameter, or recovery bookkeeping)"
                problems.add(mark, msg)
        for key, want, mark, prefix, raw in s.typed_reads:
            have = writes.get(key)
            if key in writes and not type_compatible(want, have):
                problems.add(mark, f"{prefix}, but {raw!r} is {have.__name__ if have else '?'}")
        for key, spec, mark, prefix in s.formatted_reads:
            have = writes.get(key)
            problem = format_problem(spec, have) if have is not None else None
            if have is not None and problem is not None:
                problems.add(mark, f"{prefix}: {problem} (blackboard key {key!r} is {have.__name__})")
        if s is not top:
            for r, d in s.requests.items():
                if r not in top.requests:
                    problems.add(d.mark or s.mark, f"request field {r!r} is needed by {s.path.name} but not declared by the mission {top.name}")
                elif top.requests[r].type is not d.type:
                    problems.add(d.mark or s.mark, f"request field {r!r} is {d.type.__name__} here but {top.requests[r].type.__name__} in the mission {top.name}")
    n = top.tree.size
    if n > MAX_TREE_NODES:
        problems.add(top.tree.mark, f"mission has {n} nodes once includes are expanded, more than {MAX_TREE_NODES}")
    problems.raise_if_any()
    h = hashlib.sha256()
    for f in loader.order:
        h.update(loader.hashes[f].encode())
    return Mission(
        path=p,
        name=top.name,
        description=top.description,
        files=list(loader.order),
        sha256=h.hexdigest(),
        params=dict(top.params),
        request_fields={k: d.type for k, d in top.requests.items()},
        request_defaults={k: d.default for k, d in top.requests.items() if d.has_default},
        root_file=top,
        registry=registry,
        node_count=n,
        _hashes={f: loader.hashes[f] for f in loader.order},
    )


# keep the name list of declared types importable for docs/CLI help
DECLARED_TYPES = tuple(TYPE_NAMES)
