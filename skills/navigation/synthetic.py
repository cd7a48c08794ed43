"""Synthetic planar lidar scans of an occupancy map plus circular obstacles, in pure numpy.

Used by the navigation tests and ``benchmarks/local_planner.py`` to drive the local
planner without a simulator (skills never import ``sim``): every beam is marched through
the grid at a third of a cell and intersected exactly with each circle; the nearest
return wins. Frames: the base ``pose`` in ``map``; the lidar at ``T_base_lidar``
(default: at the base centre, no yaw); beams CCW from ``-pi``.
"""

from __future__ import annotations

import math

import numpy as np

from mmexec.drivers.interfaces import LaserScan, OccupancyGrid, Pose2D
from mmexec.skills.navigation.costmap import points_to_cells

__all__ = ["cast_scan"]


def cast_scan(grid: OccupancyGrid, pose: Pose2D, centres: np.ndarray, radii: np.ndarray, *,
              n_beams: int = 400, range_min: float = 0.15, range_max: float = 8.0, noise: float = 0.0,
              rng: np.random.Generator | None = None, stamp: float = 0.0,
              T_base_lidar: np.ndarray | None = None, occupied_threshold: int = 50) -> LaserScan:
    """A 360 degree scan of ``grid`` (cells >= ``occupied_threshold`` reflect; off the map
    is open) and the circles ``centres`` (k, 2) / ``radii`` (k,) [m] from a base at
    ``pose``. ``noise``: range standard deviation [m] (needs ``rng``). Beams without a
    return within ``range_max`` read inf."""
    T_bl = np.eye(4) if T_base_lidar is None else np.asarray(T_base_lidar, dtype=float)
    T = pose.matrix() @ T_bl
    origin = T[:2, 3]
    inc = 2.0 * math.pi / n_beams
    angles = -math.pi + inc * np.arange(n_beams)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1) @ T[:2, :2].T
    # grid: march every beam at a third of a cell
    step = grid.resolution / 3.0
    ts = np.arange(1, int(range_max / step) + 1) * step
    pts = origin + ts[None, :, None] * dirs[:, None, :]
    rows, cols = points_to_cells(grid, pts)
    inside = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width)
    occ = np.zeros(rows.shape, dtype=bool)
    occ[inside] = np.asarray(grid.data)[rows[inside], cols[inside]] >= occupied_threshold
    first = np.argmax(occ, axis=1)
    r = np.where(occ.any(axis=1), ts[first], np.inf)
    # circles: nearest intersection ahead of the sensor
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    if c.shape[0]:
        m = origin - c                                         # (k, 2)
        b = dirs @ m.T                                         # (n, k)
        cc = np.einsum("ij,ij->i", m, m) - np.asarray(radii, dtype=float) ** 2
        disc = b * b - cc
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        t = np.where((disc >= 0) & (t > 0), t, np.inf)
        r = np.minimum(r, t.min(axis=1))
    if noise > 0:
        if rng is None:
            raise ValueError("cast_scan: noise > 0 needs an rng")
        r = r + rng.normal(0.0, noise, r.shape)
    r = np.where(r >= range_max, np.inf, r)  # below range_min: kept, a reading the scan marks invalid
    return LaserScan(angle_min=-math.pi, angle_increment=inc, ranges=r, range_min=range_min,
                     range_max=range_max, stamp=stamp, T_base_lidar=T_bl)
