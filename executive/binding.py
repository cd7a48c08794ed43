"""Does a config bind? The checks ``mmexec validate MISSION --config CONFIG`` runs on the
config beyond its schema, without opening or starting anything:

* the robot profile against the sections the skill packages declare
  (:mod:`mmexec.skills.profile`): unknown keys with a hint, types, ranges;
* the navigation map the run will have and the base's footprint radius, as the backend
  finds them from its section (:attr:`~mmexec.drivers.backendspec.BackendSpec.navigation`:
  the sim's world file, its problems located in the world file, and the model's radius;
  the real robot's ``robot.map`` and its ``robot.base`` section's radius);
* every base pose the profile names (``home``, ``places``, the fetch depot stop and search
  locations: the settings declared ``base_pose``) is inside that map, free in the map
  inflated as navigation inflates it (footprint radius plus the profile's nav margin),
  and reachable from ``home`` (grid A*, :mod:`mmexec.skills.navigation`).

Every problem is a :class:`~mmexec.config.yamlload.Problem` located at the value in the
config (``FILE:LINE:COL: profile.fetch.depot.base: ...``), all reported together.
"""

from __future__ import annotations

import logging

from mmexec.config.yamlload import InputError, Problem, YDict
from mmexec.drivers.backendspec import NavMap
from mmexec.drivers.interfaces import OccupancyGrid
from mmexec.executive.config import LoadedConfig, profile_problems
from mmexec.skills.profile import NamedPose, base_poses

__all__ = ["NavMap", "binding_problems", "navigation_map", "pose_problems"]

log = logging.getLogger(__name__)


def navigation_map(loaded: LoadedConfig) -> NavMap | None:
    """The map and footprint the configured backend's navigation will use, found without
    opening anything; None when the backend has no map or no base (the mock; a robot
    section without ``map`` or ``base``). InputError for a bad section or world file."""
    navigation = loaded.spec.navigation
    return navigation(loaded.section()) if navigation is not None else None


def _extent(grid: OccupancyGrid) -> str:
    o = grid.origin
    if abs(o.theta) > 1e-9:
        return f"{grid.width} x {grid.height} cells of {grid.resolution:g} m, rotated"
    x1, y1 = o.x + grid.width * grid.resolution, o.y + grid.height * grid.resolution
    return f"x {o.x:g}..{x1:g} m, y {o.y:g}..{y1:g} m"


def pose_problems(poses: list[NamedPose], nav: NavMap, margin: float) -> list[Problem]:
    """Each pose of ``poses`` that is outside ``nav``'s map, not free in the map inflated
    by the footprint radius plus ``margin`` [m], or not reachable from ``profile.home``
    (when the profile has a home that is itself free)."""
    from mmexec.skills.navigation.astar import plan_path
    from mmexec.skills.navigation.grid import inflate, world_to_cell

    cm = inflate(nav.grid, nav.radius, margin)
    need = nav.radius + margin
    problems: list[Problem] = []
    free: list[NamedPose] = []
    for p in poses:
        x, y = p.pose.x, p.pose.y
        where = f"{p.path}: ({x:g}, {y:g})"
        r, c = world_to_cell(nav.grid, x, y)
        if not cm.in_bounds(r, c):
            problems.append(Problem(p.mark, f"{where} is outside {nav.source} ({_extent(nav.grid)})"))
        elif cm.clearance[r, c] <= 0.0:
            problems.append(Problem(p.mark, f"{where} is in an obstacle of {nav.source}"))
        elif cm.blocked[r, c]:
            problems.append(Problem(p.mark, f"{where} is {float(cm.clearance[r, c]):.2f} m from an obstacle of "
                                            f"{nav.source}; the base needs {need:.3g} m (footprint radius "
                                            f"{nav.radius:g} m + nav margin {margin:g} m)"))
        else:
            free.append(p)
    home = next((p for p in free if p.path == "profile.home"), None)
    if home is None:
        log.debug("validate: no free profile.home, so reachability is not checked")
        return problems
    start = (home.pose.x, home.pose.y)
    for p in free:
        if p is not home and plan_path(cm, start, (p.pose.x, p.pose.y)) is None:
            problems.append(Problem(p.mark, f"{p.path}: ({p.pose.x:g}, {p.pose.y:g}) cannot be reached from "
                                            f"profile.home ({start[0]:g}, {start[1]:g}): no path in {nav.source} "
                                            f"inflated by {need:.3g} m"))
    return problems


def binding_problems(loaded: LoadedConfig) -> list[Problem]:
    """Every problem of the profile and of its base poses on the backend's map (see the
    module doc). Import the config's skill modules first (they declare the sections)."""
    from mmexec.skills.navigation.navigate import nav_margin

    problems = profile_problems(loaded)
    raw = loaded.raw.get("profile")
    if not isinstance(raw, YDict):
        return problems
    try:
        nav = navigation_map(loaded)
    except InputError as e:
        return problems + list(e.problems)
    if nav is None:
        return problems
    return problems + pose_problems(base_poses(raw, loaded.mark("profile")), nav, nav_margin(raw))
