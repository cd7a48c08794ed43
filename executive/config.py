"""Run configuration: which backend, its options, the robot profile, user skill modules.

A run config is YAML loaded through :mod:`mmexec.config.yamlload` and bound into
:class:`RunConfig`, so every problem is reported as ``FILE:LINE:COL: key: message``::

    backend: mock            # a registered backend (mmexec.executive.backends): mock | sim | robot
    rate_hz: 20              # tick rate [Hz of clock time], 1..1000
    mock: {...}              # options for the backend named by `backend` (one section
    sim: {...}               #   per backend name; only the selected one is read)
    profile:                 # robot profile read by skills: each section is declared by
      named_poses: {home: [0, 0, 0, 0, 0, 0]}   #   the skill package that reads it
      home: [0.0, 0.0, 0.0]                      #   (mmexec.skills.profile), checked at load
    skills:
      modules: [my_lab.skills]   # user skill modules to import (the ONLY way user code loads)
      paths: [.]                 # folders put in front of the import path first (relative to
                                 #   this file, inside its folder tree or a root)
    roots: [../shared]           # more folders includes and sim worlds may come from

No number in a config may be NaN or infinite (:func:`~mmexec.config.yamlload.bind`).
The keys a config may have follow the registry of backends
(:data:`mmexec.executive.backends.BACKENDS`): ``backend`` names one of them and each has
its section. The named backend's :class:`~mmexec.drivers.backendspec.BackendSpec` is
loaded with the config (:attr:`LoadedConfig.spec`) and answers every question about it:
its section's files are checked here, :func:`build_robot` calls its builder with the
section still as a :class:`~mmexec.config.yamlload.YDict` so it can report positions.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib
import logging
import os
import sys
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from mmexec.config.yamlload import (
    InputError,
    Mark,
    Problem,
    Problems,
    YDict,
    bind,
    is_within,
    load_yaml_bytes,
    read_file,
)
from mmexec.drivers.backendspec import CAPABILITIES, BackendSpec
from mmexec.drivers.interfaces import Robot
from mmexec.executive.backends import backend_spec, names, specs
from mmexec.skills.base import REGISTRY, SkillRegistry

__all__ = [
    "CAPABILITIES",
    "LoadedConfig",
    "RunConfig",
    "SkillsConfig",
    "add_import_paths",
    "build_robot",
    "check_options",
    "check_profile",
    "load_config",
    "load_skill_modules",
    "profile_problems",
    "robot_capabilities",
]

log = logging.getLogger(__name__)

#: Run option (``mmexec run --gui / --record``, :data:`~mmexec.drivers.backendspec.OPTIONS`)
#: -> (its command-line flag, what it does). Each backend declares the options it honours
#: (:attr:`BackendSpec.options`); asking a backend for one it cannot honour is an input
#: error, not silently ignored.
_OPTION_FLAGS: dict[str, tuple[str, str]] = {
    "gui": ("--gui", "the simulator window"),
    "record": ("--record", "a video of the simulation"),
}

#: Modules that define the built-in skills, imported before any user module: the
#: primitives, operator prompts, the general skill library, the fetch mission's own.
BUILTIN_SKILL_MODULES: tuple[str, ...] = (
    "mmexec.skills.perception.scan",
    "mmexec.skills.primitives", "mmexec.skills.operator", "mmexec.skills.navigation.navigate",
    "mmexec.skills.navigation.approach", "mmexec.skills.search", "mmexec.skills.perception.detect",
    "mmexec.skills.manipulation.arm", "mmexec.skills.fetch", "mmexec.skills.localization.skill",
    "mmexec.skills.buttons",
    "mmexec.skills.manipulation.holistic_skill",
    "mmexec.skills.fruit",
)


#: Tick rates a config or ``--rate`` may ask for [Hz of clock time].
MIN_RATE_HZ, MAX_RATE_HZ = 1.0, 1000.0


@dataclass(frozen=True)
class SkillsConfig:
    """``skills:`` section: ``modules`` are imported (in order) to register user skills;
    ``paths`` are folders (relative to the config file) put in front of the import path
    first, so modules next to the config load without PYTHONPATH."""

    modules: list[str] = field(default_factory=list)
    paths: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class RunConfig:
    """A run config file (see the module doc), without its backend sections (the selected
    one is :meth:`LoadedConfig.section`, bound by the backend itself)."""

    #: the backend to run on: a name of :data:`mmexec.executive.backends.BACKENDS`
    backend: str
    rate_hz: float = 20.0
    profile: dict[str, Any] = field(default_factory=dict)
    skills: SkillsConfig = field(default_factory=SkillsConfig)
    #: ``mmexec serve`` settings (token file, CORS origins, body cap, stream rates), bound
    #: by :func:`mmexec.executive.serve.settings.parse_section`
    serve: Any = None
    #: the localiser (AMCL on the robot's lidar and odometry, docs/localization.md), bound
    #: by :func:`mmexec.skills.localization.localizer.parse_section`; None: odometry only
    localization: Any = None
    #: more folders (relative to the config file) that mission includes and world files
    #: may come from, besides the mission's folder, trees/ and sim/worlds/
    roots: list[str] = field(default_factory=list)

    def validate(self) -> list[str]:
        if not MIN_RATE_HZ <= self.rate_hz <= MAX_RATE_HZ:
            return [f"rate_hz: expected a tick rate in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {self.rate_hz:g}"]
        return []


@functools.cache
def _file_schema(backends: tuple[str, ...]) -> type:
    """The dataclass a config file binds to: :class:`RunConfig`'s keys in order, with
    ``backend`` one of ``backends`` and a section (any mapping, bound later by its backend)
    per backend name after ``skills``, so unknown keys, hints and the ``backend`` choices
    follow the registry."""
    hints = typing.get_type_hints(RunConfig)
    fields: list[tuple[str, Any, Any]] = []
    for f in dataclasses.fields(RunConfig):
        kind = Literal[backends] if f.name == "backend" else hints[f.name]
        fields.append((f.name, kind, field(default=f.default, default_factory=f.default_factory)))
        if f.name == "skills":
            fields.extend((name, Any, field(default=None)) for name in backends)
    return dataclasses.make_dataclass("RunConfigFile", fields, frozen=True)


@dataclass(frozen=True)
class LoadedConfig:
    """A bound config plus where it came from (path, sha256 of its bytes, raw YAML) and
    the spec of the backend it names."""

    path: Path
    sha256: str
    config: RunConfig
    raw: YDict
    spec: BackendSpec[Any]

    @property
    def backend(self) -> str:
        return self.config.backend

    def section(self) -> YDict | None:
        """The selected backend's section, as loaded (with marks), or None."""
        value = self.raw.get(self.config.backend)
        return value if isinstance(value, YDict) else None

    def mark(self, key: str) -> Mark:
        """Where ``key``'s value is in the file (the file start if absent)."""
        return self.raw.value_mark(key)

    def relocate(self, error: InputError) -> InputError:
        """``error`` with the problems a backend could only place at ``<...>`` (it was
        given no section) moved to the config's ``backend:``."""
        where = self.mark("backend")
        return InputError(Problem(where, p.message) if p.mark.file.startswith("<") else p for p in error.problems)

    def capabilities(self) -> frozenset[str]:
        """The capabilities the configured robot will have, found from the section alone
        by the backend (:attr:`BackendSpec.capabilities`): nothing is opened, connected
        or started. InputError for a bad section."""
        try:
            return self.spec.section_capabilities(self.section())
        except InputError as e:
            raise self.relocate(e) from None

    @property
    def roots(self) -> tuple[Path, ...]:
        """The config's ``roots:``, resolved against the config file's folder."""
        return tuple(Path(os.path.realpath(self.path.parent / r)) for r in self.config.roots)

    @property
    def skill_paths(self) -> tuple[Path, ...]:
        """The config's ``skills.paths``, resolved against the config file's folder."""
        return tuple(Path(os.path.realpath(self.path.parent / p)) for p in self.config.skills.paths)


