from __future__ import annotations

import itertools
import math

import numpy as np

from mmexec.drivers.interfaces import OccupancyGrid
from mmexec.skills.navigation.astar import line_is_free, path_length, plan_path, simplify_path
from mmexec.skills.navigation.grid import inflate, world_to_cell


def _free(h=20, w=20, res=0.1):
    return OccupancyGrid(np.zeros((h, w), dtype=np.int8), res)


def _assert_path_valid(cm, path):
    for (x0, y0), (x1, y1) in itertools.pairwise(path):
        assert math.hypot(x1 - x0, y1 - y0) <= cm.resolution * math.sqrt(2) + 1e-9
    for x, y in path[1:]:
        assert cm.is_free(x, y)


def test_open_grid_shortest_path_is_octile():
    cm = inflate(_free(), 0.0)
    path = plan_path(cm, (0.05, 0.05), (1.55, 0.85), penalty_weight=0.0)
    assert path is not None
    assert path[0] == pytest_approx((0.05, 0.05)) and path[-1] == pytest_approx((1.55, 0.85))
    # 15 cols, 8 rows: 8 diagonals + 7 straight
    assert path_length(path) == pytest_approx(0.1 * (8 * math.sqrt(2) + 7))
    _assert_path_valid(cm, path)


def pytest_approx(x):
    import pytest

    return pytest.approx(x, rel=1e-9)


def test_wall_with_gap_and_no_corner_cutting():
    data = np.zeros((10, 10), dtype=np.int8)
    data[:, 5] = 100
    data[8, 5] = 0  # gap near the top
    cm = inflate(OccupancyGrid(data, 0.1), 0.0)
    path = plan_path(cm, (0.15, 0.15), (0.85, 0.15), penalty_weight=0.0)
    assert path is not None
    cells = [world_to_cell(cm.grid, x, y) for x, y in path]
    assert (8, 5) in cells
    _assert_path_valid(cm, path)
    # diagonal gap only: two blocked cells touching at a corner must not be crossed
    data = np.zeros((4, 4), dtype=np.int8)
    data[0, 1] = data[1, 0] = 100
    data[2:, :] = 100
    data[1, 2:] = 100
    cm = inflate(OccupancyGrid(data, 0.1), 0.0)
    assert plan_path(cm, (0.05, 0.05), (0.15, 0.15)) is None


def test_unreachable_and_blocked_goals_return_none():
    data = np.zeros((10, 10), dtype=np.int8)
    data[:, 5] = 100
    cm = inflate(OccupancyGrid(data, 0.1), 0.0)
    assert plan_path(cm, (0.15, 0.15), (0.85, 0.15)) is None
    assert plan_path(cm, (0.15, 0.15), (0.55, 0.15)) is None  # goal on the wall
    assert plan_path(cm, (0.15, 0.15), (5.0, 0.15)) is None   # goal off the map


def test_start_in_inflation_allowed_but_not_on_obstacle():
    data = np.zeros((20, 20), dtype=np.int8)
    data[:, 0] = 100
    cm = inflate(OccupancyGrid(data, 0.1), 0.25)
    assert not cm.is_free(0.25, 1.0)
    path = plan_path(cm, (0.25, 1.0), (1.5, 1.0))
    assert path is not None
    _assert_path_valid(cm, path)
    assert plan_path(cm, (0.25, 1.0), (1.5, 1.0), allow_start_in_inflation=False) is None
    assert plan_path(cm, (0.05, 1.0), (1.5, 1.0)) is None


def test_penalty_keeps_away_from_walls():
    data = np.zeros((30, 60), dtype=np.int8)
    data[0, :] = 100
    cm = inflate(OccupancyGrid(data, 0.05), 0.1)
    near = plan_path(cm, (0.2, 0.2), (2.8, 0.2), penalty_weight=0.0)
    far = plan_path(cm, (0.2, 0.2), (2.8, 0.2), penalty_weight=3.0, penalty_distance=0.3)
    assert near is not None and far is not None
    assert max(y for _, y in far) > max(y for _, y in near) + 0.1


