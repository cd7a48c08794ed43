"""What the browser console of ``mmexec serve`` needs beyond the plain API.

* its static assets (``executive/serve/static/``: plain HTML, CSS and JavaScript modules,
  no CDN), listed once when the app is made, so the route serves only those files and no
  path from a URL ever reaches the file system;
* the mission as the page shows it (:func:`mission_json`): the request fields that build
  the request form, and every node's kind, branch label (``action`` / ``recovery`` /
  ``give_up`` of a recovery node), description and the blackboard keys it reads and
  writes, by node path (the paths of the ``tree`` stream);
* stream payloads built in the tick thread: the running tree's blackboard
  (:func:`blackboard_json`), the world model's markers (:func:`markers_json`), tracked
  people (:func:`people_json`) and the marker detections sent with each camera frame
  (:class:`StreamDetector`).

Shapes: docs/console.md.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mmexec.executive import nodes as N
from mmexec.executive.display import _kind, _walk, describe
from mmexec.executive.eventlog import to_jsonable
from mmexec.executive.values import Expr
from mmexec.skills.perception.detect import WORLD_DETECTOR, WORLD_MARKERS
from mmexec.skills.perception.markers import MarkerDetector

__all__ = [
    "CONSOLE_CSP",
    "CONTENT_TYPES",
    "STATIC_DIR",
    "WORLD_PEOPLE",
    "Asset",
    "ConsoleWorld",
    "StreamDetector",
    "blackboard_json",
    "markers_json",
    "mission_json",
    "node_keys",
    "people_json",
    "static_assets",
]

#: The console's files (package data).
STATIC_DIR = Path(__file__).resolve().with_name("static")
#: Served file types, by suffix (starlette adds ``charset=utf-8`` to the text types).
CONTENT_TYPES = {
    ".html": "text/html",
    ".js": "text/javascript",
    ".css": "text/css",
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".txt": "text/plain",
}
#: The page loads nothing but its own files and talks only to its own server.
CONSOLE_CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
               "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'none'; "
               "frame-ancestors 'none'")
#: A blackboard value longer than this many characters of JSON is shown cut.
BLACKBOARD_VALUE_CHARS = 2000
#: [wall Hz] how often the blackboard is streamed at most (when it changed)
BLACKBOARD_HZ = 4.0
#: ``ctx.world`` key where the navigation stack may publish the people it tracks: rows
#: ``[x, y]`` or ``[x, y, vx, vy]`` (or mappings with those keys and an ``id``) in ``map``
#: [m, m/s]; streamed as ``people`` whenever it is replaced.
WORLD_PEOPLE = "nav.people"


@dataclass(frozen=True)
class Asset:
    """One console file: where it is and its content type."""

    path: Path
    content_type: str


def static_assets(folder: Path = STATIC_DIR) -> dict[str, Asset]:
    """Every regular file of a known type under ``folder`` by its relative path
    (``app.js``, ``vendor/x.js``); symbolic links and files resolving outside ``folder``
    are left out."""
    root = folder.resolve()
    out: dict[str, Asset] = {}
    if not root.is_dir():
        return out
    for path in sorted(root.rglob("*")):
        kind = CONTENT_TYPES.get(path.suffix)
        if kind is None or path.is_symlink() or not path.is_file():
            continue
        real = path.resolve()
        if root not in real.parents:
            continue
        out[path.relative_to(root).as_posix()] = Asset(real, kind)
    return out


# --------------------------------------------------------------------------- the mission


def node_keys(node: Any) -> tuple[list[str], list[str]]:
    """The blackboard keys ``node`` reads and writes (sorted): the references in its
    values, a condition's key, a skill's outputs, a recovery node's bookkeeping, a
    foreach's loop key. ``last_failure*`` (written by any failing leaf) are left out."""
    reads: set[str] = set()
    writes: set[str] = set()
    for value in vars(node).values():
        values = value.values() if isinstance(value, dict) else (value,)
        for v in values:
            if isinstance(v, Expr):
                reads.update(v.reads())
    if isinstance(node, N.Condition):
        reads.add(node.key)
    elif isinstance(node, N.SkillLeaf):
        writes.update(node.outputs.values())
    elif isinstance(node, N.Recovery):
        writes.update((node.k_attempts, node.k_recoveries, node.k_failure, node.k_outcome))
    elif isinstance(node, N.Foreach):
        writes.add(node.key)
    return sorted(reads), sorted(writes)


