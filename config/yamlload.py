"""Safe YAML loading that keeps line and column, and typed binding into dataclasses.

Every user-facing YAML file (missions, configs, worlds) goes through :func:`load_yaml`:

* safe loading only (no ``!!python/*`` tags: an unknown tag is an error);
* hostile input rejected quickly and clearly: files over :data:`MAX_BYTES`, invalid
  UTF-8, NUL or other control bytes, nesting deeper than :data:`MAX_DEPTH`, more than
  :data:`MAX_ALIASES` aliases (alias bombs), more than :data:`MAX_NODES` nodes;
* mappings load as :class:`YDict` and sequences as :class:`YList`, plain ``dict`` /
  ``list`` subclasses that remember where each key and item is, so later stages report
  ``FILE:LINE:COL: path.to.key: message`` (1-based line and column).

Problems are collected in a :class:`Problems` list and raised together as
:class:`InputError`, whose ``str()`` is one line per problem.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import types
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "InputError",
    "Mark",
    "MAX_ALIASES",
    "MAX_BYTES",
    "MAX_DEPTH",
    "MAX_NODES",
    "Problem",
    "Problems",
    "YDict",
    "YList",
    "bind",
    "did_you_mean",
    "load_yaml",
    "load_yaml_text",
    "mark_of",
]

MAX_BYTES = 4 * 1024 * 1024
MAX_DEPTH = 64
MAX_ALIASES = 256
MAX_NODES = 200_000


@dataclass(frozen=True)
class Mark:
    """A position in a file: 1-based line and column."""

    file: str
    line: int
    col: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}"


@dataclass(frozen=True)
class Problem:
    mark: Mark
    message: str

    def __str__(self) -> str:
        return f"{self.mark}: {self.message}"


class InputError(Exception):
    """Bad user input (mission, config, world, request): one or more located problems."""

    def __init__(self, problems: Iterable[Problem]) -> None:
        self.problems = sorted(problems, key=lambda p: (p.mark.file, p.mark.line, p.mark.col))
        super().__init__("\n".join(str(p) for p in self.problems))

    @classmethod
    def at(cls, mark: Mark, message: str) -> InputError:
        return cls([Problem(mark, message)])


class Problems(list[Problem]):
    """Collects problems; :meth:`raise_if_any` raises them as one :class:`InputError`."""

    def add(self, mark: Mark, message: str) -> None:
        self.append(Problem(mark, message))

    def raise_if_any(self) -> None:
        if self:
            raise InputError(self)


class YDict(dict[str, Any]):
    """A mapping loaded from YAML; ``mark`` is where it starts, ``key_marks[k]`` and
    ``value_marks[k]`` where key ``k`` and its value are."""

    mark: Mark
    key_marks: dict[str, Mark]
    value_marks: dict[str, Mark]

    def key_mark(self, key: str) -> Mark:
        return self.key_marks.get(key, self.mark)

    def value_mark(self, key: str) -> Mark:
        return self.value_marks.get(key, self.mark)


class YList(list[Any]):
    """A sequence loaded from YAML; ``item_marks[i]`` is where item ``i`` is."""

    mark: Mark
    item_marks: list[Mark]

    def item_mark(self, i: int) -> Mark:
        return self.item_marks[i] if 0 <= i < len(self.item_marks) else self.mark


def mark_of(value: Any, default: Mark) -> Mark:
    """The mark of a loaded container, or ``default`` for scalars."""
    return getattr(value, "mark", default)


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` when a known name is close to ``name``, else ``""``."""
    hits = difflib.get_close_matches(str(name), list(known), n=1, cutoff=0.6)
    return f"; did you mean {hits[0]!r}?" if hits else ""


# --------------------------------------------------------------------------- loading


def _mark(file: str, m: yaml.Mark | None) -> Mark:
    if m is None:
        return Mark(file, 1, 1)
    return Mark(file, m.line + 1, m.column + 1)


class _Constructor(yaml.constructor.SafeConstructor):
    pass


def _utf8_error_mark(file: str, data: bytes, pos: int) -> Mark:
    before = data[:pos]
    line = before.count(b"\n") + 1
    col = pos - (before.rfind(b"\n") + 1) + 1
    return Mark(file, line, col)


