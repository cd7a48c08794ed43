"""Ground truth of a simulated run for measurement: a JSON-lines sidecar (sim-only).

Skills never read it (they cannot: skills do not import ``sim``); campaigns and the figure
scripts do. The backend writes it when the config's ``sim.truth_log`` names a file
(:func:`open_truth_log`): one record per control tick with the robot's *true* pose, its
true clearance and its gap to every person, and one record per contact. Records (all in
``map``; m, rad, s):

=================  ========================================================================
``truth_start``    world name, seed, the robot's footprint radius, the world's obstacles
                   (name, pose, size, shape, unmapped) and people (name, radius, waypoints)
``truth``          per tick: ``t``, true ``pose`` [x, y, theta], ``clearance`` (distance
                   from the base centre to the nearest static geometry the base can touch,
                   unmapped obstacles included, less the footprint radius), ``nearest``
                   (that part's name), ``people`` ([x, y] each) and ``gaps`` (centre
                   distance less both radii, each)
``contact``        ``t``, ``part`` (``base``: a move the bumper refused; ``arm``: an arm
                   link touching static geometry or a person), ``body`` hit, ``pose``
``panel_press``    a press of a control panel's button (sim/panel.py): panel, button, ``t``,
                   ``end``, deepest travel ``depth_mm``, ``switched`` (past 70 % of the
                   travel), the press point's ``offset_mm`` from the button's centre
``panel_end``      each panel light at the end (``panel/button`` -> on) and the presses
``truth_end``      ticks, the smallest clearance (and where), the smallest gap per person,
                   the number of contacts and the bodies they were with
=================  ========================================================================

The clearance uses the footprint *circle* (``footprint_radius``): exact for the
LoCoBot's round Kobuki, conservative for a rectangular platform. Only static parts whose
height range overlaps the base's bumper bodies count (a table top above the base is not
something the base can touch), as for the bumper itself.
"""

from __future__ import annotations

import itertools
import json
import logging
import math
from pathlib import Path
from typing import IO, Any

import numpy as np
import pybullet as p

from mmexec.config.yamlload import InputError, Mark
from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.capabilities import Contact, SimCore
from mmexec.sim.objects import parts_touched
from mmexec.sim.world import World

__all__ = ["StaticFootprints", "TruthLog", "open_truth_log", "truth_log_path"]

log = logging.getLogger(__name__)


class StaticFootprints:
    """The floor plan of a world's static parts whose height range overlaps ``z_range``
    [m]: rectangles and circles in ``map``, for exact point distances."""

    def __init__(self, world: World, z_range: tuple[float, float]) -> None:
        circles = {o.name for o in world.obstacles if o.shape == "cylinder"} | {r.name for r in world.spec.reflectors}
        rect_names: list[str] = []
        rects: list[tuple[float, float, float, float, float, float]] = []
        circ_names: list[str] = []
        circs: list[tuple[float, float, float]] = []
        lo, hi = z_range
        for name, T, size, _kind in world.static_boxes():
            if T[2, 3] + size[2] / 2 < lo or T[2, 3] - size[2] / 2 > hi:
                continue
            if name in circles:
                circ_names.append(name)
                circs.append((T[0, 3], T[1, 3], size[0] / 2))
            else:
                rect_names.append(name)
                rects.append((T[0, 3], T[1, 3], T[0, 0], T[1, 0], size[0] / 2, size[1] / 2))
        self.names = rect_names + circ_names
        self._rects = np.array(rects, dtype=float).reshape(-1, 6)
        self._circs = np.array(circs, dtype=float).reshape(-1, 3)

    def distance(self, x: float, y: float) -> tuple[float, str]:
        """The distance [m] from map point ``(x, y)`` to the nearest part (0 inside one)
        and that part's name (``inf`` and "" without parts)."""
        r, c = self._rects, self._circs
        dx, dy = x - r[:, 0], y - r[:, 1]
        lx = np.abs(r[:, 2] * dx + r[:, 3] * dy) - r[:, 4]
        ly = np.abs(-r[:, 3] * dx + r[:, 2] * dy) - r[:, 5]
        d_rect = np.hypot(np.maximum(lx, 0.0), np.maximum(ly, 0.0))
        d_circ = np.maximum(np.hypot(x - c[:, 0], y - c[:, 1]) - c[:, 2], 0.0)
        d = np.concatenate([d_rect, d_circ])
        if d.size == 0:
            return math.inf, ""
        k = int(np.argmin(d))
        return float(d[k]), self.names[k]


