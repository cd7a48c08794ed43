"""Safe YAML loading that keeps line and column, and typed binding into dataclasses.

Every user-facing YAML file (missions, configs, worlds) goes through :func:`load_yaml`:

* safe loading only (no ``!!python/*`` tags: an unknown tag is an error);
* hostile input rejected quickly and clearly: anything but a regular file (a FIFO,
  ``/dev/zero``, a directory, a symlink loop: see :func:`read_file`), files over
  :data:`MAX_BYTES`, invalid UTF-8, NUL or other control bytes, nesting deeper than
  :data:`MAX_DEPTH`, more than :data:`MAX_ALIASES` aliases (alias bombs), more than
  :data:`MAX_NODES` nodes;
* mappings load as :class:`YDict` and sequences as :class:`YList`, plain ``dict`` /
  ``list`` subclasses that remember where each key and item is, so later stages report
  ``FILE:LINE:COL: path.to.key: message`` (1-based line and column);
* :func:`bind` refuses non-finite numbers (``.nan``, ``.inf``) in every ``float`` field
  and anywhere inside untyped (``Any``) data; a field that may be infinite says so with
  :data:`MaybeInfinite` (``.inf`` / ``-.inf`` then bind; NaN never does).

Problems are collected in a :class:`Problems` list and raised together as
:class:`InputError`, whose ``str()`` is one line per problem.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import errno
import functools
import math
import os
import stat
import types
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import yaml

__all__ = [
    "MAX_ALIASES",
    "MAX_BYTES",
    "MAX_DEPTH",
    "MAX_NODES",
    "MAY_BE_INFINITE",
    "InputError",
    "Mark",
    "MaybeInfinite",
    "Problem",
    "Problems",
    "YDict",
    "YList",
    "bind",
    "did_you_mean",
    "is_within",
    "load_yaml",
    "load_yaml_text",
    "mark_of",
    "read_file",
    "refuse_nonfinite",
]

MAX_BYTES = 4 * 1024 * 1024
MAX_DEPTH = 64
MAX_ALIASES = 256
MAX_NODES = 200_000


class _MayBeInfinite:
    """Marker in ``Annotated[float, MAY_BE_INFINITE]``: the field accepts +-infinity."""

    def __repr__(self) -> str:
        return "MAY_BE_INFINITE"


#: Metadata marking a float field that may be infinite (see :data:`MaybeInfinite`).
MAY_BE_INFINITE = _MayBeInfinite()
#: A float field that accepts ``.inf`` and ``-.inf`` (never ``.nan``); a plain ``float``
#: field refuses every non-finite number.
MaybeInfinite = Annotated[float, MAY_BE_INFINITE]


class Mark(typing.NamedTuple):
    """A position in a file: 1-based line and column (a tuple: cheap to make by the
    thousand while loading)."""

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


# libyaml's C parser when PyYAML was built with it (about 15x faster on large missions);
# it produces the same events, nodes and marks as the pure-Python SafeLoader.
_Loader: type = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def _utf8_error_mark(file: str, data: bytes, pos: int) -> Mark:
    before = data[:pos]
    line = before.count(b"\n") + 1
    col = pos - (before.rfind(b"\n") + 1) + 1
    return Mark(file, line, col)


_FILE_KINDS: tuple[tuple[Any, str], ...] = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _not_regular(mode: int, expected: str) -> str | None:
    """Why a file of ``mode`` cannot be read as ``expected``, or None for a regular file."""
    if stat.S_ISREG(mode):
        return None
    kind = next((name for test, name in _FILE_KINDS if test(mode)), "not a regular file")
    return f"is {kind}, expected {expected}"


def _os_reason(e: OSError) -> str:
    """A one-line reason for an OSError met opening or reading a file."""
    reasons = {
        errno.ENOENT: "no such file",
        errno.ENOTDIR: "no such file (a folder in the path is a file)",
        errno.EACCES: "permission denied",
        errno.EPERM: "permission denied",
        errno.ELOOP: "too many levels of symbolic links (a symlink loop?)",
        errno.ENAMETOOLONG: "file name too long",
    }
    return reasons.get(e.errno or 0) or f"cannot read: {e.strerror or e}"


def read_file(path: str | Path, *, limit: int = MAX_BYTES, expected: str = "a YAML file") -> bytes:
    """The bytes of the regular file at ``path``, which must be at most ``limit`` bytes.

    Anything else is an :class:`InputError` at ``path:1:1``, raised at once and without
    reading: a missing file, a directory, a FIFO (it is never waited on), a device such
    as ``/dev/zero``, a socket, a symlink loop, an unreadable file, or a file larger than
    ``limit`` (a sparse 3 GB file is refused from its size, and a file that grows while
    it is read stops being read one byte past ``limit``). ``expected`` names what the
    file should be, for the message ("a YAML file", "an event log").
    """
    where = Mark(str(path), 1, 1)
    try:
        st = os.stat(path)  # no open() yet: opening a device or a serial port has side effects
        why = _not_regular(st.st_mode, expected)
        if why is not None:
            raise InputError.at(where, why)
        flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOCTTY", 0)
        fd = os.open(path, flags)
    except OSError as e:
        raise InputError.at(where, _os_reason(e)) from None
    try:
        st = os.fstat(fd)  # what was opened, which may not be what was stat'ed a moment ago
        why = _not_regular(st.st_mode, expected)
        if why is not None:
            raise InputError.at(where, why)
        if st.st_size > limit:
            raise InputError.at(where, f"file is {st.st_size} bytes, larger than the {limit} byte limit")
        chunks: list[bytes] = []
        total = 0
        while total <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - total))
            if not chunk:
                return b"".join(chunks)
            chunks.append(chunk)
            total += len(chunk)
        raise InputError.at(where, f"file grew past the {limit} byte limit while it was read")
    except OSError as e:
        raise InputError.at(where, _os_reason(e)) from None
    finally:
        os.close(fd)


def is_within(path: str | Path, roots: Iterable[str | Path]) -> bool:
    """Whether ``path``, with every symlink resolved, lies inside one of ``roots`` (also
    resolved). Never opens or reads ``path``; a symlink loop resolves to itself."""
    real = Path(os.path.realpath(path))
    return any(real.is_relative_to(os.path.realpath(r)) for r in roots)


def load_yaml(path: str | Path) -> Any:
    """Load one YAML document from the regular file ``path`` (see module doc and
    :func:`read_file`). Raises InputError."""
    return load_yaml_bytes(read_file(path), str(path))


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
    text = text.removeprefix("\ufeff")
    for i, ch in enumerate(text):
        if ch == "\x00":
            pos = text[:i]
            raise InputError.at(
                Mark(name, pos.count("\n") + 1, i - (pos.rfind("\n") + 1) + 1),
                "contains a NUL byte; is this a binary file?",
            )
        if i > 4096:
            break
    try:
        return _build(text, name)
    except yaml.MarkedYAMLError as e:
        m = e.problem_mark or e.context_mark
        msg = " ".join(x for x in (e.context, e.problem) if x) or "malformed YAML"
        raise InputError.at(_mark(name, m), f"malformed YAML: {msg}") from None
    except yaml.YAMLError as e:
        raise InputError.at(Mark(name, 1, 1), f"malformed YAML: {e}") from None


_STR_TAG = "tag:yaml.org,2002:str"
_MAP_TAG = "tag:yaml.org,2002:map"
_SEQ_TAG = "tag:yaml.org,2002:seq"
_MERGE_TAG = "tag:yaml.org,2002:merge"
_IMPLICIT = yaml.resolver.Resolver.yaml_implicit_resolvers


@functools.lru_cache(maxsize=4096)
def _resolve_plain(value: str) -> str:
    """The tag PyYAML's resolver gives a plain scalar (YAML 1.1 rules)."""
    resolvers = _IMPLICIT.get(value[0] if value else "", [])
    for tag, regexp in resolvers + _IMPLICIT.get(None, []):
        if regexp.match(value):
            return tag
    return _STR_TAG


