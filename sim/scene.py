"""Spawns a :class:`~mmexec.sim.world.World` into a pybullet client.

Static geometry (walls, shelves, tables, depot, obstacles, reflectors) becomes one
fixed multibody, one link per part, so a single ``getClosestPoints`` call checks the
robot against all of it. Items are dynamic boxes; each carries a textured quad (its
marker) as a fixed massless-visual child link on its local +x face.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p

from mmexec.drivers.geometry import position_quat
from mmexec.sim.markers import QUIET_RATIO, marker_texture_path
from mmexec.sim.objects import spawn_objects
from mmexec.sim.panel import HOUSING_COLOR, SimPanels
from mmexec.sim.plant import PlantSim, RobotBasket, spawn_plants
from mmexec.sim.world import World

__all__ = [
    "GROUP_ARM",
    "GROUP_BODY",
    "GROUP_ITEM",
    "GROUP_QUERY",
    "GROUP_STATIC",
    "SceneHandles",
    "spawn_world",
    "yaw_of",
]

# Collision filter groups (bit masks; a pair collides when each one's group is in the
# other's mask). Static geometry never needs contacts with itself or with the kinematic
# robot body (the bumper check queries it directly with getClosestPoints), so the
# broadphase drops those pairs and stepSimulation only solves what can move. Bit 0 is
# Bullet's default group, used by ray tests (lidar): every mask includes it.
GROUP_QUERY = 1   #: rays and queries
GROUP_STATIC = 2  #: floor, walls, shelves, tables, depot, obstacles, reflectors
GROUP_ITEM = 4    #: dynamic items
GROUP_BODY = 8    #: robot links that move only with the kinematic base (base, tower, sensors)
GROUP_ARM = 16    #: arm and gripper links (may be blocked by shelves, push and grasp items)

_COLORS = {
    "wall": (0.85, 0.85, 0.8, 1.0),
    "shelf": (0.55, 0.4, 0.25, 1.0),
    "table": (0.45, 0.35, 0.3, 1.0),
    "depot": (0.2, 0.5, 0.8, 1.0),
    "obstacle": (0.8, 0.45, 0.2, 1.0),
    "reflector": (0.95, 0.95, 0.95, 1.0),
    "plant": (0.45, 0.32, 0.2, 1.0),
    "panel": HOUSING_COLOR,
}


@dataclass(frozen=True)
class SceneHandles:
    """Body ids in the pybullet client: ``static`` (all fixed parts; link i is
    ``static_names[i]``), ``floor``, ``items`` by name (the untagged objects of
    :mod:`mmexec.sim.objects` too: the gripper holds either)."""

    static: int
    static_names: tuple[str, ...]
    floor: int
    items: Mapping[str, int]
    plants: PlantSim | None = None  #: the plants' fruit (also in items) and the robot's basket (sim/plant.py)
    panels: SimPanels | None = None  #: the control panels' caps, lights and markers (sim/panel.py)


def yaw_of(T: np.ndarray) -> float:
    return math.atan2(T[1, 0], T[0, 0])


def _floor_visual(cid: int, sx: float, sy: float, tile: float = 0.5) -> int:
    """Upward-facing floor of the room plus 0.2 m under the walls as a mesh of ``tile`` [m]
    squares at z = 0 (only the top face: TinyRenderer culls back faces anyway, and
    smaller triangles keep its near-plane clipping tight)."""
    nx, ny = max(1, math.ceil((sx + 0.4) / tile)), max(1, math.ceil((sy + 0.4) / tile))
    xs = np.linspace(-0.2, sx + 0.2, nx + 1)
    ys = np.linspace(-0.2, sy + 0.2, ny + 1)
    verts = [[float(x), float(y), 0.0] for y in ys for x in xs]
    idx: list[int] = []
    for j in range(ny):
        for i in range(nx):
            a = j * (nx + 1) + i
            b, c, d = a + 1, a + nx + 2, a + nx + 1
            idx += [a, b, c, a, c, d]  # counter-clockwise seen from above
    return p.createVisualShape(p.GEOM_MESH, vertices=verts, indices=idx, normals=[[0.0, 0.0, 1.0]] * len(verts),
                               rgbaColor=[0.62, 0.62, 0.6, 1.0], physicsClientId=cid)


def spawn_world(world: World, cid: int, *, marker_bias: Mapping[str, tuple[float, float]] | None = None,
                texture_dir: Path | None = None, robot_basket: RobotBasket | None = None) -> SceneHandles:
    """Create the world's bodies in client ``cid``; ``marker_bias[item] = (lateral, up)``
    [m] prints that item's marker shifted on its face (fault injection).

    Creation order is drawing order for TinyRenderer, which shades a pixel only when it
    passes the depth test: items first, then furniture, walls and the floor last, so the
    large background surfaces are mostly rejected behind what stands in front of them
    (about a third less fragment work per frame in ``lab``). ``robot_basket``: the basket
    on the robot (:mod:`mmexec.sim.plant`), placed at the world's start pose."""
    items: dict[str, int] = {}
    bias = marker_bias or {}
    for it in world.spec.items:
        T = world.item_poses[it.name]
        half = [s / 2 for s in it.size]
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[*it.color, 1.0], physicsClientId=cid)
        s = it.marker_size * QUIET_RATIO / 2
        # quad on the +x face, seen from +x: right = +y, up = +z; uv (0,0) bottom-left
        verts = [[0, -s, -s], [0, s, -s], [0, s, s], [0, -s, s]]
        quad = p.createVisualShape(p.GEOM_MESH, vertices=verts, indices=[0, 1, 2, 0, 2, 3],
                                   uvs=[[0, 0], [1, 0], [1, 1], [0, 1]], normals=[[1, 0, 0]] * 4,
                                   physicsClientId=cid)
        dy, dz = bias.get(it.name, (0.0, 0.0))
        body = p.createMultiBody(
            baseMass=it.mass, baseCollisionShapeIndex=col, baseVisualShapeIndex=vis,
            basePosition=T[:3, 3].tolist(), baseOrientation=position_quat(T)[1],
            linkMasses=[0.0], linkCollisionShapeIndices=[-1], linkVisualShapeIndices=[quad],
            linkPositions=[[half[0] + 0.0005, dy, dz]], linkOrientations=[[0, 0, 0, 1]],
            linkInertialFramePositions=[[0, 0, 0]], linkInertialFrameOrientations=[[0, 0, 0, 1]],
            linkParentIndices=[0], linkJointTypes=[p.JOINT_FIXED], linkJointAxis=[[0, 0, 1]],
            physicsClientId=cid)
        tex = p.loadTexture(str(marker_texture_path(it.marker, texture_dir)), physicsClientId=cid)
        p.changeVisualShape(body, 0, textureUniqueId=tex, rgbaColor=[1, 1, 1, 1], physicsClientId=cid)
        # items at rest fall asleep (Bullet deactivation: still for 2 s) and cost nothing per
        # step until something touches them; contact with an awake body wakes them.
        p.changeDynamics(body, -1, lateralFriction=0.8, spinningFriction=0.001, rollingFriction=0.0,
                         activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING, physicsClientId=cid)
        for li in (-1, 0):
            p.setCollisionFilterGroupMask(body, li, GROUP_ITEM, GROUP_QUERY | GROUP_STATIC | GROUP_ITEM | GROUP_BODY | GROUP_ARM,
                                          physicsClientId=cid)
        items[it.name] = body
    items.update(spawn_objects(world.spec.objects, world.object_poses, cid,
                               (GROUP_ITEM, GROUP_QUERY | GROUP_STATIC | GROUP_ITEM | GROUP_BODY | GROUP_ARM)))
    panels = None
    if world.spec.panels:
        panels = SimPanels.spawn(world.spec.panels, world.panel_poses, cid,
                                 texture_path=lambda mid: marker_texture_path(mid, texture_dir),
                                 group=GROUP_STATIC, mask=GROUP_QUERY | GROUP_ITEM | GROUP_ARM)
    plants = spawn_plants(cid, world.plants, world.spec.depots, robot_basket, world.start.matrix(),
                          (GROUP_ITEM, GROUP_QUERY | GROUP_STATIC | GROUP_ITEM | GROUP_BODY | GROUP_ARM),
                          (GROUP_STATIC, GROUP_QUERY | GROUP_ITEM | GROUP_ARM), texture_dir)
    if plants is not None:
        items.update(plants.bodies)  # the gripper holds a fruit as it holds an item
    cylinders = world.cylinder_names()
    names, cols, viss, poss, orns = [], [], [], [], []
    # walls after the furniture in front of them (drawing order, see above)
    for name, T, size, kind in sorted(world.static_boxes(), key=lambda b: b[3] == "wall"):
        if name in cylinders:
            r = size[0] / 2
            col = p.createCollisionShape(p.GEOM_CYLINDER, radius=r, height=size[2], physicsClientId=cid)
            vis = p.createVisualShape(p.GEOM_CYLINDER, radius=r, length=size[2], rgbaColor=_COLORS[kind], physicsClientId=cid)
        else:
            half = [s / 2 for s in size]
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid)
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=_COLORS[kind], physicsClientId=cid)
        names.append(name)
        cols.append(col)
        viss.append(vis)
        poss.append(T[:3, 3].tolist())
        orns.append(position_quat(T)[1])
    n = len(names)
    static = p.createMultiBody(
        baseMass=0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=-1, basePosition=[0, 0, 0],
        linkMasses=[0] * n, linkCollisionShapeIndices=cols, linkVisualShapeIndices=viss,
        linkPositions=poss, linkOrientations=orns, linkInertialFramePositions=[[0, 0, 0]] * n,
        linkInertialFrameOrientations=[[0, 0, 0, 1]] * n, linkParentIndices=[0] * n,
        linkJointTypes=[p.JOINT_FIXED] * n, linkJointAxis=[[0, 0, 1]] * n, physicsClientId=cid)
    for i in range(-1, n):
        p.changeDynamics(static, i, lateralFriction=0.8, physicsClientId=cid)
        p.setCollisionFilterGroupMask(static, i, GROUP_STATIC, GROUP_QUERY | GROUP_ITEM | GROUP_ARM, physicsClientId=cid)

    sx, sy = world.spec.room.size
    floor_col = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
    # the plane's own visual: without one TinyRenderer draws the collision plane, which
    # z-fought with the floor (grey/blue stripes near the camera)
    floor = p.createMultiBody(0, floor_col, _floor_visual(cid, sx, sy), [0, 0, 0], physicsClientId=cid)
    p.changeDynamics(floor, -1, lateralFriction=0.8, physicsClientId=cid)
    p.setCollisionFilterGroupMask(floor, -1, GROUP_STATIC, GROUP_QUERY | GROUP_ITEM | GROUP_ARM, physicsClientId=cid)
    return SceneHandles(static=static, static_names=tuple(names), floor=floor, items=items, panels=panels, plants=plants)
