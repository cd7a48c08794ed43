"""A rolling local costmap over the static map, marked and cleared by the lidar.

Layers, all on the static map's cells (same resolution and orientation, so a window cell
*is* a map cell and nothing is resampled):

- **static**: the map's occupied cells (and unknown ones, when they count as obstacles),
  with the exact Euclidean distance to them precomputed once for the whole map
  (:func:`mmexec.skills.navigation.grid.inflate` with radius 0);
- **marks**: cells holding lidar hits that are *not* the static map, in a square window of
  ``size`` metres that follows the robot (marks that leave the window are forgotten, as
  in a ROS rolling window).

Per scan (:meth:`RollingCostmap.update`):

1. the window is re-centred on the sensor; marks in the overlap are kept;
2. **clearing**: a marked cell is cleared when the beam pointing at its centre saw free
   space beyond it (the beam's range exceeds the cell centre's distance by half a cell).
   This is ray tracing evaluated where it matters: only marked cells can be cleared, so
   the cost is one bearing per marked cell instead of one sample per beam per cell;
3. **marking**: a hit within ``mark_range`` whose distance to the nearest static obstacle
   cell is more than ``static_tolerance`` (localisation error, cell quantisation) is a
   new obstacle and marks its cell. Hits on the static map are never marks;
4. the distance to the nearest mark is recomputed over the window (``cv2.distanceTransform``,
   exact Euclidean; skipped without marks) and combined by the minimum with the static
   map's distance field, computed once: exact near the window's edge too.

**Pinned marks** (:meth:`RollingCostmap.pin`): cells a contact sensor found (a bumper,
a cliff sensor) that the planar lidar may not see (a box below the scan plane, a drop).
The lidar's clearing never removes them; they roll with the window and leave it like
any mark, or go with :meth:`RollingCostmap.unpin`.

:meth:`RollingCostmap.clearance_at` answers for any map points: the distance from the
point to the nearest obstacle cell's edge, i.e. the centre-to-centre distance field
interpolated bilinearly at the point, less half a cell: within half a cell (2.5 cm at 5
cm cells) either way of the exact distance to the obstacle squares (measured on random
maps; the worst case is a lone marked cell, a cone the interpolation rounds off), where
a cell-centre lookup is off by up to 1.2 cells; the window's field inside it, the static map's outside
it (0 off the map). The robot radius and the margin the global planner inflates by cover
the error. :meth:`RollingCostmap.merged_grid`
is the static map with the marks written in, for a global re-plan when the path is
blocked. Frames: ``map``; distances in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from mmexec.drivers.interfaces import OccupancyGrid
from mmexec.skills.navigation.checks import checked, non_negative, positive
from mmexec.skills.navigation.grid import inflate
from mmexec.skills.navigation.obstacles import ScanPoints

__all__ = ["CostmapConfig", "RollingCostmap", "StaticLayer", "points_to_cells"]


@dataclass(frozen=True)
class CostmapConfig:
    """``size`` [m] side of the square window; ``static_tolerance`` [m]; ``mark_range``
    [m] (farther hits are not marked); ``clear_range`` [m] (how far a beam with no
    return clears); ``occupied_threshold`` (0-100) and ``unknown_is_obstacle`` for the
    static map, as in :func:`mmexec.skills.navigation.grid.inflate`."""

    size: float = 6.0
    static_tolerance: float = 0.10
    mark_range: float = 4.0
    clear_range: float = 4.0
    occupied_threshold: int = 50
    unknown_is_obstacle: bool = True

    def validate(self) -> list[str]:
        errs = positive(self, "size", "mark_range", "clear_range") + non_negative(self, "static_tolerance")
        if not 0 < self.occupied_threshold <= 100:
            errs.append(f"occupied_threshold: must be in (0, 100], got {self.occupied_threshold}")
        return errs


def _cell_coords(grid: OccupancyGrid, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Continuous ``(row, col)`` coordinates [cells] of map points ``xy`` (..., 2) [m]: cell
    ``(r, c)`` spans ``[r, r + 1) x [c, c + 1)``, its centre at ``(r + 0.5, c + 0.5)``."""
    o = grid.origin
    dx, dy = xy[..., 0] - o.x, xy[..., 1] - o.y
    c, s = math.cos(o.theta), math.sin(o.theta)
    inv = 1.0 / grid.resolution
    return (-s * dx + c * dy) * inv, (c * dx + s * dy) * inv


