"""What a backend declares about itself (:class:`BackendSpec`), so the executive never
decides by a backend's name.

A backend is the module that turns a run config's backend section (``mock:``, ``sim:``,
``robot:``, ...) into a :class:`~mmexec.drivers.interfaces.Robot`. Each backend module
defines one module-level ``BACKEND = BackendSpec(...)``; the executive's registry
(:mod:`mmexec.executive.backends`) maps the names a config may give in ``backend:`` to
those module paths and imports a module only when a config names it. Everything the
executive, ``mmexec validate`` and ``mmexec campaign`` need to know about a backend is
asked of its spec:

* :attr:`BackendSpec.parse_section` binds the section (every problem located), and
  :attr:`BackendSpec.capabilities` says which capability slots the built robot will fill,
  from the bound section alone: nothing is opened, connected or started;
* :attr:`BackendSpec.build` brings the robot up;
* :attr:`BackendSpec.options`: the run options (``gui``, ``record``) it honours;
* :attr:`BackendSpec.files`: section keys naming files it will open, which the config
  loader checks lie in the folders files may come from before anything reads them;
* :attr:`BackendSpec.navigation`: the map and footprint its navigation will use, for the
  binding checks of ``mmexec validate``;
* :attr:`BackendSpec.faults_off`, :attr:`BackendSpec.fault_patches`,
  :attr:`BackendSpec.randomize_key` and :attr:`BackendSpec.item_markers`: what a campaign
  may do to its section (fault profiles, per-trial randomisation, drawing items).

Capability-contract level: imports only ``config`` and the capability interfaces.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

from mmexec.config.yamlload import YDict
from mmexec.drivers.interfaces import OccupancyGrid, Robot

__all__ = ["CAPABILITIES", "OPTIONS", "BackendSpec", "Builder", "NavMap", "SectionFile"]

#: The capability slots of :class:`~mmexec.drivers.interfaces.Robot`, in bring-up order.
CAPABILITIES: tuple[str, ...] = ("base", "arm", "gripper", "camera", "lidar")

#: The run options a backend may honour (``mmexec run --gui`` / ``--record FILE``).
OPTIONS: tuple[str, ...] = ("gui", "record")

Parsed = TypeVar("Parsed")


class Builder(Protocol):
    """``build(section, *, profile, seed, options) -> Robot``: bring the robot up from its
    config section (a :class:`~mmexec.config.yamlload.YDict` with marks, or None for
    all defaults). ``profile`` is the config's robot profile, ``seed`` the run's seed (None:
    unseeded), ``options`` the run options (``gui``: bool, ``record``: a path or None).
    Raises InputError for a bad section; anything else the backend raises is a start-up
    failure."""

    def __call__(self, section: YDict | None, *, profile: Mapping[str, Any], seed: int | None,
                 options: Mapping[str, Any]) -> Robot: ...


@dataclass(frozen=True)
class SectionFile:
    """A section key whose value may name a file the backend opens (``sim.world``).

    ``is_path(value)`` tells a path from the name of a file the backend ships (``lab``);
    a path must lie inside the config's folder tree, ``shipped``, the trees folder or a
    config root, or the config does not load. ``what`` names the file in that message
    (``a world``)."""

    key: str
    what: str
    shipped: tuple[Path, ...]
    is_path: Callable[[str], bool]


@dataclass(frozen=True)
class NavMap:
    """The occupancy grid a run navigates on, the base's footprint ``radius`` [m], and
    where the grid comes from (``source``, for messages: ``the map of world 'lab'``)."""

    grid: OccupancyGrid
    radius: float
    source: str


@dataclass(frozen=True)
class BackendSpec(Generic[Parsed]):
    """One backend, as the executive sees it (see the module doc).

    ``parse_section(section)`` binds the section (None when the config has none) and
    raises :class:`~mmexec.config.yamlload.InputError` with every problem; a problem it
    cannot place in the file (no section given) carries a ``<...>`` mark, which the
    executive moves to the config's ``backend:``. ``capabilities(parsed)`` is the set of
    :data:`CAPABILITIES` the built robot will have. ``navigation(section)`` (None: the
    backend has no map) returns the :class:`NavMap`, or None when this section gives none.

    Campaigns: ``faults_off`` is the merge patch (RFC 7396) of the section that switches
    every injected fault off (None: the backend injects none, and only the ``config``
    fault profile runs on it); ``fault_patches[profile]`` is the patch a built-in fault
    profile adds on top of it. ``randomize_key`` is the section key a campaign sets to
    draw the world anew with each trial's seed (None: nothing to draw).
    ``truth_key`` is the section key of the backend's per-run ground-truth file: a campaign
    sets it to ``truth/{seed}.jsonl`` (beside DIR/config.yaml) when the config names none,
    so every trial's truth can be scored (None: the backend keeps no truth).
    ``item_markers(section)`` lists the marker ids of the items the backend's world holds
    (``--draw item=@markers``; None: it has no such world); ``object_names(section)`` the
    names of its untagged objects (``--draw item=@objects``)."""

    name: str
    parse_section: Callable[[YDict | None], Parsed]
    capabilities: Callable[[Parsed], frozenset[str]]
    build: Builder
    options: frozenset[str] = frozenset()
    files: tuple[SectionFile, ...] = ()
    navigation: Callable[[YDict | None], NavMap | None] | None = None
    faults_off: Mapping[str, Any] | None = None
    fault_patches: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    randomize_key: str | None = None
    item_markers: Callable[[Mapping[str, Any] | None], tuple[int, ...]] | None = None
    #: the section key a campaign sets to ``truth/{seed}.jsonl`` (beside DIR/config.yaml) so
    #: each trial writes its ground truth there for the campaign to count (None: no truth)
    truth_key: str | None = None
    object_names: Callable[[Mapping[str, Any] | None], tuple[str, ...]] | None = None

    def __post_init__(self) -> None:
        if not self.options <= set(OPTIONS):
            raise ValueError(f"backend {self.name!r}: unknown run options {sorted(self.options - set(OPTIONS))} "
                             f"(expected some of {', '.join(OPTIONS)})")
        if self.fault_patches and self.faults_off is None:
            raise ValueError(f"backend {self.name!r}: fault patches need a faults_off patch to start from")

    def section_capabilities(self, section: YDict | None) -> frozenset[str]:
        """The capabilities a robot built from ``section`` will have, found without
        opening anything (InputError for a bad section)."""
        return self.capabilities(self.parse_section(section))
