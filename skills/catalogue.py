"""The item catalogue: what each item a request may name is, where it usually is, and how
to handle it.

The paper (locobot-holistic-planning-dangerous-objects, section IV-C) answers a request by
"extracting the list of possible places where the item usually is" and searching them in
turn, and asks the operator where a dangerous item's dangerous part is (IV-E). A
catalogue file holds that knowledge per item::

    items:
      screwdriver:
        detector_class: screwdriver      # the detector's label (default: the item's name)
        places: [tool_shelf, workbench]  # named base poses in map (the profile's places)
        size: [0.20, 0.03, 0.03]         # m: the footprint's two sides (any order), the height
        dangerous: true                  # ask the operator for the dangerous part
        grasp: top                       # top (from above) or front (horizontal); default: the profile's
      tape:
        places: [workbench]
        size: [0.10, 0.10, 0.05]

:func:`load_catalogue` reads it through the safe loader (:mod:`mmexec.config.yamlload`),
so every problem is one ``FILE:LINE:COL: items.NAME.key: message`` line with a
did-you-mean for a misspelt key, place or detector class, all reported together.
:func:`search_order` gives the base poses a search visits: the item's likely places
first, in the catalogue's order, then the general search locations (the fetch profile's
``search_locations``) that are not one of those places again.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Literal

from mmexec.config.yamlload import (
    Mark,
    Problems,
    YDict,
    YList,
    bind,
    did_you_mean,
    load_yaml,
    mark_of,
)
from mmexec.drivers.interfaces import Pose2D

__all__ = ["Catalogue", "CatalogueItem", "SearchStop", "UnknownItem", "load_catalogue", "search_order"]


@dataclass(frozen=True)
class CatalogueItem:
    """One item: ``name`` (as requests spell it), the ``detector_class`` label that finds
    it, its likely ``places`` (names of base poses in ``map``, most likely first), its
    ``size`` [m] (the footprint's two sides, any order, and the height, as it stands on
    its support), whether it is ``dangerous`` (the operator marks its dangerous part
    before the grasp) and its ``grasp`` (``top``: from above, orthogonal to the support;
    ``front``: horizontal, from the robot's side; None: the robot profile's default)."""

    name: str
    detector_class: str
    places: tuple[str, ...]
    size: tuple[float, float, float]
    dangerous: bool
    grasp: str | None = None


class UnknownItem(KeyError):
    """A request names an item the catalogue does not have; ``str()`` lists a close
    name or the known ones."""

    def __str__(self) -> str:
        return str(self.args[0])


@dataclass(frozen=True)
class Catalogue:
    """The items of one catalogue file (``path``), by name."""

    path: str
    items: Mapping[str, CatalogueItem]

    def item(self, name: str) -> CatalogueItem:
        """The item called ``name``; raises :class:`UnknownItem` with a did-you-mean."""
        try:
            return self.items[name]
        except KeyError:
            known = sorted(self.items)
            hint = did_you_mean(name, known) or f" (known: {', '.join(known)})"
            raise UnknownItem(f"no item {name!r} in the catalogue {self.path}{hint}") from None

    def classes(self) -> frozenset[str]:
        """The detector classes the items need."""
        return frozenset(i.detector_class for i in self.items.values())


@dataclass(frozen=True)
class _ItemEntry:
    """One item as written in the file (see the module doc)."""

    size: tuple[float, float, float]
    detector_class: str | None = None
    places: list[str] = field(default_factory=list)
    dangerous: bool = False
    grasp: Literal["top", "front"] | None = None


@dataclass(frozen=True)
class _CatalogueFile:
    items: dict[str, _ItemEntry]


def _check_names(names: Sequence[str], known: Collection[str] | None, what: str, raw: object, mark: Mark,
                 path: str, problems: Problems) -> None:
    """Each of ``names`` (items of the raw YAML list or scalar ``raw``) must be in ``known``
    (None: anything goes) and appear once."""
    marks = getattr(raw, "item_marks", [])
    seen: set[str] = set()
    for i, name in enumerate(names):
        where = marks[i] if i < len(marks) else mark
        sub = f"{path}[{i}]" if isinstance(raw, list) else path
        if name in seen:
            problems.add(where, f"{sub}: {what} {name!r} listed twice")
        seen.add(name)
        if known is not None and name not in known:
            problems.add(where, f"{sub}: unknown {what} {name!r}"
                         + (did_you_mean(name, known) or f" (known: {', '.join(sorted(known)) or 'none'})"))


def load_catalogue(
    path: str | Path,
    *,
    places: Collection[str] | None = None,
    classes: Collection[str] | None = None,
) -> Catalogue:
    """Load the catalogue file at ``path`` (see the module doc).

    ``places``: the names of the base poses the robot knows (the profile's ``places``,
    ``home``...); each item's places must be among them. ``classes``: the labels the
    detector returns; each item's ``detector_class`` must be one. None skips that check.
    Raises :class:`InputError` with every problem, located: unknown or missing keys,
    wrong types, a size that is not three positive finite numbers, an unknown or repeated
    place, an unknown detector class, an empty catalogue."""
    raw = load_yaml(path)
    name = str(path)
    top = mark_of(raw, Mark(name, 1, 1))
    problems = Problems()
    bound = bind(_CatalogueFile, raw, top, "", problems)
    if isinstance(raw, YDict) and isinstance(raw.get("items"), YDict):
        entries: YDict = raw["items"]
        if not entries:
            problems.add(raw.value_mark("items"), "items: the catalogue lists no item")
        for item, entry in entries.items():
            if not isinstance(entry, YDict):
                continue
            sub = f"items.{item}"
            size = entry.get("size")
            if isinstance(size, YList):
                for i, v in enumerate(size):  # bind reports what is not a finite number
                    if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v <= 0:
                        problems.add(size.item_mark(i), f"{sub}.size[{i}]: expected > 0 m, got {v!r}")
            if isinstance(entry.get("places"), list) and all(isinstance(p, str) for p in entry["places"]):
                _check_names(entry["places"], places, "place", entry["places"], entry.value_mark("places"),
                             f"{sub}.places", problems)
            cls = entry.get("detector_class", item)
            if isinstance(cls, str) and classes is not None and cls not in classes:
                where = entry.value_mark("detector_class") if "detector_class" in entry else entries.key_mark(item)
                label = f"{sub}.detector_class" + ("" if "detector_class" in entry else " (the item's name)")
                problems.add(where, f"{label}: the detector has no class {cls!r}"
                             + (did_you_mean(cls, classes) or f" (its classes: {', '.join(sorted(classes))})"))
    problems.raise_if_any()
    assert isinstance(bound, _CatalogueFile)
    items = {
        k: CatalogueItem(k, e.detector_class or k, tuple(e.places), tuple(float(v) for v in e.size),  # type: ignore[arg-type]
                         e.dangerous, e.grasp)
        for k, e in bound.items.items()
    }
    return Catalogue(name, MappingProxyType(items))


# --------------------------------------------------------------------------- search order


@dataclass(frozen=True)
class SearchStop:
    """A base pose a search visits: ``name`` (a place name, or ``search_locations[i]``),
    ``pose`` in ``map`` [m, m, rad], and ``likely``: one of the item's likely places."""

    name: str
    pose: Pose2D
    likely: bool


