"""Fault injection for the simulation, configured by the ``faults:`` section of ``sim:``.

Each fault exercises one recovery path of a mission (see docs/sim.md):

* ``arm_fail: always`` or ``arm_fail_attempts: [1, 3]``: the n-th arm goal (1-based,
  counting every :meth:`Arm.follow`) stops half-way and FAILS ("arm motion failed");
* ``nav_blocked: [box_3]``: a static obstacle fills the approach area in front of the
  named items (in the physics world *and* the prior map), so no path reaches them;
* ``marker_bias: {box_2: [0.02, 0.0]}``: that item's marker texture is printed shifted
  on its face by (lateral, up) metres, so the detected marker is off the true box;
* ``grasp_slip: {after: 1.0, items: [box_1]}``: a held item slips out of the gripper
  ``after`` seconds of holding (items empty = every item);
* ``camera_dropout`` / ``lidar_dropout``: ``{p: 0.2, intervals: [[10, 20]]}``: a frame or
  scan is None with probability ``p`` and always inside the clock-time intervals [s];
* ``reflector_dropout``: ``{intervals: [[20, 40]], p: 0.0, reflectors: [refl_sw]}``: the
  named laser reflectors (empty = all) are covered: the lidar sees them as ordinary
  surfaces (low intensity), per scan with probability ``p`` and always inside the
  intervals; the posts stay where they are;
* ``kidnap``: ``{at: 30.0, pose: [x, y, yaw]}``: once, at clock time ``at`` [s], the robot
  is lifted and put down at ``pose`` in ``map`` (omitted: a random pose clear of the
  static geometry, at least ``min_distance`` [m] from where it was); the odometry does
  not notice;
* ``crowd``: ``{count: 2, speed: [0.3, 1.2], pause: [0, 3], radius: [0.15, 0.25],
  waypoints: 3}``: that many people walk loops through the room (:func:`crowd_people`),
  on top of the world's own ``people``;
* ``clutter``: ``{count: 3, size: [0.25, 0.45], height: [0.7, 1.0], near: 0.5,
  keep_clear: 0.8, passage: null}``: that many boxes the map does not show stand near
  the robot's routes, always leaving a way through (:func:`clutter_obstacles`).

Randomness comes from the backend's seeded generator, so a seed reproduces the faults;
``crowd`` and ``clutter`` draw from their own streams of the run seed, so switching one on
changes nothing else a seed draws.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Literal

import cv2
import numpy as np

from mmexec.sim.world import Obstacle, Person, World, footprint_mask, room_grid

__all__ = [
    "Clutter",
    "Crowd",
    "Dropout",
    "FaultConfig",
    "FaultInjector",
    "GraspSlip",
    "Kidnap",
    "ReflectorDropout",
    "blocking_obstacles",
    "clutter_obstacles",
    "crowd_people",
    "world_extras",
]

log = logging.getLogger(__name__)

#: generator streams of the run seed (``default_rng([seed, stream])``) for the world faults
CROWD_STREAM, CLUTTER_STREAM = 0x63726F77, 0x636C7574


@dataclass(frozen=True)
class Dropout:
    """Sensor dropout: probability ``p`` per request, plus always-off ``intervals`` [s]."""

    p: float = 0.0
    intervals: tuple[tuple[float, float], ...] = ()

    def validate(self) -> list[str]:
        out = [] if 0.0 <= self.p <= 1.0 else [f"p must be in [0, 1], got {self.p}"]
        out += [f"interval [{a}, {b}] must have start <= end" for a, b in self.intervals if a > b]
        return out


@dataclass(frozen=True)
class ReflectorDropout(Dropout):
    """Covered laser reflectors: ``reflectors`` (names; empty = all) return as ordinary
    surfaces with probability ``p`` per scan and always inside ``intervals`` [s]."""

    reflectors: tuple[str, ...] = ()


@dataclass(frozen=True)
class Kidnap:
    """Teleport the robot once at clock time ``at`` [s] to ``pose`` ``(x [m], y [m], yaw
    [rad])`` in ``map``, or, when None, to a random pose clear of the static geometry and
    at least ``min_distance`` [m] away."""

    at: float
    pose: tuple[float, float, float] | None = None
    min_distance: float = 1.0

    def validate(self) -> list[str]:
        out = [] if self.at >= 0 else [f"at must be >= 0 s, got {self.at}"]
        return out + ([] if self.min_distance >= 0 else [f"min_distance must be >= 0 m, got {self.min_distance}"])


@dataclass(frozen=True)
class GraspSlip:
    """A held item slips out ``after`` seconds of holding; ``items`` limits which (empty = all)."""

    after: float = 1.0
    items: tuple[str, ...] = ()

    def validate(self) -> list[str]:
        return [] if self.after >= 0 else [f"after must be >= 0 s, got {self.after}"]


def _range_problems(what: str, lo_hi: tuple[float, float], lo: float, hi: float) -> list[str]:
    """``[what: ...]`` unless ``lo <= lo_hi[0] <= lo_hi[1] <= hi``."""
    a, b = lo_hi
    return [] if lo <= a <= b <= hi else [f"{what} must be [min, max] with {lo:g} <= min <= max <= {hi:g}, got {[a, b]}"]


@dataclass(frozen=True)
class Crowd:
    """People walking through the room: ``count`` of them, each a closed loop of
    ``waypoints`` random free points (at least 1.5 m apart, the legs clear of the static
    geometry) walked at a speed drawn from ``speed`` [m/s], standing a time drawn from
    ``pause`` [s] at each waypoint, a body ``radius`` drawn from ``radius`` [m]."""

    count: int = 2
    speed: tuple[float, float] = (0.3, 1.2)
    pause: tuple[float, float] = (0.0, 3.0)
    radius: tuple[float, float] = (0.15, 0.25)
    waypoints: int = 3

    def validate(self) -> list[str]:
        out = [] if 1 <= self.count <= 50 else [f"count must be 1..50, got {self.count}"]
        out += [] if 2 <= self.waypoints <= 20 else [f"waypoints must be 2..20, got {self.waypoints}"]
        return (out + _range_problems("speed", self.speed, 0.05, 2.0)
                + _range_problems("pause", self.pause, 0.0, 600.0)
                + _range_problems("radius", self.radius, 0.1, 0.4))


@dataclass(frozen=True)
class Clutter:
    """Boxes the map does not show, near the robot's routes: ``count`` boxes, footprint
    sides drawn from ``size`` [m], heights from ``height`` [m] (the LoCoBot's lidar scans
    at 0.64 m: a lower box is only found by the bumper), each centred within ``near``
    [m] of a route (the shortest ways between the start, the stand-offs in front of the
    items and the depot), none within ``keep_clear`` [m] of those places (edge to place:
    a goal closer to a box than a local planner's safety zone could never be reached; the
    LoCoBot's zone round a box seen from one side reaches 0.6 m), and always
    leaving a ``passage`` [m] wide way between them (None: the robot's footprint
    diameter plus 0.3 m)."""

    count: int = 3
    size: tuple[float, float] = (0.25, 0.45)
    height: tuple[float, float] = (0.7, 1.0)
    near: float = 0.5
    keep_clear: float = 0.8
    passage: float | None = None

    def validate(self) -> list[str]:
        out = [] if 1 <= self.count <= 50 else [f"count must be 1..50, got {self.count}"]
        if self.near < 0 or self.keep_clear < 0 or (self.passage is not None and self.passage <= 0):
            out.append("near and keep_clear must be >= 0 m, passage > 0 m")
        return out + _range_problems("size", self.size, 0.05, 2.0) + _range_problems(
            "height", self.height, 0.02, 3.0)


@dataclass(frozen=True)
class FaultConfig:
    """The ``sim.faults`` section (all faults off by default)."""

    arm_fail: Literal["never", "always"] = "never"
    arm_fail_attempts: tuple[int, ...] = ()
    nav_blocked: tuple[str, ...] = ()
    nav_blocked_depth: float = 1.0
    marker_bias: dict[str, tuple[float, float]] = field(default_factory=dict)
    grasp_slip: GraspSlip | None = None
    camera_dropout: Dropout = field(default_factory=Dropout)
    lidar_dropout: Dropout = field(default_factory=Dropout)
    reflector_dropout: ReflectorDropout = field(default_factory=ReflectorDropout)
    kidnap: Kidnap | None = None
    crowd: Crowd | None = None
    clutter: Clutter | None = None

    def validate(self) -> list[str]:
        out = [f"arm_fail_attempts: attempt numbers start at 1, got {a}" for a in self.arm_fail_attempts if a < 1]
        if self.nav_blocked_depth <= 0:
            out.append("nav_blocked_depth must be > 0 m")
        return out

    def item_names(self) -> list[tuple[str, str]]:
        """(key, item name) pairs this config refers to, for checking against the world."""
        refs = [("nav_blocked", n) for n in self.nav_blocked] + [("marker_bias", n) for n in self.marker_bias]
        if self.grasp_slip is not None:
            refs += [("grasp_slip.items", n) for n in self.grasp_slip.items]
        return refs


def blocking_obstacles(world: World, items: tuple[str, ...], depth: float = 1.0) -> tuple[Obstacle, ...]:
    """Obstacles that fill the floor in front of each named item: from 0.05 m in front of
    the item's face out to ``depth`` [m], 1.2 m wide, 0.3 m tall (under shelf boards
    reachable by the arm would be blocked too, so the base cannot stand anywhere near)."""
    out = []
    for name in items:
        T = world.item_poses[name]
        it = world.item(name)
        yaw = math.atan2(T[1, 0], T[0, 0])
        front = it.size[0] / 2 + 0.05
        # the box's face is inside the shelf: start past the shelf front
        for s in world.spec.shelves:
            if s.name == it.shelf:
                front = it.inset + it.size[0] / 2 + 0.05
        centre = front + depth / 2
        x = T[0, 3] + centre * math.cos(yaw)
        y = T[1, 3] + centre * math.sin(yaw)
        out.append(Obstacle(name=f"fault_block_{name}", pose=(x, y, yaw), size=(depth, 1.2, 0.3)))
    return tuple(out)


# --------------------------------------------------------------------------- world faults


#: [m] cell size of the free-space grids the world faults draw on
_RES = 0.05


class _FreeSpace:
    """The room's floor at :data:`_RES` cells: ``dist`` [m], the distance from each cell
    centre to the nearest static geometry (unmapped obstacles included; boxes whose
    bottom is below ``max_bottom`` [m]) or wall, and cell <-> map conversions."""

    def __init__(self, world: World, max_bottom: float = 1.0) -> None:
        X, Y = room_grid(world.spec.room, 0.0, _RES)
        self.h, self.w = X.shape
        free = np.ones((self.h + 2, self.w + 2), dtype=np.uint8)  # a ring of wall cells around the room
        free[0, :] = free[-1, :] = free[:, 0] = free[:, -1] = 0
        inner = free[1:-1, 1:-1]
        for _, T, size, _kind in world.static_boxes():
            if T[2, 3] - size[2] / 2 > max_bottom:
                continue
            inner[footprint_mask(X, Y, T, size)] = 0
        d = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(np.float64) * _RES
        self.dist = d[1:-1, 1:-1] - 0.5 * _RES  # centre to the obstacle cell's edge

    def cell(self, x: float, y: float) -> tuple[int, int]:
        return min(self.h - 1, max(0, int(y / _RES))), min(self.w - 1, max(0, int(x / _RES)))

    def xy(self, r: int, c: int) -> tuple[float, float]:
        return (c + 0.5) * _RES, (r + 0.5) * _RES

    def clearance(self, x: float, y: float) -> float:
        return float(self.dist[self.cell(x, y)])

    def segment_clear(self, a: tuple[float, float], b: tuple[float, float], need: float) -> bool:
        """Every point of segment ``a``-``b`` (sampled each half cell) has ``need`` [m] of clearance."""
        n = max(2, math.ceil(math.hypot(b[0] - a[0], b[1] - a[1]) / (0.5 * _RES)) + 1)
        return all(self.clearance(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])) >= need
                   for f in np.linspace(0.0, 1.0, n))


def _rng(seed: int | None, stream: int) -> np.random.Generator:
    return np.random.default_rng(None if seed is None else [seed & (2**63 - 1), stream])


def crowd_people(world: World, crowd: Crowd, seed: int | None) -> tuple[Person, ...]:
    """``crowd.count`` people (named ``crowd_1``, ...) walking random loops through
    ``world``'s free floor (see :class:`Crowd`); their first waypoint is at least 1.2 m
    from the robot's start. Drawn from the ``[seed, CROWD_STREAM]`` generator."""
    rng = _rng(seed, CROWD_STREAM)
    free = _FreeSpace(world)
    sx, sy = world.spec.room.size
    out: list[Person] = []
    for k in range(crowd.count):
        radius = float(rng.uniform(*crowd.radius))
        pts: list[tuple[float, float]] = []
        for _ in range(5000):
            if len(pts) == crowd.waypoints:
                if free.segment_clear(pts[-1], pts[0], radius + 0.05):
                    break
                pts.pop()
                continue
            q = (float(rng.uniform(0.0, sx)), float(rng.uniform(0.0, sy)))
            if free.clearance(*q) < radius + 0.15:
                continue
            if not pts and math.hypot(q[0] - world.start.x, q[1] - world.start.y) < 1.2:
                continue
            if pts and (math.hypot(q[0] - pts[-1][0], q[1] - pts[-1][1]) < 1.5
                        or not free.segment_clear(pts[-1], q, radius + 0.05)):
                continue
            pts.append(q)
        else:
            raise RuntimeError(f"crowd: no walkable loop of {crowd.waypoints} waypoints in world {world.name!r} "
                               f"in 5000 draws (the room is too cluttered or too small)")
        out.append(Person(name=f"crowd_{k + 1}", waypoints=tuple(pts), radius=radius,
                          speed=float(rng.uniform(*crowd.speed)), pause=float(rng.uniform(*crowd.pause))))
    return tuple(out)


