"""World files: the schema, loading with located errors, randomisation, and the derived
navigation map and planning scene.

A world is YAML (see ``docs/worlds.md``) loaded through :mod:`mmexec.config.yamlload`
into the frozen dataclasses below, so a mistake is reported as ``FILE:LINE:COL: path:
message``. All poses are in ``map`` (the room frame: x east, y north, z up, metres,
yaw in radians CCW from +x). The room spans ``[0, size[0]] x [0, size[1]]``.

Shelf convention: a shelf's ``pose`` yaw is the direction its open front faces; its
``width`` runs along the shelf's local y, ``depth`` along local x. An item placed on a
shelf faces the same way, and its marker sits on the item's local +x face, so markers
point into the room.

What the robot is told and what is there differ in two ways: an obstacle marked
``unmapped: true`` is in the physics world and the lidar's view but not in the map
(:meth:`World.occupancy`) or the planning scene (:meth:`World.scene_boxes`) given to the
robot, and ``people`` are kinematic cylinders walking waypoint loops
(:class:`Person`; moved by :mod:`mmexec.sim.people`), never in the map either.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from mmexec.config.yamlload import InputError, Mark, Problems, YDict, bind, did_you_mean, load_yaml
from mmexec.drivers.geometry import planar_transform, wrap_angle
from mmexec.drivers.interfaces import OccupancyGrid, Pose2D, SceneBox
from mmexec.sim.objects import SimObject, check_placement, place_object
from mmexec.sim.panel import Panel, panel_boxes, panel_transform
from mmexec.sim.plant import PlacedPlant, Plant, place_plants

__all__ = [
    "WORLDS_DIR",
    "Depot",
    "Item",
    "Obstacle",
    "Person",
    "Plant",
    "Randomize",
    "Reflector",
    "Room",
    "Shelf",
    "Table",
    "World",
    "WorldSpec",
    "footprint_mask",
    "load_world",
    "room_grid",
    "shipped_worlds",
]

WORLDS_DIR = Path(__file__).parent / "worlds"
#: longest side a room may have [m]: the navigation grid (5 cm cells) of a larger room
#: would take gigabytes (every number in a world is also finite: the loader refuses
#: .nan and .inf)
MAX_ROOM_SIZE = 100.0


def _positive(what: str, *values: float) -> list[str]:
    """``["<what> must be > 0"]`` when any of ``values`` is not, else ``[]``."""
    return [f"{what} must be > 0"] if min(values) <= 0 else []


@dataclass(frozen=True)
class Room:
    """Rectangular room: inner ``size`` [m] (x, y), walls ``wall_height`` and ``wall_thickness`` [m]."""

    size: tuple[float, float]
    wall_height: float = 1.0
    wall_thickness: float = 0.1

    def validate(self) -> list[str]:
        out = []
        if min(self.size) <= 0.5:
            out.append(f"room size {list(self.size)} too small (each side must exceed 0.5 m)")
        if max(self.size) > MAX_ROOM_SIZE:
            out.append(f"room size {list(self.size)} too large (each side at most {MAX_ROOM_SIZE:g} m)")
        if self.wall_height <= 0 or self.wall_thickness <= 0:
            out.append("wall_height and wall_thickness must be > 0")
        return out


@dataclass(frozen=True)
class Shelf:
    """Open shelf: ``pose`` [x, y, yaw] of the footprint centre (yaw = facing direction),
    ``width`` (along local y), ``depth`` (local x), ``height`` [m]; ``boards`` are the
    heights [m] of the board tops above the floor; ``board_thickness`` [m]."""

    name: str
    pose: tuple[float, float, float]
    width: float = 1.0
    depth: float = 0.35
    height: float = 0.8
    boards: tuple[float, ...] = (0.25, 0.5)
    board_thickness: float = 0.02

    def validate(self) -> list[str]:
        out = []
        if min(self.width, self.depth, self.height, self.board_thickness) <= 0:
            out.append(f"shelf {self.name!r}: width, depth, height and board_thickness must be > 0")
        for h in self.boards:
            if not self.board_thickness <= h <= self.height:
                out.append(f"shelf {self.name!r}: board at {h} m outside [{self.board_thickness}, {self.height}]")
        return out


@dataclass(frozen=True)
class Table:
    """A table: ``pose`` [x, y, yaw], ``size`` [x, y, height] (top surface at height) [m]."""

    name: str
    pose: tuple[float, float, float]
    size: tuple[float, float, float] = (0.8, 0.6, 0.45)
    top_thickness: float = 0.03

    def validate(self) -> list[str]:
        out = _positive(f"table {self.name!r}: size and top_thickness", *self.size, self.top_thickness)
        if not out and self.top_thickness >= self.size[2]:
            out.append(f"table {self.name!r}: top_thickness {self.top_thickness} m is not below its height {self.size[2]} m")
        return out


@dataclass(frozen=True)
class Item:
    """A box carrying an ArUco DICT_4X4_50 marker on its local +x face.

    Place it on a shelf (``shelf``, ``board`` index from 0 = lowest, ``offset`` [m] along
    the shelf width from its centre, ``inset`` [m] from the shelf front to the item
    front) or on a table (``table``, ``position`` [x, y] on the table top in ``map``),
    or anywhere (``pose`` [x, y, z, yaw] of the box centre). ``size`` [m] full extents,
    ``marker_size`` [m] side of the black square, ``mass`` [kg]."""

    name: str
    marker: int
    size: tuple[float, float, float] = (0.06, 0.06, 0.06)
    marker_size: float = 0.045
    mass: float = 0.06
    color: tuple[float, float, float] = (0.85, 0.85, 0.85)
    shelf: str | None = None
    board: int = 0
    offset: float = 0.0
    inset: float = 0.06
    table: str | None = None
    position: tuple[float, float] | None = None
    pose: tuple[float, float, float, float] | None = None

    def validate(self) -> list[str]:
        out = []
        if not 0 <= self.marker < 50:
            out.append(f"item {self.name!r}: marker {self.marker} outside DICT_4X4_50 ids 0..49")
        if self.marker_size * 8 / 6 > min(self.size[1], self.size[2]) + 1e-9:
            out.append(f"item {self.name!r}: marker_size {self.marker_size} with its white border "
                       f"({self.marker_size * 8 / 6:.3f} m) does not fit the {self.size[1]} x {self.size[2]} m face")
        where = sum(x is not None for x in (self.shelf, self.table, self.pose))
        if where != 1:
            out.append(f"item {self.name!r}: give exactly one of shelf, table or pose")
        if self.table is not None and self.position is None:
            out.append(f"item {self.name!r}: an item on a table needs position [x, y]")
        if self.mass <= 0 or min(self.size) <= 0:
            out.append(f"item {self.name!r}: mass and size must be > 0")
        return out


@dataclass(frozen=True)
class Depot:
    """An open basket: ``pose`` [x, y, yaw], ``size`` [x, y, rim height], wall ``thickness`` [m].
    ``marker``: an ArUco DICT_4X4_50 id printed (``marker_size`` [m] black square, with its
    white border) on the outside of the wall on the basket's local ``marker_side``
    (``-y``: the wall facing local -y), centred on the wall, facing out; None: no marker."""

    name: str
    pose: tuple[float, float, float]
    size: tuple[float, float, float] = (0.4, 0.3, 0.15)
    thickness: float = 0.01
    marker: int | None = None
    marker_size: float = 0.06
    marker_side: Literal["+x", "-x", "+y", "-y"] = "-y"

    def validate(self) -> list[str]:
        out = _positive(f"depot {self.name!r}: size and thickness", *self.size, self.thickness)
        if self.marker is not None:
            if not 0 <= self.marker < 50:
                out.append(f"depot {self.name!r}: marker {self.marker} outside DICT_4X4_50 ids 0..49")
            if self.marker_size <= 0 or self.marker_size * 8 / 6 > self.size[2] + 1e-9:
                out.append(f"depot {self.name!r}: marker_size {self.marker_size} with its white border does not fit "
                           f"the {self.size[2]} m high wall")
        return out

    def marker_pose(self) -> np.ndarray | None:
        """``T_map_marker`` of the printed marker (None without one): origin at the
        marker's centre on the wall's outer face, z out of the face, y up, x = y x z (the
        camera convention of :mod:`mmexec.skills.perception.markers`)."""
        if self.marker is None:
            return None
        lx, ly, h = self.size
        normal = {"+x": (1.0, 0.0), "-x": (-1.0, 0.0), "+y": (0.0, 1.0), "-y": (0.0, -1.0)}[self.marker_side]
        half = lx / 2 if normal[0] else ly / 2
        c, s = math.cos(self.pose[2]), math.sin(self.pose[2])
        n = np.array([c * normal[0] - s * normal[1], s * normal[0] + c * normal[1], 0.0])
        T = np.eye(4)
        y = np.array([0.0, 0.0, 1.0])
        T[:3, 0], T[:3, 1], T[:3, 2] = np.cross(y, n), y, n
        T[:3, 3] = (self.pose[0] + n[0] * (half + 0.0005), self.pose[1] + n[1] * (half + 0.0005), h / 2)
        return T


@dataclass(frozen=True)
class Obstacle:
    """A static ``box`` (``size`` [x, y, z]) or ``cylinder`` (``size`` [diameter, _, height])
    at ``pose`` [x, y, yaw] standing on the floor. ``unmapped``: in the physics world and
    the lidar's view, but left out of the map and the planning scene the robot is given
    (something put down since the map was made)."""

    name: str
    pose: tuple[float, float, float]
    size: tuple[float, float, float]
    shape: Literal["box", "cylinder"] = "box"
    unmapped: bool = False

    def validate(self) -> list[str]:
        dims = self.size if self.shape == "box" else (self.size[0], self.size[2])
        return _positive(f"obstacle {self.name!r}: size", *dims)


@dataclass(frozen=True)
class Reflector:
    """A laser reflector post: ``position`` [x, y], ``radius`` and ``height`` [m]."""

    name: str
    position: tuple[float, float]
    radius: float = 0.025
    height: float = 1.0

    def validate(self) -> list[str]:
        return _positive(f"reflector {self.name!r}: radius and height", self.radius, self.height)


#: walking speeds [m/s] a randomised person's speed is kept within
PERSON_SPEEDS = (0.3, 1.2)


@dataclass(frozen=True)
class Person:
    """A walking person: an upright kinematic cylinder of ``radius`` and ``height`` [m]
    that walks the closed loop of ``waypoints`` ``[[x, y], ...]`` in ``map`` (the last leg
    back to the first; two waypoints walk back and forth) at ``speed`` [m/s] and stands
    ``pause`` [s] at each waypoint. It starts at the first waypoint after ``delay`` [s]
    of clock time and, when ``trigger`` [m] is given, not before the robot's true position
    has come within that distance of it. A person never steps closer than 0.3 m to the
    robot's footprint (they wait, and after 3 s walk their loop the other way), so a
    contact is the robot's doing (:mod:`mmexec.sim.people`)."""

    name: str
    waypoints: tuple[tuple[float, float], ...]
    radius: float = 0.2
    height: float = 1.7
    speed: float = 0.8
    pause: float = 0.0
    delay: float = 0.0
    trigger: float | None = None

    def validate(self) -> list[str]:
        out = []
        if len(self.waypoints) < 2:
            out.append(f"person {self.name!r}: waypoints needs at least 2 points, got {len(self.waypoints)}")
        legs = zip(self.waypoints, self.waypoints[1:] + self.waypoints[:1])
        if any(math.hypot(b[0] - a[0], b[1] - a[1]) < 1e-6 for a, b in legs):
            out.append(f"person {self.name!r}: two consecutive waypoints are the same point")
        if not 0.1 <= self.radius <= 0.4:
            out.append(f"person {self.name!r}: radius {self.radius:g} m outside [0.1, 0.4]")
        if self.height <= 0:
            out.append(f"person {self.name!r}: height must be > 0")
        if not 0 < self.speed <= 2.0:
            out.append(f"person {self.name!r}: speed {self.speed:g} m/s outside (0, 2]")
        if self.pause < 0 or self.delay < 0:
            out.append(f"person {self.name!r}: pause and delay must be >= 0 s")
        if self.trigger is not None and self.trigger <= 0:
            out.append(f"person {self.name!r}: trigger must be > 0 m")
        return out


