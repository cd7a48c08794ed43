"""Mission file schema: parse and validate loaded YAML into node specs (no py_trees).

:func:`parse_file` turns one file's loaded YAML (from
:func:`mmexec.config.yamlload.load_yaml_bytes`) into a :class:`FileSpec`, recording
every problem with its ``FILE:LINE:COL`` in a shared
:class:`~mmexec.config.yamlload.Problems`. Includes are resolved through a callback so
the compiler controls file reading, caching, cycle and depth checks. The language is
documented in docs/missions.md.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mmexec.config.yamlload import Mark, Problems, YDict, YList, did_you_mean, refuse_nonfinite
from mmexec.executive.values import (
    KEY_RE,
    MAX_SECONDS,
    OPS,
    Const,
    Expr,
    Format,
    ParamRef,
    Ref,
    Template,
    ValueSyntaxError,
    format_problem,
    parse_value,
)
from mmexec.skills.base import Param, SkillRegistry, SkillSpec

__all__ = [
    "COMPOSITES",
    "DECORATORS",
    "MAX_COUNT",
    "MAX_SECONDS",
    "NODE_TYPES",
    "SIZE_CAP",
    "TYPE_NAMES",
    "FileSpec",
    "NodeSpec",
    "ParamDecl",
    "parse_file",
    "recovery_key_prefix",
    "recovery_writes",
]

COMPOSITES = ("sequence", "fallback", "parallel", "if")
DECORATORS = ("retry", "timeout", "repeat", "invert", "force_success", "force_failure", "foreach")
LEAVES = ("condition", "wait", "skill")
NODE_TYPES = COMPOSITES + DECORATORS + LEAVES + ("include", "recovery")
_NODE_TYPE_SET = frozenset(NODE_TYPES)

#: options each node type accepts besides its type key and ``name``
OPTIONS: dict[str, tuple[str, ...]] = {
    "sequence": ("reactive",),
    "fallback": ("reactive",),
    "parallel": ("policy",),
    "if": ("then", "else"),
    "retry": ("attempts",),
    "timeout": ("seconds",),
    "repeat": ("times", "until_failure"),
    "invert": (),
    "force_success": (),
    "force_failure": (),
    "foreach": ("as", "do"),
    "condition": ("op", "value"),
    "wait": (),
    "skill": ("params", "outputs"),
    "include": ("params",),
    "recovery": (),
}
#: every key a node of each type accepts (type key, options, ``name``)
_NODE_KEYS: dict[str, frozenset[str]] = {k: frozenset((k, "name", *v)) for k, v in OPTIONS.items()}
RECOVERY_KEYS = ("action", "recovery", "max_recoveries", "give_up")
TOP_KEYS = ("mission", "description", "params", "requests", "tree")
DECL_KEYS = ("type", "default", "doc")
TYPE_NAMES: dict[str, type] = {"int": int, "float": float, "str": str, "bool": bool, "list": list, "dict": dict}
NAME_RE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_\-]*")
#: recovery bookkeeping key suffixes
RECOVERY_SUFFIXES = ("attempts", "recoveries", "last_failure", "outcome")
FAILURE_KEYS = {"last_failure": str, "last_failure_kind": str, "last_failure_node": str}
#: node counts above this are reported as this (a bound, not a count, for include bombs)
SIZE_CAP = 1 << 40
#: most attempts a retry, repetitions a repeat, or recoveries a recovery node may have
MAX_COUNT = 1000


def recovery_key_prefix(spec: NodeSpec) -> str:
    """The blackboard key prefix of a recovery node: its ``name``, else ``recovery``."""
    return spec.name or "recovery"


def recovery_writes(prefix: str) -> dict[str, type]:
    """The bookkeeping keys a recovery node with key prefix ``prefix`` writes, with their types."""
    return {f"{prefix}.{suffix}": str if suffix in ("last_failure", "outcome") else int for suffix in RECOVERY_SUFFIXES}


@dataclass
class ParamDecl:
    """A declared mission parameter or request field."""

    name: str
    type: type
    default: Any = None
    has_default: bool = False
    doc: str = ""
    mark: Mark | None = None


@dataclass
class NodeSpec:
    """One validated node. ``kind`` is a NODE_TYPES entry; ``opts`` holds the parsed
    options (see the compiler for each kind's keys)."""

    kind: str
    mark: Mark
    name: str | None = None
    children: list[NodeSpec] = field(default_factory=list)
    opts: dict[str, Any] = field(default_factory=dict)
    #: nodes in this subtree once includes are expanded (capped at SIZE_CAP)
    size: int = 1


@dataclass
class FileSpec:
    """One parsed mission file."""

    path: Path
    name: str
    description: str
    params: dict[str, ParamDecl]
    requests: dict[str, ParamDecl]
    tree: NodeSpec | None
    mark: Mark
    #: blackboard keys read, with where: (key, mark)
    reads: list[tuple[str, Mark]] = field(default_factory=list)
    #: blackboard keys written by skill outputs / recovery nodes: key -> (type or None)
    writes: dict[str, type | None] = field(default_factory=dict)
    #: included files, by include node
    includes: list[NodeSpec] = field(default_factory=list)
    #: blackboard reads whose type must fit a skill parameter: (key, type, mark, message prefix, raw)
    typed_reads: list[tuple[str, type, Mark, str, Any]] = field(default_factory=list)
    #: recovery nodes of this file (not of the files it includes), innermost first
    recoveries: list[NodeSpec] = field(default_factory=list)
    #: blackboard reads with a format spec, checked once every write's type is known:
    #: (key, spec, mark, message prefix)
    formatted_reads: list[tuple[str, str, Mark, str]] = field(default_factory=list)


def _tname(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    return type(value).__name__


def _short(value: Any) -> str:
    """``repr(value)``, shortened to its first 40 characters (an integer may have thousands of digits)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:40] + f"... ({len(text)} characters)"


def accepts(tp: type, value: Any) -> bool:
    """Whether ``value`` has declared type ``tp`` (an int is accepted for a float)."""
    return Param("_", tp, required=True).accepts(value)


def type_compatible(want: type, have: type | None) -> bool:
    """Whether a value statically known to be of type ``have`` fits ``want``."""
    if have is None or have is object or want is object:
        return True
    if want is float:
        return have in (int, float)
    return have is want


class _Parser:
    def __init__(
        self,
        path: Path,
        display: str,
        problems: Problems,
        registry: SkillRegistry,
        include: Callable[[str, Mark, NodeSpec], FileSpec | None],
    ) -> None:
        self.path = path
        self.display = display
        self.p = problems
        self.registry = registry
        self.include = include
        self.params: dict[str, ParamDecl] = {}
        self.reads: list[tuple[str, Mark]] = []
        self.writes: dict[str, type | None] = {}
        self.includes: list[NodeSpec] = []
        self.recoveries: list[NodeSpec] = []
        self.typed_reads: list[tuple[str, type, Mark, str, Any]] = []
        #: the keys the enclosing foreach nodes bind, with where (innermost last)
        self.bound: list[tuple[str, Mark]] = []
        self.formatted_reads: list[tuple[str, str, Mark, str]] = []
        self.handlers: dict[str, Callable[[NodeSpec, YDict, Any, Mark, int], None]] = {
            k: getattr(self, "n_" + k) for k in NODE_TYPES
        }

    def err(self, mark: Mark, msg: str) -> None:
        self.p.add(mark, msg)

    # -- top level -------------------------------------------------------------------
    def file(self, doc: Any) -> FileSpec:
        top = Mark(self.display, 1, 1)
        name = self.path.stem
        desc = ""
        if not isinstance(doc, YDict):
            self.err(getattr(doc, "mark", top), f"a mission file is a mapping with a 'tree' key, got {_tname(doc)}")
            return FileSpec(self.path, name, desc, {}, {}, None, top)
        for key in doc:
            if key not in TOP_KEYS:
                self.err(doc.key_mark(key), f"unknown top-level key {key!r}" + (
                    did_you_mean(key, TOP_KEYS) or f" (expected one of: {', '.join(TOP_KEYS)})"))
        if "mission" in doc:
            if isinstance(doc["mission"], str) and NAME_RE.fullmatch(doc["mission"]):
                name = doc["mission"]
            else:
                self.err(doc.value_mark("mission"), f"mission: expected a name (letters, digits, _ and -), got {doc['mission']!r}")
        if "description" in doc:
            if isinstance(doc["description"], str):
                desc = doc["description"]
            else:
                self.err(doc.value_mark("description"), f"description: expected a string, got {_tname(doc['description'])}")
        self.params = self.decls(doc, "params")
        requests = self.decls(doc, "requests")
        tree: NodeSpec | None = None
        if "tree" not in doc:
            self.err(doc.mark, "missing required key 'tree' (the root node)")
        else:
            tree = self.node(doc["tree"], doc.value_mark("tree"), 0)
        for r in requests:
            self.writes[f"request.{r}"] = requests[r].type
        return FileSpec(self.path, name, desc, self.params, requests, tree, doc.mark, self.reads, self.writes,
                        self.includes, self.typed_reads, self.recoveries, self.formatted_reads)

    def decls(self, doc: YDict, key: str) -> dict[str, ParamDecl]:
        """The ``params:`` or ``requests:`` section: name -> declaration. A ``default`` must
        be finite and of the declared type (a request field with one is optional)."""
        out: dict[str, ParamDecl] = {}
        if key not in doc or doc[key] is None:
            return out
        section = doc[key]
        if not isinstance(section, YDict):
            self.err(doc.value_mark(key), f"{key}: expected a mapping of name -> {{type: ...}}, got {_tname(section)}")
            return out
        for name, d in section.items():
            km, vm = section.key_mark(name), section.value_mark(name)
            if not KEY_RE.fullmatch(name) or "." in name:
                self.err(km, f"{key}: bad name {name!r} (letters, digits, _ and -)")
                continue
            if isinstance(d, str) and d in TYPE_NAMES:
                out[name] = ParamDecl(name, TYPE_NAMES[d], mark=km)
                continue
            if not isinstance(d, YDict):
                self.err(vm, f"{key}.{name}: expected {{type: ...}} or a type name, got {d!r}")
                continue
            ok = True
            for k in d:
                if k not in DECL_KEYS:
                    hint = did_you_mean(k, DECL_KEYS)
                    self.err(d.key_mark(k), f"{key}.{name}: unknown key {k!r}{hint or ' (expected one of: ' + ', '.join(DECL_KEYS) + ')'}")
                    ok = False
            tp_name = d.get("type")
            if "type" not in d:
                self.err(d.mark, f"{key}.{name}: missing required key 'type' (one of: {', '.join(TYPE_NAMES)})")
                continue
            if not isinstance(tp_name, str) or tp_name not in TYPE_NAMES:
                self.err(d.value_mark("type"), f"{key}.{name}: unknown type {tp_name!r}" + (
                    did_you_mean(str(tp_name), TYPE_NAMES) or f" (expected one of: {', '.join(TYPE_NAMES)})"))
                continue
            tp = TYPE_NAMES[tp_name]
            doc_s = d.get("doc", "")
            if not isinstance(doc_s, str):
                self.err(d.value_mark("doc"), f"{key}.{name}.doc: expected a string, got {_tname(doc_s)}")
            decl = ParamDecl(name, tp, doc=str(doc_s), mark=km)
            if "default" in d:
                decl.default, decl.has_default = d["default"], True
                before = len(self.p)
                refuse_nonfinite(d["default"], d.value_mark("default"), f"{key}.{name}.default", self.p)
                if len(self.p) == before and not accepts(tp, d["default"]):
                    self.err(d.value_mark("default"), f"{key}.{name}: default {d['default']!r} is not {tp_name}")
                if len(self.p) > before:  # keep the declaration: its uses are not also problems
                    decl.default, decl.has_default = None, False
            if ok:
                out[name] = decl
        return out

    # -- values --------------------------------------------------------------------
    def is_param(self, name: str) -> bool:
        return name in self.params

    def value(self, raw: Any, mark: Mark, what: str) -> Expr | None:
        """Parse a mission value; None (a problem recorded) when it is malformed or holds
        a NaN or an infinity anywhere (no mission value may be non-finite)."""
        before = len(self.p)
        refuse_nonfinite(raw, mark, what, self.p)
        if len(self.p) > before:
            return None
        try:
            e = parse_value(raw, self.is_param)
        except ValueSyntaxError as ex:
            self.err(mark, f"{what}: {ex}")
            return None
        for key in e.reads():
            self.reads.append((key, mark))
        for f in e.formats():
            self.check_format(f, mark, what)
        return e

    def check_format(self, f: Format, mark: Mark, what: str) -> None:
        """Check a ``{key:spec}`` against the key's type: a parameter's now, a blackboard
        key's once the compiler knows every write (a type known only at run time is
        checked by the node, which fails with kind precondition)."""
        inner = f.expr
        if isinstance(inner, Ref):
            self.formatted_reads.append((inner.key, f.spec, mark, what))
            return
        d = self.params.get(inner.name) if isinstance(inner, ParamRef) else None
        problem = format_problem(f.spec, d.type) if d is not None else None
        if d is not None and problem is not None:
            self.err(mark, f"{what}: {problem} (parameter {d.name!r} is {d.type.__name__})")

    def static_type(self, e: Expr) -> type | None:
        """Type of ``e`` known before run time, or None."""
        if isinstance(e, Const):
            return type(e.value) if e.value is not None else None
        if isinstance(e, ParamRef):
            d = self.params.get(e.name)
            return d.type if d else None
        if isinstance(e, (Template, Format)):
            return str
        return None

    # -- nodes ---------------------------------------------------------------------
    def node(self, raw: Any, mark: Mark, depth: int) -> NodeSpec | None:
        if not isinstance(raw, YDict):
            if isinstance(raw, str) and raw in NODE_TYPES:
                self.err(mark, f"node {raw!r} needs an argument (e.g. '{raw}: ...')")
            else:
                self.err(mark, f"expected a node (a mapping with one of: {', '.join(NODE_TYPES)}), got {_tname(raw)}")
            return None
        kinds = [k for k in raw if k in _NODE_TYPE_SET]
        if not kinds:
            unknown = [k for k in raw if k != "name"]
            for k in unknown:
                hint = did_you_mean(k, NODE_TYPES)
                if hint or len(unknown) == 1:
                    self.err(raw.key_mark(k), f"unknown node type {k!r}" + (hint or f" (expected one of: {', '.join(NODE_TYPES)})"))
                    return None
            self.err(raw.mark, f"node has no type: expected one of: {', '.join(NODE_TYPES)}")
            return None
        if len(kinds) > 1:
            self.err(raw.key_mark(kinds[1]), f"node has several types ({', '.join(repr(k) for k in kinds)}); one node per mapping, put them in a sequence")
            return None
        kind = kinds[0]
        if not _NODE_KEYS[kind].issuperset(raw):
            allowed = OPTIONS[kind] + ("name",)
            for k in raw:
                if k != kind and k not in allowed:
                    self.err(raw.key_mark(k), f"unknown key {k!r} for {kind}" + (
                        did_you_mean(k, allowed) or (f" (expected one of: {', '.join(allowed)})" if len(allowed) > 1 else " (it takes only 'name')")))
        spec = NodeSpec(kind, raw.key_mark(kind))
        if "name" in raw:
            nm = raw["name"]
            if isinstance(nm, str) and NAME_RE.fullmatch(nm):
                spec.name = nm
            else:
                self.err(raw.value_mark("name"), f"name: expected a node name (letters, digits, _ and -), got {nm!r}")
        self.handlers[kind](spec, raw, raw[kind], raw.value_mark(kind), depth)
        size = 1
        for c in spec.children:
            size += c.size
        if kind == "include":
            sub = spec.opts.get("file")
            if sub is not None and sub.tree is not None:
                size += sub.tree.size
        spec.size = min(size, SIZE_CAP)
        return spec

    def child(self, arg: Any, am: Mark, depth: int, kind: str) -> NodeSpec | None:
        if arg is None:
            self.err(am, f"{kind}: expected a child node, got nothing")
            return None
        if isinstance(arg, YList):
            self.err(am, f"{kind}: expected one child node, got a list (wrap the list in a sequence)")
            return None
        return self.node(arg, am, depth + 1)

    def children(self, spec: NodeSpec, arg: Any, am: Mark, depth: int) -> None:
        if not isinstance(arg, YList) or not arg:
            self.err(am, f"{spec.kind}: expected a non-empty list of child nodes, got {_tname(arg) if arg != [] else 'an empty list'}")
            return
        for i, item in enumerate(arg):
            c = self.node(item, arg.item_mark(i), depth + 1)
            if c is not None:
                spec.children.append(c)

    def flag(self, spec: NodeSpec, raw: YDict, key: str, default: bool) -> bool:
        if key not in raw:
            return default
        v = raw[key]
        if not isinstance(v, bool):
            self.err(raw.value_mark(key), f"{spec.kind}.{key}: expected true or false, got {v!r}")
            return default
        return v

    def count(self, spec: NodeSpec, raw: YDict, key: str, minimum: int, required: bool) -> int | None:
        if key not in raw:
            if required:
                self.err(spec.mark, f"{spec.kind}: missing required key {key!r} (an integer >= {minimum})")
            return None
        return self.bounded_int(raw[key], raw.value_mark(key), f"{spec.kind}.{key}", minimum)

    def bounded_int(self, v: Any, mark: Mark, what: str, minimum: int) -> int | None:
        """``v`` when it is an integer in ``minimum..MAX_COUNT``, else None (a problem recorded)."""
        if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
            self.err(mark, f"{what}: expected an integer >= {minimum}, got {_short(v)}")
            return None
        if v > MAX_COUNT:
            self.err(mark, f"{what}: {_short(v)} is more than the limit of {MAX_COUNT}")
            return None
        return v

    def seconds(self, spec: NodeSpec, raw: Any, mark: Mark, what: str, positive: bool) -> Expr | None:
        if isinstance(raw, (int, float)) and not isinstance(raw, bool):
            try:
                secs = float(raw)
            except OverflowError:  # an integer too large for a float
                secs = math.inf
            if not math.isfinite(secs) or secs < 0 or (positive and secs == 0):
                got = "an integer too large for a float" if isinstance(raw, int) and secs == math.inf else repr(raw)
                self.err(mark, f"{what}: expected a number of seconds {'> 0' if positive else '>= 0'}, got {got}")
                return None
            if secs > MAX_SECONDS:
                self.err(mark, f"{what}: {secs:g} s is more than the limit of {MAX_SECONDS:g} s")
                return None
            return Const(secs)
        if isinstance(raw, str) and "{" in raw:
            e = self.value(raw, mark, what)
            if e is not None:
                t = self.static_type(e)
                if isinstance(e, Template) or not type_compatible(float, t):
                    self.err(mark, f"{what}: expected a number of seconds, got {raw!r} ({t.__name__ if t else 'unknown'})")
                    return None
            return e
        self.err(mark, f"{what}: expected a number of seconds or a reference like '{{timeout}}', got {raw!r}")
        return None

    def n_sequence(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        self.children(spec, arg, am, depth)
        spec.opts["reactive"] = self.flag(spec, raw, "reactive", False)

    n_fallback = n_sequence

    def n_parallel(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        self.children(spec, arg, am, depth)
        n = len(spec.children)
        pol = raw.get("policy", "all")
        threshold: int | None = None
        if pol == "all":
            threshold = max(n, 1)
        elif pol == "one":
            threshold = 1
        elif isinstance(pol, int) and not isinstance(pol, bool):
            if 1 <= pol <= max(n, 1):
                threshold = pol
            else:
                self.err(raw.value_mark("policy"), f"parallel.policy: {pol} is outside 1..{n} (the number of children)")
        else:
            self.err(raw.value_mark("policy"), f"parallel.policy: expected 'all', 'one' or a number of children, got {pol!r}"
                     + did_you_mean(str(pol), ("all", "one")))
        spec.opts["threshold"] = threshold or 1

    def _deco(self, spec: NodeSpec, arg: Any, am: Mark, depth: int) -> None:
        c = self.child(arg, am, depth, spec.kind)
        if c is not None:
            spec.children.append(c)

    def n_retry(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        self._deco(spec, arg, am, depth)
        spec.opts["attempts"] = self.count(spec, raw, "attempts", 1, True) or 1

    def n_timeout(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        self._deco(spec, arg, am, depth)
        if "seconds" not in raw:
            self.err(spec.mark, "timeout: missing required key 'seconds' (clock seconds > 0)")
        else:
            spec.opts["seconds"] = self.seconds(spec, raw["seconds"], raw.value_mark("seconds"), "timeout.seconds", True)

    def n_repeat(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        self._deco(spec, arg, am, depth)
        times = self.count(spec, raw, "times", 1, False)
        until = self.flag(spec, raw, "until_failure", False)
        if "times" in raw and until:
            self.err(spec.mark, "repeat: give either 'times' or 'until_failure: true', not both")
        elif "times" not in raw and not until and "until_failure" not in raw:
            self.err(spec.mark, "repeat: missing 'times: N' (or 'until_failure: true')")
        elif "times" not in raw and not until:
            self.err(raw.value_mark("until_failure"), "repeat: 'until_failure: false' needs 'times: N' instead")
        spec.opts["times"] = times

    def n_if(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        parts = [self.child(arg, am, depth, "if")]
        if "then" not in raw:
            self.err(spec.mark, "if: missing required key 'then' (the node run when the condition succeeds)")
        for k in ("then", "else"):
            if k in raw:
                parts.append(self.child(raw[k], raw.value_mark(k), depth, f"if.{k}"))
        spec.opts["has_else"] = "else" in raw
        spec.children = [c for c in parts if c is not None]

    def n_foreach(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        spec.opts["items"] = items = self.list_value(arg, am)
        key = raw.get("as")
        if "as" not in raw:
            self.err(spec.mark, "foreach: missing required key 'as' (the blackboard key each element is written to)")
        else:
            key = self.bound_key(key, raw.value_mark("as"), items)
        spec.opts["key"] = key
        if "do" not in raw:
            self.err(spec.mark, "foreach: missing required key 'do' (the node run once per element)")
            return
        if key is not None:
            self.bound.append((key, raw.value_mark("as")))
        try:
            c = self.child(raw["do"], raw.value_mark("do"), depth, "foreach.do")
        finally:
            if key is not None:
                self.bound.pop()
        if c is not None:
            spec.children.append(c)

    def list_value(self, arg: Any, am: Mark) -> Expr | None:
        """A foreach's list: a literal list, or a reference to a list (a parameter, a
        request field, a blackboard key); None (a problem recorded) otherwise."""
        if not isinstance(arg, (YList, str)) or (isinstance(arg, str) and "{" not in arg):
            got = _short(arg) if isinstance(arg, str) else _tname(arg)
            self.err(am, f"foreach: expected a list or a reference to one like '{{request.items}}', got {got}")
            return None
        e = self.value(arg, am, "foreach")
        if e is None:
            return None
        t = self.static_type(e)
        if isinstance(e, Ref):
            # checked by the compiler once every write is known; else by the node at run time
            self.typed_reads.append((e.key, list, am, "foreach expects a list", arg))
        elif isinstance(e, (Template, Format)) or not type_compatible(list, t):
            self.err(am, f"foreach: expected a list, but {arg!r} is {t.__name__ if t else '?'}")
            return None
        return e

    def bound_key(self, key: Any, mark: Mark, items: Expr | None) -> str | None:
        """Check a foreach's ``as`` key and record it as written (with the elements' type
        when a literal list has one); None (a problem recorded) when it is unusable."""
        if not isinstance(key, str) or not KEY_RE.fullmatch(key):
            self.err(mark, f"foreach.as: expected a blackboard key name, got {key!r}")
            return None
        if key in self.params:
            self.err(mark, f"foreach.as: {key!r} is a parameter of this file: '{{{key}}}' would read the parameter, not the element")
            return None
        if key.startswith("request.") or key in FAILURE_KEYS:
            self.err(mark, f"foreach.as: key {key!r} is reserved (written by the executive)")
            return None
        outer = next((m for k, m in self.bound if k == key), None)
        if outer is not None:
            self.err(mark, f"foreach.as: {key!r} is already bound by the enclosing foreach at {outer}; use another name")
            return None
        kinds = {type(v) for v in items.value} if isinstance(items, Const) else set()
        self.wrote(key, kinds.pop() if len(kinds) == 1 else None)
        return key

    def wrote(self, key: str, tp: type | None) -> None:
        """Record that the tree writes ``key`` with values of type ``tp`` (None: unknown,
        also when two writers disagree)."""
        prev = self.writes.get(key, tp)
        self.writes[key] = tp if prev == tp else None

    def n_invert(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        self._deco(spec, arg, am, depth)

    n_force_success = n_invert
    n_force_failure = n_invert

    def n_condition(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        key = arg
        if isinstance(key, str) and key.startswith("{") and key.endswith("}") and "{" not in key[1:-1]:
            key = key[1:-1].strip()
        if not isinstance(key, str) or not KEY_RE.fullmatch(key):
            self.err(am, f"condition: expected a blackboard key, got {arg!r}")
            key = None
        elif key in self.params:
            self.err(am, f"condition: {key!r} is a parameter, not a blackboard key (compare it in the including file)")
            key = None
        else:
            self.reads.append((key, am))
        op = raw.get("op")
        if "op" not in raw:
            self.err(spec.mark, f"condition: missing required key 'op' (one of: {', '.join(OPS)})")
        elif not isinstance(op, str) or op not in OPS:
            self.err(raw.value_mark("op"), f"condition.op: unknown operator {op!r}" + (
                did_you_mean(str(op), OPS) or f" (expected one of: {', '.join(OPS)})"))
            op = None
        value: Expr | None = Const(None)
        if op == "exists":
            if "value" in raw:
                self.err(raw.key_mark("value"), "condition: op 'exists' takes no value")
        elif op is not None:
            if "value" not in raw:
                self.err(spec.mark, f"condition: op {op!r} needs a 'value'")
            else:
                value = self.value(raw["value"], raw.value_mark("value"), "condition.value")
                if op == "in" and value is not None:
                    t = self.static_type(value)
                    if t is not None and t not in (list, str, dict):
                        self.err(raw.value_mark("value"), f"condition: op 'in' needs a list value, got {raw['value']!r}")
        spec.opts.update(key=key, op=op, value=value)

    def n_wait(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        spec.opts["seconds"] = self.seconds(spec, arg, am, "wait", False)

    def n_skill(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        if not isinstance(arg, str):
            self.err(am, f"skill: expected a skill name, got {arg!r}")
            return
        sk = self.registry.get(arg)
        if sk is None:
            hint = did_you_mean(arg, self.registry.names())
            known = self.registry.names()
            self.err(am, f"unknown skill {arg!r}" + (hint or (f" (known skills: {', '.join(known)})" if known else " (no skills are registered)")))
        spec.opts["skill"] = sk
        params: dict[str, Expr] = {}
        praw = raw.get("params")
        if praw is not None and not isinstance(praw, YDict):
            self.err(raw.value_mark("params"), f"skill {arg!r}: params: expected a mapping, got {_tname(praw)}")
            praw = None
        if isinstance(praw, YDict):
            for pname, pval in praw.items():
                vm = praw.value_mark(pname)
                e = self.value(pval, vm, f"skill {arg!r}: parameter {pname!r}")
                if e is None:
                    continue
                params[pname] = e
                if sk is None:
                    continue
                decl = sk.param(pname)
                if decl is None:
                    names = [p.name for p in sk.params]
                    self.err(praw.key_mark(pname), f"skill {arg!r}: unknown parameter {pname!r}" + (
                        did_you_mean(pname, names) or (f" (expected one of: {', '.join(names)})" if names else " (it takes no parameters)")))
                    continue
                self.check_param(sk, decl, e, pval, vm)
        if sk is not None:
            for p in sk.params:
                if p.required and p.name not in params and (not isinstance(praw, YDict) or p.name not in praw):
                    self.err(am, f"skill {arg!r}: missing required parameter {p.name!r} ({p.type_name()})")
        spec.opts["params"] = params
        outs: dict[str, str] = {}
        oraw = raw.get("outputs")
        if oraw is not None and not isinstance(oraw, YDict):
            self.err(raw.value_mark("outputs"), f"skill {arg!r}: outputs: expected a mapping output -> blackboard key, got {_tname(oraw)}")
            oraw = None
        if isinstance(oraw, YDict):
            for oname, key in oraw.items():
                vm = oraw.value_mark(oname)
                if isinstance(key, str) and key.startswith("{") and key.endswith("}"):
                    key = key[1:-1].strip()
                if not isinstance(key, str) or not KEY_RE.fullmatch(key):
                    self.err(vm, f"skill {arg!r}: output {oname!r}: expected a blackboard key name, got {oraw[oname]!r}")
                    continue
                if key.startswith("request.") or key in FAILURE_KEYS:
                    self.err(vm, f"skill {arg!r}: output {oname!r}: key {key!r} is reserved (written by the executive)")
                    continue
                out_decl = sk.output(oname) if sk is not None else None
                if sk is not None and out_decl is None:
                    names = [o.name for o in sk.outputs]
                    self.err(oraw.key_mark(oname), f"skill {arg!r}: unknown output {oname!r}" + (
                        did_you_mean(oname, names) or (f" (expected one of: {', '.join(names)})" if names else " (it declares no outputs)")))
                    continue
                outs[oname] = key
                self.wrote(key, out_decl.type if out_decl is not None else None)
        spec.opts["outputs"] = outs

    def check_param(self, sk: SkillSpec, decl: Param, e: Expr, raw: Any, mark: Mark) -> None:
        where = f"skill {sk.name!r}: parameter {decl.name!r}"
        if isinstance(e, Const):
            if not decl.accepts(e.value):
                self.err(mark, f"{where} expects {decl.type_name()}, got {_tname(e.value)} {e.value!r}")
            elif decl.choices and e.value not in decl.choices:
                self.err(mark, f"{where} must be one of {list(decl.choices)}, got {e.value!r}"
                         + did_you_mean(str(e.value), [str(c) for c in decl.choices]))
            return
        t = self.static_type(e)
        if isinstance(e, Ref):
            # checked by the compiler once every write is known; else by the leaf at run time
            self.typed_reads.append((e.key, decl.type, mark, f"{where} expects {decl.type_name()}", raw))
            return
        if not type_compatible(decl.type, t):
            self.err(mark, f"{where} expects {decl.type_name()}, but {raw!r} is {t.__name__ if t else '?'}")

    def n_include(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        if not isinstance(arg, str) or not arg.strip():
            self.err(am, f"include: expected a file path, got {arg!r}")
            return
        bindings: dict[str, tuple[Expr, Mark, Mark, Any]] = {}
        praw = raw.get("params")
        if praw is not None and not isinstance(praw, YDict):
            self.err(raw.value_mark("params"), f"include: params: expected a mapping, got {_tname(praw)}")
            praw = None
        if isinstance(praw, YDict):
            for pname, pval in praw.items():
                e = self.value(pval, praw.value_mark(pname), f"include {arg!r}: parameter {pname!r}")
                if e is not None:
                    bindings[pname] = (e, praw.key_mark(pname), praw.value_mark(pname), pval)
        spec.opts["path"] = arg
        spec.opts["bindings"] = {k: v[0] for k, v in bindings.items()}
        sub = self.include(arg, am, spec)
        spec.opts["file"] = sub
        self.includes.append(spec)
        if sub is None:
            return
        if spec.name is None:
            spec.name = sub.name
        for pname, (e, km, vm, pval) in bindings.items():
            d = sub.params.get(pname)
            if d is None:
                self.err(km, f"include {arg!r}: unknown parameter {pname!r}" + (
                    did_you_mean(pname, sub.params) or (f" (it declares: {', '.join(sub.params)})" if sub.params else " (it declares no params)")))
                continue
            if isinstance(e, Const):
                if not accepts(d.type, e.value):
                    self.err(vm, f"include {arg!r}: parameter {pname!r} expects {d.type.__name__}, got {_tname(e.value)} {e.value!r}")
            elif not type_compatible(d.type, self.static_type(e)):
                t = self.static_type(e)
                self.err(vm, f"include {arg!r}: parameter {pname!r} expects {d.type.__name__}, but {pval!r} is {t.__name__ if t else '?'}")
        for pname, d in sub.params.items():
            if not d.has_default and pname not in bindings:
                self.err(am, f"include {arg!r}: missing required parameter {pname!r} ({d.type.__name__})")

    def n_recovery(self, spec: NodeSpec, raw: YDict, arg: Any, am: Mark, depth: int) -> None:
        if not isinstance(arg, YDict):
            self.err(am, f"recovery: expected a mapping with {', '.join(RECOVERY_KEYS)}, got {_tname(arg)}")
            return
        for k in arg:
            if k not in RECOVERY_KEYS:
                self.err(arg.key_mark(k), f"unknown key {k!r} for recovery" + (
                    did_you_mean(k, RECOVERY_KEYS) or f" (expected one of: {', '.join(RECOVERY_KEYS)})"))
        parts: dict[str, NodeSpec | None] = {}
        for k in ("action", "recovery", "give_up"):
            if k in arg:
                parts[k] = self.child(arg[k], arg.value_mark(k), depth, f"recovery.{k}")
            elif k != "give_up":
                self.err(arg.mark, f"recovery: missing required key {k!r} (a node)")
        mr: int | None = 0
        if "max_recoveries" not in arg:
            self.err(arg.mark, "recovery: missing required key 'max_recoveries' (an integer >= 0)")
        else:
            mr = self.bounded_int(arg["max_recoveries"], arg.value_mark("max_recoveries"), "recovery.max_recoveries", 0)
        spec.opts["max_recoveries"] = mr or 0
        spec.opts["has_give_up"] = parts.get("give_up") is not None
        spec.children = [c for c in (parts.get("action"), parts.get("recovery"), parts.get("give_up")) if c is not None]
        self.recoveries.append(spec)
        self.writes.update(recovery_writes(recovery_key_prefix(spec)))


def parse_file(
    doc: Any,
    path: Path,
    display: str,
    problems: Problems,
    registry: SkillRegistry,
    include: Callable[[str, Mark, NodeSpec], FileSpec | None],
) -> FileSpec:
    """Validate one loaded mission file. ``include(rel_path, mark, node)`` loads an
    included file (or records a problem and returns None)."""
    return _Parser(path, display, problems, registry, include).file(doc)