def load_yaml(path: str | Path) -> Any:
    """Load one YAML document from ``path`` (see module doc). Raises InputError."""
    p = Path(path)
    name = str(path)
    try:
        size = p.stat().st_size
        if size > MAX_BYTES:
            raise InputError.at(Mark(name, 1, 1), f"file is {size} bytes, larger than the {MAX_BYTES} byte limit")
        data = p.read_bytes()
    except FileNotFoundError:
        raise InputError.at(Mark(name, 1, 1), "no such file") from None
    except IsADirectoryError:
        raise InputError.at(Mark(name, 1, 1), "is a directory, expected a YAML file") from None
    except PermissionError:
        raise InputError.at(Mark(name, 1, 1), "permission denied") from None
    except OSError as e:
        raise InputError.at(Mark(name, 1, 1), f"cannot read: {e.strerror or e}") from None
    return load_yaml_bytes(data, name)


def load_yaml_bytes(data: bytes, name: str = "<string>") -> Any:
    if len(data) > MAX_BYTES:
        raise InputError.at(Mark(name, 1, 1), f"input is {len(data)} bytes, larger than the {MAX_BYTES} byte limit")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError.at(
            _utf8_error_mark(name, data, e.start), f"not valid UTF-8 (byte 0x{data[e.start]:02x}); is this a YAML file?"
        ) from None
    return load_yaml_text(text, name)