def truth_log_path(template: str, config_mark: Mark, seed: int | None) -> Path:
    """The sidecar's path: ``template`` with ``{seed}`` replaced by the run seed (``none``
    without one), relative to the folder of the config file ``config_mark`` names (the
    working directory for a config that is not a file). InputError at the mark for an
    unknown ``{...}`` field."""
    try:
        name = template.format(seed="none" if seed is None else seed)
    except (KeyError, IndexError, ValueError) as e:
        raise InputError.at(config_mark, f"sim.truth_log: {template!r}: only {{seed}} may be filled in ({e})") from e
    path = Path(name)
    folder = Path(config_mark.file).parent if not config_mark.file.startswith("<") else Path.cwd()
    return path if path.is_absolute() else folder / path


def _reach(core: SimCore, arm_links: frozenset[int]) -> float:
    """A radius [m] round the base centre that holds the arm at any pose: the distance to
    the arm's first link plus the length of the chain to the tool, measured now."""
    core.sync()
    if not arm_links:
        return 0.0
    base = np.array([core.true_pose.x, core.true_pose.y, 0.0])
    pos = [np.array(p.getLinkState(core.body, i, physicsClientId=core.cid)[4]) for i in sorted(arm_links)]
    chain = sum(float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(pos))
    return float(np.linalg.norm((pos[0] - base)[:2])) + chain + 0.1