@dataclass(frozen=True)
class Randomize:
    """Uniform jitter half-ranges applied when the backend is asked to randomise:
    items slide along their shelf/table by ``item_xy`` [m] and turn by ``item_yaw``
    [rad]; the start pose moves by ``start_xy`` [m] and ``start_yaw`` [rad]; obstacles
    move by ``obstacle_xy`` [m]. People: each waypoint moves by ``person_xy`` [m] (kept
    in the room), the speed by ``person_speed`` [m/s] (kept within
    :data:`PERSON_SPEEDS`), and the pause and the start delay grow by up to
    ``person_pause`` and ``person_delay`` [s]. People are drawn after everything else, so
    a world without people draws what it always drew."""

    item_xy: float = 0.0
    item_yaw: float = 0.0
    start_xy: float = 0.0
    start_yaw: float = 0.0
    obstacle_xy: float = 0.0
    person_xy: float = 0.0
    person_speed: float = 0.0
    person_pause: float = 0.0
    person_delay: float = 0.0
    panel_xy: float = 0.0
    panel_yaw: float = 0.0

    def validate(self) -> list[str]:
        if min(self.item_xy, self.item_yaw, self.start_xy, self.start_yaw, self.obstacle_xy, self.person_xy,
               self.person_speed, self.person_pause, self.person_delay, self.panel_xy, self.panel_yaw) < 0:
            return ["randomize: half-ranges must be >= 0"]
        return []


