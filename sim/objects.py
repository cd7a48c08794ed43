"""Untagged objects: ordinary lab objects without markers, for the ``fetch_object`` mission.

A world's ``objects:`` list (docs/worlds.md) places objects of a few kinds on shelf
boards, tables or anywhere. Each kind is a set of coloured parts (boxes and cylinders)
in the object's frame, whose origin is the centre of the object's bounding box (x along
its long side, z up); the centre of mass follows from the parts' masses, so a two-part
object's is not its box centre:

* ``box``: one red box, 0.05 x 0.05 x 0.08 m, standing;
* ``cylinder``: one violet upright cylinder, 0.05 m across, 0.09 m tall;
* ``screwdriver``: a yellow handle (0.10 x 0.04 x 0.04 m) and a cyan blade (0.09 x 0.04 x
  0.03 m), lying; the blade is its ``dangerous`` part;
* ``pliers``: two magenta handles (0.10 x 0.015 x 0.025 m, 15 mm apart) and a lime head
  (0.06 x 0.045 x 0.03 m, the jaws), lying; the head is its dangerous part;
* ``pen``: one green cylinder, 0.04 m across, 0.14 m long, lying.

In pybullet an object is one dynamic multibody: its first part is the base link, the
others are links on fixed joints, so a contact names the part it touched
(:func:`parts_touched`). Sim-only truth helpers (never for skills): the true centre of
mass (:func:`centre_of_mass`), the pixel where a part's centre appears in a camera
(:func:`project_point`), which parts the gripper's pads touch.

Units: metres, kilograms, radians; poses in ``map``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from mmexec.config.yamlload import did_you_mean
from mmexec.drivers.geometry import planar_transform, position_quat, quat_to_matrix

if TYPE_CHECKING:
    from mmexec.sim.world import WorldSpec

__all__ = [
    "KINDS",
    "ObjectKind",
    "Part",
    "SimObject",
    "centre_of_mass",
    "check_placement",
    "object_extent",
    "object_frame",
    "part_centre",
    "parts_touched",
    "place_object",
    "project_point",
    "spawn_objects",
]


@dataclass(frozen=True)
class Part:
    """One rigid part of an object: ``shape`` box (``size`` full extents [m]) or cylinder
    (``size`` = (diameter, diameter, length) [m], axis along the part's local z before
    ``axis`` turns it: ``z`` upright, ``x`` lying along the object's x); ``centre`` [m] in
    the object frame; ``mass`` [kg]; ``rgb`` in 0..1; ``dangerous``: the part the operator
    marks for a dangerous item."""

    name: str
    shape: Literal["box", "cylinder"]
    size: tuple[float, float, float]
    centre: tuple[float, float, float]
    mass: float
    rgb: tuple[float, float, float]
    axis: Literal["z", "x"] = "z"
    dangerous: bool = False


@dataclass(frozen=True)
class ObjectKind:
    """A kind of object: its ``parts`` and bounding box ``size`` [m] (x long side, y, z
    height), origin at the box centre."""

    name: str
    size: tuple[float, float, float]
    parts: tuple[Part, ...]


_RED, _VIOLET, _YELLOW, _CYAN = (0.9, 0.08, 0.08), (0.5, 0.12, 0.85), (0.95, 0.8, 0.08), (0.08, 0.8, 0.9)
_MAGENTA, _LIME, _GREEN = (0.9, 0.1, 0.6), (0.6, 0.9, 0.1), (0.08, 0.7, 0.2)

#: The object kinds a world can place (module doc).
KINDS: Mapping[str, ObjectKind] = {
    "box": ObjectKind("box", (0.05, 0.05, 0.08), (Part("body", "box", (0.05, 0.05, 0.08), (0, 0, 0), 0.08, _RED),)),
    "cylinder": ObjectKind("cylinder", (0.05, 0.05, 0.09),
                           (Part("body", "cylinder", (0.05, 0.05, 0.09), (0, 0, 0), 0.08, _VIOLET),)),
    "screwdriver": ObjectKind("screwdriver", (0.19, 0.04, 0.04), (
        Part("handle", "box", (0.10, 0.04, 0.04), (-0.045, 0, 0), 0.05, _YELLOW),
        Part("blade", "box", (0.09, 0.04, 0.03), (0.05, 0, -0.005), 0.06, _CYAN, dangerous=True),
    )),
    "pliers": ObjectKind("pliers", (0.16, 0.045, 0.03), (
        Part("handle_l", "box", (0.10, 0.015, 0.025), (-0.03, 0.015, -0.0025), 0.03, _MAGENTA),
        Part("handle_r", "box", (0.10, 0.015, 0.025), (-0.03, -0.015, -0.0025), 0.03, _MAGENTA),
        Part("head", "box", (0.06, 0.045, 0.03), (0.05, 0, 0), 0.08, _LIME, dangerous=True),
    )),
    "pen": ObjectKind("pen", (0.14, 0.04, 0.04), (Part("body", "cylinder", (0.04, 0.04, 0.14), (0, 0, 0), 0.05, _GREEN,
                                                        axis="x"),)),
}


@dataclass(frozen=True)
class SimObject:
    """An untagged object in a world file: ``kind`` (one of :data:`KINDS`); placement as
    an item's: ``shelf`` + ``board`` (0 = lowest) + ``offset`` (along the shelf width) +
    ``inset`` (shelf front to the object's front), or ``table`` + ``position`` [x, y] in
    map, or ``pose`` [x, y, z, yaw] of the bounding-box centre; ``yaw`` [rad] turns it on
    its support (0: its long side along the shelf's width / the table's x)."""

    name: str
    kind: str
    shelf: str | None = None
    board: int = 0
    offset: float = 0.0
    inset: float = 0.08
    table: str | None = None
    position: tuple[float, float] | None = None
    pose: tuple[float, float, float, float] | None = None
    yaw: float = 0.0

    @property
    def model(self) -> ObjectKind:
        return KINDS[self.kind]

    def validate(self) -> list[str]:
        out = []
        if self.kind not in KINDS:
            out.append(f"object {self.name!r}: unknown kind {self.kind!r}" + (did_you_mean(self.kind, KINDS)
                                                                             or f" (kinds: {', '.join(KINDS)})"))
        if sum(x is not None for x in (self.shelf, self.table, self.pose)) != 1:
            out.append(f"object {self.name!r}: give exactly one of shelf, table or pose")
        if self.table is not None and self.position is None:
            out.append(f"object {self.name!r}: an object on a table needs position [x, y]")
        return out


def object_extent(obj: SimObject) -> tuple[float, float, float]:
    """The object's bounding box [m] in the frame of its support: (along the shelf's
    depth / map x, across, height) after ``yaw``."""
    lx, ly, lz = obj.model.size
    c, s = abs(math.cos(obj.yaw)), abs(math.sin(obj.yaw))
    return (c * lx + s * ly, s * lx + c * ly, lz)


def centre_of_mass(kind: ObjectKind) -> np.ndarray:
    """The centre of mass (3,) [m] in the object frame: the parts' centres weighted by
    their masses (each part uniform)."""
    m = np.array([pt.mass for pt in kind.parts])
    c = np.array([pt.centre for pt in kind.parts], dtype=float)
    return (m[:, None] * c).sum(axis=0) / m.sum()


def part_centre(kind: ObjectKind, name: str) -> np.ndarray:
    """Centre (3,) [m] of part ``name`` in the object frame."""
    for pt in kind.parts:
        if pt.name == name:
            return np.array(pt.centre, dtype=float)
    raise KeyError(f"{kind.name} has no part {name!r}")


def place_object(spec: WorldSpec, obj: SimObject, rng: np.random.Generator, xy: float, yaw: float) -> np.ndarray:
    """``T_map_object`` (bounding-box centre) of ``obj`` in the world ``spec``, slid by up
    to ``xy`` [m] along its support and turned by up to ``yaw`` [rad] (uniform draws from
    ``rng``)."""
    jx, jy = rng.uniform(-xy, xy), rng.uniform(-yaw, yaw)
    h = obj.model.size[2]
    if obj.pose is not None:
        x, y, z, th = obj.pose
        return planar_transform(x + jx, y, th + obj.yaw + jy, z)
    if obj.table is not None and obj.position is not None:
        tb = next(t for t in spec.tables if t.name == obj.table)
        return planar_transform(obj.position[0] + jx, obj.position[1], tb.pose[2] + obj.yaw + jy, tb.size[2] + h / 2 + 1e-3)
    s = next(sh for sh in spec.shelves if sh.name == obj.shelf)
    ex = object_extent(obj)
    lim = s.width / 2 - 0.02 - ex[1] / 2
    off = float(np.clip(obj.offset + jx, -lim, lim))
    local_x = s.depth / 2 - obj.inset - ex[0] / 2
    z = s.boards[obj.board] + h / 2 + 1e-3
    return planar_transform(s.pose[0], s.pose[1], s.pose[2]) @ planar_transform(local_x, off, obj.yaw + jy, z)


def check_placement(spec: WorldSpec, obj: SimObject) -> list[str]:
    """Problems with where ``obj`` stands in ``spec``: unknown shelf or table, board
    index, does not fit the board's width, depth or height."""
    out = []
    if obj.shelf is not None:
        s = next((sh for sh in spec.shelves if sh.name == obj.shelf), None)
        if s is None:
            return [f"object {obj.name!r}: no shelf {obj.shelf!r}"]
        if not 0 <= obj.board < len(s.boards):
            return [f"object {obj.name!r}: shelf {s.name!r} has boards 0..{len(s.boards) - 1}, got {obj.board}"]
        ex = object_extent(obj)
        if abs(obj.offset) + ex[1] / 2 > s.width / 2 - 0.02 or obj.inset + ex[0] > s.depth:
            out.append(f"object {obj.name!r} does not fit shelf {s.name!r} (offset {obj.offset}, inset {obj.inset})")
        above = (s.boards[obj.board + 1] - s.board_thickness if obj.board + 1 < len(s.boards)
                 else s.height - s.board_thickness) - s.boards[obj.board]
        if ex[2] > above:
            out.append(f"object {obj.name!r} ({ex[2]} m tall) does not fit under the next board ({above:.3f} m free)")
    if obj.table is not None and all(t.name != obj.table for t in spec.tables):
        out.append(f"object {obj.name!r}: no table {obj.table!r}")
    return out


def _part_T(pt: Part) -> tuple[list[float], list[float]]:
    """Position and quaternion of a part's shape in the object frame."""
    T = np.eye(4)
    if pt.axis == "x":  # the cylinder's z axis along the object's x
        T[:3, :3] = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    T[:3, 3] = pt.centre
    return position_quat(T)


def spawn_objects(objects: Sequence[SimObject], poses: Mapping[str, np.ndarray], cid: int,
                  groups: tuple[int, int]) -> dict[str, int]:
    """Create each object as a dynamic multibody in client ``cid`` at ``poses[name]``
    (``T_map_object``); ``groups`` = (collision group, mask). Returns body ids by name.
    The base link is the first part; link i (0-based) is part i + 1."""
    import pybullet as p  # here: the world schema (this module's dataclasses) loads without the engine

    out: dict[str, int] = {}
    for obj in objects:
        kind = obj.model
        cols, viss, frames = [], [], []
        for pt in kind.parts:
            pos, quat = _part_T(pt)
            if pt.shape == "box":
                half = [s / 2 for s in pt.size]
                col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid)
                vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[*pt.rgb, 1.0], physicsClientId=cid)
            else:
                r, length = pt.size[0] / 2, pt.size[2]
                col = p.createCollisionShape(p.GEOM_CYLINDER, radius=r, height=length, physicsClientId=cid)
                vis = p.createVisualShape(p.GEOM_CYLINDER, radius=r, length=length, rgbaColor=[*pt.rgb, 1.0],
                                          physicsClientId=cid)
            cols.append(col)
            viss.append(vis)
            frames.append((pos, quat))
        T = poses[obj.name]
        (p0, q0) = frames[0]
        T0 = np.eye(4)
        T0[:3, 3] = p0
        T0[:3, :3] = quat_to_matrix(q0)
        Tb = T @ T0  # the base link's frame in map
        inv0 = np.linalg.inv(T0)
        links = []
        for (pos, quat) in frames[1:]:
            Ti = np.eye(4)
            Ti[:3, :3] = quat_to_matrix(quat)
            Ti[:3, 3] = pos
            links.append(position_quat(inv0 @ Ti))  # link frame relative to the base link
        bp, bq = position_quat(Tb)
        n = len(links)
        body = p.createMultiBody(
            baseMass=kind.parts[0].mass, baseCollisionShapeIndex=cols[0], baseVisualShapeIndex=viss[0],
            basePosition=bp, baseOrientation=bq,
            linkMasses=[pt.mass for pt in kind.parts[1:]], linkCollisionShapeIndices=cols[1:],
            linkVisualShapeIndices=viss[1:], linkPositions=[lp for lp, _ in links],
            linkOrientations=[lq for _, lq in links], linkInertialFramePositions=[[0, 0, 0]] * n,
            linkInertialFrameOrientations=[[0, 0, 0, 1]] * n, linkParentIndices=[0] * n,
            linkJointTypes=[p.JOINT_FIXED] * n, linkJointAxis=[[0, 0, 1]] * n, physicsClientId=cid)
        for li in range(-1, n):
            p.changeDynamics(body, li, lateralFriction=0.9, spinningFriction=0.001, rollingFriction=0.001,
                             physicsClientId=cid)
            p.setCollisionFilterGroupMask(body, li, groups[0], groups[1], physicsClientId=cid)
        p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING, physicsClientId=cid)
        out[obj.name] = body
    return out