def _places(world: World, free: _FreeSpace, standoff: float = 0.6) -> list[tuple[float, float]]:
    """Where the robot goes in a fetch: its start, ``standoff`` [m] in front of each item's
    marker face (out of the shelf) and in front of each depot (its free side)."""
    out = [(world.start.x, world.start.y)]
    for it in world.spec.items:
        T = world.item_poses[it.name]
        front = it.size[0] / 2 + next((s.depth / 2 for s in world.spec.shelves if s.name == it.shelf), 0.0)
        out.append((T[0, 3] + (front + standoff) * T[0, 0], T[1, 3] + (front + standoff) * T[1, 0]))
    for d in world.spec.depots:
        c, s_ = math.cos(d.pose[2]), math.sin(d.pose[2])
        sides = [((d.size[0] / 2 + standoff) * c, (d.size[0] / 2 + standoff) * s_),
                 (-(d.size[0] / 2 + standoff) * c, -(d.size[0] / 2 + standoff) * s_),
                 (-(d.size[1] / 2 + standoff) * s_, (d.size[1] / 2 + standoff) * c),
                 ((d.size[1] / 2 + standoff) * s_, -(d.size[1] / 2 + standoff) * c)]
        out.append(max(((d.pose[0] + a, d.pose[1] + b) for a, b in sides), key=lambda q: free.clearance(*q)))
    return out