def points_to_cells(grid: OccupancyGrid, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, cols)`` (int64) of the cells containing the map points ``xy`` (..., 2) [m];
    the vectorised :func:`mmexec.skills.navigation.grid.world_to_cell` (same boundary
    rule). Results may lie outside the grid."""
    fr, fc = _cell_coords(grid, xy)
    return np.floor(fr + 1e-9).astype(np.int64), np.floor(fc + 1e-9).astype(np.int64)


def _bilinear(field: np.ndarray, fr: np.ndarray, fc: np.ndarray) -> np.ndarray:
    """``field`` (h, w) of values at cell centres, interpolated bilinearly at continuous
    cell coordinates (held constant beyond the outermost centres)."""
    h, w = field.shape
    y = np.clip(fr - 0.5, 0.0, h - 1.0)
    x = np.clip(fc - 0.5, 0.0, w - 1.0)
    i = np.minimum(y.astype(np.int64), max(h - 2, 0))
    j = np.minimum(x.astype(np.int64), max(w - 2, 0))
    ty, tx = y - i, x - j
    i1, j1 = np.minimum(i + 1, h - 1), np.minimum(j + 1, w - 1)
    top = field[i, j] * (1.0 - tx) + field[i, j1] * tx
    bottom = field[i1, j] * (1.0 - tx) + field[i1, j1] * tx
    return top * (1.0 - ty) + bottom * ty


#: stands for "no obstacle at all" in the distance fields (finite, so interpolation works)
_FAR = 1e6


class StaticLayer:
    """The static map's obstacles and the distance [m] from every cell centre to the
    nearest one's centre: ``clearance`` (0 on an obstacle cell, ``inf`` in a map without
    obstacles) and ``field`` (the same, with a large finite number for inf)."""

    def __init__(self, grid: OccupancyGrid, *, occupied_threshold: int = 50, unknown_is_obstacle: bool = True) -> None:
        self.grid = grid
        cm = inflate(grid, 0.0, 0.0, unknown_is_obstacle=unknown_is_obstacle, occupied_threshold=occupied_threshold)
        self.clearance = cm.clearance
        self.obstacle = cm.clearance <= 0.0
        self.field = np.minimum(cm.clearance, _FAR)

    def clearance_at(self, xy: np.ndarray) -> np.ndarray:
        """Distance [m] from each map point's *cell centre* to the nearest static obstacle
        cell's centre (0 off the map): the rule for telling map hits from new ones."""
        rows, cols = points_to_cells(self.grid, xy)
        inside = (rows >= 0) & (rows < self.grid.height) & (cols >= 0) & (cols < self.grid.width)
        out = np.zeros(rows.shape)
        out[inside] = self.clearance[rows[inside], cols[inside]]
        return out

    def edge_distance(self, xy: np.ndarray) -> np.ndarray:
        """Distance [m] from each map point to the nearest static obstacle cell's edge
        (interpolated, see the module docstring; 0 off the map)."""
        fr, fc = _cell_coords(self.grid, xy)
        inside = (fr >= 0) & (fr < self.grid.height) & (fc >= 0) & (fc < self.grid.width)
        d = _bilinear(self.field, fr, fc) - 0.5 * self.grid.resolution
        return np.where(inside, np.maximum(d, 0.0), 0.0)


