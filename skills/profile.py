"""The robot profile's schema: each skill package declares the sections it reads.

A run config's ``profile:`` mapping holds robot-specific values that skills read (named
arm poses, the base's home, the fetch mission's settings). Each top-level key is a
*section* that some skill package declares here, with its type, unit and meaning, so
the whole profile is checked in one place when the config loads (``mmexec validate``,
``mmexec run``): unknown sections and keys (with a did-you-mean hint), wrong types and
values out of range are reported as ``FILE:LINE:COL: profile.key: message``, all at once,
before any skill runs.

A section's schema is a frozen dataclass (or any type :func:`mmexec.config.yamlload.bind`
understands). Its fields carry their unit, range and meaning through :func:`setting`::

    from dataclasses import dataclass
    from mmexec.skills.profile import declare_section, setting

    @dataclass(frozen=True)
    class DockSettings:
        speed: float = setting(0.1, unit="m/s", gt=0, le=0.5, doc="docking speed")
        stop: tuple[float, float, float] = setting((0.0, 0.0, 0.0), unit="m, m, rad",
                                                   base_pose=True, doc="where the base docks")

    declare_section("dock", DockSettings, package=__name__, doc="docking skills")

Ranges are checked on the values as written (the mark of each value is kept); checks
that relate several keys stay in the dataclass's ``validate()`` method. ``refers_to``
marks a name that must be a key of another section (``stow: tuck`` names one of the
``named_poses``), checked with a did-you-mean, its default included. ``base_pose``
marks ``[x, y, theta]`` base poses in ``map`` [m, m, rad] (single, list or mapping of
them): ``mmexec validate --config`` checks each is inside the map, free for the robot's
footprint and reachable from ``home`` (:func:`base_poses`).

The sections every robot profile may hold (``home``, ``places``, ``named_poses``: read by
the primitive skills and the general skills alike) are declared by this module; the
general skill modules declare theirs (``nav``, ``arm``, ``camera``, ``search``), the fetch
package ``fetch``. A skill reads a section through :func:`section` (bound, checked, its
defaults when the profile has none). A setting that moved to another section is recorded
with :meth:`ProfileSchema.move`, so a config that still writes it at the old place gets a
located problem whose hint names the new place.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

from mmexec.config.yamlload import Mark, Problems, YDict, bind, did_you_mean, mark_of
from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import FailureKind, SkillContext, SkillFailure

__all__ = [
    "PROFILE",
    "Bounds",
    "NamedPose",
    "ProfileSchema",
    "ProfileSection",
    "base_poses",
    "declare_section",
    "declare_settings",
    "section",
    "setting",
]

#: ``setting`` metadata keys
_BOUNDS, _UNIT, _DOC, _POSE, _REF = "mmexec.bounds", "mmexec.unit", "mmexec.doc", "mmexec.base_pose", "mmexec.refers_to"


@dataclass(frozen=True)
class Bounds:
    """A numeric range: ``gt`` / ``ge`` lower and ``lt`` / ``le`` upper bounds (None: open).
    A bounded value must also be finite."""

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None

    def describe(self) -> str:
        """``"> 0"``, ``"in (0, 1]"``, ``"in [1, 180]"``, ``">= 0"``, ``"<= 5"``."""
        lo = f"({self.gt:g}" if self.gt is not None else f"[{self.ge:g}" if self.ge is not None else None
        hi = f"{self.lt:g})" if self.lt is not None else f"{self.le:g}]" if self.le is not None else None
        if lo and hi:
            return f"in {lo}, {hi}"
        if lo:
            return f"{'>' if self.gt is not None else '>='} {lo[1:]}"
        if hi:
            return f"{'<' if self.lt is not None else '<='} {hi[:-1]}"
        return "a finite number"

    def admits(self, value: float) -> bool:
        """True when ``value`` is finite and within every bound (NaN never is)."""
        return (math.isfinite(value)
                and (self.gt is None or value > self.gt) and (self.ge is None or value >= self.ge)
                and (self.lt is None or value < self.lt) and (self.le is None or value <= self.le))


def setting(
    default: Any = dataclasses.MISSING,
    *,
    unit: str = "",
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    base_pose: bool = False,
    refers_to: str | None = None,
    doc: str = "",
) -> Any:
    """A dataclass field of a profile section with its ``unit``, range and ``doc``.

    No ``default``: the key is required. A list default is copied for each instance. A
    range applies to a number or to every number of a list (``item_size > 0``).
    ``base_pose``: the value is a base pose ``[x, y, theta]`` in ``map`` [m, m, rad], or
    a list of them. ``refers_to``: the value (a string; None means unused) is a key of
    the profile section of that name."""
    metadata = {_UNIT: unit, _DOC: doc, _POSE: base_pose, _REF: refers_to}
    if any(b is not None for b in (gt, ge, lt, le)):
        metadata[_BOUNDS] = Bounds(gt, ge, lt, le)
    if isinstance(default, list):
        frozen = tuple(default)
        return dataclasses.field(default_factory=lambda: list(frozen), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


@dataclass(frozen=True)
class ProfileSection:
    """One top-level key of the profile: its ``schema`` (a dataclass or a type), the
    ``package`` that reads it, what it is (``doc``), its ``unit`` when it is a plain value,
    and whether it holds ``base_pose`` values (see :func:`setting`)."""

    key: str
    schema: Any
    package: str
    doc: str
    unit: str = ""
    base_pose: bool = False


@dataclass(frozen=True)
class NamedPose:
    """A base pose the profile names: dotted ``path`` (``profile.fetch.depot.base``),
    where its value is written (``mark``) and the ``pose`` in ``map`` [m, m, rad]."""

    path: str
    mark: Mark
    pose: Pose2D


class ProfileSchema:
    """The declared profile sections (one instance, :data:`PROFILE`, serves a run)."""

    def __init__(self) -> None:
        self._sections: dict[str, ProfileSection] = {}
        self._moved: dict[tuple[str, str], str] = {}

    def declare(self, key: str, schema: Any, *, package: str, doc: str, unit: str = "",
                base_pose: bool = False) -> ProfileSection:
        """Declare section ``key``. Declaring it again with the same schema (a module
        imported twice, two packages reading the same section) is allowed; a different
        schema for a declared key is a programming error (ValueError)."""
        section = ProfileSection(key, schema, package, doc, unit, base_pose)
        old = self._sections.get(key)
        if old is not None and (old.schema != schema or old.base_pose != base_pose):
            raise ValueError(f"profile section {key!r} is already declared by {old.package} with another schema")
        if old is None:
            self._sections[key] = section
        return self._sections[key]

    def sections(self) -> Mapping[str, ProfileSection]:
        """The declared sections by key."""
        return types.MappingProxyType(self._sections)

    def move(self, old: str, new: str) -> None:
        """Record that setting ``old`` (``SECTION.KEY`` below ``profile``, e.g.
        ``fetch.search_locations``) now lives at ``new`` (e.g. ``search.locations``): a
        profile that still writes ``old`` gets an unknown-key problem at it whose hint names
        ``new``, and the rest of the section binds as if ``old`` were not there."""
        key, _, setting_name = old.partition(".")
        if not setting_name or "." in setting_name:
            raise ValueError(f"a moved setting is SECTION.KEY, got {old!r}")
        self._moved[(key, setting_name)] = new

    def _without_moved(self, key: str, raw: Any, mark: Mark, problems: Problems, path: str) -> Any:
        """``raw`` (section ``key`` as written) without its moved settings, each reported."""
        if not isinstance(raw, Mapping) or not any((key, k) in self._moved for k in raw):
            return raw
        key_marks = getattr(raw, "key_marks", {})
        value_marks = getattr(raw, "value_marks", {})
        rest = YDict()
        rest.mark, rest.key_marks, rest.value_marks = mark_of(raw, mark), {}, {}
        for k, v in raw.items():
            new = self._moved.get((key, k))
            if new is not None:
                problems.add(key_marks.get(k, mark),
                             f"{path}.{key}.{k}: unknown key; did you mean '{path}.{new}'? (the setting moved there)")
                continue
            rest[k] = v
            rest.key_marks[k], rest.value_marks[k] = key_marks.get(k, mark), value_marks.get(k, mark)
        return rest

    def bind_section(self, key: str, raw: Any, mark: Mark, problems: Problems, path: str = "profile") -> Any:
        """Bind the value of declared section ``key`` and check its ranges, adding every
        problem to ``problems`` (a moved setting too: :meth:`move`). Returns the bound
        value, or None when it has problems."""
        section = self._sections[key]
        sub = f"{path}.{key}"
        before = len(problems)
        raw = self._without_moved(key, raw, mark, problems, path)
        out = bind(section.schema, raw, mark, sub, problems)
        _check_bounds(section.schema, raw, mark, sub, problems)
        return out if len(problems) == before else None

    def check(self, profile: Mapping[str, Any], mark: Mark, path: str = "profile") -> tuple[dict[str, Any], Problems]:
        """Check a whole profile mapping (as loaded, with marks; ``mark`` is where it
        starts). Returns the bound value of every section without problems, and the
        problems (unknown sections with a hint, and each section's own)."""
        problems = Problems()
        bound: dict[str, Any] = {}
        key_marks = getattr(profile, "key_marks", {})
        value_marks = getattr(profile, "value_marks", {})
        known = sorted(self._sections)
        for key, raw in profile.items():
            if key not in self._sections:
                hint = (did_you_mean(key, known) or self._nested_hint(key)
                        or f" (no loaded skill package declares it; declared: {', '.join(known) or 'none'})")
                problems.add(key_marks.get(key, mark), f"{path}.{key}: unknown profile section{hint}")
                continue
            out = self.bind_section(key, raw, value_marks.get(key, mark), problems, path)
            if out is not None:
                bound[key] = out
        for key, raw in profile.items():
            if key in self._sections:
                _check_refs(self._sections[key].schema, bound.get(key), raw, value_marks.get(key, mark),
                            f"{path}.{key}", profile, problems)
        return bound, problems

    def _nested_hint(self, key: str) -> str:
        """``"; did you mean 'arm.tcp_offset'?"`` when a declared section has a
        setting named (about) ``key`` at a deeper level, else ``""``."""
        paths = {".".join(p): p[-1] for s in self._sections.values() for p in _setting_paths(s.schema, (s.key,))}
        hit = did_you_mean(key, set(paths.values()))
        if not hit:
            return ""
        name = hit.split("'")[1]
        return f"; did you mean {', '.join(repr(p) for p, leaf in sorted(paths.items()) if leaf == name)}?"

    def base_poses(self, profile: Mapping[str, Any], mark: Mark, path: str = "profile") -> list[NamedPose]:
        """Every base pose in ``map`` that the profile names, in file order: the values of
        sections and settings declared ``base_pose`` that are well-formed (three numbers;
        malformed ones are :meth:`check`'s to report)."""
        out: list[NamedPose] = []
        value_marks = getattr(profile, "value_marks", {})
        for key, raw in profile.items():
            section = self._sections.get(key)
            if section is not None:
                out.extend(_poses(section.schema, raw, value_marks.get(key, mark), f"{path}.{key}", section.base_pose))
        return sorted(out, key=lambda p: (p.mark.line, p.mark.col))


# --------------------------------------------------------------------------- walking raw values


def _unwrap(tp: Any) -> Any:
    """``X`` for ``X | None``."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return tp


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _value_mark(raw: Any, key: Any, default: Mark) -> Mark:
    if isinstance(key, int):
        marks = getattr(raw, "item_marks", [])
        return marks[key] if 0 <= key < len(marks) else default
    return getattr(raw, "value_marks", {}).get(key, default)


def _dataclass_fields(tp: Any, raw: Any, mark: Mark) -> Iterator[tuple[dataclasses.Field[Any], Any, Any, Mark]]:
    """(field, its type, its raw value, the value's mark) of each key of a dataclass
    section present in ``raw``."""
    if not (dataclasses.is_dataclass(tp) and isinstance(tp, type) and isinstance(raw, Mapping)):
        return
    hints = typing.get_type_hints(tp)
    for f in dataclasses.fields(tp):
        if f.name in raw:
            yield f, hints[f.name], raw[f.name], _value_mark(raw, f.name, mark)


def _setting_paths(tp: Any, prefix: tuple[str, ...]) -> Iterator[tuple[str, ...]]:
    """The key path of every setting below dataclass ``tp`` (nested sections included)."""
    tp = _unwrap(tp)
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        hints = typing.get_type_hints(tp)
        for f in dataclasses.fields(tp):
            yield (*prefix, f.name)
            yield from _setting_paths(hints[f.name], (*prefix, f.name))


def _check_bounds(tp: Any, raw: Any, mark: Mark, path: str, problems: Problems) -> None:
    """Range problems of ``raw`` against the :func:`setting` bounds of dataclass ``tp``
    (recursing into nested sections). Values that are not numbers are left to bind()."""
    for f, ftype, value, vmark in _dataclass_fields(_unwrap(tp), raw, mark):
        sub = f"{path}.{f.name}"
        bounds: Bounds | None = f.metadata.get(_BOUNDS)
        if bounds is not None:
            unit = f" {f.metadata.get(_UNIT)}".rstrip()
            items = [(sub, value, vmark)] if not isinstance(value, list) else [
                (f"{sub}[{i}]", v, _value_mark(value, i, vmark)) for i, v in enumerate(value)]
            for where, v, m in items:
                if _is_number(v) and not bounds.admits(float(v)):
                    problems.add(m, f"{where}: expected {bounds.describe()}{unit}, got {v!r}")
        _check_bounds(ftype, value, vmark, sub, problems)


def _check_refs(tp: Any, bound: Any, raw: Any, mark: Mark, path: str, profile: Mapping[str, Any],
                problems: Problems) -> None:
    """Problems of the :func:`setting` ``refers_to`` names of a section: each must be a key
    of the profile section it refers to. ``bound`` is the bound section, whose defaults are
    then checked too (located at the nearest mapping written in the file); None when it
    did not bind, and then only the names written in ``raw`` are checked."""
    tp = _unwrap(tp)
    if not (dataclasses.is_dataclass(tp) and isinstance(tp, type)):
        return
    hints = typing.get_type_hints(tp)
    for f in dataclasses.fields(tp):
        written = isinstance(raw, Mapping) and f.name in raw
        value = getattr(bound, f.name) if bound is not None else raw[f.name] if written else None
        vmark = _value_mark(raw, f.name, mark) if written else mark
        target = f.metadata.get(_REF)
        if target is not None and isinstance(value, str):
            keys = profile.get(target)
            names = sorted(keys) if isinstance(keys, Mapping) else []
            if value not in names:
                where = "" if written else " (the default)"
                problems.add(vmark, f"{path}.{f.name}: {value!r}{where} is not one of profile.{target}"
                             + (did_you_mean(value, names) or f" (known: {', '.join(names) or 'none'})"))
        _check_refs(hints[f.name], value if bound is not None else None, raw.get(f.name) if written else None,
                    vmark, f"{path}.{f.name}", profile, problems)


def _as_pose(raw: Any) -> Pose2D | None:
    if isinstance(raw, list) and len(raw) == 3 and all(_is_number(v) and math.isfinite(v) for v in raw):
        return Pose2D(float(raw[0]), float(raw[1]), float(raw[2]))
    return None


def _poses(tp: Any, raw: Any, mark: Mark, path: str, is_pose: bool) -> list[NamedPose]:
    """The well-formed base poses in ``raw`` whose schema ``tp`` marks them (``is_pose``
    for the value itself: a pose, a list or a mapping of poses)."""
    tp = _unwrap(tp)
    if is_pose:
        pose = _as_pose(raw)
        if pose is not None:
            return [NamedPose(path, mark, pose)]
        if isinstance(raw, list):
            return [p for i, v in enumerate(raw) for p in _poses(Any, v, _value_mark(raw, i, mark), f"{path}[{i}]", True)]
        if isinstance(raw, Mapping):
            return [p for k, v in raw.items() for p in _poses(Any, v, _value_mark(raw, k, mark), f"{path}.{k}", True)]
        return []
    return [p for f, ftype, value, vmark in _dataclass_fields(tp, raw, mark)
            for p in _poses(ftype, value, vmark, f"{path}.{f.name}", bool(f.metadata.get(_POSE)))]


# --------------------------------------------------------------------------- the schema


#: The profile schema of this process: the built-in sections below, those of the general
#: skill modules and the fetch package, and whatever user skill modules declare.
PROFILE = ProfileSchema()

declare_section = PROFILE.declare

#: (section key, id of its raw value) -> (the raw value, kept so its id stays unique; bound value)
_BOUND: dict[tuple[str, int], tuple[Any, Any]] = {}


def section(profile: Mapping[str, Any], key: str) -> Any:
    """The bound value of declared section ``key`` of a robot profile (a config's, or one
    set up in code): the schema's defaults when the profile has no such section.
    SkillFailure(PRECONDITION) with the first problem, ``FILE:LINE:COL: profile.KEY...``
    when the profile came from a file (a config checked at load cannot be wrong here; a
    profile set up in code, as in tests, can). Bound values are cached per raw value."""
    raw = profile.get(key) if isinstance(profile, Mapping) else None
    cached = _BOUND.get((key, id(raw)))
    if cached is not None and cached[0] is raw:
        return cached[1]
    problems = Problems()
    out = PROFILE.bind_section(key, raw, mark_of(raw, Mark("<profile>", 1, 1)), problems)
    if problems:
        raise SkillFailure(FailureKind.PRECONDITION, str(problems[0]))
    _BOUND[(key, id(raw))] = (raw, out)
    return out


S = TypeVar("S")


def declare_settings(key: str, schema: type[S], *, package: str, doc: str) -> Callable[[SkillContext], S]:
    """Declare section ``key`` (a dataclass ``schema`` whose settings all have defaults)
    and return the function its skills read it with: ``reader(ctx)`` is the bound
    section of ``ctx.profile`` (:func:`section`: its defaults when the profile has none,
    SkillFailure(PRECONDITION) when it is wrong)."""
    declare_section(key, schema, package=package, doc=doc)

    def reader(ctx: SkillContext) -> S:
        out = section(ctx.profile, key)
        assert isinstance(out, schema)
        return out

    reader.__doc__ = f"The bound ``profile.{key}`` section ({doc}; defaults when the profile has none)."
    return reader


def base_poses(profile: Mapping[str, Any], mark: Mark) -> list[NamedPose]:
    """:meth:`ProfileSchema.base_poses` of :data:`PROFILE`."""
    return PROFILE.base_poses(profile, mark)


declare_section("home", tuple[float, float, float], package="mmexec.skills", unit="m, m, rad", base_pose=True,
                doc="the base's home pose [x, y, theta] in map (navigate / drive_to goal 'home')")
declare_section("places", dict[str, tuple[float, float, float]], package="mmexec.skills", unit="m, m, rad",
                base_pose=True, doc="more named base poses [x, y, theta] in map (navigate / drive_to goals)")
declare_section("named_poses", dict[str, list[float]], package="mmexec.skills", unit="rad",
                doc="arm joint poses by name, in the arm's joint order (move_arm pose, arm roles)")
