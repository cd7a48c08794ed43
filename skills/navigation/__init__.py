"""Navigation algorithms for a differential-drive base: occupancy-grid utilities and map
loading (:mod:`.grid`), grid A* and path simplification (:mod:`.astar`), path tracking
(:mod:`.tracker`) and stand-off poses in front of a marker (:mod:`.standoff`).

Plain Python over :class:`mmexec.drivers.interfaces.OccupancyGrid`; everything is in the
``map`` frame, metres and radians.
"""

from __future__ import annotations

from mmexec.skills.navigation.astar import plan_path, simplify_path
from mmexec.skills.navigation.grid import CostMap, cell_to_world, inflate, world_to_cell
from mmexec.skills.navigation.standoff import StandoffResult, find_standoff, standoff_pose
from mmexec.skills.navigation.tracker import PathTracker, TrackerConfig

__all__ = [
    "CostMap",
    "PathTracker",
    "StandoffResult",
    "TrackerConfig",
    "cell_to_world",
    "find_standoff",
    "inflate",
    "plan_path",
    "simplify_path",
    "standoff_pose",
    "world_to_cell",
]