def test_simplify_keeps_path_free_and_shortens():
    data = np.zeros((40, 40), dtype=np.int8)
    data[10:30, 18:22] = 100
    cm = inflate(OccupancyGrid(data, 0.05), 0.1)
    path = plan_path(cm, (0.2, 1.0), (1.8, 1.0))
    assert path is not None
    simple = simplify_path(cm, path)
    assert 2 < len(simple) < len(path)
    assert simple[0] == path[0] and simple[-1] == path[-1]
    for a, b in itertools.pairwise(simple):
        assert line_is_free(cm, a, b)
    assert path_length(simple) <= path_length(path) + 1e-9


def test_simplify_from_a_start_in_the_inflation_keeps_the_planned_first_step():
    # A start inside the inflated zone (the robot stopped close to a wall): the path leaves
    # along its planned first step; the shortcut from the start straight to the goal would
    # cross the wall (it did: the inner loop broke with the goal still chosen).
    data = np.zeros((40, 40), dtype=np.int8)
    data[0:30, 18:22] = 100
    cm = inflate(OccupancyGrid(data, 0.05), 0.15)
    start = (0.78, 1.0)  # 0.12 m from the wall's face: inside the 0.15 m inflation
    assert not cm.is_free(*start)
    path = plan_path(cm, start, (1.4, 1.0))
    assert path is not None
    simple = simplify_path(cm, path)
    assert simple[0] == path[0] and simple[-1] == path[-1]
    assert simple[1] == path[1]
    for a, b in itertools.pairwise(simple[1:]):
        assert line_is_free(cm, a, b)


def test_100x80_grid_with_obstacles():
    """A cluttered 100 x 80 grid (the lab's size): a path through free cells, no shorter
    than the straight line. (Its speed is measured in benchmarks/, not asserted here.)"""
    rng = np.random.default_rng(0)
    data = np.zeros((80, 100), dtype=np.int8)
    for _ in range(12):
        r, c = rng.integers(0, 70), rng.integers(0, 90)
        data[r : r + 10, c : c + 3] = 100
    data[0:60, 50] = 100
    cm = inflate(OccupancyGrid(data, 0.05), 0.1)
    path = plan_path(cm, (0.3, 0.3), (4.7, 3.7))
    assert path is not None
    assert all(cm.is_free(x, y) for x, y in path)
    length = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(path))
    assert length >= math.hypot(4.4, 3.4) - 1e-9


def _segment_clearance(cm, path):
    """The smallest clearance [m] of the cells the polyline's segments pass over."""
    out = math.inf
    for (x0, y0), (x1, y1) in itertools.pairwise(path):
        n = max(1, math.ceil(math.hypot(x1 - x0, y1 - y0) / (cm.resolution * 0.25)))
        for k in range(1, n + 1):
            t = k / n
            out = min(out, cm.clearance_at(x0 + t * (x1 - x0), y0 + t * (y1 - y0)))
    return out


def test_shortcuts_can_keep_the_clearance_astar_kept_round_a_corner():
    """A box in a 4 x 3 m room, start and goal either side of it: A* (with its wall
    penalty) passes the box's corner with room to spare; plain shortcutting pulls the
    path back to the inflation's edge at the corner, keep_clearance keeps the room."""
    data = np.zeros((60, 80), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[20:60, 38:42] = 100  # a wall from the north side down to y = 1.0 m
    cm = inflate(OccupancyGrid(data, 0.05), 0.2, 0.03)
    grid_path = plan_path(cm, (1.0, 2.0), (3.0, 2.0))
    assert grid_path is not None
    kept = _segment_clearance(cm, grid_path)
    plain = simplify_path(cm, grid_path)
    keep = simplify_path(cm, grid_path, keep_clearance=0.3)
    assert _segment_clearance(cm, plain) < 0.23 + 0.06  # onto the corner, by the inflation's edge
    assert _segment_clearance(cm, keep) >= min(kept, 0.23 + 0.3) - 0.05 - 1e-9
    assert _segment_clearance(cm, keep) > _segment_clearance(cm, plain) + 0.1
    assert len(keep) > len(plain) and keep[0] == plain[0] and keep[-1] == plain[-1]
