"""Occupancy-grid utilities for navigation: world <-> cell conversion and inflation (map
files are read and written by :mod:`mmexec.drivers.maps`).

Conventions follow :class:`mmexec.drivers.interfaces.OccupancyGrid` (map_server): cell
``(row, col)`` covers ``[col*res, (col+1)*res) x [row*res, (row+1)*res)`` in the grid
frame, whose pose in ``map`` is ``grid.origin`` (row 0 at the origin, rows grow along the
grid's +y). Values: 0 free, 100 occupied, -1 unknown; anything >= ``occupied_threshold``
counts as an obstacle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from mmexec.drivers.interfaces import OccupancyGrid

__all__ = [
    "CostMap",
    "cell_to_world",
    "inflate",
    "world_to_cell",
]


def world_to_cell(grid: OccupancyGrid, x: float, y: float) -> tuple[int, int]:
    """The ``(row, col)`` of the cell containing map point ``(x, y)`` [m].

    The result may lie outside the grid; check with :meth:`CostMap.in_bounds`.
    """
    o = grid.origin
    dx, dy = x - o.x, y - o.y
    c, s = math.cos(o.theta), math.sin(o.theta)
    gx, gy = c * dx + s * dy, -s * dx + c * dy
    eps = 1e-9  # points on a cell boundary (up to rounding) belong to the upper cell
    return math.floor(gy / grid.resolution + eps), math.floor(gx / grid.resolution + eps)


def cell_to_world(grid: OccupancyGrid, row: int, col: int) -> tuple[float, float]:
    """Map coordinates ``(x, y)`` [m] of the centre of cell ``(row, col)``."""
    o = grid.origin
    gx, gy = (col + 0.5) * grid.resolution, (row + 0.5) * grid.resolution
    c, s = math.cos(o.theta), math.sin(o.theta)
    return o.x + c * gx - s * gy, o.y + s * gx + c * gy


# --------------------------------------------------------------------------- inflation


@dataclass(frozen=True)
class CostMap:
    """An occupancy grid inflated for a circular robot.

    ``blocked[row, col]`` is True where the robot's centre may not be: the cell is an
    obstacle (or unknown, when unknown counts as blocked) or an obstacle cell's centre lies
    within ``radius + margin`` [m] of this cell's centre. ``clearance[row, col]`` is the
    Euclidean distance [m] from the cell centre to the nearest obstacle cell centre
    (``inf`` in a grid without obstacles).
    """

    grid: OccupancyGrid
    blocked: np.ndarray
    clearance: np.ndarray
    radius: float
    margin: float

    @property
    def resolution(self) -> float:
        return self.grid.resolution

    def in_bounds(self, row: int, col: int) -> bool:
        return 0 <= row < self.grid.height and 0 <= col < self.grid.width

    def is_free(self, x: float, y: float) -> bool:
        """True when the robot centre may be at map point ``(x, y)`` [m]."""
        r, c = world_to_cell(self.grid, x, y)
        return self.in_bounds(r, c) and not bool(self.blocked[r, c])

    def nearest_free(self, x: float, y: float, max_distance: float) -> tuple[float, float] | None:
        """The free cell centre [m] nearest to map point ``(x, y)`` within ``max_distance``
        [m] (``(x, y)`` itself when it is free), or None. Like a global planner's goal
        tolerance: a named stop that an obstacle now covers is served from just beside it."""
        if self.is_free(x, y):
            return (x, y)
        res = self.resolution
        r0, c0 = world_to_cell(self.grid, x, y)
        k = math.ceil(max_distance / res)
        rows = np.arange(max(0, r0 - k), min(self.grid.height, r0 + k + 1))
        cols = np.arange(max(0, c0 - k), min(self.grid.width, c0 + k + 1))
        if rows.size == 0 or cols.size == 0:
            return None
        rr, cc = np.meshgrid(rows, cols, indexing="ij")
        o = self.grid.origin
        gx, gy = (cc + 0.5) * res, (rr + 0.5) * res  # as cell_to_world, for every cell at once
        cth, sth = math.cos(o.theta), math.sin(o.theta)
        wx, wy = o.x + cth * gx - sth * gy, o.y + sth * gx + cth * gy
        d = np.hypot(wx - x, wy - y)
        ok = ~self.blocked[rr, cc] & (d <= max_distance)
        if not ok.any():
            return None
        i = np.unravel_index(np.argmin(np.where(ok, d, np.inf)), d.shape)
        return (float(wx[i]), float(wy[i]))

    def clearance_at(self, x: float, y: float) -> float:
        """Distance [m] from ``(x, y)``'s cell to the nearest obstacle (0 outside the grid)."""
        r, c = world_to_cell(self.grid, x, y)
        return float(self.clearance[r, c]) if self.in_bounds(r, c) else 0.0


def inflate(
    grid: OccupancyGrid,
    radius: float,
    margin: float = 0.0,
    *,
    unknown_is_obstacle: bool = True,
    occupied_threshold: int = 50,
) -> CostMap:
    """Inflate ``grid`` by the robot ``radius`` plus a safety ``margin`` [m].

    Uses an exact Euclidean distance transform (``cv2.distanceTransform``, DIST_MASK_PRECISE)
    so the cost is O(cells), independent of the radius.
    """
    if radius < 0 or margin < 0:
        raise ValueError(f"inflate: radius and margin must be >= 0 (got {radius}, {margin})")
    d = np.asarray(grid.data)
    obstacle = d >= occupied_threshold
    if unknown_is_obstacle:
        obstacle |= d < 0
    if obstacle.any():
        free_mask = np.where(obstacle, 0, 255).astype(np.uint8)
        dist_cells = cv2.distanceTransform(free_mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        clearance = dist_cells.astype(np.float64) * grid.resolution
    else:
        clearance = np.full(d.shape, math.inf)
    # a small epsilon keeps cells exactly at radius (in cell units) blocked, like the brute force
    blocked = obstacle | (clearance <= radius + margin + 1e-9)
    return CostMap(grid=grid, blocked=blocked, clearance=clearance, radius=radius, margin=margin)
