"""Plants with fruit for the ``pick_fruit`` mission (issue 14; thesis section 1.3).

A world's ``plants:`` list (docs/worlds.md) stands plants on the floor. A plant is a pot
and a trunk (static cylinders: in the map, the planning scene and the lidar's view),
thin branches and leaf clusters (visual only: they occlude the camera, but are soft, so
nothing collides with them), and fruit: apples and coloured balls, spheres of 3-5 cm
radius hanging at 0.4-1.2 m on the plant's ``front`` side (the side a robot works
from). Each fruit hangs from its branch by a **breakable constraint**, the thesis's
magnets: a point-to-point constraint between the top of the fruit (its stem) and the
branch whose force is limited to ``break_force`` [N]. Gravity alone cannot pull it off;
a gripper pulling harder moves the fruit away from the stem point, and once it is more
than :data:`BREAK_DISTANCE` away the constraint is removed: the fruit came off.

Fruit positions, sizes and classes are drawn per plant (:func:`place_plants`) from the
run seed when the world is randomised, from a fixed seed otherwise, with their own
generator (a world without plants draws what it always drew). Fruit never overlap: their
surfaces keep ``fruit_gap`` apart, and no leaf cluster sits in front of a fruit's
centre (leaves may hide part of it).

A **basket on the robot** (``sim.basket``: where on the base, its size) is a static body
moved with the base, as the fruit lying in it (:meth:`PlantSim.carry`). Depots may carry
an ArUco marker (:class:`mmexec.sim.world.Depot`), the thesis's marker-tagged basket.

Ground truth (sim-only, never for skills; :class:`PlantSim`): each fruit's state,
``plant`` (still hanging), ``held`` (in the gripper), ``robot_basket``, ``depot:NAME``
(lying in that depot's basket), ``floor`` or ``loose`` (anywhere else, e.g. falling), recorded in
the run's truth log (``sim.truth_log``, :mod:`mmexec.sim.truth`) as ``fruit_start`` (every
fruit: name, class, radius, centre) and a ``fruit`` record each time a fruit's state
changes (``t``, ``name``, ``state``, ``position``).

Units: metres, kilograms, newtons, radians; poses in ``map``.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from mmexec.sim.world import Depot

__all__ = [
    "BREAK_DISTANCE",
    "FRUIT_CLASSES",
    "Fruit",
    "FruitClass",
    "PlacedPlant",
    "Plant",
    "PlantSim",
    "RobotBasket",
    "place_plants",
    "spawn_plants",
]

#: [m] a fruit this far from its stem point has come off (the constraint is removed)
BREAK_DISTANCE = 0.01
#: [m] stem length between the fruit's top and the branch
STEM = 0.012
#: [m] a fruit whose centre lies over a basket's floor and at most this far above its rim
#: rests in it (on the others)
IN_BASKET = 0.05


@dataclass(frozen=True)
class FruitClass:
    """A kind of fruit: ``rgb`` colour (0..1) and ``density`` [kg/m^3] (the mass follows
    from the drawn radius)."""

    rgb: tuple[float, float, float]
    density: float


#: The thesis's objects, coloured so the classical detector's classes
#: (:data:`mmexec.skills.perception.detector.DEFAULT_CLASSES`) tell them apart: red
#: apples (about 150 g at r = 3.5 cm), hollow plastic balls (about 40 g).
FRUIT_CLASSES: dict[str, FruitClass] = {
    "apple": FruitClass((0.80, 0.07, 0.05), 830.0),
    "yellow_ball": FruitClass((0.92, 0.80, 0.08), 220.0),
    "green_ball": FruitClass((0.12, 0.65, 0.15), 220.0),
    "blue_ball": FruitClass((0.08, 0.22, 0.85), 220.0),
}

#: colours of the plant's parts: no hue/saturation a fruit class uses
_POT_RGB = (0.30, 0.30, 0.32)
_TRUNK_RGB = (0.45, 0.32, 0.20)
_LEAF_RGB = (0.36, 0.42, 0.30)


@dataclass(frozen=True)
class Plant:
    """A plant standing at ``pose`` [x, y, front yaw]: the fruit hang on the side facing
    ``front`` (within ``fruit_sector`` [rad] in all, centred on it).

    ``height``: trunk top [m]; ``trunk_radius`` [m]; ``pot`` [radius, height] [m].
    Fruit: ``fruit_count`` [min, max] per plant; ``fruit_radius`` [min, max] [m] (3-5 cm);
    ``fruit_height`` [min, max] of the centres [m] (0.4-1.2); ``fruit_ring`` [min, max]
    horizontal distance of the centres from the trunk axis [m]; ``fruit_gap`` [m] between
    fruit surfaces; ``fruit_classes`` drawn from (:data:`FRUIT_CLASSES`);
    ``break_force`` [N] the magnet's hold (above the heaviest fruit's weight).
    ``leaves``: leaf clusters (visual spheres of 6-14 cm radius) round the trunk."""

    name: str
    pose: tuple[float, float, float]
    height: float = 1.35
    trunk_radius: float = 0.025
    pot: tuple[float, float] = (0.16, 0.25)
    fruit_count: tuple[int, int] = (4, 6)
    fruit_radius: tuple[float, float] = (0.03, 0.04)
    fruit_height: tuple[float, float] = (0.4, 1.2)
    fruit_ring: tuple[float, float] = (0.16, 0.28)
    fruit_sector: float = 1.6
    fruit_gap: float = 0.06
    fruit_classes: tuple[str, ...] = ("apple", "yellow_ball", "green_ball", "blue_ball")
    break_force: float = 6.0
    leaves: int = 8

    def validate(self) -> list[str]:
        out = []
        pre = f"plant {self.name!r}"
        if not 0 < self.pot[0] and 0 < self.pot[1] < self.height:
            out.append(f"{pre}: pot [radius, height] must be > 0 and lower than the plant ({self.height} m)")
        if not 0 < self.trunk_radius < self.pot[0]:
            out.append(f"{pre}: trunk_radius must be > 0 and within the pot's radius")
        lo, hi = self.fruit_count
        if not 1 <= lo <= hi <= 20:
            out.append(f"{pre}: fruit_count must be 1 <= min <= max <= 20, got {list(self.fruit_count)}")
        lo, hi = self.fruit_radius
        if not 0.03 <= lo <= hi <= 0.05:
            out.append(f"{pre}: fruit_radius must lie in [0.03, 0.05] m with min <= max, got {list(self.fruit_radius)}")
        lo, hi = self.fruit_height
        if not self.pot[1] + self.fruit_radius[1] <= lo <= hi <= self.height - self.fruit_radius[1] - STEM:
            out.append(f"{pre}: fruit_height {list(self.fruit_height)} must lie above the pot and below the "
                       f"trunk top with min <= max")
        lo, hi = self.fruit_ring
        if not self.trunk_radius + self.fruit_radius[1] <= lo <= hi <= 1.0:
            out.append(f"{pre}: fruit_ring {list(self.fruit_ring)} must clear the trunk, min <= max <= 1 m")
        if not 0 < self.fruit_sector <= 2 * math.pi:
            out.append(f"{pre}: fruit_sector must be in (0, 2 pi] rad")
        if self.fruit_gap < 0:
            out.append(f"{pre}: fruit_gap must be >= 0 m")
        if not self.fruit_classes:
            out.append(f"{pre}: fruit_classes needs at least one class")
        for c in self.fruit_classes:
            if c not in FRUIT_CLASSES:
                out.append(f"{pre}: unknown fruit class {c!r} (known: {', '.join(FRUIT_CLASSES)})")
        heaviest = max((FRUIT_CLASSES[c].density for c in self.fruit_classes if c in FRUIT_CLASSES), default=0.0)
        weight = heaviest * 4.0 / 3.0 * math.pi * self.fruit_radius[1] ** 3 * 9.81
        if not self.break_force > 1.5 * weight:
            out.append(f"{pre}: break_force {self.break_force} N must exceed 1.5 x the heaviest fruit's weight "
                       f"({weight:.2f} N): the magnets would let go on their own")
        if not 0 <= self.leaves <= 40:
            out.append(f"{pre}: leaves must be 0..40")
        return out

    def solid_parts(self) -> list[tuple[str, tuple[float, float, float], tuple[float, float, float]]]:
        """The static parts: ``(name, centre [x, y, z], bounding box size)`` of the pot and
        the trunk (both upright cylinders)."""
        x, y, _ = self.pose
        pr, ph = self.pot
        r = self.trunk_radius
        return [(f"{self.name}_pot", (x, y, ph / 2), (2 * pr, 2 * pr, ph)),
                (f"{self.name}_trunk", (x, y, (ph + self.height) / 2), (2 * r, 2 * r, self.height - ph))]


@dataclass(frozen=True)
class Fruit:
    """One drawn fruit: ``name`` (``<plant>_fruit_<i>``), ``label`` (its class), ``radius``
    [m], ``mass`` [kg], ``centre`` [x, y, z] in map as it hangs, ``anchor`` the stem point
    on the branch [x, y, z] (straight above the centre)."""

    name: str
    label: str
    radius: float
    mass: float
    centre: tuple[float, float, float]
    anchor: tuple[float, float, float]


@dataclass(frozen=True)
class PlacedPlant:
    """A plant with its drawn ``fruit`` and ``leaves`` (centre [x, y, z], radius) [m]."""

    spec: Plant
    fruit: tuple[Fruit, ...]
    leaves: tuple[tuple[float, float, float, float], ...]


def _plant_rng(plant: Plant, seed: int | None) -> np.random.Generator:
    """The plant's own generator: from the run seed when randomised, else fixed; and its
    name, so two plants draw differently."""
    h = int.from_bytes(hashlib.sha256(plant.name.encode()).digest()[:4], "big")
    return np.random.default_rng([0x504C414E, h] + ([] if seed is None else [1, int(seed) & 0xFFFFFFFF]))


def _draw_fruit(plant: Plant, rng: np.random.Generator) -> tuple[Fruit, ...]:
    x0, y0, front = plant.pose
    n = int(rng.integers(plant.fruit_count[0], plant.fruit_count[1] + 1))
    out: list[Fruit] = []
    for _ in range(200 * n):
        if len(out) == n:
            break
        label = str(plant.fruit_classes[int(rng.integers(len(plant.fruit_classes)))])
        r = float(rng.uniform(*plant.fruit_radius))
        ang = front + float(rng.uniform(-plant.fruit_sector / 2, plant.fruit_sector / 2))
        d = float(rng.uniform(*plant.fruit_ring))
        z = float(rng.uniform(*plant.fruit_height))
        c = np.array([x0 + d * math.cos(ang), y0 + d * math.sin(ang), z])
        if any(np.linalg.norm(c - np.array(f.centre)) < r + f.radius + plant.fruit_gap for f in out):
            continue
        # a fruit's branch must not pass through a fruit hanging below it, nor its stem
        # through a fruit above (the branch runs from the trunk to the stem point)
        if any(_branch_hits(plant, f, c, r) for f in out):
            continue
        mass = FRUIT_CLASSES[label].density * 4.0 / 3.0 * math.pi * r ** 3
        out.append(Fruit(f"{plant.name}_fruit_{len(out) + 1}", label, r, mass, (float(c[0]), float(c[1]), z),
                         (float(c[0]), float(c[1]), z + r + STEM)))
    return tuple(out)


def _branch_hits(plant: Plant, f: Fruit, c: np.ndarray, r: float) -> bool:
    """Whether the branch of a new fruit at ``c`` (radius ``r``) or the branch of ``f``
    passes within 1.5 cm of the other fruit."""
    x0, y0, _ = plant.pose
    for (cc, rr), (other, ro) in (((c, r), (np.array(f.centre), f.radius)), ((np.array(f.centre), f.radius), (c, r))):
        top = cc[2] + rr + STEM
        a, b = np.array([x0, y0, top]), np.array([cc[0], cc[1], top])
        t = float(np.clip(np.dot(other - a, b - a) / max(float(np.dot(b - a, b - a)), 1e-12), 0.0, 1.0))
        if np.linalg.norm(other - (a + t * (b - a))) < ro + 0.015:
            return True
    return False


def _draw_leaves(plant: Plant, fruit: Sequence[Fruit], rng: np.random.Generator) -> tuple[tuple[float, ...], ...]:
    """Leaf clusters round the trunk, above the pot, up to the crown; none covers a
    fruit's centre as seen from the front (a leaf may hide part of a fruit)."""
    x0, y0, front = plant.pose
    out: list[tuple[float, float, float, float]] = []
    for _ in range(50 * max(plant.leaves, 1)):
        if len(out) == plant.leaves:
            break
        rad = float(rng.uniform(0.06, 0.14))
        ang = float(rng.uniform(0.0, 2 * math.pi))
        d = float(rng.uniform(0.0, plant.fruit_ring[1]))
        z = float(rng.uniform(plant.fruit_height[0] + 0.1, plant.height + 0.05))
        c = np.array([x0 + d * math.cos(ang), y0 + d * math.sin(ang), z])
        ahead = np.array([math.cos(front), math.sin(front), 0.0])
        ok = True
        for f in fruit:
            fc = np.array(f.centre)
            rel = c - fc
            along = float(rel @ ahead)
            lateral = float(np.linalg.norm(rel - along * ahead))
            # in front of the fruit (towards the robot) only if it leaves the centre in view
            if along > -rad and lateral < rad + 0.3 * f.radius:
                ok = False
                break
            if np.linalg.norm(rel) < rad + f.radius + 0.01:
                ok = False
                break
        if ok:
            out.append((float(c[0]), float(c[1]), z, rad))
    return tuple(out)


