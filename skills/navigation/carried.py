"""The item the arm holds while the base drives, and what it can sweep into.

A carried item is held out past the base's footprint (the LoCoBot's carry pose holds it
0.43 m ahead of the base centre, 0.25 m up; the UR platforms' 0.52 m ahead, 0.9 m up),
where neither the footprint radius of the costmap nor the safety filter's circles look.
Turning in place, or cutting round a corner, swings it through furniture the base itself
clears by centimetres, and the gripper loses it. This module gives the local drive
(:mod:`mmexec.skills.navigation.local_drive`) what it needs to keep it clear:

* :func:`held_item`: from the gripper (holding?), the arm's measured joints and the
  robot description's kinematics, the circles [m] in ``base_link`` that cover the item
  and the gripper behind it where they lie beyond the footprint, and the lowest height
  they reach;
* :func:`tall_layer`: the static map without the cells that only boxes of the robot's
  scene lower than that height cover (the depot basket's walls are passed over; shelves,
  the crate, walls are not); a map cell no scene box explains counts at every height;
* :class:`ItemGuard`: the gaps [m] between those circles and the tall obstacles or the
  lidar's marks (:meth:`RollingCostmap.clearance_over`) along an in-place turn or an arc,
  and whether a motion is clear: it is when no circle comes within ``margin`` of an
  obstacle, or, for a start already that close, when it does not get closer than at the
  start (so the base can always move away).

Frames: ``base_link`` (x forward, on the floor) for the item, ``map`` for poses and
obstacles; m, rad. Nothing here reads the simulator's ground truth.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D, Robot, SceneBox
from mmexec.skills.manipulation.kinematics import ArmKinematics
from mmexec.skills.navigation.costmap import RollingCostmap, StaticLayer

__all__ = ["ITEM_PAD", "HeldItem", "ItemGuard", "held_item", "layer_floor", "tall_layer"]

log = logging.getLogger(__name__)

#: [m] added to the held width's half diagonal for the item's circle (finger pads, sway)
ITEM_PAD = 0.02
#: [m] spacing of the circles from the grasp point back to the footprint
SPACING = 0.05
#: [m] the item hangs this far below its circle's radius under the grasp point at most
#: (a box held by its middle; the gripper's fingers)
HANG = 0.02


@dataclass(frozen=True)
class HeldItem:
    """What the arm holds out past the footprint: ``points`` (k, 2) [m] circle centres
    in ``base_link`` from the grasp point back towards the base centre, ``radius`` [m]
    of each, ``floor`` [m] the lowest height above the floor it reaches, ``reach`` [m]
    the farthest any of it lies from the base centre."""

    points: np.ndarray
    radius: float
    floor: float
    reach: float

    def in_map(self, poses: np.ndarray) -> np.ndarray:
        """The circles' centres in ``map`` (..., k, 2) [m] with the base at ``poses``
        (..., 3) ``(x, y, theta)``."""
        poses = np.asarray(poses, dtype=float)
        c, s = np.cos(poses[..., 2])[..., None], np.sin(poses[..., 2])[..., None]
        px, py = self.points[:, 0], self.points[:, 1]
        return np.stack([poses[..., 0, None] + c * px - s * py, poses[..., 1, None] + s * px + c * py], axis=-1)


_KINEMATICS: dict[str, ArmKinematics] = {}


def held_item(robot: Robot, base_radius: float) -> HeldItem | None:
    """The item the gripper holds now, with the arm where its joints are (see
    :class:`HeldItem`), or None: nothing held, no arm or description to place it, or all
    of it over the footprint of radius ``base_radius`` [m]."""
    arm, gripper, desc = robot.arm, robot.gripper, robot.description
    if arm is None or gripper is None or desc is None or desc.arm is None:
        return None
    g = gripper.state()
    if not g.holding:
        return None
    kin = _KINEMATICS.get(desc.name)
    if kin is None:
        kin = _KINEMATICS[desc.name] = ArmKinematics.from_description(desc)
    q = arm.state().positions
    if len(q) != kin.dof:
        return None
    tcp = kin.fk(q)[:3, 3] + np.asarray(desc.arm_mount, dtype=float)
    radius = math.sqrt(0.5) * max(float(g.width), 0.0) + ITEM_PAD
    d = math.hypot(tcp[0], tcp[1])
    if d + radius <= base_radius:
        return None
    # circles from the grasp point back towards the base centre, while any of them lies
    # beyond the footprint: the item, the fingers and the gripper's body behind it
    u = tcp[:2] / d
    steps = np.arange(0.0, max(d - base_radius + radius, 0.0) + 1e-9, SPACING)
    points = tcp[:2] - steps[:, None] * u
    return HeldItem(points=points, radius=radius, floor=max(float(tcp[2]) - radius - HANG, 0.0), reach=d + radius)


def layer_floor(floor: float) -> float:
    """``floor`` [m] rounded down to the centimetre: the height a tall layer is built for
    (:func:`tall_layer`; one layer serves every item within the same centimetre). Not
    coarser: the LoCoBot's carried item reaches down to 0.166 m over the depot basket's
    0.15 m walls, and a layer for 0.15 m kept the basket, so the item could never come
    over it."""
    return math.floor(floor * 100.0 + 1e-9) / 100.0


def _inside(box: SceneBox, xy: np.ndarray, pad: float) -> np.ndarray:
    """Which map points ``xy`` (n, 2) lie within ``box``'s footprint grown by ``pad`` [m]."""
    T = np.asarray(box.pose, dtype=float)
    d = xy - T[:2, 3]
    lx = d @ T[:2, 0] / max(np.hypot(*T[:2, 0]), 1e-12)
    ly = d @ T[:2, 1] / max(np.hypot(*T[:2, 1]), 1e-12)
    return (np.abs(lx) <= box.size[0] / 2 + pad) & (np.abs(ly) <= box.size[1] / 2 + pad)


