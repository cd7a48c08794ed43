"""Synthetic planar lidar scans and a closed-loop harness for the local planner, in pure numpy.

Used by the navigation tests and ``benchmarks/local_planner.py`` to drive the local
planner without a simulator (skills never import ``sim``). :func:`cast_scan` marches
every beam through the grid at a third of a cell and intersects it exactly with each
circle; the nearest return wins. :func:`run_closed_loop` drives a unicycle (exact arcs)
with A* + :class:`~mmexec.skills.navigation.local_planner.LocalPlanner` among poles and a
walking person the map does not hold, and records the smallest gaps. Frames: the base
``pose`` in ``map``; the lidar at ``T_base_lidar`` (default: at the base centre, no yaw);
beams CCW from ``-pi``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.interfaces import LaserScan, OccupancyGrid, Pose2D
from mmexec.skills.navigation.astar import plan_path
from mmexec.skills.navigation.cbf import QpStatus
from mmexec.skills.navigation.costmap import points_to_cells
from mmexec.skills.navigation.dwa import DwaStatus
from mmexec.skills.navigation.grid import inflate
from mmexec.skills.navigation.local_planner import LocalPlanner, LocalPlannerConfig

__all__ = ["ClosedLoopRecord", "Walker", "cast_scan", "run_closed_loop", "unicycle_step"]


def _march(grid: OccupancyGrid, origin: np.ndarray, dirs: np.ndarray, range_max: float,
           occupied_threshold: int) -> np.ndarray:
    """Range [m] along each unit direction (n, 2) from ``origin`` to the first occupied
    cell (inf when none within ``range_max``, or when the beam leaves the map). Sphere
    tracing on the distance field: a step never passes an obstacle cell, and within
    1.5 cells of one the beam advances by a third of a cell (the range's resolution)."""
    data = np.asarray(grid.data)
    field = inflate(grid, 0.0, 0.0, unknown_is_obstacle=False, occupied_threshold=occupied_threshold).clearance
    res = grid.resolution
    n = dirs.shape[0]
    t = np.zeros(n)
    r = np.full(n, np.inf)
    active = np.arange(n)
    while active.size:
        pts = origin + t[active, None] * dirs[active]
        rows, cols = points_to_cells(grid, pts)
        inside = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width)
        rows, cols = np.where(inside, rows, 0), np.where(inside, cols, 0)
        hit = inside & (data[rows, cols] >= occupied_threshold)
        r[active[hit]] = t[active[hit]]
        step = np.maximum(np.minimum(field[rows, cols], 1e6) - 1.5 * res, res / 3.0)
        t[active] += step
        keep = inside & ~hit & (t[active] < range_max)
        active = active[keep]
    return r


def cast_scan(grid: OccupancyGrid, pose: Pose2D, centres: np.ndarray, radii: np.ndarray, *,
              n_beams: int = 400, range_min: float = 0.15, range_max: float = 8.0, noise: float = 0.0,
              rng: np.random.Generator | None = None, stamp: float = 0.0,
              T_base_lidar: np.ndarray | None = None, occupied_threshold: int = 50) -> LaserScan:
    """A 360 degree scan of ``grid`` (cells >= ``occupied_threshold`` reflect, to a third
    of a cell; off the map is open) and the circles ``centres`` (k, 2) / ``radii`` (k,) [m] from a base at
    ``pose``. ``noise``: range standard deviation [m] (needs ``rng``). Beams without a
    return within ``range_max`` read inf."""
    T_bl = np.eye(4) if T_base_lidar is None else np.asarray(T_base_lidar, dtype=float)
    T = pose.matrix() @ T_bl
    origin = T[:2, 3]
    inc = 2.0 * math.pi / n_beams
    angles = -math.pi + inc * np.arange(n_beams)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1) @ T[:2, :2].T
    r = _march(grid, origin, dirs, range_max, occupied_threshold)
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


def unicycle_step(pose: Pose2D, v: float, w: float, dt: float) -> Pose2D:
    """The pose [m, rad] after holding ``(v, w)`` [m/s, rad/s] for ``dt`` [s] (exact arc)."""
    th = pose.theta
    if abs(w) < 1e-9:
        return Pose2D(pose.x + v * dt * math.cos(th), pose.y + v * dt * math.sin(th), th)
    return Pose2D(pose.x + v / w * (math.sin(th + w * dt) - math.sin(th)),
                  pose.y - v / w * (math.cos(th + w * dt) - math.cos(th)), th + w * dt)


@dataclass(frozen=True)
class Walker:
    """A person: a circle of ``radius`` [m] at ``start`` [m] that walks at ``velocity``
    [m/s] from the moment the robot first passes ``trigger_x`` [m] in x (at once if None)."""

    start: tuple[float, float]
    velocity: tuple[float, float]
    radius: float = 0.22
    trigger_x: float | None = None