class RollingCostmap:
    """Rolling window of lidar marks over a static map (see the module docstring).

    ``marks`` (n, n) bool and ``clearance`` (n, n) [m], the distance from each window
    cell's centre to the nearest obstacle cell's centre, index ``[i, j]`` = map cell
    ``(r0 + i, c0 + j)``."""

    def __init__(self, static: OccupancyGrid, config: CostmapConfig | None = None) -> None:
        self.config = checked(config or CostmapConfig())
        self.static = StaticLayer(static, occupied_threshold=self.config.occupied_threshold,
                                  unknown_is_obstacle=self.config.unknown_is_obstacle)
        self.grid = static
        self.n = max(3, math.ceil(self.config.size / static.resolution))
        self.r0 = self.c0 = 0
        self.marks = np.zeros((self.n, self.n), dtype=bool)
        self.pinned = np.zeros((self.n, self.n), dtype=bool)
        self._static_win = np.zeros((self.n, self.n))
        self.clearance = np.zeros((self.n, self.n))
        self._marks_field: np.ndarray | None = None  # distance [m] to the nearest mark (None: no marks)
        self._placed = False

    # ------------------------------------------------------------------ geometry
    @property
    def resolution(self) -> float:
        return self.grid.resolution

    def window_cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Window ``(i, j)`` of the map points ``xy`` (..., 2) and whether each lies inside."""
        rows, cols = points_to_cells(self.grid, xy)
        i, j = rows - self.r0, cols - self.c0
        inside = (i >= 0) & (i < self.n) & (j >= 0) & (j < self.n)
        return i, j, inside

    def cell_centres(self) -> np.ndarray:
        """Map coordinates [m] of the window's cell centres, shape (n, n, 2), [i, j] = (x, y)."""
        ii, jj = np.indices((self.n, self.n))
        return self._centres_of(ii.ravel(), jj.ravel()).reshape(self.n, self.n, 2)

    def recentre(self, x: float, y: float) -> None:
        """Move the window so that map point ``(x, y)`` [m] is in its middle cell; marks
        in the overlap of the old and new windows are kept."""
        if self._move(x, y):
            self._refresh()

    def _move(self, x: float, y: float) -> bool:
        """:meth:`recentre` without the distance update; True when the window moved."""
        (row,), (col,) = points_to_cells(self.grid, np.array([[x, y]]))
        r0, c0 = int(row) - self.n // 2, int(col) - self.n // 2
        if self._placed and (r0, c0) == (self.r0, self.c0):
            return False
        marks, pinned = np.zeros_like(self.marks), np.zeros_like(self.pinned)
        if self._placed:
            dr, dc = r0 - self.r0, c0 - self.c0
            src_r = slice(max(0, dr), min(self.n, self.n + dr))
            src_c = slice(max(0, dc), min(self.n, self.n + dc))
            dst_r = slice(max(0, -dr), min(self.n, self.n - dr))
            dst_c = slice(max(0, -dc), min(self.n, self.n - dc))
            if src_r.start < src_r.stop and src_c.start < src_c.stop:
                marks[dst_r, dst_c] = self.marks[src_r, src_c]
                pinned[dst_r, dst_c] = self.pinned[src_r, src_c]
        self.marks, self.pinned = marks, pinned
        self.r0, self.c0 = r0, c0
        self._placed = True
        # the static distance field over the window (0 off the map: no driving there)
        h, w = self.grid.height, self.grid.width
        win = np.zeros((self.n, self.n))
        rs, re = max(0, r0), min(h, r0 + self.n)
        cs, ce = max(0, c0), min(w, c0 + self.n)
        if rs < re and cs < ce:
            win[rs - r0 : re - r0, cs - c0 : ce - c0] = self.static.field[rs:re, cs:ce]
        self._static_win = win
        return True

    # ------------------------------------------------------------------ update
    def update(self, points: ScanPoints) -> np.ndarray:
        """Clear and mark with one scan in ``map``; returns the ``new`` mask (n_beams,):
        hits within ``mark_range`` that are not the static map (the obstacle points)."""
        cfg = self.config
        ox, oy = float(points.origin[0]), float(points.origin[1])
        self._move(ox, oy)
        res = self.resolution
        # clearing: marked cells whose beam saw free space past them
        mi, mj = np.nonzero(self.marks)
        if mi.size:
            centres = self._centres_of(mi, mj)
            d = np.hypot(centres[:, 0] - ox, centres[:, 1] - oy)
            beam, ok = points.beam_towards(centres)
            seen_free = ok & (np.minimum(points.free[beam], cfg.clear_range) > d + 0.5 * res) & (d > res)
            seen_free &= ~self.pinned[mi, mj]
            self.marks[mi[seen_free], mj[seen_free]] = False
        # marking: hits that are not the static map
        xy = np.where(points.hit[:, None], points.xy, 0.0)
        near = points.hit & (points.free <= cfg.mark_range)
        new = near & (self.static.clearance_at(xy) > cfg.static_tolerance)
        i, j, inside = self.window_cells(xy[new])
        self.marks[i[inside], j[inside]] = True
        self._refresh()
        return new

    def _centres_of(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Map coordinates [m] (m, 2) of window cells ``(i, j)``."""
        o, res = self.grid.origin, self.resolution
        gx, gy = (self.c0 + j + 0.5) * res, (self.r0 + i + 0.5) * res
        c, s = math.cos(o.theta), math.sin(o.theta)
        return np.stack([o.x + c * gx - s * gy, o.y + s * gx + c * gy], axis=1)

    def _refresh(self) -> None:
        """``clearance`` = min(static field, distance to the marks): the distance to the
        union of both (the static part is exact up to obstacles beyond the window too)."""
        if self.marks.any():
            free = np.where(self.marks, 0, 255).astype(np.uint8)
            marks = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
            self._marks_field = marks.astype(np.float64) * self.resolution
            self.clearance = np.minimum(self._static_win, self._marks_field)
        else:
            self._marks_field = None
            self.clearance = self._static_win.copy()

    def clear_marks(self) -> None:
        """Forget every mark, pinned ones too (e.g. after a recovery re-localised the robot)."""
        self.marks[:] = False
        self.pinned[:] = False
        self._refresh()

    def clear_disc(self, centre: tuple[float, float], radius: float) -> int:
        """Forget the marks (not the pinned ones) whose cell centre lies within ``radius``
        [m] of ``centre`` (map, [m]): where the base stands nothing else can (a mark
        there is the robot's own body, or an old one it has since driven onto). Returns
        how many were cleared."""
        mi, mj = np.nonzero(self.marks & ~self.pinned)
        if radius <= 0.0 or not mi.size:
            return 0
        c = self._centres_of(mi, mj)
        gone = np.hypot(c[:, 0] - centre[0], c[:, 1] - centre[1]) <= radius
        if gone.any():
            self.marks[mi[gone], mj[gone]] = False
            self._refresh()
        return int(gone.sum())

    def pin(self, xy: np.ndarray) -> int:
        """Mark the cells holding the map points ``xy`` (m, 2) [m] as obstacles the lidar's
        clearing never removes (what a bumper or cliff sensor found); returns how many
        points fell inside the window (the others are dropped)."""
        i, j, inside = self.window_cells(np.asarray(xy, dtype=float).reshape(-1, 2))
        self.pinned[i[inside], j[inside]] = True
        self.marks |= self.pinned
        self._refresh()
        return int(inside.sum())

    def unpin(self) -> None:
        """Let the lidar clear the pinned cells again (they stay marked until it does)."""
        self.pinned[:] = False

    # ------------------------------------------------------------------ queries
    def clearance_at(self, xy: np.ndarray) -> np.ndarray:
        """Distance [m] from each map point (xy (..., 2)) to the nearest obstacle cell's
        edge, static or marked (see the module docstring): the window's field inside it,
        the static map's outside it."""
        fr, fc = _cell_coords(self.grid, xy)
        fr, fc = fr - self.r0, fc - self.c0
        inside = (fr >= 0) & (fr < self.n) & (fc >= 0) & (fc < self.n)
        out = np.maximum(_bilinear(self.clearance, fr, fc) - 0.5 * self.resolution, 0.0)
        if not inside.all():
            out[~inside] = self.static.edge_distance(xy[~inside])
        return out

    def clearance_over(self, static: StaticLayer, xy: np.ndarray) -> np.ndarray:
        """As :meth:`clearance_at`, with another static layer in place of the map's own
        (the same grid with fewer obstacles, e.g. only those that reach a held item's
        height: :func:`mmexec.skills.navigation.carried.tall_layer`): the distance [m]
        from each map point (xy (..., 2)) to the nearest obstacle cell's edge of
        ``static`` or of the marks (what the lidar saw is taken to reach every height)."""
        out = static.edge_distance(xy)
        if self._marks_field is None:
            return out
        fr, fc = _cell_coords(self.grid, xy)
        fr, fc = fr - self.r0, fc - self.c0
        inside = (fr >= 0) & (fr < self.n) & (fc >= 0) & (fc < self.n)
        marks = np.maximum(_bilinear(self._marks_field, fr, fc) - 0.5 * self.resolution, 0.0)
        return np.where(inside, np.minimum(out, marks), out)

    def _inside(self, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Window mask (n, n): cells whose centre lies inside any disc ``centres`` (k, 2),
        ``radii`` (k,) [m]."""
        cells = self.cell_centres()
        centres = np.asarray(centres, dtype=float).reshape(-1, 2)
        d2 = ((cells[None, ..., 0] - centres[:, 0, None, None]) ** 2
              + (cells[None, ..., 1] - centres[:, 1, None, None]) ** 2)
        return (d2 <= (np.asarray(radii, dtype=float)[:, None, None]) ** 2).any(axis=0)

    def merged_grid(self, centres: np.ndarray | None = None, radii: np.ndarray | None = None, *,
                    ignore: tuple[np.ndarray, np.ndarray] | None = None) -> OccupancyGrid:
        """The static map with the current marks written in as occupied (100) cells, and
        the discs ``centres`` (k, 2) / ``radii`` (k,) [m] too when given (cells whose
        centre lies inside), for a global re-plan: inflate it by the robot radius, then
        :func:`mmexec.skills.navigation.astar.plan_path`. ``ignore`` (centres (m, 2),
        radii (m,) [m]): discs whose marks are left out (the lidar's hits on people, who
        move on); pinned marks are always written in."""
        data = np.array(self.grid.data, copy=True)
        marks = self.marks
        if ignore is not None and len(ignore[1]):
            marks = marks & (~self._inside(*ignore) | self.pinned)
        i, j = np.nonzero(marks)
        r, c = i + self.r0, j + self.c0
        if centres is not None and radii is not None and len(radii):
            di, dj = np.nonzero(self._inside(centres, radii))
            r, c = np.concatenate([r, di + self.r0]), np.concatenate([c, dj + self.c0])
        ok = (r >= 0) & (r < self.grid.height) & (c >= 0) & (c < self.grid.width)
        data[r[ok], c[ok]] = 100
        return OccupancyGrid(data=data, resolution=self.grid.resolution, origin=self.grid.origin)