def _check_paths(path: Path, cfg: RunConfig, raw: YDict, spec: BackendSpec[Any] | None, problems: Problems) -> None:
    """Each ``roots:`` entry is a folder; each ``skills.paths`` entry is a folder inside the
    config's folder tree or a root; a file the backend's section names by path
    (:attr:`BackendSpec.files`: the sim's ``world``) lies inside the config's folder tree,
    the folder the backend ships such files in, trees/ or a root (it is never opened
    otherwise)."""
    roots_raw = raw.get("roots")
    roots = [Path(os.path.realpath(path.parent / r)) for r in cfg.roots]
    for i, root in enumerate(roots):
        if not root.is_dir():
            problems.add(roots_raw.item_mark(i), f"roots[{i}]: {cfg.roots[i]!r} is not a folder ({root})")
    own = (Path(os.path.realpath(path)).parent, *roots)
    skills_raw = raw.get("skills")
    for i, entry in enumerate(cfg.skills.paths):
        folder = Path(os.path.realpath(path.parent / entry))
        mark = skills_raw["paths"].item_mark(i)
        if not is_within(folder, own):
            problems.add(mark, f"skills.paths[{i}]: {entry!r} is outside the folders skill modules may come from "
                         f"({', '.join(map(str, own))}); name its folder in 'roots:' to allow it")
        elif not folder.is_dir():
            problems.add(mark, f"skills.paths[{i}]: {entry!r} is not a folder ({folder})")
    section = raw.get(cfg.backend)
    for file in spec.files if spec is not None and isinstance(section, YDict) else ():
        value = section.get(file.key)
        if not (isinstance(value, str) and file.is_path(value)):
            continue
        from mmexec.executive.compiler import TREES_DIR

        allowed = (Path(os.path.realpath(path)).parent, *file.shipped, TREES_DIR, *roots)
        if not is_within(value, allowed):
            problems.add(section.value_mark(file.key), f"{cfg.backend}.{file.key}: {value!r} is outside the folders "
                         f"{file.what} may come from ({', '.join(map(str, allowed))}); name its folder in 'roots:' "
                         "to allow it")


