"""Fault profiles (``mmexec campaign --faults``): named sets of RFC 7396 merge patches
for a run config's backend section. ``DIR/config.yaml`` is the user's config with one
profile applied (:func:`apply_fault_profile`); the built-in profiles are
:data:`BUILTIN_PROFILES`, anything else is a profile file (:func:`load_fault_profile`).
Profiles combine with ``+`` (``--faults crowd+arm_fail_first``: every fault off once, then
each profile's own patches in turn). docs/campaigns.md has the table of built-in profiles.

Each backend declares its own patches (:class:`~mmexec.drivers.backendspec.BackendSpec`):
``faults_off`` switches every injected fault of its section off, ``fault_patches[NAME]``
is what built-in profile NAME adds on top, and ``randomize_key`` is the section key set
to draw the world per trial. Nothing here knows a backend by name."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mmexec.config.yamlload import InputError, Mark, Problem, YDict, load_yaml
from mmexec.executive.backends import backend_spec, names, specs
from mmexec.executive.campaign.jsondata import plain
from mmexec.executive.runner import ArgMark

__all__ = ["AS_WRITTEN", "BUILTIN_PROFILES", "COMBINE", "NOMINAL", "FaultProfile", "apply_fault_profile",
           "builtin_profile", "combine_profiles", "load_fault_profile", "merge_patch"]


def merge_patch(target: Any, patch: Any) -> Any:
    """RFC 7396 JSON merge patch: a mapping patch merges key by key (recursively), a
    ``None`` value deletes the key, anything else replaces the target. Returns a new
    value; ``target`` is not modified."""
    if not isinstance(patch, Mapping):
        return copy.deepcopy(patch)
    out: dict[str, Any] = dict(target) if isinstance(target, Mapping) else {}
    for key, value in patch.items():
        if value is None:
            out.pop(key, None)
        else:
            out[key] = merge_patch(out.get(key), value)
    return out


@dataclass(frozen=True)
class FaultProfile:
    """A named set of merge patches for backend sections of a run config.

    ``patches[backend]`` are applied in order to the config's ``<backend>:`` section
    (:func:`merge_patch`); a backend with no entry cannot run this profile.
    ``source`` is where it came from (``built-in`` or a file path)."""

    name: str
    description: str
    patches: Mapping[str, tuple[Mapping[str, Any], ...]]
    source: str = "built-in"


#: The built-in profile that runs the config exactly as written (the default), on every
#: backend, and the one that starts every other built-in profile: every fault off.
AS_WRITTEN, NOMINAL = "config", "nominal"

#: Built-in fault profiles (``--faults NAME``) and what each does. Each but ``config``
#: starts from ``nominal`` (the backend's ``faults_off`` patch: every fault of the config
#: off, noise as configured) and adds the backend's patch of that name
#: (``fault_patches``); a backend with neither cannot run the profile.
BUILTIN_PROFILES: dict[str, str] = {
    AS_WRITTEN: "the config's own faults section, unchanged",
    NOMINAL: "no injected faults; sensor and odometry noise as configured",
    "arm_fail_first": "the first arm attempt fails (sim: the first arm goal stops half-way and fails; "
                      "mock: the first grasp closes on nothing)",
    "arm_fail_second": "the second arm attempt fails (sim: arm goal 2, in fetch_item the pick's first move "
                       "after the initial tuck; mock: the second grasp)",
    "arm_fail_twice": "the first two arm attempts fail (sim: arm goals 1 and 2; mock: grasps 1 and 2)",
    "arm_fail_always": "every arm attempt fails (sim: every arm goal; mock: every grasp)",
    "sensor_dropout": "camera frames and lidar scans are missing with probability 0.2 (sim only)",
    "nav_blocked": "the base cannot move (mock only; for the sim name the items in a profile file: "
                   "sim: {faults: {nav_blocked: [box_3]}})",
    "crowd": "people walk loops through the room, giving way to the robot (sim only: sim.faults.crowd, 2 people "
             "at 0.3-1.2 m/s; each trial's ground truth in DIR/truth/SEED.jsonl)",
    "clutter": "boxes the map does not show stand near the robot's routes, a way through always left (sim only: "
               "sim.faults.clutter, 3 boxes; ground truth in DIR/truth/SEED.jsonl)",
    "realistic_odometry": "the odometry drifts as a real base's does (sim only: sim.odometry_noise.profile "
                          "realistic: wheel-radius and gyro scale errors, gyro bias, slip); for the localiser",
}

#: joins profiles in ``--faults`` (``crowd+arm_fail_first``)
COMBINE = "+"


def builtin_profile(name: str) -> FaultProfile:
    """Built-in profile ``name`` (a key of :data:`BUILTIN_PROFILES`) with the patches of
    every registered backend that can run it (each backend module is imported)."""
    patches: dict[str, tuple[Mapping[str, Any], ...]] = {}
    for spec in specs(ArgMark("--faults", 0, 0)):
        if name == AS_WRITTEN:
            patches[spec.name] = ()
        elif spec.faults_off is not None and name == NOMINAL:
            patches[spec.name] = (spec.faults_off,)
        elif spec.faults_off is not None and name in spec.fault_patches:
            patches[spec.name] = (spec.faults_off, spec.fault_patches[name])
    return FaultProfile(name, BUILTIN_PROFILES[name], patches)


def combine_profiles(profiles: list[FaultProfile]) -> FaultProfile:
    """One profile doing what each of ``profiles`` does, in order: for every backend all of
    them can run, the first one's patches, then each next one's without its leading
    ``faults_off`` (so the faults the earlier ones switched on stay on)."""
    first = profiles[0]
    patches: dict[str, tuple[Mapping[str, Any], ...]] = {}
    for backend in first.patches:
        if not all(backend in pr.patches for pr in profiles):
            continue
        off = backend_spec(backend, ArgMark("--faults", 0, 0)).faults_off
        out = tuple(first.patches[backend])
        for pr in profiles[1:]:
            more = tuple(pr.patches[backend])
            out += more[1:] if more and off is not None and more[0] == off else more
        patches[backend] = out
    if not patches:
        raise InputError.at(ArgMark("--faults", 0, 0), f"fault profiles {' and '.join(repr(pr.name) for pr in profiles)} "
                            f"have no backend in common")
    sources = {pr.source for pr in profiles}
    return FaultProfile(COMBINE.join(pr.name for pr in profiles), "; ".join(pr.description for pr in profiles),
                        patches, source=sources.pop() if len(sources) == 1 else ", ".join(pr.source for pr in profiles))


def load_fault_profile(name_or_path: str) -> FaultProfile:
    """A built-in profile by name, or a profile file: a YAML mapping with optional
    ``description``, ``base: nominal|config`` (start from every fault off, the default,
    or from the config as written) and one merge patch per backend name (``sim:``,
    ``mock:``); several joined by ``+`` (:func:`combine_profiles`). InputError naming
    ``--faults`` or ``FILE:LINE:COL`` otherwise."""
    if COMBINE in name_or_path and not Path(name_or_path).exists():
        parts = name_or_path.split(COMBINE)
        if any(not part for part in parts):
            raise InputError.at(ArgMark("--faults", 0, 0), f"{name_or_path!r}: an empty profile name between '+'")
        return combine_profiles([load_fault_profile(part) for part in parts])
    if name_or_path in BUILTIN_PROFILES:
        return builtin_profile(name_or_path)
    path = Path(name_or_path)
    if not (path.suffix in (".yaml", ".yml") or path.exists()):
        raise InputError.at(ArgMark("--faults", 0, 0), f"unknown fault profile {name_or_path!r} (built-in: "
                            f"{', '.join(BUILTIN_PROFILES)}; or a profile .yaml file)")
    raw = load_yaml(path)
    top = getattr(raw, "mark", Mark(str(path), 1, 1))
    if not isinstance(raw, YDict):
        raise InputError.at(top, "a fault profile is a mapping: {description: ..., sim: {faults: {...}}, mock: {...}}")
    problems: list[Problem] = []
    allowed = {"description", "base", *names()}
    for key in raw:
        if key not in allowed:
            problems.append(Problem(raw.key_mark(key) if hasattr(raw, "key_mark") else top,
                                    f"unknown key {key!r} (expected: {', '.join(sorted(allowed))})"))
    base = raw.get("base", "nominal")
    if base not in ("nominal", "config"):
        problems.append(Problem(raw.value_mark("base"), f"base: expected 'nominal' or 'config', got {base!r}"))
    desc = raw.get("description", "")
    if not isinstance(desc, str):
        problems.append(Problem(raw.value_mark("description"), "description: expected a string"))
    patches: dict[str, tuple[Mapping[str, Any], ...]] = {}
    for backend in names():
        if backend not in raw:
            continue
        value = raw[backend]
        if not isinstance(value, YDict):
            problems.append(Problem(raw.value_mark(backend), f"{backend}: expected a mapping (a merge patch "
                                                             f"of the config's {backend}: section)"))
            continue
        faults_off = backend_spec(backend, raw.key_mark(backend)).faults_off if base == NOMINAL else None
        patches[backend] = ((faults_off,) if faults_off is not None else ()) + (plain(value),)
    if not patches and not problems:
        keys = [f"{b}:" for b in names()]
        problems.append(Problem(top, f"a fault profile needs at least one backend patch "
                                     f"({', '.join(keys[:-1])} or {keys[-1]})"))
    if problems:
        raise InputError(problems)
    return FaultProfile(path.stem, str(desc), patches, source=str(path))


def apply_fault_profile(raw_config: Mapping[str, Any], profile: FaultProfile, *, randomize: bool) -> dict[str, Any]:
    """The config mapping with ``profile`` applied to its backend's section (and, for a
    backend that draws its world per trial, its ``randomize_key`` set to ``randomize``).
    InputError at ``--faults`` when the profile has nothing for the config's backend."""
    cfg = plain(raw_config)
    backend = str(cfg.get("backend", ""))
    if backend not in profile.patches:
        raise InputError.at(ArgMark("--faults", 0, 0), f"fault profile {profile.name!r} has no patch for backend "
                            f"{backend!r} (it has: {', '.join(profile.patches) or 'none'})")
    section = cfg.get(backend) or {}
    for patch in profile.patches[backend]:
        section = merge_patch(section, patch)
    randomize_key = backend_spec(backend, ArgMark("--faults", 0, 0)).randomize_key
    if randomize_key is not None:
        section[randomize_key] = randomize
    if section or backend in cfg:
        cfg[backend] = section
    return cfg
