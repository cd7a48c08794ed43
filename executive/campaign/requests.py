"""Which requests each trial serves (:class:`RequestPlan`): the same fixed requests for
every trial, or fields drawn per trial with the trial's seed (``--draw``)."""

from __future__ import annotations

import random
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from mmexec.config.yamlload import InputError, Mark, Problem
from mmexec.executive.backends import backend_spec, specs
from mmexec.executive.runner import ArgMark

__all__ = ["RequestPlan", "cli_value", "parse_draws"]


@dataclass(frozen=True)
class RequestPlan:
    """How each trial's requests are chosen.

    ``fixed``: the same requests for every trial (each a mapping of field to value).
    ``draws``: ``{field: values}``: each trial serves ``per_trial`` requests, each field
    drawn uniformly from its values with ``random.Random(trial_seed)`` (fields in sorted
    order, one ``choice`` per field per request). Neither: one empty request."""

    fixed: tuple[Mapping[str, Any], ...] = ()
    draws: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)
    per_trial: int = 1

    def requests_for(self, seed: int) -> list[dict[str, Any]]:
        if self.draws:
            rng = random.Random(seed)
            return [{k: rng.choice(self.draws[k]) for k in sorted(self.draws)} for _ in range(self.per_trial)]
        return [dict(r) for r in self.fixed] or [{}]

    def describe(self) -> str:
        if self.draws:
            parts = ", ".join(f"{k} from {list(v)}" for k, v in sorted(self.draws.items()))
            return f"{self.per_trial} request(s) per trial, {parts}, drawn with the trial seed"
        if self.fixed:
            return "fixed: " + "; ".join(", ".join(f"{k}={v}" for k, v in r.items()) or "-" for r in self.fixed)
        return "one empty request per trial"


def cli_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def world_markers(cfg: Mapping[str, Any], mark: Mark) -> tuple[int, ...]:
    """The marker ids of the items of the world the config's backend runs in
    (:attr:`~mmexec.drivers.backendspec.BackendSpec.item_markers`); InputError at ``mark``
    for a backend without such a world."""
    backend = str(cfg.get("backend", ""))
    item_markers = backend_spec(backend, mark).item_markers
    if item_markers is None:
        able = [spec.name for spec in specs(mark) if spec.item_markers is not None]
        raise InputError.at(mark, f"@markers needs a {' or '.join(able)} config (the marker ids of the world's items)")
    return item_markers(cfg.get(backend))


def world_objects(cfg: Mapping[str, Any], mark: Mark) -> tuple[str, ...]:
    """The names of the untagged objects of the world the config's backend runs in
    (:attr:`~mmexec.drivers.backendspec.BackendSpec.object_names`); InputError at ``mark``
    for a backend without them or a world with none."""
    backend = str(cfg.get("backend", ""))
    names = backend_spec(backend, mark).object_names
    if names is None:
        able = [spec.name for spec in specs(mark) if spec.object_names is not None]
        raise InputError.at(mark, f"@objects needs a {' or '.join(able)} config (the untagged objects of its world)")
    out = names(cfg.get(backend))
    if not out:
        raise InputError.at(mark, "@objects: the config's world has no untagged objects (docs/worlds.md, objects:)")
    return out


def split_values(text: str) -> list[str]:
    """``"1,2,3"`` -> ``["1", "2", "3"]``, keeping commas inside brackets and braces, so a
    list or mapping field can be drawn: ``"[0, 1],[2]"`` -> ``["[0, 1]", "[2]"]``.
    ValueError for unbalanced brackets."""
    parts: list[str] = []
    depth, start = 0, 0
    for i, ch in enumerate(text):
        if ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
            if depth < 0:
                raise ValueError(f"unbalanced {ch!r} at character {i + 1} of {text!r}")
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    if depth:
        raise ValueError(f"unclosed bracket in {text!r}")
    parts.append(text[start:])
    return parts


def parse_draws(tokens: Sequence[str], cfg: Mapping[str, Any]) -> dict[str, tuple[Any, ...]]:
    draws: dict[str, tuple[Any, ...]] = {}
    problems: list[Problem] = []
    for i, tok in enumerate(tokens, start=1):
        # values split at top-level commas: FIELD=1,2,3 or, for a list field, FIELD=[0,1],[2]
        mark = ArgMark("--draw", i, 1)
        key, sep, value = tok.partition("=")
        key = key.strip()
        if not sep or not key or not value.strip():
            problems.append(Problem(mark, f"expected FIELD=V1,V2,..., FIELD=@markers or FIELD=@objects, got {tok!r}"))
            continue
        if key in draws:
            problems.append(Problem(mark, f"field {key!r} drawn twice"))
            continue
        if value.strip() in ("@markers", "@objects"):
            try:
                draws[key] = world_markers(cfg, mark) if value.strip() == "@markers" else world_objects(cfg, mark)
            except InputError as e:
                problems.extend(e.problems)
            continue
        try:
            values = tuple(v.strip() for v in split_values(value) if v.strip())
        except ValueError as e:
            problems.append(Problem(mark, f"{key}: {e}"))
            continue
        if not values:
            problems.append(Problem(mark, f"no values to draw {key!r} from"))
            continue
        draws[key] = values
    if problems:
        raise InputError(problems)
    return draws