def load_yaml_text(text: str, name: str = "<string>") -> Any:
    """Load one YAML document from a string (see module doc). Raises InputError."""
    if text.startswith("\ufeff"):
        text = text[1:]
    for i, ch in enumerate(text):
        if ch == "\x00":
            pos = text[:i]
            raise InputError.at(
                Mark(name, pos.count("\n") + 1, i - (pos.rfind("\n") + 1) + 1),
                "contains a NUL byte; is this a binary file?",
            )
        if i > 4096:
            break
    # Pass 1: the event stream (iterative, cheap) to bound depth, aliases and size
    # before anything recursive runs.
    depth = aliases = events = docs = 0
    try:
        for ev in yaml.parse(text, Loader=yaml.SafeLoader):
            events += 1
            if isinstance(ev, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                depth += 1
                if depth > MAX_DEPTH:
                    raise InputError.at(_mark(name, ev.start_mark), f"nesting deeper than {MAX_DEPTH} levels")
            elif isinstance(ev, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                depth -= 1
            elif isinstance(ev, yaml.AliasEvent):
                aliases += 1
                if aliases > MAX_ALIASES:
                    raise InputError.at(
                        _mark(name, ev.start_mark), f"more than {MAX_ALIASES} aliases (YAML alias bomb?)"
                    )
            elif isinstance(ev, yaml.DocumentStartEvent):
                docs += 1
                if docs > 1:
                    raise InputError.at(_mark(name, ev.start_mark), "more than one YAML document in the file")
            if events > MAX_NODES:
                raise InputError.at(_mark(name, ev.start_mark), f"more than {MAX_NODES} YAML nodes")
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as e:
        m = e.problem_mark or e.context_mark
        msg = " ".join(x for x in (e.context, e.problem) if x) or "malformed YAML"
        raise InputError.at(_mark(name, m), f"malformed YAML: {msg}") from None
    except yaml.YAMLError as e:
        raise InputError.at(Mark(name, 1, 1), f"malformed YAML: {e}") from None
    if node is None:
        return None
    if _expanded_size(node, {}) > MAX_NODES:
        raise InputError.at(_mark(name, node.start_mark), f"more than {MAX_NODES} YAML nodes after alias expansion (YAML alias bomb?)")
    problems = Problems()
    budget = [MAX_NODES]
    out = _convert(node, name, _Constructor(), problems, budget, {})
    problems.raise_if_any()
    return out


def _expanded_size(node: yaml.Node, memo: dict[int, int]) -> int:
    """Node count with every alias expanded, computed in linear time (memoised)."""
    key = id(node)
    if key in memo:
        return memo[key]
    memo[key] = 1  # a cycle counts once; PyYAML's composer does not build cycles anyway
    total = 1
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            total += _expanded_size(k, memo) + _expanded_size(v, memo)
    elif isinstance(node, yaml.SequenceNode):
        for item in node.value:
            total += _expanded_size(item, memo)
    memo[key] = min(total, 1 << 62)
    return memo[key]


def _convert(
    node: yaml.Node, name: str, ctor: _Constructor, problems: Problems, budget: list[int], seen: dict[int, Any]
) -> Any:
    budget[0] -= 1
    if budget[0] < 0:
        raise InputError.at(_mark(name, node.start_mark), f"more than {MAX_NODES} YAML nodes after alias expansion")
    mark = _mark(name, node.start_mark)
    if id(node) in seen:  # an alias: share the already-built value (no re-expansion)
        return seen[id(node)]
    if isinstance(node, yaml.MappingNode):
        if node.tag not in ("tag:yaml.org,2002:map",):
            problems.add(mark, f"unsupported YAML tag {node.tag!r}")
        d = YDict()
        d.mark, d.key_marks, d.value_marks = mark, {}, {}
        seen[id(node)] = d
        try:
            ctor.flatten_mapping(node)  # merge keys (<<)
        except yaml.MarkedYAMLError as e:
            problems.add(_mark(name, e.problem_mark), f"malformed YAML: {e.problem}")
        for knode, vnode in node.value:
            kmark = _mark(name, knode.start_mark)
            if not isinstance(knode, yaml.ScalarNode):
                problems.add(kmark, "mapping keys must be plain scalars")
                continue
            key = _scalar(knode, name, ctor, problems)
            if not isinstance(key, str):
                key = str(key)
            if key in d:
                problems.add(kmark, f"duplicate key {key!r} (first at line {d.key_marks[key].line})")
                continue
            d[key] = _convert(vnode, name, ctor, problems, budget, seen)
            d.key_marks[key] = kmark
            d.value_marks[key] = _mark(name, vnode.start_mark)
        return d
    if isinstance(node, yaml.SequenceNode):
        if node.tag != "tag:yaml.org,2002:seq":
            problems.add(mark, f"unsupported YAML tag {node.tag!r}")
        lst = YList()
        lst.mark, lst.item_marks = mark, []
        seen[id(node)] = lst
        for item in node.value:
            lst.append(_convert(item, name, ctor, problems, budget, seen))
            lst.item_marks.append(_mark(name, item.start_mark))
        return lst
    return _scalar(node, name, ctor, problems)


def _scalar(node: yaml.Node, name: str, ctor: _Constructor, problems: Problems) -> Any:
    try:
        return ctor.construct_object(node, deep=True)
    except yaml.constructor.ConstructorError as e:
        problems.add(_mark(name, node.start_mark), f"unsupported YAML value: {e.problem}")
    except (ValueError, OverflowError) as e:
        problems.add(_mark(name, node.start_mark), f"bad scalar value: {e}")
    return None


# --------------------------------------------------------------------------- binding


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(tp) if a is not type(None))
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(tp))
    if origin in (list, tuple):
        args = typing.get_args(tp)
        if origin is tuple and args and args[-1] is not Ellipsis:
            return f"a list of {len(args)} numbers" if all(a in (float, int) for a in args) else f"a list of {len(args)}"
        return f"a list of {_type_name(args[0])}" if args else "a list"
    if origin is dict:
        return "a mapping"
    if dataclasses.is_dataclass(tp):
        return "a mapping"
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return "one of " + ", ".join(repr(m.value) for m in tp)
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string"}.get(tp, getattr(tp, "__name__", str(tp)))