def _decl(d: Any) -> dict[str, Any]:
    out = {"name": d.name, "type": d.type.__name__, "doc": d.doc}
    if d.has_default:
        out["default"] = to_jsonable(d.default)
    return out


def mission_json(mission: Any) -> dict[str, Any]:
    """The mission as the console shows it: ``name``, ``description``, ``sha256``,
    ``requests`` and ``params`` (``[{"name", "type", "doc", "default"?}]``, in declared
    order), and ``nodes``: ``[{"path", "name", "kind", "branch", "detail", "reads",
    "writes"}]`` depth-first, the paths the ``tree`` stream names."""
    nodes = []
    for node, _parent, branch, _depth in _walk(mission.display_tree().root):
        reads, writes = node_keys(node)
        detail = describe(node)
        nodes.append({"path": node.path, "name": node.name, "kind": _kind(node), "branch": branch,
                      "detail": "" if detail == node.name else detail, "reads": reads, "writes": writes})
    return {"name": mission.name, "description": mission.description, "sha256": mission.sha256,
            "requests": [_decl(d) for d in mission.root_file.requests.values()],
            "params": [_decl(d) for d in mission.params.values()], "nodes": nodes}


# --------------------------------------------------------------------------- stream payloads


def blackboard_json(bb: Mapping[str, Any]) -> dict[str, Any]:
    """The blackboard as plain JSON, by key (sorted); a value whose JSON is longer than
    :data:`BLACKBOARD_VALUE_CHARS` becomes its cut text ending in ``...``."""
    out: dict[str, Any] = {}
    for key in sorted(bb):
        value = to_jsonable(bb[key])
        text = json.dumps(value)
        out[key] = value if len(text) <= BLACKBOARD_VALUE_CHARS else text[:BLACKBOARD_VALUE_CHARS] + "..."
    return out


def markers_json(estimates: Mapping[int, Any]) -> list[dict[str, Any]]:
    """The world model's marker estimates (``MarkerEstimate`` by id) as ``[{"id", "x",
    "y", "z", "yaw", "samples", "t"}]`` in ``map`` [m, rad], by id."""
    out = []
    for mid in sorted(estimates):
        est = estimates[mid]
        x, y, z, yaw = est.as_list()
        out.append({"id": int(mid), "x": x, "y": y, "z": z, "yaw": yaw, "samples": int(est.samples),
                    "t": float(est.stamp)})
    return out


def people_json(people: Iterable[Any] | None) -> list[dict[str, Any]]:
    """Tracked people from the navigation stack (``nav.people``: ``[x, y]`` or ``[x, y,
    vx, vy]`` rows, or mappings with those keys and an optional ``id``, in ``map`` [m,
    m/s]) as ``[{"id", "x", "y", "vx", "vy"}]``; rows that are not finite numbers are
    left out."""
    out = []
    for i, row in enumerate(people or []):
        if isinstance(row, Mapping):
            vals = [row.get("x"), row.get("y"), row.get("vx", 0.0), row.get("vy", 0.0)]
            pid = row.get("id", i)
        else:
            vals = list(row)[:4] + [0.0] * max(0, 4 - len(row))
            pid = i
        try:
            x, y, vx, vy = (float(v) for v in vals)
        except (TypeError, ValueError):
            continue
        if all(math.isfinite(v) for v in (x, y, vx, vy)):
            out.append({"id": to_jsonable(pid), "x": x, "y": y, "vx": vx, "vy": vy})
    return out