def place_plants(plants: Sequence[Plant], seed: int | None) -> tuple[PlacedPlant, ...]:
    """Draw each plant's fruit and leaves: from ``seed`` (a randomised world) or a fixed
    seed (None)."""
    out = []
    for pl in plants:
        rng = _plant_rng(pl, seed)
        fruit = _draw_fruit(pl, rng)
        out.append(PlacedPlant(pl, fruit, _draw_leaves(pl, fruit, rng)))
    return tuple(out)


# --------------------------------------------------------------------------- physics


@dataclass(frozen=True)
class RobotBasket:
    """The basket on the robot (``sim.basket``): its floor's centre ``xyz`` [m] in the
    base frame (``base_footprint``), ``size`` [x, y, rim height] [m], wall ``thickness``."""

    xyz: tuple[float, float, float] = (-0.205, 0.0, 0.40)
    size: tuple[float, float, float] = (0.20, 0.46, 0.12)
    thickness: float = 0.008

    def validate(self) -> list[str]:
        if min(*self.size, self.thickness) <= 0 or 2 * self.thickness >= min(self.size[:2]):
            return ["basket: size and thickness must be > 0 and the walls thinner than half the basket"]
        return []

    def parts(self) -> list[tuple[tuple[float, float, float], tuple[float, float, float]]]:
        """(centre in the basket frame, full size) of the floor and the four walls."""
        lx, ly, h = self.size
        w = self.thickness
        return [((0.0, 0.0, w / 2), (lx, ly, w)),
                ((lx / 2 - w / 2, 0.0, h / 2), (w, ly, h)), ((-lx / 2 + w / 2, 0.0, h / 2), (w, ly, h)),
                ((0.0, ly / 2 - w / 2, h / 2), (lx - 2 * w, w, h)), ((0.0, -ly / 2 + w / 2, h / 2), (lx - 2 * w, w, h))]