class _Frame:
    """A mapping or sequence being built from the event stream."""

    __slots__ = ("anchor", "key", "key_mark", "merges", "size", "value")

    def __init__(self, value: YDict | YList, anchor: str | None) -> None:
        self.value = value
        self.size = 1
        self.key: Any = _NO_KEY
        self.key_mark: Mark | None = None
        self.merges: list[tuple[Any, Mark]] = []
        self.anchor = anchor


_NO_KEY = object()


def _build(text: str, name: str) -> Any:
    """Build YDict / YList / scalars straight from the parser's event stream.

    One iterative pass (no recursion, so deep nesting cannot overflow the stack) that
    bounds depth, aliases and the alias-expanded node count as it goes. Aliases share
    the anchored value (no copy), but count their full size against :data:`MAX_NODES`.
    """
    ctor = _Constructor()
    problems = Problems()
    stack: list[_Frame] = []
    anchors: dict[str, tuple[Any, int]] = {}
    root: Any = None
    docs = aliases = 0
    for ev in yaml.parse(text, Loader=_Loader):
        cls = ev.__class__
        if cls is yaml.ScalarEvent:
            mark = _mark(name, ev.start_mark)
            value = _scalar_event(ev, mark, ctor, problems)
            size = 1
            if ev.anchor is not None:
                anchors[ev.anchor] = (value, 1)
        elif cls is yaml.MappingStartEvent or cls is yaml.SequenceStartEvent:
            mark = _mark(name, ev.start_mark)
            if len(stack) >= MAX_DEPTH:
                raise InputError.at(mark, f"nesting deeper than {MAX_DEPTH} levels")
            is_map = cls is yaml.MappingStartEvent
            if ev.tag not in (None, "!", _MAP_TAG if is_map else _SEQ_TAG):
                problems.add(mark, f"unsupported YAML tag {ev.tag!r}")
            container: YDict | YList
            if is_map:
                container = YDict()
                container.key_marks, container.value_marks = {}, {}
            else:
                container = YList()
                container.item_marks = []
            container.mark = mark
            stack.append(_Frame(container, ev.anchor))
            continue
        elif cls is yaml.MappingEndEvent or cls is yaml.SequenceEndEvent:
            frame = stack.pop()
            value, size = frame.value, frame.size
            mark = value.mark
            if frame.merges:
                _apply_merges(value, frame.merges, problems)
            if frame.anchor is not None:
                anchors[frame.anchor] = (value, size)
        elif cls is yaml.AliasEvent:
            mark = _mark(name, ev.start_mark)
            aliases += 1
            if aliases > MAX_ALIASES:
                raise InputError.at(mark, f"more than {MAX_ALIASES} aliases (YAML alias bomb?)")
            if ev.anchor not in anchors:
                raise InputError.at(mark, f"malformed YAML: found undefined or recursive alias {ev.anchor!r}")
            value, size = anchors[ev.anchor]
        elif cls is yaml.DocumentStartEvent:
            docs += 1
            if docs > 1:
                raise InputError.at(_mark(name, ev.start_mark), "more than one YAML document in the file")
            continue
        else:
            continue
        if not stack:
            root = value
            continue
        parent = stack[-1]
        parent.size += size
        if parent.size > MAX_NODES:
            raise InputError.at(mark, f"more than {MAX_NODES} YAML nodes after alias expansion (YAML alias bomb?)")
        pv = parent.value
        if isinstance(pv, YList):
            pv.append(value)
            pv.item_marks.append(mark)
        elif parent.key is _NO_KEY:
            if cls is not yaml.ScalarEvent and cls is not yaml.AliasEvent or isinstance(value, (dict, list)):
                problems.add(mark, "mapping keys must be plain scalars")
                parent.key, parent.key_mark = None, mark
                continue
            if cls is yaml.ScalarEvent and not ev.style and ev.value == "<<" and ev.tag is None:
                parent.key, parent.key_mark = _MERGE_TAG, mark
                continue
            parent.key = value if isinstance(value, str) else str(value)
            parent.key_mark = mark
        else:
            key, kmark = parent.key, parent.key_mark
            parent.key = _NO_KEY
            if key is None:  # a rejected (non-scalar) key: drop its value
                continue
            if key is _MERGE_TAG:
                parent.merges.append((value, mark))
                continue
            assert kmark is not None
            if key in pv:
                problems.add(kmark, f"duplicate key {key!r} (first at line {pv.key_marks[key].line})")
                continue
            pv[key] = value
            pv.key_marks[key] = kmark
            pv.value_marks[key] = mark
    problems.raise_if_any()
    return root


