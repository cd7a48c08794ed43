"""Run configuration: which backend, its options, the robot profile, user skill modules.

A run config is YAML loaded through :mod:`mmexec.config.yamlload` and bound into
:class:`RunConfig`, so every problem is reported as ``FILE:LINE:COL: key: message``::

    backend: mock            # mock | sim | robot
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
The backend factory maps a backend name to a builder ``build(section, *, profile, seed,
options) -> Robot`` (see :data:`BACKENDS`); the section is passed still as a
:class:`~mmexec.config.yamlload.YDict` so the builder can report positions.
"""

from __future__ import annotations

import hashlib
import importlib
import logging
import os
import sys
from collections.abc import Callable, Mapping, Sequence
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
from mmexec.drivers.interfaces import Robot
from mmexec.skills.base import REGISTRY, SkillRegistry

__all__ = [
    "BACKENDS",
    "CAPABILITIES",
    "LoadedConfig",
    "RunConfig",
    "SkillsConfig",
    "add_import_paths",
    "backend_builder",
    "build_robot",
    "check_options",
    "check_profile",
    "load_config",
    "load_skill_modules",
    "profile_problems",
    "robot_capabilities",
]

log = logging.getLogger(__name__)

BackendName = Literal["mock", "sim", "robot"]

#: backend name -> ``module:function`` of its builder.
BACKENDS: dict[str, str] = {
    "mock": "mmexec.drivers.mock.backend:build",
    "sim": "mmexec.sim.backend:build",
    "robot": "mmexec.drivers.robot:build",
}

#: Run options (``mmexec run --gui / --record``) each backend honours; asking a backend
#: for one it cannot honour is an input error, not silently ignored.
BACKEND_OPTIONS: dict[str, frozenset[str]] = {
    "mock": frozenset(),
    "sim": frozenset({"gui", "record"}),
    "robot": frozenset(),
}
#: option -> (its command-line flag, what it does)
_OPTION_FLAGS: dict[str, tuple[str, str]] = {
    "gui": ("--gui", "the simulator window"),
    "record": ("--record", "a video of the simulation"),
}

#: Capability attribute names of :class:`~mmexec.drivers.interfaces.Robot`.
CAPABILITIES: tuple[str, ...] = ("base", "arm", "gripper", "camera", "lidar")