def _bfs(passable: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """Parent index (flat) of each cell on 8-connected shortest-hop paths from ``start``
    through ``passable`` cells (-1: unreached; the start is its own parent)."""
    h, w = passable.shape
    parent = np.full(h * w, -1, dtype=np.int64)
    s = start[0] * w + start[1]
    parent[s] = s
    flat = passable.ravel()
    queue = deque([s])
    steps = [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)]
    while queue:
        i = queue.popleft()
        r, c = divmod(i, w)
        for dr, dc in steps:
            rr, cc = r + dr, c + dc
            if 0 <= rr < h and 0 <= cc < w:
                j = rr * w + cc
                if parent[j] < 0 and flat[j]:
                    parent[j] = i
                    queue.append(j)
    return parent


def _connected(passable: np.ndarray, cells: list[tuple[int, int]]) -> bool:
    """All ``cells`` lie in one 8-connected component of ``passable``."""
    n, labels = cv2.connectedComponents(passable.astype(np.uint8), connectivity=8)
    ids = {int(labels[r, c]) for r, c in cells}
    return len(ids) == 1 and 0 not in ids and n > 1


def clutter_obstacles(world: World, clutter: Clutter, seed: int | None, robot_radius: float) -> tuple[Obstacle, ...]:
    """``clutter.count`` unmapped boxes (named ``clutter_1``, ...) near the routes of a
    fetch in ``world`` (see :class:`Clutter`): each box centre lies within ``near`` of a
    cell of the shortest routes between the start, the item stand-offs and the depots,
    clears the static geometry and the other boxes, keeps ``keep_clear`` from those
    places, and the places stay connected through a ``passage`` wide way (default: for a
    footprint of ``robot_radius`` [m]). A box that cannot be placed in 500 draws is left
    out (logged). Drawn from the ``[seed, CLUTTER_STREAM]`` generator."""
    rng = _rng(seed, CLUTTER_STREAM)
    free = _FreeSpace(world)
    passage = clutter.passage if clutter.passage is not None else 2.0 * robot_radius + 0.3
    half_pass = passage / 2
    stops = _places(world, free)  # every one kept clear; those with room for the passage kept connected
    places = [q for q in stops if free.clearance(*q) >= half_pass]
    cells = [free.cell(*q) for q in places]
    passable = free.dist >= half_pass
    if len(cells) < 2 or not _connected(passable, cells):
        log.warning("clutter: the places of world %r are not connected through a %.2f m passage; no clutter",
                    world.name, passage)
        return ()
    parent = _bfs(passable, cells[0])
    route: set[int] = set()
    for r, c in cells[1:]:
        j = r * free.w + c
        while parent[j] != j and parent[j] >= 0:
            route.add(j)
            j = int(parent[j])
    route_cells = np.array(sorted(route), dtype=np.int64)
    boxes: list[Obstacle] = []
    occupied = free.dist.copy()
    X, Y = np.meshgrid((np.arange(free.w) + 0.5) * _RES, (np.arange(free.h) + 0.5) * _RES)
    for k in range(clutter.count):
        for _ in range(500):
            r, c = divmod(int(route_cells[rng.integers(route_cells.size)]), free.w)
            bx, by = free.xy(r, c)
            ang, off = rng.uniform(-math.pi, math.pi), rng.uniform(0.0, clutter.near)
            x, y = bx + off * math.cos(ang), by + off * math.sin(ang)
            lx, ly = rng.uniform(*clutter.size, 2)
            yaw = float(rng.uniform(-math.pi, math.pi))
            reach = 0.5 * math.hypot(lx, ly)
            if occupied[free.cell(x, y)] < reach + 0.02:
                continue  # on the static geometry or another box
            if any(math.hypot(x - q[0], y - q[1]) < clutter.keep_clear + reach for q in stops):
                continue
            dx, dy = X - x, Y - y
            u = math.cos(yaw) * dx + math.sin(yaw) * dy
            v = -math.sin(yaw) * dx + math.cos(yaw) * dy
            inside = (np.abs(u) <= lx / 2) & (np.abs(v) <= ly / 2)
            grown = np.maximum(np.abs(u) - lx / 2, 0.0) ** 2 + np.maximum(np.abs(v) - ly / 2, 0.0) ** 2
            trial_pass = passable & (grown >= half_pass**2)
            if not _connected(trial_pass, cells):
                continue
            passable = trial_pass
            occupied = np.where(inside, 0.0, np.minimum(occupied, np.sqrt(grown)))
            boxes.append(Obstacle(name=f"clutter_{k + 1}", pose=(float(x), float(y), yaw),
                                  size=(float(lx), float(ly), float(rng.uniform(*clutter.height))), unmapped=True))
            break
        else:
            log.warning("clutter: box %d of %d not placed in world %r in 500 draws", k + 1, clutter.count, world.name)
    return tuple(boxes)


