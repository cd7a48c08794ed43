"""A conservative 2D clearance map of a world's static geometry, for the kinematic base.

The base is moved kinematically every physics substep and must not enter static geometry.
The exact test (``getClosestPoints`` of the base body against the static body) costs tens
of microseconds and needs the body placed at the new pose first; in open floor it is
wasted. :class:`ClearanceMap` answers "is a disk of radius r at (x, y) certainly clear?"
with one array lookup, and only when it cannot say so does the base run the exact test.

Conservative by construction: a cell is marked occupied when its centre lies within half a
cell diagonal of a static footprint (box footprints expanded by that much; cylinders use
their bounding box), so every obstacle point lies in a marked cell; the distance from a
query point to the nearest marked cell centre, minus one cell diagonal, is then a lower
bound of its distance to the obstacles.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from mmexec.sim.world import World, footprint_mask, room_grid

__all__ = ["ClearanceMap"]


class ClearanceMap:
    """Lower bounds of the horizontal distance [m] from a point in ``map`` to the static
    geometry whose height range overlaps ``[z_min, z_max]`` [m]."""

    def __init__(self, dist: np.ndarray, resolution: float, origin: tuple[float, float]) -> None:
        self._d = dist
        self.resolution = resolution
        self.origin = origin
        self._slack = resolution * math.sqrt(2.0)

    @classmethod
    def from_world(cls, world: World, z_min: float, z_max: float, resolution: float = 0.02) -> ClearanceMap:
        """Build the map over the room and its walls at ``resolution`` [m/cell]."""
        if resolution <= 0:
            raise ValueError(f"resolution must be > 0, got {resolution}")
        r = world.spec.room
        t = r.wall_thickness + 0.05
        X, Y = room_grid(r, t, resolution)
        free = np.ones(X.shape, dtype=np.uint8)
        grow = resolution * math.sqrt(2.0) / 2
        for _, T, size, _kind in world.static_boxes():
            lo, hi = T[2, 3] - size[2] / 2, T[2, 3] + size[2] / 2
            if hi < z_min or lo > z_max:
                continue
            free[footprint_mask(X, Y, T, size, grow)] = 0
        dist = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(np.float32) * resolution
        return cls(dist, resolution, (-t, -t))

    def lower_bound(self, x: float, y: float) -> float:
        """A distance [m] that the static geometry is at least away from (x, y); 0 outside
        the map."""
        col = int((x - self.origin[0]) / self.resolution)
        row = int((y - self.origin[1]) / self.resolution)
        if not (0 <= row < self._d.shape[0] and 0 <= col < self._d.shape[1]):
            return 0.0
        return max(0.0, float(self._d[row, col]) - self._slack)

    def clear(self, x: float, y: float, radius: float) -> bool:
        """True when a disk of ``radius`` [m] centred at (x, y) certainly touches nothing."""
        return self.lower_bound(x, y) > radius