def _box_contains(T_map_frame: np.ndarray, size: tuple[float, float, float], point: np.ndarray,
                  above: float) -> bool:
    """Whether ``point`` lies inside the open box of ``size`` (floor at the frame's
    origin) at ``T_map_frame``, up to ``above`` [m] over its rim."""
    q = np.linalg.inv(T_map_frame) @ np.append(point, 1.0)
    return abs(q[0]) < size[0] / 2 and abs(q[1]) < size[1] / 2 and -0.01 < q[2] < size[2] + above


class PlantSim:
    """The plants' fruit in a pybullet client (create with :func:`spawn_plants`).

    ``bodies``: fruit body ids by name (the gripper holds them like items);
    ``fruit``: the drawn :class:`Fruit` by name. Per control tick :meth:`tick` breaks the
    constraints pulled beyond :data:`BREAK_DISTANCE` and records state changes; each
    placement of the base :meth:`carry` moves the robot's basket and what lies in it."""

    def __init__(self, cid: int, plants: Sequence[PlacedPlant], depots: Sequence[Depot],
                 basket: RobotBasket | None, start: np.ndarray) -> None:
        import pybullet as p

        self._cid = cid
        self.fruit: dict[str, Fruit] = {f.name: f for pl in plants for f in pl.fruit}
        self.bodies: dict[str, int] = {}
        self._cons: dict[str, int] = {}
        self._depots = tuple(depots)
        self.basket = basket
        self.basket_body: int | None = None
        self._T_base = start.copy()
        self.states: dict[str, str] = {}
        self.broken: dict[str, float] = {}  #: fruit name -> clock time [s] its magnet let go
        self._force = {f.name: pl.spec.break_force for pl in plants for f in pl.fruit}
        if basket is not None:
            self.basket_body = self._spawn_basket(basket)
        for f in self.fruit.values():
            rgb = FRUIT_CLASSES[f.label].rgb
            col = p.createCollisionShape(p.GEOM_SPHERE, radius=f.radius, physicsClientId=cid)
            vis = p.createVisualShape(p.GEOM_SPHERE, radius=f.radius, rgbaColor=[*rgb, 1.0],
                                      specularColor=[0.3, 0.3, 0.3], physicsClientId=cid)
            body = p.createMultiBody(f.mass, col, vis, list(f.centre), physicsClientId=cid)
            p.changeDynamics(body, -1, lateralFriction=0.9, rollingFriction=0.002, spinningFriction=0.002,
                             linearDamping=0.4, angularDamping=0.4,
                             activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING, physicsClientId=cid)
            c = p.createConstraint(body, -1, -1, -1, p.JOINT_POINT2POINT, [0, 0, 0], [0, 0, f.radius + STEM],
                                   list(f.anchor), physicsClientId=cid)
            p.changeConstraint(c, maxForce=self._force[f.name], physicsClientId=cid)
            self.bodies[f.name] = body
            self._cons[f.name] = c
            self.states[f.name] = "plant"

    # ------------------------------------------------------------------ the basket

    def _basket_T(self) -> np.ndarray:
        assert self.basket is not None
        T = np.eye(4)
        T[:3, 3] = self.basket.xyz
        return self._T_base @ T

    def _spawn_basket(self, basket: RobotBasket) -> int:
        import pybullet as p

        from mmexec.drivers.geometry import position_quat

        cid = self._cid
        cols, viss, poss = [], [], []
        for centre, size in basket.parts():
            half = [s / 2 for s in size]
            cols.append(p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid))
            viss.append(p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[0.5, 0.4, 0.25, 1.0],
                                            physicsClientId=cid))
            poss.append(list(centre))
        n = len(cols)
        pos, quat = position_quat(self._basket_T())
        body = p.createMultiBody(0, -1, -1, pos, quat, linkMasses=[0] * n, linkCollisionShapeIndices=cols,
                                 linkVisualShapeIndices=viss, linkPositions=poss,
                                 linkOrientations=[[0, 0, 0, 1]] * n, linkInertialFramePositions=[[0, 0, 0]] * n,
                                 linkInertialFrameOrientations=[[0, 0, 0, 1]] * n, linkParentIndices=[0] * n,
                                 linkJointTypes=[p.JOINT_FIXED] * n, linkJointAxis=[[0, 0, 1]] * n,
                                 physicsClientId=cid)
        for li in range(-1, n):
            p.changeDynamics(body, li, lateralFriction=0.8, physicsClientId=cid)
        return body

    def carry(self, T_map_base: np.ndarray, held_body: int | None) -> None:
        """The base was placed at ``T_map_base``: move the robot's basket with it, and every
        fruit lying in it (not ``held_body``) by the same step."""
        if self.basket_body is None or np.array_equal(T_map_base, self._T_base):
            self._T_base = T_map_base.copy()
            return
        import pybullet as p

        from mmexec.drivers.geometry import position_quat

        cid = self._cid
        T_old = self._basket_T()
        step = T_map_base @ np.linalg.inv(self._T_base)
        inside = [b for n, b in self.bodies.items()
                  if b != held_body and n not in self._cons and self._in_robot_basket(b, T_old)]
        self._T_base = T_map_base.copy()
        p.resetBasePositionAndOrientation(self.basket_body, *position_quat(self._basket_T()), physicsClientId=cid)
        for b in inside:
            pos, orn = p.getBasePositionAndOrientation(b, physicsClientId=cid)
            T = np.eye(4)
            T[:3, :3] = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
            T[:3, 3] = pos
            p.resetBasePositionAndOrientation(b, *position_quat(step @ T), physicsClientId=cid)

    def _in_robot_basket(self, body: int, T_basket: np.ndarray | None = None) -> bool:
        if self.basket is None:
            return False
        import pybullet as p

        pos = np.array(p.getBasePositionAndOrientation(body, physicsClientId=self._cid)[0])
        return _box_contains(T_basket if T_basket is not None else self._basket_T(), self.basket.size, pos, IN_BASKET)

    # ------------------------------------------------------------------ magnets and truth

    def moving(self) -> bool:
        """Whether any fruit moves (physics must not pause)."""
        import pybullet as p

        for b in self.bodies.values():
            v, w = p.getBaseVelocity(b, physicsClientId=self._cid)
            if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > 1e-6 or w[0] * w[0] + w[1] * w[1] + w[2] * w[2] > 1e-4:
                return True
        return False

    def _state(self, name: str, body: int, pos: np.ndarray, held_body: int | None) -> str:
        if name in self._cons:
            return "plant"
        if body == held_body:
            return "held"
        if self._in_robot_basket(body):
            return "robot_basket"
        for d in self._depots:
            T = np.eye(4)
            c, s = math.cos(d.pose[2]), math.sin(d.pose[2])
            T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
            T[:3, 3] = (d.pose[0], d.pose[1], 0.0)
            if _box_contains(T, d.size, pos, IN_BASKET):
                return f"depot:{d.name}"
        return "floor" if pos[2] < self.fruit[name].radius + 0.02 else "loose"

    def tick(self, now: float, held_body: int | None, truth: Any = None) -> None:
        """Once per control tick at clock time ``now`` [s]: remove the magnets pulled more
        than :data:`BREAK_DISTANCE` off their stem point, and record each fruit whose
        state changed in ``truth`` (a :class:`mmexec.sim.truth.TruthLog`, or None)."""
        import pybullet as p

        cid = self._cid
        for name, body in self.bodies.items():
            pos_t, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
            pos = np.array(pos_t)
            f = self.fruit[name]
            cons = self._cons.get(name)
            if cons is not None:
                R = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
                stem = pos + R @ np.array([0.0, 0.0, f.radius + STEM])
                if float(np.linalg.norm(stem - np.array(f.anchor))) > BREAK_DISTANCE:
                    p.removeConstraint(cons, physicsClientId=cid)
                    del self._cons[name]
                    self.broken[name] = now
            state = self._state(name, body, pos, held_body)
            if state != self.states[name]:
                self.states[name] = state
                if truth is not None:
                    truth.record("fruit", t=round(now, 4), name=name, state=state,
                                 position=[round(float(v), 4) for v in pos])

    def start_record(self) -> dict[str, Any]:
        """The ``fruit_start`` truth record's fields: every fruit as drawn."""
        return {"fruit": [{"name": f.name, "label": f.label, "radius": round(f.radius, 4),
                           "centre": [round(v, 4) for v in f.centre]} for f in self.fruit.values()]}

    def position(self, name: str) -> np.ndarray:
        """True centre [m] of fruit ``name`` now (sim-only truth)."""
        import pybullet as p

        return np.array(p.getBasePositionAndOrientation(self.bodies[name], physicsClientId=self._cid)[0])