class ConsoleWorld:
    """The console's own stream sink (a :class:`~mmexec.executive.serve.service.StreamSink`
    of the runner's ``Streams``, in the tick thread): beside what the console sink sends,

    * ``blackboard``: the running tree's blackboard when it changed, at most
      :data:`BLACKBOARD_HZ` (wall), and its final values at ``request_end`` (sticky);
    * ``markers``: the world model's marker estimates when they changed (sticky);
    * ``people``: ``world[WORLD_PEOPLE]`` when the navigation stack replaced it (sticky);

    and keeps every event record for ``GET /api/events`` and the robot's facts (name,
    footprint radius) in the status. :meth:`watch` wraps the mission so that each tree
    built for a request is known (its blackboard)."""

    def __init__(self, service: Any, world: Mapping[str, Any]) -> None:
        self.service = service
        self.world = world
        self._tree: Any = None
        self._bb_text = ""
        self._bb_due = 0.0
        self._markers_seen: Any = None
        self._people: Any = None
        self._detector = StreamDetector()

    def watch(self, mission: Any) -> Any:
        """``mission``, noting each tree it builds (see :class:`_WatchedMission`)."""
        return _WatchedMission(mission, self._on_tree)

    def start(self, robot: Any) -> None:
        """Once the robot is up: its name and footprint radius [m] in the status."""
        self.service.set_info(robot={"name": robot.name,
                                     "footprint_radius": robot.base.radius if robot.base is not None else None})

    # StreamSink
    def refresh(self, t: float) -> bool:
        self._publish_blackboard(t, force=False)
        estimates = self.world.get(WORLD_MARKERS)
        if estimates:
            seen = tuple((k, e.stamp, e.samples) for k, e in estimates.items())
            if seen != self._markers_seen:
                self._markers_seen = seen
                self.service.hub.publish("markers", {"t": t, "markers": markers_json(estimates)})
        people = self.world.get(WORLD_PEOPLE)
        if people is not self._people:
            self._people = people
            self.service.hub.publish("people", {"t": t, "people": people_json(people)})
        return False

    def wants(self, topic: str, t: float) -> bool:
        return topic == "event"  # kept for GET /api/events; the blackboard's final values at request_end

    def send(self, topic: str, data: Any, t: float) -> None:
        if topic == "event":
            self.service.keep_event(data)
            if data.get("event") == "request_end":
                self._publish_blackboard(t, force=True)

    def detections(self, rgb: np.ndarray) -> list[dict[str, Any]]:
        """The markers on a camera image the console is sent (see :class:`StreamDetector`)."""
        return self._detector.detect(self.world, rgb)

    def _on_tree(self, tree: Any) -> None:
        self._tree = tree
        self._bb_text = ""
        self._bb_due = 0.0

    def _publish_blackboard(self, t: float, *, force: bool) -> None:
        tree = self._tree
        now = time.monotonic()
        if tree is None or (not force and now < self._bb_due):
            return
        self._bb_due = now + 1.0 / BLACKBOARD_HZ
        values = blackboard_json(tree.blackboard())
        text = json.dumps(values, sort_keys=True)
        if text != self._bb_text:
            self._bb_text = text
            self.service.hub.publish("blackboard", {"t": t, "values": values})


class _WatchedMission:
    """A mission that tells ``on_tree`` each tree it builds for a request (tick thread);
    everything else is the mission's."""

    def __init__(self, mission: Any, on_tree: Callable[[Any], None]) -> None:
        self._mission = mission
        self._on_tree = on_tree

    def __getattr__(self, name: str) -> Any:
        return getattr(self._mission, name)

    def instantiate(self, ctx: Any, request: Mapping[str, Any], params: Mapping[str, Any] | None = None) -> Any:
        tree = self._mission.instantiate(ctx, request, params)
        self._on_tree(tree)
        return tree


class StreamDetector:
    """Marker detections for the camera stream: the console draws them on the image.

    Runs its own detector (the skills' one remembers where markers were and must not see
    the stream's frames) with the configuration of the detector the skills use, once a
    skill made one (``perception.detector`` in the skill world); none before that."""

    def __init__(self) -> None:
        self._detector: Any = None

    def detect(self, world: Mapping[str, Any], rgb: np.ndarray) -> list[dict[str, Any]]:
        """``[{"id", "label", "points": [[u, v] x 4]}]`` pixels, (0, 0) top left."""
        used = world.get(WORLD_DETECTOR)
        if used is None:
            return []
        if self._detector is None or self._detector.config != used.config:
            self._detector = MarkerDetector(used.config)
        return [{"id": int(d.id), "label": f"marker {int(d.id)}",
                 "points": [[round(float(u), 1), round(float(v), 1)] for u, v in np.asarray(d.corners)]}
                for d in self._detector.detect(rgb)]