def load_config(path: str | Path) -> LoadedConfig:
    """Load and bind a run config. Raises InputError with every problem located."""
    p = Path(path)
    data = read_file(p)
    raw = load_yaml_bytes(data, str(path))
    name = str(path)
    if not isinstance(raw, YDict):
        raise InputError.at(getattr(raw, "mark", Mark(name, 1, 1)),
                            f"expected a mapping with at least 'backend: {'|'.join(names())}'")
    problems = Problems()
    bound = bind(_file_schema(names()), raw, raw.mark, "", problems)
    cfg = None
    if bound is not None:
        cfg = RunConfig(**{f.name: getattr(bound, f.name) for f in dataclasses.fields(RunConfig)})
        for message in cfg.validate():
            problems.add(raw.mark, message)
    for key in names():
        value = raw.get(key)
        if value is not None and not isinstance(value, YDict):
            problems.add(raw.value_mark(key), f"{key}: expected a mapping of backend options, got {value!r}")
    problems.raise_if_any()
    assert cfg is not None
    spec: BackendSpec[Any] | None = None
    try:
        spec = backend_spec(cfg.backend, raw.value_mark("backend"))
    except InputError as e:
        problems.extend(e.problems)
    _check_paths(p, cfg, raw, spec, problems)
    try:
        settings = localization_settings(cfg, raw)
        if settings is not None and settings.enabled and spec is not None:
            section = raw.get(cfg.backend)
            missing = sorted({"base", "lidar"} - spec.section_capabilities(section if isinstance(section, YDict) else None))
            if missing:
                problems.add(raw.value_mark("localization"), f"localization: the localiser needs a "
                             f"{' and a '.join(missing)}, and backend {cfg.backend!r} has none here "
                             "(set localization.enabled: false)")
    except InputError as e:
        problems.extend(e.problems)
    problems.raise_if_any()
    assert spec is not None
    digest = hashlib.sha256(data).hexdigest()
    return LoadedConfig(p, digest, cfg, raw, spec)


def load_skill_modules(loaded: LoadedConfig | None, registry: SkillRegistry = REGISTRY, *,
                       check: bool = True) -> None:
    """Import the built-in skill modules, then the config's ``skills.modules`` (with its
    ``skills.paths`` in front of the import path: :func:`add_import_paths`); then,
    with ``check``, check the config's robot profile against the sections those modules
    declare (:func:`check_profile`).

    A module that fails to import (missing, syntax error, exception at import) is an
    InputError naming the module and its line in the config; all are reported together.
    """
    for module in BUILTIN_SKILL_MODULES:
        registry.load_module(module)
    if loaded is None:
        return
    add_import_paths(loaded.skill_paths)
    problems = Problems()
    skills_raw = loaded.raw.get("skills")
    modules_raw = skills_raw.get("modules") if isinstance(skills_raw, YDict) else None
    for i, module in enumerate(loaded.config.skills.modules):
        mark = modules_raw.item_mark(i) if hasattr(modules_raw, "item_mark") else loaded.mark("skills")
        try:
            registry.load_module(module)
        except ModuleNotFoundError as e:
            missing = e.name or module
            detail = "no such module" if missing == module else f"it imports {missing!r}, which is not installed"
            problems.add(mark, f"skills.modules[{i}]: cannot import {module!r}: {detail}")
        except SystemExit as e:  # user code calling sys.exit() at import must not end mmexec
            problems.add(mark, f"skills.modules[{i}]: cannot import {module!r}: it called sys.exit({e.code!r})")
        except Exception as e:  # noqa: BLE001 - user code: any import failure is a config problem
            where = ""
            if isinstance(e, SyntaxError) and e.filename:
                where = f" ({e.filename}:{e.lineno})"
            problems.add(mark, f"skills.modules[{i}]: cannot import {module!r}: {type(e).__name__}: {e}{where}")
    problems.raise_if_any()
    if check:
        check_profile(loaded)