# --------------------------------------------------------------------------- truth (sim only)


def object_frame(cid: int, body: int, kind: ObjectKind) -> np.ndarray:
    """SIM-ONLY: the true ``T_map_object`` of a spawned object now (from its base link,
    the first part)."""
    import pybullet as p

    pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
    Tb = np.eye(4)
    Tb[:3, :3] = quat_to_matrix(orn)
    Tb[:3, 3] = pos
    p0, q0 = _part_T(kind.parts[0])
    T0 = np.eye(4)
    T0[:3, :3] = quat_to_matrix(q0)
    T0[:3, 3] = p0
    return Tb @ np.linalg.inv(T0)


def parts_touched(objects: Mapping[str, SimObject], item: str, links: Sequence[int]) -> tuple[str, ...]:
    """SIM-ONLY: the names of the parts of object ``item`` (``objects`` by name) whose
    link indices are ``links`` (-1 the base link, the first part); () for an item that is
    not an untagged object."""
    obj = objects.get(item)
    if obj is None:
        return ()
    parts = obj.model.parts
    return tuple(parts[li + 1].name for li in sorted(links) if -1 <= li < len(parts) - 1)


def project_point(T_map_optical: np.ndarray, fx: float, fy: float, cx: float, cy: float,
                  point: Sequence[float]) -> tuple[float, float] | None:
    """Pixel ``(u, v)`` of a map point (3,) [m] in a pinhole camera at ``T_map_optical``
    (z forward, x right, y down), or None when it lies behind the camera."""
    q = np.linalg.inv(T_map_optical) @ np.array([*point, 1.0])
    if q[2] <= 1e-6:
        return None
    return (float(fx * q[0] / q[2] + cx), float(fy * q[1] / q[2] + cy))
