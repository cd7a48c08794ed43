"""A synthetic room for the localisation tests: walls and round reflector posts as exact
geometry, its occupancy grid, and an exact ray caster (the lidar the filter sees)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D

#: room 6 x 4 m, wall segments (x0, y0, x1, y1) [m], plus a table-like box
WALLS = np.array(
    [
        [0.0, 0.0, 6.0, 0.0],
        [6.0, 0.0, 6.0, 4.0],
        [6.0, 4.0, 0.0, 4.0],
        [0.0, 4.0, 0.0, 0.0],
        [2.0, 1.5, 3.0, 1.5],
        [3.0, 1.5, 3.0, 2.2],
        [3.0, 2.2, 2.0, 2.2],
        [2.0, 2.2, 2.0, 1.5],
    ]
)
#: reflector posts (x, y) [m], radius POST_R
POSTS = np.array([[0.3, 0.3], [5.7, 0.4], [5.6, 3.7], [0.4, 3.6], [3.0, 3.7], [3.1, 0.3]])
POST_R = 0.04
RES = 0.05


def grid() -> OccupancyGrid:
    """The room's occupancy grid (walls and posts occupied), origin (-0.5, -0.5)."""
    w, h = int(7.0 / RES), int(5.0 / RES)
    data = np.zeros((h, w), dtype=np.int8)
    ox, oy = -0.5, -0.5
    xs = ox + (np.arange(w) + 0.5) * RES
    ys = oy + (np.arange(h) + 0.5) * RES
    gx, gy = np.meshgrid(xs, ys)
    for x0, y0, x1, y1 in WALLS:
        d = _seg_dist(gx, gy, x0, y0, x1, y1)
        data[d <= RES * 0.75] = 100
    for px, py in POSTS:
        data[np.hypot(gx - px, gy - py) <= POST_R + RES * 0.5] = 100
    data[(gx < 0) | (gx > 6) | (gy < 0) | (gy > 4)] = 100
    return OccupancyGrid(data=data, resolution=RES, origin=Pose2D(ox, oy, 0.0))


def _seg_dist(px, py, x0, y0, x1, y1):
    vx, vy = x1 - x0, y1 - y0
    t = np.clip(((px - x0) * vx + (py - y0) * vy) / (vx * vx + vy * vy), 0.0, 1.0)
    return np.hypot(px - (x0 + t * vx), py - (y0 + t * vy))


@dataclass
class Lidar:
    beams: int = 400
    range_max: float = 12.0
    range_min: float = 0.15
    sigma: float = 0.005

    @property
    def angles(self) -> np.ndarray:
        return -math.pi + np.arange(self.beams) * (2 * math.pi / self.beams)

    def scan(self, pose: np.ndarray, rng: np.random.Generator, posts: np.ndarray = POSTS):
        """(ranges, intensities) from sensor pose (x, y, theta) in the room."""
        a = self.angles + pose[2]
        dx, dy = np.cos(a), np.sin(a)
        best = np.full(len(a), np.inf)
        inten = np.zeros(len(a))
        for x0, y0, x1, y1 in WALLS:
            ex, ey = x1 - x0, y1 - y0
            den = dx * ey - dy * ex
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((x0 - pose[0]) * ey - (y0 - pose[1]) * ex) / den
                u = ((x0 - pose[0]) * dy - (y0 - pose[1]) * dx) / den
            hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
            closer = hit & (t < best)
            best[closer] = t[closer]
            inten[closer] = 0.2
        for px, py in posts:
            fx, fy = pose[0] - px, pose[1] - py
            b = fx * dx + fy * dy
            c = fx * fx + fy * fy - POST_R * POST_R
            disc = b * b - c
            t = -b - np.sqrt(np.maximum(disc, 0))
            closer = (disc >= 0) & (t > 0) & (t < best)
            best[closer] = t[closer]
            inten[closer] = 1.0
        r = best + rng.normal(0.0, self.sigma, len(best))
        r[(best > self.range_max) | (best < self.range_min)] = np.inf
        inten[~np.isfinite(r)] = 0.0
        return r, inten
