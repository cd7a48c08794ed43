"""Occupancy-grid utilities: world <-> cell conversion, map_server map loading, inflation.

Conventions follow :class:`mmexec.drivers.interfaces.OccupancyGrid` (map_server): cell
``(row, col)`` covers ``[col*res, (col+1)*res) x [row*res, (row+1)*res)`` in the grid
frame, whose pose in ``map`` is ``grid.origin`` (row 0 at the origin, rows grow along the
grid's +y). Values: 0 free, 100 occupied, -1 unknown; anything >= ``occupied_threshold``
counts as an obstacle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from mmexec.config.yamlload import InputError, Mark, Problems, bind, load_yaml, mark_of
from mmexec.drivers.interfaces import OccupancyGrid, Pose2D

__all__ = [
    "CostMap",
    "MapFile",
    "MapReflector",
    "cell_to_world",
    "inflate",
    "load_map",
    "read_pgm",
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


# --------------------------------------------------------------------------- map files


@dataclass(frozen=True)
class MapReflector:
    """A laser-reflector post of the map (an mmexec key of the map YAML, which map_server
    ignores): ``name``, centre ``position`` ``[x, y]`` in ``map`` [m], post ``radius`` [m].
    Read with :func:`mmexec.skills.localization.landmarks.load_reflectors`."""

    name: str
    position: tuple[float, float]
    radius: float

    def validate(self) -> list[str]:
        return [] if self.radius > 0 else [f"reflector {self.name!r}: radius must be > 0 m, got {self.radius}"]


@dataclass(frozen=True)
class MapFile:
    """A map_server map description (the YAML next to the PGM).

    ``origin`` is ``[x, y, yaw]`` of the lower-left pixel's corner in ``map`` [m, m, rad];
    ``resolution`` [m/pixel]; thresholds are occupancy probabilities in [0, 1];
    ``reflectors``: the laser-reflector landmarks, if the map has any.
    """

    image: str
    resolution: float
    origin: tuple[float, float, float]
    negate: int = 0
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    mode: Literal["trinary", "scale"] = "trinary"
    reflectors: tuple[MapReflector, ...] = ()

    def validate(self) -> list[str]:
        errs = []
        if not self.resolution > 0:
            errs.append(f"resolution: must be > 0 m/pixel, got {self.resolution}")
        if self.negate not in (0, 1):
            errs.append(f"negate: expected 0 or 1, got {self.negate}")
        if not 0.0 <= self.free_thresh < self.occupied_thresh <= 1.0:
            errs.append(
                f"thresholds: need 0 <= free_thresh < occupied_thresh <= 1, got "
                f"{self.free_thresh} and {self.occupied_thresh}"
            )
        return errs


def read_pgm(path: str | Path) -> np.ndarray:
    """Read a binary (P5) or ASCII (P2) 8-bit PGM file into an HxW uint8 array (row 0 at
    the top of the picture). Raises :class:`InputError` naming the file on bad content."""
    name = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise InputError.at(Mark(name, 1, 1), f"cannot read map image: {e.strerror or e}") from None
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:
        while pos < len(data) and data[pos : pos + 1].isspace():
            pos += 1
        if pos < len(data) and data[pos : pos + 1] == b"#":
            while pos < len(data) and data[pos : pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < len(data) and not data[pos : pos + 1].isspace() and data[pos : pos + 1] != b"#":
            pos += 1
        if start == pos:
            raise InputError.at(Mark(name, 1, 1), "truncated PGM header (expected magic, width, height, maxval)")
        tokens.append(data[start:pos])
    magic = tokens[0]
    if magic not in (b"P5", b"P2"):
        raise InputError.at(Mark(name, 1, 1), f"not a PGM image (magic {magic[:8]!r}, expected P5 or P2)")
    try:
        w, h, maxval = (int(t) for t in tokens[1:4])
    except ValueError:
        raise InputError.at(Mark(name, 1, 1), "bad PGM header: width, height and maxval must be integers") from None
    if w <= 0 or h <= 0 or not 0 < maxval < 256:
        raise InputError.at(Mark(name, 1, 1), f"unsupported PGM: {w}x{h}, maxval {maxval} (need 8-bit)")
    if magic == b"P5":
        body = data[pos + 1 : pos + 1 + w * h]
        if len(body) != w * h:
            raise InputError.at(Mark(name, 1, 1), f"PGM data truncated: {len(body)} of {w * h} bytes")
        img = np.frombuffer(body, dtype=np.uint8).reshape(h, w)
    else:
        try:
            vals = [int(t) for t in data[pos:].split()]
        except ValueError:
            raise InputError.at(Mark(name, 1, 1), "bad ASCII PGM pixel value") from None
        if len(vals) < w * h:
            raise InputError.at(Mark(name, 1, 1), f"PGM data truncated: {len(vals)} of {w * h} values")
        img = np.asarray(vals[: w * h], dtype=np.int64).clip(0, 255).astype(np.uint8).reshape(h, w)
    if maxval != 255:
        img = (img.astype(np.float64) * (255.0 / maxval)).round().clip(0, 255).astype(np.uint8)
    return img


def load_map(yaml_path: str | Path) -> OccupancyGrid:
    """Load a map_server-style map (YAML + PGM) as an :class:`OccupancyGrid` in ``map``.

    Errors (missing keys, wrong types, unreadable image) raise :class:`InputError` with
    ``FILE:LINE:COL: message``. The image is flipped so that grid row 0 is the bottom
    row of the picture (map_server convention).
    """
    raw = load_yaml(yaml_path)
    name = str(yaml_path)
    problems = Problems()
    mf = bind(MapFile, raw, mark_of(raw, Mark(name, 1, 1)), "", problems)
    problems.raise_if_any()
    assert isinstance(mf, MapFile)
    img_path = Path(mf.image)
    if not img_path.is_absolute():
        img_path = Path(yaml_path).parent / img_path
    if not img_path.exists():
        vm = raw.value_mark("image") if hasattr(raw, "value_mark") else Mark(name, 1, 1)
        raise InputError.at(vm, f"image: no such file {str(img_path)!r}")
    img = read_pgm(img_path)
    pix = img.astype(np.float64)
    p = pix / 255.0 if mf.negate else (255.0 - pix) / 255.0
    data = np.full(img.shape, -1, dtype=np.int8)
    if mf.mode == "trinary":
        data[p > mf.occupied_thresh] = 100
        data[p < mf.free_thresh] = 0
    else:
        data[p > mf.occupied_thresh] = 100
        data[p < mf.free_thresh] = 0
        mid = (p >= mf.free_thresh) & (p <= mf.occupied_thresh)
        scaled = 99.0 * (p - mf.free_thresh) / (mf.occupied_thresh - mf.free_thresh)
        data[mid] = np.round(scaled[mid]).astype(np.int8)
    data = np.ascontiguousarray(data[::-1])
    ox, oy, oyaw = mf.origin
    return OccupancyGrid(data=data, resolution=mf.resolution, origin=Pose2D(ox, oy, oyaw))


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