def add_import_paths(folders: Sequence[Path]) -> None:
    """Put ``folders`` in front of ``sys.path``, in order, as PYTHONPATH would (a folder
    already there stays where it is); they stay for the rest of the process."""
    for folder in reversed(folders):
        if str(folder) not in sys.path:
            sys.path.insert(0, str(folder))
    importlib.invalidate_caches()


def profile_problems(loaded: LoadedConfig) -> list[Problem]:
    """Every problem of the config's ``profile:`` against the sections the loaded skill
    packages declare (:data:`mmexec.skills.profile.PROFILE`): unknown sections and keys
    with a hint, wrong types, values out of range. Import the skill modules first."""
    from mmexec.skills.profile import PROFILE

    raw = loaded.raw.get("profile")
    if not isinstance(raw, YDict):
        return []  # absent, or not a mapping (the RunConfig binding reports that)
    return list(PROFILE.check(raw, loaded.mark("profile"))[1])


def check_profile(loaded: LoadedConfig) -> None:
    """Raise InputError with every :func:`profile_problems` of the config."""
    problems = profile_problems(loaded)
    if problems:
        raise InputError(problems)


def build_robot(
    loaded: LoadedConfig, *, seed: int | None = None, options: Mapping[str, Any] | None = None
) -> Robot:
    """Build the configured backend (:attr:`BackendSpec.build`). InputError for a bad
    section or a run option the backend cannot honour; exceptions of the backend itself (a
    port that will not open) propagate."""
    opts = {"gui": False, "record": None}
    opts.update(options or {})
    check_options(loaded, opts)
    try:
        robot = loaded.spec.build(loaded.section(), profile=dict(loaded.config.profile), seed=seed, options=opts)
    except InputError as e:
        # a builder given no section (None) cannot know the file: point at `backend:`
        raise loaded.relocate(e) from None
    if not isinstance(robot, Robot):
        raise TypeError(f"backend {loaded.backend!r} builder returned {type(robot).__name__}, not a Robot")
    settings = localization_settings(loaded.config, loaded.raw)
    if settings is not None:
        from mmexec.skills.localization.localizer import localise_robot

        try:
            robot = localise_robot(robot, settings, seed=seed)
        except ValueError as e:
            robot.close()
            raise InputError.at(loaded.mark("localization"), f"localization: {e}") from None
    return robot


def localization_settings(cfg: RunConfig, raw: YDict) -> Any:
    """The config's ``localization:`` section bound
    (:class:`~mmexec.skills.localization.localizer.LocalizationSettings`), None without
    one; InputError with its problems located."""
    from mmexec.skills.localization.localizer import parse_section

    return parse_section(cfg.localization, raw.value_mark("localization"))


def check_options(loaded: LoadedConfig, options: Mapping[str, Any]) -> None:
    """InputError at the config's ``backend:`` for each run option set in ``options``
    (``gui`` true, ``record`` a path) that the backend does not honour
    (:attr:`BackendSpec.options`), naming the backends that do."""
    problems = Problems()
    for name, (flag, what) in _OPTION_FLAGS.items():
        if options.get(name) and name not in loaded.spec.options:
            able = [spec.name for spec in specs(loaded.mark("backend")) if name in spec.options]
            problems.add(loaded.mark("backend"), f"backend: {loaded.backend!r} cannot honour {flag} ({what}; only "
                         f"backend {', '.join(map(repr, able))} can): run without it or use a "
                         f"{' or '.join(able)} config")
    problems.raise_if_any()


def robot_capabilities(robot: Robot) -> frozenset[str]:
    """Names of the capabilities ``robot`` has (a subset of :data:`CAPABILITIES`)."""
    return frozenset(c for c in CAPABILITIES if getattr(robot, c, None) is not None)