def bind(tp: Any, value: Any, mark: Mark, path: str, problems: Problems) -> Any:
    """Convert loaded YAML ``value`` into ``tp`` (dataclass, list[...], dict[str, ...],
    tuple[...], Optional, Literal, Enum, scalars), recording every problem with its mark
    and dotted ``path``. Unknown keys and missing required fields are problems. Returns
    the converted value, or None when it could not be converted."""
    where = f"{path}: " if path else ""
    origin = typing.get_origin(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        non_none = [a for a in args if a is not type(None)]
        if len(non_none) == 1:
            return bind(non_none[0], value, mark, path, problems)
        for a in non_none:
            trial = Problems()
            out = bind(a, value, mark, path, trial)
            if not trial:
                return out
        problems.add(mark, f"{where}expected {_type_name(tp)}, got {value!r}")
        return None
    if origin is typing.Literal:
        allowed = typing.get_args(tp)
        if value not in allowed:
            problems.add(mark, f"{where}expected one of {', '.join(map(repr, allowed))}, got {value!r}"
                         + did_you_mean(str(value), [str(a) for a in allowed]))
            return None
        return value
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        for m in tp:
            if m.value == value:
                return m
        problems.add(mark, f"{where}expected {_type_name(tp)}, got {value!r}"
                     + did_you_mean(str(value), [str(m.value) for m in tp]))
        return None
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _bind_dataclass(tp, value, mark, path, problems)
    if origin in (list, tuple) or tp in (list, tuple):
        if not isinstance(value, list):
            problems.add(mark, f"{where}expected {_type_name(tp)}, got {value!r}")
            return None
        args = typing.get_args(tp)
        marks = getattr(value, "item_marks", [])
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                problems.add(mark, f"{where}expected {_type_name(tp)}, got {len(value)} items")
                return None
            item_types = list(args)
        else:
            item_types = [args[0] if args else Any] * len(value)
        items = [
            bind(t, v, marks[i] if i < len(marks) else mark, f"{path}[{i}]", problems)
            for i, (t, v) in enumerate(zip(item_types, value))
        ]
        return tuple(items) if origin is tuple else items
    if origin is dict or tp is dict:
        if not isinstance(value, dict):
            problems.add(mark, f"{where}expected a mapping, got {value!r}")
            return None
        args = typing.get_args(tp)
        vt = args[1] if len(args) == 2 else Any
        vm = getattr(value, "value_marks", {})
        return {k: bind(vt, v, vm.get(k, mark), f"{path}.{k}" if path else str(k), problems) for k, v in value.items()}
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            problems.add(mark, f"{where}expected a number, got {value!r}")
            return None
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            problems.add(mark, f"{where}expected an integer, got {value!r}")
            return None
        return value
    if tp is bool:
        if not isinstance(value, bool):
            problems.add(mark, f"{where}expected true or false, got {value!r}")
            return None
        return value
    if tp is str:
        if not isinstance(value, str):
            problems.add(mark, f"{where}expected a string, got {value!r}")
            return None
        return value
    if isinstance(tp, type) and not isinstance(value, tp):
        problems.add(mark, f"{where}expected {_type_name(tp)}, got {value!r}")
        return None
    return value


def _bind_dataclass(tp: type, value: Any, mark: Mark, path: str, problems: Problems) -> Any:
    where = f"{path}: " if path else ""
    if value is None:
        value = YDict()
        value.mark, value.key_marks, value.value_marks = mark, {}, {}
    if not isinstance(value, Mapping):
        problems.add(mark, f"{where}expected a mapping, got {value!r}")
        return None
    hints = typing.get_type_hints(tp)
    fields = {f.name: f for f in dataclasses.fields(tp) if f.init}
    km = getattr(value, "key_marks", {})
    vm = getattr(value, "value_marks", {})
    ok = True
    for key in value:
        if key not in fields:
            problems.add(km.get(key, mark), f"{path + '.' if path else ''}{key}: unknown key"
                         + (did_you_mean(key, fields) or f" (expected one of: {', '.join(fields)})"))
            ok = False
    kwargs: dict[str, Any] = {}
    for fname, f in fields.items():
        sub = f"{path}.{fname}" if path else fname
        if fname in value:
            before = len(problems)
            kwargs[fname] = bind(hints[fname], value[fname], vm.get(fname, mark), sub, problems)
            ok = ok and len(problems) == before
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:  # type: ignore[misc]
            problems.add(mark, f"{sub}: missing required key (expected {_type_name(hints[fname])})")
            ok = False
    if not ok:
        return None
    try:
        obj = tp(**kwargs)
    except (ValueError, TypeError) as e:
        problems.add(mark, f"{where}{e}")
        return None
    validate = getattr(obj, "validate", None)
    if callable(validate):
        for msg in validate() or ():
            problems.add(mark, f"{where}{msg}")
    return obj