def _spawn_visuals(cid: int, plants: Sequence[PlacedPlant]) -> None:
    """Branches, stems and leaves: one visual-only body per plant (no collision)."""
    import pybullet as p

    for pl in plants:
        x0, y0, _ = pl.spec.pose
        viss, poss, orns = [], [], []
        for f in pl.fruit:
            ax, ay, az = f.anchor
            d = math.hypot(ax - x0, ay - y0)
            yaw = math.atan2(ay - y0, ax - x0)
            # branch: a thin box from the trunk to the stem point, and the stem down to the fruit
            viss.append(p.createVisualShape(p.GEOM_BOX, halfExtents=[d / 2, 0.006, 0.006],
                                            rgbaColor=[*_TRUNK_RGB, 1.0], physicsClientId=cid))
            poss.append([(x0 + ax) / 2, (y0 + ay) / 2, az + 0.006])
            orns.append(list(p.getQuaternionFromEuler((0.0, 0.0, yaw))))
            viss.append(p.createVisualShape(p.GEOM_CYLINDER, radius=0.003, length=STEM, rgbaColor=[*_TRUNK_RGB, 1.0],
                                            physicsClientId=cid))
            poss.append([ax, ay, az - STEM / 2])
            orns.append([0.0, 0.0, 0.0, 1.0])
        for lx, ly, lz, r in pl.leaves:
            viss.append(p.createVisualShape(p.GEOM_SPHERE, radius=r, rgbaColor=[*_LEAF_RGB, 1.0], physicsClientId=cid))
            poss.append([lx, ly, lz])
            orns.append([0.0, 0.0, 0.0, 1.0])
        n = len(viss)
        if n:
            p.createMultiBody(0, -1, -1, [0, 0, 0], linkMasses=[0] * n, linkCollisionShapeIndices=[-1] * n,
                              linkVisualShapeIndices=viss, linkPositions=poss, linkOrientations=orns,
                              linkInertialFramePositions=[[0, 0, 0]] * n,
                              linkInertialFrameOrientations=[[0, 0, 0, 1]] * n, linkParentIndices=[0] * n,
                              linkJointTypes=[p.JOINT_FIXED] * n, linkJointAxis=[[0, 0, 1]] * n, physicsClientId=cid)