@dataclass(frozen=True)
class WorldSpec:
    """A whole world file."""

    name: str
    room: Room
    start: tuple[float, float, float] = (0.5, 0.5, 0.0)
    shelves: tuple[Shelf, ...] = ()
    tables: tuple[Table, ...] = ()
    items: tuple[Item, ...] = ()
    depots: tuple[Depot, ...] = ()
    obstacles: tuple[Obstacle, ...] = ()
    reflectors: tuple[Reflector, ...] = ()
    people: tuple[Person, ...] = ()
    plants: tuple[Plant, ...] = ()
    randomize: Randomize = field(default_factory=Randomize)
    description: str = ""
    objects: tuple[SimObject, ...] = ()
    panels: tuple[Panel, ...] = ()


def _T(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """4x4 pose at (x, y, z) [m] turned ``yaw`` [rad] about z."""
    return planar_transform(x, y, yaw, z)


@dataclass(frozen=True)
class World:
    """A loaded world with concrete item, obstacle, people and start poses (after
    randomisation).

    ``item_poses[name]`` is ``T_map_item`` (box centre, marker on the local +x face);
    ``start`` is the robot's true start pose in ``map``; ``people`` walk as given here
    (waypoints, speeds, pauses drawn); ``plants`` carry their drawn fruit and leaves
    (:mod:`mmexec.sim.plant`).
    """

    spec: WorldSpec
    source: str
    item_poses: Mapping[str, np.ndarray]
    obstacles: tuple[Obstacle, ...]
    start: Pose2D
    people: tuple[Person, ...] = ()
    plants: tuple[PlacedPlant, ...] = ()
    panel_poses: Mapping[str, np.ndarray] = field(default_factory=dict)  #: ``T_map_panel`` (sim/panel.py)
    object_poses: Mapping[str, np.ndarray] = field(default_factory=dict)  #: ``T_map_object`` (sim/objects.py)

    @property
    def name(self) -> str:
        return self.spec.name

    def object_names(self) -> tuple[str, ...]:
        """Names of the untagged objects (:mod:`mmexec.sim.objects`)."""
        return tuple(o.name for o in self.spec.objects)

    def item(self, name: str) -> Item:
        for it in self.spec.items:
            if it.name == name:
                return it
        raise KeyError(f"no item {name!r} in world {self.name!r} (items: {', '.join(self.item_names())})")

    def item_names(self) -> tuple[str, ...]:
        return tuple(it.name for it in self.spec.items)

    def unmapped_names(self) -> frozenset[str]:
        """Names of the obstacles the robot's map and planning scene leave out."""
        return frozenset(o.name for o in self.obstacles if o.unmapped)

    def marker_of(self, name: str) -> int:
        return self.item(name).marker

    # ------------------------------------------------------------------ static geometry

    def static_boxes(self) -> list[tuple[str, np.ndarray, tuple[float, float, float], str]]:
        """Every static box as ``(name, T_map_box centre, full size, kind)``; kind is
        ``wall``, ``shelf``, ``table``, ``depot``, ``obstacle``, ``reflector`` or ``plant``
        (a plant's pot and trunk; cylinders appear as their bounding box). This is the physical world, unmapped
        obstacles included (:meth:`unmapped_names`); people are not static."""
        out: list[tuple[str, np.ndarray, tuple[float, float, float], str]] = []
        r = self.spec.room
        sx, sy = r.size
        t, h = r.wall_thickness, r.wall_height
        out += [
            ("wall_south", _T(sx / 2, -t / 2, h / 2, 0), (sx + 2 * t, t, h), "wall"),
            ("wall_north", _T(sx / 2, sy + t / 2, h / 2, 0), (sx + 2 * t, t, h), "wall"),
            ("wall_west", _T(-t / 2, sy / 2, h / 2, 0), (t, sy, h), "wall"),
            ("wall_east", _T(sx + t / 2, sy / 2, h / 2, 0), (t, sy, h), "wall"),
        ]
        for s in self.spec.shelves:
            base = _T(s.pose[0], s.pose[1], 0.0, s.pose[2])
            pt = 0.02  # side and back panel thickness
            parts = [(f"{s.name}_side_l", (0.0, s.width / 2 - pt / 2, s.height / 2), (s.depth, pt, s.height)),
                     (f"{s.name}_side_r", (0.0, -s.width / 2 + pt / 2, s.height / 2), (s.depth, pt, s.height)),
                     (f"{s.name}_back", (-s.depth / 2 + pt / 2, 0.0, s.height / 2), (pt, s.width, s.height)),
                     (f"{s.name}_top", (0.0, 0.0, s.height - s.board_thickness / 2), (s.depth, s.width, s.board_thickness))]
            for i, bh in enumerate(s.boards):
                parts.append((f"{s.name}_board{i}", (0.0, 0.0, bh - s.board_thickness / 2),
                              (s.depth, s.width - 2 * pt, s.board_thickness)))
            for name, xyz, size in parts:
                out.append((name, base @ _T(*xyz, 0.0), size, "shelf"))
        for tb in self.spec.tables:
            lx, ly, th = tb.size
            base = _T(tb.pose[0], tb.pose[1], 0.0, tb.pose[2])
            out.append((f"{tb.name}_top", base @ _T(0, 0, th - tb.top_thickness / 2, 0), (lx, ly, tb.top_thickness), "table"))
            for i, (a, b) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
                out.append((f"{tb.name}_leg{i}", base @ _T(a * (lx / 2 - 0.03), b * (ly / 2 - 0.03), (th - tb.top_thickness) / 2, 0),
                            (0.04, 0.04, th - tb.top_thickness), "table"))
        for d in self.spec.depots:
            lx, ly, hh = d.size
            w = d.thickness
            base = _T(d.pose[0], d.pose[1], 0.0, d.pose[2])
            for name, xyz, size in ((f"{d.name}_floor", (0, 0, w / 2), (lx, ly, w)),
                                    (f"{d.name}_wall_px", (lx / 2 - w / 2, 0, hh / 2), (w, ly, hh)),
                                    (f"{d.name}_wall_nx", (-lx / 2 + w / 2, 0, hh / 2), (w, ly, hh)),
                                    (f"{d.name}_wall_py", (0, ly / 2 - w / 2, hh / 2), (lx - 2 * w, w, hh)),
                                    (f"{d.name}_wall_ny", (0, -ly / 2 + w / 2, hh / 2), (lx - 2 * w, w, hh))):
                out.append((name, base @ _T(*xyz, 0.0), size, "depot"))
        for o in self.obstacles:
            size = o.size if o.shape == "box" else (o.size[0], o.size[0], o.size[2])
            out.append((o.name, _T(o.pose[0], o.pose[1], o.size[2] / 2, o.pose[2]), size, "obstacle"))
        for pn in self.spec.panels:
            out += [(n, T, size, "panel") for n, T, size in panel_boxes(pn, self.panel_poses[pn.name])]
        for rf in self.spec.reflectors:
            out.append((rf.name, _T(rf.position[0], rf.position[1], rf.height / 2, 0.0),
                        (2 * rf.radius, 2 * rf.radius, rf.height), "reflector"))
        for pl in self.spec.plants:
            out += [(name, _T(x, y, z, 0.0), size, "plant") for name, (x, y, z), size in pl.solid_parts()]
        return out

    def cylinder_names(self) -> frozenset[str]:
        """Names of the static parts that are upright cylinders (:meth:`static_boxes`
        gives their bounding boxes): cylindrical obstacles, reflector posts, plant pots
        and trunks."""
        return (frozenset(o.name for o in self.obstacles if o.shape == "cylinder")
                | frozenset(r.name for r in self.spec.reflectors)
                | frozenset(name for pl in self.spec.plants for name, _, _ in pl.solid_parts()))

    def scene_boxes(self) -> tuple[SceneBox, ...]:
        """Static boxes for arm planning (walls, shelf boards and panels, tables, depot
        walls, obstacles), ``pose`` = ``T_map_box`` centre, ``size`` full extents [m]: the
        robot's prior knowledge, so unmapped obstacles are left out."""
        hidden = self.unmapped_names()
        # a panel can be moved: a robot adds it to its planning scene from what it sees
        return tuple(SceneBox(n, T, s) for n, T, s, kind in self.static_boxes() if n not in hidden and kind != "panel")

    def occupancy(self, resolution: float = 0.05) -> OccupancyGrid:
        """A map_server-style grid in ``map``: 100 where a wall, shelf, table, depot,
        obstacle or reflector footprint covers the cell centre, 0 elsewhere inside the
        room. The grid covers the room plus its walls; ``origin`` is its lower-left corner.
        This is the map the robot is given: unmapped obstacles and people are not in it."""
        if resolution <= 0:
            raise ValueError(f"resolution must be > 0, got {resolution}")
        r = self.spec.room
        t = r.wall_thickness
        X, Y = room_grid(r, t, resolution)
        data = np.zeros(X.shape, dtype=np.int8)
        data[(X < 0) | (Y < 0) | (X > r.size[0]) | (Y > r.size[1])] = 100
        hidden = self.unmapped_names()
        for name, T, size, _kind in self.static_boxes():
            if T[2, 3] - size[2] / 2 > 0.5 or name in hidden:  # floats above anything the base can hit; unmapped
                continue
            data[footprint_mask(X, Y, T, size, resolution / 2)] = 100
        return OccupancyGrid(data=data, resolution=resolution, origin=Pose2D(-t, -t, 0.0))


def room_grid(room: Room, margin: float, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """``X, Y`` [m] in ``map``: the cell centres of a grid of ``resolution`` [m/cell] over
    ``room`` and ``margin`` [m] beyond it on every side (lower-left corner at
    ``(-margin, -margin)``), rows along y, columns along x."""
    w = math.ceil((room.size[0] + 2 * margin) / resolution)
    h = math.ceil((room.size[1] + 2 * margin) / resolution)
    xs = -margin + (np.arange(w) + 0.5) * resolution
    ys = -margin + (np.arange(h) + 0.5) * resolution
    X, Y = np.meshgrid(xs, ys)
    return X, Y


def footprint_mask(
    X: np.ndarray, Y: np.ndarray, T: np.ndarray, size: tuple[float, float, float], grow: float = 0.0
) -> np.ndarray:
    """True where the point (X, Y) lies in the footprint of the box at ``T`` (``T_map_box``,
    as :meth:`World.static_boxes` gives it) of full extents ``size``, grown by ``grow`` [m]
    on every side."""
    dx, dy = X - T[0, 3], Y - T[1, 3]
    lx = T[0, 0] * dx + T[1, 0] * dy
    ly = T[0, 1] * dx + T[1, 1] * dy
    return (np.abs(lx) <= size[0] / 2 + grow) & (np.abs(ly) <= size[1] / 2 + grow)


# --------------------------------------------------------------------------- loading


def shipped_worlds() -> tuple[str, ...]:
    """Names of the worlds shipped in ``sim/worlds``."""
    return tuple(sorted(p.stem for p in WORLDS_DIR.glob("*.yaml")))


def _resolve(name_or_path: str | Path, mark: Mark | None) -> Path:
    s = str(name_or_path)
    if "/" in s or s.endswith((".yaml", ".yml")):
        return Path(s)
    p = WORLDS_DIR / f"{s}.yaml"
    if not p.exists():
        known = shipped_worlds()
        msg = f"unknown world {s!r} (shipped: {', '.join(known)}; or give a path to a .yaml file)" + did_you_mean(s, known)
        raise InputError.at(mark or Mark("<world>", 1, 1), msg)
    return p


def load_world(
    name_or_path: str | Path,
    *,
    seed: int | None = None,
    randomize: bool = False,
    mark: Mark | None = None,
    extra_obstacles: tuple[Obstacle, ...] = (),
    extra_people: tuple[Person, ...] = (),
) -> World:
    """Load a shipped world by name (``"lab"``) or a world file by path, check it, and
    place items, obstacles, the start pose and people (jittered from ``seed`` when
    ``randomize``). ``mark`` locates ``name_or_path`` in a config for the error when the
    name is unknown. ``extra_obstacles`` and ``extra_people`` (fault injection) are added
    as given. Raises :class:`InputError` naming ``FILE:LINE:COL`` on any problem."""
    path = _resolve(name_or_path, mark)
    raw = load_yaml(path)
    problems = Problems()
    file_mark = Mark(str(path), 1, 1)
    if not isinstance(raw, dict):
        raise InputError.at(mark_of_raw(raw, file_mark), "a world file must be a mapping (name, room, shelves, items, ...)")
    spec = bind(WorldSpec, raw, getattr(raw, "mark", file_mark), "", problems)
    problems.raise_if_any()
    assert isinstance(spec, WorldSpec)
    _cross_check(spec, raw, problems)
    problems.raise_if_any()
    rng = np.random.default_rng(seed)
    rz = spec.randomize if randomize else Randomize()
    item_poses = {it.name: _place_item(spec, it, rng, rz) for it in spec.items}
    obstacles = tuple(
        replace(o, pose=(o.pose[0] + rng.uniform(-rz.obstacle_xy, rz.obstacle_xy),
                         o.pose[1] + rng.uniform(-rz.obstacle_xy, rz.obstacle_xy), o.pose[2]))
        for o in spec.obstacles
    ) + tuple(extra_obstacles)
    sx, sy, syaw = spec.start
    start = Pose2D(sx + rng.uniform(-rz.start_xy, rz.start_xy), sy + rng.uniform(-rz.start_xy, rz.start_xy),
                   wrap_angle(syaw + rng.uniform(-rz.start_yaw, rz.start_yaw)))
    people = tuple(_place_person(spec.room, pe, rng, rz) for pe in spec.people) + tuple(extra_people)
    # panels from their own stream: a world without them draws what it always drew
    prng = np.random.default_rng(None if seed is None else [seed, PANEL_STREAM])
    panel_poses = {pn.name: _place_panel(pn, prng, rz) for pn in spec.panels}
    # untagged objects draw from their own stream: a world without them draws what it always drew
    orng = np.random.default_rng(None if seed is None else [seed, 15])
    object_poses = {o.name: place_object(spec, o, orng, rz.item_xy, rz.item_yaw) for o in spec.objects}
    # plants draw from their own generator: a world without them draws what it always drew
    plants = place_plants(spec.plants, seed if randomize else None)
    return World(spec=spec, source=str(path), item_poses=item_poses, obstacles=obstacles, start=start, people=people,
                 object_poses=object_poses,
                 panel_poses=panel_poses, plants=plants)


#: generator stream of the run seed (``default_rng([seed, stream])``) for the panels' poses
PANEL_STREAM = 0x70616E6C


def _place_panel(pn: Panel, rng: np.random.Generator, rz: Randomize) -> np.ndarray:
    """``T_map_panel`` of ``pn`` with its position moved by up to ``panel_xy`` [m] and its
    yaw turned by up to ``panel_yaw`` [rad] (nothing drawn for a zero half-range)."""
    x, y, yaw = pn.pose
    if rz.panel_xy > 0:
        x, y = x + rng.uniform(-rz.panel_xy, rz.panel_xy), y + rng.uniform(-rz.panel_xy, rz.panel_xy)
    if rz.panel_yaw > 0:
        yaw = wrap_angle(yaw + rng.uniform(-rz.panel_yaw, rz.panel_yaw))
    return panel_transform(float(x), float(y), float(yaw), pn.height)


def mark_of_raw(raw: Any, default: Mark) -> Mark:
    return getattr(raw, "mark", default)


def _list_marks(raw: YDict, key: str) -> list[Mark]:
    seq = raw.get(key)
    if isinstance(seq, list):
        return [getattr(v, "mark", seq.item_mark(i)) for i, v in enumerate(seq)]  # type: ignore[attr-defined]
    return []


def _cross_check(spec: WorldSpec, raw: YDict, problems: Problems) -> None:
    """Names unique, references resolve, items fit their shelves, everything in the room."""
    seen: dict[str, str] = {}
    sx, sy = spec.room.size
    for key in ("shelves", "tables", "items", "depots", "obstacles", "reflectors", "people", "objects", "panels", "plants"):
        marks = _list_marks(raw, key)
        for i, obj in enumerate(getattr(spec, key)):
            m = marks[i] if i < len(marks) else raw.mark
            if obj.name in seen:
                problems.add(m, f"{key}[{i}].name: {obj.name!r} already names a {seen[obj.name]}")
            seen[obj.name] = "person" if key == "people" else key.rstrip("s")
            xy = getattr(obj, "pose", None) or getattr(obj, "position", None)
            if xy is not None and not (0 <= xy[0] <= sx and 0 <= xy[1] <= sy):
                problems.add(m, f"{key}[{i}]: {obj.name!r} at ({xy[0]}, {xy[1]}) is outside the {sx} x {sy} m room")
            for j, (wx, wy) in enumerate(getattr(obj, "waypoints", ())):
                if not (0 <= wx <= sx and 0 <= wy <= sy):
                    problems.add(m, f"{key}[{i}].waypoints[{j}]: {obj.name!r} at ({wx}, {wy}) is outside the "
                                    f"{sx} x {sy} m room")
    markers: dict[int, str] = {}
    shelves = {s.name: s for s in spec.shelves}
    tables = {t.name: t for t in spec.tables}
    for i, (it, m) in enumerate(zip(spec.items, _list_marks(raw, "items"))):
        item_raw = raw["items"][i]
        if it.marker in markers:
            problems.add(item_raw.value_mark("marker"), f"items[{i}].marker: id {it.marker} already used by {markers[it.marker]!r}")
        markers[it.marker] = it.name
        if it.shelf is not None:
            s = shelves.get(it.shelf)
            if s is None:
                problems.add(item_raw.value_mark("shelf"), f"items[{i}].shelf: no shelf {it.shelf!r}"
                             + (did_you_mean(it.shelf, shelves) or f" (shelves: {', '.join(shelves) or 'none'})"))
                continue
            if not 0 <= it.board < len(s.boards):
                problems.add(item_raw.value_mark("board") if "board" in item_raw else m,
                             f"items[{i}].board: shelf {s.name!r} has boards 0..{len(s.boards) - 1}, got {it.board}")
                continue
            if abs(it.offset) + it.size[1] / 2 > s.width / 2 - 0.02:
                problems.add(item_raw.value_mark("offset") if "offset" in item_raw else m,
                             f"items[{i}].offset: {it.offset} m puts {it.name!r} outside shelf {s.name!r} (width {s.width} m)")
            if it.inset + it.size[0] > s.depth:
                problems.add(item_raw.value_mark("inset") if "inset" in item_raw else m,
                             f"items[{i}].inset: {it.name!r} does not fit the {s.depth} m deep shelf")
            room_above = (s.boards[it.board + 1] - s.board_thickness if it.board + 1 < len(s.boards)
                          else s.height - s.board_thickness) - s.boards[it.board]
            if it.size[2] > room_above:
                problems.add(m, f"items[{i}]: {it.name!r} ({it.size[2]} m tall) does not fit under the next board "
                                f"({room_above:.3f} m free)")
        if it.table is not None and it.table not in tables:
            problems.add(item_raw.value_mark("table"), f"items[{i}].table: no table {it.table!r}"
                         + (did_you_mean(it.table, tables) or f" (tables: {', '.join(tables) or 'none'})"))
    for m, pn in zip(_list_marks(raw, "panels"), spec.panels):
        for mid in pn.marker_ids():
            if mid in markers:
                problems.add(m, f"panels: {pn.name!r}: marker {mid} already used by {markers[mid]!r}")
            markers[mid] = pn.name
    for m, obj in zip(_list_marks(raw, "objects"), spec.objects):
        for msg in check_placement(spec, obj):
            problems.add(m, msg)
    st = spec.start
    if not (0 < st[0] < sx and 0 < st[1] < sy):
        problems.add(raw.value_mark("start"), f"start: ({st[0]}, {st[1]}) is outside the {sx} x {sy} m room")


def _place_person(room: Room, pe: Person, rng: np.random.Generator, rz: Randomize) -> Person:
    """``pe`` with its waypoints, speed, pause and delay jittered by ``rz`` (nothing is
    drawn for a zero half-range); waypoints stay ``radius`` inside the room."""
    sx, sy = room.size
    out = pe
    if rz.person_xy > 0:
        pts = []
        for x, y in pe.waypoints:
            jx, jy = rng.uniform(-rz.person_xy, rz.person_xy, 2)
            pts.append((float(np.clip(x + jx, pe.radius, sx - pe.radius)), float(np.clip(y + jy, pe.radius, sy - pe.radius))))
        out = replace(out, waypoints=tuple(pts))
    if rz.person_speed > 0:
        lo, hi = PERSON_SPEEDS
        out = replace(out, speed=float(np.clip(pe.speed + rng.uniform(-rz.person_speed, rz.person_speed), lo, hi)))
    if rz.person_pause > 0:
        out = replace(out, pause=pe.pause + float(rng.uniform(0.0, rz.person_pause)))
    if rz.person_delay > 0:
        out = replace(out, delay=pe.delay + float(rng.uniform(0.0, rz.person_delay)))
    return out


def _place_item(spec: WorldSpec, it: Item, rng: np.random.Generator, rz: Randomize) -> np.ndarray:
    jx = rng.uniform(-rz.item_xy, rz.item_xy)
    jyaw = rng.uniform(-rz.item_yaw, rz.item_yaw)
    if it.pose is not None:
        x, y, z, yaw = it.pose
        return _T(x + jx, y, z, yaw + jyaw)
    if it.table is not None and it.position is not None:
        tb = next(t for t in spec.tables if t.name == it.table)
        return _T(it.position[0] + jx, it.position[1], tb.size[2] + it.size[2] / 2 + 1e-3, tb.pose[2] + jyaw)
    s = next(sh for sh in spec.shelves if sh.name == it.shelf)
    lim = s.width / 2 - 0.02 - it.size[1] / 2
    off = float(np.clip(it.offset + jx, -lim, lim))
    local_x = s.depth / 2 - it.inset - it.size[0] / 2
    z = s.boards[it.board] + it.size[2] / 2 + 1e-3
    return _T(s.pose[0], s.pose[1], 0.0, s.pose[2]) @ _T(local_x, off, z, jyaw)
