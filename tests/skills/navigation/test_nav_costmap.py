"""Rolling costmap: marking only what the static map lacks, clearing along beams, rolling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.navigation.costmap import CostmapConfig, RollingCostmap, points_to_cells
from mmexec.skills.navigation.grid import world_to_cell
from mmexec.skills.navigation.obstacles import scan_to_map
from mmexec.skills.navigation.synthetic import cast_scan


def _room(w=160, h=120, origin: Pose2D | None = None):
    d = np.zeros((h, w), dtype=np.int8)
    d[0, :] = d[-1, :] = 100
    d[:, 0] = d[:, -1] = 100
    return OccupancyGrid(data=d, resolution=0.05, origin=origin or Pose2D())


def _observe(cm, grid, pose, centres, radii, n=400):
    scan = cast_scan(grid, pose, np.asarray(centres, float).reshape(-1, 2), np.asarray(radii, float), n_beams=n)
    pts = scan_to_map(scan, pose, cm.config.clear_range)
    return pts, cm.update(pts)


def test_points_to_cells_matches_world_to_cell():
    grid = _room(origin=Pose2D(-1.3, 0.7, 0.4))
    rng = np.random.default_rng(0)
    xy = rng.uniform(-3, 8, (500, 2))
    xy[:50] = np.round(xy[:50] / 0.05) * 0.05          # points on cell boundaries too
    rows, cols = points_to_cells(grid, xy)
    expected = np.array([world_to_cell(grid, x, y) for x, y in xy])
    np.testing.assert_array_equal(np.column_stack([rows, cols]), expected)


def test_static_walls_are_not_marked_new_obstacles_are():
    grid = _room()
    cm = RollingCostmap(grid, CostmapConfig(size=6.0))
    pose = Pose2D(4.0, 3.0, 0.0)
    pts, new = _observe(cm, grid, pose, [[5.0, 3.2]], [0.2])
    # every wall hit is static; every hit on the new pole is new
    on_pole = pts.hit & (np.hypot(*(np.nan_to_num(pts.xy) - [5.0, 3.2]).T) < 0.25)
    np.testing.assert_array_equal(new[pts.hit & (pts.free <= cm.config.mark_range)],
                                  on_pole[pts.hit & (pts.free <= cm.config.mark_range)])
    assert on_pole.sum() > 5
    ci, cj = np.nonzero(cm.marks)
    centres = cm.cell_centres()[ci, cj]
    assert (np.hypot(*(centres - [5.0, 3.2]).T) < 0.2 + 0.05).all()
    # the pole shows in the clearance: its near side is 0.82 m away
    assert cm.clearance_at(np.array([[4.0, 3.0]]))[0] == pytest.approx(math.hypot(1.0, 0.2) - 0.2, abs=0.04)


def test_hits_within_the_static_tolerance_are_the_map():
    grid = _room()
    cm = RollingCostmap(grid, CostmapConfig(static_tolerance=0.1))
    # a post against the right wall (cells from x = 7.95): the cells of its near side
    # (x 7.87) are within 0.1 m (centre to centre) of a wall cell: it is the wall
    _, new = _observe(cm, grid, Pose2D(6.5, 3.0, 0.0), [[7.92, 3.0]], [0.05])
    assert not new.any()
    _, new = _observe(cm, grid, Pose2D(6.5, 3.0, 0.0), [[7.5, 3.0]], [0.05])
    assert new.any()


def test_clearing_removes_what_moved_away_and_keeps_what_is_hidden():
    grid = _room()
    cm = RollingCostmap(grid, CostmapConfig(size=6.0))
    pose = Pose2D(4.0, 3.0, 0.0)
    _observe(cm, grid, pose, [[5.5, 3.0], [2.5, 3.0]], [0.15, 0.15])
    before = cm.marks.copy()
    assert before.sum() > 0
    # the pole at (5.5, 3) leaves; a pole at (4.6, 3.0) now hides the space behind it
    _observe(cm, grid, pose, [[4.6, 3.0], [2.5, 3.0]], [0.05, 0.15])
    centres = cm.cell_centres()
    old = centres[before]
    kept = cm.marks[before]
    # marks of the departed pole that the new pole's shadow covers stay; the rest go
    bearing = np.arctan2(old[:, 1] - 3.0, old[:, 0] - 4.0)
    shadow = (np.abs(bearing) < math.atan2(0.05, 0.6) + 0.01) & (old[:, 0] > 4.6)
    visible_old = (old[:, 0] > 5.0) & ~shadow
    assert not kept[visible_old].any()
    assert kept[(old[:, 0] < 3.0)].all()   # the pole at (2.5, 3) is still there


def test_clearing_agrees_with_ray_tracing_along_each_beam():
    """Random marks, one scan: a marked cell is cleared exactly when the beam through its
    centre went on at least half a cell past it (and no hit lies in it). Checked with
    each cell's own bearing and range, on cells whose centre lies within a quarter beam
    spacing of a beam (elsewhere the nearest beam is a matter of rounding)."""
    grid = _room()
    cm = RollingCostmap(grid, CostmapConfig(size=6.0))
    rng = np.random.default_rng(2)
    cm.recentre(4.0, 3.0)
    cm.marks[:] = rng.random(cm.marks.shape) < 0.05
    marks0 = cm.marks.copy()
    pose = Pose2D(4.0, 3.0, 0.2)
    scan = cast_scan(grid, pose, np.array([[5.0, 3.5]]), np.array([0.3]), n_beams=400, range_max=8.0)
    pts = scan_to_map(scan, pose, cm.config.clear_range)
    cm.update(pts)
    cleared = marks0 & ~cm.marks
    centres = cm.cell_centres()
    d = np.hypot(centres[..., 0] - pts.origin[0], centres[..., 1] - pts.origin[1])
    bearing = np.arctan2(centres[..., 1] - pts.origin[1], centres[..., 0] - pts.origin[0])
    rel = np.mod(bearing - pts.angle0 + math.pi, 2 * math.pi) - math.pi
    off = np.abs(rel / pts.increment - np.rint(rel / pts.increment))
    beam = np.mod(np.rint(rel / pts.increment).astype(int), pts.n_beams)
    expect = marks0 & (np.minimum(pts.free[beam], cm.config.clear_range) > d + 0.025) & (d > 0.05)
    # hits re-mark their cells after clearing
    hit_i, hit_j, inside = cm.window_cells(pts.xy[pts.hit & (pts.free <= cm.config.mark_range)])
    expect[hit_i[inside], hit_j[inside]] = False
    sure = off < 0.25
    assert cleared[sure].sum() > 100 and (marks0 & ~cleared)[sure].sum() > 20
    np.testing.assert_array_equal(cleared[sure], expect[sure])


def test_window_rolls_and_keeps_marks_in_the_overlap():
    grid = _room()
    cm = RollingCostmap(grid, CostmapConfig(size=4.0))
    _observe(cm, grid, Pose2D(3.0, 3.0, 0.0), [[4.0, 3.0]], [0.1])
    n0 = int(cm.marks.sum())
    assert n0 > 0
    cm.recentre(3.5, 3.0)            # the pole stays inside the window
    assert int(cm.marks.sum()) == n0
    assert cm.clearance_at(np.array([[4.0 - 0.1, 3.0]]))[0] <= 0.02
    cm.recentre(7.0, 3.0)            # now it is behind the window's edge: forgotten
    assert int(cm.marks.sum()) == 0


def _edge_distance(q, cells, res=0.05):
    """Exact distance from points q (m, 2) to the nearest of the squares of cells (k, 2)
    given as (row, col) of a grid at the map origin."""
    x0, y0 = cells[:, 1] * res, cells[:, 0] * res
    dx = np.maximum(np.maximum(x0[None] - q[:, :1], 0.0), q[:, :1] - (x0 + res)[None])
    dy = np.maximum(np.maximum(y0[None] - q[:, 1:], 0.0), q[:, 1:] - (y0 + res)[None])
    return np.hypot(dx, dy).min(axis=1)


def test_clearance_is_the_distance_to_obstacle_edges_within_half_a_cell():
    rng = np.random.default_rng(4)
    d = np.zeros((120, 160), dtype=np.int8)
    d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 100
    for _ in range(15):
        r, c = rng.integers(10, 110), rng.integers(10, 150)
        d[r : r + rng.integers(1, 6), c : c + rng.integers(1, 6)] = 100
    grid = OccupancyGrid(data=d, resolution=0.05)
    cm = RollingCostmap(grid, CostmapConfig(size=4.0))
    cm.recentre(4.0, 3.0)
    cm.marks[30:33, 50:52] = True          # and a few marks, then a move that keeps them
    cm.recentre(4.2, 3.0)
    q = rng.uniform([0.3, 0.3], [7.7, 5.7], (2000, 2))     # inside and outside the window
    static = np.argwhere(d >= 50)
    mi, mj = np.nonzero(cm.marks)
    with_marks = np.vstack([static, np.column_stack([mi + cm.r0, mj + cm.c0])])
    _, _, inside = cm.window_cells(q)
    exact = np.where(inside, _edge_distance(q, with_marks), _edge_distance(q, static))  # marks: window only
    near = exact < 0.6
    np.testing.assert_allclose(cm.clearance_at(q)[near], exact[near], atol=0.5 * 0.05)
    assert (cm.clearance_at(np.array([[20.0, 3.0]])) == 0.0).all()    # off the map


def test_merged_grid_holds_marks_and_discs():
    grid = _room()
    cm = RollingCostmap(grid)
    _observe(cm, grid, Pose2D(2.0, 3.0, 0.0), [[3.0, 3.0]], [0.1])
    merged = cm.merged_grid(np.array([[2.0, 4.5]]), np.array([0.2]))
    assert np.array_equal(merged.data[grid.data == 100], grid.data[grid.data == 100])
    r, c = world_to_cell(grid, 2.0, 4.5)
    assert merged.data[r, c] == 100 and grid.data[r, c] == 0
    i, j = np.nonzero(cm.marks)
    assert (merged.data[i + cm.r0, j + cm.c0] == 100).all()
    assert np.count_nonzero(merged.data == 100) > np.count_nonzero(grid.data == 100) + len(i)


def test_costmap_config_validation():
    assert CostmapConfig().validate() == []
    with pytest.raises(ValueError, match="size"):
        RollingCostmap(_room(), CostmapConfig(size=0.0))