def _spawn_depot_markers(cid: int, depots: Sequence[Depot], texture_dir: Any = None) -> None:
    """A textured quad (the marker with its white border) on each tagged depot's wall."""
    import pybullet as p

    from mmexec.drivers.geometry import position_quat
    from mmexec.sim.markers import QUIET_RATIO, marker_texture_path

    for d in depots:
        T = d.marker_pose()
        if T is None or d.marker is None:
            continue
        s = d.marker_size * QUIET_RATIO / 2
        # the quad in the marker frame: x right, y up, facing +z
        verts = [[-s, -s, 0.0], [s, -s, 0.0], [s, s, 0.0], [-s, s, 0.0]]
        vis = p.createVisualShape(p.GEOM_MESH, vertices=verts, indices=[0, 1, 2, 0, 2, 3],
                                  uvs=[[0, 0], [1, 0], [1, 1], [0, 1]], normals=[[0, 0, 1]] * 4, physicsClientId=cid)
        body = p.createMultiBody(0, -1, vis, *position_quat(T), physicsClientId=cid)
        tex = p.loadTexture(str(marker_texture_path(d.marker, texture_dir)), physicsClientId=cid)
        p.changeVisualShape(body, -1, textureUniqueId=tex, rgbaColor=[1, 1, 1, 1], physicsClientId=cid)