class TruthLog:
    """Writes the ground-truth sidecar of one run (see the module docstring). Create with
    :func:`open_truth_log`; :meth:`sample` once per control tick; :meth:`close` at the end."""

    def __init__(self, stream: IO[str], core: SimCore, world: World, seed: int | None,
                 footprint_radius: float, z_range: tuple[float, float], arm_links: frozenset[int]) -> None:
        self._out = stream
        self._core = core
        self._radius = footprint_radius
        self._static = StaticFootprints(world, z_range)
        self._arm_links = arm_links
        self._reach = _reach(core, arm_links)  # [m] radius round the base holding the arm at any pose
        self._seen_contacts = len(core.contacts)
        self._seen_grasps = len(core.grasps)
        self._objects = {o.name: o for o in world.spec.objects}
        self._arm_touching: frozenset[tuple[int, int]] = frozenset()
        self.ticks = 0
        self.min_clearance = (math.inf, "")
        people = core.people
        self.min_gap = dict.fromkeys(people.names if people is not None else (), math.inf)
        self.contacts = 0
        self.contact_bodies: dict[str, int] = {}
        self._write("truth_start", world=world.name, seed=seed, robot_radius=footprint_radius,
                    obstacles=[{"name": o.name, "pose": list(o.pose), "size": list(o.size), "shape": o.shape,
                                "unmapped": o.unmapped} for o in world.obstacles],
                    people=[{"name": pe.name, "radius": pe.radius, "waypoints": [list(w) for w in pe.waypoints]}
                            for pe in (people.people if people is not None else ())])

    def _write(self, event: str, **fields: Any) -> None:
        self._out.write(json.dumps({"event": event, **fields}, separators=(",", ":")) + "\n")

    def record(self, event: str, **fields: Any) -> None:
        """Write one more record (another part of the sim's truth, e.g. the fruit's)."""
        self._write(event, **fields)

    def _contact(self, c: Contact) -> None:
        self.contacts += 1
        self.contact_bodies[c.body] = self.contact_bodies.get(c.body, 0) + 1
        self._write("contact", t=round(c.t, 4), part=c.part, body=c.body,
                    pose=[round(c.pose.x, 4), round(c.pose.y, 4), round(c.pose.theta, 4)])

    def _arm_contacts(self, now: float, pose: Pose2D) -> None:
        """Arm links touching static geometry in the last physics step, or overlapping a
        person now (people pass through the arm: :mod:`mmexec.sim.people`), each new
        touching pair once."""
        core = self._core
        others: dict[int, int | None] = {core.scene.static: None}
        touching: set[tuple[int, int]] = set()
        for pt in p.getContactPoints(bodyA=core.body, bodyB=core.scene.static, physicsClientId=core.cid):
            if pt[3] in self._arm_links and pt[8] < 0.0:
                touching.add((pt[2], pt[4]))
        people = core.people
        if people is not None and len(people):
            core.sync()
            for k in np.flatnonzero(people.gaps(pose.x, pose.y, self._reach) < 0.0):
                others[people.bodies[k]] = int(k)
                for link in self._arm_links:
                    if any(pt[8] < 0.0 for pt in p.getClosestPoints(core.body, people.bodies[k], 0.0, linkIndexA=link,
                                                                     physicsClientId=core.cid)):
                        touching.add((people.bodies[k], -1))
                        break
        for body, link in sorted(touching - self._arm_touching):
            k = others[body]
            if k is not None:
                assert core.people is not None
                name = core.people.names[k]
            else:
                names = core.scene.static_names
                name = names[link] if 0 <= link < len(names) else "static"
            c = Contact(now, "arm", name, pose)
            core.contacts.append(c)
            self._seen_contacts += 1
            self._contact(c)
        self._arm_touching = frozenset(touching)

    def sample(self) -> None:
        """One tick's record at the core's clock time, and the contacts since the last."""
        core = self._core
        now = core.clock.now()
        pose = core.true_pose
        self._arm_contacts(now, pose)
        for c in core.contacts[self._seen_contacts:]:
            self._contact(c)
        self._seen_contacts = len(core.contacts)
        for t, item, links in core.grasps[self._seen_grasps:]:  # which parts of an object the pads hold
            self._write("grasp", t=round(t, 4), item=item, links=list(links), parts=list(parts_touched(self._objects, item, links)))
        self._seen_grasps = len(core.grasps)
        d, name = self._static.distance(pose.x, pose.y)
        clearance = d - self._radius
        if clearance < self.min_clearance[0]:
            self.min_clearance = (clearance, name)
        rec: dict[str, Any] = {"t": round(now, 4), "pose": [round(pose.x, 4), round(pose.y, 4), round(pose.theta, 4)],
                               "clearance": round(clearance, 4), "nearest": name}
        people = core.people
        if people is not None and len(people):
            gaps = people.gaps(pose.x, pose.y, self._radius)
            for n, g in zip(people.names, gaps):
                self.min_gap[n] = min(self.min_gap[n], float(g))
            rec["people"] = [[round(float(x), 4), round(float(y), 4)] for x, y in people.positions()]
            rec["gaps"] = [round(float(g), 4) for g in gaps]
        self._write("truth", **rec)
        self.ticks += 1
        panels = core.scene.panels
        if panels is not None:  # the control panels' presses (sim/panel.py)
            for press in panels.drain():
                self._write("panel_press", **press.record())

    def close(self) -> None:
        """Write the summary and close the file."""
        if self._out.closed:
            return
        if self._objects:  # where each untagged object ended up (delivered or not)
            self._write("objects_end", positions={
                n: [round(float(v), 4) for v in p.getBasePositionAndOrientation(b, physicsClientId=self._core.cid)[0]]
                for n, b in self._core.scene.items.items() if n in self._objects})
        c, where = self.min_clearance
        panels = self._core.scene.panels
        if panels is not None:
            for press in panels.drain():
                self._write("panel_press", **press.record())
            self._write("panel_end", lights=panels.lights(), presses=len(panels.presses))
        self._write("truth_end", ticks=self.ticks, min_clearance=round(c, 4) if math.isfinite(c) else None,
                    nearest=where, min_gap={n: round(g, 4) if math.isfinite(g) else None for n, g in self.min_gap.items()},
                    contacts=self.contacts, contact_bodies=self.contact_bodies)
        self._out.close()


def open_truth_log(path: Path, core: SimCore, world: World, seed: int | None, footprint_radius: float,
                   z_range: tuple[float, float], arm_links: frozenset[int]) -> TruthLog:
    """Create (or replace) the sidecar at ``path`` (its folder is made) and write its
    first record. ``z_range`` [m]: the height range of the base's bumper bodies;
    ``arm_links``: the robot's arm and gripper link indices. OSError when it cannot be
    written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    stream = path.open("w", buffering=1, encoding="utf-8")  # line-buffered: a crash keeps what was measured
    log.info("ground truth of this run: %s", path)
    return TruthLog(stream, core, world, seed, footprint_radius, z_range, arm_links)
