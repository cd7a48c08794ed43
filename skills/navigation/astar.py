"""Grid A* (8-connected, octile heuristic) and line-of-sight path simplification.

Paths are lists of ``(x, y)`` map points [m] through cell centres; the first point is the
start cell's centre, the last the goal cell's centre.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import math

import numpy as np

from mmexec.skills.navigation.grid import CostMap, cell_to_world, world_to_cell

__all__ = ["line_is_free", "path_length", "plan_path", "simplify_path"]

log = logging.getLogger(__name__)

_SQRT2 = math.sqrt(2.0)


def plan_path(
    costmap: CostMap,
    start: tuple[float, float],
    goal: tuple[float, float],
    *,
    penalty_weight: float = 2.0,
    penalty_distance: float = 0.3,
    allow_start_in_inflation: bool = True,
) -> list[tuple[float, float]] | None:
    """Shortest 8-connected path from ``start`` to ``goal`` (map points [m]), or None.

    Step cost is the centre-to-centre length in cells (1 or sqrt 2) times
    ``1 + penalty_weight * max(0, 1 - extra / penalty_distance)`` of the entered cell,
    where ``extra`` [m] is its clearance beyond the inflation radius: paths keep away from
    walls where they can. Diagonal moves may not cut a blocked corner. The octile
    heuristic stays admissible because every cost factor is >= 1.

    ``allow_start_in_inflation``: the robot may start inside the inflated zone (it stopped
    close to a wall) but never on an obstacle cell. Returns None when the goal is
    blocked, outside the grid or unreachable.
    """
    grid = costmap.grid
    h, w = grid.height, grid.width
    sr, sc = world_to_cell(grid, *start)
    gr, gc = world_to_cell(grid, *goal)
    if not (costmap.in_bounds(sr, sc) and costmap.in_bounds(gr, gc)):
        log.debug("plan_path: start %s or goal %s outside the grid", start, goal)
        return None
    if costmap.blocked[gr, gc]:
        return None
    if costmap.blocked[sr, sc]:
        lethal = costmap.clearance[sr, sc] <= 0.0
        if lethal or not allow_start_in_inflation:
            return None
    s, g = sr * w + sc, gr * w + gc
    if s == g:
        return [cell_to_world(grid, sr, sc)]

    blocked_arr = costmap.blocked.copy()
    blocked_arr[sr, sc] = False
    blocked = blocked_arr.ravel().tolist()
    if penalty_weight > 0 and penalty_distance > 0:
        extra = costmap.clearance - (costmap.radius + costmap.margin)
        factor = 1.0 + penalty_weight * np.clip(1.0 - extra / penalty_distance, 0.0, 1.0)
        factor = np.where(np.isfinite(factor), factor, 1.0)
    else:
        factor = np.ones((h, w))
    fac = factor.ravel().tolist()

    # neighbour offsets: (d_index, d_row, d_col, length)
    moves = [
        (1, 0, 1, 1.0), (-1, 0, -1, 1.0), (w, 1, 0, 1.0), (-w, -1, 0, 1.0),
        (w + 1, 1, 1, _SQRT2), (w - 1, 1, -1, _SQRT2), (-w + 1, -1, 1, _SQRT2), (-w - 1, -1, -1, _SQRT2),
    ]
    n = h * w
    inf = math.inf
    gcost = [inf] * n
    parent = [-1] * n
    closed = bytearray(n)
    gcost[s] = 0.0
    k = _SQRT2 - 2.0

    def heur(i: int) -> float:
        dr = abs(i // w - gr)
        dc = abs(i % w - gc)
        return dr + dc + k * (min(dc, dr))

    openq: list[tuple[float, float, int]] = [(heur(s), 0.0, s)]
    push, pop = heapq.heappush, heapq.heappop
    while openq:
        _, gi, i = pop(openq)
        if closed[i]:
            continue
        if i == g:
            break
        closed[i] = 1
        r, c = divmod(i, w)
        for di, dr, dc, length in moves:
            nr, nc = r + dr, c + dc
            if nr < 0 or nr >= h or nc < 0 or nc >= w:
                continue
            j = i + di
            if blocked[j] or closed[j]:
                continue
            if dr and dc and (blocked[i + dr * w] or blocked[i + dc]):
                continue  # no corner cutting
            ng = gi + length * fac[j]
            if ng < gcost[j]:
                gcost[j] = ng
                parent[j] = i
                push(openq, (ng + heur(j), ng, j))
    else:
        return None
    if parent[g] < 0:
        return None
    cells = [g]
    while cells[-1] != s:
        cells.append(parent[cells[-1]])
    cells.reverse()
    return [cell_to_world(grid, *divmod(i, w)) for i in cells]


def line_is_free(costmap: CostMap, a: tuple[float, float], b: tuple[float, float], *,
                 clearance: float = 0.0) -> bool:
    """True when every cell the segment ``a``-``b`` [m] passes over is free (sampled at a
    quarter cell, so a diagonal cannot slip between two blocked cells) and, past the
    first, at least ``clearance`` [m] from the nearest obstacle cell."""
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    n = max(1, math.ceil(length / (costmap.resolution * 0.25)))
    grid = costmap.grid
    for k in range(n + 1):
        t = k / n
        r, c = world_to_cell(grid, a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
        if not costmap.in_bounds(r, c) or costmap.blocked[r, c]:
            return False
        if k and costmap.clearance[r, c] < clearance:
            return False
    return True


def simplify_path(costmap: CostMap, path: list[tuple[float, float]], *,
                  keep_clearance: float = 0.0) -> list[tuple[float, float]]:
    """Drop waypoints while the straight line between the kept ones stays free (greedy
    farthest-visible shortcutting). The first and last points are kept; the start may lie
    in the inflated zone, so segments leaving it are checked from their second cell on.
    ``keep_clearance`` [m] > 0: a shortcut also keeps as far from obstacles as the path
    it replaces did, up to that much beyond the inflation (less a cell, for the grid),
    so a path A* kept off a corner is not pulled back onto it."""
    if len(path) <= 2:
        return list(path)
    clear = None
    if keep_clearance > 0:
        cap = costmap.radius + costmap.margin + keep_clearance
        clear = [min(costmap.clearance_at(x, y), cap) - costmap.resolution for x, y in path]
    out = [path[0]]
    i = 0
    while i < len(path) - 1:
        j = len(path) - 1
        while j > i + 1:
            a = path[i]
            if i == 0 and not costmap.is_free(*a):
                # shortcut from a start in the inflation only along the planned first step
                j = i + 1
                break
            need = min(clear[i + 1 : j + 1], default=0.0) if clear is not None else 0.0
            if line_is_free(costmap, a, path[j], clearance=need):
                break
            j -= 1
        out.append(path[j])
        i = j
    return out


def path_length(path: list[tuple[float, float]]) -> float:
    """Total length [m] of a polyline."""
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(path))
