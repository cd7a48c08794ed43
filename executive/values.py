"""Values in mission files: constants, blackboard references, string templates.

A mission value is parsed once (:func:`parse_value`) into an expression tree. At load
time references may still name the file's parameters (:class:`ParamRef`); when a tree
is instantiated :func:`substitute` replaces those by the parameters' values, leaving
only constants and blackboard reads, which a node evaluates against the blackboard when
it starts (:meth:`Expr.eval`).

Syntax: a string that is exactly ``"{key}"`` is a reference (typed: it evaluates to the
key's value); ``"text {key} text"`` is a template (evaluates to a string); ``{{`` and
``}}`` are literal braces. A reference may carry a Python format spec,
``{heading:.2f}`` (:class:`Format`: it evaluates to the formatted string); the spec is
checked when the value is parsed (:func:`format_problem`).

:data:`OPS` holds the operators a ``condition`` compares with (the schema checks a
mission's ``op`` against it, the node applies it).
"""

from __future__ import annotations

import operator
import re
from collections.abc import Callable, Mapping
from typing import Any

__all__ = [
    "KEY_RE",
    "MAX_FORMAT_WIDTH",
    "MAX_SECONDS",
    "OPS",
    "BadFormat",
    "Const",
    "DictExpr",
    "EvalError",
    "Expr",
    "Format",
    "ListExpr",
    "MissingKey",
    "ParamRef",
    "Ref",
    "Template",
    "ValueSyntaxError",
    "format_problem",
    "parse_value",
    "substitute",
]

#: longest wait or timeout a mission may give [clock s] (about 11.6 days)
MAX_SECONDS = 1e6

#: a blackboard key or parameter name: dotted identifiers (``request.item``, ``grasp.attempts``)
KEY_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*(?:\.[A-Za-z0-9_\-]+)*")
_TOKEN_RE = re.compile(r"\{\{|\}\}|\{([^{}]*)\}|[{}]")
#: Python's format spec: [[fill]align][sign][z][#][0][width][grouping][.precision][type]
_SPEC_RE = re.compile(r"(?:.?[<>=^])?[-+ ]?z?#?0?(?P<width>\d+)?[_,]?(?:\.(?P<precision>\d+))?[bcdeEfFgGnosxX%]?", re.DOTALL)
_SPEC_SYNTAX = "[[fill]align][sign][z][#][0][width][grouping][.precision][type], e.g. '.2f'"
#: largest width or precision a format spec may ask for [characters]
MAX_FORMAT_WIDTH = 1000
#: a value of each declared type that a format spec is tried on (a float spec must
#: also format an int: an int is accepted where a float is declared)
_SAMPLES: dict[type, tuple[Any, ...]] = {
    int: (0,), float: (0.0, 0), str: ("",), bool: (False,), list: ([],), dict: ({},),
}


def _in(a: Any, b: Any) -> bool:
    return a in b


def _exists(a: Any, b: Any) -> bool:
    return True


#: condition operators: ``op(blackboard value, compared value) -> bool``
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


class EvalError(Exception):
    """A mission value that cannot be evaluated on the blackboard as it is now;
    ``reason`` says why (the node fails with kind precondition)."""

    reason = ""


class MissingKey(EvalError, KeyError):
    """A blackboard key read before anything wrote it."""

    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key
        self.reason = f"blackboard key {key!r} is not set (nothing wrote it yet)"


class BadFormat(EvalError, ValueError):
    """A value that its reference's format spec cannot format (``{heading:.2f}`` of a string)."""

    def __init__(self, what: str, value: Any, spec: str, error: Exception) -> None:
        super().__init__(what, value, spec)
        self.reason = f"{what} = {_short(value)} cannot be formatted with ':{spec}' ({error})"


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:60] + "..."


def _a(tp: type) -> str:
    """``an int``, ``a float``: the type's name with its article."""
    return ("an " if tp.__name__[0] in "aeiou" else "a ") + tp.__name__


def format_problem(spec: str, tp: type | None = None) -> str | None:
    """Why format spec ``spec`` is unusable for a value of declared type ``tp`` (None:
    a type not known yet, then some type must accept it), or None when it is usable."""
    m = _SPEC_RE.fullmatch(spec)
    if m is None:
        return f"bad format spec ':{spec}' (expected {_SPEC_SYNTAX})"
    for part in ("width", "precision"):
        n = m.group(part)
        if n is not None and int(n) > MAX_FORMAT_WIDTH:
            return f"format spec ':{spec}': {part} {n} is more than the limit of {MAX_FORMAT_WIDTH}"
    samples = _SAMPLES.get(tp, ()) if tp is not None else (0, 0.0, "")
    errors: list[tuple[Any, str]] = []
    for sample in samples:
        try:
            format(sample, spec)
        except (TypeError, ValueError) as e:
            errors.append((sample, f"{e}"))
    if not errors or (tp is None and len(errors) < len(samples)):
        return None
    sample, error = errors[0]
    if tp is None:
        what = "any value"
    elif type(sample) is tp:
        what = _a(tp)
    else:
        what = f"{_a(type(sample))} (accepted as {_a(tp)})"
    return f"format spec ':{spec}' cannot format {what}: {error}"