def _apply_merges(target: YDict, merges: list[tuple[Any, Mark]], problems: Problems) -> None:
    """YAML merge keys (``<<: *base`` or ``<<: [*a, *b]``): explicit keys win, then the
    first merged mapping that has the key."""
    for value, mark in merges:
        sources = value if isinstance(value, list) else [value]
        for src in sources:
            if not isinstance(src, YDict):
                problems.add(mark, "a merge key (<<) expects a mapping or a list of mappings")
                continue
            for k, v in src.items():
                if k not in target:
                    target[k] = v
                    target.key_marks[k] = src.key_mark(k)
                    target.value_marks[k] = src.value_mark(k)


def _scalar_event(ev: yaml.ScalarEvent, mark: Mark, ctor: _Constructor, problems: Problems) -> Any:
    tag = ev.tag
    if tag is None or tag == "!":
        if ev.style or tag == "!" or not ev.implicit[0]:
            return ev.value
        tag = _resolve_plain(ev.value)
        if tag == _STR_TAG or tag == _MERGE_TAG:  # "<<" is handled by the mapping builder
            return ev.value
    elif tag == _STR_TAG:
        return ev.value
    node = yaml.ScalarNode(tag, ev.value, ev.start_mark, ev.end_mark, ev.style)
    try:
        return ctor.construct_object(node, deep=True)
    except yaml.constructor.ConstructorError as e:
        problems.add(mark, f"unsupported YAML value: {e.problem}")
    except (ValueError, OverflowError) as e:
        problems.add(mark, f"bad scalar value: {e}")
    return None