#: Modules that define the built-in skills, imported before any user module: the
#: primitives, operator prompts, the general skill library, the fetch mission's own.
BUILTIN_SKILL_MODULES: tuple[str, ...] = (
    "mmexec.skills.primitives", "mmexec.skills.operator", "mmexec.skills.navigation.navigate",
    "mmexec.skills.navigation.approach", "mmexec.skills.search", "mmexec.skills.perception.detect",
    "mmexec.skills.manipulation.arm", "mmexec.skills.fetch",
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
    """A run config file (see the module doc)."""

    backend: BackendName
    rate_hz: float = 20.0
    profile: dict[str, Any] = field(default_factory=dict)
    skills: SkillsConfig = field(default_factory=SkillsConfig)
    mock: Any = None
    sim: Any = None
    robot: Any = None
    #: ``mmexec serve`` settings (token file, CORS origins, body cap, stream rates), bound
    #: by :func:`mmexec.executive.serve.settings.parse_section`
    serve: Any = None
    #: more folders (relative to the config file) that mission includes and world files
    #: may come from, besides the mission's folder, trees/ and sim/worlds/
    roots: list[str] = field(default_factory=list)

    def validate(self) -> list[str]:
        if not MIN_RATE_HZ <= self.rate_hz <= MAX_RATE_HZ:
            return [f"rate_hz: expected a tick rate in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {self.rate_hz:g}"]
        return []


@dataclass(frozen=True)
class LoadedConfig:
    """A bound config plus where it came from (path, sha256 of its bytes, raw YAML)."""

    path: Path
    sha256: str
    config: RunConfig
    raw: YDict

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

    @property
    def roots(self) -> tuple[Path, ...]:
        """The config's ``roots:``, resolved against the config file's folder."""
        return tuple(Path(os.path.realpath(self.path.parent / r)) for r in self.config.roots)

    @property
    def skill_paths(self) -> tuple[Path, ...]:
        """The config's ``skills.paths``, resolved against the config file's folder."""
        return tuple(Path(os.path.realpath(self.path.parent / p)) for p in self.config.skills.paths)


def _check_paths(path: Path, cfg: RunConfig, raw: YDict, problems: Problems) -> None:
    """Each ``roots:`` entry is a folder; each ``skills.paths`` entry is a folder inside the
    config's folder tree or a root; a sim ``world`` given as a path lies inside the
    config's folder tree, trees/, sim/worlds/ or a root (it is never opened otherwise)."""
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
    world = cfg.sim.get("world") if cfg.backend == "sim" and isinstance(cfg.sim, dict) else None
    # sim.world reads a value with a '/' or a .yaml/.yml ending as a path (from the
    # current folder), anything else as the name of a shipped world
    if isinstance(world, str) and ("/" in world or world.endswith((".yaml", ".yml"))):
        from mmexec.executive.compiler import TREES_DIR
        from mmexec.sim.world import WORLDS_DIR

        allowed = (Path(os.path.realpath(path)).parent, WORLDS_DIR, TREES_DIR, *roots)
        if not is_within(world, allowed):
            problems.add(cfg.sim.value_mark("world"), f"sim.world: {world!r} is outside the folders a world may come "
                         f"from ({', '.join(map(str, allowed))}); name its folder in 'roots:' to allow it")


def load_config(path: str | Path) -> LoadedConfig:
    """Load and bind a run config. Raises InputError with every problem located."""
    p = Path(path)
    data = read_file(p)
    raw = load_yaml_bytes(data, str(path))
    name = str(path)
    if not isinstance(raw, YDict):
        raise InputError.at(getattr(raw, "mark", Mark(name, 1, 1)),
                            "expected a mapping with at least 'backend: mock|sim|robot'")
    problems = Problems()
    cfg = bind(RunConfig, raw, raw.mark, "", problems)
    for key in BACKENDS:
        value = raw.get(key)
        if value is not None and not isinstance(value, YDict):
            problems.add(raw.value_mark(key), f"{key}: expected a mapping of backend options, got {value!r}")
    problems.raise_if_any()
    assert isinstance(cfg, RunConfig)
    _check_paths(p, cfg, raw, problems)
    problems.raise_if_any()
    digest = hashlib.sha256(data).hexdigest()
    return LoadedConfig(p, digest, cfg, raw)


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


def backend_builder(name: str, mark: Mark) -> Callable[..., Robot]:
    """The builder function for backend ``name``; InputError (at ``mark``) when the
    backend is unknown or its module is not part of this installation."""
    target = BACKENDS.get(name)
    if target is None:
        raise InputError.at(mark, f"backend: unknown backend {name!r} (expected one of: {', '.join(BACKENDS)})")
    module_name, func = target.split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        if e.name and (module_name == e.name or module_name.startswith(e.name + ".")):
            raise InputError.at(
                mark, f"backend: {name!r} is not available in this installation (module {module_name} not found)"
            ) from None
        raise InputError.at(
            mark, f"backend: {name!r} cannot load: {module_name} needs {e.name!r}, which is not installed"
        ) from None
    builder = getattr(module, func, None)
    if not callable(builder):
        raise InputError.at(mark, f"backend: {name!r} is not available: {module_name} has no {func}()")
    return builder  # type: ignore[no-any-return]


def build_robot(
    loaded: LoadedConfig, *, seed: int | None = None, options: Mapping[str, Any] | None = None
) -> Robot:
    """Build the configured backend. InputError for a bad section or missing backend;
    exceptions of the backend itself (a port that will not open) propagate."""
    builder = backend_builder(loaded.backend, loaded.mark("backend"))
    opts = {"gui": False, "record": None}
    opts.update(options or {})
    check_options(loaded, opts)
    try:
        robot = builder(loaded.section(), profile=dict(loaded.config.profile), seed=seed, options=opts)
    except InputError as e:
        # a builder given no section (None) cannot know the file: point at `backend:`
        where = loaded.mark("backend")
        raise InputError(
            Problem(where, p.message) if p.mark.file.startswith("<") else p for p in e.problems
        ) from None
    if not isinstance(robot, Robot):
        raise TypeError(f"backend {loaded.backend!r} builder returned {type(robot).__name__}, not a Robot")
    return robot


def check_options(loaded: LoadedConfig, options: Mapping[str, Any]) -> None:
    """InputError at the config's ``backend:`` for each run option set in ``options``
    (``gui`` true, ``record`` a path) that the backend does not honour (:data:`BACKEND_OPTIONS`)."""
    honoured = BACKEND_OPTIONS.get(loaded.backend, frozenset())
    problems = Problems()
    for name, (flag, what) in _OPTION_FLAGS.items():
        if options.get(name) and name not in honoured:
            able = [b for b, opts in BACKEND_OPTIONS.items() if name in opts]
            problems.add(loaded.mark("backend"), f"backend: {loaded.backend!r} cannot honour {flag} ({what}; only "
                         f"backend {', '.join(map(repr, able))} can): run without it or use a sim config")
    problems.raise_if_any()


def robot_capabilities(robot: Robot) -> frozenset[str]:
    """Names of the capabilities ``robot`` has (a subset of :data:`CAPABILITIES`)."""
    return frozenset(c for c in CAPABILITIES if getattr(robot, c, None) is not None)