def tall_layer(grid: OccupancyGrid, scene: Sequence[SceneBox], floor: float, *,
               occupied_threshold: int = 50, unknown_is_obstacle: bool = True) -> StaticLayer:
    """The static layer of the obstacles that reach height ``floor`` [m]: ``grid``'s
    occupied cells except those whose centre only boxes of ``scene`` lying wholly below
    ``floor`` cover (their footprint grown by half a cell, as a map is drawn from them);
    a cell that a box reaching ``floor`` covers too, or that no box explains, stays."""
    data = np.array(grid.data, copy=True)
    low = [b for b in scene if float(np.asarray(b.pose)[2, 3]) + b.size[2] / 2 < floor]
    if low:
        rows, cols = np.nonzero(data >= occupied_threshold)
        o, res = grid.origin, grid.resolution
        gx, gy = (cols + 0.5) * res, (rows + 0.5) * res
        c, s = math.cos(o.theta), math.sin(o.theta)
        xy = np.stack([o.x + c * gx - s * gy, o.y + s * gx + c * gy], axis=1)
        pad = 0.5 * res
        under = np.zeros(len(xy), dtype=bool)
        for b in low:
            under |= _inside(b, xy, pad)
        for b in scene:
            if b not in low:
                under &= ~_inside(b, xy, pad)
        data[rows[under], cols[under]] = 0
    return StaticLayer(OccupancyGrid(data=data, resolution=grid.resolution, origin=grid.origin),
                       occupied_threshold=occupied_threshold, unknown_is_obstacle=unknown_is_obstacle)


class ItemGuard:
    """Keeps a held item clear of what reaches its height (see the module docstring):
    ``item`` in ``base_link``, the rolling ``costmap`` (for the lidar's marks), ``static``
    the layer of tall obstacles (:func:`tall_layer`), ``margin`` [m] kept beyond the
    item's circles."""

    #: [rad] angular spacing of the poses checked along a turn
    TURN_STEP = 0.05

    def __init__(self, item: HeldItem, costmap: RollingCostmap, static: StaticLayer, margin: float = 0.02) -> None:
        self.item, self.costmap, self.static, self.margin = item, costmap, static, margin

    def gaps(self, poses: np.ndarray) -> np.ndarray:
        """Smallest gap [m] between the item's circles and a tall obstacle or mark, with
        the base at each of ``poses`` (..., 3); negative: overlapping."""
        pts = self.item.in_map(poses)
        return (self.costmap.clearance_over(self.static, pts) - self.item.radius).min(axis=-1)

    def _clear(self, pose: Pose2D, poses: np.ndarray) -> bool:
        now = float(self.gaps(np.array([pose.x, pose.y, pose.theta]))[()])
        g = self.gaps(poses)
        return not bool(np.any((g < self.margin) & (g < now - 1e-3)))

    def turn_clear(self, pose: Pose2D, angle: float) -> bool:
        """Whether an in-place turn by ``angle`` [rad] (signed, may exceed pi) from
        ``pose`` keeps the item clear."""
        n = max(1, math.ceil(abs(angle) / self.TURN_STEP))
        th = pose.theta + np.linspace(0.0, angle, n + 1)[1:]
        poses = np.stack([np.full(n, pose.x), np.full(n, pose.y), th], axis=1)
        return self._clear(pose, poses)

    def arc_clear(self, pose: Pose2D, v: float, w: float, horizon: float, step: float = 0.05) -> bool:
        """Whether holding ``(v, w)`` [m/s, rad/s] for ``horizon`` [s] from ``pose`` keeps
        the item clear (the unicycle's exact arc, checked every ``step`` seconds)."""
        t = np.arange(1, max(1, math.ceil(horizon / step)) + 1) * step
        th = pose.theta + w * t
        if abs(w) > 1e-6:
            x = pose.x + v / w * (np.sin(th) - math.sin(pose.theta))
            y = pose.y - v / w * (np.cos(th) - math.cos(pose.theta))
        else:
            x, y = pose.x + v * t * math.cos(pose.theta), pose.y + v * t * math.sin(pose.theta)
        return self._clear(pose, np.stack([x, y, th], axis=1))