# --------------------------------------------------------------------------- binding


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin is Annotated:
        base, *meta = typing.get_args(tp)
        return _type_name(base) + (" or .inf" if MAY_BE_INFINITE in meta else "")
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
        refuse_nonfinite(value, mark, path, problems)
        return value
    if origin is Annotated:
        base, *meta = typing.get_args(tp)
        if base is float:
            return _bind_float(value, mark, where, problems, allow_inf=MAY_BE_INFINITE in meta)
        return bind(base, value, mark, path, problems)
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
        return _bind_float(value, mark, where, problems, allow_inf=False)
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


def _yaml_number(x: float) -> str:
    """``x`` as YAML spells it when it is not finite (``.nan``, ``.inf``, ``-.inf``)."""
    if math.isnan(x):
        return ".nan"
    if math.isinf(x):
        return ".inf" if x > 0 else "-.inf"
    return repr(x)


def _bind_float(value: Any, mark: Mark, where: str, problems: Problems, *, allow_inf: bool) -> float | None:
    """A finite float from an int or float (``allow_inf``: +-infinity too; NaN never)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        problems.add(mark, f"{where}expected a number, got {value!r}")
        return None
    try:
        x = float(value)
    except OverflowError:  # an integer with hundreds of digits
        problems.add(mark, f"{where}expected a finite number, got an integer too large for a float")
        return None
    if math.isnan(x) or (math.isinf(x) and not allow_inf):
        problems.add(mark, f"{where}expected a finite number, got {_yaml_number(x)}")
        return None
    return x


def refuse_nonfinite(value: Any, mark: Mark, path: str, problems: Problems) -> None:
    """Record a problem at each NaN or infinity inside untyped loaded data (a free-form
    profile, a backend section bound later by its builder): nothing declares that such
    data may be infinite. Iterative; a value shared through YAML aliases is one problem."""
    stack: list[tuple[Any, Mark, str]] = [(value, mark, path)]
    seen: set[int] = set()
    while stack:
        v, m, p = stack.pop()
        if isinstance(v, float):
            if not math.isfinite(v) and all(q.mark != m for q in problems):  # once per place in the file
                problems.add(m, f"{p + ': ' if p else ''}expected a finite number, got {_yaml_number(v)}")
            continue
        if not isinstance(v, (dict, list)) or id(v) in seen:
            continue
        seen.add(id(v))
        if isinstance(v, dict):
            vm = getattr(v, "value_marks", {})
            stack.extend((x, vm.get(k, m), f"{p}.{k}" if p else str(k)) for k, x in v.items())
        else:
            im = getattr(v, "item_marks", [])
            stack.extend((x, im[i] if i < len(im) else m, f"{p}[{i}]") for i, x in enumerate(v))


def _bind_dataclass(tp: type, value: Any, mark: Mark, path: str, problems: Problems) -> Any:
    where = f"{path}: " if path else ""
    if value is None:
        value = YDict()
        value.mark, value.key_marks, value.value_marks = mark, {}, {}
    if not isinstance(value, Mapping):
        problems.add(mark, f"{where}expected a mapping, got {value!r}")
        return None
    hints = typing.get_type_hints(tp, include_extras=True)
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