def _same(a: Pose2D, b: Pose2D, distance: float, angle: float) -> bool:
    dth = math.remainder(a.theta - b.theta, math.tau)
    return a.distance_to(b) <= distance and abs(dth) <= angle


def search_order(
    item: CatalogueItem,
    places: Mapping[str, Pose2D],
    search_locations: Sequence[Pose2D],
    *,
    same_distance: float = 0.05,
    same_angle: float = math.radians(10.0),
) -> tuple[SearchStop, ...]:
    """The base poses to search for ``item``: its likely places (looked up in ``places``)
    in the catalogue's order, then each of the general ``search_locations`` that is not
    within ``same_distance`` [m] and ``same_angle`` [rad] of a pose already listed (no
    spot is searched twice). Raises ValueError for a likely place missing from
    ``places`` (with a did-you-mean)."""
    stops: list[SearchStop] = []
    for name in item.places:
        if name not in places:
            known = sorted(places)
            raise ValueError(f"item {item.name!r}: no place named {name!r}"
                             + (did_you_mean(name, known) or f" (known: {', '.join(known) or 'none'})"))
        stops.append(SearchStop(name, places[name], True))
    for i, pose in enumerate(search_locations):
        if not any(_same(pose, s.pose, same_distance, same_angle) for s in stops):
            stops.append(SearchStop(f"search_locations[{i}]", pose, False))
    return tuple(stops)