class ValueSyntaxError(ValueError):
    """A malformed reference or template in a mission value."""


class Expr:
    """An evaluable mission value. ``static`` is true when it reads no blackboard key."""

    static = True

    def eval(self, bb: Mapping[str, Any]) -> Any:
        raise TypeError(f"{type(self).__name__} cannot be evaluated")

    def reads(self) -> list[str]:
        """Blackboard keys this value reads."""
        return []

    def params(self) -> list[str]:
        """Parameter names this value refers to (before substitution)."""
        return []

    def formats(self) -> list[Format]:
        """The formatted references in this value (``{key:spec}``)."""
        return []


class Const(Expr):
    __slots__ = ("value",)

    def __init__(self, value: Any) -> None:
        self.value = value

    def eval(self, bb: Mapping[str, Any]) -> Any:
        return self.value

    def __repr__(self) -> str:
        return f"Const({self.value!r})"


class Ref(Expr):
    """Reads blackboard key ``key``."""

    __slots__ = ("key",)
    static = False

    def __init__(self, key: str) -> None:
        self.key = key

    def eval(self, bb: Mapping[str, Any]) -> Any:
        try:
            return bb[self.key]
        except KeyError:
            raise MissingKey(self.key) from None

    def reads(self) -> list[str]:
        return [self.key]

    def __repr__(self) -> str:
        return f"Ref({self.key!r})"


class ParamRef(Expr):
    """Refers to parameter ``name`` of the file it appears in (substituted at instantiate)."""

    __slots__ = ("name",)
    static = False

    def __init__(self, name: str) -> None:
        self.name = name

    def params(self) -> list[str]:
        return [self.name]

    def __repr__(self) -> str:
        return f"ParamRef({self.name!r})"


class Template(Expr):
    """A string with embedded references; ``parts`` alternates literal text and Exprs."""

    __slots__ = ("parts", "static")

    def __init__(self, parts: list[str | Expr]) -> None:
        self.parts = parts
        self.static = all(isinstance(p, str) or p.static for p in parts)

    def eval(self, bb: Mapping[str, Any]) -> Any:
        return "".join(p if isinstance(p, str) else str(p.eval(bb)) for p in self.parts)

    def reads(self) -> list[str]:
        return [k for p in self.parts if isinstance(p, Expr) for k in p.reads()]

    def params(self) -> list[str]:
        return [k for p in self.parts if isinstance(p, Expr) for k in p.params()]

    def formats(self) -> list[Format]:
        return [f for p in self.parts if isinstance(p, Expr) for f in p.formats()]


class Format(Expr):
    """``format(value, spec)`` of a reference: ``{heading:.2f}`` (evaluates to a string)."""

    __slots__ = ("expr", "spec", "static")

    def __init__(self, expr: Expr, spec: str) -> None:
        self.expr = expr
        self.spec = spec
        self.static = expr.static

    def apply(self, value: Any) -> str:
        """``value`` formatted with the spec; BadFormat when the spec does not fit it."""
        try:
            return format(value, self.spec)
        except (TypeError, ValueError) as e:
            raise BadFormat(self.label(), value, self.spec, e) from None

    def label(self) -> str:
        """What is formatted, for messages: ``blackboard key 'heading'``."""
        e = self.expr
        if isinstance(e, Ref):
            return f"blackboard key {e.key!r}"
        return f"parameter {e.name!r}" if isinstance(e, ParamRef) else "the value"

    def eval(self, bb: Mapping[str, Any]) -> Any:
        return self.apply(self.expr.eval(bb))

    def reads(self) -> list[str]:
        return self.expr.reads()

    def params(self) -> list[str]:
        return self.expr.params()

    def formats(self) -> list[Format]:
        return [self]

    def __repr__(self) -> str:
        return f"Format({self.expr!r}, {self.spec!r})"


class ListExpr(Expr):
    __slots__ = ("items", "static")

    def __init__(self, items: list[Expr]) -> None:
        self.items = items
        self.static = all(i.static for i in items)

    def eval(self, bb: Mapping[str, Any]) -> Any:
        return [i.eval(bb) for i in self.items]

    def reads(self) -> list[str]:
        return [k for i in self.items for k in i.reads()]

    def params(self) -> list[str]:
        return [k for i in self.items for k in i.params()]

    def formats(self) -> list[Format]:
        return [f for i in self.items for f in i.formats()]