@dataclass(frozen=True)
class ClosedLoopRecord:
    """What one closed-loop run did: ``reached`` the goal after ``time`` [s] of simulated
    clock in ``ticks``; the smallest gap [m] (centre distance minus both radii) to any
    pole and to the walker over the run; ``replans`` (on a blocked path); ``filtered``
    ticks where the filter changed the DWA command (the CLF's pull included),
    ``barrier_active`` ticks where a barrier constraint bound, ``infeasible`` ticks (the
    filter braked); the final DWA ``status``."""

    reached: bool
    time: float
    ticks: int
    min_pole_gap: float
    min_person_gap: float
    replans: int
    filtered: int
    barrier_active: int
    infeasible: int
    status: str


def run_closed_loop(grid: OccupancyGrid, start: Pose2D, goal: tuple[float, float], poles: np.ndarray,
                    pole_radii: np.ndarray, walker: Walker | None, config: LocalPlannerConfig, *,
                    dt: float = 0.05, t_max: float = 120.0, n_beams: int = 400, replan_every: float = 1.0,
                    stop_when: Callable[[ClosedLoopRecord], bool] | None = None) -> ClosedLoopRecord:
    """Drive a unicycle from ``start`` to ``goal`` through ``grid`` (the static map the
    planner knows) among ``poles`` (k, 2) of ``pole_radii`` and a ``walker`` (neither in
    the map): A* on the map inflated by the robot radius and margin, then every ``dt``
    [s] a scan (``n_beams``), one :meth:`LocalPlanner.step` and an exact arc. A blocked
    path is re-planned on :meth:`LocalPlanner.replan_grid` (at most every
    ``replan_every`` s). Ends at the goal (the DWA reports it and the base is at rest),
    after ``t_max`` [s], or when ``stop_when(record so far)`` holds."""
    lim = config.limits
    planner = LocalPlanner(grid, config)

    def plan(g: OccupancyGrid, s: tuple[float, float]) -> list[tuple[float, float]] | None:
        path = plan_path(inflate(g, lim.radius, config.margin), s, goal)
        return None if path is None else [s, *path[1:-1], goal]

    first = plan(grid, (start.x, start.y))
    if first is None:
        raise ValueError(f"run_closed_loop: no path from ({start.x}, {start.y}) to {goal} on the map")
    planner.set_path(first, 0.0)
    pose, v, w, t = start, 0.0, 0.0, 0.0
    t_walk: float | None = None if walker is None or walker.trigger_x is not None else 0.0
    min_pole = min_person = math.inf
    replans = filtered = active = infeasible = ticks = 0
    last_replan = -math.inf
    status = "ok"

    def record(reached: bool) -> ClosedLoopRecord:
        return ClosedLoopRecord(reached, t, ticks, min_pole, min_person, replans, filtered, active, infeasible,
                                status)

    while t < t_max:
        centres, radii = np.asarray(poles, dtype=float).reshape(-1, 2), np.asarray(pole_radii, dtype=float)
        if walker is not None:
            if t_walk is None and walker.trigger_x is not None and pose.x >= walker.trigger_x:
                t_walk = t
            walked = 0.0 if t_walk is None else t - t_walk
            person = np.asarray(walker.start) + walked * np.asarray(walker.velocity)
            centres = np.vstack([centres, person])
            radii = np.append(radii, walker.radius)
        scan = cast_scan(grid, pose, centres, radii, n_beams=n_beams, stamp=t)
        cmd = planner.step(pose, v, w, t, dt, scan)
        ticks += 1
        status = cmd.status.value
        if cmd.cbf is not None:
            filtered += abs(cmd.cbf.v - cmd.dwa.v) > 1e-6 or abs(cmd.cbf.w - cmd.dwa.w) > 1e-6
            active += bool(cmd.cbf.active.any())
            infeasible += cmd.cbf.status is QpStatus.INFEASIBLE
        if cmd.path_blocked and t - last_replan >= replan_every:
            path = plan(planner.replan_grid(t), (pose.x, pose.y))
            if path is not None:
                planner.set_path(path, t)
                replans += 1
                last_replan = t
        if cmd.status is DwaStatus.GOAL_REACHED and abs(cmd.v) < 1e-9 and abs(cmd.w) < 1e-9:
            return record(True)
        v, w = cmd.v, cmd.w
        pose = unicycle_step(pose, v, w, dt)
        t += dt
        gaps = np.hypot(centres[:, 0] - pose.x, centres[:, 1] - pose.y) - radii - lim.radius
        n_poles = len(pole_radii)
        if n_poles:
            min_pole = min(min_pole, float(gaps[:n_poles].min()))
        if walker is not None:
            min_person = min(min_person, float(gaps[-1]))
        if stop_when is not None and stop_when(record(False)):
            break
    return record(False)