def world_extras(world: World, cfg: FaultConfig, seed: int | None,
                 robot_radius: float) -> tuple[tuple[Obstacle, ...], tuple[Person, ...]]:
    """What the faults add to ``world`` for a robot of footprint ``robot_radius`` [m]:
    obstacles (``nav_blocked``'s blocks, then the ``clutter`` boxes, placed around the
    blocks) and people (the ``crowd``, walking around both). Empty tuples when none of
    these faults is on."""
    obstacles = blocking_obstacles(world, cfg.nav_blocked, cfg.nav_blocked_depth) if cfg.nav_blocked else ()
    if cfg.clutter is not None:
        obstacles += clutter_obstacles(replace(world, obstacles=world.obstacles + obstacles), cfg.clutter, seed,
                                       robot_radius)
    people: tuple[Person, ...] = ()
    if cfg.crowd is not None:
        people = crowd_people(replace(world, obstacles=world.obstacles + obstacles), cfg.crowd, seed)
    return obstacles, people


class FaultInjector:
    """Decides, deterministically from a seeded generator, when each fault fires."""

    def __init__(self, cfg: FaultConfig, rng: np.random.Generator) -> None:
        self.cfg = cfg
        self._rng = rng
        self.arm_attempts = 0
        self._kidnapped = False
        self.fired: list[tuple[float, str]] = []  #: (clock time, fault) log, for tests and campaigns

    def arm_attempt_fails(self, now: float) -> bool:
        """Count one arm goal and say whether it must fail."""
        self.arm_attempts += 1
        fail = self.cfg.arm_fail == "always" or self.arm_attempts in self.cfg.arm_fail_attempts
        if fail:
            self.fired.append((now, f"arm_fail attempt {self.arm_attempts}"))
        return fail

    def _dropped(self, d: Dropout, now: float, what: str) -> bool:
        if any(a <= now <= b for a, b in d.intervals) or (d.p > 0 and self._rng.random() < d.p):
            self.fired.append((now, what))
            return True
        return False

    def camera_dropped(self, now: float) -> bool:
        return self._dropped(self.cfg.camera_dropout, now, "camera_dropout")

    def lidar_dropped(self, now: float) -> bool:
        return self._dropped(self.cfg.lidar_dropout, now, "lidar_dropout")

    def reflectors_covered(self, now: float) -> frozenset[str] | None:
        """The reflectors covered for a scan at ``now`` [s] (an empty set: all of them), or
        None when none is."""
        d = self.cfg.reflector_dropout
        return frozenset(d.reflectors) if self._dropped(d, now, "reflector_dropout") else None

    def kidnap_pose(self, now: float, here: tuple[float, float], clear: Callable[[float, float], bool],
                    bounds: tuple[float, float, float, float]) -> tuple[float, float, float] | None:
        """Once the kidnap is due at ``now`` [s] (and only once): where to put the robot,
        ``(x, y, yaw)`` in ``map``. A random pose is drawn uniformly in ``bounds`` ``(x0,
        y0, x1, y1)`` [m] until ``clear(x, y)`` and it lies ``min_distance`` from ``here``."""
        k = self.cfg.kidnap
        if k is None or self._kidnapped or now < k.at:
            return None
        self._kidnapped = True
        pose = k.pose
        if pose is None:
            x0, y0, x1, y1 = bounds
            for _ in range(10000):
                x, y = float(self._rng.uniform(x0, x1)), float(self._rng.uniform(y0, y1))
                if math.hypot(x - here[0], y - here[1]) >= k.min_distance and clear(x, y):
                    pose = (x, y, float(self._rng.uniform(-math.pi, math.pi)))
                    break
            else:
                raise RuntimeError(f"kidnap: no clear pose {k.min_distance} m from {here} in 10000 draws")
        self.fired.append((now, f"kidnap to ({pose[0]:.3f}, {pose[1]:.3f}, {pose[2]:.3f})"))
        return pose

    def slip_after(self, item: str) -> float | None:
        """Seconds of holding after which ``item`` slips out, or None."""
        gs = self.cfg.grasp_slip
        if gs is None or (gs.items and item not in gs.items):
            return None
        return gs.after