def spawn_plants(cid: int, plants: Sequence[PlacedPlant], depots: Sequence[Depot], basket: RobotBasket | None,
                 start: np.ndarray, groups: tuple[int, int], static_groups: tuple[int, int],
                 texture_dir: Any = None) -> PlantSim | None:
    """Create the plants' fruit (magnets on), branches and leaves, the depots' markers and
    the robot's basket (at ``start`` = ``T_map_base``) in client ``cid``. ``groups``: the
    fruit's collision (group, mask), ``static_groups`` the basket's. None when there is
    nothing of it (no plant, no basket): the world runs as before."""
    import pybullet as p

    _spawn_depot_markers(cid, depots, texture_dir)
    if not plants and basket is None:
        return None
    _spawn_visuals(cid, plants)
    sim = PlantSim(cid, plants, depots, basket, start)
    for b in sim.bodies.values():
        p.setCollisionFilterGroupMask(b, -1, groups[0], groups[1], physicsClientId=cid)
    if sim.basket_body is not None:
        for li in range(-1, p.getNumJoints(sim.basket_body, physicsClientId=cid)):
            p.setCollisionFilterGroupMask(sim.basket_body, li, static_groups[0], static_groups[1], physicsClientId=cid)
    return sim


def fruit_bodies(sim: PlantSim | None) -> Mapping[str, int]:
    """The fruit body ids by name (empty without plants)."""
    return {} if sim is None else dict(sim.bodies)