class DictExpr(Expr):
    __slots__ = ("items", "static")

    def __init__(self, items: dict[str, Expr]) -> None:
        self.items = items
        self.static = all(i.static for i in items.values())

    def eval(self, bb: Mapping[str, Any]) -> Any:
        return {k: v.eval(bb) for k, v in self.items.items()}

    def reads(self) -> list[str]:
        return [k for i in self.items.values() for k in i.reads()]

    def params(self) -> list[str]:
        return [k for i in self.items.values() for k in i.params()]

    def formats(self) -> list[Format]:
        return [f for i in self.items.values() for f in i.formats()]


def _parse_string(s: str, is_param: Any) -> Expr:
    parts: list[str | Expr] = []
    text: list[str] = []
    pos = 0
    for m in _TOKEN_RE.finditer(s):
        text.append(s[pos : m.start()])
        pos = m.end()
        tok = m.group(0)
        if tok == "{{":
            text.append("{")
        elif tok == "}}":
            text.append("}")
        elif tok in ("{", "}"):
            raise ValueSyntaxError(f"unbalanced {tok!r} in {s!r} (write '{tok * 2}' for a literal brace)")
        else:
            name, colon, spec = m.group(1).partition(":")
            name = name.strip()
            if not KEY_RE.fullmatch(name):
                raise ValueSyntaxError(f"bad reference {tok!r} in {s!r} (expected {{key}} or {{key:spec}}, e.g. {{request.item}})")
            problem = format_problem(spec) if colon else None
            if problem is not None:
                raise ValueSyntaxError(f"{problem} in {tok!r}")
            lit = "".join(text)
            text = []
            if lit:
                parts.append(lit)
            ref: Expr = ParamRef(name) if is_param(name) else Ref(name)
            parts.append(Format(ref, spec) if colon else ref)
    text.append(s[pos:])
    tail = "".join(text)
    if tail:
        parts.append(tail)
    if not any(isinstance(p, Expr) for p in parts):
        return Const(tail if not parts else "".join(p for p in parts if isinstance(p, str)))
    if len(parts) == 1:
        return parts[0]  # type: ignore[return-value]
    return Template(parts)


def parse_value(value: Any, is_param: Any) -> Expr:
    """Parse a loaded YAML value into an Expr. ``is_param(name)`` tells whether a
    reference names a parameter of the current file. Raises ValueSyntaxError."""
    if isinstance(value, str):
        if "{" not in value and "}" not in value:
            return Const(value)
        return _parse_string(value, is_param)
    if isinstance(value, list):
        items = [parse_value(v, is_param) for v in value]
        if all(isinstance(i, Const) for i in items):
            return Const([i.value for i in items])  # type: ignore[attr-defined]
        return ListExpr(items)
    if isinstance(value, dict):
        d = {str(k): parse_value(v, is_param) for k, v in value.items()}
        if all(isinstance(i, Const) for i in d.values()):
            return Const({k: i.value for k, i in d.items()})  # type: ignore[attr-defined]
        return DictExpr(d)
    return Const(value)


def substitute(expr: Expr, env: Mapping[str, Expr], keys: Callable[[str], str] | None = None) -> Expr:
    """Replace every :class:`ParamRef` by ``env[name]`` (an Expr without ParamRefs), and
    with ``keys`` every blackboard key read by ``keys(key)`` (the values in ``env`` come
    from the including file, whose keys are already its own, so they are kept)."""
    if isinstance(expr, ParamRef):
        return env[expr.name]
    if isinstance(expr, Ref):
        return expr if keys is None or keys(expr.key) == expr.key else Ref(keys(expr.key))
    if isinstance(expr, Const):
        return expr
    if isinstance(expr, Format):
        inner = substitute(expr.expr, env, keys)
        return Const(expr.apply(inner.value)) if isinstance(inner, Const) else Format(inner, expr.spec)
    if isinstance(expr, Template):
        parts: list[str | Expr] = []
        for p in expr.parts:
            q = p if isinstance(p, str) else substitute(p, env, keys)
            if isinstance(q, Const):
                q = str(q.value)
            if isinstance(q, Template):
                parts.extend(q.parts)
            elif isinstance(q, str) and parts and isinstance(parts[-1], str):
                parts[-1] = parts[-1] + q
            else:
                parts.append(q)
        if all(isinstance(p, str) for p in parts):
            return Const("".join(parts))  # type: ignore[arg-type]
        return Template(parts)
    if isinstance(expr, ListExpr):
        items = [substitute(i, env, keys) for i in expr.items]
        if all(isinstance(i, Const) for i in items):
            return Const([i.value for i in items])  # type: ignore[attr-defined]
        return ListExpr(items)
    if isinstance(expr, DictExpr):
        d = {k: substitute(v, env, keys) for k, v in expr.items.items()}
        if all(isinstance(i, Const) for i in d.values()):
            return Const({k: i.value for k, i in d.items()})  # type: ignore[attr-defined]
        return DictExpr(d)
    return expr
